//! The f32 vector the micro-kernels (`micro`) are written over, once per instruction set, and
//! which of them runs on this CPU.
//!
//! Each instruction set is a zero-sized type implementing [`Simd`]: its register type, its
//! width, the rows of a register tile that fit its register file, and the dozen operations the
//! kernels use. A new one (NEON: `float32x4_t`, 4 lanes, `vfmaq_f32`, 32 registers) is one more
//! impl here, its [`Level`] and its feature test in [`level`]; `micro` instantiates its kernels
//! for it with one line.
//!
//! Every kernel sums each output element's terms in the same order whatever the width (one
//! fused multiply-add per term into that element's lane), so every level gives the same bits.

/// An f32 vector type and the operations the micro-kernels need.
///
/// # Safety
/// Implementors' vector methods may only be called on CPUs with the instruction set, from code compiled
/// with it (the `#[target_feature]` entry points `micro` generates); that is why every method is
/// `unsafe`.
pub(crate) unsafe trait Simd: Copy + Send + Sync + 'static {
    /// A register of [`Self::LANES`] floats.
    type V: Copy;
    /// Which lanes of a vector are real (the first `n`).
    type Mask: Copy;
    /// Floats per register.
    const LANES: usize;
    /// Rows of the micro-kernels' register tile (two vectors wide): `2·MR` accumulators, two
    /// vectors of the right-hand side and a broadcast fill the register file.
    const MR: usize;
    /// The instruction set, as the benchmarks print it.
    const NAME: &'static str;

    /// Whether this CPU has the instruction set (the one feature test of each set).
    fn available() -> bool;

    /// The first `min(n, LANES)` lanes.
    fn mask(n: usize) -> Self::Mask;
    /// All lanes zero.
    unsafe fn zero() -> Self::V;
    /// The float at `p` in every lane.
    unsafe fn splat(p: *const f32) -> Self::V;
    /// `LANES` floats at `p`.
    unsafe fn load(p: *const f32) -> Self::V;
    /// The masked lanes at `p`, zero elsewhere; nothing outside them is read.
    unsafe fn load_masked(m: Self::Mask, p: *const f32) -> Self::V;
    /// Writes the masked lanes to `p`; nothing outside them is written.
    unsafe fn store_masked(p: *mut f32, m: Self::Mask, v: Self::V);
    /// `a + b`.
    unsafe fn add(a: Self::V, b: Self::V) -> Self::V;
    /// `a − b`.
    unsafe fn sub(a: Self::V, b: Self::V) -> Self::V;
    /// `a · b`, rounded.
    unsafe fn mul(a: Self::V, b: Self::V) -> Self::V;
    /// `a · b + c`, rounded once.
    unsafe fn fmadd(a: Self::V, b: Self::V, c: Self::V) -> Self::V;
    /// `v` where `z > 0` or `z` is NaN, zero where `z ≤ 0` (ReLU's gradient mask).
    unsafe fn zero_where_not_positive(z: Self::V, v: Self::V) -> Self::V;
    /// The lanes, in the first `LANES` of 16.
    unsafe fn to_array(v: Self::V) -> [f32; 16];
}

/// The SIMD kernels a CPU runs: the widest it has, or narrower where the options ask.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Level {
    /// AVX-512F: 16 lanes, 32 registers.
    #[cfg(target_arch = "x86_64")]
    Avx512,
    /// AVX2 and FMA (x86-64-v3): 8 lanes, 16 registers.
    #[cfg(target_arch = "x86_64")]
    Avx2,
}

impl Level {
    /// The path's name, as the benchmarks print it.
    pub(crate) fn name(self) -> &'static str {
        match self {
            #[cfg(target_arch = "x86_64")]
            Level::Avx512 => x86::Avx512::NAME,
            #[cfg(target_arch = "x86_64")]
            Level::Avx2 => x86::Avx2::NAME,
        }
    }
}

/// The SIMD kernels f32 runs under the current [`KernelOptions`](crate::KernelOptions) on this
/// CPU, or `None` for the general gather–GEMM–scatter path.
pub(crate) fn level() -> Option<Level> {
    let asked = crate::KernelOptions::current().cpu;
    #[cfg(target_arch = "x86_64")]
    {
        use crate::CpuKernels;
        match asked {
            CpuKernels::Generic => None,
            CpuKernels::Auto if Avx512::available() => Some(Level::Avx512),
            CpuKernels::Auto | CpuKernels::Avx2 => Avx2::available().then_some(Level::Avx2),
        }
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        let _ = asked;
        None
    }
}

/// The CPU's SIMD features that matter to the op's kernels, as the benchmarks print them
/// (e.g. `avx512f avx2 fma`; empty where none are detected or on other architectures).
pub fn cpu_features() -> String {
    let mut found: Vec<&str> = Vec::new();
    #[cfg(target_arch = "x86_64")]
    {
        if std::arch::is_x86_feature_detected!("avx512f") {
            found.push("avx512f");
        }
        if std::arch::is_x86_feature_detected!("avx2") {
            found.push("avx2");
        }
        if std::arch::is_x86_feature_detected!("fma") {
            found.push("fma");
        }
    }
    #[cfg(target_arch = "aarch64")]
    if std::arch::is_aarch64_feature_detected!("neon") {
        found.push("neon");
    }
    found.join(" ")
}

