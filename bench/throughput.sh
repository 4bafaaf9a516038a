#!/bin/sh
# bench/throughput.sh OUTDIR - speed of the parts of a pass, thread scaling and
# memory, on CornellBox-Sphere at 512x512 (262144 photon paths a pass).
# Medians of 3 runs of 6 passes each; writes OUTDIR/throughput.md.
set -u
out=${1:-bench/out/full}
APPM=${APPM:-./appm}
CC=${CC:-cc}
scene=scenes/cornell-sphere.scene
mkdir -p "$out"
kv() { printf '%s\n' "$1" | tr ' ' '\n' | sed -n "s/^$2=//p"; }
median3() { printf '%s\n%s\n%s\n' "$1" "$2" "$3" | sort -g | sed -n 2p; }

# measure METHOD THREADS -> prints "photon_paths_per_s eye_paths_per_s share_eye share_photon share_grid share_gather seconds_per_pass"
measure() {
    line=$($APPM render $scene --method "$1" --threads "$2" --passes 6 --size 512x512 -q -o "$out/tp.pfm" | tail -n 1)
    awk -v p="$(kv "$line" photons)" -v s="$(kv "$line" seconds)" -v e="$(kv "$line" eye_s)" \
        -v ph="$(kv "$line" photon_s)" -v g="$(kv "$line" grid_s)" -v ga="$(kv "$line" gather_s)" \
        -v n="$(kv "$line" passes)" 'BEGIN {
            printf "%.0f %.0f %.3f %.3f %.3f %.3f %.4f\n", p / ph, 512 * 512 * n / e, e / s, ph / s, g / s, ga / s, s / n }'
}

row() { # METHOD THREADS: median over 3 runs of each column
    a=$(measure "$1" "$2"); b=$(measure "$1" "$2"); c=$(measure "$1" "$2")
    i=1
    res=""
    while [ $i -le 7 ]; do
        x=$(median3 "$(echo "$a" | cut -d' ' -f$i)" "$(echo "$b" | cut -d' ' -f$i)" "$(echo "$c" | cut -d' ' -f$i)")
        res="$res $x"
        i=$((i + 1))
    done
    echo "$res"
}

{
    echo "## Throughput (CornellBox-Sphere, 512x512, 262144 photon paths per pass)"
    echo
    cat "$out/meta.txt" 2>/dev/null | sed 's/^/    /'
    echo
    echo "| method | threads | photon paths/s | eye paths/s | eye | photons | grid | gather | s/pass |"
    echo "|---|---|---|---|---|---|---|---|---|"
} > "$out/throughput.md"
for m in ppm appm; do
    for t in 1 2; do
        set -- $(row $m $t)
        echo "| $m | $t | $1 | $2 | $(awk -v x="$3" 'BEGIN{printf "%.0f%%", 100*x}') | $(awk -v x="$4" 'BEGIN{printf "%.0f%%", 100*x}') | $(awk -v x="$5" 'BEGIN{printf "%.0f%%", 100*x}') | $(awk -v x="$6" 'BEGIN{printf "%.0f%%", 100*x}') | $7 |" >> "$out/throughput.md"
        eval "spp_${m}_$t=$7"
    done
done
{
    echo
    echo "Speed-up 1 -> 2 threads (seconds per pass): ppm $(awk -v a="$spp_ppm_1" -v b="$spp_ppm_2" 'BEGIN{printf "%.2fx", a/b}'), appm $(awk -v a="$spp_appm_1" -v b="$spp_appm_2" 'BEGIN{printf "%.2fx", a/b}')."
} >> "$out/throughput.md"

# memory: the renderer's peak with a nearly empty photon store gives the bytes
# per pixel; the growth with the default store, per stored photon, the rest
l1=$($APPM render $scene --method appm --threads 1 --passes 2 --size 512x512 --photons 1 -q -o "$out/tp.pfm" | tail -n 1)
l2=$($APPM render $scene --method appm --threads 1 --passes 2 --size 512x512 -q -o "$out/tp.pfm" | tail -n 1)
awk -v a="$(kv "$l1" peak_bytes)" -v b="$(kv "$l2" peak_bytes)" -v n="$(kv "$l2" photons_stored)" 'BEGIN {
    printf "\nMemory (appm, 512x512): %.1f bytes per pixel; %.1f bytes per stored photon (%d stored in the last pass; store, sort scratch and grid table included).\n", a / (512 * 512), (b - a) / n, n }' >> "$out/throughput.md"

if [ -f bench/bvh.sh ]; then
    echo >> "$out/throughput.md"
    sh bench/bvh.sh "$out" > /dev/null && cat "$out/bvh.md" >> "$out/throughput.md"
fi
rm -f "$out/tp.pfm"
cat "$out/throughput.md"
