//! The training loop: seeded data order and augmentation, forward, loss terms, backward, Adam
//! (AMSGrad) with the lr set every iteration from the fractional epoch, validation every
//! `train.val_every` epochs, best and latest checkpoints, CSV rows as it goes, plots per epoch.
//!
//! Resume: the loop state (`checkpoint::TrainState`) holds the step, the epoch and the batch inside
//! it; the data order and each frame's augmentation are functions of (seed, epoch, frame), so
//! restoring weights, Adam's moments and that position continues the run exactly, and the CSV rows
//! written after the checkpoint are dropped and written again.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context, Result, bail};
use burn::grad_clipping::GradientClippingConfig;
use burn::module::Module;
use burn::optim::decay::WeightDecayConfig;
use burn::optim::{GradientsParams, ModuleOptimizer};
use burn::tensor::Device;
use indicatif::ProgressBar;
use data_jrdb::{Batch, Loader};
use model::person_minkunet::PersonMinkUNet;
use model::{Detector, LossTerms, ModelConfig};
use serde::{Deserialize, Serialize};
use sparse_conv::FusedAdamConfig;

use crate::backend::init_threads;
use crate::checkpoint::{CheckpointFiles, Checkpoints, Slot, TrainState, load_model_file};
use crate::config::{OptimizerConfig, RunConfig};
use crate::data::{ensure_training_data, eval_loader, train_loader};
use crate::metrics::{CsvLog, epoch_header, field, step_header, truncate_after};
use crate::run_dir::{RunDir, write_atomic};
use crate::validate::{HeadingError, format_by_range, validate};
use crate::{plots, progress};

/// Overrides of one invocation (not part of the config: they do not change what the run is).
#[derive(Debug, Clone, Default)]
pub struct TrainOptions {
    /// Continue from the run folder's latest checkpoint.
    pub resume: bool,
    /// Stop after this many steps in total (a later `--resume` goes on).
    pub max_steps: Option<u64>,
    /// Stop after this many epochs in total (the schedule still spans `train.epochs`).
    pub max_epochs: Option<usize>,
    /// Draw progress bars (on a terminal) and print a line per epoch.
    pub verbose: bool,
    /// Set (by a signal handler) to stop after the current step with a checkpoint, as
    /// `--max-steps` stops; a later `--resume` goes on as if nothing had happened.
    pub stop: Option<std::sync::Arc<std::sync::atomic::AtomicBool>>,
}

/// What a training invocation did; also written to `summary.json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TrainSummary {
    /// Run name.
    pub name: String,
    /// Model kind.
    pub model: String,
    /// Trainable parameters.
    pub params: usize,
    /// Steps done in total.
    pub steps: u64,
    /// Epochs finished in total.
    pub epochs: usize,
    /// Whether all `train.epochs` are done.
    pub finished: bool,
    /// The latest validation's AP3D at 0.3/0.5/0.7 and its epoch (1-based).
    pub last_ap3d: Option<[f64; 3]>,
    /// Epoch of `last_ap3d`.
    pub last_epoch: Option<usize>,
    /// Best AP3D@0.3 and its epoch.
    pub best_ap3d_03: Option<(f64, usize)>,
    /// Cumulative training time, seconds (validation excluded).
    pub train_seconds: f64,
    /// AP3D at 0.3/0.5/0.7 per range band (`validate::RANGE_BANDS`) of this invocation's last
    /// validation.
    #[serde(default)]
    pub last_ap3d_by_range: Option<[[f64; 3]; 3]>,
    /// Heading error of the same validation.
    #[serde(default)]
    pub last_heading: Option<HeadingError>,
}

