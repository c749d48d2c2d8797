//! `calibration/defaults.yaml`: the rigid transforms that bring each LiDAR into the base frame.
//!
//! The file gives `calibrated.lidar_{upper,lower}_to_rgb.{translation, rotation}`; the toolkit maps
//! a sensor point p to the base frame as `Rz(rotation[2]) · (p − translation)`; the authors'
//! `jrdb_transforms.py` hard-codes the same numbers.

use std::path::Path;

use serde_norway::Value;

use crate::error::{DataError, ErrorKind, Result};

/// Which of the two Velodynes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Lidar {
    /// The upper VLP-16 (its cloud comes first in the merged cloud).
    Upper,
    /// The lower VLP-16.
    Lower,
}

impl Lidar {
    /// Both, in merge order.
    pub const BOTH: [Lidar; 2] = [Lidar::Upper, Lidar::Lower];

    /// Folder name under `pointclouds/`.
    pub fn folder(self) -> &'static str {
        match self {
            Lidar::Upper => "upper_velodyne",
            Lidar::Lower => "lower_velodyne",
        }
    }
}

/// One sensor's `*_to_rgb` entry.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LidarToBase {
    /// `translation` (metres), subtracted first.
    pub translation: [f64; 3],
    /// `rotation[2]`, the yaw (radians) applied after; the x and y angles are 0 in JRDB.
    pub yaw: f64,
}

impl LidarToBase {
    /// Sensor frame → base frame.
    pub fn to_base(&self, p: [f32; 3]) -> [f32; 3] {
        let (s, c) = self.yaw.sin_cos();
        let q = [p[0] as f64 - self.translation[0], p[1] as f64 - self.translation[1], p[2] as f64 - self.translation[2]];
        [(c * q[0] - s * q[1]) as f32, (s * q[0] + c * q[1]) as f32, q[2] as f32]
    }

    /// Base frame → sensor frame (the inverse of [`Self::to_base`], used by the simulator).
    pub fn to_sensor(&self, p: [f64; 3]) -> [f64; 3] {
        let (s, c) = self.yaw.sin_cos();
        [c * p[0] + s * p[1] + self.translation[0], -s * p[0] + c * p[1] + self.translation[1], p[2] + self.translation[2]]
    }

    /// The sensor origin in the base frame.
    pub fn origin(&self) -> [f64; 3] {
        let o = self.to_base([0.0; 3]);
        [o[0] as f64, o[1] as f64, o[2] as f64]
    }
}

/// The two LiDAR transforms of a JRDB tree.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Calibration {
    /// `lidar_upper_to_rgb`.
    pub upper: LidarToBase,
    /// `lidar_lower_to_rgb`.
    pub lower: LidarToBase,
}

impl Default for Calibration {
    /// The values of the official `defaults.yaml`.
    fn default() -> Self {
        Self {
            upper: LidarToBase { translation: [0.0, 0.0, -0.33529], yaw: 0.085 },
            lower: LidarToBase { translation: [0.0, 0.0, 0.13511], yaw: 0.0 },
        }
    }
}

impl Calibration {
    /// The transform of one LiDAR.
    pub fn lidar(&self, lidar: Lidar) -> &LidarToBase {
        match lidar {
            Lidar::Upper => &self.upper,
            Lidar::Lower => &self.lower,
        }
    }

    /// Reads `defaults.yaml`; other keys of the file are ignored.
    pub fn read(path: &Path) -> Result<Self> {
        let text = std::fs::read_to_string(path).map_err(|e| DataError::io(path, e))?;
        Self::parse(&text, path)
    }

    /// Parses the text of a `defaults.yaml`; errors name `path`.
    pub fn parse(text: &str, path: &Path) -> Result<Self> {
        let doc: Value = serde_norway::from_str(text).map_err(|e| DataError::new(path, ErrorKind::Parse(e.to_string())))?;
        let entry = |name: &str| -> Result<LidarToBase> {
            let at = format!("calibrated.{name}");
            let node = doc.get("calibrated").and_then(|c| c.get(name)).ok_or_else(|| DataError::key(path, &at, "missing"))?;
            let vec3 = |k: &str| -> Result<[f64; 3]> {
                let v = node.get(k).and_then(Value::as_sequence).ok_or_else(|| DataError::key(path, format!("{at}.{k}"), "missing or not a list"))?;
                let xs: Option<Vec<f64>> = v.iter().map(Value::as_f64).collect();
                match xs.as_deref() {
                    Some([a, b, c]) if a.is_finite() && b.is_finite() && c.is_finite() => Ok([*a, *b, *c]),
                    _ => Err(DataError::key(path, format!("{at}.{k}"), "needs three finite numbers")),
                }
            };
            let rot = vec3("rotation")?;
            if rot[0] != 0.0 || rot[1] != 0.0 {
                return Err(DataError::key(path, format!("{at}.rotation"), "only a rotation about z is supported"));
            }
            Ok(LidarToBase { translation: vec3("translation")?, yaw: rot[2] })
        };
        Ok(Self { upper: entry("lidar_upper_to_rgb")?, lower: entry("lidar_lower_to_rgb")? })
    }

    /// Writes a `defaults.yaml` with the `calibrated` section (and JRDB's image block for realism).
    pub fn write(&self, path: &Path) -> Result<()> {
        let e = |t: &LidarToBase| {
            format!(
                "    rotation: [0.0, 0.0, {}]\n    translation: [{}, {}, {}]\n",
                t.yaw, t.translation[0], t.translation[1], t.translation[2]
            )
        };
        let text = format!(
            "calibrated:\n  # the lidar_to_rgb parameters allow tweaking of the transformation between lidar and rgb frames\n  lidar_upper_to_rgb:\n{}  lidar_lower_to_rgb:\n{}image:\n  height: 480\n  width: 3760\n  stitched_image_offset: 0\n",
            e(&self.upper),
            e(&self.lower)
        );
        std::fs::write(path, text).map_err(|e| DataError::io(path, e))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sensor_and_base_frames_are_inverse() {
        let c = Calibration::default();
        let p = [3.0, -1.0, 0.2];
        for l in Lidar::BOTH {
            let t = c.lidar(l);
            let q = t.to_sensor(p);
            let b = t.to_base([q[0] as f32, q[1] as f32, q[2] as f32]);
            assert!((0..3).all(|k| (b[k] as f64 - p[k]).abs() < 1e-5));
        }
        // The upper sensor sits 0.33529 m above the base origin (`calibration/defaults.yaml`).
        assert!((c.upper.origin()[2] - 0.33529).abs() < 1e-6);
        assert!((c.lower.origin()[2] + 0.13511).abs() < 1e-6);
    }
}
