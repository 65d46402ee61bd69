//! The sample plan: one [`Tap`] per output sample, and the filters that read content through it.

use super::lattice::{self, Sampler};
use super::{Filter, Warp, finish};
use crate::content::{Atlas, Locate};
use crate::error::{Error, Result};
use crate::raster::{Pixel, Raster, Tap, pages, split};
use rayon::prelude::*;
use std::mem::MaybeUninit;
use std::ops::Range;

/// Rows per parallel task, and columns per strip within it (see `Plan::draw`). The bilinear
/// loop takes taller bands than the 8 rows it had, which with its prefetch of the next strip's
/// first row measured 3–4 % faster at 4K (six paired runs of six) and no slower at 1080p;
/// neither alone helped. The other filters draw bands as tall.
const BILINEAR_BAND_ROWS: usize = 16;
const STRIP_COLS: usize = 128;

/// How a plan lays out its taps in memory.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Order {
    /// Row after row, a pixel's k × k samples together.
    Rows,
    /// The bilinear loop's own order: bands of [`BILINEAR_BAND_ROWS`] rows, each band strip
    /// after strip of [`STRIP_COLS`] columns, each strip row after row. The loop then reads
    /// its taps as one stream, which the processor's prefetcher follows; row-major taps, read
    /// strip by strip, were sixteen short streams at once, and the 4K frame 14–29 % longer
    /// (six paired runs).
    Strips,
}

impl Order {
    fn of(filter: Filter, supersample: u32) -> Order {
        if filter == Filter::Bilinear && supersample == 1 {
            Order::Strips
        } else {
            Order::Rows
        }
    }

    /// Rows laid out together: the unit a plan is filled and rebuilt in.
    fn unit_rows(self) -> usize {
        match self {
            Order::Rows => 1,
            Order::Strips => BILINEAR_BAND_ROWS,
        }
    }
}

/// Where the tap of column `x`, row `r` of a band `rows` rows tall and `w` columns wide lies
/// in that band's taps in [`Order::Strips`].
#[inline]
fn strip_index(x: usize, r: usize, rows: usize, w: usize) -> usize {
    let x0 = x - x % STRIP_COLS;
    x0 * rows + r * STRIP_COLS.min(w - x0) + (x - x0)
}

/// A warp resolved against one content layout: what every output sample reads.
#[derive(Debug)]
pub struct Plan {
    width: usize,
    height: usize,
    supersample: u32,
    filter: Filter,
    atlas_width: usize,
    atlas_height: usize,
    order: Order,
    taps: Vec<Tap>,
}

/// A preview after a tile edit clones its plan to redo some rows: into pages mapped first, the
/// copy does not trap into the kernel every 4 KiB. Over the ~60 clones of a 1080p plan in an
/// `omniwarp bench serve` (three runs each way) the medians were alike, about 2 ms, but the
/// slowest tenth took 5–8 ms where it had taken 9–23.
impl Clone for Plan {
    fn clone(&self) -> Self {
        let mut taps = pages::mapped(self.taps.len(), Tap::NONE);
        taps.extend_from_slice(&self.taps);
        Plan { taps, ..*self }
    }
}

impl Plan {
    /// Resolves `warp` for a width × height output with k × k supersampling against content
    /// laid out in `atlas`. Positions are interpolated where that is provably within
    /// [`super::lattice::BOUND`] of the exact ones (coverage and nearest texels unchanged); see
    /// [`Plan::exact`] for every sample computed exactly.
    pub fn new<T: Pixel>(
        warp: Warp<'_>,
        content: &impl Locate,
        atlas: &Atlas<T>,
        width: u32,
        height: u32,
        supersample: u32,
        filter: Filter,
    ) -> Result<Plan> {
        Self::build(
            warp,
            content,
            atlas,
            [width, height, supersample],
            filter,
            true,
            Order::of(filter, supersample),
        )
    }

    /// As [`Plan::new`] with the position of every sample computed exactly: the reference the
    /// interpolated plan is measured against, and several times slower to build.
    pub fn exact<T: Pixel>(
        warp: Warp<'_>,
        content: &impl Locate,
        atlas: &Atlas<T>,
        width: u32,
        height: u32,
        supersample: u32,
        filter: Filter,
    ) -> Result<Plan> {
        Self::build(
            warp,
            content,
            atlas,
            [width, height, supersample],
            filter,
            false,
            Order::of(filter, supersample),
        )
    }

