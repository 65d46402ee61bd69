//! The wall measured, not assumed: two cameras of known pose film the same projector, the
//! projector pixel both decode ties a pixel of one camera to a pixel of the other, and the two
//! rays meet on the wall. The rig's own kind of surface fitted to those points gives its
//! parameters: a dome's centre and radius, a cylinder's axis and radius, a plane's normal and
//! offset. What the points cannot tell is kept from the rig: a sphere has no orientation (the
//! dome's tilt and rim stay), points on a cylinder do not say where along its axis its centre is
//! (the rig's centre is moved onto the fitted axis), and the extents of each shape stay.

use super::decode::Decoded;
use crate::error::{Error, Result};
use crate::rig::Channel;
use crate::surface::{Cylinder, Dome, Plane, Screen};
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

/// The axis and radius of the cylinder nearest `points`, by Gauss–Newton on the points'
/// distances to the surface from `start` (the rig's cylinder: the fit needs to begin near the
/// answer, which a rig document is). Returns a point on the axis, the unit axis (on the side of
/// `start`'s) and the radius; `None` when the points do not determine them (fewer than 5, or
/// all on one line along the axis).
pub fn fit_cylinder(points: &[DVec3], start: &Cylinder) -> Option<(DVec3, DVec3, f64)> {
    if points.len() < 5 {
        return None;
    }
    let mut a = DVec3::from_array(start.axis).normalize();
    let mut c = DVec3::from_array(start.centre);
    let mut r = start.radius;
    for _ in 0..30 {
        // Moves: the axis tilted by α, β along u, v; its point moved by γ, δ along u, v; r.
        let u = a.any_orthonormal_vector();
        let v = a.cross(u);
        let mut jtj = nalgebra::Matrix5::<f64>::zeros();
        let mut jtr = nalgebra::Vector5::<f64>::zeros();
        for p in points {
            let d = *p - c;
            let along = d.dot(a);
            let perp = d - a * along;
            let rho = perp.length();
            if rho < 1e-12 {
                continue;
            }
            let (pu, pv) = (perp.dot(u) / rho, perp.dot(v) / rho);
            let row = nalgebra::Vector5::new(-pu * along, -pv * along, -pu, -pv, -1.0);
            jtj += row * row.transpose();
            jtr += row * (rho - r);
        }
        let step = jtj.try_inverse()? * -jtr;
        if !step.iter().all(|s| s.is_finite()) {
            return None;
        }
        a = (a + u * step[0] + v * step[1]).normalize();
        c += u * step[2] + v * step[3];
        r += step[4];
        if step.norm() < 1e-12 {
            break;
        }
    }
    (r > 0.0 && r.is_finite()).then_some((c, a, r))
}

/// The plane nearest `points`: its centroid and unit normal (the eigenvector of their scatter
/// with the smallest eigenvalue). `None` for fewer than 3 points or points on a line.
pub fn fit_plane(points: &[DVec3]) -> Option<(DVec3, DVec3)> {
    if points.len() < 3 {
        return None;
    }
    let mean = points.iter().copied().sum::<DVec3>() / points.len() as f64;
    let mut scatter = nalgebra::Matrix3::<f64>::zeros();
    for p in points {
        let d = nalgebra::Vector3::new(p.x - mean.x, p.y - mean.y, p.z - mean.z);
        scatter += d * d.transpose();
    }
    let eig = nalgebra::SymmetricEigen::new(scatter);
    let mut order = [0, 1, 2];
    order.sort_by(|&i, &j| eig.eigenvalues[i].total_cmp(&eig.eigenvalues[j]));
    if eig.eigenvalues[order[1]] <= 1e-12 * eig.eigenvalues[order[2]].max(1e-300) {
        return None;
    }
    let n = eig.eigenvectors.column(order[0]);
    Some((mean, DVec3::new(n[0], n[1], n[2]).normalize()))
}

/// What measuring the wall found.
#[derive(Debug, Clone, PartialEq)]
pub struct WallFit {
    /// The rig's screen with the fitted parameters.
    pub screen: Screen,
    /// Points fitted, and points left out as outliers (more than 5 robust deviations off).
    pub count: usize,
    /// Points left out of the second fit (more than 5 robust deviations off the first).
    pub outliers: usize,
    /// RMS and largest distance of the fitted points to the fitted surface, metres.
    pub rms: f64,
    /// Largest distance of a fitted point to the fitted surface, metres.
    pub max: f64,
}

