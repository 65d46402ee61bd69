//! `omniwarp bench chart --scene …`: every way omniwarp can draw one scene through one view,
//! timed against how close each comes to the exact per-pixel ray cast — the speed-against-
//! accuracy chart, with the Pareto front marked, as CSV and SVG.
//!
//! Methods: the cube map (seed 000) at face sizes 256–4096 with the analytic δP; the same cube
//! through a float normal map (f32, f16) and through tile screens of several densities; the
//! cube read back and warped on the CPU with nearest, bilinear and bicubic filters and 1–4×
//! supersampling; piecewise perspective projection (seed 003) at several tolerances, and at
//! 0.25 px with 4× multisampling; and, on
//! the CPU renderer, the ray-cast cube and PPP's CPU twin. Errors: PSNR against the exact image,
//! the angular error of each pixel's sampling direction (where a method has one), and the edge
//! widths relative to the exact image's over 8 × 8 regions (seed 003's Figure 8).

use super::super::args::{ProjectionArgs, parse_size, parse_vec3};
use super::super::io::median_ms;
use anyhow::{Result, bail};
use clap::Args;
use glam::DVec3;
use omniwarp::content::Content;
use omniwarp::cubemap::{CubeMap, Layout};
use omniwarp::gpu::Renderer;
use omniwarp::gpu::frame::{FrameOptions, SceneRenderer};
use omniwarp::image_io::Loaded;
use omniwarp::normalmap::NormalMap;
use omniwarp::projection::View;
use omniwarp::raster::edges::{relative_edge_widths, spread};
use omniwarp::raster::{Raster, psnr};
use omniwarp::render::{Filter, Plan, Warp};
use omniwarp::scene::Scene;
use omniwarp::scene::ppp::{Pieces, Tolerance, true_direction};
use omniwarp::tiles::adapt::rows_for;
use omniwarp::tiles::build::from_source;
use std::path::PathBuf;
use std::process::Command;
use std::time::Instant;

mod output;
use output::{Row, mark_front, print_table, write_csv, write_svg};

#[derive(Args)]
pub struct MethodChartArgs {
    /// The scene every method draws (see `render --scene`).
    #[arg(long)]
    pub scene: Option<String>,
    #[command(flatten)]
    pub projection: ProjectionArgs,
    /// Output size WxH.
    #[arg(long, value_parser = parse_size, default_value = "1600x1200")]
    pub size: (u32, u32),
    /// Eye position x,y,z in the scene, metres.
    #[arg(long, value_parser = parse_vec3, default_value = "0,1.7,0", allow_hyphen_values = true)]
    pub eye: DVec3,
    /// Frames timed per method, 1–100 (the median is reported); every frame is redrawn.
    #[arg(long, default_value_t = 3, value_parser = clap::value_parser!(u16).range(1..=100))]
    pub frames: u16,
    /// Also the CPU renderer's methods (the ray-cast cube, PPP's CPU twin).
    #[arg(long)]
    pub cpu: bool,
    /// Rays per pixel side of the exact reference, 1–4: 1 is the point-sampled image every
    /// one-sample method approximates; 4 (16 rays, averaged) the antialiased image that
    /// supersampled methods approximate.
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u32).range(1..=4))]
    pub reference_samples: u32,
    /// Also ffmpeg's v360 and OpenCV's remap warping the same cube read back, with each of
    /// their filters (cylindrical views seen straight ahead only). ffmpeg from PATH, OpenCV
    /// from target/bench-venv or python3; calibration/bench/bench-peers installs both.
    #[arg(long)]
    pub peers: bool,
    /// Where the chart goes: NAME.csv and NAME.svg.
    #[arg(long, default_value = "calibration/bench/charts/methods")]
    pub name: PathBuf,
    #[arg(long)]
    pub adapter: Option<String>,
}

