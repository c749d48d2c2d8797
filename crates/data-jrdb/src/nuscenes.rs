//! nuScenes-style tables (nuScenes v1.0, Lyft level 5), read as a dataset and written from one
//! (docs/data.md).
//!
//! ```text
//! <root>/<version>/{scene,sample,sample_data,sample_annotation,calibrated_sensor,sensor,
//!                   ego_pose,instance,category,log,map,attribute,visibility}.json
//! <root>/samples/LIDAR_TOP/<name>.pcd.bin     x y z intensity ring, float32
//! ```
//!
//! Annotations are in the global frame: `translation` the box centre, `size` = (width, length,
//! height), `rotation` a quaternion `[w, x, y, z]` turning the box's length axis. A key frame's
//! LIDAR_TOP cloud is in the sensor's frame, which `calibrated_sensor` places in the ego frame
//! (origin at the rear axle, on the ground) and `ego_pose` places in the global frame. The base
//! frame is the ego frame's axes with its origin under the sensor and the ground 0.7 m below it,
//! as in JRDB: `p_base = R_cs·p_lidar + (0, 0, t_cs.z − 0.7)`.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::box3d::Box3d;
use crate::cloud::CloudFormat;
use crate::dataset::{DatasetConfig, FrameRef, FrameSource, OnBadFrame};
use crate::error::{DataError, ErrorKind, Result};
use crate::kitti::BASE_FLOOR_DEPTH;
use crate::labels::Label;
use crate::rigid::Rigid;
use crate::split::{Split, is_listed};

/// The official validation scenes of nuScenes v1.0-trainval (`nuscenes/utils/splits.py`,
/// 150 scenes), as runs of consecutive scene numbers.
const NUSCENES_VAL: [(u16, u16); 26] = [
    (3, 3), (12, 18), (35, 36), (38, 39), (92, 110), (221, 221), (268, 278), (329, 332), (344, 346), (519, 524), (552, 565), (625, 627), (629, 630),
    (632, 638), (770, 771), (775, 775), (777, 778), (780, 784), (794, 800), (802, 802), (904, 917), (919, 931), (962, 963), (966, 969), (971, 972), (1059, 1073),
];

/// v1.0-mini's validation scenes (`mini_val`).
const NUSCENES_MINI_VAL: [&str; 2] = ["scene-0103", "scene-0916"];

/// nuScenes' settings in `[data.nuscenes]`.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct NuscenesOptions {
    /// The tables' folder under the root (`v1.0-trainval`, `v1.0-mini`, Lyft's `train_data`);
    /// default: the one folder there holding `sample.json`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub version: Option<String>,
    /// The validation scenes (an entry ending in `*` matches by prefix); default: the official
    /// split of `v1.0-trainval` and `v1.0-mini`. Required for other releases.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub val_scenes: Option<Vec<String>>,
}

/// What a nuScenes category is to a person detector.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum NuscenesRole {
    /// Adults, children, construction workers, police officers (nuScenes' `pedestrian` detection
    /// class), and Lyft's `pedestrian`.
    Person,
    /// Strollers, wheelchairs, personal mobility: `human.pedestrian.*` that nuScenes' detection
    /// benchmark leaves out of `pedestrian`; ignored.
    Ignored,
    /// Everything else.
    Other,
}

/// The role of a category name.
pub fn role(category: &str) -> NuscenesRole {
    match category {
        "human.pedestrian.adult" | "human.pedestrian.child" | "human.pedestrian.construction_worker" | "human.pedestrian.police_officer" | "pedestrian" => NuscenesRole::Person,
        c if c.starts_with("human.pedestrian.") => NuscenesRole::Ignored,
        _ => NuscenesRole::Other,
    }
}

/// `scene.json` rows.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Scene {
    /// Token.
    pub token: String,
    /// Its log.
    pub log_token: String,
    /// Key frames in it.
    pub nbr_samples: usize,
    /// Its first key frame.
    pub first_sample_token: String,
    /// Its last key frame.
    pub last_sample_token: String,
    /// `scene-0001`.
    pub name: String,
    /// Free text.
    pub description: String,
}

