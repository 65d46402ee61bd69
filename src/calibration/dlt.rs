//! Starting points without a user guess: the direct linear transform (Hartley-normalised) of
//! the 3×4 projection matrix, decomposed into intrinsics and pose; and, for known intrinsics,
//! the pose from undistorted rays (a homography when the wall points are coplanar).

use crate::error::{Error, Result};
use glam::{DMat3, DVec3};
use nalgebra::{DMatrix, Matrix3};

/// World→camera pose: p_cam = R·p + t.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pose {
    pub r: DMat3,
    pub t: DVec3,
}

fn to_na(m: DMat3) -> Matrix3<f64> {
    Matrix3::from_column_slice(&m.to_cols_array())
}

fn from_na(m: &Matrix3<f64>) -> DMat3 {
    DMat3::from_cols_array(&m.as_slice().try_into().expect("3×3"))
}

/// The nearest rotation to m (polar decomposition).
fn orthonormalise(m: DMat3) -> DMat3 {
    let svd = to_na(m).svd(true, true);
    let (u, vt) = (svd.u.expect("u"), svd.v_t.expect("v"));
    let mut r = u * vt;
    if r.determinant() < 0.0 {
        r = -r;
    }
    from_na(&r)
}

/// The unit vector h minimising |A·h|: the right singular vector of the smallest singular value.
fn null_vector(a: DMatrix<f64>) -> Result<nalgebra::DVector<f64>> {
    let svd = a.svd(false, true);
    let vt = svd
        .v_t
        .ok_or_else(|| Error::invalid("points", "the linear start did not converge"))?;
    let (imin, _) = svd
        .singular_values
        .iter()
        .enumerate()
        .fold((0, f64::MAX), |b, (i, &s)| if s < b.1 { (i, s) } else { b });
    Ok(vt.row(imin).transpose())
}

fn normaliser2(p: &[[f64; 2]]) -> ([f64; 2], f64) {
    let n = p.len() as f64;
    let c = [
        p.iter().map(|q| q[0]).sum::<f64>() / n,
        p.iter().map(|q| q[1]).sum::<f64>() / n,
    ];
    let d = p
        .iter()
        .map(|q| (q[0] - c[0]).hypot(q[1] - c[1]))
        .sum::<f64>()
        / n;
    (
        c,
        if d > 0.0 {
            std::f64::consts::SQRT_2 / d
        } else {
            1.0
        },
    )
}

fn normaliser3(p: &[DVec3]) -> (DVec3, f64) {
    let n = p.len() as f64;
    let c = p.iter().copied().sum::<DVec3>() / n;
    let d = p.iter().map(|q| q.distance(c)).sum::<f64>() / n;
    (c, if d > 0.0 { 3f64.sqrt() / d } else { 1.0 })
}

/// The 3×4 P with pixel ∝ P·(X, 1), from ≥ 6 non-coplanar points.
pub fn projection_matrix(pixels: &[[f64; 2]], world: &[DVec3]) -> Result<[[f64; 4]; 3]> {
    if pixels.len() < 6 {
        return Err(Error::invalid(
            "points",
            format!(
                "the linear start needs at least 6 points, got {}",
                pixels.len()
            ),
        ));
    }
    let (pc, ps) = normaliser2(pixels);
    let (wc, ws) = normaliser3(world);
    let mut a = DMatrix::<f64>::zeros(2 * pixels.len(), 12);
    for (i, (q, x)) in pixels.iter().zip(world).enumerate() {
        let (u, v) = ((q[0] - pc[0]) * ps, (q[1] - pc[1]) * ps);
        let x = (*x - wc) * ws;
        let xh = [x.x, x.y, x.z, 1.0];
        for k in 0..4 {
            a[(2 * i, k)] = xh[k];
            a[(2 * i, 8 + k)] = -u * xh[k];
            a[(2 * i + 1, 4 + k)] = xh[k];
            a[(2 * i + 1, 8 + k)] = -v * xh[k];
        }
    }
    let h = null_vector(a)?;
    // Undo the normalisations: P = Tp⁻¹ · Pn · Tw.
    let pn = [
        [h[0], h[1], h[2], h[3]],
        [h[4], h[5], h[6], h[7]],
        [h[8], h[9], h[10], h[11]],
    ];
    let tw = [
        [ws, 0.0, 0.0, -ws * wc.x],
        [0.0, ws, 0.0, -ws * wc.y],
        [0.0, 0.0, ws, -ws * wc.z],
        [0.0, 0.0, 0.0, 1.0],
    ];
    let tp_inv = [
        [1.0 / ps, 0.0, pc[0]],
        [0.0, 1.0 / ps, pc[1]],
        [0.0, 0.0, 1.0],
    ];
    let mut pw = [[0.0; 4]; 3];
    for (i, row) in pw.iter_mut().enumerate() {
        for (j, out) in row.iter_mut().enumerate() {
            *out = (0..4).map(|k| pn[i][k] * tw[k][j]).sum();
        }
    }
    let mut p = [[0.0; 4]; 3];
    for (i, row) in p.iter_mut().enumerate() {
        for (j, out) in row.iter_mut().enumerate() {
            *out = (0..3).map(|k| tp_inv[i][k] * pw[k][j]).sum();
        }
    }
    Ok(p)
}

