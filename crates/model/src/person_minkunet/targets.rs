//! Person-MinkUNet's per-voxel targets (docs/model.md): nearest box centre, a soft classification
//! target, and the matched box's encoding on foreground voxels.

use data_jrdb::{Batch, Box3d};

use super::box_coder::BoxCoder;
use super::config::TargetVariant;

/// Targets of one batch, on the CPU; the foreground rows are listed in `fg`.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct VoxelTargets {
    /// Soft classification target of every voxel, in [0, 1].
    pub cls: Vec<f32>,
    /// Foreground voxel rows (`cls > 0`), ascending.
    pub fg: Vec<usize>,
    /// Centre offsets of the foreground rows, F×3.
    pub offset: Vec<f32>,
    /// Log-dimensions of the foreground rows, F×3.
    pub log_dims: Vec<f32>,
    /// Heading bin of the foreground rows, F.
    pub bin: Vec<i64>,
    /// Residuals for every bin of the foreground rows, F×bins.
    pub residuals: Vec<f32>,
    /// sin θ and cos θ of the foreground rows' headings (the coder's frame), F×2.
    pub sin_cos: Vec<f32>,
    /// 1 where the foreground row's person faces the sensor, else 0, F.
    pub facing: Vec<f32>,
}

/// `t_c = in · (1 − clamp(d, 0, 1))` for voxel centre `v` and box `b` (docs/model.md): `in` is
/// whether `v` lies in `b` enlarged by ε in l, w and h; `d` the centre distance over half the
/// (enlarged) diagonal, in the code's or the paper's form.
pub fn soft_target(v: [f64; 3], b: &Box3d, epsilon: f64, variant: TargetVariant) -> f64 {
    let grown = Box3d { l: b.l + epsilon, w: b.w + epsilon, h: b.h + epsilon, ..*b };
    if !grown.contains(v) {
        return 0.0;
    }
    let dist = ((v[0] - b.cx).powi(2) + (v[1] - b.cy).powi(2) + (v[2] - b.cz).powi(2)).sqrt();
    let half_diag = match variant {
        TargetVariant::Code => 0.5 * (grown.l.powi(2) + grown.w.powi(2) + grown.h.powi(2)).sqrt(),
        TargetVariant::Paper => 0.5 * ((b.l.powi(2) + b.w.powi(2) + b.h.powi(2)).sqrt() + epsilon),
    };
    1.0 - (dist / half_diag).clamp(0.0, 1.0)
}

/// Assigns every voxel of `batch` to the box of its sample whose centre is nearest to the voxel's
/// point (its feature), and computes the targets from the voxel centre.
pub fn assign(batch: &Batch, coder: &BoxCoder, epsilon: f64, variant: TargetVariant) -> VoxelTargets {
    let m = batch.num_voxels();
    let mut t = VoxelTargets { cls: vec![0.0; m], ..Default::default() };
    for (s, boxes) in batch.boxes.iter().enumerate() {
        if boxes.is_empty() {
            continue;
        }
        for row in batch.rows(s) {
            let p: [f64; 3] = batch.point(row).map(f64::from);
            let v: [f64; 3] = batch.centre(row).map(f64::from);
            let nearest = boxes
                .iter()
                .min_by(|a, b| centre_dist2(p, a).total_cmp(&centre_dist2(p, b)))
                .expect("boxes is not empty");
            let tc = soft_target(v, nearest, epsilon, variant);
            if tc <= 0.0 {
                continue;
            }
            t.cls[row] = tc as f32;
            t.fg.push(row);
            let e = coder.encode(nearest, v);
            t.offset.extend(e.offset.map(|x| x as f32));
            t.log_dims.extend(e.log_dims.map(|x| x as f32));
            t.bin.push(e.bin as i64);
            t.residuals.extend(e.residuals.iter().map(|&x| x as f32));
            t.sin_cos.extend([e.theta.sin() as f32, e.theta.cos() as f32]);
            t.facing.push(if e.faces_sensor { 1.0 } else { 0.0 });
        }
    }
    t
}

