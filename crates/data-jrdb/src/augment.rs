//! Training augmentation: the authors' random scale and rotation about z, applied to the points
//! and the boxes alike, and three perturbations of our own, each off unless configured: a random
//! translation (points and boxes), per-point jitter and random point dropout (points only).
//!
//! Sign convention: points are rotated by R(α) (counter-clockwise, x toward y) and each box's
//! `rot_z` grows by α, which keeps every point's in-box status under the `Box3d` convention. The
//! authors rotate points by R(−α) and add α to their opposite-signed heading; with α ~ U(0, 2π) the
//! two are the same distribution.
//!
//! Invariant: a perturbation that is off draws nothing from the generator, so a config without
//! them gives the same samples, bit for bit, as before they existed (runs resume exactly).

use rand::Rng;
use rand_distr::{Distribution, Normal};

use crate::box3d::Box3d;

/// Ranges of the random transform and perturbations.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default)]
pub struct AugmentConfig {
    /// Scale drawn from U(lo, hi).
    pub scale: [f64; 2],
    /// Whether to rotate by α ~ U(0, 2π).
    pub rotate: bool,
    /// Half-ranges of a translation t, t_i ~ U(−h_i, h_i), applied after the scale and turn (m).
    pub translate: [f64; 3],
    /// Standard deviation of each point's own Gaussian displacement along each axis (m).
    pub jitter: f64,
    /// Largest fraction of a frame's points dropped; the fraction is drawn from U(0, drop).
    pub drop: f64,
}

impl Default for AugmentConfig {
    fn default() -> Self {
        Self { scale: [0.95, 1.05], rotate: true, translate: [0.0; 3], jitter: 0.0, drop: 0.0 }
    }
}

/// One drawn transform: `p ↦ s · R(α) · p + t`.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct Augmentation {
    /// Scale s.
    pub scale: f64,
    /// Rotation α about z (radians, counter-clockwise).
    pub angle: f64,
    /// Translation t (m).
    pub translation: [f64; 3],
}

impl Augmentation {
    /// Draws a transform.
    pub fn sample<R: Rng + ?Sized>(cfg: &AugmentConfig, rng: &mut R) -> Self {
        let scale = if cfg.scale[0] < cfg.scale[1] { rng.random_range(cfg.scale[0]..cfg.scale[1]) } else { cfg.scale[0] };
        let angle = if cfg.rotate { rng.random_range(0.0..std::f64::consts::TAU) } else { 0.0 };
        let translation = cfg.translate.map(|h| if h > 0.0 { rng.random_range(-h..h) } else { 0.0 });
        Self { scale, angle, translation }
    }

    /// Transforms points in place.
    pub fn apply_points(&self, points: &mut [[f32; 3]]) {
        let (s, c) = self.angle.sin_cos();
        let t = self.translation;
        for p in points {
            let (x, y, z) = (p[0] as f64, p[1] as f64, p[2] as f64);
            *p = [(self.scale * (c * x - s * y) + t[0]) as f32, (self.scale * (s * x + c * y) + t[1]) as f32, (self.scale * z + t[2]) as f32];
        }
    }

    /// Transforms a box the same way.
    pub fn apply_box(&self, b: &Box3d) -> Box3d {
        b.rotated_z(self.angle).scaled(self.scale).translated(self.translation)
    }
}

