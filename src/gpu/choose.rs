//! Model no more than a scene needs: given a tolerance, the cheapest way to draw this scene
//! through this view that meets it. Each method's coarsest setting that meets the tolerance is
//! found from geometry alone, then both are timed on the scene itself and the faster is kept.
//!
//! * The cube map (seed 000) is off by up to half a texel where its texels are largest, at a
//!   face's centre: 1/N radians for faces of N², so N ≥ 1/tolerance (a multiple of 16; the
//!   faces drawn are still only those the view samples).
//! * Piecewise perspective projection (seed 003) is off by its pieces' measured deviation:
//!   [`Pieces::for_tolerance`].

use super::frame::{FrameOptions, SceneRenderer};
use super::warp::Source;
use crate::error::{Error, Result};
use crate::scene::ppp::{Directions, Pieces, Tolerance, ViewAt, median_pitch_on};
use std::time::Instant;

/// A method at a setting.
#[derive(Debug, Clone)]
pub enum Method {
    /// A cube map of `face` × `face` texels a face.
    Cube {
        /// Width and height of each cube face in texels (a multiple of 16, at least 64).
        face: u32,
    },
    /// Piecewise perspective projection with these pieces.
    Ppp(Pieces),
}

/// One candidate the chooser weighed.
#[derive(Debug, Clone)]
pub struct Candidate {
    /// The method and its setting.
    pub method: Method,
    /// Its worst sampling error, radians.
    pub angle: f64,
    /// One frame of this scene, milliseconds.
    pub ms: f64,
}

impl Candidate {
    /// A one-line description for people, e.g. `cube map 1024²` or
    /// `ppp 16×8 cells (128 pieces)`.
    pub fn describe(&self) -> String {
        match &self.method {
            Method::Cube { face } => format!("cube map {face}²"),
            Method::Ppp(p) => format!(
                "ppp {}×{} cells ({} pieces)",
                p.cols,
                p.rows,
                p.pieces.len()
            ),
        }
    }
}

/// The candidates, fastest first; the first is the choice. `source` is a view or a projector
/// channel's warp map; `max_face` bounds the cube.
pub fn choose(
    r: &mut SceneRenderer,
    source: Source<'_>,
    o: &FrameOptions,
    tolerance: Tolerance,
    max_face: u32,
) -> Result<Vec<Candidate>> {
    let (w, h) = o.size;
    let view_at;
    let dirs: &dyn Directions = match source {
        Source::View(view) => {
            view_at = ViewAt::new(view, w, h)?;
            &view_at
        }
        Source::Map(map) => map,
    };
    if dirs.size() != (w, h) {
        return Err(Error::invalid(
            "size",
            format!("the warp map is {:?}, the frame {w}×{h}", dirs.size()),
        ));
    }
    let angle = match tolerance {
        Tolerance::Angle(a) => a,
        Tolerance::Pixels(p) => p * median_pitch_on(dirs),
    };
    let mut out = Vec::new();
    let face = ((1.0 / angle / 16.0).ceil() * 16.0).max(64.0);
    if face <= f64::from(max_face) {
        let face = face as u32;
        let of = FrameOptions {
            face: Some(face),
            ..*o
        };
        r.frame_from(source, &of)?;
        r.invalidate();
        let start = Instant::now();
        r.frame_from(source, &of)?;
        out.push(Candidate {
            method: Method::Cube { face },
            angle: 1.0 / f64::from(face),
            ms: start.elapsed().as_secs_f64() * 1e3,
        });
    }
    if let Ok((pieces, d)) = Pieces::for_tolerance_on(dirs, Tolerance::Angle(angle)) {
        r.frame_ppp(&pieces, o)?;
        let start = Instant::now();
        r.frame_ppp(&pieces, o)?;
        out.push(Candidate {
            angle: d.angle,
            ms: start.elapsed().as_secs_f64() * 1e3,
            method: Method::Ppp(pieces),
        });
    }
    if out.is_empty() {
        return Err(Error::invalid(
            "tolerance",
            format!(
                "{}: neither a cube map up to {max_face}² nor a cut into pieces meets it",
                tolerance.describe()
            ),
        ));
    }
    out.sort_by(|a, b| a.ms.total_cmp(&b.ms));
    Ok(out)
}
