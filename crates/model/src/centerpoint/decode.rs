//! CenterPoint's decoding, CenterNet-style: sigmoid heatmap, 3×3 max-pool peaks, top-K per sample,
//! boxes from the regression channels, then the configured post-processing.

use data_jrdb::Box3d;
use sparse_conv::burn::tensor::Tensor;
use sparse_conv::burn::tensor::activation::sigmoid;
use sparse_conv::burn::tensor::module::max_pool2d;
use sparse_conv::burn::tensor::ops::MaxPoolOptions;

use super::grid::BevGrid;
use super::head::{CHANNELS, DIM, HEIGHT, HM, REG, ROT};
use crate::post::PostProcessConfig;
use crate::detector::Detections;

/// Heatmap scores with everything but 3×3 local maxima set to 0: `[B, 1, X, Y]` of logits in.
pub fn peak_scores(hm_logits: Tensor<4>) -> Tensor<4> {
    let scores = sigmoid(hm_logits);
    let mut opts = MaxPoolOptions::new([3, 3]);
    opts.stride = [1, 1];
    opts.padding = [(1, 1), (1, 1)];
    let pooled = max_pool2d(scores.clone(), opts);
    let keep = scores.clone().equal(pooled);
    scores.clone().mask_fill(keep.bool_not(), 0.0)
}

/// Detections of each sample from head output `out` (`[B, 9, X, Y]`).
pub fn decode(out: Tensor<4>, grid: &BevGrid, top_k: usize, post: &PostProcessConfig) -> Vec<Detections> {
    let [b, c, x, y] = out.dims();
    assert_eq!(c, CHANNELS, "head output channels");
    let peaks = peak_scores(out.clone().slice([0..b, HM..HM + 1, 0..x, 0..y])).into_data().try_to_vec::<f32>().expect("f32 scores");
    let values = out.into_data().try_to_vec::<f32>().expect("f32 head output");
    let plane = x * y;
    (0..b)
        .map(|s| {
            let scores = &peaks[s * plane..(s + 1) * plane];
            let mut cand: Vec<usize> = (0..plane).filter(|&i| scores[i] > 0.0 && (scores[i] as f64) > post.score_threshold).collect();
            cand.sort_by(|&i, &j| scores[j].total_cmp(&scores[i]).then(i.cmp(&j)));
            cand.truncate(top_k);
            let ch = |k: usize, i: usize| values[(s * c + k) * plane + i] as f64;
            let boxes: Vec<Box3d> = cand
                .iter()
                .map(|&i| {
                    let (ix, iy) = (i / y, i % y);
                    let [cx, cy] = grid.from_cells(ix as f64 + ch(REG, i), iy as f64 + ch(REG + 1, i));
                    Box3d {
                        cx,
                        cy,
                        cz: ch(HEIGHT, i),
                        l: ch(DIM, i).exp(),
                        w: ch(DIM + 1, i).exp(),
                        h: ch(DIM + 2, i).exp(),
                        rot_z: ch(ROT, i).atan2(ch(ROT + 1, i)),
                    }
                })
                .collect();
            post.apply(boxes, cand.iter().map(|&i| scores[i]).collect())
        })
        .collect()
}
