//! Angular fisheye images and dome masters as content: the image circle and its field of view,
//! a dome master's tilt (see the module's summary for the lookup).

use super::{Atlas, Content, Kind, PAD};
use crate::error::{Error, Result, finite};
use crate::projection::Orientation;
use crate::raster::{Pixel, Raster};
use glam::DMat3;

/// An angular (equidistant) fisheye image: a fisheye lens's frame or, with a tilt, a dome
/// master. Angles in degrees, positions in pixels from the image's top-left corner.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Fisheye {
    /// Field of view across the image circle, above 0 and at most 360 degrees.
    pub fov: f64,
    /// A dome master: the circle's centre at the zenith tilted forward by this many degrees
    /// (±90), the front of the dome at the bottom of the image. `None`: a fisheye looking at −z
    /// with up at the top of the image.
    pub tilt: Option<f64>,
    /// The circle's centre (default: the image centre).
    pub centre: Option<[f64; 2]>,
    /// The circle's radius (default: half the shorter side, the inscribed circle).
    pub radius: Option<f64>,
}

impl Fisheye {
    /// A 180° dome master filling its square image, untilted.
    pub const DOMEMASTER: Fisheye = Fisheye {
        fov: 180.0,
        tilt: Some(0.0),
        centre: None,
        radius: None,
    };

    /// A 180° fisheye looking at −z, its circle inscribed.
    pub const FISHEYE: Fisheye = Fisheye {
        fov: 180.0,
        tilt: None,
        centre: None,
        radius: None,
    };
}

impl<T: Pixel> Content<T> {
    /// An angular fisheye image or a dome master (see [`Fisheye`]); errors name the field.
    pub fn fisheye(image: &Raster<T>, f: &Fisheye) -> Result<Self> {
        let fov = finite("content-fov", f.fov)?;
        if fov <= 0.0 || fov > 360.0 {
            return Err(Error::invalid(
                "content-fov",
                format!("must be above 0 and at most 360 degrees, got {fov}"),
            ));
        }
        let (w, h) = (image.width as f64, image.height as f64);
        let [cx, cy] = f.centre.unwrap_or([w / 2.0, h / 2.0]);
        let (cx, cy) = (finite("content-circle", cx)?, finite("content-circle", cy)?);
        let radius = finite("content-circle", f.radius.unwrap_or(w.min(h) / 2.0))?;
        if !(0.0..=w).contains(&cx) || !(0.0..=h).contains(&cy) || radius < 1.0 {
            return Err(Error::invalid(
                "content-circle",
                format!(
                    "the image circle's centre ({cx}, {cy}) must lie in the {w}×{h} image and its \
                     radius {radius} be at least a pixel"
                ),
            ));
        }
        let turn = f
            .tilt
            .map(|tilt| {
                let tilt = finite("content-tilt", tilt)?;
                if tilt.abs() > 90.0 {
                    return Err(Error::invalid(
                        "content-tilt",
                        format!("must lie within ±90 degrees, got {tilt}"),
                    ));
                }
                // The dome master's turn (crate::projection's `domemaster`), inverted.
                Ok(DMat3::from_rotation_x((90.0 - tilt).to_radians()).transpose())
            })
            .transpose()?;
        let pad = PAD as f64;
        Ok(Content {
            atlas: Atlas::fisheye(image, cx, cy, radius)?,
            kind: Kind::Fisheye {
                w: image.width,
                h: image.height,
                cx: cx - 0.5 + pad,
                cy: cy - 0.5 + pad,
                radius,
                half: fov.to_radians() / 2.0,
                turn,
            },
            orientation: Orientation::default(),
            split: None,
            copies: Default::default(),
        })
    }
}
