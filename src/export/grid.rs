//! Warp grids for media servers: a per-pixel field (content u, v or wall X, Y, Z) sampled on a
//! uniform grid the reader interpolates bilinearly, with the grid's density chosen from an error
//! tolerance rather than fixed.
//!
//! Readers place the samples in one of two ways ([`Layout`]): edge to edge, the first and last of
//! a row on the image's left and right edges (normalised position i / (n − 1)), as nDisplay's
//! mesh builder, SGCT and Paul Bourke's meshes do; or at cell centres ((i + ½) / n), as a reader
//! that uploads the grid as a texture and samples it at each pixel does (PyMPCDI), clamping
//! half a cell at every border. Positions below are in pixel-centre coordinates, pixel (0, 0)'s
//! centre at (0, 0), as lens models and tile screens count them, so edge-to-edge sample 0 sits
//! at −½.

use rayon::prelude::*;
use std::sync::atomic::{AtomicBool, Ordering};

/// Where a reader places a grid's samples on the image.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Layout {
    /// Sample i of n at normalised position i / (n − 1): the outer samples on the image edges.
    Edges,
    /// Sample i of n at (i + ½) / n, the centre of its cell: a grid read as a texture.
    Centres,
}

impl Layout {
    /// Pixel-centre position of sample `i` of `n` across an image `size` pixels wide.
    pub fn position(self, i: usize, n: usize, size: usize) -> f64 {
        match self {
            Layout::Edges => i as f64 * size as f64 / (n - 1) as f64 - 0.5,
            Layout::Centres => (i as f64 + 0.5) * size as f64 / n as f64 - 0.5,
        }
    }

    /// Inverse of [`Layout::position`]: the (fractional) sample index at pixel-centre
    /// coordinate `p`.
    pub fn index(self, p: f64, n: usize, size: usize) -> f64 {
        match self {
            Layout::Edges => (p + 0.5) * (n - 1) as f64 / size as f64,
            Layout::Centres => (p + 0.5) * n as f64 / size as f64 - 0.5,
        }
    }

    /// The grid that reproduces a field exactly: a sample on every pixel corner (edges) or
    /// centre (centres).
    fn exact(self, width: usize, height: usize) -> (usize, usize) {
        match self {
            Layout::Edges => (width + 1, height + 1),
            Layout::Centres => (width, height),
        }
    }
}

/// How a reader fills a cell between its four nodes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Cells {
    /// Bilinearly (a texture sampler, most warp players).
    Bilinear,
    /// Two triangles sharing the diagonal from the cell's top-left node to its bottom-right one
    /// (image rows top to bottom): Celestia's warp mesh.
    TopLeftDiagonal,
    /// Two triangles sharing the diagonal from the bottom-left node to the top-right one: SGCT's
    /// Paul Bourke mesh.
    BottomLeftDiagonal,
    /// Any of the three: the error is the worst of them, so the grid holds its tolerance
    /// whichever way the reader splits a cell (a reader not named, or one that alternates).
    Any,
}

/// Which grids a reader can draw.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Shape {
    /// Any: rows follow the image's aspect ratio.
    Free,
    /// As many rows as columns, at most `max` nodes a side. Celestia draws a mesh's cells with
    /// the column count for both loops (`setIndices` in `warpmesh.cpp`): only a square grid is
    /// drawn whole and in bounds. Its loader refuses more than 1,024 nodes a side.
    Square {
        /// Most nodes a side.
        max: usize,
    },
}

/// How a reader reads a grid: where it places the nodes, how it fills the cells and which
/// grids it can draw.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Reading {
    /// Where the reader places the nodes on the image.
    pub layout: Layout,
    /// How the reader fills a cell between four nodes.
    pub cells: Cells,
    /// Which grids the reader can draw.
    pub shape: Shape,
}

impl Reading {
    /// Nodes edge to edge, cells bilinear.
    pub const BILINEAR: Reading = Reading {
        layout: Layout::Edges,
        cells: Cells::Bilinear,
        shape: Shape::Free,
    };
}

