//! Times kernel-map builds and the sparse convolution's forward and backward on a voxel scene.
//!
//! `cargo run -p sparse-conv --bin sparse-conv-bench -- --coords ../shared/bench/scene_jrdb_like.npy`

use std::path::PathBuf;
use std::sync::Arc;

use anyhow::Context;
use clap::{Parser, ValueEnum};
use serde::Serialize;
use sparse_conv::burn::tensor::{Device, DeviceKind, Distribution, Tensor};
use sparse_conv::timing::{median_ms, peak_rss_mb};
use sparse_conv::{CoordIndex, KernelMap, scene, sparse_conv};

#[derive(Clone, Copy, Debug, ValueEnum, Serialize)]
#[serde(rename_all = "lowercase")]
enum Backend {
    Flex,
    Ndarray,
    Wgpu,
}

#[derive(Parser, Debug)]
#[command(about = "Benchmark of pmunet's sparse convolution on a voxel scene")]
struct Args {
    /// Voxel coordinates, int32/int64 .npy, N×4 (batch, x, y, z) or N×3; default: built-in scene.
    #[arg(long)]
    coords: Option<PathBuf>,
    /// Seed of the built-in scene.
    #[arg(long, default_value_t = 20240601)]
    seed: u64,
    /// Channel counts to time (C_in = C_out).
    #[arg(long, value_delimiter = ',', default_value = "32,64,128")]
    channels: Vec<usize>,
    /// Submanifold kernel size (odd).
    #[arg(long, default_value_t = 3)]
    kernel: usize,
    #[arg(long, value_enum, default_value_t = Backend::Flex)]
    backend: Backend,
    /// CPU threads (rayon); 0 = all cores.
    #[arg(long, default_value_t = 0)]
    threads: usize,
    /// Timed runs per figure (the median is reported).
    #[arg(long, default_value_t = 10)]
    runs: usize,
    /// Untimed warm-up runs per figure.
    #[arg(long, default_value_t = 2)]
    warmup: usize,
    /// Tile the scene this many times as extra batch samples.
    #[arg(long, default_value_t = 1)]
    scale: usize,
    /// Print one JSON object instead of the table.
    #[arg(long)]
    json: bool,
}

#[derive(Serialize)]
struct Row {
    c_in: usize,
    c_out: usize,
    fwd_ms: f64,
    fwd_bwd_ms: f64,
    fwd_gflops: f64,
    fwd_bwd_gflops: f64,
}

/// The strided pair of the U-Net at one channel count: down k2s2 (its map built inside the timed
/// region, as a forward pass does) and the transposed up conv that reuses it.
#[derive(Serialize)]
struct Strided {
    channels: usize,
    down_fwd_bwd_ms: f64,
    up_fwd_bwd_ms: f64,
}

#[derive(Serialize)]
struct Report {
    voxels: usize,
    pairs: usize,
    backend: Backend,
    threads: usize,
    kernel: usize,
    runs: usize,
    map_ms: f64,
    results: Vec<Row>,
    strided: Vec<Strided>,
    peak_rss_mb: f64,
}

