//! Per-channel editable resources: the content canvas and the tile screen, each with its own
//! revision (`ETag`, `If-Match`, 412 with the current one when stale).

use crate::rig::Canvas;
use crate::rig::{Rig, SAMPLED_COLUMNS, default_rows};
use crate::server::ApiError;
use crate::server::http::jobs::run_write;
use crate::server::http::state::{
    AppState, AtRevision, Query, document_at, if_match, meta, parse_body, tagged,
};
use crate::server::storage::db::Meta;
use crate::server::storage::store::{
    Channel, ChannelData, ChannelWriter, Versioned, content_resource, tiles_resource,
};
use crate::tiles::edit::Edit;
use crate::tiles::{Layout, TileScreen};
use axum::body::Bytes;
use axum::extract::{Path, State};
use axum::http::HeaderMap;
use axum::response::Response;
use serde::Deserialize;
use std::sync::Arc;

fn not_found(id: &str) -> ApiError {
    ApiError::NotFound(format!("no channel `{id}`"))
}

async fn data(s: &Arc<AppState>, id: &str) -> Result<Arc<Channel>, ApiError> {
    s.store.channel(id).ok_or_else(|| not_found(id))
}

/// 412 unless the edit is based on the current revision.
fn fresh(current: u64, wanted: u64) -> Result<(), ApiError> {
    if current == wanted {
        Ok(())
    } else {
        Err(ApiError::Stale { current })
    }
}

/// Which of a channel's documents a write replaces.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Part {
    Content,
    Tiles,
}

impl Part {
    pub fn kind(self) -> &'static str {
        match self {
            Part::Content => "content",
            Part::Tiles => "tiles",
        }
    }

    pub fn resource(self, id: &str) -> String {
        match self {
            Part::Content => content_resource(id),
            Part::Tiles => tiles_resource(id),
        }
    }

    pub fn of_revision(self, data: &ChannelData) -> u64 {
        match self {
            Part::Content => data.content.revision,
            Part::Tiles => data.tiles.revision,
        }
    }

    /// The revision and document of this part of `data`.
    pub fn of(self, data: &ChannelData) -> (u64, serde_json::Value) {
        match self {
            Part::Content => (
                data.content.revision,
                serde_json::to_value(&data.content.value).expect("canvases serialise"),
            ),
            Part::Tiles => (
                data.tiles.revision,
                serde_json::to_value(&data.tiles.value).expect("tile screens serialise"),
            ),
        }
    }
}

/// Replaces a channel's state with `next` once the changed part is durable with its history
/// row, then announces it. A plain write can be undone back to the revision it replaced.
///
/// The write, the swap in memory and the announcement run as one task that a client going away
/// cannot stop: the handler's future is dropped when its connection closes, and a swap left
/// to it would be skipped after a durable write, leaving memory behind the database. The
/// channel stays locked (`held`) until the swap is done.
pub async fn commit(
    s: &Arc<AppState>,
    id: &str,
    mut held: ChannelWriter,
    next: ChannelData,
    part: Part,
    mut meta: Meta,
) -> Result<u64, ApiError> {
    let revision = part.of_revision(&next);
    if matches!(meta.action, "put" | "patch" | "delete") {
        meta.undo_to = Some(part.of_revision(&held));
    }
    let (state, resource, id) = (s.clone(), part.resource(id), id.to_string());
    // Turning two screens into JSON values and comparing them costs milliseconds: off the
    // runtime, with the write, and skipped where a tile edit changed only some features.
    tokio::task::spawn_blocking(move || {
        let old = &*held;
        let revisions = (part.of_revision(old), part.of_revision(&next));
        let patched = match feature_patch(&old.tiles.value, &next.tiles.value) {
            Some(patch) if part == Part::Tiles => {
                let doc = || part.of(&next).1;
                state
                    .store
                    .db
                    .write_patch(&resource, revisions, &patch, &doc, &meta)?
            }
            _ => false,
        };
        if !patched {
            let (before, after) = (part.of(old), part.of(&next));
            state
                .store
                .save_doc(&resource, (before.0, &before.1), (after.0, &after.1), &meta)?;
        }
        held.set(next);
        state.announce(
            serde_json::json!({"kind": part.kind(), "channel": id, "revision": revision}),
        );
        Ok::<_, ApiError>(())
    })
    .await
    .map_err(|e| ApiError::Internal(e.to_string()))??;
    Ok(revision)
}

