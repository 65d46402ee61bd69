//! `omniwarp export`: a channel's warp (or the whole rig) in the formats media servers read.

use super::args::{ProjectionArgs, parse_size};
use super::io::{channel, read_rig};
use anyhow::{Context, Result};
use clap::Args;
use std::path::PathBuf;

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
    /// The whole rig as an MPCDI package, 2d profile: the canvas as the buffer, a region per
    /// channel, in the --reader's conventions.
    Mpcdi,
    /// The whole rig as an MPCDI package, a3 profile (the projectors side by side).
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
    /// The content canvas (for the 2d formats): its projection and view, as for `render`;
    /// without --projection, the rig's `canvas` when it has one.
    #[command(flatten)]
    canvas: ProjectionArgs,
    /// Content image size WxH in pixels (the 2d formats); the rig canvas's by default.
    #[arg(long, value_parser = parse_size)]
    content_size: Option<(u32, u32)>,
    /// Output file.
    #[arg(long)]
    out: PathBuf,
    /// The ymap file for --format remap.
    #[arg(long)]
    ymap: Option<PathBuf>,
    /// MPCDI version written: 1.0 (WATCHOUT 6 and other older readers) or 2.0; by default the
    /// one the --reader takes (2.0 but for watchout).
    #[arg(long, value_parser = ["1.0", "2.0"])]
    mpcdi_version: Option<String>,
    /// The reader the export is made for. MPCDI 2d: whose conventions it follows (region y and
    /// v direction, PFM row order, node placement; docs/mpcdi.md): vesa (the default: the
    /// reference library and the media servers built on it), ndisplay, watchout, pympcdi or
    /// sgct. Mesh: how its cells are filled, which sizes the grid: any (the default: every
    /// way), bilinear, celestia or sgct.
    #[arg(long)]
    reader: Option<String>,
    /// The content is a panorama projected from this point x,y,z (metres) onto the wall
    /// (seed 001), as for `render --project-from`; the 2d exports follow it.
    #[arg(long, value_parser = super::args::parse_vec3, allow_hyphen_values = true)]
    project_from: Option<glam::DVec3>,
    /// Bits of the MPCDI alpha maps: 8 (what readers decode) or 16.
    #[arg(long, default_value = "8", value_parser = ["8", "16"])]
    alpha_bits: String,
}

