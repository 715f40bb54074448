#!/usr/bin/env bash
# Integration test of the MPI mode under Slurm (e.g. the cluster tools/slurm/start_local_cluster.sh
# starts): one mesh smoothed by `mpirun -n 2 vcsmooth smooth ...` inside an `sbatch` job must be
# bit-identical to the single-process run at the same --patch-size; then the same job with
# --checkpoint is cancelled mid-run, resubmitted on a different rank count, and must again give the
# identical output.
#
#   tools/slurm/test_mpi.sh VCSMOOTH_BINARY    (built with --features mpi)
#
# Exits 0 on success. Leaves its files in $WORK (default: a new directory under /tmp, removed on
# success).
set -euo pipefail

bin=$(readlink -f "${1:?usage: test_mpi.sh VCSMOOTH_BINARY (built with --features mpi)}")
WORK=${WORK:-$(mktemp -d /tmp/vcsmooth-mpi-test.XXXXXX)}
mkdir -p "$WORK"
chmod 755 "$WORK"
timeout_s=${TIMEOUT:-300}
start=$(date +%s)
fail() { echo "test_mpi: FAIL: $*" >&2; echo "test_mpi: files kept in $WORK" >&2; exit 1; }
say() { echo "test_mpi: [$(( $(date +%s) - start )) s] $*"; }
state() { scontrol show job "$1" 2>/dev/null | grep -o 'JobState=[A-Z_]*' | head -1 | cut -d= -f2; }
wait_job() {
    while squeue -h -j "$1" -t PD,R,CG,CF 2>/dev/null | grep -q .; do
        [ $(( $(date +%s) - start )) -lt "$timeout_s" ] || fail "timed out waiting for job $1"
        sleep 0.5
    done
}
scontrol ping | grep -q "is UP" || fail "no Slurm controller (run tools/slurm/start_local_cluster.sh)"
command -v mpirun >/dev/null || fail "mpirun not found (Debian: openmpi-bin)"

"$bin" generate sphere "$WORK/in.ply" --subdivisions 7 --noise 0.4 --seed 7 >/dev/null
# 60 iterations: the default method takes tens of milliseconds for one at this size, and the
# cancel below needs a window of seconds.
common=(--iterations 60 --patch-size 4096)
"$bin" smooth "$WORK/in.ply" "$WORK/plain.ply" "${common[@]}" >/dev/null
say "single-process reference written"

# The job script users would write (README, "One mesh over MPI ranks"). Root needs OpenMPI's
# consent; --oversubscribe lets 3 ranks share the 2 CPUs of a small test node.
job() { # $1 ranks, $2 output, $3.. extra smooth options
    local ranks=$1 out=$2; shift 2
    cat <<EOF
#!/bin/bash
#SBATCH --job-name=vcs-mpi-test
#SBATCH --nodes=1
#SBATCH --ntasks=1
#SBATCH --cpus-per-task=2
#SBATCH --output=$WORK/slurm-%j.out
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1
mpirun -n $ranks --oversubscribe "$bin" smooth "$WORK/in.ply" "$out" ${common[*]} --threads 1 $*
EOF
}

job 2 "$WORK/mpi2.ply" --report "$WORK/mpi2.json" > "$WORK/job2.sh"
id=$(sbatch --parsable "$WORK/job2.sh")
wait_job "$id"
[ "$(state "$id")" = COMPLETED ] || { cat "$WORK"/slurm-"$id".out >&2; fail "job $id: $(state "$id")"; }
cmp "$WORK/plain.ply" "$WORK/mpi2.ply" || fail "2 ranks under sbatch differ from the single process"
grep -q '"ranks": 2' "$WORK/mpi2.json" || fail "report does not say 2 ranks"
say "sbatch + mpirun -n 2: bit-identical to the single process"

# Cancel a checkpointed job after its first recorded iterations; resume on 3 ranks.
job 2 "$WORK/ck.ply" --checkpoint "$WORK/ck" > "$WORK/job-ck.sh"
id=$(sbatch --parsable "$WORK/job-ck.sh")
done_iters() { python3 -c 'import json,sys; print(json.load(open(sys.argv[1]))["done"])' "$WORK/ck/state.json" 2>/dev/null || echo 0; }
while [ "$(done_iters)" -lt 2 ]; do
    s=$(state "$id")
    case "$s" in COMPLETED|FAILED|CANCELLED) fail "checkpointed job ended ($s) before it could be cancelled" ;; esac
    [ $(( $(date +%s) - start )) -lt "$timeout_s" ] || fail "timed out waiting for checkpoints"
    sleep 0.05
done
scancel "$id"
wait_job "$id"
at=$(done_iters)
[ "$at" -lt 60 ] || fail "the job finished before it was cancelled"
[ -e "$WORK/ck.ply" ] && fail "a cancelled job left an output"
say "cancelled job $id after $at iterations"
job 3 "$WORK/ck.ply" --checkpoint "$WORK/ck" --report "$WORK/ck.json" > "$WORK/job-resume.sh"
id=$(sbatch --parsable "$WORK/job-resume.sh")
wait_job "$id"
[ "$(state "$id")" = COMPLETED ] || { cat "$WORK"/slurm-"$id".out >&2; fail "resume job $id: $(state "$id")"; }
cmp "$WORK/plain.ply" "$WORK/ck.ply" || fail "the resumed run differs from the uninterrupted one"
grep -q '"resumed_after": [1-9]' "$WORK/ck.json" || fail "report does not show the resume"
say "PASS: resumed on 3 ranks after $at iterations: bit-identical"
[ -n "${KEEP:-}" ] || rm -rf "$WORK"
