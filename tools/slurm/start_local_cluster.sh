#!/usr/bin/env bash
# Start a single-node Slurm cluster on this machine, from Debian's packages, for testing
# `vcsmooth batch` / `vcsmooth slurm-script` against the real scheduler (tools/slurm/test_array.sh).
#
#   sudo tools/slurm/start_local_cluster.sh          # install if needed, configure, start, wait
#   sudo tools/slurm/start_local_cluster.sh --stop   # stop the daemons this script started
#
# Needs root and a Debian/Ubuntu system (no systemd needed: the daemons are started directly).
# It writes /etc/slurm/slurm.conf unless one exists that it did not write (then it refuses, so a
# real cluster's configuration is never touched). The configuration: one node (this host, at
# 127.0.0.1) with CPUs = nproc and RealMemory = 90 % of `free -m`'s total, in the default
# partition `debug`; proctrack/linuxproc, task/none (no cgroups, so it works in containers),
# SlurmUser=slurm, munge authentication, no accounting,
# SchedulerParameters=batch_sched_delay=0 (batch jobs scheduled at once),
# DependencyParameters=kill_invalid_depend, select/cons_tres with CR_Core_Memory (--mem and
# --cpus-per-task are allocated). Logs: /var/log/slurm/. Idempotent: a running cluster is reused.
set -euo pipefail

CONF=/etc/slurm/slurm.conf
TAG="# written by vcsmooth tools/slurm/start_local_cluster.sh"
PIDS=/run/vcsmooth-slurm

die() { echo "start_local_cluster: $*" >&2; exit 1; }
[ "$(id -u)" = 0 ] || die "must run as root"

stop() {
    for d in slurmd slurmctld munged; do
        if [ -f "$PIDS/$d.pid" ]; then
            pid=$(cat "$PIDS/$d.pid")
            kill "$pid" 2>/dev/null || true
            for _ in $(seq 50); do kill -0 "$pid" 2>/dev/null || break; sleep 0.1; done
            rm -f "$PIDS/$d.pid"
        fi
    done
    echo "start_local_cluster: stopped"
}

if [ "${1:-}" = "--stop" ]; then stop; exit 0; fi

# 1. Packages.
need=()
for p in slurmctld slurmd slurm-client munge; do
    dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "ok installed" || need+=("$p")
done
if [ ${#need[@]} -gt 0 ]; then
    echo "start_local_cluster: installing ${need[*]}"
    export DEBIAN_FRONTEND=noninteractive
    apt-get update -qq
    apt-get install -y -qq "${need[@]}" >/dev/null
fi

# 2. Already up?
if scontrol ping 2>/dev/null | grep -q "is UP" &&
   sinfo -h -o '%t' 2>/dev/null | grep -qE '^(idle|mix|alloc)'; then
    echo "start_local_cluster: a cluster is already running"
    sinfo
    exit 0
fi

# 3. Configuration.
if [ -f "$CONF" ] && ! grep -qF "$TAG" "$CONF"; then
    die "$CONF exists and was not written by this script; not touching it"
fi
host=$(hostname -s)
cpus=$(nproc)
mem=$(( $(free -m | awk '/^Mem:/ {print $2}') * 9 / 10 ))
mkdir -p /etc/slurm /var/lib/slurm/slurmctld /var/lib/slurm/slurmd /var/log/slurm "$PIDS"
chown slurm:slurm /var/lib/slurm/slurmctld /var/log/slurm
cat > "$CONF" <<EOF
$TAG
ClusterName=vcsmooth-local
SlurmctldHost=$host(127.0.0.1)
SlurmUser=slurm
AuthType=auth/munge
CredType=cred/munge
MpiDefault=none
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
SelectType=select/cons_tres
SelectTypeParameters=CR_Core_Memory
SchedulerType=sched/backfill
SchedulerParameters=batch_sched_delay=0
DependencyParameters=kill_invalid_depend
MaxArraySize=1001
ReturnToService=2
StateSaveLocation=/var/lib/slurm/slurmctld
SlurmdSpoolDir=/var/lib/slurm/slurmd
SlurmctldPidFile=$PIDS/slurmctld.pid
SlurmdPidFile=$PIDS/slurmd.pid
SlurmctldLogFile=/var/log/slurm/slurmctld.log
SlurmdLogFile=/var/log/slurm/slurmd.log
AccountingStorageType=accounting_storage/none
JobAcctGatherType=jobacct_gather/none
JobCompType=jobcomp/none
MinJobAge=600
NodeName=$host NodeAddr=127.0.0.1 CPUs=$cpus RealMemory=$mem State=UNKNOWN
PartitionName=debug Nodes=$host Default=YES MaxTime=INFINITE State=UP
EOF

# 4. Munge.
if ! munge -n 2>/dev/null | unmunge >/dev/null 2>&1; then
    [ -s /etc/munge/munge.key ] || { mungekey --create --force 2>/dev/null || \
        dd if=/dev/urandom of=/etc/munge/munge.key bs=1024 count=1 2>/dev/null; }
    chown munge:munge /etc/munge/munge.key && chmod 400 /etc/munge/munge.key
    mkdir -p /run/munge /var/lib/munge /var/log/munge
    chown munge:munge /run/munge /var/lib/munge /var/log/munge
    runuser -u munge -- /usr/sbin/munged --force
    for _ in $(seq 50); do munge -n 2>/dev/null | unmunge >/dev/null 2>&1 && break; sleep 0.1; done
    cp /run/munge/munged.pid "$PIDS/munged.pid" 2>/dev/null || pgrep -u munge -x munged | head -1 > "$PIDS/munged.pid"
    munge -n | unmunge >/dev/null || die "munged did not start"
fi

# 5. Slurm daemons (slurmctld drops to SlurmUser itself).
[ -f "$PIDS/slurmctld.pid" ] && kill -0 "$(cat "$PIDS/slurmctld.pid")" 2>/dev/null ||
    /usr/sbin/slurmctld -i
for _ in $(seq 100); do scontrol ping 2>/dev/null | grep -q "is UP" && break; sleep 0.2; done
scontrol ping | grep -q "is UP" || die "slurmctld did not come up; see /var/log/slurm/slurmctld.log"
[ -f "$PIDS/slurmd.pid" ] && kill -0 "$(cat "$PIDS/slurmd.pid")" 2>/dev/null ||
    /usr/sbin/slurmd
for _ in $(seq 150); do
    state=$(sinfo -h -n "$host" -o '%t' 2>/dev/null || true)
    case "$state" in idle|mix|alloc) break ;; esac
    sleep 0.2
done
case "$state" in
    idle|mix|alloc) ;;
    *) scontrol update NodeName="$host" State=RESUME 2>/dev/null || true; sleep 1
       state=$(sinfo -h -n "$host" -o '%t')
       case "$state" in idle|mix|alloc) ;; *) die "node $host is '$state'; see /var/log/slurm/slurmd.log" ;; esac ;;
esac
echo "start_local_cluster: up: node $host, $cpus CPUs, ${mem} MB, partition debug"
sinfo
