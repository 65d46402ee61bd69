//! Black-level compensation from the rig alone (docs/photometry.md). A projector sends light
//! even at black: 1/contrast of its white. Where n projectors overlap the wall gets n times that,
//! so a dark frame shows the overlaps as bright bands although the blend hides them in white.
//! Every lit wall point is therefore lifted to the same black T, the most black light any wall
//! point gets, each projector adding its share by blend weight.
//!
//! In linear light, with each projector's white taken as 1 everywhere it lights (its own fall-off
//! and hot spot are not modelled: the camera measures those) and its black k = 1/contrast, a
//! projector whose output is o lights the wall with k + (1 − k)·o. At a wall point whose
//! projectors' blacks sum to B, projector p's lift
//!
//!   β_p = α_p · (T − B) / (1 − k_p)
//!
//! (α_p its blend weight) brings the black frame's light to B + Σ α_p (T − B) = T, and its output
//! for content c is o = c·α_p·(1 − β_p) + β_p, the form SGCT and MPCDI use. The cost is
//! contrast: black rises to T everywhere, so a wall whose overlaps reach n projectors of contrast
//! C keeps about C / n.

use super::{Channel, Rig};
use crate::error::{Error, Result};
use crate::raster::{Pixel, Raster};
use glam::DVec3;
use rayon::prelude::*;

/// Projector pixels apart of the lattice the black target is searched on: overlaps narrower
/// than this can be missed, and a point brighter than the target is left as it is.
const TARGET_STEP: usize = 4;

impl Channel {
    /// The projector's black as a fraction of its white: 1 / contrast, 0 for true black.
    pub fn black(&self) -> f64 {
        self.contrast.map_or(0.0, |c| 1.0 / c)
    }
}

impl Rig {
    /// Whether any projector shows black as light, so that there is a black level to even out.
    pub fn has_black(&self) -> bool {
        self.channels.iter().any(|c| c.contrast.is_some())
    }

    /// The black light at wall point `p`: the sum of the blacks of the projectors lighting it.
    pub fn black_at(&self, p: DVec3) -> f64 {
        self.channels
            .iter()
            .filter(|c| c.contrast.is_some() && self.pixel_lighting(c, p).is_some())
            .map(Channel::black)
            .sum()
    }

    /// The wall point channel `ch`'s pixel `q` lights, if it lights one.
    fn lit_point(&self, ch: &Channel, q: [f64; 2]) -> Option<DVec3> {
        let dir = ch.rotation * ch.lens.unproject(q).ok()?;
        self.doc
            .screen
            .intersect(ch.position, dir.normalize())
            .point()
    }

    /// The black every lit wall point is lifted to: the most black light a wall point gets,
    /// searched over every channel's pixels 4 apart. 0 when no projector has a
    /// contrast.
    pub fn black_target(&self) -> f64 {
        if !self.has_black() {
            return 0.0;
        }
        self.channels
            .iter()
            .map(|ch| {
                let (w, h) = (ch.width as usize, ch.height as usize);
                let step = TARGET_STEP.min(w).min(h).max(1);
                let lattice: Vec<[f64; 2]> = (0..h)
                    .step_by(step)
                    .flat_map(|y| (0..w).step_by(step).map(move |x| [x as f64, y as f64]))
                    .collect();
                lattice
                    .par_iter()
                    .filter_map(|&q| self.lit_point(ch, q))
                    .map(|p| self.black_at(p))
                    .reduce(|| 0.0, f64::max)
            })
            .fold(0.0, f64::max)
    }

    /// The lift β of every pixel of `ch` (linear light, 0–1), given its wall points and blend
    /// weights (from its warp) and the rig's [`Rig::black_target`]. All zero when no projector
    /// has a contrast.
    pub fn black_lift(
        &self,
        ch: &Channel,
        points: &[Option<DVec3>],
        weights: &[f32],
        target: f64,
    ) -> Vec<f32> {
        let own = ch.black();
        points
            .par_iter()
            .zip(weights.par_iter())
            .map(|(p, &alpha)| {
                let Some(p) = p else { return 0.0 };
                let others: f64 = self
                    .channels
                    .iter()
                    .filter(|o| o.id != ch.id && o.contrast.is_some())
                    .filter(|o| self.pixel_lighting(o, *p).is_some())
                    .map(Channel::black)
                    .sum();
                let lift = f64::from(alpha) * (target - own - others).max(0.0) / (1.0 - own);
                lift.clamp(0.0, 1.0) as f32
            })
            .collect()
    }
}

/// What a channel's picture is multiplied by and lifted with: its blend weights and, when any of
/// the rig's projectors has a contrast, its black lift; for a projector of gamma γ.
#[derive(Debug, Clone)]
pub struct ChannelBlend {
    /// Blend weights, linear light, per pixel.
    pub weights: Vec<f32>,
    /// Black lift β, linear light, per pixel; `None` when no projector has a contrast.
    pub lift: Option<Vec<f32>>,
    /// The projector gamma the picture is encoded for.
    pub gamma: f64,
}

impl ChannelBlend {
    /// Applies the blend and the lift to a channel's rendered picture ([`apply_blend_and_lift`];
    /// the blend's gains alone when there is no lift).
    pub fn apply<T: Pixel>(&self, img: &mut Raster<T>) -> Result<()> {
        match &self.lift {
            Some(lift) => apply_blend_and_lift(img, &self.weights, lift, self.gamma),
            None => super::apply_gains(img, &super::signal_gains(&self.weights, self.gamma)?),
        }
    }
}

