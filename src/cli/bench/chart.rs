//! `omniwarp bench chart`: grid size against the largest reconstruction error of a tile screen
//! (SVG) for cylindrical 270°×90°, fisheye 180° and fisheye 220°, with the figures printed (with
//! `--scene`, `bench chart` is the method chart of `methods/` instead).

use super::super::io::print_report;
use anyhow::{Result, bail};
use clap::Args;
use omniwarp::image_io;
use omniwarp::projection::Params;
use omniwarp::tiles::adapt::{exact, measure, rows_for};
use omniwarp::tiles::build::{Source, from_source};
use std::path::{Path, PathBuf};

#[derive(Args)]
pub struct ChartArgs {
    /// Output chart of the tile screens (.svg); without --scene.
    #[arg(long, default_value = "calibration/bench/charts/tiles-grid-error.svg")]
    out: PathBuf,
}

pub fn run(a: ChartArgs) -> Result<()> {
    chart(&a.out)
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
            print_report(&format!("{label:<22} {w}×{h}: "), &r)?;
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