fn main() -> anyhow::Result<()> {
    let args = Args::parse();
    anyhow::ensure!(args.kernel % 2 == 1, "--kernel must be odd, got {}", args.kernel);
    anyhow::ensure!(args.runs >= 1, "--runs must be at least 1");
    anyhow::ensure!(args.scale >= 1, "--scale must be at least 1");
    let pool = rayon::ThreadPoolBuilder::new().num_threads(args.threads).build_global();
    pool.context("configuring the thread pool")?;
    let threads = rayon::current_num_threads();

    let coords = match &args.coords {
        Some(path) => scene::read_npy_coords(path)?,
        None => scene::synthetic_lidar_scene(args.seed),
    };
    let coords = scene::tile_as_batch(&coords, args.scale);
    sparse_conv::coords::validate(&coords).context("scene coordinates")?;
    let device = match args.backend {
        Backend::Flex => Device::flex(),
        #[allow(deprecated)]
        Backend::Ndarray => Device::ndarray(),
        Backend::Wgpu => Device::wgpu(DeviceKind::DefaultDevice),
    };

    let map_ms = median_ms(args.warmup, args.runs, || {
        let index = CoordIndex::build(&coords).expect("validated");
        let map = KernelMap::submanifold(&coords, &index, args.kernel, 1);
        // The per-offset pair lists are part of the map the kernels run on.
        std::hint::black_box(map.pairs());
    });
    let index = CoordIndex::build(&coords)?;
    let map = Arc::new(KernelMap::submanifold(&coords, &index, args.kernel, 1));
    let pairs = map.num_pairs();
    let n = coords.len();
    let volume = map.volume();

    let mut results = Vec::new();
    for &c in &args.channels {
        let x = Tensor::<2>::random([n, c], Distribution::Uniform(-1.0, 1.0), &device);
        let w = Tensor::<3>::random([volume, c, c], Distribution::Uniform(-0.1, 0.1), &device);
        let fwd_ms = median_ms(args.warmup, args.runs, || {
            let out = sparse_conv(x.clone(), w.clone(), &map);
            device.sync().expect("device sync");
            std::hint::black_box(out);
        });
        let ad = device.clone().autodiff();
        let xa = Tensor::<2>::random([n, c], Distribution::Uniform(-1.0, 1.0), &ad).require_grad();
        let wa = Tensor::<3>::random([volume, c, c], Distribution::Uniform(-0.1, 0.1), &ad).require_grad();
        let fwd_bwd_ms = median_ms(args.warmup, args.runs, || {
            let out = sparse_conv(xa.clone(), wa.clone(), &map);
            let grads = out.sum().backward();
            let gx = xa.grad(&grads).expect("feature gradient");
            let gw = wa.grad(&grads).expect("weight gradient");
            ad.sync().expect("device sync");
            std::hint::black_box((gx, gw));
        });
        let flop = 2.0 * pairs as f64 * c as f64 * c as f64;
        results.push(Row {
            c_in: c,
            c_out: c,
            fwd_ms,
            fwd_bwd_ms,
            fwd_gflops: flop / fwd_ms / 1e6,
            fwd_bwd_gflops: 3.0 * flop / fwd_bwd_ms / 1e6,
        });
    }
    let mut strided = Vec::new();
    // The peer's table times the strided pair at C = 64; other channel lists use their first.
    let strided_channels = if args.channels.contains(&64) { Some(64) } else { args.channels.first().copied() };
    if let Some(c) = strided_channels {
        let ad = device.clone().autodiff();
        let x = Tensor::<2>::random([n, c], Distribution::Uniform(-1.0, 1.0), &ad).require_grad();
        let w = Tensor::<3>::random([8, c, c], Distribution::Uniform(-0.1, 0.1), &ad).require_grad();
        let down_fwd_bwd_ms = median_ms(args.warmup, args.runs, || {
            let (map, _) = KernelMap::down(&coords, 2, 1).expect("validated coordinates");
            let out = sparse_conv(x.clone(), w.clone(), &Arc::new(map));
            let grads = out.sum().backward();
            let g = (x.grad(&grads), w.grad(&grads));
            ad.sync().expect("device sync");
            std::hint::black_box(g);
        });
        let (down, coarse) = KernelMap::down(&coords, 2, 1)?;
        let up = Arc::new(down.transposed());
        let xc = Tensor::<2>::random([coarse.len(), c], Distribution::Uniform(-1.0, 1.0), &ad).require_grad();
        let up_fwd_bwd_ms = median_ms(args.warmup, args.runs, || {
            let out = sparse_conv(xc.clone(), w.clone(), &up);
            let grads = out.sum().backward();
            let g = (xc.grad(&grads), w.grad(&grads));
            ad.sync().expect("device sync");
            std::hint::black_box(g);
        });
        strided.push(Strided { channels: c, down_fwd_bwd_ms, up_fwd_bwd_ms });
    }
    let report = Report { voxels: n, pairs, backend: args.backend, threads, kernel: args.kernel, runs: args.runs, map_ms, results, strided, peak_rss_mb: peak_rss_mb() };
    if args.json {
        println!("{}", serde_json::to_string(&report)?);
    } else {
        print_table(&report);
    }
    Ok(())
}

fn print_table(r: &Report) {
    println!(
        "backend {:?}, {} threads, {} voxels, {} pairs (k={}), median of {} runs",
        r.backend, r.threads, r.voxels, r.pairs, r.kernel, r.runs
    );
    println!("submanifold map build: {:.2} ms", r.map_ms);
    println!("{:>6} {:>6} {:>10} {:>10} {:>14} {:>10}", "C_in", "C_out", "fwd ms", "GFLOP/s", "fwd+bwd ms", "GFLOP/s");
    for row in &r.results {
        println!(
            "{:>6} {:>6} {:>10.2} {:>10.1} {:>14.2} {:>10.1}",
            row.c_in, row.c_out, row.fwd_ms, row.fwd_gflops, row.fwd_bwd_ms, row.fwd_bwd_gflops
        );
    }
    for s in &r.strided {
        println!("down k2s2 C={} fwd+bwd (map included): {:.2} ms; up (transposed) fwd+bwd: {:.2} ms", s.channels, s.down_fwd_bwd_ms, s.up_fwd_bwd_ms);
    }
    println!("peak memory (RSS): {:.0} MiB", r.peak_rss_mb);
}
