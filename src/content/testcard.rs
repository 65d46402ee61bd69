//! Test cards a technician aligns projectors by. All but one are drawn in the projector's own
//! pixels, unwarped, because they answer questions about the projector itself: where its raster
//! ends (`edges`), whether it is square to the wall (`grid`), which channel a beam is (`ids`),
//! whether its colours and black level match its neighbours (`bars`). `crosshatch` is the
//! exception: lines of constant content azimuth and elevation every 10°, drawn through the
//! channel's warp, so that where two projectors overlap their lines coincide exactly when the
//! warps agree — the check an alignment ends with. `black` and `white` are flat fields put out
//! as content is, through the channel's blend and black lift: whether a dark frame is evenly
//! dark across the overlaps and a white one evenly bright (docs/photometry.md).

use crate::error::{Error, Result};
use crate::normalmap::NormalMap;
use crate::raster::Raster;

/// One of the test cards (see the module's description).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Card {
    /// Lines every 1/32 of the longer side, in projector pixels: whether it is square to the wall.
    Grid,
    /// Lines of constant content azimuth and elevation every 10°, through the channel's warp:
    /// whether overlapping projectors' warps agree.
    Crosshatch,
    /// Colour bars over a grey ramp, in projector pixels: whether colours and black level match
    /// the neighbours'.
    Bars,
    /// The channel's number and id on its own colour: which channel a beam is.
    Ids,
    /// The raster's border, coloured corners and an arrow pointing up: where the raster ends and
    /// which way up it is.
    Edges,
    /// Black, blended and lifted as content is: whether the overlaps vanish in the dark.
    Black,
    /// White, blended as content is: whether the blend is even where projectors overlap.
    White,
}

impl Card {
    /// Every card's name, as [`Card::parse`] takes it (the `show` field of a channel's show
    /// request, besides `content`).
    pub const NAMES: [&'static str; 7] = [
        "grid",
        "crosshatch",
        "bars",
        "ids",
        "edges",
        "black",
        "white",
    ];

    /// The card's name, one of [`Card::NAMES`].
    pub fn name(self) -> &'static str {
        match self {
            Card::Grid => "grid",
            Card::Crosshatch => "crosshatch",
            Card::Bars => "bars",
            Card::Ids => "ids",
            Card::Edges => "edges",
            Card::Black => "black",
            Card::White => "white",
        }
    }

    /// Whether the card is put out as content is, through the channel's blend and black lift
    /// ([`draw`] draws it flat; the caller applies them).
    pub fn blended(self) -> bool {
        matches!(self, Card::Black | Card::White)
    }

    /// The card of that name; an error listing [`Card::NAMES`] otherwise.
    pub fn parse(name: &str) -> Result<Card> {
        Ok(match name {
            "grid" => Card::Grid,
            "crosshatch" => Card::Crosshatch,
            "bars" => Card::Bars,
            "ids" => Card::Ids,
            "edges" => Card::Edges,
            "black" => Card::Black,
            "white" => Card::White,
            other => {
                return Err(Error::invalid(
                    "pattern",
                    format!("must be one of {}, got `{other}`", Card::NAMES.join(", ")),
                ));
            }
        })
    }
}

/// Which channel a card is drawn for: `ids` writes both, and colours the card by the index.
pub struct Label<'a> {
    /// The channel's position in the rig, from 0 (`ids` shows it plus one and colours by it).
    pub index: usize,
    /// The channel's id, as the rig names it.
    pub id: &'a str,
}

/// Spacing of the crosshatch's lines, degrees of content azimuth and elevation.
pub const CROSSHATCH_STEP: f64 = 10.0;

const BLACK: [u8; 4] = [0, 0, 0, 255];
const WHITE: [u8; 4] = [255, 255, 255, 255];

