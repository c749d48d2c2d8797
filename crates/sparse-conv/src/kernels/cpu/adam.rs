//! One Adam step over slices, the parameter and both moments in one pass (the arithmetic of
//! `crate::optim::adam`'s module docs, Burn's operation for operation).

use rayon::prelude::*;

use super::element::{Element, assume_init, scratch, vectorized};
use crate::parallel::SyncPtr;

/// The scalars of one step, in the parameter's type.
#[derive(Debug, Clone, Copy)]
pub struct AdamScalars<T> {
    /// Learning rate.
    pub lr: T,
    /// β₁, the first moment's decay.
    pub beta_1: T,
    /// β₂, the second moment's decay.
    pub beta_2: T,
    /// λ, 0 without weight decay.
    pub weight_decay: T,
    /// `c = √(1 − β₂ᵗ) / (1 − β₁ᵗ)`.
    pub correction: T,
    /// `ε·√(1 − β₂ᵗ)`.
    pub epsilon: T,
}

impl<T: Element> AdamScalars<T> {
    /// From [`AdamBackend::adam_step`]'s arguments.
    pub fn new(lr: f64, beta_1: f64, beta_2: f64, weight_decay: f64, correction: f64, epsilon: f64) -> Self {
        let t = T::from_f64;
        AdamScalars { lr: t(lr), beta_1: t(beta_1), beta_2: t(beta_2), weight_decay: t(weight_decay), correction: t(correction), epsilon: t(epsilon) }
    }
}

/// Elements per parallel task.
const CHUNK: usize = 1 << 15;

/// One Adam step over slices: `[θ'.., m₁'.., m₂'..]` (see the module's formulas); with
/// `max_moment_2` (AMSGrad) also the new running maximum of m₂, which the step divides by.
pub fn adam_update<T: Element>(param: &[T], grad: &[T], moment_1: &[T], moment_2: &[T], max_moment_2: Option<&[T]>, s: AdamScalars<T>) -> Vec<T> {
    let n = param.len();
    assert!(grad.len() == n && moment_1.len() == n && moment_2.len() == n && max_moment_2.is_none_or(|m| m.len() == n), "Adam's parameter, gradient and moments differ in size");
    let regions = 3 + max_moment_2.is_some() as usize;
    let mut out = scratch::<T>(regions * n);
    let out_ptr = SyncPtr(out.as_mut_ptr().cast::<T>());
    let out_ptr = &out_ptr;
    (0..n.div_ceil(CHUNK)).into_par_iter().for_each(|chunk| {
        let range = chunk * CHUNK..((chunk + 1) * CHUNK).min(n);
        // SAFETY: each region's part for this chunk is written by this task only.
        let at = |region: usize| unsafe { std::slice::from_raw_parts_mut(out_ptr.0.add(region * n + range.start), range.len()) };
        let (p, m1, m2) = (at(0), at(1), at(2));
        let inputs = [param, grad, moment_1, moment_2].map(|v| &v[range.clone()]);
        match max_moment_2 {
            Some(max) => vectorized(|| adam_chunk::<T, true>(inputs, &max[range.clone()], s, [p, m1, m2, at(3)])),
            None => vectorized(|| adam_chunk::<T, false>(inputs, &[], s, [p, m1, m2, &mut []])),
        }
    });
    // SAFETY: the chunks cover every element of every region.
    unsafe { assume_init(out) }
}

/// One chunk of [`adam_update`]: `out` is `[θ', m₁', m₂', max]` (`max` empty without AMSGRAD).
#[inline(always)]
fn adam_chunk<T: Element, const AMSGRAD: bool>(inputs: [&[T]; 4], max_moment_2: &[T], s: AdamScalars<T>, out: [&mut [T]; 4]) {
    let (one_minus_beta_1, one_minus_beta_2) = (T::ONE - s.beta_1, T::ONE - s.beta_2);
    let [param, grad, moment_1, moment_2] = inputs;
    let n = param.len();
    let [p, m1, m2, max] = out;
    let (grad, moment_1, moment_2, p, m1, m2) = (&grad[..n], &moment_1[..n], &moment_2[..n], &mut p[..n], &mut m1[..n], &mut m2[..n]);
    let (max_moment_2, max) = if AMSGRAD { (&max_moment_2[..n], &mut max[..n]) } else { (max_moment_2, max) };
    for j in 0..n {
        let g = if s.weight_decay == T::ZERO { grad[j] } else { param[j] * s.weight_decay + grad[j] };
        let a = moment_1[j] * s.beta_1 + g * one_minus_beta_1;
        let b = moment_2[j] * s.beta_2 + g * g * one_minus_beta_2;
        let v = if AMSGRAD {
            let v = if max_moment_2[j] < b { b } else { max_moment_2[j] };
            max[j] = v;
            v
        } else {
            b
        };
        let step = a * s.correction / (v.sqrt() + s.epsilon);
        p[j] = param[j] - step * s.lr;
        m1[j] = a;
        m2[j] = b;
    }
}
