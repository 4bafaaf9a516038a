#!/bin/sh
# Self-contained test of bench/report.c.
#
# Builds the tool into a temporary directory, writes synthetic logs whose RMSE
# follows exact power laws, runs the report and checks the fitted slopes, the
# equal-time ratio, the time-to-target table, the SVGs and the handling of bad
# input.  Prints "N passed, M failed" last; exits non-zero on any failure.
#
#   sh bench/test_report.sh
#   CC=clang sh bench/test_report.sh
#   CFLAGS='-g -fsanitize=address,undefined -fno-sanitize-recover=all' sh bench/test_report.sh

# Single quotes below hold awk programs and sh -c scripts that take their
# arguments as $1: nothing is meant to expand there.
# shellcheck disable=SC2016

here=$(cd "$(dirname "$0")" && pwd)
tmp=$(mktemp -d "${TMPDIR:-/tmp}/report-test.XXXXXX") || exit 1
trap 'rm -rf "$tmp"' EXIT INT TERM
passed=0
failed=0

ok() { passed=$((passed + 1)); echo "ok   $1"; }
bad() { failed=$((failed + 1)); echo "FAIL $1"; }
check() { # check NAME COMMAND...: passes when the command succeeds
    name=$1
    shift
    if "$@"; then ok "$name"; else bad "$name"; fi
}

# shellcheck disable=SC2086 # CFLAGS is a list of flags
if ! ${CC:-cc} -std=c99 -Wall -Wextra -pedantic -Werror -O2 ${CFLAGS:-} \
    "$here/report.c" "$here/../appm.c" -o "$tmp/report" -lm -pthread; then
    bad "compile"
    echo "$passed passed, $failed failed"
    exit 1
fi
ok "compile"

d=$tmp/res
mkdir "$d"

# gen FILE PASSES PHOTONS_PER_PASS PHOTONS_PER_SECOND A EXPONENT [PT]
# Pass p emits PHOTONS_PER_PASS photons, so photons = k p and seconds =
# photons / rate.  RMSE = A x^EXPONENT with x = photons (x = pass for PT, whose
# photons are 0).  The first third of the log range (p < PASSES^(1/3), e.g.
# passes 1-4 of 100) is raised by 1.5 so that a fit over all points would miss
# the true slope.
gen() {
    awk -v n="$2" -v k="$3" -v rate="$4" -v a="$5" -v e="$6" -v pt="${7:-0}" 'BEGIN {
        print "pass,seconds,photons,rmse,relmse"
        print "0,0,0,,"                           # no estimate yet: skipped
        for (p = 1; p <= n; p++) {
            if (pt) { ph = 0; s = p / rate; x = p }
            else { ph = k * p; s = ph / rate; x = ph }
            r = a * exp(e * log(x))
            if (p < exp(log(n) / 3) && !pt) r *= 1.5
            printf "%d,%.17g,%.17g,%.17g,%.17g\n", p, s, ph, r, 2 * r
            if (p == 50) print ""                 # blank lines are ignored
        }
    }' > "$1"
}

gen "$d/box-appm.csv" 100 100000 1000000 1 -0.5
gen "$d/box-ppm-a.csv" 100 100000 1000000 2 -0.33333333333333333
gen "$d/box-ppm-b.csv" 50 100000 700000 3 -0.33333333333333333
gen "$d/box-pt.csv" 100 0 5 0.5 -0.5 1
# CRLF line endings must read the same.
awk '{ printf "%s\r\n", $0 }' "$d/box-appm.csv" > "$d/tmp.csv" && mv "$d/tmp.csv" "$d/box-appm.csv"

# A malformed log: bad number on line 4.
printf 'pass,seconds,photons,rmse,relmse\n1,0.1,100000,0.1,0.2\n2,0.2,200000,0.09,0.18\n3,abc,300000,0.08,0.16\n' \
    > "$d/box-sppm-bad.csv"

# Degenerate scene: a one-row run, a run whose RMSE never changes, and rows
# with zero, negative and NaN RMSE.
printf 'pass,seconds,photons,rmse,relmse\n1,0.5,1000,0.01,0.02\n' > "$d/tiny-appm.csv"
printf 'pass,seconds,photons,rmse,relmse\n1,1,1000,0.01,\n2,2,2000,0.01,\n3,3,3000,0,\n4,4,4000,-1,\n5,5,5000,nan,\n6,6,6000,0.01,\n' \
    > "$d/tiny-ppm.csv"

