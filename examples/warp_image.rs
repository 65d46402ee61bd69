//! Warp a panorama through a projection: an equirectangular image (or, without an argument, a
//! generated test panorama) as a 270°×90° cylindrical screen shows it, written as a PNG.
//! `cargo run --release --example warp_image -- [IN.png|IN.jpg|IN.exr]`; the README shows it.

use omniwarp::content::{Content, pattern::Pattern};
use omniwarp::image_io::{Loaded, read_image, write_png};
use omniwarp::projection::{self, Params, View};
use omniwarp::raster::Pixel;
use omniwarp::render::{self, Filter, Warp};

fn main() -> omniwarp::Result<()> {
    let to_u8 = |p: [f32; 4]| <[u8; 4]>::from_f32(p.map(|c| c * 255.0));
    let panorama = match std::env::args().nth(1) {
        Some(path) => match read_image(path.as_ref())? {
            Loaded::U8(image) => image,
            Loaded::F32(image) => image.map(to_u8),
        },
        None => Pattern::Checker.equirect(2048, 1024, 2, false).map(to_u8),
    };
    // The whole sphere, centred straight ahead (−z).
    let content = Content::equirect(&panorama, 360.0, 180.0)?;
    let params = Params {
        hfov: Some(270.0),
        vfov: Some(90.0),
        ..Params::default()
    };
    let view = View::plain(projection::build("cylindrical", &params, 640.0 / 1920.0)?);
    // 1920×640 pixels, bilinear, one sample a pixel; alpha 0 where the view shows nothing.
    let image = render::render(Warp::View(&view), &content, 1920, 640, 1, Filter::Bilinear)?;
    write_png("cylinder.png".as_ref(), &image)
}
