//! The fisheye family: radially symmetric projections where the angle θ from the view axis is
//! a function of the distance r from the image centre, r = R(θ):
//!
//! | name | R(θ) | largest field of view |
//! | --- | --- | --- |
//! | `fisheye` (`spherical`, equidistant; seed 000's δS) | θ | 360° |
//! | `equisolid` (equal-area) | 2·sin(θ/2) | 360° |
//! | `stereographic` (conformal) | 2·tan(θ/2) | below 360° |
//! | `orthographic` | sin θ | 180° |
//!
//! With φ = atan2(t, s): d = (sin θ·cos φ, sin θ·sin φ, −cos θ). The image is scaled so that the
//! image circle of field of view `fov` is inscribed in the shorter side of the output (or, with
//! `hfov`/`vfov`, so that s = ±1 and t = ±1 are at those angles, as in ffmpeg's v360); positions
//! outside the circle (θ beyond half the field of view) are outside the domain.
//! Seed 000 writes δS with θ = √(s²+t²)·γ/2, which is the equidistant row for a square image.
//! `domemaster` is the 180° equidistant fisheye turned so that its centre looks at the zenith,
//! tilted forward by `tilt` degrees, the front of the dome at the bottom of the image (the view
//! from inside the dome with +x to the right); it is the one projection whose centre is not −z.

use super::{Entry, Params, Projection, ShaderForm, fov, missing};
use crate::error::{Error, Outside, Result, finite};
use glam::{DMat3, DVec3};
use std::f64::consts::PI;

#[derive(Debug, Clone, Copy, PartialEq)]
enum Radial {
    Equidistant,
    Equisolid,
    Stereographic,
    Orthographic,
}

impl Radial {
    fn r(self, theta: f64) -> f64 {
        match self {
            Radial::Equidistant => theta,
            Radial::Equisolid => 2.0 * (theta / 2.0).sin(),
            Radial::Stereographic => 2.0 * (theta / 2.0).tan(),
            Radial::Orthographic => theta.sin(),
        }
    }

    /// R⁻¹(r), or `None` where no angle reaches r.
    fn theta(self, r: f64) -> Option<f64> {
        match self {
            Radial::Equidistant => (r <= PI).then_some(r),
            Radial::Equisolid => (r <= 2.0).then(|| 2.0 * (r / 2.0).asin()),
            Radial::Stereographic => Some(2.0 * (r / 2.0).atan()),
            Radial::Orthographic => (r <= 1.0).then(|| r.asin()),
        }
    }

    /// The largest field of view in degrees, and whether it is excluded.
    fn max_fov(self) -> (f64, bool) {
        match self {
            Radial::Equidistant | Radial::Equisolid => (360.0, false),
            Radial::Stereographic => (360.0, true),
            Radial::Orthographic => (180.0, false),
        }
    }
}

#[derive(Debug)]
pub struct Fisheye {
    name: &'static str,
    radial: Radial,
    /// r per unit of s and t.
    sx: f64,
    sy: f64,
    theta_max: f64,
    /// Applied after the fisheye formula (identity except for the domemaster).
    turn: Option<DMat3>,
}

// Accepts the image-circle boundary despite rounding in θ computed from (s, t).
const EDGE_EPS: f64 = 1e-12;

const FOV_PARAMS: &[(&str, &str)] = &[
    (
        "fov",
        "field of view of the image circle, inscribed in the shorter side",
    ),
    (
        "hfov",
        "field of view across the image width (instead of fov)",
    ),
    (
        "vfov",
        "field of view across the image height (instead of fov)",
    ),
];

macro_rules! family_entry {
    ($const:ident, $name:literal, $aliases:expr, $radial:expr, $desc:literal) => {
        pub const $const: Entry = Entry {
            name: $name,
            aliases: $aliases,
            description: $desc,
            params: FOV_PARAMS,
            build: |p, aspect| Ok(Box::new(Fisheye::new($name, $radial, p, aspect)?)),
        };
    };
}

family_entry!(
    EQUIDISTANT,
    "fisheye",
    &["equidistant"],
    Radial::Equidistant,
    "equidistant fisheye, r = θ, any field of view up to 360°"
);
family_entry!(
    SPHERICAL,
    "spherical",
    &[],
    Radial::Equidistant,
    "seed 000's spherical projection δS: the equidistant fisheye"
);
family_entry!(
    EQUISOLID,
    "equisolid",
    &[],
    Radial::Equisolid,
    "equisolid-angle (equal-area) fisheye, r = 2·sin(θ/2), up to 360°"
);
family_entry!(
    STEREOGRAPHIC,
    "stereographic",
    &[],
    Radial::Stereographic,
    "stereographic (conformal) fisheye, r = 2·tan(θ/2), below 360°"
);
family_entry!(
    ORTHOGRAPHIC,
    "orthographic",
    &[],
    Radial::Orthographic,
    "orthographic fisheye, r = sin θ, up to 180°"
);

