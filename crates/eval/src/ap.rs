//! JRDB 3D detection AP exactly as the official `detection_eval/evaluate_object.cpp` computes it
//! (`JRDB-dataset/jrdb_toolkit`), plus clearly named non-official variants.
//!
//! The official protocol, step by step (each step is a function or a commented block below):
//! 1. **Classes and filters** (`classify_gt`, `classify_det`): a GT with `num_points < 0` is
//!    *dropped*; a GT that is not `Pedestrian`, has `num_points < 10` (10 is kept) or lies beyond
//!    25 m (`x² + z² > 25²`, so exactly 25 m is kept) is *ignored*: it is not in the recall
//!    denominator and a detection matched to it is neither TP nor FP. A detection beyond 25 m is
//!    ignored whatever its type; a non-pedestrian detection within range is not considered at all.
//!    `DontCare` GT lines also act as don't-care regions (a detection whose intersection covers
//!    more than the IoU threshold of its own volume is not an FP).
//! 2. **Score thresholds** (`tp_scores`, [`score_thresholds`]): each GT in file order takes the unassigned
//!    detection with IoU > thr and the *highest score*; the scores of the true positives are
//!    sorted and up to 41 of them are picked at recall steps of 1/40 (KITTI `getThresholds`).
//! 3. **Counting** (`count_at`): at each threshold, detections with a lower score are dropped;
//!    each GT in file order takes the unassigned in-range detection of *largest IoU* > thr (an
//!    out-of-range one only while no in-range one was found); TP, FN and FP are summed over frames.
//! 4. **AP**: precision per threshold, made monotone by `p[i] = max(p[i..41])` (unused slots stay
//!    0), then `AP = Σ p[1..=40] / 40` (slot 0 is skipped).
//!
//! IoU is 3D (official) or BEV ([`Overlap::Bev`], *not an official JRDB metric*); a match needs
//! IoU strictly greater than the threshold. Frame order never changes the result; the order of
//! lines inside a frame can (as in the tool).

use crate::geometry::{Point, convex_intersection_area};
use crate::kitti::KittiObject;

/// Number of score thresholds / precision slots of the KITTI protocol.
pub const N_SAMPLE_PTS: usize = 41;

/// The IoU thresholds the official tool offers (`t = 0, 1, 2`); 0.3 is the leaderboard's.
pub const IOU_THRESHOLDS: [f64; 3] = [0.3, 0.5, 0.7];

/// One frame: its ground truth and detections in file order.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Frame {
    /// Sequence name (the folder of the txt file, or the labels_3d file stem).
    pub sequence: String,
    /// Frame name without extension, e.g. `000123`.
    pub name: String,
    /// Ground-truth lines.
    pub gt: Vec<KittiObject>,
    /// Detection lines.
    pub det: Vec<KittiObject>,
}

/// Which overlap a match is judged by.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Overlap {
    /// 3D IoU: the official JRDB metric.
    Box3d,
    /// Rotated bird's-eye-view IoU: **not an official JRDB metric**, reported for diagnosis.
    Bev,
}

/// How precision slots become one number.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Interpolation {
    /// Official: `Σ precision[1..=40] / 40` over the 41 KITTI slots.
    Official40,
    /// **Not official**: old KITTI 11-point, `Σ precision[0, 4, …, 40] / 11`.
    ElevenPoint,
}

/// The evaluation protocol; [`Protocol::official`] is the JRDB leaderboard's.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Protocol {
    /// GT and detections with `x² + z² > r²` are ignored; `None` (**not official**) turns the filter off.
    pub max_range: Option<f64>,
    /// **Not official**: GT and detections with `x² + z² ≤ r²` are ignored too, so that
    /// `min_range..max_range` scores one range band (official: `None`).
    pub min_range: Option<f64>,
    /// GT with fewer points are ignored (official: 10).
    pub min_points: i32,
    /// How the precision slots are averaged.
    pub interpolation: Interpolation,
}

impl Protocol {
    /// The official tool's protocol: 25 m, ≥ 10 points, 40 recall slots.
    pub fn official() -> Self {
        Protocol {
            max_range: Some(25.0),
            min_range: None,
            min_points: 10,
            interpolation: Interpolation::Official40,
        }
    }
}

impl Default for Protocol {
    fn default() -> Self {
        Self::official()
    }
}

