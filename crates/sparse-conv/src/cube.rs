//! The sparse convolution as CubeCL kernels, for every cubecl runtime (wgpu/Vulkan, CUDA, ROCm).
//!
//! The same sums as [`crate::cpu`], arranged for a GPU:
//! - forward and feature gradient are one output-stationary kernel over a [`NeighborTable`]: a
//!   unit owns one `(row, channel)` of the result and sums its ≤ K partners in offset order, so
//!   no atomics are needed (the software Vulkan driver has no f32 atomics) and results do not
//!   depend on scheduling;
//! - the weight gradient gives each `(offset, c_in, c_out)` a unit that walks that offset's pairs
//!   (cut into a fixed number of slices whose partial sums are added afterwards), so it too is
//!   deterministic.
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

/// `out[o, c] = Σ_k Σ_r src[table[o, k], r] · w[k, r, c]`, with `w`'s reduction and output
/// strides given so the same kernel runs the forward (`w[k, c_in, c_out]` read as is) and the
/// feature gradient (read transposed). `table` entries `≥ n_src` mean "no partner".
#[cube(launch)]
fn gather_conv_kernel<F: Float>(
    src: &[F],
    weight: &[F],
    table: &[u32],
    out: &mut [F],
    n_src: u32,
    out_rows: usize,
    c_red: usize,
    c_out: usize,
    volume: usize,
    w_red_stride: usize,
    w_out_stride: usize,
) {
    let pos = ABSOLUTE_POS;
    if pos >= out_rows * c_out {
        terminate!();
    }
    let row = pos / c_out;
    let channel = pos % c_out;
    let mut acc = F::new(0.0);
    for k in 0..volume {
        let partner = table[row * volume + k];
        if partner < n_src {
            let src_base = partner as usize * c_red;
            let w_base = k * c_red * c_out + channel * w_out_stride;
            for r in 0..c_red {
                acc += src[src_base + r] * weight[w_base + r * w_red_stride];
            }
        }
    }
    out[pos] = acc;
}

/// `partial[s, k, i, o] = Σ_{p ∈ slice s of offset k} x[input[p], i] · g[output[p], o]`.
#[cube(launch)]
fn weight_grad_kernel<F: Float>(
    x: &[F],
    g: &[F],
    start: &[u32],
    input: &[u32],
    output: &[u32],
    partial: &mut [F],
    c_in: usize,
    c_out: usize,
    volume: usize,
    slices: usize,
) {
    let pos = ABSOLUTE_POS;
    let per_slice = volume * c_in * c_out;
    if pos >= slices * per_slice {
        terminate!();
    }
    let slice = pos / per_slice;
    let rest = pos % per_slice;
    let k = rest / (c_in * c_out);
    let i = (rest / c_out) % c_in;
    let o = rest % c_out;
    let begin = start[k] as usize;
    let len = start[k + 1] as usize - begin;
    let from = begin + len * slice / slices;
    let to = begin + len * (slice + 1) / slices;
    let mut acc = F::new(0.0);
    for p in from..to {
        acc += x[input[p] as usize * c_in + i] * g[output[p] as usize * c_out + o];
    }
    partial[pos] = acc;
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

/// The whole buffer of a contiguous tensor.
fn buffer(t: &CubeTensor) -> BufferArg {
    unsafe { BufferArg::from_raw_parts(t.handle.clone(), t.meta.num_elements()) }
}

fn units(client: &Client, count: usize) -> (CubeCount, CubeDim) {
    let dim = CubeDim::new_1d(CUBE_UNITS);
    (calculate_cube_count_elemwise(client, count, dim), dim)
}

/// Which side of the map the gather runs over.
#[derive(Clone, Copy)]
enum Direction {
    /// Outputs gather inputs through `W`.
    Forward,
    /// Inputs gather output gradients through `Wᵀ`.
    Backward,
}

fn gather_conv(src: CubeTensor, weight: CubeTensor, map: &KernelMap, direction: Direction) -> CubeTensor {
    let (src, weight) = (contiguous(src), contiguous(weight));
    let [_, c_in, c_out] = weight.meta.shape().dims();
    let device_tables = tables(map, &src.device);
    let client = src.client.clone();
    let (table, rows, c_red, c_res, w_red_stride, w_out_stride) = match direction {
        Direction::Forward => (device_tables.out_table.get_or_init(|| upload_table(&client, map.out_table())), map.n_out(), c_in, c_out, c_out, 1),
        Direction::Backward => (device_tables.in_table.get_or_init(|| upload_table(&client, map.in_table())), map.n_in(), c_out, c_in, 1, c_out),
    };
    let n_src = src.meta.shape()[0];
    if rows * c_res == 0 || n_src * c_red == 0 {
        // Nothing to gather (and wgpu cannot bind an empty buffer).
        return zeros(&src, Shape::new([rows, c_res]));
    }
    let out = empty_f32(&src, Shape::new([rows, c_res]));
    let (count, dim) = units(&client, rows * c_res);
    gather_conv_kernel::launch::<f32>(
        &client,
        count,
        dim,
        buffer(&src),
        buffer(&weight),
        unsafe { BufferArg::from_raw_parts(table.clone(), rows * map.volume()) },
        buffer(&out),
        n_src as u32,
        rows,
        c_red,
        c_res,
        map.volume(),
        w_red_stride,
        w_out_stride,
    );
    out
}

/// Forward on a cube device (f32).
pub(crate) fn forward(features: CubeTensor, weight: CubeTensor, map: &KernelMap) -> CubeTensor {
    gather_conv(features, weight, map, Direction::Forward)
}

/// Feature gradient on a cube device (f32).
pub(crate) fn input_grad(grad_out: CubeTensor, weight: CubeTensor, map: &KernelMap) -> CubeTensor {
    gather_conv(grad_out, weight, map, Direction::Backward)
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
    // Enough units to fill a GPU when the weight is small (C=32: 27k per slice), never slices
    // shorter than a few dozen pairs. The slice count depends on the problem only.
    let per_slice = volume * c_in * c_out;
    let slices = (1 << 18).div_ceil(per_slice).clamp(1, (num_pairs / (32 * volume)).max(1));
    let partial = empty_f32(&features, Shape::new([slices, volume, c_in, c_out]));
    let (count, dim) = units(&client, slices * per_slice);
    weight_grad_kernel::launch::<f32>(
        &client,
        count,
        dim,
        buffer(&features),
        buffer(&grad_out),
        unsafe { BufferArg::from_raw_parts(start.clone(), volume + 1) },
        unsafe { BufferArg::from_raw_parts(input.clone(), num_pairs) },
        unsafe { BufferArg::from_raw_parts(output.clone(), num_pairs) },
        buffer(&partial),
        c_in,
        c_out,
        volume,
        slices,
    );
    let summed = if slices == 1 { partial } else { CubeBackend::float_sum_dim(partial, 0) };
    CubeBackend::float_reshape(summed, Shape::new([volume, c_in, c_out]))
}

/// Whether the kernels here handle tensors of this dtype.
pub(crate) fn runs(t: &CubeTensor) -> bool {
    t.dtype() == DType::F32
}
