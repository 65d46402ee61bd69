//! `omniwarp calibrate`: measured correspondences in, a rig channel out.

use super::args::{named, read_camera};
use super::io::write_json;
use anyhow::{Context, Result};
use clap::Args;
use omniwarp::calibration::{CorrespondencesDoc, ModelChoice, calibrate};
use std::path::PathBuf;

#[derive(Args)]
pub struct CalibrateArgs {
    /// Correspondences (JSON, the same document the daemon's calibration route takes):
    /// {"resolution": [W, H], "points": [{"pixel": [u, v], "world": [x, y, z]}, …], and
    /// optionally "lens": {"model": …, "intrinsics": […]} (known intrinsics or a seed),
    /// "model", "intrinsics_fixed"}. Pixels count from the centre of the top-left pixel; world
    /// in metres. Example: calibration/examples/points.json.
    #[arg(
        long,
        required_unless_present_any = ["captures", "rig_captures"],
        conflicts_with_all = ["captures", "rig_captures"]
    )]
    correspondences: Option<PathBuf>,
    /// Instead of --correspondences: a folder of camera captures of the structured-light
    /// sequence (PNG or JPEG, in name order: white, black, then per axis x and y the Gray bits
    /// each with its inverse and 12 phase steps; `omniwarp simulate` writes one from its
    /// virtual camera).
    /// Needs --camera, --rig and --channel.
    #[arg(long, requires_all = ["camera", "rig", "channel"])]
    captures: Option<PathBuf>,
    /// A whole rig in one command: a folder holding one capture folder per projector, each
    /// named by its channel id in --rig, all filmed by the one camera (--camera, posed once by
    /// its own pose, --markers or --pose-captures). Every projector found is calibrated and
    /// written into --rig together, or none is; the channels without a folder are kept.
    #[arg(
        long,
        requires_all = ["camera", "rig"],
        conflicts_with_all = ["captures", "channel", "check", "out", "update"]
    )]
    rig_captures: Option<PathBuf>,
    /// The camera that took the captures, as a rig channel (JSON), its pose known.
    #[arg(long)]
    camera: Option<PathBuf>,
    /// Markers that give the camera's pose instead of --camera's own (its lens is kept): JSON
    /// {"points": [{"pixel": [u, v], "world": [x, y, z]}, …]}, wall points of known position
    /// and the camera pixels where they appear; at least 4.
    #[arg(long, requires = "camera")]
    markers: Option<PathBuf>,
    /// Instead of --markers: captures of the sequence shown by another projector, one already
    /// calibrated in --rig (--pose-channel), filmed by the camera from where it now stands. The
    /// camera's pose is solved from them, its lens kept: what that projector decodes to at a
    /// camera pixel, followed to the wall, is a marker there.
    #[arg(long, requires_all = ["camera", "pose_channel"], conflicts_with = "markers")]
    pose_captures: Option<PathBuf>,
    /// The channel of --rig that --pose-captures show.
    #[arg(long, requires = "pose_captures")]
    pose_channel: Option<String>,
    /// The rig whose wall the camera looks at; with --update, the rig the projector is
    /// written into.
    #[arg(long)]
    rig: Option<PathBuf>,
    /// The projector's channel in --rig: its resolution, and the calibration --check compares
    /// with.
    #[arg(long)]
    channel: Option<String>,
    /// With --captures: instead of calibrating, compare the captures with the channel as the
    /// rig has it; write the per-pixel residuals here (EXR: R, G the residual in projector
    /// pixels, B its length, A = 1 where decoded) and say whether the projector moved.
    #[arg(long, requires = "captures")]
    check: Option<PathBuf>,
    /// The phase period the captures' patterns were shown with, projector pixels (with
    /// --captures; `simulate --period`).
    #[arg(long, default_value_t = 16)]
    period: u32,
    /// The code the captures' patterns were shown with: gray or xor (`simulate --code`).
    #[arg(long, default_value = "gray", value_parser = super::args::parse_code)]
    code: omniwarp::structured::Code,
    /// Decoded camera pixels used as correspondences, at most (with --captures).
    #[arg(long, default_value_t = 5000)]
    points: usize,
    /// Lens model: `auto` (PINHOLE → OPENCV4 → 5 → 8 while held-out residuals improve) or a
    /// model name; overrides the file's "model" (default auto).
    #[arg(long)]
    model: Option<String>,
    /// Keep the given lens's intrinsics and solve the pose only.
    #[arg(long)]
    intrinsics_fixed: bool,
    /// Channel id written into the result.
    #[arg(long, default_value = "projector")]
    id: String,
    /// The projector as a rig channel (JSON). With --check: the channel re-fitted from the
    /// same captures, written whatever the verdict.
    #[arg(long, required_unless_present_any = ["check", "update", "rig_captures"])]
    out: Option<PathBuf>,
    /// Instead of --out: put the calibrated projector into --rig as its channel --channel (the
    /// file rewritten atomically, every other field kept), and print how it moved.
    #[arg(long, requires_all = ["rig", "channel"], conflicts_with_all = ["out", "check"])]
    update: bool,
}