printf 'scene,method,config,log\r\n' > "$d/runs.csv"
{
    printf 'box,appm,r0=1x,box-appm.csv\r\n'
    printf '\r\n'
    printf 'box,ppm,r0=1x alpha=0.667,box-ppm-a.csv\n'
    printf 'box,ppm,r0=1x alpha=0.5,box-ppm-b.csv\n'
    printf 'box,pt,spp=1,box-pt.csv\n'
    printf 'box,sppm,alpha=0.7,box-sppm-bad.csv\n'
    printf 'box,sppm,alpha=0.8,missing.csv\n'
    printf '\n'
    printf 'tiny,appm,"single, row",tiny-appm.csv\n'
    printf 'tiny,ppm,flat,tiny-ppm.csv\n'
} >> "$d/runs.csv"

"$tmp/report" "$d" --target-rmse 4e-4 --target-rmse 0.02 > "$tmp/out" 2> "$tmp/err"
status=$?
check "exit status 0 with skipped runs" test "$status" -eq 0
check "malformed log reported with file and line" grep -q 'box-sppm-bad.csv:4' "$tmp/err"
check "missing log reported" grep -q 'missing.csv' "$tmp/err"
check "results.csv written" test -s "$d/results.csv"
check "bad runs left out of results.csv" \
    sh -c '! grep -q sppm "$1"' sh "$d/results.csv"

# slope SCENE METHOD CONFIG COLUMN EXPECTED: fitted slope within 1e-3.
slope() {
    awk -F, -v m="$2" -v c="$3" -v col="$4" -v want="$5" -v s="$1" '
        NR == 1 { for (i = 1; i <= NF; i++) h[$i] = i; next }
        $1 == s && $2 == m && $3 == c { v = $h[col]; found = 1 }
        END {
            d = v - want
            if (!found || v == "" || d > 1e-3 || d < -1e-3) {
                printf "  %s %s %s: %s = \"%s\", want %s\n", s, m, c, col, v, want
                exit 1
            }
        }' "$d/results.csv"
}
check "appm slope vs photons" slope box appm r0=1x slope_rmse_photons -0.5
check "appm slope vs time" slope box appm r0=1x slope_rmse_time -0.5
check "ppm a slope vs photons" slope box ppm 'r0=1x alpha=0.667' slope_rmse_photons -0.333333
check "ppm a slope vs time" slope box ppm 'r0=1x alpha=0.667' slope_rmse_time -0.333333
check "ppm b slope vs photons" slope box ppm 'r0=1x alpha=0.5' slope_rmse_photons -0.333333
check "ppm b slope vs time" slope box ppm 'r0=1x alpha=0.5' slope_rmse_time -0.333333
check "pt slope vs passes" slope box pt spp=1 slope_rmse_photons -0.5
check "pt slope vs time" slope box pt spp=1 slope_rmse_time -0.5
check "pt says it fitted vs passes" \
    awk -F, '$2 == "pt" && $NF == "passes" { f = 1 } END { exit !f }' "$d/results.csv"
check "appm says it fitted vs photons" \
    awk -F, '$2 == "appm" && $1 == "box" && $NF == "photons" { f = 1 } END { exit !f }' "$d/results.csv"
check "final rmse and totals of appm" \
    awk -F, '$1 == "box" && $2 == "appm" {
        f = ($4 == 100 && $5 == 10 && $6 == 1e7 && ($7 - 1e-7 ^ 0.5) ^ 2 < 1e-20 &&
             ($8 - 2e-7 ^ 0.5 * 2 ^ 0.5) ^ 2 < 1e-20) }
        END { exit !f }' "$d/results.csv"
check "one-row run listed without slopes" \
    awk -F, '$1 == "tiny" && $2 == "appm" && $(NF - 1) == "" && $(NF - 2) == "" { f = 1 }
        END { exit !f }' "$d/results.csv"
