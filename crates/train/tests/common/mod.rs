//! What several of the train crate's integration tests share (each test file uses a part).
#![allow(dead_code)]

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use data_jrdb::sim::{SynthConfig, synth};
use train::RunDir;

/// The shipped Person-MinkUNet run's config and checkpoints (the facing stage beside them
/// included), copied to `dir`, so a test may write into it.
pub fn shipped_copy(dir: &Path) -> RunDir {
    fn copy_tree(from: &Path, to: &Path) {
        std::fs::create_dir_all(to).unwrap();
        for e in std::fs::read_dir(from).unwrap() {
            let e = e.unwrap();
            if e.file_type().unwrap().is_dir() {
                copy_tree(&e.path(), &to.join(e.file_name()));
            } else {
                std::fs::copy(e.path(), to.join(e.file_name())).unwrap();
            }
        }
    }
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../weights/person_minkunet");
    copy_tree(&src.join("checkpoints"), &dir.join("checkpoints"));
    std::fs::copy(src.join("config.toml"), dir.join("config.toml")).unwrap();
    RunDir::at(dir)
}

/// A simulated tree (`sim`) and a copy of the shipped run (`run`) under `dir`.
pub fn tree_and_shipped_run(dir: &Path, sim: SynthConfig) -> (PathBuf, RunDir) {
    let root = dir.join("sim");
    synth(&root, &sim).unwrap();
    (root, shipped_copy(&dir.join("run")))
}

/// The `train` binary run with `args` (colours off), whatever its outcome.
pub fn train_bin(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_train")).args(args).env("NO_COLOR", "1").output().expect("runs")
}

/// [`train_bin`], which must succeed (its output is shown when it does not).
pub fn ok(args: &[&str]) -> Output {
    let out = train_bin(args);
    assert!(out.status.success(), "train {args:?} failed:\n{}\n{}", String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr));
    out
}

/// A `FrameReport` JSON file `detect` wrote.
pub fn report(path: &Path) -> train::FrameReport {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))).unwrap()
}

/// A run's `metrics.csv` rows without their wall-clock columns (the last two).
pub fn metrics_without_times(run: &Path) -> Vec<String> {
    std::fs::read_to_string(run.join("metrics.csv")).unwrap().lines().map(|l| l.rsplitn(3, ',').nth(2).unwrap().to_string()).collect()
}

/// A sweep's `results.csv` without its time columns.
pub fn results_without_times(sweep_dir: &Path) -> Vec<String> {
    let csv = std::fs::read_to_string(sweep_dir.join("results.csv")).unwrap();
    let header: Vec<&str> = csv.lines().next().unwrap().split(',').collect();
    csv.lines().map(|l| l.split(',').zip(&header).filter(|(_, h)| !h.contains("seconds") && !h.contains("minutes")).map(|(c, _)| c.to_string()).collect::<Vec<_>>().join(",")).collect()
}

/// The reduced Person-MinkUNet the end-to-end tests train (width 0.125, batch 1, the quickstart's
/// decay over 3 epochs): `[model]`, `[train]` with `train_keys` added, `[train.schedule]`.
pub fn tiny_model_and_training(train_keys: &str) -> String {
    format!(
        r#"[model]
kind = "person_minkunet"
width = 0.125
[train]
batch_size = 1
{train_keys}[train.schedule]
kind = "exp_decay"
lr0 = 1e-3
epoch0 = 1.0
lr1 = 1e-4
epoch1 = 3.0
"#
    )
}
