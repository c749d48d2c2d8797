//! Test-time turns: the network run on the cloud turned by half or quarter turns about the
//! sensor's vertical axis, each pass's boxes turned back, and the passes fused into one set.
//!
//! A trained network's answer still moves with the cloud's heading (its kernels are not
//! symmetric), although it was trained on every heading; averaging over turns removes that
//! variance. Half and quarter turns map the voxel grid onto itself, so every pass sees the same
//! points in the same cells, turned.

use data_jrdb::{Batch, Box3d};
use std::collections::HashMap;

use eval::nms::BoxMean;

use crate::detector::Detections;
use crate::person_minkunet::box_coder::wrap_angle;

/// A turn of the cloud about z by `quarters` quarter turns, counter-clockwise (x toward y).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct GridTurn {
    quarters: u8,
}

impl GridTurn {
    /// The turns of `passes` equal steps: 1 → none, 2 → 0° and 180°, 4 → every quarter turn.
    pub fn passes(passes: usize) -> Result<Vec<GridTurn>, String> {
        let quarters: &[u8] = match passes {
            1 => &[0],
            2 => &[0, 2],
            4 => &[0, 1, 2, 3],
            n => return Err(format!("model.post.test_time_turns must be 1, 2 or 4 (turns that map the voxel grid onto itself), got {n}")),
        };
        Ok(quarters.iter().map(|&quarters| GridTurn { quarters }).collect())
    }

    /// Whether it leaves the cloud as it is.
    pub fn is_identity(self) -> bool {
        self.quarters == 0
    }

    /// A point turned; exact (sign changes and swaps), so voxels map to voxels.
    pub fn point(self, [x, y, z]: [f32; 3]) -> [f32; 3] {
        match self.quarters {
            0 => [x, y, z],
            1 => [-y, x, z],
            2 => [-x, -y, z],
            _ => [y, -x, z],
        }
    }

    /// A voxel `(b, x, y, z)` of the lattice turned, as its points turn.
    pub fn voxel(self, [b, i, j, k]: [i32; 4]) -> [i32; 4] {
        match self.quarters {
            0 => [b, i, j, k],
            1 => [b, -j, i, k],
            2 => [b, -i, -j, k],
            _ => [b, j, -i, k],
        }
    }

    /// A box found in the turned cloud, turned back into the cloud's own frame (heading in (−π, π]).
    pub fn undo(self, b: &Box3d) -> Box3d {
        let (cx, cy) = match self.quarters {
            0 => return *b,
            1 => (b.cy, -b.cx),
            2 => (-b.cx, -b.cy),
            _ => (-b.cy, b.cx),
        };
        let rot_z = wrap_angle(b.rot_z - f64::from(self.quarters) * std::f64::consts::FRAC_PI_2);
        Box3d { cx, cy, rot_z, ..*b }
    }
}

/// The indices of the points within `radius` in bird's-eye view of the centre of some box of
/// `around`, ascending: what a turned pass focused on the first pass's proposals looks at.
pub fn focus(points: &[[f32; 3]], around: &[Box3d], radius: f64) -> Vec<usize> {
    let Some(first) = around.first() else { return Vec::new() };
    // A grid over the boxes' extent with cells no smaller than the radius (so a point's 3 × 3
    // cells hold every box within reach) and at most 256 a side.
    let (lo, hi) = around.iter().fold(((first.cx, first.cy), (first.cx, first.cy)), |(lo, hi), b| {
        ((lo.0.min(b.cx), lo.1.min(b.cy)), (hi.0.max(b.cx), hi.1.max(b.cy)))
    });
    let cell = radius.max((hi.0 - lo.0).max(hi.1 - lo.1) / 256.0).max(f64::MIN_POSITIVE);
    let (nx, ny) = (((hi.0 - lo.0) / cell) as usize + 1, ((hi.1 - lo.1) / cell) as usize + 1);
    let mut grid: Vec<Vec<(f64, f64)>> = vec![Vec::new(); nx * ny];
    for b in around {
        grid[((b.cx - lo.0) / cell) as usize * ny + ((b.cy - lo.1) / cell) as usize].push((b.cx, b.cy));
    }
    let r2 = radius * radius;
    let near = |x: f64, y: f64| {
        let (i, j) = (((x - lo.0) / cell).floor(), ((y - lo.1) / cell).floor());
        if i < -1.0 || j < -1.0 || i > nx as f64 || j > ny as f64 {
            return false;
        }
        let (i, j) = (i as i64, j as i64);
        (i - 1..=i + 1)
            .filter(|&a| (0..nx as i64).contains(&a))
            .flat_map(|a| (j - 1..=j + 1).filter(|&b| (0..ny as i64).contains(&b)).map(move |b| a as usize * ny + b as usize))
            .flat_map(|k| &grid[k])
            .any(|&(cx, cy)| (x - cx).powi(2) + (y - cy).powi(2) <= r2)
    };
    (0..points.len()).filter(|&i| near(f64::from(points[i][0]), f64::from(points[i][1]))).collect()
}

