//! Greedy non-maximum suppression: the distance-based BEV NMS Person-MinkUNet uses (the authors'
//! `nms_3d_dist_gpu`), CenterPoint's circle NMS and rotated BEV-IoU NMS, and the box voting that
//! may follow any of them.
//!
//! All three walk the candidates by descending score (ties keep input order), drop scores not above
//! `score_threshold` (and NaN), and keep a candidate unless a box *already kept* suppresses it,
//! which is the result of the GPU kernels' pairwise mask followed by the sequential sweep. Kept
//! boxes live in a uniform grid whose cell is at least the largest suppression reach, so each
//! candidate looks at 3×3 cells instead of every kept box: tens of thousands of candidates per
//! frame take milliseconds.

use std::collections::HashMap;

use data_jrdb::Box3d;

use crate::geometry::bev_iou;

/// Settings shared by both NMS flavours; the defaults are Person-MinkUNet's.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NmsConfig {
    /// Candidates with `score <= score_threshold` are dropped first (default: none dropped).
    pub score_threshold: f64,
    /// At most this many boxes are kept (default: no cap).
    pub max_kept: usize,
    /// Distance NMS: suppress when `d / (w̄ + ½(l̄ − w̄)(|cos(θᵢ−φ)| + |cos(θⱼ−φ)|)) < ratio`.
    pub dist_ratio: f64,
    /// Distance NMS: mean person length l̄ (m), along the heading.
    pub mean_l: f64,
    /// Distance NMS: mean person width w̄ (m).
    pub mean_w: f64,
    /// IoU NMS: suppress when rotated BEV IoU is strictly above this.
    pub iou_threshold: f64,
}

impl Default for NmsConfig {
    fn default() -> Self {
        NmsConfig {
            score_threshold: f64::NEG_INFINITY,
            max_kept: usize::MAX,
            dist_ratio: 0.4,
            mean_l: 0.9,
            mean_w: 0.5,
            iou_threshold: 0.3,
        }
    }
}

/// Candidate indices that pass the score threshold, by descending score (stable on ties).
fn order<S: Copy + Into<f64>>(boxes: &[Box3d], scores: &[S], cfg: &NmsConfig) -> Vec<usize> {
    assert_eq!(boxes.len(), scores.len(), "one score per box");
    let s = |i: usize| -> f64 { scores[i].into() };
    let mut idx: Vec<usize> = (0..boxes.len())
        .filter(|&i| s(i) > cfg.score_threshold)
        .collect();
    idx.sort_by(|&a, &b| s(b).total_cmp(&s(a)));
    idx
}

/// Uniform hash grid over kept boxes' centres.
struct Grid {
    cell: f64,
    cells: HashMap<(i64, i64), Vec<usize>>,
}

impl Grid {
    fn new(cell: f64) -> Self {
        // A zero or non-finite reach degenerates to one cell per exact position.
        let cell = if cell.is_finite() && cell > 0.0 {
            cell
        } else {
            1.0
        };
        Grid {
            cell,
            cells: HashMap::new(),
        }
    }
    fn key(&self, b: &Box3d) -> (i64, i64) {
        (
            (b.cx / self.cell).floor() as i64,
            (b.cy / self.cell).floor() as i64,
        )
    }
    fn insert(&mut self, b: &Box3d, i: usize) {
        let k = self.key(b);
        self.cells.entry(k).or_default().push(i);
    }
    /// The entries of the 3×3 cells around `b`'s cell: every entry within one cell of it.
    fn near(&self, b: &Box3d) -> impl Iterator<Item = usize> + '_ {
        let (kx, ky) = self.key(b);
        (-1..=1)
            .flat_map(move |dx| (-1..=1).map(move |dy| (kx + dx, ky + dy)))
            .filter_map(|k| self.cells.get(&k))
            .flatten()
            .copied()
    }
    fn any_near(&self, b: &Box3d, hit: impl FnMut(usize) -> bool) -> bool {
        self.near(b).any(hit)
    }
}

/// `a` in (−π, π], the range every decoded heading lies in.
fn wrap_angle(a: f64) -> f64 {
    let r = a.rem_euclid(std::f64::consts::TAU);
    if r > std::f64::consts::PI { r - std::f64::consts::TAU } else { r }
}

