#!/bin/sh
# bench/eqcurve.sh - appm (and variants of it) against ppm at its defaults, at
# equal processor time over a range of budgets, from one error curve per run.
#
# Equal-time comparisons at one budget are noisy on this kind of machine, and
# with the low-discrepancy sampler the error of a pass count is not a smooth
# function of it: between seeds and runs, appm / ppm on the sphere box ran from
# 0.82 to 1.22 at 3 CPU-seconds (docs/experiments.md).  So each run renders
# a fixed number of passes and prints its error and processor time every K
# passes (bench/eqcpu with EQCPU_CURVE=K); the runs of a seed are interleaved.
# For each seed, each budget t of EQC_BUDGETS (processor seconds, 2 threads)
# reads every method's error at time t off its curve (linear between the
# points) and the ratio to ppm's; printed are the median over budgets and
# seeds, and the same at equal passes.  The processor time is the run's own:
# a load that changes during a run still shows; the pass costs are printed
# so that they can be checked against an instruction count.
#
#   EQC_SCENES   scenes (default: cornell-sphere, cornell-original, caustic-glass and
#                water-caustic, and water-caustic against the reference made with the kernel
#                cut, water-cutref); any other scene of scenes/ is compared with its path-traced
#                pair, the one bench/ref/SCENE-64.cmd records (built once, 20 s each; the
#                all-scenes row of docs/experiments.md ran the other eight)
#   EQC_SEEDS    seeds (default 1 2 3)
#   EQC_BUDGETS  budgets in CPU-seconds (default 1.5 2 2.5 3)
#   EQC_VARIANTS "name:MACRO=VALUE,MACRO=VALUE name2:..." appm built with
#                those #defines of appm.c changed (beside appm as it is)
#   EQC_OUT      folder (default bench/out/eqcurve)
#   EQC_COST=instr  also compare at an equal instruction count, which no load
#                changes: each build's instructions per pass on each scene are
#                counted once (valgrind's callgrind, passes 32 to 96, some
#                minutes), and the budgets are ppm's passes 0.5 - 1 x the
#                scene's count; the images are those of the curves (equal
#                passes are deterministic); then the same read off each curve's power-law
#                fit, and each variant against appm at equal instructions, paired by seed
#   EQC_GRID=1   with EQC_COST=instr: also ppm's 15-point grid (r0 in {1/4, 1/2, 1, 2, 4} x
#                the automatic radius, alpha in {0.5, 2/3, 0.8}) on every scene and seed,
#                each point at equal processor time against ppm's default (run before and
#                after the grid, its cost per pass their mean), read off the fits; the best
#                point (lowest median) against appm at equal instructions, paired.  The
#                default point itself comes out within a few percent of 1: that is the
#                noise of this comparison (some 10 minutes for the five scenes, 3 seeds)
# References (64x64, built once by bench/refs.sh, then reused): the committed sphere box
# reference; two path-traced halves of 4096 passes for every other scene a path tracer can
# reach; two ppm halves for caustic-glass and water-caustic (16384 photons x 3000 and x 600
# passes, at 256x256 reduced to 64x64 since 2026-12-07; a path tracer cannot reach their spot
# or tiny light through glass or water; these lean toward ppm's kernel, 4x less than at
# 64x64), and for water-cutref water-caustic's halves rendered again by the build of commit
# 547f20b with APPM__CUT 2 (ppm with the kernel cut).  The masked RMSE leaves out the pixels
# whose reference luminance is at least 1 (10 for water-caustic): the light seen directly.
set -u
CC=${CC:-cc}
seeds=${EQC_SEEDS:-"1 2 3"}
budgets=${EQC_BUDGETS:-"1.5 2 2.5 3"}
scenes=${EQC_SCENES:-"cornell-sphere cornell-original caustic-glass water-caustic water-cutref"}
variants=${EQC_VARIANTS:-}
out=${EQC_OUT:-bench/out/eqcurve}
mkdir -p "$out"
[ -x ./appm ] || { echo "bench: build ./appm first (make)"; exit 1; }
R=bench/ref
APPM=./appm threads=2 REF_HALVES=1 # the commands bench/ref/SCENE-64.cmd records
. bench/refs.sh
for sc in $scenes; do
    case $sc in
    cornell-sphere) ;; # committed, with its .mse
    caustic-glass | water-caustic)
        p=3000; [ $sc = water-caustic ] && p=600
        # at 4x the size, reduced (bench/refmix.c): at 1x ppm's own kernel blurs the caustic and
        # darkens the corners, and pulls every method's ratio towards 1 (docs/testing.md)
        reference $sc-64 scenes/$sc.scene 64x64 $p ppm " --sampler random --photons 16384" 4 ;;
    water-cutref) # water-caustic's pair again, by a build that gives ppm the kernel cut
        APPM=$out/appm-cut
        set -- water-caustic-64-cut scenes/water-caustic.scene 64x64 600 ppm " --sampler random --photons 16384"
        # the library no longer cuts ppm's kernel: the build is that of commit 547f20b, whose
        # APPM__CUT 2 gave every photon method the cut (docs/experiments.md)
        ref_cached "$@" || { mkdir -p "$out/cut" && for f in appm.c appm.h main.c; do
                git show 547f20b:$f > "$out/cut/$f" || exit 1; done &&
            sed -i 's/^#define APPM__CUT [0-9]*/#define APPM__CUT 2/' "$out/cut/appm.c" &&
            grep -q '^#define APPM__CUT 2' "$out/cut/appm.c" &&
            $CC -std=c99 -O2 "$out/cut/appm.c" "$out/cut/main.c" -o "$APPM" -lm -pthread; } ||
            { echo "bench: the build of 547f20b with APPM__CUT 2 failed"; exit 1; }
        reference "$@"
        APPM=./appm ;;
    *) reference $sc-64 scenes/$sc.scene 64x64 4096 pt " --sampler random" ;;
    esac
