//! Post-processing shared by both detectors: score threshold, NMS, cap.

use data_jrdb::Box3d;
use eval::nms::{NmsConfig, nms_bev_iou, nms_distance};

use crate::config::{NmsKind, PostProcessConfig};
use crate::detector::Detections;

impl PostProcessConfig {
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
    /// `max_boxes`.
    pub fn apply(&self, boxes: Vec<Box3d>, scores: Vec<f32>) -> Detections {
        let cfg = self.nms_config();
        let kept = match self.nms {
            NmsKind::Distance => nms_distance(&boxes, &scores, &cfg),
            NmsKind::BevIou => nms_bev_iou(&boxes, &scores, &cfg),
            NmsKind::Circle => nms_circle(&boxes, &scores, self.circle_radius, &cfg),
            NmsKind::None => nms_circle(&boxes, &scores, 0.0, &cfg),
        };
        Detections { boxes: kept.iter().map(|&i| boxes[i]).collect(), scores: kept.iter().map(|&i| scores[i]).collect() }
    }
}

/// CenterPoint's circle NMS: greedy by descending score (ties in input order), a candidate is
/// dropped when a kept centre lies strictly within `radius` in BEV. Radius 0 keeps everything
/// that passes the threshold.
pub fn nms_circle(boxes: &[Box3d], scores: &[f32], radius: f64, cfg: &NmsConfig) -> Vec<usize> {
    assert_eq!(boxes.len(), scores.len(), "one score per box");
    let mut idx: Vec<usize> = (0..boxes.len()).filter(|&i| scores[i] as f64 > cfg.score_threshold).collect();
    idx.sort_by(|&a, &b| scores[b].total_cmp(&scores[a]));
    let mut kept: Vec<usize> = Vec::new();
    for i in idx {
        if kept.len() >= cfg.max_kept {
            break;
        }
        let b = &boxes[i];
        if !kept.iter().any(|&k| (boxes[k].cx - b.cx).hypot(boxes[k].cy - b.cy) < radius) {
            kept.push(i);
        }
    }
    kept
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
        assert_eq!(none.apply(boxes, scores).scores, vec![0.9, 0.8]);
    }
}
