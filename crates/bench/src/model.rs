//! What the `model-bench` binary measures: an inference forward pass and one training step
//! (forward, loss, backward, Adam) of either detector on a voxel scene, medians after a warm-up,
//! and the peak resident memory (Linux `VmHWM`).


use std::cell::Cell;
use std::time::Instant;

use data_jrdb::Batch;
use serde::Serialize;
use sparse_conv::burn::module::Module;
use sparse_conv::FusedAdamConfig;
use sparse_conv::burn::optim::GradientsParams;
use sparse_conv::burn::tensor::Device;
use sparse_conv::Coord;
use crate::scene;

use model::{Detector, ModelConfig};

/// A batch of the voxels `coords` (batch column = sample): features and centres are the voxel
/// centres, `(c + ½)·voxel_size` (the scene files hold floor-voxelized coordinates); no boxes.
pub fn scene_batch(coords: &[Coord], voxel_size: [f32; 3]) -> Batch {
    let mut rows: Vec<Coord> = coords.to_vec();
    rows.sort_by_key(|c| c[0]);
    let samples = rows.last().map_or(0, |c| c[0] as usize + 1);
    let mut b = Batch { voxel_size, offsets: vec![0], ..Default::default() };
    for s in 0..samples {
        for c in rows.iter().filter(|c| c[0] as usize == s) {
            b.coords.push(*c);
            let centre = [0, 1, 2].map(|k| (c[k + 1] as f32 + 0.5) * voxel_size[k]);
            b.features.extend_from_slice(&centre);
            b.centres.extend_from_slice(&centre);
        }
        b.offsets.push(b.coords.len());
        b.boxes.push(Vec::new());
        b.num_points.push(Vec::new());
        b.frames.push(("bench".into(), format!("{s:06}")));
    }
    b
}

/// The standard scene tiled `batch` times, or the built-in synthetic one when `coords` is `None`.
pub fn bench_batch(coords: Option<Vec<Coord>>, batch: usize) -> Batch {
    let coords = coords.unwrap_or_else(|| scene::synthetic_lidar_scene(20240601));
    scene_batch(&scene::tile_as_batch(&coords, batch), scene::VOXEL_SIZE.map(|v| v as f32))
}

/// Figures of one benchmark run.
#[derive(Debug, Clone, Serialize)]
pub struct BenchReport {
    /// `person_minkunet` or `centerpoint`.
    pub model: String,
    /// Backend name.
    pub backend: String,
    /// rayon threads.
    pub threads: usize,
    /// The CPU's SIMD features (`sparse_conv::cpu_features`).
    pub cpu_features: String,
    /// The path the op's f32 CPU kernels took (`sparse_conv::cpu_kernel_path`).
    pub cpu_kernels: String,
    /// Samples in the batch.
    pub batch: usize,
    /// Voxels in the batch.
    pub voxels: usize,
    /// Trainable parameters.
    pub parameters: usize,
    /// Median inference forward pass, head output read back, ms.
    pub forward_ms: Option<f64>,
    /// Median detection (forward, decoding and NMS), ms.
    pub detect_ms: Option<f64>,
    /// Median training step (forward, loss, backward, Adam), ms.
    pub train_step_ms: Option<f64>,
    /// Mean inference forward over the same runs, ms: the whole the kernel times (means too) are
    /// a part of, whatever outliers the runs had.
    pub forward_mean_ms: Option<f64>,
    /// Mean training step over the same runs, ms (as `forward_mean_ms`).
    pub train_step_mean_ms: Option<f64>,
    /// Peak RSS after the inference runs (forward's peak), MiB.
    pub peak_forward_mib: Option<f64>,
    /// Peak RSS after the training steps (the process's peak), MiB.
    pub peak_train_mib: Option<f64>,
    /// Mean time per inference forward inside the CPU kernels, by kind (zero on GPUs).
    pub forward_kernels: Option<KernelTimes>,
    /// Mean time per training step inside the CPU kernels, by kind (zero on GPUs).
    pub train_kernels: Option<KernelTimes>,
    /// Mean wall time of a training step's phases (on GPUs, when their work was queued).
    pub train_phases: Option<StepPhases>,
    /// Timed runs per figure.
    pub runs: usize,
}

pub use crate::timing::{median_ms, peak_rss_mb};
pub use sparse_conv::profile::KernelTimes;

/// Where a training step's time goes, mean per step.
#[derive(Debug, Clone, Copy, Serialize)]
pub struct StepPhases {
    /// Forward and loss, with the autodiff graph recorded.
    pub forward_ms: f64,
    /// Backward, to the parameters' gradients.
    pub backward_ms: f64,
    /// Adam's update of every parameter.
    pub optimizer_ms: f64,
}

/// Which figures a run measures.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Parts {
    /// Inference, then training (the training peak includes the inference's).
    #[default]
    Both,
    /// Inference forward and detection only.
    Inference,
    /// Training step only, so its peak memory is the training step's alone.
    Training,
}

