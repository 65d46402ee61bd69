//! Changing a grid's density without changing its warp: subdivision (every new feature is the
//! warp as the rasteriser interpolates it there), coarsening (rows and columns whose removal
//! moves no pixel by more than a tolerance) and refinement where the screen departs most from
//! what it was sampled from (new features carry the edits around them along).
//!
//! A grid is a tensor product, so a column is inserted through every row; within the region
//! subdivided both ways every new tile lies inside one old triangle and reproduces it exactly
//! (angles are interpolated linearly; directions as weighted vectors, and a new feature keeps
//! the length of the interpolated vector as its `weight`), and outside it a new column only
//! re-splits old quads along another diagonal, which moves the warp by the quad's twist —
//! `tests/core/tiles.rs` measures both against 0.01°.

use super::raster::{angles, f_normal, unwrap_deg};
use super::{Feature, Interpolation, Layout, TileScreen};
use crate::error::{Error, Result};
use glam::{DQuat, DVec3};

/// The feature the rasteriser shows where corners `parts` have barycentric weights `w`.
pub fn interpolate(mode: Interpolation, parts: &[(f64, &Feature)]) -> Feature {
    let first = parts[0].1;
    let mix = |g: fn(&Feature) -> f64| parts.iter().map(|(w, f)| w * g(f)).sum::<f64>();
    let valid = parts.iter().all(|(_, f)| f.valid);
    let outside = parts.iter().any(|(_, f)| f.outside);
    let (phi, theta, scale, weight) = match mode {
        Interpolation::Angles => (
            parts
                .iter()
                .map(|(w, f)| w * unwrap_deg(f.phi, first.phi))
                .sum::<f64>(),
            mix(|f| f.theta),
            mix(|f| f.scale),
            1.0,
        ),
        Interpolation::Vectors => {
            // The unnormalised sum, as the rasteriser forms it: its length is the new
            // feature's weight, so tiles made from it interpolate exactly as before.
            let d: DVec3 = parts
                .iter()
                .map(|(w, f)| *w * f.weight * f_normal(f.phi, f.theta, f.scale))
                .sum();
            let (p, t) = angles(d.normalize_or(DVec3::NEG_Z));
            let weight = d.length().clamp(f64::MIN_POSITIVE, 1.0);
            (unwrap_deg(p, first.phi * first.scale), t, 1.0, weight)
        }
    };
    Feature {
        x: mix(|f| f.x),
        y: mix(|f| f.y),
        phi: fold_phi(phi),
        theta,
        scale,
        f: mix(|f| f.f),
        valid,
        outside,
        weight,
    }
}

/// Longitudes kept within ±360° (a row winding round a pole drifts otherwise).
fn fold_phi(phi: f64) -> f64 {
    if phi.abs() > 360.0 {
        phi - 360.0 * phi.signum()
    } else {
        phi
    }
}

/// A grid screen's columns, rows and features; an error naming `tiles` for a triangle soup.
pub fn grid(t: &TileScreen) -> Result<(usize, usize, &[Feature])> {
    match &t.layout {
        Layout::Grid {
            columns,
            rows,
            features,
        } => Ok((*columns, *rows, features)),
        Layout::Soup { .. } => Err(Error::invalid(
            "tiles",
            "this edit needs a grid, not a triangle soup",
        )),
    }
}

fn range(name: &str, r: Option<(usize, usize)>, n: usize) -> Result<(usize, usize)> {
    let (a, b) = r.unwrap_or((0, n - 1));
    if a >= b || b >= n {
        return Err(Error::invalid(
            name,
            format!(
                "[{a}, {b}] must be a range of at least one tile within 0..{}",
                n - 1
            ),
        ));
    }
    Ok((a, b))
}

/// Splits every tile of columns `columns` and rows `rows` (whole grid where absent) in two each
/// way, every new feature the warp as it is shown there.
pub fn subdivide(
    t: &TileScreen,
    columns: Option<(usize, usize)>,
    rows: Option<(usize, usize)>,
) -> Result<TileScreen> {
    let (c, r, _) = grid(t)?;
    let (k0, k1) = range("columns", columns, c)?;
    let (l0, l1) = range("rows", rows, r)?;
    let next = split(t, (k0, k1), (l0, l1))?;
    if (k0, k1, l0, l1) != (0, c - 1, 0, r - 1) {
        let moved = largest_change(t, &next, &next);
        if moved > KEPT_DEG {
            return Err(Error::invalid(
                if columns.is_some() { "columns" } else { "rows" },
                format!(
                    "subdividing this region alone would move the warp by {moved:.3}° where \
                     its new rows and columns cross the tiles around it (a grid's rows and \
                     columns run through it whole, and a tile split one way only is split \
                     along another diagonal); subdivide the whole grid, which keeps the warp"
                ),
            ));
        }
    }
    Ok(next)
}

