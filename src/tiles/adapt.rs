//! Choosing how dense a tile screen must be: the coarsest regular grid whose reconstruction of
//! the source warp stays within a tolerance ("model no more than a scene needs").
//!
//! The error of a tile screen is measured at every pixel centre of the output it is for: the
//! angle between the sampling vector its normal map holds and the source projection's exact one.
//! In output pixels it is that angle over the local angular size of a pixel there (the mean angle
//! to the right and lower neighbours), which is what a viewer sees as misplacement.

use super::TileScreen;
use super::build::{Source, from_source};
use crate::error::{Error, Result};
use crate::projection::View;
use crate::projection::view::screen_of_pixel;
use glam::DVec3;
use rayon::prelude::*;

/// A tolerance for the reconstruction error.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Tolerance {
    /// At most this angle between the screen's sampling vectors and the exact ones, degrees.
    Degrees(f64),
    /// At most this error in output pixels (the angle over a pixel's local angular size).
    Pixels(f64),
}

/// How well a tile screen reproduces its source.
#[derive(Debug, Clone, PartialEq)]
pub struct Report {
    /// Grid columns (a triangle soup's triangle count).
    pub columns: usize,
    /// Grid rows (1 for a triangle soup).
    pub rows: usize,
    /// Features in all.
    pub features: usize,
    /// Largest angle between the screen's sampling vector and the exact one at a pixel centre,
    /// degrees.
    pub max_deg: f64,
    /// RMS of that angle over the covered pixels, degrees.
    pub rms_deg: f64,
    /// Largest error in output pixels: the angle over the local angular size of a pixel.
    pub max_px: f64,
    /// Pixels the source shows but no tile covers (tiles with a corner outside the source's
    /// formula, e.g. at an orthographic fisheye's rim).
    pub uncovered: usize,
}

/// The exact sampling vectors of `view` at width × height pixel centres.
pub fn exact(view: &View, width: usize, height: usize) -> Vec<Option<DVec3>> {
    (0..width * height)
        .into_par_iter()
        .map(|n| {
            let (i, j) = (n % width, n / width);
            let (s, t) =
                screen_of_pixel(i as f64 + 0.5, j as f64 + 0.5, width as u32, height as u32);
            view.direction(s, t).ok()
        })
        .collect()
}

/// Measures `screen` against exact vectors for a width × height output.
pub fn measure(
    screen: &TileScreen,
    truth: &[Option<DVec3>],
    width: usize,
    height: usize,
) -> Report {
    let map = screen.feature_map(width, height).normal_map();
    let pixel_size = |n: usize, v: DVec3| {
        let (i, j) = (n % width, n / width);
        let mut sizes = Vec::with_capacity(2);
        if let Some(Some(r)) = (i + 1 < width).then(|| truth[n + 1]) {
            sizes.push(v.angle_between(r));
        }
        if let Some(Some(d)) = (j + 1 < height).then(|| truth[n + width]) {
            sizes.push(v.angle_between(d));
        }
        (!sizes.is_empty()).then(|| sizes.iter().sum::<f64>() / sizes.len() as f64)
    };
    let (max_deg, sum_sq, count, max_px, uncovered) = (0..width * height)
        .into_par_iter()
        .filter_map(|n| truth[n].map(|v| (n, v)))
        .map(|(n, v)| match map.direction(n % width, n / width) {
            Some(got) => {
                let e = v.angle_between(got);
                let px = pixel_size(n, v).map_or(0.0, |p| e / p);
                (e.to_degrees(), e.to_degrees().powi(2), 1usize, px, 0usize)
            }
            None => (0.0, 0.0, 0, 0.0, 1),
        })
        .reduce(
            || (0.0, 0.0, 0, 0.0, 0),
            |a, b| (a.0.max(b.0), a.1 + b.1, a.2 + b.2, a.3.max(b.3), a.4 + b.4),
        );
    let (columns, rows) = match &screen.layout {
        super::Layout::Grid { columns, rows, .. } => (*columns, *rows),
        super::Layout::Soup { triangles } => (triangles.len(), 1),
    };
    Report {
        columns,
        rows,
        features: screen.feature_count(),
        max_deg,
        rms_deg: (sum_sq / count.max(1) as f64).sqrt(),
        max_px,
        uncovered,
    }
}

/// Rows for `columns` columns: tiles about square on a width × height output.
pub fn rows_for(columns: usize, width: usize, height: usize) -> usize {
    (((columns - 1) as f64 * height as f64 / width as f64).round() as usize).max(1) + 1
}

/// The coarsest grid (fewest columns, rows following the output's aspect) sampled from
/// `source` whose error for a width × height output is within `tolerance`.
pub fn choose(
    source: &Source,
    width: usize,
    height: usize,
    tolerance: Tolerance,
) -> Result<(TileScreen, Report)> {
    let limit = match tolerance {
        Tolerance::Degrees(d) | Tolerance::Pixels(d) if d.is_finite() && d > 0.0 => d,
        _ => return Err(Error::invalid("tolerance", "must be a positive number")),
    };
    let truth = exact(&source.view()?, width, height);
    let attempt = |columns: usize| -> Result<(TileScreen, Report)> {
        let screen = from_source(source, columns, rows_for(columns, width, height))?;
        let report = measure(&screen, &truth, width, height);
        Ok((screen, report))
    };
    // A pixel the source shows and no tile covers is a miss whatever the tolerance.
    let fits = |r: &Report| {
        r.uncovered == 0
            && match tolerance {
                Tolerance::Degrees(_) => r.max_deg <= limit,
                Tolerance::Pixels(_) => r.max_px <= limit,
            }
    };
    // Double until it fits, then bisect between the last miss and the first fit.
    let most = width.clamp(2, 1025);
    let (mut lo, mut hi) = (1usize, 2usize);
    let mut best = loop {
        let found = attempt(hi)?;
        if fits(&found.1) {
            break found;
        }
        if hi >= most {
            return Err(Error::invalid(
                "tolerance",
                format!(
                    "not reached even by a {hi}-column grid (max error {:.4}°, {:.3} px, \
                     {} pixels uncovered)",
                    found.1.max_deg, found.1.max_px, found.1.uncovered
                ),
            ));
        }
        lo = hi;
        hi = (hi * 2).min(most);
    };
    while hi - lo > 1 {
        let mid = (lo + hi) / 2;
        let found = attempt(mid)?;
        if fits(&found.1) {
            hi = mid;
            best = found;
        } else {
            lo = mid;
        }
    }
    Ok(best)
}
