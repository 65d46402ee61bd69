//! Arguments several commands share, their parsers, and how errors about them are worded: every
//! error about an argument starts with the flag's name (`--size: …`), which is also how the
//! binary tells a refused command line (exit 2) from failed work (exit 1).

use anyhow::{Context, Result, bail};
use clap::{Args, ValueEnum};
use glam::DVec3;
use omniwarp::content::Format;
use omniwarp::projection::{self, Orientation, Params, View};
use omniwarp::render::Filter;
use omniwarp::tiles::build::Source;
use std::path::{Path, PathBuf};

#[derive(Args, Clone)]
pub struct ProjectionArgs {
    /// Projection name (see `omniwarp projections`): flat, cylindrical, fisheye, equirect, ...
    #[arg(long)]
    pub projection: Option<String>,
    /// Horizontal field of view, degrees.
    #[arg(long, allow_hyphen_values = true)]
    pub hfov: Option<f64>,
    /// Vertical field of view, degrees.
    #[arg(long, allow_hyphen_values = true)]
    pub vfov: Option<f64>,
    /// Image-circle field of view of a fisheye, degrees.
    #[arg(long, allow_hyphen_values = true)]
    pub fov: Option<f64>,
    /// Forward tilt of a domemaster's zenith, degrees.
    #[arg(long, allow_hyphen_values = true)]
    pub tilt: Option<f64>,
    /// Off-axis frustum of `flat`: angle of the left edge from the axis, degrees (negative).
    #[arg(long, allow_hyphen_values = true)]
    pub left: Option<f64>,
    /// Off-axis frustum of `flat`: angle of the right edge, degrees.
    #[arg(long, allow_hyphen_values = true)]
    pub right: Option<f64>,
    /// Off-axis frustum of `flat`: angle of the bottom edge, degrees (negative).
    #[arg(long, allow_hyphen_values = true)]
    pub bottom: Option<f64>,
    /// Off-axis frustum of `flat`: angle of the top edge, degrees.
    #[arg(long, allow_hyphen_values = true)]
    pub top: Option<f64>,
    /// Viewing direction x,y,z in the world (+y up, −z forward); any length.
    #[arg(long, value_parser = parse_vec3, default_value = "0,0,-1", allow_hyphen_values = true)]
    pub look_to: DVec3,
    /// Up direction x,y,z; must not be parallel to --look-to.
    #[arg(long, value_parser = parse_vec3, default_value = "0,1,0", allow_hyphen_values = true)]
    pub look_up: DVec3,
    /// Off-axis vector O subtracted from the view direction (unitless, length below 1).
    #[arg(long, value_parser = parse_vec3, default_value = "0,0,0", allow_hyphen_values = true)]
    pub offaxis: DVec3,
    /// Zoom factor applied to the screen coordinates before projecting (unitless, > 0).
    #[arg(long, default_value_t = 1.0, allow_hyphen_values = true)]
    pub zoom: f64,
}

impl ProjectionArgs {
    pub fn view(&self, width: u32, height: u32) -> Result<View> {
        self.source(width, height)?.view().map_err(flag_error)
    }

    /// The projection and view as a tile screen's source.
    pub fn source(&self, width: u32, height: u32) -> Result<Source> {
        let name = self
            .projection
            .as_deref()
            .context("missing --projection (or give --normal-map or --tiles)")?;
        let params = Params {
            hfov: self.hfov,
            vfov: self.vfov,
            fov: self.fov,
            tilt: self.tilt,
            left: self.left,
            right: self.right,
            bottom: self.bottom,
            top: self.top,
        };
        let aspect = f64::from(height) / f64::from(width);
        let source = Source {
            projection: name.to_string(),
            params,
            aspect,
            look_to: self.look_to.to_array(),
            look_up: self.look_up.to_array(),
            offaxis: self.offaxis.to_array(),
            zoom: self.zoom,
        };
        // Checked here so that every error names its flag.
        projection::build(name, &params, aspect).map_err(flag_error)?;
        Orientation::look(self.look_to, self.look_up).map_err(flag_error)?;
        source.view().map_err(flag_error)?;
        Ok(source)
    }
}

