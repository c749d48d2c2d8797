//! Voxelization (the authors'): one voxel per occupied cell, the first point's xyz as its feature.
//!
//! A point p lies in the voxel `round(p / voxel_size)` (ties to even, as NumPy rounds), so the
//! voxel's cell is `[C − ½, C + ½] · voxel_size` and its centre is `C · voxel_size`. The authors'
//! `(C + 0.5) · vs` reference sits half a voxel off; we use the true centre (the regression
//! absorbs the difference).

use std::collections::HashMap;
use std::hash::{BuildHasherDefault, Hasher};

use rand::Rng;
use rand::seq::index::sample;

/// How a voxel's feature is made from its points.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Pooling {
    /// The first point of the voxel in cloud order (the authors' `sparse_quantize`).
    #[default]
    First,
    /// The mean of the voxel's points.
    Mean,
}

/// Voxel size and pooling.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default)]
pub struct VoxelConfig {
    /// Metres per voxel along x, y, z.
    pub voxel_size: [f32; 3],
    /// Feature pooling.
    pub pooling: Pooling,
}

impl Default for VoxelConfig {
    fn default() -> Self {
        Self { voxel_size: [0.05, 0.05, 0.1], pooling: Pooling::First }
    }
}

/// The occupied voxels of one cloud, in order of first occurrence.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Voxels {
    /// Integer voxel coordinates (x, y, z).
    pub coords: Vec<[i32; 3]>,
    /// Feature of each voxel: raw xyz in metres (first point or mean).
    pub features: Vec<[f32; 3]>,
    /// Number of points that fell in each voxel.
    pub counts: Vec<u32>,
}

impl Voxels {
    /// Number of voxels.
    pub fn len(&self) -> usize {
        self.coords.len()
    }

    /// Whether there are none.
    pub fn is_empty(&self) -> bool {
        self.coords.is_empty()
    }

    /// Keeps at most `max` voxels, chosen uniformly without replacement (order preserved).
    pub fn subsample<R: Rng + ?Sized>(self, max: usize, rng: &mut R) -> Voxels {
        if self.len() <= max {
            return self;
        }
        let mut keep = sample(rng, self.len(), max).into_vec();
        keep.sort_unstable();
        Voxels {
            coords: keep.iter().map(|&i| self.coords[i]).collect(),
            features: keep.iter().map(|&i| self.features[i]).collect(),
            counts: keep.iter().map(|&i| self.counts[i]).collect(),
        }
    }
}

/// The voxel coordinate of a point.
pub fn voxel_coord(p: [f32; 3], voxel_size: [f32; 3]) -> [i32; 3] {
    [0, 1, 2].map(|k| (p[k] / voxel_size[k]).round_ties_even() as i32)
}

/// The centre of voxel `c` in metres.
pub fn voxel_centre(c: [i32; 3], voxel_size: [f32; 3]) -> [f32; 3] {
    [0, 1, 2].map(|k| c[k] as f32 * voxel_size[k])
}

/// Voxelizes a cloud (no cap: see [`Voxels::subsample`] for the training cap).
pub fn voxelize(points: &[[f32; 3]], cfg: &VoxelConfig) -> Voxels {
    let mut index: HashMap<[i32; 3], u32, BuildHasherDefault<CoordHasher>> =
        HashMap::with_capacity_and_hasher(points.len(), Default::default());
    let mut v = Voxels::default();
    let mut sums: Vec<[f64; 3]> = Vec::new();
    for &p in points {
        let c = voxel_coord(p, cfg.voxel_size);
        let next = v.coords.len() as u32;
        let i = *index.entry(c).or_insert(next) as usize;
        if i == v.coords.len() {
            v.coords.push(c);
            v.features.push(p);
            v.counts.push(0);
            if cfg.pooling == Pooling::Mean {
                sums.push([0.0; 3]);
            }
        }
        v.counts[i] += 1;
        if cfg.pooling == Pooling::Mean {
            for k in 0..3 {
                sums[i][k] += p[k] as f64;
            }
        }
    }
    if cfg.pooling == Pooling::Mean {
        for (f, (s, &n)) in v.features.iter_mut().zip(sums.iter().zip(&v.counts)) {
            *f = [0, 1, 2].map(|k| (s[k] / n as f64) as f32);
        }
    }
    v
}

/// A fast hasher for small integer keys (the std SipHash is several times slower here).
#[derive(Default)]
struct CoordHasher(u64);

impl Hasher for CoordHasher {
    fn finish(&self) -> u64 {
        self.0
    }
    fn write(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.write_u64(b as u64);
        }
    }
    fn write_i32(&mut self, i: i32) {
        self.write_u64(i as u32 as u64);
    }
    fn write_u64(&mut self, i: u64) {
        self.0 = (self.0.rotate_left(5) ^ i).wrapping_mul(0x51_7c_c1_b7_27_22_0a_95);
    }
    fn write_usize(&mut self, i: usize) {
        self.write_u64(i as u64);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    fn cloud(n: usize) -> Vec<[f32; 3]> {
        let mut r = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        (0..n).map(|_| [r.random_range(-5.0..5.0), r.random_range(-5.0..5.0), r.random_range(-1.0..2.0)]).collect()
    }

    #[test]
    fn every_point_lies_in_its_voxel_and_first_point_wins() {
        let cfg = VoxelConfig::default();
        let pts = cloud(20000);
        let v = voxelize(&pts, &cfg);
        assert!(v.len() <= pts.len());
        assert_eq!(v.counts.iter().map(|&c| c as usize).sum::<usize>(), pts.len());
        let mut seen = std::collections::HashSet::new();
        for p in &pts {
            let c = voxel_coord(*p, cfg.voxel_size);
            let ctr = voxel_centre(c, cfg.voxel_size);
            for k in 0..3 {
                assert!((p[k] - ctr[k]).abs() <= cfg.voxel_size[k] / 2.0 + 1e-5);
            }
            if seen.insert(c) {
                let i = v.coords.iter().position(|&q| q == c).unwrap();
                assert_eq!(v.features[i], *p);
            }
        }
        assert_eq!(seen.len(), v.len());
    }

    #[test]
    fn mean_pooling_and_cap() {
        let pts = vec![[0.0, 0.0, 0.0], [0.02, 0.0, 0.04], [1.0, 1.0, 1.0]];
        let v = voxelize(&pts, &VoxelConfig { pooling: Pooling::Mean, ..Default::default() });
        assert_eq!(v.len(), 2);
        assert_eq!(v.features[0], [0.01, 0.0, 0.02]);
        let big = voxelize(&cloud(20000), &VoxelConfig::default());
        let mut r = rand_chacha::ChaCha8Rng::seed_from_u64(1);
        let capped = big.clone().subsample(1000, &mut r);
        assert_eq!(capped.len(), 1000);
        assert!(capped.coords.iter().all(|c| big.coords.contains(c)));
    }
}
