//! Camera calibration on the virtual bench, against its ground truth: the dome example rig, a
//! 185° fisheye camera at the centre, 8-bit captures with σ = 2 grey levels of noise, both
//! gammas 2.2, 0.7 px blur and 5 % ambient (issue 19's figures).

use omniwarp::calibration::{ModelChoice, Problem, calibrate};
use omniwarp::rig::{Channel, ChannelDoc, LensDoc, PoseDoc, Rig};
use omniwarp::structured::decode::{DecodeOptions, Decoded, decode};
use omniwarp::structured::simulator::{Simulator, SimulatorOptions};
use omniwarp::structured::{Grey, check, correspondences};
use std::path::Path;

use crate::common;

fn dome() -> Rig {
    Rig::read(Path::new("calibration/rigs/dome-180-tilt15-5proj.json")).unwrap()
}

/// A 185° fisheye filling the height of a `w`×`h` image, at the dome's centre, looking at its
/// zenith.
fn fisheye(w: u32, h: u32) -> Channel {
    let f = f64::from(h) / 2.0 / 92.5f64.to_radians();
    let t = 15f64.to_radians();
    let doc = ChannelDoc {
        id: "camera".into(),
        resolution: [w, h],
        lens: LensDoc::new(
            "LENSMODEL_OPENCV_FISHEYE",
            vec![
                f,
                f,
                f64::from(w) / 2.0 - 0.5,
                f64::from(h) / 2.0 - 0.5,
                0.0,
                0.0,
                0.0,
                0.0,
            ],
        ),
        pose: PoseDoc {
            position: [0.0, 0.0, 0.0],
            look_to: Some([0.0, t.cos(), -t.sin()]),
            look_up: Some([0.0, 0.0, -1.0]),
            rvec: None,
        },
        contrast: None,
    };
    Channel::from_doc(&doc, "/camera").unwrap()
}

/// A pinhole camera of focal length `f` pixels at the dome's centre, looking along `look_to`.
fn pinhole(w: u32, h: u32, f: f64, look_to: [f64; 3]) -> Channel {
    let doc = ChannelDoc {
        id: "camera".into(),
        resolution: [w, h],
        lens: LensDoc::new(
            "LENSMODEL_PINHOLE",
            vec![f, f, f64::from(w) / 2.0 - 0.5, f64::from(h) / 2.0 - 0.5],
        ),
        pose: PoseDoc {
            position: [0.0, 0.0, 0.0],
            look_to: Some(look_to),
            look_up: Some([0.0, 1.0, 0.0]),
            rvec: None,
        },
        contrast: None,
    };
    Channel::from_doc(&doc, "/camera").unwrap()
}

/// Eight fiducials on the dome where a 1280×720 fisheye camera from the eye sees them, as
/// someone would click them: to 0.3 px.
fn markers(rig: &Rig, truth: &Channel) -> Vec<omniwarp::calibration::Correspondence> {
    use omniwarp::calibration::Correspondence;
    let mut noise = [
        0.21, -0.3, 0.05, 0.28, -0.12, -0.25, 0.3, -0.07, 0.17, 0.0, -0.2, 0.1,
    ]
    .into_iter()
    .cycle();
    [
        (360.0, 250.0),
        (920.0, 250.0),
        (640.0, 60.0),
        (490.0, 150.0),
        (790.0, 150.0),
        (500.0, 340.0),
        (780.0, 340.0),
        (640.0, 380.0),
    ]
    .iter()
    .map(|&(x, y)| {
        let ray = truth.rotation * truth.lens.unproject([x, y]).unwrap();
        let world = rig
            .doc
            .screen
            .intersect(truth.position, ray)
            .point()
            .unwrap();
        Correspondence {
            pixel: [x + noise.next().unwrap(), y + noise.next().unwrap()],
            world: world.to_array(),
        }
    })
    .collect()
}

