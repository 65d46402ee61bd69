//! Exports for media servers (docs/formats.md): ST-map EXR (R = u, G = v in [0, 1] of the content
//! image, origin bottom-left, A = 0 where unmapped), PFM (3-channel, little-endian, rows bottom
//! to top on disk; the a3 meaning — wall XYZ per pixel, NaN where there is none) and ffmpeg's
//! `remap` xmap/ymap (16-bit PGM of absolute content pixel columns and rows; 65535 where
//! unmapped, which `remap` fills).
//!
//! Content coordinates come from the content canvas: a projection and view whose inverse turns
//! each sampling vector into a position on the content image.

pub mod bourke;
pub mod channel;
pub mod grid;
pub mod mpcdi;

use crate::error::{Error, Result};
use crate::image_io::{Precision, atomic_write, write_exr_rgba};
use crate::normalmap::NormalMap;
use crate::projection::View;
use crate::projection::view::pixel_of_screen;
use crate::raster::Raster;
use rayon::prelude::*;
use std::io::Write;
use std::path::Path;

/// Content image coordinates (u, v) ∈ [0, 1]², top-left origin, of every warp pixel; `None`
/// where the pixel is invalid or its direction falls outside the canvas.
pub fn content_uv(map: &NormalMap, canvas: &View) -> Vec<Option<[f64; 2]>> {
    content_uv_unbounded(map, canvas)
        .into_iter()
        .map(|p| p.filter(|&uv| inside(uv)))
        .collect()
}

/// Whether content coordinates (u, v) lie on the content image, [0, 1]² edges included.
pub fn inside([u, v]: [f64; 2]) -> bool {
    (0.0..=1.0).contains(&u) && (0.0..=1.0).contains(&v)
}

/// [`content_uv`] continued past the canvas edges wherever the canvas projection still maps the
/// direction (grids interpolate across the edge smoothly; alpha hides what lies outside).
pub fn content_uv_unbounded(map: &NormalMap, canvas: &View) -> Vec<Option<[f64; 2]>> {
    let w = map.width();
    (0..w * map.height())
        .into_par_iter()
        .map(|n| {
            let v = map.direction(n % w, n / w)?;
            let (s, t) = canvas.screen(v).ok()?;
            let (x, y) = pixel_of_screen(s, t, 1, 1);
            Some([x, y])
        })
        .collect()
}

/// ST-map: R = u, G = 1 − v (origin bottom-left), B = 0, A = 1 where mapped.
pub fn stmap(uv: &[Option<[f64; 2]>], width: usize, height: usize) -> Raster<[f32; 4]> {
    Raster {
        width,
        height,
        data: uv
            .iter()
            .map(|p| match p {
                Some([u, v]) => [*u as f32, (1.0 - v) as f32, 0.0, 1.0],
                None => [0.0; 4],
            })
            .collect(),
    }
}

/// Writes the [`stmap`] of `uv` (a `width` × `height` grid, rows top to bottom) as a 32-bit
/// float EXR, with the attribute `omniwarp.export` saying the origin is bottom-left.
pub fn write_stmap(
    path: &Path,
    uv: &[Option<[f64; 2]>],
    width: usize,
    height: usize,
) -> Result<()> {
    let attrs = vec![(
        "omniwarp.export".to_string(),
        "stmap (origin bottom-left)".to_string(),
    )];
    write_exr_rgba(path, &stmap(uv, width, height), &attrs, Precision::Float)
}

/// A 3-channel PFM (little-endian, rows bottom to top on disk) of rows given top to bottom.
pub fn pfm_bytes(width: usize, height: usize, rows_top_down: &[[f32; 3]]) -> Result<Vec<u8>> {
    if rows_top_down.len() != width * height {
        return Err(Error::invalid(
            "pfm",
            format!(
                "{width}×{height} needs {} samples, got {}",
                width * height,
                rows_top_down.len()
            ),
        ));
    }
    let mut bytes = format!("PF\n{width} {height}\n-1.0\n").into_bytes();
    for row in (0..height).rev() {
        for px in &rows_top_down[row * width..(row + 1) * width] {
            for c in px {
                bytes.extend_from_slice(&c.to_le_bytes());
            }
        }
    }
    Ok(bytes)
}

/// Writes [`pfm_bytes`] to `path`, atomically.
pub fn write_pfm(
    path: &Path,
    width: usize,
    height: usize,
    rows_top_down: &[[f32; 3]],
) -> Result<()> {
    let bytes = pfm_bytes(width, height, rows_top_down)?;
    atomic_write(path, |f| {
        f.write_all(&bytes).map_err(|e| Error::file(path, e))
    })
}

