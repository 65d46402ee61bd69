//! The render nodes' routes (`omniwarp play --daemon`): each node reports, about once a second
//! and whenever its picture changes, what every output of it shows — the channel and the ETag
//! of the picture on screen, which a client compares with the channel's `output.png` to know
//! the wall has caught up with an edit (a calibration loop waits for it before it triggers the
//! camera). The list itself is `http/nodes.rs`.

use crate::server::ApiError;
use crate::server::http::nodes::Report;
use crate::server::http::state::{AppState, parse_body};
use axum::Json;
use axum::body::Bytes;
use axum::extract::{Path, State};
use axum::http::StatusCode;
use std::sync::Arc;

/// `PUT /v1/nodes/{id}`: a node's report. 204; a new node, or one whose pictures changed, is
/// announced on the change feed (kind `node`).
pub async fn put(
    State(s): State<Arc<AppState>>,
    Path(id): Path<String>,
    body: Bytes,
) -> Result<StatusCode, ApiError> {
    let report: Report = parse_body(&body)?;
    if s.nodes.report(&id, report)? {
        s.announce(serde_json::json!({"kind": "node", "node": id}));
    }
    Ok(StatusCode::NO_CONTENT)
}

/// `GET /v1/nodes`: every node heard from, with the seconds since it last reported.
pub async fn list(State(s): State<Arc<AppState>>) -> Json<serde_json::Value> {
    Json(serde_json::json!({ "nodes": s.nodes.list() }))
}

/// `DELETE /v1/nodes/{id}`: forgets a node that is gone for good (one still running reports
/// again within a second).
pub async fn delete(
    State(s): State<Arc<AppState>>,
    Path(id): Path<String>,
) -> Result<StatusCode, ApiError> {
    if !s.nodes.forget(&id) {
        return Err(ApiError::NotFound(format!("no node `{id}`")));
    }
    s.announce(serde_json::json!({"kind": "node", "node": id}));
    Ok(StatusCode::NO_CONTENT)
}
