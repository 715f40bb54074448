#!/usr/bin/env bash
# Issue #6 targets for `smooth --multires` against plain `vcs`, on a real scan subdivided to ≥ 4M
# triangles with normal noise σ = 0.5 × mean edge (and a clean copy: same subdivision, no noise).
#
#   tools/multires_targets.sh [SCAN] [SUBDIVIDE]      (defaults: armadillo-86k, 3 → 5.5M triangles)
#   env: DIR (work directory, default /tmp/vcsmooth-multires), VCS_ITERATIONS (10), REPEATS (5),
#        MR_ARGS (extra flags for the multires runs, e.g. "--transfer constant --levels 2").
#
# 1. plain vcs, VCS_ITERATIONS iterations: its roughness (mean dihedral angle) is the target X;
# 2. multires with the fewest fine iterations whose roughness is ≤ X;
# 3. REPEATS timings of both, interleaved (vcs, multires, vcs, …) so both see the same load;
#    medians of the smoothing phase (everything between reading and writing, the multires
#    hierarchy included) and of the whole command.
# Prints roughness, volume change against the noisy input and vertex-to-vertex RMS distance to
# the clean mesh for both, and the time ratios.
set -euo pipefail
cd "$(dirname "$0")/.."
SCAN=${1:-../shared/meshes/armadillo-86k.ply}
SUB=${2:-3}
DIR=${DIR:-/tmp/vcsmooth-multires}
N=${VCS_ITERATIONS:-10}
REPEATS=${REPEATS:-5}
MR_ARGS=${MR_ARGS:-}
cargo build --release --quiet
B=target/release/vcsmooth
mkdir -p "$DIR"
stem=$(basename "$SCAN" .ply)-s$SUB
clean=$DIR/$stem-clean.ply
noisy=$DIR/$stem-noisy.ply
[ -f "$clean" ] || $B generate mesh "$clean" --from "$SCAN" --subdivide "$SUB" --noise 0 --seed 1 >/dev/null
[ -f "$noisy" ] || $B generate mesh "$noisy" --from "$SCAN" --subdivide "$SUB" --noise 0.5 --seed 1 >/dev/null

json() { python3 -c "import json,sys; print(json.load(sys.stdin)['$1'])"; }
roughness() { $B info "$1" --json | json roughness_deg; }
# Seconds of the smoothing phase and of the whole run, from `smooth`'s last line.
run() {
    local out=$1; shift
    local log
    log=$($B smooth "$noisy" "$out" "$@")
    echo "$log" | awk '/^seconds:/ { for (i = 1; i <= NF; i++) { if ($i == "smoothing") s = $(i+1); if ($i == "total") t = $(i+1) } gsub(",", "", s); print s, t }'
}
median() { sort -g | awk '{ a[NR] = $1 } END { print (NR % 2) ? a[(NR + 1) / 2] : (a[NR / 2] + a[NR / 2 + 1]) / 2 }'; }

echo "input: $noisy ($($B info "$noisy" --json | json triangles) triangles), roughness $(roughness "$noisy")°; clean $(roughness "$clean")°"
vcs_out=$DIR/vcs.ply
mr_out=$DIR/multires.ply
run "$vcs_out" --method vcs --iterations "$N" >/dev/null
X=$(roughness "$vcs_out")
echo "target X = roughness of vcs after $N iterations = $X°"

f=1
while :; do
    # shellcheck disable=SC2086
    run "$mr_out" --multires --iterations "$f" $MR_ARGS >/dev/null
    r=$(roughness "$mr_out")
    if python3 -c "import sys; sys.exit(0 if $r <= $X else 1)"; then break; fi
    f=$((f + 1))
    if [ "$f" -gt 100 ]; then echo "multires does not reach $X° in 100 iterations" >&2; exit 1; fi
done
echo "multires reaches it with --iterations $f ($r°); flags: --multires --iterations $f $MR_ARGS"

: >"$DIR/t_vcs"; : >"$DIR/t_mr"
for _ in $(seq "$REPEATS"); do
    run "$vcs_out" --method vcs --iterations "$N" >>"$DIR/t_vcs"
    # shellcheck disable=SC2086
    run "$mr_out" --multires --iterations "$f" $MR_ARGS >>"$DIR/t_mr"
done
vs=$(cut -d' ' -f1 "$DIR/t_vcs" | median); vt=$(cut -d' ' -f2 "$DIR/t_vcs" | median)
ms=$(cut -d' ' -f1 "$DIR/t_mr" | median); mt=$(cut -d' ' -f2 "$DIR/t_mr" | median)

row() {
    local name=$1 out=$2 s=$3 t=$4
    local vol rms
    vol=$($B compare "$noisy" "$out" --json | json volume_ratio)
    rms=$($B compare "$clean" "$out" --json | json rms_distance)
    python3 -c "print(f'{\"$name\":<10} {$(roughness "$out"):>12.4f} {abs($vol - 1) * 100:>14.2e} {$rms:>14.4e} {$s:>11.3f} {$t:>9.3f}')"
}
echo
printf '%-10s %12s %14s %14s %11s %9s\n' method "roughness °" "|ΔV| / V %" "RMS to clean" "smoothing s" "total s"
row vcs "$vcs_out" "$vs" "$vt"
row multires "$mr_out" "$ms" "$mt"
python3 -c "print(f'speed-up (medians of $REPEATS, interleaved): smoothing {$vs / $ms:.2f}x, whole command {$vt / $mt:.2f}x')"
echo "RMS ratio multires / vcs: $(python3 -c "print(f'{$($B compare "$clean" "$mr_out" --json | json rms_distance) / $($B compare "$clean" "$vcs_out" --json | json rms_distance):.3f}')")"
