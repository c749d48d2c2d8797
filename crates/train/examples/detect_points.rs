//! Detect people in a point cloud with a trained run through the library API ([`RunDetector`]):
//! load once, call on any `[x, y, z]` array.
//!
//! ```bash
//! cargo run -p train --example detect_points -- [TREE] [FRAME] [RUN_DIR]
//! ```
//!
//! Defaults: the quickstart's simulated tree (`data/sim-quickstart`, made by the README's main
//! command), its first frame, the shipped weights. The points come from the tree's two LiDARs
//! merged into JRDB's base frame (metres; x forward, y left, z up, the floor near z = −0.7 m):
//! the frame a cloud of your own must be in (`data_jrdb::read_pcd` reads one from a PCD file).

use std::path::PathBuf;

use anyhow::{Context, Result};
use data_jrdb::{DatasetConfig, Dataset, Split};
use train::{RunDetector, Slot};

fn main() -> Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let tree = PathBuf::from(args.first().map_or("data/sim-quickstart", String::as_str));
    let frame: usize = args.get(1).map_or(Ok(0), |s| s.parse()).context("FRAME must be a frame index")?;
    let run = PathBuf::from(args.get(2).map_or("weights/person_minkunet", String::as_str));

    let detector = RunDetector::load(&run, Slot::Latest, None)?;
    let ds = Dataset::open(&tree, &DatasetConfig { split: Split::TrainVal, require_labels: false, ..Default::default() })?;
    let scan = ds.load(frame)?;
    let found = detector.detect(&scan.points);

    println!("{} {}: {} points, {} labelled people, {} detections", scan.sequence, scan.name, scan.points.len(), scan.boxes.len(), found.boxes.len());
    for (b, score) in found.boxes.iter().zip(&found.scores).filter(|(_, s)| **s > 0.5) {
        println!("{score:.2}  centre ({:6.2}, {:6.2}, {:5.2})  size {:.2} × {:.2} × {:.2}  heading {:5.2} rad", b.cx, b.cy, b.cz, b.l, b.w, b.h, b.rot_z);
    }
    Ok(())
}