done
$CC -std=c99 -O2 -I. bench/eqcpu.c appm.c -o "$out/eqcpu-appm" -lm -pthread || exit 1
names="appm"
for v in $variants; do
    n=${v%%:*} defs=${v#*:}
    cp appm.c "$out/appm-$n.c"
    for d in $(echo "$defs" | tr ',' ' '); do
        m=${d%%=*} val=${d#*=}
        sed "s/^#define $m [^ ]*/#define $m $val/" "$out/appm-$n.c" > "$out/t.c" && mv "$out/t.c" "$out/appm-$n.c"
        grep -q "^#define $m $val" "$out/appm-$n.c" || { echo "bench: $m not found"; exit 1; }
    done
    $CC -std=c99 -O2 -I. bench/eqcpu.c "$out/appm-$n.c" -o "$out/eqcpu-$n" -lm -pthread || exit 1
    names="$names $n"
done
passes() { # enough passes for every method to pass the largest budget on a loaded machine
    case $1 in
    cornell-sphere) echo 700 ;; cornell-original) echo 800 ;; caustic-glass) echo 800 ;; water-*) echo 260 ;;
    *) echo 600 ;;
    esac
}
# water-cutref: water-caustic against the reference pair made with the kernel cut
scene() { case $1 in water-cutref) echo water-caustic ;; *) echo $1 ;; esac; }
# bench/eqcpu's REF_A REF_B MASK REF_MSE for a scene
refargs() {
    case $1 in
    cornell-sphere) echo "$R/cornell-sphere-64.pfm $R/cornell-sphere-64.pfm 1.0 $(sed 's/ref_mse=//' \
        $R/cornell-sphere-64.mse)" ;;
    water-caustic) echo "$R/water-caustic-64-a.pfm $R/water-caustic-64-b.pfm 10.0 0" ;;
    water-cutref) echo "$R/water-caustic-64-cut-a.pfm $R/water-caustic-64-cut-b.pfm 10.0 0" ;;
    *) echo "$R/$1-64-a.pfm $R/$1-64-b.pfm 1.0 0" ;;
    esac
}
for s in $seeds; do
    for sc in $scenes; do
        n=$(passes $sc)
        EQCPU_CURVE=10 "$out/eqcpu-appm" scenes/$(scene $sc).scene ppm $s -$n 0 0 $(refargs $sc) > "$out/$sc-ppm-s$s.txt" ||
            exit 1
        for v in $names; do
            EQCPU_CURVE=10 "$out/eqcpu-$v" scenes/$(scene $sc).scene appm $s -$n 0 0 $(refargs $sc) > "$out/$sc-$v-s$s.txt" ||
                exit 1
        done
        echo "$sc seed=$s: $(for m in ppm $names; do tail -1 "$out/$sc-$m-s$s.txt" |
            sed "s/^passes=\([^ ]*\) cpu=\([^ ]*\).*/$m \1 passes \2 s;/"; done)"
    done
