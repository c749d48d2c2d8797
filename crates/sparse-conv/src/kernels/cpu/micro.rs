//! The op's f32 register-tile kernels, written once over the vector width ([`Simd`]) and
//! compiled for each instruction set the build targets (AVX-512F, AVX2 + FMA).
//!
//! - Weight gradient: the micro-kernel reads each pair's input and output-gradient rows in
//!   place, through the kernel map, and accumulates the outer products in registers. The
//!   general path ([`weight_grad`](super::weight_grad)) gathers both rows into tiles and lets
//!   matrixmultiply pack the tiles again before multiplying.
//! - Forward and feature gradient ([`pair_conv`]): by destination blocks when each offset's
//!   pairs come ordered by destination row (as [`crate::KernelMap::pairs`] and
//!   [`crate::KernelMap::pairs_by_input`] give them): a task owns a block of output rows and, for
//!   every offset, multiplies the source rows of the pairs landing in it, read in place `MR` at a
//!   time, with `W_k` packed once per call into panels two vectors wide, and adds each register
//!   tile straight into the block's rows, which stay in L2 from one offset to the next; one
//!   parallel region per call. The next tile's source rows are prefetched while a tile runs:
//!   without that, reading in place was slower than gathering the rows into a tile first (their
//!   scattered first reads stalled the FMAs); with it, faster than the gather. Scattered rows
//!   written over rather than added to (an up forward's) are asked for, to write, in the same
//!   way, and a submanifold block asks for the next block's rows (which its identity offset reads
//!   and writes first) while its own offsets run. Pairs in another order run offset by offset, in
//!   chunks, gathered. The general path copies each tile again (matrixmultiply's packing),
//!   repacks `W_k` for every chunk, and adds a product buffer in a pass of its own.
//!
//! Every output element is its first term (or zero) plus each later offset's product in offset
//! order, each product one fused multiply-add per term in that element's lane, the same way on
//! every path, at any block size and at any vector width, so results are bit-identical at any
//! thread count and on every instruction set (they differ from the general path's in the last
//! bits: its products sum their terms in another order).
//!
//! The micro-kernels are generic bodies; [`TileKernels`] is each instruction set's set of entry
//! points, functions compiled with its target features into which the bodies and the vector
//! operations inline.

use rayon::prelude::*;

use super::conv::grad_chunks;
use super::element::{PairDirection, RowEpilogue, assume_init, scratch};
use super::simd::{Hint, Simd, prefetch};
use crate::geometry::kernel_map::OffsetPairs;
use crate::parallel::SyncPtr;

/// Columns per tile: two vectors.
const fn nr<V: Simd>() -> usize {
    2 * V::LANES
}
/// The most rows any instruction set's tile has ([`Simd::MR`]): the size of the row-pointer
/// arrays.
const MAX_MR: usize = 12;
/// Pairs per block: their rows stay in L1 while every tile of the partial passes over them.
const PAIR_BLOCK: usize = 32;

/// The cache lines of a list of rows, asked for into L1 a few at a time: spread over the work
/// they overlap, the requests do not queue up behind the line-fill buffers all at once.
struct RowPrefetch<'a> {
    rows: &'a [*const f32],
    /// Floats per row.
    len: usize,
    row: usize,
    line: usize,
    hint: Hint,
}

impl<'a> RowPrefetch<'a> {
    fn new(rows: &'a [*const f32], len: usize) -> Self {
        Self::with_hint(rows, len, Hint::Read)
    }

    fn with_hint(rows: &'a [*const f32], len: usize, hint: Hint) -> Self {
        Self { rows, len, row: 0, line: 0, hint }
    }

    /// Lines in all.
    fn lines(&self) -> usize {
        self.rows.len() * self.len.div_ceil(16)
    }

    /// Asks for the next `count` lines.
    #[inline(always)]
    fn issue(&mut self, count: usize) {
        for _ in 0..count {
            let Some(&row) = self.rows.get(self.row) else { return };
            let p = row.wrapping_add(self.line);
            prefetch(p, self.hint);
            self.line += 16;
            if self.line >= self.len {
                (self.row, self.line) = (self.row + 1, 0);
            }
        }
    }
}

/// The next destination block's source and destination rows, asked for (into L2) a share per
/// tile call while this block's offsets run: its identity offset then starts on rows in cache
/// rather than waiting on memory, so the conv's memory traffic runs under its FMAs.
struct BlockAhead<'a> {
    src: RowPrefetch<'a>,
    dst: RowPrefetch<'a>,
    /// Lines of each asked for per tile call.
    per_call: (usize, usize),
}

impl<'a> BlockAhead<'a> {
    /// `src` and `dst` each one contiguous run of `src_len`, `dst_len` floats, spread over
    /// `calls` tile calls.
    fn new(src: &'a [*const f32; 1], src_len: usize, dst: &'a [*const f32; 1], dst_len: usize, calls: usize) -> Self {
        let (src, dst) = (RowPrefetch::with_hint(src, src_len, Hint::ReadLater), RowPrefetch::with_hint(dst, dst_len, Hint::Write));
        let per_call = (src.lines().div_ceil(calls.max(1)), dst.lines().div_ceil(calls.max(1)));
        Self { src, dst, per_call }
    }

    fn none() -> Self {
        Self { src: RowPrefetch::new(&[], 0), dst: RowPrefetch::new(&[], 0), per_call: (0, 0) }
    }

    #[inline(always)]
    fn issue(&mut self) {
        self.src.issue(self.per_call.0);
        self.dst.issue(self.per_call.1);
    }
}

/// The lane masks of a tile's two vectors when its first `cols` columns are real.
#[inline(always)]
fn masks<V: Simd>(cols: usize) -> [V::Mask; 2] {
    [V::mask(cols), V::mask(cols.saturating_sub(V::LANES))]
}

