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

use crate::cpu::GRAD_CHUNK;
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

/// `out[i][j] += Σ_p x[p][i] · g[p][j]` for `R` rows `i0..i0 + R` and the `cols` (≤ 32) columns
/// from `j0`, over the pairs' rows `xs[p]`, `gs[p]`.
///
/// # Safety
/// AVX-512F; `xs[p]` readable up to `i0 + R`, `gs[p]` up to `j0 + cols`, `out` rows of `ld`
/// floats writable at `i0.., j0..`.
// The register tile is indexed by constant-bounded loops that unroll into registers.
#[allow(clippy::needless_range_loop)]
#[target_feature(enable = "avx512f")]
unsafe fn pair_outer_products<const R: usize>(xs: &[*const f32], gs: &[*const f32], i0: usize, j0: usize, cols: usize, out: *mut f32, ld: usize) {
    unsafe {
        let (m0, m1) = (mask(cols, 0), mask(cols, 1));
        let mut acc = [[_mm512_setzero_ps(); 2]; R];
        for (r, acc) in acc.iter_mut().enumerate() {
            let o = out.add((i0 + r) * ld + j0);
            *acc = [_mm512_maskz_loadu_ps(m0, o), _mm512_maskz_loadu_ps(m1, o.add(16))];
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
    let mut grad = vec![0.0f32; volume * block];
    if block == 0 {
        return grad;
    }
    // Chunks are listed offset by offset; `first_chunk[k]..first_chunk[k + 1]` are offset k's.
    let mut chunks = Vec::new();
    let mut first_chunk = Vec::with_capacity(volume + 1);
    for k in 0..volume {
        first_chunk.push(chunks.len());
        chunks.extend((pairs.start[k]..pairs.start[k + 1]).step_by(GRAD_CHUNK).map(|a| (a, (a + GRAD_CHUNK).min(pairs.start[k + 1]))));
    }
    first_chunk.push(chunks.len());
    let mut partials = vec![0.0f32; chunks.len() * block];
    partials.par_chunks_mut(block).zip(chunks.par_iter()).for_each(|(partial, &(a, b))| {
        let xs: Vec<*const f32> = pairs.input[a..b].iter().map(|&i| unsafe { x.as_ptr().add(i as usize * c_in) }).collect();
        let gs: Vec<*const f32> = pairs.output[a..b].iter().map(|&o| unsafe { grad_out.as_ptr().add(o as usize * c_out) }).collect();
        // Blocks of pairs whose rows stay in L1 while every tile of the partial passes over them;
        // each tile's sums go on in pair order, so the blocking does not change the result.
        for (xs, gs) in xs.chunks(PAIR_BLOCK).zip(gs.chunks(PAIR_BLOCK)) {
            for i0 in (0..c_in).step_by(MR) {
                for j0 in (0..c_out).step_by(NR) {
                    let cols = NR.min(c_out - j0);
                    macro_rules! rows {
                        ($($r:literal)*) => {
                            match MR.min(c_in - i0) {
                                // SAFETY: rows and columns stay inside x, grad_out and the partial.
                                $($r => unsafe { pair_outer_products::<$r>(&xs, &gs, i0, j0, cols, partial.as_mut_ptr(), c_out) },)*
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
        for partial in partials[first_chunk[k] * block..first_chunk[k + 1] * block].chunks_exact(block) {
            for (d, &p) in dst.iter_mut().zip(partial) {
                *d += p;
            }
        }
    });
    grad
}
