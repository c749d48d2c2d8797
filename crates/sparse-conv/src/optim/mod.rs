//! Optimisers whose update runs as one fused pass per parameter on every backend (their math per
//! target beside the op's, in [`crate::kernels`]).
//!
//! - [`adam`]: [`FusedAdam`](adam::FusedAdam), Burn's Adam (and AMSGrad) in one pass, with Burn's
//!   state, so checkpoints load either way.

pub mod adam;