/// The command line run: whether it succeeded, its stdout and its stderr.
fn run(args: &[&str]) -> (bool, String, String) {
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_omniwarp"))
        .args(args)
        .output()
        .unwrap();
    (
        out.status.success(),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

/// The channel a daemon's 201 proposes.
fn proposed(status: axum::http::StatusCode, body: &[u8]) -> Channel {
    assert_eq!(
        status,
        axum::http::StatusCode::CREATED,
        "{}",
        String::from_utf8_lossy(body)
    );
    let doc: serde_json::Value = serde_json::from_slice(body).unwrap();
    let doc: ChannelDoc = serde_json::from_value(doc["proposed"].clone()).unwrap();
    Channel::from_doc(&doc, "").unwrap()
}

fn percentile(v: &mut [f64], p: f64) -> f64 {
    v.sort_by(f64::total_cmp);
    v[((v.len() - 1) as f64 * p).round() as usize]
}

fn capture_all(bench: &Simulator) -> Vec<Grey> {
    (0..bench.patterns().len())
        .map(|n| bench.capture(n).unwrap())
        .collect()
}

/// Decoded − true projector coordinate over the pixels both know; and how many the truth
/// lights.
fn decode_errors(bench: &Simulator, decoded: &Decoded) -> (Vec<f64>, usize) {
    let (mut errors, mut lit) = (Vec::new(), 0);
    for y in 0..decoded.height {
        for x in 0..decoded.width {
            let truth = bench.truth(x, y);
            lit += usize::from(truth.is_some());
            if let (Some(s), Some(t)) = (decoded.get(x, y), truth) {
                errors.push((s.q[0] - t[0]).hypot(s.q[1] - t[1]));
            }
        }
    }
    (errors, lit)
}

#[test]
fn captures_decode_and_calibrate_the_dome_projector_to_its_truth() {
    let rig = dome();
    let projector = rig.channel("front").unwrap().clone();
    let camera = fisheye(1920, 1080);
    let bench = Simulator::new(&rig, &projector, &camera, SimulatorOptions::default()).unwrap();
    let frames = capture_all(&bench);
    let decoded = decode(bench.patterns(), &frames, &DecodeOptions::default()).unwrap();
    let (mut errors, lit) = decode_errors(&bench, &decoded);
    let valid = errors.len();
    assert!(valid as f64 > 0.95 * lit as f64, "decoded {valid} of {lit}");
    let gross = errors.iter().filter(|&&e| e > 1.0).count();
    let p50 = percentile(&mut errors, 0.5);
    let p99 = percentile(&mut errors, 0.99);
    eprintln!(
        "{lit} lit camera pixels, {valid} decoded; error median {p50:.4} px, p99 {p99:.4} px, \
         {gross} above 1 px; rejected {:?}",
        decoded.rejected
    );
    assert!(p50 <= 0.05, "median {p50}");
    assert!(p99 <= 0.3, "p99 {p99}");
    assert!(gross as f64 <= 0.001 * valid as f64, "{gross} gross errors");

    let points = correspondences(&decoded, &camera, &rig.doc.screen, 20_000);
    assert!(points.len() > 15_000, "{} points", points.len());
    let problem = Problem {
        resolution: [projector.width, projector.height],
        points,
        lens: None,
        intrinsics_fixed: false,
    };
    let cal = calibrate(&problem, ModelChoice::Fixed(projector.lens.model())).unwrap();
    let fitted = Channel::from_doc(&cal.channel_doc("front", [1920, 1200]), "").unwrap();
    let moved = (fitted.position - projector.position).length();
    let turned = (fitted.rotation.transpose() * projector.rotation)
        .to_cols_array()
        .iter()
        .step_by(4)
        .sum::<f64>();
    let turned = ((turned - 1.0) / 2.0).clamp(-1.0, 1.0).acos().to_degrees();
    // Where the calibrated projector puts each of its pixels, seen in the true projector's
    // pixels: the warp's error, and the reprojection error against noise-free truth.
    let mut warp = Vec::new();
    for j in (0..1200).step_by(8) {
        for i in (0..1920).step_by(8) {
            let q = [f64::from(i), f64::from(j)];
            let Some(p) = rig.wall_point(&projector, q) else {
                continue;
            };
            let truth = projector
                .lens
                .project(projector.rotation.transpose() * (p - projector.position))
                .unwrap();
            assert!((truth[0] - q[0]).hypot(truth[1] - q[1]) < 1e-6);
            let Some(pf) = rig.wall_point(&fitted, q) else {
                continue;
            };
            let landed = projector
                .lens
                .project(projector.rotation.transpose() * (pf - projector.position))
                .unwrap();
            warp.push((landed[0] - q[0]).hypot(landed[1] - q[1]));
        }
    }
    let rms = (warp.iter().map(|e| e * e).sum::<f64>() / warp.len() as f64).sqrt();
    let warp99 = percentile(&mut warp, 0.99);
    eprintln!(
        "fit: {} points, RMS {:.4} px; position off by {:.3} mm, rotation by {turned:.5}°; \
         against truth over {} lit projector pixels: RMS {rms:.4} px, p99 {warp99:.4} px",
        problem.points.len(),
        cal.fit.rms,
        moved * 1e3,
        warp.len()
    );
    assert!(moved < 0.002, "position off by {moved} m");
    assert!(turned < 0.02, "rotation off by {turned}°");
    assert!(rms <= 0.1, "reprojection RMS {rms}");
    assert!(warp99 <= 0.05, "warp p99 {warp99}");

    // The check against the calibration it came from: nothing moved.
    let verdict = check(&decoded, &camera, &rig.doc.screen, &fitted);
    assert!(!verdict.moved, "{verdict:?}");
}

#[test]
fn inter_reflection_on_the_dome_leaves_one_percent_gross_errors_at_most() {
    let rig = dome();
    let projector = rig.channel("front").unwrap().clone();
    let camera = fisheye(1920, 1080);
    let opts = SimulatorOptions {
        interreflection: 0.2,
        ..SimulatorOptions::default()
    };
    let bench = Simulator::new(&rig, &projector, &camera, opts).unwrap();
    let frames = capture_all(&bench);
    // The bounce lights the whole dome: under white, the pixels the projector does not reach
    // are brighter than without it.
    let plain = Simulator::new(&rig, &projector, &camera, SimulatorOptions::default()).unwrap();
    let white_plain = plain.capture(0).unwrap();
    let brighter = (0..1080)
        .flat_map(|y| (0..1920).map(move |x| (x, y)))
        .filter(|&(x, y)| {
            let i = (y * 1920 + x) as usize;
            bench.truth(x, y).is_none() && frames[0].data[i] > white_plain.data[i] + 10
        })
        .count();
    let decoded = decode(bench.patterns(), &frames, &DecodeOptions::default()).unwrap();
    let (errors, lit) = decode_errors(&bench, &decoded);
    let gross = errors.iter().filter(|&&e| e > 1.0).count();
    eprintln!(
        "20 % inter-reflection: {} of {lit} lit pixels decoded, {gross} above 1 px; {brighter} \
         pixels brighter in black; rejected {:?}",
        errors.len(),
        decoded.rejected
    );
    assert!(errors.len() as f64 > 0.9 * lit as f64);
    assert!(gross as f64 <= 0.01 * errors.len() as f64);
    // Outside the projector's light, nothing is decoded although the bounce lights it.
    for y in 0..1080 {
        for x in 0..1920 {
            if bench.truth(x, y).is_none() {
                assert!(
                    decoded.get(x, y).is_none(),
                    "({x}, {y}) decoded in the dark"
                );
            }
        }
    }
    assert!(brighter > 100_000, "{brighter}");
}

#[test]
fn a_defocused_camera_decodes_with_a_longer_period() {
    // A blur of σ = 4 camera pixels (about 10 of the projector's) flattens the 16 px sinusoid
    // to nothing; a 64 px period keeps most of it. (The 16 px case is shown at half the size,
    // where the blur is twice as wide in projector pixels, to save time.)
    let rig = dome();
    let projector = rig.channel("front").unwrap().clone();
    let fisheye = |w, h| omniwarp::structured::simulator::fisheye_at_eye(&rig, &projector, w, h);
    let decoded = |period: u32, camera: Channel| {
        let opts = SimulatorOptions {
            blur: 4.0,
            period,
            ..Default::default()
        };
        let bench = Simulator::new(&rig, &projector, &camera, opts).unwrap();
        assert_eq!(bench.patterns().period, period);
        let decoded = decode(
            bench.patterns(),
            &capture_all(&bench),
            &DecodeOptions::default(),
        )
        .unwrap();
        let (errors, lit) = decode_errors(&bench, &decoded);
        (bench.patterns().len(), errors, lit)
    };
    let (frames, errors, _) = decoded(16, fisheye(960, 540).unwrap());
    assert_eq!(frames, 58);
    assert!(errors.is_empty(), "{} decoded at 16 px", errors.len());
    let (frames, mut errors, lit) = decoded(64, fisheye(1920, 1080).unwrap());
    assert_eq!(frames, 50);
    let gross = errors.iter().filter(|&&e| e > 1.0).count();
    let median = percentile(&mut errors, 0.5);
    eprintln!(
        "σ = 4 px blur, 64 px period: {} of {lit} lit pixels decoded, median {median:.4} px, {gross} gross",
        errors.len()
    );
    assert!(errors.len() * 10 > lit * 8, "{} of {lit}", errors.len());
    assert!(median < 0.25, "median {median}");
    assert!(gross * 100 < errors.len() * 2, "{gross} gross");
}

#[test]
fn a_yaw_of_five_hundredths_of_a_degree_is_detected_and_noise_is_not() {
    let rig = dome();
    let projector = rig.channel("front").unwrap().clone();
    // A small camera watching the projector: the verdict is on the median of thousands of
    // pixels either way.
    let camera = pinhole(480, 270, 400.0, [0.0, 0.173648, -0.984808]);
    let mut bench = Simulator::new(&rig, &projector, &camera, SimulatorOptions::default()).unwrap();
    let opts = DecodeOptions::default();
    for seed in 100..120 {
        bench.reseed(seed);
        let decoded = decode(bench.patterns(), &capture_all(&bench), &opts).unwrap();
        let c = check(&decoded, &camera, &rig.doc.screen, &projector);
        assert!(c.count > 3000, "{} pixels compared", c.count);
        assert!(!c.moved, "false alarm with seed {seed}: {c:?}");
    }
    // The projector turns 0.05° about the dome's vertical; the rig still says where it was.
    let mut doc = rig.doc.clone();
    let turn = glam::DMat3::from_axis_angle(glam::DVec3::Y, 0.05f64.to_radians());
    let front = &mut doc.channels[0];
    let to = turn * glam::DVec3::from_array(front.pose.look_to.unwrap());
    let up = turn * glam::DVec3::from_array(front.pose.look_up.unwrap());
    front.pose.look_to = Some(to.to_array());
    front.pose.look_up = Some(up.to_array());
    let turned_rig = Rig::from_doc(doc).unwrap();
    let turned = turned_rig.channel("front").unwrap().clone();
    let bench = Simulator::new(&turned_rig, &turned, &camera, SimulatorOptions::default()).unwrap();
    let decoded = decode(bench.patterns(), &capture_all(&bench), &opts).unwrap();
    let c = check(&decoded, &camera, &rig.doc.screen, &projector);
    eprintln!(
        "0.05° yaw: median residual {:.3} px (threshold {:.3}), p95 {:.3}, max {:.3}",
        c.p50, c.threshold, c.p95, c.max
    );
    assert!(c.moved, "{c:?}");
}

#[test]
fn simulated_captures_calibrate_and_check_from_the_command_line() {
    let dir = tempfile::tempdir().unwrap();
    let caps = dir.path().join("captures");
    let rig = "calibration/rigs/dome-180-tilt15-5proj.json";
    let caps_s = caps.to_str().unwrap();
    let (ok, out, err) = run(&[
        "simulate",
        "--rig",
        rig,
        "--channel",
        "front",
        "--camera-size",
        "1280x720",
        "--out",
        caps_s,
    ]);
    assert!(ok, "{err}");
    assert!(out.starts_with("58 captures of `front`"), "{out}");
    let (truth, _) = omniwarp::image_io::read_exr_rgba(&caps.join("truth.exr")).unwrap();
    assert!(truth.data.iter().filter(|p| p[3] == 1.0).count() > 100_000);
    let camera = caps.join("camera.json");
    let channel = dir.path().join("front.json");
    let (ok, _, err) = run(&[
        "calibrate",
        "--captures",
        caps_s,
        "--camera",
        camera.to_str().unwrap(),
        "--rig",
        rig,
        "--channel",
        "front",
        "--model",
        "LENSMODEL_OPENCV4",
        "--out",
        channel.to_str().unwrap(),
    ]);
    assert!(ok, "{err}");
    let doc: ChannelDoc =
        serde_json::from_str(&std::fs::read_to_string(&channel).unwrap()).unwrap();
    let fitted = Channel::from_doc(&doc, "").unwrap();
    let truth = dome().channel("front").unwrap().clone();
    assert!((fitted.position - truth.position).length() < 0.002);

    let residuals = dir.path().join("residuals.exr");
    let check_args = |channel: &'static str| {
        vec![
            "calibrate".to_string(),
            "--captures".into(),
            caps_s.into(),
            "--camera".into(),
            camera.to_str().unwrap().into(),
            "--rig".into(),
            rig.into(),
            "--channel".into(),
            channel.into(),
            "--check".into(),
            residuals.to_str().unwrap().into(),
        ]
    };
    let a = check_args("front");
    let (ok, out, err) = run(&a.iter().map(String::as_str).collect::<Vec<_>>());
    assert!(ok, "{err}");
    assert!(out.ends_with("not moved\n"), "{out}");
    let (img, _) = omniwarp::image_io::read_exr_rgba(&residuals).unwrap();
    assert_eq!((img.width, img.height), (1280, 720));
    assert!(img.data.iter().filter(|p| p[3] == 1.0).count() > 50_000);
    // The same captures checked against another projector: that one "moved".
    let a = check_args("left");
    let (ok, out, _) = run(&a.iter().map(String::as_str).collect::<Vec<_>>());
    assert!(ok && out.ends_with(": moved\n"), "{out}");
    // …and one whose image, as calibrated, none of the decoded light falls in.
    let a = check_args("back");
    let (ok, out, _) = run(&a.iter().map(String::as_str).collect::<Vec<_>>());
    assert!(
        ok && out.contains("within `back`'s image as calibrated: moved"),
        "{out}"
    );

    // A check against a rig whose `front` is 2 cm off where it is: moved, and --out gets the
    // channel re-fitted from the same captures, where the projector really is.
    let drifted = dir.path().join("drifted.json");
    let mut doc: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(rig).unwrap()).unwrap();
    let x = &mut doc["channels"][0]["pose"]["position"][0];
    *x = serde_json::json!(x.as_f64().unwrap() + 0.02);
    std::fs::write(&drifted, doc.to_string()).unwrap();
    let mut a = check_args("front");
    a[6] = drifted.to_str().unwrap().into();
    let refitted = dir.path().join("refitted.json");
    a.extend(["--model", "LENSMODEL_OPENCV4", "--out"].map(String::from));
    a.push(refitted.to_str().unwrap().into());
    let (ok, out, err) = run(&a.iter().map(String::as_str).collect::<Vec<_>>());
    assert!(ok && out.contains(": moved\n"), "{out}{err}");
    let doc: ChannelDoc =
        serde_json::from_str(&std::fs::read_to_string(&refitted).unwrap()).unwrap();
    let off = (Channel::from_doc(&doc, "").unwrap().position - truth.position).length();
    assert!(off < 0.002, "re-fitted {off} m off");

    // Any projector images through the same bench: the sequence's own first frames given as
    // pictures are filmed to the same bytes as the sequence.
    let patterns = dir.path().join("patterns");
    std::fs::create_dir(&patterns).unwrap();
    let set = omniwarp::structured::PatternSet::new(1920, 1200).unwrap();
    for (n, frame) in set.frames().into_iter().take(6).enumerate() {
        let png = set.image(frame).png().unwrap();
        std::fs::write(patterns.join(format!("{n:03}.png")), png).unwrap();
    }
    let filmed = dir.path().join("filmed");
    let film = |size: &str| {
        run(&[
            "simulate",
            "--rig",
            rig,
            "--channel",
            "front",
            "--camera-size",
            size,
            "--patterns",
            patterns.to_str().unwrap(),
            "--out",
            filmed.to_str().unwrap(),
        ])
    };
    let (ok, out, err) = film("1280x720");
    assert!(ok && out.starts_with("6 captures of `front`"), "{out}{err}");
    for n in 0..6 {
        let name = format!("{n:03}.png");
        assert!(
            std::fs::read(filmed.join(&name)).unwrap() == std::fs::read(caps.join(&name)).unwrap(),
            "{name} differs"
        );
    }
    let tiny = Grey::new(8, 8, vec![0; 64]);
    std::fs::write(patterns.join("006.png"), tiny.png().unwrap()).unwrap();
    let (ok, _, err) = film("64x64");
    assert!(
        !ok && err.contains("--patterns: image 6 in name order is 8×8, `front` shows 1920×1200"),
        "{err}"
    );

    // Conditions no camera has are refused by name.
    let (ok, _, err) = run(&["simulate", "--period", "7", "--out", caps_s]);
    assert!(
        !ok && err.contains("--period: must be an even number of projector pixels, 8–256, got 7"),
        "{err}"
    );
    let (ok, _, err) = run(&["simulate", "--rig", rig, "--noise=-1", "--out", caps_s]);
    assert!(
        !ok && err.contains("--noise: must lie within 0–64, got -1"),
        "{err}"
    );

    // A frame missing: the error says how many there should be.
    std::fs::remove_file(caps.join("057.png")).unwrap();
    let (ok, _, err) = run(&[
        "calibrate",
        "--captures",
        caps_s,
        "--camera",
        camera.to_str().unwrap(),
        "--rig",
        rig,
        "--channel",
        "front",
        "--out",
        channel.to_str().unwrap(),
    ]);
    assert!(!ok && err.contains("has 58 frames, got 57"), "{err}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_daemon_takes_captures_frame_by_frame_and_proposes_or_checks() {
    use axum::body::Body;
    use axum::http::{Request, StatusCode, header};
    use common::server::{call, get, json, state_with, write};
    let text = std::fs::read_to_string("calibration/rigs/dome-180-tilt15-5proj.json").unwrap();
    let s = state_with(None, None, omniwarp::rig::RigDoc::parse(&text).unwrap());
    let rig = dome();
    let projector = rig.channel("front").unwrap().clone();
    let camera =
        omniwarp::structured::simulator::fisheye_at_eye(&rig, &projector, 1280, 720).unwrap();
    let bench = Simulator::new(&rig, &projector, &camera, SimulatorOptions::default()).unwrap();
    let put = |n: String, ct: &str, body: Vec<u8>| {
        Request::put(format!("/v1/channels/front/captures/{n}"))
            .header(header::CONTENT_TYPE, ct)
            .body(Body::from(body))
            .unwrap()
    };
    let refit_req = |check: bool, refit: bool| {
        let body = serde_json::json!({"camera": camera.doc(), "model": "LENSMODEL_OPENCV4",
            "check": check, "refit": refit});
        write(
            "POST",
            "/v1/channels/front/captures",
            None,
            body.to_string(),
        )
    };
    let decode_req = |check: bool| refit_req(check, false);
    let png = |n: usize| bench.capture(n).unwrap().png().unwrap();
    for n in 0..57 {
        let (st, _, body) = call(&s, put(n.to_string(), "image/png", png(n))).await;
        assert_eq!(st, StatusCode::OK, "{}", String::from_utf8_lossy(&body));
    }
    let (_, _, body) = call(&s, get("/v1/channels/front/captures?period=64")).await;
    assert_eq!(
        (
            json(&body)["frames"].as_u64(),
            json(&body)["received"].as_array().map(Vec::len)
        ),
        (Some(50), Some(0))
    );
    for (uri, status) in [
        ("/v1/channels/front/pattern/49?period=64", StatusCode::OK),
        (
            "/v1/channels/front/pattern/50?period=64",
            StatusCode::BAD_REQUEST,
        ),
        (
            "/v1/channels/front/pattern/0?period=7",
            StatusCode::BAD_REQUEST,
        ),
        (
            "/v1/channels/front/captures?period=300",
            StatusCode::BAD_REQUEST,
        ),
    ] {
        assert_eq!(call(&s, get(uri)).await.0, status, "{uri}");
    }
    let (_, _, body) = call(&s, get("/v1/channels/front/captures")).await;
    let status = json(&body);
    assert_eq!(status["frames"], 58);
    assert_eq!(status["missing"], serde_json::json!([57]));
    assert_eq!(status["size"], serde_json::json!([1280, 720]));
    let (st, _, body) = call(&s, decode_req(false)).await;
    assert_eq!(st, StatusCode::BAD_REQUEST);
    assert_eq!(json(&body)["field"], "captures");
    assert!(json(&body)["error"].as_str().unwrap().contains("[57]"));

    // Refused uploads, each named.
    let (st, _, _) = call(&s, put("57".into(), "text/plain", png(57))).await;
    assert_eq!(st, StatusCode::UNSUPPORTED_MEDIA_TYPE);
    for (n, body, field) in [
        ("57", b"not an image".to_vec(), "body"),
        ("58", png(0), "n"),
        ("x", png(0), "n"),
        (
            "57",
            omniwarp::structured::Grey::new(8, 8, vec![0; 64])
                .png()
                .unwrap(),
            "body",
        ),
    ] {
        let (st, _, resp) = call(&s, put(n.into(), "image/png", body)).await;
        assert_eq!(
            (st, json(&resp)["field"].as_str()),
            (StatusCode::BAD_REQUEST, Some(field)),
            "{n}"
        );
    }

    let (st, _, _) = call(&s, put("57".into(), "image/png", png(57))).await;
    assert_eq!(st, StatusCode::OK);
    let (st, _, body) = call(&s, decode_req(false)).await;
    let fitted = proposed(st, &body);
    assert!((fitted.position - projector.position).length() < 0.002);
    let (st, _, body) = call(&s, get(&format!("/v1/proposals/{}", json(&body)["id"]))).await;
    assert_eq!(st, StatusCode::OK, "{}", String::from_utf8_lossy(&body));

    // The camera's pose from markers instead: the camera document's own pose is wrong.
    let mut lost = camera.clone();
    lost.position = glam::DVec3::new(0.3, -0.2, 0.1);
    let body = serde_json::json!({"camera": lost.doc(), "model": "LENSMODEL_OPENCV4",
        "markers": markers(&rig, &camera)});
    let req = write(
        "POST",
        "/v1/channels/front/captures",
        None,
        body.to_string(),
    );
    let (st, _, body) = call(&s, req).await;
    let fitted = proposed(st, &body);
    assert!((fitted.position - projector.position).length() < 0.005);
    let body = serde_json::json!({"camera": lost.doc(), "markers": []});
    let req = write(
        "POST",
        "/v1/channels/front/captures",
        None,
        body.to_string(),
    );
    let (st, _, body) = call(&s, req).await;
    assert_eq!(
        (st, json(&body)["field"].as_str()),
        (StatusCode::BAD_REQUEST, Some("/markers"))
    );

    let (st, _, body) = call(&s, decode_req(true)).await;
    assert_eq!(st, StatusCode::OK);
    let report = json(&body);
    assert_eq!(report["moved"], false, "{report}");
    assert!(report["count"].as_u64().unwrap() > 50_000, "{report}");
    assert!(report.get("proposal").is_none(), "{report}");

    // A re-fit from the check's captures: none while the projector is where the rig says,
    // refused without a check, and proposed once the rig no longer says where it is.
    let (st, _, body) = call(&s, refit_req(true, true)).await;
    assert_eq!(st, StatusCode::OK);
    assert_eq!(
        json(&body)["proposal"],
        serde_json::Value::Null,
        "{}",
        json(&body)
    );
    let (st, _, body) = call(&s, refit_req(false, true)).await;
    assert_eq!(
        (st, json(&body)["field"].as_str()),
        (StatusCode::BAD_REQUEST, Some("/refit"))
    );
    let (_, _, b) = call(&s, get("/v1/rig")).await;
    let (mut doc, revision) = (json(&b)["rig"].clone(), json(&b)["revision"].as_u64());
    let x = &mut doc["channels"][0]["pose"]["position"][0];
    *x = serde_json::json!(x.as_f64().unwrap() + 0.02);
    let (st, _, _) = call(&s, write("PUT", "/v1/rig", revision, doc.to_string())).await;
    assert_eq!(st, StatusCode::OK);
    let (st, _, body) = call(&s, refit_req(true, true)).await;
    assert_eq!(st, StatusCode::OK, "{}", String::from_utf8_lossy(&body));
    let report = json(&body);
    assert_eq!(report["moved"], true, "{report}");
    let doc: ChannelDoc = serde_json::from_value(report["proposal"]["proposed"].clone()).unwrap();
    let refitted = Channel::from_doc(&doc, "").unwrap();
    let off = (refitted.position - projector.position).length();
    assert!(off < 0.002, "the re-fit is {off} m from the projector");
    let (st, _, _) = call(
        &s,
        get(&format!("/v1/proposals/{}", report["proposal"]["id"])),
    )
    .await;
    assert_eq!(st, StatusCode::OK);

    let (_, _, body) = call(
        &s,
        write("DELETE", "/v1/channels/front/captures", None, String::new()),
    )
    .await;
    assert_eq!(json(&body)["dropped"], 58);
    let (st, _, _) = call(&s, decode_req(true)).await;
    assert_eq!(st, StatusCode::BAD_REQUEST);
}

#[test]
fn two_camera_poses_measure_the_dome_radius() {
    use omniwarp::structured::triangulate::{fit_sphere, triangulate};
    let rig = dome();
    let projector = rig.channel("front").unwrap().clone();
    let target = rig.wall_point(&projector, [959.5, 599.5]).unwrap();
    let camera = |x: f64| {
        let position = glam::DVec3::new(x, 0.0, 0.2);
        let mut c = pinhole(1280, 720, 700.0, (target - position).normalize().to_array());
        c.position = position;
        c
    };
    let opts = DecodeOptions::default();
    let shoot = |c: &Channel| {
        let bench = Simulator::new(&rig, &projector, c, SimulatorOptions::default()).unwrap();
        decode(bench.patterns(), &capture_all(&bench), &opts).unwrap()
    };
    let (ca, cb) = (camera(-0.5), camera(0.5));
    let (da, db) = (shoot(&ca), shoot(&cb));
    let points = triangulate((&da, &ca), (&db, &cb), [1920, 1200], 2, 0.01);
    let (centre, radius) = fit_sphere(&points).unwrap();
    let off: Vec<f64> = points.iter().map(|p| (p.length() - 3.0).abs()).collect();
    let worst = off.iter().copied().fold(0.0, f64::max);
    eprintln!(
        "two cameras 1 m apart: {} wall points (worst {:.2} mm off the true dome); radius {radius:.5} m, \
         centre {centre:.4?}",
        points.len(),
        worst * 1e3
    );
    assert!(points.len() > 20_000, "{}", points.len());
    assert!((radius - 3.0).abs() <= 0.003, "radius {radius}");
    assert!(centre.length() < 0.01, "centre {centre}");
}

#[test]
fn a_camera_pose_from_eight_markers_calibrates_the_projector_as_well() {
    use omniwarp::structured::camera_pose;
    let rig = dome();
    let projector = rig.channel("front").unwrap().clone();
    let truth =
        omniwarp::structured::simulator::fisheye_at_eye(&rig, &projector, 1280, 720).unwrap();
    let markers = markers(&rig, &truth);
    // The camera as known before: its lens, and a pose that is wrong.
    let mut guess = truth.clone();
    guess.position = glam::DVec3::new(0.3, -0.2, 0.1);
    guess.rotation = glam::DMat3::IDENTITY;
    let (camera, rms) = camera_pose(&guess, &markers).unwrap();
    let off = (camera.position - truth.position).length();
    eprintln!(
        "camera pose from 8 markers: {:.2} mm off, marker RMS {rms:.3} px",
        off * 1e3
    );
    assert!(off < 0.005, "camera {off} m off");
    assert!(camera_pose(&guess, &markers[..3]).is_err());

    let bench = Simulator::new(&rig, &projector, &truth, SimulatorOptions::default()).unwrap();
    let decoded = decode(
        bench.patterns(),
        &capture_all(&bench),
        &DecodeOptions::default(),
    )
    .unwrap();
    let fitted = |camera: &Channel| {
        let points = correspondences(&decoded, camera, &rig.doc.screen, 5000);
        let problem = Problem {
            resolution: [1920, 1200],
            points,
            lens: None,
            intrinsics_fixed: false,
        };
        let cal = calibrate(&problem, ModelChoice::Fixed(projector.lens.model())).unwrap();
        let ch = Channel::from_doc(&cal.channel_doc("front", [1920, 1200]), "").unwrap();
        (ch.position - projector.position).length()
    };
    let (with_truth, with_markers) = (fitted(&truth), fitted(&camera));
    eprintln!(
        "projector position off by {:.2} mm with the true camera pose, {:.2} mm with the pose from markers",
        with_truth * 1e3,
        with_markers * 1e3
    );
    assert!(with_markers < 0.005, "{with_markers}");
}

/// The angle between two rotations, degrees.
fn angle_between(a: glam::DMat3, b: glam::DMat3) -> f64 {
    let trace: f64 = (a.transpose() * b).to_cols_array().iter().step_by(4).sum();
    ((trace - 1.0) / 2.0).clamp(-1.0, 1.0).acos().to_degrees()
}

#[test]
fn a_camera_posed_from_a_calibrated_projector_calibrates_its_neighbour() {
    use omniwarp::structured::{PatternSet, camera_pose_from_projector, read_captures};
    let dir = tempfile::tempdir().unwrap();
    let rig_path = "calibration/rigs/dome-180-tilt15-5proj.json";
    let rig = dome();
    let (front, right) = (
        rig.channel("front").unwrap().clone(),
        rig.channel("right").unwrap().clone(),
    );
    // One camera, seeing the whole dome, films `front` (calibrated) and then `right` (not):
    // the calibration guide's example camera, `fisheye(1280, 720)`.
    let camera = Path::new("calibration/examples/camera-dome.json");
    let truth: ChannelDoc =
        serde_json::from_str(&std::fs::read_to_string(camera).unwrap()).unwrap();
    let truth = Channel::from_doc(&truth, "").unwrap();
    let expected = fisheye(1280, 720);
    assert!(truth.position == expected.position && truth.lens == expected.lens);
    assert!(angle_between(truth.rotation, expected.rotation) < 1e-4);
    let caps = |id: &str, seed: &str| {
        let out = dir.path().join(id);
        let (ok, _, err) = run(&[
            "simulate",
            "--rig",
            rig_path,
            "--channel",
            id,
            "--camera",
            camera.to_str().unwrap(),
            "--seed",
            seed,
            "--out",
            out.to_str().unwrap(),
        ]);
        assert!(ok, "{err}");
        out
    };
    let (front_caps, right_caps) = (caps("front", "1"), caps("right", "2"));
    // What is known of the camera: its lens; its pose 37 cm and 30-odd degrees off.
    let mut guess = truth.clone();
    guess.position = glam::DVec3::new(0.3, -0.2, 0.1);
    guess.rotation = glam::DMat3::IDENTITY;
    let guess_path = dir.path().join("guess.json");
    std::fs::write(&guess_path, serde_json::to_string(&guess.doc()).unwrap()).unwrap();

    let decoded = decode(
        &PatternSet::new(front.width, front.height).unwrap(),
        &read_captures(&front_caps).unwrap(),
        &DecodeOptions::default(),
    )
    .unwrap();
    let (posed, rms) =
        camera_pose_from_projector(&decoded, &guess, &front, &rig.doc.screen, 5000).unwrap();
    let off = (posed.position - truth.position).length();
    let turned = angle_between(posed.rotation, truth.rotation);
    eprintln!(
        "camera posed from `front`: {:.3} mm and {turned:.5}° off, RMS {rms:.3} px",
        off * 1e3
    );
    assert!(off < 0.001, "camera {off} m off");
    assert!(turned < 0.01, "camera turned {turned}°");
    // A projector that is not in view poses nothing.
    let dark = omniwarp::structured::decode::Decoded {
        samples: vec![None; decoded.samples.len()],
        ..decoded.clone()
    };
    let e = camera_pose_from_projector(&dark, &guess, &front, &rig.doc.screen, 5000).unwrap_err();
    assert!(e.to_string().contains("only 0 camera pixels"), "{e}");
    // Why, in words (not Rust's `Rejected { dark: … }`).
    assert!(e.to_string().contains(" dark, "), "{e}");
    assert!(!e.to_string().contains('{'), "{e}");

    let calibrate = |pose_channel: &str| {
        let out = dir.path().join("right.json");
        let result = run(&[
            "calibrate",
            "--captures",
            right_caps.to_str().unwrap(),
            "--camera",
            guess_path.to_str().unwrap(),
            "--pose-captures",
            front_caps.to_str().unwrap(),
            "--pose-channel",
            pose_channel,
            "--rig",
            rig_path,
            "--channel",
            "right",
            "--model",
            "LENSMODEL_OPENCV4",
            "--out",
            out.to_str().unwrap(),
        ]);
        (result, out)
    };
    let ((ok, _, err), out) = calibrate("front");
    assert!(ok, "{err}");
    assert!(err.contains("camera pose from `front`"), "{err}");
    let doc: ChannelDoc = serde_json::from_str(&std::fs::read_to_string(out).unwrap()).unwrap();
    let fitted = Channel::from_doc(&doc, "").unwrap();
    let moved = (fitted.position - right.position).length();
    let turned = angle_between(fitted.rotation, right.rotation);
    eprintln!(
        "`right` calibrated through that pose: {:.3} mm and {turned:.5}° off",
        moved * 1e3
    );
    assert!(moved < 0.002, "`right` {moved} m off");
    assert!(turned < 0.02, "`right` turned {turned}°");
    let ((ok, _, err), _) = calibrate("right");
    assert!(
        !ok && err.contains("--pose-channel: is the channel being calibrated"),
        "{err}"
    );

    // The daemon, with both channels' captures uploaded under one view.
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .unwrap();
    runtime.block_on(async {
        use axum::body::Body;
        use axum::http::{Request, StatusCode, header};
        use common::server::{call, json, state_with, write};
        let text = std::fs::read_to_string(rig_path).unwrap();
        let s = state_with(None, None, omniwarp::rig::RigDoc::parse(&text).unwrap());
        let post = |pose_from: &str, markers: bool| {
            let mut body = serde_json::json!({"camera": guess.doc(), "model": "LENSMODEL_OPENCV4",
                "pose_from": pose_from});
            if markers {
                body["markers"] = serde_json::json!([]);
            }
            write(
                "POST",
                "/v1/channels/right/captures?view=cam",
                None,
                body.to_string(),
            )
        };
        let field = |body: &[u8]| json(body)["field"].as_str().map(String::from);
        for (id, dir) in [("right", &right_caps), ("front", &front_caps)] {
            for n in 0..58 {
                let png = std::fs::read(dir.join(format!("{n:03}.png"))).unwrap();
                let req = Request::put(format!("/v1/channels/{id}/captures/{n}?view=cam"))
                    .header(header::CONTENT_TYPE, "image/png")
                    .body(Body::from(png))
                    .unwrap();
                assert_eq!(call(&s, req).await.0, StatusCode::OK);
            }
            if id == "right" {
                // `front`'s captures are not in yet: the pose has nothing to come from.
                let (st, _, body) = call(&s, post("front", false)).await;
                assert_eq!(
                    (st, field(&body).as_deref()),
                    (StatusCode::BAD_REQUEST, Some("/pose_from"))
                );
            }
        }
        let (st, _, body) = call(&s, post("front", false)).await;
        let fitted = proposed(st, &body);
        assert!((fitted.position - right.position).length() < 0.002);
        for (pose_from, markers) in [("right", false), ("nowhere", false), ("front", true)] {
            let (st, _, body) = call(&s, post(pose_from, markers)).await;
            assert_eq!(
                (st, field(&body).as_deref()),
                (StatusCode::BAD_REQUEST, Some("/pose_from")),
                "{pose_from}: {}",
                String::from_utf8_lossy(&body)
            );
        }
    });
}

/// The cylinder example with its wall wrong: radius 2.15 m instead of 2, axis leaning 3°,
/// centre 9 cm off.
fn wrong_cylinder() -> serde_json::Value {
    let rig = std::fs::read_to_string("calibration/rigs/cylinder-270-3proj.json").unwrap();
    let mut doc: serde_json::Value = serde_json::from_str(&rig).unwrap();
    let lean = 3f64.to_radians();
    doc["screen"]["radius"] = serde_json::json!(2.15);
    doc["screen"]["axis"] = serde_json::json!([lean.sin(), lean.cos(), 0.0]);
    doc["screen"]["centre"] = serde_json::json!([0.05, 0.0, -0.08]);
    doc
}

/// The measured cylinder is the true one: radius 2 m, axis vertical through the origin.
fn assert_true_cylinder(screen: &omniwarp::surface::Screen) {
    let omniwarp::surface::Screen::Cylinder(c) = screen else {
        panic!("{screen:?}")
    };
    let axis = glam::DVec3::from_array(c.axis);
    let centre = glam::DVec3::from_array(c.centre);
    assert!((c.radius - 2.0).abs() < 0.002, "radius {}", c.radius);
    assert!(
        axis.angle_between(glam::DVec3::Y).to_degrees() < 0.05,
        "axis {axis}"
    );
    assert!(
        (centre - axis * centre.dot(axis)).length() < 0.005,
        "centre {centre}"
    );
    // The rest of the screen is the rig's.
    assert_eq!(c.height, [-1.0, 1.2]);
}

/// The two 1280×720 pinholes 1 m apart of the walkthrough in docs/calibration.md
/// (`camera-a.json`, `-b`).
const CAMERAS: [&str; 2] = [
    "calibration/examples/camera-a.json",
    "calibration/examples/camera-b.json",
];

#[test]
fn two_cameras_measure_the_cylinder_from_the_command_line() {
    // The cylinder example's centre projector filmed by both cameras; the wall is then
    // measured starting from a rig that has it wrong.
    let dir = tempfile::tempdir().unwrap();
    let rig = "calibration/rigs/cylinder-270-3proj.json";
    let run = |args: &[&str]| {
        let (ok, out, err) = run(args);
        assert!(ok, "{err}");
        out
    };
    let path = |name: &str| dir.path().join(name).to_str().unwrap().to_string();
    for (name, camera, seed) in [("a", CAMERAS[0], "1"), ("b", CAMERAS[1], "2")] {
        run(&[
            "simulate",
            "--rig",
            rig,
            "--channel",
            "centre",
            "--camera",
            camera,
            "--seed",
            seed,
            "--out",
            &path(name),
        ]);
    }
    std::fs::write(path("wrong.json"), wrong_cylinder().to_string()).unwrap();
    let out = run(&[
        "measure",
        "--rig",
        &path("wrong.json"),
        "--channel",
        "centre",
        "--captures",
        &path("a"),
        &path("b"),
        "--camera",
        CAMERAS[0],
        CAMERAS[1],
        "--out",
        &path("measured.json"),
    ]);
    eprintln!("{out}");
    let measured = Rig::read(Path::new(&path("measured.json"))).unwrap();
    assert_true_cylinder(&measured.doc.screen);
    assert_eq!(measured.doc.channels.len(), 3);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_daemon_measures_the_wall_from_two_views() {
    use axum::body::Body;
    use axum::http::{Request, StatusCode, header};
    use common::server::{call, get, json, state_with, write};
    let wrong = serde_json::from_value(wrong_cylinder()).unwrap();
    let s = state_with(None, None, wrong);
    let rig = Rig::read(Path::new("calibration/rigs/cylinder-270-3proj.json")).unwrap();
    let projector = rig.channel("centre").unwrap().clone();
    let cameras = CAMERAS.map(|p| {
        let doc: ChannelDoc = serde_json::from_str(&std::fs::read_to_string(p).unwrap()).unwrap();
        Channel::from_doc(&doc, "").unwrap()
    });
    for (camera, view) in cameras.iter().zip(["a", "b"]) {
        let bench = Simulator::new(&rig, &projector, camera, SimulatorOptions::default()).unwrap();
        for n in 0..bench.patterns().len() {
            let png = bench.capture(n).unwrap().png().unwrap();
            let req = Request::put(format!("/v1/channels/centre/captures/{n}?view={view}"))
                .header(header::CONTENT_TYPE, "image/png")
                .body(Body::from(png))
                .unwrap();
            assert_eq!(call(&s, req).await.0, StatusCode::OK);
        }
    }
    let (_, _, body) = call(&s, get("/v1/channels/centre/captures?view=b")).await;
    assert_eq!(json(&body)["missing"], serde_json::json!([]));
    let (_, _, body) = call(&s, get("/v1/channels/centre/captures")).await;
    assert_eq!(json(&body)["received"], serde_json::json!([]));
    let wall = |views: serde_json::Value| {
        write(
            "POST",
            "/v1/channels/centre/wall",
            None,
            serde_json::json!({ "views": views }).to_string(),
        )
    };
    let view = |i: usize, name: Option<&str>| serde_json::json!({"camera": cameras[i].doc(), "view": name});
    let (st, _, body) = call(
        &s,
        wall(serde_json::json!([view(0, Some("a")), view(1, Some("b"))])),
    )
    .await;
    assert_eq!(st, StatusCode::OK, "{}", String::from_utf8_lossy(&body));
    let answer = json(&body);
    assert_true_cylinder(&serde_json::from_value(answer["screen"].clone()).unwrap());
    assert_eq!(answer["rig_screen"]["radius"], 2.15);
    assert!(answer["count"].as_u64().unwrap() > 20_000, "{answer}");

    // Refused, each by name: one view, a view name that is not one, a view with nothing
    // uploaded, and a view name in the query.
    for (views, field) in [
        (serde_json::json!([view(0, Some("a"))]), "/views"),
        (
            serde_json::json!([view(0, Some("a")), view(1, Some("b c"))]),
            "/views/1/view",
        ),
        (
            serde_json::json!([view(0, Some("a")), view(1, None)]),
            "/views/1/view",
        ),
    ] {
        let (st, _, body) = call(&s, wall(views)).await;
        assert_eq!(
            (st, json(&body)["field"].as_str()),
            (StatusCode::BAD_REQUEST, Some(field)),
            "{}",
            String::from_utf8_lossy(&body)
        );
    }
    let (st, _, body) = call(&s, get("/v1/channels/centre/captures?view=%2E%2E")).await;
    assert_eq!(
        (st, json(&body)["field"].as_str()),
        (StatusCode::BAD_REQUEST, Some("view"))
    );
}

/// The corner example: two walls at a right angle, one projector across them, a pinhole
/// camera beside it.
fn corner() -> (Rig, Channel) {
    let rig = Rig::read(Path::new("calibration/rigs/corner-90-1proj.json")).unwrap();
    let text = std::fs::read_to_string("calibration/examples/camera-corner.json").unwrap();
    let camera: ChannelDoc = serde_json::from_str(&text).unwrap();
    (rig, Channel::from_doc(&camera, "").unwrap())
}

#[test]
fn xor_codes_decode_the_corner_where_inter_reflection_defeats_the_gray_code() {
    use omniwarp::structured::Code;
    let (rig, camera) = corner();
    let projector = rig.channels[0].clone();
    // Light bounced between the walls as strong as the direct light, on average; the exposure
    // lowered so that the brightest pixels, near the corner, do not saturate.
    let opts = SimulatorOptions {
        interreflection: 1.0,
        exposure: 0.4,
        ..SimulatorOptions::default()
    };
    let mut figures = Vec::new();
    for code in [Code::Gray, Code::Xor] {
        let bench =
            Simulator::new(&rig, &projector, &camera, SimulatorOptions { code, ..opts }).unwrap();
        let decoded = decode(
            bench.patterns(),
            &capture_all(&bench),
            &DecodeOptions::default(),
        )
        .unwrap();
        let (mut errors, lit) = decode_errors(&bench, &decoded);
        let gross = errors.iter().filter(|&&e| e > 1.0).count();
        let p50 = percentile(&mut errors, 0.5);
        let decoded_share = errors.len() as f64 / lit as f64;
        let inconsistent = decoded.rejected.inconsistent as f64 / lit as f64;
        eprintln!(
            "{}: {:.1} % of {lit} lit pixels decoded, {:.2} % refused as inconsistent, \
             median {p50:.4} px, {gross} above 1 px; rejected {:?}",
            code.name(),
            100.0 * decoded_share,
            100.0 * inconsistent,
            decoded.rejected
        );
        assert!(p50 < 0.1, "{}: median {p50}", code.name());
        figures.push((
            decoded_share,
            inconsistent,
            gross as f64 / errors.len() as f64,
        ));
    }
    let ((gray, gray_bad, gray_gross), (xor, xor_bad, xor_gross)) = (figures[0], figures[1]);
    assert!(gray_bad > 0.05, "the Gray code held: {gray_bad}");
    assert!(xor_bad < 0.005, "XOR: {xor_bad} inconsistent");
    assert!(
        xor > 0.85 && xor > gray + 0.15,
        "decoded: Gray {gray}, XOR {xor}"
    );
    assert!(xor_gross < 0.001, "XOR: {xor_gross} gross");
    assert!(
        xor_gross < gray_gross,
        "gross: Gray {gray_gross}, XOR {xor_gross}"
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_daemon_serves_the_xor_code_and_keeps_its_captures_apart() {
    use axum::body::Body;
    use axum::http::{Request, StatusCode, header};
    use common::server::{call, get, json, state_with, write};
    use omniwarp::structured::{Code, PatternSet};
    let text = std::fs::read_to_string("calibration/rigs/dome-180-tilt15-5proj.json").unwrap();
    let s = state_with(None, None, omniwarp::rig::RigDoc::parse(&text).unwrap());
    let set = PatternSet::new(1920, 1200).unwrap();
    let frames = set.frames();
    // Frame 2 is the first (coarsest) x bit, frame 2 + 2·bits the first x phase step.
    let phase = 2 + 2 * set.bits(omniwarp::structured::Axis::X) as usize;
    for (n, differ) in [(2, true), (phase, false)] {
        let mut served = Vec::new();
        for (query, code) in [("", Code::Gray), ("?code=xor", Code::Xor)] {
            let (st, _, png) =
                call(&s, get(&format!("/v1/channels/front/pattern/{n}{query}"))).await;
            assert_eq!(st, StatusCode::OK);
            let grey = Grey::decode(&png, "body").unwrap();
            assert_eq!(
                grey,
                set.with_code(code).image(frames[n]),
                "frame {n}{query}"
            );
            served.push(grey);
        }
        assert_eq!(served[0] != served[1], differ, "frame {n}");
    }
    let (st, _, body) = call(&s, get("/v1/channels/front/pattern/2?code=grey")).await;
    assert_eq!(
        (st, json(&body)["field"].as_str()),
        (StatusCode::BAD_REQUEST, Some("code"))
    );
    // A capture under one code is not one under the other.
    let png = set.with_code(Code::Xor).image(frames[2]).png().unwrap();
    let req = Request::put("/v1/channels/front/captures/2?code=xor")
        .header(header::CONTENT_TYPE, "image/png")
        .body(Body::from(png))
        .unwrap();
    assert_eq!(call(&s, req).await.0, StatusCode::OK);
    for (query, received) in [
        ("?code=xor", serde_json::json!([2])),
        ("", serde_json::json!([])),
    ] {
        let (_, _, body) = call(&s, get(&format!("/v1/channels/front/captures{query}"))).await;
        assert_eq!(json(&body)["received"], received, "{query}");
    }
    let camera = fisheye(640, 360).doc();
    let body = serde_json::json!({"views": [{"camera": camera}, {"camera": camera, "view": "b"}],
        "code": "grey"});
    let req = write("POST", "/v1/channels/front/wall", None, body.to_string());
    let (st, _, body) = call(&s, req).await;
    assert_eq!(
        (st, json(&body)["field"].as_str()),
        (StatusCode::BAD_REQUEST, Some("/code"))
    );
}

/// A 16-bit camera capture is decoded at 16 bits: two pixels 100/65535 apart share an 8-bit
/// level, and the decoder must still tell them apart (they were cut to 8 bits before).
#[test]
fn a_sixteen_bit_capture_is_read_at_sixteen_bits() {
    let levels: [u16; 2] = [1000, 1100];
    let mut file = Vec::new();
    let mut enc = png::Encoder::new(&mut file, 2, 1);
    enc.set_color(png::ColorType::Grayscale);
    enc.set_depth(png::BitDepth::Sixteen);
    let mut w = enc.write_header().unwrap();
    let bytes: Vec<u8> = levels.iter().flat_map(|v| v.to_be_bytes()).collect();
    w.write_image_data(&bytes).unwrap();
    w.finish().unwrap();
    let read = Grey::decode(&file, "capture").unwrap();
    assert_eq!(read.data, [4, 4], "the 8-bit view");
    let step = read.level(1) - read.level(0);
    assert!(
        (step - 100.0 / 257.0).abs() < 1e-12,
        "levels differ by {step}"
    );
    // Written back, the capture keeps its 16 bits; an 8-bit pattern stays 8-bit.
    assert_eq!(Grey::decode(&read.png().unwrap(), "again").unwrap(), read);
    let pattern = Grey::new(2, 1, vec![4, 4]);
    let again = Grey::decode(&pattern.png().unwrap(), "pattern").unwrap();
    assert_eq!((again.deep.is_none(), again.level(1)), (true, 4.0));
}
