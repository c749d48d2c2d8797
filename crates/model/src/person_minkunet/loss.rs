//! Person-MinkUNet's loss (docs/model.md): soft-target BCE over all voxels, and on foreground
//! voxels centre MSE, log-dimension MSE, bin cross-entropy and residual MSE (or, with the heading
//! as a sine and cosine, their MSE; with the axis and facing, a facing BCE besides the bins), each
//! reported on its own.

use sparse_conv::burn::tensor::activation::{log_sigmoid, log_softmax, relu};
use sparse_conv::burn::tensor::{Device, Int, Tensor, TensorData};

use super::box_coder::{BINS, CLS, HeadingEncoding, LOG_DIMS, OFFSET, facing_channel, head_channels};
use crate::detector::LossTerms;
use super::targets::VoxelTargets;

/// Weights of the five terms; the defaults are the authors' code (100, 1, 1, 0.1, 0.01).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LossWeights {
    /// Soft-target BCE, averaged over all voxels.
    pub cls: f64,
    /// Centre-offset MSE on foreground voxels.
    pub loc: f64,
    /// Log-dimension MSE on foreground voxels.
    pub dims: f64,
    /// Bin cross-entropy on foreground voxels.
    pub bin: f64,
    /// Residual MSE (all bins) on foreground voxels.
    pub residual: f64,
    /// sin/cos MSE on foreground voxels ([`HeadingEncoding::SinCos`] only).
    pub sin_cos: f64,
    /// Facing BCE on foreground voxels ([`HeadingEncoding::AxisFacing`] only).
    pub facing: f64,
}

impl Default for LossWeights {
    fn default() -> Self {
        Self { cls: 100.0, loc: 1.0, dims: 1.0, bin: 0.1, residual: 0.01, sin_cos: 1.0, facing: 1.0 }
    }
}

/// Names of the terms, in the order [`loss`] reports them (bins).
pub const TERMS: [&str; 5] = ["cls", "loc", "dims", "bin", "residual"];
/// Names of the terms with the heading as a sine and cosine.
pub const TERMS_SIN_COS: [&str; 4] = ["cls", "loc", "dims", "heading"];
/// Names of the terms with the heading as an axis and a facing.
pub const TERMS_AXIS_FACING: [&str; 6] = ["cls", "loc", "dims", "bin", "residual", "facing"];

/// BCE with logits against a soft target, element-wise and stable for any logit:
/// `max(x, 0) − x·t + log(1 + e^{−|x|})`.
pub fn bce_with_logits<const D: usize>(x: Tensor<D>, t: Tensor<D>) -> Tensor<D> {
    relu(x.clone()) - x.clone() * t - log_sigmoid(x.abs())
}

/// A host slice as a tensor of `shape`.
fn floats<const D: usize>(v: &[f32], shape: [usize; D], device: &Device) -> Tensor<D> {
    Tensor::from_data(TensorData::new(v.to_vec(), shape), device)
}

