//! Batch norm, optionally followed by ReLU, over `[rows, C]` slices: the statistics, the
//! normalisation and its two gradients, each one pass over the rows. Every CPU backend calls
//! these; composed over Burn primitives the same layer takes about a dozen passes each way, with
//! transposed copies of the activations (a quarter of a MinkUNet training step, `crates/sparse-conv/README.md`).
//!
//! Conventions: `stats` is `[mean_0..mean_C, var_0..var_C]` with the biased variance (what the
//! output is normalised with, and what Burn's running variance takes; PyTorch's running variance
//! takes the unbiased one). The layer is
//! `z = x·a + b` with `a = γ/√(var + ε)`, `b = β − mean·a`, then `y = max(z, 0)` when `relu`;
//! ReLU's derivative at 0 is 0, and a NaN passes through (as Burn's `relu`), never hidden.
//!
//! Determinism: per-channel sums are taken over blocks of 16 rows in the element type, then in
//! f64 over fixed chunks of rows added in chunk order, so results are bit-identical at any thread
//! count. The backward recomputes `z` with the
//! same `a`, `b` and arithmetic as the forward, so its ReLU mask is the forward's exactly.

use std::mem::MaybeUninit;

use rayon::prelude::*;

use super::element::{Element, RowEpilogue, filled_in_chunks, vectorized};

/// Rows per partial sum and per parallel task.
const CHUNK_ROWS: usize = 1024;

/// Mean and biased variance of each of the `c` channels of `x`, as `[means.., variances..]`.
/// Zero rows give mean 0 and variance 0.
pub fn channel_stats<T: Element>(x: &[T], c: usize) -> Vec<T> {
    let n = x.len().checked_div(c).unwrap_or(0);
    if n == 0 {
        return vec![T::ZERO; 2 * c];
    }
    // Sums of (x − x_0): shifted by the first row, the variance does not lose its digits to
    // cancellation when a channel's mean is large against its spread.
    let shift = &x[..c];
    let shift_lanes = lane_groups(shift);
    let sums = channel_sums(x.par_chunks(CHUNK_ROWS * c).map(|rows| T::stats_sums_native(rows, c, shift).unwrap_or_else(|| stats_sums(rows, c, &shift_lanes))));
    let (s1, s2) = sums.split_at(c);
    let inv_n = 1.0 / n as f64;
    let mut out = Vec::with_capacity(2 * c);
    out.extend(s1.iter().zip(shift).map(|(s, k)| T::from_f64(k.to_f64() + s * inv_n)));
    out.extend(s1.iter().zip(s2).map(|(s1, s2)| T::from_f64((s2 * inv_n - (s1 * inv_n).powi(2)).max(0.0))));
    out
}

/// `[Σ (x − shift); Σ (x − shift)²]` per channel over `rows`: [`channel_stats`]' sums over a
/// chunk, by the general loops.
fn stats_sums<T: Element>(rows: &[T], c: usize, shift_lanes: &[[T; LANES]]) -> Vec<f64> {
    block_sums(c, rows, rows, |group, x, _, s1, s2| {
        let k = &shift_lanes[group];
        for l in 0..LANES {
            let d = x[l] - k[l];
            s1[l] += d;
            s2[l] += d * d;
        }
    })
}

/// Rows summed per block in the element type before the block's sums join the f64 totals:
/// short enough to keep f32 rounding small, long enough for the vector loops to dominate.
const BLOCK_ROWS: usize = 16;

/// Channels whose sums a reduction carries together, in registers: one AVX-512 vector of f32.
const LANES: usize = 16;

/// The `LANES` values of `row` from channel `j0`, zero past its end.
#[inline(always)]
fn lanes<T: Element>(row: &[T], j0: usize) -> [T; LANES] {
    match row.get(j0..j0 + LANES) {
        Some(v) => v.try_into().expect("LANES values"),
        None => {
            let mut out = [T::ZERO; LANES];
            out[..row.len() - j0].copy_from_slice(&row[j0..]);
            out
        }
    }
}

/// A per-channel parameter as groups of [`LANES`] channels (the last padded with zeros).
fn lane_groups<T: Element>(v: &[T]) -> Vec<[T; LANES]> {
    (0..v.len()).step_by(LANES).map(|j0| lanes(v, j0)).collect()
}

