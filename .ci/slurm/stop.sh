#!/usr/bin/env bash
# Stops the cluster .ci/slurm/start.sh started: cancels what is queued, waits for the job steps
# to end, then stops slurmd, slurmctld and munged by their pids.
set -uo pipefail
sudo=""
[ "$(id -u)" -ne 0 ] && sudo="sudo"
command -v scancel >/dev/null && $sudo scancel --user="$(id -un)" 2>/dev/null
command -v scancel >/dev/null && $sudo scancel --state=PENDING 2>/dev/null
for _ in $(seq 30); do pgrep -x slurmstepd >/dev/null || break; sleep 1; done
alive() { [ -e "/proc/$1" ] && ! grep -q '^[0-9]* ([^)]*) Z' "/proc/$1/stat" 2>/dev/null; }
for name in slurmd slurmctld munged; do
    for pid in $(pgrep -x "$name"); do
        $sudo kill -TERM "$pid" 2>/dev/null
        for _ in $(seq 20); do alive "$pid" || break; sleep 0.5; done
        alive "$pid" && $sudo kill -KILL "$pid" 2>/dev/null
    done
done
$sudo rm -f /run/slurmctld.pid /run/slurmd.pid
echo "slurm: stopped"
