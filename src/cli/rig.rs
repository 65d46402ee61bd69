//! `omniwarp rig …`: rig files as an integrator handles them before serving one.

use super::args::parse_size;
use super::io::{read_rig, write_json};
use anyhow::{Result, bail};
use clap::{Args, Subcommand, ValueEnum};
use glam::DVec3;
use std::path::PathBuf;

#[derive(Subcommand)]
pub enum RigCommand {
    /// Validate a rig file as the daemon would and print what each projector covers: the share
    /// of its pixels on the wall, the longitudes and latitudes it shows and its pixels per
    /// degree seen from the eye.
    Check(CheckArgs),
    /// Write a starting rig from a few figures: the wall, how many projectors of which
    /// resolution, and how much neighbours overlap. Pinhole lenses and poses aimed to share the
    /// wall evenly, for `rig check` to report on and calibration to replace.
    New(NewArgs),
}

#[derive(Clone, Copy, PartialEq, ValueEnum)]
enum Shape {
    /// A vertical cylinder around the eye (--radius, --height, --arc).
    Cylinder,
    /// A dome over the eye (--radius, --tilt): projectors in a ring and one at the zenith.
    Dome,
    /// A flat wall before the eye (--width, --height, --distance): projectors side by side.
    Plane,
}

#[derive(Args)]
pub struct NewArgs {
    /// The wall's shape.
    #[arg(long)]
    screen: Shape,
    /// Projectors, 1–64.
    #[arg(long, value_parser = clap::value_parser!(u32).range(1..=64))]
    projectors: u32,
    /// Each projector's resolution, WxH.
    #[arg(long, default_value = "1920x1080", value_parser = parse_size)]
    resolution: (u32, u32),
    /// How much each projector's field reaches into its neighbours', percent of its share.
    #[arg(long, default_value_t = 15.0)]
    overlap: f64,
    /// Cylinder or dome radius, metres.
    #[arg(long, default_value_t = 3.0)]
    radius: f64,
    /// Cylinder: the wall's bottom and top along the axis, metres from the eye, `LO,HI`; plane:
    /// its height in metres (the first figure).
    #[arg(long, value_delimiter = ',', allow_hyphen_values = true, default_values_t = [-1.0, 1.5])]
    height: Vec<f64>,
    /// Cylinder: the arc it spans, degrees `FROM,TO` (0 ahead, positive to the right).
    #[arg(long, value_delimiter = ',', allow_hyphen_values = true, default_values_t = [-135.0, 135.0])]
    arc: Vec<f64>,
    /// Dome: how far its zenith leans forward, degrees.
    #[arg(long, default_value_t = 0.0)]
    tilt: f64,
    /// Plane: its width, metres.
    #[arg(long, default_value_t = 6.0)]
    width: f64,
    /// Plane: its distance before the eye, metres.
    #[arg(long, default_value_t = 3.0)]
    distance: f64,
    /// Where to write the rig (JSON).
    #[arg(long)]
    out: PathBuf,
}

#[derive(Args)]
pub struct CheckArgs {
    /// The rig file (a mesh screen's OBJ is read relative to it).
    rig: PathBuf,
    /// Sample every STEP-th projector pixel each way.
    #[arg(long, default_value_t = 8, value_parser = clap::value_parser!(u32).range(1..=1024))]
    step: u32,
    /// Print JSON (one object per channel) instead of a table.
    #[arg(long)]
    json: bool,
}

pub fn run(c: RigCommand) -> Result<()> {
    match c {
        RigCommand::Check(a) => check(a),
        RigCommand::New(a) => new(a),
    }
}

/// A pinhole projector `id` at `position` looking along `look` with `up` roughly up, whose
/// image spans `hfov` degrees across.
fn projector(
    a: &NewArgs,
    id: &str,
    position: DVec3,
    look: DVec3,
    up: DVec3,
    hfov: f64,
) -> Result<serde_json::Value> {
    if !(hfov > 0.0 && hfov < 170.0) {
        bail!(
            "--projectors: each projector would need {hfov:.0}° of field, beyond a pinhole lens; \
             use more projectors or less --overlap"
        );
    }
    let (w, h) = a.resolution;
    let f = f64::from(w) / 2.0 / (hfov.to_radians() / 2.0).tan();
    let (cx, cy) = ((f64::from(w) - 1.0) / 2.0, (f64::from(h) - 1.0) / 2.0);
    let round = |v: DVec3| v.to_array().map(|c| (c * 1e6).round() / 1e6);
    Ok(serde_json::json!({
        "id": id,
        "resolution": [w, h],
        "lens": {"model": "LENSMODEL_PINHOLE", "intrinsics": [f, f, cx, cy]},
        "pose": {"position": round(position), "look_to": round(look), "look_up": round(up)}
    }))
}

/// A unit direction at longitude `phi` (0 ahead, −z; positive to the right) and latitude
/// `theta` (positive up), degrees.
fn direction(phi: f64, theta: f64) -> DVec3 {
    let (p, t) = (phi.to_radians(), theta.to_radians());
    DVec3::new(t.cos() * p.sin(), t.sin(), -t.cos() * p.cos())
}

