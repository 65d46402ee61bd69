//! The pixel types a movie is warped in, and warped frames packed for their writers: 4:2:0 planes a band of rows at a time (luma as it
//! is, chroma from each 2×2 block), in Y′CbCr as warped or converted from R′G′B′, and RGBA.

use super::yuv::Encoder;
use crate::raster::Pixel;
use crate::raster::Raster;
use crate::render::Plan;
use rayon::prelude::*;

/// Pixel types a movie can be warped in: 8-bit, or float for deeper sources.
pub trait Sample: Pixel {
    /// From 8-bit RGBA.
    fn from_rgba8(p: [u8; 4]) -> Self;
    /// From float RGBA, 0–1.
    fn from_unit(p: [f32; 4]) -> Self;
    /// To 8-bit RGBA.
    fn to_rgba8(self) -> [u8; 4];
    /// To float RGBA, 0–1.
    fn to_unit(self) -> [f32; 4];
    /// The pixels as 8-bit RGBA without a conversion, where that is what they are.
    fn bytes(pixels: &[Self]) -> Option<&[[u8; 4]]>;
}

impl Sample for [u8; 4] {
    #[inline]
    fn from_rgba8(p: [u8; 4]) -> Self {
        p
    }
    fn from_unit(p: [f32; 4]) -> Self {
        <[u8; 4]>::from_f32(p.map(|c| c * 255.0))
    }
    #[inline]
    fn to_rgba8(self) -> [u8; 4] {
        self
    }
    fn to_unit(self) -> [f32; 4] {
        self.map(|c| f32::from(c) / 255.0)
    }
    fn bytes(pixels: &[Self]) -> Option<&[[u8; 4]]> {
        Some(pixels)
    }
}

impl Sample for [f32; 4] {
    #[inline]
    fn from_rgba8(p: [u8; 4]) -> Self {
        p.map(|c| f32::from(c) / 255.0)
    }
    fn from_unit(p: [f32; 4]) -> Self {
        p
    }
    #[inline]
    fn to_rgba8(self) -> [u8; 4] {
        <[u8; 4]>::from_f32(self.map(|c| c * 255.0))
    }
    fn to_unit(self) -> [f32; 4] {
        self
    }
    fn bytes(_: &[Self]) -> Option<&[[u8; 4]]> {
        None
    }
}

/// The 4:2:0 planes in `out` cut into the pieces of a frame's bands of [`Plan::BAND`] rows:
/// each band's luma rows and its half as many chroma rows of each plane.
pub(super) type Planes<'a> = (&'a mut [u8], &'a mut [u8], &'a mut [u8]);

pub(super) fn bands(out: &mut [u8], w: usize, h: usize) -> Vec<Planes<'_>> {
    let (cw, ch) = (w.div_ceil(2), h.div_ceil(2));
    let (luma, chroma) = out.split_at_mut(w * h);
    let (cb, cr) = chroma.split_at_mut(cw * ch);
    let rows = Plan::BAND;
    luma.chunks_mut(w * rows)
        .zip(cb.chunks_mut(cw * rows / 2))
        .zip(cr.chunks_mut(cw * rows / 2))
        .map(|((y, u), v)| (y, u, v))
        .collect()
}

/// A band of a frame warped in Y′CbCr as 4:2:0 rows: luma as it is, chroma averaged over each
/// 2×2 block, black where nothing is shown, the blend's gain applied about black. Without a
/// blend, plain loops over bytes that the compiler vectorises.
pub(super) fn pack_native<T: Sample>(
    px: &[T],
    w: usize,
    gains: Option<&[f32]>,
    black: u8,
    luma: &mut [u8],
    cb: &mut [u8],
    cr: &mut [u8],
) {
    if let (None, Some(data)) = (gains, T::bytes(px)) {
        pack_plain(data, w, black, luma, cb, cr);
        return;
    }
    // A pixel as (Y′, Cb, Cr, shown): gained about black where there is a blend.
    let code = |i: usize| -> [u8; 4] {
        let p = px[i].to_rgba8();
        match gains {
            None => p,
            Some(g) => {
                let g = g[i].clamp(0.0, 1.0);
                let about = |c: u8, zero: u8| {
                    (f32::from(zero) + (f32::from(c) - f32::from(zero)) * g).round() as u8
                };
                [about(p[0], black), about(p[1], 128), about(p[2], 128), p[3]]
            }
        }
    };
    let rows = px.len() / w;
    let cw = w.div_ceil(2);
    for (j, (ys, (us, vs))) in luma
        .chunks_mut(2 * w)
        .zip(cb.chunks_mut(cw).zip(cr.chunks_mut(cw)))
        .enumerate()
    {
        let pair = [2 * j, (2 * j + 1).min(rows - 1)];
        let px: [Vec<[u8; 4]>; 2] = pair.map(|y| (y * w..(y + 1) * w).map(code).collect());
        for (row, src) in ys.chunks_exact_mut(w).zip(&px) {
            for (o, p) in row.iter_mut().zip(src) {
                *o = if p[3] == 0 { black } else { p[0] };
            }
        }
        let chroma = |p: [u8; 4], c: usize| if p[3] == 0 { 128 } else { u16::from(p[c]) };
        for (x, (u, v)) in us.iter_mut().zip(vs.iter_mut()).enumerate() {
            let (a, b) = (2 * x, (2 * x + 1).min(w - 1));
            let q = [px[0][a], px[0][b], px[1][a], px[1][b]];
            let mean = |c: usize| ((q.iter().map(|&p| chroma(p, c)).sum::<u16>() + 2) >> 2) as u8;
            *u = mean(1);
            *v = mean(2);
        }
    }
}

