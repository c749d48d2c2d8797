//! `Box3d`: the one box type of the workspace, and its convention.

use serde::{Deserialize, Serialize};

/// An upright 3D box in the JRDB base frame (metres, x forward, y left, z up).
///
/// (cx, cy, cz) is the box centre. The footprint corners are `(cx, cy) + R(rot_z)·(±l/2, ±w/2)`
/// with R the counter-clockwise rotation, so `l` lies along the heading; z spans `cz ± h/2`.
/// This is the convention the official evaluator's converter implies (docs/data.md); every in-box
/// test, augmentation, target and export goes through the methods here.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Box3d {
    /// Centre x (metres).
    pub cx: f64,
    /// Centre y (metres).
    pub cy: f64,
    /// Centre z (metres), the middle of the height.
    pub cz: f64,
    /// Length, along the heading.
    pub l: f64,
    /// Width, across the heading.
    pub w: f64,
    /// Height.
    pub h: f64,
    /// Heading (radians, counter-clockwise from +x).
    pub rot_z: f64,
}

impl Box3d {
    /// The four footprint corners, counter-clockwise, starting at (+l/2, +w/2).
    pub fn corners_bev(&self) -> [[f64; 2]; 4] {
        let (s, c) = self.rot_z.sin_cos();
        let (hl, hw) = (self.l / 2.0, self.w / 2.0);
        [[hl, hw], [-hl, hw], [-hl, -hw], [hl, -hw]]
            .map(|[u, v]| [self.cx + c * u - s * v, self.cy + s * u + c * v])
    }

    /// Whether a point lies inside the box (boundary included).
    pub fn contains(&self, p: [f64; 3]) -> bool {
        let (s, c) = self.rot_z.sin_cos();
        let (dx, dy) = (p[0] - self.cx, p[1] - self.cy);
        // Rotate the offset into the box frame: R(-rot_z)·d.
        let u = c * dx + s * dy;
        let v = -s * dx + c * dy;
        u.abs() <= self.l / 2.0 && v.abs() <= self.w / 2.0 && (p[2] - self.cz).abs() <= self.h / 2.0
    }

    /// Footprint area times height.
    pub fn volume(&self) -> f64 {
        self.l * self.w * self.h
    }

    /// The box after rotating the world by `angle` counter-clockwise about the z axis.
    ///
    /// Points rotated by the same R(angle) keep their in-box status, because the heading turns with
    /// them: `rot_z + angle` (a positive angle turns x toward y).
    pub fn rotated_z(&self, angle: f64) -> Box3d {
        let (s, c) = angle.sin_cos();
        Box3d { cx: c * self.cx - s * self.cy, cy: s * self.cx + c * self.cy, rot_z: self.rot_z + angle, ..*self }
    }

    /// The box after scaling the world by `s` about the origin (centre and sizes alike).
    pub fn scaled(&self, s: f64) -> Box3d {
        Box3d { cx: self.cx * s, cy: self.cy * s, cz: self.cz * s, l: self.l * s, w: self.w * s, h: self.h * s, rot_z: self.rot_z }
    }

    /// The box after moving the world by `t` (its centre alike).
    pub fn translated(&self, t: [f64; 3]) -> Box3d {
        Box3d { cx: self.cx + t[0], cy: self.cy + t[1], cz: self.cz + t[2], ..*self }
    }

    /// Number of `points` inside the box (the recount `num_points` is compared with).
    pub fn count_inside(&self, points: &[[f32; 3]]) -> usize {
        points.iter().filter(|p| self.contains([p[0] as f64, p[1] as f64, p[2] as f64])).count()
    }

    /// Distance of the centre from the sensor origin in the ground plane.
    pub fn bev_range(&self) -> f64 {
        self.cx.hypot(self.cy)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn length_lies_along_the_heading() {
        let b = Box3d { cx: 1.0, cy: 2.0, cz: 0.0, l: 2.0, w: 1.0, h: 1.0, rot_z: std::f64::consts::FRAC_PI_2 };
        // Heading +y: the box reaches 1 m along y and 0.5 m along x.
        assert!(b.contains([1.0, 2.99, 0.0]));
        assert!(!b.contains([1.0, 3.01, 0.0]));
        assert!(b.contains([1.49, 2.0, 0.0]));
        assert!(!b.contains([1.51, 2.0, 0.0]));
        let c = b.corners_bev();
        assert!((c[0][0] - 0.5).abs() < 1e-12 && (c[0][1] - 3.0).abs() < 1e-12);
    }
}