pub fn run(a: CalibrateArgs) -> Result<()> {
    if let Some(dir) = &a.rig_captures {
        return whole_rig(&a, dir);
    }
    if let Some(dir) = &a.captures {
        return from_captures(&a, dir);
    }
    let path = a.correspondences.as_ref().expect("clap requires one");
    let input = read_points(path, "--correspondences")?;
    let resolution = input.resolution.context(
        "--correspondences: /resolution: needed: the projector's [width, height] in pixels",
    )?;
    if let Some(m) = a.model.as_deref().filter(|m| *m != "auto") {
        m.parse::<omniwarp::lens::LensModel>()
            .map_err(|e| anyhow::anyhow!("--model: {}", e.reason()))?;
    }
    if a.intrinsics_fixed && input.lens.is_none() {
        anyhow::bail!("--intrinsics-fixed: the correspondences file gives no lens to keep");
    }
    let mut input = input;
    input.intrinsics_fixed |= a.intrinsics_fixed;
    let (problem, choice) = input
        .problem(resolution, a.model.as_deref())
        .map_err(|e| anyhow::anyhow!("--correspondences: {}", named(e)))?;
    let cal = calibrate(&problem, choice)
        .map_err(|e| anyhow::anyhow!("--correspondences: {}", named(e)))?;
    report(&cal, problem.points.len());
    place(&a, &cal, resolution)
}

fn report(cal: &omniwarp::calibration::Calibration, points: usize) {
    let fit = &cal.fit;
    for c in &cal.considered {
        match c.held_out_rms {
            Some(h) => eprintln!(
                "{}: RMS {:.4} px, held-out {h:.4} px — {}",
                c.model, c.rms, c.verdict
            ),
            None => eprintln!("{}: RMS {:.4} px — {}", c.model, c.rms, c.verdict),
        }
    }
    eprintln!(
        "chosen {}: RMS {:.4} px over {} points",
        fit.lens.model(),
        fit.rms,
        points
    );
    for (name, s) in &fit.sigma {
        eprintln!("  σ({name}) = {s:.3e}");
    }
    for w in &cal.warnings {
        eprintln!("warning: {w}");
    }
}

fn write_channel(
    cal: &omniwarp::calibration::Calibration,
    id: &str,
    resolution: [u32; 2],
    out: &std::path::Path,
) -> Result<()> {
    write_json(out, &cal.channel_doc(id, resolution))
}

/// The calibrated projector written where it was asked for: into --rig as channel --channel
/// (`--update`), or as a channel document at --out (named --id, or --channel with --captures).
fn place(
    a: &CalibrateArgs,
    cal: &omniwarp::calibration::Calibration,
    resolution: [u32; 2],
) -> Result<()> {
    let id = a.channel.as_deref().unwrap_or(&a.id);
    if !a.update {
        return write_channel(
            cal,
            id,
            resolution,
            a.out.as_ref().expect("clap requires it"),
        );
    }
    let path = a.rig.as_ref().expect("clap requires it");
    update_rig(
        path,
        vec![(id.to_string(), cal.channel_doc(id, resolution))],
        "--channel",
    )
}

