//! The `omniwarp` command line: one file per command, the arguments several commands share in
//! [`args`], loading and writing images in [`io`], the benchmarks under `omniwarp bench`.
//! Commands import the library and these two modules only, never each other. Every angle is in
//! degrees, every size in pixels; outputs are written atomically, so a failed run leaves no file
//! behind.

/// `println!` that hands a failed write (a closed pipe: `omniwarp … | head`) back to the caller
/// instead of panicking; [`main`] ends such a run quietly.
macro_rules! outln {
    ($($t:tt)*) => {{
        use std::io::Write as _;
        writeln!(std::io::stdout(), $($t)*)?;
    }};
}

mod args;
mod bench;
mod blend;
mod calibrate;
mod cubemap;
mod export;
mod io;
mod lens;
mod man;
mod measure;
mod normal_map;
mod pattern;
mod play;
mod projections;
mod render;
mod rig;
mod scene;
mod serve;
mod simulate;
mod tiles;
mod warp;

use clap::{CommandFactory, Parser, Subcommand};
#[cfg(feature = "bench")]
use std::path::PathBuf;

#[derive(Parser)]
#[command(
    name = "omniwarp",
    version,
    about = "Warps for non-planar projection walls: \
renders panoramic content (cube map, equirectangular, cylindrical) into any \
single-centre-of-projection view, and computes the float normal maps (warp maps) that drive it."
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

// Parsed once per run; boxing the larger variants would buy nothing.
#[allow(clippy::large_enum_variant)]
#[derive(Subcommand)]
enum Command {
    /// Run the daemon: the rig over HTTP/JSON on 127.0.0.1:7878 (see api/openapi.yaml).
    Serve(serve::ServeArgs),
    /// Render content through a projection, a normal map, a tile screen, a rig channel or a 3D
    /// scene into an image.
    Render(Box<render::RenderArgs>),
    /// Drive the projectors: each output shows its rig channel's picture, warped and blended,
    /// following the daemon live (--daemon) or from a rig file (--rig).
    Play(Box<play::PlayArgs>),
    /// Compute a projection's normal map (per pixel the unit sampling vector V) as float EXR.
    NormalMap(normal_map::NormalMapArgs),
    /// Resample content into a cube map in any layout (six files, strip, ffmpeg c3x2/c6x1).
    Cubemap(cubemap::CubemapArgs),
    /// Write a procedural test pattern as an equirectangular image or a cube map.
    Pattern(pattern::PatternArgs),
    /// List the projections, their parameters and what they mean.
    Projections,
    /// Projection tile screens: sample a projection, rasterise a screen.
    #[command(subcommand)]
    Tiles(tiles::TilesCommand),
    /// Lens models: project points and unproject pixels in batches (JSON).
    #[command(subcommand)]
    Lens(lens::LensCommand),
    /// Rig files: check one and see what each projector covers.
    #[command(subcommand)]
    Rig(rig::RigCommand),
    /// A rig channel's warp map (EXR): which content direction each projector pixel shows.
    Warp(warp::WarpArgs),
    /// Edge-blend masks for every channel of a rig (16-bit PNG, gamma-encoded).
    Blend(blend::BlendArgs),
    /// A channel's warp for media servers: ST-map EXR, PFM, Bourke mesh, ffmpeg remap maps or an
    /// MPCDI package.
    Export(export::ExportArgs),
    /// Calibrate a projector from measured pixel ↔ wall-point correspondences; writes a rig
    /// channel.
    Calibrate(calibrate::CalibrateArgs),
    /// The virtual projector–camera bench: what a camera sees while a projector shows the
    /// structured-light sequence (blur, gamma, ambient, vignetting, inter-reflection, noise),
    /// written as a capture folder for `calibrate --captures`, with the truth.
    Simulate(simulate::SimulateArgs),
    /// The wall's shape from two cameras' captures of one projector: triangulated wall points
    /// and the rig's kind of surface fitted to them (dome, cylinder or plane).
    Measure(measure::MeasureArgs),
    /// Write the procedural city as glTF (.gltf + .bin, or .glb).
    Scene(scene::SceneExportArgs),
    /// Benchmarks: time one part of omniwarp and print the figures (run on demand, not in CI).
    #[command(subcommand)]
    Bench(bench::BenchCommand),
    /// Write the manual pages (roff), one per command, generated from this command line.
    #[command(hide = true)]
    Man(man::ManArgs),
    // The benchmarks' names before they were gathered under `bench`, kept for old scripts.
    #[cfg(feature = "bench")]
    #[command(hide = true)]
    WarpBench {
        #[arg(long, default_value = bench::rig::DOME_RIG)]
        rig: PathBuf,
    },
    #[cfg(feature = "bench")]
    #[command(hide = true)]
    GpuBench(bench::gpu::GpuBenchArgs),
    #[cfg(feature = "bench")]
    #[command(hide = true)]
    ServeBench(bench::serve::ServeBenchArgs),
    #[cfg(feature = "bench")]
    #[command(hide = true)]
    CalibrateBench,
}

fn run(cli: Cli) -> anyhow::Result<()> {
    match cli.command {
        Command::Serve(a) => serve::run(a),
        Command::Man(a) => man::run(a, Cli::command()),
        Command::Render(a) => render::run(*a),
        Command::Play(a) => play::run(*a),
        Command::NormalMap(a) => normal_map::run(a),
        Command::Cubemap(a) => cubemap::run(a),
        Command::Pattern(a) => pattern::run(a),
        Command::Projections => projections::run(),
        Command::Tiles(c) => tiles::run(c),
        Command::Lens(c) => lens::run(c),
        Command::Rig(c) => rig::run(c),
        Command::Warp(a) => warp::run(a),
        Command::Blend(a) => blend::run(a),
        Command::Export(a) => export::run(a),
        Command::Calibrate(a) => calibrate::run(a),
        Command::Simulate(a) => simulate::run(a),
        Command::Measure(a) => measure::run(a),
        Command::Scene(a) => scene::export(a),
        Command::Bench(c) => bench::run(c),
        #[cfg(feature = "bench")]
        Command::WarpBench { rig } => bench::rig::run(&rig),
        #[cfg(feature = "bench")]
        Command::GpuBench(a) => bench::gpu::run(a),
        #[cfg(feature = "bench")]
        Command::ServeBench(a) => bench::serve::run(a),
        #[cfg(feature = "bench")]
        Command::CalibrateBench => bench::calibrate::run(),
    }
}

/// Exit status of a run that failed because of its arguments or input (clap's own usage errors
/// exit with the same 2).
pub const EXIT_USAGE: i32 = 2;
/// Exit status of a run whose work failed (a file that could not be written, a solve that did
/// not converge, …).
pub const EXIT_FAILED: i32 = 1;

/// Parses the command line, runs it, and exits with [`EXIT_USAGE`] or [`EXIT_FAILED`] on error.
pub fn main() {
    // Mesa's device-select Vulkan layer prints a warning on every start without a runtime
    // directory; it changes nothing about which device is picked, so it is turned off unless
    // the user set it.
    if std::env::var_os("NODEVICE_SELECT").is_none() {
        // SAFETY: set before any thread is started.
        unsafe { std::env::set_var("NODEVICE_SELECT", "1") };
    }
    let cli = Cli::parse();
    if let Err(e) = run(cli) {
        if io::is_broken_pipe(&e) {
            // `omniwarp … | head`: the reader has what it wanted.
            std::process::exit(0);
        }
        eprintln!("omniwarp: error: {e:#}");
        std::process::exit(if args::is_usage(&e) {
            EXIT_USAGE
        } else {
            EXIT_FAILED
        });
    }
}
