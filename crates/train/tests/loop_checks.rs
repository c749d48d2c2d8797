//! The training loop with a test detector (so these checks do not depend on a real model's
//! numerics): a non-finite loss stops the run naming the step and keeps the last good checkpoint;
//! sweep bookkeeping skips finished runs and aggregates seeds.

use std::path::Path;
use std::sync::Arc;
use std::sync::atomic::{AtomicUsize, Ordering};

use burn::module::{Module, Param};
use burn::tensor::{Device, Tensor, TensorData};
use data_jrdb::Batch;
use model::{Detections, Detector, LossTerms};
use train::checkpoint::{Checkpoints, Slot};
use train::metrics::Table;
use train::sweep::{SweepConfig, aggregate, finished, run_sweep};
use train::{Existing, RunConfig, RunDir, TrainOptions, TrainSummary, train_model};

/// A one-parameter "detector": loss = (w − 1)² per batch; from call `nan_from` on, the loss is NaN.
#[derive(Module, Debug)]
struct Toy {
    w: Param<Tensor<1>>,
    #[module(skip)]
    calls: Arc<AtomicUsize>,
    #[module(skip)]
    nan_from: usize,
}

impl Detector for Toy {
    fn loss(&self, _batch: &Batch, _device: &Device) -> LossTerms {
        let k = self.calls.fetch_add(1, Ordering::SeqCst) + 1;
        let d = self.w.val() - 1.0;
        let mut total = d.clone() * d;
        if k >= self.nan_from {
            total = total.mul_scalar(f32::NAN);
        }
        LossTerms { total: total.clone(), terms: vec![("sq", total)] }
    }

    fn head_output(&self, _batch: &Batch, _device: &Device) -> Vec<f32> {
        self.w.val().into_data().try_to_vec::<f32>().expect("f32 parameter")
    }

    fn detect(&self, batch: &Batch, _device: &Device) -> Vec<Detections> {
        vec![Detections::default(); batch.len()]
    }
}

fn config(dir: &Path, extra: &str) -> RunConfig {
    let text = format!(
        "seed = 1\n[data]\nroot = \"{}\"\nvoxel_size = [0.2, 0.2, 0.2]\nprefetch = false\n[data.simulate]\nsequences = 2\nframes = 3\nmax_people = 4\n[model]\nkind = \"person_minkunet\"\n[train]\nbatch_size = 1\nepochs = 3\ncheckpoint_every = 1\n{extra}",
        dir.join("data").display()
    );
    RunConfig::from_toml_str(&text).unwrap()
}

#[test]
fn non_finite_loss_names_the_step_and_keeps_the_last_good_checkpoint() {
    let tmp = tempfile::tempdir().unwrap();
    let cfg = config(tmp.path(), "");
    let run = RunDir::create(tmp.path().join("run"), &cfg, Existing::Refuse).unwrap();
    let device = Device::flex();
    let ad = device.clone().autodiff();
    let toy = Toy { w: Param::from_tensor(Tensor::from_data(TensorData::from([3.0f32]), &ad)), calls: Arc::new(AtomicUsize::new(0)), nan_from: 3 };
    let opts = TrainOptions { verbose: false, ..Default::default() };
    let err = train_model(toy, &cfg, &run, &opts, &device).expect_err("NaN must stop the run").to_string();
    assert!(err.contains("non-finite loss at step 3"), "{err}");
    let latest = Checkpoints::new(run.checkpoints()).get(Slot::Latest).unwrap().expect("a checkpoint from step 2");
    let state = latest.read_state().unwrap();
    assert_eq!(state.step, 2, "the checkpoint is the last good step");
    let m = Table::read(&run.metrics_csv()).unwrap();
    assert_eq!(m.rows.len(), 2);
    let loss = m.column("loss").unwrap();
    assert!(loss[1] < loss[0], "Adam moved w toward 1: {loss:?}");
    assert!(!run.summary_json().exists(), "a failed run is not finished");
}

