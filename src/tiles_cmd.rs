//! `omniwarp tiles …`: projection tile screens from the command line.

use crate::cli::{ProjectionArgs, flag_error, parse_size};
use anyhow::{Context, Result, bail};
use clap::{Args, Subcommand};
use omniwarp::image_io::{self, Precision};
use omniwarp::projection::Params;
use omniwarp::tiles::TileScreen;
use omniwarp::tiles::adapt::{Report, Tolerance, choose, exact, measure, rows_for};
use omniwarp::tiles::build::{Source, from_source};
use std::path::{Path, PathBuf};
use std::time::Instant;

// Parsed once per run; boxing the larger variant would buy nothing.
#[allow(clippy::large_enum_variant)]
#[derive(Subcommand)]
pub enum TilesCommand {
    /// Sample a projection into a tile screen: a fixed grid, or the coarsest grid within a
    /// tolerance.
    FromProjection(FromProjectionArgs),
    /// Rasterise a tile screen into a normal map (float EXR).
    NormalMap(NormalMapArgs),
    /// Chart grid size against the largest reconstruction error (SVG) for cylindrical 270°×90°,
    /// fisheye 180° and fisheye 220°, and print the figures.
    Chart(ChartArgs),
    /// Time normal-map generation for grid sizes and output sizes.
    Bench,
}

#[derive(Args)]
pub struct FromProjectionArgs {
    #[command(flatten)]
    projection: ProjectionArgs,
    /// The output size WxH the screen is for (sets the aspect ratio and where the error is
    /// measured).
    #[arg(long, value_parser = parse_size)]
    size: (u32, u32),
    /// A fixed grid: MxN features (columns × rows).
    #[arg(long, value_parser = parse_size, conflicts_with_all = ["tolerance_deg", "tolerance_px"])]
    grid: Option<(u32, u32)>,
    /// The coarsest grid whose largest error is within this many degrees.
    #[arg(long, conflicts_with = "tolerance_px", allow_hyphen_values = true)]
    tolerance_deg: Option<f64>,
    /// The coarsest grid whose largest error is within this many output pixels.
    #[arg(long, allow_hyphen_values = true)]
    tolerance_px: Option<f64>,
    /// Output tile screen (JSON).
    #[arg(long)]
    out: PathBuf,
}

#[derive(Args)]
pub struct NormalMapArgs {
    /// Tile screen (JSON).
    tiles: PathBuf,
    /// Output size WxH in pixels.
    #[arg(long, value_parser = parse_size)]
    size: (u32, u32),
    /// Store half floats instead of 32-bit.
    #[arg(long)]
    half: bool,
    /// Output file (.exr).
    #[arg(long)]
    out: PathBuf,
}

#[derive(Args)]
pub struct ChartArgs {
    /// Output chart (.svg).
    #[arg(long)]
    out: PathBuf,
}

pub fn read_tiles(path: &Path) -> Result<TileScreen> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("--tiles {}", path.display()))?;
    TileScreen::from_json(&text).with_context(|| format!("--tiles {}", path.display()))
}

fn print_report(prefix: &str, r: &Report) {
    println!(
        "{prefix}grid {}×{} ({} features): max error {:.4}° ({:.3} px), RMS {:.4}°, {} pixels \
         uncovered",
        r.columns, r.rows, r.features, r.max_deg, r.max_px, r.rms_deg, r.uncovered
    );
}

pub fn run(cmd: TilesCommand) -> Result<()> {
    match cmd {
        TilesCommand::FromProjection(a) => {
            let (w, h) = (a.size.0 as usize, a.size.1 as usize);
            let source = a.projection.source(a.size.0, a.size.1)?;
            let tolerance = match (a.tolerance_deg, a.tolerance_px) {
                (Some(d), _) => Some(Tolerance::Degrees(d)),
                (None, Some(p)) => Some(Tolerance::Pixels(p)),
                (None, None) => None,
            };
            let (screen, report) = match (a.grid, tolerance) {
                (Some((c, r)), None) => {
                    let screen =
                        from_source(&source, c as usize, r as usize).map_err(flag_error)?;
                    let report = measure(&screen, &exact(&source.view()?, w, h), w, h);
                    (screen, report)
                }
                (None, Some(t)) => choose(&source, w, h, t).map_err(|e| match (e, t) {
                    (omniwarp::Error::Invalid { reason, .. }, Tolerance::Degrees(_)) => {
                        anyhow::anyhow!("--tolerance-deg: {reason}")
                    }
                    (omniwarp::Error::Invalid { reason, .. }, Tolerance::Pixels(_)) => {
                        anyhow::anyhow!("--tolerance-px: {reason}")
                    }
                    (other, _) => other.into(),
                })?,
                _ => bail!("--grid: give --grid MxN, --tolerance-deg or --tolerance-px"),
            };
            print_report("", &report);
            let json = screen.to_json();
            image_io::atomic_write(&a.out, |f| {
                use std::io::Write;
                f.write_all(json.as_bytes())
                    .map_err(|e| omniwarp::Error::file(&a.out, e))
            })?;
            Ok(())
        }
        TilesCommand::NormalMap(a) => {
            let screen = read_tiles(&a.tiles)?;
            if !a
                .out
                .extension()
                .is_some_and(|e| e.eq_ignore_ascii_case("exr"))
            {
                bail!("--out: {} must end in .exr", a.out.display());
            }
            let map = screen
                .feature_map(a.size.0 as usize, a.size.1 as usize)
                .normal_map();
            let precision = if a.half {
                Precision::Half
            } else {
                Precision::Float
            };
            map.write(&a.out, precision)?;
            Ok(())
        }
        TilesCommand::Chart(a) => chart(&a.out),
        TilesCommand::Bench => bench(),
    }
}

