//! The radial calibration: how far a run's boxes fall short of people along the sensor's ray,
//! measured on frames it is not scored on, and the `model.post.radial_shift` that corrects it.
//!
//! A LiDAR sees a person's near side, so every voxel's offset to the centre points away from the
//! sensor, and a network that under-fits those offsets puts the centre a few centimetres short,
//! whatever the range (docs/recipe.md §6). The bias is a property of trained weights, so it is
//! measured per run: the median error along the ray of matched detections, raw (shift 0).

use anyhow::{Result, ensure};
use data_jrdb::{Split, stats};
use eval::Protocol;

use crate::backend::BackendKind;
use crate::checkpoint::Slot;
use crate::infer::detect_run_split;
use crate::run_dir::{RunDir, write_atomic};
use crate::validate::{FrameResult, MATCH_MIN_SCORE, MATCH_RADIUS, matched_by_centre};

/// Fewer matches than this are too few to calibrate from.
pub const MIN_MATCHES: usize = 100;
/// The range bands the measurement is reported in (metres, BEV).
pub const BANDS: [(f64, f64); 5] = [(0.0, 5.0), (5.0, 10.0), (10.0, 15.0), (15.0, 20.0), (20.0, 25.0)];

/// What to calibrate on.
#[derive(Debug, Clone)]
pub struct CalibrateOptions {
    /// The split (frames the run is not scored on: its training split, or another tree's).
    pub split: Split,
    /// The checkpoint (default: latest).
    pub checkpoint: Option<Slot>,
    /// Backend override.
    pub backend: Option<BackendKind>,
    /// Run on this JRDB-format tree instead of the run's own data.
    pub data_root: Option<std::path::PathBuf>,
    /// Store the shift in the run's `config.toml`.
    pub write: bool,
    /// Progress bar on stderr.
    pub verbose: bool,
}

/// The median error along the ray in one range band.
#[derive(Debug, Clone, PartialEq)]
pub struct BandBias {
    /// The band, metres.
    pub range: (f64, f64),
    /// Matched people in it.
    pub matched: usize,
    /// Median signed error (m; negative: short of the person, toward the sensor).
    pub median: f64,
}

/// A run's centres' bias along the sensor's ray.
#[derive(Debug, Clone, PartialEq)]
pub struct RadialBias {
    /// Matched people.
    pub matched: usize,
    /// Median signed error over all of them (m).
    pub median: f64,
    /// The same per band.
    pub bands: Vec<BandBias>,
    /// `-median`, rounded to the millimetre: what `model.post.radial_shift` should be.
    pub shift: f64,
}

impl std::fmt::Display for RadialBias {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        writeln!(f, "centres along the sensor's ray, median error of {} matched people: {:+.3} m", self.matched, self.median)?;
        for b in &self.bands {
            writeln!(f, "  {:>2.0}–{:<2.0} m  {:>6} matched  {:+.3} m", b.range.0, b.range.1, b.matched, b.median)?;
        }
        write!(f, "model.post.radial_shift = {:.3}", self.shift)
    }
}

/// `(range, error along the ray)` of every pair [`matched_by_centre`] makes.
pub fn radial_errors(frames: &[FrameResult], protocol: &Protocol) -> Vec<(f64, f64)> {
    let mut out = Vec::new();
    for f in frames {
        for (d, g) in matched_by_centre(f, protocol) {
            let r = g.bev_range();
            if r > 0.0 {
                out.push((r, ((d.bbox.cx - g.cx) * g.cx + (d.bbox.cy - g.cy) * g.cy) / r));
            }
        }
    }
    out
}

/// The bias of `errors` (from [`radial_errors`]), overall and per band.
pub fn radial_bias(errors: &[(f64, f64)]) -> Option<RadialBias> {
    let median = |v: Vec<f64>| (!v.is_empty()).then(|| stats::median(v));
    let all = median(errors.iter().map(|e| e.1).collect())?;
    let bands = BANDS
        .iter()
        .filter_map(|&(lo, hi)| {
            let sel: Vec<f64> = errors.iter().filter(|e| e.0 >= lo && e.0 < hi).map(|e| e.1).collect();
            let matched = sel.len();
            median(sel).map(|m| BandBias { range: (lo, hi), matched, median: m })
        })
        .collect();
    Some(RadialBias { matched: errors.len(), median: all, bands, shift: (-all * 1000.0).round() / 1000.0 })
}

