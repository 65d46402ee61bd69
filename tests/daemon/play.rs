//! The render node, `omniwarp play`: its windows under Xvfb (one wide screen, windows at
//! offsets) screenshot with ffmpeg and compared with the CPU renderer's frames; headless,
//! following the real daemon through show changes, tile edits, a SIGKILL and a restart;
//! against a daemon that answers garbage, whose pictures must never replace a good one; and the
//! daemon's list of nodes.

use crate::common;

use common::server::{start, start_on};
use omniwarp::content::testcard::{self, Card, Label};
use omniwarp::raster::Raster;
use omniwarp::rig::Rig;
use omniwarp::server::client::Client;
use std::io::{BufRead, BufReader, Read, Write};
use std::net::{SocketAddr, TcpListener, TcpStream};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::mpsc;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

fn omniwarp() -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_omniwarp"));
    c.env("NODEVICE_SELECT", "1");
    c
}

fn rig_path(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("calibration/rigs")
        .join(name)
}

fn run(cmd: &mut Command) {
    let out = cmd.output().unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}

/// An X server of one wide screen, stopped when dropped.
struct Xvfb {
    child: Child,
    display: String,
}

impl Xvfb {
    fn start(width: u32, height: u32) -> Xvfb {
        for n in 120..220 {
            if Path::new(&format!("/tmp/.X11-unix/X{n}")).exists()
                || Path::new(&format!("/tmp/.X{n}-lock")).exists()
            {
                continue;
            }
            let display = format!(":{n}");
            let child = Command::new("Xvfb")
                .args([&display, "-screen", "0", &format!("{width}x{height}x24")])
                .args(["-nolisten", "tcp"])
                .stdout(Stdio::null())
                .stderr(Stdio::null())
                .spawn()
                .expect("Xvfb (Debian's xvfb; ./scripts/test installs it)");
            let mut x = Xvfb { child, display };
            let until = Instant::now() + Duration::from_secs(10);
            while Instant::now() < until {
                if Path::new(&format!("/tmp/.X11-unix/X{n}")).exists() {
                    return x;
                }
                if x.child.try_wait().unwrap().is_some() {
                    break;
                }
                std::thread::sleep(Duration::from_millis(50));
            }
            let _ = x.child.kill();
        }
        panic!("no Xvfb display could be started");
    }

    /// The screen's `w × h` pixels at `x, y`, RGB, as ffmpeg's x11grab reads them.
    fn grab(&self, (x, y): (u32, u32), (w, h): (u32, u32)) -> Vec<u8> {
        let out = Command::new("ffmpeg")
            .args(["-loglevel", "error", "-f", "x11grab", "-draw_mouse", "0"])
            .args(["-video_size", &format!("{w}x{h}")])
            .args(["-i", &format!("{}+{x},{y}", self.display)])
            .args(["-frames:v", "1", "-f", "rawvideo", "-pix_fmt", "rgb24", "-"])
            .output()
            .unwrap();
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        out.stdout
    }
}

