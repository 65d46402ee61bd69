//! `omniwarp calibrate`: measured correspondences in, a rig channel out.

use super::args::named;
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
                .map_err(|e| anyhow::anyhow!("--correspondences: lens.{}", named(e)))?;
            Some(
                Lens::new(model, l.intrinsics.clone())
                    .map_err(|e| anyhow::anyhow!("--correspondences: lens.{}", named(e)))?,
            )
        }
        None => None,
    };
    let choice = match a.model.as_str() {
        "auto" => ModelChoice::Auto,
        m => ModelChoice::Fixed(
            m.parse()
                .map_err(|e| anyhow::anyhow!("--model: {}", named(e)))?,
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
        .map_err(|e| anyhow::anyhow!("--correspondences: {}", named(e)))?;
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
