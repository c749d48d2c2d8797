//! The MinkUNet backbone of Person-MinkUNet (the SPVNAS layout of the authors' `nets/minkunet.py`).

use burn::module::Module;
use burn::tensor::Device;
use sparse_conv::{Epilogue, SparseTensor};
use sparse_conv::modules::turns::{FieldTurn, TURNS, TiedKernel};
use sparse_conv::modules::{
    ConvBnRelu, ConvBnReluConfig, DeconvBnRelu, DeconvBnReluConfig, ResidualBlock, ResidualBlockConfig, SparseBatchNorm,
    SparseBatchNormConfig, SubmanifoldConv3d, SubmanifoldConv3dConfig,
};

/// Shape of the backbone: `channels = [stem, down_1..down_n, up_1..up_n]` (2n + 1 entries), each
/// multiplied by `width` (the paper's `cr`). The defaults are the paper's.
#[derive(Debug, Clone, PartialEq)]
pub struct MinkUNetConfig {
    /// Input feature channels (xyz of the voxel's point).
    pub in_channels: usize,
    /// `[stem, down_1..down_n, up_1..up_n]` before the width factor.
    pub channels: Vec<usize>,
    /// Width factor on every entry of `channels`.
    pub width: f64,
    /// With quarter-turn symmetry: how the input channels turn. Every layer then holds four
    /// orientation copies of a quarter of its channels (`sparse_conv::modules::turns`).
    pub input_turn: Option<FieldTurn>,
}

impl Default for MinkUNetConfig {
    fn default() -> Self {
        Self { in_channels: 3, channels: vec![32, 32, 64, 128, 256, 256, 128, 96, 96], width: 1.0, input_turn: None }
    }
}

impl MinkUNetConfig {
    /// Channels after the width factor, as torchsparse's `int(cr * c)`.
    pub fn scaled_channels(&self) -> Vec<usize> {
        self.channels.iter().map(|&c| ((self.width * c as f64) as usize).max(1)).collect()
    }

    /// Number of down (and up) stages.
    pub fn stages(&self) -> usize {
        (self.channels.len() - 1) / 2
    }

    /// Channels of the per-voxel features the backbone returns.
    pub fn out_channels(&self) -> usize {
        *self.scaled_channels().last().expect("channels are not empty")
    }

    /// A backbone with fresh parameters (initialised as the authors' torchsparse 1.2 code does).
    pub fn init(&self, device: &Device) -> MinkUNet {
        assert!(
            self.channels.len() >= 3 && self.channels.len() % 2 == 1,
            "MinkUNet channels need 2n + 1 entries (stem, n down, n up), got {}",
            self.channels.len()
        );
        let cs = self.scaled_channels();
        let n = self.stages();
        let turns = self.input_turn.is_some();
        let copies = if turns { TURNS } else { 1 };
        let stem = match &self.input_turn {
            Some(input) => {
                assert!(cs[0] % TURNS == 0, "stem channels {} do not split into {TURNS} orientation copies", cs[0]);
                let c = cs[0] / TURNS;
                [
                    SubmanifoldConv3dConfig::new([self.in_channels, cs[0]]).init_tied(TiedKernel::lifting(3, input, c), device),
                    SubmanifoldConv3dConfig::new([cs[0], cs[0]]).init_tied(TiedKernel::regular(3, c, c), device),
                ]
            }
            None => [
                SubmanifoldConv3dConfig::new([self.in_channels, cs[0]]).init(device),
                SubmanifoldConv3dConfig::new([cs[0], cs[0]]).init(device),
            ],
        };
        let norm = || SparseBatchNormConfig::new(cs[0]).with_copies(copies).init(device);
        let stem_norms = [norm(), norm()];
        let down = (1..=n)
            .map(|i| DownStage {
                conv: ConvBnReluConfig::new([cs[i - 1], cs[i - 1]]).with_turns(turns).init(device),
                blocks: vec![
                    ResidualBlockConfig::new([cs[i - 1], cs[i]]).with_turns(turns).init(device),
                    ResidualBlockConfig::new([cs[i], cs[i]]).with_turns(turns).init(device),
                ],
            })
            .collect();
        let up = (0..n)
            .map(|j| {
                let (prev, out, skip) = (cs[n + j], cs[n + 1 + j], cs[n - 1 - j]);
                UpStage {
                    deconv: DeconvBnReluConfig::new([prev, out]).with_turns(turns).init(device),
                    blocks: vec![
                        ResidualBlockConfig::new([out + skip, out]).with_turns(turns).init(device),
                        ResidualBlockConfig::new([out, out]).with_turns(turns).init(device),
                    ],
                }
            })
            .collect();
        MinkUNet { stem: stem.into(), stem_norms: stem_norms.into(), down, up, copies }
    }
}

/// Strided conv (k2 s2) → BN → ReLU, then two residual blocks.
#[derive(Module, Debug)]
pub struct DownStage {
    /// The stride-2 convolution.
    pub conv: ConvBnRelu,
    /// The residual blocks after it.
    pub blocks: Vec<ResidualBlock>,
}

