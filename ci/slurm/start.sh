#!/usr/bin/env bash
# Start a one-node Slurm on this machine (munged, slurmctld, slurmd on 127.0.0.1, 2 CPUs) for the
# farm test (tests/it/sequences.rs). Needs root and Debian's slurm-wlm + munge (.ci/run installs
# them). Idempotent: a running cluster is left as it is. Exits non-zero with a message when
# Slurm cannot start. State, logs and the config live under $SLURM_STATE (default /tmp/cloudgi-slurm).
set -euo pipefail

state=${SLURM_STATE:-/tmp/cloudgi-slurm}
conf=/etc/slurm/slurm.conf

for tool in munged slurmctld slurmd sinfo; do
  command -v "$tool" >/dev/null 2>&1 || { echo "ci/slurm/start.sh: $tool not found; install slurm-wlm and munge (apt-get install -y slurm-wlm munge)" >&2; exit 1; }
done
[ "$(id -u)" = 0 ] || { echo "ci/slurm/start.sh: must run as root (SlurmUser=root)" >&2; exit 1; }

# sinfo retries for MessageTimeout (9 s) when no controller answers: ask only a running one.
if pgrep -x slurmctld >/dev/null && sinfo -h -o %T 2>/dev/null | grep -qx idle; then
  exit 0
fi

mkdir -p "$state" /run/munge /var/log/munge /var/lib/munge /etc/munge
if [ ! -s /etc/munge/munge.key ]; then
  dd if=/dev/urandom of=/etc/munge/munge.key bs=1024 count=1 status=none
fi
chown -R munge:munge /etc/munge /run/munge /var/log/munge /var/lib/munge 2>/dev/null || true
chmod 0700 /etc/munge
chmod 0400 /etc/munge/munge.key
pgrep -x munged >/dev/null || munged --force

cat >"$conf" <<CONF
ClusterName=cloudgi-ci
SlurmctldHost=localhost(127.0.0.1)
SlurmUser=root
SlurmdUser=root
AuthType=auth/munge
CredType=cred/munge
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
SchedulerType=sched/builtin
SelectType=select/cons_tres
SelectTypeParameters=CR_CPU
ReturnToService=2
StateSaveLocation=$state/ctld
SlurmdSpoolDir=$state/d
SlurmctldPidFile=$state/slurmctld.pid
SlurmdPidFile=$state/slurmd.pid
SlurmctldLogFile=$state/slurmctld.log
SlurmdLogFile=$state/slurmd.log
MpiDefault=none
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
MinJobAge=30
# Schedule as soon as a job is released or a CPU frees (the default, batch_sched_delay=3, left the
# farm test's four scheduling steps 1-3 s each of waiting).
SchedulerParameters=batch_sched_delay=0
NodeName=localhost NodeAddr=127.0.0.1 CPUs=2 RealMemory=1000 State=UNKNOWN
# Two jobs per CPU: the farm test's arrays (up to four one-CPU elements) start in one scheduling
# pass (slurmctld schedules about once a second), not two.
PartitionName=ci Nodes=localhost Default=YES MaxTime=INFINITE State=UP OverSubscribe=FORCE:2
CONF
mkdir -p "$state/ctld" "$state/d"

pgrep -x slurmctld >/dev/null || slurmctld -c -i
pgrep -x slurmd >/dev/null || slurmd
for _ in $(seq 1 100); do
  if sinfo -h -o %T 2>/dev/null | grep -qx idle; then
    echo "slurm: node localhost idle ($(sinfo -V))"
    exit 0
  fi
  sleep 0.1
done
echo "ci/slurm/start.sh: Slurm did not come up; logs in $state" >&2
tail -n 20 "$state/slurmctld.log" "$state/slurmd.log" >&2 || true
exit 1
