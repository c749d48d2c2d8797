//! Post-processing shared by both detectors: score threshold, candidate cap, NMS, box voting,
//! output cap.

use data_jrdb::Box3d;
use eval::nms::{NmsConfig, nms_bev_iou, nms_circle, nms_distance, vote};
use serde::{Deserialize, Serialize};

use crate::detector::Detections;

/// Which greedy NMS post-processing runs.
#[derive(Serialize, Deserialize, Debug, Clone, Copy, PartialEq, Eq, Default)]
#[serde(rename_all = "snake_case")]
pub enum NmsKind {
    /// Person-MinkUNet's distance NMS in BEV (as in the authors' code; `eval::nms::nms_distance`).
    #[default]
    Distance,
    /// CenterPoint's circle NMS: suppress centres closer than `circle_radius` in BEV.
    Circle,
    /// Rotated BEV IoU NMS (`eval::nms::nms_bev_iou`) above `iou_threshold`.
    BevIou,
    /// No suppression (score threshold and cap still apply).
    None,
}

/// Score threshold, NMS and box cap applied to each sample's candidate boxes.
#[derive(Serialize, Deserialize, Debug, Clone, PartialEq)]
#[serde(default, deny_unknown_fields)]
pub struct PostProcessConfig {
    /// Candidates with `score <= score_threshold` are dropped before NMS. Default 1e-3, what
    /// the authors' `filter_submission.py` keeps; their model itself has no threshold.
    pub score_threshold: f64,
    /// NMS flavour.
    pub nms: NmsKind,
    /// Distance NMS ratio (0.4, the authors' value).
    pub dist_ratio: f64,
    /// Distance NMS mean person length and width (0.9, 0.5 m).
    pub mean_lw: [f64; 2],
    /// Circle NMS radius, metres (about 0.3 m, within the distance NMS's 0.20–0.36 m reach).
    pub circle_radius: f64,
    /// BEV IoU NMS threshold (0.3).
    pub iou_threshold: f64,
    /// At most this many boxes per sample after NMS; `None` keeps all survivors.
    pub max_boxes: Option<usize>,
    /// At most this many candidates (the best-scoring) enter NMS; `None`: all that pass the
    /// threshold (the authors'). Bounds NMS's cost and the near-duplicates it must resolve.
    pub pre_nms_max: Option<usize>,
    /// Box voting after NMS: each kept box's centre and size become the score-weighted mean of
    /// the candidates whose nearest kept centre it is, within this BEV radius (metres); 0: off
    /// (the authors'). Per-voxel proposals scatter around a person, and the best-scoring one is
    /// not the best-placed one; their mean is.
    pub merge_radius: f64,
    /// With voting, also vote the heading's axis (angles doubled, so votes π apart agree), keeping
    /// the kept box's own direction along it. A per-voxel heading is a noisy guess; the axis of
    /// a whole person's votes is not, and IoU depends on the axis alone.
    pub merge_heading: bool,
    /// With voting, each candidate weighs its score raised to this power (1: the score). Above
    /// 1 the confident candidates count more than the many doubtful ones at a person's edge.
    pub merge_power: f64,
    /// Moves every kept box's centre this far (metres) away from the sensor along its bird's-eye
    /// ray from the origin; 0: off (the authors'). A LiDAR sees a person's near side, and trained
    /// offsets fall short of the centre along the line of sight by a few centimetres whatever
    /// the range (docs/recipe.md §6): a calibration, measured on frames that are not scored.
    pub radial_shift: f64,
    /// Turn each kept box's heading to the direction the points in it show, with the facing
    /// stage fitted for the checkpoint (`facing.json` beside its weights, `train facing`), when it
    /// has one; the box, its axis and its score are unchanged, so AP is too. Applied where a run's
    /// model is loaded for inference (`infer`, a sweep's `--rescore`, `detect`, `serve`), not in
    /// training's validation, `calibrate` or `facing` itself.
    pub facing_stage: bool,
    /// Where a trained run's model detects (`train::RunDetector`: `detect`, `serve`, `infer`,
    /// `calibrate`, `facing`, the library), run it on the cloud at this many equal turns about the
    /// vertical axis (1, 2 or 4: the voxel grid's own symmetries) and fuse the passes
    /// (`crate::test_time`); 1: one pass (the authors'). Training's validation runs one pass.
    pub test_time_turns: usize,
    /// Boxes of different passes whose bird's-eye centres lie within this radius (metres) of
    /// the best one are one person.
    pub test_time_radius: f64,
    /// With turns, each turned pass runs only on the voxels whose point lies within this
    /// bird's-eye radius (metres) of a first-pass box scoring at least `test_time_focus_score`;
    /// 0: on the whole cloud. A fused score only matters where some pass draws a box, and the first pass (the
    /// cloud as it is, whole) proposes them; the turned passes re-score its proposals at a
    /// fraction of a pass's cost.
    pub test_time_focus: f64,
    /// The first-pass score a box needs for the turned passes to look around it.
    pub test_time_focus_score: f64,
}