/// Two per-channel sums over the rows of `x` and `y` (`c` values each; `y` as many rows as `x`):
/// `add(group, x, y, s1, s2)` accumulates one row's [`LANES`] channels of lane group `group`
/// into the block's sums in `T`, which are added into f64 totals block by block. Each group's
/// sums stay in registers over the block's rows; every channel still sums its rows in row order,
/// as one row at a time would. Returns `[s1.., s2..]`.
///
/// On CPUs with AVX-512 or AVX2 + FMA f32 runs kernels of its own
/// ([`Element::stats_sums_native`]), so these loops serve f64 and other CPUs.
fn block_sums<T: Element>(c: usize, x: &[T], y: &[T], add: impl Fn(usize, &[T; LANES], &[T; LANES], &mut [T; LANES], &mut [T; LANES])) -> Vec<f64> {
    let n = x.len() / c;
    let groups = c.div_ceil(LANES);
    // The f64 totals by lane group too, so that adding a block's sums is vector code as well.
    let mut totals = vec![[[0.0f64; LANES]; 2]; groups];
    for b0 in (0..n).step_by(BLOCK_ROWS) {
        let rows = b0..(b0 + BLOCK_ROWS).min(n);
        for (group, total) in totals.iter_mut().enumerate() {
            let j0 = group * LANES;
            let (mut s1, mut s2) = ([T::ZERO; LANES], [T::ZERO; LANES]);
            for r in rows.clone() {
                let (xr, yr) = (&x[r * c..(r + 1) * c], &y[r * c..(r + 1) * c]);
                add(group, &lanes(xr, j0), &lanes(yr, j0), &mut s1, &mut s2);
            }
            for l in 0..LANES {
                total[0][l] += s1[l].to_f64();
                total[1][l] += s2[l].to_f64();
            }
        }
    }
    let mut out = vec![0.0f64; 2 * c];
    for (group, total) in totals.iter().enumerate() {
        let j0 = group * LANES;
        let w = LANES.min(c - j0);
        out[j0..j0 + w].copy_from_slice(&total[0][..w]);
        out[c + j0..c + j0 + w].copy_from_slice(&total[1][..w]);
    }
    out
}

/// Adds the chunks' totals in chunk order (the order does not depend on the threads).
fn channel_sums(partials: impl IndexedParallelIterator<Item = Vec<f64>>) -> Vec<f64> {
    let partials: Vec<Vec<f64>> = partials.collect();
    let mut sums = vec![0.0f64; partials.first().map_or(0, Vec::len)];
    for partial in partials {
        for (s, p) in sums.iter_mut().zip(partial) {
            *s += p;
        }
    }
    sums
}

/// Per-channel `(a, b, 1/√(var + ε))`; forward and backward both take them from here, so the
/// backward's `z` is the forward's bit for bit.
fn affine<T: Element>(stats: &[T], gamma: &[T], beta: &[T], epsilon: f64) -> (Vec<T>, Vec<T>, Vec<f64>) {
    let c = gamma.len();
    assert_eq!(stats.len(), 2 * c, "batch norm statistics must be [2, {c}]");
    assert_eq!(beta.len(), c, "batch norm beta must have {c} channels");
    let (mean, var) = stats.split_at(c);
    let inv_std: Vec<f64> = var.iter().map(|v| 1.0 / (v.to_f64() + epsilon).sqrt()).collect();
    let a: Vec<f64> = gamma.iter().zip(&inv_std).map(|(g, s)| g.to_f64() * s).collect();
    let b = beta.iter().zip(mean).zip(&a).map(|((be, m), a)| T::from_f64(be.to_f64() - m.to_f64() * a)).collect();
    (a.into_iter().map(T::from_f64).collect(), b, inv_std)
}

/// The layer's output for one element: `z = x·a + b`, plus the residual's element with
/// `RESIDUAL` (whose sum is always followed by ReLU), then ReLU when `relu`. Every forward path
/// (the passes below and [`ConvEpilogue`]) computes it here, so they agree bit for bit.
#[inline(always)]
fn output<T: Element, const RESIDUAL: bool>(x: T, a: T, b: T, residual: T, relu: bool) -> T {
    let y = if RESIDUAL { x * a + b + residual } else { x * a + b };
    if (RESIDUAL || relu) && y <= T::ZERO { T::ZERO } else { y }
}

