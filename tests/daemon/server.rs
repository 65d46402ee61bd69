//! The daemon's routes through `oneshot` (no socket), one real server on port 0, and the
//! OpenAPI document checked against the router.

use crate::common;

use axum::body::Body;
use axum::http::{Request, StatusCode, header};
use common::server::{call, get, json, state};
use omniwarp::server::ROUTES;
use std::path::Path;

fn put_rig(body: String, if_match: Option<&str>) -> Request<Body> {
    let mut b = Request::put("/v1/rig").header(header::CONTENT_TYPE, "application/json");
    if let Some(m) = if_match {
        b = b.header(header::IF_MATCH, m);
    }
    b.body(Body::from(body)).unwrap()
}

#[tokio::test]
async fn every_route_answers_and_every_error_class_is_reported() {
    let dir = tempfile::tempdir().unwrap();
    let s = state(Some(dir.path()), None);
    let (st, _, body) = call(&s, get("/v1/health")).await;
    assert_eq!(
        (st, json(&body)["status"].as_str()),
        (StatusCode::OK, Some("ok"))
    );
    let (st, _, body) = call(&s, get("/v1/version")).await;
    assert_eq!(
        (st, json(&body)["api"].as_str()),
        (StatusCode::OK, Some("v1"))
    );
    let (st, headers, body) = call(&s, get("/v1/rig")).await;
    assert_eq!(st, StatusCode::OK);
    assert_eq!(headers[header::ETAG], "\"1\"");
    let doc = json(&body)["rig"].clone();
    let (_, _, body) = call(&s, get("/v1/channels")).await;
    assert_eq!(json(&body)["channels"].as_array().unwrap().len(), 2);

    // Outputs.
    let (st, h, body) = call(&s, get("/v1/channels/left/warp.exr")).await;
    assert_eq!(
        (st, h[header::CONTENT_TYPE].to_str().unwrap()),
        (StatusCode::OK, "image/x-exr")
    );
    assert_eq!(&body[..4], &[0x76, 0x2f, 0x31, 0x01], "EXR magic");
    let (st, _, body) = call(&s, get("/v1/channels/left/blend.png?gamma=2.4")).await;
    assert_eq!((st, &body[1..4]), (StatusCode::OK, &b"PNG"[..]));
    let (st, _, body) = call(&s, get("/v1/channels/right/render?face=32")).await;
    assert_eq!((st, &body[1..4]), (StatusCode::OK, &b"PNG"[..]));

    // Errors: unknown channel or route, bad query, missing/stale If-Match, invalid body.
    assert_eq!(
        call(&s, get("/v1/channels/nope/warp.exr")).await.0,
        StatusCode::NOT_FOUND
    );
    assert_eq!(call(&s, get("/v1/nothing")).await.0, StatusCode::NOT_FOUND);
    let (st, _, body) = call(&s, get("/v1/channels/left/render?face=4")).await;
    assert_eq!(
        (st, json(&body)["field"].as_str()),
        (StatusCode::BAD_REQUEST, Some("face"))
    );
    assert_eq!(
        call(&s, get("/v1/channels/left/blend.png?gamma=0")).await.0,
        StatusCode::BAD_REQUEST
    );
    assert_eq!(
        call(&s, put_rig(doc.to_string(), None)).await.0,
        StatusCode::PRECONDITION_REQUIRED
    );
    let (st, h, body) = call(&s, put_rig(doc.to_string(), Some("\"7\""))).await;
    assert_eq!(
        (st, h[header::ETAG].to_str().unwrap()),
        (StatusCode::PRECONDITION_FAILED, "\"1\"")
    );
    assert_eq!(json(&body)["current_revision"], 1);
    let mut bad = doc.clone();
    bad["channels"][1]["lens"]["intrinsics"] = serde_json::json!([1, 2, 3]);
    let (st, _, body) = call(&s, put_rig(bad.to_string(), Some("\"1\""))).await;
    assert_eq!(
        (st, json(&body)["field"].as_str()),
        (StatusCode::BAD_REQUEST, Some("/channels/1/lens/intrinsics"))
    );
    let mut unknown = doc.clone();
    unknown["colour"] = serde_json::json!(1);
    assert_eq!(
        call(&s, put_rig(unknown.to_string(), Some("\"1\"")))
            .await
            .0,
        StatusCode::BAD_REQUEST
    );

    // A good edit: new revision, durable, and the old one is stale now.
    let mut moved = doc.clone();
    moved["eye"] = serde_json::json!([0.0, 0.1, 0.0]);
    let (st, h, _) = call(&s, put_rig(moved.to_string(), Some("\"1\""))).await;
    assert_eq!(
        (st, h[header::ETAG].to_str().unwrap()),
        (StatusCode::OK, "\"2\"")
    );
    let (revision, saved) = common::server::stored(dir.path(), "rig").unwrap();
    assert_eq!((revision, saved["eye"][1].as_f64()), (2, Some(0.1)));
    assert_eq!(
        call(&s, put_rig(moved.to_string(), Some("\"1\""))).await.0,
        StatusCode::PRECONDITION_FAILED
    );

    // A restart finds revision 2.
    let again = state(Some(dir.path()), None);
    assert_eq!(again.store.snapshot().1, 2);
    assert_eq!(again.store.snapshot().0.doc.eye[1], 0.1);
}

