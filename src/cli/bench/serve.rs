//! `omniwarp bench serve`: the daemon under load, over real HTTP on loopback. Many clients edit
//! tile screens with `If-Match` (retrying on 412 and 503, as a console would), while one client
//! renders full-size previews of an edited channel. Reports edits per second, edit latency (first
//! attempt to acknowledgement) and render latency, with and without the edits; then the latency
//! of health and of a small edit while clients keep every worker busy and while 1,000 slow
//! connections are open; then the peak memory of the largest rig the default budget allows.

use anyhow::{Result, bail};
use clap::Args;
use omniwarp::server::client::Client;
use omniwarp::server::{AppState, Store, launch};
use std::net::SocketAddr;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

#[derive(Args)]
pub struct ServeBenchArgs {
    /// Concurrent editing clients.
    #[arg(long, default_value_t = 32)]
    clients: usize,
    /// Edits each client makes.
    #[arg(long, default_value_t = 100)]
    edits: usize,
    /// Preview renders timed (each with and without edits streaming in).
    #[arg(long, default_value_t = 12)]
    renders: usize,
}

fn percentile(v: &mut [f64], p: f64) -> f64 {
    v.sort_by(f64::total_cmp);
    if v.is_empty() {
        return f64::NAN;
    }
    v[((v.len() - 1) as f64 * p).round() as usize]
}

/// Times `n` full-size previews of `channel`, milliseconds each from the first attempt: a
/// preview refused with 503 (every worker busy, as many editing clients can keep them) is
/// retried after 20 ms, as a console would.
fn renders(addr: SocketAddr, channel: &str, n: usize) -> Result<Vec<f64>> {
    let mut c = Client::new(addr, None);
    let mut out = Vec::new();
    for _ in 0..n {
        let t = Instant::now();
        loop {
            let r = c.get(&format!("/v1/channels/{channel}/render?scale=1"))?;
            match r.status {
                200 => break,
                503 => std::thread::sleep(Duration::from_millis(20)),
                s => bail!("render: status {s}"),
            }
        }
        out.push(t.elapsed().as_secs_f64() * 1e3);
    }
    Ok(out)
}

pub fn run(a: ServeBenchArgs) -> Result<()> {
    let daemon = Daemon::start(serde_json::from_str(omniwarp::rig::DEMO_RIG)?)?;
    let (addr, dir) = (daemon.addr, daemon.dir.path());
    let channels = ["left", "centre", "right"];
    outln!(
        "demo rig (3 × 1920×1080), data on {}; {} clients × {} tile edits, renders of `centre` at 1920×1080",
        dir.display(),
        a.clients,
        a.edits
    );

    // Warm the caches, then renders alone.
    renders(addr, "centre", 1)?;
    let mut quiet = renders(addr, "centre", a.renders)?;
    after_edits(addr, a.renders)?;

    let editing = Arc::new(AtomicBool::new(true));
    let t = Instant::now();
    let writers: Vec<_> = (0..a.clients)
        .map(|k| {
            let edits = a.edits;
            std::thread::spawn(move || -> Result<(Vec<f64>, u64)> {
                let mut c = Client::new(addr, None);
                let channel = channels[k % channels.len()];
                let (column, row) = ((k / channels.len()) % 33, 1 + k / 99);
                let mut revision = c
                    .get(&format!("/v1/channels/{channel}/tiles"))?
                    .revision()
                    .unwrap_or(1);
                let (mut latencies, mut attempts) = (Vec::new(), 0u64);
                for n in 0..edits {
                    let body = serde_json::json!({"edits": [{"op": "set_feature", "column": column, "row": row, "f": 1.0 - (n % 2) as f64 * 0.5}]}).to_string();
                    let started = Instant::now();
                    loop {
                        attempts += 1;
                        let tag = format!("\"{revision}\"");
                        let r = c.send(
                            "PATCH",
                            &format!("/v1/channels/{channel}/tiles"),
                            &[("If-Match", &tag)],
                            body.as_bytes(),
                        )?;
                        match r.status {
                            200 => {
                                revision = r.revision().unwrap_or(revision + 1);
                                break;
                            }
                            412 => {
                                revision = r.json()["current_revision"].as_u64().unwrap_or(revision);
                                std::thread::sleep(Duration::from_micros((k as u64 * 37 + attempts) % 500));
                            }
                            // Every worker busy for longer than a write waits: back off.
                            503 => std::thread::sleep(Duration::from_millis(20)),
                            s => bail!("client {k}: status {s}"),
                        }
                    }
                    latencies.push(started.elapsed().as_secs_f64() * 1e3);
                }
                Ok((latencies, attempts))
            })
        })
        .collect();
    let flag = editing.clone();
    let render_thread = std::thread::spawn(move || -> Result<Vec<f64>> {
        let mut out = Vec::new();
        while flag.load(Ordering::Relaxed) {
            out.extend(renders(addr, "centre", 1)?);
        }
        Ok(out)
    });
    let mut latencies = Vec::new();
    let mut attempts = 0;
    for w in writers {
        let (l, n) = w.join().expect("writer thread")?;
        latencies.extend(l);
        attempts += n;
    }
    let took = t.elapsed().as_secs_f64();
    editing.store(false, Ordering::Relaxed);
    let mut busy = render_thread.join().expect("render thread")?;
    let n = latencies.len();
    outln!(
        "edits: {n} in {took:.1} s = {:.0} edits/s ({attempts} attempts, {:.1} per edit)",
        n as f64 / took,
        attempts as f64 / n as f64
    );
    outln!(
        "edit latency (first attempt → durable ack): p50 {:.1} ms, p99 {:.1} ms",
        percentile(&mut latencies, 0.5),
        percentile(&mut latencies, 0.99)
    );
    outln!(
        "1080p preview alone ({} renders): p50 {:.0} ms, p99 {:.0} ms",
        quiet.len(),
        percentile(&mut quiet, 0.5),
        percentile(&mut quiet, 0.99)
    );
    outln!(
        "1080p preview while edits stream ({} renders): p50 {:.0} ms, p99 {:.0} ms",
        busy.len(),
        percentile(&mut busy, 0.5),
        percentile(&mut busy, 0.99)
    );
    hostile(addr)?;
    daemon.stop()?;
    largest_rig()?;
    Ok(())
}

