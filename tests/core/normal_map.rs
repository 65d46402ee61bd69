//! Normal maps: EXR round trips, the half-float error bound, rendering through a map equals
//! rendering through its projection, and bad files are refused with the reason.

use crate::common;

use common::*;
use glam::DVec3;
use omniwarp::content::Content;
use omniwarp::content::pattern::Pattern;
use omniwarp::cubemap::CubeMap;
use omniwarp::image_io::{self, Precision};
use omniwarp::normalmap::NormalMap;
use omniwarp::projection::{Orientation, View, build};
use omniwarp::raster::{Pixel, Raster};
use omniwarp::render::{Filter, Warp, render};

fn tmp() -> tempfile::TempDir {
    tempfile::tempdir().unwrap()
}

fn fisheye_map(w: u32, h: u32) -> NormalMap {
    let p = build(
        "fisheye",
        &params(None, None, Some(200.0)),
        f64::from(h) / f64::from(w),
    )
    .unwrap();
    let c = Orientation::look(DVec3::new(0.2, 0.5, -1.0), DVec3::Y).unwrap();
    let v = View::new(p, c, DVec3::new(0.1, 0.0, 0.2), 1.1).unwrap();
    NormalMap::from_view(&v, w, h).unwrap()
}

#[test]
fn float_exr_round_trips_bit_exactly_with_attributes() {
    let dir = tmp();
    let path = dir.path().join("map.exr");
    let mut map = fisheye_map(97, 61);
    map.attributes
        .push(("omniwarp.channel".into(), "left".into()));
    map.write(&path, Precision::Float).unwrap();
    let back = NormalMap::read(&path).unwrap();
    let bits = |m: &NormalMap| {
        m.pixels()
            .data
            .iter()
            .flatten()
            .map(|c| c.to_bits())
            .collect::<Vec<_>>()
    };
    assert_eq!(bits(&back), bits(&map));
    for attr in &map.attributes {
        assert!(back.attributes.contains(attr), "lost {attr:?}");
    }
    // Outside the image circle the map is invalid: A = 0.
    assert!(back.direction(0, 0).is_none());
    assert!(back.direction(48, 30).is_some());
}

#[test]
fn half_precision_error_is_bounded() {
    let dir = tmp();
    let path = dir.path().join("half.exr");
    let map = fisheye_map(256, 256);
    map.write(&path, Precision::Half).unwrap();
    let back = NormalMap::read(&path).unwrap();
    let mut worst: f64 = 0.0;
    for j in 0..256 {
        for i in 0..256 {
            match (map.direction(i, j), back.direction(i, j)) {
                (Some(a), Some(b)) => worst = worst.max(a.angle_between(b).to_degrees()),
                (None, None) => {}
                other => panic!("validity changed at ({i}, {j}): {other:?}"),
            }
        }
    }
    println!("half-float normal map: largest angular error {worst:.4}°");
    // The bound the module docs state.
    assert!(worst < 0.03, "{worst}°");
}

#[test]
fn rendering_through_a_map_equals_rendering_through_the_projection() {
    let (w, h) = (160, 120);
    let p = build(
        "cylindrical",
        &params(Some(300.0), None, None),
        f64::from(h) / f64::from(w),
    )
    .unwrap();
    let v = View::new(
        p,
        Orientation::look(DVec3::new(1.0, 0.2, -1.0), DVec3::Y).unwrap(),
        DVec3::ZERO,
        1.0,
    )
    .unwrap();
    let map = NormalMap::from_view(&v, w, h).unwrap();
    let dir = tmp();
    let path = dir.path().join("cyl.exr");
    map.write(&path, Precision::Float).unwrap();
    let map = NormalMap::read(&path).unwrap();
    let cube = CubeMap::<[u8; 4]>::from_fn(64, 2, |d| {
        <[u8; 4] as Pixel>::from_f32(Pattern::Smooth.eval(d).map(|c| c * 255.0))
    });
    let content = Content::cube(&cube);
    let a = render(Warp::View(&v), &content, w, h, 1, Filter::Bilinear).unwrap();
    let b = render(Warp::Map(&map), &content, w, h, 1, Filter::Bilinear).unwrap();
    // The map stores V in f32; the fraction of a texel that changes is below 8-bit precision.
    let differ = a.data.iter().zip(&b.data).filter(|(x, y)| x != y).count();
    let worst = a
        .data
        .iter()
        .zip(&b.data)
        .flat_map(|(x, y)| (0..4).map(|k| x[k].abs_diff(y[k])))
        .max();
    assert!(
        worst <= Some(1) && differ < (w * h / 100) as usize,
        "{differ} pixels differ, by up to {worst:?}"
    );
}

