//! Levenberg–Marquardt over intrinsics and pose with exact Jacobians and a Huber loss.

use super::dlt;
use super::{Correspondence, Problem};
use crate::error::{Error, Result};
use crate::lens::{Lens, LensModel, Real};
use glam::{DMat3, DQuat, DVec3};
use nalgebra::{DMatrix, DVector};
use num_dual::DualSVec64;
use std::sync::atomic::{AtomicBool, Ordering};

/// Lanes for the Jacobian: up to 18 intrinsics and 6 pose parameters.
const LANES: usize = 24;
type D = DualSVec64<LANES>;

/// A fitted projector.
#[derive(Debug, Clone)]
pub struct Fit {
    /// The fitted lens: model and intrinsics (the given ones where they were held fixed).
    pub lens: Lens,
    /// World → projector: p_cam = R·p + t.
    pub r: DMat3,
    /// Translation of the world → projector transform (see `r`), metres.
    pub t: DVec3,
    /// 2-D RMS reprojection error of the inliers, pixels.
    pub rms: f64,
    /// Reprojection error of every point, pixels.
    pub residuals: Vec<f64>,
    /// Points whose residual exceeds 3 robust σ.
    pub outliers: Vec<usize>,
    /// Parameter names and their standard deviations (intrinsics first if free, then the
    /// world→projector Rodrigues vector and translation).
    pub sigma: Vec<(String, f64)>,
}

impl Fit {
    /// The pixel of world point `p` under the fitted pose and lens (pixel centres at integers);
    /// `None` where the lens has no pixel for it, e.g. behind the projector.
    pub fn reproject(&self, p: DVec3) -> Option<[f64; 2]> {
        self.lens.project(self.r * p + self.t).ok()
    }

    /// Projector-to-world pose as rigs take it: position and Rodrigues vector.
    pub fn projector_to_world(&self) -> (DVec3, DVec3) {
        let rw = self.r.transpose();
        let (axis, angle) = DQuat::from_mat3(&rw).to_axis_angle();
        (-(rw * self.t), axis * angle)
    }

    /// Parameters known worse than is useful, in words.
    pub fn warnings(&self) -> Vec<String> {
        let mut w = Vec::new();
        if let Some((_, s)) = self.sigma.iter().find(|(n, _)| n == "fx") {
            let f = self.lens.intrinsics()[0];
            if s / f > 0.002 {
                w.push(format!(
                    "the focal length is poorly determined (fx = {f:.1} ± {s:.1} px): it trades off against distance; \
                     points over a wider angle or at more varied depths pin it down"
                ));
            }
        }
        if !self.outliers.is_empty() {
            w.push(format!(
                "{} points look wrong (beyond 3 robust σ) and were down-weighted: {:?}",
                self.outliers.len(),
                self.outliers
            ));
        }
        w
    }
}

/// Rotation of p by Rodrigues vector r, on any Real.
fn rotate<T: Real>(r: [T; 3], p: [T; 3]) -> [T; 3] {
    let th2 = r[0] * r[0] + r[1] * r[1] + r[2] * r[2];
    let cross = |a: [T; 3], b: [T; 3]| {
        [
            a[1] * b[2] - a[2] * b[1],
            a[2] * b[0] - a[0] * b[2],
            a[0] * b[1] - a[1] * b[0],
        ]
    };
    if th2.re() < 1e-20 {
        // First order: R ≈ I + [r]×, exact in value and derivative at r = 0.
        let c = cross(r, p);
        return [p[0] + c[0], p[1] + c[1], p[2] + c[2]];
    }
    let th = th2.sqrt();
    let k = [r[0] / th, r[1] / th, r[2] / th];
    let (s, c) = (th.sin(), th.cos());
    let kp = cross(k, p);
    let kd = k[0] * p[0] + k[1] * p[1] + k[2] * p[2];
    let one = T::from(1.0);
    [0, 1, 2].map(|i| p[i] * c + kp[i] * s + k[i] * kd * (one - c))
}

fn rvec_of(r: DMat3) -> DVec3 {
    let (axis, angle) = DQuat::from_mat3(&r).to_axis_angle();
    axis * angle
}

struct Setup<'a> {
    lens: Lens,
    free: bool,
    points: &'a [Correspondence],
}

