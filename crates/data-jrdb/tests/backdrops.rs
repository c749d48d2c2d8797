//! Simulated people ray-cast into a scan (`sim::backdrop`): a backdrop scanned here from 1.8 m
//! (a flat road, a wall 10 m ahead, a post) stands in for a real one. People stand on its
//! ground, never in or behind the wall, no return passes through a person (their shadow is
//! cut out of the backdrop), the frame is levelled onto the base frame's floor, and a bad
//! `backdrops.csv` is named with its line.

use data_jrdb::cloud::encode_npy;
use data_jrdb::sim::geometry::Shape;
use data_jrdb::sim::scene::Prim;
use data_jrdb::sim::sensors::SensorModel;
use data_jrdb::sim::{SynthConfig, World, synth};
use data_jrdb::{DatasetConfig, Dataset, Split};

const HEIGHT: f64 = 1.8;

fn write_backdrop(dir: &std::path::Path) {
    let road = Prim { shape: Shape::PlaneZ(-HEIGHT), reflectivity: 0.3 };
    let wall = Prim { shape: Shape::Cuboid { c: [10.5, 0.0, 1.5 - HEIGHT], half: [0.5, 30.0, 1.5], yaw: 0.0 }, reflectivity: 0.5 };
    let post = Prim { shape: Shape::Cylinder { c: [-6.0, 4.0], r: 0.08, z0: -HEIGHT, z1: 3.0 - HEIGHT }, reflectivity: 0.5 };
    let m = SensorModel::Hdl64e;
    let rets = m.scanner().scan_beams(&m.elevations(), &[road, wall, post], [0.0; 3], 0.0, None, 11);
    let bytes: Vec<u8> = rets.iter().flat_map(|r| r.xyz.map(|v| v as f32)).flat_map(f32::to_le_bytes).collect();
    std::fs::write(dir.join("street.npy"), encode_npy("<f4", &format!("({}, 3)", rets.len()), &bytes)).unwrap();
    std::fs::write(dir.join("backdrops.csv"), "file,sensor,source\nstreet.npy,hdl64e,made by this test\n").unwrap();
}

fn config(backdrops: &std::path::Path, seed: u64) -> SynthConfig {
    SynthConfig { sequences: 4, frames: 2, seed, max_people: 24, world: World::Backdrops, backdrops: Some(backdrops.to_path_buf()), ..Default::default() }
}

