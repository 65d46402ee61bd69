//! A plain row-major image of RGBA pixels, top row first, and the two pixel types the renderer
//! works on: 8-bit ([u8; 4], values 0–255) and float ([f32; 4], nominally 0–1).

use crate::render::Tap;

/// A pixel the renderer can filter. Values stay in the type's own scale (0–255 for 8-bit), so
/// filtering needs no conversion beyond to and from `f32`.
pub trait Pixel: Copy + Send + Sync + Default + PartialEq + std::fmt::Debug + 'static {
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
}

impl Pixel for [u8; 4] {
    fn to_f32(self) -> [f32; 4] {
        self.map(f32::from)
    }

    fn from_f32(v: [f32; 4]) -> Self {
        v.map(|c| c.round().clamp(0.0, 255.0) as u8)
    }

    #[inline(always)]
    fn bilinear(a: Self, b: Self, c: Self, d: Self, fx: u16, fy: u16) -> Self {
        crate::render::kernel::bilinear_rgba8(a, b, c, d, fx, fy)
    }

    fn bilinear_span(data: &[Self], stride: usize, taps: &[Tap], out: &mut [Self]) {
        crate::render::kernel::bilinear_span_rgba8(data, stride, taps, out);
    }
}

impl Pixel for [f32; 4] {
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
    pub width: usize,
    pub height: usize,
    pub data: Vec<T>,
}

impl<T: Pixel> Raster<T> {
    pub fn new(width: usize, height: usize) -> Self {
        Raster {
            width,
            height,
            data: vec![T::default(); width * height],
        }
    }

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
    let mse = sum / n.max(1) as f64;
    10.0 * (peak * peak / mse).log10()
}