/// Reads a PFM (`PF` or `Pf`, either byte order) into rows top to bottom, 3 channels each
/// (a grey file repeats its one channel).
pub fn read_pfm(path: &Path) -> Result<(usize, usize, Vec<[f32; 3]>)> {
    let bytes = std::fs::read(path).map_err(|e| Error::file(path, e))?;
    parse_pfm(&bytes, &path.display().to_string())
}

/// [`read_pfm`] of bytes in memory; `name` says where they came from in errors.
pub fn parse_pfm(bytes: &[u8], name: &str) -> Result<(usize, usize, Vec<[f32; 3]>)> {
    let bad = |why: &str| Error::invalid(name, format!("not a PFM file: {why}"));
    let mut fields = Vec::new();
    let mut at = 0;
    while fields.len() < 4 {
        while at < bytes.len() && bytes[at].is_ascii_whitespace() {
            at += 1;
        }
        let start = at;
        while at < bytes.len() && !bytes[at].is_ascii_whitespace() {
            at += 1;
        }
        if start == at {
            return Err(bad("the header ends early"));
        }
        fields.push(String::from_utf8_lossy(&bytes[start..at]).into_owned());
    }
    at += 1; // the single whitespace byte after the scale
    let channels = match fields[0].as_str() {
        "PF" => 3,
        "Pf" => 1,
        _ => return Err(bad("the magic is neither PF nor Pf")),
    };
    let parse = |s: &str| {
        s.parse::<usize>()
            .map_err(|_| bad("width or height is not a number"))
    };
    let (w, h) = (parse(&fields[1])?, parse(&fields[2])?);
    let scale: f64 = fields[3]
        .parse()
        .map_err(|_| bad("the scale is not a number"))?;
    let need = w
        .checked_mul(h)
        .and_then(|n| n.checked_mul(channels * 4))
        .ok_or_else(|| bad("the size overflows"))?;
    if bytes.len() < at.saturating_add(need) {
        return Err(bad("the samples end early"));
    }
    let sample = |i: usize| {
        let b: [u8; 4] = bytes[at + 4 * i..at + 4 * i + 4]
            .try_into()
            .expect("four bytes");
        if scale < 0.0 {
            f32::from_le_bytes(b)
        } else {
            f32::from_be_bytes(b)
        }
    };
    let mut rows = vec![[0.0f32; 3]; w * h];
    for r in 0..h {
        // Row r on disk is image row h − 1 − r.
        for x in 0..w {
            let i = (r * w + x) * channels;
            let v = if channels == 3 {
                [sample(i), sample(i + 1), sample(i + 2)]
            } else {
                [sample(i); 3]
            };
            rows[(h - 1 - r) * w + x] = v;
        }
    }
    Ok((w, h, rows))
}

/// The a3 meaning: wall XYZ per pixel, NaN where the pixel lights no wall.
pub fn a3_samples(points: &[Option<glam::DVec3>]) -> Vec<[f32; 3]> {
    points
        .iter()
        .map(|p| match p {
            Some(p) => [p.x as f32, p.y as f32, p.z as f32],
            None => [f32::NAN; 3],
        })
        .collect()
}

/// ffmpeg `remap` maps: absolute content columns (xmap) and rows (ymap), nearest pixel.
pub fn write_remap_pgm(
    xmap: &Path,
    ymap: &Path,
    uv: &[Option<[f64; 2]>],
    width: usize,
    height: usize,
    content: [u32; 2],
) -> Result<()> {
    let [cw, ch] = content;
    if cw == 0 || ch == 0 || cw > 65535 || ch > 65535 {
        return Err(Error::invalid(
            "content-size",
            format!("must be between 1 and 65535 pixels each way, got {cw}×{ch}"),
        ));
    }
    for (path, axis, n) in [(xmap, 0, cw), (ymap, 1, ch)] {
        let bytes = remap_pgm_bytes(uv, width, height, axis, n);
        atomic_write(path, |f| {
            f.write_all(&bytes).map_err(|e| Error::file(path, e))
        })?;
    }
    Ok(())
}

/// One ffmpeg `remap` map: content columns (`axis` 0) or rows (1) of an `n`-pixel axis as
/// 16-bit PGM, nearest pixel, 65535 where unmapped.
pub fn remap_pgm_bytes(
    uv: &[Option<[f64; 2]>],
    width: usize,
    height: usize,
    axis: usize,
    n: u32,
) -> Vec<u8> {
    let n = f64::from(n.max(1));
    let mut bytes = format!("P5\n{width} {height}\n65535\n").into_bytes();
    for p in uv {
        let v = p.map_or(65535u16, |q| {
            (q[axis] * n - 0.5).round().clamp(0.0, n - 1.0) as u16
        });
        bytes.extend_from_slice(&v.to_be_bytes());
    }
    bytes
}