/// Microseconds: an integer in nuScenes, a float in Lyft's release.
pub type Timestamp = serde_json::Number;

fn micros(t: &Timestamp) -> f64 {
    t.as_f64().unwrap_or(0.0)
}

/// `sample.json` rows: key frames.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Sample {
    /// Token.
    pub token: String,
    /// Microseconds.
    pub timestamp: Timestamp,
    /// Its scene.
    pub scene_token: String,
    /// Previous key frame or "".
    pub prev: String,
    /// Next key frame or "".
    pub next: String,
}

/// `sample_data.json` rows: one sensor's data at one time.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct SampleData {
    /// Token.
    pub token: String,
    /// Its key frame.
    pub sample_token: String,
    /// The ego pose at its time.
    pub ego_pose_token: String,
    /// Its sensor's calibration.
    pub calibrated_sensor_token: String,
    /// Microseconds.
    pub timestamp: Timestamp,
    /// `pcd` for LiDAR.
    pub fileformat: String,
    /// Whether it is the key frame's own.
    pub is_key_frame: bool,
    /// Image height (0 for LiDAR).
    #[serde(default)]
    pub height: u32,
    /// Image width (0 for LiDAR).
    #[serde(default)]
    pub width: u32,
    /// Relative to the root.
    pub filename: String,
    /// Previous sweep or "".
    #[serde(default)]
    pub prev: String,
    /// Next sweep or "".
    #[serde(default)]
    pub next: String,
}

/// `ego_pose.json` and the pose part of `calibrated_sensor.json`.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Pose {
    /// Token.
    pub token: String,
    /// Metres.
    pub translation: [f64; 3],
    /// `[w, x, y, z]`.
    pub rotation: [f64; 4],
    /// Microseconds (ego poses).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub timestamp: Option<Timestamp>,
    /// The sensor (calibrated sensors).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sensor_token: Option<String>,
    /// A camera's 3×3 intrinsics; empty for LiDAR (calibrated sensors).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub camera_intrinsic: Option<Vec<Vec<f64>>>,
}

impl Pose {
    /// Its frame → the frame it is given in.
    pub fn rigid(&self) -> Rigid {
        Rigid::from_quaternion(self.rotation, self.translation)
    }
}

/// `sensor.json` rows.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Sensor {
    /// Token.
    pub token: String,
    /// `LIDAR_TOP`, `CAM_FRONT`, …
    pub channel: String,
    /// `lidar`, `camera`, `radar`.
    pub modality: String,
}

/// `sample_annotation.json` rows.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Annotation {
    /// Token.
    pub token: String,
    /// Its key frame.
    pub sample_token: String,
    /// The object it is an instant of.
    pub instance_token: String,
    /// Visibility bin.
    #[serde(default)]
    pub visibility_token: String,
    /// Attributes.
    #[serde(default)]
    pub attribute_tokens: Vec<String>,
    /// Box centre, global frame.
    pub translation: [f64; 3],
    /// Width, length, height.
    pub size: [f64; 3],
    /// `[w, x, y, z]`.
    pub rotation: [f64; 4],
    /// Previous annotation of the instance or "".
    #[serde(default)]
    pub prev: String,
    /// Next annotation of the instance or "".
    #[serde(default)]
    pub next: String,
    /// LIDAR_TOP points in the box (absent in Lyft's release: counted from the cloud then).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub num_lidar_pts: Option<i64>,
    /// Radar points in the box.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub num_radar_pts: Option<i64>,
}

/// `instance.json` rows.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Instance {
    /// Token.
    pub token: String,
    /// Its category.
    pub category_token: String,
    /// Annotations of it.
    pub nbr_annotations: usize,
    /// Its first annotation.
    pub first_annotation_token: String,
    /// Its last annotation.
    pub last_annotation_token: String,
}