impl Setup<'_> {
    fn n_params(&self) -> usize {
        6 + if self.free {
            self.lens.intrinsics().len()
        } else {
            0
        }
    }

    fn split<'x, T: Real>(&self, x: &'x [T], fixed: &'x [T]) -> (&'x [T], [T; 3], [T; 3]) {
        let ni = if self.free {
            self.lens.intrinsics().len()
        } else {
            0
        };
        let intr = if self.free { &x[..ni] } else { fixed };
        (
            intr,
            [x[ni], x[ni + 1], x[ni + 2]],
            [x[ni + 3], x[ni + 4], x[ni + 5]],
        )
    }

    /// Residuals (2 per point) and, with `jac`, their Jacobian.
    fn residuals(&self, x: &[f64], jac: bool) -> (DVector<f64>, Option<DMatrix<f64>>) {
        let n = self.n_params();
        let m = self.points.len();
        let mut r = DVector::zeros(2 * m);
        let mut j = jac.then(|| DMatrix::zeros(2 * m, n));
        let fixed: Vec<D> = self
            .lens
            .intrinsics()
            .iter()
            .map(|&v| D::from_re(v))
            .collect();
        let xd: Vec<D> = x
            .iter()
            .enumerate()
            .map(|(i, &v)| {
                if jac {
                    D::from_re(v).derivative(i)
                } else {
                    D::from_re(v)
                }
            })
            .collect();
        let (intr, rv, tv) = self.split(&xd, &fixed);
        for (k, c) in self.points.iter().enumerate() {
            let p = c.world.map(D::from_re);
            let pr = rotate(rv, p);
            let pc = [pr[0] + tv[0], pr[1] + tv[1], pr[2] + tv[2]];
            let q = self.lens.formula(intr, pc);
            for row in 0..2 {
                r[2 * k + row] = q[row].re - c.pixel[row];
                if let Some(j) = j.as_mut() {
                    let g = q[row]
                        .eps
                        .unwrap_generic(nalgebra::Const::<LANES>, nalgebra::U1);
                    for col in 0..n {
                        j[(2 * k + row, col)] = g[col];
                    }
                }
            }
        }
        (r, j)
    }
}

/// Fits `model` to `points` (all of the problem's, or a cross-validation fold).
/// Fits `model` to `points`; gives up with [`Error::Cancelled`] once `cancel` is set (checked
/// every Levenberg–Marquardt iteration).
pub fn fit(
    problem: &Problem,
    model: LensModel,
    points: &[Correspondence],
    cancel: &AtomicBool,
) -> Result<Fit> {
    let world: Vec<DVec3> = points.iter().map(|c| DVec3::from_array(c.world)).collect();
    let pixels: Vec<[f64; 2]> = points.iter().map(|c| c.pixel).collect();
    // Start: the given lens if it is of this model, else a linear start.
    let seed_lens = problem
        .lens
        .as_ref()
        .filter(|l| l.model() == model)
        .cloned();
    let (core, pose) = match &seed_lens {
        Some(l) => {
            let rays: Vec<[f64; 2]> = pixels
                .iter()
                .map(|q| l.unproject(*q).map(|r| [r.x / r.z, r.y / r.z]))
                .collect::<std::result::Result<_, _>>()
                .map_err(|e| {
                    Error::invalid(
                        "points",
                        format!("a pixel does not unproject through the given lens: {e}"),
                    )
                })?;
            let i = l.intrinsics();
            (
                [i[0], i[1], i[2], i[3]],
                dlt::pose_from_rays(&rays, &world)?,
            )
        }
        None => {
            let p = dlt::projection_matrix(&pixels, &world)?;
            dlt::decompose(p, &world)?
        }
    };
    let intrinsics = match &seed_lens {
        Some(l) => l.intrinsics().to_vec(),
        None => {
            let mut v = core.to_vec();
            v.resize(model.intrinsics_len(), 0.0);
            v
        }
    };
    let lens = Lens::new(model, intrinsics.clone())
        .map_err(|e| Error::invalid("points", format!("the linear start is unusable: {e}")))?;
    let free = !problem.intrinsics_fixed;
    let setup = Setup {
        lens: lens.clone(),
        free,
        points,
    };
    let rv = rvec_of(pose.r);
    let mut x: Vec<f64> = if free { intrinsics } else { Vec::new() };
    x.extend([rv.x, rv.y, rv.z, pose.t.x, pose.t.y, pose.t.z]);
    let x = levenberg_marquardt(&setup, x, cancel)?;
    finish(&setup, &x)
}

/// J with each point's two rows scaled by its weight.
fn weighted_rows(j: &DMatrix<f64>, w: &[f64]) -> DMatrix<f64> {
    let mut out = j.clone();
    for (k, wk) in w.iter().enumerate() {
        out.row_mut(2 * k).scale_mut(*wk);
        out.row_mut(2 * k + 1).scale_mut(*wk);
    }
    out
}

/// Huber weights per point (both coordinates) for the current residuals.
fn weights(r: &DVector<f64>) -> (Vec<f64>, f64) {
    let m = r.len() / 2;
    let mut norms: Vec<f64> = (0..m).map(|k| r[2 * k].hypot(r[2 * k + 1])).collect();
    let per_point = norms.clone();
    norms.sort_by(f64::total_cmp);
    let sigma = (1.4826 * norms[m / 2]).max(1e-9);
    let delta = 3.0 * sigma;
    (
        per_point
            .iter()
            .map(|&e| if e <= delta { 1.0 } else { delta / e })
            .collect(),
        sigma,
    )
}

