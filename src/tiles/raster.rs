//! Tile screen → feature map → normal map, on the CPU, as the GPU pipeline of seed 000 does it.
//!
//! **Interpolation.** The paper draws each tile as a quad whose corners are the features'
//! (x, y) in an orthographic parallel projection and lets the rasteriser interpolate the
//! per-vertex angles, scale and f "hyperbolically" (perspective-correctly). In an orthographic
//! projection every vertex has w = 1, so perspective-correct interpolation is exactly linear
//! (barycentric) interpolation within each triangle; a quad is two triangles split along its
//! (k, l)–(k+1, l+1) diagonal, as a GPU draws it. We do exactly that. Before interpolating, the
//! longitudes of a triangle's corners are unwrapped (shifted by whole turns to within 180° of
//! the first corner), so a tile whose features straddle ±180° does not sweep the long way round.
//!
//! Seed 000 interpolates the angles ([`Interpolation::Angles`]); near a pole, where φ is
//! undefined and swings through 180° within a tile, that fails however fine the grid (the test
//! `seed_weaknesses_are_measured` records by how much), so screens sampled from projections
//! interpolate the corners' unit directions instead and normalise ([`Interpolation::Vectors`]).
//!
//! **f_normal.** The extraction of seed 000 shows N = f_normal(A) as the unit vector (0, 0, 1)
//! turned by R_x(θ) and R_y(φ), next to a vector (s, t, 0). We read the first part as the
//! normal: the interpolated angles give the view direction. We read (s, t, 0) as the screen
//! position F of the following sentence ("δT(F·s) = N"), not as a summand: adding a screen
//! position to a unit direction would make the normal depend on where a tile sits on screen
//! rather than on its features, and no tile screen sampled from a projection could then
//! reproduce it. With docs/conventions.md's frame (−z ahead, +y up) and φ as longitude, θ as
//! latitude:
//!
//!   N = (cos θ'·sin φ', sin θ', −cos θ'·cos φ'),  φ' = φ·scale, θ' = θ·scale,
//!
//! i.e. R_y(−φ')·R_x(θ')·(0, 0, −1): latitude first, then longitude, so that a column of
//! features at one φ is a meridian (the paper's order R_x·R_y would make constant-θ rows tilt).
//! `scale` zooms the angles about the view axis, which is δP(F·scale) for every projection whose
//! angles are linear in F (equirect, and cylinders horizontally).

use super::{Feature, Interpolation, TileScreen};
use crate::normalmap::NormalMap;
use crate::raster::Raster;
use glam::DVec3;
use rayon::prelude::*;

/// Per pixel the view direction N and the interpolated f, `None` where no tile covers it.
#[derive(Debug, Clone)]
pub struct FeatureMap {
    pub width: usize,
    pub height: usize,
    pub data: Vec<Option<(DVec3, f64)>>,
}

/// The view direction of interpolated features.
#[inline]
pub fn f_normal(phi_deg: f64, theta_deg: f64, scale: f64) -> DVec3 {
    let (phi, theta) = (
        (phi_deg * scale).to_radians(),
        (theta_deg * scale).to_radians(),
    );
    let (st, ct) = theta.sin_cos();
    DVec3::new(ct * phi.sin(), st, -ct * phi.cos())
}

/// Longitude and latitude (degrees) of a direction, longitude 0 at the poles.
pub fn angles(d: DVec3) -> (f64, f64) {
    let rho = d.x.hypot(d.z);
    let phi = if rho == 0.0 { 0.0 } else { d.x.atan2(-d.z) };
    (phi.to_degrees(), d.y.atan2(rho).to_degrees())
}

/// `v` shifted by whole turns to within 180° of `reference`.
pub fn unwrap_deg(v: f64, reference: f64) -> f64 {
    v - 360.0 * ((v - reference) / 360.0).round()
}

const BAND: usize = 16;

struct Prepared {
    corners: [Feature; 3],
    normals: [DVec3; 3],
    area2: f64,
    y0: usize,
    y1: usize,
    x0: usize,
    x1: usize,
}

