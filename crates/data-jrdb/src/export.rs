//! A dataset written out in KITTI object's or nuScenes' layout: the same frames and boxes, so a
//! tree (a simulated one, say) can be read back in the other layout and score the same.
//!
//! The frames are written in the base frame's geometry moved into each layout's sensor frame
//! (KITTI's Velodyne 1.73 m above the road; nuScenes' LIDAR_TOP at its real mounting, ego poses
//! along a drive), so reading them back exercises every transform the readers apply.

use std::io::Write;
use std::path::Path;

use crate::dataset::{Dataset, DatasetFormat};
use crate::error::{DataError, ErrorKind, Result};
use crate::kitti::{self, BASE_FLOOR_DEPTH, KittiCalib, KittiOptions};
use crate::nuscenes::{TablesWriter, WrittenBox};
use crate::rigid::Rigid;
use crate::split::is_listed;

/// The nuScenes tables' folder an export writes (not an official release, so its validation
/// scenes are named in `data.nuscenes.val_scenes`).
pub const NUSCENES_EXPORT_VERSION: &str = "v1.0-export";

/// What was written.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ExportSummary {
    /// Frames written.
    pub frames: usize,
    /// People boxes written.
    pub boxes: usize,
    /// Of the frames, those in the validation list.
    pub val_frames: usize,
}

/// KITTI object frame 000000's calibration: the export's every frame uses it, so boxes pass
/// through a real (slightly non-orthonormal) camera extrinsic.
pub fn kitti_calibration() -> KittiCalib {
    KittiCalib {
        p2: [721.5377, 0.0, 609.5593, 44.85728, 0.0, 721.5377, 172.854, 0.2163791, 0.0, 0.0, 1.0, 0.002745884],
        r0_rect: Rigid { rotation: [[0.9999239, 0.00983776, -0.007445048], [-0.009869795, 0.9999421, -0.004278459], [0.007402527, 0.004351614, 0.9999631]], translation: [0.0; 3] },
        velo_to_cam: Rigid::from_matrix_3x4(&[0.007533745, -0.9999714, -0.000616602, -0.004069766, 0.01480249, 0.0007280733, -0.9998902, -0.07631618, 0.9998621, 0.00752379, 0.01480755, -0.2717806]),
    }
}

/// nuScenes' LIDAR_TOP mounting on its cars (scene-0061's `calibrated_sensor`): x to the right,
/// y forward, 1.84 m above the ground.
pub fn nuscenes_lidar() -> Rigid {
    Rigid::from_quaternion([0.7077955119163518, -0.006492242056004365, 0.010646214713995808, -0.7063073142877817], [0.943713, 0.0, 1.84023])
}

fn mkdir(p: &Path) -> Result<()> {
    std::fs::create_dir_all(p).map_err(|e| DataError::io(p, e))
}

fn write_floats(path: &Path, points: &[[f32; 3]], extra: usize) -> Result<()> {
    let mut bytes = Vec::with_capacity(points.len() * 4 * (3 + extra));
    for p in points {
        for v in p.iter().copied().chain(std::iter::repeat_n(0.0f32, extra)) {
            bytes.extend_from_slice(&v.to_le_bytes());
        }
    }
    std::fs::write(path, bytes).map_err(|e| DataError::io(path, e))
}

/// Writes every frame of `ds` to `out` in `format`; frames of sequences in `val` (`*` matches by
/// prefix) form the validation split (KITTI's `ImageSets/val.txt`; nuScenes' scenes keep their
/// names).
pub fn export(ds: &Dataset, format: DatasetFormat, out: &Path, val: &[String]) -> Result<ExportSummary> {
    if out.exists() && std::fs::read_dir(out).map_err(|e| DataError::io(out, e))?.next().is_some() {
        return Err(DataError::new(out, ErrorKind::Layout("exists and is not empty; export writes into a new folder".into())));
    }
    match format {
        DatasetFormat::Kitti => export_kitti(ds, out, val),
        DatasetFormat::Nuscenes => export_nuscenes(ds, out, val),
        DatasetFormat::Jrdb => Err(DataError::new(out, ErrorKind::Layout("export writes kitti or nuscenes; a JRDB tree is what the simulator writes".into()))),
    }
}

