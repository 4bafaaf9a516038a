#!/bin/sh
# bench/fewmaps.sh - "after a few photon maps the error is already below the best manually chosen
# parameters" (the paper's promise; issue 25's goal), measured (make bench-fewmaps).
#
# At equal passes, FEW_PASSES (default 8 and 128), on the two caustic scenes, appm with its
# defaults against every point of ppm's 15-point grid: the initial radius r0 in {1/4, 1/2, 1, 2,
# 4} x ppm's automatic radius (its radius= after one pass of the same seed), alpha in {0.5, 0.667,
# 0.8}.  Both take the photon paths a pass that the budget chooses (the same for every photon
# method), one thread a render, seeds FEW_SEEDS (default 1 2 3).  The error:
#   caustic-glass (56x80): the RMSE of the whole image, the reference's own noise taken off
#     (sqrt(rmse^2 - ref_mse), bench/refmix.c);
#   water-caustic (64x64): the RMSE over the pixels whose reference luminance is under 1
#     (bench/regions.c's mask): its lamp, and the lamp's image in the water, which an eye ray
#     meets about once in 4000 passes and one half of the reference met (docs/testing.md), would
#     hold most of the error of every render.  The reference's noise is not taken off there.
# The report: per scene and pass count, each point's median over the seeds, the best point (the
# lowest median), appm's median, and appm / the best point seed by seed (below 1: the promise
# holds).  References as bench/errbar.sh makes them (bench/refs.sh; cached).  Results:
# bench/out/fewmaps/{results.csv,fewmaps.md} (or FEW_OUT).
set -u
APPM=${APPM:-./appm}
CC=${CC:-cc}
threads=${BENCH_THREADS:-2}
passes=${FEW_PASSES:-"8 128"}
seeds=${FEW_SEEDS:-"1 2 3"}
out=${FEW_OUT:-bench/out/fewmaps}
mkdir -p "$out"
[ -x "$APPM" ] || { echo "bench: build $APPM first (make)"; exit 1; }
. bench/refs.sh
$CC -std=c99 -O2 bench/refmix.c appm.c -o bench/refmix -lm -pthread || exit 1
$CC -std=c99 -O2 bench/regions.c appm.c -o "$out/regions" -lm -pthread || exit 1

# err NAME MASK IMG: the error of IMG as the header says (MASK "-": the whole image less the
# reference's noise)
err() {
    if [ "$2" = - ]; then
        e_n=$(sed -n 's/^ref_mse=//p' "bench/ref/$1.mse")
        [ -n "$e_n" ] || { echo "bench: bench/ref/$1.mse has no ref_mse" >&2; return 1; }
        "$out/regions" "$3" "bench/ref/$1.pfm" /dev/null | sed -n 's/^all=//p' |
            awk -v n="$e_n" '{ e = $1 * $1 - n; printf "%.6g\n", (e > 0 ? sqrt(e) : 0) }'
    else
        "$out/regions" "$3" "bench/ref/$1.pfm" /dev/null "$2" | sed -n 's/^masked=//p'
    fi
}

# one NAME FILE SIZE MASK PASSES SEED LABEL OPTIONS...: a render's row of results.csv
one() {
    o_n=$1 o_f=$2 o_s=$3 o_m=$4 o_p=$5 o_sd=$6 o_l=$7
    shift 7
    "$APPM" render "$o_f" --size "$o_s" --passes "$o_p" --threads 1 --seed "$o_sd" -q "$@" -o "$out/img.pfm" \
        > /dev/null 2>> "$out/stderr.txt" || { echo "bench: $o_n $o_l seed $o_sd failed" >&2; exit 1; }
    o_e=$(err "$o_n" "$o_m" "$out/img.pfm")
    [ -n "$o_e" ] || { echo "bench: no error measured for $o_n $o_l seed $o_sd" >&2; exit 1; }
    echo "$o_n,$o_p,$o_sd,$o_l,$o_e" >> "$out/results.csv"
}

echo "scene,passes,seed,point,error" > "$out/results.csv"
: > "$out/stderr.txt" # the renders' warnings (water-caustic's MTL has a statement appm ignores)
# name, scene file, size, reference passes, method, options, size factor (as bench/errbar.sh), mask
list='caustic-glass-56x80e scenes/caustic-glass.scene 56x80 16384 ppm --sampler_random_--photons_17920 4 -
water-caustic-64e scenes/water-caustic.scene 64x64 16384 ppm --sampler_random_--photons_4096 4 1'
printf '%s\n' "$list" | while read -r name file size rp rm extra k mask; do
    ex=${extra:+ $(printf '%s' "$extra" | tr _ ' ')}
    reference "$name" "$file" "$size" "$rp" "$rm" "$ex" "$k"
    echo "scene $name"
    for sd in $seeds; do
        # ppm's automatic radius, which depends on the seed's first pass
        r0=$("$APPM" render "$file" --size "$size" --passes 1 --threads 1 --seed "$sd" --method ppm \
            -o "$out/img.pfm" 2>> "$out/stderr.txt" | tr ' ' '\n' | sed -n 's/^radius=//p')
        [ -n "$r0" ] || { echo "bench: no automatic radius for $name seed $sd" >&2; exit 1; }
        for p in $passes; do
            one "$name" "$file" "$size" "$mask" "$p" "$sd" appm
            for f in 0.25 0.5 1 2 4; do
                for a in 0.5 0.667 0.8; do
                    r=$(awk -v r="$r0" -v f="$f" 'BEGIN { printf "%.9g", r * f }')
                    one "$name" "$file" "$size" "$mask" "$p" "$sd" "ppm_r0=${f}x_alpha=$a" --method ppm --radius "$r" --alpha "$a"
                done
            done
        done
    done
done || exit 1 # the loop runs in a subshell (a pipeline): a failed render ends the bench here
rm -f "$out/img.pfm"

{
    echo "appm against ppm's 15-point grid at equal passes ($(date -u +%Y-%m-%d), $("$APPM" --version), seeds $seeds)"
    echo
    echo "| scene | passes | appm (median) | best point of ppm's grid (median) | appm / best point, by seed |"
    echo "|---|---|---|---|---|"
    awk -F, "$(cat bench/median.awk)"'NR > 1 { k = $1 SUBSEP $2; e[k, $4, $3] = $5; v[k, $4] = v[k, $4] " " $5; pt[$4] = 1
        if (!($3 in sd)) { sd[$3] = 1; so[++ns] = $3 }
        if (!(k in seen)) { seen[k] = 1; ord[++nk] = k } }
    END {
        for (i = 1; i <= nk; ++i) {
            k = ord[i]; split(k, kk, SUBSEP); best = ""; bm = 1e30
            for (q in pt) if (q != "appm" && med(v[k, q]) < bm) { bm = med(v[k, q]); best = q }
            r = ""
            for (j = 1; j <= ns; ++j) r = r (r == "" ? "" : " / ") sprintf("%.3f", e[k, "appm", so[j]] / e[k, best, so[j]])
            printf "| %s | %s | %.5f | %.5f (%s) | %s |\n", kk[1], kk[2], med(v[k, "appm"]), bm, best, r
        }
    }' "$out/results.csv"
} > "$out/fewmaps.md"
cat "$out/fewmaps.md"
