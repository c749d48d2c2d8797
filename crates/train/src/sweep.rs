//! Sweeps: a base config, variants (named overrides, or a grid over keys) and seeds; every
//! (variant, seed) is one run folder; finished runs are skipped on a re-run and unfinished ones
//! resumed; then `results.csv`, `results.md` and `curves.png` summarise the variants.
//!
//! ```toml
//! name = "compare"                # sweep folder under out_dir (default: the file's stem)
//! base = "../quickstart.toml"     # relative to this file
//! out_dir = "runs"                # default "runs"
//! seeds = [0, 1, 2]
//! [set]                           # overrides for every variant (dotted keys, TOML values)
//! "train.epochs" = 8
//! [[variants]]                    # either named variants ...
//! name = "minkunet"
//! set = { "model.width" = 0.5 }
//! [[variants]]
//! name = "centerpoint"
//! set = { model = { kind = "centerpoint", width = 0.25 } }   # a table replaces the whole table
//! [grid]                          # ... or a grid: every combination of these values
//! "model.epsilon" = [0.1, 0.2, 0.4]
//! ```
//!
//! Layout: `<out_dir>/<name>/<variant>/seed-<s>/` (a run folder each), `results.csv`, `results.md`,
//! `curves.png`. AP is the **last** validation of each run (no selection on the validation split);
//! mean ± sample standard deviation (n − 1) over seeds.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use serde::{Deserialize, Serialize};

use crate::checkpoint::Slot;
use crate::config::{RunConfig, set_key};
use crate::infer::{InferOptions, infer};
use crate::metrics::Table;
use crate::plots::{Scale, Series, plot_lines};
use crate::run_dir::{RunDir, write_atomic};
use crate::trainer::TrainSummary;

/// A sweep file.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SweepConfig {
    /// Folder name of the sweep (default: the file's stem).
    #[serde(default)]
    pub name: Option<String>,
    /// The base run config, relative to the sweep file.
    pub base: PathBuf,
    /// Parent of the sweep folder.
    #[serde(default = "default_out")]
    pub out_dir: PathBuf,
    /// Seeds every variant runs with.
    #[serde(default = "default_seeds")]
    pub seeds: Vec<u64>,
    /// Overrides for every variant.
    #[serde(default)]
    pub set: BTreeMap<String, toml::Value>,
    /// Named variants.
    #[serde(default)]
    pub variants: Vec<Variant>,
    /// A grid: every combination of these keys' values.
    #[serde(default)]
    pub grid: BTreeMap<String, Vec<toml::Value>>,
}

fn default_out() -> PathBuf {
    PathBuf::from("runs")
}
fn default_seeds() -> Vec<u64> {
    vec![0]
}

/// A named set of overrides.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Variant {
    /// Name (its folder).
    pub name: String,
    /// Dotted key → value.
    #[serde(default)]
    pub set: BTreeMap<String, toml::Value>,
}

/// One run of a sweep.
#[derive(Debug, Clone, PartialEq)]
pub struct Job {
    /// Variant name.
    pub variant: String,
    /// Seed.
    pub seed: u64,
    /// Resolved config.
    pub config: RunConfig,
    /// Its run folder.
    pub dir: PathBuf,
}

impl SweepConfig {
    /// Reads a sweep file.
    pub fn load(path: &Path) -> Result<(Self, PathBuf)> {
        let text = std::fs::read_to_string(path).with_context(|| format!("reading sweep {}", path.display()))?;
        let mut cfg: SweepConfig = toml::from_str(&text).map_err(|e| anyhow::anyhow!("{e}")).with_context(|| format!("in sweep {}", path.display()))?;
        if cfg.name.is_none() {
            cfg.name = path.file_stem().map(|s| s.to_string_lossy().into_owned());
        }
        let base = path.parent().unwrap_or(Path::new(".")).join(&cfg.base);
        Ok((cfg, base))
    }

