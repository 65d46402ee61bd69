//! Atlas positions of every output sample, computed exactly on a sparse lattice and interpolated
//! in between where that is provably close: "model no more than a scene needs".
//!
//! The position of a sample is `content.locate(warp.direction(x, y))`, two to four
//! transcendental functions per sample. Over most of an image it is a smooth function of (x, y),
//! so it is evaluated exactly only at lattice nodes every [`STEP`] samples and, in between, by
//! tensor-product cubic Lagrange interpolation over the 4 × 4 nodes around the cell. Its error
//! there is of fourth order in the node spacing (about 10⁻⁵ texel for a 1080p perspective view
//! of a 4096-wide panorama).
//!
//! Each cell earns interpolation by test: all 16 nodes of its stencil are covered and the
//! interpolant agrees with the exact position at the cell's centre and edge midpoints to within
//! `ACCEPT`. The centre is where the fourth-order error of a middle cell peaks, so a cell that
//! passes with this margin holds [`BOUND`] everywhere; `tests/core/exactness.rs` measures every
//! sample of a panel of views and contents against the exact positions. Cells that fail (seams
//! between cube faces, the ±180° wrap of a panorama, poles, the edge of a fisheye's circle or of
//! a partial panorama, kinks in an edited normal map) are computed exactly, sample by sample.
//!
//! Where positions jump but directions do not — a cube map's face edges — a cell can still be
//! interpolated in directions, when the content says locating a direction is cheap and
//! continuous but for seams it can point out ([`Locate::near_a_seam`]): the direction is
//! interpolated from the same stencil, located sample by sample (a face choice and a division,
//! no trigonometry), and recomputed exactly within `SEAM_MARGIN` of a seam. The same check
//! admits such a cell, against the same exact positions.
//!
//! What must not move at all is exact too: coverage (a normal map's holes and a partial
//! panorama's edge are checked per sample) and, for nearest filtering, the texel a sample picks
//! (samples within [`BOUND`] of a rounding boundary are computed exactly).

use super::{Warp, subsample};
use crate::content::Locate;
use glam::{DVec2, DVec3};
use rayon::prelude::*;
use std::ops::Range;

/// Lattice node spacing, in samples.
pub const STEP: usize = 16;

/// Largest deviation from the exact position a cell may show at its check points, in texels.
const ACCEPT: f64 = 1.0 / 4096.0;

/// Largest deviation of an interpolated position from the exact one, in texels: a quarter of
/// the renderer's finest weight step (1/256 texel), so the fixed-point bilinear weights of a
/// sample differ from the exact plan's by at most one step, and only at rounding boundaries.
pub const BOUND: f64 = 1.0 / 1024.0;

/// How close to a content seam an interpolated position may come before the sample is computed
/// exactly, in texels: twice the bound, so that a position on the wrong side of a seam, which
/// is at most [`BOUND`] from the exact one across it, always falls inside.
const SEAM_MARGIN: f64 = 2.0 * BOUND;

type Pos = Option<(f64, f64)>;
type Dir = Option<DVec3>;

/// How the samples of a lattice cell get their positions.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Cell {
    Exact,
    /// Positions interpolated.
    Positions,
    /// Directions interpolated, then located.
    Directions,
}

/// Lagrange weights of a sample over its stencil of four lattice nodes along one axis.
#[derive(Debug, Clone, Copy)]
struct Stencil {
    /// First of the four nodes.
    first: usize,
    /// The cell the sample lies in (between node `cell` and `cell + 1`).
    cell: usize,
    weights: [f64; 4],
}

/// Node positions along an axis of `n` samples: every `STEP`th, and the last sample.
fn nodes(n: usize) -> Vec<usize> {
    let mut v: Vec<usize> = (0..n).step_by(STEP).collect();
    if *v.last().unwrap_or(&0) != n.saturating_sub(1) {
        v.push(n - 1);
    }
    v
}

