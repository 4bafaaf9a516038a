#!/bin/sh
# bench/envmap.sh - what drawing shadow rays and photons from the environment
# map buys (make bench-envmap).
#
# Scene (written here): a white sphere (Kd 0.8) on a grey floor (Kd 0.5) under
# a 256 x 128 map: a dim sky (0.2 .. 0.5) and a sun 1 degree wide, 35 degrees
# high, holding about three quarters of the light (bench/envmap.py).  Two
# builds of appm: the default (the map's density; for shadow rays mixed with the cosine and the
# product density, docs/algorithm.md 5.9) and -DAPPM_ENV_UNIFORM=1 (shadow rays by the
# cosine alone, photons from uniform directions: what a constant environment
# does).  Each renders ENV_SECONDS (default 10) of wall time for each seed of
# ENV_SEEDS (default 1 2 3), appm and pt; the RMSE against a long path-traced
# reference (pt, ENV_REF_PASSES passes, default 4096, with the map's density)
# is reported per method as the median over the seeds, and the ratio.
# Results: bench/out/envmap/envmap.md (or ENV_OUT).
set -u
CC=${CC:-cc}
threads=${BENCH_THREADS:-2}
secs=${ENV_SECONDS:-10}
seeds=${ENV_SEEDS:-"1 2 3"}
refp=${ENV_REF_PASSES:-4096}
out=${ENV_OUT:-bench/out/envmap}
size=${ENV_SIZE:-128x96}
mkdir -p "$out"
$CC -std=c99 -O2 appm.c main.c -o "$out/appm-map" -lm -pthread || exit 1
$CC -std=c99 -O2 -DAPPM_ENV_UNIFORM=1 appm.c main.c -o "$out/appm-uniform" -lm -pthread || exit 1
python3 bench/envmap.py "$out" || exit 1
scene="$out/sun.scene"
if [ ! -f "$out/ref.pfm" ]; then
    echo "envmap: reference, $refp passes of pt"
    "$out/appm-map" render "$scene" --size "$size" --threads "$threads" --seed 99 --method pt --passes "$refp" \
        -q -o "$out/ref.pfm" >/dev/null || exit 1
fi
kv() { printf '%s\n' "$1" | tr ' ' '\n' | sed -n "s/^$2=//p"; }
median() { sort -g | awk '{a[NR] = $1} END {print a[int((NR + 1) / 2)]}'; }
echo "build,method,seed,passes,rmse" >"$out/results.csv"
for method in appm pt; do
    for build in map uniform; do
        for seed in $seeds; do
            line=$("$out/appm-$build" render "$scene" --size "$size" --threads "$threads" --seed "$seed" \
                --method "$method" --time "$secs" -q -o "$out/$build-$method-$seed.pfm" | tail -n 1)
            rmse=$("$out/appm-map" compare "$out/$build-$method-$seed.pfm" "$out/ref.pfm" | tr ' ' '\n' |
                sed -n 's/^rmse=//p')
            echo "$build,$method,$seed,$(kv "$line" passes),$rmse" >>"$out/results.csv"
            echo "envmap: $build $method seed $seed: passes $(kv "$line" passes) rmse $rmse"
        done
    done
done
{
    echo "| method | RMSE, map's density | RMSE, uniform | ratio | passes (map / uniform) |"
    echo "|---|---|---|---|---|"
    for method in appm pt; do
        m=$(awk -F, -v m="$method" '$1 == "map" && $2 == m {print $5}' "$out/results.csv" | median)
        u=$(awk -F, -v m="$method" '$1 == "uniform" && $2 == m {print $5}' "$out/results.csv" | median)
        pm=$(awk -F, -v m="$method" '$1 == "map" && $2 == m {print $4}' "$out/results.csv" | median)
        pu=$(awk -F, -v m="$method" '$1 == "uniform" && $2 == m {print $4}' "$out/results.csv" | median)
        echo "| $method | $m | $u | $(awk -v a="$m" -v b="$u" 'BEGIN {printf "%.3f", a / b}')x | $pm / $pu |"
    done
} >"$out/envmap.md"
cat "$out/envmap.md"
