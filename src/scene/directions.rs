//! The directions a piecewise perspective cut approximates (`ppp.rs`): a view at an output
//! size, or a projector channel's warp map, each read at any pixel position, with the
//! output's typical pixel pitch.

use crate::error::Result;
use crate::normalmap::NormalMap;
use crate::projection::View;
use crate::projection::view::screen_of_pixel;
use glam::DVec3;

/// The directions a cut approximates, at pixel positions of an output: a view at a size, or a
/// projector channel's warp map.
pub trait Directions: Sync {
    /// The output's size in pixels.
    fn size(&self) -> (u32, u32);
    /// The unit direction at pixel position (x, y), and whether it is the output's own there:
    /// `false` where the position lies outside the output's domain, the direction (if any)
    /// then continued past its edge.
    fn at(&self, x: f64, y: f64) -> (Option<DVec3>, bool);
    /// How corner directions are scaled so that the usual pieces are parallelograms.
    fn scale(&self) -> Scale {
        Scale::Unit
    }

    /// For a position outside the domain: the output's field continued there from its own
    /// directions within `radius` pixels, where that is better than [`Directions::at`]'s.
    fn continued(&self, _x: f64, _y: f64, _radius: u32) -> Option<DVec3> {
        None
    }
}

/// A view at an output size.
pub struct ViewAt<'a> {
    view: &'a View,
    width: u32,
    height: u32,
}

impl<'a> ViewAt<'a> {
    /// `view` at a `width` × `height` output; an error when the size is not one the renderer
    /// takes ([`crate::raster::check_size`]).
    pub fn new(view: &'a View, width: u32, height: u32) -> Result<ViewAt<'a>> {
        crate::raster::check_size(width, height, 1)?;
        Ok(ViewAt::sized(view, width, height))
    }

    /// [`ViewAt::new`] for a size already checked.
    pub(super) fn sized(view: &'a View, width: u32, height: u32) -> ViewAt<'a> {
        ViewAt {
            view,
            width,
            height,
        }
    }
}

impl Directions for ViewAt<'_> {
    fn size(&self) -> (u32, u32) {
        (self.width, self.height)
    }

    fn at(&self, x: f64, y: f64) -> (Option<DVec3>, bool) {
        let (s, t) = screen_of_pixel(x, y, self.width, self.height);
        match self.view.direction(s, t) {
            Ok(d) => (Some(d), true),
            Err(_) => (self.view.direction_unbounded(s, t).ok(), false),
        }
    }

    fn scale(&self) -> Scale {
        Scale::of(self.view)
    }
}

/// A warp map's directions sit at pixel centres; between them they are interpolated
/// bilinearly (and renormalised), as a reader of the map would. Where some of the four
/// neighbours are unmapped (the wall's edge in the projector image) the position is outside
/// the domain: [`Directions::at`] averages the mapped ones, and [`Directions::continued`]
/// extends the field by a quadratic fitted to the mapped pixels nearest to it, so that a piece
/// reaching past the edge still shows the pixels inside it as the map does.
impl Directions for NormalMap {
    fn size(&self) -> (u32, u32) {
        (self.width() as u32, self.height() as u32)
    }

    fn at(&self, x: f64, y: f64) -> (Option<DVec3>, bool) {
        let (w, h) = (self.width() as f64, self.height() as f64);
        let (u, v) = ((x - 0.5).clamp(0.0, w - 1.0), (y - 0.5).clamp(0.0, h - 1.0));
        let (i, j) = (u.floor(), v.floor());
        let (fx, fy) = (u - i, v - j);
        let (i, j) = (i as usize, j as usize);
        let mut sum = DVec3::ZERO;
        let mut own = true;
        for (di, dj, k) in [
            (0, 0, (1.0 - fx) * (1.0 - fy)),
            (1, 0, fx * (1.0 - fy)),
            (0, 1, (1.0 - fx) * fy),
            (1, 1, fx * fy),
        ] {
            if k == 0.0 {
                continue;
            }
            match self.direction(i + di, j + dj) {
                Some(d) => sum += k * d,
                None => own = false,
            }
        }
        ((sum.length() > 1e-12).then(|| sum.normalize()), own)
    }