/// Adds a register row (two vectors, lanes `m`) to the floats at `o`, or, without
/// `accumulate`, writes it there: the end of every micro-kernel here.
///
/// # Safety
/// `V`'s instructions; the masked lanes at `o` writable (and, to accumulate, initialised).
#[inline(always)]
unsafe fn store_row<V: Simd>(o: *mut f32, acc: [V::V; 2], m: [V::Mask; 2], accumulate: bool) {
    unsafe {
        let (mut v0, mut v1) = (acc[0], acc[1]);
        let o1 = o.wrapping_add(V::LANES);
        if accumulate {
            v0 = V::add(V::load_masked(m[0], o), v0);
            v1 = V::add(V::load_masked(m[1], o1), v1);
        }
        V::store_masked(o, m[0], v0);
        V::store_masked(o1, m[1], v1);
    }
}

/// `out[i][j] (+)= (Σ_p x[p][i] · g[p][j])` for `R` rows `i0..i0 + R` and the `cols` (≤ two
/// vectors) columns from `j0`, over the pairs' rows `xs[p]`, `gs[p]`; with `accumulate` false
/// `out` is written without being read.
///
/// # Safety
/// `V`'s instructions; `xs[p]` readable up to `i0 + R`, `gs[p]` up to `j0 + cols`, `out` rows
/// of `ld` floats writable (and, to accumulate, initialised) at `i0.., j0..`.
// The register tile is indexed by constant-bounded loops that unroll into registers.
#[allow(clippy::needless_range_loop)]
#[allow(clippy::too_many_arguments)]
#[inline(always)]
unsafe fn pair_outer_products<V: Simd, const R: usize>(
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
        let m = masks::<V>(cols);
        let mut acc = [[V::zero(); 2]; R];
        for (&x, &g) in xs.iter().zip(gs) {
            let g = g.wrapping_add(j0);
            let b0 = V::load_masked(m[0], g);
            let b1 = V::load_masked(m[1], g.wrapping_add(V::LANES));
            let x = x.wrapping_add(i0);
            for r in 0..R {
                let a = V::splat(x.wrapping_add(r));
                acc[r][0] = V::fmadd(a, b0, acc[r][0]);
                acc[r][1] = V::fmadd(a, b1, acc[r][1]);
            }
        }
        for (r, &acc) in acc.iter().enumerate() {
            store_row::<V>(out.add((i0 + r) * ld + j0), acc, m, accumulate);
        }
    }
}

/// `out_r[..cols] (+)= Σ_kk a[r·lda + kk] · panel[kk][..cols]` for `R` rows: a row tile times
/// one panel (two vectors wide) of a packed weight, each row's sums added to (or, without
/// `accumulate`, written over) its own destination.
///
/// # Safety
/// `V`'s instructions; `a` readable for `R` rows of `lda ≥ kc` floats, `panel` for `kc` rows of
/// two vectors, each `out[r]` writable (and, to accumulate, initialised) for `cols` floats.
#[allow(clippy::needless_range_loop)]
#[allow(clippy::too_many_arguments)]
#[inline(always)]
unsafe fn tile_times_panel<V: Simd, const R: usize>(a: *const f32, lda: usize, kc: usize, panel: *const f32, out: &[*mut f32], cols: usize, accumulate: bool) {
    unsafe {
        let m = masks::<V>(cols);
        let mut acc = [[V::zero(); 2]; R];
        let (mut a, mut panel) = (a, panel);
        for _ in 0..kc {
            let b0 = V::load(panel);
            let b1 = V::load(panel.wrapping_add(V::LANES));
            for r in 0..R {
                let x = V::splat(a.wrapping_add(r * lda));
                acc[r][0] = V::fmadd(x, b0, acc[r][0]);
                acc[r][1] = V::fmadd(x, b1, acc[r][1]);
            }
            a = a.wrapping_add(1);
            panel = panel.wrapping_add(nr::<V>());
        }
        for r in 0..R {
            store_row::<V>(out[r], acc[r], m, accumulate);
        }
    }
}

/// [`tile_times_panel`] with the `R` rows read in place, at `rows[r]`.
///
/// # Safety
/// As [`tile_times_panel`], each `rows[r]` readable for `kc` floats.
#[allow(clippy::needless_range_loop)]
#[inline(always)]
unsafe fn rows_times_panel<V: Simd, const R: usize>(rows: &[*const f32], kc: usize, panel: *const f32, out: &[*mut f32], cols: usize, accumulate: bool) {
    unsafe {
        let m = masks::<V>(cols);
        let mut acc = [[V::zero(); 2]; R];
        let mut a = [std::ptr::null::<f32>(); R];
        a.copy_from_slice(&rows[..R]);
        let mut panel = panel;
        for kk in 0..kc {
            let b0 = V::load(panel);
            let b1 = V::load(panel.wrapping_add(V::LANES));
            for r in 0..R {
                let x = V::splat(a[r].wrapping_add(kk));
                acc[r][0] = V::fmadd(x, b0, acc[r][0]);
                acc[r][1] = V::fmadd(x, b1, acc[r][1]);
            }
            panel = panel.wrapping_add(nr::<V>());
        }
        for r in 0..R {
            store_row::<V>(out[r], acc[r], m, accumulate);
        }
    }
}

