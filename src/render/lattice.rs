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
//! [`ACCEPT`]. The centre is where the fourth-order error of a middle cell peaks, so a cell that
//! passes with this margin holds [`BOUND`] everywhere; `tests/exactness.rs` measures every
//! sample of a panel of views and contents against the exact positions. Cells that fail (seams
//! between cube faces, the ±180° wrap of a panorama, poles, the edge of a fisheye's circle or of
//! a partial panorama, kinks in an edited normal map) are computed exactly, sample by sample.
//!
//! What must not move at all is exact too: coverage (a normal map's holes and a partial
//! panorama's edge are checked per sample) and, for nearest filtering, the texel a sample picks
//! (samples within [`BOUND`] of a rounding boundary are computed exactly).

use super::{Warp, subsample};
use crate::content::Locate;
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

type Pos = Option<(f64, f64)>;

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
    lattice: Vec<Pos>,
    columns: Vec<usize>,
    col: Vec<Stencil>,
    row: Vec<Stencil>,
    /// Whether each cell (row-major over the lattice's cells) is interpolated.
    smooth: Vec<bool>,
    /// For nearest filtering: recompute exactly what lies near a texel's rounding boundary.
    nearest: bool,
    /// The content's [`Locate::bounds`].
    bounds: Option<[f64; 4]>,
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
            columns: Vec::new(),
            col: Vec::new(),
            row: Vec::new(),
            smooth: Vec::new(),
            nearest,
            bounds: content.bounds(),
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
        lattice[needed.start * nx..needed.end * nx]
            .par_chunks_mut(nx)
            .zip(&rows[needed])
            .for_each(|(line, &j)| {
                for (p, &i) in line.iter_mut().zip(&columns) {
                    *p = s.exact(i, j);
                }
            });
        s.lattice = lattice;
        s.columns = columns;
        let mut smooth = vec![false; (ny - 1) * (nx - 1)];
        smooth[cells.start * (nx - 1)..cells.end * (nx - 1)]
            .par_iter_mut()
            .enumerate()
            .for_each(|(c, smooth)| {
                let (cx, cy) = (c % (nx - 1), cells.start + c / (nx - 1));
                *smooth = s.cell_is_smooth(cx, cy, &rows);
            });
        s.smooth = smooth;
        s
    }

    /// The exact position of sample (i, j). Kept out of line: inlined into the interpolation
    /// loop, its register pressure slowed every interpolated sample.
    #[inline(never)]
    fn exact(&self, i: usize, j: usize) -> Pos {
        let (x, y) = if self.k == 1 {
            // The common case, without the four integer divisions below.
            (i as f64 + 0.5, j as f64 + 0.5)
        } else {
            let k = self.k as usize;
            subsample(i / k, j / k, (i % k) as u32, (j % k) as u32, self.k)
        };
        self.warp
            .direction(x, y, self.width, self.height)
            .and_then(|v| self.content.locate(v))
    }

    /// The interpolated position of sample (i, j), if its cell's stencil is covered.
    fn interpolated(&self, i: usize, j: usize) -> Pos {
        let (sx, sy) = (&self.col[i], &self.row[j]);
        let nx = self.columns.len();
        let (mut x, mut y) = (0.0, 0.0);
        for (b, wy) in sy.weights.iter().enumerate() {
            for (a, wx) in sx.weights.iter().enumerate() {
                let (px, py) = self.lattice[(sy.first + b) * nx + sx.first + a]?;
                x += wy * wx * px;
                y += wy * wx * py;
            }
        }
        Some((x, y))
    }

    fn cell_is_smooth(&self, cx: usize, cy: usize, rows: &[usize]) -> bool {
        let (x0, x1) = (self.columns[cx], self.columns[cx + 1]);
        let (y0, y1) = (rows[cy], rows[cy + 1]);
        let (xm, ym) = ((x0 + x1) / 2, (y0 + y1) / 2);
        [(xm, ym), (xm, y0), (x0, ym), (xm, y1), (x1, ym)]
            .iter()
            .all(
                |&(i, j)| match (self.interpolated(i, j), self.exact(i, j)) {
                    (Some(a), Some(b)) => {
                        (a.0 - b.0).abs() <= ACCEPT && (a.1 - b.1).abs() <= ACCEPT
                    }
                    _ => false,
                },
            )
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
        // The lattice's node columns interpolated down to this row, once for the whole row (a
        // smooth cell's stencil is covered: checked when the cell was).
        let blended: Vec<(f64, f64)> = (0..nx)
            .map(|c| {
                let (mut x, mut y) = (0.0, 0.0);
                for (b, w) in sy.weights.iter().enumerate() {
                    let (px, py) = self.lattice[(sy.first + b) * nx + c].unwrap_or_default();
                    x += w * px;
                    y += w * py;
                }
                (x, y)
            })
            .collect();
        let smooth = &self.smooth[sy.cell * (nx - 1)..(sy.cell + 1) * (nx - 1)];
        // Only normal maps (never supersampled) have per-pixel holes.
        let holes = match self.warp {
            Warp::Map(map) => Some(map),
            Warp::View(_) | Warp::CubeFace(_) => None,
        };
        for (cx, &smooth) in smooth.iter().enumerate() {
            let start = self.columns[cx];
            // The last cell owns its right edge too.
            let end = if cx + 2 == nx {
                self.sw
            } else {
                self.columns[cx + 1]
            };
            if !smooth {
                (start..end).for_each(|i| emit(self.exact(i, j)));
                continue;
            }
            let first = self.col[start].first;
            let nodes: [(f64, f64); 4] = std::array::from_fn(|m| blended[first + m]);
            for i in start..end {
                if holes.is_some_and(|map| !map.covers(i, j)) {
                    emit(None);
                    continue;
                }
                let w = &self.col[i].weights;
                let x =
                    w[0] * nodes[0].0 + w[1] * nodes[1].0 + w[2] * nodes[2].0 + w[3] * nodes[3].0;
                let y =
                    w[0] * nodes[0].1 + w[1] * nodes[1].1 + w[2] * nodes[2].1 + w[3] * nodes[3].1;
                emit(if self.near_a_boundary(x, y) {
                    self.exact(i, j)
                } else {
                    Some((x, y))
                });
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
}
