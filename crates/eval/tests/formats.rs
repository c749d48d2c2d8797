//! Files in, files out: JRDB JSON → KITTI txt → boxes, the official layout, and every kind of
//! bad input giving an error that names the file (and line and column where there is one).

use std::path::{Path, PathBuf};

use eval::dataset::{Format, detect_format, load, write_kitti_tree};
use eval::jrdb::{Detection, DetectionFile, labels_to_kitti, read_labels_3d, write_detections};
use eval::kitti::{FileKind, KittiObject, read_file};
use eval::{Box3d, EvalError};

struct TempDir(PathBuf);

impl TempDir {
    fn new(name: &str) -> Self {
        let p = std::env::temp_dir().join(format!("eval-formats-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&p);
        std::fs::create_dir_all(&p).unwrap();
        TempDir(p)
    }
}

impl Drop for TempDir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

fn write(p: &Path, text: &str) {
    std::fs::create_dir_all(p.parent().unwrap()).unwrap();
    std::fs::write(p, text).unwrap();
}

const LABELS: &str = r#"{"labels": {
  "000000.pcd": [
    {"label_id": "pedestrian:1", "box": {"cx": 3.5, "cy": -1.25, "cz": 0.1, "l": 0.9, "w": 0.55, "h": 1.7, "rot_z": 4.0},
     "attributes": {"num_points": 120, "occlusion": "x"}, "observation_angle": 0.25, "file_id": "a"},
    {"label_id": "car:2", "box": {"cx": 1, "cy": 1, "cz": 0, "l": 4, "w": 2, "h": 1.5, "rot_z": 0},
     "attributes": {"num_points": 500}, "observation_angle": 0},
    {"label_id": "pedestrian:3", "box": {"cx": -7.0, "cy": 2.0, "cz": -0.2, "l": 0.6, "w": 0.5, "h": 1.6, "rot_z": -0.5},
     "attributes": {"num_points": 8}, "observation_angle": 0}
  ],
  "000001.pcd": []
}}"#;

#[test]
fn jrdb_json_to_kitti_txt_and_back() {
    let tmp = TempDir::new("roundtrip");
    let gt = tmp.0.join("labels_3d/seq-a.json");
    write(&gt, LABELS);
    let labels = read_labels_3d(&gt).unwrap();
    assert_eq!(labels.keys().collect::<Vec<_>>(), ["000000", "000001"]);
    let lines = labels_to_kitti(&labels["000000"]);
    // The car is dropped, as by the official converter; pedestrians keep their order.
    assert_eq!(lines.len(), 2);
    let k = &lines[0];
    // h_k = h, w_k = l, l_k = w, x = −cy, y = −cz + h/2, z = cx, ry = 2π − rot_z (rot_z ≥ π).
    assert_eq!(
        (k.h, k.w, k.l, k.x, k.y, k.z),
        (1.7, 0.9, 0.55, 1.25, -0.1 + 0.85, 3.5)
    );
    assert_eq!(k.ry, 2.0 * std::f64::consts::PI - 4.0);
    assert_eq!((k.num_points, k.alpha), (120, 0.25));
    assert_eq!(lines[1].ry, 0.5);

    let det_dir = tmp.0.join("dets");
    let dets = DetectionFile {
        sequence: Some("seq-a".into()),
        detections: [
            (
                "000000".to_string(),
                vec![Detection {
                    bbox: labels["000000"][0].bbox,
                    score: 0.875,
                }],
            ),
            ("000001".to_string(), vec![]),
        ]
        .into(),
    };
    write_detections(&det_dir.join("seq-a.json"), &dets).unwrap();
    assert_eq!(
        detect_format(&tmp.0.join("labels_3d")).unwrap(),
        Format::Jrdb
    );
    let frames = load(
        &tmp.0.join("labels_3d"),
        Format::Jrdb,
        &det_dir,
        Format::Jrdb,
        false,
    )
    .unwrap();
    assert_eq!(frames.len(), 2);

    // Write the official tree and read it back: the same lines, bit for bit.
    let out = tmp.0.join("kitti");
    write_kitti_tree(&out.join("gt"), &frames, FileKind::GroundTruth).unwrap();
    write_kitti_tree(&out.join("det"), &frames, FileKind::Detections).unwrap();
    assert_eq!(detect_format(&out.join("gt")).unwrap(), Format::Kitti);
    let back = read_file(&out.join("gt/seq-a/000000.txt"), FileKind::GroundTruth).unwrap();
    assert_eq!(back, frames[0].gt);
    assert_eq!(
        std::fs::read_to_string(out.join("gt/seq-a/000001.txt")).unwrap(),
        ""
    );
    let det_back = read_file(&out.join("det/seq-a/000000.txt"), FileKind::Detections).unwrap();
    assert_eq!(det_back, frames[0].det);
    let again = load(
        &out.join("gt"),
        Format::Kitti,
        &out.join("det"),
        Format::Kitti,
        false,
    )
    .unwrap();
    assert_eq!(again, frames);

    // Boxes survive the trip (rot_z comes back as −ry, the same heading; cz up to rounding).
    let b: Box3d = det_back[0].to_box3d();
    let orig = labels["000000"][0].bbox;
    assert_eq!(
        (b.cx, b.cy, b.l, b.w, b.h),
        (orig.cx, orig.cy, orig.l, orig.w, orig.h)
    );
    assert!((b.cz - orig.cz).abs() < 1e-15);
    assert!(((b.rot_z - orig.rot_z).rem_euclid(2.0 * std::f64::consts::PI)).abs() < 1e-12);
    assert!((eval::iou_3d(&b, &orig) - 1.0).abs() < 1e-12);
}

