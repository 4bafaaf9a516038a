#!/bin/sh
# tests/portability.sh - the compiler matrix of make portability (docs/CONTRIBUTING.md,
# "C99 and portability").
#
#   gcc, clang      -std=c99 -pedantic -Wall -Wextra -Wshadow -Wvla -Werror, appm.c + main.c;
#                   tests/t_portable.c built by gcc and run: its furnace means are the
#                   reference (APPM_PORTABLE_REF) for every other run of it below
#   tcc             (in a lane of its own, beside the native steps) -Wall -Werror,
#                   appm.c + main.c, and tests/t_portable.c built and run;
#                   every test built, and every one but t_appm, t_render and t_checkpoint run (quick)
#   no threads      -DAPPM_THREADS=0: no pthread symbol in the object (nm), t_portable runs
#                   (the wasm32 tests below are built without threads too)
#   mingw-w64       Win32 threads (the default) and -DAPPM_THREADS=1 (winpthreads)
#   the header      C89 and C++98, syntax only
#   -ffast-math     must fail, with the library's #error
#   wasm32-wasi     clang -Werror, no threads: the web build (appm.c + web/shim.c), and
#                   the tests that run in seconds (t_portable, t_alloc, t_image, t_loader,
#                   t_bvh, t_sampling, t_fuzz_regress, t_pmap, t_estimator, t_lights,
#                   t_extremes, t_sampler, t_checkpoint, t_decode), 32-bit size_t, under
#                   Node's WASI
# Optional, each behind a variable:
#   WINE=1          t_portable built by mingw-w64 runs under wine (both thread backends)
#   QEMU=1          (in a lane of its own, beside the other steps from the start)
#                   every test built for 32-bit i386 (i686-linux-gnu-gcc) and armhf
#                   (arm-linux-gnueabihf-gcc), those of PORTABILITY_32 run (quick) under
#                   qemu-user: 32-bit size_t; t_portable and t_decode built for aarch64
#                   and big-endian s390x, t_bvh for aarch64 (NEON box test), run under
#                   qemu-user, and their appm resumes checkpoints that the native appm wrote
# The BVH's box test: t_bvh built with SSE2, -DAPPM_SIMD=0, -mavx2 (where the CPU
# has AVX2; clang with -mfma too), and renders of each SIMD build and its scalar
# twin compared byte for byte.
# A compiler or tool that is not installed is skipped with a message, unless
# PORTABILITY_STRICT=1, where it counts as a failure.  Each step prints ok, FAIL or
# skip; the last line is "N passed, N failed"; the exit status is non-zero on failure.
# Run from anywhere; works in the repository root, builds into build/port/.
# shellcheck disable=SC2086 # $C99 and $cc are word lists on purpose
set -u
cd "$(dirname "$0")/.." || exit 1
OUT=build/port
mkdir -p "$OUT" tests/out
STRICT=${PORTABILITY_STRICT:-0}
C99="-std=c99 -pedantic -Wall -Wextra -Wshadow -Wvla -Werror"
pass=0
fail=0
log="$OUT/step.log"
lap_t=$(date +%s)

# lap: sets took to "[N s]", the seconds since the last ok, FAIL or skip, i.e.
# what this step took (its build included), so a slow step shows in CI's log.
lap() {
    now=$(date +%s)
    took="[$((now - lap_t)) s]"
    lap_t=$now
}

ok() {
    lap
    echo "ok   $1 $took"
    pass=$((pass + 1))
}

bad() {
    lap
    [ -s "$log" ] && tail -n 25 "$log" | sed 's/^/     | /'
    echo "FAIL $1 $took"
    fail=$((fail + 1))
}

# have TOOL STEP: 0 if TOOL is installed; otherwise prints skip (or FAIL if strict).
have() {
    if command -v "$1" >/dev/null 2>&1; then return 0; fi
    : >"$log"
    if [ "$STRICT" = 1 ]; then
        bad "$2 ($1 is not installed; PORTABILITY_STRICT=1)"
    else
        lap
        echo "skip $2: $1 is not installed $took"
    fi
    return 1
}

# step NAME COMMAND...: runs the command, output to the log; ok if it exits 0.
step() {
    name=$1
    shift
    if "$@" >"$log" 2>&1; then ok "$name"; else bad "$name"; fi
}

