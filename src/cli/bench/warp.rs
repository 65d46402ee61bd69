//! `omniwarp bench warp`: steady-state throughput of the CPU warp (the plan built once, then frames
//! rendered into one buffer, as a media server runs it), the machine's memory bandwidth, and
//! the bound that bandwidth puts on the warp.

use super::super::args::{FilterArg, ProjectionArgs, parse_size};
use anyhow::{Context, Result, bail};
use clap::Args;
use omniwarp::content::Content;
use omniwarp::content::pattern::Pattern;
use omniwarp::cubemap::{CubeMap, Layout};
use omniwarp::image_io::{self, Loaded};
use omniwarp::raster::{Pixel, Raster, psnr};
use omniwarp::render::{Plan, Warp, render_fn};
use rayon::prelude::*;
use std::path::PathBuf;
use std::time::Instant;

#[derive(Args)]
pub struct BenchArgs {
    #[command(flatten)]
    projection: ProjectionArgs,
    /// Output size WxH in pixels.
    #[arg(long, value_parser = parse_size, default_value = "1920x1080")]
    size: (u32, u32),
    /// Face size of the procedural cube map used as content, pixels.
    #[arg(long, default_value_t = 1024)]
    face_size: u32,
    /// Frames to time, in threes, each three after an untimed frame and followed by one copy
    /// of the bandwidth measurement (rounded up to a multiple of three).
    #[arg(long, default_value_t = 30)]
    frames: u32,
    /// Texture filter of the timed frames.
    #[arg(long, value_enum, default_value = "bilinear")]
    filter: FilterArg,
    /// Worker threads (default: all cores).
    #[arg(long)]
    threads: Option<usize>,
    /// Write the procedural cube map in ffmpeg's c6x1 layout here (the peers' input) and exit.
    #[arg(long)]
    write_content: Option<PathBuf>,
    /// Write one rendered frame here (PNG).
    #[arg(long)]
    save: Option<PathBuf>,
    /// Images (PNG, output size) to score against the exact render of the procedural content,
    /// e.g. a peer's output for the same input.
    #[arg(long, num_args = 1..)]
    psnr_of: Vec<PathBuf>,
}

pub fn run(mut a: BenchArgs) -> Result<()> {
    // Without a projection: the README's example, a 270°×90° cylinder.
    if a.projection.projection.is_none() {
        a.projection.projection = Some("cylindrical".into());
        a.projection.hfov = a.projection.hfov.or(Some(270.0));
        a.projection.vfov = a.projection.vfov.or(Some(90.0));
    }
    let threads = a.threads.unwrap_or_else(rayon::current_num_threads);
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()?;
    pool.install(|| bench(&a, threads))
}

fn to_u8(p: [f32; 4]) -> [u8; 4] {
    <[u8; 4]>::from_f32(p.map(|c| c * 255.0))
}

