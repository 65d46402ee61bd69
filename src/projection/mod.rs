//! Projection functions δP: normalised screen coordinates F = (s, t) ∈ [−1, 1]² to unit view
//! directions in the local frame (x right, y up, −z forward), and back.
//!
//! One file per projection holds only its forward and inverse formulas; the shared work
//! (content orientation C, off-axis vector O, zoom) lives once in [`view`]. Each projection has
//! one row in [`REGISTRY`]: its name, what it is, the parameters it takes and its constructor.
//! A parameter given to a projection that does not use it is an error, not silently ignored.
//! Every formula has a WGSL twin in `shaders/projections.wgsl`, which the GPU warp pass uses.

mod cylindrical;
mod cylindrical_vertical;
pub mod doc;
mod equirect;
mod fisheye;
mod perspective;
pub mod view;

pub use doc::ViewDoc;
pub use view::{Orientation, View};

use crate::error::{Error, Outside, Result, finite};
use glam::DVec3;
use std::fmt::Debug;

/// A single-centre projection function δP and its inverse.
pub trait Projection: Debug + Send + Sync {
    /// The registry name of this projection.
    fn name(&self) -> &'static str;
    /// δP(s, t): the unit local direction shown at normalised screen position (s, t).
    fn forward(&self, s: f64, t: f64) -> Result<DVec3, Outside>;
    /// δP⁻¹(d): the screen position showing the unit local direction `d`.
    fn inverse(&self, d: DVec3) -> Result<(f64, f64), Outside>;
    /// δP continued past the image's own boundary where the formula still holds (a fisheye
    /// beyond its image circle); for sampling grids whose tiles straddle that boundary.
    fn forward_unbounded(&self, s: f64, t: f64) -> Result<DVec3, Outside> {
        self.forward(s, t)
    }
    /// Which formula of `shaders/projections.wgsl` (the GPU twin of `forward`) and its
    /// constants.
    fn shader_form(&self) -> ShaderForm;
}

/// What the WGSL twin of δP needs: the formula (`kind`: 0 flat, 1 cylindrical,
/// 2 cylindrical-vertical, 3 equirect, 4 the fisheye family with `radial` 0 equidistant,
/// 1 equisolid, 2 stereographic, 3 orthographic), its constants (the same fields, in the same
/// order, as the Rust struct) and a rotation applied after it (the domemaster's turn).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ShaderForm {
    /// The formula: 0 flat, 1 cylindrical, 2 cylindrical-vertical, 3 equirect, 4 the fisheye
    /// family.
    pub kind: u32,
    /// The fisheye family's radial law: 0 equidistant, 1 equisolid, 2 stereographic,
    /// 3 orthographic; 0 for the other formulas.
    pub radial: u32,
    /// The formula's constants (angles in radians), the projection struct's fields in order;
    /// unused ones 0.
    pub p: [f64; 4],
    /// Rotation applied to δP's direction after the formula: the domemaster's turn, else identity.
    pub turn: glam::DMat3,
}

impl ShaderForm {
    fn new(kind: u32, p: [f64; 4]) -> Self {
        ShaderForm {
            kind,
            radial: 0,
            p,
            turn: glam::DMat3::IDENTITY,
        }
    }
}

/// Projection parameters as the user gives them: angles in degrees, `None` when not given.
#[derive(
    Debug,
    Clone,
    Copy,
    Default,
    PartialEq,
    serde::Serialize,
    serde::Deserialize,
    schemars::JsonSchema,
)]
#[serde(deny_unknown_fields)]
pub struct Params {
    /// Horizontal field of view, degrees.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub hfov: Option<f64>,
    /// Vertical field of view, degrees.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub vfov: Option<f64>,
    /// Image-circle field of view of a fisheye, degrees.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub fov: Option<f64>,
    /// Forward tilt of a dome's zenith, degrees.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub tilt: Option<f64>,
    /// Off-axis frustum edges as angles from the view axis, degrees (left and bottom negative).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub left: Option<f64>,
    /// Off-axis frustum: angle of the right edge from the view axis, degrees (left < right < 90).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub right: Option<f64>,
    /// Off-axis frustum: angle of the bottom edge from the view axis, degrees (−90 < bottom < top).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub bottom: Option<f64>,
    /// Off-axis frustum: angle of the top edge from the view axis, degrees (bottom < top < 90).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub top: Option<f64>,
}

