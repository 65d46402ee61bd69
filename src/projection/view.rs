//! The view transform shared by every projection (seed 000, section 3):
//! V = C·δP(F·zoom) − O, normalised, with C = [right | up | back] built from look-to and
//! look-up, O the off-axis vector (|O| < 1) and `zoom` scaling the screen coordinates.

use super::Projection;
use crate::error::{Error, Outside, Result, finite};
use glam::{DMat3, DVec3};

/// The default look-to, straight ahead (−z), for documents that leave it out.
pub fn default_look_to() -> [f64; 3] {
    [0.0, 0.0, -1.0]
}

/// The default look-up, +y, for documents that leave it out.
pub fn default_look_up() -> [f64; 3] {
    [0.0, 1.0, 0.0]
}

/// The content orientation C: an orthonormal, right-handed basis.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Orientation(DMat3);

impl Default for Orientation {
    fn default() -> Self {
        Orientation(DMat3::IDENTITY)
    }
}

fn finite_vec(name: &str, v: DVec3) -> Result<DVec3> {
    if v.is_finite() {
        Ok(v)
    } else {
        Err(Error::invalid(name, format!("must be finite, got {v}")))
    }
}

impl Orientation {
    /// C from a look-to and a look-up vector (neither need be unit, nor perpendicular).
    pub fn look(look_to: DVec3, look_up: DVec3) -> Result<Self> {
        let lt = finite_vec("look-to", look_to)?;
        let lu = finite_vec("look-up", look_up)?;
        if lt.length() < 1e-12 {
            return Err(Error::invalid("look-to", "must not be the zero vector"));
        }
        if lu.length() < 1e-12 {
            return Err(Error::invalid("look-up", "must not be the zero vector"));
        }
        let lt = lt.normalize();
        let right = lt.cross(lu.normalize());
        // Below ~0.06° between them the basis would be dominated by rounding.
        if right.length() < 1e-6 {
            return Err(Error::invalid("look-up", "must not be parallel to look-to"));
        }
        let right = right.normalize();
        let up = right.cross(lt);
        Ok(Orientation(DMat3::from_cols(right, up, -lt)))
    }

    /// C from yaw (about +y, positive turns left), pitch (about +x, positive looks up) and
    /// roll (about the view axis, positive tilts the horizon clockwise as the viewer sees it),
    /// in degrees,
    /// applied in that order: C = Ry(yaw)·Rx(pitch)·Rz(−roll).
    pub fn yaw_pitch_roll(yaw: f64, pitch: f64, roll: f64) -> Result<Self> {
        let yaw = finite("yaw", yaw)?.to_radians();
        let pitch = finite("pitch", pitch)?.to_radians();
        let roll = finite("roll", roll)?.to_radians();
        Ok(Orientation(
            DMat3::from_rotation_y(yaw)
                * DMat3::from_rotation_x(pitch)
                * DMat3::from_rotation_z(-roll),
        ))
    }

    /// The matrix C, columns right, up, back.
    pub fn matrix(&self) -> DMat3 {
        self.0
    }

    /// C·d: a direction `d` of the local (view or content) frame, in the world.
    #[inline]
    pub fn apply(&self, d: DVec3) -> DVec3 {
        self.0 * d
    }

    /// Cᵀ·d, without building Cᵀ: each component the dot product with a column of C, summed
    /// in the order `transpose() * d` sums (so the same bits). Plans call this once a sample.
    #[inline]
    pub fn apply_inverse(&self, d: DVec3) -> DVec3 {
        let c = &self.0;
        DVec3::new(c.x_axis.dot(d), c.y_axis.dot(d), c.z_axis.dot(d))
    }
}

/// A projection seen through the view transform: screen position F ↔ sampling vector V.
#[derive(Debug)]
pub struct View {
    projection: Box<dyn Projection>,
    orientation: Orientation,
    offaxis: DVec3,
    zoom: f64,
}

