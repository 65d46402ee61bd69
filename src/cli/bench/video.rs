//! `omniwarp bench video`: movies through the warp against ffmpeg, whole commands timed as a
//! producer runs them, the programs taking turns in every round (absolute times here are noisy;
//! the ratios are the figures).
//!
//! * A 3840×1920 equirect H.264 clip to a 3840×2160 cylinder, 270°×90°: warp only (omniwarp to
//!   `null:`, ffmpeg's `v360` to `-f null`), and end to end to H.264 with the same encoder and
//!   settings (libx264 `-preset ultrafast -crf 18`), with the share the codecs take: ffmpeg
//!   decoding alone, and decoding and encoding with no warp (scaled by pixel repetition), the
//!   floors under any tool's time and so bounds on the ratios.
//! * A 4096² dome master to the five channels of the example dome: one omniwarp run (one decode,
//!   five blended bilinear outputs) against five ffmpeg `remap` runs on the exported maps
//!   (nearest, no blend).
//! * Each output's PSNR against the exact render of the same decoded frame (bicubic from the
//!   frame as a still; 4×4 supersampled for the cylinder).

use anyhow::{Context, Result, bail};
use clap::Args;
use omniwarp::image_io;
use omniwarp::raster::{Raster, psnr};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::Instant;

#[derive(Args)]
pub struct VideoBenchArgs {
    /// Seconds of each clip (30 frames a second).
    #[arg(long, default_value_t = 2)]
    seconds: u32,
    /// Rounds; the median of each is reported.
    #[arg(long, default_value_t = 3)]
    rounds: usize,
    /// Where the clips and outputs go (default: a temporary directory, removed after).
    #[arg(long)]
    dir: Option<PathBuf>,
}

const DOME_RIG: &str = "calibration/rigs/dome-180-tilt15-5proj.json";
const CHANNELS: [&str; 5] = ["front", "right", "back", "left", "zenith"];
const CYLINDER: &str = "--projection cylindrical --hfov 270 --vfov 90 --size 3840x2160";
const V360: &str = "v360=input=e:output=cylindrical:h_fov=270:v_fov=90:w=3840:h=2160:interp=linear";
const X264: &str = "-c:v libx264 -preset ultrafast -crf 18";

fn words(s: &str) -> Vec<String> {
    s.split_whitespace().map(str::to_string).collect()
}

fn ffmpeg(dir: &Path, args: &str) -> Result<()> {
    let mut all = words("-hide_banner -loglevel error -nostdin -y");
    all.extend(words(args));
    run(dir, "ffmpeg", &all)
}

fn omniwarp(dir: &Path, args: &str) -> Result<()> {
    let me = std::env::current_exe()?;
    run(dir, me.to_str().context("the binary's path")?, &words(args))
}

fn run(dir: &Path, program: &str, args: &[String]) -> Result<()> {
    let out = Command::new(program)
        .current_dir(dir)
        .args(args)
        .stdin(Stdio::null())
        .output()
        .with_context(|| format!("{program} (is ffmpeg installed?)"))?;
    if !out.status.success() {
        bail!(
            "{program} {}: {}",
            args.join(" "),
            String::from_utf8_lossy(&out.stderr)
        );
    }
    Ok(())
}

/// Seconds of `f`.
fn time(f: impl FnOnce() -> Result<()>) -> Result<f64> {
    let t = Instant::now();
    f()?;
    Ok(t.elapsed().as_secs_f64())
}

