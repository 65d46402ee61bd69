//! Shared state and the rig routes.
//!
//! The rig lives in memory as an immutable snapshot (`Arc<Rig>`) with a revision; a write
//! validates the new document, makes it durable and only then swaps the snapshot and answers —
//! an acknowledged edit survives a crash.

use super::ApiError;
use super::outputs::{Computed, Geometry};
use super::store::Store;
use crate::rig::Rig;
use axum::Json;
use axum::body::Bytes;
use axum::extract::State;
use axum::http::{HeaderMap, HeaderValue, header};
use axum::response::sse::{Event, KeepAlive, Sse};
use axum::response::{IntoResponse, Response};
use futures_util::Stream;
use serde::de::DeserializeOwned;
use std::collections::HashMap;
use std::path::PathBuf;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use tokio::sync::{Semaphore, broadcast};
use tokio_stream::StreamExt;
use tokio_stream::wrappers::BroadcastStream;

/// Largest request body, bytes.
pub const MAX_BODY: usize = 4 << 20;

/// Renders, warps and calibrations running at once; more get 503 with Retry-After.
pub const WORKERS: usize = 2;

pub struct AppState {
    pub store: Store,
    pub token: Option<String>,
    /// Changes as JSON: `{"kind": "rig"|"content"|"tiles"|"proposal", …}`.
    pub events: broadcast::Sender<String>,
    /// Bounds the expensive work running at once, so it never starves the API.
    pub workers: Semaphore,
    /// Geometric warps and blend weights by (channel, rig revision).
    pub warps: Mutex<HashMap<(String, u64), Arc<Geometry>>>,
    /// Effective warps by (channel, rig revision, tiles revision).
    pub computed: Mutex<HashMap<(String, u64, u64), Arc<Computed>>>,
    pub jobs_done: AtomicU64,
    pub jobs_cancelled: AtomicU64,
    /// The GPU for previews (`?renderer=gpu`), opened on first use.
    pub gpu: std::sync::OnceLock<Option<Arc<super::outputs::GpuWarp>>>,
}

impl AppState {
    pub fn new(store: Store, token: Option<String>) -> Arc<Self> {
        Arc::new(AppState {
            store,
            token,
            events: broadcast::channel(256).0,
            workers: Semaphore::new(WORKERS),
            warps: Mutex::new(HashMap::new()),
            computed: Mutex::new(HashMap::new()),
            jobs_done: AtomicU64::new(0),
            jobs_cancelled: AtomicU64::new(0),
            gpu: std::sync::OnceLock::new(),
        })
    }

    pub fn announce(&self, change: serde_json::Value) {
        // Nobody listening is fine.
        let _ = self.events.send(change.to_string());
    }
}

pub fn etag(revision: u64) -> HeaderValue {
    HeaderValue::from_str(&format!("\"{revision}\"")).expect("digits are a valid header")
}

/// A JSON response with the revision as its ETag.
pub fn tagged(body: serde_json::Value, revision: u64) -> Response {
    let mut resp = Json(body).into_response();
    resp.headers_mut().insert(header::ETAG, etag(revision));
    resp
}

pub async fn health(State(s): State<Arc<AppState>>) -> Json<serde_json::Value> {
    Json(serde_json::json!({
        "status": "ok",
        "workers": {
            "limit": WORKERS,
            "free": s.workers.available_permits(),
            "done": s.jobs_done.load(Ordering::Relaxed),
            "cancelled": s.jobs_cancelled.load(Ordering::Relaxed),
        }
    }))
}

pub async fn version() -> Json<serde_json::Value> {
    Json(serde_json::json!({"name": "omniwarp", "version": env!("CARGO_PKG_VERSION"), "api": "v1"}))
}

pub async fn get_rig(State(s): State<Arc<AppState>>) -> Response {
    let (rig, revision) = s.store.snapshot();
    tagged(
        serde_json::json!({"revision": revision, "rig": rig.doc}),
        revision,
    )
}

