//! 3D scenes through the GPU's cube-map pass (lavapipe in CI) against the CPU's ray-cast cube
//! map: landmarks where they belong, CMF drawing exactly the faces the warp samples, the look-to
//! skip, and clear errors for scenes that cannot be read.

use glam::DVec3;
use omniwarp::cubemap::Face;
use omniwarp::gpu::Renderer;
use omniwarp::gpu::frame::{FrameOptions, SceneRenderer};
use omniwarp::normalmap::NormalMap;
use omniwarp::projection::{self, Params, View};
use omniwarp::raster::{Raster, psnr};
use omniwarp::render::coverage::faces_sampled;
use omniwarp::scene::{LANDMARKS, Scene};

fn view(name: &str, params: Params, w: u32, h: u32) -> View {
    View::plain(projection::build(name, &params, f64::from(h) / f64::from(w)).unwrap())
}

fn opts(size: (u32, u32), face: Option<u32>, cmf: bool, eye: DVec3) -> FrameOptions {
    FrameOptions {
        size,
        face,
        cmf,
        blur: None,
        eye,
    }
}

fn full_sphere(w: u32, h: u32) -> View {
    let p = Params {
        hfov: Some(360.0),
        vfov: Some(180.0),
        ..Params::default()
    };
    view("equirect", p, w, h)
}

#[test]
fn the_towers_stand_at_the_compass_points_on_both_renderers() {
    let (w, h) = (720, 360);
    let eye = DVec3::new(0.0, 120.0, 0.0);
    let v = full_sphere(w, h);
    let mut images = Vec::new();
    for renderer in [Renderer::Gpu, Renderer::Cpu] {
        let mut r = SceneRenderer::new(Scene::city(10_000), renderer, None).unwrap();
        let (img, _) = r.frame(&v, &opts((w, h), Some(256), true, eye)).unwrap();
        // From 120 m up nothing but the towers rises 5° above the horizon.
        for (color, dir) in LANDMARKS {
            let lon = f64::from(dir[0]).atan2(-f64::from(dir[2]));
            let x = ((lon / std::f64::consts::TAU + 0.5) * f64::from(w)) as usize % w as usize;
            let y = (f64::from(h) * (0.5 - 5.0 / 180.0)) as usize;
            let got = img.data[y * w as usize + x];
            let dist: i32 = (0..3)
                .map(|k| (i32::from(got[k]) - i32::from(color[k])).abs())
                .max()
                .unwrap();
            // Shading scales the colour by 0.45–1.
            let ratio = |k: usize| f64::from(got[k]) / f64::from(color[k].max(1));
            assert!(
                dist < 140 && (0..3).filter(|&k| color[k] > 100).all(|k| ratio(k) > 0.4),
                "{renderer:?}: tower {color:?} at lon {:.0}°: {got:?}",
                lon.to_degrees()
            );
        }
        images.push(img);
    }
    // The two cube-map passes differ only along edges (rasterised vs ray-cast).
    let db = psnr(&images[0], &images[1], 255.0, |_, _| true);
    eprintln!("city, GPU vs CPU: {db:.1} dB");
    // Measured 57.2 dB: the two passes differ only along triangle edges.
    assert!(db > 54.0, "{db} dB");
}

