//! 3D scenes: glTF and OBJ files, and a deterministic procedural city (a terrain, buildings on a
//! street grid, four coloured towers at the compass points) in three sizes for tests and
//! benchmarks. The GPU draws them in its cube-map pass (`gpu::cube`, `shaders/scene.wgsl`) or
//! directly through a piecewise perspective projection ([`ppp`], [`replicate`]; `gpu::ppp`);
//! [`raycast`] is both passes' CPU twin, for machines without any adapter, and the exact
//! per-pixel reference.

pub mod directions;
pub mod ppp;
pub mod raycast;
pub mod replicate;

pub use raycast::RayCaster;

use crate::error::{Error, Result};
use crate::surface::Mesh;
use glam::{DVec3, Mat4, Vec3};
use std::path::Path;

/// Sky colour where a ray meets nothing.
pub const SKY: [u8; 4] = [140, 180, 230, 255];

/// Unit direction of the sun (shading only; both renderers use it).
pub fn sun() -> Vec3 {
    Vec3::new(0.4, 0.8, 0.45).normalize()
}

/// A panorama projected from `centre` onto the scene instead of its own colours (seed 001;
/// see [`crate::content::projective`]): both renderers show it, the GPU in its cube-map pass,
/// the CPU in [`RayCaster::cube_projected`].
pub struct Projected {
    /// The 8-bit panorama, looked up at the direction (P − centre)/|P − centre| of each scene
    /// point P a ray meets.
    pub content: crate::content::Content<[u8; 4]>,
    /// The projection centre C in world coordinates, metres.
    pub centre: DVec3,
}

/// Indexed triangles with a colour per vertex.
#[derive(Debug, Clone, Default)]
pub struct Scene {
    /// Vertex positions in world coordinates, metres, +y up.
    pub positions: Vec<[f32; 3]>,
    /// One RGBA8 colour per vertex, in the order of `positions`.
    pub colors: Vec<[u8; 4]>,
    /// A triangle list: three indices into `positions` per triangle (both sides are drawn).
    pub indices: Vec<u32>,
}

/// The towers of the procedural city: colour and direction from the origin (north = −z).
pub const LANDMARKS: [([u8; 4], [f32; 3]); 4] = [
    ([220, 30, 30, 255], [0.0, 0.0, -1.0]),
    ([30, 200, 40, 255], [1.0, 0.0, 0.0]),
    ([40, 60, 230, 255], [0.0, 0.0, 1.0]),
    ([240, 220, 20, 255], [-1.0, 0.0, 0.0]),
];

/// A small deterministic generator (SplitMix64), so a city is the same everywhere.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> f32 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        ((z ^ (z >> 31)) >> 40) as f32 / (1u64 << 24) as f32
    }
}

/// Terrain height at (x, z), metres: gentle hills, flat around the origin where the eye is.
pub fn terrain_height(x: f32, z: f32) -> f32 {
    let r = (x * x + z * z).sqrt();
    let hills = 6.0 * (x * 0.011).sin() * (z * 0.013).cos() + 3.0 * (x * 0.031 + z * 0.017).sin();
    hills * ((r - 60.0) / 200.0).clamp(0.0, 1.0)
}

impl Scene {
    /// Number of triangles (`indices.len() / 3`).
    pub fn triangles(&self) -> usize {
        self.indices.len() / 3
    }

    fn push_quad(&mut self, q: [Vec3; 4], color: [u8; 4]) {
        let base = self.positions.len() as u32;
        self.positions.extend(q.map(|v| v.to_array()));
        self.colors.extend([color; 4]);
        self.indices
            .extend([base, base + 1, base + 2, base, base + 2, base + 3]);
    }

