//! Previews: the procedural test pattern through a channel's warp, desaturated by its tiles'
//! f and attenuated by its blend, on the CPU or the GPU.

use crate::content::Content;
use crate::content::pattern::Pattern;
use crate::cubemap::CubeMap;
use crate::normalmap::NormalMap;
use crate::raster::{Pixel, Raster};
use crate::render::coverage::{face_size_for, faces_sampled};
use crate::render::{self, Filter, Plan, Warp};
use crate::rig::{apply_blend_and_lift, apply_gains, signal_gains};
use crate::server::storage::cache::{Computed, GpuWarp};
use rayon::prelude::*;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, OnceLock};

/// A channel's picture made a preview: desaturated by the tiles' f and attenuated by the blend
/// weights (raised to 1/2.2: PNG previews are in signal space), lifted where the rig has a
/// black level.
pub fn finish(
    img: &mut Raster<[u8; 4]>,
    light: (&[f32], Option<&[f32]>),
    f: Option<&[f32]>,
) -> crate::Result<()> {
    if let Some(f) = f {
        crate::tiles::raster::saturation(img, f);
    }
    Light::of(light.0, light.1, 2.2)?.apply(img)
}

/// What a preview is multiplied by and lifted with, at its pixels: the blend's gains in signal
/// space, or with a black lift (docs/photometry.md) the weights and the lift.
pub enum Light {
    Gains(Vec<f32>),
    Lifted {
        weights: Vec<f32>,
        lift: Vec<f32>,
        gamma: f64,
    },
}

impl Light {
    /// The light of pixels with blend `weights` and black `lift`, for outputs of `gamma`.
    pub fn of(weights: &[f32], lift: Option<&[f32]>, gamma: f64) -> crate::Result<Light> {
        Ok(match lift {
            Some(lift) => Light::Lifted {
                weights: weights.to_vec(),
                lift: lift.to_vec(),
                gamma,
            },
            None => Light::Gains(signal_gains(weights, gamma)?),
        })
    }

    /// Applies it to a picture of the size it was made for.
    pub fn apply<T: Pixel>(&self, img: &mut Raster<T>) -> crate::Result<()> {
        match self {
            Light::Gains(g) => apply_gains(img, g),
            Light::Lifted {
                weights,
                lift,
                gamma,
            } => apply_blend_and_lift(img, weights, lift, *gamma),
        }
    }
}

/// The cube face size a preview uses unless asked for one: texels as fine as the preview's
/// finest pixels, so the pattern's edges show the warp, not the cube's stair steps; 32-bit
/// previews stop at 1024 (six such faces are 100 MB, as six 8-bit faces of 2048 are).
pub fn default_face(map: &NormalMap, exr: bool) -> usize {
    face_size_for(map, if exr { 1024 } else { 2048 }) as usize
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
pub struct PatternCubes(Mutex<Vec<Arc<PatternCube>>>);

/// A kept cube: its pattern, face size, texels, which faces are evaluated, and the atlas the
/// CPU renderer reads (made on first use: GPU previews upload the cube itself).
pub struct PatternCube {
    pattern: Pattern,
    face: usize,
    faces: [bool; 6],
    pub cube: CubeMap<[u8; 4]>,
    content: OnceLock<Content<[u8; 4]>>,
}

impl PatternCube {
    pub fn content(&self) -> &Content<[u8; 4]> {
        self.content.get_or_init(|| Content::cube(&self.cube))
    }
}

/// How many cubes are kept (each at most six 2048² faces of 8-bit RGBA, 100 MB, and its atlas
/// as much again).
const KEPT: usize = 2;

impl PatternCubes {
    /// The 8-bit cube of `look` with at least the faces `map` samples evaluated.
    pub fn get(&self, look: &Look, map: &NormalMap) -> Arc<PatternCube> {
        let need = crate::render::coverage::faces_sampled(map, look.face as u32);
        let mut on = need;
        {
            let kept = self.0.lock().expect("pattern cube lock");
            if let Some(c) = kept
                .iter()
                .find(|c| c.pattern == look.pattern && c.face == look.face)
            {
                if (0..6).all(|i| c.faces[i] || !need[i]) {
                    return c.clone();
                }
                on = std::array::from_fn(|i| c.faces[i] || need[i]);
            }
        }
        let cube = Arc::new(PatternCube {
            pattern: look.pattern,
            face: look.face,
            faces: on,
            cube: look.cube::<[u8; 4]>(on, 255.0),
            content: OnceLock::new(),
        });
        let mut kept = self.0.lock().expect("pattern cube lock");
        kept.retain(|c| !(c.pattern == look.pattern && c.face == look.face));
        kept.push(cube.clone());
        let excess = kept.len().saturating_sub(KEPT);
        kept.drain(..excess);
        cube
    }
}

/// What a preview request asks for besides the channel: equal asks of an unchanged channel
/// give the same picture.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Ask {
    pub scale: usize,
    pub pattern: Pattern,
    /// The cube's face size, or `None` to match it to the preview's pixels.
    pub face: Option<usize>,
    pub filter: Filter,
}

