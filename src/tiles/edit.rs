//! Edits of a tile screen. Each returns a new screen with the revision increased, or an error
//! that says why the edit was refused; a refused edit changes nothing, and no edit can leave a
//! non-finite value or a folded-over tile behind (the result is validated before it is returned).

use super::build::{Source, from_source, grid_of};
use super::raster::unwrap_deg;
use super::refine::grid as grid_parts;
use super::{Feature, Layout, TileScreen};
use crate::error::{Error, Result};
use glam::DVec3;

/// One change to a tile screen. As JSON (the daemon's PATCH), `"op"` names it in snake case:
/// `{"op": "set_feature", "column": 3, "row": 0, "phi": 12.5}`; ranges are `[first, last]`.
#[derive(Debug, Clone, PartialEq, serde::Deserialize)]
#[serde(tag = "op", rename_all = "snake_case", deny_unknown_fields)]
pub enum Edit {
    /// Sets any of a grid feature's angles, scale and f (column k, row l).
    SetFeature {
        /// The feature's column k, from 0 at the left.
        column: usize,
        /// The feature's row l, from 0 at the top.
        row: usize,
        /// New longitude φ, degrees (0 ahead, positive to the right; within ±360); kept when
        /// absent.
        phi: Option<f64>,
        /// New latitude θ, degrees (positive up; within ±360); kept when absent.
        theta: Option<f64>,
        /// New angular zoom, positive; kept when absent.
        scale: Option<f64>,
        /// New custom value f (the renderer's saturation); kept when absent.
        f: Option<f64>,
    },
    /// Resamples the features of columns k0..=k1, rows l0..=l1 from another projection and view,
    /// which then spans that region of the screen (s, t = ±1 at its edges).
    SetRegion {
        /// `[first, last]` feature columns the region spans, first < last.
        columns: (usize, usize),
        /// `[first, last]` feature rows the region spans, first < last.
        rows: (usize, usize),
        /// The projection and view the region shows, written as a tile screen's `source` (with its
        /// `aspect`).
        source: Source,
    },
    /// Inserts a row of features halfway between rows `at − 1` and `at`.
    InsertRow {
        /// The row the new one goes before, 1 to rows − 1.
        at: usize,
    },
    /// Inserts a column of features halfway between columns `at − 1` and `at`.
    InsertColumn {
        /// The column the new one goes before, 1 to columns − 1.
        at: usize,
    },
    /// Removes row `at` of features; a grid keeps at least 2 rows.
    RemoveRow {
        /// The row to remove, from 0 at the top.
        at: usize,
    },
    /// Removes column `at` of features; a grid keeps at least 2 columns.
    RemoveColumn {
        /// The column to remove, from 0 at the left.
        at: usize,
    },
    /// Replaces every inner feature's angles, scale and f by the mean of its four neighbours,
    /// `iterations` times; the border stays, so the screen keeps its extent, and so do invalid
    /// features and the valid ones beside them (the edge of what the screen shows).
    Smooth {
        /// How many passes, at most `limits::SMOOTH_ITERATIONS` (1000).
        iterations: usize,
    },
    /// Back to the projection the screen was sampled from, at the current grid size.
    Reset,
    /// Splits every tile of the columns and rows given (the whole grid where absent) in two
    /// each way; the new features are the warp as it is shown there, so nothing moves (within
    /// 0.01°, see [`super::refine`]).
    Subdivide {
        /// `[first, last]` feature columns (first < last) whose tiles are split; all when absent.
        #[serde(default)]
        columns: Option<(usize, usize)>,
        /// `[first, last]` feature rows (first < last) whose tiles are split; all when absent.
        #[serde(default)]
        rows: Option<(usize, usize)>,
    },
    /// Removes the inner rows and columns whose removal moves no pixel by more than `tolerance`
    /// degrees (default 0.01).
    Coarsen {
        /// Largest move a removal may cause, degrees; [`REFINE_TOLERANCE`] (0.01) when absent.
        #[serde(default)]
        tolerance: Option<f64>,
    },
    /// Inserts rows and columns where the screen departs most from what it was sampled from
    /// (the projection, or a channel's geometry) until it is within `tolerance` degrees
    /// (default 0.01) or has `max_features` (default four times as many as now); new features
    /// carry the edits around them along.
    Refine {
        /// Departure from the source to get within, degrees; [`REFINE_TOLERANCE`] (0.01) when
        /// absent.
        #[serde(default)]
        tolerance: Option<f64>,
        /// Most features the screen may grow to; four times as many as now when absent.
        #[serde(default)]
        max_features: Option<usize>,
    },
}

