//! History, undo and merges (issue 14): the real daemon under four clients editing at once and
//! a SIGKILL in the middle, reverts that give back a revision byte for byte, undo/redo as an
//! editor walks them, merges of disjoint edits, and the migration of a data directory written
//! by the file store of 0.1.0.

use crate::common;

use axum::http::StatusCode;
use common::server::{call, get, json, state, write};
use omniwarp::server::client::Client;
use omniwarp::server::{AppState, OpenOptions, Store};
use std::collections::HashMap;
use std::net::SocketAddr;

/// A nudge of feature (k, l) of channel `left` by `d` degrees of latitude from `theta`.
fn nudge(k: usize, l: usize, theta: f64) -> String {
    serde_json::json!({"edits": [{"op": "set_feature", "column": k, "row": l, "theta": theta}]})
        .to_string()
}

/// The warp's pixels (the EXR's attributes carry the revision, the pixels only the content).
fn pixels(exr: &[u8]) -> Vec<[f32; 4]> {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("w.exr");
    std::fs::write(&p, exr).unwrap();
    omniwarp::normalmap::NormalMap::read(&p)
        .unwrap()
        .pixels()
        .data
        .clone()
}

/// `edits` random nudges by each of 4 clients on one channel, each retried on 412 with the
/// current revision; returns what every revision looked like when it was current (the GET
/// answer's bytes), for the revisions a client saw.
fn edit_concurrently(addr: SocketAddr, edits: usize, seed: u64) -> HashMap<u64, Vec<u8>> {
    let threads: Vec<_> = (0..4u64)
        .map(|t| {
            std::thread::spawn(move || {
                let mut c = Client::new(addr, None);
                let mut seen = HashMap::new();
                let mut rng = seed.wrapping_mul(6364136223846793005).wrapping_add(t);
                let mut next = || {
                    rng = rng
                        .wrapping_mul(6364136223846793005)
                        .wrapping_add(1442695040888963407);
                    (rng >> 33) as usize
                };
                for _ in 0..edits {
                    loop {
                        let Ok(r) = c.get("/v1/channels/left/tiles") else {
                            return seen;
                        };
                        let revision = r.revision().unwrap();
                        let t = r.json();
                        seen.insert(revision, r.body.clone());
                        let columns = t["tiles"]["layout"]["columns"].as_u64().unwrap() as usize;
                        let rows = t["tiles"]["layout"]["rows"].as_u64().unwrap() as usize;
                        let (k, l) = (2 + next() % (columns - 4), 2 + next() % (rows - 4));
                        let f = &t["tiles"]["layout"]["features"][l * columns + k];
                        if f["valid"] == false || f["outside"] == true {
                            continue;
                        }
                        let theta = f["theta"].as_f64().unwrap();
                        let step = (next() % 100) as f64 / 1000.0 - 0.05;
                        let tag = format!("\"{revision}\"");
                        let Ok(r) = c.send(
                            "PATCH",
                            "/v1/channels/left/tiles",
                            &[("If-Match", &tag)],
                            nudge(k, l, theta + step).as_bytes(),
                        ) else {
                            return seen;
                        };
                        match r.status {
                            200 => break,
                            412 => continue,
                            other => panic!("{other}: {}", String::from_utf8_lossy(&r.body)),
                        }
                    }
                }
                seen
            })
        })
        .collect();
    let mut all = HashMap::new();
    for t in threads {
        all.extend(t.join().unwrap());
    }
    all
}

