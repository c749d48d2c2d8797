//! The CenterPoint-style dense baseline (docs/model.md): pillar encoder → dense BEV image → 2D
//! CNN → centre heatmap and box regression, built from Burn's own `Conv2d`, `BatchNorm` and
//! `ConvTranspose2d`.

/// 2D backbone with concatenated multi-scale outputs.
pub mod backbone;
/// Settings: grid, encoder, backbone, head, targets, loss, post-processing.
pub mod config;
/// Heatmap peaks and box decoding.
pub mod decode;
/// Pillar feature encoder and BEV scatter.
pub mod encoder;
/// The pillar and heatmap grids.
pub mod grid;
/// Heatmap and regression heads.
pub mod head;
/// Focal + L1 loss.
pub mod loss;
/// Gaussian heatmap targets.
pub mod targets;

use data_jrdb::Batch;
use sparse_conv::burn::module::Module;
use sparse_conv::burn::tensor::{Device, Tensor};

use crate::detector::{Detections, Detector, LossTerms};
use backbone::BevBackbone;
pub use config::CenterPointConfig;
use encoder::{PillarEncoder, Pillars};
use grid::BevGrid;
use head::CenterHead;

/// The dense detector: batch voxels → pillars → `[B, C, X, Y]` → `[B, 9, X/s, Y/s]`.
#[derive(Module, Debug)]
pub struct CenterPoint {
    /// PointNet over each pillar.
    pub encoder: PillarEncoder,
    /// 2D backbone.
    pub backbone: BevBackbone,
    /// Heatmap and regression heads.
    pub head: CenterHead,
    /// The configuration it was built from.
    #[module(skip)]
    pub config: CenterPointConfig,
}

impl CenterPoint {
    /// A model with fresh parameters.
    pub fn new(config: &CenterPointConfig, device: &Device) -> Self {
        let grid = BevGrid::new(config);
        let filters: Vec<usize> = config.pfn_filters.iter().map(|&f| config.scaled(f)).collect();
        let encoder = PillarEncoder::new(&filters, config.bn_momentum, device);
        let backbone = BevBackbone::new(config, encoder.out_channels() * grid.size[2], device);
        let head = CenterHead::new(backbone.out_channels(), config.scaled(config.head_channels), config.hm_bias, config.bn_momentum, device);
        Self { encoder, backbone, head, config: config.clone() }
    }

    /// The grid of the config.
    pub fn grid(&self) -> BevGrid {
        BevGrid::new(&self.config)
    }

    /// The dense BEV image of the batch, `[B, Z·C, X, Y]`.
    pub fn bev(&self, batch: &Batch, device: &Device) -> Tensor<4> {
        let grid = self.grid();
        let pillars = Pillars::new(batch, &grid, self.config.max_points_per_pillar);
        if pillars.is_empty() {
            let [nx, ny, nz] = grid.size;
            return Tensor::zeros([batch.len(), nz * self.encoder.out_channels(), nx, ny], device);
        }
        let features = self.encoder.forward(&pillars, device);
        PillarEncoder::scatter(features, &pillars, &grid, device)
    }

    /// Head output `[B, 9, X/s, Y/s]` (layout in [`head`]).
    pub fn forward(&self, batch: &Batch, device: &Device) -> Tensor<4> {
        self.head.forward(self.backbone.forward(self.bev(batch, device)))
    }
}

impl Detector for CenterPoint {
    fn loss(&self, batch: &Batch, device: &Device) -> LossTerms {
        let out = self.forward(batch, device);
        let c = &self.config;
        let t = targets::assign(batch, &self.grid(), c.min_overlap, c.min_radius);
        loss::loss(out, &t, c.focal_alpha, c.focal_beta, c.reg_weight, device)
    }

    fn head_output(&self, batch: &Batch, device: &Device) -> Vec<f32> {
        self.forward(batch, device).into_data().try_to_vec::<f32>().expect("f32 head output")
    }

    fn detect(&self, batch: &Batch, device: &Device) -> Vec<Detections> {
        decode::decode(self.forward(batch, device), &self.grid(), self.config.top_k, &self.config.post)
    }
}
