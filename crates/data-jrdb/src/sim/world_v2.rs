//! Writes one `bench-v2` sequence: a rig drawn for the place, its platform's body in the scene,
//! each scan levelled into the base frame with the small height and tilt errors a ground fit
//! leaves, and the labels moved the same way.

use std::collections::BTreeMap;

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::geometry::V3;
use super::lidar::{Scanner, tip, untip};
use super::rig::{Platform, Rig};
use super::scene::{Prim, Scene, SceneKind};
use super::writer::{SynthConfig, label, mix, mkdir, write_cloud};
use crate::calibration::{Calibration, Lidar};
use crate::error::Result;
use crate::labels::write_labels;
use crate::split::Layout;
use crate::timestamps::{FrameTime, write_timestamps};

/// The floor's height in JRDB's base frame, where every detector learned people stand.
const FLOOR: f64 = -0.7;

/// A roughly normal draw (sum of three uniforms) with standard deviation `sd`.
fn normalish<R: Rng + ?Sized>(rng: &mut R, sd: f64) -> f64 {
    (rng.random_range(-1.0..1.0) + rng.random_range(-1.0..1.0) + rng.random_range(-1.0..1.0)) * sd
}

/// Writes the sequence; returns its frames, points, boxes and its first frame's clutter (see
/// [`write_rigs`]).
pub(super) fn synth_sequence(layout: &Layout, seq: &str, index: u64, cfg: &SynthConfig, calib: &Calibration) -> Result<(usize, usize, usize, (usize, usize))> {
    for l in Lidar::BOTH {
        mkdir(&layout.cloud_dir(l, seq))?;
    }
    mkdir(layout.timestamps_file(seq).parent().unwrap())?;
    let seq_seed = mix(cfg.seed, index);
    let mut rng = ChaCha8Rng::seed_from_u64(seq_seed);
    let kind = SceneKind::for_sequence(seq);
    let rig = rig_for(cfg.seed, index, kind);
    let keep_clear = match rig.platform {
        Platform::Car => 3.2,
        Platform::Robot | Platform::JrdbRobot => 0.9,
        Platform::Mast => 0.5,
    };
    let mut scene = Scene::generate_v2(kind, cfg.max_people, FLOOR, rig.platform == Platform::Car, keep_clear, &mut rng);
    let clutter = scene.clutter_within(25.0);
    let dt = 1.0 / cfg.fps;
    let t0 = 1_600_000_000.0 + index as f64 * 10_000.0;
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
        let [rx, ry, ryaw] = scene.robot;
        let ground = scene.ground_at(rx, ry);
        let body = rig.body_at(rx, ry, ground, ryaw).into_iter().map(|(shape, reflectivity)| Prim { shape, reflectivity });
        let prims: Vec<Prim> = scene.statics.iter().copied().chain(scene.movers_now()).chain(body).chain(people).collect();
        // What a ground fit leaves: the floor a few centimetres off, the level a fraction of a degree.
        let dz = normalish(&mut rng, 0.02);
        let tilt_err = [normalish(&mut rng, 0.15f64.to_radians()), normalish(&mut rng, 0.15f64.to_radians())];
        let scan_seed = mix(seq_seed, fi as u64 * 2 + 1);
        // Base-frame points as the reader will compute them from the written f32 values.
        let mut base_points: Vec<[f32; 3]> = Vec::new();
        let name = format!("{fi:06}");
        // The levelled frame's map of a true, level offset from the sensor: tipped back by the
        // true tilt, then levelled by the estimated one.
        let est = [rig.tilt[0] + tilt_err[0], rig.tilt[1] + tilt_err[1]];
        let relevel = |p: V3| tip(untip(p, rig.tilt), est);
        let sensor_z = FLOOR + rig.height + dz;
        if rig.is_jrdb() {
            for l in Lidar::BOTH {
                let t = calib.lidar(l);
                let o = t.origin();
                let origin = scene.to_world([o[0], o[1], o[2] + ground - scene.floor]);
                let rets = Scanner::default().scan(&prims, origin, ryaw + t.yaw, mix(scan_seed, l as u64));
                let xyz: Vec<[f32; 3]> = rets.iter().map(|r| [r.xyz[0] as f32, r.xyz[1] as f32, (r.xyz[2] + dz) as f32]).collect();
                base_points.extend(xyz.iter().map(|&p| t.to_base(p)));
                write_cloud(&layout.cloud_dir(l, seq).join(format!("{name}.pcd")), &xyz, &rets, cfg.encoding)?;
            }
        } else {
            let origin = [rx, ry, ground + rig.height];
            let rets = rig.sensor.scanner().scan_beams(&rig.sensor.elevations(), &prims, origin, ryaw, Some(rig.tilt), scan_seed);
            let upper = calib.lidar(Lidar::Upper);
            let xyz: Vec<[f32; 3]> = rets
                .iter()
                .map(|r| {
                    let p = tip(r.xyz, est);
                    let s = upper.to_sensor([p[0], p[1], p[2] + sensor_z]);
                    [s[0] as f32, s[1] as f32, s[2] as f32]
                })
                .collect();
            base_points.extend(xyz.iter().map(|&p| upper.to_base(p)));
            write_cloud(&layout.cloud_dir(Lidar::Upper, seq).join(format!("{name}.pcd")), &xyz, &rets, cfg.encoding)?;
            write_cloud(&layout.cloud_dir(Lidar::Lower, seq).join(format!("{name}.pcd")), &[], &[], cfg.encoding)?;
        }
        n_points += base_points.len();
        let mut frame_labels = Vec::new();
        for v in &views {
            let mut b = scene.box_to_base(&v.bbox);
            // Levelled as the points were: the true offset from the sensor, re-levelled.
            let true_z = FLOOR + rig.height + (ground - scene.floor);
            let c = if rig.is_jrdb() { [b.cx, b.cy, b.cz - (ground - scene.floor) + dz] } else {
                let q = relevel([b.cx, b.cy, b.cz - true_z]);
                [q[0], q[1], q[2] + sensor_z]
            };
            (b.cx, b.cy, b.cz) = (c[0], c[1], c[2]);
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
    Ok((cfg.frames, n_points, n_boxes, clutter))
}

/// The rig of sequence `index` (its own stream, so it can be read back without the scene).
pub fn rig_for(seed: u64, index: u64, kind: SceneKind) -> Rig {
    let mut rng = ChaCha8Rng::seed_from_u64(mix(mix(seed, index), 0x5249_4721));
    Rig::sample(!matches!(kind, SceneKind::Corridor | SceneKind::Hall), &mut rng)
}

/// `rigs.csv` at the tree's root: each sequence's sensor, platform, height and tilt, and the
/// objects other than people within 25 m of the sensor in its first frame (`clutter`: an object's
/// footprint, a parked vehicle counting twice) and passing vehicles.
pub(super) fn write_rigs(out: &std::path::Path, names: &[String], seed: u64, clutter: &[(usize, usize)]) -> Result<()> {
    let mut text = String::from("sequence,sensor,platform,height_m,roll_deg,pitch_deg,clutter_25m,vehicles_moving_25m\n");
    for (i, seq) in names.iter().enumerate() {
        let r = rig_for(seed, i as u64, SceneKind::for_sequence(seq));
        let (c, m) = clutter.get(i).copied().unwrap_or_default();
        text += &format!("{seq},{},{},{:.3},{:.2},{:.2},{c},{m}\n", r.sensor_name(), r.platform.name(), r.height, r.tilt[0].to_degrees(), r.tilt[1].to_degrees());
    }
    let path = out.join("rigs.csv");
    std::fs::write(&path, text).map_err(|e| crate::error::DataError::io(&path, e))
}