/// `y = x·a + b`, then ReLU when `relu`: the layer's output.
pub fn normalize<T: Element>(x: &[T], stats: &[T], gamma: &[T], beta: &[T], epsilon: f64, relu: bool) -> Vec<T> {
    let c = gamma.len();
    let (a, b, _) = affine(stats, gamma, beta, epsilon);
    map_rows(x.len(), c, |chunk, out| {
        let rows = &x[chunk * CHUNK_ROWS * c..][..out.len()];
        for (row, dst) in rows.chunks_exact(c).zip(out.chunks_exact_mut(c)) {
            for (((d, &v), &a), &b) in dst.iter_mut().zip(row).zip(&a).zip(&b) {
                d.write(output::<T, false>(v, a, b, T::ZERO, relu));
            }
        }
    })
}

/// `y = max(x·a + b + residual, 0)`: the end of a residual block (its last batch norm, the
/// shortcut's sum and the ReLU) in one pass.
pub fn normalize_add_relu<T: Element>(x: &[T], stats: &[T], gamma: &[T], beta: &[T], residual: &[T], epsilon: f64) -> Vec<T> {
    let c = gamma.len();
    assert_eq!(x.len(), residual.len(), "batch norm input and residual differ in size");
    let (a, b, _) = affine(stats, gamma, beta, epsilon);
    map_rows(x.len(), c, |chunk, out| {
        let start = chunk * CHUNK_ROWS * c;
        let rows = x[start..][..out.len()].chunks_exact(c);
        let skips = residual[start..][..out.len()].chunks_exact(c);
        for ((row, skip), dst) in rows.zip(skips).zip(out.chunks_exact_mut(c)) {
            let (skip, a, b, dst) = (&skip[..c], &a[..c], &b[..c], &mut dst[..c]);
            for j in 0..c {
                dst[j].write(output::<T, true>(row[j], a[j], b[j], skip[j], true));
            }
        }
    })
}

/// Batch norm with given statistics (inference), then its ReLU or a residual's sum and ReLU,
/// applied in place to a convolution's finished output rows: the conv kernels run it on each
/// block of rows while the block is still in cache, instead of a pass of its own.
pub struct ConvEpilogue<'a, T> {
    a: Vec<T>,
    b: Vec<T>,
    relu: bool,
    /// All rows of the residual, `[n_out, C]`.
    residual: Option<&'a [T]>,
}

impl<'a, T: Element> ConvEpilogue<'a, T> {
    /// `stats`, `gamma`, `beta` and `epsilon` as [`normalize`]'s; with `residual`, ReLU follows
    /// its sum (as [`normalize_add_relu`]) and `relu` is ignored.
    pub fn new(stats: &[T], gamma: &[T], beta: &[T], epsilon: f64, relu: bool, residual: Option<&'a [T]>) -> Self {
        let (a, b, _) = affine(stats, gamma, beta, epsilon);
        ConvEpilogue { a, b, relu, residual }
    }
}

impl<T: Element> RowEpilogue<T> for ConvEpilogue<'_, T> {
    /// Channels of the rows it applies to.
    fn channels(&self) -> usize {
        self.a.len()
    }

    /// Applies to a whole output, in parallel chunks of rows: for paths that finish every row
    /// before any can take the epilogue.
    fn apply_all(&self, out: &mut [T]) {
        let c = self.channels();
        if c > 0 {
            out.par_chunks_mut(CHUNK_ROWS * c).enumerate().for_each(|(chunk, rows)| self.apply(chunk * CHUNK_ROWS, rows));
        }
    }

    /// Applies to whole rows, the first of which is output row `first`.
    fn apply(&self, first: usize, rows: &mut [T]) {
        let c = self.a.len();
        let (a, b) = (&self.a[..c], &self.b[..c]);
        match self.residual {
            Some(residual) => {
                let skips = residual[first * c..][..rows.len()].chunks_exact(c);
                for (row, skip) in rows.chunks_exact_mut(c).zip(skips) {
                    let (row, skip) = (&mut row[..c], &skip[..c]);
                    for j in 0..c {
                        row[j] = output::<T, true>(row[j], a[j], b[j], skip[j], true);
                    }
                }
            }
            None => {
                for row in rows.chunks_exact_mut(c) {
                    let row = &mut row[..c];
                    for j in 0..c {
                        row[j] = output::<T, false>(row[j], a[j], b[j], T::ZERO, self.relu);
                    }
                }
            }
        }
    }
}

