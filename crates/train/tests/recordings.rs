//! `detect` on recordings written by the reference tools (`tests/fixtures/recordings/`,
//! `tools/make_recording_fixtures.py`): an MCAP by Python's `mcap` + `mcap-ros2-support`, a ROS 1
//! bag (bz2 chunks) and a ROS 2 bag in SQLite (`.db3`) by Python's `rosbags`, each holding a real
//! scan as PointCloud2 in three layouts (a Velodyne driver's, an organised cloud with missing
//! returns, float64 big-endian). Every message gives the boxes `detect` gives on the same points
//! as an `.npy`, with its stamp and frame id; topics are listed; a topic that holds no clouds, a
//! missing `--topic` and a damaged file are named, never a panic.

mod common;

use std::path::{Path, PathBuf};

use common::{ok, report, train_bin};
use data_jrdb::encode_npy;
use train::FrameReport;

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

fn fixture() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/recordings/clouds.mcap")
}

/// The three storages: (path given to `detect`, the name its outputs take, the cloud type name).
fn fixtures() -> [(PathBuf, &'static str, &'static str); 3] {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/recordings");
    [
        (dir.join("clouds.mcap"), "clouds", "sensor_msgs/msg/PointCloud2\tcdr"),
        (dir.join("clouds.bag"), "clouds", "sensor_msgs/PointCloud2\tros1"),
        // A ROS 2 bag folder (metadata.yaml beside its .db3) is given as the folder.
        (dir.join("clouds_db3"), "clouds_db3", "sensor_msgs/msg/PointCloud2\tcdr"),
    ]
}

/// The fixture's points: every 4th point of the real nuScenes scan, as the script took them.
fn scan_npy(dir: &Path) -> PathBuf {
    let bytes = std::fs::read(root().join("real-scans/nuscenes/1532402927647951.npy")).unwrap();
    let cloud = data_jrdb::cloud::parse_cloud(&bytes, data_jrdb::CloudFormat::Npy).unwrap();
    let pts: Vec<[f32; 3]> = cloud.points.iter().step_by(4).copied().collect();
    let data: Vec<u8> = pts.iter().flatten().flat_map(|v| v.to_le_bytes()).collect();
    let path = dir.join("scan.npy");
    std::fs::write(&path, encode_npy("<f4", &format!("({}, 3)", pts.len()), &data)).unwrap();
    path
}

#[test]
fn every_message_gives_the_boxes_of_its_points_with_its_stamp() {
    let tmp = tempfile::tempdir().unwrap();
    let npy = scan_npy(tmp.path());
    let plain = tmp.path().join("plain");
    // A low threshold: a quarter of the scan's points leaves few confident boxes to compare.
    ok(&["detect", npy.to_str().unwrap(), "--out", plain.to_str().unwrap(), "--score-threshold", "0.05"]);
    let want = report(&plain.join("json/scan.json"));
    assert!(want.detections.len() >= 3, "boxes to compare: {:?}", want.detections);
    for (recording, name, cloud_type) in fixtures() {
        let r = recording.to_str().unwrap();
        let topics = String::from_utf8(ok(&["detect", r, "--list-topics"]).stdout).unwrap();
        for line in [format!("/velodyne_points\t{cloud_type}\t2"), format!("/ouster/points\t{cloud_type}\t1")] {
            assert!(topics.contains(&line), "{line} in:\n{topics}");
        }
        assert!(topics.contains("/camera/info\tstd_msgs/"), "{topics}");
        for (topic, messages, frame_id, nan) in [("/velodyne_points", 2, "lidar_top", false), ("/ouster/points", 1, "os_sensor", true), ("/be64/points", 1, "lidar_top", false)] {
            let out = tmp.path().join(format!("{name}{}", topic.replace('/', "_")));
            ok(&["detect", r, "--topic", topic, "--out", out.to_str().unwrap(), "--score-threshold", "0.05"]);
            let lines: Vec<FrameReport> = std::fs::read_to_string(out.join(format!("{name}.jsonl"))).unwrap().lines().map(|l| serde_json::from_str(l).unwrap()).collect();
            assert_eq!(lines.len(), messages, "{r} {topic}");
            for (i, line) in lines.iter().enumerate() {
                let m = line.message.as_ref().expect("a recording's report says its message");
                assert_eq!((m.topic.as_str(), m.index, m.frame_id.as_str()), (topic, i, frame_id), "{r}");
                assert!(m.stamp > 1.5e9 && (m.stamp.fract() - 0.25).abs() < 1e-6, "{r} {topic}: stamp {}", m.stamp);
                assert_eq!(*line, report(&out.join(format!("json/{name}/{i:06}.json"))), "the line is the frame's JSON");
                assert!(out.join(format!("kitti/{name}/{i:06}.txt")).is_file());
                assert_eq!(line.points, want.points, "{r} {topic}");
                assert_eq!(line.dropped_non_finite > 0, nan, "{r} {topic}: missing returns dropped");
                assert_eq!(line.detections, want.detections, "{r} {topic} message {i}: the .npy's boxes");
            }
        }
    }
}

