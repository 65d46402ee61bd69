//! The bicubic (Catmull–Rom, Keys' a = −0.5) lookup: in float for any pixel type, and in fixed
//! point for 8-bit pixels, the renderer's bicubic frame loop.
//!
//! Fixed point: the fraction is taken to 1/256 texel (a position error of at most 1/512 texel)
//! and the weights to 1/4096, summing to exactly 4096 at every fraction so a flat area stays
//! flat. The horizontal pass keeps 8 fractional bits, the vertical pass rounds once. Against the
//! float lookup of the same texels the result differs by at most one level (a test checks). An
//! AVX2 twin computes the same bits, two texels of a row per multiply.

use super::{Pixel, Tap};
use std::sync::OnceLock;

/// Keys' cubic convolution weights (a = −0.5) for taps at −1, 0, 1, 2 around fraction t.
#[inline]
pub(crate) fn catmull_rom(t: f32) -> [f32; 4] {
    let (t2, t3) = (t * t, t * t * t);
    [
        -0.5 * t3 + t2 - 0.5 * t,
        1.5 * t3 - 2.5 * t2 + 1.0,
        -1.5 * t3 + 2.0 * t2 + 0.5 * t,
        0.5 * t3 - 0.5 * t2,
    ]
}

/// The 4×4 block around tap `t` (texels −1..=2 both ways), weighted in float.
#[inline]
pub(crate) fn bicubic_f32<T: Pixel>(data: &[T], stride: usize, t: Tap) -> [f32; 4] {
    let wx = catmull_rom(f32::from(t.fx) / 65536.0);
    let wy = catmull_rom(f32::from(t.fy) / 65536.0);
    let mut acc = [0.0f32; 4];
    for (r, wyr) in wy.iter().enumerate() {
        let base = t.idx as usize + r * stride - stride - 1;
        for (c, wxc) in wx.iter().enumerate() {
            let v = data[base + c].to_f32();
            let wgt = wyr * wxc;
            for (a, x) in acc.iter_mut().zip(v) {
                *a += wgt * x;
            }
        }
    }
    acc
}

const WEIGHT: i32 = 4096;

/// Fixed-point weights at fractions 0, 1/256, …, 256/256, each row summing to [`WEIGHT`].
fn table() -> &'static [[i32; 4]; 257] {
    static TABLE: OnceLock<[[i32; 4]; 257]> = OnceLock::new();
    TABLE.get_or_init(|| {
        std::array::from_fn(|i| {
            let w = catmull_rom(i as f32 / 256.0).map(|x| (x * WEIGHT as f32).round() as i32);
            // Rounding can leave the sum a unit off: the largest weight takes the difference.
            let mut w = w;
            let big = (0..4).max_by_key(|&k| w[k]).unwrap_or(1);
            w[big] += WEIGHT - w.iter().sum::<i32>();
            w
        })
    })
}

/// Bicubic lookup of 8-bit pixels around tap `t` in fixed point.
#[inline]
pub(crate) fn bicubic_rgba8(data: &[[u8; 4]], stride: usize, t: Tap) -> [u8; 4] {
    let table = table();
    let step = |f: u16| ((u32::from(f) + 128) >> 8) as usize;
    let (wx, wy) = (table[step(t.fx)], table[step(t.fy)]);
    let base = t.idx as usize - stride - 1;
    let mut acc = [0i32; 4];
    for (r, wyr) in wy.iter().enumerate() {
        let row = &data[base + r * stride..base + r * stride + 4];
        let mut h = [0i32; 4];
        for (texel, wxc) in row.iter().zip(wx) {
            for k in 0..4 {
                h[k] += wxc * i32::from(texel[k]);
            }
        }
        // |h| < 1.25 · 255 · 4096: kept to 8 fractional bits, times a weight, summed over four
        // rows, it stays within i32.
        for k in 0..4 {
            acc[k] += wyr * ((h[k] + 8) >> 4);
        }
    }
    acc.map(|a| ((a + (1 << 19)) >> 20).clamp(0, 255) as u8)
}

/// [`bicubic_rgba8`] for a run of taps (a tap that covers nothing gives a transparent pixel):
/// AVX2 where the processor has it, the scalar kernel elsewhere.
pub(crate) fn bicubic_span_rgba8(
    data: &[[u8; 4]],
    stride: usize,
    taps: &[Tap],
    out: &mut [[u8; 4]],
) {
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") {
        // SAFETY: the processor supports AVX2, checked just above.
        unsafe { span_avx2(data, stride, taps, out) };
        return;
    }
    span_scalar(data, stride, taps, out);
}

