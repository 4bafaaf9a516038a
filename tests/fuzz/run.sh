#!/bin/sh
# tests/fuzz/run.sh - builds the libFuzzer program of appm's readers and runs each target
# for a bounded time on a copy of its seed corpus (make fuzz).
#
#   sh tests/fuzz/run.sh [obj mtl scene pfm checkpoint image]     (default: all six)
#
# Environment:
#   FUZZ_SECONDS=30    seconds per target
#   FUZZ_RUNS=N        stop a target after N executions instead (make fuzz-long: 10 M, at
#                      most a day each)
#   FUZZ_OPTIONAL=1    exit 0 (with a message) when clang's libFuzzer is missing
#   FUZZ_CC=clang      the compiler
#   FUZZ_JOBS=N        targets built and run side by side (default: the processors)
#   FUZZ_FAST=1        build without comparison tracing (-fno-sanitize-coverage=trace-cmp):
#                      2.5-4 times the executions a second on these targets (the renderer's
#                      loops are full of comparisons), the same sanitizers and invariants,
#                      but the fuzzer no longer sees the operands of comparisons; and the
#                      plain schedule instead of the entropic one (-entropic=0), whose
#                      bookkeeping took a third of the time on a grown corpus; make
#                      fuzz-long uses it after a first stage with both
#   FUZZ_KEEP=1        continue from build/fuzz/corpus-<target> of an earlier run instead of
#                      starting again from the seed corpus
#
# Each target: clang -g -O1 -fsanitize=fuzzer,address,undefined (UBSan made fatal,
# so that a report counts as a crash), run with -rss_limit_mb=2000 -timeout=10.
# New corpus entries go to build/fuzz/corpus-<target>/ (tests/fuzz/corpus/ is not
# touched); crash, leak, timeout and OOM inputs go to build/fuzz/artifacts/.  Keep
# a crash input, minimised (-minimize_crash=1), in tests/fuzz/regressions/ with a
# descriptive name: tests/t_fuzz_regress.c replays that folder in make test.
# Prints one line per target (executions, new corpus size, crashes) and exits
# non-zero if a build failed or any target found a crash.
# shellcheck disable=SC2086 # $FLAGS and $seeds are word lists on purpose
set -u
here=$(cd "$(dirname "$0")" && pwd)
root=$(cd "$here/../.." && pwd)
cd "$root" || exit 1
CC=${FUZZ_CC:-clang}
SECONDS_EACH=${FUZZ_SECONDS:-30}
OUT=build/fuzz
FLAGS="-g -O1 -fsanitize=fuzzer,address,undefined -fno-sanitize-recover=all -fno-omit-frame-pointer"
SCHEDULE=""
if [ "${FUZZ_FAST:-0}" = 1 ]; then
    FLAGS="$FLAGS -fno-sanitize-coverage=trace-cmp"
    SCHEDULE="-entropic=0"
fi
targets=${*:-obj mtl scene pfm checkpoint image}

unavailable() {
    echo "fuzz: $1"
    if [ "${FUZZ_OPTIONAL:-0}" = 1 ]; then
        echo "fuzz: skipped (FUZZ_OPTIONAL=1)"
        exit 0
    fi
    echo "fuzz: install clang (with its libFuzzer runtime), or set FUZZ_OPTIONAL=1 to skip"
    exit 1
}

mkdir -p "$OUT/artifacts"
# Can this compiler link a trivial fuzzer at all?
if ! command -v "$CC" >/dev/null 2>&1; then unavailable "$CC not found"; fi
cat >"$OUT/probe.c" <<'EOF'
#include <stddef.h>
#include <stdint.h>
int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);
int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) { (void)data; (void)size; return 0; }
EOF
if ! $CC $FLAGS "$OUT/probe.c" -o "$OUT/probe" >"$OUT/probe.log" 2>&1; then
    cat "$OUT/probe.log"
    unavailable "$CC cannot link a libFuzzer program (-fsanitize=fuzzer)"
fi

# The one program of every target (tests/fuzz/fuzz.c), built once; fuzz_TARGET links
# to it and fuzzes the reader it is named after.
echo "fuzz: building tests/fuzz/fuzz.c"
built=1
$CC $FLAGS -std=c99 tests/fuzz/fuzz.c -o "$OUT/fuzz" -lm -pthread || built=0

