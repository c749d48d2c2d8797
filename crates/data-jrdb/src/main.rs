//! `data-jrdb`: make a simulated JRDB-format tree, look at any dataset, export one to KITTI's or
//! nuScenes' layout.

use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Instant;

use clap::{Parser, Subcommand};
use data_jrdb::sim::{Preset, SynthConfig, World, synth};
use data_jrdb::split::DEFAULT_VAL_SEQUENCES;
use data_jrdb::{Dataset, DatasetConfig, DatasetFormat, Encoding, Split, VoxelConfig, convention, export, stats};

#[derive(Parser)]
#[command(name = "data-jrdb", about = "Datasets: simulate a JRDB-format tree, print statistics, check boxes, export to KITTI or nuScenes")]
struct Cli {
    #[command(subcommand)]
    cmd: Cmd,
}

#[derive(Clone, Copy, clap::ValueEnum)]
enum Enc {
    Ascii,
    Binary,
    BinaryCompressed,
}

#[derive(Clone, Copy, clap::ValueEnum)]
enum PresetArg {
    /// 160 sequences × 10 frames: 1,200 training and 400 validation frames from disjoint scenes.
    BenchV1,
    /// As large, in streets, campuses and cluttered halls seen by nine sensor models (eleven rigs) on cars,
    /// robots and masts 0.3–2.2 m up (docs/simulated-benchmark.md).
    BenchV2,
}

#[derive(Subcommand)]
enum Cmd {
    /// Simulate sequences and write them as a JRDB-format tree.
    Synth {
        /// Output folder (becomes the tree's root).
        #[arg(long)]
        out: PathBuf,
        /// Number of sequences.
        #[arg(long, default_value_t = SynthConfig::default().sequences)]
        sequences: usize,
        /// Frames per sequence.
        #[arg(long, default_value_t = SynthConfig::default().frames)]
        frames: usize,
        /// Seed; the same seed writes the same tree.
        #[arg(long, default_value_t = 0)]
        seed: u64,
        /// Most people per scene.
        #[arg(long, default_value_t = SynthConfig::default().max_people)]
        max_people: usize,
        /// PCD encoding.
        #[arg(long, value_enum, default_value_t = Enc::Binary)]
        encoding: Enc,
        /// A named benchmark: its sequences, frames and naming replace --sequences, --frames
        /// and --max-people (--seed still applies).
        #[arg(long, value_enum, conflicts_with = "backdrops")]
        preset: Option<PresetArg>,
        /// Put simulated people into the real scans listed in DIR/backdrops.csv (their people
        /// removed) instead of simulated places: --sequences sequences over them in turn.
        #[arg(long, value_name = "DIR")]
        backdrops: Option<PathBuf>,
        /// With --backdrops: the share of sequences (0–1) whose scan is thinned to a 32-beam
        /// sensor's density, people ray-cast with its kept beams.
        #[arg(long, default_value_t = 0.0, requires = "backdrops")]
        thinned_share: f64,
    },
    /// Print frames, points, voxels and boxes per frame and points per box of a dataset.
    Stats {
        /// The dataset (a JRDB tree, a KITTI object root, a nuScenes-style root).
        #[arg(long)]
        root: PathBuf,
        /// Its layout.
        #[arg(long, value_enum, default_value_t = DatasetFormat::Jrdb)]
        format: DatasetFormat,
        /// Print one JSON object instead of a table.
        #[arg(long)]
        json: bool,
        /// Only these sequences (nuScenes: scenes), comma-separated; default all.
        #[arg(long, value_delimiter = ',')]
        sequences: Option<Vec<String>>,
    },
    /// Write a JRDB-format tree in KITTI object's or nuScenes' layout (the same frames and boxes).
    Export {
        /// The JRDB-format tree.
        #[arg(long)]
        root: PathBuf,
        /// A new folder to write.
        #[arg(long)]
        out: PathBuf,
        /// The layout to write.
        #[arg(long, value_enum)]
        to: DatasetFormat,
        /// The validation sequences (`*` matches by prefix): KITTI's ImageSets/val.txt; nuScenes'
        /// scenes keep their names. Default: JRDB's seven.
        #[arg(long, value_delimiter = ',')]
        val_sequences: Option<Vec<String>>,
    },
    /// Recount points in each labelled box under the Box3d convention and its alternatives.
    CheckBoxes {
        /// The tree.
        #[arg(long)]
        root: PathBuf,
        /// Check every n-th frame.
        #[arg(long, default_value_t = 1)]
        stride: usize,
    },
}

