#!/bin/sh
# bench/imglap.sh - the Laplacian of the running image at equal CPU time against
# appm without it and ppm (docs/algorithm.md 4.18).  It was measured and not
# kept: bench/imglap.patch adds it to appm.c section 10 (10.5, with its own
# comments), and each variant is built from appm.c with that patch applied.
#
# Variants IMGLAP_VARIANTS (default "0:2 1:2 1:4"): ON:RHI[:K[:C]], appm built with
# APPM__IMGLAP ON, both upper bounds (APPM__RHI, APPM__RHI_DIFFUSE) RHI, APPM__IMGLAP_K K (default 1) and
# APPM__IMGLAP_COMPS C (default 3: both components; 1 the diffuse one), nothing else
# changed; ON 0 renders today's image (checked with cmp: the patch's only other
# change, the mean visible point it keeps, does not touch the image).  For each seed of IMGLAP_SEEDS (default
# 1 2 3) and scene of IMGLAP_SCENES (the four of bench/bounds.sh) each variant
# and ppm at its defaults run 3 processor seconds (bench/eqcpu), interleaved.
# References: bench/refs.sh's (those of bench/bounds.sh; built if missing).
# Then clamped= after 64 passes (64x64, 1 thread, seed 1) for every scene in
# scenes/ with each variant (IMGLAP_CLAMPED=0 leaves that out).
# IMGLAP_PASSES=N: equal passes instead (N passes on every scene; bench/eqcpu
# with a negative budget), no ppm and no clamped= lines.
# Results: bench/out/imglap/log.txt (or IMGLAP_OUT).
set -u
CC=${CC:-cc}
seeds=${IMGLAP_SEEDS:-"1 2 3"}
vars=${IMGLAP_VARIANTS:-"0:2 1:2 1:4"}
out=${IMGLAP_OUT:-bench/out/imglap}
R=bench/ref
mkdir -p "$out"
[ -x ./appm ] || { echo "bench: build ./appm first (make)"; exit 1; }
. bench/refs.sh
refs
build() { # ON RHI K C -> $out/v-ON-RHI-K-C/
    d=$out/v-$1-$2-$3-$4
    mkdir -p "$d"
    patch -s -p1 -o "$d/appm-patched.c" appm.c bench/imglap.patch || { echo "bench: bench/imglap.patch does not apply"; exit 1; }
    sed -e "s/^#define APPM__IMGLAP 1 /#define APPM__IMGLAP $1 /" -e "s/^#define APPM__RHI 2.0 /#define APPM__RHI $2 /" \
        -e "s/^#define APPM__RHI_DIFFUSE 3.0 /#define APPM__RHI_DIFFUSE $2 /" \
        -e "s/^#define APPM__IMGLAP_K 1.0 /#define APPM__IMGLAP_K $3 /" \
        -e "s/^#define APPM__IMGLAP_COMPS 3 /#define APPM__IMGLAP_COMPS $4 /" "$d/appm-patched.c" > "$d/appm.c"
    grep -q "^#define APPM__IMGLAP $1 " "$d/appm.c" && grep -q "^#define APPM__RHI $2 " "$d/appm.c" &&
        grep -q "^#define APPM__IMGLAP_K $3 " "$d/appm.c" && grep -q "^#define APPM__IMGLAP_COMPS $4 " "$d/appm.c" ||
        { echo "bench: a constant was not found"; exit 1; }
    cp appm.h main.c "$d/"
    $CC -std=c99 -O2 -I"$d" bench/eqcpu.c "$d/appm.c" -o "$d/eqcpu" -lm -pthread || exit 1
    $CC -std=c99 -O2 -I"$d" "$d/main.c" "$d/appm.c" -o "$d/appm" -lm -pthread || exit 1
}
names=
for v in $vars; do
    on=$(echo $v | cut -d: -f1) rhi=$(echo $v | cut -d: -f2) k=$(echo $v | cut -d: -f3) cm=$(echo $v | cut -d: -f4)
    [ -n "$k" ] || k=1.0
    [ -n "$cm" ] || cm=3
    build $on $rhi $k $cm
    names="$names v-$on-$rhi-$k-$cm"
done
first=$(echo $names | cut -d' ' -f1)
scenes=${IMGLAP_SCENES:-"cornell-sphere cornell-original caustic-glass water-caustic"}
log=$out/log.txt
: > "$log"
budget=3
[ -n "${IMGLAP_PASSES:-}" ] && budget=-$IMGLAP_PASSES
for s in $seeds; do
    for sc in $scenes; do
        for n in $names; do
            echo "$sc appm $n seed=$s $("$out/$n/eqcpu" scenes/$sc.scene appm $s $budget 0 0 $(args $sc))" | tee -a "$log"
        done
        [ -n "${IMGLAP_PASSES:-}" ] && continue
        echo "$sc ppm default seed=$s $("$out/$first/eqcpu" scenes/$sc.scene ppm $s 3 0 0 $(args $sc))" | tee -a "$log"
    done
done
[ "${IMGLAP_CLAMPED:-1}" = 0 ] || [ -n "${IMGLAP_PASSES:-}" ] && exit 0
for f in scenes/*.scene; do
    for n in $names; do
        echo "$(basename $f .scene) $n $("$out/$n/appm" render $f --size 64x64 --passes 64 --threads 1 --seed 1 -q \
            -o "$out/c.pfm" | sed 's/.*\(clamped=[^ ]*\).*/\1/')" | tee -a "$log"
    done
done
