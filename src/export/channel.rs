//! A channel's exports assembled from its warp: the per-pixel fields (content u, v; wall X, Y, Z
//! from the eye), grids chosen from a tolerance, and the MPCDI region, Bourke mesh and PFMs built
//! from them. Shared by the CLI and the daemon.

use super::bourke;
use super::bourke::MeshReader;
use super::grid::{self, Chosen, Layout, Reading};
use super::mpcdi::{self, Profile, Reader, Region};
use crate::error::{Error, Result};
use crate::rig::{BlendOptions, black_png_bytes, blend_png_bytes};
use glam::DVec3;
use std::sync::atomic::AtomicBool;

/// What a channel's exports are made from.
pub struct Sources<'a> {
    /// The channel's id; it names the MPCDI region.
    pub id: &'a str,
    /// Projector pixels across; every per-pixel slice is `width` × `height`, rows top first.
    pub width: usize,
    /// Projector pixels down.
    pub height: usize,
    /// Content (u, v), top-left origin, per pixel, continued past the canvas edges (see
    /// [`super::content_uv_unbounded`]); only [0, 1]² is shown.
    pub uv: &'a [Option<[f64; 2]>],
    /// Content image size, pixels: the unit of 2d tolerances.
    pub content_size: [u32; 2],
    /// Wall points, metres, world frame.
    pub points: &'a [Option<DVec3>],
    /// The eye point, metres: a3 exports store wall points relative to it (P − eye).
    pub eye: DVec3,
    /// Linear blend weights per pixel.
    pub weights: &'a [f32],
    /// Black lift β per pixel, linear light, when the rig's projectors have a contrast
    /// (docs/photometry.md): MPCDI regions then carry a beta map.
    pub lift: Option<&'a [f32]>,
    /// Set when the export is no longer wanted: grid searches stop with [`Error::Cancelled`].
    pub cancel: &'a AtomicBool,
}

/// Tolerances: content pixels for 2d fields and meshes, millimetres on the wall for a3.
#[derive(Debug, Clone, Copy)]
pub struct Tolerance(pub f64);

impl Tolerance {
    /// `v` as a tolerance if it is finite and positive; else an error naming `name`.
    pub fn checked(v: f64, name: &str) -> Result<Self> {
        if v.is_finite() && v > 0.0 {
            Ok(Tolerance(v))
        } else {
            Err(Error::invalid(
                name,
                format!("must be a positive number, got {v}"),
            ))
        }
    }

    /// The grid when it meets the tolerance; otherwise an error naming `field` that says what
    /// the finest allowed grid reached, so no export silently misses its promise.
    pub fn met<const N: usize>(self, c: Chosen<N>, field: &str) -> Result<Chosen<N>> {
        if c.max_error <= self.0 {
            return Ok(c);
        }
        Err(Error::invalid(
            field,
            format!(
                "cannot be met: the finest grid allowed ({}×{} nodes, limit {}) reaches {:.4}, \
                 above {}",
                c.grid.columns,
                c.grid.rows,
                crate::limits::EXPORT_NODES,
                c.max_error,
                self.0
            ),
        ))
    }
}