/// One instruction set's entry points: each runs the generic body of the same name compiled with
/// the set's target features, so that the body and its vector operations inline into it.
///
/// # Safety
/// Callable only on a CPU with the instruction set.
pub(crate) unsafe trait TileKernels: Simd {
    /// [`pair_outer_products`].
    #[allow(clippy::too_many_arguments)]
    unsafe fn pair_outer_products<const R: usize>(xs: &[*const f32], gs: &[*const f32], i0: usize, j0: usize, cols: usize, out: *mut f32, ld: usize, accumulate: bool);
    /// [`tile_times_panel`].
    #[allow(clippy::too_many_arguments)]
    unsafe fn tile_times_panel<const R: usize>(a: *const f32, lda: usize, kc: usize, panel: *const f32, out: &[*mut f32], cols: usize, accumulate: bool);
    /// [`rows_times_panel`].
    unsafe fn rows_times_panel<const R: usize>(rows: &[*const f32], kc: usize, panel: *const f32, out: &[*mut f32], cols: usize, accumulate: bool);
    /// [`stats_block`].
    unsafe fn stats_block(x: &[f32], c: usize, shift: &[f32], total: &mut [f64]);
    /// [`param_block`].
    #[allow(clippy::too_many_arguments)]
    unsafe fn param_block(x: &[f32], g: &[f32], c: usize, a: &[f32], b: &[f32], mean: &[f32], relu: bool, total: &mut [f64]);
    /// [`fma_chains`](super::peak::fma_chains).
    unsafe fn fma_chains(iterations: usize) -> f32;
}

/// Implements [`TileKernels`] for an instruction set `$isa` whose target features are `$features`.
macro_rules! tile_kernels {
    ($isa:ty, $features:literal) => {
        // The row-pointer arrays hold MAX_MR rows.
        const _: () = assert!(<$isa as Simd>::MR <= MAX_MR);
        // SAFETY: every entry point is compiled for `$features`, which `Simd::available` tests.
        unsafe impl TileKernels for $isa {
            #[target_feature(enable = $features)]
            unsafe fn pair_outer_products<const R: usize>(xs: &[*const f32], gs: &[*const f32], i0: usize, j0: usize, cols: usize, out: *mut f32, ld: usize, accumulate: bool) {
                unsafe { self::pair_outer_products::<Self, R>(xs, gs, i0, j0, cols, out, ld, accumulate) }
            }
            #[target_feature(enable = $features)]
            unsafe fn tile_times_panel<const R: usize>(a: *const f32, lda: usize, kc: usize, panel: *const f32, out: &[*mut f32], cols: usize, accumulate: bool) {
                unsafe { self::tile_times_panel::<Self, R>(a, lda, kc, panel, out, cols, accumulate) }
            }
            #[target_feature(enable = $features)]
            unsafe fn rows_times_panel<const R: usize>(rows: &[*const f32], kc: usize, panel: *const f32, out: &[*mut f32], cols: usize, accumulate: bool) {
                unsafe { self::rows_times_panel::<Self, R>(rows, kc, panel, out, cols, accumulate) }
            }
            #[target_feature(enable = $features)]
            unsafe fn stats_block(x: &[f32], c: usize, shift: &[f32], total: &mut [f64]) {
                unsafe { self::stats_block::<Self>(x, c, shift, total) }
            }
            #[target_feature(enable = $features)]
            unsafe fn param_block(x: &[f32], g: &[f32], c: usize, a: &[f32], b: &[f32], mean: &[f32], relu: bool, total: &mut [f64]) {
                unsafe { self::param_block::<Self>(x, g, c, a, b, mean, relu, total) }
            }
            #[target_feature(enable = $features)]
            unsafe fn fma_chains(iterations: usize) -> f32 {
                unsafe { super::peak::fma_chains::<Self>(iterations) }
            }
        }
    };
}

#[cfg(target_arch = "x86_64")]
tile_kernels!(super::simd::Avx512, "avx512f");
#[cfg(target_arch = "x86_64")]
tile_kernels!(super::simd::Avx2, "avx2,fma");

/// Runs `$call` with `$r` a constant equal to `$rows` (1 ..= [`MAX_MR`]): the row count of a
/// tile, a const parameter of the micro-kernels.
macro_rules! by_rows {
    ($rows:expr, |$r:ident| $call:expr) => {
        match $rows {
            1 => { const $r: usize = 1; $call }
            2 => { const $r: usize = 2; $call }
            3 => { const $r: usize = 3; $call }
            4 => { const $r: usize = 4; $call }
            5 => { const $r: usize = 5; $call }
            6 => { const $r: usize = 6; $call }
            7 => { const $r: usize = 7; $call }
            8 => { const $r: usize = 8; $call }
            9 => { const $r: usize = 9; $call }
            10 => { const $r: usize = 10; $call }
            11 => { const $r: usize = 11; $call }
            12 => { const $r: usize = 12; $call }
            _ => unreachable!("at most MAX_MR rows per tile"),
        }
    };
}
pub(crate) use by_rows;

/// Runs `$call` with `$v` the instruction set of `$level` (a [`Level`](super::simd::Level)).
macro_rules! at_level {
    ($level:expr, |$v:ident| $call:expr) => {
        match $level {
            #[cfg(target_arch = "x86_64")]
            $crate::kernels::cpu::Level::Avx512 => {
                type $v = $crate::kernels::cpu::simd::Avx512;
                $call
            }
            #[cfg(target_arch = "x86_64")]
            $crate::kernels::cpu::Level::Avx2 => {
                type $v = $crate::kernels::cpu::simd::Avx2;
                $call
            }
        }
    };
}
pub(crate) use at_level;

/// Rows per chunk of an offset's pairs in [`pair_conv`]: the unit of parallel work, whose
/// gathered tile stays in L2 while every panel passes over it.
const PAIR_CHUNK: usize = 256;

/// Output rows per destination block: enough blocks for rayon to balance uneven ones, at least
/// enough rows that each offset brings a few tiles' worth of pairs, at most an L2-sized block.
const BLOCKS_PER_THREAD: usize = 8;
const MIN_BLOCK_ROWS: usize = 64;
const MAX_BLOCK_ROWS: usize = 512;