/// `card` at the size of `map` (the channel's warp, at the size the card is wanted).
pub fn draw(card: Card, map: &NormalMap, label: &Label) -> Raster<[u8; 4]> {
    let (w, h) = (map.width(), map.height());
    match card {
        Card::Grid => grid(w, h),
        Card::Crosshatch => crosshatch(map),
        Card::Bars => bars(w, h),
        Card::Ids => ids(w, h, label),
        Card::Edges => edges(w, h),
        Card::Black => Raster::from_fn(w, h, |_, _| BLACK),
        Card::White => Raster::from_fn(w, h, |_, _| WHITE),
    }
}

/// Lines every 1/32 of the longer side from the centre out, the centre lines three pixels wide,
/// and the outermost rows and columns lit.
fn grid(w: usize, h: usize) -> Raster<[u8; 4]> {
    let step = (w.max(h) / 32).max(4);
    let on = |p: usize, n: usize| {
        let c = n / 2;
        p.abs_diff(c).is_multiple_of(step) || p == 0 || p + 1 == n || p.abs_diff(c) <= 1
    };
    Raster::from_fn(
        w,
        h,
        |x, y| if on(x, w) || on(y, h) { WHITE } else { BLACK },
    )
}

/// Content azimuth and elevation (degrees) of a sampling vector: N = (cos θ·sin φ, sin θ,
/// −cos θ·cos φ), as the content conventions have it.
fn angles(v: glam::DVec3) -> [f64; 2] {
    [
        v.x.atan2(-v.z).to_degrees(),
        v.y.clamp(-1.0, 1.0).asin().to_degrees(),
    ]
}

/// Lines of constant azimuth and elevation: a pixel is on one when its distance to the nearest
/// multiple of the step, divided by how fast the angle changes across the pixel, is under 0.75
/// pixel — so lines are as thin where the warp stretches as where it squeezes. The equator and
/// the azimuth-0 meridian are coloured, so the content's centre can be found.
fn crosshatch(map: &NormalMap) -> Raster<[u8; 4]> {
    let (w, h) = (map.width(), map.height());
    let at: Vec<Option<[f64; 2]>> = (0..w * h)
        .map(|k| map.direction(k % w, k / w).map(angles))
        .collect();
    let wrap = |d: f64| (d + 180.0).rem_euclid(360.0) - 180.0;
    Raster::from_fn(w, h, |x, y| {
        let Some(a) = at[y * w + x] else {
            return BLACK;
        };
        // The angles' change per pixel, from whichever neighbours are mapped.
        let mut rate = [0.0f64; 2];
        for (dx, dy) in [(1i64, 0i64), (-1, 0), (0, 1), (0, -1)] {
            let (nx, ny) = (x as i64 + dx, y as i64 + dy);
            if nx < 0 || ny < 0 || nx >= w as i64 || ny >= h as i64 {
                continue;
            }
            if let Some(b) = at[ny as usize * w + nx as usize] {
                for k in 0..2 {
                    rate[k] = rate[k].max(wrap(b[k] - a[k]).abs());
                }
            }
        }
        let mut colour = BLACK;
        for (k, tint) in [(0, [0, 255, 255, 255]), (1, [255, 255, 0, 255])] {
            let off = wrap(a[k] - (a[k] / CROSSHATCH_STEP).round() * CROSSHATCH_STEP);
            if rate[k] > 0.0 && off.abs() / rate[k] < 0.75 {
                colour = if a[k].abs() < CROSSHATCH_STEP / 2.0 {
                    tint
                } else {
                    WHITE
                };
            }
        }
        colour
    })
}

/// Seven 75 % colour bars over the top two thirds; below them a grey ramp from black to white,
/// which shows a blend's or a gamma's mismatch between neighbours as a step.
fn bars(w: usize, h: usize) -> Raster<[u8; 4]> {
    const BARS: [[u8; 3]; 7] = [
        [191, 191, 191],
        [191, 191, 0],
        [0, 191, 191],
        [0, 191, 0],
        [191, 0, 191],
        [191, 0, 0],
        [0, 0, 191],
    ];
    Raster::from_fn(w, h, |x, y| {
        if 3 * y < 2 * h {
            let [r, g, b] = BARS[(x * 7 / w).min(6)];
            [r, g, b, 255]
        } else {
            let v = if w > 1 { (x * 255 / (w - 1)) as u8 } else { 0 };
            [v, v, v, 255]
        }
    })
}