/// Which path the op's f32 CPU kernels take on this machine under the current options.
pub fn cpu_kernel_path() -> &'static str {
    match level() {
        Some(level) => level.name(),
        None => "generic gather–GEMM–scatter (matrixmultiply)",
    }
}

/// Every level this CPU can run, widest first (the tests run each).
#[cfg(all(test, target_arch = "x86_64"))]
pub(crate) fn supported() -> Vec<Level> {
    [(Avx512::available(), Level::Avx512), (Avx2::available(), Level::Avx2)].into_iter().filter_map(|(has, level)| has.then_some(level)).collect()
}

#[cfg(target_arch = "x86_64")]
pub(crate) use x86::{Avx2, Avx512};

/// The x86-64 instruction sets.
///
/// Loads and stores go through the masked intrinsics even when every lane is real: the plain
/// ones are a `read_unaligned` / `copy_nonoverlapping`, whose debug-assertion checks (the dev
/// profile keeps them) would sit in the innermost loops. With a constant all-lanes mask LLVM
/// emits the plain `vmovups`. Splats load through `_mm_load_ss` for the same reason.
#[cfg(target_arch = "x86_64")]
mod x86 {
    use std::arch::x86_64::*;

    use super::Simd;

    /// AVX-512F.
    #[derive(Debug, Clone, Copy)]
    pub(crate) struct Avx512;

    // SAFETY: the callers' contract (the trait's) makes AVX-512F present.
    unsafe impl Simd for Avx512 {
        type V = __m512;
        type Mask = __mmask16;
        const LANES: usize = 16;
        // 24 accumulators, 2 panel vectors and a broadcast of the 32 registers.
        const MR: usize = 12;
        const NAME: &'static str = "AVX-512F micro-kernels";

        fn available() -> bool {
            std::arch::is_x86_feature_detected!("avx512f")
        }

        #[inline(always)]
        fn mask(n: usize) -> __mmask16 {
            if n >= 16 { 0xFFFF } else { ((1u32 << n) - 1) as u16 }
        }
        #[inline(always)]
        unsafe fn zero() -> __m512 {
            unsafe { _mm512_setzero_ps() }
        }
        #[inline(always)]
        unsafe fn splat(p: *const f32) -> __m512 {
            unsafe { _mm512_broadcastss_ps(_mm_load_ss(p)) }
        }
        #[inline(always)]
        unsafe fn load(p: *const f32) -> __m512 {
            unsafe { _mm512_maskz_loadu_ps(0xFFFF, p) }
        }
        #[inline(always)]
        unsafe fn load_masked(m: __mmask16, p: *const f32) -> __m512 {
            unsafe { _mm512_maskz_loadu_ps(m, p) }
        }
        #[inline(always)]
        unsafe fn store_masked(p: *mut f32, m: __mmask16, v: __m512) {
            unsafe { _mm512_mask_storeu_ps(p, m, v) }
        }
        #[inline(always)]
        unsafe fn add(a: __m512, b: __m512) -> __m512 {
            unsafe { _mm512_add_ps(a, b) }
        }
        #[inline(always)]
        unsafe fn sub(a: __m512, b: __m512) -> __m512 {
            unsafe { _mm512_sub_ps(a, b) }
        }
        #[inline(always)]
        unsafe fn mul(a: __m512, b: __m512) -> __m512 {
            unsafe { _mm512_mul_ps(a, b) }
        }
        #[inline(always)]
        unsafe fn fmadd(a: __m512, b: __m512, c: __m512) -> __m512 {
            unsafe { _mm512_fmadd_ps(a, b, c) }
        }
        #[inline(always)]
        unsafe fn zero_where_not_positive(z: __m512, v: __m512) -> __m512 {
            unsafe { _mm512_maskz_mov_ps(!_mm512_cmp_ps_mask::<_CMP_LE_OQ>(z, _mm512_setzero_ps()), v) }
        }
        #[inline(always)]
        unsafe fn to_array(v: __m512) -> [f32; 16] {
            let mut a = [0.0f32; 16];
            unsafe { _mm512_mask_storeu_ps(a.as_mut_ptr(), 0xFFFF, v) };
            a
        }
    }

    /// AVX2 with FMA (x86-64-v3: Haswell and later, Zen and later).
    #[derive(Debug, Clone, Copy)]
    pub(crate) struct Avx2;

    /// The real lanes of an AVX2 vector: a lane mask, and whether it is all of them, which takes
    /// the plain load or store (a masked store is microcoded and slow on AMD's cores).
    #[derive(Debug, Clone, Copy)]
    pub(crate) struct Lanes8 {
        all: bool,
        bits: __m256i,
    }

