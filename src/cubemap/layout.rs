//! Cube-map image layouts for import and export.
//!
//! * `Strip`: the six faces side by side in omniwarp's order +X −X +Y −Y +Z −Z, each exactly as
//!   the cube-map table defines it.
//! * `FfmpegC3x2` / `FfmpegC6x1`: ffmpeg v360's `c3x2` (rows r l u / d f b) and `c6x1`
//!   (r l u d f b) with its default face order `rludfb` and no face rotation. ffmpeg's frame has
//!   y down and z forward, and its faces are drawn as seen from inside the cube; graphics cube
//!   maps are drawn as seen from outside. Its right, left, front and back faces are therefore
//!   ours mirrored left–right, its up and down faces ours mirrored top–bottom; front is −Z and
//!   back +Z. The fixtures in `calibration/fixtures/ffmpeg/` check this against ffmpeg itself.

use super::{CubeMap, Face};
use crate::raster::{Pixel, Raster};
use crate::{Error, Result};

/// How the six faces of a cube map are arranged in one image; every face is N × N pixels.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Layout {
    /// Six faces side by side (6N × N) in [`Face`] order +X −X +Y −Y +Z −Z, each as the
    /// cube-map table defines it.
    Strip,
    /// ffmpeg v360's `c3x2` (3N × 2N): rows r l u / d f b, faces in ffmpeg's orientation.
    FfmpegC3x2,
    /// ffmpeg v360's `c6x1` (6N × N): r l u d f b, faces in ffmpeg's orientation.
    FfmpegC6x1,
}

/// ffmpeg's slots r l u d f b: our face, and whether it is mirrored left–right (else
/// top–bottom).
const FFMPEG_SLOTS: [(Face, bool); 6] = [
    (Face::PosX, true),
    (Face::NegX, true),
    (Face::PosY, false),
    (Face::NegY, false),
    (Face::NegZ, true),
    (Face::PosZ, true),
];

impl Layout {
    /// Faces across and down.
    fn grid(self) -> (usize, usize) {
        match self {
            Layout::Strip | Layout::FfmpegC6x1 => (6, 1),
            Layout::FfmpegC3x2 => (3, 2),
        }
    }

    /// Slot k of the grid (row-major): our face and how the slot's image differs from it.
    fn slot(self, k: usize) -> (Face, Option<bool>) {
        match self {
            Layout::Strip => (Face::ALL[k], None),
            Layout::FfmpegC3x2 | Layout::FfmpegC6x1 => {
                let (face, horizontal) = FFMPEG_SLOTS[k];
                (face, Some(horizontal))
            }
        }
    }

    /// The size (width, height) of the image this layout makes of faces `n` pixels square.
    pub fn image_size(self, n: usize) -> (usize, usize) {
        let (cols, rows) = self.grid();
        (n * cols, n * rows)
    }

    /// Splits a layout image into a cube map.
    pub fn split<T: Pixel>(self, image: &Raster<T>) -> Result<CubeMap<T>> {
        let (cols, rows) = self.grid();
        let n = image.width / cols;
        if n == 0 || image.width != n * cols || image.height != n * rows {
            return Err(Error::invalid(
                "content",
                format!(
                    "a {self:?} cube map must be {cols}·N × {rows}·N pixels, got {}×{}",
                    image.width, image.height
                ),
            ));
        }
        let mut faces: [Raster<T>; 6] = std::array::from_fn(|_| Raster::new(n, n));
        for k in 0..6 {
            let block = image.crop((k % cols) * n, (k / cols) * n, n, n);
            let (face, flip) = self.slot(k);
            faces[face.index()] = match flip {
                None => block,
                Some(h) => block.flipped(h),
            };
        }
        CubeMap::from_faces(faces)
    }

    /// Joins a cube map into one layout image.
    pub fn join<T: Pixel>(self, cube: &CubeMap<T>) -> Raster<T> {
        let (cols, rows) = self.grid();
        let n = cube.size;
        let mut out = Raster::new(n * cols, n * rows);
        for k in 0..6 {
            let (face, flip) = self.slot(k);
            let f = cube.face(face);
            let block = match flip {
                None => f.clone(),
                Some(h) => f.flipped(h),
            };
            out.paste(&block, (k % cols) * n, (k / cols) * n);
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn numbered() -> CubeMap<[u8; 4]> {
        let faces =
            std::array::from_fn(|f| Raster::from_fn(3, 3, |x, y| [f as u8, x as u8, y as u8, 255]));
        CubeMap::from_faces(faces).unwrap()
    }

    #[test]
    fn every_layout_round_trips() {
        let cube = numbered();
        for layout in [Layout::Strip, Layout::FfmpegC3x2, Layout::FfmpegC6x1] {
            assert_eq!(
                layout.split(&layout.join(&cube)).unwrap(),
                cube,
                "{layout:?}"
            );
        }
    }

    #[test]
    fn ffmpeg_front_is_our_negative_z_mirrored() {
        let img = Layout::FfmpegC3x2.join(&numbered());
        // Row 2 of the grid, middle block: front. Its top-left pixel is −Z's top-right.
        assert_eq!(img.get(3, 3), [Face::NegZ as u8, 2, 0, 255]);
    }

    #[test]
    fn wrong_sizes_are_rejected() {
        let img: Raster<[u8; 4]> = Raster::new(10, 2);
        let err = Layout::FfmpegC6x1.split(&img).unwrap_err().to_string();
        assert!(err.contains("6·N × 1·N"), "{err}");
    }
}
