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
    /// Project and unproject throughput per model, points per second, one thread and all cores.
    Bench,
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
        LensCommand::Bench => return bench(),
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
        bail!("no input: give at least one point or pixel");
    }
    println!("{}", serde_json::to_string(&out)?);
    Ok(())
}

fn bench() -> Result<()> {
    use rayon::prelude::*;
    use std::time::Instant;
    let mut splined = vec![900.0, 905.0, 959.5, 539.5];
    splined.extend((0..384).map(|i| 0.002 * ((i % 7) as f64 - 3.0)));
    let models: [(&str, Vec<f64>); 11] = [
        ("LENSMODEL_PINHOLE", vec![1500.0, 1500.0, 959.5, 539.5]),
        (
            "LENSMODEL_OPENCV4",
            vec![1500.0, 1500.0, 959.5, 539.5, -0.2, 0.05, 1e-3, -1e-3],
        ),
        (
            "LENSMODEL_OPENCV5",
            vec![1500.0, 1500.0, 959.5, 539.5, -0.2, 0.05, 1e-3, -1e-3, 0.01],
        ),
        (
            "LENSMODEL_OPENCV8",
            vec![
                1500.0, 1500.0, 959.5, 539.5, -0.2, 0.05, 1e-3, -1e-3, 0.01, 0.02, -0.01, 0.005,
            ],
        ),
        (
            "LENSMODEL_OPENCV14",
            vec![
                1500.0, 1500.0, 959.5, 539.5, -0.2, 0.05, 1e-3, -1e-3, 0.01, 0.02, -0.01, 0.005,
                1e-3, -1e-4, 1e-3, -1e-4, 0.01, -0.01,
            ],
        ),
        (
            "LENSMODEL_OPENCV_FISHEYE",
            vec![600.0, 600.0, 959.5, 959.5, 0.02, -0.01, 0.002, -0.0005],
        ),
        ("LENSMODEL_STEREOGRAPHIC", vec![800.0, 800.0, 959.5, 539.5]),
        ("LENSMODEL_LONLAT", vec![600.0, 600.0, 959.5, 539.5]),
        ("LENSMODEL_LATLON", vec![600.0, 600.0, 959.5, 539.5]),
        (
            "LENSMODEL_CAHVOR",
            vec![
                1200.0, 1190.0, 959.5, 539.5, 0.01, -0.02, -0.05, 0.02, -0.003,
            ],
        ),
        (
            "LENSMODEL_SPLINED_STEREOGRAPHIC_order=3_Nx=16_Ny=12_fov_x_deg=120",
            splined,
        ),
    ];
    let n = 100_000;
    println!("{n} points per model; points per second (millions)");
    println!(
        "{:<26} {:>10} {:>10} {:>10} {:>10}",
        "model", "proj 1T", "proj all", "unproj 1T", "unproj all"
    );
    // The splined model's name carries its configuration; the table shows the family.
    let short = |name: &str| name.split("_order").next().unwrap_or(name).to_string();
    for (name, intrinsics) in models {
        let lens = Lens::new(name.parse()?, intrinsics)?;
        // Pixels over the image, unprojected once to get points the model can take.
        let pixels: Vec<[f64; 2]> = (0..n)
            .map(|i| [(i % 1920) as f64, ((i / 1920) % 1080) as f64])
            .collect();
        let rays: Vec<DVec3> = pixels
            .iter()
            .filter_map(|q| lens.unproject(*q).ok())
            .collect();
        let rate = |f: &dyn Fn() -> usize| {
            let t = Instant::now();
            let k = f();
            k as f64 / t.elapsed().as_secs_f64() / 1e6
        };
        let p1 = rate(&|| rays.iter().filter(|r| lens.project(**r).is_ok()).count());
        let pn = rate(&|| {
            rays.par_iter()
                .filter(|r| lens.project(**r).is_ok())
                .count()
        });
        let u1 = rate(&|| {
            pixels
                .iter()
                .filter(|q| lens.unproject(**q).is_ok())
                .count()
                .max(1)
        });
        let un = rate(&|| {
            pixels
                .par_iter()
                .filter(|q| lens.unproject(**q).is_ok())
                .count()
                .max(1)
        });
        println!(
            "{:<26} {p1:>10.2} {pn:>10.2} {u1:>10.2} {un:>10.2}",
            short(name)
        );
    }
    Ok(())
}
