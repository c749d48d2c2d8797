//! The standard evaluation: AP3D and APBEV at 0.3/0.5/0.7, per-sequence AP3D, as a table, as JSON
//! with fixed keys, and the PR points as CSV.

use std::collections::BTreeMap;
use std::path::Path;

use rayon::prelude::*;
use serde_json::{Value, json};

use crate::ap::{Counts, Curve, Frame, IOU_THRESHOLDS, Interpolation, Overlap, Protocol, evaluate};
use crate::error::{EvalError, Result};

/// Everything the CLI prints: overall and per-sequence curves under one protocol.
#[derive(Debug, Clone)]
pub struct Report {
    /// The protocol used (official unless asked otherwise).
    pub protocol: Protocol,
    /// 3D AP curves at [`IOU_THRESHOLDS`], all sequences pooled (the official number is `ap3d[0].ap`).
    pub ap3d: Vec<Curve>,
    /// BEV AP curves at [`IOU_THRESHOLDS`] (**not an official JRDB metric**).
    pub apbev: Vec<Curve>,
    /// Per sequence: 3D AP curves at [`IOU_THRESHOLDS`].
    pub per_sequence: BTreeMap<String, Vec<Curve>>,
    /// Counts over all frames.
    pub counts: Counts,
}

fn key(t: f64) -> String {
    format!("{t:.1}")
}

impl Report {
    /// Runs every evaluation of the report (in parallel).
    pub fn compute(frames: &[Frame], protocol: &Protocol) -> Report {
        let mut seqs: BTreeMap<&str, Vec<&Frame>> = BTreeMap::new();
        for f in frames {
            seqs.entry(f.sequence.as_str()).or_default().push(f);
        }
        let mut jobs: Vec<(Option<&str>, Overlap, f64)> = Vec::new();
        for kind in [Overlap::Box3d, Overlap::Bev] {
            jobs.extend(IOU_THRESHOLDS.iter().map(|&t| (None, kind, t)));
        }
        for s in seqs.keys() {
            jobs.extend(
                IOU_THRESHOLDS
                    .iter()
                    .map(|&t| (Some(*s), Overlap::Box3d, t)),
            );
        }
        let curves: Vec<Curve> = jobs
            .par_iter()
            .map(|&(seq, kind, t)| match seq {
                None => evaluate(frames, t, kind, protocol),
                Some(s) => evaluate(seqs[s].iter().copied(), t, kind, protocol),
            })
            .collect();
        let mut it = curves.into_iter();
        let ap3d: Vec<Curve> = it.by_ref().take(3).collect();
        let apbev: Vec<Curve> = it.by_ref().take(3).collect();
        let per_sequence = seqs
            .keys()
            .map(|s| (s.to_string(), it.by_ref().take(3).collect()))
            .collect();
        let counts = ap3d[0].counts;
        Report {
            protocol: *protocol,
            ap3d,
            apbev,
            per_sequence,
            counts,
        }
    }

    /// A short name of the protocol: `official`, or the list of non-official changes.
    pub fn protocol_name(&self) -> String {
        let mut parts = Vec::new();
        match self.protocol.max_range {
            Some(25.0) => {}
            Some(r) => parts.push(format!("range {r} m (non-official)")),
            None => parts.push("no range filter (non-official)".to_string()),
        }
        if let Some(r) = self.protocol.min_range {
            parts.push(format!("beyond {r} m only (non-official)"));
        }
        if self.protocol.min_points != 10 {
            parts.push(format!(
                "min {} points (non-official)",
                self.protocol.min_points
            ));
        }
        if self.protocol.interpolation == Interpolation::ElevenPoint {
            parts.push("11-point AP (non-official)".to_string());
        }
        if parts.is_empty() {
            "official JRDB (evaluate_object.cpp)".to_string()
        } else {
            parts.join(", ")
        }
    }

