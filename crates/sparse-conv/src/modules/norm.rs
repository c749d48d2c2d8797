//! Batch norm over voxel features.

use burn::config::Config;
use burn::module::{Module, Param, RunningState};
use burn::nn::{BatchNorm, BatchNormConfig};
use std::sync::Arc;

use burn::tensor::{Device, Tensor};

use crate::SparseTensor;
use crate::ops::batch_norm::{Epilogue, batch_norm_eval, batch_norm_train};
use crate::ops::conv_norm::sparse_conv_norm_eval;
use crate::geometry::kernel_map::KernelMap;
use crate::ops::conv::sparse_conv;

/// Configuration of a [`SparseBatchNorm`]; the defaults are PyTorch's `BatchNorm1d`, which the
/// authors' MinkUNet uses.
#[derive(Config, Debug)]
pub struct SparseBatchNormConfig {
    /// Channels.
    pub channels: usize,
    #[config(default = 1e-5)]
    /// ε added to the variance (1e-5).
    pub epsilon: f64,
    #[config(default = 0.1)]
    /// Momentum of the running statistics (0.1, PyTorch's convention).
    pub momentum: f64,
    #[config(default = 1)]
    /// Orientation copies the channels hold (orientation-major, [`super::turns`]): statistics,
    /// scale and shift are shared by the copies of a channel, so a turn of the input commutes
    /// with the norm. 1: plain channels.
    pub copies: usize,
}

/// Batch norm with every voxel of the batch as one sample: batch statistics and running-stat
/// updates on an autodiff device with the layer's training flag on, running statistics
/// otherwise (Burn's `BatchNorm` switch, whose parameters and record it keeps). It runs as the
/// fused op of [`crate::ops::batch_norm`], with the ReLU after it folded in by [`Self::forward_relu`]
/// and a residual block's shortcut sum and ReLU by [`Self::forward_add_relu`]; evaluating after
/// a conv, it runs inside the conv's op ([`Self::after_conv`]).
#[derive(Module, Debug)]
pub struct SparseBatchNorm {
    /// Burn's batch norm: its parameters, running statistics and record (one per channel of a
    /// copy).
    pub inner: BatchNorm,
    /// Orientation copies sharing `inner` (1: none).
    #[module(skip)]
    pub copies: usize,
}

impl SparseBatchNormConfig {
    /// Weight 1, bias 0.
    pub fn init(&self, device: &Device) -> SparseBatchNorm {
        assert!(self.copies >= 1 && self.channels % self.copies == 0, "{} channels do not split into {} copies", self.channels, self.copies);
        let inner = BatchNormConfig::new(self.channels / self.copies).with_epsilon(self.epsilon).with_momentum(self.momentum).init(device);
        SparseBatchNorm { inner, copies: self.copies }
    }
}

impl SparseBatchNorm {
    /// The same norm over plain channels: each copy's parameters and running statistics
    /// repeated, so that it computes what the shared norm does (for inference).
    pub fn untied(self) -> Self {
        if self.copies == 1 {
            return self;
        }
        let copies = self.copies;
        let every = |v: Tensor<1>| Tensor::cat(vec![v; copies], 0);
        let mut inner = self.inner;
        inner.gamma = Param::from_tensor(every(inner.gamma.val()));
        inner.beta = Param::from_tensor(every(inner.beta.val()));
        inner.running_mean = RunningState::new(every(inner.running_mean.value()));
        inner.running_var = RunningState::new(every(inner.running_var.value()));
        SparseBatchNorm { inner, copies: 1 }
    }

    /// Applies the module to `x`'s features, on `x`'s coordinates (or the level it maps to).
    pub fn forward(&self, x: SparseTensor) -> SparseTensor {
        let features = self.features(x.features(), Epilogue::Identity);
        x.with_features(features)
    }

    /// `relu(self.forward(x))` in one op.
    pub fn forward_relu(&self, x: SparseTensor) -> SparseTensor {
        let features = self.features(x.features(), Epilogue::Relu);
        x.with_features(features)
    }

