//! Projection tile screens (seed 000, section 4; seed 002): the one editable form of a warp.
//!
//! A tile screen is a set of tile features E = (x, y, φ, θ, scale, f): at screen position
//! (x, y) ∈ [0, 1]² (x to the right, y down, as image rows run) the viewer sees the direction
//! with longitude φ and latitude θ (degrees, within ±360 so that a row of features can run past
//! ±180° without a jump), zoomed by `scale`, with a custom value `f` that drives per-pixel
//! effects. Features form either a regular grid of quads, each drawn as two triangles, or a
//! "triangle soup" of independent triangles, where neighbours may differ sharply.
//!
//! [`raster`] turns a tile screen into a feature map and a normal map, [`build`] samples
//! projections into tile screens, [`adapt`] picks the coarsest grid that meets a tolerance and
//! [`edit`] changes them without ever producing a fold-over.

pub mod adapt;
pub mod build;
pub mod edit;
pub mod raster;
pub mod refine;

use crate::error::{Error, Result};
use serde::{Deserialize, Serialize};

/// One tile feature.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Feature {
    /// Screen position, 0 at the left edge, 1 at the right.
    pub x: f64,
    /// Screen position, 0 at the top edge, 1 at the bottom.
    pub y: f64,
    /// Longitude of the view direction, degrees: 0 ahead (−z), positive to the right (+x).
    pub phi: f64,
    /// Latitude of the view direction, degrees: positive up (+y).
    pub theta: f64,
    /// Angular zoom: the direction shown has angles (φ·scale, θ·scale).
    #[serde(default = "one")]
    pub scale: f64,
    /// Custom per-feature value, interpolated like the others (the renderer's saturation).
    #[serde(default = "one")]
    pub f: f64,
    /// False where the feature holds no direction at all; triangles with an invalid corner are
    /// not drawn.
    #[serde(default = "yes", skip_serializing_if = "is_true")]
    pub valid: bool,
    /// True where the feature lies past the edge of what the source shows (off the wall, past a
    /// fisheye's image circle): its direction is extrapolated, so the tiles that straddle the
    /// edge are drawn up to it, and the cut is made per pixel by the mask of the source (the
    /// projection's domain, the wall's footprint), not by the tile grid. Averaging edits hold
    /// these features and their neighbours: together they are the edge.
    #[serde(default, skip_serializing_if = "is_false")]
    pub outside: bool,
    /// How much the feature's direction counts when directions are interpolated
    /// ([`Interpolation::Vectors`]): the rasteriser interpolates weight × direction and
    /// normalises, as a GPU interpolates homogeneous coordinates. 1 for sampled features; a
    /// feature made by subdividing a tile keeps the length of the interpolated vector, so the
    /// finer grid shows exactly what the coarser one did.
    #[serde(default = "one", skip_serializing_if = "is_one")]
    pub weight: f64,
}

fn one() -> f64 {
    1.0
}
fn yes() -> bool {
    true
}
fn is_true(b: &bool) -> bool {
    *b
}
fn is_false(b: &bool) -> bool {
    !*b
}
fn is_one(v: &f64) -> bool {
    *v == 1.0
}

/// How the features are connected.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum Layout {
    /// `columns` × `rows` features, row-major from the top row; quad (k, l) has corners
    /// (k, l), (k+1, l), (k+1, l+1), (k, l+1) and is split along its (k, l)–(k+1, l+1) diagonal.
    Grid {
        /// Features per row, 2 to `limits::TILE_SIDE` (1025).
        columns: usize,
        /// Rows of features, 2 to `limits::TILE_SIDE` (1025).
        rows: usize,
        /// The `columns × rows` features, row by row from the top.
        features: Vec<Feature>,
    },
    /// Independent triangles.
    Soup {
        /// The triangles, each its three corner features; 1 to `limits::TILE_TRIANGLES`
        /// (32 768).
        triangles: Vec<[Feature; 3]>,
    },
}

/// A tile screen as stored (JSON, `"format": 1`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TileScreen {
    /// File format version: 1, the only one known.
    pub format: u32,
    /// Increases with every edit.
    #[serde(default)]
    pub revision: u64,
    /// What the screen was sampled from, so an edit can reset to it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub source: Option<build::Source>,
    /// How features are interpolated across a tile (see [`raster`]).
    #[serde(default)]
    pub interpolation: Interpolation,
    /// The features and how they are connected.
    pub layout: Layout,
}

/// What the rasteriser interpolates across a tile.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Interpolation {
    /// The features' angles, as seed 000 does: exact for projections whose angles are linear in
    /// the screen position, but singular at the poles (θ = ±90°), where φ is undefined.
    #[default]
    Angles,
    /// The features' unit view directions, normalised after interpolation: no singularity
    /// anywhere, which domes and fisheyes (whose views pass through a pole) need.
    Vectors,
}

