//! `synth`: simulates sequences and writes them as a complete JRDB-format tree.

use std::collections::BTreeMap;
use std::path::Path;

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;

use super::lidar::{Return, Scanner};
use super::scene::{Scene, SceneKind};
use crate::calibration::{Calibration, Lidar};
use crate::box3d::Box3d;
use crate::error::{DataError, Result};
use crate::labels::{Label, write_labels};
use crate::pcd::{Column, Encoding, FieldType, write_pcd};
use crate::split::{DEFAULT_TRAIN_SEQUENCES, DEFAULT_VAL_SEQUENCES, Layout};
use crate::timestamps::{FrameTime, write_timestamps};

/// What to simulate.
#[derive(Debug, Clone, PartialEq)]
pub struct SynthConfig {
    /// Number of sequences.
    pub sequences: usize,
    /// Frames per sequence.
    pub frames: usize,
    /// Seed; the same seed writes the same tree.
    pub seed: u64,
    /// Most people in one scene (0–40 as in JRDB).
    pub max_people: usize,
    /// Frames per second (JRDB's annotated rate is 15).
    pub fps: f64,
    /// PCD encoding of the clouds.
    pub encoding: Encoding,
    /// People farther than this (BEV, metres) are not labelled.
    pub label_range: f64,
    /// Simulation steps (of `1 / fps`) between written frames: 1 writes consecutive scans, more
    /// spreads a sequence's frames over more of its time (less alike, as JRDB's subsampled sets).
    pub frame_step: usize,
    /// How sequences are named, which decides their split and kind of place.
    pub naming: Naming,
    /// The world simulated: bench-v1's scenes and rig, bench-v2's, or real backdrops.
    pub world: World,
    /// With [`World::Backdrops`]: the folder of real scans (`backdrops.csv`) people are put into.
    pub backdrops: Option<std::path::PathBuf>,
    /// With [`World::Backdrops`]: the share of sequences whose scan is thinned to a 32-beam
    /// sensor's density, people ray-cast with its kept beams (`sim::thin`; 0: none).
    pub thinned_share: f64,
}

/// The simulator's generations; a new one never changes what an older one writes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum World {
    /// JRDB-like corridors, halls and plazas seen by JRDB's two VLP-16 at a fixed height.
    #[default]
    V1,
    /// Streets, campuses and furnished indoor places, a varied crowd, one of eleven rigs (nine sensor
    /// models, JRDB's pair among them) on a car, robot or mast 0.3–2.2 m up and tipped a few degrees, the platform's
    /// own body in view; each cloud written levelled, the ground under the platform at the base
    /// frame's floor (`World::V2` writes it as the upper sensor's cloud; the lower one is empty).
    V2,
    /// Real scans with their people removed (`SynthConfig::backdrops`), simulated people ray-cast
    /// into them with each scan's sensor model (`backdrop`); training sequences only.
    Backdrops,
}

/// Names of simulated sequences.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Naming {
    /// JRDB's own names (train names, every fourth from the second a validation name), so JRDB's
    /// default split applies; the kind of place is read from the name. At most 27 distinct.
    #[default]
    Jrdb,
    /// `sim-<train|val>-<corridor|hall|plaza>-NNN`: every fourth sequence from the second is a
    /// validation one (select them with `sim-val-*`), places in turn (2 halls, 2 plazas, 1
    /// corridor in 5), any number of sequences.
    Benchmark,
    /// As `benchmark`, with bench-v2's places in turn: 2 streets, 2 campuses, a hall, a plaza
    /// and a corridor in 7.
    Places,
}

/// The named simulated benchmarks.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Preset {
    /// `bench-v1`: 160 sequences (one scene each) of 10 frames a third of a second apart, 0–40
    /// people; 120 training sequences (1,200 frames) and 40 validation ones (400 frames) from
    /// scenes disjoint from them.
    BenchV1,
    /// `bench-v2`: as large (160 sequences of 10 frames, 120 for training, 40 for validation), in
    /// [`World::V2`]: streets, campuses and cluttered indoor places, many sensors and platforms.
    BenchV2,
}

impl Preset {
    /// The name configs and the CLI use (`bench-v1`).
    pub fn name(self) -> &'static str {
        match self {
            Preset::BenchV1 => "bench-v1",
            Preset::BenchV2 => "bench-v2",
        }
    }

    /// The preset's simulation with `seed`.
    pub fn synth(self, seed: u64) -> SynthConfig {
        match self {
            Preset::BenchV1 => SynthConfig {
                sequences: 160,
                frames: 10,
                seed,
                max_people: 40,
                frame_step: 5,
                naming: Naming::Benchmark,
                ..SynthConfig::default()
            },
            Preset::BenchV2 => SynthConfig {
                sequences: 160,
                frames: 10,
                seed,
                max_people: 40,
                frame_step: 5,
                naming: Naming::Places,
                world: World::V2,
                ..SynthConfig::default()
            },
        }
    }
}

