#!/bin/sh
# bench/sampler_report.sh DIR - the tables of bench/sampler.sh (markdown on
# stdout) from DIR/results.csv and DIR/regions.csv: medians over the seeds.
set -u
dir=$1
cat "$dir/meta.txt" | sed 's/^/    /'
echo
awk -F, '
function med(s,   n, a, i, j, t) {
    n = split(s, a, " ")
    for (i = 1; i <= n; ++i) for (j = i + 1; j <= n; ++j) if (a[j] + 0 < a[i] + 0) { t = a[i]; a[i] = a[j]; a[j] = t }
    if (n == 0) return ""
    return n % 2 ? a[(n + 1) / 2] : (a[n / 2] + a[n / 2 + 1]) / 2
}
function add(k, v) { val[k] = (k in val) ? val[k] " " v : v }
function m(sc, smp, mode, f) { return med(val[sc SUBSEP smp SUBSEP mode SUBSEP f]) }
NR > 1 {
    if (!($1 in seen)) { seen[$1] = 1; order[++ns] = $1 }
    k = $1 SUBSEP $2 SUBSEP $3
    add(k SUBSEP "passes", $5); add(k SUBSEP "spp", $6 / $5); add(k SUBSEP "rmse", $7)
    add(k SUBSEP "rel", sqrt($8)); add(k SUBSEP "est", $9)
}
END {
    print "**Equal time** (median RMSE over the seeds; ratio < 1: qmc better):"
    print ""
    print "| scene | random | qmc | qmc / random | passes random / qmc | qmc, 1 chain | 4 chains / 1 chain |"
    print "|---|---|---|---|---|---|---|"
    for (i = 1; i <= ns; ++i) {
        s = order[i]; r = m(s, "random", "time", "rmse"); q = m(s, "qmc", "time", "rmse"); o = m(s, "qmc-1chain", "time", "rmse")
        printf "| %s | %.5f | %.5f | **%.3f** | %d / %d | %.5f | %.3f |\n", s, r, q, (r > 0 ? q / r : 0),
            m(s, "random", "time", "passes"), m(s, "qmc", "time", "passes"), o, (o > 0 ? q / o : 0)
    }
    print ""
    print "**Equal passes** (RMSE, and seconds per pass: the cost of the sampler):"
    print ""
    print "| scene | random | qmc | qmc / random | ms/pass random | ms/pass qmc | cost qmc / random |"
    print "|---|---|---|---|---|---|---|"
    for (i = 1; i <= ns; ++i) {
        s = order[i]; r = m(s, "random", "passes", "rmse"); q = m(s, "qmc", "passes", "rmse")
        a = m(s, "random", "passes", "spp"); b = m(s, "qmc", "passes", "spp")
        printf "| %s | %.5f | %.5f | %.3f | %.2f | %.2f | %.3f |\n", s, r, q, (r > 0 ? q / r : 0), 1000 * a, 1000 * b, (a > 0 ? b / a : 0)
    }
    print ""
    print "**Error estimate at equal passes**: est_relerr against the true relative error sqrt(relmse)"
    print "(ratio est / true; 1 is honest). random: spread of the passes; qmc: spread between the 4"
    print "chains; qmc with 1 chain: spread of the (correlated) passes."
    print ""
    print "| scene | random true | est / true | qmc true | est / true | 1 chain true | est / true |"
    print "|---|---|---|---|---|---|---|"
    for (i = 1; i <= ns; ++i) {
        s = order[i]; line = "| " s
        split("random qmc qmc-1chain", smps, " ")
        for (k = 1; k <= 3; ++k) {
            t = m(s, smps[k], "passes", "rel"); e = m(s, smps[k], "passes", "est")
            line = line sprintf(" | %.4f | %.2f", t, (t > 0 ? e / t : 0))
        }
        print line " |"
    }
}' "$dir/results.csv"
if [ -f "$dir/regions.csv" ]; then
    echo
    echo "**caustic-glass, equal time, per region** (RMSE, median over the seeds; no reference noise"
    echo "subtracted):"
    echo
    awk -F, '
    function med(s,   n, a, i, j, t) {
        n = split(s, a, " ")
        for (i = 1; i <= n; ++i) for (j = i + 1; j <= n; ++j) if (a[j] + 0 < a[i] + 0) { t = a[i]; a[i] = a[j]; a[j] = t }
        return n % 2 ? a[(n + 1) / 2] : (a[n / 2] + a[n / 2 + 1]) / 2
    }
    {
        for (f = 3; f <= NF; ++f) {
            if ($f == "") continue
            split($f, kv, "=")
            if (!(kv[1] in seen)) { seen[kv[1]] = 1; order[++nr] = kv[1] }
            k = $1 SUBSEP kv[1]
            v[k] = (k in v) ? v[k] " " kv[2] : kv[2]
        }
    }
    END {
        print "| region | random | qmc | qmc / random | qmc, 1 chain |"
        print "|---|---|---|---|---|"
        for (i = 1; i <= nr; ++i) {
            g = order[i]; r = med(v["random" SUBSEP g]); q = med(v["qmc" SUBSEP g]); o = med(v["qmc-1chain" SUBSEP g])
            printf "| %s | %.5f | %.5f | **%.3f** | %.5f |\n", g, r, q, (r > 0 ? q / r : 0), o
        }
    }' "$dir/regions.csv"
fi
