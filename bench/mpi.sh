#!/bin/sh
# bench/mpi.sh [OUTDIR] - appm-mpi's speed-up and its exchange, measured:
# one job of N ranks with one thread each against appm alone with one thread,
# interleaved, MPI_ROUNDS rounds (default 3), medians; per N the wall time of
# the passes (the summary's seconds), the time in the exchange hook (waiting
# for slower ranks included) and the bytes each rank received and gave per
# pass.  Also checks that every image is byte-identical to the render alone.
# Writes OUTDIR/mpi.md (default bench/out).  MPI_SCENE, MPI_SIZE, MPI_PASSES,
# MPI_RANKS ("2" by default; "2 3 4" adds oversubscribed jobs, which measure
# nothing about speed on a 2-core machine) choose the case.
set -u
out=${1:-bench/out}
scene=${MPI_SCENE:-scenes/cornell-sphere.scene}
size=${MPI_SIZE:-800x640}
passes=${MPI_PASSES:-30}
rounds=${MPI_ROUNDS:-3}
ranks=${MPI_RANKS:-2}
OMPI_ALLOW_RUN_AS_ROOT=1
OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1
export OMPI_ALLOW_RUN_AS_ROOT OMPI_ALLOW_RUN_AS_ROOT_CONFIRM
mkdir -p "$out"
opts="render $scene --size $size --passes $passes --threads 1 -q"
field() { sed -n "s/.* $1=\([0-9.]*\).*/\1/p" "$2"; }
median() { sort -n | awk '{v[NR] = $1} END {print v[int((NR + 1) / 2)]}'; }
: >"$out/mpi-raw.txt"
r=1
while [ "$r" -le "$rounds" ]; do
    # shellcheck disable=SC2086 # $opts is a word list
    ./appm $opts -o "$out/mpi-1.pfm" >"$out/mpi-1.out" 2>/dev/null || exit 1
    echo "1 $(field seconds "$out/mpi-1.out") 0 0 0 $(field photons_stored "$out/mpi-1.out")" >>"$out/mpi-raw.txt"
    for n in $ranks; do
        # shellcheck disable=SC2086
        mpirun --oversubscribe -np "$n" ./appm-mpi $opts -o "$out/mpi-$n.pfm" >"$out/mpi-$n.out" 2>/dev/null || exit 1
        cmp -s "$out/mpi-1.pfm" "$out/mpi-$n.pfm" || {
            echo "bench/mpi.sh: the image of $n ranks differs from the render alone" >&2
            exit 1
        }
        echo "$n $(field seconds "$out/mpi-$n.out") $(field exchange_s "$out/mpi-$n.out")" \
            "$(field exchange_bytes_in "$out/mpi-$n.out") $(field exchange_bytes_out "$out/mpi-$n.out")" \
            "$(field photons_stored "$out/mpi-$n.out")" >>"$out/mpi-raw.txt"
    done
    r=$((r + 1))
done
{
    echo "## appm-mpi: $scene at $size, $passes passes, one thread a rank (medians of $rounds)"
    echo
    echo "    $(date -u '+%Y-%m-%d %H:%M UTC'), $(uname -sm), $(nproc 2>/dev/null || echo '?') cores," \
        "$(mpirun --version 2>/dev/null | head -n 1)"
    echo
    echo "| ranks | s a pass | speed-up | exchange s a pass | exchange share | MB in a pass (rank 0) | MB out a pass |"
    echo "|---|---|---|---|---|---|---|"
    t1=$(awk '$1 == 1 {print $2}' "$out/mpi-raw.txt" | median)
    for n in 1 $ranks; do
        t=$(awk -v n="$n" '$1 == n {print $2}' "$out/mpi-raw.txt" | median)
        x=$(awk -v n="$n" '$1 == n {print $3}' "$out/mpi-raw.txt" | median)
        bi=$(awk -v n="$n" '$1 == n {print $4}' "$out/mpi-raw.txt" | median)
        bo=$(awk -v n="$n" '$1 == n {print $5}' "$out/mpi-raw.txt" | median)
        awk -v n="$n" -v t="$t" -v t1="$t1" -v x="$x" -v bi="$bi" -v bo="$bo" -v p="$passes" 'BEGIN {
            printf "| %d | %.3f | %.2fx | %.3f | %.1f %% | %.1f | %.1f |\n", n, t / p, t1 / t, x / p, 100 * x / t,
                bi / p / 1e6, bo / p / 1e6 }'
    done
    echo
    echo "Photons stored in the last pass: $(awk '$1 == 1 {print $6; exit}' "$out/mpi-raw.txt");" \
        "every image byte-identical to the render alone (cmp)."
} >"$out/mpi.md"
cat "$out/mpi.md"
