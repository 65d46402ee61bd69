//! The rig: one versioned JSON document (`"format": 1`) with the screen, the viewer's eye
//! point, the content orientation and the projector channels (docs/conventions.md). Errors name the
//! field by its JSON pointer (`/channels/1/lens/intrinsics`) and say why.
//!
//! A channel's pose is the projector-to-world transform: `position` plus either `look_to` and
//! `look_up` or `rvec` (OpenCV's Rodrigues vector of that rotation; note that OpenCV's
//! `solvePnP` returns the inverse, world-to-camera). The projector frame is OpenCV's: x right,
//! y down, z forward.

mod blend;
mod canvas;
mod coverage;
mod photometry;
pub mod plan;
pub mod schema;
mod tiles;
mod warp;

pub use canvas::{Canvas, Layout};
pub use coverage::Coverage;
pub use photometry::{ChannelBlend, apply_blend_and_lift};
pub use plan::{ChannelPlan, Overlap, Plan, PointPlan, WallPlan};

pub use blend::{
    BlendOptions, apply_gains, black_png_bytes, blend_png_bytes, gain, gains_image, signal_gains,
    write_black_png, write_blend_png,
};
pub use tiles::{SAMPLED_COLUMNS, default_rows};
pub use warp::ChannelWarp;

use crate::error::{Error, Result};
use crate::lens::{Lens, LensModel};
use crate::projection::Orientation;
use crate::surface::Screen;
use glam::{DMat3, DVec3};
use serde::{Deserialize, Serialize};
use std::path::Path;

/// The demo rig `omniwarp serve --demo` starts with: the 270° cylinder with three projectors of
/// `calibration/rigs/cylinder-270-3proj.json`.
pub const DEMO_RIG: &str = include_str!("../../calibration/rigs/cylinder-270-3proj.json");

/// The rig file as written.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct RigDoc {
    /// The document's format version; only 1 is known.
    pub format: u32,
    /// The wall the projectors light.
    pub screen: Screen,
    /// The sweet spot the content is computed for, metres.
    pub eye: [f64; 3],
    /// The content's orientation and off-axis vector; left out, the identity and no offset.
    #[serde(default)]
    pub content: ContentDoc,
    /// The projectors, one channel each; at least one, at most
    /// [`crate::limits::CHANNELS`], with distinct ids.
    pub channels: Vec<ChannelDoc>,
    /// The show's content canvas, which every channel plays unless it has its own; left out,
    /// the whole sphere as a 4096×2048 equirect ([`Canvas::default`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub canvas: Option<Canvas>,
}

impl RigDoc {
    /// The memory the channels' warps take, at [`crate::limits::WARP_BYTES_PER_PIXEL`].
    pub fn warp_bytes(&self) -> u64 {
        self.channels
            .iter()
            .map(|c| u64::from(c.resolution[0]) * u64::from(c.resolution[1]))
            .sum::<u64>()
            * crate::limits::WARP_BYTES_PER_PIXEL
    }

    /// The document alone, unvalidated and with any mesh not loaded; errors name the field by
    /// JSON pointer, and text after the document is refused.
    pub fn parse(text: &str) -> Result<RigDoc> {
        let mut de = serde_json::Deserializer::from_str(text);
        let doc: RigDoc = serde_path_to_error::deserialize(&mut de).map_err(|e| {
            let mut pointer = pointer_of(&e.path().to_string());
            let mut reason = e.into_inner().to_string();
            // serde reads a tagged enum (the screen) whole before its variant, so the error
            // stops at `/screen`: read the variant again on its own for the field within.
            if pointer == "/screen"
                && let Some((inner, why)) = screen_error(text)
            {
                (pointer, reason) = (format!("/screen{inner}"), why);
            }
            // What belongs there, from the schema the same types publish.
            let doc = serde_json::from_str(text).unwrap_or(serde_json::Value::Null);
            let reason = match schema::describe(&pointer, &doc) {
                Some(d) => {
                    let first = d.split(". ").next().unwrap_or(&d).trim_end_matches('.');
                    format!("{reason} ({first})")
                }
                None => reason,
            };
            Error::invalid(pointer, reason)
        })?;
        de.end()
            .map_err(|e| Error::invalid("/", format!("text after the rig document: {e}")))?;
        Ok(doc)
    }
}

