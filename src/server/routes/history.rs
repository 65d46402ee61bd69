//! History and undo: every revision of the rig, of each channel's content canvas and of its
//! tile screen is kept (see [`crate::server::storage::db`]), listed by `GET /v1/history`, readable with
//! `?revision=N` on the resource itself, and any of them can be made current again by a revert.
//! Undo and redo are reverts too: each makes a new revision (nothing is rewritten, so another
//! client's If-Match stays meaningful), and the history row of every revision says where an
//! undo or a redo from it goes:
//!
//! * a client's write of revision r (from r − 1): undo → r − 1;
//! * undo from c to u: undo → where u's undo goes, redo → c;
//! * redo from c to x: undo and redo → where x's go;
//! * revert from c to x: undo → c, no redo.
//!
//! So undo, undo, redo, redo walks back and forth along the edits as in an editor, and a new
//! edit after an undo drops the redo.

use super::channels::{Part, commit};
use super::rig::commit_rig;
use crate::rig::RigDoc;
use crate::server::ApiError;
use crate::server::http::state::{
    AppState, Query, document_at, if_match, meta, parse_body, tagged,
};
use crate::server::storage::db::{Db, Meta, Row};
use crate::server::storage::store::ChannelData;
use crate::tiles::TileScreen;
use axum::body::Bytes;
use axum::extract::{Path, State};
use axum::http::{HeaderMap, StatusCode};
use axum::response::Response;
use serde::Deserialize;
use std::sync::Arc;

/// Rows one history request may list.
pub const HISTORY_ROWS: usize = 1000;

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct HistoryQuery {
    /// `rig`, `channels/<id>/content` or `channels/<id>/tiles`; all when absent.
    resource: Option<String>,
    /// Rows to list, newest first (default 50, at most 1000).
    limit: Option<usize>,
    /// Only rows older than this `seq` (the next page).
    before: Option<i64>,
}

pub async fn list(
    State(s): State<Arc<AppState>>,
    Query(q): Query<HistoryQuery>,
) -> Result<Response, ApiError> {
    let limit = q.limit.unwrap_or(50);
    if limit == 0 || limit > HISTORY_ROWS {
        return Err(ApiError::Invalid {
            field: "limit".into(),
            reason: format!("must be 1 to {HISTORY_ROWS} (the limit), got {limit}"),
        });
    }
    let state = s.clone();
    let rows = tokio::task::spawn_blocking(move || {
        state
            .store
            .db
            .history(q.resource.as_deref(), limit, q.before)
    })
    .await
    .map_err(|e| ApiError::Internal(e.to_string()))??;
    let next = (rows.len() == limit)
        .then(|| rows.last().map(|r| r.seq))
        .flatten();
    Ok(axum::response::IntoResponse::into_response(axum::Json(
        serde_json::json!({"history": rows, "before": next}),
    )))
}

/// What a revert, undo or redo asks for.
enum Step {
    Revert(u64),
    Undo,
    Redo,
}

/// The revision `step` makes current again, and the history entry of the new revision (the
/// history is read in the blocking pool: a query can wait on a commit's fsync).
async fn plan(
    s: &Arc<AppState>,
    resource: &str,
    current: u64,
    step: Step,
) -> Result<(u64, Meta), ApiError> {
    let (state, res, base) = (s.clone(), resource.to_string(), meta(s, "revert", None));
    tokio::task::spawn_blocking(move || plan_in(&state.store.db, &res, current, step, base))
        .await
        .map_err(|e| ApiError::Internal(e.to_string()))?
}

fn plan_in(
    db: &Db,
    resource: &str,
    current: u64,
    step: Step,
    base: Meta,
) -> Result<(u64, Meta), ApiError> {
    let row = |rev: u64| -> Result<Option<Row>, ApiError> { Ok(db.row(resource, rev)?) };
    let nothing = |what: &str| {
        ApiError::refused(
            StatusCode::CONFLICT,
            None,
            format!("nothing to {what}: revision {current} of {resource} has no {what} step"),
        )
    };
    let dropped = |to: u64| {
        ApiError::refused(
            StatusCode::CONFLICT,
            None,
            format!(
                "revision {to} of {resource} is no longer in the history (it keeps what the \
                 daemon's --history-* settings allow)"
            ),
        )
    };
    let m = |action: &'static str, to: u64| Meta {
        action,
        request: Some(serde_json::json!({ "revision": to })),
        ..base.clone()
    };
    match step {
        Step::Revert(to) => {
            if to == current || row(to)?.is_none() {
                return Err(ApiError::Invalid {
                    field: "/revision".into(),
                    reason: if to == current {
                        format!("{to} is the current revision")
                    } else {
                        format!("{resource} has no revision {to} in its history")
                    },
                });
            }
            let mut meta = m("revert", to);
            meta.undo_to = Some(current);
            Ok((to, meta))
        }
        Step::Undo => {
            let to = row(current)?
                .and_then(|r| r.undo_to)
                .ok_or_else(|| nothing("undo"))?;
            let target = row(to)?.ok_or_else(|| dropped(to))?;
            let mut meta = m("undo", to);
            meta.undo_to = target.undo_to;
            meta.redo_to = Some(current);
            Ok((to, meta))
        }
        Step::Redo => {
            let to = row(current)?
                .and_then(|r| r.redo_to)
                .ok_or_else(|| nothing("redo"))?;
            let target = row(to)?.ok_or_else(|| dropped(to))?;
            let mut meta = m("redo", to);
            meta.undo_to = target.undo_to;
            meta.redo_to = target.redo_to;
            Ok((to, meta))
        }
    }
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RevertBody {
    revision: u64,
}

