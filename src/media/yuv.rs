//! Y′CbCr ↔ R′G′B′ for 8-bit 4:2:0 frames, the layout movies are decoded to and encoded from:
//! a quarter of RGBA's bytes through the pipes, converted here as the atlas is filled and as
//! the warped frame is packed, in integer arithmetic (16 fractional bits).
//!
//! The matrix follows the stream's `color_space` tag (BT.601, BT.709 or BT.2020, from Kr and Kb)
//! and its range: limited (Y′ 16–235, Cb/Cr 16–240) unless tagged full. An untagged stream is
//! BT.601, as ffmpeg's own converter takes it. Chroma is replicated over its 2×2 block on the
//! way in (as ffmpeg's unscaled converters do) and averaged over it on the way out.

/// A Y′CbCr matrix and range.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Matrix {
    kr: f64,
    kb: f64,
    full: bool,
}

const ONE: i32 = 1 << 16;

fn fixed(v: f64) -> i32 {
    (v * f64::from(ONE)).round() as i32
}

impl Matrix {
    /// The matrix for an ffmpeg `color_space` name (`bt709`, `bt2020nc`, …; anything else is
    /// BT.601) and `color_range` (`pc`/`jpeg`: full range).
    pub fn from_tags(space: Option<&str>, range: Option<&str>) -> Self {
        let (kr, kb) = match space {
            Some("bt709") => (0.2126, 0.0722),
            Some("bt2020nc" | "bt2020c" | "bt2020_ncl" | "bt2020_cl") => (0.2627, 0.0593),
            _ => (0.299, 0.114),
        };
        Matrix {
            kr,
            kb,
            full: matches!(range, Some("pc" | "jpeg" | "full")),
        }
    }

    /// ffmpeg's name of the matrix, for its `scale` filter's `out_color_matrix`.
    pub fn ffmpeg_name(&self) -> &'static str {
        if self.kr == 0.2126 {
            "bt709"
        } else if self.kr == 0.2627 {
            "bt2020"
        } else {
            "bt601"
        }
    }

    /// The name of the matrix as a stream's `color_space` tag.
    pub fn tag(&self) -> &'static str {
        match self.ffmpeg_name() {
            "bt709" => "bt709",
            "bt2020" => "bt2020nc",
            _ => "smpte170m",
        }
    }

    /// Whether the range is full (0–255) rather than limited.
    pub fn full_range(&self) -> bool {
        self.full
    }

    fn scales(&self) -> (f64, f64, f64) {
        // (luma offset, luma span, chroma span) in 8-bit code values.
        if self.full {
            (0.0, 255.0, 255.0)
        } else {
            (16.0, 219.0, 224.0)
        }
    }

    /// The decoder: Y′CbCr code values to R′G′B′.
    pub fn decoder(&self) -> Decoder {
        let (y0, ys, cs) = self.scales();
        let kg = 1.0 - self.kr - self.kb;
        let y = 255.0 / ys;
        let c = 255.0 / cs;
        Decoder {
            y0: y0 as i32,
            y: fixed(y),
            rv: fixed(2.0 * (1.0 - self.kr) * c),
            gu: fixed(2.0 * (1.0 - self.kb) * self.kb / kg * c),
            gv: fixed(2.0 * (1.0 - self.kr) * self.kr / kg * c),
            bu: fixed(2.0 * (1.0 - self.kb) * c),
        }
    }

    /// The encoder: R′G′B′ to Y′CbCr code values.
    pub fn encoder(&self) -> Encoder {
        let (y0, ys, cs) = self.scales();
        let kg = 1.0 - self.kr - self.kb;
        let (kr, kb) = (self.kr, self.kb);
        let y = ys / 255.0;
        let cb = cs / 255.0 / (2.0 * (1.0 - kb));
        let cr = cs / 255.0 / (2.0 * (1.0 - kr));
        Encoder {
            y0: y0 as i32,
            yr: fixed(kr * y),
            yg: fixed(kg * y),
            yb: fixed(kb * y),
            ur: fixed(-kr * cb),
            ug: fixed(-kg * cb),
            ub: fixed((1.0 - kb) * cb),
            vr: fixed((1.0 - kr) * cr),
            vg: fixed(-kg * cr),
            vb: fixed(-kb * cr),
        }
    }
}

