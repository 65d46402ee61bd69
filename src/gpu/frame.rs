//! One frame of a 3D scene through a projection: cube-map pass, then warp pass, on the GPU or,
//! without one, on the CPU (ray-cast cube map, CPU warp, the same blur). The driver the CLI and
//! the benchmark share.

use super::cube::CubePass;
use super::ppp::{NEAR as PPP_NEAR, PppPass};
use super::warp::{CubeTexture, ProjectionUniform, Source, WarpPass};
use super::{Gpu, Renderer, read_rgba8_layer};
use crate::content::Content;
use crate::cubemap::CubeMap;
use crate::error::{Error, Result};
use crate::normalmap::NormalMap;
use crate::projection::View;
use crate::projection::view::screen_of_pixel;
use crate::raster::Raster;
use crate::render::blur::{Blur, radial_blur};
use crate::render::coverage::{face_size_for, faces_sampled};
use crate::render::{self, Filter, Warp};
use crate::scene::ppp::Pieces;
use crate::scene::replicate::replicate;
use crate::scene::{Projected, RayCaster, Scene};
use glam::DVec3;

/// How to draw a frame of a scene: output size, cube-map settings, blur and eye.
#[derive(Debug, Clone, Copy)]
pub struct FrameOptions {
    /// Output width and height in pixels (a warp map's size must match).
    pub size: (u32, u32),
    /// Cube face size; `None` picks it from the output ([`face_size_for`]).
    pub face: Option<u32>,
    /// Render only the faces the warp samples (seed 000's CMF).
    pub cmf: bool,
    /// Seed 000's radial blur applied to the finished frame, or none.
    pub blur: Option<Blur>,
    /// The eye (centre of projection) in world coordinates, metres.
    pub eye: DVec3,
}

/// What a frame did.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FrameReport {
    /// The cube face size used, in texels a side.
    pub face: u32,
    /// The faces the cube map covers for this frame, in [`crate::cubemap::Face`] order (all six
    /// without CMF).
    pub faces: [bool; 6],
    /// False when the look-to check found the cube map already current.
    pub cube_updated: bool,
}

enum Backend {
    Gpu {
        gpu: Box<Gpu>,
        warp: Box<WarpPass>,
        cube: Box<CubePass>,
        target: Option<CubeTexture>,
        /// Made on the first piecewise perspective frame.
        ppp: Option<Box<PppPass>>,
    },
    Cpu {
        caster: Box<RayCaster>,
        cached: Option<CpuCube>,
        panorama: Option<Box<Projected>>,
    },
}

/// The CPU's cube map and the (eye, face size, faces cast, panorama centre) it shows.
type CpuCube = (
    ([f32; 3], u32, [bool; 6], Option<[f32; 3]>),
    CubeMap<[u8; 4]>,
);

/// Face size and faces decided for a view (they change only with the view).
type Plan = (Option<Vec<u8>>, Option<u32>, bool, (u32, [bool; 6]));

/// Draws frames of one scene through views or warp maps, on the GPU when there is one and
/// on the CPU twin otherwise, keeping the cube map between frames (the look-to check).
pub struct SceneRenderer {
    backend: Backend,
    plan: Option<Plan>,
    /// The scene, for the piecewise perspective pass's replication.
    scene: Scene,
    projected: bool,
    /// The exact per-pixel ray caster, made on the first exact frame.
    exact: Option<Box<RayCaster>>,
}

/// What a piecewise perspective frame did.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PppReport {
    /// Number of perspective pieces the frame was cut into.
    pub pieces: usize,
    /// Triangles drawn (once per piece) over the scene's triangles; `None` on the CPU, whose
    /// twin casts rays instead.
    pub replication: Option<f64>,
}

/// Vulkan's standard positions of 4× multisampling within a pixel (what lavapipe and GPUs use
/// with `sample_count` 4): the CPU twin of the antialiased piecewise perspective pass.
const MSAA_POSITIONS: [(f64, f64); 4] = [
    (0.375, 0.125),
    (0.875, 0.375),
    (0.125, 0.625),
    (0.625, 0.875),
];

/// Largest face the CPU ray caster is asked for (6 × 2048² rays is already minutes).
const CPU_MAX_FACE: u32 = 2048;

