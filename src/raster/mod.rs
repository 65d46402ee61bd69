//! A plain row-major image of RGBA pixels, top row first, and the two pixel types the renderer
//! works on: 8-bit ([u8; 4], values 0–255) and float ([f32; 4], nominally 0–1).

pub(crate) mod cubic;
pub mod edges;
mod kernel;
pub(crate) mod pages;

/// A seeded xorshift64 stream: the kernel tests' random texels and taps, the same every run.
#[cfg(test)]
pub(crate) fn xorshift(mut seed: u64) -> impl FnMut() -> u64 {
    move || {
        seed ^= seed << 13;
        seed ^= seed >> 7;
        seed ^= seed << 17;
        seed
    }
}

/// `n` random RGBA8 texels from a [`xorshift`] stream.
#[cfg(test)]
pub(crate) fn random_texels(next: &mut impl FnMut() -> u64, n: usize) -> Vec<[u8; 4]> {
    (0..n)
        .map(|_| next().to_le_bytes()[..4].try_into().unwrap())
        .collect()
}

use crate::error::{Error, Result};

/// One output sample of a render plan (`render::Plan`): the atlas texel at or before the sample position, and the fraction of a
/// texel beyond it in x and y, in 1/65536 (far below any filter's visible precision).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(C)]
pub struct Tap {
    /// Index into the atlas data (row-major) of the texel at or before the sample (the
    /// top-left of a bilinear 2×2; with nearest filtering, the nearest texel and zero
    /// fractions); `u32::MAX` ([`Tap::NONE`]) when the content does not cover the sample.
    pub idx: u32,
    /// Fraction of a texel to the right of `idx`, in 1/65536.
    pub fx: u16,
    /// Fraction of a texel below `idx`, in 1/65536.
    pub fy: u16,
}

impl Tap {
    /// The tap of a sample the content does not cover.
    pub const NONE: Tap = Tap {
        idx: u32::MAX,
        fx: 0,
        fy: 0,
    };
}

/// Splits a continuous atlas coordinate, known to lie in [0, 2³¹), into texel index and 16-bit
/// fraction: v rounded half up to 1/65536, as one integer.
///
/// v · 65536 + 0.5 is exact in f64 over that range (v's bits shifted, plus a bit they leave
/// free), so this is the rounding of the exact value; taking the integer part first and
/// rounding the fraction gives the same bits (tested) at twice the cost. `floor` and `round`
/// are library calls on baseline x86-64.
#[inline]
pub(crate) fn split(v: f64) -> (i64, u16) {
    let q = (v * 65536.0 + 0.5) as i64;
    (q >> 16, q as u16)
}

/// The most samples one render may plan: 2 GiB of taps.
pub const MAX_SAMPLES: u64 = 1 << 28;

/// Checks that a width × height output with k × k supersampling is one the renderer takes.
pub fn check_size(width: u32, height: u32, supersample: u32) -> Result<()> {
    if width == 0 || height == 0 || width > 32768 || height > 32768 {
        return Err(Error::invalid(
            "size",
            format!("must be between 1×1 and 32768×32768 pixels, got {width}×{height}"),
        ));
    }
    if !(1..=16).contains(&supersample) {
        return Err(Error::invalid(
            "supersample",
            format!("must be between 1 and 16, got {supersample}"),
        ));
    }
    let samples = u64::from(width) * u64::from(height) * u64::from(supersample).pow(2);
    if samples > MAX_SAMPLES {
        return Err(Error::invalid(
            "size",
            format!(
                "{width}×{height} with {supersample}×{supersample} supersampling is {samples} \
                 samples; at most {MAX_SAMPLES} fit in memory (8 bytes of plan each)"
            ),
        ));
    }
    Ok(())
}

/// A pixel the renderer can filter. Values stay in the type's own scale (0–255 for 8-bit), so
/// filtering needs no conversion beyond to and from `f32`.
pub trait Pixel: Copy + Send + Sync + Default + PartialEq + std::fmt::Debug + 'static {
    /// Full scale in the type's own units: 255 for 8-bit, 1 for float.
    const FULL: f32;
    /// The four channels R, G, B, A as `f32`, in the type's own scale (0–255 for 8-bit).
    fn to_f32(self) -> [f32; 4];
    /// Rounds and clamps where the type needs it.
    fn from_f32(v: [f32; 4]) -> Self;
    /// Bilinear blend of the 2×2 neighbourhood a b / c d at fraction (fx, fy) in 1/65536 units.
    fn bilinear(a: Self, b: Self, c: Self, d: Self, fx: u16, fy: u16) -> Self;

    /// Bilinear lookups for a run of taps into an image `stride` pixels wide; a tap that covers
    /// nothing gives the default (transparent) pixel. The hot loop of the renderer.
    fn bilinear_span(data: &[Self], stride: usize, taps: &[Tap], out: &mut [Self]) {
        bilinear_span_portable(data, stride, taps, out);
    }

    /// Bicubic (Catmull–Rom) lookups for a run of taps, the default pixel where a tap covers
    /// nothing; 8-bit pixels run a fixed-point kernel.
    fn bicubic_span(data: &[Self], stride: usize, taps: &[Tap], out: &mut [Self]) {
        for (o, t) in out.iter_mut().zip(taps) {
            *o = if t.idx == u32::MAX {
                Self::default()
            } else {
                Self::from_f32(cubic::bicubic_f32(data, stride, *t))
            };
        }
    }
}