    /// The variants: the named ones, or every grid combination (a single `base` variant if neither).
    pub fn variants(&self) -> Result<Vec<Variant>> {
        if !self.variants.is_empty() && !self.grid.is_empty() {
            bail!("a sweep has either [[variants]] or [grid], not both");
        }
        if !self.variants.is_empty() {
            let mut names: Vec<&str> = self.variants.iter().map(|v| v.name.as_str()).collect();
            names.sort_unstable();
            names.dedup();
            if names.len() != self.variants.len() {
                bail!("variant names must be unique");
            }
            return Ok(self.variants.clone());
        }
        if self.grid.is_empty() {
            return Ok(vec![Variant { name: "base".into(), set: BTreeMap::new() }]);
        }
        let mut combos: Vec<Vec<(String, toml::Value)>> = vec![vec![]];
        for (k, values) in &self.grid {
            if values.is_empty() {
                bail!("grid key `{k}` has no values");
            }
            combos = combos.into_iter().flat_map(|c| values.iter().map(move |v| [c.clone(), vec![(k.clone(), v.clone())]].concat())).collect();
        }
        Ok(combos
            .into_iter()
            .map(|c| Variant { name: c.iter().map(|(k, v)| format!("{}={}", k.rsplit('.').next().unwrap_or(k), value_name(v))).collect::<Vec<_>>().join(","), set: c.into_iter().collect() })
            .collect())
    }

    /// The sweep's folder.
    pub fn dir(&self) -> PathBuf {
        self.out_dir.join(self.name.as_deref().unwrap_or("sweep"))
    }

    /// Every (variant, seed) run with its resolved config.
    pub fn jobs(&self, base: &Path) -> Result<Vec<Job>> {
        let text = std::fs::read_to_string(base).with_context(|| format!("reading base config {}", base.display()))?;
        let base_value: toml::Value = toml::from_str(&text).with_context(|| format!("parsing {}", base.display()))?;
        let mut jobs = Vec::new();
        for v in self.variants()? {
            for &seed in &self.seeds {
                let mut value = base_value.clone();
                for (k, x) in self.set.iter().chain(&v.set) {
                    set_key(&mut value, k, x.clone())?;
                }
                set_key(&mut value, "seed", toml::Value::Integer(seed as i64))?;
                set_key(&mut value, "name", toml::Value::String(format!("seed-{seed}")))?;
                let dir = self.dir().join(&v.name).join(format!("seed-{seed}"));
                set_key(&mut value, "out_dir", toml::Value::String(self.dir().join(&v.name).to_string_lossy().into_owned()))?;
                let config = RunConfig::from_toml_value(value).with_context(|| format!("variant `{}`", v.name))?;
                jobs.push(Job { variant: v.name.clone(), seed, config, dir });
            }
        }
        Ok(jobs)
    }
}

fn value_name(v: &toml::Value) -> String {
    match v {
        toml::Value::String(s) => s.clone(),
        toml::Value::Array(a) => a.iter().map(value_name).collect::<Vec<_>>().join("x"),
        other => other.to_string(),
    }
}

/// A finished run's summary, if the run is finished.
pub fn finished(dir: &Path) -> Option<TrainSummary> {
    let text = std::fs::read_to_string(RunDir::at(dir).summary_json()).ok()?;
    let s: TrainSummary = serde_json::from_str(&text).ok()?;
    s.finished.then_some(s)
}

/// Scores a finished run again under `job`'s post-processing and evaluation settings, which may
/// have changed since it trained (they do not change what it learned): its latest checkpoint on
/// the validation split, as the end of training validates. Every other setting must be the one
/// it trained with (its `name` and `out_dir` aside: a run copied in from another sweep is
/// rescored too). The run's `config.toml` takes the new settings, its `summary.json` the new
/// scores, its `detections/val/` the detections; the run's own training record is unchanged.
/// `None` when the run is not finished (nothing is touched).
pub fn rescore(job: &Job, verbose: bool) -> Result<Option<TrainSummary>> {
    let run = RunDir::at(&job.dir);
    let Some(mut summary) = finished(&job.dir) else { return Ok(None) };
    let mut stored = run.config()?;
    *stored.model.post_mut() = job.config.model.post().clone();
    stored.eval = job.config.eval.clone();
    // Where the run lives is not what it learned: a run copied in from another sweep (as the
    // compare sweep's comments suggest) is rescored like its own.
    (stored.name, stored.out_dir) = (job.config.name.clone(), job.config.out_dir.clone());
    if stored != job.config {
        bail!(
            "{}: only [model.post] and [eval] may differ from the settings the run trained with; retrain it instead",
            job.dir.display()
        );
    }
    let before = std::fs::read(run.config_file())?;
    write_atomic(&run.config_file(), job.config.to_toml()?.as_bytes())?;
    let opts = InferOptions { split: job.config.data.val_split, checkpoint: Some(Slot::Latest), render: 0, backend: None, verbose, data_root: None, set: vec![], out: None };
    // A run that cannot be scored (no checkpoint, say) keeps the settings it was scored with.
    let out = match infer(&run, &opts) {
        Ok(out) => out,
        Err(e) => {
            write_atomic(&run.config_file(), &before)?;
            return Err(e.context(format!("{}: not rescored, its config.toml left as it was", job.dir.display())));
        }
    };
    summary.last_ap3d = Some(out.ap3d);
    summary.last_ap3d_by_range = Some(out.ap3d_by_range);
    summary.last_heading = out.heading;
    write_atomic(&run.summary_json(), serde_json::to_string_pretty(&summary)?.as_bytes())?;
    Ok(Some(summary))
}

