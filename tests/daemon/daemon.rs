//! The daemon as a process and as a loaded server: the real binary on port 0 edited over HTTP
//! with its files checked on disk, kill -9 in the middle of a burst of edits, and 32 clients
//! editing one tile screen at once.

use crate::common;

use common::server::start;

use omniwarp::server::client::{Client, Reply};
use std::process::Command;
use std::time::{Duration, Instant};

fn patch(c: &mut Client, channel: &str, revision: u64, edits: serde_json::Value) -> Reply {
    let body = serde_json::json!({ "edits": edits }).to_string();
    let tag = format!("\"{revision}\"");
    c.send(
        "PATCH",
        &format!("/v1/channels/{channel}/tiles"),
        &[("If-Match", &tag), ("Content-Type", "application/json")],
        body.as_bytes(),
    )
    .unwrap()
}

fn feature_f(tiles: &serde_json::Value, column: usize, row: usize) -> f64 {
    let layout = &tiles["tiles"]["layout"];
    let columns = layout["columns"].as_u64().unwrap() as usize;
    layout["features"][row * columns + column]["f"]
        .as_f64()
        .unwrap()
}

#[test]
fn the_binary_serves_the_demo_edits_tiles_and_keeps_files_on_disk() {
    let dir = tempfile::tempdir().unwrap();
    let (mut child, addr) = start(dir.path(), true);
    let mut c = Client::new(addr, None);
    let tiles = c.get("/v1/channels/centre/tiles").unwrap();
    assert_eq!((tiles.status, tiles.revision()), (200, Some(1)));
    let r = patch(
        &mut c,
        "centre",
        1,
        serde_json::json!([{"op": "set_feature", "column": 16, "row": 10, "theta": 5.0, "f": 0.5}]),
    );
    assert_eq!((r.status, r.revision()), (200, Some(2)), "{:?}", r.json());
    let render = c.get("/v1/channels/centre/render?scale=8").unwrap();
    assert_eq!(render.status, 200);
    let img = image::load_from_memory(&render.body).unwrap();
    assert_eq!((img.width(), img.height()), (240, 135));
    let warp = c.get("/v1/channels/centre/warp.exr").unwrap();
    assert_eq!(warp.status, 200);
    assert!(
        warp.header("etag").unwrap().ends_with("-1.2\""),
        "{:?}",
        warp.headers
    );

    // On disk: the rig, the edited tiles with their revision, the warp map of that revision.
    let (revision, saved) = common::server::stored(dir.path(), "channels/centre/tiles").unwrap();
    assert_eq!((revision, &saved["revision"]), (2, &serde_json::json!(2)));
    let feature = &saved["layout"]["features"][10 * 33 + 16];
    assert_eq!(
        (feature["theta"].as_f64(), feature["f"].as_f64()),
        (Some(5.0), Some(0.5))
    );
    assert!(common::server::stored(dir.path(), "rig").is_some());
    // Kept under a hash of what it was computed from: the one in the ETag.
    let hash = warp
        .header("etag")
        .unwrap()
        .trim_matches('"')
        .split('-')
        .next()
        .unwrap()
        .to_string();
    // Written after the answer, by the daemon's keeper thread.
    let path = dir.path().join(format!("warps/centre-{hash}.exr"));
    let since = std::time::Instant::now();
    while !path.exists() && since.elapsed().as_secs() < 30 {
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
    let kept = std::fs::read(&path).unwrap();
    assert_eq!(
        kept, warp.body,
        "the served warp map is the one kept on disk"
    );

    // SIGTERM shuts it down cleanly; a restart without --demo serves the same state.
    Command::new("kill")
        .args(["-TERM", &child.id().to_string()])
        .status()
        .unwrap();
    assert!(child.wait().unwrap().success());
    let (mut child, addr) = start(dir.path(), false);
    let mut c = Client::new(addr, None);
    let tiles = c.get("/v1/channels/centre/tiles").unwrap();
    assert_eq!(tiles.revision(), Some(2));
    assert_eq!(feature_f(&tiles.json(), 16, 10), 0.5);
    child.kill().unwrap();
    child.wait().unwrap();
}

#[test]
fn every_acknowledged_edit_survives_kill_9() {
    let dir = tempfile::tempdir().unwrap();
    let (mut child, addr) = start(dir.path(), true);
    // Three writers, one per channel, each setting f of successive features to distinct values
    // and noting what was acknowledged; the daemon is killed while they write.
    let writers: Vec<_> = ["left", "centre", "right"]
        .into_iter()
        .map(|channel| {
            std::thread::spawn(move || {
                let mut c = Client::new(addr, None);
                let mut acked = Vec::new();
                let mut revision = 1;
                for n in 0..10_000usize {
                    let (column, row) = (n % 33, (n / 33) % 19);
                    let value = 2.0 + n as f64;
                    let body = serde_json::json!([{"op": "set_feature", "column": column, "row": row, "f": value}]);
                    let body = serde_json::json!({ "edits": body }).to_string();
                    let tag = format!("\"{revision}\"");
                    let sent = c.send(
                        "PATCH",
                        &format!("/v1/channels/{channel}/tiles"),
                        &[("If-Match", &tag)],
                        body.as_bytes(),
                    );
                    match sent {
                        Ok(r) if r.status == 200 => {
                            revision = r.revision().unwrap();
                            acked.push((column, row, value, revision));
                        }
                        Ok(r) => panic!("{channel}: status {} {:?}", r.status, r.json()),
                        Err(_) => break, // the daemon is gone
                    }
                }
                (channel, acked)
            })
        })
        .collect();
    std::thread::sleep(Duration::from_millis(1500));
    child.kill().unwrap(); // SIGKILL
    child.wait().unwrap();
    let results: Vec<_> = writers.into_iter().map(|w| w.join().unwrap()).collect();

    let (mut child, addr) = start(dir.path(), false);
    let mut c = Client::new(addr, None);
    let mut total = 0;
    for (channel, acked) in results {
        assert!(
            acked.len() > 5,
            "{channel}: only {} edits before the kill",
            acked.len()
        );
        total += acked.len();
        let tiles = c.get(&format!("/v1/channels/{channel}/tiles")).unwrap();
        let last = acked.last().unwrap().3;
        let now = tiles.revision().unwrap();
        assert!(
            now == last || now == last + 1,
            "{channel}: revision {now} after acknowledging {last}"
        );
        let json = tiles.json();
        // Within the last lap over the features, each acknowledged value is there.
        let lap = 33 * 19;
        for &(column, row, value, _) in acked.iter().rev().take(lap) {
            let f = feature_f(&json, column, row);
            assert!(
                f == value || f == value + lap as f64,
                "{channel} ({column}, {row}): {f} vs {value}"
            );
        }
    }
    eprintln!("{total} acknowledged edits survived kill -9");
    child.kill().unwrap();
    child.wait().unwrap();
}

#[test]
fn thirty_two_clients_editing_one_screen_lose_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let rt = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .unwrap();
    let listener = rt
        .block_on(tokio::net::TcpListener::bind("127.0.0.1:0"))
        .unwrap();
    let addr = listener.local_addr().unwrap();
    let state = common::server::state(Some(dir.path()), None);
    let (stop, stopped) = tokio::sync::oneshot::channel::<()>();
    let server = rt.spawn(omniwarp::server::launch(listener, state, async {
        let _ = stopped.await;
    }));
    const CLIENTS: usize = 32;
    const EDITS: usize = 200;
    let t = Instant::now();
    let clients: Vec<_> = (0..CLIENTS)
        .map(|k| {
            std::thread::spawn(move || {
                let mut c = Client::new(addr, None);
                let (column, row) = (k % 33, k / 33 + 1);
                let mut revision = 1;
                let (mut done, mut attempts) = (0, 0);
                while done < EDITS {
                    attempts += 1;
                    let edit = serde_json::json!([{"op": "set_feature", "column": column, "row": row, "f": (done + 1) as f64}]);
                    let r = patch(&mut c, "left", revision, edit);
                    match r.status {
                        200 => {
                            done += 1;
                            revision = r.revision().unwrap();
                        }
                        412 => {
                            revision = r.json()["current_revision"].as_u64().unwrap();
                            // A little jitter so 32 writers do not retry in lockstep.
                            std::thread::sleep(Duration::from_micros((k as u64 * 37 + attempts) % 500));
                        }
                        s => panic!("client {k}: status {s} {:?}", r.json()),
                    }
                }
                attempts
            })
        })
        .collect();
    let attempts: u64 = clients.into_iter().map(|c| c.join().unwrap()).sum();
    let took = t.elapsed();
    let mut c = Client::new(addr, None);
    let tiles = c.get("/v1/channels/left/tiles").unwrap();
    assert_eq!(tiles.revision(), Some(1 + (CLIENTS * EDITS) as u64));
    let json = tiles.json();
    for k in 0..CLIENTS {
        assert_eq!(
            feature_f(&json, k % 33, k / 33 + 1),
            EDITS as f64,
            "client {k}"
        );
    }
    eprintln!(
        "{} edits by {CLIENTS} clients in {:.1} s ({attempts} attempts)",
        CLIENTS * EDITS,
        took.as_secs_f64()
    );
    assert!(took < Duration::from_secs(240), "{took:?}");
    stop.send(()).unwrap();
    rt.block_on(server).unwrap().unwrap();
}

