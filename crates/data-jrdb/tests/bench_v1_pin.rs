//! `bench-v1` cannot drift: every figure in the README and `weights/README.md` was measured on it,
//! so a simulator change that alters its frames must come as a new preset (docs/simulated-benchmark.md).
//! The first eight sequences of the preset at seed 0 (halls, plazas and corridors, training and
//! validation), two frames each, are generated and reduced to a digest of their points (to the millimetre), boxes (to a
//! tenth of a millimetre) and counts. Generating fewer sequences or frames than the preset does not
//! change the ones made: each sequence draws from its own seed, and a frame from those before it
//! (the slice's PCD files equal the full preset's byte for byte). Fewer sequences miss changes:
//! with two, widening the clutter or furniture draw of `sim/scene.rs` left the digest unchanged;
//! with eight, each moves it.

use data_jrdb::sim::{Preset, SynthConfig, synth};
use data_jrdb::{DatasetConfig, JrdbDataset, Split};

/// FNV-1a, 64 bits: a stable digest with no dependency.
struct Fnv(u64);

impl Fnv {
    fn eat(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.0 = (self.0 ^ b as u64).wrapping_mul(0x100_0000_01b3);
        }
    }
    fn int(&mut self, v: i64) {
        self.eat(&v.to_le_bytes());
    }
}

#[test]
fn bench_v1_frames_have_their_pinned_digest() {
    let dir = tempfile::tempdir().unwrap();
    let cfg = SynthConfig { sequences: 8, frames: 2, ..Preset::BenchV1.synth(0) };
    synth(dir.path(), &cfg).unwrap();
    let ds = JrdbDataset::open(dir.path(), &DatasetConfig { split: Split::TrainVal, require_labels: false, ..Default::default() }).unwrap();
    let mut h = Fnv(0xcbf2_9ce4_8422_2325);
    let (mut points, mut boxes) = (0, 0);
    for i in 0..ds.len() {
        let f = ds.load(i).unwrap();
        h.eat(f.sequence.as_bytes());
        h.eat(f.name.as_bytes());
        h.int(f.points.len() as i64);
        h.int(f.n_upper as i64);
        for p in &f.points {
            for v in p {
                h.int((*v as f64 * 1e3).round() as i64);
            }
        }
        for (b, n) in f.boxes.iter().zip(&f.num_points) {
            for v in [b.cx, b.cy, b.cz, b.l, b.w, b.h, b.rot_z] {
                h.int((v * 1e4).round() as i64);
            }
            h.int(*n);
        }
        points += f.points.len();
        boxes += f.boxes.len();
    }
    let got = (ds.len(), points, boxes, format!("{:016x}", h.0));
    let pinned = (16, 835_908, 212, "9f4a32b0cda3d405".to_string());
    assert_eq!(
        got, pinned,
        "bench-v1 changed: every published figure was measured on the old frames. If the simulator must change, add a new preset (docs/simulated-benchmark.md) and leave bench-v1's frames as they are."
    );
}
