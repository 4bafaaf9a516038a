#!/bin/sh
# shellcheck disable=SC2016 # the awk programs in single quotes are not for the shell
# tests/cli.sh - the command line contract (docs/scene-format.md section 3):
# help and version, info, render to every format, exit codes and messages for
# bad options and bad files, compare, --log, --aux, failed writes, EXR and PNG
# read by their reference tools, lights from the command line, the embed
# example, checkpoint and resume, and SIGINT.
#
#   sh tests/cli.sh ./appm build/embed        (from the repository root)
#
# Prints one line per failed check and "N passed, N failed" as its last line;
# exits non-zero if any check failed.  Scratch files go to tests/out/cli/.
# POSIX sh only: no arrays, no [[ ]], no local.

if [ $# -lt 1 ]; then
    echo "usage: sh tests/cli.sh APPM [EMBED]" >&2
    exit 2
fi
if [ ! -f scenes/cornell-original.scene ]; then
    echo "tests/cli.sh: run it from the repository root" >&2
    exit 2
fi

# absolute paths, since some checks run in another folder
abspath() { (cd "$(dirname "$1")" && printf '%s/%s\n' "$(pwd)" "$(basename "$1")"); }
APPM=$(abspath "$1")
EMBED=
[ $# -ge 2 ] && EMBED=$(abspath "$2")
ROOT=$(pwd)
T=tests/out/cli
rm -rf "$T"
mkdir -p "$T"

npass=0
nfail=0

# check DESCRIPTION COMMAND...: runs the test command, counts the result
check() {
    what=$1
    shift
    if "$@"; then
        npass=$((npass + 1))
    else
        nfail=$((nfail + 1))
        echo "FAIL: $what" >&2
        if [ -s "$T/err" ]; then sed 's/^/    stderr: /' "$T/err" | head -n 5 >&2; fi
    fi
}

# run COMMAND...: runs it with stdout in $T/out, stderr in $T/err, status in $rc
run() {
    "$@" >"$T/out" 2>"$T/err"
    rc=$?
}

last_line() { tail -n 1 "$T/out"; }
# warned PATTERN N: the last run exited 0 with PATTERN on N lines of its stderr
warned() { [ "$rc" -eq 0 ] && [ "$(grep -c "$1" "$T/err")" -eq "$2" ]; }
# silent_ok: the last run exited 0 and wrote nothing to stderr
silent_ok() { [ "$rc" -eq 0 ] && [ ! -s "$T/err" ]; }
# refused_with WORD: the last run exited non-zero with WORD in its stderr
refused_with() { [ "$rc" -ne 0 ] && contains "$T/err" "$1"; }
# nonempty FILE...: every FILE exists and is not empty
nonempty() {
    for f in "$@"; do [ -s "$f" ] || return 1; done
}
# est_below E: the last run's summary line has an est_relerr below E
est_below() {
    v=$(sed -n 's/.*est_relerr=\([0-9.e+-]*\).*/\1/p' "$T/out")
    [ -n "$v" ] && awk -v v="$v" -v e="$1" 'BEGIN { exit !(v < e) }'
}
# lacks FILE WORD: FILE does not hold WORD
lacks() { ! grep -q -- "$2" "$1"; }
# not COMMAND...: COMMAND fails
not() { ! "$@"; }
# contains FILE WORD...: FILE holds every WORD
contains() {
    f=$1
    shift
    for w in "$@"; do grep -q -- "$w" "$f" || return 1; done
}
# pfm_size FILE W H: a PFM header of that size
pfm_size() { head -n 2 "$1" | tr '\n' ' ' | grep -q "^P[Ff] $2 $3 "; }
# absent FILE: no file, no dangling link
absent() { [ ! -e "$1" ] && [ ! -L "$1" ]; }
# summary_ok LINE OUTPUT: the key=value line of a 2-pass render into OUTPUT
summary_ok() {
    case $1 in "passes=2 photons="*" radius="*" output=$2"*) return 0 ;; esac
    return 1
}
# the first n bytes of a file, as printable characters
magic() { dd if="$1" bs=1 count="$2" 2>/dev/null | od -An -c | tr -d ' \n'; }

SCENE=scenes/cornell-original.scene
# small ARGS...: a quick render (32x32, 2 passes, quiet) through run
small() { run "$APPM" render "$@" --size 32x32 --passes 2 -q; }

# ---- help, version, no arguments ----------------------------------------------

run "$APPM" --help
check "appm --help exits 0" [ "$rc" -eq 0 ]
check "appm --help shows usage and the commands" contains "$T/out" usage render compare info

run "$APPM" render --help
check "appm render --help exits 0" [ "$rc" -eq 0 ]
check "appm render --help lists the options" contains "$T/out" --method --passes --output --photons

run "$APPM" --version
check "appm --version exits 0" [ "$rc" -eq 0 ]
check "appm --version prints a version number" grep -Eq '^appm [0-9]+\.[0-9]+\.[0-9]+' "$T/out"

run "$APPM"
check "appm without arguments exits 1" [ "$rc" -eq 1 ]
check "appm without arguments explains on stderr" [ -s "$T/err" ]

# ---- info ---------------------------------------------------------------------
# The triangle count must be that of the meshes: every OBJ face of k corners
# is fanned into k - 2 triangles (degenerate ones dropped and reported).

for scene in scenes/*.scene; do
    run "$APPM" info "$scene"
    check "info $scene exits 0" [ "$rc" -eq 0 ]
    expect=0
    # shellcheck disable=SC2013 # mesh names here hold no blanks
    for mesh in $(awk '$1 == "mesh" { print $2 }' "$scene"); do
        n=$(awk '$1 == "f" { t += NF - 3 } END { print t + 0 }' "scenes/$mesh")
        expect=$((expect + n))
    done
    got=$(awk '$1 == "triangles" { n = $2; d = $3; sub(/^\(/, "", d); print n + d }' "$T/out")
    check "info $scene: $got triangles (with dropped ones), the OBJ has $expect" [ "$got" = "$expect" ]
done
# Shadow rays (docs/algorithm.md 5.11): the teapot's spot gets a ray of its own and its sky the
# other; the Cornell box's two light triangles share one ray, picked by power; the studio's sky two.
run "$APPM" info scenes/teapot.scene
check "info: the teapot's shadow rays" contains "$T/out" \
    'shadow rays 2 a shading point: one to each of 1 point or spot light, one to the other light'
run "$APPM" info scenes/cornell-original.scene
check "info: the Cornell box's shadow ray" contains "$T/out" \
    'shadow rays 1 a shading point: one to a light picked by power among 2 lights'
check "info: the photon budget's three counts" contains "$T/out" 'with 262144, 524288 or 1048576 photon paths per pass'
check "info: the renderer's memory before any pass" lacks "$T/out" 'renderer 0.0 MiB'
run "$APPM" info scenes/stanford-bunny.obj
check "info: the studio's sky takes four shadow rays (docs/algorithm.md 5.10)" contains "$T/out" \
    'shadow rays 4 a shading point: four to the light'

# ---- render: every method to every format -------------------------------------

for method in appm appm-paper ppm sppm pt; do
    for ext in png ppm pfm; do
        out=$T/r-$method.$ext
        small "$SCENE" --method "$method" -o "$out"
        check "render --method $method -o .$ext exits 0" [ "$rc" -eq 0 ]
        check "render --method $method wrote $out" [ -s "$out" ]
        line=$(last_line)
        check "render --method $method: summary '$line'" summary_ok "$line" "$out"
        case $ext in # the signature: \211 P N G, P6 (binary PPM), PF (colour PFM)
        png) want='211PNG' nbytes=4 ;;
        ppm) want='P6' nbytes=2 ;;
        pfm) want='PF' nbytes=2 ;;
        esac
        got=$(magic "$out" "$nbytes")
        check "render --method $method: $out starts with $want (got $got)" [ "$got" = "$want" ]
    done
done

# the default output is SCENENAME.png in the current folder
mkdir -p "$T/cwd"
(cd "$T/cwd" && "$APPM" render "$ROOT/$SCENE" --size 32x32 --passes 2 -q >out 2>err)
rc=$?
check "render without -o exits 0" [ "$rc" -eq 0 ]
check "render without -o writes cornell-original.png in the current folder" [ -s "$T/cwd/cornell-original.png" ]
check "render without -o names it in the summary" grep -q 'output=cornell-original.png' "$T/cwd/out"

# the sampler: qmc by default, named in the summary; random is another image
small "$SCENE" -o "$T/s-qmc.pfm"
check "render: the summary names the default sampler qmc" grep -q ' sampler=qmc' "$T/out"
small "$SCENE" --sampler random -o "$T/s-random.pfm"
check "render --sampler random exits 0" [ "$rc" -eq 0 ]
check "render --sampler random: the summary says sampler=random" grep -q ' sampler=random' "$T/out"
differ() { ! cmp -s "$1" "$2"; }
check "render --sampler random renders another image than qmc" differ "$T/s-qmc.pfm" "$T/s-random.pfm"
small "$SCENE" --sampler qmc -o "$T/s-qmc2.pfm"
check "render --sampler qmc is the default" cmp -s "$T/s-qmc.pfm" "$T/s-qmc2.pfm"

# ---- bad options: exit 1 and a message ------------------------------------------

for opts in "--alpha 0" "--alpha 1.5" "--photons 0" "--size 0x0" "--size 10" "--method foo" \
    "--passes" "--no-such-option" "--threads 0" "--radius -1" "--passes 0" "--seed x" "--sampler sobol"; do
    # shellcheck disable=SC2086 # the options are meant to split
    run "$APPM" render "$SCENE" --size 8x8 -q -o "$T/never.png" $opts
    check "render $opts exits 1 (got $rc)" [ "$rc" -eq 1 ]
    check "render $opts explains on stderr" grep -q '^appm: ' "$T/err"
done
check "no image from the refused renders" [ ! -e "$T/never.png" ]

# ---- bad files: exit 2, the file (and the line) in the message ---------------------

small "$T/no-such.scene" -o "$T/never.png"
check "a missing scene exits 2 (got $rc)" [ "$rc" -eq 2 ]
check "a missing scene is named: appm: $T/no-such.scene" grep -q "^appm: $T/no-such.scene" "$T/err"

printf '# a scene with a typo on line 3\nmesh ../../../scenes/CornellBox-Original.obj\ncamara eye 0 1 4 target 0 1 0\n' \
    >"$T/bad.scene"
small "$T/bad.scene" -o "$T/never.png"
check "a malformed scene exits 2 (got $rc)" [ "$rc" -eq 2 ]
check "a malformed scene is reported as appm: FILE:3: ..." grep -q "^appm: $T/bad.scene:3: " "$T/err"
run "$APPM" info "$T/bad.scene"
check "info of a malformed scene exits 2 (got $rc)" [ "$rc" -eq 2 ]
check "info of a malformed scene reports FILE:3:" grep -q "$T/bad.scene:3: " "$T/err"

# ---- compare ------------------------------------------------------------------
# Two hand-made 2x1 PFMs.  A (little-endian, scale -1): pixels (1,1,1) and
# (0.5,0.5,0.5); B (big-endian, scale 1): (1,1,1) and (1,1,1).  Per channel the
# errors are 0,0,0,-0.5,-0.5,-0.5, so
#   rmse   = sqrt(3 * 0.25 / 6)              = 0.353553
#   relmse = 3 * 0.25 / (1 + 0.01) / 6       = 0.123762   (B is the reference)
#   mae    = 1.5 / 6                         = 0.25
#   mean_a = 4.5 / 6 = 0.75,  mean_b = 1
# IEEE 754: 1.0 = 3f800000, 0.5 = 3f000000 (bytes as printf %b octal escapes).
one_le='\0000\0000\0200\0077'
half_le='\0000\0000\0000\0077'
one_be='\0077\0200\0000\0000'
printf 'PF\n2 1\n-1.0\n%b' "$one_le$one_le$one_le$half_le$half_le$half_le" >"$T/a.pfm"
printf 'PF\n2 1\n1.0\n%b' "$one_be$one_be$one_be$one_be$one_be$one_be" >"$T/b.pfm"
printf 'PF\n1 1\n-1.0\n%b' "$one_le$one_le$one_le" >"$T/c.pfm"

line_re='^rmse=[^ ]* relmse=[^ ]* mae=[^ ]* mean_a=[^ ]* mean_b=[^ ]*$'
run "$APPM" compare "$T/a.pfm" "$T/b.pfm"
check "compare a b exits 0" [ "$rc" -eq 0 ]
check "compare prints exactly one line" [ "$(wc -l <"$T/out")" -eq 1 ]
check "compare line: $(cat "$T/out")" grep -q "$line_re" "$T/out"
# value KEY: the number after KEY= on the compare line
value() { tr ' ' '\n' <"$T/out" | sed -n "s/^$1=//p"; }
near() { awk -v a="$1" -v b="$2" 'BEGIN { d = a - b; if (d < 0) d = -d; exit !(d <= 1e-5) }'; }
check "compare a b: rmse $(value rmse) = 0.353553" near "$(value rmse)" 0.353553
check "compare a b: relmse $(value relmse) = 0.123762" near "$(value relmse)" 0.123762
check "compare a b: mae $(value mae) = 0.25" near "$(value mae)" 0.25
check "compare a b: mean_a $(value mean_a) = 0.75" near "$(value mean_a)" 0.75
check "compare a b: mean_b $(value mean_b) = 1" near "$(value mean_b)" 1

# NaN (7fc00000) and +inf (7f800000) pixels: a 3x2 image whose pixel (1,0)
# has a NaN and (2,1) an inf (rows stored bottom to top: the file's first row
# is y = 1).  compare must say how many and where the first is, and exit 2.
nan_le='\0000\0000\0300\0177'
inf_le='\0000\0000\0200\0177'
printf 'PF\n3 2\n-1.0\n%b' "$one_le$one_le$one_le$one_le$one_le$one_le$one_le$one_le$inf_le" >"$T/nan.pfm"
printf '%b' "$one_le$one_le$one_le$one_le$nan_le$one_le$one_le$one_le$one_le" >>"$T/nan.pfm"
printf 'PF\n3 2\n-1.0\n%b' "$one_le$one_le$one_le$one_le$one_le$one_le$one_le$one_le$one_le" >"$T/ones.pfm"
printf '%b' "$one_le$one_le$one_le$one_le$one_le$one_le$one_le$one_le$one_le" >>"$T/ones.pfm"
run "$APPM" compare "$T/nan.pfm" "$T/ones.pfm"
check "compare with NaN/inf exits 2 (got $rc)" [ "$rc" -eq 2 ]
check "compare with NaN/inf: no rmse line" [ ! -s "$T/out" ]
check "compare with NaN/inf: 2 pixels, the first at x=1 y=0" grep -q 'nan.pfm: 2 pixels hold NaN or infinite values; the first is x=1 y=0' "$T/err"
run "$APPM" compare "$T/ones.pfm" "$T/nan.pfm"
check "compare with NaN/inf in the reference exits 2 (got $rc)" [ "$rc" -eq 2 ]

run "$APPM" compare "$T/a.pfm" "$T/a.pfm"
check "compare a a exits 0" [ "$rc" -eq 0 ]
check "compare a a: rmse=0 relmse=0 mae=0" grep -q '^rmse=0 relmse=0 mae=0 ' "$T/out"

run "$APPM" compare "$T/a.pfm" "$T/c.pfm"
check "compare of different sizes exits 2 (got $rc)" [ "$rc" -eq 2 ]
check "compare of different sizes explains" grep -q '^appm: ' "$T/err"
run "$APPM" compare "$T/a.pfm" "$T/no-such.pfm"
check "compare with a missing file exits 2 (got $rc)" [ "$rc" -eq 2 ]
check "compare with a missing file names it" grep -q "no-such.pfm" "$T/err"

# two renders of the same scene with different seeds differ; the same seed
# gives the same image
small "$SCENE" --seed 1 -o "$T/s1.pfm"
small "$SCENE" --seed 2 -o "$T/s2.pfm"
small "$SCENE" --seed 1 --threads 1 -o "$T/s1b.pfm"
run "$APPM" compare "$T/s1.pfm" "$T/s2.pfm"
check "compare of seeds 1 and 2 exits 0" [ "$rc" -eq 0 ]
check "seeds 1 and 2 differ: rmse $(value rmse) > 0" awk -v x="$(value rmse)" 'BEGIN { exit !(x > 0) }'
check "compare of renders: means agree within 10% ($(value mean_a), $(value mean_b))" \
    awk -v a="$(value mean_a)" -v b="$(value mean_b)" 'BEGIN { exit !(a > 0.9 * b && a < 1.1 * b) }'
check "seed 1 on 1 thread and on all threads: the same file" cmp -s "$T/s1.pfm" "$T/s1b.pfm"
# the whole 64-bit range of seeds, and no more
small "$SCENE" --seed 18446744073709551615 -o "$T/smax.pfm"
check "--seed 2^64 - 1 is a seed" [ "$rc" -eq 0 ]
small "$SCENE" --seed 18446744073709551616 -o "$T/sover.pfm"
check "--seed 2^64 is refused" refused_with "from 0 to 18446744073709551615"

# ---- --log and --reference ---------------------------------------------------------

run "$APPM" render "$SCENE" --size 32x32 --passes 3 -q -o "$T/log.pfm" --log "$T/log.csv"
check "render --log exits 0" [ "$rc" -eq 0 ]
check "log header starts pass,seconds,photons,rmse,relmse" grep -q '^pass,seconds,photons,rmse,relmse' "$T/log.csv"
check "log has one row per pass" [ "$(wc -l <"$T/log.csv")" -eq 4 ]
check "log rows are passes 1, 2, 3 with photon counts, error columns empty" \
    awk -F, 'NR > 1 { if ($1 != NR - 1 || $2 !~ /^[0-9.]+$/ || $3 !~ /^[0-9]+$/ || $4 != "" || $5 != "") bad = 1 }
             END { exit bad + 0 }' "$T/log.csv"

run "$APPM" render "$SCENE" --size 32x32 --passes 3 -q -o "$T/log2.pfm" --log "$T/log2.csv" --reference "$T/s1.pfm"
check "render --log --reference exits 0" [ "$rc" -eq 0 ]
check "log with reference has one row per pass" [ "$(wc -l <"$T/log2.csv")" -eq 4 ]
check "log with reference fills rmse and relmse (positive numbers)" \
    awk -F, 'NR > 1 { if (!($4 + 0 > 0) || !($5 + 0 > 0) || $4 !~ /^[0-9.e+-]+$/) bad = 1 } END { exit bad + 0 }' "$T/log2.csv"
run "$APPM" render "$SCENE" --size 16x16 --passes 1 -q -o "$T/never.png" --reference "$T/s1.pfm"
check "a reference of another size exits 2 (got $rc)" [ "$rc" -eq 2 ]

# ---- --aux ------------------------------------------------------------------------

small "$SCENE" --method appm -o "$T/aux.png" --aux "$T/aux"
check "render --aux exits 0" [ "$rc" -eq 0 ]
for map in radius variance laplacian; do
    check "--aux wrote $T/aux-$map.pfm" [ -s "$T/aux-$map.pfm" ]
    if [ -s "$T/aux-$map.pfm" ]; then
        check "$T/aux-$map.pfm is a 32x32 PFM" pfm_size "$T/aux-$map.pfm" 32 32
    fi
done

# ---- failed writes: a message, a non-zero status, nothing left behind ---------------

small "$SCENE" -o "$T/no-such-folder/x.png"
check "writing into a missing folder fails (got $rc)" [ "$rc" -ne 0 ]
check "writing into a missing folder explains" grep -q 'x.png' "$T/err"
check "writing into a missing folder prints no summary" [ ! -s "$T/out" ]

# The writer writes NAME.tmp and renames it.  With NAME.tmp a link to /dev/full
# every write fails with "no space left": the disk-full case.
if [ -c /dev/full ]; then
    ln -s /dev/full "$T/full.png.tmp"
    small "$SCENE" -o "$T/full.png"
    check "writing to a full disk fails (got $rc)" [ "$rc" -ne 0 ]
    check "writing to a full disk explains" grep -q 'full.png' "$T/err"
    check "writing to a full disk leaves no file" absent "$T/full.png"
    check "writing to a full disk removes its temporary" absent "$T/full.png.tmp"
    # an output that is a device (here /dev/full itself, through a link with
    # an image name) is written in place: the write fails, the link stays
    ln -s /dev/full "$T/device.pfm"
    small "$SCENE" -o "$T/device.pfm"
    check "writing to /dev/full fails (got $rc)" [ "$rc" -ne 0 ]
    check "writing to /dev/full explains" grep -q 'device.pfm' "$T/err"
    check "writing to /dev/full leaves the device alone" [ -L "$T/device.pfm" ]
    check "writing to /dev/full leaves no temporary" absent "$T/device.pfm.tmp"
fi
# a folder in the way of the final name: the rename fails after a complete write
mkdir -p "$T/taken.pfm"
small "$SCENE" -o "$T/taken.pfm"
check "replacing a folder fails (got $rc)" [ "$rc" -ne 0 ]
check "replacing a folder leaves no temporary" [ ! -e "$T/taken.pfm.tmp" ]

# ---- the embedding example ------------------------------------------------------------

# ---- output formats: the reference tools read what appm writes ------------------------
# pngcheck and the OpenEXR library's own tools (exrheader, and tests/exr/exr_ref.cpp
# built against the library) check the files where they are installed; under CI=true
# (.ci/run installs them) a missing one is a failure, elsewhere a skip with a note.

# need TOOL: 0 if installed; otherwise a failure under CI=true, or a note
need() {
    command -v "$1" >/dev/null 2>&1 && return 0
    if [ "${CI:-}" = true ]; then
        check "$1 is installed (CI=true)" false
    else
        echo "note: $1 is not installed, its checks are skipped" >&2
    fi
    return 1
}

run "$APPM" render "$SCENE" --size 40x24 --passes 2 -q --seed 5 -o "$T/fmt.pfm"
for kind in "float zip" "half zip" "float none" "half none"; do
    set -- $kind
    out=$T/fmt-$1-$2.exr
    run "$APPM" render "$SCENE" --size 40x24 --passes 2 -q --seed 5 --exr "$1" --exr-compression "$2" -o "$out"
    check "render -o .exr --exr $1 --exr-compression $2 exits 0" [ "$rc" -eq 0 ]
    check "$out starts with the OpenEXR magic" [ "$(magic "$out" 4)" = 'v/1001' ]
    if need exrheader; then
        run exrheader "$out"
        check "exrheader reads $out" [ "$rc" -eq 0 ]
        case $2 in zip) c='zip, multi-scanline' ;; *) c='compression (type compression): no' ;; esac
        case $1 in float) p='32-bit floating-point' ;; *) p='16-bit floating-point' ;; esac
        check "exrheader: $out is $1, $2" contains "$T/out" "$c" "$p" '(0 0) - (39 23)'
    fi
done
exr_ref=
if need c++ && need pkg-config && pkg-config --exists OpenEXR 2>/dev/null; then
    # shellcheck disable=SC2046 # pkg-config's flags are word lists
    if c++ -O1 -o "$T/exr_ref" tests/exr/exr_ref.cpp $(pkg-config --cflags --libs OpenEXR) 2>"$T/err"; then
        exr_ref=$T/exr_ref
    else
        check "tests/exr/exr_ref.cpp builds against the OpenEXR library" false
    fi
elif [ "${CI:-}" = true ]; then
    check "the OpenEXR library (libopenexr-dev) is installed (CI=true)" false
fi
if [ -n "$exr_ref" ]; then
    for kind in "float zip" "half zip" "float none" "half none"; do
        set -- $kind
        run "$exr_ref" "$T/fmt-$1-$2.exr" "$T/fmt.pfm" "$1"
        check "the OpenEXR library reads fmt-$1-$2.exr back to the PFM's values: $(cat "$T/out")" [ "$rc" -eq 0 ]
    done
fi
run "$APPM" render "$SCENE" --size 40x24 --passes 2 -q --exr double -o "$T/never.exr"
check "--exr double is a usage error" [ "$rc" -eq 1 ]
run "$APPM" render "$SCENE" --size 40x24 --passes 2 -q --exr-compression rle -o "$T/never.exr"
check "--exr-compression rle is a usage error" [ "$rc" -eq 1 ]
if need pngcheck; then
    run pngcheck "$T/r-appm.png"
    check "pngcheck reads the PNG" [ "$rc" -eq 0 ]
fi

# ---- any OBJ renders: the studio, the white environment, --light, --environment ---------

BUNNY=scenes/stanford-bunny.obj
run "$APPM" render "$BUNNY" --size 32x32 --passes 2 -o "$T/bunny.png"
check "a bare OBJ without light renders (exit $rc)" [ "$rc" -eq 0 ]
check "... with one warning about the studio" [ "$(grep -c 'shown in a studio' "$T/err")" -eq 1 ]
check "... and writes the image" [ -s "$T/bunny.png" ]
run "$APPM" render "$BUNNY" --size 32x32 --passes 2 --stand-in white -o "$T/bunny-w.png"
check "--stand-in white: one warning about the white environment" \
    [ "$(grep -c 'white environment of radiance 1' "$T/err")" -eq 1 ]
run "$APPM" render "$BUNNY" --size 8x8 --passes 1 --stand-in grey -o "$T/never.png"
check "--stand-in grey is a usage error (exit $rc)" [ "$rc" -eq 1 ]
run "$APPM" render "$BUNNY" --size 32x32 --passes 2 -o "$T/bunny-l.pfm" --light point 0 0.3 0.3 0.05 0.05 0.05 \
    --light point 0.2 0.3 0 0.02 0.02 0.02
check "--light point (twice) exits 0" [ "$rc" -eq 0 ]
check "... without the warning" [ ! -s "$T/err" ]
run "$APPM" info "$BUNNY"
check "info of the bare OBJ: one environment" contains "$T/out" '0 area, 0 point, 0 spot, 1 environment'
run "$APPM" render "$BUNNY" --size 32x32 --passes 2 -o "$T/bunny-e.pfm" --environment 0.5 0.4 0.3
check "--environment exits 0, without the warning" silent_ok
run "$APPM" render "$SCENE" --size 32x32 --passes 2 -q -o "$T/cornell-el.pfm" --environment 0.1 0.1 0.1 \
    --light point 0 1.5 0 1 1 1
check "--environment and --light add to a scene that has lights" [ "$rc" -eq 0 ]
for bad in "--light spot 0 0 0 1 1 1" "--light point 0 0 0 1 1" "--light point 0 0 0 1 -1 1" \
    "--environment 1 1" "--environment 1 x 1" "--environment -1 0 0"; do
    # shellcheck disable=SC2086 # the options are word lists on purpose
    run "$APPM" render "$BUNNY" --size 8x8 --passes 1 -q -o "$T/never.png" $bad
    check "'$bad' is a usage error (exit $rc)" [ "$rc" -eq 1 ]
done
check "no image from the refused renders" absent "$T/never.png"

# pt cannot find a point or spot light through glass: it says so, once, and only then,
# and reports no error estimate there (its passes cannot measure light they never find)
run "$APPM" render scenes/caustic-glass.scene --method pt --size 16x20 --passes 3 -o "$T/pt-glass.pfm"
check "pt on a spot light behind glass warns about its caustics (exit $rc)" \
    warned 'pt does not render the light that reaches a surface through a mirror or glass' 1
check "... which it prints" contains "$T/out" passes=3
check "... and its summary has no est_relerr" lacks "$T/out" est_relerr=
run "$APPM" render scenes/caustic-glass.scene --method pt --size 16x20 --until-error 0.1 -o "$T/never.pfm"
check "... so --until-error alone is refused there (exit $rc)" refused_with 'would never stop'
# the same for an area light of 5 x 4 mm under water, which no diffuse bounce meets by chance
run "$APPM" render scenes/water-caustic.scene --method pt --size 8x8 --passes 2 -o "$T/pt-water.pfm"
check "pt under water-caustic's tiny light warns about its caustics (exit $rc)" \
    warned 'pt does not render the light that reaches a surface through a mirror or glass' 1
check "... and its summary has no est_relerr" lacks "$T/out" est_relerr=
run "$APPM" render "$SCENE" --method ppm --size 16x16 --until-error 0.1 -o "$T/never.pfm"
check "--until-error alone is refused for ppm, which keeps no estimate (exit $rc)" refused_with 'ppm keeps no error'
check "... and renders nothing" absent "$T/never.pfm"
run "$APPM" render "$SCENE" --method sppm --size 16x16 --until-error 0.1 --passes 2 -o "$T/sppm-u.pfm"
check "--until-error beside --passes: sppm renders, saying it has no effect (exit $rc)" \
    warned 'until-error has no effect: sppm' 1
run "$APPM" render "$SCENE" --method pt --size 16x16 --until-error 0.5 --time 60 -q -o "$T/pt-u.pfm"
check "pt on a box stops on --until-error, below it (exit $rc)" est_below 0.5
run "$APPM" render scenes/caustic-glass.scene --size 16x20 --passes 1 -o "$T/appm-glass.pfm"
check "... appm does not" warned 'pt does not' 0
run "$APPM" render "$SCENE" --method pt --size 16x16 --passes 1 -o "$T/pt-box.pfm"
check "... nor pt on a box without glass" warned 'pt does not' 0
run "$APPM" render scenes/cornell-sphere.scene --method pt --size 16x16 --passes 1 -o "$T/pt-sphere.pfm"
check "... nor pt on glass under an area light" warned 'pt does not' 0
run "$APPM" render scenes/cornell-sphere.scene --method pt --size 16x16 --passes 1 -o "$T/pt-sphere.pfm" \
    --light point 0 1.5 0 1 1 1
check "... but with a point light added" warned 'pt does not' 1

# ---- --emission ------------------------------------------------------------------
# guided (the default) renders the same bytes as no option, reports its share, writes
# each guided light's density with --aux, and is refused by a light resume; light
# emits from the lights' own distributions, another image once a light is guided.
GLASS=scenes/caustic-glass.scene
run "$APPM" render "$GLASS" --size 56x80 --passes 40 -q -o "$T/glass-d.pfm"
check "no --emission: the summary says guided" contains "$T/out" "emission=guided guided="
run "$APPM" render "$GLASS" --size 56x80 --passes 40 -q --emission light -o "$T/glass-l.pfm"
check "--emission light: the summary says so" contains "$T/out" "emission=light"
check "--emission light: not the default's image" not cmp -s "$T/glass-d.pfm" "$T/glass-l.pfm"
run "$APPM" render "$GLASS" --size 56x80 --passes 40 -q --emission guided --aux "$T/gl" -o "$T/glass-g.pfm" \
    --checkpoint "$T/glass.ckpt"
check "--emission guided exits 0" [ "$rc" -eq 0 ]
check "--emission guided: the default's image, byte for byte" cmp -s "$T/glass-d.pfm" "$T/glass-g.pfm"
check "--emission guided: the summary gives the guided share" contains "$T/out" "emission=guided guided="
check "--emission guided: the spot is guided after 40 passes" lacks "$T/out" "guided=0.000"
check "--emission guided --aux writes light 0's density" nonempty "$T/gl-emission-0.pfm" "$T/gl-emission-0.png"
run "$APPM" render "$GLASS" --size 56x80 --passes 42 -q --emission light --resume "$T/glass.ckpt" -o "$T/never.pfm"
check "a guided checkpoint is refused by --emission light (exit $rc)" refused_with emission
run "$APPM" render "$GLASS" --size 8x8 --passes 1 -q --emission both -o "$T/never.png"
check "--emission both is a usage error" [ "$rc" -eq 1 ]

# ---- the photon budget -------------------------------------------------------------
# without --photons, pass 1 chooses 1, 2 or 4 times width * height photon paths a pass
# and says so; the image is that of the same count given; --photons keeps its count.
run "$APPM" render "$GLASS" --size 56x80 --passes 3 -q -o "$T/budget-a.pfm"
check "no --photons: the summary gives the budget's choice" contains "$T/out" "photons_per_pass=17920 budget=auto budget_rays="
run "$APPM" render "$GLASS" --size 56x80 --passes 3 -q --photons 17920 -o "$T/budget-f.pfm"
check "--photons 17920: the summary says fixed" contains "$T/out" "photons_per_pass=17920 budget=fixed"
check "--photons 17920: the budget's image, byte for byte" cmp -s "$T/budget-a.pfm" "$T/budget-f.pfm"
run "$APPM" render scenes/cornell-original.scene --size 32x32 --passes 2 -q -o "$T/budget-o.pfm"
check "CornellBox-Original keeps width * height photon paths a pass" contains "$T/out" "photons_per_pass=1024 budget=auto"
run "$APPM" render scenes/cornell-original.scene --size 32x32 --passes 2 -q --method pt -o "$T/budget-p.pfm"
check "the path tracer has no photon budget" lacks "$T/out" "budget="

if [ -n "$EMBED" ]; then
    run "$EMBED" "$SCENE" "$T/embed.png"
    check "embed exits 0" [ "$rc" -eq 0 ]
    check "embed wrote a PNG" [ "$(magic "$T/embed.png" 4)" = '211PNG' ]
fi

# ---- a first pass that fails ---------------------------------------------------
# The photon store must grow in the first pass (many photons per path in a
# closed box) beyond what ulimit -v leaves: the render reports it, exits 3 and
# writes no image of zero passes.  APPM_PATTERN (the CLI built with
# -ftrivial-auto-var-init=pattern) makes a read of never-filled stats visible.
for bin in "$APPM" ${APPM_PATTERN:+"$(abspath "$APPM_PATTERN")"}; do
    rm -f "$T/oom.pfm"
    (ulimit -v 100000 2>/dev/null && exec "$bin" render scenes/cornell-empty-white.scene --size 8x8 \
        --photons 1000000 --passes 1 --threads 1 -q -o "$T/oom.pfm") >"$T/out" 2>"$T/err"
    rc=$?
    check "first pass out of memory: exit 3 (got $rc)" [ "$rc" -eq 3 ]
    check "first pass out of memory: the message" grep -q 'pass failed: out of memory' "$T/err"
    check "first pass out of memory: no image" absent "$T/oom.pfm"
done

# ---- checkpoint and resume -------------------------------------------------------
# N passes with --checkpoint, then --resume with --passes 2N: the image is the
# one of 2N passes, byte for byte, for every method and another thread count;
# a checkpoint of other options or another scene, or a damaged one, is refused.

CK="--size 16x12 --photons 2000 --threads 2 -q"
for m in appm appm-paper ppm sppm pt; do
    # shellcheck disable=SC2086 # $CK is a word list
    run "$APPM" render "$SCENE" $CK --method $m --passes 6 -o "$T/ck-whole-$m.pfm"
    # shellcheck disable=SC2086
    run "$APPM" render "$SCENE" $CK --method $m --threads 1 --passes 3 --checkpoint "$T/ck-$m.ckpt" \
        --checkpoint-every 2 -o "$T/ck-part-$m.pfm"
    check "checkpoint $m: exit 0 (got $rc)" [ "$rc" -eq 0 ]
    check "checkpoint $m: written" [ -s "$T/ck-$m.ckpt" ]
    check "checkpoint $m: no temporary left" absent "$T/ck-$m.ckpt.tmp"
    check "checkpoint $m: the summary names it" grep -q " checkpoint=$T/ck-$m.ckpt" "$T/out"
    # shellcheck disable=SC2086
    run "$APPM" render "$SCENE" $CK --method $m --passes 6 --resume "$T/ck-$m.ckpt" -o "$T/ck-res-$m.pfm"
    check "resume $m: exit 0 (got $rc)" [ "$rc" -eq 0 ]
    check "resume $m: the summary says passes=6 resumed=3" contains "$T/out" '^passes=6 ' ' resumed=3'
    check "resume $m: byte-identical to 6 uninterrupted passes" cmp -s "$T/ck-whole-$m.pfm" "$T/ck-res-$m.pfm"
done
# shellcheck disable=SC2086
run "$APPM" render "$SCENE" $CK --passes 2 --resume "$T/ck-appm.ckpt" -o "$T/ck-none.pfm"
check "resume past --passes: no pass, exit 0 (got $rc)" [ "$rc" -eq 0 ]
check "resume past --passes: the checkpoint's image" contains "$T/out" '^passes=3 ' ' resumed=3'
# shellcheck disable=SC2086
run "$APPM" render "$SCENE" $CK --method ppm --passes 6 --resume "$T/ck-appm.ckpt" -o "$T/ck-x.pfm"
check "resume with another method: exit 1 (got $rc)" [ "$rc" -eq 1 ]
check "resume with another method: says so" grep -q 'checkpoint of method appm; this render uses ppm' "$T/err"
# shellcheck disable=SC2086
run "$APPM" render "$SCENE" $CK --seed 3 --passes 6 --resume "$T/ck-appm.ckpt" -o "$T/ck-x.pfm"
check "resume with another seed: exit 1 (got $rc)" [ "$rc" -eq 1 ]
check "resume with another seed: says so" grep -q 'seed is 0 there, 3 in this render' "$T/err"
# shellcheck disable=SC2086
run "$APPM" render scenes/cornell-sphere.scene $CK --passes 6 --resume "$T/ck-appm.ckpt" -o "$T/ck-x.pfm"
check "resume of another scene: exit 1 (got $rc)" [ "$rc" -eq 1 ]
check "resume of another scene: says so" grep -q 'checkpoint of another scene' "$T/err"
head -c 1000 "$T/ck-appm.ckpt" >"$T/ck-short.ckpt"
# shellcheck disable=SC2086
run "$APPM" render "$SCENE" $CK --passes 6 --resume "$T/ck-short.ckpt" -o "$T/ck-x.pfm"
check "resume of a truncated checkpoint: exit 2 (got $rc)" [ "$rc" -eq 2 ]
check "resume of a truncated checkpoint: says so" grep -q 'ck-short.ckpt: truncated checkpoint' "$T/err"
check "a refused resume writes no image" absent "$T/ck-x.pfm"
# shellcheck disable=SC2086
run "$APPM" render "$SCENE" $CK --passes 6 --resume "$T/no-such.ckpt" -o "$T/ck-x.pfm"
check "resume of a missing file: exit 2 (got $rc)" [ "$rc" -eq 2 ]
run "$APPM" render "$SCENE" --checkpoint-every 2 --passes 1 -q -o "$T/ck-x.pfm"
check "--checkpoint-every without --checkpoint: exit 1 (got $rc)" [ "$rc" -eq 1 ]
mkdir -p "$T/ck-taken.ckpt"
# shellcheck disable=SC2086
run "$APPM" render "$SCENE" $CK --passes 2 --checkpoint "$T/ck-taken.ckpt" -o "$T/ck-y.pfm"
check "a checkpoint that cannot be written: exit 3 (got $rc)" [ "$rc" -eq 3 ]
check "a checkpoint that cannot be written: says so" grep -q 'cannot write the checkpoint' "$T/err"
check "a checkpoint that cannot be written: the image is still written" [ -s "$T/ck-y.pfm" ]

# ---- SIGINT: stop after the pass in flight, write, report ----------------------------

"$APPM" render "$SCENE" --size 64x64 --time 30 -q -o "$T/int.pfm" --checkpoint "$T/int.ckpt" >"$T/int.out" 2>"$T/int.err" &
pid=$!
sleep 1
kill -INT "$pid" 2>/dev/null
waited=0
while kill -0 "$pid" 2>/dev/null && [ "$waited" -lt 10 ]; do
    sleep 1
    waited=$((waited + 1))
done
if kill -0 "$pid" 2>/dev/null; then
    check "SIGINT ends the render within 10 s" false
    kill -KILL "$pid" 2>/dev/null
fi
wait "$pid"
rc=$?
check "SIGINT: exit status 0 (got $rc)" [ "$rc" -eq 0 ]
check "SIGINT: the summary line" grep -q '^passes=[0-9]* photons=.* output=' "$T/int.out"
check "SIGINT: the image is written" [ -s "$T/int.pfm" ]
check "SIGINT: the checkpoint is written" [ -s "$T/int.ckpt" ]
done_passes=$(sed -n 's/^passes=\([0-9]*\) .*/\1/p' "$T/int.out")
run "$APPM" render "$SCENE" --size 64x64 --passes $((${done_passes:-0} + 1)) -q --resume "$T/int.ckpt" \
    -o "$T/int2.pfm"
check "SIGINT: its checkpoint resumes (exit $rc)" contains "$T/out" "^passes=$((${done_passes:-0} + 1)) " \
    " resumed=${done_passes:-x}"

echo "$npass passed, $nfail failed"
[ "$nfail" -eq 0 ]
