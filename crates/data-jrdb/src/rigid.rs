//! `Rigid`: a rotation and a translation, the one place the datasets' frame changes are done.
//!
//! KITTI gives its transforms as 3×4 matrices and nuScenes as a translation with a unit
//! quaternion `[w, x, y, z]`; both become a `Rigid` mapping `p ↦ R·p + t`, and boxes move with
//! their points (the centre by the full transform, the heading by the rotated length axis).

use crate::box3d::Box3d;

/// `p ↦ rotation · p + translation`, in f64.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Rigid {
    /// Row-major rotation matrix.
    pub rotation: [[f64; 3]; 3],
    /// Translation, applied after the rotation.
    pub translation: [f64; 3],
}

impl Default for Rigid {
    fn default() -> Self {
        Self::IDENTITY
    }
}

impl Rigid {
    /// The identity.
    pub const IDENTITY: Rigid = Rigid { rotation: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]], translation: [0.0; 3] };

    /// A translation alone.
    pub fn translation(t: [f64; 3]) -> Self {
        Self { translation: t, ..Self::IDENTITY }
    }

    /// From a unit quaternion `[w, x, y, z]` (nuScenes' order) and a translation; the quaternion
    /// is normalised first, so a table's rounding does not scale points.
    pub fn from_quaternion(q: [f64; 4], translation: [f64; 3]) -> Self {
        let n = (q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]).sqrt();
        let [w, x, y, z] = q.map(|v| v / n);
        let rotation = [
            [1.0 - 2.0 * (y * y + z * z), 2.0 * (x * y - w * z), 2.0 * (x * z + w * y)],
            [2.0 * (x * y + w * z), 1.0 - 2.0 * (x * x + z * z), 2.0 * (y * z - w * x)],
            [2.0 * (x * z - w * y), 2.0 * (y * z + w * x), 1.0 - 2.0 * (x * x + y * y)],
        ];
        Self { rotation, translation }
    }

    /// A rotation about z by `yaw` and a translation.
    pub fn from_yaw(yaw: f64, translation: [f64; 3]) -> Self {
        Self::from_quaternion([(yaw / 2.0).cos(), 0.0, 0.0, (yaw / 2.0).sin()], translation)
    }

    /// The quaternion `[w, x, y, z]` of the rotation (w ≥ 0).
    pub fn quaternion(&self) -> [f64; 4] {
        let r = &self.rotation;
        let trace = r[0][0] + r[1][1] + r[2][2];
        let q = if trace > 0.0 {
            let s = 2.0 * (trace + 1.0).sqrt();
            [s / 4.0, (r[2][1] - r[1][2]) / s, (r[0][2] - r[2][0]) / s, (r[1][0] - r[0][1]) / s]
        } else if r[0][0] > r[1][1] && r[0][0] > r[2][2] {
            let s = 2.0 * (1.0 + r[0][0] - r[1][1] - r[2][2]).sqrt();
            [(r[2][1] - r[1][2]) / s, s / 4.0, (r[0][1] + r[1][0]) / s, (r[0][2] + r[2][0]) / s]
        } else if r[1][1] > r[2][2] {
            let s = 2.0 * (1.0 + r[1][1] - r[0][0] - r[2][2]).sqrt();
            [(r[0][2] - r[2][0]) / s, (r[0][1] + r[1][0]) / s, s / 4.0, (r[1][2] + r[2][1]) / s]
        } else {
            let s = 2.0 * (1.0 + r[2][2] - r[0][0] - r[1][1]).sqrt();
            [(r[1][0] - r[0][1]) / s, (r[0][2] + r[2][0]) / s, (r[1][2] + r[2][1]) / s, s / 4.0]
        };
        if q[0] < 0.0 { q.map(|v| -v) } else { q }
    }

    /// From the first three rows of a row-major 3×4 or 4×4 matrix `[R | t]`.
    pub fn from_matrix_3x4(m: &[f64]) -> Self {
        Self { rotation: [[m[0], m[1], m[2]], [m[4], m[5], m[6]], [m[8], m[9], m[10]]], translation: [m[3], m[7], m[11]] }
    }

    /// The row-major 3×4 matrix `[R | t]`.
    pub fn to_matrix_3x4(&self) -> [f64; 12] {
        let (r, t) = (&self.rotation, &self.translation);
        [r[0][0], r[0][1], r[0][2], t[0], r[1][0], r[1][1], r[1][2], t[1], r[2][0], r[2][1], r[2][2], t[2]]
    }

    /// `self ∘ other`: first `other`, then `self`.
    pub fn then_after(&self, other: &Rigid) -> Rigid {
        let mut rotation = [[0.0; 3]; 3];
        for (i, row) in rotation.iter_mut().enumerate() {
            for (j, v) in row.iter_mut().enumerate() {
                *v = (0..3).map(|k| self.rotation[i][k] * other.rotation[k][j]).sum();
            }
        }
        Rigid { rotation, translation: self.apply(other.translation) }
    }

    /// The inverse transform `(R⁻¹, −R⁻¹·t)`. R⁻¹ is the true inverse (by cofactors), not the
    /// transpose: a calibration's estimated rotation (KITTI's `Tr_velo_to_cam`) is orthonormal
    /// only to a few parts in 10⁴.
    pub fn inverse(&self) -> Rigid {
        let r = &self.rotation;
        let cof = |i: usize, j: usize| {
            let (a, b) = ((i + 1) % 3, (i + 2) % 3);
            let (c, d) = ((j + 1) % 3, (j + 2) % 3);
            r[a][c] * r[b][d] - r[a][d] * r[b][c]
        };
        let det = r[0][0] * cof(0, 0) + r[0][1] * cof(0, 1) + r[0][2] * cof(0, 2);
        let rotation = [0, 1, 2].map(|i| [0, 1, 2].map(|j| cof(j, i) / det));
        let t = self.translation;
        let translation = [0, 1, 2].map(|i| -(rotation[i][0] * t[0] + rotation[i][1] * t[1] + rotation[i][2] * t[2]));
        Rigid { rotation, translation }
    }

    /// The rotation alone applied to a vector.
    pub fn rotate(&self, v: [f64; 3]) -> [f64; 3] {
        let r = &self.rotation;
        [0, 1, 2].map(|i| r[i][0] * v[0] + r[i][1] * v[1] + r[i][2] * v[2])
    }

    /// A point moved.
    pub fn apply(&self, p: [f64; 3]) -> [f64; 3] {
        let v = self.rotate(p);
        [v[0] + self.translation[0], v[1] + self.translation[1], v[2] + self.translation[2]]
    }

    /// An f32 point moved (computed in f64).
    pub fn apply_f32(&self, p: [f32; 3]) -> [f32; 3] {
        self.apply(p.map(f64::from)).map(|v| v as f32)
    }

    /// An upright box moved: its centre by the transform, its heading by where the rotation takes
    /// its length axis, projected on the ground plane. Exact for rotations about z; for a small
    /// tilt the box stays upright (our boxes have no roll or pitch).
    pub fn apply_box(&self, b: &Box3d) -> Box3d {
        let [cx, cy, cz] = self.apply([b.cx, b.cy, b.cz]);
        let axis = self.rotate([b.rot_z.cos(), b.rot_z.sin(), 0.0]);
        Box3d { cx, cy, cz, rot_z: axis[1].atan2(axis[0]), ..*b }
    }

    /// The heading (yaw, radians) the rotation gives the x axis on the ground plane.
    pub fn yaw(&self) -> f64 {
        self.rotation[1][0].atan2(self.rotation[0][0])
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn close(a: [f64; 3], b: [f64; 3]) -> bool {
        (0..3).all(|i| (a[i] - b[i]).abs() < 1e-12)
    }

    #[test]
    fn quaternion_of_a_yaw_turns_x_toward_y() {
        // A quarter turn about z, by hand: (1, 0, 0) ↦ (0, 1, 0), (0, 1, 0) ↦ (−1, 0, 0).
        let q = std::f64::consts::FRAC_1_SQRT_2;
        let r = Rigid::from_quaternion([q, 0.0, 0.0, q], [1.0, 2.0, 3.0]);
        assert!(close(r.apply([1.0, 0.0, 0.0]), [1.0, 3.0, 3.0]));
        assert!(close(r.apply([0.0, 1.0, 0.0]), [0.0, 2.0, 3.0]));
        assert!((r.yaw() - std::f64::consts::FRAC_PI_2).abs() < 1e-12);
    }

    #[test]
    fn inverse_composition_and_quaternion_round_trip() {
        // A rotation about an oblique axis (quaternion of 0.7 rad about (1, 2, 2)/3).
        let (s, c) = (0.35f64.sin(), 0.35f64.cos());
        let r = Rigid::from_quaternion([c, s / 3.0, 2.0 * s / 3.0, 2.0 * s / 3.0], [0.5, -1.0, 2.0]);
        let p = [3.0, -4.0, 0.25];
        assert!(close(r.inverse().apply(r.apply(p)), p));
        assert!(close(r.then_after(&r.inverse()).apply(p), p));
        let q = r.quaternion();
        assert!(close(Rigid::from_quaternion(q, r.translation).apply(p), r.apply(p)));
        assert!(close(Rigid::from_matrix_3x4(&r.to_matrix_3x4()).apply(p), r.apply(p)));
    }

    #[test]
    fn a_box_keeps_its_points_under_a_yaw() {
        let b = Box3d { cx: 4.0, cy: 1.0, cz: -0.2, l: 0.8, w: 0.5, h: 1.7, rot_z: 0.4 };
        let r = Rigid::from_yaw(2.5, [10.0, -3.0, 1.0]);
        let moved = r.apply_box(&b);
        for p in [[4.3, 1.1, 0.5], [3.7, 0.95, -0.9], [4.5, 1.4, 0.0]] {
            let q = r.apply(p);
            assert_eq!(b.contains(p), moved.contains(q), "{p:?}");
        }
        assert!((moved.rot_z - 2.9).abs() < 1e-12);
    }
}