/// Runs every job not finished yet with `run_job` (which trains into `job.dir`, resuming what is
/// there), or, with `variants` not empty, only those variants' jobs (the tables still cover every
/// finished run of the sweep: a long sweep can be run a variant at a time, in any order). The
/// results are written before the first job and after each one, so a sweep stopped after hours
/// still has the tables of the runs it finished. A failed job is reported and the others still
/// run.
pub fn run_sweep(sweep: &SweepConfig, jobs: &[Job], variants: &[String], mut run_job: impl FnMut(&Job) -> Result<TrainSummary>, verbose: bool) -> Result<SweepResults> {
    check_variants(jobs, variants)?;
    std::fs::create_dir_all(sweep.dir())?;
    let mut results = aggregate(jobs);
    results.write(&sweep.dir())?;
    let mut failures = Vec::new();
    for (i, job) in jobs.iter().enumerate() {
        if !variants.is_empty() && !variants.contains(&job.variant) {
            continue;
        }
        if finished(&job.dir).is_some() {
            if verbose {
                eprintln!("[{}/{}] {} seed {}: finished before, skipped", i + 1, jobs.len(), job.variant, job.seed);
            }
            continue;
        }
        if verbose {
            eprintln!("[{}/{}] {} seed {} → {}", i + 1, jobs.len(), job.variant, job.seed, job.dir.display());
        }
        if let Err(e) = run_job(job) {
            eprintln!("{} seed {} failed: {e:#}", job.variant, job.seed);
            failures.push(format!("{} seed {}: {e:#}", job.variant, job.seed));
        }
        results = aggregate(jobs);
        results.write(&sweep.dir())?;
    }
    if !failures.is_empty() {
        bail!("{} of {} runs failed:\n{}", failures.len(), jobs.len(), failures.join("\n"));
    }
    Ok(results)
}

/// An error listing the sweep's variants if `variants` names one it does not have.
pub fn check_variants(jobs: &[Job], variants: &[String]) -> Result<()> {
    if let Some(unknown) = variants.iter().find(|v| !jobs.iter().any(|j| &j.variant == *v)) {
        let mut names: Vec<&str> = jobs.iter().map(|j| j.variant.as_str()).collect();
        names.dedup();
        bail!("the sweep has no variant '{unknown}' (it has: {})", names.join(", "));
    }
    Ok(())
}

/// Mean and sample standard deviation (n − 1; 0 for one value).
pub fn mean_std(xs: &[f64]) -> (f64, f64) {
    let n = xs.len() as f64;
    if xs.is_empty() {
        return (f64::NAN, f64::NAN);
    }
    let m = xs.iter().sum::<f64>() / n;
    let s = if xs.len() > 1 { (xs.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (n - 1.0)).sqrt() } else { 0.0 };
    (m, s)
}

/// `t_{0.975, df}` for `df ≥ 1` degrees of freedom, rounded down to a whole number (a
/// fractional df, as Welch's, gets the wider interval of the df below it).
fn t975(df: f64) -> f64 {
    // df = 1..=30; beyond, the normal 1.96 is within 2 %.
    const T: [f64; 30] = [
        12.706, 4.303, 3.182, 2.776, 2.571, 2.447, 2.365, 2.306, 2.262, 2.228, 2.201, 2.179, 2.160, 2.145, 2.131, 2.120, 2.110, 2.101, 2.093, 2.086,
        2.080, 2.074, 2.069, 2.064, 2.060, 2.056, 2.052, 2.048, 2.045, 2.042,
    ];
    T.get((df.floor().max(1.0) as usize) - 1).copied().unwrap_or(1.96)
}

