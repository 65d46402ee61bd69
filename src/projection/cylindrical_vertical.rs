//! Vertical cylindrical projection: the horizontal cylinder turned on its side, for tall
//! screens. d = normalise(s·tan α, sin(tβ), −cos(tβ)) for a horizontal field of view 2α (below
//! 180°) and vertical 2β (up to 360°). Inverse: t = atan2(y, −z)/β, s = x/(√(y²+z²)·tan α).

use super::{Entry, Params, Projection, ShaderForm, fov, missing};
use crate::error::{Outside, Result};
use glam::DVec3;
use std::f64::consts::PI;

pub const ENTRY: Entry = Entry {
    name: "cylindrical-vertical",
    aliases: &[],
    description: "vertical cylinder: elevation linear in t, width on the cylinder linear in s",
    params: &[
        ("hfov", "horizontal field of view, 0 < hfov < 180"),
        ("vfov", "vertical field of view, 0 < vfov ≤ 360"),
    ],
    build,
};

const NAME: &str = "cylindrical-vertical";

#[derive(Debug)]
pub struct CylindricalVertical {
    tan_alpha: f64,
    beta: f64,
}

fn build(p: &Params, aspect: f64) -> Result<Box<dyn Projection>> {
    let h = p.hfov.map(|h| fov("hfov", h, 180.0, true)).transpose()?;
    let v = p.vfov.map(|v| fov("vfov", v, 360.0, false)).transpose()?;
    let (tan_alpha, beta) = match (h, v) {
        (Some(h), Some(v)) => ((h / 2.0).tan(), v / 2.0),
        (Some(h), None) => ((h / 2.0).tan(), (h / 2.0).tan() * aspect),
        (None, Some(v)) => (v / 2.0 / aspect, v / 2.0),
        (None, None) => return Err(missing(NAME, "vfov")),
    };
    if beta > PI {
        return Err(crate::Error::invalid(
            "hfov",
            "with this aspect ratio the vertical field of view would exceed 360 degrees",
        ));
    }
    Ok(Box::new(CylindricalVertical { tan_alpha, beta }))
}

impl Projection for CylindricalVertical {
    fn shader_form(&self) -> ShaderForm {
        ShaderForm::new(2, [self.tan_alpha, self.beta, 0.0, 0.0])
    }

    fn name(&self) -> &'static str {
        NAME
    }

    fn forward(&self, s: f64, t: f64) -> Result<DVec3, Outside> {
        let el = t * self.beta;
        if el.abs() > PI {
            return Err(Outside {
                projection: NAME,
                reason: "elevation beyond ±180 degrees",
            });
        }
        Ok(DVec3::new(s * self.tan_alpha, el.sin(), -el.cos()).normalize())
    }

    fn inverse(&self, d: DVec3) -> Result<(f64, f64), Outside> {
        let rho = d.y.hypot(d.z);
        if rho == 0.0 {
            return Err(Outside {
                projection: NAME,
                reason: "the ends of the cylinder's axis have no image",
            });
        }
        Ok((d.x / (rho * self.tan_alpha), d.y.atan2(-d.z) / self.beta))
    }
}
