//! Walls: warps against independent computations, blends that sum to one and fade at every
//! projector edge, seamless overlaps on the example rigs, and bad rigs named by JSON pointer.

use glam::{DMat3, DVec3};
use omniwarp::lens::{Lens, LensModel};
use omniwarp::rig::Rig;
use std::path::Path;

fn angle(a: DVec3, b: DVec3) -> f64 {
    a.cross(b).length().atan2(a.dot(b))
}

fn example(name: &str) -> Rig {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("calibration/rigs")
        .join(name);
    Rig::read(&path).unwrap_or_else(|e| panic!("{name}: {e}"))
}

fn rig_json(screen: &str, channels: &str) -> String {
    format!(r#"{{ "format": 1, "screen": {screen}, "eye": [0, 0, 0], "channels": [{channels}] }}"#)
}

const CYLINDER: &str =
    r#"{ "kind": "cylinder", "radius": 2.0, "height": [-3, 3], "arc": [-150, 150] }"#;
const DOME: &str = r#"{ "kind": "dome", "radius": 3.0, "tilt": 15, "min_elevation": -10 }"#;
const PLANE: &str =
    r#"{ "kind": "plane", "centre": [0, 0, -3], "normal": [0, 0, 1], "width": 14, "height": 12 }"#;

#[test]
fn a_pinhole_at_the_eye_shows_its_own_perspective_whatever_the_wall() {
    let ch = r#"{ "id": "p", "resolution": [64, 48], "lens": { "model": "LENSMODEL_PINHOLE", "intrinsics": [40, 40, 31.5, 23.5] },
                  "pose": { "position": [0, 0, 0], "look_to": [0.3, 0.2, -1], "look_up": [0, 1, 0] } }"#;
    for screen in [CYLINDER, DOME, PLANE] {
        let rig = Rig::from_json(&rig_json(screen, ch), Path::new(".")).unwrap();
        let c = &rig.channels[0];
        let w = rig.warp(c);
        let mut worst: f64 = 0.0;
        for j in 0..48 {
            for i in 0..64 {
                let v = w
                    .map
                    .direction(i, j)
                    .unwrap_or_else(|| panic!("{screen}: ({i}, {j}) missed"));
                let local = DVec3::new((i as f64 - 31.5) / 40.0, (j as f64 - 23.5) / 40.0, 1.0);
                worst = worst.max(angle(v, c.rotation * local));
            }
        }
        // The map stores f32: about 1e-7 rad.
        assert!(
            worst.to_degrees() < 1e-5,
            "{screen}: {}°",
            worst.to_degrees()
        );
    }
}

/// The ray–surface intersections written out here, apart from the library's.
fn cylinder_hit(o: DVec3, d: DVec3, r: f64) -> DVec3 {
    let (a, b, c) = (
        d.x * d.x + d.z * d.z,
        2.0 * (o.x * d.x + o.z * d.z),
        o.x * o.x + o.z * o.z - r * r,
    );
    let t = (-b + (b * b - 4.0 * a * c).sqrt()) / (2.0 * a);
    o + d * t
}

fn sphere_hit(o: DVec3, d: DVec3, r: f64) -> DVec3 {
    let (b, c) = (2.0 * o.dot(d), o.dot(o) - r * r);
    let t = (-b + (b * b - 4.0 * c).sqrt()) / 2.0;
    o + d * t
}

