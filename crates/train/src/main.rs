//! `train`: the pmunet experiment runner.
//!
//! ```text
//! cargo run -p train -- --config experiments/quickstart.toml          # train + validate
//! cargo run -p train -- --config X.toml --resume                        # continue a run
//! cargo run -p train -- infer --run runs/quickstart --split val --render 4
//! cargo run -p train -- sweep experiments/sweeps/compare.toml
//! cargo run -p train -- detect scans/ --out detections --render      # your own clouds
//! cargo run -p train -- serve --addr 127.0.0.1:8080                   # the same over HTTP
//! ```

use std::path::{Path, PathBuf};
use std::process::ExitCode;

use anyhow::{Context, Result, bail};
use clap::{Args, Parser, Subcommand};
use data_jrdb::Split;
use model::FacingFeatures;
use train::{BackendKind, CalibrateOptions, DetectOptions, Existing, FacingOptions, FitBoxes, InferOptions, RunConfig, RunDetector, RunDir, FrameSpec, ServeOptions, Slot, SweepConfig, TrainOptions};

/// The weights `detect` and `serve` use unless told otherwise (relative to the working directory,
/// which is the repository's root under `cargo run`).
const SHIPPED_WEIGHTS: &str = "weights/person_minkunet";

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

impl From<SplitArg> for Split {
    fn from(s: SplitArg) -> Split {
        match s {
            SplitArg::Train => Split::Train,
            SplitArg::Val => Split::Val,
            SplitArg::TrainVal => Split::TrainVal,
        }
    }
}

