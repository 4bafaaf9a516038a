#!/bin/sh
# tests/mpi.sh - appm-mpi, the command line over MPI (mpi.c), against appm:
#   1. every method (and appm with guided emission, and with two chains):
#      the image of N = 1, 2, 3, 4 ranks (1 or 2 threads each) is byte for
#      byte the image of appm render with the same options;
#   2. a checkpoint of a job of 3 ranks resumes in a job of 2 (and in appm
#      alone) and ends in the image of the uninterrupted render;
#   3. a rank that runs out of memory - in the scene's load, the renderer's
#      creation or its first pass - ends the job: non-zero exit, its message
#      (and rank 0's naming it), within a time limit (no hang); so does a file
#      only rank 0 reads (--reference) that is missing;
#   4. a rank killed by SIGKILL ends the job (non-zero exit, no hang), and the
#      last checkpoint still loads and resumes; SIGUSR1 to mpirun stops after
#      the pass in flight with the image and checkpoint written; render --help
#      prints once;
#   5. a scene only rank 0 can read (the other rank works in a folder where the
#      scene's relative path leads nowhere) renders the same image.
#
#   sh tests/mpi.sh ./appm ./appm-mpi        (from the repository root)
#
# Needs Open MPI's mpirun (ranks beyond the cores: --oversubscribe).  Prints
# one line per failed check and "N passed, N failed" as its last line.