/// Four clients × 250 edits with the daemon SIGKILLed in the middle: after the restart every
/// acknowledged revision is there, `?revision=N` answers the bytes revision N answered when it
/// was current, and a revert to it brings back the same screen and the same warp.
#[test]
fn history_survives_a_sigkill_and_a_revert_gives_back_a_revision_exactly() {
    let dir = tempfile::tempdir().unwrap();
    drop(
        omniwarp::server::Store::open(
            Some(dir.path().to_path_buf()),
            Some(common::server::flat_rig()),
        )
        .unwrap(),
    );
    let (mut child, addr) = common::server::start(dir.path(), false);
    let mut seen = edit_concurrently(addr, 125, 1);
    let mut c = Client::new(addr, None);
    let middle = *seen.keys().filter(|r| **r > 50).min().unwrap();
    let warp_then = {
        // The warp of the middle revision, as it was served while current, comes back below.
        let r = c
            .get(&format!("/v1/channels/left/tiles?revision={middle}"))
            .unwrap();
        assert_eq!(
            r.body, seen[&middle],
            "?revision={middle} answers what it did"
        );
        r
    };
    drop(warp_then);
    child.kill().unwrap();
    child.wait().unwrap();

    let (mut child, addr) = common::server::start(dir.path(), false);
    let before_restart = *seen.keys().max().unwrap();
    seen.extend(edit_concurrently(addr, 125, 2));
    let mut c = Client::new(addr, None);
    let now = c
        .get("/v1/channels/left/tiles")
        .unwrap()
        .revision()
        .unwrap();
    assert!(
        now >= before_restart + 500 - 1,
        "{now} after {before_restart}"
    );
    for (revision, bytes) in seen.iter().filter(|(r, _)| **r % 37 == 0) {
        let r = c
            .get(&format!("/v1/channels/left/tiles?revision={revision}"))
            .unwrap();
        assert_eq!(r.status, 200);
        assert!(&r.body == bytes, "revision {revision} reads back as it was");
    }
    // Revert to the middle revision: the same screen (its own revision number aside) and the
    // same warp as when it was current.
    let tag = format!("\"{now}\"");
    let body = serde_json::json!({ "revision": middle }).to_string();
    let r = c
        .send(
            "POST",
            "/v1/channels/left/tiles/revert",
            &[("If-Match", &tag)],
            body.as_bytes(),
        )
        .unwrap();
    assert_eq!(r.status, 200, "{}", String::from_utf8_lossy(&r.body));
    let reverted = c.get("/v1/channels/left/tiles").unwrap();
    assert_eq!(reverted.revision(), Some(now + 1));
    let mut then: serde_json::Value = serde_json::from_slice(&seen[&middle]).unwrap();
    let mut back = reverted.json();
    for v in [&mut then, &mut back] {
        v["revision"] = 0.into();
        v["tiles"]["revision"] = 0.into();
    }
    assert!(then == back, "the reverted screen is the middle revision's");
    let warp_now = c.get("/v1/channels/left/warp.exr").unwrap();
    // The middle revision's warp, computed from its own document.
    let tag = format!("\"{}\"", now + 1);
    let r = c
        .send(
            "PUT",
            "/v1/channels/left/tiles",
            &[("If-Match", &tag)],
            serde_json::to_vec(&json(&seen[&middle])["tiles"])
                .unwrap()
                .as_slice(),
        )
        .unwrap();
    assert_eq!(r.status, 200);
    let warp_put = c.get("/v1/channels/left/warp.exr").unwrap();
    assert!(
        pixels(&warp_now.body) == pixels(&warp_put.body),
        "the revert's warp is the middle revision's"
    );
    child.kill().unwrap();
    child.wait().unwrap();
}

