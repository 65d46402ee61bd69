//! Per-channel outputs: the warp map (EXR), the blend mask (16-bit PNG) and a rendered preview
//! (PNG or EXR). The expensive work runs off the async runtime, at most [`WORKERS`] jobs at
//! once (more get 503 with `Retry-After`), is given up when the client goes away, and is cached
//! by a hash of its inputs. Each computed warp map is also written under the data directory
//! (`warps/<id>-<hash>.exr`) and served from there after a restart.
//!
//! [`WORKERS`]: super::state::WORKERS

use super::ApiError;
use super::jobs::{etag, inputs, job, job_from, run_job, warp_file};
use super::preview::Look;
use super::state::{AppState, Query};
use crate::content::pattern::Pattern;
use crate::image_io::{Precision, exr_bytes, png_bytes};
use crate::normalmap::NormalMap;
use crate::raster::Raster;
use crate::render::Filter;
use crate::render::coverage::face_size_for;
use crate::rig::{BlendOptions, blend_png_bytes};
use axum::body::{Body, Bytes};
use axum::extract::{Path, State};
use axum::http::header;
use axum::response::{IntoResponse, Response};
use serde::Deserialize;
use std::sync::Arc;
use std::sync::atomic::Ordering;

/// Largest preview, pixels.
const MAX_PREVIEW: usize = 4096 * 2304;

/// A large response: its bytes leave in pieces, and the body holds one of the
/// [`STREAMS`](super::state::STREAMS) permits until it is sent or dropped, so clients that do not
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
    let mut attrs = j.computed.map.attributes.clone();
    attrs.push(("omniwarp.rig_revision".into(), j.rig_revision.to_string()));
    attrs.push((
        "omniwarp.tiles_revision".into(),
        j.tiles_revision.to_string(),
    ));
    let computed = j.computed.clone();
    let bytes = run_job(&s, move |_| {
        Ok(exr_bytes(computed.map.pixels(), &attrs, Precision::Float)?)
    })
    .await?;
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
    /// Face size of the content cube map, 8–2048; by default matched to the preview's pixels.
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
    if let Some(face) = q.face
        && !(8..=2048).contains(&face)
    {
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
    let state = s.clone();
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
        let map = NormalMap::from_pixels(sub, vec![])?;
        let weights: Vec<f32> = (0..ow * oh)
            .map(|n| computed.geometry.weights[pick(n % ow, n / ow)])
            .collect();
        let f: Option<Vec<f32>> = computed
            .f
            .as_ref()
            .map(|f| (0..ow * oh).map(|n| f[pick(n % ow, n / ow)]).collect());
        if cancel.load(Ordering::Relaxed) {
            return Err(crate::Error::Cancelled.into());
        }
        // By default the cube's texels are as fine as the preview's finest pixels, so the
        // pattern's edges show the warp, not the cube's stair steps; 32-bit previews stop at
        // 1024 (six such faces are 100 MB, as six 8-bit faces of 2048 are).
        let face = q
            .face
            .unwrap_or_else(|| face_size_for(&map, if exr { 1024 } else { 2048 }) as usize);
        let look = Look {
            pattern,
            face,
            filter,
        };
        if exr {
            let cube = look.cube::<[f32; 4]>([true; 6], 1.0);
            let img = look.render(&cube, &map, &weights, f.as_deref(), 1.0)?;
            return Ok(exr_bytes(&img, &[], Precision::Float)?);
        }
        let cube = state.pattern_cubes.get(&look, &map);
        let img = match &gpu {
            Some(g) => look.render_gpu(g, &cube, &map, &weights, f.as_deref())?,
            None => look.render(&cube, &map, &weights, f.as_deref(), 2.2)?,
        };
        let encoded = png_bytes(&img);
        Ok(encoded?)
    })
    .await?;
    file(
        &s,
        bytes,
        if exr { "image/x-exr" } else { "image/png" },
        &etag,
    )
}
