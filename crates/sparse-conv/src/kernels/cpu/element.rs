//! What every CPU kernel shares: the element type with its GEMM and its hooks for kernels
//! specific to a type and CPU, the direction of a pass, the epilogue a conv may run on its rows,
//! and buffers written in parallel without zeroing.

use rayon::prelude::*;

use crate::geometry::kernel_map::OffsetPairs;

/// Pairs per partial sum of the weight gradient.
pub(crate) const GRAD_CHUNK: usize = 2048;

/// A float type the kernels run on, with its GEMM.
pub trait Element:
    Copy
    + Send
    + Sync
    + Default
    + PartialOrd
    + std::ops::AddAssign
    + std::ops::Add<Output = Self>
    + std::ops::Sub<Output = Self>
    + std::ops::Mul<Output = Self>
    + std::ops::Div<Output = Self>
    + 'static
{
    /// `C = A·B + beta·C` with arbitrary strides (matrixmultiply's contract).
    ///
    /// # Safety
    /// The pointers and strides must describe valid `m×k`, `k×n` and `m×n` matrices.
    #[allow(clippy::too_many_arguments)]
    unsafe fn gemm(
        m: usize, k: usize, n: usize,
        a: *const Self, rsa: isize, csa: isize,
        b: *const Self, rsb: isize, csb: isize,
        beta: Self, c: *mut Self, rsc: isize, csc: isize,
    );
    /// 0.
    const ZERO: Self;
    /// 1.
    const ONE: Self;
    /// The value as f64 (exact for f32 and f64).
    fn to_f64(self) -> f64;
    /// `v` rounded to this type.
    fn from_f64(v: f64) -> Self;
    /// Square root.
    fn sqrt(self) -> Self;

    /// [`weight_grad`](super::weight_grad) by a kernel specific to this type and CPU, where one runs.
    fn weight_grad_native(_x: &[Self], _c_in: usize, _grad_out: &[Self], _c_out: usize, _pairs: &OffsetPairs) -> Option<Vec<Self>> {
        None
    }

    /// The sums of [`channel_stats`](super::norm::channel_stats) over a chunk of rows by a kernel specific
    /// to this type and CPU, where one runs (the same bits as the general loops).
    fn stats_sums_native(_x: &[Self], _c: usize, _shift: &[Self]) -> Option<Vec<f64>> {
        None
    }

    /// The sums of [`param_grads`](super::norm::param_grads) over a chunk of rows, likewise.
    #[allow(clippy::too_many_arguments)]
    fn param_sums_native(_x: &[Self], _g: &[Self], _c: usize, _a: &[Self], _b: &[Self], _mean: &[Self], _relu: bool) -> Option<Vec<f64>> {
        None
    }

    /// [`pair_conv`](super::pair_conv) by a kernel specific to this type and CPU, where one runs.
    #[allow(clippy::too_many_arguments)]
    fn pair_conv_native(
        _src: &[Self], _c_src: usize, _weight: &[Self], _c_dst: usize, _n_dst: usize,
        _direction: PairDirection, _pairs: &OffsetPairs, _identity: Option<usize>, _epilogue: Option<&dyn RowEpilogue<Self>>,
    ) -> Option<Vec<Self>> {
        None
    }
}

impl Element for f64 {
    unsafe fn gemm(
        m: usize, k: usize, n: usize,
        a: *const f64, rsa: isize, csa: isize,
        b: *const f64, rsb: isize, csb: isize,
        beta: f64, c: *mut f64, rsc: isize, csc: isize,
    ) {
        unsafe { matrixmultiply::dgemm(m, k, n, 1.0, a, rsa, csa, b, rsb, csb, beta, c, rsc, csc) }
    }
    const ZERO: f64 = 0.0;
    const ONE: f64 = 1.0;
    fn to_f64(self) -> f64 {
        self
    }
    fn from_f64(v: f64) -> f64 {
        v
    }
    fn sqrt(self) -> f64 {
        f64::sqrt(self)
    }
}