/// Undo and redo walk the edits back and forth as an editor does, each a new revision; a new
/// edit after an undo drops the redo; a revert can itself be undone.
#[tokio::test]
async fn undo_and_redo_walk_the_edits_and_a_new_edit_drops_the_redo() {
    let s = state(None, None);
    let theta =
        |body: &[u8]| json(body)["tiles"]["layout"]["features"][9 * 33 + 16]["theta"].as_f64();
    let patch = |rev: u64, t: f64| {
        write(
            "PATCH",
            "/v1/channels/left/tiles",
            Some(rev),
            nudge(16, 9, t),
        )
    };
    let step = |action: &str, rev: u64| {
        write(
            "POST",
            &format!("/v1/channels/left/tiles/{action}"),
            Some(rev),
            String::new(),
        )
    };
    let (_, _, first) = call(&s, get("/v1/channels/left/tiles")).await;
    let t0 = theta(&first).unwrap();
    for (rev, d) in [(1, 0.01), (2, 0.02), (3, 0.03)] {
        assert_eq!(call(&s, patch(rev, t0 + d)).await.0, StatusCode::OK);
    }
    let now = |s: &std::sync::Arc<omniwarp::server::AppState>| {
        let s = s.clone();
        async move {
            let (_, _, b) = call(&s, get("/v1/channels/left/tiles")).await;
            (json(&b)["revision"].as_u64().unwrap(), theta(&b))
        }
    };
    let expect = [
        ("undo", 5, Some(t0 + 0.02)),
        ("undo", 6, Some(t0 + 0.01)),
        ("redo", 7, Some(t0 + 0.02)),
        ("undo", 8, Some(t0 + 0.01)),
        ("redo", 9, Some(t0 + 0.02)),
        ("redo", 10, Some(t0 + 0.03)),
    ];
    for (action, revision, t) in expect {
        let (st, _, b) = call(&s, step(action, revision - 1)).await;
        assert_eq!(
            st,
            StatusCode::OK,
            "{action}: {}",
            String::from_utf8_lossy(&b)
        );
        let (r, got) = now(&s).await;
        assert_eq!(r, revision);
        assert!(
            (got.unwrap() - t.unwrap()).abs() < 1e-12,
            "{action} to {revision}"
        );
    }
    assert_eq!(call(&s, step("redo", 10)).await.0, StatusCode::CONFLICT);
    // Back to the screen that followed the geometry, then an edit: nothing left to redo.
    for r in 10..13 {
        assert_eq!(call(&s, step("undo", r)).await.0, StatusCode::OK);
    }
    let (_, _, b) = call(&s, get("/v1/channels/left/tiles")).await;
    assert_eq!(json(&b)["follows_geometry"], true);
    assert_eq!(call(&s, step("undo", 13)).await.0, StatusCode::CONFLICT);
    assert_eq!(call(&s, patch(13, t0 + 0.05)).await.0, StatusCode::OK);
    assert_eq!(call(&s, step("redo", 14)).await.0, StatusCode::CONFLICT);
    // A revert to revision 4 and its undo.
    let revert = write(
        "POST",
        "/v1/channels/left/tiles/revert",
        Some(14),
        serde_json::json!({"revision": 4}).to_string(),
    );
    assert_eq!(call(&s, revert).await.0, StatusCode::OK);
    assert!((now(&s).await.1.unwrap() - (t0 + 0.03)).abs() < 1e-12);
    assert_eq!(call(&s, step("undo", 15)).await.0, StatusCode::OK);
    assert!((now(&s).await.1.unwrap() - (t0 + 0.05)).abs() < 1e-12);
    // Stale and missing revisions are refused as every write is.
    assert_eq!(
        call(&s, step("undo", 3)).await.0,
        StatusCode::PRECONDITION_FAILED
    );
    let missing = write(
        "POST",
        "/v1/channels/left/tiles/revert",
        Some(16),
        serde_json::json!({"revision": 99}).to_string(),
    );
    assert_eq!(call(&s, missing).await.0, StatusCode::BAD_REQUEST);
    // The history lists them, newest first, with who and what.
    let (st, _, b) = call(&s, get("/v1/history?resource=channels/left/tiles&limit=3")).await;
    assert_eq!(st, StatusCode::OK);
    let rows = json(&b)["history"].as_array().unwrap().clone();
    let actions: Vec<_> = rows.iter().map(|r| r["action"].as_str().unwrap()).collect();
    assert_eq!(actions, ["undo", "revert", "patch"]);
    assert_eq!(rows[0]["who"], "local");
    assert_eq!(rows[2]["request"][0]["op"], "set_feature");
}

