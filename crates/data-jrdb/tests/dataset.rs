//! Simulator → reader round trips, determinism, the layout variants and every malformed tree.

use std::path::{Path, PathBuf};
use std::process::Command;

use data_jrdb::calibration::Lidar;
use data_jrdb::sim::{SynthConfig, synth};
use data_jrdb::{DatasetConfig, ErrorKind, Dataset, OnBadFrame, Split};

fn tmp(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("jrdb-test-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    d
}

fn small(seed: u64) -> SynthConfig {
    SynthConfig { sequences: 2, frames: 3, seed, max_people: 12, ..Default::default() }
}

fn all() -> DatasetConfig {
    DatasetConfig { split: Split::TrainVal, ..Default::default() }
}

fn files(root: &Path) -> Vec<(PathBuf, Vec<u8>)> {
    let mut out = Vec::new();
    let mut stack = vec![root.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                stack.push(p);
            } else {
                out.push((p.strip_prefix(root).unwrap().to_path_buf(), std::fs::read(&p).unwrap()));
            }
        }
    }
    out.sort();
    out
}

#[test]
fn simulated_tree_reads_back_with_exact_num_points() {
    let root = tmp("roundtrip");
    let s = synth(&root, &small(7)).unwrap();
    let ds = Dataset::open(&root, &all()).unwrap();
    assert_eq!(ds.len(), 6);
    assert_eq!(ds.sequences, {
        let mut v = s.sequences.clone();
        v.sort();
        v
    });
    let (mut points, mut boxes) = (0, 0);
    for i in 0..ds.len() {
        let f = ds.load(i).unwrap();
        assert!(f.n_upper > 15_000 && f.points.len() - f.n_upper > 15_000, "{} points", f.points.len());
        assert_eq!(f.dropped_non_finite, 0);
        for (b, &n) in f.boxes.iter().zip(&f.num_points) {
            assert_eq!(b.count_inside(&f.points) as i64, n, "{}/{}", f.sequence, f.name);
            assert!(b.h > 1.0 && b.h < 2.0 && b.l > 0.1 && b.w > 0.2);
        }
        points += f.points.len();
        boxes += f.boxes.len();
    }
    assert_eq!((points, boxes), (s.points, s.boxes));
    assert!(boxes > 0);
    // Default split: the simulator names one of its two sequences after a JRDB validation sequence.
    let train = Dataset::open(&root, &DatasetConfig::default()).unwrap();
    let val = Dataset::open(&root, &DatasetConfig { split: Split::Val, ..Default::default() }).unwrap();
    assert_eq!((train.len(), val.len()), (3, 3));
    assert_eq!(val.sequences, ["clark-center-2019-02-28_1"]);
}

#[test]
fn same_seed_same_tree_other_seed_other_tree() {
    let (a, b, c) = (tmp("det-a"), tmp("det-b"), tmp("det-c"));
    let cfg = SynthConfig { sequences: 1, frames: 2, max_people: 8, ..small(11) };
    synth(&a, &cfg).unwrap();
    synth(&b, &cfg).unwrap();
    synth(&c, &SynthConfig { seed: 12, ..cfg }).unwrap();
    let (fa, fb, fc) = (files(&a), files(&b), files(&c));
    assert_eq!(fa, fb);
    assert_eq!(fa.len(), fc.len());
    assert_ne!(fa, fc);
}

#[test]
fn encodings_and_the_with_activity_folder_read_the_same() {
    let base = tmp("enc");
    let mut loaded = Vec::new();
    for enc in [data_jrdb::Encoding::Ascii, data_jrdb::Encoding::Binary, data_jrdb::Encoding::BinaryCompressed] {
        let root = base.join(enc.keyword()).join("train_dataset_with_activity");
        synth(&root, &SynthConfig { sequences: 1, frames: 1, max_people: 5, encoding: enc, ..small(3) }).unwrap();
        let ds = Dataset::open(root.parent().unwrap(), &all()).unwrap();
        loaded.push(ds.load(0).unwrap());
    }
    assert_eq!(loaded[0], loaded[1]);
    assert_eq!(loaded[1], loaded[2]);
}

fn expect_err(root: &Path, cfg: &DatasetConfig, names: &str) -> data_jrdb::DataError {
    let e = Dataset::open(root, cfg).expect_err("should fail");
    assert!(e.to_string().contains(names), "`{e}` should name {names}");
    e
}

