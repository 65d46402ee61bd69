//! The 8-bit bilinear kernel, the renderer's hot loop, in a portable form and an SSSE3 form
//! that computes the same bits.
//!
//! Fixed point: the vertical blend uses 6-bit weights (0..=64) and the horizontal one 8-bit
//! weights (0..=256), so the first fits the unsigned-by-signed byte multiply-add of SSSE3 and
//! the second a 16-bit multiply-add; the result is rounded once. A weight step of 1/64 texel
//! moves the result by at most 1/128 of the difference between two neighbouring texels, far
//! below what 8-bit output resolves (and the PSNR against the exact reference shows it: the
//! benchmark prints it).

use super::Tap;

#[inline(always)]
fn weights(fx: u16, fy: u16) -> (i32, i32) {
    ((i32::from(fx) + 128) >> 8, (i32::from(fy) + 512) >> 10)
}

/// Bilinear blend of a b / c d at fraction (fx, fy) in 1/65536 of a texel.
#[inline(always)]
pub(crate) fn bilinear_rgba8(
    a: [u8; 4],
    b: [u8; 4],
    c: [u8; 4],
    d: [u8; 4],
    fx: u16,
    fy: u16,
) -> [u8; 4] {
    let (wx, wy) = weights(fx, fy);
    std::array::from_fn(|k| {
        let left = i32::from(a[k]) * (64 - wy) + i32::from(c[k]) * wy;
        let right = i32::from(b[k]) * (64 - wy) + i32::from(d[k]) * wy;
        ((left * (256 - wx) + right * wx + (1 << 13)) >> 14) as u8
    })
}

/// [`crate::raster::Pixel::bilinear_span`] for RGBA8: SSSE3 where the processor has it (nearly
/// every x86-64 made since 2006), the portable kernel elsewhere.
pub(crate) fn bilinear_span_rgba8(
    data: &[[u8; 4]],
    stride: usize,
    taps: &[Tap],
    out: &mut [[u8; 4]],
) {
    #[cfg(target_arch = "x86_64")]
    {
        if std::arch::is_x86_feature_detected!("avx2") {
            // SAFETY: the processor supports AVX2 (and so SSSE3), checked just above.
            unsafe { span_avx2(data, stride, taps, out) };
            return;
        }
        if std::arch::is_x86_feature_detected!("ssse3") {
            // SAFETY: the processor supports SSSE3, checked just above.
            unsafe { span_ssse3(data, stride, taps, out) };
            return;
        }
    }
    span_portable(data, stride, taps, out);
}

fn span_portable(data: &[[u8; 4]], stride: usize, taps: &[Tap], out: &mut [[u8; 4]]) {
    super::bilinear_span_portable(data, stride, taps, out);
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "ssse3")]
unsafe fn span_ssse3(data: &[[u8; 4]], stride: usize, taps: &[Tap], out: &mut [[u8; 4]]) {
    use std::arch::x86_64::*;
    // Taps at or past this index would read beyond the image; a plan never holds one (it is
    // built for this image's size), so the check only keeps a misuse from reading out of bounds.
    let end = data.len().saturating_sub(stride + 1);
    let base = data.as_ptr().cast::<u8>();
    let round = _mm_set1_epi32(1 << 13);
    let zero = _mm_setzero_si128();
    for (o, t) in out.iter_mut().zip(taps) {
        let i = t.idx as usize;
        if i >= end {
            *o = [0; 4];
            continue;
        }
        let (wx, wy) = weights(t.fx, t.fy);
        // SAFETY: i + stride + 1 < data.len(), so both 8-byte loads (two texels each) lie inside
        // `data`; the rest only touches registers.
        let v = unsafe {
            let top = _mm_loadl_epi64(base.add(4 * i).cast());
            let bottom = _mm_loadl_epi64(base.add(4 * (i + stride)).cast());
            // a0 c0 a1 c1 a2 c2 a3 c3 b0 d0 … b3 d3: each texel above the one below it.
            let cols = _mm_unpacklo_epi8(top, bottom);
            let wyv = _mm_set1_epi16(((wy << 8) | (64 - wy)) as i16);
            let vert = _mm_maddubs_epi16(cols, wyv);
            // Left and right column side by side per channel, then the horizontal blend.
            let lr = _mm_unpacklo_epi16(vert, _mm_srli_si128(vert, 8));
            let wxv = _mm_set1_epi32((wx << 16) | (256 - wx));
            let v = _mm_srli_epi32(_mm_add_epi32(_mm_madd_epi16(lr, wxv), round), 14);
            _mm_packus_epi16(_mm_packs_epi32(v, v), zero)
        };
        *o = (_mm_cvtsi128_si32(v) as u32).to_le_bytes();
    }
}