impl Default for SynthConfig {
    fn default() -> Self {
        Self {
            sequences: 2,
            frames: 10,
            seed: 0,
            max_people: 40,
            fps: 15.0,
            encoding: Encoding::Binary,
            label_range: 35.0,
            frame_step: 1,
            naming: Naming::Jrdb,
            world: World::V1,
            backdrops: None,
            thinned_share: 0.0,
        }
    }
}

/// What `synth` wrote.
#[derive(Debug, Clone, Default, PartialEq, serde::Serialize)]
pub struct SynthSummary {
    /// The sequences' names.
    pub sequences: Vec<String>,
    /// Frames in all.
    pub frames: usize,
    /// Points in all (both sensors).
    pub points: usize,
    /// Labelled boxes in all.
    pub boxes: usize,
}

/// JRDB sequence names for simulated sequences: train names with every fourth (from the second)
/// a validation name, so the default split has train and val sequences as soon as there are two.
pub fn sequence_names(n: usize) -> Vec<String> {
    let (mut t, mut v) = (DEFAULT_TRAIN_SEQUENCES.iter(), DEFAULT_VAL_SEQUENCES.iter());
    (0..n)
        .map(|i| {
            let pick = if i % 4 == 1 { v.next().or_else(|| t.next()) } else { t.next().or_else(|| v.next()) };
            pick.map_or_else(|| format!("sim-extra-{i:03}_0"), |s| s.to_string())
        })
        .collect()
}

/// The sequence names `naming` gives `n` sequences.
pub fn names_for(naming: Naming, n: usize) -> Vec<String> {
    match naming {
        Naming::Jrdb => sequence_names(n),
        Naming::Benchmark => (0..n)
            .map(|i| {
                let split = if i % 4 == 1 { "val" } else { "train" };
                let place = ["hall", "plaza", "hall", "plaza", "corridor"][i % 5];
                format!("sim-{split}-{place}-{i:03}")
            })
            .collect(),
        Naming::Places => (0..n)
            .map(|i| {
                let split = if i % 4 == 1 { "val" } else { "train" };
                let place = ["street", "campus", "hall", "street", "plaza", "campus", "corridor"][i % 7];
                format!("sim-{split}-{place}-{i:03}")
            })
            .collect(),
    }
}

