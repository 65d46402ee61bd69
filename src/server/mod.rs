//! The omniwarp daemon: the rig over HTTP/JSON under `/v1`, revisions with `ETag`/`If-Match`,
//! per-channel outputs (warp map, blend mask, rendered preview), a change feed (Server-Sent
//! Events), atomic persistence under the data directory, and a bearer token whenever the
//! server listens beyond loopback. Every route is in one table (the `routes!` call below), from which both the router and
//! [`ROUTES`] are made; `api/openapi.yaml` documents the same routes (a test checks).

pub mod client;
mod http;
mod previews;
pub mod renders;
mod routes;
pub mod storage;
pub mod tls;

use http::guard;
use routes::{
    calib, captures, channels, console, exports, geometry, history, meshes, nodes, outputs, plan,
    renders as jobs, rig, show,
};

pub use crate::rig::Canvas;
pub use http::error::ApiError;
pub use http::guard::{BODY_TIMEOUT, MAX_HEADERS, MAX_URI};
pub use http::state::{AppState, FEEDS, MAX_BODY, Options, STREAMS, WORKERS};
pub use storage::db::Retention;
pub use storage::store::{ChannelData, OpenOptions, Store};

use axum::Router;
use axum::middleware;
use std::future::Future;
use std::sync::Arc;
use std::time::Duration;
use tokio::net::TcpListener;
use tokio::sync::Semaphore;

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
    "/v1/rig/revert" => post(history::rig_revert);
    "/v1/rig/undo" => post(history::rig_undo);
    "/v1/rig/redo" => post(history::rig_redo);
    "/v1/rig/geometry" => get(geometry::geometry);
    "/v1/rig/plan" => get(plan::plan);
    "/v1/rig/plan.png" => get(plan::picture);
    "/v1/history" => get(history::list);
    "/v1/channels" => get(rig::channels);
    "/v1/channels/{id}/content" => get(channels::get_content)
        .put(channels::put_content)
        .delete(channels::delete_content);
    "/v1/channels/{id}/content/revert" => post(history::content_revert);
    "/v1/channels/{id}/content/undo" => post(history::content_undo);
    "/v1/channels/{id}/content/redo" => post(history::content_redo);
    "/v1/channels/{id}/tiles" => get(channels::get_tiles)
        .put(channels::put_tiles)
        .patch(channels::patch_tiles)
        .delete(channels::delete_tiles);
    "/v1/channels/{id}/tiles/revert" => post(history::tiles_revert);
    "/v1/channels/{id}/tiles/undo" => post(history::tiles_undo);
    "/v1/channels/{id}/tiles/redo" => post(history::tiles_redo);
    "/v1/channels/{id}/calibration" => post(calib::propose);
    "/v1/proposals/{pid}" => get(calib::get_proposal);
    "/v1/proposals/{pid}/apply" => post(calib::apply_proposal);
    "/v1/channels/{id}/warp.exr" => get(outputs::warp);
    "/v1/channels/{id}/blend.png" => get(outputs::blend);
    "/v1/channels/{id}/render" => get(outputs::render);
    "/v1/channels/{id}/show" => get(show::get_show).put(show::put_show);
    "/v1/channels/{id}/output.png" => get(show::output);
    "/v1/channels/{id}/pattern/{n}" => get(show::pattern);
    "/v1/channels/{id}/captures" => get(captures::get_captures)
        .post(captures::post_captures)
        .delete(captures::delete_captures);
    "/v1/channels/{id}/captures/{n}" => put(captures::put_capture);
    "/v1/channels/{id}/wall" => post(captures::post_wall);
    "/v1/channels/{id}/exports/{file}" => get(exports::channel_export);
    "/v1/export.mpcdi" => get(exports::mpcdi_package);
    "/v1/jobs" => get(jobs::list).post(jobs::create);
    "/v1/jobs/{id}" => get(jobs::get_job).delete(jobs::delete);
    "/v1/jobs/{id}/cancel" => post(jobs::cancel);
    "/v1/jobs/{id}/files/{name}" => get(jobs::file);
    "/v1/meshes" => get(meshes::list);
    "/v1/meshes/{name}" => put(meshes::put).delete(meshes::delete);
    "/v1/nodes" => get(nodes::list);
    "/v1/nodes/{id}" => put(nodes::put).delete(nodes::delete);
    "/v1/events" => get(rig::events);
}

/// The daemon's HTTP service: every route of the table with the guard, token check and JSON
/// errors around it.
pub fn router(state: Arc<AppState>) -> Router {
    // Layers run outside in: JSON errors, then the guard (Host, Origin, the token, sizes, the
    // body), then the route.
    table()
        .merge(console::routes())
        .fallback(|| async { ApiError::NotFound("no such route".into()) })
        .method_not_allowed_fallback(|| async {
            ApiError::refused(
                axum::http::StatusCode::METHOD_NOT_ALLOWED,
                None,
                "this route does not take that method",
            )
        })
        .layer(axum::extract::DefaultBodyLimit::max(
            crate::limits::MESH_BYTES as usize,
        ))
        .layer(middleware::from_fn_with_state(state.clone(), guard::guard))
        .layer(middleware::from_fn(guard::json_errors))
        .with_state(state)
}

