//! Exports: PFM byte order and row order, ST-map orientation, a3 invalid markers and ffmpeg
//! remap maps, each round-tripped with an asymmetric pattern.

use crate::common;

use common::*;
use glam::DVec3;
use omniwarp::export::{a3_samples, content_uv, read_pfm, stmap, write_pfm, write_remap_pgm};
use omniwarp::normalmap::NormalMap;

#[test]
fn pfm_round_trips_and_is_stored_bottom_up_little_endian() {
    let dir = tempfile::tempdir().unwrap();
    let (w, h) = (5, 3);
    let rows: Vec<[f32; 3]> = (0..w * h)
        .map(|i| [i as f32, -(i as f32) * 0.5, f32::NAN])
        .collect();
    let path = dir.path().join("a.pfm");
    write_pfm(&path, w, h, &rows).unwrap();
    let bytes = std::fs::read(&path).unwrap();
    assert!(bytes.starts_with(b"PF\n5 3\n-1.0\n"));
    // The first sample on disk is the bottom-left pixel: image row 2, column 0 = sample 10.
    let first = f32::from_le_bytes(bytes[12..16].try_into().unwrap());
    assert_eq!(first, 10.0);
    let (rw, rh, back) = read_pfm(&path).unwrap();
    assert_eq!((rw, rh), (w, h));
    for (a, b) in rows.iter().zip(&back) {
        assert_eq!(a[0], b[0]);
        assert_eq!(a[1], b[1]);
        assert!(b[2].is_nan());
    }
    // Big-endian (positive scale) and one-channel files read too.
    let mut be = b"Pf\n2 2\n1.0\n".to_vec();
    for v in [1.0f32, 2.0, 3.0, 4.0] {
        be.extend_from_slice(&v.to_be_bytes());
    }
    let p2 = dir.path().join("b.pfm");
    std::fs::write(&p2, be).unwrap();
    let (_, _, g) = read_pfm(&p2).unwrap();
    assert_eq!(
        g.iter().map(|p| p[0]).collect::<Vec<_>>(),
        vec![3.0, 4.0, 1.0, 2.0]
    );
    std::fs::write(&p2, b"P6\n1 1\n255\n").unwrap();
    assert!(read_pfm(&p2).unwrap_err().to_string().contains("not a PFM"));
}

#[test]
fn stmap_and_remap_maps_put_the_origin_where_their_readers_expect_it() {
    // A warp that shows the content image one to one: the same equirect for output and canvas.
    let (w, h) = (64u32, 32u32);
    let v = view("equirect", params(Some(360.0), Some(180.0), None), w, h);
    let map = NormalMap::from_view(&v, w, h).unwrap();
    let uv = content_uv(&map, &v);
    let st = stmap(&uv, w as usize, h as usize);
    for (i, j) in [(0usize, 0usize), (63, 0), (10, 31), (40, 17)] {
        let p = st.get(i, j);
        let (u, vv) = ((i as f32 + 0.5) / 64.0, (j as f32 + 0.5) / 32.0);
        assert!(
            (p[0] - u).abs() < 1e-6 && (p[1] - (1.0 - vv)).abs() < 1e-6 && p[3] == 1.0,
            "({i}, {j}): {p:?}"
        );
    }
    let dir = tempfile::tempdir().unwrap();
    let (xm, ym) = (dir.path().join("x.pgm"), dir.path().join("y.pgm"));
    write_remap_pgm(&xm, &ym, &uv, w as usize, h as usize, [64, 32]).unwrap();
    let (x, y) = (std::fs::read(&xm).unwrap(), std::fs::read(&ym).unwrap());
    let header = b"P5\n64 32\n65535\n".len();
    let at = |b: &[u8], i: usize, j: usize| {
        u16::from_be_bytes([
            b[header + 2 * (j * 64 + i)],
            b[header + 2 * (j * 64 + i) + 1],
        ])
    };
    assert_eq!((at(&x, 10, 31), at(&y, 10, 31)), (10, 31));
    assert_eq!((at(&x, 63, 0), at(&y, 63, 0)), (63, 0));
    // Where the canvas does not reach, the ST-map says so in alpha and the maps with 65535.
    let narrow = view("equirect", params(Some(90.0), Some(45.0), None), w, h);
    let uv = content_uv(&map, &narrow);
    assert!(uv[0].is_none() && uv[16 * 64 + 32].is_some());
    assert_eq!(stmap(&uv, 64, 32).get(0, 0)[3], 0.0);
    write_remap_pgm(&xm, &ym, &uv, 64, 32, [64, 32]).unwrap();
    assert_eq!(at(&std::fs::read(&xm).unwrap(), 0, 0), 65535);
    assert!(write_remap_pgm(&xm, &ym, &uv, 64, 32, [0, 32]).is_err());
}

#[test]
fn a3_marks_missing_wall_points_with_nan_never_zero() {
    let s = a3_samples(&[Some(DVec3::new(1.0, -2.0, 0.5)), None]);
    assert_eq!(s[0], [1.0, -2.0, 0.5]);
    assert!(s[1].iter().all(|v| v.is_nan()));
}
