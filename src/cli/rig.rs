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
    /// wall evenly, for `rig check` to report on and calibration to replace, and the show's
    /// canvas the wall is made for: a dome master, the cylinder unrolled, the flat wall's view.
    New(NewArgs),
    /// Plan a rig before hanging it: how much of the wall none, one, two or more projectors
    /// light, each overlap's width in degrees, pixel density from the eye, pixels wasted off
    /// the wall and brightness before blending; `--picture` draws it. Give a rig file, or
    /// `rig new`'s figures (then `--sweep` varies one of them).
    Plan(PlanArgs),
    /// Print the rig document's JSON Schema (the one published as api/rig.schema.json), for
    /// editors and other tools to check rig files with.
    Schema,
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
    #[command(flatten)]
    layout: Layout,
    /// Where to write the rig (JSON).
    #[arg(long)]
    out: PathBuf,
}

/// A starting rig's figures.
#[derive(Args, Clone)]
pub struct Layout {
    /// The wall's shape (required).
    #[arg(long)]
    screen: Option<Shape>,
    /// Projectors, 1–64 (required).
    #[arg(long, value_parser = clap::value_parser!(u32).range(1..=64))]
    projectors: Option<u32>,
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
}

#[derive(Args)]
pub struct PlanArgs {
    /// The rig file; or leave it out and give `rig new`'s figures (--screen …).
    rig: Option<PathBuf>,
    #[command(flatten)]
    layout: Layout,
    /// The sampling grid's step, degrees of longitude and latitude from the eye (0.25–5).
    #[arg(long, default_value_t = omniwarp::rig::plan::STEP)]
    step: f64,
    /// Draw the plan as a PNG: the wall unrolled (a dome as a dome master) coloured by pixel
    /// density with each footprint outlined, and the rig from above and from the side.
    #[arg(long)]
    picture: Option<PathBuf>,
    /// The picture's width in pixels (320–4096).
    #[arg(long, default_value_t = 1200)]
    picture_width: usize,
    /// Vary one of `rig new`'s figures and print the headline figures for each value:
    /// `NAME=FROM:TO:STEP`, NAME one of projectors, overlap, radius, tilt, width, distance.
    #[arg(long)]
    sweep: Option<String>,
    /// Print JSON instead of tables.
    #[arg(long)]
    json: bool,
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
        RigCommand::Plan(a) => plan(a),
        RigCommand::Schema => {
            outln!("{}", omniwarp::rig::schema::text().trim_end());
            Ok(())
        }
    }
}

/// A pinhole projector `id` at `position` looking along `look` with `up` roughly up, whose
/// image spans `hfov` degrees across.
fn projector(
    a: &Layout,
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

/// The starting rig the figures describe, validated.
fn generate(a: &Layout) -> Result<omniwarp::rig::Rig> {
    let (Some(shape), Some(n)) = (a.screen, a.projectors) else {
        bail!("a starting rig needs --screen and --projectors");
    };
    let grow = 1.0 + a.overlap / 100.0;
    if !(0.0..=100.0).contains(&a.overlap) {
        bail!("--overlap: must be 0 to 100 percent, got {}", a.overlap);
    }
    let up = DVec3::Y;
    let (screen, channels, canvas) = match shape {
        Shape::Cylinder => {
            let ([lo, hi], [from, to]) = (pair(&a.height, "--height")?, pair(&a.arc, "--arc")?);
            let share = (to - from) / f64::from(n);
            // Aimed at the middle of the wall's height as the eye sees it.
            let pitch = ((hi / a.radius).atan() + (lo / a.radius).atan()).to_degrees() / 2.0;
            let channels = (0..n)
                .map(|k| {
                    let yaw = from + (f64::from(k) + 0.5) * share;
                    projector(
                        a,
                        &format!("p{}", k + 1),
                        DVec3::ZERO,
                        direction(yaw, pitch),
                        up,
                        share * grow,
                    )
                })
                .collect::<Result<Vec<_>>>()?;
            let screen = serde_json::json!({"kind": "cylinder", "radius": a.radius, "height": [lo, hi], "arc": [from, to]});
            // The wall unrolled: the arc across, its height up, about 8K wide.
            let reach = lo.abs().max(hi.abs());
            let vfov = 2.0 * (reach / a.radius).atan().to_degrees();
            let tall = 2.0 * reach / ((to - from).to_radians() * a.radius);
            let canvas = serde_json::json!({"projection": "cylindrical",
                "params": {"hfov": to - from, "vfov": vfov},
                "look_to": direction((from + to) / 2.0, 0.0).to_array(),
                "size": [7680, ((7680.0 * tall).round() as u32).clamp(16, 7680)]});
            (screen, channels, canvas)
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
                        a,
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
                    a,
                    &format!("p{n}"),
                    DVec3::ZERO,
                    zenith,
                    front,
                    cap.min(150.0),
                )?);
            }
            // A dome master: the dome's zenith at its centre, the front at the bottom.
            let canvas = serde_json::json!({"projection": "fisheye", "params": {"fov": 180},
                "look_to": zenith.to_array(), "look_up": (-front).to_array(),
                "size": [4096, 4096]});
            (screen, channels, canvas)
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
                        a,
                        &format!("p{}", k + 1),
                        DVec3::new(x, 0.0, 0.0),
                        -DVec3::Z,
                        up,
                        hfov,
                    )
                })
                .collect::<Result<Vec<_>>>()?;
            let fov = |side: f64| 2.0 * (side / 2.0 / a.distance).atan().to_degrees();
            let canvas = serde_json::json!({"projection": "flat",
                "params": {"hfov": fov(a.width), "vfov": fov(height)},
                "size": [3840, ((3840.0 * height / a.width).round() as u32).clamp(16, 7680)]});
            (screen, channels, canvas)
        }
    };
    let doc = serde_json::json!({"format": 1, "screen": screen, "eye": [0, 0, 0],
        "channels": channels, "canvas": canvas});
    // Refused here, with the field, rather than by whoever reads the file next.
    omniwarp::rig::RigDoc::parse(&doc.to_string())
        .and_then(omniwarp::rig::Rig::from_doc)
        .map_err(|e| anyhow::anyhow!("{}", super::args::named(e)))
}

