//! Black-level compensation end to end (issue 47): the demo cylinder's three projectors and the
//! example dome's five at 2,000:1, each channel rendered by `omniwarp render --rig`, and the light the wall gets summed
//! over the projectors as the model has it (docs/photometry.md): a projector of black k whose
//! pixel puts out o (the signal decoded with γ 2.2) lights the wall with k + (1 − k)·o. The wall
//! is seen as a camera would, averaged over 2° × 2° patches.

use omniwarp::rig::{Rig, RigDoc};
use rayon::prelude::*;
use std::path::Path;
use std::process::Command;

const CONTRAST: f64 = 2000.0;

fn root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

/// Renders every channel of `rig` showing a flat grey `level` (0–255) through the CLI; the
/// pictures in the rig's channel order.
fn render_all(dir: &Path, rig: &Path, ids: &[String], level: u8) -> Vec<image::RgbaImage> {
    let content = dir.join(format!("flat-{level}.png"));
    image::RgbImage::from_pixel(64, 32, image::Rgb([level; 3]))
        .save(&content)
        .unwrap();
    ids.iter()
        .map(|id| {
            let out = dir.join(format!("{id}-{level}.png"));
            let run = Command::new(env!("CARGO_BIN_EXE_omniwarp"))
                .args(["render", "--rig"])
                .arg(rig)
                .args(["--channel", id, "--content-format", "equirect", "--content"])
                .arg(&content)
                .arg("--out")
                .arg(&out)
                .output()
                .unwrap();
            assert!(
                run.status.success(),
                "{}",
                String::from_utf8_lossy(&run.stderr)
            );
            image::open(&out).unwrap().into_rgba8()
        })
        .collect()
}

/// The wall's light in 2° × 2° patches (of azimuth and elevation, all round the eye up to 70°
/// from the horizon: nearer the zenith a patch shrinks to a few projector pixels) lit all
/// over and away from the wall's edge (their eight neighbours lit too): the mean over 8 × 8
/// directions of the sum over projectors of k + (1 − k)·o, o from `pictures` (the light of the
/// projector's pixels around the one lighting the point, or 0 for `None`, an uncompensated
/// black).
fn patches(rig: &Rig, pictures: Option<&[image::RgbaImage]>) -> Vec<f64> {
    let (step, per) = (2.0f64, 8);
    let cells: Vec<(i32, i32)> = (-90..90)
        .flat_map(|a| (-35..35).map(move |e| (a, e)))
        .collect();
    let lit: std::collections::HashMap<(i32, i32), f64> = cells
        .par_iter()
        .filter_map(|&(a, e)| {
            let mut sum = 0.0;
            for s in 0..per * per {
                let az = (f64::from(a) + ((s % per) as f64 + 0.5) / per as f64) * step;
                let el = (f64::from(e) + ((s / per) as f64 + 0.5) / per as f64) * step;
                let (az, el) = (az.to_radians(), el.to_radians());
                let dir = glam::DVec3::new(az.sin() * el.cos(), el.sin(), -az.cos() * el.cos());
                let p = rig.doc.screen.intersect(rig.eye, dir).point()?;
                let mut light = 0.0;
                let mut lit = false;
                for (n, ch) in rig.channels.iter().enumerate() {
                    let Some(q) = rig.pixel_lighting(ch, p) else {
                        continue;
                    };
                    lit = true;
                    let k = ch.black();
                    let o = pictures.map_or(0.0, |pics| block_light(&pics[n], q));
                    light += k + (1.0 - k) * o;
                }
                if !lit {
                    return None;
                }
                sum += light;
            }
            Some(((a, e), sum / (per * per) as f64))
        })
        .collect();
    lit.iter()
        .filter(|((a, e), _)| {
            (-1..=1).all(|da| (-1..=1).all(|de| lit.contains_key(&(a + da, e + de))))
        })
        .map(|(_, v)| *v)
        .collect()
}

/// The light of the 4 × 4 projector pixels around `q`, averaged as a camera pixel spanning them
/// would see it (a point sample would alias with the dither of the lift).
fn block_light(pic: &image::RgbaImage, q: [f64; 2]) -> f64 {
    let (w, h) = (i64::from(pic.width()), i64::from(pic.height()));
    let (x0, y0) = (q[0].floor() as i64 - 1, q[1].floor() as i64 - 1);
    let mut sum = 0.0;
    for dy in 0..4 {
        for dx in 0..4 {
            let (x, y) = ((x0 + dx).clamp(0, w - 1), (y0 + dy).clamp(0, h - 1));
            let v = pic.get_pixel(x as u32, y as u32)[0];
            sum += (f64::from(v) / 255.0).powf(2.2);
        }
    }
    sum / 16.0
}