impl Sources<'_> {
    fn a3_field(&self) -> Vec<Option<[f64; 3]>> {
        self.points
            .iter()
            .map(|p| p.map(|p| (p - self.eye).to_array()))
            .collect()
    }

    fn uv_scale(&self) -> [f64; 2] {
        [
            f64::from(self.content_size[0]),
            f64::from(self.content_size[1]),
        ]
    }

    /// Content (x, y) grid of the 2d meaning: B = NaN (no error estimate), NaN where unknown;
    /// samples past the canvas edge keep their (outside [0, 1]) coordinates, alpha hides them.
    pub fn grid_2d(&self, tol: Tolerance) -> Result<(Chosen<2>, Vec<[f32; 3]>)> {
        let c = self.choose_2d(self.uv, self.uv_scale(), Reading::BILINEAR, tol)?;
        let rows = rows_2d(&c);
        Ok((c, rows))
    }

    fn choose_2d(
        &self,
        field: &[Option<[f64; 2]>],
        scale: [f64; 2],
        reading: Reading,
        tol: Tolerance,
    ) -> Result<Chosen<2>> {
        let c = grid::choose(
            field,
            self.width,
            self.height,
            tol.0,
            scale,
            reading,
            self.cancel,
        )?;
        tol.met(c, "tolerance")
    }

    /// The sub-rectangle of the canvas this channel shows, normalised, top-left origin: the
    /// bounding box of its lit pixels' content coordinates, padded by the tolerance and a
    /// content pixel (a reader that cuts the region out and filters it reads that far),
    /// clamped to the canvas. The whole canvas when nothing is shown.
    pub fn region_rect(&self, tol: Tolerance) -> [f64; 4] {
        let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
        for (uv, p) in self.uv.iter().zip(self.points) {
            if let (Some(uv), Some(_)) = (uv, p)
                && super::inside(*uv)
            {
                for c in 0..2 {
                    lo[c] = lo[c].min(uv[c]);
                    hi[c] = hi[c].max(uv[c]);
                }
            }
        }
        if lo[0] > hi[0] {
            return [0.0, 0.0, 1.0, 1.0];
        }
        let scale = self.uv_scale();
        let mut rect = [0.0; 4];
        for c in 0..2 {
            let pad = (tol.0 + 1.0) / scale[c];
            let (a, b) = ((lo[c] - pad).max(0.0), (hi[c] + pad).min(1.0));
            rect[c] = a;
            rect[c + 2] = (b - a).max(1.0 / scale[c]);
        }
        rect
    }

    /// The 2d warp of `reader`: content coordinates relative to `rect` (top-left origin) with v
    /// turned up for readers that measure it from the bottom, sampled where the reader places
    /// nodes; the tolerance stays in content pixels.
    fn grid_2d_in(
        &self,
        rect: [f64; 4],
        reader: Reader,
        tol: Tolerance,
    ) -> Result<(Chosen<2>, Vec<[f32; 3]>)> {
        let [x, y, w, h] = rect;
        let up = reader.v_up();
        let field: Vec<Option<[f64; 2]>> = self
            .uv
            .iter()
            .map(|p| {
                p.map(|[u, v]| {
                    let (u, v) = ((u - x) / w, (v - y) / h);
                    [u, if up { 1.0 - v } else { v }]
                })
            })
            .collect();
        let [sx, sy] = self.uv_scale();
        let c = self.choose_2d(&field, [sx * w, sy * h], reader.reading(), tol)?;
        let rows = rows_2d(&c);
        Ok((c, rows))
    }

    /// Wall X, Y, Z grid of the a3 meaning, metres from the eye, NaN where unknown.
    pub fn grid_a3(&self, tol: Tolerance) -> Result<(Chosen<3>, Vec<[f32; 3]>)> {
        let c = grid::choose(
            &self.a3_field(),
            self.width,
            self.height,
            tol.0,
            [1000.0; 3],
            Reading::BILINEAR,
            self.cancel,
        )?;
        let c = tol.met(c, "tolerance")?;
        let rows = c
            .grid
            .samples
            .iter()
            .map(|s| match s {
                Some(p) => p.map(|v| v as f32),
                None => [f32::NAN; 3],
            })
            .collect();
        Ok((c, rows))
    }

    /// `values` per pixel, zero wherever the profile's field has no value, so players that
    /// extrapolate NaN still show black there.
    fn known(&self, profile: Profile, values: &[f32]) -> Vec<f32> {
        (0..values.len())
            .map(|n| {
                let known = match profile {
                    Profile::TwoD => self.uv[n].is_some_and(super::inside),
                    Profile::A3 => self.points[n].is_some(),
                };
                if known { values[n] } else { 0.0 }
            })
            .collect()
    }

    /// Alpha (blend weights) in signal space, gamma [`mpcdi::ALPHA_GAMMA`] embedded.
    fn alpha_png(&self, profile: Profile, bits: u8) -> Result<Vec<u8>> {
        let (w, h) = (self.width as u32, self.height as u32);
        let w_known = self.known(profile, self.weights);
        blend_png_bytes(w, h, &w_known, mask_options(bits))
    }

    /// Beta (the black lift) in signal space, β^(1/γ) with the alpha map's gamma: readers
    /// add it to the signal, `colour · alpha · (1 − beta) + beta`, so that a black frame puts
    /// out β of light.
    fn beta_png(&self, profile: Profile, bits: u8) -> Result<Option<Vec<u8>>> {
        let Some(lift) = self.lift else {
            return Ok(None);
        };
        let (w, h) = (self.width as u32, self.height as u32);
        black_png_bytes(w, h, &self.known(profile, lift), mask_options(bits)).map(Some)
    }

    /// The channel's MPCDI region for `reader` (alpha map of `alpha_bits`, 8 or 16) and the
    /// worst interpolation error of its grid as that reader interpolates it. A 2d region's
    /// rectangle is its part of the canvas (y measured as the reader measures it), in buffer 0
    /// unless the caller files it under its canvas's; an a3 region's is set when the regions
    /// are laid side by side ([`mpcdi::side_by_side`]).
    pub fn region(
        &self,
        profile: Profile,
        tol: Tolerance,
        alpha_bits: u8,
        reader: Reader,
    ) -> Result<(Region, f64)> {
        let (rect, columns, rows, samples, err) = match profile {
            Profile::TwoD => {
                let rect = self.region_rect(tol);
                let (c, s) = self.grid_2d_in(rect, reader, tol)?;
                let [x, y, w, h] = rect;
                let y = if reader.v_up() { 1.0 - y - h } else { y };
                ([x, y, w, h], c.grid.columns, c.grid.rows, s, c.max_error)
            }
            Profile::A3 => {
                let (c, s) = self.grid_a3(tol)?;
                ([0.0; 4], c.grid.columns, c.grid.rows, s, c.max_error)
            }
        };
        Ok((
            Region {
                id: self.id.to_string(),
                resolution: [self.width as u32, self.height as u32],
                buffer: 0,
                rect,
                warp: (columns, rows, samples),
                alpha_png: self.alpha_png(profile, alpha_bits)?,
                beta_png: self.beta_png(profile, alpha_bits)?,
                alpha_bits,
            },
            err,
        ))
    }

    /// Paul Bourke mesh text with its grid, sized for how `reader` fills a cell (every reader
    /// of this format draws triangles; which diagonal varies) and shaped as it draws grids;
    /// intensity from the blend weight ([`bourke::mesh_text`]).
    /// Readers interpolate the
    /// intensity across each cell, so a node just off the wall, which a cell reaching the wall
    /// draws, takes the weight of the lit pixel nearest it (within a cell) rather than the 0 of
    /// an unlit pixel, which would darken the lit part of the cell. Held, not extrapolated: a
    /// weight's gradient carried over a whole cell overshoots to 0 or past 1.
    pub fn bourke(&self, tol: Tolerance, reader: MeshReader) -> Result<(String, Chosen<2>)> {
        let reading = Reading {
            layout: Layout::Edges,
            cells: reader.cells(),
            shape: reader.shape(),
        };
        let c = self.choose_2d(self.uv, self.uv_scale(), reading, tol)?;
        let (w, h) = (self.width, self.height);
        let (nx, ny) = (c.grid.columns, c.grid.rows);
        let reach = |size: usize, n: usize| (size as f64 / (n.max(2) - 1) as f64).ceil() as i64;
        let (rx, ry) = (reach(w, nx), reach(h, ny));
        let lit = |i: i64, j: i64| {
            (i >= 0 && j >= 0 && (i as usize) < w && (j as usize) < h)
                .then_some((i as usize, j as usize))
                .filter(|&(i, j)| self.points[j * w + i].is_some())
                .map(|(i, j)| f64::from(self.weights[j * w + i]))
        };
        let intensity: Vec<f64> = (0..nx * ny)
            .map(|n| {
                let x = Layout::Edges.position(n % nx, nx, w).round() as i64;
                let y = Layout::Edges.position(n / nx, ny, h).round() as i64;
                if let Some(v) = lit(x.clamp(0, w as i64 - 1), y.clamp(0, h as i64 - 1)) {
                    return v;
                }
                // The nearest lit pixel within a cell, by squared distance.
                let mut best: Option<(i64, f64)> = None;
                for j in y - ry..=y + ry {
                    for i in x - rx..=x + rx {
                        if let Some(v) = lit(i, j) {
                            let d = (i - x).pow(2) + (j - y).pow(2);
                            if best.is_none_or(|(bd, _)| d < bd) {
                                best = Some((d, v));
                            }
                        }
                    }
                }
                best.map_or(0.0, |(_, v)| v)
            })
            .collect();
        let text = bourke::mesh_text(&c.grid, &intensity, self.width as f64 / self.height as f64)?;
        Ok((text, c))
    }
}

/// A 2d grid as PFM samples: B = NaN (no error estimate), NaN where unknown.
fn rows_2d(c: &Chosen<2>) -> Vec<[f32; 3]> {
    c.grid
        .samples
        .iter()
        .map(|s| match s {
            Some([u, v]) => [*u as f32, *v as f32, f32::NAN],
            None => [f32::NAN; 3],
        })
        .collect()
}

/// Grey maps of `bits` with the gamma MPCDI readers expect embedded.
fn mask_options(bits: u8) -> BlendOptions {
    BlendOptions {
        gamma: mpcdi::ALPHA_GAMMA,
        bits,
    }
}