/// Box voting after NMS: every candidate above `score_threshold` votes, with its score raised to
/// `power` as weight (1: the score itself), for the kept box (`kept`, indices into `boxes`) whose centre is nearest in BEV if that
/// lies within `radius`; a kept box becomes the weighted mean of its voters' centres and sizes
/// (it votes for itself, so it always has one). With `axis`, its heading becomes the weighted
/// mean axis of the voters' headings (the mean of `(cos 2θ, sin 2θ)`: votes π apart agree),
/// turned to the side of its own heading (in (−π, π]); without, it keeps its own.
pub fn vote<S: Copy + Into<f64>>(
    boxes: &[Box3d],
    scores: &[S],
    kept: &[usize],
    radius: f64,
    score_threshold: f64,
    axis: bool,
    power: f64,
) -> Vec<Box3d> {
    let mut grid = Grid::new(radius);
    for (slot, &i) in kept.iter().enumerate() {
        grid.insert(&boxes[i], slot);
    }
    let mut means = vec![BoxMean::default(); kept.len()];
    for (b, &s) in boxes.iter().zip(scores) {
        let s: f64 = s.into();
        if s.is_nan() || s <= score_threshold {
            continue;
        }
        let s = if power == 1.0 { s } else { s.powf(power) };
        let nearest = grid
            .near(b)
            .map(|slot| {
                let k = &boxes[kept[slot]];
                ((k.cx - b.cx).hypot(k.cy - b.cy), slot)
            })
            .filter(|&(d, _)| d <= radius)
            .min_by(|x, y| x.0.total_cmp(&y.0));
        if let Some((_, slot)) = nearest {
            means[slot].add(b, s);
        }
    }
    kept.iter().zip(&means).map(|(&i, mean)| mean.mean(boxes[i].rot_z, axis)).collect()
}

/// A running weighted mean of boxes: centre and size, and the heading's axis as the mean of
/// `(cos 2θ, sin 2θ)` (so headings π apart agree). What box voting and the fusion of several
/// passes' boxes compute.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct BoxMean {
    /// Weighted sums of cx, cy, cz, l, w, h, the weight, cos 2θ and sin 2θ.
    sums: [f64; 9],
}

impl BoxMean {
    /// Adds `b` with weight `w` (> 0).
    pub fn add(&mut self, b: &Box3d, w: f64) {
        let (s2, c2) = (2.0 * b.rot_z).sin_cos();
        for (a, v) in self.sums.iter_mut().zip([b.cx, b.cy, b.cz, b.l, b.w, b.h, 1.0, c2, s2]) {
            *a += w * v;
        }
    }

    /// The mean box (at least one box added). Its heading: with `axis`, the mean axis turned to
    /// the side of `own` (in (−π, π]); without, `own`.
    pub fn mean(&self, own: f64, axis: bool) -> Box3d {
        let acc = &self.sums;
        let m = |k: usize| acc[k] / acc[6];
        let rot_z = if axis && acc[7].hypot(acc[8]) > 1e-9 {
            let phi = 0.5 * acc[8].atan2(acc[7]);
            // φ or φ + π, whichever is nearer `own`, in the same turn as it.
            let half = std::f64::consts::FRAC_PI_2;
            wrap_angle(own + ((phi - own + half).rem_euclid(std::f64::consts::PI) - half))
        } else {
            own
        };
        Box3d { cx: m(0), cy: m(1), cz: m(2), l: m(3), w: m(4), h: m(5), rot_z }
    }
}

/// Whether kept box `a` suppresses `b` under the distance criterion of the authors' `dist_bev`.
pub fn distance_suppresses(a: &Box3d, b: &Box3d, cfg: &NmsConfig) -> bool {
    let (dx, dy) = (b.cx - a.cx, b.cy - a.cy);
    let d = dx.hypot(dy);
    let phi = dy.atan2(dx);
    let denom = cfg.mean_w
        + 0.5
            * (cfg.mean_l - cfg.mean_w)
            * ((a.rot_z - phi).cos().abs() + (b.rot_z - phi).cos().abs());
    d / denom < cfg.dist_ratio
}

