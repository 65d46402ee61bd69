//! `omniwarp bench lens`: project and unproject throughput per lens model, points per second, on
//! one thread and on all cores.

use anyhow::Result;
use glam::DVec3;
use omniwarp::lens::Lens;

pub fn run() -> Result<()> {
    use rayon::prelude::*;
    use std::time::Instant;
    let mut splined = vec![900.0, 905.0, 959.5, 539.5];
    splined.extend((0..384).map(|i| 0.002 * ((i % 7) as f64 - 3.0)));
    let models: [(&str, Vec<f64>); 11] = [
        ("LENSMODEL_PINHOLE", vec![1500.0, 1500.0, 959.5, 539.5]),
        (
            "LENSMODEL_OPENCV4",
            vec![1500.0, 1500.0, 959.5, 539.5, -0.2, 0.05, 1e-3, -1e-3],
        ),
        (
            "LENSMODEL_OPENCV5",
            vec![1500.0, 1500.0, 959.5, 539.5, -0.2, 0.05, 1e-3, -1e-3, 0.01],
        ),
        (
            "LENSMODEL_OPENCV8",
            vec![
                1500.0, 1500.0, 959.5, 539.5, -0.2, 0.05, 1e-3, -1e-3, 0.01, 0.02, -0.01, 0.005,
            ],
        ),
        (
            "LENSMODEL_OPENCV14",
            vec![
                1500.0, 1500.0, 959.5, 539.5, -0.2, 0.05, 1e-3, -1e-3, 0.01, 0.02, -0.01, 0.005,
                1e-3, -1e-4, 1e-3, -1e-4, 0.01, -0.01,
            ],
        ),
        (
            "LENSMODEL_OPENCV_FISHEYE",
            vec![600.0, 600.0, 959.5, 959.5, 0.02, -0.01, 0.002, -0.0005],
        ),
        ("LENSMODEL_STEREOGRAPHIC", vec![800.0, 800.0, 959.5, 539.5]),
        ("LENSMODEL_LONLAT", vec![600.0, 600.0, 959.5, 539.5]),
        ("LENSMODEL_LATLON", vec![600.0, 600.0, 959.5, 539.5]),
        (
            "LENSMODEL_CAHVOR",
            vec![
                1200.0, 1190.0, 959.5, 539.5, 0.01, -0.02, -0.05, 0.02, -0.003,
            ],
        ),
        (
            "LENSMODEL_SPLINED_STEREOGRAPHIC_order=3_Nx=16_Ny=12_fov_x_deg=120",
            splined,
        ),
    ];
    let n = 100_000;
    outln!("{n} points per model over the whole image; points per second (millions), best of 5");
    outln!(
        "{:<26} {:>10} {:>10} {:>10} {:>10}",
        "model",
        "proj 1T",
        "proj all",
        "unproj 1T",
        "unproj all"
    );
    // The splined model's name carries its configuration; the table shows the family.
    let short = |name: &str| name.split("_order").next().unwrap_or(name).to_string();
    for (name, intrinsics) in models {
        let lens = Lens::new(name.parse()?, intrinsics)?;
        // Pixels on a 400 × 250 lattice over the whole 1920×1080 image (the corners, where
        // distortion and the solvers work hardest, included), unprojected once to get points the
        // model can take.
        let pixels: Vec<[f64; 2]> = (0..n)
            .map(|i| {
                let (col, row) = ((i % 400) as f64, (i / 400) as f64);
                [
                    (col + 0.5) * 1920.0 / 400.0 - 0.5,
                    (row + 0.5) * 1080.0 / 250.0 - 0.5,
                ]
            })
            .collect();
        let rays: Vec<DVec3> = pixels
            .iter()
            .filter_map(|q| lens.unproject(*q).ok())
            .collect();
        // Best of five: one timing of a few milliseconds is at the mercy of the machine.
        let rate = |f: &dyn Fn() -> usize| {
            (0..5)
                .map(|_| {
                    let t = Instant::now();
                    let k = f();
                    k as f64 / t.elapsed().as_secs_f64() / 1e6
                })
                .fold(0.0, f64::max)
        };
        let p1 = rate(&|| rays.iter().filter(|r| lens.project(**r).is_ok()).count());
        let pn = rate(&|| {
            rays.par_iter()
                .filter(|r| lens.project(**r).is_ok())
                .count()
        });
        let u1 = rate(&|| {
            pixels
                .iter()
                .filter(|q| lens.unproject(**q).is_ok())
                .count()
                .max(1)
        });
        let un = rate(&|| {
            pixels
                .par_iter()
                .filter(|q| lens.unproject(**q).is_ok())
                .count()
                .max(1)
        });
        outln!(
            "{:<26} {p1:>10.2} {pn:>10.2} {u1:>10.2} {un:>10.2}",
            short(name)
        );
    }
    Ok(())
}