/// The stencil of every sample along an axis.
fn stencils(nodes: &[usize], n: usize) -> Vec<Stencil> {
    let last_cell = nodes.len() - 2;
    let mut cell = 0;
    (0..n)
        .map(|i| {
            while cell < last_cell && nodes[cell + 1] <= i {
                cell += 1;
            }
            // The middle cell of its stencil where the lattice allows; one-sided at the ends.
            let first = cell.saturating_sub(1).min(nodes.len() - 4);
            let xs: [f64; 4] = std::array::from_fn(|m| nodes[first + m] as f64);
            let x = i as f64;
            let weights = std::array::from_fn(|m| {
                (0..4)
                    .filter(|&q| q != m)
                    .map(|q| (x - xs[q]) / (xs[m] - xs[q]))
                    .product()
            });
            Stencil {
                first,
                cell,
                weights,
            }
        })
        .collect()
}

/// Along a row, a cell's values are the cubic through its four node columns: the value at a
/// sample with weights `w`.
#[inline(always)]
fn cubic<V>(nodes: &[V], w: &[f64; 4]) -> V
where
    V: Copy + std::ops::Add<Output = V> + std::ops::Mul<f64, Output = V>,
{
    nodes[0] * w[0] + nodes[1] * w[1] + nodes[2] * w[2] + nodes[3] * w[3]
}

/// The sample rows (of `n`) whose positions can change when the warp changes in rows `changed`:
/// those whose stencil reaches into them, and the changed rows themselves.
pub(crate) fn dependents(n: usize, changed: Range<usize>) -> Range<usize> {
    let xs = nodes(n);
    if xs.len() < 4 || changed.is_empty() {
        return changed;
    }
    let reads = |s: &Stencil| xs[s.first]..=xs[s.first + 3];
    let hit: Vec<usize> = stencils(&xs, n)
        .iter()
        .enumerate()
        .filter(|(j, s)| {
            changed.contains(j)
                || (*reads(s).start() < changed.end && changed.start <= *reads(s).end())
        })
        .map(|(j, _)| j)
        .collect();
    hit[0]..hit[hit.len() - 1] + 1
}

/// The sample positions of one warp against one content layout.
pub(crate) struct Sampler<'a, L: Locate> {
    warp: Warp<'a>,
    content: &'a L,
    width: u32,
    height: u32,
    k: u32,
    /// Samples per row (output width × supersampling).
    sw: usize,
    /// Exact positions at the lattice nodes, row by row; empty when the image is too small
    /// for a lattice (then every sample is exact).
    lattice: Vec<Option<DVec2>>,
    /// Exact directions at the lattice nodes where the content has seams to interpolate
    /// directions across ([`Locate::has_seams`]); empty otherwise.
    directions: Vec<Dir>,
    columns: Vec<usize>,
    col: Vec<Stencil>,
    row: Vec<Stencil>,
    /// How each cell (row-major over the lattice's cells) is sampled.
    cells: Vec<Cell>,
    /// For nearest filtering: recompute exactly what lies near a texel's rounding boundary.
    nearest: bool,
    /// The content's [`Locate::bounds`].
    bounds: Option<[f64; 4]>,
    /// The content's [`Locate::circle`].
    circle: Option<[f64; 3]>,
}

