#!/usr/bin/env bash
# Issue #18 targets 1 and 2: how the phases of `smooth` scale from 1 to 2 threads, and what share
# of a run the statistics (`--report`) take.
#
#   tools/thread_scaling.sh MESH [METHOD] [ITERATIONS] [RUNS]     (defaults: vcs, 3, 5)
#   env: DIR (work directory for outputs and reports, default /tmp/vcsmooth-scaling)
#
# Runs `smooth MESH --report` RUNS times with --threads 1 and --threads 2, alternating (1, 2, 1, …)
# so that both see the same load, with the release binary (built first). Prints the per-phase
# medians for each thread count and their ratio, the median total ratio (target ≥ 1.8 on a mesh of
# ≥ 4M triangles), and the statistics' share of the run, two ways (target ≤ 10 %): the `metrics`
# phase over the total (median per thread count), and what the statistics add to the wall time
# (each round also runs without --report, which computes no statistics: the median wall time with
# minus without, over the median with). The two differ because the output's statistics run beside
# the write, so the `metrics` phase counts time the run spends anyway. Also checks that both thread
# counts wrote the same bytes.
set -euo pipefail
[ $# -ge 1 ] || { sed -n '2,12p' "$0" >&2; exit 2; }
mesh=$1
method=${2:-vcs}
iterations=${3:-3}
runs=${4:-5}
dir=${DIR:-/tmp/vcsmooth-scaling}
cd "$(dirname "$0")/.."
cargo build --release --quiet
bin=$PWD/target/release/vcsmooth
mkdir -p "$dir"

wall() { # start and end of the command "$@", appended to the file named by the first argument
  local out=$1 start end
  shift
  start=$(date +%s.%N)
  "$@" >/dev/null 2>&1
  end=$(date +%s.%N)
  echo "$start $end" >>"$out"
}

rm -f "$dir"/wall-*
for run in $(seq 1 "$runs"); do
  for t in 1 2; do
    wall "$dir/wall-with-t$t" "$bin" smooth "$mesh" "$dir/out-t$t.ply" --method "$method" \
      --iterations "$iterations" --threads "$t" --report "$dir/report-t$t-$run.json"
    wall "$dir/wall-without-t$t" "$bin" smooth "$mesh" "$dir/out-t$t.ply" --method "$method" \
      --iterations "$iterations" --threads "$t"
  done
  cmp -s "$dir/out-t1.ply" "$dir/out-t2.ply" || { echo "run $run: outputs differ" >&2; exit 1; }
  echo "run $run/$runs done" >&2
done

python3 - "$dir" "$runs" <<'PY'
import json, statistics, sys
d, runs = sys.argv[1], int(sys.argv[2])
t = {n: [json.load(open(f"{d}/report-t{n}-{r}.json"))["timings"] for r in range(1, runs + 1)]
     for n in (1, 2)}
phases = list(t[1][0])
med = {n: {p: statistics.median(x[p] for x in t[n]) for p in phases} for n in (1, 2)}
print(f"{'phase':<10} {'1 thread':>9} {'2 threads':>9} {'ratio':>6}   (medians of {runs} runs, s)")
for p in phases:
    a, b = med[1][p], med[2][p]
    print(f"{p:<10} {a:9.3f} {b:9.3f} {a / b if b else float('nan'):6.2f}")
ratios = [x["total"] / y["total"] for x, y in zip(t[1], t[2])]
print(f"total ratio 1/2 threads: {med[1]['total'] / med[2]['total']:.2f} (of medians), "
      f"{statistics.median(ratios):.2f} (median of the runs' ratios)")
for n in (1, 2):
    share = statistics.median(x["metrics"] / x["total"] for x in t[n])
    wall = {w: statistics.median(float(b) - float(a) for a, b in map(str.split, open(f"{d}/wall-{w}-t{n}")))
            for w in ("with", "without")}
    added = wall["with"] - wall["without"]
    print(f"statistics share, {n} thread{'s' if n > 1 else ''}: {100 * share:.1f} % of the total "
          f"(metrics phase); {100 * added / wall['with']:.1f} % of the wall time "
          f"({wall['with']:.3f} s with --report, {wall['without']:.3f} s without)")
PY
