//! `detect` and `serve` end to end through the binary, on the shipped weights, frames the
//! simulator wrote and a frame other tools wrote (pypcd4, NumPy): `detect` on a JRDB-format tree gives `infer`'s boxes; the same frame written
//! as PCD (three encodings, with NaN points and extra fields), KITTI `.bin` and `.npy` gives the
//! same boxes; a sensor pose moves them as it moves the points; bad inputs are named and the
//! others still written; the service under concurrent clients answers every valid body with
//! `detect`'s boxes, every malformed one with a 4xx, and stays healthy.

mod common;

use std::collections::BTreeMap;
use std::io::{BufRead, BufReader, Read, Write};
use std::net::TcpStream;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::Duration;

use data_jrdb::pcd::{Column, Encoding, FieldType, encode_pcd};
use data_jrdb::sim::{SynthConfig, synth};
use data_jrdb::{DatasetConfig, Dataset, Split, encode_npy};
use eval::jrdb::read_detections;
use common::{ok, report, train_bin};
use train::{BoxRecord, FrameReport};

fn weights() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../weights/person_minkunet")
}

/// A small simulated tree and its frames merged into the base frame.
fn tree(dir: &Path) -> (PathBuf, Vec<data_jrdb::Frame>) {
    let root = dir.join("sim");
    synth(&root, &SynthConfig { sequences: 1, frames: 2, seed: 11, max_people: 12, ..Default::default() }).unwrap();
    let ds = Dataset::open(&root, &DatasetConfig { split: Split::TrainVal, require_labels: false, ..Default::default() }).unwrap();
    let frames = (0..ds.len()).map(|i| ds.load(i).unwrap()).collect();
    (root, frames)
}

fn xyz_columns(points: &[[f32; 3]]) -> Vec<Column> {
    ["x", "y", "z"]
        .iter()
        .enumerate()
        .map(|(k, n)| Column { name: n.to_string(), ty: FieldType::F32, values: points.iter().map(|p| p[k] as f64).collect() })
        .collect()
}

/// A PCD with an intensity field between y and z, a ring field, and NaN points spread through.
fn pcd_with_extras_and_nans(points: &[[f32; 3]], encoding: Encoding) -> Vec<u8> {
    let mut rows: Vec<[f64; 5]> = Vec::new();
    for (i, p) in points.iter().enumerate() {
        if i % 1000 == 0 {
            rows.push([f64::NAN, f64::NAN, f64::NAN, 0.0, 0.0]);
        }
        rows.push([p[0] as f64, p[1] as f64, p[2] as f64, (i % 255) as f64, (i % 16) as f64]);
    }
    let col = |name: &str, ty, k: usize| Column { name: name.into(), ty, values: rows.iter().map(|r| r[k]).collect() };
    encode_pcd(&[col("x", FieldType::F32, 0), col("y", FieldType::F32, 1), col("intensity", FieldType::F32, 3), col("z", FieldType::F32, 2), col("ring", FieldType::U16, 4)], encoding)
}

fn kitti_bin(points: &[[f32; 3]]) -> Vec<u8> {
    points.iter().flat_map(|p| [p[0], p[1], p[2], 0.5f32]).flat_map(f32::to_le_bytes).collect()
}

/// An `.npy` (format 1.0) of `points` as N×cols, float32 or float64.
fn npy(points: &[[f32; 3]], cols: usize, f64s: bool) -> Vec<u8> {
    let mut data = Vec::new();
    for p in points {
        for &v in &[p[0], p[1], p[2], 1.0][..cols] {
            if f64s {
                data.extend((v as f64).to_le_bytes());
            } else {
                data.extend(v.to_le_bytes());
            }
        }
    }
    encode_npy(if f64s { "<f8" } else { "<f4" }, &format!("({}, {cols})", points.len()), &data)
}

fn assert_same_boxes(got: &[BoxRecord], want: &[BoxRecord], what: &str) {
    assert_eq!(got.len(), want.len(), "{what}: number of boxes");
    for (g, w) in got.iter().zip(want) {
        for (a, b) in [(g.x, w.x), (g.y, w.y), (g.z, w.z), (g.l, w.l), (g.w, w.w), (g.h, w.h), (g.yaw, w.yaw), (g.score, w.score)] {
            assert!((a - b).abs() < 1e-9, "{what}: {g:?} vs {w:?}");
        }
    }
}

