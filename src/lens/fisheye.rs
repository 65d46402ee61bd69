//! OpenCV's fisheye model (Kannala–Brandt; docs/lens-models.md), intrinsics fx fy cx cy k1..k4:
//! θ = angle from the axis, θ_d = θ·(1 + k1θ² + k2θ⁴ + k3θ⁶ + k4θ⁸), and the pixel lies at
//! radius θ_d (in focal units) in the point's azimuth. Rays at 90° or more from the axis cannot
//! be represented (OpenCV would project their antipode); they are refused.
//!
//! The inverse is a safeguarded Newton solve of θ_d(θ) = ρ on [0, 90°): unlike OpenCV 4.14 it
//! does not clamp ρ to π/2 (a radius is not an angle), and it refuses pixels beyond the radius
//! where θ_d stops increasing, instead of returning a mirrored point.

use super::Real;

/// θ_d(θ) and its derivative.
pub fn theta_d(k: [f64; 4], t: f64) -> (f64, f64) {
    let t2 = t * t;
    let poly = 1.0 + t2 * (k[0] + t2 * (k[1] + t2 * (k[2] + t2 * k[3])));
    let dpoly = 1.0 + t2 * (3.0 * k[0] + t2 * (5.0 * k[1] + t2 * (7.0 * k[2] + t2 * 9.0 * k[3])));
    (t * poly, dpoly)
}

pub fn project<T: Real>(core: [T; 4], k: &[T], p: [T; 3]) -> [T; 2] {
    let [fx, fy, cx, cy] = core;
    let rho = (p[0] * p[0] + p[1] * p[1]).sqrt();
    let theta = rho.atan2(p[2]);
    let t2 = theta * theta;
    let td = theta * (T::from(1.0) + t2 * (k[0] + t2 * (k[1] + t2 * (k[2] + t2 * k[3]))));
    // Near the axis θ_d/ρ·(x, y) → (x, y)/z; the guard keeps the derivative finite there.
    let (xd, yd) = if rho > 1e-12 * p[2].re().abs().max(1e-300) {
        (td * p[0] / rho, td * p[1] / rho)
    } else {
        (p[0] / p[2], p[1] / p[2])
    };
    [fx * xd + cx, fy * yd + cy]
}

/// The end of the usable range of θ: 90°, or where θ_d stops rising if that comes first.
pub fn theta_limit(k: [f64; 4]) -> f64 {
    let limit = std::f64::consts::FRAC_PI_2;
    let steps = 2000;
    for i in 1..=steps {
        let t = limit * i as f64 / steps as f64;
        if theta_d(k, t).1 <= 0.0 {
            return limit * (i - 1) as f64 / steps as f64;
        }
    }
    limit
}

/// The angle θ ∈ [0, `hi`] with θ_d(θ) = ρ (`hi` from [`theta_limit`]), or `None` when there
/// is none.
pub fn solve_theta(k: [f64; 4], rho: f64, hi: f64) -> Option<f64> {
    if rho < 0.0 || rho > theta_d(k, hi).0 {
        return None;
    }
    let (mut lo, mut hi) = (0.0, hi);
    let mut t = rho.min(hi);
    for _ in 0..100 {
        let (f, df) = theta_d(k, t);
        let f = f - rho;
        if f.abs() <= 4.0 * f64::EPSILON * rho {
            break;
        }
        if f > 0.0 {
            hi = t;
        } else {
            lo = t;
        }
        let next = t - f / df;
        // Newton while it stays inside the bracket, bisection otherwise.
        t = if df > 0.0 && (lo..=hi).contains(&next) {
            next
        } else {
            0.5 * (lo + hi)
        };
        if hi - lo <= f64::EPSILON * hi {
            break;
        }
    }
    (theta_d(k, t).0 - rho)
        .abs()
        .le(&(1e-12 * rho.max(1.0)))
        .then_some(t)
}
