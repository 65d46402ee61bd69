//! The omniwarp daemon: the rig over HTTP/JSON under `/v1`, revisions with `ETag`/`If-Match`,
//! per-channel outputs (warp map, blend mask, rendered preview), a change feed (Server-Sent
//! Events), atomic persistence under the data directory, and a bearer token whenever the
//! server listens beyond loopback. Every route is listed in [`router`] and in `api/openapi.yaml`.

mod calib;
mod channels;
pub mod client;
mod error;
mod exports;
mod outputs;
mod state;
mod store;

pub use error::ApiError;
pub use state::AppState;
pub use store::{Canvas, ChannelData, Store};

use axum::Router;
use axum::extract::{Request, State};
use axum::http::header::AUTHORIZATION;
use axum::middleware::{self, Next};
use axum::response::Response;
use axum::routing::{get, post};
use std::future::Future;
use std::sync::Arc;
use tokio::net::TcpListener;

/// Every route of the API; `api/openapi.yaml` lists the same (a test checks).
pub const ROUTES: &[(&str, &str)] = &[
    ("GET", "/v1/health"),
    ("GET", "/v1/version"),
    ("GET", "/v1/rig"),
    ("PUT", "/v1/rig"),
    ("GET", "/v1/channels"),
    ("GET", "/v1/channels/{id}/content"),
    ("PUT", "/v1/channels/{id}/content"),
    ("GET", "/v1/channels/{id}/tiles"),
    ("PUT", "/v1/channels/{id}/tiles"),
    ("PATCH", "/v1/channels/{id}/tiles"),
    ("DELETE", "/v1/channels/{id}/tiles"),
    ("POST", "/v1/channels/{id}/calibration"),
    ("GET", "/v1/proposals/{pid}"),
    ("POST", "/v1/proposals/{pid}/apply"),
    ("GET", "/v1/channels/{id}/warp.exr"),
    ("GET", "/v1/channels/{id}/blend.png"),
    ("GET", "/v1/channels/{id}/render"),
    ("GET", "/v1/channels/{id}/exports/{file}"),
    ("GET", "/v1/export.mpcdi"),
    ("GET", "/v1/events"),
];

pub fn router(state: Arc<AppState>) -> Router {
    Router::new()
        .route("/v1/health", get(state::health))
        .route("/v1/version", get(state::version))
        .route("/v1/rig", get(state::get_rig).put(state::put_rig))
        .route("/v1/channels", get(state::channels))
        .route(
            "/v1/channels/{id}/content",
            get(channels::get_content).put(channels::put_content),
        )
        .route(
            "/v1/channels/{id}/tiles",
            get(channels::get_tiles)
                .put(channels::put_tiles)
                .patch(channels::patch_tiles)
                .delete(channels::delete_tiles),
        )
        .route("/v1/channels/{id}/calibration", post(calib::propose))
        .route("/v1/proposals/{pid}", get(calib::get_proposal))
        .route("/v1/proposals/{pid}/apply", post(calib::apply_proposal))
        .route("/v1/channels/{id}/warp.exr", get(outputs::warp))
        .route("/v1/channels/{id}/blend.png", get(outputs::blend))
        .route("/v1/channels/{id}/render", get(outputs::render))
        .route(
            "/v1/channels/{id}/exports/{file}",
            get(exports::channel_export),
        )
        .route("/v1/export.mpcdi", get(exports::mpcdi_package))
        .route("/v1/events", get(state::events))
        .fallback(|| async { ApiError::NotFound("no such route".into()) })
        .layer(axum::extract::DefaultBodyLimit::max(state::MAX_BODY))
        .layer(middleware::from_fn_with_state(state.clone(), auth))
        .with_state(state)
}

/// With a token configured, every request must carry `Authorization: Bearer <token>`.
async fn auth(
    State(state): State<Arc<AppState>>,
    req: Request,
    next: Next,
) -> Result<Response, ApiError> {
    if let Some(token) = &state.token {
        let given = req
            .headers()
            .get(AUTHORIZATION)
            .and_then(|v| v.to_str().ok())
            .and_then(|v| v.strip_prefix("Bearer "));
        // Constant-time comparison: the token is a secret.
        let ok = given.is_some_and(|g| {
            g.len() == token.len()
                && g.bytes()
                    .zip(token.bytes())
                    .fold(0u8, |a, (x, y)| a | (x ^ y))
                    == 0
        });
        if !ok {
            return Err(ApiError::Unauthorized);
        }
    }
    Ok(next.run(req).await)
}

/// Serves until `shutdown` completes, then lets in-flight requests finish.
pub async fn launch(
    listener: TcpListener,
    state: Arc<AppState>,
    shutdown: impl Future<Output = ()> + Send + 'static,
) -> std::io::Result<()> {
    axum::serve(listener, router(state))
        .with_graceful_shutdown(shutdown)
        .await
}