# run_test NAME COMMAND...: runs a test program; ok if it exits 0 and its last
# line says "N passed, 0 failed".  The limit (RUN_LIMIT seconds, 600 unless set)
# only catches a hang: a whole suite under an unoptimising compiler or an
# emulator gets twice that, since a busy machine can stretch it past 600 s.
run_test() {
    name=$1
    shift
    run_logged "$@"
    judge "$name"
}

# run_logged COMMAND...: runs it under the limit, output in $log, status in $rc.
run_logged() {
    if command -v timeout >/dev/null 2>&1; then
        timeout "${RUN_LIMIT:-600}" "$@" >"$log" 2>&1
    else
        "$@" >"$log" 2>&1
    fi
    rc=$?
}

# judge NAME: ok if $rc is 0 and the last line of $log says "N passed, 0 failed".
judge() {
    last=$(tr -d '\r' <"$log" | tail -n 1)
    if [ "$rc" -eq 0 ] && printf '%s\n' "$last" | grep -q '^[0-9][0-9]* passed, 0 failed$'; then
        ok "$1 ($last)"
    else
        bad "$1 (exit status $rc)"
    fi
}

# run_hosted NAME COMMAND...: run_test for a program that runs inside a host (Node's
# WASI). A WebAssembly program cannot make its host die by a signal: its own faults
# (out of bounds, stack overflow) come back as a trap and exit status 1. So a status
# above 128 is the host's crash: the output is shown, the test runs once more, and the
# step is judged on that second run. But 137, a SIGKILL from outside (the kernel's
# out-of-memory killer), is not run again. (A hang ends by timeout's TERM: 124.)
run_hosted() {
    name=$1
    shift
    run_logged "$@"
    if [ "$rc" -gt 128 ] && [ "$rc" -ne 137 ]; then
        tail -n 5 "$log" | sed 's/^/     | /'
        echo "note $name: the host died by signal $((rc - 128)); running it again"
        name="$name, run again"
        run_logged "$@"
    fi
    judge "$name"
}

# suite NAME COMPILER-COMMAND LIBS [QUICK [BUILT-ONLY]]: every tests/t_*.c built
# with the given compiler command (as many at a time as there are processors)
# and run through tests/run.sh in quick mode (APPM_TEST_QUICK=QUICK, default 1;
# 2 takes a fifth of the loops whose tolerance does not depend on their length),
# except the tests named in BUILT-ONLY, which are only built; ok if the runner's
# total has no failure.
suite() {
    name=$1 cc=$2 libs=$3 quick=${4:-1} only_built=${5:-}
    dir="$OUT/suite-$(printf '%s' "$1" | tr -c 'A-Za-z0-9_\n' '_')"
    mkdir -p "$dir"
    jobs=$(getconf _NPROCESSORS_ONLN 2>/dev/null || echo 1)
    k=0
    for t in tests/t_*.c; do
        n=$(basename "$t" .c)
        # shellcheck disable=SC2086
        { $cc "$t" -o "$dir/$n" $libs >"$dir/$n.log" 2>&1; echo $? >"$dir/$n.rc"; } &
        k=$((k + 1))
        [ $((k % jobs)) -eq 0 ] && wait
    done
    wait
    set --
    for t in tests/t_*.c; do
        n=$(basename "$t" .c)
        if [ "$(cat "$dir/$n.rc" 2>/dev/null)" != 0 ]; then
            cat "$dir/$n.log" >"$log" 2>/dev/null
            bad "$name: the test suite ($n does not build)"
            return
        fi
        case " $only_built " in *" $n "*) continue ;; esac
        set -- "$@" "APPM_TEST_QUICK=$quick $dir/$n"
    done
    RUN_LIMIT=1200
    run_test "$name: the test suite" sh tests/run.sh "$@"
    RUN_LIMIT=600
}