/// PSNR of luma and of chroma (B′−Y′ and R′−Y′ together; BT.601 weights, as the untagged clips
/// are read) where `shown`: a warp's accuracy shows in luma, while chroma is also bounded by the
/// 4:2:0 storage both sides go through and by how the decoder upsamples it (ffmpeg's own two
/// ways to RGB differ by about 41 dB on these frames).
fn psnr_yc(
    a: &Raster<[u8; 4]>,
    b: &Raster<[u8; 4]>,
    shown: impl Fn(usize, usize) -> bool,
) -> (f64, f64) {
    let ycc = |p: [u8; 4]| {
        let [r, g, b] = [p[0], p[1], p[2]].map(f64::from);
        let y = 0.299 * r + 0.587 * g + 0.114 * b;
        [y, b - y, r - y]
    };
    let (mut luma, mut chroma, mut n) = (0.0, 0.0, 0usize);
    for y in 0..a.height {
        for x in (0..a.width).filter(|&x| shown(x, y)) {
            let (p, q) = (ycc(a.get(x, y)), ycc(b.get(x, y)));
            luma += (p[0] - q[0]).powi(2);
            chroma += ((p[1] - q[1]).powi(2) + (p[2] - q[2]).powi(2)) / 2.0;
            n += 1;
        }
    }
    let db = |e: f64| 10.0 * (255.0f64.powi(2) * n.max(1) as f64 / e.max(1e-12)).log10();
    (db(luma), db(chroma))
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// Frame 10 of a movie as RGBA.
fn frame(dir: &Path, movie: &str, out: &str) -> Result<Raster<[u8; 4]>> {
    ffmpeg(
        dir,
        &format!("-i {movie} -vf select=eq(n\\,10) -frames:v 1 -update 1 {out}"),
    )?;
    match image_io::read_image(&dir.join(out))? {
        image_io::Loaded::U8(r) => Ok(r),
        image_io::Loaded::F32(_) => bail!("{out}: expected 8-bit"),
    }
}

pub fn run_bench(a: VideoBenchArgs) -> Result<()> {
    let root = std::env::current_dir()?;
    let rig = root.join(DOME_RIG);
    if !rig.exists() {
        bail!("run from the repository: {DOME_RIG} is not here");
    }
    let tmp = tempfile::tempdir()?;
    let dir = a.dir.clone().unwrap_or_else(|| tmp.path().to_path_buf());
    std::fs::create_dir_all(&dir)?;
    let d = dir.as_path();
    let rig = rig.to_str().context("the rig's path")?.to_string();
    let t = a.seconds;
    eprintln!("making the clips ({t} s each) …");
    ffmpeg(
        d,
        &format!(
            "-f lavfi -i testsrc2=size=3840x1920:rate=30 -t {t} -pix_fmt yuv420p {X264} eq.mp4"
        ),
    )?;
    omniwarp(
        d,
        "render --content eq.mp4 --content-format equirect --projection domemaster --tilt 15 \
         --size 4096x4096 --preset ultrafast --out dm.mp4",
    )?;
    for ch in CHANNELS {
        omniwarp(
            d,
            &format!(
                "export --rig {rig} --channel {ch} --format remap --projection domemaster --tilt 15 \
                 --content-size 4096x4096 --out x-{ch}.pgm --ymap y-{ch}.pgm"
            ),
        )?;
    }
    let ours_null =
        format!("render --content eq.mp4 --content-format equirect {CYLINDER} --out null:");
    let ours_e2e = format!(
        "render --content eq.mp4 --content-format equirect {CYLINDER} --preset ultrafast --out ours.mp4"
    );
    let ff_null = format!("-i eq.mp4 -vf {V360} -f null -");
    let ff_e2e = format!("-i eq.mp4 -vf {V360} {X264} ff.mp4");
    let ff_decode = "-i eq.mp4 -f null -".to_string();
    // What any tool pays that decodes this clip and encodes a 3840×2160 movie with these
    // settings: ffmpeg scaling by pixel repetition, the cheapest way to the output's size.
    let ff_codecs = format!("-i eq.mp4 -vf scale=3840:2160:flags=neighbor {X264} floor.mp4");
    let ours_dome = format!(
        "render --rig {rig} --content dm.mp4 --content-format domemaster --content-tilt 15 \
         --preset ultrafast --out-dir dome"
    );
    let mut rows: Vec<(&str, Vec<f64>)> = [
        "omniwarp warp only",
        "ffmpeg v360 warp only",
        "omniwarp end to end",
        "ffmpeg v360 end to end",
        "ffmpeg decode only",
        "ffmpeg decode + encode",
        "omniwarp dome, 5 outputs",
        "ffmpeg remap, 5 runs",
    ]
    .into_iter()
    .map(|n| (n, Vec::new()))
    .collect();
    for round in 0..a.rounds {
        eprintln!("round {} of {} …", round + 1, a.rounds);
        rows[0].1.push(time(|| omniwarp(d, &ours_null))?);
        rows[1].1.push(time(|| ffmpeg(d, &ff_null))?);
        rows[2].1.push(time(|| omniwarp(d, &ours_e2e))?);
        rows[3].1.push(time(|| ffmpeg(d, &ff_e2e))?);
        rows[4].1.push(time(|| ffmpeg(d, &ff_decode))?);
        rows[5].1.push(time(|| ffmpeg(d, &ff_codecs))?);
        rows[6].1.push(time(|| omniwarp(d, &ours_dome))?);
        rows[7].1.push(time(|| {
            for ch in CHANNELS {
                ffmpeg(
                    d,
                    &format!(
                        "-i dm.mp4 -i x-{ch}.pgm -i y-{ch}.pgm -lavfi remap {X264} remap-{ch}.mp4"
                    ),
                )?;
            }
            Ok(())
        })?);
    }
    let m: Vec<f64> = rows.iter().map(|(_, v)| median(v.clone())).collect();
    let frames = f64::from(30 * t);
    println!("{} frames a clip; medians of {} rounds", frames, a.rounds);
    for ((name, _), s) in rows.iter().zip(&m) {
        println!("  {name:<26} {s:6.2} s  {:6.1} fps", frames / s);
    }
    println!("ratios (ffmpeg ÷ omniwarp):");
    println!("  warp only, 4K cylinder:    {:.2}×", m[1] / m[0]);
    println!("  end to end, same x264:     {:.2}×", m[3] / m[2]);
    println!(
        "  dome, 5 outputs vs 5 runs: {:.2}× (5 outputs in the time of {:.1} ffmpeg runs)",
        m[7] / m[6],
        5.0 * m[6] / m[7]
    );
    // The codecs' share: decoding alone, and decoding with encoding, which no tool doing this
    // job can go below; the ratio a warp costing nothing would reach.
    println!(
        "codec share of omniwarp's time: warp only, decode ≈ {:.0} %; end to end, decode and \
         encode ≈ {:.0} %",
        100.0 * m[4] / m[0],
        100.0 * m[5] / m[2]
    );
    println!(
        "bounds with a warp that cost nothing: warp only {:.2}×, end to end {:.2}×",
        m[1] / m[4],
        m[3] / m[5]
    );

    // Accuracy: frame 10 of each output against the exact render of frame 10.
    ffmpeg(
        d,
        "-i eq.mp4 -vf select=eq(n\\,10) -frames:v 1 -update 1 eq10.png",
    )?;
    omniwarp(
        d,
        &format!(
            "render --content eq10.png --content-format equirect {CYLINDER} --filter bicubic \
             --supersample 4 --out exact.png"
        ),
    )?;
    let exact = match image_io::read_image(&d.join("exact.png"))? {
        image_io::Loaded::U8(r) => r,
        image_io::Loaded::F32(_) => bail!("exact.png"),
    };
    let all = |_: usize, _: usize| true;
    let ours = frame(d, "ours.mp4", "ours10.png")?;
    let theirs = frame(d, "ff.mp4", "ff10.png")?;
    let (oy, oc) = psnr_yc(&ours, &exact, all);
    let (ty, tc) = psnr_yc(&theirs, &exact, all);
    println!(
        "PSNR against the exact render, frame 10 (both through x264): omniwarp {:.1} dB (luma \
         {oy:.1}, chroma {oc:.1}), v360 {:.1} dB (luma {ty:.1}, chroma {tc:.1})",
        psnr(&ours, &exact, 255.0, all),
        psnr(&theirs, &exact, 255.0, all)
    );
    // The dome without its blend (ffmpeg's remap has none): each channel's warp map as a normal
    // map, so that the exact render is unblended too (one sample a pixel: a normal map holds no
    // more).
    ffmpeg(
        d,
        "-i dm.mp4 -vf select=eq(n\\,10) -frames:v 1 -update 1 dm10.png",
    )?;
    for ch in ["front", "zenith"] {
        omniwarp(
            d,
            &format!("warp --rig {rig} --channel {ch} --out w-{ch}.exr"),
        )?;
        let through =
            format!("--normal-map w-{ch}.exr --content-format domemaster --content-tilt 15");
        omniwarp(
            d,
            &format!("render {through} --content dm10.png --filter bicubic --out exact-{ch}.png"),
        )?;
        omniwarp(
            d,
            &format!("render {through} --content dm.mp4 --preset ultrafast --out ours-{ch}.mp4"),
        )?;
        let exact = match image_io::read_image(&d.join(format!("exact-{ch}.png")))? {
            image_io::Loaded::U8(r) => r,
            image_io::Loaded::F32(_) => bail!("exact-{ch}.png"),
        };
        let shown = |x: usize, y: usize| exact.get(x, y)[3] == 255;
        let ours = frame(d, &format!("ours-{ch}.mp4"), &format!("ours-{ch}10.png"))?;
        let theirs = frame(d, &format!("remap-{ch}.mp4"), &format!("remap-{ch}10.png"))?;
        let (oy, oc) = psnr_yc(&ours, &exact, shown);
        let (ty, tc) = psnr_yc(&theirs, &exact, shown);
        println!(
            "PSNR against the exact render, dome {ch}, frame 10: omniwarp (bilinear) {:.1} dB \
             (luma {oy:.1}, chroma {oc:.1}), remap (nearest) {:.1} dB (luma {ty:.1}, chroma \
             {tc:.1})",
            psnr(&ours, &exact, 255.0, shown),
            psnr(&theirs, &exact, 255.0, shown)
        );
    }
    Ok(())
}
