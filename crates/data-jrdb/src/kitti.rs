//! KITTI object detection's layout, read as a dataset and written from one (docs/data.md).
//!
//! ```text
//! <root>/training/velodyne/<NNNNNN>.bin   x y z reflectance, float32
//! <root>/training/label_2/<NNNNNN>.txt    type trunc occ alpha x1 y1 x2 y2 h w l x y z ry
//! <root>/training/calib/<NNNNNN>.txt      P0..P3, R0_rect, Tr_velo_to_cam, Tr_imu_to_velo
//! <root>/training/image_2/<NNNNNN>.png    (optional: only its size is read)
//! <root>/ImageSets/{train,val}.txt        the split files OpenPCDet and mmdetection3d ship
//! ```
//!
//! A label's (x, y, z) is its bottom centre in the rectified camera frame (x right, y down,
//! z forward) and `ry` turns its length axis, `(cos ry, 0, −sin ry)`, about the camera's y axis.
//! The LiDAR frame is KITTI's Velodyne frame (x forward, y left, z up, 1.73 m above the road);
//! the base frame is the same, lowered so the road lies 0.7 m under the origin as in JRDB.
//! KITTI labels only what the left colour camera sees, so by default the points are kept only
//! inside its image, as KITTI's LiDAR detectors train and are scored.

use std::path::{Path, PathBuf};

use crate::box3d::Box3d;
use crate::cloud::CloudFormat;
use crate::dataset::{DatasetConfig, FrameRef, FrameSource, OnBadFrame};
use crate::error::{DataError, ErrorKind, Result};
use crate::labels::Label;
use crate::rigid::Rigid;
use crate::split::Split;

/// The base frame's floor lies this far below its origin (JRDB's, docs/data.md).
pub const BASE_FLOOR_DEPTH: f64 = 0.7;

/// KITTI's settings in `[data.kitti]`.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct KittiOptions {
    /// The Velodyne's height above the road (KITTI's set-up: 1.73 m).
    pub sensor_height: f64,
    /// Keep only the points the left colour camera sees (KITTI labels nothing else).
    pub camera_view_only: bool,
    /// Image size (width, height) when `image_2/<frame>.png` is absent.
    pub image_size: [u32; 2],
}

impl Default for KittiOptions {
    fn default() -> Self {
        Self { sensor_height: 1.73, camera_view_only: true, image_size: [1242, 375] }
    }
}

impl KittiOptions {
    /// Velodyne frame → base frame.
    pub fn velo_to_base(&self) -> Rigid {
        Rigid::translation([0.0, 0.0, self.sensor_height - BASE_FLOOR_DEPTH])
    }
}

/// A frame's `calib/<frame>.txt`: what its labels and its image need.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct KittiCalib {
    /// `P2`: rectified camera → left colour image, row-major 3×4.
    pub p2: [f64; 12],
    /// `R0_rect` (a rotation, no translation).
    pub r0_rect: Rigid,
    /// `Tr_velo_to_cam`.
    pub velo_to_cam: Rigid,
}

impl KittiCalib {
    /// Velodyne → rectified camera.
    pub fn velo_to_rect(&self) -> Rigid {
        self.r0_rect.then_after(&self.velo_to_cam)
    }

    /// Reads a calibration file.
    pub fn read(path: &Path) -> Result<Self> {
        let text = std::fs::read_to_string(path).map_err(|e| DataError::io(path, e))?;
        Self::parse(&text).map_err(|(key, what)| DataError::key(path, key, what))
    }

