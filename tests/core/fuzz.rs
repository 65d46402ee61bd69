//! Property-based fuzzing of every parser and validator a client or a file reaches: rig JSON,
//! tile screens and edits, content canvases, calibration bodies, lens model names, OpenCV and
//! mrcal lens files, PFM, Bourke meshes, MPCDI packages and OBJ files. Inputs are valid seeds
//! with fields replaced by extreme values, removed, or bytes flipped and cut. Each property
//! asserts that nothing panics, that what is accepted holds no NaN where NaN is not allowed, and
//! — through a counting allocator — that no single allocation passes what the limits allow.

use omniwarp::calibration::CorrespondencesDoc;
use omniwarp::rig::{Rig, RigDoc};
use omniwarp::server::Canvas;
use omniwarp::tiles::TileScreen;
use omniwarp::tiles::edit::Edit;
use proptest::prelude::*;
use proptest::test_runner::{Config, RngSeed};
use serde_json::Value;
use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;
use std::path::Path;

/// The system allocator, recording the largest single request per thread.
struct Counting;

thread_local! {
    static LARGEST: Cell<usize> = const { Cell::new(0) };
}

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        LARGEST.with(|l| l.set(l.get().max(layout.size())));
        unsafe { System.alloc(layout) }
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        unsafe { System.dealloc(ptr, layout) }
    }

    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        LARGEST.with(|l| l.set(l.get().max(new_size)));
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static ALLOC: Counting = Counting;

/// The largest single allocation any input may cause: the biggest thing a limit allows here
/// is an export-sized buffer.
const MOST: usize = omniwarp::limits::EXPORT_BYTES;

/// Runs `f`, then checks its largest allocation.
fn bounded<T>(what: &str, f: impl FnOnce() -> T) -> T {
    LARGEST.with(|l| l.set(0));
    let out = f();
    let largest = LARGEST.with(Cell::get);
    assert!(largest <= MOST, "{what}: one allocation of {largest} bytes");
    out
}

/// 300 cases per property from a fixed seed, so CI is repeatable; a longer hunt on demand:
/// `PROPTEST_CASES=20000 FUZZ_SEED=$RANDOM cargo test --release --test fuzz`.
fn config() -> Config {
    let env = |name: &str| std::env::var(name).ok().and_then(|v| v.parse().ok());
    Config {
        cases: env("PROPTEST_CASES").map_or(300, |c: u64| c as u32),
        failure_persistence: None,
        rng_seed: RngSeed::Fixed(env("FUZZ_SEED").unwrap_or(13)),
        ..Config::default()
    }
}

fn root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

/// Values that break naive code: huge, tiny, negative, wrong types.
fn hostile_value() -> impl Strategy<Value = Value> {
    prop_oneof![
        Just(serde_json::json!(0)),
        Just(serde_json::json!(-1)),
        Just(serde_json::json!(1e308)),
        Just(serde_json::json!(-1e308)),
        Just(serde_json::json!(1e-300)),
        Just(serde_json::json!(4_294_967_295u64)),
        Just(serde_json::json!(u64::MAX)),
        Just(serde_json::json!(1u64 << 63)),
        Just(serde_json::json!(i64::MIN)),
        Just(serde_json::json!(0.5)),
        Just(serde_json::json!("")),
        Just(serde_json::json!(
            "LENSMODEL_SPLINED_STEREOGRAPHIC_order=3_Nx=99999_Ny=99999_fov_x_deg=100"
        )),
        Just(serde_json::json!([])),
        Just(serde_json::json!({})),
        Just(Value::Null),
        Just(serde_json::json!(true)),
        any::<f64>()
            .prop_filter("finite", |v| v.is_finite())
            .prop_map(|v| serde_json::json!(v)),
        any::<i64>().prop_map(|v| serde_json::json!(v)),
    ]
}

/// Every path to a value in `v`.
fn paths(v: &Value, at: Vec<String>, out: &mut Vec<Vec<String>>) {
    out.push(at.clone());
    match v {
        Value::Object(m) => {
            for (k, x) in m {
                let mut p = at.clone();
                p.push(k.clone());
                paths(x, p, out);
            }
        }
        Value::Array(a) => {
            for (i, x) in a.iter().enumerate() {
                let mut p = at.clone();
                p.push(i.to_string());
                paths(x, p, out);
            }
        }
        _ => {}
    }
}

fn at_mut<'a>(v: &'a mut Value, path: &[String]) -> Option<&'a mut Value> {
    path.iter().try_fold(v, |v, k| match v {
        Value::Object(m) => m.get_mut(k),
        Value::Array(a) => a.get_mut(k.parse::<usize>().ok()?),
        _ => None,
    })
}

