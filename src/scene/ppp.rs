//! Piecewise perspective projection (seed 003, Lorenz & Döllner): a non-planar view drawn
//! directly, without a cube map in between, as many small perspective views side by side.
//!
//! The output is cut into a grid of cells on pixel boundaries. A piece maps a pixel position
//! (x, y) to a direction by one linear map, `d = A·(x, y, 1)`, which is a pinhole camera at the
//! eye: the GPU rasterises each piece with `A⁻¹` as its projection matrix, clipped to the
//! piece by a scissor rectangle. A piece takes the true directions at its corners, so pieces
//! that share an edge interpolate the same two end vectors along it: neighbours match exactly
//! at shared edges and every pixel belongs to exactly one piece (no cracks, no overlaps).
//!
//! A cell is one piece when its four corners admit one linear map (a parallelogram of vectors),
//! else two triangles on its diagonal, as the seed splits its view deformations. Directions are
//! scaled per projection so that the common cases are parallelograms: on a cylinder, vectors of
//! unit horizontal length make a vertical strip one perspective piece (the seed's slices); a
//! perspective view is one piece for the whole image, which is then exact.
//!
//! How far a piece's direction strays from the true one is measured, in angle and in output
//! pixels: [`Pieces::measure`] at every pixel centre, the chooser [`Pieces::for_tolerance`] on a
//! few points per cell. `replicate.rs` decides which triangles each cell must draw; the GPU
//! pass is `src/gpu/ppp.rs`, its CPU twin [`super::RayCaster::picture`] along [`Pieces::ray`].

use super::directions::angle_between;
pub use super::directions::{
    Directions, Scale, ViewAt, median_pitch, median_pitch_on, true_direction,
};
use crate::error::{Error, Result};
use crate::projection::View;
use glam::{DMat3, DVec3};
use rayon::prelude::*;

/// Most pieces a projection may be cut into (one uniform slot each on the GPU).
pub const MAX_PIECES: usize = 16_384;

/// How close a piecewise projection must come to the true one.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Tolerance {
    /// The largest angle between a pixel's direction and the true one, radians.
    Angle(f64),
    /// The same angle over the output's local pixel pitch.
    Pixels(f64),
}

impl Tolerance {
    /// `0.05deg`, `0.001rad` or `0.5px`.
    pub fn parse(text: &str) -> Result<Tolerance> {
        let bad = || {
            Error::invalid(
                "tolerance",
                format!(
                    "`{text}`: expected a positive angle or pixel count, as 0.05deg, 0.001rad or 0.5px"
                ),
            )
        };
        // The unit is a suffix, not the first letter: `1e-3px` has an exponent.
        let (number, unit) = ["deg", "rad", "px"]
            .into_iter()
            .find_map(|u| text.strip_suffix(u).map(|n| (n, u)))
            .ok_or_else(bad)?;
        let v: f64 = number.trim().parse().map_err(|_| bad())?;
        if !(v.is_finite() && v > 0.0) {
            return Err(bad());
        }
        Ok(match unit {
            "deg" => Tolerance::Angle(v.to_radians()),
            "rad" => Tolerance::Angle(v),
            _ => Tolerance::Pixels(v),
        })
    }

    /// The tolerance for people: an angle in degrees (`0.05°`) or pixels (`0.5 px`).
    pub fn describe(self) -> String {
        match self {
            Tolerance::Angle(a) => format!("{}°", a.to_degrees()),
            Tolerance::Pixels(p) => format!("{p} px"),
        }
    }

    fn met(self, angle: f64, pixels: f64) -> bool {
        match self {
            Tolerance::Angle(a) => angle <= a,
            Tolerance::Pixels(p) => pixels <= p,
        }
    }
}

/// Which part of its cell a piece covers.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Half {
    /// The whole cell: its corners' directions form a parallelogram, so one linear map fits.
    Whole,
    /// Strictly above the diagonal from the cell's top-left to its bottom-right corner.
    Upper,
    /// On the diagonal and below it.
    Lower,
}