fn bench(a: &BenchArgs, threads: usize) -> Result<()> {
    let n = a.face_size as usize;
    let t = Instant::now();
    let cube = CubeMap::<[u8; 4]>::from_fn(n, 1, |d| to_u8(Pattern::Smooth.eval(d)));
    if let Some(path) = &a.write_content {
        image_io::write_png(path, &Layout::FfmpegC6x1.join(&cube))?;
        outln!(
            "wrote {} ({}s to make)",
            path.display(),
            t.elapsed().as_secs_f32()
        );
        return Ok(());
    }
    let (w, h) = a.size;
    let view = a.projection.view(w, h)?;
    let warp = Warp::View(&view);
    let content = Content::cube(&cube);

    let filter = super::super::args::filter(a.filter);
    // Best of three builds each: the lattice-interpolated plan the renderer uses, and the plan
    // with every position computed exactly.
    let mut plan_ms = f64::INFINITY;
    let mut exact_ms = f64::INFINITY;
    let mut plan = None;
    for _ in 0..3 {
        let t = Instant::now();
        plan = Some(Plan::new(warp, &content, content.atlas(), w, h, 1, filter)?);
        plan_ms = plan_ms.min(t.elapsed().as_secs_f64() * 1e3);
        let t = Instant::now();
        Plan::exact(warp, &content, content.atlas(), w, h, 1, filter)?;
        exact_ms = exact_ms.min(t.elapsed().as_secs_f64() * 1e3);
    }
    let plan = plan.expect("built three times");
    let mut frame = Raster::new(w as usize, h as usize);
    plan.render_into(content.atlas(), &mut frame)?;
    // The copy that measures the bandwidth takes turns with the frames, one after every three,
    // and both are read as medians: a shared machine's load then weighs on the bound as on the
    // frames it bounds (a best copy against a median frame, measured apart, had put the
    // same loop anywhere from 38 to 69 % of its bound). A copy flushes the caches, so the
    // frame after it is drawn untimed, as the warm-up frames are.
    let mut copy = Copy::new();
    let mut times = Vec::with_capacity(a.frames as usize);
    let mut copies = Vec::with_capacity(a.frames as usize / 3 + 1);
    while times.len() < a.frames.max(1) as usize {
        plan.render_into(content.atlas(), &mut frame)?;
        for _ in 0..3 {
            let t = Instant::now();
            plan.render_into(content.atlas(), &mut frame)?;
            times.push(t.elapsed().as_secs_f64());
        }
        copies.push(copy.bytes_per_second());
    }
    times.sort_by(f64::total_cmp);
    copies.sort_by(f64::total_cmp);
    let median = times[times.len() / 2];
    let mpix = f64::from(w) * f64::from(h) / 1e6;

    let bandwidth = copies[copies.len() / 2];
    // Least traffic a frame needs: the 8-byte tap read, the 4-byte pixel written (and read for
    // ownership), and every cache line of content the taps touch, read once.
    let texture = lines_touched(&plan, content.atlas().width) as f64 * 64.0;
    let bytes_per_pixel = 16.0 + texture / (f64::from(w) * f64::from(h));
    let bound = bandwidth / bytes_per_pixel / 1e6;

    outln!(
        "omniwarp CPU warp, {}, RGBA8, {threads} threads",
        format!("{filter:?}").to_lowercase()
    );
    outln!("  content          6 × {n}² cube map");
    outln!("  output           {w}×{h} {}", view.projection().name());
    outln!(
        "  plan (once)      {plan_ms:.1} ms ({:.1}x faster than every position exact: {exact_ms:.1} ms)",
        exact_ms / plan_ms
    );
    outln!(
        "  frame (median)   {:.2} ms over {} frames (min {:.2}, max {:.2})",
        median * 1e3,
        times.len(),
        times[0] * 1e3,
        times[times.len() - 1] * 1e3
    );
    outln!("  throughput       {:.0} Mpixel/s", mpix / median);
    outln!(
        "  memory copy      {:.1} GB/s (read + write; median of {}, between the frames)",
        bandwidth / 1e9,
        copies.len()
    );
    outln!(
        "  bandwidth bound  {bound:.0} Mpixel/s at {bytes_per_pixel:.1} bytes/pixel; we reach {:.0} %",
        100.0 * mpix / median / bound
    );

    let exact = || render_fn(warp, w, h, 1, |d| Pattern::Smooth.eval(d)).map(|r| r.map(to_u8));
    if a.save.is_some() || !a.psnr_of.is_empty() {
        let exact = exact()?;
        let score =
            |img: &Raster<[u8; 4]>| psnr(img, &exact, 255.0, |x, y| exact.get(x, y)[3] == 255);
        outln!("  PSNR vs exact    omniwarp {:.2} dB", score(&frame));
        for path in &a.psnr_of {
            let img = match image_io::read_image(path)
                .with_context(|| format!("--psnr-of {}", path.display()))?
            {
                Loaded::U8(r) => r,
                Loaded::F32(r) => r.map(to_u8),
            };
            if (img.width, img.height) != (frame.width, frame.height) {
                bail!(
                    "--psnr-of: {} is {}×{}, the output {w}×{h}",
                    path.display(),
                    img.width,
                    img.height
                );
            }
            outln!(
                "  PSNR vs exact    {} {:.2} dB",
                path.display(),
                score(&img)
            );
        }
    }
    if let Some(path) = &a.save {
        image_io::write_png(path, &frame)?;
    }
    Ok(())
}

/// Distinct 64-byte lines of 4-byte texels that a plan's bilinear taps read.
fn lines_touched(plan: &Plan, atlas_width: usize) -> usize {
    let line = |texel: usize| texel * 4 / 64;
    let mut seen = std::collections::HashSet::new();
    for t in plan.taps().iter().filter(|t| t.idx != u32::MAX) {
        let i = t.idx as usize;
        for texel in [i, i + 1, i + atlas_width, i + atlas_width + 1] {
            seen.insert(line(texel));
        }
    }
    seen.len()
}

/// A parallel copy of 256 MiB, to measure the memory bandwidth.
struct Copy {
    src: Vec<u64>,
    dst: Vec<u64>,
}

impl Copy {
    fn new() -> Self {
        let len = 32 << 20;
        let mut copy = Copy {
            src: vec![1; len],
            dst: vec![0; len],
        };
        copy.bytes_per_second();
        copy
    }

    /// Bytes moved (read + written) per second by one copy.
    fn bytes_per_second(&mut self) -> f64 {
        let chunk = self.src.len() / rayon::current_num_threads().max(1) / 4;
        let t = Instant::now();
        self.dst
            .par_chunks_mut(chunk)
            .zip(self.src.par_chunks(chunk))
            .for_each(|(d, s)| d.copy_from_slice(s));
        let seconds = t.elapsed().as_secs_f64();
        std::hint::black_box(&self.dst);
        2.0 * (self.src.len() * 8) as f64 / seconds
    }
}
