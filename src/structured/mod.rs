//! Structured light: the patterns a projector shows so that a camera can tell, for each of its
//! pixels, which projector pixel lights it — the measurement behind camera-based calibration.
//!
//! Each axis is coded twice over, because each code alone fails somewhere:
//!
//! * **Gray code** down to half a phase period, every bit followed by its inverse. A bit is
//!   read as "brighter than its inverse", which needs no threshold and no knowledge of the
//!   wall's albedo, the ambient light or either gamma. Neighbouring codes differ in one bit, so
//!   a pixel on a stripe edge can only be read as one of the two stripes it touches.
//! * **N-step phase shift** of a sinusoid with a period of [`PERIOD`] projector pixels (or
//!   another, [`PatternSet::with_period`], for a camera too defocused to see 16 px), in
//!   [`STEPS`] steps: the phase gives a sub-pixel position within the period. With 12 steps,
//!   harmonics 2–10 of the sinusoid cancel in the phase, so the projector's and the camera's
//!   gamma (which bend the sinusoid) do not bias it.
//!
//! Inter-reflection spreads light over distances much longer than 16 px, where a sinusoid and
//! the finest stripes average alike: it adds the same offset to every step and to both frames
//! of a pair, and leaves the phase and the fine bits alone. The coarse Gray bits are another
//! matter: a bit and its inverse light different halves of the wall, so the light bounced onto
//! a point differs between them, and where a wall folds onto itself (a room's corner) the half
//! facing the point can bounce more light onto it than the projector sends it directly. The
//! bit then reads wrong; the phase disagrees with it and the pixel is refused as inconsistent
//! (on a sphere the bounce is the same at every point, so a dome is safe). [`Code::Xor`]
//! (Gupta et al., "A practical approach to 3D scanning in the presence of interreflections,
//! subsurface scattering and defocus", IJCV 2013) shows every coarse bit XOR the finest one
//! instead: every frame is then made of stripes half a period wide, whose bounce averages out
//! like the phase's, and the decoder XORs the finest bit back out.
//!
//! The Gray code names the half period, the phase the position within the period; the two
//! are joined by taking the period whose phase lies nearest the Gray half-period's centre,
//! which is right even when the Gray code is off by one half period at a stripe edge.
//!
//! Frame order (what a capture folder holds, and what `GET /v1/channels/{id}/pattern/{n}`
//! serves): white, black, then for x and then y: the Gray bits from the most significant, each
//! as (pattern, inverse), then the phase steps. [`PatternSet::frames`] names every frame.

pub mod decode;
mod fit;
pub mod simulator;
pub mod triangulate;

pub use fit::{
    Check, FromCaptures, calibrate_captures, calibrate_decoded, camera_pose,
    camera_pose_from_projector, check, correspondences,
};

use crate::error::{Error, Result};
use std::f64::consts::TAU;

/// The phase-shift period in projector pixels, unless a set is given another.
pub const PERIOD: u32 = 16;
/// Phase steps per axis.
pub const STEPS: u32 = 12;

/// A single-channel image, row-major, top row first: a pattern or a camera capture. Patterns
/// are 8-bit; a capture from a 16-bit PNG keeps its 16 bits, which the decoder reads, so a
/// camera's finer levels are not cut away.
#[derive(Debug, Clone, PartialEq)]
pub struct Grey {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// The `width × height` grey levels (0 black, 255 white), row by row from the top; for a
    /// 16-bit capture, its levels rounded to 8 bits.
    pub data: Vec<u8>,
    /// A 16-bit capture's own levels (0 black, 65535 white), when it had more than 8 bits.
    pub deep: Option<Vec<u16>>,
}

impl Grey {
    /// An 8-bit image.
    pub fn new(width: u32, height: u32, data: Vec<u8>) -> Grey {
        Grey {
            width,
            height,
            data,
            deep: None,
        }
    }

    /// Pixel `i`'s level on the 8-bit scale (0–255), with a 16-bit capture's fraction.
    pub fn level(&self, i: usize) -> f64 {
        match &self.deep {
            Some(d) => f64::from(d[i]) / 257.0,
            None => f64::from(self.data[i]),
        }
    }

