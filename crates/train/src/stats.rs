//! The statistics a sweep's tables report over seeds: mean and sample standard deviation, the 95 %
//! interval of a mean (Student's t), and of a difference of two means (Welch's t), which says
//! whether one variant ranks above another beyond the seeds' spread.

/// Mean and sample standard deviation (n − 1; 0 for one value).
pub fn mean_std(xs: &[f64]) -> (f64, f64) {
    let n = xs.len() as f64;
    if xs.is_empty() {
        return (f64::NAN, f64::NAN);
    }
    let m = xs.iter().sum::<f64>() / n;
    let s = if xs.len() > 1 { (xs.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (n - 1.0)).sqrt() } else { 0.0 };
    (m, s)
}

/// `t_{0.975, df}` for `df ≥ 1` degrees of freedom, rounded down to a whole number (a
/// fractional df, as Welch's, gets the wider interval of the df below it).
fn t975(df: f64) -> f64 {
    // df = 1..=30; beyond, the normal 1.96 is within 2 %.
    const T: [f64; 30] = [
        12.706, 4.303, 3.182, 2.776, 2.571, 2.447, 2.365, 2.306, 2.262, 2.228, 2.201, 2.179, 2.160, 2.145, 2.131, 2.120, 2.110, 2.101, 2.093, 2.086,
        2.080, 2.074, 2.069, 2.064, 2.060, 2.056, 2.052, 2.048, 2.045, 2.042,
    ];
    T.get((df.floor().max(1.0) as usize) - 1).copied().unwrap_or(1.96)
}

/// Half-width of the two-sided 95 % confidence interval of the mean of `n` values with sample
/// standard deviation `std` (Student's t with n − 1 degrees of freedom); NaN below 2 values.
pub fn ci95_half_width(n: usize, std: f64) -> f64 {
    if n < 2 {
        return f64::NAN;
    }
    t975((n - 1) as f64) * std / (n as f64).sqrt()
}

/// The difference of two means, `mean(a) − mean(b)`, and the half-width of its two-sided 95 %
/// interval by Welch's t (unequal variances, Welch–Satterthwaite degrees of freedom rounded
/// down): whether one variant ranks above another beyond the seeds' spread. NaN half-width below
/// 2 values on either side.
pub fn welch_ci95(a: &[f64], b: &[f64]) -> (f64, f64) {
    let ((ma, sa), (mb, sb)) = (mean_std(a), mean_std(b));
    if a.len() < 2 || b.len() < 2 {
        return (ma - mb, f64::NAN);
    }
    let (va, vb) = (sa * sa / a.len() as f64, sb * sb / b.len() as f64);
    let se2 = va + vb;
    if se2 == 0.0 {
        return (ma - mb, 0.0);
    }
    let df = se2 * se2 / (va * va / (a.len() - 1) as f64 + vb * vb / (b.len() - 1) as f64);
    (ma - mb, t975(df) * se2.sqrt())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn mean_and_sample_std() {
        let (m, s) = mean_std(&[1.0, 2.0, 3.0]);
        assert!((m - 2.0).abs() < 1e-12 && (s - 1.0).abs() < 1e-12);
        assert_eq!(mean_std(&[0.5]), (0.5, 0.0));
        assert!(mean_std(&[]).0.is_nan());
    }

    #[test]
    fn ci95_uses_students_t() {
        // n = 3, std 1: t_{0.975, 2} = 4.303, / √3.
        assert!((ci95_half_width(3, 1.0) - 4.303 / 3f64.sqrt()).abs() < 1e-12);
        assert!(ci95_half_width(1, 1.0).is_nan());
        assert!((ci95_half_width(100, 2.0) - 1.96 * 0.2).abs() < 1e-12);
    }

    #[test]
    fn welch_interval_of_a_difference() {
        // Hand-derived: both std 1, n = 3: se² = 1/3 + 1/3, df = (2/3)² / (2 · (1/3)² / 2) = 4,
        // t_{0.975, 4} = 2.776.
        let (d, h) = welch_ci95(&[1.0, 2.0, 3.0], &[4.0, 5.0, 6.0]);
        assert!((d + 3.0).abs() < 1e-12 && (h - 2.776 * (2.0f64 / 3.0).sqrt()).abs() < 1e-12, "{d} {h}");
        // Unequal variances: a's std 1 (n = 3), b's std 3 (n = 2): va = 1/3, vb = 4.5,
        // df = (29/6)² / ((1/3)²/2 + 4.5²) = 1.15, rounded down to 1: t = 12.706.
        let (d, h) = welch_ci95(&[1.0, 2.0, 3.0], &[0.0, 4.2426406871192848]);
        let se = (1.0f64 / 3.0 + 4.5).sqrt();
        assert!((d - (2.0 - 2.1213203435596424)).abs() < 1e-12 && (h - 12.706 * se).abs() < 1e-9, "{d} {h}");
        assert!(welch_ci95(&[1.0], &[2.0, 3.0]).1.is_nan());
        assert_eq!(welch_ci95(&[1.0, 1.0], &[2.0, 2.0]), (-1.0, 0.0));
    }
}
