//! What each channel shows: its content (the default), a test card sent by a technician
//! (`src/content/testcard.rs`) or a frame of its structured-light sequence, for a calibration
//! loop to capture through the projector. The choice is a resource like the others — a
//! revision, writes with `If-Match`, a `show` event on the change feed — but it is kept in
//! memory only: a test card is for the minutes of an alignment, and after a restart every
//! channel shows its content again. `output.png` is the image the channel should put out now,
//! so the render node that follows the feed (`omniwarp play`) shows what the console sent.

use super::outputs::{self, RenderQuery};
use crate::content::testcard::{self, Card, Label};
use crate::image_io::{Compression, png_bytes_with};
use crate::server::ApiError;
use crate::server::http::jobs::{job, run_job};
use crate::server::http::state::{AppState, Query, Shown, if_match, parse_body, tagged};
use crate::server::previews::pattern::{Grid, Light};
use crate::structured::PatternSet;
use axum::body::Bytes;
use axum::extract::{Path, State};
use axum::http::{HeaderMap, StatusCode, header};
use axum::response::{IntoResponse, Response};
use serde::Deserialize;
use std::sync::Arc;

/// The choice as the API writes it.
fn described(shown: &Shown) -> serde_json::Value {
    match shown {
        Shown::Content => serde_json::json!({"show": "content"}),
        Shown::Card(c) => serde_json::json!({"show": c.name()}),
        Shown::Pattern {
            frame,
            period,
            code,
        } => {
            let mut v = serde_json::json!({"show": "pattern", "frame": frame});
            if let Some(p) = period {
                v["period"] = (*p).into();
            }
            if let Some(c) = code {
                v["code"] = c.clone().into();
            }
            v
        }
    }
}