pub const DOMEMASTER: Entry = Entry {
    name: "domemaster",
    aliases: &[],
    description: "180° equidistant dome master: centre at the zenith, front at the bottom",
    params: &[(
        "tilt",
        "forward tilt of the dome, −90 ≤ tilt ≤ 90 (0: centre at the zenith)",
    )],
    build: |p, aspect| {
        let tilt = finite("tilt", p.tilt.unwrap_or(0.0))?;
        if tilt.abs() > 90.0 {
            return Err(Error::invalid(
                "tilt",
                format!("must lie within ±90 degrees, got {tilt}"),
            ));
        }
        let circle = Params {
            fov: Some(180.0),
            ..Params::default()
        };
        let mut f = Fisheye::new("domemaster", Radial::Equidistant, &circle, aspect)?;
        // Rotating the fisheye's axis −z about +x by 90° − tilt lands it on
        // (0, cos tilt, −sin tilt), and its image top (+y) on the back of the dome.
        f.turn = Some(DMat3::from_rotation_x((90.0 - tilt).to_radians()));
        Ok(Box::new(f))
    },
};

impl Fisheye {
    fn new(name: &'static str, radial: Radial, p: &Params, aspect: f64) -> Result<Self> {
        let (max, open) = radial.max_fov();
        let angle = |n: &str, v: f64| fov(n, v, max, open);
        let (sx, sy, theta_max) = match (p.fov, p.hfov, p.vfov) {
            (Some(_), Some(_), _) | (Some(_), _, Some(_)) => {
                return Err(Error::invalid(
                    "fov",
                    "give either fov or hfov/vfov, not both",
                ));
            }
            (Some(f), None, None) => {
                let theta_max = angle("fov", f)? / 2.0;
                let r0 = radial.r(theta_max);
                if aspect <= 1.0 {
                    (r0 / aspect, r0, theta_max)
                } else {
                    (r0, r0 * aspect, theta_max)
                }
            }
            (None, h, v) => {
                let h = h.map(|h| angle("hfov", h)).transpose()?;
                let v = v.map(|v| angle("vfov", v)).transpose()?;
                let limit = max.to_radians() / 2.0;
                let (sx, sy) = match (h, v) {
                    (Some(h), Some(v)) => (radial.r(h / 2.0), radial.r(v / 2.0)),
                    (Some(h), None) => (radial.r(h / 2.0), radial.r(h / 2.0) * aspect),
                    (None, Some(v)) => (radial.r(v / 2.0) / aspect, radial.r(v / 2.0)),
                    (None, None) => return Err(missing(name, "fov")),
                };
                let edge = |r: f64| radial.theta(r).unwrap_or(limit).min(limit);
                (sx, sy, edge(sx).max(edge(sy)))
            }
        };
        Ok(Fisheye {
            name,
            radial,
            sx,
            sy,
            theta_max,
            turn: None,
        })
    }

    fn outside(&self) -> Outside {
        Outside {
            projection: self.name,
            reason: "outside the image circle",
        }
    }
}

impl Projection for Fisheye {
    fn shader_form(&self) -> ShaderForm {
        let radial = match self.radial {
            Radial::Equidistant => 0,
            Radial::Equisolid => 1,
            Radial::Stereographic => 2,
            Radial::Orthographic => 3,
        };
        ShaderForm {
            kind: 4,
            radial,
            p: [self.sx, self.sy, self.theta_max * (1.0 + EDGE_EPS), 0.0],
            turn: self.turn.unwrap_or(DMat3::IDENTITY),
        }
    }

    fn name(&self) -> &'static str {
        self.name
    }

    fn forward(&self, s: f64, t: f64) -> Result<DVec3, Outside> {
        self.forward_within(s, t, self.theta_max * (1.0 + EDGE_EPS))
    }

    fn forward_unbounded(&self, s: f64, t: f64) -> Result<DVec3, Outside> {
        self.forward_within(s, t, PI)
    }

    fn inverse(&self, d: DVec3) -> Result<(f64, f64), Outside> {
        let d = self.turn.map_or(d, |m| m.transpose() * d);
        let rho = d.x.hypot(d.y);
        let theta = rho.atan2(-d.z);
        if theta > self.theta_max * (1.0 + EDGE_EPS) {
            return Err(self.outside());
        }
        if rho == 0.0 {
            return Ok((0.0, 0.0));
        }
        let r = self.radial.r(theta);
        Ok((r * d.x / rho / self.sx, r * d.y / rho / self.sy))
    }
}

impl Fisheye {
    /// δP up to angle `limit` from the axis.
    fn forward_within(&self, s: f64, t: f64, limit: f64) -> Result<DVec3, Outside> {
        let (px, py) = (s * self.sx, t * self.sy);
        let r = px.hypot(py);
        let theta = self.radial.theta(r).ok_or_else(|| self.outside())?;
        if theta > limit {
            return Err(self.outside());
        }
        let d = if r == 0.0 {
            DVec3::NEG_Z
        } else {
            let (st, ct) = theta.sin_cos();
            DVec3::new(st * px / r, st * py / r, -ct)
        };
        Ok(self.turn.map_or(d, |m| m * d))
    }
}
