//! omniwarp: warps for non-planar projection walls with a single centre of projection.
//!
//! The data flow and conventions are those of `docs/conventions.md`: projection functions δP in
//! [`projection`], cube maps in [`cubemap`], content sources in [`content`], the CPU reference
//! renderer in [`render`] and the float normal maps (warp maps) in [`normalmap`].

#![warn(missing_docs)]

pub mod calibration;
pub mod content;
pub mod cubemap;
pub mod error;
pub mod export;
#[cfg(feature = "gpu")]
pub mod gpu;
pub mod image_io;
pub mod lens;
pub mod limits;
pub mod media;
pub mod normalmap;
#[cfg(feature = "play")]
pub mod play;
pub mod projection;
pub mod raster;
pub mod render;
pub mod rig;
pub mod scene;
#[cfg(feature = "server")]
pub mod server;
pub mod structured;
pub mod surface;
pub mod tiles;

pub use error::{Error, Outside, Result};
/// The vector and matrix types of the public API (`DVec3`, `DMat3`, …), re-exported so that a
/// caller uses the same glam as the crate.
pub use glam;
