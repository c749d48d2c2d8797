//! Validation: detections for every frame of a split, scored with the official JRDB protocol
//! (`eval`), AP3D at IoU 0.3 / 0.5 / 0.7.

use std::time::Instant;

use anyhow::Result;
use burn::tensor::Device;
use data_jrdb::{Batch, Box3d, Loader, stats};
use eval::jrdb::{Detection, detections_to_kitti};
use eval::kitti::KittiObject;
use eval::{Frame, Protocol, Report};
use indicatif::ProgressBar;
use model::{Detections, Detector};

use crate::progress;

/// One frame's ground truth and detections.
#[derive(Debug, Clone, PartialEq)]
pub struct FrameResult {
    /// Sequence name.
    pub sequence: String,
    /// Frame name (`000123`).
    pub name: String,
    /// Pedestrian boxes (base frame).
    pub gt: Vec<Box3d>,
    /// `num_points` of each GT box.
    pub num_points: Vec<i64>,
    /// Boxes the evaluator ignores (KITTI's cyclists, nuScenes' strollers): a detection on one
    /// counts neither way.
    pub ignored: Vec<Box3d>,
    /// Detections, best first.
    pub detections: Vec<Detection>,
}

impl FrameResult {
    /// The GT boxes `protocol` scores: enough points, within its range.
    pub fn scored_gt(&self, protocol: &Protocol) -> Vec<&Box3d> {
        self.gt
            .iter()
            .zip(&self.num_points)
            .filter(|(b, n)| **n >= protocol.min_points as i64 && protocol.max_range.is_none_or(|r| b.bev_range() <= r))
            .map(|(b, _)| b)
            .collect()
    }

    /// The evaluator's frame: GT as the official converter writes it, detections as KITTI lines.
    pub fn to_eval_frame(&self) -> Frame {
        let gt = self
            .gt
            .iter()
            .zip(&self.num_points)
            .map(|(b, &n)| KittiObject::ground_truth(b, n, -1.0))
            .chain(self.ignored.iter().map(|b| KittiObject { kind: IGNORED_KIND.into(), ..KittiObject::ground_truth(b, 0, -1.0) }))
            .collect();
        Frame { sequence: self.sequence.clone(), name: self.name.clone(), gt, det: detections_to_kitti(&self.detections) }
    }
}

/// The type an ignored box is written with for the evaluator: not `Pedestrian`, so a detection
/// on it is neither a true nor a false positive (and not `DontCare`, which is a 2D region).
pub const IGNORED_KIND: &str = "Ignored";

/// BEV range bands (metres) AP is also reported in: near, middle and far of the official 25 m,
/// since far people are where detectors differ.
pub const RANGE_BANDS: [(f64, f64); 3] = [(0.0, 10.0), (10.0, 20.0), (20.0, 25.0)];

/// How well matched detections are oriented.
#[derive(Debug, Clone, Copy, PartialEq, Default, serde::Serialize, serde::Deserialize)]
pub struct HeadingError {
    /// Valid GT boxes matched by a detection (greedy by score, 3D IoU > 0.3, as the AP matches).
    pub matched: usize,
    /// Median |θ_det − θ_gt| in degrees, in [0, 180].
    pub median_deg: f64,
    /// Median of the same difference taken modulo 180° (the box's axis), in [0, 90]: all IoU sees.
    pub median_axis_deg: f64,
    /// Share of the matched boxes whose heading is within 90° of the truth (chance 0.5): the
    /// direction apart from the axis. Errors are bimodal once the axis is learned (near 0° or
    /// near 180°), and then the median over 360° says little about the direction. `None` in
    /// summaries written before it was reported.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub direction_right: Option<f64>,
}