/// The pointer within the screen (`/radius`) and the reason its variant refuses it, read on its
/// own from the rig text; `None` when that finds nothing more precise.
fn screen_error(text: &str) -> Option<(String, String)> {
    use crate::surface::{Cylinder, Dome, Plane};
    let mut screen = serde_json::from_str::<serde_json::Value>(text).ok()?["screen"].take();
    let kind = screen.as_object_mut()?.remove("kind")?;
    fn inner<T: serde::de::DeserializeOwned>(v: serde_json::Value) -> Option<(String, String)> {
        let e = serde_path_to_error::deserialize::<_, T>(v).err()?;
        Some((
            pointer_of(&e.path().to_string()),
            e.into_inner().to_string(),
        ))
    }
    match kind.as_str()? {
        "cylinder" => inner::<Cylinder>(screen),
        "dome" => inner::<Dome>(screen),
        "plane" => inner::<Plane>(screen),
        _ => None,
    }
    .filter(|(p, _)| p != "/")
}

/// How content directions relate to the world: V = C·d − O, normalised, where d is the unit
/// direction from the eye to the wall point and C is built from look-to/look-up as in the
/// projection view transform.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct ContentDoc {
    /// The content direction seen straight ahead of the eye (world −z); any non-zero length,
    /// (0, 0, −1) by default.
    #[serde(default = "crate::projection::view::default_look_to")]
    pub look_to: [f64; 3],
    /// The content direction seen straight up (world +y), made perpendicular to `look_to`;
    /// not parallel to it, (0, 1, 0) by default.
    #[serde(default = "crate::projection::view::default_look_up")]
    pub look_up: [f64; 3],
    /// The off-axis vector O subtracted before normalising (seed 000, section 3); its length
    /// must be below 1, zero by default.
    #[serde(default)]
    pub offaxis: [f64; 3],
}

impl Default for ContentDoc {
    fn default() -> Self {
        ContentDoc {
            look_to: crate::projection::view::default_look_to(),
            look_up: crate::projection::view::default_look_up(),
            offaxis: [0.0; 3],
        }
    }
}

/// One projector channel as the rig file writes it (an element of `channels`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct ChannelDoc {
    /// The channel's name, unique in the rig: 1–64 ASCII letters, digits, '-', '_' or '.',
    /// not starting with '.' (it names files, URL segments and MPCDI regions).
    pub id: String,
    /// Width and height in pixels.
    pub resolution: [u32; 2],
    /// The projector's lens model and intrinsics.
    pub lens: LensDoc,
    /// Where the projector is and where it points (projector-to-world).
    pub pose: PoseDoc,
    /// The projector's contrast ratio, full white over full black (2000 for 2,000:1; more
    /// than 1, at most 10,000,000). With it the channel's pictures are lifted in the dark
    /// where fewer projectors overlap, so that a black frame is evenly black
    /// (docs/photometry.md). Left out: the projector shows true black.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub contrast: Option<f64>,
}

/// A lens as the rig file writes it (a channel's `lens`); docs/lens-models.md has the models.
/// A planned projector may give its throw ratio and lens shift instead of intrinsics; the rig
/// holds them as the pinhole intrinsics they amount to.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct LensDoc {
    /// mrcal's model name, e.g. `LENSMODEL_OPENCV5`; `LENSMODEL_PINHOLE` when left out.
    #[serde(default = "pinhole")]
    pub model: String,
    /// The model's intrinsics in mrcal's (and OpenCV's) order: fx, fy, cx, cy in pixels, then
    /// the distortion parameters; (cx, cy) counts from the centre of the top-left pixel.
    /// Left out when `throw_ratio` is given.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub intrinsics: Vec<f64>,
    /// Throw distance over image width, as projector data sheets give it (0.1–20): the
    /// pinhole's fx = fy = throw ratio × width in pixels.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub throw_ratio: Option<f64>,
    /// Lens shift `[horizontal, vertical]` as fractions of the image's width and height, with
    /// `throw_ratio` only (−2 to 2 each; `[0, 0]` when left out): +0.5 vertical puts the
    /// optical axis on the image's bottom edge (the image raised half its height), +0.5
    /// horizontal moves the image half its width to the right.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub shift: Option<[f64; 2]>,
}

fn pinhole() -> String {
    "LENSMODEL_PINHOLE".into()
}