/// The voxels `rows[s]` of each sample `s` of `batch`, turned: what voxelizing the turned cloud
/// gives (`round(x / size)` is odd in x, so a voxel's turned points fall in its turned cell),
/// without voxelizing it again. Samples without rows are left out; the second value lists the
/// samples kept, in order. The batch holds no boxes or clouds: it is for the network alone.
pub fn turned_batch(batch: &Batch, rows: &[Vec<usize>], turn: GridTurn) -> (Batch, Vec<usize>) {
    let kept: Vec<usize> = (0..batch.len()).filter(|&s| !rows[s].is_empty()).collect();
    let mut out = Batch { offsets: vec![0], voxel_size: batch.voxel_size, ..Default::default() };
    for (b, &s) in kept.iter().enumerate() {
        for &r in &rows[s] {
            let [_, i, j, k] = batch.coords[r];
            out.coords.push(turn.voxel([b as i32, i, j, k]));
            out.features.extend(turn.point(batch.point(r)));
            out.centres.extend(turn.point(batch.centre(r)));
        }
        out.offsets.push(out.coords.len());
        out.frames.push(batch.frames[s].clone());
        out.boxes.push(Vec::new());
        out.num_points.push(Vec::new());
        out.ignored.push(Vec::new());
        out.clouds.push(Vec::new());
    }
    (out, kept)
}