# one TARGET: runs it; its summary line goes to $OUT/result-TARGET, and its
# executions, crashes and whether it failed to $OUT/count-TARGET
one() {
    t=$1
    rm -f "$OUT/result-$t" "$OUT/count-$t"
    case " obj mtl scene pfm checkpoint image " in
    *" $t "*) ;;
    *)
        echo "fuzz: no target $t (the targets: obj mtl scene pfm checkpoint image)" | tee "$OUT/result-$t"
        echo "0 0 1" >"$OUT/count-$t"
        return
        ;;
    esac
    if [ "$built" = 0 ]; then
        echo "FAIL fuzz_$t: build failed"
        echo "fuzz_$t: BUILD FAILED" >"$OUT/result-$t"
        echo "0 0 1" >"$OUT/count-$t"
        return
    fi
    ln -sf fuzz "$OUT/fuzz_$t"
    corpus="$OUT/corpus-$t"
    rm -rf "$OUT/artifacts/$t"
    mkdir -p "$OUT/artifacts/$t"
    if [ "${FUZZ_KEEP:-0}" != 1 ] || [ ! -d "$corpus" ]; then
        rm -rf "$corpus"
        mkdir -p "$corpus"
        cp tests/fuzz/corpus/"$t"/* "$corpus"/ 2>/dev/null
    fi
    seeds=""
    [ -d tests/fuzz/regressions ] && seeds=tests/fuzz/regressions
    runs=""
    [ -n "${FUZZ_RUNS:-}" ] && runs="-runs=$FUZZ_RUNS"
    echo "fuzz: running $t for $SECONDS_EACH s${runs:+ or $FUZZ_RUNS executions}"
    "./$OUT/fuzz_$t" -max_total_time="$SECONDS_EACH" $runs $SCHEDULE -rss_limit_mb=2000 -timeout=10 \
        -max_len=8192 -print_final_stats=1 \
        -artifact_prefix="$OUT/artifacts/$t/" "$corpus" $seeds >"$OUT/fuzz_$t.log" 2>&1
    rc=$?
    execs=$(sed -n 's/^stat::number_of_executed_units: *\([0-9]*\).*/\1/p' "$OUT/fuzz_$t.log" |
        tail -n 1)
    execs=${execs:-0}
    crashes=$(find "$OUT/artifacts/$t" -type f | wc -l | tr -d ' ')
    size=$(find "$corpus" -type f | wc -l | tr -d ' ')
    cov=$(sed -n 's/.* cov: \([0-9]*\) .*/\1/p' "$OUT/fuzz_$t.log" | tail -n 1)
    line="fuzz_$t: $execs executions, corpus $size files, coverage ${cov:-?} edges, $crashes crashes"
    bad=0
    if [ "$crashes" -ne 0 ] || [ "$rc" -ne 0 ]; then
        grep -E 'ERROR|SUMMARY|invariant|leaked|runtime error|deadly signal|Test unit written' \
            "$OUT/fuzz_$t.log" | head -n 20
        line="$line (exit status $rc; inputs in $OUT/artifacts/$t/, log $OUT/fuzz_$t.log)"
        [ "$crashes" -eq 0 ] && crashes=1
        bad=1
    fi
    echo "$line" | tee "$OUT/result-$t"
    echo "$execs $crashes $bad" >"$OUT/count-$t"
}

# FUZZ_JOBS targets at a time (each one libFuzzer process on one core)
jobs=${FUZZ_JOBS:-$(getconf _NPROCESSORS_ONLN 2>/dev/null || echo 1)}
case $jobs in '' | *[!0-9]* | 0) jobs=1 ;; esac
running=0
for t in $targets; do
    one "$t" &
    running=$((running + 1))
    if [ "$running" -ge "$jobs" ]; then
        wait
        running=0
    fi
done
wait

failed=0
total_execs=0
total_crashes=0
summary=""
for t in $targets; do
    if [ -f "$OUT/count-$t" ]; then
        read -r execs crashes bad <"$OUT/count-$t"
    else
        execs=0 crashes=0 bad=1
        echo "fuzz_$t: no result" >"$OUT/result-$t"
    fi
    [ "$bad" -ne 0 ] && failed=1
    summary="$summary
$(cat "$OUT/result-$t")"
    total_execs=$((total_execs + execs))
    total_crashes=$((total_crashes + crashes))
done
echo "fuzz summary:$summary"
echo "fuzz: $total_execs executions, $total_crashes crashes"
exit $failed