/// Drops a random fraction of the points, then jitters the rest: what real returns do that a
/// ray-cast or a single scan does not show the network (boxes are left as they are).
pub fn perturb_points<R: Rng + ?Sized>(cfg: &AugmentConfig, points: &mut Vec<[f32; 3]>, rng: &mut R) {
    if cfg.drop > 0.0 {
        let fraction = rng.random_range(0.0..cfg.drop);
        points.retain(|_| rng.random::<f64>() >= fraction);
    }
    if cfg.jitter > 0.0 {
        let normal = Normal::new(0.0, cfg.jitter).expect("jitter is validated finite and positive");
        for p in points.iter_mut() {
            for v in p.iter_mut() {
                *v = (*v as f64 + normal.sample(rng)) as f32;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    fn rng(seed: u64) -> rand_chacha::ChaCha8Rng {
        rand_chacha::ChaCha8Rng::seed_from_u64(seed)
    }

    fn points_stay_in_their_boxes(cfg: &AugmentConfig) {
        let mut r = rng(9);
        for _ in 0..50 {
            let b = Box3d { cx: r.random_range(-10.0..10.0), cy: r.random_range(-10.0..10.0), cz: 0.1, l: 0.9, w: 0.5, h: 1.7, rot_z: r.random_range(-3.0..3.0) };
            let mut pts: Vec<[f32; 3]> = (0..200)
                .map(|_| [(b.cx + r.random_range(-1.0..1.0)) as f32, (b.cy + r.random_range(-1.0..1.0)) as f32, r.random_range(-1.0..1.2)])
                .collect();
            // Stay clear of the faces so f32 rounding cannot flip a point.
            let margin = |p: &[f32; 3], bb: &Box3d| {
                let inner = Box3d { l: bb.l - 2e-3, w: bb.w - 2e-3, h: bb.h - 2e-3, ..*bb };
                let outer = Box3d { l: bb.l + 2e-3, w: bb.w + 2e-3, h: bb.h + 2e-3, ..*bb };
                let q = [p[0] as f64, p[1] as f64, p[2] as f64];
                inner.contains(q) == outer.contains(q)
            };
            pts.retain(|p| margin(p, &b));
            let before: Vec<bool> = pts.iter().map(|p| b.contains([p[0] as f64, p[1] as f64, p[2] as f64])).collect();
            let a = Augmentation::sample(cfg, &mut r);
            assert!((0.95..1.05).contains(&a.scale) && (0.0..std::f64::consts::TAU).contains(&a.angle));
            for (t, h) in a.translation.iter().zip(cfg.translate) {
                assert!(t.abs() <= h, "translation {t} outside ±{h}");
            }
            a.apply_points(&mut pts);
            let nb = a.apply_box(&b);
            let after: Vec<bool> = pts.iter().map(|p| nb.contains([p[0] as f64, p[1] as f64, p[2] as f64])).collect();
            assert_eq!(before, after);
            assert!(before.iter().any(|&x| x));
        }
    }

    #[test]
    fn points_stay_in_their_boxes_under_scale_and_turn() {
        points_stay_in_their_boxes(&AugmentConfig::default());
    }

    #[test]
    fn points_stay_in_their_boxes_under_a_translation() {
        points_stay_in_their_boxes(&AugmentConfig { translate: [0.5, 0.5, 0.1], ..AugmentConfig::default() });
    }

    #[test]
    fn the_translation_is_drawn_over_its_range() {
        let cfg = AugmentConfig { translate: [0.5, 0.0, 0.1], ..AugmentConfig::default() };
        let mut r = rng(3);
        let ts: Vec<[f64; 3]> = (0..2000).map(|_| Augmentation::sample(&cfg, &mut r).translation).collect();
        assert!(ts.iter().all(|t| t[1] == 0.0 && t[0].abs() < 0.5 && t[2].abs() < 0.1));
        let mean_abs = |i: usize| ts.iter().map(|t| t[i].abs()).sum::<f64>() / ts.len() as f64;
        // |U(−h, h)| has mean h/2.
        assert!((mean_abs(0) - 0.25).abs() < 0.02 && (mean_abs(2) - 0.05).abs() < 0.004, "{} {}", mean_abs(0), mean_abs(2));
    }

    #[test]
    fn perturbations_that_are_off_draw_nothing() {
        let off = AugmentConfig::default();
        let (mut a, mut b) = (rng(5), rng(5));
        let t = Augmentation::sample(&off, &mut a);
        let mut pts = vec![[1.0f32, 2.0, 3.0]; 100];
        perturb_points(&off, &mut pts, &mut a);
        assert_eq!(pts, vec![[1.0f32, 2.0, 3.0]; 100]);
        assert_eq!(t.translation, [0.0; 3]);
        // The generator is where the scale and the turn alone leave it.
        b.random_range(0.95..1.05);
        b.random_range(0.0..std::f64::consts::TAU);
        assert_eq!(a.random::<u64>(), b.random::<u64>());
    }

    #[test]
    fn dropout_removes_up_to_its_fraction() {
        let cfg = AugmentConfig { drop: 0.2, ..AugmentConfig::default() };
        let mut r = rng(11);
        let n = 20_000;
        let kept: Vec<f64> = (0..200)
            .map(|_| {
                let mut pts = vec![[0.0f32; 3]; n];
                perturb_points(&cfg, &mut pts, &mut r);
                pts.len() as f64 / n as f64
            })
            .collect();
        // Kept fraction 1 − U(0, 0.2), up to the binomial's ±1 %: within [0.79, 1], mean 0.9.
        assert!(kept.iter().all(|&k| (0.79..=1.0).contains(&k)), "{kept:?}");
        let mean = kept.iter().sum::<f64>() / kept.len() as f64;
        assert!((mean - 0.9).abs() < 0.01, "mean kept {mean}");
        assert!(kept.iter().any(|&k| k < 0.83) && kept.iter().any(|&k| k > 0.97));
    }

    #[test]
    fn jitter_has_its_deviation_in_every_axis() {
        let cfg = AugmentConfig { jitter: 0.02, ..AugmentConfig::default() };
        let mut r = rng(13);
        let origin = [5.0f32, -3.0, 1.0];
        let mut pts = vec![origin; 50_000];
        perturb_points(&cfg, &mut pts, &mut r);
        for k in 0..3 {
            let d: Vec<f64> = pts.iter().map(|p| (p[k] - origin[k]) as f64).collect();
            let mean = d.iter().sum::<f64>() / d.len() as f64;
            let sd = (d.iter().map(|x| (x - mean) * (x - mean)).sum::<f64>() / d.len() as f64).sqrt();
            assert!(mean.abs() < 3e-4 && (sd - 0.02).abs() < 4e-4, "axis {k}: mean {mean}, sd {sd}");
        }
    }
}
