//! Two ceilings for the benchmarks, at the width the op's kernels run: the cores' f32
//! multiply-add peak, and the rate of the op's own register tile when its data sits in cache. The
//! peak is chains of fused multiply-adds on registers alone, on every rayon thread at once: no
//! kernel on these cores can pass it. The cached tile runs the forward's micro-kernel over and
//! over on a few tiles' rows and one panel that stay in cache. The benchmarks give both beside the
//! dense SGEMM ceiling and the op's own rate: from the peak to the cached tile is what the
//! micro-kernel's own instructions cost, from the cached tile to the op everything else it does
//! (reaching the scene's rows, weight panels from L2, partial tiles, packing, scheduling).

use std::time::Instant;

use super::micro::{TileKernels, at_level, by_rows};
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
    // SAFETY: `level()` chose an instruction set this CPU has.
    let best = fastest_on_every_thread(calls, || at_level!(level, |V| unsafe { V::fma_chains(iterations) }));
    let flops = 2.0 * (rayon::current_num_threads() * CHAINS * lanes * iterations) as f64;
    Some(flops / best / 1e9)
}

/// Seconds of the fastest of `calls` runs of `work` on every rayon thread at once (the first run
/// may start before the cores reach their clock); the results are kept from the optimiser.
fn fastest_on_every_thread<T: Send>(calls: usize, work: impl Fn() -> T + Sync) -> f64 {
    (0..calls.max(1))
        .map(|_| {
            let t = Instant::now();
            std::hint::black_box(rayon::broadcast(|_| work()));
            t.elapsed().as_secs_f64()
        })
        .fold(f64::INFINITY, f64::min)
}

/// Multiply-adds per thread in one timed call of the cached tile: some 20–90 ms on the cores we
/// target.
const TILE_MULTIPLY_ADDS: usize = 2_000_000_000;

/// Row tiles the cached-tile loop cycles through, as the op's tiles follow one another.
const TILES: usize = 2;

/// Timed calls of the cached tile; the fastest counts. More than the peak's: a call is shorter,
/// so one pause of the machine more easily spans every call.
const TILE_CALLS: usize = 5;

/// The f32 GFLOP/s of the forward's register tile ([`Simd::MR`] rows of `columns` ≤ two
/// vectors) times a panel `depth` rows deep, added into its destination rows, on every rayon
/// thread at once, with its source rows, panel and destinations in cache (L1 while `TILES`
/// tiles' rows and a panel fit, L2 beyond): the op's rate without memory, to set the op's own
/// rate against. Flops count the real columns only. `None` where the kernels take the general
/// path, or `depth` or `columns` is 0.
pub fn cached_tile_gflops(depth: usize, columns: usize) -> Option<f64> {
    cached_tile_rate_at(level(), depth, columns, TILE_MULTIPLY_ADDS, TILE_CALLS)
}

/// [`cached_tile_gflops`] on `level`, with some `multiply_adds` per thread and call, the fastest
/// of `calls`.
fn cached_tile_rate_at(level: Option<Level>, depth: usize, columns: usize, multiply_adds: usize, calls: usize) -> Option<f64> {
    let level = level?;
    if depth == 0 || columns == 0 {
        return None;
    }
    let (lanes, mr): (usize, usize) = at_level!(level, |V| (V::LANES, V::MR));
    let columns = columns.min(2 * lanes);
    // The kernel runs full-width FMAs whatever the real columns: size the calls by them, so that
    // a timed call takes the same time at any width, and count the real columns' flops.
    let tile_calls = (multiply_adds / (mr * 2 * lanes * depth)).max(TILES);
    let per_tile = mr * columns * depth;
    // SAFETY: `level()` chose an instruction set this CPU has.
    let best = fastest_on_every_thread(calls, || at_level!(level, |V| unsafe { cached_tiles::<V>(depth, columns, tile_calls) }));
    let flops = 2.0 * (rayon::current_num_threads() * tile_calls * per_tile) as f64;
    Some(flops / best / 1e9)
}