fn step_of(action: &str, body: &Bytes) -> Result<Step, ApiError> {
    match action {
        "revert" => Ok(Step::Revert(parse_body::<RevertBody>(body)?.revision)),
        "undo" | "redo" if !body.is_empty() && body.as_ref() != b"{}" => Err(ApiError::Invalid {
            field: "/".into(),
            reason: format!("{action} takes no body (or {{}})"),
        }),
        "undo" => Ok(Step::Undo),
        _ => Ok(Step::Redo),
    }
}

/// `POST /v1/rig/{revert,undo,redo}`: the rig document of an earlier revision, accepted again
/// as a PUT of it would be (its mesh must still be there).
async fn rig_step(
    s: Arc<AppState>,
    headers: HeaderMap,
    body: Bytes,
    action: &str,
) -> Result<Response, ApiError> {
    let wanted = if_match(&headers)?;
    let step = step_of(action, &body)?;
    let (_, current) = s.store.snapshot();
    if wanted != current {
        return Err(ApiError::Stale { current });
    }
    let (to, meta) = plan(&s, "rig", current, step).await?;
    let doc = document_at(&s, "rig".into(), to).await?;
    let doc: RigDoc = serde_json::from_value(doc).map_err(|e| ApiError::Internal(e.to_string()))?;
    let state = s.clone();
    let rig = crate::server::http::jobs::run_write(&s, move |_| {
        Ok(state
            .store
            .meshes
            .accept(doc, state.options.memory_budget)?)
    })
    .await?;
    let revision = commit_rig(&s, wanted, rig, meta).await?;
    Ok(tagged(
        serde_json::json!({"revision": revision, "from": to}),
        revision,
    ))
}

pub async fn rig_revert(
    s: State<Arc<AppState>>,
    h: HeaderMap,
    b: Bytes,
) -> Result<Response, ApiError> {
    rig_step(s.0, h, b, "revert").await
}
pub async fn rig_undo(
    s: State<Arc<AppState>>,
    h: HeaderMap,
    b: Bytes,
) -> Result<Response, ApiError> {
    rig_step(s.0, h, b, "undo").await
}
pub async fn rig_redo(
    s: State<Arc<AppState>>,
    h: HeaderMap,
    b: Bytes,
) -> Result<Response, ApiError> {
    rig_step(s.0, h, b, "redo").await
}

/// `POST /v1/channels/{id}/{content,tiles}/{revert,undo,redo}`.
async fn channel_step(
    s: Arc<AppState>,
    id: String,
    headers: HeaderMap,
    body: Bytes,
    part: Part,
    action: &str,
) -> Result<Response, ApiError> {
    let wanted = if_match(&headers)?;
    let step = step_of(action, &body)?;
    let d = s
        .store
        .channel(&id)
        .ok_or_else(|| ApiError::NotFound(format!("no channel `{id}`")))?;
    let g = d.write().await;
    let (current, _) = part.of(&g);
    if wanted != current {
        return Err(ApiError::Stale { current });
    }
    let resource = part.resource(&id);
    let (to, meta) = plan(&s, &resource, current, step).await?;
    let doc = document_at(&s, resource, to).await?;
    let revision = current + 1;
    let mut next: ChannelData = g.clone();
    let kept = |e: serde_json::Error| ApiError::Internal(e.to_string());
    match part {
        Part::Content => {
            next.content.value = serde_json::from_value(doc).map_err(kept)?;
            if let Some(c) = &next.content.value {
                c.view()?;
            }
            next.content.revision = revision;
        }
        Part::Tiles => {
            let mut screen: Option<TileScreen> = serde_json::from_value(doc).map_err(kept)?;
            if let Some(t) = &mut screen {
                t.validate()?;
                t.revision = revision;
            }
            next.tiles.value = screen;
            next.tiles.revision = revision;
        }
    }
    commit(&s, &id, g, next, part, meta).await?;
    Ok(tagged(
        serde_json::json!({"revision": revision, "from": to}),
        revision,
    ))
}

macro_rules! channel_steps {
    ($($name:ident => $part:ident, $action:literal;)*) => {$(
        pub async fn $name(
            s: State<Arc<AppState>>,
            Path(id): Path<String>,
            h: HeaderMap,
            b: Bytes,
        ) -> Result<Response, ApiError> {
            channel_step(s.0, id, h, b, Part::$part, $action).await
        }
    )*};
}

channel_steps! {
    content_revert => Content, "revert";
    content_undo => Content, "undo";
    content_redo => Content, "redo";
    tiles_revert => Tiles, "revert";
    tiles_undo => Tiles, "undo";
    tiles_redo => Tiles, "redo";
}
