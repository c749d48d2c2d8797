//! The sparse convolution as CubeCL kernels, for every cubecl runtime (wgpu/Vulkan, CUDA, ROCm).
//!
//! The same sums as [`crate::cpu`], arranged for a GPU:
//! - forward and feature gradient are one output-stationary kernel over a [`NeighborTable`]: a
//!   unit owns a vector of channels of 4 rows and sums each row's ≤ K partners in offset order, so no
//!   atomics are needed (the software Vulkan driver has no f32 atomics) and results do not depend
//!   on scheduling;
//! - the weight gradient gives each block of `(offset, c_in, c_out)` (up to 4 × 16) a unit that walks that
//!   offset's pairs (cut into a fixed number of slices whose partial sums are added afterwards),
//!   so it too is deterministic.
//!
//! Loads and multiply-adds are vectors of 4 floats where the channel counts allow (2 or 1
//! otherwise).
//!
//! The map's tables go to the device once per map and device and stay with the map
//! ([`KernelMap::attachment`]), so a U-Net's layers sharing one map share one upload.
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

use crate::kernel_map::{KernelMap, NeighborTable};

/// Units per cube of every launch here.
const CUBE_UNITS: u32 = 256;

/// Output rows one unit of the gather kernel computes.
const ROWS_PER_UNIT: usize = 4;

/// `out[o, c] = Σ_k Σ_r src[table[o, k], r] · w[k, r, c]`, with `w` laid out `[K, C_red, C_out]`
/// (the forward's weight as is, the feature gradient's transposed). `table` entries `≥ n_src`
/// mean "no partner". A unit owns `ROWS` consecutive rows and `N` consecutive channels: each
/// weight vector it loads serves all its rows, each source vector `N` weight vectors.
#[cube(launch_unchecked)]
fn gather_conv_kernel<F: Float, N: Size>(
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

/// `partial[s, k, i, o] = Σ_{p ∈ slice s of offset k} x[input[p], i] · g[output[p], o]`. A unit
/// owns an `N × (OUT·N)` block (`N` input channels by `OUT` vectors of output channels), so each
/// pair's two row indices and input vector serve `OUT·N²` multiply-adds.
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
    #[comptime] out_per_unit: usize,
) {
    let pos = ABSOLUTE_POS;
    let out_blocks = c_out_vectors / out_per_unit;
    if pos >= slices * volume * c_in_vectors * out_blocks {
        terminate!();
    }
    let o = (pos % out_blocks) * out_per_unit;
    let rest = pos / out_blocks;
    let i = rest % c_in_vectors;
    let rest = rest / c_in_vectors;
    let k = rest % volume;
    let slice = rest / volume;
    let begin = start[k] as usize;
    let len = start[k + 1] as usize - begin;
    let from = begin + len * slice / slices;
    let to = begin + len * (slice + 1) / slices;
    let zero = Vector::<F, N>::new(F::new(0.0));
    let lanes = zero.vector_size();
    let acc_len = comptime!(lanes * out_per_unit);
    let mut acc = Array::<Vector<F, N>>::new(acc_len);
    #[unroll]
    for a in 0..acc_len {
        acc[a] = zero;
    }
    for p in from..to {
        let xs = x[input[p] as usize * c_in_vectors + i];
        let g_row = output[p] as usize * c_out_vectors + o;
        #[unroll]
        for q in 0..out_per_unit {
            let gs = g[g_row + q];
            #[unroll]
            for lane in 0..lanes {
                acc[lane * out_per_unit + q] += Vector::new(xs.extract(lane)) * gs;
            }
        }
    }
    let base = ((slice * volume + k) * c_in_vectors + i) * lanes;
    #[unroll]
    for lane in 0..lanes {
        #[unroll]
        for q in 0..out_per_unit {
            partial[(base + lane) * c_out_vectors + o + q] = acc[lane * out_per_unit + q];
        }
    }
}

/// A map's tables on one device, each uploaded the first time a kernel needs it.
struct DeviceTables {
    device: CubeDevice,
    out_table: OnceLock<Handle>,
    in_table: OnceLock<Handle>,
    /// `start`, `input`, `output` of [`crate::kernel_map::OffsetPairs`].
    pairs: OnceLock<[Handle; 3]>,
}

fn tables(map: &KernelMap, device: &CubeDevice) -> Arc<DeviceTables> {
    map.attachment(
        |t: &DeviceTables| &t.device == device,
        || DeviceTables { device: device.clone(), out_table: OnceLock::new(), in_table: OnceLock::new(), pairs: OnceLock::new() },
    )
}

fn upload_u32(client: &Client, values: &[u32]) -> Handle {
    client.create_from_slice(u32::as_bytes(values))
}