impl From<SlotArg> for Slot {
    fn from(s: SlotArg) -> Slot {
        match s {
            SlotArg::Best => Slot::Best,
            SlotArg::Latest => Slot::Latest,
        }
    }
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
        /// Run on this dataset (e.g. a simulated benchmark generated with another seed, or a
        /// KITTI or nuScenes root with --data-format) instead of the run's own data.
        #[arg(long, value_name = "DIR")]
        data_root: Option<PathBuf>,
        /// The layout of --data-root when not the run's (`kitti`, `nuscenes`, `jrdb`).
        #[arg(long, value_enum, requires = "data_root")]
        data_format: Option<data_jrdb::DatasetFormat>,
        /// Override a key of the run's config for this inference, e.g.
        /// `--set model.post.merge_radius=0.4` (repeatable; the run's config.toml is unchanged).
        #[arg(long = "set", value_name = "KEY=VALUE")]
        set: Vec<String>,
        /// Write the detections and scores here instead of RUN/detections/SPLIT.
        #[arg(long, value_name = "DIR")]
        out: Option<PathBuf>,
    },
    /// Measure how far a run's boxes fall short of people along the sensor's ray (median over
    /// matched people, on frames the run is not scored on) and, with --write, store the
    /// correcting `model.post.radial_shift` in the run's config.toml.
    Calibrate {
        #[command(flatten)]
        on: NotScored,
        /// Store the shift in RUN/config.toml (default: only print it).
        #[arg(long)]
        write: bool,
    },
    /// Fit the checkpoint's facing stage (which way each box's person faces, read from the
    /// points in it) on the run's own boxes over the training split, report the direction before
    /// and after it on the validation split and, with --write, store it beside the checkpoint
    /// (CHECKPOINT/facing.json), where infer, detect and serve apply it.
    Facing {
        #[command(flatten)]
        on: NotScored,
        /// Split to report the direction on (default: val).
        #[arg(long, value_enum, default_value = "val")]
        score_on: SplitArg,
        /// Learn from the run's matched detections (the boxes it is applied to) or the labels.
        #[arg(long, value_enum, default_value = "detections")]
        boxes: FitBoxes,
        /// Cell size (m) of the 3D occupancy histogram, 0.15 to 0.6.
        #[arg(long, default_value_t = FacingFeatures::default().cell)]
        cell: f64,
        /// Cell size (m) of the three 2D projections read beside it, 0.08 to 0.6; 0: none.
        #[arg(long, default_value_t = FacingFeatures::default().profile_cell.unwrap_or(0.0))]
        profile_cell: f64,
        /// Read the points only, not the detector's own direction.
        #[arg(long)]
        no_detector_direction: bool,
        /// Leave out each slice's mean and spread of the points along x and y.
        #[arg(long)]
        no_slice_moments: bool,
        /// Ridge weight on the standardised features (positive).
        #[arg(long, default_value_t = FacingOptions::default().l2)]
        l2: f64,
        /// Store the stage beside the checkpoint (default: only report).
        #[arg(long)]
        write: bool,
    },
    /// Detect people in point-cloud files (PCD, KITTI .bin, nuScenes .pcd.bin, .npy), folders of them, glob patterns,
    /// JRDB-format trees or recordings (.mcap, .db3, .bag or a ROS 2 bag folder, with --topic); write OUT/json/NAME.json,
    /// OUT/kitti/NAME.txt and with --render OUT/render/NAME.png per frame (a recording's frames
    /// are NAME/INDEX, and OUT/NAME.jsonl holds a line per message with its stamp).
    Detect {
        /// Files, folders (searched recursively), quoted glob patterns, JRDB-format trees.
        #[arg(required = true, value_name = "PATH")]
        paths: Vec<PathBuf>,
        #[command(flatten)]
        model: ModelArgs,
        /// Output folder.
        #[arg(long, value_name = "DIR", default_value = "detections")]
        out: PathBuf,
        /// Also draw each frame as a bird's-eye-view PNG (JRDB's base frame).
        #[arg(long)]
        render: bool,
        /// The topic of PointCloud2 messages in a recording (.mcap, .db3, .bag).
        #[arg(long)]
        topic: Option<String>,
        /// Only list each recording's topics (name, schema, encoding, messages).
        #[arg(long)]
        list_topics: bool,
        /// Also write the recordings' clouds and the people found (foxglove.SceneUpdate on
        /// /pmunet/people) to this MCAP, for Foxglove or Lichtblick.
        #[arg(long, value_name = "OUT.mcap")]
        mcap: Option<PathBuf>,
    },
    /// Serve the detector over HTTP: POST /detect with a point cloud, GET /health.
    Serve {
        #[command(flatten)]
        model: ModelArgs,
        /// Address to listen on (port 0: any free port, printed at start).
        #[arg(long, default_value = "127.0.0.1:8080")]
        addr: std::net::SocketAddr,
        /// Largest body accepted, in MiB (larger ones get 413).
        #[arg(long, default_value_t = 64.0)]
        max_body_mb: f64,
        /// Requests that may wait for the model at once (more wait for room).
        #[arg(long, default_value_t = 64)]
        queue: usize,
        /// Most points a cloud may hold (more get 413, refused from the header before decoding).
        #[arg(long, default_value_t = 2_000_000)]
        max_points: usize,
        /// Memory, in MiB, that the requests in flight may reserve together: each reserves 5 times
        /// its body until it is answered, and more wait for room. At least 5 x --max-body-mb.
        #[arg(long, default_value_t = 1024.0)]
        memory_budget_mb: f64,
        /// Longest a request may take, in seconds, from arrival to answer (an answer not ready
        /// by then: 503).
        #[arg(long, default_value_t = 60.0)]
        timeout_s: f64,
        /// Longest a client may take, in seconds, to send its body (a body not received by then:
        /// 408; a slow or stalled sender holds its reservation no longer).
        #[arg(long, default_value_t = 30.0)]
        read_timeout_s: f64,
    },
    /// Average the weights of runs fine-tuned from one set of weights (a "model soup") into a
    /// new run folder, to fit with `calibrate` and `facing` and use as any run: one network's
    /// cost, the ingredients' answers averaged.
    Soup {
        /// A run to average (repeatable; the same network shape, its latest checkpoint).
        #[arg(long = "run", value_name = "DIR", required = true)]
        runs: Vec<PathBuf>,
        /// The new run folder (must not exist).
        #[arg(long, value_name = "DIR")]
        out: PathBuf,
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
        /// Run (or with --rescore, rescore) only this variant's seeds (repeatable; default:
        /// every variant). The tables still list every finished run of the sweep.
        #[arg(long = "variant", value_name = "NAME")]
        variants: Vec<String>,
        /// Only print the runs the sweep would make.
        #[arg(long)]
        dry_run: bool,
        /// Score the finished runs again with the sweep's current [model.post] and [eval]
        /// settings (nothing is retrained; any other change is refused), then write the tables.
        #[arg(long)]
        rescore: bool,
        /// Run this many runs at once on this machine, each its own process with the cores
        /// split between them (threads per run = cores / N; the results are the same).
        #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u16).range(1..))]
        jobs: u16,
        /// Submit the runs to Slurm instead: one job array (a task per run, resuming its folder,
        /// checkpointing and requeueing itself before its time limit) and a job after it that
        /// writes the tables. With --dry-run, print the batch scripts and sbatch lines.
        #[command(flatten)]
        slurm: SlurmArgs,
        /// Each run's state (finished, pending, running, failed with its log's last line) from
        /// the run folders and Slurm's queue.
        #[arg(long, conflicts_with_all = ["rescore", "dry_run"])]
        status: bool,
        /// Only write the tables from the runs finished so far (what the Slurm tables job runs).
        #[arg(long, conflicts_with_all = ["rescore", "dry_run", "status"])]
        tables: bool,
    },
}

