//! `omniwarp bench ppp`: seed 003's Table 1 as ratios on this machine — the 35k-triangle city at
//! 1600×1200 through a 360° cylinder and through a view deformation, image-based (a 2048² cube
//! map, then the warp) against piecewise perspective projection — beside the seed's figures,
//! with each image's PSNR against the exact per-pixel ray cast; and the seed's high-quality
//! rows, antialiased, against an antialiased reference.

use super::super::io::median_ms;
use anyhow::Result;
use clap::Args;
use glam::DVec3;
use omniwarp::content::Content;
use omniwarp::gpu::Renderer;
use omniwarp::gpu::frame::{FrameOptions, SceneRenderer};
use omniwarp::projection::{Params, View, build};
use omniwarp::raster::{Raster, psnr};
use omniwarp::render::{Filter, Plan, Warp};
use omniwarp::scene::Scene;
use omniwarp::scene::ppp::{Pieces, Tolerance};

#[derive(Args)]
pub struct PppBenchArgs {
    /// Frames timed per case, 1–1000 (the median is reported).
    #[arg(long, default_value_t = 5, value_parser = clap::value_parser!(u16).range(1..=1000))]
    frames: u16,
    #[arg(long)]
    adapter: Option<String>,
}

/// Seed 003's Table 1 (fps, 35k triangles, 1600×1200): image-based, PPP, replication, and the
/// high-quality rows (16× anisotropic filtering, 16xQ antialiasing): image-based, PPP.
const SEED: [(&str, f64, f64, f64, f64, f64); 2] = [
    ("cylinder", 41.7, 84.7, 1.96, 33.8, 54.8),
    ("view deformation", 206.0, 22.1, 10.2, 95.8, 20.9),
];

pub fn run(a: PppBenchArgs) -> Result<()> {
    let (w, h) = (1600u32, 1200u32);
    let scene = Scene::city(35_000);
    let mut r = SceneRenderer::new(scene.clone(), Renderer::Gpu, a.adapter.as_deref())?;
    let aspect = f64::from(h) / f64::from(w);
    let cylinder = Params {
        hfov: Some(360.0),
        vfov: Some(90.0),
        ..Params::default()
    };
    // The seed deforms a perspective view through a camera texture; a 180° fisheye is such a
    // deformation in closed form, cut into about the seed's 9,322 pieces.
    let fisheye = Params {
        fov: Some(180.0),
        ..Params::default()
    };
    let cases = [
        (
            "cylinder",
            View::plain(build("cylindrical", &cylinder, aspect)?),
            (160, 1),
        ),
        (
            "view deformation",
            View::plain(build("fisheye", &fisheye, aspect)?),
            (80, 58),
        ),
    ];
    let o = FrameOptions {
        size: (w, h),
        face: Some(2048),
        cmf: true,
        blur: None,
        eye: DVec3::new(0.0, 1.7, 0.0),
    };
    outln!(
        "city ({} triangles), {w}×{h}, {}; median of {} frames, every frame redrawn",
        scene.triangles(),
        r.describe(),
        a.frames
    );
    outln!(
        "  case             | method                     | ms/frame | ratio to image-based | replication | PSNR vs exact | seed ratio | seed replication"
    );
    for ((name, view, cut), seed) in cases.iter().zip(SEED) {
        let chosen = Pieces::for_tolerance(view, w, h, Tolerance::Pixels(0.25))?.0;
        let seeds = Pieces::new(view, w, h, cut.0, cut.1)?;
        let cuts = [
            (format!("PPP, {}×{} cells", cut.0, cut.1), &seeds),
            (
                format!("PPP, 0.25 px: {}×{}", chosen.cols, chosen.rows),
                &chosen,
            ),
        ];
        let hq_cuts =
            [&seeds, &chosen].map(|p| (format!("HQ PPP, {}×{}, 4× MSAA", p.cols, p.rows), p));
        let exact = r.frame_exact(view, &o)?;
        let db = |img: &Raster<[u8; 4]>| psnr(img, &exact, 255.0, |_, _| true);
        let (img, _) = r.frame(view, &o)?;
        let cube_ms = median_ms(a.frames, || {
            r.invalidate();
            r.frame(view, &o).map(|_| ()).map_err(Into::into)
        })?;
        image_based_row(name, "image-based, 2048² cube", cube_ms, db(&img))?;
        let plain = Quality {
            base_ms: cube_ms,
            msaa: false,
            seed_ratio: seed.2 / seed.1,
            seed_replication: seed.3,
        };
        ppp_rows(&mut r, a.frames, &o, name, &cuts, &plain, &db)?;
        // The high-quality rows, against the antialiased reference. Pixels the view's rim
        // (a fisheye's circle) crosses are left out: the reference averages only the rays
        // that have a direction, a method draws a pixel whole or not at all.
        let inside = |x: usize, y: usize| {
            (y.saturating_sub(1)..=(y + 1).min(h as usize - 1)).all(|j| {
                (x.saturating_sub(1)..=(x + 1).min(w as usize - 1))
                    .all(|i| exact.data[j * w as usize + i][3] > 0)
            })
        };
        let reference = r.frame_reference(view, &o, 4)?;
        let db = |img: &Raster<[u8; 4]>| psnr(img, &reference, 255.0, inside);
        let cube = r.cube_map(o.eye, 2048)?;
        let content = Content::cube(&cube);
        let plan = Plan::new(
            Warp::View(view),
            &content,
            content.atlas(),
            w,
            h,
            2,
            Filter::Bilinear,
        )?;
        let img = plan.render(content.atlas())?;
        let hq_ms = median_ms(a.frames, || {
            r.invalidate();
            let cube = r.cube_map(o.eye, 2048)?;
            let content = Content::cube(&cube);
            plan.render(content.atlas()).map(|_| ()).map_err(Into::into)
        })?;
        image_based_row(name, "HQ image-based, ×2² warp", hq_ms, db(&img))?;
        let hq = Quality {
            base_ms: hq_ms,
            msaa: true,
            seed_ratio: seed.5 / seed.4,
            seed_replication: seed.3,
        };
        ppp_rows(&mut r, a.frames, &o, name, &hq_cuts, &hq, &db)?;
    }
    outln!(
        "ratio: image-based time over the method's (above 1: faster than image-based); the seed's: PPP fps over image-based fps (GeForce 8800 GTS)"
    );
    outln!(
        "HQ: PPP with 4× multisampling against the 2048² cube read back and warped on the CPU with 2×2 supersampling (our cube pass does not multisample its faces; the seed's HQ antialiased them 16xQ and filtered 16× anisotropically), PSNR against 4×4 rays a pixel (pixels on a fisheye's rim left out)"
    );
    Ok(())
}