/// The PR curve and AP of one evaluation (one IoU threshold, one overlap, a set of frames).
#[derive(Debug, Clone, PartialEq)]
pub struct Curve {
    /// The AP as a fraction in [0, 1].
    pub ap: f64,
    /// Score thresholds chosen by KITTI `getThresholds` (at most 41, descending).
    pub thresholds: Vec<f64>,
    /// The 41 monotone precision slots (slots past `thresholds.len()` are 0).
    pub precision: Vec<f64>,
    /// Recall at each threshold.
    pub recall: Vec<f64>,
    /// True positives at each threshold.
    pub tp: Vec<usize>,
    /// False positives at each threshold.
    pub fp: Vec<usize>,
    /// False negatives at each threshold.
    pub fn_: Vec<usize>,
    /// Counts of the inputs under the protocol's filters.
    pub counts: Counts,
}

/// How many GT and detections fell in each protocol category.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Counts {
    /// Frames evaluated.
    pub frames: usize,
    /// Valid GT: the recall denominator.
    pub gt: usize,
    /// Ignored GT (too few points, beyond range, or not a pedestrian).
    pub ignored_gt: usize,
    /// Dropped GT (`num_points < 0`).
    pub dropped_gt: usize,
    /// All detection lines.
    pub det: usize,
    /// Detections ignored for lying beyond range.
    pub ignored_det: usize,
    /// Detections of another class within range (never considered).
    pub other_det: usize,
}

/// Protocol state of a ground-truth line.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum GtState {
    Dropped,
    Valid,
    Ignored,
}

/// Protocol state of a detection line.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum DetState {
    Other,
    Valid,
    Ignored,
}

/// Outside the protocol's range: beyond `max_range`, or within `min_range` of the sensor.
fn beyond(o: &KittiObject, p: &Protocol) -> bool {
    let r2 = o.range_sq();
    p.max_range.is_some_and(|r| r2 > r * r) || p.min_range.is_some_and(|r| r2 <= r * r)
}

/// Step 1 for a GT line. Class: `Pedestrian` valid, anything else (incl. `Person_sitting`,
/// `DontCare`) ignored; `num_points < 0` drops the line whatever else holds.
pub(crate) fn classify_gt(g: &KittiObject, p: &Protocol) -> GtState {
    if g.num_points < 0 {
        GtState::Dropped
    } else if g.is_pedestrian() && g.num_points >= p.min_points && !beyond(g, p) {
        GtState::Valid
    } else {
        GtState::Ignored
    }
}

/// Step 1 for a detection: the range test comes first, so an out-of-range line of any class
/// is "ignored" (it can absorb a match), an in-range non-pedestrian is never considered.
pub(crate) fn classify_det(d: &KittiObject, p: &Protocol) -> DetState {
    if beyond(d, p) {
        DetState::Ignored
    } else if d.is_pedestrian() {
        DetState::Valid
    } else {
        DetState::Other
    }
}

/// Footprint in the camera (x, z) plane, built as the tool builds its polygon:
/// corners `(±l/2, ±w/2)` turned by `[[cos ry, sin ry], [−sin ry, cos ry]]`, then shifted.
fn footprint(o: &KittiObject) -> [Point; 4] {
    let (s, c) = o.ry.sin_cos();
    let (hl, hw) = (o.l / 2.0, o.w / 2.0);
    [[hl, hw], [hl, -hw], [-hl, -hw], [-hl, hw]]
        .map(|[u, v]| [c * u + s * v + o.x, -s * u + c * v + o.z])
}

/// Overlaps of a detection with a GT: `(IoU, intersection / detection size)`, the second being
/// the tool's criterion for don't-care regions.
fn overlap(d: &KittiObject, g: &KittiObject, kind: Overlap) -> (f64, f64) {
    let inter_area = convex_intersection_area(&footprint(d), &footprint(g));
    match kind {
        Overlap::Box3d => {
            // Camera y points down and (x, y, z) is the bottom: the box spans [y − h, y].
            let ymax = d.y.min(g.y);
            let ymin = (d.y - d.h).max(g.y - g.h);
            let inter = inter_area * (ymax - ymin).max(0.0);
            let det_vol = d.h * d.l * d.w;
            let gt_vol = g.h * g.l * g.w;
            (inter / (det_vol + gt_vol - inter), inter / det_vol)
        }
        Overlap::Bev => {
            let (da, ga) = (d.l * d.w, g.l * g.w);
            (inter_area / (da + ga - inter_area), inter_area / da)
        }
    }
}

/// A frame with its states and all overlaps computed once.
struct Prepared<'a> {
    frame: &'a Frame,
    gt: Vec<GtState>,
    det: Vec<DetState>,
    /// `iou[i][j]`: IoU of detection j with GT i.
    iou: Vec<Vec<f64>>,
    /// For each don't-care GT line: intersection over detection size, per detection.
    dontcare: Vec<Vec<f64>>,
}

