//! Shared pieces of the op's tests: random sparse grids, tensors from values, and the dense
//! reference computed with Burn's own `conv3d` / `conv_transpose3d` on a zero-filled grid.
#![allow(dead_code)]

use std::collections::{BTreeMap, HashSet};
use std::sync::{Arc, OnceLock, mpsc};
use std::time::Duration;

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use sparse_conv::{Coord, CoordIndex, KernelMap, sparse_conv};
use sparse_conv::burn::tensor::module::{conv_transpose3d, conv3d};
use sparse_conv::burn::tensor::ops::{ConvOptions, ConvTransposeOptions};
use sparse_conv::burn::tensor::{DType, Device, Tensor, TensorData};

pub fn rng(seed: u64) -> ChaCha8Rng {
    ChaCha8Rng::seed_from_u64(seed)
}

/// `n` unique voxels in `batches` samples, multiples of `stride`, spread over `[-extent, extent)`
/// voxels of that level (negative coordinates included).
pub fn random_coords(rng: &mut ChaCha8Rng, n: usize, batches: i32, extent: i32, stride: i32) -> Vec<Coord> {
    let mut seen = HashSet::new();
    let mut out = Vec::new();
    while out.len() < n {
        let c = [
            rng.random_range(0..batches),
            rng.random_range(-extent..extent) * stride,
            rng.random_range(-extent..extent) * stride,
            rng.random_range(-extent..extent) * stride,
        ];
        if seen.insert(c) {
            out.push(c);
        }
    }
    out
}

pub fn random_values(rng: &mut ChaCha8Rng, n: usize) -> Vec<f64> {
    (0..n).map(|_| rng.random_range(-1.0..1.0)).collect()
}

pub fn tensor2(values: &[f64], shape: [usize; 2], device: &Device, dtype: DType) -> Tensor<2> {
    Tensor::from_data(TensorData::new(values.to_vec(), shape), (device, dtype))
}

pub fn tensor3(values: &[f64], shape: [usize; 3], device: &Device, dtype: DType) -> Tensor<3> {
    Tensor::from_data(TensorData::new(values.to_vec(), shape), (device, dtype))
}

pub fn values<const D: usize>(t: Tensor<D>) -> Vec<f64> {
    t.into_data().convert::<f64>().try_to_vec::<f64>().unwrap()
}

pub fn assert_close(actual: &[f64], expected: &[f64], tol: f64, what: &str) {
    assert_eq!(actual.len(), expected.len(), "{what}: length");
    let scale = expected.iter().fold(1.0f64, |m, v| m.max(v.abs()));
    for (i, (a, e)) in actual.iter().zip(expected).enumerate() {
        assert!((a - e).abs() <= tol * scale, "{what}: element {i}: {a} vs {e} (tol {tol}, scale {scale})");
    }
}

/// Which convolution the dense reference computes.
#[derive(Clone, Copy, Debug)]
pub enum DenseKind {
    /// Odd kernel, padding k/2: the submanifold result at active sites.
    Submanifold(usize),
    /// Kernel 2 stride 2 on a grid aligned to even cells.
    Down,
    /// Transposed kernel 2 stride 2, read at the fine voxels.
    Up,
}