/// The three cases the chart shows, each with the output it is measured on.
fn chart_cases() -> Vec<(&'static str, Source, usize, usize)> {
    let p = |hfov: Option<f64>, vfov: Option<f64>, fov: Option<f64>| Params {
        hfov,
        vfov,
        fov,
        ..Params::default()
    };
    vec![
        (
            "cylindrical 270°×90°",
            Source::new("cylindrical", p(Some(270.0), Some(90.0), None), 0.5),
            960,
            480,
        ),
        (
            "fisheye 180°",
            Source::new("fisheye", p(None, None, Some(180.0)), 1.0),
            540,
            540,
        ),
        (
            "fisheye 220°",
            Source::new("fisheye", p(None, None, Some(220.0)), 1.0),
            540,
            540,
        ),
    ]
}

fn chart(out: &Path) -> Result<()> {
    use plotters::prelude::*;
    if !out
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("svg"))
    {
        bail!("--out: {} must end in .svg", out.display());
    }
    let columns = [3usize, 5, 9, 17, 33, 65, 129];
    let mut series = Vec::new();
    for (label, source, w, h) in chart_cases() {
        let truth = exact(&source.view()?, w, h);
        let mut points = Vec::new();
        for &c in &columns {
            let screen = from_source(&source, c, rows_for(c, w, h))?;
            let r = measure(&screen, &truth, w, h);
            print_report(&format!("{label:<22} {w}×{h}: "), &r);
            if r.uncovered == 0 && r.max_deg > 0.0 {
                points.push((c as f64, r.max_deg));
            }
        }
        series.push((label, points));
    }
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (800, 560)).into_drawing_area();
        root.fill(&WHITE)?;
        let mut chart = ChartBuilder::on(&root)
            .caption(
                "Tile screen: grid columns vs largest error",
                ("sans-serif", 22),
            )
            .margin(16)
            .x_label_area_size(44)
            .y_label_area_size(64)
            .build_cartesian_2d((2.0f64..160.0).log_scale(), (0.001f64..100.0).log_scale())?;
        chart
            .configure_mesh()
            .max_light_lines(1)
            .x_label_formatter(&|v| format!("{v:.0}"))
            .x_desc("grid columns (rows follow the output's aspect)")
            .y_desc("largest error, degrees")
            .draw()?;
        for (i, (label, points)) in series.iter().enumerate() {
            let colour = Palette99::pick(i).to_rgba();
            chart
                .draw_series(LineSeries::new(
                    points.iter().copied(),
                    colour.stroke_width(2),
                ))?
                .label(*label)
                .legend(move |(x, y)| {
                    PathElement::new([(x, y), (x + 20, y)], colour.stroke_width(2))
                });
            chart.draw_series(points.iter().map(|&p| Circle::new(p, 3, colour.filled())))?;
        }
        chart
            .configure_series_labels()
            .border_style(BLACK)
            .background_style(WHITE)
            .draw()?;
        root.present()?;
    }
    image_io::atomic_write(out, |f| {
        use std::io::Write;
        f.write_all(svg.as_bytes())
            .map_err(|e| omniwarp::Error::file(out, e))
    })?;
    Ok(())
}

fn bench() -> Result<()> {
    let source = Source::new(
        "fisheye",
        Params {
            fov: Some(200.0),
            ..Params::default()
        },
        9.0 / 16.0,
    );
    println!("normal map from a fisheye 200° tile screen (vector interpolation), all cores");
    for (w, h) in [(1920usize, 1080usize), (3840, 2160)] {
        for columns in [9usize, 33, 129, 513] {
            let screen = from_source(&source, columns, rows_for(columns, w, h))?;
            let mut best = f64::MAX;
            for _ in 0..3 {
                let t = Instant::now();
                let map = screen.feature_map(w, h).normal_map();
                std::hint::black_box(&map);
                best = best.min(t.elapsed().as_secs_f64());
            }
            println!("  {w}×{h}, {columns:>3} columns: {:>7.1} ms", best * 1e3);
        }
    }
    Ok(())
}
