//! A movie laid out on the daemon's content canvas (`Canvas::content`) reads each direction
//! where the canvas's own projection puts it, the coordinates the 2d exports hand to media
//! servers: two implementations of each layout, one convention.

use glam::DVec3;
use omniwarp::projection::view::pixel_of_screen;
use omniwarp::raster::Raster;
use omniwarp::rig::Canvas;

/// A frame whose texels hold their own (u, v) on the image, so that a bilinear read anywhere
/// inside gives the position it read.
fn coordinates(w: usize, h: usize) -> Raster<[f32; 4]> {
    Raster::from_fn(w, h, |x, y| {
        [
            (x as f32 + 0.5) / w as f32,
            (y as f32 + 0.5) / h as f32,
            0.0,
            1.0,
        ]
    })
}

fn canvas(json: &str) -> Canvas {
    serde_json::from_str(json).unwrap()
}

/// Directions spread over the sphere (a Fibonacci lattice).
fn directions(n: usize) -> impl Iterator<Item = DVec3> {
    let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
    (0..n).map(move |i| {
        let z = 1.0 - 2.0 * (i as f64 + 0.5) / n as f64;
        let r = (1.0 - z * z).sqrt();
        let a = golden * i as f64;
        DVec3::new(r * a.cos(), r * a.sin(), z)
    })
}

#[test]
fn a_frame_on_a_canvas_reads_where_the_canvas_projection_says() {
    let cases = [
        // (canvas, frame size, a fisheye's circle radius in frame pixels): frames need not have
        // the canvas's size (panoramas) or only its aspect (fisheyes).
        (
            r#"{"projection": "equirect", "params": {"hfov": 360, "vfov": 180}, "size": [4096, 2048]}"#,
            (512, 256),
            None,
        ),
        (
            r#"{"projection": "equirect", "params": {"hfov": 200, "vfov": 100}, "size": [2000, 1000],
                "look_to": [0.5, 0.2, -1]}"#,
            (300, 200),
            None,
        ),
        (
            r#"{"projection": "cylindrical", "params": {"hfov": 270, "vfov": 90}, "size": [3840, 2160],
                "look_to": [1, 0, -1], "look_up": [0.1, 1, 0]}"#,
            (480, 270),
            None,
        ),
        (
            r#"{"projection": "domemaster", "params": {"tilt": 15}, "size": [4096, 4096]}"#,
            (400, 400),
            Some(200.0),
        ),
        (
            r#"{"projection": "domemaster", "size": [2048, 2048], "look_to": [1, 0, -1]}"#,
            (256, 256),
            Some(128.0),
        ),
        (
            r#"{"projection": "fisheye", "params": {"fov": 220}, "size": [1600, 1200],
                "look_to": [0, 0.3, -1]}"#,
            (400, 300),
            Some(150.0),
        ),
        (
            r#"{"projection": "fisheye", "params": {"hfov": 160, "vfov": 120}, "size": [1600, 1200]}"#,
            (320, 240),
            Some(160.0),
        ),
    ];
    for (json, (w, h), rim) in cases {
        let c = canvas(json);
        let view = c.view().unwrap();
        let content = c.content(&coordinates(w, h)).unwrap();
        let (mut inside, mut outside) = (0, 0);
        for d in directions(20_000) {
            let uv = view.screen(d).ok().map(|(s, t)| {
                let (u, v) = pixel_of_screen(s, t, 1, 1);
                [u, v]
            });
            let read = content.sample(d).filter(|p| p[3] > 0.0);
            // A texel and a half from the edges: there the atlas's padding, not the image,
            // answers the bilinear read.
            let (mu, mv) = (1.5 / w as f64, 1.5 / h as f64);
            match uv {
                Some([u, v]) if (mu..1.0 - mu).contains(&u) && (mv..1.0 - mv).contains(&v) => {
                    // Near a fisheye's circle the atlas repeats the texels inside outwards.
                    let (dx, dy) = ((u - 0.5) * w as f64, (v - 0.5) * h as f64);
                    if rim.is_some_and(|r| (dx * dx + dy * dy).sqrt() > r - 2.5) {
                        continue;
                    }
                    let p =
                        read.unwrap_or_else(|| panic!("{json}: nothing read at {d} ({u}, {v})"));
                    assert!(
                        (f64::from(p[0]) - u).abs() < 2e-4 && (f64::from(p[1]) - v).abs() < 2e-4,
                        "{json}: {d} read ({}, {}), the canvas says ({u}, {v})",
                        p[0],
                        p[1]
                    );
                    inside += 1;
                }
                Some([u, v]) if !(-0.01..=1.01).contains(&u) || !(-0.01..=1.01).contains(&v) => {
                    assert!(
                        read.is_none(),
                        "{json}: {d} read outside the canvas ({u}, {v})"
                    );
                    outside += 1;
                }
                None => {
                    assert!(
                        read.is_none(),
                        "{json}: {d} read where the canvas shows nothing"
                    );
                    outside += 1;
                }
                Some(_) => {}
            }
        }
        assert!(
            inside > 2000,
            "{json}: only {inside} directions checked inside"
        );
        let whole = json.contains(r#""hfov": 360, "vfov": 180"#);
        assert!(
            whole || outside > 500,
            "{json}: only {outside} directions checked outside"
        );
    }
}

/// What a movie cannot be laid out on is refused by the canvas field at fault.
#[test]
fn canvases_a_movie_cannot_use_are_refused_by_field() {
    let frame = coordinates(64, 32);
    for (json, field) in [
        (
            r#"{"projection": "flat", "params": {"hfov": 90}, "size": [640, 480]}"#,
            "/projection",
        ),
        (
            r#"{"projection": "stereographic", "params": {"fov": 180}, "size": [640, 640]}"#,
            "/projection",
        ),
        (
            r#"{"projection": "equirect", "params": {"hfov": 360}, "size": [4096, 2048], "zoom": 2}"#,
            "/zoom",
        ),
        (r#"{"projection": "domemaster", "size": [64, 64]}"#, "/size"),
        // Fields of view that make the canvas's pixels oblong: the circle would be an ellipse.
        (
            r#"{"projection": "fisheye", "params": {"hfov": 180, "vfov": 180}, "size": [128, 64]}"#,
            "/params",
        ),
    ] {
        match canvas(json).content(&frame) {
            Err(omniwarp::Error::Invalid { name, .. }) => assert_eq!(name, field, "{json}"),
            Err(e) => panic!("{json}: {e}"),
            Ok(_) => panic!("{json}: accepted"),
        }
    }
}
