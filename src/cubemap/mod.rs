//! Cube maps: face selection and face coordinates exactly as the cube-map table shared by
//! Vulkan, Direct3D and OpenGL, so the CPU path samples the texels a wgpu
//! `TextureViewDimension::Cube` samples.
//!
//! | face | major axis ma | sc | tc |
//! | --- | --- | --- | --- |
//! | +X | x | −z | −y |
//! | −X | x | +z | −y |
//! | +Y | y | +x | +z |
//! | −Y | y | +x | −z |
//! | +Z | z | +x | −y |
//! | −Z | z | −x | −y |
//!
//! Face coordinates s = (sc/|ma| + 1)/2 to the right, t = (tc/|ma| + 1)/2 down, each in
//! [0, 1]; face images are stored top row first. Where two axes tie for the largest magnitude
//! the earlier of x, y, z wins (any choice samples the same texel on the shared edge).

mod layout;

pub use layout::Layout;

use crate::raster::{Pixel, Raster};
use glam::DVec3;

/// The six faces in omniwarp's order.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Face {
    /// +X: the face to the right of a viewer with no orientation.
    PosX = 0,
    /// −X: the face to the left of a viewer with no orientation.
    NegX = 1,
    /// +Y: the face straight up (the zenith).
    PosY = 2,
    /// −Y: the face straight down (the nadir).
    NegY = 3,
    /// +Z: the face behind a viewer with no orientation.
    PosZ = 4,
    /// −Z: the face straight ahead of a viewer with no orientation.
    NegZ = 5,
}

impl Face {
    /// The six faces in omniwarp's order, so that `Face::ALL[k].index() == k`.
    pub const ALL: [Face; 6] = [
        Face::PosX,
        Face::NegX,
        Face::PosY,
        Face::NegY,
        Face::PosZ,
        Face::NegZ,
    ];

    /// The face's position in [`Face::ALL`] and in [`CubeMap::faces`], 0 to 5.
    pub fn index(self) -> usize {
        self as usize
    }

    /// File-name friendly label: `px`, `nx`, `py`, `ny`, `pz`, `nz`.
    pub fn label(self) -> &'static str {
        ["px", "nx", "py", "ny", "pz", "nz"][self.index()]
    }
}

/// The face a direction selects and its (sc, tc, |ma|).
#[inline]
pub fn select_raw(d: DVec3) -> (Face, f64, f64, f64) {
    let (ax, ay, az) = (d.x.abs(), d.y.abs(), d.z.abs());
    if ax >= ay && ax >= az {
        if d.x >= 0.0 {
            (Face::PosX, -d.z, -d.y, ax)
        } else {
            (Face::NegX, d.z, -d.y, ax)
        }
    } else if ay >= az {
        if d.y >= 0.0 {
            (Face::PosY, d.x, d.z, ay)
        } else {
            (Face::NegY, d.x, -d.z, ay)
        }
    } else if d.z >= 0.0 {
        (Face::PosZ, d.x, -d.y, az)
    } else {
        (Face::NegZ, -d.x, -d.y, az)
    }
}

/// The face a (non-zero) direction selects and its face coordinates (s, t) ∈ [0, 1]².
#[inline]
pub fn select(d: DVec3) -> (Face, f64, f64) {
    let (face, sc, tc, ma) = select_raw(d);
    (face, 0.5 * (sc / ma + 1.0), 0.5 * (tc / ma + 1.0))
}

/// The point on the unit cube's face plane at face coordinates (s, t): the inverse of
/// [`select`] up to length. s and t may lie outside [0, 1] (the face plane extended).
pub fn face_point(face: Face, s: f64, t: f64) -> DVec3 {
    let (sc, tc) = (2.0 * s - 1.0, 2.0 * t - 1.0);
    match face {
        Face::PosX => DVec3::new(1.0, -tc, -sc),
        Face::NegX => DVec3::new(-1.0, -tc, sc),
        Face::PosY => DVec3::new(sc, 1.0, tc),
        Face::NegY => DVec3::new(sc, -1.0, -tc),
        Face::PosZ => DVec3::new(sc, -tc, 1.0),
        Face::NegZ => DVec3::new(-sc, -tc, -1.0),
    }
}