# ---- the emulated builds: a lane of their own -------------------------------------------
# qemu runs one thread and most steps below build or run one program at a time,
# so the emulated builds run beside them (qemu_lane) with their own log and
# counts; their lines are printed, with the seconds each took, when they are done.
qemu_lane() {
    # ---- 32-bit Linux under qemu-user (i386, armhf) --------------------------------------
    # every size_t multiplication the library guards is 32 bits wide here: the tests' overflow
    # checks (t_alloc, t_extremes, t_decode's size limits) run where they can actually trip

    # PORTABILITY_32: the tests to run [t_portable t_alloc t_decode t_texture t_extremes
    # t_checkpoint t_fuzz_regress: about 4 minutes for both]; "all": every tests/t_*.c (about
    # half an hour).  t_fuzz_regress lists folders: readdir fails on 32-bit glibc without
    # 64-bit file offsets where inode numbers need 64 bits (appm.c asks for them).
    # i386 gets -msse2 -mfpmath=sse (x87 arithmetic would round otherwise than every other
    # build, and qemu emulates it slowly) and no threads: qemu-user 7.2 hangs i386 programs
    # whose threads wait on each other (threads are tested natively and under armhf).
    T32=${PORTABILITY_32:-"t_portable t_alloc t_decode t_texture t_extremes t_checkpoint t_fuzz_regress"}
    [ "$T32" = all ] && T32=$(cd tests && ls t_*.c | sed 's/\.c$//')
    for triple in i686-linux-gnu arm-linux-gnueabihf; do
        case $triple in
        i686*) q=i386 flags="-msse2 -mfpmath=sse -DAPPM_THREADS=0" ;;
        *) q=arm flags="" ;;
        esac
        what="$triple: the test suite under qemu-$q"
        if have $triple-gcc "$what" && have qemu-$q "$what"; then
            # main.c alone: appm.c is compiled, with the same flags, into the tests below
            step "$triple-gcc -Werror: main.c" $triple-gcc $C99 -O2 $flags -c main.c -o "$OUT/main-$q.o"
            # every test built (tests/all.c), the ones of PORTABILITY_32 run, their loops at a
            # fifth (APPM_TEST_QUICK=2: qemu is some 50 times slower; make test runs them whole)
            if $triple-gcc $C99 -O2 $flags tests/all.c -o "$OUT/tests-$q" -lm -pthread >"$log" 2>&1; then
                ok "$triple-gcc -Werror: tests/all.c (every test)"
                for n in $T32; do
                    run_test "qemu-$q: $n" env APPM_TEST_QUICK=2 qemu-$q -L /usr/$triple "$OUT/tests-$q" "$n"
                done
            else
                bad "$triple-gcc -Werror: tests/all.c (every test)"
            fi
        fi
    done

    # ---- aarch64 and big-endian s390x under qemu-user ------------------------------------
    for triple in aarch64-linux-gnu s390x-linux-gnu; do
        arch=${triple%%-*}
        what="$arch: t_portable under qemu"
        if have $triple-gcc "$what" && have qemu-$arch "$what"; then
            step "$triple-gcc -Werror: appm.c main.c" \
                $triple-gcc $C99 -O2 appm.c main.c -o "$OUT/appm-$arch" -lm -pthread
            # a checkpoint written here resumes there: the scene hash takes values as the
            # files state them (teapot: a framed camera and a spot light; cornell-glossy:
            # smooth triangles, a glossy lobe), never ones that the machine rounds its own way
            for sc in teapot cornell-glossy; do
                what="qemu-$arch: resumes a checkpoint of scenes/$sc.scene written by the native build"
                if [ ! -x "$OUT/appm-gcc" ] || [ ! -x "$OUT/appm-$arch" ]; then continue; fi
                ck="$OUT/move-$sc.ckpt"
                if "$OUT/appm-gcc" render "scenes/$sc.scene" --size 24x16 --passes 2 --threads 1 -q \
                    --checkpoint "$ck" -o "$OUT/move-$sc.pfm" >"$log" 2>&1 &&
                    qemu-$arch -L /usr/$triple "$OUT/appm-$arch" render "scenes/$sc.scene" --size 24x16 \
                        --passes 3 --threads 1 -q --resume "$ck" -o "$OUT/move-$sc-$arch.pfm" >"$log" 2>&1 &&
                    grep -q ' resumed=2' "$log"; then
                    ok "$what"
                else
                    bad "$what"
                fi
            done
            if $triple-gcc $C99 -O2 tests/t_portable.c -o "$OUT/t_portable-$arch" -lm -pthread \
                >"$log" 2>&1; then
                run_test "qemu-$arch: t_portable" qemu-$arch -L /usr/$triple "$OUT/t_portable-$arch"
            else
                bad "$triple-gcc: tests/t_portable.c"
            fi
            # t_decode: every image decoder on a big-endian host (s390x) too
            if $triple-gcc $C99 -O2 tests/t_decode.c -o "$OUT/t_decode-$arch" -lm -pthread >"$log" 2>&1; then
                run_test "qemu-$arch: t_decode" env APPM_TEST_QUICK=1 qemu-$arch -L /usr/$triple "$OUT/t_decode-$arch"
            else
                bad "$triple-gcc: tests/t_decode.c"
            fi
            # t_bvh: the NEON box test on aarch64 (the scalar one, which s390x would
            # run, is the native -DAPPM_SIMD=0 build's: the same C, no byte order in it)
            if [ "$arch" = aarch64 ]; then
                if $triple-gcc $C99 -O2 tests/t_bvh.c -o "$OUT/t_bvh-$arch" -lm -pthread >"$log" 2>&1; then
                    run_test "qemu-$arch: t_bvh (NEON)" env APPM_TEST_QUICK=2 \
                        qemu-$arch -L /usr/$triple "$OUT/t_bvh-$arch"
                else
                    bad "$triple-gcc: tests/t_bvh.c"
                fi
            fi
        fi
    done
}