impl Params {
    fn given(&self) -> impl Iterator<Item = &'static str> + '_ {
        [
            ("hfov", self.hfov),
            ("vfov", self.vfov),
            ("fov", self.fov),
            ("tilt", self.tilt),
            ("left", self.left),
            ("right", self.right),
            ("bottom", self.bottom),
            ("top", self.top),
        ]
        .into_iter()
        .filter_map(|(n, v)| v.map(|_| n))
    }
}

/// One registry row: everything there is to know about a projection in one place.
pub struct Entry {
    /// The projection's name, as `--projection` and a document's `projection` field take it.
    pub name: &'static str,
    /// Other names accepted for it (ffmpeg v360's where they differ).
    pub aliases: &'static [&'static str],
    /// What the projection is, in one line (`omniwarp projections` lists it).
    pub description: &'static str,
    /// The parameters it takes, with their meaning; all in degrees.
    pub params: &'static [(&'static str, &'static str)],
    /// Builds it from the parameters and the output aspect ratio height / width, which fills in
    /// the field of view that is not given so that pixels are square at the image centre.
    pub build: fn(&Params, f64) -> Result<Box<dyn Projection>>,
}

/// Every projection omniwarp knows, one row each.
pub static REGISTRY: &[Entry] = &[
    perspective::ENTRY,
    cylindrical::ENTRY,
    cylindrical_vertical::ENTRY,
    equirect::ENTRY,
    fisheye::EQUIDISTANT,
    fisheye::SPHERICAL,
    fisheye::EQUISOLID,
    fisheye::STEREOGRAPHIC,
    fisheye::ORTHOGRAPHIC,
    fisheye::DOMEMASTER,
];

/// Looks a projection up by name or alias.
pub fn entry(name: &str) -> Result<&'static Entry> {
    REGISTRY
        .iter()
        .find(|e| e.name == name || e.aliases.contains(&name))
        .ok_or_else(|| {
            let names: Vec<_> = REGISTRY.iter().map(|e| e.name).collect();
            Error::invalid(
                "projection",
                format!("unknown projection `{name}`; known: {}", names.join(", ")),
            )
        })
}

/// Builds the named projection, rejecting parameters it does not use.
pub fn build(name: &str, params: &Params, aspect: f64) -> Result<Box<dyn Projection>> {
    let e = entry(name)?;
    if let Some(unused) = params
        .given()
        .find(|p| !e.params.iter().any(|(n, _)| n == p))
    {
        return Err(Error::invalid(
            unused,
            format!("not a parameter of projection `{}`", e.name),
        ));
    }
    if !(aspect.is_finite() && aspect > 0.0) {
        return Err(Error::invalid(
            "size",
            "the output must have a positive width and height",
        ));
    }
    (e.build)(params, aspect)
}

/// Reads an angle parameter in degrees and returns it in radians, checking 0 < angle ≤ max
/// (or < max when `max_open`).
pub(crate) fn fov(name: &str, deg: f64, max_deg: f64, max_open: bool) -> Result<f64> {
    let deg = finite(name, deg)?;
    let too_big = if max_open {
        deg >= max_deg
    } else {
        deg > max_deg
    };
    // Below the smallest field of view a content pixel is so small that later steps (grids
    // sized from pixel tolerances) would overflow; see crate::limits.
    let min = crate::limits::MIN_FOV_DEG;
    if deg < min || too_big {
        let bound = if max_open { "below" } else { "at most" };
        return Err(Error::invalid(
            name,
            format!("must be above 0 (at least {min}) and {bound} {max_deg} degrees, got {deg}"),
        ));
    }
    Ok(deg.to_radians())
}

pub(crate) fn missing(projection: &str, what: &str) -> Error {
    Error::invalid(what, format!("projection `{projection}` needs it"))
}
