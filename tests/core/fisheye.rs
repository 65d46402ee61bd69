//! Fisheye and dome-master content: the lookup is the fisheye projection read backwards, the
//! circle's rim is seamless and nothing outside it shows, a dome master through a dome rig shows
//! what the equivalent equirect shows, and a movie's next frame lays out as a new image would.

use crate::common;

use common::*;
use glam::DVec3;
use omniwarp::content::pattern::Pattern;
use omniwarp::content::{Content, Fisheye, Format, Locate, PAD};
use omniwarp::gpu::Renderer;
use omniwarp::gpu::frame::{FrameOptions, SceneRenderer};
use omniwarp::projection::{Orientation, Params, View, build};
use omniwarp::raster::{Raster, psnr};
use omniwarp::render::{Filter, Plan, Warp, render};
use omniwarp::rig::Rig;
use omniwarp::scene::{Projected, Scene};
use std::path::Path;

fn smooth_equirect(w: usize, h: usize) -> Raster<[f32; 4]> {
    Pattern::Smooth.equirect(w, h, 2, false)
}

fn to_u8(r: &Raster<[f32; 4]>) -> Raster<[u8; 4]> {
    r.map(|p| p.map(|c| (c * 255.0).round() as u8))
}

fn dome_rig() -> Rig {
    let path =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("calibration/rigs/dome-180-tilt15-5proj.json");
    Rig::read(&path).unwrap()
}

/// Every position the content gives is where the projection module's own fisheye (or dome
/// master) puts that direction, scaled onto the circle: two implementations, one convention.
#[test]
fn the_lookup_is_the_fisheye_projection_read_backwards() {
    let image = Raster::<[u8; 4]>::new(300, 200);
    let cases = [
        (None, 200.0, [150.0, 100.0], 100.0),
        (None, 360.0, [140.5, 90.0], 80.0),
        (Some(-30.0), 180.0, [150.0, 100.0], 100.0),
        (Some(0.0), 180.0, [160.0, 95.0], 90.0),
        (Some(45.0), 180.0, [150.0, 100.0], 99.5),
    ];
    for (tilt, fov, centre, radius) in cases {
        let f = Fisheye {
            fov,
            tilt,
            centre: Some(centre),
            radius: Some(radius),
        };
        let content = Content::fisheye(&image, &f).unwrap();
        let p = match tilt {
            Some(t) => Params {
                tilt: Some(t),
                ..Params::default()
            },
            None => params(None, None, Some(fov)),
        };
        let projection = build(
            if tilt.is_some() {
                "domemaster"
            } else {
                "fisheye"
            },
            &p,
            1.0,
        )
        .unwrap();
        let mut checked = 0;
        for i in 0..41 {
            for j in 0..41 {
                let (s, t) = (i as f64 / 20.0 - 1.0, j as f64 / 20.0 - 1.0);
                let Ok(d) = projection.forward(s, t) else {
                    continue;
                };
                let (x, y) = content.locate(d).expect("inside the circle");
                let pad = PAD as f64;
                let (ex, ey) = (
                    centre[0] + radius * s - 0.5 + pad,
                    centre[1] - radius * t - 0.5 + pad,
                );
                assert!(
                    (x - ex).abs() < 1e-9 && (y - ey).abs() < 1e-9,
                    "tilt {tilt:?} fov {fov}: ({s}, {t}) at ({x}, {y}), expected ({ex}, {ey})"
                );
                checked += 1;
            }
        }
        assert!(checked > 1000, "{checked}");
        if fov == 360.0 {
            // Straight behind a 360° fisheye is its whole rim, not its centre.
            let pad = PAD as f64;
            let (x, y) = content.locate(DVec3::Z).unwrap();
            let from_centre = (x - (centre[0] - 0.5 + pad)).hypot(y - (centre[1] - 0.5 + pad));
            assert!((from_centre - radius).abs() < 1e-9, "{from_centre}");
        }
        if fov < 360.0 {
            // Just beyond the field of view is not covered.
            let beyond = (fov / 2.0 + 0.01).to_radians();
            let d = DVec3::new(beyond.sin(), 0.0, -beyond.cos());
            let d = match tilt {
                Some(t) => glam::DMat3::from_rotation_x((90.0 - t).to_radians()) * d,
                None => d,
            };
            assert!(content.locate(d).is_none(), "tilt {tilt:?} fov {fov}");
        }
    }
}

