#!/bin/sh
# tests/crash.sh - crash safety of checkpoints (make test-crash; CI runs a short form).
#
#   sh tests/crash.sh ./appm [KILLS]
#
# 1. SIGKILL loop: a render that saves a checkpoint after every pass is killed
#    with SIGKILL at random instants (some land inside a checkpoint write: a
#    ".tmp" is left behind), then resumed from its checkpoint, until it
#    finishes; at least KILLS kills (default 50).  After every kill the
#    checkpoint on disk must load (a resume that renders nothing and writes its
#    image), and the finished image must be byte-identical to an uninterrupted
#    render.
# 2. SIGTERM and SIGINT: the render stops after the pass in flight, writes its
#    image and checkpoint and exits 0; the resumed render ends in the same bytes.
# 3. A full disk (tests/crash/enospc.c through LD_PRELOAD, where the C
#    library allows it): a checkpoint write that runs out of space fails with a
#    message and exit 3, leaves the previous checkpoint as it was, no
#    temporary behind, and a resume from it ends in the same bytes.
# Prints one line per check, the counts, and "N passed, N failed" last.
set -u
APPM=${1:-./appm}
KILLS=${2:-${CRASH_KILLS:-50}}
T=tests/out/crash
rm -rf "$T"
mkdir -p "$T"
pass=0
fail=0
ok() { pass=$((pass + 1)); echo "ok   $1"; }
bad() { fail=$((fail + 1)); echo "FAIL $1"; }
SCENE=scenes/cornell-sphere.scene
PASSES=${CRASH_PASSES:-4000}
OPTS="--size 40x40 --threads 2 --seed 7 -q"

# shellcheck disable=SC2086 # $OPTS is a word list on purpose
"$APPM" render "$SCENE" $OPTS --passes "$PASSES" -o "$T/ref.pfm" >/dev/null 2>&1 || { bad "reference render"; }

# a pseudo-random number in [lo, hi] from awk (no $RANDOM in POSIX sh)
seed=12345
rnd() {
    seed=$(awk -v s="$seed" 'BEGIN {printf "%d", (s * 1103515245 + 12345) % 2147483648}')
    awk -v s="$seed" -v lo="$1" -v hi="$2" 'BEGIN {printf "%.3f", lo + (hi - lo) * s / 2147483648}'
}

# ---- 1. SIGKILL ---------------------------------------------------------------------
ck="$T/k.ckpt"
kills=0 midwrite=0 unreadable=0 runs=0 done=0
while [ "$done" = 0 ] && [ "$runs" -lt $((KILLS * 4)) ]; do
    runs=$((runs + 1))
    resume=""
    [ -f "$ck" ] && resume="--resume $ck"
    # shellcheck disable=SC2086
    "$APPM" render "$SCENE" $OPTS --passes "$PASSES" --checkpoint "$ck" --checkpoint-every 1 $resume \
        -o "$T/k.pfm" >/dev/null 2>"$T/k.err" &
    pid=$!
    if [ "$kills" -lt "$KILLS" ]; then
        sleep "$(rnd 0.02 0.2)"
        if kill -KILL "$pid" 2>/dev/null; then
            wait "$pid" 2>/dev/null
            kills=$((kills + 1))
            [ -f "$ck.tmp" ] && midwrite=$((midwrite + 1))
            if [ -f "$ck" ]; then # the checkpoint on disk loads: a resume of 1 pass renders none
                # shellcheck disable=SC2086
                if ! "$APPM" render "$SCENE" $OPTS --passes 1 --resume "$ck" -o "$T/probe.pfm" >/dev/null 2>&1; then
                    unreadable=$((unreadable + 1))
                    cp "$ck" "$T/unreadable-$kills.ckpt"
                fi
            fi
            continue
        fi
    fi
    wait "$pid" && done=1
done
echo "crash: $kills SIGKILLs over $runs runs, $midwrite inside a checkpoint write, $unreadable unreadable checkpoints"
[ "$kills" -ge "$KILLS" ] && ok "at least $KILLS kills ($kills)" || bad "only $kills kills (the render ended first: raise CRASH_PASSES)"
[ "$unreadable" -eq 0 ] && ok "every checkpoint left by a kill loads" || bad "$unreadable unreadable checkpoints"
[ "$done" = 1 ] && ok "the killed render finishes" || bad "the killed render never finished"
cmp -s "$T/k.pfm" "$T/ref.pfm" && ok "... in the bytes of the uninterrupted render" || bad "the resumed image differs"

