//! `omniwarp lens …`: batch projection and unprojection as JSON, for scripts and checks.

use anyhow::{Context, Result, bail};
use clap::{Args, Subcommand};
use glam::DVec3;
use omniwarp::lens::{Lens, LensModel};
use std::io::Read;
use std::path::PathBuf;

#[derive(Subcommand)]
pub enum LensCommand {
    /// Camera-frame points (a JSON array of [x, y, z]; x right, y down, z forward) → a JSON array
    /// of pixels [u, v] (pixel centres at integers), `null` where a point has no pixel.
    Project(ProjectArgs),
    /// Pixels (a JSON array of [u, v]) → a JSON array of unit rays [x, y, z], `null` where a
    /// pixel does not unproject.
    Unproject(UnprojectArgs),
}

#[derive(Args)]
pub struct LensArgs {
    /// Lens model, mrcal's name: LENSMODEL_PINHOLE, LENSMODEL_OPENCV4/5/8/12/14,
    /// LENSMODEL_OPENCV_FISHEYE, LENSMODEL_STEREOGRAPHIC, LENSMODEL_LONLAT, LENSMODEL_LATLON,
    /// LENSMODEL_CAHVOR, LENSMODEL_SPLINED_STEREOGRAPHIC_order=O_Nx=NX_Ny=NY_fov_x_deg=F.
    #[arg(long)]
    model: String,
    /// Intrinsics fx,fy,cx,cy,… in pixels (then the model's distortion terms).
    #[arg(long, allow_hyphen_values = true)]
    intrinsics: String,
}

#[derive(Args)]
pub struct ProjectArgs {
    #[command(flatten)]
    lens: LensArgs,
    /// JSON file of points, or `-` for standard input (the default).
    #[arg(long, default_value = "-")]
    points: String,
}

#[derive(Args)]
pub struct UnprojectArgs {
    #[command(flatten)]
    lens: LensArgs,
    /// JSON file of pixels, or `-` for standard input (the default).
    #[arg(long, default_value = "-")]
    pixels: String,
}

impl LensArgs {
    fn lens(&self) -> Result<Lens> {
        let model: LensModel = self
            .model
            .parse()
            .map_err(|e: omniwarp::Error| anyhow::anyhow!("--model: {}", e.reason()))?;
        let intrinsics = self
            .intrinsics
            .split(',')
            .map(|v| v.trim().parse::<f64>())
            .collect::<Result<Vec<_>, _>>()
            .map_err(|e| anyhow::anyhow!("--intrinsics: expected comma-separated numbers: {e}"))?;
        Lens::new(model, intrinsics).map_err(|e| anyhow::anyhow!("--intrinsics: {}", e.reason()))
    }
}

fn read_input(flag: &str, source: &str) -> Result<String> {
    let mut text = String::new();
    if source == "-" {
        std::io::stdin()
            .read_to_string(&mut text)
            .with_context(|| format!("--{flag}: standard input"))?;
    } else {
        text = std::fs::read_to_string(PathBuf::from(source))
            .with_context(|| format!("--{flag}: {source}"))?;
    }
    Ok(text)
}

pub fn run(cmd: LensCommand) -> Result<()> {
    let out: Vec<Option<Vec<f64>>> = match cmd {
        LensCommand::Project(a) => {
            let lens = a.lens.lens()?;
            let points: Vec<[f64; 3]> = serde_json::from_str(&read_input("points", &a.points)?)
                .context("--points: expected a JSON array of [x, y, z]")?;
            points
                .iter()
                .map(|p| lens.project(DVec3::from_array(*p)).ok().map(|q| q.to_vec()))
                .collect()
        }
        LensCommand::Unproject(a) => {
            let lens = a.lens.lens()?;
            let pixels: Vec<[f64; 2]> = serde_json::from_str(&read_input("pixels", &a.pixels)?)
                .context("--pixels: expected a JSON array of [u, v]")?;
            pixels
                .iter()
                .map(|q| lens.unproject(*q).ok().map(|r| r.to_array().to_vec()))
                .collect()
        }
    };
    if out.is_empty() {
        bail!("--points/--pixels: no input; give at least one point or pixel");
    }
    outln!("{}", serde_json::to_string(&out)?);
    Ok(())
}
