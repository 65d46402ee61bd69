//! Command-line definitions and their dispatch. Every angle is in degrees, every size in
//! pixels; outputs are written atomically, so a failed run leaves no file behind.

use anyhow::{Context, Result, bail};
use clap::{Args, Parser, Subcommand, ValueEnum};
use glam::DVec3;
use omniwarp::content::pattern::Pattern;
use omniwarp::content::{Content, Format};
use omniwarp::cubemap::{CubeMap, Face};
use omniwarp::image_io::{self, Loaded, Precision};
use omniwarp::normalmap::NormalMap;
use omniwarp::projection::{self, Orientation, Params, View};
use omniwarp::raster::{Pixel, Raster};
use omniwarp::render::{self, Filter, Warp};
use omniwarp::tiles::build::Source;
use omniwarp::tiles::raster::saturation;
use std::path::{Path, PathBuf};

#[derive(Parser)]
#[command(
    name = "omniwarp",
    version,
    about = "Warps for non-planar projection walls: \
renders panoramic content (cube map, equirectangular, cylindrical) into any \
single-centre-of-projection view, and computes the float normal maps (warp maps) that drive it."
)]
pub struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Run the daemon: the rig over HTTP/JSON on 127.0.0.1:7878 (see api/openapi.yaml).
    Serve(crate::serve_cmd::ServeArgs),
    /// Write the procedural city as glTF (.gltf + .bin, or .glb).
    Scene(crate::scene_cmd::SceneExportArgs),
    /// Time 3D scenes through the GPU renderer against cube-face size, with and without CMF,
    /// beside the CPU reference (seed 000, Figure 8).
    GpuBench(crate::scene_cmd::GpuBenchArgs),
    /// Load the daemon over loopback: tile edits per second and latency with many clients, and
    /// 1080p preview latency while they edit.
    ServeBench(crate::serve_bench::ServeBenchArgs),
    /// Render content through a projection (or a normal map) into an image.
    Render(Box<RenderArgs>),
    /// Compute a projection's normal map (per pixel the unit sampling vector V) as float EXR.
    NormalMap(NormalMapArgs),
    /// Resample content into a cube map in any layout (six files, strip, ffmpeg c3x2/c6x1).
    Cubemap(CubemapArgs),
    /// Write a procedural test pattern as an equirectangular image or a cube map.
    Pattern(PatternArgs),
    /// List the projections, their parameters and what they mean.
    Projections,
    /// Time the CPU warp (steady state, plan built once) against the memory-bandwidth bound.
    Bench(crate::bench::BenchArgs),
    /// Projection tile screens: sample, rasterise, chart their accuracy.
    #[command(subcommand)]
    Tiles(crate::tiles_cmd::TilesCommand),
    /// Lens models: project points and unproject pixels in batches (JSON).
    #[command(subcommand)]
    Lens(crate::lens_cmd::LensCommand),
    /// A rig channel's warp map (EXR): which content direction each projector pixel shows.
    Warp(crate::rig_cmd::WarpArgs),
    /// Edge-blend masks for every channel of a rig (16-bit PNG, gamma-encoded).
    Blend(crate::rig_cmd::BlendArgs),
    /// A channel's warp for media servers: ST-map EXR, PFM (a3) or ffmpeg remap maps.
    Export(crate::rig_cmd::ExportArgs),
    /// Calibrate a projector from measured pixel ↔ wall-point correspondences; writes a rig
    /// channel.
    Calibrate(crate::calibrate_cmd::CalibrateArgs),
    /// Time calibration against point count (50, 500, 5000) and lens model.
    CalibrateBench,
    /// Time warp generation (3840×2160 on every surface type) and the dome example's blends.
    WarpBench {
        /// The rig whose blends are timed.
        #[arg(long, default_value = "calibration/rigs/dome-180-tilt15-5proj.json")]
        rig: PathBuf,
    },
}