/// ReLU's backward from its output: `dy` where `y > 0`, else 0 (a NaN output passes `dy`, as
/// Burn's `relu_backward`).
pub fn relu_grad<T: Element>(y: &[T], grad_out: &[T]) -> Vec<T> {
    assert_eq!(y.len(), grad_out.len(), "ReLU output and its gradient differ in size");
    const ELEMS: usize = 1 << 16;
    filled_in_chunks(y.len(), ELEMS, |chunk, dst| vectorized(|| {
        let (y, g) = (&y[chunk * ELEMS..][..dst.len()], &grad_out[chunk * ELEMS..][..dst.len()]);
        for j in 0..dst.len() {
            dst[j].write(if y[j] <= T::ZERO { T::ZERO } else { g[j] });
        }
    }))
}

/// `[Σ dz·x̂ ; Σ dz]` per channel, i.e. `[dγ ; dβ]`, where `dz` is `dy` through the ReLU's mask
/// and `x̂ = (x − mean)/√(var + ε)`.
#[allow(clippy::too_many_arguments)]
pub fn param_grads<T: Element>(x: &[T], grad_out: &[T], stats: &[T], gamma: &[T], beta: &[T], epsilon: f64, relu: bool) -> Vec<T> {
    let c = gamma.len();
    assert_eq!(x.len(), grad_out.len(), "batch norm input and output gradient differ in size");
    let (a, b, inv_std) = affine(stats, gamma, beta, epsilon);
    if c == 0 {
        return Vec::new();
    }
    let lanes = [lane_groups(&a), lane_groups(&b), lane_groups(&stats[..c])];
    let sums = channel_sums(x.par_chunks(CHUNK_ROWS * c).zip(grad_out.par_chunks(CHUNK_ROWS * c)).map(|(rows, grads)| {
        T::param_sums_native(rows, grads, c, &a, &b, &stats[..c], relu).unwrap_or_else(|| param_sums(rows, grads, c, &lanes, relu))
    }));
    let (dgamma, dbeta) = sums.split_at(c);
    dgamma.iter().zip(&inv_std).map(|(g, s)| T::from_f64(g * s)).chain(dbeta.iter().map(|&b| T::from_f64(b))).collect()
}

/// `[Σ dz·(x − mean); Σ dz]` per channel over `rows` and their gradients `grads`:
/// [`param_grads`]' sums over a chunk, by the general loops; `lanes` are `a`, `b` and the mean
/// as lane groups.
fn param_sums<T: Element>(rows: &[T], grads: &[T], c: usize, lanes: &[Vec<[T; LANES]>; 3], relu: bool) -> Vec<f64> {
    let params = |group: usize| (&lanes[0][group], &lanes[1][group], &lanes[2][group]);
    // One small closure per case, each inlined whole into the vector loop.
    if relu {
        block_sums(c, rows, grads, |group, row, grad, dgamma, dbeta| {
            let (a, b, mean) = params(group);
            param_lanes::<T, true>(row, grad, a, b, mean, dgamma, dbeta)
        })
    } else {
        block_sums(c, rows, grads, |group, row, grad, dgamma, dbeta| {
            let (a, b, mean) = params(group);
            param_lanes::<T, false>(row, grad, a, b, mean, dgamma, dbeta)
        })
    }
}

/// `dy` through the ReLU's mask: zero where `z = x·a + b ≤ 0`.
#[inline(always)]
fn masked<T: Element, const RELU: bool>(x: T, a: T, b: T, dy: T) -> T {
    if RELU && x * a + b <= T::ZERO { T::ZERO } else { dy }
}

