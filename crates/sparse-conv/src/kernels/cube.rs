//! The sparse convolution as CubeCL kernels, for every cubecl runtime (wgpu/Vulkan, CUDA, ROCm).
//!
//! The same sums as [`super::cpu`], arranged for a GPU as tiled products through shared memory:
//! - forward and feature gradient are one output-stationary gather over a [`NeighborTable`]. A
//!   cube owns a tile of rows (sorted by the offsets they use, [`RowTiles`]) and of output
//!   channels, stages its rows' partners and each used offset's weight in shared memory, and each
//!   unit sums its rows' partners in offset order. A launch of fewer tiles than
//!   `KernelOptions::gpu_tiled_min_cubes` (default 2048) runs the same sums untiled, one unit per few rows,
//!   without a tile plan. No
//!   atomics (the software Vulkan driver has no f32 atomics), and results do not depend on
//!   scheduling;
//! - the weight gradient gives each (offset, slice of its pairs, channel tile) a cube that stages
//!   the pairs' rows of both sides in shared memory; the slices' partial sums are added
//!   afterwards, in a fixed order, so it too is deterministic.
//!
//! Loads and multiply-adds are vectors of 4 floats where the channel counts allow (2 or 1
//! otherwise).
//!
//! The map's tables go to the device once per map and device and stay with the map
//! ([`KernelMap::attachment`]), so a U-Net's layers sharing one map share one upload; a deferred
//! submanifold map's are built there instead (`crate::geometry::device_maps`), and with device
//! maps every tile plan is made there from the table on the device (`crate::geometry::device_tiles`).
//!
//! f32 runs here; other float types fall back to the composition of Burn primitives.

use std::sync::{Arc, OnceLock};

use burn::backend::TensorMetadata;
use burn::backend::ops::FloatTensorOps;
use burn::tensor::{DType, Shape};
use burn_cubecl::cubecl::prelude::*;
use burn_cubecl::cubecl::client::Client;
use burn_cubecl::cubecl::server::Handle;
use burn_cubecl::cubecl::{self, calculate_cube_count_elemwise};
use burn_cubecl::kernel::into_contiguous;
use burn_cubecl::tensor::CubeTensor;
use burn_cubecl::{CubeBackend, CubeDevice};

use crate::geometry::coords::Coord;
use crate::geometry::device_down::DeviceDown;
use crate::geometry::device_maps::{DeviceMap, DevicePairs};
use crate::geometry::device_tiles::{DeviceRowTiles, MAX_VOLUME as MAX_PLAN_VOLUME};
use crate::geometry::kernel_map::{Deferred, KernelMap, MapKind, NeighborTable};
use crate::geometry::level::LevelCoords;
use crate::geometry::row_tiles::RowTiles;
use crate::profile::{Kernel, in_kernel};

/// Rows of a gather tile.
const TILE_ROWS: usize = 64;

/// Fewest cubes the tiled gather takes on ([`KernelOptions::gpu_tiled_min_cubes`]); a smaller
/// layer runs [`direct_gather_kernel`]. The tiled kernel needs the rows' tile plan ([`RowTiles`],
/// made once per map and side, on the device with device maps), which only a large enough launch
/// repays.
///
/// [`KernelOptions::gpu_tiled_min_cubes`]: crate::KernelOptions::gpu_tiled_min_cubes
fn tiled_min_cubes() -> usize {
    crate::KernelOptions::current().gpu_tiled_min_cubes
}

/// Rows one unit of the direct gather computes.
const DIRECT_UNIT_ROWS: usize = 4;

/// Rows of a tile one unit of the gather accumulates.
const UNIT_ROWS: usize = 4;

/// Most channel vectors a tile spans (output channels of the gather, either side of the weight
/// gradient).
const TILE_VECTORS: usize = 16;

/// Most reduced-channel vectors of the gather staged in shared memory per step.
const STEP_VECTORS: usize = 4;

/// Pairs of the weight gradient staged in shared memory per step.
const STEP_PAIRS: usize = 16;

/// Weight-gradient cubes to aim for (several per multiprocessor of a large GPU).
const WEIGHT_GRAD_CUBES: usize = 2048;