#[test]
fn toy_run_trains_and_checkpoints_atomically() {
    let tmp = tempfile::tempdir().unwrap();
    let cfg = config(tmp.path(), "val_every = 0\n[train.schedule]\nkind = \"constant\"\nlr = 0.1\n");
    let run = RunDir::create(tmp.path().join("run"), &cfg, Existing::Refuse).unwrap();
    let device = Device::flex();
    let ad = device.clone().autodiff();
    let toy = Toy { w: Param::from_tensor(Tensor::from_data(TensorData::from([3.0f32]), &ad)), calls: Arc::new(AtomicUsize::new(0)), nan_from: usize::MAX };
    let s = train_model(toy, &cfg, &run, &TrainOptions::default(), &device).unwrap();
    assert!(s.finished && s.epochs == 3);
    // 1 train sequence × 3 frames, batch 1.
    assert_eq!(s.steps, 9);
    let m = Table::read(&run.metrics_csv()).unwrap();
    assert_eq!(m.column("step").unwrap(), (1..=9).map(f64::from).collect::<Vec<_>>());
    let loss = m.column("sq").unwrap();
    assert!(loss.windows(2).all(|w| w[1] < w[0]) && loss[8] < 0.5 * loss[0], "Adam at lr 0.1 moves w toward 1: {loss:?}");
    let e = Table::read(&run.epochs_csv()).unwrap();
    assert_eq!(e.rows.len(), 3);
    assert!(e.column("ap3d_0.3").unwrap()[..2].iter().all(|v| v.is_nan()), "val_every = 0: only the last epoch is validated");
    assert!(e.column("ap3d_0.3").unwrap()[2].is_finite());
    // Only the folders the pointers name are kept, no temporaries.
    let names: Vec<String> = std::fs::read_dir(run.checkpoints()).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into_owned()).collect();
    assert!(names.iter().all(|n| !n.ends_with(".tmp")), "{names:?}");
    assert!(names.iter().filter(|n| n.starts_with("step-")).count() <= 2, "{names:?}");
}

fn fake_summary(dir: &Path, ap: f64, finished: bool) -> TrainSummary {
    std::fs::create_dir_all(dir).unwrap();
    let s = TrainSummary {
        name: "x".into(),
        model: "person_minkunet".into(),
        params: 42,
        steps: 10,
        epochs: 2,
        finished,
        last_ap3d: Some([ap, ap / 2.0, ap / 4.0]),
        last_epoch: Some(2),
        best_ap3d_03: Some((ap, 2)),
        train_seconds: 5.0,
        last_ap3d_by_range: None,
        last_heading: None,
    };
    std::fs::write(dir.join("summary.json"), serde_json::to_string(&s).unwrap()).unwrap();
    std::fs::write(dir.join("epochs.csv"), format!("epoch,ap3d_0.3\n1,{}\n2,{ap}\n", ap / 2.0)).unwrap();
    s
}