/// Largest and 99th-percentile angle, degrees, between `ray(i, j)` and the view's direction.
fn direction_error(
    view: &View,
    (w, h): (u32, u32),
    ray: impl Fn(u32, u32) -> Option<DVec3> + Sync,
) -> (f64, f64) {
    use rayon::prelude::*;
    let mut angles: Vec<f64> = (0..h)
        .into_par_iter()
        .flat_map_iter(|j| {
            let ray = &ray;
            (0..w).filter_map(move |i| {
                let (x, y) = (f64::from(i) + 0.5, f64::from(j) + 0.5);
                let truth = true_direction(view, x, y, w, h)?;
                let r = ray(i, j)?;
                Some(truth.cross(r).length().atan2(truth.dot(r)).to_degrees())
            })
        })
        .collect();
    if angles.is_empty() {
        return (0.0, 0.0);
    }
    angles.sort_by(f64::total_cmp);
    (
        angles[angles.len() - 1],
        angles[(angles.len() - 1) * 99 / 100],
    )
}

/// A normal map's values rounded to half precision, as an f16 EXR stores them.
fn to_f16(map: &NormalMap) -> Result<NormalMap> {
    let p = map.pixels();
    let pixels = Raster {
        width: p.width,
        height: p.height,
        data: p
            .data
            .iter()
            .map(|v| v.map(|c| exr::prelude::f16::from_f32(c).to_f32()))
            .collect(),
    };
    Ok(NormalMap::from_pixels(pixels, Vec::new())?)
}

