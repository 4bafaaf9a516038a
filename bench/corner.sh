#!/bin/sh
# bench/corner.sh - the kernel cut at a corner (appm.c 10.5, docs/algorithm.md
# 4.19) at equal passes.  Three builds: APPM__CUT 0 (every estimator as its
# paper gives it), APPM__CUT 2 with APPM__CUT_LAP 0 (the estimate cut, the
# Laplacian's stencil not) and APPM__CUT 2 (appm as used, and ppm with the
# cut); appm and ppm on the four scenes of bench/bounds.sh, seeds CORNER_SEEDS
# (default 1 2 3), 64x64.  Equal passes are deterministic, so the load of the
# machine does not enter; the cut's cost is measured apart (callgrind, 4.19).
# References and masks as bench/bounds.sh (bench/refs.sh builds them once),
# and for water-caustic also a pair made the same way with the cut.
# CORNER_SEAM=1 also renders the small-radius water reference of 4.19 (some
# 6 minutes on two cores) and prints bench/seam's comparison at the seams.
# Results: bench/out/corner/log.txt, one line per run; the medians are printed.
set -u
CC=${CC:-cc}
seeds=${CORNER_SEEDS:-"1 2 3"}
out=${CORNER_OUT:-bench/out/corner}
mkdir -p "$out"
[ -x ./appm ] || { echo "bench: build ./appm first (make)"; exit 1; }
R=bench/ref
. bench/refs.sh
refs
vars="0 est 2"
for v in $vars; do
    case $v in
    est) sed 's/^#define APPM__CUT [0-9]*/#define APPM__CUT 2/; s/^#define APPM__CUT_LAP [0-9]*/#define APPM__CUT_LAP 0/' appm.c ;;
    *) sed "s/^#define APPM__CUT [0-9]*/#define APPM__CUT $v/" appm.c ;;
    esac > "$out/appm-$v.c"
    grep -q '^#define APPM__CUT [02]' "$out/appm-$v.c" || { echo "bench: APPM__CUT not found"; exit 1; }
    [ $v != est ] || grep -q '^#define APPM__CUT_LAP 0' "$out/appm-$v.c" || { echo "bench: APPM__CUT_LAP not found"; exit 1; }
    $CC -std=c99 -O2 -I. bench/eqcpu.c "$out/appm-$v.c" -o "$out/eqcpu-$v" -lm -pthread || exit 1
done
$CC -std=c99 -O2 -I. "$out/appm-2.c" main.c -o "$out/appm-cut" -lm -pthread || exit 1
for s in a b; do # water-caustic's reference pair again, with the cut (bench/refs.sh's commands)
    seed=1000003; [ $s = b ] && seed=1000004
    [ -f $R/water-caustic-64-cut-$s.pfm ] || "$out/appm-cut" render scenes/water-caustic.scene --method ppm \
        --size 64x64 --passes 600 --threads 2 -q --sampler random --seed $seed --photons 16384 \
        -o $R/water-caustic-64-cut-$s.pfm > /dev/null || exit 1
done
log=$out/log.txt
: > "$log"
for s in $seeds; do
    for p in cornell-sphere=400 cornell-original=500 caustic-glass=450 water-caustic=130 water-cutref=130; do
        sc=${p%%=*} n=${p#*=} a=
        [ $sc = water-cutref ] && sc=water-caustic a="$R/water-caustic-64-cut-a.pfm $R/water-caustic-64-cut-b.pfm 10.0 0"
        [ -n "$a" ] || a=$(args $sc)
        for m in appm ppm; do
            for v in $vars; do
                [ $m = ppm ] && [ $v = est ] && continue
                echo "${p%%=*} $m cut=$v seed=$s $("$out/eqcpu-$v" scenes/$sc.scene $m $s -$n 0 0 $a)" | tee -a "$log"
            done
        done
    done
done
echo "medians over seeds (masked RMSE):"
for sc in cornell-sphere cornell-original caustic-glass water-caustic water-cutref; do
    for m in appm ppm; do
        for v in $vars; do
            grep "^$sc $m cut=$v " "$log" | sed 's/.*rmse_masked=\([^ ]*\).*/\1/' | sort -n |
                awk -v t="$sc $m cut=$v" '{ a[NR] = $1 } END { if (NR) print t, a[int((NR + 1) / 2)] }'
        done
    done
done
if [ "${CORNER_SEAM:-0}" = 1 ]; then
    [ -f $R/water-caustic-64-small.pfm ] || ./appm render scenes/water-caustic.scene --method ppm --alpha 1 \
        --radius 0.0084 --size 64x64 --passes 2000 --photons 65536 --threads 2 -q --seed 99 \
        -o $R/water-caustic-64-small.pfm > /dev/null || exit 1
    $CC -std=c99 -O2 -I. bench/seam.c appm.c -o "$out/seam" -lm -pthread || exit 1
    $CC -std=c99 -O2 -I. "$out/appm-0.c" main.c -o "$out/appm-nocut" -lm -pthread || exit 1
    for v in nocut cut; do
        "$out/appm-$v" render scenes/water-caustic.scene --size 64x64 --passes 130 --threads 2 -q --seed 1 \
            -o "$out/water-$v.pfm" > /dev/null || exit 1
    done
    "$out/seam" "$out/water-nocut.pfm" "$out/water-cut.pfm" $R/water-caustic-64-small.pfm "$out/water-nocut.pfm" \
        "$out/water-cut.pfm" $R/water-caustic-64-a.pfm $R/water-caustic-64-cut-a.pfm
fi