/// Distance-based BEV NMS (Person-MinkUNet's): indices kept, by descending score.
///
/// The suppression reach is at most `ratio · max(l̄, w̄)` (0.36 m by default), the grid's cell.
pub fn nms_distance<S: Copy + Into<f64>>(
    boxes: &[Box3d],
    scores: &[S],
    cfg: &NmsConfig,
) -> Vec<usize> {
    let reach = cfg.dist_ratio * cfg.mean_l.max(cfg.mean_w);
    let mut grid = Grid::new(reach);
    let mut kept = Vec::new();
    for i in order(boxes, scores, cfg) {
        if kept.len() >= cfg.max_kept {
            break;
        }
        if !grid.any_near(&boxes[i], |k| {
            distance_suppresses(&boxes[k], &boxes[i], cfg)
        }) {
            grid.insert(&boxes[i], i);
            kept.push(i);
        }
    }
    kept
}

/// CenterPoint's circle NMS: a kept box suppresses every candidate whose BEV centre lies strictly
/// within `radius` of its own; indices kept, by descending score. Radius 0 keeps every candidate
/// that passes the threshold.
pub fn nms_circle<S: Copy + Into<f64>>(
    boxes: &[Box3d],
    scores: &[S],
    radius: f64,
    cfg: &NmsConfig,
) -> Vec<usize> {
    let mut grid = Grid::new(radius);
    let mut kept = Vec::new();
    for i in order(boxes, scores, cfg) {
        if kept.len() >= cfg.max_kept {
            break;
        }
        let b = &boxes[i];
        if !grid.any_near(b, |k| (boxes[k].cx - b.cx).hypot(boxes[k].cy - b.cy) < radius) {
            grid.insert(b, i);
            kept.push(i);
        }
    }
    kept
}

