//! The facing stage: an occupancy histogram in the box's frame (and the detector's own
//! direction), read by a logistic regression.

use std::collections::HashMap;
use std::f64::consts::PI;

use data_jrdb::Box3d;
use serde::{Deserialize, Serialize};

use super::features::{FacingFeatures, axis_sign, faces_along_axis};
use super::logistic::LogisticRegression;
use crate::person_minkunet::box_coder::wrap_angle;

/// One box to learn from: its features and whether the true heading points along its signed
/// axis.
#[derive(Debug, Clone, PartialEq)]
pub struct FacingSample {
    /// [`FacingFeatures::read`] of the box.
    pub features: Vec<f64>,
    /// Whether the person faces the sensor's side of the box's axis.
    pub faces: bool,
}

impl FacingSample {
    /// The sample of box `b` (a detection, or a label) over `points`, with the person's true
    /// heading `true_rot_z`; `None` when too few points are inside.
    pub fn new(features: &FacingFeatures, points: &[[f32; 3]], b: &Box3d, true_rot_z: f64) -> Option<Self> {
        Some(Self { features: features.read(points, b)?, faces: faces_along_axis(b, true_rot_z) })
    }
}

/// A fitted facing stage, as a run stores it.
#[derive(Serialize, Deserialize, Debug, Clone, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct FacingClassifier {
    /// What is read in a box.
    pub features: FacingFeatures,
    /// How it is read.
    pub regression: LogisticRegression,
    /// The ridge weight it was fitted with.
    pub l2: f64,
    /// Boxes it was fitted on.
    pub samples: usize,
    /// Share of those it tells right.
    pub training_accuracy: f64,
}

impl FacingClassifier {
    /// Fits the stage on `samples` (read with `features`) with ridge `l2`.
    pub fn fit(features: FacingFeatures, samples: &[FacingSample], l2: f64) -> Result<Self, String> {
        features.check()?;
        if samples.is_empty() {
            return Err("no box to fit the facing stage on".into());
        }
        if let Some(s) = samples.iter().find(|s| s.features.len() != features.len()) {
            return Err(format!("a sample has {} features where the features are {}", s.features.len(), features.len()));
        }
        let xs: Vec<&[f64]> = samples.iter().map(|s| s.features.as_slice()).collect();
        let ys: Vec<bool> = samples.iter().map(|s| s.faces).collect();
        let regression = LogisticRegression::fit(&xs, &ys, l2)?;
        let right = xs.iter().zip(&ys).filter(|(x, y)| (regression.probability(x) > 0.5) == **y).count();
        let stage = Self { features, regression, l2, samples: samples.len(), training_accuracy: right as f64 / samples.len() as f64 };
        stage.check()?;
        Ok(stage)
    }

    /// Whether a stored stage is whole: a geometry with cells, as many weights, means and
    /// scales as the features, all finite.
    pub fn check(&self) -> Result<(), String> {
        self.features.check()?;
        let r = &self.regression;
        let n = self.features.len();
        if [r.weights.len(), r.mean.len(), r.scale.len()].iter().any(|&k| k != n) {
            return Err(format!(
                "the features are {n} but the regression has {} weights, {} means, {} scales",
                r.weights.len(),
                r.mean.len(),
                r.scale.len()
            ));
        }
        let finite = r.weights.iter().chain(&r.mean).all(|v| v.is_finite()) && r.scale.iter().all(|s| s.is_finite() && *s > 0.0) && r.bias.is_finite();
        if !finite {
            return Err("the regression holds a non-finite value or a non-positive scale".into());
        }
        Ok(())
    }

    /// The probability that the person in `b` faces the sensor's side of its axis; `None` when
    /// too few of `points` are inside.
    pub fn probability(&self, points: &[[f32; 3]], b: &Box3d) -> Option<f64> {
        Some(self.regression.probability(&self.features.read(points, b)?))
    }

