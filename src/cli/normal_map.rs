//! `omniwarp normal-map`: a projection's per-pixel sampling vectors as float EXR.

use super::args::{ProjectionArgs, check_ext, parse_size};
use anyhow::Result;
use clap::Args;
use omniwarp::image_io::Precision;
use omniwarp::normalmap::NormalMap;
use std::path::PathBuf;

#[derive(Args)]
pub struct NormalMapArgs {
    #[command(flatten)]
    projection: ProjectionArgs,
    /// Output size WxH in pixels.
    #[arg(long, value_parser = parse_size)]
    size: (u32, u32),
    /// Store half floats (a third of the size, up to ~0.03° of error) instead of 32-bit.
    #[arg(long)]
    half: bool,
    /// Output file (.exr).
    #[arg(long)]
    out: PathBuf,
}

pub fn run(a: NormalMapArgs) -> Result<()> {
    let (w, h) = a.size;
    check_ext(&a.out, &["exr"])?;
    let view = a.projection.view(w, h)?;
    let map = NormalMap::from_view(&view, w, h)?;
    let precision = if a.half {
        Precision::Half
    } else {
        Precision::Float
    };
    map.write(&a.out, precision)?;
    Ok(())
}