/// A uniform grid of samples, row-major from the top row; `None` where the field has none.
#[derive(Debug, Clone, PartialEq)]
pub struct Grid<const N: usize> {
    /// Nodes across: the length of a row of `samples`.
    pub columns: usize,
    /// Nodes down: the number of rows of `samples`.
    pub rows: usize,
    /// How the grid's reader reads it, which sets where its nodes lie on the image.
    pub reading: Reading,
    /// The `columns` × `rows` node values: content (u, v) or wall X, Y, Z, metres.
    pub samples: Vec<Option<[f64; N]>>,
}

/// The four corner indices around fractional index (gx, gy) of a columns × rows lattice,
/// clamped to it, and their weights as `cells` fills the cell (one is 0 for a triangle;
/// [`Cells::Any`] is taken as bilinear here, see [`Grid::max_error`]).
fn corners(gx: f64, gy: f64, columns: usize, rows: usize, cells: Cells) -> ([usize; 4], [f64; 4]) {
    let gx = gx.clamp(0.0, (columns - 1) as f64);
    let gy = gy.clamp(0.0, (rows - 1) as f64);
    let (x0, y0) = (
        (gx.floor() as usize).min(columns.saturating_sub(2)),
        (gy.floor() as usize).min(rows.saturating_sub(2)),
    );
    let (x1, y1) = ((x0 + 1).min(columns - 1), (y0 + 1).min(rows - 1));
    let (fx, fy) = (gx - x0 as f64, gy - y0 as f64);
    // Weights of the top-left, top-right, bottom-left and bottom-right nodes.
    let weights = match cells {
        Cells::Bilinear | Cells::Any => [
            (1.0 - fx) * (1.0 - fy),
            fx * (1.0 - fy),
            (1.0 - fx) * fy,
            fx * fy,
        ],
        Cells::TopLeftDiagonal if fx >= fy => [1.0 - fx, fx - fy, 0.0, fy],
        Cells::TopLeftDiagonal => [1.0 - fy, 0.0, fy - fx, fx],
        Cells::BottomLeftDiagonal if fx + fy <= 1.0 => [1.0 - fx - fy, fx, fy, 0.0],
        Cells::BottomLeftDiagonal => [0.0, 1.0 - fy, 1.0 - fx, fx + fy - 1.0],
    };
    (
        [
            y0 * columns + x0,
            y0 * columns + x1,
            y1 * columns + x0,
            y1 * columns + x1,
        ],
        weights,
    )
}

/// Interpolation of `values` (a columns × rows lattice) at (gx, gy), filling cells as `cells`
/// says; `None` when a corner that carries weight has no value — a reader would blend into an
/// invalid sample there.
fn interpolate<const N: usize>(
    values: &[Option<[f64; N]>],
    columns: usize,
    rows: usize,
    (gx, gy): (f64, f64),
    cells: Cells,
) -> Option<[f64; N]> {
    let (idx, wt) = corners(gx, gy, columns, rows, cells);
    let mut out = [0.0; N];
    for (i, w) in idx.into_iter().zip(wt) {
        if w == 0.0 {
            continue;
        }
        let v = values[i]?;
        for c in 0..N {
            out[c] += w * v[c];
        }
    }
    Some(out)
}

/// Samples a width × height field on a columns × rows grid.
///
/// A node between valid pixels is interpolated bilinearly; one next to an invalid pixel is
/// extrapolated (first order) from the nearest valid pixel within a cell's reach, so that a
/// reader interpolating the grid covers every valid pixel up to the field's edge (the
/// extrapolation error counts like any other and refines the grid when too large). Only nodes
/// with no valid pixel within a cell stay `None`; the alpha mask is zero around them.
pub fn sample<const N: usize>(
    field: &[Option<[f64; N]>],
    width: usize,
    height: usize,
    columns: usize,
    rows: usize,
    reading: Reading,
) -> Grid<N> {
    let layout = reading.layout;
    let reach_x = (width as f64 / (columns.max(2) - 1) as f64).ceil() as isize;
    let reach_y = (height as f64 / (rows.max(2) - 1) as f64).ceil() as isize;
    let samples = (0..columns * rows)
        .into_par_iter()
        .map(|n| {
            let x = layout.position(n % columns, columns, width);
            let y = layout.position(n / columns, rows, height);
            // Nodes on the image's outer edges lie half a pixel beyond the outermost centres:
            // extrapolate there too rather than let interpolation clamp.
            let within =
                (0.0..=(width - 1) as f64).contains(&x) && (0.0..=(height - 1) as f64).contains(&y);
            within
                .then(|| interpolate(field, width, height, (x, y), Cells::Bilinear))
                .flatten()
                .or_else(|| nearest_valid(field, width, height, x, y, reach_x, reach_y))
        })
        .collect();
    Grid {
        columns,
        rows,
        reading,
        samples,
    }
}

