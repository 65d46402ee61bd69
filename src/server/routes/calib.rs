//! Calibration over HTTP: correspondences measured on the wall go in, a solved projector comes
//! back as a proposal (kept durably, announced on the change feed), and the technician applies
//! it to the rig with `If-Match` like any other rig edit.

use super::rig::commit_rig;
use crate::calibration::{CorrespondencesDoc, calibrate_unless};
use crate::rig::Rig;
use crate::server::ApiError;
use crate::server::http::jobs::run_job;
use crate::server::http::state::{AppState, if_match, meta, parse_body, tagged};
use crate::server::storage::store::Proposal;
use axum::body::Bytes;
use axum::extract::{Path, State};
use axum::http::{HeaderMap, StatusCode};
use axum::response::{IntoResponse, Response};
use std::sync::Arc;

pub async fn propose(
    State(s): State<Arc<AppState>>,
    Path(id): Path<String>,
    body: Bytes,
) -> Result<Response, ApiError> {
    let b: CorrespondencesDoc = parse_body(&body)?;
    let (rig, rig_revision) = s.store.snapshot();
    let ch = rig
        .channel(&id)
        .map_err(|_| ApiError::NotFound(format!("no channel `{id}`")))?;
    let (problem, choice) = b.problem([ch.width, ch.height], None)?;
    let resolution = [ch.width, ch.height];
    let cal = run_job(&s, move |cancel| {
        calibrate_unless(&problem, choice, cancel).map_err(|e| match e {
            crate::Error::Invalid { name, reason } => ApiError::Invalid {
                field: crate::rig::pointer_of(&name),
                reason,
            },
            other => other.into(),
        })
    })
    .await?;
    offer(&s, &id, rig_revision, resolution, &cal).await
}

/// Keeps a calibration as a proposal (durably, announced on the feed) and answers 201 with it.
pub async fn offer(
    s: &Arc<AppState>,
    id: &str,
    rig_revision: u64,
    resolution: [u32; 2],
    cal: &crate::calibration::Calibration,
) -> Result<Response, ApiError> {
    let proposal = keep_offer(s, id, rig_revision, resolution, cal).await?;
    Ok((
        StatusCode::CREATED,
        axum::Json(serde_json::to_value(&proposal).expect("proposals serialise")),
    )
        .into_response())
}

/// Stores `cal` as a proposal for channel `id` and announces it.
pub async fn keep_offer(
    s: &Arc<AppState>,
    id: &str,
    rig_revision: u64,
    resolution: [u32; 2],
    cal: &crate::calibration::Calibration,
) -> Result<Proposal, ApiError> {
    let proposal = Proposal {
        // The store gives the id as it saves.
        id: 0,
        channel: id.to_string(),
        rig_revision,
        proposed: cal.channel_doc(id, resolution),
        rms: cal.fit.rms,
        considered: cal
            .considered
            .iter()
            .map(|c| {
                serde_json::json!({"model": c.model.to_string(), "rms": c.rms,
                    "held_out_rms": c.held_out_rms, "verdict": c.verdict})
            })
            .collect(),
        sigma: cal.fit.sigma.clone(),
        warnings: cal.warnings.clone(),
        residuals: cal.fit.residuals.clone(),
        outliers: cal.fit.outliers.clone(),
    };
    let state = s.clone();
    let proposal = tokio::task::spawn_blocking(move || state.store.save_new_proposal(proposal))
        .await
        .map_err(|e| ApiError::Internal(e.to_string()))??;
    let pid = proposal.id;
    for old in s.store.keep_proposal(proposal.clone()) {
        s.announce(serde_json::json!({"kind": "proposal_dropped", "id": old}));
    }
    s.announce(serde_json::json!({"kind": "proposal", "channel": id, "id": pid}));
    Ok(proposal)
}

fn find(s: &AppState, pid: u64) -> Result<Arc<Proposal>, ApiError> {
    s.store
        .proposals
        .lock()
        .expect("proposal lock")
        .get(&pid)
        .cloned()
        .ok_or_else(|| ApiError::NotFound(format!("no proposal {pid}")))
}

/// A proposal id from the path; anything but a number names no proposal.
fn proposal_id(pid: &str) -> Result<u64, ApiError> {
    pid.parse()
        .map_err(|_| ApiError::NotFound(format!("no proposal `{pid}`: ids are numbers")))
}

pub async fn get_proposal(
    State(s): State<Arc<AppState>>,
    Path(pid): Path<String>,
) -> Result<Response, ApiError> {
    let p = find(&s, proposal_id(&pid)?)?;
    Ok(axum::Json(serde_json::to_value(&*p).expect("proposals serialise")).into_response())
}

/// Replaces the proposal's channel (lens, pose, resolution) in the rig; `If-Match` is the rig
/// revision.
pub async fn apply_proposal(
    State(s): State<Arc<AppState>>,
    Path(pid): Path<String>,
    headers: HeaderMap,
) -> Result<Response, ApiError> {
    let wanted = if_match(&headers)?;
    let p = find(&s, proposal_id(&pid)?)?;
    let (rig, _) = s.store.snapshot();
    let mut doc = rig.doc.clone();
    let slot = doc
        .channels
        .iter_mut()
        .find(|c| c.id == p.channel)
        .ok_or_else(|| {
            ApiError::NotFound(format!("the rig has no channel `{}` any more", p.channel))
        })?;
    *slot = p.proposed.clone();
    let next = Rig::from_doc(doc)?;
    next.check_budget(s.options.memory_budget)?;
    let change = rig
        .channel(&p.channel)
        .and_then(|before| Ok(before.change_to(next.channel(&p.channel)?)))?;
    let request = serde_json::json!({ "proposal": p.id });
    let revision = commit_rig(&s, wanted, next, meta(&s, "apply", Some(request))).await?;
    let mut body = serde_json::json!({"revision": revision, "change": change});
    if change.turned > crate::rig::ChannelChange::SUSPICIOUS_TURN {
        body["warning"] = format!(
            "channel {} now looks {:.0}° away from where the rig had it: if these were another \
             projector's points, undo the rig (POST /v1/rig/undo)",
            p.channel, change.turned
        )
        .into();
    }
    Ok(tagged(body, revision))
}