#[test]
fn detect_gives_infers_boxes_in_every_input_format() {
    let tmp = tempfile::tempdir().unwrap();
    let (root, frames) = tree(tmp.path());
    let w = weights();
    let (w, r) = (w.to_str().unwrap(), root.to_str().unwrap());

    // The tree as `infer` scores it, and as `detect` reads it.
    let infer_out = tmp.path().join("infer");
    ok(&["infer", "--run", w, "--data-root", r, "--split", "train-val", "--out", infer_out.to_str().unwrap()]);
    let tree_out = tmp.path().join("tree-out");
    ok(&["detect", r, "--run", w, "--score-threshold", "0", "--render", "--out", tree_out.to_str().unwrap()]);
    let seq = &frames[0].sequence;
    let inferred = read_detections(&infer_out.join("json").join(format!("{seq}.json"))).unwrap();
    let mut total = 0;
    for f in &frames {
        let want: Vec<BoxRecord> = inferred.detections[&f.name].iter().map(|d| BoxRecord::new(&d.bbox, d.score)).collect();
        let got = report(&tree_out.join("json").join(seq).join(format!("{}.json", f.name)));
        assert_eq!((got.format.as_str(), got.points), ("jrdb", f.points.len()));
        assert_same_boxes(&got.detections, &want, &format!("tree frame {}", f.name));
        total += want.len();
        let txt = std::fs::read_to_string(tree_out.join("kitti").join(seq).join(format!("{}.txt", f.name))).unwrap();
        assert_eq!(txt.lines().count(), want.len());
        assert!(txt.lines().all(|l| l.starts_with("Pedestrian ")));
        let png = std::fs::read(tree_out.join("render").join(seq).join(format!("{}.png", f.name))).unwrap();
        assert!(png.starts_with(b"\x89PNG"));
    }
    assert!(total > 0, "the shipped weights find people in these frames");

    // Frame 0 in every format another tool might write.
    let points = &frames[0].points;
    let files = tmp.path().join("clouds");
    std::fs::create_dir_all(files.join("nested")).unwrap();
    let write = |name: &str, bytes: Vec<u8>| std::fs::write(files.join(name), bytes).unwrap();
    write("ascii.pcd", encode_pcd(&xyz_columns(points), Encoding::Ascii));
    write("binary.pcd", pcd_with_extras_and_nans(points, Encoding::Binary));
    write("nested/compressed.pcd", pcd_with_extras_and_nans(points, Encoding::BinaryCompressed));
    write("velodyne.bin", kitti_bin(points));
    write("n4_f32.npy", npy(points, 4, false));
    write("n3_f64.npy", npy(points, 3, true));
    write("notes.txt", b"not a cloud".to_vec());
    let files_out = tmp.path().join("files-out");
    // In the base frame already (`identity`): the boxes are the tree's exactly.
    ok(&["detect", files.to_str().unwrap(), "--run", w, "--score-threshold", "0", "--transform", "identity", "--out", files_out.to_str().unwrap()]);
    let want = report(&tree_out.join("json").join(seq).join(format!("{}.json", frames[0].name)));
    let nans = points.len().div_ceil(1000);
    for (name, format, dropped) in [
        ("ascii", "pcd", 0),
        ("binary", "pcd", nans),
        ("nested/compressed", "pcd", nans),
        ("velodyne", "bin", 0),
        ("n4_f32", "npy", 0),
        ("n3_f64", "npy", 0),
    ] {
        let got = report(&files_out.join("json").join(format!("{name}.json")));
        assert_eq!((got.format.as_str(), got.points, got.dropped_non_finite), (format, points.len(), dropped), "{name}");
        assert_same_boxes(&got.detections, &want.detections, name);
    }
    assert!(!files_out.join("json").join("notes.json").exists(), "files of other types are not inputs");

    // A glob the shell did not expand, and a sensor turned by 180° about z: the points are
    // negated in x and y exactly, so the boxes are the base frame's turned back.
    let turned: Vec<[f32; 3]> = points.iter().map(|p| [-p[0], -p[1], p[2]]).collect();
    std::fs::write(tmp.path().join("turned.npy"), npy(&turned, 3, false)).unwrap();
    let glob = tmp.path().join("turn*.npy");
    let turned_out = tmp.path().join("turned-out");
    ok(&["detect", glob.to_str().unwrap(), "--run", w, "--score-threshold", "0", "--transform", "yaw=180", "--out", turned_out.to_str().unwrap()]);
    let got = report(&turned_out.join("json").join("turned.json"));
    let expect: Vec<BoxRecord> = want
        .detections
        .iter()
        .map(|b| {
            let yaw = (b.yaw - std::f64::consts::PI).rem_euclid(std::f64::consts::TAU);
            BoxRecord { x: -b.x, y: -b.y, yaw: if yaw > std::f64::consts::PI { yaw - std::f64::consts::TAU } else { yaw }, ..*b }
        })
        .collect();
    assert_same_boxes(&got.detections, &expect, "turned sensor");

    // The default threshold keeps a subset, best first.
    let default_out = tmp.path().join("default-out");
    ok(&["detect", files.join("velodyne.bin").to_str().unwrap(), "--run", w, "--transform", "identity", "--out", default_out.to_str().unwrap()]);
    let kept = report(&default_out.join("json").join("velodyne.json"));
    assert_eq!(kept.score_threshold, 0.5);
    let expected: Vec<BoxRecord> = want.detections.iter().filter(|b| b.score >= 0.5).copied().collect();
    assert_same_boxes(&kept.detections, &expected, "default threshold");
}

