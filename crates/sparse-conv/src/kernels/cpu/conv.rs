//! The sparse convolution written once, over plain slices: forward, feature gradient, weight
//! gradient. Every CPU backend calls these; the GPU path computes the same sums.
//!
//! Determinism: every output row sums its offsets in one fixed order, and the weight gradient's
//! partial sums are cut at sizes that depend only on the problem, never on the number of threads,
//! so results are bit-identical at any thread count (no atomics, no two tasks writing one row).

use rayon::prelude::*;

use super::element::{Element, GRAD_CHUNK, PairDirection, RowEpilogue, filled_in_chunks, scratch};
use crate::parallel::SyncPtr;
use super::norm::ConvEpilogue;
use crate::geometry::kernel_map::OffsetPairs;

/// Largest `m·k + k·n` of one GEMM call that matrixmultiply 0.3 runs on the calling thread: from
/// `2^15` on (its `threading.rs` heuristic, with the `threading` feature Burn turns on) it spreads
/// the product over threads of its own, which inside our rayon tasks oversubscribes the cores
/// (measured: the weight gradient 5× slower). [`serial_gemm`] cuts products below it.
const SERIAL_GEMM_SIZE: usize = (1 << 15) - 1;

/// `C = A·B + beta·C` (strided, as [`Element::gemm`]) on the calling thread only: cut along `k`
/// (accumulating) and `m` into calls below [`SERIAL_GEMM_SIZE`]. The cut depends only on the
/// shape, so the summation order, and the result, are the same at any thread count.
///
/// # Safety
/// As [`Element::gemm`].
#[allow(clippy::too_many_arguments)]
pub(crate) unsafe fn serial_gemm<T: Element>(
    m: usize, k: usize, n: usize,
    a: *const T, rsa: isize, csa: isize,
    b: *const T, rsb: isize, csb: isize,
    beta: T, c: *mut T, rsc: isize, csc: isize,
) {
    // matrixmultiply works on k in blocks of 256 anyway. Keep all m rows in one call down to
    // k = 64, then cut m into equal pieces (never a thin remainder).
    let rows_for = |kt: usize| (SERIAL_GEMM_SIZE / kt).saturating_sub(n);
    let mut kt = k.clamp(1, 256);
    while kt > 64 && rows_for(kt) < m {
        kt /= 2;
    }
    while kt > 8 && rows_for(kt) < m.min(16) {
        kt /= 2;
    }
    let pieces = m.div_ceil(rows_for(kt).max(1)).max(1);
    let mt = m.div_ceil(pieces).max(1);
    for k0 in (0..k).step_by(kt) {
        let kk = kt.min(k - k0);
        let beta = if k0 == 0 { beta } else { T::ONE };
        for m0 in (0..m).step_by(mt) {
            let mm = mt.min(m - m0);
            unsafe {
                T::gemm(
                    mm, kk, n,
                    a.offset(m0 as isize * rsa + k0 as isize * csa), rsa, csa,
                    b.offset(k0 as isize * rsb), rsb, csb,
                    beta, c.offset(m0 as isize * rsc), rsc, csc,
                );
            }
        }
    }
    if k == 0 {
        // matrixmultiply scales C by beta for an empty k; keep that contract.
        unsafe { T::gemm(m, 0, n, a, rsa, csa, b, rsb, csb, beta, c, rsc, csc) };
    }
}

/// The weight gradient's pairs cut into chunks of at most [`GRAD_CHUNK`], `(offset, start, end)`,
/// listed offset by offset; `first_chunk[k]..first_chunk[k + 1]` are offset k's. The cut depends
/// only on the map, which keeps the partial sums, and the result, independent of the threads.
pub(crate) fn grad_chunks(pairs: &OffsetPairs) -> (Vec<(usize, usize, usize)>, Vec<usize>) {
    let volume = pairs.start.len() - 1;
    let mut chunks = Vec::new();
    let mut first_chunk = Vec::with_capacity(volume + 1);
    for k in 0..volume {
        first_chunk.push(chunks.len());
        let (s, e) = (pairs.start[k], pairs.start[k + 1]);
        chunks.extend((s..e).step_by(GRAD_CHUNK).map(|a| (k, a, (a + GRAD_CHUNK).min(e))));
    }
    first_chunk.push(chunks.len());
    (chunks, first_chunk)
}

