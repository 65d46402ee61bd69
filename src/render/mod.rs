//! The CPU warp renderer, the accuracy ground truth and the fallback when no GPU exists.
//!
//! Rendering is split the way a media server uses a warp: a [`Plan`] is built once per warp
//! and content layout (for every output sample: the sampling vector V, in f64, turned into an
//! atlas position), then [`Plan::render`] filters any number of frames of content through it.
//! The per-frame step reads 8 bytes of plan and 4 texels per output pixel, with integer
//! arithmetic for 8-bit bilinear output, and runs on all cores (rayon, one task per row). The
//! GPU's twin is the warp pass, `shaders/warp.wgsl` (drawn as the full-screen triangle of
//! `shaders/fullscreen.wgsl`), held to this path by `tests/gpu/gpu.rs`.

pub mod blur;
pub mod coverage;
pub mod lattice;
mod plan;

pub use crate::raster::{MAX_SAMPLES, Tap, check_size};
pub use plan::Plan;

use crate::cubemap::{self, Face};
use crate::error::{Error, Result};
use crate::normalmap::NormalMap;
use crate::projection::View;
use crate::projection::view::screen_of_pixel;
use crate::raster::{Pixel, Raster};
use glam::DVec3;
use rayon::prelude::*;

/// How content texels are filtered.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Filter {
    /// The texel nearest each sample, chosen once when the plan is built.
    Nearest,
    /// Bilinear over the 2×2 texels around each sample.
    Bilinear,
    /// Catmull–Rom (Keys, a = −0.5) over 4×4 texels.
    Bicubic,
}

/// Where the sampling vector of each output position comes from.
#[derive(Debug, Clone, Copy)]
pub enum Warp<'a> {
    /// Computed analytically from a projection and view transform, at any sub-pixel position.
    View(&'a View),
    /// Read from a normal map, one vector per pixel.
    Map(&'a NormalMap),
    /// The texel directions of one cube face (for building cube maps from other content).
    CubeFace(Face),
}

impl Warp<'_> {
    /// The unit sampling vector at continuous pixel position (x, y) of a width × height output,
    /// or `None` where nothing is shown.
    #[inline]
    pub fn direction(&self, x: f64, y: f64, width: u32, height: u32) -> Option<DVec3> {
        match self {
            Warp::View(view) => {
                let (s, t) = screen_of_pixel(x, y, width, height);
                view.direction(s, t).ok()
            }
            Warp::Map(map) => map.direction(x as usize, y as usize),
            Warp::CubeFace(face) => {
                let p = cubemap::face_point(*face, x / f64::from(width), y / f64::from(height));
                Some(p.normalize())
            }
        }
    }

    /// Checks that this warp can drive a width × height output with k × k supersampling.
    pub fn check(&self, width: u32, height: u32, supersample: u32) -> Result<()> {
        check_size(width, height, supersample)?;
        if let Warp::Map(map) = self {
            if supersample != 1 {
                return Err(Error::invalid(
                    "supersample",
                    "a normal map holds one vector per pixel; supersampling needs a projection",
                ));
            }
            if (map.width(), map.height()) != (width as usize, height as usize) {
                return Err(Error::invalid(
                    "size",
                    format!(
                        "the normal map is {}×{}, the output {width}×{height}",
                        map.width(),
                        map.height()
                    ),
                ));
            }
        }
        Ok(())
    }
}

/// Sub-sample positions of pixel (i, j) with k × k supersampling: a regular grid inside it.
#[inline]
pub(crate) fn subsample(i: usize, j: usize, a: u32, b: u32, k: u32) -> (f64, f64) {
    (
        i as f64 + (f64::from(a) + 0.5) / f64::from(k),
        j as f64 + (f64::from(b) + 0.5) / f64::from(k),
    )
}

/// Renders a function of direction directly, with no content image in between: the exact
/// reference that resampled renders are measured against. Each pixel is the mean of k × k
/// samples; alpha is the covered fraction.
pub fn render_fn(
    warp: Warp<'_>,
    width: u32,
    height: u32,
    supersample: u32,
    f: impl Fn(DVec3) -> [f32; 4] + Sync,
) -> Result<Raster<[f32; 4]>> {
    warp.check(width, height, supersample)?;
    let k = supersample;
    let (w, h) = (width as usize, height as usize);
    let mut out = Raster::new(w, h);
    out.data.par_chunks_mut(w).enumerate().for_each(|(j, row)| {
        for (i, px) in row.iter_mut().enumerate() {
            let mut acc = [0.0f32; 4];
            let mut hits = 0u32;
            for b in 0..k {
                for a in 0..k {
                    let (x, y) = subsample(i, j, a, b, k);
                    if let Some(v) = warp.direction(x, y, width, height) {
                        for (c, s) in acc.iter_mut().zip(f(v)) {
                            *c += s;
                        }
                        hits += 1;
                    }
                }
            }
            *px = finish(acc, hits, k * k);
        }
    });
    Ok(out)
}

/// Mean colour of the covered samples; alpha scaled by the covered fraction.
#[inline]
pub(crate) fn finish<T: Pixel>(acc: [f32; 4], hits: u32, samples: u32) -> T {
    if hits == 0 {
        return T::default();
    }
    let h = hits as f32;
    T::from_f32([acc[0] / h, acc[1] / h, acc[2] / h, acc[3] / samples as f32])
}

/// Plans and renders one frame: the convenience for single images. Frame loops build the
/// [`Plan`] once and call [`Plan::render_into`].
pub fn render<T: Pixel>(
    warp: Warp<'_>,
    content: &crate::content::Content<T>,
    width: u32,
    height: u32,
    supersample: u32,
    filter: Filter,
) -> Result<Raster<T>> {
    let plan = Plan::new(
        warp,
        content,
        content.atlas(),
        width,
        height,
        supersample,
        filter,
    )?;
    plan.render(content.atlas())
}