/// `out[o, c] = Σ_k Σ_r src[table[o, k], r] · w[k, r, c]`, with `w` laid out `[K, C_red, C_out]`
/// (the forward's weight as is, the feature gradient's transposed). `table` entries `≥ n_src`
/// mean "no partner".
///
/// A cube owns a tile of `tile_rows` rows (taken in [`RowTiles`] order) by `tile_vectors` vectors
/// of output channels. For each offset the tile's rows use, it stages their partners' features
/// and the offset's weight, `step_vectors` reduced vectors at a time, in shared memory; each unit
/// multiplies its `unit_rows` rows by its vector column from there (each staged weight vector
/// serves all its rows; units of more vectors each ran slower on an H100). Every output element is one
/// unit's sum in offset order: no atomics, the same result on every run, whatever else is in the
/// batch.
// CubeCL kernels index their buffers; they have no slice iterators.
#[allow(clippy::needless_range_loop)]
#[cube(launch_unchecked)]
fn gather_conv_kernel<F: Float, N: Size>(
    src: &[Vector<F, N>],
    weight: &[Vector<F, N>],
    table: &[u32],
    order: &[u32],
    tile_start: &[u32],
    tile_offsets: &[u32],
    out: &mut [Vector<F, N>],
    n_src: u32,
    rows: usize,
    c_red_vectors: usize,
    c_out_vectors: usize,
    volume: usize,
    #[comptime] tile_rows: usize,
    #[comptime] unit_rows: usize,
    #[comptime] tile_vectors: usize,
    #[comptime] step_vectors: usize,
) {
    let tile = CUBE_POS_Y as usize;
    let col = CUBE_POS_X as usize * tile_vectors;
    let unit = UNIT_POS as usize;
    let units = CUBE_DIM as usize;
    let tx = unit % tile_vectors;
    let ty = unit / tile_vectors;
    let zero = Vector::<F, N>::new(F::new(0.0));
    let lanes = zero.vector_size();
    let mut partners = Shared::<[u32]>::new_slice(tile_rows);
    let mut a_tile = Shared::<[Vector<F, N>]>::new_slice(comptime!(tile_rows * step_vectors));
    let mut b_tile = Shared::<[Vector<F, N>]>::new_slice(comptime!(step_vectors * lanes * tile_vectors));
    let mut acc = Array::<Vector<F, N>>::new(unit_rows);
    let mut a = Array::<Vector<F, N>>::new(unit_rows);
    #[unroll]
    for j in 0..unit_rows {
        acc[j] = zero;
    }
    let c_red = c_red_vectors * lanes;
    let first = tile_start[tile] as usize;
    let last = tile_start[tile + 1] as usize;
    for e in first..last {
        let k = tile_offsets[e] as usize;
        // After the last offset's reads of `partners` (its last step's second barrier), before
        // this offset's (the barrier below).
        let mut r = unit;
        while r < tile_rows {
            let t = tile * tile_rows + r;
            let mut partner = n_src;
            if t < rows {
                partner = table[order[t] as usize * volume + k];
            }
            partners[r] = partner;
            r += units;
        }
        sync_cube();
        let w_base = k * c_red * c_out_vectors;
        let mut c0 = 0;
        while c0 < c_red_vectors {
            let mut i = unit;
            while i < tile_rows * step_vectors {
                let partner = partners[i / step_vectors];
                let cv = c0 + i % step_vectors;
                let mut v = zero;
                if partner < n_src && cv < c_red_vectors {
                    v = src[partner as usize * c_red_vectors + cv];
                }
                a_tile[i] = v;
                i += units;
            }
            let mut i = unit;
            while i < step_vectors * lanes * tile_vectors {
                let r = c0 * lanes + i / tile_vectors;
                let c = col + i % tile_vectors;
                let mut v = zero;
                if r < c_red && c < c_out_vectors {
                    v = weight[w_base + r * c_out_vectors + c];
                }
                b_tile[i] = v;
                i += units;
            }
            sync_cube();
            #[unroll]
            for cv in 0..step_vectors {
                #[unroll]
                for j in 0..unit_rows {
                    a[j] = a_tile[(ty * unit_rows + j) * step_vectors + cv];
                }
                #[unroll]
                for lane in 0..lanes {
                    let b = b_tile[(cv * lanes + lane) * tile_vectors + tx];
                    #[unroll]
                    for j in 0..unit_rows {
                        acc[j] += Vector::new(a[j].extract(lane)) * b;
                    }
                }
            }
            c0 += step_vectors;
            sync_cube();
        }
    }
    if col + tx < c_out_vectors {
        #[unroll]
        for j in 0..unit_rows {
            let t = tile * tile_rows + ty * unit_rows + j;
            if t < rows {
                out[order[t] as usize * c_out_vectors + col + tx] = acc[j];
            }
        }
    }
}

