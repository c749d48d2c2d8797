//! AP on small cases whose value is derived by hand from the official `evaluate_object.cpp`.
//!
//! Recurring derivations (n = number of valid GT, all detections perfect unless stated):
//! - `getThresholds` keeps the k-th best TP score when `(k+2)/n − k/40 ≥ k/40 − (k+1)/n`; for
//!   n ≤ 41 and k ≤ 40 this always holds, so every TP score is a threshold.
//! - With n perfect detections (n ≤ 41) the precision is 1 in slots 0..n−1 and 0 after, so
//!   AP = (n − 1)/40 because slot 0 is skipped: n = 40 gives 39/40, n = 41 gives 1.
//! - One extra false positive scoring above every TP is counted at every threshold: precision at
//!   slot k is (k+1)/(k+2), the monotone envelope makes every used slot 40/41, so for n = 40
//!   AP = 39·(40/41)/40 = 39/41.

use eval::Box3d;
use eval::ap::{Frame, Interpolation, Overlap, Protocol, evaluate};
use eval::kitti::KittiObject;

fn person(cx: f64, cy: f64) -> Box3d {
    Box3d {
        cx,
        cy,
        cz: 0.0,
        l: 0.9,
        w: 0.5,
        h: 1.7,
        rot_z: 0.0,
    }
}

fn gt(b: Box3d, num_points: i32) -> KittiObject {
    KittiObject::from_box3d(&b, num_points, 1.0)
}

fn det(b: Box3d, score: f64) -> KittiObject {
    KittiObject::from_box3d(&b, -1, score)
}

/// `n` ≤ 100 people on a 2 m grid (x ∈ [−20, 18], y ∈ [−10, −2], all within 23 m, the line
/// y = 0 left free), each with a perfect detection of score 0.5 + i/1000 (distinct).
fn row(n: usize) -> Frame {
    let mut f = Frame {
        sequence: "s".into(),
        name: "000000".into(),
        ..Frame::default()
    };
    for i in 0..n {
        let b = person(-20.0 + 2.0 * (i % 20) as f64, -10.0 + 2.0 * (i / 20) as f64);
        f.gt.push(gt(b, 50));
        f.det.push(det(b, 0.5 + i as f64 / 1000.0));
    }
    f
}

/// Equal up to the rounding of summing 40 slots (the hand values are exact fractions).
fn close(a: f64, b: f64) {
    assert!((a - b).abs() < 1e-14, "{a} != {b}");
}

fn ap(frames: &[Frame], thr: f64) -> f64 {
    evaluate(frames, thr, Overlap::Box3d, &Protocol::official()).ap
}

#[test]
fn a_single_perfect_detection_scores_zero() {
    // n = 1: one threshold, precision slot 0 = 1, slots 1..40 = 0 ⇒ AP = 0 (slot 0 is skipped).
    let f = row(1);
    close(ap(&[f], 0.3), 0.0);
}

#[test]
fn perfect_detections_give_n_minus_one_over_forty() {
    close(ap(&[row(2)], 0.3), 1.0 / 40.0);
    close(ap(&[row(40)], 0.3), 39.0 / 40.0);
    close(ap(&[row(41)], 0.3), 1.0);
    // n = 80: getThresholds keeps 41 of the 80 scores, every precision is 1 ⇒ AP = 1.
    let c = evaluate(&[row(80)], 0.3, Overlap::Box3d, &Protocol::official());
    assert_eq!(c.thresholds.len(), 41);
    close(c.ap, 1.0);
}

#[test]
fn frames_pool_across_sequences() {
    // Two sequences of 20 perfect detections pool to n = 40 (39/40), each alone gives 19/40.
    let mut a = row(20);
    let mut b = row(20);
    a.sequence = "a".into();
    b.sequence = "b".into();
    for d in &mut b.det {
        d.score += 0.5; // distinct from a's scores
    }
    close(ap(&[a.clone(), b.clone()], 0.3), 39.0 / 40.0);
    close(ap(&[a], 0.3), 19.0 / 40.0);
}

/// 40 perfect pairs plus one extra GT/detection pair `extra` whose detection has the top score.
fn with_extra(extra_gt: Option<KittiObject>, extra_det: KittiObject) -> f64 {
    let mut f = row(40);
    f.gt.extend(extra_gt);
    f.det.push(extra_det);
    ap(&[f], 0.3)
}

