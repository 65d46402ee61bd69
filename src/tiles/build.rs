//! Tile screens sampled from projections, and the combinations of seed 000's Figure 5.

use super::raster::{angles, unwrap_deg};
use super::{Feature, Interpolation, TileScreen};
use crate::error::{Error, Result};
use crate::projection::{self, Orientation, Params, View};
use glam::DVec3;

crate::projection::doc::view_document! {
    /// A projection and view transform a tile screen was sampled from (kept so an edit can
    /// reset to it). Angles in degrees, vectors as [x, y, z].
    pub struct Source {
        /// Output height / width the projection was built for.
        pub aspect: f64,
    }
}

impl Source {
    /// The plain projection, looking ahead.
    pub fn new(projection: &str, params: Params, aspect: f64) -> Self {
        Source::from_doc(projection::ViewDoc::new(projection, params), aspect)
    }

    /// The view this source describes, for an output of its `aspect`.
    pub fn view(&self) -> Result<View> {
        self.doc().view(self.aspect)
    }
}

/// The feature of direction `d` (or an invalid one) at screen position (x, y).
fn feature(x: f64, y: f64, d: Option<DVec3>, f: f64) -> Feature {
    let (phi, theta, valid) = match d {
        Some(d) => {
            let (p, t) = angles(d);
            (p, t, true)
        }
        None => (0.0, 0.0, false),
    };
    Feature {
        x,
        y,
        phi,
        theta,
        scale: 1.0,
        f,
        valid,
        outside: false,
        weight: 1.0,
    }
}

/// Makes longitudes continuous across the grid (each within 180° of its left neighbour, or of
/// the one above in the first column), so that tiles never sweep the long way round.
fn unwrap_grid(columns: usize, features: &mut [Feature]) {
    for i in 0..features.len() {
        let (k, l) = (i % columns, i / columns);
        let reference = match (k, l) {
            (0, 0) => continue,
            (0, _) => features[i - columns].phi,
            _ => features[i - 1].phi,
        };
        if features[i].valid {
            let phi = unwrap_deg(features[i].phi, reference);
            // Rows that wind round a pole would otherwise drift past the ±360° range.
            features[i].phi = if phi.abs() > 360.0 {
                phi - 360.0 * phi.signum()
            } else {
                phi
            };
        }
    }
}

/// A columns × rows grid of features of `dir` (a direction, or `None`, and f per (s, t)).
pub fn grid_of(
    columns: usize,
    rows: usize,
    dir: impl Fn(f64, f64) -> (Option<DVec3>, f64),
) -> Result<TileScreen> {
    if columns < 2 || rows < 2 || columns.checked_mul(rows).is_none_or(|n| n > 1 << 22) {
        return Err(Error::invalid(
            "grid",
            format!("must be between 2×2 and 4M features, got {columns}×{rows}"),
        ));
    }
    let mut features = Vec::with_capacity(columns * rows);
    for l in 0..rows {
        for k in 0..columns {
            let (x, y) = (
                k as f64 / (columns - 1) as f64,
                l as f64 / (rows - 1) as f64,
            );
            let (d, f) = dir(2.0 * x - 1.0, 1.0 - 2.0 * y);
            features.push(feature(x, y, d, f));
        }
    }
    unwrap_grid(columns, &mut features);
    let mut t = TileScreen::grid(columns, rows, features)?;
    t.interpolation = Interpolation::Vectors;
    Ok(t)
}

/// Samples a projection into a columns × rows grid; features past a fisheye's image circle
/// continue its formula and are marked `outside`, so the tiles along the circle still reach it
/// and the projection's domain (the screen's mask) cuts them there.
pub fn from_source(source: &Source, columns: usize, rows: usize) -> Result<TileScreen> {
    let view = source.view()?;
    let mut t = grid_of(columns, rows, |s, t| {
        (view.direction_unbounded(s, t).ok(), 1.0)
    })?;
    if let super::Layout::Grid { features, .. } = &mut t.layout {
        for f in features.iter_mut().filter(|f| f.valid) {
            f.outside = view.direction(2.0 * f.x - 1.0, 1.0 - 2.0 * f.y).is_err();
        }
    }
    t.source = Some(source.clone());
    Ok(t)
}