/// Time a client has to send a request's headers (on a new or a kept-alive connection).
pub const HEADER_TIMEOUT: Duration = Duration::from_secs(10);
/// Time a response may wait on a client that does not read it.
pub const WRITE_TIMEOUT: Duration = Duration::from_secs(60);
/// Connections open at once by default (`serve --max-connections`); more are closed as they
/// arrive, beyond the [`RESERVE`]. Lowered to fit the process's file limit, which is raised to
/// its hard limit first.
pub const CONNECTIONS: usize = 4096;
/// Connections beyond the cap that are still answered, one request each: health, so a
/// monitor sees a daemon that is full rather than a dead one, and 503 for anything else.
pub const RESERVE: usize = 16;
/// Time a connection in the [`RESERVE`] has to send its request's headers.
const RESERVE_HEADER_TIMEOUT: Duration = Duration::from_secs(2);
/// How long shutting down waits for requests in flight before it gives up on them.
pub const DRAIN: Duration = Duration::from_secs(5);

/// The connection cap this process can keep: `wanted`, or fewer where the file limit (raised
/// to its hard limit) leaves less room beside the reserve and the files the daemon itself
/// opens.
fn connection_cap(wanted: usize) -> usize {
    let files = rlimit::increase_nofile_limit(u64::MAX).unwrap_or(1024);
    let room = usize::try_from(files.saturating_sub(256 + RESERVE as u64)).unwrap_or(usize::MAX);
    wanted.min(room.max(16))
}

/// What a connection in the reserve is served: health, and 503 for every other route.
fn reserve_router(state: Arc<AppState>) -> Router {
    Router::new()
        .route("/v1/health", axum::routing::get(routes::rig::health))
        .fallback(|| async {
            ApiError::refused(
                axum::http::StatusCode::SERVICE_UNAVAILABLE,
                None,
                "the daemon is at its connection cap; retry shortly",
            )
        })
        .layer(middleware::from_fn_with_state(state.clone(), guard::guard))
        .layer(middleware::from_fn(guard::json_errors))
        .with_state(state)
}

/// What a connection is read from and written to: TCP, or TLS over it.
trait Io: tokio::io::AsyncRead + tokio::io::AsyncWrite + Send + Unpin {}
impl<T: tokio::io::AsyncRead + tokio::io::AsyncWrite + Send + Unpin> Io for T {}

/// Serves until `shutdown` completes, then stops accepting, ends the change feeds and lets
/// requests in flight finish for up to [`DRAIN`].
///
/// Each connection has a header deadline ([`HEADER_TIMEOUT`], so slow or idle clients cannot
/// hold connections), a write deadline ([`WRITE_TIMEOUT`]) and counts against the connection
/// cap; request bodies have their own deadline in the guard.
pub async fn launch(
    listener: TcpListener,
    state: Arc<AppState>,
    shutdown: impl Future<Output = ()> + Send + 'static,
) -> std::io::Result<()> {
    use hyper_util::rt::{TokioIo, TokioTimer};
    let _ = state.bound.set(listener.local_addr()?);
    let app = router(state.clone());
    let reserve_app = reserve_router(state.clone());
    let cap = connection_cap(state.options.connections);
    let open = Arc::new(Semaphore::new(cap));
    let reserve = Arc::new(Semaphore::new(RESERVE));
    let graceful = hyper_util::server::graceful::GracefulShutdown::new();
    let mut http = hyper::server::conn::http1::Builder::new();
    http.timer(TokioTimer::new())
        .header_read_timeout(HEADER_TIMEOUT)
        .max_buf_size(MAX_HEADERS * 4);
    let mut reserve_http = http.clone();
    reserve_http
        .header_read_timeout(RESERVE_HEADER_TIMEOUT)
        .keep_alive(false);
    let acceptor = state.options.tls.as_ref().map(tls::Tls::acceptor);
    tokio::pin!(shutdown);
    loop {
        let acceptor = acceptor.clone();
        let stream = tokio::select! {
            accepted = listener.accept() => match accepted {
                Ok((stream, _)) => stream,
                Err(e) => {
                    // Out of file descriptors or similar: wait a moment rather than spin.
                    tracing::warn!(error = %e, "accept failed");
                    tokio::time::sleep(Duration::from_millis(50)).await;
                    continue;
                }
            },
            () = &mut shutdown => break,
        };
        let (permit, app, http) = match open.clone().try_acquire_owned() {
            Ok(p) => (p, &app, &http),
            Err(_) => match reserve.clone().try_acquire_owned() {
                Ok(p) => (p, &reserve_app, &reserve_http),
                Err(_) => {
                    tracing::warn!(cap, "connection refused: at the connection cap");
                    continue;
                }
            },
        };
        let _ = stream.set_nodelay(true);
        let mut io = tokio_io_timeout::TimeoutStream::new(stream);
        io.set_write_timeout(Some(WRITE_TIMEOUT));
        let io = Box::pin(io);
        let service = hyper_util::service::TowerToHyperService::new(app.clone());
        let (http, watcher) = (http.clone(), graceful.watcher());
        tokio::spawn(async move {
            // The handshake runs in the connection's own task, under the header deadline, so a
            // client that stalls in it holds one permit and nothing else.
            let io: Box<dyn Io> = match &acceptor {
                None => Box::new(io),
                Some(a) => match tokio::time::timeout(HEADER_TIMEOUT, a.accept(io)).await {
                    Ok(Ok(tls)) => Box::new(tls),
                    _ => return,
                },
            };
            let conn = http.serve_connection(TokioIo::new(io), service);
            let _ = watcher.watch(conn).await;
            drop(permit);
        });
    }
    drop(listener);
    state.stopping.send_replace(true);
    // Alongside the requests' drain, render jobs stop (and no new one is taken): the running
    // one between frames, removing what it had written, its ffmpeg children with it.
    let requests = async {
        tokio::select! {
            () = graceful.shutdown() => {}
            () = tokio::time::sleep(DRAIN) => {
                tracing::warn!("requests still running after {} s; stopping anyway", DRAIN.as_secs());
            }
        }
    };
    tokio::join!(requests, state.renders.stop_all(DRAIN));
    Ok(())
}
