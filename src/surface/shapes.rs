//! The analytic screens: a cylinder (radius, axis, centre, height range, arc range), a dome
//! (sphere with tilt and truncation) and a plane rectangle. Each keeps, of the ray's
//! intersections with the full shape, the nearest one inside its bounds.

use super::{EPS, Hit, classify, finite3, positive, unit};
use crate::error::{Error, Result};
use glam::DVec3;
use serde::{Deserialize, Serialize};

fn up() -> [f64; 3] {
    [0.0, 1.0, 0.0]
}
fn full_arc() -> [f64; 2] {
    [-180.0, 180.0]
}

/// The two roots of a·t² + b·t + c = 0 in increasing order, computed stably.
#[inline(always)]
fn roots(a: f64, b: f64, c: f64) -> Option<(f64, f64)> {
    let disc = b * b - 4.0 * a * c;
    if a.abs() < 1e-15 || disc < 0.0 {
        return None;
    }
    let q = -0.5 * (b + b.signum() * disc.sqrt());
    let (t1, t2) = if q == 0.0 { (0.0, 0.0) } else { (q / a, c / q) };
    Some((t1.min(t2), t1.max(t2)))
}

/// A cylinder seen from inside.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Cylinder {
    /// Metres.
    pub radius: f64,
    /// A point on the axis; heights are measured from it.
    #[serde(default)]
    pub centre: [f64; 3],
    /// The axis direction (any non-zero length); heights run along it. +y by default.
    #[serde(default = "up")]
    pub axis: [f64; 3],
    /// Bottom and top along the axis from `centre`, metres.
    pub height: [f64; 2],
    /// Azimuth range lit, degrees: 0 towards −z (or the direction nearest it across the axis),
    /// positive towards +x.
    #[serde(default = "full_arc")]
    pub arc: [f64; 2],
}

impl Cylinder {
    pub(super) fn frame(&self) -> (DVec3, DVec3, DVec3) {
        let a = DVec3::from_array(self.axis).normalize();
        let mut front = DVec3::NEG_Z - a * DVec3::NEG_Z.dot(a);
        if front.length() < 1e-9 {
            front = DVec3::X - a * DVec3::X.dot(a);
        }
        let front = front.normalize();
        (a, front, front.cross(a))
    }

    /// Checks the fields (radius positive, axis non-zero, bottom below top, arc within ±180°);
    /// `field` is the cylinder's JSON pointer for error messages.
    pub fn validate(&self, field: &str) -> Result<()> {
        positive(&format!("{field}/radius"), self.radius)?;
        finite3(&format!("{field}/centre"), DVec3::from_array(self.centre))?;
        unit(&format!("{field}/axis"), DVec3::from_array(self.axis))?;
        let [h0, h1] = self.height;
        if !(h0.is_finite() && h1.is_finite() && h0 < h1) {
            return Err(Error::invalid(
                format!("{field}/height"),
                format!(
                    "must be [bottom, top] with bottom < top, got {:?}",
                    self.height
                ),
            ));
        }
        let [a0, a1] = self.arc;
        if !(a0.is_finite() && a1.is_finite() && a0 < a1 && a0 >= -180.0 && a1 <= 180.0) {
            return Err(Error::invalid(
                format!("{field}/arc"),
                format!(
                    "must be [from, to] within ±180° with from < to, got {:?}",
                    self.arc
                ),
            ));
        }
        Ok(())
    }

    /// The first lit point along the unit ray from `origin` in direction `dir`.
    pub fn intersect(&self, origin: DVec3, dir: DVec3) -> Hit {
        self.prepare().intersect(origin, dir)
    }

    /// The cylinder with its frame built once, for loops that hit many rays against it.
    pub fn prepare(&self) -> PreparedCylinder<'_> {
        let (axis, front, right) = self.frame();
        PreparedCylinder {
            c: self,
            axis,
            front,
            right,
            centre: DVec3::from_array(self.centre),
            // atan2 lies within ±180° (±π turns into exactly ±180.0), so a whole turn needs
            // no azimuth, and most cylinders in use are lit all round or nearly.
            whole_turn: self.arc[0] <= -180.0 && self.arc[1] >= 180.0,
        }
    }
}

