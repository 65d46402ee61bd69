//! `omniwarp bench calibrate`: calibration time against point count (50, 500, 5000) and lens
//! model.

use super::super::args::named;
use anyhow::Result;
use omniwarp::calibration::{Correspondence, ModelChoice, Problem, calibrate};
use omniwarp::lens::{Lens, LensModel};

/// Calibration time against point count and model.
pub fn run() -> Result<()> {
    use glam::{DMat3, DVec3};
    use omniwarp::surface::{Cylinder, Screen};
    use std::time::Instant;
    let screen = Screen::Cylinder(Cylinder {
        radius: 2.5,
        centre: [0.0; 3],
        axis: [0.0, 1.0, 0.0],
        height: [-3.0, 3.0],
        arc: [-180.0, 180.0],
    });
    let truth = Lens::new(
        LensModel::OpenCv(5),
        vec![
            1500.0, 1495.0, 955.0, 560.0, -0.08, 0.03, 0.0008, -0.0005, -0.01,
        ],
    )?;
    let f = DVec3::new(0.3, 0.2, -1.0).normalize();
    let r = f.cross(DVec3::Y).normalize();
    let rot = DMat3::from_cols(r, f.cross(r), f);
    let pos = DVec3::new(0.2, -0.3, 0.4);
    outln!(
        "{:>6} {:>10} {:>10} {:>10} {:>10}",
        "points",
        "PINHOLE",
        "OPENCV4",
        "OPENCV5",
        "OPENCV8"
    );
    for n in [50usize, 500, 5000] {
        let side = (n as f64 * 16.0 / 9.0).sqrt().ceil() as usize;
        let mut points = Vec::new();
        let mut k = 0u64;
        'outer: for j in 0..side {
            for i in 0..side {
                if points.len() == n {
                    break 'outer;
                }
                let q = [
                    20.0 + 1880.0 * (i as f64 + 0.5) / side as f64,
                    20.0 + 1040.0 * (j as f64 + 0.5) * 16.0 / 9.0 / side as f64,
                ];
                if q[1] > 1060.0 {
                    continue;
                }
                k = k.wrapping_mul(6364136223846793005).wrapping_add(1);
                let noise = ((k >> 40) as f64 / (1u64 << 24) as f64 - 0.5) * 0.6;
                if let Some(p) = truth
                    .unproject(q)
                    .ok()
                    .and_then(|ray| screen.intersect(pos, rot * ray).point())
                {
                    points.push(Correspondence {
                        pixel: [q[0] + noise, q[1] - noise],
                        world: p.to_array(),
                    });
                }
            }
        }
        let problem = Problem {
            resolution: [1920, 1080],
            points,
            lens: None,
            intrinsics_fixed: false,
        };
        let mut row = format!("{:>6}", problem.points.len());
        for model in [
            LensModel::Pinhole,
            LensModel::OpenCv(4),
            LensModel::OpenCv(5),
            LensModel::OpenCv(8),
        ] {
            let t = Instant::now();
            calibrate(&problem, ModelChoice::Fixed(model))
                .map_err(|e| anyhow::anyhow!("{}", named(e)))?;
            row += &format!(" {:>8.1}ms", t.elapsed().as_secs_f64() * 1e3);
        }
        outln!("{row}");
    }
    Ok(())
}
