//! Weight soups: the element-wise mean of several runs' weights, written as a run of its own.
//!
//! Runs fine-tuned from one set of weights stay in one basin, so the mean of their weights is a
//! network of its own, at one network's cost, that answers like the average of theirs
//! ("model soups", Wortsman et al., ICML 2022). Every float tensor a module holds is averaged,
//! its BatchNorm running statistics included (not re-estimated): averaging suits ingredients
//! close to each other, which [`SoupReport`] measures.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail, ensure};
use burn::module::{Module, ModuleMapper, ModuleVisitor, Param};
use burn::tensor::{Device, Tensor, TensorData};
use model::ModelConfig;
use serde::Serialize;

use crate::checkpoint::{CheckpointFiles, Checkpoints, Slot, TrainState};
use crate::config::RunConfig;
use crate::run_dir::{RunDir, write_atomic};

/// What a soup was made of and how far apart its ingredients were.
#[derive(Debug, Clone, Serialize)]
pub struct SoupReport {
    /// The runs averaged, with the checkpoint each gave.
    pub ingredients: Vec<PathBuf>,
    /// Float tensors averaged (weights and running statistics).
    pub tensors: usize,
    /// Values averaged in all.
    pub values: usize,
    /// Each ingredient's distance to the soup, ‖wᵢ − w̄‖ / ‖w̄‖ over every value.
    pub relative_distance: Vec<f64>,
}

impl std::fmt::Display for SoupReport {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        writeln!(f, "soup of {} runs: {} tensors, {} values averaged", self.ingredients.len(), self.tensors, self.values)?;
        for (run, d) in self.ingredients.iter().zip(&self.relative_distance) {
            writeln!(f, "  {}: ‖w − soup‖ / ‖soup‖ = {d:.5}", run.display())?;
        }
        Ok(())
    }
}

/// Averages the latest checkpoints of `runs` (same network shape; post-processing may differ)
/// into a new run folder `out`: the first run's config with its post-processing calibration
/// (`model.post.radial_shift`) cleared, and one weights-only checkpoint. Fit its radial shift and
/// facing stage afterwards (`train calibrate`, `train facing`), as for a trained run.
pub fn soup(runs: &[PathBuf], out: &Path) -> Result<SoupReport> {
    ensure!(!runs.is_empty(), "a soup needs at least one run (--run)");
    ensure!(!out.exists(), "{} already exists; a soup is written to a new folder", out.display());
    let configs = runs
        .iter()
        .map(|r| RunDir::at(r).config().with_context(|| format!("{} is not a run folder", r.display())))
        .collect::<Result<Vec<_>>>()?;
    let shape_of = |m: &ModelConfig| {
        let mut m = m.clone();
        *m.post_mut() = Default::default();
        m
    };
    let first = shape_of(&configs[0].model);
    for (run, cfg) in runs.iter().zip(&configs).skip(1) {
        if shape_of(&cfg.model) != first {
            bail!("{}'s [model] differs from {}'s beyond post-processing: their weights cannot be averaged", run.display(), runs[0].display());
        }
    }
    let files = runs
        .iter()
        .map(|r| {
            Checkpoints::new(RunDir::at(r).checkpoints())
                .get(Slot::Latest)?
                .with_context(|| format!("{} has no checkpoint to average", r.display()))
        })
        .collect::<Result<Vec<_>>>()?;
    let device = configs[0].backend.device()?;
    let mut config = configs[0].clone();
    config.model.post_mut().radial_shift = 0.0;
    config.name = out.file_name().map(|n| n.to_string_lossy().into_owned());
    let report = match &configs[0].model {
        ModelConfig::PersonMinkunet(c) => average_into(runs, &files, || c.init(&device), &device, &config, out)?,
        ModelConfig::Centerpoint(c) => average_into(runs, &files, || c.init(&device), &device, &config, out)?,
    };
    write_atomic(&out.join("soup.json"), serde_json::to_string_pretty(&report)?.as_bytes())?;
    Ok(report)
}