# ---- native compilers -----------------------------------------------------------

for cc in gcc clang; do
    if have $cc "$cc -std=c99 -pedantic -Werror"; then
        step "$cc -std=c99 -pedantic -Werror: appm.c main.c" \
            $cc $C99 -O2 appm.c main.c -o "$OUT/appm-$cc" -lm -pthread
    fi
done

# The native t_portable: the reference for the other machines' furnace means.
APPM_PORTABLE_REF=
if have gcc "gcc: tests/t_portable.c runs (the reference)"; then
    if gcc $C99 -O2 tests/t_portable.c -o "$OUT/t_portable" -lm -pthread >"$log" 2>&1; then
        run_test "gcc: tests/t_portable.c runs (the reference)" "./$OUT/t_portable"
        APPM_PORTABLE_REF=$(grep '^furnace means:' "$log" | tail -n 1)
    else
        bad "gcc: tests/t_portable.c"
    fi
fi
export APPM_PORTABLE_REF

# ---- lanes: steps that run beside the others --------------------------------------
# lane NAME FUNCTION: runs FUNCTION in the background with its own log and counts
# (its lines go to $OUT/NAME.out, printed when it is joined); sets lane_pid.
lane() {
    rm -f "$OUT/$1.count"
    (
        log="$OUT/step-$1.log" pass=0 fail=0 lap_t=$(date +%s)
        APPM_TEST_OUT=$1 # the tests' scratch files: tests/out-NAME, apart from the others'
        export APPM_TEST_OUT
        "$2"
        echo "$pass $fail" >"$OUT/$1.count"
    ) >"$OUT/$1.out" 2>&1 &
    lane_pid=$!
}

# join NAME PID: waits for a lane and adds its lines and counts to these.
join() {
    wait "$2"
    cat "$OUT/$1.out"
    read -r lpass lfail <"$OUT/$1.count" || { lpass=0 lfail=1; echo "FAIL the $1 lane gave no count"; }
    pass=$((pass + lpass))
    fail=$((fail + lfail))
}

# tcc: unoptimised code, so the tests' loops at a fifth (the suite took 280 s at
# QUICK=1 on 2 cores); t_appm, t_render and t_checkpoint only built: their renders
# of real scenes, which no QUICK shortens, took 200 s of 360 (t_appm) and then 62 s
# and 48 s of the remaining 170 under tcc, and make test runs them twice
tcc_lane() {
    step "tcc -Wall -Werror: appm.c main.c" \
        tcc -Wall -Werror appm.c main.c -o "$OUT/appm-tcc" -lm -lpthread
    if tcc -Wall -Werror tests/t_portable.c -o "$OUT/t_portable-tcc" -lm -lpthread \
        >"$log" 2>&1; then
        run_test "tcc: tests/t_portable.c runs" "./$OUT/t_portable-tcc"
        suite tcc "tcc -Wall" "-lm -lpthread" 2 "t_appm t_render t_checkpoint"
    else
        bad "tcc -Wall -Werror: tests/t_portable.c"
    fi
}

