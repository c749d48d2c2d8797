//! KITTI object and nuScenes-style datasets: a simulated JRDB tree exported to each layout reads
//! back as the same frames, points and boxes; the splits agree; bad files are named.

use std::path::Path;

use data_jrdb::export::export;
use data_jrdb::sim::{SynthConfig, synth};
use data_jrdb::{Box3d, Dataset, DatasetConfig, DatasetFormat, ErrorKind, KittiOptions, NuscenesOptions, Split};

const VAL: &str = "clark-center-2019-02-28_1";

fn open(root: &Path, format: DatasetFormat, split: Split) -> Dataset {
    let cfg = DatasetConfig {
        format,
        split,
        kitti: KittiOptions { camera_view_only: false, ..Default::default() },
        nuscenes: NuscenesOptions { val_scenes: Some(vec![VAL.into()]), ..Default::default() },
        val_sequences: vec![VAL.into()],
        ..Default::default()
    };
    Dataset::open(root, &cfg).unwrap_or_else(|e| panic!("{format}: {e}"))
}

fn close_box(a: &Box3d, b: &Box3d) -> bool {
    let d = [a.cx - b.cx, a.cy - b.cy, a.cz - b.cz, a.l - b.l, a.w - b.w, a.h - b.h];
    let turn = (a.rot_z - b.rot_z + std::f64::consts::PI).rem_euclid(2.0 * std::f64::consts::PI) - std::f64::consts::PI;
    d.iter().all(|v| v.abs() < 2e-5) && turn.abs() < 2e-5
}

#[test]
fn an_exported_tree_reads_back_as_the_same_frames() {
    let tmp = tempfile::tempdir().unwrap();
    let jrdb = tmp.path().join("jrdb");
    synth(&jrdb, &SynthConfig { sequences: 4, frames: 2, seed: 5, ..Default::default() }).unwrap();
    for (to, dir) in [(DatasetFormat::Kitti, "kitti"), (DatasetFormat::Nuscenes, "nuscenes")] {
        let out = tmp.path().join(dir);
        let s = export(&open(&jrdb, DatasetFormat::Jrdb, Split::TrainVal), to, &out, &[VAL.into()]).unwrap();
        assert_eq!((s.frames, s.val_frames), (8, 2), "{to}");
        for split in [Split::Train, Split::Val, Split::TrainVal] {
            let (a, b) = (open(&jrdb, DatasetFormat::Jrdb, split), open(&out, to, split));
            assert_eq!(a.len(), b.len(), "{to} {split:?}");
            for i in 0..a.len() {
                let (fa, fb) = (a.load(i).unwrap(), b.load(i).unwrap());
                assert_eq!(fa.points.len(), fb.points.len(), "{to} frame {i}");
                let worst = fa.points.iter().zip(&fb.points).map(|(p, q)| (0..3).map(|k| (p[k] - q[k]).abs()).fold(0.0f32, f32::max)).fold(0.0, f32::max);
                assert!(worst < 1e-5, "{to} frame {i}: points {worst} m apart");
                assert_eq!(fa.boxes.len(), fb.boxes.len(), "{to} frame {i}");
                for (x, y) in fa.boxes.iter().zip(&fb.boxes) {
                    assert!(close_box(x, y), "{to} frame {i}:\n{x:?}\n{y:?}");
                }
                assert_eq!(fa.num_points, fb.num_points, "{to} frame {i}");
            }
        }
    }
}

/// Lyft's level-5 release shares nuScenes' schema with three differences: float timestamps,
/// `num_lidar_pts` of −1, and 5-float clouds named `.bin`. An export rewritten that way reads the
/// same, the points counted in the cloud.
#[test]
fn a_lyft_style_release_reads_as_nuscenes() {
    let tmp = tempfile::tempdir().unwrap();
    let jrdb = tmp.path().join("jrdb");
    synth(&jrdb, &SynthConfig { sequences: 2, frames: 2, seed: 4, ..Default::default() }).unwrap();
    let out = tmp.path().join("lyft");
    export(&open(&jrdb, DatasetFormat::Jrdb, Split::TrainVal), DatasetFormat::Nuscenes, &out, &[VAL.into()]).unwrap();
    let tables = out.join("v1.0-export");
    let edit = |name: &str, f: &dyn Fn(&mut serde_json::Value)| {
        let path = tables.join(format!("{name}.json"));
        let mut v: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
        for row in v.as_array_mut().unwrap() {
            f(row);
        }
        std::fs::write(&path, v.to_string()).unwrap();
    };
    let float = |row: &mut serde_json::Value| {
        let t = row["timestamp"].as_i64().unwrap();
        row["timestamp"] = serde_json::json!(t as f64 + 0.8);
    };
    edit("sample", &float);
    edit("ego_pose", &float);
    edit("sample_annotation", &|row| row["num_lidar_pts"] = serde_json::json!(-1));
    edit("sample_data", &|row| {
        let old = row["filename"].as_str().unwrap().to_string();
        let new = old.replace("samples/LIDAR_TOP/", "lidar/").replace(".pcd.bin", ".bin");
        std::fs::create_dir_all(out.join("lidar")).unwrap();
        std::fs::rename(out.join(&old), out.join(&new)).unwrap();
        row["filename"] = serde_json::json!(new);
    });
    let (a, b) = (open(&jrdb, DatasetFormat::Jrdb, Split::TrainVal), open(&out, DatasetFormat::Nuscenes, Split::TrainVal));
    assert_eq!(a.len(), b.len());
    for i in 0..a.len() {
        let (fa, fb) = (a.load(i).unwrap(), b.load(i).unwrap());
        assert_eq!(fa.points.len(), fb.points.len(), "frame {i}");
        assert_eq!(fa.num_points, fb.num_points, "frame {i}: counted in the cloud");
    }
}