impl SceneRenderer {
    /// `Auto` takes the GPU when an adapter exists and says once (stderr) when it falls back.
    pub fn new(scene: Scene, renderer: Renderer, adapter: Option<&str>) -> Result<Self> {
        let gpu = match renderer {
            Renderer::Cpu => None,
            Renderer::Gpu => Some(Gpu::new(adapter)?.ok_or_else(|| {
                Error::invalid(
                    "renderer",
                    "no GPU adapter (not even lavapipe: apt-get install mesa-vulkan-drivers); use --renderer cpu",
                )
            })?),
            Renderer::Auto => {
                let g = Gpu::new(adapter)?;
                if g.is_none() {
                    eprintln!("no GPU adapter: rendering on the CPU");
                }
                g
            }
        };
        let backend = match gpu {
            Some(gpu) => {
                let warp = Box::new(WarpPass::new(&gpu));
                let cube = Box::new(CubePass::new(&gpu, &scene));
                Backend::Gpu {
                    gpu: Box::new(gpu),
                    warp,
                    cube,
                    target: None,
                    ppp: None,
                }
            }
            None => Backend::Cpu {
                caster: Box::new(scene.ray_caster()?),
                cached: None,
                panorama: None,
            },
        };
        Ok(SceneRenderer {
            backend,
            plan: None,
            scene,
            projected: false,
            exact: None,
        })
    }

    /// Whether frames are drawn on a GPU adapter (lavapipe counts) rather than the CPU twin.
    pub fn on_gpu(&self) -> bool {
        matches!(self.backend, Backend::Gpu { .. })
    }

    /// The adapter's description, or "CPU".
    pub fn describe(&self) -> String {
        match &self.backend {
            Backend::Gpu { gpu, .. } => gpu.describe(),
            Backend::Cpu { .. } => "CPU (ray-cast cube map, CPU warp)".into(),
        }
    }

    /// Shows `panorama` projected from its centre onto the scene (seed 001) instead of the
    /// scene's own colours, or the scene's colours again with `None`.
    pub fn set_panorama(&mut self, panorama: Option<Projected>) -> Result<()> {
        self.projected = panorama.is_some();
        match &mut self.backend {
            Backend::Gpu { gpu, cube, .. } => cube.set_panorama(gpu, panorama.as_ref()),
            Backend::Cpu {
                panorama: p,
                cached,
                ..
            } => {
                *p = panorama.map(Box::new);
                *cached = None;
                Ok(())
            }
        }
    }

    /// Moves the projected panorama's centre (no upload of the panorama again).
    pub fn set_centre(&mut self, centre: DVec3) {
        match &mut self.backend {
            Backend::Gpu { gpu, cube, .. } => cube.set_centre(gpu, centre),
            Backend::Cpu { panorama, .. } => {
                if let Some(p) = panorama {
                    p.centre = centre;
                }
            }
        }
    }

    /// Forgets the cube map shown, so that the next frame draws it again (benchmarks that
    /// time the whole frame).
    pub fn invalidate(&mut self) {
        match &mut self.backend {
            Backend::Gpu { cube, .. } => cube.invalidate(),
            Backend::Cpu { cached, .. } => *cached = None,
        }
    }

    /// Faces drawn by the GPU so far (0 on the CPU).
    pub fn faces_drawn(&self) -> u64 {
        match &self.backend {
            Backend::Gpu { cube, .. } => cube.faces_drawn,
            Backend::Cpu { .. } => 0,
        }
    }

    /// A frame drawn straight through a piecewise perspective projection (seed 003), the
    /// pieces' replication decided for this eye; `o.face` and `o.cmf` do not apply.
    pub fn frame_ppp(
        &mut self,
        pieces: &Pieces,
        o: &FrameOptions,
    ) -> Result<(Raster<[u8; 4]>, PppReport)> {
        self.ppp(pieces, o, false)
    }

    /// [`Self::frame_ppp`] antialiased: 4× multisampling on the GPU; on the CPU, rays at the
    /// same four standard sample positions, averaged.
    pub fn frame_ppp_antialiased(
        &mut self,
        pieces: &Pieces,
        o: &FrameOptions,
    ) -> Result<(Raster<[u8; 4]>, PppReport)> {
        self.ppp(pieces, o, true)
    }

    fn ppp(
        &mut self,
        pieces: &Pieces,
        o: &FrameOptions,
        msaa: bool,
    ) -> Result<(Raster<[u8; 4]>, PppReport)> {
        if self.projected {
            return Err(Error::invalid(
                "method",
                "the piecewise perspective pass draws the scene's own colours; a projected panorama needs the cube method",
            ));
        }
        if (pieces.width, pieces.height) != o.size {
            return Err(Error::invalid(
                "size",
                format!(
                    "the pieces are cut for {}×{}, the frame is {}×{}",
                    pieces.width, pieces.height, o.size.0, o.size.1
                ),
            ));
        }
        // The CPU twin casts rays through the BVH and needs no replication.
        let (mut img, replication) = match &mut self.backend {
            Backend::Gpu { gpu, ppp, .. } => {
                let replication = replicate(&self.scene, pieces, o.eye, PPP_NEAR);
                let img = ppp
                    .get_or_insert_with(|| Box::new(PppPass::new(gpu, &self.scene)))
                    .render(gpu, pieces, &replication, o.eye, msaa)?;
                (img, Some(replication.factor))
            }
            Backend::Cpu { caster, .. } => {
                let (w, h) = o.size;
                let img = if msaa {
                    caster
                        .picture_averaged(o.eye, w, h, &MSAA_POSITIONS, |x, y| pieces.ray_at(x, y))
                } else {
                    caster.picture(o.eye, w, h, |i, j| pieces.ray(i, j))
                };
                (img, None)
            }
        };
        if let Some(b) = o.blur {
            img = radial_blur(&img, b);
        }
        Ok((
            img,
            PppReport {
                pieces: pieces.pieces.len(),
                replication,
            },
        ))
    }

