//! Previews: the procedural test pattern through a channel's warp, desaturated by its tiles'
//! f and attenuated by its blend, on the CPU or the GPU.

use super::cache::GpuWarp;
use crate::content::Content;
use crate::content::pattern::Pattern;
use crate::cubemap::CubeMap;
use crate::normalmap::NormalMap;
use crate::raster::{Pixel, Raster};
use crate::render::{self, Filter, Warp};
use std::sync::{Arc, Mutex};

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

/// Cubes of the procedural content kept between previews, by pattern and face size: a fine
/// cube (faces of 2048) costs a second to evaluate and never changes.
#[derive(Default)]
pub struct PatternCubes(Mutex<Vec<Kept>>);

/// A kept cube: its pattern, face size, texels and which faces are evaluated.
type Kept = (Pattern, usize, Arc<CubeMap<[u8; 4]>>, [bool; 6]);

/// How many cubes are kept (each at most six 2048² faces of 8-bit RGBA, 100 MB).
const KEPT: usize = 2;

impl PatternCubes {
    /// The 8-bit cube of `look` with at least the faces `map` samples evaluated.
    pub fn get(&self, look: &Look, map: &NormalMap) -> Arc<CubeMap<[u8; 4]>> {
        let need = crate::render::coverage::faces_sampled(map, look.face as u32);
        let mut on = need;
        {
            let kept = self.0.lock().expect("pattern cube lock");
            if let Some((_, _, cube, has)) = kept
                .iter()
                .find(|(p, f, _, _)| *p == look.pattern && *f == look.face)
            {
                if (0..6).all(|i| has[i] || !need[i]) {
                    return cube.clone();
                }
                on = std::array::from_fn(|i| has[i] || need[i]);
            }
        }
        let cube = Arc::new(look.cube::<[u8; 4]>(on, 255.0));
        let mut kept = self.0.lock().expect("pattern cube lock");
        kept.retain(|(p, f, _, _)| !(*p == look.pattern && *f == look.face));
        kept.push((look.pattern, look.face, cube.clone(), on));
        let excess = kept.len().saturating_sub(KEPT);
        kept.drain(..excess);
        cube
    }
}

impl Look {
    /// The procedural content on the faces marked in `on`; `full` is the pixel type's white.
    pub fn cube<T: Pixel>(&self, on: [bool; 6], full: f32) -> CubeMap<T> {
        CubeMap::<T>::from_fn_on(self.face, 1, on, |d| {
            T::from_f32(self.pattern.eval(d).map(|c| c * full))
        })
    }

    /// `cube` through `map`, desaturated by the tiles' f and attenuated by the blend weights
    /// (raised to 1/γ: PNG previews are in signal space, EXR linear).
    pub fn render<T: Pixel>(
        &self,
        cube: &CubeMap<T>,
        map: &NormalMap,
        weights: &[f32],
        f: Option<&[f32]>,
        gamma: f64,
    ) -> crate::Result<Raster<T>> {
        let content = Content::cube(cube);
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
        cube: &CubeMap<[u8; 4]>,
        map: &NormalMap,
        weights: &[f32],
        f: Option<&[f32]>,
    ) -> crate::Result<Raster<[u8; 4]>> {
        let tex = crate::gpu::warp::CubeTexture::upload(&g.gpu, cube);
        let size = (map.width() as u32, map.height() as u32);
        let source = crate::gpu::warp::Source::Map(map);
        let mut img = g.pass.render(&g.gpu, &tex, source, size, f, None)?;
        attenuate(&mut img, weights, 2.2);
        Ok(img)
    }
}