#[test]
fn clouds_written_by_other_tools_give_the_same_people() {
    // tests/fixtures/other_tools: one frame as PCD in three encodings by pypcd4 and as .npy by
    // NumPy (make_fixtures.py there).
    let tmp = tempfile::tempdir().unwrap();
    let fixtures = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/other_tools");
    let w = weights();
    ok(&["detect", fixtures.to_str().unwrap(), "--run", w.to_str().unwrap(), "--score-threshold", "0", "--render", "--out", tmp.path().to_str().unwrap()]);
    let want = report(&tmp.path().join("json/frame.json"));
    assert_eq!((want.format.as_str(), want.points), ("npy", 9746));
    assert!(want.detections.iter().filter(|b| b.score >= 0.5).count() >= 3, "the three people within 4 m are found");
    for name in ["ascii", "binary", "binary_compressed"] {
        let got = report(&tmp.path().join(format!("json/{name}.json")));
        assert_eq!((got.format.as_str(), got.points, got.dropped_non_finite), ("pcd", 9746, 0), "{name}");
        assert_same_boxes(&got.detections, &want.detections, name);
        assert!(tmp.path().join(format!("kitti/{name}.txt")).exists() && tmp.path().join(format!("render/{name}.png")).exists());
    }
}

#[test]
fn bad_inputs_are_named_and_the_others_still_written() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("mixed");
    std::fs::create_dir_all(&dir).unwrap();
    let points: Vec<[f32; 3]> = (0..500).map(|i| [3.0 + (i % 10) as f32 * 0.03, 0.5 + (i / 10 % 10) as f32 * 0.03, -0.7 + (i / 100) as f32 * 0.3]).collect();
    std::fs::write(dir.join("good.bin"), kitti_bin(&points)).unwrap();
    std::fs::write(dir.join("truncated.bin"), &kitti_bin(&points)[..100 * 16 + 5]).unwrap();
    std::fs::write(dir.join("broken.pcd"), b"VERSION 0.7\nFIELDS x y\nDATA ascii\n1 2\n").unwrap();
    std::fs::write(dir.join("empty.npy"), npy(&[], 3, false)).unwrap();
    let out = tmp.path().join("out");
    let w = weights();
    let res = train_bin(&["detect", dir.to_str().unwrap(), "--run", w.to_str().unwrap(), "--out", out.to_str().unwrap()]);
    let err = String::from_utf8_lossy(&res.stderr);
    assert!(!res.status.success());
    assert!(err.contains("truncated.bin") && err.contains("broken.pcd"), "{err}");
    assert!(err.contains("2 of 4 inputs"), "{err}");
    assert!(out.join("json/good.json").exists() && out.join("kitti/good.txt").exists());
    // An empty cloud is a valid frame with nobody in it.
    assert_eq!(report(&out.join("json/empty.json")).detections, vec![]);

    let missing = tmp.path().join("nowhere.pcd");
    let res = train_bin(&["detect", missing.to_str().unwrap(), "--run", w.to_str().unwrap(), "--out", out.to_str().unwrap()]);
    assert!(!res.status.success() && String::from_utf8_lossy(&res.stderr).contains("nowhere.pcd"));
    let res = train_bin(&["detect", dir.to_str().unwrap(), "--run", tmp.path().to_str().unwrap()]);
    assert!(!res.status.success() && String::from_utf8_lossy(&res.stderr).contains("not a run folder"));
    let res = train_bin(&["detect", dir.to_str().unwrap(), "--run", w.to_str().unwrap(), "--transform", "tilt=3"]);
    assert!(!res.status.success() && String::from_utf8_lossy(&res.stderr).contains("unknown key"));
}