    fn build<T: Pixel>(
        warp: Warp<'_>,
        content: &impl Locate,
        atlas: &Atlas<T>,
        [width, height, supersample]: [u32; 3],
        filter: Filter,
        lattice: bool,
        order: Order,
    ) -> Result<Plan> {
        warp.check(width, height, supersample)?;
        let (w, h) = (width as usize, height as usize);
        let per_row = w * (supersample * supersample) as usize;
        let mut plan = Plan {
            width: w,
            height: h,
            supersample,
            filter,
            atlas_width: atlas.width,
            atlas_height: atlas.height,
            order,
            taps: Vec::new(),
        };
        let mut taps = pages::mapped(per_row * h, Tap::NONE);
        plan.fill(
            warp,
            content,
            lattice,
            0..h,
            &mut taps.spare_capacity_mut()[..per_row * h],
        );
        // SAFETY: `fill` writes every element of the rows it is given, here all of them.
        unsafe { taps.set_len(per_row * h) };
        plan.taps = taps;
        Ok(plan)
    }

    /// Rebuilds the plan's rows after its warp changed in rows `changed` (an edit of part of a
    /// normal map): those rows and the ones whose interpolation reads them, with the result a
    /// plan of the new warp built from scratch would have, bit for bit. Returns the rows
    /// rebuilt.
    pub fn redo<T: Pixel>(
        &mut self,
        warp: Warp<'_>,
        content: &impl Locate,
        atlas: &Atlas<T>,
        changed: Range<usize>,
    ) -> Result<Range<usize>> {
        let (width, height) = (self.width as u32, self.height as u32);
        warp.check(width, height, self.supersample)?;
        if (atlas.width, atlas.height) != (self.atlas_width, self.atlas_height) {
            return Err(Error::invalid(
                "content",
                "the plan was built for another atlas",
            ));
        }
        let k = self.supersample as usize;
        let changed = changed.start.min(self.height)..changed.end.min(self.height);
        let samples = lattice::dependents(self.height * k, changed.start * k..changed.end * k);
        let rows = samples.start / k..samples.end.div_ceil(k);
        let per_row = self.width * k * k;
        // The whole units (rows, or bands of strips) that hold those rows; `fill` rewrites
        // only the rows asked for within them.
        let unit = self.order.unit_rows();
        let held = rows.start / unit * unit..(rows.end.div_ceil(unit) * unit).min(self.height);
        let mut taps = std::mem::take(&mut self.taps);
        // `fill` writes through MaybeUninit; these are initialised taps, those of the rows
        // rebuilt overwritten whole and the others left as they are.
        let slots: &mut [MaybeUninit<Tap>] = {
            let r = &mut taps[held.start * per_row..held.end * per_row];
            // SAFETY: Tap is Copy (no drop glue), and MaybeUninit<Tap> has Tap's layout;
            // slots only ever receive whole taps, so the slice read as taps again is valid.
            unsafe { std::slice::from_raw_parts_mut(r.as_mut_ptr().cast(), r.len()) }
        };
        self.fill(warp, content, true, rows.clone(), slots);
        self.taps = taps;
        Ok(rows)
    }

