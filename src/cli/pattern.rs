//! `omniwarp pattern`: procedural test patterns as equirect images or cube maps.

use super::args::{CubeLayoutArg, check_ext, parse_size};
use super::io::{AnyRaster, write_cube, write_output};
use anyhow::{Result, bail};
use clap::{Args, ValueEnum};
use omniwarp::content::pattern::Pattern;
use omniwarp::cubemap::CubeMap;
use std::path::PathBuf;

#[derive(Clone, Copy, ValueEnum)]
pub enum PatternArg {
    /// Smooth, band-limited, chiral: for comparing resamplers.
    Smooth,
    /// Sharp 10° checkerboard with red meridian lines every 30°.
    Checker,
}

#[derive(Args)]
pub struct PatternArgs {
    #[arg(long, value_enum, default_value = "smooth")]
    pattern: PatternArg,
    /// Equirect size WxH, or a cube map's face size as N (with --layout).
    #[arg(long, value_parser = parse_size)]
    size: (u32, u32),
    /// Write a cube map in this layout instead of an equirectangular image.
    #[arg(long, value_enum)]
    layout: Option<CubeLayoutArg>,
    /// Samples per pixel along each axis (anti-aliasing).
    #[arg(long, default_value_t = 4)]
    supersample: u32,
    /// Lay the equirect image out as ffmpeg's v360 reads it: the centres of the edge columns
    /// and rows at ±180° and ±90° (docs/conventions.md puts the image's outer edges there).
    #[arg(long, conflicts_with = "layout")]
    ffmpeg_equirect: bool,
    /// Output file (.png or .exr).
    #[arg(long)]
    out: PathBuf,
}

pub fn run(a: PatternArgs) -> Result<()> {
    check_ext(&a.out, &["png", "exr"])?;
    let pattern = match a.pattern {
        PatternArg::Smooth => Pattern::Smooth,
        PatternArg::Checker => Pattern::Checker,
    };
    if !(1..=16).contains(&a.supersample) {
        bail!(
            "--supersample: must be between 1 and 16, got {}",
            a.supersample
        );
    }
    let ss = a.supersample as usize;
    match a.layout {
        None => {
            let (w, h) = a.size;
            let img = pattern.equirect(w as usize, h as usize, ss, a.ffmpeg_equirect);
            write_output(&a.out, AnyRaster::F32(img), &[])
        }
        Some(layout) => {
            if a.size.0 != a.size.1 {
                bail!("--size: a cube map takes one face size N");
            }
            let cube = CubeMap::from_fn(a.size.0 as usize, ss, |d| pattern.eval(d));
            write_cube(&cube, layout, &a.out, AnyRaster::F32)
        }
    }
}
