//! Normal maps (warp maps): per output pixel the unit sampling vector V in world coordinates and
//! its validity, stored as OpenEXR with R, G, B = V and A = 1 where valid, 0 where nothing is
//! shown (docs/conventions.md). Text attributes in the header say what the map is for:
//! `omniwarp.projection`, `omniwarp.channel`, `omniwarp.rig_revision` and the like.
//!
//! 32-bit float files round-trip bit-exactly. Half-float files are a third of the size; the
//! angle between a stored and the true vector is then at most about 0.03° (measured by the
//! test `half_precision_error_is_bounded`: half floats carry 11 significant bits, so each
//! component is off by up to 2⁻¹² relative).

use crate::error::{Error, Result};
use crate::image_io::{Precision, read_exr_rgba, write_exr_rgba};
use crate::projection::View;
use crate::projection::view::screen_of_pixel;
use crate::raster::Raster;
use glam::DVec3;
use rayon::prelude::*;
use std::path::Path;

/// A per-pixel map of sampling vectors.
#[derive(Debug, Clone, PartialEq)]
pub struct NormalMap {
    pixels: Raster<[f32; 4]>,
    /// Header attributes, `omniwarp.*` names.
    pub attributes: Vec<(String, String)>,
}

/// Largest deviation of a stored vector's length from 1 accepted on reading (half floats
/// round components by up to 2⁻¹¹ relative).
const UNIT_TOLERANCE: f32 = 2e-3;

/// The first bad pixel of `rows` (`width` wide, the first of them row `top` of the map), as
/// the reason to report; rows are checked in parallel (a 4K map is 8 million pixels).
fn first_problem(rows: &[[f32; 4]], width: usize, top: usize) -> Option<String> {
    use rayon::prelude::*;
    rows.par_chunks(width.max(1))
        .enumerate()
        .find_map_first(|(r, row)| {
            row.iter().enumerate().find_map(|(i, p)| {
                let problem = pixel_problem(p)?;
                Some(format!("pixel ({i}, {}) {problem}", top + r))
            })
        })
}

/// What is wrong with a normal-map pixel, if anything.
fn pixel_problem(p: &[f32; 4]) -> Option<String> {
    if p.iter().any(|c| !c.is_finite()) {
        return Some(format!("holds a non-finite value {p:?}"));
    }
    if !(0.0..=1.0).contains(&p[3]) {
        return Some(format!("has validity A = {} outside [0, 1]", p[3]));
    }
    let len = (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt();
    if p[3] > 0.5 && (len - 1.0).abs() > UNIT_TOLERANCE {
        return Some(format!("is marked valid but its vector has length {len}"));
    }
    None
}

impl NormalMap {
    /// Samples a view at every pixel centre of a width × height image.
    pub fn from_view(view: &View, width: u32, height: u32) -> Result<Self> {
        crate::raster::check_size(width, height, 1)?;
        let (w, h) = (width as usize, height as usize);
        let mut pixels = Raster::new(w, h);
        pixels
            .data
            .par_chunks_mut(w)
            .enumerate()
            .for_each(|(j, row)| {
                for (i, px) in row.iter_mut().enumerate() {
                    let (s, t) = screen_of_pixel(i as f64 + 0.5, j as f64 + 0.5, width, height);
                    *px = match view.direction(s, t) {
                        Ok(v) => [v.x as f32, v.y as f32, v.z as f32, 1.0],
                        Err(_) => [0.0; 4],
                    };
                }
            });
        Ok(NormalMap {
            pixels,
            attributes: vec![(
                "omniwarp.projection".into(),
                view.projection().name().into(),
            )],
        })
    }

    /// Wraps raw pixels, checking every one: finite, A ∈ [0, 1], unit vector where valid.
    pub fn from_pixels(
        pixels: Raster<[f32; 4]>,
        attributes: Vec<(String, String)>,
    ) -> Result<Self> {
        match first_problem(&pixels.data, pixels.width, 0) {
            Some(reason) => Err(Error::invalid("normal-map", reason)),
            None => Ok(NormalMap { pixels, attributes }),
        }
    }

    /// This map with its rows from `top` on replaced by `rows` (as wide as the map), which
    /// are checked as [`NormalMap::from_pixels`] checks a map; the rest is copied as it is.
    pub fn with_rows(&self, top: usize, rows: &[[f32; 4]]) -> Result<Self> {
        let w = self.pixels.width.max(1);
        let start = top * w;
        if !rows.len().is_multiple_of(w) || start + rows.len() > self.pixels.data.len() {
            return Err(Error::invalid(
                "normal-map",
                format!(
                    "{} values from row {top} do not fit a {}×{} map",
                    rows.len(),
                    self.pixels.width,
                    self.pixels.height
                ),
            ));
        }
        if let Some(reason) = first_problem(rows, w, top) {
            return Err(Error::invalid("normal-map", reason));
        }
        // Copied in parallel, a band of rows a task: a 1080p map is 33 MB.
        let old = &self.pixels.data;
        let end = start + rows.len();
        let mut data = Vec::with_capacity(old.len());
        data.spare_capacity_mut()[..old.len()]
            .par_chunks_mut(w * 64)
            .enumerate()
            .for_each(|(b, out)| {
                let at = b * w * 64;
                for (n, o) in out.iter_mut().enumerate() {
                    let k = at + n;
                    o.write(if (start..end).contains(&k) {
                        rows[k - start]
                    } else {
                        old[k]
                    });
                }
            });
        // SAFETY: every element of the first `old.len()` was written above.
        unsafe { data.set_len(old.len()) };
        Ok(NormalMap {
            pixels: Raster {
                width: self.pixels.width,
                height: self.pixels.height,
                data,
            },
            attributes: self.attributes.clone(),
        })
    }

    /// The map's width, pixels.
    pub fn width(&self) -> usize {
        self.pixels.width
    }

    /// The map's height, pixels.
    pub fn height(&self) -> usize {
        self.pixels.height
    }

    /// The raw pixels, top row first: R, G, B = V and A the validity (1 shown, 0 not).
    pub fn pixels(&self) -> &Raster<[f32; 4]> {
        &self.pixels
    }

    /// The unit sampling vector of pixel (i, j), `None` where invalid or outside the map.
    #[inline]
    pub fn direction(&self, i: usize, j: usize) -> Option<DVec3> {
        if i >= self.pixels.width || j >= self.pixels.height {
            return None;
        }
        let [x, y, z, a] = self.pixels.get(i, j);
        (a > 0.5).then(|| DVec3::new(x.into(), y.into(), z.into()).normalize())
    }

    /// Whether pixel (i, j) holds a vector: [`NormalMap::direction`] without the arithmetic.
    #[inline]
    pub fn covers(&self, i: usize, j: usize) -> bool {
        i < self.pixels.width && j < self.pixels.height && self.pixels.get(i, j)[3] > 0.5
    }

    /// Writes the map as an OpenEXR file with its attributes, atomically (see
    /// [`crate::image_io::atomic_write`]).
    pub fn write(&self, path: &Path, precision: Precision) -> Result<()> {
        write_exr_rgba(path, &self.pixels, &self.attributes, precision)
    }

    /// Reads an OpenEXR normal map with its text attributes, checking every pixel as
    /// [`NormalMap::from_pixels`] does.
    pub fn read(path: &Path) -> Result<Self> {
        let (pixels, attributes) = read_exr_rgba(path)?;
        Self::from_pixels(pixels, attributes).map_err(|e| Error::file(path, e))
    }
}
