#!/bin/sh
# bench/lapdiag.sh - appm's Laplacian against the reference's at the pixel scale,
# edges and smooth pixels apart (docs/algorithm.md 4.18, the diagnosis).
#
# Builds bench/lapdiag.c against appm.c with bench/imglap.patch applied (the
# fit of the running image it uses lives there), with APPM__IMGLAP 0 (today's
# radius) and 1 (the radius with the running image's Laplacian), and runs it on
# the sphere box and CornellBox-Original, 64x64, LAPDIAG_PASSES passes (default
# 256), seeds LAPDIAG_SEEDS (default 1 2 3), 1 thread.  References as
# bench/oracle.sh uses them (the first path-traced half of CornellBox-Original,
# from bench/refs.sh).  Results: bench/out/lapdiag/log.txt.
set -u
CC=${CC:-cc}
N=${LAPDIAG_PASSES:-256}
seeds=${LAPDIAG_SEEDS:-"1 2 3"}
out=${LAPDIAG_OUT:-bench/out/lapdiag}
R=bench/ref
mkdir -p "$out"
[ -x ./appm ] || { echo "bench: build ./appm first (make)"; exit 1; }
. bench/refs.sh
ref cornell-original-64 cornell-original pt 4096
patch -s -p1 -o "$out/appm-patched.c" appm.c bench/imglap.patch || { echo "bench: bench/imglap.patch does not apply"; exit 1; }
for on in 0 1; do
    mkdir -p "$out/on$on"
    sed "s/^#define APPM__IMGLAP 1 /#define APPM__IMGLAP $on /" "$out/appm-patched.c" > "$out/on$on/appm.c"
    cp appm.h "$out/on$on/"
    $CC -std=c99 -O2 -Wall -Wextra -pedantic -I"$out/on$on" bench/lapdiag.c -o "$out/on$on/lapdiag" -lm -pthread || exit 1
done
log=$out/log.txt
: > "$log"
for on in 0 1; do
    for s in $seeds; do
        echo "APPM__IMGLAP=$on" | tee -a "$log"
        "$out/on$on/lapdiag" scenes/cornell-sphere.scene $R/cornell-sphere-64.pfm $N $s | tee -a "$log"
        "$out/on$on/lapdiag" scenes/cornell-original.scene $R/cornell-original-64-a.pfm $N $s | tee -a "$log"
    done
done
