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

/// Two pixels at a time: the SSSE3 kernel's steps on both 128-bit halves of AVX2 registers.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn span_avx2(data: &[[u8; 4]], stride: usize, taps: &[Tap], out: &mut [[u8; 4]]) {
    use std::arch::x86_64::*;
    let end = data.len().saturating_sub(stride + 1);
    let base = data.as_ptr().cast::<u8>();
    let round = _mm256_set1_epi32(1 << 13);
    let pairs = taps.len() / 2;
    for p in 0..pairs {
        let (t0, t1) = (taps[2 * p], taps[2 * p + 1]);
        let (i0, i1) = (t0.idx as usize, t1.idx as usize);
        if i0 >= end || i1 >= end {
            // SAFETY: SSSE3 is part of AVX2.
            unsafe {
                span_ssse3(
                    data,
                    stride,
                    &taps[2 * p..2 * p + 2],
                    &mut out[2 * p..2 * p + 2],
                )
            };
            continue;
        }
        let (wx0, wy0) = weights(t0.fx, t0.fy);
        let (wx1, wy1) = weights(t1.fx, t1.fy);
        let wy = |w: i32| {
            let h = (w << 8) | (64 - w);
            h | (h << 16)
        };
        let wx = |w: i32| (w << 16) | (256 - w);
        // SAFETY: i0 and i1 + stride + 1 lie inside `data` (checked above), so the four 8-byte
        // loads are in bounds; the rest only touches registers.
        let v = unsafe {
            let cols = |i: usize| {
                let top = _mm_loadl_epi64(base.add(4 * i).cast());
                let bottom = _mm_loadl_epi64(base.add(4 * (i + stride)).cast());
                _mm_unpacklo_epi8(top, bottom)
            };
            let both = _mm256_set_m128i(cols(i1), cols(i0));
            let wyv = _mm256_setr_epi32(
                wy(wy0),
                wy(wy0),
                wy(wy0),
                wy(wy0),
                wy(wy1),
                wy(wy1),
                wy(wy1),
                wy(wy1),
            );
            let vert = _mm256_maddubs_epi16(both, wyv);
            let lr = _mm256_unpacklo_epi16(vert, _mm256_srli_si256(vert, 8));
            let wxv = _mm256_setr_epi32(
                wx(wx0),
                wx(wx0),
                wx(wx0),
                wx(wx0),
                wx(wx1),
                wx(wx1),
                wx(wx1),
                wx(wx1),
            );
            let v = _mm256_srli_epi32(_mm256_add_epi32(_mm256_madd_epi16(lr, wxv), round), 14);
            let v = _mm256_packs_epi32(v, v);
            _mm256_packus_epi16(v, v)
        };
        out[2 * p] = (_mm256_cvtsi256_si32(v) as u32).to_le_bytes();
        out[2 * p + 1] = (_mm256_extract_epi32::<4>(v) as u32).to_le_bytes();
    }
    if taps.len() % 2 == 1 {
        let last = taps.len() - 1;
        // SAFETY: SSSE3 is part of AVX2.
        unsafe { span_ssse3(data, stride, &taps[last..], &mut out[last..]) };
    }
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
            // Both SIMD kernels, odd lengths included.
            for n in [taps.len(), taps.len() - 1] {
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
