//! Projector calibration from correspondences: projector pixels and the 3-D wall points they
//! land on. The projector is an inverse camera, so this is camera resectioning: find the pose
//! and the intrinsics that reproject the points onto their pixels.
//!
//! * Start without a guess: the direct linear transform (DLT) of the 3×4 projection matrix from
//!   non-coplanar points, decomposed into K, R, t; with the intrinsics known, a pose from the
//!   same DLT on undistorted rays.
//! * Refine by Levenberg–Marquardt on all parameters at once with exact Jacobians (dual numbers
//!   through the lens formula and a Rodrigues rotation), under a Huber loss so that a few bad
//!   measurements cannot pull the solution; residuals beyond 3 robust σ are reported as
//!   outliers.
//! * Choose the model: from PINHOLE up through OPENCV4, 5 and 8, a larger model is taken only
//!   while 5-fold cross-validated residuals improve by more than 2 % — more terms that only fit
//!   the noise are refused, and the report says why each was.
//! * Uncertainty of every parameter from the normal equations, and warnings when one is poorly
//!   determined (focal length against distance on a gently curved wall, typically).

mod dlt;
mod solve;

pub use solve::{Fit, fit};

use crate::error::{Error, Result};
use crate::lens::{Lens, LensModel};
use glam::DVec3;
use serde::{Deserialize, Serialize};
use std::sync::atomic::AtomicBool;

/// One measurement: projector pixel (pixel centres at integers) and the wall point it lights.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Correspondence {
    /// Projector pixel (x right, y down), pixel centres at integers: (0, 0) is the centre of the
    /// top-left pixel.
    pub pixel: [f64; 2],
    /// The wall point it lights, world coordinates in metres (+y up).
    pub world: [f64; 3],
}

/// A calibration request as a file (`omniwarp calibrate --correspondences F`) or a request body
/// (`POST /v1/channels/{id}/calibration`): one format for both, so a file measured once can be
/// posted as it is. Example: `calibration/examples/points.json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CorrespondencesDoc {
    /// The projector's width and height in pixels. Needed by the CLI; the daemon knows its
    /// channel's and refuses a file made for another size.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub resolution: Option<[u32; 2]>,
    /// The measurements, at most `limits::CALIBRATION_POINTS` (20 000).
    pub points: Vec<Correspondence>,
    /// Known intrinsics (kept with `intrinsics_fixed`) or a seed.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub lens: Option<crate::rig::LensDoc>,
    /// `auto` (PINHOLE → OPENCV4 → 5 → 8 while held-out residuals improve) or a model name;
    /// `auto` when absent. The CLI's `--model` takes precedence.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub model: Option<String>,
    /// Keep `lens`'s intrinsics and solve for the pose only (then `lens` is required); false when
    /// absent.
    #[serde(default)]
    pub intrinsics_fixed: bool,
}

impl CorrespondencesDoc {
    /// The solver's problem for a projector of `resolution`, and the model choice (`model`
    /// overrides the document's). Errors name the field by JSON pointer.
    pub fn problem(
        &self,
        resolution: [u32; 2],
        model: Option<&str>,
    ) -> crate::Result<(Problem, ModelChoice)> {
        if let Some(r) = self.resolution
            && r != resolution
        {
            return Err(Error::invalid(
                "/resolution",
                format!(
                    "the points were measured on a {}×{} image, the projector is {}×{}",
                    r[0], r[1], resolution[0], resolution[1]
                ),
            ));
        }
        crate::limits::at_most(
            "/points",
            self.points.len(),
            crate::limits::CALIBRATION_POINTS,
        )?;
        let lens = match &self.lens {
            Some(l) => {
                let m: LensModel = l
                    .model
                    .parse()
                    .map_err(|e: Error| Error::invalid("/lens/model", e.reason()))?;
                Some(
                    Lens::new(m, l.intrinsics.clone())
                        .map_err(|e| Error::invalid("/lens/intrinsics", e.reason()))?,
                )
            }
            None => None,
        };
        if self.intrinsics_fixed && lens.is_none() {
            return Err(Error::invalid(
                "/intrinsics_fixed",
                "there is no lens to keep: give `lens` with the known intrinsics",
            ));
        }
        let choice = match model.or(self.model.as_deref()).unwrap_or("auto") {
            "auto" => ModelChoice::Auto,
            m => ModelChoice::Fixed(
                m.parse()
                    .map_err(|e: Error| Error::invalid("/model", e.reason()))?,
            ),
        };
        let problem = Problem {
            resolution,
            points: self.points.clone(),
            lens,
            intrinsics_fixed: self.intrinsics_fixed,
        };
        Ok((problem, choice))
    }
}

/// What the solver is asked.
#[derive(Debug, Clone, PartialEq)]
pub struct Problem {
    /// The projector's width and height in pixels.
    pub resolution: [u32; 2],
    /// The measurements.
    pub points: Vec<Correspondence>,
    /// Known intrinsics (held fixed) or a seed, with its model.
    pub lens: Option<Lens>,
    /// Solve for the pose only, keeping `lens`'s intrinsics (which must then be given).
    pub intrinsics_fixed: bool,
}

