//! The BEV grid of the dense baseline: pillar cells of the input and the coarser cells of the
//! heatmap. Images are laid out `[B, C, X, Y]`: the third axis is x, the fourth y.

use super::config::CenterPointConfig;

/// Pillar grid and output grid of a [`CenterPointConfig`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BevGrid {
    /// Lower corner (x, y, z), metres.
    pub min: [f64; 3],
    /// Pillar size (x, y, z), metres.
    pub voxel: [f64; 3],
    /// Pillars along x, y and height slices along z.
    pub size: [usize; 3],
    /// Output (heatmap) stride in pillars.
    pub out_stride: usize,
}

impl BevGrid {
    /// The grid of a config; the output stride is the first down stride over the first up factor.
    ///
    /// # Panics
    /// If the ranges, sizes or strides are inconsistent.
    pub fn new(cfg: &CenterPointConfig) -> Self {
        let ranges = [cfg.x_range, cfg.y_range, cfg.z_range];
        let size = [0, 1, 2].map(|k| {
            let n = (ranges[k][1] - ranges[k][0]) / cfg.voxel_size[k];
            assert!(n >= 1.0 - 1e-6, "range {:?} holds no voxel of {}", ranges[k], cfg.voxel_size[k]);
            (n - 1e-6).ceil() as usize
        });
        let down: usize = cfg.down_strides.iter().product();
        assert!(
            size[0] % down == 0 && size[1] % down == 0,
            "a BEV grid of {}×{} pillars must be divisible by the down strides' product {down}",
            size[0],
            size[1]
        );
        assert!(!cfg.down_strides.is_empty() && cfg.up_strides[0] > 0, "at least one block with a positive up factor");
        assert!(cfg.down_strides[0].is_multiple_of(cfg.up_strides[0]), "the first block's stride must be a multiple of its up factor");
        BevGrid {
            min: [cfg.x_range[0], cfg.y_range[0], cfg.z_range[0]],
            voxel: cfg.voxel_size,
            size,
            out_stride: cfg.down_strides[0] / cfg.up_strides[0],
        }
    }

    /// The pillar `(x, y, z-slice)` of a point, `None` outside the grid.
    pub fn pillar_of(&self, p: [f64; 3]) -> Option<[usize; 3]> {
        let mut out = [0usize; 3];
        for k in 0..3 {
            let i = ((p[k] - self.min[k]) / self.voxel[k]).floor();
            if !(i >= 0.0 && i < self.size[k] as f64) {
                return None;
            }
            out[k] = i as usize;
        }
        Some(out)
    }

    /// Centre (x, y) of a pillar, metres.
    pub fn pillar_centre(&self, ix: usize, iy: usize) -> [f64; 2] {
        [self.min[0] + (ix as f64 + 0.5) * self.voxel[0], self.min[1] + (iy as f64 + 0.5) * self.voxel[1]]
    }

    /// Heatmap size (x, y).
    pub fn out_size(&self) -> [usize; 2] {
        [self.size[0] / self.out_stride, self.size[1] / self.out_stride]
    }

    /// Heatmap cell size (x, y), metres.
    pub fn out_cell(&self) -> [f64; 2] {
        [self.voxel[0] * self.out_stride as f64, self.voxel[1] * self.out_stride as f64]
    }

    /// Continuous heatmap coordinates of a point in the ground plane (cell i spans [i, i + 1)).
    pub fn to_cells(&self, x: f64, y: f64) -> [f64; 2] {
        let c = self.out_cell();
        [(x - self.min[0]) / c[0], (y - self.min[1]) / c[1]]
    }

    /// The inverse of [`BevGrid::to_cells`].
    pub fn from_cells(&self, u: f64, v: f64) -> [f64; 2] {
        let c = self.out_cell();
        [self.min[0] + u * c[0], self.min[1] + v * c[1]]
    }
}
