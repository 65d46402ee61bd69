//! `omniwarp bench …`: the benchmarks, one file each. They time on this machine and print
//! figures (some also write them under `calibration/charts/`); they assert nothing and are run
//! on demand, not in CI, because absolute timings here are noisy.

pub mod calibrate;
pub mod camera;
pub mod chart;
pub mod gpu;
pub mod lens;
pub mod methods;
pub mod panorama;
pub mod ppp;
pub mod rig;
pub mod serve;
pub mod store;
pub mod tiles;
pub mod warp;

use anyhow::Result;
use clap::Subcommand;
use std::path::PathBuf;

// Parsed once per run; boxing the larger variant would buy nothing.
#[allow(clippy::large_enum_variant)]
#[derive(Subcommand)]
pub enum BenchCommand {
    /// The CPU warp's frame loop (plan built once) against the memory-bandwidth bound.
    Warp(warp::BenchArgs),
    /// Rig warps (3840×2160 on every surface type) and the dome example's blends.
    Rig {
        /// The rig whose blends are timed.
        #[arg(long, default_value = rig::DOME_RIG)]
        rig: PathBuf,
    },
    /// 3D scenes through the GPU renderer against cube-face size, with and without CMF, beside
    /// the CPU reference (seed 000, Figure 8).
    Gpu(gpu::GpuBenchArgs),
    /// Seed 001's frame-rate table: a cubic and a cylindrical panorama projected onto a scene,
    /// viewer mode and from another centre, 640×480 and 1024×768, beside the seed's figures.
    Panorama(panorama::PanoramaBenchArgs),
    /// Seed 003's Table 1: the 35k-triangle city at 1600×1200 through a 360° cylinder and a
    /// view deformation, image-based against piecewise perspective, beside the seed's figures.
    Ppp(ppp::PppBenchArgs),
    /// The daemon over loopback: tile edits per second and latency with many clients, and 1080p
    /// preview latency while they edit.
    Serve(serve::ServeBenchArgs),
    /// What keeping a tile edit costs: the SQLite store with its history against the file
    /// store of 0.1.0, 8 and 32 writers; revert cost; history size after 100k edits.
    Store(store::StoreBenchArgs),
    /// The virtual projector–camera bench: a projector shows the structured-light sequence, a
    /// simulated camera captures it (blur, gamma, ambient, vignetting, inter-reflection,
    /// noise); decoding and calibration measured against the truth.
    Camera(camera::CameraBenchArgs),
    /// Calibration against point count (50, 500, 5000) and lens model.
    Calibrate,
    /// Lens models: project and unproject throughput, one thread and all cores.
    Lens,
    /// Tile screens: normal-map generation for grid and output sizes.
    Tiles,
    /// Tile screens: chart of grid size against the largest reconstruction error (SVG); with
    /// --scene, every rendering method timed against its error (CSV and SVG, Pareto front).
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
        BenchCommand::Rig { rig } => rig::run(&rig),
        BenchCommand::Gpu(a) => gpu::run(a),
        BenchCommand::Panorama(a) => panorama::run(a),
        BenchCommand::Ppp(a) => ppp::run(a),
        BenchCommand::Serve(a) => serve::run(a),
        BenchCommand::Store(a) => store::run(a),
        BenchCommand::Camera(a) => camera::run(a),
        BenchCommand::Calibrate => calibrate::run(),
        BenchCommand::Lens => lens::run(),
        BenchCommand::Tiles => tiles::run(),
        BenchCommand::Chart { tiles, methods } => match methods.scene.clone() {
            Some(spec) => methods::run(methods, &spec),
            None => chart::run(tiles),
        },
    }
}
