//! Person-MinkUNet's settings: backbone shape, head, targets, loss weights, post-processing.

use serde::{Deserialize, Serialize};
use sparse_conv::burn::tensor::Device;
use sparse_conv::modules::turns::FieldTurn;

use super::PersonMinkUNet;
use super::backbone::MinkUNetConfig;
use super::box_coder::{BoxFrame, HeadingEncoding};
use crate::post::PostProcessConfig;

/// Which soft classification target: the authors' code's or the paper's (docs/model.md).
#[derive(Serialize, Deserialize, Debug, Clone, Copy, PartialEq, Eq, Default)]
#[serde(rename_all = "snake_case")]
pub enum TargetVariant {
    /// The authors' code: `d = ‖v − c‖ / (½‖(l + ε, w + ε, h + ε)‖)`.
    #[default]
    Code,
    /// The paper's formula: `d = ‖v − c‖ / (½(‖(l, w, h)‖ + ε))`.
    Paper,
}

/// What each voxel's input features are.
#[derive(Serialize, Deserialize, Debug, Clone, Copy, PartialEq, Eq, Default)]
#[serde(rename_all = "snake_case")]
pub enum InputFeatures {
    /// The voxel's point, raw x, y, z in metres (the authors'; `in_channels = 3`).
    #[default]
    Xyz,
    /// Raw x, y, z and the point's place inside its voxel, `(p − centre) / voxel size` in
    /// [−½, ½] (`in_channels = 6`). Batch norm scales raw x by its spread over the scene (metres),
    /// so a few centimetres inside a voxel all but vanish from the raw channels; these keep them.
    XyzLocal,
    /// The point's horizontal range from the sensor's vertical axis and its height,
    /// `(√(x² + y²), z)` in metres, and its place inside its voxel as in `xyz_local`
    /// (`in_channels = 5`). No channel holds the direction the point lies in, so a person's
    /// features do not depend on which way from the sensor they stand.
    RangeHeight,
}

impl InputFeatures {
    /// What each channel holds, in order: channels of two inputs with the same name hold the same
    /// value (`x`, `y`, `z` raw; `range` horizontal; `dx`, `dy`, `dz` inside the voxel).
    pub fn channel_names(self) -> &'static [&'static str] {
        match self {
            Self::Xyz => &["x", "y", "z"],
            Self::XyzLocal => &["x", "y", "z", "dx", "dy", "dz"],
            Self::RangeHeight => &["range", "z", "dx", "dy", "dz"],
        }
    }

    /// Channels per voxel.
    pub fn channels(self) -> usize {
        self.channel_names().len()
    }

    /// How the channels change when the cloud turns by 90° about z: x, y and dx, dy as vectors,
    /// the rest unchanged.
    pub fn turn(self) -> FieldTurn {
        let names = self.channel_names();
        let at = |name: &str| names.iter().position(|n| *n == name);
        let mut turn = FieldTurn::scalars(names.len());
        for (x, y) in [("x", "y"), ("dx", "dy")] {
            if let (Some(x), Some(y)) = (at(x), at(y)) {
                turn = turn.with_vector(x, y);
            }
        }
        turn
    }
}

/// Which turns of the cloud the network answers alike by construction.
#[derive(Serialize, Deserialize, Debug, Clone, Copy, PartialEq, Eq, Default)]
#[serde(rename_all = "snake_case")]
pub enum Symmetry {
    /// None built in (the authors'): rotations are learned from augmentation.
    #[default]
    None,
    /// Quarter turns about the vertical axis: every layer holds four orientation copies of a
    /// quarter of its channels with weights tied across the turns (a p4 group convolution,
    /// `sparse_conv::modules::turns`), so a cloud turned by 90° gets its boxes turned by 90°
    /// (exactly on the voxel lattice, about the corner half a voxel from the sensor's axis).
    /// The same multiply-adds as `None` at the same width, a quarter of the weights.
    QuarterTurns,
}