/// Library errors name parameters as `name`; on the command line they are `--name`.
pub fn flag_error(e: omniwarp::Error) -> anyhow::Error {
    match e {
        omniwarp::Error::Invalid { name, reason } => anyhow::anyhow!("--{name}: {reason}"),
        other => other.into(),
    }
}

#[derive(Args)]
pub struct ContentArgs {
    /// Content image: PNG or JPEG (8-bit) or OpenEXR (float); for `render`, also a movie
    /// or an image sequence (`frame-%05d.png`), read with ffmpeg.
    #[arg(long)]
    pub content: Option<PathBuf>,
    /// How the content image is laid out.
    #[arg(long, value_enum)]
    pub content_format: Option<ContentFormat>,
    /// Horizontal field of view of a panorama, degrees (default 360).
    #[arg(long)]
    pub content_hfov: Option<f64>,
    /// Vertical field of view of a panorama, degrees (default: 180 for a full equirect; square
    /// pixels otherwise).
    #[arg(long)]
    pub content_vfov: Option<f64>,
    /// Field of view across a fisheye's or dome master's image circle, degrees (default 180;
    /// up to 360).
    #[arg(long)]
    pub content_fov: Option<f64>,
    /// Forward tilt of a dome master's zenith, degrees (default 0; ±90).
    #[arg(long, allow_hyphen_values = true)]
    pub content_tilt: Option<f64>,
    /// A fisheye's image circle: centre x,y and radius, in pixels from the image's top-left
    /// corner (default: the circle inscribed in the image).
    #[arg(long, value_parser = parse_vec3)]
    pub content_circle: Option<DVec3>,
    /// Orientation of the content in the world: yaw,pitch,roll in degrees (yaw turns left,
    /// pitch up, roll clockwise).
    #[arg(long, value_parser = parse_vec3, default_value = "0,0,0", allow_hyphen_values = true)]
    pub content_rotate: DVec3,
    /// How a cylindrical panorama is looked up: exact (atan2 per sample), residual (seed 001's
    /// linear part plus a 256×256 residual table: within 0.004 texel) or residual8 (the seed's
    /// 8-bit residuals: about half a texel off).
    #[arg(long, value_enum, default_value = "exact")]
    pub content_lookup: ContentLookup,
}

#[derive(Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum ContentLookup {
    Exact,
    Residual,
    Residual8,
}

impl ContentLookup {
    /// Applies the lookup to loaded content.
    pub fn apply<T: omniwarp::raster::Pixel>(
        self,
        c: omniwarp::content::Content<T>,
    ) -> Result<omniwarp::content::Content<T>> {
        match self {
            ContentLookup::Exact => Ok(c),
            ContentLookup::Residual => c.with_residual_split(None).map_err(flag_error),
            ContentLookup::Residual8 => c.with_residual_split(Some(8)).map_err(flag_error),
        }
    }
}

#[derive(Clone, Copy, ValueEnum)]
pub enum ContentFormat {
    /// Six faces side by side in omniwarp's order +X −X +Y −Y +Z −Z.
    Cubemap,
    /// ffmpeg v360's c3x2 layout.
    CubemapC3x2,
    /// ffmpeg v360's c6x1 layout.
    CubemapC6x1,
    /// Equirectangular panorama.
    Equirect,
    /// Cylindrical panorama (seed 001: height linear on the cylinder).
    Cylindrical,
    /// Angular (equidistant) fisheye looking ahead: --content-fov, --content-circle.
    Fisheye,
    /// Dome master: an angular fisheye with the zenith at its centre and the front of the dome
    /// at the bottom: --content-fov, --content-tilt, --content-circle.
    Domemaster,
    /// Six files: --content names them with `{face}`, replaced by px nx py ny pz nz.
    CubemapFaces,
}

