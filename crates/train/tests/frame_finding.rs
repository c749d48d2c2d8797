//! `detect`'s default frame finding (`FrameSpec::default()`, `auto`) on ray-cast scans whose ground
//! lies at different heights and tilts below the sensor: a robot's VLP-16 0.35 m up in a hall, a
//! mast's Ouster in a campus, cars' sensors 1.5–2.2 m up in streets with their own roofs in view,
//! each tipped up to 3° both ways. The fit must put the ground where the models learned it
//! (z = −0.7 in the base frame) and level the scan to a fraction of a degree. On a street the
//! plane found may lie between the road the car stands on and a sidewalk 8–20 cm higher.

use data_jrdb::sim::geometry::V3;
use data_jrdb::sim::lidar::tip;
use data_jrdb::sim::objects::placed;
use data_jrdb::sim::scene::{Prim, Scene, SceneKind};
use data_jrdb::sim::sensors::SensorModel;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use train::FrameSpec;
use train::sensor_pose::BASE_FLOOR_Z;

/// A scan in the sensor's own frame, the sensor's true height above the ground under it, and
/// every ground level within the search ring relative to that ground (a street's sidewalks).
fn scan(kind: SceneKind, on_road: bool, sensor: SensorModel, height: f64, tilt: [f64; 2], seed: u64) -> (Vec<[f32; 3]>, f64, Vec<f64>) {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let scene = Scene::generate_v2(kind, 20, BASE_FLOOR_Z, on_road, 3.0, &mut rng);
    let (people, _) = scene.people_now();
    let [x, y, yaw] = scene.robot;
    let ground = scene.ground_at(x, y);
    // A car's body under a roof sensor, so the fit must look past it.
    let roof: Vec<Prim> = if on_road {
        let body = vec![(data_jrdb::sim::objects::cuboid(-0.3, 0.0, 0.2, 4.6, 1.85, height - 0.45, 0.0), 0.5f32)];
        placed(body, x, y, ground, yaw).into_iter().map(|(shape, reflectivity)| Prim { shape, reflectivity }).collect()
    } else {
        Vec::new()
    };
    let prims: Vec<Prim> = scene.statics.iter().copied().chain(scene.movers_now()).chain(roof).chain(people).collect();
    let rets = sensor.scanner().scan_beams(&sensor.elevations(), &prims, [x, y, ground + height], yaw, Some(tilt), seed);
    let mut levels: Vec<f64> = Vec::new();
    for k in 0..2000 {
        let (r, a) = (2.0 + (k % 56) as f64 * 0.5, k as f64 * 0.61);
        let level = scene.ground_at(x + r * a.cos(), y + r * a.sin()) - ground;
        if !levels.iter().any(|l| (l - level).abs() < 1e-9) {
            levels.push(level);
        }
    }
    (rets.iter().map(|r| r.xyz.map(|v| v as f32)).collect(), height, levels)
}

#[test]
fn the_ground_is_found_at_every_height_and_tilt() {
    let deg = |d: f64| d.to_radians();
    let cases = [
        (SceneKind::Hall, false, SensorModel::Vlp16, 0.35, [deg(2.0), deg(-1.5)]),
        (SceneKind::Corridor, false, SensorModel::Os0_128, 0.6, [deg(-3.0), deg(0.0)]),
        (SceneKind::Campus, false, SensorModel::Os1_64, 1.2, [deg(0.0), deg(3.0)]),
        (SceneKind::Street, true, SensorModel::Hdl32e, 1.84, [deg(1.0), deg(1.0)]),
        (SceneKind::Street, true, SensorModel::Pandar128, 2.2, [deg(-2.5), deg(-2.0)]),
        (SceneKind::Plaza, false, SensorModel::Vlp32c, 1.6, [deg(0.5), deg(-3.0)]),
    ];
    for (i, (kind, on_road, sensor, height, tilt)) in cases.into_iter().enumerate() {
        let (points, h, levels) = scan(kind, on_road, sensor, height, tilt, 100 + i as u64);
        let placement = FrameSpec::default().place(&points);
        let what = format!("{kind:?} {} at {h} m tipped {:?}°: {}", sensor.name(), tilt.map(f64::to_degrees), placement.how);
        assert!(placement.how.starts_with("ground:"), "{what}");
        let pose = placement.pose;
        // Off the street: the platform's own ground, to 4 cm, and every return within 20 m
        // moved as the truth moves it to 3 cm plus 4 mm a metre. On a street whose road parked
        // cars and the car's own body hide, the plane can fall between the road and a sidewalk
        // 10–20 cm above it: within 10 cm of one of them.
        let street = kind == SceneKind::Street;
        let tol_z = if street { 0.10 } else { 0.04 };
        let level = levels.iter().copied().min_by(|a, b| (pose.translation[2] - (h - a + BASE_FLOOR_Z)).abs().total_cmp(&(pose.translation[2] - (h - b + BASE_FLOOR_Z)).abs())).unwrap();
        let level = if street { level } else { 0.0 };
        assert!((pose.translation[2] - (h - level + BASE_FLOOR_Z)).abs() < tol_z, "{what}: z {} for levels {levels:?}", pose.translation[2]);
        if street {
            // A plane between two grounds leans by up to their step over its width: the level
            // to within a degree.
            let (roll, pitch) = (pose.roll - tilt[0], pose.pitch - tilt[1]);
            assert!(roll.hypot(pitch).to_degrees() < 1.0, "{what}: levelled {:?}° off", [roll.to_degrees(), pitch.to_degrees()]);
            continue;
        }
        for p in points.iter().step_by(37).filter(|p| p[0].hypot(p[1]) < 20.0) {
            let want: V3 = tip(p.map(f64::from), tilt);
            let got = pose.to_base(*p);
            let err = (0..3).map(|k| (got[k] as f64 - [want[0], want[1], want[2] + h - level + BASE_FLOOR_Z][k]).abs()).fold(0.0, f64::max);
            assert!(err < 0.03 + 0.004 * p[0].hypot(p[1]) as f64, "{what}: {p:?} went to {got:?}, truth {want:?}");
        }
    }
}

#[test]
fn a_given_pose_is_kept_and_no_ground_is_said() {
    let sky: Vec<[f32; 3]> = (0..800).map(|i| [5.0 + (i % 40) as f32 * 0.1, (i / 40) as f32 * 0.1, 2.0]).collect();
    let placement = FrameSpec::default().place(&sky);
    assert!(placement.how.starts_with("no ground"), "{}", placement.how);
    assert!(placement.pose.is_identity());
    let given: FrameSpec = "z=0.3".parse().unwrap();
    assert_eq!(given.place(&sky).how, "given");
    let identity: FrameSpec = "identity".parse().unwrap();
    assert!(!identity.auto && identity.pose.is_identity());
}
