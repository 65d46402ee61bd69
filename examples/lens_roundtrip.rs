//! A lens model's projection and its inverse: a point to a pixel and back to a ray.
//!
//! OpenCV's five-coefficient model (mrcal's `LENSMODEL_OPENCV5`) with strong barrel
//! distortion; the same calls work for every model in `omniwarp::lens::LensModel`.
//!
//! ```text
//! cargo run --release --example lens_roundtrip
//! ```

use omniwarp::glam::DVec3;
use omniwarp::lens::{Lens, LensModel};

fn main() -> omniwarp::Result<()> {
    // fx, fy, cx, cy, then k1, k2, p1, p2, k3.
    let intrinsics = vec![
        1500.0, 1500.0, 959.5, 539.5, -0.2, 0.05, 0.001, -0.001, 0.01,
    ];
    let lens = Lens::new("LENSMODEL_OPENCV5".parse::<LensModel>()?, intrinsics)?;

    let mut worst = 0.0f64;
    for p in [
        DVec3::new(0.0, 0.0, 1.0),
        DVec3::new(0.1, 0.2, 1.0),
        DVec3::new(-0.4, 0.25, 1.0),
        DVec3::new(0.5, -0.3, 1.2),
    ] {
        // A point in the camera frame (z forward) to its pixel, with the exact Jacobians.
        let q = lens.project_with_jacobians(p).map_err(no_image)?;
        // The pixel back to a unit ray; the angle to the original direction is the error.
        let ray = lens.unproject(q.q).map_err(no_image)?;
        let error = ray.angle_between(p.normalize());
        worst = worst.max(error);
        println!(
            "{p} → ({:8.3}, {:8.3}) px, ∂u/∂x = {:8.2}; back within {error:.1e} rad",
            q.q[0], q.q[1], q.dq_dp[0][0]
        );
    }
    assert!(worst < 1e-9, "the inverse missed by {worst} rad");
    Ok(())
}

/// A point or pixel the lens cannot image, as a library error naming why.
fn no_image(e: omniwarp::lens::NoImage) -> omniwarp::Error {
    omniwarp::Error::invalid("point", e.0)
}
