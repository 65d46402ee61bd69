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