fn prepare<'a>(frame: &'a Frame, kind: Overlap, p: &Protocol) -> Prepared<'a> {
    let gt: Vec<GtState> = frame.gt.iter().map(|g| classify_gt(g, p)).collect();
    let det: Vec<DetState> = frame.det.iter().map(|d| classify_det(d, p)).collect();
    let row = |g: &KittiObject, crit: usize| -> Vec<f64> {
        frame
            .det
            .iter()
            .zip(&det)
            .map(|(d, s)| {
                if *s == DetState::Other {
                    return f64::NAN;
                }
                let o = overlap(d, g, kind);
                if crit == 0 { o.0 } else { o.1 }
            })
            .collect()
    };
    let iou = frame
        .gt
        .iter()
        .zip(&gt)
        .map(|(g, s)| {
            if *s == GtState::Dropped {
                Vec::new()
            } else {
                row(g, 0)
            }
        })
        .collect();
    // Don't-care regions are taken from every `DontCare` line, dropped or not (as the tool does).
    let dontcare = frame
        .gt
        .iter()
        .filter(|g| g.kind.eq_ignore_ascii_case("dontcare"))
        .map(|g| row(g, 1))
        .collect();
    Prepared {
        frame,
        gt,
        det,
        iou,
        dontcare,
    }
}

/// Step 2, per frame: scores of the detections that the highest-score matching makes TPs.
fn tp_scores(f: &Prepared, thr: f64, out: &mut Vec<f64>) {
    // The tool's "no detection yet" score: only a detection scoring above it can be picked.
    const NO_DETECTION: f64 = -10_000_000.0;
    let mut assigned = vec![false; f.det.len()];
    for (i, gs) in f.gt.iter().enumerate() {
        if *gs == GtState::Dropped {
            continue;
        }
        let mut best: Option<usize> = None;
        let mut best_score = NO_DETECTION;
        for (j, ds) in f.det.iter().enumerate() {
            if *ds == DetState::Other || assigned[j] {
                continue;
            }
            let score = f.frame.det[j].score;
            if f.iou[i][j] > thr && score > best_score {
                best = Some(j);
                best_score = score;
            }
        }
        if let Some(j) = best {
            assigned[j] = true;
            if *gs == GtState::Valid && f.det[j] == DetState::Valid {
                out.push(f.frame.det[j].score);
            }
        }
    }
}

/// Step 2: KITTI `getThresholds`. Walks the TP scores in descending order and keeps a score
/// whenever its recall `(i+1)/n_gt` is at least as close to the next 1/40 step as the following
/// one; the last score is always kept. The step accumulates `1/40` in floating point, as the tool.
pub fn score_thresholds(scores: &mut [f64], n_gt: usize) -> Vec<f64> {
    scores.sort_by(|a, b| b.total_cmp(a));
    let n = n_gt as f64;
    let mut t = Vec::new();
    let mut current = 0.0f64;
    for i in 0..scores.len() {
        let last = i + 1 == scores.len();
        let l_recall = (i + 1) as f64 / n;
        let r_recall = if last { l_recall } else { (i + 2) as f64 / n };
        if (r_recall - current) < (current - l_recall) && !last {
            continue;
        }
        t.push(scores[i]);
        current += 1.0 / (N_SAMPLE_PTS as f64 - 1.0);
    }
    t
}

/// Step 3 for one frame at one score threshold: `(tp, fp, fn)`.
fn count_at(f: &Prepared, iou_thr: f64, score_thr: f64) -> (usize, usize, usize) {
    let nd = f.det.len();
    let below: Vec<bool> = f.frame.det.iter().map(|d| d.score < score_thr).collect();
    let mut assigned = vec![false; nd];
    let (mut tp, mut fn_) = (0, 0);
    for (i, gs) in f.gt.iter().enumerate() {
        if *gs == GtState::Dropped {
            continue;
        }
        let mut chosen: Option<usize> = None;
        let mut max_overlap = 0.0f64;
        // True while the current choice is an out-of-range detection: any in-range one replaces it.
        let mut chose_ignored = false;
        for j in 0..nd {
            if f.det[j] == DetState::Other || assigned[j] || below[j] {
                continue;
            }
            let ov = f.iou[i][j];
            // Written as a positive test so that a NaN overlap never matches.
            let above = ov > iou_thr;
            if !above {
                continue;
            }
            if f.det[j] == DetState::Valid && (ov > max_overlap || chose_ignored) {
                max_overlap = ov;
                chosen = Some(j);
                chose_ignored = false;
            } else if f.det[j] == DetState::Ignored && chosen.is_none() {
                chosen = Some(j);
                chose_ignored = true;
            }
        }
        match chosen {
            None => {
                if *gs == GtState::Valid {
                    fn_ += 1;
                }
            }
            Some(j) => {
                assigned[j] = true;
                if *gs == GtState::Valid && f.det[j] == DetState::Valid {
                    tp += 1;
                }
            }
        }
    }
    let unassigned_valid =
        |assigned: &[bool], j: usize| !assigned[j] && f.det[j] == DetState::Valid && !below[j];
    let mut fp = (0..nd).filter(|&j| unassigned_valid(&assigned, j)).count();
    // Don't-care regions absorb would-be false positives.
    for row in &f.dontcare {
        for j in 0..nd {
            if unassigned_valid(&assigned, j) && row[j] > iou_thr {
                assigned[j] = true;
                fp -= 1;
            }
        }
    }
    (tp, fp, fn_)
}

