//! MPCDI 2d packages as their readers read them. Each reader below is written from that
//! reader's source, not from omniwarp's writer: where it takes the region, which way v runs,
//! which PFM row it draws at the top, where it places the grid's nodes, how many bits of the
//! alpha map it decodes. A package written for a reader must show, in that reader, what
//! `omniwarp render` shows; and what the real readers showed when calibration/interop/
//! ran them (calibration/fixtures/interop/) must still be what today's packages show.

use std::io::Read;
use std::path::{Path, PathBuf};
use std::process::Command;

fn omniwarp(args: &[&str]) {
    let out = Command::new(env!("CARGO_BIN_EXE_omniwarp"))
        .args(args)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "omniwarp {args:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
}

fn fixtures() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("calibration/fixtures/interop")
}

/// How a reader takes a 2d package (see each reader's source, cited in docs/mpcdi.md).
#[derive(Clone, Copy, Debug)]
struct Conventions {
    /// Region y and v measured up from the bottom: PyMPCDI's shader takes the media at
    /// t = y + ysize·v with t = 0 the image's bottom row; SGCT's mesh sets t = v.
    v_up: bool,
    /// The PFM's first row on disk is drawn at the top (PyMPCDI uploads it as texture row 0 at
    /// the window's top; SGCT's mesh puts row r at 1 − r/(n − 1)); the VESA library reads rows
    /// bottom-up as netpbm writes them.
    top_first: bool,
    /// Nodes at cell centres, clamped at the border (a texture sampled per pixel: PyMPCDI);
    /// otherwise edge to edge, i / (n − 1).
    centres: bool,
}

const VESA: Conventions = Conventions {
    v_up: false,
    top_first: false,
    centres: false,
};
const PYMPCDI: Conventions = Conventions {
    v_up: true,
    top_first: true,
    centres: true,
};
const SGCT: Conventions = Conventions {
    v_up: true,
    top_first: true,
    centres: false,
};

fn member(zip: &[u8], name: &str) -> Vec<u8> {
    let mut z = zip::ZipArchive::new(std::io::Cursor::new(zip)).unwrap();
    let mut out = Vec::new();
    z.by_name(name).unwrap().read_to_end(&mut out).unwrap();
    out
}

struct RegionRead {
    rect: [f64; 4],
    size: [usize; 2],
    nodes: [usize; 2],
    /// Node (u, v), row-major from the row the reader draws at the top.
    uv: Vec<[f32; 2]>,
    /// 8 bits, as both real readers decode.
    alpha: Vec<u8>,
    /// The beta map (black lift), 8 bits, if the fileset has one (the VESA library reads it as
    /// an optional `betaMap` beside the alpha map).
    beta: Option<Vec<u8>>,
}

fn read_region(pkg: &[u8], id: &str, c: Conventions) -> RegionRead {
    let xml = String::from_utf8(member(pkg, "mpcdi.xml")).unwrap();
    let doc = roxmltree::Document::parse(&xml).unwrap();
    let region = doc
        .descendants()
        .find(|n| n.has_tag_name("region") && n.attribute("id") == Some(id))
        .unwrap();
    let f = |name: &str| -> f64 { region.attribute(name).unwrap().parse().unwrap() };
    let fileset = doc
        .descendants()
        .find(|n| n.has_tag_name("fileset") && n.attribute("region") == Some(id))
        .unwrap();
    let has = |tag: &str| fileset.descendants().any(|n| n.has_tag_name(tag));
    let path = |tag: &str| -> String {
        fileset
            .descendants()
            .find(|n| n.has_tag_name(tag))
            .unwrap()
            .descendants()
            .find(|n| n.has_tag_name("path"))
            .unwrap()
            .text()
            .unwrap()
            .to_string()
    };
    let pfm = member(pkg, &path("geometryWarpFile"));
    // "PF\n<w> <h>\n<scale>\n", then little-endian floats (the scale is negative).
    let mut fields = Vec::new();
    let mut at = 0;
    while fields.len() < 4 {
        let start = at;
        while !pfm[at].is_ascii_whitespace() {
            at += 1;
        }
        fields.push(String::from_utf8_lossy(&pfm[start..at]).into_owned());
        at += 1;
    }
    assert_eq!(fields[0], "PF");
    assert!(fields[3].parse::<f64>().unwrap() < 0.0, "little-endian");
    let (nx, ny): (usize, usize) = (fields[1].parse().unwrap(), fields[2].parse().unwrap());
    let float = |i: usize| f32::from_le_bytes(pfm[at + 4 * i..at + 4 * i + 4].try_into().unwrap());
    let mut uv = vec![[0.0f32; 2]; nx * ny];
    for disk_row in 0..ny {
        let row = if c.top_first {
            disk_row
        } else {
            ny - 1 - disk_row
        };
        for x in 0..nx {
            let i = (disk_row * nx + x) * 3;
            uv[row * nx + x] = [float(i), float(i + 1)];
        }
    }
    let png = image::load_from_memory(&member(pkg, &path("alphaMap"))).unwrap();
    RegionRead {
        rect: [f("x"), f("y"), f("xsize"), f("ysize")],
        size: [f("Xresolution") as usize, f("Yresolution") as usize],
        nodes: [nx, ny],
        uv,
        alpha: png.to_luma8().into_raw(),
        beta: has("betaMap").then(|| {
            image::load_from_memory(&member(pkg, &path("betaMap")))
                .unwrap()
                .to_luma8()
                .into_raw()
        }),
    }
}

