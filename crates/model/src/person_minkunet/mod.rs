//! Person-MinkUNet: the MinkUNet backbone, a per-voxel linear head (docs/model.md), and the
//! [`Detector`] implementation tying targets, loss and decoding together.

/// The MinkUNet backbone (the SPVNAS layout, as the authors').
pub mod backbone;
/// The box encoding and head channel layout (docs/model.md).
pub mod box_coder;
/// Settings: backbone shape, targets, loss weights, post-processing.
pub mod config;
/// Per-voxel boxes and scores from the head's output (the authors' `detector.py`).
pub mod decode;
/// The five loss terms (docs/model.md).
pub mod loss;
/// Per-voxel classification and regression targets (docs/model.md).
pub mod targets;

pub use backbone::{MinkUNet, MinkUNetConfig, UNetLevels};
pub use box_coder::{BoxCoder, BoxFrame, HeadingEncoding};
pub use config::{InputFeatures, PersonMinkUNetConfig, TargetVariant};

use data_jrdb::Batch;
use sparse_conv::SparseTensor;
use sparse_conv::modules::per_voxel_linear;
use sparse_conv::burn::module::{Module, Param};
use sparse_conv::burn::nn::{Linear, LinearConfig};
use sparse_conv::burn::tensor::{Device, Tensor, TensorData};

use crate::detector::{Detections, Detector, LossTerms};
use box_coder::head_channels;
use decode::decode;
use loss::{LossWeights, loss};
use targets::assign;

/// The sparse detector: `M × 3` voxel features → `M × (2·bins + 7)` (or `M × 9`) per-voxel outputs.
#[derive(Module, Debug)]
pub struct PersonMinkUNet {
    /// Sparse U-Net, features on every input voxel.
    pub backbone: MinkUNet,
    /// Per-voxel classifier, `nn.Linear(96·cr, 2·bins + 7)` with bias, PyTorch's default init.
    pub head: Linear,
    /// The configuration it was built from (targets, loss weights, post-processing).
    #[module(skip)]
    pub config: PersonMinkUNetConfig,
}

impl PersonMinkUNet {
    /// A model with fresh parameters (initialised as the authors' torchsparse 1.2 code does).
    pub fn new(config: &PersonMinkUNetConfig, device: &Device) -> Self {
        let backbone_cfg = config.backbone();
        let channels = head_channels(config.num_bins, config.heading);
        PersonMinkUNet {
            backbone: backbone_cfg.init(device),
            head: LinearConfig::new(backbone_cfg.out_channels(), channels).init(device),
            config: config.clone(),
        }
    }

    /// The box coder of the config.
    pub fn coder(&self) -> BoxCoder {
        BoxCoder::new(self.config.mean_size, self.config.num_bins).in_frame(self.config.box_frame).with_heading(self.config.heading)
    }

    /// The loss weights of the config.
    pub fn loss_weights(&self) -> LossWeights {
        let c = &self.config;
        LossWeights { cls: c.cls_weight, loc: c.loc_weight, dims: c.dims_weight, bin: c.bin_weight, residual: c.residual_weight, sin_cos: c.sin_cos_weight, facing: c.facing_weight }
    }

    /// The batch's voxels with `features` as a stride-1 sparse tensor on `device`.
    ///
    /// # Panics
    /// If the batch's coordinates repeat a voxel (a collated batch never does).
    pub fn input(batch: &Batch, features: InputFeatures, device: &Device) -> SparseTensor {
        let m = batch.num_voxels();
        let values = match features {
            InputFeatures::Xyz => batch.features.clone(),
            InputFeatures::XyzLocal | InputFeatures::RangeHeight => {
                let mut values = Vec::with_capacity(m * features.channels());
                for row in 0..m {
                    let (p, c) = (batch.point(row), batch.centre(row));
                    let local = [0, 1, 2].map(|k| (p[k] - c[k]) / batch.voxel_size[k]);
                    let global = if features == InputFeatures::XyzLocal { &p[..] } else { &[p[0].hypot(p[1]), p[2]][..] };
                    values.extend(global.iter().copied().chain(local));
                }
                values
            }
        };
        let features = Tensor::<2>::from_data(TensorData::new(values, [m, features.channels()]), device);
        SparseTensor::new(features, batch.coords.clone()).expect("a collated batch has unique, in-range voxels")
    }

    /// These weights fed `input` instead: every weight kept, the first convolution's for each
    /// channel both inputs hold (by [`InputFeatures::channel_names`]) and zero for the others, so
    /// a fine-tuning run with another input starts from what the network learned.
    pub fn with_input(mut self, input: InputFeatures) -> Self {
        let old = self.config.input.channel_names();
        let weight = self.backbone.stem[0].weight.val();
        let [volume, _, c_out] = weight.dims();
        let device = weight.device();
        let columns: Vec<Tensor<3>> = input
            .channel_names()
            .iter()
            .map(|name| match old.iter().position(|o| o == name) {
                Some(i) => weight.clone().narrow(1, i, 1),
                None => Tensor::zeros([volume, 1, c_out], &device),
            })
            .collect();
        self.backbone.stem[0].weight = Param::from_tensor(Tensor::cat(columns, 1));
        self.config.input = input;
        self.config.in_channels = input.channels();
        self
    }

    /// Head output for every voxel of the batch, `[M, coder().channels()]` (layout in [`box_coder`]).
    pub fn forward(&self, batch: &Batch, device: &Device) -> Tensor<2> {
        let x = self.backbone.forward(Self::input(batch, self.config.input, device));
        per_voxel_linear(&self.head, &x)
    }
}

impl Detector for PersonMinkUNet {
    fn loss(&self, batch: &Batch, device: &Device) -> LossTerms {
        let out = self.forward(batch, device);
        let targets = assign(batch, &self.coder(), self.config.epsilon, self.config.target);
        loss(out, &targets, self.config.num_bins, self.config.heading, &self.loss_weights(), device)
    }

    fn head_output(&self, batch: &Batch, device: &Device) -> Vec<f32> {
        self.forward(batch, device).into_data().try_to_vec::<f32>().expect("f32 head output")
    }

    fn detect(&self, batch: &Batch, device: &Device) -> Vec<Detections> {
        decode(&self.head_output(batch, device), batch, &self.coder(), &self.config.post)
    }
}
