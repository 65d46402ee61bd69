//! Lens model names, as mrcal spells them, and what each model can do.
//!
//! A model string names a family and, for the splined family, its configuration; it parses and
//! prints back exactly. Two names are ours, for OpenCV models mrcal lacks: `LENSMODEL_OPENCV14`
//! (the 14-coefficient pinhole with a tilted sensor) and `LENSMODEL_OPENCV_FISHEYE`
//! (Kannala–Brandt, OpenCV's `cv::fisheye`).

use crate::error::{Error, Result};
use std::fmt;
use std::str::FromStr;

/// A lens model: family plus configuration.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LensModel {
    /// `LENSMODEL_PINHOLE`: no distortion; points in front of the camera (z > 0) only.
    Pinhole,
    /// OpenCV's pinhole with 4, 5, 8, 12 or 14 distortion coefficients.
    OpenCv(u8),
    /// `LENSMODEL_OPENCV_FISHEYE`: OpenCV's Kannala–Brandt fisheye (k1..k4), rays under 90° from
    /// the axis only.
    OpenCvFisheye,
    /// `LENSMODEL_STEREOGRAPHIC`: mrcal's stereographic projection; every direction but straight
    /// behind.
    Stereographic,
    /// `LENSMODEL_LONLAT`: mrcal's equirectangular, longitude across and latitude down, focal
    /// lengths in pixels per radian.
    LonLat,
    /// `LENSMODEL_LATLON`: mrcal's transverse equirectangular, latitude across and longitude down.
    LatLon,
    /// `LENSMODEL_CAHVOR`: mrcal's CAHVOR, a pinhole with radial distortion about a tilted axis
    /// (α, β, r0, r1, r2).
    Cahvor,
    /// `LENSMODEL_SPLINED_STEREOGRAPHIC_order=O_Nx=NX_Ny=NY_fov_x_deg=F`: mrcal's stereographic
    /// projection plus a B-spline correction over an NX × NY knot grid.
    SplinedStereographic {
        /// Spline order: 2 (quadratic) or 3 (cubic).
        order: u32,
        /// Knots across (`Nx`), at least 2.
        nx: u32,
        /// Knots down (`Ny`), at least 2.
        ny: u32,
        /// Horizontal field of view the knot grid spans, whole degrees, 1–359.
        fov_x_deg: u32,
    },
}

/// What a model can do, for callers to query rather than assume.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Meta {
    /// Points with z ≤ 0 have a pixel of their own (not their antipode's).
    pub can_project_behind_camera: bool,
    /// Unprojection is a formula, not an iteration.
    pub has_closed_form_inverse: bool,
    /// omniwarp computes this model (every model it can name, today).
    pub supported: bool,
}

const PREFIX: &str = "LENSMODEL_";

impl LensModel {
    /// Number of intrinsics, starting fx, fy, cx, cy.
    pub fn intrinsics_len(&self) -> usize {
        match self {
            LensModel::Pinhole
            | LensModel::Stereographic
            | LensModel::LonLat
            | LensModel::LatLon => 4,
            LensModel::OpenCv(n) => 4 + *n as usize,
            LensModel::OpenCvFisheye => 8,
            LensModel::Cahvor => 9,
            LensModel::SplinedStereographic { nx, ny, .. } => {
                4 + 2 * (*nx as usize) * (*ny as usize)
            }
        }
    }

    /// What the model can do.
    pub fn meta(&self) -> Meta {
        let (behind, closed, supported) = match self {
            LensModel::Pinhole => (false, true, true),
            LensModel::OpenCv(_) | LensModel::OpenCvFisheye => (false, false, true),
            LensModel::Stereographic | LensModel::LonLat | LensModel::LatLon => (true, true, true),
            LensModel::Cahvor => (false, false, true),
            LensModel::SplinedStereographic { .. } => (true, false, true),
        };
        Meta {
            can_project_behind_camera: behind,
            has_closed_form_inverse: closed,
            supported,
        }
    }

    /// The names of the intrinsics, in order.
    pub fn intrinsics_names(&self) -> Vec<String> {
        let mut v: Vec<String> = ["fx", "fy", "cx", "cy"].map(String::from).to_vec();
        let rest: &[&str] = match self {
            LensModel::OpenCv(n) => &[
                "k1", "k2", "p1", "p2", "k3", "k4", "k5", "k6", "s1", "s2", "s3", "s4", "taux",
                "tauy",
            ][..*n as usize],
            LensModel::OpenCvFisheye => &["k1", "k2", "k3", "k4"],
            LensModel::Cahvor => &["alpha", "beta", "r0", "r1", "r2"],
            _ => &[],
        };
        v.extend(rest.iter().map(|s| s.to_string()));
        while v.len() < self.intrinsics_len() {
            v.push(format!("knot{}", v.len() - 4));
        }
        v
    }
}

