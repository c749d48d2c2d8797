//! The fused batch norm (+ ReLU, + a residual's sum and ReLU) against Burn's own `BatchNorm`
//! followed by Burn's add and `relu`, which Burn differentiates on its own: outputs, running
//! statistics and the gradients to the features, γ, β and the residual, in training and in
//! inference, on every backend; and central finite differences.

mod common;

use common::*;
use sparse_conv::burn::module::RunningState;
use sparse_conv::burn::nn::BatchNormConfig;
use sparse_conv::burn::tensor::activation::relu;
use sparse_conv::burn::tensor::{DType, Device, Tensor, TensorData};
use sparse_conv::modules::SparseBatchNormConfig;
use sparse_conv::{Epilogue, SparseTensor, batch_norm_train};

const ROWS: usize = 2600;
const C: usize = 5;

/// Features whose channels have different means and spreads (channel 3 far from zero).
fn features(seed: u64) -> Vec<f64> {
    let v = random_values(&mut rng(seed), ROWS * C);
    v.iter().enumerate().map(|(i, x)| x * (1.0 + (i % C) as f64) + [0.0, -2.0, 0.5, 40.0, 1.0][i % C]).collect()
}

fn params(seed: u64) -> (Vec<f64>, Vec<f64>) {
    let v = random_values(&mut rng(seed), 2 * C);
    (v[..C].iter().map(|g| 1.0 + 0.5 * g).collect(), v[C..].to_vec())
}

fn vec1(v: &[f64], device: &Device, dtype: DType) -> Tensor<1> {
    Tensor::from_data(TensorData::new(v.to_vec(), [v.len()]), (device, dtype))
}

/// `L = Σ ½·y² + y·G`.
fn loss(y: Tensor<2>, g: Tensor<2>) -> Tensor<1> {
    (y.clone() * y.clone() * 0.5 + y * g).sum()
}

fn sparse(x: Tensor<2>) -> SparseTensor {
    let coords = (0..x.dims()[0] as i32).map(|i| [0, i, 0, 0]).collect();
    SparseTensor::new(x, coords).unwrap()
}

/// What follows the batch norm in a test.
#[derive(Clone, Copy, Debug)]
enum After {
    Nothing,
    Relu,
    /// `relu(· + r)` with a random residual `r`.
    AddRelu,
}

const AFTER: [After; 3] = [After::Nothing, After::Relu, After::AddRelu];

/// Our layer's forward (`fused`) or Burn's `BatchNorm` and Burn's add and `relu`.
fn apply(layer: &sparse_conv::modules::SparseBatchNorm, x: Tensor<2>, residual: Tensor<2>, after: After, fused: bool) -> Tensor<2> {
    if fused {
        let s = sparse(x);
        match after {
            After::Nothing => layer.forward(s),
            After::Relu => layer.forward_relu(s),
            After::AddRelu => layer.forward_add_relu(s, residual),
        }
        .into_features()
    } else {
        let y = layer.inner.forward(x);
        match after {
            After::Nothing => y,
            After::Relu => relu(y),
            After::AddRelu => relu(y + residual),
        }
    }
}

struct Outcome {
    y: Vec<f64>,
    dx: Vec<f64>,
    dgamma: Vec<f64>,
    dbeta: Vec<f64>,
    dresidual: Vec<f64>,
    running: [Vec<f64>; 2],
}

/// One training step's forward and backward through our layer (`fused`) or Burn's.
fn train_step(device: &Device, dtype: DType, after: After, fused: bool) -> Outcome {
    let ad = device.clone().autodiff();
    let (gamma, beta) = params(2);
    let x = tensor2(&features(1), [ROWS, C], &ad, dtype).require_grad();
    let g = tensor2(&random_values(&mut rng(3), ROWS * C), [ROWS, C], &ad, dtype);
    let residual = tensor2(&random_values(&mut rng(8), ROWS * C), [ROWS, C], &ad, dtype).require_grad();
    let mut layer = SparseBatchNormConfig::new(C).init(&ad);
    layer.inner.gamma = layer.inner.gamma.map(|_| vec1(&gamma, &ad, dtype).require_grad());
    layer.inner.beta = layer.inner.beta.map(|_| vec1(&beta, &ad, dtype).require_grad());
    layer.inner.running_mean = RunningState::new(vec1(&[0.0; C], &ad, dtype));
    layer.inner.running_var = RunningState::new(vec1(&[1.0; C], &ad, dtype));
    let y = apply(&layer, x.clone(), residual.clone(), after, fused);
    let grads = loss(y.clone(), g).backward();
    Outcome {
        y: values(y),
        dx: values(x.grad(&grads).unwrap()),
        dgamma: values(layer.inner.gamma.grad(&grads).unwrap()),
        dbeta: values(layer.inner.beta.grad(&grads).unwrap()),
        dresidual: residual.grad(&grads).map(values).unwrap_or_default(),
        running: [values(layer.inner.running_mean.value_sync()), values(layer.inner.running_var.value_sync())],
    }
}

#[test]
fn training_matches_burns_batch_norm_and_relu() {
    for t in targets() {
        for after in AFTER {
            let ours = train_step(&t.device, t.dtype, after, true);
            // The reference in f64 on the CPU, whatever the target.
            let reference = train_step(&Device::flex(), DType::F64, after, false);
            let what = |w: &str| format!("{} {after:?}: {w}", t.name);
            assert_eq!(ours.dresidual.len(), reference.dresidual.len(), "{}", what("residual gradient present"));
            assert_close(&ours.dresidual, &reference.dresidual, t.tol * 10.0, &what("residual gradient"));
            assert_close(&ours.y, &reference.y, t.tol, &what("output"));
            assert_close(&ours.dx, &reference.dx, t.tol * 10.0, &what("feature gradient"));
            assert_close(&ours.dgamma, &reference.dgamma, t.tol * 10.0, &what("gamma gradient"));
            assert_close(&ours.dbeta, &reference.dbeta, t.tol * 10.0, &what("beta gradient"));
            assert_close(&ours.running[0], &reference.running[0], t.tol, &what("running mean"));
            assert_close(&ours.running[1], &reference.running[1], t.tol, &what("running variance"));
        }
    }
}

