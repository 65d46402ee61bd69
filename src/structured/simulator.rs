//! The capture simulator (the virtual projector–camera bench): what a camera of any lens and
//! pose sees when one of the rig's projectors shows a pattern. It is the ground truth the decoder
//! and the calibration are measured against, and a technician's rehearsal of a capture before
//! the room is booked.
//!
//! Light is followed the way it goes, in linear units where the projector's full white lights
//! the wall with 1:
//!
//! 1. **Geometry.** Each camera pixel is divided into s × s sub-pixels. Where the pixel's four
//!    corners all land on the wall lit by the projector, the sub-pixels' projector coordinates
//!    are interpolated between the corners' exact ones (a camera pixel spans a few projector
//!    pixels, where the mapping is affine to far below a thousandth of a pixel); on the edges
//!    of the wall or of the projector's image, every sub-pixel is traced exactly. A wall point
//!    is lit when the projector sees it first (no other part of the wall in between) and it
//!    falls inside the projector's raster. Each projector pixel is a uniform square.
//! 2. **Projector gamma**: a pattern value v lights with (v / 255)^γp.
//! 3. **One bounce of inter-reflection** on concave walls: light from every part of the lit
//!    wall (in patches) reaching the point by the form factor cos θ · cos θ′ / (π r²), scaled so
//!    that under full white it adds `interreflection` × the direct light on average over the lit
//!    pixels, and evaluated on a 16-pixel lattice of the camera (the bounce is smooth: on a
//!    sphere it is exactly uniform).
//! 4. **Ambient light**, a constant.
//! 5. **Blur**: a Gaussian point spread with σ in camera pixels (lens and focus together).
//! 6. **Vignetting**: 1 − v · (r / r_corner)², r from the image centre.
//! 7. **Camera**: exposure, saturation, camera gamma (value = 255 · signal^(1/γc)), Gaussian
//!    sensor noise in grey levels, rounding to 8 bits. The noise is seeded per frame and row,
//!    so a capture is the same on any number of threads.
//!
//! The truth of each camera pixel is the projector coordinate of the wall point its centre
//! sees, from the exact models.

use super::{Axis, Grey, PatternSet};
use crate::error::{Error, Result};
use crate::rig::{Channel, Rig};
use crate::surface::{Hit, Screen};
use glam::DVec3;
use rand_distr::{Distribution, StandardNormal};
use rand_pcg::Pcg64;
use rand_pcg::rand_core::SeedableRng;
use rayon::prelude::*;
use std::f64::consts::PI;

/// The bench's optics and sensor. [`SimulatorOptions::default`] is the reference bench:
/// 0.7 px blur, both gammas 2.2, 5 % ambient, σ = 2 grey levels.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SimulatorOptions {
    /// Sub-pixels per camera pixel along each axis.
    pub supersample: u32,
    /// Point spread σ, camera pixels (0: none).
    pub blur: f64,
    /// Projector gamma γp: a pattern value v lights the wall with (v / 255)^γp; 0.5–4.
    pub projector_gamma: f64,
    /// Camera gamma γc: a signal s is recorded as 255 · s^(1/γc); 0.5–4.
    pub camera_gamma: f64,
    /// Ambient light as a fraction of the projector's full white.
    pub ambient: f64,
    /// Relative loss of light in the image corners.
    pub vignetting: f64,
    /// One-bounce inter-reflection under full white, as a fraction of the direct light.
    pub interreflection: f64,
    /// Sensor noise σ, grey levels.
    pub noise: f64,
    /// The fraction of full scale that full white plus ambient reaches at the image centre.
    pub exposure: f64,
    /// Seed of the sensor noise, drawn per frame and row (the same capture on any number of
    /// threads).
    pub seed: u64,
    /// The sequence's phase period, projector pixels ([`PatternSet::with_period`]).
    pub period: u32,
    /// How the sequence shows its Gray bits.
    pub code: super::Code,
}

impl Default for SimulatorOptions {
    fn default() -> Self {
        SimulatorOptions {
            supersample: 3,
            blur: 0.7,
            projector_gamma: 2.2,
            camera_gamma: 2.2,
            ambient: 0.05,
            vignetting: 0.2,
            interreflection: 0.0,
            noise: 2.0,
            exposure: 0.8,
            seed: 1,
            period: super::PERIOD,
            code: super::Code::Gray,
        }
    }
}

