//! `omniwarp warp`: a rig channel's warp map (and optionally its wall points) as EXR.

use super::io::{channel, read_rig};
use anyhow::Result;
use clap::Args;
use omniwarp::image_io::{self, Precision};
use std::path::PathBuf;
use std::time::Instant;

#[derive(Args)]
pub struct WarpArgs {
    /// Rig file (JSON).
    #[arg(long)]
    rig: PathBuf,
    /// Channel id.
    #[arg(long)]
    channel: String,
    /// Warp map (EXR): R,G,B = content sampling vector, A = 1 where the pixel lights the wall.
    #[arg(long)]
    out: PathBuf,
    /// Also write the wall point of every pixel (EXR, metres; A = validity).
    #[arg(long)]
    wall: Option<PathBuf>,
    /// Store half floats.
    #[arg(long)]
    half: bool,
}

pub fn run(a: WarpArgs) -> Result<()> {
    let rig = read_rig(&a.rig)?;
    let ch = channel(&rig, &a.channel)?;
    for path in std::iter::once(&a.out).chain(&a.wall) {
        if !path
            .extension()
            .is_some_and(|e| e.eq_ignore_ascii_case("exr"))
        {
            anyhow::bail!("--out: {} must end in .exr", path.display());
        }
    }
    let t = Instant::now();
    let w = rig.warp(ch);
    let ms = t.elapsed().as_secs_f64() * 1e3;
    let lit = w.points.iter().filter(|p| p.is_some()).count();
    eprintln!(
        "{}: {}×{} warp in {ms:.0} ms ({:.1} Mpixel/s), {:.1} % of pixels light the wall",
        ch.id,
        ch.width,
        ch.height,
        f64::from(ch.width) * f64::from(ch.height) / ms / 1e3,
        100.0 * lit as f64 / w.points.len() as f64
    );
    let precision = if a.half {
        Precision::Half
    } else {
        Precision::Float
    };
    w.map.write(&a.out, precision)?;
    if let Some(path) = &a.wall {
        image_io::write_exr_rgba(path, &w.wall(), &w.map.attributes, precision)?;
    }
    Ok(())
}