impl Drop for Xvfb {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

fn rgb(img: &Raster<[u8; 4]>) -> Vec<u8> {
    img.data.iter().flat_map(|p| [p[0], p[1], p[2]]).collect()
}

fn read_rgb(path: &Path) -> Vec<u8> {
    image::open(path).unwrap().into_rgb8().into_raw()
}

/// Stops a node with SIGTERM, as systemd does, and checks it ends by itself, cleanly.
fn terminate(mut node: Child) {
    let _ = Command::new("kill")
        .args(["-TERM", &node.id().to_string()])
        .status();
    let until = Instant::now() + Duration::from_secs(5);
    loop {
        if let Some(status) = node.try_wait().unwrap() {
            assert!(status.success(), "the node ended with {status}");
            return;
        }
        assert!(Instant::now() < until, "the node did not stop on SIGTERM");
        std::thread::sleep(Duration::from_millis(50));
    }
}

/// Waits until the node has printed `showing CHANNEL …` for each of `channels`.
fn wait_shown(node: &mut Child, channels: &[&str]) -> BufReader<std::process::ChildStdout> {
    let mut out = BufReader::new(node.stdout.take().unwrap());
    let mut left: Vec<&str> = channels.to_vec();
    let mut line = String::new();
    while !left.is_empty() {
        line.clear();
        assert!(
            out.read_line(&mut line).unwrap() > 0,
            "the node ended first"
        );
        if let Some(rest) = line.strip_prefix("showing ") {
            left.retain(|c| rest.split(' ').next() != Some(c));
        }
    }
    out
}

/// Retries `check` for a few seconds (a presented frame reaches the X server soon after).
fn eventually(what: &str, mut check: impl FnMut() -> Result<(), String>) {
    let until = Instant::now() + Duration::from_secs(10);
    loop {
        match check() {
            Ok(()) => return,
            Err(e) if Instant::now() > until => panic!("{what}: {e}"),
            Err(_) => std::thread::sleep(Duration::from_millis(100)),
        }
    }
}

/// Plays `args` into windows side by side and checks each window shows `expected` exactly.
fn windows_show(
    x: &Xvfb,
    args: &[&str],
    outputs: &[(&str, (u32, u32), Vec<u8>)],
    size: (u32, u32),
) {
    let mut cmd = omniwarp();
    cmd.arg("play").args(args).env("DISPLAY", &x.display);
    for (channel, (ox, oy), _) in outputs {
        cmd.args([
            "--output",
            &format!("{channel}={ox},{oy},{},{}", size.0, size.1),
        ]);
    }
    let mut node = cmd
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let channels: Vec<&str> = outputs.iter().map(|o| o.0).collect();
    let _out = wait_shown(&mut node, &channels);
    for (channel, at, expected) in outputs {
        eventually(&format!("window {channel}"), || {
            let got = x.grab(*at, size);
            if got.len() != expected.len() {
                return Err(format!(
                    "grabbed {} values, the CPU frame has {}",
                    got.len(),
                    expected.len()
                ));
            }
            let wrong = got.iter().zip(expected).filter(|(a, b)| a != b).count();
            if wrong == 0 {
                Ok(())
            } else {
                Err(format!(
                    "{wrong} of {} values differ from the CPU frame",
                    got.len()
                ))
            }
        });
    }
    terminate(node);
}

#[test]
fn windows_show_the_cpu_renderers_frames_bit_for_bit() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let x = Xvfb::start(5900, 1240);
    let cylinder = rig_path("cylinder-270-3proj.json");
    let equirect = d.join("equirect.png");
    run(omniwarp()
        .args([
            "pattern",
            "--pattern",
            "checker",
            "--size",
            "1024x512",
            "--out",
        ])
        .arg(&equirect));
    // Windows at offsets on one screen, one lower than the others, gaps between them.
    let places = [(0, 0), (1940, 0), (3880, 40)];
    let channels = ["left", "centre", "right"];

    // A still panorama through the cylinder's three channels, blended, as `render` draws it.
    let mut outputs = Vec::new();
    for (c, at) in channels.iter().zip(places) {
        let reference = d.join(format!("{c}.png"));
        run(omniwarp()
            .args(["render", "--rig"])
            .arg(&cylinder)
            .args(["--channel", c, "--content-format", "equirect", "--content"])
            .arg(&equirect)
            .arg("--out")
            .arg(&reference));
        outputs.push((*c, at, read_rgb(&reference)));
    }
    let content = [
        "--rig",
        cylinder.to_str().unwrap(),
        "--content",
        equirect.to_str().unwrap(),
    ];
    let args = [&content[..], &["--content-format", "equirect"]].concat();
    windows_show(&x, &args, &outputs, (1920, 1080));

    // A test card drawn through each channel's warp.
    let rig = Rig::read(&cylinder).unwrap();
    let outputs: Vec<_> = channels
        .iter()
        .zip(places)
        .map(|(c, at)| {
            let index = rig.channels.iter().position(|ch| ch.id == *c).unwrap();
            let map = rig.warp(&rig.channels[index]).map;
            let card = testcard::draw(Card::Crosshatch, &map, &Label { index, id: c });
            (*c, at, rgb(&card))
        })
        .collect();
    windows_show(
        &x,
        &["--rig", cylinder.to_str().unwrap(), "--show", "crosshatch"],
        &outputs,
        (1920, 1080),
    );

