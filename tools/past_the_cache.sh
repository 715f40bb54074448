#!/usr/bin/env bash
# Runs a command with the page cache it may fill limited to LIMIT, so that a mesh of a few
# gigabytes meets out of core what the billion-triangle run meets on this machine (issue #33):
# a sweep whose scratch is about twice the page cache. The bunny x4^5 (71,117,824 triangles,
# 2.98 GiB of scratch for vcs) under 1536M is the ratio of the bunny x4^7 (47.6 GiB of scratch,
# about 22 GiB of page cache), in two minutes instead of thirty-five:
#
#   vcsmooth generate mesh b5.ply --from ../shared/meshes/stanford-bunny.ply --subdivide 5 --noise 0.3
#   sync; echo 3 > /proc/sys/vm/drop_caches
#   tools/past_the_cache.sh 1536M target/release/vcsmooth smooth b5.ply o.ply --method vcs \
#     --iterations 1 --memory-budget 256M --scratch . --report r.json
#
# The report's `disk` gives what each phase read from the disk. Needs root and a memory cgroup
# (v1 `/sys/fs/cgroup/memory` or v2 with the memory controller); the group is removed at the end.
set -euo pipefail
if [ $# -lt 2 ]; then
  echo "usage: tools/past_the_cache.sh LIMIT COMMAND [ARGS...]" >&2
  exit 2
fi
limit="$1"
shift
name="vcsmooth-past-the-cache-$$"
if [ -d /sys/fs/cgroup/memory ] && [ -w /sys/fs/cgroup/memory ]; then
  group="/sys/fs/cgroup/memory/$name"
  mkdir "$group"
  echo "$limit" > "$group/memory.limit_in_bytes"
elif grep -qw memory /sys/fs/cgroup/cgroup.controllers 2>/dev/null; then
  group="/sys/fs/cgroup/$name"
  mkdir "$group"
  echo "$limit" > "$group/memory.max"
else
  echo "past_the_cache: no writable memory cgroup on this machine" >&2
  exit 1
fi
trap 'rmdir "$group" 2>/dev/null || true' EXIT
# The command runs in a child shell moved into the group, so this script can remove the group.
status=0
bash -c 'echo $$ > "$1/cgroup.procs"; shift; exec "$@"' _ "$group" "$@" || status=$?
exit "$status"
