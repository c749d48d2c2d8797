//! The Slurm executor: a sweep's runs as one job array (a task per run, each
//! `train --config <run>.toml`, resuming its folder) and a job that depends on it (`afterany`) and
//! writes the tables. A task checkpoints and requeues itself on the warning signal Slurm sends
//! before its time limit; one preempted (SIGTERM) checkpoints before it goes.
//!
//! Files, under `<sweep>/slurm/`: `array.sh` and `tables.sh` (the batch scripts),
//! `array-<jobid>.runs` (the run folder of each task, by task index: what `--status` and a second
//! submission read the queue with), `task-<jobid>_<task>.out` and `tables-<jobid>.out`. A run's
//! training log is `<variant>/seed-<s>.log` beside its folder, as with `--jobs`.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::Command;

use anyhow::{Context, Result, bail};

use super::{Executor, Job, finished};
use crate::run_dir::write_atomic;

/// `sbatch` settings of a sweep's tasks.
#[derive(Debug, Clone, Default)]
pub struct Slurm {
    /// The sweep file (the tables job runs `train sweep FILE --tables`).
    pub sweep_file: PathBuf,
    /// The sweep's folder.
    pub sweep_dir: PathBuf,
    /// The sweep's name (the jobs' name is `pmunet-<name>`).
    pub name: String,
    /// `--partition`.
    pub partition: Option<String>,
    /// `--time` (a task's limit; it is warned 120 s before).
    pub time: Option<String>,
    /// `--cpus-per-task` (also each run's `threads`).
    pub cpus_per_task: Option<u32>,
    /// `--gpus-per-task`.
    pub gpus_per_task: Option<u32>,
    /// `--mem`.
    pub mem: Option<String>,
    /// More `sbatch` options, as written (`--account=x`, `--qos=y`).
    pub sbatch_args: Vec<String>,
    /// Cap each run's steps (as `--max-steps`).
    pub max_steps: Option<u64>,
    /// Cap each run's epochs (as `--max-epochs`).
    pub max_epochs: Option<usize>,
    /// Only print the scripts and the `sbatch` lines.
    pub dry_run: bool,
}

/// Seconds before the time limit Slurm warns a task (SIGUSR1 to its batch shell).
const WARN_S: u32 = 120;

/// Where a run stands.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum RunState {
    /// `summary.json` says all its epochs are done.
    Finished,
    /// Queued (`squeue`'s state: PENDING, RUNNING, REQUEUED, …) as `<jobid>_<task>`.
    Queued {
        /// `<jobid>_<task>`.
        task: String,
        /// `squeue`'s state.
        state: String,
    },
    /// Started, not finished and not queued: failed or stopped, with its log's last line.
    Stopped {
        /// The last line of `<variant>/seed-<s>.log`.
        last_line: String,
    },
    /// Never started.
    NotStarted,
}

impl std::fmt::Display for RunState {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            RunState::Finished => write!(f, "finished"),
            RunState::Queued { task, state } => write!(f, "{} ({task})", state.to_lowercase()),
            RunState::Stopped { last_line } => write!(f, "failed or stopped: {last_line}"),
            RunState::NotStarted => write!(f, "not started"),
        }
    }
}

impl Slurm {
    fn slurm_dir(&self) -> PathBuf {
        self.sweep_dir.join("slurm")
    }

    fn job_name(&self) -> String {
        format!("pmunet-{}", self.name)
    }

    fn header(&self, lines: &mut Vec<String>) {
        let mut opt = |k: &str, v: Option<String>| {
            if let Some(v) = v {
                lines.push(format!("#SBATCH --{k}={v}"));
            }
        };
        opt("partition", self.partition.clone());
        opt("cpus-per-task", self.cpus_per_task.map(|n| n.to_string()));
        opt("gpus-per-task", self.gpus_per_task.map(|n| n.to_string()));
        opt("mem", self.mem.clone());
        for a in &self.sbatch_args {
            lines.push(format!("#SBATCH {a}"));
        }
    }