impl ContentFormat {
    pub fn format(self) -> Format {
        match self {
            ContentFormat::Cubemap | ContentFormat::CubemapFaces => Format::Cubemap,
            ContentFormat::CubemapC3x2 => Format::CubemapC3x2,
            ContentFormat::CubemapC6x1 => Format::CubemapC6x1,
            ContentFormat::Equirect => Format::Equirect,
            ContentFormat::Cylindrical => Format::Cylindrical,
            ContentFormat::Fisheye => Format::Fisheye,
            ContentFormat::Domemaster => Format::Domemaster,
        }
    }
}

#[derive(Clone, Copy, ValueEnum)]
pub enum FilterArg {
    Nearest,
    Bilinear,
    Bicubic,
}

#[derive(Clone, Copy, ValueEnum)]
pub enum CubeLayoutArg {
    /// Six faces side by side in omniwarp's order.
    Strip,
    /// ffmpeg's c3x2.
    C3x2,
    /// ffmpeg's c6x1.
    C6x1,
    /// Six files: OUT must contain `{face}`, replaced by px nx py ny pz nz.
    Faces,
}

pub fn parse_vec3(s: &str) -> Result<DVec3, String> {
    let v: Vec<f64> = s
        .split(',')
        .map(|c| c.trim().parse::<f64>())
        .collect::<Result<_, _>>()
        .map_err(|e| format!("expected three numbers x,y,z: {e}"))?;
    match v[..] {
        [x, y, z] if v.iter().all(|c| c.is_finite()) => Ok(DVec3::new(x, y, z)),
        [_, _, _] => Err("components must be finite".into()),
        _ => Err(format!("expected three numbers x,y,z, got {}", v.len())),
    }
}

/// A structured-light code by name: `gray` or `xor`.
pub fn parse_code(s: &str) -> Result<omniwarp::structured::Code, String> {
    s.parse().map_err(|e: omniwarp::Error| e.reason())
}

pub fn parse_size(s: &str) -> Result<(u32, u32), String> {
    let parse = |v: &str| {
        v.trim()
            .parse::<u32>()
            .ok()
            .filter(|&n| (1..=32768).contains(&n))
            .ok_or_else(|| format!("`{v}` is not a size between 1 and 32768 pixels"))
    };
    match s.split_once(['x', 'X']) {
        Some((w, h)) => Ok((parse(w)?, parse(h)?)),
        None => parse(s).map(|n| (n, n)),
    }
}

pub fn filter(f: FilterArg) -> Filter {
    match f {
        FilterArg::Nearest => Filter::Nearest,
        FilterArg::Bilinear => Filter::Bilinear,
        FilterArg::Bicubic => Filter::Bicubic,
    }
}

pub fn check_ext(path: &Path, allowed: &[&str]) -> Result<()> {
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase)
        .unwrap_or_default();
    if !allowed.contains(&ext.as_str()) {
        bail!(
            "--out: {} must end in .{}",
            path.display(),
            allowed.join(" or .")
        );
    }
    Ok(())
}

/// Whether `e` is about the command line or its input (exit 2) rather than failed work (exit 1).
pub fn is_usage(e: &anyhow::Error) -> bool {
    e.to_string().starts_with("--")
        || e.chain().any(|c| {
            matches!(
                c.downcast_ref::<omniwarp::Error>(),
                Some(omniwarp::Error::Invalid { .. } | omniwarp::Error::Outside(_))
            )
        })
}

/// A library error as "field: reason", for input whose fields are not flags (a JSON file).
pub fn named(e: omniwarp::Error) -> String {
    match e {
        omniwarp::Error::Invalid { name, reason } => format!("{name}: {reason}"),
        other => other.to_string(),
    }
}