/// One perspective piece: a linear pixel → direction map (a pinhole camera at the eye)
/// over its cell, or over the half of it on one side of the cell's diagonal.
#[derive(Debug, Clone, Copy)]
pub struct Piece {
    /// The scissor rectangle: pixels x0..x1, y0..y1.
    pub cell: [u32; 4],
    /// Pixel (x, y, 1) → direction from the eye (world, not unit).
    pub field: DMat3,
    /// Which part of the cell the piece covers (the whole, or one side of `diagonal`).
    pub half: Half,
    /// The diagonal's end points, (x0, y0, x1, y1) doubled so that they are integers (border
    /// corners sit on pixel centres, half-way into a pixel).
    pub diagonal: [i32; 4],
}

impl Piece {
    /// Whether the pixel with centre (i + ½, j + ½) of the piece's cell belongs to it; the
    /// GPU's fragment test (`shaders/ppp.wgsl`) is the same integer arithmetic.
    pub fn owns(&self, i: u32, j: u32) -> bool {
        let [x0, y0, x1, y1] = self.diagonal.map(i64::from);
        let side =
            (2 * i64::from(i) + 1 - x0) * (y1 - y0) - (2 * i64::from(j) + 1 - y0) * (x1 - x0);
        match self.half {
            Half::Whole => true,
            Half::Upper => side > 0,
            Half::Lower => side <= 0,
        }
    }

    /// The piece's direction at pixel position (x, y).
    pub fn direction(&self, x: f64, y: f64) -> DVec3 {
        self.field * DVec3::new(x, y, 1.0)
    }
}

/// A projection cut into pieces for one output size.
#[derive(Debug, Clone)]
pub struct Pieces {
    /// Output width in pixels.
    pub width: u32,
    /// Output height in pixels.
    pub height: u32,
    /// Cells across.
    pub cols: u32,
    /// Cells down.
    pub rows: u32,
    /// Cell edges in pixels: `xs[0] = 0`, `xs[cols] = width` (likewise `ys`).
    xs: Vec<u32>,
    ys: Vec<u32>,
    /// The pieces, cell by cell in row-major order: none for a cell that shows nothing, one for
    /// a whole cell, two (upper then lower) for a cell cut on its diagonal.
    pub pieces: Vec<Piece>,
    /// Per cell (row-major): its first piece and how many it has (0 where the projection shows
    /// nothing in the cell, 1 or 2).
    cells: Vec<(u32, u8)>,
    /// Per cell: its corners' unit directions, for the replication test.
    pub(super) corners: Vec<[DVec3; 4]>,
    /// The output's median pixel pitch, radians ([`median_pitch`]).
    pub pitch: f64,
    /// Per pixel, whether the view has no direction there (outside a fisheye's circle);
    /// `None` when it has one everywhere. Such pixels are transparent, as in every renderer.
    hidden: Option<std::sync::Arc<Vec<bool>>>,
}

/// What [`Pieces::measure`] found.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Deviation {
    /// The largest angle between a piece's direction and the true one, radians.
    pub angle: f64,
    /// The same angle in output pixels: over the output's median pixel pitch.
    pub pixels: f64,
}

impl Pieces {
    /// The view cut into `cols` × `rows` cells of (near) equal size.
    pub fn new(view: &View, width: u32, height: u32, cols: u32, rows: u32) -> Result<Pieces> {
        Pieces::new_on(&ViewAt::new(view, width, height)?, cols, rows)
    }

    /// [`Pieces::new`] of any directions: a view at a size, or a projector's warp map.
    pub fn new_on(dirs: &dyn Directions, cols: u32, rows: u32) -> Result<Pieces> {
        let (width, height) = dirs.size();
        crate::raster::check_size(width, height, 1)?;
        Pieces::cut(dirs, &Facts::new(dirs), cols, rows)
    }

