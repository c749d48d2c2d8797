//! `calibrate` on the shipped weights: it finds the simulated people's centres short along the
//! ray, `--write` changes the run's radial shift and nothing else, and too few people is an error
//! naming the tree that leaves the config as it was. (The matching's arithmetic is unit-tested by
//! hand in `calibrate.rs`; on seed 7's training split it gives `tools/centre_errors.py`'s 19,635
//! matches and −0.073 m.)

use data_jrdb::Split;
use data_jrdb::sim::SynthConfig;
use train::{CalibrateOptions, calibrate};

mod common;
use common::tree_and_shipped_run;

#[test]
fn measures_the_bias_and_writes_only_the_shift() {
    let tmp = tempfile::tempdir().unwrap();
    let (root, run) = tree_and_shipped_run(tmp.path(), SynthConfig { sequences: 2, frames: 8, seed: 5, max_people: 24, ..Default::default() });
    let before = run.config().unwrap();
    let opts = CalibrateOptions { split: Split::TrainVal, checkpoint: None, backend: None, data_root: Some(root.clone()), write: true, verbose: false };
    let bias = calibrate(&run, &opts).unwrap();
    eprintln!("{bias}");
    // The simulated people's centres fall short along the ray (docs/recipe.md §6).
    assert!(bias.median < -0.02 && bias.median > -0.15, "{bias}");
    let after = run.config().unwrap();
    assert_eq!(after.model.post().radial_shift, bias.shift);
    let mut restored = after.clone();
    restored.model.post_mut().radial_shift = before.model.post().radial_shift;
    assert_eq!(restored, before, "only the shift changed");
}

#[test]
fn too_few_people_is_an_error_and_writes_nothing() {
    let tmp = tempfile::tempdir().unwrap();
    let (root, run) = tree_and_shipped_run(tmp.path(), SynthConfig { sequences: 1, frames: 2, seed: 5, max_people: 3, ..Default::default() });
    let before = std::fs::read_to_string(run.config_file()).unwrap();
    let opts = CalibrateOptions { split: Split::TrainVal, checkpoint: None, backend: None, data_root: Some(root.clone()), write: true, verbose: false };
    let e = format!("{:#}", calibrate(&run, &opts).unwrap_err());
    assert!(e.contains(&root.display().to_string()) && e.contains("fewer than the 100"), "{e}");
    assert_eq!(std::fs::read_to_string(run.config_file()).unwrap(), before);
}
