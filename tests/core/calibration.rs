//! Projector calibration: against OpenCV on the same data, recovery of synthetic truth, model
//! selection that picks no more than the data supports, outliers, and degenerate input.

use crate::common;

use glam::{DMat3, DVec3};
use omniwarp::calibration::{Correspondence, ModelChoice, Problem, calibrate};
use omniwarp::lens::{Lens, LensModel};
use serde::Deserialize;

#[derive(Deserialize)]
struct Truth {
    intrinsics: Vec<f64>,
    pixels: Vec<[f64; 2]>,
}

#[derive(Deserialize)]
struct Solved {
    rms: f64,
    #[serde(default)]
    intrinsics: Vec<f64>,
}

#[derive(Deserialize)]
struct Oracle {
    resolution: [u32; 2],
    points: Vec<Correspondence>,
    truth: Truth,
    #[serde(rename = "solvePnP_true_lens")]
    pnp: Solved,
    #[serde(rename = "calibrateCamera")]
    cc: Solved,
}

fn oracle() -> Oracle {
    serde_json::from_str(
        &std::fs::read_to_string(common::fixture("calibration/opencv_cylinder.json")).unwrap(),
    )
    .unwrap()
}

/// RMS distance between a fit's predictions and the noise-free pixels.
fn model_error(
    fit: &omniwarp::calibration::Fit,
    points: &[Correspondence],
    truth: &[[f64; 2]],
) -> f64 {
    let s: f64 = points
        .iter()
        .zip(truth)
        .map(|(c, t)| {
            let q = fit.reproject(DVec3::from_array(c.world)).unwrap();
            (q[0] - t[0]).powi(2) + (q[1] - t[1]).powi(2)
        })
        .sum();
    (s / points.len() as f64).sqrt()
}

#[test]
fn equals_or_beats_opencv_on_its_own_case() {
    let o = oracle();
    let problem = Problem {
        resolution: o.resolution,
        points: o.points.clone(),
        lens: None,
        intrinsics_fixed: false,
    };
    let cal = calibrate(&problem, ModelChoice::Fixed(LensModel::OpenCv(5))).unwrap();
    let fit = &cal.fit;
    let i = fit.lens.intrinsics();
    // OpenCV's model error against the truth, from its own intrinsics and our pose machinery:
    // compare parameters directly instead.
    let dist = |v: &[f64]| {
        ((v[0] - o.truth.intrinsics[0]).powi(2) + (v[1] - o.truth.intrinsics[1]).powi(2)).sqrt()
    };
    println!(
        "ours: RMS {:.4} px, fx {:.2} fy {:.2} cx {:.2} cy {:.2}; OpenCV calibrateCamera: RMS {:.4} px, fx {:.2} fy {:.2} cx {:.2} cy {:.2}",
        fit.rms,
        i[0],
        i[1],
        i[2],
        i[3],
        o.cc.rms,
        o.cc.intrinsics[0],
        o.cc.intrinsics[1],
        o.cc.intrinsics[2],
        o.cc.intrinsics[3]
    );
    println!(
        "ours vs truth: {:.4} px RMS; σ(fx) {:.2} px; warnings {:?}",
        model_error(fit, &o.points, &o.truth.pixels),
        fit.sigma[0].1,
        cal.warnings
    );
    assert!(
        fit.rms <= o.cc.rms + 1e-6,
        "ours {} > OpenCV {}",
        fit.rms,
        o.cc.rms
    );
    assert!(
        dist(i) <= dist(&o.cc.intrinsics) + 0.05,
        "focal lengths further from the truth than OpenCV's"
    );
    assert!(model_error(fit, &o.points, &o.truth.pixels) < 0.25);

    // Pose only, with the true lens: as solvePnP.
    let lens = Lens::new(LensModel::OpenCv(5), o.truth.intrinsics.clone()).unwrap();
    let fixed = Problem {
        lens: Some(lens),
        intrinsics_fixed: true,
        ..problem
    };
    let pose = calibrate(&fixed, ModelChoice::Auto).unwrap();
    println!(
        "pose only: ours {:.4} px, solvePnP {:.4} px",
        pose.fit.rms, o.pnp.rms
    );
    assert!(pose.fit.rms <= o.pnp.rms + 1e-6);
}

struct Rng(u64);
impl Rng {
    fn uniform(&mut self) -> f64 {
        self.0 = self
            .0
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        ((self.0 >> 11) as f64 + 0.5) / (1u64 << 53) as f64
    }
    fn gauss(&mut self) -> f64 {
        let (a, b) = (self.uniform(), self.uniform());
        (-2.0 * a.ln()).sqrt() * (2.0 * std::f64::consts::PI * b).cos()
    }
}