    /// [`Pieces::new`] with what does not depend on the cut already known (the chooser tries
    /// many cuts of one view).
    fn cut(dirs: &dyn Directions, facts: &Facts, cols: u32, rows: u32) -> Result<Pieces> {
        let (width, height) = dirs.size();
        if cols == 0 || cols > width / 2 || rows == 0 || rows > height / 2 {
            return Err(Error::invalid(
                "pieces",
                format!(
                    "{cols}×{rows} cells: each cell must be at least 2 pixels wide and high, so 1–{} × 1–{} for {width}×{height}",
                    width / 2,
                    height / 2
                ),
            ));
        }
        let edges = |n: u32, size: u32| -> Vec<u32> {
            (0..=n)
                .map(|k| (u64::from(k) * u64::from(size) / u64::from(n)) as u32)
                .collect()
        };
        let (xs, ys) = (edges(cols, width), edges(rows, height));
        // Border corners on the border pixels' centres: the field is then exact there, and a
        // pole along the image's edge (equirect) does not collapse a piece's corners.
        let at = |edges: &[u32], k: usize| -> f64 {
            match k {
                0 => 0.5,
                k if k == edges.len() - 1 => f64::from(edges[k]) - 0.5,
                k => f64::from(edges[k]),
            }
        };
        let scale = dirs.scale();
        let (nx, ny) = (cols as usize + 1, rows as usize + 1);
        // A corner outside the domain may bound a cell that shows pixels up to a cell's
        // diagonal away.
        let reach = 2 * (width.div_ceil(cols)).max(height.div_ceil(rows));
        let (mut grid, strict): (Vec<Option<DVec3>>, Vec<bool>) = (0..nx * ny)
            .into_par_iter()
            .map(|k| {
                let (x, y) = (at(&xs, k % nx), at(&ys, k / nx));
                let (d, own) = dirs.at(x, y);
                let d = if own {
                    d
                } else {
                    dirs.continued(x, y, reach).or(d)
                };
                (d.map(|d| scale.apply(d)), own)
            })
            .unzip();
        // Only where a corner falls outside the output's domain can a pixel show nothing.
        let hidden = strict
            .contains(&false)
            .then(|| facts.hidden(dirs))
            .flatten();
        fill_missing(&mut grid, nx, ny);
        let mut pieces = Vec::new();
        let mut cells = Vec::with_capacity(cols as usize * rows as usize);
        let mut corners = Vec::with_capacity(cols as usize * rows as usize);
        for j in 0..rows as usize {
            for i in 0..cols as usize {
                let cell = [xs[i], ys[j], xs[i + 1], ys[j + 1]];
                let p = [
                    (at(&xs, i), at(&ys, j)),
                    (at(&xs, i + 1), at(&ys, j)),
                    (at(&xs, i + 1), at(&ys, j + 1)),
                    (at(&xs, i), at(&ys, j + 1)),
                ];
                let d = [
                    grid[j * nx + i],
                    grid[j * nx + i + 1],
                    grid[(j + 1) * nx + i + 1],
                    grid[(j + 1) * nx + i],
                ];
                let first = pieces.len() as u32;
                let shows = hidden.as_ref().is_none_or(|h| {
                    (cell[1]..cell[3])
                        .any(|y| (cell[0]..cell[2]).any(|x| !h[(y * width + x) as usize]))
                });
                if !shows {
                    cells.push((first, 0));
                    corners.push([DVec3::ZERO; 4]);
                    continue;
                }
                let Some(d) = d
                    .iter()
                    .copied()
                    .collect::<Option<Vec<DVec3>>>()
                    .map(|v| [v[0], v[1], v[2], v[3]])
                else {
                    return Err(Error::invalid(
                        "pieces",
                        format!(
                            "the cell at pixels {}–{} × {}–{} shows part of the view but no direction reaches its corners; choose more pieces",
                            cell[0], cell[2], cell[1], cell[3]
                        ),
                    ));
                };
                let diagonal = [p[0].0, p[0].1, p[2].0, p[2].1].map(|v| (2.0 * v).round() as i32);
                let make = |tri: [usize; 3], half| -> Result<Piece> {
                    Ok(Piece {
                        cell,
                        field: field(tri.map(|k| p[k]), tri.map(|k| d[k])).ok_or_else(|| {
                            Error::invalid(
                                "pieces",
                                format!(
                                    "the piece at pixels {}–{} × {}–{} has corners whose directions lie on one great circle (a pole or a singular point of the projection on its corners); choose another piece count",
                                    cell[0], cell[2], cell[1], cell[3]
                                ),
                            )
                        })?,
                        half,
                        diagonal,
                    })
                };
                let flat =
                    (d[0] + d[2] - d[1] - d[3]).length() <= 1e-9 * (d[0].length() + d[2].length());
                if flat {
                    pieces.push(make([0, 1, 2], Half::Whole)?);
                } else {
                    pieces.push(make([0, 1, 2], Half::Upper)?);
                    pieces.push(make([0, 2, 3], Half::Lower)?);
                }
                cells.push((first, (pieces.len() as u32 - first) as u8));
                corners.push(d.map(|v| v.normalize()));
            }
        }
        if pieces.len() > MAX_PIECES {
            return Err(Error::invalid(
                "pieces",
                format!(
                    "{cols}×{rows} cells make {} pieces, more than the {MAX_PIECES} allowed",
                    pieces.len()
                ),
            ));
        }
        Ok(Pieces {
            width,
            height,
            cols,
            rows,
            xs,
            ys,
            pieces,
            cells,
            corners,
            hidden,
            pitch: facts.pitch,
        })
    }

