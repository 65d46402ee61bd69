//! The cube-map pass's panoramic projective texture mapping (seed 001): the panorama's padded
//! atlas as a texture, where to find a direction in it, and the two draws per face — the sky
//! (the panorama in the ray's own direction, where no surface is met) and the scene's
//! triangles, each fragment showing the panorama's direction from the projection centre
//! (`fs_projected` in `shaders/scene.wgsl`). The CPU twin: `RayCaster::cube_projected`.

use super::Gpu;
use super::pass::{entry, rgba8_pipeline, scene_pipeline, texture, uniform};
use crate::content::PAD;
use crate::error::{Error, Result};
use crate::scene::Projected;
use bytemuck::{Pod, Zeroable};
use glam::DVec3;
use wgpu::util::DeviceExt;

/// `Panorama` of `shaders/scene.wgsl`.
#[repr(C)]
#[derive(Debug, Clone, Copy, Pod, Zeroable)]
struct PanoramaUniform {
    centre: [f32; 4],
    turn: [[f32; 4]; 3],
    head: [u32; 4],
    p: [f32; 4],
}

pub(super) struct PanoramaPass {
    pub(super) pipeline: wgpu::RenderPipeline,
    sky: wgpu::RenderPipeline,
    bind: wgpu::BindGroup,
    buffer: wgpu::Buffer,
    uniform: PanoramaUniform,
}

impl PanoramaPass {
    pub(super) fn new(
        gpu: &Gpu,
        module: &wgpu::ShaderModule,
        face: &wgpu::BindGroupLayout,
        p: &Projected,
    ) -> Result<Self> {
        let atlas = p.content.atlas();
        let max = gpu.device.limits().max_texture_dimension_2d as usize;
        if atlas.width > max || atlas.height > max {
            return Err(Error::invalid(
                "content",
                format!(
                    "the panorama's atlas is {}×{} texels, above this adapter's {max}",
                    atlas.width, atlas.height
                ),
            ));
        }
        let (kind, q) = p.content.lookup();
        let m = p.content.frame();
        let col = |k: usize| {
            let v = m.col(k);
            [v.x as f32, v.y as f32, v.z as f32, 0.0]
        };
        let values = PanoramaUniform {
            centre: [p.centre.x as f32, p.centre.y as f32, p.centre.z as f32, 0.0],
            turn: [col(0), col(1), col(2)],
            head: [kind, atlas.width as u32, atlas.height as u32, PAD as u32],
            p: q.map(|v| v as f32),
        };
        let buffer = gpu
            .device
            .create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some("panorama"),
                contents: bytemuck::bytes_of(&values),
                usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            });
        let size = wgpu::Extent3d {
            width: atlas.width as u32,
            height: atlas.height as u32,
            depth_or_array_layers: 1,
        };
        let tex = gpu.device.create_texture_with_data(
            &gpu.queue,
            &wgpu::TextureDescriptor {
                label: Some("panorama atlas"),
                size,
                mip_level_count: 1,
                sample_count: 1,
                dimension: wgpu::TextureDimension::D2,
                format: wgpu::TextureFormat::Rgba8Unorm,
                usage: wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
                view_formats: &[],
            },
            wgpu::util::TextureDataOrder::LayerMajor,
            bytemuck::cast_slice(&atlas.data),
        );
        // The atlas's border already holds what seamless filtering reads; clamp stays inside.
        let sampler = gpu.device.create_sampler(&wgpu::SamplerDescriptor {
            label: Some("panorama"),
            mag_filter: wgpu::FilterMode::Linear,
            min_filter: wgpu::FilterMode::Linear,
            ..Default::default()
        });
        let layout = gpu
            .device
            .create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
                label: Some("panorama"),
                entries: &[
                    entry(0, uniform()),
                    entry(1, texture(wgpu::TextureViewDimension::D2, true)),
                    entry(
                        2,
                        wgpu::BindingType::Sampler(wgpu::SamplerBindingType::Filtering),
                    ),
                ],
            });
        let view = tex.create_view(&Default::default());
        let bind = gpu.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("panorama"),
            layout: &layout,
            entries: &[
                wgpu::BindGroupEntry {
                    binding: 0,
                    resource: buffer.as_entire_binding(),
                },
                wgpu::BindGroupEntry {
                    binding: 1,
                    resource: wgpu::BindingResource::TextureView(&view),
                },
                wgpu::BindGroupEntry {
                    binding: 2,
                    resource: wgpu::BindingResource::Sampler(&sampler),
                },
            ],
        });
        Ok(PanoramaPass {
            pipeline: scene_pipeline(gpu, module, &[face, &layout], "fs_projected", 1),
            sky: sky_pipeline(gpu, module, &[face, &layout]),
            bind,
            buffer,
            uniform: values,
        })
    }

    pub(super) fn set_centre(&mut self, gpu: &Gpu, centre: DVec3) {
        self.uniform.centre = [centre.x as f32, centre.y as f32, centre.z as f32, 0.0];
        gpu.queue
            .write_buffer(&self.buffer, 0, bytemuck::bytes_of(&self.uniform));
    }

    /// The panorama behind everything: one triangle over the face, before the scene.
    pub(super) fn draw_sky(&self, pass: &mut wgpu::RenderPass<'_>) {
        pass.set_pipeline(&self.sky);
        pass.set_bind_group(1, &self.bind, &[]);
        pass.draw(0..3, 0..1);
    }
}

/// The sky's pipeline: no vertex buffers, depth neither tested nor written.
fn sky_pipeline(
    gpu: &Gpu,
    module: &wgpu::ShaderModule,
    layouts: &[&wgpu::BindGroupLayout],
) -> wgpu::RenderPipeline {
    let depth = Some((false, wgpu::CompareFunction::Always));
    rgba8_pipeline(gpu, module, layouts, ["vs_sky", "fs_sky"], &[], depth, 1)
}
