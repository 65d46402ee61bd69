//! `omniwarp blend`: every channel's edge-blend mask as a gamma-encoded 16-bit PNG.

use super::io::read_rig;
use anyhow::{Context, Result};
use clap::Args;
use omniwarp::rig::{BlendOptions, write_blend_png};
use std::path::PathBuf;
use std::time::Instant;

#[derive(Args)]
pub struct BlendArgs {
    /// Rig file (JSON).
    #[arg(long)]
    rig: PathBuf,
    /// Directory for one 16-bit PNG per channel, `<id>.png`.
    #[arg(long)]
    out_dir: PathBuf,
    /// Projector gamma the masks are encoded for (m = w^(1/gamma)).
    #[arg(long, default_value_t = 2.2)]
    gamma: f64,
}

pub fn run(a: BlendArgs) -> Result<()> {
    let rig = read_rig(&a.rig)?;
    std::fs::create_dir_all(&a.out_dir)
        .with_context(|| format!("--out-dir {}", a.out_dir.display()))?;
    let opts = BlendOptions {
        gamma: a.gamma,
        ..BlendOptions::default()
    };
    for ch in &rig.channels {
        let t = Instant::now();
        let w = rig.warp(ch);
        let weights = rig.blend_weights(ch, &w.points);
        let path = a.out_dir.join(format!("{}.png", ch.id));
        write_blend_png(&path, ch.width, ch.height, &weights, opts).map_err(|e| match e {
            omniwarp::Error::Invalid { reason, .. } => anyhow::anyhow!("--gamma: {reason}"),
            other => other.into(),
        })?;
        eprintln!(
            "{}: warp and blend in {:.0} ms → {}",
            ch.id,
            t.elapsed().as_secs_f64() * 1e3,
            path.display()
        );
    }
    Ok(())
}
