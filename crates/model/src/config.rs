//! The serde configuration of both detectors: what a training TOML's `[model]` table holds.
//!
//! Every field has the paper's (or, for CenterPoint, spec §4's) default and every struct is
//! `#[serde(default, deny_unknown_fields)]`, so a TOML section may omit any field and a typo is an
//! error. `kind = "person_minkunet"` or `kind = "centerpoint"` picks the model.

use serde::{Deserialize, Serialize};
use sparse_conv::burn::tensor::Device;

use crate::centerpoint::CenterPoint;
use crate::minkunet::MinkUNetConfig;
use crate::person_minkunet::PersonMinkUNet;

/// Either detector, tagged by `kind`.
#[derive(Serialize, Deserialize, Debug, Clone, PartialEq)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum ModelConfig {
    /// The sparse Person-MinkUNet (spec §1.6–1.12).
    PersonMinkunet(PersonMinkUNetConfig),
    /// The dense CenterPoint-style baseline (spec §4).
    Centerpoint(CenterPointConfig),
}

impl Default for ModelConfig {
    fn default() -> Self {
        ModelConfig::PersonMinkunet(PersonMinkUNetConfig::default())
    }
}

impl ModelConfig {
    /// The config's `kind` tag as written in TOML.
    pub fn kind(&self) -> &'static str {
        match self {
            ModelConfig::PersonMinkunet(_) => "person_minkunet",
            ModelConfig::Centerpoint(_) => "centerpoint",
        }
    }

    /// The post-processing of either model.
    pub fn post(&self) -> &PostProcessConfig {
        match self {
            ModelConfig::PersonMinkunet(c) => &c.post,
            ModelConfig::Centerpoint(c) => &c.post,
        }
    }
}

/// Which soft classification target (spec §1.9).
#[derive(Serialize, Deserialize, Debug, Clone, Copy, PartialEq, Eq, Default)]
#[serde(rename_all = "snake_case")]
pub enum TargetVariant {
    /// The authors' code: `d = ‖v − c‖ / (½‖(l + ε, w + ε, h + ε)‖)`.
    #[default]
    Code,
    /// The paper's formula: `d = ‖v − c‖ / (½(‖(l, w, h)‖ + ε))`.
    Paper,
}

/// Which greedy NMS post-processing runs.
#[derive(Serialize, Deserialize, Debug, Clone, Copy, PartialEq, Eq, Default)]
#[serde(rename_all = "snake_case")]
pub enum NmsKind {
    /// Person-MinkUNet's distance NMS in BEV (spec §1.12, `eval::nms::nms_distance`).
    #[default]
    Distance,
    /// CenterPoint's circle NMS: suppress centres closer than `circle_radius` in BEV.
    Circle,
    /// Rotated BEV IoU NMS (`eval::nms::nms_bev_iou`) above `iou_threshold`.
    BevIou,
    /// No suppression (score threshold and cap still apply).
    None,
}

/// Score threshold, NMS and box cap applied to each sample's candidate boxes.
#[derive(Serialize, Deserialize, Debug, Clone, PartialEq)]
#[serde(default, deny_unknown_fields)]
pub struct PostProcessConfig {
    /// Candidates with `score <= score_threshold` are dropped before NMS. Default 1e-3, what
    /// the authors' `filter_submission.py` keeps; the model itself has no threshold (spec §1.12).
    pub score_threshold: f64,
    /// NMS flavour.
    pub nms: NmsKind,
    /// Distance NMS ratio (0.4, spec §1.12).
    pub dist_ratio: f64,
    /// Distance NMS mean person length and width (0.9, 0.5 m).
    pub mean_lw: [f64; 2],
    /// Circle NMS radius, metres (about 0.3 m, spec §4).
    pub circle_radius: f64,
    /// BEV IoU NMS threshold (0.3).
    pub iou_threshold: f64,
    /// At most this many boxes per sample after NMS; `None` keeps all survivors.
    pub max_boxes: Option<usize>,
    /// At most this many candidates (the best-scoring) enter NMS; `None`: all that pass the
    /// threshold (the authors'). Bounds NMS's cost and the near-duplicates it must resolve.
    pub pre_nms_max: Option<usize>,
    /// Box voting after NMS: each kept box's centre and size become the score-weighted mean of
    /// the candidates whose nearest kept centre it is, within this BEV radius (metres); 0: off
    /// (the authors'). Per-voxel proposals scatter around a person, and the best-scoring one is
    /// not the best-placed one; their mean is.
    pub merge_radius: f64,
    /// With voting, also vote the heading's axis (angles doubled, so votes π apart agree), keeping
    /// the kept box's own direction along it. A per-voxel heading is a noisy guess; the axis of
    /// a whole person's votes is not, and IoU depends on the axis alone.
    pub merge_heading: bool,
}

