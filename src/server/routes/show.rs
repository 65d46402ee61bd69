//! What each channel shows: its content (the default) or a test card sent by a technician
//! (`src/content/testcard.rs`). The choice is a resource like the others — a revision, writes
//! with `If-Match`, a `show` event on the change feed — but it is kept in memory only: a test
//! card is for the minutes of an alignment, and after a restart every channel shows its content
//! again. `output.png` is the image the channel should put out now, so a player that follows
//! the feed and fetches it shows what the console sent.

use super::outputs::{self, RenderQuery};
use crate::content::testcard::{self, Card, Label};
use crate::image_io::{Compression, png_bytes_with};
use crate::server::ApiError;
use crate::server::http::jobs::{job, run_job};
use crate::server::http::state::{AppState, Query, if_match, parse_body, tagged};
use crate::server::previews::pattern::Grid;
use axum::body::Bytes;
use axum::extract::{Path, State};
use axum::http::HeaderMap;
use axum::response::Response;
use serde::Deserialize;
use std::sync::Arc;

fn name(card: Option<Card>) -> &'static str {
    card.map_or("content", Card::name)
}

/// The channel's index in the rig, 404 for an id the rig does not have.
fn index_of(s: &AppState, id: &str) -> Result<usize, ApiError> {
    let (rig, _) = s.store.snapshot();
    rig.channels
        .iter()
        .position(|c| c.id == id)
        .ok_or_else(|| ApiError::NotFound(format!("no channel `{id}`")))
}

pub async fn get_show(
    State(s): State<Arc<AppState>>,
    Path(id): Path<String>,
) -> Result<Response, ApiError> {
    index_of(&s, &id)?;
    let (revision, card) = s.shows.get(&id);
    Ok(tagged(
        serde_json::json!({"revision": revision, "show": name(card)}),
        revision,
    ))
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct ShowBody {
    show: String,
}

pub async fn put_show(
    State(s): State<Arc<AppState>>,
    Path(id): Path<String>,
    headers: HeaderMap,
    body: Bytes,
) -> Result<Response, ApiError> {
    index_of(&s, &id)?;
    let wanted = if_match(&headers)?;
    let b: ShowBody = parse_body(&body)?;
    let card = match b.show.as_str() {
        "content" => None,
        other => Some(Card::parse(other).map_err(|e| ApiError::Invalid {
            field: "/show".into(),
            reason: format!("{}; or content", e.reason()),
        })?),
    };
    let revision = { s.shows.set(&id, wanted, card)? };
    s.announce(serde_json::json!({"kind": "show", "channel": id, "revision": revision}));
    Ok(tagged(serde_json::json!({"revision": revision}), revision))
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub struct OutputQuery {
    #[serde(default)]
    scale: Option<u32>,
}

pub async fn output(
    State(s): State<Arc<AppState>>,
    Path(id): Path<String>,
    Query(q): Query<OutputQuery>,
) -> Result<Response, ApiError> {
    let index = index_of(&s, &id)?;
    let scale = q.scale.unwrap_or(1);
    let (revision, card) = s.shows.get(&id);
    let Some(card) = card else {
        // The content: the daemon's preview of the channel, as `render` draws it.
        return outputs::render(State(s), Path(id), Query(RenderQuery::at_scale(scale))).await;
    };
    if ![1, 2, 4, 8].contains(&scale) {
        return Err(ApiError::Invalid {
            field: "scale".into(),
            reason: format!("must be 1, 2, 4 or 8, got {scale}"),
        });
    }
    let j = job(&s, &id).await?;
    let computed = j.computed.clone();
    let etag = format!("\"show-{revision}-{}\"", j.etag().trim_matches('"'));
    let png = run_job(&s, move |_| {
        let k = scale as usize;
        let map = Grid::new(computed.map.width(), computed.map.height(), k).map(&computed.map)?;
        let img = testcard::draw(card, &map, &Label { index, id: &id });
        Ok(png_bytes_with(&img, Compression::Fast)?)
    })
    .await?;
    outputs::file(&s, png, "image/png", &etag)
}

/// Frame `n` of the channel's structured-light sequence (`src/structured/mod.rs`), an 8-bit
/// grey PNG at the channel's resolution: what a media server or the console puts on the
/// projector while a camera captures it for `omniwarp calibrate --captures`.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PatternQuery {
    /// The sequence's phase period, projector pixels (default 16).
    #[serde(default)]
    period: Option<u32>,
    /// The sequence's code: `gray` (default) or `xor`.
    #[serde(default)]
    code: Option<String>,
}

pub async fn pattern(
    State(s): State<Arc<AppState>>,
    Path((id, n)): Path<(String, String)>,
    Query(q): Query<PatternQuery>,
) -> Result<Response, ApiError> {
    let named = super::captures::Named {
        period: q.period,
        code: q.code.as_deref(),
        at: "",
    };
    let set = super::captures::sequence(&s, &id, named)?;
    let n = super::captures::frame_number(&n, &set)?;
    let frame = set.frame(n, "n")?;
    let etag = format!(
        "\"pattern-{}x{}-p{}-{}-{n}\"",
        set.width,
        set.height,
        set.period,
        set.code.name()
    );
    let png = run_job(&s, move |_| Ok(set.image(frame).png()?)).await?;
    outputs::file(&s, png, "image/png", &etag)
}
