//! Horizontal cylindrical projection (seed 000, section 3), rotated into the local frame:
//! d = normalise(sin(sα), t·tan β, −cos(sα)) for a horizontal field of view 2α (up to 360°)
//! and vertical 2β (below 180°). Inverse: s = atan2(x, −z)/α, t = y/(√(x²+z²)·tan β); the two
//! poles, where √(x²+z²) = 0, have no image.

use super::{Entry, Params, Projection, ShaderForm, fov, missing};
use crate::error::{Outside, Result};
use glam::DVec3;
use std::f64::consts::PI;

pub const ENTRY: Entry = Entry {
    name: "cylindrical",
    aliases: &[],
    description: "horizontal cylinder: longitude linear in s, height on the cylinder linear in t",
    params: &[
        ("hfov", "horizontal field of view, 0 < hfov ≤ 360"),
        ("vfov", "vertical field of view, 0 < vfov < 180"),
    ],
    build,
};

const NAME: &str = "cylindrical";

#[derive(Debug)]
pub struct Cylindrical {
    alpha: f64,
    tan_beta: f64,
}

fn build(p: &Params, aspect: f64) -> Result<Box<dyn Projection>> {
    let h = p.hfov.map(|h| fov("hfov", h, 360.0, false)).transpose()?;
    let v = p.vfov.map(|v| fov("vfov", v, 180.0, true)).transpose()?;
    // Square pixels at the centre: d(height)/dt = tan β must equal d(arc)/ds · aspect = α·aspect.
    let (alpha, tan_beta) = match (h, v) {
        (Some(h), Some(v)) => (h / 2.0, (v / 2.0).tan()),
        (Some(h), None) => (h / 2.0, h / 2.0 * aspect),
        (None, Some(v)) => ((v / 2.0).tan() / aspect, (v / 2.0).tan()),
        (None, None) => return Err(missing(NAME, "hfov")),
    };
    if alpha > PI {
        return Err(crate::Error::invalid(
            "vfov",
            "with this aspect ratio the horizontal field of view would exceed 360 degrees",
        ));
    }
    Ok(Box::new(Cylindrical { alpha, tan_beta }))
}

impl Projection for Cylindrical {
    fn shader_form(&self) -> ShaderForm {
        ShaderForm::new(1, [self.alpha, self.tan_beta, 0.0, 0.0])
    }

    fn name(&self) -> &'static str {
        NAME
    }

    fn forward(&self, s: f64, t: f64) -> Result<DVec3, Outside> {
        let lon = s * self.alpha;
        if lon.abs() > PI {
            return Err(Outside {
                projection: NAME,
                reason: "longitude beyond ±180 degrees",
            });
        }
        Ok(DVec3::new(lon.sin(), t * self.tan_beta, -lon.cos()).normalize())
    }

    fn inverse(&self, d: DVec3) -> Result<(f64, f64), Outside> {
        let rho = d.x.hypot(d.z);
        if rho == 0.0 {
            return Err(Outside {
                projection: NAME,
                reason: "the poles of the cylinder's axis have no image",
            });
        }
        Ok((d.x.atan2(-d.z) / self.alpha, d.y / (rho * self.tan_beta)))
    }
}
