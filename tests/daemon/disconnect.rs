//! Writes disturbed from outside: a client that goes away while its write is being saved, and
//! another process holding the database's write lock.
//!
//! A client that goes away while its write is being saved. The daemon answers a write only once
//! it is durable; the client may be gone by then. What it wrote must then be the daemon's state
//! in memory as it is in the database, so the next write based on it succeeds. The moment is
//! forced, not timed: a hook in the database stops the write just after its commit while the
//! test drops the request, as hyper does when the connection closes.

use crate::common::server::{call, get, json, state, write};
use axum::http::StatusCode;
use std::sync::{Arc, Mutex, mpsc};
use std::time::Duration;

/// Far longer than any write here takes.
const LONG: Duration = Duration::from_secs(30);

/// How long a released write may take to finish.
const SETTLE: Duration = Duration::from_secs(5);

/// Runs `req` against `s`, drops it the moment its write is committed, then lets the write go
/// on.
async fn gone_at_commit(
    s: &Arc<omniwarp::server::AppState>,
    req: axum::http::Request<axum::body::Body>,
) {
    let (committed, at_commit) = mpsc::channel::<()>();
    let (release, released) = mpsc::channel::<()>();
    let released = Arc::new(Mutex::new(released));
    s.store.db.on_commit(Some(Arc::new(move |_: &str| {
        let _ = committed.send(());
        let _ = released.lock().unwrap().recv();
    })));
    let task = tokio::spawn({
        let s = s.clone();
        async move { call(&s, req).await }
    });
    let reached = tokio::task::spawn_blocking(move || at_commit.recv_timeout(LONG).is_ok())
        .await
        .unwrap();
    if !reached {
        s.store.db.on_commit(None);
        let (status, _, body) = task.await.unwrap();
        panic!(
            "the write never reached its commit: {status} {}",
            json(&body)
        );
    }
    task.abort();
    assert!(
        task.await.unwrap_err().is_cancelled(),
        "the request ended before its drop"
    );
    s.store.db.on_commit(None);
    release.send(()).unwrap();
}

