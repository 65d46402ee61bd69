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
use std::ops::Range;

/// Per pixel the view direction N and the interpolated f, `None` where no tile covers it: the
/// whole screen, or rows `top..top + height` of it.
#[derive(Debug, Clone)]
pub struct FeatureMap {
    /// Width in pixels.
    pub width: usize,
    /// Rows held, in pixels (the screen's height for a whole map).
    pub height: usize,
    /// The screen row the first row of `data` is (0 for a whole map).
    pub top: usize,
    /// Per pixel, row by row from `top`: the unit view direction N and the interpolated f, or
    /// `None` where no tile covers it.
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
        self.feature_rows(width, height, 0..height)
    }

    /// Rows `rows` of [`Self::feature_map`], the same values: what a tile edit recomputes
    /// (see [`Self::rows_changed`]). Each pixel is drawn by the same triangles in the same
    /// order whichever rows are asked for.
    pub fn feature_rows(&self, width: usize, height: usize, rows: Range<usize>) -> FeatureMap {
        let rows = rows.start.min(height)..rows.end.min(height);
        let mut map = self.unmasked_rows(width, height, rows.clone());
        if self.source.is_some() {
            let mask = self.mask();
            let (w, h) = (width as f64, height as f64);
            map.data
                .par_chunks_mut(width.max(1))
                .enumerate()
                .for_each(|(r, row)| {
                    let j = rows.start + r;
                    for (i, p) in row.iter_mut().enumerate() {
                        if p.is_some() && !mask((i as f64 + 0.5) / w, (j as f64 + 0.5) / h) {
                            *p = None;
                        }
                    }
                });
        }
        map
    }

    /// The rows of a raster `height` pixels high in which `next`'s feature map can differ
    /// from this screen's: those any changed triangle covers, before or after the change (a
    /// pixel shows the last triangle drawn over it, and only changed triangles changed).
    /// `None` where the screens differ in more than their features' values (the layout's
    /// shape, the source, the interpolation): every row then.
    pub fn rows_changed(&self, next: &TileScreen, height: usize) -> Option<Range<usize>> {
        if self.source != next.source || self.interpolation != next.interpolation {
            return None;
        }
        let (a, b) = (self.corners(), next.corners());
        if a.len() != b.len() || height == 0 {
            return None;
        }
        let mut changed: Option<Range<usize>> = None;
        for (s, t) in a.iter().zip(&b).filter(|(s, t)| s != t) {
            for tri in [s, t] {
                let (y0, y1) = row_extent(tri, height);
                changed = Some(match changed {
                    Some(c) => c.start.min(y0)..c.end.max(y1 + 1),
                    None => y0..y1 + 1,
                });
            }
        }
        Some(changed.unwrap_or(0..0))
    }

    fn unmasked_rows(&self, width: usize, height: usize, rows: Range<usize>) -> FeatureMap {
        if rows.is_empty() {
            return FeatureMap {
                width,
                height: 0,
                top: rows.start,
                data: Vec::new(),
            };
        }
        let (w, h) = (width as f64, height as f64);
        let tris: Vec<Prepared> = self
            .corners()
            .into_iter()
            .filter(|t| t.iter().all(|f| f.valid))
            .map(|mut t| {
                t[1].phi = unwrap_deg(t[1].phi, t[0].phi);
                t[2].phi = unwrap_deg(t[2].phi, t[0].phi);
                let xs = t.map(|f| f.x * w - 0.5);
                let (y0, y1) = row_extent(&t, height);
                Prepared {
                    corners: t,
                    normals: t.map(|f| f.weight * f_normal(f.phi, f.theta, f.scale)),
                    area2: 2.0 * super::signed_area(&t[0], &t[1], &t[2]),
                    x0: lowest(xs),
                    x1: highest(xs, width),
                    y0,
                    y1,
                }
            })
            .filter(|t| t.y0 < rows.end && t.y1 >= rows.start)
            .collect();
        let interpolation = self.interpolation;
        // Which triangles touch each band of rows, in drawing order.
        let mut bands = vec![Vec::new(); rows.len().div_ceil(BAND)];
        for (n, t) in tris.iter().enumerate() {
            let (first, last) = (t.y0.max(rows.start), t.y1.min(rows.end - 1));
            for b in &mut bands[(first - rows.start) / BAND..=(last - rows.start) / BAND] {
                b.push(n);
            }
        }
        let mut data = vec![None; width * rows.len()];
        data.par_chunks_mut((width * BAND).max(1))
            .zip(bands.par_iter())
            .enumerate()
            .for_each(|(b, (band, mine))| {
                let r0 = rows.start + b * BAND;
                let r1 = r0 + band.len() / width;
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
            height: rows.len(),
            top: rows.start,
            data,
        }
    }
}