/// A white disc on black: every direction the fisheye covers shows white, up to the rim — the
/// border outside the circle repeats the rim instead of letting the filter read the black
/// around it — and the directions beyond its field of view show nothing at all.
#[test]
fn the_rim_is_seamless_and_outside_is_transparent() {
    let (n, radius) = (256usize, 128.0);
    let disc = Raster::from_fn(n, n, |x, y| {
        let (dx, dy) = (x as f64 + 0.5 - 128.0, y as f64 + 0.5 - 128.0);
        if dx.hypot(dy) <= radius {
            [1.0f32; 4]
        } else {
            [0.0, 0.0, 0.0, 1.0]
        }
    });
    let f = Fisheye {
        fov: 190.0,
        ..Fisheye::FISHEYE
    };
    let content = Content::fisheye(&disc, &f).unwrap();
    let (w, h) = (720, 360);
    let v = view("equirect", params(Some(360.0), Some(180.0), None), w, h);
    for filter in [Filter::Bilinear, Filter::Bicubic] {
        let out = render(Warp::View(&v), &content, w, h, 1, filter).unwrap();
        let (mut shown, mut darkest) = (0, 1.0f32);
        for y in 0..h as usize {
            for x in 0..w as usize {
                let p = out.get(x, y);
                let d = Warp::View(&v)
                    .direction(x as f64 + 0.5, y as f64 + 0.5, w, h)
                    .unwrap();
                let theta = d.x.hypot(d.y).atan2(-d.z).to_degrees();
                if theta > 95.0 + 0.01 {
                    assert_eq!(p[3], 0.0, "({x}, {y}) at {theta}° shows content");
                } else if theta < 95.0 - 0.01 {
                    assert!(p[3] > 0.9999, "({x}, {y}) at {theta}°: {p:?}");
                    shown += 1;
                    darkest = darkest.min(p[0]);
                }
            }
        }
        // Letting the filter read the black gives about 0.5 at the rim.
        assert!(darkest > 0.999, "{filter:?}: darkest {darkest}");
        assert!(shown > (w * h) as usize / 2, "{shown}");
    }
}

/// The positions the lattice interpolates agree with the exact ones, and coverage is decided
/// exactly at the circle's edge.
#[test]
fn interpolated_plans_keep_the_circle_exact() {
    let image = to_u8(&smooth_equirect(512, 512));
    let f = Fisheye {
        fov: 230.0,
        tilt: None,
        centre: Some([250.0, 262.0]),
        radius: Some(240.0),
    };
    let content = Content::fisheye(&image, &f)
        .unwrap()
        .with_orientation(Orientation::yaw_pitch_roll(20.0, 10.0, 0.0).unwrap());
    let (w, h) = (640, 400);
    let v = view("cylindrical", params(Some(300.0), Some(100.0), None), w, h);
    let a = content.atlas();
    let fast = Plan::new(Warp::View(&v), &content, a, w, h, 1, Filter::Bilinear)
        .unwrap()
        .render(a)
        .unwrap();
    let exact = Plan::exact(Warp::View(&v), &content, a, w, h, 1, Filter::Bilinear)
        .unwrap()
        .render(a)
        .unwrap();
    let mut edge = 0;
    for y in 0..h as usize {
        for x in 0..w as usize {
            let (p, q) = (fast.get(x, y), exact.get(x, y));
            assert_eq!(p[3], q[3], "coverage differs at ({x}, {y})");
            for k in 0..3 {
                assert!(p[k].abs_diff(q[k]) <= 1, "({x}, {y}): {p:?} {q:?}");
            }
            if x > 0 && p[3] != fast.get(x - 1, y)[3] {
                edge += 1;
            }
        }
    }
    assert!(
        edge > 100,
        "the view crosses the circle's edge {edge} times"
    );
}