    /// Parses its text: `KEY: v v v …` lines; `R_rect` and `Tr_velo_cam` (the tracking
    /// benchmark's names) are accepted too.
    pub fn parse(text: &str) -> std::result::Result<Self, (String, String)> {
        let find = |names: &[&str], n: usize| -> std::result::Result<Vec<f64>, (String, String)> {
            for line in text.lines() {
                // `KEY: values` in the object benchmark; `KEY values` in the tracking one.
                let line = line.trim_start();
                let cut = line.find(|c: char| c == ':' || c.is_whitespace()).unwrap_or(line.len());
                let (key, rest) = (&line[..cut], line[cut..].trim_start_matches(':'));
                if names.contains(&key.trim()) {
                    let v: Vec<f64> = rest
                        .split_whitespace()
                        .map(|t| t.parse::<f64>().map_err(|_| (key.trim().to_string(), format!("`{t}` is not a number"))))
                        .collect::<std::result::Result<_, _>>()?;
                    if v.len() != n {
                        return Err((key.trim().to_string(), format!("expected {n} numbers, found {}", v.len())));
                    }
                    if v.iter().any(|x| !x.is_finite()) {
                        return Err((key.trim().to_string(), "a value is not finite".into()));
                    }
                    return Ok(v);
                }
            }
            Err((names[0].to_string(), "missing".to_string()))
        };
        let p2: [f64; 12] = find(&["P2"], 12)?.try_into().unwrap();
        let r = find(&["R0_rect", "R_rect"], 9)?;
        let r0_rect = Rigid { rotation: [[r[0], r[1], r[2]], [r[3], r[4], r[5]], [r[6], r[7], r[8]]], translation: [0.0; 3] };
        let velo_to_cam = Rigid::from_matrix_3x4(&find(&["Tr_velo_to_cam", "Tr_velo_cam"], 12)?);
        let calib = Self { p2, r0_rect, velo_to_cam };
        // Both are rotations: a determinant far from 1 is a damaged file, and its inverse NaN.
        for (key, r) in [("R0_rect", &calib.r0_rect), ("Tr_velo_to_cam", &calib.velo_to_cam)] {
            let m = &r.rotation;
            let det = m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1]) - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0]) + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0]);
            if (det - 1.0).abs() > 0.01 {
                return Err((key.to_string(), format!("its rotation's determinant is {det:.4}, not 1")));
            }
        }
        Ok(calib)
    }

    /// The file's text, every matrix KITTI's readers look for (P0–P3 all `P2`, `Tr_imu_to_velo`
    /// the identity), 12 significant digits.
    pub fn to_text(&self) -> String {
        let row = |v: &[f64]| v.iter().map(|x| format!("{x:.12e}")).collect::<Vec<_>>().join(" ");
        let r = &self.r0_rect.rotation;
        let mut s = String::new();
        for k in 0..4 {
            s += &format!("P{k}: {}\n", row(&self.p2));
        }
        s += &format!("R0_rect: {}\n", row(&[r[0], r[1], r[2]].concat()));
        s += &format!("Tr_velo_to_cam: {}\n", row(&self.velo_to_cam.to_matrix_3x4()));
        s += &format!("Tr_imu_to_velo: {}\n", row(&Rigid::IDENTITY.to_matrix_3x4()));
        s
    }
}

/// The left colour camera's image, as seen from the base frame: which points it sees.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CameraView {
    /// Base frame → rectified camera.
    pub base_to_rect: Rigid,
    /// `P2`.
    pub p2: [f64; 12],
    /// Image width and height in pixels.
    pub size: [u32; 2],
}

impl CameraView {
    /// Whether a base-frame point lies in front of the camera and projects inside the image.
    pub fn sees(&self, p: [f32; 3]) -> bool {
        let c = self.base_to_rect.apply(p.map(f64::from));
        let m = &self.p2;
        let w = m[8] * c[0] + m[9] * c[1] + m[10] * c[2] + m[11];
        if c[2] <= 0.0 || w <= 0.0 {
            return false;
        }
        let u = (m[0] * c[0] + m[1] * c[1] + m[2] * c[2] + m[3]) / w;
        let v = (m[4] * c[0] + m[5] * c[1] + m[6] * c[2] + m[7]) / w;
        u >= 0.0 && u < self.size[0] as f64 && v >= 0.0 && v < self.size[1] as f64
    }
}

/// One line of a `label_2` file.
#[derive(Debug, Clone, PartialEq)]
pub struct KittiLabel {
    /// `Pedestrian`, `Person_sitting`, `Cyclist`, `Car`, `DontCare`, …
    pub kind: String,
    /// The box in the Velodyne frame (`None` for `DontCare`, which has no 3D box).
    pub bbox: Option<Box3d>,
}

/// What a KITTI class is to a person detector.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum KittiRole {
    /// `Pedestrian` and `Person_sitting`.
    Person,
    /// `Cyclist`: a person on a bicycle, which KITTI scores in its own class; ignored.
    Ignored,
    /// Everything else (vehicles, `Misc`, `DontCare`).
    Other,
}