/// A first-order extrapolation to (x, y) from the valid pixel nearest it within ±reach pixels:
/// its value plus the field's gradient there (central differences where both neighbours are
/// valid, one-sided where one is), times the offset.
fn nearest_valid<const N: usize>(
    field: &[Option<[f64; N]>],
    width: usize,
    height: usize,
    x: f64,
    y: f64,
    reach_x: isize,
    reach_y: isize,
) -> Option<[f64; N]> {
    let (cx, cy) = (x.round() as isize, y.round() as isize);
    let mut best: Option<(f64, usize, usize)> = None;
    for j in (cy - reach_y).max(0)..=(cy + reach_y).min(height as isize - 1) {
        for i in (cx - reach_x).max(0)..=(cx + reach_x).min(width as isize - 1) {
            if field[j as usize * width + i as usize].is_some() {
                let d = (i as f64 - x).powi(2) + (j as f64 - y).powi(2);
                if best.is_none_or(|(b, _, _)| d < b) {
                    best = Some((d, i as usize, j as usize));
                }
            }
        }
    }
    let (_, i, j) = best?;
    let at = |i: usize, j: usize| field[j * width + i];
    let v = at(i, j)?;
    let slope = |lo: Option<[f64; N]>, hi: Option<[f64; N]>| -> [f64; N] {
        let mut d = [0.0; N];
        match (lo, hi) {
            (Some(a), Some(b)) => (0..N).for_each(|c| d[c] = (b[c] - a[c]) / 2.0),
            (Some(a), None) => (0..N).for_each(|c| d[c] = v[c] - a[c]),
            (None, Some(b)) => (0..N).for_each(|c| d[c] = b[c] - v[c]),
            (None, None) => {}
        }
        d
    };
    let gx = slope(
        i.checked_sub(1).and_then(|i| at(i, j)),
        (i + 1 < width).then(|| at(i + 1, j)).flatten(),
    );
    let gy = slope(
        j.checked_sub(1).and_then(|j| at(i, j)),
        (j + 1 < height).then(|| at(i, j + 1)).flatten(),
    );
    let (dx, dy) = (x - i as f64, y - j as f64);
    let mut out = v;
    for c in 0..N {
        out[c] += gx[c] * dx + gy[c] * dy;
    }
    Some(out)
}

impl<const N: usize> Grid<N> {
    /// What a reader filling cells as `cells` says shows at pixel (i, j).
    pub fn at_pixel(
        &self,
        i: usize,
        j: usize,
        width: usize,
        height: usize,
        cells: Cells,
    ) -> Option<[f64; N]> {
        let layout = self.reading.layout;
        let gx = layout.index(i as f64, self.columns, width);
        let gy = layout.index(j as f64, self.rows, height);
        interpolate(&self.samples, self.columns, self.rows, (gx, gy), cells)
    }

    /// Largest distance between what the grid's reader interpolates and the field over the
    /// field's valid pixels (infinite if the grid leaves one uncovered); components are
    /// multiplied by `scale` first (content pixels per unit, millimetres per metre). For
    /// [`Cells::Any`], the worst of the three ways to fill a cell.
    pub fn max_error(
        &self,
        field: &[Option<[f64; N]>],
        width: usize,
        height: usize,
        scale: [f64; N],
    ) -> f64 {
        self.error_within(field, width, height, scale, f64::INFINITY)
            .unwrap_or(f64::INFINITY)
    }

