//! The training loop: seeded data order and augmentation, forward, loss terms, backward, Adam
//! (AMSGrad) with the lr set every iteration from the fractional epoch, validation every
//! `train.val_every` epochs, best and latest checkpoints, CSV rows as it goes, plots per epoch.
//!
//! Resume: the loop state (`checkpoint::TrainState`) holds the step, the epoch and the batch inside
//! it; the data order and each frame's augmentation are functions of (seed, epoch, frame), so
//! restoring weights, Adam's moments and that position continues the run exactly, and the CSV rows
//! written after the checkpoint are dropped and written again.

use std::time::Instant;

use anyhow::{Context, Result, bail};
use burn::grad_clipping::GradientClippingConfig;
use burn::optim::decay::WeightDecayConfig;
use burn::optim::{GradientsParams, ModuleOptimizer};
use burn::tensor::Device;
use indicatif::ProgressBar;
use model::{Detector, LossTerms, ModelConfig};
use serde::{Deserialize, Serialize};
use sparse_conv::FusedAdamConfig;

use crate::backend::init_threads;
use crate::checkpoint::{Checkpoints, Slot, TrainState};
use crate::config::{OptimizerConfig, RunConfig};
use crate::data::{ensure_dataset, eval_loader, train_loader};
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
    let device = cfg.backend.device();
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
/// `device` is the plain device of the backend; validation runs there.
pub fn train_model<D: Detector>(mut model: D, cfg: &RunConfig, run: &RunDir, opts: &TrainOptions, device: &Device) -> Result<TrainSummary> {
    let ad = device.clone().autodiff();
    let name = cfg.name.clone().unwrap_or_else(|| "run".into());
    ensure_dataset(&cfg.data)?;
    let loader = train_loader(cfg)?;
    let val_loader = eval_loader(cfg, cfg.data.val_split)?;
    let n = loader.batches_per_epoch();
    if n == 0 {
        bail!("the training split has fewer frames ({}) than one batch ({}) with drop_last", loader.dataset().len(), cfg.train.batch_size);
    }
    let params = model.num_params();
    let mut optim = optimizer(&cfg.train.optimizer);
    let ckpts = Checkpoints::new(run.checkpoints());
    let mut state = TrainState { seed: cfg.seed, ..Default::default() };
    if opts.resume {
        match ckpts.get(Slot::Latest)? {
            Some(files) => {
                state = files.read_state()?;
                if state.seed != cfg.seed {
                    bail!("checkpoint seed {} differs from the config's {}", state.seed, cfg.seed);
                }
                model = files.load_model(model)?;
                optim = files.load_optim(optim)?;
                if opts.verbose {
                    eprintln!("resuming {} at step {} (epoch {}, batch {}/{n})", run.root.display(), state.step, state.epoch + 1, state.batch);
                }
            }
            None => {
                if opts.verbose {
                    eprintln!("no checkpoint in {} yet: starting from step 0", run.root.display());
                }
            }
        }
        truncate_after(&run.metrics_csv(), "step", state.step as f64)?;
        truncate_after(&run.epochs_csv(), "epoch", state.epoch as f64)?;
    }
    let epochs = cfg.train.epochs;
    let stop_epochs = opts.max_epochs.map_or(epochs, |m| m.min(epochs));
    let mut step_log: Option<CsvLog> = None;
    let mut epoch_log: Option<CsvLog> = None;
    let mut saved_step = state.step;
    let (mut last_by_range, mut last_heading) = (None, None);
    if opts.verbose {
        eprintln!("{name}: {} ({} parameters), {} train frames / {} val frames, {n} steps per epoch, backend {:?}", cfg.model.kind(), params, loader.dataset().len(), val_loader.dataset().len(), cfg.backend);
    }
    'epochs: while state.epoch < stop_epochs {
        if opts.max_steps.is_some_and(|m| state.step >= m) {
            break;
        }
        let pb = if opts.verbose { progress::bar(n as u64, &format!("epoch {}/{epochs}", state.epoch + 1)) } else { ProgressBar::hidden() };
        pb.set_position(state.batch as u64);
        pb.reset_eta();
        for batch in loader.epoch_from(state.epoch as u64, state.batch) {
            if opts.max_steps.is_some_and(|m| state.step >= m) {
                pb.finish_and_clear();
                break 'epochs;
            }
            let batch = batch?;
            let t0 = Instant::now();
            let e = state.epoch as f64 + state.batch as f64 / n as f64;
            let lr = cfg.train.schedule.lr(e, epochs);
            let terms = model.loss(&batch, &ad);
            let names = term_names(&terms);
            let loss = terms.total.clone().into_scalar::<f32>() as f64;
            let values: Vec<f64> = terms.terms.iter().map(|(_, t)| t.clone().into_scalar::<f32>() as f64).collect();
            if !loss.is_finite() || values.iter().any(|v| !v.is_finite()) {
                pb.finish_and_clear();
                let parts: Vec<String> = names.iter().zip(&values).map(|(n, v)| format!("{n} {v}")).collect();
                bail!(
                    "non-finite loss at step {} (epoch {}, batch {}/{n}): loss {loss} ({}); stopped without writing a checkpoint, the last good one is kept in {}",
                    state.step + 1,
                    state.epoch + 1,
                    state.batch + 1,
                    parts.join(", "),
                    run.checkpoints().display()
                );
            }
            let grads = GradientsParams::from_grads(terms.total.backward(), &model);
            model = optim.step(lr, model, grads);
            let secs = t0.elapsed().as_secs_f64();
            state.step += 1;
            state.batch += 1;
            state.time += secs;
            state.epoch_seconds += secs;
            accumulate(&mut state.epoch_sums, "loss", loss);
            for (nm, v) in names.iter().zip(&values) {
                accumulate(&mut state.epoch_sums, nm, *v);
            }
            let log = match &mut step_log {
                Some(l) => l,
                None => step_log.insert(CsvLog::open(&run.metrics_csv(), &step_header(&names))?),
            };
            let mut row = vec![state.step.to_string(), field(Some(e)), field(Some(lr)), field(Some(loss))];
            row.extend(values.iter().map(|v| field(Some(*v))));
            row.extend([field(Some(secs)), field(Some(state.time))]);
            log.append(&row)?;
            if epoch_log.is_none() {
                epoch_log = Some(CsvLog::open(&run.epochs_csv(), &epoch_header(&names))?);
            }
            pb.set_message(format!("loss {loss:.4} lr {lr:.2e}"));
            pb.inc(1);
            if cfg.train.checkpoint_every > 0 && state.step % cfg.train.checkpoint_every == 0 && state.batch < n {
                ckpts.save(&model, &optim, &state, &[Slot::Latest])?;
                saved_step = state.step;
            }
        }
        pb.finish_and_clear();
        if state.batch < n {
            // The epoch's batches ran out early: only frames that were all skipped do that.
            if opts.max_steps.is_some_and(|m| state.step >= m) {
                break;
            }
        }
        // The epoch is done.
        let done = state.epoch + 1;
        let due = (cfg.train.val_every > 0 && done.is_multiple_of(cfg.train.val_every)) || done == epochs || done == stop_epochs;
        let val = if due { Some(validate(&model.valid(), &val_loader, device, &cfg.eval.protocol(), opts.verbose)?) } else { None };
        let steps_in_epoch = state.batch.max(1) as f64;
        let mean = |k: &str| state.epoch_sums.iter().find(|(n, _)| n == k).map(|(_, s)| s / steps_in_epoch);
        let names: Vec<String> = state.epoch_sums.iter().map(|(n, _)| n.clone()).filter(|n| n != "loss").collect();
        let lr_end = cfg.train.schedule.lr(done as f64, epochs);
        let mut row = vec![done.to_string(), state.step.to_string(), field(Some(lr_end)), field(mean("loss"))];
        row.extend(names.iter().map(|n| field(mean(n))));
        let ap = val.as_ref().map(|v| v.ap3d);
        row.extend((0..3).map(|i| field(ap.map(|a| a[i]))));
        row.extend([field(Some(state.epoch_seconds)), field(val.as_ref().map(|v| v.seconds)), field(Some(state.time))]);
        let elog = match &mut epoch_log {
            Some(l) => l,
            None => epoch_log.insert(CsvLog::open(&run.epochs_csv(), &epoch_header(&names))?),
        };
        elog.append(&row)?;
        if opts.verbose {
            let parts: Vec<String> = names.iter().map(|n| format!("{n} {:.4}", mean(n).unwrap_or(f64::NAN))).collect();
            let ap_text = ap.map_or_else(String::new, |a| format!("  AP3D@0.3/0.5/0.7 {:.1}/{:.1}/{:.1}", 100.0 * a[0], 100.0 * a[1], 100.0 * a[2]));
            eprintln!("epoch {done}/{epochs}  loss {:.4} ({})  lr {lr_end:.2e}{ap_text}  {:.0} s", mean("loss").unwrap_or(f64::NAN), parts.join(", "), state.epoch_seconds);
            if let Some(v) = &val {
                let heading = v.heading.map_or_else(|| "no matched box".to_string(), |h| h.to_string());
                eprintln!("  AP3D by range {}; {heading}", format_by_range(&v.ap3d_by_range));
            }
        }
        if let Some(v) = &val {
            last_by_range = Some(v.ap3d_by_range);
            last_heading = v.heading;
        }
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
        ckpts.save(&model, &optim, &state, &slots)?;
        saved_step = state.step;
        if let Err(e) = plots::plot_run(run) {
            eprintln!("warning: plots not drawn: {e:#}");
        }
    }
    if state.step != saved_step || ckpts.get(Slot::Latest)?.is_none() {
        ckpts.save(&model, &optim, &state, &[Slot::Latest])?;
    }
    let summary = TrainSummary {
        name,
        model: cfg.model.kind().to_string(),
        params,
        steps: state.step,
        epochs: state.epoch,
        finished: state.epoch >= epochs,
        last_ap3d: state.last_val.map(|(a, _)| a),
        last_epoch: state.last_val.map(|(_, e)| e),
        best_ap3d_03: state.best,
        train_seconds: state.time,
        last_ap3d_by_range: last_by_range,
        last_heading,
    };
    write_atomic(&run.summary_json(), serde_json::to_string_pretty(&summary)?.as_bytes()).context("writing summary.json")?;
    Ok(summary)
}

fn accumulate(sums: &mut Vec<(String, f64)>, key: &str, v: f64) {
    match sums.iter_mut().find(|(k, _)| k == key) {
        Some((_, s)) => *s += v,
        None => sums.push((key.to_string(), v)),
    }
}
