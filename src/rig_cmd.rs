//! `omniwarp warp`, `omniwarp blend` and the rig side of `omniwarp render`.

use anyhow::{Context, Result};
use clap::Args;
use omniwarp::image_io::{self, Precision};
use omniwarp::normalmap::NormalMap;
use omniwarp::rig::{BlendOptions, Rig, write_blend_png};
use std::path::{Path, PathBuf};
use std::time::Instant;

#[derive(Args)]
pub struct WarpArgs {
    /// Rig file (JSON).
    #[arg(long)]
    rig: PathBuf,
    /// Channel id.
    #[arg(long)]
    channel: String,
    /// Warp map (EXR): R,G,B = content sampling vector, A = 1 where the pixel lights the wall.
    #[arg(long)]
    out: PathBuf,
    /// Also write the wall point of every pixel (EXR, metres; A = validity).
    #[arg(long)]
    wall: Option<PathBuf>,
    /// Store half floats.
    #[arg(long)]
    half: bool,
}

#[derive(Args)]
pub struct BlendArgs {
    /// Rig file (JSON).
    #[arg(long)]
    rig: PathBuf,
    /// Directory for one 16-bit PNG per channel, `<id>.png`.
    #[arg(long)]
    out_dir: PathBuf,
    /// Projector gamma the masks are encoded for (m = w^(1/gamma)).
    #[arg(long, default_value_t = 2.2)]
    gamma: f64,
}

pub fn read_rig(path: &Path) -> Result<Rig> {
    Rig::read(path).with_context(|| "--rig".to_string())
}

fn channel<'a>(rig: &'a Rig, id: &str) -> Result<&'a omniwarp::rig::Channel> {
    rig.channel(id)
        .map_err(|e| anyhow::anyhow!("--channel: {}", e.reason()))
}

pub fn warp(a: WarpArgs) -> Result<()> {
    let rig = read_rig(&a.rig)?;
    let ch = channel(&rig, &a.channel)?;
    for path in std::iter::once(&a.out).chain(&a.wall) {
        if !path
            .extension()
            .is_some_and(|e| e.eq_ignore_ascii_case("exr"))
        {
            anyhow::bail!("--out: {} must end in .exr", path.display());
        }
    }
    let t = Instant::now();
    let w = rig.warp(ch);
    let ms = t.elapsed().as_secs_f64() * 1e3;
    let lit = w.points.iter().filter(|p| p.is_some()).count();
    eprintln!(
        "{}: {}×{} warp in {ms:.0} ms ({:.1} Mpixel/s), {:.1} % of pixels light the wall",
        ch.id,
        ch.width,
        ch.height,
        f64::from(ch.width) * f64::from(ch.height) / ms / 1e3,
        100.0 * lit as f64 / w.points.len() as f64
    );
    let precision = if a.half {
        Precision::Half
    } else {
        Precision::Float
    };
    w.map.write(&a.out, precision)?;
    if let Some(path) = &a.wall {
        image_io::write_exr_rgba(path, &w.wall, &w.map.attributes, precision)?;
    }
    Ok(())
}

pub fn blend(a: BlendArgs) -> Result<()> {
    let rig = read_rig(&a.rig)?;
    std::fs::create_dir_all(&a.out_dir)
        .with_context(|| format!("--out-dir {}", a.out_dir.display()))?;
    let opts = BlendOptions { gamma: a.gamma };
    for ch in &rig.channels {
        let t = Instant::now();
        let w = rig.warp(ch);
        let weights = rig.blend_weights(ch, &w.points);
        let path = a.out_dir.join(format!("{}.png", ch.id));
        write_blend_png(&path, ch.width, ch.height, &weights, opts)
            .map_err(|e| anyhow::anyhow!("--gamma: {}", e.reason()))?;
        eprintln!(
            "{}: warp and blend in {:.0} ms → {}",
            ch.id,
            t.elapsed().as_secs_f64() * 1e3,
            path.display()
        );
    }
    Ok(())
}

