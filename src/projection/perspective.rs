//! Planar perspective, symmetric or off-axis (asymmetric frustum).
//!
//! d = normalise(a_x + b_x·s, a_y + b_y·t, −1), where the frustum edges at angles l, r, b, t
//! give a_x = (tan r + tan l)/2, b_x = (tan r − tan l)/2 (likewise vertically). The symmetric
//! frustum of fields of view h, v is l = −h/2, r = h/2. Inverse: x = −d_x/d_z, s = (x − a_x)/b_x;
//! directions with d_z ≥ 0 are behind the image plane.

use super::{Entry, Params, Projection, ShaderForm, fov, missing};
use crate::error::{Error, Outside, Result, finite};
use glam::DVec3;

pub const ENTRY: Entry = Entry {
    name: "flat",
    aliases: &["perspective", "planar"],
    description: "planar perspective (pinhole), symmetric or off-axis frustum",
    params: &[
        ("hfov", "horizontal field of view, 0 < hfov < 180"),
        ("vfov", "vertical field of view, 0 < vfov < 180"),
        (
            "left",
            "off-axis frustum: angle of the left edge, −90 < left < right",
        ),
        (
            "right",
            "off-axis frustum: angle of the right edge, left < right < 90",
        ),
        (
            "bottom",
            "off-axis frustum: angle of the bottom edge, −90 < bottom < top",
        ),
        (
            "top",
            "off-axis frustum: angle of the top edge, bottom < top < 90",
        ),
    ],
    build,
};

#[derive(Debug)]
pub struct Perspective {
    ax: f64,
    bx: f64,
    ay: f64,
    by: f64,
}

const NAME: &str = "flat";

fn edge(name: &str, deg: f64) -> Result<f64> {
    let deg = finite(name, deg)?;
    if deg.abs() >= 90.0 {
        return Err(Error::invalid(
            name,
            format!("must lie strictly between −90 and 90 degrees, got {deg}"),
        ));
    }
    Ok(deg.to_radians().tan())
}

fn build(p: &Params, aspect: f64) -> Result<Box<dyn super::Projection>> {
    let off_axis = [p.left, p.right, p.bottom, p.top];
    let (l, r, b, t) = if off_axis.iter().any(Option::is_some) {
        if p.hfov.is_some() || p.vfov.is_some() {
            return Err(Error::invalid(
                "hfov",
                "give either hfov/vfov or the four frustum edges left/right/bottom/top, not both",
            ));
        }
        let get = |name: &'static str, v: Option<f64>| v.ok_or_else(|| missing(NAME, name));
        let l = edge("left", get("left", p.left)?)?;
        let r = edge("right", get("right", p.right)?)?;
        let b = edge("bottom", get("bottom", p.bottom)?)?;
        let t = edge("top", get("top", p.top)?)?;
        if l >= r {
            return Err(Error::invalid("right", "must be greater than left"));
        }
        if b >= t {
            return Err(Error::invalid("top", "must be greater than bottom"));
        }
        (l, r, b, t)
    } else {
        let h = p.hfov.map(|h| fov("hfov", h, 180.0, true)).transpose()?;
        let v = p.vfov.map(|v| fov("vfov", v, 180.0, true)).transpose()?;
        let (th, tv) = match (h, v) {
            (Some(h), Some(v)) => ((h / 2.0).tan(), (v / 2.0).tan()),
            (Some(h), None) => ((h / 2.0).tan(), (h / 2.0).tan() * aspect),
            (None, Some(v)) => ((v / 2.0).tan() / aspect, (v / 2.0).tan()),
            (None, None) => return Err(missing(NAME, "hfov")),
        };
        (-th, th, -tv, tv)
    };
    Ok(Box::new(Perspective {
        ax: (r + l) / 2.0,
        bx: (r - l) / 2.0,
        ay: (t + b) / 2.0,
        by: (t - b) / 2.0,
    }))
}

impl Projection for Perspective {
    fn shader_form(&self) -> ShaderForm {
        ShaderForm::new(0, [self.ax, self.bx, self.ay, self.by])
    }

    fn name(&self) -> &'static str {
        NAME
    }

    fn forward(&self, s: f64, t: f64) -> Result<DVec3, Outside> {
        Ok(DVec3::new(self.ax + self.bx * s, self.ay + self.by * t, -1.0).normalize())
    }

    fn inverse(&self, d: DVec3) -> Result<(f64, f64), Outside> {
        if d.z >= 0.0 {
            return Err(Outside {
                projection: NAME,
                reason: "direction is not in front of the image plane",
            });
        }
        let (x, y) = (-d.x / d.z, -d.y / d.z);
        Ok(((x - self.ax) / self.bx, (y - self.ay) / self.by))
    }
}
