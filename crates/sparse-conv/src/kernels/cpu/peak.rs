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

/// Multiply-adds per chain and thread in one timed call: some 40–90 ms on the cores we target.
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
    let lanes: usize = at_level!(level, |V| V::LANES);
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

/// The chains' factor and addend: each chain decays slowly towards `B / (1 − M)`, staying a
/// normal float.
const M: f32 = 0.999_999_9;
const B: f32 = 1.0e-7;

/// Chain `i`'s start.
fn start(i: usize) -> f32 {
    i as f32 * 1.0e-3
}

/// `CHAINS` accumulators, each `a ← a·m + b` `iterations` times from a start the compiler cannot
/// see (so no two chains can be merged); returns the sum of every lane of every chain, so that
/// none is dead code.
///
/// # Safety
/// `V`'s instructions.
#[inline(always)]
pub(super) unsafe fn fma_chains<V: Simd>(iterations: usize) -> f32 {
    unsafe {
        let (m, b) = (V::splat(&M), V::splat(&B));
        let starts: [f32; CHAINS] = std::hint::black_box(std::array::from_fn(start));
        let mut acc = starts.map(|s| V::splat(&s));
        for _ in 0..iterations {
            for a in &mut acc {
                *a = V::fmadd(*a, m, b);
            }
        }
        let sum = acc.iter().fold(V::zero(), |s, &a| V::add(s, a));
        V::to_array(sum)[..V::LANES].iter().sum()
    }
}

#[cfg(all(test, target_arch = "x86_64"))]
mod tests {
    use super::*;

    /// After n steps chain i is mⁿ·sᵢ + b·(1 − mⁿ)/(1 − m) in every lane: the loop ran every
    /// step on every chain and lane and kept its sums. f32 rounding moves the sum by a few parts
    /// in 10⁴; a missing lane or chain moves it by 6 % or more, 1 % fewer steps by about 1 %.
    #[test]
    fn chains_compute_their_recurrence() {
        let n = 200_000;
        let (m, b) = (M as f64, B as f64);
        let chain = |i: usize| m.powi(n) * start(i) as f64 + b * (1.0 - m.powi(n)) / (1.0 - m);
        let per_lane: f64 = (0..CHAINS).map(chain).sum();
        for level in super::super::simd::supported() {
            let lanes: usize = at_level!(level, |V| V::LANES);
            let sum = at_level!(level, |V| unsafe { V::fma_chains(n as usize) }) as f64;
            let want = lanes as f64 * per_lane;
            assert!((sum - want).abs() < 1e-3 * want, "{level:?}: {sum}, want {want}");
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
