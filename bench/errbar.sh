#!/bin/sh
# bench/errbar.sh - does the error bar tell the truth? (make bench-errbar)
#
# On every committed scene (64x64; caustic-glass 56x80), each method that keeps
# an error estimate (appm, appm-paper, pt; ERRBAR_METHODS) renders
# ERRBAR_PASSES passes (default 256) for each seed of ERRBAR_SEEDS (default
# 1 2 3), logging after every pass its est_relerr and its relmse against the
# reference (--log).  At passes 16, 64 and 256 the report gives est_relerr
# against the true relative error
#     true = sqrt(relmse - ref_relmse)
# (ref_relmse: the reference's own noise in the same measure, bench/refmix.c),
# as the median over the seeds of est / true: 1 is honest; and, since `--until-error` and
# `--time` stop at any pass, the lowest and highest of those medians over every pass from 16
# (bench/errbar_every.sh).  ERRBAR_OLD=BINARY
# runs a second build the same way and puts its ratios beside (in brackets).
#
# References (bench/refs.sh): pt, 16384 passes in two halves, except where a
# path tracer cannot reach the light (a spot seen through glass, a tiny light
# under water): ppm, 16384 passes, whose own bias is not subtracted, at 4x the size with the
# photon paths a pass of 1x (water-caustic 256x256 and 4096, caustic-glass 224x320 and 17920),
# reduced: at 1x ppm's kernel, uncut, read water-caustic's corners 8-15 % dark (docs/testing.md).
# ERRBAR_SCENES="name ..." restricts the run.  Results:
# bench/out/errbar/{results.csv,errbar.md} (or ERRBAR_OUT).
set -u
APPM=${APPM:-./appm}
OLD=${ERRBAR_OLD:-}
threads=${BENCH_THREADS:-2}
passes=${ERRBAR_PASSES:-256}
seeds=${ERRBAR_SEEDS:-"1 2 3"}
methods=${ERRBAR_METHODS:-"appm appm-paper pt"}
out=${ERRBAR_OUT:-bench/out/errbar}
only=${ERRBAR_SCENES:-}
mkdir -p "$out" bench/ref
[ -x "$APPM" ] || { echo "bench: build ./appm first (make)"; exit 1; }
${CC:-cc} -std=c99 -O2 bench/refmix.c appm.c -o bench/refmix -lm -pthread || exit 1
. bench/refs.sh

# one NAME SCENE SIZE METHOD SEED BUILD BINARY: one render; its rows at 16, 64, 256 passes
one() {
    log="$out/log-$1-$4-$5-$6.csv"
    "$7" render "$2" --size "$3" --method "$4" --threads "$threads" --seed "$5" --passes "$passes" -q \
        --reference "bench/ref/$1.pfm" --log "$log" -o "$out/last.pfm" > /dev/null || exit 1
    awk -F, -v s="$1,$4,$6,$5" -v rr="$ref_rel" \
        'NR > 1 && ($1 == 16 || $1 == 64 || $1 == 256) { print s "," $1 "," $5 "," $6 "," rr }' "$log" \
        >> "$out/results.csv"
}

echo "scene,method,build,seed,pass,relmse,est_relerr,ref_relmse" > "$out/results.csv"
{
    echo "date: $(date -u '+%Y-%m-%d %H:%M UTC')"
    echo "commit: $(git rev-parse --short HEAD 2>/dev/null || echo unknown)"
    echo "machine: $(uname -sm), $(nproc 2>/dev/null) cores; threads: $threads"
    echo "passes: $passes; seeds: $seeds; methods: $methods${OLD:+; old build: $OLD}"
} > "$out/meta.txt"
cat "$out/meta.txt"

