//! Piecewise perspective projection (seed 003): every pixel drawn by exactly one piece, pieces
//! meeting exactly at shared edges, no cracks on the GPU, the GPU pass against its CPU twin and
//! both against the exact per-pixel ray cast, the cut chosen from a tolerance, and where it
//! breaks (too few pieces, a triangle over the eye).

use glam::DVec3;
use omniwarp::gpu::Renderer;
use omniwarp::gpu::frame::{FrameOptions, SceneRenderer};
use omniwarp::gpu::warp::Source;
use omniwarp::projection::view::screen_of_pixel;
use omniwarp::projection::{self, Orientation, Params, View};
use omniwarp::raster::edges::{relative_edge_widths, spread};
use omniwarp::raster::psnr;
use omniwarp::scene::ppp::{Half, Pieces, Tolerance};
use omniwarp::scene::replicate::replicate;
use omniwarp::scene::{SKY, Scene};
use std::process::Command;

const EYE: DVec3 = DVec3::new(0.0, 1.7, 0.0);

fn view(name: &str, params: Params, w: u32, h: u32) -> View {
    View::plain(projection::build(name, &params, f64::from(h) / f64::from(w)).unwrap())
}

fn cylinder(w: u32, h: u32, vfov: f64) -> View {
    let p = Params {
        hfov: Some(360.0),
        vfov: Some(vfov),
        ..Params::default()
    };
    view("cylindrical", p, w, h)
}

fn opts(size: (u32, u32)) -> FrameOptions {
    FrameOptions {
        size,
        face: None,
        cmf: true,
        blur: None,
        eye: EYE,
    }
}

/// The views the structural tests cut: a cylinder, a full sphere, a fisheye (pixels outside
/// its circle show nothing), a turned perspective, and a rolled cylinder.
fn views(w: u32, h: u32) -> Vec<(&'static str, View)> {
    let equirect = Params {
        hfov: Some(360.0),
        vfov: Some(180.0),
        ..Params::default()
    };
    let fisheye = Params {
        fov: Some(180.0),
        ..Params::default()
    };
    let perspective = Params {
        hfov: Some(100.0),
        ..Params::default()
    };
    let turned = |name, p: Params| {
        View::new(
            projection::build(name, &p, f64::from(h) / f64::from(w)).unwrap(),
            Orientation::yaw_pitch_roll(30.0, 20.0, 10.0).unwrap(),
            DVec3::ZERO,
            1.0,
        )
        .unwrap()
    };
    let rolled = Params {
        hfov: Some(300.0),
        vfov: Some(100.0),
        ..Params::default()
    };
    vec![
        ("cylinder", cylinder(w, h, 90.0)),
        ("equirect", view("equirect", equirect, w, h)),
        ("fisheye", view("fisheye", fisheye, w, h)),
        ("perspective", turned("perspective", perspective)),
        ("rolled cylinder", turned("cylindrical", rolled)),
    ]
}

