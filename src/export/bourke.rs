//! Paul Bourke's warp mesh (`.data`, mesh type 2 = rectangular), as SGCT/OpenSpace, Celestia,
//! Gaia Sky and Blender's dome mode read it: line 1 the type, line 2 `nx ny`, then nx·ny nodes
//! `x y u v i`, bottom row first. x ∈ [−aspect, aspect] and y ∈ [−1, 1] place the node on the
//! projector image (edges included, y up); u, v ∈ [0, 1] point into the content image with v = 0
//! at its bottom (OpenGL texture coordinates); i is the node's intensity.
//!
//! What readers accept and do, as their code shows (Celestia's `warpmesh.cpp` since July 2025,
//! SGCT's `paulbourke.cpp`): u, v and i must lie in [0, 1] (Celestia refuses the whole mesh
//! otherwise, so a node with no content is `0 0 0`, not the negative intensity older players
//! skipped), x and y must form a monotonic grid, and i multiplies the colour as displayed —
//! gamma-encoded — so a linear blend weight w is written as w^(1/2.2), the projector gamma the
//! MPCDI alpha maps embed too.

use super::grid::{Cells, Grid, Shape};
use crate::error::{Error, Result};

/// The reader a mesh's grid is sized for: each draws a cell as two triangles, split along a
/// diagonal of its own.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum MeshReader {
    /// Whichever way a reader splits the cells (and bilinear): the default, since a mesh
    /// usually goes to more than one player.
    Any,
    /// A reader that interpolates bilinearly.
    Bilinear,
    /// Celestia (`WarpMesh`): triangles sharing the cell's top-left to bottom-right diagonal.
    Celestia,
    /// SGCT/OpenSpace (`correction/paulbourke.cpp`): the bottom-left to top-right diagonal.
    Sgct,
}

impl MeshReader {
    /// Every reader, in the order error messages list them.
    pub const ALL: [MeshReader; 4] = [
        MeshReader::Any,
        MeshReader::Bilinear,
        MeshReader::Celestia,
        MeshReader::Sgct,
    ];

    /// The reader's name as `--reader` and the API's `reader` spell it: `any`, `bilinear`,
    /// `celestia` or `sgct`.
    pub fn name(self) -> &'static str {
        match self {
            MeshReader::Any => "any",
            MeshReader::Bilinear => "bilinear",
            MeshReader::Celestia => "celestia",
            MeshReader::Sgct => "sgct",
        }
    }

    /// The reader named `s` (see [`MeshReader::name`]); an error naming `field` otherwise.
    pub fn parse(s: &str, field: &str) -> Result<Self> {
        MeshReader::ALL
            .into_iter()
            .find(|r| r.name() == s)
            .ok_or_else(|| {
                Error::invalid(
                    field,
                    format!("a mesh is read by any, bilinear, celestia or sgct, got `{s}`"),
                )
            })
    }

    /// Which grids this reader draws whole: Celestia only square ones of at most 1,024 nodes a
    /// side (see [`Shape::Square`]), so a mesh for it, or for any reader, is square.
    pub fn shape(self) -> Shape {
        match self {
            MeshReader::Any | MeshReader::Celestia => Shape::Square { max: 1024 },
            MeshReader::Bilinear | MeshReader::Sgct => Shape::Free,
        }
    }

    /// How this reader fills a cell between its four nodes, which the grid is sized for.
    pub fn cells(self) -> Cells {
        match self {
            MeshReader::Any => Cells::Any,
            MeshReader::Bilinear => Cells::Bilinear,
            MeshReader::Celestia => Cells::TopLeftDiagonal,
            MeshReader::Sgct => Cells::BottomLeftDiagonal,
        }
    }
}
use std::fmt::Write as _;

/// A mesh as read back.
#[derive(Debug, Clone, PartialEq)]
pub struct Mesh {
    /// The mesh type on line 1 (2 for the rectangular meshes omniwarp writes).
    pub kind: u32,
    /// Nodes across, from line 2.
    pub nx: usize,
    /// Nodes down, from line 2.
    pub ny: usize,
    /// `[x, y, u, v, i]` per node, in file order (bottom row first).
    pub nodes: Vec<[f64; 5]>,
}

/// The projector gamma a linear blend weight is encoded with to become a node's intensity.
pub const INTENSITY_GAMMA: f64 = 2.2;

/// The mesh text for a grid of content (u, v) (top-left origin) and the linear blend weight at
/// each node; `aspect` is the projector's width / height. Coordinates past the content's edges
/// are clamped to them (the format has no others), and nodes with no content are black.
pub fn mesh_text(uv: &Grid<2>, weights: &[f64], aspect: f64) -> Result<String> {
    if weights.len() != uv.samples.len() {
        return Err(Error::invalid("mesh", "one intensity per node is needed"));
    }
    let (nx, ny) = (uv.columns, uv.rows);
    let mut out = String::with_capacity(nx * ny * 48 + 16);
    let _ = write!(out, "2\n{nx} {ny}\n");
    for row in (0..ny).rev() {
        let y = 1.0 - 2.0 * row as f64 / (ny - 1) as f64;
        for col in 0..nx {
            let x = aspect * (2.0 * col as f64 / (nx - 1) as f64 - 1.0);
            let n = row * nx + col;
            let (u, v, i) = match uv.samples[n] {
                Some([u, v]) if u.is_finite() && v.is_finite() => (
                    u.clamp(0.0, 1.0),
                    (1.0 - v).clamp(0.0, 1.0),
                    weights[n].clamp(0.0, 1.0).powf(1.0 / INTENSITY_GAMMA),
                ),
                _ => (0.0, 0.0, 0.0),
            };
            let _ = writeln!(out, "{x:.6} {y:.6} {u:.8} {v:.8} {i:.6}");
        }
    }
    Ok(out)
}

/// Reads a mesh (any whitespace between numbers), checking the node count.
pub fn read_mesh(text: &str) -> Result<Mesh> {
    let bad = |why: String| Error::invalid("mesh", why);
    let mut lines = text.lines().filter(|l| !l.trim().is_empty());
    let kind: u32 = lines
        .next()
        .and_then(|l| l.trim().parse().ok())
        .ok_or_else(|| bad("line 1 must be the mesh type".into()))?;
    let dims: Vec<usize> = lines
        .next()
        .map(|l| {
            l.split_whitespace()
                .filter_map(|t| t.parse().ok())
                .collect()
        })
        .unwrap_or_default();
    let [nx, ny] = dims[..] else {
        return Err(bad("line 2 must be `nx ny`".into()));
    };
    let count = crate::limits::product(
        "mesh",
        nx as u64,
        ny as u64,
        crate::limits::EXPORT_NODES as u64,
    )?;
    // The count comes from the file: reserve no more than the text can hold.
    let mut nodes = Vec::with_capacity((count as usize).min(text.len() / 10));
    for (n, line) in lines.enumerate() {
        let v: Vec<f64> = line
            .split_whitespace()
            .map(str::parse)
            .collect::<std::result::Result<_, _>>()
            .map_err(|_| bad(format!("node {n}: not five numbers")))?;
        let node: [f64; 5] = v
            .try_into()
            .map_err(|_| bad(format!("node {n}: not five numbers")))?;
        nodes.push(node);
    }
    if nodes.len() as u64 != count {
        return Err(bad(format!(
            "{nx}×{ny} needs {count} nodes, found {}",
            nodes.len()
        )));
    }
    Ok(Mesh {
        kind,
        nx,
        ny,
        nodes,
    })
}
