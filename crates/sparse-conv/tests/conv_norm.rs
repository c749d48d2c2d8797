//! A conv and the batch norm after it at inference, as one op (`sparse_conv_norm_eval`), against
//! the two ops one after the other, on every backend and kind of map; and the U-Net blocks,
//! which use it when evaluating, against their layers run one by one.

mod common;

use std::sync::Arc;

use common::*;
use sparse_conv::burn::module::RunningState;
use sparse_conv::burn::tensor::{DType, Device, Tensor, TensorData};
use sparse_conv::modules::{ResidualBlockConfig, SparseBatchNorm};
use sparse_conv::{CoordIndex, Epilogue, KernelMap, SparseTensor, batch_norm_eval, sparse_conv, sparse_conv_norm_eval};

fn vec1(v: &[f64], device: &Device, dtype: DType) -> Tensor<1> {
    Tensor::from_data(TensorData::new(v.to_vec(), [v.len()]), (device, dtype))
}

/// Running statistics, γ and β for `c` channels: means and scales spread, variances positive.
fn norm_values(seed: u64, c: usize) -> [Vec<f64>; 4] {
    let v = random_values(&mut rng(seed), 4 * c);
    [v[..c].to_vec(), v[c..2 * c].iter().map(|x| 0.2 + x.abs()).collect(), v[2 * c..3 * c].iter().map(|g| 1.0 + 0.5 * g).collect(), v[3 * c..].to_vec()]
}

/// Bit for bit on the CPU backends (the kernels apply the norm with the norm's own arithmetic),
/// within the tolerance on wgpu.
#[test]
fn conv_then_norm_at_inference_equals_the_two_ops() {
    let coords = random_coords(&mut rng(3), 900, 2, 9, 1);
    let index = CoordIndex::build(&coords).unwrap();
    let sub = Arc::new(KernelMap::submanifold(&coords, &index, 3, 1));
    let (down, _) = KernelMap::down(&coords, 2, 1).unwrap();
    let up = Arc::new(down.transposed());
    let down = Arc::new(down);
    let (c_in, c_out) = (5, 37);
    for t in targets() {
        for map in [&sub, &down, &up] {
            let mut r = rng(11);
            let x = tensor2(&random_values(&mut r, map.n_in() * c_in), [map.n_in(), c_in], &t.device, t.dtype);
            let w = tensor3(&random_values(&mut r, map.volume() * c_in * c_out), [map.volume(), c_in, c_out], &t.device, t.dtype);
            let residual = tensor2(&random_values(&mut r, map.n_out() * c_out), [map.n_out(), c_out], &t.device, t.dtype);
            let [mean, var, gamma, beta] = norm_values(5, c_out).map(|v| vec1(&v, &t.device, t.dtype));
            for epilogue in [Epilogue::Identity, Epilogue::Relu, Epilogue::AddRelu(residual.clone())] {
                let relu = !matches!(epilogue, Epilogue::Identity);
                let what = format!("{} {:?} {}", t.name, map.kind(), ["identity", "relu", "add + relu"][matches!(epilogue, Epilogue::Relu) as usize + 2 * matches!(epilogue, Epilogue::AddRelu(_)) as usize]);
                let one_op = values(sparse_conv_norm_eval(x.clone(), w.clone(), map, mean.clone(), var.clone(), gamma.clone(), beta.clone(), 1e-5, epilogue.clone()));
                let conv = sparse_conv(x.clone(), w.clone(), map);
                let two_ops = values(batch_norm_eval(conv, mean.clone(), var.clone(), gamma.clone(), beta.clone(), 1e-5, epilogue));
                if t.name == "wgpu" {
                    assert_close(&one_op, &two_ops, t.tol, &what);
                } else {
                    assert!(one_op == two_ops, "{what}: the one op differs from the two");
                }
                // Both signs before the ReLU: it must clip some outputs and pass others.
                assert!(one_op.iter().any(|v| *v > 0.1), "{what}: no positive output");
                assert!(if relu { one_op.contains(&0.0) } else { one_op.iter().any(|v| *v < -0.1) }, "{what}: no output the ReLU would clip");
            }
        }
    }
}

/// A residual block with a projection shortcut, evaluating: its forward (one op per conv and
/// norm) equals its layers run one by one. In the modules' dtype, f32.
#[test]
fn residual_block_evaluates_as_its_layers_one_by_one() {
    for t in targets().into_iter().map(|t| Target { dtype: DType::F32, ..t }) {
        let block = ResidualBlockConfig::new([6, 11]).init(&t.device);
        let shortcut = block.shortcut.as_ref().expect("the channels change");
        let set = |norm: &SparseBatchNorm, seed: u64| -> SparseBatchNorm {
            let [mean, var, gamma, beta] = norm_values(seed, 11).map(|v| vec1(&v, &t.device, t.dtype));
            let mut inner = norm.inner.clone();
            inner.running_mean = RunningState::new(mean);
            inner.running_var = RunningState::new(var);
            inner.gamma = inner.gamma.clone().map(|_| gamma);
            inner.beta = inner.beta.clone().map(|_| beta);
            SparseBatchNorm { inner, copies: 1 }
        };
        let mut block = block.clone();
        block.norm1 = set(&block.norm1, 1);
        block.norm2 = set(&block.norm2, 2);
        block.shortcut.as_mut().unwrap().norm = set(&shortcut.norm, 3);
        let coords = random_coords(&mut rng(8), 500, 1, 7, 1);
        let x = SparseTensor::new(tensor2(&random_values(&mut rng(9), 500 * 6), [500, 6], &t.device, t.dtype), coords).unwrap();

        let fused = values(block.forward(x.clone()).into_features());
        let main = block.norm1.forward_relu(block.conv1.forward(x.clone()));
        let sc = block.shortcut.as_ref().unwrap();
        let skip = sc.norm.forward(sc.conv.forward(x));
        let one_by_one = values(block.norm2.forward_add_relu(block.conv2.forward(main), skip.into_features()).into_features());
        if t.name == "wgpu" {
            assert_close(&fused, &one_by_one, t.tol, t.name);
        } else {
            assert!(fused == one_by_one, "{}: the block's forward differs from its layers", t.name);
        }
    }
}