/// Puts each channel document into the rig file at `path` in place of the channel of its id,
/// validates the whole rig and writes it once (atomically), then says how each projector
/// moved. `flag` names where an unknown id came from.
fn update_rig(
    path: &std::path::Path,
    updates: Vec<(String, omniwarp::rig::ChannelDoc)>,
    flag: &str,
) -> Result<()> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("--rig {}", path.display()))?;
    let mut doc = omniwarp::rig::RigDoc::parse(&text)
        .map_err(|e| anyhow::anyhow!("--rig {}: {}", path.display(), named(e)))?;
    let mut moves = Vec::new();
    for (id, channel) in updates {
        let Some(slot) = doc.channels.iter_mut().find(|c| c.id == id) else {
            let ids: Vec<_> = doc.channels.iter().map(|c| c.id.as_str()).collect();
            anyhow::bail!(
                "{flag}: no channel `{id}` in --rig; it has {}",
                ids.join(", ")
            );
        };
        let before = omniwarp::rig::Channel::from_doc(slot, "before")
            .map_err(|e| anyhow::anyhow!("--rig: {}", named(e)))?;
        *slot = channel;
        let after = omniwarp::rig::Channel::from_doc(slot, "after")
            .map_err(|e| anyhow::anyhow!("--rig: {}", named(e)))?;
        moves.push((id, before, after));
    }
    // Validated whole, its mesh read beside it, before the file is touched.
    let base = path.parent().unwrap_or(std::path::Path::new("."));
    let mut check = doc.clone();
    check.screen.load(base, "/screen")?;
    omniwarp::rig::Rig::from_doc(check).map_err(|e| anyhow::anyhow!("--rig: {}", named(e)))?;
    write_json(path, &doc)?;
    for (id, before, after) in moves {
        let c = before.change_to(&after);
        eprintln!(
            "{}: channel {id} updated: moved {:.3} m, turned {:.2}°, {} f {:.1} px → {} f {:.1} px",
            path.display(),
            c.moved,
            c.turned,
            c.model[0],
            c.focal[0],
            c.model[1],
            c.focal[1]
        );
        if c.turned > omniwarp::rig::ChannelChange::SUSPICIOUS_TURN {
            eprintln!(
                "warning: channel {id} now looks {:.0}° away from where the rig had it; if \
                 these were another projector's points, put the file back from your copy",
                c.turned
            );
        }
    }
    Ok(())
}

/// `--captures`: decode, then calibrate or check.
fn from_captures(a: &CalibrateArgs, dir: &std::path::Path) -> Result<()> {
    use omniwarp::rig::Rig;
    use omniwarp::structured::decode::{DecodeOptions, decode};
    use omniwarp::structured::{calibrate_captures, calibrate_decoded, check, read_captures};
    let rig_path = a.rig.as_ref().expect("clap requires it");
    let rig = Rig::read(rig_path).with_context(|| format!("--rig {}", rig_path.display()))?;
    let id = a.channel.as_deref().expect("clap requires it");
    let projector = rig
        .channel(id)
        .map_err(|e| anyhow::anyhow!("--channel: {}", named(e)))?;
    let camera = posed_camera(a, &rig)?;
    let choice = model_choice(a)?;
    omniwarp::limits::at_most("--points", a.points, omniwarp::limits::CALIBRATION_POINTS)
        .map_err(|e| anyhow::anyhow!("{}", named(e)))?;
    let frames = read_captures(dir).map_err(|e| anyhow::anyhow!("--captures: {}", named(e)))?;
    let resolution = [projector.width, projector.height];
    let set = pattern_set(a, resolution)?;
    let opts = DecodeOptions::default();
    if let Some(out) = &a.check {
        let decoded = decode(&set, &frames, &opts)
            .map_err(|e| anyhow::anyhow!("--captures: {}", named(e)))?;
        let c = check(&decoded, &camera, &rig.doc.screen, projector);
        if decoded.valid() == 0 {
            anyhow::bail!(
                "--captures: no camera pixel was decoded (rejected: {:?})",
                decoded.rejected
            );
        }
        let img =
            omniwarp::raster::Raster::from_fn(c.width as usize, c.height as usize, |x, y| match c
                .residuals[y * c.width as usize + x]
            {
                Some([dx, dy]) => [dx as f32, dy as f32, dx.hypot(dy) as f32, 1.0],
                None => [0.0; 4],
            });
        omniwarp::image_io::write_exr_rgba(out, &img, &[], omniwarp::image_io::Precision::Float)?;
        if c.count == 0 {
            outln!(
                "none of the {} decoded pixels lands within `{id}`'s image as calibrated: moved",
                decoded.valid()
            );
        } else {
            outln!(
                "{} pixels compared: median {:.4} px, p95 {:.4} px, max {:.4} px; threshold {:.4} px: {}",
                c.count,
                c.p50,
                c.p95,
                c.max,
                c.threshold,
                if c.moved { "moved" } else { "not moved" }
            );
        }
        if let Some(out) = &a.out {
            let found = calibrate_decoded(
                decoded,
                resolution,
                &camera,
                &rig.doc.screen,
                choice,
                a.points,
                &Default::default(),
            )
            .map_err(|e| anyhow::anyhow!("--captures: {}", named(e)))?;
            report(&found.calibration, found.problem.points.len());
            write_channel(&found.calibration, id, resolution, out)?;
        }
        return Ok(());
    }
    let found = calibrate_captures(
        &set,
        &frames,
        &camera,
        &rig.doc.screen,
        choice,
        a.points,
        &opts,
        &Default::default(),
    )
    .map_err(|e| anyhow::anyhow!("--captures: {}", named(e)))?;
    eprintln!(
        "decoded {} camera pixels (rejected: {:?})",
        found.decoded.valid(),
        found.decoded.rejected
    );
    report(&found.calibration, found.problem.points.len());
    place(a, &found.calibration, resolution)
}