# name, scene file, size, reference passes, reference method, extra reference options, the
# reference's size factor (refs.sh: the ppm references at 4x, whose kernel is 4x narrower)
list='cornell-sphere-64e scenes/cornell-sphere.scene 64x64 16384 pt --sampler_random
cornell-sphere-dof-64e scenes/cornell-sphere-dof.scene 64x64 16384 pt --sampler_random
caustic-glass-56x80e scenes/caustic-glass.scene 56x80 16384 ppm --sampler_random_--photons_17920 4
water-caustic-64e scenes/water-caustic.scene 64x64 16384 ppm --sampler_random_--photons_4096 4
cornell-original-64e scenes/cornell-original.scene 64x64 16384 pt --sampler_random
cornell-mm-64e scenes/cornell-mm.scene 64x64 16384 pt --sampler_random
cornell-mirror-64e scenes/cornell-mirror.scene 64x64 16384 pt --sampler_random
cornell-empty-white-64e scenes/cornell-empty-white.scene 64x64 16384 pt --sampler_random
cornell-empty-rg-64e scenes/cornell-empty-rg.scene 64x64 16384 pt --sampler_random
cornell-glossy-64e scenes/cornell-glossy.scene 64x64 16384 pt --sampler_random
bunny-64e scenes/bunny.scene 64x64 16384 pt --sampler_random
teapot-64e scenes/teapot.scene 64x64 16384 pt --sampler_random
textured-64e scenes/textured.scene 64x64 16384 pt --sampler_random'
printf '%s\n' "$list" | while read -r name file size rp rm extra k; do
    case " $only " in "  " | *" $name "*) ;; *) continue ;; esac
    ex=${extra:+ $(printf '%s' "$extra" | tr _ ' ')}
    reference "$name" "$file" "$size" "$rp" "$rm" "$ex" "$k"
    ref_rel=$(sed -n 's/^ref_relmse=//p' "bench/ref/$name.mse")
    if [ -z "$ref_rel" ]; then # made by an older refmix: made again
        rm -f "bench/ref/$name.cmd"
        reference "$name" "$file" "$size" "$rp" "$rm" "$ex" "$k"
        ref_rel=$(sed -n 's/^ref_relmse=//p' "bench/ref/$name.mse")
    fi
    echo "scene $name"
    for method in $methods; do
        for seed in $seeds; do
            one "$name" "$file" "$size" "$method" "$seed" new "$APPM"
            [ -n "$OLD" ] && one "$name" "$file" "$size" "$method" "$seed" old "$OLD"
        done
    done
done
rm -f "$out/last.pfm"

# The report: median over the seeds of est / true, per scene, method and pass.
{
    cat "$out/meta.txt"
    echo
    echo "est_relerr / true relative error (median over the seeds; 1 is honest; in brackets: the old build)"
    echo
    awk -F, "$(cat bench/median.awk)"'
    NR > 1 {
        t = $6 - $8; t = t > 0 ? sqrt(t) : 1e-30
        k = $1 SUBSEP $2 SUBSEP $3 SUBSEP $5
        e = $7 == "" ? -1 : $7 / t # an empty est_relerr: the method reports none there
        r[k] = (k in r) ? r[k] " " e : e
        tr[k] = (k in tr) ? tr[k] " " t : t
        if (!(($1 SUBSEP $2) in seen)) { seen[$1 SUBSEP $2] = 1; order[++n] = $1 SUBSEP $2 }
        if ($3 == "old") old = 1
    }
    END {
        print "| scene | method | true, 16 | est / true, 16 | true, 64 | est / true, 64 | true, 256 | est / true, 256 |"
        print "|---|---|---|---|---|---|---|---|"
        for (i = 1; i <= n; ++i) {
            split(order[i], sm, SUBSEP)
            line = "| " sm[1] " | " sm[2]
            split("16 64 256", ps, " ")
            for (p = 1; p <= 3; ++p) {
                k = order[i] SUBSEP "new" SUBSEP ps[p]; ko = order[i] SUBSEP "old" SUBSEP ps[p]
                if (!(k in r)) { line = line " | - | -"; continue }
                line = line sprintf(" | %.4f | ", med(tr[k])) (med(r[k]) < 0 ? "none" : sprintf("%.2f", med(r[k])))
                if (old && (ko in r)) line = line (med(r[ko]) < 0 ? " (none)" : sprintf(" (%.2f)", med(r[ko])))
            }
            print line " |"
        }
    }' "$out/results.csv"
    echo
    echo "est_relerr / true at every pass from 16 (median over the seeds at each; bench/errbar_every.sh)"
    echo
    sh bench/errbar_every.sh "$out"
} > "$out/errbar.md"
cat "$out/errbar.md"
