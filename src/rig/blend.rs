//! Edge blending. For each projector pixel that lights the wall at P, every other projector
//! that also lights P (P projects inside its image and its own ray reaches the wall there, not
//! something in front) contributes. Each projector's raw weight is a smoothstep of its pixel's
//! distance to its nearest image edge (over half the image's shorter side), so it falls to zero
//! at its edge; the weights are normalised to sum to one at every wall point.
//!
//! The stored mask is in signal space: m = w^(1/γ) with γ = 2.2 by default, so that a media
//! server multiplying the video signal by m yields w in light on a projector with that gamma.
//! The PNG is 16-bit grey with the gamma in a text chunk (`omniwarp.blend_gamma`).

use super::{Channel, Rig};
use crate::error::{Error, Result};
use crate::image_io::atomic_write;
use crate::raster::{Pixel, Raster};
use glam::DVec3;
use rayon::prelude::*;
use std::io::Write;
use std::path::Path;

/// How a blend mask is encoded as a PNG.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BlendOptions {
    /// The projector's gamma γ; the mask stores m = w^(1/γ). Positive, 2.2 by default; 1 is
    /// linear.
    pub gamma: f64,
    /// 8 or 16 bits a sample (MPCDI readers commonly decode 8 only).
    pub bits: u8,
}

impl Default for BlendOptions {
    fn default() -> Self {
        BlendOptions {
            gamma: 2.2,
            bits: 16,
        }
    }
}

fn smoothstep(x: f64) -> f64 {
    let x = x.clamp(0.0, 1.0);
    x * x * (3.0 - 2.0 * x)
}

/// Raw weight of channel `ch` at its pixel q: 0 at the image edge, 1 half a short side inside.
fn edge_weight(ch: &Channel, q: [f64; 2]) -> f64 {
    let (w, h) = (f64::from(ch.width), f64::from(ch.height));
    let d = (q[0] + 0.5)
        .min(w - 0.5 - q[0])
        .min(q[1] + 0.5)
        .min(h - 0.5 - q[1]);
    smoothstep(d / (0.5 * w.min(h)))
}

impl Rig {
    /// Channel `ch`'s pixel showing wall point `p`, if `ch` lights it.
    pub fn pixel_lighting(&self, ch: &Channel, p: DVec3) -> Option<[f64; 2]> {
        let local = ch.rotation.transpose() * (p - ch.position);
        let q = ch.lens.project(local).ok()?;
        let inside = q[0] >= -0.5
            && q[0] <= f64::from(ch.width) - 0.5
            && q[1] >= -0.5
            && q[1] <= f64::from(ch.height) - 0.5;
        if !inside {
            return None;
        }
        // Its own ray must reach the wall at p, not stop at another part of the wall first.
        let dir = (p - ch.position).normalize();
        let hit = self.doc.screen.intersect(ch.position, dir).point()?;
        (hit.distance(p) <= 1e-6 * (1.0 + p.distance(ch.position))).then_some(q)
    }

    /// Every channel lighting wall point `p`, with its blend weight (linear light; they sum to
    /// one).
    pub fn weights_at(&self, p: DVec3) -> Vec<(usize, f64)> {
        let raw: Vec<(usize, f64)> = self
            .channels
            .iter()
            .enumerate()
            .filter_map(|(i, c)| self.pixel_lighting(c, p).map(|q| (i, edge_weight(c, q))))
            .collect();
        let total: f64 = raw.iter().map(|r| r.1).sum();
        let n = raw.len() as f64;
        raw.into_iter()
            .map(|(i, s)| (i, if total > 0.0 { s / total } else { 1.0 / n }))
            .collect()
    }

    /// Blend weights (linear light, summing to one over the channels lighting each wall point)
    /// for every pixel of `ch`, given its wall points (from its warp).
    pub fn blend_weights(&self, ch: &Channel, points: &[Option<DVec3>]) -> Vec<f32> {
        let w = ch.width as usize;
        points
            .par_iter()
            .enumerate()
            .map(|(n, p)| {
                let Some(p) = p else { return 0.0 };
                let own = edge_weight(ch, [(n % w) as f64, (n / w) as f64]);
                let others: f64 = self
                    .channels
                    .iter()
                    .filter(|o| o.id != ch.id)
                    .filter_map(|o| self.pixel_lighting(o, *p).map(|q| edge_weight(o, q)))
                    .sum();
                if own + others <= 0.0 {
                    // At the very edge of every projector lighting it: share equally.
                    let count = 1 + self
                        .channels
                        .iter()
                        .filter(|o| o.id != ch.id && self.pixel_lighting(o, *p).is_some())
                        .count();
                    return (1.0 / count as f64) as f32;
                }
                (own / (own + others)) as f32
            })
            .collect()
    }
}

/// The factor a projector's signal is multiplied by for blend weight `w` (linear light) on a
/// projector of the given gamma: m = w^(1/γ). γ = 1 gives linear output (float renders that a
/// later stage encodes).
pub fn signal_gains(weights: &[f32], gamma: f64) -> Result<Vec<f32>> {
    if !(gamma.is_finite() && gamma > 0.0) {
        return Err(Error::invalid(
            "gamma",
            format!("must be positive, got {gamma}"),
        ));
    }
    Ok(weights
        .par_iter()
        .map(|&w| f64::from(w).powf(1.0 / gamma) as f32)
        .collect())
}