/// A correspondences document (pixels and wall points) read from `path`; errors name `flag`
/// and the field by JSON pointer.
fn read_points(path: &std::path::Path, flag: &str) -> Result<CorrespondencesDoc> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("{flag} {}", path.display()))?;
    let de = &mut serde_json::Deserializer::from_str(&text);
    serde_path_to_error::deserialize(de).map_err(|e| {
        anyhow::anyhow!(
            "{flag}: {}: {}",
            omniwarp::rig::pointer_of(&e.path().to_string()),
            e.inner()
        )
    })
}

/// --camera, posed by --markers or --pose-captures when given.
fn posed_camera(a: &CalibrateArgs, rig: &omniwarp::rig::Rig) -> Result<omniwarp::rig::Channel> {
    let mut camera = read_camera(a.camera.as_ref().expect("clap requires it"))?;
    if let Some(path) = &a.markers {
        let doc = read_points(path, "--markers")?;
        let (posed, rms) = omniwarp::structured::camera_pose(&camera, &doc.points)
            .map_err(|e| anyhow::anyhow!("--markers: {}", named(e)))?;
        eprintln!(
            "camera pose from {} markers: position {:?}, marker RMS {rms:.3} px",
            doc.points.len(),
            posed.position.to_array()
        );
        camera = posed;
    }
    if let Some(dir) = &a.pose_captures {
        camera = pose_from_projector(a, rig, dir, camera)?;
    }
    Ok(camera)
}

fn model_choice(a: &CalibrateArgs) -> Result<ModelChoice> {
    Ok(match a.model.as_deref().unwrap_or("auto") {
        "auto" => ModelChoice::Auto,
        m => ModelChoice::Fixed(
            m.parse()
                .map_err(|e: omniwarp::Error| anyhow::anyhow!("--model: {}", e.reason()))?,
        ),
    })
}

/// The structured-light sequence a projector of `resolution` showed, as --period and --code
/// say.
fn pattern_set(
    a: &CalibrateArgs,
    resolution: [u32; 2],
) -> Result<omniwarp::structured::PatternSet> {
    Ok(
        omniwarp::structured::PatternSet::new(resolution[0], resolution[1])?
            .with_period(a.period)
            .map_err(|e| anyhow::anyhow!("--{}", named(e)))?
            .with_code(a.code),
    )
}