/// Measures the run's raw bias (its own shift set to 0) on `opts.split` and, with `opts.write`,
/// stores the shift that corrects it in the run's `config.toml` (nothing else changes).
pub fn calibrate(run: &RunDir, opts: &CalibrateOptions) -> Result<RadialBias> {
    let stored = run.config()?;
    let mut cfg = stored.clone();
    cfg.model.post_mut().radial_shift = 0.0;
    // The centres are what is measured; the facing stage only turns headings.
    cfg.model.post_mut().facing_stage = false;
    let slot = opts.checkpoint.unwrap_or(Slot::Latest);
    let (detector, _, frames) = detect_run_split(run, cfg, opts.data_root.as_deref(), opts.backend, slot, opts.split, opts.verbose)?;
    let cfg = detector.config();
    let errors = radial_errors(&frames, &cfg.eval.protocol());
    ensure!(
        errors.len() >= MIN_MATCHES,
        "{} frames of {} gave {} matched people (score ≥ {MATCH_MIN_SCORE}, centre within {MATCH_RADIUS} m), fewer than the {MIN_MATCHES} a calibration needs",
        frames.len(),
        cfg.data.root.display(),
        errors.len()
    );
    let bias = radial_bias(&errors).expect("at least MIN_MATCHES errors");
    if opts.write {
        let mut new = stored;
        new.model.post_mut().radial_shift = bias.shift;
        write_atomic(&run.config_file(), new.to_toml()?.as_bytes())?;
    }
    Ok(bias)
}

#[cfg(test)]
mod tests {
    use super::*;
    use data_jrdb::Box3d;
    use eval::jrdb::Detection;

    fn person(x: f64, y: f64) -> Box3d {
        Box3d { cx: x, cy: y, cz: 0.9, l: 0.5, w: 0.6, h: 1.7, rot_z: 0.0 }
    }

    /// Hand-made: a person 5 m out at (3, 4) and a detection 0.1 m short along the ray and 0.05 m
    /// across it; a second person 12 m out along −y found 0.04 m beyond; a low score, a person
    /// with too few points and one beyond 25 m are left out.
    #[test]
    fn errors_along_the_ray_by_hand() {
        let det = |x: f64, y: f64, score: f64| Detection { bbox: person(x, y), score };
        let (ux, uy) = (0.6, 0.8);
        let frame = FrameResult {
            sequence: "s".into(),
            name: "000000".into(),
            gt: vec![person(3.0, 4.0), person(0.0, -12.0), person(8.0, 0.0), person(30.0, 0.0)],
            num_points: vec![200, 40, 5, 50],
            ignored: vec![],
            detections: vec![
                det(3.0 - 0.1 * ux - 0.05 * uy, 4.0 - 0.1 * uy + 0.05 * ux, 0.9),
                det(0.0, -12.04, 0.8),
                det(8.0, 0.0, 0.7),
                det(30.0, 0.0, 0.6),
                det(0.0, -12.0, 0.2),
            ],
        };
        let protocol = Protocol::official();
        let e = radial_errors(&[frame], &protocol);
        assert_eq!(e.len(), 2, "{e:?}");
        assert!((e[0].0 - 5.0).abs() < 1e-12 && (e[0].1 + 0.1).abs() < 1e-12, "{e:?}");
        assert!((e[1].0 - 12.0).abs() < 1e-12 && (e[1].1 - 0.04).abs() < 1e-12, "{e:?}");
        let b = radial_bias(&e).unwrap();
        assert!((b.median + 0.03).abs() < 1e-12 && b.shift == 0.03, "{b:?}");
        assert_eq!(b.bands.iter().map(|x| (x.range.0, x.matched)).collect::<Vec<_>>(), [(5.0, 1), (10.0, 1)]);
        assert!(radial_bias(&[]).is_none());
    }
}
