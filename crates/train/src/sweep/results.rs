//! A sweep's tables: per variant, the mean, spread and 95 % interval of AP over seeds, the
//! differences with the first variant, the curves; `results.csv`, `results.md`, `curves.png`.

use std::collections::BTreeMap;
use std::path::Path;

use anyhow::Result;

use super::{Job, finished};
use crate::metrics::Table;
use crate::plots::{Scale, Series, plot_lines};
use crate::run_dir::{RunDir, write_atomic};
use crate::trainer::TrainSummary;
use crate::stats::{ci95_half_width, mean_std, welch_ci95};

/// One variant's aggregate over its finished seeds.
#[derive(Debug, Clone, PartialEq)]
pub struct VariantResult {
    /// Variant name.
    pub variant: String,
    /// Model kind.
    pub model: String,
    /// Seeds finished / planned.
    pub done: usize,
    /// Seeds planned.
    pub planned: usize,
    /// AP3D at 0.3/0.5/0.7: (mean, std) over finished seeds.
    pub ap3d: [(f64, f64); 3],
    /// Half-width of the 95 % interval of each AP3D mean (NaN below 2 seeds).
    pub ap3d_ci95: [f64; 3],
    /// AP3D at 0.3/0.5/0.7 of each finished seed, in seed order.
    pub ap3d_seeds: [Vec<f64>; 3],
    /// AP3D@0.3 per range band (`validate::RANGE_BANDS`), mean over the seeds that report it.
    pub ap3d_03_by_range: Option<[f64; 3]>,
    /// Median heading error of matched boxes (degrees), mean over the seeds that report it.
    pub heading_deg: Option<f64>,
    /// Share of matched boxes pointing within 90° of the truth, mean over the seeds that report it.
    pub direction_right: Option<f64>,
    /// Training time, seconds: (mean, std).
    pub train_seconds: (f64, f64),
    /// Parameters.
    pub params: usize,
    /// Validation AP3D@0.3 per epoch, averaged over finished seeds: (epoch, mean).
    pub curve: Vec<(f64, f64)>,
}

impl VariantResult {
    /// This variant's AP3D mean at threshold `i` minus `other`'s, and the half-width of the
    /// difference's 95 % interval ([`welch_ci95`]).
    pub fn difference(&self, other: &VariantResult, i: usize) -> (f64, f64) {
        welch_ci95(&self.ap3d_seeds[i], &other.ap3d_seeds[i])
    }
}

/// The mean of the values the seeds report; `None` when none does (older summaries lack a field).
fn mean_of_reported(values: impl Iterator<Item = Option<f64>>) -> Option<f64> {
    let values: Vec<f64> = values.flatten().collect();
    (!values.is_empty()).then(|| mean_std(&values).0)
}

/// All variants' results.
#[derive(Debug, Clone, PartialEq)]
pub struct SweepResults {
    /// In variant order.
    pub variants: Vec<VariantResult>,
}