/// A JSON mutation: replace the value at the n-th path (modulo their count), or remove it.
#[derive(Debug, Clone)]
enum Mutation {
    Replace(usize, Value),
    Remove(usize),
}

fn mutation() -> impl Strategy<Value = Mutation> {
    prop_oneof![
        4 => (any::<usize>(), hostile_value()).prop_map(|(n, v)| Mutation::Replace(n, v)),
        1 => any::<usize>().prop_map(Mutation::Remove),
    ]
}

fn mutate(seed: &Value, ms: &[Mutation]) -> Value {
    let mut v = seed.clone();
    for m in ms {
        let mut all = Vec::new();
        paths(&v, Vec::new(), &mut all);
        match m {
            Mutation::Replace(n, x) => {
                if let Some(slot) = at_mut(&mut v, &all[n % all.len()]) {
                    *slot = x.clone();
                }
            }
            Mutation::Remove(n) => {
                let p = &all[n % all.len()];
                if let Some((last, parent)) = p.split_last()
                    && let Some(container) = at_mut(&mut v, parent)
                {
                    match container {
                        Value::Object(m) => {
                            m.remove(last);
                        }
                        Value::Array(a) => {
                            if let Ok(i) = last.parse::<usize>()
                                && i < a.len()
                            {
                                a.remove(i);
                            }
                        }
                        _ => {}
                    }
                }
            }
        }
    }
    v
}

/// Byte damage: flip, insert or cut at positions taken modulo the length.
fn damage(seed: &[u8], edits: &[(usize, u8, u8)]) -> Vec<u8> {
    let mut b = seed.to_vec();
    for &(at, byte, kind) in edits {
        if b.is_empty() {
            break;
        }
        let i = at % b.len();
        match kind % 4 {
            0 => b[i] = byte,
            1 => b.insert(i, byte),
            2 => b.truncate(i),
            _ => b[i] ^= 1 << (byte % 8),
        }
    }
    b
}

fn byte_edits() -> impl Strategy<Value = Vec<(usize, u8, u8)>> {
    prop::collection::vec((any::<usize>(), any::<u8>(), any::<u8>()), 1..6)
}

fn seed_json(rel: &str) -> Value {
    serde_json::from_str(&std::fs::read_to_string(root().join(rel)).unwrap()).unwrap()
}

fn no_nan_in(v: &Value) -> bool {
    match v {
        Value::Number(n) => n.as_f64().is_none_or(f64::is_finite),
        Value::Array(a) => a.iter().all(no_nan_in),
        Value::Object(m) => m.values().all(no_nan_in),
        _ => true,
    }
}

