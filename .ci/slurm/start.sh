#!/usr/bin/env bash
# Starts a one-node Slurm cluster on this (Debian) machine without systemd: munge, slurmctld and
# slurmd as plain daemons, no cgroup plugins (they fail without systemd's cgroup mounts), quick
# requeues. Needs root (or sudo). Stop it with .ci/slurm/stop.sh.
set -euo pipefail
sudo=""
[ "$(id -u)" -ne 0 ] && sudo="sudo"
export DEBIAN_FRONTEND=noninteractive
if ! command -v slurmctld >/dev/null || ! command -v munged >/dev/null; then
    # Keep the packages' maintainer scripts from starting services: this script starts them.
    printf '#!/bin/sh\nexit 101\n' | $sudo tee /usr/sbin/policy-rc.d >/dev/null
    $sudo chmod +x /usr/sbin/policy-rc.d
    $sudo apt-get update -qq
    $sudo apt-get install -y -qq --no-install-recommends munge slurm-wlm slurmctld slurmd slurm-client >/dev/null
    $sudo rm -f /usr/sbin/policy-rc.d
fi

[ -f /etc/munge/munge.key ] || $sudo mungekey --create
$sudo chown munge:munge /etc/munge/munge.key
$sudo chmod 0400 /etc/munge/munge.key
$sudo mkdir -p /run/munge /var/spool/slurmctld /var/spool/slurmd /var/log/slurm
$sudo chown munge:munge /run/munge
$sudo chown slurm:slurm /var/spool/slurmctld /var/log/slurm
pgrep -x munged >/dev/null || $sudo runuser -u munge -- /usr/sbin/munged
munge -n | unmunge >/dev/null

host=$(hostname -s)
node=$(slurmd -C | head -1 | sed 's/^NodeName=[^ ]* //')
conf=/etc/slurm/slurm.conf
$sudo tee $conf >/dev/null <<CONF
ClusterName=pmunet-ci
SlurmctldHost=$host(127.0.0.1)
SlurmUser=slurm
AuthType=auth/munge
AuthInfo=cred_expire=10
StateSaveLocation=/var/spool/slurmctld
SlurmdSpoolDir=/var/spool/slurmd
SlurmctldPidFile=/run/slurmctld.pid
SlurmdPidFile=/run/slurmd.pid
SlurmctldLogFile=/var/log/slurm/slurmctld.log
SlurmdLogFile=/var/log/slurm/slurmd.log
ProctrackType=proctrack/pgid
TaskPlugin=task/affinity
SelectType=select/cons_tres
SelectTypeParameters=CR_Core
SchedulerParameters=sched_interval=5,bf_interval=5
JobRequeue=1
MailProg=/bin/true
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
ReturnToService=2
NodeName=$host NodeAddr=127.0.0.1 $node State=UNKNOWN
PartitionName=ci Nodes=$host Default=YES MaxTime=INFINITE State=UP
CONF
$sudo rm -f /run/slurmctld.pid /run/slurmd.pid
$sudo slurmctld
$sudo slurmd
for _ in $(seq 60); do
    scontrol ping >/dev/null 2>&1 && sinfo -h -o %T | grep -q idle && break
    sleep 1
done
state=$(sinfo -h -o %T)
case "$state" in
    *drain*|*down*) $sudo scontrol update NodeName="$host" State=RESUME; sleep 2 ;;
esac
sinfo -h -o '%P %T %c CPUs' | sed 's/^/slurm: /'
sinfo -h -o %T | grep -q idle
