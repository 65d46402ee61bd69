//! Seed 000's radial blur (Figure 7) on the CPU: the twin of `shaders/blur.wgsl`, tap for tap,
//! so a frame blurred on either renderer is the same to rounding.

use crate::raster::Raster;
use rayon::prelude::*;

/// Seed 000's radial blur: `strength` is the fraction of the way to the centre the blur
/// reaches, over `samples` taps.
#[derive(Debug, Clone, Copy)]
pub struct Blur {
    /// Fraction of the way from each pixel to the image centre the taps spread over, usually
    /// in [0, 1]; 0 leaves the image unchanged.
    pub strength: f32,
    /// Number of bilinear taps averaged per pixel; 0 counts as 1.
    pub samples: u32,
}

/// `shaders/blur.wgsl` on the CPU: each pixel averages `samples` bilinear taps on the way to
/// the image centre (edges clamped, as the GPU sampler does).
pub fn radial_blur(img: &Raster<[u8; 4]>, b: Blur) -> Raster<[u8; 4]> {
    let (w, h) = (img.width, img.height);
    let tap = |x: f32, y: f32| -> [f32; 4] {
        let (x, y) = (x - 0.5, y - 0.5);
        let (x0, y0) = (x.floor(), y.floor());
        let (fx, fy) = (x - x0, y - y0);
        let at = |i: f32, j: f32| {
            let (i, j) = (
                i.clamp(0.0, (w - 1) as f32) as usize,
                j.clamp(0.0, (h - 1) as f32) as usize,
            );
            img.data[j * w + i].map(f32::from)
        };
        let (a, bb, c, d) = (
            at(x0, y0),
            at(x0 + 1.0, y0),
            at(x0, y0 + 1.0),
            at(x0 + 1.0, y0 + 1.0),
        );
        [0, 1, 2, 3].map(|k| {
            (a[k] * (1.0 - fx) + bb[k] * fx) * (1.0 - fy) + (c[k] * (1.0 - fx) + d[k] * fx) * fy
        })
    };
    let n = b.samples.max(1);
    let data = (0..w * h)
        .into_par_iter()
        .map(|p| {
            let (x, y) = ((p % w) as f32 + 0.5, (p / w) as f32 + 0.5);
            let (tx, ty) = (w as f32 / 2.0 - x, h as f32 / 2.0 - y);
            let mut sum = [0.0f32; 4];
            for k in 0..n {
                let along = b.strength * k as f32 / n as f32;
                let v = tap(x + tx * along, y + ty * along);
                for c in 0..4 {
                    sum[c] += v[c];
                }
            }
            sum.map(|v| (v / n as f32).round().clamp(0.0, 255.0) as u8)
        })
        .collect();
    Raster {
        width: w,
        height: h,
        data,
    }
}