/// The RFC 6902 patch from one tile screen to the next when they differ only in some grid
/// features (and the revision): each changed feature replaced whole. `None` for anything else,
/// which the store compares as documents.
fn feature_patch(old: &Option<TileScreen>, new: &Option<TileScreen>) -> Option<json_patch::Patch> {
    let (Some(a), Some(b)) = (old, new) else {
        return None;
    };
    let (
        Layout::Grid {
            columns: c0,
            rows: r0,
            features: f0,
        },
        Layout::Grid {
            columns: c1,
            rows: r1,
            features: f1,
        },
    ) = (&a.layout, &b.layout)
    else {
        return None;
    };
    if (c0, r0, a.format, &a.source, a.interpolation)
        != (c1, r1, b.format, &b.source, b.interpolation)
    {
        return None;
    }
    let mut ops =
        vec![serde_json::json!({"op": "replace", "path": "/revision", "value": b.revision})];
    for (i, (x, y)) in f0.iter().zip(f1).enumerate() {
        if x != y {
            ops.push(serde_json::json!({"op": "replace", "path": format!("/layout/features/{i}"), "value": y}));
        }
    }
    if a.revision == b.revision {
        ops.remove(0);
    }
    // Past a quarter of the screen a document comparison is as cheap and a snapshot may be due.
    if ops.len() > f1.len() / 4 {
        return None;
    }
    serde_json::from_value(serde_json::Value::Array(ops)).ok()
}

pub async fn get_content(
    State(s): State<Arc<AppState>>,
    Path(id): Path<String>,
    Query(q): Query<AtRevision>,
) -> Result<Response, ApiError> {
    let d = data(&s, &id).await?;
    let (revision, content) = { Part::Content.of(&d.read()) };
    let (revision, content) = match q.revision {
        Some(r) if r != revision => (r, document_at(&s, content_resource(&id), r).await?),
        _ => (revision, content),
    };
    // A channel without a canvas of its own plays the rig's, as it is now.
    let own = !content.is_null();
    let content = if own {
        content
    } else {
        serde_json::to_value(s.store.snapshot().0.canvas()).expect("canvases serialise")
    };
    Ok(tagged(
        serde_json::json!({"revision": revision, "content": content, "own": own}),
        revision,
    ))
}

/// `DELETE /v1/channels/{id}/content`: the channel drops its own canvas and plays the rig's.
pub async fn delete_content(
    State(s): State<Arc<AppState>>,
    Path(id): Path<String>,
    headers: HeaderMap,
) -> Result<Response, ApiError> {
    let wanted = if_match(&headers)?;
    let d = data(&s, &id).await?;
    let g = d.write().await;
    fresh(g.content.revision, wanted)?;
    if g.content.value.is_none() {
        return Err(ApiError::refused(
            axum::http::StatusCode::CONFLICT,
            None,
            "the channel has no canvas of its own: it already plays the rig's",
        ));
    }
    let revision = wanted + 1;
    let mut next = g.clone();
    next.content = Versioned {
        revision,
        value: None,
    };
    commit(&s, &id, g, next, Part::Content, meta(&s, "delete", None)).await?;
    Ok(tagged(serde_json::json!({"revision": revision}), revision))
}

pub async fn put_content(
    State(s): State<Arc<AppState>>,
    Path(id): Path<String>,
    headers: HeaderMap,
    body: Bytes,
) -> Result<Response, ApiError> {
    let wanted = if_match(&headers)?;
    let canvas: Canvas = parse_body(&body)?;
    canvas.view()?;
    canvas.centre(&s.store.snapshot().0)?;
    let d = data(&s, &id).await?;
    let g = d.write().await;
    fresh(g.content.revision, wanted)?;
    let revision = wanted + 1;
    let mut next = g.clone();
    next.content = Versioned {
        revision,
        value: Some(canvas),
    };
    let request = Some(serde_json::to_value(&next.content.value).expect("canvases serialise"));
    commit(&s, &id, g, next, Part::Content, meta(&s, "put", request)).await?;
    Ok(tagged(serde_json::json!({"revision": revision}), revision))
}

