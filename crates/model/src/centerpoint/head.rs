//! CenterPoint's head (its `center_head.py`): a shared 3×3 conv, then one two-conv branch per task.
//!
//! Output channels, concatenated: `[0]` heatmap logit, `[1..3]` sub-cell offset (x, y), `[3]` z
//! centre (m), `[4..7]` log l, w, h (m), `[7..9]` sin θ, cos θ.

use sparse_conv::burn::module::{Module, Param};
use sparse_conv::burn::nn::PaddingConfig2d;
use sparse_conv::burn::nn::conv::{Conv2d, Conv2dConfig};
use sparse_conv::burn::tensor::{Device, Tensor};

use super::backbone::ConvBnRelu2d;

/// Heatmap channel.
pub const HM: usize = 0;
/// First of the two offset channels.
pub const REG: usize = 1;
/// The z channel.
pub const HEIGHT: usize = 3;
/// First of the three log-dimension channels.
pub const DIM: usize = 4;
/// First of the sin/cos channels.
pub const ROT: usize = 7;
/// All output channels.
pub const CHANNELS: usize = 9;
/// Channels of each task, in output order.
pub const TASKS: [(&str, usize); 5] = [("hm", 1), ("reg", 2), ("height", 1), ("dim", 3), ("rot", 2)];

/// One task branch: Conv3×3 → BN → ReLU → Conv3×3 (with bias).
#[derive(Module, Debug)]
pub struct TaskBranch {
    /// Hidden conv.
    pub hidden: ConvBnRelu2d,
    /// Output conv, with bias.
    pub out: Conv2d,
}

/// Shared conv and the five task branches.
#[derive(Module, Debug)]
pub struct CenterHead {
    /// Shared Conv3×3 → BN → ReLU.
    pub shared: ConvBnRelu2d,
    /// Branches in [`TASKS`] order.
    pub tasks: Vec<TaskBranch>,
}

impl CenterHead {
    /// The head on `c_in` channels with `hidden` channels; the heatmap bias starts at `hm_bias`.
    pub fn new(c_in: usize, hidden: usize, hm_bias: f64, momentum: f64, device: &Device) -> Self {
        let tasks = TASKS
            .iter()
            .map(|&(name, c)| {
                let mut out = Conv2dConfig::new([hidden, c], [3, 3]).with_padding(PaddingConfig2d::Explicit(1, 1, 1, 1)).init(device);
                if name == "hm" {
                    out.bias = Some(Param::from_tensor(Tensor::full([c], hm_bias, device)));
                }
                TaskBranch { hidden: ConvBnRelu2d::new(hidden, hidden, 1, momentum, device), out }
            })
            .collect();
        Self { shared: ConvBnRelu2d::new(c_in, hidden, 1, momentum, device), tasks }
    }

    /// `[B, C, X, Y] → [B, 9, X, Y]`.
    pub fn forward(&self, x: Tensor<4>) -> Tensor<4> {
        let x = self.shared.forward(x);
        Tensor::cat(self.tasks.iter().map(|t| t.out.forward(t.hidden.forward(x.clone()))).collect(), 1)
    }
}