    /// A box from `lo` to `hi` without its bottom: 10 triangles.
    fn push_box(&mut self, lo: Vec3, hi: Vec3, wall: [u8; 4], roof: [u8; 4]) {
        let c = |x: f32, y: f32, z: f32| Vec3::new(x, y, z);
        let (a, b) = (lo, hi);
        self.push_quad(
            [
                c(a.x, b.y, a.z),
                c(b.x, b.y, a.z),
                c(b.x, b.y, b.z),
                c(a.x, b.y, b.z),
            ],
            roof,
        );
        self.push_quad(
            [
                c(a.x, a.y, a.z),
                c(b.x, a.y, a.z),
                c(b.x, b.y, a.z),
                c(a.x, b.y, a.z),
            ],
            wall,
        );
        self.push_quad(
            [
                c(a.x, a.y, b.z),
                c(b.x, a.y, b.z),
                c(b.x, b.y, b.z),
                c(a.x, b.y, b.z),
            ],
            wall,
        );
        self.push_quad(
            [
                c(a.x, a.y, a.z),
                c(a.x, a.y, b.z),
                c(a.x, b.y, b.z),
                c(a.x, b.y, a.z),
            ],
            wall,
        );
        self.push_quad(
            [
                c(b.x, a.y, a.z),
                c(b.x, a.y, b.z),
                c(b.x, b.y, b.z),
                c(b.x, b.y, a.z),
            ],
            wall,
        );
    }

