//! mrcal's `LENSMODEL_SPLINED_STEREOGRAPHIC_order=O_Nx=NX_Ny=NY_fov_x_deg=F`
//! (docs/lens-models.md, "splined stereographic"): the stereographic coordinate u = 2·(x, y)/(|p| +
//! z) plus a correction Δu from two B-spline surfaces (order 2 or 3) whose NX × NY control values
//! follow fx fy cx cy, interleaved (Δuₓ, Δu_y) with x fastest; q = f·(u + Δu) + c. Knots are spaced
//! s⁻¹ = 2·u_edge/(NX − 1 − m) apart (m = 2 for cubic, 1 for quadratic) with u_edge = 2·tan(F/4);
//! outside the grid the nearest patch extrapolates.

use super::Real;

#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Config {
    pub order: u32,
    pub nx: usize,
    pub ny: usize,
    pub fov_x_deg: f64,
}

impl Config {
    /// Knots per unit of u.
    fn segments_per_u(&self) -> f64 {
        let margin = if self.order == 3 { 2.0 } else { 1.0 };
        let u_edge = 2.0 * (self.fov_x_deg.to_radians() / 4.0).tan();
        (self.nx as f64 - 1.0 - margin) / (2.0 * u_edge)
    }

    /// For continuous knot coordinate `v` on an axis of `n` knots: the first knot of the patch
    /// and the basis weights over its knots (3 or 4 of them), as functions of the fraction.
    fn patch<T: Real>(&self, v: T, n: usize) -> (usize, Vec<T>) {
        if self.order == 3 {
            let i0 = (v.re().trunc() as i64).clamp(1, n as i64 - 3) as usize;
            let t = v - i0 as f64;
            let t2 = t * t;
            let t3 = t2 * t;
            let one = T::from(1.0);
            let b = vec![
                (one - t) * (one - t) * (one - t) / 6.0,
                (t3 * 3.0 - t2 * 6.0 + 4.0) / 6.0,
                (-t3 * 3.0 + t2 * 3.0 + t * 3.0 + 1.0) / 6.0,
                t3 / 6.0,
            ];
            (i0 - 1, b)
        } else {
            let i0 = ((v.re() + 0.5).trunc() as i64).clamp(1, n as i64 - 2) as usize;
            let t = v - i0 as f64;
            let b = vec![
                (t - 0.5) * (t - 0.5) / 2.0,
                T::from(0.75) - t * t,
                (t + 0.5) * (t + 0.5) / 2.0,
            ];
            (i0 - 1, b)
        }
    }

    /// The knots and weights Δu is made of at stereographic coordinate u: (index of the knot's
    /// Δuₓ control value among the intrinsics, weight).
    pub fn weights<T: Real>(&self, u: [T; 2]) -> Vec<(usize, T)> {
        let s = self.segments_per_u();
        let ix = u[0] * s + (self.nx as f64 - 1.0) / 2.0;
        let iy = u[1] * s + (self.ny as f64 - 1.0) / 2.0;
        let (x0, bx) = self.patch(ix, self.nx);
        let (y0, by) = self.patch(iy, self.ny);
        let mut out = Vec::with_capacity(bx.len() * by.len());
        for (j, wy) in by.iter().enumerate() {
            for (i, wx) in bx.iter().enumerate() {
                out.push((4 + 2 * ((y0 + j) * self.nx + (x0 + i)), *wy * *wx));
            }
        }
        out
    }
}

pub fn stereographic_u<T: Real>(p: [T; 3]) -> [T; 2] {
    let n = (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt();
    let s = T::from(2.0) / (n + p[2]);
    [p[0] * s, p[1] * s]
}

pub fn project<T: Real>(cfg: &Config, intr: &[T], p: [T; 3]) -> [T; 2] {
    let u = stereographic_u(p);
    let mut du = [T::from(0.0), T::from(0.0)];
    for (at, w) in cfg.weights(u) {
        du[0] += w * intr[at];
        du[1] += w * intr[at + 1];
    }
    [
        intr[0] * (u[0] + du[0]) + intr[2],
        intr[1] * (u[1] + du[1]) + intr[3],
    ]
}
