//! Spinning LiDARs ray-cast against the scene, with range noise and dropped returns: a Velodyne
//! VLP-16 (16 beams over ±15°, 0.2° azimuth steps, ~100 m) and, through [`scan_beams`], any beam
//! table (`sensors`).
//!
//! Occlusion, shadows, ring structure and density falling with range come from the geometry.
//! Randomness per ray is a hash of (seed, ray index), so scans are deterministic under rayon.

use rayon::prelude::*;

use super::geometry::{V3, rot};
use super::scene::Prim;

/// A spinning sensor's mechanics (its default: a VLP-16's).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Scanner {
    /// Azimuth columns per revolution (1800 at 0.2°).
    pub columns: usize,
    /// Longest range returned (metres).
    pub max_range: f64,
    /// Shortest range returned (metres).
    pub min_range: f64,
    /// Standard deviation of the range noise (metres).
    pub range_noise: f64,
    /// Dropout probability of a square-on, bright, near return.
    pub dropout: f64,
}

impl Default for Scanner {
    fn default() -> Self {
        Self { columns: 1800, max_range: 100.0, min_range: 0.4, range_noise: 0.012, dropout: 0.02 }
    }
}

/// One return in the sensor frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Return {
    /// Position in the sensor frame (m).
    pub xyz: V3,
    /// Return strength (0–255): the surface's reflectivity, the incidence angle and the range.
    pub intensity: f32,
    /// Beam index, 0 = lowest (−15°).
    pub ring: u16,
}

/// Uniform number in [0, 1) from a hashed key.
fn unit(key: u64) -> f64 {
    let mut z = key.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^= z >> 31;
    (z >> 11) as f64 / (1u64 << 53) as f64
}

const BINS: usize = 720;

impl Scanner {
    /// A VLP-16's beam elevations (radians), lowest first.
    pub fn elevations() -> [f64; 16] {
        std::array::from_fn(|k| (-15.0 + 2.0 * k as f64).to_radians())
    }

    /// Scans the scene with a VLP-16's beams from `origin` (world) with the sensor's x axis at
    /// `yaw` (world).
    ///
    /// Returns are ordered column by column (azimuth), then by ring, as the driver emits them.
    pub fn scan(&self, prims: &[Prim], origin: V3, yaw: f64, seed: u64) -> Vec<Return> {
        self.scan_beams(&Self::elevations(), prims, origin, yaw, None, seed)
    }

    /// Ray-casts one revolution with beams at `elevations` (radians, lowest first) from `origin`,
    /// the sensor's x axis at `yaw` (world) after `tilt` (roll about x, then pitch about y) tips
    /// it. Returns are in the sensor's own frame, column by column, then by ring.
    ///
    /// Every sensor model shares this, so the ray keys (column × beams + beam) and the noise
    /// draws of a VLP-16 without tilt are bench-v1's, bit for bit.
    pub fn scan_beams(&self, elevations: &[f64], prims: &[Prim], origin: V3, yaw: f64, tilt: Option<[f64; 2]>, seed: u64) -> Vec<Return> {
        scan_beams(self, elevations, prims, origin, yaw, tilt, seed)
    }
}