    /// The procedural city with about `triangles` triangles: a terrain of ~20 % of them,
    /// buildings for the rest on a street grid (none within 40 m of the origin), four 250 m
    /// towers 600 m away at the compass points (`LANDMARKS`).
    pub fn city(triangles: usize) -> Scene {
        let mut s = Scene::default();
        let mut rng = Rng(0x0DD_BA11);
        let half = 800.0f32;
        let n = ((triangles as f32 * 0.2 / 2.0).sqrt().round() as usize).max(4);
        let step = 2.0 * half / n as f32;
        for j in 0..n {
            for i in 0..n {
                let (x0, z0) = (-half + i as f32 * step, -half + j as f32 * step);
                let (x1, z1) = (x0 + step, z0 + step);
                let p = |x: f32, z: f32| Vec3::new(x, terrain_height(x, z), z);
                let g = 90 + ((i * 7 + j * 13) % 5) as u8 * 8;
                s.push_quad(
                    [p(x0, z0), p(x0, z1), p(x1, z1), p(x1, z0)],
                    [70, g, 60, 255],
                );
            }
        }
        for (color, dir) in LANDMARKS {
            let c = Vec3::from_array(dir) * 600.0;
            let y = terrain_height(c.x, c.z) - 5.0;
            s.push_box(
                c - Vec3::new(12.0, -y, 12.0),
                c + Vec3::new(12.0, 250.0, 12.0),
                color,
                color,
            );
        }
        let buildings = triangles.saturating_sub(s.triangles()) / 10;
        let side = (buildings as f32).sqrt().ceil().max(1.0) as usize;
        let block = 1200.0 / side as f32;
        let mut placed = 0;
        'grid: for j in 0..side + 2 {
            for i in 0..side + 2 {
                if placed >= buildings {
                    break 'grid;
                }
                let cx = -600.0 + (i as f32 + 0.5) * block;
                let cz = -600.0 + (j as f32 + 0.5) * block;
                if cx.hypot(cz) < 40.0 {
                    continue;
                }
                let w = block * (0.25 + 0.35 * rng.next());
                let h = 6.0 + 40.0 * rng.next() * rng.next();
                let y = terrain_height(cx, cz) - 1.0;
                let tone = 120 + (rng.next() * 100.0) as u8;
                s.push_box(
                    Vec3::new(cx - w / 2.0, y, cz - w / 2.0),
                    Vec3::new(cx + w / 2.0, y + 1.0 + h, cz + w / 2.0),
                    [tone, tone - 20, tone - 40, 255],
                    [90, 90, 100, 255],
                );
                placed += 1;
            }
        }
        s
    }

    /// `city:small|medium|large` (~10k, ~100k, ~1M triangles), `wall:RIG.json` (the rig's
    /// screen as triangles, [`crate::surface::Screen::triangles`]) or a `.gltf`/`.glb`/`.obj`
    /// file.
    pub fn load(spec: &str) -> Result<Scene> {
        match spec {
            "city:small" => return Ok(Scene::city(10_000)),
            "city:medium" => return Ok(Scene::city(100_000)),
            "city:large" => return Ok(Scene::city(1_000_000)),
            _ => {}
        }
        if let Some(rig) = spec.strip_prefix("wall:") {
            let rig = crate::rig::Rig::read(Path::new(rig))?;
            return Ok(Scene::from_triangles(&rig.doc.screen.triangles()));
        }
        if spec.starts_with("city:") {
            return Err(Error::invalid(
                "scene",
                format!("`{spec}`: the cities are city:small, city:medium and city:large"),
            ));
        }
        let path = Path::new(spec);
        let ext = path
            .extension()
            .and_then(|e| e.to_str())
            .map(str::to_lowercase);
        let scene = match ext.as_deref() {
            Some("obj") => Scene::read_obj(path)?,
            Some("gltf" | "glb") => Scene::read_gltf(path)?,
            _ => {
                return Err(Error::invalid(
                    "scene",
                    format!(
                        "`{spec}`: expected a .gltf, .glb or .obj file, wall:RIG.json, or city:small|medium|large"
                    ),
                ));
            }
        };
        if scene.triangles() == 0 {
            return Err(Error::file(path, "the scene has no triangles"));
        }
        Ok(scene)
    }

    /// An OBJ file's triangles, in one grey.
    pub fn read_obj(path: &Path) -> Result<Scene> {
        Ok(Scene::from_triangles(&crate::surface::read_obj_triangles(
            path,
        )?))
    }

    /// Triangles in one grey.
    pub fn from_triangles(tris: &[[DVec3; 3]]) -> Scene {
        let mut s = Scene::default();
        for t in tris {
            let base = s.positions.len() as u32;
            s.positions.extend(t.map(|v| v.as_vec3().to_array()));
            s.colors.extend([[200, 200, 200, 255]; 3]);
            s.indices.extend([base, base + 1, base + 2]);
        }
        s
    }

    /// A glTF scene's triangle primitives, world transforms applied, coloured by the material's
    /// base colour factor (times COLOR_0 where present).
    pub fn read_gltf(path: &Path) -> Result<Scene> {
        let (doc, buffers, _) = gltf::import(path).map_err(|e| Error::file(path, e))?;
        let mut s = Scene::default();
        let scene = doc
            .default_scene()
            .or_else(|| doc.scenes().next())
            .ok_or_else(|| Error::file(path, "the file has no scene"))?;
        let mut stack: Vec<(gltf::Node, Mat4)> =
            scene.nodes().map(|n| (n, Mat4::IDENTITY)).collect();
        while let Some((node, parent)) = stack.pop() {
            let world = parent * Mat4::from_cols_array_2d(&node.transform().matrix());
            if let Some(mesh) = node.mesh() {
                for prim in mesh.primitives() {
                    if prim.mode() != gltf::mesh::Mode::Triangles {
                        continue;
                    }
                    let reader = prim.reader(|b| buffers.get(b.index()).map(|d| &d.0[..]));
                    let Some(positions) = reader.read_positions() else {
                        continue;
                    };
                    let base = s.positions.len() as u32;
                    let factor = prim.material().pbr_metallic_roughness().base_color_factor();
                    let mut count = 0;
                    for p in positions {
                        s.positions
                            .push(world.transform_point3(Vec3::from_array(p)).to_array());
                        count += 1;
                    }
                    let colors: Vec<[f32; 4]> = match reader.read_colors(0) {
                        Some(c) => c.into_rgba_f32().collect(),
                        None => vec![[1.0; 4]; count],
                    };
                    for c in colors.iter().take(count) {
                        let rgba = [0, 1, 2, 3].map(|k| (c[k] * factor[k]).clamp(0.0, 1.0));
                        s.colors.push(rgba.map(|v| (v * 255.0).round() as u8));
                    }
                    s.colors.resize(s.positions.len(), [255; 4]);
                    match reader.read_indices() {
                        Some(ix) => s.indices.extend(ix.into_u32().map(|i| base + i)),
                        None => s.indices.extend((0..count as u32).map(|i| base + i)),
                    }
                }
            }
            stack.extend(node.children().map(|c| (c, world)));
        }
        if s.indices.iter().any(|&i| i as usize >= s.positions.len()) {
            return Err(Error::file(path, "an index points past the vertices"));
        }
        Ok(s)
    }

    /// The scene as glTF 2.0: one mesh, positions, COLOR_0 (normalised bytes) and u32 indices in
    /// one buffer. Returns the JSON with the buffer at `uri`, and the buffer; for a `.glb`
    /// pass `None` and join them with [`glb`].
    pub fn to_gltf(&self, uri: Option<&str>) -> (String, Vec<u8>) {
        let mut bin: Vec<u8> = Vec::new();
        bin.extend(
            self.positions
                .iter()
                .flatten()
                .flat_map(|v| v.to_le_bytes()),
        );
        let colors_at = bin.len();
        bin.extend(self.colors.iter().flatten());
        let indices_at = bin.len();
        bin.extend(self.indices.iter().flat_map(|i| i.to_le_bytes()));
        let (mut lo, mut hi) = ([f32::MAX; 3], [f32::MIN; 3]);
        for p in &self.positions {
            for k in 0..3 {
                lo[k] = lo[k].min(p[k]);
                hi[k] = hi[k].max(p[k]);
            }
        }
        let n = self.positions.len();
        let mut buffer = serde_json::json!({"byteLength": bin.len()});
        if let Some(u) = uri {
            buffer["uri"] = u.into();
        }
        let json = serde_json::json!({
            "asset": {"version": "2.0", "generator": "omniwarp"},
            "scene": 0,
            "scenes": [{"nodes": [0]}],
            "nodes": [{"mesh": 0}],
            "meshes": [{"primitives": [{"attributes": {"POSITION": 0, "COLOR_0": 1}, "indices": 2}]}],
            "buffers": [buffer],
            "bufferViews": [
                {"buffer": 0, "byteOffset": 0, "byteLength": colors_at, "target": 34962},
                {"buffer": 0, "byteOffset": colors_at, "byteLength": indices_at - colors_at, "target": 34962},
                {"buffer": 0, "byteOffset": indices_at, "byteLength": bin.len() - indices_at, "target": 34963}
            ],
            "accessors": [
                {"bufferView": 0, "componentType": 5126, "count": n, "type": "VEC3", "min": lo, "max": hi},
                {"bufferView": 1, "componentType": 5121, "normalized": true, "count": n, "type": "VEC4"},
                {"bufferView": 2, "componentType": 5125, "count": self.indices.len(), "type": "SCALAR"}
            ]
        });
        (json.to_string(), bin)
    }

    /// The CPU's way to see the scene: its triangles in a BVH, built once.
    pub fn ray_caster(&self) -> Result<RayCaster> {
        let p = |i: u32| Vec3::from_array(self.positions[i as usize]).as_dvec3();
        let tris: Vec<[DVec3; 3]> = self
            .indices
            .chunks_exact(3)
            .map(|t| [p(t[0]), p(t[1]), p(t[2])])
            .collect();
        Ok(RayCaster {
            mesh: Mesh::new(tris)?,
            colors: self
                .indices
                .chunks_exact(3)
                .map(|t| self.colors[t[0] as usize])
                .collect(),
        })
    }
}

/// A binary glTF: the JSON and the buffer as two chunks, each padded to 4 bytes.
pub fn glb(json: &str, bin: &[u8]) -> Vec<u8> {
    let pad = |mut v: Vec<u8>, with: u8| {
        while !v.len().is_multiple_of(4) {
            v.push(with);
        }
        v
    };
    let (j, b) = (pad(json.as_bytes().to_vec(), b' '), pad(bin.to_vec(), 0));
    let total = 12 + 8 + j.len() + 8 + b.len();
    let mut out = Vec::with_capacity(total);
    out.extend(b"glTF");
    out.extend(2u32.to_le_bytes());
    out.extend((total as u32).to_le_bytes());
    out.extend((j.len() as u32).to_le_bytes());
    out.extend(b"JSON");
    out.extend(j);
    out.extend((b.len() as u32).to_le_bytes());
    out.extend(b"BIN\0");
    out.extend(b);
    out
}
