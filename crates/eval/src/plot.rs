//! PNG of the PR curves, drawn without text so no system font library is needed.
//!
//! Layout: the unit square recall (x) × precision (y) with a 0.1 grid; AP3D curves solid at IoU
//! 0.3 (red), 0.5 (green), 0.7 (blue); APBEV curves (non-official) in lighter shades.

use std::path::Path;

use plotters::prelude::*;

use crate::error::{EvalError, Result};
use crate::report::Report;

/// Writes the overall PR curves of `report` to a PNG.
pub fn plot_pr(report: &Report, path: &Path) -> Result<()> {
    let err = |e: String| EvalError::io(path, std::io::Error::other(e));
    let root = BitMapBackend::new(path, (800, 800)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| err(e.to_string()))?;
    let area = root.margin(30, 30, 30, 30);
    let mut chart = ChartBuilder::on(&area)
        .build_cartesian_2d(0f64..1f64, 0f64..1f64)
        .map_err(|e| err(e.to_string()))?;
    let grid = RGBColor(220, 220, 220);
    for i in 0..=10 {
        let v = i as f64 / 10.0;
        let style = if i == 0 || i == 10 {
            BLACK.stroke_width(2)
        } else {
            grid.stroke_width(1)
        };
        chart
            .draw_series(LineSeries::new([(v, 0.0), (v, 1.0)], style))
            .map_err(|e| err(e.to_string()))?;
        chart
            .draw_series(LineSeries::new([(0.0, v), (1.0, v)], style))
            .map_err(|e| err(e.to_string()))?;
    }
    let solid = [
        RGBColor(220, 30, 30),
        RGBColor(30, 160, 30),
        RGBColor(30, 30, 220),
    ];
    let light = [
        RGBColor(245, 160, 160),
        RGBColor(160, 220, 160),
        RGBColor(160, 160, 245),
    ];
    for (curves, colors) in [(&report.apbev, light), (&report.ap3d, solid)] {
        for (c, color) in curves.iter().zip(colors) {
            let pts: Vec<(f64, f64)> = (0..c.thresholds.len())
                .filter(|&k| c.recall[k].is_finite())
                .map(|k| (c.recall[k], c.precision[k]))
                .collect();
            chart
                .draw_series(LineSeries::new(pts, color.stroke_width(3)))
                .map_err(|e| err(e.to_string()))?;
        }
    }
    root.present().map_err(|e| err(e.to_string()))?;
    Ok(())
}
