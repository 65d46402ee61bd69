//! `omniwarp cubemap`: content resampled into a cube map in any layout.

use super::args::{ContentArgs, CubeLayoutArg, FilterArg, check_ext, filter};
use super::io::{AnyContent, AnyRaster, cube_faces, is_exr, load_content, write_cube};
use anyhow::Result;
use clap::Args;
use std::path::PathBuf;

#[derive(Args)]
pub struct CubemapArgs {
    #[command(flatten)]
    content: ContentArgs,
    /// Face size in pixels.
    #[arg(long)]
    face_size: u32,
    /// Output layout.
    #[arg(long, value_enum, default_value = "strip")]
    layout: CubeLayoutArg,
    /// Texture filter.
    #[arg(long, value_enum, default_value = "bilinear")]
    filter: FilterArg,
    /// K×K samples per texel.
    #[arg(long, default_value_t = 1)]
    supersample: u32,
    /// Output file (.png or .exr); for `--layout faces` a name with `{face}` in it.
    #[arg(long)]
    out: PathBuf,
}

pub fn run(a: CubemapArgs) -> Result<()> {
    check_ext(&a.out, &["png", "exr"])?;
    let (ss, f) = (a.supersample, filter(a.filter));
    match load_content(&a.content, is_exr(&a.out))? {
        AnyContent::U8(c) => write_cube(
            &cube_faces(&c, a.face_size, ss, f)?,
            a.layout,
            &a.out,
            AnyRaster::U8,
        ),
        AnyContent::F32(c) => write_cube(
            &cube_faces(&c, a.face_size, ss, f)?,
            a.layout,
            &a.out,
            AnyRaster::F32,
        ),
    }
}