    /// The array's batch script for `runs` (run folders, by task index).
    fn array_script(&self, runs: &[PathBuf], exe: &Path, cwd: &Path) -> String {
        let mut l = vec!["#!/usr/bin/env bash".to_string(), format!("#SBATCH --job-name={}", self.job_name()), format!("#SBATCH --array=0-{}", runs.len() - 1)];
        l.push(format!("#SBATCH --output={}/task-%A_%a.out", abs(cwd, &self.slurm_dir()).display()));
        l.push("#SBATCH --open-mode=append".into());
        l.push("#SBATCH --requeue".into());
        l.push(format!("#SBATCH --signal=B:USR1@{WARN_S}"));
        if let Some(t) = &self.time {
            l.push(format!("#SBATCH --time={t}"));
        }
        self.header(&mut l);
        l.push("set -u".into());
        l.push(format!("cd {}", sh(cwd)));
        l.push(format!("runs=({})", runs.iter().map(|r| sh(r)).collect::<Vec<_>>().join(" ")));
        l.push("run=${runs[$SLURM_ARRAY_TASK_ID]}".into());
        l.push("task=${SLURM_ARRAY_JOB_ID}_${SLURM_ARRAY_TASK_ID}".into());
        l.push("resume=(); [ -f \"$run/config.toml\" ] && resume=(--resume)".into());
        let mut cap = String::new();
        if let Some(n) = self.max_steps {
            cap += &format!(" --max-steps {n}");
        }
        if let Some(n) = self.max_epochs {
            cap += &format!(" --max-epochs {n}");
        }
        l.push("echo \"slurm task $task (restart ${SLURM_RESTART_COUNT:-0}) on $(hostname)\" >> \"$run.log\"".into());
        // The trainer in the background, so that the shell's traps run at once: the warning
        // (USR1, sent to this shell only) and a preemption or requeue (TERM, which the trainer
        // may get too) are passed on; the trainer checkpoints after its step and exits 75.
        l.push(format!("{} --config \"$run.toml\" --quiet \"${{resume[@]}}\"{cap} >> \"$run.log\" 2>&1 &", sh(exe)));
        l.push("pid=$!".into());
        l.push("trap 'kill -TERM $pid 2>/dev/null' USR1 TERM".into());
        l.push("wait $pid; status=$?".into());
        l.push("while kill -0 $pid 2>/dev/null; do wait $pid; status=$?; done".into());
        l.push("if [ $status -eq 75 ]; then".into());
        l.push("  echo \"slurm task $task: checkpointed on a signal, requeued\" >> \"$run.log\"".into());
        l.push("  scontrol requeue \"$task\" 2>/dev/null || true".into());
        l.push("  exit 0".into());
        l.push("fi".into());
        l.push("exit $status".into());
        l.join("\n") + "\n"
    }

    /// The tables job's batch script.
    fn tables_script(&self, exe: &Path, cwd: &Path) -> String {
        let mut l = vec!["#!/usr/bin/env bash".to_string(), format!("#SBATCH --job-name={}-tables", self.job_name())];
        l.push(format!("#SBATCH --output={}/tables-%j.out", abs(cwd, &self.slurm_dir()).display()));
        if let Some(p) = &self.partition {
            l.push(format!("#SBATCH --partition={p}"));
        }
        l.push("#SBATCH --cpus-per-task=1".into());
        l.push(format!("cd {}", sh(cwd)));
        l.push(format!("exec {} sweep {} --tables", sh(exe), sh(&self.sweep_file)));
        l.join("\n") + "\n"
    }

    /// The runs queued now (pending, running, requeued…): run folder → (`<jobid>_<task>`, state),
    /// from `squeue` and the `array-<jobid>.runs` files. Empty when `squeue` is not there.
    pub fn queued(&self) -> Result<BTreeMap<PathBuf, (String, String)>> {
        let out = match Command::new("squeue").args(["-h", "-r", "-n", &self.job_name(), "-o", "%F %K %T"]).output() {
            Ok(o) if o.status.success() => String::from_utf8_lossy(&o.stdout).into_owned(),
            Ok(o) => bail!("squeue failed: {}", String::from_utf8_lossy(&o.stderr).trim()),
            Err(_) => return Ok(BTreeMap::new()),
        };
        let mut map = BTreeMap::new();
        let mut runs_of: BTreeMap<String, Vec<PathBuf>> = BTreeMap::new();
        for line in out.lines() {
            let f: Vec<&str> = line.split_whitespace().collect();
            let [job, task, state] = f[..] else { continue };
            let Ok(i) = task.parse::<usize>() else { continue };
            if !runs_of.contains_key(job) {
                let file = self.slurm_dir().join(format!("array-{job}.runs"));
                let text = std::fs::read_to_string(&file).unwrap_or_default();
                runs_of.insert(job.to_string(), text.lines().map(PathBuf::from).collect());
            }
            if let Some(run) = runs_of[job].get(i) {
                map.insert(run.clone(), (format!("{job}_{task}"), state.to_string()));
            }
        }
        Ok(map)
    }