/// The rig and the content canvas have the same routes.
#[tokio::test]
async fn the_rig_and_the_content_undo_too() {
    let s = state(None, None);
    let (_, _, b) = call(&s, get("/v1/rig")).await;
    let mut doc = json(&b)["rig"].clone();
    doc["eye"] = serde_json::json!([0.0, 0.2, 0.0]);
    assert_eq!(
        call(&s, write("PUT", "/v1/rig", Some(1), doc.to_string()))
            .await
            .0,
        StatusCode::OK
    );
    assert_eq!(
        call(&s, write("POST", "/v1/rig/undo", Some(2), String::new()))
            .await
            .0,
        StatusCode::OK
    );
    let (_, _, b) = call(&s, get("/v1/rig")).await;
    assert_eq!(
        (
            json(&b)["revision"].as_u64(),
            json(&b)["rig"]["eye"][1].as_f64()
        ),
        (Some(3), Some(0.0))
    );
    let (_, _, b) = call(&s, get("/v1/rig?revision=2")).await;
    assert_eq!(json(&b)["rig"]["eye"][1].as_f64(), Some(0.2));
    let canvas = serde_json::json!({"projection": "cylindrical", "params": {"hfov": 200, "vfov": 60}, "size": [2000, 600]});
    assert_eq!(
        call(
            &s,
            write(
                "PUT",
                "/v1/channels/left/content",
                Some(1),
                canvas.to_string()
            )
        )
        .await
        .0,
        StatusCode::OK
    );
    assert_eq!(
        call(
            &s,
            write(
                "POST",
                "/v1/channels/left/content/undo",
                Some(2),
                "{}".into()
            )
        )
        .await
        .0,
        StatusCode::OK
    );
    let (_, _, b) = call(&s, get("/v1/channels/left/content")).await;
    assert_eq!(json(&b)["content"]["projection"], "equirect");
    let (_, _, b) = call(&s, get("/v1/channels/left/content?revision=2")).await;
    assert_eq!(json(&b)["content"]["projection"], "cylindrical");
}

/// Two technicians on different corners: the second one's edit, based on the revision before
/// the first one's, merges when asked to; on the same feature it is refused with 412.
#[tokio::test]
async fn disjoint_edits_merge_and_overlapping_ones_are_refused() {
    let s = state(None, None);
    let merged = |k: usize, l: usize, t: f64| {
        serde_json::json!({"merge": true, "edits": [{"op": "set_feature", "column": k, "row": l, "theta": t}]})
            .to_string()
    };
    let (_, _, b) = call(&s, get("/v1/channels/left/tiles")).await;
    let theta = |b: &[u8], k: usize, l: usize| {
        json(b)["tiles"]["layout"]["features"][l * 33 + k]["theta"]
            .as_f64()
            .unwrap()
    };
    let (a, c) = (theta(&b, 5, 5), theta(&b, 27, 12));
    assert_eq!(
        call(
            &s,
            write(
                "PATCH",
                "/v1/channels/left/tiles",
                Some(1),
                nudge(5, 5, a + 0.02)
            )
        )
        .await
        .0,
        StatusCode::OK
    );
    assert_eq!(
        call(
            &s,
            write(
                "PATCH",
                "/v1/channels/left/tiles",
                Some(2),
                nudge(5, 6, a + 0.01)
            )
        )
        .await
        .0,
        StatusCode::OK
    );
    // Without "merge", an old If-Match stays a 412.
    assert_eq!(
        call(
            &s,
            write(
                "PATCH",
                "/v1/channels/left/tiles",
                Some(2),
                nudge(27, 12, c + 0.02)
            )
        )
        .await
        .0,
        StatusCode::PRECONDITION_FAILED
    );
    let (st, _, body) = call(
        &s,
        write(
            "PATCH",
            "/v1/channels/left/tiles",
            Some(2),
            merged(27, 12, c + 0.02),
        ),
    )
    .await;
    assert_eq!(st, StatusCode::OK, "{}", String::from_utf8_lossy(&body));
    assert_eq!(json(&body)["revision"], 4);
    let (_, _, b) = call(&s, get("/v1/channels/left/tiles")).await;
    assert!(
        (theta(&b, 5, 5) - (a + 0.02)).abs() < 1e-12,
        "the first edit stays"
    );
    assert!(
        (theta(&b, 27, 12) - (c + 0.02)).abs() < 1e-12,
        "the second is applied"
    );
    // The same feature another client changed since: refused with the current revision.
    let (st, h, _) = call(
        &s,
        write("PATCH", "/v1/channels/left/tiles", Some(2), merged(5, 6, a)),
    )
    .await;
    assert_eq!(
        (st, h["etag"].to_str().unwrap()),
        (StatusCode::PRECONDITION_FAILED, "\"4\"")
    );
    // Smoothing touches everything: never merged.
    let smooth = serde_json::json!({"merge": true, "edits": [{"op": "smooth", "iterations": 1}]})
        .to_string();
    assert_eq!(
        call(
            &s,
            write("PATCH", "/v1/channels/left/tiles", Some(3), smooth)
        )
        .await
        .0,
        StatusCode::PRECONDITION_FAILED
    );
}