proptest! {
    #![proptest_config(config())]

    #[test]
    fn rig_documents(seed in 0usize..3, ms in prop::collection::vec(mutation(), 1..4)) {
        let file = ["calibration/rigs/cylinder-270-3proj.json", "calibration/rigs/dome-180-tilt15-5proj.json", "calibration/rigs/flat-2proj.json"][seed];
        let doc = mutate(&seed_json(file), &ms);
        let text = doc.to_string();
        let accepted = bounded("rig", || {
            RigDoc::parse(&text).and_then(|d| {
                let rig = Rig::from_doc(d)?;
                rig.check_budget(omniwarp::limits::MEMORY_BUDGET)?;
                Ok(rig)
            })
        });
        if let Ok(rig) = accepted {
            prop_assert!(no_nan_in(&serde_json::to_value(&rig.doc).unwrap()));
            // A warp pixel of every channel, computed: nothing the validation let in breaks it.
            for ch in &rig.channels {
                let _ = bounded("rig warp point", || rig.wall_point(ch, [0.0, 0.0]));
            }
        }
    }

    #[test]
    fn content_canvases(ms in prop::collection::vec(mutation(), 1..4)) {
        let seed = serde_json::to_value(Canvas::default()).unwrap();
        let text = mutate(&seed, &ms).to_string();
        let parsed: Result<Canvas, _> = serde_json::from_str(&text);
        if let Ok(c) = parsed
            && let Ok(view) = bounded("canvas", || c.view())
        {
            let d = view.direction(0.25, -0.5);
            if let Ok(d) = d {
                prop_assert!(d.is_finite());
            }
        }
    }

    #[test]
    fn tile_screens_and_edits(
        ms in prop::collection::vec(mutation(), 0..3),
        edits in prop::collection::vec(edit(), 1..6),
    ) {
        let seed = serde_json::to_value(screen()).unwrap();
        let text = mutate(&seed, &ms).to_string();
        let Ok(mut t) = serde_json::from_str::<TileScreen>(&text) else { return Ok(()); };
        if bounded("screen validate", || t.validate()).is_err() {
            return Ok(());
        }
        for e in &edits {
            if let Ok(next) = bounded("edit", || t.edit(e)) {
                prop_assert!(next.validate().is_ok(), "an edit left an invalid screen: {e:?}");
                prop_assert!(no_nan_in(&serde_json::to_value(&next).unwrap()));
                t = next;
            }
        }
    }

    #[test]
    fn calibration_bodies(ms in prop::collection::vec(mutation(), 1..4)) {
        let mut seed = seed_json("calibration/examples/points.json");
        seed["points"].as_array_mut().unwrap().truncate(24);
        let text = mutate(&seed, &ms).to_string();
        let Ok(doc) = serde_json::from_str::<CorrespondencesDoc>(&text) else { return Ok(()); };
        let Ok((problem, choice)) = bounded("calibration body", || doc.problem([1920, 1080], None)) else {
            return Ok(());
        };
        if let Ok(cal) = bounded("calibration", || omniwarp::calibration::calibrate(&problem, choice)) {
            prop_assert!(cal.fit.rms.is_finite());
        }
    }

    #[test]
    fn lens_model_names(
        parts in prop::collection::vec((0usize..12, any::<u32>()), 1..6),
        spline in (0u32..5, knots(), knots(), any::<u32>()),
        structured in any::<bool>(),
    ) {
        let name = if structured {
            let (order, nx, ny, fov) = spline;
            format!("LENSMODEL_SPLINED_STEREOGRAPHIC_order={order}_Nx={nx}_Ny={ny}_fov_x_deg={}", fov % 400)
        } else {
            let words = ["LENSMODEL_", "SPLINED_STEREOGRAPHIC_", "order=", "_Nx=", "_Ny=", "_fov_x_deg=", "OPENCV", "CAHVOR", "PINHOLE", "=", "_", "LENSMODEL_SPLINED_STEREOGRAPHIC_order="];
            parts
                .iter()
                .map(|&(w, n)| format!("{}{}", words[w], if n % 3 == 0 { n.to_string() } else { String::new() }))
                .collect()
        };
        if let Ok(m) = bounded("lens model", || name.parse::<omniwarp::lens::LensModel>()) {
            let n = bounded("intrinsics names", || m.intrinsics_names().len());
            prop_assert_eq!(n, m.intrinsics_len());
        }
    }

    #[test]
    fn lens_files(which in 0usize..3, edits in byte_edits()) {
        let dir = tempfile::tempdir().unwrap();
        let (name, seed) = match which {
            0 => ("c.yml", std::fs::read(root().join("calibration/fixtures/lens/opencv8_camera.yml")).unwrap()),
            1 => ("c.json", std::fs::read(root().join("calibration/fixtures/lens/opencv8_camera.json")).unwrap()),
            _ => ("c.cameramodel", CAMERAMODEL.as_bytes().to_vec()),
        };
        let path = dir.path().join(name);
        std::fs::write(&path, damage(&seed, &edits)).unwrap();
        if which < 2 {
            if let Ok(lens) = bounded("opencv file", || omniwarp::lens::files::read_opencv(&path, false)) {
                prop_assert!(lens.intrinsics().iter().all(|v| v.is_finite()));
            }
        } else {
            let _ = bounded("cameramodel", || omniwarp::lens::files::read_cameramodel(&path));
        }
    }

    #[test]
    fn pfm_files(edits in byte_edits()) {
        let rows: Vec<[f32; 3]> = (0..12).map(|i| [i as f32, 2.0 * i as f32, f32::NAN]).collect();
        let seed = omniwarp::export::pfm_bytes(4, 3, &rows).unwrap();
        if let Ok((w, h, px)) = bounded("pfm", || omniwarp::export::parse_pfm(&damage(&seed, &edits), "x.pfm")) {
            prop_assert_eq!(px.len(), w * h);
        }
    }

    #[test]
    fn bourke_meshes(edits in byte_edits(), dims in (any::<u32>(), any::<u32>())) {
        let seed = "2\n3 2\n-1 -1 0 0 1\n0 -1 0.5 0 1\n1 -1 1 0 1\n-1 1 0 1 1\n0 1 0.5 1 1\n1 1 1 1 -1\n";
        let _ = bounded("bourke", || omniwarp::export::bourke::read_mesh(&String::from_utf8_lossy(&damage(seed.as_bytes(), &edits))));
        let claimed = format!("2\n{} {}\n0 0 0 0 1\n", dims.0, dims.1);
        prop_assert!(bounded("bourke dims", || omniwarp::export::bourke::read_mesh(&claimed)).is_err() || dims.0 as u64 * dims.1 as u64 == 1);
    }

    #[test]
    fn mpcdi_packages(edits in byte_edits()) {
        let seed = mpcdi_seed();
        let _ = bounded("mpcdi", || omniwarp::export::mpcdi::read(&damage(&seed, &edits)));
    }

    #[test]
    fn obj_files(edits in byte_edits(), count in any::<u32>()) {
        let seed = "v -3 -2 -3\nv 3 -2 -3\nv 3 2 -3\nv -3 2 -3\nf 1 2 3 4\nf -1 -2 -3\n";
        let text = String::from_utf8_lossy(&damage(seed.as_bytes(), &edits)).into_owned();
        if let Ok(tris) = bounded("obj", || omniwarp::surface::parse_obj_triangles(&text)) {
            prop_assert!(tris.len() <= omniwarp::limits::MESH_TRIANGLES);
        }
        // A face with a huge index refers to no vertex.
        let far = format!("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 {count}\n");
        let r = omniwarp::surface::parse_obj_triangles(&far);
        prop_assert!(r.is_ok() == (1..=3).contains(&count));
    }
}

