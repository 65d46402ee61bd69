//! The omniwarp daemon: the rig over HTTP/JSON under `/v1`, revisions with `ETag`/`If-Match`,
//! per-channel outputs (warp map, blend mask, rendered preview), a change feed (Server-Sent
//! Events), atomic persistence under the data directory, and a bearer token whenever the
//! server listens beyond loopback. Every route is listed in [`router`] and in `api/openapi.yaml`.

mod error;
mod outputs;
mod state;

pub use error::ApiError;
pub use state::{AppState, Store};

use axum::Router;
use axum::extract::{Request, State};
use axum::http::header::AUTHORIZATION;
use axum::middleware::{self, Next};
use axum::response::Response;
use axum::routing::get;
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
    ("GET", "/v1/channels/{id}/warp.exr"),
    ("GET", "/v1/channels/{id}/blend.png"),
    ("GET", "/v1/channels/{id}/render.png"),
    ("GET", "/v1/events"),
];

pub fn router(state: Arc<AppState>) -> Router {
    Router::new()
        .route("/v1/health", get(state::health))
        .route("/v1/version", get(state::version))
        .route("/v1/rig", get(state::get_rig).put(state::put_rig))
        .route("/v1/channels", get(state::channels))
        .route("/v1/channels/{id}/warp.exr", get(outputs::warp))
        .route("/v1/channels/{id}/blend.png", get(outputs::blend))
        .route("/v1/channels/{id}/render.png", get(outputs::render))
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
