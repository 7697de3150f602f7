//! Figure 8 (the path) and Figures 9–12 (errors against the noise level), in the
//! paper's layout: one panel per error (x, y, z, 3-D distance), one line per method.

use crate::pipeline::plots::COLOURS;
use crate::plot_font::font_available;
use anyhow::{anyhow, Result};
use plotters::prelude::*;
use std::path::Path;

fn err<E: std::fmt::Debug>(e: E) -> anyhow::Error {
    anyhow!("plot: {e:?}")
}

/// One line: a method's MAE at each level.
pub struct Series {
    pub name: String,
    /// Per panel (x, y, z, distance): values at each level.
    pub panels: [Vec<f64>; 4],
}

pub fn sweep(
    path: &Path,
    title: &str,
    x_label: &str,
    levels: &[f64],
    series: &[Series],
) -> Result<()> {
    let text = font_available();
    let root = BitMapBackend::new(path, (1000, 750)).into_drawing_area();
    root.fill(&WHITE).map_err(err)?;
    let root = if text {
        root.titled(title, ("sans-serif", 26)).map_err(err)?
    } else {
        root
    };
    let panels = root.split_evenly((2, 2));
    let names = [
        "x error MAE (m)",
        "y error MAE (m)",
        "z error MAE (m)",
        "distance error MAE (m)",
    ];
    let (x0, x1) = (
        levels.iter().copied().fold(f64::MAX, f64::min),
        levels.iter().copied().fold(f64::MIN, f64::max),
    );
    for (p, area) in panels.iter().enumerate() {
        let ymax = series
            .iter()
            .flat_map(|s| s.panels[p].iter().copied())
            .filter(|v| v.is_finite())
            .fold(0.1f64, f64::max)
            * 1.15;
        let mut chart = ChartBuilder::on(area)
            .margin(15)
            .x_label_area_size(40)
            .y_label_area_size(55)
            .build_cartesian_2d(x0 - 0.2..x1 + 0.2, 0f64..ymax)
            .map_err(err)?;
        let mut mesh = chart.configure_mesh();
        mesh.x_desc(x_label)
            .y_desc(names[p])
            .light_line_style(WHITE)
            .x_labels(levels.len());
        if !text {
            mesh.x_labels(0).y_labels(0);
        }
        mesh.draw().map_err(err)?;
        for (i, s) in series.iter().enumerate() {
            let colour = COLOURS[i % COLOURS.len()];
            let pts: Vec<(f64, f64)> = levels
                .iter()
                .copied()
                .zip(s.panels[p].iter().copied())
                .filter(|(_, v)| v.is_finite())
                .collect();
            let line = chart
                .draw_series(LineSeries::new(pts.clone(), colour.stroke_width(2)))
                .map_err(err)?;
            if text {
                line.label(s.name.clone()).legend(move |(x, y)| {
                    PathElement::new(vec![(x, y), (x + 20, y)], colour.stroke_width(2))
                });
            }
            chart
                .draw_series(
                    pts.iter()
                        .map(|&(x, y)| Circle::new((x, y), 3, colour.filled())),
                )
                .map_err(err)?;
        }
        if text && p == 0 {
            chart
                .configure_series_labels()
                .background_style(WHITE.mix(0.85))
                .border_style(BLACK)
                .position(SeriesLabelPosition::UpperLeft)
                .draw()
                .map_err(err)?;
        }
    }
    root.present().map_err(err)?;
    Ok(())
}

/// Lines over time (the bias-step scenario): (name, [(t, value)]).
pub fn time_series(
    path: &Path,
    title: &str,
    y_label: &str,
    lines: &[(String, Vec<(f64, f64)>)],
    marks: &[f64],
) -> Result<()> {
    let text = font_available();
    let root = BitMapBackend::new(path, (1000, 500)).into_drawing_area();
    root.fill(&WHITE).map_err(err)?;
    let pts = lines.iter().flat_map(|(_, l)| l.iter());
    let (mut x0, mut x1, mut y0, mut y1) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
    for &(x, y) in pts {
        x0 = x0.min(x);
        x1 = x1.max(x);
        y0 = y0.min(y);
        y1 = y1.max(y);
    }
    if x0 > x1 {
        return Err(anyhow!("no points to plot"));
    }
    let pad = ((y1 - y0) * 0.1).max(0.5);
    let mut builder = ChartBuilder::on(&root);
    builder
        .margin(15)
        .x_label_area_size(40)
        .y_label_area_size(55);
    if text {
        builder.caption(title, ("sans-serif", 22));
    }
    let mut chart = builder
        .build_cartesian_2d(x0..x1, y0 - pad..y1 + pad)
        .map_err(err)?;
    let mut mesh = chart.configure_mesh();
    mesh.x_desc("t (s)").y_desc(y_label).light_line_style(WHITE);
    if !text {
        mesh.x_labels(0).y_labels(0);
    }
    mesh.draw().map_err(err)?;
    for &m in marks {
        chart
            .draw_series(LineSeries::new([(x0, m), (x1, m)], BLACK.mix(0.4)))
            .map_err(err)?;
    }
    for (i, (name, line)) in lines.iter().enumerate() {
        let colour = COLOURS[i % COLOURS.len()];
        let s = chart
            .draw_series(LineSeries::new(
                line.iter().copied(),
                colour.stroke_width(2),
            ))
            .map_err(err)?;
        if text {
            s.label(name.clone()).legend(move |(x, y)| {
                PathElement::new(vec![(x, y), (x + 20, y)], colour.stroke_width(2))
            });
        }
    }
    if text {
        chart
            .configure_series_labels()
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .draw()
            .map_err(err)?;
    }
    root.present().map_err(err)?;
    Ok(())
}
