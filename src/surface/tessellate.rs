//! The screens as triangles, for renderers that draw triangles (the GPU's cube-map pass shows a
//! panorama projected onto the wall this way). Curved screens are cut every [`STEP_DEG`]: the
//! chord then lies within r·(1 − cos ½°) ≈ 3.8·10⁻⁵ r of the surface (0.08 mm on a 2 m
//! cylinder). A cylinder is straight along its axis, so one band covers its height.

use super::{Screen, shapes::Dome};
use glam::DVec3;

/// Degrees between the cuts of a curved screen.
pub const STEP_DEG: f64 = 1.0;

impl Screen {
    /// The screen as triangles (a mesh screen: its own).
    pub fn triangles(&self) -> Vec<[DVec3; 3]> {
        let mut out = Vec::new();
        match self {
            Screen::Cylinder(c) => {
                let (a, front, right) = c.frame();
                let o = DVec3::from_array(c.centre);
                let n = steps(c.arc[1] - c.arc[0]);
                let at = |k: usize, h: f64| {
                    let az = (c.arc[0] + (c.arc[1] - c.arc[0]) * k as f64 / n as f64).to_radians();
                    o + a * h + c.radius * (az.cos() * front + az.sin() * right)
                };
                for k in 0..n {
                    let [h0, h1] = c.height;
                    quad(
                        &mut out,
                        [at(k, h0), at(k + 1, h0), at(k + 1, h1), at(k, h1)],
                    );
                }
            }
            Screen::Dome(d) => {
                let (z, u, w) = dome_frame(d);
                let o = DVec3::from_array(d.centre);
                let (e0, ne, na) = (d.min_elevation, steps(90.0 - d.min_elevation), steps(360.0));
                let at = |i: usize, k: usize| {
                    let el = (e0 + (90.0 - e0) * k as f64 / ne as f64).to_radians();
                    let az = (360.0 * i as f64 / na as f64).to_radians();
                    o + d.radius * (el.cos() * (az.cos() * u + az.sin() * w) + el.sin() * z)
                };
                for k in 0..ne {
                    for i in 0..na {
                        quad(
                            &mut out,
                            [at(i, k), at(i + 1, k), at(i + 1, k + 1), at(i, k + 1)],
                        );
                    }
                }
            }
            Screen::Plane(p) => {
                let (_, up, right) = p.frame();
                let c = DVec3::from_array(p.centre);
                let (x, y) = (right * p.width / 2.0, up * p.height / 2.0);
                quad(&mut out, [c - x - y, c + x - y, c + x + y, c - x + y]);
            }
            Screen::Mesh { loaded, .. } => {
                if let Some(m) = loaded {
                    out.extend_from_slice(m.triangles());
                }
            }
        }
        out
    }
}

fn steps(degrees: f64) -> usize {
    ((degrees / STEP_DEG).ceil() as usize).max(1)
}

fn quad(out: &mut Vec<[DVec3; 3]>, q: [DVec3; 4]) {
    out.push([q[0], q[1], q[2]]);
    out.push([q[0], q[2], q[3]]);
}

/// The dome's zenith and two axes across it.
fn dome_frame(d: &Dome) -> (DVec3, DVec3, DVec3) {
    let z = d.zenith();
    let u = z.any_orthonormal_vector();
    (z, u, z.cross(u))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::surface::{Cylinder, Plane};

    /// Every vertex lies on the surface, and every triangle's centre within the chord bound.
    #[test]
    fn triangles_lie_on_the_screen() {
        let screens = [
            Screen::Cylinder(Cylinder {
                radius: 2.0,
                centre: [0.0, 0.5, 0.0],
                axis: [0.0, 1.0, 0.0],
                height: [-1.0, 1.2],
                arc: [-135.0, 135.0],
            }),
            Screen::Dome(Dome {
                radius: 3.0,
                centre: [0.0, 0.0, 0.0],
                tilt: 20.0,
                min_elevation: -10.0,
            }),
            Screen::Plane(Plane {
                centre: [0.0, 1.0, -2.0],
                normal: [0.0, 0.0, 1.0],
                up: [0.0, 1.0, 0.0],
                width: 3.0,
                height: 2.0,
            }),
        ];
        let sagitta = |r: f64| r * (1.0 - (STEP_DEG.to_radians() / 2.0).cos());
        for s in &screens {
            let tris = s.triangles();
            assert!(!tris.is_empty());
            for t in &tris {
                let centroid = (t[0] + t[1] + t[2]) / 3.0;
                // Rays towards each vertex and the centroid from inside meet the screen there.
                for (p, slack) in [(t[0], 1e-9), (centroid, 0.0)] {
                    let (dist, bound) = match s {
                        Screen::Cylinder(c) => {
                            let q = p - DVec3::from_array(c.centre);
                            let rho = (q - DVec3::Y * q.y).length();
                            ((rho - c.radius).abs(), sagitta(c.radius))
                        }
                        Screen::Dome(d) => {
                            let r = (p - DVec3::from_array(d.centre)).length();
                            ((r - d.radius).abs(), sagitta(d.radius) * 2.0)
                        }
                        _ => ((p.z + 2.0).abs(), 0.0),
                    };
                    assert!(dist <= bound + slack + 1e-12, "{dist} > {bound}");
                }
            }
        }
        // The cylinder covers its arc: 270 cuts, two triangles each.
        assert_eq!(screens[0].triangles().len(), 540);
    }
}
