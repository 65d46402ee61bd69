//! `omniwarp bench rig`: warp generation for a 3840×2160 projector on each surface type, and blend
//! computation for the five-projector dome example.

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
    for lens in ["LENSMODEL_PINHOLE", "LENSMODEL_OPENCV5"] {
        let intrinsics: Vec<f64> = match lens {
            "LENSMODEL_PINHOLE" => vec![2400.0, 2400.0, 1919.5, 1079.5],
            _ => vec![
                2400.0, 2400.0, 1919.5, 1079.5, -0.05, 0.01, 0.0005, -0.0003, -0.002,
            ],
        };
        for (name, screen) in &screens {
            let doc = omniwarp::rig::RigDoc {
                format: 1,
                screen: screen.clone(),
                eye: [0.0; 3],
                content: Default::default(),
                channels: vec![omniwarp::rig::ChannelDoc {
                    id: "p".into(),
                    resolution: [3840, 2160],
                    lens: omniwarp::rig::LensDoc::new(lens, intrinsics.clone()),
                    pose: omniwarp::rig::PoseDoc {
                        position: [0.0, 0.3, 0.5],
                        look_to: Some([0.0, 0.0, -1.0]),
                        look_up: Some([0.0, 1.0, 0.0]),
                        rvec: None,
                    },
                }],
                canvas: None,
            };
            let rig = Rig::from_doc(doc)?;
            // The best of three, each with its outputs freshly allocated (as a warp computed
            // on request has them), as the C probe of calibration/bench/bench-peers reports its best.
            let s = (0..3)
                .map(|_| {
                    let t = Instant::now();
                    std::hint::black_box(rig.warp(&rig.channels[0]));
                    t.elapsed().as_secs_f64()
                })
                .fold(f64::INFINITY, f64::min);
            outln!(
                "warp 3840×2160, {lens:<18} on {name:<22} {:>7.0} ms  {:>5.1} Mpixel/s",
                s * 1e3,
                3840.0 * 2160.0 / s / 1e6
            );
        }
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
