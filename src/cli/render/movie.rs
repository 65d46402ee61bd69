//! `omniwarp render` with a movie or an image sequence on either side: the content decoded
//! once, warped to every output (one per rig channel with `--out-dir`), encoded by ffmpeg or
//! written as a sequence; progress on a terminal; Ctrl-C leaves nothing behind.

use crate::cli::args::{ContentArgs, flag_error};
use crate::cli::io::layout;
use anyhow::{Context, Result, bail};
use clap::{Args, ValueEnum};
use omniwarp::content::Content;
use omniwarp::image_io;
use omniwarp::media::{self, Encoding, Input, OutputSpec, Progress, Rate, Sample, Target};
use omniwarp::normalmap::NormalMap;
use omniwarp::projection::{Orientation, View};
use omniwarp::raster::Raster;
use omniwarp::render::{Filter, Plan, Warp};
use std::io::IsTerminal;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

#[derive(Args)]
pub struct MovieArgs {
    /// Movies: the ffmpeg encoder (libx264, libx265, prores_ks, hap, ffv1, …; default libx264,
    /// prores_ks for .mov, ffv1 for .nut).
    #[arg(long)]
    encoder: Option<String>,
    /// Movies: the constant rate factor of libx264/libx265 (default 18).
    #[arg(long)]
    crf: Option<u32>,
    /// Movies: the encoder preset (libx264/libx265: ultrafast … veryslow).
    #[arg(long)]
    preset: Option<String>,
    /// Movies: the stored pixel format (default: yuv420p; yuv422p10le for ProRes, bgr0 for
    /// FFV1, rgba for HAP).
    #[arg(long)]
    pix_fmt: Option<String>,
    /// Movies: a further encoder option NAME=VALUE, passed as -NAME VALUE (repeatable).
    #[arg(long, value_parser = option)]
    encoder_option: Vec<(String, String)>,
    /// Image sequences out: EXR frames as half floats.
    #[arg(long)]
    exr_half: bool,
    /// Image sequences in: frames a second (e.g. 25, 30000/1001; default 30).
    #[arg(long, value_parser = rate)]
    frame_rate: Option<Rate>,
    /// With a rig: bake the blend into the frames (default), write it beside each output as
    /// `<name>-blend.png` instead, or leave it out.
    #[arg(long, value_enum, default_value = "baked")]
    blend: BlendArg,
}

#[derive(Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum BlendArg {
    Baked,
    Separate,
    None,
}

fn option(s: &str) -> Result<(String, String), String> {
    s.split_once('=')
        .map(|(k, v)| (k.to_string(), v.to_string()))
        .ok_or_else(|| format!("`{s}` is not NAME=VALUE"))
}

fn rate(s: &str) -> Result<Rate, String> {
    Rate::parse(s).ok_or_else(|| format!("`{s}` is not a frame rate (25, 29.97, 30000/1001)"))
}

/// How one output's directions are found.
pub enum Source {
    /// A projection of the given size.
    View(View, (u32, u32)),
    /// A warp map (a normal map, a rig channel's warp) at its own size.
    Map(NormalMap),
}

/// One output of a movie render.
pub struct Output {
    /// Where its frames go: a movie or a sequence pattern.
    pub path: PathBuf,
    pub source: Source,
    /// The blend's gains in signal space (a rig channel).
    pub gains: Option<Vec<f32>>,
}

/// What the render command hands over.
pub struct Job<'a> {
    pub content: &'a ContentArgs,
    pub outputs: Vec<Output>,
    pub movie: &'a MovieArgs,
    pub supersample: u32,
    pub filter: Filter,
}

/// Whether a path names a movie or a sequence.
pub fn is_media(path: &Path) -> bool {
    media::is_media(path)
}

