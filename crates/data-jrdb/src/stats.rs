//! Dataset statistics: frames, points, voxels and boxes per frame and points per box, per
//! sequence and overall, for real or simulated trees alike.

use std::collections::BTreeMap;

use rayon::prelude::*;
use serde::Serialize;

use crate::box3d::Box3d;
use crate::dataset::Dataset;
use crate::error::Result;
use crate::voxelize::{VoxelConfig, voxelize};

/// Totals over a set of frames.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct Counts {
    /// Frames.
    pub frames: usize,
    /// Finite points of both LiDARs.
    pub points: usize,
    /// Pedestrian boxes.
    pub boxes: usize,
    /// Voxels at the configured size.
    pub voxels: usize,
    /// Non-finite points dropped.
    pub dropped_non_finite: usize,
}

impl Counts {
    fn add(&mut self, o: &Counts) {
        self.frames += o.frames;
        self.points += o.points;
        self.boxes += o.boxes;
        self.voxels += o.voxels;
        self.dropped_non_finite += o.dropped_non_finite;
    }
}

/// Minimum, mean and maximum of a per-frame quantity.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct Range {
    /// Smallest.
    pub min: f64,
    /// Mean.
    pub mean: f64,
    /// Largest.
    pub max: f64,
}

fn range(v: &[f64]) -> Range {
    if v.is_empty() {
        return Range::default();
    }
    Range {
        min: v.iter().copied().fold(f64::INFINITY, f64::min),
        mean: v.iter().sum::<f64>() / v.len() as f64,
        max: v.iter().copied().fold(f64::NEG_INFINITY, f64::max),
    }
}

/// BEV range bands (metres) of the per-band box statistics; the last is open.
pub const RANGE_BANDS: [(f64, f64); 4] = [(0.0, 10.0), (10.0, 20.0), (20.0, 25.0), (25.0, f64::INFINITY)];

/// Boxes whose BEV centre range lies in one of [`RANGE_BANDS`].
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct Band {
    /// `"0-10"`, …, `"25+"`.
    pub band: String,
    /// Boxes in the band.
    pub boxes: usize,
    /// Their median `num_points`.
    pub median_points: f64,
    /// The share of them with at least 10 points (what the official protocol scores), in [0, 1].
    pub scored_share: f64,
}

/// Edges of the points-per-box histogram: bucket k holds `EDGES[k] <= n < EDGES[k + 1]`.
pub const BOX_POINT_EDGES: [i64; 8] = [0, 1, 10, 50, 100, 200, 500, 1000];

/// Statistics of a dataset.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct Stats {
    /// Frames.
    pub frames: usize,
    /// Finite points of both LiDARs.
    pub points: usize,
    /// Pedestrian boxes.
    pub boxes: usize,
    /// Voxels.
    pub voxels: usize,
    /// Dropped non-finite points.
    pub dropped_non_finite: usize,
    /// Per sequence.
    pub sequences: BTreeMap<String, Counts>,
    /// Points per frame.
    pub points_per_frame: Range,
    /// Voxels per frame.
    pub voxels_per_frame: Range,
    /// Boxes per frame.
    pub boxes_per_frame: Range,
    /// `num_points` per box.
    pub points_per_box: Range,
    /// Histogram of `num_points` per box, labelled by bucket (`"10-49"`, `"1000+"`).
    pub points_per_box_histogram: BTreeMap<String, usize>,
    /// Box length (along the heading), width and height in metres.
    pub box_size: [Range; 3],
    /// Median of `l / w` over the boxes (how much a wrong heading costs IoU).
    pub median_l_over_w: f64,
    /// Boxes and their points by BEV range.
    pub by_range: Vec<Band>,
}

/// The median of `v` (the mean of the middle two for an even count); 0 for none.
pub fn median(mut v: Vec<f64>) -> f64 {
    if v.is_empty() {
        return 0.0;
    }
    v.sort_by(f64::total_cmp);
    let n = v.len();
    if n % 2 == 1 { v[n / 2] } else { 0.5 * (v[n / 2 - 1] + v[n / 2]) }
}

fn bucket(n: i64) -> String {
    let k = BOX_POINT_EDGES.iter().rposition(|&e| n >= e);
    match k {
        None => "<0".to_string(),
        Some(k) if k + 1 == BOX_POINT_EDGES.len() => format!("{:04}+", BOX_POINT_EDGES[k]),
        Some(k) => format!("{:04}-{:04}", BOX_POINT_EDGES[k], BOX_POINT_EDGES[k + 1] - 1),
    }
}

