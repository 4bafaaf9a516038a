#!/bin/sh
# bench/sampler_report.sh DIR - the tables of bench/sampler.sh (markdown on
# stdout) from DIR/results.csv, the per-pass logs it names, and
# DIR/regions.csv: medians over the seeds.  RMSE is against the reference with
# the reference's own noise (ref_mse) subtracted.
set -u
dir=$1
sed 's/^/    /' "$dir/meta.txt"
echo
awk -F, '
function med(s,   n, a, i, j, t) {
    n = split(s, a, " ")
    for (i = 1; i <= n; ++i) for (j = i + 1; j <= n; ++j) if (a[j] + 0 < a[i] + 0) { t = a[i]; a[i] = a[j]; a[j] = t }
    if (n == 0) return 0
    return n % 2 ? a[(n + 1) / 2] : (a[n / 2] + a[n / 2 + 1]) / 2
}
function add(k, v) { val[k] = (k in val) ? val[k] " " v : v }
function m(sc, smp, f) { return med(val[sc SUBSEP smp SUBSEP f]) }
function truth(r, n,   x) { x = r * r - n; return x > 0 ? sqrt(x) : 0 }
# the RMSE of run k after the last pass that ended by time t (and that pass)
function at_time(k, t,   i, best) {
    best = 1
    for (i = 1; i <= N[k]; ++i) if (E[k, i] <= t) best = i
    atpass = best
    return truth(R[k, best], RM[k])
}
NR > 1 {
    sc = $1; smp = $2; seed = $3; k = sc SUBSEP smp SUBSEP seed
    if (!(sc in seen)) { seen[sc] = 1; order[++ns] = sc }
    if (!((sc SUBSEP seed) in sd)) { sd[sc SUBSEP seed] = 1; seeds[sc] = seeds[sc] " " seed }
    RM[k] = $8; n = 0
    while ((getline line < $9) > 0) {
        split(line, f, ",")
        if (f[1] == "pass") continue
        ++n; E[k, n] = f[2]; R[k, n] = f[4]
    }
    close($9); N[k] = n
    add(sc SUBSEP smp SUBSEP "rmse", truth(R[k, n], RM[k]))
    add(sc SUBSEP smp SUBSEP "spp", E[k, n] / n)
    add(sc SUBSEP smp SUBSEP "rel", sqrt($6)); add(sc SUBSEP smp SUBSEP "est", $7)
    passes = n
}
END {
    for (i = 1; i <= ns; ++i) {
        sc = order[i]; ns2 = split(seeds[sc], sl, " ")
        for (j = 1; j <= ns2; ++j) {
            q = sc SUBSEP "qmc" SUBSEP sl[j]; r = sc SUBSEP "random" SUBSEP sl[j]; o = sc SUBSEP "qmc-1chain" SUBSEP sl[j]
            t = E[q, N[q]] < E[r, N[r]] ? E[q, N[q]] : E[r, N[r]]
            add(sc SUBSEP "qmc" SUBSEP "trmse", at_time(q, t)); add(sc SUBSEP "qmc" SUBSEP "tpass", atpass)
            add(sc SUBSEP "random" SUBSEP "trmse", at_time(r, t)); add(sc SUBSEP "random" SUBSEP "tpass", atpass)
            add(sc SUBSEP "time", t)
            t = E[q, N[q]] < E[o, N[o]] ? E[q, N[q]] : E[o, N[o]]
            add(sc SUBSEP "qmc" SUBSEP "trmse1", at_time(q, t)); add(sc SUBSEP "qmc-1chain" SUBSEP "trmse1", at_time(o, t))
        }
    }
    print "**Equal time** (per seed, both samplers stopped at the shorter run'"'"'s time; medians over the"
    print "seeds; ratio < 1: qmc better):"
    print ""
    print "| scene | seconds | random | qmc | qmc / random | passes random / qmc |"
    print "|---|---|---|---|---|---|"
    for (i = 1; i <= ns; ++i) {
        s = order[i]; r = m(s, "random", "trmse"); q = m(s, "qmc", "trmse")
        printf "| %s | %.1f | %.5f | %.5f | **%.3f** | %d / %d |\n", s, med(val[s SUBSEP "time"]), r, q,
            (r > 0 ? q / r : 0), m(s, "random", "tpass"), m(s, "qmc", "tpass")
    }
    print ""
    printf "**Equal passes** (%d; RMSE, and wall milliseconds per pass, the cost of the sampler):\n", passes
    print ""
    print "| scene | random | qmc | qmc / random | ms/pass random | ms/pass qmc | cost qmc / random |"
    print "|---|---|---|---|---|---|---|"
    for (i = 1; i <= ns; ++i) {
        s = order[i]; r = m(s, "random", "rmse"); q = m(s, "qmc", "rmse")
        a = m(s, "random", "spp"); b = m(s, "qmc", "spp")
        printf "| %s | %.5f | %.5f | **%.3f** | %.1f | %.1f | %.3f |\n", s, r, q, (r > 0 ? q / r : 0), 1000 * a, 1000 * b, (a > 0 ? b / a : 0)
    }
    print ""
    print "**Four chains against one** (qmc built with -DAPPM__CHAINS=1: one sequence over all passes):"
    print "RMSE at equal passes and at equal time."
    print ""
    print "| scene | 4 chains, passes | 1 chain, passes | 4 / 1 | 4 chains, time | 1 chain, time | 4 / 1 |"
    print "|---|---|---|---|---|---|---|"
    for (i = 1; i <= ns; ++i) {
        s = order[i]; q = m(s, "qmc", "rmse"); o = m(s, "qmc-1chain", "rmse")
        a = m(s, "qmc", "trmse1"); b = m(s, "qmc-1chain", "trmse1")
        printf "| %s | %.5f | %.5f | %.3f | %.5f | %.5f | %.3f |\n", s, q, o, (o > 0 ? q / o : 0), a, b, (b > 0 ? a / b : 0)
    }
    print ""
    printf "**Error estimate after %d passes**: est_relerr against the true relative error\n", passes
    print "sqrt(relmse) (est / true = 1 is honest). random: the spread of the passes; qmc: the spread"
    print "between the 4 chains; qmc with 1 chain: the spread of its correlated passes."
    print ""
    print "| scene | random: true | est / true | qmc: true | est / true | 1 chain: true | est / true |"
    print "|---|---|---|---|---|---|---|"
    for (i = 1; i <= ns; ++i) {
        s = order[i]; line = "| " s
        split("random qmc qmc-1chain", smps, " ")
        for (k = 1; k <= 3; ++k) {
            t = m(s, smps[k], "rel"); e = m(s, smps[k], "est")
            line = line sprintf(" | %.4f | %.2f", t, (t > 0 ? e / t : 0))
        }
        print line " |"
    }
}' "$dir/results.csv"
if [ -f "$dir/regions.csv" ]; then
    echo
    echo "**caustic-glass per region, equal passes** (RMSE, median over the seeds; the reference's"
    echo "noise not subtracted):"
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
