//! How wide edges come out, region by region, against a reference image: the measure behind seed
//! 003's Figure 8, where an image resampled from a cube map draws one-pixel lines wider in some
//! parts of the image than in others and a piecewise perspective projection does not.
//!
//! An edge blurred to w pixels keeps its height but spreads its gradient over w pixels, so its
//! squared-gradient energy falls as 1/w. The reference's energy over the image's, per region, is
//! the image's edge width relative to the reference's there: 1 where they match, above 1 where
//! the image is blurred, below where it is sharper (aliased).

use super::{Pixel, Raster};

/// Regions whose reference has less than this share of the median region's edge energy are
/// left out (sky, flat walls): their ratio would be noise.
const QUIET: f64 = 0.05;

/// Relative edge widths of `image` against `reference` in a `blocks` × `blocks` grid of regions,
/// row by row, for the regions with edges enough to measure.
pub fn relative_edge_widths<T: Pixel>(
    image: &Raster<T>,
    reference: &Raster<T>,
    blocks: usize,
) -> Vec<f64> {
    assert_eq!(
        (image.width, image.height),
        (reference.width, reference.height),
        "edge widths of images of different sizes"
    );
    let energy = |img: &Raster<T>| -> Vec<f64> {
        let luma = |x: usize, y: usize| {
            let p = img.get(x, y).to_f32();
            f64::from(p[0] + p[1] + p[2]) / 3.0
        };
        let mut e = vec![0.0; blocks * blocks];
        for y in 0..img.height.saturating_sub(1) {
            for x in 0..img.width.saturating_sub(1) {
                let c = luma(x, y);
                let (dx, dy) = (luma(x + 1, y) - c, luma(x, y + 1) - c);
                let k = (y * blocks / img.height) * blocks + x * blocks / img.width;
                e[k] += dx * dx + dy * dy;
            }
        }
        e
    };
    let (mine, theirs) = (energy(image), energy(reference));
    let mut sorted = theirs.clone();
    sorted.sort_by(f64::total_cmp);
    let median = sorted[sorted.len() / 2];
    theirs
        .iter()
        .zip(&mine)
        .filter(|(r, m)| **r > QUIET * median && **r > 0.0 && **m > 0.0)
        .map(|(r, m)| r / m)
        .collect()
}

/// The spread of relative edge widths: their 90th percentile over their 10th (1 when every
/// region's edges are as wide relative to the reference as every other's).
pub fn spread(widths: &[f64]) -> f64 {
    let mut w = widths.to_vec();
    w.sort_by(f64::total_cmp);
    let at = |q: f64| w[((w.len() - 1) as f64 * q).round() as usize];
    if w.is_empty() {
        f64::NAN
    } else {
        at(0.9) / at(0.1)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Vertical bars, each `width` pixels of a linear ramp between black and white.
    fn bars(width: usize) -> Raster<[u8; 4]> {
        Raster::from_fn(256, 64, |x, _| {
            let phase = (x % 32) as f64;
            let v = (phase / width as f64).min(1.0) * 255.0;
            let v = if (x / 32) % 2 == 0 { v } else { 255.0 - v };
            [v as u8, v as u8, v as u8, 255]
        })
    }

    #[test]
    fn a_blurred_image_has_wider_edges_and_the_same_one_none() {
        let sharp = bars(1);
        let same = relative_edge_widths(&sharp, &sharp, 4);
        assert!(same.iter().all(|w| (w - 1.0).abs() < 1e-12), "{same:?}");
        assert!((spread(&same) - 1.0).abs() < 1e-12);
        let soft = bars(4);
        let wider = relative_edge_widths(&soft, &sharp, 4);
        assert!(wider.iter().all(|&w| w > 2.0), "{wider:?}");
    }
}
