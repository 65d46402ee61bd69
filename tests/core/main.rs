//! The library's behaviour, without the daemon or the GPU: projections, resampling, lenses, walls
//! and rigs, tile screens, calibration, exports and their readers, structured light. Tests by part
//! of the data flow, one module each (tests/README.md).

#[path = "../common/mod.rs"]
mod common;

mod calibration;
mod canvas;
mod exactness;
mod export;
mod failure_map;
mod fisheye;
mod fuzz;
mod interop;
mod lens;
mod normal_map;
mod peer_ffmpeg;
mod plan;
mod projections;
mod projective;
mod rig;
mod structured;
mod tiles;
