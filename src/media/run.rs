//! The frame loop: each content frame decoded once, laid into the content's atlas (converted
//! from the pipe's pixel format as it goes), warped through every output's plan, blended, packed
//! for that output's writer.

use super::input::{Frame, Input};
use super::output::{Carry, OutputSpec, Packet, Pipe, Sink};
use super::pack::{Sample, bands, pack_native, pack_rgba, pack_yuv, sized};
use super::yuv::{Decoder, Encoder, Matrix};
use crate::content::Content;
use crate::raster::{Pixel, Raster};
use crate::render::Plan;
use crate::{Error, Result};
use rayon::prelude::*;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

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
    for t in &targets {
        let pixels = (t.size.0 * t.size.1) as usize;
        for (name, v) in [("gains", &t.gains), ("saturation", &t.saturation)] {
            if let Some(n) = v.as_ref().map(Vec::len).filter(|&n| n != pixels) {
                return Err(Error::invalid(
                    name,
                    format!("{n} values for a {}×{} output", t.size.0, t.size.1),
                ));
            }
        }
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
            let way = Way {
                pipe: sink.pipe,
                native,
                black,
                encoder: &encoder,
            };
            let packet = warp(t, content.atlas(), buf, &way, sink.buffer(), &mut |s| {
                lap(if s == Stage::Warp {
                    &mut summary.warp
                } else {
                    &mut summary.pack
                })
            })?;
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

/// Where a frame's time went, for the run's summary.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Stage {
    /// Warping and blending (with the 4:2:0 packing, done band by band as the warp draws).
    Warp,
    /// Packing a whole frame for its writer.
    Pack,
}

/// How a target's frames leave the loop.
struct Way<'a> {
    pipe: Pipe,
    /// The frame was warped in Y′CbCr (see `transcode`).
    native: bool,
    /// Y′ of black.
    black: u8,
    encoder: &'a Encoder,
}

/// One frame of one target: warped from `atlas` into `buf`, saturation and gains applied,
/// packed for its writer into `bytes` (a buffer to reuse). For a 4:2:0 pipe the packing runs on
/// each band of rows as soon as it is drawn, while it is in the cache: a 4K frame is 33 MB of
/// pixels, which otherwise go out to memory and back once more.
fn warp<T: Sample>(
    t: &Target,
    atlas: &crate::content::Atlas<T>,
    buf: &mut Raster<T>,
    way: &Way,
    bytes: Vec<u8>,
    lap: &mut dyn FnMut(Stage),
) -> Result<Packet> {
    let (gains, sat) = (t.gains.as_deref(), t.saturation.as_deref());
    let w = buf.width;
    if way.pipe == Pipe::Yuv420 {
        let mut bytes = sized(bytes, super::yuv::frame_len(w, buf.height));
        let pieces = bands(&mut bytes, w, buf.height);
        t.plan
            .render_bands(atlas, buf, pieces, |y0, px, (ys, us, vs)| {
                let at = y0 * w..y0 * w + px.len();
                if way.native {
                    pack_native(px, w, gains.map(|g| &g[at]), way.black, ys, us, vs);
                } else {
                    finish(px, sat.map(|f| &f[at.clone()]), gains.map(|g| &g[at]));
                    pack_yuv(px, w, way.encoder, ys, us, vs);
                }
            })?;
        lap(Stage::Warp);
        return Ok(Packet::Bytes(bytes));
    }
    t.plan.render_into(atlas, buf)?;
    buf.data.par_chunks_mut(w).enumerate().for_each(|(y, row)| {
        let at = y * w..(y + 1) * w;
        finish(row, sat.map(|f| &f[at.clone()]), gains.map(|g| &g[at]));
    });
    lap(Stage::Warp);
    let packet = match way.pipe {
        Pipe::Rgba => Packet::Bytes(pack_rgba(buf, bytes)),
        Pipe::Png => Packet::U8(buf.map(T::to_rgba8)),
        Pipe::Exr => Packet::F32(buf.map(T::to_unit)),
        Pipe::Yuv420 => unreachable!("packed band by band above"),
    };
    lap(Stage::Pack);
    Ok(packet)
}