/// `category.json` rows.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Category {
    /// Token.
    pub token: String,
    /// `human.pedestrian.adult`, …
    pub name: String,
    /// Free text.
    #[serde(default)]
    pub description: String,
}

fn read_table<T: for<'de> Deserialize<'de>>(dir: &Path, name: &str) -> Result<Vec<T>> {
    let path = dir.join(format!("{name}.json"));
    let text = std::fs::read_to_string(&path).map_err(|e| DataError::io(&path, e))?;
    serde_json::from_str(&text).map_err(|e| DataError::new(&path, ErrorKind::Parse(e.to_string())))
}

/// The tables' folder: `<root>/<version>`, or the one folder under the root holding `sample.json`.
pub fn tables_dir(root: &Path, opts: &NuscenesOptions) -> Result<PathBuf> {
    if let Some(v) = &opts.version {
        let dir = root.join(v);
        return if dir.join("sample.json").is_file() {
            Ok(dir)
        } else {
            Err(DataError::new(&dir, ErrorKind::Layout("no sample.json here (data.nuscenes.version)".into())))
        };
    }
    let rd = std::fs::read_dir(root).map_err(|e| DataError::io(root, e))?;
    let mut found = Vec::new();
    for e in rd {
        let p = e.map_err(|e| DataError::io(root, e))?.path();
        if p.join("sample.json").is_file() {
            found.push(p);
        }
    }
    found.sort();
    match found.len() {
        1 => Ok(found.remove(0)),
        0 => Err(DataError::new(root, ErrorKind::Layout("not a nuScenes-style root: no folder here holds sample.json".into()))),
        _ => Err(DataError::new(root, ErrorKind::Layout(format!("several table folders ({}): name one with data.nuscenes.version", found.iter().map(|p| p.file_name().unwrap().to_string_lossy().into_owned()).collect::<Vec<_>>().join(", "))))),
    }
}

/// Whether `scene` is a validation scene.
fn is_val(scene: &str, version: &str, opts: &NuscenesOptions, at: &Path) -> Result<bool> {
    if let Some(list) = &opts.val_scenes {
        return Ok(is_listed(scene, list));
    }
    match version {
        "v1.0-trainval" => {
            let n: Option<u16> = scene.strip_prefix("scene-").and_then(|s| s.parse().ok());
            Ok(n.is_some_and(|n| NUSCENES_VAL.iter().any(|&(a, b)| (a..=b).contains(&n))))
        }
        "v1.0-mini" => Ok(NUSCENES_MINI_VAL.contains(&scene)),
        _ => Err(DataError::new(at, ErrorKind::Layout(format!("release `{version}` has no official validation split: list its scenes in data.nuscenes.val_scenes")))),
    }
}

