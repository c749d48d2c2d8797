//! The ground under a sensor, found in its own scan: a robust plane fit (RANSAC scoring a plane
//! by the returns on it less those below it, then least squares on the inliers) over the returns
//! around and below it. What `detect` needs to move a
//! user's cloud into the frame the models learned (the floor level and a known distance below
//! the origin) without being told the sensor's height and tilt.

use rand::{Rng, SeedableRng};
use rayon::prelude::*;

use crate::sim::geometry::{cross, dot, sub};

/// How the ground is searched for.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GroundSearch {
    /// Returns this far from the sensor in bird's-eye view (metres) are candidates: near enough
    /// to be dense, beyond the platform carrying the sensor.
    pub range: [f32; 2],
    /// Candidates lie at least this far below the sensor (metres).
    pub below: f32,
    /// A return within this distance of the plane is on it (metres).
    pub tolerance: f32,
    /// The plane's normal may lean this far from the sensor's z axis (degrees).
    pub max_tilt_deg: f32,
    /// The fewest returns on the plane, and the smallest share of the candidates, to accept it.
    pub min_inliers: usize,
    /// Share of candidates that must lie on it.
    pub min_share: f32,
    /// RANSAC draws.
    pub iterations: usize,
}

impl Default for GroundSearch {
    fn default() -> Self {
        Self { range: [2.0, 30.0], below: 0.2, tolerance: 0.08, max_tilt_deg: 20.0, min_inliers: 300, min_share: 0.05, iterations: 1024 }
    }
}

/// A plane `normal · p = −height`: the ground `height` metres below the sensor along `normal`
/// (unit, pointing up).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GroundPlane {
    /// Unit normal, z positive.
    pub normal: [f64; 3],
    /// The sensor's distance above the plane (metres).
    pub height: f64,
    /// Candidate returns on the plane.
    pub inliers: usize,
    /// Candidate returns searched.
    pub candidates: usize,
}

impl GroundPlane {
    /// The tilt of the sensor's z axis from the plane's normal (degrees).
    pub fn tilt_deg(&self) -> f64 {
        self.normal[2].clamp(-1.0, 1.0).acos().to_degrees()
    }

    /// Roll (about x, then) pitch (about y), radians, that turn `normal` onto +z:
    /// `R_y(pitch) · R_x(roll) · normal = (0, 0, 1)`.
    pub fn levelling(&self) -> (f64, f64) {
        let [nx, ny, nz] = self.normal;
        let roll = ny.atan2(nz);
        let pitch = (-nx).atan2(ny.hypot(nz));
        (roll, pitch)
    }
}

/// Why no ground was accepted.
#[derive(Debug, Clone, PartialEq)]
pub enum NoGround {
    /// Too few returns in the search ring below the sensor.
    TooFewCandidates(usize),
    /// The best plane held too few of them, or leaned too far.
    NoPlane {
        /// Returns on the best plane found.
        best_inliers: usize,
        /// Returns searched.
        candidates: usize,
    },
}

impl std::fmt::Display for NoGround {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            NoGround::TooFewCandidates(n) => write!(f, "only {n} returns lie around and below the sensor"),
            NoGround::NoPlane { best_inliers, candidates } => {
                write!(f, "no level plane holds enough of the {candidates} returns around and below the sensor (best: {best_inliers})")
            }
        }
    }
}

/// Fits the ground of a scan in the sensor's frame (origin at the sensor, z roughly up).
/// Deterministic: the draws come from a fixed seed.
pub fn fit_ground(points: &[[f32; 3]], s: &GroundSearch) -> Result<GroundPlane, NoGround> {
    let candidates: Vec<[f64; 3]> = points
        .iter()
        .filter(|p| {
            let r = p[0].hypot(p[1]);
            r >= s.range[0] && r <= s.range[1] && p[2] <= -s.below
        })
        .map(|p| p.map(f64::from))
        .collect();
    let n = candidates.len();
    if n < s.min_inliers.max(3) {
        return Err(NoGround::TooFewCandidates(n));
    }
    let min_nz = (s.max_tilt_deg as f64).to_radians().cos();
    let tol = s.tolerance as f64;
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(0x6772_6f75_6e64);
    // Hypotheses are scored on at most ~8,000 of the candidates (every `stride`-th), refined on all.
    let stride = n.div_ceil(8000).max(1);
    // Drawn in order from the seed, scored in parallel, the first best kept: the same plane
    // whatever the number of threads.
    let hypotheses: Vec<([f64; 3], f64)> = (0..s.iterations)
        .filter_map(|_| {
            let [a, b, c] = [0, 1, 2].map(|_| candidates[rng.random_range(0..n)]);
            let mut normal = cross(sub(b, a), sub(c, a));
            let len = dot(normal, normal).sqrt();
            if len < 1e-9 {
                return None;
            }
            normal = normal.map(|x| x / len);
            if normal[2] < 0.0 {
                normal = normal.map(|x| -x);
            }
            (normal[2] >= min_nz).then(|| (normal, -dot(normal, a)))
        })
        .collect();
    let scores: Vec<i64> = hypotheses
        .par_iter()
        .map(|&(normal, d)| {
            // The ground is the lowest surface: returns below a plane count against it. A level
            // band through walls and vehicles can hold more returns than a road split by kerbs,
            // but has the road below it; of a road and a sidewalk beside it, the road wins.
            let (mut on, mut below) = (0i64, 0i64);
            for p in candidates.iter().step_by(stride) {
                let e = dot(normal, *p) + d;
                if e.abs() <= tol {
                    on += 1;
                } else if e < -tol {
                    below += 1;
                }
            }
            on - below
        })
        .collect();
    let mut best: Option<([f64; 3], f64, i64)> = None;
    for (&(normal, d), &score) in hypotheses.iter().zip(&scores) {
        if best.is_none_or(|b| score > b.2) {
            best = Some((normal, d, score));
        }
    }
    let Some((normal, d, _)) = best else { return Err(NoGround::NoPlane { best_inliers: 0, candidates: n }) };
    // Least squares z = αx + βy + γ over the inliers, twice (the second with the refined plane).
    let (mut normal, mut d) = (normal, d);
    let mut inliers = 0;
    for _ in 0..2 {
        let on: Vec<&[f64; 3]> = candidates.iter().filter(|p| (dot(normal, **p) + d).abs() <= tol).collect();
        inliers = on.len();
        if inliers < 3 {
            break;
        }
        let (mut sxx, mut sxy, mut syy, mut sx, mut sy, mut sxz, mut syz, mut sz) = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0);
        for p in &on {
            let [x, y, z] = **p;
            sxx += x * x;
            sxy += x * y;
            syy += y * y;
            sx += x;
            sy += y;
            sxz += x * z;
            syz += y * z;
            sz += z;
        }
        let m = inliers as f64;
        let Some([alpha, beta, gamma]) = solve3([[sxx, sxy, sx], [sxy, syy, sy], [sx, sy, m]], [sxz, syz, sz]) else { break };
        let len = (alpha * alpha + beta * beta + 1.0).sqrt();
        normal = [-alpha / len, -beta / len, 1.0 / len];
        d = -gamma / len;
    }
    if inliers < s.min_inliers || (inliers as f32) < s.min_share * n as f32 || normal[2] < min_nz {
        return Err(NoGround::NoPlane { best_inliers: inliers, candidates: n });
    }
    // normal · p + d = 0 with the origin above the plane: d > 0 is the height.
    Ok(GroundPlane { normal, height: d, inliers, candidates: n })
}

