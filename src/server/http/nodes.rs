//! The render nodes the daemon follows (`omniwarp play --daemon`), as each last reported:
//! kept in memory, like the shows, since a node reports again within a second of a restart.
//! The routes are in `routes/nodes.rs`.

use super::error::ApiError;
use crate::limits::{NODE_OUTPUTS, NODES};
use axum::http::StatusCode;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::sync::Mutex;
use std::time::{Duration, Instant};

/// A node silent this long is forgotten when another needs its place.
const STALE: Duration = Duration::from_secs(30);
/// Characters of each string a report carries (a channel, an ETag, an error message).
const TEXT: usize = 512;

/// What a node said, as it said it.
#[derive(Clone, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Report {
    /// Its outputs, in the order it was started with.
    pub outputs: Vec<Output>,
    /// Frames presented per second, over the last second or so.
    #[serde(default)]
    pub fps: f64,
    /// Frames it could not present since it started.
    #[serde(default)]
    pub dropped: u64,
    /// Whether the operator muted its outputs to black.
    #[serde(default)]
    pub black: bool,
    /// Its last error (a fetch that failed, a picture it refused), if any.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub error: Option<String>,
}

/// One output of a node.
#[derive(Clone, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Output {
    /// The rig channel it shows.
    pub channel: String,
    /// The ETag of the picture on it (as `output.png` answered it); none before the first.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub showing: Option<String>,
    /// Frames presented on it since the node started.
    #[serde(default)]
    pub frames: u64,
}

/// The nodes heard from, by id, with when.
#[derive(Default)]
pub struct Nodes(Mutex<BTreeMap<String, (Instant, Report)>>);

impl Nodes {
    /// Keeps node `id`'s report, checked; whether the feed should hear of it (a new node, or
    /// one whose pictures changed).
    pub fn report(&self, id: &str, report: Report) -> Result<bool, ApiError> {
        check(id, &report)?;
        let mut nodes = self.0.lock().expect("nodes lock");
        let now = Instant::now();
        if !nodes.contains_key(id) && nodes.len() >= NODES {
            let stale = nodes
                .iter()
                .filter(|(_, (seen, _))| now.duration_since(*seen) > STALE)
                .min_by_key(|(_, (seen, _))| *seen)
                .map(|(k, _)| k.clone());
            match stale {
                Some(k) => {
                    nodes.remove(&k);
                }
                None => {
                    return Err(ApiError::refused(
                        StatusCode::CONFLICT,
                        Some("id"),
                        format!("the daemon follows {NODES} nodes, all heard from lately"),
                    ));
                }
            }
        }
        let before = nodes.insert(id.to_string(), (now, report.clone()));
        // Frames and rates change every report; the feed hears of what is on the wall.
        Ok(before.is_none_or(|(_, b)| !same_shown(&b, &report)))
    }

    /// Every node, as it reported, with its `id` and the `age_seconds` since.
    pub fn list(&self) -> Vec<serde_json::Value> {
        let nodes = self.0.lock().expect("nodes lock");
        let now = Instant::now();
        nodes
            .iter()
            .map(|(id, (seen, r))| {
                let mut v = serde_json::to_value(r).unwrap_or_default();
                v["id"] = id.clone().into();
                v["age_seconds"] = (now.duration_since(*seen).as_millis() as f64 / 1000.0).into();
                v
            })
            .collect()
    }

    /// Forgets node `id`; whether it was there.
    pub fn forget(&self, id: &str) -> bool {
        self.0.lock().expect("nodes lock").remove(id).is_some()
    }
}

/// Whether two reports say the same is on the wall: the same pictures on the same channels,
/// muted alike.
fn same_shown(a: &Report, b: &Report) -> bool {
    a.black == b.black
        && a.outputs.len() == b.outputs.len()
        && a.outputs
            .iter()
            .zip(&b.outputs)
            .all(|(x, y)| x.channel == y.channel && x.showing == y.showing)
}

fn check(id: &str, r: &Report) -> Result<(), ApiError> {
    let invalid = |field: String, reason: String| ApiError::Invalid { field, reason };
    let plain = |s: &str| {
        s.chars()
            .all(|c| c.is_ascii_alphanumeric() || "._-".contains(c))
    };
    if id.is_empty() || id.len() > 64 || !plain(id) {
        return Err(invalid(
            "id".into(),
            "must be 1–64 letters, digits, '.', '_' or '-'".into(),
        ));
    }
    if r.outputs.len() > NODE_OUTPUTS {
        return Err(invalid(
            "/outputs".into(),
            format!("at most {NODE_OUTPUTS} outputs, got {}", r.outputs.len()),
        ));
    }
    if !r.fps.is_finite() || r.fps < 0.0 || r.fps > 1e6 {
        return Err(invalid(
            "/fps".into(),
            format!("must be 0–1e6, got {}", r.fps),
        ));
    }
    let long = |s: &str| s.chars().count() > TEXT;
    if r.error.as_deref().is_some_and(long) {
        return Err(invalid(
            "/error".into(),
            format!("at most {TEXT} characters"),
        ));
    }
    for (i, o) in r.outputs.iter().enumerate() {
        if long(&o.channel) || o.showing.as_deref().is_some_and(long) {
            return Err(invalid(
                format!("/outputs/{i}"),
                format!("channel and showing are at most {TEXT} characters"),
            ));
        }
    }
    Ok(())
}
