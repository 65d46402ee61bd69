//! `omniwarp bench gpu`: 3D scenes through the GPU renderer against cube-face size, with and
//! without CMF, beside the CPU reference (seed 000, Figure 8).

use anyhow::Result;
use clap::Args;
use glam::DVec3;
use omniwarp::gpu::Renderer;
use omniwarp::gpu::frame::{FrameOptions, SceneRenderer};
use omniwarp::projection::View;
use omniwarp::scene::Scene;

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
pub fn run(a: GpuBenchArgs) -> Result<()> {
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
        outln!(
            "city:{name} ({} triangles), 1600×1200 cylindrical 120°×60°, {}",
            scene.triangles(),
            gpu.describe()
        );
        outln!("  face | all 6 faces | CMF (faces) | CPU reference (CMF) | CPU / GPU (CMF)");
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
            // The CPU casts the same faces the GPU's CMF frame renders: equal work compared.
            let cpu_ms = if face <= a.cpu_max_face {
                Some(time_frames(&mut cpu, &view, cmf_opts)?)
            } else {
                None
            };
            outln!(
                "  {face:>4} | {all:>8.0} ms | {cmf:>6.0} ms ({faces}) | {} | {}",
                cpu_ms.map_or("      —".into(), |c| format!("{c:>7.0} ms")),
                cpu_ms.map_or("—".into(), |c| format!("{:.1}×", c / cmf))
            );
            face *= 2;
        }
    }
    Ok(())
}
