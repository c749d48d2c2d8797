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
//!
//! Here: the file format and its expansion into [`Job`](crate::sweep::Job)s; `executor`: who runs
//! them (the [`Executor`](crate::sweep::Executor) seam, the [`Local`](crate::sweep::Local) one that
//! trains in this process, [`Processes`](crate::sweep::Processes) for `--jobs N`, rescoring);
//! `slurm`: the cluster's ([`Slurm`](crate::sweep::Slurm), `--slurm`: a job array and a tables
//! job); `results`: the tables (statistics in [`crate::stats`]).

mod executor;
mod results;
mod slurm;

pub use executor::{Executor, Local, Processes, plan, rescore, rescore_all, run_sweep, run_sweep_with, training};
pub use slurm::{RunState, Slurm};
pub use results::{SweepResults, VariantResult, aggregate};

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use serde::{Deserialize, Serialize};

use crate::config::{RunConfig, set_key};
use crate::run_dir::RunDir;
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

/// An error listing the sweep's variants if `variants` names one it does not have.
pub fn check_variants(jobs: &[Job], variants: &[String]) -> Result<()> {
    if let Some(unknown) = variants.iter().find(|v| !jobs.iter().any(|j| &j.variant == *v)) {
        let mut names: Vec<&str> = jobs.iter().map(|j| j.variant.as_str()).collect();
        names.dedup();
        bail!("the sweep has no variant '{unknown}' (it has: {})", names.join(", "));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

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
