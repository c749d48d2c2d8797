//! The public entry point of the op on Burn tensors, whatever the backend of the device.

use std::sync::Arc;

use burn::backend::Dispatch;
use burn::tensor::Tensor;

use crate::backend::SparseConvBackend;
use crate::geometry::kernel_map::KernelMap;

/// `out[o] = Σ_k Σ_{(i, o) ∈ M_k} features[i] · weight[k]`, differentiable in both arguments.
///
/// `features` is `[map.n_in(), C_in]`, `weight` is `[map.volume(), C_in, C_out]`; the result is
/// `[map.n_out(), C_out]` on the same device.
pub fn sparse_conv(features: Tensor<2>, weight: Tensor<3>, map: &Arc<KernelMap>) -> Tensor<2> {
    check_conv_inputs(&features, &weight, map);
    Tensor::from_dispatch(<Dispatch as SparseConvBackend>::sparse_conv(
        features.into_dispatch(),
        weight.into_dispatch(),
        map.clone(),
    ))
}

/// Panics, naming the mismatch, unless `features` and `weight` fit `map` and each other; returns
/// the output channels.
pub(crate) fn check_conv_inputs(features: &Tensor<2>, weight: &Tensor<3>, map: &KernelMap) -> usize {
    let [rows, c_in] = features.dims();
    let [volume, w_in, c_out] = weight.dims();
    assert_eq!(rows, map.n_in(), "features have {rows} rows but the kernel map expects {}", map.n_in());
    assert_eq!(volume, map.volume(), "weight has {volume} offsets but the kernel map has {}", map.volume());
    assert_eq!(c_in, w_in, "features have {c_in} channels, the weight expects {w_in}");
    c_out
}