/// Triangles below this signed area (in screen units², 1 = the whole screen) count as
/// degenerate: about a thousandth of a pixel on a 4K output.
const MIN_AREA: f64 = 1e-12;

/// Tiles with an inner angle below this are reported as acute (seed 000: artefacts there).
pub const ACUTE_DEG: f64 = 10.0;

/// Signed area of triangle a b c (positive when the corners run clockwise on screen, as the
/// top-left, top-right, bottom-right corners of a grid quad do with y pointing down).
pub fn signed_area(a: &Feature, b: &Feature, c: &Feature) -> f64 {
    0.5 * ((b.x - a.x) * (c.y - a.y) - (b.y - a.y) * (c.x - a.x))
}

/// The smallest inner angle of a triangle, degrees.
pub fn min_angle(t: &[Feature; 3]) -> f64 {
    (0..3)
        .map(|i| {
            let (a, b, c) = (&t[i], &t[(i + 1) % 3], &t[(i + 2) % 3]);
            let (ux, uy, vx, vy) = (b.x - a.x, b.y - a.y, c.x - a.x, c.y - a.y);
            (ux * vy - uy * vx)
                .abs()
                .atan2(ux * vx + uy * vy)
                .to_degrees()
        })
        .fold(180.0, f64::min)
}

impl TileScreen {
    /// A `columns` × `rows` grid of `features` (row by row from the top), validated: revision 0,
    /// no source, [`Interpolation::Angles`].
    pub fn grid(columns: usize, rows: usize, features: Vec<Feature>) -> Result<Self> {
        let t = TileScreen {
            format: 1,
            revision: 0,
            source: None,
            interpolation: Interpolation::default(),
            layout: Layout::Grid {
                columns,
                rows,
                features,
            },
        };
        t.validate()?;
        Ok(t)
    }

    /// A triangle soup, validated: revision 0, no source, [`Interpolation::Angles`].
    pub fn soup(triangles: Vec<[Feature; 3]>) -> Result<Self> {
        let t = TileScreen {
            format: 1,
            revision: 0,
            source: None,
            interpolation: Interpolation::default(),
            layout: Layout::Soup { triangles },
        };
        t.validate()?;
        Ok(t)
    }

    /// Every triangle, with a name for error messages.
    pub fn triangles(&self) -> Vec<([Feature; 3], String)> {
        let columns = match &self.layout {
            Layout::Grid { columns, .. } => Some(columns.saturating_sub(1).max(1)),
            Layout::Soup { .. } => None,
        };
        self.corners()
            .into_iter()
            .enumerate()
            .map(|(n, t)| {
                let name = match columns {
                    // Two triangles a quad, quads row by row.
                    Some(c) => format!("tile ({}, {})", (n / 2) % c, (n / 2) / c),
                    None => format!("triangle {n}"),
                };
                (t, name)
            })
            .collect()
    }

    /// Every triangle's corners, in drawing order: a grid's quads row by row, each split
    /// along its (k, l)–(k+1, l+1) diagonal.
    pub fn corners(&self) -> Vec<[Feature; 3]> {
        match &self.layout {
            Layout::Grid {
                columns,
                rows,
                features,
            } => {
                let mut out = Vec::with_capacity(2 * columns * rows);
                for l in 0..rows.saturating_sub(1) {
                    for k in 0..columns.saturating_sub(1) {
                        let at = |k: usize, l: usize| features[l * columns + k];
                        let (a, b, c, d) = (at(k, l), at(k + 1, l), at(k + 1, l + 1), at(k, l + 1));
                        out.push([a, b, c]);
                        out.push([a, c, d]);
                    }
                }
                out
            }
            Layout::Soup { triangles } => triangles.clone(),
        }
    }

    /// How many features the screen holds: a grid's, or three per triangle of a soup.
    pub fn feature_count(&self) -> usize {
        match &self.layout {
            Layout::Grid { features, .. } => features.len(),
            Layout::Soup { triangles } => 3 * triangles.len(),
        }
    }

