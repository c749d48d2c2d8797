//! L2-regularised logistic regression on standardised features, fitted by damped Newton steps.
//!
//! A few hundred features and a few tens of thousands of samples: the Hessian fits in memory and
//! Newton converges in a dozen steps, where gradient descent would need a learning rate tuned per
//! feature set.

use serde::{Deserialize, Serialize};

/// `P(y) = σ(w · (x − mean) / scale + bias)`.
#[derive(Serialize, Deserialize, Debug, Clone, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct LogisticRegression {
    /// Per-feature mean of the training samples.
    pub mean: Vec<f64>,
    /// Per-feature standard deviation of the training samples (+1e-6: constant features read 0).
    pub scale: Vec<f64>,
    /// Weights on the standardised features.
    pub weights: Vec<f64>,
    /// Intercept.
    pub bias: f64,
}

/// Numerically stable `ln(1 + e^m)`.
fn softplus(m: f64) -> f64 {
    if m > 0.0 { m + (-m).exp().ln_1p() } else { m.exp().ln_1p() }
}

fn sigmoid(m: f64) -> f64 {
    0.5 * (1.0 + (0.5 * m).tanh())
}

/// Solves `a · x = b` for a symmetric positive definite `a` (row-major n×n, its lower triangle
/// read) by Cholesky; `None` when `a` is not positive definite.
fn solve_spd(a: &[f64], b: &[f64]) -> Option<Vec<f64>> {
    let n = b.len();
    let mut l = vec![0.0; n * n];
    for i in 0..n {
        for j in 0..=i {
            let s = a[i * n + j] - (0..j).map(|k| l[i * n + k] * l[j * n + k]).sum::<f64>();
            if i == j {
                if s <= 0.0 {
                    return None;
                }
                l[i * n + i] = s.sqrt();
            } else {
                l[i * n + j] = s / l[j * n + j];
            }
        }
    }
    let mut y = vec![0.0; n];
    for i in 0..n {
        y[i] = (b[i] - (0..i).map(|k| l[i * n + k] * y[k]).sum::<f64>()) / l[i * n + i];
    }
    let mut x = vec![0.0; n];
    for i in (0..n).rev() {
        x[i] = (y[i] - (i + 1..n).map(|k| l[k * n + i] * x[k]).sum::<f64>()) / l[i * n + i];
    }
    Some(x)
}

