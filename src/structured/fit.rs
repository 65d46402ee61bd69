//! From a decoded map to the rig: projector pixel ↔ wall point correspondences through a
//! camera of known pose, the camera's own pose (from markers or from a projector already
//! calibrated), the projector's calibration, and the check of a calibration against a fresh
//! capture.

use super::{Grey, PatternSet, decode};
use crate::error::{Error, Result};

/// Projector pixel ↔ wall point correspondences from a decoded map, for a camera of known
/// pose: each decoded camera pixel's ray is followed to the wall. At most `limit` are taken, on
/// a regular lattice over the decoded pixels (keeping the image's coverage, which is what
/// determines the lens), the most confident first where a lattice cell holds several.
pub fn correspondences(
    decoded: &decode::Decoded,
    camera: &crate::rig::Channel,
    screen: &crate::surface::Screen,
    limit: usize,
) -> Vec<crate::calibration::Correspondence> {
    spread(decoded, limit)
        .filter_map(|(x, y, s)| {
            let ray = camera.lens.unproject([f64::from(x), f64::from(y)]).ok()?;
            let point = screen
                .intersect(camera.position, camera.rotation * ray)
                .point()?;
            Some(crate::calibration::Correspondence {
                pixel: s.q,
                world: point.to_array(),
            })
        })
        .take(limit)
        .collect()
}

/// At most `limit` of the decoded camera pixels, on a regular lattice over them: the most
/// confident of each lattice cell.
fn spread(
    decoded: &decode::Decoded,
    limit: usize,
) -> impl Iterator<Item = (u32, u32, decode::Sample)> + '_ {
    let valid = decoded.valid();
    // The lattice step that keeps at most `limit` of the decoded pixels.
    let step = if valid == 0 || limit == 0 {
        decoded.width.max(decoded.height).max(1)
    } else {
        ((valid as f64 / limit as f64).sqrt().ceil() as u32).max(1)
    };
    let cells_x = decoded.width.div_ceil(step);
    let cells = cells_x * decoded.height.div_ceil(step);
    (0..cells).filter_map(move |c| {
        let (cx, cy) = ((c % cells_x) * step, (c / cells_x) * step);
        let mut best: Option<(u32, u32, decode::Sample)> = None;
        for y in cy..(cy + step).min(decoded.height) {
            for x in cx..(cx + step).min(decoded.width) {
                if let Some(s) = decoded.get(x, y)
                    && best.is_none_or(|b| s.sigma < b.2.sigma)
                {
                    best = Some((x, y, s));
                }
            }
        }
        best
    })
}

/// The camera's pose from a projector already calibrated (its lens and pose right): the
/// projector coordinate decoded at a camera pixel, followed through the projector's model to
/// the wall, is a marker there ([`camera_pose`]), and the decoded map gives thousands of them
/// over the whole of the projector's image. This is how one camera, moved between shots,
/// carries a calibration from projector to projector without surveyed fiducials. At most
/// `limit` camera pixels are used; returns the camera with its pose replaced and the RMS
/// reprojection error in camera pixels.
pub fn camera_pose_from_projector(
    decoded: &decode::Decoded,
    camera: &crate::rig::Channel,
    projector: &crate::rig::Channel,
    screen: &crate::surface::Screen,
    limit: usize,
) -> Result<(crate::rig::Channel, f64)> {
    let markers: Vec<_> = spread(decoded, limit)
        .filter_map(|(x, y, s)| {
            let ray = projector.lens.unproject(s.q).ok()?;
            let point = screen
                .intersect(projector.position, projector.rotation * ray)
                .point()?;
            Some(crate::calibration::Correspondence {
                pixel: [f64::from(x), f64::from(y)],
                world: point.to_array(),
            })
        })
        .take(limit)
        .collect();
    if markers.len() < 50 {
        return Err(Error::invalid(
            "captures",
            format!(
                "only {} camera pixels of the posing projector `{}` were decoded on the wall \
                 (rejected: {}); is it lit and in the camera's view?",
                markers.len(),
                projector.id,
                decoded.rejected
            ),
        ));
    }
    camera_pose(camera, &markers)
}