/// What a case's PPP rows are compared with: the image-based time at their quality, and the
/// seed's figures.
struct Quality {
    base_ms: f64,
    msaa: bool,
    seed_ratio: f64,
    seed_replication: f64,
}

fn image_based_row(name: &str, label: &str, ms: f64, db: f64) -> Result<()> {
    outln!(
        "  {name:<16} | {label:<26} | {ms:8.1} | {:20.2} | {:>11} | {db:10.2} dB | {:>10} | {:>16}",
        1.0,
        "-",
        "1.00",
        "-"
    );
    Ok(())
}

/// One row per cut, labelled: PPP (with 4× MSAA at high quality) timed against the
/// image-based frame.
fn ppp_rows(
    r: &mut SceneRenderer,
    frames: u16,
    o: &FrameOptions,
    name: &str,
    cuts: &[(String, &Pieces)],
    q: &Quality,
    db: &dyn Fn(&Raster<[u8; 4]>) -> f64,
) -> Result<()> {
    for (label, pieces) in cuts {
        let draw = |r: &mut SceneRenderer| {
            if q.msaa {
                r.frame_ppp_antialiased(pieces, o)
            } else {
                r.frame_ppp(pieces, o)
            }
        };
        let (img, report) = draw(r)?;
        let ms = median_ms(frames, || draw(r).map(|_| ()).map_err(Into::into))?;
        outln!(
            "  {name:<16} | {label:<26} | {ms:8.1} | {:20.2} | {:11.2} | {:10.2} dB | {:10.2} | {:16.2}",
            q.base_ms / ms,
            report.replication.unwrap_or(f64::NAN),
            db(&img),
            q.seed_ratio,
            q.seed_replication
        );
    }
    Ok(())
}
