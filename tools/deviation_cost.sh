#!/bin/sh
# What the deviation field, its statistics and the report's SHA-256 cost a run: `smooth` with and
# without `--deviation-field --deviation-colours`, both with `--report` (whose timings say the
# field's seconds, `timings.deviation`, and the hash's, `timings.hash`), REPEATS times each (3),
# medians.
#
#   tools/deviation_cost.sh [DIR] [EXTRA SMOOTH FLAGS...]
#   MESH=path/to/in.ply tools/deviation_cost.sh /big/tmp --memory-budget 1G
#
# Without MESH it generates a noisy level-9 icosphere (5,242,880 triangles) in DIR.
set -eu
BIN=${VCSMOOTH:-target/release/vcsmooth}
DIR=${1:-/dev/shm/vcsmooth-deviation}
[ $# -gt 0 ] && shift
mkdir -p "$DIR"
MESH=${MESH:-$DIR/s9.ply}
[ -f "$MESH" ] || "$BIN" generate sphere "$MESH" --subdivisions 9 --noise 0.3 >/dev/null
for k in $(seq 1 "${REPEATS:-3}"); do
    "$BIN" smooth "$MESH" "$DIR/plain.ply" --report "$DIR/plain-$k.json" "$@" >/dev/null
    "$BIN" smooth "$MESH" "$DIR/field.ply" --deviation-field --deviation-colours \
        --report "$DIR/field-$k.json" "$@" >/dev/null
done
python3 - "$DIR" "${REPEATS:-3}" <<'PY'
import json, statistics, sys
d, n = sys.argv[1], int(sys.argv[2])
def med(kind, key):
    return statistics.median(json.load(open(f"{d}/{kind}-{k}.json"))["timings"][key] for k in range(1, n + 1))
r = json.load(open(f"{d}/field-1.json"))
print(f"{r['input']['stats']['triangles']} triangles, storage {r['memory']['storage']}, {r['machine']['threads']} threads")
for key in ("total", "write", "deviation", "hash"):
    print(f"{key:>10}: plain {med('plain', key):8.3f} s   field {med('field', key):8.3f} s")
plain, field = med("plain", "total"), med("field", "total")
print(f"field + statistics: {field - plain:+.3f} s on the total ({100 * (field - plain) / plain:+.1f} %); "
      f"its own phase {med('field', 'deviation'):.3f} s ({100 * med('field', 'deviation') / plain:.1f} %)")
print(f"SHA-256 of the input: {med('plain', 'hash'):.3f} s ({100 * med('plain', 'hash') / plain:.1f} % of the run)")
PY