/// The virtual bench's scene and conditions, shared by `omniwarp simulate` and
/// `omniwarp bench camera`.
#[derive(Args)]
pub struct BenchConditions {
    #[arg(long, default_value = "calibration/rigs/dome-180-tilt15-5proj.json")]
    pub rig: PathBuf,
    /// The projector's channel id (default: the rig's first).
    #[arg(long)]
    pub channel: Option<String>,
    /// The camera as a rig channel (JSON: id, resolution, lens, pose). Default: a 185° fisheye
    /// of --camera-size at the rig's eye, looking at the middle of the projector's image.
    #[arg(long)]
    pub camera: Option<PathBuf>,
    /// The default camera's size.
    #[arg(long, value_parser = parse_size, default_value = "1920x1080")]
    pub camera_size: (u32, u32),
    /// Sensor noise σ, grey levels.
    #[arg(long, default_value_t = 2.0)]
    pub noise: f64,
    /// Point spread σ, camera pixels.
    #[arg(long, default_value_t = 0.7)]
    pub blur: f64,
    /// Projector and camera gamma.
    #[arg(long, default_value_t = 2.2)]
    pub gamma: f64,
    /// Ambient light, a fraction of the projector's white.
    #[arg(long, default_value_t = 0.05)]
    pub ambient: f64,
    /// Light lost in the image corners, a fraction.
    #[arg(long, default_value_t = 0.2)]
    pub vignetting: f64,
    /// One-bounce inter-reflection under white, a fraction of the direct light.
    #[arg(long, default_value_t = 0.0)]
    pub interreflection: f64,
    /// The share of the camera's full scale that white plus ambient reaches at the image
    /// centre: lower it where bounced light would saturate the camera.
    #[arg(long, default_value_t = 0.8)]
    pub exposure: f64,
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// The sequence's phase period, projector pixels (even, 8–256): longer for a camera too
    /// defocused to see 16 px stripes. Give calibrate and measure the same.
    #[arg(long, default_value_t = 16)]
    pub period: u32,
    /// How the sequence shows its Gray bits: gray, or xor (each coarse bit XOR the finest, for
    /// walls that fold onto themselves). Give calibrate and measure the same.
    #[arg(long, default_value = "gray", value_parser = parse_code)]
    pub code: omniwarp::structured::Code,
}

impl BenchConditions {
    /// The rig, the projector, the camera and the bench's options, each error naming its flag.
    pub fn setup(
        &self,
    ) -> Result<(
        omniwarp::rig::Rig,
        omniwarp::rig::Channel,
        omniwarp::rig::Channel,
        omniwarp::structured::simulator::SimulatorOptions,
    )> {
        use omniwarp::rig::Rig;
        let rig = Rig::read(&self.rig).with_context(|| format!("--rig {}", self.rig.display()))?;
        let projector = match &self.channel {
            Some(id) => rig
                .channel(id)
                .map_err(|e| anyhow::anyhow!("--channel: {}", named(e)))?,
            None => &rig.channels[0],
        }
        .clone();
        let camera = match &self.camera {
            Some(path) => read_camera(path)?,
            None => omniwarp::structured::simulator::fisheye_at_eye(
                &rig,
                &projector,
                self.camera_size.0,
                self.camera_size.1,
            )
            .map_err(|e| anyhow::anyhow!("--channel: {}", named(e)))?,
        };
        let opts = omniwarp::structured::simulator::SimulatorOptions {
            noise: self.noise,
            blur: self.blur,
            projector_gamma: self.gamma,
            camera_gamma: self.gamma,
            ambient: self.ambient,
            vignetting: self.vignetting,
            interreflection: self.interreflection,
            exposure: self.exposure,
            seed: self.seed,
            period: self.period,
            code: self.code,
            ..Default::default()
        };
        opts.validate().map_err(|e| match e {
            omniwarp::Error::Invalid { name, reason } => {
                anyhow::anyhow!("--{}: {reason}", name.replace('_', "-"))
            }
            other => other.into(),
        })?;
        Ok((rig, projector, camera, opts))
    }
}

/// `--camera`: a camera as a rig channel document, errors naming the flag and the field.
pub fn read_camera(path: &Path) -> Result<omniwarp::rig::Channel> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("--camera {}", path.display()))?;
    let de = &mut serde_json::Deserializer::from_str(&text);
    let doc: omniwarp::rig::ChannelDoc = serde_path_to_error::deserialize(de).map_err(|e| {
        anyhow::anyhow!(
            "--camera: {}: {}",
            omniwarp::rig::pointer_of(&e.path().to_string()),
            e.inner()
        )
    })?;
    omniwarp::rig::Channel::from_doc(&doc, "")
        .map_err(|e| anyhow::anyhow!("--camera: {}", named(e)))
}