/// Half-width of the two-sided 95 % confidence interval of the mean of `n` values with sample
/// standard deviation `std` (Student's t with n − 1 degrees of freedom); NaN below 2 values.
pub fn ci95_half_width(n: usize, std: f64) -> f64 {
    if n < 2 {
        return f64::NAN;
    }
    t975((n - 1) as f64) * std / (n as f64).sqrt()
}

/// The difference of two means, `mean(a) − mean(b)`, and the half-width of its two-sided 95 %
/// interval by Welch's t (unequal variances, Welch–Satterthwaite degrees of freedom rounded
/// down): whether one variant ranks above another beyond the seeds' spread. NaN half-width below
/// 2 values on either side.
pub fn welch_ci95(a: &[f64], b: &[f64]) -> (f64, f64) {
    let ((ma, sa), (mb, sb)) = (mean_std(a), mean_std(b));
    if a.len() < 2 || b.len() < 2 {
        return (ma - mb, f64::NAN);
    }
    let (va, vb) = (sa * sa / a.len() as f64, sb * sb / b.len() as f64);
    let se2 = va + vb;
    if se2 == 0.0 {
        return (ma - mb, 0.0);
    }
    let df = se2 * se2 / (va * va / (a.len() - 1) as f64 + vb * vb / (b.len() - 1) as f64);
    (ma - mb, t975(df) * se2.sqrt())
}

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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn mean_and_sample_std() {
        let (m, s) = mean_std(&[1.0, 2.0, 3.0]);
        assert!((m - 2.0).abs() < 1e-12 && (s - 1.0).abs() < 1e-12);
        assert_eq!(mean_std(&[0.5]), (0.5, 0.0));
        assert!(mean_std(&[]).0.is_nan());
    }

    #[test]
    fn ci95_uses_students_t() {
        // n = 3, std 1: t_{0.975, 2} = 4.303, / √3.
        assert!((ci95_half_width(3, 1.0) - 4.303 / 3f64.sqrt()).abs() < 1e-12);
        assert!(ci95_half_width(1, 1.0).is_nan());
        assert!((ci95_half_width(100, 2.0) - 1.96 * 0.2).abs() < 1e-12);
    }

    #[test]
    fn welch_interval_of_a_difference() {
        // Hand-derived: both std 1, n = 3: se² = 1/3 + 1/3, df = (2/3)² / (2 · (1/3)² / 2) = 4,
        // t_{0.975, 4} = 2.776.
        let (d, h) = welch_ci95(&[1.0, 2.0, 3.0], &[4.0, 5.0, 6.0]);
        assert!((d + 3.0).abs() < 1e-12 && (h - 2.776 * (2.0f64 / 3.0).sqrt()).abs() < 1e-12, "{d} {h}");
        // Unequal variances: a's std 1 (n = 3), b's std 3 (n = 2): va = 1/3, vb = 4.5,
        // df = (29/6)² / ((1/3)²/2 + 4.5²) = 1.15, rounded down to 1: t = 12.706.
        let (d, h) = welch_ci95(&[1.0, 2.0, 3.0], &[0.0, 4.2426406871192848]);
        let se = (1.0f64 / 3.0 + 4.5).sqrt();
        assert!((d - (2.0 - 2.1213203435596424)).abs() < 1e-12 && (h - 12.706 * se).abs() < 1e-9, "{d} {h}");
        assert!(welch_ci95(&[1.0], &[2.0, 3.0]).1.is_nan());
        assert_eq!(welch_ci95(&[1.0, 1.0], &[2.0, 2.0]), (-1.0, 0.0));
    }

    #[test]
    fn grid_expands_to_every_combination() {
        let s: SweepConfig = toml::from_str("base = \"b.toml\"\n[grid]\n\"model.width\" = [0.5, 1.0]\n\"data.voxel_size\" = [[0.05, 0.05, 0.1], [0.1, 0.1, 0.1]]\n").unwrap();
        let v = s.variants().unwrap();
        assert_eq!(v.len(), 4);
        assert!(v.iter().all(|x| x.set.len() == 2));
        let names: Vec<&str> = v.iter().map(|x| x.name.as_str()).collect();
        assert!(names.contains(&"voxel_size=0.05x0.05x0.1,width=0.5"), "{names:?}");
        assert!(toml::from_str::<SweepConfig>("base = \"b\"\nvariant = []\n").is_err(), "unknown keys are refused");
    }
}
