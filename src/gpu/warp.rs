//! The warp pass: output pixel → sampling vector V (analytic δP in WGSL, or a float normal map)
//! → bilinear cube-map sample → optional saturation by the tiles' f → optional radial blur →
//! readback. The cube map is an RGBA8 texture of six layers in the CPU's face order and table.

use super::blur::BlurPass;
use super::pass::{draw, entry, fullscreen, output, texture, uniform};
use super::{Gpu, read_rgba8, warp_source};
use crate::cubemap::{CubeMap, Face};
use crate::error::{Error, Result};
use crate::normalmap::NormalMap;
use crate::projection::View;
use crate::raster::Raster;
use crate::render::blur::Blur;
use bytemuck::{Pod, Zeroable};
use wgpu::util::DeviceExt;

/// `Projection` of `shaders/projections.wgsl`.
#[repr(C)]
#[derive(Debug, Clone, Copy, Pod, Zeroable)]
pub struct ProjectionUniform {
    head: [u32; 4],
    p: [f32; 4],
    turn: [[f32; 4]; 3],
    c: [[f32; 4]; 3],
    offaxis_zoom: [f32; 4],
}

impl ProjectionUniform {
    /// The uniform that evaluates `view` in WGSL for a `width` × `height` output: the
    /// projection's shader form, the view transform's C, off-axis vector O and zoom.
    pub fn of(view: &View, width: u32, height: u32) -> Self {
        let form = view.projection().shader_form();
        let (c, o, zoom) = view.parts();
        let col = |m: glam::DMat3, k: usize| {
            let v = m.col(k);
            [v.x as f32, v.y as f32, v.z as f32, 0.0]
        };
        ProjectionUniform {
            head: [form.kind, form.radial, width, height],
            p: form.p.map(|v| v as f32),
            turn: [col(form.turn, 0), col(form.turn, 1), col(form.turn, 2)],
            c: [col(c, 0), col(c, 1), col(c, 2)],
            offaxis_zoom: [o.x as f32, o.y as f32, o.z as f32, zoom as f32],
        }
    }
}