/// The revision an edit is based on, from `If-Match`.
pub fn if_match(headers: &HeaderMap) -> Result<u64, ApiError> {
    let v = headers
        .get(header::IF_MATCH)
        .ok_or(ApiError::PreconditionRequired)?;
    v.to_str()
        .ok()
        .map(|s| s.trim().trim_start_matches("W/").trim_matches('"'))
        .and_then(|s| s.parse().ok())
        .ok_or_else(|| ApiError::Invalid {
            field: "If-Match".into(),
            reason: "must be a revision such as \"3\"".into(),
        })
}

/// Parses a JSON body, naming the offending field by JSON pointer; unknown fields are refused
/// by the types themselves.
pub fn parse_body<T: DeserializeOwned>(body: &Bytes) -> Result<T, ApiError> {
    let de = &mut serde_json::Deserializer::from_slice(body);
    serde_path_to_error::deserialize(de).map_err(|e| ApiError::Invalid {
        field: crate::rig::pointer_of(&e.path().to_string()),
        reason: e.into_inner().to_string(),
    })
}

/// Makes `rig` the new revision if `wanted` is still current; durable before it returns.
pub async fn commit_rig(s: &Arc<AppState>, wanted: u64, rig: Rig) -> Result<u64, ApiError> {
    let _writer = s.store.rig_writer.lock().await;
    let (_, current) = s.store.snapshot();
    if wanted != current {
        return Err(ApiError::Stale { current });
    }
    let revision = current + 1;
    let state = s.clone();
    let doc = rig.doc.clone();
    tokio::task::spawn_blocking(move || state.store.save_rig(&doc, revision))
        .await
        .map_err(|e| ApiError::Internal(e.to_string()))??;
    s.store.install(rig, revision);
    s.warps
        .lock()
        .expect("cache lock")
        .retain(|k, _| k.1 == revision);
    s.computed
        .lock()
        .expect("cache lock")
        .retain(|k, _| k.1 == revision);
    s.announce(serde_json::json!({"kind": "rig", "revision": revision}));
    tracing::info!(revision, "rig updated");
    Ok(revision)
}

pub async fn put_rig(
    State(s): State<Arc<AppState>>,
    headers: HeaderMap,
    body: Bytes,
) -> Result<Response, ApiError> {
    let wanted = if_match(&headers)?;
    let text = std::str::from_utf8(&body).map_err(|_| ApiError::Invalid {
        field: "/".into(),
        reason: "the body is not UTF-8".into(),
    })?;
    let base = s.store.dir.clone().unwrap_or_else(|| PathBuf::from("."));
    let rig = Rig::from_json(text, &base)?;
    let revision = commit_rig(&s, wanted, rig).await?;
    Ok(tagged(serde_json::json!({"revision": revision}), revision))
}

pub async fn channels(State(s): State<Arc<AppState>>) -> Response {
    let (rig, revision) = s.store.snapshot();
    let list: Vec<_> = rig
        .channels
        .iter()
        .map(|c| serde_json::json!({"id": c.id, "resolution": [c.width, c.height], "lens": c.lens.model().to_string()}))
        .collect();
    tagged(
        serde_json::json!({"revision": revision, "channels": list}),
        revision,
    )
}

/// The change feed: the rig's revision first, then every change as it is made.
pub async fn events(
    State(s): State<Arc<AppState>>,
) -> Sse<impl Stream<Item = Result<Event, std::convert::Infallible>>> {
    let (_, now) = s.store.snapshot();
    let first = serde_json::json!({"kind": "rig", "revision": now}).to_string();
    let first = tokio_stream::once(Ok(Event::default().event("change").data(first)));
    let rest = BroadcastStream::new(s.events.subscribe())
        .filter_map(|r| r.ok())
        .map(|c| Ok(Event::default().event("change").data(c)));
    Sse::new(first.chain(rest)).keep_alive(KeepAlive::default())
}
