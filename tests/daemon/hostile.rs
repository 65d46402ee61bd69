//! The daemon against hostile and careless clients. Each test guards one case that an attack on
//! the daemon found (issue 13), asserting the refusal or the fixed behaviour and that
//! `/v1/health` still answers. Routes go through `oneshot` where a socket adds nothing;
//! connection behaviour uses the real binary.
//!
//! | case | what it did before | guarded by |
//! | --- | --- | --- |
//! | a splined lens with 2³²−1 knots each way | allocated until the process died | `a_spline_with_billions_of_knots_is_refused_before_anything_is_allocated` |
//! | a 16384² channel, then `render?scale=8` | aborted; the rig was saved first | `a_rig_whose_warps_exceed_the_memory_budget_is_refused_and_never_saved` |
//! | `smooth` with 10¹² iterations | froze every route, health included | `smoothing_iterations_are_bounded` |
//! | a mesh screen from `/dev/zero`, a FIFO, `/etc/passwd` | hung; told existing files from missing | `mesh_screens_come_from_the_mesh_directories_only` |
//! | a tile grid of 2⁶³ columns | index panic; loaded from disk unvalidated | `a_tile_grid_whose_size_overflows_is_refused_from_a_client_and_from_disk` |
//! | 1000-edit PATCHes of `insert_row` | 270 s of CPU holding the lock | `grid_growth_is_bounded_and_quick` |
//! | hundreds of clients that never read `warp.exr` | 24 MB each, abort at 260 | `clients_that_never_read_large_outputs_cannot_pile_them_up` |
//! | calibrations whose clients went away | kept running, workers reported free | `a_calibration_stops_when_its_client_goes_away_and_frees_its_worker` |
//! | clients posting calibrations for 20 s | 404 proposals kept | `proposals_are_capped_oldest_first` |
//! | a content `hfov` of 1e-300 | an 81 s, 648 MB export | `a_vanishing_field_of_view_is_refused` |
//! | `Host: attacker.example` (DNS rebinding) | a web page replaced the rig | `a_rebinding_host_is_refused_and_changes_nothing` |
//! | a cross-site form POST (`text/plain`) | accepted without preflight | `a_cross_site_form_post_is_refused_and_only_allowed_origins_pass_preflight` |
//! | a document damaged on disk, then edited again | a stale warp served under the same ETag | `a_document_refused_on_start_falls_back_to_the_revision_before_as_a_new_one` |
//! | damaged state started with `--demo` | the demo silently replaced it | `damaged_state_stops_the_start_even_with_demo_unless_reset` |
//! | kill -9 rounds | temporary files left forever | `temporary_files_a_killed_process_left_are_removed_at_start` |
//! | slowloris headers | connections held 70 s+, health stopped | `slow_clients_are_cut_off_and_do_not_stop_health` |
//! | a body that never arrives | held without a deadline | `a_body_that_never_arrives_times_out` |
//! | `?scale=abc`, 413, 405, trailing garbage | text or empty bodies, fields not JSON pointers | `every_refusal_is_the_one_json_shape_with_a_field` |
//! | SIGTERM with a change feed open | the process kept running | `sigterm_ends_the_daemon_with_an_event_stream_open` |
//! | limits nobody could find | undocumented | `the_limits_are_documented_where_users_read_them` |

use crate::common;

use axum::body::Body;
use axum::http::{Request, StatusCode, header};
use common::server::{call, demo_rig, demo_state, flat_rig, get, json, start, state, write};
use omniwarp::server::client::Client;
use omniwarp::server::{AppState, OpenOptions, Options, Store};
use std::io::{Read, Write};
use std::net::{SocketAddr, TcpStream};
use std::path::Path;
use std::sync::Arc;
use std::time::{Duration, Instant};

fn rig_body(s: &Arc<AppState>) -> serde_json::Value {
    serde_json::to_value(&s.store.snapshot().0.doc).unwrap()
}

async fn put_rig(s: &Arc<AppState>, doc: &serde_json::Value) -> (StatusCode, serde_json::Value) {
    let (_, rev) = s.store.snapshot();
    let (st, _, body) = call(s, write("PUT", "/v1/rig", Some(rev), doc.to_string())).await;
    (st, json(&body))
}

/// Health answers, and fast, on the oneshot router.
async fn healthy(s: &Arc<AppState>) {
    let t = Instant::now();
    let (st, _, body) = call(s, get("/v1/health")).await;
    assert_eq!(
        (st, json(&body)["status"].as_str()),
        (StatusCode::OK, Some("ok"))
    );
    assert!(t.elapsed() < Duration::from_secs(1));
}

/// Health over a fresh connection to a real daemon, within a second.
fn healthy_at(addr: SocketAddr) {
    let t = Instant::now();
    let r = Client::new(addr, None).get("/v1/health").unwrap();
    assert_eq!(r.status, 200);
    assert!(
        t.elapsed() < Duration::from_secs(1),
        "health took {:?}",
        t.elapsed()
    );
}

#[tokio::test]
async fn a_spline_with_billions_of_knots_is_refused_before_anything_is_allocated() {
    let s = state(None, None);
    let mut doc = rig_body(&s);
    let huge = "LENSMODEL_SPLINED_STEREOGRAPHIC_order=3_Nx=4294967295_Ny=4294967295_fov_x_deg=100";
    doc["channels"][0]["lens"]["model"] = huge.into();
    let (st, body) = put_rig(&s, &doc).await;
    assert_eq!(st, StatusCode::BAD_REQUEST);
    assert_eq!(body["field"], "/channels/0/lens/model");
    assert!(body["error"].as_str().unwrap().contains("limit"), "{body}");
    // The same model in a calibration body.
    let cal = serde_json::json!({"points": [], "lens": {"model": huge, "intrinsics": []}});
    let (st, _, body) = call(
        &s,
        write(
            "POST",
            "/v1/channels/left/calibration",
            None,
            cal.to_string(),
        ),
    )
    .await;
    assert_eq!(
        (st, json(&body)["field"].as_str()),
        (StatusCode::BAD_REQUEST, Some("/lens/model"))
    );
    assert_eq!(s.store.snapshot().1, 1, "the rig is unchanged");
    healthy(&s).await;
}

#[tokio::test]
async fn a_rig_whose_warps_exceed_the_memory_budget_is_refused_and_never_saved() {
    let dir = tempfile::tempdir().unwrap();
    let s = state(Some(dir.path()), None);
    let mut doc = rig_body(&s);
    doc["channels"][1]["resolution"] = serde_json::json!([16384, 16384]);
    let (st, body) = put_rig(&s, &doc).await;
    assert_eq!(st, StatusCode::BAD_REQUEST, "{body}");
    assert_eq!(body["field"], "/channels/1/resolution");
    assert!(
        body["error"].as_str().unwrap().contains("memory budget"),
        "{body}"
    );
    let saved = common::server::stored(dir.path(), "rig")
        .unwrap()
        .1
        .to_string();
    assert!(
        !saved.contains("16384"),
        "the refused rig never reaches the disk"
    );

    // The budget is the daemon's setting: a small one refuses even the test rig…
    let small = AppState::with_options(
        Store::open(None, Some(flat_rig())).unwrap(),
        Options {
            memory_budget: 1 << 20,
            ..Options::default()
        },
    );
    let (st, _) = put_rig(&small, &rig_body(&small)).await;
    assert_eq!(st, StatusCode::BAD_REQUEST);
    // …and a data directory holding a rig above it does not start.
    let opened = Store::open_with(
        Some(dir.path().to_path_buf()),
        OpenOptions {
            memory_budget: 1 << 20,
            ..OpenOptions::default()
        },
    );
    assert!(opened.is_err());
    healthy(&s).await;
}