/// A merge is judged on what the edits change, not on what they name: re-sending a feature as
/// one saw it would put back another client's acknowledged edit, and a smooth from a revision it
/// left unchanged (a fixed point of smoothing) would smooth that edit away. Both are 412.
#[tokio::test]
async fn merges_are_judged_on_what_the_edits_change() {
    let s = state(None, None);
    let (_, _, b) = call(&s, get("/v1/channels/left/tiles")).await;
    // A screen that is a fixed point of smoothing: angles linear in the grid (whole degrees, so
    // every mean is exact), every feature valid and inside.
    let mut screen = json(&b)["tiles"].clone();
    let columns = screen["layout"]["columns"].as_u64().unwrap() as usize;
    let rows = screen["layout"]["rows"].as_u64().unwrap() as usize;
    for (i, f) in screen["layout"]["features"]
        .as_array_mut()
        .unwrap()
        .iter_mut()
        .enumerate()
    {
        let (k, l) = ((i % columns) as f64, (i / columns) as f64);
        f["phi"] = serde_json::json!(2.0 * k - columns as f64);
        f["theta"] = serde_json::json!(rows as f64 - 2.0 * l);
        f["scale"] = serde_json::json!(1.0);
        f["valid"] = serde_json::json!(true);
        f["outside"] = serde_json::json!(false);
    }
    let put = write(
        "PUT",
        "/v1/channels/left/tiles",
        Some(1),
        screen.to_string(),
    );
    let (st, _, body) = call(&s, put).await;
    assert_eq!(st, StatusCode::OK, "{}", String::from_utf8_lossy(&body));
    let (k, l) = (columns / 2, rows / 2);
    let seen = rows as f64 - 2.0 * l as f64;
    // Client 1 moves the middle feature up half a degree: revision 3.
    let nudged = write(
        "PATCH",
        "/v1/channels/left/tiles",
        Some(2),
        nudge(k, l, seen + 0.5),
    );
    assert_eq!(call(&s, nudged).await.0, StatusCode::OK);
    let theta =
        |b: &[u8]| json(b)["tiles"]["layout"]["features"][l * columns + k]["theta"].as_f64();
    let merge =
        |edit: serde_json::Value| serde_json::json!({"merge": true, "edits": [edit]}).to_string();
    // Client 2, still at revision 2, re-sends that feature as it saw it.
    let resent = merge(serde_json::json!(
        {"op": "set_feature", "column": k, "row": l, "theta": seen}));
    let (st, h, _) = call(
        &s,
        write("PATCH", "/v1/channels/left/tiles", Some(2), resent),
    )
    .await;
    assert_eq!(
        (st, h["etag"].to_str().unwrap()),
        (StatusCode::PRECONDITION_FAILED, "\"3\"")
    );
    // Client 2 smooths from revision 2, which smoothing leaves as it is.
    let smooth = merge(serde_json::json!({"op": "smooth", "iterations": 3}));
    let (st, _, _) = call(
        &s,
        write("PATCH", "/v1/channels/left/tiles", Some(2), smooth),
    )
    .await;
    assert_eq!(st, StatusCode::PRECONDITION_FAILED);
    let (_, _, b) = call(&s, get("/v1/channels/left/tiles")).await;
    assert_eq!(json(&b)["revision"], 3);
    assert_eq!(theta(&b), Some(seen + 0.5), "client 1's edit stays");
    // A feature elsewhere, as client 2 saw it changed, still merges.
    let elsewhere = merge(serde_json::json!(
        {"op": "set_feature", "column": 2, "row": 2, "theta": rows as f64 - 3.75}));
    let (st, _, body) = call(
        &s,
        write("PATCH", "/v1/channels/left/tiles", Some(2), elsewhere),
    )
    .await;
    assert_eq!(st, StatusCode::OK, "{}", String::from_utf8_lossy(&body));
    let (_, _, b) = call(&s, get("/v1/channels/left/tiles")).await;
    assert_eq!(theta(&b), Some(seen + 0.5));
}