#[test]
fn a_missing_detection_file_is_an_error_naming_it_unless_allowed() {
    let tmp = TempDir::new("missing");
    write(
        &tmp.0.join("gt/s1/000000.txt"),
        "Pedestrian 0 0 50 0 0 0 0 0 1.7 0.9 0.5 1 0.85 5 0 1\n",
    );
    write(&tmp.0.join("gt/s1/000001.txt"), "");
    write(
        &tmp.0.join("det/s1/000000.txt"),
        "Pedestrian 0 0 -1 0 -1 -1 -1 -1 1.7 0.9 0.5 1 0.85 5 0 0.9\n",
    );
    let e = load(
        &tmp.0.join("gt"),
        Format::Kitti,
        &tmp.0.join("det"),
        Format::Kitti,
        false,
    )
    .unwrap_err();
    assert!(matches!(e, EvalError::MissingDetections { .. }));
    let msg = e.to_string();
    assert!(
        msg.contains("gt/s1/000001.txt") && msg.contains("det/s1/000001.txt"),
        "{msg}"
    );
    let frames = load(
        &tmp.0.join("gt"),
        Format::Kitti,
        &tmp.0.join("det"),
        Format::Kitti,
        true,
    )
    .unwrap();
    assert_eq!(frames.len(), 2);
    assert!(frames[1].det.is_empty());

    // JSON: a missing sequence file and a missing frame key.
    write(&tmp.0.join("lab/s1.json"), LABELS);
    let e = load(
        &tmp.0.join("lab"),
        Format::Jrdb,
        &tmp.0.join("dj"),
        Format::Jrdb,
        false,
    )
    .unwrap_err();
    assert!(e.to_string().contains("dj/s1.json"), "{e}");
    write(
        &tmp.0.join("dj/s1.json"),
        r#"{"detections": {"000000": []}}"#,
    );
    let e = load(
        &tmp.0.join("lab"),
        Format::Jrdb,
        &tmp.0.join("dj"),
        Format::Jrdb,
        false,
    )
    .unwrap_err();
    assert!(e.to_string().contains("frame \"000001\""), "{e}");
    assert!(
        load(
            &tmp.0.join("lab"),
            Format::Jrdb,
            &tmp.0.join("dj"),
            Format::Jrdb,
            true
        )
        .is_ok()
    );
    // A "sequence" field that contradicts the file name.
    write(
        &tmp.0.join("dj/s1.json"),
        r#"{"sequence": "other", "detections": {}}"#,
    );
    let e = load(
        &tmp.0.join("lab"),
        Format::Jrdb,
        &tmp.0.join("dj"),
        Format::Jrdb,
        true,
    )
    .unwrap_err();
    assert!(e.to_string().contains("`other`"), "{e}");
}