fn scan_beams(p: &Scanner, elevations: &[f64], prims: &[Prim], origin: V3, yaw: f64, tilt: Option<[f64; 2]>, seed: u64) -> Vec<Return> {
    let beams = elevations.len();
    // Azimuth bins of candidate shapes (world azimuth around the origin); planes go everywhere.
    let mut bins: Vec<Vec<u32>> = vec![Vec::new(); BINS];
    let bw = std::f64::consts::TAU / BINS as f64;
    let mut everywhere = Vec::new();
    // A tilted sensor's ray sweeps at most `tilt` off its column's azimuth near the zenith; its
    // beams stay within 45 degrees of the horizon, where the azimuth moves by less than twice it.
    let slack = tilt.map_or(0.0, |[r, q]| 2.0 * r.abs().max(q.abs()));
    for (i, pr) in prims.iter().enumerate() {
        let Some((c, r)) = pr.shape.bounds_xy() else {
            everywhere.push(i as u32);
            continue;
        };
        let (dx, dy) = (c[0] - origin[0], c[1] - origin[1]);
        let d = dx.hypot(dy);
        if d - r > p.max_range {
            continue;
        }
        if d <= r + 0.05 {
            everywhere.push(i as u32);
            continue;
        }
        let half = (r / d).asin() + bw + slack;
        let a = dy.atan2(dx).rem_euclid(std::f64::consts::TAU);
        let (b0, b1) = (((a - half) / bw).floor() as i64, ((a + half) / bw).floor() as i64);
        for b in b0..=b1 {
            bins[b.rem_euclid(BINS as i64) as usize].push(i as u32);
        }
    }
    let start = column_start(seed, p.columns);
    let cols: Vec<Vec<Return>> = (0..p.columns)
        .into_par_iter()
        .map(|j| {
            let az = start + j as f64 * std::f64::consts::TAU / p.columns as f64;
            let waz = (az + yaw).rem_euclid(std::f64::consts::TAU);
            let bin = &bins[((waz / bw) as usize).min(BINS - 1)];
            let mut out = Vec::with_capacity(beams);
            for (k, &el) in elevations.iter().enumerate() {
                let ds = [el.cos() * az.cos(), el.cos() * az.sin(), el.sin()];
                let d = rot(tilt.map_or(ds, |t| tip(ds, t)), yaw);
                let mut best: Option<(f64, V3, f32)> = None;
                for &i in everywhere.iter().chain(bin) {
                    let pr = &prims[i as usize];
                    let t_max = best.map_or(p.max_range, |b| b.0);
                    if let Some(h) = pr.shape.intersect(origin, d, t_max) {
                        best = Some((h.t, h.normal, pr.reflectivity));
                    }
                }
                let Some((t, n, refl)) = best else { continue };
                if t < p.min_range {
                    continue;
                }
                let key = seed ^ ((j * beams + k) as u64).wrapping_mul(0xD6E8_FEB8_6659_FD93);
                let cos = -(n[0] * d[0] + n[1] * d[1] + n[2] * d[2]);
                let cos = cos.abs().clamp(0.0, 1.0);
                let rr = t / p.max_range;
                let p_drop = p.dropout + 0.35 * (1.0 - cos).powi(6) + 0.2 * rr * rr + if refl < 0.2 { 0.05 } else { 0.0 };
                if unit(key ^ 1) < p_drop {
                    continue;
                }
                // Box–Muller range noise.
                let (u1, u2) = (unit(key ^ 2).max(1e-12), unit(key ^ 3));
                let noise = p.range_noise * (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos();
                let r = t + noise;
                let intensity = (255.0 * refl as f64 * (0.3 + 0.7 * cos) * (1.0 - 0.5 * rr) + 4.0 * (unit(key ^ 4) - 0.5)).clamp(0.0, 255.0).round();
                out.push(Return { xyz: [ds[0] * r, ds[1] * r, ds[2] * r], intensity: intensity as f32, ring: k as u16 });
            }
            out
        })
        .collect();
    cols.into_iter().flatten().collect()
}

/// The azimuth (sensor frame, radians) of the first column of the scan drawn with `seed`: each
/// revolution starts at a random fraction of a column.
pub(super) fn column_start(seed: u64, columns: usize) -> f64 {
    unit(seed) * std::f64::consts::TAU / columns as f64
}

/// A direction of the tipped sensor's frame in the level frame: `R_y(pitch) · R_x(roll) · d`.
pub fn tip([x, y, z]: V3, [roll, pitch]: [f64; 2]) -> V3 {
    let (sr, cr) = roll.sin_cos();
    let (y, z) = (cr * y - sr * z, sr * y + cr * z);
    let (sp, cp) = pitch.sin_cos();
    [cp * x + sp * z, y, -sp * x + cp * z]
}

/// The inverse of [`tip`]: `R_x(−roll) · R_y(−pitch) · d`.
pub fn untip([x, y, z]: V3, [roll, pitch]: [f64; 2]) -> V3 {
    let (sp, cp) = pitch.sin_cos();
    let (x, z) = (cp * x - sp * z, sp * x + cp * z);
    let (sr, cr) = roll.sin_cos();
    [x, cr * y + sr * z, -sr * y + cr * z]
}