/// Gives the invalid features of a grid that touch a valid one (in any of the 8 directions) a
/// direction extrapolated from the valid ones, and marks them `outside`: the tiles that straddle
/// the edge of what the source shows are then drawn, and the source's own mask (a wall's
/// footprint, a projection's domain) cuts them per pixel where the edge really is, instead of
/// the grid cutting them at whole tiles.
///
/// `beyond(x, y)` gives the source's own continuation where it has one (the wall continued
/// past its edge); otherwise each extrapolation continues a line of two valid features through
/// the invalid one (2·a − b, in unit directions) and averages over the lines that exist; with
/// none, the nearest valid neighbour's direction is held. Only features that were valid are
/// used, so the result does not depend on the order of the scan.
pub fn extend_past_edge(t: &mut TileScreen, beyond: impl Fn(f64, f64) -> Option<DVec3>) {
    let super::Layout::Grid {
        columns,
        rows,
        features,
    } = &mut t.layout
    else {
        return;
    };
    let (c, r) = (*columns as i64, *rows as i64);
    let before = features.clone();
    let at = |k: i64, l: i64| -> Option<&Feature> {
        (k >= 0 && l >= 0 && k < c && l < r)
            .then(|| &before[(l * c + k) as usize])
            .filter(|f| f.valid && !f.outside)
    };
    let dir = |f: &Feature| super::raster::f_normal(f.phi, f.theta, f.scale);
    for l in 0..r {
        for k in 0..c {
            let me = &before[(l * c + k) as usize];
            if me.valid {
                continue;
            }
            let mut sum = DVec3::ZERO;
            let mut near: Option<&Feature> = None;
            for (dk, dl) in [
                (1, 0),
                (-1, 0),
                (0, 1),
                (0, -1),
                (1, 1),
                (1, -1),
                (-1, 1),
                (-1, -1),
            ] {
                let Some(a) = at(k + dk, l + dl) else {
                    continue;
                };
                // Sides come before corners, so the anchor is a side neighbour when one exists.
                near = near.or(Some(a));
                if let Some(b) = at(k + 2 * dk, l + 2 * dl) {
                    let e = 2.0 * dir(a) - dir(b);
                    if e.length() > 1e-9 {
                        sum += e.normalize();
                    }
                }
            }
            let Some(anchor) = near else { continue };
            let d = if let Some(d) = beyond(me.x, me.y) {
                d
            } else if sum.length() > 1e-9 {
                sum.normalize()
            } else {
                dir(anchor)
            };
            let (phi, theta) = angles(d);
            let phi = unwrap_deg(phi, anchor.phi);
            features[(l * c + k) as usize] = Feature {
                phi: if phi.abs() > 360.0 {
                    phi - 360.0 * phi.signum()
                } else {
                    phi
                },
                theta,
                scale: 1.0,
                valid: true,
                outside: true,
                weight: 1.0,
                ..*me
            };
        }
    }
}

/// Seed 000, Figure 5A: a planar perspective in the centre, cylindrical to the sides.
///
/// The planar part covers `planar_hfov` degrees across the middle `planar_width` of the screen
/// (a fraction of its width); the cylinder continues to `hfov` in all. The cylinder's height
/// scale is the planar part's vertical scale times cos(planar_hfov/2), which makes the two meet
/// without a step. f falls from 1 in the planar part to 0.25 at the outer edges: the Figure's
/// saturation falloff.
pub fn planar_with_cylindrical_sides(
    hfov: f64,
    planar_hfov: f64,
    vfov: f64,
    planar_width: f64,
    columns: usize,
    rows: usize,
) -> Result<TileScreen> {
    let check = |name: &str, v: f64, lo: f64, hi: f64| {
        if v.is_finite() && v > lo && v < hi {
            Ok(v)
        } else {
            Err(Error::invalid(
                name,
                format!("must lie strictly between {lo} and {hi}, got {v}"),
            ))
        }
    };
    let hfov = check("hfov", hfov, 0.0, 360.0 + 1e-9)?.to_radians();
    let hc = check("planar-hfov", planar_hfov, 0.0, 180.0)?.to_radians();
    let tv = (check("vfov", vfov, 0.0, 180.0)?.to_radians() / 2.0).tan();
    let s0 = check("planar-width", planar_width, 0.0, 1.0)?;
    if hc >= hfov {
        return Err(Error::invalid("planar-hfov", "must be smaller than hfov"));
    }
    let th = (hc / 2.0).tan();
    grid_of(columns, rows, |s, t| {
        if s.abs() <= s0 {
            (Some(DVec3::new(s / s0 * th, t * tv, -1.0).normalize()), 1.0)
        } else {
            let u = (s.abs() - s0) / (1.0 - s0);
            let lon = s.signum() * (hc / 2.0 + u * (hfov / 2.0 - hc / 2.0));
            let h = t * tv * (hc / 2.0).cos();
            (
                Some(DVec3::new(lon.sin(), h, -lon.cos()).normalize()),
                1.0 - 0.75 * u,
            )
        }
    })
}

