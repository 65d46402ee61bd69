//! What a projector covers, as an integrator decides a rig from: the share of its pixels that
//! land on the wall, the part of the content they show (longitude and latitude from the eye, in
//! the content's frame) and how densely (pixels per degree seen from the eye).

use super::{Channel, Rig};
use crate::tiles::raster::{angles, unwrap_deg};

/// A channel's coverage, from its pixels sampled on a grid (see [`Rig::coverage`]).
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct Coverage {
    /// The channel's id.
    pub id: String,
    /// Share of the sampled pixels that light the wall, 0–1; the rest are wasted off it.
    pub on_wall: f64,
    /// Longitudes shown, degrees `[least, most]`, unwrapped around the channel's middle and
    /// written with the range's middle in (−180, 180], so a channel behind the eye reads e.g.
    /// `[150, 210]`; `None` when no pixel lands.
    pub longitude: Option<[f64; 2]>,
    /// Latitudes shown, degrees `[least, most]`.
    pub latitude: Option<[f64; 2]>,
    /// Pixels per degree of the content seen from the eye, across the projector's rows:
    /// `[least, median, most]`.
    pub pixels_per_degree: Option<[f64; 3]>,
}

impl Rig {
    /// The coverage of channel `ch`, from every `step`-th pixel each way (at least 1).
    pub fn coverage(&self, ch: &Channel, step: u32) -> Coverage {
        let step = step.max(1);
        let (cols, rows) = (ch.width.div_ceil(step), ch.height.div_ceil(step));
        let at = |i: u32, j: u32| {
            let q = [f64::from(i * step), f64::from(j * step)];
            self.wall_point(ch, q)
                .and_then(|p| self.sampling_vector(p))
                .map(|v| (q, v))
        };
        let middle = at(cols / 2, rows / 2).map_or(0.0, |(_, v)| angles(v).0);
        let (mut lit, mut lon, mut lat, mut density) = (
            0usize,
            [f64::MAX, f64::MIN],
            [f64::MAX, f64::MIN],
            Vec::new(),
        );
        for j in 0..rows {
            let mut before: Option<([f64; 2], glam::DVec3)> = None;
            for i in 0..cols {
                let here = at(i, j);
                if let Some((q, v)) = here {
                    lit += 1;
                    let (phi, theta) = angles(v);
                    let phi = unwrap_deg(phi, middle);
                    lon = [lon[0].min(phi), lon[1].max(phi)];
                    lat = [lat[0].min(theta), lat[1].max(theta)];
                    if let Some((q0, v0)) = before {
                        let degrees = v0.angle_between(v).to_degrees();
                        if degrees > 0.0 {
                            density.push((q[0] - q0[0]) / degrees);
                        }
                    }
                }
                before = here;
            }
        }
        density.sort_by(f64::total_cmp);
        let range = |r: [f64; 2]| (lit > 0).then_some(r);
        // Written with the middle of the range in (−180°, 180°]: a channel behind the eye reads
        // 90 … 270, not −270 … −90.
        let turns = ((lon[0] + lon[1]) / 2.0 / 360.0 - 0.5).ceil();
        let lon = lon.map(|v| v - 360.0 * turns);
        Coverage {
            id: ch.id.clone(),
            on_wall: lit as f64 / (u64::from(cols) * u64::from(rows)) as f64,
            longitude: range(lon),
            latitude: range(lat),
            pixels_per_degree: (!density.is_empty()).then(|| {
                [
                    density[0],
                    density[density.len() / 2],
                    density[density.len() - 1],
                ]
            }),
        }
    }
}
