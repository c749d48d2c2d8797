//! The one interface both detectors implement, so training and evaluation never branch on the
//! model kind.

use burn::module::Module;
use burn::tensor::{Device, Tensor};
use data_jrdb::{Batch, Box3d};

/// The loss of one batch: `total` is what backward runs on; `terms` are its named parts (already
/// weighted, summing to `total`) for training curves.
#[derive(Debug, Clone)]
pub struct LossTerms {
    /// The weighted sum of the terms: what backward runs on.
    pub total: Tensor<1>,
    /// Each named term, weighted, for the training curves.
    pub terms: Vec<(&'static str, Tensor<1>)>,
}

/// Detections of one sample of a batch, after post-processing (NMS), best first.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Detections {
    /// Boxes, best first.
    pub boxes: Vec<Box3d>,
    /// Their scores in [0, 1].
    pub scores: Vec<f32>,
}

/// A 3D person detector trained and evaluated on JRDB-format batches.
pub trait Detector: Module + Sized {
    /// Forward on a training batch (on `device`, usually an autodiff device) and its loss.
    fn loss(&self, batch: &Batch, device: &Device) -> LossTerms;

    /// The head output of an inference forward pass, read back row-major (Person-MinkUNet:
    /// `[M, 2·bins + 7]`; CenterPoint: `[B, 9, X, Y]`): the forward without decoding.
    fn head_output(&self, batch: &Batch, device: &Device) -> Vec<f32>;

    /// Detections for every sample of `batch`, post-processed as the model's config says.
    fn detect(&self, batch: &Batch, device: &Device) -> Vec<Detections>;
}
