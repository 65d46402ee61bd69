//! The player's pass: a finished picture (warped and blended on the CPU) put on an output —
//! a window's surface or, headless, a texture read back — pixel for pixel, or black while the
//! operator mutes it. Shader: `shaders/show.wgsl`.

use super::pass::{entry, output, texture, uniform};
use super::{Gpu, SHOW_WGSL, read_rgba8};
use crate::error::{Error, Result};
use crate::raster::Raster;
use wgpu::util::DeviceExt;

/// The pass: one bind-group layout, a pipeline per target format (a window's surface is
/// usually BGRA, a headless target RGBA).
pub struct ShowPass {
    module: wgpu::ShaderModule,
    layout: wgpu::BindGroupLayout,
    pipelines: Vec<(wgpu::TextureFormat, wgpu::RenderPipeline)>,
}

/// A picture on the device, ready to be shown on one output.
pub struct Picture {
    /// Kept with the bind group that reads it.
    _texture: wgpu::Texture,
    uniform: wgpu::Buffer,
    bind: wgpu::BindGroup,
    /// Its size in pixels.
    pub size: (u32, u32),
}

impl ShowPass {
    /// Compiles the shader; pipelines are made for each target format as it is first met.
    pub fn new(gpu: &Gpu) -> Self {
        let module = gpu
            .device
            .create_shader_module(wgpu::ShaderModuleDescriptor {
                label: Some("show"),
                source: wgpu::ShaderSource::Wgsl(SHOW_WGSL.into()),
            });
        let layout = gpu
            .device
            .create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
                label: Some("show"),
                entries: &[
                    entry(0, texture(wgpu::TextureViewDimension::D2, false)),
                    entry(1, uniform()),
                ],
            });
        ShowPass {
            module,
            layout,
            pipelines: Vec::new(),
        }
    }

    /// Uploads `img`; errors when the adapter cannot hold a texture that large.
    pub fn upload(&self, gpu: &Gpu, img: &Raster<[u8; 4]>) -> Result<Picture> {
        let (w, h) = (img.width as u32, img.height as u32);
        let max = gpu.device.limits().max_texture_dimension_2d;
        if w == 0 || h == 0 || w > max || h > max {
            return Err(Error::invalid(
                "picture",
                format!("must be 1–{max} pixels each way on this adapter, got {w}×{h}"),
            ));
        }
        let texture = gpu.device.create_texture_with_data(
            &gpu.queue,
            &wgpu::TextureDescriptor {
                label: Some("picture"),
                size: wgpu::Extent3d {
                    width: w,
                    height: h,
                    depth_or_array_layers: 1,
                },
                mip_level_count: 1,
                sample_count: 1,
                dimension: wgpu::TextureDimension::D2,
                format: wgpu::TextureFormat::Rgba8Unorm,
                usage: wgpu::TextureUsages::TEXTURE_BINDING,
                view_formats: &[],
            },
            wgpu::util::TextureDataOrder::LayerMajor,
            bytemuck::cast_slice(&img.data),
        );
        let uniform = gpu.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("show"),
            size: 16,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let view = texture.create_view(&Default::default());
        let bind = gpu.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("show"),
            layout: &self.layout,
            entries: &[
                wgpu::BindGroupEntry {
                    binding: 0,
                    resource: wgpu::BindingResource::TextureView(&view),
                },
                wgpu::BindGroupEntry {
                    binding: 1,
                    resource: uniform.as_entire_binding(),
                },
            ],
        });
        Ok(Picture {
            _texture: texture,
            uniform,
            bind,
            size: (w, h),
        })
    }

    fn pipeline(&mut self, gpu: &Gpu, format: wgpu::TextureFormat) -> &wgpu::RenderPipeline {
        let at = match self.pipelines.iter().position(|(f, _)| *f == format) {
            Some(i) => i,
            None => {
                let made = self.make(gpu, format);
                self.pipelines.push((format, made));
                self.pipelines.len() - 1
            }
        };
        &self.pipelines[at].1
    }

    fn make(&self, gpu: &Gpu, format: wgpu::TextureFormat) -> wgpu::RenderPipeline {
        let pl = gpu
            .device
            .create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
                label: Some("show"),
                bind_group_layouts: &[Some(&self.layout)],
                immediate_size: 0,
            });
        gpu.device
            .create_render_pipeline(&wgpu::RenderPipelineDescriptor {
                label: Some("show"),
                layout: Some(&pl),
                vertex: wgpu::VertexState {
                    module: &self.module,
                    entry_point: Some("vs_main"),
                    compilation_options: Default::default(),
                    buffers: &[],
                },
                primitive: Default::default(),
                depth_stencil: None,
                multisample: Default::default(),
                fragment: Some(wgpu::FragmentState {
                    module: &self.module,
                    entry_point: Some("fs_main"),
                    compilation_options: Default::default(),
                    targets: &[Some(wgpu::ColorTargetState {
                        format,
                        blend: None,
                        write_mask: wgpu::ColorWrites::ALL,
                    })],
                }),
                multiview_mask: None,
                cache: None,
            })
    }

    /// Draws `picture` (black when `black`) into `view`, a `format` target of `size` pixels,
    /// and submits the work.
    pub fn draw(
        &mut self,
        gpu: &Gpu,
        picture: &Picture,
        black: bool,
        (view, format, size): (&wgpu::TextureView, wgpu::TextureFormat, (u32, u32)),
    ) {
        let settings: [u32; 4] = [
            (size.0 as f32).to_bits(),
            (size.1 as f32).to_bits(),
            u32::from(black),
            0,
        ];
        gpu.queue
            .write_buffer(&picture.uniform, 0, bytemuck::cast_slice(&settings));
        let pipeline = self.pipeline(gpu, format).clone();
        let mut enc = gpu
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor { label: None });
        {
            let mut pass = enc.begin_render_pass(&wgpu::RenderPassDescriptor {
                label: Some("show"),
                color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                    view,
                    depth_slice: None,
                    resolve_target: None,
                    ops: wgpu::Operations {
                        load: wgpu::LoadOp::Clear(wgpu::Color::BLACK),
                        store: wgpu::StoreOp::Store,
                    },
                })],
                depth_stencil_attachment: None,
                timestamp_writes: None,
                occlusion_query_set: None,
                multiview_mask: None,
            });
            pass.set_pipeline(&pipeline);
            pass.set_bind_group(0, &picture.bind, &[]);
            pass.draw(0..3, 0..1);
        }
        gpu.queue.submit([enc.finish()]);
    }

    /// What an output of `size` pixels shows of `picture`, drawn off screen and read back: the
    /// headless player, and the check that the pass copies pixels unchanged.
    pub fn render(
        &mut self,
        gpu: &Gpu,
        picture: &Picture,
        black: bool,
        size: (u32, u32),
    ) -> Result<Raster<[u8; 4]>> {
        let target = Offscreen::new(gpu, size);
        self.draw(gpu, picture, black, target.target());
        target.read(gpu)
    }
}

/// An output off screen: an RGBA8 texture to draw into and read back.
pub struct Offscreen {
    texture: wgpu::Texture,
    view: wgpu::TextureView,
    size: (u32, u32),
}

impl Offscreen {
    /// An output of `size` pixels.
    pub fn new(gpu: &Gpu, size: (u32, u32)) -> Self {
        let texture = output(gpu, size.0, size.1);
        let view = texture.create_view(&Default::default());
        Offscreen {
            texture,
            view,
            size,
        }
    }

    /// What [`ShowPass::draw`] draws into.
    pub fn target(&self) -> (&wgpu::TextureView, wgpu::TextureFormat, (u32, u32)) {
        (&self.view, wgpu::TextureFormat::Rgba8Unorm, self.size)
    }

    /// Its pixels.
    pub fn read(&self, gpu: &Gpu) -> Result<Raster<[u8; 4]>> {
        read_rgba8(gpu, &self.texture, self.size.0, self.size.1)
    }
}
