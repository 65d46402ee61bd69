//! The radial-blur pass (seed 000, Figure 7): `shaders/blur.wgsl` drawn full screen over the
//! warp pass's output. Its CPU twin is `src/render/blur.rs`, tap for tap.

use super::pass::{draw, entry, fullscreen, output, texture, uniform};
use super::{BLUR_WGSL, Gpu};
use crate::render::blur::Blur;
use wgpu::util::DeviceExt;

/// The GPU radial-blur pass: the pipeline, bind-group layout and clamping bilinear sampler
/// of `shaders/blur.wgsl`, built once and reused for every frame.
pub struct BlurPass {
    pipeline: wgpu::RenderPipeline,
    layout: wgpu::BindGroupLayout,
    sampler: wgpu::Sampler,
}

impl BlurPass {
    /// Builds the pipeline on `gpu`.
    pub fn new(gpu: &Gpu) -> Self {
        use wgpu::TextureViewDimension as D;
        let layout = gpu
            .device
            .create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
                label: Some("blur"),
                entries: &[
                    entry(0, uniform()),
                    entry(1, texture(D::D2, true)),
                    entry(
                        2,
                        wgpu::BindingType::Sampler(wgpu::SamplerBindingType::Filtering),
                    ),
                ],
            });
        // Edges clamp, as the CPU twin's taps do.
        let sampler = gpu.device.create_sampler(&wgpu::SamplerDescriptor {
            mag_filter: wgpu::FilterMode::Linear,
            min_filter: wgpu::FilterMode::Linear,
            ..Default::default()
        });
        BlurPass {
            pipeline: fullscreen(gpu, BLUR_WGSL, &layout),
            layout,
            sampler,
        }
    }

    /// `input` (width × height, RGBA8) blurred into a new texture of the same size.
    pub fn apply(
        &self,
        gpu: &Gpu,
        input: &wgpu::Texture,
        (width, height): (u32, u32),
        b: Blur,
    ) -> wgpu::Texture {
        let params = [
            b.strength,
            b.samples.max(1) as f32,
            width as f32,
            height as f32,
        ];
        let p_buf = gpu
            .device
            .create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: None,
                contents: bytemuck::cast_slice(&params),
                usage: wgpu::BufferUsages::UNIFORM,
            });
        let src = input.create_view(&Default::default());
        let bind = gpu.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: None,
            layout: &self.layout,
            entries: &[
                wgpu::BindGroupEntry {
                    binding: 0,
                    resource: p_buf.as_entire_binding(),
                },
                wgpu::BindGroupEntry {
                    binding: 1,
                    resource: wgpu::BindingResource::TextureView(&src),
                },
                wgpu::BindGroupEntry {
                    binding: 2,
                    resource: wgpu::BindingResource::Sampler(&self.sampler),
                },
            ],
        });
        let blurred = output(gpu, width, height);
        draw(gpu, &self.pipeline, &bind, &blurred);
        blurred
    }
}
