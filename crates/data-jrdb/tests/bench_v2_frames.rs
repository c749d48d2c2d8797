//! bench-v2's frames are in the frame `detect` puts a cloud in: levelled, the ground under the
//! platform near z = −0.7, the sensor above the origin; every place and platform of the first
//! sequences is drawn as `rigs.csv` says; a sequence's people stand on the ground and hold their
//! returns.

use data_jrdb::sim::{Preset, SynthConfig, synth};
use data_jrdb::{DatasetConfig, Dataset, Split};

#[test]
fn bench_v2_frames_are_levelled_on_the_platforms_ground() {
    let dir = tempfile::tempdir().unwrap();
    synth(dir.path(), &SynthConfig { sequences: 7, frames: 1, ..Preset::BenchV2.synth(3) }).unwrap();
    let rigs = std::fs::read_to_string(dir.path().join("rigs.csv")).unwrap();
    let rows: Vec<Vec<&str>> = rigs.lines().skip(1).map(|l| l.split(',').collect()).collect();
    assert_eq!(rows.len(), 7);
    let places: Vec<&str> = rows.iter().map(|r| r[0].split('-').nth(2).unwrap()).collect();
    assert_eq!(places, ["street", "campus", "hall", "street", "plaza", "campus", "corridor"]);
    let ds = Dataset::open(dir.path(), &DatasetConfig { split: Split::TrainVal, require_labels: false, ..Default::default() }).unwrap();
    assert_eq!(ds.len(), 7);
    for i in 0..ds.len() {
        let f = ds.load(i).unwrap();
        let row = rows.iter().find(|r| r[0] == f.sequence).unwrap();
        let (platform, height): (&str, f64) = (row[2], row[3].parse().unwrap());
        assert!((0.3..=2.2).contains(&height), "{row:?}");
        assert!(["car", "robot", "jrdb-robot", "mast"].contains(&platform), "{row:?}");
        // The lowest returns 3–20 m around the sensor are the ground under the platform (a
        // sidewalk or lawn beside it lies higher, a car's own body hides the road nearby): their
        // lowest 3 % sit at the floor.
        let mut near: Vec<f32> = f.points.iter().filter(|p| (3.0..20.0).contains(&p[0].hypot(p[1]))).map(|p| p[2]).collect();
        near.sort_by(f32::total_cmp);
        let low = near[near.len() * 3 / 100];
        assert!((low + 0.7).abs() < 0.12, "{}: ground at {low} (rig {row:?})", f.sequence);
        // Nothing but the platform's own body and its mount lies right above the origin up to
        // the sensor: the sensor is there.
        let above = f.points.iter().filter(|p| p[0].hypot(p[1]) < 0.3 && p[2] > 0.0).count();
        assert_eq!(above, 0, "{}: returns above the origin", f.sequence);
        // People stand on the ground (the floor or a raised sidewalk, terrace or lawn).
        for b in &f.boxes {
            let feet = b.cz - b.h / 2.0;
            assert!((-0.85..0.6).contains(&feet), "{}: a person's feet at {feet}", f.sequence);
        }
        assert!(f.num_points.iter().zip(&f.boxes).all(|(&n, b)| n as usize == b.count_inside(&f.points)));
    }
}