    /// The cheapest cut (fewest pieces) whose deviation meets `tolerance`: sampled on a 7 × 7
    /// lattice of pixel centres per cell while searching, then confirmed at every pixel.
    ///
    /// The deviation shrinks as cells narrow or shorten, so the search walks the staircase of
    /// the smallest feasible row count for each column count (columns up, rows only down):
    /// about as many trials as there are candidate counts, not their product.
    pub fn for_tolerance(
        view: &View,
        width: u32,
        height: u32,
        tolerance: Tolerance,
    ) -> Result<(Pieces, Deviation)> {
        Pieces::for_tolerance_on(&ViewAt::new(view, width, height)?, tolerance)
    }

    /// [`Pieces::for_tolerance`] of any directions.
    pub fn for_tolerance_on(
        dirs: &dyn Directions,
        tolerance: Tolerance,
    ) -> Result<(Pieces, Deviation)> {
        let counts = |limit: u32| -> Vec<u32> {
            let mut v: Vec<u32> = [1, 3]
                .iter()
                .flat_map(|&m| (0..16).map(move |e| m << e))
                .filter(|&n| n <= limit)
                .collect();
            v.sort_unstable();
            v
        };
        let (width, height) = dirs.size();
        crate::raster::check_size(width, height, 1)?;
        let (cols, rows) = (counts(width / 2), counts(height / 2));
        let facts = Facts::new(dirs);
        let meets = |c: u32, r: u32| -> Option<Pieces> {
            let p = Pieces::cut(dirs, &facts, c, r).ok()?;
            let d = p.deviation(dirs, Sampling::Lattice(7));
            tolerance.met(d.angle, d.pixels).then_some(p)
        };
        let mut best: Option<(Pieces, Deviation)> = None;
        let mut r = rows.len() - 1;
        for &c in &cols {
            if best
                .as_ref()
                .is_some_and(|(b, _)| c as usize >= b.pieces.len())
            {
                break;
            }
            // Two pieces a cell where cells are cut on their diagonal.
            while r > 0 && 2 * (c * rows[r]) as usize > MAX_PIECES {
                r -= 1;
            }
            let Some(mut found) = meets(c, rows[r]) else {
                continue;
            };
            while r > 0 {
                match meets(c, rows[r - 1]) {
                    Some(p) => {
                        found = p;
                        r -= 1;
                    }
                    None => break,
                }
            }
            if best
                .as_ref()
                .is_some_and(|(b, _)| b.pieces.len() <= found.pieces.len())
            {
                continue;
            }
            // The lattice may miss a cell's worst pixel: confirm everywhere.
            let d = found.measure_on(dirs);
            if tolerance.met(d.angle, d.pixels) {
                best = Some((found, d));
            }
        }
        best.ok_or_else(|| {
            Error::invalid(
                "tolerance",
                format!(
                    "{}: no cut into at most {MAX_PIECES} pieces meets it for these directions at {width}×{height}",
                    tolerance.describe()
                ),
            )
        })
    }

