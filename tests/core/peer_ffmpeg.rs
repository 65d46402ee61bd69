//! Peer check: omniwarp's renders against ffmpeg's v360 filter on the same input, both
//! bilinear. The fixtures and the exact ffmpeg command lines are in
//! calibration/fixtures/ffmpeg/ (made by calibration/ffmpeg/make_fixtures.sh).
//!
//! Convention mapping: ffmpeg's frame has x right, y down, z forward, ours x right, y up, −z
//! forward, so ffmpeg's (x, y, z) is our (x, −y, −z); its equirect, cylindrical, fisheye and
//! flat outputs then agree with ours pixel for pixel (both put pixel centres at +0.5). Its cube
//! faces differ from graphics cube faces by a mirror; see `omniwarp::cubemap::Layout`.

use crate::common;

use common::*;
use omniwarp::content::Format;
use omniwarp::cubemap::{CubeMap, Face, Layout};
use omniwarp::raster::{Raster, fraction, psnr};
use omniwarp::render::{Filter, Warp, render};

// ffmpeg truncates its 14-bit fixed-point filter sums, a bias of half a level that alone caps
// the agreement at about 51 dB; a mirrored face, a swapped axis or a half-pixel shift costs
// 10–20 dB. The issue asks for 40.
const MIN_PSNR: f64 = 48.0;

/// PSNR against ffmpeg where we show content, after checking that we show content wherever
/// the projection covers the image (`expected`: that fraction of the pixels, from the view
/// alone), so a render that lost its coverage cannot pass on the pixels it kept.
fn compare(name: &str, ours: &Raster<[u8; 4]>, theirs: &Raster<[u8; 4]>, expected: f64) -> f64 {
    let shown = |x, y| ours.get(x, y)[3] == 255;
    let covered = fraction(ours.width, ours.height, shown);
    // Rim pixels that the domain only partly covers have alpha below 255.
    assert!(
        covered >= expected - 0.01,
        "{name}: content on {:.1} % of the pixels, the projection covers {:.1} %",
        100.0 * covered,
        100.0 * expected
    );
    // Only where we show content; ffmpeg fills the rest with black or edge texels.
    let p = psnr(ours, theirs, 255.0, shown);
    println!("{name}: {p:.2} dB");
    if p < MIN_PSNR {
        let dir = save_failure(name, ours, theirs);
        panic!(
            "{name}: PSNR {p:.2} dB < {MIN_PSNR} dB against ffmpeg (images in {})",
            dir.display()
        );
    }
    p
}

fn from_equirect(
    name: &str,
    projection: &str,
    p: omniwarp::projection::Params,
    fixture_name: &str,
) {
    let content = content(&fixture("ffmpeg/input_equirect.png"), Format::Equirect);
    let theirs = read_u8(&fixture(&format!("ffmpeg/{fixture_name}")));
    let (w, h) = (theirs.width as u32, theirs.height as u32);
    let v = view(projection, p, w, h);
    let ours = render(Warp::View(&v), &content, w, h, 1, Filter::Bilinear).unwrap();
    let expected = fraction(w as usize, h as usize, |i, j| {
        Warp::View(&v)
            .direction(i as f64 + 0.5, j as f64 + 0.5, w, h)
            .is_some()
    });
    compare(name, &ours, &theirs, expected);
}

#[test]
fn equirect_to_cylindrical_270x90() {
    from_equirect(
        "cylindrical",
        "cylindrical",
        params(Some(270.0), Some(90.0), None),
        "equirect_to_cylindrical_270x90.png",
    );
}

#[test]
fn equirect_to_fisheye_180() {
    from_equirect(
        "fisheye",
        "fisheye",
        params(None, None, Some(180.0)),
        "equirect_to_fisheye_180.png",
    );
}

#[test]
fn equirect_to_flat_90() {
    from_equirect(
        "flat",
        "flat",
        params(Some(90.0), Some(73.7397952917), None),
        "equirect_to_flat_90.png",
    );
}

/// ffmpeg's fisheye input back to equirect. Its fisheye input, like its equirect input, puts
/// the circle's rim on the centres of the edge pixels, so the circle is given explicitly:
/// radius 127.5 pixels about (128, 128). Where its bilinear taps straddle the rim it reads the
/// black around the circle and ours reads the rim repeated, so the last degree is left out.
#[test]
fn fisheye_180_to_equirect() {
    let input = read_u8(&fixture("ffmpeg/equirect_to_fisheye_180.png"));
    let f = omniwarp::content::Fisheye {
        centre: Some([128.0, 128.0]),
        radius: Some(127.5),
        ..omniwarp::content::Fisheye::FISHEYE
    };
    let content = omniwarp::content::Content::fisheye(&input, &f).unwrap();
    let theirs = read_u8(&fixture("ffmpeg/fisheye_to_equirect.png"));
    let (w, h) = (theirs.width as u32, theirs.height as u32);
    let v = view("equirect", params(Some(360.0), Some(180.0), None), w, h);
    let ours = render(Warp::View(&v), &content, w, h, 1, Filter::Bilinear).unwrap();
    let inside = |x: usize, y: usize| {
        let d = Warp::View(&v)
            .direction(x as f64 + 0.5, y as f64 + 0.5, w, h)
            .unwrap();
        d.x.hypot(d.y).atan2(-d.z).to_degrees() < 89.0
    };
    let masked = Raster::from_fn(w as usize, h as usize, |x, y| {
        if inside(x, y) { ours.get(x, y) } else { [0; 4] }
    });
    compare(
        "fisheye",
        &masked,
        &theirs,
        fraction(w as usize, h as usize, inside),
    );
}

fn our_cube(layout: Layout, face: u32) -> Raster<[u8; 4]> {
    let content = content(&fixture("ffmpeg/input_equirect.png"), Format::Equirect);
    let faces: Vec<_> = Face::ALL
        .iter()
        .map(|&f| render(Warp::CubeFace(f), &content, face, face, 1, Filter::Bilinear).unwrap())
        .collect();
    layout.join(&CubeMap::from_faces(faces.try_into().unwrap()).unwrap())
}

#[test]
fn equirect_to_ffmpeg_cube_layouts() {
    for (layout, file) in [
        (Layout::FfmpegC3x2, "equirect_to_c3x2.png"),
        (Layout::FfmpegC6x1, "equirect_to_c6x1.png"),
    ] {
        let theirs = read_u8(&fixture(&format!("ffmpeg/{file}")));
        compare(file, &our_cube(layout, 128), &theirs, 1.0);
    }
}

#[test]
fn ffmpeg_cube_layouts_to_equirect() {
    for (format, input, file) in [
        (
            Format::CubemapC3x2,
            "equirect_to_c3x2.png",
            "c3x2_to_equirect.png",
        ),
        (
            Format::CubemapC6x1,
            "equirect_to_c6x1.png",
            "c6x1_to_equirect.png",
        ),
    ] {
        let content = content(&fixture(&format!("ffmpeg/{input}")), format);
        let theirs = read_u8(&fixture(&format!("ffmpeg/{file}")));
        let v = view("equirect", params(Some(360.0), Some(180.0), None), 512, 256);
        let ours = render(Warp::View(&v), &content, 512, 256, 1, Filter::Bilinear).unwrap();
        compare(file, &ours, &theirs, 1.0);
    }
}
