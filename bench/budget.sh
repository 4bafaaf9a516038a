#!/bin/sh
# bench/budget.sh - what a photon budget per pass could buy: appm at k = 1/4, 1/2, 1, 2, 4
# photon paths a pixel a pass (bench/budget.c), one thread, two renders side by side, on the
# scenes with a reference in bench/ref (64x64; caustic-glass 56x80; built by bench/errbar.sh).
# For each scene and seed: the error at 128 passes against k = 1's (equal passes: how much of
# the error the photons decide), and at equal time (1/4, 1/2 and all of k = 1's seconds, read
# off each curve, log-log between its points) against k = 1's; medians over seeds and budgets.
#   BUDGET_SEEDS (default "1 2"), BUDGET_OUT (default bench/out/budget)
set -u
seeds=${BUDGET_SEEDS:-"1 2"}
out=${BUDGET_OUT:-bench/out/budget}
mkdir -p "$out"
${CC:-cc} -std=c99 -O2 bench/budget.c appm.c -o "$out/budget" -lm -pthread || exit 1
# scene reference mask passes-at-k=1
list="cornell-sphere cornell-sphere-64e 1 256
cornell-original cornell-original-64e 1 256
caustic-glass caustic-glass-56x80e 1 256
water-caustic water-caustic-64e 10 128
bunny bunny-64e 1 256
cornell-empty-white cornell-empty-white-64e 1 256
teapot teapot-64e 1 256"
echo "$list" | while read -r sc ref mask n; do
    [ -f "bench/ref/$ref.pfm" ] || { echo "budget: bench/ref/$ref.pfm missing (sh bench/errbar.sh builds it)" >&2; exit 1; }
    for s in $seeds; do
        for k in 0.25 0.5 1 2 4; do
            # as many passes as k = 1 makes in about the same time, and twice that
            p=$(awk -v n="$n" -v k="$k" 'BEGIN { print int(k > 1 ? 2 * n / k : (k < 1 ? 2 * n : n)) }')
            echo "$out/budget scenes/$sc.scene bench/ref/$ref.pfm $k $mask $s $p > $out/$sc-k$k-s$s.txt"
        done
    done
done | xargs -P 2 -I{} sh -c '{}' || exit 1
python3 - "$out" <<'PY'
import glob, math, collections, sys, statistics
d = collections.defaultdict(dict)
for f in glob.glob(sys.argv[1] + '/*-k*-s*.txt'):
    b = f.split('/')[-1][:-4]; sc, rest = b.rsplit('-k', 1); k, s = rest.split('-s')
    d[sc][(float(k), int(s))] = [tuple(map(float, l.split())) for l in open(f) if l.strip()]
def at(pts, T):
    for a, b in zip(pts, pts[1:]):
        if a[1] <= T <= b[1]:
            t = (math.log(T) - math.log(a[1])) / (math.log(b[1]) - math.log(a[1]))
            return math.exp(math.log(a[2]) + t * (math.log(b[2]) - math.log(a[2])))
    return float('nan')
ks = [0.25, 0.5, 1, 2, 4]
print('| scene | ms a pass at k = 1/4 .. 4 | equal passes (128): k = 1/4, 1/2, 2, 4 | equal time: k = 1/4, 1/2, 2, 4 |')
print('|---|---|---|---|')
for sc in sorted(d):
    seeds = sorted({s for (_, s) in d[sc]})
    eqp, eqt = [], []
    for k in ks:
        if k == 1: continue
        v, w = [], []
        for s in seeds:
            e = {int(p[0]): p[2] for p in d[sc][(k, s)]}; e1 = {int(p[0]): p[2] for p in d[sc][(1, s)]}
            if 128 in e and 128 in e1: v.append(e[128] / e1[128])
            T1 = d[sc][(1, s)][-1][1]
            for fr in (0.25, 0.5, 1.0):
                w.append(at(d[sc][(k, s)], T1 * fr) / at(d[sc][(1, s)], T1 * fr))
        w = [x for x in w if x == x]  # nan: a curve that ends before the budget
        eqp.append(statistics.median(v) if v else float('nan'))
        eqt.append(statistics.median(w) if w else float('nan'))
    ms = [1000 * statistics.median(d[sc][(k, s)][-1][1] / d[sc][(k, s)][-1][0] for s in seeds) for k in ks]
    f = lambda x: '%.3f' % x if x == x else '-'
    print('| %s | %s | %s | %s |' % (sc, ' / '.join('%.1f' % m for m in ms), ' / '.join(f(x) for x in eqp),
                                     ' / '.join(f(x) for x in eqt)))
PY
