//! The op and its companions as Burn backend extensions, each with its own backward in
//! `Autodiff`: the CPU backends call [`crate::kernels::cpu`], the cubecl backends
//! [`crate::kernels::cube`], any other backend a composition of Burn primitives (the reference
//! the tests compare against).
//!
//! - [`conv`]: the sparse convolution ([`sparse_conv`](conv::sparse_conv)).
//! - [`batch_norm`]: batch norm (+ ReLU, + a residual's sum) as one op.
//! - [`conv_norm`]: a conv and the batch norm after it at inference (fixed statistics) as one op.
//! - [`concat`]: channel concatenation (skip connections) as one op.
//! - [`output_grad`]: a backward pass from a given output gradient ([`backward_from`](output_grad::backward_from)).
//! - `host`: how the CPU paths read a CPU backend's floats and wrap results.

pub mod batch_norm;
pub mod concat;
pub mod conv;
pub mod conv_norm;
pub(crate) mod host;
pub mod output_grad;