impl LensDoc {
    /// A lens of `model` with `intrinsics`.
    pub fn new(model: impl Into<String>, intrinsics: Vec<f64>) -> LensDoc {
        LensDoc {
            model: model.into(),
            intrinsics,
            throw_ratio: None,
            shift: None,
        }
    }

    /// The lens of a `width` × `height` projector as its model and intrinsics, from its
    /// throw ratio and shift when given; errors name the field under `prefix`.
    pub fn intrinsics_for(&self, width: u32, height: u32, prefix: &str) -> Result<Vec<f64>> {
        let at = |f: &str| format!("{prefix}/{f}");
        let Some(throw) = self.throw_ratio else {
            if self.shift.is_some() {
                return Err(Error::invalid(
                    at("shift"),
                    "is given with throw_ratio only",
                ));
            }
            return Ok(self.intrinsics.clone());
        };
        if !self.intrinsics.is_empty() {
            return Err(Error::invalid(
                at("throw_ratio"),
                "give either intrinsics or throw_ratio, not both",
            ));
        }
        if self.model != "LENSMODEL_PINHOLE" {
            return Err(Error::invalid(
                at("model"),
                "a throw ratio describes a pinhole lens: LENSMODEL_PINHOLE or left out",
            ));
        }
        if !(0.1..=20.0).contains(&throw) {
            return Err(Error::invalid(
                at("throw_ratio"),
                format!("must be 0.1 to 20, got {throw}"),
            ));
        }
        let [sx, sy] = self.shift.unwrap_or([0.0; 2]);
        if !(sx.abs() <= 2.0 && sy.abs() <= 2.0) {
            return Err(Error::invalid(
                at("shift"),
                "each part must be −2 to 2 (fractions of the image's width and height)",
            ));
        }
        let (w, h) = (f64::from(width), f64::from(height));
        let f = throw * w;
        Ok(vec![
            f,
            f,
            (w - 1.0) / 2.0 - sx * w,
            (h - 1.0) / 2.0 + sy * h,
        ])
    }
}

/// A projector's pose as the rig file writes it: the projector-to-world transform, given by
/// `position` and either `look_to` and `look_up` or `rvec`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct PoseDoc {
    /// The projector's centre of projection in the world, metres.
    pub position: [f64; 3],
    /// The world direction of the projector's optical axis (its frame's +z); any non-zero
    /// length. Given with `look_up`, never with `rvec`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub look_to: Option<[f64; 3]>,
    /// The world direction that is up in the projected image (its frame's −y, made
    /// perpendicular to `look_to`); not parallel to `look_to`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub look_up: Option<[f64; 3]>,
    /// The projector-to-world rotation as a Rodrigues vector (axis × angle, radians), in place
    /// of `look_to` and `look_up`; OpenCV's `solvePnP` returns the inverse.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rvec: Option<[f64; 3]>,
}

/// A validated channel.
#[derive(Debug, Clone, PartialEq)]
pub struct Channel {
    /// The channel's id, unique in the rig.
    pub id: String,
    /// Projector pixels across, 1 to [`crate::limits::CHANNEL_SIDE`].
    pub width: u32,
    /// Projector pixels down, 1 to [`crate::limits::CHANNEL_SIDE`].
    pub height: u32,
    /// The projector's lens: projector frame ↔ pixel (OpenCV frame, pixel centres at integers).
    pub lens: Lens,
    /// The projector's centre of projection in the world, metres.
    pub position: DVec3,
    /// Projector frame to world.
    pub rotation: DMat3,
    /// Full white over full black, from the channel's `contrast`; `None` for true black.
    pub contrast: Option<f64>,
}

impl Channel {
    /// The channel as a document, its pose as a Rodrigues vector: what
    /// [`Channel::from_doc`] reads back to the same channel.
    pub fn doc(&self) -> ChannelDoc {
        let (axis, angle) = glam::DQuat::from_mat3(&self.rotation).to_axis_angle();
        ChannelDoc {
            id: self.id.clone(),
            resolution: [self.width, self.height],
            lens: LensDoc::new(
                self.lens.model().to_string(),
                self.lens.intrinsics().to_vec(),
            ),
            pose: PoseDoc {
                position: self.position.to_array(),
                look_to: None,
                look_up: None,
                rvec: Some((axis * angle).to_array()),
            },
            contrast: self.contrast,
        }
    }

