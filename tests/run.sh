#!/bin/sh
# Runs every test program given on the command line (and tests/cli.sh when
# APPM_CLI is set to the appm binary), adds up their "N passed, N failed"
# closing lines and prints the total as its own last line.
# A program that crashes or prints no summary counts as one failure.
pass=0
fail=0
mkdir -p tests/out
for t in "$@"; do
    out=$(sh -c "$t" 2>&1)
    rc=$?
    last=$(printf '%s\n' "$out" | tail -n 1)
    p=$(printf '%s\n' "$last" | sed -n 's/^\([0-9][0-9]*\) passed, \([0-9][0-9]*\) failed$/\1/p')
    f=$(printf '%s\n' "$last" | sed -n 's/^\([0-9][0-9]*\) passed, \([0-9][0-9]*\) failed$/\2/p')
    if [ -z "$p" ]; then
        printf '%s\n' "$out" | tail -n 20
        echo "FAIL $t: no summary line (exit status $rc)"
        fail=$((fail + 1))
        continue
    fi
    if [ "$rc" -ne 0 ] && [ "$f" -eq 0 ]; then f=1; fi
    if [ "$f" -ne 0 ]; then
        printf '%s\n' "$out" | grep -v '^[0-9]* passed' | tail -n 40
        echo "FAIL $t: $p passed, $f failed"
    else
        echo "ok   $t: $p passed"
    fi
    pass=$((pass + p))
    fail=$((fail + f))
done
echo "$pass passed, $fail failed"
[ "$fail" -eq 0 ]