/// The camera's pose from markers: wall points of known position (surveyed fiducials, a
/// dome's seams) and the camera pixels where they appear, the camera's lens known. This is
/// the projector calibration's own problem (resectioning) with the intrinsics held, so it
/// needs no guess: a pose from the rays, refined under the robust loss. Returns the camera
/// with its pose replaced, and the markers' RMS reprojection error in camera pixels.
pub fn camera_pose(
    camera: &crate::rig::Channel,
    markers: &[crate::calibration::Correspondence],
) -> Result<(crate::rig::Channel, f64)> {
    if markers.len() < 4 {
        return Err(Error::invalid(
            "markers",
            format!(
                "a camera's pose needs at least 4 markers, got {}",
                markers.len()
            ),
        ));
    }
    let problem = crate::calibration::Problem {
        resolution: [camera.width, camera.height],
        points: markers.to_vec(),
        lens: Some(camera.lens.clone()),
        intrinsics_fixed: true,
    };
    let cal = crate::calibration::calibrate(
        &problem,
        crate::calibration::ModelChoice::Fixed(camera.lens.model()),
    )?;
    let doc = cal.channel_doc(&camera.id, [camera.width, camera.height]);
    Ok((crate::rig::Channel::from_doc(&doc, "markers")?, cal.fit.rms))
}

/// What a capture set made of a projector: the decoded map, the correspondences taken from
/// it, and the calibration.
pub struct FromCaptures {
    /// The decoded captures: per camera pixel, the projector pixel that lights it.
    pub decoded: decode::Decoded,
    /// The correspondences taken from them (decoded pixels' wall points), with free intrinsics.
    pub problem: crate::calibration::Problem,
    /// The projector's calibration from those correspondences.
    pub calibration: crate::calibration::Calibration,
}

/// Decodes `frames` (the sequence `set`, in order), turns at most
/// `points` decoded pixels into correspondences through `camera` (pose known) onto `screen`,
/// and calibrates, until `cancel` is set.
#[allow(clippy::too_many_arguments)]
pub fn calibrate_captures<F: std::borrow::Borrow<Grey> + Sync>(
    set: &PatternSet,
    frames: &[F],
    camera: &crate::rig::Channel,
    screen: &crate::surface::Screen,
    choice: crate::calibration::ModelChoice,
    points: usize,
    opts: &decode::DecodeOptions,
    cancel: &std::sync::atomic::AtomicBool,
) -> Result<FromCaptures> {
    if let Some(f) = frames.first().map(std::borrow::Borrow::borrow)
        && (f.width, f.height) != (camera.width, camera.height)
    {
        return Err(Error::invalid(
            "captures",
            format!(
                "are {}×{}, the camera {}×{}",
                f.width, f.height, camera.width, camera.height
            ),
        ));
    }
    let decoded = decode::decode(set, frames, opts)?;
    let resolution = [set.width, set.height];
    calibrate_decoded(decoded, resolution, camera, screen, choice, points, cancel)
}

/// [`calibrate_captures`] from captures already decoded.
pub fn calibrate_decoded(
    decoded: decode::Decoded,
    resolution: [u32; 2],
    camera: &crate::rig::Channel,
    screen: &crate::surface::Screen,
    choice: crate::calibration::ModelChoice,
    points: usize,
    cancel: &std::sync::atomic::AtomicBool,
) -> Result<FromCaptures> {
    let found = correspondences(&decoded, camera, screen, points);
    if found.len() < 50 {
        return Err(Error::invalid(
            "captures",
            format!(
                "only {} camera pixels were decoded on the wall (rejected: {}); is the \
                 projector lit and in view, and the camera's pose right?",
                found.len(),
                decoded.rejected
            ),
        ));
    }
    let problem = crate::calibration::Problem {
        resolution,
        points: found,
        lens: None,
        intrinsics_fixed: false,
    };
    let calibration = crate::calibration::calibrate_unless(&problem, choice, cancel)?;
    Ok(FromCaptures {
        decoded,
        problem,
        calibration,
    })
}