    /// `relu(self.forward(x) + residual)` in one op; `residual` holds features of `x`'s voxels.
    pub fn forward_add_relu(&self, x: SparseTensor, residual: Tensor<2>) -> SparseTensor {
        let features = self.features(x.features(), Epilogue::AddRelu(residual));
        x.with_features(features)
    }

    /// `epilogue(self(conv))` for the conv of `features` with `weight` over `map`: evaluating, one
    /// op (the norm runs on the conv's finished rows); training, the conv and then the norm.
    pub fn after_conv(&self, features: Tensor<2>, weight: Tensor<3>, map: &Arc<KernelMap>, epilogue: Epilogue) -> Tensor<2> {
        match self.running_stats(&features.device()) {
            Some((mean, var)) => {
                let bn = &self.inner;
                let every = |v: Tensor<1>| if self.copies == 1 { v } else { Tensor::cat(vec![v; self.copies], 0) };
                let (mean, var, gamma, beta) = (every(mean), every(var), every(bn.gamma.val()), every(bn.beta.val()));
                sparse_conv_norm_eval(features, weight, map, mean, var, gamma, beta, bn.epsilon, epilogue)
            }
            None => self.features(sparse_conv(features, weight, map), epilogue),
        }
    }

    /// The running mean and variance on `device` when the layer normalises with them (not
    /// training on an autodiff device), else `None` (batch statistics).
    fn running_stats(&self, device: &Device) -> Option<(Tensor<1>, Tensor<1>)> {
        let bn = &self.inner;
        (!(device.is_autodiff() && bn.training.is_enabled())).then(|| (bn.running_mean.value().to_device(device), bn.running_var.value().to_device(device)))
    }

    fn features(&self, x: Tensor<2>, epilogue: Epilogue) -> Tensor<2> {
        if self.copies == 1 {
            return self.plain_features(x, epilogue);
        }
        // Orientation-major rows of C = copies·c channels are `copies` rows of c channels each.
        let [rows, total] = x.dims();
        let per_copy = |t: Tensor<2>| t.reshape([rows * self.copies, total / self.copies]);
        let epilogue = match epilogue {
            Epilogue::AddRelu(residual) => Epilogue::AddRelu(per_copy(residual)),
            other => other,
        };
        self.plain_features(per_copy(x), epilogue).reshape([rows, total])
    }

    fn plain_features(&self, x: Tensor<2>, epilogue: Epilogue) -> Tensor<2> {
        let bn = &self.inner;
        let [rows, channels] = x.dims();
        assert_eq!(channels, bn.gamma.dims()[0], "batch norm of {} channels got features of {channels}", bn.gamma.dims()[0]);
        let device = x.device();
        if let Some((mean, var)) = self.running_stats(&device) {
            return batch_norm_eval(x, mean, var, bn.gamma.val(), bn.beta.val(), bn.epsilon, epilogue);
        }
        let (out, stats) = batch_norm_train(x, bn.gamma.val(), bn.beta.val(), bn.epsilon, epilogue);
        // An empty batch has no statistics; the running averages keep their values.
        if rows > 0 {
            let stat = |i: usize| stats.clone().slice([i..i + 1, 0..channels]).reshape([channels]).detach();
            let blend = |running: Tensor<1>, batch: Tensor<1>| {
                running.mul_scalar(1.0 - bn.momentum).add(batch.mul_scalar(bn.momentum)).detach()
            };
            bn.running_mean.update(blend(bn.running_mean.value_sync().to_device(&device), stat(0)));
            bn.running_var.update(blend(bn.running_var.value_sync().to_device(&device), stat(1)));
            // Burn holds an update per thread until the next sync, and a saved record reads the
            // synced value: without this, a checkpoint written between steps (not after a
            // validation, which syncs) missed the last step's update, and a run resumed from it
            // validated differently from an uninterrupted one.
            let _ = (bn.running_mean.value_sync(), bn.running_var.value_sync());
        }
        out
    }
}