/// Builds Adam from the config: [`FusedAdamConfig`], Burn's Adam in one pass per parameter.
pub fn optimizer(cfg: &OptimizerConfig) -> ModuleOptimizer {
    let mut adam = FusedAdamConfig::new().with_beta_1(cfg.beta_1).with_beta_2(cfg.beta_2).with_epsilon(cfg.epsilon).with_amsgrad(cfg.amsgrad);
    if cfg.weight_decay > 0.0 {
        adam = adam.with_weight_decay(Some(WeightDecayConfig { penalty: cfg.weight_decay }));
    }
    if let Some(n) = cfg.grad_clip_norm {
        adam = adam.with_grad_clipping(Some(GradientClippingConfig::Norm(n)));
    }
    adam.init()
}

/// Trains the run's model (dispatching once on `model.kind`) in `run`.
pub fn train(cfg: &RunConfig, run: &RunDir, opts: &TrainOptions) -> Result<TrainSummary> {
    init_threads(cfg.threads)?;
    cfg.kernels.apply();
    let device = match cfg.train.devices.first() {
        Some(&first) => cfg.backend.device_at(first)?,
        None => cfg.backend.device()?,
    };
    // The same seed gives the same initial weights.
    device.seed(cfg.seed);
    let ad = device.clone().autodiff();
    match &cfg.model {
        ModelConfig::PersonMinkunet(c) => train_model(c.init(&ad), cfg, run, opts, &device),
        ModelConfig::Centerpoint(c) => train_model(c.init(&ad), cfg, run, opts, &device),
    }
}

fn term_names(terms: &LossTerms) -> Vec<String> {
    terms.terms.iter().map(|(n, _)| n.to_string()).collect()
}

/// Trains `model` (initialised on `device.autodiff()`) as `cfg` says, writing into `run`.
/// `device` is the plain device of the backend (with `train.devices`, the first of them);
/// validation runs there.
pub fn train_model<D: Detector>(model: D, cfg: &RunConfig, run: &RunDir, opts: &TrainOptions, device: &Device) -> Result<TrainSummary> {
    let ad = device.clone().autodiff();
    let mut session = Session::set_up(cfg, run, opts)?;
    // The other devices of `train.devices`, each with a replica of the model every step.
    session.replicas = cfg.train.devices.iter().skip(1).map(|&i| cfg.backend.device_at(i).map(|d| d.autodiff())).collect::<Result<_>>()?;
    let params = model.num_params();
    let (mut model, mut optim) = session.resume(model, optimizer(&cfg.train.optimizer))?;
    session.announce(params);
    'epochs: while session.state.epoch < session.stop_epochs {
        if session.steps_exhausted() {
            break;
        }
        let pb = session.epoch_bar();
        for batch in session.loader.epoch_from(session.state.epoch as u64, session.state.batch) {
            if session.steps_exhausted() {
                pb.finish_and_clear();
                break 'epochs;
            }
            model = session.step(model, &mut optim, &batch?, &ad, &pb)?;
        }
        pb.finish_and_clear();
        // The epoch's batches ran out early (only frames that were all skipped do that).
        if session.state.batch < session.n && session.steps_exhausted() {
            break;
        }
        session.end_epoch(&model, &optim, device)?;
    }
    session.finish(&model, &optim, params)
}

/// A training invocation's state apart from the model and its optimiser: the data, the position
/// in the schedule, the CSV logs and the checkpoints. The loop above calls its parts in order:
/// set-up and resume, one step per batch, the end of each epoch, the end of the run.
struct Session<'a> {
    cfg: &'a RunConfig,
    run: &'a RunDir,
    opts: &'a TrainOptions,
    name: String,
    loader: Loader,
    val_loader: Loader,
    /// Batches per epoch.
    n: usize,
    /// `train.epochs`: what the schedule spans.
    epochs: usize,
    /// Where this invocation stops (`--max-epochs`).
    stop_epochs: usize,
    ckpts: Checkpoints,
    state: TrainState,
    step_log: Option<CsvLog>,
    epoch_log: Option<CsvLog>,
    /// The step of the last checkpoint written.
    saved_step: u64,
    last_by_range: Option<[[f64; 3]; 3]>,
    last_heading: Option<HeadingError>,
    /// The autodiff devices of `train.devices` after the first, one replica each per step.
    replicas: Vec<Device>,
}