#[test]
fn the_daemon_tells_a_service_manager_it_is_ready_once_its_port_answers() {
    // systemd's Type=notify: READY=1 as a datagram to $NOTIFY_SOCKET, sent only once the
    // port takes connections.
    use std::os::unix::net::UnixDatagram;
    let dir = tempfile::tempdir().unwrap();
    let socket = dir.path().join("notify");
    let manager = UnixDatagram::bind(&socket).unwrap();
    manager
        .set_read_timeout(Some(std::time::Duration::from_secs(60)))
        .unwrap();
    let mut child = std::process::Command::new(env!("CARGO_BIN_EXE_omniwarp"))
        .args(["serve", "--demo", "--bind", "127.0.0.1:0", "--data"])
        .arg(dir.path().join("data"))
        .env("NOTIFY_SOCKET", &socket)
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap();
    let mut buf = [0u8; 256];
    let n = manager.recv(&mut buf).unwrap();
    let said = String::from_utf8_lossy(&buf[..n]).to_string();
    assert!(said.lines().any(|l| l == "READY=1"), "{said}");
    let mut line = String::new();
    std::io::BufRead::read_line(
        &mut std::io::BufReader::new(child.stdout.take().unwrap()),
        &mut line,
    )
    .unwrap();
    let addr: std::net::SocketAddr = line
        .trim()
        .strip_prefix("listening on http://")
        .unwrap()
        .parse()
        .unwrap();
    let reply = omniwarp::server::client::Client::new(addr, None)
        .get("/v1/health")
        .unwrap();
    assert_eq!(reply.status, 200);
    // A stop is announced too.
    std::process::Command::new("kill")
        .args(["-TERM", &child.id().to_string()])
        .status()
        .unwrap();
    let n = manager.recv(&mut buf).unwrap();
    assert!(String::from_utf8_lossy(&buf[..n]).contains("STOPPING=1"));
    child.wait().unwrap();
}
