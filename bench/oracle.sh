#!/bin/sh
# bench/oracle.sh - the error-minimising fixed radius per pixel against
# appm's radius (docs/algorithm.md 4.16).
#
# For the sphere box and CornellBox-Original (64x64, ORACLE_PASSES passes,
# default 256, seeds ORACLE_SEEDS, default 1 2 3 4 5, 1 thread): ppm with alpha 1
# (the radius the same on every pass) at r0 = f x r_auto for each f of
# ORACLE_F, and appm at its defaults with --aux; then bench/oracle picks each
# pixel's error-minimising f and compares it, per region, with appm's radius.
# References as bench/bounds.sh builds them (the committed sphere box
# reference; two path-traced halves for CornellBox-Original, the first used).
# ORACLE_RHI=H renders appm built with both upper bounds at H (as
# bench/bounds.sh does) and writes its files to ORACLE_OUT (default
# bench/out/oracle-rhiH), reusing the ppm images of ORACLE_PPM (default
# bench/out/oracle); the tables' "bound" stays 2x (the caustic component's;
# the diffuse one's is 3x since docs/algorithm.md 4.20, and bench/oracle.c
# counts a pixel at or beyond 2x as at the bound).
# ORACLE_PATCH=FILE renders appm built from appm.c with that patch applied
# (bench/edgecap.patch: the edge caps of docs/algorithm.md 4.17), and
# ORACLE_DEFS="MACRO=VALUE,..." with those macros of section 10 set by sed
# (after the patch), into ORACLE_OUT (default bench/out/oracle-defs), with
# the ppm images of ORACLE_PPM as above.
# ORACLE_APPM=BINARY renders appm with that build instead (for example one of
# bench/imglap.sh's variants); give it its own ORACLE_OUT, and ORACLE_PPM for
# ppm images already rendered.
# ORACLE_REUSE=1 keeps the images already there (no clamped= lines then).
# Results: bench/out/oracle/SCENE.txt (or ORACLE_OUT).
set -u
CC=${CC:-cc}
N=${ORACLE_PASSES:-256}
seeds=${ORACLE_SEEDS:-"1 2 3 4 5"}
fs=${ORACLE_F:-"0.125 0.177 0.25 0.354 0.5 0.707 1 1.41 2 2.83 4 8"}
rhi=${ORACLE_RHI:-2.0}
defs=${ORACLE_DEFS:-}
pat=${ORACLE_PATCH:-}
out=${ORACLE_OUT:-bench/out/oracle}
[ "$rhi" = 2.0 ] || out=${ORACLE_OUT:-bench/out/oracle-rhi$rhi}
[ -z "$defs$pat" ] || out=${ORACLE_OUT:-bench/out/oracle-defs}
ppmout=$out
[ "$rhi" = 2.0 ] && [ -z "$defs$pat" ] || ppmout=${ORACLE_PPM:-bench/out/oracle}
[ -n "${ORACLE_PPM:-}" ] && ppmout=$ORACLE_PPM
R=bench/ref
mkdir -p "$out" "$ppmout"
[ -x ./appm ] || { echo "bench: build ./appm first (make)"; exit 1; }
APPM=./appm
if [ "$rhi" != 2.0 ] || [ -n "$defs$pat" ]; then
    sed -e "s/^#define APPM__RHI 2.0 /#define APPM__RHI $rhi /" \
        -e "s/^#define APPM__RHI_DIFFUSE 3.0 /#define APPM__RHI_DIFFUSE $rhi /" appm.c > "$out/appm.c"
    grep -q "^#define APPM__RHI $rhi " "$out/appm.c" && grep -q "^#define APPM__RHI_DIFFUSE $rhi " "$out/appm.c" ||
        { echo "bench: APPM__RHI or APPM__RHI_DIFFUSE not found"; exit 1; }
    if [ -n "$pat" ]; then # the patch may touch the tests too: apply it to a copy of both
        rm -rf "$out/src" && mkdir -p "$out/src/tests" && cp "$out/appm.c" "$out/src/" &&
            cp tests/t_appm.c "$out/src/tests/" && patch -s -p1 -d "$out/src" < "$pat" &&
            cp "$out/src/appm.c" "$out/appm.c" || { echo "bench: $pat does not apply"; exit 1; }
    fi
    for d in $(echo "$defs" | tr ',' ' '); do
        m=${d%%=*} val=${d#*=}
        sed "s/^#define $m [^ ]*/#define $m $val/" "$out/appm.c" > "$out/t.c" && mv "$out/t.c" "$out/appm.c"
        grep -q "^#define $m $val" "$out/appm.c" || { echo "bench: $m not found"; exit 1; }
    done
    cp appm.h main.c "$out/"
    $CC -std=c99 -O2 -I"$out" "$out/main.c" "$out/appm.c" -o "$out/appm" -lm -pthread || exit 1
    APPM=$out/appm
fi
[ -n "${ORACLE_APPM:-}" ] && APPM=$ORACLE_APPM
$CC -std=c99 -O2 -Wall -Wextra -pedantic bench/oracle.c appm.c -o "$out/oracle" -lm -pthread || exit 1
[ -f $R/cornell-original-64-a.pfm ] || ./appm render scenes/cornell-original.scene --method pt --size 64x64 \
    --passes 4096 --threads 2 -q --sampler random --seed 1000003 -o $R/cornell-original-64-a.pfm > /dev/null || exit 1
nf=$(echo $fs | wc -w)
ns=$(echo $seeds | wc -w)
for sc in cornell-sphere cornell-original; do
    case $sc in
    cornell-sphere) ref=$R/cornell-sphere-64.pfm reg=bench/oracle-sphere-regions.txt ;;
    *) ref=$R/cornell-original-64-a.pfm reg=bench/oracle-original-regions.txt ;;
    esac
    ra=$(./appm render scenes/$sc.scene --method ppm --size 64x64 --passes 1 --threads 1 -q --seed 1 -o "$out/r.pfm" |
         sed 's/.* radius=\([^ ]*\).*/\1/')
    imgs= pre=
    for f in $fs; do
        r0=$(awk "BEGIN { print $ra * $f }")
        for s in $seeds; do
            o=$ppmout/$sc-f$f-s$s.pfm
            [ "${ORACLE_REUSE:-0}" = 1 ] && [ -f "$o" ] || ./appm render scenes/$sc.scene --method ppm --alpha 1 --radius $r0 --size 64x64 --passes $N \
                --threads 1 -q --seed $s -o "$o" > /dev/null || exit 1
            imgs="$imgs $o"
        done
    done
    for s in $seeds; do
        [ "${ORACLE_REUSE:-0}" = 1 ] && [ -f "$out/$sc-appm-s$s.pfm" ] ||
        echo "$sc appm seed=$s $($APPM render scenes/$sc.scene --size 64x64 --passes $N --threads 1 -q --seed $s \
            -o "$out/$sc-appm-s$s.pfm" --aux "$out/$sc-appm-s$s" | sed 's/.*\(clamped=[^ ]*\).*/\1/')"
        pre="$pre $out/$sc-appm-s$s"
    done
    "$out/oracle" $ref $ra $N $reg $nf $fs $ns $imgs $pre | tee "$out/$sc.txt"
done
