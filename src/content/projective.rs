//! Panoramic projective texture mapping (seed 001): a panorama shot at a centre C is projected
//! from C onto a receiving surface (the wall, or a scene) and seen from the eye. The eye ray
//! that meets the surface at P shows the panorama's direction P − C.
//!
//! With C at the eye this is the panorama viewer: P − C lies along the eye ray itself, so the
//! viewer sees what a plain panorama render shows, whatever the surface. Away from the eye the
//! image depends on where the surface is — the parallax a room shows when the panorama was shot
//! elsewhere than where the audience stands. A ray that meets nothing sees the panorama in its
//! own direction: a point infinitely far along it lies in that direction from any C.
//!
//! Like the seed's projective texturing, there is no shadow test: a point hidden from C by
//! other geometry still shows the panorama's direction towards it. The wall surfaces (inside of
//! a cylinder or a dome, a plane) are seen whole from any centre inside them.

use crate::raster::Raster;
use crate::surface::{Mesh, Screen};
use glam::DVec3;
use rayon::prelude::*;
use std::sync::atomic::{AtomicBool, Ordering};

/// A surface the panorama lands on.
pub trait Receiver: Sync {
    /// The first point the unit ray from `origin` along `dir` meets.
    fn hit(&self, origin: DVec3, dir: DVec3) -> Option<DVec3>;
}

impl Receiver for Screen {
    fn hit(&self, origin: DVec3, dir: DVec3) -> Option<DVec3> {
        self.intersect(origin, dir).point()
    }
}

impl Receiver for Mesh {
    fn hit(&self, origin: DVec3, dir: DVec3) -> Option<DVec3> {
        self.first_hit(origin, dir)
            .map(|(t, _, _)| origin + dir * t)
    }
}

/// A panorama projected from `centre` onto `surface`, seen from `eye`.
pub struct Projective<'a> {
    /// The receiving surface: the wall, or a scene's mesh.
    pub surface: &'a dyn Receiver,
    /// The viewer's position, world coordinates in metres.
    pub eye: DVec3,
    /// The panorama's projection centre C, world coordinates in metres; C = `eye` shows the plain
    /// panorama.
    pub centre: DVec3,
}

impl Projective<'_> {
    /// The panorama direction (unit, world) the eye sees along the unit ray `ray`: towards the
    /// surface point it meets, from the centre; along the ray itself where it meets nothing.
    pub fn direction(&self, ray: DVec3) -> DVec3 {
        match self.surface.hit(self.eye, ray) {
            Some(p) => self.of_point(p).unwrap_or(ray),
            None => ray,
        }
    }

    /// The panorama direction of surface point `p`; `None` at the centre itself.
    pub fn of_point(&self, p: DVec3) -> Option<DVec3> {
        (p - self.centre).try_normalize()
    }
}

/// A w × h raster of the unit vectors `f` gives (A = 1), zero where it gives none; rows in
/// parallel, `None` once `cancel` is set.
pub fn map_pixels(
    w: usize,
    h: usize,
    cancel: &AtomicBool,
    f: impl Fn(usize, usize) -> Option<DVec3> + Sync,
) -> Option<Raster<[f32; 4]>> {
    let mut out = Raster::new(w, h);
    out.data
        .par_chunks_mut(w.max(1))
        .enumerate()
        .for_each(|(j, row)| {
            if cancel.load(Ordering::Relaxed) {
                return;
            }
            for (i, px) in row.iter_mut().enumerate() {
                if let Some(v) = f(i, j) {
                    *px = [v.x as f32, v.y as f32, v.z as f32, 1.0];
                }
            }
        });
    (!cancel.load(Ordering::Relaxed)).then_some(out)
}