    fn continued(&self, x: f64, y: f64, radius: u32) -> Option<DVec3> {
        let (u, v) = (x - 0.5, y - 0.5);
        let (ci, cj) = nearest_mapped(self, u, v, radius)?;
        // The 7 × 7 block about the nearest mapped pixel, its mapped pixels in coordinates
        // relative to (u, v), scaled to about one so that the normal equations stay well
        // conditioned.
        let s = 1.0 / (f64::from(radius) + 4.0);
        let mut rows: Vec<([f64; 6], DVec3)> = Vec::with_capacity(49);
        for j in cj.saturating_sub(3)..=cj + 3 {
            for i in ci.saturating_sub(3)..=ci + 3 {
                if let Some(d) = self.direction(i, j) {
                    let (dx, dy) = ((i as f64 - u) * s, (j as f64 - v) * s);
                    rows.push(([1.0, dx, dy, dx * dx, dx * dy, dy * dy], d));
                }
            }
        }
        // A quadratic where the block holds enough to fix one, else a plane.
        let terms = if rows.len() >= 12 { 6 } else { 3 };
        let mut m = [[0.0; 6]; 6];
        let mut rhs = [DVec3::ZERO; 6];
        for (g, d) in &rows {
            for a in 0..terms {
                for b in 0..terms {
                    m[a][b] += g[a] * g[b];
                }
                rhs[a] += g[a] * *d;
            }
        }
        let d = solve(&mut m, &mut rhs, terms)?;
        (d.length() > 1e-12).then(|| d.normalize())
    }
}

/// The mapped pixel nearest to map position (u, v), within `radius` pixels (by rings).
fn nearest_mapped(map: &NormalMap, u: f64, v: f64, radius: u32) -> Option<(usize, usize)> {
    let (ci, cj) = (u.round() as i64, v.round() as i64);
    let (w, h) = (map.width() as i64, map.height() as i64);
    for r in 0..=i64::from(radius) {
        let mut best: Option<(f64, usize, usize)> = None;
        for j in (cj - r).max(0)..=(cj + r).min(h - 1) {
            let edge = j == cj - r || j == cj + r;
            let step = if edge { 1 } else { (2 * r).max(1) as usize };
            for i in (ci - r..=ci + r).step_by(step) {
                if i < 0 || i >= w || !map.covers(i as usize, j as usize) {
                    continue;
                }
                let d = (i as f64 - u).powi(2) + (j as f64 - v).powi(2);
                if best.is_none_or(|b| d < b.0) {
                    best = Some((d, i as usize, j as usize));
                }
            }
        }
        if let Some((_, i, j)) = best {
            return Some((i, j));
        }
    }
    None
}

/// Solves the first `n` rows and columns of `m · a = rhs` (one right-hand side per vector
/// component) by Gaussian elimination with partial pivoting; `a[0]` is returned. `None` when
/// the system is singular.
fn solve(m: &mut [[f64; 6]; 6], rhs: &mut [DVec3; 6], n: usize) -> Option<DVec3> {
    let scale = (0..n).map(|k| m[k][k].abs()).fold(0.0, f64::max);
    for c in 0..n {
        let p = (c..n).max_by(|&a, &b| m[a][c].abs().total_cmp(&m[b][c].abs()))?;
        if m[p][c].abs() <= 1e-12 * scale {
            return None;
        }
        m.swap(c, p);
        rhs.swap(c, p);
        let pivot = m[c];
        for r in c + 1..n {
            let f = m[r][c] / pivot[c];
            for (x, p) in m[r][c..n].iter_mut().zip(&pivot[c..n]) {
                *x -= f * p;
            }
            let sub = rhs[c] * f;
            rhs[r] -= sub;
        }
    }
    let mut a = [DVec3::ZERO; 6];
    for r in (0..n).rev() {
        let mut v = rhs[r];
        for k in r + 1..n {
            v -= a[k] * m[r][k];
        }
        a[r] = v / m[r][r];
    }
    Some(a[0])
}

/// How corner directions are scaled so that the usual pieces are parallelograms.
pub enum Scale {
    /// Unit horizontal length about the cylinder's axis.
    Cylinder(DVec3),
    /// Unit length along the view's axis.
    Plane(DVec3),
    /// The unit directions unchanged (off-axis views, other projections, warp maps).
    Unit,
}

impl Scale {
    pub(super) fn of(view: &View) -> Scale {
        let (turn, offaxis, _) = view.parts();
        if offaxis != DVec3::ZERO {
            return Scale::Unit;
        }
        match view.projection().name() {
            "cylindrical" => Scale::Cylinder(turn * DVec3::Y),
            "cylindrical-vertical" => Scale::Cylinder(turn * DVec3::X),
            "flat" => Scale::Plane(turn * DVec3::NEG_Z),
            _ => Scale::Unit,
        }
    }

    pub(super) fn apply(&self, d: DVec3) -> DVec3 {
        match self {
            Scale::Cylinder(axis) => {
                let across = (d - d.dot(*axis) * *axis).length();
                if across > 1e-9 { d / across } else { d }
            }
            Scale::Plane(axis) => {
                let along = d.dot(*axis);
                if along > 1e-9 { d / along } else { d }
            }
            Scale::Unit => d,
        }
    }
}

/// The view's unit direction at pixel position (x, y), where it has one.
pub fn true_direction(view: &View, x: f64, y: f64, width: u32, height: u32) -> Option<DVec3> {
    ViewAt::sized(view, width, height).at(x, y).0
}

pub(super) fn angle_between(a: DVec3, b: DVec3) -> f64 {
    a.cross(b).length().atan2(a.dot(b))
}

/// The output's typical pixel: the median angle between neighbouring pixel centres, over a
/// lattice of about 64 × 64 pixels. A median, not the local pitch, so that pixels which span
/// almost no angle (an equirect's rows at a pole) do not make every tolerance unreachable.
pub fn median_pitch(view: &View, w: u32, h: u32) -> f64 {
    ViewAt::new(view, w, h).map_or(f64::NAN, |d| median_pitch_on(&d))
}

/// [`median_pitch`] of any directions.
pub fn median_pitch_on(dirs: &dyn Directions) -> f64 {
    let (w, h) = dirs.size();
    let mut pitches: Vec<f64> = (0..64u32)
        .flat_map(|b| (0..64u32).map(move |a| (a, b)))
        .filter_map(|(a, b)| {
            let (x, y) = (
                (f64::from(a) + 0.5) * f64::from(w - 1) / 64.0 + 0.5,
                (f64::from(b) + 0.5) * f64::from(h - 1) / 64.0 + 0.5,
            );
            let d = dirs.at(x, y).0?;
            let right = dirs.at(x + 1.0, y).0?;
            let down = dirs.at(x, y + 1.0).0?;
            Some([angle_between(d, right), angle_between(d, down)])
        })
        .flatten()
        .filter(|a| a.is_finite() && *a > 0.0)
        .collect();
    if pitches.is_empty() {
        return f64::NAN;
    }
    pitches.sort_by(f64::total_cmp);
    pitches[pitches.len() / 2]
}