/// A channel's warp map and its blend mask in signal space, for `render --rig`.
pub fn render_inputs(path: &Path, id: &str, gamma: f64) -> Result<(NormalMap, Vec<f32>)> {
    let rig = read_rig(path)?;
    let ch = channel(&rig, id)?;
    let w = rig.warp(ch);
    let mask = rig
        .blend_weights(ch, &w.points)
        .iter()
        .map(|&x| (f64::from(x).powf(1.0 / gamma)) as f32)
        .collect();
    Ok((w.map, mask))
}

/// `omniwarp warp-bench`: warp generation for a 3840×2160 projector on each surface type, and
/// blend computation for the five-projector dome example.
pub fn bench(dome_rig: &Path) -> Result<()> {
    use omniwarp::surface::{Cylinder, Dome, Mesh, Plane, Screen};
    let cylinder = Cylinder {
        radius: 2.0,
        centre: [0.0; 3],
        axis: [0.0, 1.0, 0.0],
        height: [-2.0, 2.0],
        arc: [-180.0, 180.0],
    };
    let (n_az, n_h) = (720, 16);
    let mut tris = Vec::new();
    let at = |i: usize, j: usize| {
        let az = (-180.0 + 360.0 * i as f64 / n_az as f64).to_radians();
        glam::DVec3::new(
            2.0 * az.sin(),
            -2.0 + 4.0 * j as f64 / n_h as f64,
            -2.0 * az.cos(),
        )
    };
    for i in 0..n_az {
        for j in 0..n_h {
            tris.push([at(i, j), at(i + 1, j), at(i + 1, j + 1)]);
            tris.push([at(i, j), at(i + 1, j + 1), at(i, j + 1)]);
        }
    }
    let screens = [
        ("cylinder", Screen::Cylinder(cylinder)),
        (
            "dome",
            Screen::Dome(Dome {
                radius: 3.0,
                centre: [0.0; 3],
                tilt: 15.0,
                min_elevation: -30.0,
            }),
        ),
        (
            "plane",
            Screen::Plane(Plane {
                centre: [0.0, 0.0, -3.0],
                normal: [0.0, 0.0, 1.0],
                up: [0.0, 1.0, 0.0],
                width: 12.0,
                height: 8.0,
            }),
        ),
        (
            "mesh (23k triangles)",
            Screen::Mesh {
                obj: String::new(),
                loaded: Some(std::sync::Arc::new(Mesh::new(tris)?)),
            },
        ),
    ];
    for lens in ["LENSMODEL_PINHOLE", "LENSMODEL_OPENCV5"] {
        let intrinsics: Vec<f64> = match lens {
            "LENSMODEL_PINHOLE" => vec![2400.0, 2400.0, 1919.5, 1079.5],
            _ => vec![
                2400.0, 2400.0, 1919.5, 1079.5, -0.05, 0.01, 0.0005, -0.0003, -0.002,
            ],
        };
        for (name, screen) in &screens {
            let doc = omniwarp::rig::RigDoc {
                format: 1,
                screen: screen.clone(),
                eye: [0.0; 3],
                content: Default::default(),
                channels: vec![omniwarp::rig::ChannelDoc {
                    id: "p".into(),
                    resolution: [3840, 2160],
                    lens: omniwarp::rig::LensDoc {
                        model: lens.into(),
                        intrinsics: intrinsics.clone(),
                    },
                    pose: omniwarp::rig::PoseDoc {
                        position: [0.0, 0.3, 0.5],
                        look_to: Some([0.0, 0.0, -1.0]),
                        look_up: Some([0.0, 1.0, 0.0]),
                        rvec: None,
                    },
                }],
            };
            let rig = Rig::from_doc(doc)?;
            let t = Instant::now();
            let w = rig.warp(&rig.channels[0]);
            let s = t.elapsed().as_secs_f64();
            std::hint::black_box(&w);
            println!(
                "warp 3840×2160, {lens:<18} on {name:<22} {:>7.0} ms  {:>5.1} Mpixel/s",
                s * 1e3,
                3840.0 * 2160.0 / s / 1e6
            );
        }
    }
    let rig = read_rig(dome_rig)?;
    let t = Instant::now();
    let warps: Vec<_> = rig.channels.iter().map(|c| rig.warp(c)).collect();
    let tw = t.elapsed().as_secs_f64();
    let t = Instant::now();
    for (c, w) in rig.channels.iter().zip(&warps) {
        std::hint::black_box(rig.blend_weights(c, &w.points));
    }
    println!(
        "dome example, {} projectors of {}×{}: warps {:.0} ms, blends {:.0} ms",
        rig.channels.len(),
        rig.channels[0].width,
        rig.channels[0].height,
        tw * 1e3,
        t.elapsed().as_secs_f64() * 1e3
    );
    Ok(())
}

