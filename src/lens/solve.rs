//! Iterative unprojection, as mrcal does it: the unknown is the ray's 2-D stereographic
//! coordinate w (a ray (w, 1 − |w|²/4) for every w, singular only straight behind), started from
//! a guess or the undistorted pinhole ray, and Levenberg–Marquardt drives the pixel residual of
//! the model's own projection to zero. The 2×2 Jacobian comes from forward differences: three
//! plain evaluations cost less than one with dual numbers, and only the residual, not the
//! Jacobian, decides the answer's accuracy. It stops at a residual below 1e-10 px; a pixel it
//! cannot bring below 1e-8 px is refused, never answered with a wrong ray. Rays behind the lens
//! are searched only for models that can image them.

use super::{Lens, NoImage};
use glam::DVec3;

fn ray(w: [f64; 2]) -> [f64; 3] {
    [w[0], w[1], 1.0 - (w[0] * w[0] + w[1] * w[1]) / 4.0]
}

/// Residual and Jacobian at w; `None` where the ray is outside what the lens images.
fn eval(lens: &Lens, q: [f64; 2], w: [f64; 2]) -> Option<([f64; 2], [[f64; 2]; 2])> {
    let r = ray(w);
    let behind = r[2] <= 0.0 && !lens.model().meta().can_project_behind_camera;
    if behind || (r[2] > 0.0 && r[0].hypot(r[1]) / r[2] > lens.fold_radius()) {
        return None;
    }
    let i = lens.intrinsics();
    let at = |w: [f64; 2]| lens.formula(i, ray(w));
    let out = at(w);
    let h = 1e-7 * (1.0 + w[0].abs().max(w[1].abs()));
    let (ox, oy) = (at([w[0] + h, w[1]]), at([w[0], w[1] + h]));
    let j = [
        [(ox[0] - out[0]) / h, (oy[0] - out[0]) / h],
        [(ox[1] - out[1]) / h, (oy[1] - out[1]) / h],
    ];
    let res = [out[0] - q[0], out[1] - q[1]];
    res.iter()
        .chain(j.iter().flatten())
        .all(|v| v.is_finite())
        .then_some((res, j))
}

/// `guess`: a ray near the answer (a neighbouring pixel's), else the undistorted pinhole ray.
pub fn unproject(lens: &Lens, q: [f64; 2], guess: Option<DVec3>) -> Result<DVec3, NoImage> {
    let i = lens.intrinsics();
    let seed = guess.unwrap_or_else(|| DVec3::new((q[0] - i[2]) / i[0], (q[1] - i[3]) / i[1], 1.0));
    let n = seed.length();
    let mut w = [2.0 * seed.x / (n + seed.z), 2.0 * seed.y / (n + seed.z)];
    let (mut res, mut jac) = match (eval(lens, q, w), guess) {
        (Some(found), _) => found,
        // A guess outside the lens: start again from the undistorted ray.
        (None, Some(_)) => return unproject(lens, q, None),
        (None, None) => return Err(NoImage("the undistorted seed ray is outside the lens")),
    };
    let norm = |r: [f64; 2]| r[0].hypot(r[1]);
    let mut lambda = 1e-6;
    for _ in 0..200 {
        if norm(res) < 1e-10 {
            break;
        }
        // (JᵀJ + λ·diag(JᵀJ)) δ = −Jᵀr, a 2×2 system.
        let a00 = jac[0][0] * jac[0][0] + jac[1][0] * jac[1][0];
        let a01 = jac[0][0] * jac[0][1] + jac[1][0] * jac[1][1];
        let a11 = jac[0][1] * jac[0][1] + jac[1][1] * jac[1][1];
        let g = [
            jac[0][0] * res[0] + jac[1][0] * res[1],
            jac[0][1] * res[0] + jac[1][1] * res[1],
        ];
        let (a00, a11) = (a00 * (1.0 + lambda), a11 * (1.0 + lambda));
        let det = a00 * a11 - a01 * a01;
        if det == 0.0 || !det.is_finite() {
            return Err(NoImage("the lens model is singular at this pixel"));
        }
        let step = [
            -(a11 * g[0] - a01 * g[1]) / det,
            -(a00 * g[1] - a01 * g[0]) / det,
        ];
        let next = [w[0] + step[0], w[1] + step[1]];
        match eval(lens, q, next) {
            Some((r, j)) if norm(r) < norm(res) => {
                (w, res, jac) = (next, r, j);
                lambda = (lambda / 10.0).max(1e-12);
            }
            _ => {
                lambda *= 10.0;
                if lambda > 1e12 {
                    break;
                }
            }
        }
    }
    if norm(res) > 1e-8 {
        // A guess may have led into another branch; the plain start decides.
        if guess.is_some() {
            return unproject(lens, q, None);
        }
        return Err(NoImage("unprojection did not converge at this pixel"));
    }
    Ok(DVec3::from_array(ray(w)).normalize())
}