fn new(a: NewArgs) -> Result<()> {
    let rig = generate(&a.layout)?;
    write_json(&a.out, &rig.doc)?;
    outln!(
        "wrote {} ({} projectors); see what they cover with `omniwarp rig check {}`",
        a.out.display(),
        rig.channels.len(),
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

/// A `--sweep NAME=FROM:TO:STEP`: the figure's name and its values, FROM to TO inclusive.
fn sweep_values(spec: &str) -> Result<(String, Vec<f64>)> {
    const NAMES: [&str; 6] = [
        "projectors",
        "overlap",
        "radius",
        "tilt",
        "width",
        "distance",
    ];
    let bad = || {
        anyhow::anyhow!(
            "--sweep: give NAME=FROM:TO:STEP with NAME one of {}, e.g. tilt=10:30:5",
            NAMES.join(", ")
        )
    };
    let (name, range) = spec.split_once('=').ok_or_else(bad)?;
    if !NAMES.contains(&name) {
        return Err(bad());
    }
    let parts: Vec<f64> = range
        .split(':')
        .map(|v| v.trim().parse::<f64>())
        .collect::<std::result::Result<_, _>>()
        .map_err(|_| bad())?;
    let [from, to, step] = parts[..] else {
        return Err(bad());
    };
    if !(from.is_finite() && to.is_finite() && step > 0.0 && from <= to) {
        bail!("--sweep: FROM must not be above TO, and STEP must be above zero");
    }
    let count = ((to - from) / step + 1e-9).floor() as usize + 1;
    if count > 64 {
        bail!("--sweep: {count} values; at most 64 in one sweep");
    }
    Ok((
        name.to_string(),
        (0..count).map(|k| from + k as f64 * step).collect(),
    ))
}

fn set_figure(layout: &mut Layout, name: &str, v: f64) -> Result<()> {
    match name {
        "projectors" => {
            if !(1.0..=64.0).contains(&v) || v.fract() != 0.0 {
                bail!("--sweep: projectors must be whole numbers 1–64, got {v}");
            }
            layout.projectors = Some(v as u32);
        }
        "overlap" => layout.overlap = v,
        "radius" => layout.radius = v,
        "tilt" => layout.tilt = v,
        "width" => layout.width = v,
        _ => layout.distance = v,
    }
    Ok(())
}

fn plan(a: PlanArgs) -> Result<()> {
    omniwarp::rig::plan::check_step(a.step, "--step").map_err(|e| anyhow::anyhow!("{}", e))?;
    let figures = (a.layout.screen.is_some() || a.layout.projectors.is_some()).then_some(&a.layout);
    let rig = match (&a.rig, figures) {
        (Some(_), Some(_)) => {
            bail!("give a rig file or `rig new`'s figures (--screen …), not both")
        }
        (None, None) => bail!("give a rig file, or `rig new`'s figures (--screen …)"),
        (Some(path), None) => {
            if a.sweep.is_some() {
                bail!(
                    "--sweep varies a figure of `rig new`: give the rig as --screen … instead of a file"
                );
            }
            read_rig(path)?
        }
        (None, Some(layout)) => generate(layout)?,
    };
    if let Some(spec) = &a.sweep {
        let (name, values) = sweep_values(spec)?;
        let mut layout = a.layout.clone();
        let mut rows = Vec::new();
        for v in values {
            set_figure(&mut layout, &name, v)?;
            let rig = generate(&layout).map_err(|e| anyhow::anyhow!("{name}={v}: {e}"))?;
            rows.push((v, rig.plan(a.step)?));
        }
        if a.json {
            let out: Vec<_> = rows
                .iter()
                .map(|(v, p)| serde_json::json!({"value": v, "plan": p}))
                .collect();
            outln!(
                "{}",
                serde_json::to_string_pretty(&serde_json::json!({"figure": name, "values": out}))?
            );
            return Ok(());
        }
        outln!(
            "{:>12} {:>8} {:>8} {:>8} {:>8} {:>14} {:>10} {:>16}",
            name,
            "unlit",
            "one",
            "two",
            "3+",
            "px/° min/med",
            "wasted",
            "narrowest overlap"
        );
        for (v, p) in &rows {
            let [none, one, two, more] = p.wall.lit_by.map(|s| format!("{:.1}%", 100.0 * s));
            let density = p
                .wall
                .pixels_per_degree
                .map_or("—".into(), |[lo, med, _]| format!("{lo:.1} / {med:.1}"));
            outln!(
                "{:>12} {none:>8} {one:>8} {two:>8} {more:>8} {density:>14} {:>9.1}% {:>16}",
                format!("{v}"),
                100.0 * wasted_share(p),
                narrowest(p).map_or("—".into(), |w| format!("{w:.1}°"))
            );
        }
        return Ok(());
    }
    let plan = rig.plan(a.step)?;
    if let Some(path) = &a.picture {
        let img = plan
            .picture(&rig, a.picture_width)
            .map_err(|e| anyhow::anyhow!("invalid `--picture-width`: {}", e.reason()))?;
        omniwarp::image_io::write_png(path, &img)?;
    }
    if a.json {
        outln!("{}", serde_json::to_string_pretty(&plan)?);
        return Ok(());
    }
    print_plan(&plan)?;
    if let Some(path) = &a.picture {
        outln!("wrote {}", path.display());
    }
    Ok(())
}

/// Share of all the rig's pixels that light nothing.
fn wasted_share(p: &omniwarp::rig::Plan) -> f64 {
    let wasted: u64 = p.channels.iter().map(|c| c.wasted_pixels).sum();
    let total: f64 = p
        .channels
        .iter()
        .map(|c| c.wasted_pixels as f64 / (1.0 - c.on_wall).max(1e-12))
        .zip(&p.channels)
        .map(|(t, c)| if c.on_wall >= 1.0 { 0.0 } else { t })
        .sum();
    if total > 0.0 {
        wasted as f64 / total
    } else {
        0.0
    }
}

fn narrowest(p: &omniwarp::rig::Plan) -> Option<f64> {
    p.overlaps.iter().map(|o| o.width).min_by(f64::total_cmp)
}

fn print_plan(p: &omniwarp::rig::Plan) -> Result<()> {
    let w = &p.wall;
    let [none, one, two, more] = w.lit_by.map(|s| 100.0 * s);
    outln!(
        "wall: {:.2} m² seen from the eye ({:.2} sr); lit by no projector {none:.1}%, one \
         {one:.1}%, two {two:.1}%, three or more {more:.1}%",
        w.area,
        w.solid_angle
    );
    if let Some([lo, med, hi]) = w.pixels_per_degree {
        outln!(
            "pixel density from the eye: {lo:.1} / {med:.1} / {hi:.1} px/° (least / median / most)"
        );
    }
    if let Some([lo, med, hi]) = w.brightness {
        outln!(
            "brightness before blending: {lo:.2} / {med:.2} / {hi:.2} × a single projector's median"
        );
    }
    outln!(
        "\n{:<12} {:>8} {:>12} {:>10} {:>22} {:>14}",
        "channel",
        "on wall",
        "wasted px",
        "wall share",
        "px/° min/median/max",
        "brightness"
    );
    for c in &p.channels {
        let density = c.pixels_per_degree.map_or("—".into(), |[a, b, m]| {
            format!("{a:.1} / {b:.1} / {m:.1}")
        });
        let bright = c
            .brightness
            .map_or("—".into(), |[a, b]| format!("{a:.2} … {b:.2}"));
        outln!(
            "{:<12} {:>7.1}% {:>12} {:>9.1}% {density:>22} {bright:>14}",
            c.id,
            100.0 * c.on_wall,
            c.wasted_pixels,
            100.0 * c.wall_share
        );
    }
    if p.overlaps.is_empty() {
        outln!("\nno two projectors light the same wall: nothing to blend");
        return Ok(());
    }
    outln!(
        "\n{:<24} {:>8} {:>10} {:>10} {:>20} {:>16}",
        "overlap (blend region)",
        "width",
        "across",
        "wall share",
        "longitude (°)",
        "latitude (°)"
    );
    for o in &p.overlaps {
        outln!(
            "{:<24} {:>7.1}° {:>10} {:>9.1}% {:>20} {:>16}",
            format!("{} + {}", o.channels[0], o.channels[1]),
            o.width,
            o.across,
            100.0 * o.wall_share,
            format!("{:.1} … {:.1}", o.longitude[0], o.longitude[1]),
            format!("{:.1} … {:.1}", o.latitude[0], o.latitude[1])
        );
    }
    Ok(())
}