/// A mesh screen is counted in the memory budget with the warps, from its triangle count before
/// anything is built: a 5 MiB OBJ of polygons fanning into a million triangles (288 MB to read
/// and index) is refused under a 768 MiB budget of which the demo rig's warps take 569, while a mesh
/// within what is left is taken.
#[tokio::test]
async fn a_mesh_is_counted_in_the_memory_budget_before_it_is_built() {
    let dir = tempfile::tempdir().unwrap();
    let budget = 768 << 20;
    let store = Store::open_with(
        Some(dir.path().to_path_buf()),
        OpenOptions {
            initial: Some(demo_rig()),
            memory_budget: budget,
            ..OpenOptions::default()
        },
    )
    .unwrap();
    let s = AppState::with_options(
        store,
        Options {
            memory_budget: budget,
            ..Options::default()
        },
    );
    let ring = 1000;
    let mut many = String::from("v 0 0 -3\n");
    for i in 0..ring {
        let a = i as f64 / ring as f64 * std::f64::consts::TAU;
        many += &format!("v {} {} -3\n", 3.0 * a.cos(), 3.0 * a.sin());
    }
    let polygon: Vec<String> = (1..=ring + 1).map(|i| i.to_string()).collect();
    let polygon = format!("f {}\n", polygon.join(" "));
    many += &polygon.repeat(1_000_000 / (ring - 1) + 1);
    assert!(many.len() < 6 << 20, "{} bytes", many.len());
    for (name, obj) in [("many.obj", many), ("fan.obj", fan(100_000, -3.0))] {
        let upload = Request::put(format!("/v1/meshes/{name}"))
            .body(Body::from(obj))
            .unwrap();
        assert_eq!(call(&s, upload).await.0, StatusCode::CREATED);
    }
    let t = Instant::now();
    let (st, body) = put_rig(&s, &with_mesh(&s, "many.obj")).await;
    assert_eq!(
        (st, body["field"].as_str()),
        (StatusCode::BAD_REQUEST, Some("/screen/obj")),
        "{body}"
    );
    let why = body["error"].as_str().unwrap();
    assert!(
        why.starts_with("`many.obj`: its 1000998 triangles need 274 MiB")
            && why.contains("memory budget"),
        "{why}"
    );
    assert!(t.elapsed() < Duration::from_secs(2), "{:?}", t.elapsed());
    let (st, body) = put_rig(&s, &with_mesh(&s, "fan.obj")).await;
    assert_eq!(st, StatusCode::OK, "{body}");
}

#[tokio::test]
async fn smoothing_iterations_are_bounded() {
    let s = state(None, None);
    let patch =
        serde_json::json!({"edits": [{"op": "smooth", "iterations": 1_000_000_000_000u64}]});
    let t = Instant::now();
    let (st, _, body) = call(
        &s,
        write(
            "PATCH",
            "/v1/channels/left/tiles",
            Some(1),
            patch.to_string(),
        ),
    )
    .await;
    assert_eq!(
        (st, json(&body)["field"].as_str()),
        (StatusCode::BAD_REQUEST, Some("/edits/0/iterations"))
    );
    assert!(t.elapsed() < Duration::from_secs(2));
    // The largest allowed smooth runs in the worker pool and finishes.
    let patch = serde_json::json!({"edits": [{"op": "smooth", "iterations": omniwarp::limits::SMOOTH_ITERATIONS}]});
    let (st, _, _) = call(
        &s,
        write(
            "PATCH",
            "/v1/channels/left/tiles",
            Some(1),
            patch.to_string(),
        ),
    )
    .await;
    assert_eq!(st, StatusCode::OK);
    healthy(&s).await;
}

/// One PATCH does a bounded amount of work (1000 × smooth(1000), each edit within its own
/// limits, used to hold the channel for minutes), and reads of the channel never wait on a
/// write in progress: they see the last committed revision.
#[tokio::test]
async fn a_patch_is_bounded_in_work_and_reads_do_not_wait_on_it() {
    let s = state(None, None);
    let smooths = |n: usize| {
        let edits: Vec<_> = (0..n)
            .map(|_| serde_json::json!({"op": "smooth", "iterations": 1000}))
            .collect();
        serde_json::json!({"edits": edits}).to_string()
    };
    let t = Instant::now();
    let (st, _, body) = call(
        &s,
        write("PATCH", "/v1/channels/left/tiles", Some(1), smooths(1000)),
    )
    .await;
    let body = json(&body);
    assert_eq!(st, StatusCode::BAD_REQUEST, "{body}");
    let field = body["field"].as_str().unwrap().to_string();
    assert!(
        field.starts_with("/edits/") && field != "/edits/0",
        "{body}"
    );
    assert!(body["error"].as_str().unwrap().contains("limit"), "{body}");
    assert!(t.elapsed() < Duration::from_secs(10), "{:?}", t.elapsed());
    // Just under the bound (the field names the first edit past it): a write of a second or
    // more, during which the channel's reads are answered at once from revision 1.
    let within: usize = field["/edits/".len()..].parse().unwrap();
    let _ = call(&s, get("/v1/channels/left/render?scale=4")).await;
    let writer = {
        let s = s.clone();
        tokio::spawn(async move {
            let t = Instant::now();
            let patch = write("PATCH", "/v1/channels/left/tiles", Some(1), smooths(within));
            let (st, _, _) = call(&s, patch).await;
            (st, t.elapsed())
        })
    };
    tokio::time::sleep(Duration::from_millis(200)).await;
    for uri in [
        "/v1/channels/left/tiles",
        "/v1/channels/left/content",
        "/v1/channels/left/render?scale=4",
    ] {
        let t = Instant::now();
        let (st, _, b) = call(&s, get(uri)).await;
        assert_eq!(st, StatusCode::OK, "{uri}: {}", String::from_utf8_lossy(&b));
        assert!(
            t.elapsed() < Duration::from_secs(1),
            "{uri} waited {:?}",
            t.elapsed()
        );
        if uri.ends_with("tiles") {
            assert_eq!(json(&b)["revision"], 1, "a write in progress is not seen");
        }
    }
    assert!(!writer.is_finished(), "the write should still be running");
    let (st, took) = writer.await.unwrap();
    assert_eq!(st, StatusCode::OK);
    eprintln!("{within} × smooth(1000) took {took:?}");
    let (_, _, b) = call(&s, get("/v1/channels/left/tiles")).await;
    assert_eq!(json(&b)["revision"], 2);
}

/// A rig whose screen is the mesh `obj`.
fn with_mesh(s: &Arc<AppState>, obj: &str) -> serde_json::Value {
    let mut doc = rig_body(s);
    doc["screen"] = serde_json::json!({"kind": "mesh", "obj": obj});
    doc
}

