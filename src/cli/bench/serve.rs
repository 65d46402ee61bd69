//! `omniwarp bench serve`: the daemon under load, over real HTTP on loopback. Many clients edit
//! tile screens with `If-Match` (retrying on 412, as a console would), while one client renders
//! full-size previews of an edited channel. Reports edits per second, edit latency (first attempt
//! to acknowledgement) and render latency, with and without the edits.

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

/// Times `n` full-size previews of `channel`; milliseconds each.
fn renders(addr: SocketAddr, channel: &str, n: usize) -> Result<Vec<f64>> {
    let mut c = Client::new(addr, None);
    let mut out = Vec::new();
    for _ in 0..n {
        let t = Instant::now();
        let r = c.get(&format!("/v1/channels/{channel}/render?scale=1"))?;
        match r.status {
            200 => out.push(t.elapsed().as_secs_f64() * 1e3),
            // The workers are shared with nobody else here; a 503 would be a finding.
            s => bail!("render: status {s}"),
        }
    }
    Ok(out)
}

pub fn run(a: ServeBenchArgs) -> Result<()> {
    let dir = tempfile::tempdir()?;
    let doc = serde_json::from_str(omniwarp::rig::DEMO_RIG)?;
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
    let channels = ["left", "centre", "right"];
    outln!(
        "demo rig (3 × 1920×1080), data on {}; {} clients × {} tile edits, renders of `centre` at 1920×1080",
        dir.path().display(),
        a.clients,
        a.edits
    );

    // Warm the caches, then renders alone.
    renders(addr, "centre", 1)?;
    let mut quiet = renders(addr, "centre", a.renders)?;

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
    let _ = stop.send(());
    rt.block_on(server)??;
    Ok(())
}