impl LogisticRegression {
    /// Fits `labels` from `samples` (all of one length), minimising the mean log-loss plus
    /// `l2 / 2 · |w|²` (not on the bias, `l2 > 0`: the shares of a histogram sum to one, so
    /// without it the weights are not determined), until a step gains less than 1e-9 or after
    /// 50 steps. An error when the input is empty or ragged, or when no step could be taken (a
    /// singular system, a non-finite loss): a stage that never moved from zero would turn
    /// every box away from the sensor.
    pub fn fit<S: AsRef<[f64]>>(samples: &[S], labels: &[bool], l2: f64) -> Result<Self, String> {
        if samples.is_empty() || samples.len() != labels.len() {
            return Err(format!("{} samples and {} labels (as many, at least one, are needed)", samples.len(), labels.len()));
        }
        if !(l2 > 0.0 && l2.is_finite()) {
            return Err(format!("ridge {l2}: it must be a positive number"));
        }
        let samples: Vec<&[f64]> = samples.iter().map(AsRef::as_ref).collect();
        let (n, d) = (samples.len(), samples[0].len());
        if let Some(s) = samples.iter().find(|s| s.len() != d) {
            return Err(format!("samples of {} and {d} features", s.len()));
        }
        let nf = n as f64;
        let mut mean = vec![0.0; d];
        for s in &samples {
            mean.iter_mut().zip(*s).for_each(|(m, v)| *m += v / nf);
        }
        let mut scale = vec![0.0; d];
        for s in &samples {
            scale.iter_mut().zip(s.iter().zip(&mean)).for_each(|(q, (v, m))| *q += (v - m) * (v - m) / nf);
        }
        scale.iter_mut().for_each(|q| *q = q.sqrt() + 1e-6);
        // Standardised rows with a trailing 1 for the bias.
        let z: Vec<Vec<f64>> = samples.iter().map(|s| s.iter().zip(mean.iter().zip(&scale)).map(|(v, (m, q))| (v - m) / q).chain([1.0]).collect()).collect();
        let y: Vec<f64> = labels.iter().map(|&b| if b { 1.0 } else { 0.0 }).collect();
        let dim = d + 1;
        let reg = |i: usize| if i < d { l2 } else { 0.0 };
        let margins = |w: &[f64]| -> Vec<f64> { z.iter().map(|r| r.iter().zip(w).map(|(a, b)| a * b).sum()).collect() };
        let objective = |w: &[f64]| {
            let m = margins(w);
            m.iter().zip(&y).map(|(m, y)| softplus(*m) - y * m).sum::<f64>() / nf + 0.5 * w.iter().enumerate().map(|(i, v)| reg(i) * v * v).sum::<f64>()
        };
        let mut w = vec![0.0; dim];
        let mut f = objective(&w);
        let mut steps = 0;
        for _ in 0..50 {
            let m = margins(&w);
            let mut grad: Vec<f64> = (0..dim).map(|i| reg(i) * w[i]).collect();
            // Lower triangle of the Hessian, then mirrored.
            let mut hess = vec![0.0; dim * dim];
            for (r, (&mi, &yi)) in z.iter().zip(m.iter().zip(&y)) {
                let p = sigmoid(mi);
                let (g, h) = ((p - yi) / nf, p * (1.0 - p) / nf);
                for i in 0..dim {
                    if r[i] == 0.0 {
                        continue;
                    }
                    grad[i] += g * r[i];
                    let hi = h * r[i];
                    let row = &mut hess[i * dim..i * dim + i + 1];
                    row.iter_mut().zip(&r[..=i]).for_each(|(a, rj)| *a += hi * rj);
                }
            }
            // The solver reads the lower triangle only.
            for i in 0..dim {
                hess[i * dim + i] += reg(i) + 1e-9;
            }
            let Some(step) = solve_spd(&hess, &grad) else { break };
            let mut t = 1.0;
            let mut next: Vec<f64> = w.iter().zip(&step).map(|(a, s)| a - s).collect();
            let mut f_next = objective(&next);
            // `!(a <= b)` rather than `a > b`: a NaN loss is no descent.
            while !(f_next <= f) && t > 1e-4 {
                t *= 0.5;
                next = w.iter().zip(&step).map(|(a, s)| a - t * s).collect();
                f_next = objective(&next);
            }
            if !(f_next <= f) {
                break;
            }
            let gain = f - f_next;
            (w, f) = (next, f_next);
            steps += 1;
            if gain < 1e-9 {
                break;
            }
        }
        if steps == 0 {
            return Err("the fit took no step (a singular system or a non-finite loss)".into());
        }
        let bias = w.pop().expect("the bias");
        Ok(Self { mean, scale, weights: w, bias })
    }

    /// Number of features it reads.
    pub fn len(&self) -> usize {
        self.weights.len()
    }

    /// Whether it reads no feature.
    pub fn is_empty(&self) -> bool {
        self.weights.is_empty()
    }

