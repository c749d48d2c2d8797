//! The cores' f32 multiply-add peak at the width the op's kernels run: chains of fused
//! multiply-adds on registers alone, on every rayon thread at once. No kernel on these cores can
//! pass it, so the benchmarks give it beside the dense SGEMM ceiling: the SGEMM says what a GEMM
//! reaches, the peak what the cores allow.

use std::time::Instant;

use super::micro::{TileKernels, at_level};
use super::simd::{Level, Simd, level};

/// Independent accumulators: more than FMA latency × FMA pipes on the cores we target (4 × 2
/// on Zen 4 and on Intel's client and server cores), so the chains never wait on each other.
const CHAINS: usize = 12;

/// Multiply-adds per chain and thread in one timed call: about 0.1 s at 3 GHz.
const ITERATIONS: usize = 25_000_000;

/// Timed calls; the fastest counts (the first may run before the cores reach their clock).
const CALLS: usize = 3;

/// The f32 GFLOP/s (2 per multiply-add) of [`CHAINS`] register chains on every rayon thread at
/// once, at the vector width of the kernels' current instruction set; `None` where the kernels
/// take the general path (no SIMD micro-kernels to set against it).
pub fn fma_peak_gflops() -> Option<f64> {
    peak_at(level(), ITERATIONS, CALLS)
}

/// [`fma_peak_gflops`] on `level`, with `iterations` per chain and the fastest of `calls`.
fn peak_at(level: Option<Level>, iterations: usize, calls: usize) -> Option<f64> {
    let level = level?;
    let lanes = at_level!(level, |V| V::LANES);
    let best = (0..calls.max(1))
        .map(|_| {
            let t = Instant::now();
            // SAFETY: `level()` chose an instruction set this CPU has.
            let sums = rayon::broadcast(|_| at_level!(level, |V| unsafe { V::fma_chains(iterations) }));
            std::hint::black_box(sums);
            t.elapsed().as_secs_f64()
        })
        .fold(f64::INFINITY, f64::min);
    let flops = 2.0 * (rayon::current_num_threads() * CHAINS * lanes * iterations) as f64;
    Some(flops / best / 1e9)
}

/// `CHAINS` accumulators, each `a ← a·m + b` `iterations` times; returns a lane of their sum so
/// that no chain is dead code.
///
/// # Safety
/// `V`'s instructions.
#[inline(always)]
pub(super) unsafe fn fma_chains<V: Simd>(iterations: usize) -> f32 {
    unsafe {
        let (m, b) = (V::splat(&0.999_999_9), V::splat(&1.0e-7));
        let mut acc = [V::zero(); CHAINS];
        for _ in 0..iterations {
            for a in &mut acc {
                *a = V::fmadd(*a, m, b);
            }
        }
        let sum = acc.iter().fold(V::zero(), |s, &a| V::add(s, a));
        V::to_array(sum)[0]
    }
}

#[cfg(all(test, target_arch = "x86_64"))]
mod tests {
    use super::*;

    /// Each chain converges on b / (1 − m) = 1: the loop ran and kept its sums.
    #[test]
    fn chains_compute_their_recurrence() {
        for level in super::super::simd::supported() {
            let sum = at_level!(level, |V| unsafe { V::fma_chains(200_000) });
            // 12 chains, each 1 − 0.9999999^200000 ≈ 0.0198 (from 0).
            let one = 1.0 - 0.999_999_9f64.powi(200_000);
            assert!((sum as f64 - 12.0 * one).abs() < 1e-3, "{level:?}: {sum}");
        }
    }

    #[test]
    fn peak_is_a_rate_on_simd_paths_and_none_on_the_general_one() {
        assert_eq!(peak_at(None, 1000, 1), None);
        for level in super::super::simd::supported() {
            let gflops = peak_at(Some(level), 100_000, 1).expect("a SIMD level");
            assert!(gflops.is_finite() && gflops > 0.0, "{level:?}: {gflops}");
        }
    }
}
