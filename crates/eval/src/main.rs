//! `eval`: JRDB 3D detection AP of a detection set against ground truth, as the official tool
//! computes it (spec §6), plus non-official diagnostics clearly labelled.

use std::path::PathBuf;

use anyhow::Context;
use clap::Parser;
use eval::ap::{Interpolation, Protocol};
use eval::dataset::{self, Format};
use eval::kitti::FileKind;
use eval::{Report, plot};

/// JRDB-style AP (official evaluate_object.cpp protocol): AP3D and APBEV at IoU 0.3/0.5/0.7.
#[derive(Parser, Debug)]
#[command(name = "eval", version)]
struct Args {
    /// Ground truth: KITTI tree `GT/<seq>/<frame>.txt`, or JRDB `labels_3d` folder / `<seq>.json`.
    #[arg(long)]
    gt: PathBuf,
    /// Detections: KITTI tree `DET/<seq>/<frame>.txt`, or pmunet detection JSON folder / `<seq>.json`.
    #[arg(long)]
    det: PathBuf,
    /// Layout of both GT and DET (default: guessed from each path).
    #[arg(long, value_enum)]
    format: Option<Format>,
    /// Print one JSON object instead of the table.
    #[arg(long)]
    json: bool,
    /// Write the precision/recall points to this CSV file.
    #[arg(long, value_name = "FILE")]
    pr_csv: Option<PathBuf>,
    /// Write the PR curves to this PNG (AP3D solid red/green/blue = IoU 0.3/0.5/0.7, APBEV lighter).
    #[arg(long, value_name = "FILE.png")]
    plot: Option<PathBuf>,
    /// Treat a GT frame without a detection file as a frame with no detections (the official tool refuses).
    #[arg(long)]
    missing_as_empty: bool,
    /// Non-official: turn the 25 m range filter off.
    #[arg(long)]
    no_range_filter: bool,
    /// Non-official: old KITTI 11-point AP instead of the official 40 slots.
    #[arg(long)]
    eleven_point: bool,
    /// Write the GT as the official txt tree into this folder (e.g. to run the official tool).
    #[arg(long, value_name = "DIR")]
    write_kitti_gt: Option<PathBuf>,
    /// Write the detections as the official txt tree into this folder (leaderboard submission layout).
    #[arg(long, value_name = "DIR")]
    write_kitti_det: Option<PathBuf>,
}

fn main() -> anyhow::Result<()> {
    let args = Args::parse();
    let gt_format = match args.format {
        Some(f) => f,
        None => dataset::detect_format(&args.gt).context("cannot tell the format of --gt")?,
    };
    let det_format = match args.format {
        Some(f) => f,
        None => dataset::detect_format(&args.det).context("cannot tell the format of --det")?,
    };
    let frames = dataset::load(
        &args.gt,
        gt_format,
        &args.det,
        det_format,
        args.missing_as_empty,
    )?;
    if let Some(dir) = &args.write_kitti_gt {
        dataset::write_kitti_tree(dir, &frames, FileKind::GroundTruth)?;
    }
    if let Some(dir) = &args.write_kitti_det {
        dataset::write_kitti_tree(dir, &frames, FileKind::Detections)?;
    }
    let mut protocol = Protocol::official();
    if args.no_range_filter {
        protocol.max_range = None;
    }
    if args.eleven_point {
        protocol.interpolation = Interpolation::ElevenPoint;
    }
    let report = Report::compute(&frames, &protocol);
    if args.json {
        println!("{}", serde_json::to_string_pretty(&report.to_json())?);
    } else {
        print!("{}", report.to_table());
    }
    if let Some(p) = &args.pr_csv {
        report.write_pr_csv(p)?;
    }
    if let Some(p) = &args.plot {
        plot::plot_pr(&report, p)?;
    }
    Ok(())
}