/// The weighted terms and their sum for head output `out` (`[M, 2·bins + 7]`, `[M, 2·bins + 8]`
/// with the axis and facing, or `[M, 9]` with `heading` = sin/cos) and `targets`: [`TERMS`],
/// [`TERMS_AXIS_FACING`] or [`TERMS_SIN_COS`].
///
/// A batch without foreground voxels gives zero for the foreground terms (finite loss).
pub fn loss(out: Tensor<2>, targets: &VoxelTargets, num_bins: usize, heading: HeadingEncoding, w: &LossWeights, device: &Device) -> LossTerms {
    let [m, c] = out.dims();
    let want = head_channels(num_bins, heading);
    assert_eq!(c, want, "head output has {c} channels, the layout needs {want}");
    assert_eq!(targets.cls.len(), m, "one classification target per voxel");
    let logits = out.clone().slice([0..m, CLS..CLS + 1]).reshape([m]);
    let t_cls = floats(&targets.cls, [m], device);
    let cls = bce_with_logits(logits, t_cls).mean() * w.cls;
    let names: &[&'static str] = match heading {
        HeadingEncoding::Bins => &TERMS,
        HeadingEncoding::AxisFacing => &TERMS_AXIS_FACING,
        HeadingEncoding::SinCos => &TERMS_SIN_COS,
    };
    let f = targets.fg.len();
    let foreground: Vec<Tensor<1>> = if f == 0 {
        names[1..].iter().map(|_| Tensor::<1>::zeros([1], device)).collect()
    } else {
        let idx: Vec<i64> = targets.fg.iter().map(|&r| r as i64).collect();
        let rows = out.select(0, Tensor::<1, Int>::from_data(TensorData::new(idx, [f]), device));
        let mse = |a: Tensor<2>, b: Tensor<2>| (a - b).powi_scalar(2).mean();
        let loc = mse(rows.clone().slice([0..f, OFFSET..OFFSET + 3]), floats(&targets.offset, [f, 3], device));
        let dims = mse(rows.clone().slice([0..f, LOG_DIMS..LOG_DIMS + 3]), floats(&targets.log_dims, [f, 3], device));
        let mut terms = vec![loc * w.loc, dims * w.dims];
        match heading {
            HeadingEncoding::Bins | HeadingEncoding::AxisFacing => {
                let log_p = log_softmax(rows.clone().slice([0..f, BINS..BINS + num_bins]), 1);
                let k = Tensor::<1, Int>::from_data(TensorData::new(targets.bin.clone(), [f]), device).reshape([f, 1]);
                let bin = -log_p.gather(1, k).mean();
                let res_pred = rows.clone().slice([0..f, BINS + num_bins..BINS + 2 * num_bins]);
                let residual = mse(res_pred, floats(&targets.residuals, [f, num_bins], device));
                terms.extend([bin * w.bin, residual * w.residual]);
                if heading == HeadingEncoding::AxisFacing {
                    let at = facing_channel(num_bins);
                    let logit = rows.slice([0..f, at..at + 1]).reshape([f]);
                    let facing = bce_with_logits(logit, floats(&targets.facing, [f], device)).mean();
                    terms.push(facing * w.facing);
                }
            }
            HeadingEncoding::SinCos => {
                let sin_cos = mse(rows.slice([0..f, BINS..BINS + 2]), floats(&targets.sin_cos, [f, 2], device));
                terms.push(sin_cos * w.sin_cos);
            }
        }
        terms
    };
    let total = foreground.iter().fold(cls.clone(), |acc, t| acc + t.clone());
    LossTerms { total, terms: names.iter().copied().zip(std::iter::once(cls).chain(foreground)).collect() }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scalar(t: &Tensor<1>) -> f64 {
        t.to_data().try_to_vec::<f32>().unwrap()[0] as f64
    }

    #[test]
    fn each_term_matches_a_hand_computation() {
        let device = Device::flex();
        let bins = 2;
        // Three voxels, channels: cls, 3 offset, 3 log-dims, 2 bin logits, 2 residuals.
        let rows: [[f32; 11]; 3] = [
            [2.0, 0.1, -0.2, 0.3, 0.0, 0.5, -0.5, 1.0, -1.0, 0.2, -0.4],
            [-30.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
            [-1.0, 1.0, 1.0, 1.0, 0.1, 0.2, 0.3, 0.0, 3.0, 1.0, 1.0],
        ];
        let out = Tensor::<1>::from_data(TensorData::new(rows.concat(), [33]), &device).reshape([3, 11]);
        let t = VoxelTargets {
            cls: vec![0.7, 0.0, 0.25],
            fg: vec![0, 2],
            offset: vec![0.0, 0.0, 0.0, 1.0, 2.0, 1.0],
            log_dims: vec![0.1, 0.5, -0.5, 0.0, 0.0, 0.0],
            bin: vec![0, 0],
            residuals: vec![0.2, 0.0, 0.5, -1.0],
            sin_cos: vec![0.0, 1.0, 1.0, 0.0],
            facing: vec![1.0, 0.0],
        };
        let w = LossWeights::default();
        let l = loss(out.clone(), &t, bins, HeadingEncoding::Bins, &w, &device);
        let bce = |x: f64, t: f64| -(t * (1.0 / (1.0 + (-x).exp())).ln() + (1.0 - t) * (1.0 / (1.0 + x.exp())).ln());
        let cls = 100.0 * (bce(2.0, 0.7) + bce(-30.0, 0.0) + bce(-1.0, 0.25)) / 3.0;
        let loc = (0.01 + 0.04 + 0.09 + 0.0 + 1.0 + 0.0) / 6.0;
        let dims = (0.01 + 0.0 + 0.0 + 0.01 + 0.04 + 0.09) / 6.0;
        let ce = |a: f64, b: f64, k: usize| -([a, b][k] - (a.exp() + b.exp()).ln());
        let bin = 0.1 * (ce(1.0, -1.0, 0) + ce(0.0, 3.0, 0)) / 2.0;
        let residual = 0.01 * (0.0 + 0.16 + 0.25 + 4.0) / 4.0;
        let want = [cls, loc, dims, bin, residual];
        for ((name, got), want) in l.terms.iter().zip(want) {
            assert!((scalar(got) - want).abs() < 1e-4 * want.abs().max(1.0), "{name}: {} vs {want}", scalar(got));
        }
        assert!((scalar(&l.total) - want.iter().sum::<f64>()).abs() < 1e-3);
        assert_eq!(l.terms.iter().map(|(n, _)| *n).collect::<Vec<_>>(), TERMS);

        // The same rows read as the sin/cos layout (channels 7 and 8 are sin and cos).
        let l = loss(out.clone().slice([0..3, 0..9]), &t, bins, HeadingEncoding::SinCos, &w, &device);
        // Row 0 predicts (1, −1) against (0, 1); row 2 (0, 3) against (1, 0).
        let heading = (1.0 + 4.0 + 1.0 + 9.0) / 4.0;
        for ((name, got), want) in l.terms.iter().zip([cls, loc, dims, heading]) {
            assert!((scalar(got) - want).abs() < 1e-4 * want.abs().max(1.0), "{name}: {} vs {want}", scalar(got));
        }
        assert_eq!(l.terms.iter().map(|(n, _)| *n).collect::<Vec<_>>(), TERMS_SIN_COS);

        // The axis-and-facing layout: the same rows and a facing logit (0.5, 9, −1.5) after them;
        // the bin terms are the bins' own, the facing BCE is over the two foreground rows.
        let facing_logits = Tensor::<1>::from_data(TensorData::new(vec![0.5f32, 9.0, -1.5], [3]), &device).reshape([3, 1]);
        let l = loss(Tensor::cat(vec![out, facing_logits], 1), &t, bins, HeadingEncoding::AxisFacing, &w, &device);
        let facing = (bce(0.5, 1.0) + bce(-1.5, 0.0)) / 2.0;
        for ((name, got), want) in l.terms.iter().zip([cls, loc, dims, bin, residual, facing]) {
            assert!((scalar(got) - want).abs() < 1e-4 * want.abs().max(1.0), "{name}: {} vs {want}", scalar(got));
        }
        assert_eq!(l.terms.iter().map(|(n, _)| *n).collect::<Vec<_>>(), TERMS_AXIS_FACING);
    }

    #[test]
    fn no_person_gives_a_finite_loss_with_gradients() {
        let device = Device::flex().autodiff();
        let out = Tensor::<2>::from_data(TensorData::new(vec![50.0f32; 2 * 31], [2, 31]), &device).require_grad();
        let t = VoxelTargets { cls: vec![0.0, 0.0], ..Default::default() };
        let l = loss(out.clone(), &t, 12, HeadingEncoding::Bins, &LossWeights::default(), &device);
        let v = scalar(&l.total);
        assert!(v.is_finite() && (v - 5000.0).abs() < 1e-2, "BCE of logit 50 against 0 is 50, ×100: {v}");
        let grads = l.total.backward();
        let g = out.grad(&grads).unwrap().to_data().try_to_vec::<f32>().unwrap();
        assert!(g.iter().all(|x| x.is_finite()));
        assert!((g[0] - 50.0).abs() < 1e-3, "d/dx of 100·mean BCE = 100·(σ(x) − t)/M = 50, got {}", g[0]);
    }
}
