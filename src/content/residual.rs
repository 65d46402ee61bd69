//! Seed 001's local warping split for cylindrical panoramas, as an alternative lookup.
//!
//! The seed could not evaluate atan2 per pixel on 2002 hardware, so it split the cylinder's
//! mapping around a *direction of projection* (DOP) θₖ: a direction is projected onto the plane
//! at unit distance along the DOP, at plane coordinates (x′, y′), and
//!
//! * θ = θₖ + atan(x′)                 = θₖ + a·x′ + R_θ(x′)
//! * y / (ρ·H) = y′ / (H·√(1 + x′²))  = b·y′ + R_v(x′, y′)
//!
//! with a and b the least-squares linear parts and the residuals R_θ, R_v read from tables
//! (the seed's 256×256 bump map; bilinear here). Each of [`SECTORS`] DOPs serves the quarter of
//! the circle nearest it, so |x′| ≤ tan 45° = 1, and the sector edges fall on the ±180° seam.
//!
//! What it costs in accuracy is measured (`residual_split_error_is_bounded`): with f32 tables of
//! [`TABLE`] entries the lookup is within 1/250 of a texel of the exact one on a
//! 4096-texel panorama; with the seed's 8-bit residuals it is off by about half a texel.

use glam::DVec3;
use std::f64::consts::PI;

/// Sectors around the circle, one per DOP.
pub const SECTORS: usize = 4;

/// Table entries along x′ and along y′ (the seed's bump map was 256×256).
pub const TABLE: usize = 256;

/// Seed 001's lookup of a cylindrical panorama: per direction of projection, a linear part plus
/// residual tables, in place of an atan2 per sample.
#[derive(Debug, Clone, PartialEq)]
pub struct ResidualSplit {
    /// Per sector: the DOP's unit normal and tangent in the horizontal plane, and its azimuth.
    dops: [(DVec3, DVec3, f64); SECTORS],
    a: f64,
    b: f64,
    /// Half-widths of the tables' domains: |x′| ≤ x_max, |y′| ≤ y_max.
    x_max: f64,
    y_max: f64,
    r_theta: Vec<f32>,
    /// TABLE × TABLE, y′ rows of x′ columns.
    r_v: Vec<f32>,
}

/// Table position of `x` in [−max, max]: the cell and the fraction in it.
#[inline]
fn cell(x: f64, max: f64) -> (usize, f64) {
    let f = ((x / max + 1.0) * 0.5 * (TABLE - 1) as f64).clamp(0.0, (TABLE - 1) as f64);
    let i = (f as usize).min(TABLE - 2);
    (i, f - i as f64)
}

impl ResidualSplit {
    /// The split for a cylinder of height `h` (= 2·tan(vfov/2)); `bits` quantises the
    /// residuals to that many signed bits of their range, as the seed's 8-bit bump offsets
    /// were (`None`: f32).
    pub fn new(h: f64, bits: Option<u32>) -> Self {
        let dops = std::array::from_fn(|k| {
            let theta = -PI + (k as f64 + 0.5) * 2.0 * PI / SECTORS as f64;
            let n = DVec3::new(theta.sin(), 0.0, -theta.cos());
            let t = DVec3::new(theta.cos(), 0.0, theta.sin());
            (n, t, theta)
        });
        let x_max = (PI / SECTORS as f64).tan();
        // Where the panorama ends: |y′| = (H/2)·√(1 + x′²), widest at the sector's edge.
        let y_max = 0.5 * h * (1.0 + x_max * x_max).sqrt();
        let node = |i: usize, max: f64| (2.0 * i as f64 / (TABLE - 1) as f64 - 1.0) * max;
        let g = |x: f64| 1.0 / (h * (1.0 + x * x).sqrt());
        // Least squares over the table's nodes.
        let (mut xa, mut xx) = (0.0, 0.0);
        for i in 0..TABLE {
            let x = node(i, x_max);
            xa += x * x.atan();
            xx += x * x;
        }
        let a = xa / xx;
        let b = (0..TABLE).map(|i| g(node(i, x_max))).sum::<f64>() / TABLE as f64;
        let r_theta: Vec<f64> = (0..TABLE)
            .map(|i| {
                let x = node(i, x_max);
                x.atan() - a * x
            })
            .collect();
        let mut r_v = Vec::with_capacity(TABLE * TABLE);
        for j in 0..TABLE {
            let y = node(j, y_max);
            for i in 0..TABLE {
                r_v.push(y * (g(node(i, x_max)) - b));
            }
        }
        let quantise = |t: Vec<f64>| -> Vec<f32> {
            let Some(bits) = bits else {
                return t.iter().map(|&v| v as f32).collect();
            };
            let range = t
                .iter()
                .fold(0.0f64, |m, v| m.max(v.abs()))
                .max(f64::MIN_POSITIVE);
            let steps = f64::from((1u32 << (bits - 1)) - 1);
            t.iter()
                .map(|&v| ((v / range * steps).round() / steps * range) as f32)
                .collect()
        };
        ResidualSplit {
            dops,
            a,
            b,
            x_max,
            y_max,
            r_theta: quantise(r_theta),
            r_v: quantise(r_v),
        }
    }

