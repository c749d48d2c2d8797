//! What carries the sensor in `bench-v2`: a car's roof, a robot's body or a mast, with the sensor
//! mounted 0.3–2.2 m above the ground and tipped by a few degrees; the platform's own body is in
//! the scene, so the sensor sees it as real sensors see theirs.

use rand::Rng;

use super::geometry::Shape;
use super::objects::{Parts, Vehicle, cuboid, placed};
use super::sensors::SensorModel;

/// The kind of platform.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Platform {
    /// A car with the sensor on a roof mount (1.5–2.2 m).
    Car,
    /// A wheeled robot with the sensor on top of its body (0.3–1.2 m).
    Robot,
    /// JRDB's robot: two VLP-16 at its calibrated positions.
    JrdbRobot,
    /// A thin mast or tripod (0.8–2.2 m).
    Mast,
}

impl Platform {
    /// Its name in statistics.
    pub fn name(self) -> &'static str {
        match self {
            Platform::Car => "car",
            Platform::Robot => "robot",
            Platform::JrdbRobot => "jrdb-robot",
            Platform::Mast => "mast",
        }
    }
}

/// A sensor on its platform.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Rig {
    /// The sensor (ignored on `JrdbRobot`, whose sensors are two VLP-16).
    pub sensor: SensorModel,
    /// The platform carrying it.
    pub platform: Platform,
    /// The sensor's origin above the ground under the platform (m).
    pub height: f64,
    /// Roll and pitch of the sensor (radians), applied as `sim::lidar::tip` applies them.
    pub tilt: [f64; 2],
    /// Length, width and roof height of the platform's body (m).
    body: [f64; 3],
    /// Where along the body the sensor sits (m forward of the body's centre).
    mount_x: f64,
}

impl Rig {
    /// A random rig for a place outdoors (`street`) or not: cars only outdoors.
    pub fn sample<R: Rng + ?Sized>(outdoors: bool, rng: &mut R) -> Self {
        let platform = match (outdoors, rng.random_range(0..10)) {
            (true, 0..=5) => Platform::Car,
            (true, 6..=8) | (false, 0..=4) => Platform::Robot,
            (false, 5..=7) => Platform::JrdbRobot,
            _ => Platform::Mast,
        };
        let sensor = match platform {
            // Cars carry the automotive sensors; robots the smaller ones as often as not.
            Platform::Car => [SensorModel::Hdl32e, SensorModel::Vlp32c, SensorModel::Vlp32cPair, SensorModel::Pandar40p, SensorModel::Hdl64e, SensorModel::Os1_64, SensorModel::Os1_128, SensorModel::Pandar128][rng.random_range(0..8)],
            _ => [SensorModel::Vlp16, SensorModel::Vlp16, SensorModel::Vlp32c, SensorModel::Hdl32e, SensorModel::Os1_64, SensorModel::Os1_128, SensorModel::Os0_128, SensorModel::Pandar40p][rng.random_range(0..8)],
        };
        let (height, body, mount_x) = match platform {
            Platform::Car => {
                let h = rng.random_range(1.5..2.2);
                let l = rng.random_range(4.2..5.2);
                let roof = (h - rng.random_range(0.15..0.5f64)).min(1.9);
                (h, [l, rng.random_range(1.75..2.0), roof], rng.random_range(-0.6..0.3))
            }
            Platform::Robot => {
                let h = rng.random_range(0.3..1.2);
                (h, [rng.random_range(0.45..0.9), rng.random_range(0.4..0.7), h - rng.random_range(0.08..0.2)], rng.random_range(-0.1..0.1))
            }
            // JRDB's robot: the upper VLP-16 0.335 m above the base frame's origin, 0.7 m up.
            Platform::JrdbRobot => (1.035, [0.7, 0.6, 0.45], 0.0),
            Platform::Mast => (rng.random_range(0.8..2.2), [0.06, 0.06, 0.0], 0.0),
        };
        let tilt_deg = |rng: &mut R| (rng.random_range(-1.0..1.0f64) + rng.random_range(-1.0..1.0) + rng.random_range(-1.0..1.0)).clamp(-3.0, 3.0);
        let tilt = if platform == Platform::JrdbRobot { [0.0, 0.0] } else { [tilt_deg(rng).to_radians(), tilt_deg(rng).to_radians()] };
        Rig { sensor, platform, height, tilt, body, mount_x }
    }

    /// The platform's body in the level frame whose origin is the ground point under the sensor
    /// (x forward).
    pub fn body(&self) -> Parts {
        let [l, w, roof] = self.body;
        let x = -self.mount_x;
        match self.platform {
            Platform::Car => {
                let kind = if roof > 1.65 { Vehicle::Van } else { Vehicle::Car };
                let mut p = vec![(cuboid(x, 0.0, 0.2, l, w, 0.8, 0.0), 0.5), (cuboid(x - 0.1 * l, 0.0, 1.0, 0.55 * l, 0.92 * w, roof - 1.0, 0.0), 0.05)];
                if kind == Vehicle::Van {
                    p[1] = (cuboid(x - 0.1 * l, 0.0, 1.0, 0.75 * l, w, roof - 1.0, 0.0), 0.5);
                }
                // Roof bars and the sensor's mount.
                p.push((cuboid(x - 0.1 * l, 0.0, roof, 0.5 * l, 0.08, 0.05, 0.0), 0.5));
                p.push((Shape::Cylinder { c: [0.0, 0.0], r: 0.07, z0: roof, z1: self.height - 0.08 }, 0.3));
                p
            }
            Platform::Robot => vec![
                (cuboid(x, 0.0, 0.05, l, w, 0.25_f64.min(roof - 0.05), 0.0), 0.4),
                (Shape::Cylinder { c: [x, 0.0], r: 0.45 * w, z0: 0.05, z1: roof }, 0.5),
                (Shape::Cylinder { c: [0.0, 0.0], r: 0.05, z0: roof, z1: self.height - 0.06 }, 0.3),
            ],
            // Below the lower sensor (0.565 m up), and the mast between the two.
            Platform::JrdbRobot => vec![
                (cuboid(x, 0.0, 0.05, l, w, roof - 0.05, 0.0), 0.4),
                (Shape::Cylinder { c: [0.0, 0.0], r: 0.04, z0: 0.62, z1: self.height - 0.07 }, 0.3),
            ],
            Platform::Mast => vec![(Shape::Cylinder { c: [0.0, 0.0], r: 0.03, z0: 0.0, z1: self.height - 0.08 }, 0.4)],
        }
    }

    /// The body in the world: the platform at (x, y) on ground `z`, heading `yaw`.
    pub fn body_at(&self, x: f64, y: f64, z: f64, yaw: f64) -> Parts {
        placed(self.body(), x, y, z, yaw)
    }

    /// Whether the sensor is JRDB's pair of VLP-16.
    pub fn is_jrdb(&self) -> bool {
        self.platform == Platform::JrdbRobot
    }

    /// The sensor's name in statistics.
    pub fn sensor_name(&self) -> &'static str {
        if self.is_jrdb() { "2x vlp16" } else { self.sensor.name() }
    }
}