/// A preview after each of `n` edits moving one feature of `centre` by half a degree, on its
/// own: how long the edit's preview takes, and where its time went (the daemon's
/// Server-Timing), against the frame of a preview with nothing to redo.
fn after_edits(addr: SocketAddr, n: usize) -> Result<()> {
    let mut c = Client::new(addr, None);
    let timing = |r: &omniwarp::server::client::Reply, name: &str| -> f64 {
        // "name;desc=\"…\";dur=1.23, …"
        let entry = r
            .header("server-timing")
            .and_then(|t| t.split(", ").find(|e| e.split(';').next() == Some(name)));
        entry
            .and_then(|e| e.split(';').find_map(|p| p.strip_prefix("dur=")))
            .and_then(|d| d.parse().ok())
            .unwrap_or(0.0)
    };
    let path = "/v1/channels/centre/render?scale=1";
    let (mut total, mut warp, mut frame, mut kept_frame, mut how) = (
        Vec::new(),
        Vec::new(),
        Vec::new(),
        Vec::new(),
        String::new(),
    );
    for k in 0..n {
        let revision = c.get("/v1/channels/centre/tiles")?.revision().unwrap_or(1);
        let phi = if k % 2 == 0 { 0.5 } else { 0.0 };
        let body = serde_json::json!({"edits": [{"op": "set_feature", "column": 16, "row": 9, "phi": phi}]});
        let r = c.send(
            "PATCH",
            "/v1/channels/centre/tiles",
            &[("If-Match", &format!("\"{revision}\""))],
            body.to_string().as_bytes(),
        )?;
        if r.status != 200 {
            bail!("edit: status {}", r.status);
        }
        let t = Instant::now();
        let r = c.get(path)?;
        total.push(t.elapsed().as_secs_f64() * 1e3);
        if r.status != 200 {
            bail!("render after an edit: status {}", r.status);
        }
        warp.push(timing(&r, "warp"));
        frame.push(timing(&r, "frame"));
        how = r.header("x-omniwarp-preview").unwrap_or("?").to_string();
        // The same preview again: kept, its frame alone.
        kept_frame.push(timing(&c.get(path)?, "frame"));
    }
    // What the tile warp cost when every edit drew the whole screen: the same screen drawn
    // whole here, in this process.
    let screen: omniwarp::tiles::TileScreen =
        serde_json::from_value(c.get("/v1/channels/centre/tiles")?.json()["tiles"].take())?;
    let mut whole: Vec<f64> = (0..5)
        .map(|_| {
            let t = Instant::now();
            let fm = screen.feature_map(1920, 1080);
            std::hint::black_box((fm.normal_map(), fm.f()));
            t.elapsed().as_secs_f64() * 1e3
        })
        .collect();
    let f = percentile(&mut kept_frame, 0.5);
    let p = percentile(&mut total, 0.5);
    outln!(
        "1080p preview after a one-feature move ({n} edits): p50 {p:.0} ms = {:.1}× the frame \
         ({f:.1} ms); the tile warp p50 {:.1} ms (the whole screen drawn: {:.1} ms), the \
         frame {:.1} ms; made from {how}",
        p / f,
        percentile(&mut warp, 0.5),
        percentile(&mut whole, 0.5),
        percentile(&mut frame, 0.5),
    );
    Ok(())
}

