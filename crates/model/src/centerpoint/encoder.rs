//! Pillar feature encoder (PointPillars / CenterPoint `PillarFeatureNet`, CenterPoint's
//! `readers/pillar_encoder.py`) and the scatter to a dense BEV image.
//!
//! The "points" are the batch's voxels (raw xyz of each voxel's point), grouped into pillars on
//! the CPU. Each point is decorated to `[x, y, z, x − x̄, y − ȳ, z − z̄, x − x_c, y − y_c]` (pillar
//! mean x̄, pillar centre x_c); each PFN layer is Linear (no bias) → BN (eps 1e-3, momentum 0.01 by default) →
//! ReLU → max over the pillar's points, every layer but the last concatenating that max to each
//! point's features.

use data_jrdb::Batch;
use sparse_conv::burn::module::Module;
use sparse_conv::burn::nn::{BatchNorm, BatchNormConfig, Linear, LinearConfig};
use sparse_conv::burn::tensor::activation::relu;
use sparse_conv::burn::tensor::{Device, IndexingUpdateOp, Int, Tensor, TensorData};

use super::grid::BevGrid;

/// Decorated point features per point.
pub const POINT_FEATURES: usize = 8;

/// Pillars of one batch, on the CPU: which points each holds and where each lands in the image.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Pillars {
    /// Decorated features of the kept points, `N × 8` row-major.
    pub points: Vec<f32>,
    /// Pillar of each kept point, `N`.
    pub point_pillar: Vec<i64>,
    /// `P × K` rows into the points, `N` (a zero row) where a pillar has fewer than K points.
    pub slots: Vec<i64>,
    /// Points per pillar slot row, K.
    pub k: usize,
    /// Flat index of each pillar in `[B, Z, X, Y]`, `P`.
    pub cell: Vec<i64>,
    /// Samples in the batch.
    pub batch: usize,
}

impl Pillars {
    /// Groups the batch's voxels into pillars of `grid`, keeping the first `max_points` of each
    /// (in batch order); voxels outside the grid are dropped.
    pub fn new(batch: &Batch, grid: &BevGrid, max_points: usize) -> Self {
        let [nx, ny, nz] = grid.size;
        let mut index = std::collections::HashMap::<i64, usize>::new();
        let mut members: Vec<Vec<usize>> = Vec::new();
        let mut cell = Vec::new();
        for s in 0..batch.len() {
            for row in batch.rows(s) {
                let p = batch.point(row).map(f64::from);
                let Some([ix, iy, iz]) = grid.pillar_of(p) else { continue };
                let flat = (((s * nz + iz) * nx + ix) * ny + iy) as i64;
                let id = *index.entry(flat).or_insert_with(|| {
                    members.push(Vec::new());
                    cell.push(flat);
                    members.len() - 1
                });
                if members[id].len() < max_points {
                    members[id].push(row);
                }
            }
        }
        let k = members.iter().map(Vec::len).max().unwrap_or(1).max(1);
        let n: usize = members.iter().map(Vec::len).sum();
        let mut out = Pillars { k, cell, batch: batch.len(), ..Default::default() };
        out.points.reserve(n * POINT_FEATURES);
        for (id, rows) in members.iter().enumerate() {
            let xyz: Vec<[f64; 3]> = rows.iter().map(|&r| batch.point(r).map(f64::from)).collect();
            let mean = [0, 1, 2].map(|k| xyz.iter().map(|p| p[k]).sum::<f64>() / xyz.len() as f64);
            let p0 = xyz[0];
            let [ix, iy, _] = grid.pillar_of(p0).expect("members lie in the grid");
            let centre = grid.pillar_centre(ix, iy);
            let first = out.point_pillar.len();
            for p in &xyz {
                let f = [p[0], p[1], p[2], p[0] - mean[0], p[1] - mean[1], p[2] - mean[2], p[0] - centre[0], p[1] - centre[1]];
                out.points.extend(f.map(|x| x as f32));
                out.point_pillar.push(id as i64);
            }
            out.slots.extend((0..k).map(|j| if j < rows.len() { (first + j) as i64 } else { n as i64 }));
        }
        out
    }

