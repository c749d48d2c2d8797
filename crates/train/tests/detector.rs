//! The library API on the shipped weights: one cloud at a time gives exactly the boxes the batch
//! path (`infer`'s) gives for the same frames, test-time turns turn with the cloud, and a bad run
//! folder is an error naming it.

use std::path::Path;

use data_jrdb::sim::{SynthConfig, synth};
use data_jrdb::{Dataset, Loader, LoaderConfig, Split};
use train::{RunDetector, Slot};

fn weights() -> std::path::PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../weights/person_minkunet")
}

#[test]
fn one_cloud_at_a_time_matches_the_batch_path() {
    let tmp = tempfile::tempdir().unwrap();
    let root = tmp.path().join("sim");
    synth(&root, &SynthConfig { sequences: 1, frames: 3, seed: 11, max_people: 12, ..Default::default() }).unwrap();
    let detector = RunDetector::load(&weights(), Slot::Latest, None).unwrap();
    let data = &detector.config().data;
    let ds = std::sync::Arc::new(Dataset::open(&root, &data.dataset(Split::TrainVal)).unwrap());
    let loader = Loader::new(ds.clone(), LoaderConfig { batch_size: 2, shuffle: false, sample: data.eval_sample(), prefetch: false, ..Default::default() });
    let mut batched = Vec::new();
    for batch in loader.epoch(0) {
        batched.extend(detector.detect_batch(&batch.unwrap()));
    }
    assert_eq!(batched.len(), 3);
    assert!(batched.iter().map(|d| d.boxes.len()).sum::<usize>() > 0, "the weights find people in the frames");
    for (i, want) in batched.iter().enumerate() {
        let got = detector.detect(&ds.load(i).unwrap().points);
        assert_eq!(&got, want, "frame {i}");
    }
}

#[test]
fn a_folder_without_a_run_is_an_error_naming_it() {
    let tmp = tempfile::tempdir().unwrap();
    let e = RunDetector::load(tmp.path(), Slot::Latest, None).err().unwrap();
    assert!(format!("{e:#}").contains(&tmp.path().display().to_string()), "{e:#}");
}

/// With four test-time turns the passes over a cloud and over the same cloud turned by a quarter
/// are the same four clouds, so the fused boxes turn with the cloud (up to the order of the
/// fusion's sums); a pass whose boxes were not turned back, or turned the wrong way, breaks it.
#[test]
fn with_four_turns_the_boxes_turn_with_the_cloud() {
    let tmp = tempfile::tempdir().unwrap();
    let root = tmp.path().join("sim");
    synth(&root, &SynthConfig { sequences: 1, frames: 1, seed: 12, max_people: 12, ..Default::default() }).unwrap();
    let mut cfg = train::RunDir::at(&weights()).config().unwrap();
    cfg.model.post_mut().test_time_turns = 4;
    let detector = RunDetector::with_config(&weights(), cfg, Slot::Latest, None).unwrap();
    let ds = Dataset::open(&root, &detector.config().data.dataset(Split::TrainVal)).unwrap();
    let points = ds.load(0).unwrap().points;
    let quarter: Vec<[f32; 3]> = points.iter().map(|&[x, y, z]| [-y, x, z]).collect();
    let (a, b) = (detector.detect(&points), detector.detect(&quarter));
    let strong = a.scores.iter().filter(|&&s| s >= 0.5).count();
    assert!(strong > 0, "the weights find people in the frame");
    assert_eq!(a.boxes.len(), b.boxes.len());
    for (p, s) in a.boxes.iter().zip(&a.scores) {
        // p turned by a quarter is one of b's boxes (the order of near-equal scores may differ).
        let (q, t) = b
            .boxes
            .iter()
            .zip(&b.scores)
            .min_by(|x, y| (x.0.cx + p.cy).hypot(x.0.cy - p.cx).total_cmp(&(y.0.cx + p.cy).hypot(y.0.cy - p.cx)))
            .unwrap();
        assert!((-p.cy - q.cx).abs() < 1e-4 && (p.cx - q.cy).abs() < 1e-4 && (p.cz - q.cz).abs() < 1e-4, "{p:?} turned is not {q:?}");
        // The axis agrees modulo π (the facing stage picks the direction).
        let axis = (q.rot_z - p.rot_z - std::f64::consts::FRAC_PI_2).rem_euclid(std::f64::consts::PI);
        assert!((p.l - q.l).abs() < 1e-4 && (p.w - q.w).abs() < 1e-4 && axis.min(std::f64::consts::PI - axis) < 1e-4, "{p:?} vs {q:?}");
        assert!((s - t).abs() < 1e-5, "scores {s} and {t}");
    }
    // One pass alone does not turn with the cloud this exactly: what the turns average out.
    let one = RunDetector::load(&weights(), Slot::Latest, None).unwrap();
    let (c, d) = (one.detect(&points), one.detect(&quarter));
    assert!(c.scores.iter().zip(&d.scores).any(|(s, t)| (s - t).abs() > 1e-3) || c.boxes.len() != d.boxes.len());
}

/// Focused turns: turned passes that look at every point give exactly the whole-cloud fusion,
/// and turned passes that look at nothing leave each first-pass box a quarter of its score.
#[test]
fn focused_turns_look_only_around_the_first_pass_boxes() {
    let tmp = tempfile::tempdir().unwrap();
    let root = tmp.path().join("sim");
    synth(&root, &SynthConfig { sequences: 1, frames: 1, seed: 13, max_people: 12, ..Default::default() }).unwrap();
    let with = |turns: usize, focus: f64, focus_score: f64| {
        let mut cfg = train::RunDir::at(&weights()).config().unwrap();
        let post = cfg.model.post_mut();
        (post.test_time_turns, post.test_time_focus, post.test_time_focus_score) = (turns, focus, focus_score);
        post.facing_stage = false;
        RunDetector::with_config(&weights(), cfg, Slot::Latest, None).unwrap()
    };
    let points = Dataset::open(&root, &with(1, 0.0, 0.05).config().data.dataset(Split::TrainVal)).unwrap().load(0).unwrap().points;
    let whole = with(4, 0.0, 0.05).detect(&points);
    assert!(whole.scores.iter().any(|&s| s >= 0.5), "the weights find people in the frame");
    // A radius wider than the volume around every first-pass box: every point, the same passes.
    assert_eq!(with(4, 1000.0, 0.0).detect(&points), whole);
    // No first-pass box scores above 1: the turned passes see nothing.
    let one = with(1, 0.0, 0.05).detect(&points);
    assert!(one.scores.iter().all(|&s| s < 1.0));
    let blind = with(4, 2.0, 1.0).detect(&points);
    assert_eq!(blind.boxes.len(), one.boxes.len());
    for ((b, s), (c, t)) in blind.boxes.iter().zip(&blind.scores).zip(one.boxes.iter().zip(&one.scores)) {
        assert!((s - t / 4.0).abs() < 1e-6 && (b.cx - c.cx).abs() < 1e-9 && (b.cy - c.cy).abs() < 1e-9, "{b:?} {s} vs {c:?} {t}");
    }
    // Focused on 2 m around the boxes scoring ≥ 0.05: the strong people of the whole fusion stay.
    let focused = with(4, 2.0, 0.05).detect(&points);
    for (p, _) in whole.boxes.iter().zip(&whole.scores).filter(|(_, s)| **s >= 0.5) {
        assert!(focused.boxes.iter().zip(&focused.scores).any(|(q, &t)| t >= 0.3 && (p.cx - q.cx).hypot(p.cy - q.cy) < 0.3), "{p:?} lost");
    }
}
