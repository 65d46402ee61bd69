//! mrcal's closed-form central models (docs/lens-models.md), intrinsics fx fy cx cy:
//!
//! * STEREOGRAPHIC: u = 2·(x, y)/(|p| + z), q = f·u + c; everything but straight behind.
//! * LONLAT: lon = atan2(x, z), lat = asin(y/|p|), q = (fx·lon + cx, fy·lat + cy).
//! * LATLON: lat = asin(x/|p|), lon = atan2(y, z), q = (fx·lat + cx, fy·lon + cy).

use super::Real;
use glam::DVec3;

pub fn stereographic<T: Real>(core: [T; 4], p: [T; 3]) -> [T; 2] {
    let [fx, fy, cx, cy] = core;
    let n = (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt();
    let s = T::from(2.0) / (n + p[2]);
    [fx * p[0] * s + cx, fy * p[1] * s + cy]
}

pub fn lonlat<T: Real>(core: [T; 4], p: [T; 3]) -> [T; 2] {
    let [fx, fy, cx, cy] = core;
    let n = (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt();
    [fx * p[0].atan2(p[2]) + cx, fy * (p[1] / n).asin() + cy]
}

pub fn latlon<T: Real>(core: [T; 4], p: [T; 3]) -> [T; 2] {
    let [fx, fy, cx, cy] = core;
    let n = (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt();
    [fx * (p[0] / n).asin() + cx, fy * p[1].atan2(p[2]) + cy]
}

/// Unit ray of normalised coordinates (u, v) = ((qx − cx)/fx, (qy − cy)/fy).
pub fn unproject_stereographic(u: f64, v: f64) -> DVec3 {
    DVec3::new(u, v, 1.0 - (u * u + v * v) / 4.0).normalize()
}

pub fn unproject_lonlat(lon: f64, lat: f64) -> DVec3 {
    DVec3::new(lat.cos() * lon.sin(), lat.sin(), lat.cos() * lon.cos())
}

pub fn unproject_latlon(lat: f64, lon: f64) -> DVec3 {
    DVec3::new(lat.sin(), lat.cos() * lon.sin(), lat.cos() * lon.cos())
}