if [ $# -lt 2 ]; then
    echo "usage: sh tests/mpi.sh APPM APPM-MPI" >&2
    exit 2
fi
abspath() { (cd "$(dirname "$1")" && printf '%s/%s\n' "$(pwd)" "$(basename "$1")"); }
APPM=$(abspath "$1")
AMPI=$(abspath "$2")
ROOT=$(pwd)
T=$ROOT/tests/out/mpi
rm -rf "$T"
mkdir -p "$T"
# Open MPI refuses root without these (CI runs as root)
OMPI_ALLOW_RUN_AS_ROOT=1
OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1
OMPI_MCA_rmaps_base_oversubscribe=1
OMPI_MCA_btl_vader_single_copy_mechanism=none # containers forbid the cross-process copy
export OMPI_ALLOW_RUN_AS_ROOT OMPI_ALLOW_RUN_AS_ROOT_CONFIRM OMPI_MCA_rmaps_base_oversubscribe OMPI_MCA_btl_vader_single_copy_mechanism
MPIRUN="mpirun --oversubscribe"

npass=0
nfail=0
ok() { npass=$((npass + 1)); }
bad() {
    nfail=$((nfail + 1))
    echo "FAIL: $*"
}
# same WHAT A B: the two files hold the same bytes
same() {
    if [ -f "$2" ] && [ -f "$3" ] && cmp -s "$2" "$3"; then ok; else bad "$1: $2 and $3 differ"; fi
}

if ! command -v mpirun >/dev/null 2>&1; then
    bad "no mpirun (install openmpi-bin)"
    echo "$npass passed, $nfail failed"
    exit 1
fi

BOX=scenes/cornell-sphere.scene
GLASS=scenes/caustic-glass.scene
SMALL="--size 40x30 --passes 4 --photons 4000 -q"

# 1. byte identity, every method, N = 1..4
for case in "appm:$BOX" "appm-paper:$BOX" "ppm:$BOX" "sppm:$BOX" "pt:$BOX" "appm:$GLASS:--emission guided" \
    "appm:$GLASS:--chains 2"; do
    m=${case%%:*}
    rest=${case#*:}
    scene=${rest%%:*}
    extra=
    [ "$rest" != "$scene" ] && extra=${rest#*:}
    tag=$(printf '%s-%s-%s' "$m" "$(basename "$scene" .scene)" "$extra" | tr -c 'a-z0-9-' '_')
    # shellcheck disable=SC2086 # the option lists split on purpose
    "$APPM" render "$scene" $SMALL --method "$m" $extra --threads 2 -o "$T/$tag-1.pfm" >/dev/null 2>&1 ||
        bad "$tag: appm alone failed"
    for n in 1 2 3 4; do
        th=$((1 + n % 2))
        # shellcheck disable=SC2086
        timeout 120 $MPIRUN -np $n "$AMPI" render "$scene" $SMALL --method "$m" $extra --threads $th \
            -o "$T/$tag-n$n.pfm" >"$T/$tag-n$n.out" 2>&1 || bad "$tag: $n ranks failed: $(tail -n 3 "$T/$tag-n$n.out")"
        same "$tag, $n ranks x $th threads" "$T/$tag-1.pfm" "$T/$tag-n$n.pfm"
    done
done
# the summary line: rank 0's alone, with the job's size and exchange appended
if grep -q '^passes=4 .* ranks=3 exchange_s=[0-9.]* exchange_bytes_in=[1-9]' "$T/appm-cornell-sphere--n3.out" &&
    [ "$(grep -c '^passes=' "$T/appm-cornell-sphere--n3.out")" -eq 1 ]; then ok; else
    bad "summary of 3 ranks: $(cat "$T/appm-cornell-sphere--n3.out")"
fi

# 2. resume across sizes: 2 passes on 3 ranks, then 2 more on 2 ranks (and alone)
OPT="--size 40x30 --photons 4000 -q"
# shellcheck disable=SC2086
"$APPM" render $BOX $OPT --passes 4 -o "$T/r-ref.pfm" >/dev/null 2>&1
# shellcheck disable=SC2086
timeout 120 $MPIRUN -np 3 "$AMPI" render $BOX $OPT --passes 2 --checkpoint "$T/r.ck" -o "$T/r-2.pfm" \
    >/dev/null 2>&1 || bad "resume: the job of 3 ranks failed"
cp "$T/r.ck" "$T/r-alone.ck"
# shellcheck disable=SC2086
timeout 120 $MPIRUN -np 2 "$AMPI" render $BOX $OPT --passes 4 --resume "$T/r.ck" -o "$T/r-4.pfm" \
    >"$T/r-4.out" 2>&1 || bad "resume: the job of 2 ranks failed: $(tail -n 3 "$T/r-4.out")"
same "resume 3 ranks -> 2 ranks" "$T/r-ref.pfm" "$T/r-4.pfm"
grep -q ' resumed=2' "$T/r-4.out" && ok || bad "resume: no resumed=2 in $(cat "$T/r-4.out")"
# shellcheck disable=SC2086
"$APPM" render $BOX $OPT --passes 4 --resume "$T/r-alone.ck" -o "$T/r-alone.pfm" >/dev/null 2>&1
same "resume 3 ranks -> appm alone" "$T/r-ref.pfm" "$T/r-alone.pfm"

# 3. a rank out of memory in its first pass
APPM_MPI_FAIL=1:pass timeout 60 $MPIRUN -np 2 "$AMPI" render $BOX $OPT --passes 3 -o "$T/f.pfm" >"$T/f.out" 2>&1
rc=$?
if [ "$rc" -ne 0 ] && [ "$rc" -ne 124 ] && grep -q 'appm: rank 1: pass failed: out of memory' "$T/f.out" &&
    grep -q 'rank 1 failed in the photon' "$T/f.out"; then ok; else
    bad "rank out of memory (exit $rc): $(cat "$T/f.out")"
fi
[ ! -f "$T/f.pfm" ] && ok || bad "rank out of memory: an image was written without a pass"
# ... in its renderer's creation: the ranks agree to stop, rank 0 names the rank
APPM_MPI_FAIL=1:create timeout 60 $MPIRUN -np 2 "$AMPI" render $BOX $OPT --passes 3 -o "$T/f3.pfm" >"$T/f3.out" 2>&1
rc=$?
if [ "$rc" -eq 3 ] && grep -q 'appm: rank 1 of 2 failed (exit code 3' "$T/f3.out" &&
    grep -q 'appm: rank 1: out of memory' "$T/f3.out"; then ok; else
    bad "rank out of memory at creation (exit $rc): $(cat "$T/f3.out")"
fi
# ... while the scene's files are still being sent: the job is ended at once
APPM_MPI_FAIL=1:load timeout 60 $MPIRUN -np 2 "$AMPI" render $BOX $OPT --passes 3 -o "$T/f4.pfm" >"$T/f4.out" 2>&1
rc=$?
if [ "$rc" -ne 0 ] && [ "$rc" -ne 124 ] && grep -q 'appm: rank 1: .*out of memory' "$T/f4.out" &&
    grep -q 'appm: rank 1: ending the job' "$T/f4.out"; then ok; else
    bad "rank out of memory in the load (exit $rc): $(cat "$T/f4.out")"
fi

# a file only rank 0 reads (--reference) missing, with a --resume that every rank reads: exit 2, no hang
# shellcheck disable=SC2086
timeout 60 $MPIRUN -np 2 "$AMPI" render $BOX $OPT --passes 3 --resume "$T/r-alone.ck" --reference "$T/none.pfm" \
    -o "$T/f2.pfm" >"$T/f2.out" 2>&1
rc=$?
if [ "$rc" -eq 2 ] && grep -q 'none.pfm' "$T/f2.out"; then ok; else bad "missing reference (exit $rc): $(cat "$T/f2.out")"; fi

# 4. a rank killed while the job checkpoints every pass
# shellcheck disable=SC2086
timeout 120 $MPIRUN -np 2 "$AMPI" render $BOX --size 64x48 -q --passes 100000 --time 100 --checkpoint "$T/k.ck" \
    --checkpoint-every 1 -o "$T/k.pfm" >"$T/k.out" 2>&1 &
job=$!
i=0
while [ ! -f "$T/k.ck" ] && [ $i -lt 200 ]; do
    sleep 0.1
    i=$((i + 1))
done
sleep 0.5
victim=
for p in $(pgrep -P "$(pgrep -P $job mpirun)"); do # this job's ranks: children of its mpirun
    if tr '\0' '\n' <"/proc/$p/environ" 2>/dev/null | grep -q '^OMPI_COMM_WORLD_RANK=1$'; then victim=$p; fi
done
if [ -n "$victim" ]; then
    kill -9 "$victim"
    wait $job
    rc=$?
    if [ "$rc" -ne 0 ] && [ "$rc" -ne 124 ]; then ok; else bad "killed rank: the job ended with $rc"; fi
    passes=$("$APPM" render $BOX --size 64x48 -q --passes 1 --resume "$T/k.ck" -o "$T/k0.pfm" 2>&1 |
        sed -n 's/^passes=\([0-9]*\) .*/\1/p')
    if [ -n "$passes" ] && [ "$passes" -ge 1 ] &&
        "$APPM" render $BOX --size 64x48 -q --passes $((passes + 1)) --resume "$T/k.ck" -o "$T/k1.pfm" \
            >/dev/null 2>&1; then ok; else bad "killed rank: the checkpoint did not resume ($passes passes)"; fi
else
    kill $job 2>/dev/null
    wait $job
    bad "killed rank: rank 1's process not found"
fi

# SIGUSR1 to mpirun (which Open MPI passes on; Ctrl-C kills the ranks): the pass in flight
# ends, the image and the checkpoint are written, exit 0
rm -f "$T/u.pfm" "$T/u.ck"
timeout 120 $MPIRUN -np 2 "$AMPI" render $BOX --size 64x48 --passes 100000 --time 100 --checkpoint "$T/u.ck" \
    -o "$T/u.pfm" >"$T/u.out" 2>&1 &
job=$!
sleep 3
pkill -USR1 -P $job mpirun
wait $job
rc=$?
if [ "$rc" -eq 0 ] && grep -q ' interrupted=1' "$T/u.out" && [ -f "$T/u.pfm" ] && [ -f "$T/u.ck" ]; then ok; else
    bad "SIGUSR1 (exit $rc): $(cat "$T/u.out")"
fi
# render --help: once, exit 0
out=$(timeout 60 $MPIRUN -np 2 "$AMPI" render --help 2>&1)
rc=$?
if [ "$rc" -eq 0 ] && [ "$(printf '%s\n' "$out" | grep -c '^usage: appm render')" -eq 1 ]; then ok; else
    bad "render --help (exit $rc): $out"
fi

# 5. a scene only rank 0 can read: rank 1 works in an empty folder
mkdir -p "$T/seen/scenes" "$T/blind"
cp scenes/cornell-sphere.scene scenes/CornellBox-Sphere.obj scenes/CornellBox-Sphere.mtl "$T/seen/scenes/"
(cd "$T/seen" && "$APPM" render scenes/cornell-sphere.scene $OPT --passes 3 -o "$T/s-1.pfm" >/dev/null 2>&1)
# shellcheck disable=SC2086
timeout 120 $MPIRUN -np 1 --wdir "$T/seen" "$AMPI" render scenes/cornell-sphere.scene $OPT --passes 3 \
    -o "$T/s-2.pfm" : -np 1 --wdir "$T/blind" "$AMPI" render scenes/cornell-sphere.scene $OPT --passes 3 \
    -o "$T/s-2.pfm" >"$T/s.out" 2>&1 || bad "scene on rank 0 only: the job failed: $(tail -n 3 "$T/s.out")"
# the premise: from rank 1's folder the scene cannot be read
# shellcheck disable=SC2086
(cd "$T/blind" && "$APPM" render scenes/cornell-sphere.scene $OPT --passes 1 -o "$T/s-0.pfm" >/dev/null 2>&1)
[ $? -eq 2 ] && ok || bad "scene on rank 0 only: appm in rank 1's folder read the scene"
same "scene on rank 0 only" "$T/s-1.pfm" "$T/s-2.pfm"

echo "$npass passed, $nfail failed"
[ "$nfail" -eq 0 ]