/// [`gather_conv_kernel`]'s sums without tiles, for layers too small to fill a GPU with tiles (the
/// U-Net's coarse levels): a unit owns `rows_per_unit` consecutive rows and one channel vector
/// and walks their partners straight from device memory, so the launch has many more units and
/// no barriers. Each output element is the same sum in the same order as in the tiled kernel.
#[cube(launch_unchecked)]
fn direct_gather_kernel<F: Float, N: Size>(
    src: &[Vector<F, N>],
    weight: &[Vector<F, N>],
    table: &[u32],
    out: &mut [Vector<F, N>],
    n_src: u32,
    rows: usize,
    c_red_vectors: usize,
    c_out_vectors: usize,
    volume: usize,
    #[comptime] rows_per_unit: usize,
) {
    let pos = ABSOLUTE_POS;
    let row_blocks = rows.div_ceil(rows_per_unit);
    if pos >= row_blocks * c_out_vectors {
        terminate!();
    }
    let first_row = (pos / c_out_vectors) * rows_per_unit;
    let channel = pos % c_out_vectors;
    let zero = Vector::<F, N>::new(F::new(0.0));
    let lanes = zero.vector_size();
    let mut acc = Array::<Vector<F, N>>::new(rows_per_unit);
    let mut partners = Array::<u32>::new(rows_per_unit);
    let mut weights = Array::<Vector<F, N>>::new(lanes);
    #[unroll]
    for j in 0..rows_per_unit {
        acc[j] = zero;
    }
    let w_offset_stride = c_red_vectors * lanes * c_out_vectors;
    for k in 0..volume {
        let mut any = false;
        #[unroll]
        for j in 0..rows_per_unit {
            let mut partner = n_src;
            if first_row + j < rows {
                partner = table[(first_row + j) * volume + k];
            }
            partners[j] = partner;
            any = any || partner < n_src;
        }
        if any {
            let w_base = k * w_offset_stride + channel;
            for r in 0..c_red_vectors {
                let w_row = w_base + r * lanes * c_out_vectors;
                #[unroll]
                for lane in 0..lanes {
                    weights[lane] = weight[w_row + lane * c_out_vectors];
                }
                #[unroll]
                for j in 0..rows_per_unit {
                    let partner = partners[j];
                    if partner < n_src {
                        let values = src[partner as usize * c_red_vectors + r];
                        #[unroll]
                        for lane in 0..lanes {
                            acc[j] += Vector::new(values.extract(lane)) * weights[lane];
                        }
                    }
                }
            }
        }
    }
    #[unroll]
    for j in 0..rows_per_unit {
        if first_row + j < rows {
            out[(first_row + j) * c_out_vectors + channel] = acc[j];
        }
    }
}

/// `partial[s, k, i, o] = Σ_{p ∈ slice s of offset k} x[input[p], i] · g[output[p], o]`.
///
/// A cube owns one slice of one offset's pairs and a tile of `in_vectors` input-channel vectors
/// by `out_vectors` output-channel vectors; it stages `step_pairs` pairs' rows of both sides in
/// shared memory, and each unit accumulates one input vector's `N` rows of one output vector.
#[cube(launch_unchecked)]
fn weight_grad_kernel<F: Float, N: Size>(
    x: &[Vector<F, N>],
    g: &[Vector<F, N>],
    start: &[u32],
    input: &[u32],
    output: &[u32],
    partial: &mut [Vector<F, N>],
    c_in_vectors: usize,
    c_out_vectors: usize,
    volume: usize,
    slices: usize,
    #[comptime] in_vectors: usize,
    #[comptime] out_vectors: usize,
    #[comptime] step_pairs: usize,
) {
    let o0 = CUBE_POS_X as usize * out_vectors;
    let i0 = CUBE_POS_Y as usize * in_vectors;
    let k = CUBE_POS_Z as usize / slices;
    let slice = CUBE_POS_Z as usize % slices;
    let tx = UNIT_POS as usize % out_vectors;
    let ty = UNIT_POS as usize / out_vectors;
    let begin = start[k] as usize;
    let len = start[k + 1] as usize - begin;
    let from = begin + len * slice / slices;
    let to = begin + len * (slice + 1) / slices;
    let zero = Vector::<F, N>::new(F::new(0.0));
    let lanes = zero.vector_size();
    let mut x_tile = Shared::<[Vector<F, N>]>::new_slice(comptime!(step_pairs * in_vectors));
    let mut g_tile = Shared::<[Vector<F, N>]>::new_slice(comptime!(step_pairs * out_vectors));
    let mut acc = Array::<Vector<F, N>>::new(lanes);
    #[unroll]
    for lane in 0..lanes {
        acc[lane] = zero;
    }
    let mut p0 = from;
    while p0 < to {
        stage_pair_rows::<F, N>(x, input, &mut x_tile, p0, to, i0, c_in_vectors, in_vectors, step_pairs);
        stage_pair_rows::<F, N>(g, output, &mut g_tile, p0, to, o0, c_out_vectors, out_vectors, step_pairs);
        sync_cube();
        #[unroll]
        for q in 0..step_pairs {
            let xs = x_tile[q * in_vectors + ty];
            let gs = g_tile[q * out_vectors + tx];
            #[unroll]
            for lane in 0..lanes {
                acc[lane] += Vector::new(xs.extract(lane)) * gs;
            }
        }
        sync_cube();
        p0 += step_pairs;
    }
    if i0 + ty < c_in_vectors && o0 + tx < c_out_vectors {
        let base = ((slice * volume + k) * c_in_vectors + i0 + ty) * lanes;
        #[unroll]
        for lane in 0..lanes {
            partial[(base + lane) * c_out_vectors + o0 + tx] = acc[lane];
        }
    }
}