/// The four nodes around fractional node index (gx, gy) of an nx × ny grid and their bilinear
/// weights.
fn corners(gx: f64, gy: f64, nx: usize, ny: usize) -> [(usize, usize, f64); 4] {
    let (x0, y0) = ((gx as usize).min(nx - 2), (gy as usize).min(ny - 2));
    let (fx, fy) = (gx - x0 as f64, gy - y0 as f64);
    [
        (x0, y0, (1.0 - fx) * (1.0 - fy)),
        (x0 + 1, y0, fx * (1.0 - fy)),
        (x0, y0 + 1, (1.0 - fx) * fy),
        (x0 + 1, y0 + 1, fx * fy),
    ]
}

/// Bilinear at pixel-centre coordinates, clamped to the image.
fn sample(img: &image::RgbaImage, x: f64, y: f64) -> [f64; 3] {
    let (w, h) = (img.width() as f64, img.height() as f64);
    let (x, y) = (x.clamp(0.0, w - 1.0), y.clamp(0.0, h - 1.0));
    let (x0, y0) = (x.floor() as u32, y.floor() as u32);
    let (x1, y1) = (
        (x0 + 1).min(img.width() - 1),
        (y0 + 1).min(img.height() - 1),
    );
    let (fx, fy) = (x - f64::from(x0), y - f64::from(y0));
    let mut out = [0.0; 3];
    for (px, py, wt) in [
        (x0, y0, (1.0 - fx) * (1.0 - fy)),
        (x1, y0, fx * (1.0 - fy)),
        (x0, y1, (1.0 - fx) * fy),
        (x1, y1, fx * fy),
    ] {
        let p = img.get_pixel(px, py).0;
        for k in 0..3 {
            out[k] += wt * f64::from(p[k]);
        }
    }
    out
}

/// What the reader shows for the region: per pixel the warp interpolated between nodes, the
/// media sampled where it says, times the alpha map (stored with its gamma, so in signal
/// space), lifted by the beta map if there is one, `colour · alpha · (1 − beta) + beta` as
/// SGCT and nDisplay apply it. Transparent where a weighted node is unknown or alpha is 0.
fn show(r: &RegionRead, c: Conventions, media: &image::RgbaImage) -> image::RgbaImage {
    let [w, h] = r.size;
    let [nx, ny] = r.nodes;
    let node = |p: usize, size: usize, n: usize| {
        let t = (p as f64 + 0.5) / size as f64;
        if c.centres {
            (t * n as f64 - 0.5).clamp(0.0, (n - 1) as f64)
        } else {
            t * (n - 1) as f64
        }
    };
    let [x, y, xs, ys] = r.rect;
    let (mw, mh) = (f64::from(media.width()), f64::from(media.height()));
    image::RgbaImage::from_fn(w as u32, h as u32, |i, j| {
        let (gx, gy) = (node(i as usize, w, nx), node(j as usize, h, ny));
        let mut uv = [0.0f64; 2];
        for (px, py, wt) in corners(gx, gy, nx, ny) {
            if wt == 0.0 {
                continue;
            }
            let n = r.uv[py * nx + px];
            if n[0].is_nan() || n[1].is_nan() {
                return image::Rgba([0; 4]);
            }
            uv[0] += wt * f64::from(n[0]);
            uv[1] += wt * f64::from(n[1]);
        }
        let a = f64::from(r.alpha[j as usize * w + i as usize]) / 255.0;
        if a == 0.0 {
            return image::Rgba([0; 4]);
        }
        let mu = x + uv[0] * xs;
        let t = y + uv[1] * ys;
        let mv = if c.v_up { 1.0 - t } else { t };
        let col = sample(media, mu * mw - 0.5, mv * mh - 0.5);
        let b = r
            .beta
            .as_ref()
            .map_or(0.0, |b| f64::from(b[j as usize * w + i as usize]) / 255.0);
        let out = |c: f64| (c * a * (1.0 - b) + 255.0 * b).round() as u8;
        image::Rgba([out(col[0]), out(col[1]), out(col[2]), 255])
    })
}