/// Which pixels of a channel's warp a preview shows: the centre pixel of each k × k block.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Grid {
    pub w: usize,
    pub h: usize,
    pub k: usize,
    pub ow: usize,
    pub oh: usize,
}

impl Grid {
    pub fn new(w: usize, h: usize, k: usize) -> Grid {
        Grid {
            w,
            h,
            k,
            ow: w.div_ceil(k),
            oh: h.div_ceil(k),
        }
    }

    #[inline]
    fn pick(&self, i: usize, j: usize) -> usize {
        let k = self.k;
        ((j * k + k / 2).min(self.h - 1)) * self.w + (i * k + k / 2).min(self.w - 1)
    }

    /// The picked values of a per-pixel array of the channel.
    pub fn values<T: Copy + Send + Sync>(&self, full: &[T]) -> Vec<T> {
        if self.k == 1 {
            return full.to_vec();
        }
        let mut out = Vec::with_capacity(self.ow * self.oh);
        for j in 0..self.oh {
            out.extend((0..self.ow).map(|i| full[self.pick(i, j)]));
        }
        out
    }

    pub fn map(&self, full: &NormalMap) -> crate::Result<NormalMap> {
        let data = self.values(&full.pixels().data);
        NormalMap::from_pixels(
            Raster {
                width: self.ow,
                height: self.oh,
                data,
            },
            vec![],
        )
    }

    /// Rows `rows` of a map, as a map of their own.
    fn rows(map: &NormalMap, rows: std::ops::Range<usize>) -> crate::Result<NormalMap> {
        let w = map.width();
        NormalMap::from_pixels(
            Raster {
                width: w,
                height: rows.len(),
                data: map.pixels().data[rows.start * w..rows.end * w].to_vec(),
            },
            vec![],
        )
    }

    /// The preview rows whose picked pixels differ between two maps of the channel.
    fn changed(&self, a: &NormalMap, b: &NormalMap) -> std::ops::Range<usize> {
        let (a, b) = (&a.pixels().data, &b.pixels().data);
        let differs = |j: usize| {
            if self.k == 1 {
                let row = j * self.w..(j + 1) * self.w;
                return a[row.clone()] != b[row];
            }
            (0..self.ow).any(|i| a[self.pick(i, j)] != b[self.pick(i, j)])
        };
        let first = (0..self.oh).into_par_iter().find_first(|&j| differs(j));
        let last = (0..self.oh).into_par_iter().find_last(|&j| differs(j));
        match (first, last) {
            (Some(first), Some(last)) => first..last + 1,
            _ => 0..0,
        }
    }
}

/// A CPU preview ready to render again: everything but the frame. Kept per channel and ask;
/// after a tile edit the plan is rebuilt only in the rows whose warp changed.
pub struct Prepared {
    id: String,
    ask: Ask,
    key: u64,
    computed: Arc<Computed>,
    grid: Grid,
    cube: Arc<PatternCube>,
    plan: Plan,
    /// The blend (and black lift) per pixel, for PNG previews in signal space (γ 2.2).
    light: Arc<Light>,
    /// The tiles' f at the preview's pixels where it is subsampled; at full scale the frame
    /// reads the computed warp's own (copying it took a 1080p preview 2–4 ms).
    f: Option<Vec<f32>>,
}

impl Prepared {
    /// Renders the preview: the plan's frame, desaturated by the tiles' f and attenuated by the
    /// blend, as [`Look::render`] does.
    pub fn frame(&self) -> crate::Result<Raster<[u8; 4]>> {
        let mut img = self.plan.render(self.cube.content().atlas())?;
        let f = if self.grid.k == 1 {
            self.computed.f.as_deref()
        } else {
            self.f.as_deref()
        };
        if let Some(f) = f {
            crate::tiles::raster::saturation(&mut img, f);
        }
        self.light.apply(&mut img)?;
        Ok(img)
    }
}

/// How many prepared previews are kept (a 1080p one holds about 40 MB).
const PREPARED: usize = 4;

/// Prepared previews, most recent last.
#[derive(Default)]
pub struct Previews(Mutex<Vec<Arc<Prepared>>>);

/// How a preview was made ready, for the `X-Omniwarp-Preview` header and the tests.
#[derive(Debug, Clone, PartialEq)]
pub enum Made {
    /// Kept from an earlier request with the same inputs.
    Kept,
    /// From an earlier preview of the channel, its plan rebuilt in these rows.
    Rebuilt(std::ops::Range<usize>),
    /// From nothing.
    Built,
}