    /// Number of pillars.
    pub fn len(&self) -> usize {
        self.cell.len()
    }

    /// Whether there are no pillars.
    pub fn is_empty(&self) -> bool {
        self.cell.is_empty()
    }

    /// Number of kept points.
    pub fn num_points(&self) -> usize {
        self.point_pillar.len()
    }
}

fn ints(v: &[i64], device: &Device) -> Tensor<1, Int> {
    Tensor::<1, Int>::from_data(TensorData::new(v.to_vec(), [v.len()]), device)
}

/// One PFN layer: Linear (no bias) → BN → ReLU.
#[derive(Module, Debug)]
pub struct PfnLayer {
    /// `[C_in → C_out]`, no bias.
    pub linear: Linear,
    /// BatchNorm1d over points (eps 1e-3).
    pub norm: BatchNorm,
}

/// The PointNet over each pillar's points, max-pooled per pillar.
#[derive(Module, Debug)]
pub struct PillarEncoder {
    /// Layers in order; every one but the last outputs half its filters and concatenates the max.
    pub layers: Vec<PfnLayer>,
}

impl PillarEncoder {
    /// Layers for `filters` (e.g. [64, 64]).
    pub fn new(filters: &[usize], momentum: f64, device: &Device) -> Self {
        assert!(!filters.is_empty(), "at least one PFN layer");
        let mut c_in = POINT_FEATURES;
        let layers = filters
            .iter()
            .enumerate()
            .map(|(i, &f)| {
                let last = i + 1 == filters.len();
                let c_out = if last { f } else { (f / 2).max(1) };
                let layer = PfnLayer {
                    linear: LinearConfig::new(c_in, c_out).with_bias(false).init(device),
                    norm: BatchNormConfig::new(c_out).with_epsilon(1e-3).with_momentum(momentum).init(device),
                };
                c_in = if last { f } else { 2 * c_out };
                layer
            })
            .collect();
        Self { layers }
    }

    /// Channels of the pillar features.
    pub fn out_channels(&self) -> usize {
        self.layers.last().expect("at least one layer").linear.weight.dims()[1]
    }

    /// Pillar features `[P, C]`.
    pub fn forward(&self, pillars: &Pillars, device: &Device) -> Tensor<2> {
        let n = pillars.num_points();
        let (p, k) = (pillars.len(), pillars.k);
        let slots = ints(&pillars.slots, device);
        let point_pillar = ints(&pillars.point_pillar, device);
        let mut x = Tensor::<2>::from_data(TensorData::new(pillars.points.clone(), [n, POINT_FEATURES]), device);
        for (i, layer) in self.layers.iter().enumerate() {
            let y = relu(layer.norm.forward(layer.linear.forward(x)));
            let c = y.dims()[1];
            // ReLU outputs are ≥ 0 and every pillar has a point, so zero padding leaves the max alone.
            let padded = Tensor::cat(vec![y.clone(), Tensor::zeros([1, c], device)], 0);
            let pooled = padded.select(0, slots.clone()).reshape([p, k, c]).max_dim(1).reshape([p, c]);
            if i + 1 == self.layers.len() {
                return pooled;
            }
            x = Tensor::cat(vec![y, pooled.select(0, point_pillar.clone())], 1);
        }
        unreachable!("the loop returns at its last layer")
    }

    /// The dense BEV image `[B, Z·C, X, Y]` of pillar features `[P, C]` (zero where no pillar).
    pub fn scatter(features: Tensor<2>, pillars: &Pillars, grid: &BevGrid, device: &Device) -> Tensor<4> {
        let [nx, ny, nz] = grid.size;
        let c = features.dims()[1];
        let b = pillars.batch;
        let canvas = Tensor::<2>::zeros([b * nz * nx * ny, c], device);
        let canvas = if pillars.is_empty() {
            canvas
        } else {
            canvas.select_assign(0, ints(&pillars.cell, device), features, IndexingUpdateOp::Add)
        };
        canvas.reshape([b, nz, nx, ny, c]).permute([0, 1, 4, 2, 3]).reshape([b, nz * c, nx, ny])
    }
}