    /// The piece that draws pixel (i, j), if any does.
    pub fn piece_at(&self, i: u32, j: u32) -> Option<&Piece> {
        let col = self.xs.partition_point(|&x| x <= i) - 1;
        let row = self.ys.partition_point(|&y| y <= j) - 1;
        let (first, n) = self.cells[row * self.cols as usize + col];
        self.pieces[first as usize..first as usize + n as usize]
            .iter()
            .find(|p| p.owns(i, j))
    }

    /// The direction the pieces show at pixel (i, j): the ray the GPU's rasteriser follows
    /// there. `None` where no piece draws.
    pub fn ray(&self, i: u32, j: u32) -> Option<DVec3> {
        if self.is_hidden(i, j) {
            return None;
        }
        self.piece_at(i, j).map(|p| {
            p.direction(f64::from(i) + 0.5, f64::from(j) + 0.5)
                .normalize()
        })
    }

    /// The direction the pieces show at continuous position (x, y): the piece that owns the
    /// pixel there, evaluated at (x, y) (a multisample's position).
    pub fn ray_at(&self, x: f64, y: f64) -> Option<DVec3> {
        let (i, j) = (x.floor() as u32, y.floor() as u32);
        if x < 0.0 || y < 0.0 || i >= self.width || j >= self.height || self.is_hidden(i, j) {
            return None;
        }
        self.piece_at(i, j).map(|p| p.direction(x, y).normalize())
    }

    /// Whether pixel (i, j) shows nothing (the view has no direction there).
    pub fn is_hidden(&self, i: u32, j: u32) -> bool {
        self.hidden
            .as_ref()
            .is_some_and(|h| h[j as usize * self.width as usize + i as usize])
    }

    /// Per cell: its pieces (none where the view shows nothing).
    pub fn cells(&self) -> impl Iterator<Item = &[Piece]> + '_ {
        self.cells
            .iter()
            .map(|&(first, n)| &self.pieces[first as usize..first as usize + n as usize])
    }

    /// The deviation from the true projection at every pixel centre the view shows.
    pub fn measure(&self, view: &View) -> Deviation {
        self.measure_on(&ViewAt::sized(view, self.width, self.height))
    }

    /// [`Pieces::measure`] against any directions of the pieces' size.
    pub fn measure_on(&self, dirs: &dyn Directions) -> Deviation {
        self.deviation(dirs, Sampling::Every)
    }

    fn deviation(&self, dirs: &dyn Directions, sampling: Sampling) -> Deviation {
        let (w, h) = (self.width, self.height);
        let points: Vec<(u32, u32)> = match sampling {
            Sampling::Every => (0..h).flat_map(|j| (0..w).map(move |i| (i, j))).collect(),
            Sampling::Lattice(n) => (0..self.rows as usize)
                .flat_map(|r| (0..self.cols as usize).map(move |c| (c, r)))
                .flat_map(|(c, r)| {
                    let (x0, x1) = (self.xs[c], self.xs[c + 1] - 1);
                    let (y0, y1) = (self.ys[r], self.ys[r + 1] - 1);
                    let at = move |a: u32, b: u32, k: u32| a + (b - a) * k / (n - 1);
                    (0..n).flat_map(move |v| (0..n).map(move |u| (at(x0, x1, u), at(y0, y1, v))))
                })
                .collect(),
        };
        let angle = points
            .par_chunks(4096)
            .map(|chunk| {
                chunk
                    .iter()
                    .filter_map(|&(i, j)| {
                        let (x, y) = (f64::from(i) + 0.5, f64::from(j) + 0.5);
                        Some(angle_between(dirs.at(x, y).0?, self.ray(i, j)?))
                    })
                    .fold(0.0, f64::max)
            })
            .reduce(|| 0.0, f64::max);
        Deviation {
            angle,
            pixels: angle / self.pitch,
        }
    }
}