    /// Validates one channel document (a projector, or a camera on the virtual bench) whose
    /// fields sit under the JSON pointer `prefix`. The id is checked by the rig, which knows the
    /// other ids.
    pub fn from_doc(c: &ChannelDoc, prefix: &str) -> Result<Channel> {
        let at = |f: &str| format!("{prefix}/{f}");
        let [w, h] = c.resolution;
        let side = crate::limits::CHANNEL_SIDE;
        if !(1..=side).contains(&w) || !(1..=side).contains(&h) {
            return Err(Error::invalid(
                at("resolution"),
                format!("must be between 1 and {side} pixels each way, got {w}×{h}"),
            ));
        }
        let model: LensModel = c
            .lens
            .model
            .parse()
            .map_err(|e: Error| Error::invalid(at("lens/model"), e.reason()))?;
        let intrinsics = c.lens.intrinsics_for(w, h, &at("lens"))?;
        let lens = Lens::new(model, intrinsics)
            .map_err(|e| Error::invalid(at("lens/intrinsics"), e.reason()))?;
        let position = vec3(&at("pose/position"), c.pose.position)?;
        let rotation = match (c.pose.look_to, c.pose.look_up, c.pose.rvec) {
            (Some(to), Some(upv), None) => {
                let f = crate::surface::unit(&at("pose/look_to"), DVec3::from_array(to))?;
                let u = crate::surface::unit(&at("pose/look_up"), DVec3::from_array(upv))?;
                let right = f.cross(u);
                if right.length() < 1e-6 {
                    return Err(Error::invalid(
                        at("pose/look_up"),
                        "must not be parallel to look_to",
                    ));
                }
                let right = right.normalize();
                // OpenCV frame: x right, y down, z forward.
                DMat3::from_cols(right, f.cross(right), f)
            }
            (None, None, Some(r)) => rodrigues(vec3(&at("pose/rvec"), r)?),
            _ => {
                return Err(Error::invalid(
                    at("pose"),
                    "give either look_to and look_up, or rvec",
                ));
            }
        };
        if let Some(k) = c.contrast
            && !(k.is_finite() && k > 1.0 && k <= 1e7)
        {
            return Err(Error::invalid(
                at("contrast"),
                format!("must be more than 1 and at most 10000000 (white over black), got {k}"),
            ));
        }
        Ok(Channel {
            id: c.id.clone(),
            width: w,
            height: h,
            lens,
            position,
            rotation,
            contrast: c.contrast,
        })
    }
}

/// How a projector changed from one lens and pose to another (a calibration applied): what
/// `calibrate --update` prints and the daemon's proposal apply answers.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ChannelChange {
    /// How far its centre of projection moved, metres.
    pub moved: f64,
    /// How far its optical axis turned, degrees.
    pub turned: f64,
    /// Its lens model, before and after.
    pub model: [String; 2],
    /// Its focal length fx, before and after, pixels.
    pub focal: [f64; 2],
}

impl ChannelChange {
    /// A turn beyond which the points were more likely another projector's than this one's
    /// (a first calibration of a planned rig moves projectors, but does not turn them round).
    pub const SUSPICIOUS_TURN: f64 = 30.0;
}

impl Channel {
    /// How this channel changed into `after`.
    pub fn change_to(&self, after: &Channel) -> ChannelChange {
        let forward = |c: &Channel| c.rotation * DVec3::Z;
        ChannelChange {
            moved: (after.position - self.position).length(),
            turned: forward(self).angle_between(forward(after)).to_degrees(),
            model: [
                self.lens.model().to_string(),
                after.lens.model().to_string(),
            ],
            focal: [self.lens.intrinsics()[0], after.lens.intrinsics()[0]],
        }
    }
}

/// A validated rig.
#[derive(Debug, Clone)]
pub struct Rig {
    /// The document the rig was validated from, a mesh screen's OBJ loaded.
    pub doc: RigDoc,
    /// The eye point the content is computed for, metres.
    pub eye: DVec3,
    /// The content orientation C, from the document's `content.look_to` and `look_up`.
    pub content: Orientation,
    /// The off-axis vector O, from `content.offaxis`; shorter than 1.
    pub offaxis: DVec3,
    /// The validated channels, in the document's order.
    pub channels: Vec<Channel>,
}

/// Rodrigues: rotation by |r| about r/|r|.
pub fn rodrigues(r: DVec3) -> DMat3 {
    let theta = r.length();
    if theta < f64::EPSILON {
        return DMat3::IDENTITY;
    }
    DMat3::from_axis_angle(r / theta, theta)
}