impl<'a> Session<'a> {
    /// The data (generated on first use) and its loaders, a fresh position.
    fn set_up(cfg: &'a RunConfig, run: &'a RunDir, opts: &'a TrainOptions) -> Result<Self> {
        ensure_training_data(&cfg.data)?;
        let loader = train_loader(cfg)?;
        let val_loader = eval_loader(cfg, cfg.data.val_split)?;
        let n = loader.batches_per_epoch();
        if n == 0 {
            bail!("the training split has fewer frames ({}) than one batch ({}) with drop_last", loader.dataset().len(), cfg.train.batch_size);
        }
        let epochs = cfg.train.epochs;
        Ok(Session {
            cfg,
            run,
            opts,
            name: cfg.name.clone().unwrap_or_else(|| "run".into()),
            loader,
            val_loader,
            n,
            epochs,
            stop_epochs: opts.max_epochs.map_or(epochs, |m| m.min(epochs)),
            ckpts: Checkpoints::new(run.checkpoints()),
            state: TrainState { seed: cfg.seed, ..Default::default() },
            step_log: None,
            epoch_log: None,
            saved_step: 0,
            last_by_range: None,
            last_heading: None,
            replicas: Vec::new(),
        })
    }

    /// With `--resume`, the latest checkpoint's weights, optimiser state and position, and the
    /// CSV rows written after it dropped; a run at step 0 starts from `train.init`'s weights if
    /// set, otherwise from what it was given.
    fn resume<D: Detector>(&mut self, mut model: D, mut optim: ModuleOptimizer) -> Result<(D, ModuleOptimizer)> {
        if self.opts.resume {
            match self.ckpts.get(Slot::Latest)? {
                Some(files) => {
                    self.state = files.read_state()?;
                    if self.state.seed != self.cfg.seed {
                        bail!("checkpoint seed {} differs from the config's {}", self.state.seed, self.cfg.seed);
                    }
                    model = files.load_model(model)?;
                    optim = files.load_optim(optim)?;
                    if self.opts.verbose {
                        let s = &self.state;
                        eprintln!("resuming {} at step {} (epoch {}, batch {}/{})", self.run.root.display(), s.step, s.epoch + 1, s.batch, self.n);
                    }
                }
                None => {
                    if self.opts.verbose {
                        eprintln!("no checkpoint in {} yet: starting from step 0", self.run.root.display());
                    }
                }
            }
            truncate_after(&self.run.metrics_csv(), "step", self.state.step as f64)?;
            truncate_after(&self.run.epochs_csv(), "epoch", self.state.epoch as f64)?;
        }
        if self.state.step == 0 {
            model = self.init(model)?;
        }
        self.saved_step = self.state.step;
        Ok((model, optim))
    }

    /// At step 0, `train.init`'s weights (its latest checkpoint); a shape that differs from this
    /// model's is an error naming the tensor, as Burn's record validation reports it.
    fn init<D: Detector>(&self, model: D) -> Result<D> {
        let Some(dir) = &self.cfg.train.init else { return Ok(model) };
        let checkpoints = RunDir::at(dir).checkpoints();
        let files = Checkpoints::new(&checkpoints)
            .get(Slot::Latest)
            .with_context(|| format!("train.init = {}", dir.display()))?
            .with_context(|| format!("train.init = {}: no checkpoint there (expected {})", dir.display(), checkpoints.join("latest").display()))?;
        let weights = self.init_for_input(dir, &files)?.unwrap_or_else(|| files.model());
        let model = load_model_file(model, &weights).with_context(|| format!("train.init = {}: its weights do not fit this run's [model]", dir.display()))?;
        if self.opts.verbose {
            eprintln!("starting from the weights of {}", files.model().display());
        }
        Ok(model)
    }

