//! `Loader`: seeded shuffling into batches, optionally prepared one batch ahead on a second thread.
//!
//! Each frame's randomness (augmentation, voxel cap) comes from its own generator seeded by
//! (seed, epoch, frame index), so a batch is the same whether it was prepared ahead or not.

use std::sync::Arc;
use std::sync::mpsc::{Receiver, sync_channel};
use std::thread::JoinHandle;

use rand::SeedableRng;
use rand::seq::SliceRandom;
use rand_chacha::ChaCha8Rng;

use crate::batch::{Batch, SampleConfig, collate, prepare};
use crate::dataset::{Dataset, OnBadFrame};
use crate::error::DataError;

/// Batching settings.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default)]
pub struct LoaderConfig {
    /// Samples per batch.
    pub batch_size: usize,
    /// Shuffle the frame order every epoch.
    pub shuffle: bool,
    /// Drop the last, smaller batch.
    pub drop_last: bool,
    /// Seed of the order and of each frame's randomness.
    pub seed: u64,
    /// Per-frame processing.
    pub sample: SampleConfig,
    /// Skip unreadable frames with a warning instead of ending the epoch with an error.
    pub on_bad_frame: OnBadFrame,
    /// Prepare the next batch on a second thread.
    pub prefetch: bool,
}

impl Default for LoaderConfig {
    fn default() -> Self {
        Self { batch_size: 36, shuffle: true, drop_last: false, seed: 0, sample: SampleConfig::default(), on_bad_frame: OnBadFrame::Fail, prefetch: true }
    }
}

/// Turns a dataset into batches, epoch by epoch.
#[derive(Debug, Clone)]
pub struct Loader {
    dataset: Arc<Dataset>,
    cfg: LoaderConfig,
}

fn mix(a: u64, b: u64) -> u64 {
    // splitmix64 of a combination: decorrelates neighbouring (epoch, index) pairs.
    let mut z = a ^ b.wrapping_mul(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

impl Loader {
    /// A loader over `dataset`.
    pub fn new(dataset: Arc<Dataset>, cfg: LoaderConfig) -> Self {
        assert!(cfg.batch_size > 0, "batch_size must be positive");
        Self { dataset, cfg }
    }

    /// The dataset.
    pub fn dataset(&self) -> &Dataset {
        &self.dataset
    }

    /// Batches in one epoch.
    pub fn batches_per_epoch(&self) -> usize {
        let (n, b) = (self.dataset.len(), self.cfg.batch_size);
        if self.cfg.drop_last { n / b } else { n.div_ceil(b) }
    }

    /// The frame indices of each batch of `epoch`.
    pub fn plan(&self, epoch: u64) -> Vec<Vec<usize>> {
        let mut order: Vec<usize> = (0..self.dataset.len()).collect();
        if self.cfg.shuffle {
            order.shuffle(&mut ChaCha8Rng::seed_from_u64(mix(self.cfg.seed, epoch)));
        }
        let mut chunks: Vec<Vec<usize>> = order.chunks(self.cfg.batch_size).map(<[usize]>::to_vec).collect();
        if self.cfg.drop_last && chunks.last().is_some_and(|c| c.len() < self.cfg.batch_size) {
            chunks.pop();
        }
        chunks
    }

    /// Builds one batch from frame indices (bad frames skipped or reported per the config).
    pub fn make_batch(&self, epoch: u64, frames: &[usize]) -> Result<Batch, DataError> {
        make_batch(&self.dataset, &self.cfg, epoch, frames)
    }

    /// The batches of `epoch`, in order; an `Err` ends the epoch.
    pub fn epoch(&self, epoch: u64) -> Batches {
        self.epoch_from(epoch, 0)
    }

    /// The batches of `epoch` from its `skip`-th on, as [`epoch`](Self::epoch) gives them: a
    /// resumed run continues mid-epoch with the batches it would have seen.
    pub fn epoch_from(&self, epoch: u64, skip: usize) -> Batches {
        let plan: Vec<Vec<usize>> = self.plan(epoch).into_iter().skip(skip).collect();
        if !self.cfg.prefetch {
            return Batches { inner: Inner::Direct { loader: self.clone(), epoch, plan: plan.into_iter() } };
        }
        let (tx, rx) = sync_channel(1);
        let loader = self.clone();
        let handle = std::thread::spawn(move || {
            for frames in plan {
                let r = loader.make_batch(epoch, &frames);
                let stop = r.is_err();
                if tx.send(r).is_err() || stop {
                    break;
                }
            }
        });
        Batches { inner: Inner::Prefetch { rx, handle: Some(handle) } }
    }
}

fn make_batch(ds: &Dataset, cfg: &LoaderConfig, epoch: u64, frames: &[usize]) -> Result<Batch, DataError> {
    let mut samples = Vec::with_capacity(frames.len());
    for &i in frames {
        match ds.load(i) {
            Ok(f) => {
                let mut rng = ChaCha8Rng::seed_from_u64(mix(mix(cfg.seed, epoch), i as u64 + 1));
                samples.push(prepare(f, &cfg.sample, &mut rng));
            }
            Err(e) if cfg.on_bad_frame == OnBadFrame::Skip => eprintln!("warning: skipping frame: {e}"),
            Err(e) => return Err(e),
        }
    }
    Ok(collate(samples, cfg.sample.voxel.voxel_size))
}

enum Inner {
    Direct { loader: Loader, epoch: u64, plan: std::vec::IntoIter<Vec<usize>> },
    Prefetch { rx: Receiver<Result<Batch, DataError>>, handle: Option<JoinHandle<()>> },
}

/// Iterator over the batches of one epoch (see [`Loader::epoch`]).
pub struct Batches {
    inner: Inner,
}

impl Iterator for Batches {
    type Item = Result<Batch, DataError>;

    fn next(&mut self) -> Option<Self::Item> {
        loop {
            let r = match &mut self.inner {
                Inner::Direct { loader, epoch, plan } => loader.make_batch(*epoch, &plan.next()?),
                Inner::Prefetch { rx, handle } => match rx.recv() {
                    Ok(r) => r,
                    Err(_) => {
                        if let Some(h) = handle.take() {
                            // The worker only ends by finishing its plan; a panic there is a bug.
                            h.join().expect("batch worker panicked");
                        }
                        return None;
                    }
                },
            };
            // A batch whose frames were all skipped is no batch.
            if matches!(&r, Ok(b) if b.is_empty()) {
                continue;
            }
            return Some(r);
        }
    }
}