fn levenberg_marquardt(setup: &Setup, mut x: Vec<f64>, cancel: &AtomicBool) -> Result<Vec<f64>> {
    let n = x.len();
    let cost = |r: &DVector<f64>, w: &[f64]| {
        (0..w.len())
            .map(|k| w[k] * (r[2 * k].powi(2) + r[2 * k + 1].powi(2)))
            .sum::<f64>()
    };
    let mut lambda = 1e-3;
    for _ in 0..200 {
        if cancel.load(Ordering::Relaxed) {
            return Err(Error::Cancelled);
        }
        let (r, j) = setup.residuals(&x, true);
        let j = j.expect("asked for");
        let (w, _) = weights(&r);
        let c0 = cost(&r, &w);
        let wj = weighted_rows(&j, &w);
        let mut wr = r.clone();
        for (k, wk) in w.iter().enumerate() {
            wr[2 * k] *= wk;
            wr[2 * k + 1] *= wk;
        }
        let jtj = j.transpose() * &wj;
        let g = j.transpose() * &wr;
        let mut improved = false;
        for _ in 0..20 {
            let mut a = jtj.clone();
            for i in 0..n {
                a[(i, i)] += lambda * jtj[(i, i)].max(1e-12);
            }
            let Some(step) = a.cholesky().map(|c| c.solve(&(-&g))) else {
                lambda *= 10.0;
                continue;
            };
            let next: Vec<f64> = x.iter().zip(step.iter()).map(|(a, b)| a + b).collect();
            let (rn, _) = setup.residuals(&next, false);
            let c1 = cost(&rn, &w);
            if c1.is_finite() && c1 < c0 {
                let small = step.norm() <= 1e-12 * (1.0 + DVector::from_vec(x.clone()).norm());
                x = next;
                lambda = (lambda / 10.0).max(1e-12);
                improved = true;
                if small || (c0 - c1) <= 1e-15 * c0 {
                    return Ok(x);
                }
                break;
            }
            lambda *= 10.0;
        }
        if !improved {
            return Ok(x);
        }
    }
    Ok(x)
}

fn finish(setup: &Setup, x: &[f64]) -> Result<Fit> {
    let (r, j) = setup.residuals(x, true);
    let j = j.expect("asked for");
    let (w, sigma) = weights(&r);
    let m = setup.points.len();
    let residuals: Vec<f64> = (0..m).map(|k| r[2 * k].hypot(r[2 * k + 1])).collect();
    let outliers: Vec<usize> = (0..m)
        .filter(|&k| residuals[k] > 3.0 * sigma && residuals[k] > 1e-6)
        .collect();
    let inliers: Vec<f64> = (0..m)
        .filter(|k| !outliers.contains(k))
        .map(|k| residuals[k])
        .collect();
    let rms = (inliers.iter().map(|e| e * e).sum::<f64>() / inliers.len().max(1) as f64).sqrt();
    let n = x.len();
    let ni = n - 6;
    let intr: Vec<f64> = if setup.free {
        x[..ni].to_vec()
    } else {
        setup.lens.intrinsics().to_vec()
    };
    let lens = Lens::new(setup.lens.model(), intr)
        .map_err(|e| Error::invalid("points", format!("the solution is unusable: {e}")))?;
    let rv = DVec3::new(x[ni], x[ni + 1], x[ni + 2]);
    let t = DVec3::new(x[ni + 3], x[ni + 4], x[ni + 5]);
    // Parameter uncertainty: s²·(JᵀWJ)⁻¹ with s² the weighted residual variance per degree of freedom.
    let wj = weighted_rows(&j, &w);
    let dof = (2 * m).saturating_sub(n).max(1) as f64;
    let s2 = (0..m).map(|k| w[k] * residuals[k].powi(2)).sum::<f64>() / dof;
    let cov = (j.transpose() * wj).try_inverse();
    let mut names: Vec<String> = if setup.free {
        setup.lens.model().intrinsics_names()
    } else {
        Vec::new()
    };
    names.extend(["r1", "r2", "r3", "t1", "t2", "t3"].map(String::from));
    let sigma_p = names
        .into_iter()
        .enumerate()
        .map(|(i, name)| {
            (
                name,
                cov.as_ref()
                    .map_or(f64::INFINITY, |c| (c[(i, i)].max(0.0) * s2).sqrt()),
            )
        })
        .collect();
    Ok(Fit {
        lens,
        r: crate::rig::rodrigues(rv),
        t,
        rms,
        residuals,
        outliers,
        sigma: sigma_p,
    })
}
