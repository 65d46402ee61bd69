//! Procedural content defined as functions of direction, for tests, benchmarks and the demo:
//! they can be evaluated exactly at any direction, so a render through any content source can be
//! compared against the truth.

use crate::raster::Raster;
use glam::DVec3;
use rayon::prelude::*;
use std::f64::consts::PI;

/// Which pattern.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Pattern {
    /// Smooth, band-limited and chiral (a mirror image differs): sums of sinusoids in the
    /// direction's coordinates, shortest period about 14°. For comparisons between resamplers,
    /// where hard edges would measure sub-pixel rounding rather than correctness.
    Smooth,
    /// A 10°×10° checkerboard in longitude/latitude with thin (0.5°) meridian lines every 30°:
    /// sharp, to measure how much detail a content source keeps.
    Checker,
}

impl Pattern {
    /// The colour (RGBA, 0–1) seen in unit direction `d`.
    pub fn eval(self, d: DVec3) -> [f32; 4] {
        match self {
            Pattern::Smooth => {
                let s = |v: f64| (0.5 + 0.4 * v.sin()) as f32;
                [
                    s(9.0 * d.x + 14.0 * d.y + 3.0 * d.z),
                    s(-7.0 * d.x + 4.0 * d.y + 17.0 * d.z + 1.0),
                    s(20.0 * d.x - 5.0 * d.z + 2.0 + 6.0 * d.y * d.x),
                    1.0,
                ]
            }
            Pattern::Checker => {
                let lon = d.x.atan2(-d.z).to_degrees();
                let lat = d.y.atan2(d.x.hypot(d.z)).to_degrees();
                let cell = ((lon / 10.0).floor() + (lat / 10.0).floor()) as i64;
                let v = if cell.rem_euclid(2) == 0 { 0.85 } else { 0.15 };
                // Distance to the nearest 30° meridian, measured along the parallel.
                let m = (lon / 30.0 - (lon / 30.0).round()).abs() * 30.0 * lat.to_radians().cos();
                if m < 0.25 {
                    [1.0, 0.1, 0.1, 1.0]
                } else {
                    [v as f32, v as f32, (0.3 + 0.4 * v) as f32, 1.0]
                }
            }
        }
    }

    /// A full 360°×180° equirectangular image of the pattern, each pixel the mean of `ss` × `ss`
    /// samples. `centres_at_edges` follows ffmpeg v360's equirect input convention instead of
    /// the one of docs/conventions.md: the centres of the first and last columns (rows) lie at
    /// ±180° (±90°), so a pixel spans 360°/(W − 1) rather than 360°/W.
    pub fn equirect(
        self,
        width: usize,
        height: usize,
        ss: usize,
        centres_at_edges: bool,
    ) -> Raster<[f32; 4]> {
        // Pixel x covers [x, x + 1) in units of `du`, starting at `u0`.
        let (du, dv, u0, v0) = if centres_at_edges {
            let (w, h) = ((width - 1).max(1) as f64, (height - 1).max(1) as f64);
            (1.0 / w, 1.0 / h, -0.5 / w, -0.5 / h)
        } else {
            (1.0 / width as f64, 1.0 / height as f64, 0.0, 0.0)
        };
        let rows: Vec<Vec<[f32; 4]>> = (0..height)
            .into_par_iter()
            .map(|y| {
                (0..width)
                    .map(|x| {
                        let mut acc = [0.0f32; 4];
                        for a in 0..ss {
                            for b in 0..ss {
                                let u = u0 + (x as f64 + (a as f64 + 0.5) / ss as f64) * du;
                                let v = v0 + (y as f64 + (b as f64 + 0.5) / ss as f64) * dv;
                                let (lon, lat) = ((u - 0.5) * 2.0 * PI, (0.5 - v) * PI);
                                let d = DVec3::new(
                                    lat.cos() * lon.sin(),
                                    lat.sin(),
                                    -lat.cos() * lon.cos(),
                                );
                                for (a, c) in acc.iter_mut().zip(self.eval(d)) {
                                    *a += c;
                                }
                            }
                        }
                        acc.map(|a| a / (ss * ss) as f32)
                    })
                    .collect()
            })
            .collect();
        Raster {
            width,
            height,
            data: rows.into_iter().flatten().collect(),
        }
    }
}