    /// `b` with its heading turned to the side the stage reads (box, axis and score unchanged);
    /// as it was when too few points are inside. Applied once to a detector's box: with
    /// `detector_direction` the box's own direction is one of the features, so a turned box
    /// reads differently.
    pub fn orient(&self, points: &[[f32; 3]], b: &Box3d) -> Box3d {
        let Some(p) = self.probability(points, b) else { return *b };
        let along = axis_sign(b) > 0.0;
        if along == (p > 0.5) { *b } else { Box3d { rot_z: wrap_angle(b.rot_z + PI), ..*b } }
    }

    /// [`orient`](Self::orient) for every box of one frame. The frame's points are bucketed
    /// once by bird's-eye cell, so each box reads only those near it: a frame holds tens of
    /// thousands of points and a hundred or more kept boxes.
    pub fn orient_all(&self, points: &[[f32; 3]], boxes: &mut [Box3d]) {
        if boxes.is_empty() {
            return;
        }
        let key = |x: f64, y: f64| ((x / BUCKET).floor() as i64, (y / BUCKET).floor() as i64);
        let mut buckets: HashMap<(i64, i64), Vec<[f32; 3]>> = HashMap::new();
        for p in points.iter().filter(|p| p.iter().all(|v| v.is_finite())) {
            buckets.entry(key(p[0] as f64, p[1] as f64)).or_default().push(*p);
        }
        let mut near = Vec::new();
        for b in boxes.iter_mut() {
            let reach = (b.l / 2.0 + self.features.margin).hypot(b.w / 2.0 + self.features.margin);
            // A box wider than a room (no person's; a diverged network's, a non-finite one) reads
            // every point rather than walk the cells, decided before any cell index is formed.
            if !(reach <= MAX_BUCKET_REACH && b.cx.is_finite() && b.cy.is_finite()) {
                *b = self.orient(points, b);
                continue;
            }
            let ((x0, y0), (x1, y1)) = (key(b.cx - reach, b.cy - reach), key(b.cx + reach, b.cy + reach));
            near.clear();
            for ix in x0..=x1 {
                for iy in y0..=y1 {
                    near.extend_from_slice(buckets.get(&(ix, iy)).map_or(&[][..], Vec::as_slice));
                }
            }
            *b = self.orient(&near, b);
        }
    }
}

/// The bird's-eye bucket of [`FacingClassifier::orient_all`] (m): about a person's reach.
const BUCKET: f64 = 1.0;
/// Boxes reaching farther than this (m) from their centre read the whole cloud instead.
const MAX_BUCKET_REACH: f64 = 16.0;

#[cfg(test)]
mod tests {
    use super::*;

    /// A person at (cx, cy) facing `rot_z`: a torso column and feet reaching forward, the cue
    /// the stage has to find.
    fn person_points(cx: f64, cy: f64, rot_z: f64) -> Vec<[f32; 3]> {
        let (s, c) = rot_z.sin_cos();
        let mut pts = Vec::new();
        for k in 0..30 {
            let (u, v) = (0.02 * (k % 5) as f64 - 0.04, 0.05 * (k % 6) as f64 - 0.12);
            pts.push([cx + c * u - s * v, cy + s * u + c * v, -0.2 + 0.04 * k as f64]);
        }
        for k in 0..6 {
            let (u, v) = (0.25, 0.06 * k as f64 - 0.15);
            pts.push([cx + c * u - s * v, cy + s * u + c * v, -0.68]);
        }
        pts.iter().map(|p| p.map(|v| v as f32)).collect()
    }

    fn box_at(cx: f64, cy: f64, rot_z: f64) -> Box3d {
        Box3d { cx, cy, cz: 0.15, l: 0.7, w: 0.6, h: 1.7, rot_z }
    }