/// Fuses the detections of several passes over one cloud (weighted box fusion, one box per pass
/// per person): walking every pass's boxes by descending score, a box joins the nearest person
/// whose first (best) box lies within `radius` in bird's-eye view and who has no box of its pass
/// yet, else it is a new person. A person's box is the score-weighted mean of theirs (with `axis`,
/// the heading their mean axis, as box voting); their score the sum of their boxes' scores divided
/// by the number of passes. A person every pass finds keeps their mean score; a box one pass of
/// four draws keeps a quarter of its own. Two boxes of one pass are never one person: box voting
/// may leave a pass's kept boxes closer together than its NMS radius. Best first.
pub fn fuse(passes: &[Detections], radius: f64, axis: bool) -> Detections {
    if passes.len() == 1 {
        return passes[0].clone();
    }
    let mut all: Vec<(f32, usize, &Box3d)> = passes
        .iter()
        .enumerate()
        .flat_map(|(k, d)| d.scores.iter().zip(&d.boxes).map(move |(&s, b)| (s, k, b)))
        .filter(|(s, ..)| !s.is_nan())
        .collect();
    all.sort_by(|a, b| b.0.total_cmp(&a.0));
    struct Person<'a> {
        first: &'a Box3d,
        mean: BoxMean,
        score: f32,
        passes: Vec<bool>,
    }
    let cell = |b: &Box3d| ((b.cx / radius).floor() as i64, (b.cy / radius).floor() as i64);
    let mut people: Vec<Person> = Vec::new();
    let mut grid: HashMap<(i64, i64), Vec<usize>> = HashMap::new();
    for (s, k, b) in all {
        let (x, y) = cell(b);
        let join = (-1..=1)
            .flat_map(|dx| (-1..=1).map(move |dy| (x + dx, y + dy)))
            .filter_map(|key| grid.get(&key))
            .flatten()
            .filter(|&&i| !people[i].passes[k])
            .map(|&i| ((people[i].first.cx - b.cx).hypot(people[i].first.cy - b.cy), i))
            .filter(|&(d, _)| d <= radius)
            .min_by(|p, q| p.0.total_cmp(&q.0).then(p.1.cmp(&q.1)));
        let i = match join {
            Some((_, i)) => i,
            None => {
                grid.entry((x, y)).or_default().push(people.len());
                people.push(Person { first: b, mean: BoxMean::default(), score: 0.0, passes: vec![false; passes.len()] });
                people.len() - 1
            }
        };
        let p = &mut people[i];
        // A zero score still places the box of a person nobody scored above zero.
        p.mean.add(b, f64::from(s).max(1e-12));
        p.score += s;
        p.passes[k] = true;
    }
    let n = passes.len() as f32;
    let mut fused: Vec<(f32, Box3d)> = people.iter().map(|p| (p.score / n, p.mean.mean(p.first.rot_z, axis))).collect();
    fused.sort_by(|a, b| b.0.total_cmp(&a.0));
    Detections { boxes: fused.iter().map(|f| f.1).collect(), scores: fused.iter().map(|f| f.0).collect() }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn at(x: f64, y: f64, rot_z: f64) -> Box3d {
        Box3d { cx: x, cy: y, cz: -0.2, l: 0.8, w: 0.5, h: 1.7, rot_z }
    }

    #[test]
    fn a_turned_box_turns_back_to_where_it_was() {
        let b = at(3.0, 1.0, 2.5);
        let p = [3.0f32, 1.0, -0.2];
        for turn in GridTurn::passes(4).unwrap() {
            let k = f64::from(turn.quarters) * std::f64::consts::FRAC_PI_2;
            // The box as it lies in the turned cloud: its centre where the turned point lies.
            let seen = Box3d { rot_z: b.rot_z + k, ..b.rotated_z(k) };
            let q = turn.point(p);
            assert!((seen.cx - q[0] as f64).abs() < 1e-12 && (seen.cy - q[1] as f64).abs() < 1e-12, "{turn:?}");
            let back = turn.undo(&Box3d { cx: q[0] as f64, cy: q[1] as f64, ..seen });
            assert_eq!((back.cx, back.cy, back.cz, back.l, back.w, back.h), (3.0, 1.0, -0.2, 0.8, 0.5, 1.7), "{turn:?}");
            assert!((back.rot_z - 2.5).abs() < 1e-12 && back.rot_z > -std::f64::consts::PI && back.rot_z <= std::f64::consts::PI, "{turn:?}: {}", back.rot_z);
        }
        assert!(GridTurn::passes(3).is_err() && GridTurn::passes(0).is_err());
        assert_eq!(GridTurn::passes(2).unwrap().iter().map(|t| t.quarters).collect::<Vec<_>>(), vec![0, 2]);
    }

    #[test]
    fn focus_keeps_exactly_the_points_within_the_radius_of_a_box() {
        // A line of points every 0.25 m along x at y = 0.5, and boxes at x = 0 and x = 10.
        let cloud: Vec<[f32; 3]> = (-20..=60).map(|i| [i as f32 * 0.25, 0.5, 0.1]).collect();
        let boxes = [at(0.0, 0.0, 0.0), at(10.0, 0.0, 0.0)];
        // Within 1.3 m of (0, 0) or (10, 0) at y = 0.5: |x| ≤ 1.2 or |x − 10| ≤ 1.2.
        let want: Vec<usize> = (0..cloud.len()).filter(|&i| cloud[i][0].abs() <= 1.2 || (cloud[i][0] - 10.0).abs() <= 1.2).collect();
        assert_eq!(want.len(), 18);
        assert_eq!(focus(&cloud, &boxes, 1.3), want);
        assert!(focus(&cloud, &[], 1.3).is_empty());
        assert_eq!(focus(&cloud, &boxes, 100.0), (0..cloud.len()).collect::<Vec<_>>());
        // A radius far below the boxes' spread (the grid's cells grow, never its size).
        assert_eq!(focus(&cloud, &boxes, 1e-9), Vec::<usize>::new());
        assert_eq!(focus(&[[0.0, 0.0, 0.0], [10.0, 1e-10, 0.0]], &boxes, 1e-9), vec![0, 1]);
    }

    #[test]
    fn a_turned_batch_is_the_turned_cloud_voxelized() {
        use data_jrdb::{Frame, SampleConfig, VoxelConfig, collate, prepare};
        use rand::SeedableRng;
        // Points on both sides of every axis, some on cell boundaries (x = 0.1 = half a voxel).
        let cloud: Vec<[f32; 3]> = (0..200).map(|i| { let t = i as f32 * 0.37; [(t.sin() * 7.0 * 10.0).round() / 10.0 + 0.1 * (i % 3) as f32, t.cos() * 5.3 - 0.1, (t * 0.3).sin()] }).collect();
        let batch_of = |points: Vec<[f32; 3]>| {
            let frame = Frame { sequence: "s".into(), name: "f".into(), n_upper: points.len(), points, dropped_non_finite: 0, boxes: Vec::new(), num_points: Vec::new(), label_ids: Vec::new(), ignored: Vec::new() };
            let cfg = SampleConfig { voxel: VoxelConfig { voxel_size: [0.2; 3], ..Default::default() }, ..SampleConfig::eval() };
            collate(vec![prepare(frame, &cfg, &mut rand_chacha::ChaCha8Rng::seed_from_u64(0))], [0.2; 3])
        };
        let whole = batch_of(cloud.clone());
        for turn in GridTurn::passes(4).unwrap() {
            let again = batch_of(cloud.iter().map(|&p| turn.point(p)).collect());
            let (turned, kept) = turned_batch(&whole, &[(0..whole.num_voxels()).collect()], turn);
            assert_eq!(kept, vec![0]);
            assert_eq!((&turned.coords, &turned.features, &turned.centres, &turned.offsets), (&again.coords, &again.features, &again.centres, &again.offsets), "{turn:?}");
        }
        let (none, kept) = turned_batch(&whole, &[Vec::new()], GridTurn::passes(2).unwrap()[1]);
        assert!(kept.is_empty() && none.is_empty() && none.num_voxels() == 0);
    }

    #[test]
    fn fusion_averages_scores_over_passes_and_boxes_by_score() {
        // Pass 0 sees a person at (5, 0) and a false box at (0, 8); pass 1 sees the person 0.2 m
        // away and a neighbour 0.4 m from them (within the radius, but pass 1 has its box there).
        let passes = [
            Detections { boxes: vec![at(5.0, 0.0, 0.0), at(0.0, 8.0, 1.0)], scores: vec![0.8, 0.6] },
            Detections { boxes: vec![at(5.2, 0.0, 0.0), at(5.0, 0.4, 0.0)], scores: vec![0.4, 0.3] },
        ];
        let d = fuse(&passes, 0.6, true);
        // The person: (0.8 + 0.4) / 2; the lone box: 0.6 / 2; the neighbour: 0.3 / 2.
        let want = [0.6, 0.3, 0.15];
        assert!(d.scores.iter().zip(want).all(|(s, w)| (s - w).abs() < 1e-6), "{:?}", d.scores);
        // Centre: (0.8·5 + 0.4·5.2) / 1.2.
        assert!((d.boxes[0].cx - 6.08 / 1.2).abs() < 1e-6 && d.boxes[0].cy.abs() < 1e-9, "{:?}", d.boxes[0]);
        let lone = d.boxes[1];
        assert!(lone.cx.abs() < 1e-9 && (lone.cy - 8.0).abs() < 1e-9 && (lone.rot_z - 1.0).abs() < 1e-9, "{lone:?}");
        assert!((d.boxes[2].cx - 5.0).abs() < 1e-9 && (d.boxes[2].cy - 0.4).abs() < 1e-9, "{:?}", d.boxes[2]);
        // One pass is itself.
        assert_eq!(fuse(&passes[..1], 0.6, true), passes[0]);
    }

    #[test]
    fn a_box_joins_the_nearest_person_its_pass_has_not_reached() {
        // Pass 0 keeps two neighbours 0.5 m apart (box voting can leave them that close); pass 1
        // sees each 0.05 m off. Each of pass 1's boxes joins its own neighbour.
        let passes = [
            Detections { boxes: vec![at(-2.0, 11.6, 0.0), at(-2.5, 11.6, 0.0)], scores: vec![0.8, 0.4] },
            Detections { boxes: vec![at(-2.05, 11.6, 0.0), at(-2.45, 11.6, 0.0)], scores: vec![0.85, 0.6] },
        ];
        let d = fuse(&passes, 0.6, true);
        assert_eq!(d.boxes.len(), 2);
        assert!((d.scores[0] - 0.825).abs() < 1e-6 && (d.scores[1] - 0.5).abs() < 1e-6, "{:?}", d.scores);
        assert!((d.boxes[0].cx - (-0.8 * 2.0 - 0.85 * 2.05) / 1.65).abs() < 1e-9, "{:?}", d.boxes[0]);
        assert!((d.boxes[1].cx - (-0.4 * 2.5 - 0.6 * 2.45) / 1.0).abs() < 1e-9, "{:?}", d.boxes[1]);
    }
}