impl Default for PostProcessConfig {
    fn default() -> Self {
        Self {
            score_threshold: 1e-3,
            nms: NmsKind::Distance,
            dist_ratio: 0.4,
            mean_lw: [0.9, 0.5],
            circle_radius: 0.3,
            iou_threshold: 0.3,
            max_boxes: None,
            pre_nms_max: None,
            merge_radius: 0.0,
            merge_heading: true,
            merge_power: 1.0,
            radial_shift: 0.0,
            facing_stage: true,
            test_time_turns: 1,
            test_time_radius: 0.6,
            test_time_focus: 0.0,
            test_time_focus_score: 0.05,
        }
    }
}

impl PostProcessConfig {
    /// Checks values serde cannot.
    pub fn validate(&self) -> Result<(), String> {
        crate::test_time::GridTurn::passes(self.test_time_turns)?;
        if !(self.test_time_radius > 0.0 && self.test_time_radius.is_finite()) {
            return Err(format!("model.post.test_time_radius must be a positive number of metres, got {}", self.test_time_radius));
        }
        if !(self.test_time_focus >= 0.0 && self.test_time_focus.is_finite()) {
            return Err(format!("model.post.test_time_focus must be 0 (the whole cloud) or a positive number of metres, got {}", self.test_time_focus));
        }
        if !(0.0..=1.0).contains(&self.test_time_focus_score) {
            return Err(format!("model.post.test_time_focus_score must lie in [0, 1], got {}", self.test_time_focus_score));
        }
        Ok(())
    }

    /// The `eval` NMS settings this config stands for.
    pub fn nms_config(&self) -> NmsConfig {
        NmsConfig {
            score_threshold: self.score_threshold,
            max_kept: self.max_boxes.unwrap_or(usize::MAX),
            dist_ratio: self.dist_ratio,
            mean_l: self.mean_lw[0],
            mean_w: self.mean_lw[1],
            iou_threshold: self.iou_threshold,
        }
    }

    /// Keeps the candidates that pass the threshold and survive NMS, best first, at most
    /// `max_boxes`; with `pre_nms_max` only the best-scoring candidates enter NMS, and with
    /// `merge_radius > 0` each kept box is the score-weighted mean of its neighbours.
    pub fn apply(&self, boxes: Vec<Box3d>, scores: Vec<f32>) -> Detections {
        let (boxes, scores) = match self.pre_nms_max {
            Some(k) if boxes.len() > k => best_k(boxes, scores, k),
            _ => (boxes, scores),
        };
        let cfg = self.nms_config();
        let kept = match self.nms {
            NmsKind::Distance => nms_distance(&boxes, &scores, &cfg),
            NmsKind::BevIou => nms_bev_iou(&boxes, &scores, &cfg),
            NmsKind::Circle => nms_circle(&boxes, &scores, self.circle_radius, &cfg),
            NmsKind::None => nms_circle(&boxes, &scores, 0.0, &cfg),
        };
        let mut kept_boxes = if self.merge_radius > 0.0 {
            vote(&boxes, &scores, &kept, self.merge_radius, self.score_threshold, self.merge_heading, self.merge_power)
        } else {
            kept.iter().map(|&i| boxes[i]).collect()
        };
        if self.radial_shift != 0.0 {
            kept_boxes.iter_mut().for_each(|b| *b = shifted_along_ray(b, self.radial_shift));
        }
        Detections { boxes: kept_boxes, scores: kept.iter().map(|&i| scores[i]).collect() }
    }
}

