//! The piecewise perspective pass (seed 003): the scene drawn straight into the output through
//! the pieces of `scene::ppp`, each piece one draw of the triangles `scene::replicate` gave its
//! cell, with its own matrix (a dynamic uniform offset) and its cell as the scissor rectangle.
//! `shaders/ppp.wgsl` keeps the half of a cut cell; the CPU twin ray-casts along the same
//! pieces (`RayCaster::picture` with `Pieces::ray`).

use super::pass::{buffer, depth_view, output, scene_pipeline, uniform_layout};
use super::{Gpu, read_rgba8};
use crate::error::Result;
use crate::raster::Raster;
use crate::scene::ppp::{Half, Piece, Pieces};
use crate::scene::replicate::Replication;
use crate::scene::{SKY, Scene, sun};
use bytemuck::{Pod, Zeroable};
use glam::{DMat4, DVec3, DVec4};
use wgpu::util::DeviceExt;

/// Nearest and farthest distance drawn, metres along a piece's rays (as the cube-map pass).
pub const NEAR: f64 = 0.1;
const FAR: f64 = 5000.0;

/// `Piece` of `shaders/ppp.wgsl`, padded to the uniform offset alignment.
#[repr(C)]
#[derive(Debug, Clone, Copy, Pod, Zeroable)]
struct PieceUniform {
    clip: [[f32; 4]; 4],
    sun: [f32; 4],
    diagonal: [i32; 4],
    half: [u32; 4],
    pad: [u32; 36],
}

const STRIDE: u64 = std::mem::size_of::<PieceUniform>() as u64;

/// Clip-space matrix of one piece: world point P → (x·w, y·w, w) through the inverse of the
/// piece's pixel → direction map (w is the distance along the pixel's ray in units of its
/// direction's length), then pixels → normalised device coordinates, depth from w.
fn piece_matrix(piece: &Piece, eye: DVec3, width: u32, height: u32) -> DMat4 {
    let m = piece.field.inverse();
    let camera = DMat4::from_cols(
        m.x_axis.extend(0.0),
        m.y_axis.extend(0.0),
        m.z_axis.extend(0.0),
        DVec4::W,
    ) * DMat4::from_translation(-eye);
    let (a, b) = (FAR / (FAR - NEAR), -FAR * NEAR / (FAR - NEAR));
    let (sx, sy) = (2.0 / f64::from(width), 2.0 / f64::from(height));
    let ndc = DMat4::from_cols(
        DVec4::new(sx, 0.0, 0.0, 0.0),
        DVec4::new(0.0, -sy, 0.0, 0.0),
        DVec4::new(-1.0, 1.0, a, 1.0),
        DVec4::new(0.0, 0.0, b, 0.0),
    );
    ndc * camera
}

/// Samples a pixel when the pass antialiases (`render`'s `msaa`).
pub const MSAA: u32 = 4;

/// The piecewise perspective pass of one scene: its pipelines (single-sampled and
/// [`MSAA`]) and the scene's vertex buffers on the GPU.
pub struct PppPass {
    pipeline: wgpu::RenderPipeline,
    /// The same with [`MSAA`] samples a pixel.
    multisampled: wgpu::RenderPipeline,
    layout: wgpu::BindGroupLayout,
    positions: wgpu::Buffer,
    colors: wgpu::Buffer,
    /// Pieces drawn since creation (tests and benchmarks).
    pub pieces_drawn: u64,
}

impl PppPass {
    /// Uploads `scene`'s vertices and builds both pipelines.
    pub fn new(gpu: &Gpu, scene: &Scene) -> Self {
        let module = gpu
            .device
            .create_shader_module(wgpu::ShaderModuleDescriptor {
                label: Some("ppp"),
                source: wgpu::ShaderSource::Wgsl(super::PPP_WGSL.into()),
            });
        let layout = uniform_layout(gpu, "piece", Some(STRIDE));
        let pipeline = scene_pipeline(gpu, &module, &[&layout], "fs_main", 1);
        let multisampled = scene_pipeline(gpu, &module, &[&layout], "fs_main", MSAA);
        let vertices = |bytes: &[u8]| buffer(gpu, bytes, wgpu::BufferUsages::VERTEX);
        PppPass {
            pipeline,
            multisampled,
            layout,
            positions: vertices(bytemuck::cast_slice(&scene.positions)),
            colors: vertices(bytemuck::cast_slice(&scene.colors)),
            pieces_drawn: 0,
        }
    }