impl<'a, L: Locate> Sampler<'a, L> {
    /// A sampler for sample rows `window` of the image (`0..height × k` for all of it): only
    /// the lattice those rows read is computed, and their positions are those a sampler of the
    /// whole image gives.
    pub(crate) fn new(
        warp: Warp<'a>,
        content: &'a L,
        [width, height, k]: [u32; 3],
        nearest: bool,
        lattice: bool,
        window: Range<usize>,
    ) -> Self {
        let sw = width as usize * k as usize;
        let sh = height as usize * k as usize;
        let mut s = Sampler {
            warp,
            content,
            width,
            height,
            k,
            sw,
            lattice: Vec::new(),
            directions: Vec::new(),
            columns: Vec::new(),
            col: Vec::new(),
            row: Vec::new(),
            cells: Vec::new(),
            nearest,
            bounds: content.bounds(),
            circle: content.circle(),
        };
        let (columns, rows) = (nodes(sw), nodes(sh));
        if !lattice || columns.len() < 4 || rows.len() < 4 {
            return s;
        }
        let (nx, ny) = (columns.len(), rows.len());
        s.col = stencils(&columns, sw);
        s.row = stencils(&rows, sh);
        let window = window.start.min(sh)..window.end.min(sh);
        // The cell rows the window's samples lie in, and the node rows their stencils read.
        let (cells, needed) = if window.is_empty() {
            (0..0, 0..0)
        } else {
            let (a, b) = (&s.row[window.start], &s.row[window.end - 1]);
            // One node row more than the stencils: a cell's check on its lower edge lies in
            // the next cell's stencil.
            (a.cell..b.cell + 1, a.first..(b.first + 5).min(ny))
        };
        let mut lattice = vec![None; nx * ny];
        // Directions are kept only where cells may interpolate them, and then located from.
        let mut directions = vec![None; if content.has_seams() { nx * ny } else { 0 }];
        let node_rows = needed.start * nx..needed.end * nx;
        if !directions.is_empty() {
            directions[node_rows.clone()]
                .par_chunks_mut(nx)
                .zip(&rows[needed.clone()])
                .for_each(|(row, &j)| {
                    for (d, &i) in row.iter_mut().zip(&columns) {
                        *d = s.direction(i, j);
                    }
                });
        }
        lattice[node_rows.clone()]
            .par_chunks_mut(nx)
            .zip(&rows[needed])
            .enumerate()
            .for_each(|(r, (row, &j))| {
                let at = node_rows.start + r * nx;
                let kept = (!directions.is_empty()).then(|| &directions[at..at + nx]);
                for (c, (p, &i)) in row.iter_mut().zip(&columns).enumerate() {
                    let d = kept.map_or_else(|| s.direction(i, j), |kept| kept[c]);
                    *p = d.and_then(|d| s.content.locate(d)).map(DVec2::from);
                }
            });
        s.lattice = lattice;
        s.directions = directions;
        s.columns = columns;
        let mut kinds = vec![Cell::Exact; (ny - 1) * (nx - 1)];
        kinds[cells.start * (nx - 1)..cells.end * (nx - 1)]
            .par_iter_mut()
            .enumerate()
            .for_each(|(c, kind)| {
                let (cx, cy) = (c % (nx - 1), cells.start + c / (nx - 1));
                *kind = s.classify(cx, cy, &rows);
            });
        s.cells = kinds;
        s
    }

    /// The exact direction of sample (i, j).
    #[inline]
    fn direction(&self, i: usize, j: usize) -> Dir {
        let (x, y) = if self.k == 1 {
            // The common case, without the four integer divisions below.
            (i as f64 + 0.5, j as f64 + 0.5)
        } else {
            let k = self.k as usize;
            subsample(i / k, j / k, (i % k) as u32, (j % k) as u32, self.k)
        };
        self.warp.direction(x, y, self.width, self.height)
    }

    /// The exact position of sample (i, j). Kept out of line: inlined into the interpolation
    /// loop, its register pressure slowed every interpolated sample.
    #[inline(never)]
    fn exact(&self, i: usize, j: usize) -> Pos {
        self.direction(i, j).and_then(|v| self.content.locate(v))
    }

    /// The node values around sample (i, j) blended by its stencil's weights, if all 16 are
    /// known.
    fn blend<V>(&self, nodes: &[Option<V>], i: usize, j: usize) -> Option<V>
    where
        V: Copy + Default + std::ops::Add<Output = V> + std::ops::Mul<f64, Output = V>,
    {
        let (sx, sy) = (&self.col[i], &self.row[j]);
        let nx = self.columns.len();
        let mut v = V::default();
        for (b, wy) in sy.weights.iter().enumerate() {
            for (a, wx) in sx.weights.iter().enumerate() {
                v = v + nodes[(sy.first + b) * nx + sx.first + a]? * (wy * wx);
            }
        }
        Some(v)
    }

    /// The lattice's node columns interpolated down to the row of stencil `sy`, once for the
    /// whole row (a cell's stencil is covered: checked when the cell was).
    fn down<V>(&self, nodes: &[Option<V>], sy: &Stencil) -> Vec<V>
    where
        V: Copy + Default + std::ops::Add<Output = V> + std::ops::Mul<f64, Output = V>,
    {
        let nx = self.columns.len();
        (0..nx)
            .map(|c| {
                let mut v = V::default();
                for (b, &w) in sy.weights.iter().enumerate() {
                    v = v + nodes[(sy.first + b) * nx + c].unwrap_or_default() * w;
                }
                v
            })
            .collect()
    }

