//! End to end through the binary (as users run it): data generation, training, validation,
//! checkpoints, plots, inference and scoring; and resume against an uninterrupted run.

mod common;

use std::path::Path;
use std::process::Command;

use common::{metrics_without_times, ok as train_bin, results_without_times};
use train::metrics::Table;

fn tiny_config(dir: &Path, data: &Path, extra: &str) -> std::path::PathBuf {
    let training = common::tiny_model_and_training("");
    let text = format!(
        r#"seed = 3
backend = "flex"
threads = 2
[data]
root = "{}"
voxel_size = [0.1, 0.1, 0.1]
max_voxels = 4000
prefetch = false
[data.simulate]
sequences = 2
frames = 4
seed = 1
max_people = 8
{training}[eval]
frame_stride = 2
{extra}
"#,
        data.display()
    );
    let p = dir.join("cfg.toml");
    std::fs::write(&p, text).unwrap();
    p
}


#[test]
fn smoke_generate_train_validate_checkpoint_infer() {
    let tmp = tempfile::tempdir().unwrap();
    let data = tmp.path().join("data");
    let cfg = tiny_config(tmp.path(), &data, "");
    // `train.epochs` defaults to 40: stop after 2 with --max-epochs (validation runs at the stop).
    let runs = tmp.path().join("runs");
    train_bin(&["--config", cfg.to_str().unwrap(), "--out", runs.to_str().unwrap(), "--name", "smoke", "--max-epochs", "2", "--quiet"]);
    assert!(data.join("pointclouds").is_dir(), "the simulated dataset was generated");
    let run = runs.join("smoke");
    for f in ["config.toml", "metrics.csv", "epochs.csv", "summary.json", "plots/steps.png", "plots/epochs.png", "checkpoints/latest", "checkpoints/best"] {
        assert!(run.join(f).exists(), "{f} missing");
    }
    let resolved = std::fs::read_to_string(run.join("config.toml")).unwrap();
    assert!(resolved.contains("epochs = 40") && resolved.contains("amsgrad = true"), "{resolved}");
    let m = Table::read(&run.join("metrics.csv")).unwrap();
    assert!(m.rows.len() >= 2);
    assert!(m.col("cls").is_some() || m.header.len() > 6, "loss terms are columns: {:?}", m.header);
    assert!(m.column("loss").unwrap().iter().all(|v| v.is_finite()));
    let e = Table::read(&run.join("epochs.csv")).unwrap();
    assert_eq!(e.column("epoch").unwrap(), vec![1.0, 2.0]);
    let ap = e.column("ap3d_0.3").unwrap();
    assert!(ap[1].is_finite() && (0.0..=1.0).contains(&ap[1]), "validated at the stop: {ap:?}");
    // A second plain invocation refuses to overwrite the run.
    let again = Command::new(env!("CARGO_BIN_EXE_train")).args(["--config", cfg.to_str().unwrap(), "--out", runs.to_str().unwrap(), "--name", "smoke", "--quiet"]).output().unwrap();
    assert!(!again.status.success() && String::from_utf8_lossy(&again.stderr).contains("--resume"));

    let out = train_bin(&["infer", "--run", run.to_str().unwrap(), "--split", "val", "--render", "1"]);
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(text.contains("frames"), "{text}");
    let det = run.join("detections/val");
    let json: Vec<_> = std::fs::read_dir(det.join("json")).unwrap().collect();
    assert!(!json.is_empty());
    assert!(det.join("kitti").is_dir() && det.join("kitti_gt").is_dir() && det.join("eval.json").exists());
    let eval: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(det.join("eval.json")).unwrap()).unwrap();
    assert!(eval.to_string().contains("0.3"), "{eval}");
    let pngs: Vec<_> = std::fs::read_dir(run.join("render/val")).unwrap().collect();
    assert_eq!(pngs.len(), 1);
}

