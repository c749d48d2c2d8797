//! PNG plots of a run's curves (plotters), redrawn after every epoch:
//! `plots/steps.png` (every loss term per step, log scale; lr per step) and `plots/epochs.png`
//! (mean loss per epoch; validation AP3D@0.3/0.5/0.7 per epoch). [`plot_lines`] draws any set of
//! named curves (the sweep's comparison plot).
//!
//! Text needs a font and plotters' usual font path needs system libraries (fontconfig, freetype);
//! instead plotters' pure-Rust `ab_glyph` renderer draws DejaVu Sans, embedded from the `dejavu` crate.

use std::path::Path;
use std::sync::Once;

use anyhow::{Result, anyhow};
use plotters::coord::Shift;
use plotters::prelude::*;

use crate::metrics::Table;
use crate::run_dir::RunDir;

static FONTS: Once = Once::new();

/// Registers the embedded font as plotters' `sans-serif` (once per process).
pub fn register_fonts() {
    FONTS.call_once(|| {
        // The font bytes are a valid TrueType file shipped by the `dejavu` crate.
        for (style, bytes) in [(FontStyle::Normal, dejavu::sans::regular()), (FontStyle::Bold, dejavu::sans::bold())] {
            assert!(plotters::style::register_font("sans-serif", style, bytes).is_ok(), "the embedded DejaVu Sans parses");
        }
    });
}

fn pe<E: std::fmt::Debug>(e: E) -> anyhow::Error {
    anyhow!("plotting: {e:?}")
}

/// One named curve.
#[derive(Debug, Clone, PartialEq)]
pub struct Series {
    /// Legend text.
    pub label: String,
    /// Points (x, y); non-finite ones are left out.
    pub points: Vec<(f64, f64)>,
}

impl Series {
    /// A series from x and y columns, dropping points where either is not finite.
    pub fn new(label: impl Into<String>, x: &[f64], y: &[f64]) -> Self {
        let points = x.iter().zip(y).filter(|(a, b)| a.is_finite() && b.is_finite()).map(|(&a, &b)| (a, b)).collect();
        Self { label: label.into(), points }
    }
}

/// Axis scale.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Scale {
    /// Linear.
    Linear,
    /// Logarithmic (non-positive values are left out).
    Log,
}

fn bounds(series: &[Series], scale: Scale) -> Option<(f64, f64, f64, f64)> {
    let pts = series.iter().flat_map(|s| s.points.iter()).filter(|p| scale == Scale::Linear || p.1 > 0.0);
    let (mut x0, mut x1, mut y0, mut y1) = (f64::INFINITY, f64::NEG_INFINITY, f64::INFINITY, f64::NEG_INFINITY);
    for &(x, y) in pts {
        x0 = x0.min(x);
        x1 = x1.max(x);
        y0 = y0.min(y);
        y1 = y1.max(y);
    }
    if !x0.is_finite() {
        return None;
    }
    if x1 <= x0 {
        x1 = x0 + 1.0;
    }
    if y1 <= y0 {
        // A flat curve (a constant lr): a range around it, so the axis has labels.
        (y0, y1) = match scale {
            Scale::Log => (y0 / 2.0, y1 * 2.0),
            Scale::Linear => {
                let pad = if y0 == 0.0 { 1.0 } else { y0.abs() * 0.1 };
                (y0 - pad, y1 + pad)
            }
        };
    }
    Some((x0, x1, y0, y1))
}