fn new(a: NewArgs) -> Result<()> {
    let n = a.projectors;
    let grow = 1.0 + a.overlap / 100.0;
    if !(0.0..=100.0).contains(&a.overlap) {
        bail!("--overlap: must be 0 to 100 percent, got {}", a.overlap);
    }
    let up = DVec3::Y;
    let (screen, channels) = match a.screen {
        Shape::Cylinder => {
            let ([lo, hi], [from, to]) = (pair(&a.height, "--height")?, pair(&a.arc, "--arc")?);
            let share = (to - from) / f64::from(n);
            // Aimed at the middle of the wall's height as the eye sees it.
            let pitch = ((hi / a.radius).atan() + (lo / a.radius).atan()).to_degrees() / 2.0;
            let channels = (0..n)
                .map(|k| {
                    let yaw = from + (f64::from(k) + 0.5) * share;
                    projector(
                        &a,
                        &format!("p{}", k + 1),
                        DVec3::ZERO,
                        direction(yaw, pitch),
                        up,
                        share * grow,
                    )
                })
                .collect::<Result<Vec<_>>>()?;
            let screen = serde_json::json!({"kind": "cylinder", "radius": a.radius, "height": [lo, hi], "arc": [from, to]});
            (screen, channels)
        }
        Shape::Dome => {
            let screen = serde_json::json!({"kind": "dome", "radius": a.radius, "tilt": a.tilt});
            // The dome's frame: its zenith leaning forward by the tilt.
            let t = a.tilt.to_radians();
            let (zenith, front) = (
                DVec3::new(0.0, t.cos(), -t.sin()),
                DVec3::new(0.0, -t.sin(), -t.cos()),
            );
            let right = front.cross(zenith);
            let ring = if n >= 4 { n - 1 } else { n };
            let share = 360.0 / f64::from(ring);
            let elevation = if n >= 4 { 25.0f64 } else { 35.0 };
            let mut channels = (0..ring)
                .map(|k| {
                    let az = (f64::from(k) * share).to_radians();
                    let (el_s, el_c) = elevation.to_radians().sin_cos();
                    let look = el_c * (az.cos() * front + az.sin() * right) + el_s * zenith;
                    projector(
                        &a,
                        &format!("p{}", k + 1),
                        DVec3::ZERO,
                        look,
                        zenith,
                        share * grow,
                    )
                })
                .collect::<Result<Vec<_>>>()?;
            if n >= 4 {
                // The cap above the ring: from its top edge to the zenith and over.
                let cap = 2.0 * (90.0 - elevation) * grow;
                channels.push(projector(
                    &a,
                    &format!("p{n}"),
                    DVec3::ZERO,
                    zenith,
                    front,
                    cap.min(150.0),
                )?);
            }
            (screen, channels)
        }
        Shape::Plane => {
            let height = a.height.first().copied().unwrap_or(2.5).abs();
            let screen = serde_json::json!({"kind": "plane", "centre": [0.0, 0.0, -a.distance], "normal": [0, 0, 1], "width": a.width, "height": height});
            let share = a.width / f64::from(n);
            let hfov = 2.0 * (share * grow / 2.0 / a.distance).atan().to_degrees();
            let channels = (0..n)
                .map(|k| {
                    let x = -a.width / 2.0 + (f64::from(k) + 0.5) * share;
                    projector(
                        &a,
                        &format!("p{}", k + 1),
                        DVec3::new(x, 0.0, 0.0),
                        -DVec3::Z,
                        up,
                        hfov,
                    )
                })
                .collect::<Result<Vec<_>>>()?;
            (screen, channels)
        }
    };
    let doc =
        serde_json::json!({"format": 1, "screen": screen, "eye": [0, 0, 0], "channels": channels});
    // Refused here, with the field, rather than by whoever reads the file next.
    let rig = omniwarp::rig::RigDoc::parse(&doc.to_string())
        .and_then(omniwarp::rig::Rig::from_doc)
        .map_err(|e| anyhow::anyhow!("{}", super::args::named(e)))?;
    write_json(&a.out, &rig.doc)?;
    outln!(
        "wrote {} ({} projectors); see what they cover with `omniwarp rig check {}`",
        a.out.display(),
        n,
        a.out.display()
    );
    Ok(())
}

/// Two figures given as `A,B`, the first below the second.
fn pair(v: &[f64], flag: &str) -> Result<[f64; 2]> {
    match v {
        [a, b] if a < b && a.is_finite() && b.is_finite() => Ok([*a, *b]),
        _ => bail!("{flag}: give two numbers, the first below the second, e.g. -1,1.5"),
    }
}

fn check(a: CheckArgs) -> Result<()> {
    let rig = read_rig(&a.rig)?;
    let covered: Vec<_> = rig
        .channels
        .iter()
        .map(|ch| rig.coverage(ch, a.step))
        .collect();
    if a.json {
        outln!("{}", serde_json::to_string_pretty(&covered)?);
        return Ok(());
    }
    outln!(
        "{}: valid; {} channel(s), eye at {:?}",
        a.rig.display(),
        rig.channels.len(),
        rig.eye.to_array()
    );
    outln!(
        "{:<12} {:>11} {:>8} {:>20} {:>18} {:>22}",
        "channel",
        "resolution",
        "on wall",
        "longitude (°)",
        "latitude (°)",
        "px/° min/median/max"
    );
    let range = |r: Option<[f64; 2]>| r.map_or("—".into(), |[a, b]| format!("{a:.1} … {b:.1}"));
    for (ch, c) in rig.channels.iter().zip(&covered) {
        let density = c.pixels_per_degree.map_or("—".into(), |[a, b, m]| {
            format!("{a:.1} / {b:.1} / {m:.1}")
        });
        outln!(
            "{:<12} {:>11} {:>7.1}% {:>20} {:>18} {:>22}",
            ch.id,
            format!("{}×{}", ch.width, ch.height),
            100.0 * c.on_wall,
            range(c.longitude),
            range(c.latitude),
            density
        );
    }
    Ok(())
}