#[test]
fn cmf_draws_exactly_the_faces_the_warp_samples() {
    let eye = DVec3::new(0.0, 1.7, 0.0);
    let cases = [
        (
            "flat 60",
            view(
                "flat",
                Params {
                    hfov: Some(60.0),
                    ..Params::default()
                },
                320,
                240,
            ),
            vec![Face::NegZ],
        ),
        (
            "fisheye 180",
            view(
                "fisheye",
                Params {
                    fov: Some(180.0),
                    ..Params::default()
                },
                256,
                256,
            ),
            vec![Face::PosX, Face::NegX, Face::PosY, Face::NegY, Face::NegZ],
        ),
        ("equirect", full_sphere(256, 128), Face::ALL.to_vec()),
    ];
    let city = Scene::city(10_000);
    for (name, v, expected) in cases {
        // A fresh renderer: the look-to check would rightly skip a cube map already complete.
        let mut r = SceneRenderer::new(city.clone(), Renderer::Gpu, None).unwrap();
        let size = match name {
            "flat 60" => (320, 240),
            "equirect" => (256, 128),
            _ => (256, 256),
        };
        let before = r.faces_drawn();
        let (culled, report) = r.frame(&v, &opts(size, Some(128), true, eye)).unwrap();
        let drawn: Vec<Face> = Face::ALL
            .into_iter()
            .filter(|f| report.faces[f.index()])
            .collect();
        assert_eq!(drawn, expected, "{name}");
        assert_eq!(r.faces_drawn() - before, expected.len() as u64, "{name}");
        // The skipped faces hold magenta; an output identical to the all-faces render proves
        // no pixel needed them.
        let (all, _) = r.frame(&v, &opts(size, Some(128), false, eye)).unwrap();
        assert!(culled.data == all.data, "{name}: CMF changed the output");
        // And each drawn face is needed: the sampled set from the normal map is the same.
        let map = NormalMap::from_view(&v, size.0, size.1).unwrap();
        assert_eq!(faces_sampled(&map, 128), report.faces, "{name}");
        // The CPU reference casts the same faces (so `bench gpu` compares equal work), and
        // its output does not change either.
        let mut c = SceneRenderer::new(city.clone(), Renderer::Cpu, None).unwrap();
        let (cpu_culled, cpu) = c.frame(&v, &opts(size, Some(128), true, eye)).unwrap();
        assert_eq!(cpu.faces, report.faces, "{name}: faces the CPU casts");
        let (cpu_all, _) = c.frame(&v, &opts(size, Some(128), false, eye)).unwrap();
        assert!(
            cpu_culled.data == cpu_all.data,
            "{name}: CMF changed the CPU output"
        );
    }
}

#[test]
fn an_unchanged_eye_and_scene_skip_the_cube_update() {
    let mut r = SceneRenderer::new(Scene::city(10_000), Renderer::Gpu, None).unwrap();
    let v = full_sphere(128, 64);
    let eye = DVec3::new(0.0, 1.7, 0.0);
    let (a, first) = r.frame(&v, &opts((128, 64), Some(64), true, eye)).unwrap();
    let drawn = r.faces_drawn();
    let (b, second) = r.frame(&v, &opts((128, 64), Some(64), true, eye)).unwrap();
    assert!(first.cube_updated && !second.cube_updated);
    assert_eq!((r.faces_drawn(), a.data == b.data), (drawn, true));
    let (_, moved) = r
        .frame(&v, &opts((128, 64), Some(64), true, eye + DVec3::X))
        .unwrap();
    assert!(moved.cube_updated && r.faces_drawn() == drawn + 6);
}

#[test]
fn face_size_follows_the_output_and_can_be_forced() {
    let mut r = SceneRenderer::new(Scene::city(10_000), Renderer::Gpu, None).unwrap();
    let eye = DVec3::new(0.0, 1.7, 0.0);
    let cyl = |w: u32, h: u32| {
        view(
            "cylindrical",
            Params {
                hfov: Some(270.0),
                vfov: Some(90.0),
                ..Params::default()
            },
            w,
            h,
        )
    };
    let (_, small) = r
        .frame(&cyl(400, 150), &opts((400, 150), None, true, eye))
        .unwrap();
    let (_, large) = r
        .frame(&cyl(1600, 600), &opts((1600, 600), None, true, eye))
        .unwrap();
    eprintln!(
        "face sizes: {} for 400 px, {} for 1600 px",
        small.face, large.face
    );
    assert!(
        large.face >= 3 * small.face && large.face <= 5 * small.face,
        "{} vs {}",
        small.face,
        large.face
    );
    let (_, forced) = r
        .frame(&cyl(400, 150), &opts((400, 150), Some(96), true, eye))
        .unwrap();
    assert_eq!(forced.face, 96);
    assert!(
        r.frame(&cyl(400, 150), &opts((400, 150), Some(4), true, eye))
            .is_err()
    );
}