/// Model choice: `Auto` tries PINHOLE, OPENCV4, 5, 8 in turn.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ModelChoice {
    /// PINHOLE, then OPENCV4, 5 and 8, each kept only while the 5-fold cross-validated RMS
    /// improves by more than 2 %; with fixed intrinsics, the given lens's model alone.
    Auto,
    /// This model only, without comparison.
    Fixed(LensModel),
}

/// A considered model and what became of it.
#[derive(Debug, Clone, PartialEq)]
pub struct Considered {
    /// The lens model tried.
    pub model: LensModel,
    /// RMS reprojection error of the inliers under a fit to all points, pixels; NaN where the model
    /// was not fitted (too few points for its parameters).
    pub rms: f64,
    /// 5-fold cross-validated RMS of held-out points, pixels; only where models were compared
    /// (`ModelChoice::Auto` with free intrinsics).
    pub held_out_rms: Option<f64>,
    /// Why the model was taken or rejected, in words (e.g. "held-out RMS improved to … px").
    pub verdict: String,
}

/// The result: the projector, how well it fits, and why this model.
#[derive(Debug, Clone)]
pub struct Calibration {
    /// The chosen model's fit: lens, pose, residuals and parameter uncertainties.
    pub fit: Fit,
    /// Every model tried, in the order tried, with its verdict.
    pub considered: Vec<Considered>,
    /// Poorly determined parameters and outlying points, in words ([`Fit::warnings`]).
    pub warnings: Vec<String>,
}

const AUTO_MODELS: [LensModel; 4] = [
    LensModel::Pinhole,
    LensModel::OpenCv(4),
    LensModel::OpenCv(5),
    LensModel::OpenCv(8),
];

impl Problem {
    fn check(&self) -> Result<()> {
        let [w, h] = self.resolution;
        if w == 0 || h == 0 {
            return Err(Error::invalid("resolution", "must be positive"));
        }
        for (n, c) in self.points.iter().enumerate() {
            if !c.pixel.iter().chain(&c.world).all(|v| v.is_finite()) {
                return Err(Error::invalid(
                    format!("points[{n}]"),
                    "holds a non-finite number",
                ));
            }
            // Far outside the image or the room, a point is a typing error, and its squares
            // overflow the solver.
            let [x, y] = c.pixel;
            let (fw, fh) = (f64::from(w), f64::from(h));
            if !(-fw..=2.0 * fw).contains(&x) || !(-fh..=2.0 * fh).contains(&y) {
                return Err(Error::invalid(
                    format!("points[{n}].pixel"),
                    format!("({x}, {y}) is far outside the {w}×{h} image"),
                ));
            }
            let far = crate::limits::WORLD_EXTENT;
            if c.world.iter().any(|v| v.abs() > far) {
                return Err(Error::invalid(
                    format!("points[{n}].world"),
                    format!("is more than the limit of {far} m from the origin"),
                ));
            }
        }
        if self.intrinsics_fixed && self.lens.is_none() {
            return Err(Error::invalid(
                "lens",
                "fixed intrinsics need the lens to be given",
            ));
        }
        // The points' spread over the image: a corner of it says little about the lens.
        let (mut lo, mut hi) = ([f64::MAX; 2], [f64::MIN; 2]);
        for c in &self.points {
            for k in 0..2 {
                lo[k] = lo[k].min(c.pixel[k]);
                hi[k] = hi[k].max(c.pixel[k]);
            }
        }
        let covered = ((hi[0] - lo[0]) * (hi[1] - lo[1])) / (f64::from(w) * f64::from(h));
        if !self.intrinsics_fixed && covered < 0.1 {
            return Err(Error::invalid(
                "points",
                format!(
                    "cover only {:.1} % of the image; spread them over at least 10 % to determine the lens",
                    covered * 100.0
                ),
            ));
        }
        Ok(())
    }
}

/// Whether the wall points lie (nearly) in one plane, relative to their spread.
pub fn coplanar(points: &[DVec3]) -> bool {
    let n = points.len() as f64;
    let mean = points.iter().copied().sum::<DVec3>() / n;
    let mut cov = nalgebra::Matrix3::<f64>::zeros();
    for p in points {
        let d = *p - mean;
        let v = nalgebra::Vector3::new(d.x, d.y, d.z);
        cov += v * v.transpose();
    }
    let eig = cov.symmetric_eigenvalues();
    let (min, max) = (eig.min(), eig.max());
    max <= 0.0 || min / max < 1e-8
}

/// Calibrates a projector from correspondences.
pub fn calibrate(problem: &Problem, choice: ModelChoice) -> Result<Calibration> {
    calibrate_unless(problem, choice, &AtomicBool::new(false))
}

