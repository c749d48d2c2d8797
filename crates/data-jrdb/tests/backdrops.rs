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