impl View {
    /// The view of `projection` through orientation C, off-axis vector O (|O| < 1) and `zoom`
    /// (0.001–1000); errors name `offaxis` or `zoom`.
    pub fn new(
        projection: Box<dyn Projection>,
        orientation: Orientation,
        offaxis: DVec3,
        zoom: f64,
    ) -> Result<Self> {
        let offaxis = finite_vec("offaxis", offaxis)?;
        if offaxis.length() >= 1.0 {
            return Err(Error::invalid(
                "offaxis",
                format!(
                    "its length must be below 1 (else V vanishes where δP = O), got {}",
                    offaxis.length()
                ),
            ));
        }
        let zoom = finite("zoom", zoom)?;
        let (lo, hi) = crate::limits::ZOOM;
        if !(lo..=hi).contains(&zoom) {
            return Err(Error::invalid(
                "zoom",
                format!("must be positive, between {lo} and {hi}, got {zoom}"),
            ));
        }
        Ok(View {
            projection,
            orientation,
            offaxis,
            zoom,
        })
    }

    /// The plain projection: identity orientation, no off-axis vector, zoom 1.
    pub fn plain(projection: Box<dyn Projection>) -> Self {
        View {
            projection,
            orientation: Orientation::default(),
            offaxis: DVec3::ZERO,
            zoom: 1.0,
        }
    }

    /// The projection δP alone, without the view transform.
    pub fn projection(&self) -> &dyn Projection {
        self.projection.as_ref()
    }

    /// Orientation C, off-axis vector O and zoom, for the GPU's twin of [`View::direction`].
    pub fn parts(&self) -> (glam::DMat3, DVec3, f64) {
        (self.orientation.matrix(), self.offaxis, self.zoom)
    }

    /// The unit sampling vector V at screen position (s, t).
    pub fn direction(&self, s: f64, t: f64) -> Result<DVec3, Outside> {
        let d = self.projection.forward(s * self.zoom, t * self.zoom)?;
        // |O| < 1 and |C·d| = 1 keep this away from zero.
        Ok((self.orientation.apply(d) - self.offaxis).normalize())
    }

    /// [`View::direction`] through [`Projection::forward_unbounded`].
    pub fn direction_unbounded(&self, s: f64, t: f64) -> Result<DVec3, Outside> {
        let d = self
            .projection
            .forward_unbounded(s * self.zoom, t * self.zoom)?;
        Ok((self.orientation.apply(d) - self.offaxis).normalize())
    }

    /// The screen position whose sampling vector points along `v` (any non-zero length).
    pub fn screen(&self, v: DVec3) -> Result<(f64, f64), Outside> {
        let v = v.normalize();
        // C·d = λ·V + O with |d| = 1: λ² + 2λ(V·O) + |O|² − 1 = 0, whose one positive root is
        // this one because |O| < 1.
        let vo = v.dot(self.offaxis);
        let lambda = -vo + (vo * vo - self.offaxis.length_squared() + 1.0).sqrt();
        let d = self.orientation.apply_inverse(lambda * v + self.offaxis);
        let (s, t) = self.projection.inverse(d.normalize())?;
        Ok((s / self.zoom, t / self.zoom))
    }
}

/// Normalised screen coordinates of a continuous pixel position (x to the right, y down, in
/// pixels from the image's top-left corner; pixel (i, j) has its centre at (i + 0.5, j + 0.5)).
pub fn screen_of_pixel(x: f64, y: f64, width: u32, height: u32) -> (f64, f64) {
    (2.0 * x / width as f64 - 1.0, 1.0 - 2.0 * y / height as f64)
}

/// The inverse of [`screen_of_pixel`].
pub fn pixel_of_screen(s: f64, t: f64, width: u32, height: u32) -> (f64, f64) {
    (
        (s + 1.0) * width as f64 / 2.0,
        (1.0 - t) * height as f64 / 2.0,
    )
}