    /// Each job's state, from its run folder and the queue.
    pub fn status(&self, jobs: &[Job]) -> Result<Vec<RunState>> {
        let queued = self.queued()?;
        Ok(jobs
            .iter()
            .map(|j| {
                if finished(&j.dir).is_some() {
                    return RunState::Finished;
                }
                if let Some((task, state)) = queued.get(&j.dir) {
                    return RunState::Queued { task: task.clone(), state: state.clone() };
                }
                let log = j.dir.with_extension("log");
                match std::fs::read_to_string(&log) {
                    Ok(t) => RunState::Stopped { last_line: t.lines().rev().find(|l| !l.trim().is_empty()).unwrap_or("").to_string() },
                    Err(_) if j.dir.exists() => RunState::Stopped { last_line: "(no log)".into() },
                    Err(_) => RunState::NotStarted,
                }
            })
            .collect())
    }
}

impl Executor for Slurm {
    fn execute(&mut self, todo: &[&Job], _written: &mut dyn FnMut() -> Result<()>, verbose: bool) -> Result<Vec<String>> {
        let queued = self.queued()?;
        let todo: Vec<&Job> = todo
            .iter()
            .copied()
            .filter(|j| match queued.get(&j.dir) {
                Some((task, state)) => {
                    eprintln!("{} seed {}: {} as {task}, not submitted again", j.variant, j.seed, state.to_lowercase());
                    false
                }
                None => true,
            })
            .collect();
        if todo.is_empty() {
            eprintln!("nothing to submit");
            return Ok(vec![]);
        }
        let cwd = std::env::current_dir()?;
        let exe = std::env::current_exe()?;
        let runs: Vec<PathBuf> = todo.iter().map(|j| j.dir.clone()).collect();
        let array = self.array_script(&runs, &exe, &cwd);
        let tables = self.tables_script(&exe, &cwd);
        let dir = self.slurm_dir();
        if self.dry_run {
            println!("# {}/array.sh\n{array}\n# {}/tables.sh\n{tables}", dir.display(), dir.display());
            println!("sbatch --parsable {}/array.sh", dir.display());
            println!("sbatch --parsable --dependency=afterany:<array job> {}/tables.sh", dir.display());
            return Ok(vec![]);
        }
        // Every task's config beside its folder (with the task's cores as its threads), and the
        // simulated trees generated here, once, before tasks race to write them.
        for j in &todo {
            crate::data::ensure_training_data(&j.config.data)?;
            let mut config = j.config.clone();
            if let Some(n) = self.cpus_per_task {
                config.threads = Some(n as usize);
            }
            std::fs::create_dir_all(j.dir.parent().context("a run folder has a parent")?)?;
            write_atomic(&j.dir.with_extension("toml"), config.to_toml()?.as_bytes())?;
        }
        std::fs::create_dir_all(&dir)?;
        write_atomic(&dir.join("array.sh"), array.as_bytes())?;
        write_atomic(&dir.join("tables.sh"), tables.as_bytes())?;
        let id = sbatch(&[], &dir.join("array.sh"))?;
        let listed: String = runs.iter().map(|r| format!("{}\n", r.display())).collect();
        write_atomic(&dir.join(format!("array-{id}.runs")), listed.as_bytes())?;
        let tid = sbatch(&[format!("--dependency=afterany:{id}")], &dir.join("tables.sh"))?;
        if verbose {
            eprintln!("submitted {} runs as job array {id} (tasks 0-{}), the tables as job {tid} after it", runs.len(), runs.len() - 1);
            eprintln!("follow with: train sweep {} --status", self.sweep_file.display());
        }
        Ok(vec![])
    }
}

/// `sbatch --parsable ARGS SCRIPT`: the job id.
fn sbatch(args: &[String], script: &Path) -> Result<String> {
    let out = Command::new("sbatch").arg("--parsable").args(args).arg(script).output().context("running sbatch (is Slurm installed here?)")?;
    if !out.status.success() {
        bail!("sbatch {} failed: {}", script.display(), String::from_utf8_lossy(&out.stderr).trim());
    }
    let id = String::from_utf8_lossy(&out.stdout).trim().split(';').next().unwrap_or("").to_string();
    if id.is_empty() || !id.chars().all(|c| c.is_ascii_digit()) {
        bail!("sbatch {} printed no job id: {:?}", script.display(), String::from_utf8_lossy(&out.stdout));
    }
    Ok(id)
}

fn abs(cwd: &Path, p: &Path) -> PathBuf {
    if p.is_absolute() { p.to_path_buf() } else { cwd.join(p) }
}

/// A path quoted for the shell.
fn sh(p: &Path) -> String {
    format!("'{}'", p.display().to_string().replace('\'', "'\\''"))
}
