//! Which triangles each piece of a piecewise perspective projection draws (seed 003's
//! coverage and replication), decided on the CPU once per eye position and cut.
//!
//! A piece's frustum is the convex cone of its corner directions: three or four planes through
//! the eye. A triangle goes to a cell unless, for each of the cell's pieces, all its vertices
//! lie outside one of the piece's planes: conservative (it may draw a triangle into a cell it
//! misses, never the reverse) and tight for the tall, thin strips of a cylinder. Cells are
//! first tested in blocks of 8 × 8 by bounding cones (the block's corner directions against
//! the triangle's bounding sphere seen from the eye), so a triangle costs one test per block it
//! does not meet; a triangle whose sphere holds the eye (the ground under it, a triangle
//! crossing a cylinder's axis) skips that test and meets the planes of every cell.

use super::Scene;
use super::ppp::{Half, Piece, Pieces};
use glam::DVec3;
use rayon::prelude::*;

/// Per cell, the scene's indices of the triangles it draws, concatenated.
#[derive(Debug, Clone)]
pub struct Replication {
    /// Vertex indices (three per triangle), cell after cell.
    pub indices: Vec<u32>,
    /// Per cell: the range of `indices` it draws.
    pub ranges: Vec<std::ops::Range<u32>>,
    /// Triangles drawn, counted once per piece, over the scene's triangles.
    pub factor: f64,
}

/// A circular cone: unit axis and the cosine and angle of its half-opening.
#[derive(Debug, Clone, Copy)]
struct Cone {
    axis: DVec3,
    angle: f64,
}

impl Cone {
    fn around(dirs: impl Iterator<Item = DVec3> + Clone) -> Cone {
        let sum: DVec3 = dirs.clone().sum();
        if sum.length() < 1e-9 {
            return Cone {
                axis: DVec3::Z,
                angle: std::f64::consts::PI,
            };
        }
        let axis = sum.normalize();
        let angle = dirs
            .map(|d| axis.dot(d).clamp(-1.0, 1.0).acos())
            .fold(0.0, f64::max);
        Cone {
            axis,
            angle: angle + 1e-6,
        }
    }

    fn meets(&self, other: &Cone) -> bool {
        let reach = self.angle + other.angle;
        reach >= std::f64::consts::PI || self.axis.dot(other.axis) >= reach.cos()
    }
}

const BLOCK: usize = 8;

/// Inward normals of a piece's side planes through the eye.
#[derive(Debug, Clone, Copy)]
struct Frustum {
    planes: [DVec3; 4],
    count: usize,
}

impl Frustum {
    fn around(corners: &[DVec3]) -> Frustum {
        let inside: DVec3 = corners.iter().sum();
        let mut planes = [DVec3::ZERO; 4];
        for (k, plane) in planes.iter_mut().enumerate().take(corners.len()) {
            let n = corners[k].cross(corners[(k + 1) % corners.len()]);
            *plane = if n.dot(inside) < 0.0 { -n } else { n };
        }
        Frustum {
            planes,
            count: corners.len(),
        }
    }

    /// Whether the triangle (vertices relative to the eye) may show in the frustum.
    fn may_hold(&self, v: &[DVec3; 3]) -> bool {
        self.planes[..self.count]
            .iter()
            .all(|n| v.iter().any(|p| n.dot(*p) >= -1e-9 * p.length()))
    }
}

/// The frusta of a cell's pieces.
fn frusta(pieces: &[Piece], corners: &[DVec3; 4]) -> Vec<Frustum> {
    pieces
        .iter()
        .map(|p| match p.half {
            Half::Whole => Frustum::around(corners),
            Half::Upper => Frustum::around(&[corners[0], corners[1], corners[2]]),
            Half::Lower => Frustum::around(&[corners[0], corners[2], corners[3]]),
        })
        .collect()
}

/// The triangles of `scene` each cell of `pieces` must draw, seen from `eye`.
pub fn replicate(scene: &Scene, pieces: &Pieces, eye: DVec3, near: f64) -> Replication {
    let (cols, rows) = (pieces.cols as usize, pieces.rows as usize);
    let cells: Vec<Vec<Frustum>> = pieces
        .cells()
        .zip(&pieces.corners)
        .map(|(p, c)| frusta(p, c))
        .collect();
    let shown = |k: usize| !cells[k].is_empty();
    let (bx, by) = (cols.div_ceil(BLOCK), rows.div_ceil(BLOCK));
    let blocks: Vec<(Option<Cone>, Vec<usize>)> = (0..bx * by)
        .map(|b| {
            let (i0, j0) = ((b % bx) * BLOCK, (b / bx) * BLOCK);
            let members: Vec<usize> = (j0..(j0 + BLOCK).min(rows))
                .flat_map(|j| (i0..(i0 + BLOCK).min(cols)).map(move |i| j * cols + i))
                .filter(|&k| shown(k))
                .collect();
            let dirs = members.iter().flat_map(|&k| pieces.corners[k]);
            let cone = (!members.is_empty()).then(|| Cone::around(dirs));
            (cone, members)
        })
        .collect();
    let triangles = scene.triangles();
    // Per triangle, the cells it goes to; gathered per cell afterwards.
    let hits: Vec<Vec<u32>> = (0..triangles)
        .into_par_iter()
        .map(|t| {
            let p = |k: usize| {
                glam::Vec3::from_array(scene.positions[scene.indices[3 * t + k] as usize])
                    .as_dvec3()
            };
            let v = [p(0) - eye, p(1) - eye, p(2) - eye];
            let centre = (v[0] + v[1] + v[2]) / 3.0;
            let radius = v.iter().map(|p| p.distance(centre)).fold(0.0, f64::max);
            let distance = centre.length();
            let cone = (distance > radius + near).then(|| Cone {
                axis: centre / distance,
                angle: (radius / distance).asin(),
            });
            let mut out = Vec::new();
            for (block, members) in &blocks {
                if cone.is_some_and(|c| !block.is_some_and(|b| b.meets(&c))) {
                    continue;
                }
                out.extend(
                    members
                        .iter()
                        .filter(|&&k| cells[k].iter().any(|f| f.may_hold(&v)))
                        .map(|&k| k as u32),
                );
            }
            out
        })
        .collect();
    let mut per_cell: Vec<Vec<u32>> = vec![Vec::new(); cells.len()];
    for (t, cells) in hits.iter().enumerate() {
        for &k in cells {
            per_cell[k as usize].push(t as u32);
        }
    }
    let mut indices = Vec::new();
    let mut ranges = Vec::with_capacity(per_cell.len());
    let mut drawn = 0usize;
    for (tris, cell) in per_cell.iter().zip(pieces.cells()) {
        let start = indices.len() as u32;
        for &t in tris {
            indices.extend_from_slice(&scene.indices[3 * t as usize..3 * t as usize + 3]);
        }
        drawn += tris.len() * cell.len();
        ranges.push(start..indices.len() as u32);
    }
    Replication {
        indices,
        ranges,
        factor: drawn as f64 / triangles.max(1) as f64,
    }
}
