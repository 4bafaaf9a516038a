#!/bin/sh
# bench/studio.sh - the first picture a newcomer sees (make bench-studio): the
# README's first command, `appm render scenes/stanford-bunny.obj --time 10`,
# in the studio (the default) and under the white environment of earlier
# versions (--stand-in white).
#   form   the mean luminance of the central tenth of the image against its
#          four corner tenths (bench/studio.c), at 512 x 512 after 10 s
#   noise  RMSE and sqrt(relmse) against a path-traced reference (STUDIO_REF
#          passes of pt, default 4000, at 256 x 256) after STUDIO_SECONDS
#          (default 10) of appm and of pt at 256 x 256
#   grain  what a viewer of the README's picture sees: each pixel's luminance
#          as an 8-bit sRGB code, RMS against a path-traced reference
#          (STUDIO_REF512 passes of pt, default 2000, at 512 x 512) over the
#          middle 60 % of the image in each direction, and the share of those
#          pixels more than 4 codes off (bench/studio.c), for the README's
#          command itself and for pt in the same time
# for each seed of STUDIO_SEEDS (default 1 2 3); medians.
# Results: bench/out/studio/studio.md (or STUDIO_OUT).
set -u
APPM=${APPM:-./appm}
CC=${CC:-cc}
secs=${STUDIO_SECONDS:-10}
seeds=${STUDIO_SEEDS:-"1 2 3"}
refp=${STUDIO_REF:-4000}
ref512=${STUDIO_REF512:-2000}
out=${STUDIO_OUT:-bench/out/studio}
bunny=scenes/stanford-bunny.obj
mkdir -p "$out"
[ -x "$APPM" ] || { echo "bench: build ./appm first (make)"; exit 1; }
$CC -std=c99 -O2 bench/studio.c appm.c -o "$out/studio" -lm -pthread || exit 1
median() { sort -g | awk '{a[NR] = $1} END {print a[int((NR + 1) / 2)]}'; }
field() { tr ' ' '\n' | sed -n "s/^$1=//p"; }
if [ ! -f "$out/ref.pfm" ]; then
    echo "studio: reference, $refp passes of pt at 256x256"
    "$APPM" render "$bunny" --size 256x256 --method pt --seed 99 --passes "$refp" -q -o "$out/ref.pfm" >/dev/null || exit 1
fi
if [ ! -f "$out/ref512-$ref512.pfm" ]; then
    echo "studio: reference, $ref512 passes of pt at 512x512"
    "$APPM" render "$bunny" --method pt --seed 98 --passes "$ref512" -q -o "$out/ref512-$ref512.pfm" >/dev/null || exit 1
fi
echo "kind,seed,diff,rmse,relerr" >"$out/results.csv"
echo "method,seed,codes,over4" >"$out/grain.csv"
for seed in $seeds; do
    for kind in studio white; do
        "$APPM" render "$bunny" --time "$secs" --seed "$seed" --stand-in "$kind" -q -o "$out/$kind-$seed.pfm" >/dev/null
        diff=$("$out/studio" "$out/$kind-$seed.pfm" | field diff)
        rmse="" rel=""
        if [ "$kind" = studio ]; then
            for m in appm pt; do
                "$APPM" render "$bunny" --size 256x256 --time "$secs" --seed "$seed" --method "$m" -q \
                    -o "$out/noise-$m-$seed.pfm" >/dev/null
                c=$("$APPM" compare "$out/noise-$m-$seed.pfm" "$out/ref.pfm")
                echo "studio,$seed,,$(echo "$c" | field rmse),$(echo "$c" | field relmse)" |
                    sed "s/^studio/noise-$m/" >>"$out/results.csv"
            done
            "$APPM" render "$bunny" --time "$secs" --seed "$seed" --method pt -q -o "$out/grain-pt-$seed.pfm" >/dev/null
            for m in appm pt; do
                img="$out/grain-pt-$seed.pfm"
                [ "$m" = appm ] && img="$out/studio-$seed.pfm"
                g=$("$out/studio" "$img" "$out/ref512-$ref512.pfm")
                echo "$m,$seed,$(echo "$g" | field codes),$(echo "$g" | field over4)" >>"$out/grain.csv"
            done
        fi
        echo "$kind,$seed,$diff,$rmse,$rel" >>"$out/results.csv"
        echo "studio: $kind seed $seed: centre/corner difference $diff"
    done
done
{
    echo "| | centre vs corners (luminance) | RMSE at ${secs} s, 256x256 | sqrt(relmse) |"
    echo "|---|---|---|---|"
    for kind in studio white; do
        d=$(awk -F, -v k="$kind" '$1 == k {print $3}' "$out/results.csv" | median)
        echo "| $kind, 512x512, appm, ${secs} s | $d | | |"
    done
    for m in appm pt; do
        r=$(awk -F, -v k="noise-$m" '$1 == k {print $4}' "$out/results.csv" | median)
        e=$(awk -F, -v k="noise-$m" '$1 == k {print sqrt($5)}' "$out/results.csv" | median)
        echo "| studio, $m | | $r | $e |"
    done
    echo
    echo "| grain, 512x512, ${secs} s | 8-bit codes RMS (middle 60 %) | pixels more than 4 codes off |"
    echo "|---|---|---|"
    for m in appm pt; do
        c=$(awk -F, -v k="$m" '$1 == k {print $3}' "$out/grain.csv" | median)
        o=$(awk -F, -v k="$m" '$1 == k {print $4}' "$out/grain.csv" | median)
        echo "| $m$( [ "$m" = appm ] && echo ", the README's command") | $c | $o |"
    done
} >"$out/studio.md"
cat "$out/studio.md"
