# bench/refs.sh - the references, built in one place: sourced by bench/run.sh, bench/sampler.sh
# and bench/eqcurve.sh, which set APPM (the command line tool) and threads (its --threads).
#
# reference NAME SCENE SIZE PASSES [METHOD [EXTRA [K]]]: bench/ref/NAME.pfm, the mean of two
# independent renders (seeds 1000003 and 1000004) of PASSES passes each with METHOD (default pt)
# and the options EXTRA (one string that starts with a space, e.g. " --sampler random"), each
# rendered at K times SIZE and reduced to it by refmix (default 1; bench/refmix.c says why), cached
# with the commands that made it in bench/ref/NAME.cmd: it is rendered again only when they
# change.  refmix also measures the reference's own noise, ref_mse = E[(A - B)^2] / 4, in
# bench/ref/NAME.mse, which is subtracted from every measured MSE: a method's error and the
# reference's are independent, so they add.  The two halves, bench/ref/NAME-a.pfm and -b.pfm,
# are removed, or kept with REF_HALVES=1 (bench/eqcpu takes them and subtracts the noise
# itself).
#
# A scene whose light a path tracer cannot reach (a spot light seen through glass, a tiny light
# under water) gets ppm halves instead, which lean toward ppm's kernel: at K times the size its
# kernel is K times narrower.

# ref_size SIZE K: SIZE (WxH) times K
ref_size() {
    echo "$1" | awk -F x -v k="$2" '{ print $1 * k "x" $2 * k }'
}

# ref_cached NAME SCENE SIZE PASSES [METHOD [EXTRA [K]]]: whether bench/ref/NAME is there, made by
# these commands (sets ref, cmd and want for reference)
ref_cached() {
    ref=bench/ref/$1.pfm
    k=${7:-1}
    cmd="$APPM render $2 --method ${5:-pt} --size $(ref_size "$3" "$k") --passes $4 --threads $threads -q${6:-}"
    kx=; [ "$k" = 1 ] || kx=" $k"
    want="$cmd --seed 1000003 -o bench/ref/$1-a.pfm; $cmd --seed 1000004 -o bench/ref/$1-b.pfm; bench/refmix bench/ref/$1-a.pfm bench/ref/$1-b.pfm $ref$kx"
    [ -f "$ref" ] && [ -f "bench/ref/$1.mse" ] && [ -f "bench/ref/$1.cmd" ] &&
        [ "$(cat "bench/ref/$1.cmd")" = "$want" ] &&
        { [ "${REF_HALVES:-0}" != 1 ] || { [ -f "bench/ref/$1-a.pfm" ] && [ -f "bench/ref/$1-b.pfm" ]; }; }
}

reference() {
    if ref_cached "$@"; then
        echo "reference $ref (cached, $(cat "bench/ref/$1.mse"))"
        return 0
    fi
    echo "reference $ref: $want"
    mkdir -p bench/ref
    [ -x bench/refmix ] || ${CC:-cc} -std=c99 -O2 bench/refmix.c appm.c -o bench/refmix -lm -pthread || exit 1
    $cmd --seed 1000003 -o "bench/ref/$1-a.pfm" > /dev/null &&
        $cmd --seed 1000004 -o "bench/ref/$1-b.pfm" > /dev/null &&
        bench/refmix "bench/ref/$1-a.pfm" "bench/ref/$1-b.pfm" "$ref" $kx > "bench/ref/$1.mse" ||
        { echo "bench: reference failed"; exit 1; }
    if [ "${REF_HALVES:-0}" = 1 ]; then # kept at SIZE, as their users read them beside the renders
        for h in a b; do
            [ "$k" = 1 ] || bench/refmix "bench/ref/$1-$h.pfm" "bench/ref/$1-$h.pfm" "bench/ref/$1-$h.pfm" "$k" \
                > /dev/null || { echo "bench: reference failed"; exit 1; }
        done
    else
        rm -f "bench/ref/$1-a.pfm" "bench/ref/$1-b.pfm"
    fi
    printf '%s\n' "$want" > "bench/ref/$1.cmd"
}
