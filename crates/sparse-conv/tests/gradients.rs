//! The op's gradients to features and weights equal central finite differences (f64) and the
//! gradients of the dense reference (Burn's autodiff through `conv3d` on a zero-filled grid).

mod common;

use std::sync::Arc;

use common::*;
use sparse_conv::burn::tensor::module::conv3d;
use sparse_conv::burn::tensor::ops::ConvOptions;
use sparse_conv::burn::tensor::{DType, Device, Int, Tensor, TensorData};
use sparse_conv::{Coord, CoordIndex, KernelMap, sparse_conv};

/// `L = Σ ½·out² + out·G`: quadratic, so central differences are exact up to rounding.
fn loss(out: Tensor<2>, g: Tensor<2>) -> Tensor<1> {
    (out.clone() * out.clone() * 0.5 + out * g).sum()
}

struct Case {
    map: Arc<KernelMap>,
    c_in: usize,
    c_out: usize,
    x: Vec<f64>,
    w: Vec<f64>,
    g: Vec<f64>,
}

impl Case {
    fn loss_value(&self, x: &[f64], w: &[f64], dev: &Device) -> f64 {
        let out = sparse_conv(
            tensor2(x, [self.map.n_in(), self.c_in], dev, DType::F64),
            tensor3(w, [self.map.volume(), self.c_in, self.c_out], dev, DType::F64),
            &self.map,
        );
        values(loss(out, tensor2(&self.g, [self.map.n_out(), self.c_out], dev, DType::F64)))[0]
    }

    fn analytic(&self, dev: &Device) -> (Vec<f64>, Vec<f64>) {
        let ad = dev.clone().autodiff();
        let x = tensor2(&self.x, [self.map.n_in(), self.c_in], &ad, DType::F64).require_grad();
        let w = tensor3(&self.w, [self.map.volume(), self.c_in, self.c_out], &ad, DType::F64).require_grad();
        let out = sparse_conv(x.clone(), w.clone(), &self.map);
        let g = tensor2(&self.g, [self.map.n_out(), self.c_out], &ad, DType::F64);
        let grads = loss(out, g).backward();
        (values(x.grad(&grads).unwrap()), values(w.grad(&grads).unwrap()))
    }
}

fn check_finite_differences(case: &Case, what: &str) {
    let dev = Device::flex();
    let (gx, gw) = case.analytic(&dev);
    let eps = 1e-3;
    let mut r = rng(99);
    use rand::Rng;
    for (name, values_of, grad) in [("features", &case.x, &gx), ("weight", &case.w, &gw)] {
        for _ in 0..25 {
            let i = r.random_range(0..values_of.len());
            let mut plus = values_of.clone();
            let mut minus = values_of.clone();
            plus[i] += eps;
            minus[i] -= eps;
            let (lp, lm) = if name == "features" {
                (case.loss_value(&plus, &case.w, &dev), case.loss_value(&minus, &case.w, &dev))
            } else {
                (case.loss_value(&case.x, &plus, &dev), case.loss_value(&case.x, &minus, &dev))
            };
            let fd = (lp - lm) / (2.0 * eps);
            assert!((fd - grad[i]).abs() <= 1e-6 * (1.0 + fd.abs()), "{what}: d/d{name}[{i}] analytic {} vs finite difference {fd}", grad[i]);
        }
    }
}

fn random_case(map: KernelMap, c_in: usize, c_out: usize, seed: u64) -> Case {
    let mut r = rng(seed);
    let x = random_values(&mut r, map.n_in() * c_in);
    let w = random_values(&mut r, map.volume() * c_in * c_out);
    let g = random_values(&mut r, map.n_out() * c_out);
    Case { map: Arc::new(map), c_in, c_out, x, w, g }
}

#[test]
fn submanifold_gradients_match_finite_differences() {
    let coords = random_coords(&mut rng(1), 120, 2, 4, 1);
    let index = CoordIndex::build(&coords).unwrap();
    let case = random_case(KernelMap::submanifold(&coords, &index, 3, 1), 3, 4, 10);
    check_finite_differences(&case, "submanifold");
}

#[test]
fn down_and_up_gradients_match_finite_differences() {
    let coords = random_coords(&mut rng(2), 120, 2, 5, 2);
    let (down, _) = KernelMap::down(&coords, 2, 2).unwrap();
    let up = down.transposed();
    check_finite_differences(&random_case(down, 3, 4, 11), "down");
    check_finite_differences(&random_case(up, 4, 3, 12), "up");
}