const CAMERAMODEL: &str = "{ 'lensmodel': 'LENSMODEL_OPENCV4', 'intrinsics': [ 1000., 1000., 959.5, 539.5, 0.01, -0.02, 0.001, 0.0005, ], 'imagersize': [ 1920, 1080, ], 'extrinsics': [ 0., 0., 0., 0., 0., 0., ], }\n";

/// A small tile screen: a 90° perspective view on a 5×4 grid.
fn screen() -> TileScreen {
    omniwarp::tiles::build::grid_of(5, 4, |s, t| {
        let d = glam::DVec3::new(s, t, -1.0).normalize();
        (Some(d), 1.0)
    })
    .unwrap()
}

/// Spline knot counts: ordinary, at the limit, and far past it.
fn knots() -> impl Strategy<Value = u32> {
    prop_oneof![
        2u32..40,
        Just(omniwarp::limits::SPLINE_KNOTS_SIDE),
        Just(u32::MAX),
        any::<u32>()
    ]
}

fn hostile_index() -> impl Strategy<Value = usize> {
    prop_oneof![
        0usize..8,
        Just(usize::MAX),
        Just(1usize << 40),
        any::<usize>()
    ]
}

fn edit() -> impl Strategy<Value = Edit> {
    let angle = || {
        prop_oneof![
            Just(None),
            (-400.0f64..400.0).prop_map(Some),
            Just(Some(f64::MAX)),
            Just(Some(-1e-300))
        ]
    };
    prop_oneof![
        (
            hostile_index(),
            hostile_index(),
            angle(),
            angle(),
            angle(),
            angle()
        )
            .prop_map(|(column, row, phi, theta, scale, f)| Edit::SetFeature {
                column,
                row,
                phi,
                theta,
                scale,
                f
            }),
        hostile_index().prop_map(|at| Edit::InsertRow { at }),
        hostile_index().prop_map(|at| Edit::InsertColumn { at }),
        hostile_index().prop_map(|at| Edit::RemoveRow { at }),
        hostile_index().prop_map(|at| Edit::RemoveColumn { at }),
        prop_oneof![0usize..20, Just(usize::MAX)]
            .prop_map(|iterations| Edit::Smooth { iterations }),
        Just(Edit::Reset),
    ]
}

fn mpcdi_seed() -> Vec<u8> {
    use omniwarp::export::mpcdi::{Header, Profile, Reader, Region, Version, package};
    let (w, h) = (8u32, 6u32);
    let alpha = omniwarp::rig::blend_png_bytes(
        w,
        h,
        &vec![1.0f32; (w * h) as usize],
        omniwarp::rig::BlendOptions::default(),
    )
    .unwrap();
    let samples: Vec<[f32; 3]> = (0..6).map(|i| [i as f32 / 6.0, 0.5, f32::NAN]).collect();
    let region = Region {
        id: "a".into(),
        resolution: [w, h],
        buffer: 0,
        rect: [0.25, 0.5, 0.5, 0.25],
        warp: (3, 2, samples),
        alpha_png: alpha,
        beta_png: None,
        alpha_bits: 16,
    };
    let header = Header {
        version: Version::V2,
        profile: Profile::TwoD,
        reader: Reader::Vesa,
        buffers: vec![[32, 24]],
        unix_time: 0,
    };
    package(&header, &[region]).unwrap()
}