/// One row's terms of [`param_grads`]' sums, for one group of [`LANES`] channels. `RELU` is a
/// constant and the lanes fixed, so the loop compiles to straight vector code.
#[inline(always)]
fn param_lanes<T: Element, const RELU: bool>(
    row: &[T; LANES],
    grad: &[T; LANES],
    a: &[T; LANES],
    b: &[T; LANES],
    mean: &[T; LANES],
    dgamma: &mut [T; LANES],
    dbeta: &mut [T; LANES],
) {
    for j in 0..LANES {
        let dz = masked::<T, RELU>(row[j], a[j], b[j], grad[j]);
        dbeta[j] += dz;
        dgamma[j] += dz * (row[j] - mean[j]);
    }
}

/// One row of [`input_grad`]: `dx = a·dz + c0 + c1·(x − mean)`; as [`param_row`].
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn input_grad_row<T: Element, const RELU: bool>(row: &[T], grad: &[T], a: &[T], b: &[T], c0: &[T], c1: &[T], mean: &[T], dst: &mut [MaybeUninit<T>]) {
    let c = row.len();
    let (grad, a, b, c0, c1, mean, dst) = (&grad[..c], &a[..c], &b[..c], &c0[..c], &c1[..c], &mean[..c], &mut dst[..c]);
    for j in 0..c {
        dst[j].write(a[j] * masked::<T, RELU>(row[j], a[j], b[j], grad[j]) + c0[j] + c1[j] * (row[j] - mean[j]));
    }
}

/// The input gradient. With `batch_stats` (training: the statistics are the batch's own)
/// `dx = a·(dz − dβ/N − x̂·dγ/N)`; without (running statistics, constants) `dx = a·dz`.
/// `param_grads` is [`param_grads`]' result for the same arguments.
#[allow(clippy::too_many_arguments)]
pub fn input_grad<T: Element>(
    x: &[T],
    grad_out: &[T],
    stats: &[T],
    gamma: &[T],
    beta: &[T],
    param_grads: &[T],
    epsilon: f64,
    relu: bool,
    batch_stats: bool,
) -> Vec<T> {
    let c = gamma.len();
    assert_eq!(x.len(), grad_out.len(), "batch norm input and output gradient differ in size");
    assert_eq!(param_grads.len(), 2 * c, "batch norm parameter gradients must be [2, {c}]");
    let n = x.len().checked_div(c).unwrap_or(0);
    let (a, b, inv_std) = affine(stats, gamma, beta, epsilon);
    let mean = &stats[..c];
    // dx = a·dz + c0 + c1·(x − mean), with c0 = −a·dβ/N and c1 = −a·s·dγ/N.
    let (c0, c1): (Vec<T>, Vec<T>) = (0..c)
        .map(|j| {
            if !batch_stats {
                return (T::ZERO, T::ZERO);
            }
            let a = a[j].to_f64() / n as f64;
            (T::from_f64(-a * param_grads[c + j].to_f64()), T::from_f64(-a * inv_std[j] * param_grads[j].to_f64()))
        })
        .unzip();
    map_rows(x.len(), c, |chunk, out| {
        let start = chunk * CHUNK_ROWS * c;
        let rows = x[start..][..out.len()].chunks_exact(c);
        let grads = grad_out[start..][..out.len()].chunks_exact(c);
        for ((row, grad), dst) in rows.zip(grads).zip(out.chunks_exact_mut(c)) {
            if relu {
                input_grad_row::<T, true>(row, grad, &a, &b, &c0, &c1, mean, dst);
            } else {
                input_grad_row::<T, false>(row, grad, &a, &b, &c0, &c1, mean, dst);
            }
        }
    })
}