    /// The scene from `eye` as a cube map of `face`² on the CPU: drawn by the cube-map pass and
    /// read back on the GPU, ray cast on the CPU. For warping it on the CPU with any filter
    /// and supersampling (the method chart).
    pub fn cube_map(&mut self, eye: DVec3, face: u32) -> Result<CubeMap<[u8; 4]>> {
        match &mut self.backend {
            Backend::Gpu {
                gpu, cube, target, ..
            } => {
                if target.as_ref().is_none_or(|t| t.size != face) {
                    *target = Some(CubeTexture::target(gpu, face));
                }
                let t = target.as_ref().expect("set above");
                cube.render(gpu, t, eye, [true; 6]);
                let faces = crate::cubemap::Face::ALL
                    .map(|f| read_rgba8_layer(gpu, &t.texture, face, face, f.index() as u32));
                let [a, b, c, d, e, f] = faces;
                CubeMap::from_faces([a?, b?, c?, d?, e?, f?])
            }
            Backend::Cpu { caster, .. } => Ok(caster.cube(eye, face as usize, [true; 6])),
        }
    }

    /// The exact reference: one ray per pixel centre along the view's own direction, cast on
    /// the CPU whatever the backend; transparent where the view shows nothing.
    pub fn frame_exact(&mut self, view: &View, o: &FrameOptions) -> Result<Raster<[u8; 4]>> {
        self.frame_reference(view, o, 1)
    }

    /// [`Self::frame_exact`] with `samples` × `samples` rays per pixel, averaged: the reference
    /// for antialiased (supersampled) methods, which one ray per pixel centre penalises.
    pub fn frame_reference(
        &mut self,
        view: &View,
        o: &FrameOptions,
        samples: u32,
    ) -> Result<Raster<[u8; 4]>> {
        if self.projected {
            return Err(Error::invalid(
                "method",
                "the exact reference draws the scene's own colours; a projected panorama needs the cube method",
            ));
        }
        crate::raster::check_size(o.size.0, o.size.1, samples)?;
        if !(1..=8).contains(&samples) {
            return Err(Error::invalid(
                "samples",
                format!("must be 1–8 per side, got {samples}"),
            ));
        }
        let caster = self.exact_caster()?;
        let (w, h) = o.size;
        let k = f64::from(samples);
        let grid: Vec<(f64, f64)> = (0..samples * samples)
            .map(|n| {
                let (a, b) = (f64::from(n % samples), f64::from(n / samples));
                ((a + 0.5) / k, (b + 0.5) / k)
            })
            .collect();
        let mut img = caster.picture_averaged(o.eye, w, h, &grid, |x, y| {
            let (s, t) = screen_of_pixel(x, y, w, h);
            view.direction(s, t).ok()
        });
        if let Some(b) = o.blur {
            img = radial_blur(&img, b);
        }
        Ok(img)
    }

    /// The exact reference through a projector channel's warp map: one ray per pixel along
    /// the map's own direction, transparent where the map has none.
    pub fn frame_exact_map(
        &mut self,
        map: &NormalMap,
        o: &FrameOptions,
    ) -> Result<Raster<[u8; 4]>> {
        if self.projected {
            return Err(Error::invalid(
                "method",
                "the exact reference draws the scene's own colours; a projected panorama needs the cube method",
            ));
        }
        let (w, h) = o.size;
        if (map.width(), map.height()) != (w as usize, h as usize) {
            return Err(Error::invalid(
                "size",
                format!(
                    "the warp map is {}×{}, the frame {w}×{h}",
                    map.width(),
                    map.height()
                ),
            ));
        }
        let caster = self.exact_caster()?;
        let mut img = caster.picture(o.eye, w, h, |i, j| map.direction(i as usize, j as usize));
        if let Some(b) = o.blur {
            img = radial_blur(&img, b);
        }
        Ok(img)
    }

    /// The CPU ray caster: the backend's own on the CPU, else one built on first need.
    fn exact_caster(&mut self) -> Result<&RayCaster> {
        Ok(match &self.backend {
            Backend::Cpu { caster, .. } => caster,
            Backend::Gpu { .. } => match &mut self.exact {
                Some(c) => c,
                slot => slot.insert(Box::new(self.scene.ray_caster()?)),
            },
        })
    }

