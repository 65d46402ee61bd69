//! Which cube faces, and how fine a cube, a warp needs: seed 000's cube-map face culling (CMF)
//! decided exactly from the sampling vectors, and the face size from the output's pixel pitch.
//! The GPU's cube-map pass (`src/gpu/cube.rs`) draws only these faces; the CPU ray caster
//! (`src/scene/raycast.rs`) uses the same size.

use crate::cubemap::{Face, face_point, select};
use crate::normalmap::NormalMap;
use rayon::prelude::*;

/// The faces a bilinear lookup along any valid vector of `map` reads on a cube of `size`:
/// the face each vector selects, and a neighbour wherever its footprint crosses an edge.
pub fn faces_sampled(map: &NormalMap, size: u32) -> [bool; 6] {
    let n = f64::from(size);
    let (w, h) = (map.width(), map.height());
    let sets: Vec<u8> = (0..h)
        .into_par_iter()
        .map(|j| {
            let mut set = 0u8;
            for i in 0..w {
                let Some(v) = map.direction(i, j) else {
                    continue;
                };
                let (face, s, t) = select(v);
                set |= 1 << face.index();
                // The footprint spans texel centres x and x + 1 (likewise y); where it
                // leaves the face it reads the neighbour across that edge.
                let (x, y) = (s * n - 0.5, t * n - 0.5);
                let (xi, yi) = (x.clamp(0.0, n - 1.0) + 0.5, y.clamp(0.0, n - 1.0) + 0.5);
                let mut beyond = Vec::new();
                if x < 0.0 {
                    beyond.push((-0.5, yi));
                }
                if x > n - 1.0 {
                    beyond.push((n + 0.5, yi));
                }
                if y < 0.0 {
                    beyond.push((xi, -0.5));
                }
                if y > n - 1.0 {
                    beyond.push((xi, n + 0.5));
                }
                for (bx, by) in beyond {
                    set |= 1 << select(face_point(face, bx / n, by / n)).0.index();
                }
            }
            set
        })
        .collect();
    let all = sets.iter().fold(0u8, |a, b| a | b);
    Face::ALL.map(|f| all & (1 << f.index()) != 0)
}

/// The smallest face size (a multiple of 16, 64 to `max`) whose texels at the face centres
/// are no larger than the output's finer pixels (the 10th percentile of the angle between
/// neighbouring sampling vectors): a finer cube map would add nothing the output can show.
pub fn face_size_for(map: &NormalMap, max: u32) -> u32 {
    let (w, h) = (map.width(), map.height());
    // Every few rows are plenty for a percentile (about 64 rows of a 4K map), and it is asked
    // for on every preview.
    let stride = (h / 64).max(1);
    let mut pitch: Vec<f64> = (0..h)
        .into_par_iter()
        .step_by(stride)
        .flat_map_iter(|j| {
            (0..w.saturating_sub(1)).filter_map(move |i| {
                let (a, b) = (map.direction(i, j)?, map.direction(i + 1, j)?);
                Some(a.angle_between(b))
            })
        })
        .filter(|a| *a > 0.0)
        .collect();
    if pitch.is_empty() {
        return 64;
    }
    let tenth = pitch.len() / 10;
    let fine = *pitch.select_nth_unstable_by(tenth, f64::total_cmp).1;
    // A centre texel of a size-N face spans 2/N radians.
    let n = (2.0 / fine).ceil() as u32;
    (n.div_ceil(16) * 16).clamp(64, max)
}
