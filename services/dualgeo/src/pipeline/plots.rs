//! PNG plots: the latency percentile distribution (HdrHistogram's plotter style:
//! latency against 1/(1 − percentile) on a log axis) and the estimated path against
//! truth.
//!
//! Text is drawn with DejaVu Sans, read at run time from Debian's `fonts-dejavu-core`
//! (installed by scripts/setup.sh). Without it the plots are still drawn, without text.

use crate::plot_font::font_available;
use anyhow::{anyhow, Result};
use hdrhistogram::Histogram;
use plotters::coord::types::RangedCoordf64;
use plotters::prelude::*;
use std::path::Path;

pub const COLOURS: [RGBColor; 5] = [
    RGBColor(31, 119, 180),
    RGBColor(255, 127, 14),
    RGBColor(44, 160, 44),
    RGBColor(214, 39, 40),
    RGBColor(148, 103, 189),
];

fn err<E: std::fmt::Debug>(e: E) -> anyhow::Error {
    anyhow!("plot: {e:?}")
}

/// A chart over two f64 axes on a PNG.
type Chart<'a, 'b> =
    ChartContext<'a, BitMapBackend<'b>, Cartesian2d<RangedCoordf64, RangedCoordf64>>;

/// One line in `colour`, named in the legend when text can be drawn.
fn labelled_line<'a>(
    chart: &mut Chart<'a, 'a>,
    points: Vec<(f64, f64)>,
    colour: RGBColor,
    name: String,
    text: bool,
) -> Result<()> {
    let series = chart
        .draw_series(LineSeries::new(points, colour.stroke_width(2)))
        .map_err(err)?;
    if text {
        series.label(name).legend(move |(x, y)| {
            PathElement::new(vec![(x, y), (x + 20, y)], colour.stroke_width(2))
        });
    }
    Ok(())
}

/// The legend box of every plot here.
fn legend<'a>(chart: &mut Chart<'a, 'a>, position: SeriesLabelPosition) -> Result<()> {
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .position(position)
        .draw()
        .map_err(err)
}

/// Latency (ms) against percentile, one line per row, like HdrHistogram's plotter.
pub fn latency_percentiles(path: &Path, rows: &[(String, Histogram<u64>)]) -> Result<()> {
    let text = font_available();
    let root = BitMapBackend::new(path, (1000, 600)).into_drawing_area();
    root.fill(&WHITE).map_err(err)?;
    let max_ms = rows
        .iter()
        .map(|(_, h)| h.max() as f64 / 1000.0)
        .fold(0.01f64, f64::max)
        * 1.1;
    // x: log10 of 1/(1 − p), from 1 (p = 0) to 10⁵ (p99.999).
    let mut builder = ChartBuilder::on(&root);
    builder
        .margin(20)
        .x_label_area_size(50)
        .y_label_area_size(70);
    if text {
        builder.caption("latency by percentile", ("sans-serif", 24));
    }
    let mut chart = builder
        .build_cartesian_2d(0f64..5f64, 0f64..max_ms)
        .map_err(err)?;
    let mut mesh = chart.configure_mesh();
    mesh.x_labels(6)
        .x_label_formatter(&|v| {
            let p = 100.0 * (1.0 - 10f64.powf(-*v));
            format!("{}%", (p * 1000.0).round() / 1000.0)
        })
        .x_desc("percentile")
        .y_desc("latency (ms)");
    if !text {
        mesh.disable_x_mesh().x_labels(0).y_labels(0);
    }
    mesh.draw().map_err(err)?;
    for (i, (name, h)) in rows.iter().enumerate() {
        let colour = COLOURS[i % COLOURS.len()];
        let points: Vec<(f64, f64)> = h
            .iter_quantiles(5)
            .filter_map(|v| {
                let q = v.quantile_iterated_to();
                (q < 1.0).then(|| {
                    (
                        (1.0 / (1.0 - q)).log10().min(5.0),
                        v.value_iterated_to() as f64 / 1000.0,
                    )
                })
            })
            .collect();
        labelled_line(&mut chart, points, colour, name.clone(), text)?;
    }
    if text {
        legend(&mut chart, SeriesLabelPosition::UpperLeft)?;
    }
    root.present().map_err(err)?;
    Ok(())
}