/// Max over min of the patches, and their count.
fn spread(v: &[f64]) -> (f64, usize) {
    let max = v.iter().copied().fold(0.0, f64::max);
    let min = v.iter().copied().fold(f64::INFINITY, f64::min);
    (max / min, v.len())
}

/// `rig` (a file of calibration/rigs/) with every projector at [`CONTRAST`]: its path in `dir`
/// and the rig.
fn with_contrast(dir: &Path, rig: &str) -> (std::path::PathBuf, serde_json::Value, Rig) {
    let mut doc: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(root().join("calibration/rigs").join(rig)).unwrap(),
    )
    .unwrap();
    for ch in doc["channels"].as_array_mut().unwrap() {
        ch["contrast"] = CONTRAST.into();
    }
    let path = dir.join(rig);
    std::fs::write(&path, doc.to_string()).unwrap();
    let parsed = Rig::from_doc(RigDoc::parse(&doc.to_string()).unwrap()).unwrap();
    (path, doc, parsed)
}

#[test]
fn a_black_frame_is_evenly_black_across_the_overlaps() {
    // Where most projectors overlap: two on the cylinder, three on the dome.
    for (file, overlap) in [
        ("cylinder-270-3proj.json", 2.0),
        ("dome-180-tilt15-5proj.json", 3.0),
    ] {
        let dir = tempfile::tempdir().unwrap();
        let (path, _, rig) = with_contrast(dir.path(), file);
        let ids: Vec<String> = rig.channels.iter().map(|c| c.id.clone()).collect();

        let (before, n) = spread(&patches(&rig, None));
        let black = render_all(dir.path(), &path, &ids, 0);
        let (after, m) = spread(&patches(&rig, Some(&black)));
        let grey = render_all(dir.path(), &path, &ids, 128);
        let (grey, _) = spread(&patches(&rig, Some(&grey)));
        eprintln!(
            "{file}: black frame, brightest over darkest of {n} patches: {before:.3} \
             uncompensated, {after:.3} compensated; 50 % grey {grey:.3}"
        );
        assert!(n > 1000 && n == m, "{file}: {n} and {m} patches lit");
        assert!(
            before > overlap * 0.95,
            "{file}: uncompensated spread {before}"
        );
        assert!(after < 1.05, "{file}: compensated black spread {after}");
        assert!(grey < 1.05, "{file}: 50 % grey spread {grey}");
    }
}

/// `omniwarp blend` writes each channel's black lift beside its blend mask, the very lift the
/// renderer adds: where the content is black, the rendered picture is the black mask.
#[test]
fn the_black_mask_is_the_lift_the_renderer_adds() {
    let dir = tempfile::tempdir().unwrap();
    let (path, mut doc, _) = with_contrast(dir.path(), "cylinder-270-3proj.json");
    let out = dir.path().join("masks");
    let run = Command::new(env!("CARGO_BIN_EXE_omniwarp"))
        .args(["blend", "--rig"])
        .arg(&path)
        .arg("--out-dir")
        .arg(&out)
        .output()
        .unwrap();
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    let black = render_all(dir.path(), &path, &["left".to_string()], 0).remove(0);
    let mask = image::open(out.join("left-black.png"))
        .unwrap()
        .into_luma16();
    let (mut lifted, mut worst) = (0, 0i32);
    for (x, y, m) in mask.enumerate_pixels() {
        let rendered = i32::from(black.get_pixel(x, y)[0]);
        let masked = (f64::from(m[0]) / 257.0).round() as i32;
        worst = worst.max((rendered - masked).abs());
        lifted += usize::from(masked > 0);
    }
    assert!(lifted > 100_000, "{lifted} pixels lifted");
    assert!(worst <= 1, "render and black mask differ by {worst} of 255");

    // Without contrasts there is nothing to lift and no black mask; a contrast of 1 or less
    // (black as bright as white) is refused naming the field.
    std::fs::write(
        &path,
        std::fs::read(root().join("calibration/rigs/cylinder-270-3proj.json")).unwrap(),
    )
    .unwrap();
    let plain = dir.path().join("plain");
    let run = Command::new(env!("CARGO_BIN_EXE_omniwarp"))
        .args(["blend", "--rig"])
        .arg(&path)
        .arg("--out-dir")
        .arg(&plain)
        .output()
        .unwrap();
    assert!(run.status.success());
    assert!(plain.join("left.png").exists() && !plain.join("left-black.png").exists());
    doc["channels"][1]["contrast"] = 0.5.into();
    std::fs::write(&path, doc.to_string()).unwrap();
    let run = Command::new(env!("CARGO_BIN_EXE_omniwarp"))
        .args(["rig", "check"])
        .arg(&path)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&run.stderr);
    assert!(
        !run.status.success()
            && err.contains("/channels/1/contrast")
            && err.contains("more than 1"),
        "{err}"
    );
}