    /// The bytes the image holds in memory.
    pub fn bytes(&self) -> usize {
        self.data.len() + self.deep.as_ref().map_or(0, |d| 2 * d.len())
    }

    /// The image as a greyscale PNG file: 16-bit for a 16-bit capture, else 8-bit.
    pub fn png(&self) -> Result<Vec<u8>> {
        let mut out = Vec::new();
        let mut enc = png::Encoder::new(&mut out, self.width, self.height);
        enc.set_color(png::ColorType::Grayscale);
        let bytes = match &self.deep {
            Some(d) => {
                enc.set_depth(png::BitDepth::Sixteen);
                d.iter().flat_map(|v| v.to_be_bytes()).collect()
            }
            None => {
                enc.set_depth(png::BitDepth::Eight);
                self.data.clone()
            }
        };
        enc.set_compression(png::Compression::Fast);
        let mut w = enc
            .write_header()
            .map_err(|e| Error::invalid("png", e.to_string()))?;
        w.write_image_data(&bytes)
            .map_err(|e| Error::invalid("png", e.to_string()))?;
        w.finish()
            .map_err(|e| Error::invalid("png", e.to_string()))?;
        Ok(out)
    }

    /// Reads a PNG or JPEG of any colour type as luma (Rec. 709 weights, as the `image`
    /// crate converts), keeping 16 bits where the file has more than 8. `field` names the
    /// input in errors.
    pub fn decode(bytes: &[u8], field: &str) -> Result<Grey> {
        let bad = |e: image::ImageError| {
            Error::invalid(field, format!("is not a PNG or JPEG image: {e}"))
        };
        let reader = || {
            image::ImageReader::new(std::io::Cursor::new(bytes))
                .with_guessed_format()
                .map_err(|e| Error::invalid(field, e.to_string()))
        };
        // The header first: a small file may claim an image too large to allocate.
        let (w, h) = reader()?.into_dimensions().map_err(bad)?;
        crate::limits::at_most(field, (w as usize) * (h as usize), CAPTURE_PIXELS)?;
        let mut r = reader()?;
        let mut limits = image::Limits::default();
        // Room for a 16-bit RGBA decode of the pixels the header declared.
        limits.max_alloc = Some(u64::from(w) * u64::from(h) * 8 + (1 << 20));
        r.limits(limits);
        let img = r.decode().map_err(bad)?;
        let channel_bytes = img.color().bytes_per_pixel() / img.color().channel_count();
        if channel_bytes == 1 {
            return Ok(Grey::new(w, h, img.into_luma8().into_raw()));
        }
        let deep = img.into_luma16().into_raw();
        let data = deep
            .iter()
            .map(|&v| ((u32::from(v) + 128) / 257) as u8)
            .collect();
        Ok(Grey {
            width: w,
            height: h,
            data,
            deep: Some(deep),
        })
    }
}

/// The most pixels a camera capture may hold (a 20-megapixel camera fits).
pub const CAPTURE_PIXELS: usize = 24 << 20;

/// Which axis a frame codes: projector columns (x) or rows (y).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Axis {
    /// Projector columns: the frame varies across the image, in vertical stripes.
    X,
    /// Projector rows: the frame varies down the image, in horizontal stripes.
    Y,
}

/// One frame of the sequence.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Frame {
    /// Full white (255) everywhere; with `Black`, it tells which camera pixels the projector
    /// lights.
    White,
    /// Black (0) everywhere: the ambient light and the projector's black level.
    Black,
    /// Gray code bit `bit` (0 = most significant) of half-period stripes.
    Gray {
        /// The axis the bit codes.
        axis: Axis,
        /// Which bit, 0 the most significant.
        bit: u32,
        /// Whether this is the bit's inverse, shown right after it; a bit reads 1 where it is
        /// brighter than its inverse.
        inverse: bool,
    },
    /// Phase step `step` of [`STEPS`].
    Phase {
        /// The axis the sinusoid varies along.
        axis: Axis,
        /// The step, 0 to [`STEPS`] − 1: the sinusoid shifted by 2π·step/[`STEPS`].
        step: u32,
    },
}

