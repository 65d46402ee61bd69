//! Content sources: what the viewer should see in every direction. A source maps a unit world
//! direction to a position in its [`Atlas`], a padded texel array in which plain bilinear or
//! bicubic filtering equals seamless filtering of the source (across cube-face edges, across
//! the ±180° seam of a full panorama, over the poles of an equirectangular image).
//!
//! * Cube map: the cube-map table of [`crate::cubemap`].
//! * Equirectangular: u = 0.5 + lon/hfov, v = 0.5 − lat/vfov, lon = atan2(x, −z),
//!   lat = asin(y); with hfov = 360, vfov = 180 this is the u = 0.5 + atan2(x, −z)/2π,
//!   v = 0.5 − asin(y)/π of docs/conventions.md.
//! * Cylindrical panorama (seed 001): u = 0.5 + lon/hfov, v = 0.5 − y/(H·√(x² + z²)) with
//!   H = 2·tan(vfov/2); seed 001 writes v = z/(H·√(x²+y²)) + 0.5 for a z-up frame with v up.
//!
//! * Fisheye (angular, equidistant) and dome master: the angle θ from the image circle's axis
//!   is linear in the distance from the circle's centre, r = R·θ/(fov/2), at the angle
//!   atan2(y, x) from the +x axis with image rows running down; the axis is −z, or for a dome
//!   master the zenith tilted forward by `tilt`, the front of the dome at the bottom of the image
//!   (the projection `domemaster` of [`crate::projection`], read backwards). Directions beyond
//!   fov/2 from the axis are not covered.
//!
//! Each source has its own orientation: the content frame is turned by it before lookup.

mod atlas;
mod fisheye;
pub mod pattern;
pub mod projective;
pub mod residual;
pub mod testcard;

pub use atlas::{Atlas, PAD};
pub use fisheye::Fisheye;

use atlas::Rule;

use crate::cubemap::{self, CubeMap};
use crate::error::{Error, Result, finite};
use crate::projection::Orientation;
use crate::raster::{Pixel, Raster, split};
use glam::{DMat3, DVec3};
use rayon::prelude::*;
use std::f64::consts::PI;

#[derive(Debug, Clone, Copy, PartialEq)]
enum Kind {
    Cube {
        n: usize,
        /// How the faces lie in the source image, when the content came from one; a new
        /// frame ([`Content::refill`]) is split the same way.
        layout: Option<cubemap::Layout>,
    },
    Panorama {
        w: usize,
        h: usize,
        hfov: f64,
        vertical: Vertical,
    },
    Fisheye {
        w: usize,
        h: usize,
        /// The circle's centre and radius in atlas texels (centre as `locate` gives positions).
        cx: f64,
        cy: f64,
        radius: f64,
        /// Half the field of view, radians.
        half: f64,
        /// Content frame → the fisheye's own frame (axis −z): the dome master's turn, inverted.
        turn: Option<DMat3>,
    },
}

#[derive(Debug, Clone, Copy, PartialEq)]
enum Vertical {
    /// Latitude linear in v over `vfov` radians.
    Equirect { vfov: f64 },
    /// Height on the unit cylinder linear in v over `h` = 2·tan(vfov/2).
    Cylinder { h: f64 },
}

/// A content source ready to be sampled.
#[derive(Debug, Clone)]
pub struct Content<T> {
    atlas: Atlas<T>,
    kind: Kind,
    orientation: Orientation,
    /// A cylindrical panorama looked up by seed 001's linear + residual split instead of
    /// exactly ([`Content::with_residual_split`]).
    split: Option<std::sync::Arc<residual::ResidualSplit>>,
    /// The atlas texels a new frame fills by copying ([`Content::refill`]), listed once.
    copies: std::sync::OnceLock<std::sync::Arc<Vec<(u32, u32)>>>,
}

/// Where a direction falls in the atlas: continuous texel coordinates, integers at texel
/// centres. `None` where the content does not cover the direction.
pub trait Locate: Sync {
    /// The atlas position of world direction `d` (texel centres at integers), or `None` where the
    /// content does not cover it.
    fn locate(&self, d: DVec3) -> Option<(f64, f64)>;

