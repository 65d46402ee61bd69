//! The padded texel array behind every content source.
//!
//! Each source image gets a border of [`PAD`] texels so that every filter tap stays inside the
//! array and the border holds what seamless filtering would read there:
//! * cube faces: an edge texel of the neighbouring face, found by folding the face plane over
//!   the cube edge (as Vulkan's seamless cube filtering does); in the corners, where three faces
//!   meet, the mean of the three candidates;
//! * full panoramas: the columns of the other side (wrap-around); over the poles of a full
//!   equirectangular image, the row mirrored across the pole half a turn round;
//! * a fisheye's image circle: outside it, the texel on the same radius a texel and a half
//!   inside the rim, so that filtering at the rim reads the picture and not the black around
//!   the circle;
//! * anything else: the nearest edge texel (clamp).
//!
//! Apart from a cube's corners, every texel is a copy of one source pixel, so a new frame of a
//! movie is laid out by the same rule, row by row, then the copies ([`Atlas::refill`]).

use crate::cubemap::{self, CubeMap, Face};
use crate::raster::{Pixel, Raster};
use crate::{Error, Result};
use glam::DVec3;
use rayon::prelude::*;

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
        Atlas::laid_out(image, Rule::Panorama { wrap, poles })
    }

    /// A fisheye image with its border, the circle centred at (`cx`, `cy`) image pixels from
    /// the top-left corner with radius `radius` pixels.
    pub fn fisheye(image: &Raster<T>, cx: f64, cy: f64, radius: f64) -> Result<Self> {
        Atlas::laid_out(image, Rule::Circle { cx, cy, radius })
    }

    fn sized(w: usize, h: usize) -> Result<Self> {
        if w < 2 || h < 2 {
            return Err(Error::invalid(
                "content",
                format!("a panorama or fisheye needs at least 2×2 pixels, got {w}×{h}"),
            ));
        }
        let (pw, ph) = (w + 2 * PAD, h + 2 * PAD);
        Ok(Atlas {
            width: pw,
            height: ph,
            data: vec![T::default(); pw * ph],
        })
    }

    /// Lays out a `w` × `h` source by `rule`, in place: `row(y, texels)` writes source row y
    /// into the atlas (rows in parallel), then every texel the rule fills from elsewhere copies
    /// the texel it names, by the index pairs [`Atlas::copies`] lists. A movie's next frame,
    /// converted from its own pixel format as it is read.
    pub(super) fn refill(
        &mut self,
        w: usize,
        h: usize,
        copies: &[(u32, u32)],
        row: impl Fn(usize, &mut [T]) + Sync,
    ) {
        debug_assert_eq!((self.width, self.height), (w + 2 * PAD, h + 2 * PAD));
        let pw = self.width;
        self.data[PAD * pw..(PAD + h) * pw]
            .par_chunks_mut(pw)
            .enumerate()
            .for_each(|(y, texels)| row(y, &mut texels[PAD..PAD + w]));
        for &(to, from) in copies {
            self.data[to as usize] = self.data[from as usize];
        }
    }

    /// The (texel, source texel) index pairs of a `w` × `h` source laid out by `rule`: every
    /// texel that is not its own source pixel, with the texel holding that pixel. Sources read
    /// by a copy are always their own (inside the image, inside the circle), so the order of the
    /// copies does not matter.
    pub(super) fn copies(rule: Rule, w: usize, h: usize) -> Vec<(u32, u32)> {
        let (pw, ph) = (w + 2 * PAD, h + 2 * PAD);
        let mut out = Vec::new();
        for ay in 0..ph {
            for ax in 0..pw {
                let (x, y) = (ax as isize - PAD as isize, ay as isize - PAD as isize);
                let (sx, sy) = rule.source(x, y, w, h);
                if (sx as isize, sy as isize) != (x, y) {
                    let from = (sy + PAD) * pw + sx + PAD;
                    out.push(((ay * pw + ax) as u32, from as u32));
                }
            }
        }
        out
    }

    fn laid_out(image: &Raster<T>, rule: Rule) -> Result<Self> {
        let (w, h) = (image.width, image.height);
        let mut atlas = Atlas::sized(w, h)?;
        let copies = Atlas::<T>::copies(rule, w, h);
        atlas.refill(w, h, &copies, |y, row| {
            row.copy_from_slice(&image.data[y * w..(y + 1) * w])
        });
        Ok(atlas)
    }
}

/// Which source pixel a bordered texel copies (see the module's description).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) enum Rule {
    Panorama { wrap: bool, poles: bool },
    Circle { cx: f64, cy: f64, radius: f64 },
}

impl Rule {
    /// The source pixel texel (x, y) copies, x and y counted from the image's top-left pixel
    /// (negative or past the size in the border).
    fn source(self, x: isize, y: isize, w: usize, h: usize) -> (usize, usize) {
        let (w, h) = (w as isize, h as isize);
        let clamp = |x: isize, y: isize| (x.clamp(0, w - 1) as usize, y.clamp(0, h - 1) as usize);
        match self {
            Rule::Panorama { wrap, poles } => {
                let (mut x, mut y) = (x, y);
                if poles && (y < 0 || y >= h) {
                    // Over a pole: the same latitude on the meridian half a turn round.
                    y = if y < 0 { -1 - y } else { 2 * h - 1 - y };
                    x += w / 2;
                }
                let x = if wrap { x.rem_euclid(w) } else { x };
                clamp(x, y)
            }
            Rule::Circle { cx, cy, radius } => {
                let (dx, dy) = (x as f64 + 0.5 - cx, y as f64 + 0.5 - cy);
                let r2 = dx * dx + dy * dy;
                let inner = (radius - 0.5).max(0.0);
                if r2 <= inner * inner {
                    return clamp(x, y);
                }
                // Pulled in along its radius to a pixel wholly inside the circle: the pixel
                // holding the point radius − 1.5 out has its centre within radius − 0.5 (at most
                // 0.71 px from the point), so it is its own source, and the order of the copies
                // does not matter.
                let k = (radius - 1.5).max(0.0) / r2.sqrt();
                clamp(
                    (cx + k * dx).floor() as isize,
                    (cy + k * dy).floor() as isize,
                )
            }
        }
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