/// The role of a KITTI class name.
pub fn role(kind: &str) -> KittiRole {
    match kind {
        "Pedestrian" | "Person_sitting" => KittiRole::Person,
        "Cyclist" => KittiRole::Ignored,
        _ => KittiRole::Other,
    }
}

/// Parses a `label_2` file's text into Velodyne-frame boxes; errors give the line.
pub fn parse_labels(text: &str, calib: &KittiCalib) -> std::result::Result<Vec<KittiLabel>, (String, String)> {
    let rect_to_velo = calib.velo_to_rect().inverse();
    let mut out = Vec::new();
    for (i, line) in text.lines().enumerate() {
        let at = format!("line {}", i + 1);
        let t: Vec<&str> = line.split_whitespace().collect();
        if t.is_empty() {
            continue;
        }
        if t.len() != 15 && t.len() != 16 {
            return Err((at, format!("has {} columns, a KITTI label has 15 (16 with a score)", t.len())));
        }
        let v: Vec<f64> = t[1..15]
            .iter()
            .map(|s| s.parse::<f64>().map_err(|_| (at.clone(), format!("`{s}` is not a number"))))
            .collect::<std::result::Result<_, _>>()?;
        let kind = t[0].to_string();
        let [h, w, l, x, y, z, ry] = [v[7], v[8], v[9], v[10], v[11], v[12], v[13]];
        let bbox = if kind == "DontCare" {
            None
        } else if h <= 0.0 || w <= 0.0 || l <= 0.0 {
            if role(&kind) != KittiRole::Other {
                return Err((at, format!("a {kind} with a size that is not positive (h {h}, w {w}, l {l})")));
            }
            None
        } else {
            if ![h, w, l, x, y, z, ry].iter().all(|x| x.is_finite()) {
                return Err((at, "a non-finite box value".into()));
            }
            // Camera y points down: the centre is h/2 above the bottom centre.
            let [cx, cy, cz] = rect_to_velo.apply([x, y - h / 2.0, z]);
            let axis = rect_to_velo.rotate([ry.cos(), 0.0, -ry.sin()]);
            Some(Box3d { cx, cy, cz, l, w, h, rot_z: axis[1].atan2(axis[0]) })
        };
        out.push(KittiLabel { kind, bbox });
    }
    Ok(out)
}

/// A `label_2` line for a Velodyne-frame box: the 2D box projected with `P2` and clipped to the
/// image (`-1 -1 -1 -1` when a corner lies behind the camera), truncation and occlusion 0.
pub fn label_line(kind: &str, b: &Box3d, calib: &KittiCalib, image: [u32; 2]) -> String {
    let to_rect = calib.velo_to_rect();
    let [x, yc, z] = to_rect.apply([b.cx, b.cy, b.cz]);
    let y = yc + b.h / 2.0;
    let ry = camera_yaw(b.rot_z, &to_rect.inverse());
    let alpha = ry - x.atan2(z);
    let alpha = (alpha + std::f64::consts::PI).rem_euclid(2.0 * std::f64::consts::PI) - std::f64::consts::PI;
    let mut bb = [f64::INFINITY, f64::INFINITY, f64::NEG_INFINITY, f64::NEG_INFINITY];
    let mut behind = false;
    for [cx, cy] in b.corners_bev() {
        for dz in [-b.h / 2.0, b.h / 2.0] {
            let c = to_rect.apply([cx, cy, b.cz + dz]);
            let m = &calib.p2;
            let w = m[8] * c[0] + m[9] * c[1] + m[10] * c[2] + m[11];
            if c[2] <= 0.0 || w <= 0.0 {
                behind = true;
                continue;
            }
            let u = (m[0] * c[0] + m[1] * c[1] + m[2] * c[2] + m[3]) / w;
            let v = (m[4] * c[0] + m[5] * c[1] + m[6] * c[2] + m[7]) / w;
            bb = [bb[0].min(u), bb[1].min(v), bb[2].max(u), bb[3].max(v)];
        }
    }
    let bb = if behind {
        [-1.0; 4]
    } else {
        let (wd, ht) = (image[0].max(1) as f64 - 1.0, image[1].max(1) as f64 - 1.0);
        [bb[0].clamp(0.0, wd), bb[1].clamp(0.0, ht), bb[2].clamp(0.0, wd), bb[3].clamp(0.0, ht)]
    };
    format!(
        "{kind} 0.00 0 {alpha:.6} {:.2} {:.2} {:.2} {:.2} {:.6} {:.6} {:.6} {x:.6} {y:.6} {z:.6} {ry:.6}",
        bb[0], bb[1], bb[2], bb[3], b.h, b.w, b.l
    )
}