/// Draws named curves into one panel of a drawing area.
pub fn draw_panel(area: &DrawingArea<BitMapBackend<'_>, Shift>, title: &str, x_desc: &str, y_desc: &str, series: &[Series], scale: Scale, y_range: Option<(f64, f64)>) -> Result<()> {
    register_fonts();
    let Some((x0, x1, mut y0, mut y1)) = bounds(series, scale) else {
        // Nothing to draw yet: a titled empty panel.
        area.titled(title, ("sans-serif", 20)).map_err(pe)?;
        return Ok(());
    };
    if let Some((a, b)) = y_range {
        (y0, y1) = (a, b);
    }
    let mut builder = ChartBuilder::on(area);
    builder.caption(title, ("sans-serif", 20)).margin(12).x_label_area_size(40).y_label_area_size(70);
    let colors: Vec<RGBColor> = (0..series.len()).map(|i| Palette99::pick(i).to_rgba()).map(|c| RGBColor(c.0, c.1, c.2)).collect();
    macro_rules! body {
        ($chart:ident) => {{
            $chart.configure_mesh().x_desc(x_desc).y_desc(y_desc).label_style(("sans-serif", 14)).draw().map_err(pe)?;
            for (s, &c) in series.iter().zip(&colors) {
                let pts: Vec<(f64, f64)> = s.points.iter().copied().filter(|p| scale == Scale::Linear || p.1 > 0.0).collect();
                $chart
                    .draw_series(LineSeries::new(pts, c.stroke_width(2)))
                    .map_err(pe)?
                    .label(s.label.clone())
                    .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], c.stroke_width(2)));
            }
            $chart
                .configure_series_labels()
                .position(SeriesLabelPosition::UpperRight)
                .label_font(("sans-serif", 14))
                .background_style(WHITE.mix(0.85))
                .border_style(BLACK)
                .draw()
                .map_err(pe)?;
        }};
    }
    match scale {
        Scale::Linear => {
            let mut chart = builder.build_cartesian_2d(x0..x1, y0..y1).map_err(pe)?;
            body!(chart);
        }
        Scale::Log => {
            let mut chart = builder.build_cartesian_2d(x0..x1, (y0..y1).log_scale()).map_err(pe)?;
            body!(chart);
        }
    }
    Ok(())
}

/// One PNG with one panel of named curves.
pub fn plot_lines(path: &Path, title: &str, x_desc: &str, y_desc: &str, series: &[Series], scale: Scale) -> Result<()> {
    let root = BitMapBackend::new(path, (1000, 600)).into_drawing_area();
    root.fill(&WHITE).map_err(pe)?;
    draw_panel(&root, title, x_desc, y_desc, series, scale, None)?;
    root.present().map_err(pe)?;
    Ok(())
}

/// Redraws `plots/steps.png` and `plots/epochs.png` from the run's CSV files (those that exist).
pub fn plot_run(run: &RunDir) -> Result<()> {
    std::fs::create_dir_all(run.plots())?;
    if run.metrics_csv().exists() {
        let t = Table::read(&run.metrics_csv())?;
        let step = t.column("step").unwrap_or_default();
        let skip = ["step", "epoch", "lr", "seconds", "time"];
        let losses: Vec<Series> = t.header.iter().filter(|h| !skip.contains(&h.as_str())).map(|h| Series::new(h.clone(), &step, &t.column(h).unwrap_or_default())).collect();
        let lr = [Series::new("lr", &step, &t.column("lr").unwrap_or_default())];
        let path = run.plots().join("steps.png");
        let root = BitMapBackend::new(&path, (1000, 900)).into_drawing_area();
        root.fill(&WHITE).map_err(pe)?;
        let (top, bottom) = root.split_vertically(600);
        draw_panel(&top, "training loss per step", "step", "loss (log)", &losses, Scale::Log, None)?;
        draw_panel(&bottom, "learning rate", "step", "lr (log)", &lr, Scale::Log, None)?;
        root.present().map_err(pe)?;
    }
    if run.epochs_csv().exists() {
        let t = Table::read(&run.epochs_csv())?;
        let epoch = t.column("epoch").unwrap_or_default();
        let skip = ["epoch", "steps", "lr", "ap3d_0.3", "ap3d_0.5", "ap3d_0.7", "train_seconds", "val_seconds", "time"];
        let losses: Vec<Series> = t.header.iter().filter(|h| !skip.contains(&h.as_str())).map(|h| Series::new(h.clone(), &epoch, &t.column(h).unwrap_or_default())).collect();
        let aps: Vec<Series> = ["0.3", "0.5", "0.7"]
            .iter()
            .map(|k| {
                let y: Vec<f64> = t.column(&format!("ap3d_{k}")).unwrap_or_default().iter().map(|v| 100.0 * v).collect();
                Series::new(format!("AP3D@{k}"), &epoch, &y)
            })
            .collect();
        let path = run.plots().join("epochs.png");
        let root = BitMapBackend::new(&path, (1000, 900)).into_drawing_area();
        root.fill(&WHITE).map_err(pe)?;
        let (top, bottom) = root.split_vertically(450);
        draw_panel(&top, "mean training loss per epoch", "epoch", "loss (log)", &losses, Scale::Log, None)?;
        draw_panel(&bottom, "validation AP3D (%)", "epoch", "AP3D (%)", &aps, Scale::Linear, Some((0.0, 100.0)))?;
        root.present().map_err(pe)?;
    }
    Ok(())
}
