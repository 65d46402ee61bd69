//! Equirectangular (longitude/latitude linear in s and t), full or partial field of view:
//! lon = s·h/2, lat = t·v/2, d = (cos lat·sin lon, sin lat, −cos lat·cos lon).
//! Inverse: lon = atan2(x, −z) (0 at the poles), lat = atan2(y, √(x²+z²)).

use super::{Entry, Params, Projection, ShaderForm, fov, missing};
use crate::error::{Outside, Result};
use glam::DVec3;
use std::f64::consts::{FRAC_PI_2, PI};

pub const ENTRY: Entry = Entry {
    name: "equirect",
    aliases: &["equirectangular", "e"],
    description: "equirectangular: longitude linear in s, latitude linear in t",
    params: &[
        ("hfov", "horizontal field of view, 0 < hfov ≤ 360"),
        ("vfov", "vertical field of view, 0 < vfov ≤ 180"),
    ],
    build,
};

const NAME: &str = "equirect";

#[derive(Debug)]
pub struct Equirect {
    half_h: f64,
    half_v: f64,
}

fn build(p: &Params, aspect: f64) -> Result<Box<dyn Projection>> {
    let h = p.hfov.map(|h| fov("hfov", h, 360.0, false)).transpose()?;
    let v = p.vfov.map(|v| fov("vfov", v, 180.0, false)).transpose()?;
    let (h, v) = match (h, v) {
        (Some(h), Some(v)) => (h, v),
        (Some(h), None) => (h, h * aspect),
        (None, Some(v)) => (v / aspect, v),
        (None, None) => return Err(missing(NAME, "hfov")),
    };
    if h > 2.0 * PI + 1e-12 || v > PI + 1e-12 {
        return Err(crate::Error::invalid(
            "hfov",
            "with this aspect ratio the derived field of view would exceed 360×180 degrees",
        ));
    }
    Ok(Box::new(Equirect {
        half_h: h / 2.0,
        half_v: v / 2.0,
    }))
}

impl Projection for Equirect {
    fn shader_form(&self) -> ShaderForm {
        ShaderForm::new(3, [self.half_h, self.half_v, 0.0, 0.0])
    }

    fn name(&self) -> &'static str {
        NAME
    }

    fn forward(&self, s: f64, t: f64) -> Result<DVec3, Outside> {
        let (lon, lat) = (s * self.half_h, t * self.half_v);
        if lon.abs() > PI || lat.abs() > FRAC_PI_2 {
            return Err(Outside {
                projection: NAME,
                reason: "beyond ±180 degrees of longitude or ±90 of latitude",
            });
        }
        let (sl, cl) = lat.sin_cos();
        Ok(DVec3::new(cl * lon.sin(), sl, -cl * lon.cos()))
    }

    fn inverse(&self, d: DVec3) -> Result<(f64, f64), Outside> {
        let rho = d.x.hypot(d.z);
        // Every longitude shows the poles; take the centre column's.
        let lon = if rho == 0.0 { 0.0 } else { d.x.atan2(-d.z) };
        let lat = d.y.atan2(rho);
        Ok((lon / self.half_h, lat / self.half_v))
    }
}
