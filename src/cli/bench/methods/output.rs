//! The method chart's output: its rows, the Pareto front among them, the table printed and
//! the CSV and SVG files `bench chart --scene` writes.

use anyhow::{Result, bail};

/// One method at one setting, measured.
pub struct Row {
    pub family: &'static str,
    pub setting: String,
    pub renderer: &'static str,
    pub ms: f64,
    pub db: f64,
    /// Sampling-direction error, degrees: largest and 99th percentile (None: exact by
    /// construction, the view's own formula).
    pub direction: Option<(f64, f64)>,
    /// Edge width relative to the exact image: median over regions, and p90/p10 spread.
    pub edges: (f64, f64),
    pub front: bool,
}

/// Marks the rows no other row beats in both time and PSNR.
pub fn mark_front(rows: &mut [Row]) {
    let points: Vec<(f64, f64)> = rows.iter().map(|r| (r.ms, r.db)).collect();
    for (k, r) in rows.iter_mut().enumerate() {
        r.front = !points.iter().enumerate().any(|(o, &(ms, db))| {
            o != k
                && ms <= points[k].0
                && db >= points[k].1
                && (ms < points[k].0 || db > points[k].1)
        });
    }
}

/// The rows as a table on standard output, the front starred.
pub fn print_table(rows: &[Row]) -> Result<()> {
    outln!(
        "  method         | setting                          | on  | ms/frame | × fastest |   PSNR | dir. max° | dir. p99° | edge width | spread | front"
    );
    let fastest = rows.iter().map(|r| r.ms).fold(f64::INFINITY, f64::min);
    for r in rows {
        let (dmax, dp99) = r.direction.map_or(("-".into(), "-".into()), |(m, p)| {
            (format!("{m:.4}"), format!("{p:.4}"))
        });
        outln!(
            "  {:<14} | {:<32} | {:<3} | {:8.1} | {:9.2} | {:6.2} | {dmax:>9} | {dp99:>9} | {:10.2} | {:6.2} | {}",
            r.family,
            r.setting,
            r.renderer,
            r.ms,
            r.ms / fastest,
            r.db,
            r.edges.0,
            r.edges.1,
            if r.front { "*" } else { "" }
        );
    }
    Ok(())
}

/// Time (ratio to the fastest, log scale) against PSNR, one colour per method and renderer,
/// the Pareto front joined.
pub fn write_svg(name: &std::path::Path, title: &str, rows: &[Row]) -> Result<()> {
    use plotters::prelude::*;
    let path = name.with_extension("svg");
    let fastest = rows.iter().map(|r| r.ms).fold(f64::INFINITY, f64::min);
    let ratio = |r: &Row| r.ms / fastest;
    let top = rows.iter().map(ratio).fold(1.0, f64::max) * 1.5;
    let (lo, hi) = rows
        .iter()
        .map(|r| r.db)
        .filter(|d| d.is_finite())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), d| {
            (a.min(d), b.max(d))
        });
    let mut families: Vec<String> = Vec::new();
    for r in rows {
        let f = format!("{} ({})", r.family, r.renderer);
        if !families.contains(&f) {
            families.push(f);
        }
    }
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (1000, 680)).into_drawing_area();
        root.fill(&WHITE)?;
        let mut chart = ChartBuilder::on(&root)
            .caption(
                format!("Speed against accuracy: {title}"),
                ("sans-serif", 18),
            )
            .margin(16)
            .x_label_area_size(44)
            .y_label_area_size(56)
            .build_cartesian_2d((0.8f64..top).log_scale(), (lo - 1.0)..(hi + 1.0))?;
        chart
            .configure_mesh()
            .max_light_lines(1)
            .x_label_formatter(&|v| format!("{v:.1}×"))
            .x_desc("time per frame, over the fastest method's (log)")
            .y_desc("PSNR against the exact ray cast, dB")
            .draw()?;
        let mut front: Vec<(f64, f64)> = rows
            .iter()
            .filter(|r| r.front)
            .map(|r| (ratio(r), r.db))
            .collect();
        front.sort_by(|a, b| a.0.total_cmp(&b.0));
        chart
            .draw_series(LineSeries::new(front, BLACK.stroke_width(1)))?
            .label("Pareto front")
            .legend(|(x, y)| PathElement::new([(x, y), (x + 20, y)], BLACK));
        for (k, family) in families.iter().enumerate() {
            let colour = Palette99::pick(k).to_rgba();
            let mine: Vec<&Row> = rows
                .iter()
                .filter(|r| &format!("{} ({})", r.family, r.renderer) == family)
                .collect();
            chart
                .draw_series(mine.iter().map(|r| {
                    let size = if r.front { 6 } else { 4 };
                    Circle::new((ratio(r), r.db), size, colour.filled())
                }))?
                .label(family.as_str())
                .legend(move |(x, y)| Circle::new((x + 10, y), 4, colour.filled()));
            chart.draw_series(mine.iter().map(|r| {
                Text::new(
                    r.setting.clone(),
                    (ratio(r), r.db),
                    ("sans-serif", 10).into_font().color(&BLACK),
                )
            }))?;
        }
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::LowerRight)
            .border_style(BLACK)
            .background_style(WHITE)
            .draw()?;
        root.present()?;
    }
    omniwarp::image_io::atomic_write(&path, |f| {
        use std::io::Write;
        f.write_all(svg.as_bytes())
            .map_err(|e| omniwarp::Error::file(&path, e))
    })?;
    Ok(())
}