impl HeadingError {
    /// Matches `frames`' detections to their valid GT (official filters of `protocol`) and takes
    /// the median heading errors; `None` when nothing matched.
    pub fn of(frames: &[FrameResult], protocol: &Protocol) -> Option<HeadingError> {
        let mut errors: Vec<f64> = Vec::new();
        for f in frames {
            let valid = f.scored_gt(protocol);
            let mut taken = vec![false; valid.len()];
            // Detections are best first.
            for d in &f.detections {
                let best = valid
                    .iter()
                    .enumerate()
                    .filter(|(i, _)| !taken[*i])
                    .map(|(i, g)| (i, eval::geometry::iou_3d(&d.bbox, g)))
                    .filter(|(_, iou)| *iou > 0.3)
                    .max_by(|a, b| a.1.total_cmp(&b.1));
                if let Some((i, _)) = best {
                    taken[i] = true;
                    let diff = (d.bbox.rot_z - valid[i].rot_z).rem_euclid(std::f64::consts::TAU);
                    errors.push(diff.min(std::f64::consts::TAU - diff));
                }
            }
        }
        if errors.is_empty() {
            return None;
        }
        let axis: Vec<f64> = errors.iter().map(|e| e.min(std::f64::consts::PI - e)).collect();
        let right = errors.iter().filter(|&&e| e < std::f64::consts::FRAC_PI_2).count() as f64 / errors.len() as f64;
        Some(HeadingError {
            matched: errors.len(),
            median_deg: stats::median(errors).to_degrees(),
            median_axis_deg: stats::median(axis).to_degrees(),
            direction_right: Some(right),
        })
    }
}

impl std::fmt::Display for HeadingError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "median heading error {:.1}° ({:.1}° of the axis)", self.median_deg, self.median_axis_deg)?;
        if let Some(right) = self.direction_right {
            write!(f, ", direction within 90° for {:.1} % (chance 50 %)", 100.0 * right)?;
        }
        write!(f, " over {} matched boxes", self.matched)
    }
}

/// The outcome of one validation.
#[derive(Debug, Clone)]
pub struct Validation {
    /// AP3D at IoU 0.3, 0.5, 0.7 (fractions in [0, 1]).
    pub ap3d: [f64; 3],
    /// AP3D at IoU 0.3, 0.5, 0.7 in each of [`RANGE_BANDS`] (not an official metric).
    pub ap3d_by_range: [[f64; 3]; 3],
    /// Heading error of matched detections.
    pub heading: Option<HeadingError>,
    /// The whole report (APBEV, per-sequence AP, counts, PR curves).
    pub report: Report,
    /// Per-frame results, in split order.
    pub frames: Vec<FrameResult>,
    /// Wall time, seconds.
    pub seconds: f64,
}

/// Runs `detect` (a model in eval mode on a plain device, or a [`crate::RunDetector`]) over every
/// batch of `loader`'s epoch 0.
pub fn detect_split(detect: impl Fn(&Batch) -> Vec<Detections>, loader: &Loader, show_progress: bool) -> Result<Vec<FrameResult>> {
    let mut out = Vec::with_capacity(loader.dataset().len());
    visit_split(detect, loader, show_progress, |frame, _| out.push(frame))?;
    Ok(out)
}

/// As [`detect_split`], handing each frame's result to `visit` with the frame's points (empty
/// unless the loader keeps them, as evaluation loaders do) instead of collecting the results:
/// for what needs the points and cannot hold a whole split's.
pub fn visit_split(
    detect: impl Fn(&Batch) -> Vec<Detections>,
    loader: &Loader,
    show_progress: bool,
    mut visit: impl FnMut(FrameResult, &[[f32; 3]]),
) -> Result<()> {
    let pb = if show_progress { progress::bar(loader.dataset().len() as u64, "detect") } else { ProgressBar::hidden() };
    for batch in loader.epoch(0) {
        let batch = batch?;
        let dets = detect(&batch);
        anyhow::ensure!(dets.len() == batch.len(), "the model returned {} detection lists for a batch of {}", dets.len(), batch.len());
        for (b, d) in dets.into_iter().enumerate() {
            let (sequence, name) = batch.frames[b].clone();
            let detections = d.boxes.iter().zip(&d.scores).map(|(bb, &s)| Detection { bbox: *bb, score: s as f64 }).collect();
            let frame = FrameResult { sequence, name, gt: batch.boxes[b].clone(), num_points: batch.num_points[b].clone(), ignored: batch.ignored.get(b).cloned().unwrap_or_default(), detections };
            visit(frame, batch.clouds.get(b).map_or(&[][..], Vec::as_slice));
        }
        pb.inc(batch.len() as u64);
    }
    pb.finish_and_clear();
    Ok(())
}