/// `train sweep --slurm` and the `sbatch` options of its tasks.
#[derive(Args)]
struct SlurmArgs {
    /// Submit to Slurm (see `sweep --help`).
    #[arg(long)]
    slurm: bool,
    /// sbatch --partition.
    #[arg(long, requires = "slurm")]
    partition: Option<String>,
    /// sbatch --time: each task's limit (it checkpoints and requeues 2 minutes before).
    #[arg(long, requires = "slurm")]
    time: Option<String>,
    /// sbatch --cpus-per-task, also each run's threads.
    #[arg(long, requires = "slurm")]
    cpus_per_task: Option<u32>,
    /// sbatch --gpus-per-task.
    #[arg(long, requires = "slurm")]
    gpus_per_task: Option<u32>,
    /// sbatch --mem.
    #[arg(long, requires = "slurm")]
    mem: Option<String>,
    /// Any other sbatch option, as written (repeatable): --sbatch-arg=--qos=long.
    #[arg(long = "sbatch-arg", value_name = "OPTION", requires = "slurm", allow_hyphen_values = true)]
    sbatch_args: Vec<String>,
}

/// A run's checkpoint on frames it is not scored on: what `calibrate` and `facing` measure on.
#[derive(Args)]
struct NotScored {
    /// The run folder.
    #[arg(long)]
    run: PathBuf,
    /// Split to work on (default: the training split; or another tree's, with --data-root).
    #[arg(long, value_enum, default_value = "train")]
    split: SplitArg,
    /// Checkpoint (default: latest).
    #[arg(long, value_enum)]
    checkpoint: Option<SlotArg>,
    /// Backend (overrides the run's).
    #[arg(long, value_enum)]
    backend: Option<BackendKind>,
    /// Work on this JRDB-format tree instead of the run's own data.
    #[arg(long, value_name = "DIR")]
    data_root: Option<PathBuf>,
}

/// The model and the frame of `detect` and `serve`.
#[derive(Args)]
struct ModelArgs {
    /// The run folder whose model detects (default: the shipped Person-MinkUNet).
    #[arg(long, value_name = "DIR", default_value = SHIPPED_WEIGHTS)]
    run: PathBuf,
    /// Checkpoint (default: latest).
    #[arg(long, value_enum)]
    checkpoint: Option<SlotArg>,
    /// Backend (overrides the run's).
    #[arg(long, value_enum)]
    backend: Option<BackendKind>,
    /// Keep boxes scoring at least this (0.5 is near the best F1 at IoU 0.3 on the benchmark's
    /// validation frames; 0 keeps every box the run's post-processing keeps, as `infer` scores).
    #[arg(long, default_value_t = 0.5)]
    score_threshold: f64,
    /// Where your sensor frame sits in JRDB's base frame (x forward, y left, z up, metres, the
    /// floor at z = -0.7). `auto` (the default) finds the height and tilt from the ground in each
    /// scan (`auto,yaw=-90` for a sensor whose y points forward); a scan without ground in view
    /// keeps the pose given beside `auto` (the identity: the base frame) and its report says so.
    /// A pose given whole skips the search: `z=0.5,yaw=90` maps a point p to R(yaw)·p + (x, y,
    /// z); keys x, y, z in metres, yaw (and roll, pitch) in degrees; `identity` for a cloud in
    /// the base frame already. Not applied to JRDB-format trees (their calibration is).
    #[arg(long, value_name = "auto|identity|x=…,y=…,z=…,yaw=…", default_value = "auto")]
    transform: FrameSpec,
    /// Override a key of the run's config for this invocation (repeatable; its config.toml is
    /// unchanged), e.g. `--set model.post.test_time_turns=4`: four turned passes fused, about a
    /// third of the speed and fewer false boxes on real scans (docs/detect.md).
    #[arg(long = "set", value_name = "KEY=VALUE")]
    set: Vec<String>,
}

