//! OpenCV's pinhole model with 4, 5, 8, 12 or 14 distortion coefficients
//! (`distCoeffs = k1 k2 p1 p2 [k3 [k4 k5 k6 [s1 s2 s3 s4 [τx τy]]]]`, missing terms 0), and the
//! plain pinhole as the case without distortion. docs/lens-models.md ("OpenCV pinhole"), in
//! OpenCV's order:
//!
//! x' = x/z, y' = y/z, r² = x'² + y'²,
//! g = (1 + k1 r² + k2 r⁴ + k3 r⁶) / (1 + k4 r² + k5 r⁴ + k6 r⁶),
//! x'' = x'·g + 2 p1 x'y' + p2 (r² + 2x'²) + s1 r² + s2 r⁴,
//! y'' = y'·g + p1 (r² + 2y'²) + 2 p2 x'y' + s3 r² + s4 r⁴,
//! then the tilt (14 coefficients): (a, b, c) = M(τx, τy)·(x'', y'', 1), x''' = a/c, y''' = b/c,
//! with M = Pz·Ry(τy)·Rx(τx) as in OpenCV's `computeTiltProjectionMatrix`; u = fx x''' + cx.
//! Points with z ≤ 0 are refused: OpenCV would project their antipode.

use super::Real;

/// (u, v) of camera-frame point p; `d` the distortion coefficients (any count up to 14).
pub fn project<T: Real>(core: [T; 4], d: &[T], p: [T; 3]) -> [T; 2] {
    let [fx, fy, cx, cy] = core;
    let zero = T::from(0.0);
    let k = |i: usize| d.get(i).copied().unwrap_or(zero);
    let (x, y) = (p[0] / p[2], p[1] / p[2]);
    let r2 = x * x + y * y;
    let (r4, r6) = (r2 * r2, r2 * r2 * r2);
    let one = T::from(1.0);
    let g = (one + k(0) * r2 + k(1) * r4 + k(4) * r6) / (one + k(5) * r2 + k(6) * r4 + k(7) * r6);
    let (p1, p2) = (k(2), k(3));
    let xd = x * g + p1 * x * y * 2.0 + p2 * (r2 + x * x * 2.0) + k(8) * r2 + k(9) * r4;
    let yd = y * g + p1 * (r2 + y * y * 2.0) + p2 * x * y * 2.0 + k(10) * r2 + k(11) * r4;
    let (xt, yt) = if d.len() > 12 {
        tilt(k(12), k(13), xd, yd)
    } else {
        (xd, yd)
    };
    [fx * xt + cx, fy * yt + cy]
}

/// OpenCV's tilted-sensor projection of (x'', y'', 1).
fn tilt<T: Real>(tx: T, ty: T, x: T, y: T) -> (T, T) {
    let (sx, cxx) = (tx.sin(), tx.cos());
    let (sy, cyy) = (ty.sin(), ty.cos());
    let zero = T::from(0.0);
    let one = T::from(1.0);
    // Rx(τx) and Ry(τy) as in OpenCV (row-major), Rt = Ry·Rx.
    let rx = [[one, zero, zero], [zero, cxx, sx], [zero, -sx, cxx]];
    let ry = [[cyy, zero, -sy], [zero, one, zero], [sy, zero, cyy]];
    let mut rt = [[zero; 3]; 3];
    for i in 0..3 {
        for j in 0..3 {
            rt[i][j] = ry[i][0] * rx[0][j] + ry[i][1] * rx[1][j] + ry[i][2] * rx[2][j];
        }
    }
    let pz = [
        [rt[2][2], zero, -rt[0][2]],
        [zero, rt[2][2], -rt[1][2]],
        [zero, zero, one],
    ];
    let v = [x, y, one];
    let mut m_v = [zero; 3];
    for (i, out) in m_v.iter_mut().enumerate() {
        // (Pz·Rt)·v
        let mut acc = zero;
        for (j, vj) in v.iter().enumerate() {
            let m_ij = pz[i][0] * rt[0][j] + pz[i][1] * rt[1][j] + pz[i][2] * rt[2][j];
            acc += m_ij * *vj;
        }
        *out = acc;
    }
    (m_v[0] / m_v[2], m_v[1] / m_v[2])
}