impl Frame {
    /// The axis the frame varies along; white and black vary along none.
    pub fn axis(self) -> Option<Axis> {
        match self {
            Frame::White | Frame::Black => None,
            Frame::Gray { axis, .. } | Frame::Phase { axis, .. } => Some(axis),
        }
    }
}

/// How the Gray bits are shown (see the module's notes on inter-reflection).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub enum Code {
    /// Each bit as it is: stripes from half the image wide down to half a period.
    #[default]
    Gray,
    /// Each bit but the finest XOR the finest: stripes half a period wide in every frame.
    Xor,
}

impl Code {
    /// The code's name, as it parses: `gray` or `xor`.
    pub fn name(self) -> &'static str {
        match self {
            Code::Gray => "gray",
            Code::Xor => "xor",
        }
    }
}

impl std::str::FromStr for Code {
    type Err = Error;
    fn from_str(s: &str) -> Result<Code> {
        match s {
            "gray" => Ok(Code::Gray),
            "xor" => Ok(Code::Xor),
            _ => Err(Error::invalid(
                "code",
                format!("must be `gray` or `xor`, got `{s}`"),
            )),
        }
    }
}

/// The pattern sequence for one projector.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PatternSet {
    /// The projector's width in pixels, 1 to `limits::CHANNEL_SIDE` (16384).
    pub width: u32,
    /// The projector's height in pixels, 1 to `limits::CHANNEL_SIDE` (16384).
    pub height: u32,
    /// The phase-shift period, projector pixels; the finest Gray stripe is half of it.
    pub period: u32,
    /// How the Gray bits are shown; [`Code::Gray`] unless [`PatternSet::with_code`] chose another.
    pub code: Code,
}

impl PatternSet {
    /// The sequence for a `width` × `height` projector with the default [`PERIOD`] and Gray code;
    /// an error naming `resolution` for a side of 0 or above `limits::CHANNEL_SIDE`.
    pub fn new(width: u32, height: u32) -> Result<PatternSet> {
        let side = crate::limits::CHANNEL_SIDE;
        if !(1..=side).contains(&width) || !(1..=side).contains(&height) {
            return Err(Error::invalid(
                "resolution",
                format!("must be between 1 and {side} pixels each way, got {width}×{height}"),
            ));
        }
        Ok(PatternSet {
            width,
            height,
            period: PERIOD,
            code: Code::Gray,
        })
    }

    /// The same sequence with its Gray bits shown in `code`.
    pub fn with_code(self, code: Code) -> PatternSet {
        PatternSet { code, ..self }
    }

    /// The same sequence with a phase period of `period` projector pixels (even, 8–256). Blur
    /// of σ (in projector pixels) keeps exp(−2π²σ²/P²) of a period P's amplitude: at σ = 2 a
    /// 16 px period keeps 74 %, at σ = 8 under 1 %, where a 64 px period keeps 74 % again. A
    /// longer period costs precision in proportion (the phase's error in pixels grows with
    /// the period) and saves a Gray bit per doubling.
    pub fn with_period(self, period: u32) -> Result<PatternSet> {
        if !(8..=256).contains(&period) || !period.is_multiple_of(2) {
            return Err(Error::invalid(
                "period",
                format!("must be an even number of projector pixels, 8–256, got {period}"),
            ));
        }
        Ok(PatternSet { period, ..self })
    }

    fn side(&self, axis: Axis) -> u32 {
        match axis {
            Axis::X => self.width,
            Axis::Y => self.height,
        }
    }

    /// Gray bits for an axis: enough to number its half periods.
    pub fn bits(&self, axis: Axis) -> u32 {
        let halves = self.side(axis).div_ceil(self.period / 2);
        (u32::BITS - (halves - 1).leading_zeros()).max(1)
    }

    /// Every frame in order.
    pub fn frames(&self) -> Vec<Frame> {
        let mut out = vec![Frame::White, Frame::Black];
        for axis in [Axis::X, Axis::Y] {
            for bit in 0..self.bits(axis) {
                for inverse in [false, true] {
                    out.push(Frame::Gray { axis, bit, inverse });
                }
            }
            for step in 0..STEPS {
                out.push(Frame::Phase { axis, step });
            }
        }
        out
    }