/// Every offset's `[c_src, c_dst]` matrix (`W_k`, or `W_kᵀ` read through the strides
/// `(rs, cs)` of its rows and columns: `(c_dst, 1)` or `(1, c_src)`) packed as panels of
/// `nr` (two vectors) columns: panel `p` of offset `k` holds `kc` rows of `nr` floats (zero past
/// `c_dst`), at `(k·panels + p)·c_src·nr`.
fn pack_panels<V: Simd>(weight: &[f32], volume: usize, c_src: usize, c_dst: usize, rs: usize, cs: usize) -> Vec<f32> {
    let nr = nr::<V>();
    let panels = c_dst.div_ceil(nr);
    let mut packed = vec![0.0f32; volume * panels * c_src * nr];
    if packed.is_empty() {
        return packed;
    }
    packed.par_chunks_mut(panels * c_src * nr).enumerate().for_each(|(k, dst)| {
        let w = &weight[k * c_src * c_dst..][..c_src * c_dst];
        for (p, panel) in dst.chunks_exact_mut(c_src * nr).enumerate() {
            let cols = nr.min(c_dst - p * nr);
            if cs == 1 {
                // W_k: each panel row is a piece of a weight row.
                for (kk, row) in panel.chunks_exact_mut(nr).enumerate() {
                    row[..cols].copy_from_slice(&w[kk * rs + p * nr..][..cols]);
                }
            } else {
                // W_kᵀ: read the weight by rows (a panel column each), write the panel, which
                // stays in L1, by columns.
                debug_assert_eq!(rs, 1, "a weight read by rows or by columns");
                for j in 0..cols {
                    for (kk, &v) in w[(p * nr + j) * cs..][..c_src].iter().enumerate() {
                        panel[kk * nr + j] = v;
                    }
                }
            }
        }
    });
    packed
}

