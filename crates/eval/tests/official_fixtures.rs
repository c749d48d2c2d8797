//! Our evaluator against numbers printed by the official JRDB tool on the same files.
//!
//! Each `tests/fixtures/seed*/` holds a case from `generate.py` and the official tool's output
//! (`official_{kitti,json}_t{0,1,2}.txt`: one line per evaluation, `name,AP,prec_0,…,prec_40`;
//! see the README there). `kitti` pairs `gt/` + `det/` (all classes, DontCare, other-class
//! detections); `json` pairs `gt_json/` + `det_json/`, whose official numbers were computed on
//! the official converter's output of the same JSON.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use eval::Report;
use eval::ap::{IOU_THRESHOLDS, Overlap, Protocol, evaluate};
use eval::dataset::{Format, load};

const TOL: f64 = 1e-9;

fn fixtures() -> Vec<PathBuf> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures");
    let mut v: Vec<PathBuf> = std::fs::read_dir(&root)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.is_dir() && p.file_name().unwrap().to_string_lossy().starts_with("seed"))
        .collect();
    v.sort();
    assert!(v.len() >= 4, "fixtures missing in {}", root.display());
    v
}

/// name → (AP, 41 precision slots), as the official tool wrote them.
fn official(path: &Path) -> BTreeMap<String, (f64, Vec<f64>)> {
    std::fs::read_to_string(path)
        .unwrap()
        .lines()
        .map(|l| {
            let mut it = l.split(',');
            let name = it.next().unwrap().to_string();
            let nums: Vec<f64> = it.map(|x| x.parse().unwrap()).collect();
            (name, (nums[0], nums[1..].to_vec()))
        })
        .collect()
}

fn check(dir: &Path, gt: &str, det: &str, format: Format, tag: &str) -> usize {
    let frames = load(&dir.join(gt), format, &dir.join(det), format, false).unwrap();
    let report = Report::compute(&frames, &Protocol::official());
    let mut checked = 0;
    for (t, thr) in IOU_THRESHOLDS.iter().enumerate() {
        let off = official(&dir.join(format!("official_{tag}_t{t}.txt")));
        let (ap, prec) = &off["overall"];
        let ours = &report.ap3d[t];
        assert!(
            (ours.ap - ap).abs() < TOL,
            "{} {tag} IoU {thr}: ours {} official {ap}",
            dir.display(),
            ours.ap
        );
        assert_eq!(prec.len(), 41);
        for (k, (a, b)) in ours.precision.iter().zip(prec).enumerate() {
            assert!(
                (a - b).abs() < TOL,
                "{} {tag} IoU {thr} slot {k}: ours {a} official {b}",
                dir.display()
            );
        }
        for (seq, (ap, _)) in off.iter().filter(|(k, _)| *k != "overall") {
            let ours = report.per_sequence[seq][t].ap;
            assert!(
                (ours - ap).abs() < TOL,
                "{} {tag} {seq} IoU {thr}: ours {ours} official {ap}",
                dir.display()
            );
            checked += 1;
        }
        assert_eq!(report.per_sequence.len(), off.len() - 1);
        checked += 1;
    }
    checked
}

#[test]
fn kitti_files_give_the_official_numbers() {
    let n: usize = fixtures()
        .iter()
        .map(|d| check(d, "gt", "det", Format::Kitti, "kitti"))
        .sum();
    assert!(n >= 30, "only {n} numbers checked");
}

#[test]
fn jrdb_json_gives_the_official_numbers_of_the_converted_files() {
    let n: usize = fixtures()
        .iter()
        .map(|d| check(d, "gt_json", "det_json", Format::Jrdb, "json"))
        .sum();
    assert!(n >= 30, "only {n} numbers checked");
}

#[test]
fn fixtures_are_not_trivial() {
    // The cases must exercise the protocol: non-zero APs that differ between thresholds,
    // ignored and dropped GT, ignored and other-class detections.
    for d in fixtures() {
        let frames = load(
            &d.join("gt"),
            Format::Kitti,
            &d.join("det"),
            Format::Kitti,
            false,
        )
        .unwrap();
        let c = evaluate(&frames, 0.3, Overlap::Box3d, &Protocol::official());
        assert!(c.ap > 0.05, "{}", d.display());
        assert!(
            c.counts.ignored_gt > 0 && c.counts.dropped_gt > 0 && c.counts.ignored_det > 0,
            "{:?}",
            c.counts
        );
        let c7 = evaluate(&frames, 0.7, Overlap::Box3d, &Protocol::official());
        assert!(c7.ap < c.ap);
    }
}

#[test]
fn the_cli_prints_the_official_number() {
    let d = &fixtures()[0];
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_eval"))
        .args([
            "--gt",
            d.join("gt").to_str().unwrap(),
            "--det",
            d.join("det").to_str().unwrap(),
            "--json",
        ])
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    for (t, key) in ["0.3", "0.5", "0.7"].iter().enumerate() {
        let off = official(&d.join(format!("official_kitti_t{t}.txt")));
        let ours = v["ap3d"][key].as_f64().unwrap();
        assert!((ours - off["overall"].0).abs() < TOL);
        for (seq, (ap, _)) in off.iter().filter(|(k, _)| *k != "overall") {
            assert!(
                (v["per_sequence"][seq][format!("ap3d_{key}")]
                    .as_f64()
                    .unwrap()
                    - ap)
                    .abs()
                    < TOL
            );
        }
        assert!(v["apbev"][key].as_f64().is_some());
    }
    for k in ["num_gt", "num_ignored_gt", "num_det"] {
        assert!(v[k].as_u64().is_some(), "{k}");
    }
}