#[tokio::test]
async fn mesh_screens_come_from_the_mesh_directories_only() {
    let dir = tempfile::tempdir().unwrap();
    let s = state(Some(dir.path()), None);
    // Host paths, devices, traversal and missing files all get one answer, so it tells nothing
    // about the host's files; none of them is opened.
    let mut answers = Vec::new();
    for obj in [
        "/dev/zero",
        "/etc/passwd",
        "../../../../etc/passwd",
        "/nonexistent",
        "a/b.obj",
    ] {
        let t = Instant::now();
        let (st, body) = put_rig(&s, &with_mesh(&s, obj)).await;
        assert_eq!(
            (st, body["field"].as_str()),
            (StatusCode::BAD_REQUEST, Some("/screen/obj"))
        );
        assert!(t.elapsed() < Duration::from_secs(1));
        answers.push(body["error"].clone());
    }
    assert!(answers.windows(2).all(|w| w[0] == w[1]), "{answers:?}");
    // A FIFO put where meshes live is not a regular file: refused at once, not read forever.
    std::fs::create_dir_all(dir.path().join("meshes")).unwrap();
    let fifo = dir.path().join("meshes/fifo.obj");
    assert!(
        std::process::Command::new("mkfifo")
            .arg(&fifo)
            .status()
            .unwrap()
            .success()
    );
    let (st, _) = put_rig(&s, &with_mesh(&s, "fifo.obj")).await;
    assert_eq!(st, StatusCode::BAD_REQUEST);

    // Uploaded, it can be named.
    let wall = "v -3 -2 -3\nv 3 -2 -3\nv 3 2 -3\nv -3 2 -3\nf 1 2 3 4\n";
    let upload = |body: &str| {
        Request::put("/v1/meshes/wall.obj")
            .header(header::CONTENT_TYPE, "model/obj")
            .body(Body::from(body.to_string()))
            .unwrap()
    };
    assert_eq!(call(&s, upload(wall)).await.0, StatusCode::CREATED);
    assert_eq!(
        call(&s, upload(wall)).await.0,
        StatusCode::OK,
        "the same again"
    );
    let other = wall.replace("-3\n", "-4\n");
    assert_eq!(call(&s, upload(&other)).await.0, StatusCode::CONFLICT);
    let (st, body) = put_rig(&s, &with_mesh(&s, "wall.obj")).await;
    assert_eq!(st, StatusCode::OK, "{body}");
    let (_, _, list) = call(&s, get("/v1/meshes")).await;
    assert_eq!(json(&list)["meshes"], serde_json::json!(["wall.obj"]));
    // Not a mesh, or an unsafe name: refused by field.
    let bad = Request::put("/v1/meshes/x.obj")
        .body(Body::from("f 1 2 3\n"))
        .unwrap();
    assert_eq!(call(&s, bad).await.0, StatusCode::BAD_REQUEST);
    let traversal = Request::put("/v1/meshes/..%2Fx.obj")
        .body(Body::from(wall))
        .unwrap();
    assert_ne!(call(&s, traversal).await.0, StatusCode::CREATED);
    healthy(&s).await;
}