pub fn run(mut job: Job) -> Result<()> {
    let path = job.content.content.as_ref().context("--content: needed")?;
    if !is_media(path) {
        bail!(
            "--content: a movie ({}) or an image sequence (frame-%05d.png) when the output is one",
            media::MOVIE_EXTENSIONS.join(", ")
        );
    }
    let input = Input::open(path, job.movie.frame_rate).map_err(|e| match e {
        omniwarp::Error::Invalid { name, reason } if name == "frame-rate" => {
            anyhow::anyhow!("--frame-rate: {reason}")
        }
        omniwarp::Error::Invalid { reason, .. } => anyhow::anyhow!("--content: {reason}"),
        other => anyhow::Error::from(other).context("--content"),
    })?;
    let encoding = Encoding {
        encoder: job.movie.encoder.clone(),
        crf: job.movie.crf,
        preset: job.movie.preset.clone(),
        pix_fmt: job.movie.pix_fmt.clone(),
        options: job.movie.encoder_option.clone(),
        half: job.movie.exr_half,
    };
    encoding.check().map_err(flag_error)?;
    let mut outputs = std::mem::take(&mut job.outputs);
    for o in &mut outputs {
        if o.path == *path {
            bail!("--out: {} is the content itself", o.path.display());
        }
        if !is_media(&o.path) {
            bail!(
                "--out: {} is not a movie ({}) or a sequence pattern (out-%05d.png)",
                o.path.display(),
                media::MOVIE_EXTENSIONS.join(", ")
            );
        }
        if job.movie.blend != BlendArg::Baked {
            let gains = o.gains.take();
            if let (BlendArg::Separate, Some(g)) = (job.movie.blend, gains) {
                write_blend(&o.path, &o.source, &g)?;
            }
        }
    }
    let float = input.deep()
        || outputs.iter().any(|o| {
            o.path
                .extension()
                .is_some_and(|e| e.eq_ignore_ascii_case("exr"))
        });
    let stop = Arc::new(AtomicBool::new(false));
    // Ctrl-C ends the run between frames: outputs removed, children stopped.
    // A second one ends the process at once (exit 130), should a stage hang.
    for signal in [signal_hook::consts::SIGINT, signal_hook::consts::SIGTERM] {
        signal_hook::flag::register_conditional_shutdown(signal, 130, stop.clone())
            .and_then(|_| signal_hook::flag::register(signal, stop.clone()))
            .context("installing a signal handler")?;
    }
    let spec = |o: &Output| OutputSpec {
        path: o.path.clone(),
        encoding: encoding.clone(),
    };
    let specs: Vec<OutputSpec> = outputs.iter().map(spec).collect();
    let count = outputs.len();
    let terminal = std::io::stderr().is_terminal();
    let summary = if float {
        go::<[f32; 4]>(&job, &input, outputs, specs, &stop, terminal)
    } else {
        go::<[u8; 4]>(&job, &input, outputs, specs, &stop, terminal)
    };
    if terminal {
        eprintln!();
    }
    match summary {
        Ok(s) => {
            eprintln!(
                "{} frames to {} output(s) in {:.1} s ({:.1} fps): decode wait {:.1} s, fill {:.1} s, \
                 warp {:.1} s, pack {:.1} s, encode wait {:.1} s",
                s.frames,
                count,
                s.seconds,
                s.frames as f64 / s.seconds.max(1e-9),
                s.waiting_for_decode,
                s.fill,
                s.warp,
                s.pack,
                s.waiting_for_encode
            );
            Ok(())
        }
        Err(omniwarp::Error::Cancelled) if stop.load(Ordering::Relaxed) => {
            bail!("stopped: no output was written")
        }
        // The content flags' own errors, already naming their flag.
        Err(omniwarp::Error::Invalid { name, reason }) if name == LAYOUT => bail!("{reason}"),
        Err(e @ omniwarp::Error::Invalid { .. }) => Err(flag_error(e)),
        Err(e) => Err(e.into()),
    }
}

/// The name a content-layout error travels under through the library's frame loop.
const LAYOUT: &str = "content layout";

fn go<T: Sample>(
    job: &Job,
    input: &Input,
    outputs: Vec<Output>,
    specs: Vec<OutputSpec>,
    stop: &AtomicBool,
    terminal: bool,
) -> omniwarp::Result<media::Summary> {
    let a = job.content;
    let setup = |first: &Raster<T>| -> omniwarp::Result<(Content<T>, Vec<Target>)> {
        let orient = Orientation::yaw_pitch_roll(
            a.content_rotate.x,
            a.content_rotate.y,
            a.content_rotate.z,
        )?;
        let content = layout(a, first)
            .and_then(|c| a.content_lookup.apply(c.with_orientation(orient)))
            .map_err(|e| omniwarp::Error::invalid(LAYOUT, format!("{e:#}")))?;
        let mut targets = Vec::new();
        for (o, out) in outputs.into_iter().zip(specs) {
            let (warp, size) = match &o.source {
                Source::View(v, s) => (Warp::View(v), *s),
                Source::Map(m) => (Warp::Map(m), (m.width() as u32, m.height() as u32)),
            };
            let plan = Plan::new(
                warp,
                &content,
                content.atlas(),
                size.0,
                size.1,
                job.supersample,
                job.filter,
            )?;
            targets.push(Target {
                plan,
                size,
                gains: o.gains,
                saturation: None,
                out,
            });
        }
        Ok((content, targets))
    };
    let mut last = std::time::Instant::now();
    let progress = |p: Progress| {
        if !terminal || (last.elapsed().as_millis() < 200 && Some(p.frame) != p.frames) {
            return;
        }
        last = std::time::Instant::now();
        let fps = p.frame as f64 / p.elapsed.as_secs_f64().max(1e-9);
        match p.frames {
            Some(n) => eprint!(
                "\rframe {}/{n}  {fps:.1} fps  ETA {:.0} s   ",
                p.frame,
                n.saturating_sub(p.frame) as f64 / fps.max(1e-9)
            ),
            None => eprint!("\rframe {}  {fps:.1} fps   ", p.frame),
        }
    };
    media::transcode(input, setup, progress, stop)
}

/// The blend mask beside an output, as `<name>-blend.png`: gains in signal space, grey.
fn write_blend(path: &Path, source: &Source, gains: &[f32]) -> Result<()> {
    let Source::Map(m) = source else {
        return Ok(());
    };
    let stem = path
        .file_name()
        .and_then(|n| n.to_str())
        .unwrap_or("out")
        .split(['.', '%'])
        .next()
        .unwrap_or("out")
        .trim_end_matches('-')
        .to_string();
    let mask = omniwarp::rig::gains_image(m.width(), m.height(), gains);
    let out = path.with_file_name(format!("{stem}-blend.png"));
    if let Some(dir) = out.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).with_context(|| format!("--out: {}", dir.display()))?;
    }
    image_io::write_png(&out, &mask).context("--blend")
}
