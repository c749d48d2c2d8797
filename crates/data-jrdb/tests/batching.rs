//! Samples, batches and the loader on a small simulated tree.

use std::sync::Arc;

use data_jrdb::sim::{SynthConfig, synth};
use data_jrdb::voxelize::{voxel_centre, voxel_coord};
use data_jrdb::{DatasetConfig, Dataset, Loader, LoaderConfig, OnBadFrame, SampleConfig, Split, prepare};
use rand::SeedableRng;

fn dataset(name: &str) -> Dataset {
    let root = std::env::temp_dir().join(format!("jrdb-batch-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&root);
    synth(&root, &SynthConfig { sequences: 2, frames: 3, seed: 21, max_people: 16, ..Default::default() }).unwrap();
    Dataset::open(&root, &DatasetConfig { split: Split::TrainVal, ..Default::default() }).unwrap()
}

#[test]
fn samples_keep_points_in_their_voxels_and_boxes() {
    let ds = dataset("sample");
    let frame = ds.load(0).unwrap();
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(1);
    let s = prepare(frame.clone(), &SampleConfig { max_voxels: None, ..Default::default() }, &mut rng);
    let aug = s.augmentation.unwrap();
    let mut pts = frame.points.clone();
    aug.apply_points(&mut pts);
    assert!(s.voxels.len() <= pts.len());
    let vs = SampleConfig::default().voxel.voxel_size;
    for (c, f) in s.voxels.coords.iter().zip(&s.voxels.features) {
        assert_eq!(voxel_coord(*f, vs), *c);
        let ctr = voxel_centre(*c, vs);
        assert!((0..3).all(|k| (f[k] - ctr[k]).abs() <= vs[k] / 2.0 + 1e-4));
    }
    // Augmented boxes hold (nearly) the same points: only points within f32 rounding of a face may flip.
    for (b0, b1) in frame.boxes.iter().zip(&s.boxes) {
        let (n0, n1) = (b0.count_inside(&frame.points) as i64, b1.count_inside(&pts) as i64);
        assert!((n0 - n1).abs() <= 2 + n0 / 100, "{n0} vs {n1}");
    }
    let capped = prepare(frame, &SampleConfig { max_voxels: Some(5000), ..Default::default() }, &mut rng);
    assert_eq!(capped.voxels.len(), 5000);
    let eval = prepare(ds.load(0).unwrap(), &SampleConfig::eval(), &mut rng);
    assert!(eval.augmentation.is_none() && eval.voxels.len() > 20_000);
    assert_eq!(eval.boxes, ds.load(0).unwrap().boxes);
}

#[test]
fn loader_is_seeded_and_prefetch_changes_nothing() {
    let ds = Arc::new(dataset("loader"));
    let cfg = LoaderConfig { batch_size: 4, seed: 5, ..Default::default() };
    let a: Vec<_> = Loader::new(ds.clone(), cfg.clone()).epoch(0).map(Result::unwrap).collect();
    let b: Vec<_> = Loader::new(ds.clone(), LoaderConfig { prefetch: false, ..cfg.clone() }).epoch(0).map(Result::unwrap).collect();
    assert_eq!(a, b);
    assert_eq!(a.len(), 2);
    assert_eq!(a.iter().map(|x| x.len()).sum::<usize>(), 6);
    // A resumed epoch continues with exactly the batches the full one gives, prefetched or not.
    for prefetch in [true, false] {
        let rest: Vec<_> = Loader::new(ds.clone(), LoaderConfig { prefetch, ..cfg.clone() }).epoch_from(0, 1).map(Result::unwrap).collect();
        assert_eq!(rest, a[1..], "prefetch {prefetch}");
    }
    let other: Vec<_> = Loader::new(ds.clone(), cfg.clone()).epoch(1).map(Result::unwrap).collect();
    assert_ne!(a, other);
    let batch = &a[0];
    assert_eq!(batch.offsets.len(), batch.len() + 1);
    assert_eq!(batch.features.len(), 3 * batch.num_voxels());
    assert_eq!(batch.centres.len(), 3 * batch.num_voxels());
    for bi in 0..batch.len() {
        let rows = batch.offsets[bi]..batch.offsets[bi + 1];
        assert!(rows.len() <= 30_000);
        assert!(batch.coords[rows].iter().all(|c| c[0] == bi as i32));
    }
    let mut seen: Vec<_> = a.iter().flat_map(|b| b.frames.clone()).collect();
    seen.sort();
    seen.dedup();
    assert_eq!(seen.len(), 6);
    let loader = Loader::new(ds.clone(), LoaderConfig { drop_last: true, ..cfg });
    assert_eq!(loader.batches_per_epoch(), 1);
}

#[test]
fn loader_skips_or_fails_on_a_frame_broken_after_opening() {
    let ds = dataset("broken");
    std::fs::write(ds.frames[2].cloud_files()[0], b"VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nWIDTH 5\nPOINTS 5\nDATA binary\n\x00").unwrap();
    let ds = Arc::new(ds);
    let cfg = LoaderConfig { batch_size: 3, shuffle: false, prefetch: true, ..Default::default() };
    let fail: Vec<_> = Loader::new(ds.clone(), cfg.clone()).epoch(0).collect();
    assert_eq!(fail.len(), 1);
    let e = fail[0].as_ref().unwrap_err();
    assert!(e.to_string().contains(&format!("{}.pcd", ds.frames[2].name)), "{e}");
    let skip: Vec<_> = Loader::new(ds, LoaderConfig { on_bad_frame: OnBadFrame::Skip, ..cfg }).epoch(0).map(Result::unwrap).collect();
    assert_eq!(skip.iter().map(|b| b.len()).collect::<Vec<_>>(), [2, 3]);
}