#[tokio::test]
async fn a_token_is_required_when_configured() {
    let s = state(None, Some("a-long-enough-secret-token"));
    assert_eq!(
        call(&s, get("/v1/health")).await.0,
        StatusCode::UNAUTHORIZED
    );
    let wrong = Request::get("/v1/health")
        .header(header::AUTHORIZATION, "Bearer nope")
        .body(Body::empty())
        .unwrap();
    assert_eq!(call(&s, wrong).await.0, StatusCode::UNAUTHORIZED);
    let right = Request::get("/v1/health")
        .header(header::AUTHORIZATION, "Bearer a-long-enough-secret-token")
        .body(Body::empty())
        .unwrap();
    assert_eq!(call(&s, right).await.0, StatusCode::OK);
}

#[tokio::test]
async fn a_real_server_on_port_0_serves_and_shuts_down() {
    let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
    let addr = listener.local_addr().unwrap();
    let (stop, stopped) = tokio::sync::oneshot::channel::<()>();
    let server = tokio::spawn(omniwarp::server::launch(
        listener,
        state(None, None),
        async {
            let _ = stopped.await;
        },
    ));
    let mut stream = tokio::net::TcpStream::connect(addr).await.unwrap();
    use tokio::io::{AsyncReadExt, AsyncWriteExt};
    stream
        .write_all(b"GET /v1/health HTTP/1.1\r\nHost: 127.0.0.1\r\nConnection: close\r\n\r\n")
        .await
        .unwrap();
    let mut text = String::new();
    stream.read_to_string(&mut text).await.unwrap();
    assert!(
        text.starts_with("HTTP/1.1 200") && text.contains("\"ok\""),
        "{text}"
    );
    stop.send(()).unwrap();
    tokio::time::timeout(std::time::Duration::from_secs(10), server)
        .await
        .unwrap()
        .unwrap()
        .unwrap();
}

#[test]
fn the_openapi_document_lists_exactly_the_routes() {
    let doc =
        std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("api/openapi.yaml"))
            .unwrap();
    let mut listed = Vec::new();
    let mut path = None;
    for line in doc.lines() {
        if let Some(p) = line.strip_prefix("  /").and_then(|l| l.strip_suffix(':')) {
            path = Some(format!("/{p}"));
        } else if let (Some(p), Some(m)) = (
            &path,
            line.strip_prefix("    ").and_then(|l| l.strip_suffix(':')),
        ) && ["get", "put", "post", "patch", "delete"].contains(&m)
        {
            listed.push((m.to_uppercase(), p.clone()));
        }
    }
    let mut routes: Vec<(String, String)> = ROUTES
        .iter()
        .map(|(m, p)| (m.to_string(), p.to_string()))
        .collect();
    listed.sort();
    routes.sort();
    assert_eq!(listed, routes);
}

/// Every route of the table reaches its handler: asked with a channel and proposal that do not
/// exist and an empty body, it answers with its own error (or its content), never the router's
/// fallback 404 or a 405. Together with the test above (the document lists exactly
/// [`ROUTES`], which the router is built from), a route cannot be served undocumented or
/// documented unserved.
#[tokio::test]
async fn every_documented_route_reaches_its_handler() {
    use tower::ServiceExt;
    let s = state(None, None);
    for (method, path) in ROUTES {
        let uri = path
            .replace("{id}", "no-such-channel")
            .replace("{pid}", "999")
            .replace("{file}", "stmap.exr");
        let req = Request::builder()
            .method(*method)
            .uri(&uri)
            .header(header::CONTENT_TYPE, "application/json")
            .body(Body::from("{}"))
            .unwrap();
        let resp = omniwarp::server::router(s.clone())
            .oneshot(req)
            .await
            .unwrap();
        let status = resp.status();
        assert_ne!(status, StatusCode::METHOD_NOT_ALLOWED, "{method} {path}");
        if status == StatusCode::NOT_FOUND {
            use http_body_util::BodyExt;
            let body = resp.into_body().collect().await.unwrap().to_bytes();
            let text = String::from_utf8_lossy(&body);
            assert!(!text.contains("no such route"), "{method} {path}: {text}");
        }
    }
}