    // A dome master through three of the dome's five channels.
    let dome = rig_path("dome-180-tilt15-5proj.json");
    let master = d.join("master.png");
    run(omniwarp()
        .args(["render", "--content-format", "equirect", "--content"])
        .arg(&equirect)
        .args([
            "--projection",
            "fisheye",
            "--fov",
            "180",
            "--size",
            "1024x1024",
            "--out",
        ])
        .arg(&master));
    let mut outputs = Vec::new();
    for (c, at) in ["front", "zenith", "left"]
        .iter()
        .zip([(0, 0), (1940, 0), (3880, 0)])
    {
        let reference = d.join(format!("dome-{c}.png"));
        run(omniwarp()
            .args(["render", "--rig"])
            .arg(&dome)
            .args([
                "--channel",
                c,
                "--content-format",
                "domemaster",
                "--content",
            ])
            .arg(&master)
            .arg("--out")
            .arg(&reference));
        outputs.push((*c, at, read_rgb(&reference)));
    }
    let args = [
        "--rig",
        dome.to_str().unwrap(),
        "--content",
        master.to_str().unwrap(),
    ];
    let args = [&args[..], &["--content-format", "domemaster"]].concat();
    windows_show(&x, &args, &outputs, (1920, 1200));
}

/// Sends `key` to the window titled `title`, as the operator's keyboard would (xdotool): the
/// window is given the focus first, and the key pressed once the window has seen that (a key
/// that arrives with the focus is dropped).
fn press(x: &Xvfb, title: &str, key: &str) {
    let xdotool = |args: &[&str]| {
        let ok = Command::new("xdotool")
            .args(args)
            .env("DISPLAY", &x.display)
            .status()
            .expect("xdotool (Debian's xdotool; ./scripts/test installs it)");
        assert!(ok.success(), "xdotool {args:?}");
    };
    xdotool(&["search", "--name", title, "windowfocus", "--sync"]);
    std::thread::sleep(Duration::from_millis(300));
    xdotool(&["key", key]);
}

#[test]
fn the_operator_mutes_to_black_and_puts_the_overlay_up_from_the_keyboard() {
    let x = Xvfb::start(1920, 1080);
    let cylinder = rig_path("cylinder-270-3proj.json");
    let rig = Rig::read(&cylinder).unwrap();
    let map = rig.warp(&rig.channels[0]).map;
    let card = rgb(&testcard::draw(
        Card::Grid,
        &map,
        &Label {
            index: 0,
            id: "left",
        },
    ));
    let mut node = omniwarp()
        .args([
            "play",
            "--rig",
            cylinder.to_str().unwrap(),
            "--show",
            "grid",
        ])
        .args(["--output", "left=0,0,1920,1080"])
        .env("DISPLAY", &x.display)
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let _out = wait_shown(&mut node, &["left"]);
    let screen = |want: &dyn Fn(&[u8]) -> Result<(), String>, what: &str| {
        eventually(what, || want(&x.grab((0, 0), (1920, 1080))))
    };
    let is_card = |got: &[u8]| {
        (got == card.as_slice())
            .then_some(())
            .ok_or("not the card".into())
    };
    screen(&is_card, "the card");
    press(&x, "omniwarp left", "b");
    screen(
        &|got| {
            got.iter()
                .all(|&v| v == 0)
                .then_some(())
                .ok_or("not black".into())
        },
        "muted to black",
    );
    press(&x, "omniwarp left", "b");
    screen(&is_card, "the card again");
    // The overlay: a darkened box in the middle, white text in it; the corners of the box
    // darkened to a quarter.
    press(&x, "omniwarp left", "o");
    screen(
        &|got| {
            let at = |x: usize, y: usize| (y * 1920 + x) * 3;
            // Two corners of the box, far from the text, grid lines and black between them.
            let corners = [(242..442, 272..322), (1478..1678, 757..807)];
            for (xs, ys) in corners {
                for y in ys {
                    for x in xs.clone() {
                        let (g, c) = (got[at(x, y)], card[at(x, y)]);
                        if g != c / 4 {
                            return Err(format!(
                                "({x}, {y}) is {g}, the card's {c} / 4 is {}",
                                c / 4
                            ));
                        }
                    }
                }
            }
            let white = (272..808)
                .flat_map(|y| (242..1678).map(move |x| (x, y)))
                .filter(|&(x, y)| got[at(x, y)..at(x, y) + 3] == [255, 255, 255])
                .count();
            (white > 1000)
                .then_some(())
                .ok_or(format!("{white} white pixels of text"))
        },
        "the overlay",
    );
    press(&x, "omniwarp left", "o");
    screen(&is_card, "the card without the overlay");
    terminate(node);
}