impl Default for PostProcessConfig {
    fn default() -> Self {
        Self {
            score_threshold: 1e-3,
            nms: NmsKind::Distance,
            dist_ratio: 0.4,
            mean_lw: [0.9, 0.5],
            circle_radius: 0.3,
            iou_threshold: 0.3,
            max_boxes: None,
            pre_nms_max: None,
            merge_radius: 0.0,
            merge_heading: true,
        }
    }
}

/// Person-MinkUNet: MinkUNet backbone, per-voxel head, targets, loss and decoding (spec §1.6–1.12).
#[derive(Serialize, Deserialize, Debug, Clone, PartialEq)]
#[serde(default, deny_unknown_fields)]
pub struct PersonMinkUNetConfig {
    /// Input feature channels (raw xyz: 3).
    pub in_channels: usize,
    /// Backbone channels `[stem, down_1..down_n, up_1..up_n]` (2n + 1 entries) before `width`.
    pub channels: Vec<usize>,
    /// Width factor (the paper's `cr`).
    pub width: f64,
    /// Rotation bins (12).
    pub num_bins: usize,
    /// Mean person size (l, w, h) the log-dimensions are relative to (0.9, 0.5, 1.7).
    pub mean_size: [f64; 3],
    /// ε of the soft classification target (0.2 m).
    pub epsilon: f64,
    /// Code or paper form of the soft target.
    pub target: TargetVariant,
    /// Weight of the BCE classification term (the code's 100; the paper has 1).
    pub cls_weight: f64,
    /// Weight of the centre MSE (1).
    pub loc_weight: f64,
    /// Weight of the log-dimension MSE (1).
    pub dims_weight: f64,
    /// Weight of the bin cross-entropy (0.1).
    pub bin_weight: f64,
    /// Weight of the residual MSE (0.01 = 0.1 × 0.1).
    pub residual_weight: f64,
    /// Post-processing of the per-voxel boxes.
    pub post: PostProcessConfig,
}

impl Default for PersonMinkUNetConfig {
    fn default() -> Self {
        Self {
            in_channels: 3,
            channels: vec![32, 32, 64, 128, 256, 256, 128, 96, 96],
            width: 1.0,
            num_bins: 12,
            mean_size: [0.9, 0.5, 1.7],
            epsilon: 0.2,
            target: TargetVariant::Code,
            cls_weight: 100.0,
            loc_weight: 1.0,
            dims_weight: 1.0,
            bin_weight: 0.1,
            residual_weight: 0.01,
            post: PostProcessConfig::default(),
        }
    }
}

impl PersonMinkUNetConfig {
    /// The backbone's configuration.
    pub fn backbone(&self) -> MinkUNetConfig {
        MinkUNetConfig::new().with_in_channels(self.in_channels).with_channels(self.channels.clone()).with_width(self.width)
    }

    /// A model with freshly initialised parameters on `device`.
    pub fn init(&self, device: &Device) -> PersonMinkUNet {
        PersonMinkUNet::new(self, device)
    }
}

/// The CenterPoint-style dense baseline (spec §4; JRDB defaults of its last paragraph).
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
    /// cell); a smaller z size (the paper's (0.05, 0.05, 0.2)) stacks each height slice's encoded
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn toml_sections_may_omit_fields_and_reject_typos() {
        let c: ModelConfig = toml::from_str("kind = \"person_minkunet\"\nwidth = 0.5\n").unwrap();
        let ModelConfig::PersonMinkunet(p) = &c else { panic!("wrong kind") };
        assert_eq!(p.width, 0.5);
        assert_eq!(p.num_bins, 12);
        assert_eq!(p.cls_weight, 100.0);
        let c: ModelConfig = toml::from_str("kind = \"centerpoint\"\n[post]\nnms = \"circle\"\n").unwrap();
        let ModelConfig::Centerpoint(cp) = &c else { panic!("wrong kind") };
        assert_eq!(cp.layer_nums, vec![3, 5, 5]);
        assert_eq!(cp.post.nms, NmsKind::Circle);
        assert!(toml::from_str::<ModelConfig>("kind = \"centerpoint\"\nwidht = 1.0\n").is_err());
        assert!(toml::from_str::<ModelConfig>("kind = \"pointpillars\"\n").is_err());
        for c in [ModelConfig::default(), ModelConfig::Centerpoint(CenterPointConfig::default())] {
            let text = toml::to_string(&c).unwrap();
            assert_eq!(toml::from_str::<ModelConfig>(&text).unwrap(), c, "{text}");
        }
    }
}
