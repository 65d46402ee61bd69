//! The console's side of the daemon through `oneshot`: its files (served without the token, with
//! the headers that keep other sites from framing or feeding it), the test cards a channel is
//! sent and what it then puts out, and the rig's geometry for drawing it. The console itself is
//! tested in Chromium by `scripts/console-test` (tests/console/).

use crate::common;

use axum::body::Body;
use axum::http::{Request, StatusCode, header};
use common::server::{call, get, json, state, write};

fn with_token(uri: &str, token: &str) -> Request<Body> {
    Request::get(uri)
        .header(header::AUTHORIZATION, format!("Bearer {token}"))
        .body(Body::empty())
        .unwrap()
}

#[tokio::test]
async fn the_console_is_served_without_the_token_and_the_api_still_needs_it() {
    let s = state(None, Some("secret"));
    for path in ["/", "/console/", "/console/app.js", "/console/tiles.js"] {
        let (st, h, body) = call(&s, get(path)).await;
        assert_eq!(st, StatusCode::OK, "{path}");
        assert_eq!(h[header::X_FRAME_OPTIONS], "DENY", "{path}");
        let csp = h[header::CONTENT_SECURITY_POLICY].to_str().unwrap();
        assert!(csp.contains("frame-ancestors 'none'") && csp.contains("connect-src 'self'"));
        assert!(!body.is_empty());
    }
    let (_, h, body) = call(&s, get("/")).await;
    assert!(
        h[header::CONTENT_TYPE]
            .to_str()
            .unwrap()
            .starts_with("text/html")
    );
    assert!(String::from_utf8(body).unwrap().contains("/console/app.js"));
    let (_, h, _) = call(&s, get("/console/app.js")).await;
    assert!(
        h[header::CONTENT_TYPE]
            .to_str()
            .unwrap()
            .starts_with("text/javascript")
    );
    assert_eq!(
        call(&s, get("/console")).await.0,
        StatusCode::PERMANENT_REDIRECT
    );
    let (st, _, body) = call(&s, get("/console/../omniwarp.db")).await;
    assert_eq!(
        st,
        StatusCode::NOT_FOUND,
        "{}",
        String::from_utf8_lossy(&body)
    );
    assert_eq!(
        call(&s, get("/console/nope.js")).await.0,
        StatusCode::NOT_FOUND
    );
    // The files are public; the API is not.
    assert_eq!(call(&s, get("/v1/rig")).await.0, StatusCode::UNAUTHORIZED);
    assert_eq!(
        call(&s, with_token("/v1/rig", "secret")).await.0,
        StatusCode::OK
    );
    // Writes to the console's paths are not exempt.
    let (st, _, _) = call(&s, write("POST", "/console/", None, "{}".into())).await;
    assert_eq!(st, StatusCode::UNAUTHORIZED);
}