#[test]
fn an_off_eye_projector_with_distortion_matches_an_independent_warp() {
    let ch = r#"{ "id": "q", "resolution": [80, 60], "lens": { "model": "LENSMODEL_OPENCV5", "intrinsics": [45, 46, 40.2, 29.1, -0.08, 0.02, 0.001, -0.0005, -0.003] },
                  "pose": { "position": [0.3, -0.4, 0.5], "look_to": [-0.2, 0.3, -1], "look_up": [0.1, 1, 0] } }"#;
    let lens = Lens::new(
        LensModel::OpenCv(5),
        vec![45.0, 46.0, 40.2, 29.1, -0.08, 0.02, 0.001, -0.0005, -0.003],
    )
    .unwrap();
    for (screen, hit) in [
        (CYLINDER, cylinder_hit as fn(DVec3, DVec3, f64) -> DVec3),
        (DOME, sphere_hit),
    ] {
        let r = if screen == CYLINDER { 2.0 } else { 3.0 };
        let rig = Rig::from_json(&rig_json(screen, ch), Path::new(".")).unwrap();
        let c = &rig.channels[0];
        let f = DVec3::new(-0.2, 0.3, -1.0).normalize();
        let right = f.cross(DVec3::new(0.1, 1.0, 0.0)).normalize();
        let rot = DMat3::from_cols(right, f.cross(right), f);
        assert!(rot.abs_diff_eq(c.rotation, 1e-12));
        let w = rig.warp(c);
        let (mut worst, mut n) = (0.0f64, 0);
        for j in 0..60 {
            for i in 0..80 {
                let Some(v) = w.map.direction(i, j) else {
                    continue;
                };
                let ray = rot * lens.unproject([i as f64, j as f64]).unwrap();
                let p = hit(DVec3::new(0.3, -0.4, 0.5), ray, r);
                worst = worst.max(angle(v, p.normalize()));
                n += 1;
            }
        }
        assert!(
            n > 3000 && worst < 1e-6,
            "{screen}: {n} pixels, {worst} rad"
        );
    }
}

#[test]
fn blend_weights_sum_to_one_and_fade_at_every_edge() {
    for name in [
        "cylinder-270-3proj.json",
        "dome-180-tilt15-5proj.json",
        "flat-2proj.json",
    ] {
        let rig = example(name).downscaled(16).unwrap();
        let (mut overlap_pixels, mut edge_checked) = (0, 0);
        for (ci, ch) in rig.channels.iter().enumerate() {
            let w = rig.warp(ch);
            let weights = rig.blend_weights(ch, &w.points);
            for (n, p) in w.points.iter().enumerate() {
                let Some(p) = p else {
                    assert_eq!(weights[n], 0.0);
                    continue;
                };
                let at = rig.weights_at(*p);
                let total: f64 = at.iter().map(|x| x.1).sum();
                assert!((total - 1.0).abs() < 1e-9, "{name}: weights sum to {total}");
                if let Some(own) = at.iter().find(|x| x.0 == ci) {
                    assert!(
                        (own.1 - f64::from(weights[n])).abs() < 1e-5,
                        "{name} {}: {} vs {}",
                        ch.id,
                        own.1,
                        weights[n]
                    );
                }
                if at.len() > 1 {
                    overlap_pixels += 1;
                    let (i, j) = (n % ch.width as usize, n / ch.width as usize);
                    // Where every projector lighting the point is at its own edge (corners of
                    // overlaps) the shares are a tie; elsewhere this edge must hand over.
                    let others_inside = rig
                        .channels
                        .iter()
                        .filter(|o| o.id != ch.id)
                        .filter_map(|o| rig.pixel_lighting(o, *p).map(|q| (o, q)))
                        .any(|(o, q)| {
                            let d = (q[0] + 0.5)
                                .min(f64::from(o.width) - 0.5 - q[0])
                                .min(q[1] + 0.5)
                                .min(f64::from(o.height) - 0.5 - q[1]);
                            d > 0.125 * f64::from(o.width.min(o.height))
                        });
                    let at_edge = i == 0
                        || j == 0
                        || i + 1 == ch.width as usize
                        || j + 1 == ch.height as usize;
                    if at_edge && others_inside {
                        assert!(
                            weights[n] < 0.02,
                            "{name} {}: {} at its edge pixel ({i}, {j})",
                            ch.id,
                            weights[n]
                        );
                        edge_checked += 1;
                    }
                }
            }
        }
        println!(
            "{name}: {overlap_pixels} overlap pixels, {edge_checked} of them on a projector's edge"
        );
        assert!(
            overlap_pixels > 50 && edge_checked > 5,
            "{name}: {overlap_pixels} / {edge_checked}"
        );
    }
}

