//! Scene previews: a channel's warp showing a procedural 3D scene instead of a test pattern,
//! drawn by the method the request names — the cube map (seed 000), piecewise perspective
//! projection (seed 003) with the pieces cut from the channel's own warp map, or the exact ray
//! cast — or by the cheaper of cube and pieces that meets a tolerance (`method=auto`), as
//! `omniwarp render --scene … --method` does for views.
//!
//! Only the procedural cities are offered: a client names no file on the daemon's disk, and a
//! city's size is bounded. The scene is seen from [`EYE`], the CLI's default eye, in the
//! directions the channel's warp gives.

use crate::error::{Error, Result};
use crate::gpu::Renderer;
use crate::gpu::choose::{Method, choose};
use crate::gpu::frame::{FrameOptions, SceneRenderer};
use crate::gpu::warp::Source;
use crate::normalmap::NormalMap;
use crate::raster::Raster;
use crate::scene::Scene;
use crate::scene::ppp::{Deviation, Pieces, Tolerance};
use glam::DVec3;
use std::sync::Mutex;
use std::sync::atomic::{AtomicBool, Ordering};

/// The scenes a preview may show.
pub const SCENES: [&str; 2] = ["city:small", "city:medium"];

/// Where the scene is seen from (the city's street level).
pub const EYE: DVec3 = DVec3::new(0.0, 1.7, 0.0);

/// How the scene reaches the channel.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum SceneMethod {
    Cube,
    Ppp,
    Exact,
    Auto,
}

impl SceneMethod {
    pub fn parse(text: &str) -> Result<SceneMethod> {
        Ok(match text {
            "cube" => SceneMethod::Cube,
            "ppp" => SceneMethod::Ppp,
            "exact" => SceneMethod::Exact,
            "auto" => SceneMethod::Auto,
            other => {
                return Err(Error::invalid(
                    "method",
                    format!("must be cube, ppp, exact or auto, got `{other}`"),
                ));
            }
        })
    }
}

/// What a scene preview asks for besides the channel's warp.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SceneAsk {
    pub scene: &'static str,
    pub method: SceneMethod,
    /// For `ppp` (the cut) and `auto` (the method and its setting).
    pub tolerance: Tolerance,
    pub renderer: Renderer,
    /// The cube's face size (`cube` only); by default matched to the warp's pixels.
    pub face: Option<u32>,
}

impl SceneAsk {
    /// The scene named by a request, if it is one offered.
    pub fn scene(name: &str) -> Result<&'static str> {
        SCENES.iter().copied().find(|s| *s == name).ok_or_else(|| {
            Error::invalid(
                "scene",
                format!("must be one of {}, got `{name}`", SCENES.join(", ")),
            )
        })
    }
}

/// A cut or a choice made for one warp, kept: both cost more than the frame they serve.
#[derive(Clone)]
enum Decided {
    Pieces(Pieces, Deviation),
    Chosen(Method, f64),
}