pub fn run(a: MethodChartArgs, spec: &str) -> Result<()> {
    let (w, h) = a.size;
    let p = &a.projection;
    if a.peers
        && (p.projection.as_deref() != Some("cylindrical")
            || p.look_to != DVec3::NEG_Z
            || p.look_up != DVec3::Y
            || p.offaxis != DVec3::ZERO
            || p.zoom != 1.0)
    {
        bail!(
            "--peers: ffmpeg's and OpenCV's rows are drawn for --projection cylindrical seen straight ahead (no --look-to, --look-up, --offaxis or --zoom)"
        );
    }
    let view = a.projection.view(w, h)?;
    let source = a.projection.source(w, h)?;
    let scene = Scene::load(spec).map_err(|e| anyhow::anyhow!("--scene: {}", e.reason()))?;
    let o = FrameOptions {
        size: (w, h),
        face: None,
        cmf: true,
        blur: None,
        eye: a.eye,
    };
    let mut gpu = SceneRenderer::new(scene.clone(), Renderer::Gpu, a.adapter.as_deref())?;
    let exact_start = Instant::now();
    let exact = gpu.frame_reference(&view, &o, a.reference_samples)?;
    let exact_ms = exact_start.elapsed().as_secs_f64() * 1e3;
    let measure = |img: &Raster<[u8; 4]>| {
        let widths = relative_edge_widths(img, &exact, 8);
        let mut sorted = widths.clone();
        sorted.sort_by(f64::total_cmp);
        let median = sorted.get(sorted.len() / 2).copied().unwrap_or(f64::NAN);
        (
            psnr(img, &exact, 255.0, |_, _| true),
            (median, spread(&widths)),
        )
    };
    let mut rows = Vec::new();
    let mut push = |family, setting: String, renderer, ms, img: &Raster<[u8; 4]>, direction| {
        let (db, edges) = measure(img);
        eprintln!("{family:<14} {setting:<28} {renderer:<4} {ms:9.1} ms {db:6.2} dB");
        rows.push(Row {
            family,
            setting,
            renderer,
            ms,
            db,
            direction,
            edges,
            front: false,
        });
    };
    let max_face = 4096;
    for face in [256u32, 512, 1024, 2048, max_face] {
        let of = FrameOptions {
            face: Some(face),
            ..o
        };
        let (img, _) = gpu.frame(&view, &of)?;
        let ms = median_ms(a.frames, || {
            gpu.invalidate();
            gpu.frame(&view, &of).map(|_| ()).map_err(Into::into)
        })?;
        push(
            "cube",
            format!("{face}², analytic δP"),
            "gpu",
            ms,
            &img,
            None,
        );
    }
    let face = 1024;
    let of = FrameOptions {
        face: Some(face),
        ..o
    };
    let f32_map = NormalMap::from_view(&view, w, h)?;
    let mut maps = vec![("normal map f32".to_string(), f32_map.clone())];
    maps.push(("normal map f16".to_string(), to_f16(&f32_map)?));
    for columns in [9usize, 17, 33, 65] {
        let rows_n = rows_for(columns, w as usize, h as usize);
        let screen = from_source(&source, columns, rows_n)?;
        maps.push((
            format!("tiles {columns}×{rows_n}"),
            screen.feature_map(w as usize, h as usize).normal_map(),
        ));
    }
    for (label, map) in &maps {
        let (img, _) = gpu.frame_map(map, &of)?;
        let ms = median_ms(a.frames, || {
            gpu.invalidate();
            gpu.frame_map(map, &of).map(|_| ()).map_err(Into::into)
        })?;
        let err = direction_error(&view, (w, h), |i, j| map.direction(i as usize, j as usize));
        push(
            "cube",
            format!("{face}², {label}"),
            "gpu",
            ms,
            &img,
            Some(err),
        );
    }
    let filters = [
        (Filter::Nearest, 1),
        (Filter::Bilinear, 1),
        (Filter::Bicubic, 1),
        (Filter::Bilinear, 2),
        (Filter::Bicubic, 2),
        (Filter::Bilinear, 4),
    ];
    // The cube drawn and read back, then warped in steady state (the plan built once, as the
    // frame loop and the peers' rows do); each new cube needs its atlas made again.
    let cube = gpu.cube_map(a.eye, face)?;
    let cube_ms = median_ms(a.frames, || {
        gpu.invalidate();
        gpu.cube_map(a.eye, face).map(|_| ()).map_err(Into::into)
    })?;
    for (filter, ss) in filters {
        let content = Content::cube(&cube);
        let plan = Plan::new(
            Warp::View(&view),
            &content,
            content.atlas(),
            w,
            h,
            ss,
            filter,
        )?;
        let img = plan.render(content.atlas())?;
        let ms = median_ms(a.frames, || {
            let content = Content::cube(&cube);
            plan.render(content.atlas()).map(|_| ()).map_err(Into::into)
        })?;
        let setting = format!("{face}² read back, CPU {filter:?} ×{ss}²").to_lowercase();
        push("cube+cpu warp", setting, "gpu", cube_ms + ms, &img, None);
    }
    if a.peers {
        peer_rows(&a, (&cube, cube_ms), &mut push)?;
    }
    let mut cuts: Vec<(String, Pieces)> = Vec::new();
    for t in ["1px", "0.5px", "0.25px", "0.1px"] {
        let Ok((p, _)) = Pieces::for_tolerance(&view, w, h, Tolerance::parse(t)?) else {
            eprintln!("ppp {t}: no cut meets it");
            continue;
        };
        if !cuts
            .iter()
            .any(|(_, q)| (q.cols, q.rows) == (p.cols, p.rows))
        {
            cuts.push((format!("{t}: {}×{} cells", p.cols, p.rows), p));
        }
    }
    let ppp_errors: Vec<(f64, f64)> = cuts
        .iter()
        .map(|(_, pieces)| direction_error(&view, (w, h), |i, j| pieces.ray(i, j)))
        .collect();
    for ((label, pieces), err) in cuts.iter().zip(&ppp_errors) {
        let (img, _) = gpu.frame_ppp(pieces, &o)?;
        let ms = median_ms(a.frames, || {
            gpu.frame_ppp(pieces, &o).map(|_| ()).map_err(Into::into)
        })?;
        push("ppp", label.clone(), "gpu", ms, &img, Some(*err));
    }
    if let (Some((label, pieces)), Some(err)) = (
        cuts.get(2).or(cuts.last()),
        ppp_errors.get(2).or(ppp_errors.last()),
    ) {
        let (img, _) = gpu.frame_ppp_antialiased(pieces, &o)?;
        let ms = median_ms(a.frames, || {
            gpu.frame_ppp_antialiased(pieces, &o)
                .map(|_| ())
                .map_err(Into::into)
        })?;
        push(
            "ppp",
            format!("{label}, 4× MSAA"),
            "gpu",
            ms,
            &img,
            Some(*err),
        );
    }
    let adapter = gpu.describe();
    drop(gpu);
    if a.cpu {
        let mut cpu = SceneRenderer::new(scene, Renderer::Cpu, None)?;
        for face in [256u32, 512] {
            let of = FrameOptions {
                face: Some(face),
                ..o
            };
            let (img, _) = cpu.frame(&view, &of)?;
            let ms = median_ms(a.frames, || {
                cpu.invalidate();
                cpu.frame(&view, &of).map(|_| ()).map_err(Into::into)
            })?;
            push(
                "cube",
                format!("{face}², analytic δP"),
                "cpu",
                ms,
                &img,
                None,
            );
        }
        for ((label, pieces), err) in cuts.iter().zip(&ppp_errors).take(2) {
            let (img, _) = cpu.frame_ppp(pieces, &o)?;
            let ms = median_ms(a.frames, || {
                cpu.frame_ppp(pieces, &o).map(|_| ()).map_err(Into::into)
            })?;
            push("ppp", label.clone(), "cpu", ms, &img, Some(*err));
        }
    }
    mark_front(&mut rows);
    let k = a.reference_samples;
    let title = format!(
        "{spec}, {} {w}×{h}, {adapter}, reference {k}×{k} rays a pixel",
        a.projection.projection.as_deref().unwrap_or("")
    );
    write_csv(&a.name, &rows, exact_ms)?;
    write_svg(&a.name, &title, &rows)?;
    outln!("{title}; exact reference (CPU ray cast) {exact_ms:.0} ms");
    print_table(&rows)?;
    Ok(())
}