/// `calls` calls of the forward's in-place register tile ([`TileKernels::rows_times_panel`],
/// all `MR` rows, the first `columns` of two vectors), cycling through [`TILES`] tiles of rows
/// `depth` floats long, each adding into its own destination rows; returns the destination rows
/// (`TILES·MR` rows of two vectors, zero past `columns`), so that no call is dead code.
///
/// # Safety
/// `V`'s instructions.
unsafe fn cached_tiles<V: TileKernels>(depth: usize, columns: usize, calls: usize) -> Vec<f32> {
    assert!(V::available(), "{} called on a CPU without them", V::NAME);
    let (mr, nr) = (V::MR, 2 * V::LANES);
    let columns = columns.min(nr);
    // Small values: a call adds at most depth·24e-6 to an element, so a timing's calls (about
    // TILE_MULTIPLY_ADDS / (MR·2·LANES·depth) in all) add at most about 4,000 at any depth: far
    // inside f32's normal range.
    let rows: Vec<f32> = (0..TILES * mr * depth).map(|i| (i % 7) as f32 * 1.0e-3).collect();
    let panel: Vec<f32> = (0..depth * nr).map(|i| (i % 5) as f32 * 1.0e-3).collect();
    let mut out = vec![0.0f32; TILES * mr * nr];
    let sources: Vec<*const f32> = rows.chunks_exact(depth).map(<[f32]>::as_ptr).collect();
    let destinations: Vec<*mut f32> = out.chunks_exact_mut(nr).map(<[f32]>::as_mut_ptr).collect();
    by_rows!(mr, |R| {
        for call in 0..calls {
            let first_row = (call % TILES) * R;
            let tile = first_row..first_row + R;
            // SAFETY: each source row holds `depth` floats, the panel `depth` rows of two
            // vectors, each destination two vectors.
            unsafe { V::rows_times_panel::<R>(&sources[tile.clone()], depth, panel.as_ptr(), &destinations[tile], columns, true) };
        }
    });
    out
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

    /// Element (r, j) of tile t ends as (calls of t) · Σ_kk row_r[kk] · panel[kk][j] for the
    /// first `columns` j, and zero past them: every call ran, on its own tile's rows, added into
    /// its own destination rows, and wrote no column past the real ones.
    #[test]
    fn cached_tiles_add_every_call_into_their_own_rows() {
        let (depth, calls) = (37, 5);
        for level in super::super::simd::supported() {
            let (mr, nr): (usize, usize) = at_level!(level, |V| (V::MR, 2 * V::LANES));
            // Full width; a partial second vector; a partial first one (nothing stored from the
            // second); more than two vectors (clamped to two).
            for columns in [nr, nr - 3, nr / 2 - 3, nr + 5] {
                let row = |r: usize, kk: usize| ((r * depth + kk) % 7) as f64 * 1.0e-3;
                let panel = |kk: usize, j: usize| ((kk * nr + j) % 5) as f64 * 1.0e-3;
                let out = at_level!(level, |V| unsafe { cached_tiles::<V>(depth, columns, calls) });
                assert_eq!(out.len(), TILES * mr * nr);
                for r in 0..TILES * mr {
                    let tile_calls = (calls + TILES - 1 - r / mr) / TILES;
                    for j in 0..nr {
                        let want = if j < columns { tile_calls as f64 * (0..depth).map(|kk| row(r, kk) * panel(kk, j)).sum::<f64>() } else { 0.0 };
                        let got = out[r * nr + j] as f64;
                        assert!((got - want).abs() <= 1e-5 * want, "{level:?}, {columns} columns, ({r}, {j}): {got}, want {want}");
                    }
                }
            }
        }
    }

    #[test]
    fn cached_tile_rate_is_a_rate_on_simd_paths_and_none_otherwise() {
        assert_eq!(cached_tile_rate_at(None, 64, 16, 1000, 1), None);
        for level in super::super::simd::supported() {
            assert_eq!(cached_tile_rate_at(Some(level), 0, 16, 1000, 1), None);
            assert_eq!(cached_tile_rate_at(Some(level), 64, 0, 1000, 1), None);
            let gflops = cached_tile_rate_at(Some(level), 64, 16, 1_000_000, 1).expect("a SIMD level");
            assert!(gflops.is_finite() && gflops > 0.0, "{level:?}: {gflops}");
        }
    }
}