    /// When `train.init`'s Person-MinkUNet was fed another input than this run's, its weights
    /// carried over to this run's input ([`PersonMinkUNet::with_input`]), written to the run's
    /// `init-carried.bpk` (kept: Burn reads a loaded file's tensors lazily, and it says what the
    /// run started from); `None` when the weights load as they are.
    fn init_for_input(&self, dir: &Path, files: &CheckpointFiles) -> Result<Option<PathBuf>> {
        let ModelConfig::PersonMinkunet(ours) = &self.cfg.model else { return Ok(None) };
        let theirs = RunDir::at(dir).config().with_context(|| format!("train.init = {}", dir.display()))?;
        let ModelConfig::PersonMinkunet(theirs) = &theirs.model else { return Ok(None) };
        if theirs.input == ours.input {
            return Ok(None);
        }
        let device = self.cfg.backend.device()?;
        let trained = files.load_model(PersonMinkUNet::new(theirs, &device)).with_context(|| format!("train.init = {}", dir.display()))?;
        let path = self.run.root.join("init-carried.bpk");
        trained.with_input(ours.input).save_file(&path).map_err(|e| anyhow::anyhow!("writing {}: {e:?}", path.display()))?;
        if self.opts.verbose {
            eprintln!("train.init = {}: input {:?} carried over to {:?} (the channels both hold; zero for the others)", dir.display(), theirs.input, ours.input);
        }
        Ok(Some(path))
    }

    fn announce(&self, params: usize) {
        if self.opts.verbose {
            let cfg = self.cfg;
            eprintln!(
                "{}: {} ({} parameters), {} train frames / {} val frames, {} steps per epoch, backend {:?}",
                self.name,
                cfg.model.kind(),
                params,
                self.loader.dataset().len(),
                self.val_loader.dataset().len(),
                self.n,
                cfg.backend
            );
        }
    }

    /// Whether `--max-steps` is reached or a stop was asked for.
    fn steps_exhausted(&self) -> bool {
        self.opts.max_steps.is_some_and(|m| self.state.step >= m) || self.opts.stop.as_ref().is_some_and(|s| s.load(std::sync::atomic::Ordering::Relaxed))
    }

    fn epoch_bar(&self) -> ProgressBar {
        let pb = if self.opts.verbose { progress::bar(self.n as u64, &format!("epoch {}/{}", self.state.epoch + 1, self.epochs)) } else { ProgressBar::hidden() };
        pb.set_position(self.state.batch as u64);
        pb.reset_eta();
        pb
    }