/// Without autodiff (inference), the layer normalises with the running statistics, as Burn's.
#[test]
fn inference_uses_the_running_statistics() {
    for t in targets() {
        let (gamma, beta) = params(4);
        let mut ours = SparseBatchNormConfig::new(C).init(&t.device);
        let mut burns = BatchNormConfig::new(C).init(&t.device);
        for bn in [&mut ours.inner, &mut burns] {
            bn.gamma = bn.gamma.clone().map(|_| vec1(&gamma, &t.device, t.dtype));
            bn.beta = bn.beta.clone().map(|_| vec1(&beta, &t.device, t.dtype));
            bn.running_mean = RunningState::new(vec1(&[0.5, -1.0, 0.0, 39.0, 2.0], &t.device, t.dtype));
            bn.running_var = RunningState::new(vec1(&[1.0, 4.0, 9.0, 0.25, 2.0], &t.device, t.dtype));
        }
        let x = tensor2(&features(5), [ROWS, C], &t.device, t.dtype);
        let residual = tensor2(&random_values(&mut rng(9), ROWS * C), [ROWS, C], &t.device, t.dtype);
        let reference = sparse_conv::modules::SparseBatchNorm { inner: burns, copies: 1 };
        for after in AFTER {
            let expected = values(apply(&reference, x.clone(), residual.clone(), after, false));
            let actual = values(apply(&ours, x.clone(), residual.clone(), after, true));
            assert_close(&actual, &expected, t.tol, &format!("{} {after:?}: inference", t.name));
        }
    }
}

/// The gradients of the fused op equal central differences of its loss (f64), with the ReLU and
/// with the residual's sum and ReLU (away from the kink: the points are random).
#[test]
fn gradients_match_finite_differences() {
    let device = Device::flex();
    let (rows, c) = (40, 3);
    let x0 = random_values(&mut rng(6), rows * c);
    let g0 = random_values(&mut rng(7), rows * c);
    let r0 = random_values(&mut rng(10), rows * c);
    let (gamma0, beta0) = (vec![1.3, 0.7, -0.4], vec![0.1, -0.2, 0.3]);
    for with_residual in [false, true] {
        // args: x, γ, β, residual.
        let forward = |d: &Device, args: [Tensor<2>; 2], gamma: Tensor<1>, beta: Tensor<1>| {
            let [x, r] = args;
            let epilogue = if with_residual { Epilogue::AddRelu(r) } else { Epilogue::Relu };
            let (y, _) = batch_norm_train(x, gamma, beta, 1e-5, epilogue);
            loss(y, tensor2(&g0, [rows, c], d, DType::F64))
        };
        let loss_of = |args: &[Vec<f64>; 4]| {
            let t = |v: &[f64]| tensor2(v, [rows, c], &device, DType::F64);
            values(forward(&device, [t(&args[0]), t(&args[3])], vec1(&args[1], &device, DType::F64), vec1(&args[2], &device, DType::F64)))[0]
        };
        let ad = device.clone().autodiff();
        let x = tensor2(&x0, [rows, c], &ad, DType::F64).require_grad();
        let r = tensor2(&r0, [rows, c], &ad, DType::F64).require_grad();
        let gamma = vec1(&gamma0, &ad, DType::F64).require_grad();
        let beta = vec1(&beta0, &ad, DType::F64).require_grad();
        let grads = forward(&ad, [x.clone(), r.clone()], gamma.clone(), beta.clone()).backward();
        let analytic = [values(x.grad(&grads).unwrap()), values(gamma.grad(&grads).unwrap()), values(beta.grad(&grads).unwrap()), r.grad(&grads).map(values).unwrap_or_default()];
        assert_eq!(analytic[3].is_empty(), !with_residual, "a residual gradient exactly when there is a residual");
        let eps = 1e-6;
        for (which, grad) in analytic.iter().enumerate() {
            for i in 0..grad.len() {
                let mut args = [x0.clone(), gamma0.clone(), beta0.clone(), r0.clone()];
                args[which][i] += eps;
                let plus = loss_of(&args);
                args[which][i] -= 2.0 * eps;
                let minus = loss_of(&args);
                let numeric = (plus - minus) / (2.0 * eps);
                assert!((grad[i] - numeric).abs() < 1e-5 * (1.0 + numeric.abs()), "residual {with_residual}, argument {which}, element {i}: {} vs {numeric}", grad[i]);
            }
        }
    }
}

/// An empty batch normalises nothing and leaves the running statistics as they were.
#[test]
fn empty_batch_keeps_the_running_statistics() {
    let ad = Device::flex().autodiff();
    let layer = SparseBatchNormConfig::new(C).init(&ad);
    let x = Tensor::<2>::zeros([0, C], &ad);
    let y = layer.forward_relu(SparseTensor::new(x, Vec::new()).unwrap());
    assert_eq!(y.features().dims(), [0, C]);
    assert_eq!(values(layer.inner.running_mean.value_sync()), vec![0.0; C]);
    assert_eq!(values(layer.inner.running_var.value_sync()), vec![1.0; C]);
}