    /// Writes every tap of the pixel rows `rows` into `out`, the taps of the whole units of
    /// the plan's order that hold those rows (from the unit of `rows.start` on). Other rows'
    /// slots in `out` are left alone.
    fn fill(
        &self,
        warp: Warp<'_>,
        content: &impl Locate,
        lattice: bool,
        rows: Range<usize>,
        out: &mut [MaybeUninit<Tap>],
    ) {
        let (aw, ah) = (self.atlas_width as i64, self.atlas_height as i64);
        let nearest = self.filter == Filter::Nearest;
        let k = self.supersample as usize;
        let per_row = self.width * k * k;
        let dims = [self.width as u32, self.height as u32, self.supersample];
        let window = rows.start * k..rows.end * k;
        let sampler = Sampler::new(warp, content, dims, nearest, lattice, window);
        let (aw_f, ah_f) = (aw as f64, ah as f64);
        let tap = |(ax, ay): (f64, f64)| {
            // Far outside (or NaN): nothing to split.
            if !(ax >= 0.0 && ay >= 0.0 && ax < aw_f && ay < ah_f) {
                return Tap::NONE;
            }
            let (xi, fx) = split(ax);
            let (yi, fy) = split(ay);
            // The atlas border keeps every tap of a covered sample inside; checking here,
            // once, lets the frame loop index without fear.
            if !(xi >= 1 && yi >= 1 && xi + 2 < aw && yi + 2 < ah) {
                return Tap::NONE;
            }
            if nearest {
                // The texel is chosen now, once, not every frame.
                let dx = i64::from(fx >= 32768);
                let dy = i64::from(fy >= 32768);
                Tap {
                    idx: ((yi + dy) * aw + xi + dx) as u32,
                    fx: 0,
                    fy: 0,
                }
            } else {
                Tap {
                    idx: (yi * aw + xi) as u32,
                    fx,
                    fy,
                }
            }
        };
        if self.order == Order::Strips {
            let w = self.width;
            let first_band = rows.start / BILINEAR_BAND_ROWS;
            out.par_chunks_mut(w * BILINEAR_BAND_ROWS)
                .enumerate()
                .for_each(|(b, band)| {
                    let y0 = (first_band + b) * BILINEAR_BAND_ROWS;
                    let height = band.len() / w;
                    for r in (0..height).filter(|r| rows.contains(&(y0 + r))) {
                        let mut x = 0;
                        sampler.row(y0 + r, |p| {
                            band[strip_index(x, r, height, w)].write(p.map_or(Tap::NONE, tap));
                            x += 1;
                        });
                    }
                });
            return;
        }
        out.par_chunks_mut(per_row)
            .enumerate()
            .for_each(|(r, row)| {
                // A pixel's k × k taps are contiguous, row by row; sample rows come in turn.
                for b in 0..k {
                    let (mut n, mut a) = (b * k, 0);
                    sampler.row((rows.start + r) * k + b, |p| {
                        row[n].write(p.map_or(Tap::NONE, tap));
                        a += 1;
                        if a == k {
                            a = 0;
                            n += k * k - k + 1;
                        } else {
                            n += 1;
                        }
                    });
                }
            });
    }

    /// Output width in pixels.
    pub fn width(&self) -> usize {
        self.width
    }

    /// Output height in pixels.
    pub fn height(&self) -> usize {
        self.height
    }

    /// Every tap, in the order the frame loop reads them: row after row (a pixel's k × k
    /// samples together), or for bilinear filtering without supersampling bands of column
    /// strips. For counting, or comparing plans of one filter and size; [`Plan::pixel`]
    /// finds a pixel's.
    pub fn taps(&self) -> &[Tap] {
        &self.taps
    }

    /// The k × k taps of the pixel at column `x`, row `y`, row by row.
    pub fn pixel(&self, x: usize, y: usize) -> &[Tap] {
        assert!(
            x < self.width && y < self.height,
            "pixel ({x}, {y}) is outside the plan"
        );
        let kk = (self.supersample * self.supersample) as usize;
        let i = match self.order {
            Order::Rows => (y * self.width + x) * kk,
            Order::Strips => {
                let band = y - y % BILINEAR_BAND_ROWS;
                let rows = BILINEAR_BAND_ROWS.min(self.height - band);
                band * self.width + strip_index(x, y - band, rows, self.width)
            }
        };
        &self.taps[i..i + kk]
    }

    /// Filters one frame of content through the plan.
    pub fn render<T: Pixel>(&self, atlas: &Atlas<T>) -> Result<Raster<T>> {
        let mut out = Raster::new(self.width, self.height);
        self.render_into(atlas, &mut out)?;
        Ok(out)
    }

    /// As [`Plan::render`], into an existing image of the plan's size (no allocation, for
    /// frame loops).
    pub fn render_into<T: Pixel>(&self, atlas: &Atlas<T>, out: &mut Raster<T>) -> Result<()> {
        let bands = self.height.div_ceil(Self::BAND);
        self.render_bands(atlas, out, vec![(); bands], |_, _, ()| {})
    }