/// [`pair_conv`](super::pair_conv) for f32 on `V`'s instructions; same arguments and result, up to
/// rounding.
#[allow(clippy::too_many_arguments)]
pub(crate) fn pair_conv<V: TileKernels>(
    src: &[f32],
    c_src: usize,
    weight: &[f32],
    c_dst: usize,
    n_dst: usize,
    direction: PairDirection,
    pairs: &OffsetPairs,
    identity: Option<usize>,
    epilogue: Option<&dyn RowEpilogue<f32>>,
) -> Vec<f32> {
    assert!(V::available(), "{} called on a CPU without them", V::NAME);
    let (nr, mr) = (nr::<V>(), V::MR);
    let volume = pairs.start.len() - 1;
    assert_eq!(weight.len(), volume * c_src * c_dst, "weight does not match the map and channels");
    if n_dst == 0 || c_dst == 0 {
        return vec![0.0; n_dst * c_dst];
    }
    // Forward multiplies by W_k (c_in × c_out, row-major), the feature gradient by W_kᵀ.
    let (rs, cs) = match direction {
        PairDirection::Forward => (c_dst, 1),
        PairDirection::Backward => (1, c_src),
    };
    let (gather_side, scatter_side) = match direction {
        PairDirection::Forward => (&pairs.input, &pairs.output),
        PairDirection::Backward => (&pairs.output, &pairs.input),
    };
    let panels = c_dst.div_ceil(nr);
    let packed = pack_panels::<V>(weight, volume, c_src, c_dst, rs, cs);
    let panel_of = |k: usize, p: usize| packed[(k * panels + p) * c_src * nr..].as_ptr();
    let mut out = scratch::<f32>(n_dst * c_dst);
    let out_ptr = SyncPtr(out.as_mut_ptr().cast::<f32>());
    let out_ptr = &out_ptr;
    // Multiplies the `m` rows at `tile` (row stride `lda`) with offset k's panels `panel_range`
    // and adds each row's products to its destination row, `dst[r]` or, for the identity
    // offset (`dst` empty), `first + r`; without `accumulate` it writes them.
    let multiply = |k: usize, panel_range: std::ops::Range<usize>, tile: *const f32, lda: usize, m: usize, dst: &[u32], first: usize, accumulate: bool| {
        let dst = |r: usize| if dst.is_empty() { first + r } else { dst[r] as usize };
        let mut rows = [std::ptr::null_mut::<f32>(); MAX_MR];
        for p in panel_range {
            let (j0, panel) = (p * nr, panel_of(k, p));
            let cols = nr.min(c_dst - j0);
            for r0 in (0..m).step_by(mr) {
                let r_count = mr.min(m - r0);
                for (r, row) in rows.iter_mut().enumerate().take(r_count) {
                    // SAFETY: destination rows are < n_dst.
                    *row = unsafe { out_ptr.0.add(dst(r0 + r) * c_dst + j0) };
                }
                // SAFETY: the tile holds m rows of lda ≥ c_src floats, the panel c_src rows of
                // nr; destination rows are written by this call only (see below).
                let a = unsafe { tile.add(r0 * lda) };
                by_rows!(r_count, |R| unsafe { V::tile_times_panel::<R>(a, lda, c_src, panel, &rows[..R], cols, accumulate) });
            }
        }
    };
    // The source rows at `srcs`, read in place, times offset k's panels, added to (or, without
    // `accumulate`, written over) destination rows `dst`: row tile by row tile, so a tile's rows
    // stay in L1 across the panels (the identity too), asking for the next tile's scattered source
    // rows while this one's run and, for scattered rows written over (the block's first touch of
    // them, the up forward's), for its destination rows to write: without that the tile's stores
    // wait on their lines. With
    // `contiguous` (the identity), source row i is `srcs[0] + i·c_src` and `dst[i]` is
    // `dst[0] + i`.
    let multiply_in_place = |k: usize, srcs: &[*const f32], dst: &[u32], contiguous: bool, accumulate: bool, ahead: &mut BlockAhead<'_>| {
        let mut outs = [std::ptr::null_mut::<f32>(); MAX_MR];
        let mut next_outs = [std::ptr::null::<f32>(); MAX_MR];
        for r0 in (0..srcs.len()).step_by(mr) {
            let r_count = mr.min(srcs.len() - r0);
            // The identity's rows were asked for a block ahead ([`BlockAhead`]).
            let next = if contiguous { r0..r0 } else { (r0 + mr).min(srcs.len())..(r0 + 2 * mr).min(srcs.len()) };
            let next_written = if accumulate { 0 } else { next.len() };
            for (o, &r) in next_outs.iter_mut().zip(&dst[next.clone()]).take(next_written) {
                *o = out_ptr.0.wrapping_add(r as usize * c_dst);
            }
            let mut prefetch = RowPrefetch::new(&srcs[next], c_src);
            let mut prefetch_out = RowPrefetch::with_hint(&next_outs[..next_written], c_dst, Hint::Write);
            let (per_call, out_per_call) = (prefetch.lines().div_ceil(panels), prefetch_out.lines().div_ceil(panels));
            for p in 0..panels {
                let (j0, panel) = (p * nr, panel_of(k, p));
                let cols = nr.min(c_dst - j0);
                prefetch.issue(per_call);
                prefetch_out.issue(out_per_call);
                ahead.issue();
                for (r, o) in outs.iter_mut().enumerate().take(r_count) {
                    // SAFETY: destination rows are < n_dst.
                    *o = unsafe { out_ptr.0.add(dst[r0 + r] as usize * c_dst + j0) };
                }
                let rows = &srcs[r0..r0 + r_count];
                // SAFETY: each source row holds c_src floats, the panel c_src rows of two
                // vectors; the destination rows are the caller's block's, each once per offset.
                if contiguous {
                    // One base and a stride: MR − 1 registers freed in the loop, a few % at 32
                    // and 64 channels.
                    by_rows!(r_count, |R| unsafe { V::tile_times_panel::<R>(rows[0], c_src, c_src, panel, &outs[..R], cols, accumulate) });
                } else {
                    by_rows!(r_count, |R| unsafe { V::rows_times_panel::<R>(rows, c_src, panel, &outs[..R], cols, accumulate) });
                }
            }
        }
    };
    let written_once = identity.is_none() && scatter_side.len() == n_dst && {
        let mut seen = vec![false; n_dst];
        scatter_side.iter().all(|&r| !std::mem::replace(&mut seen[r as usize], true))
    };
    if let Some(k) = identity {
        assert_eq!(pairs.start[k + 1] - pairs.start[k], n_dst, "the identity offset must pair every row with itself");
        assert!(src.len() >= n_dst * c_src, "the identity offset reads {n_dst} source rows, the source has fewer");
    }
    if (0..volume).all(|k| scatter_side[pairs.start[k]..pairs.start[k + 1]].is_sorted()) {
        // Destination blocks: each task owns a block of output rows and runs every offset's
        // pairs that land in it, so the block's rows stay in L2 between offsets and a conv is
        // one parallel region, not one per offset.
        let block_rows = (n_dst / (BLOCKS_PER_THREAD * rayon::current_num_threads())).clamp(MIN_BLOCK_ROWS, MAX_BLOCK_ROWS);
        (0..n_dst.div_ceil(block_rows)).into_par_iter().for_each_init(
            || (Vec::<*const f32>::with_capacity(block_rows), Vec::<u32>::with_capacity(block_rows), Vec::with_capacity(volume)),
            |(srcs, rows, ranges), block| {
                let (r0, r1) = (block * block_rows, ((block + 1) * block_rows).min(n_dst));
                // Each offset's pairs landing in the block.
                ranges.clear();
                ranges.extend((0..volume).filter(|&k| Some(k) != identity).map(|k| {
                    let (s, e) = (pairs.start[k], pairs.start[k + 1]);
                    let dst = &scatter_side[s..e];
                    (k, s + dst.partition_point(|&r| (r as usize) < r0), s + dst.partition_point(|&r| (r as usize) < r1))
                }));
                // A thread mostly runs consecutive blocks (rayon splits the range in halves), so
                // the next block is most likely its next task.
                let (n0, n1) = (r1, (r1 + block_rows).min(n_dst));
                let ahead_src = [src.as_ptr().wrapping_add(n0 * c_src)];
                let ahead_dst = [out_ptr.0.wrapping_add(n0 * c_dst).cast_const()];
                // With an identity offset (a submanifold conv) a block starts by reading source
                // rows and writing output rows of its own numbers, contiguous: those of the next
                // block are asked for while this one runs.
                let mut ahead = match identity {
                    Some(_) => {
                        let calls = panels * ((r1 - r0).div_ceil(mr) + ranges.iter().map(|&(_, a, b)| (b - a).div_ceil(mr)).sum::<usize>());
                        BlockAhead::new(&ahead_src, (n1 - n0) * c_src, &ahead_dst, (n1 - n0) * c_dst, calls)
                    }
                    None => BlockAhead::none(),
                };
                match identity {
                    Some(k) => {
                        srcs.clear();
                        srcs.extend((r0..r1).map(|r| src.as_ptr().wrapping_add(r * c_src)));
                        rows.clear();
                        rows.extend(r0 as u32..r1 as u32);
                        multiply_in_place(k, srcs, rows, true, false, &mut ahead);
                    }
                    None if written_once => {}
                    // SAFETY: rows r0..r1 are this block's.
                    None => unsafe { std::ptr::write_bytes(out_ptr.0.add(r0 * c_dst), 0, (r1 - r0) * c_dst) },
                }
                for &(k, a, b) in ranges.iter() {
                    srcs.clear();
                    srcs.extend(gather_side[a..b].iter().map(|&r| src.as_ptr().wrapping_add(r as usize * c_src)));
                    multiply_in_place(k, srcs, &scatter_side[a..b], false, !written_once, &mut ahead);
                }
                if let Some(e) = epilogue {
                    // SAFETY: the block's rows, all written above (see below), this task's only.
                    e.apply(r0, unsafe { std::slice::from_raw_parts_mut(out_ptr.0.add(r0 * c_dst), (r1 - r0) * c_dst) });
                }
            },
        );
        // SAFETY: every row was written by its block: the identity's products, the zero fill, or
        // (written once) its one pair.
        return unsafe { assume_init(out) };
    }
    match identity {
        Some(k) => {
            // The centre pairs (r, r) in row order: its products write every output row, its
            // source rows read in place, so the output is not zeroed first.
            (0..n_dst.div_ceil(PAIR_CHUNK)).into_par_iter().for_each(|chunk| {
                let r0 = chunk * PAIR_CHUNK;
                let m = PAIR_CHUNK.min(n_dst - r0);
                multiply(k, 0..panels, src[r0 * c_src..].as_ptr(), c_src, m, &[], r0, false);
            });
        }
        // Every destination row is one pair's (an up map's forward, a down map's feature
        // gradient): the offsets write their products, nothing to start from.
        None if written_once => {}
        // No offset covers every row: the sums start from zero.
        None => out.par_chunks_mut(1 << 16).for_each(|c| {
            c.iter_mut().for_each(|v| {
                v.write(0.0);
            })
        }),
    }
    for k in (0..volume).filter(|&k| Some(k) != identity) {
        let (s, e) = (pairs.start[k], pairs.start[k + 1]);
        if s == e {
            continue;
        }
        // An offset with few pairs has few chunks: its panels are then split into groups, so
        // that every thread gets work (each output element is still one tile call's sum, so the
        // split does not change the result).
        let chunks = (e - s).div_ceil(PAIR_CHUNK);
        let groups = panels.min((2 * rayon::current_num_threads()).div_ceil(chunks)).max(1);
        let per_group = panels.div_ceil(groups);
        (0..chunks * groups).into_par_iter().for_each_init(
            || scratch::<f32>(PAIR_CHUNK * c_src),
            |tile, unit| {
                let (chunk, group) = (unit / groups, unit % groups);
                let panel_range = group * per_group..((group + 1) * per_group).min(panels);
                let a = s + chunk * PAIR_CHUNK;
                let b = (a + PAIR_CHUNK).min(e);
                let tile = tile.as_mut_ptr().cast::<f32>();
                for (j, &r) in gather_side[a..b].iter().enumerate() {
                    // SAFETY: row r of the source and row j < PAIR_CHUNK of the tile.
                    unsafe { std::ptr::copy_nonoverlapping(src.as_ptr().add(r as usize * c_src), tile.add(j * c_src), c_src) };
                }
                // Within offset k each destination row appears once, so chunks running at once
                // write disjoint rows; offsets run one after another, each row summing them in
                // offset order.
                multiply(k, panel_range, tile, c_src, b - a, &scatter_side[a..b], 0, !written_once);
            },
        );
    }
    // SAFETY: every element was written: by the identity's products, the zero fill, or (written
    // once) the one pair of each row.
    let mut out = unsafe { assume_init(out) };
    if let Some(e) = epilogue {
        e.apply_all(&mut out);
    }
    out
}