/// [`pack_native`] of 8-bit pixels without a blend: plain loops over bytes, no copies.
pub(super) fn pack_plain(
    data: &[[u8; 4]],
    w: usize,
    black: u8,
    luma: &mut [u8],
    cb: &mut [u8],
    cr: &mut [u8],
) {
    let rows = data.len() / w;
    let cw = w.div_ceil(2);
    for (j, (ys, (us, vs))) in luma
        .chunks_mut(2 * w)
        .zip(cb.chunks_mut(cw).zip(cr.chunks_mut(cw)))
        .enumerate()
    {
        let r0 = &data[2 * j * w..(2 * j + 1) * w];
        let y1 = (2 * j + 1).min(rows - 1);
        let r1 = &data[y1 * w..(y1 + 1) * w];
        for (row, src) in ys.chunks_exact_mut(w).zip([r0, r1]) {
            for (o, p) in row.iter_mut().zip(src) {
                *o = if p[3] == 0 { black } else { p[0] };
            }
        }
        let c = |p: &[u8; 4], k: usize| if p[3] == 0 { 128 } else { u16::from(p[k]) };
        for (((u, v), a), b) in us
            .iter_mut()
            .zip(vs.iter_mut())
            .zip(r0.chunks(2))
            .zip(r1.chunks(2))
        {
            // An odd width's last block repeats its column.
            let (a1, b1) = (&a[a.len() - 1], &b[b.len() - 1]);
            let mean = |k| ((c(&a[0], k) + c(a1, k) + c(&b[0], k) + c(b1, k) + 2) >> 2) as u8;
            *u = mean(1);
            *v = mean(2);
        }
    }
}

/// `buf` as a buffer of `len` bytes, every one of which the caller overwrites.
pub(super) fn sized(buf: Vec<u8>, len: usize) -> Vec<u8> {
    if buf.len() == len { buf } else { vec![0; len] }
}

pub(super) fn pack_rgba<T: Sample>(img: &Raster<T>, out: Vec<u8>) -> Vec<u8> {
    let mut out = sized(out, img.data.len() * 4);
    out.par_chunks_mut(4 * img.width)
        .zip(img.data.par_chunks(img.width))
        .for_each(|(o, row)| {
            for (o, p) in o.chunks_exact_mut(4).zip(row) {
                o.copy_from_slice(&p.to_rgba8());
            }
        });
    out
}

/// A band of a warped frame as 4:2:0 rows: luma per pixel, chroma from the sum of each 2×2
/// block (odd sizes repeat the last row or column into it). Each plane's loop is plain enough
/// for the compiler to vectorise.
pub(super) fn pack_yuv<T: Sample>(
    px: &[T],
    w: usize,
    e: &Encoder,
    luma: &mut [u8],
    cb: &mut [u8],
    cr: &mut [u8],
) {
    let rows = px.len() / w;
    let cw = w.div_ceil(2);
    let rgb = |y: usize| -> Vec<[i32; 3]> {
        px[y * w..(y + 1) * w]
            .iter()
            .map(|p| {
                let [r, g, b, _] = p.to_rgba8();
                [i32::from(r), i32::from(g), i32::from(b)]
            })
            .collect()
    };
    for (j, (ys, (us, vs))) in luma
        .chunks_mut(2 * w)
        .zip(cb.chunks_mut(cw).zip(cr.chunks_mut(cw)))
        .enumerate()
    {
        let top = rgb(2 * j);
        let bottom = if 2 * j + 1 < rows {
            rgb(2 * j + 1)
        } else {
            top.clone()
        };
        for (k, row) in [&top, &bottom].iter().enumerate().take(ys.len() / w) {
            for (o, &c) in ys[k * w..(k + 1) * w].iter_mut().zip(row.iter()) {
                *o = e.y(c);
            }
        }
        for x in 0..cw {
            let (a, b) = (2 * x, (2 * x + 1).min(w - 1));
            let mut sum = [0i32; 3];
            for c in [top[a], top[b], bottom[a], bottom[b]] {
                sum[0] += c[0];
                sum[1] += c[1];
                sum[2] += c[2];
            }
            let (u, v) = e.uv(sum, true);
            us[x] = u;
            vs[x] = v;
        }
    }
}