/// Stages into `tile` (`pairs × tile_vectors`) the channel vectors `first..first + tile_vectors` of
/// the rows `rows[p0..p0 + pairs]` of `src`, zeros past pair `to` or the row's `row_vectors`.
#[cube]
fn stage_pair_rows<F: Float, N: Size>(
    src: &[Vector<F, N>],
    rows: &[u32],
    tile: &mut Shared<[Vector<F, N>]>,
    p0: usize,
    to: usize,
    first: usize,
    row_vectors: usize,
    #[comptime] tile_vectors: usize,
    #[comptime] pairs: usize,
) {
    let units = CUBE_DIM as usize;
    let mut i = UNIT_POS as usize;
    while i < pairs * tile_vectors {
        let p = p0 + i / tile_vectors;
        let c = first + i % tile_vectors;
        let mut v = Vector::<F, N>::new(F::new(0.0));
        if p < to && c < row_vectors {
            v = src[rows[p] as usize * row_vectors + c];
        }
        tile[i] = v;
        i += units;
    }
}

/// `out[i] = Σ_s partial[s, i]`, slices added in order (the weight gradient's last step, kept out
/// of Burn's autotuned reduction so the op's cost and sums are its own).
#[cube(launch_unchecked)]
fn sum_slices_kernel<F: Float, N: Size>(partial: &[Vector<F, N>], out: &mut [Vector<F, N>], len: usize, slices: usize) {
    let i = ABSOLUTE_POS;
    if i >= len {
        terminate!();
    }
    let mut sum = partial[i];
    for s in 1..slices {
        sum += partial[s * len + i];
    }
    out[i] = sum;
}

/// One Adam step per element (`crate::optim::adam`'s arithmetic): `out = [θ'; m₁'; m₂']`, each `len`,
/// with `amsgrad` also the new running maximum of m₂ (Burn's `max_pair`: `b` where the old
/// maximum is lower).
#[cube(launch_unchecked)]
#[allow(clippy::too_many_arguments)]
fn adam_kernel(
    param: &[f32],
    grad: &[f32],
    moment_1: &[f32],
    moment_2: &[f32],
    max_moment_2: &[f32],
    out: &mut [f32],
    len: usize,
    lr: f32,
    beta_1: f32,
    one_minus_beta_1: f32,
    beta_2: f32,
    one_minus_beta_2: f32,
    weight_decay: f32,
    correction: f32,
    epsilon: f32,
    #[comptime] decay: bool,
    #[comptime] amsgrad: bool,
) {
    let i = ABSOLUTE_POS;
    if i >= len {
        terminate!();
    }
    let p = param[i];
    let mut g = grad[i];
    if decay {
        g += p * weight_decay;
    }
    let a = moment_1[i] * beta_1 + g * one_minus_beta_1;
    let b = moment_2[i] * beta_2 + g * g * one_minus_beta_2;
    let mut v = b;
    if amsgrad {
        let previous = max_moment_2[i];
        if b < previous {
            v = previous;
        }
        out[3 * len + i] = v;
    }
    let step = a * correction / (f32::sqrt(v) + epsilon);
    out[i] = p - step * lr;
    out[len + i] = a;
    out[2 * len + i] = b;
}

/// One side's gather table on a device.
struct GatherTables {
    table: Handle,
    /// The rows' tile plan, made the first time the tiled kernel runs on this side.
    tiles: OnceLock<DeviceRowTiles>,
}

impl GatherTables {
    fn upload(client: &Client, table: &NeighborTable) -> Self {
        Self { table: in_kernel(Kernel::Upload, || upload(client, table.as_slice())), tiles: OnceLock::new() }
    }

    fn on_device(table: &Handle) -> Self {
        Self { table: table.clone(), tiles: OnceLock::new() }
    }
}

/// A map's tables on one device, each uploaded the first time a kernel needs it.
struct DeviceTables {
    device: CubeDevice,
    /// The forward's gather (rows: outputs) and the feature gradient's (rows: inputs).
    forward: OnceLock<GatherTables>,
    backward: OnceLock<GatherTables>,
    /// `start`, `input`, `output` of [`crate::geometry::kernel_map::OffsetPairs`].
    pairs: OnceLock<[Handle; 3]>,
    /// A deferred map's tables and pairs, built on the device.
    built: OnceLock<DeviceMap>,
    built_pairs: OnceLock<DevicePairs>,
}