    /// Azimuth θ (radians, 0 towards −z, as atan2(x, −z)) and height y/(ρ·H) of direction
    /// `d`, from the linear parts and the tables; `None` straight up or down, or beyond the
    /// tables' height (where the panorama ends anyway).
    #[inline]
    pub fn angles(&self, d: DVec3) -> Option<(f64, f64)> {
        let (mut best, mut along) = (0, f64::MIN);
        for (k, (n, _, _)) in self.dops.iter().enumerate() {
            let c = d.x * n.x + d.z * n.z;
            if c > along {
                (best, along) = (k, c);
            }
        }
        if along <= 0.0 {
            return None;
        }
        let (_, t, theta0) = self.dops[best];
        let x = (d.x * t.x + d.z * t.z) / along;
        let y = d.y / along;
        if y.abs() > self.y_max {
            return None;
        }
        let (i, fx) = cell(x, self.x_max);
        let rt = f64::from(self.r_theta[i]) * (1.0 - fx) + f64::from(self.r_theta[i + 1]) * fx;
        let (j, fy) = cell(y, self.y_max);
        let row = |j: usize| {
            let r = &self.r_v[j * TABLE..];
            f64::from(r[i]) * (1.0 - fx) + f64::from(r[i + 1]) * fx
        };
        let rv = row(j) * (1.0 - fy) + row(j + 1) * fy;
        Some((theta0 + self.a * x + rt, self.b * y + rv))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Largest distance, in texels of a 4096 × 1024 panorama (360° × 90°), between the split's
    /// lookup and the exact one, over a million directions the panorama covers.
    fn worst_texels(split: &ResidualSplit, h: f64) -> f64 {
        let (w, rows) = (4096.0, 1024.0);
        let mut worst = 0.0f64;
        let mut bits = crate::raster::xorshift(0x9E37_79B9_7F4A_7C15);
        let mut next = || (bits() >> 11) as f64 / (1u64 << 53) as f64;
        for _ in 0..1_000_000 {
            let theta = (next() * 2.0 - 1.0) * PI;
            let up = (next() - 0.5) * h * 0.999;
            let d = DVec3::new(theta.sin(), up, -theta.cos()).normalize() * (0.5 + next());
            let (t, v) = split.angles(d).expect("covered");
            let exact_v = d.y / (d.x.hypot(d.z) * h);
            let mut dt = (t - theta).abs();
            dt = dt.min(2.0 * PI - dt);
            worst = worst
                .max(dt / (2.0 * PI) * w)
                .max((v - exact_v).abs() * rows);
        }
        worst
    }

    #[test]
    fn residual_split_error_is_bounded() {
        let h = 2.0 * (PI / 4.0).tan();
        let f32_tables = worst_texels(&ResidualSplit::new(h, None), h);
        let seed = worst_texels(&ResidualSplit::new(h, Some(8)), h);
        eprintln!("residual split: f32 {f32_tables:.2e} texels, 8-bit {seed:.3} texels");
        // Measured 3.9e-3 and 0.49 texels.
        assert!(f32_tables < 5e-3, "{f32_tables}");
        assert!(seed > 0.05 && seed < 1.0, "{seed}");
    }

    #[test]
    fn the_sectors_meet_at_the_seam() {
        let split = ResidualSplit::new(2.0, None);
        for theta in [PI - 1e-9, -PI + 1e-9, PI / 2.0, 0.0, -PI / 2.0] {
            let d = DVec3::new(theta.sin(), 0.1, -theta.cos());
            let (t, _) = split.angles(d).unwrap();
            assert!((t - theta).abs() < 1e-5, "{theta}: {t}");
        }
    }
}
