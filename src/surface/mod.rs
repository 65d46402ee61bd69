//! Projection surfaces and ray intersection. A screen is lit from inside (projectors and viewer
//! face it from the same side), and every intersection reports the nearest hit the projector
//! actually lights, a miss, or a grazing hit (light arriving within [`GRAZING_DEG`] of the
//! surface's tangent plane, which spreads a pixel over too much wall to be trusted).
//!
//! World frame as docs/conventions.md: metres, +y up, −z ahead. Azimuths are measured like
//! longitude: 0 towards −z, positive towards +x.

mod mesh;
mod shapes;
mod tessellate;

pub use mesh::{Mesh, parse_obj_triangles, read_obj_triangles};
pub use shapes::{Cylinder, Dome, Plane, PreparedCylinder, PreparedDome, PreparedPlane};

use crate::error::{Error, Result};
use glam::DVec3;
use serde::{Deserialize, Serialize};

/// Hits arriving closer than this to the tangent plane count as grazing.
pub const GRAZING_DEG: f64 = 89.0;

/// sin(90° − GRAZING_DEG): the cosine of incidence below which a hit grazes. Written out
/// because `sin` is not a const fn and classifying every pixel's hit called it.
const GRAZING_COS: f64 = 0.017_452_406_437_283_51;

/// A point closer than this to a surface counts as on it, metres.
pub const ON_SURFACE: f64 = 1e-3;

/// Rays start this far in front of their origin, so a point on the surface does not hit itself.
const EPS: f64 = 1e-9;

/// What a ray meets.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Hit {
    /// The first lit point: distance along the unit ray, the point, the unit normal facing the
    /// ray's origin.
    Lit {
        /// Distance from the ray's origin to the point, metres (the ray is unit length).
        t: f64,
        /// The point hit, world coordinates in metres.
        point: DVec3,
        /// The surface's unit normal at the point, turned towards the ray's origin.
        normal: DVec3,
    },
    /// The ray meets the surface only at a grazing angle (the point is given for diagnostics).
    Grazing {
        /// Where the ray grazes the surface, world coordinates in metres.
        point: DVec3,
    },
    /// The ray meets no lit part of the surface.
    Miss,
}

impl Hit {
    /// The lit point, if the ray lights one (`None` for a grazing hit or a miss).
    pub fn point(&self) -> Option<DVec3> {
        match self {
            Hit::Lit { point, .. } => Some(*point),
            _ => None,
        }
    }
}

/// Classifies a candidate hit at distance t with geometric normal n.
#[inline(always)]
fn classify(origin: DVec3, dir: DVec3, t: f64, n: DVec3) -> Hit {
    let point = origin + dir * t;
    let n = if n.dot(dir) > 0.0 { -n } else { n };
    let cos = -n.dot(dir);
    if cos < GRAZING_COS {
        Hit::Grazing { point }
    } else {
        Hit::Lit {
            t,
            point,
            normal: n,
        }
    }
}

/// A [`Screen`] ready to hit many rays: see [`Screen::prepare`].
pub enum PreparedScreen<'a> {
    /// A prepared [`Cylinder`].
    Cylinder(PreparedCylinder<'a>),
    /// A prepared [`Dome`].
    Dome(PreparedDome),
    /// A prepared [`Plane`].
    Plane(PreparedPlane),
    /// A mesh screen's loaded mesh; `None` (not loaded) misses every ray.
    Mesh(Option<&'a Mesh>),
}

impl PreparedScreen<'_> {
    // Always inlined, with the shapes' tests: a hit returned through memory costs a
    // store-forwarding stall per pixel.
    /// The first lit point along the unit ray from `origin` in direction `dir`, as
    /// [`Screen::intersect`].
    #[inline(always)]
    pub fn intersect(&self, origin: DVec3, dir: DVec3) -> Hit {
        match self {
            PreparedScreen::Cylinder(c) => c.intersect(origin, dir),
            PreparedScreen::Dome(d) => d.intersect(origin, dir),
            PreparedScreen::Plane(p) => p.intersect(origin, dir),
            PreparedScreen::Mesh(m) => m.map_or(Hit::Miss, |m| m.intersect(origin, dir)),
        }
    }
}

/// A projection screen.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum Screen {
    /// `"kind": "cylinder"`: part of a cylinder, lit from inside.
    Cylinder(Cylinder),
    /// `"kind": "dome"`: part of a sphere, tilted and truncated, lit from inside.
    Dome(Dome),
    /// `"kind": "plane"`: a flat rectangle.
    Plane(Plane),
    /// A triangle mesh from an OBJ file (path relative to the rig file).
    Mesh {
        /// The OBJ file's path as the rig writes it, relative to the rig file.
        obj: String,
        /// The mesh read from `obj` (not part of the JSON); `None` until [`Screen::load`].
        #[serde(skip)]
        loaded: Option<std::sync::Arc<Mesh>>,
    },
}

