#!/bin/sh
# bench/corner.sh - the kernel cut at a corner (appm.c 10.5, docs/algorithm.md
# 4.19) at equal passes: appm and ppm, each built with APPM__CUT 0 (the
# estimators as their papers give them) and with the cut (APPM__CUT 2: every
# photon method; appm's default, 1, gives appm's rows of it), on the four
# scenes of bench/bounds.sh, seeds CORNER_SEEDS (default 1 2 3), 64x64.
# Equal passes are deterministic, so the load of the machine does not enter;
# the cut's cost is measured apart (callgrind, section 4.19).  References and
# masks as bench/bounds.sh (bench/refs.sh builds them once).  Results:
# bench/out/corner/log.txt, one line per run, then the medians over the seeds.
set -u
CC=${CC:-cc}
seeds=${CORNER_SEEDS:-"1 2 3"}
out=${CORNER_OUT:-bench/out/corner}
mkdir -p "$out"
[ -x ./appm ] || { echo "bench: build ./appm first (make)"; exit 1; }
R=bench/ref
. bench/refs.sh
refs
for v in 0 2; do
    sed "s/^#define APPM__CUT [0-9]*/#define APPM__CUT $v/" appm.c > "$out/appm-$v.c"
    grep -q "^#define APPM__CUT $v" "$out/appm-$v.c" || { echo "bench: APPM__CUT not found"; exit 1; }
    $CC -std=c99 -O2 -I. bench/eqcpu.c "$out/appm-$v.c" -o "$out/eqcpu-$v" -lm -pthread || exit 1
done
log=$out/log.txt
: > "$log"
for s in $seeds; do
    for p in cornell-sphere=400 cornell-original=500 caustic-glass=450 water-caustic=130; do
        sc=${p%%=*} n=${p#*=}
        for m in appm ppm; do
            for v in 0 2; do
                echo "$sc $m cut=$v seed=$s $("$out/eqcpu-$v" scenes/$sc.scene $m $s -$n 0 0 $(args $sc))" | tee -a "$log"
            done
        done
    done
done
echo "medians over seeds (masked RMSE):"
for sc in cornell-sphere cornell-original caustic-glass water-caustic; do
    for m in appm ppm; do
        for v in 0 2; do
            grep "^$sc $m cut=$v " "$log" | sed 's/.*rmse_masked=\([^ ]*\).*/\1/' | sort -n |
                awk -v t="$sc $m cut=$v" '{ a[NR] = $1 } END { if (NR) print t, a[int((NR + 1) / 2)] }'
        done
    done
done