/// A tile screen's saturation, then the blend's gains, on warped pixels.
fn finish<T: Pixel>(px: &mut [T], saturation: Option<&[f32]>, gains: Option<&[f32]>) {
    if let Some(f) = saturation {
        for (p, &s) in px.iter_mut().zip(f) {
            crate::tiles::raster::saturate(p, s);
        }
    }
    if let Some(g) = gains {
        for (p, &m) in px.iter_mut().zip(g) {
            crate::rig::gain(p, m);
        }
    }
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rig::apply_gains;

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

    /// A whole frame's 4:2:0 planes, packed as one band.
    fn whole_native<T: Sample>(img: &Raster<T>, gains: Option<&[f32]>, black: u8) -> Vec<u8> {
        let (w, h) = (img.width, img.height);
        let mut out = vec![0; super::super::yuv::frame_len(w, h)];
        let (luma, chroma) = out.split_at_mut(w * h);
        let (cb, cr) = chroma.split_at_mut(w.div_ceil(2) * h.div_ceil(2));
        pack_native(&img.data, w, gains, black, luma, cb, cr);
        out
    }

    /// The byte loops give what the general path gives (float pixels take it), at even and odd
    /// sizes; empty pixels are black; a blend's gain scales about black and about 128.
    #[test]
    fn packing_in_ycbcr_is_the_same_on_both_paths_and_gains_scale_about_black() {
        for (w, h) in [(8, 6), (7, 5)] {
            let bytes = frame(w, h);
            let floats = bytes.map(|p| p.map(|c| f32::from(c) / 255.0));
            let a = whole_native(&bytes, None, 16);
            let b = whole_native(&floats, None, 16);
            assert_eq!(a, b, "{w}×{h}");
            let empty = (0..w * h).find(|&i| bytes.data[i][3] == 0).unwrap();
            assert_eq!(a[empty], 16);
        }
        let one = Raster::from_fn(2, 2, |_, _| [216u8, 200, 56, 255]);
        let packed = whole_native(&one, Some(&[0.5; 4]), 16);
        assert_eq!(packed, vec![116, 116, 116, 116, 164, 92]);
    }

    /// Packing band by band as the warp draws gives the frame that warping it whole, then
    /// saturating, blending and packing it whole gives: at an odd size three bands tall, on
    /// both the Y′CbCr and the R′G′B′ path.
    #[test]
    fn packing_each_band_as_it_is_drawn_gives_the_whole_frames_packing() {
        let image = frame(64, 32);
        let content = Content::equirect(&image, 360.0, 180.0).unwrap();
        let view = crate::projection::View::new(
            crate::projection::build(
                "cylindrical",
                &crate::projection::Params {
                    hfov: Some(270.0),
                    vfov: Some(90.0),
                    ..Default::default()
                },
                37.0 / 45.0,
            )
            .unwrap(),
            Default::default(),
            glam::DVec3::ZERO,
            1.0,
        )
        .unwrap();
        let (w, h) = (45, 37);
        let plan = || {
            Plan::new(
                crate::render::Warp::View(&view),
                &content,
                content.atlas(),
                w as u32,
                h as u32,
                1,
                crate::render::Filter::Bilinear,
            )
            .unwrap()
        };
        let gains: Vec<f32> = (0..w * h).map(|i| (i % 17) as f32 / 16.0).collect();
        let saturation: Vec<f32> = (0..w * h).map(|i| (i % 5) as f32 / 4.0).collect();
        let encoder = Matrix::from_tags(None, None).encoder();
        for native in [true, false] {
            let t = Target {
                plan: plan(),
                size: (w as u32, h as u32),
                gains: Some(gains.clone()),
                saturation: (!native).then(|| saturation.clone()),
                out: OutputSpec {
                    path: "unused.mp4".into(),
                    encoding: Default::default(),
                },
            };
            let way = Way {
                pipe: Pipe::Yuv420,
                native,
                black: 16,
                encoder: &encoder,
            };
            let mut buf = Raster::new(w, h);
            let Packet::Bytes(fused) =
                warp(&t, content.atlas(), &mut buf, &way, Vec::new(), &mut |_| {}).unwrap()
            else {
                panic!("4:2:0 frames are bytes")
            };
            let mut img = plan().render(content.atlas()).unwrap();
            let whole = if native {
                whole_native(&img, Some(&gains), 16)
            } else {
                crate::tiles::raster::saturation(&mut img, &saturation);
                apply_gains(&mut img, &gains).unwrap();
                let mut out = vec![0; super::super::yuv::frame_len(w, h)];
                let (luma, chroma) = out.split_at_mut(w * h);
                let (cb, cr) = chroma.split_at_mut(w.div_ceil(2) * h.div_ceil(2));
                pack_yuv(&img.data, w, &encoder, luma, cb, cr);
                out
            };
            assert!(fused == whole, "native {native}: the fused frame differs");
        }
    }
}