#[test]
fn sweep_skips_finished_runs_and_aggregates_seeds() {
    let tmp = tempfile::tempdir().unwrap();
    std::fs::write(tmp.path().join("base.toml"), "[model]\nkind = \"person_minkunet\"\n").unwrap();
    let sweep_text = format!(
        "base = \"base.toml\"\nout_dir = \"{}\"\nseeds = [0, 1]\n[set]\n\"train.epochs\" = 2\n[[variants]]\nname = \"a\"\nset = {{ \"model.width\" = 0.5 }}\n[[variants]]\nname = \"b\"\nset = {{ model = {{ kind = \"centerpoint\" }} }}\n",
        tmp.path().join("runs").display()
    );
    std::fs::write(tmp.path().join("s.toml"), sweep_text).unwrap();
    let (sweep, base) = SweepConfig::load(&tmp.path().join("s.toml")).unwrap();
    let jobs = sweep.jobs(&base).unwrap();
    assert_eq!(jobs.len(), 4);
    assert_eq!(jobs[0].config.train.epochs, 2);
    assert_eq!(jobs[3].config.model.kind(), "centerpoint");
    assert_eq!((jobs[1].variant.as_str(), jobs[1].seed, jobs[1].config.seed), ("a", 1, 1));
    // Variant b seed 1 finished in an earlier invocation; a seed 1 was interrupted.
    fake_summary(&jobs[3].dir, 0.9, true);
    fake_summary(&jobs[1].dir, 0.0, false);
    let mut ran = Vec::new();
    let results = run_sweep(
        &sweep,
        &jobs,
        &[],
        |j| {
            ran.push((j.variant.clone(), j.seed));
            // The tables are written before the first job and after each: at "a" seed 1, seed 0
            // of "a" and the earlier run of "b" are in them.
            let md = std::fs::read_to_string(sweep.dir().join("results.md")).unwrap();
            let expected = match (j.variant.as_str(), j.seed) {
                ("a", 0) => "| a | person_minkunet | 0/2 |",
                ("a", 1) => "| a | person_minkunet | 1/2 |",
                _ => "| a | person_minkunet | 2/2 |",
            };
            assert!(md.contains(expected) && md.contains("| b | centerpoint | 1/2 |"), "{md}");
            Ok(fake_summary(&j.dir, if j.variant == "a" { 0.4 + 0.2 * j.seed as f64 } else { 0.7 }, true))
        },
        false,
    )
    .unwrap();
    assert_eq!(ran, vec![("a".into(), 0), ("a".into(), 1), ("b".into(), 0)]);
    let a = &results.variants[0];
    assert_eq!((a.done, a.planned), (2, 2));
    assert!((a.ap3d[0].0 - 0.5).abs() < 1e-12 && (a.ap3d[0].1 - 0.02f64.sqrt()).abs() < 1e-12, "{:?}", a.ap3d[0]);
    let b = &results.variants[1];
    assert!((b.ap3d[0].0 - 0.8).abs() < 1e-12, "mean of the skipped run (0.9) and the new one (0.7)");
    assert_eq!(b.curve.len(), 2);
    assert!((b.curve[0].1 - 0.4).abs() < 1e-12 && (b.curve[1].1 - 0.8).abs() < 1e-12, "{:?}", b.curve);
    let md = std::fs::read_to_string(sweep.dir().join("results.md")).unwrap();
    assert!(md.contains("| a | person_minkunet | 2/2 | 50.0 ± 14.1 [-77.1, 177.1] |"), "{md}");
    assert!(sweep.dir().join("results.csv").exists() && sweep.dir().join("curves.png").exists());
    // A re-run has nothing left to do.
    let again = run_sweep(&sweep, &jobs, &[], |_| panic!("every run is finished"), false).unwrap();
    assert_eq!(again, results);
    assert!(jobs.iter().all(|j| finished(&j.dir).is_some()));
    assert_eq!(aggregate(&jobs), results);
    // One variant at a time: with "a" seed 0 unfinished again, running "b" leaves it alone (and
    // the tables still list "a"'s finished seed), running "a" runs that seed only.
    fake_summary(&jobs[0].dir, 0.0, false);
    let only_b = run_sweep(&sweep, &jobs, &["b".into()], |_| panic!("b is finished"), false).unwrap();
    assert_eq!((only_b.variants[0].done, only_b.variants[1].done), (1, 2));
    let mut ran = Vec::new();
    run_sweep(&sweep, &jobs, &["a".into()], |j| {
        ran.push((j.variant.clone(), j.seed));
        Ok(fake_summary(&j.dir, 0.4, true))
    }, false)
    .unwrap();
    assert_eq!(ran, vec![("a".into(), 0)]);
    let unknown = run_sweep(&sweep, &jobs, &["c".into()], |_| panic!("nothing runs"), false).unwrap_err();
    assert!(format!("{unknown}").contains("no variant 'c' (it has: a, b)"), "{unknown}");
}

/// A one-parameter "detector" whose loss, (w − frames in the batch)², tells the parts of a
/// data-parallel step apart; it records each part's size.
#[derive(Module, Debug)]
struct FrameCount {
    w: Param<Tensor<1>>,
    #[module(skip)]
    parts: Arc<std::sync::Mutex<Vec<usize>>>,
}

impl Detector for FrameCount {
    fn loss(&self, batch: &Batch, _device: &Device) -> LossTerms {
        self.parts.lock().unwrap().push(batch.len());
        let d = self.w.val() - batch.len() as f32;
        let total = d.clone() * d;
        LossTerms { total: total.clone(), terms: vec![("sq", total)] }
    }

    fn head_output(&self, _batch: &Batch, _device: &Device) -> Vec<f32> {
        self.w.val().into_data().try_to_vec::<f32>().expect("f32 parameter")
    }

    fn detect(&self, batch: &Batch, _device: &Device) -> Vec<Detections> {
        vec![Detections::default(); batch.len()]
    }
}

