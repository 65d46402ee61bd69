//! The omniwarp daemon: the rig over HTTP/JSON under `/v1`, revisions with `ETag`/`If-Match`,
//! per-channel outputs (warp map, blend mask, rendered preview), a change feed (Server-Sent
//! Events), atomic persistence under the data directory, and a bearer token whenever the
//! server listens beyond loopback. Every route is in one table (the `routes!` call below), from which both the router and
//! [`ROUTES`] are made; `api/openapi.yaml` documents the same routes (a test checks).

mod cache;
mod calib;
mod channels;
pub mod client;
mod error;
mod exports;
mod jobs;
mod outputs;
mod preview;
mod rig;
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
use std::future::Future;
use std::sync::Arc;
use tokio::net::TcpListener;

/// The route table, written once: it builds the router and lists every (method, path) in
/// [`ROUTES`], which `api/openapi.yaml` is checked against, so the two cannot drift.
macro_rules! routes {
    ($($path:literal => $first:ident($h:path) $(. $more:ident($hm:path))*;)*) => {
        /// Every route of the API as (method, path), in the order of the table.
        pub const ROUTES: &[(&str, &str)] = &[
            $((routes!(@method $first), $path), $((routes!(@method $more), $path),)*)*
        ];

        fn table() -> Router<Arc<AppState>> {
            Router::new()$(.route($path, axum::routing::$first($h)$(.$more($hm))*))*
        }
    };
    (@method get) => { "GET" };
    (@method put) => { "PUT" };
    (@method post) => { "POST" };
    (@method patch) => { "PATCH" };
    (@method delete) => { "DELETE" };
}

routes! {
    "/v1/health" => get(rig::health);
    "/v1/version" => get(rig::version);
    "/v1/rig" => get(rig::get_rig).put(rig::put_rig);
    "/v1/channels" => get(rig::channels);
    "/v1/channels/{id}/content" => get(channels::get_content).put(channels::put_content);
    "/v1/channels/{id}/tiles" => get(channels::get_tiles)
        .put(channels::put_tiles)
        .patch(channels::patch_tiles)
        .delete(channels::delete_tiles);
    "/v1/channels/{id}/calibration" => post(calib::propose);
    "/v1/proposals/{pid}" => get(calib::get_proposal);
    "/v1/proposals/{pid}/apply" => post(calib::apply_proposal);
    "/v1/channels/{id}/warp.exr" => get(outputs::warp);
    "/v1/channels/{id}/blend.png" => get(outputs::blend);
    "/v1/channels/{id}/render" => get(outputs::render);
    "/v1/channels/{id}/exports/{file}" => get(exports::channel_export);
    "/v1/export.mpcdi" => get(exports::mpcdi_package);
    "/v1/events" => get(rig::events);
}

pub fn router(state: Arc<AppState>) -> Router {
    table()
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