#[test]
fn malformed_files_name_file_line_and_column() {
    let tmp = TempDir::new("malformed");
    let ok = "Pedestrian 0 0 50 0 0 0 0 0 1.7 0.9 0.5 1 0.85 5 0 1\n";
    let cases: [(&str, &str, usize, usize); 5] = [
        (
            "Pedestrian 0 0 50 0 0 0 0 0 1.7 0.9 0.5 1 0.85 5 0\n",
            "expected 17",
            2,
            17,
        ),
        (
            "Pedestrian 0 0 50 0 0 0 0 0 1.7 0.9 0.5 1 0.85 5 0 1 7\n",
            "found 18",
            2,
            18,
        ),
        (
            "Pedestrian 0 0 fifty 0 0 0 0 0 1.7 0.9 0.5 1 0.85 5 0 1\n",
            "num_points: expected an integer",
            2,
            4,
        ),
        (
            "Pedestrian 0 0 50 0 0 0 0 0 1.7 0.9 0.5 1 0.85 5 nan? 1\n",
            "ry: expected a number",
            2,
            16,
        ),
        (
            "Pedestrian 0 0 50 0 0 0 0 0 -1.7 0.9 0.5 1 0.85 5 0 1\n",
            "h: a box size must not be negative",
            2,
            10,
        ),
    ];
    for (i, (bad, what, line, column)) in cases.iter().enumerate() {
        let gt = tmp.0.join(format!("gt{i}"));
        write(&gt.join("s/000000.txt"), &format!("{ok}{bad}"));
        let e = load(&gt, Format::Kitti, &tmp.0.join("none"), Format::Kitti, true).unwrap_err();
        match &e {
            EvalError::Parse {
                path,
                line: l,
                column: c,
                message,
            } => {
                assert!(path.ends_with("s/000000.txt"));
                assert_eq!((*l, *c), (*line, *column), "{e}");
                assert!(message.contains(what), "{e}");
            }
            other => panic!("unexpected error {other}"),
        }
    }
    // A detection score that is not a number.
    let gt = tmp.0.join("gtd");
    write(&gt.join("s/000000.txt"), ok);
    write(
        &tmp.0.join("det/s/000000.txt"),
        "\n\nPedestrian 0 0 -1 0 -1 -1 -1 -1 1.7 0.9 0.5 1 0.85 5 0 high\n",
    );
    let e = load(&gt, Format::Kitti, &tmp.0.join("det"), Format::Kitti, false)
        .unwrap_err()
        .to_string();
    assert!(
        e.ends_with("det/s/000000.txt:3: column 17: score: expected a number, found `high`"),
        "{e}"
    );
    // A label that is not what JRDB writes.
    write(
        &tmp.0.join("lab/s.json"),
        "{\"labels\": {\n \"000000.pcd\": [{\"label_id\": 3}]}}",
    );
    let e = load(
        &tmp.0.join("lab"),
        Format::Jrdb,
        &tmp.0.join("x"),
        Format::Jrdb,
        true,
    )
    .unwrap_err();
    // A label of the wrong shape names the file and the key (data-jrdb's reader, as training's).
    assert!(matches!(e, EvalError::Data(_)), "{e}");
    assert!(e.to_string().contains("lab/s.json") && e.to_string().contains("label_id"), "{e}");
    // A missing folder, and a folder of neither format.
    let e = load(
        &tmp.0.join("nowhere"),
        Format::Kitti,
        &tmp.0.join("x"),
        Format::Kitti,
        true,
    )
    .unwrap_err();
    assert!(e.to_string().contains("nowhere"), "{e}");
    std::fs::create_dir_all(tmp.0.join("empty")).unwrap();
    assert!(
        detect_format(&tmp.0.join("empty"))
            .unwrap_err()
            .to_string()
            .contains("--format")
    );
}

#[test]
fn cli_writes_json_csv_and_png() {
    let tmp = TempDir::new("cli");
    write(&tmp.0.join("lab/s1.json"), LABELS);
    write(
        &tmp.0.join("dj/s1.json"),
        r#"{"detections": {"000000.pcd": [{"box": {"cx": 3.5, "cy": -1.25, "cz": 0.1, "l": 0.9, "w": 0.55, "h": 1.7, "rot_z": 4.0}, "score": 0.5}], "000001": []}}"#,
    );
    let csv = tmp.0.join("pr.csv");
    let png = tmp.0.join("pr.png");
    let kitti = tmp.0.join("k");
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_eval"))
        .args([
            "--gt",
            tmp.0.join("lab").to_str().unwrap(),
            "--det",
            tmp.0.join("dj").to_str().unwrap(),
            "--json",
        ])
        .args([
            "--pr-csv",
            csv.to_str().unwrap(),
            "--plot",
            png.to_str().unwrap(),
        ])
        .args(["--write-kitti-det", kitti.to_str().unwrap()])
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    // One valid GT (120 points); the 8-point one is ignored; the car is not a pedestrian line.
    assert_eq!(v["num_gt"], 1);
    assert_eq!(v["num_ignored_gt"], 1);
    assert_eq!(v["num_det"], 1);
    // n = 1 ⇒ AP 0 by the official slot-0 rule, even though the detection is perfect.
    assert_eq!(v["ap3d"]["0.3"], 0.0);
    assert!(v["per_sequence"]["s1"]["ap3d_0.3"].is_number());
    let text = std::fs::read_to_string(&csv).unwrap();
    assert!(text.starts_with("metric,iou,sequence,slot,score_threshold"));
    assert!(
        text.contains("ap3d,0.3,overall,0,0.5,1,0,0,1,1,1"),
        "{text}"
    );
    assert_eq!(&std::fs::read(&png).unwrap()[1..4], b"PNG");
    assert!(kitti.join("s1/000000.txt").is_file());

    // The table, and a failure with a clear message.
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_eval"))
        .args([
            "--gt",
            tmp.0.join("lab").to_str().unwrap(),
            "--det",
            tmp.0.join("nodets").to_str().unwrap(),
            "--format",
            "jrdb",
        ])
        .output()
        .unwrap();
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("nodets/s1.json"));
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_eval"))
        .args([
            "--gt",
            tmp.0.join("lab").to_str().unwrap(),
            "--det",
            tmp.0.join("dj").to_str().unwrap(),
        ])
        .output()
        .unwrap();
    let table = String::from_utf8_lossy(&out.stdout);
    assert!(
        table.contains("AP3D")
            && table.contains("not an official JRDB metric")
            && table.contains("s1"),
        "{table}"
    );
}

