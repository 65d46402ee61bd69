//! `omniwarp bench camera`: the virtual projector–camera bench. One projector of a rig shows
//! the structured-light sequence, a simulated camera captures it, the captures are decoded and
//! the projector calibrated from them, and every step is measured against the bench's truth.
//! `omniwarp simulate` writes the same captures to a folder instead.

use super::super::args::{BenchConditions, named};
use anyhow::Result;
use clap::Args;
use omniwarp::calibration::ModelChoice;
use omniwarp::rig::Channel;
use omniwarp::structured::decode::{DecodeOptions, decode};
use omniwarp::structured::simulator::Simulator;
use omniwarp::structured::{Grey, calibrate_decoded};
use std::time::Instant;

#[derive(Args)]
pub struct CameraBenchArgs {
    #[command(flatten)]
    conditions: BenchConditions,
    /// Lens model of the fit: auto or a model name (default: the projector's own).
    #[arg(long)]
    model: Option<String>,
    /// Decoded pixels used as correspondences, at most.
    #[arg(long, default_value_t = 5000)]
    points: usize,
}

pub fn run(a: CameraBenchArgs) -> Result<()> {
    let (rig, projector, camera, opts) = a.conditions.setup()?;
    let choice = match a.model.as_deref() {
        None => ModelChoice::Fixed(projector.lens.model()),
        Some("auto") => ModelChoice::Auto,
        Some(m) => ModelChoice::Fixed(
            m.parse()
                .map_err(|e: omniwarp::Error| anyhow::anyhow!("--model: {}", e.reason()))?,
        ),
    };
    omniwarp::limits::at_most("--points", a.points, omniwarp::limits::CALIBRATION_POINTS)
        .map_err(|e| anyhow::anyhow!("{}", named(e)))?;

    let t = Instant::now();
    let bench = Simulator::new(&rig, &projector, &camera, opts)
        .map_err(|e| anyhow::anyhow!("{}", named(e)))?;
    let t_bench = t.elapsed();
    let t = Instant::now();
    let frames: Vec<Grey> = (0..bench.patterns().len())
        .map(|n| bench.capture(n))
        .collect::<omniwarp::Result<_>>()?;
    let t_capture = t.elapsed();
    let t = Instant::now();
    let decoded = decode(bench.patterns(), &frames, &DecodeOptions::default())?;
    let t_decode = t.elapsed();
    let t = Instant::now();
    let found = calibrate_decoded(
        decoded,
        [projector.width, projector.height],
        &camera,
        &rig.doc.screen,
        choice,
        a.points,
        &Default::default(),
    )
    .map_err(|e| anyhow::anyhow!("{}", named(e)))?;
    let t_fit = t.elapsed();
    let decoded = &found.decoded;

    let (mut errors, mut lit) = (Vec::new(), 0usize);
    for y in 0..camera.height {
        for x in 0..camera.width {
            let truth = bench.truth(x, y);
            lit += usize::from(truth.is_some());
            if let (Some(s), Some(t)) = (decoded.get(x, y), truth) {
                errors.push((s.q[0] - t[0]).hypot(s.q[1] - t[1]));
            }
        }
    }
    let gross = errors.iter().filter(|&&e| e > 1.0).count();
    let fit = &found.calibration.fit;
    let doc = found
        .calibration
        .channel_doc(&projector.id, [projector.width, projector.height]);
    let fitted = Channel::from_doc(&doc, "")?;
    let mut warp = Vec::new();
    for j in (0..projector.height).step_by(8) {
        for i in (0..projector.width).step_by(8) {
            let q = [f64::from(i), f64::from(j)];
            if rig.wall_point(&projector, q).is_none() {
                continue;
            }
            let Some(p) = rig.wall_point(&fitted, q) else {
                continue;
            };
            if let Ok(l) = projector
                .lens
                .project(projector.rotation.transpose() * (p - projector.position))
            {
                warp.push((l[0] - q[0]).hypot(l[1] - q[1]));
            }
        }
    }
    let turned = {
        let m = fitted.rotation.transpose() * projector.rotation;
        let trace = m.x_axis.x + m.y_axis.y + m.z_axis.z;
        ((trace - 1.0) / 2.0).clamp(-1.0, 1.0).acos().to_degrees()
    };
    outln!(
        "projector `{}` {}×{}, camera {} {}×{}, {} frames",
        projector.id,
        projector.width,
        projector.height,
        camera.lens.model(),
        camera.width,
        camera.height,
        frames.len()
    );
    outln!(
        "times: bench {:.2} s, captures {:.2} s, decode {:.2} s, fit {:.2} s",
        t_bench.as_secs_f64(),
        t_capture.as_secs_f64(),
        t_decode.as_secs_f64(),
        t_fit.as_secs_f64()
    );
    outln!(
        "decoded {} of {lit} lit camera pixels ({:.1} %); rejected {:?}",
        errors.len(),
        100.0 * errors.len() as f64 / lit.max(1) as f64,
        decoded.rejected
    );
    if !errors.is_empty() {
        outln!(
            "decoded against truth: median {:.4} px, p99 {:.4} px, max {:.4} px, {gross} above 1 px ({:.3} %)",
            percentile(&mut errors, 0.5),
            percentile(&mut errors, 0.99),
            percentile(&mut errors, 1.0),
            100.0 * gross as f64 / errors.len() as f64
        );
    }
    outln!(
        "fit {}: {} points, RMS {:.4} px; position off by {:.3} mm, rotation by {:.5}°",
        fit.lens.model(),
        found.problem.points.len(),
        fit.rms,
        (fitted.position - projector.position).length() * 1e3,
        turned
    );
    if !warp.is_empty() {
        let rms = (warp.iter().map(|e| e * e).sum::<f64>() / warp.len() as f64).sqrt();
        outln!(
            "warp against truth over {} lit projector pixels: RMS {rms:.4} px, p99 {:.4} px, max {:.4} px",
            warp.len(),
            percentile(&mut warp, 0.99),
            percentile(&mut warp, 1.0)
        );
    }
    Ok(())
}

fn percentile(v: &mut [f64], p: f64) -> f64 {
    v.sort_by(f64::total_cmp);
    v[((v.len() - 1) as f64 * p).round() as usize]
}
