#!/usr/bin/env bash
# The 103M-triangle run of docs/performance.md's figures: the kitten scan of ../shared/meshes split into 4^6
# (103,407,616 triangles), noise 0.3 × mean edge length, vcs under a 1 GiB memory budget, through
# tools/billion_run.sh (phases, peak RssAnon, scratch bytes, disk high-water mark). Needs about
# 2 GB for the input, 2 GB for the output and 14 GB of scratch space in WORK_DIR.
#
#   tools/large_run.sh [WORK_DIR] [BUDGET] [ITERATIONS]
set -euo pipefail
here="$(cd "$(dirname "$0")/.." && pwd)"
exec "$here/tools/billion_run.sh" "${1:-/tmp/vcsmooth-large}" 6 "${2:-1G}" "${3:-2}" \
  "$here/../shared/meshes/kitten-25k.ply"