impl DeviceTables {
    fn new(device: &CubeDevice, built: Option<DeviceMap>) -> Self {
        Self {
            device: device.clone(),
            forward: OnceLock::new(),
            backward: OnceLock::new(),
            pairs: OnceLock::new(),
            built: built.map(OnceLock::from).unwrap_or_default(),
            built_pairs: OnceLock::new(),
        }
    }

    /// A deferred map's tables on the device: a submanifold map's built here from its level's
    /// coordinates the first time, a down-sampling map's made with it (on this device, or none:
    /// the host's are uploaded), a transposed one's its down-sampling map's swapped.
    fn built(&self, map: &KernelMap, client: &Client) -> Option<&DeviceMap> {
        if let Some(built) = self.built.get() {
            return Some(built);
        }
        let made = match (map.deferred()?, map.kind()) {
            (Deferred::Submanifold { level, stride }, MapKind::Submanifold { kernel }) => {
                let coords = device_coords(level, &self.device, client);
                in_kernel(Kernel::MapBuild, || DeviceMap::submanifold(client, &coords.handle, level.len(), kernel, *stride))
            }
            (Deferred::Up { down }, _) => tables(down, &self.device).built(down, client)?.transposed(map.n_out()),
            _ => return None,
        };
        Some(self.built.get_or_init(|| made))
    }

    /// The forward's (`backward` false) or the feature gradient's gather table.
    fn gather(&self, map: &KernelMap, client: &Client, backward: bool) -> &GatherTables {
        let side = if backward { &self.backward } else { &self.forward };
        side.get_or_init(|| match self.built(map, client) {
            Some(built) => GatherTables::on_device(if backward { &built.backward } else { &built.forward }),
            None => GatherTables::upload(client, if backward { map.in_table() } else { map.out_table() }),
        })
    }
}

fn tables(map: &KernelMap, device: &CubeDevice) -> Arc<DeviceTables> {
    map.attachment(|t: &DeviceTables| &t.device == device, || DeviceTables::new(device, None))
}

/// A level's coordinates on one device, `[len, 4]` `i32`.
struct DeviceCoords {
    device: CubeDevice,
    handle: Handle,
}

/// `level`'s coordinates on `device`: where it was made there, or uploaded once.
fn device_coords(level: &LevelCoords, device: &CubeDevice, client: &Client) -> Arc<DeviceCoords> {
    level.attachment(
        |c: &DeviceCoords| &c.device == device,
        || {
            let flat: Vec<i32> = level.host().iter().flatten().copied().collect();
            DeviceCoords { device: device.clone(), handle: in_kernel(Kernel::Upload, || upload(client, &flat)) }
        },
    )
}

/// The down-sampling map of `kernel` from `level` (tensor `stride`) and the coarse level, made on
/// `device` if it is a CubeCL one; the coarse coordinates stay there until the host reads them.
/// `coarse`: the coarse level's voxel count if the host counted it (read back otherwise).
pub(crate) fn down_on_device(device: &burn::tensor::Device, level: &Arc<LevelCoords>, kernel: usize, stride: i32, coarse: Option<usize>) -> Option<(KernelMap, Arc<LevelCoords>)> {
    let inner = device.clone().inner();
    let burn::backend::DispatchDevice::Cube(device) = inner.as_dispatch() else { return None };
    let device = device.clone();
    if level.is_empty() {
        return None;
    }
    let client = device.client();
    let coords = device_coords(level, &device, &client);
    let down = in_kernel(Kernel::MapBuild, || DeviceDown::build(&client, &coords.handle, level.len(), kernel, stride, coarse));
    let coarse_handle = down.coarse_coords.clone();
    let coarse = down.coarse;
    let read_back = {
        let (client, handle) = (client.clone(), coarse_handle.clone());
        move || -> Vec<Coord> {
            crate::profile::count_read_back();
            let bytes = client.read_one(handle.clone()).expect("reading a level's coordinates back");
            i32::from_bytes(&bytes)[..4 * coarse].chunks_exact(4).map(|c| [c[0], c[1], c[2], c[3]]).collect()
        }
    };
    let coarse_level = LevelCoords::on_device(coarse, Arc::new(DeviceCoords { device: device.clone(), handle: coarse_handle }), read_back);
    let map = KernelMap::down_deferred(level.clone(), kernel, stride, coarse, Arc::new(DeviceTables::new(&device, Some(down.map))));
    Some((map, Arc::new(coarse_level)))
}

