//! The wgpu renderer (on Mesa's lavapipe where there is no GPU) against the CPU reference: warp and
//! cube-map passes, scenes, piecewise perspective projection, and the daemon's scene previews.

#[path = "../common/mod.rs"]
mod common;

mod gpu;
mod gpu_scene;
mod ppp;
mod ppp_channels;