#[test]
fn kitti_keeps_the_cameras_view_and_ignores_cyclists() {
    let tmp = tempfile::tempdir().unwrap();
    let jrdb = tmp.path().join("jrdb");
    synth(&jrdb, &SynthConfig { sequences: 1, frames: 1, seed: 2, ..Default::default() }).unwrap();
    let out = tmp.path().join("kitti");
    export(&open(&jrdb, DatasetFormat::Jrdb, Split::TrainVal), DatasetFormat::Kitti, &out, &[]).unwrap();
    // A cyclist ahead and a car: the first is ignored, the second not a person at all.
    let label = out.join("training/label_2/000000.txt");
    let mut text = std::fs::read_to_string(&label).unwrap();
    text += "Cyclist 0.00 0 -1.57 600 150 650 300 1.70 0.60 1.80 0.0 1.65 9.0 -1.57\nCar 0.00 0 -1.57 500 150 700 300 1.50 1.60 4.00 3.0 1.65 15.0 -1.57\nDontCare -1 -1 -10 503.89 169.71 590.74 190.13 -1 -1 -1 -1000 -1000 -1000 -10\n";
    std::fs::write(&label, text).unwrap();
    let all = open(&out, DatasetFormat::Kitti, Split::TrainVal).load(0).unwrap();
    assert_eq!(all.ignored.len(), 1);
    assert!((all.ignored[0].cx - 9.27).abs() < 0.1, "{:?}", all.ignored[0]);
    let cfg = DatasetConfig { format: DatasetFormat::Kitti, split: Split::TrainVal, ..Default::default() };
    let view = Dataset::open(&out, &cfg).unwrap().load(0).unwrap();
    assert!(view.points.len() < all.points.len() / 3, "{} of {} points in the camera's view", view.points.len(), all.points.len());
    assert!(view.points.iter().all(|p| p[0] > 0.0), "only points ahead");
    assert_eq!(view.boxes.len(), all.boxes.len(), "the labels are kept; points outside the view are not");
}

#[test]
fn bad_files_are_named() {
    let tmp = tempfile::tempdir().unwrap();
    let jrdb = tmp.path().join("jrdb");
    synth(&jrdb, &SynthConfig { sequences: 1, frames: 1, seed: 2, ..Default::default() }).unwrap();
    let (kitti, nus) = (tmp.path().join("kitti"), tmp.path().join("nus"));
    let ds = open(&jrdb, DatasetFormat::Jrdb, Split::TrainVal);
    export(&ds, DatasetFormat::Kitti, &kitti, &[]).unwrap();
    export(&ds, DatasetFormat::Nuscenes, &nus, &[]).unwrap();
    let err = |root: &Path, format| Dataset::open(root, &DatasetConfig { format, split: Split::TrainVal, nuscenes: NuscenesOptions { val_scenes: Some(vec![]), ..Default::default() }, ..Default::default() }).unwrap_err();

    std::fs::write(kitti.join("training/calib/000000.txt"), "P2: 1 2 3\n").unwrap();
    let e = err(&kitti, DatasetFormat::Kitti);
    assert!(e.path.ends_with("training/calib/000000.txt") && e.to_string().contains("P2"), "{e}");

    std::fs::remove_dir_all(kitti.join("ImageSets")).unwrap();
    let e = Dataset::open(&kitti, &DatasetConfig { format: DatasetFormat::Kitti, split: Split::Val, ..Default::default() }).unwrap_err();
    assert!(e.path.ends_with("ImageSets/val.txt"), "{e}");

    let table = nus.join("v1.0-export/sample_annotation.json");
    std::fs::write(&table, "[{\"token\": 1}]").unwrap();
    let e = err(&nus, DatasetFormat::Nuscenes);
    assert!(e.path == table && matches!(e.kind, ErrorKind::Parse(_)), "{e}");

    let e = Dataset::open(&jrdb, &DatasetConfig { format: DatasetFormat::Nuscenes, ..Default::default() }).unwrap_err();
    assert!(e.to_string().contains("sample.json"), "{e}");
}