#[test]
fn every_pixel_belongs_to_exactly_one_piece_and_neighbours_meet_at_shared_edges() {
    let (w, h) = (203, 117);
    for (name, v) in views(w, h) {
        for (c, r) in [(1, 1), (7, 1), (13, 9), (40, 30)] {
            let Ok(p) = Pieces::new(&v, w, h, c, r) else {
                // A cut may be refused (a 360° cell has no pinhole camera), never misdrawn.
                continue;
            };
            for j in 0..h {
                for i in 0..w {
                    let owners: usize = p
                        .pieces
                        .iter()
                        .filter(|q| {
                            let [x0, y0, x1, y1] = q.cell;
                            (x0..x1).contains(&i) && (y0..y1).contains(&j) && q.owns(i, j)
                        })
                        .count();
                    // Pixels the view does not show may lie in a drawn cell (they are masked
                    // afterwards); every pixel it shows is drawn once.
                    if p.is_hidden(i, j) {
                        assert!(
                            owners <= 1,
                            "{name} {c}×{r}: pixel ({i}, {j}) drawn {owners}×"
                        );
                    } else {
                        assert_eq!(owners, 1, "{name} {c}×{r}: pixel ({i}, {j})");
                    }
                }
            }
            // Shared edges: the pieces on either side whose triangles hold the edge agree in
            // direction along it (the upper half holds a cell's right and top edges, the
            // lower half its left and bottom edges).
            let holding = |i: u32, j: u32, not: Half| {
                p.pieces.iter().find(|q| {
                    let [x0, y0, x1, y1] = q.cell;
                    (x0..x1).contains(&i) && (y0..y1).contains(&j) && q.half != not
                })
            };
            let gap = |a: Option<&omniwarp::scene::ppp::Piece>,
                       b: Option<&omniwarp::scene::ppp::Piece>,
                       x: f64,
                       y: f64| {
                let (a, b) = (a?, b?);
                Some(
                    a.direction(x, y)
                        .normalize()
                        .cross(b.direction(x, y).normalize())
                        .length(),
                )
            };
            let mut checked = 0;
            for q in p.pieces.iter().filter(|q| q.half != Half::Lower) {
                let [x0, y0, x1, y1] = q.cell;
                for y in y0..y1 {
                    let yc = f64::from(y) + 0.5;
                    let right = (x1 < w).then(|| holding(x1, y, Half::Upper)).flatten();
                    if let Some(g) = gap(Some(q), right, f64::from(x1), yc) {
                        assert!(g < 1e-9, "{name} {c}×{r}: {g} rad at x = {x1}, y = {yc}");
                        checked += 1;
                    }
                }
                for x in x0..x1 {
                    let xc = f64::from(x) + 0.5;
                    let above = (y0 > 0).then(|| holding(x, y0 - 1, Half::Upper)).flatten();
                    let own = p
                        .pieces
                        .iter()
                        .find(|l| l.cell == q.cell && l.half != Half::Lower);
                    if let Some(g) = gap(own, above, xc, f64::from(y0)) {
                        assert!(g < 1e-9, "{name} {c}×{r}: {g} rad at y = {y0}, x = {xc}");
                        checked += 1;
                    }
                }
                if q.half == Half::Upper {
                    let lower = p
                        .pieces
                        .iter()
                        .find(|l| l.cell == q.cell && l.half == Half::Lower);
                    let [a, b, cx, cy] = q.diagonal.map(|v| f64::from(v) / 2.0);
                    for k in 0..=8 {
                        let t = f64::from(k) / 8.0;
                        let (x, y) = (a + (cx - a) * t, b + (cy - b) * t);
                        let g = gap(Some(q), lower, x, y).expect("a cut cell has both halves");
                        assert!(g < 1e-9, "{name} {c}×{r}: {g} rad on a diagonal");
                    }
                }
            }
            if c > 1 {
                assert!(checked > 0, "{name} {c}×{r}: no shared edge checked");
            }
        }
    }
}

/// The inside of a closed box around the eye: every ray meets a wall, so a sky pixel is a
/// crack between pieces.
fn closed_box() -> Scene {
    let (lo, hi) = (DVec3::new(-4.0, -1.0, -5.0), DVec3::new(6.0, 4.0, 3.0));
    let c = |x: bool, y: bool, z: bool| {
        DVec3::new(
            if x { hi.x } else { lo.x },
            if y { hi.y } else { lo.y },
            if z { hi.z } else { lo.z },
        )
    };
    let quads = [
        [
            c(false, false, false),
            c(true, false, false),
            c(true, true, false),
            c(false, true, false),
        ],
        [
            c(false, false, true),
            c(true, false, true),
            c(true, true, true),
            c(false, true, true),
        ],
        [
            c(false, false, false),
            c(false, true, false),
            c(false, true, true),
            c(false, false, true),
        ],
        [
            c(true, false, false),
            c(true, true, false),
            c(true, true, true),
            c(true, false, true),
        ],
        [
            c(false, false, false),
            c(true, false, false),
            c(true, false, true),
            c(false, false, true),
        ],
        [
            c(false, true, false),
            c(true, true, false),
            c(true, true, true),
            c(false, true, true),
        ],
    ];
    let tris: Vec<[DVec3; 3]> = quads
        .iter()
        .flat_map(|q| [[q[0], q[1], q[2]], [q[0], q[2], q[3]]])
        .collect();
    Scene::from_triangles(&tris)
}

