//! Where methods break, measured: the regimes of docs/failure-map.md that no other test covers,
//! one table row each, every one either a named error or a measured quantity held to its stated
//! bound. The page itself is checked too: every test it names exists.

use glam::DVec3;
use omniwarp::content::Content;
use omniwarp::content::pattern::Pattern;
use omniwarp::cubemap::CubeMap;
use omniwarp::normalmap::NormalMap;
use omniwarp::projection::view::screen_of_pixel;
use omniwarp::projection::{Orientation, Params, View, build};
use omniwarp::raster::psnr;
use omniwarp::render::coverage::face_size_for;
use omniwarp::render::{Filter, Warp, render, render_fn};
use omniwarp::surface::{Cylinder, GRAZING_DEG, Hit};
use std::path::Path;

fn view(name: &str, p: Params, w: u32, h: u32) -> View {
    View::plain(build(name, &p, f64::from(h) / f64::from(w)).unwrap())
}

fn params(hfov: Option<f64>, vfov: Option<f64>, fov: Option<f64>) -> Params {
    Params {
        hfov,
        vfov,
        fov,
        ..Params::default()
    }
}

/// What a row found: a measured value against its bound (value ≤ bound unless `above`).
struct Measured {
    value: f64,
    bound: f64,
    above: bool,
    unit: &'static str,
}

fn at_most(value: f64, bound: f64, unit: &'static str) -> Measured {
    Measured {
        value,
        bound,
        above: false,
        unit,
    }
}

fn at_least(value: f64, bound: f64, unit: &'static str) -> Measured {
    Measured {
        value,
        bound,
        above: true,
        unit,
    }
}

/// Half floats carry 11 significant bits: a unit vector stored as f16 is off by up to about
/// 0.03°, which is a third of a pixel of a 4K equirect and two thirds at 8K.
fn f16_maps_at_4k_and_8k() -> Vec<(String, Measured)> {
    use exr::prelude::f16;
    let mut out = Vec::new();
    for (w, bound) in [(4096u32, 0.3), (8192, 0.6)] {
        let h = w / 2;
        let v = view("equirect", params(Some(360.0), Some(180.0), None), w, h);
        let pitch = 360f64.to_radians() / f64::from(w);
        let mut worst = 0.0f64;
        // Every 5th row and column: the worst case is the same everywhere along a row.
        for j in (0..h).step_by(5) {
            for i in (0..w).step_by(5) {
                let (s, t) = screen_of_pixel(f64::from(i) + 0.5, f64::from(j) + 0.5, w, h);
                let d = v.direction(s, t).unwrap();
                let q = |c: f64| f64::from(f16::from_f64(c).to_f32());
                let stored = DVec3::new(q(d.x), q(d.y), q(d.z));
                worst = worst.max(d.angle_between(stored));
            }
        }
        out.push((
            format!("f16 map, {w}×{h} equirect"),
            at_most(worst / pitch, bound, "px"),
        ));
    }
    out
}

/// A cylinder's rows cover latitude atan(t·tan(vfov/2)): the horizon's rows are 1/cos²(vfov/2)
/// times coarser in angle than the top and bottom rows, so the cube face the finest rows need
/// grows without bound as vfov → 180°, which is refused.
fn cylinder_vfov_towards_180() -> Vec<(String, Measured)> {
    let mut out = Vec::new();
    for vfov in [150.0f64, 170.0, 179.0] {
        let (w, h) = (64u32, 2001u32);
        let map = NormalMap::from_view(
            &view("cylindrical", params(Some(90.0), Some(vfov), None), w, h),
            w,
            h,
        )
        .unwrap();
        let step = |j: usize| {
            let a = map.direction(32, j).unwrap();
            a.angle_between(map.direction(32, j + 1).unwrap())
        };
        let ratio = step(1000) / step(0);
        let expected = 1.0 / (vfov.to_radians() / 2.0).cos().powi(2);
        out.push((
            format!("cylinder vfov {vfov}°: row pitch ratio {ratio:.0} vs 1/cos² {expected:.0}"),
            at_most((ratio / expected - 1.0).abs(), 0.01, "relative"),
        ));
    }
    let refused = build("cylindrical", &params(Some(90.0), Some(180.0), None), 0.5)
        .err()
        .map(|e| e.to_string())
        .unwrap_or_default();
    out.push((
        format!("cylinder vfov 180° refused: {refused}"),
        at_least(f64::from(u8::from(refused.contains("vfov"))), 1.0, "named"),
    ));
    out
}

