//! `omniwarp render --scene`: a 3D scene through a projection, on the GPU (wgpu; lavapipe where
//! there is no GPU) or the CPU, and `omniwarp gpu-bench`, frame time against cube-face size.

use crate::cli::flag_error;
use anyhow::{Context, Result};
use clap::{Args, ValueEnum};
use glam::DVec3;
use omniwarp::gpu::Renderer;
use omniwarp::gpu::frame::{FrameOptions, SceneRenderer};
use omniwarp::gpu::scene::Scene;
use omniwarp::gpu::warp::Blur;
use omniwarp::projection::View;
use std::path::Path;

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
    /// Render a 3D scene instead of content: a .gltf/.glb or .obj file, or the procedural
    /// city:small, city:medium or city:large (~10k, 100k, 1M triangles).
    #[arg(long, conflicts_with_all = ["content", "normal_map", "tiles", "rig"])]
    pub scene: Option<String>,
    /// Eye position x,y,z in the scene, metres.
    #[arg(long, value_parser = crate::cli::parse_vec3, default_value = "0,1.7,0", allow_hyphen_values = true)]
    pub eye: DVec3,
    /// Cube face size in pixels (default: chosen from the output's pixel pitch).
    #[arg(long)]
    pub face: Option<u32>,
    /// Draw all six faces even where the warp samples fewer (turns off seed 000's CMF).
    #[arg(long)]
    pub all_faces: bool,
    /// gpu, cpu, or auto (the GPU when an adapter exists).
    #[arg(long, value_enum, default_value = "auto")]
    pub renderer: RendererArg,
    /// Adapter to use: part of its name or backend (e.g. vulkan, gl, llvmpipe).
    #[arg(long)]
    pub adapter: Option<String>,
    /// Radial blur towards the image centre: the fraction of the way it reaches (0 to 1).
    #[arg(long)]
    pub blur: Option<f32>,
}

pub fn render(spec: &str, a: &SceneArgs, view: &View, size: (u32, u32), out: &Path) -> Result<()> {
    let blur = match a.blur {
        Some(s) if (0.0..=1.0).contains(&s) => Some(Blur {
            strength: s,
            samples: 16,
        }),
        Some(s) => anyhow::bail!("--blur: must be between 0 and 1, got {s}"),
        None => None,
    };
    let scene = Scene::load(spec).map_err(|e| anyhow::anyhow!("--scene: {}", e.reason()))?;
    let mut r = SceneRenderer::new(scene, a.renderer.renderer(), a.adapter.as_deref())
        .map_err(flag_error)?;
    let opts = FrameOptions {
        size,
        face: a.face,
        cmf: !a.all_faces,
        blur,
        eye: a.eye,
    };
    let (img, report) = r.frame(view, &opts).map_err(flag_error)?;
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
    if out
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("exr"))
    {
        let f = omniwarp::raster::Raster {
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
        omniwarp::image_io::write_png(out, &img).context("--out")?;
    }
    Ok(())
}

#[derive(Args)]
pub struct GpuBenchArgs {
    /// Largest cube face timed.
    #[arg(long, default_value_t = 2048)]
    max_face: u32,
    /// Largest face the CPU reference renders too (ray casting is slow).
    #[arg(long, default_value_t = 512)]
    cpu_max_face: u32,
    /// Scenes: any of small, medium, large.
    #[arg(long, value_delimiter = ',', default_value = "small,medium,large")]
    scenes: Vec<String>,
    #[arg(long)]
    adapter: Option<String>,
}

/// Median of three frames, the eye moved each time so the cube map is redrawn; milliseconds.
fn time_frames(r: &mut SceneRenderer, view: &View, o: FrameOptions) -> Result<f64> {
    let mut t = Vec::new();
    for k in 0..3 {
        let mut o = o;
        o.eye.x += 0.01 * f64::from(k + 1);
        let start = std::time::Instant::now();
        r.frame(view, &o)?;
        t.push(start.elapsed().as_secs_f64() * 1e3);
    }
    t.sort_by(f64::total_cmp);
    Ok(t[1])
}

