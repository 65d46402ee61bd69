//! The daemon's shared state, and the helpers every route uses for revisions and bodies.
//!
//! The rig lives in memory as an immutable snapshot (`Arc<Rig>`) with a revision; a write
//! validates the new document, makes it durable and only then swaps the snapshot and answers —
//! an acknowledged edit survives a crash.

use super::ApiError;
use super::cache::{Computed, Geometry, GpuWarp};
use super::store::Store;
use axum::Json;
use axum::body::Bytes;
use axum::http::{HeaderMap, HeaderValue, header};
use axum::response::{IntoResponse, Response};
use serde::de::DeserializeOwned;
use std::collections::HashMap;
use std::sync::atomic::AtomicU64;
use std::sync::{Arc, Mutex};
use tokio::sync::{Semaphore, broadcast};

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
    pub gpu: std::sync::OnceLock<Option<Arc<GpuWarp>>>,
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

    /// The GPU for previews, opened on first use.
    pub fn gpu(&self) -> Option<Arc<GpuWarp>> {
        self.gpu.get_or_init(GpuWarp::open).clone()
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