/// What the daemon lists for node `id`: per output, the ETag it shows.
fn showing(c: &mut Client, id: &str) -> Vec<Option<String>> {
    let nodes = c.get("/v1/nodes").unwrap().json();
    let Some(node) = nodes["nodes"]
        .as_array()
        .unwrap()
        .iter()
        .find(|n| n["id"] == id)
    else {
        return Vec::new();
    };
    node["outputs"]
        .as_array()
        .unwrap()
        .iter()
        .map(|o| o["showing"].as_str().map(String::from))
        .collect()
}

/// Waits until node `id` reports showing, on every output, what the daemon's `output.png` is
/// now, and checks the file it wrote is that picture.
fn caught_up(c: &mut Client, id: &str, out: &Path, channels: &[&str]) {
    eventually("the node showing the daemon's pictures", || {
        let shown = showing(c, id);
        for (i, ch) in channels.iter().enumerate() {
            let now = c.get(&format!("/v1/channels/{ch}/output.png")).unwrap();
            let tag = now.header("etag").map(String::from);
            if shown.get(i) != Some(&tag) {
                return Err(format!(
                    "{ch}: shows {:?}, the daemon has {tag:?}",
                    shown.get(i)
                ));
            }
            let want = image::load_from_memory(&now.body)
                .unwrap()
                .into_rgb8()
                .into_raw();
            if read_rgb(&out.join(format!("{ch}.png"))) != want {
                return Err(format!("{ch}.png is not the daemon's picture"));
            }
        }
        Ok(())
    });
}

#[test]
fn a_headless_node_follows_the_daemon_through_edits_and_a_restart() {
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("data");
    let out = dir.path().join("wall");
    let (mut daemon, addr) = start(&data, true);
    let mut node = omniwarp()
        .args([
            "play",
            "--daemon",
            &format!("http://{addr}"),
            "--node",
            "wall-1",
        ])
        .args(["--headless", "--out"])
        .arg(&out)
        .args(["--output", "left", "--output", "centre"])
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let mut c = Client::new(addr, None);
    let channels = ["left", "centre"];
    caught_up(&mut c, "wall-1", &out, &channels);

    // A test card sent to one channel, then a tile edit on the other.
    let r = c
        .send(
            "PUT",
            "/v1/channels/left/show",
            &[("If-Match", "\"1\"")],
            br#"{"show": "grid"}"#,
        )
        .unwrap();
    assert_eq!(r.status, 200);
    caught_up(&mut c, "wall-1", &out, &channels);
    assert!(
        showing(&mut c, "wall-1")[0]
            .as_deref()
            .unwrap()
            .contains("card-grid")
    );
    let edit = |c: &mut Client, revision: u64| {
        let body = serde_json::json!({"edits": [
            {"op": "set_feature", "column": 16, "row": 10, "theta": 5.0, "f": 0.5}
        ]});
        let r = c
            .send(
                "PATCH",
                "/v1/channels/centre/tiles",
                &[("If-Match", &format!("\"{revision}\""))],
                body.to_string().as_bytes(),
            )
            .unwrap();
        assert_eq!(r.status, 200, "{:?}", r.json());
    };
    let before = showing(&mut c, "wall-1")[1].clone();
    edit(&mut c, 1);
    caught_up(&mut c, "wall-1", &out, &channels);
    assert_ne!(showing(&mut c, "wall-1")[1], before);

    // A frame of the structured-light sequence, as a calibration loop puts it up: on the
    // output bit for bit (grey in every colour), and acknowledged by its ETag.
    let r = c
        .send(
            "PUT",
            "/v1/channels/centre/show",
            &[("If-Match", "\"1\"")],
            br#"{"show": "pattern", "frame": 5, "period": 32}"#,
        )
        .unwrap();
    assert_eq!(r.status, 200, "{:?}", r.json());
    caught_up(&mut c, "wall-1", &out, &channels);
    let frame = c.get("/v1/channels/centre/pattern/5?period=32").unwrap();
    let grey = image::load_from_memory(&frame.body)
        .unwrap()
        .into_luma8()
        .into_raw();
    let rgb: Vec<u8> = grey.iter().flat_map(|&v| [v, v, v]).collect();
    assert!(
        read_rgb(&out.join("centre.png")) == rgb,
        "the pattern frame, bit for bit"
    );
    assert!(
        showing(&mut c, "wall-1")[1]
            .as_deref()
            .unwrap()
            .contains("pattern")
    );

    // The daemon killed: the node's pictures stay where they were.
    let kept = read_rgb(&out.join("centre.png"));
    daemon.kill().unwrap();
    daemon.wait().unwrap();
    std::thread::sleep(Duration::from_millis(1500));
    assert!(
        read_rgb(&out.join("centre.png")) == kept,
        "the picture kept"
    );
    assert!(
        node.try_wait().unwrap().is_none(),
        "the node stopped with the daemon"
    );

    // Back on the same port: the node reconnects, shows the restarted daemon's pictures (the
    // test card was for the minutes of an alignment and is gone) and the next edit.
    let bind = format!("127.0.0.1:{}", addr.port());
    let (mut daemon, _) = start_on(&bind, &data, false, &[]);
    let mut c = Client::new(addr, None);
    caught_up(&mut c, "wall-1", &out, &channels);
    edit(&mut c, 2);
    caught_up(&mut c, "wall-1", &out, &channels);
    terminate(node);
    let _ = daemon.kill();
    let _ = daemon.wait();
}