fn open_all(root: &std::path::Path, format: DatasetFormat, sequences: Option<Vec<String>>) -> anyhow::Result<Dataset> {
    let cfg = DatasetConfig { format, split: Split::TrainVal, sequences, require_labels: false, ..Default::default() };
    Ok(Dataset::open(root, &cfg)?)
}

fn run(cli: Cli) -> anyhow::Result<()> {
    match cli.cmd {
        Cmd::Synth { out, sequences, frames, seed, max_people, encoding, preset, backdrops, thinned_share } => {
            let encoding = match encoding {
                Enc::Ascii => Encoding::Ascii,
                Enc::Binary => Encoding::Binary,
                Enc::BinaryCompressed => Encoding::BinaryCompressed,
            };
            let t = Instant::now();
            let cfg = match preset {
                Some(PresetArg::BenchV1) => SynthConfig { encoding, ..Preset::BenchV1.synth(seed) },
                Some(PresetArg::BenchV2) => SynthConfig { encoding, ..Preset::BenchV2.synth(seed) },
                None => {
                    let world = if backdrops.is_some() { World::Backdrops } else { World::V1 };
                    SynthConfig { sequences, frames, seed, max_people, encoding, world, backdrops, thinned_share, ..Default::default() }
                }
            };
            let s = synth(&out, &cfg)?;
            println!(
                "wrote {} sequences, {} frames, {} points, {} boxes to {} in {:.1} s",
                s.sequences.len(),
                s.frames,
                s.points,
                s.boxes,
                out.display(),
                t.elapsed().as_secs_f64()
            );
        }
        Cmd::Stats { root, format, json, sequences } => {
            let ds = open_all(&root, format, sequences)?;
            let s = stats::compute(&ds, &VoxelConfig::default())?;
            if json {
                println!("{}", serde_json::to_string_pretty(&s)?);
            } else {
                print!("{s}");
            }
        }
        Cmd::CheckBoxes { root, stride } => {
            let ds = open_all(&root, DatasetFormat::Jrdb, None)?;
            for a in convention::check(&ds, stride)? {
                println!(
                    "{:<32} boxes {:>7}  exact {:>6.1}%  within 10% {:>6.1}%  mean |diff| {:.2}",
                    a.convention,
                    a.boxes,
                    100.0 * a.exact as f64 / a.boxes.max(1) as f64,
                    100.0 * a.close as f64 / a.boxes.max(1) as f64,
                    a.mean_abs_diff
                );
            }
        }
        Cmd::Export { root, out, to, val_sequences } => {
            let ds = open_all(&root, DatasetFormat::Jrdb, None)?;
            let val = val_sequences.unwrap_or_else(|| DEFAULT_VAL_SEQUENCES.map(String::from).to_vec());
            let t = Instant::now();
            let s = export::export(&ds, to, &out, &val)?;
            println!(
                "wrote {} frames ({} in validation), {} people to {} in {to} layout in {:.1} s",
                s.frames,
                s.val_frames,
                s.boxes,
                out.display(),
                t.elapsed().as_secs_f64()
            );
            match to {
                DatasetFormat::Kitti => println!("train on it with [data] format = \"kitti\", root = {:?}, and [data.kitti] camera_view_only = false (the simulated people stand all around)", out),
                DatasetFormat::Nuscenes => println!("train on it with [data] format = \"nuscenes\", root = {:?}, and [data.nuscenes] val_scenes = {:?}", out, val),
                DatasetFormat::Jrdb => {}
            }
        }
    }
    Ok(())
}

fn main() -> ExitCode {
    match run(Cli::parse()) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}