/// Grid pixels of `lens` (posed projector-to-world by `rot`, `pos`) cast onto `screen`, with
/// Gaussian noise of `sigma` px; returns the correspondences and the noise-free pixels.
fn synthetic(
    lens: &Lens,
    rot: DMat3,
    pos: DVec3,
    screen: &omniwarp::surface::Screen,
    sigma: f64,
    seed: u64,
) -> (Vec<Correspondence>, Vec<[f64; 2]>) {
    let mut rng = Rng(seed);
    let (mut pts, mut truth) = (Vec::new(), Vec::new());
    for j in 0..12 {
        for i in 0..18 {
            let q = [
                40.0 + i as f64 * 1840.0 / 17.0,
                40.0 + j as f64 * 1000.0 / 11.0,
            ];
            let Ok(ray) = lens.unproject(q) else { continue };
            let Some(p) = screen.intersect(pos, rot * ray).point() else {
                continue;
            };
            pts.push(Correspondence {
                pixel: [q[0] + sigma * rng.gauss(), q[1] + sigma * rng.gauss()],
                world: p.to_array(),
            });
            truth.push(q);
        }
    }
    (pts, truth)
}

fn look(f: DVec3, up: DVec3) -> DMat3 {
    let f = f.normalize();
    let r = f.cross(up).normalize();
    DMat3::from_cols(r, f.cross(r), f)
}

fn screens() -> Vec<(&'static str, omniwarp::surface::Screen)> {
    use omniwarp::surface::{Cylinder, Dome, Screen};
    vec![
        (
            "cylinder",
            Screen::Cylinder(Cylinder {
                radius: 2.5,
                centre: [0.0; 3],
                axis: [0.0, 1.0, 0.0],
                height: [-3.0, 3.0],
                arc: [-180.0, 180.0],
            }),
        ),
        (
            "dome",
            Screen::Dome(Dome {
                radius: 3.0,
                centre: [0.0; 3],
                tilt: 10.0,
                min_elevation: -40.0,
            }),
        ),
    ]
}

#[test]
fn recovers_synthetic_projectors_within_the_noise() {
    let lenses = [
        Lens::new(
            LensModel::OpenCv(5),
            vec![
                1500.0, 1495.0, 955.0, 560.0, -0.08, 0.03, 0.0008, -0.0005, -0.01,
            ],
        )
        .unwrap(),
        Lens::new(
            LensModel::OpenCv(4),
            vec![1100.0, 1100.0, 960.0, 540.0, 0.05, -0.02, 0.0, 0.0005],
        )
        .unwrap(),
    ];
    for (name, screen) in screens() {
        for (n, lens) in lenses.iter().enumerate() {
            let rot = look(DVec3::new(0.3, 0.25, -1.0), DVec3::Y);
            let (pts, truth) = synthetic(
                lens,
                rot,
                DVec3::new(0.2, -0.3, 0.4),
                &screen,
                0.3,
                11 + n as u64,
            );
            let problem = Problem {
                resolution: [1920, 1080],
                points: pts.clone(),
                lens: None,
                intrinsics_fixed: false,
            };
            let cal = calibrate(&problem, ModelChoice::Fixed(lens.model())).unwrap();
            let err = model_error(&cal.fit, &pts, &truth);
            println!(
                "{name} {}: RMS {:.3} px over {} points, model vs truth {err:.3} px",
                lens.model(),
                cal.fit.rms,
                pts.len()
            );
            assert!(
                (cal.fit.rms - 0.3 * 2f64.sqrt()).abs() < 0.08,
                "{name}: RMS {}",
                cal.fit.rms
            );
            assert!(
                err < 0.15,
                "{name} {}: {err} px from the truth",
                lens.model()
            );
        }
    }
}

#[test]
fn model_selection_picks_the_generating_model_and_says_why() {
    let (_, screen) = screens().remove(0);
    let rot = look(DVec3::new(-0.2, 0.1, -1.0), DVec3::Y);
    for (lens, want) in [
        (
            Lens::new(LensModel::Pinhole, vec![1400.0, 1400.0, 950.0, 545.0]).unwrap(),
            LensModel::Pinhole,
        ),
        (
            Lens::new(
                LensModel::OpenCv(4),
                vec![1400.0, 1400.0, 950.0, 545.0, -0.12, 0.05, 0.001, -0.0008],
            )
            .unwrap(),
            LensModel::OpenCv(4),
        ),
    ] {
        let (pts, _) = synthetic(&lens, rot, DVec3::new(0.1, 0.0, 0.3), &screen, 0.05, 5);
        let problem = Problem {
            resolution: [1920, 1080],
            points: pts,
            lens: None,
            intrinsics_fixed: false,
        };
        let cal = calibrate(&problem, ModelChoice::Auto).unwrap();
        for c in &cal.considered {
            println!(
                "{}: {} RMS {:.4}, held out {:.4}: {}",
                lens.model(),
                c.model,
                c.rms,
                c.held_out_rms
                    .expect("auto compares models on held-out points"),
                c.verdict
            );
        }
        assert_eq!(cal.fit.lens.model(), want);
        assert!(
            cal.considered
                .iter()
                .any(|c| c.verdict.starts_with("rejected")),
            "no larger model was tried and refused"
        );
    }
}