impl fmt::Display for LensModel {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            LensModel::Pinhole => write!(f, "{PREFIX}PINHOLE"),
            LensModel::OpenCv(n) => write!(f, "{PREFIX}OPENCV{n}"),
            LensModel::OpenCvFisheye => write!(f, "{PREFIX}OPENCV_FISHEYE"),
            LensModel::Stereographic => write!(f, "{PREFIX}STEREOGRAPHIC"),
            LensModel::LonLat => write!(f, "{PREFIX}LONLAT"),
            LensModel::LatLon => write!(f, "{PREFIX}LATLON"),
            LensModel::Cahvor => write!(f, "{PREFIX}CAHVOR"),
            LensModel::SplinedStereographic {
                order,
                nx,
                ny,
                fov_x_deg,
            } => write!(
                f,
                "{PREFIX}SPLINED_STEREOGRAPHIC_order={order}_Nx={nx}_Ny={ny}_fov_x_deg={fov_x_deg}"
            ),
        }
    }
}

impl FromStr for LensModel {
    type Err = Error;

    fn from_str(s: &str) -> Result<Self> {
        let bad = |why: String| Error::invalid("model", format!("`{s}`: {why}"));
        let rest = s
            .strip_prefix(PREFIX)
            .ok_or_else(|| bad(format!("a lens model name starts with {PREFIX}")))?;
        Ok(match rest {
            "PINHOLE" => LensModel::Pinhole,
            "OPENCV4" => LensModel::OpenCv(4),
            "OPENCV5" => LensModel::OpenCv(5),
            "OPENCV8" => LensModel::OpenCv(8),
            "OPENCV12" => LensModel::OpenCv(12),
            "OPENCV14" => LensModel::OpenCv(14),
            "OPENCV_FISHEYE" => LensModel::OpenCvFisheye,
            "STEREOGRAPHIC" => LensModel::Stereographic,
            "LONLAT" => LensModel::LonLat,
            "LATLON" => LensModel::LatLon,
            "CAHVOR" => LensModel::Cahvor,
            _ => {
                let config = rest.strip_prefix("SPLINED_STEREOGRAPHIC_").ok_or_else(|| {
                    bad("unknown model; known: PINHOLE, OPENCV4/5/8/12/14, OPENCV_FISHEYE, \
                         STEREOGRAPHIC, LONLAT, LATLON, CAHVOR, SPLINED_STEREOGRAPHIC_order=…_Nx=…_Ny=…_fov_x_deg=…"
                        .into())
                })?;
                // The configuration is order=O_Nx=NX_Ny=NY_fov_x_deg=F; `fov_x_deg` itself holds
                // underscores, so match the whole shape rather than split blindly.
                let parsed = parse_splined(config).ok_or_else(|| {
                    bad("expected SPLINED_STEREOGRAPHIC_order=O_Nx=NX_Ny=NY_fov_x_deg=F with whole numbers".into())
                })?;
                let (order, nx, ny, fov_x_deg) = parsed;
                if !(2..=3).contains(&order) {
                    return Err(bad(format!("spline order must be 2 or 3, got {order}")));
                }
                if nx < 2 || ny < 2 {
                    return Err(bad(format!("needs at least 2×2 knots, got {nx}×{ny}")));
                }
                let (side, all) = (
                    crate::limits::SPLINE_KNOTS_SIDE,
                    crate::limits::SPLINE_KNOTS,
                );
                if nx > side || ny > side || u64::from(nx) * u64::from(ny) > all {
                    return Err(bad(format!(
                        "{nx}×{ny} knots are above the limit of {side} each way and {all} in all"
                    )));
                }
                if fov_x_deg == 0 || fov_x_deg >= 360 {
                    return Err(bad(format!(
                        "fov_x_deg must lie in 1..359, got {fov_x_deg}"
                    )));
                }
                LensModel::SplinedStereographic {
                    order,
                    nx,
                    ny,
                    fov_x_deg,
                }
            }
        })
    }
}

fn parse_splined(config: &str) -> Option<(u32, u32, u32, u32)> {
    let rest = config.strip_prefix("order=")?;
    let (order, rest) = rest.split_once("_Nx=")?;
    let (nx, rest) = rest.split_once("_Ny=")?;
    let (ny, fov) = rest.split_once("_fov_x_deg=")?;
    let num = |s: &str| {
        (!s.is_empty() && s.bytes().all(|b| b.is_ascii_digit()))
            .then(|| s.parse().ok())
            .flatten()
    };
    Some((num(order)?, num(nx)?, num(ny)?, num(fov)?))
}
