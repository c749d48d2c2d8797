//! The frame a box's direction is read in, and what is read: the share of the box's points in
//! each cell of a grid centred on their centroid.

use data_jrdb::Box3d;
use serde::{Deserialize, Serialize};

use crate::person_minkunet::box_coder::faces_sensor;

/// The occupancy histogram's geometry.
///
/// The frame: x along the box's axis, signed to point at the sensor's side (the sensor is the
/// base frame's origin), y to its left, z up from the box's floor. x and y are centred on the
/// points' centroid, not on the box's centre: where a detector puts the centre already depends on
/// the direction it believes, and where the labelled centre sits on the body gives the direction
/// away (the feet reach forward).
#[derive(Serialize, Deserialize, Debug, Clone, Copy, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct FacingFeatures {
    /// Cell size (m) in x, y and z.
    pub cell: f64,
    /// The grid covers ±`half_width` around the centroid in x and y (m).
    pub half_width: f64,
    /// And `height` up from the box's floor (m).
    pub height: f64,
    /// The box is grown by this much (m) on every side before its points are taken.
    pub margin: f64,
    /// Boxes with fewer points inside are left as the detector oriented them.
    pub min_points: usize,
    /// Also the three 2D projections (x–y, x–z, y–z) of the same points at this finer cell
    /// (m): a finer read than the 3D grid affords in cells a linear fit can weigh.
    #[serde(default)]
    pub profile_cell: Option<f64>,
    /// Also the detector's own direction: +1 when the box's heading points at the sensor's side
    /// of its axis, −1 away. A detector that has learned some of the direction (CenterPoint's
    /// regressed sine and cosine) then keeps it where the points say little. Absent from a
    /// stored stage: off (the first stages did not read it), though on by default.
    #[serde(default)]
    pub detector_direction: bool,
    /// Also, for each horizontal slice of the grid (its z cells), the mean and the spread of
    /// the slice's points along x and y (m, from the centroid; 0 for an empty slice): where the
    /// feet or a backpack sit relative to the body is a ratio of counts, which shares read
    /// linearly cannot form.
    #[serde(default)]
    pub slice_moments: bool,
}

impl Default for FacingFeatures {
    /// 0.15 m cells over 1.2 × 1.2 × 1.95 m (8 × 8 × 13 = 832 cells; the height is rounded to
    /// whole cells), 0.1 m projections (624 cells), the 13 slices' moments (52) and the
    /// detector's direction, 5 cm margin, at least 3 points: the best of the variants measured
    /// on the shipped weights (docs/recipe.md §15).
    fn default() -> Self {
        Self { cell: 0.15, half_width: 0.6, height: 2.0, margin: 0.05, min_points: 3, profile_cell: Some(0.1), detector_direction: true, slice_moments: true }
    }
}

/// Whether heading `rot_z` points along box `b`'s axis as the features' frame signs it (towards
/// the sensor's side): the answer the classifier is fitted to give.
pub fn faces_along_axis(b: &Box3d, rot_z: f64) -> bool {
    let sign = axis_sign(b);
    sign * (rot_z - b.rot_z).cos() > 0.0
}

/// +1 when `b`'s heading points at the sensor's side, −1 when away: the frame's x is `sign` times
/// the heading's direction.
pub(crate) fn axis_sign(b: &Box3d) -> f64 {
    if faces_sensor(b.cx, b.cy, b.rot_z) { 1.0 } else { -1.0 }
}

impl FacingFeatures {
    /// Cells along x (= along y) and along z at cell size `cell`.
    fn grid(&self, cell: f64) -> (usize, usize) {
        ((2.0 * self.half_width / cell).round() as usize, (self.height / cell).round() as usize)
    }

    /// Whether the geometry has cells to count in: every size finite and positive (the margin
    /// not negative), at least one cell along every axis of every grid, a few million cells
    /// at most. A stored stage is checked before anything is sized from it.
    pub fn check(&self) -> Result<(), String> {
        let sizes = [self.cell, self.half_width, self.height].into_iter().chain(self.profile_cell);
        if sizes.clone().any(|v| !(v.is_finite() && v > 0.0)) || !(self.margin.is_finite() && self.margin >= 0.0) {
            return Err(format!("facing features with a size that is not a positive number: {self:?}"));
        }
        for c in [self.cell].into_iter().chain(self.profile_cell) {
            let (n, nz) = (2.0 * self.half_width / c, self.height / c);
            if n.round() < 1.0 || nz.round() < 1.0 || n * n * nz > 4e6 {
                return Err(format!("facing features whose {c} m grid has {n:.0} × {n:.0} × {nz:.0} cells"));
            }
        }
        Ok(())
    }

    /// How many features [`read`](Self::read) returns.
    pub fn len(&self) -> usize {
        let (n, nz) = self.grid(self.cell);
        let profiles = self.profile_cell.map_or(0, |c| {
            let (np, nzp) = self.grid(c);
            np * np + 2 * np * nzp
        });
        n * n * nz + profiles + if self.slice_moments { 4 * nz } else { 0 } + self.detector_direction as usize
    }

