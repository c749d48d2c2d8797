//! Weights tied across quarter turns (`modules::turns`): each convolution kind commutes with a turn
//! of the lattice (the turned input gives the turned output, orientation copies cycled), and the
//! free weights' gradients equal central finite differences.

mod common;

use std::collections::BTreeMap;
use std::sync::Arc;

use common::*;
use sparse_conv::burn::tensor::{DType, Device};
use sparse_conv::modules::turns::{FieldTurn, TURNS, TiedKernel};
use sparse_conv::{Coord, CoordIndex, KernelMap, sparse_conv};

/// A level-`stride` coordinate turned once: (x, y) → (−y − stride, x), the lattice map
/// (i, j) → (−j − 1, i) on the cells a coordinate stands for.
fn turn_coord(c: Coord, stride: i32) -> Coord {
    [c[0], -c[2] - stride, c[1], c[3]]
}

/// Regular features (`TURNS` copies of `c`, orientation-major) after a turn: copy r moves to r + 1.
fn cycle_copies(x: &[f64], c: usize) -> Vec<f64> {
    x.chunks(TURNS * c).flat_map(|row| (0..TURNS).flat_map(move |r| row[((r + TURNS - 1) % TURNS) * c..][..c].to_vec())).collect()
}

/// `sparse_conv` with `tied`'s full weights from `free`, in f64 on flex.
fn run(map: &Arc<KernelMap>, x: &[f64], free: &[f64], tied: &TiedKernel) -> Vec<f64> {
    let dev = Device::flex();
    let [_, c_in, _] = tied.full_shape();
    let w = tied.expand(tensor3(free, tied.free_shape(), &dev, DType::F64));
    values(sparse_conv(tensor2(x, [map.n_in(), c_in], &dev, DType::F64), w, map))
}

#[test]
fn tied_convolutions_commute_with_a_quarter_turn() {
    let (c_in, c_out) = (2, 3);
    let mut r = rng(5);
    // Fine voxels of two samples with negative coordinates, and the same voxels turned.
    let coords = random_coords(&mut r, 150, 2, 5, 1);
    let turned: Vec<Coord> = coords.iter().map(|&c| turn_coord(c, 1)).collect();
    let x = random_values(&mut r, coords.len() * TURNS * c_in);
    let tx = cycle_copies(&x, c_in);

    // Submanifold 3×3×3 and 1×1×1 between regular features.
    for kernel in [3, 1] {
        let tied = TiedKernel::regular(kernel, c_in, c_out);
        let free = random_values(&mut r, tied.free_shape().iter().product());
        let map = |c: &[Coord]| Arc::new(KernelMap::submanifold(c, &CoordIndex::build(c).unwrap(), kernel, 1));
        let (out, tout) = (run(&map(&coords), &x, &free, &tied), run(&map(&turned), &tx, &free, &tied));
        let expected: BTreeMap<Coord, Vec<f64>> =
            coords.iter().enumerate().map(|(i, &c)| (turn_coord(c, 1), cycle_copies(&out[i * TURNS * c_out..][..TURNS * c_out], c_out))).collect();
        assert_maps_close(&by_coord(&turned, &tout, TURNS * c_out), &expected, 1e-12, &format!("submanifold {kernel}"));
    }

    // The first layer: plain channels (a vector and a scalar) lifted to regular features.
    let fields = FieldTurn::scalars(3).with_vector(0, 1);
    let tied = TiedKernel::lifting(3, &fields, c_out);
    let free = random_values(&mut r, tied.free_shape().iter().product());
    let p = random_values(&mut r, coords.len() * 3);
    let tp = fields.apply(&p);
    let map = |c: &[Coord]| Arc::new(KernelMap::submanifold(c, &CoordIndex::build(c).unwrap(), 3, 1));
    let (out, tout) = (run(&map(&coords), &p, &free, &tied), run(&map(&turned), &tp, &free, &tied));
    let expected: BTreeMap<Coord, Vec<f64>> =
        coords.iter().enumerate().map(|(i, &c)| (turn_coord(c, 1), cycle_copies(&out[i * TURNS * c_out..][..TURNS * c_out], c_out))).collect();
    assert_maps_close(&by_coord(&turned, &tout, TURNS * c_out), &expected, 1e-12, "lifting");

    // Strided 2×2×2 down-sampling and its transposed up-sampling.
    let tied_down = TiedKernel::regular(2, c_in, c_out);
    let tied_up = TiedKernel::regular(2, c_out, c_in);
    let free_down = random_values(&mut r, tied_down.free_shape().iter().product());
    let free_up = random_values(&mut r, tied_up.free_shape().iter().product());
    let (down, coarse) = KernelMap::down(&coords, 2, 1).unwrap();
    let (tdown, tcoarse) = KernelMap::down(&turned, 2, 1).unwrap();
    let (down, tdown) = (Arc::new(down), Arc::new(tdown));
    let (mid, tmid) = (run(&down, &x, &free_down, &tied_down), run(&tdown, &tx, &free_down, &tied_down));
    let expected: BTreeMap<Coord, Vec<f64>> =
        coarse.iter().enumerate().map(|(i, &c)| (turn_coord(c, 2), cycle_copies(&mid[i * TURNS * c_out..][..TURNS * c_out], c_out))).collect();
    assert_maps_close(&by_coord(&tcoarse, &tmid, TURNS * c_out), &expected, 1e-12, "down");
    let (up, tup) = (Arc::new(down.transposed()), Arc::new(tdown.transposed()));
    let (back, tback) = (run(&up, &mid, &free_up, &tied_up), run(&tup, &tmid, &free_up, &tied_up));
    let expected: BTreeMap<Coord, Vec<f64>> =
        coords.iter().enumerate().map(|(i, &c)| (turn_coord(c, 1), cycle_copies(&back[i * TURNS * c_in..][..TURNS * c_in], c_in))).collect();
    assert_maps_close(&by_coord(&turned, &tback, TURNS * c_in), &expected, 1e-12, "up");

    // A head pooling the copies into plain channels that turn (a vector, two cycled bins).
    let head = FieldTurn::scalars(5).with_vector(1, 2).with_cycle(3, 2, 1);
    let tied = TiedKernel::pooling(c_in, &head);
    let free = random_values(&mut r, tied.free_shape().iter().product());
    let map = |c: &[Coord]| Arc::new(KernelMap::submanifold(c, &CoordIndex::build(c).unwrap(), 1, 1));
    let (out, tout) = (run(&map(&coords), &x, &free, &tied), run(&map(&turned), &tx, &free, &tied));
    let expected: BTreeMap<Coord, Vec<f64>> = coords.iter().enumerate().map(|(i, &c)| (turn_coord(c, 1), head.apply(&out[i * 5..][..5]))).collect();
    assert_maps_close(&by_coord(&turned, &tout, 5), &expected, 1e-12, "pooling head");

    // Untied weights of the same shape do not commute: the check can fail.
    let free = random_values(&mut r, 27 * TURNS * c_in * TURNS * c_out);
    let plain = |c: &[Coord], x: &[f64]| {
        let dev = Device::flex();
        let m = KernelMap::submanifold(c, &CoordIndex::build(c).unwrap(), 3, 1);
        values(sparse_conv(tensor2(x, [c.len(), TURNS * c_in], &dev, DType::F64), tensor3(&free, [27, TURNS * c_in, TURNS * c_out], &dev, DType::F64), &Arc::new(m)))
    };
    let (out, tout) = (plain(&coords, &x), plain(&turned, &tx));
    let moved = by_coord(&turned, &tout, TURNS * c_out);
    let worst = coords
        .iter()
        .enumerate()
        .flat_map(|(i, &c)| cycle_copies(&out[i * TURNS * c_out..][..TURNS * c_out], c_out).into_iter().zip(moved[&turn_coord(c, 1)].clone()))
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f64::max);
    assert!(worst > 0.1, "untied weights happened to commute ({worst})");
}

