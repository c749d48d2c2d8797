//! `train`: the pmunet experiment runner.
//!
//! ```text
//! cargo run -p train -- --config experiments/quickstart.toml          # train + validate
//! cargo run -p train -- --config X.toml --resume                        # continue a run
//! cargo run -p train -- infer --run runs/quickstart --split val --render 4
//! cargo run -p train -- sweep experiments/sweeps/compare.toml
//! ```

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::{Context, Result, bail};
use clap::{Args, Parser, Subcommand};
use data_jrdb::Split;
use train::{BackendKind, Existing, InferOptions, RunConfig, RunDir, Slot, SweepConfig, TrainOptions};

#[derive(Parser)]
#[command(name = "train", about = "Train, evaluate and compare 3D person detectors (Person-MinkUNet, CenterPoint)")]
#[command(args_conflicts_with_subcommands = true)]
struct Cli {
    #[command(subcommand)]
    cmd: Option<Cmd>,
    #[command(flatten)]
    train: TrainArgs,
}

#[derive(Args)]
struct TrainArgs {
    /// The run's TOML config.
    #[arg(long)]
    config: Option<PathBuf>,
    /// Backend (overrides the config's `backend`).
    #[arg(long, value_enum)]
    backend: Option<BackendKind>,
    /// Put the run folder under DIR instead of the config's `out_dir` (default `runs/`).
    #[arg(long, value_name = "DIR")]
    out: Option<PathBuf>,
    /// The run's name (its folder; default: the config file's stem).
    #[arg(long)]
    name: Option<String>,
    /// Override a config key: `--set train.epochs=3` (value in TOML syntax; repeatable).
    #[arg(long = "set", value_name = "KEY=VALUE")]
    set: Vec<String>,
    /// Continue the run in its folder from the latest checkpoint.
    #[arg(long, conflicts_with = "overwrite")]
    resume: bool,
    /// Delete an existing run folder of the same name and start over.
    #[arg(long)]
    overwrite: bool,
    /// Stop after this many steps in total (smoke runs; `--resume` goes on later).
    #[arg(long)]
    max_steps: Option<u64>,
    /// Stop after this many epochs in total (the lr schedule still spans `train.epochs`).
    #[arg(long)]
    max_epochs: Option<usize>,
    /// No progress bars or per-epoch lines.
    #[arg(long)]
    quiet: bool,
}

#[derive(Clone, Copy, clap::ValueEnum)]
enum SplitArg {
    Train,
    Val,
    TrainVal,
}

#[derive(Clone, Copy, clap::ValueEnum)]
enum SlotArg {
    Best,
    Latest,
}

#[derive(Subcommand)]
enum Cmd {
    /// Write a run's detections for a split (pmunet JSON + official KITTI layout), score them, draw some.
    Infer {
        /// The run folder.
        #[arg(long)]
        run: PathBuf,
        /// Split to run on.
        #[arg(long, value_enum, default_value = "val")]
        split: SplitArg,
        /// Checkpoint (default: latest; best was picked on the validation frames, so its AP on
        /// them is optimistic).
        #[arg(long, value_enum)]
        checkpoint: Option<SlotArg>,
        /// Draw the first N frames as bird's-eye-view PNGs.
        #[arg(long, default_value_t = 0)]
        render: usize,
        /// Backend (overrides the run's).
        #[arg(long, value_enum)]
        backend: Option<BackendKind>,
        /// Run on this JRDB-format tree (e.g. a simulated benchmark generated with another seed)
        /// instead of the run's own data.
        #[arg(long, value_name = "DIR")]
        data_root: Option<PathBuf>,
        /// Override a key of the run's config for this inference, e.g.
        /// `--set model.post.merge_radius=0.4` (repeatable; the run's config.toml is unchanged).
        #[arg(long = "set", value_name = "KEY=VALUE")]
        set: Vec<String>,
        /// Write the detections and scores here instead of RUN/detections/SPLIT.
        #[arg(long, value_name = "DIR")]
        out: Option<PathBuf>,
    },
    /// Run a sweep file: variants × seeds, then results.csv, results.md and curves.png.
    Sweep {
        /// The sweep's TOML file.
        file: PathBuf,
        /// Backend for every run (overrides the configs').
        #[arg(long, value_enum)]
        backend: Option<BackendKind>,
        /// Stop each run after this many steps (smoke test of a sweep).
        #[arg(long)]
        max_steps: Option<u64>,
        /// Stop each run after this many epochs.
        #[arg(long)]
        max_epochs: Option<usize>,
        /// Only print the runs the sweep would make.
        #[arg(long)]
        dry_run: bool,
        /// Score the finished runs again with the sweep's current [model.post] and [eval]
        /// settings (nothing is retrained; any other change is refused), then write the tables.
        #[arg(long)]
        rescore: bool,
    },
}

/// Makes `backend` Burn's default device before any thread starts (optimizer state loads there).
fn pin(backend: BackendKind) {
    // SAFETY: called from `main` before this process starts any thread.
    unsafe { backend.pin_default_device() };
}