#[tokio::test]
async fn a_test_card_is_sent_with_a_revision_announced_and_put_out() {
    let s = state(None, None);
    let mut feed = s.events.subscribe();
    let (st, h, body) = call(&s, get("/v1/channels/left/show")).await;
    assert_eq!(
        (st, h[header::ETAG].to_str().unwrap()),
        (StatusCode::OK, "\"1\"")
    );
    assert_eq!(json(&body)["show"], "content");
    let send = |show: &str, rev: Option<u64>| {
        write(
            "PUT",
            "/v1/channels/left/show",
            rev,
            serde_json::json!({ "show": show }).to_string(),
        )
    };
    assert_eq!(
        call(&s, send("grid", None)).await.0,
        StatusCode::PRECONDITION_REQUIRED
    );
    let (st, _, body) = call(&s, send("smpte", Some(1))).await;
    assert_eq!(
        (st, json(&body)["field"].as_str()),
        (StatusCode::BAD_REQUEST, Some("/show"))
    );
    let (st, _, body) = call(&s, send("grid", Some(1))).await;
    assert_eq!(
        (st, json(&body)["revision"].as_u64()),
        (StatusCode::OK, Some(2))
    );
    let change: serde_json::Value = serde_json::from_str(&feed.recv().await.unwrap()).unwrap();
    assert_eq!(
        change,
        serde_json::json!({"kind": "show", "channel": "left", "revision": 2})
    );
    let (st, _, body) = call(&s, send("bars", Some(1))).await;
    assert_eq!(
        (st, json(&body)["current_revision"].as_u64()),
        (StatusCode::PRECONDITION_FAILED, Some(2))
    );
    assert_eq!(
        call(&s, get("/v1/channels/nope/show")).await.0,
        StatusCode::NOT_FOUND
    );

    // What the channel puts out: the grid at its resolution / scale, white lines on black.
    let (st, _, png) = call(&s, get("/v1/channels/left/output.png?scale=2")).await;
    assert_eq!(st, StatusCode::OK);
    let img = image::load_from_memory(&png).unwrap().to_rgba8();
    assert_eq!(img.dimensions(), (96, 54));
    assert_eq!(
        img.get_pixel(0, 20).0,
        [255, 255, 255, 255],
        "the raster's edge"
    );
    assert_eq!(
        img.get_pixel(48, 20).0,
        [255, 255, 255, 255],
        "the centre line"
    );
    assert_eq!(img.get_pixel(6, 6).0, [0, 0, 0, 255], "between the lines");
    // Each card differs; back to the content, the output is the channel's preview.
    let mut seen = vec![png];
    for (rev, card) in [
        (2, "crosshatch"),
        (3, "bars"),
        (4, "ids"),
        (5, "edges"),
        (6, "black"),
        (7, "white"),
    ] {
        assert_eq!(call(&s, send(card, Some(rev))).await.0, StatusCode::OK);
        let (st, _, png) = call(&s, get("/v1/channels/left/output.png?scale=2")).await;
        assert_eq!(st, StatusCode::OK, "{card}");
        assert!(!seen.contains(&png), "{card} looks like another card");
        seen.push(png);
    }
    assert_eq!(call(&s, send("content", Some(8))).await.0, StatusCode::OK);
    let (_, _, out) = call(&s, get("/v1/channels/left/output.png?scale=2")).await;
    let (_, _, preview) = call(&s, get("/v1/channels/left/render?scale=2")).await;
    assert_eq!(out, preview);
    let (st, _, body) = call(&s, get("/v1/channels/left/output.png?scale=3")).await;
    assert_eq!(
        (st, json(&body)["field"].as_str()),
        (StatusCode::BAD_REQUEST, Some("scale"))
    );
}

