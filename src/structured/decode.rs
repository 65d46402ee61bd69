//! Decoding captures of the [`PatternSet`] sequence: per camera pixel, the projector pixel
//! that lights it, to a fraction of a pixel, with a confidence.

use super::{Axis, Code, Grey, PatternSet, STEPS, step_angle};
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
    /// Pixels dropped next to every undecoded one (see `erode`).
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
    /// With the XOR code, also a pixel on the finest stripe's edge with no neighbour read clear
    /// of it.
    pub inconsistent: usize,
    /// Outside the projector's image.
    pub outside: usize,
    /// Predicted deviation above `max_sigma`.
    pub noisy: usize,
    /// Decoded, but within `erode` pixels of an undecoded pixel.
    pub edge: usize,
}

/// In words, for error messages: `12034 dark, 310 flat, 4 inconsistent, 0 outside, 0 noisy,
/// 88 on an edge`.
impl std::fmt::Display for Rejected {
    fn fmt(&self, out: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            out,
            "{} dark, {} flat, {} inconsistent, {} outside, {} noisy, {} on an edge",
            self.dark, self.flat, self.inconsistent, self.outside, self.noisy, self.edge
        )
    }
}

/// The decoded map, one entry per camera pixel.
#[derive(Debug, Clone)]
pub struct Decoded {
    /// The capture's width in camera pixels.
    pub width: u32,
    /// The capture's height in camera pixels.
    pub height: u32,
    /// Per camera pixel, row by row from the top: the decoded sample, or `None` where it was
    /// rejected (counted in `rejected`).
    pub samples: Vec<Option<Sample>>,
    /// Why the undecoded pixels were not decoded, counted.
    pub rejected: Rejected,
}

impl Decoded {
    /// The sample of camera pixel (x, y), x < `width` and y < `height`; `None` where it was not
    /// decoded.
    pub fn get(&self, x: u32, y: u32) -> Option<Sample> {
        self.samples[(y * self.width + x) as usize]
    }

