//! Weight soups on the shipped weights: a soup of one run is that run bit for bit, a soup of two
//! is the element-wise mean of their tensors (weights and BatchNorm running statistics alike), a
//! soup is a run `detect` loads, and runs of different shape are refused naming the run.

use std::path::{Path, PathBuf};

use burn::module::{Module, ModuleMapper, ModuleVisitor, Param};
use burn::tensor::{Tensor, TensorData};
use model::{ModelConfig, PersonMinkUNet};
use train::{Checkpoints, RunDetector, RunDir, Slot};

fn weights() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../weights/person_minkunet")
}

/// Every float tensor of a run's latest checkpoint, in visiting order.
fn tensors(run: &Path) -> Vec<Vec<f32>> {
    let cfg = RunDir::at(run).config().unwrap();
    let ModelConfig::PersonMinkunet(c) = &cfg.model else { panic!("a Person-MinkUNet run") };
    let files = Checkpoints::new(RunDir::at(run).checkpoints()).get(Slot::Latest).unwrap().unwrap();
    let model: PersonMinkUNet = files.load_model(c.init(&cfg.backend.device().unwrap())).unwrap();
    struct All(Vec<Vec<f32>>);
    impl ModuleVisitor for All {
        fn visit_float<const D: usize>(&mut self, param: &Param<Tensor<D>>) {
            self.0.push(param.val().into_data().try_to_vec::<f32>().unwrap());
        }
    }
    let mut all = All(Vec::new());
    model.visit(&mut all);
    all.0
}

/// A copy of the shipped run folder whose every float tensor x became 2x + 1 (running
/// statistics too), as a second ingredient unlike the first everywhere.
fn changed_copy(dir: &Path) -> PathBuf {
    let out = dir.join("changed");
    let cfg = RunDir::at(weights()).config().unwrap();
    let ModelConfig::PersonMinkunet(c) = &cfg.model else { panic!("a Person-MinkUNet run") };
    let device = cfg.backend.device().unwrap();
    let files = Checkpoints::new(RunDir::at(weights()).checkpoints()).get(Slot::Latest).unwrap().unwrap();
    let model: PersonMinkUNet = files.load_model(c.init(&device)).unwrap();
    struct TwiceAndOne(burn::tensor::Device);
    impl ModuleMapper for TwiceAndOne {
        fn map_float<const D: usize>(&mut self, param: Param<Tensor<D>>) -> Param<Tensor<D>> {
            let device = self.0.clone();
            param.map(|t| {
                let shape = t.shape();
                let v: Vec<f32> = t.into_data().try_to_vec::<f32>().unwrap().into_iter().map(|x| 2.0 * x + 1.0).collect();
                Tensor::from_data(TensorData::new(v, shape), &device)
            })
        }
    }
    let changed = model.map(&mut TwiceAndOne(device));
    let run = RunDir::create(&out, &cfg, train::Existing::Refuse).unwrap();
    Checkpoints::new(run.checkpoints()).save_weights(&changed, &train::TrainState::default(), &[Slot::Latest]).unwrap();
    out
}

#[test]
fn a_soup_of_one_run_is_that_run() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("one");
    let report = train::soup(&[weights()], &out).unwrap();
    assert_eq!(report.relative_distance, vec![0.0]);
    assert_eq!(tensors(&out), tensors(&weights()));
    // The calibration belongs to the weights it was fitted on: cleared, to be fitted again.
    assert_eq!(RunDir::at(&out).config().unwrap().model.post().radial_shift, 0.0);
    assert!(out.join("soup.json").is_file());
}

#[test]
fn a_soup_of_two_runs_is_their_mean_and_detects() {
    let tmp = tempfile::tempdir().unwrap();
    let other = changed_copy(tmp.path());
    let out = tmp.path().join("two");
    let report = train::soup(&[weights(), other.clone()], &out).unwrap();
    let (a, b, soup) = (tensors(&weights()), tensors(&other), tensors(&out));
    assert_eq!(report.tensors, a.len());
    // The shipped network holds BatchNorm layers: weights, biases, running means and variances.
    assert!(a.len() > 100, "{} tensors", a.len());
    for (k, ((a, b), s)) in a.iter().zip(&b).zip(&soup).enumerate() {
        for ((&x, &y), &m) in a.iter().zip(b).zip(s) {
            let want = 1.5 * f64::from(x) + 0.5;
            assert!((f64::from(m) - want).abs() <= 1e-6 * want.abs().max(1.0), "tensor {k}: {m} against {want} (from {x}, {y})");
        }
    }
    // Both ingredients lie as far from the mean.
    let [d0, d1] = report.relative_distance[..] else { panic!("two distances") };
    assert!((d0 - d1).abs() < 1e-9 && d0 > 0.1, "{d0} {d1}");
    // It is a run like any other.
    let detector = RunDetector::load(&out, Slot::Latest, None).unwrap();
    let _ = detector.detect(&[[5.0, 0.0, 0.0], [5.0, 0.1, 0.5]]);
}

#[test]
fn runs_of_another_shape_or_an_existing_folder_are_refused() {
    let tmp = tempfile::tempdir().unwrap();
    let wide = tmp.path().join("wide");
    let mut cfg = RunDir::at(weights()).config().unwrap();
    let ModelConfig::PersonMinkunet(c) = &mut cfg.model else { panic!("a Person-MinkUNet run") };
    c.width *= 2.0;
    RunDir::create(&wide, &cfg, train::Existing::Refuse).unwrap();
    let e = train::soup(&[weights(), wide.clone()], &tmp.path().join("out")).unwrap_err();
    assert!(format!("{e:#}").contains(&wide.display().to_string()), "{e:#}");
    assert!(!tmp.path().join("out").exists(), "nothing written");
    // Post-processing may differ: only the network's shape must agree.
    let e = train::soup(&[weights()], &wide).unwrap_err();
    assert!(format!("{e:#}").contains("already exists"), "{e:#}");
}
