//! `omniwarp measure`: the wall's shape from two cameras filming one projector's sequence.
//! Each pair of camera pixels that decode to the same projector pixel gives a wall point where
//! their rays meet; the rig's kind of surface is fitted to those points.

use super::args::{named, read_camera};
use super::io::{channel, read_rig, write_json};
use anyhow::Result;
use clap::Args;
use omniwarp::structured::decode::{DecodeOptions, decode};
use omniwarp::structured::triangulate::{fit_screen, triangulate};
use omniwarp::structured::{PatternSet, read_captures};
use omniwarp::surface::Screen;
use std::path::PathBuf;

#[derive(Args)]
pub struct MeasureArgs {
    /// The rig: its channel's resolution, and the kind of wall fitted (dome: centre and
    /// radius; cylinder: axis and radius; plane: normal and offset) with its first guess.
    #[arg(long)]
    rig: PathBuf,
    /// The projector both cameras filmed.
    #[arg(long)]
    channel: String,
    /// The two capture folders (as `calibrate --captures` reads them), one per camera.
    #[arg(long, num_args = 2, value_names = ["A", "B"], required = true)]
    captures: Vec<PathBuf>,
    /// The two cameras (rig channel documents, poses known), in --captures' order.
    #[arg(long, num_args = 2, value_names = ["A", "B"], required = true)]
    camera: Vec<PathBuf>,
    /// Use every n-th decoded pixel of the first camera, each way.
    #[arg(long, default_value_t = 2, value_parser = clap::value_parser!(u32).range(1..=64))]
    step: u32,
    /// Leave out pixel pairs whose rays pass further apart than this, metres.
    #[arg(long, default_value_t = 0.01)]
    gap: f64,
    /// The phase period the patterns were shown with, projector pixels.
    #[arg(long, default_value_t = 16)]
    period: u32,
    /// The code the patterns were shown with: gray or xor.
    #[arg(long, default_value = "gray", value_parser = super::args::parse_code)]
    code: omniwarp::structured::Code,
    /// Write the rig with the fitted wall here (JSON).
    #[arg(long)]
    out: Option<PathBuf>,
}

pub fn run(a: MeasureArgs) -> Result<()> {
    if !(a.gap.is_finite() && a.gap > 0.0 && a.gap <= 1.0) {
        anyhow::bail!("--gap: must lie within 0–1 m, got {}", a.gap);
    }
    let rig = read_rig(&a.rig)?;
    let projector = channel(&rig, &a.channel)?;
    let set = PatternSet::new(projector.width, projector.height)?
        .with_period(a.period)
        .map_err(|e| anyhow::anyhow!("--{}", named(e)))?
        .with_code(a.code);
    let mut views = Vec::new();
    for (dir, camera) in a.captures.iter().zip(&a.camera) {
        let camera = read_camera(camera)?;
        let frames = read_captures(dir)
            .map_err(|e| anyhow::anyhow!("--captures {}: {}", dir.display(), named(e)))?;
        if let Some(f) = frames.first()
            && (f.width, f.height) != (camera.width, camera.height)
        {
            anyhow::bail!(
                "--captures {}: are {}×{}, the camera {}×{}",
                dir.display(),
                f.width,
                f.height,
                camera.width,
                camera.height
            );
        }
        let decoded = decode(&set, &frames, &DecodeOptions::default())
            .map_err(|e| anyhow::anyhow!("--captures {}: {}", dir.display(), named(e)))?;
        eprintln!(
            "{}: decoded {} camera pixels",
            dir.display(),
            decoded.valid()
        );
        views.push((decoded, camera));
    }
    let points = triangulate(
        (&views[0].0, &views[0].1),
        (&views[1].0, &views[1].1),
        [projector.width, projector.height],
        a.step,
        a.gap,
    );
    let fit = fit_screen(&rig.doc.screen, &points).map_err(|e| anyhow::anyhow!("{}", named(e)))?;
    outln!(
        "{} wall points ({} outliers left out): RMS {:.3} mm, max {:.3} mm off the fitted wall",
        fit.count,
        fit.outliers,
        fit.rms * 1e3,
        fit.max * 1e3
    );
    outln!("rig:    {}", describe(&rig.doc.screen));
    outln!("fitted: {}", describe(&fit.screen));
    if let Some(out) = &a.out {
        let mut doc = rig.doc.clone();
        doc.screen = fit.screen;
        write_json(out, &doc)?;
    }
    Ok(())
}

/// The parameters a measurement can change, in a line.
fn describe(screen: &Screen) -> String {
    let v = |a: [f64; 3]| format!("[{:.4}, {:.4}, {:.4}]", a[0], a[1], a[2]);
    match screen {
        Screen::Dome(d) => format!("dome radius {:.5} m, centre {}", d.radius, v(d.centre)),
        Screen::Cylinder(c) => format!(
            "cylinder radius {:.5} m, axis {}, centre {}",
            c.radius,
            v(c.axis),
            v(c.centre)
        ),
        Screen::Plane(p) => format!("plane normal {}, centre {}", v(p.normal), v(p.centre)),
        Screen::Mesh { obj, .. } => format!("mesh {obj}"),
    }
}
