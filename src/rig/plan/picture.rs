//! The plan drawn ([`Plan::picture`]): the wall unrolled, or as a dome master, coloured by pixel
//! density with each footprint outlined, the density scale, and the rig from above and the side.

use super::{Plan, Sample, direction};
use crate::content::testcard::{channel_colour, text_in};
use crate::error::{Error, Result};
use crate::raster::Raster;
use crate::rig::Rig;
use crate::surface::Screen;
use crate::tiles::raster::unwrap_deg;
use glam::DVec3;
use rayon::prelude::*;

/// How the plan's picture lays the wall out.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Layout {
    /// A dome master: the content's zenith at the centre, ahead at the bottom, `reach` degrees
    /// from the zenith at the rim.
    DomeMaster { reach: f64 },
    /// Longitude across and latitude down, at equal degrees a pixel, over the wall's range.
    Unrolled { lon: [f64; 2], lat: [f64; 2] },
}

const BACKGROUND: [u8; 4] = [16, 16, 16, 255];
const UNLIT: [u8; 4] = [70, 70, 70, 255];
const INK: [u8; 4] = [230, 230, 230, 255];
const WALL: [u8; 4] = [120, 120, 120, 255];

/// Density `t` (0–1) as a colour from dark blue through green to yellow, legible on grey.
fn ramp(t: f64) -> [u8; 4] {
    const STOPS: [[f64; 3]; 5] = [
        [48.0, 18.0, 110.0],
        [33.0, 100.0, 160.0],
        [30.0, 160.0, 120.0],
        [140.0, 200.0, 50.0],
        [250.0, 230.0, 40.0],
    ];
    let x = t.clamp(0.0, 1.0) * 4.0;
    let k = (x as usize).min(3);
    let f = x - k as f64;
    let c = |n: usize| (STOPS[k][n] + (STOPS[k + 1][n] - STOPS[k][n]) * f) as u8;
    [c(0), c(1), c(2), 255]
}

impl Plan {
    fn layout(&self, rig: &Rig) -> Layout {
        let g = &self.grid;
        let wall = g
            .samples
            .iter()
            .enumerate()
            .filter(|(_, s)| s.is_some())
            .map(|(n, _)| (g.longitude(n % g.columns), g.latitude(n / g.columns)));
        if matches!(rig.doc.screen, Screen::Dome(_)) {
            let lowest = wall.map(|(_, lat)| lat).fold(90.0, f64::min);
            return Layout::DomeMaster {
                reach: (90.0 - lowest + g.step).min(180.0),
            };
        }
        // Unwrapped around the wall's mean direction, so a wall behind the eye is not cut in two.
        let (mut sx, mut sz, mut lat) = (0.0, 0.0, [f64::MAX, f64::MIN]);
        let points: Vec<(f64, f64)> = wall.collect();
        for &(lo, la) in &points {
            sx += lo.to_radians().sin();
            sz += lo.to_radians().cos();
            lat = [lat[0].min(la), lat[1].max(la)];
        }
        let middle = sx.atan2(sz).to_degrees();
        let mut lon = [f64::MAX, f64::MIN];
        for &(lo, _) in &points {
            let lo = unwrap_deg(lo, middle);
            lon = [lon[0].min(lo), lon[1].max(lo)];
        }
        let half = g.step / 2.0;
        Layout::Unrolled {
            lon: [lon[0] - half, lon[1] + half],
            lat: [lat[0] - half, lat[1] + half],
        }
    }

