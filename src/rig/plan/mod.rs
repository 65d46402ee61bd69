//! Planning a rig before the projectors are bought or hung: what the wall gets from a set of
//! projector positions and lenses, as an integrator decides the projector count, lenses and
//! positions from (docs/planning.md).
//!
//! The wall is sampled from the eye on a grid of content longitude and latitude. Each sample
//! that meets the wall is a patch of it (its solid angle from the eye and its area in square
//! metres); every projector lighting that point (it falls inside its image and the projector's
//! own ray reaches it first, as for the blends) is counted, with
//! - its pixel density from the eye: the square root of the pixels per square degree, from the
//!   derivative of the projector's exact lens model along two perpendicular eye directions;
//! - its relative irradiance cos i / d² (i the angle of incidence, d the throw), which summed
//!   over the projectors lighting a point is its brightness before blending.
//!
//! Overlaps are measured per pair: their share of the wall, and their width the way the blend
//! ramps, from one footprint's middle towards the other's: across longitude (the median over
//! sample rows of the angle the overlap spans along the row) when the two lie side by side,
//! across latitude (the median over columns) when one is above the other.

mod picture;

use super::Rig;
use crate::error::{Error, Result};
use crate::surface::Hit;
use crate::tiles::raster::unwrap_deg;
use glam::DVec3;
use rayon::prelude::*;
use serde::Serialize;
use std::collections::BTreeMap;

/// The grid step by default, degrees; [`crate::limits::PLAN_STEP`] bounds it.
pub const STEP: f64 = 0.5;

/// The plan of a rig: the wall as a whole, each channel, and each overlapping pair.
#[derive(Debug, Clone, Serialize)]
pub struct Plan {
    /// The sampling grid's step, degrees of content longitude and latitude.
    pub step: f64,
    /// The wall as a whole.
    pub wall: WallPlan,
    /// Each channel, in the rig's order.
    pub channels: Vec<ChannelPlan>,
    /// Each pair of channels lighting some of the same wall, in the rig's order.
    pub overlaps: Vec<Overlap>,
    #[serde(skip)]
    grid: Grid,
    #[serde(skip)]
    reference: f64,
}

/// What the plan found at one direction from the eye.
#[derive(Debug, Clone, PartialEq)]
pub struct PointPlan {
    /// The indices of the channels lighting it, in the rig's order.
    pub channels: Vec<usize>,
    /// The finest of their pixel densities from the eye, pixels per degree (0 when unlit).
    pub pixels_per_degree: f64,
    /// Its brightness before blending, relative to a single projector's median irradiance.
    pub brightness: f64,
}

/// The wall as a whole.
#[derive(Debug, Clone, Serialize)]
pub struct WallPlan {
    /// The part of the eye's view the wall fills, steradians.
    pub solid_angle: f64,
    /// The area of the wall seen from the eye, square metres.
    pub area: f64,
    /// Shares of that area lit by no projector, one, two, and three or more; they sum to 1.
    pub lit_by: [f64; 4],
    /// Pixel density from the eye, pixels per degree, where the wall is lit (the finest
    /// projector at each point): least, median (by solid angle) and most.
    pub pixels_per_degree: Option<[f64; 3]>,
    /// Brightness before blending, relative to a single projector's median irradiance: the sum
    /// of cos i / d² over the projectors lighting a point; least, median and most.
    pub brightness: Option<[f64; 3]>,
}

/// One channel's part in the plan.
#[derive(Debug, Clone, Serialize)]
pub struct ChannelPlan {
    /// The channel's id.
    pub id: String,
    /// Share of its pixels that land on the wall (from every 8th pixel or finer).
    pub on_wall: f64,
    /// Its pixels that light nothing, wasted off the wall.
    pub wasted_pixels: u64,
    /// Share of the wall's area it lights.
    pub wall_share: f64,
    /// Longitudes it shows, degrees `[least, most]`.
    pub longitude: Option<[f64; 2]>,
    /// Latitudes it shows, degrees `[least, most]`.
    pub latitude: Option<[f64; 2]>,
    /// Its pixel density from the eye: least, median (by solid angle) and most.
    pub pixels_per_degree: Option<[f64; 3]>,
    /// Its own irradiance across its footprint, relative to the rig's single-projector median:
    /// least and most (the fall-off a uniformity correction has to take out).
    pub brightness: Option<[f64; 2]>,
}

/// Two channels lighting the same wall: where their blend ramps.
#[derive(Debug, Clone, Serialize)]
pub struct Overlap {
    /// The two channels' ids.
    pub channels: [String; 2],
    /// Share of the wall's area both light.
    pub wall_share: f64,
    /// Its width the way the blend ramps (from one footprint towards the other), degrees from
    /// the eye.
    pub width: f64,
    /// Which way that is: `longitude` (side by side) or `latitude` (one above the other).
    pub across: &'static str,
    /// Longitudes it spans, degrees `[least, most]`.
    pub longitude: [f64; 2],
    /// Latitudes it spans, degrees `[least, most]`.
    pub latitude: [f64; 2],
}