/// Lists the key frames of `cfg.split`, scene by scene (scenes by name, frames by time).
pub fn list_frames(root: &Path, cfg: &DatasetConfig) -> Result<(Vec<FrameRef>, Vec<String>)> {
    let opts = &cfg.nuscenes;
    let dir = tables_dir(root, opts)?;
    let version = dir.file_name().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
    let scenes: Vec<Scene> = read_table(&dir, "scene")?;
    let samples: Vec<Sample> = read_table(&dir, "sample")?;
    let sample_data: Vec<SampleData> = read_table(&dir, "sample_data")?;
    let ego_poses: Vec<Pose> = read_table(&dir, "ego_pose")?;
    let calibrated: Vec<Pose> = read_table(&dir, "calibrated_sensor")?;
    let sensors: Vec<Sensor> = read_table(&dir, "sensor")?;
    let annotations: Vec<Annotation> = read_table(&dir, "sample_annotation")?;
    let instances: Vec<Instance> = read_table(&dir, "instance")?;
    let categories: Vec<Category> = read_table(&dir, "category")?;

    let by_token = |t: &str, table: &str, key: &str| DataError::key(dir.join(format!("{table}.json")), key.to_string(), format!("token {t} is not in the table"));
    let ego: HashMap<&str, &Pose> = ego_poses.iter().map(|p| (p.token.as_str(), p)).collect();
    let calib: HashMap<&str, &Pose> = calibrated.iter().map(|p| (p.token.as_str(), p)).collect();
    let lidar_top: Vec<&str> = sensors.iter().filter(|s| s.channel == "LIDAR_TOP").map(|s| s.token.as_str()).collect();
    let category: HashMap<&str, &str> = categories.iter().map(|c| (c.token.as_str(), c.name.as_str())).collect();
    let instance_category: HashMap<&str, &str> = instances.iter().map(|i| (i.token.as_str(), i.category_token.as_str())).collect();
    let mut lidar_of: HashMap<&str, &SampleData> = HashMap::new();
    for sd in &sample_data {
        if sd.is_key_frame && calib.get(sd.calibrated_sensor_token.as_str()).is_some_and(|c| c.sensor_token.as_deref().is_some_and(|s| lidar_top.contains(&s))) {
            lidar_of.insert(sd.sample_token.as_str(), sd);
        }
    }
    let mut anns_of: HashMap<&str, Vec<&Annotation>> = HashMap::new();
    for a in &annotations {
        anns_of.entry(a.sample_token.as_str()).or_default().push(a);
    }

    if let Some(only) = &cfg.sequences
        && let Some(missing) = only.iter().find(|n| !scenes.iter().any(|s| &s.name == *n))
    {
        return Err(DataError::new(dir.join("scene.json"), ErrorKind::Layout(format!("no scene named `{missing}`"))));
    }
    let mut chosen: Vec<&Scene> = Vec::new();
    for s in &scenes {
        if let Some(only) = &cfg.sequences {
            if only.contains(&s.name) {
                chosen.push(s);
            }
            continue;
        }
        if match cfg.split {
            Split::Train => !is_val(&s.name, &version, opts, &dir)?,
            Split::Val => is_val(&s.name, &version, opts, &dir)?,
            Split::TrainVal => true,
        } {
            chosen.push(s);
        }
    }
    chosen.sort_by(|a, b| a.name.cmp(&b.name));
    let mut frames = Vec::new();
    for scene in &chosen {
        let mut keys: Vec<&Sample> = samples.iter().filter(|s| s.scene_token == scene.token).collect();
        keys.sort_by(|a, b| micros(&a.timestamp).total_cmp(&micros(&b.timestamp)));
        for (i, sample) in keys.iter().enumerate() {
            let built = (|| -> Result<FrameRef> {
                let sd = lidar_of.get(sample.token.as_str()).ok_or_else(|| DataError::key(dir.join("sample_data.json"), format!("sample {}", sample.token), "has no LIDAR_TOP key frame"))?;
                let cs = calib.get(sd.calibrated_sensor_token.as_str()).ok_or_else(|| by_token(&sd.calibrated_sensor_token, "calibrated_sensor", "calibrated_sensor_token"))?;
                let pose = ego.get(sd.ego_pose_token.as_str()).ok_or_else(|| by_token(&sd.ego_pose_token, "ego_pose", "ego_pose_token"))?;
                for (what, q, table) in [("calibrated_sensor", cs.rotation, "calibrated_sensor"), ("ego_pose", pose.rotation, "ego_pose")] {
                    let n = q.iter().map(|v| v * v).sum::<f64>().sqrt();
                    if !(n > 1e-6 && n.is_finite()) || cs.translation.iter().chain(&pose.translation).any(|v| !v.is_finite()) {
                        return Err(DataError::key(dir.join(format!("{table}.json")), format!("{what} {}", if table == "ego_pose" { &pose.token } else { &cs.token }), "rotation is not a unit quaternion or a value is not finite"));
                    }
                }
                let cs_rigid = cs.rigid();
                let to_base = Rigid { rotation: cs_rigid.rotation, translation: [0.0, 0.0, cs.translation[2] - BASE_FLOOR_DEPTH] };
                let box_to_base = Rigid::translation([-cs.translation[0], -cs.translation[1], -BASE_FLOOR_DEPTH]).then_after(&pose.rigid().inverse());
                let (mut labels, mut ignored) = (Vec::new(), Vec::new());
                let mut count_points = false;
                for a in anns_of.get(sample.token.as_str()).map(Vec::as_slice).unwrap_or(&[]) {
                    let cat = instance_category
                        .get(a.instance_token.as_str())
                        .and_then(|c| category.get(c))
                        .ok_or_else(|| by_token(&a.instance_token, "instance", &format!("sample_annotation {}", a.token)))?;
                    let [w, l, h] = a.size;
                    let qn = a.rotation.iter().map(|v| v * v).sum::<f64>().sqrt();
                    if !(w > 0.0 && l > 0.0 && h > 0.0) || !(qn > 1e-6) || a.translation.iter().chain(&a.size).chain(&a.rotation).any(|v| !v.is_finite()) {
                        return Err(DataError::key(dir.join("sample_annotation.json"), format!("sample_annotation {}", a.token), "a size that is not positive, a rotation that is not a unit quaternion, or a value that is not finite"));
                    }
                    let global = Box3d { cx: a.translation[0], cy: a.translation[1], cz: a.translation[2], l, w, h, rot_z: Rigid::from_quaternion(a.rotation, [0.0; 3]).yaw() };
                    let b = box_to_base.apply_box(&global);
                    match role(cat) {
                        NuscenesRole::Person => {
                            // Lyft's release writes −1 for "not counted": counted in the cloud then.
                            let stated = a.num_lidar_pts.filter(|&n| n >= 0);
                            count_points |= stated.is_none();
                            labels.push(Label { id: format!("{cat}:{}", a.instance_token), bbox: b, num_points: stated.unwrap_or(-1), observation_angle: -1.0 });
                        }
                        NuscenesRole::Ignored => ignored.push(b),
                        NuscenesRole::Other => {}
                    }
                }
                Ok(FrameRef {
                    sequence: scene.name.clone(),
                    name: format!("{i:06}"),
                    // Lyft names its 5-float clouds `.bin`: the format is the table's, not the name's.
                    source: FrameSource::Cloud { path: root.join(&sd.filename), format: CloudFormat::NuScenesBin, to_base, view: None },
                    labels,
                    ignored,
                    count_points,
                })
            })();
            match built {
                Ok(f) => frames.push(f),
                Err(e) if cfg.on_bad_frame == OnBadFrame::Skip => eprintln!("warning: skipping: {e}"),
                Err(e) => return Err(e),
            }
        }
    }
    Ok((frames, chosen.iter().map(|s| s.name.clone()).collect()))
}