/// The tile screen a channel shows: its edited one, or its geometry sampled into a grid.
pub async fn get_tiles(
    State(s): State<Arc<AppState>>,
    Path(id): Path<String>,
    Query(q): Query<AtRevision>,
) -> Result<Response, ApiError> {
    let d = data(&s, &id).await?;
    let (mut revision, mut value) = {
        let now = d.read();
        (now.tiles.revision, now.tiles.value.clone())
    };
    if let Some(r) = q.revision.filter(|r| *r != revision) {
        let doc = document_at(&s, tiles_resource(&id), r).await?;
        value = serde_json::from_value(doc).map_err(|e| ApiError::Internal(e.to_string()))?;
        revision = r;
    }
    // A revision that followed the geometry is shown sampled from today's rig.
    let (screen, follows) = match value {
        Some(t) => (t, false),
        None => {
            let (rig, _) = s.store.snapshot();
            let ch = rig.channel(&id).map_err(|_| not_found(&id))?;
            (rig.default_tiles(ch)?, true)
        }
    };
    Ok(tagged(
        serde_json::json!({"revision": revision, "follows_geometry": follows, "tiles": screen}),
        revision,
    ))
}

pub async fn put_tiles(
    State(s): State<Arc<AppState>>,
    Path(id): Path<String>,
    headers: HeaderMap,
    body: Bytes,
) -> Result<Response, ApiError> {
    let wanted = if_match(&headers)?;
    let screen: TileScreen = parse_body(&body)?;
    screen.validate().map_err(|e| match e {
        crate::Error::Invalid { name, reason } => ApiError::Invalid {
            field: screen_pointer(&name),
            reason,
        },
        other => other.into(),
    })?;
    replace_tiles(&s, &id, wanted, Some(screen), "put").await
}

/// Back to the geometry's exact warp.
pub async fn delete_tiles(
    State(s): State<Arc<AppState>>,
    Path(id): Path<String>,
    headers: HeaderMap,
) -> Result<Response, ApiError> {
    let wanted = if_match(&headers)?;
    replace_tiles(&s, &id, wanted, None, "delete").await
}

