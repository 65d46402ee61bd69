//! The daemon's shared state, and the helpers every route uses for revisions and bodies.
//!
//! The rig lives in memory as an immutable snapshot (`Arc<Rig>`) with a revision; a write
//! validates the new document, makes it durable and only then swaps the snapshot and answers —
//! an acknowledged edit survives a crash.

use crate::content::testcard::Card;
use crate::server::ApiError;
use crate::server::storage::cache::{Computed, Geometry, GpuWarp};
use crate::server::storage::db::Meta;
use crate::server::storage::store::Store;
use crate::structured::Grey;
use axum::Json;
use axum::body::Bytes;
use axum::http::{HeaderMap, HeaderValue, header};
use axum::response::{IntoResponse, Response};
use serde::Deserialize;
use serde::de::DeserializeOwned;
use std::collections::HashMap;
use std::net::SocketAddr;
use std::sync::atomic::AtomicU64;
use std::sync::{Arc, Mutex, OnceLock};
use tokio::sync::{Semaphore, broadcast, watch};

/// Largest request body, bytes.
pub const MAX_BODY: usize = 4 << 20;

/// Renders, warps, edits, calibrations and exports running at once; more get 503 with
/// Retry-After.
pub const WORKERS: usize = 2;

/// Large responses (warp maps, exports, previews) being sent at once: each holds its body in
/// memory until the client has read it, so a client that never reads cannot pile them up.
pub const STREAMS: usize = 16;

/// Change feeds open at once; more get 503. At most half the connection cap, so subscribers
/// that never leave cannot take every connection.
pub const FEEDS: usize = 256;

/// How the daemon was started: who may call it and how much it may hold.
#[derive(Debug, Clone)]
pub struct Options {
    /// Every request must carry `Authorization: Bearer <token>` when set.
    pub token: Option<String>,
    /// Bytes the warps of a rig may hold at once (see [`crate::limits::MEMORY_BUDGET`]).
    pub memory_budget: u64,
    /// Host names (beyond loopback names and addresses and the bound address) requests may
    /// name in `Host`.
    pub allow_hosts: Vec<String>,
    /// Origins (`scheme://host[:port]`) beyond the daemon's own that browsers may call it from.
    pub allow_origins: Vec<String>,
    /// Who the history records as making a change: the token's name (its file's name without
    /// the extension) when one is required, `local` otherwise.
    pub user: String,
    /// Connections open at once (see [`crate::server::CONNECTIONS`]); lowered at start to what
    /// the process's file limit allows.
    pub connections: usize,
    /// Serve TLS with this identity (`None`: plain HTTP, loopback's default).
    pub tls: Option<crate::server::tls::Tls>,
    /// The folder render jobs read content from and write `renders/` into (`None`: no jobs).
    pub media: Option<std::path::PathBuf>,
}

impl Default for Options {
    fn default() -> Self {
        Options {
            token: None,
            memory_budget: crate::limits::MEMORY_BUDGET,
            allow_hosts: Vec::new(),
            allow_origins: Vec::new(),
            user: "local".into(),
            connections: crate::server::CONNECTIONS,
            tls: None,
            media: None,
        }
    }
}

/// What every request handler shares: the store, the options the daemon started with, and
/// what is kept computed or in flight.
pub struct AppState {
    /// The rig and the channels' documents, kept durably.
    pub store: Store,
    /// How the daemon was started (token, limits, budget).
    pub options: Options,
    /// The address the server listens on, once it does (the `Host` check allows it).
    pub bound: OnceLock<SocketAddr>,
    /// Changes as JSON: `{"kind": "rig"|"content"|"tiles"|"proposal", …}`.
    pub events: broadcast::Sender<String>,
    /// Flips to true when the server shuts down; event streams end on it.
    pub stopping: watch::Sender<bool>,
    /// Bounds the expensive work running at once, so it never starves the API.
    pub workers: Arc<Semaphore>,
    /// Bounds the large responses in flight (see [`STREAMS`]).
    pub streams: Arc<Semaphore>,
    /// Bounds the change feeds open at once (see [`FEEDS`]).
    pub feeds: Arc<Semaphore>,
    /// Geometric warps and blend weights by channel and a hash of what they are computed from.
    pub warps: Mutex<HashMap<(String, u64), Arc<Geometry>>>,
    /// Effective warps by channel and a hash of the geometry's inputs and the tile screen.
    pub computed: Mutex<HashMap<(String, u64), Arc<Computed>>>,
    /// Heavy jobs finished since start (`/v1/health`).
    pub jobs_done: AtomicU64,
    /// Heavy jobs abandoned because their client went away (`/v1/health`).
    pub jobs_cancelled: AtomicU64,
    /// The GPU for previews (`?renderer=gpu`), opened on first use.
    pub gpu: std::sync::OnceLock<Option<Arc<GpuWarp>>>,
    /// The previews' procedural content, evaluated once per pattern and face size.
    pub pattern_cubes: crate::server::previews::pattern::PatternCubes,
    /// CPU previews ready to render again.
    pub previews: crate::server::previews::pattern::Previews,
    /// Scene previews' renderer and the cuts and choices made for them.
    pub scene_previews: crate::server::previews::scene::ScenePreviews,
    /// Writes computed warps to disk after the requests that computed them.
    pub keeper: crate::server::storage::keep::Keeper,
    /// What each channel shows: its content or a test card.
    pub shows: Shows,
    /// Camera captures uploaded for calibration.
    pub captures: Captures,
    /// Render jobs and the media folder they read from.
    pub renders: crate::server::renders::Renders,
    /// The render nodes following the daemon, as they last reported.
    pub nodes: super::nodes::Nodes,
}

