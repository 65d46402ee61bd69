//! `omniwarp calibrate`: measured correspondences in, a rig channel out.

use anyhow::{Context, Result, bail};
use clap::Args;
use omniwarp::calibration::{Correspondence, ModelChoice, Problem, calibrate};
use omniwarp::lens::{Lens, LensModel};
use omniwarp::rig::LensDoc;
use serde::Deserialize;
use std::path::PathBuf;

#[derive(Args)]
pub struct CalibrateArgs {
    /// Correspondences (JSON): {"resolution": [W, H], "points": [{"pixel": [u, v], "world":
    /// [x, y, z]}, …], "lens": {"model": …, "intrinsics": […]} (optional: known intrinsics or a
    /// seed)}. Pixels count from the centre of the top-left pixel; world in metres.
    #[arg(long)]
    correspondences: PathBuf,
    /// Lens model: `auto` (PINHOLE → OPENCV4 → 5 → 8 while held-out residuals improve) or a
    /// model name.
    #[arg(long, default_value = "auto")]
    model: String,
    /// Keep the given lens's intrinsics and solve the pose only.
    #[arg(long)]
    intrinsics_fixed: bool,
    /// Channel id written into the result.
    #[arg(long, default_value = "projector")]
    id: String,
    /// The projector as a rig channel (JSON).
    #[arg(long)]
    out: PathBuf,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct Input {
    resolution: [u32; 2],
    points: Vec<Correspondence>,
    #[serde(default)]
    lens: Option<LensDoc>,
}

fn reason(e: omniwarp::Error) -> String {
    match e {
        omniwarp::Error::Invalid { name, reason } => format!("{name}: {reason}"),
        other => other.to_string(),
    }
}

pub fn run(a: CalibrateArgs) -> Result<()> {
    let text = std::fs::read_to_string(&a.correspondences)
        .with_context(|| format!("--correspondences {}", a.correspondences.display()))?;
    let de = &mut serde_json::Deserializer::from_str(&text);
    let input: Input = serde_path_to_error::deserialize(de)
        .map_err(|e| anyhow::anyhow!("--correspondences: at {}: {}", e.path(), e.inner()))?;
    let lens = match &input.lens {
        Some(l) => {
            let model: LensModel = l
                .model
                .parse()
                .map_err(|e| anyhow::anyhow!("--correspondences: lens.{}", reason(e)))?;
            Some(
                Lens::new(model, l.intrinsics.clone())
                    .map_err(|e| anyhow::anyhow!("--correspondences: lens.{}", reason(e)))?,
            )
        }
        None => None,
    };
    let choice = match a.model.as_str() {
        "auto" => ModelChoice::Auto,
        m => ModelChoice::Fixed(
            m.parse()
                .map_err(|e| anyhow::anyhow!("--model: {}", reason(e)))?,
        ),
    };
    if a.intrinsics_fixed && lens.is_none() {
        bail!("--intrinsics-fixed: the correspondences file gives no lens to keep");
    }
    let problem = Problem {
        resolution: input.resolution,
        points: input.points,
        lens,
        intrinsics_fixed: a.intrinsics_fixed,
    };
    let cal = calibrate(&problem, choice)
        .map_err(|e| anyhow::anyhow!("--correspondences: {}", reason(e)))?;
    let fit = &cal.fit;
    for c in &cal.considered {
        eprintln!(
            "{}: RMS {:.4} px, held-out {:.4} px — {}",
            c.model, c.rms, c.held_out_rms, c.verdict
        );
    }
    eprintln!(
        "chosen {}: RMS {:.4} px over {} points",
        fit.lens.model(),
        fit.rms,
        problem.points.len()
    );
    for (name, s) in &fit.sigma {
        eprintln!("  σ({name}) = {s:.3e}");
    }
    for w in &cal.warnings {
        eprintln!("warning: {w}");
    }
    let doc = cal.channel_doc(&a.id, input.resolution);
    let json = serde_json::to_string_pretty(&doc)?;
    omniwarp::image_io::atomic_write(&a.out, |f| {
        use std::io::Write;
        f.write_all(json.as_bytes())
            .map_err(|e| omniwarp::Error::file(&a.out, e))
    })?;
    Ok(())
}

/// Calibration time against point count and model.
pub fn bench() -> Result<()> {
    use glam::{DMat3, DVec3};
    use omniwarp::surface::{Cylinder, Screen};
    use std::time::Instant;
    let screen = Screen::Cylinder(Cylinder {
        radius: 2.5,
        centre: [0.0; 3],
        axis: [0.0, 1.0, 0.0],
        height: [-3.0, 3.0],
        arc: [-180.0, 180.0],
    });
    let truth = Lens::new(
        LensModel::OpenCv(5),
        vec![
            1500.0, 1495.0, 955.0, 560.0, -0.08, 0.03, 0.0008, -0.0005, -0.01,
        ],
    )?;
    let f = DVec3::new(0.3, 0.2, -1.0).normalize();
    let r = f.cross(DVec3::Y).normalize();
    let rot = DMat3::from_cols(r, f.cross(r), f);
    let pos = DVec3::new(0.2, -0.3, 0.4);
    println!(
        "{:>6} {:>10} {:>10} {:>10} {:>10}",
        "points", "PINHOLE", "OPENCV4", "OPENCV5", "OPENCV8"
    );
    for n in [50usize, 500, 5000] {
        let side = (n as f64 * 16.0 / 9.0).sqrt().ceil() as usize;
        let mut points = Vec::new();
        let mut k = 0u64;
        'outer: for j in 0..side {
            for i in 0..side {
                if points.len() == n {
                    break 'outer;
                }
                let q = [
                    20.0 + 1880.0 * (i as f64 + 0.5) / side as f64,
                    20.0 + 1040.0 * (j as f64 + 0.5) * 16.0 / 9.0 / side as f64,
                ];
                if q[1] > 1060.0 {
                    continue;
                }
                k = k.wrapping_mul(6364136223846793005).wrapping_add(1);
                let noise = ((k >> 40) as f64 / (1u64 << 24) as f64 - 0.5) * 0.6;
                if let Some(p) = truth
                    .unproject(q)
                    .ok()
                    .and_then(|ray| screen.intersect(pos, rot * ray).point())
                {
                    points.push(Correspondence {
                        pixel: [q[0] + noise, q[1] - noise],
                        world: p.to_array(),
                    });
                }
            }
        }
        let problem = Problem {
            resolution: [1920, 1080],
            points,
            lens: None,
            intrinsics_fixed: false,
        };
        let mut row = format!("{:>6}", problem.points.len());
        for model in [
            LensModel::Pinhole,
            LensModel::OpenCv(4),
            LensModel::OpenCv(5),
            LensModel::OpenCv(8),
        ] {
            let t = Instant::now();
            calibrate(&problem, ModelChoice::Fixed(model))
                .map_err(|e| anyhow::anyhow!("{}", reason(e)))?;
            row += &format!(" {:>8.1}ms", t.elapsed().as_secs_f64() * 1e3);
        }
        println!("{row}");
    }
    Ok(())
}