fn upload_table(client: &Client, table: &NeighborTable) -> Handle {
    upload_u32(client, table.as_slice())
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

fn units(client: &Client, count: usize) -> (CubeCount, CubeDim) {
    let dim = CubeDim::new_1d(CUBE_UNITS);
    (calculate_cube_count_elemwise(client, count, dim), dim)
}

/// The widest of 4, 2 or 1 that divides every count: the vector width for channel counts, and the
/// output vectors a weight-gradient unit takes on.
fn widest_block(counts: &[usize]) -> usize {
    [4, 2, 1].into_iter().find(|v| counts.iter().all(|c| c % v == 0)).unwrap_or(1)
}

/// The whole buffer of a contiguous tensor, as vectors of `vector` floats.
fn vectors(t: &CubeTensor, vector: usize) -> BufferArg {
    unsafe { BufferArg::from_raw_parts(t.handle.clone(), t.meta.num_elements() / vector) }
}

/// `out[o] = Σ_k src[table[o, k]] · w_k` for `w` laid out `[K, C_red, C_out]`.
fn gather_conv(src: CubeTensor, weight: CubeTensor, table: &Handle, rows: usize, volume: usize) -> CubeTensor {
    let [_, c_red, c_out] = weight.meta.shape().dims();
    let n_src = src.meta.shape()[0];
    if rows * c_out == 0 || n_src * c_red == 0 {
        // Nothing to gather (and wgpu cannot bind an empty buffer).
        return zeros(&src, Shape::new([rows, c_out]));
    }
    let vector = widest_block(&[c_red, c_out]);
    let out = empty_f32(&src, Shape::new([rows, c_out]));
    let client = src.client.clone();
    let (count, dim) = units(&client, rows.div_ceil(ROWS_PER_UNIT) * c_out / vector);
    // Safety: every index the kernel forms is in bounds: rows and channels by the guard on
    // `pos`, partners by `partner < n_src`, weights by the shapes checked by the callers.
    unsafe {
        gather_conv_kernel::launch_unchecked::<f32>(
            &client,
            count,
            dim,
            vector,
            vectors(&src, vector),
            vectors(&weight, vector),
            BufferArg::from_raw_parts(table.clone(), rows * volume),
            vectors(&out, vector),
            n_src as u32,
            rows,
            c_red / vector,
            c_out / vector,
            volume,
            ROWS_PER_UNIT,
        );
    }
    out
}

/// Forward on a cube device (f32).
pub(crate) fn forward(features: CubeTensor, weight: CubeTensor, map: &KernelMap) -> CubeTensor {
    let (features, weight) = (contiguous(features), contiguous(weight));
    let tables = tables(map, &features.device);
    let table = tables.out_table.get_or_init(|| upload_table(&features.client, map.out_table()));
    gather_conv(features, weight, table, map.n_out(), map.volume())
}

/// Feature gradient on a cube device (f32): the forward's gather over the transposed map, with
/// `W_kᵀ`.
pub(crate) fn input_grad(grad_out: CubeTensor, weight: CubeTensor, map: &KernelMap) -> CubeTensor {
    let grad_out = contiguous(grad_out);
    let weight_t = into_contiguous(CubeBackend::float_swap_dims(weight, 1, 2));
    let tables = tables(map, &grad_out.device);
    let table = tables.in_table.get_or_init(|| upload_table(&grad_out.client, map.in_table()));
    gather_conv(grad_out, weight_t, table, map.n_in(), map.volume())
}

/// Weight gradient on a cube device (f32), `[K, C_in, C_out]`.
pub(crate) fn weight_grad(features: CubeTensor, grad_out: CubeTensor, map: &KernelMap) -> CubeTensor {
    let (features, grad_out) = (contiguous(features), contiguous(grad_out));
    let (c_in, c_out, volume) = (features.meta.shape()[1], grad_out.meta.shape()[1], map.volume());
    let num_pairs = map.pairs().input.len();
    if num_pairs * c_in * c_out == 0 {
        return zeros(&features, Shape::new([volume, c_in, c_out]));
    }
    let client = features.client.clone();
    let device_tables = tables(map, &features.device);
    let [start, input, output] = device_tables.pairs.get_or_init(|| {
        let pairs = map.pairs();
        let start: Vec<u32> = pairs.start.iter().map(|&s| s as u32).collect();
        [upload_u32(&client, &start), upload_u32(&client, &pairs.input), upload_u32(&client, &pairs.output)]
    });
    let vector = widest_block(&[c_in, c_out]);
    let out_per_unit = widest_block(&[c_out / vector]);
    // Enough units to fill a GPU (2^16), never slices shorter than a few dozen pairs. The slice
    // count depends on the problem only, so the sums' order does too.
    let units_per_slice = volume * c_in * c_out / (vector * vector * out_per_unit);
    let slices = (1usize << 16).div_ceil(units_per_slice).clamp(1, (num_pairs / (32 * volume)).max(1));
    let partial = empty_f32(&features, Shape::new([slices, volume, c_in, c_out]));
    let (count, dim) = units(&client, slices * units_per_slice);
    // Safety: units past the last block return; pair rows are rows of `features` and `grad_out`.
    unsafe {
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
            out_per_unit,
        );
    }
    let summed = if slices == 1 { partial } else { CubeBackend::float_sum_dim(partial, 0) };
    CubeBackend::float_reshape(summed, Shape::new([volume, c_in, c_out]))
}

/// Whether the kernels here handle tensors of this dtype.
pub(crate) fn runs(t: &CubeTensor) -> bool {
    t.dtype() == DType::F32
}