/// [`subdivide`] without the check: columns k0..=k1 and rows l0..=l1.
fn split(t: &TileScreen, (k0, k1): (usize, usize), (l0, l1): (usize, usize)) -> Result<TileScreen> {
    let (c, r, f) = grid(t)?;
    let (nc, nr) = (c + (k1 - k0), r + (l1 - l0));
    crate::limits::product(
        "grid",
        nc as u64,
        nr as u64,
        crate::limits::TILE_FEATURES as u64,
    )?;
    crate::limits::at_most("columns", nc, crate::limits::TILE_SIDE)?;
    crate::limits::at_most("rows", nr, crate::limits::TILE_SIDE)?;
    let mode = t.interpolation;
    let at = |k: usize, l: usize| &f[l * c + k];
    // Each new column index maps to (k, half): the original column k, or halfway to k + 1.
    let cols: Vec<(usize, bool)> = (0..c)
        .flat_map(|k| {
            let mid = (k0..k1).contains(&k);
            std::iter::once((k, false)).chain(mid.then_some((k, true)))
        })
        .collect();
    let rws: Vec<(usize, bool)> = (0..r)
        .flat_map(|l| {
            let mid = (l0..l1).contains(&l);
            std::iter::once((l, false)).chain(mid.then_some((l, true)))
        })
        .collect();
    let mut out = Vec::with_capacity(nc * nr);
    for &(l, down) in &rws {
        for &(k, right) in &cols {
            out.push(match (right, down) {
                (false, false) => *at(k, l),
                (true, false) => interpolate(mode, &[(0.5, at(k, l)), (0.5, at(k + 1, l))]),
                (false, true) => interpolate(mode, &[(0.5, at(k, l)), (0.5, at(k, l + 1))]),
                // A quad's centre lies on its (k, l)–(k+1, l+1) diagonal, where it is split.
                (true, true) => interpolate(mode, &[(0.5, at(k, l)), (0.5, at(k + 1, l + 1))]),
            });
        }
    }
    let mut next = t.clone();
    next.layout = Layout::Grid {
        columns: nc,
        rows: nr,
        features: out,
    };
    Ok(next)
}

/// How far a subdivision may move the warp, degrees.
pub const KEPT_DEG: f64 = 0.01;

/// Samples per tile each way when two screens' warps are compared.
const SAMPLES: usize = 6;

/// The largest angle, degrees, between two screens' warps on a raster fine enough for `like`
/// (`SAMPLES` per tile each way), or infinity where one covers a pixel the other does not.
pub fn largest_change(a: &TileScreen, b: &TileScreen, like: &TileScreen) -> f64 {
    let (c, r) = match &like.layout {
        Layout::Grid { columns, rows, .. } => (*columns, *rows),
        Layout::Soup { triangles } => (triangles.len().isqrt() + 2, triangles.len().isqrt() + 2),
    };
    let (w, h) = ((c - 1) * SAMPLES, (r - 1) * SAMPLES);
    let (ma, mb) = (a.feature_map(w, h), b.feature_map(w, h));
    ma.data
        .iter()
        .zip(&mb.data)
        .map(|(p, q)| match (p, q) {
            (Some((u, _)), Some((v, _))) => u.angle_between(*v).to_degrees(),
            (None, None) => 0.0,
            _ => f64::INFINITY,
        })
        .fold(0.0, f64::max)
}

fn without(t: &TileScreen, index: usize, column: bool) -> TileScreen {
    let (c, r, f) = grid(t).expect("a grid");
    let features = f
        .iter()
        .enumerate()
        .filter(|(i, _)| {
            if column {
                i % c != index
            } else {
                i / c != index
            }
        })
        .map(|(_, v)| *v)
        .collect();
    let mut next = t.clone();
    next.layout = Layout::Grid {
        columns: if column { c - 1 } else { c },
        rows: if column { r } else { r - 1 },
        features,
    };
    next
}

/// Removes the inner columns and rows whose removal keeps the warp within `tolerance` degrees
/// of this one everywhere (compared with the screen before any removal, so errors do not
/// add up) and every pixel covered as before.
pub fn coarsen(t: &TileScreen, tolerance: f64) -> Result<TileScreen> {
    if !(tolerance.is_finite() && tolerance > 0.0 && tolerance <= 10.0) {
        return Err(Error::invalid(
            "tolerance",
            format!("must be above 0 and at most 10 degrees, got {tolerance}"),
        ));
    }
    grid(t)?;
    let mut now = t.clone();
    for column in [true, false] {
        let mut index = 1;
        loop {
            let (c, r, _) = grid(&now)?;
            let n = if column { c } else { r };
            if index + 1 >= n {
                break;
            }
            let candidate = without(&now, index, column);
            if candidate.validate().is_ok() && largest_change(t, &candidate, t) <= tolerance {
                now = candidate;
            } else {
                index += 1;
            }
        }
    }
    Ok(now)
}