/// A projector lighting a sample.
#[derive(Debug, Clone, Copy)]
struct Lit {
    channel: usize,
    pixels_per_degree: f64,
    irradiance: f64,
}

/// A grid sample that meets the wall.
#[derive(Debug, Clone)]
struct Sample {
    solid_angle: f64,
    area: f64,
    lit: Vec<Lit>,
}

/// The sampled wall: row 0 at the top (latitude 90° − step/2), column 0 at longitude
/// −180° + step/2.
#[derive(Debug, Clone, Default)]
struct Grid {
    step: f64,
    columns: usize,
    rows: usize,
    samples: Vec<Option<Sample>>,
}

impl Grid {
    fn longitude(&self, i: usize) -> f64 {
        -180.0 + (i as f64 + 0.5) * self.step
    }

    fn latitude(&self, j: usize) -> f64 {
        90.0 - (j as f64 + 0.5) * self.step
    }

    /// The sample nearest content direction (longitude, latitude), degrees.
    fn at(&self, lon: f64, lat: f64) -> Option<&Sample> {
        let i = ((lon + 180.0).rem_euclid(360.0) / self.step) as usize;
        let j = ((90.0 - lat) / self.step).max(0.0) as usize;
        let (i, j) = (i.min(self.columns - 1), j.min(self.rows - 1));
        self.samples[j * self.columns + i].as_ref()
    }
}

/// The unit content direction at longitude `lon` (0 ahead, −z; positive to the right, +x) and
/// latitude `lat`, degrees.
fn direction(lon: f64, lat: f64) -> DVec3 {
    let (p, t) = (lon.to_radians(), lat.to_radians());
    DVec3::new(t.cos() * p.sin(), t.sin(), -t.cos() * p.cos())
}