impl SimulatorOptions {
    /// Refuses values outside what a camera can be, naming the option.
    pub fn validate(&self) -> Result<()> {
        let check = |name: &str, v: f64, lo: f64, hi: f64| -> Result<()> {
            if v.is_finite() && (lo..=hi).contains(&v) {
                Ok(())
            } else {
                Err(Error::invalid(
                    name,
                    format!("must lie within {lo}–{hi}, got {v}"),
                ))
            }
        };
        if !(1..=8).contains(&self.supersample) {
            return Err(Error::invalid(
                "supersample",
                format!("must lie within 1–8, got {}", self.supersample),
            ));
        }
        check("blur", self.blur, 0.0, 10.0)?;
        check("projector_gamma", self.projector_gamma, 0.5, 4.0)?;
        check("camera_gamma", self.camera_gamma, 0.5, 4.0)?;
        check("ambient", self.ambient, 0.0, 1.0)?;
        check("vignetting", self.vignetting, 0.0, 0.95)?;
        check("interreflection", self.interreflection, 0.0, 1.0)?;
        check("noise", self.noise, 0.0, 64.0)?;
        check("exposure", self.exposure, 0.01, 4.0)?;
        PatternSet::new(1, 1)?.with_period(self.period).map(|_| ())
    }
}

/// Projector pixel index of a sub-pixel, or `OFF` where the projector does not light it.
const OFF: u16 = u16::MAX;
/// Camera lattice spacing of the inter-reflection, pixels.
const BOUNCE_STEP: usize = 16;
/// Wall patches of the inter-reflection along the projector's longer side.
const BOUNCE_PATCHES: u32 = 32;

/// One projector seen by one camera, ready to render captures.
pub struct Simulator {
    camera: Channel,
    set: PatternSet,
    opts: SimulatorOptions,
    /// s² projector pixel indices (column, row) per camera pixel.
    samples: Vec<[u16; 2]>,
    truth: Vec<Option<[f64; 2]>>,
    vignette: Vec<f32>,
    bounce: Option<Bounce>,
}

/// The inter-reflection's form factors from the wall patches to the camera lattice.
struct Bounce {
    nodes: [usize; 2],
    /// Per node, per patch, already scaled.
    kernel: Vec<f32>,
    /// The patches' projector pixel ranges: columns and rows.
    patches: Vec<([u32; 2], [u32; 2])>,
}

impl Simulator {
    /// The bench for channel `projector` of `rig` and `camera`. The camera's id is not used.
    pub fn new(
        rig: &Rig,
        projector: &Channel,
        camera: &Channel,
        opts: SimulatorOptions,
    ) -> Result<Simulator> {
        opts.validate()?;
        if projector.width >= u32::from(OFF) || projector.height >= u32::from(OFF) {
            return Err(Error::invalid(
                "projector",
                "the bench handles projectors up to 65534 pixels each way",
            ));
        }
        crate::limits::at_most(
            "camera/resolution",
            camera.width as usize * camera.height as usize,
            super::CAPTURE_PIXELS,
        )?;
        let set = PatternSet::new(projector.width, projector.height)?
            .with_period(opts.period)?
            .with_code(opts.code);
        let screen = &rig.doc.screen;
        let (w, h) = (camera.width as usize, camera.height as usize);
        let s = opts.supersample as usize;

        // The projector coordinates of the camera pixels' corners, exactly.
        let corners: Vec<Option<[f64; 2]>> = (0..(w + 1) * (h + 1))
            .into_par_iter()
            .with_min_len(1024)
            .map(|i| {
                let (x, y) = ((i % (w + 1)) as f64 - 0.5, (i / (w + 1)) as f64 - 0.5);
                lit(screen, projector, seen(screen, camera, [x, y])?)
            })
            .collect();
        let samples: Vec<[u16; 2]> = (0..w * h)
            .into_par_iter()
            .with_min_len(256)
            .flat_map_iter(|i| {
                let (x, y) = (i % w, i / w);
                let c = |dx: usize, dy: usize| corners[(y + dy) * (w + 1) + x + dx];
                let quad = [c(0, 0), c(1, 0), c(0, 1), c(1, 1)];
                let mut out = Vec::with_capacity(s * s);
                for b in 0..s {
                    for a in 0..s {
                        let (fx, fy) = ((a as f64 + 0.5) / s as f64, (b as f64 + 0.5) / s as f64);
                        let q = match quad {
                            [Some(q00), Some(q10), Some(q01), Some(q11)] => Some([0, 1].map(|k| {
                                (1.0 - fy) * ((1.0 - fx) * q00[k] + fx * q10[k])
                                    + fy * ((1.0 - fx) * q01[k] + fx * q11[k])
                            })),
                            _ => seen(screen, camera, [x as f64 - 0.5 + fx, y as f64 - 0.5 + fy])
                                .and_then(|p| lit(screen, projector, p)),
                        };
                        out.push(q.map_or([OFF; 2], |q| pixel_of(q, projector)));
                    }
                }
                out
            })
            .collect();
        let truth = (0..w * h)
            .into_par_iter()
            .with_min_len(1024)
            .map(|i| {
                let q = [(i % w) as f64, (i / w) as f64];
                let q = lit(screen, projector, seen(screen, camera, q)?)?;
                (pixel_of(q, projector) != [OFF; 2]).then_some(q)
            })
            .collect();
        let corner = ((w as f64 / 2.0).powi(2) + (h as f64 / 2.0).powi(2)).max(1e-9);
        let vignette = (0..w * h)
            .map(|i| {
                let (dx, dy) = (
                    (i % w) as f64 + 0.5 - w as f64 / 2.0,
                    (i / w) as f64 + 0.5 - h as f64 / 2.0,
                );
                (1.0 - opts.vignetting * (dx * dx + dy * dy) / corner) as f32
            })
            .collect();
        let mut bench = Simulator {
            camera: camera.clone(),
            set,
            opts,
            samples,
            truth,
            vignette,
            bounce: None,
        };
        if opts.interreflection > 0.0 {
            bench.bounce = bench.bounce(screen, projector);
        }
        Ok(bench)
    }