# The emulated builds (the longest lane, one process at a time) and the tcc suite
# start here, once the native t_portable has set the reference, and run beside
# the native steps below.
qemu_pid=
if [ "${QEMU:-0}" = 1 ]; then
    RUN_LIMIT=1800 # a hang limit for emulated tests: t_appm takes 8-11 minutes under qemu
    lane qemu qemu_lane
    qemu_pid=$lane_pid
    RUN_LIMIT=600
fi
tcc_pid=
if have tcc "tcc -Wall -Werror"; then
    lane tcc tcc_lane
    tcc_pid=$lane_pid
fi

# ---- no threads -------------------------------------------------------------------

if have gcc "-DAPPM_THREADS=0"; then
    # one object of appm.c without threads: the command line linked with it (no -pthread) and
    # nm's look at it; the threaded object beside it only proves that nm sees pthread at all
    # (-O0: the same calls, a third of the compile)
    if gcc $C99 -O2 -DAPPM_THREADS=0 -c appm.c -o "$OUT/appm-nothreads.o" >"$log" 2>&1 &&
        gcc $C99 -O0 -c appm.c -o "$OUT/appm-threads.o" >>"$log" 2>&1; then
        step "gcc -DAPPM_THREADS=0: appm.c main.c, linked without -pthread" \
            gcc $C99 -O2 -DAPPM_THREADS=0 main.c "$OUT/appm-nothreads.o" -o "$OUT/appm-nothreads" -lm
        if have nm "nm: no pthread symbol with -DAPPM_THREADS=0"; then
            nm "$OUT/appm-nothreads.o" >"$OUT/nothreads.nm" 2>"$log"
            nm "$OUT/appm-threads.o" >"$OUT/threads.nm" 2>>"$log"
            if grep -qi pthread "$OUT/nothreads.nm"; then
                grep -i pthread "$OUT/nothreads.nm" >"$log"
                bad "nm: no pthread symbol with -DAPPM_THREADS=0"
            elif ! grep -qi pthread "$OUT/threads.nm"; then
                echo "the default build has no pthread symbol either: is nm working?" >"$log"
                bad "nm: no pthread symbol with -DAPPM_THREADS=0"
            else
                ok "nm: no pthread symbol with -DAPPM_THREADS=0"
            fi
        fi
    else
        bad "gcc -DAPPM_THREADS=0 -c appm.c"
    fi
    if gcc $C99 -O2 -DAPPM_THREADS=0 tests/t_portable.c -o "$OUT/t_portable-nothreads" -lm \
        >"$log" 2>&1; then
        run_test "-DAPPM_THREADS=0: tests/t_portable.c runs" "./$OUT/t_portable-nothreads"
    else
        bad "gcc -DAPPM_THREADS=0: tests/t_portable.c"
    fi
fi

# ---- SIMD and scalar box tests of the BVH ---------------------------------------------
# t_bvh on each path a compiler can build here (it also runs the scalar test of
# the same build, ray by ray), and the CLI's renders of a SIMD build and of its
# -DAPPM_SIMD=0 twin, which must be the same bytes.  AVX2 (8-wide tree) and
# FMA (no contraction under clang) only where this CPU has them.

cpu_has() { grep -qw "$1" /proc/cpuinfo 2>/dev/null; }

# same_render NAME FLAGS...: appm built with FLAGS and with FLAGS -DAPPM_SIMD=0
# renders the sphere box (ppm, appm and pt) to the same bytes.
same_render() {
    name=$1
    shift
    tag=$(printf '%s' "$name" | tr -c 'A-Za-z0-9_\n' '_')
    if ! gcc $C99 -O2 "$@" appm.c main.c -o "$OUT/appm-simd-$tag" -lm -pthread >"$log" 2>&1 ||
        ! gcc $C99 -O2 "$@" -DAPPM_SIMD=0 appm.c main.c -o "$OUT/appm-scalar-$tag" -lm -pthread >"$log" 2>&1; then
        bad "$name: SIMD and scalar renders (build)"
        return
    fi
    : >"$log"
    for m in ppm appm pt; do
        for v in simd scalar; do
            "./$OUT/appm-$v-$tag" render scenes/cornell-sphere.scene --method $m --size 48x48 --passes 2 \
                --threads 2 -q -o "$OUT/render-$v-$tag-$m.pfm" >>"$log" 2>&1 || echo "$v $m failed" >>"$log"
        done
        cmp "$OUT/render-simd-$tag-$m.pfm" "$OUT/render-scalar-$tag-$m.pfm" >>"$log" 2>&1 ||
            echo "$m: the images differ" >>"$log"
    done
    if grep -q 'differ\|failed' "$log"; then bad "$name: SIMD and scalar renders"; else ok "$name: SIMD and scalar renders are the same bytes"; fi
}

