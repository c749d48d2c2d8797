//! The library API on the shipped weights: one cloud at a time gives exactly the boxes the batch
//! path (`infer`'s) gives for the same frames, and a bad run folder is an error naming it.

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