#[test]
fn ten_points_is_kept_nine_is_ignored() {
    let b = person(-5.0, 0.0);
    // 10 points: a 41st valid GT, found ⇒ n = 41 perfect ⇒ AP = 1.
    close(with_extra(Some(gt(b, 10)), det(b, 0.99)), 1.0);
    // 9 points: ignored; its detection is neither TP nor FP ⇒ as the 40 alone: 39/40.
    close(with_extra(Some(gt(b, 9)), det(b, 0.99)), 39.0 / 40.0);
    // 0 points: ignored too.
    close(with_extra(Some(gt(b, 0)), det(b, 0.99)), 39.0 / 40.0);
}

#[test]
fn negative_points_drop_the_gt_and_its_detection_becomes_a_false_positive() {
    let b = person(-5.0, 0.0);
    close(with_extra(Some(gt(b, -1)), det(b, 0.99)), 39.0 / 41.0);
    // The same detection scoring below every threshold is never counted.
    close(with_extra(Some(gt(b, -1)), det(b, 0.01)), 39.0 / 40.0);
}

#[test]
fn exactly_25_m_is_kept_beyond_is_ignored() {
    // (15, 20): 15² + 20² = 625 exactly, not > 625 ⇒ valid.
    let at = person(15.0, 20.0);
    close(with_extra(Some(gt(at, 50)), det(at, 0.99)), 1.0);
    let (x, y) = (25.0, 0.0);
    close(
        with_extra(Some(gt(person(x, y), 50)), det(person(x, y), 0.99)),
        1.0,
    );
    // A hair beyond: ignored GT, and its detection (also beyond) ignored ⇒ 39/40.
    let beyond = person(25.000001, 0.0);
    close(
        with_extra(Some(gt(beyond, 50)), det(beyond, 0.99)),
        39.0 / 40.0,
    );
}

#[test]
fn detections_beyond_25_m_are_never_false_positives() {
    // No GT there: within range the detection is an FP (39/41), beyond it is ignored (39/40).
    close(with_extra(None, det(person(25.0, 0.0), 0.99)), 39.0 / 41.0);
    close(with_extra(None, det(person(0.0, -25.5), 0.99)), 39.0 / 40.0);
}

#[test]
fn a_detection_beyond_range_does_not_count_for_a_valid_gt() {
    // A GT at 24.9 m (valid) whose only detection sits at 25.1 m with IoU > 0.3. The match goes
    // to the range-ignored detection: the pair is neither TP nor FN, but the GT stays in the
    // recall denominator. With the 40 perfect pairs: n = 41, 40 TP scores, all 40 are thresholds
    // (the 41st recall step is never reached), precision 1 in slots 0..39 ⇒ AP = 39/40, as if it
    // were missed; a valid detection would give 1.
    let g = Box3d {
        cx: 24.9,
        cy: 0.0,
        cz: 0.0,
        l: 0.9,
        w: 0.5,
        h: 1.7,
        rot_z: 0.0,
    };
    let d = Box3d { cx: 25.1, ..g };
    assert!(eval::iou_3d(&g, &d) > 0.3);
    close(with_extra(Some(gt(g, 50)), det(d, 0.99)), 39.0 / 40.0);
}

#[test]
fn non_pedestrian_gt_is_ignored_not_dropped() {
    let b = person(-5.0, 0.0);
    let mut car = gt(b, 50);
    car.kind = "Car".into();
    // Ignored: the detection on it is not an FP ⇒ 39/40 (dropped would give 39/41).
    close(with_extra(Some(car.clone()), det(b, 0.99)), 39.0 / 40.0);
    car.num_points = -1;
    close(with_extra(Some(car), det(b, 0.99)), 39.0 / 41.0);
    // Class names are compared case-insensitively.
    let mut lower = gt(b, 50);
    lower.kind = "pEdEsTrIaN".into();
    close(with_extra(Some(lower), det(b, 0.99)), 1.0);
}