/// `m · x = r` by Cramer's rule; `None` when `m` is singular.
fn solve3(m: [[f64; 3]; 3], r: [f64; 3]) -> Option<[f64; 3]> {
    let det = |m: [[f64; 3]; 3]| {
        m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1]) - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
            + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0])
    };
    let d = det(m);
    if d.abs() < 1e-12 {
        return None;
    }
    let col = |k: usize| {
        let mut c = m;
        for i in 0..3 {
            c[i][k] = r[i];
        }
        det(c) / d
    };
    Some([col(0), col(1), col(2)])
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A ring-scanned floor `height` below a sensor tilted by `roll`, `pitch` (radians), with
    /// clutter above it.
    fn scan(height: f64, roll: f64, pitch: f64) -> Vec<[f32; 3]> {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
        let mut pts = Vec::new();
        for i in 0..6000 {
            let (r, a): (f64, f64) = (rng.random_range(1.0..35.0), rng.random_range(0.0..std::f64::consts::TAU));
            let z = if i % 4 == 0 { rng.random_range(-height..2.0) } else { -height + rng.random_range(-0.02..0.02) };
            pts.push([r * a.cos(), r * a.sin(), z]);
        }
        // The sensor is tilted: its frame sees the world turned by R_x(−roll)·R_y(−pitch).
        pts.iter()
            .map(|&[x, y, z]| {
                let (sp, cp) = (-pitch).sin_cos();
                let (x, z) = (cp * x + sp * z, -sp * x + cp * z);
                let (sr, cr) = (-roll).sin_cos();
                let (y, z) = (cr * y - sr * z, sr * y + cr * z);
                [x as f32, y as f32, z as f32]
            })
            .collect()
    }

    #[test]
    fn finds_the_height_and_tilt_it_was_given() {
        for (h, roll, pitch) in [(1.73, 0.0, 0.0), (0.4, 0.03, -0.05), (2.1, -0.06, 0.04), (1.0, 0.0, 0.09)] {
            let g = fit_ground(&scan(h, roll, pitch), &GroundSearch::default()).unwrap();
            assert!((g.height - h).abs() < 0.02, "height {} for {h}", g.height);
            let (r, p) = g.levelling();
            assert!((r - roll).abs() < 0.01 && (p - pitch).abs() < 0.01, "roll {r} pitch {p} for {roll} {pitch}");
        }
    }

    #[test]
    fn a_scan_without_ground_says_so() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(9);
        let sky: Vec<[f32; 3]> = (0..5000).map(|_| [rng.random_range(-20.0..20.0), rng.random_range(-20.0..20.0), rng.random_range(0.5..6.0)]).collect();
        assert!(matches!(fit_ground(&sky, &GroundSearch::default()), Err(NoGround::TooFewCandidates(_))));
        let wall: Vec<[f32; 3]> = (0..5000).map(|_| [5.0, rng.random_range(-20.0..20.0), rng.random_range(-3.0..-0.5)]).collect();
        assert!(matches!(fit_ground(&wall, &GroundSearch::default()), Err(NoGround::NoPlane { .. })));
    }

    #[test]
    fn the_plane_does_not_depend_on_the_number_of_threads() {
        let points = scan(1.2, 0.02, -0.03);
        let on = |threads: usize| rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap().install(|| fit_ground(&points, &GroundSearch::default()));
        let one = on(1).unwrap();
        assert_eq!(on(3).unwrap(), one);
        assert_eq!(on(8).unwrap(), one);
    }
}