/// The daemon on a free loopback port, in this process, with its data in a temporary directory.
struct Daemon {
    addr: SocketAddr,
    dir: tempfile::TempDir,
    rt: tokio::runtime::Runtime,
    stop: tokio::sync::oneshot::Sender<()>,
    server: tokio::task::JoinHandle<std::io::Result<()>>,
}

impl Daemon {
    fn start(doc: omniwarp::rig::RigDoc) -> Result<Daemon> {
        let dir = tempfile::tempdir()?;
        let state = AppState::new(
            Store::open(Some(dir.path().to_path_buf()), Some(doc))?,
            None,
        );
        let rt = tokio::runtime::Runtime::new()?;
        let listener = rt.block_on(tokio::net::TcpListener::bind("127.0.0.1:0"))?;
        let addr = listener.local_addr()?;
        let (stop, stopped) = tokio::sync::oneshot::channel::<()>();
        let server = rt.spawn(launch(listener, state, async {
            let _ = stopped.await;
        }));
        Ok(Daemon {
            addr,
            dir,
            rt,
            stop,
            server,
        })
    }

    fn stop(self) -> Result<()> {
        let _ = self.stop.send(());
        self.rt.block_on(self.server)??;
        Ok(())
    }
}

/// `samples` timings of `f`, milliseconds, p50 and p99.
fn timed(samples: usize, mut f: impl FnMut() -> Result<()>) -> Result<(f64, f64)> {
    let mut t = Vec::with_capacity(samples);
    for _ in 0..samples {
        let start = Instant::now();
        f()?;
        t.push(start.elapsed().as_secs_f64() * 1e3);
        std::thread::sleep(Duration::from_millis(10));
    }
    Ok((percentile(&mut t, 0.5), percentile(&mut t, 0.99)))
}

/// Health and a one-feature edit (retried on 412 and 503), timed on fresh connections.
fn probes(addr: SocketAddr, what: &str) -> Result<()> {
    let (h50, h99) = timed(50, || {
        let r = Client::new(addr, None).get("/v1/health")?;
        if r.status != 200 {
            bail!("health: status {}", r.status);
        }
        Ok(())
    })?;
    let (e50, e99) = timed(20, || {
        let mut c = Client::new(addr, None);
        loop {
            let rev = c.get("/v1/channels/left/tiles")?.revision().unwrap_or(1);
            let body = r#"{"edits": [{"op": "set_feature", "column": 3, "row": 3, "f": 0.7}]}"#;
            let tag = format!("\"{rev}\"");
            let r = c.send(
                "PATCH",
                "/v1/channels/left/tiles",
                &[("If-Match", &tag)],
                body.as_bytes(),
            )?;
            match r.status {
                200 => return Ok(()),
                412 | 503 => continue,
                s => bail!("edit: status {s}"),
            }
        }
    })?;
    outln!(
        "{what}: health p50 {h50:.1} ms, p99 {h99:.1} ms; small edit p50 {e50:.1} ms, p99 {e99:.1} ms"
    );
    Ok(())
}