fn export_kitti(ds: &Dataset, out: &Path, val: &[String]) -> Result<ExportSummary> {
    let data = out.join("training");
    for d in ["velodyne", "label_2", "calib"] {
        mkdir(&data.join(d))?;
    }
    mkdir(&out.join("ImageSets"))?;
    let calib = kitti_calibration();
    let calib_text = calib.to_text();
    let base_to_velo = KittiOptions::default().velo_to_base().inverse();
    let (mut train, mut valn) = (String::new(), String::new());
    let mut sources = String::from("kitti_frame,sequence,frame\n");
    let mut summary = ExportSummary { frames: 0, boxes: 0, val_frames: 0 };
    for i in 0..ds.len() {
        let f = ds.load(i)?;
        let name = format!("{i:06}");
        let velo: Vec<[f32; 3]> = f.points.iter().map(|&p| base_to_velo.apply_f32(p)).collect();
        write_floats(&data.join("velodyne").join(format!("{name}.bin")), &velo, 1)?;
        let calib_path = data.join("calib").join(format!("{name}.txt"));
        std::fs::write(&calib_path, &calib_text).map_err(|e| DataError::io(&calib_path, e))?;
        let mut labels = String::new();
        let boxes = f.boxes.iter().map(|b| ("Pedestrian", b)).chain(f.ignored.iter().map(|b| ("Cyclist", b)));
        for (kind, b) in boxes {
            labels += &kitti::label_line(kind, &base_to_velo.apply_box(b), &calib, [1242, 375]);
            labels.push('\n');
        }
        let label_path = data.join("label_2").join(format!("{name}.txt"));
        std::fs::write(&label_path, labels).map_err(|e| DataError::io(&label_path, e))?;
        if is_listed(&f.sequence, val) {
            valn += &format!("{name}\n");
            summary.val_frames += 1;
        } else {
            train += &format!("{name}\n");
        }
        sources += &format!("{name},{},{}\n", f.sequence, f.name);
        summary.frames += 1;
        summary.boxes += f.boxes.len();
    }
    for (file, text) in [("ImageSets/train.txt", &train), ("ImageSets/val.txt", &valn), ("sources.csv", &sources)] {
        let p = out.join(file);
        std::fs::File::create(&p).and_then(|mut h| h.write_all(text.as_bytes())).map_err(|e| DataError::io(&p, e))?;
    }
    Ok(summary)
}

fn export_nuscenes(ds: &Dataset, out: &Path, val: &[String]) -> Result<ExportSummary> {
    let lidar = nuscenes_lidar();
    // base ↔ LIDAR_TOP and base ↔ ego, as the reader defines them.
    let to_base = Rigid { rotation: lidar.rotation, translation: [0.0, 0.0, lidar.translation[2] - BASE_FLOOR_DEPTH] };
    let base_to_lidar = to_base.inverse();
    let base_to_ego = Rigid::translation([lidar.translation[0], lidar.translation[1], BASE_FLOOR_DEPTH]);
    mkdir(&out.join("samples/LIDAR_TOP"))?;
    let mut writer = TablesWriter::new(out, NUSCENES_EXPORT_VERSION, lidar);
    let mut summary = ExportSummary { frames: 0, boxes: 0, val_frames: 0 };
    let mut i = 0;
    while i < ds.len() {
        let sequence = ds.frames[i].sequence.clone();
        let mut frames = Vec::new();
        let mut k = 0usize;
        while i < ds.len() && ds.frames[i].sequence == sequence {
            let f = ds.load(i)?;
            let lidar_points: Vec<[f32; 3]> = f.points.iter().map(|&p| base_to_lidar.apply_f32(p)).collect();
            write_floats(&out.join(TablesWriter::lidar_file(&sequence, k)), &lidar_points, 2)?;
            // A drive: 1 m/s forward along a turning heading, far from the global origin.
            let t = k as f64 * 0.5;
            let ego = Rigid::from_yaw(0.4 + 0.02 * t, [411.3 + 0.9 * t, 1180.6 + 0.4 * t, 0.05]);
            let to_global = ego.then_after(&base_to_ego);
            let mut boxes: Vec<WrittenBox> = Vec::new();
            for (j, b) in f.boxes.iter().enumerate() {
                boxes.push(WrittenBox { category: "human.pedestrian.adult".into(), global: to_global.apply_box(b), num_lidar_pts: f.num_points[j], instance: f.label_ids[j].clone() });
            }
            for (j, b) in f.ignored.iter().enumerate() {
                boxes.push(WrittenBox { category: "human.pedestrian.stroller".into(), global: to_global.apply_box(b), num_lidar_pts: b.count_inside(&f.points) as i64, instance: format!("ignored:{j}") });
            }
            summary.boxes += f.boxes.len();
            summary.frames += 1;
            if is_listed(&sequence, val) {
                summary.val_frames += 1;
            }
            frames.push((ego, 1_600_000_000_000_000 + (k as i64) * 500_000, boxes));
            k += 1;
            i += 1;
        }
        writer.add_scene(&sequence, &frames);
    }
    writer.finish()?;
    Ok(summary)
}