/// `train.devices = [0, 0]`: each batch of 3 frames is cut into parts of 2 and 1, each part's
/// loss computed by its own replica, the logged loss their mean and the step the one of their
/// averaged gradients; a device the backend does not have is an error naming it.
#[test]
fn two_devices_split_each_batch_and_average_the_parts() {
    let tmp = tempfile::tempdir().unwrap();
    let text = format!(
        "seed = 1\n[data]\nroot = \"{}\"\nvoxel_size = [0.2, 0.2, 0.2]\nprefetch = false\n[data.simulate]\nsequences = 2\nframes = 3\nmax_people = 4\n[model]\nkind = \"person_minkunet\"\n[train]\nbatch_size = 3\nepochs = 3\nval_every = 0\ndevices = [0, 0]\n[train.schedule]\nkind = \"constant\"\nlr = 0.1\n",
        tmp.path().join("data").display()
    );
    let cfg = RunConfig::from_toml_str(&text).unwrap();
    let run = RunDir::create(tmp.path().join("run"), &cfg, Existing::Refuse).unwrap();
    let device = Device::flex();
    let ad = device.clone().autodiff();
    let parts = Arc::new(std::sync::Mutex::new(Vec::new()));
    let model = FrameCount { w: Param::from_tensor(Tensor::from_data(TensorData::from([3.0f32]), &ad)), parts: parts.clone() };
    let s = train_model(model, &cfg, &run, &TrainOptions::default(), &device).unwrap();
    assert_eq!(s.steps, 3, "1 train sequence × 3 frames, batch 3, 3 epochs");
    // Validation's forward passes do not call the loss.
    assert_eq!(*parts.lock().unwrap(), vec![2, 1, 2, 1, 2, 1]);
    let sq = Table::read(&run.metrics_csv()).unwrap().column("sq").unwrap();
    assert_eq!(sq[0], 2.5, "the first step logs the mean of (3 − 2)² and (3 − 1)²");
    // Adam moves w by about lr a step toward 1.5, where the parts' gradients cancel (one device
    // would move it toward 3, where its loss already is 0).
    assert!(sq.windows(2).all(|w| w[1] < w[0]), "{sq:?}");

    let cfg = RunConfig::from_toml_str(&text.replace("devices = [0, 0]", "devices = [0, 1]")).unwrap();
    let run = RunDir::create(tmp.path().join("run-2"), &cfg, Existing::Refuse).unwrap();
    let model = FrameCount { w: Param::from_tensor(Tensor::from_data(TensorData::from([3.0f32]), &ad)), parts };
    let err = train_model(model, &cfg, &run, &TrainOptions::default(), &device).expect_err("flex has no device 1").to_string();
    assert!(err.contains("device 1") && err.contains("--backend cuda"), "{err}");
}

#[test]
fn train_init_starts_from_another_runs_weights_and_refuses_what_does_not_fit() {
    let tmp = tempfile::tempdir().unwrap();
    let device = Device::flex();
    let ad = device.clone().autodiff();
    let toy = |w: &[f32]| Toy { w: Param::from_tensor(Tensor::from_data(TensorData::new(w.to_vec(), [w.len()]), &ad)), calls: Arc::new(AtomicUsize::new(0)), nan_from: usize::MAX };
    let constant = "val_every = 0\n[train.schedule]\nkind = \"constant\"\nlr = 0.1\n";
    let first = tmp.path().join("first");
    let cfg = config(tmp.path(), constant);
    let run = RunDir::create(&first, &cfg, Existing::Refuse).unwrap();
    train_model(toy(&[3.0]), &cfg, &run, &TrainOptions::default(), &device).unwrap();
    let last = Table::read(&run.metrics_csv()).unwrap().column("sq").unwrap()[8];

    // Started from the first run's weights: the first step's loss is at most the first run's
    // last, not (3 − 1)² = 4 of the random start it was given.
    let cfg = config(tmp.path(), &format!("init = \"{}\"\n{constant}", first.display()));
    let run = RunDir::create(tmp.path().join("second"), &cfg, Existing::Refuse).unwrap();
    train_model(toy(&[3.0]), &cfg, &run, &TrainOptions { max_steps: Some(1), ..Default::default() }, &device).unwrap();
    let loss = Table::read(&run.metrics_csv()).unwrap().column("sq").unwrap()[0];
    assert!(loss < last, "first step {loss}, the first run's last {last}");

    // A folder without checkpoints, and weights of another shape, are errors naming the folder.
    let cfg = config(tmp.path(), &format!("init = \"{}\"\n{constant}", tmp.path().join("data").display()));
    let run = RunDir::create(tmp.path().join("third"), &cfg, Existing::Refuse).unwrap();
    let err = format!("{:#}", train_model(toy(&[3.0]), &cfg, &run, &TrainOptions::default(), &device).unwrap_err());
    assert!(err.contains("no checkpoint there") && err.contains("data"), "{err}");
    // That run failed before its first step, so its folder does not block the next attempt; a
    // run that has taken steps does.
    RunDir::create(tmp.path().join("third"), &cfg, Existing::Refuse).expect("a folder with only a config is started over");
    let err = RunDir::create(&first, &cfg, Existing::Refuse).err().expect("a trained run is kept").to_string();
    assert!(err.contains("already holds a run"), "{err}");
    let cfg = config(tmp.path(), &format!("init = \"{}\"\n{constant}", first.display()));
    let run = RunDir::create(tmp.path().join("fourth"), &cfg, Existing::Refuse).unwrap();
    let err = format!("{:#}", train_model(toy(&[3.0, 3.0]), &cfg, &run, &TrainOptions::default(), &device).unwrap_err());
    assert!(err.contains("do not fit") && err.contains("first") && err.contains("shape"), "{err}");
}

