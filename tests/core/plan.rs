//! Rig plans (src/rig/plan/) against figures worked out by hand: a flat wall lit by two
//! pinhole projectors, the example dome's waste, and throw ratios as a data sheet gives them.

use omniwarp::rig::{Rig, RigDoc};
use serde_json::json;

/// A 6 m × 2.5 m wall 3 m before the eye, and two pinhole projectors beside the eye at
/// x = ±0.5 m looking straight at it, f = 1000 px over 1000×500 pixels: each lights 3 m × 1.5 m
/// (x from −2 to 1 and from −1 to 2), overlapping over x from −1 to 1.
fn two_on_a_flat_wall() -> Rig {
    let projector = |id: &str, x: f64| {
        json!({"id": id, "resolution": [1000, 500],
            "lens": {"model": "LENSMODEL_PINHOLE", "intrinsics": [1000.0, 1000.0, 499.5, 249.5]},
            "pose": {"position": [x, 0, 0], "look_to": [0, 0, -1], "look_up": [0, 1, 0]}})
    };
    let doc = json!({"format": 1,
        "screen": {"kind": "plane", "centre": [0, 0, -3], "normal": [0, 0, 1], "up": [0, 1, 0],
            "width": 6.0, "height": 2.5},
        "eye": [0, 0, 0],
        "channels": [projector("left", -0.5), projector("right", 0.5)]});
    Rig::from_doc(RigDoc::parse(&doc.to_string()).unwrap()).unwrap()
}

#[test]
fn a_flat_wall_with_two_projectors_is_planned_as_worked_out_by_hand() {
    let rig = two_on_a_flat_wall();
    let plan = rig.plan(0.25).unwrap();
    let w = &plan.wall;
    assert!((w.area - 15.0).abs() < 0.05, "area {}", w.area);
    // Lit: 3 m × 1.5 m each, 2 m × 1.5 m of it shared; of the wall's 15 m².
    let expected = [1.0 - 6.0 / 15.0, 3.0 / 15.0, 3.0 / 15.0, 0.0];
    for (got, want) in w.lit_by.iter().zip(expected) {
        assert!(
            (got - want).abs() < 0.006,
            "lit by {:?}, want {expected:?}",
            w.lit_by
        );
    }
    // The overlap spans x from −1 to 1 on the wall: 2·atan(1/3) = 36.87° seen from the eye at
    // its height, a little less along rows above and below it (cos of the latitude, at most
    // 14°).
    let [o] = &plan.overlaps[..] else {
        panic!("{:?}", plan.overlaps)
    };
    let by_hand = 2.0 * (1.0f64 / 3.0).atan().to_degrees();
    assert_eq!(o.across, "longitude");
    assert!(
        (o.width - by_hand).abs() < 0.75 && o.width <= by_hand + 0.25,
        "{} against {by_hand}",
        o.width
    );
    assert!((o.wall_share - 0.2).abs() < 0.006, "{}", o.wall_share);
    // Straight ahead both projectors give f px per radian each way: 1000·π/180 px/°.
    let ahead = plan.point(0.0, 0.0).unwrap();
    assert_eq!(ahead.channels, vec![0, 1]);
    let want = 1000.0 * std::f64::consts::PI / 180.0;
    assert!(
        (ahead.pixels_per_degree - want).abs() < 0.05,
        "{}",
        ahead.pixels_per_degree
    );
    // Where the eye looks at x = 1.5 m only the right projector lights the wall (x = 1 m from
    // its axis): along the row x = 3·tan φ gives f·sec²φ = 1250 px/rad, down the column
    // y = 3·tan θ / cos φ gives 1000·√1.25 px/rad; the density is their geometric mean.
    let lon = (0.5f64).atan().to_degrees();
    let edge = plan.point(lon, 0.0).unwrap();
    assert_eq!(edge.channels, vec![1]);
    let want = (1250.0 * 1000.0 * 1.25f64.sqrt()).sqrt().to_radians();
    assert!(
        (edge.pixels_per_degree - want).abs() < 0.1,
        "{} against {want}",
        edge.pixels_per_degree
    );
    // Brightness: cos i / d² summed. Ahead, each projector 0.5 m off: 2 × (3/√9.25)/9.25; at
    // x = 1.5, one projector 1 m off: (3/√10)/10.
    let ahead_sum = 2.0 * (3.0 / 9.25f64.sqrt()) / 9.25;
    let at_edge = (3.0 / 10.0f64.sqrt()) / 10.0;
    let ratio = ahead.brightness / edge.brightness;
    assert!(
        (ratio - ahead_sum / at_edge).abs() < 0.02,
        "{ratio} against {}",
        ahead_sum / at_edge
    );
    // Every pixel of both lands on the wall.
    for c in &plan.channels {
        assert!(c.on_wall > 0.999 && c.wasted_pixels == 0, "{c:?}");
        assert!((c.wall_share - 0.3).abs() < 0.006, "{c:?}");
    }
}

