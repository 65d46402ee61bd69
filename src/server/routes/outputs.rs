//! Per-channel outputs: the warp map (EXR), the blend mask (16-bit PNG) and a rendered preview
//! (PNG or EXR). The expensive work runs off the async runtime, at most [`WORKERS`] jobs at
//! once (more get 503 with `Retry-After`), is given up when the client goes away, and is cached
//! by a hash of its inputs. Each computed warp map is also written under the data directory
//! (`warps/<id>-<hash>.exr`, by `keep` after the answer) and served from there after a restart.
//! CPU previews are kept ready per channel (`previews::pattern::Previews`).
//!
//! [`WORKERS`]: crate::server::http::state::WORKERS

use crate::content::pattern::Pattern;
use crate::gpu::Renderer;
use crate::image_io::{Compression, Precision, exr_bytes, png_bytes_with};
use crate::render::Filter;
use crate::rig::{BlendOptions, blend_png_bytes};
use crate::scene::ppp::Tolerance;
use crate::server::ApiError;
use crate::server::http::jobs::{etag, inputs, job, job_from, run_job};
use crate::server::http::state::{AppState, Query};
use crate::server::previews::pattern::{Ask, Grid, Look, Made, default_face, finish};
use crate::server::previews::scene::{SceneAsk, SceneMethod};
use crate::server::storage::cache::GpuWarp;
use crate::server::storage::keep::warp_file;
use axum::body::{Body, Bytes};
use axum::extract::{Path, State};
use axum::http::header;
use axum::response::{IntoResponse, Response};
use serde::Deserialize;
use std::sync::Arc;
use std::sync::atomic::Ordering;
use std::time::Instant;

/// Largest preview, pixels.
const MAX_PREVIEW: usize = 4096 * 2304;

/// A large response: its bytes leave in pieces, and the body holds one of the
/// [`STREAMS`](crate::server::http::state::STREAMS) permits until it is sent or dropped, so clients that do not
/// read cannot make the daemon hold more than that many bodies (503 beyond).
pub fn file(
    s: &AppState,
    bytes: Vec<u8>,
    mime: &'static str,
    etag: &str,
) -> Result<Response, ApiError> {
    let permit = s
        .streams
        .clone()
        .try_acquire_owned()
        .map_err(|_| ApiError::Busy)?;
    let len = bytes.len();
    let bytes = Bytes::from(bytes);
    const PIECE: usize = 256 << 10;
    let pieces = futures_util::stream::unfold((0usize, permit), move |(at, permit)| {
        let bytes = bytes.clone();
        async move {
            (at < bytes.len()).then(|| {
                let end = (at + PIECE).min(bytes.len());
                (
                    Ok::<_, std::convert::Infallible>(bytes.slice(at..end)),
                    (end, permit),
                )
            })
        }
    });
    let mut resp = ([(header::CONTENT_TYPE, mime)], Body::from_stream(pieces)).into_response();
    let h = resp.headers_mut();
    h.insert(header::CONTENT_LENGTH, len.into());
    if let Ok(v) = etag.parse() {
        h.insert(header::ETAG, v);
    }
    Ok(resp)
}

