//! The wall measured, not assumed: two cameras of known pose film the same projector, the
//! projector pixel both decode ties a pixel of one camera to a pixel of the other, and the two
//! rays meet on the wall. A surface fitted to those points gives its parameters (a dome's
//! centre and radius here).

use super::decode::Decoded;
use crate::rig::Channel;
use glam::DVec3;
use rayon::prelude::*;

/// Wall points triangulated from two decoded captures of one projector (`size` its
/// resolution), by cameras `a` and `b` of known pose. Every `step`-th decoded pixel of `a`
/// (each way) is matched to a sub-pixel position in `b` through their common projector
/// coordinate; pairs whose rays pass further than `gap` metres apart are left out.
pub fn triangulate(
    a: (&Decoded, &Channel),
    b: (&Decoded, &Channel),
    size: [u32; 2],
    step: u32,
    gap: f64,
) -> Vec<DVec3> {
    let (da, ca) = a;
    let (db, cb) = b;
    // Which pixel of b decodes to each projector pixel (the most confident of several).
    let (pw, ph) = (size[0] as usize, size[1] as usize);
    let mut index: Vec<Option<(u32, u32, f64)>> = vec![None; pw * ph];
    for y in 0..db.height {
        for x in 0..db.width {
            let Some(s) = db.get(x, y) else { continue };
            let (i, j) = (s.q[0].round(), s.q[1].round());
            if i < 0.0 || j < 0.0 || i >= pw as f64 || j >= ph as f64 {
                continue;
            }
            let cell = &mut index[j as usize * pw + i as usize];
            if cell.is_none_or(|c| s.sigma < c.2) {
                *cell = Some((x, y, s.sigma));
            }
        }
    }
    let step = step.max(1);
    let rows: Vec<u32> = (0..da.height).step_by(step as usize).collect();
    rows.par_iter()
        .flat_map_iter(|&y| {
            let index = &index;
            (0..da.width).step_by(step as usize).filter_map(move |x| {
                let s = da.get(x, y)?;
                let (i, j) = (s.q[0].round(), s.q[1].round());
                if i < 0.0 || j < 0.0 || i >= pw as f64 || j >= ph as f64 {
                    return None;
                }
                let (bx, by, _) = index[j as usize * pw + i as usize]?;
                let pb = subpixel(db, bx, by, s.q)?;
                let ra = ca.rotation * ca.lens.unproject([f64::from(x), f64::from(y)]).ok()?;
                let rb = cb.rotation * cb.lens.unproject(pb).ok()?;
                meet(ca.position, ra, cb.position, rb, gap)
            })
        })
        .collect()
}

/// The sub-pixel position in `d` near pixel (x, y) that decodes to projector coordinate `q`:
/// the decoded map fitted as affine over the 5×5 pixels around, then inverted.
fn subpixel(d: &Decoded, x: u32, y: u32, q: [f64; 2]) -> Option<[f64; 2]> {
    // Least squares of q(u, v) = q0 + J·(u, v) over the neighbourhood, (u, v) from (x, y).
    let mut ata = nalgebra::Matrix3::<f64>::zeros();
    let mut atb = [nalgebra::Vector3::<f64>::zeros(); 2];
    let mut n = 0;
    for dy in -2i32..=2 {
        for dx in -2i32..=2 {
            let (u, v) = (x as i32 + dx, y as i32 + dy);
            if u < 0 || v < 0 || u >= d.width as i32 || v >= d.height as i32 {
                continue;
            }
            let Some(s) = d.get(u as u32, v as u32) else {
                continue;
            };
            let row = nalgebra::Vector3::new(1.0, f64::from(dx), f64::from(dy));
            ata += row * row.transpose();
            for (sum, q) in atb.iter_mut().zip(s.q) {
                *sum += row * q;
            }
            n += 1;
        }
    }
    if n < 6 {
        return None;
    }
    let inv = ata.try_inverse()?;
    let (c0, c1) = (inv * atb[0], inv * atb[1]);
    let j = nalgebra::Matrix2::new(c0[1], c0[2], c1[1], c1[2]);
    let d = j.try_inverse()? * nalgebra::Vector2::new(q[0] - c0[0], q[1] - c1[0]);
    // The answer must lie within the neighbourhood the fit describes.
    (d.amax() <= 2.0).then(|| [f64::from(x) + d[0], f64::from(y) + d[1]])
}

/// The midpoint of the closest approach of two rays, if they pass within `gap` of each other
/// in front of both origins.
fn meet(pa: DVec3, ra: DVec3, pb: DVec3, rb: DVec3, gap: f64) -> Option<DVec3> {
    let w = pa - pb;
    let (a, b, c) = (ra.dot(ra), ra.dot(rb), rb.dot(rb));
    let (d, e) = (ra.dot(w), rb.dot(w));
    let den = a * c - b * b;
    if den < 1e-12 {
        return None;
    }
    let (s, t) = ((b * e - c * d) / den, (a * e - b * d) / den);
    if s <= 0.0 || t <= 0.0 {
        return None;
    }
    let (p, q) = (pa + ra * s, pb + rb * t);
    ((p - q).length() <= gap).then(|| (p + q) / 2.0)
}

/// The sphere nearest `points`: centre and radius, by the algebraic fit refined by
/// Gauss–Newton on the points' distances to the surface. `None` for fewer than 4 points or
/// points on a plane.
pub fn fit_sphere(points: &[DVec3]) -> Option<(DVec3, f64)> {
    if points.len() < 4 {
        return None;
    }
    // |p|² = 2 c·p + k, with k = r² − |c|²: linear in (c, k).
    let mut ata = nalgebra::Matrix4::<f64>::zeros();
    let mut atb = nalgebra::Vector4::<f64>::zeros();
    for p in points {
        let row = nalgebra::Vector4::new(2.0 * p.x, 2.0 * p.y, 2.0 * p.z, 1.0);
        ata += row * row.transpose();
        atb += row * p.length_squared();
    }
    let x = ata.try_inverse()? * atb;
    let mut c = DVec3::new(x[0], x[1], x[2]);
    let mut r = (x[3] + c.length_squared()).sqrt();
    if !r.is_finite() {
        return None;
    }
    for _ in 0..10 {
        // Residual |p − c| − r; its gradient in (c, r) is (−(p − c)/|p − c|, −1).
        let mut jtj = nalgebra::Matrix4::<f64>::zeros();
        let mut jtr = nalgebra::Vector4::<f64>::zeros();
        for p in points {
            let d = *p - c;
            let len = d.length();
            if len < 1e-12 {
                continue;
            }
            let u = d / len;
            let row = nalgebra::Vector4::new(-u.x, -u.y, -u.z, -1.0);
            jtj += row * row.transpose();
            jtr += row * (len - r);
        }
        let step = jtj.try_inverse()? * -jtr;
        c += DVec3::new(step[0], step[1], step[2]);
        r += step[3];
        if step.norm() < 1e-12 {
            break;
        }
    }
    Some((c, r))
}