impl Edit {
    /// The work of this edit on a grid of `features` features, in feature visits (each about a
    /// microsecond on one core, measured on the demo rig's 33×19 grid): every edit validates the
    /// whole grid once; a smooth pass costs a 64th of that per feature, a subdivision builds
    /// four times the features, a refinement samples the warp up to its feature cap, and a
    /// coarsening tries each removal.
    pub fn work(&self, features: usize) -> u64 {
        let n = features as u64;
        n + match self {
            Edit::Smooth { iterations } => (*iterations as u64).saturating_mul(n) / 64,
            Edit::Subdivide { .. } => 16 * n,
            Edit::Refine { max_features, .. } => {
                let cap = max_features.unwrap_or(4 * features);
                12 * cap.min(crate::limits::TILE_FEATURES) as u64
            }
            Edit::Coarsen { .. } => 100 * n,
            _ => 0,
        }
    }
}

/// The tolerance of `coarsen` and `refine` when none is given, degrees.
pub const REFINE_TOLERANCE: f64 = 0.01;

fn index_in(name: &str, i: usize, n: usize) -> Result<usize> {
    if i < n {
        Ok(i)
    } else {
        Err(Error::invalid(name, format!("{i} is outside 0..{}", n - 1)))
    }
}

/// Midpoint of two features, the longitudes taken the short way round.
fn midpoint(a: &Feature, b: &Feature) -> Feature {
    Feature {
        x: (a.x + b.x) / 2.0,
        y: (a.y + b.y) / 2.0,
        phi: (a.phi + unwrap_deg(b.phi, a.phi)) / 2.0,
        theta: (a.theta + b.theta) / 2.0,
        scale: (a.scale + b.scale) / 2.0,
        f: (a.f + b.f) / 2.0,
        valid: a.valid && b.valid,
        // Possibly on the wall, but nothing here says so: held, like the edge it sits at.
        outside: a.outside || b.outside,
        weight: 1.0,
    }
}

impl TileScreen {
    /// Applies `edit`, returning the new screen (revision + 1) or why it was refused.
    pub fn edit(&self, edit: &Edit) -> Result<TileScreen> {
        let layout = match edit {
            Edit::SetFeature {
                column,
                row,
                phi,
                theta,
                scale,
                f,
            } => self.set_feature((*column, *row), [*phi, *theta, *scale, *f])?,
            Edit::SetRegion {
                columns,
                rows,
                source,
            } => self.set_region(*columns, *rows, source)?,
            Edit::InsertRow { at } => self.insert(Line::Row, *at)?,
            Edit::InsertColumn { at } => self.insert(Line::Column, *at)?,
            Edit::RemoveRow { at } => self.remove(Line::Row, *at)?,
            Edit::RemoveColumn { at } => self.remove(Line::Column, *at)?,
            Edit::Smooth { iterations } => self.smooth(*iterations)?,
            Edit::Subdivide { columns, rows } => {
                super::refine::subdivide(self, *columns, *rows)?.layout
            }
            Edit::Coarsen { tolerance } => {
                super::refine::coarsen(self, tolerance.unwrap_or(REFINE_TOLERANCE))?.layout
            }
            Edit::Refine {
                tolerance,
                max_features,
            } => self.refine_to_source(*tolerance, *max_features)?,
            Edit::Reset => self.reset()?,
        };
        let next = TileScreen {
            layout,
            revision: self.revision + 1,
            ..self.clone()
        };
        next.validate()?;
        // Edits that move features can fold the content over while the screen positions stay
        // put; insertions take midpoints and a reset resamples, which cannot.
        if matches!(
            edit,
            Edit::SetFeature { .. } | Edit::SetRegion { .. } | Edit::Smooth { .. }
        ) {
            refuse_content_folds(self, &next, edit)?;
        }
        Ok(next)
    }

    /// The grid with feature (column, row)'s φ, θ, scale and f set where given.
    fn set_feature(
        &self,
        (column, row): (usize, usize),
        values: [Option<f64>; 4],
    ) -> Result<Layout> {
        let (c, r, f) = grid_parts(self)?;
        let (k, l) = (index_in("column", column, c)?, index_in("row", row, r)?);
        let mut features = f.to_vec();
        let feat = &mut features[l * c + k];
        let [phi, theta, scale, f] = values;
        feat.phi = phi.unwrap_or(feat.phi);
        feat.theta = theta.unwrap_or(feat.theta);
        feat.scale = scale.unwrap_or(feat.scale);
        feat.f = f.unwrap_or(feat.f);
        Ok(grid_layout(c, r, features))
    }

