//! `[[data.also_train]]`: another tree's training split is trained on beside `data.root`'s, each
//! generated on first use from its own `simulate`, while validation stays on `data.root`; trees
//! with different calibrations are refused, naming the file.

use train::RunConfig;
use train::data::{ensure_dataset, ensure_training_data, eval_loader, train_loader};

#[test]
fn a_second_tree_adds_its_training_frames_and_nothing_to_validation() {
    let tmp = tempfile::tempdir().unwrap();
    let (a, b) = (tmp.path().join("a"), tmp.path().join("b"));
    let text = format!(
        r#"
[model]
kind = "person_minkunet"
[data]
root = "{}"
val_sequences = ["sim-val-*"]
[data.simulate]
sequences = 4
frames = 2
seed = 1
naming = "benchmark"
[[data.also_train]]
root = "{}"
[data.also_train.simulate]
sequences = 5
frames = 3
seed = 2
naming = "places"
"#,
        a.display(),
        b.display()
    );
    let cfg = RunConfig::from_toml_str(&text).unwrap();
    // What infer needs is the root alone; training generates the other tree too.
    ensure_dataset(&cfg.data).unwrap();
    assert!(a.exists() && !b.exists());
    ensure_training_data(&cfg.data).unwrap();
    assert!(b.exists(), "both trees are generated before training");
    // a: 4 sequences, the second a validation one: 3 × 2 training frames. b: 5, one validation
    // (the second): 4 × 3.
    let train = train_loader(&cfg).unwrap();
    assert_eq!(train.dataset().len(), 3 * 2 + 4 * 3);
    let upper = |f: &data_jrdb::dataset::FrameRef| f.cloud_files()[0].to_path_buf();
    assert!(train.dataset().frames.iter().any(|f| upper(f).starts_with(&b)));
    let val = eval_loader(&cfg, cfg.data.val_split).unwrap();
    assert_eq!(val.dataset().len(), 2);
    assert!(val.dataset().frames.iter().all(|f| upper(f).starts_with(&a)));

    // Another calibration cannot be merged by the root's: refused, naming the file.
    let calib = b.join("calibration/defaults.yaml");
    let t = std::fs::read_to_string(&calib).unwrap().replacen("-0.33529", "-0.5", 1);
    std::fs::write(&calib, t).unwrap();
    let Err(err) = train_loader(&cfg) else { panic!("a tree with another calibration was merged") };
    let err = format!("{err:#}");
    assert!(err.contains("defaults.yaml") && err.contains("calibration differs"), "{err}");
}