    /// Rows of the bands [`Plan::render_bands`] draws (the last may be shorter): even, so that
    /// a band's 4:2:0 chroma rows are its own.
    pub const BAND: usize = BILINEAR_BAND_ROWS;

    /// As [`Plan::render_into`], handing each band of [`Plan::BAND`] rows to `then` as soon as
    /// it is drawn, with its first row and the caller's own piece for it (`pieces`, one per
    /// band, top to bottom): what follows the warp in a frame loop (a blend, packing for an
    /// encoder) then reads the band while it is still in the cache, not the whole frame back
    /// from memory.
    pub fn render_bands<T: Pixel, P: Send>(
        &self,
        atlas: &Atlas<T>,
        out: &mut Raster<T>,
        pieces: Vec<P>,
        then: impl Fn(usize, &mut [T], P) + Sync,
    ) -> Result<()> {
        if (atlas.width, atlas.height) != (self.atlas_width, self.atlas_height) {
            return Err(Error::invalid(
                "content",
                format!(
                    "the plan was built for a {}×{} atlas, this content's is {}×{}",
                    self.atlas_width, self.atlas_height, atlas.width, atlas.height
                ),
            ));
        }
        if (out.width, out.height) != (self.width, self.height) {
            return Err(Error::invalid(
                "size",
                "output image and plan differ in size",
            ));
        }
        let w = self.width;
        let rows = Self::BAND;
        assert_eq!(
            pieces.len(),
            self.height.div_ceil(rows),
            "one piece per band"
        );
        let kk = (self.supersample * self.supersample) as usize;
        out.data
            .par_chunks_mut(w * rows)
            .zip(self.taps.par_chunks(w * rows * kk))
            .zip(pieces)
            .enumerate()
            .for_each(|(k, ((band, taps), piece))| {
                self.draw(atlas, band, taps);
                then(k * rows, band, piece);
            });
        Ok(())
    }

    /// Draws one band of whole rows from its taps.
    fn draw<T: Pixel>(&self, atlas: &Atlas<T>, band: &mut [T], taps: &[Tap]) {
        let w = self.width;
        let kk = (self.supersample * self.supersample) as usize;
        let aw = atlas.width;
        let data = &atlas.data[..];
        if self.order == Order::Strips {
            // A band's rows walked in short column strips: neighbouring output rows read
            // neighbouring texels, so a strip's texels are still in L1 when the next row needs
            // them, whichever way the warp runs through the texture. The taps are stored in
            // this order (`Order::Strips`), so they stream in; a strip's rows, and the strips,
            // follow each other.
            let rows = band.len() / w;
            for x0 in (0..w).step_by(STRIP_COLS) {
                let cols = STRIP_COLS.min(w - x0);
                let strip = &taps[x0 * rows..(x0 + cols) * rows];
                for r in 0..rows {
                    let row = &strip[r * cols..(r + 1) * cols];
                    // The row filtered after the next one (the taps that follow, in this
                    // strip or the next): its texels are fetched while two rows are filtered.
                    // One row ahead was enough for the slower four-pixel kernel; with the
                    // eight-pixel one, two rows ahead took 3–9 % less time at 4K (five paired
                    // runs), and three or more were no better.
                    // Every other tap is enough (a cache line holds 16 texels) and halves the
                    // cost.
                    let at = (x0 * rows + (r + 2) * cols).min(taps.len());
                    let next = &taps[at..(at + STRIP_COLS).min(taps.len())];
                    for t in next.iter().step_by(2) {
                        prefetch(data, t.idx as usize, aw);
                    }
                    let span = r * w + x0..r * w + x0 + cols;
                    T::bilinear_span(data, aw, row, &mut band[span]);
                }
            }
            return;
        }
        if self.filter == Filter::Nearest && kk == 1 {
            // One texel per pixel, chosen when the plan was built, copied as it is: no
            // conversion to float and back (the general path below gives the same bits, about
            // ten times slower). A tap that covers nothing (u32::MAX) lies past the atlas: the
            // default.
            for (o, t) in band.iter_mut().zip(taps) {
                *o = data.get(t.idx as usize).copied().unwrap_or_default();
            }
            return;
        }
        if self.filter == Filter::Bicubic && kk == 1 {
            // The pixel type's own lookup: fixed point for 8-bit content.
            T::bicubic_span(data, aw, taps, band);
            return;
        }
        let filter = self.filter;
        for (o, samples) in band.iter_mut().zip(taps.chunks_exact(kk)) {
            let mut acc = [0.0f32; 4];
            let mut hits = 0;
            for t in samples.iter().filter(|t| t.idx != u32::MAX) {
                let v = sample(data, aw, *t, filter);
                for (a, c) in acc.iter_mut().zip(v) {
                    *a += c;
                }
                hits += 1;
            }
            *o = finish(acc, hits, kk as u32);
        }
    }
}

