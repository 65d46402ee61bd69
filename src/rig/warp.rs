//! Per-channel warps: projector pixel (i, j) → unproject q = (i, j) (pixel centres at integers,
//! as lens models count them) → world ray → first lit wall point P → direction from the eye →
//! content sampling vector V. Exact per pixel, rows in parallel.

use super::{Channel, Rig};
use crate::normalmap::NormalMap;
use crate::raster::Raster;
use glam::DVec3;
use rayon::prelude::*;
use std::sync::atomic::{AtomicBool, Ordering};

/// A channel's warp: V per pixel (the warp map), and the wall point it lands on.
#[derive(Debug, Clone)]
pub struct ChannelWarp {
    pub map: NormalMap,
    /// X, Y, Z of the wall point in metres, A = 1 where the pixel lights the wall.
    pub wall: Raster<[f32; 4]>,
    /// The wall points in full precision (`None` off the wall).
    pub points: Vec<Option<DVec3>>,
}

impl Rig {
    /// The wall point projector pixel q of channel `ch` lights, if any.
    pub fn wall_point(&self, ch: &Channel, q: [f64; 2]) -> Option<DVec3> {
        let ray = ch.lens.unproject(q).ok()?;
        self.doc
            .screen
            .intersect(ch.position, ch.rotation * ray)
            .point()
    }

    /// The content sampling vector for wall point `p`.
    pub fn sampling_vector(&self, p: DVec3) -> Option<DVec3> {
        let d = (p - self.eye).try_normalize()?;
        Some((self.content.apply(d) - self.offaxis).normalize())
    }

    pub fn warp(&self, ch: &Channel) -> ChannelWarp {
        self.warp_unless(ch, &AtomicBool::new(false))
            .expect("never cancelled")
    }

    /// [`Rig::warp`], given up (`None`) as soon as `cancel` is set — checked once per row, so a
    /// client that goes away stops the work within a row's time.
    pub fn warp_unless(&self, ch: &Channel, cancel: &AtomicBool) -> Option<ChannelWarp> {
        let (w, h) = (ch.width as usize, ch.height as usize);
        // Points are written once, below (filling 32 bytes × 8 million pixels beforehand cost
        // a tenth of a 4K warp); the two rasters start as zeroed pages.
        let mut points: Vec<Option<DVec3>> = Vec::with_capacity(w * h);
        let mut map = vec![[0.0f32; 4]; w * h];
        let mut wall = vec![[0.0f32; 4]; w * h];
        // One pass per row writes all three outputs; along a row each pixel's ray starts the
        // next one's iterative unprojection.
        points.spare_capacity_mut()[..w * h]
            .par_chunks_mut(w)
            .zip(map.par_chunks_mut(w))
            .zip(wall.par_chunks_mut(w))
            .enumerate()
            .for_each(|(j, ((row, vectors), walls))| {
                if cancel.load(Ordering::Relaxed) {
                    row.fill(std::mem::MaybeUninit::new(None));
                    return;
                }
                let mut guess = None;
                for (i, ((p, v), o)) in row.iter_mut().zip(vectors).zip(walls).enumerate() {
                    let ray = ch.lens.unproject_near([i as f64, j as f64], guess).ok();
                    guess = ray;
                    let point = ray.and_then(|r| {
                        self.doc
                            .screen
                            .intersect(ch.position, ch.rotation * r)
                            .point()
                    });
                    p.write(point);
                    if let Some(q) = point {
                        *o = [q.x as f32, q.y as f32, q.z as f32, 1.0];
                        if let Some(s) = self.sampling_vector(q) {
                            *v = [s.x as f32, s.y as f32, s.z as f32, 1.0];
                        }
                    }
                }
            });
        // SAFETY: every row above wrote each of its w points (a cancelled row fills its own),
        // and the rows cover all w × h.
        unsafe { points.set_len(w * h) };
        if cancel.load(Ordering::Relaxed) {
            return None;
        }
        let map = Raster {
            width: w,
            height: h,
            data: map,
        };
        let wall = Raster {
            width: w,
            height: h,
            data: wall,
        };
        let attributes = vec![
            ("omniwarp.channel".to_string(), ch.id.clone()),
            ("omniwarp.projection".to_string(), "rig".to_string()),
        ];
        Some(ChannelWarp {
            map: NormalMap::from_pixels(map, attributes).expect("unit vectors and 0/1 validity"),
            wall,
            points,
        })
    }
}