#[test]
fn scenes_load_from_gltf_and_obj_and_bad_ones_say_why() {
    let dir = tempfile::tempdir().unwrap();
    // One red triangle, moved 2 m along −z by its node.
    let positions: Vec<u8> = [[-1.0f32, -1.0, 0.0], [1.0, -1.0, 0.0], [0.0, 1.0, 0.0]]
        .iter()
        .flatten()
        .flat_map(|v| v.to_le_bytes())
        .collect();
    let b64 = {
        const T: &[u8] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
        positions
            .chunks(3)
            .flat_map(|c| {
                let n = (u32::from(c[0]) << 16)
                    | (u32::from(*c.get(1).unwrap_or(&0)) << 8)
                    | u32::from(*c.get(2).unwrap_or(&0));
                let k = c.len() + 1;
                (0..4).map(move |i| {
                    if i < k {
                        T[(n >> (18 - 6 * i) & 63) as usize] as char
                    } else {
                        '='
                    }
                })
            })
            .collect::<String>()
    };
    let gltf = serde_json::json!({
        "asset": {"version": "2.0"},
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": [{"mesh": 0, "translation": [0.0, 0.0, -2.0]}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "material": 0}]}],
        "materials": [{"pbrMetallicRoughness": {"baseColorFactor": [1.0, 0.0, 0.0, 1.0]}}],
        "buffers": [{"byteLength": 36, "uri": format!("data:application/octet-stream;base64,{b64}")}],
        "bufferViews": [{"buffer": 0, "byteLength": 36}],
        "accessors": [{"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3", "min": [-1.0, -1.0, 0.0], "max": [1.0, 1.0, 0.0]}]
    });
    let path = dir.path().join("tri.gltf");
    std::fs::write(&path, gltf.to_string()).unwrap();
    let s = Scene::load(path.to_str().unwrap()).unwrap();
    assert_eq!((s.triangles(), s.colors[0]), (1, [255, 0, 0, 255]));
    assert_eq!(s.positions[2], [0.0, 1.0, -2.0]);
    // Straight ahead through it: red (shaded), on the GPU as on the CPU.
    for renderer in [Renderer::Gpu, Renderer::Cpu] {
        let mut r = SceneRenderer::new(s.clone(), renderer, None).unwrap();
        let v = view(
            "flat",
            Params {
                hfov: Some(40.0),
                ..Params::default()
            },
            64,
            64,
        );
        let (img, _) = r
            .frame(&v, &opts((64, 64), Some(64), true, DVec3::ZERO))
            .unwrap();
        let c = img.data[32 * 64 + 32];
        assert!(c[0] > 100 && c[1] < 20 && c[2] < 20, "{renderer:?}: {c:?}");
    }

    let obj = dir.path().join("quad.obj");
    std::fs::write(&obj, "v 0 0 -1\nv 1 0 -1\nv 1 1 -1\nv 0 1 -1\nf 1 2 3 4\n").unwrap();
    assert_eq!(Scene::load(obj.to_str().unwrap()).unwrap().triangles(), 2);

    let bad_obj = dir.path().join("bad.obj");
    std::fs::write(&bad_obj, "v 0 0\nf 1 2 3\n").unwrap();
    let broken = dir.path().join("broken.gltf");
    std::fs::write(&broken, "{ not json").unwrap();
    for (spec, expect) in [
        (bad_obj.to_str().unwrap().to_string(), "line 1"),
        (broken.to_str().unwrap().to_string(), "broken.gltf"),
        (
            dir.path().join("missing.glb").to_str().unwrap().to_string(),
            "missing.glb",
        ),
        ("city:huge".to_string(), "city:small"),
        ("scene.fbx".to_string(), ".gltf"),
    ] {
        let err = Scene::load(&spec)
            .err()
            .unwrap_or_else(|| panic!("{spec} loaded"))
            .to_string();
        assert!(err.contains(expect), "{spec}: {err}");
    }
}

#[test]
fn the_cpu_blur_matches_the_gpu_blur() {
    let v = full_sphere(256, 128);
    let eye = DVec3::new(0.0, 1.7, 0.0);
    let mut o = opts((256, 128), Some(128), true, eye);
    o.blur = Some(omniwarp::render::blur::Blur {
        strength: 0.25,
        samples: 8,
    });
    let mut out: Vec<Raster<[u8; 4]>> = Vec::new();
    for renderer in [Renderer::Gpu, Renderer::Cpu] {
        let mut r = SceneRenderer::new(Scene::city(10_000), renderer, None).unwrap();
        out.push(r.frame(&v, &o).unwrap().0);
    }
    let db = psnr(&out[0], &out[1], 255.0, |_, _| true);
    eprintln!("blurred city, GPU vs CPU: {db:.1} dB");
    // Measured 67.0 dB.
    assert!(db > 64.0, "{db} dB");
}
