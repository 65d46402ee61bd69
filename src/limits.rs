//! Every size, count and iteration a client or a file can set, in one place. A value past its
//! limit is refused with an error naming the field, the value and the limit, before any work or
//! allocation it would cause. docs/limits.md and `api/openapi.yaml` list the same numbers; a
//! test reads them from here.

use crate::error::{Error, Result};

/// Projector pixels each way (a channel's `resolution`).
pub const CHANNEL_SIDE: u32 = 16384;
/// Channels in one rig.
pub const CHANNELS: usize = 64;
/// Bytes a channel's warp holds per projector pixel while it is computed and cached: the warp
/// map and the wall points as f32 RGBA (16 + 16), the wall points in f64 (32), the blend
/// weight (4), the effective map of an edited screen (16) and its f (4); rounded up.
pub const WARP_BYTES_PER_PIXEL: u64 = 96;
/// The daemon's default budget for the warps of all channels at once (`--memory-budget`).
pub const MEMORY_BUDGET: u64 = 2 << 30;
/// Knots of a splined lens model each way, and in all.
pub const SPLINE_KNOTS_SIDE: u32 = 200;
/// Knots of a splined lens model in all (columns × rows).
pub const SPLINE_KNOTS: u64 = 10_000;
/// The finest grid a rig's plan samples the wall on, degrees (`step`; 0.25° is about a
/// million samples), and the coarsest.
pub const PLAN_STEP: [f64; 2] = [0.25, 5.0];
/// Width of a plan's picture in pixels, at least and at most (`width`, `--picture-width`).
pub const PLAN_PICTURE_WIDTH: [usize; 2] = [320, 4096];
/// Features of a tile grid each way, and in all; triangles of a triangle soup.
pub const TILE_SIDE: usize = 1025;
/// Features of a tile grid in all (columns × rows).
pub const TILE_FEATURES: usize = 16_641;
/// Triangles of a tile screen's triangle soup.
pub const TILE_TRIANGLES: usize = 32_768;
/// Edits in one PATCH.
pub const EDITS_PER_PATCH: usize = 1000;
/// Iterations of one `smooth` edit.
pub const SMOOTH_ITERATIONS: usize = 1000;
/// The work one PATCH of a tile screen may do, in feature visits (about a microsecond each on
/// one core, see `Edit::work`): about two seconds. The first edit always runs, since the grid
/// limits bound it alone.
pub const EDIT_WORK: u64 = 2_000_000;
/// Point correspondences in one calibration.
pub const CALIBRATION_POINTS: usize = 20_000;
/// How far from the origin a world point may be, metres (rigs and calibration points).
pub const WORLD_EXTENT: f64 = 1e5;
/// Calibration proposals the daemon keeps; the oldest go first.
pub const PROPOSALS: usize = 64;
/// Nodes of an exported grid (PFM, Bourke mesh, MPCDI region).
pub const EXPORT_NODES: usize = 1 << 22;
/// Bytes of one export's body.
pub const EXPORT_BYTES: usize = 256 << 20;
/// Content canvas pixels each way.
pub const CANVAS_SIDE: u32 = 65535;
/// A movie's or image sequence's frame, pixels each way: a 16K dome master.
pub const MEDIA_SIDE: u64 = 16384;
/// Frames of an image sequence (about 11 hours at 25 frames a second).
pub const SEQUENCE_FRAMES: usize = 1_000_000;
/// Outputs one run of a movie feeds (a rig's channels).
pub const MEDIA_OUTPUTS: usize = CHANNELS;
/// Render jobs the daemon lists (queued, running and finished); finished ones must be deleted
/// before more are taken.
pub const RENDER_JOBS: usize = 64;
/// Render jobs waiting for their turn behind the one running; more are answered 503.
pub const RENDER_JOBS_WAITING: usize = 4;
/// Render nodes the daemon follows at once (`PUT /v1/nodes/{id}`); one silent for 30 s gives
/// its place to a new one.
pub const NODES: usize = 64;
/// Outputs of one render node.
pub const NODE_OUTPUTS: usize = 16;
/// Bytes of a path under the daemon's media folder.
pub const MEDIA_PATH: usize = 1024;
/// The smallest field of view a projection accepts, degrees: below it a content pixel is so
/// small that pixel-sized tolerances ask for grids no export can hold.
pub const MIN_FOV_DEG: f64 = 0.01;
/// Zoom factor range of a view.
pub const ZOOM: (f64, f64) = (1e-3, 1e3);
/// Largest magnitude of a tile feature's custom value `f`, and largest `scale`: past them the
/// values overflow the f32 the renderer interpolates in (1e308 became inf, then NaN between
/// features).
pub const FEATURE_VALUE: f64 = 1e3;
/// Largest mesh screen file (and upload), bytes, and its triangles.
pub const MESH_BYTES: u64 = 64 << 20;
/// Triangles of a mesh screen (an OBJ file or upload).
pub const MESH_TRIANGLES: usize = 4_000_000;
/// Meshes the data directory keeps (uploads beyond are a 507 until one is deleted).
pub const MESHES: usize = 256;
/// Bytes all uploaded meshes together may take on disk.
pub const MESH_STORE_BYTES: u64 = 1 << 30;
/// Memory a mesh screen takes per triangle while it is read and indexed, counted in the memory
/// budget with the warps (measured: a 4,000,000-triangle fan, a 7.6 MiB OBJ, peaked at 1.13 GB).
pub const MESH_BYTES_PER_TRIANGLE: u64 = 288;
/// Largest camera capture upload (one frame, PNG or JPEG), bytes.
pub const CAPTURE_BODY: u64 = 64 << 20;
/// Camera captures the daemon holds at once over all channels, bytes (one byte per pixel).
pub const CAPTURE_BYTES: usize = 1 << 30;
/// Capture sequences (channel, view, period and code) the daemon holds at once: each costs
/// bookkeeping beyond its pixels.
pub const CAPTURE_SLOTS: usize = 64;
/// Lines or values in a lens file, a PFM or a Bourke mesh, as a reader accepts them.
pub const FILE_VALUES: u64 = 1 << 26;

/// `value` when it is at most `limit`, else an error naming `field`.
pub fn at_most<T: PartialOrd + std::fmt::Display>(field: &str, value: T, limit: T) -> Result<T> {
    if value <= limit {
        Ok(value)
    } else {
        Err(Error::invalid(
            field,
            format!("{value} is above the limit of {limit}"),
        ))
    }
}

/// `a × b`, refused (naming `field`) when it overflows or passes `limit`.
pub fn product(field: &str, a: u64, b: u64, limit: u64) -> Result<u64> {
    let p = a.checked_mul(b).ok_or_else(|| {
        Error::invalid(field, format!("{a} × {b} overflows; the limit is {limit}"))
    })?;
    if p > limit {
        return Err(Error::invalid(
            field,
            format!("{a} × {b} = {p} is above the limit of {limit}"),
        ));
    }
    Ok(p)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn products_overflow_into_errors_not_wraps() {
        assert!(product("x", 1 << 63, 2, u64::MAX).is_err());
        assert_eq!(product("x", 3, 4, 12).unwrap(), 12);
        let e = product("/grid", 5, 4, 12).unwrap_err().to_string();
        assert!(
            e.contains("/grid") && e.contains("20") && e.contains("12"),
            "{e}"
        );
        assert!(at_most("n", 5, 4).is_err());
    }
}