#[test]
fn people_stand_on_the_backdrops_ground_and_cast_shadows() {
    let bd = tempfile::tempdir().unwrap();
    write_backdrop(bd.path());
    let out = tempfile::tempdir().unwrap();
    let summary = synth(out.path(), &config(bd.path(), 5)).unwrap();
    assert_eq!(summary.sequences.len(), 4);
    assert!(summary.sequences.iter().all(|s| s.starts_with("bd-train-street-")), "{:?}", summary.sequences);
    let ds = Dataset::open(out.path(), &DatasetConfig { split: Split::TrainVal, require_labels: false, ..Default::default() }).unwrap();
    assert_eq!(ds.len(), 8);
    let mut people = 0;
    for i in 0..ds.len() {
        let f = ds.load(i).unwrap();
        // Levelled onto the floor: the road's returns sit at z = -0.7.
        let mut low: Vec<f32> = f.points.iter().filter(|p| (4.0..9.0).contains(&p[0].hypot(p[1]))).map(|p| p[2]).collect();
        low.sort_by(f32::total_cmp);
        assert!((low[low.len() / 2] + 0.7).abs() < 0.03, "road at {}", low[low.len() / 2]);
        // The sensor's position in the base frame: straight above the origin, HEIGHT over the floor.
        let sensor = [0.0f64, 0.0, HEIGHT - 0.7];
        let sph = |p: &[f32; 3]| {
            let (x, y, z) = (p[0] as f64 - sensor[0], p[1] as f64 - sensor[1], p[2] as f64 - sensor[2]);
            let r = (x * x + y * y + z * z).sqrt();
            (y.atan2(x), (z / r).asin(), r)
        };
        // Every return by azimuth, to find the ones behind a return.
        let mut all: Vec<(f64, f64, f64)> = f.points.iter().map(sph).collect();
        all.sort_by(|a, b| a.0.total_cmp(&b.0));
        for b in &f.boxes {
            people += 1;
            let feet = b.cz - b.h / 2.0;
            assert!((feet + 0.7).abs() < 0.05, "{}: feet at {feet}", f.sequence);
            // Not in the wall, nor within 0.8 m of it or of the post, nor behind the wall.
            assert!(b.cx < 10.0 - 0.7 + 0.45, "{}: a person at x = {} (wall at 10)", f.sequence, b.cx);
            assert!((b.cx + 6.0).hypot(b.cy - 4.0) > 0.75, "{}: a person on the post", f.sequence);
            // No return lies behind a person's return whose neighbours on both sides are theirs
            // too (inside the silhouette, where every ray hits them): their shadow is cut.
            let mine: Vec<(f64, f64, f64)> = f.points.iter().filter(|p| b.contains(p.map(f64::from))).map(sph).collect();
            let col = std::f64::consts::TAU / 2000.0;
            let inner = mine.iter().filter(|m| {
                let side = |s: f64| mine.iter().any(|o| ((o.0 - m.0) * s - col).abs() < 0.3 * col && (o.1 - m.1).abs() < 1e-3);
                side(1.0) && side(-1.0)
            });
            for m in inner {
                let from = all.partition_point(|q| q.0 < m.0 - 0.5 * col);
                let behind = all[from..].iter().take_while(|q| q.0 < m.0 + 0.5 * col).filter(|q| q.2 > m.2 + 0.3 && (q.1 - m.1).abs() < 1e-3).count();
                assert_eq!(behind, 0, "{}: a return behind a person's at {:.1} m", f.sequence, m.2);
            }
        }
    }
    assert!(people >= 16, "only {people} people in 8 frames");
    // The same seed writes the same frames.
    let again = tempfile::tempdir().unwrap();
    assert_eq!(synth(again.path(), &config(bd.path(), 5)).unwrap(), summary);
}

#[test]
fn a_bad_index_is_named_with_its_line() {
    let bd = tempfile::tempdir().unwrap();
    write_backdrop(bd.path());
    std::fs::write(bd.path().join("backdrops.csv"), "file,sensor\nstreet.npy,hdl65\n").unwrap();
    let e = synth(tempfile::tempdir().unwrap().path(), &config(bd.path(), 0)).unwrap_err().to_string();
    assert!(e.contains("backdrops.csv") && e.contains("line 2") && e.contains("unknown sensor `hdl65`"), "{e}");
    std::fs::write(bd.path().join("backdrops.csv"), "file,sensor\nmissing.npy,hdl64e\n").unwrap();
    let e = synth(tempfile::tempdir().unwrap().path(), &config(bd.path(), 0)).unwrap_err().to_string();
    assert!(e.contains("missing.npy"), "{e}");
}

/// The backdrop of `write_backdrop` written ring after ring, each ring from −π round (as KITTI's
/// HDL-64E files are), which is how its rings are told apart: its steep beams meet the road
/// within a few metres, too near to be told apart by elevation.
fn write_ring_major_backdrop(dir: &std::path::Path) {
    let road = Prim { shape: Shape::PlaneZ(-HEIGHT), reflectivity: 0.3 };
    let wall = Prim { shape: Shape::Cuboid { c: [10.5, 0.0, 1.5 - HEIGHT], half: [0.5, 30.0, 1.5], yaw: 0.0 }, reflectivity: 0.5 };
    let m = SensorModel::Hdl64e;
    let mut rets = m.scanner().scan_beams(&m.elevations(), &[road, wall], [0.0; 3], 0.0, None, 11);
    rets.sort_by(|a, b| a.ring.cmp(&b.ring).then(a.xyz[1].atan2(a.xyz[0]).total_cmp(&b.xyz[1].atan2(b.xyz[0]))));
    let bytes: Vec<u8> = rets.iter().flat_map(|r| r.xyz.map(|v| v as f32)).flat_map(f32::to_le_bytes).collect();
    std::fs::write(dir.join("street.npy"), encode_npy("<f4", &format!("({}, 3)", rets.len()), &bytes)).unwrap();
    std::fs::write(dir.join("backdrops.csv"), "file,sensor,source\nstreet.npy,hdl64e,made by this test\n").unwrap();
}

