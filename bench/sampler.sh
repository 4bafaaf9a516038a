#!/bin/sh
# bench/sampler.sh - what the low-discrepancy sampler buys (make bench-sampler;
# also part of make bench).
#
# On every committed scene (64x64) and on the caustic-glass scene (56x80), appm
# with --sampler qmc (the default) against --sampler random:
#   equal time    SAMPLER_SECS seconds each (default 6), RMSE and passes
#   equal passes  SAMPLER_PASSES passes each (default 128): RMSE, seconds per
#                 pass (the sampler's cost), and the error estimate est_relerr
#                 against the true relative error sqrt(relmse)
# for each seed of SAMPLER_SEEDS (default 1 2 3); the tables show medians over
# the seeds.  A third build, qmc with one chain (-DAPPM__CHAINS=1), shows what
# the four chains cost in accuracy and what the spread of correlated passes
# would claim as the error.  On caustic-glass the equal-time error is also
# given per region (bench/caustic-glass-regions.txt: directly lit floor, floor
# lit by the environment only, the glass, the caustic).
#
# References: path-traced (mean of two seeds, the reference's own noise
# subtracted, as in bench/run.sh), except caustic-glass, which a path tracer
# cannot render (a spot light seen through glass): there a long ppm render
# (alpha 2/3, 32768 passes, two seeds), whose own bias is not subtracted.
# SAMPLER_SCENES="name ..." restricts the run to some of the scenes below.
# Results: bench/out/sampler/{results.csv,sampler.md} (or SAMPLER_OUT).
set -u
APPM=${APPM:-./appm}
CC=${CC:-cc}
threads=${BENCH_THREADS:-2}
secs=${SAMPLER_SECS:-6}
passes=${SAMPLER_PASSES:-128}
seeds=${SAMPLER_SEEDS:-"1 2 3"}
out=${SAMPLER_OUT:-bench/out/sampler}
mkdir -p "$out" bench/ref
[ -x "$APPM" ] || { echo "bench: build ./appm first (make)"; exit 1; }
$CC -std=c99 -O2 bench/refmix.c appm.c -o bench/refmix -lm -pthread || exit 1
$CC -std=c99 -O2 bench/regions.c appm.c -o "$out/regions" -lm -pthread || exit 1
$CC -std=c99 -O2 -DAPPM__CHAINS=1 appm.c main.c -o "$out/appm-1chain" -lm -pthread || exit 1

kv() { printf '%s\n' "$1" | tr ' ' '\n' | sed -n "s/^$2=//p"; }

# reference NAME SCENE SIZE PASSES METHOD [EXTRA]: cached with its command, as in run.sh
reference() {
    ref=bench/ref/$1.pfm
    cmd="$APPM render $2 --method $5 --size $3 --passes $4 --threads $threads -q${6:-}"
    want="$cmd --seed 1000003 -o bench/ref/$1-a.pfm; $cmd --seed 1000004 -o bench/ref/$1-b.pfm; bench/refmix bench/ref/$1-a.pfm bench/ref/$1-b.pfm $ref"
    if [ -f "$ref" ] && [ -f "bench/ref/$1.mse" ] && [ -f "bench/ref/$1.cmd" ] &&
        [ "$(cat "bench/ref/$1.cmd")" = "$want" ]; then
        return 0
    fi
    echo "reference $ref: $want"
    $cmd --seed 1000003 -o "bench/ref/$1-a.pfm" > /dev/null &&
        $cmd --seed 1000004 -o "bench/ref/$1-b.pfm" > /dev/null &&
        bench/refmix "bench/ref/$1-a.pfm" "bench/ref/$1-b.pfm" "$ref" > "bench/ref/$1.mse" ||
        { echo "bench: reference failed"; exit 1; }
    rm -f "bench/ref/$1-a.pfm" "bench/ref/$1-b.pfm"
    printf '%s\n' "$want" > "bench/ref/$1.cmd"
}