/// Loads each run's checkpoint into a fresh model of one type, averages them and writes the run.
fn average_into<M: Module>(runs: &[PathBuf], files: &[CheckpointFiles], init: impl Fn() -> M, device: &Device, config: &RunConfig, out: &Path) -> Result<SoupReport> {
    let models = runs.iter().zip(files).map(|(r, f)| f.load_model(init()).with_context(|| format!("{}'s weights", r.display()))).collect::<Result<Vec<_>>>()?;
    let (soup, report) = average(models, files.iter().map(|f| f.dir.clone()).collect(), device)?;
    write_run(&soup, config, out)?;
    Ok(report)
}

/// Writes `model` as the only checkpoint of a new run folder with `config`.
fn write_run<M: Module>(model: &M, config: &RunConfig, out: &Path) -> Result<()> {
    let dir = RunDir::create(out, config, crate::run_dir::Existing::Refuse)?;
    Checkpoints::new(dir.checkpoints()).save_weights(model, &TrainState::default(), &[Slot::Latest, Slot::Best])?;
    Ok(())
}

/// The element-wise mean of `models` (one architecture), as the first model's structure.
pub fn average<M: Module>(models: Vec<M>, ingredients: Vec<PathBuf>, device: &Device) -> Result<(M, SoupReport)> {
    let mut models = models.into_iter();
    let first = models.next().context("nothing to average")?;
    let mut sum = Gather::default();
    first.visit(&mut sum);
    let mut values = vec![sum.values.clone()];
    let mut count = 1.0;
    for (k, m) in models.enumerate() {
        let mut g = Gather::default();
        m.visit(&mut g);
        ensure!(g.shapes == sum.shapes, "ingredient {} has other tensors than the first", k + 2);
        for (s, v) in sum.values.iter_mut().zip(&g.values) {
            for (a, b) in s.iter_mut().zip(v) {
                *a += b;
            }
        }
        values.push(g.values);
        count += 1.0;
    }
    let mean: Vec<Vec<f64>> = sum.values.iter().map(|v| v.iter().map(|x| x / count).collect()).collect();
    let norm = mean.iter().flatten().map(|x| x * x).sum::<f64>().sqrt().max(f64::MIN_POSITIVE);
    let relative_distance = values
        .iter()
        .map(|vs| vs.iter().flatten().zip(mean.iter().flatten()).map(|(a, b)| (a - b) * (a - b)).sum::<f64>().sqrt() / norm)
        .collect();
    let report = SoupReport { ingredients, tensors: sum.shapes.len(), values: mean.iter().map(Vec::len).sum(), relative_distance };
    let mut put = Put { means: mean.into_iter(), device: device.clone() };
    Ok((first.map(&mut put), report))
}

/// Every float tensor of a module in visiting order, as f64.
#[derive(Default)]
struct Gather {
    shapes: Vec<Vec<usize>>,
    values: Vec<Vec<f64>>,
}

impl ModuleVisitor for Gather {
    fn visit_float<const D: usize>(&mut self, param: &Param<Tensor<D>>) {
        let t = param.val();
        self.shapes.push(t.shape().to_vec());
        let values = t.into_data().try_to_vec::<f32>().expect("float tensors of a CPU model are f32");
        self.values.push(values.into_iter().map(f64::from).collect());
    }
}

/// Replaces every float tensor by the next mean, in the order [`Gather`] met them.
struct Put {
    means: std::vec::IntoIter<Vec<f64>>,
    device: Device,
}

impl ModuleMapper for Put {
    fn map_float<const D: usize>(&mut self, param: Param<Tensor<D>>) -> Param<Tensor<D>> {
        let mean = self.means.next().expect("the same module visited and mapped");
        let device = self.device.clone();
        param.map(|t| {
            let shape = t.shape();
            let data = TensorData::new(mean.into_iter().map(|x| x as f32).collect::<Vec<f32>>(), shape);
            Tensor::from_data(data, &device)
        })
    }
}