/// A colour per channel, far apart for neighbouring indices (hues by the golden ratio).
pub fn channel_colour(index: usize) -> [u8; 4] {
    let hue = (index as f64 * 0.618_033_988_75).fract() * 6.0;
    let x = 1.0 - (hue % 2.0 - 1.0).abs();
    let (r, g, b) = match hue as usize {
        0 => (1.0, x, 0.0),
        1 => (x, 1.0, 0.0),
        2 => (0.0, 1.0, x),
        3 => (0.0, x, 1.0),
        4 => (x, 0.0, 1.0),
        _ => (1.0, 0.0, x),
    };
    let c = |v: f64| (40.0 + 160.0 * v) as u8;
    [c(r), c(g), c(b), 255]
}

/// The channel's number (1-based) large in the middle and its id beneath, white on the
/// channel's colour, with a white border.
fn ids(w: usize, h: usize, label: &Label) -> Raster<[u8; 4]> {
    let mut img = Raster::from_fn(w, h, |x, y| {
        if x == 0 || y == 0 || x + 1 == w || y + 1 == h {
            WHITE
        } else {
            channel_colour(label.index)
        }
    });
    let number = (label.index + 1).to_string();
    // Font pixels as large as a share of the height allows, and the line still fits across.
    let size = |height: usize, chars: usize| (height / 8).min(w / (8 * chars + 8)).max(1);
    text(
        &mut img,
        &number,
        w / 2,
        h * 2 / 5,
        size(h / 3, number.len()),
    );
    let small = size(h / 12, label.id.len().max(1));
    text(&mut img, label.id, w / 2, h * 3 / 4, small);
    img
}

fn text(img: &mut Raster<[u8; 4]>, s: &str, cx: usize, cy: usize, size: usize) {
    text_in(img, s, cx, cy, size, WHITE);
}

/// Writes `s` centred on (cx, cy) in `colour` in the 8×8 font, each font pixel `size` pixels
/// wide; letters outside the font's ASCII range are drawn as '?'.
pub(crate) fn text_in(
    img: &mut Raster<[u8; 4]>,
    s: &str,
    cx: usize,
    cy: usize,
    size: usize,
    colour: [u8; 4],
) {
    let n = s.chars().count();
    let x0 = cx as i64 - (n * 8 * size) as i64 / 2;
    let y0 = cy as i64 - (4 * size) as i64;
    for (k, ch) in s.chars().enumerate() {
        let code = if ch.is_ascii() {
            ch as usize
        } else {
            '?' as usize
        };
        let glyph = font8x8::legacy::BASIC_LEGACY[code];
        for (row, bits) in glyph.iter().enumerate() {
            for col in 0..8 {
                if bits >> col & 1 == 0 {
                    continue;
                }
                for dy in 0..size {
                    for dx in 0..size {
                        let x = x0 + ((k * 8 + col) * size + dx) as i64;
                        let y = y0 + (row * size + dy) as i64;
                        if x >= 0 && y >= 0 && (x as usize) < img.width && (y as usize) < img.height
                        {
                            let w = img.width;
                            img.data[y as usize * w + x as usize] = colour;
                        }
                    }
                }
            }
        }
    }
}

