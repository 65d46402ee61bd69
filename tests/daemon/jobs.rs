//! Render jobs (`/v1/jobs`): a sequence and a movie from the media folder through the rig's
//! channels, each output equal to `omniwarp render` of each frame's still; progress on the feed;
//! cancelling leaves nothing; paths out of the media folder, bad content and bad options are
//! refused by field; the list survives a restart, a job the daemon stopped in marked failed.

use crate::common::read_u8;
use crate::common::server::{call, flat_rig, get, json, write};
use axum::http::StatusCode;
use omniwarp::raster::Raster;
use omniwarp::server::{AppState, Options, Store};
use serde_json::Value;
use std::path::Path;
use std::process::{Command, Stdio};
use std::sync::Arc;
use std::time::{Duration, Instant};

fn ffmpeg(dir: &Path, args: &str) {
    let mut all = vec!["-hide_banner", "-loglevel", "error", "-y"];
    all.extend(args.split_whitespace());
    let out = Command::new("ffmpeg")
        .current_dir(dir)
        .args(&all)
        .stdin(Stdio::null())
        .output()
        .expect("ffmpeg (scripts/test installs it)");
    assert!(
        out.status.success(),
        "ffmpeg {args}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
}

fn omniwarp(dir: &Path, args: &[&str]) {
    let out = Command::new(env!("CARGO_BIN_EXE_omniwarp"))
        .current_dir(dir)
        .args(args)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}

fn frame_count(file: &Path) -> String {
    let out = Command::new("ffprobe")
        .args(["-v", "error", "-count_frames", "-select_streams", "v:0"])
        .args(["-show_entries", "stream=nb_read_frames", "-of", "csv=p=0"])
        .arg(file)
        .output()
        .unwrap();
    String::from_utf8_lossy(&out.stdout).trim().to_string()
}

fn state(media: Option<&Path>) -> Arc<AppState> {
    AppState::with_options(
        Store::open(None, Some(flat_rig())).unwrap(),
        Options {
            media: media.map(|m| m.canonicalize().unwrap()),
            ..Options::default()
        },
    )
}

async fn post(s: &Arc<AppState>, body: Value) -> (StatusCode, Value) {
    let (status, _, b) = call(s, write("POST", "/v1/jobs", None, body.to_string())).await;
    (status, json(&b))
}

/// The job's record once it has ended (the GET waits for it).
async fn ended(s: &Arc<AppState>, id: u64) -> Value {
    let (status, _, b) = call(s, get(&format!("/v1/jobs/{id}?wait=60"))).await;
    assert_eq!(status, StatusCode::OK);
    let r = json(&b);
    assert!(
        ["done", "failed", "cancelled"].contains(&r["state"].as_str().unwrap()),
        "job {id} still {r}"
    );
    r
}

fn rgb(r: &Raster<[u8; 4]>) -> Vec<[u8; 3]> {
    r.data.iter().map(|p| [p[0], p[1], p[2]]).collect()
}

/// A PNG sequence through both channels of the flat rig into lossless movies: each frame of each
/// channel is `omniwarp render --rig --channel` of that frame's still (blend baked in), the
/// feed tells the progress, the files download as they are on disk.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_sequence_renders_every_channel_as_each_frames_still() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    ffmpeg(
        d,
        "-f lavfi -i testsrc2=size=256x128:rate=15 -frames:v 6 -start_number 1 in-%03d.png",
    );
    let s = state(Some(d));
    let mut feed = s.events.subscribe();
    let (status, r) = post(
        &s,
        serde_json::json!({"content": "in-%03d.png", "container": "nut"}),
    )
    .await;
    assert_eq!(status, StatusCode::ACCEPTED, "{r}");
    assert_eq!(r["state"], "queued");
    assert_eq!(r["frames"], 6);
    let id = r["id"].as_u64().unwrap();
    let r = ended(&s, id).await;
    assert_eq!(r["state"], "done", "{r}");
    assert_eq!(r["frame"], 6);
    let mut heard = Vec::new();
    while let Ok(m) = feed.try_recv() {
        let m: Value = serde_json::from_str(&m).unwrap();
        if m["kind"] == "job" && m["id"] == id {
            heard.push(m["state"].as_str().unwrap().to_string());
        }
    }
    for want in ["queued", "running", "done"] {
        assert!(heard.iter().any(|h| h == want), "the feed said {heard:?}");
    }
    let rig = d.join("rig.json");
    std::fs::write(&rig, serde_json::to_string(&flat_rig()).unwrap()).unwrap();
    let out = d.join("renders").join(id.to_string());
    for ch in ["left", "right"] {
        let movie = out.join(format!("{ch}.nut"));
        assert_eq!(frame_count(&movie), "6", "{ch}");
        // Downloads are the file.
        let (status, headers, body) = call(&s, get(&format!("/v1/jobs/{id}/files/{ch}.nut"))).await;
        assert_eq!(status, StatusCode::OK);
        assert_eq!(headers["content-length"], body.len().to_string().as_str());
        assert!(
            body == std::fs::read(&movie).unwrap(),
            "{ch}: the download differs"
        );
        ffmpeg(
            d,
            &format!("-i {} -start_number 1 {ch}-%03d.png", movie.display()),
        );
        for k in [1, 4, 6] {
            omniwarp(
                d,
                &[
                    "render",
                    "--rig",
                    "rig.json",
                    "--channel",
                    ch,
                    "--content",
                    &format!("in-{k:03}.png"),
                    "--content-format",
                    "equirect",
                    "--out",
                    "still.png",
                ],
            );
            let (a, b) = (
                read_u8(&d.join(format!("{ch}-{k:03}.png"))),
                read_u8(&d.join("still.png")),
            );
            assert!(rgb(&a) == rgb(&b), "{ch}: frame {k} differs from its still");
        }
    }
    let (status, _, _) = call(&s, get(&format!("/v1/jobs/{id}/files/nothing.nut"))).await;
    assert_eq!(status, StatusCode::NOT_FOUND);
    // A finished job is deleted with its folder.
    let (status, _, _) = call(
        &s,
        write("DELETE", &format!("/v1/jobs/{id}"), None, String::new()),
    )
    .await;
    assert_eq!(status, StatusCode::NO_CONTENT);
    assert!(!out.exists());
    let (status, _, _) = call(&s, get(&format!("/v1/jobs/{id}"))).await;
    assert_eq!(status, StatusCode::NOT_FOUND);
}