# same_as_default NAME TAG: the SIMD renders of same_render NAME equal the default build's.
same_as_default() {
    : >"$log"
    for m in ppm appm pt; do
        cmp "$OUT/render-simd-gcc_SSE2-$m.pfm" "$OUT/render-simd-$2-$m.pfm" >>"$log" 2>&1 || echo "$m differs" >>"$log"
    done
    if grep -q 'differ' "$log"; then bad "$1: renders differ from the default build's"; else ok "$1: renders are the default build's bytes"; fi
}

# bvh_test NAME COMPILER FLAGS...: t_bvh built and run in quick mode
bvh_test() {
    name=$1 cc=$2
    shift 2
    tag=$(printf '%s' "$name" | tr -c 'A-Za-z0-9_\n' '_')
    if $cc $C99 -O2 "$@" tests/t_bvh.c -o "$OUT/t_bvh-$tag" -lm -pthread >"$log" 2>&1; then
        run_test "$name: t_bvh" env APPM_TEST_QUICK=1 "./$OUT/t_bvh-$tag"
    else
        bad "$name: t_bvh (build)"
    fi
}

if have gcc "SIMD paths"; then
    bvh_test "gcc SSE2" gcc
    bvh_test "gcc -DAPPM_SIMD=0" gcc -DAPPM_SIMD=0
    same_render "gcc SSE2"
    if cpu_has avx2; then
        bvh_test "gcc -mavx2" gcc -mavx2
        bvh_test "gcc -mavx2 -DAPPM_SIMD=0" gcc -mavx2 -DAPPM_SIMD=0
        same_render "gcc -mavx2" -mavx2
        same_as_default "gcc -mavx2" gcc__mavx2
    else
        lap
        echo "skip -mavx2: this CPU has no AVX2 $took"
    fi
fi
if have clang "clang SIMD paths" && cpu_has avx2 && cpu_has fma; then
    bvh_test "clang -mavx2 -mfma" clang -mavx2 -mfma
fi

# ---- mingw-w64 ----------------------------------------------------------------------

MINGW=x86_64-w64-mingw32-gcc
if have $MINGW "mingw-w64 (Win32 threads)"; then
    step "mingw-w64 -Werror, Win32 threads: appm.c main.c" \
        $MINGW $C99 -O2 appm.c main.c -o "$OUT/appm-win32.exe"
    step "mingw-w64 -Werror, -DAPPM_THREADS=1 (winpthreads): appm.c main.c" \
        $MINGW $C99 -O2 -DAPPM_THREADS=1 appm.c main.c -o "$OUT/appm-winpthreads.exe" -lpthread
fi

# ---- the header alone ----------------------------------------------------------------

if have gcc "appm.h as C89"; then
    step "appm.h: gcc -x c -std=c89 -pedantic -Werror -fsyntax-only" \
        gcc -x c -std=c89 -pedantic -Wall -Wextra -Werror -fsyntax-only appm.h
fi
if have g++ "appm.h as C++98"; then
    step "appm.h: g++ -x c++ -std=c++98 -pedantic -Werror -fsyntax-only" \
        g++ -x c++ -std=c++98 -pedantic -Wall -Wextra -Werror -fsyntax-only appm.h
fi

# ---- -ffast-math must be refused -------------------------------------------------------