impl ModelArgs {
    fn slot(&self) -> Slot {
        self.checkpoint.map_or(Slot::Latest, Slot::from)
    }

    /// Finds the shipped weights from any working directory (see [`shipped_weights`]), pins the
    /// backend and checks the threshold, before anything loads.
    fn prepare(mut self) -> Result<Self> {
        if self.run == Path::new(SHIPPED_WEIGHTS) && !self.run.join("config.toml").is_file() {
            self.run = shipped_weights()?;
        }
        self.check()?;
        Ok(self)
    }

    fn check(&self) -> Result<()> {
        anyhow::ensure!((0.0..=1.0).contains(&self.score_threshold), "--score-threshold {} must lie in [0, 1]", self.score_threshold);
        let b = match self.backend {
            Some(b) => b,
            None => RunDir::at(&self.run).config().with_context(|| format!("{} is not a run folder (--run DIR names one)", self.run.display()))?.backend,
        };
        pin(b);
        Ok(())
    }
}

/// The shipped weights when the working directory is not the repository's root: beside the
/// sources this binary was built from, or above the executable (`<repo>/target/debug/train`).
fn shipped_weights() -> Result<PathBuf> {
    let built_from = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..").join(SHIPPED_WEIGHTS);
    let exe = std::env::current_exe().ok();
    let above_exe = exe.iter().flat_map(|e| e.ancestors().skip(1)).map(|d| d.join(SHIPPED_WEIGHTS));
    let tried: Vec<PathBuf> = std::iter::once(PathBuf::from(SHIPPED_WEIGHTS)).chain(std::iter::once(built_from)).chain(above_exe).collect();
    match tried.iter().find(|d| d.join("config.toml").is_file()) {
        Some(d) => Ok(d.canonicalize().unwrap_or_else(|_| d.clone())),
        None => anyhow::bail!(
            "the shipped weights ({SHIPPED_WEIGHTS}) are not in the working directory, beside the sources this binary was built from, or above it; pass --run DIR (looked in {})",
            tried.iter().map(|d| d.display().to_string()).collect::<Vec<_>>().join(", ")
        ),
    }
}

/// Makes `backend` Burn's default device before any thread starts (optimizer state loads there).
fn pin(backend: BackendKind) {
    // SAFETY: called from `main` before this process starts any thread.
    unsafe { backend.pin_default_device() };
}

fn run_train(a: TrainArgs) -> Result<()> {
    let Some(path) = a.config else { bail!("--config FILE is required (or a subcommand: infer, calibrate, facing, sweep, detect, serve); see --help") };
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
    let stop = stop_on_signals()?;
    let opts = TrainOptions { resume: a.resume, max_steps: a.max_steps, max_epochs: a.max_epochs, verbose: !a.quiet, stop: Some(stop.clone()) };
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
    if stop.load(std::sync::atomic::Ordering::Relaxed) && !s.finished {
        eprintln!("stopped by a signal after step {} with a checkpoint; --resume continues", s.steps);
        std::process::exit(STOPPED_BY_SIGNAL);
    }
    Ok(())
}

/// The exit status of a run stopped by SIGTERM or SIGUSR1 with its checkpoint written
/// (`EX_TEMPFAIL`: try again; a Slurm task requeues itself on it).
const STOPPED_BY_SIGNAL: i32 = 75;

/// SIGTERM and SIGUSR1 (a scheduler's preemption, or its warning before a time limit) stop a
/// run after its current step with a checkpoint. A second one changes nothing (a scheduler may
/// signal both the batch shell, which passes it on, and the run); SIGINT still ends it at once.
fn stop_on_signals() -> Result<std::sync::Arc<std::sync::atomic::AtomicBool>> {
    let stop = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
    #[cfg(unix)]
    for sig in [signal_hook::consts::SIGTERM, signal_hook::consts::SIGUSR1] {
        signal_hook::flag::register(sig, stop.clone())?;
    }
    Ok(stop)
}