/// The history keeps what the retention allows: beyond the newest revisions (compacted every
/// 64th write), beyond an age, beyond a size. Every revision still listed rebuilds (the oldest
/// kept became a snapshot), also after a restart, and an undo into what was dropped says so.
#[tokio::test]
async fn the_history_keeps_what_the_retention_allows() {
    use omniwarp::server::Retention;
    use omniwarp::server::storage::db::{Db, Meta};
    let dir = tempfile::tempdir().unwrap();
    let keep = Retention {
        revisions: 10,
        ..Retention::default()
    };
    let open = |retention| {
        Store::open_with(
            Some(dir.path().to_path_buf()),
            OpenOptions {
                initial: Some(common::server::demo_rig()),
                retention,
                ..OpenOptions::default()
            },
        )
        .unwrap()
    };
    let s = AppState::new(open(keep), None);
    let (_, _, b) = call(&s, get("/v1/channels/left/tiles")).await;
    let a = json(&b)["tiles"]["layout"]["features"][5 * 33 + 5]["theta"]
        .as_f64()
        .unwrap();
    let theta = |r: u64| a + r as f64 * 1e-3;
    for r in 1..=64 {
        let patch = write(
            "PATCH",
            "/v1/channels/left/tiles",
            Some(r),
            nudge(5, 5, theta(r)),
        );
        assert_eq!(call(&s, patch).await.0, StatusCode::OK);
    }
    let resource = "channels/left/tiles";
    let rows = |db: &Db| db.history(Some(resource), 1000, None).unwrap();
    // Compacted at revision 64 to 55..=64; 65 written after.
    let kept: Vec<u64> = rows(&s.store.db).iter().map(|r| r.revision).collect();
    assert_eq!(kept, (55..=65).rev().collect::<Vec<_>>());
    let at = |b: &[u8]| json(b)["tiles"]["layout"]["features"][5 * 33 + 5]["theta"].as_f64();
    let (st, _, b) = call(&s, get("/v1/channels/left/tiles?revision=55")).await;
    assert_eq!((st, at(&b)), (StatusCode::OK, Some(theta(54))));
    let (st, _, _) = call(&s, get("/v1/channels/left/tiles?revision=54")).await;
    assert_eq!(st, StatusCode::NOT_FOUND);
    // Undo walks back to 55, then finds the rest dropped.
    let undo = |at: u64| {
        write(
            "POST",
            "/v1/channels/left/tiles/undo",
            Some(at),
            String::new(),
        )
    };
    let mut current = 65;
    for _ in 55..65 {
        let (st, _, body) = call(&s, undo(current)).await;
        assert_eq!(st, StatusCode::OK, "{}", String::from_utf8_lossy(&body));
        current += 1;
    }
    let (_, _, b) = call(&s, get("/v1/channels/left/tiles")).await;
    assert_eq!(at(&b), Some(theta(54)));
    let (st, _, body) = call(&s, undo(current)).await;
    assert_eq!(st, StatusCode::CONFLICT);
    assert!(
        json(&body)["error"]
            .as_str()
            .unwrap()
            .contains("no longer in the history"),
        "{}",
        String::from_utf8_lossy(&body)
    );
    drop(s);
    // After a restart with the default retention, every kept revision still rebuilds.
    let store = open(Retention::default());
    for r in 55..=current {
        assert!(store.db.at(resource, r).unwrap().is_some(), "revision {r}");
    }
    drop(store);

    // Age and size, on the database alone: documents of 10 kB that share nothing, so each
    // row is a snapshot.
    let db = Db::open(None).unwrap();
    let meta = Meta {
        who: "test".into(),
        action: "put",
        request: None,
        undo_to: None,
        redo_to: None,
    };
    for r in 1..=20u64 {
        let doc = serde_json::json!({"text": r.to_string().repeat(10_000 / r.to_string().len())});
        db.write("doc", None, (r, &doc), &meta).unwrap();
    }
    db.set_retention(Retention {
        bytes: 50_000,
        ..Retention::default()
    })
    .unwrap();
    let kept = |db: &Db| -> Vec<u64> {
        let rows = db.history(Some("doc"), 100, None).unwrap();
        rows.iter().map(|r| r.revision).collect()
    };
    // A row holds its patch and its snapshot (each a whole document here): two fit.
    assert_eq!(kept(&db), [20, 19]);
    assert_eq!(
        db.at("doc", 20).unwrap().unwrap()["text"]
            .as_str()
            .unwrap()
            .len(),
        10_000
    );
    std::thread::sleep(std::time::Duration::from_millis(20));
    db.set_retention(Retention {
        max_age: std::time::Duration::from_millis(10),
        ..Retention::default()
    })
    .unwrap();
    assert_eq!(
        kept(&db),
        [20],
        "only the current revision outlives the age"
    );
}