#[test]
fn resumed_run_continues_exactly() {
    let tmp = tempfile::tempdir().unwrap();
    let data = tmp.path().join("data");
    // No validation before the last epoch; checkpoints at epoch ends and at the stop.
    let cfg = tiny_config(tmp.path(), &data, "");
    let cfg = cfg.to_str().unwrap();
    let runs = tmp.path().join("runs");
    let runs = runs.to_str().unwrap();
    let set = ["--set", "train.epochs=3", "--set", "train.val_every=0", "--quiet"];
    let args = |name: &'static str, steps: &'static str| {
        let mut a = vec!["--config", cfg, "--out", runs, "--name", name, "--max-steps", steps];
        a.extend(set);
        a
    };
    train_bin(&args("whole", "5"));
    train_bin(&args("split", "2"));
    let mut resume = args("split", "5");
    resume.push("--resume");
    train_bin(&resume);
    let whole = Table::read(&Path::new(runs).join("whole/metrics.csv")).unwrap();
    let split = Table::read(&Path::new(runs).join("split/metrics.csv")).unwrap();
    assert_eq!(whole.header, split.header);
    assert_eq!(whole.rows.len(), 5);
    assert_eq!(split.rows.len(), 5, "rows of the resumed run: steps 1-2 then 3-5");
    let skip = ["seconds", "time"];
    for (a, b) in whole.rows.iter().zip(&split.rows) {
        for (i, h) in whole.header.iter().enumerate() {
            if skip.contains(&h.as_str()) {
                continue;
            }
            assert!((a[i] - b[i]).abs() <= 1e-6 * a[i].abs().max(1e-6), "column {h}: {} vs {} at step {}", a[i], b[i], a[0]);
        }
    }
    // The data of both runs spans an epoch boundary (2 train frames per epoch at batch 1).
    assert!(whole.column("epoch").unwrap().iter().any(|&e| e >= 1.0));
}

#[test]
fn sweep_rescore_scores_finished_runs_with_new_post_processing_only() {
    let tmp = tempfile::tempdir().unwrap();
    let data = tmp.path().join("data");
    let cfg = tiny_config(tmp.path(), &data, "");
    let text = std::fs::read_to_string(&cfg).unwrap().replace("[train]\n", "[train]\nepochs = 1\n");
    std::fs::write(&cfg, text).unwrap();
    let sweep = tmp.path().join("s.toml");
    let write_sweep = |set: &str| {
        let runs = tmp.path().join("runs");
        std::fs::write(&sweep, format!("base = \"cfg.toml\"\nout_dir = \"{}\"\nseeds = [0]\n[set]\n{set}\n", runs.display())).unwrap();
    };
    write_sweep("");
    train_bin(&["sweep", sweep.to_str().unwrap()]);
    let run = tmp.path().join("runs/s/base/seed-0");
    let summary = |p: &Path| -> serde_json::Value { serde_json::from_str(&std::fs::read_to_string(p.join("summary.json")).unwrap()).unwrap() };
    let before = summary(&run);
    let metrics = std::fs::read_to_string(run.join("metrics.csv")).unwrap();
    // Other post-processing: the scores change (as `infer` with the same settings gives them),
    // the training record does not.
    write_sweep("\"model.post.nms\" = \"none\"\n\"model.post.max_boxes\" = 3");
    train_bin(&["sweep", sweep.to_str().unwrap(), "--rescore"]);
    let after = summary(&run);
    assert_ne!(before["last_ap3d"], after["last_ap3d"]);
    assert_eq!((before["steps"].clone(), before["train_seconds"].clone()), (after["steps"].clone(), after["train_seconds"].clone()));
    assert_eq!(metrics, std::fs::read_to_string(run.join("metrics.csv")).unwrap());
    assert!(std::fs::read_to_string(run.join("config.toml")).unwrap().contains("max_boxes = 3"));
    let eval: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(run.join("detections/val/eval.json")).unwrap()).unwrap();
    assert_eq!(eval["ap3d"]["0.3"], after["last_ap3d"][0], "{eval}");
    // A change to what the model learns is refused: retrain instead.
    write_sweep("\"model.width\" = 0.25");
    let out = Command::new(env!("CARGO_BIN_EXE_train")).args(["sweep", sweep.to_str().unwrap(), "--rescore"]).output().unwrap();
    assert!(!out.status.success() && String::from_utf8_lossy(&out.stderr).contains("only [model.post] and [eval] may differ"));
    // A run copied into another sweep (another out_dir in its config) is rescored there.
    let other = tmp.path().join("s2.toml");
    std::fs::write(&other, std::fs::read_to_string(&sweep).unwrap().replace("\"model.width\" = 0.25", "\"model.post.max_boxes\" = 4")).unwrap();
    let copy = tmp.path().join("runs/s2/base/seed-0");
    std::fs::create_dir_all(copy.parent().unwrap()).unwrap();
    assert!(Command::new("cp").args(["-r", run.to_str().unwrap(), copy.to_str().unwrap()]).status().unwrap().success());
    train_bin(&["sweep", other.to_str().unwrap(), "--rescore"]);
    assert!(std::fs::read_to_string(copy.join("config.toml")).unwrap().contains("max_boxes = 4"));
    // A run that cannot be scored (its checkpoints gone) is an error naming it, and keeps the
    // settings it was scored with.
    std::fs::remove_dir_all(run.join("checkpoints")).unwrap();
    let config = std::fs::read_to_string(run.join("config.toml")).unwrap();
    write_sweep("\"model.post.max_boxes\" = 5");
    let out = Command::new(env!("CARGO_BIN_EXE_train")).args(["sweep", sweep.to_str().unwrap(), "--rescore", "--variant", "base"]).output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success() && err.contains("not rescored") && err.contains(&run.display().to_string()), "{err}");
    assert_eq!(std::fs::read_to_string(run.join("config.toml")).unwrap(), config);
}