/// A planar inset in a cylindrical view (seed 000, Figure 5B).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Inset {
    /// Tile range covered: columns k0..k1 and rows l0..l1 of tiles.
    pub tiles: (usize, usize, usize, usize),
    /// Where the inset looks: longitude and latitude, degrees.
    pub look: (f64, f64),
    /// Horizontal field of view of the inset, degrees.
    pub hfov: f64,
}

/// Seed 000, Figure 5B: a cylindrical view with planar insets, as a triangle soup so that the
/// insets' borders are hard transitions. f is 1 inside an inset and 0.3 outside.
pub fn cylinder_with_planar_insets(
    hfov: f64,
    vfov: f64,
    columns: usize,
    rows: usize,
    insets: &[Inset],
) -> Result<TileScreen> {
    let base = Source::new(
        "cylindrical",
        Params {
            hfov: Some(hfov),
            vfov: Some(vfov),
            ..Params::default()
        },
        1.0,
    )
    .view()?;
    let grid = grid_of(columns, rows, |s, t| (base.direction(s, t).ok(), 0.3))?;
    let mut views = Vec::new();
    for (n, inset) in insets.iter().enumerate() {
        let (k0, k1, l0, l1) = inset.tiles;
        if k0 >= k1 || l0 >= l1 || k1 >= columns || l1 >= rows {
            return Err(Error::invalid(
                format!("insets[{n}]"),
                format!(
                    "tile range {k0}..{k1} × {l0}..{l1} is empty or outside the {columns}×{rows} grid"
                ),
            ));
        }
        let look = super::raster::f_normal(inset.look.0, inset.look.1, 1.0);
        // The inset's own frame: its rectangle's aspect sets the vertical field of view.
        let (x0, x1) = (
            k0 as f64 / (columns - 1) as f64,
            k1 as f64 / (columns - 1) as f64,
        );
        let (y0, y1) = (l0 as f64 / (rows - 1) as f64, l1 as f64 / (rows - 1) as f64);
        let aspect = (y1 - y0) / (x1 - x0);
        let p = projection::build(
            "flat",
            &Params {
                hfov: Some(inset.hfov),
                ..Params::default()
            },
            aspect,
        )
        .map_err(|e| Error::invalid(format!("insets[{n}].hfov"), e.to_string()))?;
        let view = View::new(p, Orientation::look(look, DVec3::Y)?, DVec3::ZERO, 1.0)?;
        views.push((x0, x1, y0, y1, view));
    }
    let mut triangles = Vec::new();
    for (tri, _) in grid.triangles() {
        let (cx, cy) = (
            (tri[0].x + tri[1].x + tri[2].x) / 3.0,
            (tri[0].y + tri[1].y + tri[2].y) / 3.0,
        );
        let inside = views
            .iter()
            .find(|v| cx > v.0 && cx < v.1 && cy > v.2 && cy < v.3);
        let tri = match inside {
            None => tri,
            Some((x0, x1, y0, y1, view)) => tri.map(|f| {
                let (s, t) = (
                    2.0 * (f.x - x0) / (x1 - x0) - 1.0,
                    1.0 - 2.0 * (f.y - y0) / (y1 - y0),
                );
                feature(f.x, f.y, view.direction(s, t).ok(), 1.0)
            }),
        };
        let mut tri = tri;
        tri[1].phi = unwrap_deg(tri[1].phi, tri[0].phi);
        tri[2].phi = unwrap_deg(tri[2].phi, tri[0].phi);
        triangles.push(tri);
    }
    let mut t = TileScreen::soup(triangles)?;
    t.interpolation = Interpolation::Vectors;
    Ok(t)
}
