//! The weight gradient's f32 kernel for x86-64 CPUs with AVX-512: its micro-kernel reads each
//! pair's input and output-gradient rows in place, through the kernel map, and accumulates the
//! outer products in registers. The general path ([`crate::cpu::weight_grad`]) gathers both rows
//! into tiles and lets matrixmultiply pack the tiles again before multiplying.
//!
//! (The forward and feature gradient stay on the general path: a micro-kernel reading their
//! rows in place was measured slower from 64 channels on, its scattered first reads stalling
//! the FMAs where the general path's gather copies stream.)
//!
//! Same sums as the general path, cut at the same fixed pair counts, so results are
//! bit-identical at any thread count (they differ from the general path's in the last bits:
//! each partial sums its pairs in another order).

use std::arch::x86_64::*;
use std::sync::OnceLock;

use rayon::prelude::*;

use crate::cpu::{SyncPtr, grad_chunks, scratch};
use crate::kernel_map::OffsetPairs;

/// Columns per tile: two 16-lane vectors.
const NR: usize = 32;
/// Rows per tile: 12 × 2 accumulators, 2 gradient vectors and a broadcast fit the 32 vector
/// registers.
const MR: usize = 12;
/// Pairs per block: their rows stay in L1 while every tile of the partial passes over them.
const PAIR_BLOCK: usize = 32;

/// Whether this kernel runs: the CPU has AVX-512F and `PMUNET_AVX512` is not `0` (which
/// selects the general path, for comparisons).
pub fn available() -> bool {
    static AVAILABLE: OnceLock<bool> = OnceLock::new();
    *AVAILABLE.get_or_init(|| std::arch::is_x86_feature_detected!("avx512f") && std::env::var("PMUNET_AVX512").map_or(true, |v| v != "0"))
}

/// Lane mask of vector `v` of a tile whose first `cols` columns are real.
fn mask(cols: usize, v: usize) -> __mmask16 {
    let c = cols.saturating_sub(16 * v);
    if c >= 16 { 0xFFFF } else { ((1u32 << c) - 1) as u16 }
}

/// `out[i][j] (+)= Σ_p x[p][i] · g[p][j]` for `R` rows `i0..i0 + R` and the `cols` (≤ 32)
/// columns from `j0`, over the pairs' rows `xs[p]`, `gs[p]`; with `accumulate` false `out` is
/// written without being read.
///
/// # Safety
/// AVX-512F; `xs[p]` readable up to `i0 + R`, `gs[p]` up to `j0 + cols`, `out` rows of `ld`
/// floats writable (and, to accumulate, initialised) at `i0.., j0..`.
// The register tile is indexed by constant-bounded loops that unroll into registers.
#[allow(clippy::needless_range_loop)]
#[target_feature(enable = "avx512f")]
#[allow(clippy::too_many_arguments)]
unsafe fn pair_outer_products<const R: usize>(
    xs: &[*const f32],
    gs: &[*const f32],
    i0: usize,
    j0: usize,
    cols: usize,
    out: *mut f32,
    ld: usize,
    accumulate: bool,
) {
    unsafe {
        let (m0, m1) = (mask(cols, 0), mask(cols, 1));
        let mut acc = [[_mm512_setzero_ps(); 2]; R];
        if accumulate {
            for (r, acc) in acc.iter_mut().enumerate() {
                let o = out.add((i0 + r) * ld + j0);
                *acc = [_mm512_maskz_loadu_ps(m0, o), _mm512_maskz_loadu_ps(m1, o.add(16))];
            }
        }
        for (&x, &g) in xs.iter().zip(gs) {
            let g = g.add(j0);
            let b0 = _mm512_maskz_loadu_ps(m0, g);
            let b1 = _mm512_maskz_loadu_ps(m1, g.add(16));
            let x = x.add(i0);
            for r in 0..R {
                let a = _mm512_set1_ps(*x.add(r));
                acc[r][0] = _mm512_fmadd_ps(a, b0, acc[r][0]);
                acc[r][1] = _mm512_fmadd_ps(a, b1, acc[r][1]);
            }
        }
        for (r, acc) in acc.iter().enumerate() {
            let o = out.add((i0 + r) * ld + j0);
            _mm512_mask_storeu_ps(o, m0, acc[0]);
            _mm512_mask_storeu_ps(o.add(16), m1, acc[1]);
        }
    }
}