/// The dense reference, sample by sample, on a zero-filled grid in units of `stride`.
///
/// `coords` are the input voxels (multiples of `stride`); the result maps each output coordinate
/// (finest-level units) to its features. For `Up`, `outputs` are the fine voxels to read.
#[allow(clippy::too_many_arguments)]
pub fn dense_reference(
    kind: DenseKind,
    coords: &[Coord],
    x: &[f64],
    c_in: usize,
    weight: &[f64],
    c_out: usize,
    stride: i32,
    outputs: &[Coord],
    device: &Device,
) -> BTreeMap<Coord, Vec<f64>> {
    let k = match kind {
        DenseKind::Submanifold(k) => k,
        DenseKind::Down | DenseKind::Up => 2,
    };
    // Burn's conv3d weight is [C_out, C_in, kx, ky, kz]; conv_transpose3d's is [C_in, C_out, ...].
    let w = Tensor::<1>::from_data(TensorData::new(weight.to_vec(), [weight.len()]), (device, DType::F64)).reshape([k, k, k, c_in, c_out]);
    let mut result = BTreeMap::new();
    let batches: Vec<i32> = coords.iter().map(|c| c[0]).collect::<std::collections::BTreeSet<_>>().into_iter().collect();
    for b in batches {
        let rows: Vec<usize> = (0..coords.len()).filter(|&r| coords[r][0] == b).collect();
        let grid: Vec<[i32; 3]> = rows.iter().map(|&r| [coords[r][1] / stride, coords[r][2] / stride, coords[r][3] / stride]).collect();
        // Origin on an even cell so that k2s2 cells line up with floor(c / 2)·2.
        let lo: [i32; 3] = std::array::from_fn(|d| grid.iter().map(|g| g[d]).min().unwrap().div_euclid(2) * 2);
        let hi: [i32; 3] = std::array::from_fn(|d| grid.iter().map(|g| g[d]).max().unwrap());
        let dims: [usize; 3] = std::array::from_fn(|d| ((hi[d] - lo[d] + 2) / 2 * 2) as usize);
        let mut dense = vec![0.0f64; c_in * dims[0] * dims[1] * dims[2]];
        for (j, &r) in rows.iter().enumerate() {
            let g = grid[j];
            let p = [(g[0] - lo[0]) as usize, (g[1] - lo[1]) as usize, (g[2] - lo[2]) as usize];
            for c in 0..c_in {
                dense[((c * dims[0] + p[0]) * dims[1] + p[1]) * dims[2] + p[2]] = x[r * c_in + c];
            }
        }
        let input = Tensor::<1>::from_data(TensorData::new(dense, [c_in * dims[0] * dims[1] * dims[2]]), (device, DType::F64))
            .reshape([1, c_in, dims[0], dims[1], dims[2]]);
        let (out, read): (Tensor<5>, Vec<(Coord, [usize; 3])>) = match kind {
            DenseKind::Submanifold(k) => {
                let pad = k / 2;
                let out = conv3d(input, w.clone().permute([4, 3, 0, 1, 2]), None, ConvOptions::new([1, 1, 1], [pad, pad, pad], [1, 1, 1], 1));
                let read = rows.iter().zip(&grid).map(|(&r, g)| (coords[r], std::array::from_fn(|d| (g[d] - lo[d]) as usize))).collect();
                (out, read)
            }
            DenseKind::Down => {
                let out = conv3d(input, w.clone().permute([4, 3, 0, 1, 2]), None, ConvOptions::new([2, 2, 2], [0, 0, 0], [1, 1, 1], 1));
                let parents: std::collections::BTreeSet<[i32; 3]> = grid.iter().map(|g| g.map(|v| v.div_euclid(2) * 2)).collect();
                let read = parents
                    .into_iter()
                    .map(|p| ([b, p[0] * stride, p[1] * stride, p[2] * stride], std::array::from_fn(|d| ((p[d] - lo[d]) / 2) as usize)))
                    .collect();
                (out, read)
            }
            DenseKind::Up => {
                let out = conv_transpose3d(input, w.clone().permute([3, 4, 0, 1, 2]), None, ConvTransposeOptions::new([2, 2, 2], [0, 0, 0], [0, 0, 0], [1, 1, 1], 1));
                // Fine voxels live at half this level's stride.
                let fine = stride / 2;
                let read = outputs
                    .iter()
                    .filter(|c| c[0] == b)
                    .map(|c| (*c, std::array::from_fn(|d| (c[d + 1] / fine - 2 * lo[d]) as usize)))
                    .collect();
                (out, read)
            }
        };
        let [_, _, ox, oy, oz] = out.dims();
        let out = values(out);
        for (coord, p) in read {
            let f: Vec<f64> = (0..c_out).map(|c| out[((c * ox + p[0]) * oy + p[1]) * oz + p[2]]).collect();
            result.insert(coord, f);
        }
    }
    result
}

/// Rows of `features` (`rows × c`) keyed by their coordinates.
pub fn by_coord(coords: &[Coord], features: &[f64], c: usize) -> BTreeMap<Coord, Vec<f64>> {
    coords.iter().enumerate().map(|(r, &co)| (co, features[r * c..(r + 1) * c].to_vec())).collect()
}

pub fn assert_maps_close(actual: &BTreeMap<Coord, Vec<f64>>, expected: &BTreeMap<Coord, Vec<f64>>, tol: f64, what: &str) {
    assert_eq!(actual.keys().collect::<Vec<_>>(), expected.keys().collect::<Vec<_>>(), "{what}: output coordinates");
    for (c, e) in expected {
        assert_close(&actual[c], e, tol, &format!("{what} at {c:?}"));
    }
}

/// How long the wgpu probe may take (device bring-up and one tiny convolution), and how long a
/// test binary may run once it has a wgpu device, before it fails instead of waiting for ever.
const PROBE_LIMIT: Duration = Duration::from_secs(120);
const BINARY_LIMIT: Duration = Duration::from_secs(25 * 60);