/// Detections scoring below this are not matched by [`matched_by_centre`] (the confident ones
/// are the ones that count).
pub const MATCH_MIN_SCORE: f64 = 0.3;
/// [`matched_by_centre`] pairs a detection with the nearest unmatched person whose centre is this
/// close in BEV (m).
pub const MATCH_RADIUS: f64 = 0.5;

/// `(detection, person)` pairs of one frame: each detection scoring at least
/// [`MATCH_MIN_SCORE`], best first, takes the nearest unmatched person within [`MATCH_RADIUS`]
/// in BEV among those `protocol` scores (enough points, within its range). By centre, not IoU:
/// what is measured on the pairs (a centre's error, a direction) must not decide who is paired.
pub fn matched_by_centre<'a>(f: &'a FrameResult, protocol: &Protocol) -> Vec<(&'a Detection, &'a Box3d)> {
    let valid = f.scored_gt(protocol);
    let mut taken = vec![false; valid.len()];
    let mut out = Vec::new();
    // Detections are best first.
    for d in f.detections.iter().take_while(|d| d.score >= MATCH_MIN_SCORE) {
        let nearest = valid
            .iter()
            .enumerate()
            .filter(|(i, _)| !taken[*i])
            .map(|(i, g)| (i, (d.bbox.cx - g.cx).hypot(d.bbox.cy - g.cy)))
            .filter(|(_, dist)| *dist < MATCH_RADIUS)
            .min_by(|a, b| a.1.total_cmp(&b.1));
        if let Some((i, _)) = nearest {
            taken[i] = true;
            out.push((d, valid[i]));
        }
    }
    out
}

/// The evaluator's frames of `frames`.
pub fn to_eval_frames(frames: &[FrameResult]) -> Vec<Frame> {
    frames.iter().map(FrameResult::to_eval_frame).collect()
}

/// Scores frame results under `protocol`.
pub fn score(frames: &[FrameResult], protocol: &Protocol) -> Report {
    Report::compute(&to_eval_frames(frames), protocol)
}

/// AP3D at IoU 0.3, 0.5, 0.7 in each of [`RANGE_BANDS`], `protocol` otherwise.
pub fn ap3d_by_range(eval_frames: &[Frame], protocol: &Protocol) -> [[f64; 3]; 3] {
    RANGE_BANDS.map(|(lo, hi)| {
        let band = Protocol { min_range: (lo > 0.0).then_some(lo), max_range: Some(hi), ..*protocol };
        eval::ap::IOU_THRESHOLDS.map(|t| eval::ap::evaluate(eval_frames, t, eval::ap::Overlap::Box3d, &band).ap)
    })
}

/// One line of AP by range band, in percent: `0–10 m 81.2/40.1/3.0  10–20 m …`.
pub fn format_by_range(by_range: &[[f64; 3]; 3]) -> String {
    RANGE_BANDS
        .iter()
        .zip(by_range)
        .map(|((lo, hi), a)| format!("{lo:.0}–{hi:.0} m {:.1}/{:.1}/{:.1}", 100.0 * a[0], 100.0 * a[1], 100.0 * a[2]))
        .collect::<Vec<_>>()
        .join("  ")
}