fn gpu_renderer(scene: Scene) -> SceneRenderer {
    SceneRenderer::new(scene, Renderer::Gpu, None)
        .expect("no GPU adapter: install mesa-vulkan-drivers (scripts/test does)")
}

#[test]
fn the_gpu_leaves_no_crack_between_pieces() {
    let (w, h) = (320, 200);
    let mut r = gpu_renderer(closed_box());
    for (name, v) in views(w, h) {
        for (c, r_) in [(1, 1), (16, 1), (24, 12), (80, 50)] {
            let Ok(p) = Pieces::new(&v, w, h, c, r_) else {
                continue;
            };
            let (img, _) = r.frame_ppp(&p, &opts((w, h))).unwrap();
            for (k, px) in img.data.iter().enumerate() {
                let (i, j) = ((k % w as usize) as u32, (k / w as usize) as u32);
                if p.is_hidden(i, j) {
                    assert_eq!(*px, [0; 4], "{name} {c}×{r_}: ({i}, {j}) shows something");
                } else {
                    assert!(
                        *px != SKY && px[3] == 255,
                        "{name} {c}×{r_}: a crack at ({i}, {j}): {px:?}"
                    );
                }
            }
        }
    }
}

/// The city at the seed's size (35k triangles), 1600×1200, cylindrical 360° × 90°, the cut
/// chosen for 0.25 output pixels. Measured on lavapipe: 64 strips, 0.215 px, 48.3 dB against
/// the exact ray cast (128 strips: 54.4 dB); the cube method at its default face (704²)
/// 40.5 dB, at 2048² 46.8 dB.
const CITY_PPP_DB: f64 = 46.0;

#[test]
fn ppp_on_the_city_is_closer_to_the_exact_image_than_the_cube_map_with_even_edges() {
    let (w, h) = (1600, 1200);
    let v = cylinder(w, h, 90.0);
    let mut r = gpu_renderer(Scene::city(35_000));
    let exact = r.frame_exact(&v, &opts((w, h))).unwrap();
    let (pieces, d) = Pieces::for_tolerance(&v, w, h, Tolerance::Pixels(0.25)).unwrap();
    assert!(d.pixels <= 0.25, "{d:?}");
    assert_eq!(pieces.rows, 1, "a cylinder is cut into vertical strips");
    let (img, report) = r.frame_ppp(&pieces, &opts((w, h))).unwrap();
    let all = |_: usize, _: usize| true;
    let ppp = psnr(&img, &exact, 255.0, all);
    let (cube_img, _) = r.frame(&v, &opts((w, h))).unwrap();
    let cube = psnr(&cube_img, &exact, 255.0, all);
    eprintln!(
        "{} pieces, replication {:?}: ppp {ppp:.2} dB, cube {cube:.2} dB",
        report.pieces, report.replication
    );
    assert!(ppp >= CITY_PPP_DB, "ppp {ppp:.2} dB");
    // Seed 003's Figure 8: drawn directly, edges are as wide as the exact image's everywhere;
    // resampled from the cube map, wider, and by how much varies across the image.
    let widths = relative_edge_widths(&img, &exact, 8);
    let cube_widths = relative_edge_widths(&cube_img, &exact, 8);
    eprintln!(
        "edge width spread (p90/p10 over 8×8 regions): ppp {:.3}, cube {:.3}",
        spread(&widths),
        spread(&cube_widths)
    );
    assert!(spread(&widths) <= 1.10, "ppp edge widths {widths:?}");
    assert!(spread(&cube_widths) > spread(&widths));
    assert!(ppp >= cube + 5.0, "ppp {ppp:.2} dB, cube {cube:.2} dB");
    let replication = report.replication.expect("the GPU replicates");
    assert!(replication < 3.0, "replication {replication}");
}

/// GPU pass against its CPU twin (the same pieces, a ray per pixel): measured 50.9–58 dB over
/// the views; they differ where rasterisation and ray casting round an edge differently.
const TWIN_DB: f64 = 45.0;

