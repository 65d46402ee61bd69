//! Per-channel outputs: the warp map (EXR), the blend mask (16-bit PNG) and a rendered preview
//! (PNG or EXR). The expensive work runs off the async runtime, at most [`WORKERS`] jobs at
//! once (more get 503 with `Retry-After`), is given up when the client goes away, and is cached
//! by (channel, rig revision, tiles revision). Each computed warp map is also written under the
//! data directory (`warps/<id>-r<rig>-t<tiles>.exr`) and served from there after a restart.
//!
//! [`WORKERS`]: super::state::WORKERS

use super::ApiError;
use super::state::AppState;
use super::store::Canvas;
use crate::content::Content;
use crate::content::pattern::Pattern;
use crate::cubemap::CubeMap;
use crate::image_io::{Precision, atomic_write, exr_bytes, png_bytes};
use crate::normalmap::NormalMap;
use crate::raster::{Pixel, Raster};
use crate::render::{self, Filter, Warp};
use crate::rig::{BlendOptions, ChannelWarp, Rig, blend_png_bytes};
use axum::extract::{Path, Query, State};
use axum::http::header;
use axum::response::{IntoResponse, Response};
use serde::Deserialize;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

/// Largest preview, pixels.
const MAX_PREVIEW: usize = 4096 * 2304;

/// What depends on the rig alone: the geometric warp and the blend weights (tile edits change
/// which content a pixel shows, not where its light lands).
pub struct Geometry {
    pub warp: ChannelWarp,
    pub weights: Vec<f32>,
}

/// A channel's warp as it is shown: the geometry, the effective sampling map (the tile
/// screen's where one is set) and the tiles' f per pixel.
pub struct Computed {
    pub geometry: Arc<Geometry>,
    pub map: NormalMap,
    pub f: Option<Vec<f32>>,
}

/// What a job worked from.
pub struct Job {
    pub rig: Arc<Rig>,
    pub rig_revision: u64,
    pub tiles_revision: u64,
    pub canvas: Canvas,
    pub computed: Arc<Computed>,
}

impl Job {
    /// `"<rig>.<tiles>"`: changes whenever the output can.
    pub fn etag(&self) -> String {
        format!("\"{}.{}\"", self.rig_revision, self.tiles_revision)
    }
}

/// Sets the flag when dropped: a handler future dropped because its client went away stops
/// the blocking work it started.
struct CancelOnDrop(Arc<AtomicBool>);

impl Drop for CancelOnDrop {
    fn drop(&mut self) {
        self.0.store(true, Ordering::Relaxed);
    }
}

/// Runs `work` on the blocking pool under a worker permit; `None` from `work` means cancelled.
pub async fn run_job<T: Send + 'static>(
    s: &Arc<AppState>,
    work: impl FnOnce(&AtomicBool) -> Option<T> + Send + 'static,
) -> Result<T, ApiError> {
    let _permit = s.workers.try_acquire().map_err(|_| ApiError::Busy)?;
    let flag = Arc::new(AtomicBool::new(false));
    let _guard = CancelOnDrop(flag.clone());
    let state = s.clone();
    tokio::task::spawn_blocking(move || {
        let out = work(&flag);
        let counter = if out.is_some() {
            &state.jobs_done
        } else {
            &state.jobs_cancelled
        };
        counter.fetch_add(1, Ordering::Relaxed);
        out
    })
    .await
    .map_err(|e| ApiError::Internal(e.to_string()))?
    .ok_or_else(|| ApiError::Internal("cancelled".into()))
}

fn warp_file(id: &str, rig_revision: u64, tiles_revision: u64) -> String {
    format!("warps/{id}-r{rig_revision}-t{tiles_revision}.exr")
}