/// Detects and scores a split.
pub fn validate<D: Detector>(model: &D, loader: &Loader, device: &Device, protocol: &Protocol, show_progress: bool) -> Result<Validation> {
    let t0 = Instant::now();
    let frames = detect_split(|b| model.detect(b, device), loader, show_progress)?;
    let eval_frames = to_eval_frames(&frames);
    let report = Report::compute(&eval_frames, protocol);
    let ap3d = [report.ap3d[0].ap, report.ap3d[1].ap, report.ap3d[2].ap];
    let ap3d_by_range = ap3d_by_range(&eval_frames, protocol);
    let heading = HeadingError::of(&frames, protocol);
    Ok(Validation { ap3d, ap3d_by_range, heading, report, frames, seconds: t0.elapsed().as_secs_f64() })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn perfect_detections_score_one_and_none_score_zero() {
        let b = Box3d { cx: 5.0, cy: 1.0, cz: 0.1, l: 0.9, w: 0.5, h: 1.7, rot_z: 0.3 };
        let far = Box3d { cx: 40.0, ..b };
        let mk = |dets: Vec<Detection>| FrameResult {
            sequence: "s".into(),
            name: "000000".into(),
            gt: vec![b, far],
            num_points: vec![50, 50],
            ignored: vec![],
            detections: dets,
        };
        let p = Protocol::official();
        // The official 40-recall-point AP needs many GT to reach 1 (one GT gives one threshold).
        let many = |f: &dyn Fn(usize) -> Vec<Detection>| -> Vec<FrameResult> {
            (0..50).map(|i| FrameResult { name: format!("{i:06}"), ..mk(f(i)) }).collect()
        };
        let r = score(&many(&|i| vec![Detection { bbox: b, score: 0.5 + i as f64 / 100.0 }]), &p);
        assert!((r.ap3d[0].ap - 1.0).abs() < 1e-9 && (r.ap3d[2].ap - 1.0).abs() < 1e-9, "{}", r.ap3d[0].ap);
        assert_eq!(r.counts.gt, 50, "the GT beyond 25 m is ignored");
        let r = score(&many(&|_| vec![]), &p);
        assert_eq!(r.ap3d[0].ap, 0.0);
        let shifted = Box3d { cx: 5.3, ..b };
        let r = score(&many(&|i| vec![Detection { bbox: shifted, score: 0.5 + i as f64 / 100.0 }]), &p);
        assert!(r.ap3d[0].ap > 0.9 && r.ap3d[2].ap < 0.1, "{:?}", [r.ap3d[0].ap, r.ap3d[2].ap]);
        // A detection on an ignored box (a cyclist) counts neither way; on nothing it is false.
        let cyclist = Box3d { cx: 8.0, cy: -2.0, ..b };
        let with = |ignored: Vec<Box3d>| -> Vec<FrameResult> {
            (0..50).map(|i| FrameResult { ignored: ignored.clone(), detections: vec![Detection { bbox: b, score: 0.5 }, Detection { bbox: cyclist, score: 0.9 }], name: format!("{i:06}"), ..mk(vec![]) }).collect()
        };
        let r = score(&with(vec![cyclist]), &p);
        assert!((r.ap3d[0].ap - 1.0).abs() < 1e-9, "{}", r.ap3d[0].ap);
        let r = score(&with(vec![]), &p);
        assert!(r.ap3d[0].ap < 0.6, "{}", r.ap3d[0].ap);
    }

    /// Square boxes (IoU does not see the heading) turned by hand-picked errors: the medians over
    /// 360° and of the axis, and the share pointing the right way, worked out by hand.
    #[test]
    fn heading_errors_split_the_axis_from_the_direction() {
        let gt = Box3d { cx: 5.0, cy: 1.0, cz: 0.1, l: 0.6, w: 0.6, h: 1.7, rot_z: 0.3 };
        // Errors 10°, 20° and 100° the right way round, 170° (axis 10°) and 190° (= −170°) flipped.
        let frames: Vec<FrameResult> = [10.0f64, 20.0, 100.0, 170.0, 190.0]
            .iter()
            .enumerate()
            .map(|(i, e)| FrameResult {
                sequence: "s".into(),
                name: format!("{i:06}"),
                gt: vec![gt],
                num_points: vec![50],
                ignored: vec![],
                detections: vec![Detection { bbox: Box3d { rot_z: gt.rot_z + e.to_radians(), ..gt }, score: 0.9 }],
            })
            .collect();
        let h = HeadingError::of(&frames, &Protocol::official()).expect("every box matches");
        assert_eq!(h.matched, 5);
        // Sorted over 360°: 10, 20, 100, 170, 170 → 100; of the axis: 10, 20, 80, 10, 10 → 10.
        assert!((h.median_deg - 100.0).abs() < 1e-6, "{}", h.median_deg);
        assert!((h.median_axis_deg - 10.0).abs() < 1e-6, "{}", h.median_axis_deg);
        assert_eq!(h.direction_right, Some(0.4), "10° and 20° only: 100° and the two flipped ones are not");
        // A summary written before the share was reported still reads.
        let old: HeadingError = serde_json::from_str(r#"{"matched": 3, "median_deg": 80.0, "median_axis_deg": 20.0}"#).unwrap();
        assert_eq!(old.direction_right, None);
    }
}