/// A 360° fisheye's rim is one direction (straight back): across the ring of outer pixels a
/// step sideways turns the view by sin θ of what it turns at the centre, so the content around
/// the back is oversampled without bound and the rim itself shows a single direction.
fn fisheye_towards_360() -> Vec<(String, Measured)> {
    let (w, h) = (1001u32, 1001u32);
    let map = NormalMap::from_view(
        &view("fisheye", params(None, None, Some(360.0)), w, h),
        w,
        h,
    )
    .unwrap();
    // Azimuthal pitch (between horizontal neighbours on the vertical diameter) near the centre
    // and in the outer 1 % of the radius.
    let step = |j: usize| {
        map.direction(500, j)
            .unwrap()
            .angle_between(map.direction(501, j).unwrap())
    };
    let (centre, rim) = (step(490), step(3));
    let back = map.direction(500, 0).unwrap();
    vec![
        (
            format!("fisheye 360°: centre pitch / rim pitch {:.1}", centre / rim),
            at_least(centre / rim, 50.0, "×"),
        ),
        (
            "fisheye 360°: the top rim pixel looks straight back".into(),
            at_most(back.angle_between(DVec3::Z).to_degrees(), 0.2, "°"),
        ),
    ]
}

/// Cube faces below the size the output needs ([`face_size_for`]) lose detail the output could
/// show: a checkerboard through a quarter of the chosen size against the exact render.
fn cube_faces_below_the_needed_size() -> Vec<(String, Measured)> {
    let (w, h) = (480u32, 240u32);
    let v = view("cylindrical", params(Some(270.0), Some(90.0), None), w, h);
    let map = NormalMap::from_view(&v, w, h).unwrap();
    let needed = face_size_for(&map, 4096);
    let truth = render_fn(Warp::View(&v), w, h, 2, |d| Pattern::Checker.eval(d)).unwrap();
    let db = |n: u32| {
        let cube = CubeMap::<[f32; 4]>::from_fn(n as usize, 1, |d| Pattern::Checker.eval(d));
        let img = render(
            Warp::View(&v),
            &Content::cube(&cube),
            w,
            h,
            2,
            Filter::Bilinear,
        )
        .unwrap();
        psnr(&img, &truth, 1.0, |x, y| truth.get(x, y)[3] > 0.99)
    };
    let (full, quarter) = (db(needed), db(needed / 4));
    vec![(
        format!(
            "faces of {needed}² (chosen) {full:.1} dB, {}² {quarter:.1} dB",
            needed / 4
        ),
        at_least(full - quarter, 3.0, "dB lost"),
    )]
}

/// Light arriving within 1° of the wall's tangent plane spreads one pixel over too much wall:
/// such pixels are not lit (the warp leaves them out) rather than trusted.
fn grazing_projector_rays() -> Vec<(String, Measured)> {
    let c = Cylinder {
        radius: 2.0,
        centre: [0.0; 3],
        axis: [0.0, 1.0, 0.0],
        height: [-1.0, 1.0],
        arc: [-180.0, 180.0],
    };
    // A ray meeting the wall at (0, 0, −2) at incidence `deg` from its normal, starting at the
    // middle of its chord (inside the cylinder).
    let lit = |deg: f64| {
        let p = DVec3::new(0.0, 0.0, -2.0);
        let a = deg.to_radians();
        let dir = DVec3::new(a.sin(), 0.0, -a.cos());
        matches!(c.intersect(p - dir * (2.0 * a.cos()), dir), Hit::Lit { .. })
    };
    let (inside, beyond) = (GRAZING_DEG - 0.1, GRAZING_DEG + 0.1);
    vec![(
        format!("incidence {inside}° lit, {beyond}° not"),
        at_least(
            f64::from(u8::from(lit(inside) && !lit(beyond))),
            1.0,
            "held",
        ),
    )]
}

/// Look-to parallel to look-up leaves the view without a right-hand direction: refused.
fn look_to_parallel_to_look_up() -> Vec<(String, Measured)> {
    let e = Orientation::look(DVec3::Y, DVec3::Y * 2.0)
        .err()
        .map(|e| e.to_string())
        .unwrap_or_default();
    vec![(
        format!("look-to ∥ look-up refused: {e}"),
        at_least(f64::from(u8::from(e.contains("look-up"))), 1.0, "named"),
    )]
}