/// [`weight_grad`](super::weight_grad) for f32 on `V`'s instructions; same arguments and result.
pub(crate) fn weight_grad<V: TileKernels>(x: &[f32], c_in: usize, grad_out: &[f32], c_out: usize, pairs: &OffsetPairs) -> Vec<f32> {
    assert!(V::available(), "{} called on a CPU without them", V::NAME);
    let (nr, mr) = (nr::<V>(), V::MR);
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
        // each tile sums a block's products in registers, then adds them to its running sum (loading
        // it only then, so the FMAs never wait on it): a grouping set by PAIR_BLOCK, not by threads.
        for (block_index, (xs_block, gs_block)) in xs.chunks(PAIR_BLOCK).zip(gs.chunks(PAIR_BLOCK)).enumerate() {
            // The next block's rows are scattered, so the hardware prefetchers cannot see them
            // coming: ask for them while this block's tiles run, a share per tile.
            let next = ((block_index + 1) * PAIR_BLOCK).min(xs.len())..((block_index + 2) * PAIR_BLOCK).min(xs.len());
            let (mut next_x, mut next_g) = (RowPrefetch::new(&xs[next.clone()], c_in), RowPrefetch::new(&gs[next], c_out));
            let tiles = c_in.div_ceil(mr) * c_out.div_ceil(nr);
            let (x_per_tile, g_per_tile) = (next_x.lines().div_ceil(tiles), next_g.lines().div_ceil(tiles));
            let (xs, gs) = (xs_block, gs_block);
            for i0 in (0..c_in).step_by(mr) {
                for j0 in (0..c_out).step_by(nr) {
                    let cols = nr.min(c_out - j0);
                    next_x.issue(x_per_tile);
                    next_g.issue(g_per_tile);
                    // SAFETY: rows and columns stay inside x, grad_out and the block; the first
                    // pair block writes every element before any is read.
                    by_rows!(mr.min(c_in - i0), |R| unsafe { V::pair_outer_products::<R>(xs, gs, i0, j0, cols, out, c_out, block_index > 0) });
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
    // SAFETY: every block was written, by its offset's first chunk or the zero fill above.
    unsafe { assume_init(grad) }
}

/// Rows per block of the batch-norm sums: as [`crate::kernels::cpu::norm`]'s blocks, so the sums are its
/// bits.
const NORM_BLOCK_ROWS: usize = 16;

/// Adds the two block sums' first `lanes` lanes, widened to f64, into the totals at `t1`, `t2`.
///
/// # Safety
/// `V`'s instructions; `t1`, `t2` writable for `lanes ≤ V::LANES` f64.
#[inline(always)]
unsafe fn add_to_totals<V: Simd>(s1: V::V, s2: V::V, t1: *mut f64, t2: *mut f64, lanes: usize) {
    unsafe {
        for (s, t) in [(s1, t1), (s2, t2)] {
            for (l, v) in V::to_array(s).into_iter().take(lanes).enumerate() {
                *t.add(l) += v as f64;
            }
        }
    }
}

/// [`crate::kernels::cpu::norm`]'s channel statistics sums over `x`'s rows (`c` channels): `[Σ d; Σ d²]`
/// with `d = x − shift`, in blocks of 16 rows summed in f32 then added in f64, as the general
/// loops do, so the same bits.
pub(crate) fn stats_sums<V: TileKernels>(x: &[f32], c: usize, shift: &[f32]) -> Vec<f64> {
    assert!(V::available(), "{} called on a CPU without them", V::NAME);
    assert!(shift.len() == c && x.len().is_multiple_of(c), "rows of {c} channels");
    let mut total = vec![0.0f64; 2 * c];
    // SAFETY: the CPU has V's instructions; the loops stay inside x, shift and total.
    unsafe { V::stats_block(x, c, shift, &mut total) };
    total
}

/// The body of [`stats_sums`].
///
/// # Safety
/// `V`'s instructions; `shift` of `c` floats, `x` whole rows of `c`, `total` of `2·c`.
#[inline(always)]
unsafe fn stats_block<V: Simd>(x: &[f32], c: usize, shift: &[f32], total: &mut [f64]) {
    unsafe {
        let n = x.len() / c;
        let (x, shift, total) = (x.as_ptr(), shift.as_ptr(), total.as_mut_ptr());
        for b0 in (0..n).step_by(NORM_BLOCK_ROWS) {
            let b1 = (b0 + NORM_BLOCK_ROWS).min(n);
            for j0 in (0..c).step_by(V::LANES) {
                let m = V::mask(c - j0);
                let k = V::load_masked(m, shift.add(j0));
                let (mut s1, mut s2) = (V::zero(), V::zero());
                for r in b0..b1 {
                    let d = V::sub(V::load_masked(m, x.add(r * c + j0)), k);
                    s1 = V::add(s1, d);
                    s2 = V::add(s2, V::mul(d, d));
                }
                add_to_totals::<V>(s1, s2, total.add(j0), total.add(c + j0), (c - j0).min(V::LANES));
            }
        }
    }
}

/// [`crate::kernels::cpu::norm`]'s batch-norm parameter-gradient sums over the rows of `x` and `g`:
/// `[Σ dz·(x − mean); Σ dz]`, `dz = g` masked where `x·a + b ≤ 0` (with `relu`); blocks as
/// [`stats_sums`], the same bits as the general loops.
#[allow(clippy::too_many_arguments)]
pub(crate) fn param_sums<V: TileKernels>(x: &[f32], g: &[f32], c: usize, a: &[f32], b: &[f32], mean: &[f32], relu: bool) -> Vec<f64> {
    assert!(V::available(), "{} called on a CPU without them", V::NAME);
    assert!(a.len() == c && b.len() == c && mean.len() == c && x.len().is_multiple_of(c) && g.len() == x.len(), "rows of {c} channels");
    let mut total = vec![0.0f64; 2 * c];
    // SAFETY: the CPU has V's instructions; the loops stay inside the slices.
    unsafe { V::param_block(x, g, c, a, b, mean, relu, &mut total) };
    total
}

/// The body of [`param_sums`].
///
/// # Safety
/// `V`'s instructions; `a`, `b`, `mean` of `c` floats, `x` and `g` whole rows of `c`, `total`
/// of `2·c`.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
unsafe fn param_block<V: Simd>(x: &[f32], g: &[f32], c: usize, a: &[f32], b: &[f32], mean: &[f32], relu: bool, total: &mut [f64]) {
    unsafe {
        let n = x.len() / c;
        let (x, g, total) = (x.as_ptr(), g.as_ptr(), total.as_mut_ptr());
        for b0 in (0..n).step_by(NORM_BLOCK_ROWS) {
            let b1 = (b0 + NORM_BLOCK_ROWS).min(n);
            for j0 in (0..c).step_by(V::LANES) {
                let m = V::mask(c - j0);
                let (va, vb, vmean) = (V::load_masked(m, a.as_ptr().add(j0)), V::load_masked(m, b.as_ptr().add(j0)), V::load_masked(m, mean.as_ptr().add(j0)));
                let (mut dgamma, mut dbeta) = (V::zero(), V::zero());
                for r in b0..b1 {
                    let v = V::load_masked(m, x.add(r * c + j0));
                    let mut dz = V::load_masked(m, g.add(r * c + j0));
                    if relu {
                        // z = x·a + b rounded twice (no FMA), as the forward computes it; a NaN z
                        // keeps its gradient.
                        let z = V::add(V::mul(v, va), vb);
                        dz = V::zero_where_not_positive(z, dz);
                    }
                    dbeta = V::add(dbeta, dz);
                    dgamma = V::add(dgamma, V::mul(dz, V::sub(v, vmean)));
                }
                add_to_totals::<V>(dgamma, dbeta, total.add(j0), total.add(c + j0), (c - j0).min(V::LANES));
            }
        }
    }
}

// The instruction sets the tests run are x86-64 ones (until a NEON `Simd` lands).
#[cfg(all(test, target_arch = "x86_64"))]
mod tests {
    use super::*;
    use super::super::element::GRAD_CHUNK;
    use super::super::norm::ConvEpilogue;
    use super::super::simd::supported;

    /// On every instruction set this CPU has: against a naive f64 sum, on offsets of several
    /// chunks (the partials path), none (zeros) and a few pairs, with channel counts that leave
    /// partial row and column tiles; the same bits at one and two threads and on every set.
    #[test]
    fn weight_grad_matches_a_naive_sum() {
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
        let mut first: Option<Vec<f32>> = None;
        for level in supported() {
            let run = || at_level!(level, |V| weight_grad::<V>(&x, c_in, &g, c_out, &pairs));
            let one = rayon::ThreadPoolBuilder::new().num_threads(1).build().unwrap().install(run);
            let two = rayon::ThreadPoolBuilder::new().num_threads(2).build().unwrap().install(run);
            assert!(one == two, "{level:?}: the weight gradient depends on the thread count");
            let first = first.get_or_insert_with(|| one.clone());
            assert!(*first == one, "{level:?}: the weight gradient differs from the widest set's");
            for k in 0..counts.len() {
                for i in 0..c_in {
                    for j in 0..c_out {
                        let want: f64 = (pairs.start[k]..pairs.start[k + 1])
                            .map(|p| x[pairs.input[p] as usize * c_in + i] as f64 * g[pairs.output[p] as usize * c_out + j] as f64)
                            .sum();
                        let got = one[(k * c_in + i) * c_out + j] as f64;
                        assert!((got - want).abs() <= 1e-4 * (1.0 + want.abs()), "{level:?} offset {k} ({i}, {j}): {got} vs {want}");
                    }
                }
            }
        }
    }

    /// The destination-block path (pairs sorted by destination) and the per-offset path (any
    /// order) give the same bits, in both directions, with an identity offset (submanifold),
    /// rows summed from zero (down forward) and rows written once (up forward), at 1 and 2
    /// threads, in channel counts that leave partial panels and row tiles.
    #[test]
    fn destination_blocks_match_the_per_offset_path() {
        use crate::{Coord, CoordIndex, KernelMap};
        let coords: Vec<Coord> = {
            let mut c: Vec<Coord> = (0..3000).map(|i: i32| [i % 2, (i * 7) % 23 - 11, (i * 5) % 19 - 9, (i * 3) % 17 - 8]).collect();
            c.sort();
            c.dedup();
            c
        };
        let index = CoordIndex::build(&coords).unwrap();
        let sub = KernelMap::submanifold(&coords, &index, 3, 1);
        let (down, _) = KernelMap::down(&coords, 2, 1).unwrap();
        let up = down.transposed();
        // The pairs with each offset's order reversed: no longer sorted, so the per-offset path.
        let reversed = |p: &OffsetPairs| {
            let mut r = OffsetPairs { start: p.start.clone(), input: p.input.clone(), output: p.output.clone() };
            for k in 0..p.start.len() - 1 {
                r.input[p.start[k]..p.start[k + 1]].reverse();
                r.output[p.start[k]..p.start[k + 1]].reverse();
            }
            r
        };
        let (c_a, c_b) = (45, 37);
        for map in [&sub, &down, &up] {
            for (direction, pairs, c_src, c_dst, n_src, n_dst) in [
                (PairDirection::Forward, map.pairs(), c_a, c_b, map.n_in(), map.n_out()),
                (PairDirection::Backward, map.pairs_by_input(), c_b, c_a, map.n_out(), map.n_in()),
            ] {
                let src: Vec<f32> = (0..n_src * c_src).map(|i| ((i * 37 % 101) as f32 - 50.0) / 50.0).collect();
                let w: Vec<f32> = (0..map.volume() * c_a * c_b).map(|i| ((i * 53 % 97) as f32 - 48.0) / 480.0).collect();
                let stats: Vec<f32> = (0..2 * c_dst).map(|j| if j < c_dst { 0.1 * (j % 5) as f32 - 0.2 } else { 0.5 + 0.1 * (j % 3) as f32 }).collect();
                let (gamma, beta): (Vec<f32>, Vec<f32>) = (0..c_dst).map(|j| (1.0 + 0.05 * j as f32, 0.02 * j as f32 - 0.3)).unzip();
                let residual: Vec<f32> = (0..n_dst * c_dst).map(|i| ((i * 29 % 89) as f32 - 44.0) / 88.0).collect();
                let mut first: Option<Vec<f32>> = None;
                for level in supported() {
                    let run = |p: &OffsetPairs, threads: usize| {
                        rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap().install(|| at_level!(level, |V| pair_conv::<V>(&src, c_src, &w, c_dst, n_dst, direction, p, map.identity_offset(), None)))
                    };
                    let blocked = run(pairs, 2);
                    assert!(blocked.iter().any(|v| *v != 0.0));
                    let what = format!("{level:?} {:?} {direction:?}", map.kind());
                    assert!(blocked == *first.get_or_insert_with(|| blocked.clone()), "{what}: differs from the widest set's");
                    assert!(blocked == run(&reversed(pairs), 2), "{what}: the two paths differ");
                    assert!(blocked == run(pairs, 1), "{what}: the blocks depend on the thread count");
                    // With a batch norm (+ ReLU, + a residual) on the finished rows: each path applies
                    // it where it finishes rows, with the same result as a pass after the conv.
                    for (relu, residual) in [(true, None), (false, Some(&residual[..]))] {
                        let epilogue = ConvEpilogue::new(&stats, &gamma, &beta, 1e-5, relu, residual);
                        let run = |p: &OffsetPairs| at_level!(level, |V| pair_conv::<V>(&src, c_src, &w, c_dst, n_dst, direction, p, map.identity_offset(), Some(&epilogue)));
                        let mut expected = blocked.clone();
                        epilogue.apply_all(&mut expected);
                        assert!(run(pairs) == expected, "{what}: the blocks' epilogue differs from a pass after");
                        assert!(run(&reversed(pairs)) == expected, "{what}: the per-offset path's epilogue differs");
                    }
                }
            }
        }
    }
}
