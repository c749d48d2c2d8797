//! A simulated JRDB tree exported to KITTI's and nuScenes' layouts trains and scores the same as
//! the tree itself: same frames, same boxes, same losses step by step, same AP.

mod common;

use std::path::Path;

use common::ok as train_bin;
use data_jrdb::sim::{SynthConfig, synth};

const VAL: &str = "clark-center-2019-02-28_1";

fn config(dir: &Path, name: &str, data: &str) -> std::path::PathBuf {
    let training = common::tiny_model_and_training("");
    let text = format!(
        r#"seed = 3
backend = "flex"
threads = 2
[data]
{data}
val_sequences = ["{VAL}"]
voxel_size = [0.1, 0.1, 0.1]
max_voxels = 4000
prefetch = false
{training}"#
    );
    let p = dir.join(format!("{name}.toml"));
    std::fs::write(&p, text).unwrap();
    p
}

/// `metrics.csv` rows as numbers, without the wall-clock columns.
fn losses(run: &Path) -> Vec<Vec<f64>> {
    common::metrics_without_times(run).iter().skip(1).map(|l| l.split(',').filter_map(|v| v.parse().ok()).collect()).collect()
}

#[test]
fn kitti_and_nuscenes_exports_train_and_score_as_the_tree() {
    let tmp = tempfile::tempdir().unwrap();
    let jrdb = tmp.path().join("jrdb");
    synth(&jrdb, &SynthConfig { sequences: 4, frames: 2, seed: 1, max_people: 8, ..Default::default() }).unwrap();
    let data_bin = env!("CARGO_BIN_EXE_train").replace("/train", "/data-jrdb");
    for (to, dir) in [("kitti", "kitti"), ("nuscenes", "nus")] {
        let out = std::process::Command::new(&data_bin)
            .args(["export", "--root", jrdb.to_str().unwrap(), "--out", tmp.path().join(dir).to_str().unwrap(), "--to", to, "--val-sequences", VAL])
            .output()
            .expect("data-jrdb runs (built with the workspace)");
        assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    }
    let runs = tmp.path().join("runs");
    let variants = [
        ("jrdb", format!("root = {:?}", jrdb)),
        ("kitti", format!("format = \"kitti\"\nroot = {:?}\nkitti = {{ camera_view_only = false }}", tmp.path().join("kitti"))),
        ("nuscenes", format!("format = \"nuscenes\"\nroot = {:?}\nnuscenes = {{ val_scenes = [\"{VAL}\"] }}", tmp.path().join("nus"))),
    ];
    for (name, data) in &variants {
        let cfg = config(tmp.path(), name, data);
        train_bin(&["--config", cfg.to_str().unwrap(), "--out", runs.to_str().unwrap(), "--name", name, "--max-epochs", "2", "--quiet"]);
    }
    let summary = |name: &str| -> serde_json::Value { serde_json::from_str(&std::fs::read_to_string(runs.join(name).join("summary.json")).unwrap()).unwrap() };
    let reference = losses(&runs.join("jrdb"));
    assert_eq!(reference.len(), 12, "6 training frames, 2 epochs");
    for name in ["kitti", "nuscenes"] {
        let got = losses(&runs.join(name));
        assert_eq!(got.len(), reference.len(), "{name}");
        for (step, (a, b)) in reference.iter().zip(&got).enumerate() {
            // The exports round coordinates in their own units, and training amplifies that:
            // tight on the first step (the same model on the same frame), looser after (on an
            // AVX2-only machine the two runs drift 3e-4 apart by step 7; a wrong or missing
            // box moves a loss term by far more).
            let tol = if step == 0 { 1e-4 } else { 2e-3 };
            for (x, y) in a.iter().zip(b) {
                assert!((x - y).abs() <= tol * x.abs().max(1.0), "{name}, step {step}: {a:?} against {b:?}");
            }
        }
        assert_eq!(summary(name)["last_ap3d"], summary("jrdb")["last_ap3d"], "{name}");
    }
}