/// Reads every frame (in parallel) and gathers the statistics; the first bad file is the error.
pub fn compute(ds: &Dataset, voxel: &VoxelConfig) -> Result<Stats> {
    let per: Vec<(String, Counts, Vec<i64>, Vec<Box3d>)> = (0..ds.len())
        .into_par_iter()
        .map(|i| {
            let f = ds.load(i)?;
            let c = Counts { frames: 1, points: f.points.len(), boxes: f.boxes.len(), voxels: voxelize(&f.points, voxel).len(), dropped_non_finite: f.dropped_non_finite };
            Ok((f.sequence, c, f.num_points, f.boxes))
        })
        .collect::<Result<_>>()?;
    let mut s = Stats::default();
    let mut all = Counts::default();
    let mut box_pts = Vec::new();
    for b in BOX_POINT_EDGES {
        s.points_per_box_histogram.insert(bucket(b), 0);
    }
    let mut bands: Vec<Vec<f64>> = vec![Vec::new(); RANGE_BANDS.len()];
    let mut sizes: [Vec<f64>; 3] = Default::default();
    let mut ratios = Vec::new();
    for (seq, c, nps, boxes) in &per {
        all.add(c);
        s.sequences.entry(seq.clone()).or_default().add(c);
        for &n in nps {
            *s.points_per_box_histogram.entry(bucket(n)).or_default() += 1;
            box_pts.push(n as f64);
        }
        for (b, &n) in boxes.iter().zip(nps) {
            let r = b.bev_range();
            if let Some(k) = RANGE_BANDS.iter().position(|&(lo, hi)| r >= lo && r < hi) {
                bands[k].push(n as f64);
            }
            for (v, x) in sizes.iter_mut().zip([b.l, b.w, b.h]) {
                v.push(x);
            }
            if b.w > 0.0 {
                ratios.push(b.l / b.w);
            }
        }
    }
    s.box_size = sizes.map(|v| range(&v));
    s.median_l_over_w = median(ratios);
    s.by_range = RANGE_BANDS
        .iter()
        .zip(bands)
        .map(|(&(lo, hi), v)| Band {
            band: if hi.is_finite() { format!("{lo:.0}-{hi:.0}") } else { format!("{lo:.0}+") },
            boxes: v.len(),
            scored_share: if v.is_empty() { 0.0 } else { v.iter().filter(|&&n| n >= 10.0).count() as f64 / v.len() as f64 },
            median_points: median(v),
        })
        .collect();
    for seq in &ds.sequences {
        s.sequences.entry(seq.clone()).or_default();
    }
    let col = |f: &dyn Fn(&Counts) -> usize| per.iter().map(|(_, c, _, _)| f(c) as f64).collect::<Vec<_>>();
    s.points_per_frame = range(&col(&|c| c.points));
    s.voxels_per_frame = range(&col(&|c| c.voxels));
    s.boxes_per_frame = range(&col(&|c| c.boxes));
    s.points_per_box = range(&box_pts);
    (s.frames, s.points, s.boxes, s.voxels, s.dropped_non_finite) = (all.frames, all.points, all.boxes, all.voxels, all.dropped_non_finite);
    Ok(s)
}

impl std::fmt::Display for Stats {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        writeln!(f, "{:<44} {:>7} {:>12} {:>10} {:>8}", "sequence", "frames", "points", "voxels", "boxes")?;
        for (seq, c) in &self.sequences {
            writeln!(f, "{seq:<44} {:>7} {:>12} {:>10} {:>8}", c.frames, c.points, c.voxels, c.boxes)?;
        }
        writeln!(f, "{:<44} {:>7} {:>12} {:>10} {:>8}", "total", self.frames, self.points, self.voxels, self.boxes)?;
        let r = |n: &str, r: &Range| format!("{n:<18} min {:>9.1}  mean {:>9.1}  max {:>9.1}", r.min, r.mean, r.max);
        writeln!(f, "{}", r("points per frame", &self.points_per_frame))?;
        writeln!(f, "{}", r("voxels per frame", &self.voxels_per_frame))?;
        writeln!(f, "{}", r("boxes per frame", &self.boxes_per_frame))?;
        writeln!(f, "{}", r("points per box", &self.points_per_box))?;
        if self.dropped_non_finite > 0 {
            writeln!(f, "non-finite points dropped: {}", self.dropped_non_finite)?;
        }
        for (name, r) in ["box l (m)", "box w (m)", "box h (m)"].iter().zip(&self.box_size) {
            writeln!(f, "{name:<18} min {:>9.2}  mean {:>9.2}  max {:>9.2}", r.min, r.mean, r.max)?;
        }
        writeln!(f, "median l / w       {:.2}", self.median_l_over_w)?;
        writeln!(f, "by BEV range: band, boxes, median points per box, share with >= 10 points")?;
        for b in &self.by_range {
            writeln!(f, "  {:>8} m {:>8} {:>9.0} {:>7.1} %", b.band, b.boxes, b.median_points, 100.0 * b.scored_share)?;
        }
        writeln!(f, "points per box (num_points):")?;
        let max = self.points_per_box_histogram.values().copied().max().unwrap_or(0).max(1);
        for (b, &n) in &self.points_per_box_histogram {
            writeln!(f, "  {b:>10} {n:>8} {}", "#".repeat(n * 40 / max))?;
        }
        Ok(())
    }
}