/// The estimated target path against the true one, top view (ENU x east, y north).
pub fn path_against_truth(path: &Path, estimated: &[[f64; 2]], truth: &[[f64; 2]]) -> Result<()> {
    let text = font_available();
    let all = estimated.iter().chain(truth);
    let (mut x0, mut x1, mut y0, mut y1) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
    for p in all {
        x0 = x0.min(p[0]);
        x1 = x1.max(p[0]);
        y0 = y0.min(p[1]);
        y1 = y1.max(p[1]);
    }
    if x0 > x1 {
        return Err(anyhow!("no points to plot"));
    }
    // Same scale on both axes.
    let span = (x1 - x0).max(y1 - y0).max(1.0) * 1.1;
    let (cx, cy) = ((x0 + x1) / 2.0, (y0 + y1) / 2.0);
    let root = BitMapBackend::new(path, (800, 800)).into_drawing_area();
    root.fill(&WHITE).map_err(err)?;
    let mut builder = ChartBuilder::on(&root);
    builder
        .margin(20)
        .x_label_area_size(45)
        .y_label_area_size(60);
    if text {
        builder.caption("target path: estimated vs truth", ("sans-serif", 24));
    }
    let mut chart = builder
        .build_cartesian_2d(
            cx - span / 2.0..cx + span / 2.0,
            cy - span / 2.0..cy + span / 2.0,
        )
        .map_err(err)?;
    let mut mesh = chart.configure_mesh();
    mesh.x_desc("east (m)")
        .y_desc("north (m)")
        .light_line_style(WHITE);
    if !text {
        mesh.x_labels(0).y_labels(0);
    }
    mesh.draw().map_err(err)?;
    let truth_series = chart
        .draw_series(LineSeries::new(
            truth.iter().map(|p| (p[0], p[1])),
            BLACK.stroke_width(2),
        ))
        .map_err(err)?;
    if text {
        truth_series
            .label("truth")
            .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], BLACK.stroke_width(2)));
    }
    let red = COLOURS[3];
    let est_series = chart
        .draw_series(
            estimated
                .iter()
                .map(|p| Circle::new((p[0], p[1]), 2, red.filled())),
        )
        .map_err(err)?;
    if text {
        est_series
            .label("estimated")
            .legend(move |(x, y)| Circle::new((x + 10, y), 3, red.filled()));
        chart
            .configure_series_labels()
            .background_style(WHITE.mix(0.8))
            .border_style(BLACK)
            .draw()
            .map_err(err)?;
    }
    root.present().map_err(err)?;
    Ok(())
}

/// A named line: (label, points).
type Series = (String, Vec<(f64, f64)>);

/// The soak report over time: each process's RSS (MiB, top) and each stage's p99 per
/// interval (ms, bottom).
pub fn soak(path: &Path, samples: &[super::soak::Sample]) -> Result<()> {
    use super::soak::{LATENCIES, PROCESSES};
    let text = font_available();
    let root = BitMapBackend::new(path, (1000, 800)).into_drawing_area();
    root.fill(&WHITE).map_err(err)?;
    let (top, bottom) = root.split_vertically(400);
    let t_max = samples.last().map_or(1.0, |s| s.t_s / 60.0).max(1e-3) * 1.02;
    let panels: [(&str, Vec<Series>); 2] = [
        (
            "resident memory (MiB)",
            PROCESSES
                .iter()
                .enumerate()
                .map(|(i, p)| {
                    let pts = samples
                        .iter()
                        .map(|s| (s.t_s / 60.0, s.rss_kib[i] as f64 / 1024.0))
                        .collect();
                    (p.to_string(), pts)
                })
                .collect(),
        ),
        (
            "p99 per interval (ms)",
            LATENCIES
                .iter()
                .enumerate()
                .map(|(i, (stage, h))| {
                    let pts = samples
                        .iter()
                        .filter(|s| s.p99_us[i] > 0)
                        .map(|s| (s.t_s / 60.0, s.p99_us[i] as f64 / 1e3))
                        .collect();
                    let name = if *h == "compute" {
                        stage.to_string()
                    } else {
                        h.to_string()
                    };
                    (name, pts)
                })
                .collect(),
        ),
    ];
    for (area, (title, series)) in [top, bottom].iter().zip(panels) {
        let y_max = series
            .iter()
            .flat_map(|(_, p)| p.iter().map(|v| v.1))
            .fold(1e-3f64, f64::max)
            * 1.15;
        let mut builder = ChartBuilder::on(area);
        builder
            .margin(15)
            .x_label_area_size(40)
            .y_label_area_size(60);
        if text {
            builder.caption(title, ("sans-serif", 20));
        }
        let mut chart = builder
            .build_cartesian_2d(0f64..t_max, 0f64..y_max)
            .map_err(err)?;
        let mut mesh = chart.configure_mesh();
        mesh.x_desc("minutes").y_desc(title);
        if !text {
            mesh.disable_x_mesh().x_labels(0).y_labels(0);
        }
        mesh.draw().map_err(err)?;
        for (i, (name, pts)) in series.into_iter().enumerate() {
            let colour = COLOURS[i % COLOURS.len()];
            labelled_line(&mut chart, pts, colour, name, text)?;
        }
        if text {
            legend(&mut chart, SeriesLabelPosition::LowerRight)?;
        }
    }
    root.present().map_err(err)?;
    Ok(())
}
