//! CenterPoint's loss (its `centernet_loss.py`): CornerNet focal loss on the heatmap (α = 2,
//! β = 4, predictions clamped to [1e-4, 1 − 1e-4], normalised by the number of objects) plus
//! `reg_weight` × L1 on the eight regression values at the objects' centre cells (normalised by
//! the number of objects).

use sparse_conv::burn::tensor::activation::sigmoid;
use sparse_conv::burn::tensor::{Device, Int, Tensor, TensorData};

use super::head::{CHANNELS, HM, REG};
use super::targets::{HeatmapTargets, REG_VALUES};
use crate::detector::LossTerms;

/// Names of the reported terms: the focal loss, then the weighted L1 of each regression group.
pub const TERMS: [&str; 5] = ["hm", "offset", "height", "dims", "rot"];

/// CornerNet's focal loss of heatmap logits `[N]` against the Gaussian target `[N]`; `positives`
/// are the flat indices of the objects' centre cells. Summed, divided by the number of positives
/// (when there is any).
pub fn focal_loss(logits: Tensor<1>, target: Tensor<1>, positives: &[i64], alpha: f64, beta: f64, device: &Device) -> Tensor<1> {
    let p = sigmoid(logits).clamp(1e-4, 1.0 - 1e-4);
    let neg = ((p.clone().neg() + 1.0).log() * p.clone().powf_scalar(alpha) * (target.neg() + 1.0).powf_scalar(beta)).sum();
    if positives.is_empty() {
        return neg.neg();
    }
    let idx = Tensor::<1, Int>::from_data(TensorData::new(positives.to_vec(), [positives.len()]), device);
    let pp = p.select(0, idx);
    let pos = (pp.clone().log() * (pp.neg() + 1.0).powf_scalar(alpha)).sum();
    (pos + neg).neg() / positives.len() as f64
}

/// The loss of head output `out` (`[B, 9, X, Y]`) against `t`.
pub fn loss(out: Tensor<4>, t: &HeatmapTargets, alpha: f64, beta: f64, reg_weight: f64, device: &Device) -> LossTerms {
    let [b, c, x, y] = out.dims();
    assert_eq!(c, CHANNELS, "head output channels");
    // [B, 9, X, Y] → [B·X·Y, 9]: one row per cell, in the targets' flat index order.
    let cells = out.permute([0, 2, 3, 1]).reshape([b * x * y, c]);
    let hm_target = Tensor::<1>::from_data(TensorData::new(t.heatmap.clone(), [t.heatmap.len()]), device);
    let hm = focal_loss(cells.clone().slice([0..b * x * y, HM..HM + 1]).reshape([b * x * y]), hm_target, &t.index, alpha, beta, device);
    let n = t.num_objects();
    let groups: [std::ops::Range<usize>; 4] = [0..2, 2..3, 3..6, 6..8];
    let mut terms = vec![(TERMS[0], hm.clone())];
    let mut total = hm;
    if n == 0 {
        for name in &TERMS[1..] {
            terms.push((name, Tensor::zeros([1], device)));
        }
    } else {
        let idx = Tensor::<1, Int>::from_data(TensorData::new(t.index.clone(), [n]), device);
        let pred = cells.select(0, idx).slice([0..n, REG..REG + REG_VALUES]);
        let target = Tensor::<1>::from_data(TensorData::new(t.reg.clone(), [n * REG_VALUES]), device).reshape([n, REG_VALUES]);
        let l1 = (pred - target).abs();
        for (name, g) in TERMS[1..].iter().zip(groups) {
            let term = l1.clone().slice([0..n, g]).sum() * (reg_weight / n as f64);
            total = total + term.clone();
            terms.push((name, term));
        }
    }
    LossTerms { total, terms }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scalar(t: &Tensor<1>) -> f64 {
        t.to_data().try_to_vec::<f32>().unwrap()[0] as f64
    }

    #[test]
    fn focal_and_l1_match_hand_computation() {
        let device = Device::flex();
        // One sample, 1×2 cells; cell 0 is an object centre.
        let logits = [0.5f32, -1.0];
        let mut out = vec![0f32; 9 * 2];
        out[0] = logits[0];
        out[1] = logits[1];
        let reg_pred = [0.2f32, 0.7, 0.1, 0.0, -0.5, 0.5, 0.3, 0.9];
        for (k, v) in reg_pred.iter().enumerate() {
            out[(1 + k) * 2] = *v; // channel 1 + k at cell 0
        }
        let out = Tensor::<1>::from_data(TensorData::new(out, [18]), &device).reshape([1, 9, 1, 2]);
        let t = HeatmapTargets {
            heatmap: vec![1.0, 0.5],
            index: vec![0],
            reg: vec![0.5, 0.5, 0.0, 0.0, -0.7, 0.5, 0.0, 1.0],
        };
        let l = loss(out, &t, 2.0, 4.0, 0.25, &device);
        let s = |x: f64| 1.0 / (1.0 + (-x).exp());
        let (p0, p1) = (s(0.5), s(-1.0));
        let pos = p0.ln() * (1.0 - p0).powi(2);
        let neg = (1.0 - p1).ln() * p1.powi(2) * 0.5f64.powi(4); // cell 0's (1 − 1)^4 = 0
        let hm = -(pos + neg);
        let diffs = [0.3, 0.2, 0.1, 0.0, 0.2, 0.0, 0.3, 0.1];
        let want = [hm, 0.25 * 0.5, 0.25 * 0.1, 0.25 * 0.2, 0.25 * 0.4];
        for ((name, got), w) in l.terms.iter().zip(want) {
            assert!((scalar(got) - w).abs() < 1e-5, "{name}: {} vs {w}", scalar(got));
        }
        assert!((diffs.iter().sum::<f64>() * 0.25 + hm - scalar(&l.total)).abs() < 1e-5);
    }

    #[test]
    fn no_object_is_finite() {
        let device = Device::flex();
        let out = Tensor::<4>::full([1, 9, 4, 4], -2.19, &device);
        let t = HeatmapTargets { heatmap: vec![0.0; 16], ..Default::default() };
        let l = loss(out, &t, 2.0, 4.0, 0.25, &device);
        let p = 1.0 / (1.0 + 2.19f64.exp());
        assert!((scalar(&l.total) + 16.0 * (1.0 - p).ln() * p * p).abs() < 1e-4);
    }
}