#[tokio::test]
async fn a_pattern_frame_is_put_out_as_the_pattern_route_draws_it_and_refused_by_name() {
    let s = state(None, None);
    let send = |body: serde_json::Value, rev: u64| {
        write("PUT", "/v1/channels/left/show", Some(rev), body.to_string())
    };
    for (body, field) in [
        (serde_json::json!({"show": "pattern"}), "/frame"),
        (
            serde_json::json!({"show": "pattern", "frame": 100000}),
            "/frame",
        ),
        (
            serde_json::json!({"show": "pattern", "frame": 1, "period": 3}),
            "/period",
        ),
        (
            serde_json::json!({"show": "pattern", "frame": 1, "code": "morse"}),
            "/code",
        ),
        (serde_json::json!({"show": "grid", "frame": 1}), "/frame"),
        (
            serde_json::json!({"show": "content", "period": 16}),
            "/period",
        ),
    ] {
        let (st, _, b) = call(&s, send(body.clone(), 1)).await;
        assert_eq!(
            (st, json(&b)["field"].as_str()),
            (StatusCode::BAD_REQUEST, Some(field)),
            "{body}"
        );
    }
    let body = serde_json::json!({"show": "pattern", "frame": 3, "code": "xor"});
    assert_eq!(call(&s, send(body.clone(), 1)).await.0, StatusCode::OK);
    let (_, _, shown) = call(&s, get("/v1/channels/left/show")).await;
    assert_eq!(
        json(&shown),
        serde_json::json!({"show": "pattern", "frame": 3, "code": "xor", "revision": 2})
    );
    let (st, _, png) = call(&s, get("/v1/channels/left/output.png")).await;
    assert_eq!(st, StatusCode::OK);
    let (_, _, frame) = call(&s, get("/v1/channels/left/pattern/3?code=xor")).await;
    assert!(png == frame, "not the frame the pattern route draws");
    // A card's tag names the card: another card is never answered 304 for it, the same card
    // is, whatever the shows' revision (which a restart resets).
    let card_tag = |s: &std::sync::Arc<omniwarp::server::AppState>| {
        let s = s.clone();
        async move {
            let (_, h, _) = call(&s, get("/v1/channels/left/output.png")).await;
            h[header::ETAG].to_str().unwrap().to_string()
        }
    };
    assert_eq!(
        call(&s, send(serde_json::json!({"show": "grid"}), 2))
            .await
            .0,
        StatusCode::OK
    );
    let grid = card_tag(&s).await;
    assert_eq!(
        call(&s, send(serde_json::json!({"show": "crosshatch"}), 3))
            .await
            .0,
        StatusCode::OK
    );
    let crosshatch = card_tag(&s).await;
    assert_ne!(grid, crosshatch);
    let stale = Request::get("/v1/channels/left/output.png")
        .header(header::IF_NONE_MATCH, &grid)
        .body(Body::empty())
        .unwrap();
    assert_eq!(call(&s, stale).await.0, StatusCode::OK);
    assert_eq!(
        call(&s, send(serde_json::json!({"show": "grid"}), 4))
            .await
            .0,
        StatusCode::OK
    );
    assert_eq!(card_tag(&s).await, grid);
    assert_eq!(call(&s, send(body.clone(), 5)).await.0, StatusCode::OK);
    let (_, h, _) = call(&s, get("/v1/channels/left/output.png")).await;

    // The node's revalidation: the same ETag is a 304, without the picture.
    let tag = h[header::ETAG].to_str().unwrap().to_string();
    assert!(tag.starts_with("\"pattern-"), "{tag}");
    let again = Request::get("/v1/channels/left/output.png")
        .header(header::IF_NONE_MATCH, &tag)
        .body(Body::empty())
        .unwrap();
    let (st, _, body) = call(&s, again).await;
    assert_eq!((st, body.len()), (StatusCode::NOT_MODIFIED, 0));
    let (st, _, _) = call(&s, get("/v1/channels/left/output.png?scale=2")).await;
    assert_eq!(st, StatusCode::BAD_REQUEST);
}

#[tokio::test]
async fn the_geometry_draws_each_projector_onto_the_wall() {
    let s = state(None, None);
    let (st, h, body) = call(&s, get("/v1/rig/geometry")).await;
    assert_eq!(
        (st, h[header::ETAG].to_str().unwrap()),
        (StatusCode::OK, "\"1\"")
    );
    let g = json(&body);
    assert_eq!(g["revision"], 1);
    assert!(!g["wall"].as_array().unwrap().is_empty());
    let channels = g["channels"].as_array().unwrap();
    assert_eq!(channels.len(), 2);
    // The flat rig's wall is the plane z = −3, 6 m by 2.5 m around the axis; its left projector
    // overfills the left edge, so part of its outline is spill, on the plane continued.
    let points = |v: &serde_json::Value| -> Vec<[f64; 3]> {
        v.as_array()
            .unwrap()
            .iter()
            .flat_map(|l| l.as_array().unwrap().iter())
            .map(|p| [0, 1, 2].map(|k| p[k].as_f64().unwrap()))
            .collect()
    };
    for ch in channels {
        let (lit, spill) = (points(&ch["footprint"]), points(&ch["spill"]));
        assert!(lit.len() + spill.len() >= 4 * 48, "{}", ch["id"]);
        for [x, y, z] in &lit {
            assert!((z + 3.0).abs() < 1e-3 && x.abs() <= 3.0005 && y.abs() <= 1.2505);
        }
        assert!(spill.iter().all(|p| (p[2] + 3.0).abs() < 1e-3));
        assert!(
            ch["frustum"]
                .as_array()
                .unwrap()
                .iter()
                .all(|p| p.is_array())
        );
    }
    let left = &channels[0];
    assert!(points(&left["spill"]).iter().any(|p| p[0] < -3.0), "{left}");
}

