//! Per-channel outputs: the warp map (EXR), the blend mask (16-bit PNG) and a rendered preview
//! (PNG) of procedural content. Warps are computed off the async runtime, at most two at a time,
//! and cached by (channel, revision).

use super::{ApiError, AppState};
use crate::content::Content;
use crate::content::pattern::Pattern;
use crate::cubemap::CubeMap;
use crate::image_io::{Precision, exr_bytes, png_bytes};
use crate::raster::Pixel;
use crate::render::{self, Filter, Warp};
use crate::rig::{BlendOptions, ChannelWarp, Rig, blend_png_bytes};
use axum::extract::{Path, Query, State};
use axum::http::header;
use axum::response::{IntoResponse, Response};
use serde::Deserialize;
use std::sync::Arc;

/// Largest preview, pixels.
const MAX_PREVIEW: u32 = 4096 * 2304;

async fn channel_warp(
    s: &Arc<AppState>,
    id: &str,
) -> Result<(Arc<Rig>, u64, Arc<ChannelWarp>), ApiError> {
    let (rig, revision) = s.store.snapshot();
    if rig.channel(id).is_err() {
        return Err(ApiError::NotFound(format!("no channel `{id}`")));
    }
    let key = (id.to_string(), revision);
    if let Some(w) = s.warps.lock().expect("cache lock").get(&key) {
        return Ok((rig, revision, w.clone()));
    }
    let _permit = s.workers.try_acquire().map_err(|_| ApiError::Busy)?;
    let (r, id2) = (rig.clone(), id.to_string());
    let w = tokio::task::spawn_blocking(move || {
        let ch = r.channel(&id2).expect("checked above");
        Arc::new(r.warp(ch))
    })
    .await
    .map_err(|e| ApiError::Internal(e.to_string()))?;
    s.warps.lock().expect("cache lock").insert(key, w.clone());
    Ok((rig, revision, w))
}

fn file(bytes: Vec<u8>, mime: &'static str, revision: u64) -> Response {
    let mut resp = ([(header::CONTENT_TYPE, mime)], bytes).into_response();
    if let Ok(v) = format!("\"{revision}\"").parse() {
        resp.headers_mut().insert(header::ETAG, v);
    }
    resp
}

pub async fn warp(
    State(s): State<Arc<AppState>>,
    Path(id): Path<String>,
) -> Result<Response, ApiError> {
    let (_, revision, w) = channel_warp(&s, &id).await?;
    let mut attrs = w.map.attributes.clone();
    attrs.push(("omniwarp.rig_revision".into(), revision.to_string()));
    let bytes = exr_bytes(w.map.pixels(), &attrs, Precision::Float)?;
    Ok(file(bytes, "image/x-exr", revision))
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
    let (rig, revision, w) = channel_warp(&s, &id).await?;
    let gamma = q.gamma.unwrap_or(2.2);
    let (r2, w2, id2) = (rig.clone(), w.clone(), id.clone());
    let weights = tokio::task::spawn_blocking(move || {
        r2.blend_weights(r2.channel(&id2).expect("exists"), &w2.points)
    })
    .await
    .map_err(|e| ApiError::Internal(e.to_string()))?;
    let ch = rig
        .channel(&id)
        .map_err(|_| ApiError::NotFound(id.clone()))?;
    let bytes = blend_png_bytes(ch.width, ch.height, &weights, BlendOptions { gamma })?;
    Ok(file(bytes, "image/png", revision))
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RenderQuery {
    /// Face size of the procedural cube map.
    #[serde(default)]
    face: Option<usize>,
}

pub async fn render(
    State(s): State<Arc<AppState>>,
    Path(id): Path<String>,
    Query(q): Query<RenderQuery>,
) -> Result<Response, ApiError> {
    let face = q.face.unwrap_or(256);
    if !(8..=2048).contains(&face) {
        return Err(ApiError::Invalid {
            field: "face".into(),
            reason: format!("must be between 8 and 2048, got {face}"),
        });
    }
    let (rig, revision, w) = channel_warp(&s, &id).await?;
    let ch = rig
        .channel(&id)
        .map_err(|_| ApiError::NotFound(id.clone()))?
        .clone();
    if ch.width * ch.height > MAX_PREVIEW {
        return Err(ApiError::Invalid {
            field: "id".into(),
            reason: "the channel is too large to preview".into(),
        });
    }
    let _permit = s.workers.try_acquire().map_err(|_| ApiError::Busy)?;
    let bytes = tokio::task::spawn_blocking(move || -> crate::Result<Vec<u8>> {
        let cube = CubeMap::<[u8; 4]>::from_fn(face, 1, |d| {
            <[u8; 4]>::from_f32(Pattern::Smooth.eval(d).map(|c| c * 255.0))
        });
        let content = Content::cube(&cube);
        let mut img = render::render(
            Warp::Map(&w.map),
            &content,
            ch.width,
            ch.height,
            1,
            Filter::Bilinear,
        )?;
        let weights = rig.blend_weights(&ch, &w.points);
        for (p, &k) in img.data.iter_mut().zip(&weights) {
            let m = f64::from(k).powf(1.0 / 2.2) as f32;
            let v = p.to_f32();
            *p = <[u8; 4]>::from_f32([v[0] * m, v[1] * m, v[2] * m, v[3]]);
        }
        png_bytes(&img)
    })
    .await
    .map_err(|e| ApiError::Internal(e.to_string()))??;
    Ok(file(bytes, "image/png", revision))
}