/// Writes nuScenes-style tables one key frame at a time (what `data-jrdb export` uses): one
/// LIDAR_TOP sensor with one calibration, a log, the standard visibility levels.
pub struct TablesWriter {
    root: PathBuf,
    version: String,
    lidar: Pose,
    scenes: Vec<Scene>,
    samples: Vec<Sample>,
    sample_data: Vec<SampleData>,
    ego_poses: Vec<Pose>,
    annotations: Vec<Annotation>,
    instances: Vec<Instance>,
    categories: Vec<Category>,
    next: u64,
}

/// One annotated object of a key frame being written.
pub struct WrittenBox {
    /// Its category (`human.pedestrian.adult`, …).
    pub category: String,
    /// Its box in the global frame.
    pub global: Box3d,
    /// `num_lidar_pts`.
    pub num_lidar_pts: i64,
    /// The same object's key in the previous frames of the scene (links `prev`/`next`).
    pub instance: String,
}

impl TablesWriter {
    /// Starts tables under `root/version` for a LIDAR_TOP placed in the ego frame by `lidar`.
    pub fn new(root: &Path, version: &str, lidar: Rigid) -> Self {
        let mut w = Self {
            root: root.to_path_buf(),
            version: version.into(),
            lidar: Pose { token: String::new(), translation: lidar.translation, rotation: lidar.quaternion(), timestamp: None, sensor_token: None, camera_intrinsic: Some(Vec::new()) },
            scenes: Vec::new(),
            samples: Vec::new(),
            sample_data: Vec::new(),
            ego_poses: Vec::new(),
            annotations: Vec::new(),
            instances: Vec::new(),
            categories: Vec::new(),
            next: 0,
        };
        w.lidar.token = w.token();
        w
    }

