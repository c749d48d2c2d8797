//! `backward_from(out, G)` gives the gradients of `Σ out·G` (Burn's own backward through a
//! product and a sum), through the op and through Burn's ops after it, on every backend.

mod common;

use std::sync::Arc;

use common::*;
use sparse_conv::burn::tensor::{Device, Tensor};
use sparse_conv::{CoordIndex, KernelMap, backward_from, sparse_conv};

#[test]
fn a_given_output_gradient_equals_the_gradient_of_its_dot_product() {
    for target in targets() {
        given_gradient_on(&target);
    }
}

fn given_gradient_on(target: &Target) {
    let (dev, dtype, tol) = (target.device.clone().autodiff(), target.dtype, target.tol);
    let mut r = rng(7);
    let coords = random_coords(&mut r, 60, 2, 6, 1);
    let index = CoordIndex::build(&coords).unwrap();
    let map = Arc::new(KernelMap::submanifold(&coords, &index, 3, 1));
    let (n, c_in, c_out) = (coords.len(), 3, 5);
    let (x, w, g) = (random_values(&mut r, n * c_in), random_values(&mut r, 27 * c_in * c_out), random_values(&mut r, n * c_out));
    // The conv alone, and the conv followed by Burn's ops (the gradient must flow through them).
    let outputs: [fn(Tensor<2>) -> Tensor<2>; 2] = [|out| out, |out| (out.clone() * out * 0.5).exp()];
    for (which, then) in outputs.into_iter().enumerate() {
        let run = |given: bool| {
            let xt = tensor2(&x, [n, c_in], &dev, dtype).require_grad();
            let wt = tensor3(&w, [27, c_in, c_out], &dev, dtype).require_grad();
            let out = then(sparse_conv(xt.clone(), wt.clone(), &map));
            let gt = tensor2(&g, [n, c_out], &dev, dtype);
            let grads = if given { backward_from(out, gt) } else { (out * gt).sum().backward() };
            (values(xt.grad(&grads).unwrap()), values(wt.grad(&grads).unwrap()))
        };
        let ((gx, gw), (ex, ew)) = (run(true), run(false));
        let what = format!("{} output {which}", target.name);
        assert_close(&gx, &ex, tol, &format!("{what}: feature gradient"));
        assert_close(&gw, &ew, tol, &format!("{what}: weight gradient"));
        assert!(gx.iter().any(|v| v.abs() > 1e-3), "{what}: the gradient must not vanish");
    }
}

/// A gradient of another shape is refused, not broadcast.
#[test]
#[should_panic(expected = "an output's gradient must have the output's shape")]
fn a_gradient_of_another_shape_is_refused() {
    let dev = Device::flex().autodiff();
    let x = Tensor::<2>::ones([4, 3], &dev).require_grad();
    let out = x.clone() * 2.0;
    backward_from(out, Tensor::<2>::ones([4, 1], &dev));
}