/// Where two projectors overlap they must show the same content: A's warp at its pixel and B's
/// warp map, interpolated at the pixel of B that lights the same wall point, agree to well
/// under one of B's pixels.
#[test]
fn example_rigs_have_no_seams_in_their_overlaps() {
    for name in [
        "cylinder-270-3proj.json",
        "dome-180-tilt15-5proj.json",
        "flat-2proj.json",
    ] {
        let rig = example(name).downscaled(8).unwrap();
        let warps: Vec<_> = rig.channels.iter().map(|c| rig.warp(c)).collect();
        let mut worst_px: f64 = 0.0;
        let mut compared = 0;
        for (a, wa) in rig.channels.iter().zip(&warps) {
            for (n, p) in wa.points.iter().enumerate().step_by(7) {
                let Some(p) = p else { continue };
                let va = wa
                    .map
                    .direction(n % a.width as usize, n / a.width as usize)
                    .unwrap();
                for (b, wb) in rig
                    .channels
                    .iter()
                    .zip(&warps)
                    .filter(|(b, _)| b.id != a.id)
                {
                    let Some(q) = rig.pixel_lighting(b, *p) else {
                        continue;
                    };
                    let (x, y) = (q[0].floor() as usize, q[1].floor() as usize);
                    if x + 1 >= b.width as usize || y + 1 >= b.height as usize {
                        continue;
                    }
                    let (fx, fy) = (q[0] - x as f64, q[1] - y as f64);
                    let corners = [(x, y), (x + 1, y), (x, y + 1), (x + 1, y + 1)]
                        .map(|(i, j)| wb.map.direction(i, j));
                    let [Some(c00), Some(c10), Some(c01), Some(c11)] = corners else {
                        continue;
                    };
                    let vb = (c00 * (1.0 - fx) * (1.0 - fy)
                        + c10 * fx * (1.0 - fy)
                        + c01 * (1.0 - fx) * fy
                        + c11 * fx * fy)
                        .normalize();
                    let pixel = angle(c00, c10).max(angle(c00, c01));
                    worst_px = worst_px.max(angle(va, vb) / pixel);
                    compared += 1;
                }
            }
        }
        println!("{name}: {compared} overlap samples, largest disagreement {worst_px:.3} px");
        assert!(
            compared > 20 && worst_px < 0.05,
            "{name}: {compared} samples, {worst_px} px"
        );
    }
}

#[test]
fn bad_rigs_are_refused_with_the_field_named() {
    let good_ch = r#"{ "id": "a", "resolution": [64, 48], "lens": { "model": "LENSMODEL_PINHOLE", "intrinsics": [40, 40, 31.5, 23.5] }, "pose": { "position": [0, 0, 0], "look_to": [0, 0, -1], "look_up": [0, 1, 0] } }"#;
    assert!(Rig::from_json(&rig_json(PLANE, good_ch), Path::new(".")).is_ok());
    let cases = [
        (
            rig_json(
                PLANE,
                &good_ch.replace("\"id\": \"a\",", "\"id\": \"a\", \"colour\": 1,"),
            ),
            "/channels/0",
            "colour",
        ),
        (
            rig_json(
                PLANE,
                &good_ch.replace("[40, 40, 31.5, 23.5]", "[40, 40, 31.5]"),
            ),
            "/channels/0/lens/intrinsics",
            "takes 4",
        ),
        (
            rig_json(
                PLANE,
                &good_ch.replace("LENSMODEL_PINHOLE", "LENSMODEL_NOPE"),
            ),
            "/channels/0/lens/model",
            "unknown",
        ),
        (
            rig_json(PLANE, &good_ch.replace("[64, 48]", "[0, 48]")),
            "/channels/0/resolution",
            "between",
        ),
        (
            rig_json(PLANE, &format!("{good_ch}, {good_ch}")),
            "/channels/1/id",
            "another channel",
        ),
        (
            rig_json(
                PLANE,
                &good_ch.replace(
                    "\"look_to\": [0, 0, -1], \"look_up\": [0, 1, 0]",
                    "\"look_to\": [0, 0, -1]",
                ),
            ),
            "/channels/0/pose",
            "either",
        ),
        (
            rig_json(
                PLANE,
                &good_ch.replace("\"look_up\": [0, 1, 0]", "\"look_up\": [0, 0, -2]"),
            ),
            "/channels/0/pose/look_up",
            "parallel",
        ),
        (
            rig_json(&PLANE.replace("\"width\": 14", "\"width\": -14"), good_ch),
            "/screen/width",
            "positive",
        ),
        (
            rig_json(
                &CYLINDER.replace("\"arc\": [-150, 150]", "\"arc\": [150, -150]"),
                good_ch,
            ),
            "/screen/arc",
            "from < to",
        ),
        (
            rig_json(PLANE, good_ch).replace("\"format\": 1", "\"format\": 2"),
            "/format",
            "only format 1",
        ),
        (rig_json(PLANE, "").to_string(), "/channels", "at least one"),
        (
            rig_json(PLANE, good_ch).replace("\"eye\": [0, 0, 0]", "\"eye\": [0, 0]"),
            "/eye",
            "",
        ),
    ];
    for (json, pointer, why) in cases {
        let e = Rig::from_json(&json, Path::new("."))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains(&format!("`{pointer}")) && e.contains(why),
            "{pointer}: {e}"
        );
    }
}