/// A finite vector within [`crate::limits::WORLD_EXTENT`] of the origin in each coordinate
/// (points in metres; directions are far inside it).
fn vec3(field: &str, v: [f64; 3]) -> Result<DVec3> {
    let v = crate::surface::finite3(field, DVec3::from_array(v))?;
    let far = crate::limits::WORLD_EXTENT;
    if v.abs().max_element() > far {
        return Err(Error::invalid(
            field,
            format!("is more than the limit of {far} m from the origin"),
        ));
    }
    Ok(v)
}

impl Rig {
    /// Parses and validates a rig; `base` is where relative paths (mesh screens) start.
    pub fn from_json(text: &str, base: &Path) -> Result<Rig> {
        let mut doc = RigDoc::parse(text)?;
        doc.screen.load(base, "/screen")?;
        Rig::from_doc(doc)
    }

    /// Reads, parses and validates a rig file; mesh paths are relative to its folder, and
    /// errors name the file.
    pub fn read(path: &Path) -> Result<Rig> {
        let text = std::fs::read_to_string(path).map_err(|e| Error::file(path, e))?;
        let base = path.parent().unwrap_or(Path::new("."));
        Rig::from_json(&text, base).map_err(|e| Error::file(path, e))
    }

    /// Validates a parsed document (its mesh, if any, already loaded); errors name the field
    /// by JSON pointer.
    pub fn from_doc(doc: RigDoc) -> Result<Rig> {
        if doc.format != 1 {
            return Err(Error::invalid(
                "/format",
                format!("only format 1 is known, got {}", doc.format),
            ));
        }
        doc.screen.validate("/screen")?;
        let eye = vec3("/eye", doc.eye)?;
        let content = Orientation::look(
            vec3("/content/look_to", doc.content.look_to)?,
            vec3("/content/look_up", doc.content.look_up)?,
        )
        .map_err(|e| Error::invalid("/content", e.to_string()))?;
        let offaxis = vec3("/content/offaxis", doc.content.offaxis)?;
        if offaxis.length() >= 1.0 {
            return Err(Error::invalid(
                "/content/offaxis",
                "its length must be below 1",
            ));
        }
        if doc.channels.is_empty() {
            return Err(Error::invalid(
                "/channels",
                "a rig needs at least one channel",
            ));
        }
        crate::limits::at_most("/channels", doc.channels.len(), crate::limits::CHANNELS)?;
        let mut channels = Vec::with_capacity(doc.channels.len());
        for (n, c) in doc.channels.iter().enumerate() {
            let at = |f: &str| format!("/channels/{n}/{f}");
            // Ids name files, URL segments and MPCDI regions: keep them to a safe alphabet.
            let safe = |ch: char| ch.is_ascii_alphanumeric() || matches!(ch, '-' | '_' | '.');
            if c.id.is_empty()
                || c.id.len() > 64
                || !c.id.chars().all(safe)
                || c.id.starts_with('.')
            {
                return Err(Error::invalid(
                    at("id"),
                    "must be 1–64 letters, digits, '-', '_' or '.', not starting with '.'",
                ));
            }
            if doc.channels[..n].iter().any(|o| o.id == c.id) {
                return Err(Error::invalid(
                    at("id"),
                    format!("`{}` is used by another channel", c.id),
                ));
            }
            channels.push(Channel::from_doc(c, &format!("/channels/{n}"))?);
        }
        if let Some(canvas) = &doc.canvas {
            canvas.view().map_err(|e| under("/canvas", e))?;
        }
        // A throw ratio is held as the intrinsics it amounts to, which every reader knows.
        let mut doc = doc;
        for (c, ch) in doc.channels.iter_mut().zip(&channels) {
            if c.lens.throw_ratio.is_some() {
                c.lens = LensDoc::new(c.lens.model.clone(), ch.lens.intrinsics().to_vec());
            }
        }
        let rig = Rig {
            doc,
            eye,
            content,
            offaxis,
            channels,
        };
        if let Some(canvas) = &rig.doc.canvas {
            canvas.centre(&rig).map_err(|e| under("/canvas", e))?;
        }
        Ok(rig)
    }

    /// The show's content canvas: the document's, or the whole sphere by default.
    pub fn canvas(&self) -> Canvas {
        self.doc.canvas.clone().unwrap_or_default()
    }