/// The undistorted normalised point (x', y') whose projection is pixel `q`, for models without
/// the tilt (at most 12 coefficients): Newton's method on the image plane with the closed-form
/// Jacobian of the distortion, started from `guess` (a neighbouring pixel's answer, which is
/// a step or two away). It stops where the residual is below 1e-10 px, the same criterion as
/// the general solver (`solve::unproject`), whose root it finds: inside the radius `fold`
/// where ρ·g(ρ) still rises there is one. `None` (the caller asks the general solver) when a
/// step leaves that radius or twelve steps do not converge. With the answer, the number of
/// Newton steps it took.
// Always inlined: its arguments and answer passed through memory cost a store-forwarding
// stall per call, a tenth of a 4K rig warp.
#[inline(always)]
pub fn undistort(
    core: [f64; 4],
    d: &[f64],
    q: [f64; 2],
    guess: [f64; 2],
    fold: f64,
) -> Option<([f64; 2], u32)> {
    let k = |i: usize| d.get(i).copied().unwrap_or(0.0);
    // Most lenses have neither the rational denominator nor the thin prism: their terms are
    // left out (where they are zero they add exact zeros, so the answer is the same bits).
    let rational = k(5) != 0.0 || k(6) != 0.0 || k(7) != 0.0;
    let prism = (8..12).any(|i| k(i) != 0.0);
    match (rational, prism) {
        (false, false) => newton::<false, false>(core, d, q, guess, fold),
        (true, false) => newton::<true, false>(core, d, q, guess, fold),
        (false, true) => newton::<false, true>(core, d, q, guess, fold),
        (true, true) => newton::<true, true>(core, d, q, guess, fold),
    }
}

#[inline(always)]
fn newton<const RATIONAL: bool, const PRISM: bool>(
    core: [f64; 4],
    d: &[f64],
    q: [f64; 2],
    guess: [f64; 2],
    fold: f64,
) -> Option<([f64; 2], u32)> {
    let [fx, fy, cx, cy] = core;
    let (tx, ty) = ((q[0] - cx) / fx, (q[1] - cy) / fy);
    let k = |i: usize| d.get(i).copied().unwrap_or(0.0);
    let (k1, k2, p1, p2, k3, k4, k5, k6) = (k(0), k(1), k(2), k(3), k(4), k(5), k(6), k(7));
    let (s1, s2, s3, s4) = (k(8), k(9), k(10), k(11));
    let [mut x, mut y] = guess;
    for steps in 0..12 {
        let r2 = x * x + y * y;
        if r2.is_nan() || r2 > fold * fold {
            return None;
        }
        let (r4, r6) = (r2 * r2, r2 * r2 * r2);
        let a = 1.0 + k1 * r2 + k2 * r4 + k3 * r6;
        // g and dg/d(r²)
        let (g, dg) = if RATIONAL {
            let b = 1.0 + k4 * r2 + k5 * r4 + k6 * r6;
            let da = (k1 + 2.0 * k2 * r2 + 3.0 * k3 * r4) * b;
            (
                a / b,
                (da - a * (k4 + 2.0 * k5 * r2 + 3.0 * k6 * r4)) / (b * b),
            )
        } else {
            (a, k1 + 2.0 * k2 * r2 + 3.0 * k3 * r4)
        };
        let (mut ex, mut ey) = (
            x * g + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x) - tx,
            y * g + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y - ty,
        );
        if PRISM {
            ex += s1 * r2 + s2 * r4;
            ey += s3 * r2 + s4 * r4;
        }
        // Squared pixel residual: no square root needed to compare it.
        if (fx * ex).powi(2) + (fy * ey).powi(2) < 1e-20 {
            return Some(([x, y], steps));
        }
        let mut j00 = g + 2.0 * x * x * dg + 2.0 * p1 * y + 6.0 * p2 * x;
        let mut j01 = 2.0 * x * y * dg + 2.0 * p1 * x + 2.0 * p2 * y;
        let mut j10 = j01;
        let mut j11 = g + 2.0 * y * y * dg + 6.0 * p1 * y + 2.0 * p2 * x;
        if PRISM {
            j00 += 2.0 * s1 * x + 4.0 * s2 * r2 * x;
            j01 += 2.0 * s1 * y + 4.0 * s2 * r2 * y;
            j10 += 2.0 * s3 * x + 4.0 * s4 * r2 * x;
            j11 += 2.0 * s3 * y + 4.0 * s4 * r2 * y;
        }
        let det = j00 * j11 - j01 * j10;
        if det == 0.0 || !det.is_finite() {
            return None;
        }
        let inv = 1.0 / det;
        x -= (j11 * ex - j01 * ey) * inv;
        y -= (j00 * ey - j10 * ex) * inv;
    }
    None
}