    /// One optimisation step on `batch`: the loss and its terms (refusing non-finite ones before
    /// anything is written), backward, Adam at the scheduled rate, the step's CSV row, and the
    /// mid-epoch checkpoint when `train.checkpoint_every` says so.
    fn step<D: Detector>(&mut self, model: D, optim: &mut ModuleOptimizer, batch: &Batch, ad: &Device, pb: &ProgressBar) -> Result<D> {
        let (n, state) = (self.n, &mut self.state);
        let t0 = Instant::now();
        let e = state.epoch as f64 + state.batch as f64 / n as f64;
        let lr = self.cfg.train.schedule.lr(e, self.epochs);
        // One part of the batch per device (one part, the batch itself, on one device), each
        // part's loss by the model or its replica there.
        let split;
        let parts: Vec<&Batch> = if self.replicas.is_empty() {
            vec![batch]
        } else {
            split = batch.split(1 + self.replicas.len());
            split.iter().collect()
        };
        let devices = std::iter::once(ad).chain(&self.replicas);
        let replicas: Vec<(D, LossTerms)> = parts
            .iter()
            .zip(devices)
            .enumerate()
            .map(|(i, (part, device))| {
                let replica = if i == 0 { model.clone() } else { model.clone().fork(device) };
                let terms = replica.loss(part, device);
                (replica, terms)
            })
            .collect();
        let names = term_names(&replicas[0].1);
        // The parts' mean (the batch's own on one device).
        let mean = |value: &dyn Fn(&LossTerms) -> f64| replicas.iter().map(|(_, t)| value(t)).sum::<f64>() / replicas.len() as f64;
        let loss = mean(&|t| t.total.clone().into_scalar::<f32>() as f64);
        let values: Vec<f64> = (0..names.len()).map(|k| mean(&|t| t.terms[k].1.clone().into_scalar::<f32>() as f64)).collect();
        if !loss.is_finite() || values.iter().any(|v| !v.is_finite()) {
            pb.finish_and_clear();
            let parts: Vec<String> = names.iter().zip(&values).map(|(n, v)| format!("{n} {v}")).collect();
            bail!(
                "non-finite loss at step {} (epoch {}, batch {}/{n}): loss {loss} ({}); stopped without writing a checkpoint, the last good one is kept in {}",
                state.step + 1,
                state.epoch + 1,
                state.batch + 1,
                parts.join(", "),
                self.run.checkpoints().display()
            );
        }
        let mut grads: Vec<GradientsParams> = replicas.into_iter().map(|(replica, terms)| GradientsParams::from_grads(terms.total.backward(), &replica)).collect();
        let grads = if grads.len() == 1 { grads.remove(0) } else { crate::data_parallel::average_gradients(grads, &model, ad) };
        let model = optim.step(lr, model, grads);
        let secs = t0.elapsed().as_secs_f64();
        state.step += 1;
        state.batch += 1;
        state.time += secs;
        state.epoch_seconds += secs;
        accumulate(&mut state.epoch_sums, "loss", loss);
        for (nm, v) in names.iter().zip(&values) {
            accumulate(&mut state.epoch_sums, nm, *v);
        }
        let log = match &mut self.step_log {
            Some(l) => l,
            None => self.step_log.insert(CsvLog::open(&self.run.metrics_csv(), &step_header(&names))?),
        };
        let mut row = vec![state.step.to_string(), field(Some(e)), field(Some(lr)), field(Some(loss))];
        row.extend(values.iter().map(|v| field(Some(*v))));
        row.extend([field(Some(secs)), field(Some(state.time))]);
        log.append(&row)?;
        if self.epoch_log.is_none() {
            self.epoch_log = Some(CsvLog::open(&self.run.epochs_csv(), &epoch_header(&names))?);
        }
        pb.set_message(format!("loss {loss:.4} lr {lr:.2e}"));
        pb.inc(1);
        let every = self.cfg.train.checkpoint_every;
        if every > 0 && self.state.step % every == 0 && self.state.batch < n {
            self.ckpts.save(&model, optim, &self.state, &[Slot::Latest])?;
            self.saved_step = self.state.step;
        }
        Ok(model)
    }

