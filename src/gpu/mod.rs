//! The GPU renderer (wgpu): a headless device, the cube-map pass that draws 3D scenes into a
//! dynamic cube map (seed 000), the warp pass that samples it through the analytic δP or a float
//! normal map, and readback. Runs on a real GPU where there is one and on Mesa's lavapipe or
//! llvmpipe (the CPU) where there is none; with no adapter at all, callers fall back to the CPU
//! renderer, which stays the accuracy reference.
//!
//! One file per pass — [`cube`] (scenes into the cube map), [`warp`] (the cube map through the
//! warp), [`ppp`] (scenes straight into a non-planar view, piece by piece), [`blur`] (the
//! radial blur) — with what full-screen passes share in `pass.rs` and the
//! driver of a whole frame in [`frame`]. Shaders live in `shaders/` (WGSL), each naming its CPU
//! twin; `projections.wgsl` mirrors `src/projection/` formula for formula and is prepended to
//! the passes that need it.

pub mod blur;
pub mod choose;
pub mod cube;
pub mod frame;
mod pass;
pub mod ppp;
mod projected;
pub mod show;
pub mod warp;

use crate::error::{Error, Result};

// WGSL has no includes: a pass's module is its own file with the shared ones it names in its
// header ("Prepended: …") put before it.
/// The projections in WGSL, twin of `src/projection/`.
pub const PROJECTIONS_WGSL: &str = include_str!("../../shaders/projections.wgsl");
/// The warp pass (the projections are prepended at run time, see [`warp_source`]).
pub const WARP_WGSL: &str = concat!(
    include_str!("../../shaders/fullscreen.wgsl"),
    "\n",
    include_str!("../../shaders/warp.wgsl")
);
/// The cube-map scene pass and the projected panoramas.
pub const SCENE_WGSL: &str = concat!(
    include_str!("../../shaders/mesh.wgsl"),
    "\n",
    include_str!("../../shaders/scene.wgsl")
);
/// The radial blur.
pub const BLUR_WGSL: &str = concat!(
    include_str!("../../shaders/fullscreen.wgsl"),
    "\n",
    include_str!("../../shaders/blur.wgsl")
);
/// The player's pass: a picture put on an output as it is.
pub const SHOW_WGSL: &str = concat!(
    include_str!("../../shaders/fullscreen.wgsl"),
    "\n",
    include_str!("../../shaders/show.wgsl")
);
/// Piecewise perspective projection.
pub const PPP_WGSL: &str = concat!(
    include_str!("../../shaders/mesh.wgsl"),
    "\n",
    include_str!("../../shaders/ppp.wgsl")
);

/// The warp shader as compiled: the projections prepended.
pub fn warp_source() -> String {
    format!("{PROJECTIONS_WGSL}\n{WARP_WGSL}")
}

/// Every shader module as the renderers compile it, by name (for validation).
pub fn shader_modules() -> [(&'static str, String); 5] {
    [
        ("show", SHOW_WGSL.to_string()),
        ("warp", warp_source()),
        ("scene", SCENE_WGSL.to_string()),
        ("blur", BLUR_WGSL.to_string()),
        ("ppp", PPP_WGSL.to_string()),
    ]
}

/// A device and its queue, with what was chosen.
pub struct Gpu {
    /// The logical device, with downlevel default limits raised to the adapter's resolution.
    pub device: wgpu::Device,
    /// The device's command queue.
    pub queue: wgpu::Queue,
    /// The chosen adapter: name, backend and device type.
    pub info: wgpu::AdapterInfo,
    /// The adapter itself, for what a window's surface can take.
    pub adapter: wgpu::Adapter,
}

/// How the adapter list is ranked: a real GPU first (discrete, then integrated), then software;
/// Vulkan before GL at equal rank (lavapipe filters float textures, llvmpipe's GL does not).
fn rank(info: &wgpu::AdapterInfo) -> (u8, u8) {
    let device = match info.device_type {
        wgpu::DeviceType::DiscreteGpu => 0,
        wgpu::DeviceType::IntegratedGpu => 1,
        wgpu::DeviceType::VirtualGpu => 2,
        wgpu::DeviceType::Cpu => 3,
        wgpu::DeviceType::Other => 4,
    };
    let backend = match info.backend {
        wgpu::Backend::Vulkan => 0,
        wgpu::Backend::Metal | wgpu::Backend::Dx12 => 1,
        _ => 2,
    };
    (device, backend)
}

impl Gpu {
    /// The best adapter, or the first whose name or backend contains `wanted` (case-blind);
    /// `WGPU_BACKEND` limits the backends tried. `Ok(None)` when there is no adapter at all.
    pub fn new(wanted: Option<&str>) -> Result<Option<Gpu>> {
        let instance =
            wgpu::Instance::new(wgpu::InstanceDescriptor::new_without_display_handle_from_env());
        Gpu::on(&instance, wanted, None)
    }

    /// [`Gpu::new`] on `instance`, among the adapters that can present to `surface` when one
    /// is given (a window's, for the player).
    pub fn on(
        instance: &wgpu::Instance,
        wanted: Option<&str>,
        surface: Option<&wgpu::Surface>,
    ) -> Result<Option<Gpu>> {
        let backends = wgpu::Backends::from_env().unwrap_or(wgpu::Backends::all());
        let mut adapters = pollster::block_on(instance.enumerate_adapters(backends));
        if let Some(surface) = surface {
            adapters.retain(|a| a.is_surface_supported(surface));
        }
        adapters.sort_by_key(|a| rank(&a.get_info()));
        let chosen = match wanted {
            None => adapters.into_iter().next(),
            Some(w) => {
                let w = w.to_lowercase();
                let names: Vec<String> = adapters
                    .iter()
                    .map(|a| {
                        let i = a.get_info();
                        format!("{} ({:?})", i.name, i.backend)
                    })
                    .collect();
                let found = adapters.into_iter().find(|a| {
                    let i = a.get_info();
                    i.name.to_lowercase().contains(&w)
                        || format!("{:?}", i.backend).to_lowercase().contains(&w)
                });
                if found.is_none() {
                    return Err(Error::invalid(
                        "adapter",
                        format!("no adapter matches `{w}`; there are: {}", names.join(", ")),
                    ));
                }
                found
            }
        };
        let Some(adapter) = chosen else {
            return Ok(None);
        };
        let info = adapter.get_info();
        let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
            label: Some("omniwarp"),
            required_features: wgpu::Features::empty(),
            required_limits: wgpu::Limits::downlevel_defaults().using_resolution(adapter.limits()),
            ..Default::default()
        }))
        .map_err(|e| Error::invalid("adapter", format!("{}: {e}", info.name)))?;
        Ok(Some(Gpu {
            device,
            queue,
            info,
            adapter,
        }))
    }

    /// The adapter for people: its name, then its backend and device type in brackets.
    pub fn describe(&self) -> String {
        format!(
            "{} ({:?}, {:?})",
            self.info.name, self.info.backend, self.info.device_type
        )
    }

    /// Blocks until the queue is idle.
    pub fn wait(&self) -> Result<()> {
        self.device
            .poll(wgpu::PollType::wait_indefinitely())
            .map(|_| ())
            .map_err(|e| Error::invalid("gpu", e.to_string()))
    }
}