/// Seed 000's test of a content kind: the same world through a rig channel, once as an equirect
/// and once as the dome master made from it, tilted as the dome is. Inside the circle the two
/// agree; the only loss is the dome master's own resampling.
#[test]
fn a_dome_master_through_the_dome_rig_shows_what_the_equirect_shows() {
    let equirect = smooth_equirect(2048, 1024);
    let pano = Content::equirect(&equirect, 360.0, 180.0).unwrap();
    let n = 2048;
    let dm_view = View::plain(
        build(
            "domemaster",
            &Params {
                tilt: Some(15.0),
                ..Params::default()
            },
            1.0,
        )
        .unwrap(),
    );
    let master = render(Warp::View(&dm_view), &pano, n, n, 1, Filter::Bilinear).unwrap();
    let dome = Content::fisheye(
        &master,
        &Fisheye {
            tilt: Some(15.0),
            ..Fisheye::DOMEMASTER
        },
    )
    .unwrap();
    let rig = dome_rig();
    for ch in &rig.channels {
        let warp = rig.warp(ch);
        let (w, h) = (ch.width, ch.height);
        let a = render(Warp::Map(&warp.map), &pano, w, h, 1, Filter::Bilinear).unwrap();
        let b = render(Warp::Map(&warp.map), &dome, w, h, 1, Filter::Bilinear).unwrap();
        let both = |x, y| a.get(x, y)[3] == 1.0 && b.get(x, y)[3] == 1.0;
        let shown = omniwarp::raster::fraction(w as usize, h as usize, both);
        let db = psnr(&a, &b, 1.0, both);
        println!(
            "{}: {db:.1} dB over {:.0} % of its pixels",
            ch.id,
            100.0 * shown
        );
        assert!(db >= 50.0 && shown > 0.3, "{}: {db} dB over {shown}", ch.id);
    }
}

/// A movie's next frame, laid out by `refill` from a pixel reader, equals content made afresh
/// from that frame, for each kind of content; and a frame of another size is refused.
#[test]
fn a_refilled_frame_equals_content_made_from_it() {
    for (format, w, h) in [
        (Format::Equirect, 128, 64),
        (Format::Cylindrical, 128, 64),
        (Format::Fisheye, 100, 64),
        (Format::Domemaster, 64, 64),
        (Format::CubemapC3x2, 96, 64),
    ] {
        let first = to_u8(&smooth_equirect(w, h));
        let second = Raster::from_fn(w, h, |x, y| {
            [(x * 2) as u8, (y * 3) as u8, (x + y) as u8, 255]
        });
        let mut c = Content::from_image(&first, format, None, None).unwrap();
        c.refill((w, h), |y, row| {
            row.copy_from_slice(&second.data[y * w..(y + 1) * w])
        })
        .unwrap();
        let fresh = Content::from_image(&second, format, None, None).unwrap();
        assert!(c.atlas() == fresh.atlas(), "{format:?}");
        let e = c.refill((w, 48), |_, _| ()).unwrap_err();
        assert!(
            e.to_string().contains(&format!("{w}×48")),
            "{format:?}: {e}"
        );
    }
}

/// The GPU's twin of the lookup (shaders/scene.wgsl) against the CPU's, a tilted, turned dome
/// master projected onto the dome wall.
#[test]
fn gpu_and_cpu_look_a_dome_master_up_alike() {
    let rig_path =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("calibration/rigs/dome-180-tilt15-5proj.json");
    let n = 1024;
    let master = to_u8(&Raster::from_fn(n, n, |x, y| {
        let (u, v) = (x as f64 / n as f64, y as f64 / n as f64);
        Pattern::Smooth.eval(DVec3::new(u * 9.0, v * 7.0, u * v * 5.0))
    }));
    let content = Content::fisheye(
        &master,
        &Fisheye {
            fov: 200.0,
            tilt: Some(15.0),
            centre: Some([500.0, 520.0]),
            radius: Some(490.0),
        },
    )
    .unwrap()
    .with_orientation(Orientation::yaw_pitch_roll(30.0, 0.0, 5.0).unwrap());
    let (w, h) = (480, 240);
    let v = view("cylindrical", params(Some(270.0), Some(90.0), None), w, h);
    let opts = FrameOptions {
        size: (w, h),
        face: Some(384),
        cmf: true,
        blur: None,
        eye: DVec3::ZERO,
    };
    let mut images = Vec::new();
    for renderer in [Renderer::Gpu, Renderer::Cpu] {
        let scene = Scene::load(&format!("wall:{}", rig_path.display())).unwrap();
        let mut r = SceneRenderer::new(scene, renderer, None).unwrap();
        r.set_panorama(Some(Projected {
            content: content.clone(),
            centre: DVec3::new(0.3, 0.5, -0.2),
        }))
        .unwrap();
        images.push(r.frame(&v, &opts).unwrap().0);
    }
    let db = psnr(&images[0], &images[1], 255.0, |_, _| true);
    println!("dome master projected onto the dome, GPU vs CPU: {db:.1} dB");
    if db < 50.0 {
        save_failure("fisheye-gpu-cpu", &images[0], &images[1]);
    }
    assert!(db >= 50.0, "{db} dB");
}