#[test]
fn train_init_carries_weights_over_to_another_input() {
    use model::person_minkunet::InputFeatures;
    use model::{ModelConfig, PersonMinkUNet};
    let tmp = tempfile::tempdir().unwrap();
    let cfg = |input: &str, channels: usize, init: &str| {
        RunConfig::from_toml_str(&format!(
            "seed = 1\n[data]\nroot = \"{}\"\nvoxel_size = [0.2, 0.2, 0.2]\nprefetch = false\n[data.simulate]\nsequences = 2\nframes = 2\nmax_people = 4\n[model]\nkind = \"person_minkunet\"\nwidth = 0.25\ninput = \"{input}\"\nin_channels = {channels}\n[train]\nbatch_size = 1\nepochs = 1\nval_every = 0\n{init}[train.schedule]\nkind = \"constant\"\nlr = 1e-12\n",
            tmp.path().join("data").display()
        ))
        .unwrap()
    };
    let opts = TrainOptions { max_steps: Some(1), ..Default::default() };
    let latest = |run: &RunDir, cfg: &RunConfig| {
        let ModelConfig::PersonMinkunet(c) = &cfg.model else { unreachable!() };
        let files = Checkpoints::new(run.checkpoints()).get(Slot::Latest).unwrap().expect("a checkpoint");
        files.load_model(PersonMinkUNet::new(c, &Device::flex())).unwrap()
    };
    let xyz = cfg("xyz", 3, "");
    let first = RunDir::create(tmp.path().join("xyz"), &xyz, Existing::Refuse).unwrap();
    train::train(&xyz, &first, &opts).unwrap();
    let trained = latest(&first, &xyz);

    let init = format!("init = \"{}\"\n", first.root.display());
    let range_height = cfg("range_height", 5, &init);
    let second = RunDir::create(tmp.path().join("range_height"), &range_height, Existing::Refuse).unwrap();
    train::train(&range_height, &second, &opts).unwrap();
    assert!(second.root.join("init-carried.bpk").is_file(), "the carried weights the run started from are kept beside it");
    let carried = latest(&second, &range_height);
    assert_eq!(carried.config.input, InputFeatures::RangeHeight);
    let (old, new) = (trained.backbone.stem[0].weight.val(), carried.backbone.stem[0].weight.val());
    let [k, c_in, c_out] = new.dims();
    assert_eq!([k, c_in], [27, 5]);
    let (old, new) = (old.into_data().try_to_vec::<f32>().unwrap(), new.into_data().try_to_vec::<f32>().unwrap());
    for kk in 0..k {
        for o in 0..c_out {
            // range_height's channels: range, z, dx, dy, dz; xyz's: x, y, z.
            let z = (old[(kk * 3 + 2) * c_out + o], new[(kk * 5 + 1) * c_out + o]);
            assert!((z.0 - z.1).abs() < 1e-6, "offset {kk}, out {o}: z weight {} became {}", z.0, z.1);
            for ch in [0, 2, 3, 4] {
                assert!(new[(kk * 5 + ch) * c_out + o].abs() < 1e-6, "channel {ch} starts at zero");
            }
        }
    }
    // Every other weight came over as it was (a step of lr 1e-12 moves nothing visibly).
    let head = |m: &PersonMinkUNet| m.head.weight.val().into_data().try_to_vec::<f32>().unwrap();
    let (a, b) = (head(&trained), head(&carried));
    assert!(a.iter().zip(&b).all(|(a, b)| (a - b).abs() < 1e-6));
}
