#!/bin/sh
# bench/sampler.sh - what the low-discrepancy sampler buys (make bench-sampler;
# also part of make bench).
#
# On every committed scene (64x64) and on the caustic-glass scene (56x80), appm
# with --sampler qmc (the default) against --sampler random, SAMPLER_PASSES
# passes each (default 256) for each seed of SAMPLER_SEEDS (default 1 2 3),
# logging the RMSE after every pass.  From the logs (bench/sampler_report.sh):
#   equal passes  the RMSE after the last pass, and the error estimate
#                 est_relerr against the true relative error sqrt(relmse)
#   cost          processor seconds per pass (cpu_s of the summary), 1 thread,
#                 SAMPLER_COST_PASSES passes (default 48), SAMPLER_COST_ROUNDS
#                 rounds (default 3) of qmc and random interleaved: on a shared
#                 machine wall time measures the other users too, and even
#                 processor time moves by several per cent from run to run
#                 (instruction counts, which it does not measure, are steadier)
#   equal time    equal processor time: the sampler that costs more per pass is
#                 read from its log at the pass where it has spent what the
#                 other spent on all of its passes
# as medians over the seeds (and rounds).  A third
# run, qmc with 4 chains (--chains 4), shows what the chains that make the
# error estimate honest cost in accuracy, against the spread of correlated
# passes that the default (one chain) takes as the error.  On caustic-glass the error after the last pass is also given per
# region (bench/caustic-glass-regions.txt: directly lit floor, floor lit by the
# environment only, the glass, the caustic).
#
# References: path-traced (mean of two seeds, the reference's own noise
# subtracted, as in bench/run.sh), except caustic-glass, which a path tracer
# cannot render (a spot light seen through glass): there a long ppm render
# (alpha 2/3, 32768 passes, two seeds), whose own bias is not subtracted.
# SAMPLER_SCENES="name ..." restricts the run to some of the scenes below.
# SAMPLER_COST_ONLY=1 measures the cost again and rewrites the tables from the
# renders already in SAMPLER_OUT (which are deterministic; the cost is not).
# Results: bench/out/sampler/{results.csv,sampler.md} (or SAMPLER_OUT).
set -u
APPM=${APPM:-./appm}
CC=${CC:-cc}
threads=${BENCH_THREADS:-2}
passes=${SAMPLER_PASSES:-256}
cpasses=${SAMPLER_COST_PASSES:-48}
crounds=${SAMPLER_COST_ROUNDS:-3}
seeds=${SAMPLER_SEEDS:-"1 2 3"}
out=${SAMPLER_OUT:-bench/out/sampler}
mkdir -p "$out" bench/ref
[ -x "$APPM" ] || { echo "bench: build ./appm first (make)"; exit 1; }
$CC -std=c99 -O2 bench/refmix.c appm.c -o bench/refmix -lm -pthread || exit 1
$CC -std=c99 -O2 bench/regions.c appm.c -o "$out/regions" -lm -pthread || exit 1

kv() { printf '%s\n' "$1" | tr ' ' '\n' | sed -n "s/^$2=//p"; }

# reference NAME SCENE SIZE PASSES METHOD [EXTRA]: cached with its command (bench/refs.sh)
. bench/refs.sh

# one NAME SCENE SIZE LABEL SEED BINARY OPTIONS...: one render, its log, one csv row
one() {
    name=$1 scene=$2 size=$3 label=$4 seed=$5 bin=$6
    shift 6
    img="$out/$name-$label-$seed.pfm" log="$out/log-$name-$label-$seed.csv"
    line=$($bin render "$scene" --size "$size" --threads "$threads" --seed "$seed" -q --passes "$passes" \
        --reference "bench/ref/$name.pfm" --log "$log" -o "$img" "$@" | tail -n 1)
    printf '%s,%s,%s,%s,%s,%s,%s,%s,%s,%s\n' "$name" "$label" "$seed" "$(kv "$line" passes)" \
        "$(kv "$line" seconds)" "$(kv "$line" relmse)" "$(kv "$line" est_relerr)" \
        "$(sed -n 's/^ref_mse=//p' "bench/ref/$name.mse")" "$log" "$(kv "$line" cpu_s)" >> "$out/results.csv"
    if [ "$name" = caustic-glass-56x80 ]; then
        printf '%s,%s,%s\n' "$label" "$seed" "$("$out/regions" "$img" "bench/ref/$name.pfm" \
            bench/caustic-glass-regions.txt | tr '\n' ',')" >> "$out/regions.csv"
    fi
}

# cost NAME SCENE SIZE: processor seconds per pass on 1 thread, interleaved rounds
cost() {
    round=0
    while [ "$round" -lt "$crounds" ]; do
        round=$((round + 1))
        for smp in qmc random; do
            line=$($APPM render "$2" --size "$3" --threads 1 --passes "$cpasses" --sampler "$smp" -q \
                -o "$out/cost.pfm" | tail -n 1)
            printf '%s,%s,%s,%s,%s\n' "$1" "$smp" "$round" "$(kv "$line" passes)" "$(kv "$line" cpu_s)" \
                >> "$out/cost.csv"
        done
    done
}

scene() { # NAME SCENE SIZE
    echo "scene $1"
    cost "$1" "$2" "$3"
    [ -n "$costonly" ] && return 0
    for seed in $seeds; do
        one "$1" "$2" "$3" qmc "$seed" "$APPM" --sampler qmc
        one "$1" "$2" "$3" random "$seed" "$APPM" --sampler random
        one "$1" "$2" "$3" qmc-4chains "$seed" "$APPM" --sampler qmc --chains 4
    done
}

costonly=${SAMPLER_COST_ONLY:-}
if [ -z "$costonly" ]; then
    echo "scene,sampler,seed,passes,seconds,relmse,est_relerr,ref_mse,log,cpu_s" > "$out/results.csv"
    rm -f "$out/regions.csv"
fi
echo "scene,sampler,round,passes,cpu_s" > "$out/cost.csv"
if [ -n "$costonly" ] && [ -f "$out/meta.txt" ]; then
    echo "cost measured again: $(date -u '+%Y-%m-%d %H:%M UTC'), commit $(git rev-parse --short HEAD 2>/dev/null || echo unknown), $cpasses passes, 1 thread, $crounds rounds" >> "$out/meta.txt"
else
    {
        echo "date: $(date -u '+%Y-%m-%d %H:%M UTC')"
        echo "commit: $(git rev-parse --short HEAD 2>/dev/null || echo unknown)"
        echo "machine: $(uname -sm), $(nproc 2>/dev/null) cores; threads: $threads"
        echo "passes: $passes; seeds: $seeds; cost: $cpasses passes, 1 thread, $crounds rounds"
    } > "$out/meta.txt"
fi
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