/// The service's process, killed when the test ends however it ends.
struct Server {
    child: Child,
    addr: String,
}

impl Drop for Server {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

fn start_server(extra: &[&str]) -> Server {
    let w = weights();
    let mut args = vec!["serve", "--run", w.to_str().unwrap(), "--addr", "127.0.0.1:0"];
    args.extend_from_slice(extra);
    let mut child = Command::new(env!("CARGO_BIN_EXE_train")).args(&args).stdout(Stdio::piped()).stderr(Stdio::null()).spawn().expect("starts");
    let mut line = String::new();
    BufReader::new(child.stdout.take().unwrap()).read_line(&mut line).unwrap();
    let addr = line.trim().strip_prefix("listening on http://").unwrap_or_else(|| panic!("unexpected first line {line:?}")).to_string();
    Server { child, addr }
}

struct Reply {
    status: u16,
    headers: BTreeMap<String, String>,
    body: Vec<u8>,
}

/// One HTTP/1.1 request on its own connection. The body is sent from another thread while the
/// reply is read, so a server that answers before reading a body (413) is still heard.
fn request(addr: &str, method: &str, target: &str, headers: &[(&str, &str)], body: &[u8]) -> Reply {
    let mut stream = TcpStream::connect(addr).unwrap();
    stream.set_read_timeout(Some(Duration::from_secs(120))).unwrap();
    let mut head = format!("{method} {target} HTTP/1.1\r\nHost: {addr}\r\nConnection: close\r\nContent-Length: {}\r\n", body.len());
    for (k, v) in headers {
        head.push_str(&format!("{k}: {v}\r\n"));
    }
    head.push_str("\r\n");
    let mut writer = stream.try_clone().unwrap();
    let body = body.to_vec();
    let sender = std::thread::spawn(move || {
        let _ = writer.write_all(head.as_bytes()).and_then(|_| writer.write_all(&body));
    });
    let mut raw = Vec::new();
    let _ = stream.read_to_end(&mut raw);
    let _ = sender.join();
    let split = raw.windows(4).position(|w| w == b"\r\n\r\n").unwrap_or_else(|| panic!("no reply head in {:?}", String::from_utf8_lossy(&raw)));
    let head = String::from_utf8_lossy(&raw[..split]).into_owned();
    let mut lines = head.lines();
    let status = lines.next().unwrap().split_whitespace().nth(1).unwrap().parse().unwrap();
    let headers = lines.filter_map(|l| l.split_once(':')).map(|(k, v)| (k.trim().to_ascii_lowercase(), v.trim().to_string())).collect();
    Reply { status, headers, body: raw[split + 4..].to_vec() }
}

#[test]
fn the_service_answers_concurrent_valid_and_malformed_bodies() {
    let tmp = tempfile::tempdir().unwrap();
    let (_, frames) = tree(tmp.path());
    let points = frames[0].points.clone();
    let pcd = encode_pcd(&xyz_columns(&points), Encoding::BinaryCompressed);
    std::fs::write(tmp.path().join("frame.pcd"), &pcd).unwrap();
    let out = tmp.path().join("out");
    let w = weights();
    ok(&["detect", tmp.path().join("frame.pcd").to_str().unwrap(), "--run", w.to_str().unwrap(), "--score-threshold", "0.2", "--out", out.to_str().unwrap()]);
    let want = report(&out.join("json/frame.json")).detections;
    assert!(!want.is_empty());

    let server = start_server(&["--score-threshold", "0.2", "--max-body-mb", "2"]);
    let health = request(&server.addr, "GET", "/health", &[], b"");
    assert_eq!(health.status, 200);
    let h: serde_json::Value = serde_json::from_slice(&health.body).unwrap();
    assert_eq!((h["model"].as_str(), h["backend"].as_str()), (Some("person_minkunet"), Some("flex")));

    let bin = kitti_bin(&points);
    let npy = npy(&points, 4, false);
    let oversize = vec![0u8; 3 << 20];
    let threads: Vec<_> = (0..8)
        .map(|t| {
            let (addr, pcd, bin, npy, oversize, want) = (server.addr.clone(), pcd.clone(), bin.clone(), npy.clone(), oversize.clone(), want.clone());
            std::thread::spawn(move || {
                for round in 0..2 {
                    let case = (t + round) % 8;
                    let r = match case {
                        0 => request(&addr, "POST", "/detect", &[("Content-Type", "application/octet-stream")], &pcd),
                        1 => request(&addr, "POST", "/detect?format=bin", &[], &bin),
                        2 => request(&addr, "POST", "/detect", &[("Content-Type", "application/x-kitti-bin")], &bin),
                        3 => request(&addr, "POST", "/detect", &[], &npy),
                        4 => request(&addr, "POST", "/detect", &[("Content-Type", "image/png")], &bin),
                        5 => request(&addr, "POST", "/detect", &[], &pcd[..pcd.len() / 2]),
                        6 => request(&addr, "POST", "/detect?format=bin", &[], &oversize),
                        _ => request(&addr, "POST", "/detect?frmat=bin", &[], &bin),
                    };
                    match case {
                        0..=3 => {
                            assert_eq!(r.status, 200, "case {case}: {}", String::from_utf8_lossy(&r.body));
                            let got: FrameReport = serde_json::from_slice(&r.body).unwrap();
                            assert_same_boxes(&got.detections, &want, &format!("case {case}"));
                        }
                        4 => assert_eq!(r.status, 415, "{}", String::from_utf8_lossy(&r.body)),
                        5 => {
                            assert_eq!(r.status, 400);
                            assert!(String::from_utf8_lossy(&r.body).contains("not a valid pcd cloud"), "{}", String::from_utf8_lossy(&r.body));
                        }
                        6 => assert_eq!(r.status, 413),
                        _ => assert_eq!(r.status, 400, "an unknown query parameter"),
                    }
                }
            })
        })
        .collect();
    for t in threads {
        t.join().expect("a client's checks failed");
    }
    let png = request(&server.addr, "POST", "/detect?render=1", &[], &npy);
    assert_eq!((png.status, png.headers.get("content-type").map(String::as_str)), (200, Some("image/png")));
    assert!(png.body.starts_with(b"\x89PNG"));
    assert_eq!(request(&server.addr, "POST", "/detect", &[], b"").status, 400);
    assert_eq!(request(&server.addr, "GET", "/health", &[], b"").status, 200, "still healthy");
}

/// Hostile inputs as files: a 271-byte PCD claiming 4·10⁹ points (binary and
/// ascii), an `.npy` whose shape claims 10¹² × 3, points a million metres out, and finite rows at
/// ±1e38 after NaN and infinite ones.
fn hostile_files(dir: &Path, people: &[[f32; 3]]) {
    std::fs::create_dir_all(dir).unwrap();
    let claim = |data: &str| {
        let mut b = format!("# .PCD v0.7 - Point Cloud Data file format\nVERSION 0.7\nFIELDS x y z intensity\nSIZE 4 4 4 4\nTYPE F F F F\nCOUNT 1 1 1 1\nWIDTH 4000000000\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS 4000000000\nDATA {data}\n").into_bytes();
        b.resize(271, b'1');
        b
    };
    std::fs::write(dir.join("claims_4e9_binary.pcd"), claim("binary")).unwrap();
    std::fs::write(dir.join("claims_4e9_ascii.pcd"), claim("ascii")).unwrap();
    std::fs::write(dir.join("shape_1e12.npy"), encode_npy("<f4", "(1000000000000, 3)", &[])).unwrap();
    let mut far = people.to_vec();
    far.extend([[1e6, 1e6, 1e6], [-1e6, -1e6, -1e6]]);
    std::fs::write(dir.join("far.bin"), kitti_bin(&far)).unwrap();
    let mut huge = vec![[f32::NAN, 0.0, 0.0], [f32::INFINITY, 1.0, 1.0], [0.0, f32::NEG_INFINITY, 2.0]];
    huge.extend([[1e38, 1e38, 1e38], [-1e38, -1e38, -1e38], [1e38, -1e38, 0.0]]);
    std::fs::write(dir.join("huge_after_nan.bin"), kitti_bin(&huge)).unwrap();
}

#[test]
fn hostile_files_are_named_far_points_cropped_and_the_rest_written() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("hostile");
    let (_, frames) = tree(tmp.path());
    hostile_files(&dir, &frames[0].points);
    std::fs::write(dir.join("good.bin"), kitti_bin(&frames[0].points)).unwrap();
    let out = tmp.path().join("out");
    let w = weights();
    let started = std::time::Instant::now();
    let res = train_bin(&["detect", dir.to_str().unwrap(), "--run", w.to_str().unwrap(), "--out", out.to_str().unwrap()]);
    let err = String::from_utf8_lossy(&res.stderr);
    assert!(!res.status.success());
    assert!(err.contains("3 of 6 inputs"), "{err}");
    for (file, says) in [("claims_4e9_binary.pcd", "4000000000 points"), ("claims_4e9_ascii.pcd", "4000000000 points"), ("shape_1e12.npy", "1000000000000×3")] {
        let line = err.lines().find(|l| l.contains(file)).unwrap_or_else(|| panic!("{file} not named in\n{err}"));
        assert!(line.contains(says), "{line}");
    }
    // Far points are outside the working volume: dropped, counted, and the people still found.
    let far = report(&out.join("json/far.json"));
    let good = report(&out.join("json/good.json"));
    assert_eq!((far.dropped_out_of_volume, far.points), (2, good.points + 2));
    assert_same_boxes(&far.detections, &good.detections, "far points added");
    let huge = report(&out.join("json/huge_after_nan.json"));
    assert_eq!((huge.points, huge.dropped_non_finite, huge.dropped_out_of_volume, huge.detections.len()), (3, 3, 3, 0));
    assert!(started.elapsed() < Duration::from_secs(60), "hostile inputs took {:?}", started.elapsed());
}