/// K (fx, fy, cx, cy) and the pose from a projection matrix.
pub fn decompose(p: [[f64; 4]; 3], world: &[DVec3]) -> Result<([f64; 4], Pose)> {
    let mut p = p;
    // Points must end up in front of the projector.
    let depth =
        |p: &[[f64; 4]; 3], x: DVec3| p[2][0] * x.x + p[2][1] * x.y + p[2][2] * x.z + p[2][3];
    if world.iter().filter(|x| depth(&p, **x) > 0.0).count() * 2 < world.len() {
        p = p.map(|r| r.map(|v| -v));
    }
    let m = Matrix3::new(
        p[0][0], p[0][1], p[0][2], p[1][0], p[1][1], p[1][2], p[2][0], p[2][1], p[2][2],
    );
    // RQ decomposition M = K·R through QR of the reversed, transposed matrix.
    let flip = Matrix3::new(0.0, 0.0, 1.0, 0.0, 1.0, 0.0, 1.0, 0.0, 0.0);
    let qr = (flip * m).transpose().qr();
    let (q, r) = (qr.q(), qr.r());
    let mut k = flip * r.transpose() * flip;
    let mut rot = flip * q.transpose();
    // Positive diagonal of K.
    let mut s = Matrix3::identity();
    for i in 0..3 {
        if k[(i, i)] < 0.0 {
            s[(i, i)] = -1.0;
        }
    }
    k *= s;
    rot = s * rot;
    let scale = k[(2, 2)];
    if scale.abs() < 1e-300 || !scale.is_finite() {
        return Err(Error::invalid("points", "the linear start is degenerate"));
    }
    let k = k / scale;
    let p4 = nalgebra::Vector3::new(p[0][3], p[1][3], p[2][3]) / scale;
    let kinv = k
        .try_inverse()
        .ok_or_else(|| Error::invalid("points", "the linear start is degenerate"))?;
    let mut t = kinv * p4;
    if rot.determinant() < 0.0 {
        rot = -rot;
        t = -t;
    }
    let pose = Pose {
        r: orthonormalise(from_na(&rot)),
        t: DVec3::new(t[0], t[1], t[2]),
    };
    Ok(([k[(0, 0)], k[(1, 1)], k[(0, 2)], k[(1, 2)]], pose))
}

/// The pose from undistorted rays (x/z, y/z) of known intrinsics.
pub fn pose_from_rays(rays: &[[f64; 2]], world: &[DVec3]) -> Result<Pose> {
    if super::coplanar(world) {
        return pose_from_plane(rays, world);
    }
    let p = projection_matrix(rays, world)?;
    let (_, pose) = decompose(p, world)?;
    Ok(pose)
}

/// Pose from a homography between the wall plane and the normalised image (Zhang's method).
fn pose_from_plane(rays: &[[f64; 2]], world: &[DVec3]) -> Result<Pose> {
    if rays.len() < 4 {
        return Err(Error::invalid("points", "a plane needs at least 4 points"));
    }
    let n = world.len() as f64;
    let c = world.iter().copied().sum::<DVec3>() / n;
    let e1 = (world.iter().map(|p| *p - c).fold(DVec3::ZERO, |a, d| {
        if d.length() > a.length() { d } else { a }
    }))
    .normalize();
    let normal = world
        .iter()
        .map(|p| (*p - c).cross(e1))
        .fold(
            DVec3::ZERO,
            |a, d| if d.length() > a.length() { d } else { a },
        )
        .normalize();
    let e2 = normal.cross(e1);
    let plane: Vec<[f64; 2]> = world
        .iter()
        .map(|p| [(*p - c).dot(e1), (*p - c).dot(e2)])
        .collect();
    let mut a = DMatrix::<f64>::zeros(2 * rays.len(), 9);
    for (i, (r, x)) in rays.iter().zip(&plane).enumerate() {
        let xh = [x[0], x[1], 1.0];
        for k in 0..3 {
            a[(2 * i, k)] = xh[k];
            a[(2 * i, 6 + k)] = -r[0] * xh[k];
            a[(2 * i + 1, 3 + k)] = xh[k];
            a[(2 * i + 1, 6 + k)] = -r[1] * xh[k];
        }
    }
    let h = null_vector(a)?;
    let (h1, h2, h3) = (
        DVec3::new(h[0], h[3], h[6]),
        DVec3::new(h[1], h[4], h[7]),
        DVec3::new(h[2], h[5], h[8]),
    );
    let mut lambda = 2.0 / (h1.length() + h2.length());
    if h3.z * lambda < 0.0 {
        lambda = -lambda;
    }
    let (r1, r2, t) = (h1 * lambda, h2 * lambda, h3 * lambda);
    let r_plane = orthonormalise(DMat3::from_cols(r1, r2, r1.cross(r2)));
    // Plane coordinates → world: X = c + e1·a + e2·b, so R_world = R_plane·[e1 e2 n]ᵀ.
    let basis = DMat3::from_cols(e1, e2, normal);
    let r = r_plane * basis.transpose();
    Ok(Pose { r, t: t - r * c })
}
