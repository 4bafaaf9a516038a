# appm - build, test, portability, benchmarks.
#   make              the command line tool ./appm
#   make test         every test, normal build and ASan+UBSan build, plus the CLI
#   make test-long    the slow statistical tests (more samples)
#   make mpi          appm-mpi, the command line over MPI (mpicc); make test-mpi: it against appm;
#                     make bench-mpi: its speed-up and exchange (bench/mpi.sh)
#   make portability  gcc, clang, tcc, no threads, mingw-w64 (both thread backends), wasm32-wasi,
#                     C89/C++ header; QEMU=1: aarch64, s390x, i386 and armhf under qemu-user
#   make test-crash   SIGKILL/SIGTERM/SIGINT and a full disk against checkpoints (tests/crash.sh)
#   make bench        the speed/accuracy suite (bench/run.sh); make bench-quick: a subset;
#                     make bench-glossy: CornellBox-Glossy alone
#                     make bench-sampler: --sampler qmc against random on every scene
#                     make bench-envmap: environment-map sampling against uniform directions
#                     make bench-errbar: est_relerr against the true error, every scene and method
#                     make bench-studio: the bare bunny's studio (form, noise and grain at 10 s)
#                     make bench-fewmaps: appm against ppm's 15-point grid after 8 and 128 passes
#   make bench-bvh    the BVH alone: binary vs wide tree, SIMD vs scalar (bench/bvh.sh)
#   make fuzz         libFuzzer runs of the readers (clang), bounded in time; make fuzz-long:
#                     10 million executions each (hours)
#   make dynamic      valgrind memcheck on a short render, ThreadSanitizer on the threads
#   make web          web/appm.wasm and the scenes of the classroom page (clang, lld, wasi-libc)
#   make test-web     the page in headless Chromium against the native build (web/README.md)
# Without make:  cc -std=c99 -O2 appm.c main.c -lm -pthread -o appm

CC      ?= cc
CFLAGS  ?= -O2
WARN     = -std=c99 -Wall -Wextra -pedantic -Wshadow -Wvla
LDLIBS   = -lm -pthread
SAN      = -O1 -g -fsanitize=address,undefined -fno-sanitize-recover=all -fno-omit-frame-pointer
# the sanitizer build prefers clang: its UBSan also checks pointer arithmetic that leaves an
# object (a pointer formed one row before an array is undefined even if never read), gcc's does not
SANCC   ?= $(shell command -v clang >/dev/null 2>&1 && echo clang || echo $(CC))
TESTSRC  = $(wildcard tests/t_*.c)
TESTS    = $(patsubst tests/%.c,build/%,$(TESTSRC))
STESTS   = $(patsubst tests/%.c,build/san/%,$(TESTSRC))
DEPS     = appm.c appm.h tests/check.h tests/inflate.h tests/fuzz/targets.h

.PHONY: all mpi test-mpi bench-mpi test test-long test-crash portability dynamic bench bench-quick bench-glossy bench-bvh bench-sampler bench-envmap bench-errbar bench-studio bench-fewmaps fuzz fuzz-long web \
        test-web clean

all: appm

appm: appm.c appm.h main.c
	$(CC) $(WARN) $(CFLAGS) appm.c main.c -o $@ $(LDLIBS)

# appm-mpi: the command line over MPI (mpi.c includes main.c); the library stays MPI-free
MPICC ?= mpicc
mpi: appm-mpi

appm-mpi: appm.c appm.h main.c mpi.c
	$(MPICC) $(WARN) $(CFLAGS) appm.c mpi.c -o $@ $(LDLIBS)

test-mpi: appm appm-mpi
	@sh tests/mpi.sh ./appm ./appm-mpi

bench-mpi: appm appm-mpi
	sh bench/mpi.sh

# The tests: every tests/t_*.c in one program (tests/all.c), so that appm.c is
# compiled once per build rather than once per test; build/t_NAME is a link to
# it, and the program runs the test it is named after.  Each t_*.c still builds
# alone (cc tests/t_image.c -lm -pthread), as make portability's tcc suite does.
build/tests: tests/all.c $(TESTSRC) $(DEPS)
	@mkdir -p build
	$(CC) $(WARN) $(CFLAGS) -g tests/all.c -o $@ $(LDLIBS)

build/san/tests: tests/all.c $(TESTSRC) $(DEPS)
	@mkdir -p build/san
	$(SANCC) $(WARN) $(SAN) tests/all.c -o $@ $(LDLIBS)

build/t_%: build/tests
	ln -sf tests $@

build/san/t_%: build/san/tests
	ln -sf tests $@