# ---- 2. SIGTERM and SIGINT ----------------------------------------------------------------
for sig in TERM INT; do
    ck2="$T/s-$sig.ckpt"
    # shellcheck disable=SC2086
    "$APPM" render "$SCENE" $OPTS --passes "$PASSES" --checkpoint "$ck2" --checkpoint-every 1000 \
        -o "$T/s-$sig.pfm" >"$T/s.out" 2>"$T/s.err" &
    pid=$!
    sleep 0.5
    kill "-$sig" "$pid"
    wait "$pid"
    rc=$?
    [ "$rc" -eq 0 ] && [ -s "$T/s-$sig.pfm" ] && [ -s "$ck2" ] && ok "SIG$sig: exit 0, image and checkpoint written" ||
        bad "SIG$sig: exit $rc"
    # shellcheck disable=SC2086
    "$APPM" render "$SCENE" $OPTS --passes "$PASSES" --resume "$ck2" -o "$T/s-$sig-end.pfm" >/dev/null 2>&1
    cmp -s "$T/s-$sig-end.pfm" "$T/ref.pfm" && ok "SIG$sig: the resumed render ends in the same bytes" ||
        bad "SIG$sig: the resumed image differs"
done

# ---- 3. A full disk -------------------------------------------------------------------------
so="$T/enospc.so"
if ${CC:-cc} -shared -fPIC -O1 tests/crash/enospc.c -o "$so" -ldl 2>/dev/null &&
    LD_PRELOAD="$so" "$APPM" --version >/dev/null 2>&1; then
    ck3="$T/full.ckpt"
    # shellcheck disable=SC2086
    "$APPM" render "$SCENE" $OPTS --passes 5 --checkpoint "$ck3" -o "$T/full5.pfm" >/dev/null 2>&1
    size=$(wc -c <"$ck3")
    cp "$ck3" "$T/full-before.ckpt"
    # room for about half a checkpoint: the next save runs out of space
    # shellcheck disable=SC2086
    APPM_ENOSPC_BYTES=$((size / 2)) LD_PRELOAD="$so" "$APPM" render "$SCENE" $OPTS --passes "$PASSES" \
        --resume "$ck3" --checkpoint "$ck3" --checkpoint-every 1 -o "$T/full.pfm" >/dev/null 2>"$T/full.err"
    rc=$?
    [ "$rc" -eq 3 ] && grep -q "cannot write the checkpoint" "$T/full.err" &&
        ok "full disk: the failed save says so, exit 3" || bad "full disk: exit $rc, $(head -c 200 "$T/full.err")"
    cmp -s "$ck3" "$T/full-before.ckpt" && ok "full disk: the previous checkpoint is untouched" ||
        bad "full disk: the checkpoint changed"
    [ ! -e "$ck3.tmp" ] && ok "full disk: no temporary left behind" || bad "full disk: $ck3.tmp left behind"
    # shellcheck disable=SC2086
    "$APPM" render "$SCENE" $OPTS --passes "$PASSES" --resume "$ck3" -o "$T/full-end.pfm" >/dev/null 2>&1
    cmp -s "$T/full-end.pfm" "$T/ref.pfm" && ok "full disk: resuming from it ends in the same bytes" ||
        bad "full disk: the resumed image differs"
    # an image write on a full disk: an error, no partial file under the final name
    # shellcheck disable=SC2086
    APPM_ENOSPC_BYTES=1000 LD_PRELOAD="$so" "$APPM" render "$SCENE" $OPTS --passes 1 -o "$T/full-img.pfm" \
        >/dev/null 2>"$T/img.err"
    rc=$?
    [ "$rc" -ne 0 ] && [ ! -e "$T/full-img.pfm" ] && [ ! -e "$T/full-img.pfm.tmp" ] &&
        ok "full disk: an image that does not fit is an error, no file left" || bad "full disk image: exit $rc"
else
    echo "skip full disk: no LD_PRELOAD shim here (needs a dynamic C library with dlsym)"
fi
echo "$pass passed, $fail failed"
[ "$fail" -eq 0 ]