/// The raster's outermost pixels lit, a triangle in each corner (top-left red, top-right green,
/// bottom-right blue, bottom-left yellow), an arrow at the top pointing up and a cross at the
/// centre: which way up, which way round and whether anything is cut off.
fn edges(w: usize, h: usize) -> Raster<[u8; 4]> {
    let size = (w.min(h) / 8).max(2);
    let (cx, cy) = (w / 2, h / 2);
    Raster::from_fn(w, h, |x, y| {
        if x == 0 || y == 0 || x + 1 == w || y + 1 == h {
            return WHITE;
        }
        let (rx, by) = (w - 1 - x, h - 1 - y);
        if x + y < size {
            return [255, 0, 0, 255];
        }
        if rx + y < size {
            return [0, 255, 0, 255];
        }
        if rx + by < size {
            return [0, 0, 255, 255];
        }
        if x + by < size {
            return [255, 255, 0, 255];
        }
        // The arrow: a triangle whose tip touches the top edge's middle.
        if y < size && 2 * x.abs_diff(cx) <= y {
            return WHITE;
        }
        if (x.abs_diff(cx) <= 1 && y.abs_diff(cy) < size)
            || (y.abs_diff(cy) <= 1 && x.abs_diff(cx) < size)
        {
            return WHITE;
        }
        BLACK
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::projection::view::View;
    use crate::projection::{Params, build};

    fn flat(w: u32, h: u32) -> NormalMap {
        let params = Params {
            hfov: Some(90.0),
            vfov: Some(60.0),
            ..Params::default()
        };
        let aspect = f64::from(h) / f64::from(w);
        let v = View::plain(build("flat", &params, aspect).unwrap());
        NormalMap::from_view(&v, w, h).unwrap()
    }

    #[test]
    fn every_name_parses_and_unknown_ones_are_refused() {
        for n in Card::NAMES {
            assert_eq!(Card::parse(n).unwrap().name(), n);
        }
        let e = Card::parse("smpte").unwrap_err();
        assert!(
            matches!(e, Error::Invalid { ref name, .. } if name == "pattern"),
            "{e}"
        );
    }

    #[test]
    fn crosshatch_lines_fall_on_multiples_of_the_step() {
        // A 90°-wide flat view 901 pixels across: the centre column looks along azimuth 0, so
        // it is on the coloured meridian, and a column whose azimuth is 5° is on no line.
        let map = flat(901, 301);
        let img = draw(Card::Crosshatch, &map, &Label { index: 0, id: "c" });
        let (cy, cx) = (150, 450);
        assert_eq!(img.get(cx, cy - 40), [0, 255, 255, 255]);
        let x5 = (450.0 + 450.0 * 5f64.to_radians().tan()).round() as usize;
        assert_eq!(img.get(x5, cy - 40), BLACK);
        let x10 = (450.0 + 450.0 * 10f64.to_radians().tan()).round() as usize;
        assert_eq!(img.get(x10, cy - 40), WHITE);
    }

    #[test]
    fn edges_mark_each_corner_in_its_own_colour() {
        let img = edges(64, 48);
        assert_eq!(img.get(0, 0), WHITE);
        assert_eq!(img.get(2, 2), [255, 0, 0, 255]);
        assert_eq!(img.get(61, 2), [0, 255, 0, 255]);
        assert_eq!(img.get(61, 45), [0, 0, 255, 255]);
        assert_eq!(img.get(2, 45), [255, 255, 0, 255]);
    }

    #[test]
    fn ids_write_the_channel_number() {
        let img = ids(
            160,
            90,
            &Label {
                index: 2,
                id: "right",
            },
        );
        let lit = img.data.iter().filter(|p| **p == WHITE).count();
        // The border alone is 496 pixels; the digit "3" and the id add more.
        assert!(lit > 496 + 100, "{lit}");
        assert_ne!(channel_colour(0), channel_colour(1));
        // The console draws channels in these colours too (console/tiles.js, its unit test).
        assert_eq!(channel_colour(0), [200, 40, 40, 255]);
    }

    #[test]
    fn grid_and_bars_fill_the_raster() {
        let g = grid(320, 180);
        assert_eq!(g.get(160, 37), WHITE);
        assert_eq!(g.get(165, 37), BLACK);
        let b = bars(70, 30);
        assert_eq!(b.get(5, 5), [191, 191, 191, 255]);
        assert_eq!(b.get(65, 5), [0, 0, 191, 255]);
        assert_eq!(b.get(69, 29), WHITE);
    }
}
