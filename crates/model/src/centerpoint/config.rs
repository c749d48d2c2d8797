//! The CenterPoint baseline's settings: grid, encoder, backbone, head, targets, loss,
//! post-processing.

use serde::{Deserialize, Serialize};
use sparse_conv::burn::tensor::Device;

use super::CenterPoint;
use crate::post::PostProcessConfig;

/// The CenterPoint-style dense baseline: CenterPoint's defaults adapted to people (docs/model.md).
#[derive(Serialize, Deserialize, Debug, Clone, PartialEq)]
#[serde(default, deny_unknown_fields)]
pub struct CenterPointConfig {
    /// BEV range along x, metres (−25.6, 25.6).
    pub x_range: [f64; 2],
    /// BEV range along y, metres (−25.6, 25.6).
    pub y_range: [f64; 2],
    /// Height range kept, metres (−1.0, 1.6).
    pub z_range: [f64; 2],
    /// Pillar (voxel) size, metres. The z size defaults to the whole z range (one pillar per BEV
    /// cell); a smaller z size (such as 0.05 × 0.05 × 0.2 m point voxels) stacks each height slice's encoded
    /// features as extra BEV channels.
    pub voxel_size: [f64; 3],
    /// Points (voxels of the batch) kept per pillar (20).
    pub max_points_per_pillar: usize,
    /// PointNet filters (64, 64): every layer but the last concatenates its pillar max.
    pub pfn_filters: Vec<usize>,
    /// Convolutions per down block after its strided one ([3, 5, 5]).
    pub layer_nums: Vec<usize>,
    /// Stride of each down block's first convolution ([2, 2, 2]).
    pub down_strides: Vec<usize>,
    /// Filters of each down block ([64, 128, 256]).
    pub down_filters: Vec<usize>,
    /// Up-sampling factor of each block's transposed convolution ([1, 2, 4]: all land on the
    /// first block's resolution, output stride 2 = 0.2 m cells).
    pub up_strides: Vec<usize>,
    /// Filters of each up block ([128, 128, 128], concatenated to 384).
    pub up_filters: Vec<usize>,
    /// Channels of the shared and per-task head convolutions (64).
    pub head_channels: usize,
    /// Width factor on every filter count above (1.0).
    pub width: f64,
    /// Momentum of every batch norm (CenterPoint's 0.01, PyTorch convention; eps is 1e-3).
    pub bn_momentum: f64,
    /// Initial bias of the heatmap logits (−2.19, a prior of 0.1).
    pub hm_bias: f64,
    /// Gaussian radius rule: minimum overlap (0.1) and minimum radius in cells (2).
    pub min_overlap: f64,
    /// Minimum Gaussian radius, heatmap cells.
    pub min_radius: usize,
    /// Focal loss exponents α (2) and β (4).
    pub focal_alpha: f64,
    /// See `focal_alpha`.
    pub focal_beta: f64,
    /// Weight of the L1 regression loss (0.25).
    pub reg_weight: f64,
    /// Peaks kept per sample before NMS (500, CenterPoint's `max_per_img`).
    pub top_k: usize,
    /// Post-processing of the peaks.
    pub post: PostProcessConfig,
}

impl Default for CenterPointConfig {
    fn default() -> Self {
        Self {
            x_range: [-25.6, 25.6],
            y_range: [-25.6, 25.6],
            z_range: [-1.0, 1.6],
            voxel_size: [0.1, 0.1, 2.6],
            max_points_per_pillar: 20,
            pfn_filters: vec![64, 64],
            layer_nums: vec![3, 5, 5],
            down_strides: vec![2, 2, 2],
            down_filters: vec![64, 128, 256],
            up_strides: vec![1, 2, 4],
            up_filters: vec![128, 128, 128],
            head_channels: 64,
            width: 1.0,
            bn_momentum: 0.01,
            hm_bias: -2.19,
            min_overlap: 0.1,
            min_radius: 2,
            focal_alpha: 2.0,
            focal_beta: 4.0,
            reg_weight: 0.25,
            top_k: 500,
            post: PostProcessConfig::default(),
        }
    }
}

impl CenterPointConfig {
    /// A model with freshly initialised parameters on `device`.
    pub fn init(&self, device: &Device) -> CenterPoint {
        CenterPoint::new(self, device)
    }

    /// `c × width`, at least 1 (torchsparse-style `int(cr·c)`).
    pub fn scaled(&self, c: usize) -> usize {
        ((self.width * c as f64) as usize).max(1)
    }
}