#[test]
fn the_example_dome_wastes_a_third_of_each_side_projector() {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    let rig = Rig::read(&root.join("calibration/rigs/dome-180-tilt15-5proj.json")).unwrap();
    let plan = rig.plan(1.0).unwrap();
    // A hemisphere seen from its centre: 2π steradians.
    let hemisphere = 2.0 * std::f64::consts::PI;
    assert!((plan.wall.solid_angle - hemisphere).abs() < 0.01 * hemisphere);
    assert!((plan.wall.lit_by.iter().sum::<f64>() - 1.0).abs() < 1e-9);
    for c in &plan.channels {
        let waste = 1.0 - c.on_wall;
        if c.id == "zenith" {
            assert!(waste < 0.001, "{c:?}");
        } else {
            assert!((waste - 0.34).abs() < 0.01, "{} wastes {waste}", c.id);
            let pixels = 1920.0 * 1200.0;
            assert!((c.wasted_pixels as f64 / pixels - waste).abs() < 1e-6);
        }
    }
    // Neighbours on the ring overlap side by side, each with the zenith one above the other.
    for o in &plan.overlaps {
        let want = if o.channels.contains(&"zenith".to_string()) {
            "latitude"
        } else {
            "longitude"
        };
        assert_eq!(o.across, want, "{o:?}");
    }
    assert_eq!(plan.overlaps.len(), 8);
    // The picture is a dome master: its centre (the content's zenith) is lit, its corners are
    // outside the circle.
    let img = plan.picture(&rig, 600).unwrap();
    let side = 400;
    assert_eq!(
        img.get(side / 2, side / 2)[..3],
        img.get(side / 2, side / 2 + 1)[..3]
    );
    assert_ne!(img.get(side / 2, side / 2), img.get(1, 1));
}

#[test]
fn a_throw_ratio_and_lens_shift_light_the_wall_a_data_sheet_says() {
    // Throw ratio 1.5 three metres from a wall: an image 2 m wide; 1920×1080 makes it 1.125 m
    // tall, and a vertical shift of +0.5 puts the optical axis on its bottom edge.
    let doc = |lens: serde_json::Value| {
        json!({"format": 1,
            "screen": {"kind": "plane", "centre": [0, 0, -3], "normal": [0, 0, 1], "up": [0, 1, 0],
                "width": 8.0, "height": 4.0},
            "eye": [0, 0, 0],
            "channels": [{"id": "p", "resolution": [1920, 1080], "lens": lens,
                "pose": {"position": [0, 0, 0], "look_to": [0, 0, -1], "look_up": [0, 1, 0]}}]})
        .to_string()
    };
    let rig =
        Rig::from_doc(RigDoc::parse(&doc(json!({"throw_ratio": 1.5, "shift": [0, 0.5]}))).unwrap())
            .unwrap();
    let ch = &rig.channels[0];
    let at = |q: [f64; 2]| rig.wall_point(ch, q).unwrap();
    assert!((at([-0.5, 539.5]).x + 1.0).abs() < 1e-9);
    assert!((at([1919.5, 539.5]).x - 1.0).abs() < 1e-9);
    assert!(at([959.5, 1079.5]).y.abs() < 1e-9);
    assert!((at([959.5, -0.5]).y - 1.125).abs() < 1e-9);
    // Held as the intrinsics it amounts to, which every reader of the rig knows.
    let lens = &rig.doc.channels[0].lens;
    assert_eq!(lens.intrinsics, vec![2880.0, 2880.0, 959.5, 1079.5]);
    assert_eq!((lens.throw_ratio, lens.shift), (None, None));
    for (lens, field) in [
        (
            json!({"throw_ratio": 1.5, "intrinsics": [1, 1, 1, 1]}),
            "/channels/0/lens/throw_ratio",
        ),
        (json!({"throw_ratio": 0.0}), "/channels/0/lens/throw_ratio"),
        (
            json!({"throw_ratio": f64::MAX}),
            "/channels/0/lens/throw_ratio",
        ),
        (
            json!({"throw_ratio": 1.5, "shift": [0, 3]}),
            "/channels/0/lens/shift",
        ),
        (
            json!({"model": "LENSMODEL_PINHOLE", "intrinsics": [1000, 1000, 959.5, 539.5], "shift": [0, 0.5]}),
            "/channels/0/lens/shift",
        ),
        (
            json!({"model": "LENSMODEL_OPENCV5", "throw_ratio": 1.5}),
            "/channels/0/lens/model",
        ),
    ] {
        let e = RigDoc::parse(&doc(lens.clone()))
            .and_then(Rig::from_doc)
            .unwrap_err();
        assert!(e.to_string().contains(field), "{lens}: {e}");
    }
}

#[test]
fn a_plan_refuses_a_grid_out_of_bounds_and_a_picture_too_small() {
    let rig = two_on_a_flat_wall();
    for step in [0.1, 10.0, f64::NAN] {
        let e = rig.plan(step).unwrap_err();
        assert!(e.to_string().contains("step"), "{e}");
    }
    let plan = rig.plan(2.0).unwrap();
    for width in [100, 10_000] {
        let e = plan.picture(&rig, width).unwrap_err();
        assert!(e.to_string().contains("width"), "{e}");
    }
}
