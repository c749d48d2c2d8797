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
use data_jrdb::ground::{GroundSearch, fit_ground};

/// The floor's height in JRDB's base frame (metres), which the models learned people stand on.
pub const BASE_FLOOR_Z: f64 = -0.7;

/// A rigid motion: the input frame's pose in the base frame. A point is levelled first (turned
/// by `roll` about x, then `pitch` about y), then turned by `yaw` about z and moved by
/// `translation`.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct SensorPose {
    /// Translation (metres) added after the rotation.
    pub translation: [f64; 3],
    /// Rotation about z (radians, counter-clockwise).
    pub yaw: f64,
    /// Rotation about x applied first (radians).
    pub roll: f64,
    /// Rotation about y applied second (radians).
    pub pitch: f64,
}

impl SensorPose {
    /// The identity: the input is in the base frame already.
    pub fn is_identity(&self) -> bool {
        *self == Self::default()
    }

    /// A point of the input in the base frame.
    pub fn to_base(&self, p: [f32; 3]) -> [f32; 3] {
        let [x, y, z] = self.level(p.map(f64::from));
        let (s, c) = self.yaw.sin_cos();
        let t = self.translation;
        [(c * x - s * y + t[0]) as f32, (s * x + c * y + t[1]) as f32, (z + t[2]) as f32]
    }

    /// `R_y(pitch) · R_x(roll) · p`.
    fn level(&self, [x, y, z]: [f64; 3]) -> [f64; 3] {
        if self.roll == 0.0 && self.pitch == 0.0 {
            return [x, y, z];
        }
        let (sr, cr) = self.roll.sin_cos();
        let (y, z) = (cr * y - sr * z, sr * y + cr * z);
        let (sp, cp) = self.pitch.sin_cos();
        [cp * x + sp * z, y, -sp * x + cp * z]
    }

    /// The inverse of [`level`](Self::level).
    fn unlevel(&self, [x, y, z]: [f64; 3]) -> [f64; 3] {
        if self.roll == 0.0 && self.pitch == 0.0 {
            return [x, y, z];
        }
        let (sp, cp) = self.pitch.sin_cos();
        let (x, z) = (cp * x - sp * z, sp * x + cp * z);
        let (sr, cr) = self.roll.sin_cos();
        [x, cr * y + sr * z, -sr * y + cr * z]
    }

    /// A box found in the base frame, in the input's frame: its centre moved exactly, its heading
    /// turned back by the yaw (a levelled upright box stays upright: the tilt, a few degrees, is
    /// left out of its orientation).
    pub fn box_to_input(&self, b: &Box3d) -> Box3d {
        let (s, c) = self.yaw.sin_cos();
        let t = self.translation;
        let (dx, dy) = (b.cx - t[0], b.cy - t[1]);
        let [cx, cy, cz] = self.unlevel([c * dx + s * dy, -s * dx + c * dy, b.cz - t[2]]);
        Box3d { cx, cy, cz, rot_z: wrap_angle(b.rot_z - self.yaw), ..*b }
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
                "roll" => pose.roll = v.to_radians(),
                "pitch" => pose.pitch = v.to_radians(),
                k => return Err(format!("unknown key `{k}` (keys: x, y, z in metres, yaw, roll, pitch in degrees)")),
            }
        }
        Ok(pose)
    }
}

impl fmt::Display for SensorPose {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let [x, y, z] = self.translation;
        write!(f, "x={x},y={y},z={z},yaw={}", self.yaw.to_degrees())?;
        if self.roll != 0.0 || self.pitch != 0.0 {
            write!(f, ",roll={},pitch={}", self.roll.to_degrees(), self.pitch.to_degrees())?;
        }
        Ok(())
    }
}

/// How `detect` and `serve` place a cloud in the base frame: the ground found in the scan itself
/// (`auto`, the default: the sensor's height and tilt from a plane fit, the floor then put where
/// the models learned it), with any yaw, x and y given beside it, or a pose given whole.
///
/// A scan without ground in view keeps the pose given beside `auto` (by default the identity:
/// the cloud is taken to be in the base frame already) and its placement says so.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FrameSpec {
    /// The pose given (with `auto`, its yaw, x and y; its z, roll and pitch come from the ground).
    pub pose: SensorPose,
    /// Find the ground in each scan.
    pub auto: bool,
}

impl Default for FrameSpec {
    /// `auto`: find the ground.
    fn default() -> Self {
        Self { pose: SensorPose::default(), auto: true }
    }
}

impl FrameSpec {
    /// A pose given whole, no ground search.
    pub fn given(pose: SensorPose) -> Self {
        Self { pose, auto: false }
    }
}

/// How a scan was placed, for its report.
#[derive(Debug, Clone, PartialEq)]
pub struct Placement {
    /// The pose applied.
    pub pose: SensorPose,
    /// `given`, `ground: …` (what the fit found) or `no ground: … (the given pose kept)`.
    pub how: String,
}