/// Fits `screen`'s own kind of surface to `points` (see the module's notes for what is kept),
/// once on all points and again without those more than 5 robust deviations off the first
/// fit. Mesh screens are refused: their shape is the file's.
pub fn fit_screen(screen: &Screen, points: &[DVec3]) -> Result<WallFit> {
    let too_few = || {
        Error::invalid(
            "points",
            format!(
                "{} triangulated wall points do not determine the surface; do both cameras \
                 see the projector's light, from positions far enough apart?",
                points.len()
            ),
        )
    };
    let once = |points: &[DVec3]| -> Result<Screen> {
        Ok(match screen {
            Screen::Dome(d) => {
                let (centre, radius) = fit_sphere(points).ok_or_else(too_few)?;
                Screen::Dome(Dome {
                    radius,
                    centre: centre.to_array(),
                    ..d.clone()
                })
            }
            Screen::Cylinder(cyl) => {
                let (on_axis, axis, radius) = fit_cylinder(points, cyl).ok_or_else(too_few)?;
                let axis = if axis.dot(DVec3::from_array(cyl.axis)) < 0.0 {
                    -axis
                } else {
                    axis
                };
                let old = DVec3::from_array(cyl.centre);
                let centre = on_axis + axis * (old - on_axis).dot(axis);
                Screen::Cylinder(Cylinder {
                    radius,
                    centre: centre.to_array(),
                    axis: axis.to_array(),
                    ..cyl.clone()
                })
            }
            Screen::Plane(pl) => {
                let (mean, normal) = fit_plane(points).ok_or_else(too_few)?;
                let normal = if normal.dot(DVec3::from_array(pl.normal)) < 0.0 {
                    -normal
                } else {
                    normal
                };
                let old = DVec3::from_array(pl.centre);
                Screen::Plane(Plane {
                    centre: (old - normal * (old - mean).dot(normal)).to_array(),
                    normal: normal.to_array(),
                    ..pl.clone()
                })
            }
            Screen::Mesh { .. } => {
                return Err(Error::invalid(
                    "screen",
                    "a mesh wall's shape is its file's; measure a dome, cylinder or plane",
                ));
            }
        })
    };
    let first = once(points)?;
    let off: Vec<f64> = points.iter().map(|p| distance(&first, *p)).collect();
    let mut sorted: Vec<f64> = off.iter().map(|d| d.abs()).collect();
    sorted.sort_by(f64::total_cmp);
    // 1.4826 × the median absolute deviation estimates σ; the floor keeps exact points.
    let bound = (5.0 * 1.4826 * sorted[sorted.len() / 2]).max(1e-9);
    let kept: Vec<DVec3> = points
        .iter()
        .zip(&off)
        .filter(|(_, d)| d.abs() <= bound)
        .map(|(p, _)| *p)
        .collect();
    let screen = once(&kept)?;
    let off: Vec<f64> = kept.iter().map(|p| distance(&screen, *p).abs()).collect();
    let rms = (off.iter().map(|d| d * d).sum::<f64>() / off.len() as f64).sqrt();
    screen.validate("screen")?;
    Ok(WallFit {
        screen,
        count: kept.len(),
        outliers: points.len() - kept.len(),
        rms,
        max: off.iter().copied().fold(0.0, f64::max),
    })
}