#[test]
fn tied_kernels_gradients_match_finite_differences() {
    let mut r = rng(6);
    let coords = random_coords(&mut r, 80, 1, 4, 1);
    let index = CoordIndex::build(&coords).unwrap();
    let map = Arc::new(KernelMap::submanifold(&coords, &index, 3, 1));
    let fields = FieldTurn::scalars(3).with_vector(0, 1);
    for (what, tied) in [("regular", TiedKernel::regular(3, 2, 2)), ("lifting", TiedKernel::lifting(3, &fields, 2))] {
        let [_, c_in, c_out] = tied.full_shape();
        let x = random_values(&mut r, coords.len() * c_in);
        let g = random_values(&mut r, coords.len() * c_out);
        let free = random_values(&mut r, tied.free_shape().iter().product());
        // L = Σ ½·out² + out·G, quadratic in the free weights: central differences are exact up to
        // rounding.
        let loss = |w: &[f64]| -> f64 { run(&map, &x, w, &tied).iter().zip(&g).map(|(o, g)| 0.5 * o * o + o * g).sum() };
        let ad = Device::flex().autodiff();
        let w = tensor3(&free, tied.free_shape(), &ad, DType::F64).require_grad();
        let out = sparse_conv(tensor2(&x, [coords.len(), c_in], &ad, DType::F64), tied.expand(w.clone()), &map);
        let gt = tensor2(&g, [coords.len(), c_out], &ad, DType::F64);
        let grads = (out.clone() * out.clone() * 0.5 + out * gt).sum().backward();
        let analytic = values(w.grad(&grads).unwrap());
        let eps = 1e-3;
        for i in (0..free.len()).step_by(free.len() / 30 + 1) {
            let (mut plus, mut minus) = (free.clone(), free.clone());
            plus[i] += eps;
            minus[i] -= eps;
            let fd = (loss(&plus) - loss(&minus)) / (2.0 * eps);
            assert!((fd - analytic[i]).abs() <= 1e-6 * (1.0 + fd.abs()), "{what}: d/dw[{i}] analytic {} vs finite difference {fd}", analytic[i]);
        }
    }
}