    /// The grid with columns k0..=k1, rows l0..=l1 seeing what `source` sees, spread over them.
    fn set_region(
        &self,
        columns: (usize, usize),
        rows: (usize, usize),
        source: &Source,
    ) -> Result<Layout> {
        let view = source.view()?;
        let (c, r, f) = grid_parts(self)?;
        let (k0, k1) = (
            index_in("columns", columns.0, c)?,
            index_in("columns", columns.1, c)?,
        );
        let (l0, l1) = (index_in("rows", rows.0, r)?, index_in("rows", rows.1, r)?);
        if k0 >= k1 || l0 >= l1 {
            return Err(Error::invalid(
                "columns",
                "a region needs at least one tile",
            ));
        }
        let region = grid_of(k1 - k0 + 1, l1 - l0 + 1, |s, t| {
            (view.direction(s, t).ok(), 1.0)
        })?;
        let Layout::Grid {
            features: fresh, ..
        } = region.layout
        else {
            unreachable!("grid_of makes grids")
        };
        let mut features = f.to_vec();
        for l in l0..=l1 {
            for k in k0..=k1 {
                let src = fresh[(l - l0) * (k1 - k0 + 1) + (k - k0)];
                let dst = &mut features[l * c + k];
                // Keep the screen positions and where the source's edge is; only what is seen
                // there changes.
                let (x, y, f, outside) = (dst.x, dst.y, dst.f, dst.outside);
                *dst = Feature {
                    x,
                    y,
                    f,
                    outside,
                    ..src
                };
            }
        }
        Ok(grid_layout(c, r, features))
    }

    /// The grid with a row or column of midpoints inserted before row or column `at`.
    fn insert(&self, line: Line, at: usize) -> Result<Layout> {
        let (c, r, f) = grid_parts(self)?;
        let row = line == Line::Row;
        let n = if row { r } else { c };
        if at == 0 || at >= n {
            return Err(Error::invalid(
                "at",
                format!("must lie in 1..{}, got {at}", n - 1),
            ));
        }
        let mut out = Vec::with_capacity(f.len() + if row { c } else { r });
        for l in 0..r {
            if row && l == at {
                out.extend((0..c).map(|k| midpoint(&f[(l - 1) * c + k], &f[l * c + k])));
            }
            for k in 0..c {
                if !row && k == at {
                    out.push(midpoint(&f[l * c + k - 1], &f[l * c + k]));
                }
                out.push(f[l * c + k]);
            }
        }
        let (c, r) = if row { (c, r + 1) } else { (c + 1, r) };
        Ok(grid_layout(c, r, out))
    }

    /// The grid without row or column `at`.
    fn remove(&self, line: Line, at: usize) -> Result<Layout> {
        let (c, r, f) = grid_parts(self)?;
        let row = line == Line::Row;
        let n = if row { r } else { c };
        index_in("at", at, n)?;
        if n <= 2 {
            return Err(Error::invalid(
                "at",
                "a grid keeps at least 2 rows and 2 columns",
            ));
        }
        let out: Vec<Feature> = f
            .iter()
            .enumerate()
            .filter(|(i, _)| if row { i / c != at } else { i % c != at })
            .map(|(_, v)| *v)
            .collect();
        let (c, r) = if row { (c, r - 1) } else { (c - 1, r) };
        Ok(grid_layout(c, r, out))
    }

    /// The grid with every inner feature replaced by the mean of its four neighbours,
    /// `iterations` times.
    fn smooth(&self, iterations: usize) -> Result<Layout> {
        crate::limits::at_most("iterations", iterations, crate::limits::SMOOTH_ITERATIONS)?;
        let (c, r, f) = grid_parts(self)?;
        let mut features = f.to_vec();
        for _ in 0..iterations {
            let before = features.clone();
            for l in 1..r - 1 {
                for k in 1..c - 1 {
                    let me = before[l * c + k];
                    let n = [
                        before[l * c + k - 1],
                        before[l * c + k + 1],
                        before[(l - 1) * c + k],
                        before[(l + 1) * c + k],
                    ];
                    // Invalid features hold no direction (φ = θ = 0) and outside ones an
                    // extrapolated one; a feature beside either is the wall's edge. All stay
                    // where they are, so the edge does not drift inwards.
                    let held = |f: &Feature| !f.valid || f.outside;
                    if held(&me) || n.iter().any(held) {
                        continue;
                    }
                    let mean = |g: fn(&Feature) -> f64| n.iter().map(g).sum::<f64>() / 4.0;
                    let phi = n.iter().map(|v| unwrap_deg(v.phi, me.phi)).sum::<f64>() / 4.0;
                    let f = &mut features[l * c + k];
                    f.phi = phi;
                    f.theta = mean(|v| v.theta);
                    f.scale = mean(|v| v.scale);
                    f.f = mean(|v| v.f);
                }
            }
        }
        Ok(grid_layout(c, r, features))
    }

