//! What the passes share: bind-group entries, the full-screen RGBA8 pipeline, the cube-map
//! pass's scene pipeline, the output texture and one draw.

use super::Gpu;

pub(super) fn entry(binding: u32, ty: wgpu::BindingType) -> wgpu::BindGroupLayoutEntry {
    wgpu::BindGroupLayoutEntry {
        binding,
        visibility: wgpu::ShaderStages::FRAGMENT,
        ty,
        count: None,
    }
}

pub(super) fn uniform() -> wgpu::BindingType {
    wgpu::BindingType::Buffer {
        ty: wgpu::BufferBindingType::Uniform,
        has_dynamic_offset: false,
        min_binding_size: None,
    }
}

pub(super) fn texture(dim: wgpu::TextureViewDimension, filterable: bool) -> wgpu::BindingType {
    wgpu::BindingType::Texture {
        sample_type: wgpu::TextureSampleType::Float { filterable },
        view_dimension: dim,
        multisampled: false,
    }
}

/// A full-screen pipeline writing RGBA8.
pub(super) fn fullscreen(
    gpu: &Gpu,
    source: &str,
    layout: &wgpu::BindGroupLayout,
) -> wgpu::RenderPipeline {
    let module = gpu
        .device
        .create_shader_module(wgpu::ShaderModuleDescriptor {
            label: None,
            source: wgpu::ShaderSource::Wgsl(source.into()),
        });
    rgba8_pipeline(
        gpu,
        &module,
        &[layout],
        ["vs_main", "fs_main"],
        &[],
        None,
        1,
    )
}

/// A pipeline of `module`'s `entries` (vertex, fragment) writing RGBA8 with `samples` samples
/// a pixel, both sides of every triangle drawn (the cube faces' matrices mirror), with a
/// Depth32Float test when `depth` says whether to write and how to compare.
pub(super) fn rgba8_pipeline(
    gpu: &Gpu,
    module: &wgpu::ShaderModule,
    layouts: &[&wgpu::BindGroupLayout],
    entries: [&str; 2],
    buffers: &[Option<wgpu::VertexBufferLayout<'_>>],
    depth: Option<(bool, wgpu::CompareFunction)>,
    samples: u32,
) -> wgpu::RenderPipeline {
    let layouts: Vec<_> = layouts.iter().map(|l| Some(*l)).collect();
    let pl = gpu
        .device
        .create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: None,
            bind_group_layouts: &layouts,
            immediate_size: 0,
        });
    gpu.device
        .create_render_pipeline(&wgpu::RenderPipelineDescriptor {
            label: Some(entries[1]),
            layout: Some(&pl),
            vertex: wgpu::VertexState {
                module,
                entry_point: Some(entries[0]),
                compilation_options: Default::default(),
                buffers,
            },
            primitive: wgpu::PrimitiveState {
                cull_mode: None,
                ..Default::default()
            },
            depth_stencil: depth.map(|(write, compare)| wgpu::DepthStencilState {
                format: wgpu::TextureFormat::Depth32Float,
                depth_write_enabled: Some(write),
                depth_compare: Some(compare),
                stencil: Default::default(),
                bias: Default::default(),
            }),
            multisample: wgpu::MultisampleState {
                count: samples,
                ..Default::default()
            },
            fragment: Some(wgpu::FragmentState {
                module,
                entry_point: Some(entries[1]),
                compilation_options: Default::default(),
                targets: &[Some(wgpu::ColorTargetState {
                    format: wgpu::TextureFormat::Rgba8Unorm,
                    blend: None,
                    write_mask: wgpu::ColorWrites::ALL,
                })],
            }),
            multiview_mask: None,
            cache: None,
        })
}

pub(super) fn output(gpu: &Gpu, width: u32, height: u32) -> wgpu::Texture {
    gpu.device.create_texture(&wgpu::TextureDescriptor {
        label: Some("output"),
        size: wgpu::Extent3d {
            width,
            height,
            depth_or_array_layers: 1,
        },
        mip_level_count: 1,
        sample_count: 1,
        dimension: wgpu::TextureDimension::D2,
        format: wgpu::TextureFormat::Rgba8Unorm,
        usage: wgpu::TextureUsages::RENDER_ATTACHMENT
            | wgpu::TextureUsages::COPY_SRC
            | wgpu::TextureUsages::TEXTURE_BINDING,
        view_formats: &[],
    })
}

