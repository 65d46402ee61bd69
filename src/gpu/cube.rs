//! The cube-map pass: the scene drawn from the eye into the faces of a cube map, one render pass
//! per face with its own depth (seed 000's dynamic cube map). Two optimisations from the seed:
//! CMF renders only the faces the warp samples (decided exactly from the sampling vectors,
//! filtering footprint included), and the look-to check skips the update entirely when the eye,
//! the faces and the scene are what the cube map already shows. The face size is chosen from
//! the output's finest angular pixel pitch unless given.

use super::Gpu;
use super::pass::{buffer, depth_view, scene_pipeline, uniform_layout};
use super::projected::PanoramaPass;
use super::warp::CubeTexture;
use crate::cubemap::Face;
use crate::error::Result;
use crate::scene::Projected;
use crate::scene::{SKY, Scene, sun};
use bytemuck::{Pod, Zeroable};
use glam::{DVec3, Mat4, Vec4};
use wgpu::util::DeviceExt;

const NEAR: f32 = 0.1;
const FAR: f32 = 5000.0;

/// `Face` of `shaders/scene.wgsl`.
#[repr(C)]
#[derive(Debug, Clone, Copy, Pod, Zeroable)]
struct FaceUniform {
    clip: [[f32; 4]; 4],
    sun: [f32; 4],
    /// sc, −tc, ma: where the sky pass of a projected panorama finds its directions.
    axes: [[f32; 4]; 3],
}

/// The axes sc, tc and ma of the CPU's cube table for one face.
fn face_axes(face: Face) -> (Vec4, Vec4, Vec4) {
    match face {
        Face::PosX => (-Vec4::Z, -Vec4::Y, Vec4::X),
        Face::NegX => (Vec4::Z, -Vec4::Y, -Vec4::X),
        Face::PosY => (Vec4::X, Vec4::Z, Vec4::Y),
        Face::NegY => (Vec4::X, -Vec4::Z, -Vec4::Y),
        Face::PosZ => (Vec4::X, -Vec4::Y, Vec4::Z),
        Face::NegZ => (-Vec4::X, -Vec4::Y, -Vec4::Z),
    }
}

/// Clip-space matrix of one face: rows (sc, −tc, depth, |ma|) of the CPU's cube table applied to
/// P − eye, so that x = sc/|ma|, y = −tc/|ma| (texture rows run down) and depth ∈ [0, 1].
pub fn face_matrix(face: Face, eye: glam::Vec3) -> Mat4 {
    let (sc, tc, ma) = face_axes(face);
    let (a, b) = (FAR / (FAR - NEAR), -FAR * NEAR / (FAR - NEAR));
    let rows = [sc, -tc, ma * a + Vec4::W * b, ma];
    Mat4::from_cols(rows[0], rows[1], rows[2], rows[3]).transpose() * Mat4::from_translation(-eye)
}

/// The cube-map pass of one scene: its pipeline, the scene's vertex and index buffers on the
/// GPU, and what the target cube map shows now (for the look-to check).
pub struct CubePass {
    module: wgpu::ShaderModule,
    pipeline: wgpu::RenderPipeline,
    layout: wgpu::BindGroupLayout,
    /// A panorama projected onto the scene instead of its colours (seed 001).
    panorama: Option<PanoramaPass>,
    positions: wgpu::Buffer,
    colors: wgpu::Buffer,
    indices: wgpu::Buffer,
    count: u32,
    /// The depth buffer, kept while the face size stays.
    depth: Option<(u32, wgpu::TextureView)>,
    /// What the target shows now: eye, size, faces (the look-to check).
    shown: Option<([f32; 3], u32, [bool; 6])>,
    /// Faces drawn since creation (for tests and benchmarks).
    pub faces_drawn: u64,
}

impl CubePass {
    /// Uploads `scene`'s geometry and builds the pipeline; the scene shows its own colours.
    pub fn new(gpu: &Gpu, scene: &Scene) -> Self {
        let module = gpu
            .device
            .create_shader_module(wgpu::ShaderModuleDescriptor {
                label: Some("scene"),
                source: wgpu::ShaderSource::Wgsl(super::SCENE_WGSL.into()),
            });
        let layout = uniform_layout(gpu, "face", None);
        let pipeline = scene_pipeline(gpu, &module, &[&layout], "fs_main", 1);
        let buffer = |bytes: &[u8], usage| buffer(gpu, bytes, usage);
        CubePass {
            module,
            pipeline,
            layout,
            panorama: None,
            positions: buffer(
                bytemuck::cast_slice(&scene.positions),
                wgpu::BufferUsages::VERTEX,
            ),
            colors: buffer(
                bytemuck::cast_slice(&scene.colors),
                wgpu::BufferUsages::VERTEX,
            ),
            indices: buffer(
                bytemuck::cast_slice(&scene.indices),
                wgpu::BufferUsages::INDEX,
            ),
            count: scene.indices.len() as u32,
            depth: None,
            shown: None,
            faces_drawn: 0,
        }
    }