/// `dW_k = Σ_{(i, o) ∈ M_k} x[i]ᵀ · g[o]`, as `[K, C_in, C_out]`.
///
/// Each offset's pairs are cut into fixed chunks whose partial products are summed in chunk order;
/// the `identity` offset (pairs `(r, r)` in row order) reads its rows without a gather.
pub fn weight_grad<T: Element>(
    x: &[T],
    c_in: usize,
    grad_out: &[T],
    c_out: usize,
    pairs: &OffsetPairs,
    identity: Option<usize>,
) -> Vec<T> {
    if let Some(grad) = T::weight_grad_native(x, c_in, grad_out, c_out, pairs) {
        return grad;
    }
    let volume = pairs.start.len() - 1;
    let block = c_in * c_out;
    let (chunks, first_chunk) = grad_chunks(pairs);
    let mut partials = vec![T::ZERO; chunks.len() * block];
    if block > 0 {
        partials.par_chunks_mut(block).zip(chunks.par_iter()).for_each_init(
            || (vec![T::ZERO; GRAD_CHUNK * c_in], vec![T::ZERO; GRAD_CHUNK * c_out]),
            |(xs, gs), (partial, &(k, a, b))| {
                let m = b - a;
                if Some(k) == identity {
                    // The centre pairs are (r, r) for r = 0.. in order: read the rows in place.
                    let r = a - pairs.start[k];
                    unsafe {
                        serial_gemm(c_in, m, c_out, x[r * c_in..].as_ptr(), 1, c_in as isize, grad_out[r * c_out..].as_ptr(), c_out as isize, 1, T::ZERO, partial.as_mut_ptr(), c_out as isize, 1);
                    }
                    return;
                }
                for (j, p) in (a..b).enumerate() {
                    let i = pairs.input[p] as usize;
                    let o = pairs.output[p] as usize;
                    xs[j * c_in..(j + 1) * c_in].copy_from_slice(&x[i * c_in..(i + 1) * c_in]);
                    gs[j * c_out..(j + 1) * c_out].copy_from_slice(&grad_out[o * c_out..(o + 1) * c_out]);
                }
                // (c_in × m) · (m × c_out): the gathered inputs read transposed through strides.
                unsafe {
                    serial_gemm(c_in, m, c_out, xs.as_ptr(), 1, c_in as isize, gs.as_ptr(), c_out as isize, 1, T::ZERO, partial.as_mut_ptr(), c_out as isize, 1);
                }
            },
        );
    }
    let mut grad = vec![T::ZERO; volume * block];
    if block > 0 {
        grad.par_chunks_mut(block).enumerate().for_each(|(k, dst)| {
            for partial in partials[first_chunk[k] * block..first_chunk[k + 1] * block].chunks_exact(block) {
                for (d, &p) in dst.iter_mut().zip(partial) {
                    *d += p;
                }
            }
        });
    }
    grad
}

/// Rows per GEMM of the offset-major kernel.
const CHUNK_ROWS: usize = 256;