    #[test]
    fn learns_feet_forward_and_orients_boxes_of_either_direction() {
        let f = FacingFeatures::default();
        let mut samples = Vec::new();
        for i in 0..80 {
            let (azimuth, heading) = (0.3 * i as f64, 0.77 * i as f64);
            let (cx, cy) = (6.0 * azimuth.cos(), 6.0 * azimuth.sin());
            // The box's heading is the axis only: half of them point the wrong way.
            let det = box_at(cx, cy, if i % 2 == 0 { heading } else { heading + PI });
            samples.push(FacingSample::new(&f, &person_points(cx, cy, heading), &det, heading).unwrap());
        }
        assert!(samples.iter().any(|s| s.faces) && samples.iter().any(|s| !s.faces));
        let stage = FacingClassifier::fit(f, &samples, 1e-2).unwrap();
        stage.check().unwrap();
        assert_eq!(stage.training_accuracy, 1.0);
        // People it never saw, boxes flipped or not: each turned to within 90° of the truth.
        for i in 0..20 {
            let (azimuth, heading) = (0.5 + 0.41 * i as f64, -1.0 + 0.53 * i as f64);
            let (cx, cy) = (9.0 * azimuth.cos(), 9.0 * azimuth.sin());
            for flip in [0.0, PI] {
                let b = stage.orient(&person_points(cx, cy, heading), &box_at(cx, cy, heading + flip));
                assert!(wrap_angle(b.rot_z - heading).abs() < 1e-9, "person {i}, flip {flip}: {} vs {heading}", b.rot_z);
            }
        }
        // No points: the box is left as it was.
        let b = box_at(3.0, 0.0, 1.0);
        assert_eq!(stage.orient(&[], &b), b);
        // A whole frame at once (bucketed) turns every box as one at a time (all points) does,
        // with people on bucket borders, a box with no points and a box wider than a room.
        let mut cloud = Vec::new();
        let mut boxes = Vec::new();
        for i in 0..30 {
            let (cx, cy, heading) = (-7.0 + 0.5 * i as f64, 0.98 + 0.7 * (i % 4) as f64, 0.9 * i as f64);
            cloud.extend(person_points(cx, cy, heading));
            boxes.push(box_at(cx, cy, heading + if i % 3 == 0 { PI } else { 0.0 }));
        }
        boxes.push(box_at(40.0, 40.0, 0.3));
        boxes.push(Box3d { l: 3000.0, ..box_at(1.0, 1.0, 0.2) });
        boxes.push(Box3d { l: 1e20, ..box_at(-2.0, 1.0, 0.2) });
        boxes.push(Box3d { w: f64::INFINITY, ..box_at(2.0, 1.0, 0.2) });
        let one_by_one: Vec<Box3d> = boxes.iter().map(|b| stage.orient(&cloud, b)).collect();
        stage.orient_all(&cloud, &mut boxes);
        assert_eq!(boxes, one_by_one);
    }

    #[test]
    fn a_damaged_stage_is_refused() {
        let f = FacingFeatures::default();
        let mut stage = FacingClassifier {
            features: f,
            regression: LogisticRegression { mean: vec![0.0; f.len()], scale: vec![1.0; f.len()], weights: vec![0.0; f.len()], bias: 0.0 },
            l2: 0.01,
            samples: 1,
            training_accuracy: 1.0,
        };
        stage.check().unwrap();
        stage.regression.weights.pop();
        assert!(stage.check().unwrap_err().contains(&format!("{} weights", f.len() - 1)));
        stage.regression.weights.push(0.0);
        stage.check().unwrap();
        // A damaged geometry is refused before anything is sized from it.
        for bad in [FacingFeatures { cell: 0.0, ..f }, FacingFeatures { height: 0.01, ..f }, FacingFeatures { profile_cell: Some(f64::NAN), ..f }] {
            assert!(FacingClassifier { features: bad, ..stage.clone() }.check().is_err(), "{bad:?}");
        }
        stage.regression.weights.pop();
        stage.regression.weights.push(f64::NAN);
        assert!(stage.check().is_err());
        assert!(FacingClassifier::fit(f, &[], 0.01).is_err());
    }
}