impl AppState {
    /// The state of a daemon serving `store`, with `token` required when given and default
    /// options otherwise.
    pub fn new(store: Store, token: Option<String>) -> Arc<Self> {
        Self::with_options(
            store,
            Options {
                token,
                ..Options::default()
            },
        )
    }

    /// The state of a daemon serving `store` with `options`.
    pub fn with_options(store: Store, options: Options) -> Arc<Self> {
        let feeds = FEEDS.min(options.connections / 2);
        let renders = crate::server::renders::Renders::open(options.media.as_deref());
        Arc::new(AppState {
            store,
            options,
            bound: OnceLock::new(),
            events: broadcast::channel(256).0,
            stopping: watch::channel(false).0,
            workers: Arc::new(Semaphore::new(WORKERS)),
            streams: Arc::new(Semaphore::new(STREAMS)),
            feeds: Arc::new(Semaphore::new(feeds)),
            warps: Mutex::new(HashMap::new()),
            computed: Mutex::new(HashMap::new()),
            jobs_done: AtomicU64::new(0),
            jobs_cancelled: AtomicU64::new(0),
            gpu: std::sync::OnceLock::new(),
            pattern_cubes: Default::default(),
            previews: Default::default(),
            scene_previews: Default::default(),
            keeper: Default::default(),
            shows: Default::default(),
            captures: Default::default(),
            renders,
            nodes: Default::default(),
        })
    }

    /// The GPU for previews, opened on first use.
    pub fn gpu(&self) -> Option<Arc<GpuWarp>> {
        self.gpu.get_or_init(GpuWarp::open).clone()
    }

    /// Sends `change` to every change-feed subscriber (`/v1/events`).
    pub fn announce(&self, change: serde_json::Value) {
        // Nobody listening is fine.
        let _ = self.events.send(change.to_string());
    }
}

/// What a channel shows (see `show.rs`).
#[derive(Debug, Clone, PartialEq, Default)]
pub enum Shown {
    /// Its content.
    #[default]
    Content,
    /// A test card.
    Card(Card),
    /// Frame `frame` of its structured-light sequence, with the sequence's period and code as
    /// `GET …/pattern/{n}` takes them (their defaults when `None`).
    Pattern {
        /// The frame, from 0.
        frame: usize,
        /// The phase period, projector pixels.
        period: Option<u32>,
        /// The code's name.
        code: Option<String>,
    },
}

/// What each channel shows: per channel id, the revision of the choice and the choice.
#[derive(Default)]
pub struct Shows(Mutex<HashMap<String, (u64, Shown)>>);

impl Shows {
    pub fn get(&self, id: &str) -> (u64, Shown) {
        let map = self.0.lock().expect("shows lock");
        map.get(id).cloned().unwrap_or((1, Shown::Content))
    }

    /// Shows `shown` on channel `id` if `wanted` is the current revision; the new revision.
    pub fn set(&self, id: &str, wanted: u64, shown: Shown) -> Result<u64, ApiError> {
        let mut map = self.0.lock().expect("shows lock");
        let entry = map.entry(id.to_string()).or_insert((1, Shown::Content));
        if entry.0 != wanted {
            return Err(ApiError::Stale { current: entry.0 });
        }
        *entry = (entry.0 + 1, shown);
        Ok(entry.0)
    }
}