    /// How many camera pixels were decoded.
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
    // Per pixel: the sample or why there is none, and per axis whether an XOR code's coarse
    // bits could not be read there (see `unwrap_from_neighbours`).
    type Outcome = (Option<Sample>, Option<Fail>, [bool; 2]);
    let results: Vec<Outcome> = (0..(w as usize) * (h as usize))
        .into_par_iter()
        .with_min_len(4096)
        .map(|i| {
            let v = |k: usize| frames[k].level(i);
            let contrast = v(0) - v(1);
            if contrast < opts.min_contrast {
                return (None, Some(Fail::Dark), [false; 2]);
            }
            let ax = match axis(v, x_at, bx, set.width, set, opts) {
                Ok(a) => a,
                Err(f) => return (None, Some(f), [false; 2]),
            };
            let ay = match axis(v, y_at, by, set.height, set, opts) {
                Ok(a) => a,
                Err(f) => return (None, Some(f), [false; 2]),
            };
            let sigma = ax.sigma.max(ay.sigma);
            if sigma > opts.max_sigma * f64::from(set.period) / f64::from(super::PERIOD) {
                return (None, Some(Fail::Noisy), [false; 2]);
            }
            (
                Some(Sample {
                    q: [ax.x, ay.x],
                    sigma,
                }),
                None,
                [ax.ambiguous, ay.ambiguous],
            )
        })
        .collect();
    let mut rejected = Rejected::default();
    let mut samples = Vec::with_capacity(results.len());
    let mut ambiguous = Vec::with_capacity(results.len());
    for (s, f, a) in results {
        samples.push(s);
        ambiguous.push(a);
        match f {
            Some(Fail::Dark) => rejected.dark += 1,
            Some(Fail::Flat) => rejected.flat += 1,
            Some(Fail::Inconsistent) => rejected.inconsistent += 1,
            Some(Fail::Outside) => rejected.outside += 1,
            Some(Fail::Noisy) => rejected.noisy += 1,
            None => {}
        }
    }
    rejected.inconsistent += unwrap_from_neighbours(&mut samples, &ambiguous, w as usize, set);
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

/// Where an XOR code's finest stripe changes (mid-period), every frame of the axis changes
/// with it, so a camera pixel straddling that edge reads all its bits near the threshold and
/// noise can flip any of them: the decoded half period can land anywhere, and the phase, which
/// only checks the position within a period, cannot tell. The two half periods on either
/// side of that edge share all their coarse bits, though, so a neighbour read clear of the edge
/// names the period: such a pixel keeps its phase and takes the period nearest the closest
/// clear neighbour's position (within 3 pixels). Without one, or when that lands off the
/// projector's image, it is dropped and counted as inconsistent; returns how many were.
fn unwrap_from_neighbours(
    samples: &mut [Option<Sample>],
    ambiguous: &[[bool; 2]],
    w: usize,
    set: &PatternSet,
) -> usize {
    const REACH: usize = 3;
    let h = samples.len() / w.max(1);
    let p = f64::from(set.period);
    let sides = [set.width, set.height];
    let mut fixed = Vec::new();
    for (i, a) in ambiguous.iter().enumerate() {
        let Some(s) = samples[i] else { continue };
        if !a[0] && !a[1] {
            continue;
        }
        let (x, y) = (i % w, i / w);
        let mut q = s.q;
        let mut ok = true;
        for axis in (0..2).filter(|&k| a[k]) {
            let mut best: Option<(usize, f64)> = None;
            for ny in y.saturating_sub(REACH)..(y + REACH + 1).min(h) {
                for nx in x.saturating_sub(REACH)..(x + REACH + 1).min(w) {
                    let j = ny * w + nx;
                    let (Some(n), false) = (samples[j], ambiguous[j][axis]) else {
                        continue;
                    };
                    let d = nx.abs_diff(x).pow(2) + ny.abs_diff(y).pow(2);
                    if best.is_none_or(|b| d < b.0) {
                        best = Some((d, n.q[axis]));
                    }
                }
            }
            match best {
                Some((_, near)) => {
                    q[axis] += p * ((near - q[axis]) / p).round();
                    ok &= inside(q[axis], sides[axis]);
                }
                None => ok = false,
            }
        }
        fixed.push((i, ok.then_some(Sample { q, ..s })));
    }
    let mut dropped = 0;
    for (i, s) in fixed {
        dropped += usize::from(s.is_none());
        samples[i] = s;
    }
    dropped
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

/// Whether position `x` lies on a projector axis of `side` pixels.
fn inside(x: f64, side: u32) -> bool {
    (-0.5..=f64::from(side) - 0.5).contains(&x)
}

/// One axis of one pixel, decoded.
struct AxisRead {
    /// The position, projector pixels.
    x: f64,
    /// Its predicted deviation.
    sigma: f64,
    /// An XOR code's finest bit was read too close to its threshold for the coarse bits to be
    /// trusted (see `unwrap_from_neighbours`).
    ambiguous: bool,
}

/// An XOR code's finest pair whose difference is under this share of white − black is read
/// too near its edge to trust the coarse bits.
const XOR_CLEAR: f64 = 0.25;

/// One axis of one pixel. `v(k)` reads frame k; the axis's Gray pairs start at `at`, its
/// phase steps follow them.
fn axis(
    v: impl Fn(usize) -> f64,
    at: usize,
    bits: usize,
    side: u32,
    set: &PatternSet,
    opts: &DecodeOptions,
) -> std::result::Result<AxisRead, Fail> {
    let period = set.period;
    let last = at + 2 * (bits - 1);
    let ambiguous =
        set.code == Code::Xor && (v(last) - v(last + 1)).abs() < XOR_CLEAR * (v(0) - v(1));
    let mut gray = 0u32;
    for b in 0..bits {
        gray = (gray << 1) | u32::from(v(at + 2 * b) > v(at + 2 * b + 1));
    }
    if set.code == Code::Xor && gray & 1 == 1 {
        // Every bit but the finest was shown XOR the finest.
        gray ^= ((1u32 << bits) - 1) & !1;
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
    // An ambiguous pixel's half period is chosen again from its neighbours, and checked then.
    if !ambiguous {
        if (x - centre).abs() > 3.0 * p / 8.0 {
            return Err(Fail::Inconsistent);
        }
        if !inside(x, side) {
            return Err(Fail::Outside);
        }
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
    Ok(AxisRead {
        x,
        sigma,
        ambiguous,
    })
}