/// A request without a body: its status and JSON answer.
async fn send(s: &Arc<AppState>, method: &str, uri: &str) -> (StatusCode, Value) {
    let (status, _, b) = call(s, write(method, uri, None, String::new())).await;
    (status, serde_json::from_slice(&b).unwrap_or(Value::Null))
}

/// A movie job cancelled mid-run stops, leaves only its record, and cannot be deleted while it
/// runs; four jobs wait behind it and a fifth is told to come back, a waiting one is cancelled
/// at once; the blend can go beside the movie instead of into it.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_cancelled_movie_leaves_nothing_and_jobs_wait_their_turn() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    ffmpeg(
        d,
        "-f lavfi -i testsrc2=size=512x256:rate=30 -frames:v 1500 -c:v libx264 -preset ultrafast \
         -pix_fmt yuv420p long.mp4",
    );
    ffmpeg(
        d,
        "-f lavfi -i testsrc2=size=256x128:rate=30 -frames:v 3 -pix_fmt yuv420p -c:v libx264 short.mp4",
    );
    let s = state(Some(d));
    let (status, r) = post(
        &s,
        serde_json::json!({"content": "long.mp4", "channels": ["left"]}),
    )
    .await;
    assert_eq!(status, StatusCode::ACCEPTED, "{r}");
    let id = r["id"].as_u64().unwrap();
    let start = Instant::now();
    loop {
        let (_, r) = send(&s, "GET", &format!("/v1/jobs/{id}")).await;
        if r["state"] == "running" && r["frame"].as_u64().unwrap() > 0 {
            break;
        }
        assert!(r["state"] == "queued" || r["state"] == "running", "{r}");
        assert!(start.elapsed() < Duration::from_secs(60));
        tokio::time::sleep(Duration::from_millis(10)).await;
    }
    let (status, _) = send(&s, "DELETE", &format!("/v1/jobs/{id}")).await;
    assert_eq!(status, StatusCode::CONFLICT);
    let mut waiting = Vec::new();
    for _ in 0..4 {
        let (status, r) = post(
            &s,
            serde_json::json!({"content": "short.mp4", "channels": ["left"]}),
        )
        .await;
        assert_eq!(
            (status, r["state"].as_str()),
            (StatusCode::ACCEPTED, Some("queued")),
            "{r}"
        );
        waiting.push(r["id"].as_u64().unwrap());
    }
    let (status, b) = post(&s, serde_json::json!({"content": "short.mp4"})).await;
    assert_eq!(status, StatusCode::SERVICE_UNAVAILABLE, "{b}");
    let (status, r) = send(&s, "POST", &format!("/v1/jobs/{}/cancel", waiting[0])).await;
    assert_eq!(
        (status, r["state"].as_str()),
        (StatusCode::OK, Some("cancelled")),
        "{r}"
    );
    let (status, r) = send(&s, "POST", &format!("/v1/jobs/{id}/cancel")).await;
    assert_eq!(
        (status, r["state"].as_str()),
        (StatusCode::OK, Some("cancelled")),
        "{r}"
    );
    let left: Vec<String> = std::fs::read_dir(d.join("renders").join(id.to_string()))
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    assert_eq!(left, ["job.json"]);
    let (status, _) = send(&s, "POST", &format!("/v1/jobs/{id}/cancel")).await;
    assert_eq!(status, StatusCode::CONFLICT);
    for id in &waiting[1..] {
        assert_eq!(ended(&s, *id).await["state"], "done");
    }
    assert_eq!(ended(&s, waiting[0]).await["state"], "cancelled");

    let (status, r) = post(
        &s,
        serde_json::json!({"content": "short.mp4", "channels": ["right"], "blend": "separate",
                           "crf": 0, "preset": "ultrafast"}),
    )
    .await;
    assert_eq!(status, StatusCode::ACCEPTED, "{r}");
    let r = ended(&s, r["id"].as_u64().unwrap()).await;
    assert_eq!(r["state"], "done", "{r}");
    let names: Vec<&str> = r["files"]
        .as_array()
        .unwrap()
        .iter()
        .map(|f| f["name"].as_str().unwrap())
        .collect();
    assert_eq!(names, ["right.mp4", "right-blend.png"]);
}