check "flat run has slope 0" slope tiny ppm flat slope_rmse_time 0

for s in box tiny; do
    for kind in time photons; do
        f=$d/$s-rmse-$kind.svg
        check "$s-rmse-$kind.svg exists" test -s "$f"
        check "$s-rmse-$kind.svg is an svg" grep -q '<svg' "$f"
        check "$s-rmse-$kind.svg has no NaN" sh -c '! grep -qi nan "$1"' sh "$f"
        check "$s-rmse-$kind.svg is complete" grep -q '</svg>' "$f"
    done
done
check "guide lines labelled" sh -c 'grep -q "slope -1/3" "$1" && grep -q "slope -1/2" "$1"' \
    sh "$d/box-rmse-time.svg"
check "legend names method and config" grep -q 'ppm r0=1x alpha=0.667' "$d/box-rmse-time.svg"
check "pt left out of photon plot" sh -c '! grep -q "pt spp=1" "$1"' sh "$d/box-rmse-photons.svg"
check "pt drawn in time plot" grep -q 'pt spp=1' "$d/box-rmse-time.svg"

# The equal time is where the shortest run (ppm b: 50 passes of 1e5 photons at
# 7e5 photons/s) stops: T = 5e6 / 7e5 = 50/7 s, when appm and ppm a have emitted
# x = 1e6 T = 5e7/7 photons.  There appm has RMSE x^(-1/2) and the best ppm
# (a; b has 3 (5e6)^(-1/3) = 0.01754 > 2 x^(-1/3) = 0.01038) has 2 x^(-1/3),
# so the ratio is x^(-1/6) / 2 = 0.5 exp(-ln(7142857.14) / 6) = 0.0360295.
check "report.md written" test -s "$d/report.md"
check "ratio line has the right value" awk '
    /^appm \/ best ppm equal-time RMSE ratio: / && !seen {
        seen = 1
        v = $8 + 0
        want = 0.5 * exp(-log(5e7 / 7) / 6)
        if (want - 0.0360295 > 1e-6 || want - 0.0360295 < -1e-6) exit 1
        f = (v - want) / want < 1e-3 && (want - v) / want < 1e-3
        if (!f) printf "  ratio %s, want %.6g\n", $8, want
    }
    END { exit !f }' "$d/report.md"
check "equal time is 50/7 s" grep -q 'Equal-time RMSE at T = 7.143 s' "$d/report.md"
# In scene tiny the one-row appm run stops (0.5 s) before ppm's first row (1 s).
check "ratio line for the scene without a common time" \
    grep -q '^appm / best ppm equal-time RMSE ratio: — (no equal-time RMSE)$' "$d/report.md"
check "plots embedded" sh -c 'grep -q "](box-rmse-time.svg)" "$1" &&
    grep -q "](box-rmse-photons.svg)" "$1"' sh "$d/report.md"
# appm reaches 4e-4 at x = 6.25e6 photons, 6.25 s (between passes 62 and 63);
# its first point (0.1 s) is already below 0.02.  ppm a reaches 0.02 at 1e6
# photons, 1 s, and never reaches 4e-4.
check "time to target appm" grep -q '^| appm | r0=1x | 6.25 | 0.1 |$' "$d/report.md"
check "time to target ppm" grep -q '^| ppm | r0=1x alpha=0.667 | — | 1 |$' "$d/report.md"

# Nothing usable at all: exit status 2.
mkdir "$tmp/empty"
printf 'scene,method,config,log\nbox,ppm,x,nothere.csv\n' > "$tmp/empty/runs.csv"
"$tmp/report" "$tmp/empty" > /dev/null 2> "$tmp/err2"
status=$?
check "exit status 2 when no run is usable" test "$status" -eq 2
check "no run reported" grep -q 'nothere.csv' "$tmp/err2"

# Default targets: three, between the median first and final RMSE.
"$tmp/report" "$d" > /dev/null 2>&1
check "default targets give three columns" \
    sh -c 'grep -A2 "^### Time to reach" "$1" | grep -q "^| method | config | RMSE [^|]* | RMSE [^|]* | RMSE [^|]* |$"' \
    sh "$d/report.md"

echo "$passed passed, $failed failed"
test "$failed" -eq 0
