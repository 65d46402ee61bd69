//! Previews: the procedural test pattern through a channel's warp, desaturated by its tiles'
//! f and attenuated by its blend, on the CPU or the GPU.

use super::cache::GpuWarp;
use crate::content::Content;
use crate::content::pattern::Pattern;
use crate::cubemap::CubeMap;
use crate::normalmap::NormalMap;
use crate::raster::{Pixel, Raster};
use crate::render::{self, Filter, Warp};

/// Multiplies colour by the blend weight raised to 1/γ (γ = 1: linear output).
fn attenuate<T: Pixel>(img: &mut Raster<T>, weights: &[f32], gamma: f64) {
    for (p, &k) in img.data.iter_mut().zip(weights) {
        let m = f64::from(k).powf(1.0 / gamma) as f32;
        let v = p.to_f32();
        *p = T::from_f32([v[0] * m, v[1] * m, v[2] * m, v[3]]);
    }
}

/// What a preview shows and how it samples it.
pub struct Look {
    pub pattern: Pattern,
    pub face: usize,
    pub filter: Filter,
}

impl Look {
    /// The procedural content through `map`, desaturated by the tiles' f and attenuated by the
    /// blend weights (raised to 1/γ: PNG previews are in signal space, EXR linear); `full` is
    /// the pixel type's white.
    pub fn render<T: Pixel>(
        &self,
        map: &NormalMap,
        weights: &[f32],
        f: Option<&[f32]>,
        gamma: f64,
        full: f32,
    ) -> crate::Result<Raster<T>> {
        let cube = CubeMap::<T>::from_fn(self.face, 1, |d| {
            T::from_f32(self.pattern.eval(d).map(|c| c * full))
        });
        let content = Content::cube(&cube);
        let (w, h) = (map.width() as u32, map.height() as u32);
        let mut img = render::render(Warp::Map(map), &content, w, h, 1, self.filter)?;
        if let Some(f) = f {
            crate::tiles::raster::saturation(&mut img, f);
        }
        attenuate(&mut img, weights, gamma);
        Ok(img)
    }

    /// [`Look::render`] of 8-bit PNG previews with the warp on the GPU.
    pub fn render_gpu(
        &self,
        g: &GpuWarp,
        map: &NormalMap,
        weights: &[f32],
        f: Option<&[f32]>,
    ) -> crate::Result<Raster<[u8; 4]>> {
        let cube = CubeMap::<[u8; 4]>::from_fn(self.face, 1, |d| {
            <[u8; 4]>::from_f32(self.pattern.eval(d).map(|c| c * 255.0))
        });
        let tex = crate::gpu::warp::CubeTexture::upload(&g.gpu, &cube);
        let size = (map.width() as u32, map.height() as u32);
        let source = crate::gpu::warp::Source::Map(map);
        let mut img = g.pass.render(&g.gpu, &tex, source, size, f, None)?;
        attenuate(&mut img, weights, 2.2);
        Ok(img)
    }
}