    /// The plan drawn: the wall unrolled (or as a dome master for a dome) coloured by pixel
    /// density, each footprint outlined in its channel's colour with its id, the density scale,
    /// and beneath it the rig from above and from the side. `width` is the picture's width in
    /// pixels, within [`crate::limits::PLAN_PICTURE_WIDTH`].
    pub fn picture(&self, rig: &Rig, width: usize) -> Result<Raster<[u8; 4]>> {
        let [lo, hi] = crate::limits::PLAN_PICTURE_WIDTH;
        if !(lo..=hi).contains(&width) {
            return Err(Error::invalid(
                "width",
                format!("must be {lo} to {hi} pixels, got {width}"),
            ));
        }
        let layout = self.layout(rig);
        let (map_w, map_h) = match layout {
            Layout::DomeMaster { .. } => (width * 2 / 3, width * 2 / 3),
            Layout::Unrolled { lon, lat } => {
                let h = (width as f64 * (lat[1] - lat[0]) / (lon[1] - lon[0])).round() as usize;
                (width, h.clamp(16, width))
            }
        };
        let (lo, hi) = self
            .wall
            .pixels_per_degree
            .map_or((0.0, 1.0), |[a, _, b]| (a, b.max(a + 1e-9)));
        let sample_of = |x: usize, y: usize| -> Option<&Sample> {
            let (u, v) = (
                (x as f64 + 0.5) / map_w as f64,
                (y as f64 + 0.5) / map_h as f64,
            );
            let (lon, lat) = match layout {
                Layout::DomeMaster { reach } => {
                    let (dx, dy) = (2.0 * u - 1.0, 2.0 * v - 1.0);
                    let r = dx.hypot(dy);
                    if r > 1.0 {
                        return None;
                    }
                    // Ahead (−z) at the bottom, right (+x) to the right.
                    let zenith = (r * reach).to_radians();
                    let (ax, ay) = if r > 0.0 {
                        (dx / r, dy / r)
                    } else {
                        (0.0, 0.0)
                    };
                    let v = DVec3::new(zenith.sin() * ax, zenith.cos(), -zenith.sin() * ay);
                    crate::tiles::raster::angles(v)
                }
                Layout::Unrolled { lon, lat } => (
                    lon[0] + u * (lon[1] - lon[0]),
                    lat[1] - v * (lat[1] - lat[0]),
                ),
            };
            self.grid.at(lon, lat)
        };
        let mask = |s: Option<&Sample>| -> u64 {
            s.map_or(0, |s| {
                s.lit.iter().fold(0, |m, l| m | 1 << (l.channel % 64))
            })
        };
        let masks: Vec<u64> = (0..map_w * map_h)
            .into_par_iter()
            .map(|n| mask(sample_of(n % map_w, n / map_w)))
            .collect();
        let size = (width / 400).max(1);
        // The scale's bar with its ends labelled, and a line of key beneath.
        let scale_h = 40 + 16 * size;
        let views_h = width / 3;
        let mut img = Raster::from_fn(width, map_h + scale_h + views_h, |_, _| BACKGROUND);
        let map_x0 = (width - map_w) / 2;
        for y in 0..map_h {
            for x in 0..map_w {
                let colour = match sample_of(x, y) {
                    None => BACKGROUND,
                    Some(s) if s.lit.is_empty() => UNLIT,
                    Some(s) => {
                        let finest = s
                            .lit
                            .iter()
                            .map(|l| l.pixels_per_degree)
                            .fold(0.0, f64::max);
                        ramp((finest - lo) / (hi - lo))
                    }
                };
                img.data[y * width + map_x0 + x] = colour;
            }
        }
        // Footprint outlines: where a channel lights a pixel and not its right or lower
        // neighbour, or the other way round.
        for y in 0..map_h {
            for x in 0..map_w {
                let m = masks[y * map_w + x];
                let right = if x + 1 < map_w {
                    masks[y * map_w + x + 1]
                } else {
                    0
                };
                let below = if y + 1 < map_h {
                    masks[(y + 1) * map_w + x]
                } else {
                    0
                };
                let edge = (m ^ right) | (m ^ below);
                if edge != 0 {
                    let k = edge.trailing_zeros() as usize;
                    img.data[y * width + map_x0 + x] = channel_colour(k);
                }
            }
        }
        for (k, ch) in rig.channels.iter().enumerate().take(64) {
            let (mut sx, mut sy, mut n) = (0usize, 0usize, 0usize);
            for (i, &m) in masks.iter().enumerate() {
                if m >> k & 1 == 1 {
                    (sx, sy, n) = (sx + i % map_w, sy + i / map_w, n + 1);
                }
            }
            if let (Some(x), Some(y)) = (sx.checked_div(n), sy.checked_div(n)) {
                text_in(&mut img, &ch.id, map_x0 + x, y, size, INK);
            }
        }
        // The density scale.
        let bar = width / 2;
        let (bx, by) = (width / 4, map_h + 8);
        for x in 0..bar {
            let c = ramp(x as f64 / (bar - 1) as f64);
            for y in by..by + 10 {
                img.data[y * width + bx + x] = c;
            }
        }
        let label = format!("{lo:.1} px/deg");
        text_in(
            &mut img,
            &label,
            bx.saturating_sub(label.len() * 4 * size + 8),
            by + 5,
            size,
            INK,
        );
        let label = format!("{hi:.1} px/deg");
        text_in(
            &mut img,
            &label,
            bx + bar + label.len() * 4 * size + 8,
            by + 5,
            size,
            INK,
        );
        let key = "grey: wall that no projector lights";
        text_in(&mut img, key, width / 2, by + 22 + 8 * size, size, INK);
        let top = map_h + scale_h;
        draw_views(&mut img, rig, top, views_h);
        Ok(img)
    }
}