/// PSNR over the pixels `reference` shows (alpha > 0); those must be most of the image.
fn psnr(reference: &image::RgbaImage, got: &image::RgbaImage) -> f64 {
    assert_eq!(reference.dimensions(), got.dimensions());
    let (mut se, mut n) = (0.0, 0usize);
    for (a, b) in reference.pixels().zip(got.pixels()) {
        if a.0[3] > 0 {
            n += 1;
            for k in 0..3 {
                se += (f64::from(a.0[k]) - f64::from(b.0[k])).powi(2);
            }
        }
    }
    assert!(n * 2 > reference.len() / 4, "only {n} pixels shown");
    10.0 * (255.0f64.powi(2) / (se / (3 * n) as f64)).log10()
}

struct Case {
    dir: tempfile::TempDir,
    media: image::RgbaImage,
}

impl Case {
    /// The fixture's inputs: its rig, and the content the real readers were given.
    fn new() -> Case {
        let dir = tempfile::tempdir().unwrap();
        let content = dir.path().join("content.png");
        omniwarp(&[
            "pattern",
            "--pattern",
            "smooth",
            "--size",
            "1024x512",
            "--out",
            content.to_str().unwrap(),
        ]);
        let media = image::open(&content).unwrap().to_rgba8();
        Case { dir, media }
    }

    fn path(&self, name: &str) -> String {
        self.dir.path().join(name).to_str().unwrap().to_string()
    }

    fn export(&self, reader: &str) -> Vec<u8> {
        self.export_rig(&fixtures().join("rig.json"), reader)
    }

    fn export_rig(&self, rig: &Path, reader: &str) -> Vec<u8> {
        let out = self.path(&format!("{reader}.mpcdi"));
        omniwarp(&[
            "export",
            "--rig",
            rig.to_str().unwrap(),
            "--format",
            "mpcdi",
            "--projection",
            "equirect",
            "--hfov",
            "360",
            "--vfov",
            "180",
            "--content-size",
            "1024x512",
            "--reader",
            reader,
            "--out",
            &out,
        ]);
        std::fs::read(out).unwrap()
    }

    fn render(&self, channel: &str) -> image::RgbaImage {
        self.render_rig(&fixtures().join("rig.json"), channel, "content.png")
    }

    fn render_rig(&self, rig: &Path, channel: &str, content: &str) -> image::RgbaImage {
        let out = self.path(&format!("ref-{channel}.png"));
        omniwarp(&[
            "render",
            "--rig",
            rig.to_str().unwrap(),
            "--channel",
            channel,
            "--content",
            &self.path(content),
            "--content-format",
            "equirect",
            "--out",
            &out,
        ]);
        image::open(out).unwrap().to_rgba8()
    }
}

const CHANNELS: [&str; 3] = ["left", "centre", "right"];