/// `values` on the device; one zero for none (wgpu cannot bind an empty buffer).
pub(crate) fn upload<E: CubeElement + Default>(client: &Client, values: &[E]) -> Handle {
    let zero = [E::default()];
    client.create_from_slice(E::as_bytes(if values.is_empty() { &zero } else { values }))
}

/// The host's tile plan of `table`, uploaded.
fn upload_tiles(client: &Client, table: &NeighborTable, n_src: usize) -> DeviceRowTiles {
    let tiles = in_kernel(Kernel::TilePlan, || RowTiles::new(table, n_src, TILE_ROWS));
    in_kernel(Kernel::Upload, || DeviceRowTiles {
        order: upload(client, &tiles.order),
        start: upload(client, &tiles.start),
        offsets: upload(client, &tiles.offsets),
        tiles: tiles.tiles(),
        // An empty list is uploaded as one unused entry.
        offsets_capacity: tiles.offsets.len().max(1),
    })
}

fn empty_f32(like: &CubeTensor, shape: Shape) -> CubeTensor {
    let handle = like.client.empty(shape.num_elements() * size_of::<f32>());
    CubeTensor::new_contiguous(like.client.clone(), like.device.clone(), shape, handle, DType::F32)
}

fn zeros(like: &CubeTensor, shape: Shape) -> CubeTensor {
    CubeBackend::float_zeros(shape, &like.device, burn::tensor::FloatDType::F32)
}

fn contiguous(t: CubeTensor) -> CubeTensor {
    if t.is_contiguous() { t } else { into_contiguous(t) }
}

/// The widest of 4, 2 or 1 that divides every count: the vector width for channel counts.
fn widest_block(counts: &[usize]) -> usize {
    [4, 2, 1].into_iter().find(|v| counts.iter().all(|c| c % v == 0)).unwrap_or(1)
}

/// The vectors a tile spans across `vectors` channel vectors: a power of two up to
/// [`TILE_VECTORS`], so narrow layers do not idle most of a cube.
fn tile_vectors(vectors: usize) -> usize {
    vectors.next_power_of_two().clamp(1, TILE_VECTORS)
}

/// The whole buffer of a contiguous tensor, as vectors of `vector` floats.
fn vectors(t: &CubeTensor, vector: usize) -> BufferArg {
    unsafe { BufferArg::from_raw_parts(t.handle.clone(), t.meta.num_elements() / vector) }
}

/// `out[o] = Σ_k src[table[o, k]] · w_k` for `w` laid out `[K, C_red, C_out]`, over the rows of
/// the map's forward table (`backward`: its feature gradient's), whose device copy is `gather`.
fn gather_conv(src: CubeTensor, weight: CubeTensor, gather: &GatherTables, map: &KernelMap, backward: bool) -> CubeTensor {
    let [_, c_red, c_out] = weight.meta.shape().dims();
    let (n_src, volume) = (src.meta.shape()[0], map.volume());
    let rows = if backward { map.n_in() } else { map.n_out() };
    if rows * c_out == 0 || n_src * c_red == 0 {
        // Nothing to gather (and wgpu cannot bind an empty buffer).
        return zeros(&src, Shape::new([rows, c_out]));
    }
    let vector = widest_block(&[c_red, c_out]);
    let out = empty_f32(&src, Shape::new([rows, c_out]));
    let client = src.client.clone();
    let tile_vectors = tile_vectors(c_out / vector);
    let col_tiles = (c_out / vector).div_ceil(tile_vectors);
    let tiles = rows.div_ceil(TILE_ROWS);
    // Tiles are the launch's second dimension, which a device limits to 65,535 cubes.
    if tiles * col_tiles < tiled_min_cubes() || tiles > u16::MAX as usize {
        let dim = CubeDim::new_1d(256);
        let count = calculate_cube_count_elemwise(&client, rows.div_ceil(DIRECT_UNIT_ROWS) * c_out / vector, dim);
        // Safety: rows and channels are bounded by the guard on the unit's position, partners by
        // `partner < n_src`, weights by the shapes checked by the callers.
        in_kernel(Kernel::GpuDispatch, || unsafe {
            direct_gather_kernel::launch_unchecked::<f32>(
                &client,
                count,
                dim,
                vector,
                vectors(&src, vector),
                vectors(&weight, vector),
                BufferArg::from_raw_parts(gather.table.clone(), rows * volume),
                vectors(&out, vector),
                n_src as u32,
                rows,
                c_red / vector,
                c_out / vector,
                volume,
                DIRECT_UNIT_ROWS,
            );
        });
        return out;
    }
    // With device maps the plan is made on the device from the table there; otherwise (or for
    // kernels of more offsets than a mask holds) on the host, from the host table.
    let plan = gather.tiles.get_or_init(|| {
        if volume <= MAX_PLAN_VOLUME && crate::KernelOptions::current().gpu_maps == crate::GpuMaps::Device {
            in_kernel(Kernel::TilePlan, || DeviceRowTiles::build(&client, &gather.table, rows, volume, n_src, TILE_ROWS))
        } else {
            let table = in_kernel(Kernel::MapBuild, || if backward { map.in_table() } else { map.out_table() });
            upload_tiles(&client, table, n_src)
        }
    });
    let step_vectors = (c_red / vector).next_power_of_two().min(STEP_VECTORS);
    let count = CubeCount::Static(col_tiles as u32, plan.tiles as u32, 1);
    let dim = CubeDim::new_1d((tile_vectors * TILE_ROWS / UNIT_ROWS) as u32);
    // Safety: every index the kernel forms is in bounds: rows by `t < rows`, channels by the
    // column and reduced-vector guards, partners by `partner < n_src`, the tile plan by its
    // construction from this table.
    in_kernel(Kernel::GpuDispatch, || unsafe {
        gather_conv_kernel::launch_unchecked::<f32>(
            &client,
            count,
            dim,
            vector,
            vectors(&src, vector),
            vectors(&weight, vector),
            BufferArg::from_raw_parts(gather.table.clone(), rows * volume),
            BufferArg::from_raw_parts(plan.order.clone(), rows),
            BufferArg::from_raw_parts(plan.start.clone(), plan.tiles + 1),
            BufferArg::from_raw_parts(plan.offsets.clone(), plan.offsets_capacity),
            vectors(&out, vector),
            n_src as u32,
            rows,
            c_red / vector,
            c_out / vector,
            volume,
            TILE_ROWS,
            UNIT_ROWS,
            tile_vectors,
            step_vectors,
        );
    });
    out
}