/// The signed distance from `p` to the full surface (sphere, infinite cylinder or plane).
fn distance(screen: &Screen, p: DVec3) -> f64 {
    match screen {
        Screen::Dome(d) => (p - DVec3::from_array(d.centre)).length() - d.radius,
        Screen::Cylinder(c) => {
            let a = DVec3::from_array(c.axis).normalize();
            let d = p - DVec3::from_array(c.centre);
            (d - a * d.dot(a)).length() - c.radius
        }
        Screen::Plane(pl) => (p - DVec3::from_array(pl.centre)).dot(DVec3::from_array(pl.normal)),
        Screen::Mesh { .. } => 0.0,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Points on a cylinder of radius 2.5 whose axis leans 4° and passes 10 cm off the origin,
    /// over a 100° arc and 1.5 m of height, with `bad` of them thrown 0.2 m off.
    fn leaning_cylinder(bad: usize) -> (Vec<DVec3>, DVec3, DVec3) {
        let axis = DVec3::new(4f64.to_radians().sin(), 4f64.to_radians().cos(), 0.0);
        let on_axis = DVec3::new(0.1, 0.0, 0.0);
        let u = axis.any_orthonormal_vector();
        let v = axis.cross(u);
        let mut points = Vec::new();
        for i in 0..40 {
            for j in 0..30 {
                let a = (-50.0 + 100.0 * f64::from(i) / 39.0).to_radians();
                let h = -0.5 + 1.5 * f64::from(j) / 29.0;
                points.push(on_axis + axis * h + (u * a.cos() + v * a.sin()) * 2.5);
            }
        }
        let every = points.len() / bad.max(1);
        for p in points.iter_mut().step_by(every).take(bad) {
            *p *= 1.08;
        }
        (points, on_axis, axis)
    }

    fn rig_cylinder() -> Cylinder {
        Cylinder {
            radius: 2.0,
            centre: [0.0, 0.3, 0.0],
            axis: [0.0, 1.0, 0.0],
            height: [-1.0, 1.0],
            arc: [-180.0, 180.0],
        }
    }

    #[test]
    fn a_cylinder_is_fitted_from_a_wrong_start_and_its_centre_kept_on_the_axis() {
        let (points, on_axis, axis) = leaning_cylinder(0);
        let (c, a, r) = fit_cylinder(&points, &rig_cylinder()).unwrap();
        assert!((r - 2.5).abs() < 1e-9, "{r}");
        assert!(a.angle_between(axis) < 1e-9, "{a}");
        let off = (c - on_axis) - axis * (c - on_axis).dot(axis);
        assert!(off.length() < 1e-9, "{c}");
        let fit = fit_screen(&Screen::Cylinder(rig_cylinder()), &points).unwrap();
        let Screen::Cylinder(fitted) = &fit.screen else {
            panic!()
        };
        // The rig's centre moved onto the axis along the shortest way: heights keep meaning.
        let centre = DVec3::from_array(fitted.centre);
        let along = (DVec3::new(0.0, 0.3, 0.0) - on_axis).dot(axis);
        assert!(
            (centre - (on_axis + axis * along)).length() < 1e-9,
            "{centre}"
        );
        assert!(fit.rms < 1e-9 && fit.outliers == 0, "{fit:?}");
    }

    #[test]
    fn outliers_are_left_out_of_the_second_fit() {
        let (points, _, _) = leaning_cylinder(60);
        let fit = fit_screen(&Screen::Cylinder(rig_cylinder()), &points).unwrap();
        let Screen::Cylinder(fitted) = &fit.screen else {
            panic!()
        };
        assert_eq!(fit.outliers, 60);
        assert!((fitted.radius - 2.5).abs() < 1e-9, "{}", fitted.radius);
    }

    #[test]
    fn a_plane_keeps_its_side_and_a_sphere_its_tilt() {
        let normal = DVec3::new(0.1, 0.0, 1.0).normalize();
        let points: Vec<DVec3> = (0..100)
            .map(|i| {
                let (x, y) = (f64::from(i % 10) * 0.3, f64::from(i / 10) * 0.2);
                let p = DVec3::new(x, y, 0.0);
                p - normal * (p.dot(normal) + 2.0)
            })
            .collect();
        let plane = Plane {
            centre: [0.0, 0.0, -1.5],
            normal: [0.0, 0.0, 1.0],
            up: [0.0, 1.0, 0.0],
            width: 4.0,
            height: 2.0,
        };
        let fit = fit_screen(&Screen::Plane(plane), &points).unwrap();
        let Screen::Plane(p) = &fit.screen else {
            panic!()
        };
        assert!(DVec3::from_array(p.normal).angle_between(normal) < 1e-9);
        assert!((DVec3::from_array(p.centre).dot(normal) + 2.0).abs() < 1e-9);
        let dome = Dome {
            radius: 2.0,
            centre: [0.0; 3],
            tilt: 15.0,
            min_elevation: 0.0,
        };
        let sphere: Vec<DVec3> = (0..200)
            .map(|i| {
                let (a, e) = (f64::from(i % 20) * 0.3, f64::from(i / 20) * 0.15);
                DVec3::new(a.cos() * e.cos(), e.sin(), a.sin() * e.cos()) * 3.0
                    + DVec3::new(0.0, 0.1, 0.0)
            })
            .collect();
        let fit = fit_screen(&Screen::Dome(dome), &sphere).unwrap();
        let Screen::Dome(d) = &fit.screen else {
            panic!()
        };
        assert!((d.radius - 3.0).abs() < 1e-9 && (d.centre[1] - 0.1).abs() < 1e-9);
        assert_eq!(d.tilt, 15.0);
        let mesh = Screen::Mesh {
            obj: "wall.obj".into(),
            loaded: None,
        };
        assert!(fit_screen(&mesh, &sphere).is_err());
        assert!(
            fit_screen(
                &Screen::Dome(Dome {
                    radius: 1.0,
                    ..d.clone()
                }),
                &sphere[..3]
            )
            .is_err()
        );
    }
}
