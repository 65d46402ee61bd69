//! `omniwarp warp`: a rig channel's warp map (and optionally its wall points) as EXR.

use super::io::{channel, read_rig};
use anyhow::{Context, Result};
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
    #[arg(long, required_unless_present = "out_dir", conflicts_with = "out_dir")]
    channel: Option<String>,
    /// Warp map (EXR): R,G,B = content sampling vector, A = 1 where the pixel lights the wall.
    #[arg(long, required_unless_present = "out_dir", conflicts_with = "out_dir")]
    out: Option<PathBuf>,
    /// Instead of --channel and --out: every channel of the rig, its warp map as `<id>.exr`
    /// and its blend mask as `<id>-blend.png` (16-bit, gamma 2.2, as `omniwarp blend`) in this
    /// folder, with the progress on a terminal.
    #[arg(long, conflicts_with = "wall")]
    out_dir: Option<PathBuf>,
    /// Also write the wall point of every pixel (EXR, metres; A = validity).
    #[arg(long)]
    wall: Option<PathBuf>,
    /// Store half floats.
    #[arg(long)]
    half: bool,
}

pub fn run(a: WarpArgs) -> Result<()> {
    let rig = read_rig(&a.rig)?;
    if let Some(dir) = &a.out_dir {
        return whole_rig(&rig, dir, a.half);
    }
    let ch = channel(&rig, a.channel.as_deref().expect("clap requires it"))?;
    let out = a.out.as_ref().expect("clap requires it");
    for path in std::iter::once(out).chain(&a.wall) {
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
    w.map.write(out, precision)?;
    if let Some(path) = &a.wall {
        image_io::write_exr_rgba(path, &w.wall(), &w.map.attributes, precision)?;
    }
    Ok(())
}

/// Every channel's warp and blend into `dir`, channel by channel (each warp is parallel
/// already), the progress redrawn on one line of a terminal, a line a channel otherwise.
fn whole_rig(rig: &omniwarp::rig::Rig, dir: &std::path::Path, half: bool) -> Result<()> {
    use std::io::IsTerminal;
    std::fs::create_dir_all(dir).with_context(|| format!("--out-dir {}", dir.display()))?;
    let precision = if half {
        Precision::Half
    } else {
        Precision::Float
    };
    let terminal = std::io::stderr().is_terminal();
    let (n, start) = (rig.channels.len(), Instant::now());
    for (k, ch) in rig.channels.iter().enumerate() {
        let w = rig.warp(ch);
        w.map
            .write(&dir.join(format!("{}.exr", ch.id)), precision)?;
        let weights = rig.blend_weights(ch, &w.points);
        omniwarp::rig::write_blend_png(
            &dir.join(format!("{}-blend.png", ch.id)),
            ch.width,
            ch.height,
            &weights,
            omniwarp::rig::BlendOptions::default(),
        )?;
        let done = k + 1;
        let spent = start.elapsed().as_secs_f64();
        let left = spent / done as f64 * (n - done) as f64;
        if terminal {
            let bar: String = (0..20)
                .map(|i| if i * n < 20 * done { '#' } else { '.' })
                .collect();
            eprint!("\r[{bar}] {done}/{n} channels, {spent:.1} s, about {left:.0} s left   ");
        } else {
            eprintln!(
                "{}: warp and blend written ({done}/{n}, {spent:.1} s)",
                ch.id
            );
        }
    }
    if terminal {
        eprintln!();
    }
    outln!(
        "{n} warps and blends in {:.1} s → {}",
        start.elapsed().as_secs_f64(),
        dir.display()
    );
    Ok(())
}
