//! CSV curves written as the run goes: `metrics.csv` (one row per step) and `epochs.csv` (one row per
//! epoch). Columns:
//!
//! - `metrics.csv`: `step, epoch, lr, loss, <each loss term>, seconds, time` — `step` counts from 1,
//!   `epoch` is the fractional epoch the lr was computed at, `seconds` the step's wall time, `time`
//!   the run's cumulative training time (validation excluded).
//! - `epochs.csv`: `epoch, steps, lr, loss, <each loss term>, ap3d_0.3, ap3d_0.5, ap3d_0.7,
//!   train_seconds, val_seconds, time` — `epoch` counts from 1, losses are the epoch's means, AP
//!   is empty where the epoch was not validated (AP as fractions in [0, 1]).
//!
//! Every row is flushed when written, so the files can be read (and plotted) while a run goes on.

use std::fs::{File, OpenOptions};
use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};

/// An append-only CSV file with a fixed header.
#[derive(Debug)]
pub struct CsvLog {
    path: PathBuf,
    header: Vec<String>,
    writer: csv::Writer<File>,
}

impl CsvLog {
    /// Opens `path` for appending; a new or empty file gets `header`, an existing one must have it.
    pub fn open(path: &Path, header: &[String]) -> Result<Self> {
        let exists = path.exists() && std::fs::metadata(path)?.len() > 0;
        if exists {
            let table = Table::read(path)?;
            if table.header != header {
                bail!("{} has columns {:?}, this run writes {:?}", path.display(), table.header, header);
            }
        }
        let file = OpenOptions::new().create(true).append(true).open(path).with_context(|| format!("opening {}", path.display()))?;
        let mut writer = csv::WriterBuilder::new().has_headers(false).from_writer(file);
        if !exists {
            writer.write_record(header)?;
            writer.flush()?;
        }
        Ok(Self { path: path.to_path_buf(), header: header.to_vec(), writer })
    }

    /// Appends one row (as many fields as the header) and flushes it.
    pub fn append(&mut self, row: &[String]) -> Result<()> {
        if row.len() != self.header.len() {
            bail!("{}: row of {} fields for {} columns", self.path.display(), row.len(), self.header.len());
        }
        self.writer.write_record(row)?;
        self.writer.flush()?;
        Ok(())
    }
}

/// A number as a CSV field: full precision, empty for `None`.
pub fn field(v: Option<f64>) -> String {
    v.map_or_else(String::new, |x| format!("{x}"))
}

/// A CSV file read back: header and numeric rows (`NaN` for empty or non-numeric fields).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Table {
    /// Column names.
    pub header: Vec<String>,
    /// Rows.
    pub rows: Vec<Vec<f64>>,
}

impl Table {
    /// Reads a CSV file.
    pub fn read(path: &Path) -> Result<Self> {
        let mut r = csv::ReaderBuilder::new().has_headers(true).from_path(path).with_context(|| format!("reading {}", path.display()))?;
        let header = r.headers()?.iter().map(String::from).collect();
        let mut rows = Vec::new();
        for rec in r.records() {
            let rec = rec.with_context(|| format!("reading {}", path.display()))?;
            rows.push(rec.iter().map(|f| f.parse::<f64>().unwrap_or(f64::NAN)).collect());
        }
        Ok(Self { header, rows })
    }

    /// Index of a column.
    pub fn col(&self, name: &str) -> Option<usize> {
        self.header.iter().position(|h| h == name)
    }

    /// A column's values.
    pub fn column(&self, name: &str) -> Option<Vec<f64>> {
        let i = self.col(name)?;
        Some(self.rows.iter().map(|r| r[i]).collect())
    }
}

/// Drops the rows whose `column` exceeds `max` (a resumed run rewrites what came after its
/// checkpoint). The file is rewritten atomically; a missing file is left missing.
pub fn truncate_after(path: &Path, column: &str, max: f64) -> Result<()> {
    if !path.exists() {
        return Ok(());
    }
    let mut r = csv::ReaderBuilder::new().has_headers(true).from_path(path)?;
    let header = r.headers()?.clone();
    let i = header.iter().position(|h| h == column).with_context(|| format!("{} has no column {column}", path.display()))?;
    let mut w = csv::Writer::from_writer(Vec::new());
    w.write_record(&header)?;
    for rec in r.records() {
        let rec = rec?;
        if rec.get(i).and_then(|f| f.parse::<f64>().ok()).is_some_and(|v| v <= max) {
            w.write_record(&rec)?;
        }
    }
    let bytes = w.into_inner().map_err(|e| anyhow::anyhow!("{e}"))?;
    crate::run_dir::write_atomic(path, &bytes)
}

/// The header of `metrics.csv` for a model with these loss terms.
pub fn step_header(terms: &[String]) -> Vec<String> {
    let mut h: Vec<String> = ["step", "epoch", "lr", "loss"].map(String::from).to_vec();
    h.extend(terms.iter().cloned());
    h.extend(["seconds", "time"].map(String::from));
    h
}

/// The header of `epochs.csv` for a model with these loss terms.
pub fn epoch_header(terms: &[String]) -> Vec<String> {
    let mut h: Vec<String> = ["epoch", "steps", "lr", "loss"].map(String::from).to_vec();
    h.extend(terms.iter().cloned());
    h.extend(["ap3d_0.3", "ap3d_0.5", "ap3d_0.7", "train_seconds", "val_seconds", "time"].map(String::from));
    h
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn append_reopen_truncate() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("m.csv");
        let h = step_header(&["cls".into()]);
        let row = |s: u64| vec![s.to_string(), "0.5".into(), "0.001".into(), "2".into(), "1".into(), "0.1".into(), field(Some(s as f64))];
        let mut log = CsvLog::open(&p, &h).unwrap();
        log.append(&row(1)).unwrap();
        log.append(&row(2)).unwrap();
        drop(log);
        let mut log = CsvLog::open(&p, &h).unwrap();
        log.append(&row(3)).unwrap();
        assert!(log.append(&["1".into()]).is_err());
        drop(log);
        assert!(CsvLog::open(&p, &step_header(&[])).is_err(), "other columns are refused");
        assert_eq!(Table::read(&p).unwrap().column("step").unwrap(), vec![1.0, 2.0, 3.0]);
        truncate_after(&p, "step", 2.0).unwrap();
        let t = Table::read(&p).unwrap();
        assert_eq!(t.header, h);
        assert_eq!(t.column("step").unwrap(), vec![1.0, 2.0]);
    }
}
