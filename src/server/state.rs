//! Shared state, persistence and the rig routes.
//!
//! The rig lives in memory as an immutable snapshot (`Arc<Rig>`) with a revision; a write
//! validates the new document, makes it durable (atomic write of `rig.json` under the data
//! directory, the previous good file kept as `rig.prev.json`) and only then swaps the snapshot
//! and answers — an acknowledged edit survives a crash.

use super::ApiError;
use crate::image_io::atomic_write;
use crate::rig::{ChannelWarp, Rig, RigDoc};
use axum::Json;
use axum::body::Bytes;
use axum::extract::State;
use axum::http::{HeaderMap, HeaderValue, StatusCode, header};
use axum::response::sse::{Event, KeepAlive, Sse};
use axum::response::{IntoResponse, Response};
use futures_util::Stream;
use serde::{Deserialize, Serialize};
use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex, RwLock};
use tokio::sync::{Semaphore, broadcast};
use tokio_stream::StreamExt;
use tokio_stream::wrappers::BroadcastStream;

/// Largest request body, bytes.
pub const MAX_BODY: usize = 4 << 20;

/// The persisted form: the rig and its revision.
#[derive(Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct Saved {
    revision: u64,
    rig: RigDoc,
}

/// The current rig and where it is kept.
pub struct Store {
    dir: Option<PathBuf>,
    current: RwLock<(Arc<Rig>, u64)>,
    /// Serialises writers, so revision checks and durability happen in order.
    writing: tokio::sync::Mutex<()>,
}

impl Store {
    /// Loads `rig.json` from `dir` (falling back to `rig.prev.json` if it is corrupt), else
    /// starts from `initial`.
    pub fn open(dir: Option<PathBuf>, initial: Option<RigDoc>) -> crate::Result<Store> {
        let mut loaded = None;
        if let Some(d) = &dir {
            std::fs::create_dir_all(d).map_err(|e| crate::Error::file(d, e))?;
            for name in ["rig.json", "rig.prev.json"] {
                let path = d.join(name);
                if !path.exists() {
                    continue;
                }
                match load(&path) {
                    Ok(found) => {
                        loaded = Some(found);
                        break;
                    }
                    Err(e) => {
                        tracing::error!(file = %path.display(), error = %e, "unreadable rig file; trying the previous good one")
                    }
                }
            }
        }
        let (rig, revision) = match (loaded, initial) {
            (Some(found), _) => found,
            (None, Some(doc)) => (Rig::from_doc(doc)?, 1),
            (None, None) => {
                return Err(crate::Error::invalid(
                    "data",
                    "no rig in the data directory; start with --demo or put a rig.json there",
                ));
            }
        };
        let store = Store {
            dir,
            current: RwLock::new((Arc::new(rig), revision)),
            writing: tokio::sync::Mutex::new(()),
        };
        store.persist()?;
        Ok(store)
    }

    pub fn snapshot(&self) -> (Arc<Rig>, u64) {
        let g = self
            .current
            .read()
            .expect("no writer panics while holding the lock");
        (g.0.clone(), g.1)
    }

    fn persist(&self) -> crate::Result<()> {
        let Some(dir) = &self.dir else { return Ok(()) };
        let (rig, revision) = self.snapshot();
        write_saved(dir, &rig.doc, revision)
    }
}

fn load(path: &Path) -> crate::Result<(Rig, u64)> {
    let text = std::fs::read_to_string(path).map_err(|e| crate::Error::file(path, e))?;
    let saved: Saved = serde_json::from_str(&text).map_err(|e| crate::Error::file(path, e))?;
    let mut doc = saved.rig;
    doc.screen
        .load(path.parent().unwrap_or(Path::new(".")), "/rig/screen")?;
    Ok((Rig::from_doc(doc)?, saved.revision))
}