    /// How cell (cx, cy) is sampled: positions interpolated where they agree with the exact
    /// ones at its centre and edge midpoints within `ACCEPT`, else directions where the
    /// content has seams and their located positions agree so, else exactly.
    fn classify(&self, cx: usize, cy: usize, rows: &[usize]) -> Cell {
        let (x0, x1) = (self.columns[cx], self.columns[cx + 1]);
        let (y0, y1) = (rows[cy], rows[cy + 1]);
        let (xm, ym) = ((x0 + x1) / 2, (y0 + y1) / 2);
        let points = [(xm, ym), (xm, y0), (x0, ym), (xm, y1), (x1, ym)];
        let close = |a: Option<DVec2>, b: Pos| match (a, b) {
            (Some(a), Some(b)) => (a.x - b.0).abs() <= ACCEPT && (a.y - b.1).abs() <= ACCEPT,
            _ => false,
        };
        let mut exact: [Option<Pos>; 5] = [None; 5];
        let mut exact_at =
            |n: usize| *exact[n].get_or_insert_with(|| self.exact(points[n].0, points[n].1));
        if (0..5).all(|n| {
            close(
                self.blend(&self.lattice, points[n].0, points[n].1),
                exact_at(n),
            )
        }) {
            return Cell::Positions;
        }
        let located = |(i, j): (usize, usize)| {
            let d = self.blend(&self.directions, i, j)?;
            self.content.locate(d).map(DVec2::from)
        };
        if !self.directions.is_empty() && (0..5).all(|n| close(located(points[n]), exact_at(n))) {
            return Cell::Directions;
        }
        Cell::Exact
    }

    /// The positions of sample row `j`, passed to `emit` in column order, `sw` of them.
    #[inline]
    pub(crate) fn row(&self, j: usize, mut emit: impl FnMut(Pos)) {
        if self.lattice.is_empty() {
            (0..self.sw).for_each(|i| emit(self.exact(i, j)));
            return;
        }
        let nx = self.columns.len();
        let sy = &self.row[j];
        let cells = &self.cells[sy.cell * (nx - 1)..(sy.cell + 1) * (nx - 1)];
        let positions: Vec<DVec2> = self.down(&self.lattice, sy);
        let directions: Vec<DVec3> = if cells.contains(&Cell::Directions) {
            self.down(&self.directions, sy)
        } else {
            Vec::new()
        };
        // Only normal maps (never supersampled) have per-pixel holes.
        let holes = match self.warp {
            Warp::Map(map) => Some(map),
            Warp::View(_) | Warp::CubeFace(_) => None,
        };
        for (cx, &cell) in cells.iter().enumerate() {
            let start = self.columns[cx];
            // The last cell owns its right edge too.
            let end = if cx + 2 == nx {
                self.sw
            } else {
                self.columns[cx + 1]
            };
            let first = self.col[start].first;
            let position = |i: usize| -> Pos {
                let p = cubic(&positions[first..first + 4], &self.col[i].weights);
                if self.near_a_boundary(p.x, p.y) {
                    self.exact(i, j)
                } else {
                    Some((p.x, p.y))
                }
            };
            let located = |i: usize| -> Pos {
                let d = cubic(&directions[first..first + 4], &self.col[i].weights);
                match self.content.locate_clear(d, SEAM_MARGIN) {
                    Some((x, y)) if !self.near_a_boundary(x, y) => Some((x, y)),
                    _ => self.exact(i, j),
                }
            };
            let covered = |i: usize| holes.is_none_or(|map| map.covers(i, j));
            match cell {
                Cell::Exact => (start..end).for_each(|i| emit(self.exact(i, j))),
                Cell::Positions => {
                    (start..end).for_each(|i| emit(if covered(i) { position(i) } else { None }))
                }
                Cell::Directions => {
                    (start..end).for_each(|i| emit(if covered(i) { located(i) } else { None }))
                }
            }
        }
    }