/// Offset-major gather–GEMM–scatter: for each offset in a fixed order, its pairs in chunks of
/// [`CHUNK_ROWS`] (gather rows, one GEMM with `W_k`, add the products to their destination rows).
///
/// Within one offset every destination row appears at most once, so chunks of an offset run in
/// parallel without conflicts, and each row sums its offsets in the same order at any thread
/// count. `identity` names an offset whose pairs are `(r, r)` for every row (the submanifold
/// centre): it runs first as a plain GEMM that initialises the output. Pairs ordered by
/// destination row within each offset ([`crate::KernelMap::pairs`] forward,
/// [`crate::KernelMap::pairs_by_input`] backward) let the AVX-512 kernel run by destination
/// blocks; any order gives the same result. `epilogue` (inference: the batch norm after the
/// conv, with its ReLU or residual) runs on the finished rows.
#[allow(clippy::too_many_arguments)]
pub fn pair_conv<T: Element>(
    src: &[T],
    c_src: usize,
    weight: &[T],
    c_dst: usize,
    n_dst: usize,
    direction: PairDirection,
    pairs: &OffsetPairs,
    identity: Option<usize>,
    epilogue: Option<&ConvEpilogue<'_, T>>,
) -> Vec<T> {
    if let Some(e) = epilogue {
        assert_eq!(e.channels(), c_dst, "the epilogue's channels differ from the conv's output");
    }
    if let Some(out) = T::pair_conv_native(src, c_src, weight, c_dst, n_dst, direction, pairs, identity, epilogue.map(|e| e as &dyn RowEpilogue<T>)) {
        return out;
    }
    let volume = pairs.start.len() - 1;
    assert_eq!(weight.len(), volume * c_src * c_dst, "weight does not match the map and channels");
    if n_dst == 0 || c_dst == 0 {
        return vec![T::ZERO; n_dst * c_dst];
    }
    if let Some(k) = identity {
        assert_eq!(pairs.start[k + 1] - pairs.start[k], n_dst, "the identity offset must pair every row with itself");
        // Every output row is then written by the centre GEMM below (the output is not zeroed).
        assert!(src.len() >= n_dst * c_src, "the identity offset reads {n_dst} source rows, the source has fewer");
    }
    // Forward reads W_k (c_in × c_out) as stored; backward reads W_kᵀ.
    let (rsb, csb) = match direction {
        PairDirection::Forward => (c_dst as isize, 1),
        PairDirection::Backward => (1, c_src as isize),
    };
    let (gather_side, scatter_side) = match direction {
        PairDirection::Forward => (&pairs.input, &pairs.output),
        PairDirection::Backward => (&pairs.output, &pairs.input),
    };
    let mut out = match identity {
        // The centre's GEMM (beta = 0) writes every output row without reading it, so the
        // output is not zeroed first (a whole pass over it, and its page faults, saved).
        Some(k) if c_src > 0 => {
            let w = &weight[k * c_src * c_dst..];
            // The identity offset has n_dst pairs (asserted): its chunks write every row.
            filled_in_chunks(n_dst * c_dst, CHUNK_ROWS * c_dst, |chunk, dst| {
                let m = dst.len() / c_dst;
                let rows = &src[chunk * CHUNK_ROWS * c_src..][..m * c_src];
                // SAFETY: matrixmultiply writes C without reading it when beta is zero.
                unsafe {
                    serial_gemm(m, c_src, c_dst, rows.as_ptr(), c_src as isize, 1, w.as_ptr(), rsb, csb, T::ZERO, dst.as_mut_ptr().cast::<T>(), c_dst as isize, 1);
                }
            })
        }
        _ => vec![T::ZERO; n_dst * c_dst],
    };
    let out_ptr = SyncPtr(out.as_mut_ptr());
    for k in (0..volume).filter(|&k| Some(k) != identity) {
        let (s, e) = (pairs.start[k], pairs.start[k + 1]);
        if s == e {
            continue;
        }
        let w = &weight[k * c_src * c_dst..];
        let out_ptr = &out_ptr;
        let chunks = (e - s).div_ceil(CHUNK_ROWS);
        (0..chunks).into_par_iter().for_each_init(
            // Scratch that is written before it is read: rayon may call this once per split, so
            // zeroing it would be a pass over it each time for nothing.
            || (scratch::<T>(CHUNK_ROWS * c_src), scratch::<T>(CHUNK_ROWS * c_dst)),
            |(gathered, product), chunk| {
                let a = s + chunk * CHUNK_ROWS;
                let b = (a + CHUNK_ROWS).min(e);
                let m = b - a;
                let (gathered, product) = (gathered.as_mut_ptr().cast::<T>(), product.as_mut_ptr().cast::<T>());
                for (j, &r) in gather_side[a..b].iter().enumerate() {
                    // SAFETY: row r of the source and row j < CHUNK_ROWS of the scratch.
                    unsafe { std::ptr::copy_nonoverlapping(src.as_ptr().add(r as usize * c_src), gathered.add(j * c_src), c_src) };
                }
                // SAFETY: the m gathered rows were written above; with beta = 0 the product is
                // written, not read.
                unsafe {
                    serial_gemm(m, c_src, c_dst, gathered, c_src as isize, 1, w.as_ptr(), rsb, csb, T::ZERO, product, c_dst as isize, 1);
                }
                for (j, &r) in scatter_side[a..b].iter().enumerate() {
                    // SAFETY: within offset k each destination row appears once, so no two tasks
                    // touch the same row; offsets run one after another. Product row j < m was
                    // written by the GEMM.
                    let (dst, product) = unsafe {
                        (std::slice::from_raw_parts_mut(out_ptr.0.add(r as usize * c_dst), c_dst), std::slice::from_raw_parts(product.add(j * c_dst), c_dst))
                    };
                    for (d, &p) in dst.iter_mut().zip(product) {
                        *d += p;
                    }
                }
            },
        );
    }
    if let Some(e) = epilogue {
        e.apply_all(&mut out);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The cut product equals a naive triple loop, for shapes that cut k, m or both, with strided
    /// (transposed) operands and an accumulating beta.
    #[test]
    fn serial_gemm_matches_a_naive_product() {
        for &(m, k, n) in &[(5, 3, 4), (32, 2048, 32), (256, 128, 128), (700, 600, 300), (1, 1000, 900), (64, 0, 8)] {
            let a: Vec<f64> = (0..m * k).map(|i| ((i * 37 % 101) as f64 - 50.0) / 50.0).collect();
            let b: Vec<f64> = (0..k * n).map(|i| ((i * 53 % 97) as f64 - 48.0) / 48.0).collect();
            let c0: Vec<f64> = (0..m * n).map(|i| (i % 7) as f64).collect();
            // A is read transposed: stored k×m.
            let at: Vec<f64> = (0..k * m).map(|i| a[(i % m) * k + i / m]).collect();
            let mut c = c0.clone();
            unsafe { serial_gemm(m, k, n, at.as_ptr(), 1, m as isize, b.as_ptr(), n as isize, 1, 0.5, c.as_mut_ptr(), n as isize, 1) };
            for i in 0..m {
                for j in 0..n {
                    let want = 0.5 * c0[i * n + j] + (0..k).map(|l| a[i * k + l] * b[l * n + j]).sum::<f64>();
                    assert!((c[i * n + j] - want).abs() < 1e-9, "({m}, {k}, {n}) at ({i}, {j}): {} vs {want}", c[i * n + j]);
                }
            }
        }
    }
}
