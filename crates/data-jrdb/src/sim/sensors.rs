//! Spinning LiDARs by their datasheets' beam tables: what `bench-v2` mounts on its platforms.
//!
//! Elevations are the vendors' published per-laser angles (rounded to 0.01°) or, where a
//! datasheet gives only the field of view and the spacing, that spacing. Columns are one
//! revolution's firings at the rate the sensor is most often run at (10 Hz; nuScenes' HDL-32E at
//! 20 Hz).

use super::lidar::Scanner;

/// A sensor model.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SensorModel {
    /// Velodyne VLP-16 (Puck): 16 beams, ±15° every 2°.
    Vlp16,
    /// Velodyne HDL-32E: 32 beams, −30.67° to +10.67° every 1.33°.
    Hdl32e,
    /// Velodyne VLP-32C (Ultra Puck): 32 beams, −25° to +15°, dense around the horizon.
    Vlp32c,
    /// Two VLP-32C stacked, the upper one upside down (Argoverse 2's rig): 64 beams, −25° to +25.2°.
    Vlp32cPair,
    /// Hesai Pandar40P: 40 beams, −25° to +15°, 0.33° apart from −6° to +2°.
    Pandar40p,
    /// Velodyne HDL-64E: 64 beams, +2° to −24.9° (0.33° in the upper block, 0.5° in the lower).
    Hdl64e,
    /// Ouster OS1-64: 64 beams, ±22.5° uniform, 1024 columns.
    Os1_64,
    /// Ouster OS1-128: 128 beams, ±22.5° uniform, 1024 columns.
    Os1_128,
    /// Ouster OS0-128: 128 beams, ±45° uniform, 1024 columns (a robot's wide-view sensor).
    Os0_128,
    /// Hesai Pandar64: 64 beams, −25° to +15°, 0.167° apart from −6° to +2° (real backdrops'
    /// sensor; no `bench-v2` rig draws it).
    Pandar64,
    /// Hesai Pandar128: 128 beams, −25° to +15°, 0.125° apart from −6° to +2°.
    Pandar128,
    /// Ouster OS1-64 of the first generation at 2048 columns: 64 beams, ±16.6° uniform (RELLIS-3D's
    /// robot-mounted backdrops; no `bench-v2` rig draws it).
    Os1_64Gen1,
}

impl SensorModel {
    /// Every model, in the order above.
    pub const ALL: [SensorModel; 12] = [
        SensorModel::Vlp16,
        SensorModel::Hdl32e,
        SensorModel::Vlp32c,
        SensorModel::Vlp32cPair,
        SensorModel::Pandar40p,
        SensorModel::Hdl64e,
        SensorModel::Os1_64,
        SensorModel::Os1_128,
        SensorModel::Os0_128,
        SensorModel::Pandar128,
        SensorModel::Pandar64,
        SensorModel::Os1_64Gen1,
    ];