/// Health and edits while the heavy routes are saturated, then with 1,000 slow connections.
fn hostile(addr: SocketAddr) -> Result<()> {
    let saturating = Arc::new(AtomicBool::new(true));
    let busy: Vec<_> = (0..6)
        .map(|k| {
            let flag = saturating.clone();
            std::thread::spawn(move || {
                let (mut served, mut refused) = (0u64, 0u64);
                let mut c = Client::new(addr, None);
                let path = format!("/v1/channels/{}/render?scale=1", ["centre", "right"][k % 2]);
                while flag.load(Ordering::Relaxed) {
                    match c.get(&path).map(|r| r.status) {
                        Ok(200) => served += 1,
                        _ => refused += 1,
                    }
                }
                (served, refused)
            })
        })
        .collect();
    std::thread::sleep(Duration::from_millis(500));
    probes(addr, "6 clients rendering 1080p previews without pause")?;
    saturating.store(false, Ordering::Relaxed);
    let (served, refused) = busy
        .into_iter()
        .map(|t| t.join().expect("render thread"))
        .fold((0, 0), |a, b| (a.0 + b.0, a.1 + b.1));
    outln!("  (their renders: {served} served, {refused} answered 503)");

    let mut slow = Vec::new();
    for i in 0..1000 {
        let mut c = std::net::TcpStream::connect(addr)?;
        std::io::Write::write_all(
            &mut c,
            format!("GET /v1/health HTTP/1.1\r\nX-Slow: {i}\r\n").as_bytes(),
        )?;
        slow.push(c);
    }
    probes(addr, "1,000 connections sending headers that never end")?;
    drop(slow);
    Ok(())
}

/// The demo rig with its three projectors at 4096×1820: as much as the default memory budget
/// admits. A daemon of its own (this binary, `serve --data`) computes every channel's warp and
/// blend; its peak resident memory is read from /proc when it is done.
fn largest_rig() -> Result<()> {
    let mut doc: omniwarp::rig::RigDoc = serde_json::from_str(omniwarp::rig::DEMO_RIG)?;
    let (w, h) = (4096u32, 1820u32);
    for c in &mut doc.channels {
        let (sx, sy) = (
            f64::from(w) / f64::from(c.resolution[0]),
            f64::from(h) / f64::from(c.resolution[1]),
        );
        let i = &mut c.lens.intrinsics;
        i[0] *= sx;
        i[1] *= sy;
        i[2] = (i[2] + 0.5) * sx - 0.5;
        i[3] = (i[3] + 0.5) * sy - 0.5;
        c.resolution = [w, h];
    }
    let rig = omniwarp::rig::Rig::from_doc(doc.clone())?;
    rig.check_budget(omniwarp::limits::MEMORY_BUDGET)?;
    let dir = tempfile::tempdir()?;
    let saved = serde_json::json!({"revision": 1, "rig": doc});
    std::fs::write(dir.path().join("rig.json"), saved.to_string())?;
    let mut child = std::process::Command::new(std::env::current_exe()?)
        .args(["serve", "--bind", "127.0.0.1:0", "--data"])
        .arg(dir.path())
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::null())
        .spawn()?;
    let mut line = String::new();
    std::io::BufRead::read_line(
        &mut std::io::BufReader::new(child.stdout.take().expect("piped")),
        &mut line,
    )?;
    let measured = (|| -> Result<(f64, u64, u64)> {
        let addr: SocketAddr = line
            .trim()
            .strip_prefix("listening on http://")
            .ok_or_else(|| anyhow::anyhow!("the daemon said `{line}`"))?
            .parse()?;
        let before = peak_rss_mib(child.id());
        let t = Instant::now();
        for ch in ["left", "centre", "right"] {
            let r = Client::new(addr, None).get(&format!("/v1/channels/{ch}/blend.png"))?;
            if r.status != 200 {
                bail!("largest rig, {ch}: status {}", r.status);
            }
        }
        Ok((t.elapsed().as_secs_f64(), before, peak_rss_mib(child.id())))
    })();
    let _ = child.kill();
    let _ = child.wait();
    let (took, before, peak) = measured?;
    outln!(
        "largest rig the default budget admits (3 × {w}×{h}, {} MiB by the estimate): warps in \
         {took:.1} s; the daemon's peak RSS {peak} MiB (at start {before} MiB)",
        rig.warp_bytes() >> 20,
    );
    Ok(())
}

/// Process `pid`'s peak resident set (VmHWM), MiB; 0 where /proc is not there.
fn peak_rss_mib(pid: u32) -> u64 {
    std::fs::read_to_string(format!("/proc/{pid}/status"))
        .ok()
        .and_then(|s| {
            s.lines()
                .find_map(|l| l.strip_prefix("VmHWM:"))
                .and_then(|v| v.trim().trim_end_matches("kB").trim().parse::<u64>().ok())
        })
        .map_or(0, |kb| kb >> 10)
}