/// Where the sampling vectors come from.
#[derive(Clone, Copy)]
pub enum Source<'a> {
    /// A view's analytic δP and view transform, evaluated in the shader at each pixel centre.
    View(&'a View),
    /// A float normal map (warp map) of the output's size, read per pixel; alpha below 0.5
    /// leaves the pixel transparent.
    Map(&'a NormalMap),
}

/// A cube map on the GPU: six RGBA8 layers, +X −X +Y −Y +Z −Z.
pub struct CubeTexture {
    /// The texture: `size` × `size` × 6 layers, `Rgba8Unorm`, renderable and copyable.
    pub texture: wgpu::Texture,
    /// A `Cube` view of the texture, for sampling.
    pub view: wgpu::TextureView,
    /// Width and height of each face in texels.
    pub size: u32,
}

impl CubeTexture {
    /// An empty cube map that passes can render into.
    pub fn target(gpu: &Gpu, size: u32) -> Self {
        let texture = gpu.device.create_texture(&wgpu::TextureDescriptor {
            label: Some("cube"),
            size: wgpu::Extent3d {
                width: size,
                height: size,
                depth_or_array_layers: 6,
            },
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format: wgpu::TextureFormat::Rgba8Unorm,
            usage: wgpu::TextureUsages::TEXTURE_BINDING
                | wgpu::TextureUsages::RENDER_ATTACHMENT
                | wgpu::TextureUsages::COPY_DST
                | wgpu::TextureUsages::COPY_SRC,
            view_formats: &[],
        });
        let view = texture.create_view(&wgpu::TextureViewDescriptor {
            dimension: Some(wgpu::TextureViewDimension::Cube),
            ..Default::default()
        });
        CubeTexture {
            texture,
            view,
            size,
        }
    }

    /// Uploads a CPU cube map.
    pub fn upload(gpu: &Gpu, cube: &CubeMap<[u8; 4]>) -> Self {
        let size = cube.face(Face::PosX).width as u32;
        let t = CubeTexture::target(gpu, size);
        for face in Face::ALL {
            let data: &[u8] = bytemuck::cast_slice(&cube.face(face).data);
            gpu.queue.write_texture(
                wgpu::TexelCopyTextureInfo {
                    texture: &t.texture,
                    mip_level: 0,
                    origin: wgpu::Origin3d {
                        x: 0,
                        y: 0,
                        z: face.index() as u32,
                    },
                    aspect: wgpu::TextureAspect::All,
                },
                data,
                wgpu::TexelCopyBufferLayout {
                    offset: 0,
                    bytes_per_row: Some(size * 4),
                    rows_per_image: Some(size),
                },
                wgpu::Extent3d {
                    width: size,
                    height: size,
                    depth_or_array_layers: 1,
                },
            );
        }
        t
    }
}

/// The warp pass: its full-screen pipeline, its bilinear cube sampler and the blur pass that
/// follows it; built once per device and reused for every frame.
pub struct WarpPass {
    pipeline: wgpu::RenderPipeline,
    layout: wgpu::BindGroupLayout,
    blur: BlurPass,
    sampler: wgpu::Sampler,
}

/// A float texture read with textureLoad (w × h, `channels` 1 or 4).
fn float_texture(gpu: &Gpu, w: u32, h: u32, data: &[f32], channels: u32) -> wgpu::TextureView {
    let format = if channels == 4 {
        wgpu::TextureFormat::Rgba32Float
    } else {
        wgpu::TextureFormat::R32Float
    };
    gpu.device
        .create_texture_with_data(
            &gpu.queue,
            &wgpu::TextureDescriptor {
                label: None,
                size: wgpu::Extent3d {
                    width: w,
                    height: h,
                    depth_or_array_layers: 1,
                },
                mip_level_count: 1,
                sample_count: 1,
                dimension: wgpu::TextureDimension::D2,
                format,
                usage: wgpu::TextureUsages::TEXTURE_BINDING,
                view_formats: &[],
            },
            wgpu::util::TextureDataOrder::LayerMajor,
            bytemuck::cast_slice(data),
        )
        .create_view(&Default::default())
}

impl WarpPass {
    /// Builds the pipeline (the projections prepended to the warp shader) and the blur pass.
    pub fn new(gpu: &Gpu) -> Self {
        use wgpu::TextureViewDimension as D;
        let layout = gpu
            .device
            .create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
                label: Some("warp"),
                entries: &[
                    entry(0, uniform()),
                    entry(1, uniform()),
                    entry(2, texture(D::Cube, true)),
                    entry(
                        3,
                        wgpu::BindingType::Sampler(wgpu::SamplerBindingType::Filtering),
                    ),
                    entry(4, texture(D::D2, false)),
                    entry(5, texture(D::D2, false)),
                ],
            });
        let sampler = gpu.device.create_sampler(&wgpu::SamplerDescriptor {
            mag_filter: wgpu::FilterMode::Linear,
            min_filter: wgpu::FilterMode::Linear,
            ..Default::default()
        });
        WarpPass {
            pipeline: fullscreen(gpu, &warp_source(), &layout),
            layout,
            blur: BlurPass::new(gpu),
            sampler,
        }
    }

    /// Renders `width` × `height` pixels of `cube` through `source`; `f` (one per pixel) lowers
    /// the saturation; `blur` adds the radial blur.
    pub fn render(
        &self,
        gpu: &Gpu,
        cube: &CubeTexture,
        source: Source<'_>,
        (width, height): (u32, u32),
        f: Option<&[f32]>,
        blur: Option<Blur>,
    ) -> Result<Raster<[u8; 4]>> {
        let max = gpu.device.limits().max_texture_dimension_2d;
        if width == 0 || height == 0 || width > max || height > max {
            return Err(Error::invalid(
                "size",
                format!("must be 1–{max} pixels each way on this adapter, got {width}×{height}"),
            ));
        }
        let n = (width * height) as usize;
        if f.is_some_and(|f| f.len() != n) {
            return Err(Error::invalid("f", "needs one value per output pixel"));
        }
        let (uniform, mode, normals) = match source {
            Source::View(view) => (
                ProjectionUniform::of(view, width, height),
                0u32,
                float_texture(gpu, 1, 1, &[0.0; 4], 4),
            ),
            Source::Map(map) => {
                if (map.width(), map.height()) != (width as usize, height as usize) {
                    return Err(Error::invalid(
                        "normal-map",
                        format!(
                            "is {}×{}, the output {width}×{height}",
                            map.width(),
                            map.height()
                        ),
                    ));
                }
                let data: &[f32] = bytemuck::cast_slice(&map.pixels().data);
                let uniform = ProjectionUniform::zeroed();
                (uniform, 1, float_texture(gpu, width, height, data, 4))
            }
        };
        let f_view = match f {
            Some(f) => float_texture(gpu, width, height, f, 1),
            None => float_texture(gpu, 1, 1, &[1.0], 1),
        };
        let settings = [mode, u32::from(f.is_some()), 0, 0];
        let buf = |bytes: &[u8]| {
            gpu.device
                .create_buffer_init(&wgpu::util::BufferInitDescriptor {
                    label: None,
                    contents: bytes,
                    usage: wgpu::BufferUsages::UNIFORM,
                })
        };
        let (u_buf, s_buf) = (
            buf(bytemuck::bytes_of(&uniform)),
            buf(bytemuck::cast_slice(&settings)),
        );
        let bind = gpu.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: None,
            layout: &self.layout,
            entries: &[
                wgpu::BindGroupEntry {
                    binding: 0,
                    resource: u_buf.as_entire_binding(),
                },
                wgpu::BindGroupEntry {
                    binding: 1,
                    resource: s_buf.as_entire_binding(),
                },
                wgpu::BindGroupEntry {
                    binding: 2,
                    resource: wgpu::BindingResource::TextureView(&cube.view),
                },
                wgpu::BindGroupEntry {
                    binding: 3,
                    resource: wgpu::BindingResource::Sampler(&self.sampler),
                },
                wgpu::BindGroupEntry {
                    binding: 4,
                    resource: wgpu::BindingResource::TextureView(&normals),
                },
                wgpu::BindGroupEntry {
                    binding: 5,
                    resource: wgpu::BindingResource::TextureView(&f_view),
                },
            ],
        });
        let target = output(gpu, width, height);
        draw(gpu, &self.pipeline, &bind, &target);
        match blur {
            None => read_rgba8(gpu, &target, width, height),
            Some(b) => {
                let blurred = self.blur.apply(gpu, &target, (width, height), b);
                read_rgba8(gpu, &blurred, width, height)
            }
        }
    }
}