#[test]
fn a_sweep_run_two_at_a_time_gives_the_local_sweeps_tables() {
    // Two variants × one seed, once one after another in this process and once two at a time as
    // child processes with a thread each: the same runs, bit for bit (the tables and each run's
    // metrics, times aside).
    let tmp = tempfile::tempdir().unwrap();
    let data = tmp.path().join("data");
    let cfg = tiny_config(tmp.path(), &data, "");
    let text = std::fs::read_to_string(&cfg).unwrap().replace("[train]\n", "[train]\nepochs = 1\n");
    std::fs::write(&cfg, text).unwrap();
    let sweep = |name: &str| {
        let path = tmp.path().join(format!("{name}.toml"));
        let runs = tmp.path().join("runs");
        std::fs::write(&path, format!("base = \"cfg.toml\"\nout_dir = \"{}\"\nseeds = [0]\n[[variants]]\nname = \"a\"\n[[variants]]\nname = \"b\"\nset = {{ \"model.cls_weight\" = 10.0 }}\n", runs.display())).unwrap();
        path
    };
    let (local, parallel) = (sweep("local"), sweep("parallel"));
    train_bin(&["sweep", local.to_str().unwrap()]);
    let out = train_bin(&["sweep", parallel.to_str().unwrap(), "--jobs", "2"]);
    assert!(String::from_utf8_lossy(&out.stderr).contains("1 threads"), "{}", String::from_utf8_lossy(&out.stderr));
    let runs = tmp.path().join("runs");
    for v in ["a", "b"] {
        assert!(runs.join(format!("parallel/{v}/seed-0.log")).is_file(), "each run's log beside its folder");
        let metrics = |s: &str| metrics_without_times(&runs.join(format!("{s}/{v}/seed-0")));
        assert_eq!(metrics("local"), metrics("parallel"), "variant {v}");
    }
    let table = |s: &str| results_without_times(&runs.join(s));
    assert_eq!(table("local"), table("parallel"));
    // Submitting again skips the finished runs.
    let again = train_bin(&["sweep", parallel.to_str().unwrap(), "--jobs", "2"]);
    assert!(String::from_utf8_lossy(&again.stderr).matches("finished before, skipped").count() == 2);
}
