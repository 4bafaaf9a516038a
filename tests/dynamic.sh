#!/bin/sh
# tests/dynamic.sh - dynamic analysis that the ASan+UBSan builds of `make test`
# do not cover.
#
#   1. Valgrind memcheck (uninitialised reads, invalid accesses and leaks in a
#      build without sanitizer instrumentation, so in the code as shipped):
#        the command line rendering a Cornell box; tests/t_image.c;
#        tests/t_alloc.c, whose failed allocations walk every error path;
#        the loader-heavy groups of tests/t_extremes.c (degenerate triangles,
#        zero-area lights, a camera inside a cube).
#   2. ThreadSanitizer (testing.md R4): tests/tsan_render.c renders with 4
#      threads, every method, and compares with 1 thread byte for byte; any
#      reported race stops it (halt_on_error=1).
#
# Each step counts as one test; the last line is "N passed, N failed" like the
# other runners, and the exit status is non-zero when something failed.  A
# missing tool (no valgrind, a compiler without the TSan runtime) skips its
# steps with a message - unless DYNAMIC_STRICT=1, which counts it as a failure.
#
# Usage (from anywhere):  sh tests/dynamic.sh      CC=clang sh tests/dynamic.sh
# Builds go to build/dynamic/ (debug info, -O1: Valgrind's reports then name
# lines; the optimiser still runs, as it does for users).

cd "$(dirname "$0")/.." || exit 1

CC=${CC:-cc}
WARN="-std=c99 -Wall -Wextra -pedantic -Wshadow -Wvla"
OUT=build/dynamic
STRICT=${DYNAMIC_STRICT:-0}
VALGRIND="valgrind --error-exitcode=1 --leak-check=full -q"

pass=0
fail=0
mkdir -p "$OUT" tests/out

ok() {
    pass=$((pass + 1))
    echo "ok   $1"
}

bad() {
    fail=$((fail + 1))
    echo "FAIL $1"
}

# A tool that is not there: a failure only when DYNAMIC_STRICT=1.
missing() {
    if [ "$STRICT" = 1 ]; then
        bad "$1 (DYNAMIC_STRICT=1)"
    else
        echo "skip $1"
    fi
}

# run NAME COMMAND...: runs the command, keeps its output in $OUT/NAME.log,
# shows the end of it when it fails.
run() {
    name=$1
    shift
    "$@" >"$OUT/$name.log" 2>&1
    rc=$?
    if [ "$rc" -eq 0 ]; then
        ok "$name"
    else
        tail -n 30 "$OUT/$name.log"
        bad "$name (exit status $rc; log in $OUT/$name.log)"
    fi
}

# ---- 1. Valgrind memcheck -----------------------------------------------------
if command -v valgrind >/dev/null 2>&1; then
    # DWARF 4: older Valgrind releases cannot read the DWARF 5 that newer
    # compilers emit by default (clang 14: "Possibly corrupted debuginfo")
    VG_CFLAGS="-O1 -g -gdwarf-4"
    if $CC $WARN $VG_CFLAGS appm.c main.c -o "$OUT/appm" -lm -pthread &&
        $CC $WARN $VG_CFLAGS tests/t_image.c -o "$OUT/t_image" -lm -pthread &&
        $CC $WARN $VG_CFLAGS tests/t_alloc.c -o "$OUT/t_alloc" -lm -pthread &&
        $CC $WARN $VG_CFLAGS tests/t_extremes.c -o "$OUT/t_extremes" -lm -pthread; then
        run valgrind-cli $VALGRIND "$OUT/appm" render scenes/cornell-sphere.scene --size 16x16 \
            --passes 2 --threads 2 -q -o tests/out/vg.pfm
        run valgrind-t_image $VALGRIND "$OUT/t_image"
        run valgrind-t_alloc $VALGRIND "$OUT/t_alloc"
        run valgrind-t_extremes env APPM_TEST_ONLY=dlc $VALGRIND "$OUT/t_extremes"
    else
        bad "building the Valgrind programs with $CC"
    fi
else
    missing "Valgrind memcheck: valgrind is not installed"
fi

# ---- 2. ThreadSanitizer ---------------------------------------------------------
if $CC $WARN -O1 -g -fsanitize=thread tests/tsan_render.c -o "$OUT/tsan_render" -lm -pthread \
    >"$OUT/tsan-build.log" 2>&1; then
    # Some kernels map memory where TSan's shadow wants to be ("unexpected
    # memory mapping"); without address randomisation it works.
    if TSAN_OPTIONS=halt_on_error=1 "$OUT/tsan_render" >"$OUT/tsan.log" 2>&1; then
        ok "tsan_render"
    elif grep -q "unexpected memory mapping" "$OUT/tsan.log" && command -v setarch >/dev/null 2>&1; then
        run tsan_render-no-aslr env TSAN_OPTIONS=halt_on_error=1 setarch "$(uname -m)" -R "$OUT/tsan_render"
    else
        tail -n 40 "$OUT/tsan.log"
        bad "tsan_render (log in $OUT/tsan.log)"
    fi
else
    missing "ThreadSanitizer: $CC cannot build with -fsanitize=thread (see $OUT/tsan-build.log)"
fi

echo "$pass passed, $fail failed"
[ "$fail" -eq 0 ]