/// [`crate::cpu::weight_grad`] for f32 on AVX-512; same arguments and result.
pub fn weight_grad(x: &[f32], c_in: usize, grad_out: &[f32], c_out: usize, pairs: &OffsetPairs) -> Vec<f32> {
    assert!(available(), "AVX-512F kernels called on a CPU without AVX-512F");
    let volume = pairs.start.len() - 1;
    let block = c_in * c_out;
    if block == 0 {
        return Vec::new();
    }
    // Each offset's pairs in fixed chunks. An offset's first chunk writes its block of the result
    // directly, each other chunk a partial of its own, added after in chunk order: the same sums
    // as zero plus every partial, without zeroing the result or copying into it.
    let (chunks, first_chunk) = grad_chunks(pairs);
    // Partial slot of each chunk that is not its offset's first.
    let mut slots = vec![None; chunks.len()];
    let mut partials_len = 0;
    for (i, &(k, _, _)) in chunks.iter().enumerate() {
        if i != first_chunk[k] {
            slots[i] = Some(partials_len);
            partials_len += 1;
        }
    }
    let mut grad = scratch::<f32>(volume * block);
    let mut partials = scratch::<f32>(partials_len * block);
    let (grad_ptr, partials_ptr) = (SyncPtr(grad.as_mut_ptr().cast::<f32>()), SyncPtr(partials.as_mut_ptr().cast::<f32>()));
    let (grad_ptr, partials_ptr) = (&grad_ptr, &partials_ptr);
    chunks.par_iter().zip(&slots).for_each(|(&(k, a, b), slot)| {
        // SAFETY: each chunk writes a block no other chunk writes: its offset's block of the
        // result (the first chunk) or its own partial slot.
        let out = unsafe {
            match slot {
                None => grad_ptr.0.add(k * block),
                Some(slot) => partials_ptr.0.add(slot * block),
            }
        };
        let xs: Vec<*const f32> = pairs.input[a..b].iter().map(|&i| unsafe { x.as_ptr().add(i as usize * c_in) }).collect();
        let gs: Vec<*const f32> = pairs.output[a..b].iter().map(|&o| unsafe { grad_out.as_ptr().add(o as usize * c_out) }).collect();
        // Blocks of pairs whose rows stay in L1 while every tile of the block passes over them;
        // each tile's sums go on in pair order, so the blocking does not change the result.
        for (block_index, (xs, gs)) in xs.chunks(PAIR_BLOCK).zip(gs.chunks(PAIR_BLOCK)).enumerate() {
            for i0 in (0..c_in).step_by(MR) {
                for j0 in (0..c_out).step_by(NR) {
                    let cols = NR.min(c_out - j0);
                    macro_rules! rows {
                        ($($r:literal)*) => {
                            match MR.min(c_in - i0) {
                                // SAFETY: rows and columns stay inside x, grad_out and the block;
                                // the first pair block writes every element before any is read.
                                $($r => unsafe { pair_outer_products::<$r>(&xs, &gs, i0, j0, cols, out, c_out, block_index > 0) },)*
                                _ => unreachable!(),
                            }
                        };
                    }
                    rows!(1 2 3 4 5 6 7 8 9 10 11 12);
                }
            }
        }
    });
    grad.par_chunks_mut(block).enumerate().for_each(|(k, dst)| {
        let offset_chunks = first_chunk[k]..first_chunk[k + 1];
        if offset_chunks.is_empty() {
            dst.iter_mut().for_each(|v| {
                v.write(0.0);
            });
            return;
        }
        // SAFETY: the offset's first chunk wrote this block.
        let dst = unsafe { std::slice::from_raw_parts_mut(dst.as_mut_ptr().cast::<f32>(), block) };
        for slot in slots[offset_chunks].iter().filter_map(|s| *s) {
            // SAFETY: the chunk of this slot wrote it.
            let partial = unsafe { std::slice::from_raw_parts(partials.as_ptr().cast::<f32>().add(slot * block), block) };
            for (d, &p) in dst.iter_mut().zip(partial) {
                *d += p;
            }
        }
    });
    // SAFETY: every block was written, by its offset's first chunk or the zero fill above;
    // MaybeUninit<f32> has f32's layout.
    let mut grad = std::mem::ManuallyDrop::new(grad);
    unsafe { Vec::from_raw_parts(grad.as_mut_ptr().cast::<f32>(), grad.len(), grad.capacity()) }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cpu::GRAD_CHUNK;

    /// Against a naive f64 sum, on offsets of several chunks (the partials path), none (zeros)
    /// and a few pairs, with channel counts that leave partial row and column tiles; and the same
    /// bits at one and two threads.
    #[test]
    fn weight_grad_matches_a_naive_sum() {
        if !available() {
            return;
        }
        let (c_in, c_out, n) = (13, 37, 700);
        let counts = [2 * GRAD_CHUNK + 300, 0, 100, GRAD_CHUNK];
        let mut pairs = OffsetPairs { start: vec![0], input: Vec::new(), output: Vec::new() };
        for (k, &count) in counts.iter().enumerate() {
            for p in 0..count {
                pairs.input.push(((p * 7 + k) % n) as u32);
                pairs.output.push(((p * 13 + 3 * k) % n) as u32);
            }
            pairs.start.push(pairs.input.len());
        }
        let x: Vec<f32> = (0..n * c_in).map(|i| ((i * 37 % 101) as f32 - 50.0) / 50.0).collect();
        let g: Vec<f32> = (0..n * c_out).map(|i| ((i * 53 % 97) as f32 - 48.0) / 48.0).collect();
        let run = || weight_grad(&x, c_in, &g, c_out, &pairs);
        let one = rayon::ThreadPoolBuilder::new().num_threads(1).build().unwrap().install(run);
        let two = rayon::ThreadPoolBuilder::new().num_threads(2).build().unwrap().install(run);
        assert!(one == two, "the weight gradient depends on the thread count");
        for k in 0..counts.len() {
            for i in 0..c_in {
                for j in 0..c_out {
                    let want: f64 = (pairs.start[k]..pairs.start[k + 1])
                        .map(|p| x[pairs.input[p] as usize * c_in + i] as f64 * g[pairs.output[p] as usize * c_out + j] as f64)
                        .sum();
                    let got = one[(k * c_in + i) * c_out + j] as f64;
                    assert!((got - want).abs() <= 1e-4 * (1.0 + want.abs()), "offset {k} ({i}, {j}): {got} vs {want}");
                }
            }
        }
    }
}
