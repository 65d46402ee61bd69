//! `omniwarp blend`: every channel's edge-blend mask as a gamma-encoded 16-bit PNG, and its
//! black-level mask when the rig's projectors have a contrast.

use super::io::read_rig;
use anyhow::{Context, Result};
use clap::Args;
use omniwarp::rig::{BlendOptions, write_black_png, write_blend_png};
use std::path::PathBuf;
use std::time::Instant;

#[derive(Args)]
pub struct BlendArgs {
    /// Rig file (JSON).
    #[arg(long)]
    rig: PathBuf,
    /// Directory for one 16-bit PNG per channel, `<id>.png`, and `<id>-black.png` with its
    /// black lift when the rig gives projector contrasts (docs/photometry.md).
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
    let gamma_error = |e| match e {
        omniwarp::Error::Invalid { reason, .. } => anyhow::anyhow!("--gamma: {reason}"),
        other => other.into(),
    };
    let target = rig.black_target();
    for ch in &rig.channels {
        let t = Instant::now();
        let w = rig.warp(ch);
        let weights = rig.blend_weights(ch, &w.points);
        let path = a.out_dir.join(format!("{}.png", ch.id));
        write_blend_png(&path, ch.width, ch.height, &weights, opts).map_err(gamma_error)?;
        if rig.has_black() {
            let lift = rig.black_lift(ch, &w.points, &weights, target);
            let path = a.out_dir.join(format!("{}-black.png", ch.id));
            write_black_png(&path, ch.width, ch.height, &lift, opts).map_err(gamma_error)?;
        }
        eprintln!(
            "{}: warp and blend in {:.0} ms → {}",
            ch.id,
            t.elapsed().as_secs_f64() * 1e3,
            path.display()
        );
    }
    Ok(())
}
