# bench/refs.sh - sourced by bench/bounds.sh, bench/imglap.sh, bench/edgecap.sh,
# bench/eqcurve.sh and bench/lapdiag.sh: the 64x64 references of docs/algorithm.md 4.13 and the
# reference arguments of bench/eqcpu for each scene.  Needs R (the
# reference folder).
#
# The committed sphere box reference; two path-traced halves for
# CornellBox-Original; two ppm halves for caustic-glass and water-caustic (a
# path tracer cannot reach their spot or tiny light through glass or water;
# these lean toward ppm's kernel).  Built once, then reused.
ref() { # name scene method passes extra...
    n=$1 sc=$2 m=$3 p=$4
    shift 4
    for s in a b; do
        seed=1000003; [ $s = b ] && seed=1000004
        [ -f $R/$n-$s.pfm ] || ./appm render scenes/$sc.scene --method $m --size 64x64 --passes $p --threads 2 -q \
            --sampler random --seed $seed "$@" -o $R/$n-$s.pfm > /dev/null || exit 1
    done
}
refs() {
    ref cornell-original-64 cornell-original pt 4096
    ref caustic-glass-64 caustic-glass ppm 3000 --photons 16384
    ref water-caustic-64 water-caustic ppm 600 --photons 16384
}
# refs_pt SCENE...: for the scenes refs() leaves out, the two path-traced halves of 4096 passes
# that bench/ref/SCENE-64.cmd records; a light reached only through glass or water would need
# ppm halves instead, as for the two above
refs_pt() {
    for sc; do
        case $sc in
        cornell-sphere | cornell-original | caustic-glass | water-*) ;;
        *) ref $sc-64 $sc pt 4096 ;;
        esac
    done
}
# bench/eqcpu's REF_A REF_B MASK REF_MSE for a scene; the mask leaves out the
# pixels whose reference luminance is at least 1 (10 for water-caustic): the
# light seen directly
args() {
    case $1 in
    cornell-sphere) echo "$R/cornell-sphere-64.pfm $R/cornell-sphere-64.pfm 1.0 $(sed 's/ref_mse=//' $R/cornell-sphere-64.mse)" ;;
    water-caustic) echo "$R/$1-64-a.pfm $R/$1-64-b.pfm 10.0 0" ;;
    *) echo "$R/$1-64-a.pfm $R/$1-64-b.pfm 1.0 0" ;;
    esac
}
