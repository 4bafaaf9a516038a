#!/bin/sh
# bench/sampler_report.sh DIR - the tables of bench/sampler.sh (markdown on
# stdout) from DIR/cost.csv, DIR/results.csv, the per-pass logs it names, and
# DIR/regions.csv: medians over the seeds.  RMSE is against the reference with
# the reference's own noise (ref_mse) subtracted.
set -u
dir=$1
sed 's/^/    /' "$dir/meta.txt"
echo
awk -F, -v W="${SAMPLER_WINDOW:-32}" "$(cat bench/median.awk)"'
function add(k, v) { val[k] = (k in val) ? val[k] " " v : v }
function m(sc, smp, f) { return med(val[sc SUBSEP smp SUBSEP f]) }
function truth(r, n,   x) { x = r * r - n; return x > 0 ? sqrt(x) : 0 }
# the RMSE of run k around pass p: the root mean square over passes p-W+1 .. p
# (one pass'"'"'s RMSE moves by some 10 % from pass to pass, which would decide a
# comparison read at two different passes)
function at_pass(k, p,   i, sum, n, x) {
    if (p < 1) p = 1
    if (p > N[k]) p = N[k]
    sum = n = 0
    for (i = p - W + 1; i <= p; ++i) if (i >= 1) { x = truth(R[k, i], RM[k]); sum += x * x; ++n }
    return sqrt(sum / n)
}
FNR == NR {
    if (FNR > 1) add($1 SUBSEP $2 SUBSEP "cpu", $5 / $4)
    next
}
FNR > 1 {
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
    add(sc SUBSEP smp SUBSEP "rmse", truth(R[k, n], RM[k])); add(sc SUBSEP smp SUBSEP "wrmse", at_pass(k, n))
    add(sc SUBSEP smp SUBSEP "spp", E[k, n] / n)
    add(sc SUBSEP smp SUBSEP "rel", sqrt($6)); add(sc SUBSEP smp SUBSEP "est", $7)
    passes = n
}
END {
    for (i = 1; i <= ns; ++i) {
        sc = order[i]; ns2 = split(seeds[sc], sl, " ")
        a = m(sc, "random", "cpu"); b = m(sc, "qmc", "cpu"); c = a > 0 ? b / a : 1; cr[sc] = c
        for (j = 1; j <= ns2; ++j) {
            q = sc SUBSEP "qmc" SUBSEP sl[j]; r = sc SUBSEP "random" SUBSEP sl[j]
            pq = c > 1 ? int(N[q] / c) : N[q]; pr = c > 1 ? N[r] : int(N[r] * c)
            add(sc SUBSEP "qmc" SUBSEP "trmse", at_pass(q, pq)); add(sc SUBSEP "qmc" SUBSEP "tpass", pq)
            add(sc SUBSEP "random" SUBSEP "trmse", at_pass(r, pr)); add(sc SUBSEP "random" SUBSEP "tpass", pr)
        }
    }
    print "**Cost and equal time.** Processor milliseconds per pass (1 thread, median of the rounds in"
    print "the header), and"
    print "the RMSE at equal processor time: the dearer sampler read at the pass where it has spent what"
    printf "the other spent on all its passes (RMS over the %d passes up to there; medians over the\n", W
    print "seeds; ratio < 1: qmc better):"
    print ""
    print "| scene | ms/pass random | ms/pass qmc | cost qmc / random | passes random / qmc | RMSE random | RMSE qmc | qmc / random |"
    print "|---|---|---|---|---|---|---|---|"
    for (i = 1; i <= ns; ++i) {
        s = order[i]; r = m(s, "random", "trmse"); q = m(s, "qmc", "trmse")
        printf "| %s | %.2f | %.2f | %.3f | %d / %d | %.5f | %.5f | **%.3f** |\n", s, 1000 * m(s, "random", "cpu"),
            1000 * m(s, "qmc", "cpu"), cr[s], m(s, "random", "tpass"), m(s, "qmc", "tpass"), r, q, (r > 0 ? q / r : 0)
    }
    print ""
    printf "**Equal passes**: RMSE after pass %d, and (window) the RMS over passes %d-%d; qmc with 4\n", passes, passes - W + 1, passes
    print "chains (--chains 4) costs the same per pass (medians over the seeds; ratio < 1: qmc better):"
    print ""
    print "| scene | random | qmc | qmc / random | window: random | qmc | qmc / random | qmc, 4 chains | 4 chains / random |"
    print "|---|---|---|---|---|---|---|---|---|"
    for (i = 1; i <= ns; ++i) {
        s = order[i]; r = m(s, "random", "rmse"); q = m(s, "qmc", "rmse")
        wr = m(s, "random", "wrmse"); wq = m(s, "qmc", "wrmse"); o = m(s, "qmc-4chains", "wrmse")
        printf "| %s | %.5f | %.5f | %.3f | %.5f | %.5f | **%.3f** | %.5f | %.3f |\n", s, r, q, (r > 0 ? q / r : 0),
            wr, wq, (wr > 0 ? wq / wr : 0), o, (wr > 0 ? o / wr : 0)
    }
    print ""
    printf "**Error estimate after %d passes**: est_relerr against the true relative error\n", passes
    print "sqrt(relmse) (est / true = 1 is honest). random: the spread of the passes; qmc (one chain):"
    print "the spread of its correlated passes; qmc, 4 chains: the spread between the chains."
    print ""
    print "| scene | random: true | est / true | qmc: true | est / true | 4 chains: true | est / true |"
    print "|---|---|---|---|---|---|---|"
    for (i = 1; i <= ns; ++i) {
        s = order[i]; line = "| " s
        split("random qmc qmc-4chains", smps, " ")
        for (k = 1; k <= 3; ++k) {
            t = m(s, smps[k], "rel"); e = m(s, smps[k], "est")
            line = line sprintf(" | %.4f | %.2f", t, (t > 0 ? e / t : 0))
        }
        print line " |"
    }
}' "$dir/cost.csv" "$dir/results.csv"
if [ -f "$dir/regions.csv" ]; then
    echo
    echo "**caustic-glass per region, equal passes** (RMSE, median over the seeds; the reference's"
    echo "noise not subtracted):"
    echo
    awk -F, "$(cat bench/median.awk)"'
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
        print "| region | random | qmc | qmc / random | qmc, 4 chains |"
        print "|---|---|---|---|---|"
        for (i = 1; i <= nr; ++i) {
            g = order[i]; r = med(v["random" SUBSEP g]); q = med(v["qmc" SUBSEP g]); o = med(v["qmc-4chains" SUBSEP g])
            printf "| %s | %.5f | %.5f | **%.3f** | %.5f |\n", g, r, q, (r > 0 ? q / r : 0), o
        }
    }' "$dir/regions.csv"
fi
