//! Training augmentation, as the authors': a random scale and a random rotation about z, applied to
//! the points and the boxes alike.
//!
//! Sign convention: points are rotated by R(α) (counter-clockwise, x toward y) and each box's
//! `rot_z` grows by α, which keeps every point's in-box status under the `Box3d` convention. The
//! authors rotate points by R(−α) and add α to their opposite-signed heading; with α ~ U(0, 2π) the
//! two are the same distribution.

use rand::Rng;

use crate::box3d::Box3d;

/// Ranges of the random transform.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default)]
pub struct AugmentConfig {
    /// Scale drawn from U(lo, hi).
    pub scale: [f64; 2],
    /// Whether to rotate by α ~ U(0, 2π).
    pub rotate: bool,
}

impl Default for AugmentConfig {
    fn default() -> Self {
        Self { scale: [0.95, 1.05], rotate: true }
    }
}

/// One drawn transform: `p ↦ s · R(α) · p`.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct Augmentation {
    /// Scale s.
    pub scale: f64,
    /// Rotation α about z (radians, counter-clockwise).
    pub angle: f64,
}

impl Augmentation {
    /// Draws a transform.
    pub fn sample<R: Rng + ?Sized>(cfg: &AugmentConfig, rng: &mut R) -> Self {
        let scale = if cfg.scale[0] < cfg.scale[1] { rng.random_range(cfg.scale[0]..cfg.scale[1]) } else { cfg.scale[0] };
        let angle = if cfg.rotate { rng.random_range(0.0..std::f64::consts::TAU) } else { 0.0 };
        Self { scale, angle }
    }

    /// Transforms points in place.
    pub fn apply_points(&self, points: &mut [[f32; 3]]) {
        let (s, c) = self.angle.sin_cos();
        for p in points {
            let (x, y, z) = (p[0] as f64, p[1] as f64, p[2] as f64);
            *p = [(self.scale * (c * x - s * y)) as f32, (self.scale * (s * x + c * y)) as f32, (self.scale * z) as f32];
        }
    }

    /// Transforms a box the same way.
    pub fn apply_box(&self, b: &Box3d) -> Box3d {
        b.rotated_z(self.angle).scaled(self.scale)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    #[test]
    fn points_stay_in_their_boxes() {
        let mut r = rand_chacha::ChaCha8Rng::seed_from_u64(9);
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
            let a = Augmentation::sample(&AugmentConfig::default(), &mut r);
            assert!((0.95..1.05).contains(&a.scale) && (0.0..std::f64::consts::TAU).contains(&a.angle));
            a.apply_points(&mut pts);
            let nb = a.apply_box(&b);
            let after: Vec<bool> = pts.iter().map(|p| nb.contains([p[0] as f64, p[1] as f64, p[2] as f64])).collect();
            assert_eq!(before, after);
            assert!(before.iter().any(|&x| x));
        }
    }
}