/// Six square faces of `size` × `size` texels, in [`Face`] order.
#[derive(Debug, Clone, PartialEq)]
pub struct CubeMap<T> {
    /// Width and height of every face in texels.
    pub size: usize,
    /// The face images, top row first, indexed by [`Face::index`].
    pub faces: [Raster<T>; 6],
}

impl<T: Pixel> CubeMap<T> {
    /// Checks that the six faces are square and equal in size.
    pub fn from_faces(faces: [Raster<T>; 6]) -> crate::Result<Self> {
        let size = faces[0].width;
        for (face, r) in Face::ALL.iter().zip(&faces) {
            if r.width != size || r.height != size || size == 0 {
                return Err(crate::Error::invalid(
                    "content",
                    format!(
                        "cube face {} is {}×{}; all faces must be square and of one size",
                        face.label(),
                        r.width,
                        r.height
                    ),
                ));
            }
        }
        Ok(CubeMap { size, faces })
    }

    /// A cube map whose texels average `f` over `ss` × `ss` directions inside each texel.
    pub fn from_fn(size: usize, ss: usize, f: impl Fn(DVec3) -> T + Sync) -> Self {
        Self::from_fn_on(size, ss, [true; 6], f)
    }

    /// [`CubeMap::from_fn`] on the faces marked in `on` only (the others are left transparent
    /// black): a warp that samples two faces of a fine cube pays for two.
    pub fn from_fn_on(
        size: usize,
        ss: usize,
        on: [bool; 6],
        f: impl Fn(DVec3) -> T + Sync,
    ) -> Self {
        use rayon::prelude::*;
        let texel = |face: Face, x: usize, y: usize| {
            let mut acc = [0.0f32; 4];
            for a in 0..ss {
                for b in 0..ss {
                    let s = (x as f64 + (a as f64 + 0.5) / ss as f64) / size as f64;
                    let t = (y as f64 + (b as f64 + 0.5) / ss as f64) / size as f64;
                    let v = f(face_point(face, s, t).normalize()).to_f32();
                    for k in 0..4 {
                        acc[k] += v[k];
                    }
                }
            }
            T::from_f32(acc.map(|c| c / (ss * ss) as f32))
        };
        let faces = Face::ALL.map(|face| {
            let mut data = vec![T::from_f32([0.0; 4]); size * size];
            if on[face.index()] {
                data.par_chunks_mut(size).enumerate().for_each(|(y, row)| {
                    for (x, p) in row.iter_mut().enumerate() {
                        *p = texel(face, x, y);
                    }
                });
            }
            Raster {
                width: size,
                height: size,
                data,
            }
        });
        CubeMap { size, faces }
    }

    /// The image of `face`.
    pub fn face(&self, face: Face) -> &Raster<T> {
        &self.faces[face.index()]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn select_inverts_face_point_on_every_face() {
        for face in Face::ALL {
            for &(s, t) in &[(0.5, 0.5), (0.1, 0.9), (0.99, 0.01), (0.3, 0.7)] {
                let (f, s2, t2) = select(face_point(face, s, t));
                assert_eq!(f, face);
                assert!((s - s2).abs() < 1e-15 && (t - t2).abs() < 1e-15);
            }
        }
    }

    #[test]
    fn face_centres_are_the_axes() {
        let axes = [
            DVec3::X,
            DVec3::NEG_X,
            DVec3::Y,
            DVec3::NEG_Y,
            DVec3::Z,
            DVec3::NEG_Z,
        ];
        for (face, axis) in Face::ALL.iter().zip(axes) {
            assert_eq!(face_point(*face, 0.5, 0.5), axis);
        }
    }

    #[test]
    fn table_matches_the_graphics_apis() {
        // The top-left texel of +X looks towards +y and +z (sc = −z, tc = −y at s = t = 0).
        let d = face_point(Face::PosX, 0.0, 0.0);
        assert_eq!(d, DVec3::new(1.0, 1.0, 1.0));
        // +Y: s follows +x, t follows +z (top row towards −z).
        assert_eq!(
            face_point(Face::PosY, 0.0, 0.0),
            DVec3::new(-1.0, 1.0, -1.0)
        );
        // −Z: s follows −x.
        assert_eq!(face_point(Face::NegZ, 0.0, 0.0), DVec3::new(1.0, 1.0, -1.0));
    }
}