/// The figures of one run, `None` where its [`Parts`] left them out.
#[derive(Default)]
struct Figures {
    forward_ms: Option<f64>,
    detect_ms: Option<f64>,
    train_step_ms: Option<f64>,
    forward_mean_ms: Option<f64>,
    train_step_mean_ms: Option<f64>,
    peak_forward_mib: Option<f64>,
    peak_train_mib: Option<f64>,
    forward_kernels: Option<KernelTimes>,
    train_kernels: Option<KernelTimes>,
    train_phases: Option<StepPhases>,
}

/// Median and mean of `runs` calls of `f` after `warmup` untimed ones, and the mean kernel times
/// of the timed calls.
fn timed_with_kernels(warmup: usize, runs: usize, mut f: impl FnMut()) -> (f64, f64, KernelTimes) {
    for _ in 0..warmup {
        f();
    }
    let (before, start) = (KernelTimes::now(), Instant::now());
    let ms = median_ms(0, runs, f);
    let mean_ms = start.elapsed().as_secs_f64() * 1e3 / runs.max(1) as f64;
    (ms, mean_ms, KernelTimes::now().per_run_since(&before, runs))
}

/// Times `model` (built on `device.autodiff()`) on `batch`; inference runs on its `valid()` copy.
fn measure<M: Detector>(mut model: M, batch: &Batch, device: &Device, parts: Parts, warmup: usize, runs: usize) -> Figures {
    let mut figures = Figures::default();
    if parts != Parts::Training {
        let inner = device.clone().inner();
        let eval = model.valid();
        let (ms, mean_ms, kernels) = timed_with_kernels(warmup, runs, || {
            std::hint::black_box(eval.head_output(batch, &inner));
        });
        (figures.forward_ms, figures.forward_mean_ms, figures.forward_kernels) = (Some(ms), Some(mean_ms), Some(kernels));
        figures.detect_ms = Some(median_ms(0, runs.min(3), || {
            std::hint::black_box(eval.detect(batch, &inner));
        }));
        figures.peak_forward_mib = Some(peak_rss_mb());
    }
    if parts != Parts::Inference {
        let mut optim = FusedAdamConfig::new().init();
        let phases = Cell::new([0.0f64; 3]);
        let mut step = || {
            let t = Instant::now();
            let terms = model.clone().loss(batch, device);
            let t_forward = t.elapsed();
            let grads = GradientsParams::from_grads(terms.total.backward(), &model);
            let t_backward = t.elapsed();
            model = optim.step(1e-3, model.clone(), grads);
            let mut sums = phases.get();
            for (sum, d) in sums.iter_mut().zip([t_forward, t_backward - t_forward, t.elapsed() - t_backward]) {
                *sum += d.as_secs_f64() * 1e3;
            }
            phases.set(sums);
        };
        for _ in 0..warmup {
            step();
        }
        phases.set([0.0; 3]);
        let (ms, mean_ms, kernels) = timed_with_kernels(0, runs, &mut step);
        (figures.train_step_ms, figures.train_step_mean_ms, figures.train_kernels) = (Some(ms), Some(mean_ms), Some(kernels));
        let [forward_ms, backward_ms, optimizer_ms] = phases.get().map(|s| s / runs as f64);
        figures.train_phases = Some(StepPhases { forward_ms, backward_ms, optimizer_ms });
        figures.peak_train_mib = Some(peak_rss_mb());
    }
    figures
}

/// Benchmarks the model of `cfg` on `batch` on `device` (a plain device; training uses its
/// autodiff twin).
pub fn run(cfg: &ModelConfig, batch: &Batch, device: &Device, backend: &str, parts: Parts, warmup: usize, runs: usize) -> BenchReport {
    let ad = device.clone().autodiff();
    let (parameters, Figures { forward_ms, detect_ms, train_step_ms, forward_mean_ms, train_step_mean_ms, peak_forward_mib, peak_train_mib, forward_kernels, train_kernels, train_phases }) = match cfg {
        ModelConfig::PersonMinkunet(c) => {
            let m = c.init(&ad);
            (m.num_params(), measure(m, batch, &ad, parts, warmup, runs))
        }
        ModelConfig::Centerpoint(c) => {
            let m = c.init(&ad);
            (m.num_params(), measure(m, batch, &ad, parts, warmup, runs))
        }
    };
    BenchReport {
        cpu_features: sparse_conv::cpu_features(),
        cpu_kernels: sparse_conv::cpu_kernel_path().to_string(),
        model: cfg.kind().to_string(),
        backend: backend.to_string(),
        threads: rayon_threads(),
        batch: batch.len(),
        voxels: batch.num_voxels(),
        parameters,
        forward_ms,
        detect_ms,
        train_step_ms,
        forward_mean_ms,
        train_step_mean_ms,
        peak_forward_mib,
        peak_train_mib,
        forward_kernels,
        train_kernels,
        train_phases,
        runs,
    }
}

fn rayon_threads() -> usize {
    rayon::current_num_threads()
}