/// `b` moved `delta` metres away from the origin along its centre's bird's-eye ray (a box at the
/// origin, whose ray is undefined, stays).
fn shifted_along_ray(b: &Box3d, delta: f64) -> Box3d {
    let r = b.cx.hypot(b.cy);
    if r == 0.0 {
        return *b;
    }
    Box3d { cx: b.cx + delta * b.cx / r, cy: b.cy + delta * b.cy / r, ..*b }
}

/// The `k` best-scoring candidates, in their input order (ties: the earlier wins).
fn best_k(boxes: Vec<Box3d>, scores: Vec<f32>, k: usize) -> (Vec<Box3d>, Vec<f32>) {
    let mut idx: Vec<usize> = (0..boxes.len()).collect();
    idx.sort_by(|&a, &b| scores[b].total_cmp(&scores[a]));
    idx.truncate(k);
    idx.sort_unstable();
    (idx.iter().map(|&i| boxes[i]).collect(), idx.iter().map(|&i| scores[i]).collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn at(x: f64, y: f64) -> Box3d {
        Box3d { cx: x, cy: y, cz: 0.0, l: 0.9, w: 0.5, h: 1.7, rot_z: 0.0 }
    }

    #[test]
    fn threshold_nms_and_cap() {
        let boxes = vec![at(0.0, 0.0), at(0.1, 0.0), at(2.0, 0.0), at(4.0, 0.0), at(6.0, 0.0)];
        let scores = vec![0.5, 0.9, 0.8, 0.0005, 0.7];
        for nms in [NmsKind::Distance, NmsKind::Circle, NmsKind::BevIou] {
            let post = PostProcessConfig { nms, ..Default::default() };
            let d = post.apply(boxes.clone(), scores.clone());
            assert_eq!(d.scores, vec![0.9, 0.8, 0.7], "{nms:?}");
            assert_eq!(d.boxes[0], boxes[1]);
        }
        let none = PostProcessConfig { nms: NmsKind::None, max_boxes: Some(2), ..Default::default() };
        assert_eq!(none.apply(boxes.clone(), scores.clone()).scores, vec![0.9, 0.8]);
        // Only the 2 best candidates enter NMS: 0.9 (suppressing nothing else left) and 0.8.
        let capped = PostProcessConfig { pre_nms_max: Some(2), ..Default::default() };
        assert_eq!(capped.apply(boxes, scores).scores, vec![0.9, 0.8]);
    }

    #[test]
    fn voting_moves_a_kept_box_to_its_neighbours_weighted_mean() {
        let boxes = vec![at(0.0, 0.0), at(0.2, 0.0), at(0.0, 0.3), at(3.0, 0.0), at(3.0, 0.1)];
        let scores = vec![0.6, 0.3, 0.1, 0.5, 0.0005];
        let post = PostProcessConfig { nms: NmsKind::Circle, circle_radius: 1.0, merge_radius: 0.5, ..Default::default() };
        let d = post.apply(boxes, scores);
        assert_eq!(d.scores, vec![0.6, 0.5], "NMS keeps the two people, scores unchanged");
        // (0.6·0 + 0.3·0.2 + 0.1·0) / 1.0 and (0.6·0 + 0.3·0 + 0.1·0.3) / 1.0, up to the f32 scores.
        assert!((d.boxes[0].cx - 0.06).abs() < 1e-7 && (d.boxes[0].cy - 0.03).abs() < 1e-7, "{:?}", d.boxes[0]);
        // The candidate below the threshold does not vote.
        assert_eq!(d.boxes[1], at(3.0, 0.0));
        let off = PostProcessConfig { merge_radius: 0.0, ..post.clone() };
        assert_eq!(off.apply(vec![at(0.0, 0.0), at(0.2, 0.0)], vec![0.6, 0.3]).boxes[0], at(0.0, 0.0));
    }

    #[test]
    fn radial_shift_moves_kept_boxes_away_from_the_sensor() {
        let post = PostProcessConfig { nms: NmsKind::Circle, circle_radius: 0.5, radial_shift: 0.1, ..Default::default() };
        let d = post.apply(vec![at(3.0, 4.0), at(-2.0, 0.0), at(0.0, 0.0)], vec![0.9, 0.8, 0.7]);
        // (3, 4) is 5 m out: 0.1 m further is (3.06, 4.08); (−2, 0) goes to (−2.1, 0); the origin stays.
        let want = [(3.06, 4.08), (-2.1, 0.0), (0.0, 0.0)];
        for (b, (x, y)) in d.boxes.iter().zip(want) {
            assert!((b.cx - x).abs() < 1e-12 && (b.cy - y).abs() < 1e-12, "{b:?} vs ({x}, {y})");
            assert_eq!((b.cz, b.l, b.w, b.h, b.rot_z), (0.0, 0.9, 0.5, 1.7, 0.0));
        }
        let off = PostProcessConfig { radial_shift: 0.0, ..post };
        assert_eq!(off.apply(vec![at(3.0, 4.0)], vec![0.9]).boxes[0], at(3.0, 4.0));
    }

    #[test]
    fn voting_power_weighs_confident_candidates_more() {
        let boxes = vec![at(0.0, 0.0), at(0.3, 0.0)];
        let post = PostProcessConfig { nms: NmsKind::Circle, circle_radius: 0.2, merge_radius: 0.5, merge_power: 2.0, ..Default::default() };
        let d = post.apply(boxes, vec![0.8, 0.4]);
        // NMS keeps both (0.3 m apart, circle 0.2 m); the first votes for itself alone, the second
        // for itself alone too (each candidate votes for its nearest kept box).
        assert_eq!(d.boxes.len(), 2);
        let one = PostProcessConfig { circle_radius: 0.5, ..post.clone() };
        let d = one.apply(vec![at(0.0, 0.0), at(0.3, 0.0)], vec![0.8, 0.4]);
        // Weights 0.64 and 0.16: cx = 0.16·0.3 / 0.8 = 0.06 (0.1 with the scores themselves).
        assert_eq!(d.boxes.len(), 1);
        assert!((d.boxes[0].cx - 0.06).abs() < 1e-6, "{:?}", d.boxes[0]);
        let linear = PostProcessConfig { merge_power: 1.0, ..one };
        assert!((linear.apply(vec![at(0.0, 0.0), at(0.3, 0.0)], vec![0.8, 0.4]).boxes[0].cx - 0.1).abs() < 1e-6);
    }

    #[test]
    fn voting_takes_the_mean_axis_and_keeps_the_kept_direction() {
        let turned = |yaw: f64| Box3d { rot_z: yaw, ..at(0.0, 0.0) };
        // Kept box at 3.0 rad; voters at 0.1 − π and 0.3 (the same axis as 0.3 − π ≈ −2.84).
        let boxes = vec![turned(3.0), turned(0.1 - std::f64::consts::PI), turned(0.3)];
        let scores = vec![0.5, 0.25, 0.25];
        let post = PostProcessConfig { nms: NmsKind::Circle, circle_radius: 1.0, merge_radius: 0.5, ..Default::default() };
        let got = post.apply(boxes.clone(), scores.clone()).boxes[0].rot_z;
        // Axes (mod π): 3.0 − π = −0.1416, 0.1, 0.3; weighted mean of the doubled angles.
        let (s, c) = [(3.0, 0.5), (0.1, 0.25), (0.3, 0.25)]
            .iter()
            .fold((0.0, 0.0), |(s, c), &(a, w): &(f64, f64)| (s + w * (2.0 * a).sin(), c + w * (2.0 * a).cos()));
        let want = 0.5 * s.atan2(c) + std::f64::consts::PI;
        // Just past π, so written as its twin in (−π, π].
        assert!(want > std::f64::consts::PI);
        let want = want - std::f64::consts::TAU;
        assert!((got - want).abs() < 1e-6, "{got} vs {want}: the axis, on the kept box's side");
        let own = PostProcessConfig { merge_heading: false, ..post };
        assert_eq!(own.apply(boxes, scores).boxes[0].rot_z, 3.0);
    }
}