/// A panorama projected from a centre C near the wall (seed 001): the eye's neighbouring rays
/// meet the near wall a small distance from C, so one output pixel spans |P − eye|/|P − C| times
/// its own angle of the panorama (more than a bilinear tap can average: aliasing), while the far
/// wall spans less (blur). Straight ahead of a 2 m cylinder's axis with C 1.8 m ahead: 10× and
/// 2/3.8 = 0.53×.
fn projection_centre_near_the_wall() -> Vec<(String, Measured)> {
    let text = r#"{ "format": 1, "screen": { "kind": "cylinder", "radius": 2.0, "height": [-2, 2] },
        "eye": [0, 0, 0], "channels": [ { "id": "p", "resolution": [8, 8],
        "lens": { "model": "LENSMODEL_PINHOLE", "intrinsics": [4, 4, 3.5, 3.5] },
        "pose": { "position": [0, 0, 0], "look_to": [0, 0, -1], "look_up": [0, 1, 0] } } ] }"#;
    let rig = omniwarp::rig::Rig::from_json(text, Path::new(".")).unwrap();
    let c = rig.check_centre(DVec3::new(0.0, 0.0, -1.8), "c").unwrap();
    let mut out = Vec::new();
    for (ahead, expected) in [(DVec3::NEG_Z, 10.0), (DVec3::Z, 2.0 / 3.8)] {
        // Two eye rays 1e-4 rad apart, sideways, and the panorama angle between what they show.
        let side = ahead.cross(DVec3::Y) * 1e-4;
        let from = omniwarp::content::projective::Projective {
            surface: &rig.doc.screen,
            eye: rig.eye,
            centre: c,
        };
        let v = |d: DVec3| from.direction(d.normalize());
        let spread = v(ahead).angle_between(v(ahead + side)) / 1e-4;
        out.push((
            format!("C 0.2 m from the wall, looking {ahead}: {spread:.3}× the eye's angle (expected {expected:.3})"),
            at_most((spread / expected - 1.0).abs(), 1e-3, "relative"),
        ));
    }
    out
}

type Row = (&'static str, fn() -> Vec<(String, Measured)>);

const ROWS: [Row; 7] = [
    (
        "projection_centre_near_the_wall",
        projection_centre_near_the_wall,
    ),
    ("f16_maps_at_4k_and_8k", f16_maps_at_4k_and_8k),
    ("cylinder_vfov_towards_180", cylinder_vfov_towards_180),
    ("fisheye_towards_360", fisheye_towards_360),
    (
        "cube_faces_below_the_needed_size",
        cube_faces_below_the_needed_size,
    ),
    ("grazing_projector_rays", grazing_projector_rays),
    ("look_to_parallel_to_look_up", look_to_parallel_to_look_up),
];

#[test]
fn every_regime_of_the_failure_map_holds_its_bound() {
    let mut failed = Vec::new();
    for (row, measure) in ROWS {
        for (what, m) in measure() {
            let ok = if m.above {
                m.value >= m.bound
            } else {
                m.value <= m.bound
            };
            let sign = if m.above { "≥" } else { "≤" };
            eprintln!(
                "{row}: {what}: {:.4} {} ({sign} {} wanted)",
                m.value, m.unit, m.bound
            );
            if !ok {
                failed.push(format!("{row}: {what}: {} {}", m.value, m.unit));
            }
        }
    }
    assert!(failed.is_empty(), "{failed:#?}");
}

/// The page names a test for every regime; each must exist (a row of this file or a test
/// function elsewhere), so the map cannot point at something deleted or renamed.
#[test]
fn every_test_the_failure_map_names_exists() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let page = std::fs::read_to_string(root.join("docs/failure-map.md")).unwrap();
    let mut sources = String::new();
    for dir in ["tests", "src"] {
        let mut stack = vec![root.join(dir)];
        while let Some(d) = stack.pop() {
            for e in std::fs::read_dir(&d).unwrap() {
                let p = e.unwrap().path();
                if p.is_dir() {
                    stack.push(p);
                } else if p.extension().is_some_and(|x| x == "rs") {
                    sources.push_str(&std::fs::read_to_string(&p).unwrap());
                }
            }
        }
    }
    let mut named = 0;
    for line in page.lines().filter(|l| l.starts_with('|')) {
        let Some(cell) = line.trim_end_matches('|').rsplit('|').next() else {
            continue;
        };
        for name in cell.split('`').skip(1).step_by(2) {
            let test = name.rsplit("::").next().unwrap_or(name);
            let row = ROWS.iter().any(|r| r.0 == test);
            assert!(
                row || sources.contains(&format!("fn {test}(")),
                "docs/failure-map.md names `{name}`, which no test defines"
            );
            named += 1;
        }
    }
    assert!(named >= ROWS.len(), "only {named} tests named");
}