    /// The rectangle [x0, y0, x1, y1] outside which `locate` gives `None`, when the content
    /// covers only part of the sphere that way (a partial panorama). Interpolated positions
    /// near it are recomputed exactly, so coverage is decided exactly.
    fn bounds(&self) -> Option<[f64; 4]> {
        None
    }

    /// The circle [centre x, centre y, radius] in atlas texels outside which `locate` gives
    /// `None`, when the content is a fisheye's image circle; checked like [`Locate::bounds`].
    fn circle(&self) -> Option<[f64; 3]> {
        None
    }

    /// Whether `locate` is cheap and bounded in its derivatives, continuous but across seams
    /// [`Locate::near_a_seam`] can point out: a cube map, whose faces meet at seams and whose
    /// lookup is a face choice and a division. Plans then interpolate directions, not
    /// positions, over the cells a seam crosses. A panorama's lookup is trigonometry and
    /// unbounded at its poles, so it says no.
    fn has_seams(&self) -> bool {
        false
    }

    /// Whether atlas position (x, y), as `locate` gives it, lies within `margin` texels of a
    /// seam: there a direction a little off could be located on the other side.
    fn near_a_seam(&self, x: f64, y: f64, margin: f64) -> bool {
        let _ = (x, y, margin);
        false
    }

    /// `locate` where the position lies at least `margin` texels from every seam, else `None`
    /// (as where the content does not cover the direction). Within a few ulps of `locate`'s
    /// position (a content may trade a division for a multiplication), so only for positions
    /// that may differ from the exact ones by a stated bound.
    #[inline]
    fn locate_clear(&self, d: DVec3, margin: f64) -> Option<(f64, f64)> {
        self.locate(d)
            .filter(|&(x, y)| !self.near_a_seam(x, y, margin))
    }
}

fn panorama_fov(name: &str, deg: f64, max: f64) -> Result<f64> {
    let deg = finite(name, deg)?;
    if deg <= 0.0 || deg > max {
        return Err(Error::invalid(
            name,
            format!("must be above 0 and at most {max} degrees, got {deg}"),
        ));
    }
    Ok(deg.to_radians())
}

impl<T: Pixel> Content<T> {
    /// A cube map, covering every direction.
    pub fn cube(cube: &CubeMap<T>) -> Self {
        Content {
            atlas: Atlas::cube(cube),
            kind: Kind::Cube {
                n: cube.size,
                layout: None,
            },
            orientation: Orientation::default(),
            split: None,
            copies: Default::default(),
        }
    }

    /// An equirectangular panorama spanning `hfov` × `vfov` degrees, centred on −z.
    pub fn equirect(image: &Raster<T>, hfov: f64, vfov: f64) -> Result<Self> {
        let hfov = panorama_fov("content-hfov", hfov, 360.0)?;
        let vfov = panorama_fov("content-vfov", vfov, 180.0)?;
        let full = (hfov - 2.0 * PI).abs() < 1e-12;
        let poles = full && (vfov - PI).abs() < 1e-12;
        Ok(Content {
            atlas: Atlas::panorama(image, full, poles)?,
            kind: Kind::Panorama {
                w: image.width,
                h: image.height,
                hfov,
                vertical: Vertical::Equirect { vfov },
            },
            orientation: Orientation::default(),
            split: None,
            copies: Default::default(),
        })
    }

    /// A cylindrical panorama spanning `hfov` degrees around and `vfov` degrees vertically.
    pub fn cylindrical(image: &Raster<T>, hfov: f64, vfov: f64) -> Result<Self> {
        let hfov = panorama_fov("content-hfov", hfov, 360.0)?;
        let vfov = finite("content-vfov", vfov)?;
        if vfov <= 0.0 || vfov >= 180.0 {
            return Err(Error::invalid(
                "content-vfov",
                format!("must be above 0 and below 180 degrees for a cylinder, got {vfov}"),
            ));
        }
        let full = (hfov - 2.0 * PI).abs() < 1e-12;
        Ok(Content {
            atlas: Atlas::panorama(image, full, false)?,
            kind: Kind::Panorama {
                w: image.width,
                h: image.height,
                hfov,
                vertical: Vertical::Cylinder {
                    h: 2.0 * (vfov.to_radians() / 2.0).tan(),
                },
            },
            orientation: Orientation::default(),
            split: None,
            copies: Default::default(),
        })
    }