/// Least, median and most of `values` weighted by their second element.
fn quantiles(mut values: Vec<(f64, f64)>) -> Option<[f64; 3]> {
    if values.is_empty() {
        return None;
    }
    values.sort_by(|a, b| a.0.total_cmp(&b.0));
    let total: f64 = values.iter().map(|v| v.1).sum();
    let mut run = 0.0;
    let median = values
        .iter()
        .find(|v| {
            run += v.1;
            run >= total / 2.0
        })
        .map_or(values[values.len() / 2].0, |v| v.0);
    Some([values[0].0, median, values[values.len() - 1].0])
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// Checks a grid step, degrees; `field` names it.
pub fn check_step(step: f64, field: &str) -> Result<f64> {
    let [lo, hi] = crate::limits::PLAN_STEP;
    if !(lo..=hi).contains(&step) {
        return Err(Error::invalid(
            field,
            format!("must be {lo} to {hi} degrees, got {step}"),
        ));
    }
    Ok(step)
}

impl Rig {
    /// The rig's plan on a grid of `step` degrees (see [`check_step`]).
    pub fn plan(&self, step: f64) -> Result<Plan> {
        let step = check_step(step, "step")?;
        let grid = self.sample_wall(step);
        let total_area: f64 = grid.samples.iter().flatten().map(|s| s.area).sum();
        let solid_angle: f64 = grid.samples.iter().flatten().map(|s| s.solid_angle).sum();
        if total_area <= 0.0 {
            return Err(Error::invalid(
                "/screen",
                "the eye sees no wall: nothing to plan",
            ));
        }
        let mut lit_by = [0.0; 4];
        for s in grid.samples.iter().flatten() {
            lit_by[s.lit.len().min(3)] += s.area / total_area;
        }
        // The irradiance a single projector typically gives: what brightness is relative to.
        let reference = quantiles(
            grid.samples
                .iter()
                .flatten()
                .flat_map(|s| s.lit.iter().map(|l| (l.irradiance, s.solid_angle)))
                .collect(),
        )
        .map_or(1.0, |q| q[1]);
        let lit = || grid.samples.iter().flatten().filter(|s| !s.lit.is_empty());
        let wall = WallPlan {
            solid_angle,
            area: total_area,
            lit_by,
            pixels_per_degree: quantiles(
                lit()
                    .map(|s| {
                        let finest = s
                            .lit
                            .iter()
                            .map(|l| l.pixels_per_degree)
                            .fold(0.0, f64::max);
                        (finest, s.solid_angle)
                    })
                    .collect(),
            ),
            brightness: quantiles(
                lit()
                    .map(|s| {
                        let sum: f64 = s.lit.iter().map(|l| l.irradiance).sum();
                        (sum / reference, s.solid_angle)
                    })
                    .collect(),
            ),
        };
        let channels =
            self.channels
                .par_iter()
                .enumerate()
                .map(|(k, ch)| {
                    let mine = || {
                        grid.samples.iter().flatten().filter_map(move |s| {
                            s.lit.iter().find(|l| l.channel == k).map(|l| (s, l))
                        })
                    };
                    // About 256 samples across whatever the resolution.
                    let coverage = self.coverage(ch, (ch.width / 256).clamp(1, 8));
                    let pixels = u64::from(ch.width) * u64::from(ch.height);
                    let brightness = quantiles(
                        mine()
                            .map(|(s, l)| (l.irradiance / reference, s.solid_angle))
                            .collect(),
                    );
                    ChannelPlan {
                        id: ch.id.clone(),
                        on_wall: coverage.on_wall,
                        wasted_pixels: ((1.0 - coverage.on_wall) * pixels as f64).round() as u64,
                        wall_share: mine().map(|(s, _)| s.area).sum::<f64>() / total_area,
                        longitude: coverage.longitude,
                        latitude: coverage.latitude,
                        pixels_per_degree: quantiles(
                            mine()
                                .map(|(s, l)| (l.pixels_per_degree, s.solid_angle))
                                .collect(),
                        ),
                        brightness: brightness.map(|[a, _, b]| [a, b]),
                    }
                })
                .collect();
        let overlaps = self.overlaps(&grid, total_area);
        Ok(Plan {
            step,
            wall,
            channels,
            overlaps,
            grid,
            reference,
        })
    }

    /// The wall sampled from the eye, with every projector lighting each sample.
    fn sample_wall(&self, step: f64) -> Grid {
        let (columns, rows) = (
            (360.0 / step).round() as usize,
            (180.0 / step).round() as usize,
        );
        let mut grid = Grid {
            step,
            columns,
            rows,
            samples: Vec::new(),
        };
        let screen = self.doc.screen.prepare();
        let h = step.to_radians();
        // Small enough to be a derivative, large enough to stay clear of rounding.
        let delta = 1e-4;
        let samples: Vec<Vec<Option<Sample>>> = (0..rows)
            .into_par_iter()
            .map(|j| {
                let lat = grid.latitude(j);
                (0..columns)
                    .map(|i| {
                        let lon = grid.longitude(i);
                        let d = self.world_direction(direction(lon, lat));
                        let Hit::Lit { t, point, normal } = screen.intersect(self.eye, d) else {
                            return None;
                        };
                        // The world solid angle of the content cell: equal to the content's
                        // cos(lat)·h² unless the off-axis vector bends it.
                        let solid_angle = if self.offaxis == DVec3::ZERO {
                            lat.to_radians().cos() * h * h
                        } else {
                            let dl = self.world_direction(direction(lon + step / 2.0, lat)) - d;
                            let dt = self.world_direction(direction(lon, lat + step / 2.0)) - d;
                            4.0 * dl.cross(dt).length()
                        };
                        let area = solid_angle * t * t / normal.dot(d).abs().max(1e-6);
                        // Two eye rays a hair away, perpendicular to each other and to d.
                        let e1 = d.any_orthonormal_vector();
                        let e2 = d.cross(e1);
                        let nearby = |e: DVec3| {
                            [delta, -delta].into_iter().find_map(|s| {
                                let p = screen.intersect(self.eye, (d + s * e).normalize());
                                p.point().map(|p| (p, s))
                            })
                        };
                        let (a, b) = (nearby(e1), nearby(e2));
                        let lit = self
                            .channels
                            .iter()
                            .enumerate()
                            .filter_map(|(k, ch)| {
                                let q = self.pixel_lighting(ch, point)?;
                                let pixel = |(p, s): (DVec3, f64)| {
                                    let local = ch.rotation.transpose() * (p - ch.position);
                                    let r = ch.lens.project(local).ok()?;
                                    Some([(r[0] - q[0]) / s, (r[1] - q[1]) / s])
                                };
                                // Pixels per radian along e1 and e2: the Jacobian's columns.
                                let density = match (a.and_then(pixel), b.and_then(pixel)) {
                                    (Some(u), Some(v)) => {
                                        (u[0] * v[1] - u[1] * v[0]).abs().sqrt().to_radians()
                                    }
                                    _ => 0.0,
                                };
                                let to = ch.position - point;
                                let throw = to.length();
                                Some(Lit {
                                    channel: k,
                                    pixels_per_degree: density,
                                    irradiance: normal.dot(to / throw).abs() / (throw * throw),
                                })
                            })
                            .collect();
                        Some(Sample {
                            solid_angle,
                            area,
                            lit,
                        })
                    })
                    .collect()
            })
            .collect();
        grid.samples = samples.into_iter().flatten().collect();
        grid
    }

    fn overlaps(&self, grid: &Grid, total_area: f64) -> Vec<Overlap> {
        struct Acc {
            area: f64,
            sum: DVec3,
            rows: Vec<u32>,
            columns: Vec<u32>,
            middle: Option<f64>,
            lon: [f64; 2],
            lat: [f64; 2],
        }
        let mut pairs: BTreeMap<(usize, usize), Acc> = BTreeMap::new();
        for (n, s) in grid.samples.iter().enumerate() {
            let Some(s) = s else { continue };
            let (i, j) = (n % grid.columns, n / grid.columns);
            for (x, a) in s.lit.iter().enumerate() {
                for b in &s.lit[x + 1..] {
                    let acc = pairs.entry((a.channel, b.channel)).or_insert_with(|| Acc {
                        area: 0.0,
                        sum: DVec3::ZERO,
                        rows: vec![0; grid.rows],
                        columns: vec![0; grid.columns],
                        middle: None,
                        lon: [f64::MAX, f64::MIN],
                        lat: [f64::MAX, f64::MIN],
                    });
                    acc.area += s.area;
                    acc.sum += s.solid_angle * direction(grid.longitude(i), grid.latitude(j));
                    acc.rows[j] += 1;
                    acc.columns[i] += 1;
                    let lon = unwrap_deg(
                        grid.longitude(i),
                        *acc.middle.get_or_insert(grid.longitude(i)),
                    );
                    acc.lon = [acc.lon[0].min(lon), acc.lon[1].max(lon)];
                    let lat = grid.latitude(j);
                    acc.lat = [acc.lat[0].min(lat), acc.lat[1].max(lat)];
                }
            }
        }
        let h = grid.step;
        // Each footprint's middle seen from the eye: its mean content direction.
        let mut sums = vec![DVec3::ZERO; self.channels.len()];
        for (n, s) in grid.samples.iter().enumerate() {
            let Some(s) = s else { continue };
            let d = direction(
                grid.longitude(n % grid.columns),
                grid.latitude(n / grid.columns),
            );
            for l in &s.lit {
                sums[l.channel] += d * s.solid_angle;
            }
        }
        let middles: Vec<DVec3> = sums.iter().map(|v| v.normalize_or(DVec3::NEG_Z)).collect();
        pairs
            .into_iter()
            .map(|((a, b), acc)| {
                let along_rows = median(
                    acc.rows
                        .iter()
                        .enumerate()
                        .filter(|r| *r.1 > 0)
                        .map(|(j, &c)| f64::from(c) * h * grid.latitude(j).to_radians().cos())
                        .collect(),
                );
                let along_columns = median(
                    acc.columns
                        .iter()
                        .filter(|&&c| c > 0)
                        .map(|&c| f64::from(c) * h)
                        .collect(),
                );
                // The blend ramps from one footprint to the other: across longitude when their
                // middles lie side by side, across latitude when one is above the other.
                // Judged at the overlap's own middle, along its line of latitude and its
                // meridian.
                let (lon, lat) = crate::tiles::raster::angles(acc.sum.normalize_or(DVec3::NEG_Z));
                let (lon, lat) = (lon.to_radians(), lat.to_radians());
                let east = DVec3::new(lon.cos(), 0.0, lon.sin());
                let north = DVec3::new(-lat.sin() * lon.sin(), lat.cos(), lat.sin() * lon.cos());
                let chord = middles[b] - middles[a];
                let (width, across) = if chord.dot(east).abs() >= chord.dot(north).abs() {
                    (along_rows, "longitude")
                } else {
                    (along_columns, "latitude")
                };
                let half = h / 2.0;
                // Written with the range's middle in (−180°, 180°], as coverage writes it.
                let turns = ((acc.lon[0] + acc.lon[1]) / 2.0 / 360.0 - 0.5).ceil();
                let acc_lon = acc.lon.map(|v| v - 360.0 * turns);
                Overlap {
                    channels: [self.channels[a].id.clone(), self.channels[b].id.clone()],
                    wall_share: acc.area / total_area,
                    width,
                    across,
                    longitude: [acc_lon[0] - half, acc_lon[1] + half],
                    latitude: [acc.lat[0] - half, acc.lat[1] + half],
                }
            })
            .collect()
    }
}

impl Plan {
    /// The wall at content longitude `lon` and latitude `lat` (degrees), from the grid sample
    /// nearest it; `None` where the eye sees no wall.
    pub fn point(&self, lon: f64, lat: f64) -> Option<PointPlan> {
        let s = self.grid.at(lon, lat)?;
        Some(PointPlan {
            channels: s.lit.iter().map(|l| l.channel).collect(),
            pixels_per_degree: s
                .lit
                .iter()
                .map(|l| l.pixels_per_degree)
                .fold(0.0, f64::max),
            brightness: s.lit.iter().map(|l| l.irradiance).sum::<f64>() / self.reference,
        })
    }
}