/// A fresh capture compared with what the current calibration predicts.
#[derive(Debug, Clone)]
pub struct Check {
    /// The camera's width in pixels (the row length of `residuals`).
    pub width: u32,
    /// The camera's height in pixels.
    pub height: u32,
    /// Per camera pixel: decoded − predicted projector coordinate, pixels.
    pub residuals: Vec<Option<[f64; 2]>>,
    /// Pixels compared.
    pub count: usize,
    /// Median residual length, projector pixels; NaN when no pixel was compared.
    pub p50: f64,
    /// 95th-percentile residual length, projector pixels; NaN when no pixel was compared.
    pub p95: f64,
    /// Largest residual length, projector pixels; NaN when no pixel was compared.
    pub max: f64,
    /// The median residual above which the projector is said to have moved: 0.15 px, or 4×
    /// the capture's own median predicted deviation where the capture is noisier.
    pub threshold: f64,
    /// The median residual is above the threshold, or none of the decoded pixels lands
    /// within the channel's reach as calibrated.
    pub moved: bool,
}

/// The smallest median residual, projector pixels, that [`check`] calls a move.
pub const MOVED_PX: f64 = 0.15;

/// Compares a decoded capture with channel `projector` as calibrated: each decoded camera
/// pixel's wall point (the camera's pose known) projected through the channel's model, where
/// it lands within half an image of the channel's raster. A
/// projector that moved or whose lens drifted shifts the whole map; noise moves single
/// pixels, so the verdict is on the median.
pub fn check(
    decoded: &decode::Decoded,
    camera: &crate::rig::Channel,
    screen: &crate::surface::Screen,
    projector: &crate::rig::Channel,
) -> Check {
    use rayon::prelude::*;
    let w = decoded.width as usize;
    let residuals: Vec<Option<[f64; 2]>> = decoded
        .samples
        .par_iter()
        .enumerate()
        .with_min_len(1024)
        .map(|(i, s)| {
            let s = (*s)?;
            let ray = camera
                .lens
                .unproject([(i % w) as f64, (i / w) as f64])
                .ok()?;
            let crate::surface::Hit::Lit { point, .. } =
                screen.intersect(camera.position, camera.rotation * ray)
            else {
                return None;
            };
            // Behind the projector, or far outside its image, a lens formula still gives a
            // pixel, but not one the projector could light: the channel as calibrated does not
            // reach that wall point, and a residual there would measure the formula's
            // extrapolation. Half an image beyond each edge is still compared.
            let local = projector.rotation.transpose() * (point - projector.position);
            if local.z <= 0.0 {
                return None;
            }
            let q = projector.lens.project(local).ok()?;
            let (w, h) = (f64::from(projector.width), f64::from(projector.height));
            let near = (-w / 2.0..=1.5 * w).contains(&q[0]) && (-h / 2.0..=1.5 * h).contains(&q[1]);
            near.then(|| [s.q[0] - q[0], s.q[1] - q[1]])
        })
        .collect();
    let mut size: Vec<f64> = residuals
        .iter()
        .flatten()
        .map(|r| r[0].hypot(r[1]))
        .collect();
    let mut sigma: Vec<f64> = decoded.samples.iter().flatten().map(|s| s.sigma).collect();
    size.sort_by(f64::total_cmp);
    sigma.sort_by(f64::total_cmp);
    let at = |v: &[f64], p: f64| {
        if v.is_empty() {
            f64::NAN
        } else {
            v[((v.len() - 1) as f64 * p).round() as usize]
        }
    };
    let threshold = MOVED_PX.max(4.0 * at(&sigma, 0.5));
    let p50 = at(&size, 0.5);
    Check {
        width: decoded.width,
        height: decoded.height,
        count: size.len(),
        p50,
        p95: at(&size, 0.95),
        max: size.last().copied().unwrap_or(f64::NAN),
        threshold,
        // Decoded light the calibration says the projector cannot reach at all: it moved.
        moved: if size.is_empty() {
            decoded.valid() > 0
        } else {
            p50 > threshold
        },
        residuals,
    }
}