/// Which warp (channel, input hash, scale) and ask a decision was made for.
type DecisionKey = (String, u64, usize, &'static str, String);

/// The renderer of the last scene shown (its BVH or GPU buffers), and decisions made for it.
struct Kept {
    scene: &'static str,
    renderer: Renderer,
    r: SceneRenderer,
    decided: Vec<(DecisionKey, Decided)>,
}

/// How many cuts and choices are kept.
const DECIDED: usize = 8;

/// Scene previews' state: one scene's renderer at a time.
#[derive(Default)]
pub struct ScenePreviews(Mutex<Option<Kept>>);

impl ScenePreviews {
    /// Channel `id`'s warp `map` (its input hash `key`, shown at 1/`scale`) showing the scene;
    /// with what was drawn, said in ASCII for a header.
    pub fn render(
        &self,
        ask: &SceneAsk,
        (id, key, scale): (&str, u64, usize),
        map: &NormalMap,
        cancel: &AtomicBool,
    ) -> Result<(Raster<[u8; 4]>, String)> {
        let stop = || {
            if cancel.load(Ordering::Relaxed) {
                Err(Error::Cancelled)
            } else {
                Ok(())
            }
        };
        // One scene at a time: a second request waits here, in its worker, not on the runtime.
        let mut slot = self.0.lock().unwrap_or_else(|e| e.into_inner());
        if slot
            .as_ref()
            .is_none_or(|k| k.scene != ask.scene || k.renderer != ask.renderer)
        {
            *slot = None;
            let r = SceneRenderer::new(Scene::load(ask.scene)?, ask.renderer, None)?;
            *slot = Some(Kept {
                scene: ask.scene,
                renderer: ask.renderer,
                r,
                decided: Vec::new(),
            });
        }
        let kept = slot.as_mut().expect("set above");
        stop()?;
        let o = FrameOptions {
            size: (map.width() as u32, map.height() as u32),
            face: ask.face,
            cmf: true,
            blur: None,
            eye: EYE,
        };
        let (img, said) = match ask.method {
            SceneMethod::Cube => cube_frame(&mut kept.r, map, &o, ask.face)?,
            SceneMethod::Exact => (kept.r.frame_exact_map(map, &o)?, "exact".to_string()),
            SceneMethod::Ppp | SceneMethod::Auto => {
                let decided = kept.decide(ask, (id, key, scale), map, &o)?;
                stop()?;
                match decided {
                    Decided::Pieces(p, d) => {
                        let (img, said) = ppp_frame(&mut kept.r, &p, &o)?;
                        let error = format!("{:.4} deg ({:.3} px)", d.angle.to_degrees(), d.pixels);
                        (img, format!("{said}, max error {error}"))
                    }
                    Decided::Chosen(method, angle) => {
                        let (img, said) = match &method {
                            Method::Cube { face } => cube_frame(&mut kept.r, map, &o, Some(*face))?,
                            Method::Ppp(p) => ppp_frame(&mut kept.r, p, &o)?,
                        };
                        let error = format!("{:.4} deg", angle.to_degrees());
                        (img, format!("auto: {said}, max error {error}"))
                    }
                }
            }
        };
        // The exact reference is a CPU ray cast whatever the renderer.
        let on = if kept.r.on_gpu() && ask.method != SceneMethod::Exact {
            "gpu"
        } else {
            "cpu"
        };
        Ok((img, format!("{said}; {on}")))
    }
}

impl Kept {
    /// The cut (`ppp`) or the method and setting (`auto`) for this warp and ask: kept from an
    /// earlier request, else decided now.
    fn decide(
        &mut self,
        ask: &SceneAsk,
        (id, key, scale): (&str, u64, usize),
        map: &NormalMap,
        o: &FrameOptions,
    ) -> Result<Decided> {
        let which = if ask.method == SceneMethod::Ppp {
            "ppp"
        } else {
            "auto"
        };
        let dkey: DecisionKey = (
            id.to_string(),
            key,
            scale,
            which,
            format!("{:?}", ask.tolerance),
        );
        if let Some((_, d)) = self.decided.iter().find(|(k, _)| *k == dkey) {
            return Ok(d.clone());
        }
        let d = if ask.method == SceneMethod::Ppp {
            let (p, d) = Pieces::for_tolerance_on(map, ask.tolerance)?;
            Decided::Pieces(p, d)
        } else {
            let max_face = if self.r.on_gpu() { 4096 } else { 2048 };
            let c =
                choose(&mut self.r, Source::Map(map), o, ask.tolerance, max_face)?.swap_remove(0);
            Decided::Chosen(c.method, c.angle)
        };
        self.decided.push((dkey, d.clone()));
        let excess = self.decided.len().saturating_sub(DECIDED);
        self.decided.drain(..excess);
        Ok(d)
    }
}

fn ppp_frame(
    r: &mut SceneRenderer,
    p: &Pieces,
    o: &FrameOptions,
) -> Result<(Raster<[u8; 4]>, String)> {
    let (img, report) = r.frame_ppp(p, o)?;
    let replication = report
        .replication
        .map_or(String::new(), |f| format!(", replication {f:.2}"));
    let said = format!(
        "ppp {}x{} cells ({} pieces{replication})",
        p.cols, p.rows, report.pieces
    );
    Ok((img, said))
}

fn cube_frame(
    r: &mut SceneRenderer,
    map: &NormalMap,
    o: &FrameOptions,
    face: Option<u32>,
) -> Result<(Raster<[u8; 4]>, String)> {
    let o = FrameOptions { face, ..*o };
    let (img, report) = r.frame_map(map, &o)?;
    Ok((img, format!("cube {}", report.face)))
}