/// Sends a request head announcing `announced` body bytes but only `sent` of them, then waits
/// for the reply (a slow or stalled sender).
fn stalled_request(addr: &str, announced: usize, sent: usize) -> u16 {
    let mut stream = TcpStream::connect(addr).unwrap();
    stream.set_read_timeout(Some(Duration::from_secs(60))).unwrap();
    let head = format!("POST /detect?format=bin HTTP/1.1\r\nHost: {addr}\r\nContent-Length: {announced}\r\n\r\n");
    stream.write_all(head.as_bytes()).unwrap();
    stream.write_all(&vec![0u8; sent]).unwrap();
    let mut raw = Vec::new();
    let mut buf = [0u8; 4096];
    while !raw.windows(4).any(|w| w == b"\r\n\r\n") {
        match stream.read(&mut buf) {
            Ok(0) | Err(_) => break,
            Ok(n) => raw.extend_from_slice(&buf[..n]),
        }
    }
    String::from_utf8_lossy(&raw).split_whitespace().nth(1).and_then(|s| s.parse().ok()).unwrap_or(0)
}

#[cfg(unix)]
#[test]
fn the_service_answers_hostile_bodies_with_4xx_and_stops_cleanly_on_sigterm() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("hostile");
    let (_, frames) = tree(tmp.path());
    hostile_files(&dir, &frames[0].points);
    let server = start_server(&["--max-points", "80000", "--read-timeout-s", "3"]);
    let body = |name: &str| std::fs::read(dir.join(name)).unwrap();
    for (name, query, status) in [
        ("claims_4e9_binary.pcd", "", 413),
        ("claims_4e9_ascii.pcd", "", 413),
        ("shape_1e12.npy", "", 400),
        ("far.bin", "?format=bin", 200),
        ("huge_after_nan.bin", "?format=bin", 200),
    ] {
        let r = request(&server.addr, "POST", &format!("/detect{query}"), &[], &body(name));
        assert_eq!(r.status, status, "{name}: {}", String::from_utf8_lossy(&r.body));
        let v: serde_json::Value = serde_json::from_slice(&r.body).unwrap();
        if status == 200 {
            assert!(v["dropped_out_of_volume"].as_u64().unwrap() >= 2, "{name}: {v}");
        } else {
            assert!(v["error"].as_str().unwrap().contains("points") || v["error"].as_str().unwrap().contains("NPY"), "{name}: {v}");
        }
    }
    // Over --max-points: refused from its size before it is decoded.
    let many: Vec<[f32; 3]> = (0..80_001).map(|i| [3.0 + (i % 100) as f32 * 0.01, 0.0, 0.0]).collect();
    assert_eq!(request(&server.addr, "POST", "/detect?format=bin", &[], &kitti_bin(&many)).status, 413);
    // A sender that stalls mid-body gets 408 when its time is up; the service goes on.
    assert_eq!(stalled_request(&server.addr, 16_000, 1_000), 408);
    assert_eq!(request(&server.addr, "GET", "/health", &[], b"").status, 200, "still healthy");

    // SIGTERM while a request is in flight: it is answered, then the process exits 0.
    let addr = server.addr.clone();
    let valid = kitti_bin(&frames[0].points);
    let in_flight = std::thread::spawn(move || request(&addr, "POST", "/detect?format=bin", &[], &valid).status);
    std::thread::sleep(Duration::from_millis(300));
    let mut server = server;
    // SAFETY: kill(2) on the child's pid, which this test owns until it is waited for below.
    assert_eq!(unsafe { libc::kill(server.child.id() as libc::pid_t, libc::SIGTERM) }, 0);
    assert_eq!(in_flight.join().unwrap(), 200, "the request in flight at SIGTERM is answered");
    let status = server.child.wait().unwrap();
    assert!(status.success(), "exit status after SIGTERM: {status:?}");
}