/// The dense reference as a differentiable Burn graph: scatter the voxels into a zero grid,
/// `conv3d` with padding 1, gather the active sites back.
fn dense_submanifold(x: Tensor<2>, w: Tensor<3>, coords: &[Coord], dev: &Device) -> Tensor<2> {
    let [n, c_in] = x.dims();
    let [_, _, c_out] = w.dims();
    let lo: [i32; 3] = std::array::from_fn(|d| coords.iter().map(|c| c[d + 1]).min().unwrap());
    let hi: [i32; 3] = std::array::from_fn(|d| coords.iter().map(|c| c[d + 1]).max().unwrap());
    let dims: [usize; 3] = std::array::from_fn(|d| (hi[d] - lo[d] + 1) as usize);
    let cells = dims[0] * dims[1] * dims[2];
    let flat: Vec<i64> = coords
        .iter()
        .map(|c| {
            let p: [usize; 3] = std::array::from_fn(|d| (c[d + 1] - lo[d]) as usize);
            ((p[0] * dims[1] + p[1]) * dims[2] + p[2]) as i64
        })
        .collect();
    let idx = Tensor::<1, Int>::from_data(TensorData::new(flat, [n]), dev);
    let grid = Tensor::<2>::zeros([cells, c_in], (dev, DType::F64)).select_assign(0, idx.clone(), x, sparse_conv::burn::tensor::IndexingUpdateOp::Add);
    let grid = grid.transpose().reshape([1, c_in, dims[0], dims[1], dims[2]]);
    let weight = w.reshape([3, 3, 3, c_in, c_out]).permute([4, 3, 0, 1, 2]);
    let out = conv3d(grid, weight, None, ConvOptions::new([1, 1, 1], [1, 1, 1], [1, 1, 1], 1));
    out.reshape([c_out, cells]).transpose().select(0, idx)
}

#[test]
fn submanifold_gradients_match_the_dense_reference() {
    for target in targets() {
        submanifold_gradients_on(&target, 3, 5);
    }
}

/// Channel counts that span several 32-column panels with a partial last one, both ways (the
/// AVX-512 kernel packs `W_k` for the forward and `W_kᵀ` for the feature gradient).
#[test]
fn wide_submanifold_gradients_match_the_dense_reference() {
    for target in targets() {
        submanifold_gradients_on(&target, 37, 70);
    }
}

/// The op's output and gradients on `target` against the dense graph's in f64 on flex.
fn submanifold_gradients_on(target: &Target, c_in: usize, c_out: usize) {
    let reference = Device::flex().autodiff();
    let dev = target.device.clone().autodiff();
    let mut r = rng(3);
    let coords = random_coords(&mut r, 150, 1, 5, 1);
    let n = coords.len();
    let xv = random_values(&mut r, n * c_in);
    let wv = random_values(&mut r, 27 * c_in * c_out);
    let gv = random_values(&mut r, n * c_out);
    let index = CoordIndex::build(&coords).unwrap();
    let map = Arc::new(KernelMap::submanifold(&coords, &index, 3, 1));
    let run = |sparse: bool| {
        let (dev, dtype) = if sparse { (&dev, target.dtype) } else { (&reference, DType::F64) };
        let x = tensor2(&xv, [n, c_in], dev, dtype).require_grad();
        let w = tensor3(&wv, [27, c_in, c_out], dev, dtype).require_grad();
        let out = if sparse { sparse_conv(x.clone(), w.clone(), &map) } else { dense_submanifold(x.clone(), w.clone(), &coords, dev) };
        let g = tensor2(&gv, [n, c_out], dev, dtype);
        let grads = loss(out.clone(), g).backward();
        (values(x.grad(&grads).unwrap()), values(w.grad(&grads).unwrap()), values(out))
    };
    let (sx, sw, so) = run(true);
    let (dx, dw, d_out) = run(false);
    let tol = target.tol.max(1e-10);
    let what = |w: &str| format!("{} C {c_in}→{c_out}: {w} vs dense", target.name);
    assert_close(&so, &d_out, tol, &what("output"));
    assert_close(&sx, &dx, tol, &what("feature gradient"));
    assert_close(&sw, &dw, tol, &what("weight gradient"));
}