/// Greedy rotated-BEV-IoU NMS: indices kept, by descending score.
///
/// Two footprints can only overlap when their centres are closer than the sum of their half
/// diagonals, so the grid cell is the largest diagonal among the candidates.
pub fn nms_bev_iou<S: Copy + Into<f64>>(
    boxes: &[Box3d],
    scores: &[S],
    cfg: &NmsConfig,
) -> Vec<usize> {
    let idx = order(boxes, scores, cfg);
    let reach = idx
        .iter()
        .map(|&i| boxes[i].l.hypot(boxes[i].w))
        .fold(0.0, f64::max);
    let mut grid = Grid::new(reach);
    let mut kept = Vec::new();
    for i in idx {
        if kept.len() >= cfg.max_kept {
            break;
        }
        if !grid.any_near(&boxes[i], |k| {
            bev_iou(&boxes[k], &boxes[i]) > cfg.iou_threshold
        }) {
            grid.insert(&boxes[i], i);
            kept.push(i);
        }
    }
    kept
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    fn person(cx: f64, cy: f64, rot_z: f64) -> Box3d {
        Box3d {
            cx,
            cy,
            cz: 0.0,
            l: 0.9,
            w: 0.5,
            h: 1.7,
            rot_z,
        }
    }

    /// All-pairs reference of the same greedy rule.
    fn brute(
        boxes: &[Box3d],
        scores: &[f64],
        cfg: &NmsConfig,
        sup: impl Fn(&Box3d, &Box3d) -> bool,
    ) -> Vec<usize> {
        let mut idx: Vec<usize> = (0..boxes.len())
            .filter(|&i| scores[i] > cfg.score_threshold)
            .collect();
        idx.sort_by(|&a, &b| scores[b].total_cmp(&scores[a]));
        let mut kept: Vec<usize> = Vec::new();
        for i in idx {
            if kept.len() < cfg.max_kept && !kept.iter().any(|&k| sup(&boxes[k], &boxes[i])) {
                kept.push(i);
            }
        }
        kept
    }

    #[test]
    fn distance_radius_depends_on_direction() {
        let cfg = NmsConfig::default();
        let a = person(0.0, 0.0, 0.0);
        // Along the heading the radius is 0.4·0.9 = 0.36 m, across it 0.4·0.5 = 0.20 m.
        assert!(distance_suppresses(&a, &person(0.35, 0.0, 0.0), &cfg));
        assert!(!distance_suppresses(&a, &person(0.37, 0.0, 0.0), &cfg));
        assert!(distance_suppresses(&a, &person(0.0, 0.19, 0.0), &cfg));
        assert!(!distance_suppresses(&a, &person(0.0, 0.21, 0.0), &cfg));
        // Same centre: always suppressed.
        assert!(distance_suppresses(&a, &person(0.0, 0.0, 1.0), &cfg));
    }

    #[test]
    fn keeps_by_score_and_respects_threshold_and_cap() {
        let boxes = [
            person(0.0, 0.0, 0.0),
            person(0.1, 0.0, 0.0),
            person(5.0, 0.0, 0.0),
            person(9.0, 0.0, 0.0),
        ];
        let scores = [0.5f32, 0.9, 0.7, 0.05];
        let cfg = NmsConfig::default();
        assert_eq!(nms_distance(&boxes, &scores, &cfg), vec![1, 2, 3]);
        assert_eq!(nms_bev_iou(&boxes, &scores, &cfg), vec![1, 2, 3]);
        assert_eq!(nms_circle(&boxes, &scores, 0.5, &cfg), vec![1, 2, 3]);
        assert_eq!(nms_circle(&boxes, &scores, 0.0, &cfg), vec![1, 2, 0, 3]);
        let cfg = NmsConfig {
            score_threshold: 0.1,
            ..cfg
        };
        assert_eq!(nms_distance(&boxes, &scores, &cfg), vec![1, 2]);
        let cfg = NmsConfig { max_kept: 1, ..cfg };
        assert_eq!(nms_bev_iou(&boxes, &scores, &cfg), vec![1]);
    }

    #[test]
    fn grid_matches_all_pairs_on_random_crowds() {
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        for round in 0..5 {
            let n = 3000;
            let boxes: Vec<Box3d> = (0..n)
                .map(|_| Box3d {
                    cx: rng.random_range(-8.0..8.0),
                    cy: rng.random_range(-8.0..8.0),
                    cz: 0.0,
                    l: rng.random_range(0.2..1.5),
                    w: rng.random_range(0.2..1.0),
                    h: 1.7,
                    rot_z: rng.random_range(-3.2..3.2),
                })
                .collect();
            // Some tied scores, to check the stable order.
            let scores: Vec<f64> = (0..n)
                .map(|_| (rng.random_range(0..500) as f64) / 500.0)
                .collect();
            let cfg = NmsConfig {
                score_threshold: 0.01,
                max_kept: if round == 0 { 100 } else { usize::MAX },
                ..Default::default()
            };
            assert_eq!(
                nms_distance(&boxes, &scores, &cfg),
                brute(&boxes, &scores, &cfg, |a, b| distance_suppresses(
                    a, b, &cfg
                ))
            );
            for radius in [0.0, 0.3, 0.8] {
                assert_eq!(
                    nms_circle(&boxes, &scores, radius, &cfg),
                    brute(&boxes, &scores, &cfg, |a, b| (a.cx - b.cx).hypot(a.cy - b.cy) < radius)
                );
            }
            assert_eq!(
                nms_bev_iou(&boxes, &scores, &cfg),
                brute(&boxes, &scores, &cfg, |a, b| bev_iou(a, b)
                    > cfg.iou_threshold)
            );
        }
    }

    #[test]
    fn a_candidate_looks_at_its_neighbours_only() {
        // 50,000 people over 50 m × 50 m (20 per m²) with distance NMS's 0.36 m cell: each lookup
        // sees the boxes of its 3×3 cells (about 1.2 m², some 23 boxes), never all of them, so
        // NMS over a frame's candidates is linear in their number.
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        let boxes: Vec<Box3d> = (0..50_000)
            .map(|_| {
                person(
                    rng.random_range(-25.0..25.0),
                    rng.random_range(-25.0..25.0),
                    rng.random_range(-3.2..3.2),
                )
            })
            .collect();
        let cfg = NmsConfig::default();
        let mut grid = Grid::new(cfg.dist_ratio * cfg.mean_l.max(cfg.mean_w));
        for (i, b) in boxes.iter().enumerate() {
            grid.insert(b, i);
        }
        let looked: usize = boxes.iter().map(|b| grid.near(b).count()).sum();
        assert!(looked < 40 * boxes.len(), "{} lookups per candidate", looked / boxes.len());
        assert!(!nms_distance(&boxes, &vec![0.5f32; boxes.len()], &cfg).is_empty());
    }
}