    /// Takes the pixels of a new frame of the same size and layout, keeping the geometry (and
    /// so every plan made for it): a movie's frame loop. `row(y, pixels)` writes row y of the
    /// `size` = (width, height) frame, converting it from the frame's own pixel format as it
    /// goes (rows in parallel); an error if the size differs from the first frame's, or for a
    /// cube map not read from one image.
    pub fn refill(
        &mut self,
        size: (usize, usize),
        row: impl Fn(usize, &mut [T]) + Sync,
    ) -> Result<()> {
        let (w, h, rule) = match self.kind {
            Kind::Cube { layout, n } => {
                let layout = layout.ok_or_else(|| {
                    Error::invalid("content", "this cube map was not read from one image")
                })?;
                let (w, h) = layout.image_size(n);
                (w, h, None)
            }
            Kind::Panorama {
                w,
                h,
                hfov,
                vertical,
            } => {
                let full = (hfov - 2.0 * PI).abs() < 1e-12;
                let poles = full
                    && matches!(vertical, Vertical::Equirect { vfov } if (vfov - PI).abs() < 1e-12);
                (w, h, Some(Rule::Panorama { wrap: full, poles }))
            }
            Kind::Fisheye {
                w,
                h,
                cx,
                cy,
                radius,
                ..
            } => {
                let pad = PAD as f64;
                let rule = Rule::Circle {
                    cx: cx + 0.5 - pad,
                    cy: cy + 0.5 - pad,
                    radius,
                };
                (w, h, Some(rule))
            }
        };
        if (w, h) != size {
            return Err(Error::invalid(
                "content",
                format!(
                    "a frame is {}×{} pixels where the first was {w}×{h}",
                    size.0, size.1
                ),
            ));
        }
        match (self.kind, rule) {
            (Kind::Cube { layout, .. }, _) => {
                let mut image = Raster::new(w, h);
                image
                    .data
                    .par_chunks_mut(w)
                    .enumerate()
                    .for_each(|(y, r)| row(y, r));
                let layout = layout.expect("checked above");
                self.atlas = Atlas::cube(&layout.split(&image)?);
            }
            (_, Some(rule)) => {
                let copies = self
                    .copies
                    .get_or_init(|| std::sync::Arc::new(Atlas::<T>::copies(rule, w, h)))
                    .clone();
                self.atlas.refill(w, h, &copies, row);
            }
            (_, None) => unreachable!("panoramas and fisheyes have a rule"),
        }
        Ok(())
    }

    /// Looks a cylindrical panorama up by seed 001's split into a linear part and a residual
    /// table ([`residual`]), with the residuals in f32 or quantised to `bits`; an error for
    /// any other content.
    pub fn with_residual_split(mut self, bits: Option<u32>) -> Result<Self> {
        let Kind::Panorama {
            vertical: Vertical::Cylinder { h },
            ..
        } = self.kind
        else {
            return Err(Error::invalid(
                "content-lookup",
                "the residual split is seed 001's lookup for cylindrical panoramas only",
            ));
        };
        if bits.is_some_and(|b| !(2..=16).contains(&b)) {
            return Err(Error::invalid(
                "content-lookup",
                "residual bits must be 2–16",
            ));
        }
        self.split = Some(std::sync::Arc::new(residual::ResidualSplit::new(h, bits)));
        Ok(self)
    }

    /// Turns the content: a direction d of the world shows the content's C⁻¹·d.
    pub fn with_orientation(mut self, orientation: Orientation) -> Self {
        self.orientation = orientation;
        self
    }

