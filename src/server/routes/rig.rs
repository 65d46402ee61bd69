//! The rig routes: health, version, the rig document and its channels, and the change feed.

use crate::rig::Rig;
use crate::server::ApiError;
use crate::server::http::jobs::run_write;
use crate::server::http::state::{
    AppState, AtRevision, Query, WORKERS, document_at, if_match, meta, tagged,
};
use crate::server::storage::db::Meta;
use axum::Json;
use axum::body::Bytes;
use axum::extract::State;
use axum::http::HeaderMap;
use axum::response::Response;
use axum::response::sse::{Event, KeepAlive, Sse};
use futures_util::Stream;
use std::sync::Arc;
use std::sync::atomic::Ordering;
use tokio_stream::StreamExt;
use tokio_stream::wrappers::BroadcastStream;
use tokio_stream::wrappers::errors::BroadcastStreamRecvError;

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

/// The daemon's name, version and API; over TLS also its certificate's fingerprint, which the
/// console shows beside the token prompt for the technician to compare with what the daemon
/// printed at start.
pub async fn version(State(s): State<Arc<AppState>>) -> Json<serde_json::Value> {
    let mut v =
        serde_json::json!({"name": "omniwarp", "version": env!("CARGO_PKG_VERSION"), "api": "v1"});
    if let Some(tls) = &s.options.tls {
        v["tls_sha256"] = tls.fingerprint().into();
    }
    Json(v)
}

pub async fn get_rig(
    State(s): State<Arc<AppState>>,
    Query(q): Query<AtRevision>,
) -> Result<Response, ApiError> {
    let (rig, revision) = s.store.snapshot();
    let (doc, revision) = match q.revision {
        Some(r) if r != revision => (document_at(&s, "rig".into(), r).await?, r),
        _ => (
            serde_json::to_value(&rig.doc).expect("rigs serialise"),
            revision,
        ),
    };
    Ok(tagged(
        serde_json::json!({"revision": revision, "rig": doc}),
        revision,
    ))
}

/// Makes `rig` the new revision if `wanted` is still current; durable, with its history row,
/// before it returns. A plain write can be undone back to `wanted`.
pub async fn commit_rig(
    s: &Arc<AppState>,
    wanted: u64,
    rig: Rig,
    mut meta: Meta,
) -> Result<u64, ApiError> {
    let writer = s.store.rig_writer.clone().lock_owned().await;
    let (_, current) = s.store.snapshot();
    if wanted != current {
        return Err(ApiError::Stale { current });
    }
    let revision = current + 1;
    let state = s.clone();
    if matches!(meta.action, "put" | "apply") {
        meta.undo_to = Some(current);
    }
    // The write and the swap in memory are one task a client going away cannot stop (see
    // `channels::commit`), and the next writer waits for both.
    tokio::task::spawn_blocking(move || {
        let _writer = writer;
        state.store.save_rig(&rig.doc, revision, &meta)?;
        let ids: Vec<&str> = rig.doc.channels.iter().map(|c| c.id.as_str()).collect();
        state.captures.keep_channels(&ids);
        state.store.install(rig, revision);
        // Cached warps are keyed by content; those of the old rig can only take memory now.
        state.warps.lock().expect("cache lock").clear();
        state.computed.lock().expect("cache lock").clear();
        state.announce(serde_json::json!({"kind": "rig", "revision": revision}));
        tracing::info!(revision, "rig updated");
        Ok::<_, ApiError>(())
    })
    .await
    .map_err(|e| ApiError::Internal(e.to_string()))??;
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
    // Reading a mesh and validating a large rig is blocking work: in the pool, under a permit.
    let (state, text) = (s.clone(), text.to_string());
    let rig = run_write(&s, move |_| {
        Ok(state.store.accept_rig(&text, state.options.memory_budget)?)
    })
    .await?;
    let revision = commit_rig(&s, wanted, rig, meta(&s, "put", None)).await?;
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

/// The change feed: the rig's revision first, then every change as it is made, until the
/// server shuts down (the stream ends then, so shutting down does not wait on listeners).
pub async fn events(
    State(s): State<Arc<AppState>>,
) -> Result<Sse<impl Stream<Item = Result<Event, std::convert::Infallible>>>, ApiError> {
    let Ok(open) = s.feeds.clone().try_acquire_owned() else {
        return Err(ApiError::refused(
            axum::http::StatusCode::SERVICE_UNAVAILABLE,
            None,
            "the daemon holds as many change feeds open as it keeps; retry shortly",
        ));
    };
    let (_, now) = s.store.snapshot();
    let first = serde_json::json!({"kind": "rig", "revision": now}).to_string();
    let first = tokio_stream::once(Ok(Event::default().event("change").data(first)));
    // A subscriber too slow for the changes is told it missed some, so that it reads again
    // whatever it holds (the render nodes refetch every picture).
    let rest = BroadcastStream::new(s.events.subscribe()).map(|r| {
        let data = r.unwrap_or_else(|BroadcastStreamRecvError::Lagged(n)| {
            serde_json::json!({"kind": "lagged", "missed": n}).to_string()
        });
        Ok(Event::default().event("change").data(data))
    });
    let mut stopping = s.stopping.subscribe();
    // The feed's place is held as long as its stream, which ends with the connection.
    let stop = async move {
        let _open = open;
        let _ = stopping.wait_for(|&stop| stop).await;
    };
    Ok(Sse::new(futures_util::StreamExt::take_until(
        first.chain(rest),
        Box::pin(stop),
    ))
    .keep_alive(KeepAlive::default()))
}
