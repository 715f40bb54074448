#!/usr/bin/env bash
# Integration test of `vcsmooth slurm-script` / `vcsmooth batch` on a real Slurm cluster (e.g. the
# one tools/slurm/start_local_cluster.sh starts):
#
#   1. generate 10 noisy spheres; `vcsmooth slurm-script --max-array-size 5` → 5 array tasks of
#      2 inputs each, plus a summary job (afterany);
#   2. run the wrapper; once array task 4 is running, `scancel JOB_4`;
#   3. wait: tasks 0-3 COMPLETED, task 4 CANCELLED, its inputs without a marker, the summary job
#      FAILED (it lists them as missing);
#   4. rerun task 4 with the wrapper (`bash submit.sh 4`), wait: the new summary job COMPLETED,
#      summary.json lists all 10 meshes, nothing missing, every output present, volume ≈ 100 %,
#      and the markers of tasks 0-3 were not rewritten.
#
#   tools/slurm/test_array.sh [VCSMOOTH_BINARY]   (default: target/debug/vcsmooth, built if missing)
#
# Exits 0 on success. Takes about 45 s on 2 cores. Leaves its files in $WORK (default: a new
# directory under /tmp, removed on success). Jobs run as the calling user; the directory must be
# visible to the node (here: the same machine).
set -euo pipefail

root=$(cd "$(dirname "$0")/../.." && pwd)
bin=${1:-$root/target/debug/vcsmooth}
if [ ! -x "$bin" ]; then (cd "$root" && cargo build --quiet); fi
bin=$(readlink -f "$bin")
WORK=${WORK:-$(mktemp -d /tmp/vcsmooth-slurm-test.XXXXXX)}
mkdir -p "$WORK"
chmod 755 "$WORK"
in=$WORK/in
out=$WORK/out
mkdir -p "$in"
n=10
timeout_s=${TIMEOUT:-420}
start=$(date +%s)

fail() { echo "test_array: FAIL: $*" >&2; echo "test_array: files kept in $WORK" >&2; exit 1; }
say() { echo "test_array: [$(( $(date +%s) - start )) s] $*"; }

scontrol ping | grep -q "is UP" || fail "no Slurm controller (run tools/slurm/start_local_cluster.sh)"

# Job state of job (or array element) $1, from scontrol (finished jobs are kept for MinJobAge).
state() { scontrol show job "$1" 2>/dev/null | grep -o 'JobState=[A-Z_]*' | head -1 | cut -d= -f2; }
# Wait until none of the jobs $@ is pending or running.
wait_jobs() {
    while squeue -h -j "$(IFS=,; echo "$*")" -t PD,R,CG,CF 2>/dev/null | grep -q .; do
        [ $(( $(date +%s) - start )) -lt "$timeout_s" ] || fail "timed out waiting for jobs $*"
        sleep 0.5
    done
}

for k in $(seq 0 $((n - 1))); do
    "$bin" generate sphere "$in/m$k.ply" --subdivisions 4 --noise 0.3 --seed "$k" >/dev/null
done
say "generated $n meshes in $in"

# 3000 iterations: a task runs for tens of seconds, so that the kill below lands while task 4 runs
# even on a loaded machine, where Slurm may report a task RUNNING 15 s late (at 1000, under the
# other MPI tests, task 4 once finished both of its inputs before the kill).
"$bin" slurm-script "$in" "$out" --iterations 3000 --cpus 1 --max-array-size 5 \
    --job-name vcs-test > "$WORK/submit.sh"
grep -q -- '--array=0-4' "$WORK/submit.sh" || fail "expected --array=0-4 in $WORK/submit.sh"
submitted=$(bash "$WORK/submit.sh")
say "$submitted"
array_job=$(echo "$submitted" | sed -n 's/^array job \([0-9]*\), summary job \([0-9]*\)$/\1/p')
summary_job=$(echo "$submitted" | sed -n 's/^array job \([0-9]*\), summary job \([0-9]*\)$/\2/p')
[ -n "$array_job" ] && [ -n "$summary_job" ] || fail "cannot parse: $submitted"

# Kill task 4 once it runs.
while [ "$(state "${array_job}_4")" != RUNNING ]; do
    s=$(state "${array_job}_4")
    case "$s" in COMPLETED|FAILED|CANCELLED) fail "task 4 ended ($s) before it could be killed" ;; esac
    [ $(( $(date +%s) - start )) -lt "$timeout_s" ] || fail "timed out waiting for task 4 to run"
    sleep 0.1
done
scancel "${array_job}_4"
say "cancelled running task ${array_job}_4"
wait_jobs "$array_job" "$summary_job"

for t in 0 1 2 3; do
    [ "$(state "${array_job}_$t")" = COMPLETED ] || fail "task $t: $(state "${array_job}_$t")"
done
[ "$(state "${array_job}_4")" = CANCELLED ] || fail "task 4: $(state "${array_job}_4"), expected CANCELLED"
[ -e "$out/.done/m9.json" ] && fail "task 4 was killed but m9 has a marker"
[ "$(state "$summary_job")" = FAILED ] || fail "first summary job: $(state "$summary_job"), expected FAILED"
grep -q "m9.ply" "$out/.slurm/summary-$summary_job.out" || fail "first summary does not name m9 as missing"
say "after the kill: tasks 0-3 COMPLETED, task 4 CANCELLED, summary FAILED listing the missing inputs"

# Markers of the finished tasks, to check they are not redone.
declare -A before
for k in 0 1 2 3 5 6 7 8; do before[$k]=$(stat -c %Y.%y "$out/.done/m$k.json"); done

submitted=$(bash "$WORK/submit.sh" 4)
say "rerun: $submitted"
rerun_job=$(echo "$submitted" | sed -n 's/^array job \([0-9]*\), summary job \([0-9]*\)$/\1/p')
summary_job=$(echo "$submitted" | sed -n 's/^array job \([0-9]*\), summary job \([0-9]*\)$/\2/p')
wait_jobs "$rerun_job" "$summary_job"
[ "$(state "${rerun_job}_4")" = COMPLETED ] || fail "rerun of task 4: $(state "${rerun_job}_4")"
[ "$(state "$summary_job")" = COMPLETED ] || {
    cat "$out/.slurm/summary-$summary_job.out" >&2; fail "second summary job: $(state "$summary_job")"; }

for k in $(seq 0 $((n - 1))); do
    [ -s "$out/m$k.ply" ] || fail "output m$k.ply missing"
    [ -s "$out/.done/m$k.json" ] || fail "marker of m$k missing"
done
for k in 0 1 2 3 5 6 7 8; do
    [ "${before[$k]}" = "$(stat -c %Y.%y "$out/.done/m$k.json")" ] || fail "m$k was redone by the rerun"
done
ls -A "$out" | grep -q '\.tmp-' && fail "temporary files left in $out"
python3 - "$out/summary.json" "$n" <<'EOF' || fail "summary.json check failed"
import json, sys
s = json.load(open(sys.argv[1]))
n = int(sys.argv[2])
assert len(s["meshes"]) == n, len(s["meshes"])
assert s["inputs"] == n and s["missing"] == [] and s["unreadable"] == [], s
for m in s["meshes"]:
    assert m["iterations"] == 3000 and m["triangles"] == 5120, m
    assert abs(m["volume_pct"] - 100) < 1e-6, m
    assert m["slurm"] and m["slurm"]["array_job_id"], m
EOF
say "PASS: $n outputs, markers and summary.json complete after killing and rerunning one task"
cat "$out/.slurm/summary-$summary_job.out"
[ -n "${KEEP:-}" ] || rm -rf "$WORK"
