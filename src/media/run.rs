//! The frame loop: each content frame decoded once, laid into the content's atlas (converted
//! from the pipe's pixel format as it goes), warped through every output's plan, blended, packed
//! for that output's writer.

use super::input::{Frame, Input};
use super::output::{Carry, OutputSpec, Packet, Pipe, Sink};
use super::yuv::{Decoder, Encoder, Matrix};
use crate::content::Content;
use crate::raster::{Pixel, Raster};
use crate::render::Plan;
use crate::rig::apply_gains;
use crate::{Error, Result};
use rayon::prelude::*;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

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

/// One output of a run: the warp's plan over the content's atlas, its size, the blend gains
/// (signal space) to bake in, and where it goes.
pub struct Target {
    /// The plan, made for the content the run's `setup` returns.
    pub plan: Plan,
    /// Output width and height, pixels.
    pub size: (u32, u32),
    /// Per-pixel gains multiplied in (a channel's blend), if any.
    pub gains: Option<Vec<f32>>,
    /// Per-pixel colour saturation (a tile screen's f: 1 as it is, 0 grey), applied before
    /// the gains, if any.
    pub saturation: Option<Vec<f32>>,
    /// Where the frames go.
    pub out: OutputSpec,
}

/// Where a run stands, handed to the progress callback after every frame.
#[derive(Debug, Clone, Copy)]
pub struct Progress {
    /// Frames done.
    pub frame: u64,
    /// Frames in all, when known.
    pub frames: Option<u64>,
    /// Time since the first frame arrived.
    pub elapsed: Duration,
}

/// What a run did and where its time went.
#[derive(Debug, Clone, Copy, Default)]
pub struct Summary {
    /// Frames warped (each to every output).
    pub frames: u64,
    /// Wall time of the whole run, seconds.
    pub seconds: f64,
    /// Seconds waiting for the decoder.
    pub waiting_for_decode: f64,
    /// Seconds laying frames into the atlas (with the pixel-format conversion).
    pub fill: f64,
    /// Seconds warping and blending.
    pub warp: f64,
    /// Seconds packing warped frames for the writers (with the conversion to 4:2:0).
    pub pack: f64,
    /// Seconds waiting for the writers (the encoders) to take a frame.
    pub waiting_for_encode: f64,
}