    /// [`Grid::max_error`] if it is at most `limit`, else `None` as soon as one pixel shows
    /// more: a grid the tolerance search rejects costs a few rows, not the whole image.
    pub fn error_within(
        &self,
        field: &[Option<[f64; N]>],
        width: usize,
        height: usize,
        scale: [f64; N],
        limit: f64,
    ) -> Option<f64> {
        let ways: &[Cells] = match self.reading.cells {
            Cells::Any => &[
                Cells::Bilinear,
                Cells::TopLeftDiagonal,
                Cells::BottomLeftDiagonal,
            ],
            one => &[one],
        };
        let over = AtomicBool::new(false);
        let worst = (0..height)
            .into_par_iter()
            .map(|j| {
                let mut worst = 0.0f64;
                if over.load(Ordering::Relaxed) {
                    return worst;
                }
                for i in 0..width {
                    let Some(exact) = field[j * width + i] else {
                        continue;
                    };
                    for cells in ways {
                        let Some(got) = self.at_pixel(i, j, width, height, *cells) else {
                            over.store(true, Ordering::Relaxed);
                            return f64::INFINITY;
                        };
                        let d2: f64 = (0..N)
                            .map(|c| ((got[c] - exact[c]) * scale[c]).powi(2))
                            .sum();
                        worst = worst.max(d2.sqrt());
                    }
                    if worst > limit {
                        over.store(true, Ordering::Relaxed);
                        return worst;
                    }
                }
                worst
            })
            .reduce(|| 0.0, f64::max);
        (!over.load(Ordering::Relaxed) && worst <= limit).then_some(worst)
    }
}

/// The chosen grid and its measured worst error.
#[derive(Debug, Clone)]
pub struct Chosen<const N: usize> {
    /// The grid.
    pub grid: Grid<N>,
    /// Its worst interpolation error over the field's valid pixels, in the units of `scale`
    /// (content pixels, or millimetres on the wall); infinite if it leaves a pixel uncovered.
    pub max_error: f64,
}