#[tokio::test]
async fn the_served_patterns_decode_to_each_projector_pixel() {
    use omniwarp::structured::decode::{DecodeOptions, decode};
    use omniwarp::structured::{Grey, PatternSet};
    let s = state(None, None);
    let (_, _, body) = call(&s, get("/v1/channels")).await;
    let left = json(&body)["channels"]
        .as_array()
        .and_then(|a| a.iter().find(|c| c["id"] == "left").cloned())
        .unwrap();
    let [w, h] = [0, 1].map(|k| left["resolution"][k].as_u64().unwrap() as u32);
    let set = PatternSet::new(w, h).unwrap();
    let mut frames = Vec::new();
    for n in 0..set.len() {
        let (st, hd, png) = call(&s, get(&format!("/v1/channels/left/pattern/{n}"))).await;
        assert_eq!(st, StatusCode::OK, "frame {n}");
        assert_eq!(hd[header::CONTENT_TYPE], "image/png");
        let g = Grey::decode(&png, "png").unwrap();
        assert_eq!((g.width, g.height), (w, h));
        frames.push(g);
    }
    // The projector filmed by itself: every pixel decodes to its own coordinates.
    let d = decode(&set, &frames, &DecodeOptions::default()).unwrap();
    let mut seen = 0;
    for y in 0..h {
        for x in 0..w {
            if let Some(p) = d.get(x, y) {
                seen += 1;
                let e = (p.q[0] - f64::from(x)).hypot(p.q[1] - f64::from(y));
                assert!(e < 0.02, "({x}, {y}) decoded as {:?}", p.q);
            }
        }
    }
    assert_eq!(
        seen,
        ((w - 4) * (h - 4)) as usize,
        "all but the eroded border"
    );
    for (uri, status, field) in [
        (
            format!("/v1/channels/left/pattern/{}", set.len()),
            StatusCode::BAD_REQUEST,
            Some("n"),
        ),
        (
            "/v1/channels/left/pattern/one".into(),
            StatusCode::BAD_REQUEST,
            Some("n"),
        ),
        (
            "/v1/channels/nope/pattern/0".into(),
            StatusCode::NOT_FOUND,
            None,
        ),
    ] {
        let (st, _, body) = call(&s, get(&uri)).await;
        assert_eq!(st, status, "{uri}");
        if let Some(f) = field {
            assert_eq!(json(&body)["field"], f, "{uri}");
        }
    }
}

#[tokio::test]
async fn the_plan_of_the_current_rig_is_served_as_figures_and_as_a_picture() {
    let s = state(None, None);
    let (st, h, body) = call(&s, get("/v1/rig/plan?step=1")).await;
    assert_eq!(
        (st, h[header::ETAG].to_str().unwrap()),
        (StatusCode::OK, "\"1\"")
    );
    let p = json(&body);
    assert_eq!(p["revision"], 1);
    // The flat test rig: two projectors side by side on a 6 m × 2.5 m wall, overlapping.
    let area = p["wall"]["area"].as_f64().unwrap();
    assert!((area - 15.0).abs() < 0.3, "{area}");
    let shares: f64 = (0..4)
        .map(|k| p["wall"]["lit_by"][k].as_f64().unwrap())
        .sum();
    assert!((shares - 1.0).abs() < 1e-9);
    assert_eq!(p["channels"].as_array().unwrap().len(), 2);
    assert_eq!(
        p["overlaps"][0]["channels"],
        serde_json::json!(["left", "right"])
    );
    assert_eq!(p["overlaps"][0]["across"], "longitude");
    let (st, h, png) = call(&s, get("/v1/rig/plan.png?step=2&width=400")).await;
    assert_eq!(
        (st, h[header::CONTENT_TYPE].to_str().unwrap()),
        (StatusCode::OK, "image/png")
    );
    assert_eq!(image::load_from_memory(&png).unwrap().width(), 400);
    for (uri, field) in [
        ("/v1/rig/plan?step=0.01", "step"),
        ("/v1/rig/plan?width=400", "width"),
        ("/v1/rig/plan.png?width=99999", "width"),
        ("/v1/rig/plan?colour=red", "colour"),
    ] {
        let (st, _, body) = call(&s, get(uri)).await;
        assert_eq!(st, StatusCode::BAD_REQUEST, "{uri}");
        let error = json(&body);
        assert!(
            error["field"] == field || error["error"].as_str().unwrap().contains(field),
            "{uri}: {error}"
        );
    }
}
