//! Running a sweep's jobs: the [`Executor`] seam, the local one, and rescoring.

use anyhow::{Context, Result, bail};

use super::{Job, SweepConfig, SweepResults, aggregate, check_variants, finished};
use crate::checkpoint::Slot;
use crate::infer::{InferOptions, infer};
use crate::run_dir::{Existing, RunDir, write_atomic};
use crate::trainer::{TrainOptions, TrainSummary, train};

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
    let opts = InferOptions { split: job.config.data.val_split, checkpoint: Some(Slot::Latest), render: 0, backend: None, verbose, data_root: None, data_format: None, set: vec![], out: None };
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

/// Where a sweep's runs execute. [`Local`] trains them one after another in this process; a
/// cluster's scheduler is another implementation (it would submit them and report them pending).
/// The run folders are the contract: an executor trains `job.config` into `job.dir`, resuming
/// what is there, and [`aggregate`] reads whatever has finished.
pub trait Executor {
    /// Runs (or hands on) `todo`, the jobs selected and not finished yet, in order; `written`
    /// rewrites the sweep's tables and is to be called whenever a run may have finished. Returns
    /// the failures, one line each.
    fn execute(&mut self, todo: &[&Job], written: &mut dyn FnMut() -> Result<()>, verbose: bool) -> Result<Vec<String>>;
}

/// The local executor: each job by `run_job` in turn, the tables rewritten after each, a failed
/// one reported and the others still run.
pub struct Local<F: FnMut(&Job) -> Result<TrainSummary>> {
    /// Trains one job into its run folder.
    pub run_job: F,
}

impl<F: FnMut(&Job) -> Result<TrainSummary>> Executor for Local<F> {
    fn execute(&mut self, todo: &[&Job], written: &mut dyn FnMut() -> Result<()>, verbose: bool) -> Result<Vec<String>> {
        let mut failures = Vec::new();
        for (i, job) in todo.iter().enumerate() {
            if verbose {
                eprintln!("[{}/{}] {} seed {} → {}", i + 1, todo.len(), job.variant, job.seed, job.dir.display());
            }
            if let Err(e) = (self.run_job)(job) {
                eprintln!("{} seed {} failed: {e:#}", job.variant, job.seed);
                failures.push(format!("{} seed {}: {e:#}", job.variant, job.seed));
            }
            written()?;
        }
        Ok(failures)
    }
}

/// The local executor that trains each job as `train --config <run folder>/config.toml` would:
/// into its run folder, resuming a folder that holds one, capped at `max_steps` / `max_epochs`.
pub fn training(max_steps: Option<u64>, max_epochs: Option<usize>) -> Local<impl FnMut(&Job) -> Result<TrainSummary>> {
    Local {
        run_job: move |job: &Job| {
            let existing = if job.dir.join("config.toml").exists() { Existing::Resume } else { Existing::Refuse };
            job.config.backend.device()?;
            let run = RunDir::create(&job.dir, &job.config, existing)?;
            let opts = TrainOptions { resume: existing == Existing::Resume, max_steps, max_epochs, verbose: true, stop: None };
            train(&job.config, &run, &opts)
        },
    }
}

/// The local executor for `--jobs N`: up to `jobs` runs at once, each a child process of this
/// binary (`train --config <variant>/seed-<s>.toml`, its output in `<variant>/seed-<s>.log`)
/// with the machine's cores split between them (`threads` = cores / jobs; results do not depend
/// on the thread count). The simulated trees are generated first, one at a time, so that runs
/// starting together do not race to write the same tree.
pub struct Processes {
    /// Runs at once.
    pub jobs: usize,
    /// Cap each run's steps (as `--max-steps`).
    pub max_steps: Option<u64>,
    /// Cap each run's epochs (as `--max-epochs`).
    pub max_epochs: Option<usize>,
}

impl Processes {
    fn spawn(&self, job: &Job, threads: usize) -> Result<std::process::Child> {
        let variant_dir = job.dir.parent().context("a run folder has a parent")?;
        std::fs::create_dir_all(variant_dir)?;
        let stem = job.dir.file_name().context("a run folder has a name")?.to_string_lossy().into_owned();
        let mut config = job.config.clone();
        config.threads = Some(threads);
        let config_path = variant_dir.join(format!("{stem}.toml"));
        write_atomic(&config_path, config.to_toml()?.as_bytes())?;
        let log = std::fs::File::create(variant_dir.join(format!("{stem}.log")))?;
        let mut cmd = std::process::Command::new(std::env::current_exe()?);
        cmd.arg("--config").arg(&config_path).arg("--quiet");
        if job.dir.join("config.toml").exists() {
            cmd.arg("--resume");
        }
        if let Some(n) = self.max_steps {
            cmd.arg("--max-steps").arg(n.to_string());
        }
        if let Some(n) = self.max_epochs {
            cmd.arg("--max-epochs").arg(n.to_string());
        }
        cmd.stdout(log.try_clone()?).stderr(log);
        cmd.spawn().with_context(|| format!("starting {} seed {}", job.variant, job.seed))
    }
}