/// The `ry` whose length axis `(cos ry, 0, −sin ry)` the reader turns back into heading `rot_z`:
/// `rect_to_velo` takes it to `cos ry·m₀ − sin ry·m₂` (its columns), whose ground-plane part must
/// point along `(cos rot_z, sin rot_z)`. Solved exactly, so a tilted camera loses nothing.
fn camera_yaw(rot_z: f64, rect_to_velo: &Rigid) -> f64 {
    let m = &rect_to_velo.rotation;
    let (s, c) = rot_z.sin_cos();
    // Across the heading: −s·a_x + c·a_y = 0 with a = cos ry·m₀ − sin ry·m₂.
    let (u, v) = (-s * m[0][0] + c * m[1][0], -s * m[0][2] + c * m[1][2]);
    let mut ry = u.atan2(v);
    let along = |ry: f64| c * (ry.cos() * m[0][0] - ry.sin() * m[0][2]) + s * (ry.cos() * m[1][0] - ry.sin() * m[1][2]);
    if along(ry) < 0.0 {
        ry += std::f64::consts::PI;
    }
    (ry + std::f64::consts::PI).rem_euclid(2.0 * std::f64::consts::PI) - std::f64::consts::PI
}

/// The folder holding `velodyne/`: `<root>/training` or `<root>` itself.
pub fn data_dir(root: &Path) -> Result<PathBuf> {
    for cand in [root.join("training"), root.to_path_buf()] {
        if cand.join("velodyne").is_dir() {
            return Ok(cand);
        }
    }
    Err(DataError::new(root, ErrorKind::Layout("not a KITTI object tree: no velodyne/ folder here nor in training/".into())))
}

/// A split file's frame names: `<root>/ImageSets/<split>.txt` (or beside the data folder's parent).
fn split_file(root: &Path, data: &Path, name: &str) -> Option<PathBuf> {
    [root.join("ImageSets").join(name), data.parent().unwrap_or(data).join("ImageSets").join(name)].into_iter().find(|p| p.is_file())
}

fn read_split(path: &Path) -> Result<Vec<String>> {
    let text = std::fs::read_to_string(path).map_err(|e| DataError::io(path, e))?;
    let names: Vec<String> = text.lines().map(str::trim).filter(|l| !l.is_empty()).map(String::from).collect();
    if names.is_empty() {
        return Err(DataError::new(path, ErrorKind::Layout("lists no frames".into())));
    }
    Ok(names)
}

/// Image width and height from a PNG's IHDR chunk, if the file is a PNG.
fn png_size(path: &Path) -> Option<[u32; 2]> {
    use std::io::Read;
    let mut head = [0u8; 24];
    std::fs::File::open(path).ok()?.read_exact(&mut head).ok()?;
    if &head[..8] != b"\x89PNG\r\n\x1a\n" || &head[12..16] != b"IHDR" {
        return None;
    }
    let size = [u32::from_be_bytes(head[16..20].try_into().ok()?), u32::from_be_bytes(head[20..24].try_into().ok()?)];
    // PNG allows 1 to 2³¹ − 1 pixels a side.
    size.iter().all(|&v| (1..=i32::MAX as u32).contains(&v)).then_some(size)
}

