//! The CPU's way to see a scene: a cube map ray-cast through the scene's BVH, shaded as the GPU
//! shades it. The CPU twin of the cube-map pass (`src/gpu/cube.rs`, `shaders/scene.wgsl`): same
//! face table, same sun, same sky, so the two agree to rounding where both see one triangle.

use super::{Projected, SKY, sun};
use crate::content::projective::Projective;
use crate::cubemap::CubeMap;
use crate::raster::Raster;
use crate::surface::Mesh;
use glam::DVec3;
use rayon::prelude::*;

/// A scene's triangles in a BVH, each with one colour, ready to cast rays from an eye: the
/// CPU's cube maps, pictures and exact references. Made by [`super::Scene::ray_caster`].
pub struct RayCaster {
    pub(super) mesh: Mesh,
    /// Per triangle: its first vertex's colour.
    pub(super) colors: Vec<[u8; 4]>,
}

impl RayCaster {
    /// The scene seen from `eye` with a panorama projected onto it (the CPU's twin of the GPU's
    /// `fs_projected` and `fs_sky`): a surface point P shows the panorama's direction P − C, a
    /// ray that meets nothing the panorama in its own direction; opaque black where the
    /// panorama does not reach.
    pub fn cube_projected(
        &self,
        eye: DVec3,
        face: usize,
        on: [bool; 6],
        p: &Projected,
    ) -> CubeMap<[u8; 4]> {
        let from = Projective {
            surface: &self.mesh,
            eye,
            centre: p.centre,
        };
        CubeMap::from_fn_on(face, 1, on, |d| match p.content.sample(from.direction(d)) {
            Some(c) => {
                let f = |v: f32| v.round().clamp(0.0, 255.0) as u8;
                [f(c[0]), f(c[1]), f(c[2]), 255]
            }
            None => [0, 0, 0, 255],
        })
    }

    /// The scene seen from `eye` as a cube map (the CPU's cube-map pass): the colour of the
    /// first triangle met, shaded as the GPU shades it, else the sky.
    pub fn cube(&self, eye: DVec3, face: usize, on: [bool; 6]) -> CubeMap<[u8; 4]> {
        CubeMap::from_fn_on(face, 1, on, |d| self.shade(eye, d))
    }

    /// What the eye sees along `d`: the first triangle met, shaded as `shaders/scene.wgsl`
    /// and `shaders/ppp.wgsl` shade it (`flat_shade` in `shaders/mesh.wgsl`), else the sky.
    pub fn shade(&self, eye: DVec3, d: DVec3) -> [u8; 4] {
        match self.mesh.first_hit(eye, d) {
            None => SKY,
            Some((_, k, n)) => {
                let c = self.colors[k as usize];
                let light = 0.45 + 0.55 * n.dot(sun().as_dvec3()).abs();
                let f = |v: u8| (f64::from(v) * light).round().clamp(0.0, 255.0) as u8;
                [f(c[0]), f(c[1]), f(c[2]), 255]
            }
        }
    }

    /// An image of the scene from `eye`, one ray per pixel centre along `ray(i, j)`;
    /// transparent where there is no ray. Along a view's own directions this is the exact
    /// reference every method is measured against; along [`super::ppp::Pieces::ray`] it is the
    /// CPU twin of the GPU's piecewise perspective pass.
    pub fn picture(
        &self,
        eye: DVec3,
        width: u32,
        height: u32,
        ray: impl Fn(u32, u32) -> Option<DVec3> + Sync,
    ) -> Raster<[u8; 4]> {
        let data = (0..height)
            .into_par_iter()
            .flat_map_iter(|j| {
                let ray = &ray;
                (0..width).map(move |i| ray(i, j).map_or([0; 4], |d| self.shade(eye, d)))
            })
            .collect();
        Raster {
            width: width as usize,
            height: height as usize,
            data,
        }
    }

    /// An image of the scene from `eye` with one ray per sample position (offsets within the
    /// pixel, 0–1) along `ray(x, y)` (x, y continuous pixel positions), averaged over the rays
    /// that exist; transparent where none does. With the single offset (½, ½) it is
    /// [`Self::picture`].
    pub fn picture_averaged(
        &self,
        eye: DVec3,
        width: u32,
        height: u32,
        offsets: &[(f64, f64)],
        ray: impl Fn(f64, f64) -> Option<DVec3> + Sync,
    ) -> Raster<[u8; 4]> {
        let data = (0..height)
            .into_par_iter()
            .flat_map_iter(|j| {
                let ray = &ray;
                (0..width).map(move |i| {
                    let mut sum = [0u32; 4];
                    let mut n = 0;
                    for &(dx, dy) in offsets {
                        if let Some(d) = ray(f64::from(i) + dx, f64::from(j) + dy) {
                            let c = self.shade(eye, d);
                            for (s, v) in sum.iter_mut().zip(c) {
                                *s += u32::from(v);
                            }
                            n += 1;
                        }
                    }
                    if n == 0 {
                        [0; 4]
                    } else {
                        sum.map(|s| ((s + n / 2) / n) as u8)
                    }
                })
            })
            .collect();
        Raster {
            width: width as usize,
            height: height as usize,
            data,
        }
    }
}