/// Aggregates the finished runs of `jobs` per variant.
pub fn aggregate(jobs: &[Job]) -> SweepResults {
    let mut order: Vec<&str> = Vec::new();
    for j in jobs {
        if !order.contains(&j.variant.as_str()) {
            order.push(&j.variant);
        }
    }
    let variants = order
        .into_iter()
        .map(|v| {
            let mine: Vec<&Job> = jobs.iter().filter(|j| j.variant == v).collect();
            let done: Vec<(TrainSummary, &Job)> = mine.iter().filter_map(|j| finished(&j.dir).map(|s| (s, *j))).collect();
            let ap_values = [0, 1, 2].map(|i| done.iter().filter_map(|(s, _)| s.last_ap3d.map(|a| a[i])).collect::<Vec<_>>());
            let ap3d = ap_values.each_ref().map(|v| mean_std(v));
            let ap3d_ci95 = [0, 1, 2].map(|i| ci95_half_width(ap_values[i].len(), ap3d[i].1));
            let bands: Vec<[[f64; 3]; 3]> = done.iter().filter_map(|(s, _)| s.last_ap3d_by_range).collect();
            let ap3d_03_by_range = (!bands.is_empty()).then(|| [0, 1, 2].map(|b| mean_std(&bands.iter().map(|x| x[b][0]).collect::<Vec<_>>()).0));
            let heading_deg = mean_of_reported(done.iter().map(|(s, _)| s.last_heading.map(|h| h.median_deg)));
            let direction_right = mean_of_reported(done.iter().map(|(s, _)| s.last_heading.and_then(|h| h.direction_right)));
            let mut curves: BTreeMap<i64, Vec<f64>> = BTreeMap::new();
            for (_, j) in &done {
                if let Ok(t) = Table::read(&RunDir::at(&j.dir).epochs_csv()) {
                    let (e, a) = (t.column("epoch").unwrap_or_default(), t.column("ap3d_0.3").unwrap_or_default());
                    for (e, a) in e.into_iter().zip(a).filter(|(_, a)| a.is_finite()) {
                        curves.entry(e as i64).or_default().push(a);
                    }
                }
            }
            VariantResult {
                variant: v.to_string(),
                model: mine[0].config.model.kind().to_string(),
                done: done.len(),
                planned: mine.len(),
                ap3d,
                ap3d_ci95,
                ap3d_seeds: ap_values,
                ap3d_03_by_range,
                heading_deg,
                direction_right,
                train_seconds: mean_std(&done.iter().map(|(s, _)| s.train_seconds).collect::<Vec<_>>()),
                params: done.first().map_or(0, |(s, _)| s.params),
                curve: curves.into_iter().map(|(e, a)| (e as f64, mean_std(&a).0)).collect(),
            }
        })
        .collect();
    SweepResults { variants }
}

impl SweepResults {
    /// The CSV text (AP as fractions, seconds).
    pub fn to_csv(&self) -> Result<String> {
        let mut w = csv::Writer::from_writer(Vec::new());
        w.write_record([
            "variant", "model", "seeds_done", "seeds", "ap3d_0.3_mean", "ap3d_0.3_std", "ap3d_0.3_ci95", "ap3d_0.5_mean", "ap3d_0.5_std", "ap3d_0.5_ci95", "ap3d_0.7_mean",
            "ap3d_0.7_std", "ap3d_0.7_ci95", "ap3d_0.3_0-10m", "ap3d_0.3_10-20m", "ap3d_0.3_20-25m", "heading_error_deg", "heading_direction_right", "train_seconds_mean", "train_seconds_std", "params",
            "d_ap3d_0.3_vs_first", "d_ap3d_0.3_ci95", "d_ap3d_0.5_vs_first", "d_ap3d_0.5_ci95", "d_ap3d_0.7_vs_first", "d_ap3d_0.7_ci95",
        ])?;
        let opt = |x: Option<f64>| x.map_or_else(String::new, |v| format!("{v}"));
        for v in &self.variants {
            let mut row = vec![v.variant.clone(), v.model.clone(), v.done.to_string(), v.planned.to_string()];
            for ((m, s), ci) in v.ap3d.into_iter().zip(v.ap3d_ci95) {
                row.extend([format!("{m}"), format!("{s}"), format!("{ci}")]);
            }
            row.extend((0..3).map(|b| opt(v.ap3d_03_by_range.map(|r| r[b]))));
            row.push(opt(v.heading_deg));
            row.push(opt(v.direction_right));
            row.extend([format!("{}", v.train_seconds.0), format!("{}", v.train_seconds.1), v.params.to_string()]);
            for i in 0..3 {
                let (d, h) = v.difference(&self.variants[0], i);
                row.extend([format!("{d}"), format!("{h}")]);
            }
            w.write_record(&row)?;
        }
        Ok(String::from_utf8(w.into_inner().map_err(|e| anyhow::anyhow!("{e}"))?)?)
    }

