//! Data-parallel training over several devices of one machine: each step's batch is cut into one
//! part per device, a replica of the model on each device computes its part's loss and gradients,
//! and the gradients are averaged on the first device, where Adam steps the one model.
//!
//! As PyTorch's DistributedDataParallel does it: each part's loss is normalised within the part,
//! and batch norm's statistics are each replica's own (no synchronised batch norm); the running
//! statistics kept are the first device's.

use burn::module::{Module, ModuleVisitor, Param};
use burn::optim::GradientsParams;
use burn::tensor::{Device, Tensor};

/// The mean of `parts` (gradients of `module`'s parameters, any devices), on `device`.
pub fn average_gradients<M: Module>(parts: Vec<GradientsParams>, module: &M, device: &Device) -> GradientsParams {
    let n = parts.len();
    let mut average = GradientsParams::new();
    let mut visitor = Average { parts: parts.into_iter().map(|g| g.to_device(device, module)).collect(), average: &mut average, scale: 1.0 / n.max(1) as f32 };
    module.visit(&mut visitor);
    average
}

/// Sums each parameter's gradient over the parts and scales it.
struct Average<'a> {
    parts: Vec<GradientsParams>,
    average: &'a mut GradientsParams,
    scale: f32,
}

impl ModuleVisitor for Average<'_> {
    fn visit_float<const D: usize>(&mut self, param: &Param<Tensor<D>>) {
        let sum = self.parts.iter_mut().filter_map(|g| g.remove::<D>(param.id)).reduce(|a, b| a + b);
        if let Some(sum) = sum {
            self.average.register(param.id, sum.mul_scalar(self.scale));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use burn::tensor::TensorData;

    #[derive(Module, Debug)]
    struct Two {
        a: Param<Tensor<2>>,
        b: Param<Tensor<1>>,
    }

    /// Gradients of `Σ a·x + Σ b·y`: `x` and `y` themselves.
    fn grads(model: &Two, x: [f32; 4], y: [f32; 2], device: &Device) -> GradientsParams {
        let x = Tensor::<2>::from_data(TensorData::new(x.to_vec(), [2, 2]), device);
        let y = Tensor::<1>::from_data(TensorData::new(y.to_vec(), [2]), device);
        let loss = (model.a.val() * x).sum() + (model.b.val() * y).sum();
        GradientsParams::from_grads(loss.backward(), model)
    }

    #[test]
    fn the_average_is_the_mean_of_the_parts_gradients_on_the_first_device() {
        let device = Device::flex();
        let ad = device.clone().autodiff();
        let model = Two { a: Param::from_tensor(Tensor::zeros([2, 2], &ad)), b: Param::from_tensor(Tensor::zeros([2], &ad)) };
        // The second part on a replica forked as the trainer forks one (same parameter ids).
        let replica = model.clone().fork(&ad);
        let parts = vec![grads(&model, [1.0, 2.0, 3.0, 4.0], [10.0, -2.0], &ad), grads(&replica, [3.0, 0.0, -1.0, 8.0], [0.0, 4.0], &ad)];
        let mut average = average_gradients(parts, &model, &ad);
        let a = average.remove::<2>(model.a.id).expect("a's gradient").into_data().try_to_vec::<f32>().unwrap();
        let b = average.remove::<1>(model.b.id).expect("b's gradient").into_data().try_to_vec::<f32>().unwrap();
        assert_eq!(a, vec![2.0, 1.0, 1.0, 6.0]);
        assert_eq!(b, vec![5.0, 1.0]);
        assert!(average.is_empty());
    }
}
