//! `FusedAdam` steps parameters as Burn's `Adam` does (weight decay, AMSGrad, several ranks) on
//! every backend, and resumes from its own or Burn's saved state, with and without AMSGrad.
// burn-ndarray is deprecated in Burn 0.22 but is one of the CPU backends pmunet supports.
#![allow(deprecated)]

mod common;

use common::*;
use sparse_conv::FusedAdamConfig;
use sparse_conv::burn::module::{Module, Param};
use sparse_conv::burn::optim::decay::WeightDecayConfig;
use sparse_conv::burn::optim::{AdamConfig, GradientsParams, ModuleOptimizer};
use sparse_conv::burn::tensor::{DType, Device, Tensor, TensorData};

#[derive(Module, Debug)]
struct Params {
    weight: Param<Tensor<3>>,
    bias: Param<Tensor<1>>,
}

/// Rank-3 and rank-1 parameters (a conv weight, a bias) of random values on `device`.
fn params(device: &Device, dtype: DType) -> Params {
    let mut r = rng(5);
    let (w, b) = (random_values(&mut r, 4 * 3 * 5), random_values(&mut r, 7));
    Params {
        weight: Param::from_tensor(Tensor::from_data(TensorData::new(w, [4, 3, 5]), (device, dtype))),
        bias: Param::from_tensor(Tensor::from_data(TensorData::new(b, [7]), (device, dtype))),
    }
}

/// One step of a loss whose gradient changes from step to step: `Σ (w − 0.1·i)² + Σ b·sin b`.
fn step(model: Params, optim: &mut ModuleOptimizer, i: usize) -> Params {
    let target = model.weight.val().ones_like().mul_scalar(0.1 * i as f64);
    let loss = (model.weight.val() - target).powi_scalar(2).sum() + (model.bias.val() * model.bias.val().sin()).sum();
    let grads = GradientsParams::from_grads(loss.backward(), &model);
    optim.step(1e-2, model, grads)
}

fn flat(model: &Params) -> Vec<f64> {
    let mut v = values(model.weight.val());
    v.extend(values(model.bias.val()));
    v
}

fn devices() -> Vec<(Device, DType, &'static str)> {
    let mut out = vec![(Device::flex(), DType::F32, "flex"), (Device::ndarray(), DType::F32, "ndarray"), (Device::flex(), DType::F64, "flex f64")];
    if let Some(wgpu) = wgpu_device() {
        out.push((wgpu, DType::F32, "wgpu"));
    }
    out
}

#[test]
fn steps_match_burns_adam() {
    for (device, dtype, name) in devices() {
        let ad = device.clone().autodiff();
        for (weight_decay, amsgrad) in [(None, false), (Some(0.05), false), (Some(0.05), true)] {
            let decay = weight_decay.map(|penalty| WeightDecayConfig { penalty });
            let mut fused = FusedAdamConfig::new().with_epsilon(1e-8).with_weight_decay(decay.clone()).with_amsgrad(amsgrad).init();
            let mut burn = AdamConfig::new().with_epsilon(1e-8).with_weight_decay(decay).with_amsgrad(amsgrad).init();
            let (mut a, mut b) = (params(&ad, dtype), params(&ad, dtype));
            let start = flat(&a);
            for i in 0..6 {
                a = step(a, &mut fused, i);
                b = step(b, &mut burn, i);
                let what = format!("{name}, weight decay {weight_decay:?}, AMSGrad {amsgrad}, step {i}");
                assert_close(&flat(&a), &flat(&b), 1e-6, &what);
            }
            assert!(flat(&a).iter().zip(&start).all(|(x, y)| x != y), "{name}: every parameter moved");
        }
    }
}

#[test]
fn resumes_from_saved_state() {
    let device = Device::flex().autodiff();
    let dir = std::env::temp_dir().join(format!("pmunet-adam-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let decay = || Some(WeightDecayConfig { penalty: 0.01 });
    for amsgrad in [false, true] {
        let new_fused = || FusedAdamConfig::new().with_weight_decay(decay()).with_amsgrad(amsgrad).init();
        let mut straight = new_fused();
        let mut model = params(&device, DType::F32);
        for i in 0..6 {
            model = step(model, &mut straight, i);
        }
        let expected = flat(&model);
        // Three steps by FusedAdam, or by Burn's Adam, then saved; three more by a new FusedAdam
        // loaded from that state.
        for (name, mut first) in [("fused", new_fused()), ("burn", AdamConfig::new().with_weight_decay(decay()).with_amsgrad(amsgrad).init())] {
            let mut model = params(&device, DType::F32);
            for i in 0..3 {
                model = step(model, &mut first, i);
            }
            let path = dir.join(format!("{name}-{amsgrad}.bpk"));
            first.save(&path).unwrap();
            let mut resumed = new_fused().load(&path).unwrap();
            for i in 3..6 {
                model = step(model, &mut resumed, i);
            }
            assert_close(&flat(&model), &expected, 1e-6, &format!("resumed from {name}'s state, AMSGrad {amsgrad}"));
        }
    }
    std::fs::remove_dir_all(&dir).ok();
}