impl Pixel for [u8; 4] {
    const FULL: f32 = 255.0;
    fn to_f32(self) -> [f32; 4] {
        self.map(f32::from)
    }

    #[inline]
    fn from_f32(v: [f32; 4]) -> Self {
        // Equal to `c.round().clamp(0.0, 255.0) as u8` for every f32 (NaN gives 0 both ways):
        // c + 0.5 is exact in f64 (not in f32, where 0.49999997 + 0.5 rounds up to 1), and
        // truncation of a non-negative number is floor. `round` is a library call on baseline
        // x86-64 and was a third of a preview's time.
        v.map(|c| (f64::from(c.clamp(0.0, 255.0)) + 0.5) as u8)
    }

    #[inline(always)]
    fn bilinear(a: Self, b: Self, c: Self, d: Self, fx: u16, fy: u16) -> Self {
        kernel::bilinear_rgba8(a, b, c, d, fx, fy)
    }

    fn bilinear_span(data: &[Self], stride: usize, taps: &[Tap], out: &mut [Self]) {
        kernel::bilinear_span_rgba8(data, stride, taps, out);
    }

    fn bicubic_span(data: &[Self], stride: usize, taps: &[Tap], out: &mut [Self]) {
        cubic::bicubic_span_rgba8(data, stride, taps, out);
    }
}

impl Pixel for [f32; 4] {
    const FULL: f32 = 1.0;
    fn to_f32(self) -> [f32; 4] {
        self
    }

    fn from_f32(v: [f32; 4]) -> Self {
        v
    }

    #[inline(always)]
    fn bilinear(a: Self, b: Self, c: Self, d: Self, fx: u16, fy: u16) -> Self {
        let wx = f32::from(fx) / 65536.0;
        let wy = f32::from(fy) / 65536.0;
        std::array::from_fn(|k| {
            let top = a[k] + (b[k] - a[k]) * wx;
            let bottom = c[k] + (d[k] - c[k]) * wx;
            top + (bottom - top) * wy
        })
    }
}

/// [`Pixel::bilinear_span`] through [`Pixel::bilinear`], one tap at a time.
pub(crate) fn bilinear_span_portable<T: Pixel>(
    data: &[T],
    stride: usize,
    taps: &[Tap],
    out: &mut [T],
) {
    for (o, t) in out.iter_mut().zip(taps) {
        *o = if t.idx == Tap::NONE.idx {
            T::default()
        } else {
            let i = t.idx as usize;
            T::bilinear(
                data[i],
                data[i + 1],
                data[i + stride],
                data[i + stride + 1],
                t.fx,
                t.fy,
            )
        };
    }
}

/// A width × height image, row-major, top row first.
#[derive(Debug, Clone, PartialEq)]
pub struct Raster<T> {
    /// Pixels across.
    pub width: usize,
    /// Pixels down.
    pub height: usize,
    /// The `width` × `height` pixels, row-major, top row first: (x, y) is at `y * width + x`.
    pub data: Vec<T>,
}

impl<T: Pixel> Raster<T> {
    /// A `width` × `height` image of default pixels (transparent black).
    pub fn new(width: usize, height: usize) -> Self {
        Raster {
            width,
            height,
            data: vec![T::default(); width * height],
        }
    }

    /// A `width` × `height` image whose pixel (x, y) is `f(x, y)`, called row by row from the
    /// top.
    pub fn from_fn(width: usize, height: usize, mut f: impl FnMut(usize, usize) -> T) -> Self {
        let mut data = Vec::with_capacity(width * height);
        for y in 0..height {
            for x in 0..width {
                data.push(f(x, y));
            }
        }
        Raster {
            width,
            height,
            data,
        }
    }

    /// The pixel at column `x`, row `y` (0 is the top row); `x` must be below `width`.
    #[inline]
    pub fn get(&self, x: usize, y: usize) -> T {
        self.data[y * self.width + x]
    }

    /// The `w` × `h` block whose top-left pixel is (x0, y0).
    pub fn crop(&self, x0: usize, y0: usize, w: usize, h: usize) -> Self {
        Raster::from_fn(w, h, |x, y| self.get(x0 + x, y0 + y))
    }

    /// Copies `src` into this image with its top-left pixel at (x0, y0).
    pub fn paste(&mut self, src: &Raster<T>, x0: usize, y0: usize) {
        for y in 0..src.height {
            let row = &src.data[y * src.width..(y + 1) * src.width];
            let at = (y0 + y) * self.width + x0;
            self.data[at..at + src.width].copy_from_slice(row);
        }
    }