fn main() -> ExitCode {
    bench::heap::retain_freed_memory();
    let cli = Cli::parse();
    let r = match cli.cmd {
        None => run_train(cli.train),
        Some(Cmd::Infer { run, split, checkpoint, render, backend, data_root, data_format, set, out }) => (|| -> Result<()> {
            let dir = RunDir::at(&run);
            let b = backend.unwrap_or(dir.config()?.backend);
            pin(b);
            let (split, checkpoint) = (split.into(), checkpoint.map(Slot::from));
            let out = train::infer(&dir, &InferOptions { split, checkpoint, render, backend, verbose: true, data_root, data_format, set, out })?;
            println!("{}", out.table);
            println!("{} frames; detections and scores in {}", out.frames, out.dir.display());
            Ok(())
        })(),
        Some(Cmd::Facing { on: NotScored { run, split, checkpoint, backend, data_root }, score_on, boxes, cell, profile_cell, no_detector_direction, no_slice_moments, l2, write }) => (|| -> Result<()> {
            let dir = RunDir::at(&run);
            pin(backend.unwrap_or(dir.config()?.backend));
            anyhow::ensure!((0.15..=0.6).contains(&cell), "--cell {cell} must lie in [0.15, 0.6] m (finer grids have too many cells for the fit)");
            anyhow::ensure!(l2 > 0.0 && l2.is_finite(), "--l2 {l2} must be a positive number");
            let profile_cell = (profile_cell != 0.0).then_some(profile_cell);
            if let Some(c) = profile_cell {
                anyhow::ensure!((0.08..=0.6).contains(&c), "--profile-cell {c} must be 0 or lie in [0.08, 0.6] m");
            }
            let features = FacingFeatures { cell, profile_cell, detector_direction: !no_detector_direction, slice_moments: !no_slice_moments, ..Default::default() };
            let opts = FacingOptions {
                split: split.into(),
                score_on: Some(score_on.into()),
                checkpoint: checkpoint.map(Slot::from),
                backend,
                data_root,
                boxes,
                features,
                l2,
                write,
                verbose: true,
            };
            println!("{}", train::fit_facing(&dir, &opts)?);
            Ok(())
        })(),
        Some(Cmd::Soup { runs, out }) => (|| -> Result<()> {
            pin(RunDir::at(&runs[0]).config()?.backend);
            let report = train::soup(&runs, &out)?;
            print!("{report}");
            println!("written to {} (fit it: train calibrate --run {0} --write; train facing --run {0} --write)", out.display());
            Ok(())
        })(),
        Some(Cmd::Calibrate { on: NotScored { run, split, checkpoint, backend, data_root }, write }) => (|| -> Result<()> {
            let dir = RunDir::at(&run);
            pin(backend.unwrap_or(dir.config()?.backend));
            let (split, checkpoint) = (split.into(), checkpoint.map(Slot::from));
            let bias = train::calibrate(&dir, &CalibrateOptions { split, checkpoint, backend, data_root, write, verbose: true })?;
            println!("{bias}");
            if write {
                println!("written to {}", dir.config_file().display());
            }
            Ok(())
        })(),
        Some(Cmd::Detect { paths, model, out, render, topic, list_topics, mcap }) => (|| -> Result<()> {
            if list_topics {
                let mut files = Vec::new();
                for p in &paths {
                    let bag = train::recording::bag_folder_files(p)?;
                    if bag.is_empty() { files.push(p.clone()) } else { files.extend(bag) }
                }
                for p in &files {
                    for t in train::recording::Recording::open(p)?.topics()? {
                        println!("{}\t{}\t{}\t{}\t{}", p.display(), t.name, t.schema, t.encoding, t.messages.map_or_else(|| "?".into(), |n| n.to_string()));
                    }
                }
                return Ok(());
            }
            let model = model.prepare()?;
            let inputs = train::detect::collect_inputs(&paths)?;
            let detector = RunDetector::load_with(&model.run, &model.set, model.slot(), model.backend)?;
            let opts = DetectOptions { frame: model.transform, score_threshold: model.score_threshold, out: out.clone(), render, verbose: true, topic, mcap };
            let s = train::detect::detect(&detector, &inputs, &opts)?;
            println!(
                "{} frames, {} people scoring ≥ {} in {:.1} s: {:.2} frames/s ({:.2} frames/s in the detector alone); outputs in {}",
                s.frames,
                s.boxes,
                model.score_threshold,
                s.seconds,
                s.frames as f64 / s.seconds.max(1e-9),
                s.frames as f64 / s.detect_seconds.max(1e-9),
                out.display()
            );
            if !s.failed.is_empty() {
                bail!("{} of {} inputs could not be read or written (listed above); the others' outputs are written", s.failed.len(), inputs.len());
            }
            Ok(())
        })(),
        Some(Cmd::Serve { model, addr, max_body_mb, queue, max_points, memory_budget_mb, timeout_s, read_timeout_s }) => (|| -> Result<()> {
            let model = model.prepare()?;
            anyhow::ensure!(max_body_mb > 0.0 && max_body_mb.is_finite(), "--max-body-mb must be positive");
            anyhow::ensure!(max_points > 0, "--max-points must be at least 1");
            let per_body = train::serve::RESERVE_PER_BODY_BYTE as f64;
            anyhow::ensure!(
                memory_budget_mb.is_finite() && memory_budget_mb >= per_body * max_body_mb,
                "--memory-budget-mb ({memory_budget_mb}) must hold at least one largest request: {per_body} x --max-body-mb = {}",
                per_body * max_body_mb
            );
            for (name, s) in [("--timeout-s", timeout_s), ("--read-timeout-s", read_timeout_s)] {
                anyhow::ensure!(s > 0.0 && s <= 86_400.0, "{name} must lie in (0, 86400]");
            }
            let opts = ServeOptions {
                run: model.run.clone(),
                overrides: model.set.clone(),
                checkpoint: model.slot(),
                backend: model.backend,
                addr,
                max_body_bytes: (max_body_mb * 1024.0 * 1024.0) as usize,
                score_threshold: model.score_threshold,
                frame: model.transform,
                queue,
                max_points,
                memory_budget_bytes: (memory_budget_mb * 1024.0 * 1024.0) as usize,
                timeout: std::time::Duration::from_secs_f64(timeout_s),
                read_timeout: std::time::Duration::from_secs_f64(read_timeout_s),
            };
            train::serve::serve(&opts)
        })(),
        Some(Cmd::Sweep { file, backend, max_steps, max_epochs, variants, dry_run, rescore, jobs: parallel, slurm, status, tables }) => (|| -> Result<()> {
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
            let mut executor = train::sweep::Slurm {
                sweep_file: file.clone(),
                sweep_dir: sweep.dir(),
                name: sweep.name.clone().unwrap_or_default(),
                partition: slurm.partition,
                time: slurm.time,
                cpus_per_task: slurm.cpus_per_task,
                gpus_per_task: slurm.gpus_per_task,
                mem: slurm.mem,
                sbatch_args: slurm.sbatch_args,
                max_steps,
                max_epochs,
                dry_run,
            };
            if status {
                for (j, s) in jobs.iter().zip(executor.status(&jobs)?) {
                    println!("{} seed {}: {s} ({})", j.variant, j.seed, j.dir.display());
                }
                return Ok(());
            }
            if tables {
                let results = train::sweep::aggregate(&jobs);
                results.write(&sweep.dir())?;
                println!("{}", results.to_markdown());
                println!("results in {}", sweep.dir().display());
                return Ok(());
            }
            if slurm.slurm && dry_run {
                train::sweep::check_variants(&jobs, &variants)?;
                let todo: Vec<&train::sweep::Job> = jobs.iter().filter(|j| (variants.is_empty() || variants.contains(&j.variant)) && train::sweep::finished(&j.dir).is_none()).collect();
                use train::sweep::Executor;
                executor.execute(&todo, &mut || Ok(()), true)?;
                return Ok(());
            }
            if slurm.slurm {
                train::sweep::run_sweep_with(&sweep, &jobs, &variants, &mut executor, true)?;
                return Ok(());
            }
            if dry_run {
                train::sweep::plan(&jobs, &variants)?.iter().for_each(|line| println!("{line}"));
                return Ok(());
            }
            let results = if rescore {
                train::sweep::rescore_all(&sweep, &jobs, &variants)?
            } else if parallel > 1 {
                let mut executor = train::sweep::Processes { jobs: parallel as usize, max_steps, max_epochs };
                train::sweep::run_sweep_with(&sweep, &jobs, &variants, &mut executor, true)?
            } else {
                train::sweep::run_sweep_with(&sweep, &jobs, &variants, &mut train::sweep::training(max_steps, max_epochs), true)?
            };
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