/// `--rig-captures`: every projector with a capture folder calibrated from it with the one
/// camera, and written into the rig together.
fn whole_rig(a: &CalibrateArgs, root: &std::path::Path) -> Result<()> {
    use omniwarp::structured::{calibrate_captures, decode::DecodeOptions, read_captures};
    let rig_path = a.rig.as_ref().expect("clap requires it");
    let rig = omniwarp::rig::Rig::read(rig_path)
        .with_context(|| format!("--rig {}", rig_path.display()))?;
    let mut folders: Vec<(String, PathBuf)> = std::fs::read_dir(root)
        .with_context(|| format!("--rig-captures {}", root.display()))?
        .filter_map(|e| e.ok())
        .filter(|e| e.path().is_dir())
        .map(|e| (e.file_name().to_string_lossy().into_owned(), e.path()))
        .collect();
    folders.sort();
    if folders.is_empty() {
        anyhow::bail!(
            "--rig-captures {}: no capture folders in it (one per projector, named by its \
             channel id)",
            root.display()
        );
    }
    // Every folder names a channel before any work starts.
    for (id, _) in &folders {
        rig.channel(id)
            .map_err(|e| anyhow::anyhow!("--rig-captures: folder `{id}`: {}", e.reason()))?;
    }
    let camera = posed_camera(a, &rig)?;
    let choice = model_choice(a)?;
    omniwarp::limits::at_most("--points", a.points, omniwarp::limits::CALIBRATION_POINTS)
        .map_err(|e| anyhow::anyhow!("{}", named(e)))?;
    let mut updates = Vec::new();
    for (id, dir) in &folders {
        let projector = rig.channel(id).expect("checked above");
        let resolution = [projector.width, projector.height];
        let what = |e: omniwarp::Error| anyhow::anyhow!("--rig-captures: {id}: {}", named(e));
        let frames = read_captures(dir).map_err(what)?;
        let found = calibrate_captures(
            &pattern_set(a, resolution)?,
            &frames,
            &camera,
            &rig.doc.screen,
            choice,
            a.points,
            &DecodeOptions::default(),
            &Default::default(),
        )
        .map_err(what)?;
        eprintln!(
            "{id}: decoded {} camera pixels; {} RMS {:.4} px over {} points",
            found.decoded.valid(),
            found.calibration.fit.lens.model(),
            found.calibration.fit.rms,
            found.problem.points.len()
        );
        for w in &found.calibration.warnings {
            eprintln!("{id}: warning: {w}");
        }
        updates.push((id.clone(), found.calibration.channel_doc(id, resolution)));
    }
    let n = updates.len();
    update_rig(rig_path, updates, "--rig-captures")?;
    outln!(
        "{}: {n} of {} channels calibrated from {}",
        rig_path.display(),
        rig.channels.len(),
        root.display()
    );
    Ok(())
}

/// `--pose-captures`: the camera posed from another projector's captures.
fn pose_from_projector(
    a: &CalibrateArgs,
    rig: &omniwarp::rig::Rig,
    dir: &std::path::Path,
    camera: omniwarp::rig::Channel,
) -> Result<omniwarp::rig::Channel> {
    use omniwarp::structured::decode::{DecodeOptions, decode};
    use omniwarp::structured::{PatternSet, camera_pose_from_projector, read_captures};
    let anchor_id = a.pose_channel.as_deref().expect("clap requires it");
    if Some(anchor_id) == a.channel.as_deref() {
        anyhow::bail!(
            "--pose-channel: is the channel being calibrated; the camera is posed from another \
             one, already calibrated"
        );
    }
    let anchor = rig
        .channel(anchor_id)
        .map_err(|e| anyhow::anyhow!("--pose-channel: {}", named(e)))?;
    let frames =
        read_captures(dir).map_err(|e| anyhow::anyhow!("--pose-captures: {}", named(e)))?;
    if let Some(f) = frames.first()
        && (f.width, f.height) != (camera.width, camera.height)
    {
        anyhow::bail!(
            "--pose-captures: are {}×{}, the camera {}×{}",
            f.width,
            f.height,
            camera.width,
            camera.height
        );
    }
    let set = PatternSet::new(anchor.width, anchor.height)?
        .with_period(a.period)
        .map_err(|e| anyhow::anyhow!("--{}", named(e)))?
        .with_code(a.code);
    let decoded = decode(&set, &frames, &DecodeOptions::default())
        .map_err(|e| anyhow::anyhow!("--pose-captures: {}", named(e)))?;
    let (posed, rms) =
        camera_pose_from_projector(&decoded, &camera, anchor, &rig.doc.screen, a.points)
            .map_err(|e| anyhow::anyhow!("--pose-captures: {}", named(e)))?;
    eprintln!(
        "camera pose from `{anchor_id}` ({} pixels decoded): position {:?}, RMS {rms:.3} px",
        decoded.valid(),
        posed.position.to_array()
    );
    Ok(posed)
}