#[derive(Args, Clone)]
pub struct ProjectionArgs {
    /// Projection name (see `omniwarp projections`): flat, cylindrical, fisheye, equirect, ...
    #[arg(long)]
    projection: Option<String>,
    /// Horizontal field of view, degrees.
    #[arg(long, allow_hyphen_values = true)]
    hfov: Option<f64>,
    /// Vertical field of view, degrees.
    #[arg(long, allow_hyphen_values = true)]
    vfov: Option<f64>,
    /// Image-circle field of view of a fisheye, degrees.
    #[arg(long, allow_hyphen_values = true)]
    fov: Option<f64>,
    /// Forward tilt of a domemaster's zenith, degrees.
    #[arg(long, allow_hyphen_values = true)]
    tilt: Option<f64>,
    /// Off-axis frustum of `flat`: angle of the left edge from the axis, degrees (negative).
    #[arg(long, allow_hyphen_values = true)]
    left: Option<f64>,
    /// Off-axis frustum of `flat`: angle of the right edge, degrees.
    #[arg(long, allow_hyphen_values = true)]
    right: Option<f64>,
    /// Off-axis frustum of `flat`: angle of the bottom edge, degrees (negative).
    #[arg(long, allow_hyphen_values = true)]
    bottom: Option<f64>,
    /// Off-axis frustum of `flat`: angle of the top edge, degrees.
    #[arg(long, allow_hyphen_values = true)]
    top: Option<f64>,
    /// Viewing direction x,y,z in the world (+y up, −z forward); any length.
    #[arg(long, value_parser = parse_vec3, default_value = "0,0,-1", allow_hyphen_values = true)]
    look_to: DVec3,
    /// Up direction x,y,z; must not be parallel to --look-to.
    #[arg(long, value_parser = parse_vec3, default_value = "0,1,0", allow_hyphen_values = true)]
    look_up: DVec3,
    /// Off-axis vector O subtracted from the view direction (unitless, length below 1).
    #[arg(long, value_parser = parse_vec3, default_value = "0,0,0", allow_hyphen_values = true)]
    offaxis: DVec3,
    /// Zoom factor applied to the screen coordinates before projecting (unitless, > 0).
    #[arg(long, default_value_t = 1.0, allow_hyphen_values = true)]
    zoom: f64,
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
struct ContentArgs {
    /// Content image: PNG or JPEG (8-bit) or OpenEXR (float).
    #[arg(long)]
    content: Option<PathBuf>,
    /// How the content image is laid out.
    #[arg(long, value_enum)]
    content_format: Option<ContentFormat>,
    /// Horizontal field of view of a panorama, degrees (default 360).
    #[arg(long)]
    content_hfov: Option<f64>,
    /// Vertical field of view of a panorama, degrees (default: 180 for a full equirect; square
    /// pixels otherwise).
    #[arg(long)]
    content_vfov: Option<f64>,
    /// Orientation of the content in the world: yaw,pitch,roll in degrees (yaw turns left,
    /// pitch up, roll clockwise).
    #[arg(long, value_parser = parse_vec3, default_value = "0,0,0", allow_hyphen_values = true)]
    content_rotate: DVec3,
}

#[derive(Clone, Copy, ValueEnum)]
enum ContentFormat {
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
    /// Six files: --content names them with `{face}`, replaced by px nx py ny pz nz.
    CubemapFaces,
}

impl ContentFormat {
    fn format(self) -> Format {
        match self {
            ContentFormat::Cubemap | ContentFormat::CubemapFaces => Format::Cubemap,
            ContentFormat::CubemapC3x2 => Format::CubemapC3x2,
            ContentFormat::CubemapC6x1 => Format::CubemapC6x1,
            ContentFormat::Equirect => Format::Equirect,
            ContentFormat::Cylindrical => Format::Cylindrical,
        }
    }
}

#[derive(Clone, Copy, ValueEnum)]
enum FilterArg {
    Nearest,
    Bilinear,
    Bicubic,
}

#[derive(Args)]
struct RenderArgs {
    #[command(flatten)]
    content: ContentArgs,
    #[command(flatten)]
    projection: ProjectionArgs,
    /// Take the sampling vectors from this normal map (EXR) instead of a projection.
    #[arg(long, conflicts_with = "projection")]
    normal_map: Option<PathBuf>,
    /// Take the sampling vectors from this tile screen (JSON) instead; its f values scale the
    /// saturation (seed 000, Figure 5).
    #[arg(long, conflicts_with_all = ["projection", "normal_map"])]
    tiles: Option<PathBuf>,
    /// Render a rig channel's projector image instead (with --channel): its own warp, its
    /// blend mask applied in signal space.
    #[arg(long, requires = "channel", conflicts_with_all = ["projection", "normal_map", "tiles"])]
    rig: Option<PathBuf>,
    /// The rig channel to render.
    #[arg(long, requires = "rig")]
    channel: Option<String>,
    /// Projector gamma for the blend mask (with --rig).
    #[arg(long, default_value_t = 2.2)]
    gamma: f64,
    /// Texture filter.
    #[arg(long, value_enum, default_value = "bilinear")]
    filter: FilterArg,
    /// K×K samples per output pixel, averaged (1 to 16).
    #[arg(long, default_value_t = 1)]
    supersample: u32,
    /// Output size WxH in pixels (default: the normal map's).
    #[arg(long, value_parser = parse_size)]
    size: Option<(u32, u32)>,
    /// Output image: .png (8-bit RGBA) or .exr (32-bit float RGBA). Alpha is 0 where nothing
    /// is shown.
    #[arg(long)]
    out: PathBuf,
    #[command(flatten)]
    scene: crate::scene_cmd::SceneArgs,
}

#[derive(Args)]
struct NormalMapArgs {
    #[command(flatten)]
    projection: ProjectionArgs,
    /// Output size WxH in pixels.
    #[arg(long, value_parser = parse_size)]
    size: (u32, u32),
    /// Store half floats (a third of the size, up to ~0.03° of error) instead of 32-bit.
    #[arg(long)]
    half: bool,
    /// Output file (.exr).
    #[arg(long)]
    out: PathBuf,
}

#[derive(Clone, Copy, ValueEnum)]
enum CubeLayoutArg {
    /// Six faces side by side in omniwarp's order.
    Strip,
    /// ffmpeg's c3x2.
    C3x2,
    /// ffmpeg's c6x1.
    C6x1,
    /// Six files: OUT must contain `{face}`, replaced by px nx py ny pz nz.
    Faces,
}

#[derive(Args)]
struct CubemapArgs {
    #[command(flatten)]
    content: ContentArgs,
    /// Face size in pixels.
    #[arg(long)]
    face_size: u32,
    /// Output layout.
    #[arg(long, value_enum, default_value = "strip")]
    layout: CubeLayoutArg,
    /// Texture filter.
    #[arg(long, value_enum, default_value = "bilinear")]
    filter: FilterArg,
    /// K×K samples per texel.
    #[arg(long, default_value_t = 1)]
    supersample: u32,
    /// Output file (.png or .exr); for `--layout faces` a name with `{face}` in it.
    #[arg(long)]
    out: PathBuf,
}

#[derive(Clone, Copy, ValueEnum)]
enum PatternArg {
    /// Smooth, band-limited, chiral: for comparing resamplers.
    Smooth,
    /// Sharp 10° checkerboard with red meridian lines every 30°.
    Checker,
}

#[derive(Args)]
struct PatternArgs {
    #[arg(long, value_enum, default_value = "smooth")]
    pattern: PatternArg,
    /// Equirect size WxH, or a cube map's face size as N (with --layout).
    #[arg(long, value_parser = parse_size)]
    size: (u32, u32),
    /// Write a cube map in this layout instead of an equirectangular image.
    #[arg(long, value_enum)]
    layout: Option<CubeLayoutArg>,
    /// Samples per pixel along each axis (anti-aliasing).
    #[arg(long, default_value_t = 4)]
    supersample: u32,
    /// Lay the equirect image out as ffmpeg's v360 reads it: the centres of the edge columns
    /// and rows at ±180° and ±90° (DESIGN.md puts the image's outer edges there).
    #[arg(long, conflicts_with = "layout")]
    ffmpeg_equirect: bool,
    /// Output file (.png or .exr).
    #[arg(long)]
    out: PathBuf,
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

fn filter(f: FilterArg) -> Filter {
    match f {
        FilterArg::Nearest => Filter::Nearest,
        FilterArg::Bilinear => Filter::Bilinear,
        FilterArg::Bicubic => Filter::Bicubic,
    }
}

pub fn run(cli: Cli) -> Result<()> {
    match cli.command {
        Command::Serve(a) => crate::serve_cmd::run(a),
        Command::ServeBench(a) => crate::serve_bench::run(a),
        Command::GpuBench(a) => crate::scene_cmd::bench(a),
        Command::Scene(a) => crate::scene_cmd::export(a),
        Command::Render(a) => render_cmd(*a),
        Command::NormalMap(a) => {
            let (w, h) = a.size;
            let view = a.projection.view(w, h)?;
            let map = NormalMap::from_view(&view, w, h)?;
            let precision = if a.half {
                Precision::Half
            } else {
                Precision::Float
            };
            check_ext(&a.out, &["exr"])?;
            map.write(&a.out, precision)?;
            Ok(())
        }
        Command::Cubemap(a) => cubemap_cmd(a),
        Command::Pattern(a) => pattern_cmd(a),
        Command::Projections => {
            for e in projection::REGISTRY {
                let aliases = if e.aliases.is_empty() {
                    String::new()
                } else {
                    format!(" (also {})", e.aliases.join(", "))
                };
                println!("{}{aliases}: {}", e.name, e.description);
                for (p, what) in e.params {
                    println!("    --{p:<7} {what} (degrees)");
                }
            }
            Ok(())
        }
        Command::Bench(a) => crate::bench::run(a),
        Command::Tiles(t) => crate::tiles_cmd::run(t),
        Command::Lens(l) => crate::lens_cmd::run(l),
        Command::Warp(a) => crate::rig_cmd::warp(a),
        Command::Blend(a) => crate::rig_cmd::blend(a),
        Command::Export(a) => crate::rig_cmd::export(a),
        Command::WarpBench { rig } => crate::rig_cmd::bench(&rig),
        Command::Calibrate(a) => crate::calibrate_cmd::run(a),
        Command::CalibrateBench => crate::calibrate_cmd::bench(),
    }
}

fn check_ext(path: &Path, allowed: &[&str]) -> Result<()> {
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

/// Content in the pixel type the output needs: float when either side is float.
enum AnyContent {
    U8(Content<[u8; 4]>),
    F32(Content<[f32; 4]>),
}

fn load_content(a: &ContentArgs, want_float: bool) -> Result<AnyContent> {
    let path = a
        .content
        .as_ref()
        .context("--content: needed (render can take --scene instead)")?;
    let format = a
        .content_format
        .context("--content-format: needed with --content")?;
    let loaded = match format {
        ContentFormat::CubemapFaces => image_io::read_cube_faces(&path.to_string_lossy()),
        _ => image_io::read_image(path),
    }
    .context("--content")?;
    let orient =
        Orientation::yaw_pitch_roll(a.content_rotate.x, a.content_rotate.y, a.content_rotate.z)
            .map_err(flag_error)?;
    let fmt = format.format();
    let (hfov, vfov) = (a.content_hfov, a.content_vfov);
    let content = match loaded {
        Loaded::U8(r) if !want_float => AnyContent::U8(
            Content::from_image(&r, fmt, hfov, vfov)
                .map_err(flag_error)?
                .with_orientation(orient),
        ),
        Loaded::U8(r) => AnyContent::F32(
            Content::from_image(&r.map(to_float), fmt, hfov, vfov)
                .map_err(flag_error)?
                .with_orientation(orient),
        ),
        Loaded::F32(r) => AnyContent::F32(
            Content::from_image(&r, fmt, hfov, vfov)
                .map_err(flag_error)?
                .with_orientation(orient),
        ),
    };
    Ok(content)
}

fn to_float(p: [u8; 4]) -> [f32; 4] {
    p.map(|c| f32::from(c) / 255.0)
}

fn to_u8(p: [f32; 4]) -> [u8; 4] {
    <[u8; 4]>::from_f32(p.map(|c| c * 255.0))
}

fn write_output(path: &Path, img: AnyRaster, attrs: &[(String, String)]) -> Result<()> {
    if image_io_is_exr(path) {
        let f = match img {
            AnyRaster::U8(r) => r.map(to_float),
            AnyRaster::F32(r) => r,
        };
        image_io::write_exr_rgba(path, &f, attrs, Precision::Float)?;
    } else {
        let b = match img {
            AnyRaster::U8(r) => r,
            AnyRaster::F32(r) => r.map(to_u8),
        };
        image_io::write_png(path, &b)?;
    }
    Ok(())
}

fn image_io_is_exr(path: &Path) -> bool {
    path.extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("exr"))
}

enum AnyRaster {
    U8(Raster<[u8; 4]>),
    F32(Raster<[f32; 4]>),
}

fn render_cmd(a: RenderArgs) -> Result<()> {
    check_ext(&a.out, &["png", "exr"])?;
    if let Some(spec) = &a.scene.scene {
        let (w, h) = a.size.context("--size: needed with --scene")?;
        let view = a.projection.view(w, h)?;
        return crate::scene_cmd::render(spec, &a.scene, &view, (w, h), &a.out);
    }
    let mut mask = None;
    let map = match (&a.rig, &a.channel) {
        (Some(rig), Some(id)) => {
            let (m, k) = crate::rig_cmd::render_inputs(rig, id, a.gamma)?;
            mask = Some(k);
            Some(m)
        }
        _ => a
            .normal_map
            .as_deref()
            .map(NormalMap::read)
            .transpose()
            .context("--normal-map")?,
    };
    let (w, h) = match (a.size, &map) {
        (Some(s), _) => s,
        (None, Some(m)) => (m.width() as u32, m.height() as u32),
        (None, None) => bail!("--size: needed when rendering through a projection or tiles"),
    };
    let features = match &a.tiles {
        Some(path) => Some(crate::tiles_cmd::read_tiles(path)?.feature_map(w as usize, h as usize)),
        None => None,
    };
    let tile_map = features.as_ref().map(|f| f.normal_map());
    let view;
    let warp = match (&map, &tile_map) {
        (Some(m), _) | (None, Some(m)) => Warp::Map(m),
        (None, None) => {
            view = a.projection.view(w, h)?;
            Warp::View(&view)
        }
    };
    let content = load_content(&a.content, image_io_is_exr(&a.out))?;
    let (ss, f) = (a.supersample, filter(a.filter));
    let effect = features.as_ref().map(|f| f.f());
    let scale = |img: &mut [f32; 4], m: f32| {
        for c in &mut img[..3] {
            *c *= m;
        }
    };
    let img = match &content {
        AnyContent::U8(c) => {
            let mut r = render::render(warp, c, w, h, ss, f).map_err(flag_error)?;
            if let Some(e) = &effect {
                saturation(&mut r, e);
            }
            if let Some(m) = &mask {
                for (p, &k) in r.data.iter_mut().zip(m) {
                    let mut v = p.to_f32();
                    scale(&mut v, k);
                    *p = <[u8; 4]>::from_f32(v);
                }
            }
            AnyRaster::U8(r)
        }
        AnyContent::F32(c) => {
            let mut r = render::render(warp, c, w, h, ss, f).map_err(flag_error)?;
            if let Some(e) = &effect {
                saturation(&mut r, e);
            }
            if let Some(m) = &mask {
                for (p, &k) in r.data.iter_mut().zip(m) {
                    scale(p, k);
                }
            }
            AnyRaster::F32(r)
        }
    };
    write_output(&a.out, img, &[])
}

fn cube_faces<T: Pixel>(c: &Content<T>, n: u32, ss: u32, f: Filter) -> Result<CubeMap<T>> {
    let faces: Vec<Raster<T>> = Face::ALL
        .iter()
        .map(|&face| render::render(Warp::CubeFace(face), c, n, n, ss, f))
        .collect::<Result<_, _>>()
        .map_err(flag_error)?;
    Ok(CubeMap::from_faces(faces.try_into().expect("six faces"))?)
}

fn write_cube<T: Pixel>(
    cube: &CubeMap<T>,
    layout: CubeLayoutArg,
    out: &Path,
    wrap: fn(Raster<T>) -> AnyRaster,
) -> Result<()> {
    use omniwarp::cubemap::Layout;
    let layout = match layout {
        CubeLayoutArg::Strip => Layout::Strip,
        CubeLayoutArg::C3x2 => Layout::FfmpegC3x2,
        CubeLayoutArg::C6x1 => Layout::FfmpegC6x1,
        CubeLayoutArg::Faces => {
            let pattern = out.to_string_lossy();
            if !pattern.contains("{face}") {
                bail!("--out: with --layout faces the name must contain {{face}}");
            }
            for face in Face::ALL {
                let path = PathBuf::from(pattern.replace("{face}", face.label()));
                write_output(&path, wrap(cube.face(face).clone()), &[])?;
            }
            return Ok(());
        }
    };
    write_output(out, wrap(layout.join(cube)), &[])
}

fn cubemap_cmd(a: CubemapArgs) -> Result<()> {
    check_ext(&a.out, &["png", "exr"])?;
    let (ss, f) = (a.supersample, filter(a.filter));
    match load_content(&a.content, image_io_is_exr(&a.out))? {
        AnyContent::U8(c) => write_cube(
            &cube_faces(&c, a.face_size, ss, f)?,
            a.layout,
            &a.out,
            AnyRaster::U8,
        ),
        AnyContent::F32(c) => write_cube(
            &cube_faces(&c, a.face_size, ss, f)?,
            a.layout,
            &a.out,
            AnyRaster::F32,
        ),
    }
}

fn pattern_cmd(a: PatternArgs) -> Result<()> {
    check_ext(&a.out, &["png", "exr"])?;
    let pattern = match a.pattern {
        PatternArg::Smooth => Pattern::Smooth,
        PatternArg::Checker => Pattern::Checker,
    };
    if !(1..=16).contains(&a.supersample) {
        bail!(
            "--supersample: must be between 1 and 16, got {}",
            a.supersample
        );
    }
    let ss = a.supersample as usize;
    match a.layout {
        None => {
            let (w, h) = a.size;
            let img = pattern.equirect(w as usize, h as usize, ss, a.ffmpeg_equirect);
            write_output(&a.out, AnyRaster::F32(img), &[])
        }
        Some(layout) => {
            if a.size.0 != a.size.1 {
                bail!("--size: a cube map takes one face size N");
            }
            let cube = CubeMap::from_fn(a.size.0 as usize, ss, |d| pattern.eval(d));
            write_cube(&cube, layout, &a.out, AnyRaster::F32)
        }
    }
}