pub fn run(a: ExportArgs) -> Result<()> {
    use omniwarp::export::{self, bourke::MeshReader, channel::Sources, channel::Tolerance, mpcdi};
    if a.reader.is_some() && !matches!(a.format, ExportFormat::Mpcdi | ExportFormat::Mesh) {
        anyhow::bail!("--reader: only MPCDI 2d packages and meshes are made for a reader");
    }
    // The command line waits for its export; nothing cancels it.
    let never = std::sync::atomic::AtomicBool::new(false);
    let rig = read_rig(&a.rig)?;
    // Without --projection the 2d exports point into the rig's own canvas, when it has one:
    // its view, its size and its projection centre, each unless a flag says otherwise.
    let rig_canvas = match (&a.canvas.projection, &rig.doc.canvas) {
        (None, Some(c)) => Some(c.clone()),
        _ => None,
    };
    let content_size = a
        .content_size
        .or(rig_canvas.as_ref().map(|c| (c.size[0], c.size[1])));
    let project_from = a.project_from.or(rig_canvas
        .as_ref()
        .and_then(|c| c.project_from)
        .map(glam::DVec3::from_array));
    let view = |w: u32, h: u32| -> Result<omniwarp::projection::View> {
        match &rig_canvas {
            Some(c) => {
                let mut c = c.clone();
                c.size = [w, h];
                c.view()
                    .map_err(|e| anyhow::anyhow!("the rig's canvas: {}", super::args::named(e)))
            }
            None => a.canvas.view(w, h),
        }
    };
    let centre = project_from
        .map(|c| rig.check_centre(c, "project-from"))
        .transpose()
        .map_err(super::args::flag_error)?;
    // A channel's warp, its map seen from the projection centre when there is one.
    let warp_of = |ch| {
        let mut warp = rig.warp(ch);
        if let Some(c) = centre {
            warp.map = rig
                .projected(&warp.map, Some(&warp.points), c, &never)
                .expect("never cancelled");
        }
        warp
    };
    let size = || content_size.context("--content-size: needed for this format");
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
            mpcdi::Profile::A3 => content_size.unwrap_or((1, 1)),
        };
        let canvas = match profile {
            mpcdi::Profile::TwoD => Some(view(cw, chh)?),
            mpcdi::Profile::A3 => None,
        };
        let reader = match &a.reader {
            Some(r) => mpcdi::Reader::parse(r, "--reader")?,
            None => mpcdi::Reader::Vesa,
        };
        let mut regions = Vec::new();
        let target = rig.black_target();
        for ch in &rig.channels {
            let warp = warp_of(ch);
            let uv = canvas
                .as_ref()
                .map(|c| export::content_uv_unbounded(&warp.map, c))
                .unwrap_or_else(|| vec![None; warp.points.len()]);
            let weights = rig.blend_weights(ch, &warp.points);
            let lift = rig
                .has_black()
                .then(|| rig.black_lift(ch, &warp.points, &weights, target));
            let src = Sources {
                id: &ch.id,
                width: ch.width as usize,
                height: ch.height as usize,
                uv: &uv,
                content_size: [cw, chh],
                points: &warp.points,
                eye: rig.eye,
                weights: &weights,
                lift: lift.as_deref(),
                cancel: &never,
            };
            let bits = if a.alpha_bits == "16" { 16 } else { 8 };
            let (region, err) = src.region(profile, tol, bits, reader)?;
            eprintln!(
                "{}: {}×{} grid, worst error {err:.4}",
                ch.id, region.warp.0, region.warp.1
            );
            regions.push(region);
        }
        let buffers = match profile {
            mpcdi::Profile::TwoD => vec![[cw, chh]],
            mpcdi::Profile::A3 => mpcdi::side_by_side(&mut regions),
        };
        let header = mpcdi::Header {
            version: match &a.mpcdi_version {
                Some(v) => mpcdi::Version::parse(v, "--mpcdi-version")?,
                None => reader.version(),
            },
            profile,
            reader,
            buffers,
            unix_time: mpcdi::unix_now(),
        };
        write(&mpcdi::package(&header, &regions)?)?;
        return Ok(());
    }
    let id = a
        .channel
        .as_deref()
        .context("--channel: needed for this format")?;
    let ch = channel(&rig, id)?;
    let (w, h) = (ch.width as usize, ch.height as usize);
    let warp = warp_of(ch);
    let canvas_uv = |size: Option<(u32, u32)>| -> Result<Vec<Option<[f64; 2]>>> {
        let (cw, chh) = size.context("--content-size: needed for this format")?;
        Ok(export::content_uv(&warp.map, &view(cw, chh)?))
    };
    match a.format {
        ExportFormat::Stmap => export::write_stmap(&a.out, &canvas_uv(content_size)?, w, h)?,
        ExportFormat::PfmA3 => export::write_pfm(&a.out, w, h, &export::a3_samples(&warp.points))?,
        ExportFormat::Remap => {
            let ymap = a
                .ymap
                .as_ref()
                .context("--ymap: remap needs a second file for the rows")?;
            let (cw, chh) = size()?;
            export::write_remap_pgm(&a.out, ymap, &canvas_uv(content_size)?, w, h, [cw, chh])?;
        }
        ExportFormat::Pfm2d | ExportFormat::Mesh => {
            let (cw, chh) = size()?;
            let uv = export::content_uv_unbounded(&warp.map, &view(cw, chh)?);
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
                lift: None,
                cancel: &never,
            };
            let tol = tolerance(0.5)?;
            if let ExportFormat::Mesh = a.format {
                let reader = match &a.reader {
                    Some(r) => MeshReader::parse(r, "--reader")?,
                    None => MeshReader::Any,
                };
                let (text, c) = src.bourke(tol, reader)?;
                eprintln!(
                    "{}×{} mesh, worst error {:.4} px",
                    c.grid.columns, c.grid.rows, c.max_error
                );
                write(text.as_bytes())?;
            } else {
                let (c, rows) = src.grid_2d(tol)?;
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