fn etag_revision(headers: &axum::http::HeaderMap) -> u64 {
    let tag = headers["etag"].to_str().unwrap().trim_matches('"');
    tag.rsplit('.').next().unwrap().parse().unwrap()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_write_whose_client_left_at_the_commit_is_kept_and_the_next_one_succeeds() {
    let edit = |f: f64| {
        serde_json::json!({"edits": [{"op": "set_feature", "column": 3, "row": 2, "f": f}]})
            .to_string()
    };
    let tiles = "/v1/channels/left/tiles";
    let content = "/v1/channels/left/content";
    let s = state(None, None);
    let (_, _, body) = call(&s, get(content)).await;
    let canvas = json(&body)["content"].to_string();
    let (_, _, rig) = call(&s, get("/v1/rig")).await;
    let rig = json(&rig)["rig"].to_string();
    // (what is dropped at its commit, its method and path, its body, the resource it writes)
    let cases = [
        ("PATCH tiles", "PATCH", tiles.to_string(), edit(0.5), tiles),
        (
            "undo tiles",
            "POST",
            format!("{tiles}/undo"),
            String::new(),
            tiles,
        ),
        (
            "PUT content",
            "PUT",
            content.to_string(),
            canvas.clone(),
            content,
        ),
        (
            "PUT rig",
            "PUT",
            "/v1/rig".to_string(),
            rig.clone(),
            "/v1/rig",
        ),
        (
            "DELETE tiles",
            "DELETE",
            tiles.to_string(),
            String::new(),
            tiles,
        ),
    ];
    for (what, method, path, body, uri) in cases {
        let (_, headers, _) = call(&s, get(uri)).await;
        let before = etag_revision(&headers);
        gone_at_commit(&s, write(method, &path, Some(before), body)).await;
        // The write goes on after its release, for a moment, to put the new document in
        // memory: a read in that moment is a read from before the write.
        let since = std::time::Instant::now();
        let headers = loop {
            let (status, headers, _) = call(&s, get(uri)).await;
            assert_eq!(status, StatusCode::OK, "{what}: GET {uri}");
            if etag_revision(&headers) > before || since.elapsed() > SETTLE {
                break headers;
            }
            tokio::time::sleep(Duration::from_millis(5)).await;
        };
        let stored = s.store.db.current(uri.trim_start_matches("/v1/")).unwrap();
        assert_eq!(
            stored.map(|(r, _)| r),
            Some(before + 1),
            "{what}: the database"
        );
        assert_eq!(
            etag_revision(&headers),
            before + 1,
            "{what}: the daemon does not show the write its database holds"
        );
        // The next write, based on the revision the database holds, succeeds.
        let next = match uri {
            "/v1/rig" => write("PUT", uri, Some(before + 1), rig.clone()),
            u if u == content => write("PUT", uri, Some(before + 1), canvas.clone()),
            _ => write("PATCH", uri, Some(before + 1), edit(0.25)),
        };
        let (status, _, body) = call(&s, next).await;
        assert_eq!(
            status,
            StatusCode::OK,
            "{what}: the next write: {}",
            json(&body)
        );
    }
}

/// A backup or `sqlite3` holding SQLite's write lock for a moment delays a write; it does not
/// fail it ("database is locked" at once was the answer while transactions began as reads).
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_write_waits_for_another_process_holding_the_database_lock() {
    let dir = tempfile::tempdir().unwrap();
    let s = state(Some(dir.path()), None);
    let other =
        rusqlite::Connection::open(dir.path().join(omniwarp::server::storage::db::FILE)).unwrap();
    other.execute_batch("BEGIN IMMEDIATE").unwrap();
    let edit =
        serde_json::json!({"edits": [{"op": "set_feature", "column": 3, "row": 2, "f": 0.5}]});
    let task = tokio::spawn({
        let s = s.clone();
        async move {
            call(
                &s,
                write(
                    "PATCH",
                    "/v1/channels/left/tiles",
                    Some(1),
                    edit.to_string(),
                ),
            )
            .await
        }
    });
    tokio::time::sleep(Duration::from_millis(500)).await;
    assert!(!task.is_finished(), "the write did not wait for the lock");
    other.execute_batch("COMMIT").unwrap();
    let (status, _, body) = task.await.unwrap();
    assert_eq!(status, StatusCode::OK, "{}", json(&body));
}

/// The daemon on a 4 MiB tmpfs of its own, mounted in a user and mount namespace (`unshare`),
/// so the test needs no privilege; `None` where the machine does not allow that.
fn on_a_small_disk() -> Option<(std::process::Child, std::net::SocketAddr, tempfile::TempDir)> {
    use std::io::BufRead;
    use std::process::{Command, Stdio};
    let mount = "mount -t tmpfs -o size=4m tmpfs \"$0\"";
    let root = tempfile::tempdir().unwrap();
    let can = Command::new("unshare")
        .args(["--user", "--map-root-user", "--mount", "sh", "-c", mount])
        .arg(root.path())
        .stderr(Stdio::null())
        .status()
        .is_ok_and(|s| s.success());
    if !can {
        return None;
    }
    let serve =
        format!("{mount} && exec \"$1\" serve --bind 127.0.0.1:0 --data \"$0/state\" --demo");
    let mut child = Command::new("unshare")
        .args(["--user", "--map-root-user", "--mount", "sh", "-c", &serve])
        .arg(root.path())
        .arg(env!("CARGO_BIN_EXE_omniwarp"))
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let mut line = String::new();
    std::io::BufReader::new(child.stdout.take().unwrap())
        .read_line(&mut line)
        .unwrap();
    let Some(addr) = line
        .trim()
        .strip_prefix("listening on http://")
        .and_then(|a| a.parse().ok())
    else {
        let _ = child.kill();
        let _ = child.wait();
        panic!("the daemon on a small disk did not start: {line:?}");
    };
    // The mount point lives as long as the daemon: removed, its tmpfs would go with it.
    Some((child, addr, root))
}

/// A full disk is the operator's to fix, and the client's to hear about: 507 naming the disk,
/// for a file the daemon writes (a mesh) and for its database alike, with nothing half-written
/// and the last acknowledged write still served.
#[test]
fn a_full_disk_is_answered_507_and_keeps_what_was_acknowledged() {
    use omniwarp::server::client::Client;
    let Some((mut child, addr, _mount_point)) = on_a_small_disk() else {
        eprintln!("skipped: this machine does not let a test mount a small tmpfs (unshare)");
        return;
    };
    let mut c = Client::new(addr, None);
    let full = |r: &omniwarp::server::client::Reply, what: &str| {
        assert_eq!(r.status, 507, "{what}: {}", r.json());
        assert!(
            r.json()["error"].as_str().unwrap().contains("disk"),
            "{what}"
        );
    };
    // Meshes fill the disk (each about 0.5 MiB of text).
    let mut answer = None;
    for i in 0..40 {
        let obj = crate::hostile::fan(8000, -3.0 - i as f64 * 0.01);
        let r = c
            .send("PUT", &format!("/v1/meshes/m{i}.obj"), &[], obj.as_bytes())
            .unwrap();
        if r.status != 201 {
            answer = Some(r);
            break;
        }
    }
    full(&answer.expect("4 MiB held 40 meshes"), "a mesh upload");
    // Then the database: edits until one does not fit.
    let tiles = "/v1/channels/centre/tiles";
    let mut acknowledged = None;
    let mut refused = None;
    for i in 0..500 {
        let revision = c.get(tiles).unwrap().revision().unwrap();
        let f = 0.3 + i as f64 * 1e-3;
        let edit = serde_json::json!({"edits": [
            {"op": "set_feature", "column": 3, "row": 2, "f": f}
        ]});
        let tag = format!("\"{revision}\"");
        let r = c
            .send(
                "PATCH",
                tiles,
                &[("If-Match", &tag), ("Content-Type", "application/json")],
                edit.to_string().as_bytes(),
            )
            .unwrap();
        match r.status {
            200 => acknowledged = Some((r.revision().unwrap(), f)),
            _ => {
                refused = Some(r);
                break;
            }
        }
    }
    full(&refused.expect("the disk never filled"), "a tile edit");
    let (revision, f) = acknowledged.expect("no edit fitted at all");
    let now = c.get(tiles).unwrap();
    assert_eq!(now.revision(), Some(revision));
    let layout = &now.json()["tiles"]["layout"];
    let columns = layout["columns"].as_u64().unwrap() as usize;
    assert_eq!(layout["features"][2 * columns + 3]["f"].as_f64(), Some(f));
    assert_eq!(c.get("/v1/health").unwrap().status, 200);
    child.kill().unwrap();
    child.wait().unwrap();
}

/// A proposal whose save fails (here: another process holds the database past the busy
/// timeout) uses up no id: the next one saved gets it.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_proposal_that_could_not_be_saved_uses_up_no_id() {
    let dir = tempfile::tempdir().unwrap();
    // A cylinder: points on a flat wall cannot calibrate free intrinsics.
    let s = crate::common::server::state_with(
        Some(dir.path()),
        None,
        crate::common::server::demo_rig(),
    );
    let rig = s.store.snapshot().0;
    let ch = rig.channel("left").unwrap();
    let (w, h) = (f64::from(ch.width), f64::from(ch.height));
    let mut points = Vec::new();
    for j in 0..30 {
        for i in 0..40 {
            let q = [
                (0.5 + f64::from(i)) * w / 40.0,
                (0.5 + f64::from(j)) * h / 30.0,
            ];
            if let Some(p) = rig.wall_point(ch, q) {
                points.push(serde_json::json!({"pixel": q, "world": p.to_array()}));
            }
        }
    }
    let body = serde_json::json!({"points": points}).to_string();
    let propose = || {
        call(
            &s,
            write("POST", "/v1/channels/left/calibration", None, body.clone()),
        )
    };
    let other =
        rusqlite::Connection::open(dir.path().join(omniwarp::server::storage::db::FILE)).unwrap();
    other.execute_batch("BEGIN EXCLUSIVE").unwrap();
    let (status, _, failed) = propose().await;
    assert!(status.is_server_error(), "{status}: {}", json(&failed));
    other.execute_batch("COMMIT").unwrap();
    let (status, _, saved) = propose().await;
    assert_eq!(status, StatusCode::CREATED);
    let (_, _, first) = call(&s, get("/v1/proposals/1")).await;
    assert_eq!(json(&first)["id"], 1);
    assert_eq!(json(&saved)["id"], 1);
}
