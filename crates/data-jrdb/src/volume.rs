//! The working volume: the box of the base frame a model looks at. Points outside it are dropped
//! (and counted) before voxelization, so a LiDAR's far and max-range returns, or a stray point at
//! 1e38, never reach the integer voxel grid, whose coordinates must stay small.

use serde::{Deserialize, Serialize};

/// Axis-aligned ranges (metres, both ends kept) in the frame the model runs in.
///
/// The default, ±100 m across and −20 to 40 m up, holds every return the simulator makes (its
/// sensors see 100 m; `bench-v1`'s points reach 75 m across and 18 m up) and every person a scan
/// can show, and keeps a 0.05 m voxel grid within ±2,000 cells.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Volume {
    /// Forward range `[min, max]`.
    pub x: [f32; 2],
    /// Left range `[min, max]`.
    pub y: [f32; 2],
    /// Up range `[min, max]`.
    pub z: [f32; 2],
}

impl Default for Volume {
    fn default() -> Self {
        Self { x: [-100.0, 100.0], y: [-100.0, 100.0], z: [-20.0, 40.0] }
    }
}

/// The largest voxel coordinate (in finest voxels) a volume may reach: the sparse index packs 18
/// signed bits per axis (±131,072), and the U-Net's coarsest stride rounds outward from there.
pub const MAX_VOXEL_COORD: f32 = 100_000.0;

impl Volume {
    /// Whether `p` lies inside (a NaN coordinate never does).
    pub fn contains(&self, p: [f32; 3]) -> bool {
        let inside = |v: f32, r: [f32; 2]| v >= r[0] && v <= r[1];
        inside(p[0], self.x) && inside(p[1], self.y) && inside(p[2], self.z)
    }

    /// Drops the points outside, keeping the others' order; returns how many were dropped.
    pub fn crop(&self, points: &mut Vec<[f32; 3]>) -> usize {
        let before = points.len();
        points.retain(|&p| self.contains(p));
        before - points.len()
    }

    /// Checks that the ranges are finite and ordered and that voxels of `voxel_size` inside them
    /// have coordinates the sparse index can hold.
    pub fn validate(&self, voxel_size: [f32; 3]) -> Result<(), String> {
        for (axis, r, vs) in [("x", self.x, voxel_size[0]), ("y", self.y, voxel_size[1]), ("z", self.z, voxel_size[2])] {
            if !(r[0].is_finite() && r[1].is_finite() && r[0] < r[1]) {
                return Err(format!("data.volume.{axis} = {r:?} must be two finite numbers, the smaller first"));
            }
            let cells = r[0].abs().max(r[1].abs()) / vs;
            if !(cells <= MAX_VOXEL_COORD) {
                return Err(format!(
                    "data.volume.{axis} = {r:?} spans {cells:.0} voxels of {vs} m from the origin; at most {MAX_VOXEL_COORD:.0} fit the sparse index"
                ));
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn far_and_nan_points_are_dropped_and_counted() {
        let v = Volume::default();
        let mut pts = vec![[1.0, 2.0, 0.0], [1e6, 0.0, 0.0], [0.0, -1e38, 0.0], [f32::NAN, 0.0, 0.0], [100.0, -100.0, 40.0], [0.0, 0.0, -20.5]];
        assert_eq!(v.crop(&mut pts), 4);
        assert_eq!(pts, vec![[1.0, 2.0, 0.0], [100.0, -100.0, 40.0]]);
    }

    #[test]
    fn ranges_too_wide_for_the_voxels_are_refused() {
        assert!(Volume::default().validate([0.05, 0.05, 0.1]).is_ok());
        assert!(Volume { x: [-1e4, 1e4], ..Default::default() }.validate([0.05, 0.05, 0.1]).unwrap_err().contains("voxels"));
        assert!(Volume { z: [1.0, -1.0], ..Default::default() }.validate([0.05, 0.05, 0.1]).is_err());
        assert!(Volume { y: [f32::NEG_INFINITY, 0.0], ..Default::default() }.validate([0.05, 0.05, 0.1]).is_err());
    }
}