/// A [`Cylinder`] and what every ray's test shares.
pub struct PreparedCylinder<'a> {
    c: &'a Cylinder,
    axis: DVec3,
    front: DVec3,
    right: DVec3,
    centre: DVec3,
    whole_turn: bool,
}

impl PreparedCylinder<'_> {
    /// The first lit point along the unit ray from `origin` in direction `dir`.
    #[inline(always)]
    pub fn intersect(&self, origin: DVec3, dir: DVec3) -> Hit {
        let (c, a) = (self.c, self.axis);
        let o = origin - self.centre;
        let dp = dir - a * dir.dot(a);
        let op = o - a * o.dot(a);
        let Some((t1, t2)) = roots(
            dp.dot(dp),
            2.0 * dp.dot(op),
            op.dot(op) - c.radius * c.radius,
        ) else {
            return Hit::Miss;
        };
        for t in [t1, t2] {
            if t <= EPS {
                continue;
            }
            let p = o + dir * t;
            let h = p.dot(a);
            let radial = p - a * h;
            if h >= c.height[0] && h <= c.height[1] && (self.whole_turn || self.in_arc(radial)) {
                return classify(origin, dir, t, radial / c.radius);
            }
        }
        Hit::Miss
    }

    fn in_arc(&self, radial: DVec3) -> bool {
        let az = radial
            .dot(self.right)
            .atan2(radial.dot(self.front))
            .to_degrees();
        az >= self.c.arc[0] && az <= self.c.arc[1]
    }
}

/// A spherical dome seen from inside.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Dome {
    /// The sphere's radius, metres.
    pub radius: f64,
    /// The sphere's centre, metres; the origin by default.
    #[serde(default)]
    pub centre: [f64; 3],
    /// Degrees the zenith leans forward (towards −z).
    #[serde(default)]
    pub tilt: f64,
    /// Lowest elevation lit in the dome's own frame, degrees: 0 for a hemisphere, negative to
    /// continue below the springline.
    #[serde(default)]
    pub min_elevation: f64,
}

impl Dome {
    /// The unit zenith direction: +y leaned `tilt` degrees towards −z.
    pub fn zenith(&self) -> DVec3 {
        let t = self.tilt.to_radians();
        DVec3::new(0.0, t.cos(), -t.sin())
    }

    /// Checks the fields (radius positive, tilt within ±90°, min_elevation strictly within
    /// ±90°); `field` is the dome's JSON pointer for error messages.
    pub fn validate(&self, field: &str) -> Result<()> {
        positive(&format!("{field}/radius"), self.radius)?;
        finite3(&format!("{field}/centre"), DVec3::from_array(self.centre))?;
        if !(self.tilt.is_finite() && self.tilt.abs() <= 90.0) {
            return Err(Error::invalid(
                format!("{field}/tilt"),
                format!("must lie within ±90°, got {}", self.tilt),
            ));
        }
        if !(self.min_elevation.is_finite()
            && self.min_elevation > -90.0
            && self.min_elevation < 90.0)
        {
            return Err(Error::invalid(
                format!("{field}/min_elevation"),
                format!("must lie strictly within ±90°, got {}", self.min_elevation),
            ));
        }
        Ok(())
    }

    /// The first lit point along the unit ray from `origin` in direction `dir`.
    pub fn intersect(&self, origin: DVec3, dir: DVec3) -> Hit {
        self.prepare().intersect(origin, dir)
    }

    /// The dome with its zenith and rim computed once.
    pub fn prepare(&self) -> PreparedDome {
        PreparedDome {
            centre: DVec3::from_array(self.centre),
            radius: self.radius,
            zenith: self.zenith(),
            lowest: self.min_elevation.to_radians().sin(),
        }
    }
}

