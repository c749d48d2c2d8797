//! A tiny sparse U-Net (down, residual, up, concatenation, batch norm, linear head) trains a few
//! Adam steps with a falling loss, and its checkpoint saves and loads to identical outputs.

mod common;

use common::*;
use sparse_conv::burn::module::Module;
use sparse_conv::burn::optim::{AdamConfig, GradientsParams};
use sparse_conv::burn::tensor::{Device, Tensor, TensorData};
use sparse_conv::modules::*;
use sparse_conv::{Coord, SparseTensor};

#[derive(Module, Debug)]
struct TinyUNet {
    stem: SubmanifoldConv3d,
    stem_norm: SparseBatchNorm,
    down: ConvBnRelu,
    inner: ResidualBlock,
    up: DeconvBnRelu,
    fuse: ResidualBlock,
    head: SparseLinear,
}

impl TinyUNet {
    fn new(device: &Device) -> Self {
        Self {
            stem: SubmanifoldConv3dConfig::new([3, 8]).init(device),
            stem_norm: SparseBatchNormConfig::new(8).init(device),
            down: ConvBnReluConfig::new([8, 16]).init(device),
            inner: ResidualBlockConfig::new([16, 16]).init(device),
            up: DeconvBnReluConfig::new([16, 8]).init(device),
            fuse: ResidualBlockConfig::new([16, 8]).init(device),
            head: SparseLinearConfig::new([8, 1]).init(device),
        }
    }

    fn forward(&self, x: SparseTensor) -> Tensor<2> {
        let x0 = relu(self.stem_norm.forward(self.stem.forward(x)));
        let x1 = self.inner.forward(self.down.forward(x0.clone()));
        let y = self.up.forward(x1);
        assert_eq!(y.coords(), x0.coords(), "the transposed conv lands on the finer level's voxels");
        self.head.forward(self.fuse.forward(y.cat(&x0))).into_features()
    }
}

/// Features: scaled coordinates; target: how crowded each voxel's neighbourhood is, which the
/// network can only learn from context.
fn sample(seed: u64, device: &Device) -> (SparseTensor, Tensor<2>) {
    let coords: Vec<Coord> = random_coords(&mut rng(seed), 600, 2, 7, 1);
    let set: std::collections::HashSet<Coord> = coords.iter().copied().collect();
    let n = coords.len();
    let feats: Vec<f32> = coords.iter().flat_map(|c| [c[1] as f32 / 7.0, c[2] as f32 / 7.0, c[3] as f32 / 7.0]).collect();
    let target: Vec<f32> = coords
        .iter()
        .map(|c| {
            let mut count = 0;
            for d in 0..27 {
                let q = [c[0], c[1] + d / 9 - 1, c[2] + (d / 3) % 3 - 1, c[3] + d % 3 - 1];
                count += set.contains(&q) as i32;
            }
            count as f32 / 4.0
        })
        .collect();
    let x = SparseTensor::new(Tensor::from_data(TensorData::new(feats, [n, 3]), device), coords).unwrap();
    (x, Tensor::from_data(TensorData::new(target, [n, 1]), device))
}

#[test]
fn tiny_unet_trains_and_round_trips_a_checkpoint() {
    let device = Device::flex().autodiff();
    device.seed(5);
    let mut model = TinyUNet::new(&device);
    let mut optim = AdamConfig::new().init();
    let (x, target) = sample(51, &device);
    let mut losses = Vec::new();
    for _ in 0..40 {
        let pred = model.forward(x.clone());
        let loss = (pred - target.clone()).powf_scalar(2.0).mean();
        losses.push(values(loss.clone())[0]);
        let grads = GradientsParams::from_grads(loss.backward(), &model);
        model = optim.step(1e-2, model, grads);
    }
    let (first, last) = (losses[0], *losses.last().unwrap());
    assert!(last < 0.3 * first, "loss fell only from {first} to {last}: {losses:?}");

    let dir = std::env::temp_dir().join(format!("pmunet-unet-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("tiny.bpk");
    let plain = Device::flex();
    let (x_eval, _) = sample(52, &plain);
    let before = values(model.valid().forward(x_eval.clone()));
    model.clone().save_file(&path).unwrap();
    let loaded = TinyUNet::new(&device).load_file(&path);
    let after = values(loaded.valid().forward(x_eval));
    assert_eq!(before, after, "a loaded checkpoint gives identical outputs");
    std::fs::remove_dir_all(&dir).ok();
}