/// What every cut of one output shares: its median pixel pitch, and (computed on first need)
/// which pixels it shows nothing at (`None`: it shows something everywhere).
struct Facts {
    pitch: f64,
    hidden: std::sync::OnceLock<Option<std::sync::Arc<Vec<bool>>>>,
}

impl Facts {
    fn new(dirs: &dyn Directions) -> Facts {
        Facts {
            pitch: median_pitch_on(dirs),
            hidden: std::sync::OnceLock::new(),
        }
    }

    fn hidden(&self, dirs: &dyn Directions) -> Option<std::sync::Arc<Vec<bool>>> {
        self.hidden
            .get_or_init(|| {
                let h = hidden_pixels(dirs);
                h.contains(&true).then(|| std::sync::Arc::new(h))
            })
            .clone()
    }
}

enum Sampling {
    Every,
    Lattice(u32),
}

fn hidden_pixels(dirs: &dyn Directions) -> Vec<bool> {
    let (w, h) = dirs.size();
    (0..h)
        .into_par_iter()
        .flat_map_iter(|j| (0..w).map(move |i| !dirs.at(f64::from(i) + 0.5, f64::from(j) + 0.5).1))
        .collect()
}

/// Corners where the projection has no direction (outside a fisheye's circle) take one
/// continued from their neighbours, so that the cells they bound still have a field for the
/// pixels inside the domain.
fn fill_missing(grid: &mut [Option<DVec3>], nx: usize, ny: usize) {
    for _ in 0..nx.max(ny) {
        let before = grid.iter().filter(|d| d.is_none()).count();
        if before == 0 {
            return;
        }
        let snapshot = grid.to_vec();
        let get = |i: isize, j: isize| -> Option<DVec3> {
            if i < 0 || j < 0 || i >= nx as isize || j >= ny as isize {
                return None;
            }
            snapshot[j as usize * nx + i as usize]
        };
        for j in 0..ny as isize {
            for i in 0..nx as isize {
                if snapshot[j as usize * nx + i as usize].is_some() {
                    continue;
                }
                let mut sum = DVec3::ZERO;
                let mut n = 0.0;
                for (di, dj) in [(1, 0), (-1, 0), (0, 1), (0, -1)] {
                    if let Some(a) = get(i + di, j + dj) {
                        sum += match get(i + 2 * di, j + 2 * dj) {
                            Some(b) => 2.0 * a - b,
                            None => a,
                        };
                        n += 1.0;
                    }
                }
                if n > 0.0 {
                    grid[j as usize * nx + i as usize] = Some(sum / n);
                }
            }
        }
        if grid.iter().filter(|d| d.is_none()).count() == before {
            return;
        }
    }
}

/// The linear map taking pixel positions `p` to directions `d` (columns), or `None` when the
/// directions are (nearly) linearly dependent and no pinhole camera shows them.
fn field(p: [(f64, f64); 3], d: [DVec3; 3]) -> Option<DMat3> {
    let pixels = DMat3::from_cols(
        DVec3::new(p[0].0, p[0].1, 1.0),
        DVec3::new(p[1].0, p[1].1, 1.0),
        DVec3::new(p[2].0, p[2].1, 1.0),
    );
    let dirs = DMat3::from_cols(d[0], d[1], d[2]);
    let volume = dirs.determinant().abs() / (d[0].length() * d[1].length() * d[2].length());
    if volume < 1e-12 || pixels.determinant().abs() < 1e-9 {
        return None;
    }
    Some(dirs * pixels.inverse())
}