#[test]
fn the_gpu_pass_matches_its_cpu_twin() {
    let (w, h) = (400, 240);
    let scene = Scene::city(10_000);
    let mut gpu = gpu_renderer(scene.clone());
    let mut cpu = SceneRenderer::new(scene, Renderer::Cpu, None).unwrap();
    for (name, v) in views(w, h) {
        let (pieces, _) = Pieces::for_tolerance(&v, w, h, Tolerance::Pixels(0.25)).unwrap();
        let (a, _) = gpu.frame_ppp(&pieces, &opts((w, h))).unwrap();
        let (b, _) = cpu.frame_ppp(&pieces, &opts((w, h))).unwrap();
        let db = psnr(&a, &b, 255.0, |_, _| true);
        eprintln!("{name}: {}×{} cells, {db:.2} dB", pieces.cols, pieces.rows);
        assert!(db >= TWIN_DB, "{name}: {db:.2} dB");
    }
}

#[test]
fn a_perspective_view_is_one_exact_piece() {
    let (w, h) = (640, 480);
    for (_, v) in views(w, h).into_iter().filter(|(n, _)| *n == "perspective") {
        let (p, d) = Pieces::for_tolerance(&v, w, h, Tolerance::Pixels(1e-6)).unwrap();
        assert_eq!((p.cols, p.rows, p.pieces.len()), (1, 1, 1));
        assert!(d.angle < 1e-12, "{d:?}");
    }
}

#[test]
fn the_chosen_cut_meets_its_tolerance_and_a_coarser_one_does_not() {
    let (w, h) = (640, 400);
    for (name, v) in views(w, h) {
        for t in [
            Tolerance::Pixels(0.5),
            Tolerance::Angle(0.1f64.to_radians()),
        ] {
            let (p, d) = Pieces::for_tolerance(&v, w, h, t).unwrap();
            let again = p.measure(&v);
            assert_eq!(d, again);
            let (value, limit) = match t {
                Tolerance::Pixels(l) => (d.pixels, l),
                Tolerance::Angle(l) => (d.angle, l),
            };
            assert!(value <= limit, "{name} {t:?}: {d:?}");
            // Halving the finer direction's count breaks the tolerance (or the cut).
            let (c, r) = if p.cols >= p.rows {
                (p.cols / 2, p.rows)
            } else {
                (p.cols, p.rows / 2)
            };
            if c * r >= 1
                && p.pieces.len() > 1
                && let Ok(q) = Pieces::new(&v, w, h, c, r)
            {
                let e = q.measure(&v);
                let coarse = match t {
                    Tolerance::Pixels(_) => e.pixels,
                    Tolerance::Angle(_) => e.angle,
                };
                assert!(coarse > limit, "{name} {t:?}: {c}×{r} also meets it: {e:?}");
            }
        }
    }
}

#[test]
fn too_few_pieces_are_measured_or_refused() {
    let (w, h) = (720, 360);
    let v = cylinder(w, h, 90.0);
    // One cell for 360°: a pinhole looking backwards through a sliver; drawn, and its
    // deviation said (half a turn), never passed off as fine.
    let whole = Pieces::new(&v, w, h, 1, 1).unwrap().measure(&v);
    assert!(whole.angle.to_degrees() > 90.0, "{whole:?}");
    // Four 90° strips: tens of pixels.
    let d = Pieces::new(&v, w, h, 4, 1).unwrap().measure(&v);
    assert!(d.pixels > 10.0 && d.angle.to_degrees() > 5.0, "{d:?}");
    let many = Pieces::new(&v, w, h, 360, 1).unwrap().measure(&v);
    assert!(many.pixels < 0.05, "{many:?}");
    let e = Pieces::new(&v, w, h, 361, 1).unwrap_err().to_string();
    assert!(e.contains("pieces") && e.contains("2 pixels"), "{e}");
    let e = Pieces::for_tolerance(&v, w, h, Tolerance::Pixels(1e-9))
        .unwrap_err()
        .to_string();
    assert!(e.contains("tolerance"), "{e}");
    // A 360° fisheye: the image circle's rim is one direction (straight back). Cut in 2 × 2,
    // a piece's corners lie on one great circle; cut in 1, no corner has a direction at all.
    let (w, h) = (400, 400);
    let fisheye = Params {
        fov: Some(360.0),
        ..Params::default()
    };
    let v = view("fisheye", fisheye, w, h);
    let e = Pieces::new(&v, w, h, 2, 2).unwrap_err().to_string();
    assert!(e.contains("great circle"), "{e}");
    let e = Pieces::new(&v, w, h, 1, 1).unwrap_err().to_string();
    assert!(e.contains("no direction reaches its corners"), "{e}");
    let (p, d) = Pieces::for_tolerance(&v, w, h, Tolerance::Pixels(1.0)).unwrap();
    assert!(d.pixels <= 1.0, "{}×{}: {d:?}", p.cols, p.rows);
}