    /// The end of an epoch: validation when due, the epoch's CSV row and line, the latest (and,
    /// on a better AP3D@0.3, the best) checkpoint, the plots.
    fn end_epoch<D: Detector>(&mut self, model: &D, optim: &ModuleOptimizer, device: &Device) -> Result<()> {
        let (cfg, epochs) = (self.cfg, self.epochs);
        let done = self.state.epoch + 1;
        let due = (cfg.train.val_every > 0 && done.is_multiple_of(cfg.train.val_every)) || done == epochs || done == self.stop_epochs;
        let val = if due { Some(validate(&model.valid(), &self.val_loader, device, &cfg.eval.protocol(), self.opts.verbose)?) } else { None };
        let state = &self.state;
        let steps_in_epoch = state.batch.max(1) as f64;
        let mean = |k: &str| state.epoch_sums.iter().find(|(n, _)| n == k).map(|(_, s)| s / steps_in_epoch);
        let names: Vec<String> = state.epoch_sums.iter().map(|(n, _)| n.clone()).filter(|n| n != "loss").collect();
        let lr_end = cfg.train.schedule.lr(done as f64, epochs);
        let mut row = vec![done.to_string(), state.step.to_string(), field(Some(lr_end)), field(mean("loss"))];
        row.extend(names.iter().map(|n| field(mean(n))));
        let ap = val.as_ref().map(|v| v.ap3d);
        row.extend((0..3).map(|i| field(ap.map(|a| a[i]))));
        row.extend([field(Some(state.epoch_seconds)), field(val.as_ref().map(|v| v.seconds)), field(Some(state.time))]);
        let elog = match &mut self.epoch_log {
            Some(l) => l,
            None => self.epoch_log.insert(CsvLog::open(&self.run.epochs_csv(), &epoch_header(&names))?),
        };
        elog.append(&row)?;
        if self.opts.verbose {
            let parts: Vec<String> = names.iter().map(|n| format!("{n} {:.4}", mean(n).unwrap_or(f64::NAN))).collect();
            let ap_text = ap.map_or_else(String::new, |a| format!("  AP3D@0.3/0.5/0.7 {:.1}/{:.1}/{:.1}", 100.0 * a[0], 100.0 * a[1], 100.0 * a[2]));
            eprintln!("epoch {done}/{epochs}  loss {:.4} ({})  lr {lr_end:.2e}{ap_text}  {:.0} s", mean("loss").unwrap_or(f64::NAN), parts.join(", "), state.epoch_seconds);
            if let Some(v) = &val {
                let heading = v.heading.map_or_else(|| "no matched box".to_string(), |h| h.to_string());
                eprintln!("  AP3D by range {}; {heading}", format_by_range(&v.ap3d_by_range));
            }
        }
        if let Some(v) = &val {
            self.last_by_range = Some(v.ap3d_by_range);
            self.last_heading = v.heading;
        }
        let state = &mut self.state;
        state.epoch = done;
        state.batch = 0;
        state.epoch_sums.clear();
        state.epoch_seconds = 0.0;
        let mut slots = vec![Slot::Latest];
        if let Some(a) = ap {
            state.last_val = Some((a, done));
            if state.best.is_none_or(|(b, _)| a[0] > b) {
                state.best = Some((a[0], done));
                slots.push(Slot::Best);
            }
        }
        self.ckpts.save(model, optim, &self.state, &slots)?;
        self.saved_step = self.state.step;
        if let Err(e) = plots::plot_run(self.run) {
            eprintln!("warning: plots not drawn: {e:#}");
        }
        Ok(())
    }

    /// The end of the invocation: a last checkpoint if steps were taken since one, and
    /// `summary.json`.
    fn finish<D: Detector>(self, model: &D, optim: &ModuleOptimizer, params: usize) -> Result<TrainSummary> {
        let state = &self.state;
        if state.step != self.saved_step || self.ckpts.get(Slot::Latest)?.is_none() {
            self.ckpts.save(model, optim, state, &[Slot::Latest])?;
        }
        let summary = TrainSummary {
            name: self.name.clone(),
            model: self.cfg.model.kind().to_string(),
            params,
            steps: state.step,
            epochs: state.epoch,
            finished: state.epoch >= self.epochs,
            last_ap3d: state.last_val.map(|(a, _)| a),
            last_epoch: state.last_val.map(|(_, e)| e),
            best_ap3d_03: state.best,
            train_seconds: state.time,
            last_ap3d_by_range: self.last_by_range,
            last_heading: self.last_heading,
        };
        write_atomic(&self.run.summary_json(), serde_json::to_string_pretty(&summary)?.as_bytes()).context("writing summary.json")?;
        Ok(summary)
    }
}

fn accumulate(sums: &mut Vec<(String, f64)>, key: &str, v: f64) {
    match sums.iter_mut().find(|(k, _)| k == key) {
        Some((_, s)) => *s += v,
        None => sums.push((key.to_string(), v)),
    }
}