/// The wgpu device, once per test binary, when an adapter on a native API runs the op correctly
/// within [`PROBE_LIMIT`]; `None` otherwise (the test then skips, saying why), unless
/// `PMUNET_REQUIRE_WGPU=1`, which CI sets after installing the software Vulkan driver: then a
/// missing or failing adapter is a test failure. With a device, a watchdog ends the binary
/// with a message if it runs past [`BINARY_LIMIT`].
pub fn wgpu_device() -> Option<Device> {
    static DEVICE: OnceLock<Option<Device>> = OnceLock::new();
    DEVICE.get_or_init(probe_wgpu).clone()
}

fn probe_wgpu() -> Option<Device> {
    let required = std::env::var("PMUNET_REQUIRE_WGPU").is_ok_and(|v| v == "1");
    let skip = |why: String| -> Option<Device> {
        if required {
            panic!("PMUNET_REQUIRE_WGPU=1 but {why}");
        }
        to_terminal(&format!("skipping wgpu: {why} (set PMUNET_REQUIRE_WGPU=1 to make this an error)"));
        None
    };
    let (tx, rx) = mpsc::channel();
    // The probe runs on its own thread: a driver that never answers leaves it blocked, not us.
    std::thread::spawn(move || {
        let attempt = std::panic::catch_unwind(|| -> Result<Device, String> {
            let device = sparse_conv::wgpu_device()?;
            let coords = vec![[0, 0, 0, 0], [0, 1, 0, 0]];
            let index = sparse_conv::CoordIndex::build(&coords).unwrap();
            let map = Arc::new(sparse_conv::KernelMap::submanifold(&coords, &index, 3, 1));
            let x = Tensor::<2>::ones([2, 1], &device);
            let w = Tensor::<3>::ones([27, 1, 1], &device);
            let out = values(sparse_conv(x, w, &map));
            if out != vec![2.0, 2.0] {
                return Err(format!("a 2-voxel convolution gave {out:?} instead of [2.0, 2.0]"));
            }
            Ok(device)
        });
        let _ = tx.send(attempt.unwrap_or_else(|_| Err("the probe panicked".to_string())));
    });
    match rx.recv_timeout(PROBE_LIMIT) {
        Ok(Ok(device)) => {
            std::thread::spawn(|| {
                std::thread::sleep(BINARY_LIMIT);
                to_terminal(&format!(
                    "error: this test binary has run {} minutes with a wgpu device: a driver that stopped answering? \
                     (the wgpu tests finish in a few minutes on lavapipe)",
                    BINARY_LIMIT.as_secs() / 60
                ));
                std::process::exit(101);
            });
            Some(device)
        }
        Ok(Err(why)) => skip(format!("no adapter runs the sparse conv: {why}")),
        Err(_) => skip(format!("the wgpu probe did not finish within {} s", PROBE_LIMIT.as_secs())),
    }
}

/// Writes a line to the terminal even from a passing test: libtest captures `eprintln!` (in
/// threads a test spawns too) and shows it only for failures, which would hide why wgpu was
/// skipped, and the watchdog's message before it exits.
pub fn to_terminal(line: &str) {
    use std::io::Write;
    let _ = writeln!(std::io::stderr(), "{line}");
}

/// A backend the op's correctness tests run on, with the dtype it runs there and the tolerance
/// that dtype allows against an f64 reference.
pub struct Target {
    pub name: &'static str,
    pub device: Device,
    pub dtype: DType,
    pub tol: f64,
}

/// Every backend's own kernels: flex and ndarray in f64, and the CubeCL kernel on wgpu in f32
/// (the precision it runs; sums of ≤ 27·C products of values in [-1, 1]).
pub fn targets() -> Vec<Target> {
    #[allow(deprecated)]
    let mut targets = vec![
        Target { name: "flex", device: Device::flex(), dtype: DType::F64, tol: 1e-12 },
        Target { name: "ndarray", device: Device::ndarray(), dtype: DType::F64, tol: 1e-12 },
        // f32 on the CPU runs the type-specific kernels (AVX-512 weight gradient where present).
        Target { name: "flex f32", device: Device::flex(), dtype: DType::F32, tol: 1e-5 },
    ];
    if let Some(device) = wgpu_device() {
        targets.push(Target { name: "wgpu", device, dtype: DType::F32, tol: 1e-5 });
    }
    targets
}