#[test]
fn each_reader_shows_omniwarps_render_from_the_package_written_for_it() {
    let case = Case::new();
    let refs: Vec<_> = CHANNELS.iter().map(|ch| case.render(ch)).collect();
    for (reader, c) in [
        ("vesa", VESA),
        ("ndisplay", VESA),
        ("watchout", VESA),
        ("pympcdi", PYMPCDI),
        ("sgct", SGCT),
    ] {
        let pkg = case.export(reader);
        let xml = String::from_utf8(member(&pkg, "mpcdi.xml")).unwrap();
        // The buffer is the content canvas; a region is the part of it a projector shows.
        assert!(
            xml.contains(r#"<buffer id="buffer0" Xresolution="1024" Yresolution="512">"#),
            "{reader}: {xml}"
        );
        let version = if reader == "watchout" { "1.0" } else { "2.0" };
        assert!(xml.contains(&format!(r#"version="{version}""#)), "{reader}");
        for (ch, reference) in CHANNELS.iter().zip(&refs) {
            let r = read_region(&pkg, ch, c);
            assert!(
                r.rect[2] < 0.5 && r.rect[3] < 0.5,
                "{reader} {ch}: {:?}",
                r.rect
            );
            let db = psnr(reference, &show(&r, c, &case.media));
            eprintln!(
                "{reader} {ch}: {db:.2} dB, {}×{} nodes",
                r.nodes[0], r.nodes[1]
            );
            assert!(db >= 40.0, "{reader} {ch}: {db:.2} dB");
        }
    }
    // Read with another reader's conventions, a package shows the wrong picture: the profiles
    // are not interchangeable, so the test above could not pass by accident.
    let pkg = case.export("vesa");
    for c in [PYMPCDI, SGCT] {
        let db = psnr(
            &refs[1],
            &show(&read_region(&pkg, "centre", c), c, &case.media),
        );
        assert!(db < 20.0, "{c:?}: {db:.2} dB");
    }
}

/// Projectors with a contrast: the package carries each region's black lift as a beta map, and a
/// VESA reader applying it shows what `omniwarp render` shows, in the dark and in the light.
#[test]
fn a_package_for_projectors_with_a_contrast_carries_their_black_lift() {
    let case = Case::new();
    let mut doc: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(fixtures().join("rig.json")).unwrap())
            .unwrap();
    for ch in doc["channels"].as_array_mut().unwrap() {
        ch["contrast"] = 2000.into();
    }
    let rig = case.dir.path().join("contrast.json");
    std::fs::write(&rig, doc.to_string()).unwrap();
    let black = image::RgbaImage::from_pixel(1024, 512, image::Rgba([0, 0, 0, 255]));
    black.save(case.path("black.png")).unwrap();

    let pkg = case.export_rig(&rig, "vesa");
    let xml = String::from_utf8(member(&pkg, "mpcdi.xml")).unwrap();
    assert!(
        xml.contains(r#"level="2""#) && xml.contains("<path>BetaMap-left.png</path>"),
        "{xml}"
    );
    for ch in CHANNELS {
        let r = read_region(&pkg, ch, VESA);
        assert!(r.beta.is_some(), "{ch}: no beta map");
        for (content, media) in [("black.png", &black), ("content.png", &case.media)] {
            let reference = case.render_rig(&rig, ch, content);
            let db = psnr(&reference, &show(&r, VESA, media));
            eprintln!("{ch} {content}: {db:.2} dB with the beta map");
            // Black is exact. Between black and white the reader's sum in signal space lifts
            // a signal S by b·(1 − S) where ours lifts the light (docs/photometry.md): a few
            // levels of 255 in the darks at 2,000:1.
            let floor = if content == "black.png" { 50.0 } else { 35.0 };
            assert!(db >= floor, "{ch} {content}: {db:.2} dB");
            if content == "black.png" {
                let lifted = reference.pixels().filter(|p| p.0[0] > 0).count();
                assert!(
                    lifted > reference.len() / 40,
                    "{ch}: {lifted} pixels lifted"
                );
                // Without its beta map the reader shows the black unlifted, the bright seams
                // back: the comparison above could not pass by accident.
                let plain = RegionRead {
                    beta: None,
                    ..read_region(&pkg, ch, VESA)
                };
                let db = psnr(&reference, &show(&plain, VESA, media));
                eprintln!("{ch} {content}: {db:.2} dB without it");
                assert!(db < 40.0, "{ch}: {db:.2} dB without the beta map");
            }
        }
    }
    // Projectors without a contrast: no beta map, level 1, as before.
    let xml = String::from_utf8(member(&case.export("vesa"), "mpcdi.xml")).unwrap();
    assert!(!xml.contains("betaMap") && xml.contains(r#"level="1""#));
}

#[test]
fn todays_packages_show_what_the_real_readers_showed() {
    let case = Case::new();
    let recorded = std::fs::read_to_string(fixtures().join("COMMANDS.txt")).unwrap();
    // The fixtures were made from this content: if the pattern changed, they must be remade.
    let fnv = case
        .media
        .as_raw()
        .iter()
        .fold(0xcbf2_9ce4_8422_2325u64, |h, &b| {
            (h ^ u64::from(b)).wrapping_mul(0x0100_0000_01b3)
        });
    assert!(
        recorded.contains("1024x512"),
        "the fixtures' content is the 1024×512 smooth pattern"
    );
    assert_eq!(
        fnv, 0x3d5e_af0f_ce65_fe4f,
        "the smooth pattern changed: remake calibration/fixtures/interop"
    );
    for (reader, c) in [("vesa", VESA), ("pympcdi", PYMPCDI)] {
        let pkg = case.export(reader);
        for ch in CHANNELS {
            let real = image::open(fixtures().join(format!("{reader}-{ch}.png")))
                .unwrap()
                .to_rgba8();
            let ours = show(&read_region(&pkg, ch, c), c, &case.media);
            // Compared where our reader shows the picture (the real PyMPCDI frame is opaque
            // black where the region shows nothing).
            let db = psnr(&ours, &real);
            eprintln!("{reader} {ch}: {db:.2} dB against the real reader's frame");
            assert!(db >= 35.0, "{reader} {ch}: {db:.2} dB");
        }
    }
}

impl Case {
    /// One of the centre channel's single-channel exports, by `--format`.
    fn export_centre(&self, format: &str, out: &str, extra: &[&str]) -> String {
        let rig = fixtures().join("rig.json");
        let path = self.path(out);
        let mut args = vec![
            "export",
            "--rig",
            rig.to_str().unwrap(),
            "--channel",
            "centre",
            "--format",
            format,
            "--projection",
            "equirect",
            "--hfov",
            "360",
            "--vfov",
            "180",
            "--content-size",
            "1024x512",
            "--out",
            &path,
        ];
        args.extend_from_slice(extra);
        omniwarp(&args);
        path
    }

    /// The centre channel's warp rendered without its blend (what the single-channel exports
    /// map), with `filter`.
    fn render_unblended(&self, filter: &str) -> image::RgbaImage {
        let rig = fixtures().join("rig.json");
        let warp = self.path("centre.exr");
        omniwarp(&[
            "warp",
            "--rig",
            rig.to_str().unwrap(),
            "--channel",
            "centre",
            "--out",
            &warp,
        ]);
        let out = self.path(&format!("unblended-{filter}.png"));
        omniwarp(&[
            "render",
            "--normal-map",
            &warp,
            "--content",
            &self.path("content.png"),
            "--content-format",
            "equirect",
            "--filter",
            filter,
            "--out",
            &out,
        ]);
        image::open(out).unwrap().to_rgba8()
    }
}

/// An image of `w` × `h` showing the content where `at` maps pixel (i, j) (content pixels,
/// pixel-centre coordinates), transparent where it maps nothing.
fn shown(w: usize, h: usize, at: impl Fn(usize, usize) -> Option<[f64; 3]>) -> image::RgbaImage {
    image::RgbaImage::from_fn(w as u32, h as u32, |i, j| {
        match at(i as usize, j as usize) {
            Some(c) => image::Rgba([
                c[0].round() as u8,
                c[1].round() as u8,
                c[2].round() as u8,
                255,
            ]),
            None => image::Rgba([0; 4]),
        }
    })
}

/// The ST-map, the 2d PFM and ffmpeg's remap maps, read as Nuke (u across, v up), OpenCV (the
/// PFM's rows bottom-up on disk, nodes edge to edge) and ffmpeg (absolute pixels, 65535 for
/// none) read them, show omniwarp's render; and what OpenImageIO, OpenCV and ffmpeg themselves
/// showed (calibration/interop/make_channel_fixtures.sh) is still what today's exports show.
#[test]
fn single_channel_exports_show_what_oiio_opencv_and_ffmpeg_showed() {
    let case = Case::new();
    let media = &case.media;
    let (cw, ch) = (f64::from(media.width()), f64::from(media.height()));
    let bilinear = case.render_unblended("bilinear");
    let nearest = case.render_unblended("nearest");
    let (w, h) = (bilinear.width() as usize, bilinear.height() as usize);
    let real = |name: &str| image::open(fixtures().join(name)).unwrap().to_rgba8();

    let st = case.export_centre("stmap", "st.exr", &[]);
    let (stmap, _) = omniwarp::image_io::read_exr_rgba(Path::new(&st)).unwrap();
    let ours = shown(w, h, |i, j| {
        let [u, v, _, a] = stmap.data[j * w + i];
        (a > 0.0).then(|| {
            sample(
                media,
                f64::from(u) * cw - 0.5,
                (1.0 - f64::from(v)) * ch - 0.5,
            )
        })
    });
    let (db, db_real) = (
        psnr(&bilinear, &ours),
        psnr(&ours, &real("oiio-stmap-centre.png")),
    );
    eprintln!("stmap: {db:.2} dB vs render, {db_real:.2} dB vs OpenImageIO's");
    assert!(db >= 40.0 && db_real >= 35.0, "{db} {db_real}");

    let pfm = std::fs::read(case.export_centre("pfm2d", "g.pfm", &[])).unwrap();
    let text = String::from_utf8_lossy(&pfm[..32]).to_string();
    let mut head = text.split_ascii_whitespace();
    assert_eq!(head.next(), Some("PF"));
    let nx: usize = head.next().unwrap().parse().unwrap();
    let ny: usize = head.next().unwrap().parse().unwrap();
    let body = &pfm[pfm.len() - nx * ny * 12..];
    // Bottom row first on disk.
    let node = |x: usize, y: usize| {
        let k = ((ny - 1 - y) * nx + x) * 12;
        let f = |o: usize| {
            f64::from(f32::from_le_bytes(
                body[k + o..k + o + 4].try_into().unwrap(),
            ))
        };
        [f(0), f(4)]
    };
    let ours = shown(w, h, |i, j| {
        let gx = (i as f64 + 0.5) / w as f64 * (nx - 1) as f64;
        let gy = (j as f64 + 0.5) / h as f64 * (ny - 1) as f64;
        let mut uv = [0.0; 2];
        for (x, y, wt) in corners(gx, gy, nx, ny) {
            let n = node(x, y);
            uv = [uv[0] + wt * n[0], uv[1] + wt * n[1]];
        }
        (uv.iter().all(|c| (0.0..=1.0).contains(c)))
            .then(|| sample(media, uv[0] * cw - 0.5, uv[1] * ch - 0.5))
    });
    let (db, db_real) = (
        psnr(&bilinear, &ours),
        psnr(&ours, &real("opencv-pfm2d-centre.png")),
    );
    eprintln!("pfm2d: {db:.2} dB vs render, {db_real:.2} dB vs OpenCV's");
    assert!(db >= 40.0 && db_real >= 35.0, "{db} {db_real}");

    let xmap =
        std::fs::read(case.export_centre("remap", "x.pgm", &["--ymap", &case.path("y.pgm")]))
            .unwrap();
    let ymap = std::fs::read(case.path("y.pgm")).unwrap();
    let at = |pgm: &[u8], n: usize| {
        let k = pgm.len() - (w * h - n) * 2;
        u16::from_be_bytes([pgm[k], pgm[k + 1]])
    };
    let ours = shown(w, h, |i, j| {
        let (x, y) = (at(&xmap, j * w + i), at(&ymap, j * w + i));
        (x != 65535 && y != 65535).then(|| {
            let p = media.get_pixel(u32::from(x), u32::from(y)).0;
            [f64::from(p[0]), f64::from(p[1]), f64::from(p[2])]
        })
    });
    let (db, db_real) = (
        psnr(&nearest, &ours),
        psnr(&ours, &real("ffmpeg-remap-centre.png")),
    );
    eprintln!("remap: {db:.2} dB vs render --filter nearest, {db_real:.2} dB vs ffmpeg's");
    assert!(db >= 40.0 && db_real >= 35.0, "{db} {db_real}");
}
