//! `omniwarp render`: content through a projection, a normal map, a tile screen or a rig
//! channel's warp (with its blend), or a 3D scene through a projection on the GPU (wgpu;
//! lavapipe where there is no GPU) or the CPU.

use crate::cli::args::{
    ContentArgs, ContentLookup, FilterArg, ProjectionArgs, check_ext, filter, flag_error,
    parse_size, parse_vec3,
};
use crate::cli::io::{
    AnyContent, AnyRaster, channel, channel_blend, is_exr, load_content, read_rig, read_tiles,
    render_inputs, write_output,
};
use anyhow::{Context, Result, bail};
use clap::{Args, ValueEnum};
use glam::DVec3;
use omniwarp::gpu::Renderer;
use omniwarp::gpu::choose::{Method, choose};
use omniwarp::gpu::frame::{FrameOptions, SceneRenderer};
use omniwarp::gpu::warp::Source;
use omniwarp::normalmap::NormalMap;
use omniwarp::projection::View;
use omniwarp::raster::Raster;
use omniwarp::render::blur::Blur;
use omniwarp::render::{self, Warp};
use omniwarp::rig::signal_gains;
use omniwarp::scene::ppp::{Pieces, Tolerance};
use omniwarp::scene::{Projected, Scene};
use omniwarp::tiles::raster::saturation;
use std::path::{Path, PathBuf};

mod movie;

#[derive(Args)]
pub struct RenderArgs {
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
    /// Render a rig instead: with --channel, that projector's image (its own warp, its blend
    /// mask applied in signal space); without, what the rig's eye sees of the wall through
    /// --projection (nothing where the view misses the wall).
    #[arg(long, conflicts_with_all = ["normal_map", "tiles"])]
    rig: Option<PathBuf>,
    /// The rig channel to render.
    #[arg(long, requires = "rig", conflicts_with = "projection")]
    channel: Option<String>,
    /// Project the content panorama from this point x,y,z (metres) onto the rig's wall or the
    /// scene (seed 001), instead of showing it around the eye: the eye ray that meets the
    /// surface at P shows the content's direction P − C. At the eye this is the plain
    /// panorama; the point must be inside the wall.
    #[arg(long, value_parser = parse_vec3, allow_hyphen_values = true)]
    project_from: Option<DVec3>,
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
    /// is shown. With a movie or sequence as content: a movie (.mp4, .mov, .mkv, …) or a
    /// sequence pattern (out-%05d.png or .exr); with --rig, `{channel}` in the name writes one
    /// per channel (all of them, or --channel). `null:` warps and discards: the throughput.
    #[arg(long, required_unless_present = "out_dir")]
    out: Option<PathBuf>,
    /// With --rig and a movie or sequence as content: one movie per channel, DIR/<id>.mp4
    /// (as --out DIR/{channel}.mp4).
    #[arg(long, requires = "rig", conflicts_with = "out")]
    out_dir: Option<PathBuf>,
    #[command(flatten)]
    movie: movie::MovieArgs,
    #[command(flatten)]
    scene: SceneArgs,
}