pub(super) fn mix(a: u64, b: u64) -> u64 {
    let mut z = a ^ b.wrapping_mul(0x9E37_79B9_7F4A_7C15).wrapping_add(0x632B_E59B_D9B4_E019);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// One LiDAR's cloud as a PCD: x, y, z as written, the returns' intensity and ring.
pub(super) fn write_cloud(path: &Path, xyz: &[[f32; 3]], rets: &[Return], encoding: Encoding) -> Result<()> {
    let col = |name: &str, ty, values: Vec<f64>| Column { name: name.into(), ty, values };
    let cols = [
        col("x", FieldType::F32, xyz.iter().map(|p| p[0] as f64).collect()),
        col("y", FieldType::F32, xyz.iter().map(|p| p[1] as f64).collect()),
        col("z", FieldType::F32, xyz.iter().map(|p| p[2] as f64).collect()),
        col("intensity", FieldType::F32, rets.iter().map(|r| r.intensity as f64).collect()),
        col("ring", FieldType::U16, rets.iter().map(|r| r.ring as f64).collect()),
    ];
    write_pcd(path, &cols, encoding)
}

/// Person `id`'s label for base-frame box `b`, its points counted among the frame's.
pub(super) fn label(id: usize, b: Box3d, base_points: &[[f32; 3]]) -> Label {
    let num_points = b.count_inside(base_points) as i64;
    let observation_angle = b.cy.atan2(b.cx) - b.rot_z;
    Label { id: format!("pedestrian:{id}"), bbox: b, num_points, observation_angle }
}

pub(super) fn mkdir(p: &Path) -> Result<()> {
    std::fs::create_dir_all(p).map_err(|e| DataError::io(p, e))
}

/// Writes a simulated JRDB-format tree under `out` (a plain root: `out/pointclouds/...`).
pub fn synth(out: &Path, cfg: &SynthConfig) -> Result<SynthSummary> {
    if cfg.frame_step == 0 {
        return Err(DataError::key(out, "frame_step", "must be at least 1"));
    }
    if !(0.0..=1.0).contains(&cfg.thinned_share) {
        return Err(DataError::key(out, "thinned_share", format!("{} is not a share between 0 and 1", cfg.thinned_share)));
    }
    if cfg.thinned_share > 0.0 && cfg.world != World::Backdrops {
        return Err(DataError::key(out, "thinned_share", "thins real backdrops: set `backdrops` too"));
    }
    let layout = Layout { root: out.to_path_buf() };
    let calib = Calibration::default();
    mkdir(&out.join("calibration"))?;
    calib.write(&layout.calibration_file())?;
    mkdir(&out.join("labels").join("labels_3d"))?;
    if cfg.world == World::Backdrops {
        let dir = cfg.backdrops.as_deref().ok_or_else(|| DataError::key(out, "backdrops", "the backdrops world needs a folder of real scans"))?;
        let backdrops = super::backdrop::read_backdrops(dir)?;
        let (sequences, frames, points, boxes) = super::backdrop::synth_backdrops(&layout, &backdrops, cfg, &calib)?;
        return Ok(SynthSummary { sequences, frames, points, boxes });
    }
    let names = names_for(cfg.naming, cfg.sequences);
    let mut summary = SynthSummary { sequences: names.clone(), ..Default::default() };
    // Sequences one after another; the rays of each scan run in parallel.
    let mut clutter = Vec::new();
    for (si, seq) in names.iter().enumerate() {
        let (f, p, b) = match cfg.world {
            World::V1 => synth_sequence(&layout, seq, si as u64, cfg, &calib)?,
            World::Backdrops => unreachable!("written above"),
            World::V2 => {
                let (f, p, b, c) = super::world_v2::synth_sequence(&layout, seq, si as u64, cfg, &calib)?;
                clutter.push(c);
                (f, p, b)
            }
        };
        summary.frames += f;
        summary.points += p;
        summary.boxes += b;
    }
    if cfg.world == World::V2 {
        super::world_v2::write_rigs(out, &names, cfg.seed, &clutter)?;
    }
    Ok(summary)
}

fn synth_sequence(layout: &Layout, seq: &str, index: u64, cfg: &SynthConfig, calib: &Calibration) -> Result<(usize, usize, usize)> {
    for l in Lidar::BOTH {
        mkdir(&layout.cloud_dir(l, seq))?;
    }
    mkdir(layout.timestamps_file(seq).parent().unwrap())?;
    let seq_seed = mix(cfg.seed, index);
    let mut rng = ChaCha8Rng::seed_from_u64(seq_seed);
    let mut scene = Scene::generate(SceneKind::for_sequence(seq), cfg.max_people, &mut rng);
    let lidar = Scanner::default();
    let dt = 1.0 / cfg.fps;
    let t0 = 1_550_000_000.0 + index as f64 * 10_000.0;
    let mut labels = BTreeMap::new();
    let mut times = Vec::new();
    let (mut n_points, mut n_boxes) = (0, 0);
    for fi in 0..cfg.frames {
        if fi > 0 {
            for _ in 0..cfg.frame_step {
                scene.step(dt, &mut rng);
            }
        }
        let (people, views) = scene.people_now();
        let prims: Vec<_> = scene.statics.iter().copied().chain(people).collect();
        let name = format!("{fi:06}");
        // Base-frame points exactly as the reader will compute them from the written f32 values.
        let mut base_points: Vec<[f32; 3]> = Vec::new();
        let clouds: Vec<_> = Lidar::BOTH
            .par_iter()
            .map(|&l| {
                let t = calib.lidar(l);
                let origin = scene.to_world(t.origin());
                let scan_seed = mix(seq_seed, (fi as u64) * 2 + l as u64 + 1);
                (l, lidar.scan(&prims, origin, scene.robot[2] + t.yaw, scan_seed))
            })
            .collect();
        for (l, rets) in clouds {
            let t = calib.lidar(l);
            let xyz: Vec<[f32; 3]> = rets.iter().map(|r| [r.xyz[0] as f32, r.xyz[1] as f32, r.xyz[2] as f32]).collect();
            base_points.extend(xyz.iter().map(|&p| t.to_base(p)));
            write_cloud(&layout.cloud_dir(l, seq).join(format!("{name}.pcd")), &xyz, &rets, cfg.encoding)?;
        }
        n_points += base_points.len();
        let mut frame_labels = Vec::new();
        for v in &views {
            let b = scene.box_to_base(&v.bbox);
            if b.bev_range() > cfg.label_range {
                continue;
            }
            frame_labels.push(label(v.id, b, &base_points));
        }
        n_boxes += frame_labels.len();
        labels.insert(format!("{name}.pcd"), frame_labels);
        times.push(FrameTime { frame_id: fi as u64, timestamp: t0 + (fi * cfg.frame_step) as f64 * dt });
    }
    write_labels(&layout.labels_file(seq), &labels)?;
    write_timestamps(&layout.timestamps_file(seq), seq, &times)?;
    Ok((cfg.frames, n_points, n_boxes))
}
