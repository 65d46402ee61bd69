//! `omniwarp bench tiles`: normal-map generation from tile screens for grid and output sizes.

use anyhow::Result;
use omniwarp::projection::Params;
use omniwarp::tiles::adapt::rows_for;
use omniwarp::tiles::build::{Source, from_source};
use std::time::Instant;

pub fn run() -> Result<()> {
    let source = Source::new(
        "fisheye",
        Params {
            fov: Some(200.0),
            ..Params::default()
        },
        9.0 / 16.0,
    );
    outln!("normal map from a fisheye 200° tile screen (vector interpolation), all cores");
    for (w, h) in [(1920usize, 1080usize), (3840, 2160)] {
        for columns in [9usize, 33, 129, 513] {
            let screen = from_source(&source, columns, rows_for(columns, w, h))?;
            let mut best = f64::MAX;
            for _ in 0..3 {
                let t = Instant::now();
                let map = screen.feature_map(w, h).normal_map();
                std::hint::black_box(&map);
                best = best.min(t.elapsed().as_secs_f64());
            }
            outln!("  {w}×{h}, {columns:>3} columns: {:>7.1} ms", best * 1e3);
        }
    }
    Ok(())
}
