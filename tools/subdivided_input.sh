# Sourced by tools/billion_run.sh and tools/out_of_core_ratio.sh: builds the release binary and
# makes, once, the large input they time (generation is never part of a timed run).
#
#   subdivided_input WORK LEVEL SOURCE   sets $bin (the binary) and $input (SOURCE × 4^LEVEL,
#                                        noise 0.3 × mean edge length, in WORK)
subdivided_input() {
  local work="$1" level="$2" source="$3"
  local here
  here="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
  mkdir -p "$work"
  cargo build --release --manifest-path "$here/Cargo.toml" >&2
  bin="$here/target/release/vcsmooth"
  input="$work/$(basename "${source%.*}")-x4^$level.ply"
  if [ ! -f "$input" ]; then
    echo "generating $input (not timed)" >&2
    "$bin" generate mesh "$input" --from "$source" --subdivide "$level" --noise 0.3
  fi
}