#[test]
fn outliers_are_flagged_and_do_not_pull_the_solution() {
    let (_, screen) = screens().remove(0);
    let lens = Lens::new(
        LensModel::OpenCv(4),
        vec![1400.0, 1400.0, 950.0, 545.0, -0.1, 0.04, 0.0, 0.0],
    )
    .unwrap();
    let (mut pts, truth) = synthetic(
        &lens,
        look(DVec3::new(0.0, 0.1, -1.0), DVec3::Y),
        DVec3::ZERO,
        &screen,
        0.2,
        9,
    );
    for k in [3, 50, 120] {
        pts[k].pixel[0] += 25.0;
    }
    let problem = Problem {
        resolution: [1920, 1080],
        points: pts.clone(),
        lens: None,
        intrinsics_fixed: false,
    };
    let cal = calibrate(&problem, ModelChoice::Fixed(LensModel::OpenCv(4))).unwrap();
    assert_eq!(cal.fit.outliers, vec![3, 50, 120]);
    assert!(model_error(&cal.fit, &pts, &truth) < 0.2);
    assert!(cal.warnings.iter().any(|w| w.contains("look wrong")));
}

#[test]
fn degenerate_input_is_refused_with_the_reason() {
    let (_, screen) = screens().remove(0);
    let lens = Lens::new(
        LensModel::OpenCv(4),
        vec![1400.0, 1400.0, 950.0, 545.0, -0.1, 0.04, 0.0, 0.0],
    )
    .unwrap();
    let (pts, _) = synthetic(
        &lens,
        look(DVec3::new(0.0, 0.1, -1.0), DVec3::Y),
        DVec3::ZERO,
        &screen,
        0.2,
        3,
    );
    let base = Problem {
        resolution: [1920, 1080],
        points: pts.clone(),
        lens: None,
        intrinsics_fixed: false,
    };
    let err = |p: &Problem| {
        calibrate(p, ModelChoice::Fixed(LensModel::OpenCv(4)))
            .unwrap_err()
            .to_string()
    };
    let few = Problem {
        points: pts.iter().step_by(45).copied().collect(),
        ..base.clone()
    };
    assert!(err(&few).contains("cannot determine"), "{}", err(&few));
    let flat: Vec<Correspondence> = pts
        .iter()
        .map(|c| Correspondence {
            world: [c.world[0], c.world[1], -2.5],
            ..*c
        })
        .collect();
    assert!(
        err(&Problem {
            points: flat.clone(),
            ..base.clone()
        })
        .contains("one plane")
    );
    let corner: Vec<Correspondence> = pts
        .iter()
        .map(|c| Correspondence {
            pixel: [c.pixel[0] * 0.1, c.pixel[1] * 0.1],
            ..*c
        })
        .collect();
    assert!(
        err(&Problem {
            points: corner,
            ..base.clone()
        })
        .contains("cover only")
    );
    let mut nan = pts.clone();
    nan[4].world[1] = f64::NAN;
    assert!(
        err(&Problem {
            points: nan,
            ..base.clone()
        })
        .contains("points[4]")
    );
    assert!(
        err(&Problem {
            intrinsics_fixed: true,
            ..base.clone()
        })
        .contains("`lens`")
    );
    // Coplanar points are fine when the intrinsics are known: the pose comes from a homography.
    let wall = omniwarp::surface::Screen::Plane(omniwarp::surface::Plane {
        centre: [0.0, 0.0, -3.0],
        normal: [0.0, 0.0, 1.0],
        up: [0.0, 1.0, 0.0],
        width: 20.0,
        height: 20.0,
    });
    let (pts, truth) = synthetic(
        &lens,
        look(DVec3::new(0.1, 0.05, -1.0), DVec3::Y),
        DVec3::new(0.2, 0.1, 0.0),
        &wall,
        0.2,
        4,
    );
    let fixed = Problem {
        points: pts.clone(),
        lens: Some(lens),
        intrinsics_fixed: true,
        ..base
    };
    let cal = calibrate(&fixed, ModelChoice::Auto).unwrap();
    assert!(
        model_error(&cal.fit, &pts, &truth) < 0.1,
        "{}",
        model_error(&cal.fit, &pts, &truth)
    );
}