/// Forward on a cube device (f32).
pub(crate) fn forward(features: CubeTensor, weight: CubeTensor, map: &KernelMap) -> CubeTensor {
    let (features, weight) = (contiguous(features), contiguous(weight));
    let tables = tables(map, &features.device);
    let gather = tables.gather(map, &features.client, false);
    gather_conv(features, weight, gather, map, false)
}

/// Feature gradient on a cube device (f32): the forward's gather over the transposed map, with
/// `W_kᵀ`.
pub(crate) fn input_grad(grad_out: CubeTensor, weight: CubeTensor, map: &KernelMap) -> CubeTensor {
    let grad_out = contiguous(grad_out);
    let weight_t = into_contiguous(CubeBackend::float_swap_dims(weight, 1, 2));
    let tables = tables(map, &grad_out.device);
    let gather = tables.gather(map, &grad_out.client, true);
    gather_conv(grad_out, weight_t, gather, map, true)
}

/// `out = Σ_s partial[s]` for a contiguous `partial` of `slices` blocks of `out`'s size.
fn sum_slices(partial: &CubeTensor, out: &CubeTensor, slices: usize, vector: usize) {
    let len = out.meta.num_elements() / vector;
    let dim = CubeDim::new_1d(256);
    let count = CubeCount::Static(len.div_ceil(256) as u32, 1, 1);
    // Safety: the kernel reads `slices · len` and writes `len` vectors, the buffers' sizes.
    in_kernel(Kernel::GpuDispatch, || unsafe {
        sum_slices_kernel::launch_unchecked::<f32>(&partial.client, count, dim, vector, vectors(partial, vector), vectors(out, vector), len, slices);
    });
}