#[test]
fn the_scene_mcap_holds_the_clouds_and_the_boxes_of_the_json() {
    for (recording, name, cloud_type) in fixtures() {
        let tmp = tempfile::tempdir().unwrap();
        let (out, scene) = (tmp.path().join("o"), tmp.path().join("scene.mcap"));
        ok(&["detect", recording.to_str().unwrap(), "--topic", "/velodyne_points", "--out", out.to_str().unwrap(), "--mcap", scene.to_str().unwrap(), "--score-threshold", "0.05"]);
        // The clouds are copied as they were stored: ROS 1's serialization with its bag's definition,
        // CDR with the ros2msg definition.
        let (schema, encoding) = cloud_type.split_once('\t').unwrap();
        let bytes = std::fs::read(&scene).unwrap();
        let (mut clouds, mut updates) = (0, Vec::new());
        for m in mcap::MessageStream::new(&bytes).unwrap() {
            let m = m.unwrap();
            match m.channel.topic.as_str() {
                "/velodyne_points" => {
                    let s = m.channel.schema.as_ref().unwrap();
                    assert_eq!((s.name.as_str(), m.channel.message_encoding.as_str()), (schema, encoding));
                    assert_eq!(s.encoding, if encoding == "ros1" { "ros1msg" } else { "ros2msg" });
                    assert!(String::from_utf8_lossy(&s.data).contains("uint32 point_step"));
                    clouds += 1;
                }
                "/pmunet/people" => {
                    assert_eq!((m.channel.schema.as_ref().unwrap().name.as_str(), m.channel.message_encoding.as_str()), ("foxglove.SceneUpdate", "json"));
                    updates.push(serde_json::from_slice::<serde_json::Value>(&m.data).unwrap());
                }
                other => panic!("unexpected topic {other}"),
            }
        }
        assert_eq!((clouds, updates.len()), (2, 2));
        // The scene is itself a recording: read back (ROS 1 clouds in an MCAP included), its
        // clouds give the same boxes.
        let again = tmp.path().join("again");
        ok(&["detect", scene.to_str().unwrap(), "--topic", "/velodyne_points", "--out", again.to_str().unwrap(), "--score-threshold", "0.05"]);
        for i in 0..2 {
            let (a, b) = (report(&out.join(format!("json/{name}/{i:06}.json"))), report(&again.join(format!("json/scene/{i:06}.json"))));
            assert_eq!((a.points, a.detections), (b.points, b.detections), "{name}: message {i} read back from the scene");
        }
        assert!(updates.iter().all(|u| !u["entities"][0]["cubes"].as_array().unwrap().is_empty()), "boxes to compare");
        for (i, u) in updates.iter().enumerate() {
            let want = report(&out.join(format!("json/{name}/{i:06}.json")));
            let e = &u["entities"][0];
            assert_eq!(e["frame_id"], "lidar_top");
            assert_eq!((e["timestamp"]["sec"].as_i64(), e["timestamp"]["nsec"].as_u64()), (Some(1_532_402_927 + i as i64), Some(250_000_000)));
            let cubes = e["cubes"].as_array().unwrap();
            assert_eq!(cubes.len(), want.detections.len());
            for (c, (d, t)) in cubes.iter().zip(want.detections.iter().zip(e["texts"].as_array().unwrap())) {
                let f = |v: &serde_json::Value| v.as_f64().unwrap();
                let yaw = 2.0 * f(&c["pose"]["orientation"]["z"]).atan2(f(&c["pose"]["orientation"]["w"]));
                let got = [f(&c["pose"]["position"]["x"]), f(&c["pose"]["position"]["y"]), f(&c["pose"]["position"]["z"]), f(&c["size"]["x"]), f(&c["size"]["y"]), f(&c["size"]["z"])];
                assert_eq!(got, [d.x, d.y, d.z, d.l, d.w, d.h]);
                assert!((yaw - d.yaw).rem_euclid(std::f64::consts::TAU).min((d.yaw - yaw).rem_euclid(std::f64::consts::TAU)) < 1e-9);
                assert_eq!(t["text"].as_str().unwrap(), format!("{:.2}", d.score));
            }
        }
    }
}