done
# instructions per pass of build $1 (method $2) on scene $3: (I(96 passes) - I(32)) / 64
instr() {
    f=$out/instr-$1-$2-$(scene $3).txt
    [ -s "$f" ] && [ "$f" -nt "$out/eqcpu-$1" ] && { cat "$f"; return; }
    for p in 32 96; do
        valgrind --tool=callgrind --callgrind-out-file=/dev/null "$out/eqcpu-$1" scenes/$(scene $3).scene $2 1 -$p 0 0 \
            $(refargs $3) 2>&1 | sed -n 's/.*refs: *//p' | tr -d ,
    done | awk '{ i[NR] = $1 } END { printf "%.0f", (i[2] - i[1]) / 64 }' | tee "$f"
}
# err_at FILE KEY VALUE: the masked RMSE where column KEY (passes or cpu) reaches VALUE, linear
# between the curve's points; empty beyond its end
err_at() {
    sed -n 's/^curve passes=\([^ ]*\) cpu=\([^ ]*\) rmse=[^ ]* rmse_masked=\([^ ]*\)$/\1 \2 \3/p' "$1" |
        awk -v key="$2" -v t="$3" '{ x = key == "cpu" ? $2 : $1
            if (x >= t) { if (NR == 1 || x == px) print $3; else print pe + ($3 - pe) * (t - px) / (x - px); done = 1; exit }
            px = x; pe = $3 }'
}
# fit_at FILE FROM P: the masked RMSE at P passes from a power law e = A n^b fitted (least squares in
# log e, log n) to the curve's points from FROM passes on; smooths the pass-to-pass swings of the
# low-discrepancy sampler, which an interpolated point keeps
fit_at() {
    sed -n 's/^curve passes=\([^ ]*\) cpu=[^ ]* rmse=[^ ]* rmse_masked=\([^ ]*\)$/\1 \2/p' "$1" |
        awk -v lo="$2" -v p="$3" '$1 >= lo && $2 > 0 { x = log($1); y = log($2); n++; sx += x; sy += y; sxx += x * x; sxy += x * y }
            END { if (n < 2) exit; b = (n * sxy - sx * sy) / (n * sxx - sx * sx); a = (sy - b * sx) / n; print exp(a + b * log(p)) }'
}
# pair_fit A B SA SB N FROM: for k = 4 .. 8, the fitted error of curve A at N k / 8 x SA passes over
# that of curve B at N k / 8 x SB (SA, SB: awk expressions), one ratio a line
pair_fit() {
    for k in 4 5 6 7 8; do
        qa=$(awk "BEGIN { print $5 * $k / 8 * ($3) }") qb=$(awk "BEGIN { print $5 * $k / 8 * ($4) }")
        a=$(fit_at "$1" $6 $qa) b=$(fit_at "$2" $6 $qb)
        [ -n "$a" ] && [ -n "$b" ] && awk "BEGIN { print $a / $b }"
    done
}
median() { sort -n | awk '{ a[NR] = $1 } END { if (NR) printf "%.3f (%d: %.3f - %.3f)", NR % 2 ? a[(NR + 1) / 2] : (a[NR / 2] + a[NR / 2 + 1]) / 2, NR, a[1], a[NR] }'; }
echo "masked RMSE ratio to ppm at its defaults: median over budgets and seeds (count: range)"
for sc in $scenes; do
    n=$(passes $sc)
    for v in $names; do
        et=$(for s in $seeds; do for t in $budgets; do
            a=$(err_at "$out/$sc-$v-s$s.txt" cpu $t) b=$(err_at "$out/$sc-ppm-s$s.txt" cpu $t)
            [ -n "$a" ] && [ -n "$b" ] && awk "BEGIN { print $a / $b }"; done; done | median)
        ep=$(for s in $seeds; do for p in $(awk "BEGIN { for (k = 4; k <= 8; ++k) print int($n * k / 80) * 10 }"); do
            a=$(err_at "$out/$sc-$v-s$s.txt" passes $p) b=$(err_at "$out/$sc-ppm-s$s.txt" passes $p)
            [ -n "$a" ] && [ -n "$b" ] && awk "BEGIN { print $a / $b }"; done; done | median)
        cost=$(for s in $seeds; do
            a=$(tail -1 "$out/$sc-$v-s$s.txt" | sed 's/.* cpu=\([^ ]*\).*/\1/') b=$(tail -1 "$out/$sc-ppm-s$s.txt" | sed 's/.* cpu=\([^ ]*\).*/\1/')
            awk "BEGIN { print $a / $b }"; done | median)
        echo "$sc $v: equal time $et; equal passes (0.5 - 1 x $n) $ep; CPU per pass / ppm's $cost"
    done