/// [`calibrate`], given up with [`Error::Cancelled`] soon after `cancel` is set.
pub fn calibrate_unless(
    problem: &Problem,
    choice: ModelChoice,
    cancel: &AtomicBool,
) -> Result<Calibration> {
    problem.check()?;
    let world: Vec<DVec3> = problem
        .points
        .iter()
        .map(|c| DVec3::from_array(c.world))
        .collect();
    let models: Vec<LensModel> = match (choice, &problem.lens) {
        (ModelChoice::Fixed(m), _) => vec![m],
        (ModelChoice::Auto, Some(l)) if problem.intrinsics_fixed => vec![l.model()],
        (ModelChoice::Auto, _) => AUTO_MODELS.to_vec(),
    };
    if !problem.intrinsics_fixed && coplanar(&world) {
        return Err(Error::invalid(
            "points",
            "all lie in one plane: with free intrinsics that cannot separate focal length from distance; \
             fix the intrinsics (--intrinsics-fixed) or measure points off the plane",
        ));
    }
    let mut considered = Vec::new();
    let mut best: Option<(Fit, f64)> = None;
    for model in models {
        let n_params = model.intrinsics_len() * usize::from(!problem.intrinsics_fixed) + 6;
        if 2 * problem.points.len() < n_params + 4 {
            if best.is_none() {
                return Err(Error::invalid(
                    "points",
                    format!(
                        "{} points cannot determine {model} ({n_params} parameters); give at least {}",
                        problem.points.len(),
                        (n_params + 5) / 2
                    ),
                ));
            }
            considered.push(Considered {
                model,
                rms: f64::NAN,
                held_out_rms: None,
                verdict: "too few points for its parameters".into(),
            });
            break;
        }
        let full = fit(problem, model, &problem.points, cancel)?;
        let compared = choice == ModelChoice::Auto && !problem.intrinsics_fixed;
        // Without a comparison there is nothing to hold points out for; the plain fit decides.
        let held_out = if compared {
            cross_validate(problem, model, cancel)?
        } else {
            full.rms
        };
        let verdict;
        let better = match &best {
            None => true,
            Some((_, prev)) => held_out < 0.98 * prev,
        };
        if better {
            verdict = if !compared {
                "the model asked for".to_string()
            } else if best.is_none() {
                "first model".to_string()
            } else {
                format!("held-out RMS improved to {held_out:.4} px")
            };
            considered.push(Considered {
                model,
                rms: full.rms,
                held_out_rms: compared.then_some(held_out),
                verdict,
            });
            best = Some((full, held_out));
        } else {
            let prev = best.as_ref().map_or(f64::NAN, |b| b.1);
            considered.push(Considered {
                model,
                rms: full.rms,
                held_out_rms: Some(held_out),
                verdict: format!(
                    "rejected: held-out RMS {held_out:.4} px is not 2 % better than {prev:.4} px"
                ),
            });
            break;
        }
    }
    let (fit, _) = best.expect("at least one model was fitted");
    if !fit.rms.is_finite() || fit.sigma.iter().any(|(_, v)| !v.is_finite()) {
        return Err(Error::invalid(
            "points",
            "the solve did not reach finite values; check the points for outliers",
        ));
    }
    let warnings = fit.warnings();
    Ok(Calibration {
        fit,
        considered,
        warnings,
    })
}

/// RMS of each fold's points under a fit to the other four folds.
fn cross_validate(problem: &Problem, model: LensModel, cancel: &AtomicBool) -> Result<f64> {
    let folds = 5;
    let (mut sum, mut n) = (0.0, 0usize);
    for f in 0..folds {
        let train: Vec<Correspondence> = problem
            .points
            .iter()
            .enumerate()
            .filter(|(i, _)| i % folds != f)
            .map(|(_, c)| *c)
            .collect();
        let test: Vec<Correspondence> = problem
            .points
            .iter()
            .enumerate()
            .filter(|(i, _)| i % folds == f)
            .map(|(_, c)| *c)
            .collect();
        let fitted = fit(problem, model, &train, cancel)?;
        for c in &test {
            match fitted.reproject(DVec3::from_array(c.world)) {
                Some(q) => sum += (q[0] - c.pixel[0]).powi(2) + (q[1] - c.pixel[1]).powi(2),
                None => sum += 1e6,
            }
            n += 1;
        }
    }
    Ok((sum / n as f64).sqrt())
}

impl Calibration {
    /// The solved projector as a rig channel (pose as projector-to-world rvec).
    pub fn channel_doc(&self, id: &str, resolution: [u32; 2]) -> crate::rig::ChannelDoc {
        let (position, rvec) = self.fit.projector_to_world();
        crate::rig::ChannelDoc {
            id: id.to_string(),
            resolution,
            lens: crate::rig::LensDoc::new(
                self.fit.lens.model().to_string(),
                self.fit.lens.intrinsics().to_vec(),
            ),
            pose: crate::rig::PoseDoc {
                position: position.to_array(),
                look_to: None,
                look_up: None,
                rvec: Some(rvec.to_array()),
            },
            contrast: None,
        }
    }
}