#[test]
fn bad_maps_are_refused_with_the_pixel_named() {
    let mut px: Raster<[f32; 4]> = Raster::new(4, 3);
    px.data.fill([0.0, 0.0, -1.0, 1.0]);
    assert!(NormalMap::from_pixels(px.clone(), vec![]).is_ok());
    let cases = [
        ([f32::NAN, 0.0, -1.0, 1.0], "non-finite"),
        ([0.0, 0.0, -0.5, 1.0], "length"),
        ([0.0, 0.0, -1.0, 1.5], "validity"),
    ];
    for (bad, why) in cases {
        let mut p = px.clone();
        p.data[6] = bad;
        let msg = NormalMap::from_pixels(p, vec![]).unwrap_err().to_string();
        assert!(msg.contains("pixel (2, 1)") && msg.contains(why), "{msg}");
    }
    // Invalid pixels may hold anything finite.
    let mut p = px.clone();
    p.data[0] = [0.0, 0.0, 0.0, 0.0];
    assert!(NormalMap::from_pixels(p, vec![]).is_ok());
}

#[test]
fn a_map_of_another_size_or_with_supersampling_is_refused() {
    let map = fisheye_map(20, 10);
    let cube = CubeMap::<[u8; 4]>::from_fn(8, 1, |_| [0u8; 4]);
    let content = Content::cube(&cube);
    let e = render(Warp::Map(&map), &content, 21, 10, 1, Filter::Bilinear).unwrap_err();
    assert!(e.to_string().contains("`size`"), "{e}");
    let e = render(Warp::Map(&map), &content, 20, 10, 2, Filter::Bilinear).unwrap_err();
    assert!(e.to_string().contains("`supersample`"), "{e}");
}

#[test]
fn png_and_exr_images_round_trip() {
    let dir = tmp();
    let img = Raster::from_fn(37, 11, |x, y| {
        [x as u8 * 7, y as u8 * 20, 200, (x * y) as u8]
    });
    let png = dir.path().join("a.png");
    image_io::write_png(&png, &img).unwrap();
    match image_io::read_image(&png).unwrap() {
        image_io::Loaded::U8(back) => assert_eq!(back, img),
        _ => panic!("PNG read as float"),
    }
    let f = img.map(|p| p.map(|c| f32::from(c) / 255.0 - 0.25));
    let exr = dir.path().join("a.exr");
    image_io::write_exr_rgba(&exr, &f, &[], Precision::Float).unwrap();
    match image_io::read_image(&exr).unwrap() {
        image_io::Loaded::F32(back) => assert_eq!(back, f),
        _ => panic!("EXR read as 8-bit"),
    }
}

#[test]
fn a_failed_write_leaves_nothing_behind() {
    let dir = tmp();
    let target = dir.path().join("out.exr");
    let err = image_io::atomic_write(&target, |f| {
        use std::io::Write;
        f.write_all(b"half a file").unwrap();
        Err(omniwarp::Error::invalid("test", "stopped half way"))
    });
    assert!(err.is_err());
    let left: Vec<_> = std::fs::read_dir(dir.path()).unwrap().collect();
    assert!(left.is_empty(), "left behind: {left:?}");
}
