//! What several of the train crate's integration tests share (each test file uses a part).
#![allow(dead_code)]

use std::path::{Path, PathBuf};

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
