//! `omniwarp tiles …`: projection tile screens from the command line.

use super::args::{ProjectionArgs, flag_error, parse_size};
use super::io::{print_report, read_tiles};
use anyhow::{Result, bail};
use clap::{Args, Subcommand};
use omniwarp::image_io::{self, Precision};
use omniwarp::tiles::adapt::{Tolerance, choose, exact, measure};
use omniwarp::tiles::build::from_source;
use std::path::PathBuf;

// Parsed once per run; boxing the larger variant would buy nothing.
#[allow(clippy::large_enum_variant)]
#[derive(Subcommand)]
pub enum TilesCommand {
    /// Sample a projection into a tile screen: a fixed grid, or the coarsest grid within a
    /// tolerance.
    FromProjection(FromProjectionArgs),
    /// Rasterise a tile screen into a normal map (float EXR).
    NormalMap(NormalMapArgs),
}

#[derive(Args)]
pub struct FromProjectionArgs {
    #[command(flatten)]
    projection: ProjectionArgs,
    /// The output size WxH the screen is for (sets the aspect ratio and where the error is
    /// measured).
    #[arg(long, value_parser = parse_size)]
    size: (u32, u32),
    /// A fixed grid: MxN features (columns × rows).
    #[arg(long, value_parser = parse_size, conflicts_with_all = ["tolerance_deg", "tolerance_px"])]
    grid: Option<(u32, u32)>,
    /// The coarsest grid whose largest error is within this many degrees.
    #[arg(long, conflicts_with = "tolerance_px", allow_hyphen_values = true)]
    tolerance_deg: Option<f64>,
    /// The coarsest grid whose largest error is within this many output pixels.
    #[arg(long, allow_hyphen_values = true)]
    tolerance_px: Option<f64>,
    /// Output tile screen (JSON).
    #[arg(long)]
    out: PathBuf,
}

#[derive(Args)]
pub struct NormalMapArgs {
    /// Tile screen (JSON).
    tiles: PathBuf,
    /// Output size WxH in pixels.
    #[arg(long, value_parser = parse_size)]
    size: (u32, u32),
    /// Store half floats instead of 32-bit.
    #[arg(long)]
    half: bool,
    /// Output file (.exr).
    #[arg(long)]
    out: PathBuf,
}

pub fn run(cmd: TilesCommand) -> Result<()> {
    match cmd {
        TilesCommand::FromProjection(a) => {
            let (w, h) = (a.size.0 as usize, a.size.1 as usize);
            let source = a.projection.source(a.size.0, a.size.1)?;
            let tolerance = match (a.tolerance_deg, a.tolerance_px) {
                (Some(d), _) => Some(Tolerance::Degrees(d)),
                (None, Some(p)) => Some(Tolerance::Pixels(p)),
                (None, None) => None,
            };
            let (screen, report) = match (a.grid, tolerance) {
                (Some((c, r)), None) => {
                    let screen =
                        from_source(&source, c as usize, r as usize).map_err(flag_error)?;
                    let report = measure(&screen, &exact(&source.view()?, w, h), w, h);
                    (screen, report)
                }
                (None, Some(t)) => choose(&source, w, h, t).map_err(|e| match (e, t) {
                    (omniwarp::Error::Invalid { reason, .. }, Tolerance::Degrees(_)) => {
                        anyhow::anyhow!("--tolerance-deg: {reason}")
                    }
                    (omniwarp::Error::Invalid { reason, .. }, Tolerance::Pixels(_)) => {
                        anyhow::anyhow!("--tolerance-px: {reason}")
                    }
                    (other, _) => other.into(),
                })?,
                _ => bail!("--grid: give --grid MxN, --tolerance-deg or --tolerance-px"),
            };
            print_report("", &report)?;
            let json = screen.to_json();
            image_io::atomic_write(&a.out, |f| {
                use std::io::Write;
                f.write_all(json.as_bytes())
                    .map_err(|e| omniwarp::Error::file(&a.out, e))
            })?;
            Ok(())
        }
        TilesCommand::NormalMap(a) => {
            let screen = read_tiles(&a.tiles)?;
            if !a
                .out
                .extension()
                .is_some_and(|e| e.eq_ignore_ascii_case("exr"))
            {
                bail!("--out: {} must end in .exr", a.out.display());
            }
            let map = screen
                .feature_map(a.size.0 as usize, a.size.1 as usize)
                .normal_map();
            let precision = if a.half {
                Precision::Half
            } else {
                Precision::Float
            };
            map.write(&a.out, precision)?;
            Ok(())
        }
    }
}
