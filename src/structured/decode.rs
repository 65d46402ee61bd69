//! Decoding captures of the [`PatternSet`] sequence: per camera pixel, the projector pixel
//! that lights it, to a fraction of a pixel, with a confidence.

use super::{Axis, Grey, PatternSet, STEPS, step_angle};
use crate::error::{Error, Result};
use rayon::prelude::*;
use std::borrow::Borrow;
use std::f64::consts::TAU;

/// When a pixel counts as decoded.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DecodeOptions {
    /// Least white − black difference, grey levels: below it the projector does not light
    /// the pixel enough to measure.
    pub min_contrast: f64,
    /// Least amplitude of the phase sinusoid, grey levels, on both axes.
    pub min_modulation: f64,
    /// Largest predicted standard deviation of the decoded position, projector pixels, for the
    /// 16 px period; other periods scale it with theirs (it bounds the phase's noise, which
    /// is the same fraction of any period).
    pub max_sigma: f64,
    /// Pixels dropped next to every undecoded one (see [`erode`]).
    pub erode: u32,
}

impl Default for DecodeOptions {
    fn default() -> Self {
        DecodeOptions {
            min_contrast: 20.0,
            min_modulation: 8.0,
            max_sigma: 0.2,
            erode: 2,
        }
    }
}

/// One decoded camera pixel.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Sample {
    /// Projector pixel (centres at integers), sub-pixel.
    pub q: [f64; 2],
    /// Predicted standard deviation of `q` (the larger axis), projector pixels: the phase
    /// fit's residual noise carried through its amplitude. The confidence.
    pub sigma: f64,
}

/// Why pixels were not decoded, counted.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Rejected {
    /// White − black below `min_contrast`: not lit (most of the image, usually).
    pub dark: usize,
    /// Phase amplitude below `min_modulation`.
    pub flat: usize,
    /// Gray code and phase disagree by more than 3/8 of a period: inter-reflection or motion.
    pub inconsistent: usize,
    /// Outside the projector's image.
    pub outside: usize,
    /// Predicted deviation above `max_sigma`.
    pub noisy: usize,
    /// Decoded, but within `erode` pixels of an undecoded pixel.
    pub edge: usize,
}

/// The decoded map, one entry per camera pixel.
#[derive(Debug, Clone)]
pub struct Decoded {
    pub width: u32,
    pub height: u32,
    pub samples: Vec<Option<Sample>>,
    pub rejected: Rejected,
}

impl Decoded {
    pub fn get(&self, x: u32, y: u32) -> Option<Sample> {
        self.samples[(y * self.width + x) as usize]
    }

    pub fn valid(&self) -> usize {
        self.samples.iter().flatten().count()
    }
}

enum Fail {
    Dark,
    Flat,
    Inconsistent,
    Outside,
    Noisy,
}

/// Decodes one capture per frame of `set`, in its order.
pub fn decode<F: Borrow<Grey> + Sync>(
    set: &PatternSet,
    frames: &[F],
    opts: &DecodeOptions,
) -> Result<Decoded> {
    let frames: Vec<&Grey> = frames.iter().map(Borrow::borrow).collect();
    if frames.len() != set.len() {
        return Err(Error::invalid(
            "captures",
            format!(
                "a {}×{} projector's sequence has {} frames, got {}",
                set.width,
                set.height,
                set.len(),
                frames.len()
            ),
        ));
    }
    let (w, h) = (frames[0].width, frames[0].height);
    if let Some(n) = frames.iter().position(|f| (f.width, f.height) != (w, h)) {
        return Err(Error::invalid(
            format!("captures/{n}"),
            format!(
                "is {}×{}, the first capture {w}×{h}",
                frames[n].width, frames[n].height
            ),
        ));
    }
    let bx = set.bits(Axis::X) as usize;
    let by = set.bits(Axis::Y) as usize;
    let n = STEPS as usize;
    // Where each axis's Gray pairs and phase steps start in the sequence.
    let x_at = 2;
    let y_at = x_at + 2 * bx + n;
    let results: Vec<(Option<Sample>, Option<Fail>)> = (0..(w as usize) * (h as usize))
        .into_par_iter()
        .with_min_len(4096)
        .map(|i| {
            let v = |k: usize| f64::from(frames[k].data[i]);
            let contrast = v(0) - v(1);
            if contrast < opts.min_contrast {
                return (None, Some(Fail::Dark));
            }
            let ax = match axis(v, x_at, bx, set.width, set.period, opts) {
                Ok(a) => a,
                Err(f) => return (None, Some(f)),
            };
            let ay = match axis(v, y_at, by, set.height, set.period, opts) {
                Ok(a) => a,
                Err(f) => return (None, Some(f)),
            };
            let sigma = ax.1.max(ay.1);
            if sigma > opts.max_sigma * f64::from(set.period) / f64::from(super::PERIOD) {
                return (None, Some(Fail::Noisy));
            }
            (
                Some(Sample {
                    q: [ax.0, ay.0],
                    sigma,
                }),
                None,
            )
        })
        .collect();
    let mut rejected = Rejected::default();
    let mut samples = Vec::with_capacity(results.len());
    for (s, f) in results {
        samples.push(s);
        match f {
            Some(Fail::Dark) => rejected.dark += 1,
            Some(Fail::Flat) => rejected.flat += 1,
            Some(Fail::Inconsistent) => rejected.inconsistent += 1,
            Some(Fail::Outside) => rejected.outside += 1,
            Some(Fail::Noisy) => rejected.noisy += 1,
            None => {}
        }
    }
    let edge = erode(
        &mut samples,
        w as usize,
        h as usize,
        opts.erode * set.period / super::PERIOD,
    );
    rejected.edge = edge;
    Ok(Decoded {
        width: w,
        height: h,
        samples,
        rejected,
    })
}