    /// The number of frames: white, black, then per axis two per Gray bit and [`STEPS`] phase
    /// steps.
    pub fn len(&self) -> usize {
        2 + 2 * STEPS as usize + 2 * (self.bits(Axis::X) + self.bits(Axis::Y)) as usize
    }

    /// Always false: every sequence has its white and black frames.
    pub fn is_empty(&self) -> bool {
        false
    }

    /// Frame `n`, or an error naming `field` when there is none.
    pub fn frame(&self, n: usize, field: &str) -> Result<Frame> {
        self.frames().get(n).copied().ok_or_else(|| {
            Error::invalid(
                field,
                format!(
                    "frame {n} does not exist: a {}×{} projector's sequence has {} (0–{})",
                    self.width,
                    self.height,
                    self.len(),
                    self.len() - 1
                ),
            )
        })
    }

    /// The frame's 8-bit value along its axis at projector column or row `i`: every pattern
    /// varies along one axis only.
    pub fn value(&self, frame: Frame, i: u32) -> u8 {
        match frame {
            Frame::White => 255,
            Frame::Black => 0,
            Frame::Gray { axis, bit, inverse } => {
                let half = i / (self.period / 2);
                let gray = half ^ (half >> 1);
                let last = self.bits(axis) - 1;
                let mut on = (gray >> (last - bit)) & 1 == 1;
                if self.code == Code::Xor && bit < last {
                    on ^= gray & 1 == 1;
                }
                if on != inverse { 255 } else { 0 }
            }
            Frame::Phase { step, .. } => {
                let v = 0.5 + 0.5 * phase_cos(f64::from(i), self.period, step);
                (255.0 * v).round() as u8
            }
        }
    }

    /// One row (x frames) or column (y frames, and white and black) of the frame's values.
    pub fn profile(&self, frame: Frame) -> Vec<u8> {
        let axis = frame.axis().unwrap_or(Axis::X);
        (0..self.side(axis)).map(|i| self.value(frame, i)).collect()
    }

    /// The frame as the projector shows it.
    pub fn image(&self, frame: Frame) -> Grey {
        let profile = self.profile(frame);
        let (w, h) = (self.width as usize, self.height as usize);
        let mut data = vec![0u8; w * h];
        let by_column = frame.axis() != Some(Axis::Y);
        for (y, row) in data.chunks_exact_mut(w).enumerate() {
            if by_column {
                row.copy_from_slice(&profile);
            } else {
                row.fill(profile[y]);
            }
        }
        Grey::new(self.width, self.height, data)
    }
}

/// The phase pattern's cosine at projector coordinate `x` for step `step` of a `period`:
/// cos(2π·x/P − 2π·step/N). Pixel centres sit at integer `x`.
fn phase_cos(x: f64, period: u32, step: u32) -> f64 {
    (TAU * x / f64::from(period) - step_angle(step)).cos()
}

fn step_angle(step: u32) -> f64 {
    TAU * f64::from(step) / f64::from(STEPS)
}

/// The capture files of a folder in name order: every `.png`, `.jpg` and `.jpeg` (other files,
/// such as the camera's JSON, are left alone).
pub fn read_captures(dir: &std::path::Path) -> Result<Vec<Grey>> {
    read_images(dir, "captures")
}

/// The images of a folder in name order, as [`read_captures`] reads them; `field` names the
/// folder in an error.
pub fn read_images(dir: &std::path::Path, field: &str) -> Result<Vec<Grey>> {
    let mut names: Vec<std::path::PathBuf> = std::fs::read_dir(dir)
        .map_err(|e| Error::file(dir, e))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| {
            p.extension()
                .and_then(|e| e.to_str())
                .is_some_and(|e| matches!(e.to_ascii_lowercase().as_str(), "png" | "jpg" | "jpeg"))
        })
        .collect();
    names.sort();
    crate::limits::at_most(field, names.len(), MAX_FRAMES)?;
    names
        .iter()
        .map(|p| {
            let bytes = std::fs::read(p).map_err(|e| Error::file(p, e))?;
            Grey::decode(&bytes, &p.display().to_string())
        })
        .collect()
}