    /// `P(y = true | x)`; `x` must have [`len`](Self::len) features.
    pub fn probability(&self, x: &[f64]) -> f64 {
        let m: f64 = x.iter().zip(self.mean.iter().zip(self.scale.iter().zip(&self.weights))).map(|(v, (m, (s, w)))| w * (v - m) / s).sum();
        sigmoid(m + self.bias)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    #[test]
    fn cholesky_solves_a_hand_system() {
        // [[4, 2], [2, 3]] x = [2, 1] → x = [0.5, 0].
        let x = solve_spd(&[4.0, 2.0, 2.0, 3.0], &[2.0, 1.0]).unwrap();
        assert!((x[0] - 0.5).abs() < 1e-12 && x[1].abs() < 1e-12);
        assert!(solve_spd(&[1.0, 2.0, 2.0, 1.0], &[1.0, 1.0]).is_none());
    }

    #[test]
    fn recovers_the_weights_that_drew_the_labels() {
        // Labels drawn from σ(2·x0 − x1 + 0.5) with standard normal features: with many samples
        // and almost no ridge the fit returns those weights (scale ≈ 1, mean ≈ 0).
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        let normal = |rng: &mut rand_chacha::ChaCha8Rng| {
            let (u, v): (f64, f64) = (rng.random::<f64>().max(1e-12), rng.random());
            (-2.0 * u.ln()).sqrt() * (std::f64::consts::TAU * v).cos()
        };
        let (mut xs, mut ys) = (Vec::new(), Vec::new());
        for _ in 0..20_000 {
            let x = vec![normal(&mut rng), normal(&mut rng), normal(&mut rng)];
            let p = sigmoid(2.0 * x[0] - x[1] + 0.5);
            ys.push(rng.random::<f64>() < p);
            xs.push(x);
        }
        let m = LogisticRegression::fit(&xs, &ys, 1e-6).unwrap();
        let w: Vec<f64> = (0..3).map(|i| m.weights[i] / m.scale[i]).collect();
        let b = m.bias - (0..3).map(|i| w[i] * m.mean[i]).sum::<f64>();
        assert!((w[0] - 2.0).abs() < 0.1 && (w[1] + 1.0).abs() < 0.1 && w[2].abs() < 0.1 && (b - 0.5).abs() < 0.1, "{w:?} {b}");
        // Probability reads the same model.
        assert!((m.probability(&[0.0, 0.0, 0.0]) - sigmoid(b)).abs() < 1e-12);
    }

    #[test]
    fn separable_data_stops_without_diverging() {
        // Perfectly separable: the ridge keeps the weights finite and every label right.
        let xs: Vec<Vec<f64>> = (0..100).map(|i| vec![i as f64, 0.0]).collect();
        let ys: Vec<bool> = (0..100).map(|i| i >= 50).collect();
        let m = LogisticRegression::fit(&xs, &ys, 1e-2).unwrap();
        assert!(m.weights.iter().all(|w| w.is_finite()));
        assert!(xs.iter().zip(&ys).all(|(x, &y)| (m.probability(x) > 0.5) == y));
    }

    /// At the fit the objective's gradient, written out here from its definition, vanishes: with
    /// a constant column (standardised to zeros) and sparse 0/1 columns like a histogram's, so
    /// both the Hessian's skipped zero entries and the ridge are exercised.
    #[test]
    fn the_fit_is_a_stationary_point_of_the_objective() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(9);
        let (mut xs, mut ys) = (Vec::new(), Vec::new());
        for _ in 0..3_000 {
            let x: Vec<f64> = vec![1.0, (rng.random::<f64>() < 0.2) as u8 as f64, (rng.random::<f64>() < 0.6) as u8 as f64, rng.random::<f64>()];
            ys.push(rng.random::<f64>() < sigmoid(1.5 * x[1] - 2.0 * x[2] + x[3]));
            xs.push(x);
        }
        let l2 = 0.05;
        let m = LogisticRegression::fit(&xs, &ys, l2).unwrap();
        let n = xs.len() as f64;
        let z = |x: &[f64], i: usize| (x[i] - m.mean[i]) / m.scale[i];
        let mut grad = vec![0.0; 5];
        for (x, &y) in xs.iter().zip(&ys) {
            let r = m.probability(x) - if y { 1.0 } else { 0.0 };
            (0..4).for_each(|i| grad[i] += r * z(x, i) / n);
            grad[4] += r / n;
        }
        (0..4).for_each(|i| grad[i] += l2 * m.weights[i]);
        assert!(grad.iter().all(|g| g.abs() < 1e-6), "{grad:?}");
        assert!(m.weights[0].abs() < 1e-12, "a constant column carries no weight: {}", m.weights[0]);
        assert!(LogisticRegression::fit(&xs, &ys, 0.0).is_err(), "no ridge");
        assert!(LogisticRegression::fit(&xs[..0], &ys[..0], l2).is_err(), "no sample");
    }
}
