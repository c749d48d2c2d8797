//! `eval`: JRDB 3D detection AP of a detection set against ground truth, as the official tool
//! computes it (`evaluate_object.cpp`), plus non-official diagnostics clearly labelled.

use std::path::PathBuf;

use anyhow::Context;
use clap::Parser;
use eval::ap::{Interpolation, Protocol};
use eval::centre::centre_ap;
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
    /// Non-official: GT with fewer points are ignored (official: 10).
    #[arg(long, value_name = "N")]
    min_points: Option<i32>,
    /// Non-official: also the bird's-eye-centre AP: a detection matches a pedestrian whose centre
    /// lies within R metres in bird's-eye view, the closest first (for real scans whose boxes are
    /// drawn by other conventions than the detector's).
    #[arg(long, value_name = "R")]
    centre_radius: Option<f64>,
    /// With --centre-radius: recall and false boxes per frame of the detections scoring at least S.
    #[arg(long, value_name = "S", default_value_t = 0.5)]
    at_score: f64,
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
    if let Some(n) = args.min_points {
        protocol.min_points = n;
    }
    let report = Report::compute(&frames, &protocol);
    let centre = args.centre_radius.map(|r| {
        anyhow::ensure!(r > 0.0 && r.is_finite(), "--centre-radius must be a positive number of metres");
        let curve = centre_ap(&frames, r, &protocol);
        let (tp, fp, fn_) = curve.at_score(args.at_score);
        Ok(serde_json::json!({
            "radius_m": r,
            "ap": curve.ap,
            "num_gt": curve.num_gt,
            "at_score": args.at_score,
            "recall_at_score": tp as f64 / (tp + fn_).max(1) as f64,
            "tp_at_score": tp,
            "fp_at_score": fp,
            "fp_per_frame_at_score": fp as f64 / frames.len().max(1) as f64,
            "note": "not a JRDB metric: bird's-eye centre distance, closest first, all-point AP",
        }))
    });
    let centre = centre.transpose()?;
    if args.json {
        let mut v = report.to_json();
        if let Some(c) = &centre {
            v["bev_centre"] = c.clone();
        }
        println!("{}", serde_json::to_string_pretty(&v)?);
    } else {
        print!("{}", report.to_table());
        if let Some(c) = &centre {
            println!(
                "bird's-eye centre within {} m (not a JRDB metric): AP {:.1} % over {} people; at score >= {}: recall {:.1} % ({} found), {:.2} false boxes per frame",
                c["radius_m"], 100.0 * c["ap"].as_f64().unwrap_or(0.0), c["num_gt"], c["at_score"],
                100.0 * c["recall_at_score"].as_f64().unwrap_or(0.0), c["tp_at_score"], c["fp_per_frame_at_score"].as_f64().unwrap_or(0.0)
            );
        }
    }
    if let Some(p) = &args.pr_csv {
        report.write_pr_csv(p)?;
    }
    if let Some(p) = &args.plot {
        plot::plot_pr(&report, p)?;
    }
    Ok(())
}