/// The channel's current state and its computed warp (from the cache, or computed now).
pub async fn job(s: &Arc<AppState>, id: &str) -> Result<Job, ApiError> {
    let (rig, rig_revision) = s.store.snapshot();
    let data = s
        .store
        .channel(id)
        .ok_or_else(|| ApiError::NotFound(format!("no channel `{id}`")))?;
    let (tiles, tiles_revision, canvas) = {
        let g = data.lock().await;
        (
            g.tiles.value.clone(),
            g.tiles.revision,
            g.content.value.clone(),
        )
    };
    let key = (id.to_string(), rig_revision, tiles_revision);
    if let Some(c) = s.computed.lock().expect("cache lock").get(&key) {
        return Ok(Job {
            rig,
            rig_revision,
            tiles_revision,
            canvas,
            computed: c.clone(),
        });
    }
    let geometry = s
        .warps
        .lock()
        .expect("cache lock")
        .get(&(id.to_string(), rig_revision))
        .cloned();
    let (r, id2, state) = (rig.clone(), id.to_string(), s.clone());
    let computed = run_job(s, move |cancel| {
        let ch = r.channel(&id2).ok()?;
        let geometry = match geometry {
            Some(g) => g,
            None => {
                let warp = r.warp_unless(ch, cancel)?;
                let weights = r.blend_weights(ch, &warp.points);
                Arc::new(Geometry { warp, weights })
            }
        };
        state
            .warps
            .lock()
            .expect("cache lock")
            .insert((id2.clone(), rig_revision), geometry.clone());
        let (map, f) = match &tiles {
            Some(t) => {
                let fm = t.feature_map(ch.width as usize, ch.height as usize);
                (fm.normal_map(), Some(fm.f()))
            }
            None => (geometry.warp.map.clone(), None),
        };
        if cancel.load(Ordering::Relaxed) {
            return None;
        }
        if let Some(dir) = &state.store.dir {
            let path = dir.join(warp_file(&id2, rig_revision, tiles_revision));
            let mut attrs = map.attributes.clone();
            attrs.push(("omniwarp.rig_revision".into(), rig_revision.to_string()));
            attrs.push(("omniwarp.tiles_revision".into(), tiles_revision.to_string()));
            let written = std::fs::create_dir_all(dir.join("warps"))
                .map_err(|e| crate::Error::file(dir, e))
                .and_then(|_| exr_bytes(map.pixels(), &attrs, Precision::Float))
                .and_then(|bytes| {
                    atomic_write(&path, |f| {
                        std::io::Write::write_all(f, &bytes)
                            .map_err(|e| crate::Error::file(&path, e))
                    })
                });
            match written {
                Ok(()) => remove_older_warps(dir, &id2, &path),
                Err(e) => tracing::error!(error = %e, "could not keep the warp map"),
            }
        }
        Some(Arc::new(Computed { geometry, map, f }))
    })
    .await?;
    s.computed
        .lock()
        .expect("cache lock")
        .insert(key, computed.clone());
    Ok(Job {
        rig,
        rig_revision,
        tiles_revision,
        canvas,
        computed,
    })
}

fn remove_older_warps(dir: &std::path::Path, id: &str, keep: &std::path::Path) {
    let Ok(entries) = std::fs::read_dir(dir.join("warps")) else {
        return;
    };
    let prefix = format!("{id}-r");
    for e in entries.flatten() {
        let p = e.path();
        let name = e.file_name().to_string_lossy().into_owned();
        if p != keep && name.starts_with(&prefix) && name.ends_with(".exr") {
            let _ = std::fs::remove_file(p);
        }
    }
}

pub fn file(bytes: Vec<u8>, mime: &'static str, etag: &str) -> Response {
    let mut resp = ([(header::CONTENT_TYPE, mime)], bytes).into_response();
    if let Ok(v) = etag.parse() {
        resp.headers_mut().insert(header::ETAG, v);
    }
    resp
}

pub async fn warp(
    State(s): State<Arc<AppState>>,
    Path(id): Path<String>,
) -> Result<Response, ApiError> {
    // After a restart the kept file answers without recomputing.
    let (_, rig_revision) = s.store.snapshot();
    if let (Some(dir), Some(data)) = (&s.store.dir, s.store.channel(&id)) {
        let tiles_revision = data.lock().await.tiles.revision;
        let path = dir.join(warp_file(&id, rig_revision, tiles_revision));
        let read = tokio::task::spawn_blocking(move || std::fs::read(path)).await;
        if let Ok(Ok(bytes)) = read {
            return Ok(file(
                bytes,
                "image/x-exr",
                &format!("\"{rig_revision}.{tiles_revision}\""),
            ));
        }
    }
    let j = job(&s, &id).await?;
    let mut attrs = j.computed.map.attributes.clone();
    attrs.push(("omniwarp.rig_revision".into(), j.rig_revision.to_string()));
    attrs.push((
        "omniwarp.tiles_revision".into(),
        j.tiles_revision.to_string(),
    ));
    let bytes = exr_bytes(j.computed.map.pixels(), &attrs, Precision::Float)?;
    Ok(file(bytes, "image/x-exr", &j.etag()))
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
    let bytes = blend_png_bytes(
        ch.width,
        ch.height,
        &j.computed.geometry.weights,
        BlendOptions { gamma },
    )
    .map_err(|e| ApiError::Invalid {
        field: "gamma".into(),
        reason: e.reason(),
    })?;
    Ok(file(bytes, "image/png", &j.etag()))
}

