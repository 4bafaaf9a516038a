#!/bin/sh
# bench/teach.sh [SECONDS] - the pictures of the README's teaching section:
# CornellBox-Sphere at 256x256, each for the same wall time, with ppm at a
# quarter of the automatic radius (noisy), at four times it (blurred), and appm
# (adaptive), plus appm's radius, noise and Laplacian maps, and appm on
# CornellBox-Glossy.  Writes docs/img/.
set -u
secs=${1:-20}
APPM=${APPM:-./appm}
out=docs/img
scene=scenes/cornell-sphere.scene
mkdir -p "$out"
kv() { printf '%s\n' "$1" | tr ' ' '\n' | sed -n "s/^$2=//p"; }
r0=$(kv "$($APPM render $scene --size 256x256 --passes 1 --method ppm -q -o "$out/probe.pfm")" radius)
rm -f "$out/probe.pfm"
small=$(awk -v r="$r0" 'BEGIN { printf "%.6g", r / 4 }')
large=$(awk -v r="$r0" 'BEGIN { printf "%.6g", r * 4 }')
echo "automatic radius $r0; ppm with $small and $large; $secs s each"
$APPM render $scene --size 256x256 --time "$secs" --method ppm --radius "$small" -q -o "$out/ppm-small.png"
$APPM render $scene --size 256x256 --time "$secs" --method ppm --radius "$large" -q -o "$out/ppm-large.png"
$APPM render $scene --size 256x256 --time "$secs" --method appm -q -o "$out/appm.png" --aux "$out/appm"
# the glossy box (glossy sphere and floor, section 6.1 of appm.c), three times as long
$APPM render scenes/cornell-glossy.scene --size 256x256 --time "$((secs * 3))" --method appm -q -o "$out/cornell-glossy.png"
rm -f "$out"/appm-*.pfm
ls -l "$out"