/// A conv's output and both gradients, for comparing backends.
pub struct ConvOutputs {
    pub out: Vec<f64>,
    pub gx: Vec<f64>,
    pub gw: Vec<f64>,
}

/// `sparse_conv` on `device` in f32 with the loss `Σ out · g`: its output and gradients.
pub fn conv_outputs(map: &Arc<KernelMap>, x: &[f64], w: &[f64], g: &[f64], c: [usize; 2], device: &Device) -> ConvOutputs {
    conv_outputs_in(map, x, w, g, c, device, DType::F32)
}

/// [`conv_outputs`] in `dtype`.
pub fn conv_outputs_in(map: &Arc<KernelMap>, x: &[f64], w: &[f64], g: &[f64], c: [usize; 2], device: &Device, dtype: DType) -> ConvOutputs {
    let ad = device.clone().autodiff();
    let xt = tensor2(x, [map.n_in(), c[0]], &ad, dtype).require_grad();
    let wt = tensor3(w, [map.volume(), c[0], c[1]], &ad, dtype).require_grad();
    let out = sparse_conv(xt.clone(), wt.clone(), map);
    let grads = (out.clone() * tensor2(g, [map.n_out(), c[1]], &ad, dtype)).sum().backward();
    ConvOutputs { out: values(out), gx: values(xt.grad(&grads).unwrap()), gw: values(wt.grad(&grads).unwrap()) }
}

/// The same random cases give the same outputs and gradients on flex, ndarray and wgpu (where an
/// adapter is found): three map kinds, and channel counts that take the GPU kernels through one
/// tile, several column tiles with partial last ones (72 and 136 are 18 and 34 vectors of 4),
/// vectors of 2, and a dense scene whose weight gradient sums several slices.
pub fn backends_agree_on_random_cases() {
    let mut r = rng(21);
    let coords = random_coords(&mut r, 400, 2, 6, 1);
    let index = CoordIndex::build(&coords).unwrap();
    let subm = Arc::new(KernelMap::submanifold(&coords, &index, 3, 1));
    let (down, _) = KernelMap::down(&coords, 2, 1).unwrap();
    let up = Arc::new(down.transposed());
    let down = Arc::new(down);
    #[allow(deprecated)]
    let mut devices = vec![("flex", Device::flex()), ("ndarray", Device::ndarray())];
    if let Some(wgpu) = wgpu_device() {
        devices.push(("wgpu", wgpu));
    }
    eprintln!("comparing flex with: {:?}", devices[1..].iter().map(|(n, _)| *n).collect::<Vec<_>>());
    let dense_coords = random_coords(&mut r, 6000, 1, 12, 1);
    let dense = Arc::new(KernelMap::submanifold(&dense_coords, &CoordIndex::build(&dense_coords).unwrap(), 3, 1));
    // Deferred maps: on a GPU built there (`geometry::device_maps`), on the CPU on first use.
    let deferred = Arc::new(KernelMap::submanifold_deferred(Arc::new(sparse_conv::LevelCoords::on_host(coords.clone().into())), 3, 1));
    let dense_deferred = Arc::new(KernelMap::submanifold_deferred(Arc::new(sparse_conv::LevelCoords::on_host(dense_coords.clone().into())), 3, 1));
    let cases = [("deferred submanifold", &deferred, [8, 16]), ("dense deferred submanifold", &dense_deferred, [72, 136]), ("submanifold", &subm, [8, 16]), ("down", &down, [8, 16]), ("up", &up, [8, 16]), ("submanifold", &subm, [72, 136]), ("up", &up, [136, 72]), ("submanifold", &subm, [6, 10]), ("dense submanifold", &dense, [8, 16]), ("dense submanifold", &dense, [72, 136]), ("dense submanifold", &dense, [136, 72])];
    for (name, map, c) in cases {
        let x = random_values(&mut r, map.n_in() * c[0]);
        let w = random_values(&mut r, map.volume() * c[0] * c[1]);
        let g = random_values(&mut r, map.n_out() * c[1]);
        let reference = conv_outputs(map, &x, &w, &g, c, &devices[0].1);
        for (device_name, device) in &devices[1..] {
            let other = conv_outputs(map, &x, &w, &g, c, device);
            let what = format!("{name} {c:?} on {device_name} vs flex");
            assert_close(&other.out, &reference.out, 1e-5, &format!("{what}: output"));
            assert_close(&other.gx, &reference.gx, 1e-5, &format!("{what}: feature gradient"));
            assert_close(&other.gw, &reference.gw, 1e-5, &format!("{what}: weight gradient"));
        }
    }
}
