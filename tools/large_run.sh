#!/usr/bin/env bash
# Smooth a mesh of more than 100M triangles under a 1 GiB memory budget and print the peak
# anonymous memory (RssAnon; the memory-mapped input and scratch files are file-backed and do not
# count). Needs about 2 GB for the input, 2 GB for the output and 13 GB of scratch space in WORK.
#
#   tools/large_run.sh [WORK_DIR] [BUDGET] [ITERATIONS]
#
# The input is the kitten scan of ../shared/meshes split into 4^6 (103,407,616 triangles) by the
# streaming generator, with noise 0.3 × mean edge length.
set -euo pipefail
here="$(cd "$(dirname "$0")/.." && pwd)"
work="${1:-/tmp/vcsmooth-large}"
budget="${2:-1G}"
iterations="${3:-2}"
mkdir -p "$work"
cargo build --release --manifest-path "$here/Cargo.toml" >&2
bin="$here/target/release/vcsmooth"
input="$work/kitten-x4096.ply"
if [ ! -f "$input" ]; then
  "$bin" generate mesh "$input" --from "$here/../shared/meshes/kitten-25k.ply" --subdivide 6 --noise 0.3
fi
"$bin" smooth "$input" "$work/smoothed.ply" --method vcs --iterations "$iterations" \
  --memory-budget "$budget" --scratch "$work" --report "$work/report.json"
python3 - "$work/report.json" "$budget" <<'PY'
import json, sys
r = json.load(open(sys.argv[1]))
m, t = r["memory"], r["timings"]
print(f"triangles {r['input']['stats']['triangles']:,}, storage {m['storage']}, budget {m['budget'] / 2**30:.2f} GiB")
print(f"peak anonymous memory (RssAnon): {m['peak_anon'] / 2**20:.1f} MiB  "
      f"({'within' if m['peak_anon'] <= m['budget'] else 'OVER'} the budget)")
print(f"volume {r['summary']['volume_pct']:.9f} %, seconds total {t['total']:.1f} "
      f"(ingest {t['ingest']:.1f}, reorder {t['reorder']:.1f}, topology {t['topology']:.1f}, "
      f"smoothing {t['smoothing']:.1f}, write {t['write']:.1f})")
sys.exit(0 if m["peak_anon"] <= m["budget"] else 1)
PY
rm -f "$work/smoothed.ply"
