//! Helpers for the daemon's tests: a small rig, state on a data directory, oneshot calls.

use axum::body::Body;
use axum::http::{HeaderMap, Request, StatusCode, header};
use http_body_util::BodyExt;
use omniwarp::rig::RigDoc;
use omniwarp::server::{AppState, Store, router};
use std::io::{BufRead, BufReader};
use std::net::SocketAddr;
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::sync::Arc;
use tower::ServiceExt;

/// The two-projector flat rig at a tenth of its resolution, so warps are quick.
pub fn flat_rig() -> RigDoc {
    let text = std::fs::read_to_string(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("calibration/rigs/flat-2proj.json"),
    )
    .unwrap();
    let mut doc: RigDoc = serde_json::from_str(&text).unwrap();
    for c in &mut doc.channels {
        c.resolution = [192, 108];
        let i = &mut c.lens.intrinsics;
        i[0] /= 10.0;
        i[1] /= 10.0;
        i[2] = (i[2] + 0.5) / 10.0 - 0.5;
        i[3] = (i[3] + 0.5) / 10.0 - 0.5;
    }
    doc
}

pub fn state_with(dir: Option<&Path>, token: Option<&str>, rig: RigDoc) -> Arc<AppState> {
    AppState::new(
        Store::open(dir.map(Path::to_path_buf), Some(rig)).unwrap(),
        token.map(String::from),
    )
}

/// The daemon's built-in demo rig (three channels on a cylinder), as `serve --demo` holds it.
pub fn demo_rig() -> RigDoc {
    serde_json::from_str(omniwarp::rig::DEMO_RIG).unwrap()
}

/// In-memory state holding the demo rig, with no token.
pub fn demo_state() -> Arc<AppState> {
    state_with(None, None, demo_rig())
}

pub fn state(dir: Option<&Path>, token: Option<&str>) -> Arc<AppState> {
    state_with(dir, token, flat_rig())
}

pub async fn call(s: &Arc<AppState>, req: Request<Body>) -> (StatusCode, HeaderMap, Vec<u8>) {
    let resp = router(s.clone()).oneshot(req).await.unwrap();
    let (parts, body) = resp.into_parts();
    (
        parts.status,
        parts.headers,
        body.collect().await.unwrap().to_bytes().to_vec(),
    )
}

pub fn get(uri: &str) -> Request<Body> {
    Request::get(uri).body(Body::empty()).unwrap()
}

/// A write with an optional `If-Match` revision and a JSON body.
pub fn write(method: &str, uri: &str, if_match: Option<u64>, body: String) -> Request<Body> {
    let mut b = Request::builder()
        .method(method)
        .uri(uri)
        .header(header::CONTENT_TYPE, "application/json");
    if let Some(m) = if_match {
        b = b.header(header::IF_MATCH, format!("\"{m}\""));
    }
    b.body(Body::from(body)).unwrap()
}

pub fn json(bytes: &[u8]) -> serde_json::Value {
    serde_json::from_slice(bytes).unwrap()
}

/// Starts `omniwarp serve` on port 0 and returns it with the address it printed.
pub fn start(data: &Path, demo: bool) -> (Child, SocketAddr) {
    start_with(data, demo, &[])
}

/// [`start`] with more arguments for `serve`.
pub fn start_with(data: &Path, demo: bool, extra: &[&str]) -> (Child, SocketAddr) {
    start_on("127.0.0.1:0", data, demo, extra)
}

/// [`start_with`] on the address `bind` (a daemon restarted where its clients look for it).
pub fn start_on(bind: &str, data: &Path, demo: bool, extra: &[&str]) -> (Child, SocketAddr) {
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_omniwarp"));
    cmd.args(["serve", "--bind", bind, "--data"])
        .arg(data)
        .stdout(Stdio::piped())
        .stderr(Stdio::null());
    if demo {
        cmd.arg("--demo");
    }
    cmd.args(extra);
    let mut child = cmd.spawn().unwrap();
    let mut out = BufReader::new(child.stdout.take().unwrap());
    let mut line = String::new();
    out.read_line(&mut line).unwrap();
    let addr = line
        .trim()
        .strip_prefix("listening on http://")
        .unwrap_or_else(|| panic!("unexpected first line {line:?}"))
        .parse()
        .unwrap();
    (child, addr)
}

/// What the data directory's database holds as the current revision of `resource`.
#[allow(dead_code)]
pub fn stored(data: &Path, resource: &str) -> Option<(u64, serde_json::Value)> {
    let db = omniwarp::server::storage::db::Db::open(Some(
        &data.join(omniwarp::server::storage::db::FILE),
    ))
    .unwrap();
    db.current(resource).unwrap()
}