    /// The padded texel array the content is sampled from.
    pub fn atlas(&self) -> &Atlas<T> {
        &self.atlas
    }

    /// The content seen in direction `d`, bilinearly filtered as a plan's bilinear tap reads it
    /// (the same split into texel and 1/65536 fraction); `None` where the content does not
    /// cover `d`. For one-off lookups (a ray caster's shading); images go through a
    /// [`crate::render::Plan`].
    pub fn sample(&self, d: DVec3) -> Option<[f32; 4]> {
        let (x, y) = self.locate(d)?;
        // locate keeps positions inside the padded atlas, so they are non-negative.
        let ((i, fx), (j, fy)) = (split(x.max(0.0)), split(y.max(0.0)));
        let (i, j) = (i as usize, j as usize);
        let w = self.atlas.width;
        if i + 1 >= w || j + 1 >= self.atlas.height {
            return None;
        }
        let at = j * w + i;
        let a = &self.atlas.data;
        Some(T::bilinear(a[at], a[at + 1], a[at + w], a[at + w + 1], fx, fy).to_f32())
    }

    /// How directions map into the atlas, for a GPU twin of [`Locate::locate`]: kind (0 cube,
    /// 1 equirect, 2 cylinder, 3 fisheye), then the face size, or the panorama's width, height,
    /// hfov and vfov (equirect, radians) or H = 2·tan(vfov/2) (cylinder), or the fisheye
    /// circle's centre x, y and radius in atlas texels and half its field of view (radians).
    /// Directions are turned into the content's frame by [`Content::frame`] first.
    pub fn lookup(&self) -> (u32, [f64; 4]) {
        match self.kind {
            Kind::Cube { n, .. } => (0, [n as f64, 0.0, 0.0, 0.0]),
            Kind::Panorama {
                w,
                h,
                hfov,
                vertical: Vertical::Equirect { vfov },
            } => (1, [w as f64, h as f64, hfov, vfov]),
            Kind::Panorama {
                w,
                h,
                hfov,
                vertical: Vertical::Cylinder { h: height },
            } => (2, [w as f64, h as f64, hfov, height]),
            Kind::Fisheye {
                cx,
                cy,
                radius,
                half,
                ..
            } => (3, [cx, cy, radius, half]),
        }
    }

    /// World → the frame [`Content::lookup`]'s formulas take directions in: the orientation's
    /// inverse, then for a dome master its turn from the zenith.
    pub fn frame(&self) -> DMat3 {
        let m = self.orientation.matrix().transpose();
        match self.kind {
            Kind::Fisheye { turn: Some(t), .. } => t * m,
            _ => m,
        }
    }

    /// The content's orientation in the world (identity unless [`Content::with_orientation`] set
    /// one).
    pub fn orientation(&self) -> Orientation {
        self.orientation
    }
}