#[test]
fn the_shipped_weights_are_found_from_any_working_directory() {
    let tmp = tempfile::tempdir().unwrap();
    let frame = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/other_tools/frame.npy");
    let out = tmp.path().join("out");
    let res = Command::new(env!("CARGO_BIN_EXE_train"))
        .args(["detect", frame.to_str().unwrap(), "--out", out.to_str().unwrap()])
        .current_dir("/")
        .output()
        .unwrap();
    assert!(res.status.success(), "{}", String::from_utf8_lossy(&res.stderr));
    assert!(!report(&out.join("json/frame.json")).detections.is_empty());
    // A checkpoint the folder lacks (the shipped weights keep only the latest) is named as the
    // option spells it.
    let w = weights();
    let res = train_bin(&["detect", frame.to_str().unwrap(), "--run", w.to_str().unwrap(), "--checkpoint", "best", "--out", out.to_str().unwrap()]);
    let err = String::from_utf8_lossy(&res.stderr);
    assert!(!res.status.success() && err.contains("has no `best` checkpoint"), "{err}");
}

#[test]
fn auto_finds_a_raised_tilted_sensor_and_reports_it() {
    let tmp = tempfile::tempdir().unwrap();
    let (_, frames) = tree(tmp.path());
    // The frame as a sensor 0.5 m higher than the base origin and pitched 3° would record it.
    let pose: train::SensorPose = "z=0.5,pitch=3".parse().unwrap();
    let inverse = |p: [f32; 3]| -> [f32; 3] {
        // Undo the translation, then the pitch about y.
        let (x, y, z) = (p[0] as f64, p[1] as f64, p[2] as f64 - 0.5);
        let (s, c) = (-pose.pitch).sin_cos();
        [(c * x + s * z) as f32, y as f32, (-s * x + c * z) as f32]
    };
    let sensor: Vec<[f32; 3]> = frames[0].points.iter().map(|&p| inverse(p)).collect();
    for p in sensor.iter().step_by(5000) {
        let back = pose.to_base(*p);
        assert!((0..3).all(|k| (back[k] - frames[0].points[sensor.iter().position(|q| q == p).unwrap()][k]).abs() < 1e-4));
    }
    std::fs::write(tmp.path().join("raised.bin"), kitti_bin(&sensor)).unwrap();
    let w = weights();
    let given = tmp.path().join("given");
    let auto = tmp.path().join("auto");
    let file = tmp.path().join("raised.bin");
    ok(&["detect", file.to_str().unwrap(), "--run", w.to_str().unwrap(), "--transform", "z=0.5,pitch=3", "--out", given.to_str().unwrap()]);
    ok(&["detect", file.to_str().unwrap(), "--run", w.to_str().unwrap(), "--transform", "auto", "--out", auto.to_str().unwrap()]);
    let by_default = tmp.path().join("default");
    ok(&["detect", file.to_str().unwrap(), "--run", w.to_str().unwrap(), "--out", by_default.to_str().unwrap()]);
    let (g, a) = (report(&given.join("json/raised.json")), report(&auto.join("json/raised.json")));
    assert_eq!(report(&by_default.join("json/raised.json")), a, "finding the frame is the default");
    assert_eq!(g.frame, "given");
    assert!(a.frame.starts_with("ground: 1.20 m below the sensor, tilted 3.0°"), "{}", a.frame);
    // The same people, within a few centimetres (the fitted plane is not the exact one).
    assert!(!g.detections.is_empty());
    let near = g.detections.iter().filter(|d| a.detections.iter().any(|e| (d.x - e.x).hypot(d.y - e.y) < 0.1)).count();
    assert!(near * 10 >= g.detections.len() * 9, "{near} of {} boxes found again", g.detections.len());
}