/// Camera captures uploaded per channel (see `captures.rs`), frame by frame, held in memory
/// until they are decoded or dropped: a capture session lasts minutes, and the captures of a
/// fresh session replace it.
#[derive(Default)]
pub struct Captures(Mutex<HashMap<String, Vec<Option<Arc<Grey>>>>>);

impl Captures {
    /// Keeps frame `n` of a `len`-frame sequence for channel `id`. Every frame of a channel
    /// must have the first one's size; all channels together hold at most
    /// [`crate::limits::CAPTURE_BYTES`].
    pub fn put(&self, id: &str, n: usize, len: usize, frame: Grey) -> Result<(), ApiError> {
        let mut map = self.0.lock().expect("captures lock");
        let held: usize = map
            .iter()
            .filter(|(k, _)| k.as_str() != id)
            .flat_map(|(_, v)| v.iter().flatten())
            .map(|g| g.bytes())
            .sum();
        let limit = crate::limits::CAPTURE_BYTES;
        // Caps that agree: a sequence that could never be held whole is refused at its first
        // frame, not at the one that tips it over.
        let whole = len.saturating_mul(frame.bytes());
        if whole > limit {
            return Err(ApiError::Invalid {
                field: "body".into(),
                reason: format!(
                    "a {len}-frame sequence of {}×{} captures needs {} MiB, above the {} MiB \
                    the daemon holds; capture at a lower resolution or bit depth",
                    frame.width,
                    frame.height,
                    whole >> 20,
                    limit >> 20
                ),
            });
        }
        let slots = crate::limits::CAPTURE_SLOTS;
        if !map.contains_key(id) && map.len() >= slots {
            return Err(ApiError::Invalid {
                field: "view".into(),
                reason: format!(
                    "the daemon holds captures of at most {slots} sequences (channel, view, \
                    period and code) at once; decode or DELETE some first"
                ),
            });
        }
        let frames = map.entry(id.to_string()).or_default();
        frames.resize(len, None);
        if let Some(first) = frames
            .iter()
            .enumerate()
            .find_map(|(k, f)| f.as_ref().filter(|_| k != n))
            && (first.width, first.height) != (frame.width, frame.height)
        {
            return Err(ApiError::Invalid {
                field: "body".into(),
                reason: format!(
                    "is {}×{}, the channel's other captures {}×{} (DELETE the captures to start \
                     again with another camera)",
                    frame.width, frame.height, first.width, first.height
                ),
            });
        }
        let mine: usize = frames
            .iter()
            .enumerate()
            .filter(|(k, _)| *k != n)
            .flat_map(|(_, f)| f.iter())
            .map(|g| g.bytes())
            .sum();
        if held + mine + frame.bytes() > limit {
            return Err(ApiError::Invalid {
                field: "body".into(),
                reason: format!(
                    "the daemon holds captures up to {} MiB in all; decode or DELETE some first",
                    limit >> 20
                ),
            });
        }
        frames[n] = Some(Arc::new(frame));
        Ok(())
    }

    /// Frame numbers received for a `len`-frame sequence, and their size.
    pub fn status(&self, id: &str, len: usize) -> (Vec<usize>, Option<[u32; 2]>) {
        let map = self.0.lock().expect("captures lock");
        let frames = map.get(id).map(Vec::as_slice).unwrap_or(&[]);
        let got: Vec<usize> = (0..len)
            .filter(|&n| frames.get(n).is_some_and(Option::is_some))
            .collect();
        let size = frames.iter().flatten().next().map(|g| [g.width, g.height]);
        (got, size)
    }

    /// All `len` frames, or the numbers of those missing.
    pub fn all(&self, id: &str, len: usize) -> Result<Vec<Arc<Grey>>, Vec<usize>> {
        let map = self.0.lock().expect("captures lock");
        let frames = map.get(id).map(Vec::as_slice).unwrap_or(&[]);
        let missing: Vec<usize> = (0..len)
            .filter(|&n| !frames.get(n).is_some_and(Option::is_some))
            .collect();
        if missing.is_empty() {
            Ok(frames[..len].iter().flatten().cloned().collect())
        } else {
            Err(missing)
        }
    }

    /// Drops channel `id`'s captures; how many there were.
    pub fn clear(&self, id: &str) -> usize {
        let mut map = self.0.lock().expect("captures lock");
        map.remove(id).map_or(0, |v| v.iter().flatten().count())
    }

    /// Drops the captures of every channel not in `channels`: once a rig has lost a channel
    /// its captures can be neither decoded nor deleted, and would hold the cap for ever.
    pub fn keep_channels(&self, channels: &[&str]) {
        let mut map = self.0.lock().expect("captures lock");
        // A key is the channel id, then the sequence, after a unit separator.
        map.retain(|key, _| {
            let id = key.split('\u{1f}').next().unwrap_or(key);
            channels.contains(&id)
        });
    }