/// The structured-light sequence a pattern show names, checked against the channel.
fn sequence(
    s: &AppState,
    id: &str,
    period: Option<u32>,
    code: Option<&str>,
) -> Result<PatternSet, ApiError> {
    let named = super::captures::Named {
        period,
        code,
        at: "/",
    };
    super::captures::sequence(s, id, named)
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
    let (revision, shown) = s.shows.get(&id);
    let mut body = described(&shown);
    body["revision"] = revision.into();
    Ok(tagged(body, revision))
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct ShowBody {
    show: String,
    /// With `pattern`: the frame of the structured-light sequence.
    #[serde(default)]
    frame: Option<usize>,
    /// With `pattern`: the sequence's phase period.
    #[serde(default)]
    period: Option<u32>,
    /// With `pattern`: the sequence's code.
    #[serde(default)]
    code: Option<String>,
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
    let shown = match b.show.as_str() {
        "pattern" => {
            let frame = b.frame.ok_or_else(|| ApiError::Invalid {
                field: "/frame".into(),
                reason: "needed with show pattern: the frame of the channel's sequence".into(),
            })?;
            let set = sequence(&s, &id, b.period, b.code.as_deref())?;
            set.frame(frame, "/frame")?;
            Shown::Pattern {
                frame,
                period: b.period,
                code: b.code,
            }
        }
        other => {
            if b.frame.is_some() || b.period.is_some() || b.code.is_some() {
                let field = match (b.frame, b.period) {
                    (Some(_), _) => "/frame",
                    (None, Some(_)) => "/period",
                    (None, None) => "/code",
                };
                return Err(ApiError::Invalid {
                    field: field.into(),
                    reason: "only with show pattern".into(),
                });
            }
            match other {
                "content" => Shown::Content,
                card => Shown::Card(Card::parse(card).map_err(|e| ApiError::Invalid {
                    field: "/show".into(),
                    reason: format!("{}; or content, or pattern", e.reason()),
                })?),
            }
        }
    };
    let revision = { s.shows.set(&id, wanted, shown)? };
    s.announce(serde_json::json!({"kind": "show", "channel": id, "revision": revision}));
    Ok(tagged(serde_json::json!({"revision": revision}), revision))
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub struct OutputQuery {
    #[serde(default)]
    scale: Option<u32>,
}

/// A 304 when the client's `If-None-Match` names `etag`: a render node revalidating the
/// picture it shows costs no render and no transfer.
fn unchanged(headers: &HeaderMap, etag: &str) -> Option<Response> {
    let asked = headers.get(header::IF_NONE_MATCH)?.to_str().ok()?;
    asked.split(',').any(|t| t.trim() == etag).then(|| {
        let mut r = StatusCode::NOT_MODIFIED.into_response();
        if let Ok(v) = etag.parse() {
            r.headers_mut().insert(header::ETAG, v);
        }
        r
    })
}

pub async fn output(
    State(s): State<Arc<AppState>>,
    Path(id): Path<String>,
    Query(q): Query<OutputQuery>,
    headers: HeaderMap,
) -> Result<Response, ApiError> {
    let index = index_of(&s, &id)?;
    let scale = q.scale.unwrap_or(1);
    let (_, shown) = s.shows.get(&id);
    let card = match shown {
        Shown::Card(card) => card,
        Shown::Content => {
            // The content: the daemon's preview of the channel, as `render` draws it, tagged
            // as the preview is (by the warp it is drawn through).
            if scale == 1 {
                let j = job(&s, &id).await?;
                if let Some(r) = unchanged(&headers, &j.etag()) {
                    return Ok(r);
                }
            }
            let q = RenderQuery::at_scale(scale);
            return outputs::render(State(s), Path(id), Query(q)).await;
        }
        Shown::Pattern {
            frame,
            period,
            code,
        } => {
            if scale != 1 {
                return Err(ApiError::Invalid {
                    field: "scale".into(),
                    reason: "a pattern frame is put out at the channel's resolution (1)".into(),
                });
            }
            let set = sequence(&s, &id, period, code.as_deref())?;
            let f = set.frame(frame, "frame")?;
            let etag = pattern_etag(&set, frame);
            if let Some(r) = unchanged(&headers, &etag) {
                return Ok(r);
            }
            let png = run_job(&s, move |_| Ok(set.image(f).png()?)).await?;
            return outputs::file(&s, png, "image/png", &etag);
        }
    };
    if ![1, 2, 4, 8].contains(&scale) {
        return Err(ApiError::Invalid {
            field: "scale".into(),
            reason: format!("must be 1, 2, 4 or 8, got {scale}"),
        });
    }
    let j = job(&s, &id).await?;
    let computed = j.computed.clone();
    // Named by what it draws: the card, the scale and the warp (the crosshatch follows it), so
    // a 304 is never a different card, even after a restart resets the shows' revisions.
    let etag = format!(
        "\"card-{}-s{scale}-{}\"",
        card.name(),
        j.etag().trim_matches('"')
    );
    if let Some(r) = unchanged(&headers, &etag) {
        return Ok(r);
    }
    let png = run_job(&s, move |_| {
        let k = scale as usize;
        let grid = Grid::new(computed.map.width(), computed.map.height(), k);
        let map = grid.map(&computed.map)?;
        let mut img = testcard::draw(card, &map, &Label { index, id: &id });
        if card.blended() {
            let weights = grid.values(&computed.geometry.weights);
            let lift = computed.geometry.lift.as_ref().map(|l| grid.values(l));
            Light::of(&weights, lift.as_deref(), 2.2)?.apply(&mut img)?;
        }
        Ok(png_bytes_with(&img, Compression::Fast)?)
    })
    .await?;
    outputs::file(&s, png, "image/png", &etag)
}

/// The tag of frame `n` of a pattern sequence, named by what it draws, so the same tag is the
/// same picture before and after a restart (the pattern route and a pattern show answer with it).
fn pattern_etag(set: &PatternSet, n: usize) -> String {
    format!(
        "\"pattern-{}x{}-p{}-{}-{n}\"",
        set.width,
        set.height,
        set.period,
        set.code.name()
    )
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
    let etag = pattern_etag(&set, n);
    let png = run_job(&s, move |_| Ok(set.image(frame).png()?)).await?;
    outputs::file(&s, png, "image/png", &etag)
}
