//! `facing` on the shipped weights: the stage it fits turns the directions of the run's boxes
//! towards the truth and changes nothing else, is stored beside the checkpoint and applied where
//! the run is loaded; a damaged stage is refused naming its file; too few people is an error
//! that writes nothing. (Features and fit are checked by hand in `model::facing`.)

use data_jrdb::Split;
use data_jrdb::sim::SynthConfig;
use train::facing::FACING_FILE;
use train::{FacingOptions, RunDetector, RunDir, Slot, fit_facing};

mod common;
use common::{shipped_copy, tree_and_shipped_run};

/// Where the run's latest checkpoint keeps its facing stage.
fn stage_file(run: &RunDir) -> std::path::PathBuf {
    let latest = std::fs::read_to_string(run.checkpoints().join("latest")).unwrap();
    run.checkpoints().join(latest.trim()).join(FACING_FILE)
}

/// The run's config pointed at the tree `root`.
fn config_on(run: &RunDir, root: &std::path::Path, stage: bool) -> train::RunConfig {
    let mut cfg = run.config().unwrap();
    cfg.data.root = root.to_path_buf();
    cfg.data.simulate = None;
    cfg.model.post_mut().facing_stage = stage;
    cfg
}

#[test]
fn fits_a_stage_that_turns_only_headings() {
    let tmp = tempfile::tempdir().unwrap();
    let (root, run) = tree_and_shipped_run(tmp.path(), SynthConfig { sequences: 3, frames: 20, seed: 5, max_people: 24, ..Default::default() });
    let opts = FacingOptions { split: Split::TrainVal, score_on: Some(Split::TrainVal), data_root: Some(root.clone()), write: true, ..Default::default() };
    let report = fit_facing(&run, &opts).unwrap();
    eprintln!("{report}");
    let (network, staged) = report.scored.unwrap();
    // Scored on the boxes it was fitted on: it must tell most of them, where the network's
    // directions are near chance.
    let (before, after) = (network.direction_right.unwrap(), staged.direction_right.unwrap());
    assert!(after > before + 0.1 && after > 0.7, "{before} → {after}");
    // A half turn in f64 moves a heading's axis by rounding only (1e-13° on the shipped weights).
    let (axis, staged_axis) = (network.median_axis_deg, staged.median_axis_deg);
    assert!((axis - staged_axis).abs() < 1e-9, "the axis is the network's: {axis} → {staged_axis}");
    let path = report.written.unwrap();
    assert_eq!(path.file_name().unwrap(), FACING_FILE);
    assert!(path.starts_with(run.checkpoints()));

    // Loaded with the run, it turns headings by half a turn or not at all.
    let with = RunDetector::with_config(&run.root, config_on(&run, &root, true), Slot::Latest, None).unwrap();
    let without = RunDetector::with_config(&run.root, config_on(&run, &root, false), Slot::Latest, None).unwrap();
    assert!(with.facing().is_some() && without.facing().is_none());
    let loader = train::data::eval_loader(with.config(), Split::TrainVal).unwrap();
    let batch = loader.epoch(0).next().unwrap().unwrap();
    let turned: usize = with.detect_batch(&batch).iter().zip(&without.detect_batch(&batch)).map(|(a, b)| half_turns(a, b)).sum();
    assert!(turned > 0, "the stage turned none of the first batch's boxes");
    // The one-cloud path of `detect` and `serve` applies it too.
    let cloud = &batch.clouds[0];
    assert!(half_turns(&with.detect(cloud), &without.detect(cloud)) > 0);
}

/// How many of `a`'s boxes are `b`'s turned by half a turn; panics unless every other box is the
/// same, with the same score.
fn half_turns(a: &model::Detections, b: &model::Detections) -> usize {
    use std::f64::consts::{PI, TAU};
    assert_eq!(a.scores, b.scores);
    let mut turned = 0;
    for (x, y) in a.boxes.iter().zip(&b.boxes) {
        assert_eq!([x.cx, x.cy, x.cz, x.l, x.w, x.h], [y.cx, y.cy, y.cz, y.l, y.w, y.h]);
        let d = (x.rot_z - y.rot_z).rem_euclid(TAU);
        let half_turn = (d - PI).abs() < 1e-9;
        assert!(d < 1e-9 || TAU - d < 1e-9 || half_turn, "{} vs {}", x.rot_z, y.rot_z);
        turned += half_turn as usize;
    }
    turned
}

#[test]
fn a_damaged_stage_is_refused_naming_its_file() {
    let tmp = tempfile::tempdir().unwrap();
    let run = shipped_copy(&tmp.path().join("run"));
    let path = stage_file(&run);
    std::fs::write(&path, "{\"features\": ").unwrap();
    let e = format!("{:#}", RunDetector::load(&run.root, Slot::Latest, None).err().unwrap());
    assert!(e.contains(&path.display().to_string()) && e.contains("not a facing stage"), "{e}");
    // Switched off, the file is not read.
    let mut cfg = run.config().unwrap();
    cfg.model.post_mut().facing_stage = false;
    assert!(RunDetector::with_config(&run.root, cfg, Slot::Latest, None).unwrap().facing().is_none());
}

#[test]
fn too_few_people_is_an_error_and_writes_nothing() {
    let tmp = tempfile::tempdir().unwrap();
    let (root, run) = tree_and_shipped_run(tmp.path(), SynthConfig { sequences: 1, frames: 2, seed: 5, max_people: 3, ..Default::default() });
    let path = stage_file(&run);
    let before = std::fs::read(&path).ok();
    let opts = FacingOptions { split: Split::TrainVal, score_on: None, data_root: Some(root.clone()), write: true, ..Default::default() };
    let e = format!("{:#}", fit_facing(&run, &opts).unwrap_err());
    assert!(e.contains(&root.display().to_string()) && e.contains("fewer than the 200"), "{e}");
    assert_eq!(std::fs::read(&path).ok(), before);
}