impl<T: Pixel> Locate for Content<T> {
    #[inline]
    fn locate(&self, d: DVec3) -> Option<(f64, f64)> {
        let d = self.orientation.apply_inverse(d);
        let pad = PAD as f64;
        match self.kind {
            Kind::Cube { n, .. } => {
                let (face, s, t) = cubemap::select(d);
                let nf = n as f64;
                let y0 = (face.index() * (n + 2 * PAD)) as f64;
                Some((s * nf - 0.5 + pad, y0 + t * nf - 0.5 + pad))
            }
            Kind::Panorama {
                w,
                h,
                hfov,
                vertical,
            } => {
                let (u, v) = match &self.split {
                    Some(split) => {
                        let (theta, up) = split.angles(d)?;
                        (0.5 + theta / hfov, 0.5 - up)
                    }
                    None => {
                        let u = 0.5 + d.x.atan2(-d.z) / hfov;
                        let rho = d.x.hypot(d.z);
                        let v = match vertical {
                            Vertical::Equirect { vfov } => 0.5 - d.y.atan2(rho) / vfov,
                            Vertical::Cylinder { h } => {
                                if rho == 0.0 {
                                    return None;
                                }
                                0.5 - d.y / (rho * h)
                            }
                        };
                        (u, v)
                    }
                };
                if !(0.0..=1.0).contains(&u) || !(0.0..=1.0).contains(&v) {
                    return None;
                }
                Some((u * w as f64 - 0.5 + pad, v * h as f64 - 0.5 + pad))
            }
            Kind::Fisheye {
                cx,
                cy,
                radius,
                half,
                turn,
                ..
            } => {
                let d = turn.map_or(d, |t| t * d);
                let rho = d.x.hypot(d.y);
                let theta = rho.atan2(-d.z);
                // The projection module's tolerance, so the rim of its own fisheye is covered.
                if theta > half * (1.0 + 1e-12) {
                    return None;
                }
                if rho == 0.0 {
                    // The axis, or (a 360° fisheye) straight behind it: all of the rim.
                    return Some(if theta == 0.0 {
                        (cx, cy)
                    } else {
                        (cx + radius, cy)
                    });
                }
                let k = radius * theta / (half * rho);
                let (x, y) = (cx + k * d.x, cy - k * d.y);
                // A full-frame fisheye's circle reaches past the frame; what lies beyond the
                // frame was not shot.
                let [x0, y0, x1, y1] = self.bounds()?;
                ((x0..=x1).contains(&x) && (y0..=y1).contains(&y)).then_some((x, y))
            }
        }
    }

    fn has_seams(&self) -> bool {
        matches!(self.kind, Kind::Cube { .. })
    }

    #[inline]
    fn near_a_seam(&self, x: f64, y: f64, margin: f64) -> bool {
        let Kind::Cube { n, .. } = self.kind else {
            return false;
        };
        // Faces are stacked top to bottom, each in a border of PAD texels; `locate` gives
        // positions from PAD − ½ to PAD − ½ + n on both axes of its face.
        let (lo, hi) = (PAD as f64 - 0.5 + margin, (n + PAD) as f64 - 0.5 - margin);
        // Positions are never negative, so truncation finds the face (`%` on floats and
        // `floor` are library calls on baseline x86-64).
        let block = (n + 2 * PAD) as f64;
        let y = y - f64::from((y / block) as u32) * block;
        x <= lo || x >= hi || y <= lo || y >= hi
    }

    #[inline]
    fn locate_clear(&self, d: DVec3, margin: f64) -> Option<(f64, f64)> {
        let Kind::Cube { n, .. } = self.kind else {
            // Panoramas have no seams.
            return self.locate(d);
        };
        // `locate`'s s·n − ½ + PAD with one division for both axes, and the seam test on the
        // face-local position, without finding the face again from y.
        let (face, sc, tc, ma) = cubemap::select_raw(self.orientation.apply_inverse(d));
        let nf = n as f64;
        let r = 0.5 * nf / ma;
        let centre = 0.5 * nf - 0.5 + PAD as f64;
        let (x, y) = (sc * r + centre, tc * r + centre);
        let (lo, hi) = (PAD as f64 - 0.5 + margin, (n + PAD) as f64 - 0.5 - margin);
        if x <= lo || x >= hi || y <= lo || y >= hi {
            return None;
        }
        Some((x, y + (face.index() * (n + 2 * PAD)) as f64))
    }

    fn circle(&self) -> Option<[f64; 3]> {
        match self.kind {
            Kind::Fisheye { cx, cy, radius, .. } => Some([cx, cy, radius]),
            _ => None,
        }
    }

    fn bounds(&self) -> Option<[f64; 4]> {
        match self.kind {
            Kind::Cube { .. } => None,
            Kind::Panorama { w, h, .. } | Kind::Fisheye { w, h, .. } => {
                let pad = PAD as f64;
                Some([
                    pad - 0.5,
                    pad - 0.5,
                    w as f64 + pad - 0.5,
                    h as f64 + pad - 0.5,
                ])
            }
        }
    }
}

