//! Where a JRDB tree keeps its files, and which sequences belong to which split (docs/data.md).

use std::path::{Path, PathBuf};

use crate::calibration::Lidar;
use crate::error::{DataError, ErrorKind, Result};

/// The 7 validation sequences of the JRDB devkit and Person_MinkUNet.
pub const DEFAULT_VAL_SEQUENCES: [&str; 7] = [
    "clark-center-2019-02-28_1",
    "gates-ai-lab-2019-02-08_0",
    "huang-2-2019-01-25_0",
    "meyer-green-2019-03-16_0",
    "nvidia-aud-2019-04-18_0",
    "tressider-2019-03-16_1",
    "tressider-2019-04-26_2",
];

/// The 20 JRDB training sequences outside the default validation split.
pub const DEFAULT_TRAIN_SEQUENCES: [&str; 20] = [
    "bytes-cafe-2019-02-07_0",
    "clark-center-2019-02-28_0",
    "clark-center-intersection-2019-02-28_0",
    "cubberly-auditorium-2019-04-22_0",
    "forbes-cafe-2019-01-22_0",
    "gates-159-group-meeting-2019-04-03_0",
    "gates-basement-elevators-2019-01-17_1",
    "gates-to-clark-2019-02-28_1",
    "hewlett-packard-intersection-2019-01-24_0",
    "huang-basement-2019-01-25_0",
    "huang-lane-2019-02-12_0",
    "jordan-hall-2019-04-22_0",
    "memorial-court-2019-03-16_0",
    "packard-poster-session-2019-03-20_0",
    "packard-poster-session-2019-03-20_1",
    "packard-poster-session-2019-03-20_2",
    "stlc-111-2019-04-19_0",
    "svl-meeting-gates-2-2019-04-08_0",
    "svl-meeting-gates-2-2019-04-08_1",
    "tressider-2019-03-16_0",
];

/// Which sequences of a tree to use.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Split {
    /// Every sequence except the validation ones.
    #[default]
    Train,
    /// The validation sequences.
    Val,
    /// Every sequence of the tree (the test-set checkpoint's `train_val`).
    TrainVal,
}

/// The folders of one JRDB tree; `root` is the folder that holds `pointclouds/`.
#[derive(Debug, Clone, PartialEq)]
pub struct Layout {
    /// The resolved root.
    pub root: PathBuf,
}

impl Layout {
    /// Finds the tree at `dir` itself or in its `train_dataset_with_activity/` (or `train_dataset/`).
    pub fn resolve(dir: &Path) -> Result<Self> {
        for cand in [dir.to_path_buf(), dir.join("train_dataset_with_activity"), dir.join("train_dataset")] {
            if cand.join("pointclouds").is_dir() {
                return Ok(Self { root: cand });
            }
        }
        Err(DataError::new(
            dir,
            ErrorKind::Layout("no pointclouds/ folder here nor in train_dataset_with_activity/ or train_dataset/".into()),
        ))
    }

    /// `pointclouds/<lidar>/<seq>/`.
    pub fn cloud_dir(&self, lidar: Lidar, seq: &str) -> PathBuf {
        self.root.join("pointclouds").join(lidar.folder()).join(seq)
    }

    /// `labels/labels_3d/<seq>.json`.
    pub fn labels_file(&self, seq: &str) -> PathBuf {
        self.root.join("labels").join("labels_3d").join(format!("{seq}.json"))
    }

    /// `calibration/defaults.yaml`.
    pub fn calibration_file(&self) -> PathBuf {
        self.root.join("calibration").join("defaults.yaml")
    }

    /// `timestamps/<seq>/frames_pc.json`.
    pub fn timestamps_file(&self, seq: &str) -> PathBuf {
        self.root.join("timestamps").join(seq).join("frames_pc.json")
    }

    /// The sequences present, i.e. the folders under `pointclouds/upper_velodyne/`, sorted.
    pub fn sequences(&self) -> Result<Vec<String>> {
        let dir = self.root.join("pointclouds").join(Lidar::Upper.folder());
        let rd = std::fs::read_dir(&dir).map_err(|e| DataError::io(&dir, e))?;
        let mut out = Vec::new();
        for e in rd {
            let e = e.map_err(|e| DataError::io(&dir, e))?;
            if e.path().is_dir() {
                out.push(e.file_name().to_string_lossy().into_owned());
            }
        }
        out.sort();
        Ok(out)
    }
}

/// Whether `seq` is listed in `val`, where an entry ending in `*` matches by prefix.
pub fn is_listed(seq: &str, val: &[String]) -> bool {
    val.iter().any(|v| match v.strip_suffix('*') {
        Some(prefix) => seq.starts_with(prefix),
        None => v == seq,
    })
}

/// The sequences of `split` among `present`, given the validation list (see [`is_listed`]).
pub fn select_sequences(present: &[String], split: Split, val: &[String]) -> Vec<String> {
    present
        .iter()
        .filter(|s| match split {
            Split::Train => !is_listed(s, val),
            Split::Val => is_listed(s, val),
            Split::TrainVal => true,
        })
        .cloned()
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn splits_partition_the_tree() {
        let present: Vec<String> = ["bytes-cafe-2019-02-07_0", "huang-2-2019-01-25_0", "x"].map(String::from).to_vec();
        let val: Vec<String> = DEFAULT_VAL_SEQUENCES.map(String::from).to_vec();
        assert_eq!(select_sequences(&present, Split::Val, &val), ["huang-2-2019-01-25_0"]);
        assert_eq!(select_sequences(&present, Split::Train, &val), ["bytes-cafe-2019-02-07_0", "x"]);
        assert_eq!(select_sequences(&present, Split::TrainVal, &val).len(), 3);
        let bench: Vec<String> = ["sim-train-hall-000", "sim-val-plaza-001", "sim-valx"].map(String::from).to_vec();
        let pattern = vec!["sim-val-*".to_string()];
        assert_eq!(select_sequences(&bench, Split::Val, &pattern), ["sim-val-plaza-001"]);
        assert_eq!(select_sequences(&bench, Split::Train, &pattern), ["sim-train-hall-000", "sim-valx"]);
    }
}