/// What cannot be rendered is refused by field before any work, and the daemon goes on.
#[tokio::test]
async fn bad_jobs_are_refused_by_field() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let (status, b) = post(&state(None), serde_json::json!({"content": "a.mp4"})).await;
    assert_eq!(status, StatusCode::CONFLICT, "{b}");
    assert!(b["error"].as_str().unwrap().contains("--media"), "{b}");

    let outside = tempfile::tempdir().unwrap();
    std::fs::write(outside.path().join("secret.mp4"), b"x").unwrap();
    std::os::unix::fs::symlink(outside.path().join("secret.mp4"), d.join("link.mp4")).unwrap();
    std::fs::write(d.join("bad.mp4"), vec![7u8; 4096]).unwrap();
    std::fs::write(d.join("notes.txt"), b"x").unwrap();
    ffmpeg(
        d,
        "-f lavfi -i testsrc2=size=64x32:rate=15 -frames:v 3 -start_number 1 gap-%03d.png",
    );
    std::fs::remove_file(d.join("gap-002.png")).unwrap();
    ffmpeg(
        d,
        "-f lavfi -i testsrc2=size=64x32:rate=15 -frames:v 2 ok.mkv",
    );
    // A sequence whose second frame is a link to a file elsewhere.
    std::fs::create_dir(d.join("shots")).unwrap();
    ffmpeg(
        d,
        "-f lavfi -i testsrc2=size=64x32:rate=15 -frames:v 2 -start_number 1 shots/f-%03d.png",
    );
    let away = outside.path().join("f-002.png");
    std::fs::rename(d.join("shots/f-002.png"), &away).unwrap();
    std::os::unix::fs::symlink(&away, d.join("shots/f-002.png")).unwrap();
    let s = state(Some(d));
    for (body, field) in [
        (serde_json::json!({"content": "../secret.mp4"}), "/content"),
        (serde_json::json!({"content": "/etc/passwd"}), "/content"),
        (serde_json::json!({"content": "link.mp4"}), "/content"),
        (serde_json::json!({"content": "missing.mp4"}), "/content"),
        (serde_json::json!({"content": "notes.txt"}), "/content"),
        (serde_json::json!({"content": "bad.mp4"}), "/content"),
        (serde_json::json!({"content": "gap-%03d.png"}), "/content"),
        (
            serde_json::json!({"content": "ok.mkv", "frame_rate": "25"}),
            "/frame_rate",
        ),
        (
            serde_json::json!({"content": "ok.mkv", "channels": ["middle"]}),
            "/channels/0",
        ),
        (
            serde_json::json!({"content": "ok.mkv", "channels": ["left", "left"]}),
            "/channels/1",
        ),
        (
            serde_json::json!({"content": "ok.mkv", "channels": []}),
            "/channels",
        ),
        (
            serde_json::json!({"content": "ok.mkv", "container": "avi"}),
            "/container",
        ),
        (
            serde_json::json!({"content": "ok.mkv", "encoder": "x264 -y"}),
            "/encoder",
        ),
        (serde_json::json!({"content": "ok.mkv", "crf": 99}), "/crf"),
        (
            serde_json::json!({"content": "ok.mkv", "filter": "lanczos"}),
            "/filter",
        ),
        (
            serde_json::json!({"content": "ok.mkv", "speed": 2}),
            "/speed",
        ),
    ] {
        let (status, b) = post(&s, body.clone()).await;
        assert_eq!(status, StatusCode::BAD_REQUEST, "{body}: {b}");
        assert_eq!(b["field"], field, "{body}: {b}");
    }
    for content in ["link.mp4", "shots/f-%03d.png"] {
        let (status, b) = post(&s, serde_json::json!({ "content": content })).await;
        let error = b["error"].as_str().unwrap();
        assert!(error.contains("out of the media folder"), "{status} {b}");
        assert!(!error.contains(outside.path().to_str().unwrap()), "{b}");
        assert_eq!(b["field"], "/content");
    }
    // A canvas a movie cannot be laid out on.
    let canvas =
        serde_json::json!({"projection": "flat", "params": {"hfov": 90}, "size": [640, 480]});
    let (status, _, _) = call(
        &s,
        write(
            "PUT",
            "/v1/channels/left/content",
            Some(1),
            canvas.to_string(),
        ),
    )
    .await;
    assert_eq!(status, StatusCode::OK);
    let (status, b) = post(
        &s,
        serde_json::json!({"content": "ok.mkv", "channels": ["left"]}),
    )
    .await;
    assert_eq!(status, StatusCode::CONFLICT, "{b}");
    assert_eq!(b["field"], "/projection", "{b}");
    // Canvases that differ only in size differ in layout where a field of view follows the
    // aspect: one decode cannot serve both.
    let canvas = serde_json::json!({"projection": "equirect", "params": {"hfov": 360}, "size": [4096, 1024]});
    let (status, _, _) = call(
        &s,
        write(
            "PUT",
            "/v1/channels/left/content",
            Some(2),
            canvas.to_string(),
        ),
    )
    .await;
    assert_eq!(status, StatusCode::OK);
    let (status, b) = post(&s, serde_json::json!({"content": "ok.mkv"})).await;
    assert_eq!(status, StatusCode::CONFLICT, "{b}");
    assert_eq!(b["field"], "/channels", "{b}");
    let (status, _, b) = call(&s, get("/v1/jobs")).await;
    assert_eq!(status, StatusCode::OK);
    assert_eq!(json(&b)["jobs"], serde_json::json!([]));
    let (status, _, _) = call(&s, get("/v1/jobs/nine")).await;
    assert_eq!(status, StatusCode::NOT_FOUND);
    let (status, _, b) = call(&s, get("/v1/jobs/1?wait=61")).await;
    assert_eq!(
        (status, json(&b)["field"].as_str()),
        (StatusCode::BAD_REQUEST, Some("wait"))
    );
}