#[test]
fn what_is_not_a_cloud_topic_or_file_is_named() {
    let tmp = tempfile::tempdir().unwrap();
    let mcap = fixture();
    let m = mcap.to_str().unwrap();
    let out = tmp.path().join("o");
    let fail = |args: &[&str]| {
        let o = train_bin(args);
        assert!(!o.status.success() || !String::from_utf8_lossy(&o.stderr).is_empty(), "{args:?}");
        String::from_utf8_lossy(&o.stderr).into_owned()
    };
    let e = fail(&["detect", m, "--out", out.to_str().unwrap()]);
    assert!(e.contains("give --topic") && e.contains("/velodyne_points [sensor_msgs/msg/PointCloud2]"), "{e}");
    let e = fail(&["detect", m, "--topic", "/camera/info", "--out", out.to_str().unwrap()]);
    assert!(e.contains("holds std_msgs/msg/String"), "{e}");
    let e = fail(&["detect", m, "--topic", "/nope", "--out", out.to_str().unwrap()]);
    assert!(e.contains("no topic `/nope`"), "{e}");
    // A recording cut short: named, never a panic.
    let bytes = std::fs::read(&mcap).unwrap();
    let cut = tmp.path().join("cut.mcap");
    std::fs::write(&cut, &bytes[..bytes.len() / 2]).unwrap();
    let o = train_bin(&["detect", cut.to_str().unwrap(), "--topic", "/velodyne_points", "--out", out.to_str().unwrap()]);
    let e = String::from_utf8_lossy(&o.stderr);
    assert!(e.contains("cut.mcap") && !e.contains("panicked"), "{e}");
    let o = train_bin(&["detect", cut.to_str().unwrap(), "--list-topics"]);
    assert!(!String::from_utf8_lossy(&o.stderr).contains("panicked"));
    // The same for a ROS 1 bag and a ROS 2 SQLite bag cut short, and a file of garbage.
    let dir = mcap.parent().unwrap();
    for (from, to) in [("clouds.bag", "cut.bag"), ("clouds_db3/clouds_db3.db3", "cut.db3")] {
        let bytes = std::fs::read(dir.join(from)).unwrap();
        for (what, data) in [("cut", &bytes[..bytes.len() / 2]), ("garbage", &[7u8; 4096][..])] {
            let path = tmp.path().join(format!("{what}-{to}"));
            std::fs::write(&path, data).unwrap();
            for args in [vec!["--topic", "/velodyne_points", "--out", out.to_str().unwrap()], vec!["--list-topics"]] {
                let o = train_bin(&[&["detect", path.to_str().unwrap()][..], &args].concat());
                let e = String::from_utf8_lossy(&o.stderr);
                assert!(!o.status.success() && e.contains(&format!("{what}-{to}")) && !e.contains("panicked"), "{what} {to} {args:?}: {e}");
            }
        }
    }
}