#[test]
fn duplicates_and_score_ties() {
    // A duplicate of a detection is an FP; with the top score it costs 39/40 → 39/41.
    let b = person(-5.0, 0.0);
    let mut f = row(40);
    let top = det(f.gt[0].to_box3d(), 0.99);
    f.det.push(top.clone());
    f.det.push(top);
    close(ap(&[f], 0.3), 39.0 / 41.0);
    // Two detections of one GT with equal scores: whichever matches, the other is an FP at the
    // same score, so the result is the same 39/41 as above.
    let mut f = row(40);
    f.gt.push(gt(b, 50));
    f.det.push(det(b, 0.99));
    f.det.push(det(Box3d { cx: -5.05, ..b }, 0.99));
    // n = 41, TP scores: 40 rows + 0.99 ⇒ 41 thresholds; precision at slot 0 (score 0.99) is
    // 1/2, at slot k ≥ 1 (k+1)/(k+2); envelope: slot k = 41/42 for all k ≤ 40 ⇒ AP = 41/42.
    assert!((ap(&[f], 0.3) - 41.0 / 42.0).abs() < 1e-15);
}

#[test]
fn iou_must_be_strictly_above_the_threshold() {
    // Same unit footprint, heights [0, 3] and [1, 4]: overlap 2, union 4 ⇒ IoU = 0.5 exactly.
    let mut rows = row(40);
    let g = Box3d {
        cx: -5.0,
        cy: 0.0,
        cz: 1.5,
        l: 1.0,
        w: 1.0,
        h: 3.0,
        rot_z: 0.0,
    };
    let d = Box3d { cz: 2.5, ..g };
    assert_eq!(eval::iou_3d(&g, &d), 0.5);
    rows.gt.push(gt(g, 50));
    rows.det.push(det(d, 0.99));
    // IoU 0.3: matched ⇒ n = 41 perfect ⇒ 1. IoU 0.5: not matched ⇒ one FN and one top FP.
    close(ap(&[rows.clone()], 0.3), 1.0);
    let at_half = ap(&[rows], 0.5);
    // n = 41, 40 TPs: thresholds = the 40 TP scores (the 41st step is never reached);
    // precision (k+1)/(k+2) ⇒ envelope 40/41 in slots 0..39 ⇒ AP = 39·(40/41)/40 = 39/41.
    close(at_half, 39.0 / 41.0);
}

#[test]
fn eleven_point_differs_from_forty() {
    // 40 perfect detections: slots 0..39 are 1, slot 40 is 0.
    // Official: 39/40 = 0.975. Eleven-point: slots 0, 4, …, 40 ⇒ 10/11.
    let f = row(40);
    let p = Protocol {
        interpolation: Interpolation::ElevenPoint,
        ..Protocol::official()
    };
    close(
        evaluate(std::slice::from_ref(&f), 0.3, Overlap::Box3d, &p).ap,
        10.0 / 11.0,
    );
    close(ap(&[f], 0.3), 39.0 / 40.0);
}

#[test]
fn no_range_filter_counts_far_objects() {
    // A far GT with a perfect detection: ignored officially (39/40), valid without the filter (1).
    let far = person(40.0, 0.0);
    let mut f = row(40);
    f.gt.push(gt(far, 50));
    f.det.push(det(far, 0.99));
    close(ap(&[f.clone()], 0.3), 39.0 / 40.0);
    let p = Protocol {
        max_range: None,
        ..Protocol::official()
    };
    close(evaluate(&[f], 0.3, Overlap::Box3d, &p).ap, 1.0);
}

#[test]
fn a_range_band_ignores_what_lies_inside_it() {
    // 40 perfect detections (all at least 8 m out), plus a GT at 1 m that nothing detects and a
    // false positive at 1.5 m above every score. Officially both count against the AP; in the
    // band beyond 3 m both are ignored and the 40 perfect ones give 39/40.
    let mut f = row(40);
    f.gt.push(gt(person(1.0, 0.0), 50));
    f.det.push(det(person(0.0, 1.5), 0.999));
    let band = Protocol {
        min_range: Some(3.0),
        ..Protocol::official()
    };
    close(evaluate(std::slice::from_ref(&f), 0.3, Overlap::Box3d, &band).ap, 39.0 / 40.0);
    assert!(ap(&[f], 0.3) < 39.0 / 40.0 - 0.01);
}

#[test]
fn bev_ignores_height() {
    // A detection at the right place but 2 m too high: 3D IoU 0, BEV IoU 1.
    let mut f = row(40);
    let g = person(-5.0, 0.0);
    f.gt.push(gt(g, 50));
    f.det.push(det(Box3d { cz: 2.0, ..g }, 0.99));
    close(
        evaluate(&[f.clone()], 0.7, Overlap::Bev, &Protocol::official()).ap,
        1.0,
    );
    close(ap(&[f], 0.3), 39.0 / 41.0);
}

