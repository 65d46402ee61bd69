//! `GET /v1/rig/plan` and `/v1/rig/plan.png`: the current rig's plan (crate::rig::plan) as
//! figures and as a picture, computed in the worker pool.

use crate::server::ApiError;
use crate::server::http::jobs::run_job;
use crate::server::http::state::{AppState, Query, tagged};
use crate::server::routes::outputs::file;
use axum::extract::State;
use axum::response::Response;
use serde::Deserialize;
use std::sync::Arc;

#[derive(Deserialize, Default)]
#[serde(deny_unknown_fields)]
pub struct PlanQuery {
    /// The sampling grid's step, degrees.
    #[serde(default)]
    step: Option<f64>,
    /// The picture's width, pixels.
    #[serde(default)]
    width: Option<usize>,
}

pub async fn plan(
    State(s): State<Arc<AppState>>,
    Query(q): Query<PlanQuery>,
) -> Result<Response, ApiError> {
    if q.width.is_some() {
        return Err(ApiError::Invalid {
            field: "width".into(),
            reason: "is for the picture, /v1/rig/plan.png".into(),
        });
    }
    let step = q.step.unwrap_or(crate::rig::plan::STEP);
    let (rig, revision) = s.store.snapshot();
    let mut body = run_job(&s, move |_| {
        let plan = rig.plan(step)?;
        Ok(serde_json::to_value(plan).expect("a plan is JSON"))
    })
    .await?;
    body["revision"] = revision.into();
    Ok(tagged(body, revision))
}

pub async fn picture(
    State(s): State<Arc<AppState>>,
    Query(q): Query<PlanQuery>,
) -> Result<Response, ApiError> {
    let step = q.step.unwrap_or(crate::rig::plan::STEP);
    let width = q.width.unwrap_or(1200);
    let (rig, revision) = s.store.snapshot();
    let png = run_job(&s, move |_| {
        let img = rig.plan(step).and_then(|p| p.picture(&rig, width))?;
        Ok(crate::image_io::png_bytes(&img)?)
    })
    .await?;
    file(&s, png, "image/png", &format!("\"{revision}\""))
}
