#!/usr/bin/env bash
# Issue #13's run: a scan subdivided to about a billion triangles, smoothed out of core under a
# memory budget, with every phase's time, the peak anonymous memory (RssAnon), the scratch bytes
# and the disk high-water mark of the work directory's file system.
#
#   tools/billion_run.sh [WORK_DIR] [LEVEL] [BUDGET] [ITERATIONS] [SOURCE] [METHOD]
#
# Defaults: /tmp/vcsmooth-billion, level 7 (the bunny's 69,451 triangles × 4^7 = 1,137,885,184),
# 1G, 2 iterations, ../shared/meshes/stanford-bunny.ply, vcs (`default` runs the default
# method). Level 5 (71M triangles) checks the script in a few minutes. The input is generated once and kept (generation is not part of
# the timed run); the output is removed after the figures are printed.
#
# Before it smooths, it refuses to start when the free space cannot hold the scratch files and
# the output by the estimate below: the larger of the smoothing's scratch (the most alive at once
# on the bunny, an open mesh, the report's memory.scratch_peak_bytes: 45.3 bytes per triangle
# for vcs since stop 65, 45.7 for the default method at stop 66, rounded up) and the write's (the
# smoothed positions and the triangles, 24 bytes per triangle since stop 63) beside the output
# it writes (a binary PLY holds about 19 bytes per triangle).
set -euo pipefail
here="$(cd "$(dirname "$0")/.." && pwd)"
work="${1:-/tmp/vcsmooth-billion}"
level="${2:-7}"
budget="${3:-1G}"
iterations="${4:-2}"
source="${5:-$here/../shared/meshes/stanford-bunny.ply}"
method="${6:-vcs}"
method_args=()
[ "$method" = default ] || method_args=(--method "$method")
# shellcheck source=tools/subdivided_input.sh
. "$here/tools/subdivided_input.sh"
subdivided_input "$work" "$level" "$source"
triangles=$(python3 -c "
import re, sys
head = open(sys.argv[1], 'rb').read(4096).split(b'end_header')[0].decode('ascii', 'replace')
print(re.search(r'element face (\d+)', head).group(1))" "$input")
free=$(df --output=avail -B1 "$work" | tail -1)
need=$(python3 -c "print(int($triangles * max(45.8, 24 + 19)))")
echo "input $input: $triangles triangles, $(du -h "$input" | cut -f1); free $((free / 2**30)) GiB, estimated need $((need / 2**30)) GiB" >&2
if [ "$need" -gt "$free" ]; then
  echo "billion_run: not enough free disk in $work for the output and the scratch files" >&2
  exit 1
fi

# The disk high-water mark: the most the work directory's file system had in use while smoothing.
used_file="$work/.disk-used"
base=$(df --output=used -B1 "$work" | tail -1)
( max=$base; while :; do
    u=$(df --output=used -B1 "$work" | tail -1); [ "$u" -gt "$max" ] && max=$u && echo "$max" > "$used_file"
    sleep 1
  done ) &
sampler=$!
trap 'kill $sampler 2>/dev/null || true' EXIT
echo "$base" > "$used_file"
start=$(date +%s.%N)
"$bin" smooth "$input" "$work/smoothed.ply" "${method_args[@]}" --iterations "$iterations" \
  --memory-budget "$budget" --scratch "$work" --report "$work/report.json"
end=$(date +%s.%N)
kill $sampler 2>/dev/null || true
python3 - "$work/report.json" "$base" "$(cat "$used_file")" "$start" "$end" "$method" <<'PY'
import json, sys
r = json.load(open(sys.argv[1]))
base, high, start, end = int(sys.argv[2]), int(sys.argv[3]), float(sys.argv[4]), float(sys.argv[5])
m, t = r["memory"], r["timings"]
n = r["input"]["stats"]["triangles"]
gib = 2**30
print(f"triangles {n:,}, method {sys.argv[6]}, {len(r['iterations'])} iterations, storage {m['storage']}, "
      f"budget {m['budget'] / gib:.2f} GiB")
print(f"wall {end - start:.1f} s; phases: " + ", ".join(
    f"{k} {t[k]:.1f}" for k in ("ingest", "reorder", "topology", "partition", "smoothing",
                               "write", "metrics", "total") if k in t))
print(f"peak anonymous memory (RssAnon): {m['peak_anon'] / 2**20:.1f} MiB "
      f"({'within' if m['peak_anon'] <= m['budget'] else 'OVER'} the budget)")
print(f"scratch bytes: {m['scratch_bytes'] / gib:.2f} GiB in all ({m['scratch_bytes'] / n:.1f} B per triangle), "
      f"at most {m['scratch_peak_bytes'] / gib:.2f} GiB at once ({m['scratch_peak_bytes'] / n:.1f} B per triangle)")
print(f"disk high-water above the start: {(high - base) / gib:.2f} GiB "
      f"({(high - base) / n:.1f} B per triangle; output and scratch, sampled every second)")
d = r.get("disk")
if d:
    print("disk read / written, GiB: " + ", ".join(
        f"{k} {d[k]['disk_read_bytes'] / gib:.2f} / {d[k]['disk_written_bytes'] / gib:.2f}"
        for k in ("ingest", "reorder", "topology", "partition", "smoothing", "restore", "write",
                  "total")))
print(f"volume change {r['summary']['volume_pct'] - 100:.3e} % of the input's")
sys.exit(0 if m["peak_anon"] <= m["budget"] else 1)
PY
rm -f "$work/smoothed.ply" "$used_file"
