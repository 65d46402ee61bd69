//! Iterative unprojection, as mrcal does it: the unknown is the ray's 2-D stereographic
//! coordinate w (a ray (w, 1 − |w|²/4) for every w, singular only straight behind), started from
//! the undistorted pinhole ray, and Levenberg–Marquardt drives the pixel residual of the
//! model's own projection to zero using its exact 2×2 Jacobian. It stops at a residual below
//! 1e-10 px; a pixel it cannot bring below 1e-8 px is refused, never answered with a wrong ray.
//! Rays behind the lens are searched only for models that can image them.

use super::{Lens, NoImage};
use glam::DVec3;
use num_dual::DualSVec64;

type D2 = DualSVec64<2>;

fn ray<T: super::Real>(w: [T; 2]) -> [T; 3] {
    let one = T::from(1.0);
    [w[0], w[1], one - (w[0] * w[0] + w[1] * w[1]) / 4.0]
}

pub fn unproject(lens: &Lens, q: [f64; 2]) -> Result<DVec3, NoImage> {
    let intr: Vec<D2> = lens.intrinsics().iter().map(|&v| D2::from_re(v)).collect();
    let i = lens.intrinsics();
    let seed = DVec3::new((q[0] - i[2]) / i[0], (q[1] - i[3]) / i[1], 1.0);
    let n = seed.length();
    let mut w = [2.0 * seed.x / (n + seed.z), 2.0 * seed.y / (n + seed.z)];
    // Residual and Jacobian at w; None where the ray is not in front of the lens.
    let eval = |w: [f64; 2]| -> Option<([f64; 2], [[f64; 2]; 2])> {
        let r = ray(w);
        let behind = r[2] <= 0.0 && !lens.model().meta().can_project_behind_camera;
        if behind || (r[2] > 0.0 && r[0].hypot(r[1]) / r[2] > lens.fold_radius()) {
            return None;
        }
        let wd = [
            D2::from_re(w[0]).derivative(0),
            D2::from_re(w[1]).derivative(1),
        ];
        let out = lens.formula(&intr, ray(wd));
        let j = out.map(|o| {
            let m = o.eps.unwrap_generic(nalgebra::U2, nalgebra::U1);
            [m[0], m[1]]
        });
        let res = [out[0].re - q[0], out[1].re - q[1]];
        res.iter().all(|v| v.is_finite()).then_some((res, j))
    };
    let norm = |r: [f64; 2]| r[0].hypot(r[1]);
    let (mut res, mut jac) =
        eval(w).ok_or(NoImage("the undistorted seed ray is outside the lens"))?;
    let mut lambda = 1e-6;
    for _ in 0..200 {
        if norm(res) < 1e-10 {
            break;
        }
        // (JᵀJ + λ·diag(JᵀJ)) δ = −Jᵀr, a 2×2 system.
        let a = [
            [
                jac[0][0] * jac[0][0] + jac[1][0] * jac[1][0],
                jac[0][0] * jac[0][1] + jac[1][0] * jac[1][1],
            ],
            [0.0, jac[0][1] * jac[0][1] + jac[1][1] * jac[1][1]],
        ];
        let g = [
            jac[0][0] * res[0] + jac[1][0] * res[1],
            jac[0][1] * res[0] + jac[1][1] * res[1],
        ];
        let (a00, a01, a11) = (a[0][0] * (1.0 + lambda), a[0][1], a[1][1] * (1.0 + lambda));
        let det = a00 * a11 - a01 * a01;
        if det == 0.0 || !det.is_finite() {
            return Err(NoImage("the lens model is singular at this pixel"));
        }
        let step = [
            -(a11 * g[0] - a01 * g[1]) / det,
            -(a00 * g[1] - a01 * g[0]) / det,
        ];
        let next = [w[0] + step[0], w[1] + step[1]];
        match eval(next) {
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
        return Err(NoImage("unprojection did not converge at this pixel"));
    }
    let r = ray(w);
    Ok(DVec3::from_array(r).normalize())
}
