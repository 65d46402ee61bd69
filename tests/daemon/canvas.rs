//! The show's content canvas in the rig, which every channel plays unless it has its own: the
//! same exports as identical canvases of their own, a channel returning to the rig's, and data
//! directories whose channels have canvases of their own keeping them.

use crate::common;

use axum::http::{StatusCode, header};
use common::server::{call, get, json, state, state_with, write};
use omniwarp::rig::{Canvas, Rig, RigDoc};

/// The example dome's five projectors at a tenth of their resolution.
fn dome(canvas: Option<&str>) -> RigDoc {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    let rig = Rig::read(&root.join("calibration/rigs/dome-180-tilt15-5proj.json")).unwrap();
    let mut doc = rig.downscaled(10).unwrap().doc;
    doc.canvas = canvas.map(|c| serde_json::from_str(c).unwrap());
    doc
}

/// A dome master: the zenith at its centre, 180° across.
const SHOW: &str = r#"{"projection": "fisheye", "params": {"fov": 180}, "look_to": [0, 1, 0],
    "look_up": [0, 0, 1], "size": [1024, 1024]}"#;

async fn export(s: &std::sync::Arc<omniwarp::server::AppState>, id: &str) -> (String, Vec<u8>) {
    let (st, h, body) = call(s, get(&format!("/v1/channels/{id}/exports/stmap.exr"))).await;
    assert_eq!(st, StatusCode::OK, "{}", String::from_utf8_lossy(&body));
    (h[header::ETAG].to_str().unwrap().to_string(), body)
}

/// An EXR's pixels, bit for bit (its chunks may be written in any order).
fn pixels(exr: &[u8]) -> Vec<u32> {
    let file = tempfile::NamedTempFile::new().unwrap();
    std::fs::write(file.path(), exr).unwrap();
    let (img, _) = omniwarp::image_io::read_exr_rgba(file.path()).unwrap();
    img.data.iter().flatten().map(|v| v.to_bits()).collect()
}

#[tokio::test]
async fn the_rigs_canvas_plays_on_every_channel_as_identical_canvases_of_their_own_would() {
    let show: Canvas = serde_json::from_str(SHOW).unwrap();
    let rig_wide = state_with(None, None, dome(Some(SHOW)));
    let own = state_with(None, None, dome(None));
    let ids: Vec<String> = dome(None).channels.iter().map(|c| c.id.clone()).collect();
    assert_eq!(ids.len(), 5);
    for id in &ids {
        let (_, _, body) = call(&rig_wide, get(&format!("/v1/channels/{id}/content"))).await;
        let got = json(&body);
        assert_eq!(got["own"], false, "{got}");
        assert_eq!(
            serde_json::from_value::<Canvas>(got["content"].clone()).unwrap(),
            show
        );
        let uri = format!("/v1/channels/{id}/content");
        let (st, _, _) = call(&own, write("PUT", &uri, Some(1), SHOW.to_string())).await;
        assert_eq!(st, StatusCode::OK);
        let (_, _, body) = call(&own, get(&uri)).await;
        assert_eq!(json(&body)["own"], true);
        // The same stmap, to the byte, from the rig's canvas as from the channel's own.
        let (a, b) = (export(&rig_wide, id).await.1, export(&own, id).await.1);
        assert!(pixels(&a) == pixels(&b), "{id}: the exports differ");
    }

    // Back to the rig's canvas (the default sphere here): another map; only once.
    let id = &ids[0];
    let uri = format!("/v1/channels/{id}/content");
    let before = export(&own, id).await.1;
    let (st, _, _) = call(&own, write("DELETE", &uri, Some(2), String::new())).await;
    assert_eq!(st, StatusCode::OK);
    let (_, _, body) = call(&own, get(&uri)).await;
    let got = json(&body);
    assert_eq!(
        (got["own"].as_bool(), got["revision"].as_u64()),
        (Some(false), Some(3))
    );
    assert_eq!(got["content"]["projection"], "equirect");
    assert!(pixels(&export(&own, id).await.1) != pixels(&before));
    let (st, _, _) = call(&own, write("DELETE", &uri, Some(3), String::new())).await;
    assert_eq!(st, StatusCode::CONFLICT);
    // Undo brings the channel's own canvas back.
    let (st, _, _) = call(
        &own,
        write("POST", &format!("{uri}/undo"), Some(3), "{}".into()),
    )
    .await;
    assert_eq!(st, StatusCode::OK);
    assert!(pixels(&export(&own, id).await.1) == pixels(&before));

    // A new canvas for the show changes every export's tag, and no warp's.
    let (warp_tag, _) = {
        let (_, h, _) = call(&rig_wide, get(&format!("/v1/channels/{id}/warp.exr"))).await;
        (h[header::ETAG].to_str().unwrap().to_string(), ())
    };
    let (export_tag, _) = export(&rig_wide, id).await;
    let mut doc = dome(Some(SHOW));
    doc.canvas.as_mut().unwrap().size = [2048, 2048];
    let body = serde_json::to_string(&doc).unwrap();
    let (st, _, out) = call(&rig_wide, write("PUT", "/v1/rig", Some(1), body)).await;
    assert_eq!(st, StatusCode::OK, "{}", String::from_utf8_lossy(&out));
    let (_, h, _) = call(&rig_wide, get(&format!("/v1/channels/{id}/warp.exr"))).await;
    let key = |t: &str| t.trim_matches('"').split('-').next().unwrap().to_string();
    assert_eq!(key(h[header::ETAG].to_str().unwrap()), key(&warp_tag));
    assert_ne!(export(&rig_wide, id).await.0, export_tag);
}