if have gcc "-ffast-math is refused"; then
    if gcc -std=c99 -O2 -ffast-math -c appm.c -o "$OUT/fast-math.o" >"$log" 2>&1; then
        echo "appm.c compiled with -ffast-math" >"$log"
        bad "-ffast-math is refused by the #error"
    elif grep -q 'fast-math' "$log" && grep -q 'error' "$log"; then
        ok "-ffast-math is refused by the #error"
    else
        bad "-ffast-math is refused by the #error (it failed, but not with the #error)"
    fi
fi

# ---- wasm32-wasi: 32-bit size_t, no threads, no pthread (the browser build) ------------------

WASI_SYSROOT=${WASI_SYSROOT:-/usr}
WASM="clang --target=wasm32-wasi --sysroot=$WASI_SYSROOT $C99 -O2 -DAPPM_THREADS=0"
if have clang "wasm32-wasi"; then
    if [ -f "$WASI_SYSROOT/include/wasm32-wasi/stdio.h" ] ||
        [ -f "$WASI_SYSROOT/include/stdio.h" ]; then
        step "clang wasm32-wasi -Werror: appm.c web/shim.c (make web)" \
            $WASM -mexec-model=reactor appm.c web/shim.c -o "$OUT/appm.wasm"
        if have node "wasm32-wasi: the tests under Node's WASI"; then
            # wasm-ld gives the C stack 64 KiB and puts it above the data, where an
            # overflow silently overwrites malloc's state; the tests' big local arrays
            # (t_bvh's most of all) get 32 MiB, below the data, so an overflow traps.
            # Every test is built (tests/all.c: one compilation of appm.c), the ones that
            # run in seconds are run.
            if $WASM tests/all.c -o "$OUT/tests.wasm" -Wl,-z,stack-size=33554432 \
                -Wl,--stack-first >"$log" 2>&1; then
                ok "clang wasm32-wasi -Werror: tests/all.c (every test)"
                for n in t_portable t_alloc t_image t_loader t_bvh t_sampling t_fuzz_regress t_pmap \
                    t_estimator t_lights t_extremes t_sampler t_checkpoint t_decode; do
                    run_hosted "wasm32-wasi: $n under node" env APPM_TEST_QUICK=1 \
                        node --experimental-wasi-unstable-preview1 --no-warnings \
                        tests/wasi-run.mjs "$OUT/tests.wasm" "$n"
                done
            else
                bad "clang wasm32-wasi -Werror: tests/all.c (every test)"
            fi
        fi
    else
        : >"$log"
        if [ "$STRICT" = 1 ]; then
            bad "wasm32-wasi (no wasi-libc under $WASI_SYSROOT; PORTABILITY_STRICT=1)"
        else
            lap
            echo "skip wasm32-wasi: no wasi-libc under $WASI_SYSROOT (set WASI_SYSROOT) $took"
        fi
    fi
fi

# ---- optional: wine ------------------------------------------------------------------------

if [ "${WINE:-0}" = 1 ]; then
    if have $MINGW "wine: t_portable.exe" && have wine "wine: t_portable.exe"; then
        WINEDEBUG=-all
        export WINEDEBUG
        if $MINGW $C99 -O2 tests/t_portable.c -o "$OUT/t_portable.exe" >"$log" 2>&1; then
            run_test "wine: t_portable.exe (Win32 threads)" wine "$OUT/t_portable.exe"
        else
            bad "mingw-w64: tests/t_portable.c"
        fi
        # -static: winpthreads' DLL is not on wine's path
        if $MINGW $C99 -O2 -DAPPM_THREADS=1 -static tests/t_portable.c \
            -o "$OUT/t_portable-pthread.exe" -lpthread >"$log" 2>&1; then
            run_test "wine: t_portable-pthread.exe (winpthreads)" wine "$OUT/t_portable-pthread.exe"
        else
            bad "mingw-w64 -DAPPM_THREADS=1 -static: tests/t_portable.c"
        fi
    fi
else
    lap
    echo "skip wine: set WINE=1 to run a mingw-w64 build under wine $took"
fi

[ -n "$tcc_pid" ] && join tcc "$tcc_pid"
if [ -n "$qemu_pid" ]; then
    join qemu "$qemu_pid"
else
    lap
    echo "skip qemu: set QEMU=1 to run 32-bit i386 and armhf, aarch64 and big-endian s390x builds under qemu-user $took"
fi

echo "$pass passed, $fail failed"
[ "$fail" -eq 0 ]
