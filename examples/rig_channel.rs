//! A projector channel of a rig: its warp map and blend, applied to content.
//!
//! Reads a rig (default: the demo rig, a 270° cylinder with three projectors), computes one
//! channel's warp (which content direction each projector pixel shows) and its edge-blend
//! weights, renders a test panorama through the warp, multiplies it by the blend in signal
//! space and writes what that projector must show, beside its blend mask:
//!
//! ```text
//! cargo run --release --example rig_channel -- [RIG.json] [CHANNEL]
//! ```

use omniwarp::content::Content;
use omniwarp::content::pattern::Pattern;
use omniwarp::image_io::write_png;
use omniwarp::raster::Pixel;
use omniwarp::render::{self, Filter, Warp};
use omniwarp::rig::{BlendOptions, Rig, apply_gains, signal_gains, write_blend_png};
use std::path::Path;

fn main() -> omniwarp::Result<()> {
    let mut args = std::env::args().skip(1);
    let rig = match args.next() {
        Some(path) => Rig::read(Path::new(&path))?,
        None => Rig::from_json(omniwarp::rig::DEMO_RIG, Path::new("."))?,
    };
    let id = args.next().unwrap_or_else(|| "centre".into());
    // A quarter of the projectors' resolution keeps the example quick; drop this for the real
    // thing.
    let rig = rig.downscaled(4)?;
    let channel = rig.channel(&id)?;

    // The warp: for every projector pixel, the sampling vector V of the content it shows (the
    // map) and the wall point it lights (for the blend).
    let warp = rig.warp(channel);
    let lit = warp.points.iter().filter(|p| p.is_some()).count();
    println!(
        "{id}: {}×{} pixels, {lit} light the wall",
        channel.width, channel.height
    );

    // Blend weights in linear light (they sum to one where projectors overlap), then the gains
    // a projector of gamma 2.2 needs in its signal.
    let weights = rig.blend_weights(channel, &warp.points);
    let gains = signal_gains(&weights, 2.2)?;

    let panorama = Pattern::Checker
        .equirect(2048, 1024, 2, false)
        .map(|p| <[u8; 4]>::from_f32(p.map(|c| c * 255.0)));
    let content = Content::equirect(&panorama, 360.0, 180.0)?;
    let (w, h) = (channel.width, channel.height);
    let mut image = render::render(Warp::Map(&warp.map), &content, w, h, 1, Filter::Bilinear)?;
    apply_gains(&mut image, &gains)?;

    write_png(Path::new(&format!("{id}.png")), &image)?;
    let mask = format!("{id}-blend.png");
    write_blend_png(Path::new(&mask), w, h, &weights, BlendOptions::default())?;
    println!("{id}.png, {mask}");
    Ok(())
}
