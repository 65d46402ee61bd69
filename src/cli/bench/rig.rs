//! `omniwarp bench rig`: warp generation for a 3840×2160 and a 1920×1080 projector on each
//! surface type, the OPENCV5 ones against calibration/bench/rig_probe.c built for this machine
//! and run in the same process's turn (the ratio is the figure: absolute times here are noisy),
//! and blend computation for the five-projector dome example.

use super::super::io::read_rig;
use anyhow::Result;
use omniwarp::rig::Rig;
use std::path::Path;
use std::time::Instant;

/// The rig whose blends are timed unless another is named.
pub const DOME_RIG: &str = "calibration/rigs/dome-180-tilt15-5proj.json";

pub fn run(dome_rig: &Path) -> Result<()> {
    use omniwarp::surface::{Cylinder, Dome, Mesh, Plane, Screen};
    let cylinder = Cylinder {
        radius: 2.0,
        centre: [0.0; 3],
        axis: [0.0, 1.0, 0.0],
        height: [-2.0, 2.0],
        arc: [-180.0, 180.0],
    };
    let (n_az, n_h) = (720, 16);
    let mut tris = Vec::new();
    let at = |i: usize, j: usize| {
        let az = (-180.0 + 360.0 * i as f64 / n_az as f64).to_radians();
        glam::DVec3::new(
            2.0 * az.sin(),
            -2.0 + 4.0 * j as f64 / n_h as f64,
            -2.0 * az.cos(),
        )
    };
    for i in 0..n_az {
        for j in 0..n_h {
            tris.push([at(i, j), at(i + 1, j), at(i + 1, j + 1)]);
            tris.push([at(i, j), at(i + 1, j + 1), at(i, j + 1)]);
        }
    }
    let screens = [
        ("cylinder", Screen::Cylinder(cylinder)),
        (
            "dome",
            Screen::Dome(Dome {
                radius: 3.0,
                centre: [0.0; 3],
                tilt: 15.0,
                min_elevation: -30.0,
            }),
        ),
        (
            "plane",
            Screen::Plane(Plane {
                centre: [0.0, 0.0, -3.0],
                normal: [0.0, 0.0, 1.0],
                up: [0.0, 1.0, 0.0],
                width: 12.0,
                height: 8.0,
            }),
        ),
        (
            "mesh (23k triangles)",
            Screen::Mesh {
                obj: String::new(),
                loaded: Some(std::sync::Arc::new(Mesh::new(tris)?)),
            },
        ),
    ];
    let probe = build_probe();
    for lens in ["LENSMODEL_PINHOLE", "LENSMODEL_OPENCV5"] {
        for (w, h) in [(3840u32, 2160u32), (1920, 1080)] {
            let f = f64::from(w) / 3840.0;
            let mut intrinsics: Vec<f64> = match lens {
                "LENSMODEL_PINHOLE" => vec![2400.0, 2400.0, 1919.5, 1079.5],
                _ => vec![
                    2400.0, 2400.0, 1919.5, 1079.5, -0.05, 0.01, 0.0005, -0.0003, -0.002,
                ],
            };
            intrinsics[0] *= f;
            intrinsics[1] *= f;
            intrinsics[2] = (intrinsics[2] + 0.5) * f - 0.5;
            intrinsics[3] = (intrinsics[3] + 0.5) * f - 0.5;
            for (name, screen) in &screens {
                let doc = omniwarp::rig::RigDoc {
                    format: 1,
                    screen: screen.clone(),
                    eye: [0.0; 3],
                    content: Default::default(),
                    channels: vec![omniwarp::rig::ChannelDoc {
                        id: "p".into(),
                        resolution: [w, h],
                        lens: omniwarp::rig::LensDoc::new(lens, intrinsics.clone()),
                        pose: omniwarp::rig::PoseDoc {
                            position: [0.0, 0.3, 0.5],
                            look_to: Some([0.0, 0.0, -1.0]),
                            look_up: Some([0.0, 1.0, 0.0]),
                            rvec: None,
                        },
                        contrast: None,
                    }],
                    canvas: None,
                };
                let rig = Rig::from_doc(doc)?;
                // The best of five, each with its outputs freshly allocated (as a warp
                // computed on request has them), as the C probe reports its best of five.
                let s = (0..5)
                    .map(|_| {
                        let t = Instant::now();
                        std::hint::black_box(rig.warp(&rig.channels[0]));
                        t.elapsed().as_secs_f64()
                    })
                    .fold(f64::INFINITY, f64::min);
                let against = match (&probe, lens) {
                    (Some(p), "LENSMODEL_OPENCV5") if !name.starts_with("mesh") => {
                        run_probe(p, name, w, h)
                            .map(|c| format!("  C probe {:>6.0} ms: {:.2}× it", c * 1e3, s / c))
                    }
                    _ => None,
                };
                outln!(
                    "warp {w}×{h}, {lens:<18} on {name:<22} {:>7.0} ms  {:>5.1} Mpixel/s{}",
                    s * 1e3,
                    f64::from(w) * f64::from(h) / s / 1e6,
                    against.unwrap_or_default()
                );
            }
        }
    }
    if let Some(p) = &probe {
        let _ = std::fs::remove_file(p);
    }
    let rig = read_rig(dome_rig)?;
    let t = Instant::now();
    let warps: Vec<_> = rig.channels.iter().map(|c| rig.warp(c)).collect();
    let tw = t.elapsed().as_secs_f64();
    let t = Instant::now();
    for (c, w) in rig.channels.iter().zip(&warps) {
        std::hint::black_box(rig.blend_weights(c, &w.points));
    }
    outln!(
        "dome example, {} projectors of {}×{}: warps {:.0} ms, blends {:.0} ms",
        rig.channels.len(),
        rig.channels[0].width,
        rig.channels[0].height,
        tw * 1e3,
        t.elapsed().as_secs_f64() * 1e3
    );
    Ok(())
}

/// calibration/bench/rig_probe.c built for this machine (`-O3 -march=native`, OpenMP), or
/// `None`, said why, when there is no C compiler.
fn build_probe() -> Option<std::path::PathBuf> {
    let source = Path::new(env!("CARGO_MANIFEST_DIR")).join("calibration/bench/rig_probe.c");
    let out = std::env::temp_dir().join(format!("omniwarp-rig-probe-{}", std::process::id()));
    let built = std::process::Command::new("cc")
        .args(["-O3", "-march=native", "-fopenmp", "-o"])
        .arg(&out)
        .arg(&source)
        .arg("-lm")
        .status();
    match built {
        Ok(s) if s.success() => Some(out),
        _ => {
            eprintln!(
                "no C probe: `cc -O3 -march=native -fopenmp` could not build {}",
                source.display()
            );
            None
        }
    }
}

/// The probe's best of five on `surface` at `w`×`h`, seconds, with as many threads as rayon.
fn run_probe(probe: &Path, surface: &str, w: u32, h: u32) -> Option<f64> {
    let out = std::process::Command::new(probe)
        .args([surface, &format!("{w}x{h}")])
        .env("OMP_NUM_THREADS", rayon::current_num_threads().to_string())
        .output()
        .ok()?;
    let text = String::from_utf8_lossy(&out.stdout);
    let ms: f64 = text
        .split(": ")
        .nth(1)?
        .split(" ms")
        .next()?
        .trim()
        .parse()
        .ok()?;
    Some(ms / 1e3)
}