impl Executor for Processes {
    fn execute(&mut self, todo: &[&Job], written: &mut dyn FnMut() -> Result<()>, verbose: bool) -> Result<Vec<String>> {
        let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
        let threads = (cores / self.jobs.max(1)).max(1);
        for job in todo {
            crate::data::ensure_training_data(&job.config.data)?;
        }
        let mut pending: std::collections::VecDeque<&Job> = todo.iter().copied().collect();
        let mut running: Vec<(&Job, std::process::Child)> = Vec::new();
        let mut failures = Vec::new();
        let total = todo.len();
        let mut started = 0;
        while !pending.is_empty() || !running.is_empty() {
            while running.len() < self.jobs.max(1) {
                let Some(job) = pending.pop_front() else { break };
                started += 1;
                if verbose {
                    eprintln!("[{started}/{total}] {} seed {} → {} ({threads} threads; log beside it)", job.variant, job.seed, job.dir.display());
                }
                match self.spawn(job, threads) {
                    Ok(child) => running.push((job, child)),
                    Err(e) => failures.push(format!("{} seed {}: {e:#}", job.variant, job.seed)),
                }
            }
            std::thread::sleep(std::time::Duration::from_millis(100));
            let mut i = 0;
            while i < running.len() {
                let Some(status) = running[i].1.try_wait()? else {
                    i += 1;
                    continue;
                };
                let (job, _) = running.remove(i);
                if !status.success() {
                    let log = job.dir.with_extension("log");
                    let last = std::fs::read_to_string(&log).ok().and_then(|t| t.lines().rev().find(|l| !l.trim().is_empty()).map(str::to_string)).unwrap_or_default();
                    eprintln!("{} seed {} failed ({status}): {last}", job.variant, job.seed);
                    failures.push(format!("{} seed {}: {status}: {last} (log: {})", job.variant, job.seed, log.display()));
                }
                written()?;
            }
        }
        Ok(failures)
    }
}

/// Runs every job not finished yet with `executor`, or, with `variants` not empty, only those
/// variants' jobs (the tables still cover every finished run of the sweep: a long sweep can be run
/// a variant at a time, in any order). The results are written before the first job and whenever
/// the executor says, so a sweep stopped after hours still has the tables of the runs it finished.
pub fn run_sweep_with(sweep: &SweepConfig, jobs: &[Job], variants: &[String], executor: &mut dyn Executor, verbose: bool) -> Result<SweepResults> {
    check_variants(jobs, variants)?;
    std::fs::create_dir_all(sweep.dir())?;
    aggregate(jobs).write(&sweep.dir())?;
    let mut todo = Vec::new();
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
        todo.push(job);
    }
    let dir = sweep.dir();
    let failures = executor.execute(&todo, &mut || aggregate(jobs).write(&dir), verbose)?;
    let results = aggregate(jobs);
    results.write(&dir)?;
    if !failures.is_empty() {
        bail!("{} of {} runs failed:\n{}", failures.len(), jobs.len(), failures.join("\n"));
    }
    Ok(results)
}

/// [`run_sweep_with`] the local executor `run_job`.
pub fn run_sweep(sweep: &SweepConfig, jobs: &[Job], variants: &[String], run_job: impl FnMut(&Job) -> Result<TrainSummary>, verbose: bool) -> Result<SweepResults> {
    run_sweep_with(sweep, jobs, variants, &mut Local { run_job }, verbose)
}

/// What a sweep would run, one line per job of `variants` (every variant when empty):
/// `variant seed s → run folder`.
pub fn plan(jobs: &[Job], variants: &[String]) -> Result<Vec<String>> {
    check_variants(jobs, variants)?;
    Ok(jobs
        .iter()
        .filter(|j| variants.is_empty() || variants.contains(&j.variant))
        .map(|j| format!("{} seed {} → {}", j.variant, j.seed, j.dir.display()))
        .collect())
}

/// Scores the finished runs of `variants` (every variant when empty) again with their current
/// post-processing (see [`rescore`]) and writes the tables.
pub fn rescore_all(sweep: &SweepConfig, jobs: &[Job], variants: &[String]) -> Result<SweepResults> {
    check_variants(jobs, variants)?;
    for j in jobs.iter().filter(|j| variants.is_empty() || variants.contains(&j.variant)) {
        eprintln!("rescoring {} seed {} ({})", j.variant, j.seed, j.dir.display());
        match rescore(j, true)? {
            None => eprintln!("  not finished, not rescored"),
            Some(s) => {
                if let Some(a) = s.last_ap3d {
                    eprintln!("  AP3D@0.3/0.5/0.7 {:.1}/{:.1}/{:.1}", 100.0 * a[0], 100.0 * a[1], 100.0 * a[2]);
                }
            }
        }
    }
    let results = aggregate(jobs);
    results.write(&sweep.dir())?;
    Ok(results)
}