/// Eight pixels at a time, in two steps of four that each fill both 128-bit halves of AVX2
/// registers; the same bits as the SSSE3 kernel, in fewer instructions, which the frame waits
/// on: with the content in cache a 4K frame took 15 % less time than with the earlier four-pixel
/// kernel, and with 2048² faces, from memory, 6–10 % less (six paired runs, 2026-12-04).
///
/// Per four pixels: the weights come from one load of their taps (six instructions where
/// shifts and masks took twelve); each pixel's four texels are two 8-byte loads, the lower row
/// addressed from its own base pointer, and one byte shuffle then leaves every texel above the
/// one below it with the left column's pair before the right's, so the vertical multiply-add
/// already gives what the horizontal one reads. The rounding of the horizontal blend is split
/// around the pack to 16 bits, and eight pixels share the pack to bytes and one store.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn span_avx2(data: &[[u8; 4]], stride: usize, taps: &[Tap], out: &mut [[u8; 4]]) {
    use std::arch::x86_64::*;
    let end = data.len().saturating_sub(stride + 1);
    let base = data.as_ptr().cast::<u8>();
    // Only dereferenced at a tap that passed the check against `end`.
    let below = base.wrapping_add(4 * stride);
    // The same 16-byte shuffle in both halves.
    let lanes = |v: [i8; 16]| {
        // SAFETY: reads the 16 bytes of `v`.
        let v = unsafe { _mm_loadu_si128(v.as_ptr().cast()) };
        _mm256_set_m128i(v, v)
    };
    // Each half holds two taps, four 16-bit words each: idx (two words), fx, fy. The weight
    // words below sit where fx and fy were. The first tap's vertical pair is bytes 6–7 and its
    // horizontal pair bytes 4–7, the second tap's 14–15 and 12–15; these spread a pair over
    // all of one pixel's channels. LLVM turns a constant shuffle that repeats one word into two
    // shuffles (a word shuffle, then a dword one), one more per step than the single byte
    // shuffle: black_box keeps the byte shuffle (8 px a step: faster in 4 of 5 paired runs).
    let wy_first = lanes(std::hint::black_box([
        6, 7, 6, 7, 6, 7, 6, 7, 6, 7, 6, 7, 6, 7, 6, 7,
    ]));
    let wy_second = lanes(std::hint::black_box([
        14, 15, 14, 15, 14, 15, 14, 15, 14, 15, 14, 15, 14, 15, 14, 15,
    ]));
    let wx_first = lanes([4, 5, 6, 7, 4, 5, 6, 7, 4, 5, 6, 7, 4, 5, 6, 7]);
    let wx_second = lanes([
        12, 13, 14, 15, 12, 13, 14, 15, 12, 13, 14, 15, 12, 13, 14, 15,
    ]);
    // A pixel's texels loaded as a b (top row) c d (bottom row), 4 bytes each, to
    // a0 c0 b0 d0 a1 c1 b1 d1 …: the vertical multiply-add then leaves l0 r0 l1 r1 … l3 r3.
    let pairs = lanes([0, 8, 4, 12, 1, 9, 5, 13, 2, 10, 6, 14, 3, 11, 7, 15]);
    // Per tap, as words over (idx, idx, fx, fy); the idx words' results are never read.
    let per_tap = |fx: i64, fy: i64| _mm256_set1_epi64x((fy << 48) | (fx << 32));
    // wx = (fx + 128) >> 8 and wy = (fy + 512) >> 10, as in `weights`, without overflowing 16
    // bits: the rounding average (a + b + 1) >> 1 halves first, so (fx + 128) >> 8 is
    // avg(fx, 127) >> 7 and (fy + 512) >> 10 is avg(fy, 511) >> 9; the two shifts are one
    // unsigned high multiply, by 2⁹ and by 2⁷.
    let halves = per_tap(127, 511);
    let shifts = per_tap(1 << 9, 1 << 7);
    // Then 256 − wx, and the byte pair (64 − wy, wy) as the word wy · 255 + 64.
    let scale = per_tap(0xffff, 255);
    let offset = per_tap(256, 64);
    let zero = _mm256_setzero_si256();
    // Four pixels' values as 16-bit words, pixels 0 1 | 2 3, for taps whose indices passed
    // the check against `end`.
    let four_pixels = |four: &[Tap]| {
        let i = [0, 1, 2, 3].map(|k| four[k].idx as usize);
        // SAFETY: every i + stride + 1 lies inside `data` (the caller checked), so the eight
        // 8-byte texel loads are in bounds; `four` is 32 bytes of taps (`Tap` is repr(C),
        // 8 bytes); the rest only touches registers.
        unsafe {
            let t = _mm256_loadu_si256(four.as_ptr().cast());
            let w = _mm256_mulhi_epu16(_mm256_avg_epu16(t, halves), shifts);
            let wy = _mm256_add_epi16(_mm256_mullo_epi16(w, scale), offset);
            // (256 − wx, wx) as the two words of the dword that held (fx, fy).
            let wx = _mm256_blend_epi16::<0b1010_1010>(wy, _mm256_slli_epi32(w, 16));
            let texels = |i: usize| {
                let top = _mm_loadl_epi64(base.add(4 * i).cast());
                let both = _mm_loadh_pd(_mm_castsi128_pd(top), below.add(4 * i).cast());
                _mm_castpd_si128(both)
            };
            // Pixels 0 and 2 in `first`, 1 and 3 in `second`, matching the halves of `t`.
            let first = _mm256_shuffle_epi8(_mm256_set_m128i(texels(i[2]), texels(i[0])), pairs);
            let second = _mm256_shuffle_epi8(_mm256_set_m128i(texels(i[3]), texels(i[1])), pairs);
            // (v + 2¹³) >> 14 is ((v >> 13) + 1) >> 1: the shift here, the rest (an average
            // with zero) after the pack, on half as many registers.
            let blend = |cols: __m256i, wys: __m256i, wxs: __m256i| {
                let lr = _mm256_maddubs_epi16(cols, _mm256_shuffle_epi8(wy, wys));
                let v = _mm256_madd_epi16(lr, _mm256_shuffle_epi8(wx, wxs));
                _mm256_srli_epi32(v, 13)
            };
            let v = _mm256_packs_epi32(
                blend(first, wy_first, wx_first),
                blend(second, wy_second, wx_second),
            );
            _mm256_avg_epu16(v, zero)
        }
    };
    let covered = |taps: &[Tap]| taps.iter().all(|t| (t.idx as usize) < end);
    let taps = &taps[..taps.len().min(out.len())];
    let mut k = 0;
    while k + 8 <= taps.len() {
        let eight = &taps[k..k + 8];
        if covered(eight) {
            // SAFETY: `out` has eight pixels from k; the rest only touches registers.
            unsafe {
                // Pixels 0 1 4 5 | 2 3 6 7, then in order.
                let v = _mm256_packus_epi16(four_pixels(&eight[..4]), four_pixels(&eight[4..]));
                let v = _mm256_permute4x64_epi64::<0b11_01_10_00>(v);
                _mm256_storeu_si256(out.as_mut_ptr().add(k).cast(), v);
            }
        } else {
            // SAFETY: SSSE3 is part of AVX2.
            unsafe { span_ssse3(data, stride, eight, &mut out[k..k + 8]) };
        }
        k += 8;
    }
    if k + 4 <= taps.len() && covered(&taps[k..k + 4]) {
        // SAFETY: `out` has four pixels from k; the rest only touches registers.
        unsafe {
            let v = four_pixels(&taps[k..k + 4]);
            // Pixels 0 1 0 1 | 2 3 2 3, then 0 1 2 3 in the low half.
            let v = _mm256_permute4x64_epi64::<0b1000>(_mm256_packus_epi16(v, v));
            _mm_storeu_si128(out.as_mut_ptr().add(k).cast(), _mm256_castsi256_si128(v));
        }
        k += 4;
    }
    // SAFETY: SSSE3 is part of AVX2.
    unsafe { span_ssse3(data, stride, &taps[k..], &mut out[k..]) };
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The SIMD kernel must give exactly the portable kernel's bits.
    #[test]
    fn simd_and_portable_kernels_agree_bit_for_bit() {
        let stride = 7;
        let mut next = crate::raster::xorshift(0x2545_f491_4f6c_dd1du64);
        let data = crate::raster::random_texels(&mut next, stride * 6);
        // One tap in about seventeen covers nothing, so that some groups of four and of
        // eight the AVX2 kernel takes whole hold one and must go the careful way.
        let mut taps: Vec<Tap> = (0..2000)
            .map(|_| {
                let r = next();
                if r.is_multiple_of(17) {
                    return Tap::NONE;
                }
                Tap {
                    idx: (r % (stride as u64 * 5 - 1)) as u32,
                    fx: (r >> 20) as u16,
                    fy: (r >> 40) as u16,
                }
            })
            .collect();
        taps.extend([
            Tap::NONE,
            Tap {
                idx: 0,
                fx: 0,
                fy: 0,
            },
            Tap {
                idx: 3,
                fx: u16::MAX,
                fy: u16::MAX,
            },
        ]);
        let mut fast = vec![[9u8; 4]; taps.len()];
        let mut slow = vec![[7u8; 4]; taps.len()];
        bilinear_span_rgba8(&data, stride, &taps, &mut fast);
        span_portable(&data, stride, &taps, &mut slow);
        assert_eq!(fast, slow);
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx2") {
            // Both SIMD kernels, every remainder of eight included.
            for n in (taps.len() - 7..=taps.len()).chain(1..8) {
                let (mut a, mut b) = (vec![[1u8; 4]; n], vec![[2u8; 4]; n]);
                // SAFETY: the processor supports AVX2 and SSSE3, checked just above.
                unsafe {
                    span_avx2(&data, stride, &taps[..n], &mut a);
                    span_ssse3(&data, stride, &taps[..n], &mut b);
                }
                assert_eq!(a, slow[..n]);
                assert_eq!(b, slow[..n]);
            }
        }
        // Corners reproduce the texels exactly.
        assert_eq!(slow[taps.len() - 2], data[0]);
        assert_eq!(slow[taps.len() - 1], data[3 + stride + 1]);
    }

    /// The SIMD kernels derive the weights from the fractions in their own ways (the AVX2 one
    /// through averages and a high multiply): every value of fx and of fy, each once, must give
    /// the portable kernel's bits.
    #[test]
    fn every_fraction_weighs_as_in_the_portable_kernel() {
        let stride = 16;
        let mut next = crate::raster::xorshift(0x9e37_79b9_7f4a_7c15u64);
        let data = crate::raster::random_texels(&mut next, stride * 8);
        // fy runs through every value too, in another order (40503 is odd, so k ↦ 40503·k
        // permutes the 16-bit numbers).
        let taps: Vec<Tap> = (0..=u16::MAX)
            .map(|k| Tap {
                idx: (next() % (stride as u64 * 6)) as u32,
                fx: k,
                fy: k.wrapping_mul(40503),
            })
            .collect();
        let mut fast = vec![[9u8; 4]; taps.len()];
        let mut slow = vec![[7u8; 4]; taps.len()];
        bilinear_span_rgba8(&data, stride, &taps, &mut fast);
        span_portable(&data, stride, &taps, &mut slow);
        let first = fast.iter().zip(&slow).position(|(a, b)| a != b);
        assert_eq!(first.map(|k| (taps[k], fast[k], slow[k])), None);
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("ssse3") {
            // SAFETY: the processor supports SSSE3, checked just above.
            unsafe { span_ssse3(&data, stride, &taps, &mut fast) };
            assert!(
                fast == slow,
                "the SSSE3 kernel weighs some fraction otherwise"
            );
        }
    }
}
