//! f32, the type training runs in: its GEMM, and its hooks to the SIMD micro-kernels where the
//! CPU has them (the general kernels otherwise).

use super::element::{Element, PairDirection, RowEpilogue};
use super::micro::{self, at_level};
use super::simd::level;
use crate::geometry::kernel_map::OffsetPairs;

impl Element for f32 {
    unsafe fn gemm(
        m: usize, k: usize, n: usize,
        a: *const f32, rsa: isize, csa: isize,
        b: *const f32, rsb: isize, csb: isize,
        beta: f32, c: *mut f32, rsc: isize, csc: isize,
    ) {
        unsafe { matrixmultiply::sgemm(m, k, n, 1.0, a, rsa, csa, b, rsb, csb, beta, c, rsc, csc) }
    }
    const ZERO: f32 = 0.0;
    const ONE: f32 = 1.0;
    fn to_f64(self) -> f64 {
        self as f64
    }
    fn from_f64(v: f64) -> f32 {
        v as f32
    }
    fn sqrt(self) -> f32 {
        f32::sqrt(self)
    }

    fn weight_grad_native(x: &[f32], c_in: usize, grad_out: &[f32], c_out: usize, pairs: &OffsetPairs) -> Option<Vec<f32>> {
        let level = level()?;
        Some(at_level!(level, |V| micro::weight_grad::<V>(x, c_in, grad_out, c_out, pairs)))
    }

    fn stats_sums_native(x: &[f32], c: usize, shift: &[f32]) -> Option<Vec<f64>> {
        let level = level()?;
        Some(at_level!(level, |V| micro::stats_sums::<V>(x, c, shift)))
    }

    fn param_sums_native(x: &[f32], g: &[f32], c: usize, a: &[f32], b: &[f32], mean: &[f32], relu: bool) -> Option<Vec<f64>> {
        let level = level()?;
        Some(at_level!(level, |V| micro::param_sums::<V>(x, g, c, a, b, mean, relu)))
    }

    fn pair_conv_native(
        src: &[f32], c_src: usize, weight: &[f32], c_dst: usize, n_dst: usize,
        direction: PairDirection, pairs: &OffsetPairs, identity: Option<usize>, epilogue: Option<&dyn RowEpilogue<f32>>,
    ) -> Option<Vec<f32>> {
        let level = level()?;
        Some(at_level!(level, |V| micro::pair_conv::<V>(src, c_src, weight, c_dst, n_dst, direction, pairs, identity, epilogue)))
    }
}
