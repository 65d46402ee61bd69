//! `omniwarp bench panorama`: seed 001's frame-rate table — a cubic and a cylindrical panorama
//! projected onto a scene, in viewer mode (centre at the eye) and from another centre, at
//! 640×480 and 1024×768 — as frame rates on this machine's adapter (lavapipe without a GPU)
//! and as ratios to the cubic viewer, beside the seed's GeForce3 figures.

use anyhow::Result;
use clap::Args;
use glam::DVec3;
use omniwarp::content::Content;
use omniwarp::content::pattern::Pattern;
use omniwarp::cubemap::CubeMap;
use omniwarp::gpu::Renderer;
use omniwarp::gpu::frame::{FrameOptions, SceneRenderer};
use omniwarp::projection::{Params, View, build};
use omniwarp::raster::psnr;
use omniwarp::render::{Filter, Plan, Warp};
use omniwarp::scene::{Projected, Scene};

#[derive(Args)]
pub struct PanoramaBenchArgs {
    /// The scene the panorama is projected onto.
    #[arg(long, default_value = "city:small")]
    scene: String,
    /// Frames timed per case, 1–1000 (the median is reported).
    #[arg(long, default_value_t = 9, value_parser = clap::value_parser!(u16).range(1..=1000))]
    frames: u16,
    #[arg(long)]
    adapter: Option<String>,
}

/// Seed 001's table (frames per second, Pentium III 450 MHz + GeForce3): 640×480, 1024×768.
const SEED: [(&str, [f64; 2]); 4] = [
    ("cubic viewer", [652.0, 269.0]),
    ("cylindrical viewer", [140.0, 104.0]),
    ("cubic projection", [469.0, 227.0]),
    ("cylindrical projection", [53.0, 46.0]),
];

fn to_u8(img: &omniwarp::raster::Raster<[f32; 4]>) -> omniwarp::raster::Raster<[u8; 4]> {
    img.map(|p| p.map(|c| (c * 255.0).round().clamp(0.0, 255.0) as u8))
}

pub fn run(a: PanoramaBenchArgs) -> Result<()> {
    let scene = Scene::load(&a.scene)?;
    let eye = DVec3::new(0.0, 1.7, 0.0);
    let elsewhere = DVec3::new(6.0, 25.0, 4.0);
    let cube = CubeMap::from_fn(1024, 1, |d| {
        let c = Pattern::Checker.eval(d);
        c.map(|v| (v * 255.0).round() as u8)
    });
    // A cylindrical panorama of the usual 360° × 90° (4096 × 1024 texels at the horizon).
    let cyl = {
        let vfov = 90.0f64;
        let h = 2.0 * (vfov.to_radians() / 2.0).tan();
        let (w, rows) = (4096usize, 1024usize);
        let img = omniwarp::raster::Raster::from_fn(w, rows, |x, y| {
            let lon = ((x as f64 + 0.5) / w as f64 - 0.5) * std::f64::consts::TAU;
            let up = (0.5 - (y as f64 + 0.5) / rows as f64) * h;
            let d = DVec3::new(lon.sin(), up, -lon.cos()).normalize();
            Pattern::Checker.eval(d)
        });
        Content::cylindrical(&to_u8(&img), 360.0, vfov)?
    };
    let kinds = [("cubic", Content::cube(&cube)), ("cylindrical", cyl)];
    let mut r = SceneRenderer::new(scene.clone(), Renderer::Gpu, a.adapter.as_deref())?;
    outln!(
        "{} ({} triangles) with a projected panorama, flat 60°×45° view, {}",
        a.scene,
        scene.triangles(),
        r.describe()
    );
    outln!(
        "  case                   | size     | fps here | ratio to cubic viewer | seed fps | seed ratio"
    );
    for (k, &(w, h)) in [(640u32, 480u32), (1024, 768)].iter().enumerate() {
        let p = Params {
            hfov: Some(60.0),
            vfov: Some(45.0),
            ..Params::default()
        };
        let view = View::plain(build("flat", &p, f64::from(h) / f64::from(w))?);
        let mut base = None;
        for (kind, content) in &kinds {
            r.set_panorama(Some(Projected {
                content: content.clone(),
                centre: eye,
            }))?;
            for (mode, centre) in [("viewer", eye), ("projection", elsewhere)] {
                r.set_centre(centre);
                let o = FrameOptions {
                    size: (w, h),
                    face: None,
                    cmf: true,
                    blur: None,
                    eye,
                };
                r.frame(&view, &o)?;
                let mut t = Vec::new();
                for _ in 0..a.frames {
                    // Every frame draws the cube map again, as the seed's frames draw the scene.
                    r.invalidate();
                    let start = std::time::Instant::now();
                    r.frame(&view, &o)?;
                    t.push(start.elapsed().as_secs_f64());
                }
                t.sort_by(f64::total_cmp);
                let fps = 1.0 / t[t.len() / 2];
                let base_fps = *base.get_or_insert(fps);
                let name = format!("{kind} {mode}");
                let seed = SEED.iter().find(|s| s.0 == name).map_or([0.0; 2], |s| s.1);
                outln!(
                    "  {name:<22} | {:<8} | {fps:>8.1} | {:>21.2} | {:>8.0} | {:>10.2}",
                    format!("{w}×{h}"),
                    fps / base_fps,
                    seed[k],
                    seed[k] / SEED[0].1[k]
                );
            }
        }
    }
    split(&kinds[1].1)
}

/// Seed 001's linear + residual split against the exact lookup, on the CPU: the plan with every
/// sample located (`Plan::exact`, where the lookup's cost shows) and the error it leaves.
fn split(cyl: &Content<[u8; 4]>) -> Result<()> {
    let (w, h) = (1920u32, 1080u32);
    let p = Params {
        hfov: Some(100.0),
        vfov: Some(60.0),
        ..Params::default()
    };
    let view = View::plain(build("flat", &p, f64::from(h) / f64::from(w))?);
    let warp = Warp::View(&view);
    outln!(
        "seed 001's local warping split, {w}×{h} flat 100° view of the 4096×1024 cylinder, CPU:"
    );
    outln!("  lookup          | plan, every sample located | ratio | render vs exact lookup");
    let mut exact = None;
    for (name, bits) in [
        ("exact", None),
        ("residual f32", Some(None)),
        ("residual 8-bit", Some(Some(8))),
    ] {
        let c = match bits {
            None => cyl.clone(),
            Some(b) => cyl.clone().with_residual_split(b)?,
        };
        let mut t = Vec::new();
        let mut plan = None;
        for _ in 0..5 {
            let start = std::time::Instant::now();
            plan = Some(Plan::exact(warp, &c, c.atlas(), w, h, 1, Filter::Bilinear)?);
            t.push(start.elapsed().as_secs_f64() * 1e3);
        }
        t.sort_by(f64::total_cmp);
        let img = plan.expect("planned").render(c.atlas())?;
        let (base_ms, base_img) = exact.get_or_insert((t[2], img.clone()));
        let db = psnr(&img, base_img, 255.0, |_, _| true);
        outln!(
            "  {name:<15} | {:>23.1} ms | {:>5.2} | {}",
            t[2],
            t[2] / *base_ms,
            if db.is_finite() {
                format!("{db:.1} dB")
            } else {
                "identical".into()
            }
        );
    }
    Ok(())
}
