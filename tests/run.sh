#!/bin/sh
# tests/run.sh - runs every test command given on the command line, RUN_JOBS
# of them at a time (default: the number of processors), prints each one's
# result in the order given, with its seconds, and then the total
# "N passed, N failed" as its own last line; exits non-zero on any failure.
# Each command's closing line "N passed, N failed" is added up; one that
# crashes or prints no summary counts as one failure.
#
# Side by side is safe: no test asserts a time, and every command gets its own
# APPM_TEST_OUT (its number): tests/check.h's check_path puts its scratch files
# in tests/out-NUMBER, so that the normal and the sanitizer build of one test
# never write the same file.
jobs=${RUN_JOBS:-$(getconf _NPROCESSORS_ONLN 2>/dev/null || echo 1)}
case $jobs in '' | *[!0-9]* | 0) jobs=1 ;; esac
mkdir -p tests/out
dir=$(mktemp -d "${TMPDIR:-/tmp}/appm-run.XXXXXX") || exit 1
trap 'rm -rf "$dir"' EXIT
trap 'rm -rf "$dir"; exit 130' INT TERM
n=0
for t in "$@"; do
    n=$((n + 1))
    printf '%s\n' "$t" >"$dir/cmd.$n"
done
k=0
while [ "$k" -lt "$n" ]; do
    k=$((k + 1))
    echo "$k"
done | xargs -P "$jobs" -I{} sh -c '
    t0=$(date +%s)
    APPM_TEST_OUT="$2" sh -c "$(cat "$1/cmd.$2")" >"$1/out.$2" 2>&1
    echo $? >"$1/rc.$2"
    echo $(($(date +%s) - t0)) >"$1/sec.$2"' sh "$dir" {}

pass=0
fail=0
k=0
for t in "$@"; do
    k=$((k + 1))
    rc=$(cat "$dir/rc.$k" 2>/dev/null || echo 1)
    sec=$(cat "$dir/sec.$k" 2>/dev/null || echo "?")
    last=$(tail -n 1 "$dir/out.$k" 2>/dev/null)
    p=$(printf '%s\n' "$last" | sed -n 's/^\([0-9][0-9]*\) passed, \([0-9][0-9]*\) failed$/\1/p')
    f=$(printf '%s\n' "$last" | sed -n 's/^\([0-9][0-9]*\) passed, \([0-9][0-9]*\) failed$/\2/p')
    if [ -z "$p" ]; then
        tail -n 20 "$dir/out.$k" 2>/dev/null
        echo "FAIL $t: no summary line (exit status $rc) [$sec s]"
        fail=$((fail + 1))
        continue
    fi
    if [ "$rc" -ne 0 ] && [ "$f" -eq 0 ]; then f=1; fi
    if [ "$f" -ne 0 ]; then
        grep -v '^[0-9]* passed' "$dir/out.$k" | tail -n 40
        echo "FAIL $t: $p passed, $f failed [$sec s]"
    else
        echo "ok   $t: $p passed [$sec s]"
    fi
    pass=$((pass + p))
    fail=$((fail + f))
done
echo "$pass passed, $fail failed"
[ "$fail" -eq 0 ]