/// Runs `input` through the warp to every target. `setup` receives the first frame and returns
/// the content made from it (its layout and orientation) with the targets planned for that
/// content; later frames refill the same content. `stop` is checked between frames: when set,
/// the run ends with [`Error::Cancelled`] and, as on any failure, leaves no output behind.
pub fn transcode<T: Sample>(
    input: &Input,
    setup: impl FnOnce(&Raster<T>) -> Result<(Content<T>, Vec<Target>)>,
    mut progress: impl FnMut(Progress),
    stop: &AtomicBool,
) -> Result<Summary> {
    let start = Instant::now();
    let mut summary = Summary::default();
    let matrix = input
        .info()
        .map_or(Matrix::from_tags(None, None), |i| i.matrix());
    let decoder = matrix.decoder();
    let (w, h) = input.size();
    let mut frames = input.decode()?;
    let first = match frames.next() {
        Some(f) => f?,
        None => return Err(Error::invalid("content", "it holds no frame")),
    };
    let (mut content, targets) = setup(&whole(&first, (w, h), &decoder))?;
    if targets.is_empty() || targets.len() > crate::limits::MEDIA_OUTPUTS {
        return Err(Error::invalid(
            "out",
            format!(
                "1–{} outputs, got {}",
                crate::limits::MEDIA_OUTPUTS,
                targets.len()
            ),
        ));
    }
    let carry = Carry {
        audio_from: match input {
            Input::Movie { path, info } if info.audio => Some(path.clone()),
            _ => None,
        },
        timecode: input.info().and_then(|i| i.timecode.clone()),
        color: input.info().map(|i| i.color.clone()).unwrap_or_default(),
    };
    let first_number = match input {
        Input::Sequence(s, _) => s.first,
        Input::Movie { .. } => 1,
    };
    let mut sinks = targets
        .iter()
        .map(|t| Sink::start(&t.out, t.size, input.rate(), first_number, matrix, &carry))
        .collect::<Result<Vec<_>>>()?;
    let encoder = matrix.encoder();
    // Y′CbCr in and out: the atlas holds Y′CbCr itself and the warp filters it directly. The
    // conversion is affine and the filters are affine combinations, so this is the RGB path's
    // result without either conversion (up to rounding and clamping); the blend, a gain on
    // R′G′B′, is the same gain on Y′ − black and on Cb, Cr − 128.
    // Saturation is defined on R′G′B′ (Rec. 709 luma), so a target with one takes that path.
    let native = matches!(first, Frame::Yuv420(_))
        && sinks.iter().all(|s| s.pipe == Pipe::Yuv420)
        && targets.iter().all(|t| t.saturation.is_none());
    let black = if matrix.full_range() { 0 } else { 16 };
    let mut buffers: Vec<Raster<T>> = targets
        .iter()
        .map(|t| Raster::new(t.size.0 as usize, t.size.1 as usize))
        .collect();
    let mut next = Some(first);
    let mut frame_no = 0u64;
    let mut clock = Instant::now();
    let mut lap = |slot: &mut f64| {
        let now = Instant::now();
        *slot += (now - clock).as_secs_f64();
        clock = now;
    };
    lap(&mut summary.waiting_for_decode);
    while let Some(frame) = next.take() {
        if stop.load(Ordering::Relaxed) {
            return Err(Error::Cancelled);
        }
        if native {
            fill_native(&mut content, &frame, (w, h))?;
            lap(&mut summary.fill);
        } else if frame_no > 0 {
            fill(&mut content, &frame, (w, h), &decoder)?;
            lap(&mut summary.fill);
        }
        frames.recycle(frame);
        for ((t, buf), sink) in targets.iter().zip(&mut buffers).zip(&mut sinks) {
            t.plan.render_into(content.atlas(), buf)?;
            if let Some(f) = &t.saturation {
                crate::tiles::raster::saturation(buf, f);
            }
            if let (Some(g), false) = (&t.gains, native) {
                apply_gains(buf, g)?;
            }
            lap(&mut summary.warp);
            let bytes = sink.buffer();
            let packet = match sink.pipe {
                Pipe::Yuv420 if native => {
                    Packet::Bytes(pack_native(buf, t.gains.as_deref(), black, bytes))
                }
                Pipe::Yuv420 => Packet::Bytes(pack_yuv(buf, &encoder, bytes)),
                Pipe::Rgba => Packet::Bytes(pack_rgba(buf, bytes)),
                Pipe::Png => Packet::U8(buf.map(T::to_rgba8)),
                Pipe::Exr => Packet::F32(buf.map(T::to_unit)),
            };
            lap(&mut summary.pack);
            sink.send(packet)?;
            lap(&mut summary.waiting_for_encode);
        }
        frame_no += 1;
        progress(Progress {
            frame: frame_no,
            frames: input.frames(),
            elapsed: start.elapsed(),
        });
        next = frames.next().transpose()?;
        lap(&mut summary.waiting_for_decode);
    }
    drop(frames);
    // Every output complete before any is put in place: a failure in one leaves none.
    for sink in &mut sinks {
        sink.complete()?;
    }
    for sink in sinks {
        sink.place()?;
    }
    lap(&mut summary.waiting_for_encode);
    summary.frames = frame_no;
    summary.seconds = start.elapsed().as_secs_f64();
    Ok(summary)
}

/// A whole frame as a raster, for the content's first layout.
fn whole<T: Sample>(frame: &Frame, (w, h): (usize, usize), d: &Decoder) -> Raster<T> {
    let mut r = Raster::new(w, h);
    r.data.par_chunks_mut(w).enumerate().for_each(|(y, row)| {
        for (x, p) in row.iter_mut().enumerate() {
            *p = pixel(frame, w, h, d, x, y);
        }
    });
    r
}

#[inline]
fn pixel<T: Sample>(frame: &Frame, w: usize, h: usize, d: &Decoder, x: usize, y: usize) -> T {
    match frame {
        Frame::Yuv420(b) => {
            let cw = w.div_ceil(2);
            let c = (y / 2) * cw + x / 2;
            let u0 = w * h;
            let v0 = u0 + cw * h.div_ceil(2);
            let [r, g, bl] = d.rgb(b[y * w + x], b[u0 + c], b[v0 + c]);
            T::from_rgba8([r, g, bl, 255])
        }
        Frame::Rgba8(r) => T::from_rgba8(r.data[y * w + x]),
        Frame::RgbaF32(r) => T::from_unit(r.data[y * w + x]),
    }
}