/// The list is kept in the media folder: after a restart the finished jobs are there, a job the
/// daemon stopped in is failed with its partial files gone, and new jobs take new numbers.
#[tokio::test]
async fn the_list_survives_a_restart_and_an_interrupted_job_is_failed() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let job = d.join("renders/7");
    std::fs::create_dir_all(&job).unwrap();
    let record = serde_json::json!({
        "id": 7, "state": "running", "content": "show.mp4", "channels": ["left"],
        "container": "mp4", "blend": "baked", "rig_revision": 1, "created_ms": 1,
        "frame": 40, "frames": 100, "files": [],
    });
    std::fs::write(job.join("job.json"), record.to_string()).unwrap();
    std::fs::write(job.join(".left.mp4.partial-123.mp4"), b"half").unwrap();
    // A record that points a download elsewhere, and a job folder that is a link, are not read.
    let planted = d.join("renders/9");
    std::fs::create_dir_all(&planted).unwrap();
    let mut hostile = record.clone();
    hostile["id"] = 9.into();
    hostile["state"] = "done".into();
    hostile["files"] =
        serde_json::json!([{"name": "../../../etc/passwd", "channel": "left", "bytes": 1}]);
    std::fs::write(planted.join("job.json"), hostile.to_string()).unwrap();
    let elsewhere = tempfile::tempdir().unwrap();
    let mut linked = record.clone();
    linked["id"] = 10.into();
    std::fs::write(elsewhere.path().join("job.json"), linked.to_string()).unwrap();
    std::fs::write(elsewhere.path().join("keep.mp4"), b"x").unwrap();
    std::os::unix::fs::symlink(elsewhere.path(), d.join("renders/10")).unwrap();
    let s = state(Some(d));
    let (status, _, b) = call(&s, get("/v1/jobs/7")).await;
    assert_eq!(status, StatusCode::OK);
    let r = json(&b);
    assert_eq!(r["state"], "failed", "{r}");
    assert!(
        r["error"]["reason"].as_str().unwrap().contains("stopped"),
        "{r}"
    );
    let left: Vec<_> = std::fs::read_dir(&job)
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    assert_eq!(left, ["job.json"]);
    for id in [9, 10] {
        let (status, _, _) = call(&s, get(&format!("/v1/jobs/{id}"))).await;
        assert_eq!(status, StatusCode::NOT_FOUND, "job {id}");
    }
    assert!(elsewhere.path().join("keep.mp4").exists());
    let kept: Value =
        serde_json::from_slice(&std::fs::read(job.join("job.json")).unwrap()).unwrap();
    assert_eq!(kept["state"], "failed");
    ffmpeg(
        d,
        "-f lavfi -i testsrc2=size=64x32:rate=15 -frames:v 2 ok.mkv",
    );
    let (status, r) = post(
        &s,
        serde_json::json!({"content": "ok.mkv", "container": "mkv"}),
    )
    .await;
    assert_eq!(status, StatusCode::ACCEPTED, "{r}");
    assert_eq!(r["id"], 11);
    assert_eq!(ended(&s, 11).await["state"], "done");
}

/// A `renders/` that is a link to a folder elsewhere turns jobs off rather than writing (and
/// cleaning up) there.
#[tokio::test]
async fn a_linked_renders_folder_turns_jobs_off() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let elsewhere = tempfile::tempdir().unwrap();
    std::fs::create_dir(elsewhere.path().join("1")).unwrap();
    std::fs::write(elsewhere.path().join("1/keep.mp4"), b"x").unwrap();
    std::os::unix::fs::symlink(elsewhere.path(), d.join("renders")).unwrap();
    ffmpeg(
        d,
        "-f lavfi -i testsrc2=size=64x32:rate=15 -frames:v 2 ok.mkv",
    );
    let s = state(Some(d));
    let (status, b) = post(&s, serde_json::json!({"content": "ok.mkv"})).await;
    assert_eq!(status, StatusCode::CONFLICT, "{b}");
    assert!(elsewhere.path().join("1/keep.mp4").exists());
}