/// A row's measurements as `run`'s `push` takes them.
type Push<'a> =
    dyn FnMut(&'static str, String, &'static str, f64, &Raster<[u8; 4]>, Option<(f64, f64)>) + 'a;

/// The peers' rows: the cube drawn on the GPU and read back (`cube_ms`, as our own read-back
/// rows), written in ffmpeg's c6x1 layout, warped by ffmpeg's v360 and OpenCV's
/// remap with each of their filters. Their time a frame is the cube's plus their steady-state
/// warp (ffmpeg: the difference between runs of 1 and 1 + N looped frames, so decoding and
/// start-up cancel; OpenCV: the median `cv2.remap` with its maps built once), same threads.
fn peer_rows(
    a: &MethodChartArgs,
    cube: (&CubeMap<[u8; 4]>, f64),
    push: &mut Push<'_>,
) -> Result<()> {
    let dir = std::env::temp_dir().join(format!("omniwarp-chart-peers-{}", std::process::id()));
    std::fs::create_dir_all(&dir)?;
    let done = peer_rows_in(&dir, a, cube, push);
    // The peers' inputs and outputs go whether they ran or failed.
    let _ = std::fs::remove_dir_all(&dir);
    done
}

/// [`peer_rows`] with its files in `dir`.
fn peer_rows_in(
    dir: &std::path::Path,
    a: &MethodChartArgs,
    (cube, cube_ms): (&CubeMap<[u8; 4]>, f64),
    push: &mut Push<'_>,
) -> Result<()> {
    let face = cube.size;
    let (w, h) = a.size;
    let (hfov, vfov) = (
        a.projection.hfov.unwrap_or(360.0),
        a.projection.vfov.unwrap_or(90.0),
    );
    let input = dir.join("cube.png");
    omniwarp::image_io::write_png(&input, &Layout::FfmpegC6x1.join(cube))?;
    let threads = std::thread::available_parallelism().map_or(2, |n| n.get());
    let frames = 20;
    let read = |path: &std::path::Path| -> Result<Raster<[u8; 4]>> {
        match omniwarp::image_io::read_image(path)? {
            Loaded::U8(img) => Ok(img),
            Loaded::F32(_) => bail!("{}: expected an 8-bit image", path.display()),
        }
    };
    let run = |cmd: &mut Command| -> Result<std::process::Output> {
        let out = cmd
            .output()
            .map_err(|e| anyhow::anyhow!("--peers: {cmd:?}: {e}"))?;
        if !out.status.success() {
            bail!(
                "--peers: {cmd:?} failed: {}",
                String::from_utf8_lossy(&out.stderr)
            );
        }
        Ok(out)
    };
    for (filter, interp) in [
        ("nearest", "near"),
        ("bilinear", "linear"),
        ("bicubic", "cubic"),
    ] {
        let vf = format!(
            "v360=input=c6x1:output=cylindrical:h_fov={hfov}:v_fov={vfov}:w={w}:h={h}:interp={interp}"
        );
        let out = dir.join(format!("ffmpeg-{filter}.png"));
        let ffmpeg = || {
            let mut c = Command::new("ffmpeg");
            c.args(["-nostdin", "-loglevel", "error", "-y", "-filter_threads"])
                .arg(threads.to_string())
                .arg("-i")
                .arg(&input);
            c
        };
        run(ffmpeg()
            .args([
                "-vf",
                &format!("format=gbrp,{vf},format=rgba"),
                "-frames:v",
                "1",
            ])
            .arg(&out))?;
        let timed = |loops: u32| -> Result<f64> {
            let start = Instant::now();
            run(ffmpeg().args([
                "-vf",
                &format!("format=gbrp,loop=loop={loops}:size=1,{vf}"),
                "-f",
                "null",
                "-",
            ]))?;
            Ok(start.elapsed().as_secs_f64() * 1e3)
        };
        let mut per_frame: Vec<f64> = (0..3)
            .map(|_| Ok((timed(frames)? - timed(0)?) / f64::from(frames)))
            .collect::<Result<_>>()?;
        per_frame.sort_by(f64::total_cmp);
        let setting = format!("{face}² read back, v360 {filter}");
        push(
            "ffmpeg v360",
            setting,
            "gpu",
            cube_ms + per_frame[1],
            &read(&out)?,
            None,
        );
    }
    let python = ["target/bench-venv/bin/python", "python3"]
        .into_iter()
        .find(|py| {
            Command::new(py)
                .args(["-c", "import cv2"])
                .output()
                .is_ok_and(|o| o.status.success())
        })
        .ok_or_else(|| anyhow::anyhow!("--peers: no Python with OpenCV (calibration/bench/bench-peers installs one in target/bench-venv)"))?;
    let script =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("calibration/bench/opencv_remap.py");
    for filter in ["nearest", "bilinear", "bicubic"] {
        let out = dir.join(format!("opencv-{filter}.png"));
        let said = run(Command::new(python)
            .arg(&script)
            .arg(&input)
            .args([
                w.to_string(),
                h.to_string(),
                frames.to_string(),
                threads.to_string(),
            ])
            .arg(&out)
            .args([filter.to_string(), hfov.to_string(), vfov.to_string()]))?;
        let said = String::from_utf8_lossy(&said.stdout);
        let ms: f64 = said
            .split(" ms/frame")
            .next()
            .and_then(|head| head.rsplit(' ').next())
            .and_then(|n| n.parse().ok())
            .ok_or_else(|| anyhow::anyhow!("--peers: OpenCV said `{said}`"))?;
        let setting = format!("{face}² read back, remap {filter}");
        push(
            "opencv remap",
            setting,
            "gpu",
            cube_ms + ms,
            &read(&out)?,
            None,
        );
    }
    Ok(())
}