/// Inserts columns and rows where the screen departs most from `exact` (the warp it was
/// sampled from: the wall's geometry, a projection) until no pixel departs by more than
/// `tolerance` degrees, or `limit` features are reached. A new feature is `exact` there,
/// turned by the edit the screen holds around it (the rotation from the source's own tile
/// interpolation to the screen's), so an unedited screen gains exact features and an edited one
/// keeps its edits. Returns the screen and the largest departure left.
pub fn refine(
    t: &TileScreen,
    tolerance: f64,
    limit: usize,
    exact: &(dyn Fn(f64, f64) -> Option<DVec3> + Sync),
) -> Result<(TileScreen, f64)> {
    if !(tolerance.is_finite() && tolerance > 0.0) {
        return Err(Error::invalid(
            "tolerance",
            format!("must be above 0 degrees, got {tolerance}"),
        ));
    }
    let limit = limit.min(crate::limits::TILE_FEATURES);
    let mut now = t.clone();
    for _ in 0..REFINE_STEPS {
        let (c, r, f) = grid(&now)?;
        // The source sampled at the screen's own features: its tiles' error is what refining
        // can remove, whatever the edits.
        let mut reference = now.clone();
        if let Layout::Grid { features, .. } = &mut reference.layout {
            for g in features.iter_mut().filter(|g| g.valid) {
                if let Some(d) = exact(g.x, g.y) {
                    let (phi, theta) = angles(d);
                    (g.phi, g.theta, g.scale) = (unwrap_deg(phi, g.phi), theta, 1.0);
                    g.weight = 1.0;
                }
            }
        }
        let (w, h) = ((c - 1) * SAMPLES, (r - 1) * SAMPLES);
        let map = reference.feature_map(w, h);
        let mut worst = (0.0f64, 0.0, 0.0);
        for (n, p) in map.data.iter().enumerate() {
            let (x, y) = (
                ((n % w) as f64 + 0.5) / w as f64,
                ((n / w) as f64 + 0.5) / h as f64,
            );
            if let (Some((v, _)), Some(e)) = (p, exact(x, y)) {
                let a = v.angle_between(e).to_degrees();
                if a > worst.0 {
                    worst = (a, x, y);
                }
            }
        }
        if worst.0 <= tolerance || (c + 1) * (r + 1) > limit {
            return Ok((now, worst.0));
        }
        // The tile holding the worst pixel (along the first row and column: grids sampled from
        // a source are tensor products).
        let k = (0..c - 1).find(|&k| worst.1 <= f[k + 1].x).unwrap_or(c - 2);
        let l = (0..r - 1)
            .find(|&l| worst.2 <= f[(l + 1) * c].y)
            .unwrap_or(r - 2);
        let mut next = split(&now, (k, k + 1), (l, l + 1))?;
        let (nc, _, _) = grid(&next)?;
        let ref_split = split(&reference, (k, k + 1), (l, l + 1))?;
        let (Layout::Grid { features, .. }, Layout::Grid { features: refs, .. }) =
            (&mut next.layout, &ref_split.layout)
        else {
            unreachable!()
        };
        // The new features: column k + 1 and row l + 1 of the subdivided grid.
        for (i, g) in features.iter_mut().enumerate() {
            let (kk, ll) = (i % nc, i / nc);
            if (kk != k + 1 && ll != l + 1) || !g.valid {
                continue;
            }
            let (Some(e), shown, base) = (
                exact(g.x, g.y),
                f_normal(g.phi, g.theta, g.scale),
                f_normal(refs[i].phi, refs[i].theta, refs[i].scale),
            ) else {
                continue;
            };
            let d = DQuat::from_rotation_arc(base, shown) * e;
            let (phi, theta) = angles(d);
            (g.phi, g.theta, g.scale) = (fold_phi(unwrap_deg(phi, g.phi)), theta, 1.0);
            g.weight = 1.0;
        }
        next.validate()?;
        now = next;
    }
    let left = largest_change(&now, &now, &now);
    Ok((now, left))
}

/// Columns and rows one `refine` inserts at most (each step one of each).
pub const REFINE_STEPS: usize = 64;
