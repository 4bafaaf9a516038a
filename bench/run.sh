#!/bin/sh
# bench/run.sh - the speed/accuracy suite behind `make bench` and `make bench-quick`.
#
#   sh bench/run.sh quick     one scene, small image, 6 runs of 8 s (plus the reference
#                             the first time)
#   sh bench/run.sh full      five scenes, the full ppm grid, throughput and scaling,
#                             and the sampler suite (bench/sampler.sh)
#   sh bench/run.sh refs      only the references of the full suite (the slow part)
#   sh bench/run.sh glossy    only CornellBox-Glossy of the full suite (its reference,
#                             the first time, is 2 x 67 M path-traced paths: 10 minutes
#                             on 2 loaded cores, then 6 runs of 10 s)
#
# For every scene: a reference (rendered once by a long path-tracing run and
# cached in bench/ref/ with the exact command in NAME.cmd; never committed),
# then every method for the same time budget with --reference and --log, then
# bench/report turns the logs into results.csv, report.md and SVG plots.
# The full suite also measures throughput (photon paths/s, eye paths/s, BVH
# rays/s, the share of each phase of a pass, 1 vs 2 threads, memory).
# Results go to bench/out/MODE/.  BENCH_THREADS (default 2) sets --threads.
set -u
mode=${1:-quick}
APPM=${APPM:-./appm}
CC=${CC:-cc}
threads=${BENCH_THREADS:-2}
out=bench/out/$mode
mkdir -p "$out" bench/ref
rm -f "$out"/*.csv "$out"/*.svg "$out"/*.md

[ -x "$APPM" ] || { echo "bench: build ./appm first (make)"; exit 1; }
$CC -std=c99 -O2 bench/report.c appm.c -o bench/report -lm -pthread || exit 1
$CC -std=c99 -O2 bench/refmix.c appm.c -o bench/refmix -lm -pthread || exit 1

# value of key=... in a summary line
kv() { printf '%s\n' "$1" | tr ' ' '\n' | sed -n "s/^$2=//p"; }

# reference NAME SCENE SIZE PASSES: two independent path-traced renders of PASSES passes,
# their mean and its own noise, cached with the commands that made them (bench/refs.sh)
. bench/refs.sh

# run NAME SCENE SIZE SECONDS METHOD CONFIG-LABEL [extra options...]
run() {
    name=$1 scene=$2 size=$3 secs=$4 method=$5 label=$6
    shift 6
    tag=$(printf '%s' "$method-$label" | tr ' =/' '_-_')
    log=$name-$tag.csv
    line=$($APPM render "$scene" --method "$method" --size "$size" --time "$secs" --threads "$threads" \
        --reference "bench/ref/$name.pfm" --log "$out/raw-$log" -q -o "$out/$name-$tag.pfm" "$@" | tail -n 1)
    # the RMSE against the truth: sqrt(measured MSE - reference noise); rows
    # whose error is within the reference's noise are left blank
    refmse=$(sed -n 's/^ref_mse=//p' "bench/ref/$name.mse")
    awk -F, -v OFS=, -v n="$refmse" 'NR == 1 { print; next }
        { if ($4 != "") { m = $4 * $4 - n; $4 = m > 0 ? sprintf("%.9g", sqrt(m)) : "" } print }' \
        "$out/raw-$log" > "$out/$log"
    printf '%s,%s,%s,%s\n' "$name" "$method" "$label" "$log" >> "$out/runs.csv"
    printf '  %-6s %-22s %s\n' "$method" "$label" "rmse=$(tail -n 1 "$out/$log" | cut -d, -f4) passes=$(kv "$line" passes)"
}

# scene NAME SCENE SIZE SECONDS REFPASSES GRID(small|full)
scene() {
    name=$1 file=$2 size=$3 secs=$4 refpasses=$5 grid=$6
    reference "$name" "$file" "$size" "$refpasses"
    r0=$(kv "$($APPM render "$file" --size "$size" --passes 1 --method ppm -q -o "$out/probe.pfm")" radius)
    rm -f "$out/probe.pfm"
    echo "scene $name ($size, ${secs}s per run, default radius $r0)"
    run "$name" "$file" "$size" "$secs" appm "default"
    run "$name" "$file" "$size" "$secs" sppm "default"
    run "$name" "$file" "$size" "$secs" pt "default"
    if [ "$grid" = full ]; then
        scales="0.25 0.5 1 2 4"
        alphas="0.5 0.667 0.8"
    else
        scales="0.25 1 4"
        alphas="0.667"
    fi
    for a in $alphas; do
        for s in $scales; do
            r=$(awk -v r="$r0" -v s="$s" 'BEGIN { printf "%.6g", r * s }')
            run "$name" "$file" "$size" "$secs" ppm "r0=${s}x alpha=$a" --radius "$r" --alpha "$a"
        done
    done
}

echo "scene,method,config,log" > "$out/runs.csv"
{
    echo "date: $(date -u '+%Y-%m-%d %H:%M UTC')"
    echo "commit: $(git rev-parse --short HEAD 2>/dev/null || echo unknown)"
    echo "machine: $(uname -sm), $(grep -m1 'model name' /proc/cpuinfo 2>/dev/null | sed 's/.*: //'), $(nproc 2>/dev/null) cores"
    echo "compiler: $($CC --version 2>/dev/null | head -n 1)"
    echo "threads: $threads"
} > "$out/meta.txt"
cat "$out/meta.txt"

if [ "$mode" = refs ]; then # only render (or check) the references of the full suite
    reference cornell-sphere-256 scenes/cornell-sphere.scene 256x256 8192
    reference cornell-original-128 scenes/cornell-original.scene 128x128 4096
    reference cornell-sphere-dof-128 scenes/cornell-sphere-dof.scene 128x128 4096
    reference cornell-mm-128 scenes/cornell-mm.scene 128x128 4096
    reference cornell-glossy-128 scenes/cornell-glossy.scene 128x128 4096
    exit 0
elif [ "$mode" = quick ]; then
    scene cornell-sphere-64 scenes/cornell-sphere.scene 64x64 8 8192 small
elif [ "$mode" = glossy ]; then
    scene cornell-glossy-128 scenes/cornell-glossy.scene 128x128 10 4096 small
else
    scene cornell-sphere-256 scenes/cornell-sphere.scene 256x256 30 8192 full
    scene cornell-original-128 scenes/cornell-original.scene 128x128 10 4096 small
    scene cornell-sphere-dof-128 scenes/cornell-sphere-dof.scene 128x128 10 4096 small
    scene cornell-mm-128 scenes/cornell-mm.scene 128x128 10 4096 small
    scene cornell-glossy-128 scenes/cornell-glossy.scene 128x128 10 4096 small
fi
bench/report "$out" > /dev/null || exit 1

if [ "$mode" = full ]; then
    sh bench/throughput.sh "$out" || exit 1
    sh bench/sampler.sh || exit 1
fi
echo "wrote $out/report.md"