fn write_saved(dir: &Path, doc: &RigDoc, revision: u64) -> crate::Result<()> {
    let path = dir.join("rig.json");
    if path.exists() {
        let prev = dir.join("rig.prev.json");
        let bytes = std::fs::read(&path).map_err(|e| crate::Error::file(&path, e))?;
        if serde_json::from_slice::<Saved>(&bytes).is_ok() {
            atomic_write(&prev, |f| {
                std::io::Write::write_all(f, &bytes).map_err(|e| crate::Error::file(&prev, e))
            })?;
        }
    }
    let text = serde_json::to_vec_pretty(&Saved {
        revision,
        rig: doc.clone(),
    })
    .expect("rigs serialise");
    atomic_write(&path, |f| {
        std::io::Write::write_all(f, &text).map_err(|e| crate::Error::file(&path, e))
    })
}

pub struct AppState {
    pub store: Store,
    pub token: Option<String>,
    pub events: broadcast::Sender<u64>,
    /// Bounds the renders and warps running at once, so they never starve the API.
    pub workers: Semaphore,
    pub warps: Mutex<HashMap<(String, u64), Arc<ChannelWarp>>>,
}

impl AppState {
    pub fn new(store: Store, token: Option<String>) -> Arc<Self> {
        Arc::new(AppState {
            store,
            token,
            events: broadcast::channel(64).0,
            workers: Semaphore::new(2),
            warps: Mutex::new(HashMap::new()),
        })
    }
}

fn etag(revision: u64) -> HeaderValue {
    HeaderValue::from_str(&format!("\"{revision}\"")).expect("digits are a valid header")
}

pub async fn health() -> Json<serde_json::Value> {
    Json(serde_json::json!({"status": "ok"}))
}

pub async fn version() -> Json<serde_json::Value> {
    Json(serde_json::json!({"name": "omniwarp", "version": env!("CARGO_PKG_VERSION"), "api": "v1"}))
}

pub async fn get_rig(State(s): State<Arc<AppState>>) -> Response {
    let (rig, revision) = s.store.snapshot();
    let mut resp = Json(serde_json::json!({"revision": revision, "rig": rig.doc})).into_response();
    resp.headers_mut().insert(header::ETAG, etag(revision));
    resp
}

fn if_match(headers: &HeaderMap) -> Result<u64, ApiError> {
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
    let _writer = s.store.writing.lock().await;
    let (_, current) = s.store.snapshot();
    if wanted != current {
        return Err(ApiError::Stale { current });
    }
    let revision = current + 1;
    if let Some(dir) = s.store.dir.clone() {
        let doc = rig.doc.clone();
        tokio::task::spawn_blocking(move || write_saved(&dir, &doc, revision))
            .await
            .map_err(|e| ApiError::Internal(e.to_string()))??;
    }
    *s.store
        .current
        .write()
        .expect("no writer panics while holding the lock") = (Arc::new(rig), revision);
    s.warps
        .lock()
        .expect("cache lock")
        .retain(|k, _| k.1 == revision);
    let _ = s.events.send(revision);
    tracing::info!(revision, "rig updated");
    let mut resp = (
        StatusCode::OK,
        Json(serde_json::json!({"revision": revision})),
    )
        .into_response();
    resp.headers_mut().insert(header::ETAG, etag(revision));
    Ok(resp)
}

pub async fn channels(State(s): State<Arc<AppState>>) -> Json<serde_json::Value> {
    let (rig, revision) = s.store.snapshot();
    let list: Vec<_> = rig
        .channels
        .iter()
        .map(|c| serde_json::json!({"id": c.id, "resolution": [c.width, c.height], "lens": c.lens.model().to_string()}))
        .collect();
    Json(serde_json::json!({"revision": revision, "channels": list}))
}

pub async fn events(
    State(s): State<Arc<AppState>>,
) -> Sse<impl Stream<Item = Result<Event, std::convert::Infallible>>> {
    let (_, now) = s.store.snapshot();
    let first = tokio_stream::once(Ok(Event::default().event("revision").data(now.to_string())));
    let rest = BroadcastStream::new(s.events.subscribe())
        .filter_map(|r| r.ok())
        .map(|rev| Ok(Event::default().event("revision").data(rev.to_string())));
    Sse::new(first.chain(rest)).keep_alive(KeepAlive::default())
}
