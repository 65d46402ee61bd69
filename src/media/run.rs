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
    let native = matches!(first, Frame::Yuv420(_)) && sinks.iter().all(|s| s.pipe == Pipe::Yuv420);
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
        for ((t, buf), sink) in targets.iter().zip(&mut buffers).zip(&mut sinks) {
            t.plan.render_into(content.atlas(), buf)?;
            if let (Some(g), false) = (&t.gains, native) {
                apply_gains(buf, g)?;
            }
            lap(&mut summary.warp);
            let packet = match sink.pipe {
                Pipe::Yuv420 if native => {
                    Packet::Bytes(pack_native(buf, t.gains.as_deref(), black))
                }
                Pipe::Yuv420 => Packet::Bytes(pack_yuv(buf, &encoder)),
                Pipe::Rgba => Packet::Bytes(pack_rgba(buf)),
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
    for sink in sinks {
        sink.finish()?;
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
/// parallel, each plane in a loop of its own that the compiler can vectorise.
fn pack_native<T: Sample>(img: &Raster<T>, gains: Option<&[f32]>, black: u8) -> Vec<u8> {
    let (w, h) = (img.width, img.height);
    let (cw, ch) = (w.div_ceil(2), h.div_ceil(2));
    let mut out = vec![0u8; super::yuv::frame_len(w, h)];
    let (luma, chroma) = out.split_at_mut(w * h);
    let (cb, cr) = chroma.split_at_mut(cw * ch);
    let black = i32::from(black);
    luma.par_chunks_mut(2 * w)
        .zip(cb.par_chunks_mut(cw).zip(cr.par_chunks_mut(cw)))
        .enumerate()
        .for_each(|(j, (ys, (us, vs)))| {
            // The pair's pixels as (Y′, Cb, Cr) code values in 1/256ths, gained, black where
            // empty; the second row repeats the first at an odd height's end.
            let rows = [2 * j, (2 * j + 1).min(h - 1)];
            let mut q = [vec![[0i32; 3]; w], vec![[0i32; 3]; w]];
            for (k, &y) in rows.iter().enumerate() {
                let src = &img.data[y * w..(y + 1) * w];
                let g = gains.map(|g| &g[y * w..(y + 1) * w]);
                for (x, (o, p)) in q[k].iter_mut().zip(src).enumerate() {
                    let [l, u, v, a] = p.to_rgba8();
                    let gain = match g {
                        _ if a == 0 => 0,
                        Some(g) => (g[x].clamp(0.0, 1.0) * 256.0 + 0.5) as i32,
                        None => 256,
                    };
                    *o = [
                        (black << 8) + (i32::from(l) - black) * gain,
                        (128 << 8) + (i32::from(u) - 128) * gain,
                        (128 << 8) + (i32::from(v) - 128) * gain,
                    ];
                }
            }
            for (k, row) in ys.chunks_exact_mut(w).enumerate() {
                for (o, p) in row.iter_mut().zip(&q[k]) {
                    *o = ((p[0] + 128) >> 8).clamp(0, 255) as u8;
                }
            }
            for x in 0..cw {
                let (a, b) = (2 * x, (2 * x + 1).min(w - 1));
                let sum = |c: usize| q[0][a][c] + q[0][b][c] + q[1][a][c] + q[1][b][c];
                us[x] = ((sum(1) + 512) >> 10).clamp(0, 255) as u8;
                vs[x] = ((sum(2) + 512) >> 10).clamp(0, 255) as u8;
            }
        });
    out
}

fn pack_rgba<T: Sample>(img: &Raster<T>) -> Vec<u8> {
    let mut out = vec![0u8; img.data.len() * 4];
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
fn pack_yuv<T: Sample>(img: &Raster<T>, e: &Encoder) -> Vec<u8> {
    let (w, h) = (img.width, img.height);
    let cw = w.div_ceil(2);
    let ch = h.div_ceil(2);
    let mut out = vec![0u8; super::yuv::frame_len(w, h)];
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