/// A data directory written by 0.1.0 (the file store; `calibration/fixtures/datadir-0.1.0`)
/// is migrated on first start: the rig, the edited tiles and the content keep their revisions
/// and documents, the proposal is kept, the old files move to `migrated-0.1/`, and the history
/// starts at the migrated revisions.
#[tokio::test]
async fn a_file_store_data_directory_is_migrated_on_first_start() {
    let fixture = common::fixture("datadir-0.1.0");
    let dir = tempfile::tempdir().unwrap();
    for sub in ["", "channels", "proposals"] {
        std::fs::create_dir_all(dir.path().join(sub)).unwrap();
    }
    for f in [
        "rig.json",
        "channels/centre.json",
        "channels/centre.json.prev",
        "proposals/1.json",
    ] {
        std::fs::copy(fixture.join(f), dir.path().join(f)).unwrap();
    }
    let s = state(Some(dir.path()), None);
    let expected_rig = json(&std::fs::read(fixture.join("expected-rig.json")).unwrap());
    let expected_tiles = json(&std::fs::read(fixture.join("expected-centre-tiles.json")).unwrap());
    let (_, _, b) = call(&s, get("/v1/rig")).await;
    assert_eq!(json(&b), expected_rig);
    let (_, h, b) = call(&s, get("/v1/channels/centre/tiles")).await;
    assert_eq!(h["etag"], "\"2\"");
    assert!(
        json(&b) == expected_tiles,
        "the edited screen comes through"
    );
    let (_, _, b) = call(&s, get("/v1/channels/centre/content")).await;
    assert_eq!(json(&b)["content"]["projection"], "cylindrical");
    assert_eq!(call(&s, get("/v1/proposals/1")).await.0, StatusCode::OK);
    assert!(dir.path().join("migrated-0.1/rig.json").exists());
    assert!(!dir.path().join("rig.json").exists());
    let (_, _, b) = call(&s, get("/v1/history?resource=channels/centre/tiles")).await;
    let rows = json(&b)["history"].clone();
    assert_eq!(
        (rows[0]["action"].as_str(), rows[0]["revision"].as_u64()),
        (Some("migrate"), Some(2))
    );
    // And it edits on from there; a restart starts from the database, not the files.
    let edit = nudge(
        16,
        8,
        expected_tiles["tiles"]["layout"]["features"][8 * 33 + 16]["theta"]
            .as_f64()
            .unwrap()
            + 0.01,
    );
    assert_eq!(
        call(
            &s,
            write("PATCH", "/v1/channels/centre/tiles", Some(2), edit)
        )
        .await
        .0,
        StatusCode::OK
    );
    drop(s);
    let again = state(Some(dir.path()), None);
    let (_, h, _) = call(&again, get("/v1/channels/centre/tiles")).await;
    assert_eq!(h["etag"], "\"3\"");
}