    // SAFETY: the callers' contract (the trait's) makes AVX2 and FMA present.
    unsafe impl Simd for Avx2 {
        type V = __m256;
        type Mask = Lanes8;
        const LANES: usize = 8;
        // 12 accumulators, 2 panel vectors and a broadcast of the 16 registers.
        const MR: usize = 6;
        const NAME: &'static str = "AVX2+FMA micro-kernels";

        fn available() -> bool {
            std::arch::is_x86_feature_detected!("avx2") && std::arch::is_x86_feature_detected!("fma")
        }

        #[inline(always)]
        fn mask(n: usize) -> Lanes8 {
            let n = n.min(8) as i32;
            let lane = [0, 1, 2, 3, 4, 5, 6, 7].map(|i| if i < n { -1i32 } else { 0 });
            // SAFETY: SSE2-only transmute of eight i32 into a 256-bit integer vector (no
            // instruction needed beyond the baseline).
            let bits = unsafe { std::mem::transmute::<[i32; 8], __m256i>(lane) };
            Lanes8 { all: n == 8, bits }
        }
        #[inline(always)]
        unsafe fn zero() -> __m256 {
            unsafe { _mm256_setzero_ps() }
        }
        #[inline(always)]
        unsafe fn splat(p: *const f32) -> __m256 {
            unsafe { _mm256_broadcastss_ps(_mm_load_ss(p)) }
        }
        #[inline(always)]
        unsafe fn load(p: *const f32) -> __m256 {
            unsafe { _mm256_maskload_ps(p, _mm256_set1_epi32(-1)) }
        }
        #[inline(always)]
        unsafe fn load_masked(m: Lanes8, p: *const f32) -> __m256 {
            unsafe { if m.all { Self::load(p) } else { _mm256_maskload_ps(p, m.bits) } }
        }
        #[inline(always)]
        unsafe fn store_masked(p: *mut f32, m: Lanes8, v: __m256) {
            unsafe {
                if m.all {
                    _mm256_maskstore_ps(p, _mm256_set1_epi32(-1), v)
                } else {
                    _mm256_maskstore_ps(p, m.bits, v)
                }
            }
        }
        #[inline(always)]
        unsafe fn add(a: __m256, b: __m256) -> __m256 {
            unsafe { _mm256_add_ps(a, b) }
        }
        #[inline(always)]
        unsafe fn sub(a: __m256, b: __m256) -> __m256 {
            unsafe { _mm256_sub_ps(a, b) }
        }
        #[inline(always)]
        unsafe fn mul(a: __m256, b: __m256) -> __m256 {
            unsafe { _mm256_mul_ps(a, b) }
        }
        #[inline(always)]
        unsafe fn fmadd(a: __m256, b: __m256, c: __m256) -> __m256 {
            unsafe { _mm256_fmadd_ps(a, b, c) }
        }
        #[inline(always)]
        unsafe fn zero_where_not_positive(z: __m256, v: __m256) -> __m256 {
            // "Not less or equal, unordered": true where z > 0 or z is NaN.
            unsafe { _mm256_and_ps(_mm256_cmp_ps::<_CMP_NLE_UQ>(z, _mm256_setzero_ps()), v) }
        }
        #[inline(always)]
        unsafe fn to_array(v: __m256) -> [f32; 16] {
            let mut a = [0.0f32; 16];
            unsafe { Self::store_masked(a.as_mut_ptr(), Self::mask(8), v) };
            a
        }
    }
}

/// What a prefetch asks a cache line for.
#[derive(Debug, Clone, Copy)]
pub(crate) enum Hint {
    /// To read next: into L1.
    Read,
    /// To read later than the next tile: into L2.
    ReadLater,
    /// To write: the line comes in owned, so the stores that follow do not wait for it.
    Write,
}

/// Asks for the cache line holding `p` (any address: a prefetch never faults); a no-op where the
/// architecture has no hint here.
#[inline(always)]
pub(crate) fn prefetch(p: *const f32, hint: Hint) {
    #[cfg(target_arch = "x86_64")]
    {
        use std::arch::x86_64::{_MM_HINT_T0, _MM_HINT_T1, _mm_prefetch};
        // SAFETY: a prefetch of any address is harmless. T0 and T1 are SSE (every x86-64 CPU);
        // PREFETCHW is on every CPU with AVX-512F and on AMD's and Intel's AVX2 cores since
        // Broadwell; the ones before execute its encoding as a NOP.
        match hint {
            Hint::Read => unsafe { _mm_prefetch::<_MM_HINT_T0>(p.cast()) },
            Hint::ReadLater => unsafe { _mm_prefetch::<_MM_HINT_T1>(p.cast()) },
            Hint::Write => unsafe { std::arch::asm!("prefetchw [{p}]", p = in(reg) p, options(nostack, readonly, preserves_flags)) },
        }
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = (p, hint);
}
