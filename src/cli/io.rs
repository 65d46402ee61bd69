//! Loading content and writing images for the commands that render: the pixel type follows the
//! files (8-bit PNG/JPEG, float EXR), and every write is atomic.

use super::args::{ContentArgs, ContentFormat, CubeLayoutArg, flag_error};
use anyhow::{Context, Result, bail};
use glam::DVec3;
use omniwarp::content::{Content, Fisheye, Format};
use omniwarp::cubemap::{CubeMap, Face};
use omniwarp::image_io::{self, Loaded, Precision};
use omniwarp::normalmap::NormalMap;
use omniwarp::projection::Orientation;
use omniwarp::raster::{Pixel, Raster};
use omniwarp::render::{self, Filter, Warp};
use omniwarp::rig::{Channel, ChannelBlend, Rig};
use omniwarp::tiles::TileScreen;
use omniwarp::tiles::adapt::Report;
use std::path::{Path, PathBuf};

/// Content in the pixel type the output needs: float when either side is float.
pub enum AnyContent {
    U8(Content<[u8; 4]>),
    F32(Content<[f32; 4]>),
}

pub fn load_content(a: &ContentArgs, want_float: bool) -> Result<AnyContent> {
    let path = a
        .content
        .as_ref()
        .context("--content: needed (render can take --scene instead)")?;
    let format = a
        .content_format
        .context("--content-format: needed with --content")?;
    let loaded = match format {
        ContentFormat::CubemapFaces => image_io::read_cube_faces(&path.to_string_lossy()),
        _ => image_io::read_image(path),
    }
    .context("--content")?;
    let orient =
        Orientation::yaw_pitch_roll(a.content_rotate.x, a.content_rotate.y, a.content_rotate.z)
            .map_err(flag_error)?;
    let lookup = a.content_lookup;
    let content = match loaded {
        Loaded::U8(r) if !want_float => {
            AnyContent::U8(lookup.apply(layout(a, &r)?.with_orientation(orient))?)
        }
        Loaded::U8(r) => {
            AnyContent::F32(lookup.apply(layout(a, &r.map(to_float))?.with_orientation(orient))?)
        }
        Loaded::F32(r) => AnyContent::F32(lookup.apply(layout(a, &r)?.with_orientation(orient))?),
    };
    Ok(content)
}

/// Content from an image as the content flags describe its layout (before orientation and
/// lookup): the first frame of a movie goes through here too.
pub fn layout<T: Pixel>(a: &ContentArgs, image: &Raster<T>) -> Result<Content<T>> {
    let format = a
        .content_format
        .context("--content-format: needed with --content")?
        .format();
    let fisheye = match format {
        Format::Fisheye => Some(Fisheye::FISHEYE),
        Format::Domemaster => Some(Fisheye::DOMEMASTER),
        _ => None,
    };
    let Some(mut f) = fisheye else {
        if let Some(flag) = [
            ("--content-fov", a.content_fov.is_some()),
            ("--content-tilt", a.content_tilt.is_some()),
            ("--content-circle", a.content_circle.is_some()),
        ]
        .iter()
        .find_map(|(n, given)| given.then_some(n))
        {
            bail!("{flag}: for fisheye and domemaster content only");
        }
        return Content::from_image(image, format, a.content_hfov, a.content_vfov)
            .map_err(flag_error);
    };
    if a.content_hfov.is_some() || a.content_vfov.is_some() {
        bail!(
            "--content-hfov: a fisheye's field of view is its image circle's: give --content-fov"
        );
    }
    if a.content_tilt.is_some() && format == Format::Fisheye {
        bail!("--content-tilt: tilts a dome master (--content-format domemaster)");
    }
    if let Some(fov) = a.content_fov {
        f.fov = fov;
    }
    if let Some(t) = a.content_tilt {
        f.tilt = Some(t);
    }
    if let Some(c) = a.content_circle {
        f.centre = Some([c.x, c.y]);
        f.radius = Some(c.z);
    }
    Content::fisheye(image, &f).map_err(flag_error)
}

pub fn to_float(p: [u8; 4]) -> [f32; 4] {
    p.map(|c| f32::from(c) / 255.0)
}

pub fn to_u8(p: [f32; 4]) -> [u8; 4] {
    <[u8; 4]>::from_f32(p.map(|c| c * 255.0))
}

pub fn write_output(path: &Path, img: AnyRaster, attrs: &[(String, String)]) -> Result<()> {
    write_image(path, img, attrs).context("--out")
}

fn write_image(path: &Path, img: AnyRaster, attrs: &[(String, String)]) -> Result<()> {
    if is_exr(path) {
        let f = match img {
            AnyRaster::U8(r) => r.map(to_float),
            AnyRaster::F32(r) => r,
        };
        image_io::write_exr_rgba(path, &f, attrs, Precision::Float)?;
    } else {
        let b = match img {
            AnyRaster::U8(r) => r,
            AnyRaster::F32(r) => r.map(to_u8),
        };
        image_io::write_png(path, &b)?;
    }
    Ok(())
}

pub fn is_exr(path: &Path) -> bool {
    path.extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("exr"))
}

pub enum AnyRaster {
    U8(Raster<[u8; 4]>),
    F32(Raster<[f32; 4]>),
}

