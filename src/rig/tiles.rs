//! A channel's geometric warp as an editable tile screen: what a technician starts from when
//! they first adjust a channel by hand.

use super::{Channel, Rig};
use crate::error::Result;
use crate::tiles::TileScreen;
use crate::tiles::build::{extend_past_edge, grid_of};

/// Columns of a tile screen sampled from a channel's geometry when none are asked for.
pub const SAMPLED_COLUMNS: usize = 33;

impl Rig {
    /// Channel `ch`'s geometric warp sampled into a `columns` × `rows` grid: feature (x, y) shows
    /// the content direction of the projector pixel at (x·W − ½, y·H − ½), so the grid runs from
    /// image edge to image edge. Features just off the wall are extrapolated
    /// ([`extend_past_edge`]): the tiles across the wall's edge stay, and the warp's own
    /// footprint cuts them.
    pub fn sample_tiles(&self, ch: &Channel, columns: usize, rows: usize) -> Result<TileScreen> {
        let (w, h) = (f64::from(ch.width), f64::from(ch.height));
        let pixel = |x: f64, y: f64| [x * w - 0.5, y * h - 0.5];
        let mut t = grid_of(columns, rows, |s, t| {
            let v = self
                .wall_point(ch, pixel((s + 1.0) / 2.0, (1.0 - t) / 2.0))
                .and_then(|p| self.sampling_vector(p));
            (v, 1.0)
        })?;
        let wider = self.doc.screen.extended();
        extend_past_edge(&mut t, |x, y| {
            let ray = ch.lens.unproject(pixel(x, y)).ok()?;
            let p = wider.intersect(ch.position, ch.rotation * ray).point()?;
            self.sampling_vector(p)
        });
        Ok(t)
    }

    /// [`Rig::sample_tiles`] at [`SAMPLED_COLUMNS`] columns and as many rows as keep the tiles
    /// about square on the projector's raster.
    pub fn default_tiles(&self, ch: &Channel) -> Result<TileScreen> {
        self.sample_tiles(ch, SAMPLED_COLUMNS, default_rows(ch))
    }
}

/// Rows of a [`SAMPLED_COLUMNS`]-column grid on `ch`'s raster, following its aspect.
pub fn default_rows(ch: &Channel) -> usize {
    let r = (SAMPLED_COLUMNS - 1) as f64 * f64::from(ch.height) / f64::from(ch.width);
    (r.round() as usize + 1).max(2)
}