#[test]
fn counts_follow_the_filters() {
    let mut f = row(3);
    f.gt.push(gt(person(-5.0, 0.0), 9));
    f.gt.push(gt(person(-6.0, 0.0), -1));
    f.gt.push(gt(person(30.0, 0.0), 100));
    f.det.push(det(person(30.0, 0.0), 0.1));
    let mut car = det(person(-7.0, 0.0), 0.2);
    car.kind = "Car".into();
    f.det.push(car);
    let c = evaluate(&[f], 0.3, Overlap::Box3d, &Protocol::official()).counts;
    assert_eq!(
        (
            c.gt,
            c.ignored_gt,
            c.dropped_gt,
            c.det,
            c.ignored_det,
            c.other_det
        ),
        (3, 2, 1, 5, 1, 1)
    );
}

#[test]
fn dontcare_regions_absorb_false_positives() {
    // 40 perfect pairs plus a top-score detection with no GT: an FP ⇒ 39/41. Inside a 3×3×2 m
    // DontCare region it covers 100 % > 30 % of its own volume, so it is not an FP ⇒ 39/40.
    // (Its IoU with the region, 0.765/18 ≈ 0.04, is too small for the region to match it as an
    // ignored GT, so the don't-care rule alone decides.) A dropped (num_points < 0) DontCare
    // line still counts as a region, as in the tool.
    let d = det(person(-5.0, 0.0), 0.99);
    assert!(
        eval::iou_3d(
            &person(-5.0, 0.0),
            &Box3d {
                l: 3.0,
                w: 3.0,
                h: 2.0,
                ..person(-5.0, 0.0)
            }
        ) < 0.3
    );
    let mut region = gt(
        Box3d {
            l: 3.0,
            w: 3.0,
            h: 2.0,
            ..person(-5.0, 0.0)
        },
        0,
    );
    region.kind = "DontCare".into();
    close(with_extra(None, d.clone()), 39.0 / 41.0);
    close(with_extra(Some(region.clone()), d.clone()), 39.0 / 40.0);
    region.num_points = -1;
    close(with_extra(Some(region.clone()), d.clone()), 39.0 / 40.0);
    // A region elsewhere does not help.
    let mut far_region = gt(
        Box3d {
            l: 3.0,
            w: 3.0,
            h: 2.0,
            ..person(-15.0, 5.0)
        },
        0,
    );
    far_region.kind = "DontCare".into();
    close(with_extra(Some(far_region), d), 39.0 / 41.0);
}

#[test]
fn counting_pass_takes_the_largest_iou_not_the_highest_score() {
    // GT A at x = 0, B at x = 0.6 (same y; l = 0.9 along x), C far away. Detections in file
    // order: D1 exactly on A (score 0.8), D2 at x = 0.3 (score 0.9), D3 exactly on C (0.7).
    // IoUs (overlap of lengths / union of lengths): D1–A 1, D2–A 0.6/1.2 = 0.5,
    // D2–B 0.5, D1–B 0.3/1.5 = 0.2 (< 0.3).
    // Pass 1 (highest score): A takes D2 (0.9), B finds nothing (D1 is at 0.2), C takes D3 (0.7);
    // n = 3, TP scores [0.9, 0.7] ⇒ thresholds [0.9, 0.7].
    // At 0.9 only D2 counts: A takes it ⇒ tp 1, fp 0 ⇒ precision 1.
    // At 0.7, largest IoU: A takes D1 (1 > 0.5), B takes D2, C takes D3 ⇒ precision 1.
    // (Highest score would give A D2, leave D1 an FP and B unmatched ⇒ 2/3.)
    // AP = precision[1] / 40 = 1/40.
    let a = person(0.0, 0.0);
    let b = person(0.6, 0.0);
    let c = person(-5.0, 3.0);
    let f = Frame {
        sequence: "s".into(),
        name: "0".into(),
        gt: vec![gt(a, 50), gt(b, 50), gt(c, 50)],
        det: vec![det(a, 0.8), det(person(0.3, 0.0), 0.9), det(c, 0.7)],
    };
    let curve = evaluate(&[f], 0.3, Overlap::Box3d, &Protocol::official());
    assert_eq!(curve.thresholds, vec![0.9, 0.7]);
    assert_eq!(
        (curve.tp.clone(), curve.fp.clone(), curve.fn_.clone()),
        (vec![1, 3], vec![0, 0], vec![2, 0])
    );
    close(curve.ap, 1.0 / 40.0);
}