/// `--set` overrides the run's config for one invocation: focused test-time turns give the
/// library's boxes with the same settings (and the service's, which reports them on /health),
/// the run's config.toml is untouched, and a value the config refuses is an error naming it,
/// nothing written.
#[test]
fn set_overrides_the_runs_post_processing_for_one_invocation() {
    let tmp = tempfile::tempdir().unwrap();
    let (_, frames) = tree(tmp.path());
    let points = &frames[0].points;
    std::fs::write(tmp.path().join("frame.npy"), npy(points, 3, false)).unwrap();
    let (w, before) = (weights(), std::fs::read(weights().join("config.toml")).unwrap());
    let out = tmp.path().join("out");
    let sets = ["model.post.test_time_turns=2", "model.post.test_time_focus=5.0"];
    let frame = tmp.path().join("frame.npy");
    let mut args: Vec<String> = ["detect", frame.to_str().unwrap(), "--run", w.to_str().unwrap(), "--score-threshold", "0", "--transform", "identity", "--out", out.to_str().unwrap()].map(String::from).to_vec();
    for s in sets {
        args.extend(["--set".to_string(), s.to_string()]);
    }
    ok(&args.iter().map(String::as_str).collect::<Vec<_>>());
    let got = report(&out.join("json").join("frame.json"));
    let sets: Vec<String> = sets.iter().map(|s| s.to_string()).collect();
    let detector = train::RunDetector::load_with(&w, &sets, train::Slot::Latest, None).unwrap();
    assert_eq!(detector.config().model.post().test_time_focus, 5.0);
    let want = detector.detect(points);
    assert_eq!(got.detections.len(), want.boxes.len());
    for (g, (b, s)) in got.detections.iter().zip(want.boxes.iter().zip(&want.scores)) {
        assert!((g.x - b.cx).abs() < 1e-9 && (g.y - b.cy).abs() < 1e-9 && (g.score - f64::from(*s)).abs() < 1e-6, "{g:?} vs {b:?} {s}");
    }
    // One pass's scores are not these (the second pass counted).
    let one = train::RunDetector::load(&w, train::Slot::Latest, None).unwrap().detect(points);
    assert!(one.scores.iter().zip(&want.scores).any(|(a, b)| (a - b).abs() > 1e-3));
    assert_eq!(std::fs::read(w.join("config.toml")).unwrap(), before, "the run's config is unchanged");

    // The service with the same keys answers the same boxes and says what it overrides.
    let server = start_server(&["--set", sets[0].as_str(), "--set", sets[1].as_str(), "--score-threshold", "0", "--transform", "identity"]);
    let h: serde_json::Value = serde_json::from_slice(&request(&server.addr, "GET", "/health", &[], b"").body).unwrap();
    assert_eq!(h["overrides"], serde_json::json!(sets));
    let r = request(&server.addr, "POST", "/detect", &[], &std::fs::read(&frame).unwrap());
    assert_eq!(r.status, 200, "{}", String::from_utf8_lossy(&r.body));
    let served: FrameReport = serde_json::from_slice(&r.body).unwrap();
    assert_same_boxes(&served.detections, &got.detections, "served with --set");
    drop(server);

    let bad_out = tmp.path().join("bad");
    let bad = common::train_bin(&["detect", tmp.path().join("frame.npy").to_str().unwrap(), "--run", w.to_str().unwrap(), "--set", "model.post.test_time_turns=3", "--out", bad_out.to_str().unwrap()]);
    let stderr = String::from_utf8_lossy(&bad.stderr);
    assert!(!bad.status.success() && stderr.contains("test_time_turns") && stderr.contains("config.toml"), "{stderr}");
    assert!(!bad_out.exists(), "nothing written");
}