# one NAME SCENE SIZE LABEL MODE SEED BINARY OPTIONS...: one render, one csv row
one() {
    name=$1 scene=$2 size=$3 label=$4 mode=$5 seed=$6 bin=$7
    shift 7
    img="$out/$name-$label-$mode-$seed.pfm"
    line=$($bin render "$scene" --size "$size" --threads "$threads" --seed "$seed" -q \
        --reference "bench/ref/$name.pfm" -o "$img" "$@" | tail -n 1)
    refmse=$(sed -n 's/^ref_mse=//p' "bench/ref/$name.mse")
    rmse=$(awk -v r="$(kv "$line" rmse)" -v n="$refmse" 'BEGIN { m = r * r - n; printf "%.6g", (m > 0 ? sqrt(m) : 0) }')
    p=$(kv "$line" passes) s=$(kv "$line" seconds)
    printf '%s,%s,%s,%s,%s,%s,%s,%s,%s\n' "$name" "$label" "$mode" "$seed" "$p" "$s" "$rmse" \
        "$(kv "$line" relmse)" "$(kv "$line" est_relerr)" >> "$out/results.csv"
    if [ "$name" = caustic-glass-56x80 ] && [ "$mode" = time ]; then
        printf '%s,%s,%s' "$label" "$seed" "$("$out/regions" "$img" "bench/ref/$name.pfm" \
            bench/caustic-glass-regions.txt | tr '\n' ',')" >> "$out/regions.csv"
        echo >> "$out/regions.csv"
    fi
}

scene() { # NAME SCENE SIZE
    echo "scene $1"
    for seed in $seeds; do
        for smp in qmc random; do
            one "$1" "$2" "$3" "$smp" time "$seed" "$APPM" --time "$secs" --sampler "$smp"
            one "$1" "$2" "$3" "$smp" passes "$seed" "$APPM" --passes "$passes" --sampler "$smp"
        done
        one "$1" "$2" "$3" qmc-1chain passes "$seed" "$out/appm-1chain" --passes "$passes"
        one "$1" "$2" "$3" qmc-1chain time "$seed" "$out/appm-1chain" --time "$secs"
    done
}

echo "scene,sampler,mode,seed,passes,seconds,rmse,relmse,est_relerr" > "$out/results.csv"
rm -f "$out/regions.csv"
{
    echo "date: $(date -u '+%Y-%m-%d %H:%M UTC')"
    echo "commit: $(git rev-parse --short HEAD 2>/dev/null || echo unknown)"
    echo "machine: $(uname -sm), $(nproc 2>/dev/null) cores; threads: $threads"
    echo "equal time: $secs s; equal passes: $passes; seeds: $seeds"
} > "$out/meta.txt"
cat "$out/meta.txt"

# name, scene file, size, reference passes, reference method, extra reference options
list='cornell-sphere-64 scenes/cornell-sphere.scene 64x64 8192 pt
cornell-sphere-dof-64 scenes/cornell-sphere-dof.scene 64x64 4096 pt --sampler_random
caustic-glass-56x80 scenes/caustic-glass.scene 56x80 32768 ppm --sampler_random
cornell-original-64 scenes/cornell-original.scene 64x64 4096 pt --sampler_random
cornell-mm-64 scenes/cornell-mm.scene 64x64 4096 pt --sampler_random
cornell-mirror-64 scenes/cornell-mirror.scene 64x64 4096 pt --sampler_random
cornell-empty-white-64 scenes/cornell-empty-white.scene 64x64 4096 pt --sampler_random
cornell-empty-rg-64 scenes/cornell-empty-rg.scene 64x64 4096 pt --sampler_random
cornell-glossy-64 scenes/cornell-glossy.scene 64x64 4096 pt --sampler_random
bunny-64 scenes/bunny.scene 64x64 4096 pt --sampler_random
teapot-64 scenes/teapot.scene 64x64 4096 pt --sampler_random'
only=${SAMPLER_SCENES:-}
printf '%s\n' "$list" | while read -r name file size rp rm extra; do
    case " $only " in "  " | *" $name "*) ;; *) continue ;; esac
    reference "$name" "$file" "$size" "$rp" "$rm" "${extra:+ $(printf '%s' "$extra" | tr _ ' ')}"
    scene "$name" "$file" "$size"
done
sh bench/sampler_report.sh "$out" > "$out/sampler.md" || exit 1
cat "$out/sampler.md"