#[derive(Clone, Copy, clap::ValueEnum)]
pub enum ExportFormat {
    /// ST-map EXR: R = u, G = v of the content image, origin bottom-left, A = validity.
    Stmap,
    /// PFM of wall XYZ per projector pixel (MPCDI's a3 meaning), NaN where none.
    PfmA3,
    /// ffmpeg `remap` xmap (--out) and ymap (--ymap) as 16-bit PGM.
    Remap,
    /// PFM of content (x, y) on a grid sized from --tolerance (MPCDI's 2d meaning).
    Pfm2d,
    /// Paul Bourke warp mesh (type 2) on a grid sized from --tolerance.
    Mesh,
    /// The whole rig as an MPCDI v2.0 package, 2d profile (every channel, one canvas).
    Mpcdi,
    /// The whole rig as an MPCDI v2.0 package, a3 profile.
    MpcdiA3,
}

#[derive(Args)]
pub struct ExportArgs {
    /// Rig file (JSON).
    #[arg(long)]
    rig: PathBuf,
    /// Channel id (every format but the MPCDI packages).
    #[arg(long)]
    channel: Option<String>,
    #[arg(long, value_enum)]
    format: ExportFormat,
    /// Largest interpolation error of grid formats: content pixels (pfm2d, mesh, mpcdi) or
    /// millimetres (mpcdi-a3).
    #[arg(long)]
    tolerance: Option<f64>,
    /// The content canvas (for stmap and remap): its projection and view, as for `render`.
    #[command(flatten)]
    canvas: crate::cli::ProjectionArgs,
    /// Content image size WxH in pixels (stmap and remap).
    #[arg(long, value_parser = crate::cli::parse_size)]
    content_size: Option<(u32, u32)>,
    /// Output file.
    #[arg(long)]
    out: PathBuf,
    /// The ymap file for --format remap.
    #[arg(long)]
    ymap: Option<PathBuf>,
}

