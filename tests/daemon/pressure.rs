//! Clients that take the daemon's room: uploads without the token, change feeds and idle
//! connections up to the caps, and pages from other sites loading what they cannot read.
//! Each case once went unanswered or was served (issue 42); health must answer through all.

use crate::common::server::{call, json, start_with, state};
use axum::body::Body;
use axum::http::{Request, StatusCode};
use omniwarp::server::client::Client;
use std::io::{Read, Write};
use std::net::{SocketAddr, TcpStream};
use std::time::{Duration, Instant};

/// The status of the answer on `c`, or 0 when none came within `within` (or the server
/// closed the connection unanswered).
pub(crate) fn status_within(c: &mut TcpStream, within: Duration) -> u16 {
    c.set_read_timeout(Some(within)).unwrap();
    let mut line = Vec::new();
    let mut b = [0u8];
    while matches!(c.read(&mut b), Ok(1)) && b[0] != b'\n' {
        line.push(b[0]);
    }
    String::from_utf8_lossy(&line)
        .split(' ')
        .nth(1)
        .and_then(|s| s.parse().ok())
        .unwrap_or(0)
}

fn send(addr: SocketAddr, request: &[u8]) -> TcpStream {
    let mut c = TcpStream::connect(addr).unwrap();
    c.write_all(request).unwrap();
    c
}

/// Without the token, a 60 MiB upload is refused on its headers: the daemon neither waits for
/// nor buffers the body (it did both, for up to 30 s and 64 MiB each, before answering 401).
#[test]
fn an_upload_without_the_token_is_refused_on_its_headers() {
    let dir = tempfile::tempdir().unwrap();
    let token = dir.path().join("token");
    std::fs::write(&token, "a-long-enough-secret-token").unwrap();
    let (mut child, addr) = start_with(
        &dir.path().join("data"),
        true,
        &["--token-file", token.to_str().unwrap()],
    );
    let head = format!(
        "PUT /v1/meshes/big.obj HTTP/1.1\r\nHost: {addr}\r\nContent-Length: {}\r\n\r\n",
        60 << 20
    );
    let mut uploads: Vec<TcpStream> = (0..12)
        .map(|_| {
            let mut c = send(addr, head.as_bytes());
            // The start of the body; the rest never comes.
            let _ = c.write_all(&[b'v'; 64 << 10]);
            c
        })
        .collect();
    for (i, c) in uploads.iter_mut().enumerate() {
        assert_eq!(
            status_within(c, Duration::from_secs(5)),
            401,
            "upload {i}: no 401 within 5 s of its headers"
        );
    }
    let r = Client::new(addr, Some("a-long-enough-secret-token".into()))
        .get("/v1/health")
        .unwrap();
    assert_eq!(r.status, 200);
    child.kill().unwrap();
    child.wait().unwrap();
}

/// Change feeds take at most half the connections (8 of 16 here; the 9th is 503), and a daemon
/// whose every connection is taken still answers health from its reserve (and 503 for any
/// other route) instead of closing the connection unanswered.
#[test]
fn feeds_and_idle_connections_up_to_the_cap_leave_health_answered() {
    let dir = tempfile::tempdir().unwrap();
    let (mut child, addr) = start_with(dir.path(), true, &["--max-connections", "16"]);
    let feed = format!("GET /v1/events HTTP/1.1\r\nHost: {addr}\r\n\r\n");
    let mut feeds: Vec<TcpStream> = (0..8).map(|_| send(addr, feed.as_bytes())).collect();
    for (i, c) in feeds.iter_mut().enumerate() {
        assert_eq!(status_within(c, Duration::from_secs(5)), 200, "feed {i}");
    }
    let mut ninth = send(addr, feed.as_bytes());
    assert_eq!(status_within(&mut ninth, Duration::from_secs(5)), 503);
    // The rest of the connections say nothing (the header deadline would close them in 10 s).
    let _idle: Vec<TcpStream> = (0..7).map(|_| send(addr, b"")).collect();
    std::thread::sleep(Duration::from_millis(300));
    let t = Instant::now();
    let r = Client::new(addr, None).get("/v1/health").unwrap();
    assert_eq!(r.status, 200, "health at the cap");
    assert!(t.elapsed() < Duration::from_secs(1), "{:?}", t.elapsed());
    let r = Client::new(addr, None).get("/v1/rig").unwrap();
    assert_eq!(r.status, 503, "another route at the cap");
    child.kill().unwrap();
    child.wait().unwrap();
}

/// What an `<img>` or `<script>` on another site sends: no Origin, `Sec-Fetch-Site:
/// cross-site`. Refused, so a web page cannot keep the workers busy with renders and exports;
/// the daemon's own console (`same-origin`) and a typed address (`none`) pass.
#[tokio::test]
async fn a_page_from_another_site_cannot_load_from_the_daemon() {
    let s = state(None, None);
    let load = |site: &str| {
        Request::get("/v1/rig")
            .header("sec-fetch-site", site)
            .body(Body::empty())
            .unwrap()
    };
    for site in ["cross-site", "same-site"] {
        let (status, _, body) = call(&s, load(site)).await;
        assert_eq!(
            (status, json(&body)["field"].as_str()),
            (StatusCode::FORBIDDEN, Some("Sec-Fetch-Site")),
            "{site}"
        );
    }
    for site in ["same-origin", "none"] {
        let (status, _, body) = call(&s, load(site)).await;
        assert_eq!(status, StatusCode::OK, "{site}: {}", json(&body));
    }
}