/// The first and last pixel row (of `height`) a triangle's bounding box reaches.
fn row_extent(t: &[Feature; 3], height: usize) -> (usize, usize) {
    let h = height as f64;
    let ys = t.map(|f| f.y * h - 0.5);
    (lowest(ys), highest(ys, height))
}

fn lowest(v: [f64; 3]) -> usize {
    v.iter().copied().fold(f64::MAX, f64::min).floor().max(0.0) as usize
}

fn highest(v: [f64; 3], n: usize) -> usize {
    (v.iter().copied().fold(f64::MIN, f64::max).ceil().max(0.0) as usize).min(n - 1)
}

impl FeatureMap {
    /// Leaves only the pixels `mask` also covers: a channel's tiles are cut where the
    /// projector's light leaves the wall, which the tile grid only approximates.
    pub fn cut_by(&mut self, mask: &NormalMap) {
        let top = self.top;
        self.data
            .par_chunks_mut(self.width.max(1))
            .enumerate()
            .for_each(|(r, row)| {
                for (i, p) in row.iter_mut().enumerate() {
                    if !mask.covers(i, top + r) {
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
            data: self.data.par_iter().map(normal_pixel).collect(),
        };
        NormalMap::from_pixels(pixels, normal_map_attributes())
            .expect("f_normal gives finite unit vectors")
    }

    /// The custom value f per pixel (1 where nothing is covered).
    pub fn f(&self) -> Vec<f32> {
        self.data.par_iter().map(f_value).collect()
    }

    /// A whole screen's normal map and f with these rows put in: what drawing the whole
    /// screen again would give, when only these rows changed. `None` where the sizes do not
    /// fit.
    pub fn spliced(&self, map: &NormalMap, f: &[f32]) -> Option<(NormalMap, Vec<f32>)> {
        let start = self.top * self.width;
        let end = start + self.data.len();
        if map.width() != self.width || f.len() != map.pixels().data.len() || end > f.len() {
            return None;
        }
        let rows: Vec<[f32; 4]> = self.data.par_iter().map(normal_pixel).collect();
        let map = map.with_rows(self.top, &rows).ok()?;
        let mut f = f.to_vec();
        f[start..end]
            .par_iter_mut()
            .zip(&self.data)
            .for_each(|(v, d)| *v = f_value(d));
        Some((map, f))
    }
}

fn normal_pixel(p: &Option<(DVec3, f64)>) -> [f32; 4] {
    match p {
        Some((n, _)) => [n.x as f32, n.y as f32, n.z as f32, 1.0],
        None => [0.0; 4],
    }
}

fn f_value(p: &Option<(DVec3, f64)>) -> f32 {
    p.map_or(1.0, |(_, f)| f as f32)
}

fn normal_map_attributes() -> Vec<(String, String)> {
    vec![("omniwarp.projection".into(), "tiles".into())]
}

/// Seed 000's Figure 5 effect: saturation scaled by f (0 grey, 1 unchanged), per pixel.
pub fn saturation<T: crate::raster::Pixel>(img: &mut Raster<T>, f: &[f32]) {
    img.data
        .par_iter_mut()
        .zip(f.par_iter())
        .for_each(|(p, &s)| saturate(p, s));
}

/// One pixel of [`saturation`].
#[inline]
pub fn saturate<T: crate::raster::Pixel>(p: &mut T, s: f32) {
    // At full saturation (f ≥ 1, clamped) a pixel stays as it is: y + (r − y) is r to within
    // an ulp, which rounds back to r in 8 bits (and float pixels keep r itself).
    if s < 1.0 {
        let [r, g, b, a] = p.to_f32();
        // Rec. 709 luma: the grey a desaturated pixel falls to.
        let y = 0.2126 * r + 0.7152 * g + 0.0722 * b;
        let s = s.clamp(0.0, 1.0);
        *p = T::from_f32([y + (r - y) * s, y + (g - y) * s, y + (b - y) * s, a]);
    }
}