    /// A frame through `view` by the cube-map method: the cube map (redrawn only when the eye,
    /// face size or faces changed), then the warp pass and the optional blur.
    pub fn frame(
        &mut self,
        view: &View,
        o: &FrameOptions,
    ) -> Result<(Raster<[u8; 4]>, FrameReport)> {
        self.frame_from(Source::View(view), o)
    }

    /// A frame through a warp map instead of a view: a projector channel's warp (directions
    /// from the eye) samples the scene's cube map as seed 000's warp pass does. The map's size
    /// is the output's.
    pub fn frame_map(
        &mut self,
        map: &NormalMap,
        o: &FrameOptions,
    ) -> Result<(Raster<[u8; 4]>, FrameReport)> {
        if (map.width(), map.height()) != (o.size.0 as usize, o.size.1 as usize) {
            return Err(Error::invalid(
                "size",
                format!(
                    "the warp map is {}×{}, the frame {}×{}",
                    map.width(),
                    map.height(),
                    o.size.0,
                    o.size.1
                ),
            ));
        }
        self.frame_from(Source::Map(map), o)
    }

    /// [`Self::frame`] or [`Self::frame_map`], as `source` says.
    pub fn frame_from(
        &mut self,
        source: Source<'_>,
        o: &FrameOptions,
    ) -> Result<(Raster<[u8; 4]>, FrameReport)> {
        let (w, h) = o.size;
        let max = match &self.backend {
            Backend::Gpu { gpu, .. } => gpu.device.limits().max_texture_dimension_2d.min(8192),
            Backend::Cpu { .. } => CPU_MAX_FACE,
        };
        if let Some(f) = o.face
            && !(8..=max).contains(&f)
        {
            return Err(Error::invalid(
                "face",
                format!("must be 8–{max} on this renderer, got {f}"),
            ));
        }
        // The sampling vectors decide the face size and the faces; for a view they are
        // computed once, not per frame (a warp map is decided on each call).
        let key = match source {
            Source::View(view) => {
                Some(bytemuck::bytes_of(&ProjectionUniform::of(view, w, h)).to_vec())
            }
            Source::Map(_) => None,
        };
        let (face, faces) = match &self.plan {
            Some((k, f, c, decided))
                if key.is_some() && *k == key && *f == o.face && *c == o.cmf =>
            {
                *decided
            }
            _ => {
                let decided = if let (Some(face), false) = (o.face, o.cmf) {
                    (face, [true; 6])
                } else {
                    let from_view;
                    let map = match source {
                        Source::View(view) => {
                            from_view = NormalMap::from_view(view, w, h)?;
                            &from_view
                        }
                        Source::Map(map) => map,
                    };
                    let face = o.face.unwrap_or_else(|| face_size_for(map, max));
                    let faces = if o.cmf {
                        faces_sampled(map, face)
                    } else {
                        [true; 6]
                    };
                    (face, faces)
                };
                self.plan = Some((key, o.face, o.cmf, decided));
                decided
            }
        };
        match &mut self.backend {
            Backend::Gpu {
                gpu,
                warp,
                cube,
                target,
                ..
            } => {
                if target.as_ref().is_none_or(|t| t.size != face) {
                    *target = Some(CubeTexture::target(gpu, face));
                }
                let t = target.as_ref().expect("set above");
                let updated = cube.render(gpu, t, o.eye, faces);
                let img = warp.render(gpu, t, source, (w, h), None, o.blur)?;
                Ok((
                    img,
                    FrameReport {
                        face,
                        faces,
                        cube_updated: updated,
                    },
                ))
            }
            Backend::Cpu {
                caster,
                cached,
                panorama,
            } => {
                // Only the faces the view samples are cast, as the GPU renders only those.
                let centre = panorama.as_ref().map(|p| p.centre.as_vec3().to_array());
                let key = (o.eye.as_vec3().to_array(), face, faces, centre);
                let updated = cached.as_ref().is_none_or(|c| c.0 != key);
                if updated {
                    let cube = match panorama {
                        Some(p) => caster.cube_projected(o.eye, face as usize, faces, p),
                        None => caster.cube(o.eye, face as usize, faces),
                    };
                    *cached = Some((key, cube));
                }
                let cube = &cached.as_ref().expect("set above").1;
                let warp = match source {
                    Source::View(view) => Warp::View(view),
                    Source::Map(map) => Warp::Map(map),
                };
                let mut img =
                    render::render(warp, &Content::cube(cube), w, h, 1, Filter::Bilinear)?;
                if let Some(b) = o.blur {
                    img = radial_blur(&img, b);
                }
                Ok((
                    img,
                    FrameReport {
                        face,
                        faces,
                        cube_updated: updated,
                    },
                ))
            }
        }
    }
}
