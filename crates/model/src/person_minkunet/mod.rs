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
pub use config::{InputFeatures, PersonMinkUNetConfig, Symmetry, TargetVariant};

use data_jrdb::Batch;
use std::sync::Arc;

use sparse_conv::SparseTensor;
use sparse_conv::modules::turns::{FieldTurn, TURNS, TiedKernel, pooled_bias};
use sparse_conv::modules::{per_voxel_linear, pooled_linear};
use sparse_conv::burn::module::{Module, Param};
use sparse_conv::burn::nn::{Linear, LinearConfig};
use sparse_conv::burn::tensor::{Device, Tensor, TensorData};

use crate::detector::{Detections, Detector, LossTerms};
use box_coder::{BINS, OFFSET, head_channels};
use decode::decode;
use loss::{LossWeights, loss};
use targets::assign;

/// The sparse detector: `M × 3` voxel features → `M × (2·bins + 7)` (or `M × 9`) per-voxel outputs.
#[derive(Module, Debug)]
pub struct PersonMinkUNet {
    /// Sparse U-Net, features on every input voxel.
    pub backbone: MinkUNet,
    /// Per-voxel classifier, `nn.Linear(96·cr, 2·bins + 7)` with bias, PyTorch's default init.
    /// With quarter-turn symmetry it reads one orientation copy (`96·cr / 4` channels) and the
    /// four copies' outputs, turned back, are averaged ([`Self::forward`]).
    pub head: Linear,
    /// The configuration it was built from (targets, loss weights, post-processing).
    #[module(skip)]
    pub config: PersonMinkUNetConfig,
    /// The head reads one orientation copy and averages the four (quarter-turn symmetry, until
    /// [`Self::untied`] writes that out as a plain head).
    #[module(skip)]
    pub pooled_head: bool,
}

impl PersonMinkUNet {
    /// A model with fresh parameters (initialised as the authors' torchsparse 1.2 code does).
    pub fn new(config: &PersonMinkUNetConfig, device: &Device) -> Self {
        let backbone_cfg = config.backbone();
        let channels = head_channels(config.num_bins, config.heading);
        let copies = if config.symmetry == Symmetry::QuarterTurns { TURNS } else { 1 };
        PersonMinkUNet {
            backbone: backbone_cfg.init(device),
            head: LinearConfig::new(backbone_cfg.out_channels() / copies, channels).init(device),
            config: config.clone(),
            pooled_head: copies > 1,
        }
    }

    /// The same network with its quarter-turn ties written out as plain weights (backbone and
    /// head), computing the same function at a plain network's cost: what inference runs. Its
    /// record no longer loads into a network built from the config; train the tied one.
    pub fn untied(mut self) -> Self {
        if !self.pooled_head {
            return self;
        }
        let turn = self.head_turn();
        let [c, n] = self.head.weight.dims();
        let weight = TiedKernel::pooling(c, &turn).expand(self.head.weight.val().reshape([1, c, n]));
        self.head.weight = Param::from_tensor(weight.reshape([TURNS * c, n]));
        self.head.bias = self.head.bias.map(|b| Param::from_tensor(pooled_bias(b.val(), &turn)));
        self.backbone = self.backbone.untied();
        self.pooled_head = false;
        self
    }

    /// How the head's channels change when the cloud turns by 90°: in the base frame the centre
    /// offset turns as a vector and the heading moves by a quarter turn (whole bins, or its sine
    /// and cosine as a vector); in the ray frame nothing changes.
    pub fn head_turn(&self) -> FieldTurn {
        let c = &self.config;
        let turn = FieldTurn::scalars(head_channels(c.num_bins, c.heading));
        if c.box_frame == BoxFrame::Ray {
            return turn;
        }
        let turn = turn.with_vector(OFFSET, OFFSET + 1);
        let quarter = match c.heading {
            HeadingEncoding::Bins => c.num_bins % 4,
            HeadingEncoding::AxisFacing => c.num_bins % 2,
            HeadingEncoding::SinCos => 0,
        };
        assert_eq!(quarter, 0, "a quarter turn is not whole heading bins with {} bins ({:?})", c.num_bins, c.heading);
        let bins = |shift: usize| turn.clone().with_cycle(BINS, c.num_bins, shift).with_cycle(BINS + c.num_bins, c.num_bins, shift);
        match c.heading {
            HeadingEncoding::Bins => bins(c.num_bins / 4),
            HeadingEncoding::AxisFacing => bins(c.num_bins / 2),
            // Channels [7] and [8] are sin θ and cos θ: (cos, sin) turns as a vector.
            HeadingEncoding::SinCos => turn.clone().with_vector(BINS + 1, BINS),
        }
    }

    /// Where the lattice's quarter turns are centred for `voxel_size`, metres in x and y: the
    /// corner half a voxel below the origin's voxel centre, which every level's cells share
    /// (`sparse_conv::modules::turns`). With quarter-turn symmetry the raw x, y fed to the network
    /// are taken about it.
    pub fn turn_centre(voxel_size: [f32; 3]) -> [f32; 2] {
        [-voxel_size[0] / 2.0, -voxel_size[1] / 2.0]
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
        Self::input_about(batch, features, [0.0, 0.0], device)
    }

    /// [`Self::input`] with the raw x and y (and the range) taken about `centre` instead of the
    /// origin.
    pub fn input_about(batch: &Batch, features: InputFeatures, centre: [f32; 2], device: &Device) -> SparseTensor {
        let m = batch.num_voxels();
        let values = match features {
            InputFeatures::Xyz if centre == [0.0, 0.0] => batch.features.clone(),
            _ => {
                let mut values = Vec::with_capacity(m * features.channels());
                for row in 0..m {
                    let (p, c) = (batch.point(row), batch.centre(row));
                    let local = [0, 1, 2].map(|k| (p[k] - c[k]) / batch.voxel_size[k]);
                    let q = [p[0] - centre[0], p[1] - centre[1], p[2]];
                    match features {
                        InputFeatures::Xyz => values.extend(q),
                        InputFeatures::XyzLocal => values.extend(q.into_iter().chain(local)),
                        InputFeatures::RangeHeight => values.extend([q[0].hypot(q[1]), q[2]].into_iter().chain(local)),
                    }
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
        if self.config.symmetry == Symmetry::QuarterTurns {
            let kernel = self.backbone.stem[0].kernel_size;
            self.backbone.stem[0].tied = Some(Arc::new(TiedKernel::lifting(kernel, &input.turn(), c_out)));
        }
        self.config.input = input;
        self.config.in_channels = input.channels();
        self
    }

    /// Head output for every voxel of the batch, `[M, coder().channels()]` (layout in [`box_coder`]).
    pub fn forward(&self, batch: &Batch, device: &Device) -> Tensor<2> {
        let input = match self.config.symmetry {
            Symmetry::None => Self::input(batch, self.config.input, device),
            Symmetry::QuarterTurns => {
                assert_eq!(
                    batch.voxel_size[0], batch.voxel_size[1],
                    "model.symmetry = \"quarter_turns\" needs square voxels in x and y, got {:?}",
                    batch.voxel_size
                );
                Self::input_about(batch, self.config.input, Self::turn_centre(batch.voxel_size), device)
            }
        };
        let x = self.backbone.forward(input);
        match self.pooled_head {
            true => pooled_linear(&self.head, &x, &self.head_turn()),
            false => per_voxel_linear(&self.head, &x),
        }
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
