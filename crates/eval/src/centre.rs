//! Bird's-eye-centre AP (**not a JRDB metric**): a detection matches a pedestrian whose box
//! centre lies within a radius in bird's-eye view, as nuScenes matches. Real scans labelled by
//! other tools draw boxes by other conventions (tighter, looser, another height) than the ones a
//! detector learned, so an IoU criterion would score the labelling convention; the centre is what
//! a user of a person detector needs.
//!
//! The protocol's filters hold as in [`crate::ap`]: a pedestrian beyond its range or with fewer
//! points than its minimum is ignored (a detection on it counts neither way), and a detection
//! beyond the range is not counted. Matching runs per frame in descending score order, each detection taking the closest unmatched
//! pedestrian within the radius. AP is the area under the precision envelope (all-point
//! interpolation), so a set of few people is not capped by the official 40-slot sampling.

use crate::ap::{DetState, Frame, GtState, Protocol, classify_det, classify_gt};
use crate::kitti::KittiObject;

/// The curve of one evaluation.
#[derive(Debug, Clone, PartialEq)]
pub struct CentreCurve {
    /// Area under the precision envelope, in [0, 1].
    pub ap: f64,
    /// Valid pedestrians: the recall denominator.
    pub num_gt: usize,
    /// Frames evaluated.
    pub frames: usize,
    /// Counted detections, best first: `(score, true positive)`.
    pub ranked: Vec<(f64, bool)>,
}

impl CentreCurve {
    /// `(true positives, false positives, missed pedestrians)` of the detections scoring at least `score`.
    pub fn at_score(&self, score: f64) -> (usize, usize, usize) {
        let kept = self.ranked.iter().filter(|(s, _)| *s >= score);
        let tp = kept.clone().filter(|(_, t)| *t).count();
        let fp = kept.filter(|(_, t)| !*t).count();
        (tp, fp, self.num_gt - tp)
    }
}

fn distance(a: &KittiObject, b: &KittiObject) -> f64 {
    // Camera x and z span the ground plane.
    (a.x - b.x).hypot(a.z - b.z)
}

/// Bird's-eye-centre AP of `frames` pooled, matching within `radius` metres.
pub fn centre_ap(frames: &[Frame], radius: f64, p: &Protocol) -> CentreCurve {
    let mut ranked = Vec::new();
    let mut num_gt = 0;
    for f in frames {
        let gt: Vec<GtState> = f.gt.iter().map(|g| classify_gt(g, p)).collect();
        num_gt += gt.iter().filter(|s| **s == GtState::Valid).count();
        let mut order: Vec<usize> = (0..f.det.len()).filter(|&j| classify_det(&f.det[j], p) != DetState::Other).collect();
        order.sort_by(|&a, &b| f.det[b].score.total_cmp(&f.det[a].score));
        let mut taken = vec![false; f.gt.len()];
        for j in order {
            let d = &f.det[j];
            let closest = (0..f.gt.len())
                .filter(|&i| gt[i] != GtState::Dropped && !taken[i])
                .map(|i| (i, distance(d, &f.gt[i])))
                .filter(|&(_, dist)| dist <= radius)
                .min_by(|a, b| a.1.total_cmp(&b.1));
            let valid_det = classify_det(d, p) == DetState::Valid;
            match closest {
                Some((i, _)) => {
                    taken[i] = true;
                    if gt[i] == GtState::Valid && valid_det {
                        ranked.push((d.score, true));
                    }
                }
                None if valid_det => ranked.push((d.score, false)),
                None => {}
            }
        }
    }
    ranked.sort_by(|a, b| b.0.total_cmp(&a.0));
    // Precision at each rank, then its envelope from the right; AP sums it over recall steps.
    let (mut tp, mut precision, mut is_tp) = (0usize, Vec::with_capacity(ranked.len()), Vec::with_capacity(ranked.len()));
    for (k, &(_, t)) in ranked.iter().enumerate() {
        tp += t as usize;
        precision.push(tp as f64 / (k + 1) as f64);
        is_tp.push(t);
    }
    for k in (0..precision.len().saturating_sub(1)).rev() {
        precision[k] = precision[k].max(precision[k + 1]);
    }
    let ap = if num_gt == 0 { 0.0 } else { precision.iter().zip(&is_tp).filter(|(_, t)| **t).map(|(p, _)| p).sum::<f64>() / num_gt as f64 };
    CentreCurve { ap, num_gt, frames: frames.len(), ranked }
}

#[cfg(test)]
mod tests {
    use super::*;
    use data_jrdb::Box3d;

    fn person(x: f64, y: f64, num_points: i64) -> KittiObject {
        KittiObject::ground_truth(&Box3d { cx: x, cy: y, cz: 0.0, l: 0.5, w: 0.5, h: 1.7, rot_z: 0.0 }, num_points, -1.0)
    }

    fn det(x: f64, y: f64, score: f64) -> KittiObject {
        KittiObject::from_box3d(&Box3d { cx: x, cy: y, cz: 0.0, l: 0.9, w: 0.7, h: 1.5, rot_z: 1.0 }, -1, score)
    }

    #[test]
    fn hand_derived_matches_recall_and_ap() {
        let p = Protocol { min_points: 5, ..Protocol::official() };
        let frames = vec![
            Frame {
                sequence: String::new(),
                name: "a".into(),
                // A and B valid; C has 3 points (ignored); D lies 30 m out (ignored).
                gt: vec![person(5.0, 0.0, 50), person(8.0, 2.0, 40), person(3.0, -3.0, 3), person(30.0, 0.0, 80)],
                det: vec![
                    det(5.3, 0.0, 0.9),  // 0.3 m from A: a true positive, though its box is drawn otherwise
                    det(8.0, 2.7, 0.8),  // 0.7 m from B: a false positive, and B is missed
                    det(3.1, -3.0, 0.7), // on the ignored C: not counted
                    det(30.2, 0.0, 0.6), // beyond 25 m: not counted
                    det(12.0, 5.0, 0.4), // nothing there: a false positive
                ],
            },
            Frame {
                sequence: String::new(),
                name: "b".into(),
                gt: vec![person(6.0, 1.0, 20)],
                // Two on one person: the better one matches, the other is a false positive.
                det: vec![det(6.1, 1.1, 0.3), det(6.0, 1.0, 0.2)],
            },
        ];
        let c = centre_ap(&frames, 0.5, &p);
        assert_eq!(c.num_gt, 3);
        // Ranked: 0.9 TP, 0.8 FP, 0.4 FP, 0.3 TP, 0.2 FP. Precision 1, 1/2, 1/3, 1/2, 2/5;
        // envelope at the TPs: 1 and 1/2; AP = (1 + 1/2) / 3.
        assert_eq!(c.ranked.iter().map(|r| r.1).collect::<Vec<_>>(), vec![true, false, false, true, false]);
        assert!((c.ap - 0.5).abs() < 1e-12, "{}", c.ap);
        assert_eq!(c.at_score(0.5), (1, 1, 2));
        assert_eq!(c.at_score(0.0), (2, 3, 1));
        // A wider radius takes B too: 0.9 TP, 0.8 TP, 0.4 FP, 0.3 TP, 0.2 FP → AP (1 + 1 + 3/4) / 3.
        let wide = centre_ap(&frames, 1.0, &p);
        assert!((wide.ap - 2.75 / 3.0).abs() < 1e-12, "{}", wide.ap);
    }
}
