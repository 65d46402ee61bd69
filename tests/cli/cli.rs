//! The `omniwarp` command end to end: good runs write their files, bad flags fail with the flag
//! named, a non-zero exit and no output file.

use image::GenericImageView;
use std::path::{Path, PathBuf};
use std::process::Command;

fn omniwarp(dir: &Path, args: &[&str]) -> (bool, String) {
    let (code, err) = status(dir, args);
    (code == Some(0), err)
}

/// The exit status of a run, and what it printed on stderr.
fn status(dir: &Path, args: &[&str]) -> (Option<i32>, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_omniwarp"))
        .current_dir(dir)
        .args(args)
        .output()
        .unwrap();
    (
        out.status.code(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

struct Scene {
    dir: tempfile::TempDir,
}

impl Scene {
    /// A directory holding a small equirect pattern, `eq.png`.
    fn new() -> Self {
        let dir = tempfile::tempdir().unwrap();
        let (ok, err) = omniwarp(
            dir.path(),
            &["pattern", "--size", "128x64", "--out", "eq.png"],
        );
        assert!(ok, "{err}");
        Scene { dir }
    }

    fn run(&self, args: &[&str]) -> (bool, String) {
        omniwarp(self.dir.path(), args)
    }

    fn path(&self, name: &str) -> PathBuf {
        self.dir.path().join(name)
    }
}

const EQ: [&str; 4] = ["--content", "eq.png", "--content-format", "equirect"];

fn render(extra: &[&str]) -> Vec<String> {
    let mut v: Vec<String> = ["render"]
        .iter()
        .chain(EQ.iter())
        .map(|s| s.to_string())
        .collect();
    v.extend(extra.iter().map(|s| s.to_string()));
    v
}

fn strs(v: &[String]) -> Vec<&str> {
    v.iter().map(String::as_str).collect()
}

#[test]
fn render_normal_map_and_cube_layouts_work_end_to_end() {
    let s = Scene::new();
    let cyl = render(&[
        "--projection",
        "cylindrical",
        "--hfov",
        "270",
        "--vfov",
        "90",
        "--size",
        "96x48",
        "--out",
        "cyl.png",
    ]);
    let (ok, err) = s.run(&strs(&cyl));
    assert!(ok, "{err}");
    let (ok, err) = s.run(&[
        "normal-map",
        "--projection",
        "cylindrical",
        "--hfov",
        "270",
        "--vfov",
        "90",
        "--size",
        "96x48",
        "--out",
        "cyl.exr",
    ]);
    assert!(ok, "{err}");
    let via_map = render(&["--normal-map", "cyl.exr", "--out", "cyl-map.png"]);
    let (ok, err) = s.run(&strs(&via_map));
    assert!(ok, "{err}");
    let a = image::open(s.path("cyl.png")).unwrap().to_rgba8();
    let b = image::open(s.path("cyl-map.png")).unwrap().to_rgba8();
    assert_eq!(a.dimensions(), (96, 48));
    let worst = a
        .pixels()
        .zip(b.pixels())
        .flat_map(|(p, q)| (0..4).map(move |k| p.0[k].abs_diff(q.0[k])))
        .max();
    assert!(worst <= Some(1), "normal-map render differs by {worst:?}");

    let (ok, err) = s.run(&[
        "cubemap",
        "--content",
        "eq.png",
        "--content-format",
        "equirect",
        "--face-size",
        "32",
        "--layout",
        "c3x2",
        "--out",
        "cube.png",
    ]);
    assert!(ok, "{err}");
    assert_eq!(
        image::image_dimensions(s.path("cube.png")).unwrap(),
        (96, 64)
    );
    let (ok, err) = s.run(&[
        "render",
        "--content",
        "cube.png",
        "--content-format",
        "cubemap-c3x2",
        "--projection",
        "fisheye",
        "--fov",
        "180",
        "--filter",
        "bicubic",
        "--supersample",
        "2",
        "--size",
        "40x40",
        "--out",
        "fish.exr",
    ]);
    assert!(ok, "{err}");
    assert!(s.path("fish.exr").exists());
    let (ok, err) = s.run(&[
        "cubemap",
        "--content",
        "eq.png",
        "--content-format",
        "equirect",
        "--face-size",
        "8",
        "--layout",
        "faces",
        "--out",
        "face-{face}.png",
    ]);
    assert!(ok, "{err}");
    for f in ["px", "nx", "py", "ny", "pz", "nz"] {
        assert!(s.path(&format!("face-{f}.png")).exists(), "{f}");
    }
    // Six faces back in, and the strip layout out and in again, give the same render.
    let (ok, err) = s.run(&[
        "cubemap",
        "--content",
        "face-{face}.png",
        "--content-format",
        "cubemap-faces",
        "--face-size",
        "8",
        "--layout",
        "strip",
        "--filter",
        "nearest",
        "--out",
        "strip.png",
    ]);
    assert!(ok, "{err}");
    let strip = image::open(s.path("strip.png")).unwrap().to_rgba8();
    let px = image::open(s.path("face-px.png")).unwrap().to_rgba8();
    assert_eq!(strip.dimensions(), (48, 8));
    assert_eq!(strip.view(0, 0, 8, 8).to_image(), px);
}

#[test]
fn bad_input_names_the_flag_and_leaves_no_file() {
    let s = Scene::new();
    let table = std::fs::read_to_string(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/cli/refusals.txt"),
    )
    .unwrap();
    let mut cases = 0;
    for line in table
        .lines()
        .filter(|l| !l.is_empty() && !l.starts_with('#'))
    {
        let (args, said) = line
            .split_once(" | ")
            .expect("`arguments | words` on every line");
        let root = env!("CARGO_MANIFEST_DIR");
        let args: Vec<String> = args
            .split_whitespace()
            .map(|a| a.replace("$ROOT", root))
            .collect();
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        let (ok, err) = s.run(&args);
        assert!(!ok, "{line}: succeeded");
        for word in said.split_whitespace() {
            assert!(err.contains(word), "{line}: `{err}` does not say {word}");
        }
        let names: Vec<_> = std::fs::read_dir(s.dir.path())
            .unwrap()
            .map(|e| e.unwrap().file_name())
            .collect();
        assert_eq!(names, ["eq.png"], "{line}: files left behind");
        cases += 1;
    }
    assert!(cases >= 16, "only {cases} refusals read");
}

#[test]
fn projections_lists_every_registry_row() {
    let out = Command::new(env!("CARGO_BIN_EXE_omniwarp"))
        .arg("projections")
        .output()
        .unwrap();
    let text = String::from_utf8(out.stdout).unwrap();
    for e in omniwarp::projection::REGISTRY {
        assert!(text.contains(e.name), "{} missing", e.name);
    }
}

#[test]
fn tile_screens_from_the_command_line() {
    let s = Scene::new();
    let (ok, err) = s.run(&[
        "tiles",
        "from-projection",
        "--projection",
        "fisheye",
        "--fov",
        "180",
        "--size",
        "64x64",
        "--tolerance-px",
        "0.5",
        "--out",
        "fish.json",
    ]);
    assert!(ok, "{err}");
    let json = std::fs::read_to_string(s.path("fish.json")).unwrap();
    assert!(
        json.contains("\"format\": 1") && json.contains("\"vectors\""),
        "{json}"
    );
    let (ok, err) = s.run(&[
        "tiles",
        "normal-map",
        "fish.json",
        "--size",
        "64x64",
        "--out",
        "fish.exr",
    ]);
    assert!(ok, "{err}");
    let (ok, err) = s.run(&[
        "render",
        "--content",
        "eq.png",
        "--content-format",
        "equirect",
        "--tiles",
        "fish.json",
        "--size",
        "64x64",
        "--out",
        "fish.png",
    ]);
    assert!(ok, "{err}");
    let (ok, err) = s.run(&[
        "tiles",
        "from-projection",
        "--projection",
        "cylindrical",
        "--hfov",
        "270",
        "--vfov",
        "90",
        "--size",
        "64x32",
        "--grid",
        "9x5",
        "--out",
        "cyl.json",
    ]);
    assert!(ok, "{err}");
    for (args, flag) in [
        (
            vec![
                "tiles",
                "from-projection",
                "--projection",
                "flat",
                "--hfov",
                "90",
                "--size",
                "8x8",
                "--grid",
                "1x4",
                "--out",
                "bad.json",
            ],
            "grid",
        ),
        (
            vec![
                "tiles",
                "from-projection",
                "--projection",
                "flat",
                "--hfov",
                "90",
                "--size",
                "8x8",
                "--tolerance-deg",
                "-1",
                "--out",
                "bad.json",
            ],
            "--tolerance-deg",
        ),
        (
            vec![
                "tiles",
                "from-projection",
                "--projection",
                "flat",
                "--hfov",
                "190",
                "--size",
                "8x8",
                "--grid",
                "3x3",
                "--out",
                "bad.json",
            ],
            "--hfov",
        ),
        (
            vec![
                "tiles",
                "normal-map",
                "eq.png",
                "--size",
                "8x8",
                "--out",
                "bad.exr",
            ],
            "--tiles",
        ),
        (
            vec![
                "render",
                "--content",
                "eq.png",
                "--content-format",
                "equirect",
                "--tiles",
                "missing.json",
                "--size",
                "8x8",
                "--out",
                "bad.png",
            ],
            "--tiles",
        ),
    ] {
        let (ok, err) = s.run(&args);
        assert!(!ok && err.contains(flag), "{args:?}: {err}");
        assert!(
            !s.path("bad.json").exists()
                && !s.path("bad.exr").exists()
                && !s.path("bad.png").exists()
        );
    }
}

#[test]
fn lens_project_and_unproject_from_the_command_line() {
    let s = Scene::new();
    std::fs::write(
        s.path("pts.json"),
        "[[0.1, 0.2, 1.0], [0, 0, -1], [0.5, -0.3, 2.0]]",
    )
    .unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_omniwarp"))
        .current_dir(s.dir.path())
        .args([
            "lens",
            "project",
            "--model",
            "LENSMODEL_OPENCV5",
            "--intrinsics",
            "1500,1500,959.5,539.5,-0.2,0.05,0.001,-0.001,0.01",
            "--points",
            "pts.json",
        ])
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let q: Vec<Option<[f64; 2]>> = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(q.len(), 3);
    assert!(q[1].is_none(), "a point behind the camera has no pixel");
    std::fs::write(
        s.path("px.json"),
        serde_json::to_string(&[q[0].unwrap(), q[2].unwrap()]).unwrap(),
    )
    .unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_omniwarp"))
        .current_dir(s.dir.path())
        .args([
            "lens",
            "unproject",
            "--model",
            "LENSMODEL_OPENCV5",
            "--intrinsics",
            "1500,1500,959.5,539.5,-0.2,0.05,0.001,-0.001,0.01",
            "--pixels",
            "px.json",
        ])
        .output()
        .unwrap();
    let rays: Vec<Option<[f64; 3]>> = serde_json::from_slice(&out.stdout).unwrap();
    let want = glam::DVec3::new(0.1, 0.2, 1.0).normalize();
    let got = glam::DVec3::from_array(rays[0].unwrap());
    assert!(got.cross(want).length() < 1e-12, "{got} vs {want}");
    for (args, flag) in [
        (
            vec![
                "lens",
                "project",
                "--model",
                "LENSMODEL_OPENCV6",
                "--intrinsics",
                "1,1,0,0",
                "--points",
                "pts.json",
            ],
            "--model",
        ),
        (
            vec![
                "lens",
                "project",
                "--model",
                "LENSMODEL_OPENCV4",
                "--intrinsics",
                "1,1,0,0",
                "--points",
                "pts.json",
            ],
            "--intrinsics",
        ),
        (
            vec![
                "lens",
                "project",
                "--model",
                "LENSMODEL_PINHOLE",
                "--intrinsics",
                "1,1,zero,0",
                "--points",
                "pts.json",
            ],
            "--intrinsics",
        ),
        (
            vec![
                "lens",
                "project",
                "--model",
                "LENSMODEL_PINHOLE",
                "--intrinsics",
                "1,1,0,0",
                "--points",
                "missing.json",
            ],
            "--points",
        ),
        (
            vec![
                "lens",
                "unproject",
                "--model",
                "LENSMODEL_PINHOLE",
                "--intrinsics",
                "1,1,0,0",
                "--pixels",
                "pts.json",
            ],
            "--pixels",
        ),
    ] {
        let (ok, err) = s.run(&args);
        assert!(!ok && err.contains(flag), "{args:?}: {err}");
    }
}

#[test]
fn rig_warp_blend_and_render_from_the_command_line() {
    let s = Scene::new();
    let rig = Path::new(env!("CARGO_MANIFEST_DIR")).join("calibration/rigs/flat-2proj.json");
    let rig = rig.to_str().unwrap();
    let (ok, err) = s.run(&[
        "warp",
        "--rig",
        rig,
        "--channel",
        "left",
        "--out",
        "left.exr",
        "--wall",
        "left-wall.exr",
    ]);
    assert!(ok, "{err}");
    let map = omniwarp::normalmap::NormalMap::read(&s.path("left.exr")).unwrap();
    assert_eq!((map.width(), map.height()), (1920, 1080));
    assert!(
        map.attributes
            .iter()
            .any(|(k, v)| k == "omniwarp.channel" && v == "left")
    );
    // The wall points lie on the rig's plane z = −3 where the warp is valid, nowhere else,
    // and the sampling vector points from the eye to them.
    let (wall, _) = omniwarp::image_io::read_exr_rgba(&s.path("left-wall.exr")).unwrap();
    let mut lit = 0;
    for (k, p) in wall.data.iter().enumerate() {
        let d = map.direction(k % 1920, k / 1920);
        assert_eq!(p[3] > 0.5, d.is_some(), "pixel {k}");
        if let Some(d) = d {
            lit += 1;
            assert!((p[2] + 3.0).abs() < 1e-4, "pixel {k}: {p:?}");
            let to = glam::DVec3::new(f64::from(p[0]), f64::from(p[1]), f64::from(p[2]));
            // The rig's eye is the origin and the content is not turned: V ∥ P.
            assert!(d.angle_between(to) < 1e-4, "pixel {k}");
        }
    }
    assert!(lit > 1920 * 1080 / 2, "{lit} pixels light the wall");
    let (ok, err) = s.run(&["blend", "--rig", rig, "--out-dir", "blend"]);
    assert!(ok, "{err}");
    let decoder = png::Decoder::new(std::io::BufReader::new(
        std::fs::File::open(s.path("blend/right.png")).unwrap(),
    ));
    let reader = decoder.read_info().unwrap();
    let info = reader.info();
    assert_eq!(
        (info.width, info.height, info.bit_depth),
        (1920, 1080, png::BitDepth::Sixteen)
    );
    assert!(
        info.uncompressed_latin1_text
            .iter()
            .any(|t| t.keyword == "omniwarp.blend_gamma" && t.text == "2.2")
    );
    let (ok, err) = s.run(&[
        "render",
        "--rig",
        rig,
        "--channel",
        "right",
        "--content",
        "eq.png",
        "--content-format",
        "equirect",
        "--out",
        "right.png",
    ]);
    assert!(ok, "{err}");
    assert_eq!(
        image::image_dimensions(s.path("right.png")).unwrap(),
        (1920, 1080)
    );
    for (args, flag) in [
        (
            vec![
                "warp",
                "--rig",
                rig,
                "--channel",
                "middle",
                "--out",
                "bad.exr",
            ],
            "--channel",
        ),
        (
            vec![
                "warp",
                "--rig",
                "missing.json",
                "--channel",
                "left",
                "--out",
                "bad.exr",
            ],
            "--rig",
        ),
        (
            vec![
                "warp",
                "--rig",
                rig,
                "--channel",
                "left",
                "--out",
                "bad.png",
            ],
            "--out",
        ),
        (
            vec!["blend", "--rig", rig, "--out-dir", "b2", "--gamma", "0"],
            "--gamma",
        ),
    ] {
        let (ok, err) = s.run(&args);
        assert!(!ok && err.contains(flag), "{args:?}: {err}");
        assert!(!s.path("bad.exr").exists() && !s.path("bad.png").exists());
    }
}

#[test]
fn calibrate_writes_a_channel_that_drops_into_a_rig() {
    let s = Scene::new();
    // The example file the README names (the oracle's points, in the one format the CLI and
    // the daemon both read).
    std::fs::copy(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("calibration/examples/points.json"),
        s.path("c.json"),
    )
    .unwrap();
    let (ok, err) = s.run(&[
        "calibrate",
        "--correspondences",
        "c.json",
        "--model",
        "LENSMODEL_OPENCV5",
        "--id",
        "left",
        "--out",
        "left.json",
    ]);
    assert!(ok, "{err}");
    assert!(
        err.contains("chosen LENSMODEL_OPENCV5") && err.contains("warning: the focal length"),
        "{err}"
    );
    let channel = std::fs::read_to_string(s.path("left.json")).unwrap();
    let rig = format!(
        r#"{{ "format": 1, "screen": {{ "kind": "cylinder", "radius": 2.0, "height": [-2, 2] }}, "eye": [0, 0, 0], "channels": [{channel}] }}"#
    );
    let rig = omniwarp::rig::Rig::from_json(&rig, Path::new(".")).unwrap();
    let c = &rig.channels[0];
    // The calibrated projector's centre is where the oracle put it, to a few millimetres.
    assert!(
        c.position.distance(glam::DVec3::new(0.12, -0.35, -0.60)) < 0.02,
        "{}",
        c.position
    );
    for (args, flag) in [
        (
            vec![
                "calibrate",
                "--correspondences",
                "missing.json",
                "--out",
                "x.json",
            ],
            "--correspondences",
        ),
        (
            vec![
                "calibrate",
                "--correspondences",
                "c.json",
                "--model",
                "LENSMODEL_NOPE",
                "--out",
                "x.json",
            ],
            "--model",
        ),
        (
            vec![
                "calibrate",
                "--correspondences",
                "c.json",
                "--intrinsics-fixed",
                "--out",
                "x.json",
            ],
            "--intrinsics-fixed",
        ),
        (
            vec![
                "calibrate",
                "--correspondences",
                "eq.png",
                "--out",
                "x.json",
            ],
            "--correspondences",
        ),
    ] {
        let (ok, err) = s.run(&args);
        assert!(!ok && err.contains(flag), "{args:?}: {err}");
        assert!(!s.path("x.json").exists());
    }
}

#[test]
fn serve_refuses_to_listen_beyond_loopback_without_a_token() {
    let s = Scene::new();
    let (ok, err) = s.run(&["serve", "--demo", "--bind", "0.0.0.0:0"]);
    assert!(
        !ok && err.contains("--bind") && err.contains("--token-file"),
        "{err}"
    );
    std::fs::write(s.path("token"), "short").unwrap();
    let (ok, err) = s.run(&[
        "serve",
        "--demo",
        "--bind",
        "0.0.0.0:0",
        "--token-file",
        "token",
    ]);
    assert!(!ok && err.contains("--token-file"), "{err}");
    let (ok, err) = s.run(&["serve", "--bind", "127.0.0.1:0", "--data", "empty"]);
    assert!(
        !ok && err.contains("--data") && err.contains("--demo"),
        "{err}"
    );
}

#[test]
fn export_writes_stmap_pfm_and_remap_maps() {
    let s = Scene::new();
    let rig = Path::new(env!("CARGO_MANIFEST_DIR")).join("calibration/rigs/flat-2proj.json");
    let rig = rig.to_str().unwrap();
    let canvas = [
        "--projection",
        "flat",
        "--hfov",
        "100",
        "--content-size",
        "1920x1080",
    ];
    let mut st = vec![
        "export",
        "--rig",
        rig,
        "--channel",
        "left",
        "--format",
        "stmap",
        "--out",
        "st.exr",
    ];
    st.extend(canvas);
    let (ok, err) = s.run(&st);
    assert!(ok, "{err}");
    let (ok, err) = s.run(&[
        "export",
        "--rig",
        rig,
        "--channel",
        "left",
        "--format",
        "pfm-a3",
        "--out",
        "a3.pfm",
    ]);
    assert!(ok, "{err}");
    let (w, h, xyz) = omniwarp::export::read_pfm(&s.path("a3.pfm")).unwrap();
    assert_eq!((w, h), (1920, 1080));
    // The wall is the plane z = −3; the left projector lights 77.0 % of its pixels on it.
    let lit: Vec<_> = xyz.iter().filter(|p| !p[2].is_nan()).collect();
    assert!(
        lit.len() * 10 > xyz.len() * 7,
        "{} of {} lit",
        lit.len(),
        xyz.len()
    );
    assert!(lit.iter().all(|p| (p[2] + 3.0).abs() < 1e-4));
    let mut rm = vec![
        "export",
        "--rig",
        rig,
        "--channel",
        "left",
        "--format",
        "remap",
        "--out",
        "x.pgm",
    ];
    rm.extend(canvas);
    let (ok, err) = s.run(&rm);
    assert!(!ok && err.contains("--ymap"), "{err}");
    rm.extend(["--ymap", "y.pgm"]);
    let (ok, err) = s.run(&rm);
    assert!(ok, "{err}");
    // The ST-map and the remap maps say the same: x = u·W − ½, y = (1 − v_st)·H − ½, rounded,
    // and both are unmapped in the same places; most of the projector shows content.
    let (st, _) = omniwarp::image_io::read_exr_rgba(&s.path("st.exr")).unwrap();
    let (xmap, ymap) = (pgm16(&s.path("x.pgm")), pgm16(&s.path("y.pgm")));
    assert_eq!((st.width, st.height), (1920, 1080));
    assert_eq!((xmap.len(), ymap.len()), (1920 * 1080, 1920 * 1080));
    let mut mapped = 0;
    for ((p, &x), &y) in st.data.iter().zip(&xmap).zip(&ymap) {
        if p[3] == 0.0 {
            assert_eq!((x, y), (65535, 65535));
            continue;
        }
        mapped += 1;
        let ex = (f64::from(p[0]) * 1920.0 - 0.5).round().clamp(0.0, 1919.0);
        let ey = ((1.0 - f64::from(p[1])) * 1080.0 - 0.5)
            .round()
            .clamp(0.0, 1079.0);
        assert!((f64::from(x) - ex).abs() <= 1.0 && (f64::from(y) - ey).abs() <= 1.0);
    }
    assert!(mapped > 1920 * 1080 / 2, "{mapped} pixels mapped");
    let (ok, err) = s.run(&[
        "export",
        "--rig",
        rig,
        "--channel",
        "left",
        "--format",
        "stmap",
        "--projection",
        "flat",
        "--hfov",
        "100",
        "--out",
        "bad.exr",
    ]);
    assert!(
        !ok && err.contains("--content-size") && !s.path("bad.exr").exists(),
        "{err}"
    );
}

#[test]
fn export_writes_meshes_2d_grids_and_mpcdi_packages() {
    let s = Scene::new();
    let rig = Path::new(env!("CARGO_MANIFEST_DIR")).join("calibration/rigs/flat-2proj.json");
    let rig = rig.to_str().unwrap();
    let canvas = [
        "--projection",
        "flat",
        "--hfov",
        "100",
        "--content-size",
        "1920x1080",
    ];
    let run = |format: &str, out: &str, extra: &[&str]| {
        let mut args = vec!["export", "--rig", rig, "--format", format, "--out", out];
        args.extend(canvas);
        args.extend(extra);
        s.run(&args)
    };
    let (ok, err) = run(
        "mesh",
        "left.data",
        &["--channel", "left", "--tolerance", "1"],
    );
    assert!(ok, "{err}");
    let mesh =
        omniwarp::export::bourke::read_mesh(&std::fs::read_to_string(s.path("left.data")).unwrap())
            .unwrap();
    assert!(
        mesh.nx > 2 && mesh.nx < 1921 && err.contains("worst error"),
        "{err}"
    );
    let (ok, err) = run("pfm2d", "left.pfm", &["--channel", "left"]);
    assert!(ok, "{err}");
    // A grid coarser than the projector, of canvas coordinates in [0, 1] where the wall is lit.
    let (gw, gh, xy) = omniwarp::export::read_pfm(&s.path("left.pfm")).unwrap();
    let valid: Vec<_> = xy.iter().filter(|p| !p[0].is_nan()).collect();
    assert!(gw > 2 && gw < 1920 && gh > 2 && gh < 1080, "{gw}×{gh}");
    assert!(
        valid.len() > xy.len() / 2,
        "{} of {} nodes",
        valid.len(),
        xy.len()
    );
    assert!(
        valid
            .iter()
            .all(|p| (-0.1..=1.1).contains(&p[0]) && (-0.1..=1.1).contains(&p[1]))
    );
    let (ok, err) = run("mpcdi", "rig.mpcdi", &[]);
    assert!(ok, "{err}");
    let pkg = omniwarp::export::mpcdi::read(&std::fs::read(s.path("rig.mpcdi")).unwrap()).unwrap();
    assert_eq!(pkg.buffers[0].regions.len(), 2);
    assert_eq!(pkg.attr("version"), Some("2.0"));
    assert!(
        pkg.xml.contains("<bitDepth>8</bitDepth>"),
        "8-bit alpha by default"
    );
    // WATCHOUT 6 reads 1.0; 16-bit alpha on request.
    let (ok, err) = run(
        "mpcdi",
        "old.mpcdi",
        &["--mpcdi-version", "1.0", "--alpha-bits", "16"],
    );
    assert!(ok, "{err}");
    let old = omniwarp::export::mpcdi::read(&std::fs::read(s.path("old.mpcdi")).unwrap()).unwrap();
    assert_eq!(old.attr("version"), Some("1.0"));
    assert!(old.xml.contains("<bitDepth>16</bitDepth>"));
    let (ok, err) = run("mesh", "x.data", &[]);
    assert!(!ok && err.contains("--channel"), "{err}");
    let (ok, err) = run("mesh", "y.data", &["--channel", "left", "--tolerance", "0"]);
    assert!(
        !ok && err.contains("--tolerance") && !s.path("y.data").exists(),
        "{err}"
    );
}

#[test]
fn render_draws_a_scene_on_the_gpu_and_the_cpu() {
    let s = Scene::new();
    let base = [
        "render",
        "--scene",
        "city:small",
        "--projection",
        "cylindrical",
        "--hfov",
        "360",
        "--vfov",
        "100",
        "--size",
        "256x80",
        "--face",
        "128",
    ];
    let mut images = Vec::new();
    for renderer in ["gpu", "cpu"] {
        let out = format!("city-{renderer}.png");
        let mut args = base.to_vec();
        args.extend(["--renderer", renderer, "--out", &out]);
        let (ok, err) = s.run(&args);
        assert!(ok, "{renderer}: {err}");
        assert!(err.contains("faces"), "{err}");
        let img = image::open(s.path(&out)).unwrap().into_rgba8();
        assert_eq!((img.width(), img.height()), (256, 80));
        images.push(omniwarp::raster::Raster {
            width: 256,
            height: 80,
            data: img.pixels().map(|p| p.0).collect(),
        });
    }
    // Both renderers draw the whole view and agree but along triangle edges (rasterised vs
    // ray-cast cube faces): measured 74.3 dB at this size.
    let db = omniwarp::raster::psnr(&images[0], &images[1], 255.0, |_, _| true);
    assert!(
        images.iter().all(|i| i.data.iter().all(|p| p[3] == 255)) && db > CITY_GPU_CPU_DB,
        "GPU vs CPU: {db:.1} dB"
    );
    eprintln!("GPU vs CPU: {db:.1} dB");
    let mut args = base.to_vec();
    args.extend([
        "--renderer",
        "gpu",
        "--adapter",
        "no-such-adapter",
        "--out",
        "x.png",
    ]);
    let (ok, err) = s.run(&args);
    assert!(
        !ok && err.contains("--adapter") && err.contains("no-such-adapter"),
        "{err}"
    );
    let (ok, err) = s.run(&[
        "render",
        "--scene",
        "nope.fbx",
        "--projection",
        "flat",
        "--hfov",
        "90",
        "--size",
        "8x8",
        "--out",
        "y.png",
    ]);
    assert!(
        !ok && err.contains("--scene") && !s.path("y.png").exists(),
        "{err}"
    );
    let (ok, err) = s.run(&[
        "render",
        "--projection",
        "flat",
        "--hfov",
        "90",
        "--size",
        "8x8",
        "--out",
        "z.png",
    ]);
    assert!(!ok && err.contains("--content"), "{err}");
    // The GPU draws scenes only; asked to render content it refuses rather than quietly using
    // the CPU.
    let (ok, err) = s.run(&[
        "render",
        "--content",
        "eq.png",
        "--content-format",
        "equirect",
        "--projection",
        "flat",
        "--hfov",
        "90",
        "--size",
        "8x8",
        "--renderer",
        "gpu",
        "--out",
        "w.png",
    ]);
    assert!(
        !ok && err.contains("--renderer") && !s.path("w.png").exists(),
        "{err}"
    );
}

const CITY_GPU_CPU_DB: f64 = 70.0;

#[test]
fn the_city_written_as_gltf_renders_exactly_like_the_built_in_one() {
    let s = Scene::new();
    for out in ["city.gltf", "city.glb"] {
        let (ok, err) = s.run(&["scene", "--city", "small", "--out", out]);
        assert!(ok, "{err}");
    }
    assert!(s.path("city.bin").exists());
    let render = |scene: &str, out: &str| {
        let scene = if scene.starts_with("city:") {
            scene.to_string()
        } else {
            s.path(scene).to_str().unwrap().to_string()
        };
        s.run(&[
            "render",
            "--scene",
            &scene,
            "--projection",
            "cylindrical",
            "--hfov",
            "270",
            "--vfov",
            "90",
            "--size",
            "384x128",
            "--renderer",
            "gpu",
            "--out",
            out,
        ])
    };
    for (scene, out) in [
        ("city:small", "a.png"),
        ("city.gltf", "b.png"),
        ("city.glb", "c.png"),
    ] {
        let (ok, err) = render(scene, out);
        assert!(ok, "{scene}: {err}");
    }
    let a = std::fs::read(s.path("a.png")).unwrap();
    assert_eq!(a, std::fs::read(s.path("b.png")).unwrap(), "gltf");
    assert_eq!(a, std::fs::read(s.path("c.png")).unwrap(), "glb");
    let (ok, err) = s.run(&["scene", "--city", "tiny", "--out", "x.gltf"]);
    assert!(!ok && err.contains("--city"), "{err}");
    let (ok, err) = s.run(&["scene", "--out", "x.fbx"]);
    assert!(!ok && err.contains("--out"), "{err}");
}

/// The samples of a 16-bit binary PGM (ffmpeg's remap maps), row by row.
fn pgm16(path: &Path) -> Vec<u16> {
    let bytes = std::fs::read(path).unwrap();
    let text = String::from_utf8_lossy(&bytes[..32.min(bytes.len())]).into_owned();
    let mut fields = text.split_ascii_whitespace();
    assert_eq!(fields.next(), Some("P5"));
    let (w, h): (usize, usize) = (
        fields.next().unwrap().parse().unwrap(),
        fields.next().unwrap().parse().unwrap(),
    );
    assert_eq!(fields.next(), Some("65535"));
    let body = &bytes[bytes.len() - 2 * w * h..];
    body.chunks(2)
        .map(|c| u16::from_be_bytes([c[0], c[1]]))
        .collect()
}

/// Exit 2 for a refused command line or input (clap's usage errors and ours alike), 1 for work
/// that failed, 0 and nothing on stderr when the reader of stdout goes away (`… | head`).
#[test]
fn exit_codes_tell_bad_usage_from_failed_work_and_a_closed_pipe_is_quiet() {
    let s = Scene::new();
    let dir = s.dir.path();
    for args in [
        &["pattern", "--bogus"][..],
        &["pattern", "--size", "0x8", "--out", "x.png"],
        &[
            "render",
            "--content",
            "eq.png",
            "--content-format",
            "equirect",
            "--projection",
            "flat",
            "--hfov",
            "200",
            "--size",
            "8x8",
            "--out",
            "x.png",
        ],
        &[
            "pattern",
            "--size",
            "16x8",
            "--out",
            "/nonexistent/dir/x.png",
        ],
    ] {
        let (code, err) = status(dir, args);
        assert_eq!(code, Some(2), "{args:?}: {err}");
    }
    // The output directory is fine, but one mask's file name is taken by a directory.
    let rig = Path::new(env!("CARGO_MANIFEST_DIR")).join("calibration/rigs/flat-2proj.json");
    std::fs::create_dir_all(s.path("masks/left.png")).unwrap();
    let (code, err) = status(
        dir,
        &[
            "blend",
            "--rig",
            rig.to_str().unwrap(),
            "--out-dir",
            "masks",
        ],
    );
    assert!(
        code == Some(1) && err.contains("left.png"),
        "{code:?}: {err}"
    );
    // The file named in the error is the one asked for, not a temporary file.
    let (_, err) = status(
        dir,
        &[
            "pattern",
            "--size",
            "16x8",
            "--out",
            "/nonexistent/dir/x.png",
        ],
    );
    assert!(
        err.contains("--out: /nonexistent/dir/x.png") && !err.contains(".omniwarp-"),
        "{err}"
    );
    // A reader that stops after one line.
    let mut child = Command::new(env!("CARGO_BIN_EXE_omniwarp"))
        .arg("projections")
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    drop(child.stdout.take());
    let out = child.wait_with_output().unwrap();
    assert!(
        out.status.success() && out.stderr.is_empty(),
        "{:?}: {}",
        out.status,
        String::from_utf8_lossy(&out.stderr)
    );
}

/// `bench warp` times the frames in threes between copies and reads the bound from the copies
/// taken among them: as many frames as asked (rounded up to three), one copy per three, and a
/// share of the bound that is a percentage of a real measurement.
#[test]
fn bench_warp_pairs_its_frames_with_the_bandwidth_copies() {
    let out = Command::new(env!("CARGO_BIN_EXE_omniwarp"))
        .args(["bench", "warp", "--size", "64x32", "--face-size", "16"])
        .args(["--frames", "7", "--threads", "1"])
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{text}");
    let number_after = |key: &str| -> f64 {
        let line = text
            .lines()
            .find(|l| l.contains(key))
            .unwrap_or_else(|| panic!("{text}"));
        let rest = &line[line.find(key).unwrap() + key.len()..];
        let end = rest
            .find(|c: char| !c.is_ascii_digit() && c != '.')
            .unwrap_or(rest.len());
        rest[..end].parse().unwrap_or_else(|_| panic!("{line}"))
    };
    assert_eq!(number_after("over "), 9.0, "{text}");
    assert_eq!(number_after("median of "), 3.0, "{text}");
    let share = number_after("we reach ");
    assert!(share > 0.0 && share < 1000.0, "{text}");
}