    /// The JSON object of `--json`: AP as fractions in [0, 1] with full f64 precision.
    pub fn to_json(&self) -> Value {
        let aps = |c: &[Curve]| -> Value {
            Value::Object(
                IOU_THRESHOLDS
                    .iter()
                    .zip(c)
                    .map(|(t, c)| (key(*t), json!(c.ap)))
                    .collect(),
            )
        };
        let per_sequence: serde_json::Map<String, Value> = self
            .per_sequence
            .iter()
            .map(|(s, c)| {
                let mut m: serde_json::Map<String, Value> = IOU_THRESHOLDS
                    .iter()
                    .zip(c)
                    .map(|(t, c)| (format!("ap3d_{}", key(*t)), json!(c.ap)))
                    .collect();
                m.insert("num_gt".into(), json!(c[0].counts.gt));
                m.insert("num_frames".into(), json!(c[0].counts.frames));
                (s.clone(), Value::Object(m))
            })
            .collect();
        let c = &self.counts;
        json!({
            "protocol": self.protocol_name(),
            "ap3d": aps(&self.ap3d),
            "apbev": aps(&self.apbev),
            "apbev_note": "BEV AP is not an official JRDB metric",
            "num_frames": c.frames,
            "num_gt": c.gt,
            "num_ignored_gt": c.ignored_gt,
            "num_dropped_gt": c.dropped_gt,
            "num_det": c.det,
            "num_ignored_det": c.ignored_det,
            "per_sequence": per_sequence,
        })
    }

    /// A readable table (AP in percent).
    pub fn to_table(&self) -> String {
        let c = &self.counts;
        let mut s = format!(
            "JRDB 3D detection, pedestrian — protocol: {}\n",
            self.protocol_name()
        );
        s += &format!(
            "frames {}  GT {} (ignored {}, dropped {})  detections {} (beyond range {})\n\n",
            c.frames, c.gt, c.ignored_gt, c.dropped_gt, c.det, c.ignored_det
        );
        s += "IoU      AP3D     APBEV*\n";
        for (i, t) in IOU_THRESHOLDS.iter().enumerate() {
            s += &format!(
                "{t:.1}  {:8.4}  {:8.4}\n",
                100.0 * self.ap3d[i].ap,
                100.0 * self.apbev[i].ap
            );
        }
        s += "* BEV AP is not an official JRDB metric. The leaderboard's number is AP3D@0.3.\n\n";
        let w = self
            .per_sequence
            .keys()
            .map(|k| k.len())
            .max()
            .unwrap_or(8)
            .max(8);
        s += &format!("{:w$}  {:>6}  {:>9}\n", "sequence", "GT", "AP3D@0.3");
        for (name, c) in &self.per_sequence {
            s += &format!(
                "{name:w$}  {:>6}  {:9.4}\n",
                c[0].counts.gt,
                100.0 * c[0].ap
            );
        }
        s
    }

    /// Writes every PR point: one row per (metric, IoU, sequence or `overall`, score threshold).
    pub fn write_pr_csv(&self, path: &Path) -> Result<()> {
        let io = |e: csv::Error| EvalError::io(path, std::io::Error::other(e));
        let mut w = csv::Writer::from_path(path).map_err(io)?;
        w.write_record([
            "metric",
            "iou",
            "sequence",
            "slot",
            "score_threshold",
            "tp",
            "fp",
            "fn",
            "recall",
            "precision",
            "precision_monotone",
        ])
        .map_err(io)?;
        let mut rows: Vec<(&str, &str, &Curve, f64)> = Vec::new();
        for (i, t) in IOU_THRESHOLDS.iter().enumerate() {
            rows.push(("ap3d", "overall", &self.ap3d[i], *t));
            rows.push(("apbev", "overall", &self.apbev[i], *t));
            for (s, c) in &self.per_sequence {
                rows.push(("ap3d", s, &c[i], *t));
            }
        }
        for (metric, seq, c, t) in rows {
            for k in 0..c.thresholds.len() {
                let raw = c.tp[k] as f64 / (c.tp[k] + c.fp[k]) as f64;
                w.write_record([
                    metric.to_string(),
                    key(t),
                    seq.to_string(),
                    k.to_string(),
                    c.thresholds[k].to_string(),
                    c.tp[k].to_string(),
                    c.fp[k].to_string(),
                    c.fn_[k].to_string(),
                    c.recall[k].to_string(),
                    raw.to_string(),
                    c.precision[k].to_string(),
                ])
                .map_err(io)?;
            }
        }
        w.flush().map_err(|e| EvalError::io(path, e))
    }
}