    /// Whether it reads no feature at all.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The share of `b`'s points (grown by the margin) in each cell of the frame, x-major then y
    /// then z, then (with `profile_cell`) in each cell of the x–y, x–z and y–z projections, then
    /// (with `slice_moments`) each z slice's mean x, mean y, spread x, spread y, then (with
    /// `detector_direction`) ±1; `None` when fewer than `min_points` are inside. Points
    /// outside a grid count in its border cells.
    pub fn read(&self, points: &[[f32; 3]], b: &Box3d) -> Option<Vec<f64>> {
        let sign = axis_sign(b);
        let (s, c) = b.rot_z.sin_cos();
        let floor = b.cz - b.h / 2.0;
        let m = self.margin;
        // A cheap bound first: most of a frame's points are far from any one box.
        let reach = (b.l / 2.0 + m).hypot(b.w / 2.0 + m);
        let inside: Vec<[f64; 3]> = points
            .iter()
            .filter_map(|p| {
                let (dx, dy, dz) = (p[0] as f64 - b.cx, p[1] as f64 - b.cy, p[2] as f64 - floor);
                if dx.abs() > reach || dy.abs() > reach {
                    return None;
                }
                let (x, y) = (c * dx + s * dy, -s * dx + c * dy);
                let within = x.abs() <= b.l / 2.0 + m && y.abs() <= b.w / 2.0 + m && dz >= -m && dz <= b.h + m;
                within.then_some([sign * x, sign * y, dz])
            })
            .collect();
        if inside.len() < self.min_points.max(1) {
            return None;
        }
        let n = inside.len() as f64;
        let (mx, my) = (inside.iter().map(|q| q[0]).sum::<f64>() / n, inside.iter().map(|q| q[1]).sum::<f64>() / n);
        let index = |v: f64, cell: f64, cells: usize| ((v / cell).floor().max(0.0) as usize).min(cells - 1);
        let centred: Vec<[f64; 3]> = inside.iter().map(|q| [q[0] - mx + self.half_width, q[1] - my + self.half_width, q[2]]).collect();
        let (nxy, nz) = self.grid(self.cell);
        let mut h = vec![0.0; self.len()];
        for q in &centred {
            let (ix, iy, iz) = (index(q[0], self.cell, nxy), index(q[1], self.cell, nxy), index(q[2], self.cell, nz));
            h[(ix * nxy + iy) * nz + iz] += 1.0 / n;
        }
        if let Some(c) = self.profile_cell {
            let (np, nzp) = self.grid(c);
            let (xy, xz) = (nxy * nxy * nz, nxy * nxy * nz + np * np);
            let yz = xz + np * nzp;
            for q in &centred {
                let (ix, iy, iz) = (index(q[0], c, np), index(q[1], c, np), index(q[2], c, nzp));
                h[xy + ix * np + iy] += 1.0 / n;
                h[xz + ix * nzp + iz] += 1.0 / n;
                h[yz + iy * nzp + iz] += 1.0 / n;
            }
        }
        if self.slice_moments {
            let start = nxy * nxy * nz + self.profile_cell.map_or(0, |c| {
                let (np, nzp) = self.grid(c);
                np * np + 2 * np * nzp
            });
            // Per slice: count, Σx, Σy, Σx², Σy² of the points from the centroid.
            let mut sums = vec![[0.0f64; 5]; nz];
            for q in &centred {
                let (x, y) = (q[0] - self.half_width, q[1] - self.half_width);
                let s = &mut sums[index(q[2], self.cell, nz)];
                for (acc, v) in s.iter_mut().zip([1.0, x, y, x * x, y * y]) {
                    *acc += v;
                }
            }
            for (k, s) in sums.iter().enumerate().filter(|(_, s)| s[0] > 0.0) {
                let (mx, my) = (s[1] / s[0], s[2] / s[0]);
                let (vx, vy) = ((s[3] / s[0] - mx * mx).max(0.0), (s[4] / s[0] - my * my).max(0.0));
                h[start + 4 * k..start + 4 * k + 4].copy_from_slice(&[mx, my, vx.sqrt(), vy.sqrt()]);
            }
        }
        if self.detector_direction {
            *h.last_mut().expect("the direction's slot") = sign;
        }
        Some(h)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::PI;

    fn person(cx: f64, cy: f64, rot_z: f64) -> Box3d {
        Box3d { cx, cy, cz: 0.15, l: 0.5, w: 0.6, h: 1.7, rot_z }
    }

    #[test]
    fn the_axis_is_signed_towards_the_sensor() {
        // A person 5 m ahead on +x: heading π faces the sensor, heading 0 faces away.
        assert!(faces_along_axis(&person(5.0, 0.0, 0.0), PI));
        assert!(!faces_along_axis(&person(5.0, 0.0, 0.0), 0.0));
        // The box's own heading does not matter, only its axis.
        assert!(faces_along_axis(&person(5.0, 0.0, PI), PI));
        // Off the axis by less than 90°: still towards.
        assert!(faces_along_axis(&person(5.0, 0.0, 0.1), PI - 1.2));
    }

    #[test]
    fn histogram_by_hand() {
        let f = FacingFeatures { cell: 0.2, profile_cell: None, detector_direction: false, slice_moments: false, ..Default::default() };
        assert_eq!(f.len(), 6 * 6 * 10);
        // A person 5 m ahead on +x, heading 0 (away): the frame's x points back at the sensor
        // (the base's −x), its y to the base's −y. Two points at the floor, centroid (5, 0):
        // (4.85, 0.13) sits at frame (x, y) = (+0.15, −0.13), (5.15, −0.13) at (−0.15, +0.13).
        // Cells count from −0.6: x +0.15 → 3, −0.15 → 2; y −0.13 → 2, +0.13 → 3; z 0.05 → 0.
        let b = person(5.0, 0.0, 0.0);
        let floor = (b.cz - b.h / 2.0) as f32;
        let pts = [[4.85, 0.13, floor + 0.05], [5.15, -0.13, floor + 0.05], [9.0, 0.0, 0.0]];
        let h = FacingFeatures { min_points: 2, ..f }.read(&pts, &b).unwrap();
        let at = |ix: usize, iy: usize, iz: usize| h[(ix * 6 + iy) * 10 + iz];
        assert_eq!(at(3, 2, 0), 0.5);
        assert_eq!(at(2, 3, 0), 0.5);
        assert_eq!(h.iter().sum::<f64>(), 1.0);
        // Fewer than min_points (3) inside: nothing to read.
        assert!(f.read(&pts, &b).is_none());
        // With 0.1 m profiles (12 × 12 x–y, 12 × 20 x–z, 12 × 20 y–z cells after the 360): x
        // +0.15 → 7, −0.15 → 4; y −0.13 → 4, +0.13 → 7; z → 0.
        let g = FacingFeatures { min_points: 2, profile_cell: Some(0.1), ..f };
        assert_eq!(g.len(), 360 + 144 + 240 + 240);
        let h = g.read(&pts, &b).unwrap();
        let (xy, xz, yz) = (360, 360 + 144, 360 + 144 + 240);
        assert_eq!([h[xy + 7 * 12 + 4], h[xy + 4 * 12 + 7]], [0.5, 0.5]);
        assert_eq!([h[xz + 7 * 20], h[xz + 4 * 20], h[yz + 4 * 20], h[yz + 7 * 20]], [0.5; 4]);
        assert!((h.iter().sum::<f64>() - 4.0).abs() < 1e-12);
        // Slice moments: both points in the first slice, at x ±0.15 and y ∓0.13 from their
        // centroid: means 0, spreads 0.15 and 0.13; the other nine slices empty.
        let m = FacingFeatures { min_points: 2, slice_moments: true, ..f };
        assert_eq!(m.len(), 360 + 4 * 10);
        let h = m.read(&pts, &b).unwrap();
        let s0 = &h[360..364];
        assert!(s0[0].abs() < 1e-6 && s0[1].abs() < 1e-6 && (s0[2] - 0.15).abs() < 1e-6 && (s0[3] - 0.13).abs() < 1e-6, "{s0:?}");
        assert!(h[364..].iter().all(|v| *v == 0.0));
        // The detector's direction last: heading 0 points away from the sensor (−1), π at it.
        let d = FacingFeatures { min_points: 2, detector_direction: true, ..f };
        assert_eq!(d.len(), 361);
        assert_eq!(d.read(&pts, &b).unwrap()[360], -1.0);
        assert_eq!(d.read(&pts, &person(5.0, 0.0, PI)).unwrap()[360], 1.0);
    }

    #[test]
    fn turning_the_box_by_half_a_turn_reads_the_same_histogram() {
        let f = FacingFeatures { min_points: 1, ..Default::default() };
        assert_eq!(f.len(), 832 + 624 + 52 + 1);
        let pts: Vec<[f32; 3]> = (0..40).map(|i| [5.0 + 0.01 * i as f32, 0.3 - 0.012 * i as f32, -0.7 + 0.04 * i as f32]).collect();
        let a = f.read(&pts, &person(5.1, 0.1, 0.4)).unwrap();
        let b = f.read(&pts, &person(5.1, 0.1, 0.4 + PI)).unwrap();
        // The histogram reads the same; only the detector's direction flips.
        let n = f.len() - 1;
        assert!(a[..n].iter().zip(&b[..n]).all(|(x, y)| (x - y).abs() < 1e-12));
        assert_eq!(a[n], -b[n]);
    }
}