    /// Reseeds the sensor noise: another capture of the same scene.
    pub fn reseed(&mut self, seed: u64) {
        self.opts.seed = seed;
    }

    /// The pattern sequence the projector shows.
    pub fn patterns(&self) -> &PatternSet {
        &self.set
    }

    /// The camera: its lens, pose and resolution.
    pub fn camera(&self) -> &Channel {
        &self.camera
    }

    /// The projector coordinate the centre of camera pixel (x, y) sees, where the projector
    /// lights it.
    pub fn truth(&self, x: u32, y: u32) -> Option<[f64; 2]> {
        self.truth[(y * self.camera.width + x) as usize]
    }

    /// Form factors from the projector's wall patches to a lattice over the camera image.
    fn bounce(&self, screen: &Screen, projector: &Channel) -> Option<Bounce> {
        let (pw, ph) = (projector.width, projector.height);
        let along = BOUNCE_PATCHES.min(pw.max(ph));
        let size = pw.max(ph).div_ceil(along);
        let (nx, ny) = (pw.div_ceil(size), ph.div_ceil(size));
        let mut patches = Vec::new();
        // Each patch: its range, wall point, outward normal × area.
        let mut emitters = Vec::new();
        for b in 0..ny {
            for a in 0..nx {
                let cols = [a * size, ((a + 1) * size).min(pw)];
                let rows = [b * size, ((b + 1) * size).min(ph)];
                let at = |u: f64, v: f64| -> Option<(DVec3, DVec3)> {
                    let ray = projector.lens.unproject([u, v]).ok()?;
                    match screen.intersect(projector.position, projector.rotation * ray) {
                        Hit::Lit { point, normal, .. } => Some((point, normal)),
                        _ => None,
                    }
                };
                let (u0, u1) = (f64::from(cols[0]) - 0.5, f64::from(cols[1]) - 0.5);
                let (v0, v1) = (f64::from(rows[0]) - 0.5, f64::from(rows[1]) - 0.5);
                let (um, vm) = ((u0 + u1) / 2.0, (v0 + v1) / 2.0);
                let found = (|| {
                    let (p, n) = at(um, vm)?;
                    let du = at(u1, vm)?.0 - at(u0, vm)?.0;
                    let dv = at(um, v1)?.0 - at(um, v0)?.0;
                    Some((p, n * du.cross(dv).length()))
                })();
                if let Some(e) = found {
                    patches.push((cols, rows));
                    emitters.push(e);
                }
            }
        }
        let (w, h) = (self.camera.width as usize, self.camera.height as usize);
        let nodes = [(w - 1) / BOUNCE_STEP + 2, (h - 1) / BOUNCE_STEP + 2];
        let mut kernel: Vec<f32> = (0..nodes[0] * nodes[1])
            .into_par_iter()
            .flat_map_iter(|i| {
                let q = [
                    ((i % nodes[0]) * BOUNCE_STEP) as f64,
                    ((i / nodes[0]) * BOUNCE_STEP) as f64,
                ];
                let ray = self.camera.lens.unproject(q).ok();
                let hit =
                    ray.map(|r| screen.intersect(self.camera.position, self.camera.rotation * r));
                let row: Vec<f32> = match hit {
                    Some(Hit::Lit { point, normal, .. }) => emitters
                        .iter()
                        .map(|&(p2, n2a)| {
                            let d = p2 - point;
                            let r2 = d.length_squared().max(n2a.length());
                            let r = r2.sqrt();
                            let cos = normal.dot(d) / r;
                            let cos2a = -n2a.dot(d) / r;
                            (cos.max(0.0) * cos2a.max(0.0) / (PI * r2)) as f32
                        })
                        .collect(),
                    _ => vec![0.0; emitters.len()],
                };
                row
            })
            .collect();
        // Scale so that full white returns `interreflection` of the direct light, on average
        // over the lattice nodes the projector lights.
        let k = emitters.len();
        let (mut sum, mut count) = (0.0f64, 0usize);
        for (i, row) in kernel.chunks_exact(k.max(1)).enumerate() {
            let (x, y) = ((i % nodes[0]) * BOUNCE_STEP, (i / nodes[0]) * BOUNCE_STEP);
            if x < w && y < h && self.truth[y * w + x].is_some() {
                sum += row.iter().map(|&v| f64::from(v)).sum::<f64>();
                count += 1;
            }
        }
        if k == 0 || count == 0 || sum <= 0.0 {
            return None;
        }
        let scale = (self.opts.interreflection * count as f64 / sum) as f32;
        kernel.iter_mut().for_each(|v| *v *= scale);
        Some(Bounce {
            nodes,
            kernel,
            patches,
        })
    }