    fn token(&mut self) -> String {
        self.next += 1;
        format!("{:032x}", (self.next as u128).wrapping_mul(0x9E37_79B9_7F4A_7C15_F39C_C060_5CED_C835))
    }

    /// The LIDAR_TOP file of the next key frame, relative to the root.
    pub fn lidar_file(scene: &str, frame: usize) -> String {
        format!("samples/LIDAR_TOP/{scene}__LIDAR_TOP__{frame:06}.pcd.bin")
    }

    /// Adds a scene's key frames: each its ego pose (ego → global), its time and its boxes.
    /// The clouds themselves are written by the caller at [`Self::lidar_file`].
    pub fn add_scene(&mut self, name: &str, frames: &[(Rigid, i64, Vec<WrittenBox>)]) {
        let scene_token = self.token();
        let tokens: Vec<String> = frames.iter().map(|_| self.token()).collect();
        let mut instance_of: HashMap<String, usize> = HashMap::new();
        for (i, (pose, time, boxes)) in frames.iter().enumerate() {
            let pose_token = self.token();
            self.ego_poses.push(Pose { token: pose_token.clone(), translation: pose.translation, rotation: pose.quaternion(), timestamp: Some((*time).into()), sensor_token: None, camera_intrinsic: None });
            let sd_token = self.token();
            self.sample_data.push(SampleData {
                token: sd_token,
                sample_token: tokens[i].clone(),
                ego_pose_token: pose_token,
                calibrated_sensor_token: self.lidar.token.clone(),
                timestamp: (*time).into(),
                fileformat: "pcd".into(),
                is_key_frame: true,
                height: 0,
                width: 0,
                filename: Self::lidar_file(name, i),
                prev: String::new(),
                next: String::new(),
            });
            self.samples.push(Sample {
                token: tokens[i].clone(),
                timestamp: (*time).into(),
                scene_token: scene_token.clone(),
                prev: if i > 0 { tokens[i - 1].clone() } else { String::new() },
                next: tokens.get(i + 1).cloned().unwrap_or_default(),
            });
            for b in boxes {
                let cat_token = match self.categories.iter().find(|c| c.name == b.category) {
                    Some(c) => c.token.clone(),
                    None => {
                        let t = self.token();
                        self.categories.push(Category { token: t.clone(), name: b.category.clone(), description: String::new() });
                        t
                    }
                };
                let ann_token = self.token();
                let inst = match instance_of.get(&b.instance) {
                    Some(&k) => {
                        let last = self.instances[k].last_annotation_token.clone();
                        if let Some(prev) = self.annotations.iter_mut().rev().find(|a| a.token == last) {
                            prev.next = ann_token.clone();
                        }
                        self.instances[k].last_annotation_token = ann_token.clone();
                        self.instances[k].nbr_annotations += 1;
                        (k, last)
                    }
                    None => {
                        let t = self.token();
                        self.instances.push(Instance { token: t, category_token: cat_token, nbr_annotations: 1, first_annotation_token: ann_token.clone(), last_annotation_token: ann_token.clone() });
                        instance_of.insert(b.instance.clone(), self.instances.len() - 1);
                        (self.instances.len() - 1, String::new())
                    }
                };
                let g = &b.global;
                self.annotations.push(Annotation {
                    token: ann_token,
                    sample_token: tokens[i].clone(),
                    instance_token: self.instances[inst.0].token.clone(),
                    visibility_token: "4".into(),
                    attribute_tokens: Vec::new(),
                    translation: [g.cx, g.cy, g.cz],
                    size: [g.w, g.l, g.h],
                    rotation: Rigid::from_yaw(g.rot_z, [0.0; 3]).quaternion(),
                    prev: inst.1,
                    next: String::new(),
                    num_lidar_pts: Some(b.num_lidar_pts),
                    num_radar_pts: Some(0),
                });
            }
        }
        self.scenes.push(Scene {
            token: scene_token,
            log_token: "log".into(),
            nbr_samples: frames.len(),
            first_sample_token: tokens.first().cloned().unwrap_or_default(),
            last_sample_token: tokens.last().cloned().unwrap_or_default(),
            name: name.into(),
            description: "exported by pmunet".into(),
        });
    }