/// Lists the frames of `cfg.split`: `ImageSets/train.txt` or `val.txt`, every frame of
/// `velodyne/` for `train_val` (and for `train` when there are no split files).
pub fn list_frames(root: &Path, cfg: &DatasetConfig) -> Result<(Vec<FrameRef>, Vec<String>)> {
    let data = data_dir(root)?;
    let opts = cfg.kitti;
    let all = || -> Result<Vec<String>> {
        let dir = data.join("velodyne");
        let mut names = Vec::new();
        for e in std::fs::read_dir(&dir).map_err(|e| DataError::io(&dir, e))? {
            let e = e.map_err(|e| DataError::io(&dir, e))?;
            if let Some(stem) = e.file_name().to_string_lossy().strip_suffix(".bin") {
                names.push(stem.to_string());
            }
        }
        names.sort();
        Ok(names)
    };
    let names = match cfg.split {
        Split::TrainVal => all()?,
        Split::Train => match split_file(root, &data, "train.txt") {
            Some(p) => read_split(&p)?,
            None if split_file(root, &data, "val.txt").is_none() => all()?,
            None => return Err(DataError::new(root.join("ImageSets/train.txt"), ErrorKind::Layout("missing, while val.txt is present".into()))),
        },
        Split::Val => match split_file(root, &data, "val.txt") {
            Some(p) => read_split(&p)?,
            None => {
                return Err(DataError::new(
                    root.join("ImageSets/val.txt"),
                    ErrorKind::Layout("missing: KITTI's validation split is the ImageSets/val.txt that OpenPCDet and mmdetection3d ship (3,769 frames)".into()),
                ));
            }
        },
    };
    let sequence = "training".to_string();
    let mut frames = Vec::with_capacity(names.len());
    for name in names {
        match frame(&data, &name, &opts, cfg.require_labels) {
            Ok(f) => frames.push(f),
            Err(e) if cfg.on_bad_frame == OnBadFrame::Skip => eprintln!("warning: skipping: {e}"),
            Err(e) => return Err(e),
        }
    }
    Ok((frames, vec![sequence]))
}

