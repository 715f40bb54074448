#!/bin/sh
# Seed the fuzzers' corpora (fuzz/corpus/<target>/, not committed) from the hostile-input corpus of
# tests/corpus/cases.rs, small generated meshes, and the first 3 KB of each mesh in ../shared/meshes.
# Run from the repository root: sh fuzz/seed.sh
set -eu
cargo build -q --bin vcsmooth
dump=$(mktemp -d)
VCSMOOTH_DUMP_CORPUS="$dump" cargo test -q --test tests dump_corpus >/dev/null
for t in ply obj off stl; do
    mkdir -p "fuzz/corpus/$t"
    cp "$dump"/*."$t" "fuzz/corpus/$t/" 2>/dev/null || true
    for k in 0 1; do
        target/debug/vcsmooth generate sphere "fuzz/corpus/$t/sphere$k.$t" --subdivisions "$k" >/dev/null
    done
done
cp "$dump"/*.dat "$dump"/*.bin fuzz/corpus/ply/
for m in ../shared/meshes/*.ply; do
    [ -f "$m" ] && head -c 3000 "$m" >"fuzz/corpus/ply/slice-$(basename "$m")"
done
target/debug/vcsmooth generate torus fuzz/corpus/obj/torus0.obj --subdivisions 0 >/dev/null
rm -r "$dump"