fn fill<T: Sample>(
    content: &mut Content<T>,
    frame: &Frame,
    (w, h): (usize, usize),
    d: &Decoder,
) -> Result<()> {
    match frame {
        Frame::Yuv420(b) => {
            let cw = w.div_ceil(2);
            let (u0, v0) = (w * h, w * h + cw * h.div_ceil(2));
            content.refill((w, h), |y, row| {
                let ys = &b[y * w..(y + 1) * w];
                let c = (y / 2) * cw;
                let (us, vs) = (&b[u0 + c..u0 + c + cw], &b[v0 + c..v0 + c + cw]);
                for (x, (p, &l)) in row.iter_mut().zip(ys).enumerate() {
                    let [r, g, bl] = d.rgb(l, us[x / 2], vs[x / 2]);
                    *p = T::from_rgba8([r, g, bl, 255]);
                }
            })
        }
        Frame::Rgba8(r) => content.refill((w, h), |y, row| {
            for (p, &q) in row.iter_mut().zip(&r.data[y * w..(y + 1) * w]) {
                *p = T::from_rgba8(q);
            }
        }),
        Frame::RgbaF32(r) => content.refill((w, h), |y, row| {
            for (p, &q) in row.iter_mut().zip(&r.data[y * w..(y + 1) * w]) {
                *p = T::from_unit(q);
            }
        }),
    }
}

/// A 4:2:0 frame laid into the atlas as it is: texels (Y′, Cb, Cr, 1), chroma repeated over
/// its 2×2 block.
fn fill_native<T: Sample>(
    content: &mut Content<T>,
    frame: &Frame,
    (w, h): (usize, usize),
) -> Result<()> {
    let Frame::Yuv420(b) = frame else {
        unreachable!("native only for 4:2:0 frames")
    };
    let cw = w.div_ceil(2);
    let (u0, v0) = (w * h, w * h + cw * h.div_ceil(2));
    content.refill((w, h), |y, row| {
        let ys = &b[y * w..(y + 1) * w];
        let c = (y / 2) * cw;
        let (us, vs) = (&b[u0 + c..u0 + c + cw], &b[v0 + c..v0 + c + cw]);
        for ((pair, ls), (&u, &v)) in row
            .chunks_exact_mut(2)
            .zip(ys.chunks_exact(2))
            .zip(us.iter().zip(vs))
        {
            pair[0] = T::from_rgba8([ls[0], u, v, 255]);
            pair[1] = T::from_rgba8([ls[1], u, v, 255]);
        }
        if w % 2 == 1 {
            row[w - 1] = T::from_rgba8([ys[w - 1], us[cw - 1], vs[cw - 1], 255]);
        }
    })
}