#[test]
fn a_triangle_over_the_eye_reaches_every_piece_and_is_drawn_right() {
    // A ceiling crossing the cylinder's axis above the eye, and a floor under it.
    let quad = |y: f64| {
        let c = |x, z| DVec3::new(x, y, z);
        [
            [c(-3.0, -3.0), c(3.0, -3.0), c(3.0, 3.0)],
            [c(-3.0, -3.0), c(3.0, 3.0), c(-3.0, 3.0)],
        ]
    };
    let tris: Vec<[DVec3; 3]> = quad(3.0).into_iter().chain(quad(0.0)).collect();
    let mut scene = Scene::from_triangles(&tris);
    for (k, c) in scene.colors.iter_mut().enumerate() {
        *c = if k < 6 {
            [220, 60, 40, 255]
        } else {
            [40, 90, 200, 255]
        };
    }
    let (w, h) = (720, 400);
    let v = cylinder(w, h, 150.0);
    let p = Pieces::new(&v, w, h, 120, 1).unwrap();
    // Seen from below, each ceiling triangle spans half the azimuths (one side of the
    // diagonal over the eye): the seed's leftmost/rightmost test breaks here, the planes not.
    let rep = replicate(&scene, &p, EYE, 0.1);
    let mut strips = [0usize; 4];
    for range in &rep.ranges {
        let drawn = &rep.indices[range.start as usize..range.end as usize];
        for (t, n) in strips.iter_mut().enumerate() {
            *n += usize::from(drawn.chunks(3).any(|c| c[0] as usize == 3 * t));
        }
    }
    for (t, n) in strips.iter().enumerate() {
        assert!((60..=120).contains(n), "triangle {t} in {n} of 120 strips");
    }
    let mut r = gpu_renderer(scene);
    let exact = r.frame_exact(&v, &opts((w, h))).unwrap();
    let (img, _) = r.frame_ppp(&p, &opts((w, h))).unwrap();
    let db = psnr(&img, &exact, 255.0, |_, _| true);
    assert!(db >= 30.0, "{db:.2} dB");
}

#[test]
fn tolerances_parse_with_their_unit_or_name_the_field() {
    assert_eq!(Tolerance::parse("0.5px").unwrap(), Tolerance::Pixels(0.5));
    assert_eq!(
        Tolerance::parse("0.001rad").unwrap(),
        Tolerance::Angle(0.001)
    );
    match Tolerance::parse("2deg").unwrap() {
        Tolerance::Angle(a) => assert!((a - 2f64.to_radians()).abs() < 1e-15),
        other => panic!("{other:?}"),
    }
    // An exponent is part of the number, not the unit.
    assert_eq!(Tolerance::parse("1e-3px").unwrap(), Tolerance::Pixels(1e-3));
    assert_eq!(
        Tolerance::parse("2.5E-4rad").unwrap(),
        Tolerance::Angle(2.5e-4)
    );
    for bad in [
        "", "5", "-1px", "0px", "nanpx", "1m", "px", "infdeg", "1e-3", "1epx",
    ] {
        let e = Tolerance::parse(bad).unwrap_err().to_string();
        assert!(e.contains("tolerance"), "{bad}: {e}");
    }
}