pub async fn warp(
    State(s): State<Arc<AppState>>,
    Path(id): Path<String>,
) -> Result<Response, ApiError> {
    // After a restart the kept file answers without recomputing.
    let inputs = inputs(&s, &id).await?;
    if let Some(dir) = &s.store.dir {
        let path = dir.join(warp_file(&id, inputs.key));
        let read = tokio::task::spawn_blocking(move || std::fs::read(path)).await;
        if let Ok(Ok(bytes)) = read {
            let tag = etag(inputs.key, inputs.rig_revision, inputs.tiles_revision);
            return file(&s, bytes, "image/x-exr", &tag);
        }
    }
    let j = job_from(&s, &id, inputs).await?;
    // Encoded once per computed warp (and shared with the copy kept on disk): later requests
    // need no worker.
    let bytes = match j.computed.exr.get() {
        Some(b) => b.clone(),
        None => {
            let (computed, r, t) = (j.computed.clone(), j.rig_revision, j.tiles_revision);
            run_job(&s, move |_| Ok(computed.exr(r, t)?.to_vec())).await?
        }
    };
    file(&s, bytes, "image/x-exr", &j.etag())
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BlendQuery {
    #[serde(default)]
    gamma: Option<f64>,
}

pub async fn blend(
    State(s): State<Arc<AppState>>,
    Path(id): Path<String>,
    Query(q): Query<BlendQuery>,
) -> Result<Response, ApiError> {
    let j = job(&s, &id).await?;
    let ch = j
        .rig
        .channel(&id)
        .map_err(|_| ApiError::NotFound(id.clone()))?;
    let gamma = q.gamma.unwrap_or(2.2);
    let (w, h, computed) = (ch.width, ch.height, j.computed.clone());
    let bytes = run_job(&s, move |_| {
        blend_png_bytes(
            w,
            h,
            &computed.geometry.weights,
            BlendOptions {
                gamma,
                ..BlendOptions::default()
            },
        )
        .map_err(|e| ApiError::Invalid {
            field: "gamma".into(),
            reason: e.reason(),
        })
    })
    .await?;
    file(&s, bytes, "image/png", &j.etag())
}

#[derive(Deserialize, Default)]
#[serde(deny_unknown_fields)]
pub struct RenderQuery {
    /// `png` (8-bit sRGB-ish, blend applied in signal space) or `exr` (linear f32).
    #[serde(default)]
    format: Option<String>,
    /// Output is the channel's size divided by this: 1, 2, 4 or 8.
    #[serde(default)]
    scale: Option<u32>,
    /// nearest, bilinear or bicubic.
    #[serde(default)]
    filter: Option<String>,
    /// The procedural content: smooth or checker.
    #[serde(default)]
    content: Option<String>,
    /// Face size of the content cube map, 8–2048; by default matched to the preview's pixels.
    #[serde(default)]
    face: Option<usize>,
    /// `cpu` (the reference), `gpu` (wgpu; 8-bit, bilinear) or `auto`.
    #[serde(default)]
    renderer: Option<String>,
    /// PNG compression: `fast` (default), `balanced` or `high`.
    #[serde(default)]
    compression: Option<String>,
    /// A procedural 3D scene to show instead of the test pattern (`previews::scene::SCENES`).
    #[serde(default)]
    scene: Option<String>,
    /// How the scene reaches the channel: `cube`, `ppp`, `exact` or `auto`.
    #[serde(default)]
    method: Option<String>,
    /// For `ppp` and `auto`: the largest sampling error allowed (`0.25px`, `0.05deg`).
    #[serde(default)]
    tolerance: Option<String>,
}

impl RenderQuery {
    /// The default preview at `scale`: what a channel showing its content puts out.
    pub(super) fn at_scale(scale: u32) -> RenderQuery {
        RenderQuery {
            scale: Some(scale),
            ..RenderQuery::default()
        }
    }
}

/// A preview of `ow` × `oh` pixels is within [`MAX_PREVIEW`].
fn check_preview_size(ow: usize, oh: usize) -> Result<(), ApiError> {
    if ow * oh > MAX_PREVIEW {
        return Err(invalid(
            "scale",
            format!(
                "{ow}×{oh} is above the preview limit of {MAX_PREVIEW} pixels; use a larger scale"
            ),
        ));
    }
    Ok(())
}

fn invalid(field: &str, reason: impl Into<String>) -> ApiError {
    ApiError::Invalid {
        field: field.into(),
        reason: reason.into(),
    }
}

/// A render request, checked in one step: the test pattern through the warp, or a scene.
enum Checked {
    Pattern(PatternRender),
    Scene(SceneAsk, usize, Compression),
}

/// The test pattern through a channel's warp, as asked for.
struct PatternRender {
    exr: bool,
    /// Output is the channel's size divided by this.
    scale: usize,
    ask: Ask,
    compression: Compression,
    /// The GPU that renders it; the CPU reference when none.
    gpu: Option<Arc<GpuWarp>>,
}

/// The value of the choice named `given`, or a refusal naming `field` and listing the choices.
fn choice<T: Copy>(field: &str, given: &str, choices: &[(&str, T)]) -> Result<T, ApiError> {
    match choices.iter().find(|(name, _)| *name == given) {
        Some((_, value)) => Ok(*value),
        None => {
            let names: Vec<&str> = choices.iter().map(|(n, _)| *n).collect();
            let (last, rest) = names.split_last().expect("choices");
            Err(invalid(
                field,
                format!("must be {} or {last}, got `{given}`", rest.join(", ")),
            ))
        }
    }
}

impl RenderQuery {
    /// Every parameter checked against the others and against this machine (`gpu`, its
    /// adapter if it has one); errors name the parameter.
    fn check(self, gpu: impl Fn() -> Option<Arc<GpuWarp>>) -> Result<Checked, ApiError> {
        let exr = choice(
            "format",
            self.format.as_deref().unwrap_or("png"),
            &[("png", false), ("exr", true)],
        )?;
        let scale = self.scale.unwrap_or(1);
        if ![1, 2, 4, 8].contains(&scale) {
            return Err(invalid(
                "scale",
                format!("must be 1, 2, 4 or 8, got {scale}"),
            ));
        }
        let filter = choice(
            "filter",
            self.filter.as_deref().unwrap_or("bilinear"),
            &[
                ("nearest", Filter::Nearest),
                ("bilinear", Filter::Bilinear),
                ("bicubic", Filter::Bicubic),
            ],
        )?;
        let pattern = choice(
            "content",
            self.content.as_deref().unwrap_or("smooth"),
            &[("smooth", Pattern::Smooth), ("checker", Pattern::Checker)],
        )?;
        if let Some(face) = self.face
            && !(8..=2048).contains(&face)
        {
            return Err(invalid(
                "face",
                format!("must be between 8 and 2048, got {face}"),
            ));
        }
        let compression = match self.compression.as_deref() {
            None => Compression::Fast,
            Some(c) => Compression::parse(c).map_err(|e| invalid("compression", e.reason()))?,
        };
        if let Some(name) = self.scene.as_deref() {
            let ask = self.scene_ask(name, gpu)?;
            return Ok(Checked::Scene(ask, scale as usize, compression));
        }
        for (field, given) in [("method", &self.method), ("tolerance", &self.tolerance)] {
            if given.is_some() {
                return Err(invalid(
                    field,
                    "applies to scene previews (scene=city:small or city:medium); the test pattern is sampled from its cube map",
                ));
            }
        }
        let gpu = match self.renderer.as_deref().unwrap_or("cpu") {
            "cpu" => None,
            r @ ("gpu" | "auto") => {
                let g = gpu();
                if g.is_none() && r == "gpu" {
                    return Err(invalid("renderer", "this machine has no GPU adapter"));
                }
                if g.is_some() && (exr || !matches!(filter, Filter::Bilinear)) {
                    return Err(invalid(
                        "renderer",
                        "the GPU renders 8-bit PNG with the bilinear filter",
                    ));
                }
                g
            }
            other => {
                return Err(invalid(
                    "renderer",
                    format!("must be cpu, gpu or auto, got `{other}`"),
                ));
            }
        };
        Ok(Checked::Pattern(PatternRender {
            exr,
            scale: scale as usize,
            ask: Ask {
                scale: scale as usize,
                pattern,
                face: self.face,
                filter,
            },
            compression,
            gpu,
        }))
    }

    /// The scene preview asked for: the parameters that apply to the test pattern only are
    /// refused, the method's own ones checked.
    fn scene_ask(
        &self,
        name: &str,
        gpu: impl Fn() -> Option<Arc<GpuWarp>>,
    ) -> Result<SceneAsk, ApiError> {
        let scene = SceneAsk::scene(name)?;
        for (field, wrong, reason) in [
            (
                "format",
                self.format.as_deref().is_some_and(|f| f != "png"),
                "scene previews are 8-bit PNG",
            ),
            (
                "filter",
                self.filter.as_deref().is_some_and(|f| f != "bilinear"),
                "scene previews sample their cube map bilinearly",
            ),
            (
                "content",
                self.content.is_some(),
                "a scene preview shows the scene, not the test pattern",
            ),
        ] {
            if wrong {
                return Err(invalid(field, reason));
            }
        }
        let method = SceneMethod::parse(self.method.as_deref().unwrap_or("cube"))?;
        if self.tolerance.is_some() && !matches!(method, SceneMethod::Ppp | SceneMethod::Auto) {
            return Err(invalid(
                "tolerance",
                "chooses the cut of method=ppp or the method of method=auto",
            ));
        }
        if self.face.is_some() && method != SceneMethod::Cube {
            return Err(invalid("face", "the cube's face size, for method=cube"));
        }
        let tolerance = Tolerance::parse(self.tolerance.as_deref().unwrap_or("0.25px"))?;
        let renderer = match self.renderer.as_deref().unwrap_or("cpu") {
            "cpu" => Renderer::Cpu,
            "gpu" if gpu().is_none() => {
                return Err(invalid("renderer", "this machine has no GPU adapter"));
            }
            "gpu" => Renderer::Gpu,
            "auto" if gpu().is_some() => Renderer::Gpu,
            "auto" => Renderer::Cpu,
            other => {
                return Err(invalid(
                    "renderer",
                    format!("must be cpu, gpu or auto, got `{other}`"),
                ));
            }
        };
        Ok(SceneAsk {
            scene,
            method,
            tolerance,
            renderer,
            face: self.face.map(|f| f as u32),
        })
    }
}

pub async fn render(
    State(s): State<Arc<AppState>>,
    Path(id): Path<String>,
    Query(q): Query<RenderQuery>,
) -> Result<Response, ApiError> {
    match q.check(|| s.gpu())? {
        Checked::Pattern(r) => render_pattern(s, id, r).await,
        Checked::Scene(ask, k, compression) => render_scene(s, id, ask, k, compression).await,
    }
}

/// A channel's preview showing the test pattern; CPU PNG previews are kept ready between
/// requests, and say how they were made and where their time went.
async fn render_pattern(
    s: Arc<AppState>,
    id: String,
    r: PatternRender,
) -> Result<Response, ApiError> {
    let PatternRender {
        exr,
        scale: k,
        ask,
        compression,
        gpu,
    } = r;
    let j = job(&s, &id).await?;
    let (w, h) = (j.computed.map.width(), j.computed.map.height());
    let (ow, oh) = (w.div_ceil(k), h.div_ceil(k));
    check_preview_size(ow, oh)?;
    let etag = j.etag();
    let (computed, key, warp_time) = (j.computed.clone(), j.key, j.computed_in);
    let state = s.clone();
    let (bytes, made) = run_job(&s, move |cancel| {
        if !exr && gpu.is_none() {
            // The CPU preview: kept ready between requests, so a repeated one costs a frame
            // and its encoding.
            let t = Instant::now();
            let (prepared, made) =
                state
                    .previews
                    .get(&id, ask, key, &computed, &state.pattern_cubes, cancel)?;
            let ready = t.elapsed();
            let img = prepared.frame()?;
            let framed = t.elapsed();
            let png = png_bytes_with(&img, compression)?;
            // The warp's own time where this request computed it (after an edit), and the
            // rows of a tile screen it drew again.
            let warp = warp_time.map(|d| {
                let desc = match &computed.redrawn {
                    Some(r) => format!(";desc=\"rows {}-{}\"", r.start, r.end),
                    None => String::new(),
                };
                (format!("warp{desc}"), d)
            });
            let timing: Vec<(String, _)> = warp
                .into_iter()
                .chain([
                    ("prepare".to_string(), ready),
                    ("frame".to_string(), framed - ready),
                    ("encode".to_string(), t.elapsed() - framed),
                ])
                .collect();
            return Ok((png, Some((made, timing))));
        }
        let grid = Grid::new(w, h, k);
        let map = grid.map(&computed.map)?;
        let weights = grid.values(&computed.geometry.weights);
        let lift = computed.geometry.lift.as_ref().map(|l| grid.values(l));
        let light = (weights.as_slice(), lift.as_deref());
        let f = computed.f.as_ref().map(|f| grid.values(f));
        if cancel.load(Ordering::Relaxed) {
            return Err(crate::Error::Cancelled.into());
        }
        let look = Look {
            pattern: ask.pattern,
            face: ask.face.unwrap_or_else(|| default_face(&map, exr)),
            filter: ask.filter,
        };
        if exr {
            let cube = look.cube::<[f32; 4]>([true; 6], 1.0);
            let img = look.render(&cube, &map, light, f.as_deref(), 1.0)?;
            return Ok((exr_bytes(&img, &[], Precision::Float)?, None));
        }
        let cube = state.pattern_cubes.get(&look, &map);
        let g = gpu.as_ref().expect("the CPU's PNG previews returned above");
        let img = look.render_gpu(g, &cube.cube, &map, light, f.as_deref())?;
        Ok((png_bytes_with(&img, compression)?, None))
    })
    .await?;
    let mut resp = file(
        &s,
        bytes,
        if exr { "image/x-exr" } else { "image/png" },
        &etag,
    )?;
    if let Some((made, timing)) = made {
        // How the preview was made ready, and where its time went (Server-Timing, which
        // browsers' developer tools show).
        let how = match made {
            Made::Kept => "kept".to_string(),
            Made::Rebuilt(rows) => format!("rows {}-{}", rows.start, rows.end),
            Made::Built => "built".to_string(),
        };
        let timing: Vec<String> = timing
            .iter()
            .map(|(name, d)| format!("{name};dur={:.2}", d.as_secs_f64() * 1e3))
            .collect();
        let h = resp.headers_mut();
        for (name, value) in [
            ("x-omniwarp-preview", how),
            ("server-timing", timing.join(", ")),
        ] {
            if let Ok(v) = value.parse() {
                h.insert(name, v);
            }
        }
    }
    Ok(resp)
}

/// A channel's preview showing a procedural scene, drawn by the method asked for
/// (`previews::scene::ScenePreviews`), with the tiles' f and the blend applied as for the pattern.
async fn render_scene(
    s: Arc<AppState>,
    id: String,
    ask: SceneAsk,
    k: usize,
    compression: Compression,
) -> Result<Response, ApiError> {
    let j = job(&s, &id).await?;
    let (w, h) = (j.computed.map.width(), j.computed.map.height());
    let (ow, oh) = (w.div_ceil(k), h.div_ceil(k));
    check_preview_size(ow, oh)?;
    let etag = j.etag();
    let (computed, key) = (j.computed.clone(), j.key);
    let state = s.clone();
    let (png, said) = run_job(&s, move |cancel| {
        let grid = Grid::new(w, h, k);
        let map = grid.map(&computed.map)?;
        let (mut img, said) = state
            .scene_previews
            .render(&ask, (&id, key, k), &map, cancel)?;
        let weights = grid.values(&computed.geometry.weights);
        let lift = computed.geometry.lift.as_ref().map(|l| grid.values(l));
        let f = computed.f.as_ref().map(|f| grid.values(f));
        finish(&mut img, (&weights, lift.as_deref()), f.as_deref())?;
        Ok((png_bytes_with(&img, compression)?, said))
    })
    .await?;
    let mut resp = file(&s, png, "image/png", &etag)?;
    if let Ok(v) = said.parse() {
        resp.headers_mut().insert("x-omniwarp-method", v);
    }
    Ok(resp)
}