    /// What the camera captures while the projector shows frame `n` of its sequence.
    pub fn capture(&self, n: usize) -> Result<Grey> {
        let frame = self.set.frame(n, "frame")?;
        let linear = |v: &u8| self.linear(f64::from(*v));
        let light = match frame.axis() {
            None => Light::Uniform(self.linear(f64::from(self.set.value(frame, 0)))),
            Some(axis) => Light::Stripes {
                rows: axis == Axis::Y,
                values: self.set.profile(frame).iter().map(linear).collect(),
            },
        };
        Ok(self.film(&light, n as u64))
    }

    /// What the camera captures while the projector shows `image`, any picture of the
    /// projector's size (another structured-light code, say); `n` seeds the sensor noise as a
    /// frame number does.
    pub fn capture_image(&self, image: &Grey, n: u64) -> Result<Grey> {
        if [image.width, image.height] != [self.set.width, self.set.height] {
            return Err(Error::invalid(
                "image",
                format!(
                    "is {}×{}, the projector shows {}×{}",
                    image.width, image.height, self.set.width, self.set.height
                ),
            ));
        }
        let values = (0..image.data.len())
            .map(|i| self.linear(image.level(i)))
            .collect();
        let width = image.width as usize;
        Ok(self.film(&Light::Image { width, values }, n))
    }

    fn linear(&self, v: f64) -> f32 {
        (v / 255.0).powf(self.opts.projector_gamma) as f32
    }