    /// The scene from `eye` through `pieces`, each cell drawing the triangles `replication`
    /// gave it; transparent where the view shows nothing. With `msaa`, [`MSAA`] samples a pixel
    /// resolved to one (triangle edges antialiased; a cut cell's halves still split whole
    /// pixels, which is invisible: both halves draw the same scene continuously).
    pub fn render(
        &mut self,
        gpu: &Gpu,
        pieces: &Pieces,
        replication: &Replication,
        eye: DVec3,
        msaa: bool,
    ) -> Result<Raster<[u8; 4]>> {
        let samples = if msaa { MSAA } else { 1 };
        let (w, h) = (pieces.width, pieces.height);
        let uniforms: Vec<PieceUniform> = pieces
            .pieces
            .iter()
            .map(|p| PieceUniform {
                clip: piece_matrix(p, eye, w, h).as_mat4().to_cols_array_2d(),
                sun: sun().extend(0.0).to_array(),
                diagonal: p.diagonal,
                half: [
                    match p.half {
                        Half::Whole => 0,
                        Half::Upper => 1,
                        Half::Lower => 2,
                    },
                    0,
                    0,
                    0,
                ],
                pad: [0; 36],
            })
            .collect();
        let uniform = gpu
            .device
            .create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some("pieces"),
                contents: bytemuck::cast_slice(&uniforms),
                usage: wgpu::BufferUsages::UNIFORM,
            });
        let bind = gpu.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: None,
            layout: &self.layout,
            entries: &[wgpu::BindGroupEntry {
                binding: 0,
                resource: wgpu::BindingResource::Buffer(wgpu::BufferBinding {
                    buffer: &uniform,
                    offset: 0,
                    size: wgpu::BufferSize::new(STRIDE),
                }),
            }],
        });
        // One index more than needed keeps the buffer non-empty when nothing is drawn.
        let mut indices = replication.indices.clone();
        indices.push(0);
        let index = buffer(
            gpu,
            bytemuck::cast_slice(&indices),
            wgpu::BufferUsages::INDEX,
        );
        let target = output(gpu, w, h);
        let (view, depth_view) = (
            target.create_view(&Default::default()),
            depth_view(gpu, w, h, samples),
        );
        let many = msaa.then(|| {
            gpu.device
                .create_texture(&wgpu::TextureDescriptor {
                    label: Some("multisampled"),
                    size: wgpu::Extent3d {
                        width: w,
                        height: h,
                        depth_or_array_layers: 1,
                    },
                    mip_level_count: 1,
                    sample_count: MSAA,
                    dimension: wgpu::TextureDimension::D2,
                    format: wgpu::TextureFormat::Rgba8Unorm,
                    usage: wgpu::TextureUsages::RENDER_ATTACHMENT,
                    view_formats: &[],
                })
                .create_view(&Default::default())
        });
        let c = |v: u8| f64::from(v) / 255.0;
        let mut enc = gpu
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor { label: None });
        {
            let mut pass = enc.begin_render_pass(&wgpu::RenderPassDescriptor {
                label: Some("ppp"),
                color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                    view: many.as_ref().unwrap_or(&view),
                    depth_slice: None,
                    resolve_target: many.as_ref().map(|_| &view),
                    ops: wgpu::Operations {
                        load: wgpu::LoadOp::Clear(wgpu::Color {
                            r: c(SKY[0]),
                            g: c(SKY[1]),
                            b: c(SKY[2]),
                            a: 1.0,
                        }),
                        store: wgpu::StoreOp::Store,
                    },
                })],
                depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                    view: &depth_view,
                    depth_ops: Some(wgpu::Operations {
                        load: wgpu::LoadOp::Clear(1.0),
                        store: wgpu::StoreOp::Discard,
                    }),
                    stencil_ops: None,
                }),
                timestamp_writes: None,
                occlusion_query_set: None,
                multiview_mask: None,
            });
            pass.set_pipeline(if msaa {
                &self.multisampled
            } else {
                &self.pipeline
            });
            pass.set_vertex_buffer(0, self.positions.slice(..));
            pass.set_vertex_buffer(1, self.colors.slice(..));
            pass.set_index_buffer(index.slice(..), wgpu::IndexFormat::Uint32);
            let mut k = 0u64;
            for (cell, range) in pieces.cells().zip(&replication.ranges) {
                for piece in cell {
                    if !range.is_empty() {
                        let [x0, y0, x1, y1] = piece.cell;
                        pass.set_scissor_rect(x0, y0, x1 - x0, y1 - y0);
                        pass.set_bind_group(0, &bind, &[(k * STRIDE) as u32]);
                        pass.draw_indexed(range.clone(), 0, 0..1);
                        self.pieces_drawn += 1;
                    }
                    k += 1;
                }
            }
            // wgpu's GL backend resolves the multisampled target with a blit at the pass's
            // end, under the scissor still set: only the last piece would be resolved.
            pass.set_scissor_rect(0, 0, w, h);
        }
        gpu.queue.submit([enc.finish()]);
        let mut img = read_rgba8(gpu, &target, w, h)?;
        for (k, px) in img.data.iter_mut().enumerate() {
            if pieces.is_hidden(k as u32 % w, k as u32 / w) {
                *px = [0; 4];
            }
        }
        Ok(img)
    }
}