/// 4:2:0 planes of a frame warped in Y′CbCr: luma as it is, chroma averaged over each 2×2
/// block, black where nothing is shown, the blend's gain applied about black. Row pairs in
/// parallel; without a blend, plain loops over bytes that the compiler vectorises.
fn pack_native<T: Sample>(
    img: &Raster<T>,
    gains: Option<&[f32]>,
    black: u8,
    out: Vec<u8>,
) -> Vec<u8> {
    let (w, h) = (img.width, img.height);
    let (cw, ch) = (w.div_ceil(2), h.div_ceil(2));
    let mut out = sized(out, super::yuv::frame_len(w, h));
    let (luma, chroma) = out.split_at_mut(w * h);
    let (cb, cr) = chroma.split_at_mut(cw * ch);
    if let (None, Some(data)) = (gains, T::bytes(&img.data)) {
        pack_plain(data, w, h, black, luma, cb, cr);
        return out;
    }
    // A pixel as (Y′, Cb, Cr, shown): gained about black where there is a blend.
    let code = |i: usize| -> [u8; 4] {
        let p = img.data[i].to_rgba8();
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
    luma.par_chunks_mut(2 * w)
        .zip(cb.par_chunks_mut(cw).zip(cr.par_chunks_mut(cw)))
        .enumerate()
        .for_each(|(j, (ys, (us, vs)))| {
            let rows = [2 * j, (2 * j + 1).min(h - 1)];
            let px: [Vec<[u8; 4]>; 2] = rows.map(|y| (y * w..(y + 1) * w).map(code).collect());
            for (row, src) in ys.chunks_exact_mut(w).zip(&px) {
                for (o, p) in row.iter_mut().zip(src) {
                    *o = if p[3] == 0 { black } else { p[0] };
                }
            }
            let chroma = |p: [u8; 4], c: usize| if p[3] == 0 { 128 } else { u16::from(p[c]) };
            for (x, (u, v)) in us.iter_mut().zip(vs.iter_mut()).enumerate() {
                let (a, b) = (2 * x, (2 * x + 1).min(w - 1));
                let q = [px[0][a], px[0][b], px[1][a], px[1][b]];
                let mean =
                    |c: usize| ((q.iter().map(|&p| chroma(p, c)).sum::<u16>() + 2) >> 2) as u8;
                *u = mean(1);
                *v = mean(2);
            }
        });
    out
}

/// [`pack_native`] of 8-bit pixels without a blend: plain loops over bytes, no copies.
fn pack_plain(
    data: &[[u8; 4]],
    w: usize,
    h: usize,
    black: u8,
    luma: &mut [u8],
    cb: &mut [u8],
    cr: &mut [u8],
) {
    let cw = w.div_ceil(2);
    luma.par_chunks_mut(2 * w)
        .zip(cb.par_chunks_mut(cw).zip(cr.par_chunks_mut(cw)))
        .enumerate()
        .for_each(|(j, (ys, (us, vs)))| {
            let r0 = &data[2 * j * w..(2 * j + 1) * w];
            let y1 = (2 * j + 1).min(h - 1);
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
        });
}

/// `buf` as a buffer of `len` bytes, every one of which the caller overwrites.
fn sized(buf: Vec<u8>, len: usize) -> Vec<u8> {
    if buf.len() == len { buf } else { vec![0; len] }
}

fn pack_rgba<T: Sample>(img: &Raster<T>, out: Vec<u8>) -> Vec<u8> {
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

/// 4:2:0 planes of a warped frame: luma per pixel, chroma from the sum of each 2×2 block
/// (odd sizes repeat the last row or column into it). Row pairs in parallel; each plane's loop
/// is plain enough for the compiler to vectorise.
fn pack_yuv<T: Sample>(img: &Raster<T>, e: &Encoder, out: Vec<u8>) -> Vec<u8> {
    let (w, h) = (img.width, img.height);
    let cw = w.div_ceil(2);
    let ch = h.div_ceil(2);
    let mut out = sized(out, super::yuv::frame_len(w, h));
    let (luma, chroma) = out.split_at_mut(w * h);
    let (cb, cr) = chroma.split_at_mut(cw * ch);
    luma.par_chunks_mut(2 * w)
        .zip(cb.par_chunks_mut(cw).zip(cr.par_chunks_mut(cw)))
        .enumerate()
        .for_each(|(j, (ys, (us, vs)))| {
            let rgb = |y: usize| -> Vec<[i32; 3]> {
                img.data[y * w..(y + 1) * w]
                    .iter()
                    .map(|p| {
                        let [r, g, b, _] = p.to_rgba8();
                        [i32::from(r), i32::from(g), i32::from(b)]
                    })
                    .collect()
            };
            let top = rgb(2 * j);
            let bottom = if 2 * j + 1 < h {
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
        });
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frame(w: usize, h: usize) -> Raster<[u8; 4]> {
        Raster::from_fn(w, h, |x, y| {
            let a = if (x * 7 + y * 3) % 11 == 0 { 0 } else { 255 };
            [
                (x * 13 + y) as u8,
                (x * 5 + 90) as u8,
                (y * 9 + 20) as u8,
                a,
            ]
        })
    }

    /// The byte loops give what the general path gives (float pixels take it), at even and odd
    /// sizes; empty pixels are black; a blend's gain scales about black and about 128.
    #[test]
    fn packing_in_ycbcr_is_the_same_on_both_paths_and_gains_scale_about_black() {
        for (w, h) in [(8, 6), (7, 5)] {
            let bytes = frame(w, h);
            let floats = bytes.map(|p| p.map(|c| f32::from(c) / 255.0));
            let a = pack_native(&bytes, None, 16, Vec::new());
            let b = pack_native(&floats, None, 16, Vec::new());
            assert_eq!(a, b, "{w}×{h}");
            let empty = (0..w * h).find(|&i| bytes.data[i][3] == 0).unwrap();
            assert_eq!(a[empty], 16);
        }
        let one = Raster::from_fn(2, 2, |_, _| [216u8, 200, 56, 255]);
        let packed = pack_native(&one, Some(&[0.5; 4]), 16, Vec::new());
        assert_eq!(packed, vec![116, 116, 116, 116, 164, 92]);
    }
}