/// Seed 000's Figure 8: frame time against cube-face size for a 1600×1200 cylindrical view
/// (120°×60°, three faces), three scene sizes, with and without CMF, and the CPU reference beside it.
pub fn bench(a: GpuBenchArgs) -> Result<()> {
    let (w, h) = (1600, 1200);
    let params = omniwarp::projection::Params {
        hfov: Some(120.0),
        vfov: Some(60.0),
        ..Default::default()
    };
    let view = View::plain(omniwarp::projection::build("cylindrical", &params, 0.75)?);
    for name in &a.scenes {
        let scene = Scene::load(&format!("city:{name}"))?;
        let mut gpu = SceneRenderer::new(scene.clone(), Renderer::Gpu, a.adapter.as_deref())?;
        let mut cpu = SceneRenderer::new(scene.clone(), Renderer::Cpu, None)?;
        println!(
            "city:{name} ({} triangles), 1600×1200 cylindrical 120°×60°, {}",
            scene.triangles(),
            gpu.describe()
        );
        println!("  face | all 6 faces | CMF (faces) | CPU reference | CPU / GPU (CMF)");
        let mut face = 128;
        while face <= a.max_face {
            let o = FrameOptions {
                size: (w, h),
                face: Some(face),
                cmf: false,
                blur: None,
                eye: DVec3::new(0.0, 1.7, 0.0),
            };
            let all = time_frames(&mut gpu, &view, o)?;
            let cmf_opts = FrameOptions { cmf: true, ..o };
            let cmf = time_frames(&mut gpu, &view, cmf_opts)?;
            let faces = gpu
                .frame(&view, &cmf_opts)?
                .1
                .faces
                .iter()
                .filter(|f| **f)
                .count();
            let cpu_ms = if face <= a.cpu_max_face {
                Some(time_frames(&mut cpu, &view, o)?)
            } else {
                None
            };
            println!(
                "  {face:>4} | {all:>8.0} ms | {cmf:>6.0} ms ({faces}) | {} | {}",
                cpu_ms.map_or("      —".into(), |c| format!("{c:>7.0} ms")),
                cpu_ms.map_or("—".into(), |c| format!("{:.1}×", c / cmf))
            );
            face *= 2;
        }
    }
    Ok(())
}

#[derive(Args)]
pub struct SceneExportArgs {
    /// The procedural city to write: small, medium or large.
    #[arg(long, default_value = "small")]
    city: String,
    /// Output: .gltf (with a .bin beside it) or .glb.
    #[arg(long)]
    out: std::path::PathBuf,
}

/// Writes a procedural city as glTF, for other tools or for `render --scene file.gltf`.
pub fn export(a: SceneExportArgs) -> Result<()> {
    let scene = Scene::load(&format!("city:{}", a.city))
        .map_err(|e| anyhow::anyhow!("--city: {}", e.reason()))?;
    let write = |path: &Path, bytes: &[u8]| {
        omniwarp::image_io::atomic_write(path, |f| {
            std::io::Write::write_all(f, bytes).map_err(|e| omniwarp::Error::file(path, e))
        })
    };
    match a.out.extension().and_then(|e| e.to_str()) {
        Some("glb") => {
            let (json, bin) = scene.to_gltf(None);
            write(&a.out, &omniwarp::gpu::scene::glb(&json, &bin))?;
        }
        Some("gltf") => {
            let bin_path = a.out.with_extension("bin");
            let name = bin_path
                .file_name()
                .and_then(|n| n.to_str())
                .context("--out: the file name is not UTF-8")?;
            let (json, bin) = scene.to_gltf(Some(name));
            write(&bin_path, &bin)?;
            write(&a.out, json.as_bytes())?;
        }
        _ => anyhow::bail!("--out: must end in .gltf or .glb"),
    }
    eprintln!(
        "city:{} ({} triangles) → {}",
        a.city,
        scene.triangles(),
        a.out.display()
    );
    Ok(())
}