#[test]
fn a_thinned_backdrop_keeps_a_32_beam_sensors_rings_and_its_people_are_as_sparse() {
    let bd = tempfile::tempdir().unwrap();
    write_ring_major_backdrop(bd.path());
    let open = |root: &std::path::Path| Dataset::open(root, &DatasetConfig { split: Split::TrainVal, require_labels: false, ..Default::default() }).unwrap();
    let (dense, sparse) = (tempfile::tempdir().unwrap(), tempfile::tempdir().unwrap());
    let base = SynthConfig { sequences: 6, frames: 1, max_people: 24, ..config(bd.path(), 9) };
    synth(dense.path(), &base).unwrap();
    let summary = synth(sparse.path(), &SynthConfig { thinned_share: 1.0, ..base.clone() }).unwrap();
    assert!(summary.sequences.iter().all(|s| s.starts_with("bd-train-thin-street-")), "{:?}", summary.sequences);
    let (dense, sparse) = (open(dense.path()), open(sparse.path()));
    // Elevations seen from the sensor (straight above the base frame's origin, HEIGHT over the floor).
    let elevation = |p: &[f32; 3]| (p[2] as f64 - (HEIGHT - 0.7)).atan2((p[0] as f64).hypot(p[1] as f64)).to_degrees();
    let (mut dense_pts, mut sparse_pts, mut people) = (0, 0, 0);
    for i in 0..sparse.len() {
        let (d, s) = (dense.load(i).unwrap(), sparse.load(i).unwrap());
        dense_pts += d.points.len();
        sparse_pts += s.points.len();
        // The road's and the wall's returns lie on rings at least 1.2° apart (within their noise).
        let mut rings: Vec<f64> = s.points.iter().filter(|p| p[0].hypot(p[1]) > 6.0).map(elevation).collect();
        rings.sort_by(f64::total_cmp);
        let mut centres: Vec<f64> = Vec::new();
        for e in rings {
            if centres.last().is_none_or(|c| e - c > 0.2) {
                centres.push(e);
            }
        }
        assert!(centres.windows(2).all(|w| w[1] - w[0] > 1.0), "{}: rings at {centres:?}", s.sequence);
        // People are labelled from the returns they keep, and keep at least three.
        for b in &s.boxes {
            people += 1;
            let inside = s.points.iter().filter(|p| b.contains(p.map(f64::from))).count();
            assert!(inside >= 3, "{}: a person with {inside} returns", s.sequence);
        }
    }
    assert!(people >= 6, "only {people} people in 6 frames");
    // Every fourth or third ring and every other column: about a seventh of the returns.
    assert!(sparse_pts * 5 < dense_pts && sparse_pts * 12 > dense_pts, "{sparse_pts} returns thinned from {dense_pts}");
}

#[test]
fn a_thinned_share_is_checked_and_an_unthinnable_backdrop_named() {
    let bd = tempfile::tempdir().unwrap();
    write_backdrop(bd.path());
    let out = tempfile::tempdir().unwrap();
    let e = synth(out.path(), &SynthConfig { thinned_share: 1.5, ..config(bd.path(), 0) }).unwrap_err().to_string();
    assert!(e.contains("thinned_share") && e.contains("1.5"), "{e}");
    let e = synth(out.path(), &SynthConfig { thinned_share: 0.5, world: World::V1, backdrops: None, ..config(bd.path(), 0) }).unwrap_err().to_string();
    assert!(e.contains("thinned_share") && e.contains("backdrops"), "{e}");
    // Written column by column, with its steep beams only near: no way to tell its rings apart.
    let e = synth(out.path(), &SynthConfig { thinned_share: 1.0, ..config(bd.path(), 0) }).unwrap_err().to_string();
    assert!(e.contains("street.npy") && e.contains("cannot thin"), "{e}");
}