impl Screen {
    /// The first lit point along the unit ray from `origin` in direction `dir`.
    pub fn intersect(&self, origin: DVec3, dir: DVec3) -> Hit {
        self.prepare().intersect(origin, dir)
    }

    /// The screen with what every ray's test shares (a frame, a rim) computed once: loops
    /// that hit a ray per pixel intersect through this.
    pub fn prepare(&self) -> PreparedScreen<'_> {
        match self {
            Screen::Cylinder(c) => PreparedScreen::Cylinder(c.prepare()),
            Screen::Dome(d) => PreparedScreen::Dome(d.prepare()),
            Screen::Plane(p) => PreparedScreen::Plane(p.prepare()),
            Screen::Mesh { loaded, .. } => PreparedScreen::Mesh(loaded.as_deref()),
        }
    }

    /// The same surface continued past its edges (a cylinder a height taller each way and 30°
    /// wider each side, a dome 30° lower, a plane three times the size; a mesh as it is): where
    /// a projector's light just misses the wall, this says where it would land if the wall went
    /// on, which is how the warp is continued past the edge.
    pub fn extended(&self) -> Screen {
        match self {
            Screen::Cylinder(c) => {
                let grow = (c.height[1] - c.height[0]).max(c.radius);
                let arc = if c.arc[1] - c.arc[0] + 60.0 >= 360.0 {
                    [-180.0, 180.0]
                } else {
                    [c.arc[0] - 30.0, c.arc[1] + 30.0]
                };
                Screen::Cylinder(Cylinder {
                    height: [c.height[0] - grow, c.height[1] + grow],
                    arc,
                    ..c.clone()
                })
            }
            Screen::Dome(d) => Screen::Dome(Dome {
                min_elevation: (d.min_elevation - 30.0).max(-89.0),
                ..d.clone()
            }),
            Screen::Plane(p) => Screen::Plane(Plane {
                width: 3.0 * p.width,
                height: 3.0 * p.height,
                ..p.clone()
            }),
            Screen::Mesh { .. } => self.clone(),
        }
    }

    /// Checks the geometry; `field` is the JSON pointer of this screen for error messages.
    pub fn validate(&self, field: &str) -> Result<()> {
        match self {
            Screen::Cylinder(c) => c.validate(field),
            Screen::Dome(d) => d.validate(field),
            Screen::Plane(p) => p.validate(field),
            Screen::Mesh { loaded, obj } => match loaded {
                Some(_) => Ok(()),
                None => Err(Error::invalid(
                    format!("{field}/obj"),
                    format!("mesh `{obj}` is not loaded"),
                )),
            },
        }
    }

    /// Checks that `point` lies where the surface can be projected onto from: inside a
    /// cylinder or a dome's sphere, on the lit side of a plane, and for a mesh reachable from
    /// `eye` without crossing it. A point within [`ON_SURFACE`] of the surface is refused too:
    /// every direction from it meets the wall at once. `field` names the point in errors.
    pub fn check_inside(&self, eye: DVec3, point: DVec3, field: &str) -> Result<()> {
        let point = finite3(field, point)?;
        let m = |v: f64| format!("{v:.3} m");
        let far = crate::limits::WORLD_EXTENT;
        if point.abs().max_element() > far {
            return Err(Error::invalid(
                field,
                format!("is more than the limit of {far} m from the origin"),
            ));
        }
        // The signed distance inside (positive) or beyond (negative) the surface, and what
        // "beyond" means for this shape.
        let (inside, beyond) = match self {
            Screen::Cylinder(c) => {
                let a = DVec3::from_array(c.axis).normalize();
                let o = point - DVec3::from_array(c.centre);
                // Along the axis, the room is the wall's height, and the eye's where it stands
                // above or below it: a centre far up the axis would see the whole wall in one
                // direction (every pixel the nadir at 1e6 m, nothing lit at 1e300 m).
                let (h, eye_h) = (o.dot(a), (eye - DVec3::from_array(c.centre)).dot(a));
                let (lo, hi) = (c.height[0].min(eye_h), c.height[1].max(eye_h));
                if !(lo..=hi).contains(&h) {
                    return Err(Error::invalid(
                        field,
                        format!(
                            "lies {} along the axis, outside the cylinder's height from {} to {} \
                             (the wall's, extended to the eye)",
                            m(h),
                            m(lo),
                            m(hi)
                        ),
                    ));
                }
                let rho = (o - a * o.dot(a)).length();
                (
                    c.radius - rho,
                    format!(
                        "{} from the axis, outside the cylinder of radius {}",
                        m(rho),
                        m(c.radius)
                    ),
                )
            }
            Screen::Dome(d) => {
                let r = (point - DVec3::from_array(d.centre)).length();
                (
                    d.radius - r,
                    format!(
                        "{} from the centre, outside the dome of radius {}",
                        m(r),
                        m(d.radius)
                    ),
                )
            }
            Screen::Plane(p) => {
                let (n, up, right) = p.frame();
                let (o, e) = (
                    point - DVec3::from_array(p.centre),
                    eye - DVec3::from_array(p.centre),
                );
                // The room before a flat wall is as wide and high as the wall (extended to
                // the eye) and, in depth, ten times its larger side or the eye's distance:
                // from further away every pixel would show one direction of the content.
                let room = |axis: DVec3, half: f64, name: &str| {
                    let (c, eye_c) = (o.dot(axis), e.dot(axis));
                    let (lo, hi) = ((-half).min(eye_c), half.max(eye_c));
                    if (lo..=hi).contains(&c) {
                        Ok(())
                    } else {
                        Err(Error::invalid(
                            field,
                            format!(
                                "lies {} {name} of the plane's centre, beyond the wall's extent \
                                 from {} to {} (extended to the eye)",
                                m(c),
                                m(lo),
                                m(hi)
                            ),
                        ))
                    }
                };
                room(right, p.width / 2.0, "right")?;
                room(up, p.height / 2.0, "up")?;
                let (s, depth) = (o.dot(n), 10.0 * e.dot(n).max(p.width).max(p.height));
                if s > depth {
                    return Err(Error::invalid(
                        field,
                        format!(
                            "lies {} before the plane, beyond ten times the wall's size or the \
                             eye's distance ({})",
                            m(s),
                            m(depth)
                        ),
                    ));
                }
                (s, format!("{} behind the plane", m(-s)))
            }
            Screen::Mesh { loaded, .. } => {
                let Some(mesh) = loaded else { return Ok(()) };
                let to = point - eye;
                let len = to.length();
                if len < ON_SURFACE {
                    return Ok(());
                }
                match mesh.first_hit(eye, to / len) {
                    Some((t, _, _)) if t < len + ON_SURFACE => (
                        t - len,
                        format!(
                            "behind the mesh as seen from the eye ({} past it)",
                            m(len - t)
                        ),
                    ),
                    _ => (f64::INFINITY, String::new()),
                }
            }
        };
        if inside.abs() <= ON_SURFACE {
            Err(Error::invalid(
                field,
                format!(
                    "lies on the wall ({} from it); a projection centre must be at least {} inside",
                    m(inside.abs()),
                    m(ON_SURFACE)
                ),
            ))
        } else if inside < 0.0 {
            Err(Error::invalid(field, format!("lies {beyond}")))
        } else {
            Ok(())
        }
    }

    /// Loads a mesh screen's OBJ file, relative to `base`.
    pub fn load(&mut self, base: &std::path::Path, field: &str) -> Result<()> {
        self.load_with(field, |obj| Ok(base.join(obj)), u64::MAX)
    }

    /// Loads a mesh screen's OBJ file from the path `resolve` gives its name; `resolve` may
    /// refuse a name (the daemon reads meshes from its own directories only), and a mesh that
    /// would take more than `budget` bytes is refused before it is built.
    pub fn load_with(
        &mut self,
        field: &str,
        resolve: impl FnOnce(&str) -> Result<std::path::PathBuf>,
        budget: u64,
    ) -> Result<()> {
        if let Screen::Mesh { obj, loaded } = self {
            let at = format!("{field}/obj");
            let path = resolve(obj).map_err(|e| Error::invalid(&at, e.reason()))?;
            // Named as the document names it: where the file lies is the host's business.
            let mesh = Mesh::read_obj_within(&path, budget).map_err(|e| match e {
                Error::File { reason, .. } => Error::invalid(&at, format!("`{obj}`: {reason}")),
                other => Error::invalid(&at, other.to_string()),
            })?;
            *loaded = Some(std::sync::Arc::new(mesh));
        }
        Ok(())
    }
}

/// `v` if all its components are finite, else an error naming `field`.
pub fn finite3(field: &str, v: DVec3) -> Result<DVec3> {
    if v.is_finite() {
        Ok(v)
    } else {
        Err(Error::invalid(field, format!("must be finite, got {v}")))
    }
}

/// `v` if it is finite and above zero, else an error naming `field`.
pub fn positive(field: &str, v: f64) -> Result<f64> {
    if v.is_finite() && v > 0.0 {
        Ok(v)
    } else {
        Err(Error::invalid(
            field,
            format!("must be a positive number, got {v}"),
        ))
    }
}

/// A unit vector from a non-zero finite one.
pub fn unit(field: &str, v: DVec3) -> Result<DVec3> {
    let v = finite3(field, v)?;
    if v.length() < 1e-12 {
        return Err(Error::invalid(field, "must not be the zero vector"));
    }
    Ok(v.normalize())
}

#[cfg(test)]
mod tests;

#[cfg(test)]
mod grazing {
    #[test]
    fn the_written_out_cosine_is_the_grazing_angle() {
        let exact = (90.0 - super::GRAZING_DEG).to_radians().sin();
        assert!((super::GRAZING_COS - exact).abs() < 1e-17, "{exact}");
    }
}