/// Applies a blend to a channel's rendered image: each pixel's colour (not its alpha) is
/// multiplied by its gain from [`signal_gains`]. The image and the gains must be the channel's
/// size, pixel for pixel.
pub fn apply_gains<T: Pixel>(img: &mut Raster<T>, gains: &[f32]) -> Result<()> {
    if gains.len() != img.data.len() {
        return Err(Error::invalid(
            "gains",
            format!(
                "{} values for a {}×{} image",
                gains.len(),
                img.width,
                img.height
            ),
        ));
    }
    img.data
        .par_iter_mut()
        .zip(gains.par_iter())
        .for_each(|(p, &m)| gain(p, m));
    Ok(())
}

/// One pixel of [`apply_gains`]: its colour times `m`, its alpha kept.
#[inline]
pub fn gain<T: Pixel>(p: &mut T, m: f32) {
    // Outside the blend zones the gain is 1 and the pixel stays as it is.
    if m != 1.0 {
        let v = p.to_f32();
        *p = T::from_f32([v[0] * m, v[1] * m, v[2] * m, v[3]]);
    }
}

/// Blend gains (signal space, from [`signal_gains`]) as an 8-bit grey image, for a media
/// server that applies the blend itself.
pub fn gains_image(width: usize, height: usize, gains: &[f32]) -> Raster<[u8; 4]> {
    Raster {
        width,
        height,
        data: gains
            .iter()
            .map(|&g| {
                let v = (g.clamp(0.0, 1.0) * 255.0).round() as u8;
                [v, v, v, 255]
            })
            .collect(),
    }
}

/// Writes blend weights as a grey PNG (16 or 8 bits) in signal space (m = w^(1/γ)).
pub fn write_blend_png(
    path: &Path,
    width: u32,
    height: u32,
    weights: &[f32],
    opts: BlendOptions,
) -> Result<()> {
    let bytes = blend_png_bytes(width, height, weights, opts)?;
    atomic_write(path, |f| {
        f.write_all(&bytes).map_err(|e| Error::file(path, e))
    })
}

/// The PNG of [`write_blend_png`], in memory.
pub fn blend_png_bytes(
    width: u32,
    height: u32,
    weights: &[f32],
    opts: BlendOptions,
) -> Result<Vec<u8>> {
    mask_png_bytes(width, height, weights, opts, "omniwarp.blend_gamma", false)
}

/// Writes a channel's black lift β (linear light) as a grey PNG in signal space, b = β^(1/γ),
/// the way the blend mask is written: a reader applying `colour · m · (1 − b) + b` to the
/// signal (SGCT's black-level mask) puts out β of light where the content is black.
pub fn write_black_png(
    path: &Path,
    width: u32,
    height: u32,
    lift: &[f32],
    opts: BlendOptions,
) -> Result<()> {
    let bytes = black_png_bytes(width, height, lift, opts)?;
    atomic_write(path, |f| {
        f.write_all(&bytes).map_err(|e| Error::file(path, e))
    })
}

/// The PNG of [`write_black_png`], in memory.
pub fn black_png_bytes(
    width: u32,
    height: u32,
    lift: &[f32],
    opts: BlendOptions,
) -> Result<Vec<u8>> {
    mask_png_bytes(width, height, lift, opts, "omniwarp.black_gamma", true)
}

/// Values in 0–1 as a grey PNG of `opts.bits`, raised to 1/γ, the gamma in text chunk `key`;
/// with `dither`, non-zero 8-bit values are dithered as the renderer dithers a lift
/// ([`super::photometry::dither_at`]).
fn mask_png_bytes(
    width: u32,
    height: u32,
    weights: &[f32],
    opts: BlendOptions,
    key: &str,
    dither: bool,
) -> Result<Vec<u8>> {
    if !(opts.gamma.is_finite() && opts.gamma > 0.0) {
        return Err(Error::invalid(
            "gamma",
            format!("must be positive, got {}", opts.gamma),
        ));
    }
    if !matches!(opts.bits, 8 | 16) {
        return Err(Error::invalid(
            "bits",
            format!("must be 8 or 16, got {}", opts.bits),
        ));
    }
    let mut data = Vec::with_capacity(weights.len() * usize::from(opts.bits / 8));
    for (n, &w) in weights.iter().enumerate() {
        let m = f64::from(w.clamp(0.0, 1.0)).powf(1.0 / opts.gamma);
        if opts.bits == 8 {
            let d = if dither && w > 0.0 {
                super::photometry::dither_at(n, width as usize)
            } else {
                0.0
            };
            data.push(((m * 255.0) as f32 + d).round().clamp(0.0, 255.0) as u8);
        } else {
            data.extend_from_slice(&((m * 65535.0).round() as u16).to_be_bytes());
        }
    }
    let mut out = Vec::new();
    let png_err = |e: png::EncodingError| Error::invalid("png", e.to_string());
    {
        let mut enc = png::Encoder::new(&mut out, width, height);
        enc.set_color(png::ColorType::Grayscale);
        enc.set_depth(if opts.bits == 8 {
            png::BitDepth::Eight
        } else {
            png::BitDepth::Sixteen
        });
        enc.add_text_chunk(key.into(), format!("{}", opts.gamma))
            .map_err(png_err)?;
        let mut w = enc.write_header().map_err(png_err)?;
        w.write_image_data(&data).map_err(png_err)?;
        w.finish().map_err(png_err)?;
    }
    Ok(out)
}