/// Uploaded meshes stay within a quota of files and bytes (507 beyond, until one is deleted);
/// `DELETE /v1/meshes/{name}` removes one the current rig does not show (409 for the one it
/// shows); and a mesh deleted and uploaded again with another shape is another mesh to the
/// warp cache, on disk too.
#[tokio::test]
async fn meshes_keep_to_a_quota_and_can_be_deleted() {
    let dir = tempfile::tempdir().unwrap();
    let s = state(Some(dir.path()), None);
    let upload = |name: &str, obj: String| {
        Request::put(format!("/v1/meshes/{name}"))
            .body(Body::from(obj))
            .unwrap()
    };
    let delete = |name: &str| {
        Request::delete(format!("/v1/meshes/{name}"))
            .body(Body::empty())
            .unwrap()
    };
    assert_eq!(
        call(&s, upload("m.obj", fan(64, -3.0))).await.0,
        StatusCode::CREATED
    );
    let (st, body) = put_rig(&s, &with_mesh(&s, "m.obj")).await;
    assert_eq!(st, StatusCode::OK, "{body}");
    let (st, _, first) = call(&s, get("/v1/channels/left/warp.exr")).await;
    assert_eq!(st, StatusCode::OK);
    // The keeper writes the warp to warps/ a second after the channel's last change.
    let since = Instant::now();
    let kept = |d: std::fs::ReadDir| {
        d.flatten()
            .any(|e| !e.file_name().to_string_lossy().starts_with('.'))
    };
    while !std::fs::read_dir(dir.path().join("warps")).is_ok_and(kept) {
        assert!(since.elapsed() < Duration::from_secs(30), "no warp kept");
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    let (st, _, body) = call(&s, delete("m.obj")).await;
    assert_eq!(
        st,
        StatusCode::CONFLICT,
        "{}",
        String::from_utf8_lossy(&body)
    );
    let mesh_rig = with_mesh(&s, "m.obj");
    let (st, _) = put_rig(
        &s,
        &serde_json::to_value(common::server::demo_rig()).unwrap(),
    )
    .await;
    assert_eq!(st, StatusCode::OK);
    assert_eq!(call(&s, delete("m.obj")).await.0, StatusCode::NO_CONTENT);
    assert_eq!(call(&s, delete("m.obj")).await.0, StatusCode::NOT_FOUND);
    assert!(!dir.path().join("meshes/m.obj").exists());
    // The same name, another wall: the rig document is the same as before, the warp is not.
    assert_eq!(
        call(&s, upload("m.obj", fan(64, -4.0))).await.0,
        StatusCode::CREATED
    );
    let (st, body) = put_rig(&s, &mesh_rig).await;
    assert_eq!(st, StatusCode::OK, "{body}");
    let (_, _, second) = call(&s, get("/v1/channels/left/warp.exr")).await;
    assert_ne!(
        first, second,
        "a warp of the deleted mesh was served for the new one"
    );

    // The quota: as many files as it allows, then 507 naming it, and room again after a delete.
    let most = omniwarp::limits::MESHES;
    for n in 1..most {
        let (st, _, body) = call(&s, upload(&format!("q{n}.obj"), fan(3, -3.0))).await;
        assert_eq!(
            st,
            StatusCode::CREATED,
            "{n}: {}",
            String::from_utf8_lossy(&body)
        );
    }
    let (st, _, body) = call(&s, upload("one-more.obj", fan(3, -3.0))).await;
    let body = json(&body);
    assert_eq!(st, StatusCode::INSUFFICIENT_STORAGE, "{body}");
    assert!(
        body["error"]
            .as_str()
            .unwrap()
            .contains("quota of 256 files"),
        "{body}"
    );
    assert_eq!(call(&s, delete("q1.obj")).await.0, StatusCode::NO_CONTENT);
    assert_eq!(
        call(&s, upload("one-more.obj", fan(3, -3.0))).await.0,
        StatusCode::CREATED
    );
    healthy(&s).await;
}

/// A fan of `n` triangles around the origin on the plane z = `z`.
pub(crate) fn fan(n: usize, z: f64) -> String {
    let mut obj = format!("v 0 0 {z}\n");
    for i in 0..=n {
        let a = i as f64 / n as f64 * std::f64::consts::TAU;
        obj += &format!("v {} {} {z}\n", 3.0 * a.cos(), 3.0 * a.sin());
    }
    for i in 0..n {
        obj += &format!("f 1 {} {}\n", i + 2, i + 3);
    }
    obj
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn of_two_uploads_racing_for_a_mesh_name_one_wins_and_the_other_is_told() {
    let dir = tempfile::tempdir().unwrap();
    let s = state(Some(dir.path()), None);
    // Small, so that both uploads reach the file at nearly the same moment; several rounds,
    // since each is a race (the old check-then-rename lost the first).
    let (a, b) = (fan(50, -3.0), fan(50, -4.0));
    for round in 0..20 {
        let name = format!("/v1/meshes/race{round}.obj");
        let upload = |body: &str| {
            call(
                &s,
                Request::put(&name)
                    .body(Body::from(body.to_string()))
                    .unwrap(),
            )
        };
        let (first, second) = tokio::join!(upload(&a), upload(&b));
        let mut got = [first.0, second.0];
        got.sort();
        assert_eq!(
            got,
            [StatusCode::CREATED, StatusCode::CONFLICT],
            "round {round}: {}",
            String::from_utf8_lossy(&second.2)
        );
        // The file holds the winner's upload whole.
        let kept = std::fs::read_to_string(dir.path().join(format!("meshes/race{round}.obj")));
        let winner = if first.0 == StatusCode::CREATED {
            &a
        } else {
            &b
        };
        assert!(kept.unwrap() == *winner, "round {round}");
    }
}

/// Every file and directory under `dir` that group or others can read or enter.
fn shared_files(dir: &Path) -> Vec<String> {
    use std::os::unix::fs::PermissionsExt;
    let mut found = Vec::new();
    let mut todo = vec![dir.to_path_buf()];
    while let Some(d) = todo.pop() {
        // A temporary file may be renamed away while the walk runs.
        let Ok(meta) = std::fs::metadata(&d) else {
            continue;
        };
        let mode = meta.permissions().mode();
        if mode & 0o077 != 0 {
            found.push(format!("{} {:o}", d.display(), mode & 0o777));
        }
        if d.is_dir() {
            todo.extend(std::fs::read_dir(&d).unwrap().flatten().map(|e| e.path()));
        }
    }
    found
}

#[tokio::test]
async fn the_daemon_keeps_its_files_to_its_user() {
    let root = tempfile::tempdir().unwrap();
    let dir = root.path().join("state");
    let s = state(Some(&dir), None);
    let upload = Request::put("/v1/meshes/wall.obj")
        .body(Body::from(fan(8, -3.0)))
        .unwrap();
    assert_eq!(call(&s, upload).await.0, StatusCode::CREATED);
    let (st, _, _) = call(&s, get("/v1/channels/left/warp.exr")).await;
    assert_eq!(st, StatusCode::OK);
    // The keeper writes the warp a second after the channel's last change.
    let since = Instant::now();
    let kept = |d: std::fs::ReadDir| {
        d.flatten()
            .any(|e| !e.file_name().to_string_lossy().starts_with('.'))
    };
    while !std::fs::read_dir(dir.join("warps")).is_ok_and(kept) {
        assert!(since.elapsed() < Duration::from_secs(30), "no warp kept");
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    let names: Vec<_> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().into_string().unwrap())
        .collect();
    assert!(
        names.iter().any(|n| n.ends_with("-wal")),
        "the test must see the WAL: {names:?}"
    );
    assert_eq!(shared_files(&dir), Vec::<String>::new());
}

#[tokio::test]
async fn numbers_a_client_writes_are_read_strictly() {
    let s = state(None, None);
    // A frame number is digits: `+1` is not frame 1.
    for path in [
        "/v1/channels/left/pattern/+1",
        "/v1/channels/left/pattern/%201",
    ] {
        let (st, _, body) = call(&s, get(path)).await;
        assert_eq!(st, StatusCode::BAD_REQUEST, "{path}");
        assert_eq!(json(&body)["field"], "n", "{path}");
    }
    let capture = Request::put("/v1/channels/left/captures/+1")
        .header(header::CONTENT_TYPE, "image/png")
        .body(Body::from(vec![0u8; 8]))
        .unwrap();
    let (st, _, body) = call(&s, capture).await;
    assert_eq!(st, StatusCode::BAD_REQUEST);
    assert_eq!(json(&body)["field"], "n");
    // A feature's custom value and zoom within what the renderer's f32 holds.
    for (field, value) in [("f", 1e308), ("f", -2e3), ("scale", 1e308)] {
        let edit = serde_json::json!({"edits": [
            {"op": "set_feature", "column": 3, "row": 2, field: value}
        ]});
        let (st, _, body) = call(
            &s,
            write(
                "PATCH",
                "/v1/channels/left/tiles",
                Some(1),
                edit.to_string(),
            ),
        )
        .await;
        let body = json(&body);
        assert_eq!(st, StatusCode::BAD_REQUEST, "{field} {value}: {body}");
        assert!(
            body["field"]
                .as_str()
                .unwrap()
                .ends_with(&format!("/{field}")),
            "{field} {value}: {body}"
        );
    }
}

/// Uploads `frame` as frame `n` of channel `id`'s captures, under `view` if given.
async fn put_capture(
    s: &Arc<AppState>,
    id: &str,
    n: usize,
    view: Option<&str>,
    frame: &omniwarp::structured::Grey,
) -> (StatusCode, serde_json::Value) {
    let query = view.map_or(String::new(), |v| format!("?view={v}"));
    let req = Request::put(format!("/v1/channels/{id}/captures/{n}{query}"))
        .header(header::CONTENT_TYPE, "image/png")
        .body(Body::from(frame.png().unwrap()))
        .unwrap();
    let (st, _, body) = call(s, req).await;
    (st, json(&body))
}

#[tokio::test]
async fn captures_go_with_their_channel() {
    let s = demo_state();
    let tiny = omniwarp::structured::Grey::new(64, 64, vec![0; 64 * 64]);
    assert_eq!(
        put_capture(&s, "right", 0, None, &tiny).await.0,
        StatusCode::OK
    );
    assert_eq!(s.captures.held(), 64 * 64);
    // A rig without `right`: its captures can be neither decoded nor deleted now.
    let mut doc = rig_body(&s);
    doc["channels"]
        .as_array_mut()
        .unwrap()
        .retain(|c| c["id"] != "right");
    let (st, body) = put_rig(&s, &doc).await;
    assert_eq!(st, StatusCode::OK, "{body}");
    assert_eq!(
        s.captures.held(),
        0,
        "the removed channel's captures are still held"
    );
}

#[tokio::test]
async fn a_capture_sequence_that_could_never_be_held_whole_is_refused_at_its_first_frame() {
    let s = demo_state();
    let (_, _, status) = call(&s, get("/v1/channels/left/captures")).await;
    let frames = json(&status)["frames"].as_u64().unwrap() as usize;
    // The smallest square frame whose whole sequence is above the cap, and still within the
    // pixel limit of one frame (so only the cap can refuse it).
    let side = ((omniwarp::limits::CAPTURE_BYTES / frames) as f64).sqrt() as u32 + 1;
    assert!(
        (side as usize).pow(2) <= omniwarp::structured::CAPTURE_PIXELS,
        "{frames} frames of {side}² fit the cap: the test needs a longer sequence"
    );
    let big = omniwarp::structured::Grey::new(side, side, vec![0; (side * side) as usize]);
    let (st, body) = put_capture(&s, "left", 0, None, &big).await;
    assert_eq!(st, StatusCode::BAD_REQUEST, "{body}");
    assert_eq!(body["field"], "body");
    assert!(
        body["error"].as_str().unwrap().contains("sequence"),
        "{body}"
    );
    assert_eq!(s.captures.held(), 0);
}

#[tokio::test]
async fn the_captures_held_at_once_are_bounded_in_sequences_too() {
    let s = demo_state();
    let one = omniwarp::structured::Grey::new(2, 2, vec![0; 4]);
    for v in 0..omniwarp::limits::CAPTURE_SLOTS {
        let (st, body) = put_capture(&s, "left", 0, Some(&format!("v{v}")), &one).await;
        assert_eq!(st, StatusCode::OK, "view {v}: {body}");
    }
    let (st, body) = put_capture(&s, "left", 0, Some("more"), &one).await;
    assert_eq!(st, StatusCode::BAD_REQUEST, "{body}");
    assert_eq!(body["field"], "view");
    // An existing sequence still takes its frames.
    let (st, body) = put_capture(&s, "left", 1, Some("v0"), &one).await;
    assert_eq!(st, StatusCode::OK, "{body}");
}

#[tokio::test]
async fn a_tile_grid_whose_size_overflows_is_refused_from_a_client_and_from_disk() {
    let dir = tempfile::tempdir().unwrap();
    let s = state(Some(dir.path()), None);
    let screen = serde_json::json!({
        "format": 1,
        "layout": {"kind": "grid", "columns": 1u64 << 63, "rows": 2, "features": []}
    });
    let (st, _, body) = call(
        &s,
        write(
            "PUT",
            "/v1/channels/left/tiles",
            Some(1),
            screen.to_string(),
        ),
    )
    .await;
    assert_eq!(
        st,
        StatusCode::BAD_REQUEST,
        "{}",
        String::from_utf8_lossy(&body)
    );
    assert!(
        json(&body)["field"]
            .as_str()
            .unwrap()
            .starts_with("/layout")
    );
    drop(s);
    // The same screen kept in the database (written there by a bug or a hand) stops the start;
    // --reset starts the channel's screen again from the geometry, as a new revision.
    {
        let db =
            omniwarp::server::storage::db::Db::open(Some(&dir.path().join("omniwarp.db"))).unwrap();
        let meta = omniwarp::server::storage::db::Meta {
            who: "test".into(),
            action: "put",
            request: None,
            undo_to: None,
            redo_to: None,
        };
        db.write("channels/left/tiles", None, (2, &screen), &meta)
            .unwrap();
    }
    let refused = Store::open(Some(dir.path().to_path_buf()), Some(flat_rig()));
    let why = refused
        .err()
        .expect("a damaged channel stops the start")
        .to_string();
    assert!(
        why.contains("--reset") && why.contains("channels/left/tiles"),
        "{why}"
    );
    let reset = Store::open_with(
        Some(dir.path().to_path_buf()),
        OpenOptions {
            initial: Some(flat_rig()),
            reset: true,
            ..OpenOptions::default()
        },
    )
    .unwrap();
    let left = reset.channel("left").unwrap();
    let g = left.read();
    assert_eq!((g.tiles.revision, g.tiles.value.is_none()), (3, true));
}

#[tokio::test]
async fn grid_growth_is_bounded_and_quick() {
    let s = state(None, None);
    // Rows inserted all over the grid (row n + 19 rows exist before edit n), so tiles stay
    // well shaped and only the size limit can stop them.
    let edits: Vec<_> = (0..1000)
        .map(|n| serde_json::json!({"op": "insert_row", "at": 1 + (n * 37) % (18 + n)}))
        .collect();
    let t = Instant::now();
    let (st, _, body) = call(
        &s,
        write(
            "PATCH",
            "/v1/channels/left/tiles",
            Some(1),
            serde_json::json!({"edits": edits}).to_string(),
        ),
    )
    .await;
    // 33 columns × (19 + n) rows passes the feature limit long before 1000 rows are in.
    let body = json(&body);
    assert_eq!(st, StatusCode::BAD_REQUEST, "{body}");
    assert!(
        body["field"].as_str().unwrap().starts_with("/edits/"),
        "{body}"
    );
    assert!(body["error"].as_str().unwrap().contains("limit"), "{body}");
    assert!(t.elapsed() < Duration::from_secs(20), "{:?}", t.elapsed());
    let too_many: Vec<_> = (0..1001)
        .map(|_| serde_json::json!({"op": "reset"}))
        .collect();
    let (st, _, body) = call(
        &s,
        write(
            "PATCH",
            "/v1/channels/left/tiles",
            Some(1),
            serde_json::json!({"edits": too_many}).to_string(),
        ),
    )
    .await;
    assert_eq!(
        (st, json(&body)["field"].as_str()),
        (StatusCode::BAD_REQUEST, Some("/edits"))
    );
    healthy(&s).await;
}

/// Raw HTTP/1.1 on a socket: what a client that never reads its answer sends.
fn raw(addr: SocketAddr, request: &str) -> TcpStream {
    let mut c = TcpStream::connect(addr).unwrap();
    c.write_all(request.as_bytes()).unwrap();
    c
}

/// The status code of the answer waiting on `c` (reads its first line only).
fn status_of(c: &mut TcpStream) -> u16 {
    crate::pressure::status_within(c, Duration::from_secs(60))
}

#[test]
fn clients_that_never_read_large_outputs_cannot_pile_them_up() {
    let dir = tempfile::tempdir().unwrap();
    let (mut child, addr) = start(dir.path(), true);
    // The warp map of a 1080p channel is ~24 MB: far more than the socket buffers hold.
    assert_eq!(
        Client::new(addr, None)
            .get("/v1/channels/centre/warp.exr")
            .unwrap()
            .status,
        200
    );
    let get = format!("GET /v1/channels/centre/warp.exr HTTP/1.1\r\nHost: {addr}\r\n\r\n");
    let mut held: Vec<TcpStream> = (0..omniwarp::server::STREAMS + 8)
        .map(|_| raw(addr, &get))
        .collect();
    let codes: Vec<u16> = held.iter_mut().map(status_of).collect();
    let served = codes.iter().filter(|&&c| c == 200).count();
    let busy = codes.iter().filter(|&&c| c == 503).count();
    assert_eq!((served, busy), (omniwarp::server::STREAMS, 8), "{codes:?}");
    healthy_at(addr);
    // Gone clients give their permits back.
    drop(held);
    let t = Instant::now();
    loop {
        let r = Client::new(addr, None)
            .get("/v1/channels/centre/warp.exr")
            .unwrap();
        if r.status == 200 {
            break;
        }
        assert!(
            t.elapsed() < Duration::from_secs(10),
            "permits not returned"
        );
        std::thread::sleep(Duration::from_millis(100));
    }
    child.kill().unwrap();
    child.wait().unwrap();
}

/// 20,000 correspondences on the demo rig's cylinder for channel `left`: a calibration that
/// takes many seconds with the automatic model choice.
fn big_calibration(s: &Arc<AppState>) -> String {
    let rig = s.store.snapshot().0;
    let ch = rig.channel("left").unwrap();
    let mut points = Vec::new();
    for j in 0..125 {
        for i in 0..160 {
            let q = [6.0 + 12.0 * f64::from(i), 4.0 + 8.6 * f64::from(j)];
            if let Some(p) = rig.wall_point(ch, q) {
                points.push(serde_json::json!({"pixel": q, "world": p.to_array()}));
            }
        }
    }
    assert!(points.len() > 15_000);
    serde_json::json!({"points": points}).to_string()
}

fn workers(body: &[u8]) -> (u64, u64) {
    let w = &json(body)["workers"];
    (
        w["free"].as_u64().unwrap(),
        w["cancelled"].as_u64().unwrap(),
    )
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_calibration_stops_when_its_client_goes_away_and_frees_its_worker() {
    let s = demo_state();
    let body = big_calibration(&s);
    let post = call(
        &s,
        write("POST", "/v1/channels/left/calibration", None, body),
    );
    assert!(
        tokio::time::timeout(Duration::from_millis(1500), post)
            .await
            .is_err(),
        "the calibration should still be running"
    );
    // Busy until the work itself has stopped, then free, counted as cancelled.
    let t = Instant::now();
    loop {
        let (_, _, h) = call(&s, get("/v1/health")).await;
        let (free, cancelled) = workers(&h);
        if free == 2 {
            assert_eq!(cancelled, 1);
            break;
        }
        assert!(
            t.elapsed() < Duration::from_secs(5),
            "still working after its client left"
        );
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
    // Too many points are refused by field.
    let many: Vec<_> = (0..omniwarp::limits::CALIBRATION_POINTS + 1)
        .map(|i| serde_json::json!({"pixel": [i as f64, 1.0], "world": [1.0, 2.0, 3.0]}))
        .collect();
    let (st, _, resp) = call(
        &s,
        write(
            "POST",
            "/v1/channels/left/calibration",
            None,
            serde_json::json!({"points": many}).to_string(),
        ),
    )
    .await;
    assert_eq!(
        (st, json(&resp)["field"].as_str()),
        (StatusCode::BAD_REQUEST, Some("/points"))
    );
}

#[tokio::test]
async fn proposals_are_capped_oldest_first() {
    let dir = tempfile::tempdir().unwrap();
    let s = state(Some(dir.path()), None);
    let rig = s.store.snapshot().0;
    let ch = rig.channel("right").unwrap();
    let mut points = Vec::new();
    for j in 0..4 {
        for i in 0..6 {
            let q = [10.0 + 30.0 * f64::from(i), 8.0 + 25.0 * f64::from(j)];
            if let Some(p) = rig.wall_point(ch, q) {
                points.push(serde_json::json!({"pixel": q, "world": p.to_array()}));
            }
        }
    }
    let body = serde_json::json!({"points": points, "lens": rig.doc.channels[1].lens, "intrinsics_fixed": true})
        .to_string();
    let cap = omniwarp::limits::PROPOSALS as u64;
    for _ in 0..cap + 6 {
        let (st, _, _) = call(
            &s,
            write("POST", "/v1/channels/right/calibration", None, body.clone()),
        )
        .await;
        assert_eq!(st, StatusCode::CREATED);
    }
    assert_eq!(
        call(&s, get("/v1/proposals/6")).await.0,
        StatusCode::NOT_FOUND
    );
    assert_eq!(call(&s, get("/v1/proposals/7")).await.0, StatusCode::OK);
    let kept = omniwarp::server::storage::db::Db::open(Some(&dir.path().join("omniwarp.db")))
        .unwrap()
        .proposals()
        .unwrap()
        .len();
    assert_eq!(kept as u64, cap, "and on disk");
    drop(s);
    let again = state(Some(dir.path()), None);
    assert_eq!(
        call(&again, get("/v1/proposals/70")).await.0,
        StatusCode::OK
    );
}

#[tokio::test]
async fn a_vanishing_field_of_view_is_refused() {
    let s = state(None, None);
    let canvas = serde_json::json!({"projection": "equirect", "params": {"hfov": 1e-300, "vfov": 90}, "size": [4096, 2048]});
    let (st, _, body) = call(
        &s,
        write(
            "PUT",
            "/v1/channels/left/content",
            Some(1),
            canvas.to_string(),
        ),
    )
    .await;
    assert_eq!(
        (st, json(&body)["field"].as_str()),
        (StatusCode::BAD_REQUEST, Some("/params/hfov"))
    );
    let zoom = serde_json::json!({"projection": "equirect", "params": {"hfov": 360, "vfov": 180}, "zoom": 1e-300, "size": [4096, 2048]});
    let (st, _, body) = call(
        &s,
        write(
            "PUT",
            "/v1/channels/left/content",
            Some(1),
            zoom.to_string(),
        ),
    )
    .await;
    assert_eq!(
        (st, json(&body)["field"].as_str()),
        (StatusCode::BAD_REQUEST, Some("/zoom"))
    );
    // A tolerance no allowed grid meets is a 422 that says what was reached.
    let (st, _, body) = call(
        &s,
        get("/v1/channels/left/exports/mesh.data?tolerance=0.000001"),
    )
    .await;
    assert_eq!(
        st,
        StatusCode::UNPROCESSABLE_ENTITY,
        "{}",
        String::from_utf8_lossy(&body)
    );
    assert_eq!(json(&body)["field"], "tolerance");
    assert!(json(&body)["error"].as_str().unwrap().contains("reaches"));
    healthy(&s).await;
}

fn with_headers(method: &str, uri: &str, headers: &[(&str, &str)], body: &str) -> Request<Body> {
    let mut b = Request::builder().method(method).uri(uri);
    for (k, v) in headers {
        b = b.header(*k, *v);
    }
    b.body(Body::from(body.to_string())).unwrap()
}

#[tokio::test]
async fn a_rebinding_host_is_refused_and_changes_nothing() {
    let s = state(None, None);
    let doc = rig_body(&s).to_string();
    let json_type = ("content-type", "application/json");
    for host in [
        "attacker.example",
        "attacker.example:7878",
        "127.0.0.1.nip.io",
        "localhost.evil",
    ] {
        let r = with_headers("GET", "/v1/rig", &[("host", host)], "");
        let (st, _, body) = call(&s, r).await;
        assert_eq!(
            (st, json(&body)["field"].as_str()),
            (StatusCode::FORBIDDEN, Some("Host"))
        );
        let r = with_headers(
            "PUT",
            "/v1/rig",
            &[("host", host), ("if-match", "\"1\""), json_type],
            &doc,
        );
        assert_eq!(call(&s, r).await.0, StatusCode::FORBIDDEN);
    }
    assert_eq!(s.store.snapshot().1, 1, "no write went through");
    for host in [
        "localhost:7878",
        "127.0.0.1:7878",
        "[::1]:7878",
        "127.0.0.2",
        "LOCALHOST",
    ] {
        let (st, _, _) = call(&s, with_headers("GET", "/v1/health", &[("host", host)], "")).await;
        assert_eq!(st, StatusCode::OK, "{host}");
    }
    // A name the operator allows.
    let named = AppState::with_options(
        Store::open(None, Some(flat_rig())).unwrap(),
        Options {
            allow_hosts: vec!["showpc.local".into()],
            ..Options::default()
        },
    );
    let r = with_headers("GET", "/v1/health", &[("host", "showpc.local:7878")], "");
    assert_eq!(call(&named, r).await.0, StatusCode::OK);
}

#[tokio::test]
async fn a_cross_site_form_post_is_refused_and_only_allowed_origins_pass_preflight() {
    let s = state(None, None);
    let form = with_headers(
        "POST",
        "/v1/channels/left/calibration",
        &[("host", "127.0.0.1:7878"), ("content-type", "text/plain")],
        "{\"points\": []}",
    );
    let (st, _, body) = call(&s, form).await;
    assert_eq!(
        (st, json(&body)["field"].as_str()),
        (StatusCode::UNSUPPORTED_MEDIA_TYPE, Some("Content-Type"))
    );
    let evil = with_headers(
        "POST",
        "/v1/channels/left/calibration",
        &[
            ("host", "127.0.0.1:7878"),
            ("origin", "http://evil.example"),
            ("content-type", "application/json"),
        ],
        "{\"points\": []}",
    );
    let (st, _, body) = call(&s, evil).await;
    assert_eq!(
        (st, json(&body)["field"].as_str()),
        (StatusCode::FORBIDDEN, Some("Origin"))
    );
    let preflight = |origin: &str| {
        with_headers(
            "OPTIONS",
            "/v1/rig",
            &[
                ("host", "127.0.0.1:7878"),
                ("origin", origin),
                ("access-control-request-method", "PUT"),
            ],
            "",
        )
    };
    assert_eq!(
        call(&s, preflight("http://evil.example")).await.0,
        StatusCode::FORBIDDEN
    );
    // The daemon's own origin may; so may one the operator names, with CORS headers.
    let own = with_headers(
        "GET",
        "/v1/rig",
        &[
            ("host", "127.0.0.1:7878"),
            ("origin", "http://127.0.0.1:7878"),
        ],
        "",
    );
    assert_eq!(call(&s, own).await.0, StatusCode::OK);
    let console = AppState::with_options(
        Store::open(None, Some(flat_rig())).unwrap(),
        Options {
            allow_origins: vec!["https://console.example".into()],
            ..Options::default()
        },
    );
    let (st, h, _) = call(&console, preflight("https://console.example")).await;
    assert_eq!(st, StatusCode::NO_CONTENT);
    assert_eq!(h["access-control-allow-origin"], "https://console.example");
    assert!(
        h["access-control-allow-headers"]
            .to_str()
            .unwrap()
            .contains("if-match")
    );
    let (st, h, _) = call(
        &console,
        with_headers(
            "GET",
            "/v1/rig",
            &[("origin", "https://console.example")],
            "",
        ),
    )
    .await;
    assert_eq!(st, StatusCode::OK);
    assert!(
        h["access-control-expose-headers"]
            .to_str()
            .unwrap()
            .contains("etag")
    );
}

/// PATCH one feature of channel `left` to `theta`, based on `revision`.
async fn set_theta(s: &Arc<AppState>, revision: u64, theta: f64) -> StatusCode {
    let edit = serde_json::json!({"edits": [{"op": "set_feature", "column": 16, "row": 9, "theta": theta}]});
    call(
        s,
        write(
            "PATCH",
            "/v1/channels/left/tiles",
            Some(revision),
            edit.to_string(),
        ),
    )
    .await
    .0
}

/// A kept document that fails validation on start (written behind the daemon's back, or valid
/// under an older release) falls back to the newest revision before it that passes, kept as a
/// new revision: revision numbers never repeat, so no cache can serve the lost one's warp.
#[tokio::test]
async fn a_document_refused_on_start_falls_back_to_the_revision_before_as_a_new_one() {
    let dir = tempfile::tempdir().unwrap();
    let s = state(Some(dir.path()), None);
    assert_eq!(set_theta(&s, 1, 0.3).await, StatusCode::OK);
    assert_eq!(set_theta(&s, 2, 0.6).await, StatusCode::OK);
    let (_, h, _) = call(&s, get("/v1/channels/left/warp.exr")).await;
    let kept_tag = h[header::ETAG].to_str().unwrap().to_string();
    drop(s);
    let (_, mut doc) = common::server::stored(dir.path(), "channels/left/tiles").unwrap();
    doc["layout"]["features"][0]["x"] = serde_json::json!(7.0);
    doc["revision"] = serde_json::json!(4);
    let db =
        omniwarp::server::storage::db::Db::open(Some(&dir.path().join("omniwarp.db"))).unwrap();
    let meta = omniwarp::server::storage::db::Meta {
        who: "test".into(),
        action: "put",
        request: None,
        undo_to: None,
        redo_to: None,
    };
    db.write("channels/left/tiles", None, (4, &doc), &meta)
        .unwrap();
    drop(db);
    let s = state(Some(dir.path()), None);
    let (_, h, _) = call(&s, get("/v1/channels/left/warp.exr")).await;
    let tag = h[header::ETAG].to_str().unwrap();
    assert!(tag.ends_with("-1.5\""), "{tag}");
    // The ETag's first part hashes what the warp is computed from.
    let hash = |t: &str| t.split('-').next().unwrap().to_string();
    assert_eq!(
        hash(tag),
        hash(&kept_tag),
        "revision 5 shows what revision 3 showed"
    );
    assert_eq!(set_theta(&s, 5, -0.6).await, StatusCode::OK);
    let (_, h, _) = call(&s, get("/v1/channels/left/warp.exr")).await;
    assert!(h[header::ETAG].to_str().unwrap().ends_with("-1.6\""));
}

#[test]
fn damaged_state_stops_the_start_even_with_demo_unless_reset() {
    let dir = tempfile::tempdir().unwrap();
    drop(Store::open(Some(dir.path().to_path_buf()), Some(flat_rig())).unwrap());
    let db = dir.path().join("omniwarp.db");
    let mut bytes = std::fs::read(&db).unwrap();
    // A sector of garbage over the header: no longer a database SQLite opens.
    bytes[..512].fill(0x5a);
    std::fs::write(&db, &bytes).unwrap();
    let demo = demo_rig();
    let refused = Store::open(Some(dir.path().to_path_buf()), Some(demo.clone()));
    let why = refused
        .err()
        .expect("damaged state stops the start")
        .to_string();
    assert!(
        why.contains("omniwarp.db") && why.contains("--reset"),
        "{why}"
    );
    assert_eq!(std::fs::read(&db).unwrap(), bytes, "nothing is overwritten");
    // The binary says the same and exits non-zero.
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_omniwarp"))
        .args(["serve", "--demo", "--bind", "127.0.0.1:0", "--data"])
        .arg(dir.path())
        .output()
        .unwrap();
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("--reset"));
    let reset = Store::open_with(
        Some(dir.path().to_path_buf()),
        OpenOptions {
            initial: Some(demo),
            reset: true,
            ..OpenOptions::default()
        },
    )
    .unwrap();
    assert_eq!(reset.snapshot().1, 1);
    assert_eq!(
        std::fs::read(dir.path().join("omniwarp.db.damaged")).unwrap(),
        bytes,
        "set aside for whoever wants to look"
    );
}

#[test]
fn temporary_files_a_killed_process_left_are_removed_at_start() {
    let dir = tempfile::tempdir().unwrap();
    drop(Store::open(Some(dir.path().to_path_buf()), Some(flat_rig())).unwrap());
    let left: Vec<_> = ["", "meshes", "warps"]
        .iter()
        .map(|sub| {
            let d = dir.path().join(sub);
            std::fs::create_dir_all(&d).unwrap();
            let f = d.join(".omniwarp-Ab12Cd");
            std::fs::write(&f, "half").unwrap();
            f
        })
        .collect();
    drop(Store::open(Some(dir.path().to_path_buf()), None).unwrap());
    for f in left {
        assert!(!f.exists(), "{} left behind", f.display());
    }
}

#[test]
fn slow_clients_are_cut_off_and_do_not_stop_health() {
    let dir = tempfile::tempdir().unwrap();
    let (mut child, addr) = start(dir.path(), true);
    // Slowloris: headers that never end, and connections that say nothing.
    let mut slow: Vec<TcpStream> = (0..200)
        .map(|i| {
            let partial = format!("GET /v1/health HTTP/1.1\r\nHost: {addr}\r\nX-Slow: {i}\r\n");
            raw(addr, if i % 2 == 0 { &partial } else { "" })
        })
        .collect();
    healthy_at(addr);
    // Within the header deadline (10 s) every one of them is closed by the server.
    let deadline = omniwarp::server::HEADER_TIMEOUT + Duration::from_secs(5);
    let t = Instant::now();
    for c in &mut slow {
        c.set_read_timeout(Some(
            deadline
                .saturating_sub(t.elapsed())
                .max(Duration::from_millis(10)),
        ))
        .unwrap();
        let mut buf = [0u8; 512];
        let closed = loop {
            match c.read(&mut buf) {
                Ok(0) => break true,
                Ok(_) => continue,
                Err(e) if e.kind() == std::io::ErrorKind::ConnectionReset => break true,
                Err(_) => break false,
            }
        };
        assert!(
            closed,
            "a slow connection is still open after {:?}",
            t.elapsed()
        );
    }
    healthy_at(addr);
    child.kill().unwrap();
    child.wait().unwrap();
}

#[tokio::test(start_paused = true)]
async fn a_body_that_never_arrives_times_out() {
    let s = state(None, None);
    // A body stream that never yields: the guard's deadline answers 408.
    let never = futures_util::stream::pending::<Result<axum::body::Bytes, std::io::Error>>();
    let req = Request::put("/v1/rig")
        .header(header::CONTENT_TYPE, "application/json")
        .header(header::IF_MATCH, "\"1\"")
        .body(Body::from_stream(never))
        .unwrap();
    let (st, _, body) = call(&s, req).await;
    assert_eq!(
        st,
        StatusCode::REQUEST_TIMEOUT,
        "{}",
        String::from_utf8_lossy(&body)
    );
}

#[tokio::test]
async fn every_refusal_is_the_one_json_shape_with_a_field() {
    let s = state(None, None);
    let check = |st: StatusCode, body: &[u8], want: StatusCode, field: Option<&str>| {
        assert_eq!(st, want, "{}", String::from_utf8_lossy(body));
        let v: serde_json::Value = serde_json::from_slice(body).expect("a JSON body");
        assert!(v["error"].is_string(), "{v}");
        assert_eq!(v["field"].as_str(), field, "{v}");
    };
    let (st, _, b) = call(&s, get("/v1/channels/left/render?scale=abc")).await;
    check(st, &b, StatusCode::BAD_REQUEST, Some("scale"));
    let (st, _, b) = call(&s, get("/v1/channels/left/render?sclae=2")).await;
    check(st, &b, StatusCode::BAD_REQUEST, Some("sclae"));
    let (st, _, b) = call(&s, get("/v1/proposals/abc")).await;
    check(st, &b, StatusCode::NOT_FOUND, None);
    let (st, h, b) = call(&s, write("DELETE", "/v1/rig", Some(1), String::new())).await;
    check(st, &b, StatusCode::METHOD_NOT_ALLOWED, None);
    assert!(h.contains_key(header::ALLOW));
    let big = format!("{{\"x\": \"{}\"}}", "a".repeat(omniwarp::server::MAX_BODY));
    let (st, _, b) = call(&s, write("PUT", "/v1/rig", Some(1), big)).await;
    check(st, &b, StatusCode::PAYLOAD_TOO_LARGE, Some("body"));
    let long = format!("/v1/health?{}", "a".repeat(omniwarp::server::MAX_URI));
    let (st, _, b) = call(&s, get(&long)).await;
    check(st, &b, StatusCode::URI_TOO_LONG, Some("uri"));
    let (st, _, b) = call(
        &s,
        with_headers(
            "GET",
            "/v1/health",
            &[("x-big", &"a".repeat(omniwarp::server::MAX_HEADERS))],
            "",
        ),
    )
    .await;
    check(st, &b, StatusCode::REQUEST_HEADER_FIELDS_TOO_LARGE, None);
    // Trailing garbage after the document.
    let canvas = serde_json::json!({"projection": "equirect", "params": {"hfov": 360, "vfov": 180}, "size": [64, 32]}).to_string();
    let (st, _, b) = call(
        &s,
        write(
            "PUT",
            "/v1/channels/left/content",
            Some(1),
            format!("{canvas}xx"),
        ),
    )
    .await;
    check(st, &b, StatusCode::BAD_REQUEST, Some("/"));
    let (st, _, b) = call(
        &s,
        write("PUT", "/v1/rig", Some(1), format!("{}xx", rig_body(&s))),
    )
    .await;
    check(st, &b, StatusCode::BAD_REQUEST, Some("/"));
    // If-Match: "n" or W/"n", nothing else.
    for bad in ["1", "\"1", "\"1\" junk", "*", "\"-1\"", "\"\""] {
        let r = with_headers(
            "PUT",
            "/v1/channels/left/content",
            &[("if-match", bad), ("content-type", "application/json")],
            &canvas,
        );
        let (st, _, b) = call(&s, r).await;
        check(st, &b, StatusCode::BAD_REQUEST, Some("If-Match"));
    }
    let r = with_headers(
        "PUT",
        "/v1/channels/left/content",
        &[
            ("if-match", "W/\"1\""),
            ("content-type", "application/json"),
        ],
        &canvas,
    );
    assert_eq!(call(&s, r).await.0, StatusCode::OK);
    // A tile screen's fault is named by JSON pointer into the document.
    let (_, _, tiles) = call(&s, get("/v1/channels/left/tiles")).await;
    let mut screen = json(&tiles)["tiles"].clone();
    screen["layout"]["features"][102]["scale"] = serde_json::json!(-1.0);
    let (st, _, b) = call(
        &s,
        write(
            "PUT",
            "/v1/channels/left/tiles",
            Some(1),
            screen.to_string(),
        ),
    )
    .await;
    check(
        st,
        &b,
        StatusCode::BAD_REQUEST,
        Some("/layout/features/102/scale"),
    );
    let bad_view = serde_json::json!({"projection": "equirect", "params": {"hfov": 360, "vfov": 180}, "look_to": [0, 0, 0], "size": [64, 32]});
    let (st, _, b) = call(
        &s,
        write(
            "PUT",
            "/v1/channels/left/content",
            Some(2),
            bad_view.to_string(),
        ),
    )
    .await;
    check(st, &b, StatusCode::BAD_REQUEST, Some("/look_to"));
}

#[test]
fn sigterm_ends_the_daemon_with_an_event_stream_open() {
    let dir = tempfile::tempdir().unwrap();
    let (mut child, addr) = start(dir.path(), true);
    let mut feed = raw(
        addr,
        &format!("GET /v1/events HTTP/1.1\r\nHost: {addr}\r\n\r\n"),
    );
    assert_eq!(status_of(&mut feed), 200);
    let t = Instant::now();
    std::process::Command::new("kill")
        .args(["-TERM", &child.id().to_string()])
        .status()
        .unwrap();
    loop {
        if let Some(status) = child.try_wait().unwrap() {
            assert!(status.success(), "{status}");
            break;
        }
        // Well inside the drain deadline, which only backs this up: the feed ends by itself.
        assert!(
            t.elapsed() < omniwarp::server::DRAIN - Duration::from_secs(1),
            "still running with a feed open after {:?}",
            t.elapsed()
        );
        std::thread::sleep(Duration::from_millis(50));
    }
    // The stream ended rather than being cut mid-event.
    feed.set_read_timeout(Some(Duration::from_secs(2))).unwrap();
    let mut rest = Vec::new();
    let _ = feed.read_to_end(&mut rest);
    assert!(String::from_utf8_lossy(&rest).contains("event: change"));
}

#[test]
fn the_limits_are_documented_where_users_read_them() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let page = std::fs::read_to_string(root.join("docs/limits.md")).unwrap();
    let api = std::fs::read_to_string(root.join("api/openapi.yaml")).unwrap();
    use omniwarp::limits as l;
    let figures = [
        l::CHANNEL_SIDE.to_string(),
        l::CHANNELS.to_string(),
        l::SPLINE_KNOTS_SIDE.to_string(),
        l::TILE_FEATURES.to_string(),
        l::EDITS_PER_PATCH.to_string(),
        l::SMOOTH_ITERATIONS.to_string(),
        l::EDIT_WORK.to_string(),
        l::CALIBRATION_POINTS.to_string(),
        l::PROPOSALS.to_string(),
        l::EXPORT_NODES.to_string(),
        l::FEATURE_VALUE.to_string(),
        l::CAPTURE_SLOTS.to_string(),
        l::MEDIA_SIDE.to_string(),
        l::MESHES.to_string(),
        l::NODES.to_string(),
        l::NODE_OUTPUTS.to_string(),
        l::PLAN_PICTURE_WIDTH[1].to_string(),
        l::PLAN_STEP[0].to_string(),
        omniwarp::server::STREAMS.to_string(),
        omniwarp::server::FEEDS.to_string(),
        omniwarp::server::RESERVE.to_string(),
        omniwarp::server::CONNECTIONS.to_string(),
    ];
    // Numbers are written with thousands separators where they are long.
    let spaced = |n: &str| {
        let mut out = String::new();
        for (i, c) in n.chars().enumerate() {
            if i > 0 && (n.len() - i).is_multiple_of(3) {
                out.push(',');
            }
            out.push(c);
        }
        out
    };
    for f in figures {
        for (name, text) in [("docs/limits.md", &page), ("api/openapi.yaml", &api)] {
            assert!(
                text.contains(&f) || text.contains(&spaced(&f)),
                "{name} does not state the limit {f}"
            );
        }
    }
    for rule in [
        "--allow-host",
        "--allow-origin",
        "--memory-budget",
        "--max-connections",
        "Sec-Fetch-Site",
    ] {
        assert!(page.contains(rule) && api.contains(rule), "{rule}");
    }
}
