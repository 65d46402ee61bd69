//! The padded texel array behind every content source.
//!
//! Each source image gets a border of [`PAD`] texels so that every filter tap stays inside the
//! array and the border holds what seamless filtering would read there:
//! * cube faces: an edge texel of the neighbouring face, found by folding the face plane over
//!   the cube edge (as Vulkan's seamless cube filtering does); in the corners, where three faces
//!   meet, the mean of the three candidates;
//! * full panoramas: the columns of the other side (wrap-around); over the poles of a full
//!   equirectangular image, the row mirrored across the pole half a turn round;
//! * anything else: the nearest edge texel (clamp).

use crate::cubemap::{self, CubeMap, Face};
use crate::raster::{Pixel, Raster};
use crate::{Error, Result};
use glam::DVec3;

/// Border width: bicubic filtering reads one texel before and two after the sample position.
pub const PAD: usize = 2;

/// A source's texels with a border of [`PAD`] texels on every side, filled as seamless
/// filtering would read there (see the module's description).
#[derive(Debug, Clone, PartialEq)]
pub struct Atlas<T> {
    /// Width in texels, border included.
    pub width: usize,
    /// Height in texels, border included (a cube's six bordered faces are stacked top to bottom).
    pub height: usize,
    /// The `width × height` texels, row by row from the top.
    pub data: Vec<T>,
}

impl<T: Pixel> Atlas<T> {
    /// The six faces stacked top to bottom in face order, each with its own border.
    pub fn cube(cube: &CubeMap<T>) -> Self {
        let n = cube.size;
        let side = n + 2 * PAD;
        let mut data = Vec::with_capacity(side * side * 6);
        for face in Face::ALL {
            for y in 0..side {
                for x in 0..side {
                    data.push(cube_texel(
                        cube,
                        face,
                        x as isize - PAD as isize,
                        y as isize - PAD as isize,
                    ));
                }
            }
        }
        Atlas {
            width: side,
            height: side * 6,
            data,
        }
    }

    /// A panorama image with its border: wrapped round from the other side when `wrap` (a full
    /// 360° panorama), clamped otherwise, and mirrored over the poles when `poles` (a full
    /// 360° × 180° equirect). An error for images under 2×2 pixels.
    pub fn panorama(image: &Raster<T>, wrap: bool, poles: bool) -> Result<Self> {
        let (w, h) = (image.width as isize, image.height as isize);
        if w < 2 || h < 2 {
            return Err(Error::invalid(
                "content",
                format!("a panorama needs at least 2×2 pixels, got {w}×{h}"),
            ));
        }
        let (pw, ph) = (image.width + 2 * PAD, image.height + 2 * PAD);
        let mut data = Vec::with_capacity(pw * ph);
        for y in 0..ph as isize {
            for x in 0..pw as isize {
                let (mut x, mut y) = (x - PAD as isize, y - PAD as isize);
                if poles && (y < 0 || y >= h) {
                    // Over a pole: the same latitude on the meridian half a turn round.
                    y = if y < 0 { -1 - y } else { 2 * h - 1 - y };
                    x += w / 2;
                }
                let x = if wrap {
                    x.rem_euclid(w)
                } else {
                    x.clamp(0, w - 1)
                };
                data.push(image.get(x as usize, y.clamp(0, h - 1) as usize));
            }
        }
        Ok(Atlas {
            width: pw,
            height: ph,
            data,
        })
    }
}

/// Texel (x, y) of `face`, where x or y may lie up to PAD outside the face.
fn cube_texel<T: Pixel>(cube: &CubeMap<T>, face: Face, x: isize, y: isize) -> T {
    let n = cube.size as isize;
    let inside = |v: isize| (0..n).contains(&v);
    match (inside(x), inside(y)) {
        (true, true) => cube.face(face).get(x as usize, y as usize),
        (false, true) => fold(cube, face, x, y, true),
        (true, false) => fold(cube, face, x, y, false),
        (false, false) => {
            let candidates = [
                fold(cube, face, x, y.clamp(0, n - 1), true),
                fold(cube, face, x.clamp(0, n - 1), y, false),
                cube.face(face)
                    .get(x.clamp(0, n - 1) as usize, y.clamp(0, n - 1) as usize),
            ];
            let mut acc = [0.0f32; 4];
            for c in candidates {
                for (a, v) in acc.iter_mut().zip(c.to_f32()) {
                    *a += v;
                }
            }
            T::from_f32(acc.map(|a| a / 3.0))
        }
    }
}

/// Folds the face plane over the edge crossed by texel (x, y) (along x when `along_x`) onto the
/// neighbouring face, and reads the texel there: depth k beyond the edge lands on depth k − 1
/// inside the neighbour.
fn fold<T: Pixel>(cube: &CubeMap<T>, face: Face, x: isize, y: isize, along_x: bool) -> T {
    let n = cube.size as f64;
    let p = cubemap::face_point(face, (x as f64 + 0.5) / n, (y as f64 + 0.5) / n);
    let major = cubemap::face_point(face, 0.5, 0.5);
    // The face-plane axis that went past ±1 is the crossed edge's normal direction.
    let beyond = if along_x {
        cubemap::face_point(face, (x as f64 + 0.5) / n, 0.5) - major
    } else {
        cubemap::face_point(face, 0.5, (y as f64 + 0.5) / n) - major
    };
    let edge_axis = beyond.normalize();
    let delta = beyond.length() - 1.0;
    let along = p - major - beyond;
    let q: DVec3 = edge_axis + major * (1.0 - delta) + along;
    let (g, s, t) = cubemap::select(q);
    let last = cube.size - 1;
    let xi = ((s * n).floor() as isize).clamp(0, last as isize) as usize;
    let yi = ((t * n).floor() as isize).clamp(0, last as isize) as usize;
    cube.face(g).get(xi, yi)
}