pub fn export(a: ExportArgs) -> Result<()> {
    use omniwarp::export::{self, channel::Sources, channel::Tolerance, mpcdi};
    let rig = read_rig(&a.rig)?;
    let size = || {
        a.content_size
            .context("--content-size: needed for this format")
    };
    let tolerance = |default: f64| {
        Tolerance::checked(a.tolerance.unwrap_or(default), "tolerance")
            .map_err(|e| anyhow::anyhow!("--tolerance: {}", e.reason()))
    };
    let write = |bytes: &[u8]| {
        omniwarp::image_io::atomic_write(&a.out, |f| {
            std::io::Write::write_all(f, bytes).map_err(|e| omniwarp::Error::file(&a.out, e))
        })
    };
    if let ExportFormat::Mpcdi | ExportFormat::MpcdiA3 = a.format {
        let (profile, tol) = match a.format {
            ExportFormat::Mpcdi => (mpcdi::Profile::TwoD, tolerance(0.5)?),
            _ => (mpcdi::Profile::A3, tolerance(1.0)?),
        };
        let (cw, chh) = match profile {
            mpcdi::Profile::TwoD => size()?,
            mpcdi::Profile::A3 => a.content_size.unwrap_or((1, 1)),
        };
        let canvas = match profile {
            mpcdi::Profile::TwoD => Some(a.canvas.view(cw, chh)?),
            mpcdi::Profile::A3 => None,
        };
        let mut regions = Vec::new();
        for ch in &rig.channels {
            let warp = rig.warp(ch);
            let uv = canvas
                .as_ref()
                .map(|c| export::content_uv_unbounded(&warp.map, c))
                .unwrap_or_else(|| vec![None; warp.points.len()]);
            let weights = rig.blend_weights(ch, &warp.points);
            let src = Sources {
                id: &ch.id,
                width: ch.width as usize,
                height: ch.height as usize,
                uv: &uv,
                content_size: [cw, chh],
                points: &warp.points,
                eye: rig.eye,
                weights: &weights,
            };
            let (region, err) = src.region(profile, tol)?;
            eprintln!(
                "{}: {}×{} grid, worst error {err:.4}",
                ch.id, region.warp.0, region.warp.1
            );
            regions.push(region);
        }
        let now = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| d.as_secs());
        write(&mpcdi::package(mpcdi::Version::V2, profile, &regions, now)?)?;
        return Ok(());
    }
    let id = a
        .channel
        .as_deref()
        .context("--channel: needed for this format")?;
    let ch = channel(&rig, id)?;
    let (w, h) = (ch.width as usize, ch.height as usize);
    let warp = rig.warp(ch);
    let canvas_uv = |size: Option<(u32, u32)>| -> Result<Vec<Option<[f64; 2]>>> {
        let (cw, chh) = size.context("--content-size: needed for this format")?;
        let canvas = a.canvas.view(cw, chh)?;
        Ok(export::content_uv(&warp.map, &canvas))
    };
    match a.format {
        ExportFormat::Stmap => export::write_stmap(&a.out, &canvas_uv(a.content_size)?, w, h)?,
        ExportFormat::PfmA3 => export::write_pfm(&a.out, w, h, &export::a3_samples(&warp.points))?,
        ExportFormat::Remap => {
            let ymap = a
                .ymap
                .as_ref()
                .context("--ymap: remap needs a second file for the rows")?;
            let (cw, chh) = size()?;
            export::write_remap_pgm(&a.out, ymap, &canvas_uv(a.content_size)?, w, h, [cw, chh])?;
        }
        ExportFormat::Pfm2d | ExportFormat::Mesh => {
            let (cw, chh) = size()?;
            let uv = export::content_uv_unbounded(&warp.map, &a.canvas.view(cw, chh)?);
            let weights = rig.blend_weights(ch, &warp.points);
            let src = Sources {
                id: &ch.id,
                width: w,
                height: h,
                uv: &uv,
                content_size: [cw, chh],
                points: &warp.points,
                eye: rig.eye,
                weights: &weights,
            };
            let tol = tolerance(0.5)?;
            if let ExportFormat::Mesh = a.format {
                let (text, c) = src.bourke(tol)?;
                eprintln!(
                    "{}×{} mesh, worst error {:.4} px",
                    c.grid.columns, c.grid.rows, c.max_error
                );
                write(text.as_bytes())?;
            } else {
                let (c, rows) = src.grid_2d(tol);
                eprintln!(
                    "{}×{} grid, worst error {:.4} px",
                    c.grid.columns, c.grid.rows, c.max_error
                );
                export::write_pfm(&a.out, c.grid.columns, c.grid.rows, &rows)?;
            }
        }
        ExportFormat::Mpcdi | ExportFormat::MpcdiA3 => unreachable!("handled above"),
    }
    Ok(())
}