async fn replace_tiles(
    s: &Arc<AppState>,
    id: &str,
    wanted: u64,
    screen: Option<TileScreen>,
    action: &'static str,
) -> Result<Response, ApiError> {
    let d = data(s, id).await?;
    let g = d.write().await;
    fresh(g.tiles.revision, wanted)?;
    let revision = wanted + 1;
    let mut next = g.clone();
    next.tiles = Versioned {
        revision,
        value: screen.map(|mut t| {
            t.revision = revision;
            t
        }),
    };
    commit(s, id, g, next, Part::Tiles, meta(s, action, None)).await?;
    Ok(tagged(serde_json::json!({"revision": revision}), revision))
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Patch {
    pub edits: Vec<Edit>,
    /// With an `If-Match` older than the current revision: apply on top of the current screen
    /// when no revision since touched the features these edits touch (else 412 as always).
    #[serde(default)]
    pub merge: bool,
}

/// Applies a list of edits, all or none; the first edit of a channel that follows the geometry
/// starts from the geometry sampled into a grid.
pub async fn patch_tiles(
    State(s): State<Arc<AppState>>,
    Path(id): Path<String>,
    headers: HeaderMap,
    body: Bytes,
) -> Result<Response, ApiError> {
    let wanted = if_match(&headers)?;
    let patch: Patch = parse_body(&body)?;
    let limit = crate::limits::EDITS_PER_PATCH;
    if patch.edits.is_empty() || patch.edits.len() > limit {
        return Err(ApiError::Invalid {
            field: "/edits".into(),
            reason: format!(
                "must hold 1 to {limit} edits (the limit), got {}",
                patch.edits.len()
            ),
        });
    }
    let d = data(&s, &id).await?;
    let g = d.write().await;
    let current = g.tiles.revision;
    if current < wanted || (current > wanted && !patch.merge) {
        return Err(ApiError::Stale { current });
    }
    let (rig, _) = s.store.snapshot();
    let start = g.tiles.value.clone();
    // Edits resample and validate whole grids: in the pool, not on the runtime, and given up
    // when the client goes away. The channel stays locked meanwhile, so edits stay in order.
    let request = serde_json::from_slice::<serde_json::Value>(&body)
        .ok()
        .map(|v| v["edits"].clone());
    let (id2, edits, state) = (id.clone(), patch.edits, s.clone());
    let mut screen = run_write(&s, move |cancel| {
        if current == wanted {
            return apply_edits(&rig, &id2, start, edits, cancel);
        }
        let after = apply_edits(&rig, &id2, start.clone(), edits.clone(), cancel)?;
        let merging = (wanted, current);
        merges(&state, &rig, &id2, merging, &edits, (start, &after), cancel)?;
        Ok(after)
    })
    .await?;
    let revision = current + 1;
    screen.revision = revision;
    let mut next = g.clone();
    next.tiles = Versioned {
        revision,
        value: Some(screen),
    };
    commit(&s, &id, g, next, Part::Tiles, meta(&s, "patch", request)).await?;
    Ok(tagged(serde_json::json!({"revision": revision}), revision))
}

/// Whether `edits`, written against revision `base` and applied to the screen of revision
/// `current` (`now`, giving `after`), merge: judged on what the edits change, not on what they
/// name. The features they change where the client saw the screen and where it is now must not
/// meet those any revision since changed (from the history's patches), and the edits must do
/// the same in both places: outside the features others changed, the two results agree (a
/// smooth whose neighbours moved does something else). Anything but features changing (grid
/// size, source, interpolation, a whole screen put) does not merge. Otherwise 412 with the
/// current revision.
fn merges(
    s: &AppState,
    rig: &Rig,
    id: &str,
    (base, current): (u64, u64),
    edits: &[Edit],
    (now, after): (Option<TileScreen>, &TileScreen),
    cancel: &std::sync::atomic::AtomicBool,
) -> Result<(), ApiError> {
    let stale = || ApiError::Stale { current };
    let resource = tiles_resource(id);
    let doc = s.store.db.at(&resource, base)?.ok_or_else(stale)?;
    let before: Option<TileScreen> =
        serde_json::from_value(doc).map_err(|e| ApiError::Internal(e.to_string()))?;
    let ch = rig.channel(id).map_err(|_| not_found(id))?;
    let or_sampled = |t: Option<TileScreen>| match t {
        Some(t) => Ok::<_, ApiError>(t),
        None => Ok(rig.default_tiles(ch)?),
    };
    let (before, now) = (or_sampled(before)?, or_sampled(now)?);
    let seen_after = apply_edits(rig, id, Some(before.clone()), edits.to_vec(), cancel)?;
    let json = |t: &TileScreen| serde_json::to_value(t).expect("tile screens serialise");
    let changes = |a: &TileScreen, b: &TileScreen| {
        touched(&json_patch::diff(&json(a), &json(b))).ok_or_else(stale)
    };
    let mut theirs = std::collections::BTreeSet::new();
    for r in base + 1..=current {
        let patch = s.store.db.patch_of(&resource, r)?.ok_or_else(stale)?;
        theirs.extend(touched(&patch).ok_or_else(stale)?);
    }
    let mut mine = changes(&before, &seen_after)?;
    mine.extend(changes(&now, after)?);
    if mine.is_disjoint(&theirs) && changes(&seen_after, after)?.is_subset(&theirs) {
        Ok(())
    } else {
        Err(stale())
    }
}

/// The grid features a patch of a tile screen document changes, or `None` if it changes
/// anything else (its own revision number aside).
fn touched(patch: &json_patch::Patch) -> Option<std::collections::BTreeSet<usize>> {
    let mut out = std::collections::BTreeSet::new();
    for op in &patch.0 {
        let path = op.path().as_str();
        if path == "/revision" {
            continue;
        }
        let mut parts = path.strip_prefix("/layout/features/")?.split('/');
        let index = parts.next()?;
        // Adding or removing a whole feature changes the grid.
        let whole = parts.next().is_none();
        if whole && !matches!(op, json_patch::PatchOperation::Replace(_)) {
            return None;
        }
        out.insert(index.parse().ok()?);
    }
    Some(out)
}

/// The screen after `edits`, all or none; errors name the edit (`/edits/N/field`).
fn apply_edits(
    rig: &Rig,
    id: &str,
    start: Option<TileScreen>,
    edits: Vec<Edit>,
    cancel: &std::sync::atomic::AtomicBool,
) -> Result<TileScreen, ApiError> {
    let ch = rig.channel(id).map_err(|_| not_found(id))?;
    let mut screen = match start {
        Some(t) => t,
        None => rig.default_tiles(ch)?,
    };
    let mut work = 0u64;
    for (n, e) in edits.into_iter().enumerate() {
        if cancel.load(std::sync::atomic::Ordering::Relaxed) {
            return Err(crate::Error::Cancelled.into());
        }
        // Bounded by what it would do, not by the clock, so a request is refused or not
        // whatever the machine's load.
        work = work.saturating_add(e.work(screen.feature_count()));
        let limit = crate::limits::EDIT_WORK;
        if n > 0 && work > limit {
            return Err(ApiError::Invalid {
                field: format!("/edits/{n}"),
                reason: format!(
                    "brings this request's work to {work} feature visits, above the limit of \
                     {limit}; nothing was applied: send the edits from here on in another PATCH"
                ),
            });
        }
        let named = |err: crate::Error| match err {
            crate::Error::Invalid { name, reason } => ApiError::Invalid {
                field: format!("/edits/{n}/{}", edit_field(&name)),
                reason,
            },
            other => other.into(),
        };
        // `reset` resamples the geometry: a screen sampled from it keeps no other source.
        screen = match e {
            Edit::Reset => {
                let (c, r) = match &screen.layout {
                    crate::tiles::Layout::Grid { columns, rows, .. } => (*columns, *rows),
                    crate::tiles::Layout::Soup { .. } => (SAMPLED_COLUMNS, default_rows(ch)),
                };
                rig.sample_tiles(ch, c, r).map_err(named)?
            }
            // A channel's screen is refined towards its geometry, which the rig knows.
            Edit::Refine {
                tolerance,
                max_features,
            } if screen.source.is_none() => {
                // The wall continued past its edge, as the screen's outside features are.
                let (w, h) = (f64::from(ch.width), f64::from(ch.height));
                let wider = rig.doc.screen.extended();
                let exact = |x: f64, y: f64| {
                    let ray = ch.lens.unproject([x * w - 0.5, y * h - 0.5]).ok()?;
                    let p = wider.intersect(ch.position, ch.rotation * ray).point()?;
                    rig.sampling_vector(p)
                };
                screen
                    .refined(tolerance, max_features, &exact)
                    .map_err(named)?
            }
            other => screen.edit(&other).map_err(named)?,
        };
    }
    Ok(screen)
}

/// A tile screen error's name (`features[102] (column 3, row 3).scale`, `grid`) as the JSON
/// pointer into the screen's document (`/layout/features/102/scale`, `/layout`).
fn screen_pointer(name: &str) -> String {
    let p = format!("/{}", edit_field(name));
    let in_layout = ["/features", "/triangles", "/columns", "/rows"];
    if p == "/grid" {
        "/layout".into()
    } else if in_layout.iter().any(|l| p.starts_with(l)) {
        format!("/layout{p}")
    } else {
        p
    }
}

/// A tile screen error's name as a JSON pointer below the edit: `features[102] (column 3, row
/// 3).scale` names the screen's feature 102, which the edit made invalid.
fn edit_field(name: &str) -> String {
    let plain = name.split(" (").next().unwrap_or(name);
    let tail = name.rsplit_once(").").map(|(_, t)| format!(".{t}"));
    let path = format!("{plain}{}", tail.unwrap_or_default());
    crate::rig::pointer_of(&path)
        .trim_start_matches('/')
        .to_string()
}