    /// Mirrored left–right (`horizontal`) or top–bottom.
    pub fn flipped(&self, horizontal: bool) -> Self {
        let (w, h) = (self.width, self.height);
        Raster::from_fn(w, h, |x, y| {
            if horizontal {
                self.get(w - 1 - x, y)
            } else {
                self.get(x, h - 1 - y)
            }
        })
    }

    /// This image with `f` applied to every pixel, e.g. to convert the pixel type.
    pub fn map<U: Pixel>(&self, f: impl Fn(T) -> U) -> Raster<U> {
        Raster {
            width: self.width,
            height: self.height,
            data: self.data.iter().map(|&p| f(p)).collect(),
        }
    }
}

/// Peak signal-to-noise ratio in dB over the RGB channels of the pixels where `mask` holds,
/// with `peak` the largest value (255 for 8-bit). Infinite for identical images.
///
/// Panics when the mask selects no pixel: "no difference over nothing" would otherwise read
/// as a perfect score, and a render that lost all its coverage would pass every comparison.
/// Callers should also check how much the mask covers ([`fraction`]).
pub fn psnr<T: Pixel>(
    a: &Raster<T>,
    b: &Raster<T>,
    peak: f64,
    mask: impl Fn(usize, usize) -> bool,
) -> f64 {
    assert_eq!(
        (a.width, a.height),
        (b.width, b.height),
        "psnr of images of different sizes"
    );
    let (mut sum, mut n) = (0.0f64, 0usize);
    for y in 0..a.height {
        for x in 0..a.width {
            if !mask(x, y) {
                continue;
            }
            let (p, q) = (a.get(x, y).to_f32(), b.get(x, y).to_f32());
            for k in 0..3 {
                let e = f64::from(p[k]) - f64::from(q[k]);
                sum += e * e;
            }
            n += 3;
        }
    }
    assert!(n > 0, "psnr over an empty mask: no pixel to compare");
    let mse = sum / n as f64;
    10.0 * (peak * peak / mse).log10()
}

/// The fraction of a width × height image's pixels where `mask` holds.
pub fn fraction(width: usize, height: usize, mask: impl Fn(usize, usize) -> bool) -> f64 {
    let n = (0..height)
        .flat_map(|y| (0..width).map(move |x| (x, y)))
        .filter(|&(x, y)| mask(x, y))
        .count();
    n as f64 / (width * height).max(1) as f64
}

#[cfg(test)]
mod tests {
    use super::{Pixel, split};

    /// `from_f32` avoids `round`; it must still round exactly as `round` does, at every half
    /// and the floats on either side of it, at the clamps, and for NaN.
    #[test]
    fn split_carries_a_fraction_that_rounds_up() {
        assert_eq!(split(2.999_999_999), (3, 0));
        assert_eq!(split(0.5), (0, 32768));
        assert_eq!(split(7.25), (7, 16384));
        // Against the integer part and the rounded fraction taken apart, at every half step of
        // 1/65536 and the floats on either side of it, across the whole range, and at random.
        let apart = |v: f64| {
            let base = v as u32;
            let q = ((v - f64::from(base)) * 65536.0 + 0.5) as u32;
            if q >= 65536 {
                (i64::from(base) + 1, 0)
            } else {
                (i64::from(base), q as u16)
            }
        };
        let mut next = super::xorshift(0x9e37_79b9_7f4a_7c15);
        let mut values = vec![0.0, f64::MIN_POSITIVE, 0.5 / 65536.0, 2147483647.99];
        for e in -20..31 {
            for _ in 0..2000 {
                let m = (next() >> 11) as f64 / (1u64 << 53) as f64;
                let v = (1.0 + m) * 2f64.powi(e);
                let half = ((v * 65536.0).floor() + 0.5) / 65536.0;
                values.extend([v, half, half.next_up(), half.next_down()]);
            }
        }
        for v in values
            .into_iter()
            .filter(|v| (0.0..2147483648.0).contains(v))
        {
            assert_eq!(split(v), apart(v), "{v:e}");
        }
    }

    #[test]
    fn eight_bit_conversion_rounds_as_round_does() {
        let reference = |c: f32| c.round().clamp(0.0, 255.0) as u8;
        let mut values = vec![f32::NAN, f32::INFINITY, f32::NEG_INFINITY, -0.0, 1e-45];
        for k in -2..=258 {
            for base in [k as f32, k as f32 + 0.5] {
                let mut v = base;
                for _ in 0..4 {
                    values.push(v);
                    v = f32::from_bits(v.to_bits() + 1);
                }
                let mut v = base;
                for _ in 0..4 {
                    values.push(v);
                    v = f32::from_bits(v.to_bits().wrapping_sub(1));
                }
            }
        }
        values.extend((0..2_000_000).map(|n| n as f32 * 1.3e-4 - 1.0));
        for c in values {
            assert_eq!(
                <[u8; 4]>::from_f32([c; 4]),
                [reference(c); 4],
                "{c:e} ({:#x})",
                c.to_bits()
            );
        }
    }
}