/// Drops decoded pixels within `radius` pixels (a square) of an undecoded one; returns how
/// many. A camera pixel on the edge of the lit region (the wall's edge, the projector's image
/// edge, a shadow) sees light from part of its area only, and its blur reaches past the edge:
/// its position is that of the lit part, not of its centre.
fn erode(samples: &mut [Option<Sample>], w: usize, h: usize, radius: u32) -> usize {
    let r = radius as usize;
    if r == 0 {
        return 0;
    }
    let valid: Vec<bool> = samples.iter().map(Option::is_some).collect();
    // Distance to the nearest undecoded pixel along rows, then the worst over the column
    // window: a square structuring element in two 1-D passes.
    let mut near = vec![false; w * h];
    for y in 0..h {
        let row = &valid[y * w..(y + 1) * w];
        let mut last_gap: Option<usize> = None;
        for x in 0..w {
            if !row[x] {
                last_gap = Some(x);
            }
            near[y * w + x] = last_gap.is_some_and(|g| x - g <= r);
        }
        let mut next_gap: Option<usize> = None;
        for x in (0..w).rev() {
            if !row[x] {
                next_gap = Some(x);
            }
            near[y * w + x] |= next_gap.is_some_and(|g| g - x <= r);
        }
        // The image's border counts as undecoded.
        for x in (0..w).filter(|&x| x < r || x + r >= w) {
            near[y * w + x] = true;
        }
    }
    let mut dropped = 0;
    for y in 0..h {
        for x in 0..w {
            let lo = y.saturating_sub(r);
            let hi = (y + r).min(h - 1);
            let drop = y < r || y + r >= h || (lo..=hi).any(|yy| near[yy * w + x]);
            if drop && samples[y * w + x].take().is_some() {
                dropped += 1;
            }
        }
    }
    dropped
}

/// One axis of one pixel: the position and its predicted deviation. `v(k)` reads frame k;
/// the axis's Gray pairs start at `at`, its phase steps follow them.
fn axis(
    v: impl Fn(usize) -> f64,
    at: usize,
    bits: usize,
    side: u32,
    period: u32,
    opts: &DecodeOptions,
) -> std::result::Result<(f64, f64), Fail> {
    let mut gray = 0u32;
    for b in 0..bits {
        gray = (gray << 1) | u32::from(v(at + 2 * b) > v(at + 2 * b + 1));
    }
    // Gray → binary: each bit is the XOR of all higher Gray bits.
    let mut half = gray;
    let mut shift = 1;
    while shift < 32 {
        half ^= half >> shift;
        shift <<= 1;
    }
    let n = STEPS as usize;
    let steps = at + 2 * bits;
    let (mut s, mut c, mut mean) = (0.0, 0.0, 0.0);
    for k in 0..n {
        let (sin, cos) = step_angle(k as u32).sin_cos();
        let i = v(steps + k);
        s += i * sin;
        c += i * cos;
        mean += i;
    }
    mean /= n as f64;
    let nf = n as f64;
    let modulation = 2.0 / nf * s.hypot(c);
    if modulation < opts.min_modulation {
        return Err(Fail::Flat);
    }
    let phi = s.atan2(c);
    let p = f64::from(period);
    let wrapped = phi / TAU * p;
    let centre = (f64::from(half) + 0.5) * p / 2.0;
    let x = wrapped + p * ((centre - wrapped) / p).round();
    if (x - centre).abs() > 3.0 * p / 8.0 {
        return Err(Fail::Inconsistent);
    }
    if !(-0.5..=f64::from(side) - 0.5).contains(&x) {
        return Err(Fail::Outside);
    }
    // The fit's residuals estimate the noise (N − 3 degrees of freedom: mean, amplitude,
    // phase); an 8-bit capture's rounding sets a floor.
    let mut rss = 0.0;
    for k in 0..n {
        let r = v(steps + k) - mean - modulation * (phi - step_angle(k as u32)).cos();
        rss += r * r;
    }
    let noise = (rss / (nf - 3.0)).sqrt().max(1.0 / 12f64.sqrt());
    let sigma = (2.0 / nf).sqrt() * noise / modulation * p / TAU;
    Ok((x, sigma))
}
