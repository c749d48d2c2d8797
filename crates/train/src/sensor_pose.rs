//! Where a user's sensor frame sits in JRDB's base frame, so that `detect` and `serve` take clouds
//! in the frame their driver writes and answer boxes in that same frame.
//!
//! The detectors were trained in JRDB's base frame: metres, x forward, y left, z up, the floor
//! about 0.7 m below the origin. A point `p` of the input becomes `R(yaw)·p + (x, y, z)` there,
//! with `R` the counter-clockwise rotation about z. For a sensor whose own frame already has x
//! forward and z up with its origin `H` metres above the floor, `z = H − 0.7`.

use std::fmt;
use std::str::FromStr;

use data_jrdb::Box3d;

/// The floor's height in JRDB's base frame (metres), which the models learned people stand on.
pub const BASE_FLOOR_Z: f64 = -0.7;

/// A rigid motion about z: the input frame's pose in the base frame.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct SensorPose {
    /// Translation (metres) added after the rotation.
    pub translation: [f64; 3],
    /// Rotation about z (radians, counter-clockwise).
    pub yaw: f64,
}

impl SensorPose {
    /// The identity: the input is in the base frame already.
    pub fn is_identity(&self) -> bool {
        *self == Self::default()
    }

    /// A point of the input in the base frame.
    pub fn to_base(&self, p: [f32; 3]) -> [f32; 3] {
        let (s, c) = self.yaw.sin_cos();
        let [x, y, z] = p.map(f64::from);
        let t = self.translation;
        [(c * x - s * y + t[0]) as f32, (s * x + c * y + t[1]) as f32, (z + t[2]) as f32]
    }

    /// A box found in the base frame, in the input's frame.
    pub fn box_to_input(&self, b: &Box3d) -> Box3d {
        let (s, c) = self.yaw.sin_cos();
        let t = self.translation;
        let (dx, dy) = (b.cx - t[0], b.cy - t[1]);
        Box3d { cx: c * dx + s * dy, cy: -s * dx + c * dy, cz: b.cz - t[2], rot_z: wrap_angle(b.rot_z - self.yaw), ..*b }
    }
}

/// `a` in (−π, π].
fn wrap_angle(a: f64) -> f64 {
    let r = a.rem_euclid(std::f64::consts::TAU);
    if r > std::f64::consts::PI { r - std::f64::consts::TAU } else { r }
}

/// `x=0,y=0,z=-0.4,yaw=90`: any of the keys, metres and degrees.
impl FromStr for SensorPose {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, String> {
        let mut pose = Self::default();
        for part in s.split(',').map(str::trim).filter(|p| !p.is_empty()) {
            let (key, value) = part.split_once('=').ok_or_else(|| format!("`{part}` is not KEY=VALUE (keys x, y, z in metres, yaw in degrees)"))?;
            let v: f64 = value.trim().parse().map_err(|_| format!("`{value}` in `{part}` is not a number"))?;
            if !v.is_finite() {
                return Err(format!("`{part}` is not finite"));
            }
            match key.trim() {
                "x" => pose.translation[0] = v,
                "y" => pose.translation[1] = v,
                "z" => pose.translation[2] = v,
                "yaw" => pose.yaw = v.to_radians(),
                k => return Err(format!("unknown key `{k}` (keys: x, y, z in metres, yaw in degrees)")),
            }
        }
        Ok(pose)
    }
}

impl fmt::Display for SensorPose {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let [x, y, z] = self.translation;
        write!(f, "x={x},y={y},z={z},yaw={}", self.yaw.to_degrees())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_keys_in_metres_and_degrees() {
        let p: SensorPose = "z=-0.4, yaw=90".parse().unwrap();
        assert_eq!(p.translation, [0.0, 0.0, -0.4]);
        assert!((p.yaw - std::f64::consts::FRAC_PI_2).abs() < 1e-12);
        assert!("".parse::<SensorPose>().unwrap().is_identity());
        assert!("roll=3".parse::<SensorPose>().unwrap_err().contains("unknown key"));
        assert!("z".parse::<SensorPose>().unwrap_err().contains("KEY=VALUE"));
        assert!("z=abc".parse::<SensorPose>().unwrap_err().contains("not a number"));
    }

    #[test]
    fn a_box_round_trips_with_its_points() {
        // Hand-derived: yaw 90° maps the input's x axis onto the base frame's y axis.
        let pose = SensorPose { translation: [1.0, 2.0, 0.5], yaw: std::f64::consts::FRAC_PI_2 };
        let p = pose.to_base([3.0, 0.0, 0.0]);
        assert!((p[0] - 1.0).abs() < 1e-6 && (p[1] - 5.0).abs() < 1e-6 && (p[2] - 0.5).abs() < 1e-6);
        // A box at that base point heading along base +y is, in the input, at (3, 0, 0) heading +x.
        let b = Box3d { cx: 1.0, cy: 5.0, cz: 0.5, l: 0.6, w: 0.5, h: 1.7, rot_z: std::f64::consts::FRAC_PI_2 };
        let back = pose.box_to_input(&b);
        assert!((back.cx - 3.0).abs() < 1e-9 && back.cy.abs() < 1e-9 && back.cz.abs() < 1e-9 && back.rot_z.abs() < 1e-9);
        assert_eq!((back.l, back.w, back.h), (0.6, 0.5, 1.7));
        // Points inside the base box are inside the input box.
        let q = [3.2f32, 0.1, 0.3];
        let qb = pose.to_base(q);
        let inside = |b: &Box3d, p: [f64; 3]| {
            let (s, c) = b.rot_z.sin_cos();
            let (dx, dy) = (p[0] - b.cx, p[1] - b.cy);
            (c * dx + s * dy).abs() <= b.l / 2.0 && (-s * dx + c * dy).abs() <= b.w / 2.0 && (p[2] - b.cz).abs() <= b.h / 2.0
        };
        assert!(inside(&b, qb.map(f64::from)) && inside(&back, q.map(f64::from)));
    }
}