/// A daemon that serves one good picture for `left`, then garbage, then an error, while
/// keeping the reports it is sent.
struct Liar {
    addr: SocketAddr,
    poke: mpsc::Sender<()>,
    reports: Arc<Mutex<Vec<serde_json::Value>>>,
}

fn liar(good: Vec<u8>) -> Liar {
    let listener = TcpListener::bind("127.0.0.1:0").unwrap();
    let addr = listener.local_addr().unwrap();
    let (poke, poked) = mpsc::channel::<()>();
    let poked = Arc::new(Mutex::new(poked));
    let reports = Arc::new(Mutex::new(Vec::new()));
    let served = Arc::new(Mutex::new(0));
    let r = reports.clone();
    std::thread::spawn(move || {
        for conn in listener.incoming() {
            let Ok(conn) = conn else { return };
            let (good, poked, reports, served) =
                (good.clone(), poked.clone(), r.clone(), served.clone());
            std::thread::spawn(move || serve(conn, &good, &poked, &reports, &served));
        }
    });
    Liar {
        addr,
        poke,
        reports,
    }
}

fn serve(
    conn: TcpStream,
    good: &[u8],
    poked: &Mutex<mpsc::Receiver<()>>,
    reports: &Mutex<Vec<serde_json::Value>>,
    served: &Mutex<usize>,
) {
    let mut w = conn.try_clone().unwrap();
    let mut r = BufReader::new(conn);
    loop {
        let mut line = String::new();
        if r.read_line(&mut line).unwrap_or(0) == 0 {
            return;
        }
        let path = line.split(' ').nth(1).unwrap_or("").to_string();
        let mut len = 0;
        loop {
            let mut h = String::new();
            r.read_line(&mut h).unwrap();
            if h.trim().is_empty() {
                break;
            }
            if let Some(v) = h.to_lowercase().strip_prefix("content-length:") {
                len = v.trim().parse().unwrap();
            }
        }
        let mut body = vec![0; len];
        r.read_exact(&mut body).unwrap();
        let answer = |w: &mut TcpStream, status: &str, tag: &str, body: &[u8]| {
            let head = format!(
                "HTTP/1.1 {status}\r\nContent-Length: {}\r\nETag: {tag}\r\n\r\n",
                body.len()
            );
            let _ = w.write_all(head.as_bytes());
            let _ = w.write_all(body);
        };
        if path == "/v1/events" {
            let head = "HTTP/1.1 200 OK\r\nContent-Type: text/event-stream\r\n\
                        Transfer-Encoding: chunked\r\n\r\n";
            let _ = w.write_all(head.as_bytes());
            let mut event = |data: &str| {
                let e = format!("event: change\ndata: {data}\n\n");
                let _ = write!(w, "{:x}\r\n{e}\r\n", e.len());
            };
            event(r#"{"kind":"rig","revision":1}"#);
            while poked.lock().unwrap().recv().is_ok() {
                event(r#"{"kind":"show","channel":"left","revision":2}"#);
            }
            return;
        } else if path.starts_with("/v1/nodes/") {
            reports
                .lock()
                .unwrap()
                .push(serde_json::from_slice(&body).unwrap());
            let _ = w.write_all(b"HTTP/1.1 204 No Content\r\n\r\n");
        } else if path == "/v1/channels/left/output.png" {
            let mut n = served.lock().unwrap();
            *n += 1;
            match *n {
                1 => answer(&mut w, "200 OK", "\"good\"", good),
                2 => answer(&mut w, "200 OK", "\"garbage\"", b"\x89PNG garbage"),
                _ => answer(&mut w, "500 Internal Server Error", "\"x\"", b"{}"),
            }
        } else {
            answer(&mut w, "404 Not Found", "\"x\"", b"{}");
        }
    }
}

#[test]
fn a_bad_picture_never_replaces_a_good_one() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("wall");
    let good = Raster::from_fn(64, 48, |x, y| [(x * 4) as u8, (y * 5) as u8, 99, 255]);
    let png = omniwarp::image_io::png_bytes(&good).unwrap();
    let daemon = liar(png);
    let node = omniwarp()
        .args([
            "play",
            "--daemon",
            &format!("http://{}", daemon.addr),
            "--node",
            "n",
        ])
        .args(["--headless", "--out"])
        .arg(&out)
        .args(["--output", "left"])
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let last = || {
        daemon
            .reports
            .lock()
            .unwrap()
            .last()
            .cloned()
            .unwrap_or_default()
    };
    eventually("the good picture reported", || {
        let r = last();
        (r["outputs"][0]["showing"] == "\"good\"")
            .then_some(())
            .ok_or(format!("{r}"))
    });
    assert!(
        read_rgb(&out.join("left.png")) == rgb(&good),
        "the good picture"
    );
    for reason in ["not a picture", "answered 500"] {
        daemon.poke.send(()).unwrap();
        eventually(&format!("the node saying {reason}"), || {
            let r = last();
            let said = r["error"].as_str().unwrap_or("");
            (said.contains(reason) && r["outputs"][0]["showing"] == "\"good\"")
                .then_some(())
                .ok_or(format!("{r}"))
        });
        assert!(
            read_rgb(&out.join("left.png")) == rgb(&good),
            "the good picture"
        );
    }
    terminate(node);
}

#[tokio::test]
async fn nodes_report_and_are_listed_within_their_limits() {
    use axum::http::StatusCode;
    use common::server::{call, get, json, state, write};
    let s = state(None, None);
    let report = |channels: usize| {
        let outputs: Vec<_> = (0..channels)
            .map(|i| serde_json::json!({"channel": "left", "showing": format!("\"{i}\""), "frames": 3}))
            .collect();
        serde_json::json!({"outputs": outputs, "fps": 60.0}).to_string()
    };
    let mut feed = s.events.subscribe();
    let (st, _, _) = call(&s, write("PUT", "/v1/nodes/wall-1", None, report(2))).await;
    assert_eq!(st, StatusCode::NO_CONTENT);
    assert!(feed.try_recv().unwrap().contains(r#""node":"wall-1""#));
    // The same pictures again, only more frames presented at another rate: nothing the feed
    // needs to hear about (a node reports every second).
    let later = report(2).replace(r#""frames":3"#, r#""frames":90"#);
    assert!(later.contains("90"));
    call(&s, write("PUT", "/v1/nodes/wall-1", None, later)).await;
    assert!(feed.try_recv().is_err());
    let (_, _, body) = call(&s, get("/v1/nodes")).await;
    let listed = &json(&body)["nodes"][0];
    assert_eq!(
        (listed["id"].as_str(), listed["fps"].as_f64()),
        (Some("wall-1"), Some(60.0))
    );
    assert_eq!(listed["outputs"][1]["showing"], "\"1\"");

    // Refused by name: a bad id, too many outputs, a negative rate, an unknown field.
    for (uri, body, field) in [
        ("/v1/nodes/a%20b", report(1), "id"),
        ("/v1/nodes/n", report(17), "/outputs"),
        (
            "/v1/nodes/n",
            r#"{"outputs": [], "fps": -1}"#.to_string(),
            "/fps",
        ),
        (
            "/v1/nodes/n",
            r#"{"outputs": [], "colour": 1}"#.to_string(),
            "",
        ),
    ] {
        let (st, _, b) = call(&s, write("PUT", uri, None, body)).await;
        assert_eq!(st, StatusCode::BAD_REQUEST, "{uri}");
        assert!(
            json(&b)["field"].as_str().unwrap_or("").starts_with(field),
            "{b:?}"
        );
    }

    // 64 nodes heard from lately fill the list; the 65th is told so.
    for i in 1..64 {
        let (st, _, _) = call(
            &s,
            write("PUT", &format!("/v1/nodes/n{i}"), None, report(1)),
        )
        .await;
        assert_eq!(st, StatusCode::NO_CONTENT);
    }
    let (st, _, b) = call(&s, write("PUT", "/v1/nodes/late", None, report(1))).await;
    assert_eq!(
        (st, json(&b)["field"].as_str()),
        (StatusCode::CONFLICT, Some("id"))
    );
    let (st, _, _) = call(&s, write("DELETE", "/v1/nodes/n1", None, String::new())).await;
    assert_eq!(st, StatusCode::NO_CONTENT);
    let (st, _, _) = call(&s, write("DELETE", "/v1/nodes/n1", None, String::new())).await;
    assert_eq!(st, StatusCode::NOT_FOUND);
    let (st, _, _) = call(&s, write("PUT", "/v1/nodes/late", None, report(1))).await;
    assert_eq!(st, StatusCode::NO_CONTENT);
}

#[tokio::test]
async fn a_feed_that_falls_behind_is_told_so() {
    use http_body_util::BodyExt;
    use tower::ServiceExt;
    let s = common::server::state(None, None);
    let response = omniwarp::server::router(s.clone())
        .oneshot(common::server::get("/v1/events"))
        .await
        .unwrap();
    // More changes than the feed keeps, before the subscriber reads any.
    for k in 0..400 {
        s.announce(serde_json::json!({"kind": "tiles", "channel": "left", "revision": k}));
    }
    let mut body = response.into_body();
    let mut seen = String::new();
    while !seen.contains("lagged") {
        let frame = tokio::time::timeout(Duration::from_secs(5), body.frame())
            .await
            .expect("the feed went quiet before saying it fell behind")
            .unwrap()
            .unwrap();
        if let Ok(data) = frame.into_data() {
            seen.push_str(&String::from_utf8_lossy(&data));
        }
    }
    assert!(seen.contains(r#""kind":"lagged","missed":144"#), "{seen}");
}

/// The `black` card through a rig whose projectors have a contrast is the channel's lifted
/// black, the picture `render --rig` puts out for a black frame (docs/photometry.md).
#[test]
fn the_black_card_is_the_lifted_black_a_black_frame_renders_to() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let mut doc: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(rig_path("cylinder-270-3proj.json")).unwrap(),
    )
    .unwrap();
    for ch in doc["channels"].as_array_mut().unwrap() {
        ch["contrast"] = 2000.into();
    }
    let rig = d.join("rig.json");
    std::fs::write(&rig, doc.to_string()).unwrap();
    let black = d.join("black.png");
    image::RgbImage::new(64, 32).save(&black).unwrap();
    let reference = d.join("reference.png");
    run(omniwarp()
        .args(["render", "--rig"])
        .arg(&rig)
        .args([
            "--channel",
            "left",
            "--content-format",
            "equirect",
            "--content",
        ])
        .arg(&black)
        .arg("--out")
        .arg(&reference));
    let cards = d.join("cards");
    run(omniwarp()
        .args(["play", "--rig"])
        .arg(&rig)
        .args(["--show", "black", "--headless", "--output", "left", "--out"])
        .arg(&cards));
    let (want, got) = (read_rgb(&reference), read_rgb(&cards.join("left.png")));
    let lifted = want.iter().filter(|v| **v > 0).count();
    assert!(
        lifted > want.len() / 4,
        "{lifted} of {} values lifted",
        want.len()
    );
    assert!(
        want == got,
        "the black card is not the rendered black frame"
    );
}