#[test]
fn the_cli_renders_a_scene_piecewise() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("ppp.png");
    let run = |extra: &[&str]| {
        Command::new(env!("CARGO_BIN_EXE_omniwarp"))
            .args([
                "render",
                "--scene",
                "city:small",
                "--projection",
                "cylindrical",
                "--hfov",
                "360",
                "--vfov",
                "90",
                "--size",
                "320x240",
                "--renderer",
                "cpu",
                "--out",
            ])
            .arg(&out)
            .args(extra)
            .output()
            .unwrap()
    };
    let ok = run(&["--method", "ppp", "--tolerance", "0.5px"]);
    let said = String::from_utf8_lossy(&ok.stderr);
    assert!(ok.status.success(), "{said}");
    assert!(
        said.contains("ppp: ") && said.contains("cells") && said.contains("px"),
        "{said}"
    );
    let img = image::open(&out).unwrap().to_rgba8();
    assert_eq!(img.dimensions(), (320, 240));
    let auto = run(&["--method", "auto", "--tolerance", "1px"]);
    let said = String::from_utf8_lossy(&auto.stderr);
    assert!(
        auto.status.success() && said.contains("auto: chose"),
        "{said}"
    );
    let bad = run(&["--method", "cube", "--pieces", "8x1"]);
    let said = String::from_utf8_lossy(&bad.stderr);
    assert!(!bad.status.success() && said.contains("--pieces"), "{said}");
    let bad = run(&["--method", "ppp", "--tolerance", "much"]);
    let said = String::from_utf8_lossy(&bad.stderr);
    assert!(
        !bad.status.success() && said.contains("--tolerance"),
        "{said}"
    );
    // The chart's peers warp a cube as ffmpeg's cylindrical output does: any other view is
    // refused before anything is drawn.
    for view in [
        "--projection equirect",
        "--projection cylindrical --hfov 360 --vfov 90 --look-to 1,0,0",
    ] {
        let bad = Command::new(env!("CARGO_BIN_EXE_omniwarp"))
            .args("bench chart --scene city:small --size 64x32 --peers".split(' '))
            .args(view.split(' '))
            .arg("--name")
            .arg(dir.path().join("chart"))
            .output()
            .unwrap();
        let said = String::from_utf8_lossy(&bad.stderr);
        assert!(
            !bad.status.success() && said.contains("--peers") && said.contains("straight ahead"),
            "{said}"
        );
    }
}

#[test]
fn the_chooser_meets_the_tolerance_on_three_scenes() {
    use omniwarp::gpu::choose::{Method, choose};
    let dome =
        env!("CARGO_MANIFEST_DIR").to_string() + "/calibration/rigs/dome-180-tilt15-5proj.json";
    let scenes = [
        ("city", Scene::city(10_000)),
        ("closed box", closed_box()),
        ("dome wall", Scene::load(&format!("wall:{dome}")).unwrap()),
    ];
    let (w, h) = (480, 320);
    let fisheye = Params {
        fov: Some(180.0),
        ..Params::default()
    };
    let views = [cylinder(w, h, 90.0), view("fisheye", fisheye, w, h)];
    for (name, scene) in scenes {
        let mut r = gpu_renderer(scene);
        for v in &views {
            for t in [
                Tolerance::Pixels(0.5),
                Tolerance::Angle(0.05f64.to_radians()),
            ] {
                let limit = match t {
                    Tolerance::Angle(a) => a,
                    Tolerance::Pixels(p) => p * omniwarp::scene::ppp::median_pitch(v, w, h),
                };
                let picks = choose(&mut r, Source::View(v), &opts((w, h)), t, 4096).unwrap();
                assert!(!picks.is_empty());
                for c in &picks {
                    assert!(
                        c.angle <= limit,
                        "{name} {t:?}: {} at {}",
                        c.describe(),
                        c.angle
                    );
                    if let Method::Ppp(p) = &c.method {
                        assert!(p.measure(v).angle <= limit, "{name} {t:?}");
                    }
                }
                assert!(
                    picks.windows(2).all(|p| p[0].ms <= p[1].ms),
                    "fastest first"
                );
                eprintln!(
                    "{name} {t:?}: {}",
                    picks
                        .iter()
                        .map(|c| format!("{} {:.0} ms", c.describe(), c.ms))
                        .collect::<Vec<_>>()
                        .join(", ")
                );
            }
        }
    }
    // Beyond what either method reaches, a named error.
    let mut r = gpu_renderer(closed_box());
    let e = choose(
        &mut r,
        Source::View(&views[0]),
        &opts((w, h)),
        Tolerance::Angle(1e-7),
        4096,
    )
    .unwrap_err()
    .to_string();
    assert!(e.contains("tolerance"), "{e}");
}