#[test]
fn a_folder_of_txt_files_is_one_unnamed_sequence_as_detect_writes_it() {
    // `train detect scans/ --out OUT` writes OUT/kitti/<name>.txt for plain files.
    let tmp = TempDir::new("flat");
    let person = Box3d { cx: 4.0, cy: -1.0, cz: -0.1, l: 0.6, w: 0.5, h: 1.7, rot_z: 0.3 };
    let gt = KittiObject::ground_truth(&person, 120, -1.0).to_line(FileKind::GroundTruth) + "\n";
    let det = KittiObject::from_box3d(&person, -1, 0.9).to_line(FileKind::Detections) + "\n";
    let (gt, det) = (gt.as_str(), det.as_str());
    write(&tmp.0.join("gt/scan_a.txt"), gt);
    write(&tmp.0.join("gt/scan_b.txt"), gt);
    write(&tmp.0.join("det/kitti/scan_a.txt"), det);
    write(&tmp.0.join("det/kitti/scan_b.txt"), det);
    let (g, d) = (tmp.0.join("gt"), tmp.0.join("det/kitti"));
    assert_eq!((detect_format(&g).unwrap(), detect_format(&d).unwrap()), (Format::Kitti, Format::Kitti));
    let frames = load(&g, Format::Kitti, &d, Format::Kitti, false).unwrap();
    let names: Vec<(&str, &str, usize, usize)> = frames.iter().map(|f| (f.sequence.as_str(), f.name.as_str(), f.gt.len(), f.det.len())).collect();
    assert_eq!(names, vec![("", "scan_a", 1, 1), ("", "scan_b", 1, 1)]);
    // A missing one is named where it was expected.
    std::fs::remove_file(tmp.0.join("det/kitti/scan_b.txt")).unwrap();
    let e = load(&g, Format::Kitti, &d, Format::Kitti, false).unwrap_err().to_string();
    assert!(e.contains("det/kitti/scan_b.txt"), "{e}");
    // The documented command: the CLI scores them (two people found exactly: with one, the
    // official slot-0 rule gives AP 0).
    write(&tmp.0.join("det/kitti/scan_b.txt"), &(KittiObject::from_box3d(&person, -1, 0.8).to_line(FileKind::Detections) + "\n"));
    let score = |g: &Path, d: &Path| -> serde_json::Value {
        let out = std::process::Command::new(env!("CARGO_BIN_EXE_eval")).args(["--gt", g.to_str().unwrap(), "--det", d.to_str().unwrap(), "--json"]).output().unwrap();
        assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
        serde_json::from_slice(&out.stdout).unwrap()
    };
    let flat = score(&g, &d);
    assert_eq!((flat["num_gt"].as_u64(), flat["num_det"].as_u64(), flat["num_frames"].as_u64()), (Some(2), Some(2), Some(2)), "{flat}");
    // The same files as one named sequence score the same.
    for (from, to) in [(&g, tmp.0.join("gt_seq/s")), (&d, tmp.0.join("det_seq/s"))] {
        std::fs::create_dir_all(&to).unwrap();
        for f in ["scan_a.txt", "scan_b.txt"] {
            std::fs::copy(from.join(f), to.join(f)).unwrap();
        }
    }
    let nested = score(&tmp.0.join("gt_seq"), &tmp.0.join("det_seq"));
    assert_eq!((flat["ap3d"].clone(), flat["apbev"].clone()), (nested["ap3d"].clone(), nested["apbev"].clone()));
}