fn span_scalar(data: &[[u8; 4]], stride: usize, taps: &[Tap], out: &mut [[u8; 4]]) {
    for (o, t) in out.iter_mut().zip(taps) {
        *o = if t.idx == u32::MAX {
            [0; 4]
        } else {
            bicubic_rgba8(data, stride, *t)
        };
    }
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn span_avx2(data: &[[u8; 4]], stride: usize, taps: &[Tap], out: &mut [[u8; 4]]) {
    use std::arch::x86_64::*;
    let table = table();
    let step = |f: u16| ((u32::from(f) + 128) >> 8) as usize;
    for (o, t) in out.iter_mut().zip(taps) {
        if t.idx == u32::MAX {
            *o = [0; 4];
            continue;
        }
        let (wx, wy) = (table[step(t.fx)], table[step(t.fy)]);
        let base = t.idx as usize - stride - 1;
        // The 4×4 block, bounds-checked once; each row's four texels are 16 contiguous bytes.
        let block = &data[base..base + 3 * stride + 4];
        // Lanes 0–3 weigh texel 0 (then 2), lanes 4–7 texel 1 (then 3).
        let w01 = _mm256_setr_epi32(wx[0], wx[0], wx[0], wx[0], wx[1], wx[1], wx[1], wx[1]);
        let w23 = _mm256_setr_epi32(wx[2], wx[2], wx[2], wx[2], wx[3], wx[3], wx[3], wx[3]);
        let mut acc = _mm_setzero_si128();
        for (r, wyr) in wy.iter().enumerate() {
            let row = &block[r * stride..r * stride + 4];
            // SAFETY: `row` is four [u8; 4] texels, 16 bytes; an unaligned load reads them.
            let bytes = unsafe { _mm_loadu_si128(row.as_ptr().cast()) };
            let t01 = _mm256_cvtepu8_epi32(bytes);
            let t23 = _mm256_cvtepu8_epi32(_mm_srli_si128::<8>(bytes));
            let sum = _mm256_add_epi32(_mm256_mullo_epi32(t01, w01), _mm256_mullo_epi32(t23, w23));
            let h = _mm_add_epi32(
                _mm256_castsi256_si128(sum),
                _mm256_extracti128_si256::<1>(sum),
            );
            let h = _mm_srai_epi32::<4>(_mm_add_epi32(h, _mm_set1_epi32(8)));
            acc = _mm_add_epi32(acc, _mm_mullo_epi32(h, _mm_set1_epi32(*wyr)));
        }
        let v = _mm_srai_epi32::<20>(_mm_add_epi32(acc, _mm_set1_epi32(1 << 19)));
        // Saturating packs clamp to 0..=255 as the scalar kernel does.
        let px = _mm_packus_epi16(_mm_packs_epi32(v, v), _mm_setzero_si128());
        *o = _mm_cvtsi128_si32(px).to_le_bytes();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn catmull_rom_weights_sum_to_one_and_interpolate() {
        for t in [0.0, 0.25, 0.5, 0.9] {
            let w = catmull_rom(t);
            assert!((w.iter().sum::<f32>() - 1.0).abs() < 1e-6);
        }
        assert_eq!(catmull_rom(0.0), [0.0, 1.0, 0.0, 0.0]);
        assert!(table().iter().all(|w| w.iter().sum::<i32>() == WEIGHT));
        assert_eq!(table()[256], [0, 0, WEIGHT, 0]);
    }

    /// Against the float lookup of the same texels, on random content and fractions: never
    /// more than one level apart, and exact on flat content.
    #[test]
    fn fixed_point_stays_within_a_level_of_float() {
        let (w, h) = (16usize, 16usize);
        let mut next = crate::raster::xorshift(0x2545_f491_4f6c_dd1du64);
        let data: Vec<[u8; 4]> = (0..w * h)
            .map(|_| std::array::from_fn(|_| next() as u8))
            .collect();
        let flat = vec![[7u8, 100, 200, 255]; w * h];
        let mut worst = 0i32;
        for _ in 0..20_000 {
            let (x, y) = (1 + next() as usize % (w - 3), 1 + next() as usize % (h - 3));
            let t = Tap {
                idx: (y * w + x) as u32,
                fx: next() as u16,
                fy: next() as u16,
            };
            let exact = <[u8; 4]>::from_f32(bicubic_f32(&data, w, t));
            let got = bicubic_rgba8(&data, w, t);
            for k in 0..4 {
                worst = worst.max((i32::from(got[k]) - i32::from(exact[k])).abs());
            }
            assert_eq!(bicubic_rgba8(&flat, w, t), flat[0]);
        }
        assert!(worst <= 1, "{worst} levels apart");
    }

    /// The AVX2 kernel gives exactly the scalar kernel's bits.
    #[test]
    fn simd_and_scalar_bicubic_agree_bit_for_bit() {
        let stride = 9;
        let mut next = crate::raster::xorshift(0x9e37_79b9_7f4a_7c15u64);
        let data = crate::raster::random_texels(&mut next, stride * 8);
        let mut taps: Vec<Tap> = (0..5000)
            .map(|_| {
                let r = next();
                let (x, y) = (1 + r as usize % (stride - 3), 1 + (r >> 8) as usize % 5);
                Tap {
                    idx: (y * stride + x) as u32,
                    fx: (r >> 20) as u16,
                    fy: (r >> 40) as u16,
                }
            })
            .collect();
        taps.push(Tap::NONE);
        let mut fast = vec![[9u8; 4]; taps.len()];
        let mut slow = vec![[7u8; 4]; taps.len()];
        bicubic_span_rgba8(&data, stride, &taps, &mut fast);
        span_scalar(&data, stride, &taps, &mut slow);
        assert_eq!(fast, slow);
    }
}