impl TileScreen {
    /// Whether the screen's source shows anything at screen position (x, y): the mask of the
    /// projection it was sampled from (a fisheye's image circle), true without a source. Tiles
    /// are drawn past the edge (see [`super::Feature::outside`]); this is where they are cut.
    pub fn mask(&self) -> impl Fn(f64, f64) -> bool + Sync + '_ {
        let view = self.source.as_ref().and_then(|s| s.view().ok());
        move |x, y| {
            view.as_ref()
                .is_none_or(|v| v.direction(2.0 * x - 1.0, 1.0 - 2.0 * y).is_ok())
        }
    }

    /// Rasterises the tile screen at width × height pixel centres, cut by its [`Self::mask`].
    pub fn feature_map(&self, width: usize, height: usize) -> FeatureMap {
        let mut map = self.unmasked_feature_map(width, height);
        if self.source.is_some() {
            let mask = self.mask();
            let (w, h) = (width as f64, height as f64);
            map.data
                .par_chunks_mut(width)
                .enumerate()
                .for_each(|(j, row)| {
                    for (i, p) in row.iter_mut().enumerate() {
                        if p.is_some() && !mask((i as f64 + 0.5) / w, (j as f64 + 0.5) / h) {
                            *p = None;
                        }
                    }
                });
        }
        map
    }

    fn unmasked_feature_map(&self, width: usize, height: usize) -> FeatureMap {
        let (w, h) = (width as f64, height as f64);
        let tris: Vec<Prepared> = self
            .triangles()
            .into_iter()
            .filter(|(t, _)| t.iter().all(|f| f.valid))
            .map(|(mut t, _)| {
                t[1].phi = unwrap_deg(t[1].phi, t[0].phi);
                t[2].phi = unwrap_deg(t[2].phi, t[0].phi);
                let xs = t.map(|f| f.x * w - 0.5);
                let ys = t.map(|f| f.y * h - 0.5);
                let lo = |v: [f64; 3]| {
                    v.iter().copied().fold(f64::MAX, f64::min).floor().max(0.0) as usize
                };
                let hi = |v: [f64; 3], n: usize| {
                    (v.iter().copied().fold(f64::MIN, f64::max).ceil().max(0.0) as usize).min(n - 1)
                };
                Prepared {
                    corners: t,
                    normals: t.map(|f| f.weight * f_normal(f.phi, f.theta, f.scale)),
                    area2: 2.0 * super::signed_area(&t[0], &t[1], &t[2]),
                    x0: lo(xs),
                    x1: hi(xs, width),
                    y0: lo(ys),
                    y1: hi(ys, height),
                }
            })
            .collect();
        let interpolation = self.interpolation;
        // Which triangles touch each band of rows, in drawing order.
        let mut bands = vec![Vec::new(); height.div_ceil(BAND)];
        for (n, t) in tris.iter().enumerate() {
            for b in bands.iter_mut().take(t.y1 / BAND + 1).skip(t.y0 / BAND) {
                b.push(n);
            }
        }
        let mut data = vec![None; width * height];
        data.par_chunks_mut(width * BAND)
            .zip(bands.par_iter())
            .enumerate()
            .for_each(|(b, (band, mine))| {
                let (r0, r1) = (b * BAND, b * BAND + band.len() / width);
                for t in mine.iter().map(|&n| &tris[n]) {
                    let [a, bb, c] = &t.corners;
                    for j in t.y0.max(r0)..=t.y1.min(r1 - 1) {
                        let py = (j as f64 + 0.5) / h;
                        for i in t.x0..=t.x1 {
                            let px = (i as f64 + 0.5) / w;
                            // Barycentric weights from edge functions, in the triangle's orientation.
                            let e = |p: &Feature, q: &Feature| {
                                (q.x - p.x) * (py - p.y) - (q.y - p.y) * (px - p.x)
                            };
                            let (wa, wb, wc) =
                                (e(bb, c) / t.area2, e(c, a) / t.area2, e(a, bb) / t.area2);
                            // Inclusive edges (with rounding slack) leave no gap between neighbours.
                            if wa < -1e-12 || wb < -1e-12 || wc < -1e-12 {
                                continue;
                            }
                            let mix = |f: fn(&Feature) -> f64| wa * f(a) + wb * f(bb) + wc * f(c);
                            let n = match interpolation {
                                Interpolation::Angles => {
                                    f_normal(mix(|f| f.phi), mix(|f| f.theta), mix(|f| f.scale))
                                }
                                Interpolation::Vectors => {
                                    (wa * t.normals[0] + wb * t.normals[1] + wc * t.normals[2])
                                        .normalize()
                                }
                            };
                            band[(j - r0) * width + i] = Some((n, mix(|f| f.f)));
                        }
                    }
                }
            });
        FeatureMap {
            width,
            height,
            data,
        }
    }
}

impl FeatureMap {
    /// Leaves only the pixels `mask` also covers: a channel's tiles are cut where the
    /// projector's light leaves the wall, which the tile grid only approximates.
    pub fn cut_by(&mut self, mask: &NormalMap) {
        self.data
            .par_chunks_mut(self.width)
            .enumerate()
            .for_each(|(j, row)| {
                for (i, p) in row.iter_mut().enumerate() {
                    if !mask.covers(i, j) {
                        *p = None;
                    }
                }
            });
    }

    /// The normal map: N = f_normal(φ, θ, scale) where a tile covers the pixel.
    pub fn normal_map(&self) -> NormalMap {
        let pixels = Raster {
            width: self.width,
            height: self.height,
            data: self
                .data
                .par_iter()
                .map(|p| match p {
                    Some((n, _)) => [n.x as f32, n.y as f32, n.z as f32, 1.0],
                    None => [0.0; 4],
                })
                .collect(),
        };
        NormalMap::from_pixels(pixels, vec![("omniwarp.projection".into(), "tiles".into())])
            .expect("f_normal gives finite unit vectors")
    }

    /// The custom value f per pixel (1 where nothing is covered).
    pub fn f(&self) -> Vec<f32> {
        self.data
            .par_iter()
            .map(|p| p.map_or(1.0, |(_, f)| f as f32))
            .collect()
    }
}

/// Seed 000's Figure 5 effect: saturation scaled by f (0 grey, 1 unchanged), per pixel.
pub fn saturation<T: crate::raster::Pixel>(img: &mut Raster<T>, f: &[f32]) {
    img.data
        .par_iter_mut()
        .zip(f.par_iter())
        // At full saturation (f ≥ 1, clamped) a pixel stays as it is: y + (r − y) is r to
        // within an ulp, which rounds back to r in 8 bits (and float pixels keep r itself).
        .filter(|(_, s)| **s < 1.0)
        .for_each(|(p, &s)| {
            let [r, g, b, a] = p.to_f32();
            // Rec. 709 luma: the grey a desaturated pixel falls to.
            let y = 0.2126 * r + 0.7152 * g + 0.0722 * b;
            let s = s.clamp(0.0, 1.0);
            *p = T::from_f32([y + (r - y) * s, y + (g - y) * s, y + (b - y) * s, a]);
        });
}