/// Evaluates a set of frames pooled together (the tool's "overall"; pass one sequence's frames
/// for its per-sequence AP).
pub fn evaluate<'a>(
    frames: impl IntoIterator<Item = &'a Frame>,
    iou_thr: f64,
    kind: Overlap,
    p: &Protocol,
) -> Curve {
    let prepared: Vec<Prepared> = frames.into_iter().map(|f| prepare(f, kind, p)).collect();
    let mut counts = Counts {
        frames: prepared.len(),
        ..Counts::default()
    };
    for f in &prepared {
        for s in &f.gt {
            match s {
                GtState::Valid => counts.gt += 1,
                GtState::Ignored => counts.ignored_gt += 1,
                GtState::Dropped => counts.dropped_gt += 1,
            }
        }
        counts.det += f.det.len();
        counts.ignored_det += f.det.iter().filter(|s| **s == DetState::Ignored).count();
        counts.other_det += f.det.iter().filter(|s| **s == DetState::Other).count();
    }

    let mut scores = Vec::new();
    for f in &prepared {
        tp_scores(f, iou_thr, &mut scores);
    }
    let mut thresholds = score_thresholds(&mut scores, counts.gt);
    // At most 41 can be chosen (recall never exceeds 1); the guard only keeps slots in bounds.
    thresholds.truncate(N_SAMPLE_PTS);

    let k = thresholds.len();
    let (mut tp, mut fp, mut fn_) = (vec![0; k], vec![0; k], vec![0; k]);
    for f in &prepared {
        for (t, &s) in thresholds.iter().enumerate() {
            let (a, b, c) = count_at(f, iou_thr, s);
            tp[t] += a;
            fp[t] += b;
            fn_[t] += c;
        }
    }
    let recall: Vec<f64> = (0..k)
        .map(|t| tp[t] as f64 / (tp[t] + fn_[t]) as f64)
        .collect();
    let mut precision = vec![0.0f64; N_SAMPLE_PTS];
    for t in 0..k {
        precision[t] = tp[t] as f64 / (tp[t] + fp[t]) as f64;
    }
    // Monotone precision: slot i becomes the first maximum of slots i..41, compared with `<`
    // as std::max_element does (so a NaN, possible only in degenerate inputs, behaves as in C++).
    for t in 0..k {
        let mut m = precision[t];
        for &q in &precision[t + 1..] {
            if m < q {
                m = q;
            }
        }
        precision[t] = m;
    }
    let ap = match p.interpolation {
        Interpolation::Official40 => {
            precision[1..].iter().fold(0.0, |a, &x| a + x) / (N_SAMPLE_PTS as f64 - 1.0)
        }
        Interpolation::ElevenPoint => precision.iter().step_by(4).fold(0.0, |a, &x| a + x) / 11.0,
    };
    Curve {
        ap,
        thresholds,
        precision,
        recall,
        tp,
        fp,
        fn_,
        counts,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn thresholds_take_every_score_when_there_are_40_gt() {
        // With n_gt = 40 every TP is exactly one recall step: all are kept.
        let mut s: Vec<f64> = (0..40).map(|i| i as f64 / 40.0).collect();
        let t = score_thresholds(&mut s, 40);
        assert_eq!(t.len(), 40);
        assert_eq!(t[0], 39.0 / 40.0);
    }

    #[test]
    fn thresholds_subsample_many_scores() {
        // 400 TPs of 400 GT: one in ten (recall steps of 1/40) plus the last.
        let mut s: Vec<f64> = (0..400).map(|i| i as f64).collect();
        let t = score_thresholds(&mut s, 400);
        assert!(t.len() <= 41 && t.len() >= 40, "{}", t.len());
        assert_eq!(*t.last().unwrap(), 0.0);
    }

    #[test]
    fn thresholds_with_one_gt() {
        let mut s = vec![0.7];
        assert_eq!(score_thresholds(&mut s, 1), vec![0.7]);
        let mut none: Vec<f64> = vec![];
        assert!(score_thresholds(&mut none, 0).is_empty());
    }
}
