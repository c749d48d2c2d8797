//! Person-MinkUNet's decoding (the authors' `detector.py`): a sigmoid score and a box for every
//! voxel, then the configured post-processing per sample.

use data_jrdb::{Batch, Box3d};

use super::box_coder::{BoxCoder, CLS};
use crate::post::PostProcessConfig;
use crate::detector::Detections;

/// `1 / (1 + e^{−x})`.
pub fn sigmoid(x: f32) -> f32 {
    1.0 / (1.0 + (-x).exp())
}

/// Detections of every sample from the head output `out` (row-major `[M, coder.channels()]`).
///
/// Voxels whose score does not pass the threshold are not decoded (NMS would drop them anyway).
pub fn decode(out: &[f32], batch: &Batch, coder: &BoxCoder, post: &PostProcessConfig) -> Vec<Detections> {
    let c = coder.channels();
    assert_eq!(out.len(), batch.num_voxels() * c, "head output is M × {c}");
    (0..batch.len())
        .map(|s| {
            let (mut boxes, mut scores): (Vec<Box3d>, Vec<f32>) = (Vec::new(), Vec::new());
            for row in batch.rows(s) {
                let values = &out[row * c..(row + 1) * c];
                let score = sigmoid(values[CLS]);
                if (score as f64) <= post.score_threshold {
                    continue;
                }
                let v = batch.centre(row).map(f64::from);
                boxes.push(coder.decode_row(values, v));
                scores.push(score);
            }
            post.apply(boxes, scores)
        })
        .collect()
}