impl FrameSpec {
    /// The pose for one scan in the input's frame.
    pub fn place(&self, points: &[[f32; 3]]) -> Placement {
        if !self.auto {
            return Placement { pose: self.pose, how: "given".into() };
        }
        match fit_ground(points, &GroundSearch::default()) {
            Ok(g) => {
                let (roll, pitch) = g.levelling();
                let [x, y, _] = self.pose.translation;
                let pose = SensorPose { translation: [x, y, g.height + BASE_FLOOR_Z], roll, pitch, ..self.pose };
                let how = format!(
                    "ground: {:.2} m below the sensor, tilted {:.1}° ({} of {} returns around and below it on the plane)",
                    g.height,
                    g.tilt_deg(),
                    g.inliers,
                    g.candidates
                );
                Placement { pose, how }
            }
            Err(why) => Placement { pose: self.pose, how: format!("no ground: {why}; the given pose kept ({})", self.pose) },
        }
    }
}

/// `auto`, `auto,yaw=-90`, or a pose (see [`SensorPose`]'s keys; `identity` or an empty string
/// for the base frame itself).
impl FromStr for FrameSpec {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, String> {
        let mut auto = false;
        let rest: Vec<&str> = s
            .split(',')
            .filter(|p| {
                let is_auto = p.trim() == "auto";
                auto |= is_auto;
                !is_auto
            })
            .collect();
        let rest: Vec<&str> = rest.into_iter().filter(|p| p.trim() != "identity").collect();
        let pose: SensorPose = rest.join(",").parse()?;
        if auto && (pose.translation[2] != 0.0 || pose.roll != 0.0 || pose.pitch != 0.0) {
            return Err("`auto` finds z, roll and pitch from the ground; give only yaw, x or y beside it".into());
        }
        Ok(Self { pose, auto })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn auto_finds_a_raised_tilted_sensor_and_boxes_return_to_its_frame() {
        // A floor 1.8 m below a sensor pitched 4°, in the sensor's frame.
        let given = SensorPose { translation: [0.0, 0.0, 1.1], pitch: 0.07, ..Default::default() };
        let truth = |p: [f32; 3]| given.to_base(p);
        let mut pts = Vec::new();
        for i in 0..4000 {
            let (r, a) = (2.0 + (i % 97) as f64 * 0.25, i as f64 * 0.37);
            // Points on the base floor (z = −0.7), mapped back into the sensor's frame.
            let base = [r * a.cos(), r * a.sin(), BASE_FLOOR_Z];
            pts.push(given.unlevel([base[0], base[1], base[2] - 1.1]).map(|v| v as f32));
        }
        let spec: FrameSpec = "auto".parse().unwrap();
        let placed = spec.place(&pts);
        assert!(placed.how.starts_with("ground: 1.80 m"), "{}", placed.how);
        for p in pts.iter().step_by(97) {
            let (a, b) = (placed.pose.to_base(*p), truth(*p));
            assert!((0..3).all(|k| (a[k] - b[k]).abs() < 0.02), "{a:?} vs {b:?}");
        }
        let b = Box3d { cx: 5.0, cy: 1.0, cz: -0.7 + 0.85, l: 0.6, w: 0.5, h: 1.7, rot_z: 0.3 };
        let back = placed.pose.box_to_input(&b);
        let again = placed.pose.to_base([back.cx as f32, back.cy as f32, back.cz as f32]);
        assert!((again[0] as f64 - b.cx).abs() < 1e-4 && (again[2] as f64 - b.cz).abs() < 1e-4);
        // No ground in view: the given pose, said so.
        let sky: Vec<[f32; 3]> = (0..500).map(|i| [i as f32 * 0.01, 1.0, 3.0]).collect();
        let placed = "auto,yaw=90".parse::<FrameSpec>().unwrap().place(&sky);
        assert!(placed.how.starts_with("no ground"), "{}", placed.how);
        assert!((placed.pose.yaw - std::f64::consts::FRAC_PI_2).abs() < 1e-12);
        assert!("auto,z=1".parse::<FrameSpec>().is_err());
    }

    #[test]
    fn parses_keys_in_metres_and_degrees() {
        let p: SensorPose = "z=-0.4, yaw=90".parse().unwrap();
        assert_eq!(p.translation, [0.0, 0.0, -0.4]);
        assert!((p.yaw - std::f64::consts::FRAC_PI_2).abs() < 1e-12);
        assert!("".parse::<SensorPose>().unwrap().is_identity());
        assert!("tilt=3".parse::<SensorPose>().unwrap_err().contains("unknown key"));
        assert!("z".parse::<SensorPose>().unwrap_err().contains("KEY=VALUE"));
        assert!("z=abc".parse::<SensorPose>().unwrap_err().contains("not a number"));
    }

    #[test]
    fn a_box_round_trips_with_its_points() {
        // Hand-derived: yaw 90° maps the input's x axis onto the base frame's y axis.
        let pose = SensorPose { translation: [1.0, 2.0, 0.5], yaw: std::f64::consts::FRAC_PI_2, ..Default::default() };
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
