#!/bin/sh
# bench/bvh.sh [OUTDIR] - the BVH benchmark (bench/bvh_bench.c) in three builds:
# the default one (SSE2 on x86-64, NEON on aarch64: each 8-wide node in two
# 4-wide halves), one with -march=native (AVX2 where the CPU has it: a node in
# one 8-wide vector) and the scalar one (-DAPPM_SIMD=0).  Each run compares the binary tree, the wide tree with the
# scalar box test and the wide tree with the build's SIMD test, interleaved, as
# medians of 3 (see bench/bvh_bench.c).  Writes OUTDIR/bvh.md (default bench/out).
# BVH_RAYS (default 1000000) and BVH_SIZE (photon pass image side, default 512)
# make it shorter; BVH_ROUNDS (default 3) sets the rounds each median is taken
# over (the wall-clock photon figures want 5 or more on a shared machine).
set -u
out=${1:-bench/out}
CC=${CC:-cc}
rays=${BVH_RAYS:-1000000}
size=${BVH_SIZE:-512}
mkdir -p "$out"
{
    echo "## BVH (stanford-bunny, $rays rays; photon pass: CornellBox-Sphere at ${size}x$size)"
    echo
    echo "    $(date -u '+%Y-%m-%d %H:%M UTC'), $(uname -sm), $($CC --version 2>/dev/null | head -n 1)"
} > "$out/bvh.md"
for v in "default:" "native:-march=native" "scalar:-DAPPM_SIMD=0"; do
    name=${v%%:*} flags=${v#*:}
    # shellcheck disable=SC2086 # $flags is a word list
    $CC -std=c99 -O2 $flags bench/bvh_bench.c -o "$out/bvh_bench-$name" -lm -pthread || exit 1
    {
        echo
        echo "$name build (-O2 $flags):"
        echo
        "$out/bvh_bench-$name" scenes/stanford-bunny.obj "$rays" scenes/cornell-sphere.scene "$size" |
            sed 's/^/    /'
    } >> "$out/bvh.md"
done
cat "$out/bvh.md"