pub fn cube_faces<T: Pixel>(c: &Content<T>, n: u32, ss: u32, f: Filter) -> Result<CubeMap<T>> {
    let faces: Vec<Raster<T>> = Face::ALL
        .iter()
        .map(|&face| render::render(Warp::CubeFace(face), c, n, n, ss, f))
        .collect::<Result<_, _>>()
        .map_err(flag_error)?;
    Ok(CubeMap::from_faces(faces.try_into().expect("six faces"))?)
}

pub fn write_cube<T: Pixel>(
    cube: &CubeMap<T>,
    layout: CubeLayoutArg,
    out: &Path,
    wrap: fn(Raster<T>) -> AnyRaster,
) -> Result<()> {
    use omniwarp::cubemap::Layout;
    let layout = match layout {
        CubeLayoutArg::Strip => Layout::Strip,
        CubeLayoutArg::C3x2 => Layout::FfmpegC3x2,
        CubeLayoutArg::C6x1 => Layout::FfmpegC6x1,
        CubeLayoutArg::Faces => {
            let pattern = out.to_string_lossy();
            if !pattern.contains("{face}") {
                bail!("--out: with --layout faces the name must contain {{face}}");
            }
            for face in Face::ALL {
                let path = PathBuf::from(pattern.replace("{face}", face.label()));
                write_output(&path, wrap(cube.face(face).clone()), &[])?;
            }
            return Ok(());
        }
    };
    write_output(out, wrap(layout.join(cube)), &[])
}

/// `value` as pretty JSON at `path`, atomically.
pub fn write_json(path: &Path, value: &impl serde::Serialize) -> Result<()> {
    let json = serde_json::to_string_pretty(value)?;
    image_io::atomic_write(path, |f| {
        use std::io::Write;
        f.write_all(json.as_bytes())
            .map_err(|e| omniwarp::Error::file(path, e))
    })?;
    Ok(())
}

pub fn read_rig(path: &Path) -> Result<Rig> {
    Rig::read(path).with_context(|| "--rig".to_string())
}

pub fn channel<'a>(rig: &'a Rig, id: &str) -> Result<&'a Channel> {
    rig.channel(id)
        .map_err(|e| anyhow::anyhow!("--channel: {}", e.reason()))
}

/// A channel's warp map (for a panorama projected from `project_from`, if given) and its blend
/// and black lift, for `render --rig`.
pub fn render_inputs(
    path: &Path,
    id: &str,
    gamma: f64,
    project_from: Option<DVec3>,
) -> Result<(NormalMap, ChannelBlend)> {
    let rig = read_rig(path)?;
    let ch = channel(&rig, id)?;
    let w = rig.warp(ch);
    let blend = channel_blend(&rig, ch, &w.points, gamma)?;
    let map = match project_from {
        Some(c) => {
            let c = rig.check_centre(c, "project-from").map_err(flag_error)?;
            let never = std::sync::atomic::AtomicBool::new(false);
            rig.projected(&w.map, Some(&w.points), c, &never)
                .expect("never cancelled")
        }
        None => w.map,
    };
    Ok((map, blend))
}

/// A channel's blend, and its black lift when the rig's projectors have a contrast.
pub fn channel_blend(
    rig: &Rig,
    ch: &Channel,
    points: &[Option<DVec3>],
    gamma: f64,
) -> Result<ChannelBlend> {
    rig.channel_blend(ch, points, gamma).map_err(flag_error)
}

pub fn read_tiles(path: &Path) -> Result<TileScreen> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("--tiles {}", path.display()))?;
    TileScreen::from_json(&text).with_context(|| format!("--tiles {}", path.display()))
}

/// Whether `e` comes from writing into a pipe whose reader has gone (`omniwarp … | head`).
pub fn is_broken_pipe(e: &anyhow::Error) -> bool {
    e.chain().any(|c| {
        c.downcast_ref::<std::io::Error>()
            .is_some_and(|io| io.kind() == std::io::ErrorKind::BrokenPipe)
            || matches!(
                c.downcast_ref::<omniwarp::Error>(),
                Some(omniwarp::Error::File {
                    kind: Some(std::io::ErrorKind::BrokenPipe),
                    ..
                })
            )
    })
}

/// One line about a tile screen's accuracy against the exact warp.
pub fn print_report(prefix: &str, r: &Report) -> Result<()> {
    outln!(
        "{prefix}grid {}×{} ({} features): max error {:.4}° ({:.3} px), RMS {:.4}°, {} pixels \
         uncovered",
        r.columns,
        r.rows,
        r.features,
        r.max_deg,
        r.max_px,
        r.rms_deg,
        r.uncovered
    );
    Ok(())
}

/// The median wall time of `frames` calls of `f`, milliseconds (benchmarks).
#[cfg(feature = "bench")]
pub fn median_ms(frames: u16, mut f: impl FnMut() -> Result<()>) -> Result<f64> {
    let mut t = Vec::new();
    for _ in 0..frames.max(1) {
        let start = std::time::Instant::now();
        f()?;
        t.push(start.elapsed().as_secs_f64() * 1e3);
    }
    t.sort_by(f64::total_cmp);
    Ok(t[t.len() / 2])
}
