//! `omniwarp bench …`: the benchmarks, one file each. They time on this machine and print
//! figures (some also write them under `calibration/bench/charts/`); they assert nothing and are
//! run on demand, not in CI, because absolute timings here are noisy. `bench warp` ships with the
//! command, since it tells a user whether their machine keeps up; the rest are the developers'
//! and need the `bench` feature (`cargo run --release --features bench -- bench …`).

#[cfg(feature = "bench")]
pub mod calibrate;
#[cfg(feature = "bench")]
pub mod camera;
#[cfg(feature = "bench")]
pub mod chart;
#[cfg(feature = "bench")]
pub mod gpu;
#[cfg(feature = "bench")]
pub mod lens;
#[cfg(feature = "bench")]
pub mod methods;
#[cfg(feature = "bench")]
pub mod panorama;
#[cfg(feature = "bench")]
pub mod play;
#[cfg(feature = "bench")]
pub mod ppp;
#[cfg(feature = "bench")]
pub mod rig;
#[cfg(feature = "bench")]
pub mod serve;
#[cfg(feature = "bench")]
pub mod store;
#[cfg(feature = "bench")]
pub mod tiles;
#[cfg(feature = "bench")]
pub mod video;
pub mod warp;

use anyhow::Result;
use clap::Subcommand;
#[cfg(feature = "bench")]
use std::path::PathBuf;

// Parsed once per run; boxing the larger variant would buy nothing.
#[allow(clippy::large_enum_variant)]
#[derive(Subcommand)]
pub enum BenchCommand {
    /// The CPU warp's frame loop (plan built once) against the memory-bandwidth bound.
    Warp(warp::BenchArgs),
    /// Rig warps (3840×2160 on every surface type) and the dome example's blends.
    #[cfg(feature = "bench")]
    Rig {
        /// The rig whose blends are timed.
        #[arg(long, default_value = rig::DOME_RIG)]
        rig: PathBuf,
    },
    /// 3D scenes through the GPU renderer against cube-face size, with and without CMF, beside
    /// the CPU reference (seed 000, Figure 8).
    #[cfg(feature = "bench")]
    Gpu(gpu::GpuBenchArgs),
    /// Seed 001's frame-rate table: a cubic and a cylindrical panorama projected onto a scene,
    /// viewer mode and from another centre, 640×480 and 1024×768, beside the seed's figures.
    #[cfg(feature = "bench")]
    Panorama(panorama::PanoramaBenchArgs),
    /// Seed 003's Table 1: the 35k-triangle city at 1600×1200 through a 360° cylinder and a
    /// view deformation, image-based against piecewise perspective, beside the seed's figures.
    #[cfg(feature = "bench")]
    Ppp(ppp::PppBenchArgs),
    /// The render node: per output, the CPU frame, the upload and the pass that shows it, at
    /// 1080p and 4K; the latency from a tile edit's acknowledgement to the node showing it.
    #[cfg(feature = "bench")]
    Play(play::PlayBenchArgs),
    /// The daemon over loopback: tile edits per second and latency with many clients, and 1080p
    /// preview latency while they edit.
    #[cfg(feature = "bench")]
    Serve(serve::ServeBenchArgs),
    /// What keeping a tile edit costs: the SQLite store with its history against the file
    /// store of 0.1.0, 8 and 32 writers; revert cost; history size after 100k edits.
    #[cfg(feature = "bench")]
    Store(store::StoreBenchArgs),
    /// The virtual projector–camera bench: a projector shows the structured-light sequence, a
    /// simulated camera captures it (blur, gamma, ambient, vignetting, inter-reflection,
    /// noise); decoding and calibration measured against the truth.
    #[cfg(feature = "bench")]
    Camera(camera::CameraBenchArgs),
    /// Movies against ffmpeg: a 4K equirect clip to a 4K cylinder (warp only, and end to end
    /// with the same x264 settings) against v360, and a 4096² dome master to the five-projector
    /// dome (one decode, blended) against five `remap` runs; PSNR against the exact render.
    #[cfg(feature = "bench")]
    Video(video::VideoBenchArgs),
    /// Calibration against point count (50, 500, 5000) and lens model.
    #[cfg(feature = "bench")]
    Calibrate,
    /// Lens models: project and unproject throughput, one thread and all cores.
    #[cfg(feature = "bench")]
    Lens,
    /// Tile screens: normal-map generation for grid and output sizes.
    #[cfg(feature = "bench")]
    Tiles,
    /// Tile screens: chart of grid size against the largest reconstruction error (SVG); with
    /// --scene, every rendering method timed against its error (CSV and SVG, Pareto front).
    #[cfg(feature = "bench")]
    Chart {
        #[command(flatten)]
        tiles: chart::ChartArgs,
        #[command(flatten)]
        methods: methods::MethodChartArgs,
    },
}

pub fn run(cmd: BenchCommand) -> Result<()> {
    match cmd {
        BenchCommand::Warp(a) => warp::run(a),
        #[cfg(feature = "bench")]
        BenchCommand::Rig { rig } => rig::run(&rig),
        #[cfg(feature = "bench")]
        BenchCommand::Gpu(a) => gpu::run(a),
        #[cfg(feature = "bench")]
        BenchCommand::Panorama(a) => panorama::run(a),
        #[cfg(feature = "bench")]
        BenchCommand::Ppp(a) => ppp::run(a),
        #[cfg(feature = "bench")]
        BenchCommand::Play(a) => play::run(a),
        #[cfg(feature = "bench")]
        BenchCommand::Serve(a) => serve::run(a),
        #[cfg(feature = "bench")]
        BenchCommand::Store(a) => store::run(a),
        #[cfg(feature = "bench")]
        BenchCommand::Camera(a) => camera::run(a),
        #[cfg(feature = "bench")]
        BenchCommand::Video(a) => video::run_bench(a),
        #[cfg(feature = "bench")]
        BenchCommand::Calibrate => calibrate::run(),
        #[cfg(feature = "bench")]
        BenchCommand::Lens => lens::run(),
        #[cfg(feature = "bench")]
        BenchCommand::Tiles => tiles::run(),
        #[cfg(feature = "bench")]
        BenchCommand::Chart { tiles, methods } => match methods.scene.clone() {
            Some(spec) => methods::run(methods, &spec),
            None => chart::run(tiles),
        },
    }
}