#[test]
fn the_supersampled_reference_averages_only_across_edges() {
    let (w, h) = (240, 160);
    let v = cylinder(w, h, 90.0);
    let mut r = SceneRenderer::new(closed_box(), Renderer::Cpu, None).unwrap();
    let one = r.frame_exact(&v, &opts((w, h))).unwrap();
    // One ray a pixel is the plain per-pixel cast at pixel centres.
    let direct = closed_box()
        .ray_caster()
        .unwrap()
        .picture(EYE, w, h, |i, j| {
            let (s, t) = screen_of_pixel(f64::from(i) + 0.5, f64::from(j) + 0.5, w, h);
            v.direction(s, t).ok()
        });
    assert!(
        direct.data == one.data,
        "one ray a pixel differs from the per-pixel cast"
    );
    let three = r.frame_reference(&v, &opts((w, h)), 3).unwrap();
    let at = |x: usize, y: usize| one.data[y * w as usize + x];
    let mut differ = 0;
    for y in 0..h as usize {
        for x in 0..w as usize {
            if three.data[y * w as usize + x] == at(x, y) {
                continue;
            }
            differ += 1;
            // A wall's own pixels keep its colour; only pixels a face edge crosses mix.
            let near_edge = [(1, 0), (-1, 0), (0, 1), (0, -1)].iter().any(|&(dx, dy)| {
                let (nx, ny) = (x as isize + dx, y as isize + dy);
                (0..w as isize).contains(&nx)
                    && (0..h as isize).contains(&ny)
                    && at(nx as usize, ny as usize) != at(x, y)
            });
            assert!(near_edge, "({x}, {y}) changed away from any edge");
        }
    }
    assert!(differ > 0, "no edge pixel was averaged");
    assert!(r.frame_reference(&v, &opts((w, h)), 9).is_err());
}

#[test]
fn multisampled_ppp_matches_its_twin_and_the_antialiased_reference() {
    let (w, h) = (480, 360);
    let v = cylinder(w, h, 90.0);
    let scene = Scene::city(10_000);
    let mut gpu = gpu_renderer(scene.clone());
    let mut cpu = SceneRenderer::new(scene, Renderer::Cpu, None).unwrap();
    let (pieces, _) = Pieces::for_tolerance(&v, w, h, Tolerance::Pixels(0.25)).unwrap();
    let o = opts((w, h));
    let reference = gpu.frame_reference(&v, &o, 4).unwrap();
    let (plain, _) = gpu.frame_ppp(&pieces, &o).unwrap();
    let (msaa, _) = gpu.frame_ppp_antialiased(&pieces, &o).unwrap();
    let (twin, _) = cpu.frame_ppp_antialiased(&pieces, &o).unwrap();
    let all = |_: usize, _: usize| true;
    let (plain_db, msaa_db) = (
        psnr(&plain, &reference, 255.0, all),
        psnr(&msaa, &reference, 255.0, all),
    );
    let twin_db = psnr(&msaa, &twin, 255.0, all);
    eprintln!(
        "against 4×4 rays: plain {plain_db:.2} dB, 4× MSAA {msaa_db:.2} dB; GPU vs CPU twin {twin_db:.2} dB"
    );
    // Measured on lavapipe: plain 37.8 dB, 4× MSAA 50.7 dB, twins 64.8 dB (the CPU casts at
    // Vulkan's standard sample positions).
    assert!(
        msaa_db >= plain_db + 6.0,
        "plain {plain_db:.2}, msaa {msaa_db:.2}"
    );
    assert!(twin_db >= 55.0, "{twin_db:.2} dB");
    // wgpu's GL backend resolves at the pass's end under the last scissor rectangle unless
    // the pass resets it (measured 6 dB before it did).
    let mut gl = SceneRenderer::new(Scene::city(10_000), Renderer::Gpu, Some("gl"))
        .expect("no GL adapter: install libegl-mesa0 (scripts/test does)");
    let (on_gl, _) = gl.frame_ppp_antialiased(&pieces, &o).unwrap();
    let gl_db = psnr(&on_gl, &twin, 255.0, all);
    eprintln!("GL against the CPU twin: {gl_db:.2} dB");
    assert!(gl_db >= 45.0, "{gl_db:.2} dB");
}