pub fn run(a: RenderArgs) -> Result<()> {
    let media_in = a.content.content.as_deref().is_some_and(movie::is_media);
    let media_out = a.out.as_deref().is_some_and(movie::is_media) || a.out_dir.is_some();
    if media_in || media_out {
        return render_movie(&a);
    }
    let out = a.out.clone().context("--out: needed")?;
    check_ext(&out, &["png", "exr"])?;
    if let Some(spec) = &a.scene.scene {
        let (w, h) = a.size.context("--size: needed with --scene")?;
        let view = a.projection.view(w, h)?;
        let panorama = match &a.content.content {
            Some(_) => Some(scene_panorama(&a, a.project_from.unwrap_or(a.scene.eye))?),
            None if a.project_from.is_some() => {
                bail!("--project-from: needs the panorama to project (--content)")
            }
            None => None,
        };
        return render_scene(spec, &a.scene, panorama, &view, (w, h), &out);
    }
    if let (Some(renderer), Some(rig), Some(id)) = (a.scene.renderer, &a.rig, &a.channel) {
        return render_channel_on_wall(&a, renderer, rig, id, &out);
    }
    if let Some(RendererArg::Gpu) = a.scene.renderer {
        bail!(
            "--renderer: gpu renders 3D scenes (--scene) and rig channels (--rig, --channel) \
             only; other content renders run on the CPU reference path (leave --renderer out)"
        );
    }
    let mut mask = None;
    let map = match (&a.rig, &a.channel) {
        (Some(rig), Some(id)) => {
            let (m, k) = render_inputs(rig, id, a.gamma, a.project_from)?;
            mask = Some(k);
            Some(m)
        }
        (Some(path), None) => Some(eye_view(&a, path)?),
        (None, _) if a.project_from.is_some() => {
            bail!("--project-from: needs a surface to project onto: --rig (its wall) or --scene")
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
        Some(path) => Some(read_tiles(path)?.feature_map(w as usize, h as usize)),
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
    let content = load_content(&a.content, is_exr(&out))?;
    let (ss, f) = (a.supersample, filter(a.filter));
    let effect = features.as_ref().map(|f| f.f());
    let img = match &content {
        AnyContent::U8(c) => {
            let mut r = render::render(warp, c, w, h, ss, f).map_err(flag_error)?;
            if let Some(e) = &effect {
                saturation(&mut r, e);
            }
            if let Some(m) = &mask {
                m.apply(&mut r)?;
            }
            AnyRaster::U8(r)
        }
        AnyContent::F32(c) => {
            let mut r = render::render(warp, c, w, h, ss, f).map_err(flag_error)?;
            if let Some(e) = &effect {
                saturation(&mut r, e);
            }
            if let Some(m) = &mask {
                m.apply(&mut r)?;
            }
            AnyRaster::F32(r)
        }
    };
    write_output(&out, img, &[])
}

/// A movie or an image sequence through the warp: one output, or one per rig channel.
fn render_movie(a: &RenderArgs) -> Result<()> {
    if a.scene.scene.is_some() || a.scene.renderer.is_some() {
        bail!("--scene: movies and sequences are warped as content on the CPU path");
    }
    if a.tiles.is_some() {
        bail!("--tiles: a movie goes through a projection, a normal map or a rig");
    }
    let template = match (&a.out, &a.out_dir) {
        (_, Some(dir)) => dir.join("{channel}.mp4"),
        (Some(out), None) => out.clone(),
        (None, None) => bail!("--out: needed"),
    };
    let per_channel = template.to_string_lossy().contains("{channel}");
    let mut outputs = Vec::new();
    match &a.rig {
        Some(rig) if per_channel || a.channel.is_some() => {
            let ids = match &a.channel {
                Some(id) => vec![id.clone()],
                None => read_rig(rig)?
                    .channels
                    .iter()
                    .map(|c| c.id.clone())
                    .collect(),
            };
            for id in ids {
                let (map, blend) = render_inputs(rig, &id, a.gamma, a.project_from)?;
                if blend.lift.is_some() {
                    bail!(
                        "--rig: black-level compensation (the channels' contrast) is applied to \
                         stills so far, not to movies; leave contrast out of the rig for a movie"
                    );
                }
                let gains = signal_gains(&blend.weights, blend.gamma).map_err(flag_error)?;
                outputs.push(movie::Output {
                    path: PathBuf::from(template.to_string_lossy().replace("{channel}", &id)),
                    source: movie::Source::Map(map),
                    gains: Some(gains),
                });
            }
        }
        _ if per_channel => bail!("--out: {{channel}} names one output per rig channel (--rig)"),
        Some(rig) => outputs.push(movie::Output {
            path: template,
            source: movie::Source::Map(eye_view(a, rig)?),
            gains: None,
        }),
        None if a.project_from.is_some() => {
            bail!("--project-from: needs a surface to project onto: --rig (its wall)")
        }
        None => {
            let source = match &a.normal_map {
                Some(p) => movie::Source::Map(NormalMap::read(p).context("--normal-map")?),
                None => {
                    let (w, h) = a
                        .size
                        .context("--size: needed when rendering through a projection")?;
                    movie::Source::View(a.projection.view(w, h)?, (w, h))
                }
            };
            outputs.push(movie::Output {
                path: template,
                source,
                gains: None,
            });
        }
    }
    movie::run(movie::Job {
        content: &a.content,
        outputs,
        movie: &a.movie,
        supersample: a.supersample,
        filter: filter(a.filter),
    })
}

/// The rig's wall seen from its eye (or `--project-from`) through `--projection` at `--size`:
/// `render --rig` without `--channel`.
fn eye_view(a: &RenderArgs, path: &Path) -> Result<NormalMap> {
    let (w, h) = a
        .size
        .context("--size: needed for the eye's view of a rig (--rig without --channel)")?;
    if a.projection.projection.is_none() {
        bail!("--projection: needed for the eye's view of a rig (or give --channel)");
    }
    let rig = read_rig(path)?;
    let centre = rig
        .check_centre(a.project_from.unwrap_or(rig.eye), "project-from")
        .map_err(flag_error)?;
    let view = a.projection.view(w, h)?;
    rig.eye_view(&view, w, h, centre).map_err(flag_error)
}

/// The content panorama as the scene renderers take it (8-bit, looked up exactly), projected
/// from `centre`.
fn scene_panorama(a: &RenderArgs, centre: DVec3) -> Result<Projected> {
    if a.content.content_lookup != ContentLookup::Exact {
        bail!("--content-lookup: the scene renderers look panoramas up exactly");
    }
    match load_content(&a.content, false)? {
        AnyContent::U8(content) => Ok(Projected { content, centre }),
        AnyContent::F32(_) => {
            bail!("--content: a panorama projected onto a scene is 8-bit (PNG or JPEG)")
        }
    }
}

/// A rig channel through the scene renderers (`--renderer`): the wall as triangles with the
/// content panorama projected onto it (from `--project-from`, or the eye) drawn into the eye's
/// cube map, then sampled through the channel's warp — seed 000's pipeline, on the GPU or its
/// CPU twin — with the blend mask applied as in the exact path.
fn render_channel_on_wall(
    a: &RenderArgs,
    renderer: RendererArg,
    path: &Path,
    id: &str,
    out: &Path,
) -> Result<()> {
    if a.supersample != 1 || !matches!(a.filter, FilterArg::Bilinear) {
        bail!("--renderer: the scene renderers filter bilinearly, one sample per pixel");
    }
    let rig = read_rig(path)?;
    let centre = rig
        .check_centre(a.project_from.unwrap_or(rig.eye), "project-from")
        .map_err(flag_error)?;
    let panorama = scene_panorama(a, centre)?;
    let ch = channel(&rig, id)?;
    let warp = rig.warp(ch);
    let scene = Scene::from_triangles(&rig.doc.screen.triangles());
    let mut r = SceneRenderer::new(scene, renderer.renderer(), a.scene.adapter.as_deref())
        .map_err(flag_error)?;
    r.set_panorama(Some(panorama)).map_err(flag_error)?;
    let opts = FrameOptions {
        size: (ch.width, ch.height),
        face: a.scene.face,
        cmf: !a.scene.all_faces,
        blur: None,
        eye: rig.eye,
    };
    let (mut img, report) = r.frame_map(&warp.map, &opts).map_err(flag_error)?;
    eprintln!("{}: cube faces at {}²", r.describe(), report.face);
    channel_blend(&rig, ch, &warp.points, a.gamma)?.apply(&mut img)?;
    write_output(out, AnyRaster::U8(img), &[])
}

#[derive(Clone, Copy, ValueEnum)]
pub enum RendererArg {
    Gpu,
    Cpu,
    Auto,
}

impl RendererArg {
    pub fn renderer(self) -> Renderer {
        match self {
            RendererArg::Gpu => Renderer::Gpu,
            RendererArg::Cpu => Renderer::Cpu,
            RendererArg::Auto => Renderer::Auto,
        }
    }
}

#[derive(Args)]
pub struct SceneArgs {
    /// Render a 3D scene instead of content: a .gltf/.glb or .obj file, the procedural
    /// city:small, city:medium or city:large (~10k, 100k, 1M triangles), or wall:RIG.json (a
    /// rig's screen as triangles, cut every degree). With --content, the content panorama is projected onto the scene from --project-from
    /// (default: the eye) instead of the scene's own colours.
    #[arg(long, conflicts_with_all = ["normal_map", "tiles", "rig"])]
    pub scene: Option<String>,
    /// Eye position x,y,z in the scene, metres.
    #[arg(long, value_parser = parse_vec3, default_value = "0,1.7,0", allow_hyphen_values = true)]
    pub eye: DVec3,
    /// Cube face size in pixels (default: chosen from the output's pixel pitch).
    #[arg(long)]
    pub face: Option<u32>,
    /// Draw all six faces even where the warp samples fewer (turns off seed 000's CMF).
    #[arg(long)]
    pub all_faces: bool,
    /// gpu, cpu, or auto (the GPU when an adapter exists; the default). Scenes only: content
    /// renders run on the CPU reference path.
    #[arg(long, value_enum)]
    pub renderer: Option<RendererArg>,
    /// Adapter to use: part of its name or backend (e.g. vulkan, gl, llvmpipe).
    #[arg(long)]
    pub adapter: Option<String>,
    /// Radial blur towards the image centre: the fraction of the way it reaches (0 to 1).
    #[arg(long)]
    pub blur: Option<f32>,
    /// How a scene reaches the projection: cube (seed 000: a cube map, then the warp), ppp
    /// (seed 003: straight into the output through piecewise perspective pieces), auto (the
    /// cheaper of the two that meets --tolerance) or exact (one ray per pixel on the CPU: the
    /// reference the others are measured against; slow).
    #[arg(long, value_enum, default_value = "cube")]
    pub method: MethodArg,
    /// ppp: the cut, cells across × down (e.g. 160x1); default: the fewest pieces that meet
    /// --tolerance.
    #[arg(long, value_parser = parse_size, conflicts_with = "tolerance")]
    pub pieces: Option<(u32, u32)>,
    /// ppp and auto: the largest deviation from the true projection allowed when choosing the
    /// cut (and, for auto, the method): an angle (0.05deg, 0.001rad) or output pixels (median
    /// pixel pitches; 0.25px, the default).
    #[arg(long)]
    pub tolerance: Option<String>,
    /// ppp: antialias with 4× multisampling (the CPU twin casts at the same 4 positions).
    #[arg(long)]
    pub msaa: bool,
}

#[derive(Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum MethodArg {
    Cube,
    Ppp,
    Exact,
    /// The cheaper of cube and ppp at the settings that meet --tolerance, timed on the scene.
    Auto,
}

fn render_scene(
    spec: &str,
    a: &SceneArgs,
    panorama: Option<Projected>,
    view: &View,
    size: (u32, u32),
    out: &Path,
) -> Result<()> {
    let blur = match a.blur {
        Some(s) if (0.0..=1.0).contains(&s) => Some(Blur {
            strength: s,
            samples: 16,
        }),
        Some(s) => anyhow::bail!("--blur: must be between 0 and 1, got {s}"),
        None => None,
    };
    let scene = Scene::load(spec).map_err(|e| anyhow::anyhow!("--scene: {}", e.reason()))?;
    let mut r = SceneRenderer::new(
        scene,
        a.renderer.unwrap_or(RendererArg::Auto).renderer(),
        a.adapter.as_deref(),
    )
    .map_err(flag_error)?;
    r.set_panorama(panorama).map_err(flag_error)?;
    let opts = FrameOptions {
        size,
        face: a.face,
        cmf: !a.all_faces,
        blur,
        eye: a.eye,
    };
    if a.method != MethodArg::Ppp && a.method != MethodArg::Auto && a.tolerance.is_some() {
        bail!("--tolerance: chooses the cut of --method ppp or the method of --method auto");
    }
    if a.method != MethodArg::Ppp && a.pieces.is_some() {
        bail!("--pieces: the cut of --method ppp");
    }
    if a.msaa && !matches!(a.method, MethodArg::Ppp | MethodArg::Auto) {
        bail!("--msaa: antialiases --method ppp (the cube method filters its cube map instead)");
    }
    let img = match a.method {
        MethodArg::Ppp => ppp_frame(&mut r, &ppp_pieces(a, view, size)?, &opts, a.msaa)?,
        MethodArg::Exact => r.frame_exact(view, &opts).map_err(flag_error)?,
        MethodArg::Cube => cube_frame(&mut r, view, &opts)?,
        MethodArg::Auto => {
            if a.face.is_some() {
                bail!("--face: --method auto chooses the face size itself");
            }
            let t =
                Tolerance::parse(a.tolerance.as_deref().unwrap_or("0.25px")).map_err(flag_error)?;
            let max_face = if matches!(a.renderer, Some(RendererArg::Cpu)) {
                2048
            } else {
                4096
            };
            let candidates =
                choose(&mut r, Source::View(view), &opts, t, max_face).map_err(flag_error)?;
            for c in &candidates {
                eprintln!(
                    "auto: {} — error at most {:.4}°, {:.0} ms a frame",
                    c.describe(),
                    c.angle.to_degrees(),
                    c.ms
                );
            }
            eprintln!("auto: chose {}", candidates[0].describe());
            match &candidates[0].method {
                Method::Cube { face } => {
                    let o = FrameOptions {
                        face: Some(*face),
                        ..opts
                    };
                    cube_frame(&mut r, view, &o)?
                }
                Method::Ppp(pieces) => ppp_frame(&mut r, pieces, &opts, a.msaa)?,
            }
        }
    };
    write_picture(&img, out)
}

/// The cut for `--method ppp`: `--pieces` as given, else the fewest pieces meeting
/// `--tolerance`; either way the deviation it reaches is measured and said.
fn ppp_pieces(a: &SceneArgs, view: &View, (w, h): (u32, u32)) -> Result<Pieces> {
    let (pieces, deviation) = match a.pieces {
        Some((c, r)) => {
            let p = Pieces::new(view, w, h, c, r).map_err(flag_error)?;
            let d = p.measure(view);
            (p, d)
        }
        None => {
            let t =
                Tolerance::parse(a.tolerance.as_deref().unwrap_or("0.25px")).map_err(flag_error)?;
            Pieces::for_tolerance(view, w, h, t).map_err(flag_error)?
        }
    };
    eprintln!(
        "ppp: {}×{} cells, deviation from the true projection at most {:.4}° ({:.3} px)",
        pieces.cols,
        pieces.rows,
        deviation.angle.to_degrees(),
        deviation.pixels
    );
    Ok(pieces)
}

fn ppp_frame(
    r: &mut SceneRenderer,
    pieces: &Pieces,
    opts: &FrameOptions,
    msaa: bool,
) -> Result<Raster<[u8; 4]>> {
    let (img, report) = if msaa {
        r.frame_ppp_antialiased(pieces, opts)
    } else {
        r.frame_ppp(pieces, opts)
    }
    .map_err(flag_error)?;
    let replication = report
        .replication
        .map_or(String::new(), |f| format!(", replication {f:.2}"));
    eprintln!(
        "{}: piecewise perspective, {} pieces{replication}",
        r.describe(),
        report.pieces
    );
    Ok(img)
}

fn cube_frame(r: &mut SceneRenderer, view: &View, opts: &FrameOptions) -> Result<Raster<[u8; 4]>> {
    let (img, report) = r.frame(view, opts).map_err(flag_error)?;
    let drawn: Vec<&str> = omniwarp::cubemap::Face::ALL
        .iter()
        .filter(|f| report.faces[f.index()])
        .map(|f| f.label())
        .collect();
    eprintln!(
        "{}: faces {} at {}²",
        r.describe(),
        drawn.join(" "),
        report.face
    );
    Ok(img)
}

fn write_picture(img: &Raster<[u8; 4]>, out: &Path) -> Result<()> {
    if out
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("exr"))
    {
        let f = Raster {
            width: img.width,
            height: img.height,
            data: img
                .data
                .iter()
                .map(|p| p.map(|c| f32::from(c) / 255.0))
                .collect(),
        };
        omniwarp::image_io::write_exr_rgba(out, &f, &[], omniwarp::image_io::Precision::Float)?;
    } else {
        omniwarp::image_io::write_png(out, img).context("--out")?;
    }
    Ok(())
}
