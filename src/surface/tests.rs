use super::*;

fn cyl() -> Cylinder {
    Cylinder {
        radius: 2.0,
        centre: [0.0; 3],
        axis: [0.0, 1.0, 0.0],
        height: [-1.0, 1.2],
        arc: [-135.0, 135.0],
    }
}

#[test]
fn cylinder_hits_misses_and_grazes() {
    let c = cyl();
    // Straight ahead from the centre: the wall at 2 m.
    let Hit::Lit { t, point, normal } = c.intersect(DVec3::ZERO, DVec3::NEG_Z) else {
        panic!()
    };
    assert!((t - 2.0).abs() < 1e-12 && point.abs_diff_eq(DVec3::new(0.0, 0.0, -2.0), 1e-12));
    assert!(
        normal.abs_diff_eq(DVec3::Z, 1e-12),
        "the normal faces the viewer"
    );
    // Behind, outside the 270° arc: a miss.
    assert_eq!(c.intersect(DVec3::ZERO, DVec3::Z), Hit::Miss);
    // Above the top edge: a miss; from outside the cylinder the far wall is lit.
    assert_eq!(
        c.intersect(DVec3::ZERO, DVec3::new(0.0, 1.0, -1.0).normalize()),
        Hit::Miss
    );
    let outside = c.intersect(DVec3::new(0.0, 0.0, 5.0), DVec3::NEG_Z);
    assert!(
        outside
            .point()
            .unwrap()
            .abs_diff_eq(DVec3::new(0.0, 0.0, -2.0), 1e-12),
        "{outside:?}"
    );
    // Almost along the wall: grazing.
    let g = c.intersect(DVec3::new(1.99999, 0.0, 0.0), DVec3::new(0.0, 0.0, -1.0));
    assert!(matches!(g, Hit::Grazing { .. }), "{g:?}");
    // Parallel to the axis: a miss.
    assert_eq!(c.intersect(DVec3::ZERO, DVec3::Y), Hit::Miss);
}

#[test]
fn dome_tilt_and_truncation() {
    let d = Dome {
        radius: 3.0,
        centre: [0.0; 3],
        tilt: 15.0,
        min_elevation: 0.0,
    };
    assert!(d.intersect(DVec3::ZERO, DVec3::Y).point().is_some());
    // Straight back and level: 15° below the tilted springline, so not lit.
    assert_eq!(d.intersect(DVec3::ZERO, DVec3::Z), Hit::Miss);
    // Level ahead: 15° above it.
    let p = d.intersect(DVec3::ZERO, DVec3::NEG_Z).point().unwrap();
    assert!((p.length() - 3.0).abs() < 1e-12);
    let lower = Dome {
        min_elevation: -20.0,
        ..d.clone()
    };
    assert!(lower.intersect(DVec3::ZERO, DVec3::Z).point().is_some());
}

#[test]
fn plane_rectangle_bounds() {
    let p = Plane {
        centre: [0.0, 0.0, -3.0],
        normal: [0.0, 0.0, 1.0],
        up: [0.0, 1.0, 0.0],
        width: 4.0,
        height: 2.0,
    };
    assert!(
        p.intersect(DVec3::ZERO, DVec3::new(0.6, 0.3, -1.0).normalize())
            .point()
            .is_some()
    );
    assert_eq!(
        p.intersect(DVec3::ZERO, DVec3::new(0.7, 0.0, -1.0).normalize()),
        Hit::Miss
    );
    assert_eq!(p.intersect(DVec3::ZERO, DVec3::Z), Hit::Miss);
    assert_eq!(p.intersect(DVec3::ZERO, DVec3::X), Hit::Miss);
}

#[test]
fn mesh_of_a_cylinder_agrees_with_the_analytic_one() {
    let c = cyl();
    let (n_az, n_h) = (720, 8);
    let mut tris = Vec::new();
    let at = |i: usize, j: usize| {
        let az = (-135.0 + 270.0 * i as f64 / n_az as f64).to_radians();
        let h = -1.0 + 2.2 * j as f64 / n_h as f64;
        DVec3::new(2.0 * az.sin(), h, -2.0 * az.cos())
    };
    for i in 0..n_az {
        for j in 0..n_h {
            tris.push([at(i, j), at(i + 1, j), at(i + 1, j + 1)]);
            tris.push([at(i, j), at(i + 1, j + 1), at(i, j + 1)]);
        }
    }
    let m = Mesh::new(tris).unwrap();
    // The chord of a 0.375° facet sags 2·(1 − cos 0.1875°) ≈ 1.1e-5 m.
    let mut worst: f64 = 0.0;
    for k in 0..500 {
        let az = (-130.0 + 260.0 * k as f64 / 499.0).to_radians();
        let el = (-20.0 + 40.0 * ((k * 7) % 500) as f64 / 499.0).to_radians();
        let d = DVec3::new(el.cos() * az.sin(), el.sin(), -el.cos() * az.cos());
        let (a, b) = (
            c.intersect(DVec3::ZERO, d).point().unwrap(),
            m.intersect(DVec3::ZERO, d).point().unwrap(),
        );
        worst = worst.max(a.distance(b));
    }
    assert!(worst < 2e-5, "mesh and cylinder differ by {worst} m");
    assert_eq!(m.intersect(DVec3::ZERO, DVec3::Z), Hit::Miss);
}

#[test]
fn bad_geometry_names_the_field() {
    let mut c = cyl();
    c.radius = -1.0;
    assert!(
        c.validate("/screen")
            .unwrap_err()
            .to_string()
            .contains("/screen/radius")
    );
    let mut c = cyl();
    c.height = [1.0, 0.0];
    assert!(
        c.validate("/screen")
            .unwrap_err()
            .to_string()
            .contains("/screen/height")
    );
    let d = Dome {
        radius: 1.0,
        centre: [0.0; 3],
        tilt: 100.0,
        min_elevation: 0.0,
    };
    assert!(
        d.validate("/screen")
            .unwrap_err()
            .to_string()
            .contains("/screen/tilt")
    );
    let p = Plane {
        centre: [0.0; 3],
        normal: [0.0, 1.0, 0.0],
        up: [0.0, 2.0, 0.0],
        width: 1.0,
        height: 1.0,
    };
    assert!(
        p.validate("/screen")
            .unwrap_err()
            .to_string()
            .contains("/screen/up")
    );
}