/// Transposed conv → BN → ReLU, concatenation `[upsampled, skip]`, two residual blocks.
#[derive(Module, Debug)]
pub struct UpStage {
    /// The stride-2 transposed convolution; its output is concatenated with the skip.
    pub deconv: DeconvBnRelu,
    /// The residual blocks after it.
    pub blocks: Vec<ResidualBlock>,
}

/// Sparse U-Net: features for every input voxel, computed through four (configurable) levels.
#[derive(Module, Debug)]
pub struct MinkUNet {
    /// The two 3×3×3 convolutions at full resolution.
    pub stem: Vec<SubmanifoldConv3d>,
    /// Their batch norms.
    pub stem_norms: Vec<SparseBatchNorm>,
    /// Encoder stages, finest first.
    pub down: Vec<DownStage>,
    /// Decoder stages, coarsest first.
    pub up: Vec<UpStage>,
    /// Orientation copies every layer's channels hold (4 with quarter-turn symmetry, else 1).
    #[module(skip)]
    pub copies: usize,
}

/// Every level a forward pass went through: `down[0]` is the stem output (stride 1), `down[i]`
/// stage i's (stride 2^i); `up[j]` up stage j's output, on the coordinates of `down[n − 1 − j]`.
#[derive(Debug, Clone)]
pub struct UNetLevels {
    /// Stem and down-stage outputs, finest first.
    pub down: Vec<SparseTensor>,
    /// Up-stage outputs, coarsest first; the last is the backbone's output.
    pub up: Vec<SparseTensor>,
}

impl MinkUNet {
    /// The same network with its quarter-turn ties written out: plain weights and plain
    /// concatenations computing the same function, for inference (where the ties only cost
    /// time). The up stages' first blocks read `[upsampled, skip]` instead of the copies
    /// interleaved, their input rows reordered to match.
    pub fn untied(self) -> Self {
        let copies = self.copies;
        if copies == 1 {
            return self;
        }
        let untie_all = |blocks: Vec<ResidualBlock>| blocks.into_iter().map(ResidualBlock::untied).collect::<Vec<_>>();
        let down = self.down.into_iter().map(|s| DownStage { conv: s.conv.untied(), blocks: untie_all(s.blocks) }).collect();
        let up = self
            .up
            .into_iter()
            .map(|s| {
                let deconv = s.deconv.untied();
                let mut blocks = untie_all(s.blocks);
                let upsampled = deconv.conv.weight.dims()[2];
                let skip = blocks[0].conv1.weight.dims()[1] - upsampled;
                let (a, b) = (upsampled / copies, skip / copies);
                // Plain channel p of [upsampled, skip] was channel `order[p]` of the copies interleaved.
                let order: Vec<usize> = (0..upsampled + skip)
                    .map(|p| if p < upsampled { (p / a) * (a + b) + p % a } else { ((p - upsampled) / b) * (a + b) + a + (p - upsampled) % b })
                    .collect();
                blocks[0] = blocks[0].clone().with_input_order(&order);
                UpStage { deconv, blocks }
            })
            .collect();
        MinkUNet {
            stem: self.stem.into_iter().map(|c| c.untied()).collect(),
            stem_norms: self.stem_norms.into_iter().map(|n| n.untied()).collect(),
            down,
            up,
            copies: 1,
        }
    }

    /// Per-voxel features on the input's voxels (stride 1).
    pub fn forward(&self, x: SparseTensor) -> SparseTensor {
        let mut levels = self.forward_levels(x);
        match levels.up.pop() {
            Some(out) => out,
            None => levels.down.pop().expect("the stem always runs"),
        }
    }

    /// The forward pass keeping every level's output (for checks of the stride bookkeeping).
    pub fn forward_levels(&self, x: SparseTensor) -> UNetLevels {
        // Every level's map before any layer is queued: on a GPU the levels' sizes are counted on
        // the host here and their maps queued on the device, nothing read back.
        x.prepare_down_levels(self.down.iter().map(|stage| stage.conv.conv.kernel_size));
        let mut x = x;
        for (conv, norm) in self.stem.iter().zip(&self.stem_norms) {
            x = conv.forward_norm(x, norm, Epilogue::Relu);
        }
        let mut down = vec![x];
        for stage in &self.down {
            let mut y = stage.conv.forward(down.last().unwrap().clone());
            for block in &stage.blocks {
                y = block.forward(y);
            }
            down.push(y);
        }
        let mut up: Vec<SparseTensor> = Vec::with_capacity(self.up.len());
        let n = down.len();
        for (j, stage) in self.up.iter().enumerate() {
            let below = up.last().unwrap_or(&down[n - 1]).clone();
            // Concatenation order is [upsampled, skip] (as in the authors' `minkunet.py`), within
            // each orientation copy.
            let mut y = stage.deconv.forward(below).cat_copies(&down[n - 2 - j], self.copies);
            for block in &stage.blocks {
                y = block.forward(y);
            }
            up.push(y);
        }
        UNetLevels { down, up }
    }
}