pub fn write_csv(name: &std::path::Path, rows: &[Row], exact_ms: f64) -> Result<()> {
    let path = name.with_extension("csv");
    let fastest = rows.iter().map(|r| r.ms).fold(f64::INFINITY, f64::min);
    let mut text = String::from(
        "method,setting,renderer,ms_per_frame,ratio_to_fastest,psnr_db,direction_max_deg,direction_p99_deg,edge_width_median,edge_width_spread,pareto\n",
    );
    for r in rows {
        let (dmax, dp99) = r
            .direction
            .map_or((String::new(), String::new()), |(m, p)| {
                (format!("{m:.6}"), format!("{p:.6}"))
            });
        text += &format!(
            "{},\"{}\",{},{:.2},{:.3},{:.3},{dmax},{dp99},{:.4},{:.4},{}\n",
            r.family,
            r.setting,
            r.renderer,
            r.ms,
            r.ms / fastest,
            r.db,
            r.edges.0,
            r.edges.1,
            r.front
        );
    }
    text += &format!(
        "exact,\"per-pixel ray cast (the reference)\",cpu,{exact_ms:.2},{:.3},inf,0,0,1,1,false\n",
        exact_ms / fastest
    );
    if let Some(dir) = path.parent()
        && !dir.as_os_str().is_empty()
        && !dir.is_dir()
    {
        bail!("--name: {} is not a directory", dir.display());
    }
    omniwarp::image_io::atomic_write(&path, |f| {
        use std::io::Write;
        f.write_all(text.as_bytes())
            .map_err(|e| omniwarp::Error::file(&path, e))
    })?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn row(ms: f64, db: f64) -> Row {
        Row {
            family: "x",
            setting: String::new(),
            renderer: "gpu",
            ms,
            db,
            direction: None,
            edges: (1.0, 1.0),
            front: false,
        }
    }

    #[test]
    fn the_front_keeps_only_rows_nothing_beats_in_both() {
        let mut rows = vec![
            row(10.0, 40.0),
            row(20.0, 45.0),
            row(30.0, 44.0),
            row(5.0, 30.0),
            row(10.0, 39.0),
        ];
        mark_front(&mut rows);
        let front: Vec<bool> = rows.iter().map(|r| r.front).collect();
        assert_eq!(front, [true, true, false, true, false]);
    }
}
