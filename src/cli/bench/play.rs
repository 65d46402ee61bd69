//! `omniwarp bench play`: what the render node costs on this machine. Per output and frame, the
//! picture's upload and the pass that puts it on an output (off screen, waited for), at 1080p
//! and 4K, beside the CPU frame that makes the picture; then the latency from a tile edit's
//! acknowledgement by the daemon to the node reporting the edited picture shown, with a real
//! daemon and a headless node over loopback (the daemon's render, the transfer, the decode, the
//! pass and the node's file write all inside it).

use anyhow::{Context, Result, bail};
use clap::Args;
use omniwarp::content::Content;
use omniwarp::content::pattern::Pattern;
use omniwarp::gpu::Gpu;
use omniwarp::gpu::show::{Offscreen, ShowPass};
use omniwarp::normalmap::NormalMap;
use omniwarp::projection::{self, Params, View};
use omniwarp::raster::Pixel;
use omniwarp::render::{Filter, Plan, Warp};
use omniwarp::server::client::Client;
use std::io::BufRead;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

#[derive(Args)]
pub struct PlayBenchArgs {
    /// Frames timed at each size.
    #[arg(long, default_value_t = 30)]
    frames: usize,
    /// Tile edits whose way to the node is timed.
    #[arg(long, default_value_t = 20)]
    edits: usize,
}

fn quantiles(mut v: Vec<f64>) -> (f64, f64, f64) {
    v.sort_by(f64::total_cmp);
    let at = |p: f64| v[((v.len() - 1) as f64 * p).round() as usize];
    (at(0.0), at(0.5), at(0.95))
}

pub fn run(a: PlayBenchArgs) -> Result<()> {
    if a.frames == 0 || a.edits == 0 {
        bail!("--frames, --edits: at least 1");
    }
    let gpu = Gpu::new(None)?.context("no GPU adapter: install mesa-vulkan-drivers")?;
    outln!("adapter: {}", gpu.describe());
    let mut pass = ShowPass::new(&gpu);
    let to_u8 = |p: [f32; 4]| <[u8; 4]>::from_f32(p.map(|c| c * 255.0));
    let panorama = Pattern::Checker.equirect(2048, 1024, 2, false).map(to_u8);
    let content = Content::equirect(&panorama, 360.0, 180.0)?;
    outln!(
        "per output and frame, ms (min / median / p95), {} frames:",
        a.frames
    );
    for (w, h) in [(1920u32, 1080u32), (3840, 2160)] {
        let params = Params {
            hfov: Some(90.0),
            vfov: Some(90.0 * f64::from(h) / f64::from(w)),
            ..Params::default()
        };
        let view = View::plain(projection::build(
            "cylindrical",
            &params,
            f64::from(h) / f64::from(w),
        )?);
        let map = NormalMap::from_view(&view, w, h)?;
        let plan = Plan::new(
            Warp::Map(&map),
            &content,
            content.atlas(),
            w,
            h,
            1,
            Filter::Bilinear,
        )?;
        let (mut cpu, mut upload, mut draw) = (Vec::new(), Vec::new(), Vec::new());
        let target = Offscreen::new(&gpu, (w, h));
        for _ in 0..a.frames {
            let t = Instant::now();
            let img = plan.render(content.atlas())?;
            cpu.push(t.elapsed().as_secs_f64() * 1e3);
            let t = Instant::now();
            let picture = pass.upload(&gpu, &img)?;
            gpu.wait()?;
            upload.push(t.elapsed().as_secs_f64() * 1e3);
            let t = Instant::now();
            pass.draw(&gpu, &picture, false, target.target());
            gpu.wait()?;
            draw.push(t.elapsed().as_secs_f64() * 1e3);
        }
        for (what, v) in [
            ("CPU frame (warp)", cpu),
            ("upload", upload),
            ("show pass", draw),
        ] {
            let (lo, mid, p95) = quantiles(v);
            outln!("  {w}×{h} {what:<17} {lo:7.2} {mid:7.2} {p95:7.2}");
        }
    }
    latency(a.edits)
}

/// A daemon and a node as processes, stopped when dropped.
struct Running(Vec<Child>);

impl Drop for Running {
    fn drop(&mut self) {
        for c in &mut self.0 {
            let _ = c.kill();
            let _ = c.wait();
        }
    }
}

fn latency(edits: usize) -> Result<()> {
    let me = std::env::current_exe()?;
    let dir = tempfile::tempdir()?;
    let mut daemon = Command::new(&me)
        .args(["serve", "--demo", "--bind", "127.0.0.1:0", "--data"])
        .arg(dir.path().join("data"))
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()?;
    let mut line = String::new();
    std::io::BufReader::new(daemon.stdout.take().context("daemon's output")?)
        .read_line(&mut line)?;
    let mut running = Running(vec![daemon]);
    let addr = line
        .trim()
        .strip_prefix("listening on http://")
        .with_context(|| format!("the daemon said {line:?}"))?
        .to_string();
    let node = Command::new(&me)
        .args([
            "play",
            "--daemon",
            &format!("http://{addr}"),
            "--node",
            "bench",
        ])
        .args(["--headless", "--out"])
        .arg(dir.path().join("wall"))
        .args(["--output", "centre"])
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()?;
    running.0.push(node);
    let mut c = Client::new(addr.parse()?, None);
    let shown = |c: &mut Client| -> Result<Option<String>> {
        let nodes = c.get("/v1/nodes")?.json();
        Ok(nodes["nodes"][0]["outputs"][0]["showing"]
            .as_str()
            .map(String::from))
    };
    let current = |c: &mut Client| -> Result<Option<String>> {
        Ok(c.get("/v1/channels/centre/output.png")?
            .header("etag")
            .map(String::from))
    };
    // Until the node reports a picture other than `before`.
    let changed = |c: &mut Client, before: &Option<String>| -> Result<Option<String>> {
        let until = Instant::now() + Duration::from_secs(30);
        loop {
            let now = shown(c)?;
            if now.is_some() && now != *before {
                return Ok(now);
            }
            if Instant::now() > until {
                bail!("the node showed nothing new within 30 s");
            }
            std::thread::sleep(Duration::from_millis(2));
        }
    };
    let mut before = changed(&mut c, &None)?;
    let mut took = Vec::new();
    for k in 0..edits {
        let body = serde_json::json!({"edits": [
            {"op": "set_feature", "column": 16, "row": 10, "theta": 1.0 + k as f64 * 0.1}
        ]});
        let revision = (k + 1).to_string();
        let r = c.send(
            "PATCH",
            "/v1/channels/centre/tiles",
            &[("If-Match", &format!("\"{revision}\""))],
            body.to_string().as_bytes(),
        )?;
        if r.status != 200 {
            bail!("tile edit {k}: status {}", r.status);
        }
        let acknowledged = Instant::now();
        let now = changed(&mut c, &before)?;
        took.push(acknowledged.elapsed().as_secs_f64() * 1e3);
        if now != current(&mut c)? {
            bail!("the node shows {now:?}, not the daemon's picture");
        }
        before = now;
    }
    let (lo, mid, p95) = quantiles(took);
    outln!(
        "tile edit acknowledged → the node reports it shown (1920×1080, headless, {edits} edits), \
         ms: {lo:.0} / {mid:.0} / {p95:.0} (min / median / p95)"
    );
    Ok(())
}
