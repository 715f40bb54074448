#!/usr/bin/env bash
# Issue #13's target 3: the vcs sweep out of core (scratch files under a 1 GiB budget) against the
# same sweep in core, on the same mesh, runs alternating so that the machine's drift falls on both.
# Prints each run's phases and edge stencils per second, then the medians and their ratio.
#
#   tools/out_of_core_ratio.sh [WORK_DIR] [LEVEL] [ROUNDS] [ITERATIONS] [SOURCE]
#
# Defaults: /tmp/vcsmooth-large, level 6 of ../shared/meshes/kitten-25k.ply (103,407,616
# triangles: the mesh of tools/large_run.sh), 3 rounds, 2 iterations. The in-core run needs about
# 95 bytes per triangle of memory (9.2 GiB at level 6); the out-of-core one about as much free
# disk in WORK_DIR, beside 2 × 19 bytes per triangle for the input and output. BUDGET (default
# 1G) is the out-of-core runs' --memory-budget; the mesh must be larger than it.
set -euo pipefail
here="$(cd "$(dirname "$0")/.." && pwd)"
work="${1:-/tmp/vcsmooth-large}"
level="${2:-6}"
rounds="${3:-3}"
iterations="${4:-2}"
source="${5:-$here/../shared/meshes/kitten-25k.ply}"
# shellcheck source=tools/subdivided_input.sh
. "$here/tools/subdivided_input.sh"
subdivided_input "$work" "$level" "$source"
trap 'rm -f "$work/ratio-out.ply"' EXIT
reports=()
for r in $(seq 1 "$rounds"); do
  for mode in in-core out-of-core; do
    extra=()
    [ "$mode" = out-of-core ] && extra=(--memory-budget "${BUDGET:-1G}" --scratch "$work")
    sync
    "$bin" smooth "$input" "$work/ratio-out.ply" --method vcs --iterations "$iterations" \
      "${extra[@]}" --report "$work/ratio-$mode-$r.json" > /dev/null
    reports+=("$work/ratio-$mode-$r.json")
  done
done
python3 - "${reports[@]}" <<'PY'
import json, statistics, sys
rates = {"heap": [], "scratch": []}
for path in sys.argv[1:]:
    r = json.load(open(path))
    t, its = r["timings"], r["iterations"]
    stencils = sum(i["stencils"]["applied"] + i["stencils"]["rejected"]
                   + i["stencils"]["skipped_fixed"] + i["stencils"]["skipped_degenerate"] for i in its)
    seconds = sum(i["seconds"] for i in its)
    rate = stencils / seconds / 1e6
    storage = r["memory"]["storage"]
    rates[storage].append(rate)
    print(f"{storage:7s} smoothing {t['smoothing']:6.1f} s, iterations "
          + " / ".join(f"{i['seconds']:.1f}" for i in its)
          + f" s, {rate:.2f} M edge stencils/s; total {t['total']:.1f} s, "
          f"peak anonymous {r['memory']['peak_anon'] / 2**30:.2f} GiB, "
          f"scratch at most {r['memory']['scratch_peak_bytes'] / 2**30:.2f} GiB")
if not rates["scratch"]:
    sys.exit("out_of_core_ratio: the mesh fits the budget, so no run went out of core; "
             "take a higher level or a lower BUDGET")
a, b = statistics.median(rates["heap"]), statistics.median(rates["scratch"])
print(f"median: in core {a:.2f}, out of core {b:.2f} M edge stencils/s: out of core = {b / a:.2f}x in core")
PY
rm -f "$work"/ratio-*.json