    /// Shows `panorama` projected from its centre onto the scene instead of the scene's own
    /// colours (seed 001), or the scene's colours again with `None`.
    pub fn set_panorama(&mut self, gpu: &Gpu, panorama: Option<&Projected>) -> Result<()> {
        self.panorama = match panorama {
            Some(p) => Some(PanoramaPass::new(gpu, &self.module, &self.layout, p)?),
            None => None,
        };
        self.shown = None;
        Ok(())
    }

    /// Moves the projected panorama's centre.
    pub fn set_centre(&mut self, gpu: &Gpu, centre: DVec3) {
        if let Some(p) = &mut self.panorama {
            p.set_centre(gpu, centre);
            self.shown = None;
        }
    }

    /// Forgets what the target shows, so that the next render draws (benchmarks).
    pub fn invalidate(&mut self) {
        self.shown = None;
    }

    /// Draws the scene from `eye` into the `faces` of `target` (the others are cleared to
    /// magenta, which no correct warp shows); returns false when the target already shows
    /// exactly this and nothing was drawn.
    pub fn render(
        &mut self,
        gpu: &Gpu,
        target: &CubeTexture,
        eye: DVec3,
        faces: [bool; 6],
    ) -> bool {
        let key = (eye.as_vec3().to_array(), target.size, faces);
        if self.shown == Some(key) {
            return false;
        }
        if self.depth.as_ref().is_none_or(|d| d.0 != target.size) {
            self.depth = Some((target.size, depth_view(gpu, target.size, target.size, 1)));
        }
        let depth_view = &self.depth.as_ref().expect("set above").1;
        let srgb = |v: u8| f64::from(v) / 255.0;
        let sky = wgpu::Color {
            r: srgb(SKY[0]),
            g: srgb(SKY[1]),
            b: srgb(SKY[2]),
            a: 1.0,
        };
        let magenta = wgpu::Color {
            r: 1.0,
            g: 0.0,
            b: 1.0,
            a: 1.0,
        };
        let mut enc = gpu
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor { label: None });
        let mut keep = Vec::new();
        for face in Face::ALL {
            let draw = faces[face.index()];
            let layer = target.texture.create_view(&wgpu::TextureViewDescriptor {
                dimension: Some(wgpu::TextureViewDimension::D2),
                base_array_layer: face.index() as u32,
                array_layer_count: Some(1),
                ..Default::default()
            });
            let (sc, tc, ma) = face_axes(face);
            let uniform = FaceUniform {
                clip: face_matrix(face, eye.as_vec3()).to_cols_array_2d(),
                sun: sun().extend(0.0).to_array(),
                axes: [sc.to_array(), (-tc).to_array(), ma.to_array()],
            };
            let buf = gpu
                .device
                .create_buffer_init(&wgpu::util::BufferInitDescriptor {
                    label: None,
                    contents: bytemuck::bytes_of(&uniform),
                    usage: wgpu::BufferUsages::UNIFORM,
                });
            let bind = gpu.device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: None,
                layout: &self.layout,
                entries: &[wgpu::BindGroupEntry {
                    binding: 0,
                    resource: buf.as_entire_binding(),
                }],
            });
            {
                let mut pass = enc.begin_render_pass(&wgpu::RenderPassDescriptor {
                    label: Some("cube face"),
                    color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                        view: &layer,
                        depth_slice: None,
                        resolve_target: None,
                        ops: wgpu::Operations {
                            load: wgpu::LoadOp::Clear(if draw { sky } else { magenta }),
                            store: wgpu::StoreOp::Store,
                        },
                    })],
                    depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                        view: depth_view,
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
                if draw {
                    pass.set_bind_group(0, &bind, &[]);
                    let pipeline = match &self.panorama {
                        Some(p) => {
                            p.draw_sky(&mut pass);
                            &p.pipeline
                        }
                        None => &self.pipeline,
                    };
                    pass.set_pipeline(pipeline);
                    pass.set_vertex_buffer(0, self.positions.slice(..));
                    pass.set_vertex_buffer(1, self.colors.slice(..));
                    pass.set_index_buffer(self.indices.slice(..), wgpu::IndexFormat::Uint32);
                    pass.draw_indexed(0..self.count, 0, 0..1);
                    self.faces_drawn += 1;
                }
            }
            keep.push(buf);
        }
        gpu.queue.submit([enc.finish()]);
        self.shown = Some(key);
        true
    }
}