pub(super) fn draw(
    gpu: &Gpu,
    pipeline: &wgpu::RenderPipeline,
    bind: &wgpu::BindGroup,
    target: &wgpu::Texture,
) {
    let view = target.create_view(&Default::default());
    let mut enc = gpu
        .device
        .create_command_encoder(&wgpu::CommandEncoderDescriptor { label: None });
    {
        let mut pass = enc.begin_render_pass(&wgpu::RenderPassDescriptor {
            label: Some("warp"),
            color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                view: &view,
                depth_slice: None,
                resolve_target: None,
                ops: wgpu::Operations {
                    load: wgpu::LoadOp::Clear(wgpu::Color::TRANSPARENT),
                    store: wgpu::StoreOp::Store,
                },
            })],
            depth_stencil_attachment: None,
            timestamp_writes: None,
            occlusion_query_set: None,
            multiview_mask: None,
        });
        pass.set_pipeline(pipeline);
        pass.set_bind_group(0, bind, &[]);
        pass.draw(0..3, 0..1);
    }
    gpu.queue.submit([enc.finish()]);
}

/// A pipeline drawing the scene's triangles (positions, colours) with depth, fragment shader
/// `fs` of `module`, `samples` samples a pixel.
pub(super) fn scene_pipeline(
    gpu: &Gpu,
    module: &wgpu::ShaderModule,
    layouts: &[&wgpu::BindGroupLayout],
    fs: &str,
    samples: u32,
) -> wgpu::RenderPipeline {
    let buffers = [
        Some(wgpu::VertexBufferLayout {
            array_stride: 12,
            step_mode: wgpu::VertexStepMode::Vertex,
            attributes: &wgpu::vertex_attr_array![0 => Float32x3],
        }),
        Some(wgpu::VertexBufferLayout {
            array_stride: 4,
            step_mode: wgpu::VertexStepMode::Vertex,
            attributes: &wgpu::vertex_attr_array![1 => Unorm8x4],
        }),
    ];
    let depth = Some((true, wgpu::CompareFunction::Less));
    rgba8_pipeline(
        gpu,
        module,
        layouts,
        ["vs_main", fs],
        &buffers,
        depth,
        samples,
    )
}

/// A Depth32Float attachment of width × height, `samples` samples a pixel.
pub(super) fn depth_view(gpu: &Gpu, width: u32, height: u32, samples: u32) -> wgpu::TextureView {
    gpu.device
        .create_texture(&wgpu::TextureDescriptor {
            label: Some("depth"),
            size: wgpu::Extent3d {
                width,
                height,
                depth_or_array_layers: 1,
            },
            mip_level_count: 1,
            sample_count: samples,
            dimension: wgpu::TextureDimension::D2,
            format: wgpu::TextureFormat::Depth32Float,
            usage: wgpu::TextureUsages::RENDER_ATTACHMENT,
            view_formats: &[],
        })
        .create_view(&Default::default())
}

/// The layout of one uniform buffer at binding 0 seen by both stages; with `dynamic`, bound at
/// offsets of that many bytes (one slot per draw).
pub(super) fn uniform_layout(
    gpu: &Gpu,
    label: &str,
    dynamic: Option<u64>,
) -> wgpu::BindGroupLayout {
    gpu.device
        .create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some(label),
            entries: &[wgpu::BindGroupLayoutEntry {
                binding: 0,
                visibility: wgpu::ShaderStages::VERTEX_FRAGMENT,
                ty: wgpu::BindingType::Buffer {
                    ty: wgpu::BufferBindingType::Uniform,
                    has_dynamic_offset: dynamic.is_some(),
                    min_binding_size: dynamic.and_then(wgpu::BufferSize::new),
                },
                count: None,
            }],
        })
}

/// A buffer holding `bytes` for `usage` (a scene's vertices or indices).
pub(super) fn buffer(gpu: &Gpu, bytes: &[u8], usage: wgpu::BufferUsages) -> wgpu::Buffer {
    use wgpu::util::DeviceExt;
    gpu.device
        .create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: None,
            contents: bytes,
            usage,
        })
}
