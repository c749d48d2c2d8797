//! The box-convention check (JRDB's own tools disagree on the heading's sign, docs/data.md):
//! recount the points inside each labelled box under the `Box3d` convention and under the
//! alternatives, and see which agrees with `num_points`.

use rayon::prelude::*;
use serde::Serialize;

use crate::box3d::Box3d;
use crate::dataset::Dataset;
use crate::error::Result;

/// The box readings compared.
pub const CONVENTIONS: [&str; 3] = ["box3d (l along R(+rot_z)x)", "mirrored (l along R(-rot_z)x)", "l and w swapped"];

/// How one convention's recounts compare with `num_points`.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct Agreement {
    /// Which reading.
    pub convention: String,
    /// Boxes compared.
    pub boxes: usize,
    /// Boxes whose recount equals `num_points`.
    pub exact: usize,
    /// Boxes within 10 % (or 2 points) of `num_points`.
    pub close: usize,
    /// Mean |recount − num_points|.
    pub mean_abs_diff: f64,
}

fn variants(b: &Box3d) -> [Box3d; 3] {
    [*b, Box3d { rot_z: -b.rot_z, ..*b }, Box3d { l: b.w, w: b.l, ..*b }]
}

/// Checks every `stride`-th frame of the dataset.
pub fn check(ds: &Dataset, stride: usize) -> Result<Vec<Agreement>> {
    let diffs: Vec<Vec<([i64; 3], i64)>> = (0..ds.len())
        .step_by(stride.max(1))
        .collect::<Vec<_>>()
        .into_par_iter()
        .map(|i| {
            let f = ds.load(i)?;
            Ok(f.boxes
                .iter()
                .zip(&f.num_points)
                .filter(|(_, n)| **n >= 0)
                .map(|(b, &n)| (variants(b).map(|v| v.count_inside(&f.points) as i64 - n), n))
                .collect())
        })
        .collect::<Result<_>>()?;
    Ok((0..3)
        .map(|k| {
            let mut a = Agreement { convention: CONVENTIONS[k].to_string(), ..Default::default() };
            let mut sum = 0.0;
            for (d, n) in diffs.iter().flatten() {
                a.boxes += 1;
                a.exact += (d[k] == 0) as usize;
                sum += d[k].abs() as f64;
                a.close += (d[k].abs() as f64 <= (0.1 * *n as f64).max(2.0)) as usize;
            }
            a.mean_abs_diff = if a.boxes > 0 { sum / a.boxes as f64 } else { 0.0 };
            a
        })
        .collect())
}
