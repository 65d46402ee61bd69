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

/// Four pixels at a time, the SSSE3 kernel's arithmetic on both 128-bit halves of AVX2
/// registers: the weights of all four come from one load of their taps, and the result is one
/// 16-byte store. Doing two pixels at a time, building each pixel's weights in scalar registers
/// and storing four bytes at a time took 20–25 % longer per frame.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn span_avx2(data: &[[u8; 4]], stride: usize, taps: &[Tap], out: &mut [[u8; 4]]) {
    use std::arch::x86_64::*;
    let end = data.len().saturating_sub(stride + 1);
    let base = data.as_ptr().cast::<u8>();
    let round = _mm256_set1_epi32(1 << 13);
    // The same 16-byte shuffle in both halves.
    let lanes = |v: [i8; 16]| {
        // SAFETY: reads the 16 bytes of `v`.
        let v = unsafe { _mm_loadu_si128(v.as_ptr().cast()) };
        _mm256_set_m128i(v, v)
    };
    // Each half holds two taps (idx, fx | fy << 16 as 32-bit words): the first tap's fraction
    // word is bytes 4–7, the second's 12–15. These spread one tap's vertical weight pair over
    // all eight of its channel pairs, and its horizontal pair over all four channels.
    let wy_first = lanes([4, 5, 4, 5, 4, 5, 4, 5, 4, 5, 4, 5, 4, 5, 4, 5]);
    let wy_second = lanes([
        12, 13, 12, 13, 12, 13, 12, 13, 12, 13, 12, 13, 12, 13, 12, 13,
    ]);
    let wx_first = lanes([4, 5, 6, 7, 4, 5, 6, 7, 4, 5, 6, 7, 4, 5, 6, 7]);
    let wx_second = lanes([
        12, 13, 14, 15, 12, 13, 14, 15, 12, 13, 14, 15, 12, 13, 14, 15,
    ]);
    // Left and right column side by side per channel: l0 r0 l1 r1 l2 r2 l3 r3.
    let left_right = lanes([0, 1, 8, 9, 2, 3, 10, 11, 4, 5, 12, 13, 6, 7, 14, 15]);
    let taps = &taps[..taps.len().min(out.len())];
    let quads = taps.len() / 4;
    for q in 0..quads {
        let four = &taps[4 * q..4 * q + 4];
        let i = [0, 1, 2, 3].map(|k| four[k].idx as usize);
        if i.iter().any(|&i| i >= end) {
            // SAFETY: SSSE3 is part of AVX2.
            unsafe { span_ssse3(data, stride, four, &mut out[4 * q..4 * q + 4]) };
            continue;
        }
        // SAFETY: every i + stride + 1 lies inside `data` (checked above), so the eight 8-byte
        // texel loads are in bounds; `four` is 32 bytes of taps (`Tap` is repr(C), 8 bytes) and
        // `out` has four pixels from 4q; the rest only touches registers.
        unsafe {
            let t = _mm256_loadu_si256(four.as_ptr().cast());
            // wx = (fx + 128) >> 8 and wy = (fy + 512) >> 10 as in `weights`, then the pairs
            // (256 − wx, wx) as 16-bit words and (64 − wy, wy) as bytes.
            let fx = _mm256_and_si256(t, _mm256_set1_epi32(0xffff));
            let wx = _mm256_srli_epi32(_mm256_add_epi32(fx, _mm256_set1_epi32(128)), 8);
            let wx = _mm256_add_epi32(
                _mm256_sub_epi32(_mm256_slli_epi32(wx, 16), wx),
                _mm256_set1_epi32(256),
            );
            let fy = _mm256_srli_epi32(t, 16);
            let wy = _mm256_srli_epi32(_mm256_add_epi32(fy, _mm256_set1_epi32(512)), 10);
            let wy = _mm256_add_epi32(
                _mm256_sub_epi32(_mm256_slli_epi32(wy, 8), wy),
                _mm256_set1_epi32(64),
            );
            let row = |a: usize, b: usize| {
                let lo = _mm_loadl_epi64(base.add(4 * a).cast());
                let both = _mm_loadh_pd(_mm_castsi128_pd(lo), base.add(4 * b).cast());
                _mm_castpd_si128(both)
            };
            let top = _mm256_set_m128i(row(i[2], i[3]), row(i[0], i[1]));
            let bottom = _mm256_set_m128i(
                row(i[2] + stride, i[3] + stride),
                row(i[0] + stride, i[1] + stride),
            );
            // Each texel above the one below it: a0 c0 a1 c1 … b3 d3, pixels 0 and 2 in
            // `first`, 1 and 3 in `second`.
            let first = _mm256_unpacklo_epi8(top, bottom);
            let second = _mm256_unpackhi_epi8(top, bottom);
            let blend = |cols: __m256i, wys: __m256i, wxs: __m256i| {
                let vert = _mm256_maddubs_epi16(cols, _mm256_shuffle_epi8(wy, wys));
                let lr = _mm256_shuffle_epi8(vert, left_right);
                let v = _mm256_madd_epi16(lr, _mm256_shuffle_epi8(wx, wxs));
                _mm256_srli_epi32(_mm256_add_epi32(v, round), 14)
            };
            let v = _mm256_packs_epi32(
                blend(first, wy_first, wx_first),
                blend(second, wy_second, wx_second),
            );
            // Pixels 0 1 0 1 | 2 3 2 3, then 0 1 2 3 in the low half.
            let v = _mm256_packus_epi16(v, v);
            let v = _mm256_permute4x64_epi64::<0b1000>(v);
            _mm_storeu_si128(
                out.as_mut_ptr().add(4 * q).cast(),
                _mm256_castsi256_si128(v),
            );
        }
    }
    let done = 4 * quads;
    // SAFETY: SSSE3 is part of AVX2.
    unsafe { span_ssse3(data, stride, &taps[done..], &mut out[done..]) };
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The SIMD kernel must give exactly the portable kernel's bits.
    #[test]
    fn simd_and_portable_kernels_agree_bit_for_bit() {
        let stride = 7;
        let mut next = crate::raster::xorshift(0x2545_f491_4f6c_dd1du64);
        let data: Vec<[u8; 4]> = (0..stride * 6)
            .map(|_| next().to_le_bytes()[..4].try_into().unwrap())
            .collect();
        let mut taps: Vec<Tap> = (0..2000)
            .map(|_| {
                let r = next();
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
            // Both SIMD kernels, every remainder of four included.
            for n in (taps.len() - 3..=taps.len()).chain([1, 2, 3]) {
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
}