impl Previews {
    /// The prepared preview of channel `id` for `ask`, given its computed warp (and that
    /// warp's input hash `key`).
    pub fn get(
        &self,
        id: &str,
        ask: Ask,
        key: u64,
        computed: &Arc<Computed>,
        cubes: &PatternCubes,
        cancel: &AtomicBool,
    ) -> crate::Result<(Arc<Prepared>, Made)> {
        let (kept, base) = {
            let all = self.0.lock().expect("preview lock");
            let same = |p: &&Arc<Prepared>| p.id == id && p.ask == ask;
            (
                all.iter().filter(same).find(|p| p.key == key).cloned(),
                all.iter().rev().find(same).cloned(),
            )
        };
        if let Some(p) = kept {
            return Ok((p, Made::Kept));
        }
        let full = &computed.map;
        let grid = Grid::new(full.width(), full.height(), ask.scale);
        // At full scale the preview reads the channel's map itself.
        let sub;
        let map = if ask.scale == 1 {
            full
        } else {
            sub = grid.map(full)?;
            &sub
        };
        let stop = || {
            if cancel.load(Ordering::Relaxed) {
                Err(crate::Error::Cancelled)
            } else {
                Ok(())
            }
        };
        stop()?;
        let face = ask.face.unwrap_or_else(|| default_face(map, false));
        let look = Look {
            pattern: ask.pattern,
            face,
            filter: ask.filter,
        };
        let light = |c: &Computed| -> crate::Result<Arc<Light>> {
            let lift = c.geometry.lift.as_ref().map(|l| grid.values(l));
            Ok(Arc::new(Light::of(
                &grid.values(&c.geometry.weights),
                lift.as_deref(),
                2.2,
            )?))
        };
        let f = match ask.scale {
            1 => None,
            _ => computed.f.as_ref().map(|f| grid.values(f)),
        };
        // An earlier preview of this channel and ask, another warp: keep what still holds.
        let reuse = base.filter(|b| b.grid == grid && b.cube.face == face);
        let made = match reuse {
            Some(b) => {
                let changed = grid.changed(&b.computed.map, full);
                let need = if changed.is_empty() {
                    [false; 6]
                } else {
                    faces_sampled(&Grid::rows(map, changed.clone())?, face as u32)
                };
                if (0..6).all(|i| b.cube.faces[i] || !need[i]) {
                    let mut plan = b.plan.clone();
                    let content = b.cube.content();
                    let rows = plan.redo(Warp::Map(map), content, content.atlas(), changed)?;
                    let light = if Arc::ptr_eq(&b.computed.geometry, &computed.geometry) {
                        b.light.clone()
                    } else {
                        light(computed)?
                    };
                    Some((plan, b.cube.clone(), light, Made::Rebuilt(rows)))
                } else {
                    None
                }
            }
            None => None,
        };
        let (plan, cube, light, made) = match made {
            Some(m) => m,
            None => {
                let cube = cubes.get(&look, map);
                stop()?;
                let content = cube.content();
                let (w, h) = (grid.ow as u32, grid.oh as u32);
                let plan = Plan::new(
                    Warp::Map(map),
                    content,
                    content.atlas(),
                    w,
                    h,
                    1,
                    ask.filter,
                )?;
                (plan, cube, light(computed)?, Made::Built)
            }
        };
        let prepared = Arc::new(Prepared {
            id: id.to_string(),
            ask,
            key,
            computed: computed.clone(),
            grid,
            cube,
            plan,
            light,
            f,
        });
        let mut all = self.0.lock().expect("preview lock");
        all.retain(|p| !(p.id == id && p.ask == ask));
        all.push(prepared.clone());
        let excess = all.len().saturating_sub(PREPARED);
        all.drain(..excess);
        Ok((prepared, made))
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
        light: (&[f32], Option<&[f32]>),
        f: Option<&[f32]>,
        gamma: f64,
    ) -> crate::Result<Raster<T>> {
        let content = Content::cube(cube);
        let (w, h) = (map.width() as u32, map.height() as u32);
        let mut img = render::render(Warp::Map(map), &content, w, h, 1, self.filter)?;
        if let Some(f) = f {
            crate::tiles::raster::saturation(&mut img, f);
        }
        Light::of(light.0, light.1, gamma)?.apply(&mut img)?;
        Ok(img)
    }

    /// [`Look::render`] of 8-bit PNG previews with the warp on the GPU.
    pub fn render_gpu(
        &self,
        g: &GpuWarp,
        cube: &CubeMap<[u8; 4]>,
        map: &NormalMap,
        light: (&[f32], Option<&[f32]>),
        f: Option<&[f32]>,
    ) -> crate::Result<Raster<[u8; 4]>> {
        let tex = crate::gpu::warp::CubeTexture::upload(&g.gpu, cube);
        let size = (map.width() as u32, map.height() as u32);
        let source = crate::gpu::warp::Source::Map(map);
        let mut img = g.pass.render(&g.gpu, &tex, source, size, f, None)?;
        Light::of(light.0, light.1, 2.2)?.apply(&mut img)?;
        Ok(img)
    }
}