    /// Checks every value and every tile; the error names the feature or tile at fault.
    pub fn validate(&self) -> Result<()> {
        if self.format != 1 {
            return Err(Error::invalid(
                "format",
                format!("only format 1 is known, got {}", self.format),
            ));
        }
        let named_features: Vec<(String, &Feature)> = match &self.layout {
            Layout::Grid {
                columns,
                rows,
                features,
            } => {
                if *columns < 2 || *rows < 2 {
                    return Err(Error::invalid(
                        "grid",
                        format!("needs at least 2×2 features, got {columns}×{rows}"),
                    ));
                }
                use crate::limits::{TILE_FEATURES, TILE_SIDE, at_most, product};
                at_most("columns", *columns, TILE_SIDE)?;
                at_most("rows", *rows, TILE_SIDE)?;
                product("grid", *columns as u64, *rows as u64, TILE_FEATURES as u64)?;
                if features.len() != columns * rows {
                    return Err(Error::invalid(
                        "features",
                        format!(
                            "a {columns}×{rows} grid has {} features, got {}",
                            columns * rows,
                            features.len()
                        ),
                    ));
                }
                features
                    .iter()
                    .enumerate()
                    .map(|(i, f)| {
                        (
                            format!(
                                "features[{i}] (column {}, row {})",
                                i % columns,
                                i / columns
                            ),
                            f,
                        )
                    })
                    .collect()
            }
            Layout::Soup { triangles } => {
                crate::limits::at_most(
                    "triangles",
                    triangles.len(),
                    crate::limits::TILE_TRIANGLES,
                )?;
                if triangles.is_empty() {
                    return Err(Error::invalid(
                        "triangles",
                        "a triangle soup needs at least one triangle",
                    ));
                }
                triangles
                    .iter()
                    .enumerate()
                    .flat_map(|(i, t)| {
                        t.iter()
                            .enumerate()
                            .map(move |(j, f)| (format!("triangles[{i}][{j}]"), f))
                    })
                    .collect()
            }
        };
        for (name, f) in named_features {
            check_feature(&name, f)?;
        }
        for (t, name) in self.triangles() {
            let area = signed_area(&t[0], &t[1], &t[2]);
            if area.abs() <= MIN_AREA {
                return Err(Error::invalid(name, "has zero area"));
            }
            if area < 0.0 {
                return Err(Error::invalid(
                    name,
                    "is inverted or folded over (its corners run the wrong way round)",
                ));
            }
        }
        Ok(())
    }

    /// Tiles with an inner angle below [`ACUTE_DEG`]: where seed 000 reports artefacts.
    pub fn acute_tiles(&self) -> Vec<(String, f64)> {
        self.triangles()
            .into_iter()
            .filter_map(|(t, name)| {
                let a = min_angle(&t);
                (a < ACUTE_DEG).then_some((name, a))
            })
            .collect()
    }

    /// The screen as stored: pretty-printed JSON.
    pub fn to_json(&self) -> String {
        serde_json::to_string_pretty(self).expect("tile screens always serialise")
    }

    /// A stored screen read from JSON and validated; an error naming `tiles` when the text is not
    /// a tile screen.
    pub fn from_json(text: &str) -> Result<Self> {
        let t: TileScreen = serde_json::from_str(text)
            .map_err(|e| Error::invalid("tiles", format!("not a tile screen: {e}")))?;
        t.validate()?;
        Ok(t)
    }
}

/// A value for an error message: 1e308 as that, not as 309 digits.
fn shown(v: f64) -> String {
    if v.abs() < 1e6 {
        v.to_string()
    } else {
        format!("{v:e}")
    }
}

fn check_feature(name: &str, f: &Feature) -> Result<()> {
    let fields = [
        ("x", f.x),
        ("y", f.y),
        ("phi", f.phi),
        ("theta", f.theta),
        ("scale", f.scale),
        ("f", f.f),
        ("weight", f.weight),
    ];
    for (field, v) in fields {
        if !v.is_finite() {
            return Err(Error::invalid(
                format!("{name}.{field}"),
                format!("must be finite, got {v}"),
            ));
        }
    }
    for (field, v) in [("x", f.x), ("y", f.y)] {
        if !(0.0..=1.0).contains(&v) {
            return Err(Error::invalid(
                format!("{name}.{field}"),
                format!("must lie in [0, 1], got {v}"),
            ));
        }
    }
    for (field, v) in [("phi", f.phi), ("theta", f.theta)] {
        if v.abs() > 360.0 {
            return Err(Error::invalid(
                format!("{name}.{field}"),
                format!("must lie in [−360, 360] degrees, got {v}"),
            ));
        }
    }
    if !(f.weight > 0.0 && f.weight <= 1.0) {
        return Err(Error::invalid(
            format!("{name}.weight"),
            format!("must lie in (0, 1], got {}", f.weight),
        ));
    }
    let most = crate::limits::FEATURE_VALUE;
    if !(f.scale > 0.0 && f.scale <= most) {
        return Err(Error::invalid(
            format!("{name}.scale"),
            format!("must lie in (0, {most}], got {}", shown(f.scale)),
        ));
    }
    if f.f.abs() > most {
        return Err(Error::invalid(
            format!("{name}.f"),
            format!("must lie in [−{most}, {most}], got {}", shown(f.f)),
        ));
    }
    Ok(())
}