fn frame(data: &Path, name: &str, opts: &KittiOptions, require_labels: bool) -> Result<FrameRef> {
    let path = data.join("velodyne").join(format!("{name}.bin"));
    if !path.is_file() {
        return Err(DataError::new(&path, ErrorKind::Layout("listed in the split file but missing".into())));
    }
    let calib_path = data.join("calib").join(format!("{name}.txt"));
    let calib = KittiCalib::read(&calib_path)?;
    let to_base = opts.velo_to_base();
    let label_path = data.join("label_2").join(format!("{name}.txt"));
    let (mut labels, mut ignored) = (Vec::new(), Vec::new());
    if !label_path.is_file() && require_labels {
        return Err(DataError::new(&label_path, ErrorKind::Layout("missing (a frame without labels would train as one without people)".into())));
    }
    if label_path.is_file() {
        let text = std::fs::read_to_string(&label_path).map_err(|e| DataError::io(&label_path, e))?;
        let parsed = parse_labels(&text, &calib).map_err(|(key, what)| DataError::key(&label_path, key, what))?;
        for (i, l) in parsed.into_iter().enumerate() {
            let Some(b) = l.bbox else { continue };
            let b = to_base.apply_box(&b);
            match role(&l.kind) {
                KittiRole::Person => labels.push(Label { id: format!("{}:{i}", l.kind), bbox: b, num_points: -1, observation_angle: -1.0 }),
                KittiRole::Ignored => ignored.push(b),
                KittiRole::Other => {}
            }
        }
    }
    let view = opts.camera_view_only.then(|| CameraView {
        base_to_rect: calib.velo_to_rect().then_after(&to_base.inverse()),
        p2: calib.p2,
        size: png_size(&data.join("image_2").join(format!("{name}.png"))).unwrap_or(opts.image_size),
    });
    Ok(FrameRef {
        sequence: "training".into(),
        name: name.to_string(),
        source: FrameSource::Cloud { path, format: CloudFormat::KittiBin, to_base, view },
        labels,
        ignored,
        count_points: true,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// KITTI object frame 000000's calibration (training/calib/000000.txt).
    const CALIB_000000: &str = "P2: 7.215377000000e+02 0.000000000000e+00 6.095593000000e+02 4.485728000000e+01 0.000000000000e+00 7.215377000000e+02 1.728540000000e+02 2.163791000000e-01 0.000000000000e+00 0.000000000000e+00 1.000000000000e+00 2.745884000000e-03
R0_rect: 9.999239000000e-01 9.837760000000e-03 -7.445048000000e-03 -9.869795000000e-03 9.999421000000e-01 -4.278459000000e-03 7.402527000000e-03 4.351614000000e-03 9.999631000000e-01
Tr_velo_to_cam: 7.533745000000e-03 -9.999714000000e-01 -6.166020000000e-04 -4.069766000000e-03 1.480249000000e-02 7.280733000000e-04 -9.998902000000e-01 -7.631618000000e-02 9.998621000000e-01 7.523790000000e-03 1.480755000000e-02 -2.717806000000e-01
";

    #[test]
    fn frame_000000s_pedestrian_lands_where_openpcdet_puts_it() {
        // label_2/000000.txt: the frame's one Pedestrian. OpenPCDet's
        // `boxes3d_kitti_camera_to_lidar` (numpy's matrix inverse of R0_rect·Tr_velo_to_cam,
        // the bottom moved, then lifted by h/2) gives the LiDAR box centre
        // (8.6982, −1.8253, −1.4737 + 1.89/2), heading −(π/2 + 0.01). It lifts along the LiDAR's z
        // where we lift along the camera's −y: 1.5 cm apart at this tilt.
        let calib = KittiCalib::parse(CALIB_000000).unwrap();
        let text = "Pedestrian 0.00 0 -0.20 712.40 143.00 810.73 307.92 1.89 0.48 1.20 1.84 1.47 8.41 0.01\n";
        let l = parse_labels(text, &calib).unwrap();
        let b = l[0].bbox.unwrap();
        let expect = [8.6982, -1.8253, -1.4737 + 1.89 / 2.0];
        for (got, want) in [b.cx, b.cy, b.cz].iter().zip(expect) {
            assert!((got - want).abs() < 0.02, "{b:?}");
        }
        assert!((b.rot_z + std::f64::consts::FRAC_PI_2 + 0.01).abs() < 0.01, "{}", b.rot_z);
        assert_eq!((b.l, b.w, b.h), (1.20, 0.48, 1.89));
        // Written back and read again: the same box (to the 6 decimals written).
        let line = label_line("Pedestrian", &b, &calib, [1242, 375]);
        let again = parse_labels(&line, &calib).unwrap()[0].bbox.unwrap();
        for (a, c) in [(b.cx, again.cx), (b.cy, again.cy), (b.cz, again.cz)] {
            assert!((a - c).abs() < 1e-5, "{line}");
        }
        assert!((b.rot_z - again.rot_z).abs() < 1e-5, "{line}");
        // Its 2D box (the 3D box's corners projected) holds the annotator's tighter one, to
        // a few pixels, and is no more than 25 px wider on a side.
        let bb: Vec<f64> = line.split_whitespace().skip(4).take(4).map(|t| t.parse().unwrap()).collect();
        let label = [712.40, 143.00, 810.73, 307.92];
        assert!(bb[0] <= label[0] + 6.0 && bb[1] <= label[1] + 6.0 && bb[2] >= label[2] - 6.0 && bb[3] >= label[3] - 6.0, "{line}");
        assert!(bb.iter().zip(label).all(|(g, w)| (g - w).abs() < 25.0), "{line}");
    }

    #[test]
    fn the_camera_sees_ahead_not_behind() {
        let calib = KittiCalib::parse(CALIB_000000).unwrap();
        let opts = KittiOptions::default();
        let view = CameraView { base_to_rect: calib.velo_to_rect().then_after(&opts.velo_to_base().inverse()), p2: calib.p2, size: [1242, 375] };
        assert!(view.sees([10.0, 0.0, -0.5]));
        assert!(!view.sees([-10.0, 0.0, -0.5]));
        assert!(!view.sees([2.0, 10.0, -0.5]), "90° to the left is outside a 80° image");
    }

    #[test]
    fn the_tracking_benchmarks_calibration_reads_the_same() {
        // The tracking benchmark writes `R_rect` and `Tr_velo_cam` without colons.
        let tracking = CALIB_000000.replace("R0_rect:", "R_rect").replace("Tr_velo_to_cam:", "Tr_velo_cam").replace("P2:", "P2");
        assert_eq!(KittiCalib::parse(&tracking).unwrap(), KittiCalib::parse(CALIB_000000).unwrap());
        let bad = CALIB_000000.replace("R0_rect: 9.999239000000e-01", "R0_rect: 3.0");
        assert!(KittiCalib::parse(&bad).unwrap_err().1.contains("determinant"));
    }

    #[test]
    fn bad_lines_are_named() {
        let calib = KittiCalib::parse(CALIB_000000).unwrap();
        let e = parse_labels("Pedestrian 0 0\n", &calib).unwrap_err();
        assert_eq!(e.0, "line 1");
        let e = KittiCalib::parse("P2: 1 2 3\n").unwrap_err();
        assert_eq!(e.0, "P2");
    }
}