    /// Its name in statistics and file names.
    pub fn name(self) -> &'static str {
        match self {
            SensorModel::Vlp16 => "vlp16",
            SensorModel::Hdl32e => "hdl32e",
            SensorModel::Vlp32c => "vlp32c",
            SensorModel::Vlp32cPair => "vlp32c-pair",
            SensorModel::Pandar40p => "pandar40p",
            SensorModel::Hdl64e => "hdl64e",
            SensorModel::Os1_64 => "os1-64",
            SensorModel::Os1_128 => "os1-128",
            SensorModel::Os0_128 => "os0-128",
            SensorModel::Pandar128 => "pandar128",
            SensorModel::Pandar64 => "pandar64",
            SensorModel::Os1_64Gen1 => "os1-64-gen1",
        }
    }

    /// The model a name (as [`name`](Self::name) writes it) names.
    pub fn from_name(name: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|m| m.name() == name)
    }

    /// Beam elevations in degrees, lowest first.
    pub fn elevations_deg(self) -> Vec<f64> {
        let uniform = |lo: f64, hi: f64, n: usize| -> Vec<f64> { (0..n).map(|k| lo + (hi - lo) * k as f64 / (n - 1) as f64).collect() };
        let mut e = match self {
            SensorModel::Vlp16 => uniform(-15.0, 15.0, 16),
            SensorModel::Hdl32e => uniform(-30.67, 10.67, 32),
            SensorModel::Vlp32c => VLP32C.to_vec(),
            // The upside-down sensor's beams fall between the upright one's (half its finest step
            // apart) rather than on them: the two sit 10–20 cm apart and fire out of phase.
            SensorModel::Vlp32cPair => VLP32C.iter().flat_map(|&a| [a, 0.165 - a]).collect(),
            SensorModel::Pandar40p => {
                let mut e = vec![15.0, 11.0, 8.0, 5.0, 3.0, 2.0, -7.0, -8.0, -9.0, -10.0, -11.0, -12.0, -13.0, -14.0, -19.0, -25.0];
                e.extend(uniform(-6.0, 5.0 / 3.0, 24));
                e
            }
            SensorModel::Hdl64e => {
                let mut e = uniform(-8.33, 2.0, 32);
                e.extend(uniform(-24.33, -8.83, 32));
                e
            }
            SensorModel::Os1_64 => uniform(-22.5, 22.5, 64),
            SensorModel::Os1_64Gen1 => uniform(-16.6, 16.6, 64),
            SensorModel::Os1_128 => uniform(-22.5, 22.5, 128),
            SensorModel::Os0_128 => uniform(-45.0, 45.0, 128),
            SensorModel::Pandar64 => {
                let mut e = vec![15.0, 11.0, 8.0, 5.0, 3.0, -7.0, -8.0, -9.0, -10.0, -11.0, -12.0, -13.0, -14.0, -19.0, -25.0];
                e.extend(uniform(-6.0, 2.0, 49));
                e
            }
            SensorModel::Pandar128 => {
                let mut e = uniform(-6.0, 2.0, 64);
                e.extend(uniform(2.6, 15.0, 14));
                e.extend(uniform(-25.0, -6.4, 50));
                e
            }
        };
        e.sort_by(f64::total_cmp);
        e
    }

    /// Beam elevations in radians, lowest first.
    pub fn elevations(self) -> Vec<f64> {
        self.elevations_deg().into_iter().map(f64::to_radians).collect()
    }

    /// The mechanics: columns per revolution, range limits and noise.
    pub fn scanner(self) -> Scanner {
        let (columns, max_range, range_noise) = match self {
            SensorModel::Vlp16 => (1800, 100.0, 0.015),
            SensorModel::Hdl32e => (1084, 80.0, 0.02),
            SensorModel::Vlp32c | SensorModel::Vlp32cPair => (1800, 100.0, 0.015),
            SensorModel::Pandar40p => (1800, 100.0, 0.02),
            SensorModel::Hdl64e => (2000, 100.0, 0.02),
            SensorModel::Os1_64 | SensorModel::Os1_128 => (1024, 100.0, 0.015),
            SensorModel::Os0_128 => (1024, 50.0, 0.02),
            SensorModel::Os1_64Gen1 => (2048, 100.0, 0.015),
            SensorModel::Pandar128 | SensorModel::Pandar64 => (1800, 100.0, 0.02),
        };
        Scanner { columns, max_range, range_noise, ..Scanner::default() }
    }
}

/// The VLP-32C's 32 laser elevations (degrees), from its user manual's table.
const VLP32C: [f64; 32] = [
    -25.0, -15.64, -11.31, -8.84, -7.25, -6.15, -5.33, -4.67, -4.0, -3.67, -3.33, -3.0, -2.67, -2.33, -2.0, -1.67, -1.33, -1.0, -0.67, -0.33, 0.0, 0.33, 0.67, 1.0,
    1.33, 1.67, 2.33, 3.33, 4.67, 7.0, 10.33, 15.0,
];

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn beam_tables_have_the_datasheets_counts_and_fields_of_view() {
        for (m, n, lo, hi) in [
            (SensorModel::Vlp16, 16, -15.0, 15.0),
            (SensorModel::Hdl32e, 32, -30.67, 10.67),
            (SensorModel::Vlp32c, 32, -25.0, 15.0),
            (SensorModel::Vlp32cPair, 64, -25.0, 25.165),
            (SensorModel::Pandar40p, 40, -25.0, 15.0),
            (SensorModel::Hdl64e, 64, -24.33, 2.0),
            (SensorModel::Os1_64, 64, -22.5, 22.5),
            (SensorModel::Os1_128, 128, -22.5, 22.5),
            (SensorModel::Os0_128, 128, -45.0, 45.0),
            (SensorModel::Pandar128, 128, -25.0, 15.0),
            (SensorModel::Pandar64, 64, -25.0, 15.0),
            (SensorModel::Os1_64Gen1, 64, -16.6, 16.6),
        ] {
            let e = m.elevations_deg();
            assert_eq!(e.len(), n, "{}", m.name());
            assert!((e[0] - lo).abs() < 1e-9 && (e[n - 1] - hi).abs() < 1e-9, "{}: {:?}", m.name(), (e[0], e[n - 1]));
            assert!(e.windows(2).all(|w| w[1] > w[0]), "{}: beams are distinct and sorted", m.name());
        }
        // The VLP-16's table is the one bench-v1 scans with.
        let v: Vec<f64> = Scanner::elevations().to_vec();
        assert_eq!(SensorModel::Vlp16.elevations(), v);
    }
}