# the CLI with every local variable pre-filled (where the compiler can), so that
# tests/cli.sh sees a read of a never-written variable
build/appm-pattern: appm.c appm.h main.c
	@mkdir -p build
	$(CC) $(WARN) $(CFLAGS) -ftrivial-auto-var-init=pattern appm.c main.c -o $@ $(LDLIBS) 2>/dev/null || \
	$(CC) $(WARN) $(CFLAGS) appm.c main.c -o $@ $(LDLIBS)

build/quickstart: examples/quickstart.c appm.c appm.h
	@mkdir -p build
	$(CC) $(WARN) $(CFLAGS) -I. examples/quickstart.c appm.c -o $@ $(LDLIBS)

build/embed: examples/embed.c appm.c appm.h
	@mkdir -p build
	$(CC) $(WARN) $(CFLAGS) examples/embed.c appm.c -o $@ $(LDLIBS)

test: build/san/tests build/tests appm build/embed build/appm-pattern build/quickstart $(TESTS) $(STESTS)
	@mkdir -p tests/out
	@sh tests/run.sh $(foreach t,$(STESTS),"APPM_TEST_QUICK=1 $(t)") $(TESTS) "APPM_PATTERN=build/appm-pattern sh tests/cli.sh ./appm build/embed" \
		"sh tests/alone.sh build/t_image build/t_loader" "sh tests/quickstart.sh build/quickstart" \
		"sh tests/layout.sh"

test-long: $(TESTS)
	@mkdir -p tests/out
	@APPM_TEST_LONG=1 sh tests/run.sh $(TESTS)

portability:
	sh tests/portability.sh

# SIGKILL at random instants, SIGTERM/SIGINT and a full disk against checkpoints
# (tests/crash.sh); CI runs it with CRASH_KILLS=20
test-crash: appm
	sh tests/crash.sh ./appm

dynamic: appm
	sh tests/dynamic.sh

bench: appm
	sh bench/run.sh full

bench-quick: appm
	sh bench/run.sh quick

bench-glossy: appm
	sh bench/run.sh glossy

bench-bvh:
	sh bench/bvh.sh

bench-sampler: appm
	sh bench/sampler.sh

bench-errbar: appm
	sh bench/errbar.sh

bench-envmap:
	sh bench/envmap.sh

bench-studio: appm
	sh bench/studio.sh

bench-fewmaps: appm
	sh bench/fewmaps.sh

fuzz:
	sh tests/fuzz/run.sh

# every target to 10 million executions (hours; outside CI): 10 minutes each with
# comparison tracing, then on from that corpus without it (FUZZ_FAST, 2.5-4 times the
# speed) to 10 M; FUZZ_TARGETS="obj mtl" picks targets.  docs/testing.md has the figures
fuzz-long:
	FUZZ_SECONDS=600 sh tests/fuzz/run.sh $(FUZZ_TARGETS)
	FUZZ_KEEP=1 FUZZ_FAST=1 FUZZ_RUNS=10000000 FUZZ_SECONDS=86400 sh tests/fuzz/run.sh $(FUZZ_TARGETS)

# WebAssembly: appm.c unchanged, no threads, as a WASI reactor (no main; the page
# calls the exports of web/shim.c).  Debian's wasi-libc installs under /usr.  The
# C stack gets 1 MiB instead of wasm-ld's 64 KiB, placed below the data so that an
# overflow traps instead of overwriting it.
WASMCC      ?= clang
WASI_SYSROOT ?= /usr
WEBSCENES    = $(patsubst scenes/%,web/scenes/%,$(wildcard scenes/CornellBox-*.obj scenes/CornellBox-*.mtl)) \
               $(patsubst %,web/scenes/cornell-%.scene,sphere original mirror glossy empty-rg empty-white) \
               web/scenes/CREDITS-cornell.txt

web: web/appm.wasm $(WEBSCENES)

web/appm.wasm: appm.c appm.h web/shim.c
	$(WASMCC) --target=wasm32-wasi --sysroot=$(WASI_SYSROOT) -mexec-model=reactor $(WARN) -O2 \
	    -DAPPM_THREADS=0 appm.c web/shim.c -o $@ -Wl,--strip-debug \
	    -Wl,-z,stack-size=1048576 -Wl,--stack-first

web/scenes/%: scenes/%
	@mkdir -p web/scenes
	cp $< $@

test-web: web appm
	python3 tests/web.py

clean:
	rm -rf appm appm.exe appm-mpi build tests/out tests/out-* bench/report web/appm.wasm web/scenes