/// A [`Dome`] and what every ray's test shares.
pub struct PreparedDome {
    centre: DVec3,
    radius: f64,
    zenith: DVec3,
    /// The sine of the lowest elevation lit.
    lowest: f64,
}

impl PreparedDome {
    /// The first lit point along the unit ray from `origin` in direction `dir`.
    #[inline(always)]
    pub fn intersect(&self, origin: DVec3, dir: DVec3) -> Hit {
        let o = origin - self.centre;
        let Some((t1, t2)) = roots(
            dir.dot(dir),
            2.0 * dir.dot(o),
            o.dot(o) - self.radius * self.radius,
        ) else {
            return Hit::Miss;
        };
        for t in [t1, t2] {
            if t <= EPS {
                continue;
            }
            let p = (o + dir * t) / self.radius;
            if p.dot(self.zenith) >= self.lowest {
                return classify(origin, dir, t, p);
            }
        }
        Hit::Miss
    }
}

/// A flat rectangle.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Plane {
    /// The rectangle's centre, metres.
    pub centre: [f64; 3],
    /// Towards the viewer.
    pub normal: [f64; 3],
    /// The rectangle's up direction (made perpendicular to the normal).
    #[serde(default = "up")]
    pub up: [f64; 3],
    /// The rectangle's extent across `up`, metres.
    pub width: f64,
    /// The rectangle's extent along `up`, metres.
    pub height: f64,
}

impl Plane {
    pub(super) fn frame(&self) -> (DVec3, DVec3, DVec3) {
        let n = DVec3::from_array(self.normal).normalize();
        let up = DVec3::from_array(self.up);
        let up = (up - n * up.dot(n)).normalize();
        (n, up, up.cross(n))
    }

    /// Checks the fields (normal and up non-zero and not parallel, width and height
    /// positive); `field` is the plane's JSON pointer for error messages.
    pub fn validate(&self, field: &str) -> Result<()> {
        finite3(&format!("{field}/centre"), DVec3::from_array(self.centre))?;
        let n = unit(&format!("{field}/normal"), DVec3::from_array(self.normal))?;
        let up = unit(&format!("{field}/up"), DVec3::from_array(self.up))?;
        if n.cross(up).length() < 1e-6 {
            return Err(Error::invalid(
                format!("{field}/up"),
                "must not be parallel to the normal",
            ));
        }
        positive(&format!("{field}/width"), self.width)?;
        positive(&format!("{field}/height"), self.height)?;
        Ok(())
    }

    /// The first lit point along the unit ray from `origin` in direction `dir`.
    pub fn intersect(&self, origin: DVec3, dir: DVec3) -> Hit {
        self.prepare().intersect(origin, dir)
    }

    /// The plane with its frame built once.
    pub fn prepare(&self) -> PreparedPlane {
        let (n, up, right) = self.frame();
        PreparedPlane {
            centre: DVec3::from_array(self.centre),
            n,
            up,
            right,
            half: [self.width / 2.0, self.height / 2.0],
        }
    }
}

/// A [`Plane`] and what every ray's test shares.
pub struct PreparedPlane {
    centre: DVec3,
    n: DVec3,
    up: DVec3,
    right: DVec3,
    /// Half the width and half the height.
    half: [f64; 2],
}

impl PreparedPlane {
    /// The first lit point along the unit ray from `origin` in direction `dir`.
    #[inline(always)]
    pub fn intersect(&self, origin: DVec3, dir: DVec3) -> Hit {
        let (c, n) = (self.centre, self.n);
        let denom = dir.dot(n);
        if denom.abs() < 1e-15 {
            return Hit::Miss;
        }
        let t = (c - origin).dot(n) / denom;
        if t <= EPS {
            return Hit::Miss;
        }
        let p = origin + dir * t - c;
        if p.dot(self.right).abs() <= self.half[0] && p.dot(self.up).abs() <= self.half[1] {
            classify(origin, dir, t, n)
        } else {
            Hit::Miss
        }
    }
}