/// Which side of each pair a pass gathers from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PairDirection {
    /// Gather inputs, scatter to outputs: the forward.
    Forward,
    /// Gather output gradients, scatter to inputs: the feature gradient.
    Backward,
}

/// What a conv kernel runs on its finished output rows: the inference batch norm after the conv
/// ([`ConvEpilogue`](super::norm::ConvEpilogue)), applied while the rows are in cache.
pub trait RowEpilogue<T>: Sync {
    /// Channels of the rows it applies to.
    fn channels(&self) -> usize;
    /// Applies to whole rows, the first of which is output row `first`.
    fn apply(&self, first: usize, rows: &mut [T]);
    /// Applies to a whole output.
    fn apply_all(&self, out: &mut [T]);
}

/// `len` elements of scratch space, not initialised.
pub(crate) fn scratch<T>(len: usize) -> Vec<std::mem::MaybeUninit<T>> {
    let mut v = Vec::with_capacity(len);
    // SAFETY: MaybeUninit needs no initialisation.
    unsafe { v.set_len(len) };
    v
}

/// `v` as the values written into it.
///
/// # Safety
/// Every element of `v` must have been written.
pub(crate) unsafe fn assume_init<T>(v: Vec<std::mem::MaybeUninit<T>>) -> Vec<T> {
    let mut v = std::mem::ManuallyDrop::new(v);
    // SAFETY: MaybeUninit<T> has T's layout; the caller vouches for every element.
    unsafe { Vec::from_raw_parts(v.as_mut_ptr().cast::<T>(), v.len(), v.capacity()) }
}

/// A `len`-element output written in parallel, `chunk` elements per task (the last may be
/// shorter), without zeroing it first: `fill(i, dst)` gets chunk `i` and must write every
/// element of it.
pub(crate) fn filled_in_chunks<T: Send>(len: usize, chunk: usize, fill: impl Fn(usize, &mut [std::mem::MaybeUninit<T>]) + Sync) -> Vec<T> {
    let mut out = Vec::with_capacity(len);
    out.spare_capacity_mut()[..len].par_chunks_mut(chunk.max(1)).enumerate().for_each(|(i, dst)| fill(i, dst));
    // SAFETY: the chunks cover all `len` elements and `fill` writes every element of each.
    unsafe { out.set_len(len) };
    out
}

/// Runs `f` compiled for the widest SIMD the CPU has (and `KernelOptions` allows). Plain loops
/// over channels or elements are vectorized for the features of the function they land in, so
/// only if LLVM inlines `f` into it: a small closure calling an `#[inline(always)]` function is
/// (Adam's chunks, the ReLU gradient); the batch-norm passes' row closures were not, which the
/// binary shows (`zmm`/`ymm` or only `xmm` in the symbol). The default x86-64 target has 128-bit
/// SSE2 only. Without fused multiply-adds (Rust never contracts `a·b + c`) the results are the
/// same bits either way.
#[inline(always)]
pub(crate) fn vectorized<R>(f: impl FnOnce() -> R) -> R {
    #[cfg(target_arch = "x86_64")]
    match super::simd::level() {
        Some(super::simd::Level::Avx512) => {
            #[target_feature(enable = "avx512f")]
            unsafe fn with_avx512<R>(f: impl FnOnce() -> R) -> R {
                f()
            }
            // SAFETY: the CPU has AVX-512F.
            return unsafe { with_avx512(f) };
        }
        Some(super::simd::Level::Avx2) => {
            #[target_feature(enable = "avx2,fma")]
            unsafe fn with_avx2<R>(f: impl FnOnce() -> R) -> R {
                f()
            }
            // SAFETY: the CPU has AVX2 and FMA.
            return unsafe { with_avx2(f) };
        }
        None => {}
    }
    f()
}