#[test]
fn mesh_screens_load_from_obj_beside_the_rig() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(
        dir.path().join("wall.obj"),
        "# a 6 m × 4 m wall at z = -3\nv -3 -2 -3\nv 3 -2 -3\nv 3 2 -3\nv -3 2 -3\nf 1 2 3 4\n",
    )
    .unwrap();
    let ch = r#"{ "id": "m", "resolution": [32, 24], "lens": { "model": "LENSMODEL_PINHOLE", "intrinsics": [30, 30, 15.5, 11.5] }, "pose": { "position": [0, 0, 0], "look_to": [0, 0, -1], "look_up": [0, 1, 0] } }"#;
    let text = rig_json(r#"{ "kind": "mesh", "obj": "wall.obj" }"#, ch);
    let path = dir.path().join("rig.json");
    std::fs::write(&path, &text).unwrap();
    let rig = Rig::read(&path).unwrap();
    let w = rig.warp(&rig.channels[0]);
    let p = w.points[12 * 32 + 16].unwrap();
    assert!((p.z + 3.0).abs() < 1e-12, "{p}");
    std::fs::write(dir.path().join("wall.obj"), "v 0 0 0\nf 1 2 3\n").unwrap();
    let e = Rig::read(&path).unwrap_err().to_string();
    assert!(e.contains("/screen/obj") && e.contains("line 2"), "{e}");
}

