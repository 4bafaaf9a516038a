#!/bin/sh
# bench/edgecap.sh - edge caps on appm's upper radius bound (docs/algorithm.md
# 4.17; measured, not used) against the bound without them, at equal CPU time.
#
# The edge caps are not in appm.c: bench/edgecap.patch adds them (appm.c's
# section 10.5, with its tests in tests/t_appm.c) to the appm.c of the
# commit that made it; later changes to section 10 may need it refreshed.
# Builds one bench/eqcpu per variant of EDGE_VARIANTS (default "old new"):
# "old" is appm.c as it is; any other NAME is appm.c with the patch, or
# NAME:MACRO=VALUE,MACRO=VALUE,... with those macros of the patch's section
# 10 set by sed as well (nothing else changed).  Then, for each
# seed of EDGE_SEEDS (default 1 2 3) and scene of EDGE_SCENES (default: the
# four of bench/bounds.sh), every variant and ppm at its defaults for
# EDGE_BUDGET processor seconds (default 3; negative: that many passes),
# interleaved; EDGE_PASSES="SCENE=N ..." renders N passes of that scene
# instead (equal passes: deterministic, so the error without the noise of
# the machine's load; the cost then comes from `cpu=` or callgrind).
# References and masks as bench/bounds.sh (bench/refs.sh builds them once).
# Results: bench/out/edgecap/log.txt (or EDGE_OUT), one line per run; then
# per scene and variant the run with the median masked RMSE over the seeds.
set -u
CC=${CC:-cc}
seeds=${EDGE_SEEDS:-"1 2 3"}
vars=${EDGE_VARIANTS:-"old new"}
budget=${EDGE_BUDGET:-3}
out=${EDGE_OUT:-bench/out/edgecap}
mkdir -p "$out"
[ -x ./appm ] || { echo "bench: build ./appm first (make)"; exit 1; }
R=bench/ref
. bench/refs.sh
refs
cp appm.h "$out/"
rm -rf "$out/src" && mkdir -p "$out/src/tests" && cp appm.c appm.h "$out/src/" && cp tests/t_appm.c tests/check.h "$out/src/tests/"
patch -s -p1 -d "$out/src" < bench/edgecap.patch || { echo "bench: bench/edgecap.patch does not apply"; exit 1; }
for v in $vars; do
    name=${v%%:*} defs=
    [ "$name" = "$v" ] || defs=${v#*:}
    if [ "$name" = old ]; then cp appm.c "$out/appm-$name.c"; else cp "$out/src/appm.c" "$out/appm-$name.c"; fi
    for d in $(echo "$defs" | tr ',' ' '); do
        m=${d%%=*} val=${d#*=}
        sed "s/^#define $m [^ ]*/#define $m $val/" "$out/appm-$name.c" > "$out/t.c" && mv "$out/t.c" "$out/appm-$name.c"
        grep -q "^#define $m $val" "$out/appm-$name.c" || { echo "bench: $m not found"; exit 1; }
    done
    $CC -std=c99 -O2 bench/eqcpu.c "$out/appm-$name.c" -o "$out/eqcpu-$name" -lm -pthread || exit 1
done
scenes=${EDGE_SCENES:-"cornell-sphere cornell-original caustic-glass water-caustic"}
log=$out/log.txt
: > "$log"
first=$(echo $vars | cut -d' ' -f1); first=${first%%:*}
for s in $seeds; do
    for sc in $scenes; do
        b=$budget
        for p in ${EDGE_PASSES:-}; do [ "${p%%=*}" = "$sc" ] && b=-${p#*=}; done
        for v in $vars; do
            name=${v%%:*}
            echo "$sc appm $name seed=$s $("$out/eqcpu-$name" scenes/$sc.scene appm $s $b 0 0 $(args $sc))" | tee -a "$log"
        done
        [ "${EDGE_PPM:-1}" = 1 ] &&
        echo "$sc ppm default seed=$s $("$out/eqcpu-$first" scenes/$sc.scene ppm $s $b 0 0 $(args $sc))" | tee -a "$log"
    done
done
echo "medians over seeds (masked RMSE; passes; clamped=):"
for sc in $scenes; do
    for name in $(for v in $vars; do echo ${v%%:*}; done) default; do
        grep "^$sc [a-z]* $name seed=" "$log" | sed 's/.*passes=\([^ ]*\).*rmse_masked=\([^ ]*\) clamped=\([^ ]*\).*/\2 \1 \3/' |
            sort -n | awk -v sc=$sc -v n=$name '{ a[NR] = $0 } END { if (NR) print sc, n, a[int((NR + 1) / 2)] }'
    done
done