    /// [`Edit::Refine`] towards the projection the screen was sampled from.
    fn refine_to_source(
        &self,
        tolerance: Option<f64>,
        max_features: Option<usize>,
    ) -> Result<Layout> {
        let view = self
            .source
            .as_ref()
            .ok_or_else(|| Error::invalid("tiles", "has no source projection to refine towards"))?
            .view()?;
        // Past a fisheye's circle its formula goes on, as the screen's features do.
        let exact = |x: f64, y: f64| view.direction_unbounded(2.0 * x - 1.0, 1.0 - 2.0 * y).ok();
        Ok(self.refined(tolerance, max_features, &exact)?.layout)
    }

    /// The grid sampled afresh from the screen's source projection, at its current size.
    fn reset(&self) -> Result<Layout> {
        let (c, r, _) = grid_parts(self)?;
        let source = self
            .source
            .as_ref()
            .ok_or_else(|| Error::invalid("tiles", "has no source projection to reset to"))?;
        Ok(from_source(source, c, r)?.layout)
    }
}

/// Which kind of grid line an insertion or removal is about.
#[derive(Clone, Copy, PartialEq)]
enum Line {
    Row,
    Column,
}

fn grid_layout(columns: usize, rows: usize, features: Vec<Feature>) -> Layout {
    Layout::Grid {
        columns,
        rows,
        features,
    }
}

impl TileScreen {
    /// [`Edit::Refine`] towards `exact` (what the screen was sampled from).
    pub fn refined(
        &self,
        tolerance: Option<f64>,
        max_features: Option<usize>,
        exact: &(dyn Fn(f64, f64) -> Option<DVec3> + Sync),
    ) -> Result<TileScreen> {
        let limit = max_features.unwrap_or(4 * self.feature_count());
        let tol = tolerance.unwrap_or(REFINE_TOLERANCE);
        Ok(super::refine::refine(self, tol, limit, exact)?.0)
    }
}

/// The direction a feature shows (its angles times its scale).
fn shown(f: &Feature) -> DVec3 {
    let (p, t) = (
        (f.phi * f.scale).to_radians(),
        (f.theta * f.scale).to_radians(),
    );
    DVec3::new(t.cos() * p.sin(), t.sin(), -t.cos() * p.cos())
}

/// Which way round a triangle's content directions run, seen from outside the unit sphere: 1 or
/// −1, and 0 where a corner is invalid or the triangle is too small to tell (a row at a pole;
/// the screen-space check already refuses degenerate tiles).
fn content_turn(t: &[Feature; 3]) -> i8 {
    if !t.iter().all(|f| f.valid) {
        return 0;
    }
    let [a, b, c] = t.map(|f| shown(&f));
    let s = (b - a).cross(c - a).dot(a + b + c);
    if s.abs() < 1e-12 {
        0
    } else if s > 0.0 {
        1
    } else {
        -1
    }
}

/// Refuses `next` if the edit turned a triangle against the way the screen's content runs (a
/// fold in content space, which screen positions alone do not show). Naming: the feature a
/// `set_feature` moved, else the tile.
fn refuse_content_folds(before: &TileScreen, next: &TileScreen, edit: &Edit) -> Result<()> {
    let turns = |t: &TileScreen| -> Vec<(i8, String)> {
        t.triangles()
            .iter()
            .map(|(t, name)| (content_turn(t), name.clone()))
            .collect()
    };
    let (was, now) = (turns(before), turns(next));
    let majority = was.iter().map(|(t, _)| i64::from(*t)).sum::<i64>().signum() as i8;
    if majority == 0 {
        return Ok(());
    }
    let against = |v: &[(i8, String)]| v.iter().filter(|(t, _)| *t == -majority).count();
    let folded = if was.len() == now.len() {
        now.iter()
            .zip(&was)
            .find(|((t, _), (old, _))| *t == -majority && *old != -majority)
            .map(|((_, name), _)| name.clone())
    } else if against(&now) > against(&was) {
        now.iter()
            .find(|(t, _)| *t == -majority)
            .map(|(_, name)| name.clone())
    } else {
        None
    };
    let Some(tile) = folded else {
        return Ok(());
    };
    let (name, what) = match (edit, &next.layout) {
        (Edit::SetFeature { column, row, .. }, Layout::Grid { columns, .. }) => (
            format!(
                "features[{}] (column {column}, row {row})",
                row * columns + column
            ),
            format!("folds {tile} over in content space"),
        ),
        _ => (
            tile,
            "is folded over in content space (its directions run the wrong way round)".into(),
        ),
    };
    Err(Error::invalid(
        name,
        format!("{what}: a neighbour would show content from the other side"),
    ))
}
