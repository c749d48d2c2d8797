//! Times an inference forward pass and one training step (forward, loss, backward, Adam) of either
//! detector on a voxel scene, and reports the peak memory.
//!
//! `cargo run -p bench --bin model-bench -- --model person_minkunet --coords bench/scene_jrdb_like.npy --threads 2`

use std::path::PathBuf;

use anyhow::Context;
use clap::{Parser, ValueEnum};
use bench::model::{KernelTimes, Parts, bench_batch, run};
use model::{CenterPointConfig, ModelConfig, PersonMinkUNetConfig};
use bench::backend::Backend;
use bench::scene;

#[derive(Clone, Copy, Debug, ValueEnum)]
#[value(rename_all = "snake_case")]
enum Kind {
    PersonMinkunet,
    Centerpoint,
}

#[derive(Clone, Copy, Debug, ValueEnum)]
enum Only {
    Infer,
    Train,
}

#[derive(Parser, Debug)]
#[command(about = "Forward, training-step and memory benchmark of pmunet's detectors")]
struct Args {
    /// The op's kernel knobs.
    #[command(flatten)]
    kernels: sparse_conv::KernelOptions,
    /// Which detector (paper defaults).
    #[arg(long, value_enum, default_value_t = Kind::PersonMinkunet)]
    model: Kind,
    /// Voxel coordinates (.npy, N×4 or N×3); default: the built-in synthetic scene.
    #[arg(long)]
    coords: Option<PathBuf>,
    /// Backend.
    #[arg(long, value_enum, default_value_t = Backend::Flex)]
    backend: Backend,
    /// Samples: the scene is tiled this many times.
    #[arg(long, default_value_t = 2)]
    batch: usize,
    /// Width factor of the model (1.0 = paper).
    #[arg(long, default_value_t = 1.0)]
    width: f64,
    /// CPU threads (rayon); 0 = all cores.
    #[arg(long, default_value_t = 0)]
    threads: usize,
    /// Timed runs per figure (the median is reported).
    #[arg(long, default_value_t = 3)]
    runs: usize,
    /// Untimed warm-up runs per figure.
    #[arg(long, default_value_t = 1)]
    warmup: usize,
    /// Measure only inference or only the training step (whose peak memory is then its own).
    #[arg(long, value_enum)]
    only: Option<Only>,
    /// Print one JSON object instead of text.
    #[arg(long)]
    json: bool,
}

fn main() -> anyhow::Result<()> {
    bench::heap::retain_freed_memory();
    let args = Args::parse();
    args.kernels.apply();
    anyhow::ensure!(args.batch >= 1 && args.runs >= 1, "--batch and --runs must be at least 1");
    rayon::ThreadPoolBuilder::new().num_threads(args.threads).build_global().context("configuring the thread pool")?;
    let coords = args.coords.as_ref().map(|p| scene::read_npy_coords(p)).transpose()?;
    let batch = bench_batch(coords, args.batch);
    let cfg = match args.model {
        Kind::PersonMinkunet => ModelConfig::PersonMinkunet(PersonMinkUNetConfig { width: args.width, ..Default::default() }),
        Kind::Centerpoint => ModelConfig::Centerpoint(CenterPointConfig { width: args.width, ..Default::default() }),
    };
    let (device, name) = (args.backend.device()?, args.backend.name());
    let parts = match args.only {
        None => Parts::Both,
        Some(Only::Infer) => Parts::Inference,
        Some(Only::Train) => Parts::Training,
    };
    let r = run(&cfg, &batch, &device, name, parts, args.warmup, args.runs);
    if args.json {
        println!("{}", serde_json::to_string(&r)?);
    } else {
        println!(
            "{} on {} ({} threads): batch {}, {} voxels, {} parameters, median of {} runs",
            r.model, r.backend, r.threads, r.batch, r.voxels, r.parameters, r.runs
        );
        println!("  CPU features: {}; f32 CPU kernels: {}", if r.cpu_features.is_empty() { "none detected" } else { &r.cpu_features }, r.cpu_kernels);
        if let (Some(forward), Some(detect), Some(peak)) = (r.forward_ms, r.detect_ms, r.peak_forward_mib) {
            println!("  inference forward   {forward:>10.1} ms   (detect incl. decode + NMS {detect:.1} ms)");
            print_kernels(r.forward_kernels, r.forward_mean_ms);
            println!("  peak RSS            {peak:>10.0} MiB after inference");
        }
        if let (Some(step), Some(peak)) = (r.train_step_ms, r.peak_train_mib) {
            println!("  training step       {step:>10.1} ms   (forward, loss, backward, Adam)");
            if let Some(p) = r.train_phases {
                println!("    forward + loss {:.1} ms, backward {:.1} ms, Adam {:.1} ms (means)", p.forward_ms, p.backward_ms, p.optimizer_ms);
            }
            print_kernels(r.train_kernels, r.train_step_mean_ms);
            println!("  peak RSS            {peak:>10.0} MiB after training");
        }
    }
    Ok(())
}

/// The mean time inside the CPU kernels, and the rest of the mean wall time of the same runs (a
/// median would leave a slow run's kernel time out of the whole but not out of the part).
fn print_kernels(k: Option<KernelTimes>, mean_wall_ms: Option<f64>) {
    let (Some(k), Some(wall_ms)) = (k.filter(|k| k.total_ms() > 0.0), mean_wall_ms) else { return };
    println!(
        "    in the kernels {:.1} ms (maps {:.1}, conv fwd {:.1}, input grad {:.1}, weight grad {:.1}, batch norm {:.1}); outside them {:.1} ms (means)",
        k.total_ms(),
        k.map_build_ms,
        k.conv_forward_ms,
        k.conv_input_grad_ms,
        k.conv_weight_grad_ms,
        k.batch_norm_ms,
        wall_ms - k.total_ms()
    );
    if k.gpu_host_ms() > 0.0 {
        println!(
            "    the op's host work on the GPU path: tile plans {:.1} ms, uploads {:.1} ms, dispatch {:.1} ms (in the {:.1} ms above); {:.1} read-backs from the device",
            k.tile_plan_ms, k.upload_ms, k.gpu_dispatch_ms, k.total_ms(), k.read_backs
        );
    } else if k.conv_gflop > 0.0 {
        println!("    conv kernels: {:.1} GFLOP at {:.1} GFLOP/s", k.conv_gflop, k.conv_gflops());
    }
}