    /// Writes the thirteen tables.
    pub fn finish(mut self) -> Result<()> {
        let dir = self.root.join(&self.version);
        std::fs::create_dir_all(&dir).map_err(|e| DataError::io(&dir, e))?;
        let write = |name: &str, v: serde_json::Value| -> Result<()> {
            let path = dir.join(format!("{name}.json"));
            std::fs::write(&path, serde_json::to_string_pretty(&v).unwrap()).map_err(|e| DataError::io(&path, e))
        };
        let sensor_token = "lidar_top".to_string();
        self.lidar.sensor_token = Some(sensor_token.clone());
        write("sensor", serde_json::json!([{"token": sensor_token, "channel": "LIDAR_TOP", "modality": "lidar"}]))?;
        write("calibrated_sensor", serde_json::to_value([&self.lidar]).unwrap())?;
        write("scene", serde_json::to_value(&self.scenes).unwrap())?;
        write("sample", serde_json::to_value(&self.samples).unwrap())?;
        write("sample_data", serde_json::to_value(&self.sample_data).unwrap())?;
        write("ego_pose", serde_json::to_value(&self.ego_poses).unwrap())?;
        write("sample_annotation", serde_json::to_value(&self.annotations).unwrap())?;
        write("instance", serde_json::to_value(&self.instances).unwrap())?;
        write("category", serde_json::to_value(&self.categories).unwrap())?;
        write("attribute", serde_json::json!([]))?;
        write("map", serde_json::json!([{"token": "map", "log_tokens": ["log"], "category": "semantic_prior", "filename": ""}]))?;
        write("log", serde_json::json!([{"token": "log", "logfile": "pmunet-export", "vehicle": "sim", "date_captured": "2026-01-01", "location": "sim"}]))?;
        let levels = [("1", "v0-40"), ("2", "v40-60"), ("3", "v60-80"), ("4", "v80-100")];
        write("visibility", serde_json::Value::Array(levels.iter().map(|(t, l)| serde_json::json!({"token": t, "level": l, "description": ""})).collect()))?;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_official_val_split_has_150_scenes() {
        let n: u16 = NUSCENES_VAL.iter().map(|&(a, b)| b - a + 1).sum();
        assert_eq!(n, 150);
        let opts = NuscenesOptions::default();
        let at = Path::new("t");
        assert!(is_val("scene-0003", "v1.0-trainval", &opts, at).unwrap());
        assert!(!is_val("scene-0001", "v1.0-trainval", &opts, at).unwrap());
        assert!(is_val("scene-1073", "v1.0-trainval", &opts, at).unwrap());
        assert!(is_val("scene-0916", "v1.0-mini", &opts, at).unwrap());
        assert!(is_val("x", "train_data", &opts, at).is_err());
    }

    #[test]
    fn categories() {
        assert_eq!(role("human.pedestrian.adult"), NuscenesRole::Person);
        assert_eq!(role("human.pedestrian.stroller"), NuscenesRole::Ignored);
        assert_eq!(role("vehicle.car"), NuscenesRole::Other);
        assert_eq!(role("pedestrian"), NuscenesRole::Person);
    }
}