/// The 16-bit PNG masks themselves, as a media server reads them: decoded, linearised with the
/// gamma they were written for, and summed over every projector lighting a wall point (the
/// others' masks interpolated at their pixel of that point), they add up to one.
#[test]
fn the_blend_pngs_a_media_server_gets_sum_to_one() {
    use omniwarp::rig::{BlendOptions, blend_png_bytes};
    let gamma = 2.2;
    for name in [
        "cylinder-270-3proj.json",
        "dome-180-tilt15-5proj.json",
        "flat-2proj.json",
    ] {
        let rig = example(name).downscaled(16).unwrap();
        let warps: Vec<_> = rig.channels.iter().map(|c| rig.warp(c)).collect();
        // Each channel's mask as decoded from its PNG, linear.
        let masks: Vec<Vec<f64>> = rig
            .channels
            .iter()
            .zip(&warps)
            .map(|(ch, w)| {
                let weights = rig.blend_weights(ch, &w.points);
                let png = blend_png_bytes(
                    ch.width,
                    ch.height,
                    &weights,
                    BlendOptions {
                        gamma,
                        ..BlendOptions::default()
                    },
                )
                .unwrap();
                let mut reader = png::Decoder::new(std::io::Cursor::new(png))
                    .read_info()
                    .unwrap();
                let mut buf = vec![0; reader.output_buffer_size().unwrap()];
                let info = reader.next_frame(&mut buf).unwrap();
                assert_eq!(info.bit_depth, png::BitDepth::Sixteen);
                assert_eq!(info.color_type, png::ColorType::Grayscale);
                buf[..info.buffer_size()]
                    .chunks(2)
                    .map(|c| (f64::from(u16::from_be_bytes([c[0], c[1]])) / 65535.0).powf(gamma))
                    .collect()
            })
            .collect();
        // A mask sampled bilinearly at continuous pixel q (centres at integers), from the
        // neighbours that light the wall: a neighbour off the wall has weight 0 but sends no
        // light there either.
        let sample = |k: usize, q: [f64; 2]| {
            let ch = &rig.channels[k];
            let (w, h) = (ch.width as isize, ch.height as isize);
            let (x0, y0) = (q[0].floor(), q[1].floor());
            let (fx, fy) = (q[0] - x0, q[1] - y0);
            let (mut sum, mut norm) = (0.0, 0.0);
            for (di, dj, b) in [
                (0, 0, (1.0 - fx) * (1.0 - fy)),
                (1, 0, fx * (1.0 - fy)),
                (0, 1, (1.0 - fx) * fy),
                (1, 1, fx * fy),
            ] {
                let (i, j) = (x0 as isize + di, y0 as isize + dj);
                if i < 0 || j < 0 || i >= w || j >= h {
                    continue;
                }
                let n = (j * w + i) as usize;
                if warps[k].points[n].is_some() {
                    sum += b * masks[k][n];
                    norm += b;
                }
            }
            (norm > 0.0).then(|| sum / norm)
        };
        let (mut worst, mut overlaps, mut checked, mut skipped) = (0.0f64, 0, 0, 0);
        for (k, (ch, w)) in rig.channels.iter().zip(&warps).enumerate() {
            for (n, p) in w.points.iter().enumerate() {
                let Some(p) = p else { continue };
                let mut total = masks[k][n];
                let mut others = 0;
                // Within two pixels of a projector's image edge, where every ramp nears 0 and
                // the shares of two vanishing weights change from one pixel to the next, the
                // interpolated sum is not meaningful; those pixels are counted, not checked.
                let near_edge = |c: &omniwarp::rig::Channel, q: [f64; 2]| {
                    q[0].min(f64::from(c.width) - 1.0 - q[0])
                        .min(q[1])
                        .min(f64::from(c.height) - 1.0 - q[1])
                        < 2.0
                };
                let mut border = near_edge(
                    ch,
                    [
                        (n % ch.width as usize) as f64,
                        (n / ch.width as usize) as f64,
                    ],
                );
                for (o, other) in rig.channels.iter().enumerate() {
                    if o == k {
                        continue;
                    }
                    let Some(q) = rig.pixel_lighting(other, *p) else {
                        continue;
                    };
                    if let Some(m) = sample(o, q) {
                        total += m;
                        others += 1;
                        border |= near_edge(other, q);
                    }
                }
                overlaps += usize::from(others > 0);
                if border {
                    skipped += 1;
                    continue;
                }
                checked += 1;
                worst = worst.max((total - 1.0).abs());
                assert!(
                    (total - 1.0).abs() < MASK_SUM_TOLERANCE,
                    "{name} {} pixel {n}: the masks sum to {total}",
                    ch.id
                );
            }
        }
        println!(
            "{name}: {checked} lit pixels checked ({skipped} at an image edge), {overlaps} in \
             overlaps, worst |Σ − 1| {worst:.4}"
        );
        assert!(
            overlaps > 50 && checked > 5 * skipped,
            "{name}: {overlaps} / {checked} / {skipped}"
        );
    }
}

/// Worst |Σ − 1| away from image edges, measured at 1/16 of the rigs' resolution: 0.025
/// (cylinder), 0.016 (dome), 0.048 (flat), from bilinear sampling of the others' ramps; reading
/// the masks as linear instead of gamma 2.2 puts the sums off by 0.2 and more.
const MASK_SUM_TOLERANCE: f64 = 0.06;

#[test]
fn the_published_rig_schema_is_the_one_the_types_generate() {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("api/rig.schema.json");
    let published = std::fs::read_to_string(&path).unwrap_or_default();
    assert!(
        published == omniwarp::rig::schema::text(),
        "api/rig.schema.json is not what the rig types generate: `omniwarp rig schema > \
         api/rig.schema.json`"
    );
}

#[test]
fn a_mistyped_field_is_named_and_described_from_the_schema() {
    let dome = std::fs::read_to_string(
        std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("calibration/rigs/dome-180-tilt15-5proj.json"),
    )
    .unwrap();
    let mut doc: serde_json::Value = serde_json::from_str(&dome).unwrap();
    doc["screen"]["radius"] = "3 m".into();
    let e = omniwarp::rig::RigDoc::parse(&doc.to_string())
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("/screen/radius") && e.contains("The sphere's radius, metres"),
        "{e}"
    );
    let mut doc: serde_json::Value = serde_json::from_str(&dome).unwrap();
    doc["channels"][2]["lens"] = serde_json::json!({"throw_ratio": "long"});
    let e = omniwarp::rig::RigDoc::parse(&doc.to_string())
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("/channels/2/lens/throw_ratio") && e.contains("Throw distance over image width"),
        "{e}"
    );
    // Descriptions are written for people: no rustdoc links left in them.
    assert!(!omniwarp::rig::schema::text().contains("[`"));
}