/// The most frames a capture set may hold (a 16384-pixel projector needs 2 + 2·(2·11 + 12)).
pub const MAX_FRAMES: usize = 80;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn neighbouring_half_periods_differ_in_one_bit() {
        let set = PatternSet::new(1920, 1200).unwrap();
        assert_eq!(set.bits(Axis::X), 8, "240 half periods need 8 bits");
        assert_eq!(set.bits(Axis::Y), 8, "150 half periods need 8 bits");
        assert_eq!(set.len(), 2 + 2 * (16 + 12));
        let bits = |i: u32| -> Vec<u8> {
            (0..set.bits(Axis::X))
                .map(|bit| {
                    set.value(
                        Frame::Gray {
                            axis: Axis::X,
                            bit,
                            inverse: false,
                        },
                        i,
                    )
                })
                .collect()
        };
        for h in 0..239 {
            let (a, b) = (bits(h * 8), bits(h * 8 + 8));
            let differ = a.iter().zip(&b).filter(|(p, q)| p != q).count();
            assert_eq!(differ, 1, "half periods {h} and {}", h + 1);
        }
        let f = Frame::Gray {
            axis: Axis::Y,
            bit: 3,
            inverse: false,
        };
        let inv = Frame::Gray {
            axis: Axis::Y,
            bit: 3,
            inverse: true,
        };
        let (a, b) = (set.image(f), set.image(inv));
        assert!(a.data.iter().zip(&b.data).all(|(p, q)| p ^ q == 255));
        // A y frame is constant along rows.
        assert!(a.data[..1920].iter().all(|&v| v == a.data[0]));
        assert!(set.frame(set.len(), "n").is_err());
    }

    /// The longest run of equal values in an x frame.
    fn longest_run(set: &PatternSet, frame: Frame) -> usize {
        let p = set.profile(frame);
        p.chunk_by(|a, b| a == b).map(<[u8]>::len).max().unwrap()
    }

    #[test]
    fn xor_frames_are_fine_stripes_that_decode_to_the_same_positions() {
        let gray = PatternSet::new(256, 48).unwrap();
        let xor = gray.with_code(Code::Xor);
        let bits = gray.bits(Axis::X);
        let frame = |bit| Frame::Gray {
            axis: Axis::X,
            bit,
            inverse: false,
        };
        // Gray's first bit is half the image wide; every XOR frame's stripes are at most a
        // period wide, the finest bit the same in both.
        assert_eq!(longest_run(&gray, frame(0)), 128);
        for bit in 0..bits {
            assert!(longest_run(&xor, frame(bit)) <= 16, "bit {bit}");
        }
        assert_eq!(gray.profile(frame(bits - 1)), xor.profile(frame(bits - 1)));
        // Shown straight to a camera of the projector's own pixels, each sequence decodes to
        // every pixel's own position (but the border the decoder erodes), and only with its own
        // code.
        let opts = decode::DecodeOptions::default();
        let right = |d: &decode::Decoded| {
            d.samples
                .iter()
                .enumerate()
                .filter_map(|(i, s)| Some((i as u32 % d.width, i as u32 / d.width, (*s)?)))
                .filter(|(x, y, s)| (s.q[0] - f64::from(*x)).hypot(s.q[1] - f64::from(*y)) < 0.05)
                .count()
        };
        for (set, other) in [(gray, xor), (xor, gray)] {
            let frames: Vec<Grey> = set.frames().into_iter().map(|f| set.image(f)).collect();
            let decoded = decode::decode(&set, &frames, &opts).unwrap();
            let all = (256 - 4) * (48 - 4);
            assert_eq!(
                (decoded.valid(), right(&decoded)),
                (all, all),
                "{:?}",
                set.code
            );
            let wrong = decode::decode(&other, &frames, &opts).unwrap();
            assert!(
                right(&wrong) < all / 2,
                "{:?} read as {:?}: {} right",
                set.code,
                other.code,
                right(&wrong)
            );
        }
        assert_eq!("xor".parse::<Code>().unwrap(), Code::Xor);
        assert!("grey".parse::<Code>().is_err());
    }
}