#[derive(Deserialize)]
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
    /// Face size of the content cube map, 8–2048.
    #[serde(default)]
    face: Option<usize>,
    /// `cpu` (the reference), `gpu` (wgpu; 8-bit, bilinear) or `auto`.
    #[serde(default)]
    renderer: Option<String>,
}

fn invalid(field: &str, reason: impl Into<String>) -> ApiError {
    ApiError::Invalid {
        field: field.into(),
        reason: reason.into(),
    }
}

pub async fn render(
    State(s): State<Arc<AppState>>,
    Path(id): Path<String>,
    Query(q): Query<RenderQuery>,
) -> Result<Response, ApiError> {
    let exr = match q.format.as_deref().unwrap_or("png") {
        "png" => false,
        "exr" => true,
        other => {
            return Err(invalid(
                "format",
                format!("must be png or exr, got `{other}`"),
            ));
        }
    };
    let scale = q.scale.unwrap_or(1);
    if ![1, 2, 4, 8].contains(&scale) {
        return Err(invalid(
            "scale",
            format!("must be 1, 2, 4 or 8, got {scale}"),
        ));
    }
    let filter = match q.filter.as_deref().unwrap_or("bilinear") {
        "nearest" => Filter::Nearest,
        "bilinear" => Filter::Bilinear,
        "bicubic" => Filter::Bicubic,
        other => {
            return Err(invalid(
                "filter",
                format!("must be nearest, bilinear or bicubic, got `{other}`"),
            ));
        }
    };
    let pattern = match q.content.as_deref().unwrap_or("smooth") {
        "smooth" => Pattern::Smooth,
        "checker" => Pattern::Checker,
        other => {
            return Err(invalid(
                "content",
                format!("must be smooth or checker, got `{other}`"),
            ));
        }
    };
    let face = q.face.unwrap_or(256);
    if !(8..=2048).contains(&face) {
        return Err(invalid(
            "face",
            format!("must be between 8 and 2048, got {face}"),
        ));
    }
    let gpu = match q.renderer.as_deref().unwrap_or("cpu") {
        "cpu" => None,
        r @ ("gpu" | "auto") => {
            let g = s.gpu();
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
    let j = job(&s, &id).await?;
    let (w, h) = (j.computed.map.width(), j.computed.map.height());
    let k = scale as usize;
    let (ow, oh) = (w.div_ceil(k), h.div_ceil(k));
    if ow * oh > MAX_PREVIEW {
        return Err(invalid(
            "scale",
            format!(
                "{ow}×{oh} is above the preview limit of {MAX_PREVIEW} pixels; use a larger scale"
            ),
        ));
    }
    let etag = j.etag();
    let computed = j.computed.clone();
    let bytes = run_job(&s, move |cancel| {
        // Every k-th pixel of the warp, its centre pixel per k×k block.
        let pick =
            |i: usize, jj: usize| ((jj * k + k / 2).min(h - 1)) * w + (i * k + k / 2).min(w - 1);
        let src = computed.map.pixels();
        let sub = Raster {
            width: ow,
            height: oh,
            data: (0..ow * oh)
                .map(|n| src.data[pick(n % ow, n / ow)])
                .collect(),
        };
        let map = NormalMap::from_pixels(sub, vec![]).ok()?;
        let weights: Vec<f32> = (0..ow * oh)
            .map(|n| computed.geometry.weights[pick(n % ow, n / ow)])
            .collect();
        let f: Option<Vec<f32>> = computed
            .f
            .as_ref()
            .map(|f| (0..ow * oh).map(|n| f[pick(n % ow, n / ow)]).collect());
        if cancel.load(Ordering::Relaxed) {
            return None;
        }
        let look = Look {
            pattern,
            face,
            filter,
        };
        if let Some(g) = &gpu {
            return Some(
                look.render_gpu(g, &map, &weights, f.as_deref())
                    .and_then(|img| png_bytes(&img)),
            );
        }
        let encoded = if exr {
            let img = look.render::<[f32; 4]>(&map, &weights, f.as_deref(), 1.0, 1.0)?;
            exr_bytes(&img, &[], Precision::Float)
        } else {
            let img = look.render::<[u8; 4]>(&map, &weights, f.as_deref(), 2.2, 255.0)?;
            png_bytes(&img)
        };
        Some(encoded)
    })
    .await?
    .map_err(ApiError::from)?;
    Ok(file(
        bytes,
        if exr { "image/x-exr" } else { "image/png" },
        &etag,
    ))
}

/// Multiplies colour by the blend weight raised to 1/γ (γ = 1: linear output).
fn attenuate<T: Pixel>(img: &mut Raster<T>, weights: &[f32], gamma: f64) {
    for (p, &k) in img.data.iter_mut().zip(weights) {
        let m = f64::from(k).powf(1.0 / gamma) as f32;
        let v = p.to_f32();
        *p = T::from_f32([v[0] * m, v[1] * m, v[2] * m, v[3]]);
    }
}

/// The daemon's GPU, if the machine has an adapter: created on first use.
pub struct GpuWarp {
    pub gpu: crate::gpu::Gpu,
    pub pass: crate::gpu::warp::WarpPass,
}

impl AppState {
    pub fn gpu(&self) -> Option<Arc<GpuWarp>> {
        self.gpu
            .get_or_init(|| match crate::gpu::Gpu::new(None) {
                Ok(Some(gpu)) => {
                    tracing::info!(adapter = %gpu.describe(), "GPU renderer ready");
                    let pass = crate::gpu::warp::WarpPass::new(&gpu);
                    Some(Arc::new(GpuWarp { gpu, pass }))
                }
                Ok(None) => {
                    tracing::warn!("no GPU adapter: previews render on the CPU");
                    None
                }
                Err(e) => {
                    tracing::warn!(error = %e, "GPU unusable: previews render on the CPU");
                    None
                }
            })
            .clone()
    }
}

/// What a preview shows and how it samples it.
struct Look {
    pattern: Pattern,
    face: usize,
    filter: Filter,
}

impl Look {
    /// The procedural content through `map`, desaturated by the tiles' f and attenuated by the
    /// blend weights (raised to 1/γ: PNG previews are in signal space, EXR linear); `full` is
    /// the pixel type's white.
    fn render<T: Pixel>(
        &self,
        map: &NormalMap,
        weights: &[f32],
        f: Option<&[f32]>,
        gamma: f64,
        full: f32,
    ) -> Option<Raster<T>> {
        let cube = CubeMap::<T>::from_fn(self.face, 1, |d| {
            T::from_f32(self.pattern.eval(d).map(|c| c * full))
        });
        let content = Content::cube(&cube);
        let (w, h) = (map.width() as u32, map.height() as u32);
        let mut img = render::render(Warp::Map(map), &content, w, h, 1, self.filter).ok()?;
        if let Some(f) = f {
            crate::tiles::raster::saturation(&mut img, f);
        }
        attenuate(&mut img, weights, gamma);
        Some(img)
    }

    /// [`Look::render`] of 8-bit PNG previews with the warp on the GPU.
    fn render_gpu(
        &self,
        g: &GpuWarp,
        map: &NormalMap,
        weights: &[f32],
        f: Option<&[f32]>,
    ) -> crate::Result<Raster<[u8; 4]>> {
        let cube = CubeMap::<[u8; 4]>::from_fn(self.face, 1, |d| {
            <[u8; 4]>::from_f32(self.pattern.eval(d).map(|c| c * 255.0))
        });
        let tex = crate::gpu::warp::CubeTexture::upload(&g.gpu, &cube);
        let size = (map.width() as u32, map.height() as u32);
        let source = crate::gpu::warp::Source::Map(map);
        let mut img = g.pass.render(&g.gpu, &tex, source, size, f, None)?;
        attenuate(&mut img, weights, 2.2);
        Ok(img)
    }
}
