#!/bin/sh
# bench/errbar_every.sh - the error bar at every pass (called by bench/errbar.sh, or alone on
# its output): `--until-error` and `--time` stop at any pass, not only at 16, 64 and 256.
#
#   sh bench/errbar_every.sh [OUT]      (OUT: bench/errbar.sh's folder, default bench/out/errbar)
#
# For each scene and method of OUT/results.csv, the logs of its seeds (the new build's) give
# est / true at every pass from 16 on, true = sqrt(relmse - ref_relmse) as in errbar.sh; per
# pass the median over the seeds.  Prints a markdown table: the lowest and the highest of those
# medians with their passes, and the passes where the median leaves 0.7-1.3 (how many, first
# and last).
set -u
out=${1:-bench/out/errbar}
echo "| scene | method | lowest (pass) | highest (pass) | passes outside 0.7-1.3 |"
echo "|---|---|---|---|---|"
awk -F, 'NR > 1 && $3 == "new" && !seen[$1 SUBSEP $2]++ { print $1, $2, $8 }' "$out/results.csv" |
    while read -r name method rr; do
        for log in "$out"/log-"$name"-"$method"-*-new.csv; do
            [ -f "$log" ] || continue
            awk -F, -v rr="$rr" 'NR > 1 && $1 >= 16 && $6 != "" {
                t = $5 - rr; t = t > 0 ? sqrt(t) : 1e-30; print $1, $6 / t }' "$log"
        done | awk -v s="$name" -v m="$method" "$(cat bench/median.awk)"'
            { v[$1] = ($1 in v) ? v[$1] " " $2 : $2; if ($1 > last) last = $1 }
            END {
                lo = 1e30; hi = -1; n = 0; first = 0; end = 0
                for (p = 16; p <= last; ++p) {
                    if (!(p in v)) continue
                    e = med(v[p])
                    if (e < lo) { lo = e; plo = p }
                    if (e > hi) { hi = e; phi = p }
                    if (e < 0.7 || e > 1.3) { n++; if (!first) first = p; end = p }
                }
                if (hi < 0) { printf "| %s | %s | none | none | - |\n", s, m; exit }
                printf "| %s | %s | %.2f (%d) | %.2f (%d) | %s |\n", s, m, lo, plo, hi, phi,
                    n ? sprintf("%d, %d to %d", n, first, end) : "0"
            }'
    done