/// The rig from above (x across, ahead up) and from the right (ahead to the right, up up),
/// side by side in the band of `img` from row `top`, `h` tall: the wall as the eye sees it, the
/// eye, each projector and the rays to its image's corners.
fn draw_views(img: &mut Raster<[u8; 4]>, rig: &Rig, top: usize, h: usize) {
    let screen = rig.doc.screen.prepare();
    let mut wall = Vec::new();
    for lon in (-180..180).step_by(5) {
        for lat in (-85..=85).step_by(5) {
            let d = direction(f64::from(lon), f64::from(lat));
            if let Some(p) = screen.intersect(rig.eye, d).point() {
                wall.push(p);
            }
        }
    }
    let mut rays: Vec<(usize, DVec3, DVec3)> = Vec::new();
    for (k, ch) in rig.channels.iter().enumerate() {
        let (w, hh) = (f64::from(ch.width - 1), f64::from(ch.height - 1));
        for q in [
            [0.0, 0.0],
            [w, 0.0],
            [w, hh],
            [0.0, hh],
            [w / 2.0, hh / 2.0],
        ] {
            let end = rig.wall_point(ch, q).or_else(|| {
                let r = ch.lens.unproject(q).ok()?;
                Some(ch.position + ch.rotation * r)
            });
            if let Some(end) = end {
                rays.push((k, ch.position, end));
            }
        }
    }
    type Flatten = fn(DVec3) -> [f64; 2];
    let views: [(&str, Flatten); 2] = [
        ("from above", |p| [p.x, p.z]),
        ("from the right", |p| [-p.z, -p.y]),
    ];
    let panel = img.width / 2;
    for (n, (name, flat)) in views.into_iter().enumerate() {
        let points = wall
            .iter()
            .copied()
            .chain(rays.iter().flat_map(|r| [r.1, r.2]))
            .chain([rig.eye])
            .map(flat);
        let (mut lo, mut hi) = ([f64::MAX; 2], [f64::MIN; 2]);
        for p in points {
            lo = [lo[0].min(p[0]), lo[1].min(p[1])];
            hi = [hi[0].max(p[0]), hi[1].max(p[1])];
        }
        let margin = 12.0 + 8.0 * (img.width / 400).max(1) as f64;
        let span = (hi[0] - lo[0]).max(hi[1] - lo[1]).max(1e-6);
        let scale = ((panel as f64 - 2.0 * margin).min(h as f64 - 2.0 * margin)) / span;
        let x0 = n as f64 * panel as f64 + (panel as f64 - scale * (hi[0] - lo[0])) / 2.0;
        let y0 = top as f64 + (h as f64 - scale * (hi[1] - lo[1])) / 2.0;
        let at = |p: DVec3| {
            let f = flat(p);
            [x0 + (f[0] - lo[0]) * scale, y0 + (f[1] - lo[1]) * scale]
        };
        for &p in &wall {
            dot(img, at(p), 1, WALL);
        }
        for &(k, from, to) in &rays {
            line(img, at(from), at(to), channel_colour(k));
        }
        for (k, ch) in rig.channels.iter().enumerate() {
            dot(img, at(ch.position), 2, channel_colour(k));
        }
        dot(img, at(rig.eye), 3, INK);
        let size = (img.width / 400).max(1);
        text_in(img, name, n * panel + panel / 2, top + 4 * size, size, INK);
    }
}

fn put(img: &mut Raster<[u8; 4]>, x: f64, y: f64, c: [u8; 4]) {
    if x >= 0.0 && y >= 0.0 && (x as usize) < img.width && (y as usize) < img.height {
        let w = img.width;
        img.data[y as usize * w + x as usize] = c;
    }
}

fn dot(img: &mut Raster<[u8; 4]>, p: [f64; 2], r: i32, c: [u8; 4]) {
    for dy in -r..=r {
        for dx in -r..=r {
            put(img, p[0] + f64::from(dx), p[1] + f64::from(dy), c);
        }
    }
}

fn line(img: &mut Raster<[u8; 4]>, a: [f64; 2], b: [f64; 2], c: [u8; 4]) {
    let n = (b[0] - a[0]).abs().max((b[1] - a[1]).abs()).ceil().min(1e5) as usize;
    for k in 0..=n {
        let t = k as f64 / n.max(1) as f64;
        put(img, a[0] + (b[0] - a[0]) * t, a[1] + (b[1] - a[1]) * t, c);
    }
}