/// Person-MinkUNet: MinkUNet backbone, per-voxel head, targets, loss and decoding (docs/model.md).
#[derive(Serialize, Deserialize, Debug, Clone, PartialEq)]
#[serde(default, deny_unknown_fields)]
pub struct PersonMinkUNetConfig {
    /// Input feature channels: 3 for `input = "xyz"`, 6 for `"xyz_local"`, 5 for `"range_height"`.
    pub in_channels: usize,
    /// The input features (the authors' raw xyz).
    pub input: InputFeatures,
    /// Backbone channels `[stem, down_1..down_n, up_1..up_n]` (2n + 1 entries) before `width`.
    pub channels: Vec<usize>,
    /// Width factor (the paper's `cr`).
    pub width: f64,
    /// Rotation bins (12).
    pub num_bins: usize,
    /// The heading as bins with residuals (`"bins"`, the authors'), as its axis in `num_bins` bins
    /// over 180° and a facing logit (`"axis_facing"`, the facing weighted by `facing_weight`), or
    /// as a sine and cosine (`"sin_cos"`, weighted by `sin_cos_weight`; `num_bins` and the bin
    /// weights then unused).
    pub heading: HeadingEncoding,
    /// Mean person size (l, w, h) the log-dimensions are relative to (0.9, 0.5, 1.7).
    pub mean_size: [f64; 3],
    /// The frame of the centre offsets and the heading: `"base"` (the authors') or `"ray"`
    /// (turned by each voxel's azimuth from the sensor; the heading as the observation angle).
    pub box_frame: BoxFrame,
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
    /// Weight of the sin/cos MSE with `heading = "sin_cos"` (1).
    pub sin_cos_weight: f64,
    /// Weight of the facing BCE with `heading = "axis_facing"` (1).
    pub facing_weight: f64,
    /// Turns the network answers alike by construction (`"none"`, the authors'; `"quarter_turns"`).
    pub symmetry: Symmetry,
    /// Post-processing of the per-voxel boxes.
    pub post: PostProcessConfig,
}

impl Default for PersonMinkUNetConfig {
    fn default() -> Self {
        Self {
            in_channels: 3,
            input: InputFeatures::Xyz,
            channels: vec![32, 32, 64, 128, 256, 256, 128, 96, 96],
            width: 1.0,
            num_bins: 12,
            heading: HeadingEncoding::Bins,
            mean_size: [0.9, 0.5, 1.7],
            box_frame: BoxFrame::Base,
            epsilon: 0.2,
            target: TargetVariant::Code,
            cls_weight: 100.0,
            loc_weight: 1.0,
            dims_weight: 1.0,
            bin_weight: 0.1,
            residual_weight: 0.01,
            sin_cos_weight: 1.0,
            facing_weight: 1.0,
            symmetry: Symmetry::None,
            post: PostProcessConfig::default(),
        }
    }
}

impl PersonMinkUNetConfig {
    /// Checks what serde cannot: the input features fill `in_channels`; with quarter turns, every
    /// layer's channels split into four copies and a quarter turn moves the heading by whole bins.
    pub fn validate(&self) -> Result<(), String> {
        if self.in_channels != self.input.channels() {
            return Err(format!(
                "model.in_channels = {} but model.input = {:?} gives {} channels",
                self.in_channels,
                self.input,
                self.input.channels()
            ));
        }
        if self.symmetry == Symmetry::QuarterTurns {
            let channels = self.backbone().scaled_channels();
            if let Some(c) = channels.iter().find(|&&c| c % 4 != 0) {
                return Err(format!(
                    "model.symmetry = \"quarter_turns\" needs every layer's channels (model.channels × model.width = {channels:?}) divisible by 4; {c} is not"
                ));
            }
            let quarter = match self.heading {
                HeadingEncoding::Bins => self.num_bins % 4 == 0,
                HeadingEncoding::AxisFacing => self.num_bins % 2 == 0,
                HeadingEncoding::SinCos => true,
            };
            if !quarter && self.box_frame == BoxFrame::Base {
                return Err(format!(
                    "model.symmetry = \"quarter_turns\" needs a quarter turn to be whole heading bins: model.num_bins = {} with model.heading = {:?}",
                    self.num_bins, self.heading
                ));
            }
        }
        Ok(())
    }

    /// The backbone's configuration.
    pub fn backbone(&self) -> MinkUNetConfig {
        let input_turn = (self.symmetry == Symmetry::QuarterTurns).then(|| self.input.turn());
        MinkUNetConfig { in_channels: self.in_channels, channels: self.channels.clone(), width: self.width, input_turn }
    }

    /// A model with freshly initialised parameters on `device`.
    pub fn init(&self, device: &Device) -> PersonMinkUNet {
        PersonMinkUNet::new(self, device)
    }
}
