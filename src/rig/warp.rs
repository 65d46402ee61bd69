//! Per-channel warps: projector pixel (i, j) → unproject q = (i, j) (pixel centres at integers,
//! as lens models count them) → world ray → first lit wall point P → direction from the eye →
//! content sampling vector V. Exact per pixel, rows in parallel.

use super::{Channel, Rig};
use crate::content::projective::{Projective, Receiver, map_pixels};
use crate::normalmap::NormalMap;
use crate::projection::view::screen_of_pixel;
use crate::raster::{Raster, pages};
use glam::DVec3;
use rayon::prelude::*;
use std::mem::MaybeUninit;
use std::sync::atomic::{AtomicBool, Ordering};

/// A channel's warp: V per pixel (the warp map), and the wall point it lands on.
#[derive(Debug, Clone)]
pub struct ChannelWarp {
    /// The warp map: the unit sampling vector V per projector pixel, invalid (A = 0) where the
    /// pixel misses the wall or the content.
    pub map: NormalMap,
    /// The wall points in full precision, row by row (`None` off the wall); [`Self::wall`]
    /// makes them a raster.
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
    #[inline(always)]
    pub fn sampling_vector(&self, p: DVec3) -> Option<DVec3> {
        self.sampling_vector_from(p, self.eye)
    }

    /// The content sampling vector for wall point `p` when the content is a panorama projected
    /// from `centre` (seed 001); at the eye this is [`Rig::sampling_vector`], to the bit.
    // Always inlined: its answer returned through memory stalls the warp's loop.
    #[inline(always)]
    pub fn sampling_vector_from(&self, p: DVec3, centre: DVec3) -> Option<DVec3> {
        // V = C·d − O normalised, d = r/|r|, is C·r − |r|·O normalised (C is linear): without
        // an off-axis offset |r| is not needed, one square root a pixel instead of two.
        let r = p - centre;
        if self.offaxis == DVec3::ZERO {
            return self.content.apply(r).try_normalize();
        }
        let len = r.length();
        if !(len > 0.0 && len.is_finite()) {
            return None;
        }
        (self.content.apply(r) - len * self.offaxis).try_normalize()
    }

    /// V = C·d − O, normalised: the content direction of world direction `d`.
    fn content_vector(&self, d: DVec3) -> DVec3 {
        (self.content.apply(d) - self.offaxis).normalize()
    }

    /// The world direction `d` whose content direction is `v` (the inverse of V = C·d − O
    /// normalised): C·d = λ·V + O with λ the positive root of |λ·V + O| = 1, which exists
    /// because |O| < 1.
    pub fn world_direction(&self, v: DVec3) -> DVec3 {
        let o = self.offaxis;
        let vo = v.dot(o);
        let lambda = -vo + (vo * vo + 1.0 - o.length_squared()).sqrt();
        self.content.apply_inverse(lambda * v + o).normalize()
    }

    /// Checks a panorama projection centre: inside the wall, not on it. `field` names it.
    pub fn check_centre(&self, centre: DVec3, field: &str) -> crate::Result<DVec3> {
        self.doc.screen.check_inside(self.eye, centre, field)?;
        Ok(centre)
    }

    /// A channel's warp map for a panorama projected from `centre` onto the wall, from its map
    /// of sampling vectors from the eye (the geometry's or a tile screen's). With `points`, the
    /// wall points of the channel's own warp, each pixel's wall point is taken from there;
    /// otherwise (a tile screen moved the directions) each direction is followed from the eye
    /// to the wall. `None` once `cancel` is set.
    pub fn projected(
        &self,
        map: &NormalMap,
        points: Option<&[Option<DVec3>]>,
        centre: DVec3,
        cancel: &AtomicBool,
    ) -> Option<NormalMap> {
        let w = map.width();
        let from = Projective {
            surface: &self.doc.screen,
            eye: self.eye,
            centre,
        };
        let pixels = map_pixels(w, map.height(), cancel, |i, j| {
            let v = map.direction(i, j)?;
            match points.and_then(|p| p[j * w + i]) {
                Some(p) => self.sampling_vector_from(p, centre),
                None => Some(self.content_vector(from.direction(self.world_direction(v)))),
            }
        })?;
        let mut attributes = map.attributes.clone();
        attributes.push(("omniwarp.project_from".into(), format_point(centre)));
        Some(NormalMap::from_pixels(pixels, attributes).expect("unit vectors and 0/1 validity"))
    }