#[tokio::test]
async fn a_channels_own_canvas_is_kept_across_restarts_and_rig_canvas_changes() {
    let dir = tempfile::tempdir().unwrap();
    let mine =
        r#"{"projection": "equirect", "params": {"hfov": 180, "vfov": 90}, "size": [2048, 1024]}"#;
    {
        // As every earlier release kept a canvas PUT to a channel: its document, as is.
        let s = state(Some(dir.path()), None);
        let uri = "/v1/channels/left/content";
        let (st, _, _) = call(&s, write("PUT", uri, Some(1), mine.to_string())).await;
        assert_eq!(st, StatusCode::OK);
    }
    let s = state(Some(dir.path()), None);
    let mut doc = common::server::flat_rig();
    doc.canvas = Some(serde_json::from_str(SHOW).unwrap());
    let body = serde_json::to_string(&doc).unwrap();
    let (st, _, _) = call(&s, write("PUT", "/v1/rig", Some(1), body)).await;
    assert_eq!(st, StatusCode::OK);
    drop(s);
    let s = state(Some(dir.path()), None);
    let (_, _, body) = call(&s, get("/v1/channels/left/content")).await;
    let left = json(&body);
    assert_eq!(
        (left["own"].as_bool(), left["revision"].as_u64()),
        (Some(true), Some(2))
    );
    assert_eq!(left["content"]["size"], serde_json::json!([2048, 1024]));
    let (_, _, body) = call(&s, get("/v1/channels/right/content")).await;
    let right = json(&body);
    assert_eq!(right["own"], false);
    assert_eq!(right["content"]["projection"], "fisheye");
    // A canvas the rig's wall cannot hold is refused with its field.
    let mut doc = common::server::flat_rig();
    let mut bad: Canvas = serde_json::from_str(SHOW).unwrap();
    bad.project_from = Some([0.0, 0.0, -10.0]);
    doc.canvas = Some(bad);
    let body = serde_json::to_string(&doc).unwrap();
    let (st, _, out) = call(&s, write("PUT", "/v1/rig", Some(2), body)).await;
    assert_eq!(
        (st, json(&out)["field"].as_str()),
        (StatusCode::BAD_REQUEST, Some("/canvas/project_from"))
    );
}
