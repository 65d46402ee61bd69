//! Helpers shared by the integration tests.
#![allow(dead_code)]

pub mod server;

use omniwarp::content::{Content, Format};
use omniwarp::image_io::{self, Loaded};
use omniwarp::projection::{self, Params, View};
use omniwarp::raster::Raster;
use std::path::{Path, PathBuf};

pub fn fixture(rel: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("calibration/fixtures")
        .join(rel)
}

pub fn read_u8(path: &Path) -> Raster<[u8; 4]> {
    match image_io::read_image(path).unwrap_or_else(|e| panic!("{}: {e}", path.display())) {
        Loaded::U8(r) => r,
        Loaded::F32(_) => panic!("{}: expected an 8-bit image", path.display()),
    }
}

pub fn content(path: &Path, format: Format) -> Content<[u8; 4]> {
    Content::from_image(&read_u8(path), format, None, None).unwrap()
}

pub fn params(hfov: Option<f64>, vfov: Option<f64>, fov: Option<f64>) -> Params {
    Params {
        hfov,
        vfov,
        fov,
        ..Params::default()
    }
}

pub fn view(name: &str, p: Params, w: u32, h: u32) -> View {
    View::plain(projection::build(name, &p, f64::from(h) / f64::from(w)).unwrap())
}

/// Writes actual and difference images next to the test's output directory when a comparison
/// fails, so the failure can be looked at.
pub fn save_failure(name: &str, actual: &Raster<[u8; 4]>, expected: &Raster<[u8; 4]>) -> PathBuf {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("failures");
    std::fs::create_dir_all(&dir).unwrap();
    let diff = Raster::from_fn(actual.width, actual.height, |x, y| {
        let (a, e) = (actual.get(x, y), expected.get(x, y));
        let d = |k: usize| (4 * (i32::from(a[k]) - i32::from(e[k])).abs()).min(255) as u8;
        [d(0), d(1), d(2), 255]
    });
    image_io::write_png(&dir.join(format!("{name}-actual.png")), actual).unwrap();
    image_io::write_png(&dir.join(format!("{name}-diff.png")), &diff).unwrap();
    dir
}
