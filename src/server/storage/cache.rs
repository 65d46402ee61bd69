//! What the daemon keeps computed between requests: per channel the geometric warp and blend
//! weights and the warp as shown (each keyed by a hash of its inputs, see `jobs::keys`), and
//! the GPU handle previews use. Plain data: the functions that fill it live in `jobs`.

use crate::normalmap::NormalMap;
use crate::rig::ChannelWarp;
use std::sync::Arc;

/// What depends on the rig alone: the geometric warp, the blend weights and, when the rig's
/// projectors have a contrast, the black lift (tile edits change which content a pixel shows,
/// not where its light lands).
pub struct Geometry {
    pub warp: ChannelWarp,
    pub weights: Vec<f32>,
    pub lift: Option<Vec<f32>>,
}

/// A channel's warp as it is shown: the geometry, the effective sampling map (the tile
/// screen's where one is set) and the tiles' f per pixel.
pub struct Computed {
    pub geometry: Arc<Geometry>,
    pub map: NormalMap,
    pub f: Option<Vec<f32>>,
    /// The tile screen `map` and `f` were drawn from as they are (none where there is no
    /// screen, or a panorama centre moved its directions): a later edit of it redraws only
    /// the rows it changed, into copies of these.
    pub drawn_from: Option<crate::tiles::TileScreen>,
    /// The rows of `map` drawn again from the channel's previous warp after a tile edit
    /// (`None`: drawn whole, or no tile screen).
    pub redrawn: Option<std::ops::Range<usize>>,
    /// The map as an EXR file, encoded once: what `warp.exr` serves and `keep` writes, so
    /// both are the same bytes and a request after the first needs no worker.
    pub exr: std::sync::OnceLock<Vec<u8>>,
}

impl Computed {
    /// The map's EXR bytes, stamped with the revisions of the first caller.
    pub fn exr(&self, rig_revision: u64, tiles_revision: u64) -> crate::Result<&[u8]> {
        if let Some(b) = self.exr.get() {
            return Ok(b);
        }
        let mut attrs = self.map.attributes.clone();
        attrs.push(("omniwarp.rig_revision".into(), rig_revision.to_string()));
        attrs.push(("omniwarp.tiles_revision".into(), tiles_revision.to_string()));
        let bytes = crate::image_io::exr_bytes(
            self.map.pixels(),
            &attrs,
            crate::image_io::Precision::Float,
        )?;
        Ok(self.exr.get_or_init(|| bytes))
    }
}

/// The daemon's GPU, if the machine has an adapter: created on first use.
pub struct GpuWarp {
    pub gpu: crate::gpu::Gpu,
    pub pass: crate::gpu::warp::WarpPass,
}

impl GpuWarp {
    /// The machine's GPU with the warp pass built, or `None` (logged) where there is none.
    pub fn open() -> Option<Arc<GpuWarp>> {
        match crate::gpu::Gpu::new(None) {
            Ok(Some(gpu)) => {
                tracing::info!(adapter = %gpu.describe(), "GPU renderer ready");
                let pass = crate::gpu::warp::WarpPass::new(&gpu);
                Some(Arc::new(GpuWarp { gpu, pass }))
            }
            Ok(None) => {
                tracing::warn!("no GPU adapter: previews render on the CPU");
                None
            }
            Err(e) => {
                tracing::warn!(error = %e, "GPU unusable: previews render on the CPU");
                None
            }
        }
    }
}