#[inline]
fn clamp8(v: i32) -> u8 {
    v.clamp(0, 255) as u8
}

/// Y′CbCr → R′G′B′ in fixed point.
#[derive(Debug, Clone, Copy)]
pub struct Decoder {
    y0: i32,
    y: i32,
    rv: i32,
    gu: i32,
    gv: i32,
    bu: i32,
}

impl Decoder {
    /// The R′G′B′ of code values y, u (Cb), v (Cr).
    #[inline]
    pub fn rgb(&self, y: u8, u: u8, v: u8) -> [u8; 3] {
        let l = (i32::from(y) - self.y0) * self.y + ONE / 2;
        let (u, v) = (i32::from(u) - 128, i32::from(v) - 128);
        [
            clamp8((l + self.rv * v) >> 16),
            clamp8((l - self.gu * u - self.gv * v) >> 16),
            clamp8((l + self.bu * u) >> 16),
        ]
    }
}

/// R′G′B′ → Y′CbCr in fixed point.
#[derive(Debug, Clone, Copy)]
pub struct Encoder {
    y0: i32,
    yr: i32,
    yg: i32,
    yb: i32,
    ur: i32,
    ug: i32,
    ub: i32,
    vr: i32,
    vg: i32,
    vb: i32,
}

impl Encoder {
    /// The luma code value of an R′G′B′ pixel.
    #[inline]
    pub fn y(&self, [r, g, b]: [i32; 3]) -> u8 {
        clamp8(((self.yr * r + self.yg * g + self.yb * b + ONE / 2) >> 16) + self.y0)
    }

    /// The chroma code values (Cb, Cr) of an R′G′B′ pixel, or of the sum of four (`four`).
    #[inline]
    pub fn uv(&self, [r, g, b]: [i32; 3], four: bool) -> (u8, u8) {
        let (shift, half) = if four { (18, 1 << 17) } else { (16, ONE / 2) };
        let u = (self.ur * r + self.ug * g + self.ub * b + half) >> shift;
        let v = (self.vr * r + self.vg * g + self.vb * b + half) >> shift;
        (clamp8(u + 128), clamp8(v + 128))
    }
}

/// A 4:2:0 frame's planes as one buffer: Y′ (w × h), then Cb and Cr (⌈w/2⌉ × ⌈h/2⌉ each).
pub fn frame_len(w: usize, h: usize) -> usize {
    w * h + 2 * w.div_ceil(2) * h.div_ceil(2)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trips_within_a_code_value_and_hits_the_reference_points() {
        for m in [
            Matrix::from_tags(None, None),
            Matrix::from_tags(Some("bt709"), None),
            Matrix::from_tags(Some("bt2020nc"), Some("pc")),
        ] {
            let (d, e) = (m.decoder(), m.encoder());
            for rgb in [
                [0, 0, 0],
                [255, 255, 255],
                [255, 0, 0],
                [12, 200, 99],
                [3, 3, 250],
            ] {
                let y = e.y(rgb);
                let (u, v) = e.uv(rgb, false);
                let back = d.rgb(y, u, v);
                for k in 0..3 {
                    assert!(
                        (i32::from(back[k]) - rgb[k]).abs() <= 2,
                        "{m:?} {rgb:?} {back:?}"
                    );
                }
            }
            let white = e.y([255, 255, 255]);
            assert_eq!(white, if m.full_range() { 255 } else { 235 });
            assert_eq!(e.uv([255, 255, 255], false), (128, 128));
            assert_eq!(e.uv([4 * 90, 4 * 90, 4 * 90], true), (128, 128));
        }
        // BT.601 limited red, as every reference table gives it: (81, 90, 240).
        let e = Matrix::from_tags(None, None).encoder();
        assert_eq!(
            (e.y([255, 0, 0]), e.uv([255, 0, 0], false)),
            (81, (90, 240))
        );
    }
}