/// Asks the processor to start loading the 2×2 block at `i` into the cache.
#[inline(always)]
fn prefetch<T>(data: &[T], i: usize, stride: usize) {
    #[cfg(target_arch = "x86_64")]
    {
        use std::arch::x86_64::{_MM_HINT_T0, _mm_prefetch};
        let p = data.as_ptr().wrapping_add(i);
        // SAFETY: a prefetch is a hint that never faults, whatever the address (taps that
        // cover nothing hold u32::MAX); wrapping_add keeps the pointer arithmetic defined.
        unsafe {
            _mm_prefetch::<_MM_HINT_T0>(p.cast());
            _mm_prefetch::<_MM_HINT_T0>(p.wrapping_add(stride).cast());
        }
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = (data, i, stride);
}

/// One filtered sample, in the pixel type's own scale.
#[inline]
fn sample<T: Pixel>(data: &[T], aw: usize, t: Tap, filter: Filter) -> [f32; 4] {
    let i = t.idx as usize;
    match filter {
        // The plan chose the texel when it was built.
        Filter::Nearest => data[i].to_f32(),
        Filter::Bilinear => T::bilinear(
            data[i],
            data[i + 1],
            data[i + aw],
            data[i + aw + 1],
            t.fx,
            t.fy,
        )
        .to_f32(),
        Filter::Bicubic => crate::raster::cubic::bicubic_f32(data, aw, t),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::content::Content;
    use crate::cubemap::CubeMap;
    use crate::projection::{self, Params, View};

    /// A bilinear plan in the frame loop's strip order holds, pixel for pixel, the taps of the
    /// same plan in row order, and its loop draws the same bits as the general path reading
    /// the rows: at sizes whose last strip and last band are partial, and smaller than one.
    #[test]
    fn strip_order_holds_and_draws_what_row_order_does() {
        let cube = CubeMap::<[u8; 4]>::from_fn(64, 1, |d| {
            let c = |v: f64| (127.5 + 127.0 * v) as u8;
            [c(d.x), c(d.y), c(d.z), 255]
        });
        let content = Content::cube(&cube);
        let atlas = content.atlas();
        for (w, h) in [(300u32, 37u32), (256, 32), (100, 10), (129, 17)] {
            let p = Params {
                hfov: Some(120.0),
                vfov: Some(70.0),
                ..Params::default()
            };
            let view =
                View::plain(projection::build("flat", &p, f64::from(h) / f64::from(w)).unwrap());
            let warp = Warp::View(&view);
            let dims = [w, h, 1];
            let plan = |order| {
                Plan::build(warp, &content, atlas, dims, Filter::Bilinear, true, order).unwrap()
            };
            let (strips, rows) = (plan(Order::Strips), plan(Order::Rows));
            assert_eq!(strips.order, Order::of(Filter::Bilinear, 1));
            let (w, h) = (w as usize, h as usize);
            let mut distinct = std::collections::HashSet::new();
            for y in 0..h {
                for x in 0..w {
                    assert_eq!(strips.pixel(x, y), rows.pixel(x, y), "{w}×{h}: ({x}, {y})");
                    distinct.insert(strips.pixel(x, y)[0].idx);
                }
            }
            // Every pixel sees its own texels: the comparison above is not of constant taps.
            assert!(
                distinct.len() > w * h / 4,
                "{w}×{h}: {} distinct taps",
                distinct.len()
            );
            let mut a = Raster::new(w, h);
            let mut b = Raster::new(w, h);
            strips.render_into(atlas, &mut a).unwrap();
            rows.render_into(atlas, &mut b).unwrap();
            assert!(
                a.data == b.data,
                "{w}×{h}: the strip loop draws other pixels"
            );
        }
    }
}