/// How a content image is laid out.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Format {
    /// Six faces side by side in omniwarp's order (+X −X +Y −Y +Z −Z).
    Cubemap,
    /// ffmpeg v360's `c3x2`.
    CubemapC3x2,
    /// ffmpeg v360's `c6x1`.
    CubemapC6x1,
    /// An equirectangular panorama: longitude linear across, latitude linear down (360° wide,
    /// with square pixels, unless a field of view is given).
    Equirect,
    /// A cylindrical panorama (seed 001): longitude linear across, height on the cylinder linear
    /// down.
    Cylindrical,
    /// An angular fisheye looking at −z (180°, inscribed, unless [`Content::fisheye`] is told
    /// otherwise).
    Fisheye,
    /// A dome master: a 180° angular fisheye whose centre is the zenith, front at the bottom.
    Domemaster,
}

impl Format {
    /// Every format with its name, as `--content-format` spells it.
    pub const NAMES: [(&'static str, Format); 7] = [
        ("cubemap", Format::Cubemap),
        ("cubemap-c3x2", Format::CubemapC3x2),
        ("cubemap-c6x1", Format::CubemapC6x1),
        ("equirect", Format::Equirect),
        ("cylindrical", Format::Cylindrical),
        ("fisheye", Format::Fisheye),
        ("domemaster", Format::Domemaster),
    ];

    /// The format of that name (see [`Format::NAMES`]); an error listing the known names otherwise.
    pub fn parse(name: &str) -> Result<Self> {
        Self::NAMES
            .iter()
            .find(|(n, _)| *n == name)
            .map(|(_, f)| *f)
            .ok_or_else(|| {
                let names: Vec<_> = Self::NAMES.iter().map(|(n, _)| *n).collect();
                Error::invalid(
                    "content-format",
                    format!("unknown format `{name}`; known: {}", names.join(", ")),
                )
            })
    }

    /// The cube layout, for the cube-map formats.
    pub fn cube_layout(self) -> Option<cubemap::Layout> {
        match self {
            Format::Cubemap => Some(cubemap::Layout::Strip),
            Format::CubemapC3x2 => Some(cubemap::Layout::FfmpegC3x2),
            Format::CubemapC6x1 => Some(cubemap::Layout::FfmpegC6x1),
            _ => None,
        }
    }
}

impl<T: Pixel> Content<T> {
    /// Content from an image in the given format. `hfov`/`vfov` (degrees) apply to panoramas
    /// and default to 360 × 180 (equirect) or 360 × the square-pixel height (cylindrical).
    pub fn from_image(
        image: &Raster<T>,
        format: Format,
        hfov: Option<f64>,
        vfov: Option<f64>,
    ) -> Result<Self> {
        if let Some(layout) = format.cube_layout() {
            if hfov.is_some() || vfov.is_some() {
                return Err(Error::invalid(
                    "content-hfov",
                    "a cube map always covers every direction; the field of view is for panoramas",
                ));
            }
            let mut c = Content::cube(&layout.split(image)?);
            if let Kind::Cube { layout: l, .. } = &mut c.kind {
                *l = Some(layout);
            }
            return Ok(c);
        }
        let fisheye = match format {
            Format::Fisheye => Some(Fisheye::FISHEYE),
            Format::Domemaster => Some(Fisheye::DOMEMASTER),
            _ => None,
        };
        if let Some(f) = fisheye {
            if hfov.is_some() || vfov.is_some() {
                return Err(Error::invalid(
                    "content-hfov",
                    "a fisheye's field of view is its image circle's (content-fov)",
                ));
            }
            return Content::fisheye(image, &f);
        }
        let hfov = hfov.unwrap_or(360.0);
        let aspect = image.height as f64 / image.width as f64;
        match format {
            Format::Equirect => Content::equirect(image, hfov, vfov.unwrap_or(hfov * aspect)),
            _ => {
                // Square pixels at the horizon: the cylinder's height per pixel equals its arc.
                let default_vfov = || 2.0 * (hfov.to_radians() * aspect / 2.0).atan().to_degrees();
                Content::cylindrical(image, hfov, vfov.unwrap_or_else(default_vfov))
            }
        }
    }
}
