//! Learning-rate schedules, evaluated at the fractional epoch `e = epoch + batch / batches_per_epoch`
//! before every iteration (the authors' `optim.py` sets the lr every iteration, not every epoch).

use anyhow::{Result, bail};
use serde::{Deserialize, Serialize};

/// A learning-rate schedule (`[train.schedule]`, `kind` picks it).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum Schedule {
    /// The authors' (`lidar_det/pipeline/optim.py`): `lr0` until `epoch0`, then exponential decay
    /// reaching `lr1` at `epoch1`: `lr0 · (lr1/lr0)^((e − epoch0)/(epoch1 − epoch0))`; `lr1` after
    /// `epoch1`.
    ExpDecay {
        /// Initial lr.
        #[serde(default = "lr0")]
        lr0: f64,
        /// End of the constant part.
        #[serde(default = "epoch0")]
        epoch0: f64,
        /// lr reached at `epoch1`.
        #[serde(default = "lr1")]
        lr1: f64,
        /// End of the decay.
        #[serde(default = "epoch1")]
        epoch1: f64,
    },
    /// One lr throughout.
    Constant {
        /// The lr.
        #[serde(default = "lr0")]
        lr: f64,
    },
    /// Linear warm-up from `lr_min` over `warmup_epochs`, then half a cosine from `lr` to `lr_min`
    /// at the run's last epoch (`train.epochs`).
    Cosine {
        /// Peak lr.
        #[serde(default = "lr0")]
        lr: f64,
        /// Floor.
        #[serde(default = "lr1")]
        lr_min: f64,
        /// Warm-up length.
        #[serde(default)]
        warmup_epochs: f64,
    },
}

fn lr0() -> f64 {
    1e-3
}
fn lr1() -> f64 {
    1e-6
}
fn epoch0() -> f64 {
    15.0
}
fn epoch1() -> f64 {
    40.0
}

impl Default for Schedule {
    /// The paper's: 1e-3 until epoch 15, exponential decay to 1e-6 at epoch 40.
    fn default() -> Self {
        Schedule::ExpDecay { lr0: lr0(), epoch0: epoch0(), lr1: lr1(), epoch1: epoch1() }
    }
}

impl Schedule {
    /// The lr at fractional epoch `e` of a run of `epochs` epochs.
    pub fn lr(&self, e: f64, epochs: usize) -> f64 {
        match *self {
            Schedule::ExpDecay { lr0, epoch0, lr1, epoch1 } => {
                if e < epoch0 {
                    lr0
                } else if e >= epoch1 {
                    lr1
                } else {
                    lr0 * (lr1 / lr0).powf((e - epoch0) / (epoch1 - epoch0))
                }
            }
            Schedule::Constant { lr } => lr,
            Schedule::Cosine { lr, lr_min, warmup_epochs } => {
                if e < warmup_epochs {
                    lr_min + (lr - lr_min) * e / warmup_epochs
                } else {
                    let span = (epochs as f64 - warmup_epochs).max(f64::MIN_POSITIVE);
                    let t = ((e - warmup_epochs) / span).clamp(0.0, 1.0);
                    lr_min + 0.5 * (lr - lr_min) * (1.0 + (std::f64::consts::PI * t).cos())
                }
            }
        }
    }

    /// Checks the numbers.
    pub fn validate(&self) -> Result<()> {
        let ok = match *self {
            Schedule::ExpDecay { lr0, epoch0, lr1, epoch1 } => lr0 > 0.0 && lr1 > 0.0 && epoch0 >= 0.0 && epoch1 > epoch0,
            Schedule::Constant { lr } => lr > 0.0,
            Schedule::Cosine { lr, lr_min, warmup_epochs } => lr > 0.0 && lr_min >= 0.0 && lr_min <= lr && warmup_epochs >= 0.0,
        };
        if !ok {
            bail!("train.schedule: invalid values in {self:?} (lrs must be positive, epochs increasing)");
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn close(a: f64, b: f64) -> bool {
        (a - b).abs() <= 1e-12 * b.abs().max(1e-12)
    }

    #[test]
    fn papers_schedule_at_0_15_27_5_40() {
        let s = Schedule::default();
        assert!(close(s.lr(0.0, 40), 1e-3));
        assert!(close(s.lr(14.999, 40), 1e-3));
        assert!(close(s.lr(15.0, 40), 1e-3));
        // Half-way through the decay: the geometric mean of 1e-3 and 1e-6.
        assert!(close(s.lr(27.5, 40), 10f64.powf(-4.5)), "{}", s.lr(27.5, 40));
        assert!(close(s.lr(40.0, 40), 1e-6));
        // Strictly decreasing inside the decay, per iteration.
        assert!(s.lr(15.01, 40) < s.lr(15.0, 40) && s.lr(39.99, 40) > 1e-6);
    }

    #[test]
    fn other_schedules() {
        assert_eq!(Schedule::Constant { lr: 0.5 }.lr(33.0, 40), 0.5);
        let c = Schedule::Cosine { lr: 1.0, lr_min: 0.0, warmup_epochs: 2.0 };
        assert!(close(c.lr(1.0, 10), 0.5));
        assert!(close(c.lr(2.0, 10), 1.0));
        assert!(close(c.lr(6.0, 10), 0.5));
        assert!(c.lr(10.0, 10).abs() < 1e-12);
    }
}
