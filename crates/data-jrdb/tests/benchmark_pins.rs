//! The simulated benchmarks cannot drift: every figure in the README, `docs/accuracy.md` and `weights/README.md` was
//! measured on them and the shipped weights trained on them, so a simulator change that alters
//! their frames must come as a new preset (docs/simulated-benchmark.md). The first sequences of
//! each preset at seed 0 (bench-v1: eight, its halls, plazas and corridors; bench-v2: seven, one
//! of each place in turn, with their sensors and platforms), training and validation, two frames
//! each, are generated and reduced to a digest of their points (to the millimetre), boxes (to a
//! tenth of a millimetre) and counts. Generating fewer sequences or frames than the preset does not
//! change the ones made: each sequence draws from its own seed, and a frame from those before it
//! (the slice's PCD files equal the full preset's byte for byte). Fewer sequences miss changes:
//! with two, widening the clutter or furniture draw of `sim/scene.rs` left the digest unchanged;
//! with eight, each moves it.

use data_jrdb::sim::{Preset, SynthConfig, synth};
use data_jrdb::{DatasetConfig, Dataset, Split};

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

/// Frames, points, boxes and the digest of the first `sequences` of `preset` at seed 0.
fn digest(preset: Preset, sequences: usize) -> (usize, usize, usize, String) {
    let dir = tempfile::tempdir().unwrap();
    let cfg = SynthConfig { sequences, frames: 2, ..preset.synth(0) };
    synth(dir.path(), &cfg).unwrap();
    let ds = Dataset::open(dir.path(), &DatasetConfig { split: Split::TrainVal, require_labels: false, ..Default::default() }).unwrap();
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
    (ds.len(), points, boxes, format!("{:016x}", h.0))
}

#[test]
fn bench_v1_frames_have_their_pinned_digest() {
    assert_eq!(
        digest(Preset::BenchV1, 8),
        (16, 835_908, 212, "9f4a32b0cda3d405".to_string()),
        "bench-v1 changed: every published figure was measured on the old frames. If the simulator must change, add a new preset (docs/simulated-benchmark.md) and leave bench-v1's frames as they are."
    );
}

#[test]
fn bench_v2_frames_have_their_pinned_digest() {
    assert_eq!(
        digest(Preset::BenchV2, 7),
        (14, 715_179, 282, "87628024b635c473".to_string()),
        "bench-v2 changed: the shipped weights were trained on it and its figures measured on it. If the simulator must change, add a new preset (docs/simulated-benchmark.md) and leave bench-v2's frames as they are."
    );
}