#[test]
fn malformed_trees_are_errors_naming_the_file() {
    let root = tmp("bad");
    let s = synth(&root, &small(5)).unwrap();
    let seq = s.sequences[0].clone();
    let labels = root.join("labels/labels_3d").join(format!("{seq}.json"));
    let good = std::fs::read_to_string(&labels).unwrap();

    std::fs::write(&labels, &good[..good.len() / 2]).unwrap();
    let e = expect_err(&root, &all(), &format!("{seq}.json"));
    assert!(matches!(e.kind, ErrorKind::Parse(_)));
    std::fs::write(&labels, good.replacen("\"rot_z\"", "\"rot_y\"", 1)).unwrap();
    let e = expect_err(&root, &all(), &format!("{seq}.json"));
    assert!(matches!(&e.kind, ErrorKind::Key { key, .. } if key.ends_with(".box.rot_z")), "{e}");
    std::fs::write(&labels, good.replacen("\"num_points\":", "\"num_points\":\"x\",\"n\":", 1)).unwrap();
    expect_err(&root, &all(), "num_points");
    std::fs::write(&labels, "{\"frames\": {}}").unwrap();
    expect_err(&root, &all(), "`labels`");
    // Skipping a sequence with bad labels keeps the others.
    let ds = Dataset::open(&root, &DatasetConfig { on_bad_frame: OnBadFrame::Skip, ..all() }).unwrap();
    assert_eq!(ds.len(), 3);
    std::fs::remove_file(&labels).unwrap();
    expect_err(&root, &all(), &format!("{seq}.json"));
    let ds = Dataset::open(&root, &DatasetConfig { require_labels: false, ..all() }).unwrap();
    assert_eq!(ds.len(), 6);
    std::fs::write(&labels, &good).unwrap();

    // Missing sequence folders.
    let cfg = DatasetConfig { sequences: Some(vec!["nowhere-2019_0".into()]), ..all() };
    expect_err(&root, &cfg, "nowhere-2019_0");
    let lower = root.join("pointclouds/lower_velodyne").join(&seq);
    let moved = root.join("moved");
    std::fs::rename(&lower, &moved).unwrap();
    expect_err(&root, &all(), &format!("lower_velodyne/{seq}"));
    std::fs::rename(&moved, &lower).unwrap();

    // An upper cloud without its lower twin.
    std::fs::remove_file(lower.join("000001.pcd")).unwrap();
    let e = expect_err(&root, &all(), &format!("upper_velodyne/{seq}/000001.pcd"));
    assert!(e.to_string().contains("lower twin"));
    let ds = Dataset::open(&root, &DatasetConfig { on_bad_frame: OnBadFrame::Skip, ..all() }).unwrap();
    assert_eq!(ds.len(), 5);

    // Calibration.
    let calib = root.join("calibration/defaults.yaml");
    let text = std::fs::read_to_string(&calib).unwrap();
    std::fs::write(&calib, text.replace("lidar_lower_to_rgb", "lidar_lower")).unwrap();
    expect_err(&root, &all(), "defaults.yaml");
    assert!(text.contains("translation: [0, 0, 0.13511]"));
    std::fs::write(&calib, text.replace("translation: [0, 0, 0.13511]", "translation: [0, 0]")).unwrap();
    let e = expect_err(&root, &all(), "defaults.yaml");
    assert!(e.to_string().contains("calibrated.lidar_lower_to_rgb.translation"), "{e}");
    std::fs::write(&calib, "calibrated: [unclosed").unwrap();
    expect_err(&root, &all(), "defaults.yaml");

    // Not a JRDB tree at all.
    expect_err(&root.join("pointclouds"), &all(), "pointclouds");
}

#[test]
fn stats_cli_prints_json_and_fails_on_a_bad_file() {
    let root = tmp("cli");
    let s = synth(&root, &small(9)).unwrap();
    let exe = env!("CARGO_BIN_EXE_data-jrdb");
    let out = Command::new(exe).args(["stats", "--json", "--root"]).arg(&root).output().unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["frames"], 6);
    assert_eq!(v["points"], s.points);
    assert_eq!(v["boxes"], s.boxes);
    for seq in &s.sequences {
        assert_eq!(v["sequences"][seq]["frames"], 3);
        assert!(v["sequences"][seq]["points"].as_u64().unwrap() > 0);
        assert!(v["sequences"][seq]["boxes"].is_u64());
    }
    let text = Command::new(exe).args(["stats", "--root"]).arg(&root).output().unwrap();
    assert!(String::from_utf8_lossy(&text.stdout).contains("points per box"));

    let bad = root.join("pointclouds").join(Lidar::Lower.folder()).join(&s.sequences[1]).join("000002.pcd");
    let bytes = std::fs::read(&bad).unwrap();
    std::fs::write(&bad, &bytes[..bytes.len() - 100]).unwrap();
    let out = Command::new(exe).args(["stats", "--json", "--root"]).arg(&root).output().unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("000002.pcd") && err.contains("truncated"), "{err}");
}