    /// Steps 3–7 of the module's list for the projector's light, noise seeded by `n`.
    fn film(&self, light: &Light, n: u64) -> Grey {
        let (w, h) = (self.camera.width as usize, self.camera.height as usize);
        let s2 = (self.opts.supersample * self.opts.supersample) as usize;
        let mut radiance: Vec<f32> = self
            .samples
            .par_chunks_exact(s2)
            .with_min_len(1024)
            .map(|px| {
                let sum: f32 = px
                    .iter()
                    .filter(|q| q[0] != OFF)
                    .map(|&q| light.at(q))
                    .sum();
                sum / s2 as f32
            })
            .collect();
        if let Some(b) = &self.bounce {
            self.add_bounce(b, light, &mut radiance);
        }
        let radiance = blur(&radiance, w, h, self.opts.blur);
        let o = &self.opts;
        let full = 1.0 / (1.0 + o.ambient);
        let mut data = vec![0u8; w * h];
        data.par_chunks_exact_mut(w)
            .enumerate()
            .for_each(|(y, row)| {
                let mut rng = Pcg64::seed_from_u64(
                    o.seed
                        .wrapping_mul(0x9E37_79B9_7F4A_7C15)
                        .wrapping_add((n << 32) | y as u64),
                );
                for (x, out) in row.iter_mut().enumerate() {
                    let i = y * w + x;
                    let e = f64::from(self.vignette[i]) * (f64::from(radiance[i]) + o.ambient);
                    let signal = (o.exposure * full * e).clamp(0.0, 1.0);
                    let mut v = 255.0 * signal.powf(1.0 / o.camera_gamma);
                    if o.noise > 0.0 {
                        let z: f64 = StandardNormal.sample(&mut rng);
                        v += o.noise * z;
                    }
                    *out = v.round().clamp(0.0, 255.0) as u8;
                }
            });
        Grey::new(self.camera.width, self.camera.height, data)
    }

    /// Adds the one-bounce light of the projector's `light`.
    fn add_bounce(&self, b: &Bounce, light: &Light, radiance: &mut [f32]) {
        let emit: Vec<f32> = b
            .patches
            .iter()
            .map(|&(cols, rows)| light.mean(cols, rows))
            .collect();
        let k = emit.len();
        let lattice: Vec<f32> = b
            .kernel
            .par_chunks_exact(k)
            .map(|row| row.iter().zip(&emit).map(|(a, e)| a * e).sum())
            .collect();
        let w = self.camera.width as usize;
        radiance
            .par_chunks_exact_mut(w)
            .enumerate()
            .for_each(|(y, row)| {
                let (gy, fy) = (
                    y / BOUNCE_STEP,
                    (y % BOUNCE_STEP) as f32 / BOUNCE_STEP as f32,
                );
                for (x, v) in row.iter_mut().enumerate() {
                    let (gx, fx) = (
                        x / BOUNCE_STEP,
                        (x % BOUNCE_STEP) as f32 / BOUNCE_STEP as f32,
                    );
                    let at = |dx: usize, dy: usize| lattice[(gy + dy) * b.nodes[0] + gx + dx];
                    *v += (1.0 - fy) * ((1.0 - fx) * at(0, 0) + fx * at(1, 0))
                        + fy * ((1.0 - fx) * at(0, 1) + fx * at(1, 1));
                }
            });
    }
}

/// What the projector shows, in linear light. The sequence's own frames vary along one axis,
/// so they are kept as one value per column or row; any other picture is kept whole.
enum Light {
    Uniform(f32),
    Stripes { rows: bool, values: Vec<f32> },
    Image { width: usize, values: Vec<f32> },
}

impl Light {
    fn at(&self, q: [u16; 2]) -> f32 {
        match self {
            Light::Uniform(v) => *v,
            Light::Stripes { rows, values } => values[usize::from(q[usize::from(*rows)])],
            Light::Image { width, values } => values[usize::from(q[1]) * width + usize::from(q[0])],
        }
    }

    /// The mean over projector columns `cols` and rows `rows` (half-open, not empty).
    fn mean(&self, cols: [u32; 2], rows: [u32; 2]) -> f32 {
        let span = |r: [u32; 2]| r[0] as usize..r[1] as usize;
        let mean = |v: &[f32]| v.iter().sum::<f32>() / v.len() as f32;
        match self {
            Light::Uniform(v) => *v,
            Light::Stripes {
                rows: false,
                values,
            } => mean(&values[span(cols)]),
            Light::Stripes { rows: true, values } => mean(&values[span(rows)]),
            Light::Image { width, values } => {
                let sums: Vec<f32> = span(rows)
                    .map(|y| mean(&values[y * width..(y + 1) * width][span(cols)]))
                    .collect();
                mean(&sums)
            }
        }
    }
}