    /// Whether an interpolated position is too close to a decision the exact one makes: the
    /// edge of the content's domain, or (nearest filtering) a texel's rounding boundary.
    #[inline]
    fn near_a_boundary(&self, x: f64, y: f64) -> bool {
        // Positions near a decision are never negative (the atlas has a border), and `floor`
        // is a library call on baseline x86-64.
        let half = |v: f64| (v - (v as i64) as f64 - 0.5).abs() <= BOUND;
        (self.nearest && (half(x) || half(y)))
            || self.bounds.is_some_and(|[x0, y0, x1, y1]| {
                let near = |v: f64, lo: f64, hi: f64| v <= lo + BOUND || v >= hi - BOUND;
                near(x, x0, x1) || near(y, y0, y1)
            })
            || self.circle.is_some_and(|[cx, cy, r]| {
                let (dx, dy) = (x - cx, y - cy);
                dx * dx + dy * dy >= (r - BOUND) * (r - BOUND)
            })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nodes_end_on_the_last_sample_and_stencils_reproduce_cubics() {
        assert_eq!(nodes(33), vec![0, 16, 32]);
        assert_eq!(nodes(34), vec![0, 16, 32, 33]);
        let n = 70;
        let xs = nodes(n);
        let f = |x: f64| 0.5 + 0.25 * x - 1e-3 * x * x + 2e-5 * x * x * x;
        for (i, s) in stencils(&xs, n).iter().enumerate() {
            let v: f64 = (0..4)
                .map(|m| s.weights[m] * f(xs[s.first + m] as f64))
                .sum();
            assert!(
                (v - f(i as f64)).abs() < 1e-9,
                "sample {i}: {v} vs {}",
                f(i as f64)
            );
            assert!(xs[s.cell] <= i && (i <= xs[s.cell + 1]));
        }
    }

    /// Across a cube map's face seams positions jump but directions do not: a 360° × 100°
    /// cylinder at 3840 × 1080, crossing four seams and the edges of both caps, has its seam
    /// cells interpolated in directions, none computed sample by sample, and every located
    /// sample within the bound of the exact one, on the face the exact one is on, and exact
    /// next to a seam. (At a third of the size the lattice is too coarse for the caps' edges
    /// in either form, and some cells there are exact.)
    #[test]
    fn seam_cells_interpolate_directions() {
        use crate::content::Content;
        use crate::cubemap::CubeMap;
        use crate::projection::{self, Orientation, Params, View};

        let (w, h) = (3840u32, 1080u32);
        let params = Params {
            hfov: Some(360.0),
            vfov: Some(100.0),
            ..Params::default()
        };
        let projection = projection::build("cylindrical", &params, f64::from(h) / f64::from(w));
        let view = View::new(
            projection.unwrap(),
            Orientation::default(),
            DVec3::ZERO,
            1.0,
        );
        let view = view.unwrap();
        let cube = CubeMap::<[u8; 4]>::from_fn(128, 1, |_| [0; 4]);
        let content = Content::cube(&cube);
        let sampler = Sampler::new(
            Warp::View(&view),
            &content,
            [w, h, 1],
            false,
            true,
            0..h as usize,
        );
        let count = |kind| sampler.cells.iter().filter(|&&c| c == kind).count();
        let (positions, directions) = (count(Cell::Positions), count(Cell::Directions));
        assert_eq!(
            count(Cell::Exact),
            0,
            "cells computed sample by sample ({directions} in directions)"
        );
        assert!(
            directions > 60 && positions > directions,
            "{directions} of {positions}"
        );
        let face = |y: f64| (y / (128 + 2 * crate::content::PAD) as f64) as usize;
        let (mut located, mut worst) = (0, 0.0f64);
        for j in 0..h as usize {
            let mut i = 0;
            let nx = sampler.columns.len();
            sampler.row(j, |p| {
                let cell = sampler.cells[sampler.row[j].cell * (nx - 1) + sampler.col[i].cell];
                let exact = sampler.exact(i, j);
                if cell == Cell::Directions && p != exact {
                    let ((x, y), (ex, ey)) = (p.unwrap(), exact.unwrap());
                    assert!(
                        !content.near_a_seam(x, y, SEAM_MARGIN),
                        "sample ({i}, {j}) located next to a seam"
                    );
                    assert_eq!(face(y), face(ey), "sample ({i}, {j}) on another face");
                    worst = worst.max((x - ex).abs().max((y - ey).abs()));
                    located += 1;
                }
                i += 1;
            });
        }
        assert!(located > 10_000, "{located} samples located");
        assert!(worst <= BOUND, "{worst} texel off");
    }

    /// Cube positions near a face's edge, on any face of the stacked atlas, are near a seam;
    /// the face's inside is not.
    #[test]
    fn a_cube_points_out_its_seams() {
        use crate::content::{Content, PAD};
        use crate::cubemap::CubeMap;

        let n = 64;
        let content = Content::cube(&CubeMap::<[u8; 4]>::from_fn(n, 1, |_| [0; 4]));
        assert!(content.has_seams());
        let (lo, hi) = (PAD as f64 - 0.5, (n + PAD) as f64 - 0.5);
        let block = (n + 2 * PAD) as f64;
        for face in 0..6 {
            let y0 = face as f64 * block;
            let mid = (lo + hi) / 2.0;
            for (x, y, near) in [
                (mid, y0 + mid, false),
                (lo + 0.01, y0 + mid, false),
                (lo + 0.001, y0 + mid, true),
                (hi - 0.001, y0 + mid, true),
                (mid, y0 + lo + 0.001, true),
                (mid, y0 + hi - 0.001, true),
                (mid, y0 + hi - 0.01, false),
            ] {
                assert_eq!(
                    content.near_a_seam(x, y, 0.002),
                    near,
                    "face {face}: ({x}, {y})"
                );
            }
        }
        let pano = crate::raster::Raster::<[u8; 4]>::new(64, 32);
        let pano = Content::equirect(&pano, 360.0, 180.0).unwrap();
        assert!(!pano.has_seams());
    }

    /// The direction cells' lookup, `locate_clear`, is `locate` to within a few ulps (it
    /// multiplies where `locate` divides), and refuses exactly what `near_a_seam` calls near a
    /// seam, on every face, including directions aimed at a seam to within the margin.
    #[test]
    fn a_cube_locates_clear_of_its_seams_as_locate_does() {
        use crate::content::Content;
        use crate::cubemap::CubeMap;

        let n = 64;
        let cube = CubeMap::<[u8; 4]>::from_fn(n, 1, |_| [0; 4]);
        let turned = crate::projection::Orientation::yaw_pitch_roll(30.0, 20.0, 10.0).unwrap();
        for content in [
            Content::cube(&cube),
            Content::cube(&cube).with_orientation(turned),
        ] {
            locates_clear(&content);
        }
    }

    fn locates_clear(content: &crate::content::Content<[u8; 4]>) {
        let margin = 0.01;
        let mut next = crate::raster::xorshift(7);
        let mut unit = || (next() >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0;
        let (mut clear, mut refused) = (0, 0);
        for k in 0..200_000 {
            let mut d = DVec3::new(unit(), unit(), unit());
            if k % 2 == 0 {
                // Onto the seam between the faces of its two largest components, then a
                // little off it: a quarter of these fall within the margin.
                let mut c = [d.x, d.y, d.z];
                let mut order = [0, 1, 2];
                order.sort_by(|&a, &b| c[b].abs().total_cmp(&c[a].abs()));
                c[order[1]] = c[order[0]].abs().copysign(c[order[1]]) * (1.0 - 2e-3 * unit().abs());
                d = content.orientation().apply(DVec3::from_array(c));
            }
            let exact = content.locate(d).expect("a cube covers every direction");
            match content.locate_clear(d, margin) {
                Some(p) => {
                    clear += 1;
                    assert!(!content.near_a_seam(exact.0, exact.1, margin), "{d}");
                    let off = (p.0 - exact.0).abs().max((p.1 - exact.1).abs());
                    assert!(off < 1e-11, "{d}: {p:?} vs {exact:?}");
                }
                None => {
                    refused += 1;
                    // Ties at the margin itself may go either way by an ulp.
                    let barely = [margin - 1e-9, margin + 1e-9];
                    assert!(
                        barely
                            .iter()
                            .any(|&m| content.near_a_seam(exact.0, exact.1, m)),
                        "{d} refused at {exact:?}"
                    );
                }
            }
        }
        assert!(
            clear > 100_000 && refused > 10_000,
            "{clear} clear, {refused} refused"
        );
    }
}