fn run_train(a: TrainArgs) -> Result<()> {
    let Some(path) = a.config else { bail!("--config FILE is required (or a subcommand: infer, sweep); see --help") };
    let mut cfg = RunConfig::load(&path, &a.set)?;
    if let Some(b) = a.backend {
        cfg.backend = b;
    }
    if let Some(o) = a.out {
        cfg.out_dir = o;
    }
    if let Some(n) = a.name {
        cfg.name = Some(n);
    }
    pin(cfg.backend);
    let dir = cfg.out_dir.join(cfg.name.as_deref().unwrap_or("run"));
    let existing = if a.resume {
        Existing::Resume
    } else if a.overwrite {
        Existing::Overwrite
    } else {
        Existing::Refuse
    };
    // A backend that cannot start fails before the run folder exists (a folder left behind
    // would make the next attempt ask for --resume or --overwrite).
    cfg.backend.device()?;
    let run = RunDir::create(&dir, &cfg, existing)?;
    let opts = TrainOptions { resume: a.resume, max_steps: a.max_steps, max_epochs: a.max_epochs, verbose: !a.quiet };
    let s = train::train(&cfg, &run, &opts)?;
    let ap = s.last_ap3d.map_or_else(|| "not validated".to_string(), |a| format!("AP3D@0.3/0.5/0.7 {:.1}/{:.1}/{:.1} %", 100.0 * a[0], 100.0 * a[1], 100.0 * a[2]));
    println!(
        "{}: {} steps, {} epochs{}, {ap}, {:.0} s training → {}",
        s.name,
        s.steps,
        s.epochs,
        if s.finished { "" } else { " (stopped early; --resume continues)" },
        s.train_seconds,
        run.root.display()
    );
    Ok(())
}

fn main() -> ExitCode {
    sparse_conv::heap::retain_freed_memory();
    let cli = Cli::parse();
    let r = match cli.cmd {
        None => run_train(cli.train),
        Some(Cmd::Infer { run, split, checkpoint, render, backend, data_root, set, out }) => (|| -> Result<()> {
            let dir = RunDir::at(&run);
            let b = backend.unwrap_or(dir.config()?.backend);
            pin(b);
            let split = match split {
                SplitArg::Train => Split::Train,
                SplitArg::Val => Split::Val,
                SplitArg::TrainVal => Split::TrainVal,
            };
            let checkpoint = checkpoint.map(|c| match c {
                SlotArg::Best => Slot::Best,
                SlotArg::Latest => Slot::Latest,
            });
            let out = train::infer(&dir, &InferOptions { split, checkpoint, render, backend, verbose: true, data_root, set, out })?;
            println!("{}", out.table);
            println!("{} frames; detections and scores in {}", out.frames, out.dir.display());
            Ok(())
        })(),
        Some(Cmd::Sweep { file, backend, max_steps, max_epochs, dry_run, rescore }) => (|| -> Result<()> {
            let (sweep, base) = SweepConfig::load(&file)?;
            let mut jobs = sweep.jobs(&base)?;
            if let Some(b) = backend {
                jobs.iter_mut().for_each(|j| j.config.backend = b);
            }
            let b = jobs.first().context("the sweep has no runs")?.config.backend;
            if jobs.iter().any(|j| j.config.backend != b) {
                bail!("all runs of a sweep use one backend");
            }
            pin(b);
            if dry_run {
                for j in &jobs {
                    println!("{} seed {} → {}", j.variant, j.seed, j.dir.display());
                }
                return Ok(());
            }
            if rescore {
                for j in &jobs {
                    eprintln!("rescoring {} seed {} ({})", j.variant, j.seed, j.dir.display());
                    match train::sweep::rescore(j, true)? {
                        None => eprintln!("  not finished, not rescored"),
                        Some(s) => {
                            if let Some(a) = s.last_ap3d {
                                eprintln!("  AP3D@0.3/0.5/0.7 {:.1}/{:.1}/{:.1}", 100.0 * a[0], 100.0 * a[1], 100.0 * a[2]);
                            }
                        }
                    }
                }
                let results = train::sweep::aggregate(&jobs);
                results.write(&sweep.dir())?;
                println!("{}", results.to_markdown());
                println!("results in {}", sweep.dir().display());
                return Ok(());
            }
            let results = train::run_sweep(
                &sweep,
                &jobs,
                |job| {
                    let existing = if job.dir.join("config.toml").exists() { Existing::Resume } else { Existing::Refuse };
                    job.config.backend.device()?;
                    let run = RunDir::create(&job.dir, &job.config, existing)?;
                    let opts = TrainOptions { resume: existing == Existing::Resume, max_steps, max_epochs, verbose: true };
                    train::train(&job.config, &run, &opts)
                },
                true,
            )?;
            println!("{}", results.to_markdown());
            println!("results in {}", sweep.dir().display());
            Ok(())
        })(),
    };
    match r {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}
