//! JPL's CAHVOR as mrcal parametrises it (docs/lens-models.md, "CAHVOR"), intrinsics
//! fx fy cx cy α β r0 r1 r2: a radial stretch about the axis o = (sin α cos β, sin β, cos α cos β),
//! ω = p·o, τ = |p|²/ω² − 1, μ = r0 + r1 τ + r2 τ², p' = p + μ (p − ω o), then a pinhole.

use super::Real;

/// ω and the stretched point p'.
fn stretch<T: Real>(k: &[T], p: [T; 3]) -> (T, [T; 3]) {
    let (alpha, beta) = (k[0], k[1]);
    let o = [
        alpha.sin() * beta.cos(),
        beta.sin(),
        alpha.cos() * beta.cos(),
    ];
    let omega = p[0] * o[0] + p[1] * o[1] + p[2] * o[2];
    let n2 = p[0] * p[0] + p[1] * p[1] + p[2] * p[2];
    let tau = n2 / (omega * omega) - 1.0;
    let mu = k[2] + k[3] * tau + k[4] * tau * tau;
    (omega, [0, 1, 2].map(|i| p[i] + mu * (p[i] - omega * o[i])))
}

pub fn project<T: Real>(core: [T; 4], k: &[T], p: [T; 3]) -> [T; 2] {
    let [fx, fy, cx, cy] = core;
    let (_, pp) = stretch(k, p);
    [fx * pp[0] / pp[2] + cx, fy * pp[1] / pp[2] + cy]
}

/// ω and p'_z: a point is imaged only where both are positive.
pub fn depths(k: &[f64], p: [f64; 3]) -> (f64, f64) {
    let (omega, pp) = stretch(k, p);
    (omega, pp[2])
}
