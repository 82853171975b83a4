#!/bin/bash
# A throwaway single-node Slurm cluster on this machine, entirely inside one folder, for trying
# the array job (and for tests/slurm.rs): munged, slurmctld and slurmd started in the
# foreground under this script's control, with their sockets, state, logs and pid files in
# the folder and their own ports. No system service or file under /etc is touched. Needs
# Debian's slurm-wlm and munge packages, and root (slurmd runs jobs as their submitter).
#
#   examples/slurm/local-cluster.sh start DIR   # prints the SLURM_CONF to export
#   SLURM_CONF=DIR/slurm.conf sbatch ...
#   examples/slurm/local-cluster.sh stop DIR
#
# Ports: SLURM_LOCAL_PORT (default 17817) for slurmctld and the next one for slurmd.
set -euo pipefail

usage() {
  echo "usage: $0 start|stop DIR" >&2
  exit 2
}
[ $# -eq 2 ] || usage
command=$1
dir=$2

stop() {
  # slurmd first, so that it does not report to a controller that is going away.
  for name in slurmd slurmctld munged; do
    pidfile="$dir/$name.pid"
    [ -f "$pidfile" ] || continue
    pid=$(cat "$pidfile")
    if [ -n "$pid" ] && kill -0 "$pid" 2>/dev/null; then
      kill -TERM "$pid" 2>/dev/null || true
      for _ in $(seq 1 100); do
        kill -0 "$pid" 2>/dev/null || break
        sleep 0.1
      done
      kill -KILL "$pid" 2>/dev/null || true
    fi
    rm -f "$pidfile"
  done
}

case $command in
  start) ;;
  stop) stop; exit 0 ;;
  *) usage ;;
esac

for tool in munged slurmctld slurmd sinfo; do
  command -v "$tool" >/dev/null || {
    echo "$0: $tool not found: install Debian's slurm-wlm and munge" >&2
    exit 1
  }
done
mkdir -p "$dir"
dir=$(cd "$dir" && pwd)
if [ -e "$dir/slurm.conf" ]; then
  echo "$0: $dir already holds a cluster; stop it and use a fresh folder" >&2
  exit 1
fi
mkdir -p "$dir/state" "$dir/spool"
port=${SLURM_LOCAL_PORT:-17817}
host=$(hostname -s)
# The node's CPUs and memory as slurmd sees them, so that the configuration matches the
# hardware.
node=$(slurmd -C)
cpus=$(echo "$node" | sed -n 's/.*CPUs=\([0-9]*\).*/\1/p')
memory=$(echo "$node" | sed -n 's/.*RealMemory=\([0-9]*\).*/\1/p')
cpus=${cpus:-1}
memory=${memory:-1000}

# The munge key: 1 KiB of random bytes, readable by its owner only (munged checks).
head -c 1024 /dev/urandom > "$dir/munge.key"
chmod 600 "$dir/munge.key"
# --force: munged refuses to run as root, or with the key in a folder others can write to,
# unless forced; this cluster lives in a private test folder.
munged --foreground --force --socket="$dir/munge.socket" --key-file="$dir/munge.key" \
  --log-file="$dir/munged.log" --seed-file="$dir/munged.seed" \
  --pid-file="$dir/munged.pid.unused" > "$dir/munged.out" 2>&1 &
echo $! > "$dir/munged.pid"

cat > "$dir/slurm.conf" <<CONF
ClusterName=splatscene-local
SlurmctldHost=$host(127.0.0.1)
SlurmctldPort=$port
SlurmdPort=$((port + 1))
SlurmUser=root
SlurmdUser=root
# The clients and daemons find munged at this socket.
AuthType=auth/munge
AuthInfo=socket=$dir/munge.socket
CredType=cred/munge
StateSaveLocation=$dir/state
SlurmdSpoolDir=$dir/spool
SlurmctldPidFile=$dir/slurmctld.pid.unused
SlurmdPidFile=$dir/slurmd.pid.unused
SlurmctldLogFile=$dir/slurmctld.log
SlurmdLogFile=$dir/slurmd.log
# No cgroups (a container may not offer them): processes tracked by their parent ids, tasks
# not bound, no accounting.
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
JobCompType=jobcomp/none
MpiDefault=none
SwitchType=switch/none
# Cores, not whole nodes, are given out: one-CPU array tasks run side by side.
SelectType=select/cons_tres
SelectTypeParameters=CR_Core
SchedulerType=sched/backfill
ReturnToService=2
SlurmctldTimeout=30
SlurmdTimeout=30
MinJobAge=300
KillWait=5
NodeName=$host NodeAddr=127.0.0.1 CPUs=$cpus RealMemory=$memory State=UNKNOWN
PartitionName=local Nodes=$host Default=YES MaxTime=INFINITE State=UP
CONF

# Wait for munged's socket before the daemons that need it.
for _ in $(seq 1 100); do
  [ -S "$dir/munge.socket" ] && break
  sleep 0.1
done
slurmctld -D -f "$dir/slurm.conf" > "$dir/slurmctld.out" 2>&1 &
echo $! > "$dir/slurmctld.pid"
slurmd -D -f "$dir/slurm.conf" > "$dir/slurmd.out" 2>&1 &
echo $! > "$dir/slurmd.pid"

export SLURM_CONF="$dir/slurm.conf"
for _ in $(seq 1 300); do
  if [ "$(sinfo --noheader --format=%T 2>/dev/null)" = idle ]; then
    echo "SLURM_CONF=$dir/slurm.conf"
    exit 0
  fi
  sleep 0.2
done
echo "$0: the node did not come up in 60 s; the daemons said:" >&2
tail -n 20 "$dir"/munged.out "$dir"/slurmctld.out "$dir"/slurmd.out "$dir"/slurmctld.log \
  "$dir"/slurmd.log >&2 2>/dev/null || true
stop
exit 1