impl Rig {
    /// Channel `ch`'s blend and black lift, given its wall points (from its warp).
    pub fn channel_blend(
        &self,
        ch: &Channel,
        points: &[Option<DVec3>],
        gamma: f64,
    ) -> Result<ChannelBlend> {
        if !(gamma.is_finite() && gamma > 0.0) {
            return Err(Error::invalid(
                "gamma",
                format!("must be positive, got {gamma}"),
            ));
        }
        let weights = self.blend_weights(ch, points);
        let lift = self
            .has_black()
            .then(|| self.black_lift(ch, points, &weights, self.black_target()));
        Ok(ChannelBlend {
            weights,
            lift,
            gamma,
        })
    }
}

/// A 4 × 4 Bayer matrix as offsets in (−0.5, 0.5) of one output step.
const BAYER: [f32; 16] = {
    let m = [0, 8, 2, 10, 12, 4, 14, 6, 3, 11, 1, 9, 15, 7, 13, 5];
    let mut out = [0.0; 16];
    let mut i = 0;
    while i < 16 {
        out[i] = (m[i] as f32 + 0.5) / 16.0 - 0.5;
        i += 1;
    }
    out
};

/// The ordered dither's offset at pixel `n` of an image `width` pixels wide, in output steps:
/// what the renderer adds to a lifted pixel before rounding it to 8 bits, and the 8-bit black
/// masks to theirs, so that a reader adding the mask to black puts out the renderer's picture.
pub(crate) fn dither_at(n: usize, width: usize) -> f32 {
    BAYER[(n / width.max(1) % 4) * 4 + n % width.max(1) % 4]
}

/// Applies a channel's blend and black lift to its rendered picture (signal space, a projector
/// of gamma γ): in linear light o = c·α·(1 − β) + β, colour only, alpha kept. With β all zero
/// this is the blend alone, c·α^(1/γ) in signal space, as [`super::apply_gains`] does.
///
/// A lift is a few thousandths of white, a signal of 5–15 in 8 bits, where one step is a fifth
/// of the light: rounded alike over a smooth lift, the steps add up to visible bands (the
/// example dome's black varied by 8 % over 2° patches). Lifted pixels of integer types are
/// therefore dithered (ordered, 4 × 4), so that a patch averages to the lift; unlifted pixels
/// are rounded as before.
pub fn apply_blend_and_lift<T: Pixel>(
    img: &mut Raster<T>,
    weights: &[f32],
    lift: &[f32],
    gamma: f64,
) -> Result<()> {
    if !(gamma.is_finite() && gamma > 0.0) {
        return Err(Error::invalid(
            "gamma",
            format!("must be positive, got {gamma}"),
        ));
    }
    if weights.len() != img.data.len() || lift.len() != img.data.len() {
        return Err(Error::invalid(
            "lift",
            format!(
                "{} weights and {} lifts for a {}×{} image",
                weights.len(),
                lift.len(),
                img.width,
                img.height
            ),
        ));
    }
    let full = f64::from(T::FULL);
    let width = img.width;
    let steps = T::FULL > 1.0;
    img.data
        .par_iter_mut()
        .zip(weights.par_iter().zip(lift.par_iter()))
        .enumerate()
        .for_each(|(n, (px, (&alpha, &beta)))| {
            let (a, b) = (f64::from(alpha), f64::from(beta));
            let dither = if steps && beta > 0.0 {
                dither_at(n, width)
            } else {
                0.0
            };
            let v = px.to_f32();
            let out = |c: f32| {
                let linear = (f64::from(c) / full).max(0.0).powf(gamma);
                ((linear * a * (1.0 - b) + b).powf(1.0 / gamma) * full) as f32 + dither
            };
            *px = T::from_f32([out(v[0]), out(v[1]), out(v[2]), v[3]]);
        });
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_lift_is_the_blend_alone_at_zero_and_black_light_at_black() {
        let mut img = Raster::new(3, 1);
        img.data.fill([0u8, 128, 255, 255]);
        apply_blend_and_lift(&mut img, &[1.0, 0.25, 0.5], &[0.0, 0.0, 0.01], 2.2).unwrap();
        // No lift: the blend's own gain on the signal.
        assert_eq!(img.data[0], [0, 128, 255, 255]);
        let m = 0.25f64.powf(1.0 / 2.2);
        let expect = |v: f64| (v * m).round() as u8;
        assert_eq!(img.data[1], [0, expect(128.0), expect(255.0), 255]);
        // Black content under a lift of 0.01 puts out 0.01 of light, dithered (pixel 2 of the
        // first row takes the Bayer offset of cell 2).
        assert_eq!(
            img.data[2][0],
            (0.01f64.powf(1.0 / 2.2) * 255.0 + f64::from(BAYER[2])).round() as u8
        );
        // Over a 4 × 4 block the dither averages to the lift.
        let mut block = Raster::<[u8; 4]>::new(4, 4);
        apply_blend_and_lift(&mut block, &[1.0; 16], &[0.003; 16], 2.2).unwrap();
        let mean = block.data.iter().map(|p| f64::from(p[0])).sum::<f64>() / 16.0;
        let exact = 0.003f64.powf(1.0 / 2.2) * 255.0;
        assert!((mean - exact).abs() < 0.07, "{mean} vs {exact}");
        let bad = apply_blend_and_lift(&mut img, &[1.0], &[0.0], 2.2).unwrap_err();
        assert!(bad.to_string().contains("lift"), "{bad}");
    }
}