    /// What the warps of all channels hold in memory at once, bytes (see
    /// [`crate::limits::WARP_BYTES_PER_PIXEL`]).
    pub fn warp_bytes(&self) -> u64 {
        self.doc.warp_bytes()
    }

    /// What the rig is counted as in a memory budget: its warps and its mesh screen, if any.
    pub fn memory_bytes(&self) -> u64 {
        self.warp_bytes() + self.mesh_bytes()
    }

    fn mesh_bytes(&self) -> u64 {
        match &self.doc.screen {
            crate::surface::Screen::Mesh {
                loaded: Some(mesh), ..
            } => mesh.memory_bytes(),
            _ => 0,
        }
    }

    /// Refuses a rig whose warps and mesh would not fit in `budget` bytes, naming the largest
    /// channel (or the mesh, when it is the larger part).
    pub fn check_budget(&self, budget: u64) -> Result<()> {
        let need = self.memory_bytes();
        if need <= budget {
            return Ok(());
        }
        let (n, c) = self
            .channels
            .iter()
            .enumerate()
            .max_by_key(|(_, c)| u64::from(c.width) * u64::from(c.height))
            .expect("a rig has channels");
        let (mesh, warps) = (self.mesh_bytes(), self.warp_bytes());
        let field = if mesh > warps {
            "/screen/obj".to_string()
        } else {
            format!("/channels/{n}/resolution")
        };
        let with_mesh = if mesh > 0 {
            format!(" with the mesh screen's {} MiB", mesh >> 20)
        } else {
            String::new()
        };
        Err(Error::invalid(
            field,
            format!(
                "the warps of all channels need {} MiB ({}×{} is the largest){with_mesh}, above \
                 the memory budget of {} MiB",
                warps >> 20,
                c.width,
                c.height,
                budget >> 20
            ),
        ))
    }

    /// The channel with id `id`; an error listing the rig's ids if there is none.
    pub fn channel(&self, id: &str) -> Result<&Channel> {
        self.channels.iter().find(|c| c.id == id).ok_or_else(|| {
            let ids: Vec<_> = self.channels.iter().map(|c| c.id.as_str()).collect();
            Error::invalid(
                "channel",
                format!("no channel `{id}`; the rig has {}", ids.join(", ")),
            )
        })
    }

    /// The same rig with every projector's resolution divided by `factor` (the lenses scaled to
    /// match): previews and tests at a fraction of the cost.
    pub fn downscaled(&self, factor: u32) -> Result<Rig> {
        let f = f64::from(factor.max(1));
        let mut doc = self.doc.clone();
        for (c, ch) in doc.channels.iter_mut().zip(&self.channels) {
            c.resolution = [
                (ch.width / factor.max(1)).max(1),
                (ch.height / factor.max(1)).max(1),
            ];
            let i = &mut c.lens.intrinsics;
            i[0] /= f;
            i[1] /= f;
            i[2] = (i[2] + 0.5) / f - 0.5;
            i[3] = (i[3] + 0.5) / f - 0.5;
        }
        // The cloned document keeps the loaded mesh, if any.
        Rig::from_doc(doc)
    }
}

/// An error of a part of the document, its field pointer put under `prefix`.
fn under(prefix: &str, e: Error) -> Error {
    match e {
        Error::Invalid { name, reason } if name.starts_with('/') => {
            Error::invalid(format!("{prefix}{name}"), reason)
        }
        Error::Invalid { name, reason } => Error::invalid(format!("{prefix}/{name}"), reason),
        other => other,
    }
}

/// serde_path_to_error's `channels[1].lens.model` as a JSON pointer `/channels/1/lens/model`.
pub fn pointer_of(path: &str) -> String {
    if path == "." || path.is_empty() {
        return "/".into();
    }
    let mut out = String::new();
    for part in path.split('.') {
        let mut rest = part;
        while let Some(open) = rest.find('[') {
            if open > 0 {
                out.push('/');
                out.push_str(&rest[..open]);
            }
            let close = rest[open..].find(']').map_or(rest.len(), |c| open + c);
            out.push('/');
            out.push_str(&rest[open + 1..close]);
            rest = &rest[(close + 1).min(rest.len())..];
        }
        if !rest.is_empty() {
            out.push('/');
            out.push_str(rest);
        }
    }
    out
}