/// A `len`-element output of `c`-channel rows written [`CHUNK_ROWS`] rows per parallel task;
/// `fill` must write every element of the chunk it is given.
fn map_rows<T: Element>(len: usize, c: usize, fill: impl Fn(usize, &mut [MaybeUninit<T>]) + Sync) -> Vec<T> {
    // Not through `vectorized`: LLVM does not inline these passes' closures into its AVX-512
    // body (checked in the binary), and the passes run at memory speed anyway.
    filled_in_chunks(len, CHUNK_ROWS * c, fill)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Hand-derived case: one channel [1, 2, 3, 6], γ = 2, β = 1, ε = 0: mean 3, var 3.5.
    #[test]
    fn one_channel_by_hand() {
        let x = [1.0f64, 2.0, 3.0, 6.0];
        let stats = channel_stats(&x, 1);
        assert_eq!(stats, vec![3.0, 3.5]);
        let y = normalize(&x, &stats, &[2.0], &[1.0], 0.0, false);
        let s = 1.0 / 3.5f64.sqrt();
        for (y, x) in y.iter().zip(x) {
            assert!((y - (2.0 * (x - 3.0) * s + 1.0)).abs() < 1e-12);
        }
        // With ReLU, rows below the mean by more than β/(γ·s) are cut.
        let y = normalize(&x, &stats, &[2.0], &[1.0], 0.0, true);
        assert_eq!(y[0], 0.0);
        assert!(y[2] > 0.0);
    }

    /// The shifted sums keep the variance of values far from zero.
    #[test]
    fn variance_of_large_values() {
        let x: Vec<f32> = (0..5000).map(|i| 1.0e4 + (i % 2) as f32).collect();
        let stats = channel_stats(&x, 1);
        assert!((stats[1] - 0.25).abs() < 1e-6, "var {}", stats[1]);
    }

    /// Every SIMD level's sums are the general loops' bits: partial lane groups (37 channels)
    /// and blocks (1005 rows), a single group, three channels; with and without ReLU, with a NaN
    /// input (whose gradient ReLU keeps).
    #[test]
    #[cfg(target_arch = "x86_64")]
    fn simd_sums_are_the_general_loops_bits() {
        use super::super::micro::{at_level, param_sums as simd_param_sums, stats_sums as simd_stats_sums};
        for level in super::super::simd::supported() {
            for &(n, c) in &[(1005, 37), (64, 16), (33, 3)] {
                let mut x: Vec<f32> = (0..n * c).map(|i| ((i * 7919 % 1000) as f32 - 400.0) / 300.0).collect();
                let g: Vec<f32> = (0..n * c).map(|i| ((i * 104729 % 997) as f32 - 500.0) / 500.0).collect();
                let shift = x[..c].to_vec();
                let simd = at_level!(level, |V| simd_stats_sums::<V>(&x, c, &shift));
                assert!(simd == stats_sums(&x, c, &lane_groups(&shift)), "{level:?} channel sums, {n} × {c}");
                let stats = channel_stats(&x, c);
                x[n * c / 2] = f32::NAN;
                let (a, b): (Vec<f32>, Vec<f32>) = (0..c).map(|j| (0.5 + j as f32 * 0.1, j as f32 * 0.05 - 0.3)).unzip();
                let lanes = [lane_groups(&a), lane_groups(&b), lane_groups(&stats[..c])];
                for relu in [true, false] {
                    let simd = at_level!(level, |V| simd_param_sums::<V>(&x, &g, c, &a, &b, &stats[..c], relu));
                    let general = param_sums(&x, &g, c, &lanes, relu);
                    // NaN ≠ NaN: compare the bits.
                    let bits = |v: &[f64]| v.iter().map(|f| f.to_bits()).collect::<Vec<_>>();
                    assert!(bits(&simd) == bits(&general), "{level:?} parameter sums, {n} × {c}, ReLU {relu}");
                }
            }
        }
    }

    /// Any chunking of rows over threads gives the same bits.
    #[test]
    fn same_bits_at_one_and_two_threads() {
        let c = 7;
        let x: Vec<f32> = (0..c * 5000).map(|i| ((i * 7919 % 1000) as f32 - 400.0) / 300.0).collect();
        let g: Vec<f32> = (0..c * 5000).map(|i| ((i * 104729 % 997) as f32 - 500.0) / 500.0).collect();
        let gamma: Vec<f32> = (0..c).map(|j| 0.5 + j as f32 * 0.1).collect();
        let beta: Vec<f32> = (0..c).map(|j| j as f32 * 0.05 - 0.1).collect();
        let run = || {
            let stats = channel_stats(&x, c);
            let y = normalize(&x, &stats, &gamma, &beta, 1e-5, true);
            let p = param_grads(&x, &g, &stats, &gamma, &beta, 1e-5, true);
            let dx = input_grad(&x, &g, &stats, &gamma, &beta, &p, 1e-5, true, true);
            (stats, y, p, dx)
        };
        let one = rayon::ThreadPoolBuilder::new().num_threads(1).build().unwrap().install(run);
        let two = rayon::ThreadPoolBuilder::new().num_threads(2).build().unwrap().install(run);
        assert!(one == two);
    }
}