/// The bench's default camera: a 185° fisheye (Kannala–Brandt, no distortion) of `w`×`h`
/// whose circle fills the image's height, at the rig's eye, looking at the middle of the
/// projector's image on the wall — it sees all of any projector a viewer at the eye sees.
pub fn fisheye_at_eye(rig: &Rig, projector: &Channel, w: u32, h: u32) -> Result<Channel> {
    let centre = [
        f64::from(projector.width) / 2.0 - 0.5,
        f64::from(projector.height) / 2.0 - 0.5,
    ];
    let target = rig.wall_point(projector, centre).ok_or_else(|| {
        Error::invalid(
            "channel",
            format!("the middle of `{}`'s image misses the wall", projector.id),
        )
    })?;
    let to = (target - rig.eye).normalize();
    let up = if to.cross(DVec3::Y).length() > 0.1 {
        DVec3::Y
    } else {
        DVec3::NEG_Z
    };
    let f = f64::from(h) / 2.0 / 92.5f64.to_radians();
    let doc = crate::rig::ChannelDoc {
        id: "camera".into(),
        resolution: [w, h],
        lens: crate::rig::LensDoc::new(
            "LENSMODEL_OPENCV_FISHEYE",
            vec![
                f,
                f,
                f64::from(w) / 2.0 - 0.5,
                f64::from(h) / 2.0 - 0.5,
                0.0,
                0.0,
                0.0,
                0.0,
            ],
        ),
        pose: crate::rig::PoseDoc {
            position: rig.eye.to_array(),
            look_to: Some(to.to_array()),
            look_up: Some(up.to_array()),
            rvec: None,
        },
        contrast: None,
    };
    Channel::from_doc(&doc, "/camera")
}

/// The wall point camera pixel `q` sees, if any.
fn seen(screen: &Screen, camera: &Channel, q: [f64; 2]) -> Option<DVec3> {
    let ray = camera.lens.unproject(q).ok()?;
    match screen.intersect(camera.position, camera.rotation * ray) {
        Hit::Lit { point, .. } => Some(point),
        _ => None,
    }
}

/// The projector coordinate of wall point `p`, where the projector reaches it first.
fn lit(screen: &Screen, projector: &Channel, p: DVec3) -> Option<[f64; 2]> {
    let d = p - projector.position;
    let dist = d.length();
    match screen.intersect(projector.position, d / dist) {
        Hit::Lit { t, .. } if (t - dist).abs() <= 1e-6 * dist.max(1.0) => {}
        _ => return None,
    }
    projector
        .lens
        .project(projector.rotation.transpose() * d)
        .ok()
}

/// The projector pixel holding coordinate `q`, or `OFF` outside the raster.
fn pixel_of(q: [f64; 2], projector: &Channel) -> [u16; 2] {
    let (i, j) = ((q[0] + 0.5).floor(), (q[1] + 0.5).floor());
    if i >= 0.0 && j >= 0.0 && i < f64::from(projector.width) && j < f64::from(projector.height) {
        [i as u16, j as u16]
    } else {
        [OFF; 2]
    }
}

/// Separable Gaussian blur, σ in pixels, edges clamped.
fn blur(img: &[f32], w: usize, h: usize, sigma: f64) -> Vec<f32> {
    if sigma <= 0.0 {
        return img.to_vec();
    }
    let r = (3.0 * sigma).ceil() as isize;
    let mut taps: Vec<f32> = (-r..=r)
        .map(|i| (-(i * i) as f64 / (2.0 * sigma * sigma)).exp() as f32)
        .collect();
    let total: f32 = taps.iter().sum();
    taps.iter_mut().for_each(|t| *t /= total);
    let clamp = |k: isize, len: usize| k.clamp(0, len as isize - 1) as usize;
    let mut across = vec![0.0; w * h];
    across
        .par_chunks_exact_mut(w)
        .zip(img.par_chunks_exact(w))
        .for_each(|(out, src)| {
            for (x, o) in out.iter_mut().enumerate() {
                *o = taps
                    .iter()
                    .enumerate()
                    .map(|(t, tap)| tap * src[clamp(x as isize + t as isize - r, w)])
                    .sum();
            }
        });
    let mut out = vec![0.0; w * h];
    out.par_chunks_exact_mut(w)
        .enumerate()
        .for_each(|(y, row)| {
            for (t, tap) in taps.iter().enumerate() {
                let src = clamp(y as isize + t as isize - r, h);
                let src = &across[src * w..(src + 1) * w];
                row.iter_mut().zip(src).for_each(|(o, v)| *o += tap * v);
            }
        });
    out
}
