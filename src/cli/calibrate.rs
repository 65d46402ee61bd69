//! `omniwarp calibrate`: measured correspondences in, a rig channel out.

use super::args::named;
use anyhow::{Context, Result};
use clap::Args;
use omniwarp::calibration::{CorrespondencesDoc, calibrate};
use std::path::PathBuf;

#[derive(Args)]
pub struct CalibrateArgs {
    /// Correspondences (JSON, the same document the daemon's calibration route takes):
    /// {"resolution": [W, H], "points": [{"pixel": [u, v], "world": [x, y, z]}, …], and
    /// optionally "lens": {"model": …, "intrinsics": […]} (known intrinsics or a seed),
    /// "model", "intrinsics_fixed"}. Pixels count from the centre of the top-left pixel; world
    /// in metres. Example: calibration/examples/points.json.
    #[arg(long)]
    correspondences: PathBuf,
    /// Lens model: `auto` (PINHOLE → OPENCV4 → 5 → 8 while held-out residuals improve) or a
    /// model name; overrides the file's "model" (default auto).
    #[arg(long)]
    model: Option<String>,
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

pub fn run(a: CalibrateArgs) -> Result<()> {
    let text = std::fs::read_to_string(&a.correspondences)
        .with_context(|| format!("--correspondences {}", a.correspondences.display()))?;
    let de = &mut serde_json::Deserializer::from_str(&text);
    let input: CorrespondencesDoc = serde_path_to_error::deserialize(de).map_err(|e| {
        anyhow::anyhow!(
            "--correspondences: {}: {}",
            omniwarp::rig::pointer_of(&e.path().to_string()),
            e.inner()
        )
    })?;
    let resolution = input.resolution.context(
        "--correspondences: /resolution: needed: the projector's [width, height] in pixels",
    )?;
    if let Some(m) = a.model.as_deref().filter(|m| *m != "auto") {
        m.parse::<omniwarp::lens::LensModel>()
            .map_err(|e| anyhow::anyhow!("--model: {}", e.reason()))?;
    }
    if a.intrinsics_fixed && input.lens.is_none() {
        anyhow::bail!("--intrinsics-fixed: the correspondences file gives no lens to keep");
    }
    let mut input = input;
    input.intrinsics_fixed |= a.intrinsics_fixed;
    let (problem, choice) = input
        .problem(resolution, a.model.as_deref())
        .map_err(|e| anyhow::anyhow!("--correspondences: {}", named(e)))?;
    let cal = calibrate(&problem, choice)
        .map_err(|e| anyhow::anyhow!("--correspondences: {}", named(e)))?;
    let fit = &cal.fit;
    for c in &cal.considered {
        match c.held_out_rms {
            Some(h) => eprintln!(
                "{}: RMS {:.4} px, held-out {h:.4} px — {}",
                c.model, c.rms, c.verdict
            ),
            None => eprintln!("{}: RMS {:.4} px — {}", c.model, c.rms, c.verdict),
        }
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
    let doc = cal.channel_doc(&a.id, resolution);
    let json = serde_json::to_string_pretty(&doc)?;
    omniwarp::image_io::atomic_write(&a.out, |f| {
        use std::io::Write;
        f.write_all(json.as_bytes())
            .map_err(|e| omniwarp::Error::file(&a.out, e))
    })?;
    Ok(())
}