    /// Bytes held over all channels.
    pub fn held(&self) -> usize {
        let map = self.0.lock().expect("captures lock");
        map.values().flatten().flatten().map(|g| g.bytes()).sum()
    }
}

pub fn etag(revision: u64) -> HeaderValue {
    HeaderValue::from_str(&format!("\"{revision}\"")).expect("digits are a valid header")
}

/// A JSON response with the revision as its ETag.
/// The history entry of a client's write: who made it, and what it was.
pub fn meta(s: &AppState, action: &'static str, request: Option<serde_json::Value>) -> Meta {
    Meta {
        who: s.options.user.clone(),
        action,
        request,
        undo_to: None,
        redo_to: None,
    }
}

pub fn tagged(body: serde_json::Value, revision: u64) -> Response {
    let mut resp = Json(body).into_response();
    resp.headers_mut().insert(header::ETAG, etag(revision));
    resp
}

/// The revision an edit is based on, from `If-Match`: `"<n>"` or `W/"<n>"`, nothing else.
pub fn if_match(headers: &HeaderMap) -> Result<u64, ApiError> {
    let v = headers
        .get(header::IF_MATCH)
        .ok_or(ApiError::PreconditionRequired)?;
    v.to_str()
        .ok()
        .map(str::trim)
        .map(|s| s.strip_prefix("W/").unwrap_or(s))
        .and_then(|s| s.strip_prefix('"')?.strip_suffix('"'))
        .filter(|n| !n.is_empty() && n.len() <= 19 && n.bytes().all(|b| b.is_ascii_digit()))
        .and_then(|n| n.parse().ok())
        .ok_or_else(|| ApiError::Invalid {
            field: "If-Match".into(),
            reason: "must be a revision in quotes, such as \"3\" (or W/\"3\")".into(),
        })
}

/// Parses a JSON body, naming the offending field by JSON pointer; unknown fields are refused
/// by the types themselves, and anything after the document but white space is refused too.
pub fn parse_body<T: DeserializeOwned>(body: &Bytes) -> Result<T, ApiError> {
    let mut de = serde_json::Deserializer::from_slice(body);
    let value = serde_path_to_error::deserialize(&mut de).map_err(|e| ApiError::Invalid {
        field: crate::rig::pointer_of(&e.path().to_string()),
        reason: e.into_inner().to_string(),
    })?;
    de.end().map_err(|e| ApiError::Invalid {
        field: "/".into(),
        reason: format!("the body goes on after its JSON document: {e}"),
    })?;
    Ok(value)
}

/// A query string as `T`; a parameter that cannot be read is refused with its name as `field`
/// (the framework's own extractor answers in plain text without naming it).
pub struct Query<T>(pub T);

impl<T: DeserializeOwned, S: Send + Sync> axum::extract::FromRequestParts<S> for Query<T> {
    type Rejection = ApiError;

    async fn from_request_parts(
        parts: &mut axum::http::request::Parts,
        _: &S,
    ) -> Result<Self, ApiError> {
        let q = parts.uri.query().unwrap_or("");
        let de = serde_urlencoded::Deserializer::new(form_urlencoded::parse(q.as_bytes()));
        serde_path_to_error::deserialize(de)
            .map(Query)
            .map_err(|e| {
                let path = e.path().to_string();
                let reason = e.into_inner().to_string();
                // serde_urlencoded reports an unknown parameter at the root; name it.
                let field = match reason.strip_prefix("unknown field `") {
                    Some(rest) => rest.split('`').next().unwrap_or("query").to_string(),
                    None if path == "." => "query".to_string(),
                    None => path,
                };
                ApiError::Invalid { field, reason }
            })
    }
}

/// The document of `resource` at `revision`, 404 where the history has none.
pub async fn document_at(
    s: &Arc<AppState>,
    resource: String,
    revision: u64,
) -> Result<serde_json::Value, ApiError> {
    let state = s.clone();
    let r = resource.clone();
    tokio::task::spawn_blocking(move || state.store.db.at(&r, revision))
        .await
        .map_err(|e| ApiError::Internal(e.to_string()))??
        .ok_or_else(|| ApiError::NotFound(format!("{resource} has no revision {revision}")))
}

/// `?revision=N` on a resource's GET: that revision from the history instead of the current.
#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AtRevision {
    pub revision: Option<u64>,
}