    /// What the eye sees of the wall through `view` (its directions taken as eye rays in the
    /// world) with a panorama projected from `centre` onto it: the content sampling vector per
    /// pixel, or none where the ray misses the wall.
    pub fn eye_view(
        &self,
        view: &crate::projection::View,
        width: u32,
        height: u32,
        centre: DVec3,
    ) -> crate::Result<NormalMap> {
        crate::raster::check_size(width, height, 1)?;
        let never = AtomicBool::new(false);
        let pixels = map_pixels(width as usize, height as usize, &never, |i, j| {
            let (s, t) = screen_of_pixel(i as f64 + 0.5, j as f64 + 0.5, width, height);
            let ray = view.direction(s, t).ok()?;
            let p = self.doc.screen.hit(self.eye, ray)?;
            self.sampling_vector_from(p, centre)
        })
        .expect("never cancelled");
        let attributes = vec![
            (
                "omniwarp.projection".into(),
                view.projection().name().into(),
            ),
            ("omniwarp.project_from".into(), format_point(centre)),
        ];
        NormalMap::from_pixels(pixels, attributes)
    }

    /// Channel `ch`'s warp, every projector pixel q = (i, j) traced to the wall and the content.
    pub fn warp(&self, ch: &Channel) -> ChannelWarp {
        self.warp_unless(ch, &AtomicBool::new(false))
            .expect("never cancelled")
    }

    /// [`Rig::warp`], given up (`None`) as soon as `cancel` is set — checked once per row, so a
    /// client that goes away stops the work within a row's time.
    pub fn warp_unless(&self, ch: &Channel, cancel: &AtomicBool) -> Option<ChannelWarp> {
        let (w, h) = (ch.width as usize, ch.height as usize);
        let screen = self.doc.screen.prepare();
        // Both outputs are written once, below, into pages mapped beforehand (a 4K warp's
        // 400 MB; see `raster::pages`).
        let mut points: Vec<Option<DVec3>> = pages::mapped(w * h, None);
        let mut map: Vec<[f32; 4]> = pages::mapped(w * h, [0.0; 4]);
        // One pass per row writes both outputs, walking the lens along it (each pixel's
        // unprojection starts from the ones before) and the wall prepared once. The f32 wall
        // raster `--wall` writes is made from the points only when asked for.
        points.spare_capacity_mut()[..w * h]
            .par_chunks_mut(w)
            .zip(map.spare_capacity_mut()[..w * h].par_chunks_mut(w))
            .enumerate()
            .for_each(|(j, (row, vectors))| {
                if cancel.load(Ordering::Relaxed) {
                    row.fill(MaybeUninit::new(None));
                    vectors.fill(MaybeUninit::new([0.0; 4]));
                    return;
                }
                let mut walk = ch.lens.walk();
                for (i, (p, v)) in row.iter_mut().zip(vectors).enumerate() {
                    let ray = walk.unproject([i as f64, j as f64]).ok();
                    let point =
                        ray.and_then(|r| screen.intersect(ch.position, ch.rotation * r).point());
                    p.write(point);
                    v.write(match point.and_then(|q| self.sampling_vector(q)) {
                        Some(s) => [s.x as f32, s.y as f32, s.z as f32, 1.0],
                        None => [0.0; 4],
                    });
                }
            });
        // SAFETY: every row above wrote each of its w points and vectors (a cancelled row
        // fills its own), and the rows cover all w × h.
        unsafe {
            points.set_len(w * h);
            map.set_len(w * h);
        }
        if cancel.load(Ordering::Relaxed) {
            return None;
        }
        let map = Raster {
            width: w,
            height: h,
            data: map,
        };
        let attributes = vec![
            ("omniwarp.channel".to_string(), ch.id.clone()),
            ("omniwarp.projection".to_string(), "rig".to_string()),
        ];
        Some(ChannelWarp {
            map: NormalMap::from_pixels(map, attributes).expect("unit vectors and 0/1 validity"),
            points,
        })
    }
}

impl ChannelWarp {
    /// X, Y, Z of each pixel's wall point in metres as f32, A = 1 where the pixel lights the
    /// wall (all 0 elsewhere): the wall raster `omniwarp warp --wall` writes.
    pub fn wall(&self) -> Raster<[f32; 4]> {
        let data = self
            .points
            .par_iter()
            .map(|p| p.map_or([0.0; 4], |q| [q.x as f32, q.y as f32, q.z as f32, 1.0]))
            .collect();
        Raster {
            width: self.map.width(),
            height: self.map.height(),
            data,
        }
    }
}

fn format_point(p: DVec3) -> String {
    format!("{},{},{}", p.x, p.y, p.z)
}