fn centre_dist2(p: [f64; 3], b: &Box3d) -> f64 {
    (p[0] - b.cx).powi(2) + (p[1] - b.cy).powi(2) + (p[2] - b.cz).powi(2)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn batch_of(points: &[[f32; 3]], boxes: Vec<Box3d>) -> Batch {
        let vs = [0.05, 0.05, 0.1];
        let mut b = Batch { voxel_size: vs, offsets: vec![0, points.len()], boxes: vec![boxes], ..Default::default() };
        b.frames.push(("s".into(), "000000".into()));
        b.num_points.push(vec![]);
        for p in points {
            // Points placed at voxel centres, so point and centre coincide.
            let c = [0, 1, 2].map(|k| (p[k] / vs[k]).round() as i32);
            b.coords.push([0, c[0], c[1], c[2]]);
            b.features.extend_from_slice(p);
            b.centres.extend([0, 1, 2].map(|k| c[k] as f32 * vs[k]));
        }
        b
    }

    #[test]
    fn centre_voxel_is_one_outside_is_zero() {
        let person = Box3d { cx: 1.0, cy: 2.0, cz: 0.1, l: 0.6, w: 0.4, h: 1.6, rot_z: 0.7 };
        let other = Box3d { cx: 3.0, cy: 2.0, cz: 0.1, ..person };
        let pts = [[1.0, 2.0, 0.1], [3.0, 2.0, 0.1], [5.0, 5.0, 0.0], [1.0, 2.0, 1.2], [2.0, 2.0, 0.1]];
        let b = batch_of(&pts, vec![person, other]);
        let coder = BoxCoder::new([0.9, 0.5, 1.7], 12);
        let t = assign(&b, &coder, 0.2, TargetVariant::Code);
        assert!((t.cls[0] - 1.0).abs() < 1e-6 && (t.cls[1] - 1.0).abs() < 1e-6, "{:?}", t.cls);
        assert_eq!(&t.cls[2..], &[0.0, 0.0, 0.0], "far, above the head, between the people");
        assert_eq!(t.fg, vec![0, 1]);
        assert_eq!(t.bin.len(), 2);
        assert_eq!(t.residuals.len(), 24);
        // Voxel 1 is matched to the second person: its offset is (0, 0, 0) up to the voxel grid.
        assert!(t.offset[3..6].iter().all(|x| x.abs() < 1e-5));
        assert!((t.log_dims[0] - (0.6f32 / 0.9).ln()).abs() < 1e-6);
    }

    #[test]
    fn soft_target_matches_hand_values_in_both_variants() {
        let b = Box3d { cx: 0.0, cy: 0.0, cz: 0.0, l: 0.8, w: 0.4, h: 1.6, rot_z: 0.0 };
        let v = [0.3, 0.0, 0.4]; // inside; distance 0.5
        let code = 1.0 - 0.5 / (0.5 * (1.0f64 + 0.36 + 3.24).sqrt());
        let paper = 1.0 - 0.5 / (0.5 * ((0.64f64 + 0.16 + 2.56).sqrt() + 0.2));
        assert!((soft_target(v, &b, 0.2, TargetVariant::Code) - code).abs() < 1e-12);
        assert!((soft_target(v, &b, 0.2, TargetVariant::Paper) - paper).abs() < 1e-12);
        // Inside the enlarged box only (x = 0.45 > l/2 = 0.4 but < 0.5): still foreground.
        assert!(soft_target([0.45, 0.0, 0.0], &b, 0.2, TargetVariant::Code) > 0.0);
        assert_eq!(soft_target([0.55, 0.0, 0.0], &b, 0.2, TargetVariant::Code), 0.0);
        // The box is rotated: a point along its width axis after a quarter turn.
        let r = Box3d { rot_z: std::f64::consts::FRAC_PI_2, ..b };
        assert_eq!(soft_target([0.45, 0.0, 0.0], &r, 0.2, TargetVariant::Code), 0.0);
        assert!(soft_target([0.0, 0.45, 0.0], &r, 0.2, TargetVariant::Code) > 0.0);
    }

    #[test]
    fn no_boxes_means_no_foreground() {
        let b = batch_of(&[[0.0, 0.0, 0.0], [1.0, 1.0, 0.0]], vec![]);
        let t = assign(&b, &BoxCoder::new([0.9, 0.5, 1.7], 12), 0.2, TargetVariant::Code);
        assert_eq!(t.cls, vec![0.0, 0.0]);
        assert!(t.fg.is_empty());
    }
}