/// The coarsest grid (columns growing by about √2 per step, rows keeping the image's aspect)
/// whose worst interpolation error, as `reading` says a reader reads it, is within `tolerance`;
/// the exact grid (`Layout::exact`) when none is. Grids stop at [`crate::limits::EXPORT_NODES`]: the finest grid tried is returned, and
/// the caller compares its `max_error` with the tolerance. [`Error::Cancelled`] once `cancel`
/// is set.
///
/// [`Error::Cancelled`]: crate::Error::Cancelled
pub fn choose<const N: usize>(
    field: &[Option<[f64; N]>],
    width: usize,
    height: usize,
    tolerance: f64,
    scale: [f64; N],
    reading: Reading,
    cancel: &AtomicBool,
) -> crate::Result<Chosen<N>> {
    let fits = |c: usize, r: usize| {
        c.checked_mul(r)
            .is_some_and(|n| n <= crate::limits::EXPORT_NODES)
    };
    let cancelled = || {
        if cancel.load(Ordering::Relaxed) {
            Err(crate::Error::Cancelled)
        } else {
            Ok(())
        }
    };
    // Grids the tolerance rejects are measured only until they fail; the one returned is
    // measured in full.
    let measured = |grid: Grid<N>| {
        let max_error = grid.max_error(field, width, height, scale);
        Chosen { grid, max_error }
    };
    let square = match reading.shape {
        Shape::Square { max } => Some(max.max(2)),
        Shape::Free => None,
    };
    let mut columns = 2usize;
    let mut finest: Option<Grid<N>> = None;
    while columns < square.map_or(width, |_| width.max(height)) {
        let rows = match square {
            Some(_) => columns,
            None => ((columns as f64 * height as f64 / width as f64).round() as usize).max(2),
        };
        if !fits(columns, rows) || square.is_some_and(|max| columns > max) {
            break;
        }
        cancelled()?;
        let grid = sample(field, width, height, columns, rows, reading);
        if let Some(max_error) = grid.error_within(field, width, height, scale, tolerance) {
            return Ok(Chosen { grid, max_error });
        }
        finest = Some(grid);
        columns = ((columns as f64 * std::f64::consts::SQRT_2).ceil() as usize).max(columns + 1);
    }
    let (columns, rows) = match square {
        // The finest square the reader and the node limit allow, no finer than exact.
        Some(max) => {
            let (c, r) = reading.layout.exact(width, height);
            let limit = (crate::limits::EXPORT_NODES as f64).sqrt() as usize;
            let n = c.max(r).min(max).min(limit);
            (n, n)
        }
        None => reading.layout.exact(width, height),
    };
    cancelled()?;
    Ok(match finest {
        Some(g) if !fits(columns, rows) => measured(g),
        _ => measured(sample(field, width, height, columns, rows, reading)),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A projective field (a plane seen in perspective) with an invalid corner region.
    fn field(w: usize, h: usize) -> Vec<Option<[f64; 2]>> {
        (0..w * h)
            .map(|n| {
                let (x, y) = ((n % w) as f64, (n / w) as f64);
                let d = 1.0 + 0.002 * x + 0.001 * y;
                (x + 2.0 * y > 40.0).then_some([(3.0 * x + 10.0) / d, (2.0 * y - x) / d])
            })
            .collect()
    }

    /// A reader written independently: normalised position u = (p + ½) / size, sample index
    /// u · (n − 1) (edges) or u · n − ½ clamped to the grid, as a texture sampler clamps to its
    /// edge (centres); within a cell bilinear, or along the two edges of the triangle the point
    /// falls in.
    fn read(g: &Grid<2>, cells: Cells, w: usize, h: usize, i: usize, j: usize) -> Option<[f64; 2]> {
        let to = |p: f64, n: usize, size: usize| {
            let u = (p + 0.5) / size as f64;
            match g.reading.layout {
                Layout::Edges => u * (n - 1) as f64,
                Layout::Centres => (u * n as f64 - 0.5).clamp(0.0, (n - 1) as f64),
            }
        };
        let (gx, gy) = (to(i as f64, g.columns, w), to(j as f64, g.rows, h));
        let (x0, y0) = (
            (gx.floor() as usize).min(g.columns - 2),
            (gy.floor() as usize).min(g.rows - 2),
        );
        let (fx, fy) = (gx - x0 as f64, gy - y0 as f64);
        let at = |x: usize, y: usize| g.samples[y * g.columns + x];
        let (tl, tr, bl, br) = (
            at(x0, y0),
            at(x0 + 1, y0),
            at(x0, y0 + 1),
            at(x0 + 1, y0 + 1),
        );
        // a + s·(b − a) + t·(c − d), componentwise.
        let walk = |a: [f64; 2], s: f64, b: [f64; 2], t: f64, c: [f64; 2], d: [f64; 2]| {
            [0, 1].map(|k| a[k] + s * (b[k] - a[k]) + t * (c[k] - d[k]))
        };
        Some(match cells {
            Cells::Bilinear | Cells::Any => {
                let (tl, tr, bl, br) = (tl?, tr?, bl?, br?);
                let top = walk(tl, fx, tr, 0.0, tl, tl);
                let bottom = walk(bl, fx, br, 0.0, bl, bl);
                walk(top, fy, bottom, 0.0, top, top)
            }
            Cells::TopLeftDiagonal if fx >= fy => walk(tl?, fx, tr?, fy, br?, tr?),
            Cells::TopLeftDiagonal => walk(tl?, fy, bl?, fx, br?, bl?),
            Cells::BottomLeftDiagonal if fx + fy <= 1.0 => walk(tl?, fx, tr?, fy, bl?, tl?),
            Cells::BottomLeftDiagonal => walk(br?, 1.0 - fx, bl?, 1.0 - fy, tr?, br?),
        })
    }

    #[test]
    fn chosen_grids_meet_the_tolerance_as_an_independent_reader_sees_them() {
        let (w, h) = (160, 90);
        let f = field(w, h);
        let cells = [
            Cells::Bilinear,
            Cells::TopLeftDiagonal,
            Cells::BottomLeftDiagonal,
            Cells::Any,
        ];
        let readings = cells
            .map(|cells| Reading {
                layout: Layout::Edges,
                cells,
                shape: Shape::Free,
            })
            .into_iter()
            .chain([
                Reading {
                    layout: Layout::Centres,
                    cells: Cells::Bilinear,
                    shape: Shape::Free,
                },
                Reading {
                    layout: Layout::Edges,
                    cells: Cells::TopLeftDiagonal,
                    shape: Shape::Square { max: 1024 },
                },
            ]);
        let mut coarsest = Vec::new();
        for reading in readings {
            let layout = reading.layout;
            let mut columns = Vec::new();
            for tol in [0.05, 0.2, 1.0] {
                let never = AtomicBool::new(false);
                let c = choose(&f, w, h, tol, [1.0, 1.0], reading, &never).unwrap();
                assert_eq!(c.grid.reading, reading);
                assert!(c.max_error <= tol, "{tol}: {}", c.max_error);
                if let Shape::Square { max } = reading.shape {
                    let g = &c.grid;
                    assert!(g.columns == g.rows && g.columns <= max, "{reading:?}");
                }
                let mut worst = 0.0f64;
                let ways: &[Cells] = match reading.cells {
                    Cells::Any => &cells[..3],
                    _ => std::slice::from_ref(&reading.cells),
                };
                for j in 0..h {
                    for i in 0..w {
                        if let Some(e) = f[j * w + i] {
                            for &way in ways {
                                let got = read(&c.grid, way, w, h, i, j).expect("covered");
                                worst = worst.max((got[0] - e[0]).hypot(got[1] - e[1]));
                            }
                        }
                    }
                }
                assert!(
                    (worst - c.max_error).abs() < 1e-9,
                    "{tol}: {worst} vs {}",
                    c.max_error
                );
                columns.push(c.grid.columns);
            }
            // Nodes at cell centres leave the outer half cell clamped, where this field's
            // slope of 3 allows no more than a third of a pixel: those grids are near exact.
            // Edge-to-edge grids follow the tolerance down.
            let coarser = |p: &[usize]| match layout {
                Layout::Edges => p[1] < p[0] && p[0] < w / 2,
                Layout::Centres => p[1] <= p[0],
            };
            assert!(columns.windows(2).all(coarser), "{reading:?}: {columns:?}");
            coarsest.push(columns[2]);
        }
        // Holding the tolerance for any reader costs at least what the hardest one needs.
        assert!(
            coarsest[3] >= coarsest[..3].iter().copied().max().unwrap(),
            "{coarsest:?}"
        );
    }

    #[test]
    fn a_square_reader_gets_square_grids_no_larger_than_it_draws() {
        let (w, h) = (160, 90);
        let f = field(w, h);
        let never = AtomicBool::new(false);
        let reading = Reading {
            layout: Layout::Edges,
            cells: Cells::TopLeftDiagonal,
            shape: Shape::Square { max: 12 },
        };
        // A tolerance no 12 × 12 grid meets: the finest square allowed, with its error.
        let c = choose(&f, w, h, 1e-6, [1.0, 1.0], reading, &never).unwrap();
        assert_eq!((c.grid.columns, c.grid.rows), (12, 12));
        assert!(c.max_error > 1e-6);
        // Where the cap is not reached, the grid is square as well.
        let c = choose(
            &f,
            w,
            h,
            0.3,
            [1.0, 1.0],
            Reading {
                shape: Shape::Square { max: 1024 },
                ..reading
            },
            &never,
        )
        .unwrap();
        assert_eq!(c.grid.columns, c.grid.rows);
    }

    /// The tolerance search stops measuring a grid once it fails; what it reports and chooses
    /// must be what measuring every pixel gives.
    #[test]
    fn measuring_until_a_grid_fails_agrees_with_measuring_it_all() {
        let (w, h) = (120, 80);
        let f = field(w, h);
        for (columns, rows) in [(2, 2), (5, 4), (9, 6), (30, 20), (120, 80)] {
            let g = sample(&f, w, h, columns, rows, Reading::BILINEAR);
            let full = g.max_error(&f, w, h, [1.0, 1.0]);
            for limit in [full * 0.5, full, full * 2.0] {
                assert_eq!(
                    g.error_within(&f, w, h, [1.0, 1.0], limit),
                    (full <= limit).then_some(full),
                    "{columns}×{rows} against {limit}"
                );
            }
        }
        let cancel = AtomicBool::new(false);
        for tolerance in [0.05, 0.5, 5.0] {
            let c = choose(&f, w, h, tolerance, [1.0, 1.0], Reading::BILINEAR, &cancel).unwrap();
            assert_eq!(c.max_error, c.grid.max_error(&f, w, h, [1.0, 1.0]));
            assert!(c.max_error <= tolerance, "{tolerance}: {}", c.max_error);
        }
    }
}