    /// The Markdown table (AP in %, mean ± std over seeds, the 95 % interval of the mean in
    /// brackets where there are at least 2 seeds; range bands and heading error where reported).
    pub fn to_markdown(&self) -> String {
        let mut s = String::from(
            "| variant | model | seeds | AP3D@0.3 (%) | AP3D@0.5 (%) | AP3D@0.7 (%) | AP3D@0.3 by range 0–10 / 10–20 / 20–25 m (%) | heading error (direction within 90°) | train time | params |\n|---|---|---|---|---|---|---|---|---|---|\n",
        );
        for v in &self.variants {
            let ap = |i: usize| {
                if v.done == 0 {
                    return "–".to_string();
                }
                let (m, sd) = v.ap3d[i];
                let ci = v.ap3d_ci95[i];
                let interval = if ci.is_finite() { format!(" [{:.1}, {:.1}]", 100.0 * (m - ci), 100.0 * (m + ci)) } else { String::new() };
                format!("{:.1} ± {:.1}{interval}", 100.0 * m, 100.0 * sd)
            };
            let bands = v.ap3d_03_by_range.map_or_else(|| "–".to_string(), |r| format!("{:.1} / {:.1} / {:.1}", 100.0 * r[0], 100.0 * r[1], 100.0 * r[2]));
            let heading = match (v.heading_deg, v.direction_right) {
                (Some(h), Some(r)) => format!("{h:.0}° ({:.0} %)", 100.0 * r),
                (Some(h), None) => format!("{h:.0}°"),
                _ => "–".to_string(),
            };
            let t = if v.done == 0 { "–".to_string() } else { format!("{:.0} ± {:.0} s", v.train_seconds.0, v.train_seconds.1) };
            s.push_str(&format!("| {} | {} | {}/{} | {} | {} | {} | {bands} | {heading} | {} | {} |\n", v.variant, v.model, v.done, v.planned, ap(0), ap(1), ap(2), t, v.params));
        }
        if let [first, rest @ ..] = self.variants.as_slice()
            && !rest.is_empty()
        {
            s.push_str(&format!(
                "\nAgainst `{}`: difference of the means in AP3D points, with its 95 % interval (Welch's t) where both have at least 2 seeds; * where the interval excludes 0.\n\n| variant | Δ AP3D@0.3 | Δ AP3D@0.5 | Δ AP3D@0.7 |\n|---|---|---|---|\n",
                first.variant
            ));
            for v in rest {
                let d = |i: usize| {
                    if v.done == 0 || first.done == 0 {
                        return "–".to_string();
                    }
                    let (d, h) = v.difference(first, i);
                    if h.is_finite() {
                        let star = if (d - h) * (d + h) > 0.0 { " *" } else { "" };
                        format!("{:+.1} [{:+.1}, {:+.1}]{star}", 100.0 * d, 100.0 * (d - h), 100.0 * (d + h))
                    } else {
                        format!("{:+.1}", 100.0 * d)
                    }
                };
                s.push_str(&format!("| {} | {} | {} | {} |\n", v.variant, d(0), d(1), d(2)));
            }
        }
        s
    }

    /// Writes `results.csv`, `results.md` and `curves.png` into `dir`.
    pub fn write(&self, dir: &Path) -> Result<()> {
        write_atomic(&dir.join("results.csv"), self.to_csv()?.as_bytes())?;
        write_atomic(&dir.join("results.md"), self.to_markdown().as_bytes())?;
        let series: Vec<Series> =
            self.variants.iter().map(|v| Series { label: v.variant.clone(), points: v.curve.iter().map(|&(e, a)| (e, 100.0 * a)).collect() }).collect();
        if let Err(e) = plot_lines(&dir.join("curves.png"), "validation AP3D@0.3 (mean over seeds)", "epoch", "AP3D@0.3 (%)", &series, Scale::Linear) {
            eprintln!("warning: curves.png not drawn: {e:#}");
        }
        Ok(())
    }
}