/// Which renderer a command uses.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Renderer {
    /// A GPU adapter (lavapipe counts); an error when there is none.
    Gpu,
    /// The CPU renderer, even when a GPU exists.
    Cpu,
    /// The GPU when an adapter exists, else the CPU (said once in the log).
    Auto,
}

/// Bytes per row of a texture→buffer copy: a multiple of 256 (wgpu's rule).
pub fn padded_row(width: u32, bytes_per_pixel: u32) -> u32 {
    let unpadded = width * bytes_per_pixel;
    unpadded.div_ceil(wgpu::COPY_BYTES_PER_ROW_ALIGNMENT) * wgpu::COPY_BYTES_PER_ROW_ALIGNMENT
}

/// Reads an RGBA8 texture back into a raster, dropping the row padding.
pub fn read_rgba8(
    gpu: &Gpu,
    texture: &wgpu::Texture,
    width: u32,
    height: u32,
) -> Result<crate::raster::Raster<[u8; 4]>> {
    read_rgba8_layer(gpu, texture, width, height, 0)
}

/// [`read_rgba8`] of one array layer (a cube map's face).
pub fn read_rgba8_layer(
    gpu: &Gpu,
    texture: &wgpu::Texture,
    width: u32,
    height: u32,
    layer: u32,
) -> Result<crate::raster::Raster<[u8; 4]>> {
    let row = padded_row(width, 4);
    let buffer = gpu.device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("readback"),
        size: u64::from(row) * u64::from(height),
        usage: wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::MAP_READ,
        mapped_at_creation: false,
    });
    let mut enc = gpu
        .device
        .create_command_encoder(&wgpu::CommandEncoderDescriptor { label: None });
    enc.copy_texture_to_buffer(
        wgpu::TexelCopyTextureInfo {
            texture,
            mip_level: 0,
            origin: wgpu::Origin3d {
                x: 0,
                y: 0,
                z: layer,
            },
            aspect: wgpu::TextureAspect::All,
        },
        wgpu::TexelCopyBufferInfo {
            buffer: &buffer,
            layout: wgpu::TexelCopyBufferLayout {
                offset: 0,
                bytes_per_row: Some(row),
                rows_per_image: Some(height),
            },
        },
        wgpu::Extent3d {
            width,
            height,
            depth_or_array_layers: 1,
        },
    );
    gpu.queue.submit([enc.finish()]);
    let slice = buffer.slice(..);
    let (tx, rx) = std::sync::mpsc::channel();
    slice.map_async(wgpu::MapMode::Read, move |r| {
        let _ = tx.send(r);
    });
    gpu.wait()?;
    rx.recv()
        .map_err(|e| Error::invalid("gpu", e.to_string()))?
        .map_err(|e| Error::invalid("gpu", e.to_string()))?;
    let view = slice
        .get_mapped_range()
        .map_err(|e| Error::invalid("gpu", e.to_string()))?;
    let mut data = Vec::with_capacity((width * height) as usize);
    for y in 0..height as usize {
        let line = &view[y * row as usize..y * row as usize + width as usize * 4];
        data.extend(line.chunks_exact(4).map(|p| [p[0], p[1], p[2], p[3]]));
    }
    drop(view);
    buffer.unmap();
    Ok(crate::raster::Raster {
        width: width as usize,
        height: height as usize,
        data,
    })
}
