//! Runs stopped and started again give the runs they would have been: a run sent SIGTERM
//! checkpoints after its step, exits 75 and resumes to the uninterrupted run's metrics; and,
//! against a real Slurm (`.ci/run` starts a one-node cluster with `.ci/slurm/start.sh` and sets
//! `PMUNET_TEST_SLURM=1`), a sweep submitted with `--slurm`, one task requeued while it trains,
//! writes the local sweep's tables.
#![cfg(unix)]

mod common;

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::{Duration, Instant};

use common::{metrics_without_times, ok, results_without_times};

fn config(dir: &Path, data: &Path) -> PathBuf {
    let training = common::tiny_model_and_training("epochs = 3\n");
    let text = format!(
        r#"seed = 0
backend = "flex"
threads = 1
[data]
root = "{}"
voxel_size = [0.1, 0.1, 0.1]
max_voxels = 4000
prefetch = false
[data.simulate]
sequences = 4
frames = 6
seed = 1
max_people = 8
{training}[eval]
frame_stride = 3
"#,
        data.display()
    );
    let path = dir.join("cfg.toml");
    std::fs::write(&path, text).unwrap();
    path
}

fn rows(run: &Path) -> usize {
    std::fs::read_to_string(run.join("metrics.csv")).map_or(0, |t| t.lines().count().saturating_sub(1))
}

fn wait_for(what: &str, limit: Duration, mut ok: impl FnMut() -> bool) {
    let t = Instant::now();
    while !ok() {
        assert!(t.elapsed() < limit, "timed out waiting for {what}");
        std::thread::sleep(Duration::from_millis(50));
    }
}

#[test]
fn a_run_sent_sigterm_checkpoints_and_resumes_to_the_same_metrics() {
    let tmp = tempfile::tempdir().unwrap();
    let cfg = config(tmp.path(), &tmp.path().join("data"));
    let runs = tmp.path().join("runs");
    let (cfg_s, runs_s) = (cfg.to_str().unwrap(), runs.to_str().unwrap());
    ok(&["--config", cfg_s, "--out", runs_s, "--name", "whole", "--quiet"]);
    let mut child = Command::new(env!("CARGO_BIN_EXE_train")).args(["--config", cfg_s, "--out", runs_s, "--name", "cut", "--quiet"]).spawn().unwrap();
    let cut = runs.join("cut");
    wait_for("a few steps", Duration::from_secs(300), || rows(&cut) >= 3);
    // SAFETY: signalling our own child.
    assert_eq!(unsafe { libc::kill(child.id() as i32, libc::SIGTERM) }, 0);
    let status = child.wait().unwrap();
    assert_eq!(status.code(), Some(75), "a signalled run exits 75 (EX_TEMPFAIL)");
    let summary = std::fs::read_to_string(cut.join("summary.json")).unwrap();
    assert!(summary.contains("\"finished\": false"), "{summary}");
    let stopped_at = rows(&cut);
    assert!(stopped_at < rows(&runs.join("whole")), "the signal came before the end ({stopped_at} steps)");
    ok(&["--config", cfg_s, "--out", runs_s, "--name", "cut", "--resume", "--quiet"]);
    assert_eq!(metrics_without_times(&cut), metrics_without_times(&runs.join("whole")));
    // Its validation too: the checkpoint held the batch norms' running statistics of its last step.
    let scored = |run: &Path| -> Vec<String> {
        std::fs::read_to_string(run.join("summary.json")).unwrap().lines().filter(|l| !l.contains("\"name\"") && !l.contains("seconds")).map(str::to_string).collect()
    };
    assert_eq!(scored(&cut), scored(&runs.join("whole")));
}

#[test]
fn a_sweep_on_slurm_with_a_requeued_task_writes_the_local_sweeps_tables() {
    if std::env::var_os("PMUNET_TEST_SLURM").is_none() {
        eprintln!("PMUNET_TEST_SLURM is not set: no Slurm cluster to submit to (.ci/run starts one)");
        return;
    }
    let tmp = tempfile::tempdir().unwrap();
    let cfg = config(tmp.path(), &tmp.path().join("data"));
    let name = format!("ci{}", std::process::id());
    let sweep = |stem: &str| {
        let path = tmp.path().join(format!("{stem}.toml"));
        std::fs::write(
            &path,
            format!(
                "name = \"{stem}{name}\"\nbase = \"{}\"\nout_dir = \"{}\"\nseeds = [0, 1]\n[[variants]]\nname = \"a\"\n[[variants]]\nname = \"b\"\nset = {{ \"model.cls_weight\" = 10.0 }}\n",
                cfg.display(),
                tmp.path().join("runs").display()
            ),
        )
        .unwrap();
        path
    };
    let (local, cluster) = (sweep("local"), sweep("slurm"));
    ok(&["sweep", local.to_str().unwrap()]);
    let out = ok(&["sweep", cluster.to_str().unwrap(), "--slurm", "--cpus-per-task", "1", "--time", "10"]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("submitted 4 runs as job array"), "{err}");
    let sdir = tmp.path().join("runs").join(format!("slurm{name}"));
    // Requeue the first task once it has trained a few steps; it resumes from its checkpoint.
    let first = sdir.join("a/seed-0");
    wait_for("task 0 to train", Duration::from_secs(600), || rows(&first) >= 3);
    let runs_file = std::fs::read_dir(sdir.join("slurm")).unwrap().map(|e| e.unwrap().path()).find(|p| p.extension().is_some_and(|x| x == "runs")).unwrap();
    let job = runs_file.file_stem().unwrap().to_str().unwrap().trim_start_matches("array-").to_string();
    let rq = Command::new("scontrol").args(["requeue", &format!("{job}_0")]).output().unwrap();
    assert!(rq.status.success(), "scontrol requeue: {}", String::from_utf8_lossy(&rq.stderr));
    // Resubmitting while tasks are queued submits nothing again.
    let again = ok(&["sweep", cluster.to_str().unwrap(), "--slurm"]);
    let again = String::from_utf8_lossy(&again.stderr);
    assert!(again.contains("nothing to submit") && again.matches("not submitted again").count() == 4, "{again}");
    wait_for("the array and the tables job", Duration::from_secs(900), || {
        let q = Command::new("squeue").args(["-h", "-n", &format!("pmunet-slurm{name},pmunet-slurm{name}-tables")]).output().unwrap();
        q.stdout.is_empty() && sdir.join("results.csv").exists()
    });
    let log = std::fs::read_to_string(first.with_extension("log")).unwrap();
    assert!(log.contains("restart 1") && log.contains("stopped by a signal"), "task 0 was requeued and resumed:\n{log}");
    let status = ok(&["sweep", cluster.to_str().unwrap(), "--status"]);
    assert_eq!(String::from_utf8_lossy(&status.stdout).matches(": finished (").count(), 4, "{}", String::from_utf8_lossy(&status.stdout));
    for v in ["a/seed-0", "a/seed-1", "b/seed-0", "b/seed-1"] {
        let l = tmp.path().join("runs").join(format!("local{name}")).join(v);
        assert_eq!(metrics_without_times(&sdir.join(v)), metrics_without_times(&l), "{v}");
    }
    assert_eq!(results_without_times(&sdir), results_without_times(&tmp.path().join("runs").join(format!("local{name}"))));
}
