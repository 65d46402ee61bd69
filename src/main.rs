//! The `omniwarp` command: a thin layer over the library.

mod bench;
mod calibrate_cmd;
mod cli;
mod lens_cmd;
mod rig_cmd;
mod scene_cmd;
mod serve_bench;
mod serve_cmd;
mod tiles_cmd;

use clap::Parser;

fn main() {
    let args = cli::Cli::parse();
    if let Err(e) = cli::run(args) {
        eprintln!("omniwarp: error: {e:#}");
        std::process::exit(1);
    }
}