/// Weight gradient on a cube device (f32), `[K, C_in, C_out]`.
pub(crate) fn weight_grad(features: CubeTensor, grad_out: CubeTensor, map: &KernelMap) -> CubeTensor {
    let (features, grad_out) = (contiguous(features), contiguous(grad_out));
    let (c_in, c_out, volume) = (features.meta.shape()[1], grad_out.meta.shape()[1], map.volume());
    let client = features.client.clone();
    let device_tables = tables(map, &features.device);
    // A deferred map's pairs are built on the device, their count unknown to the host: the
    // buffers have room for every (row, offset) and the kernel reads each offset's range there.
    let (num_pairs, [start, input, output]) = match device_tables.built(map, &client) {
        Some(built) => {
            let pairs = device_tables.built_pairs.get_or_init(|| in_kernel(Kernel::MapBuild, || built.pairs(&client)));
            (pairs.capacity, [&pairs.start, &pairs.input, &pairs.output])
        }
        None => {
            // The pairs grouped by offset are made from the table on first use: map work.
            let num_pairs = in_kernel(Kernel::MapBuild, || map.pairs().input.len());
            let [start, input, output] = device_tables.pairs.get_or_init(|| {
                let pairs = map.pairs();
                let start: Vec<u32> = pairs.start.iter().map(|&s| s as u32).collect();
                in_kernel(Kernel::Upload, || [upload(&client, &start), upload(&client, &pairs.input), upload(&client, &pairs.output)])
            });
            (num_pairs, [start, input, output])
        }
    };
    if num_pairs * c_in * c_out == 0 || map.n_in() * map.n_out() == 0 {
        return zeros(&features, Shape::new([volume, c_in, c_out]));
    }
    let vector = widest_block(&[c_in, c_out]);
    let (in_vectors, out_vectors) = (tile_vectors(c_in / vector), tile_vectors(c_out / vector));
    let (in_tiles, out_tiles) = ((c_in / vector).div_ceil(in_vectors), (c_out / vector).div_ceil(out_vectors));
    // Enough cubes to fill a large GPU, never slices shorter than a few steps. The slice count
    // depends on the problem only, so the sums' order does too.
    let cubes_per_slice = volume * in_tiles * out_tiles;
    let slices = WEIGHT_GRAD_CUBES.div_ceil(cubes_per_slice).clamp(1, (num_pairs / (4 * STEP_PAIRS * volume)).max(1));
    let partial = empty_f32(&features, Shape::new([slices, volume, c_in, c_out]));
    let count = CubeCount::Static(out_tiles as u32, in_tiles as u32, (volume * slices) as u32);
    let dim = CubeDim::new_1d((in_vectors * out_vectors) as u32);
    // Safety: pair rows are rows of `features` and `grad_out`; channels are guarded; every
    // element of `partial` is written by the cube of its slice, offset and tile.
    in_kernel(Kernel::GpuDispatch, || unsafe {
        weight_grad_kernel::launch_unchecked::<f32>(
            &client,
            count,
            dim,
            vector,
            vectors(&features, vector),
            vectors(&grad_out, vector),
            BufferArg::from_raw_parts(start.clone(), volume + 1),
            BufferArg::from_raw_parts(input.clone(), num_pairs),
            BufferArg::from_raw_parts(output.clone(), num_pairs),
            vectors(&partial, vector),
            c_in / vector,
            c_out / vector,
            volume,
            slices,
            in_vectors,
            out_vectors,
            STEP_PAIRS,
        );
    });
    let shape = Shape::new([volume, c_in, c_out]);
    if slices == 1 {
        return CubeBackend::float_reshape(partial, shape);
    }
    let summed = empty_f32(&features, shape);
    sum_slices(&partial, &summed, slices, vector);
    summed
}

/// Whether `device` (with or without autodiff) is a CubeCL device, where the kernels here run and
/// submanifold maps are built on the device.
pub(crate) fn is_cube_device(device: &burn::tensor::Device) -> bool {
    matches!(device.clone().inner().as_dispatch(), burn::backend::DispatchDevice::Cube(_))
}

/// Whether the kernels here handle tensors of this dtype.
pub(crate) fn runs(t: &CubeTensor) -> bool {
    t.dtype() == DType::F32
}

/// One Adam step of a flat f32 parameter on a cube device, `[3, n]` (see `crate::optim::adam`).
pub(crate) fn adam_step(param: CubeTensor, grad: CubeTensor, moment_1: CubeTensor, moment_2: CubeTensor, max_moment_2: Option<CubeTensor>, s: crate::kernels::cpu::adam::AdamScalars<f32>) -> CubeTensor {
    let amsgrad = max_moment_2.is_some();
    // Without AMSGrad the kernel never reads the maximum; m₂ stands in for the binding.
    let max_moment_2 = max_moment_2.unwrap_or_else(|| moment_2.clone());
    let [param, grad, moment_1, moment_2, max_moment_2] = [param, grad, moment_1, moment_2, max_moment_2].map(contiguous);
    let len = param.meta.num_elements();
    let out = empty_f32(&param, Shape::new([3 + amsgrad as usize, len]));
    if len == 0 {
        return out;
    }
    let dim = CubeDim::new_1d(256);
    let count = CubeCount::Static(len.div_ceil(256) as u32, 1, 1);
    let buffer = |t: &CubeTensor| vectors(t, 1);
    // Safety: the kernel reads `len` elements of each input and writes `3 · len` (AMSGrad:
    // `4 · len`) of `out`, the buffers' sizes.
    in_kernel(Kernel::GpuDispatch, || unsafe {
        adam_kernel::launch_unchecked(
            &param.client,
            count,
            dim,
            buffer(&param),
            buffer(&grad),
            buffer(&moment_1),
            buffer(&moment_2),
            buffer(&max_moment_2),
            buffer(&out),
            len,
            s.lr,
            s.beta_1,
            1.0 - s.beta_1,
            s.beta_2,
            1.0 - s.beta_2,
            s.weight_decay,
            s.correction,
            s.epsilon,
            s.weight_decay != 0.0,
            amsgrad,
        );
    });
    out
}