done
[ "${EQC_COST:-}" = instr ] || exit 0
echo "masked RMSE ratio to ppm at its defaults at equal instructions: median over budgets and seeds"
for sc in $scenes; do
    n=$(passes $sc)
    cp=$(instr appm ppm $sc)
    for v in $names; do
        ca=$(instr $v appm $sc)
        ei=$(for s in $seeds; do for k in 4 5 6 7 8; do
            p=$(awk "BEGIN { print $n * $k / 8 }") q=$(awk "BEGIN { print $n * $k / 8 * $cp / $ca }")
            a=$(err_at "$out/$sc-$v-s$s.txt" passes $q) b=$(err_at "$out/$sc-ppm-s$s.txt" passes $p)
            [ -n "$a" ] && [ -n "$b" ] && awk "BEGIN { print $a / $b }"; done; done | median)
        echo "$sc $v: equal instructions $ei; instructions per pass $ca, ppm's $cp ($(awk "BEGIN { printf \"%.3f\", $ca / $cp }")x)"
    done
done
echo "the same from each curve's power-law fit (passes n/4 to n), and each variant against appm, paired"
for sc in $scenes; do
    n=$(passes $sc)
    cp=$(instr appm ppm $sc) c0=$(instr appm appm $sc)
    for v in $names; do
        ca=$(instr $v appm $sc)
        ef=$(for s in $seeds; do
            pair_fit "$out/$sc-$v-s$s.txt" "$out/$sc-ppm-s$s.txt" "$cp / $ca" 1 $n $((n / 4)); done | median)
        ev=
        [ $v = appm ] || ev="; against appm $(for s in $seeds; do
            pair_fit "$out/$sc-$v-s$s.txt" "$out/$sc-appm-s$s.txt" "$c0 / $ca" 1 $n $((n / 4)); done | median)"
        echo "$sc $v: fitted, equal instructions $ef$ev"
    done
done
[ "${EQC_GRID:-0}" = 1 ] || exit 0
cost() { tail -1 "$1" | sed 's/^passes=\([^ ]*\) cpu=\([^ ]*\).*/\2 \1/' | awk '{ print $1 / $2 }'; }
defcost() { awk "BEGIN { print ($(cost "$out/$1-gdef1-s$2.txt") + $(cost "$out/$1-gdef2-s$2.txt")) / 2 }"; }
grid="0.25:0.5 0.25:0.6666667 0.25:0.8 0.5:0.5 0.5:0.6666667 0.5:0.8 1:0.5 1:0.6666667 1:0.8 2:0.5 2:0.6666667 2:0.8 4:0.5 4:0.6666667 4:0.8"
echo "ppm's grid at equal processor time against its default (fitted), and appm against the grid's best point"
for sc in $scenes; do
    n=$(passes $sc)
    lo=$((n / 4))
    ra=$(./appm render scenes/$(scene $sc).scene --method ppm --size 64x64 --passes 1 --threads 1 -q --seed 1 \
        -o "$out/r.pfm" | sed 's/.* radius=\([^ ]*\).*/\1/')
    for s in $seeds; do
        EQCPU_CURVE=10 "$out/eqcpu-appm" scenes/$(scene $sc).scene ppm $s -$n 0 0 $(refargs $sc) > "$out/$sc-gdef1-s$s.txt" || exit 1
        for g in $grid; do
            r0=$(awk "BEGIN { print $ra * ${g%%:*} }")
            EQCPU_CURVE=10 "$out/eqcpu-appm" scenes/$(scene $sc).scene ppm $s -$n $r0 ${g#*:} $(refargs $sc) \
                > "$out/$sc-g$g-s$s.txt" || exit 1
        done
        EQCPU_CURVE=10 "$out/eqcpu-appm" scenes/$(scene $sc).scene ppm $s -$n 0 0 $(refargs $sc) > "$out/$sc-gdef2-s$s.txt" || exit 1
    done
    best= bm=
    for g in $grid; do
        m=$(for s in $seeds; do
            pair_fit "$out/$sc-g$g-s$s.txt" "$out/$sc-gdef1-s$s.txt" "$(defcost $sc $s) / $(cost "$out/$sc-g$g-s$s.txt")" 1 \
                $n $lo; done | median)
        echo "$sc ppm r0=${g%%:*}x alpha=${g#*:}: $m"
        v=${m%% *}
        if [ -z "$bm" ] || awk "BEGIN { exit !($v < $bm) }"; then best=$g bm=$v; fi
    done
    cp=$(instr appm ppm $sc) ca=$(instr appm appm $sc)
    ab=$(for s in $seeds; do
        pair_fit "$out/$sc-appm-s$s.txt" "$out/$sc-g$best-s$s.txt" "$cp / $ca" \
            "$(defcost $sc $s) / $(cost "$out/$sc-g$best-s$s.txt")" $n $lo; done | median)
    echo "$sc: best grid point r0=${best%%:*}x alpha=${best#*:} ($bm of the default); appm against it $ab"
done
