/* appm.c - Adaptive Progressive Photon Mapping.  The whole implementation.
 *
 * Read appm.h for the API and its manual; this file is for those who want to
 * know how it works.  Sections are numbered; each uses only the ones above it.
 *
 * TABLE OF CONTENTS
 *   1. Platform and threads   feature macros, timer, mutex, spawn-per-call
 *                             parallel loop over a mutex-guarded task counter
 *   2. Core utilities         diagnostics, the one allocation wrapper, growable
 *                             arrays, float3 math, the PCG32 random streams
 *   3. Image I/O              PFM read/write, PPM (P6), PNG and OpenEXR with
 *                             their own deflate (LZ77 + Huffman), sRGB transfer,
 *                             write-to-temporary-then-rename
 *   4. OBJ/MTL and scenes     locale-free number parser, OBJ/MTL/`.scene`
 *                             readers with file:line errors
 *   5. BVH                    binned-SAH build, watertight ray/triangle test,
 *                             closest-hit and any-hit traversal, ray offsets
 *   6. Materials and lights   Lambert, mirror, Fresnel dielectric, glossy; light
 *                             choice by power, emission and next-event sampling;
 *                             scene assembly (loader arrays -> scene)
 *   7. Photons and the map    32-byte photon records, octahedral directions, the
 *                             hash grid: counting sort into cells, range queries
 *   8. Renderer and eye pass  the renderer's state; camera paths to the first
 *                             diffuse vertex
 *   9. Photon pass            photon paths, per-worker stores, chunk order
 *  10. Estimators             kernels and the gather's sums; ppm (Knaus-Zwicker),
 *                             sppm (Hachisuka-Jensen); the paper's adaptive
 *                             radius (Kaplanyan-Dachsbacher, appm-paper) and
 *                             appm's extensions of it; the gather
 *  11. Path-tracing reference unidirectional, next-event estimation + MIS
 *  12. Renderer               life cycle, the pass loop, image, maps, statistics
 *  13. Checkpoints            the render state to a file and back
 *
 * CONVENTIONS
 *   Geometry is single precision (float3); every accumulator that grows with the
 *   number of passes or photons is double or uint64_t.  Directions point away
 *   from the surface (wo towards the eye, wi towards the light).  Names follow
 *   the papers: r (radius), M (photon paths per pass), j or N (pass, 1-based),
 *   W (eye-path weight), gamma (photon weight), Psi = W f gamma.
 */

/* One copy per program: tests/all.c builds every test into one program, and
 * each test includes this file (to reach the internals) as a program of its own
 * does; the second inclusion is empty. */
#ifndef APPM_C_INCLUDED
#define APPM_C_INCLUDED

/* ==== 1. PLATFORM AND THREADS ============================================
 *
 * Everything that differs between operating systems lives here.  The thread
 * backend is chosen at compile time (APPM_THREADS: 0 none, 1 pthreads, 2 Win32).
 * Parallel work is a loop over tasks 0..n-1 handed out by a mutex-guarded
 * counter: tasks are coarse (a row of pixels, a chunk of photon paths), so one
 * lock per task costs nothing measurable, and no atomics are needed (tcc has
 * none).  Threads are started and joined inside each call: no pool, no
 * condition variables, nothing that can deadlock.  Results never depend on which
 * worker ran a task: workers only ever write to per-task or per-pixel memory.
 */
#if defined(__FAST_MATH__) && !defined(APPM_ALLOW_FAST_MATH)
#error "appm must not be compiled with -ffast-math: it relies on NaN checks and IEEE sums"
#endif
/* No fused multiply-adds either: the watertight triangle test (section 5) needs
 * its edge functions U = Cx By - Cy Bx, ... rounded the same way for both
 * triangles of a shared edge, and an fma rounds one product and not the other,
 * so rays from inside a closed mesh leak through its edges.  GCC does not
 * contract in ISO C mode (-std=c99); clang does by default where the target has
 * FMA (-march=native), unless told not to. */
#if defined(__clang__)
#pragma STDC FP_CONTRACT OFF
#endif

#ifndef _POSIX_C_SOURCE
#define _POSIX_C_SOURCE 200809L
#endif
/* 64-bit file offsets on 32-bit glibc: without it fopen refuses a file over
 * 2 GiB (a big render's checkpoint) and readdir fails on a file system whose
 * inode numbers need 64 bits (seen under qemu-i386).  64-bit systems have
 * such offsets already (glibc then names its calls fopen64 and the like). */
#ifndef _FILE_OFFSET_BITS
#define _FILE_OFFSET_BITS 64
#endif
#if defined(_WIN32) && !defined(_CRT_SECURE_NO_WARNINGS)
#define _CRT_SECURE_NO_WARNINGS
#endif

#include "appm.h"

#include <float.h>
#include <limits.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <time.h>

#ifndef S_ISREG
#define S_ISREG(m) (((m) & S_IFMT) == S_IFREG)
#endif

#ifndef APPM_THREADS
#if defined(_WIN32)
#define APPM_THREADS 2
#elif defined(__unix__) || defined(__APPLE__)
#define APPM_THREADS 1
#else
#define APPM_THREADS 0
#endif
#endif

#if APPM_THREADS == 1
#include <pthread.h>
#include <unistd.h>
typedef pthread_mutex_t appm__mutex;
#define appm__mutex_init(m) pthread_mutex_init((m), NULL)
#define appm__mutex_destroy(m) pthread_mutex_destroy(m)
#define appm__mutex_lock(m) pthread_mutex_lock(m)
#define appm__mutex_unlock(m) pthread_mutex_unlock(m)
#elif APPM_THREADS == 2
#ifndef WIN32_LEAN_AND_MEAN
#define WIN32_LEAN_AND_MEAN
#endif
#include <windows.h>
typedef CRITICAL_SECTION appm__mutex;
#define appm__mutex_init(m) InitializeCriticalSection(m)
#define appm__mutex_destroy(m) DeleteCriticalSection(m)
#define appm__mutex_lock(m) EnterCriticalSection(m)
#define appm__mutex_unlock(m) LeaveCriticalSection(m)
#else
typedef int appm__mutex;
#define appm__mutex_init(m) ((void)(m))
#define appm__mutex_destroy(m) ((void)(m))
#define appm__mutex_lock(m) ((void)(m))
#define appm__mutex_unlock(m) ((void)(m))
#endif

#if defined(_WIN32) && APPM_THREADS != 2
#ifndef WIN32_LEAN_AND_MEAN
#define WIN32_LEAN_AND_MEAN
#endif
#include <windows.h>
#endif
#if defined(_WIN32)
#include <io.h> /* _commit, _fileno: appm__file_sync */
#elif defined(__unix__) || defined(__APPLE__)
#include <fcntl.h>  /* open: appm__dir_sync */
#include <unistd.h> /* fsync */
#define APPM__FSYNC 1
#endif

#define APPM__MAX_THREADS 256

/* SIMD.  Only the BVH (section 5) uses vector instructions, in its child-box
 * test and its leaves' four-triangle test, and only those the compiler says
 * the target has: SSE2 on x86-64 (part of the
 * architecture, so every x86-64 build gets it: two 4-wide halves of a node;
 * with -mavx2 or -march=native all 8 children in one AVX2 vector; SSE4.1 adds
 * nothing the test needs), NEON on aarch64 (two halves).  There is no run-time
 * CPU dispatch: the build flags choose.  Every other compiler or target (tcc,
 * s390x, 32-bit ARM) and -DAPPM_SIMD=0 get the portable scalar test, which
 * performs the very same float operations in the same order, so a SIMD build
 * and its -DAPPM_SIMD=0 twin find the same hits and render the same bytes.  The tree is 8 wide on every
 * target (APPM_BVH_WIDTH=4 builds a 4-wide one, for comparisons): on this
 * project's benchmark 8 children per node beat 4 even with SSE2's two halves,
 * as the tree is then shallower and the traversal waits on fewer node loads. */
#ifndef APPM_SIMD
#define APPM_SIMD 1
#endif
#if APPM_SIMD && !defined(__TINYC__) && \
    (defined(__SSE2__) || defined(_M_X64) || (defined(_M_IX86_FP) && _M_IX86_FP >= 2))
#define APPM__SSE 1
#include <emmintrin.h>
#if defined(__AVX2__)
#include <immintrin.h>
#endif
#elif APPM_SIMD && !defined(__TINYC__) && defined(__ARM_NEON) && defined(__aarch64__)
#define APPM__NEON 1
#include <arm_neon.h>
#endif
#ifndef APPM_BVH_WIDTH /* 4 or 8 */
#define APPM_BVH_WIDTH 8
#endif
#define APPM__BVH_W APPM_BVH_WIDTH
#if APPM__BVH_W != 4 && APPM__BVH_W != 8
#error "APPM_BVH_WIDTH must be 4 or 8"
#endif
#if defined(APPM__SSE) && defined(__AVX2__) && APPM__BVH_W == 8
#define APPM__AVX8 1 /* one 256-bit vector holds a node's eight children */
#endif
#if defined(APPM__AVX8)
#define APPM__SIMD_NAME "avx2"
#elif defined(APPM__SSE)
#define APPM__SIMD_NAME "sse2"
#elif defined(APPM__NEON)
#define APPM__SIMD_NAME "neon"
#else
#define APPM__SIMD_NAME "scalar"
#endif

/* Wall-clock seconds from an arbitrary origin (clock() would be CPU time). */
static double appm__seconds(void)
{
#if defined(_WIN32)
    LARGE_INTEGER f, c;
    QueryPerformanceFrequency(&f);
    QueryPerformanceCounter(&c);
    return (double)c.QuadPart / (double)f.QuadPart;
#elif defined(CLOCK_MONOTONIC)
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
#else
    return (double)clock() / (double)CLOCKS_PER_SEC;
#endif
}

APPM_API unsigned appm_cpu_count(void)
{
#if APPM_THREADS == 1 && !defined(_WIN32)
    long n = sysconf(_SC_NPROCESSORS_ONLN);
    if (n < 1) return 1;
    return n > APPM__MAX_THREADS ? APPM__MAX_THREADS : (unsigned)n;
#elif APPM_THREADS != 0 /* Win32 threads, or winpthreads: Windows has no sysconf */
    SYSTEM_INFO si;
    GetSystemInfo(&si);
    if (si.dwNumberOfProcessors < 1) return 1;
    return si.dwNumberOfProcessors > APPM__MAX_THREADS ? APPM__MAX_THREADS
                                                         : (unsigned)si.dwNumberOfProcessors;
#else
    return 1;
#endif
}

/* Replace `to` by `from` (both in one folder).  POSIX rename() replaces; the
 * Windows C library refuses when `to` exists, so remove it first there. */
static int appm__rename_replace(const char *from, const char *to)
{
#if defined(_WIN32)
    return MoveFileExA(from, to, MOVEFILE_REPLACE_EXISTING) ? 0 : -1;
#else
    return rename(from, to);
#endif
}

/* Makes the bytes written to f durable before the rename that publishes
 * them: without it a power cut soon after the rename can leave the new name
 * holding nothing (file systems allocate blocks late, and may write the
 * rename first).  A killed process loses nothing either way - its writes are
 * in the kernel already - but a crashed machine would.  0 on success. */
static int appm__file_sync(FILE *f)
{
    if (fflush(f) != 0) return -1;
#if defined(_WIN32)
    return _commit(_fileno(f));
#elif defined(APPM__FSYNC)
    return fsync(fileno(f));
#else
    return 0;
#endif
}

/* After a rename: makes the folder's new entry durable too (POSIX; Windows'
 * MoveFileEx needs nothing more here).  Best effort: a folder that cannot
 * be opened (no read permission) leaves it to the file system. */
static void appm__dir_sync(const char *path)
{
#if defined(APPM__FSYNC)
    char dir[4096];
    size_t n = strlen(path), cut = 0, i;
    int fd;
    for (i = 0; i < n; ++i)
        if (path[i] == '/') cut = i;
    if (n >= sizeof dir) return;
    if (path[cut] == '/') {
        memcpy(dir, path, cut ? cut : 1);
        dir[cut ? cut : 1] = 0;
    } else {
        dir[0] = '.';
        dir[1] = 0;
    }
    fd = open(dir, O_RDONLY);
    if (fd >= 0) {
        (void)fsync(fd);
        (void)close(fd);
    }
#else
    (void)path;
#endif
}

/* Whether `path` exists and is not a regular file (a device such as /dev/full
 * or /dev/stdout, a FIFO): such a destination is written in place, since
 * renaming a temporary over it would replace the device node. */
static int appm__is_special_file(const char *path)
{
    struct stat st;
    if (stat(path, &st) != 0) return 0;
    return !S_ISREG(st.st_mode);
}

typedef void (*appm__task_fn)(void *arg, uint32_t task, unsigned worker);

typedef struct appm__queue {
    appm__mutex lock;
    uint32_t first, next, count; /* tasks first + [next, count) are left */
    appm__task_fn fn;
    void *arg;
} appm__queue;

typedef struct appm__worker {
    appm__queue *q;
    unsigned id;
} appm__worker;

static void appm__worker_loop(appm__queue *q, unsigned id)
{
    for (;;) {
        uint32_t t;
        int ok;
        appm__mutex_lock(&q->lock);
        ok = q->next < q->count;
        t = q->next;
        if (ok) q->next++;
        appm__mutex_unlock(&q->lock);
        if (!ok) return;
        q->fn(q->arg, q->first + t, id);
    }
}

#if APPM_THREADS == 1
static void *appm__thread_main(void *p)
{
    appm__worker *w = (appm__worker *)p;
    appm__worker_loop(w->q, w->id);
    return NULL;
}
#elif APPM_THREADS == 2
static DWORD WINAPI appm__thread_main(LPVOID p)
{
    appm__worker *w = (appm__worker *)p;
    appm__worker_loop(w->q, w->id);
    return 0;
}
#endif

/* Runs fn(arg, t, worker) for t = first .. first + count - 1 on up to `threads`
 * workers (the caller is worker 0).  A thread that cannot be started simply
 * leaves its share to the others, so this never fails. */
static void appm__parallel_range(unsigned threads, uint32_t first, uint32_t count, appm__task_fn fn, void *arg)
{
    appm__queue q;
    unsigned n = threads < 1 ? 1 : threads, i;
    if (n > APPM__MAX_THREADS) n = APPM__MAX_THREADS;
    if (n > count) n = count ? count : 1;
    q.first = first;
    q.next = 0;
    q.count = count;
    q.fn = fn;
    q.arg = arg;
    appm__mutex_init(&q.lock);
#if APPM_THREADS == 1 || APPM_THREADS == 2
    if (n > 1) {
        appm__worker w[APPM__MAX_THREADS];
#if APPM_THREADS == 1
        pthread_t th[APPM__MAX_THREADS];
#else
        HANDLE th[APPM__MAX_THREADS];
#endif
        int started[APPM__MAX_THREADS];
        for (i = 1; i < n; ++i) {
            w[i].q = &q;
            w[i].id = i;
#if APPM_THREADS == 1
            started[i] = pthread_create(&th[i], NULL, appm__thread_main, &w[i]) == 0;
#else
            th[i] = CreateThread(NULL, 0, appm__thread_main, &w[i], 0, NULL);
            started[i] = th[i] != NULL;
#endif
        }
        appm__worker_loop(&q, 0);
        for (i = 1; i < n; ++i) {
            if (!started[i]) continue;
#if APPM_THREADS == 1
            pthread_join(th[i], NULL);
#else
            WaitForSingleObject(th[i], INFINITE);
            CloseHandle(th[i]);
#endif
        }
    } else
#endif
    {
        (void)i;
        appm__worker_loop(&q, 0);
    }
    appm__mutex_destroy(&q.lock);
}

static void appm__parallel_for(unsigned threads, uint32_t count, appm__task_fn fn, void *arg)
{
    appm__parallel_range(threads, 0, count, fn, arg);
}

/* ==== 2. CORE UTILITIES ==================================================
 *
 * Diagnostics: the first error of a call wins (later ones are usually its
 * consequences) and carries file and line.  Memory: every byte goes through
 * appm__alloc, which checks count * size for overflow, checks for NULL, zeroes
 * (uninitialised memory is a classic source of non-determinism) and counts live
 * and peak bytes.  A 16-byte header keeps the size, so the user's free hook gets
 * the exact size that was allocated.  Growth is allocate-copy-free: no realloc.
 */
#define APPM__PI 3.14159265358979323846
#define APPM__PIF 3.14159265358979323846f
#define APPM__INV_PI 0.31830988618379067154

static const char *const appm__status_text[APPM_STATUS_COUNT] = {
    "ok", "out of memory", "input/output error", "malformed input",
    "invalid argument"};

APPM_API const char *appm_status_string(appm_status s)
{
    if ((int)s < 0 || s >= APPM_STATUS_COUNT) return "unknown status";
    return appm__status_text[s];
}

APPM_API const char *appm_version(void) { return APPM_VERSION; }

static void appm__diag_clear(appm_diag *d)
{
    if (!d) return;
    d->status = APPM_OK;
    d->line = 0;
    d->file[0] = 0;
    d->message[0] = 0;
}

static void appm__copy_str(char *dst, size_t cap, const char *src)
{
    size_t n = strlen(src);
    if (n >= cap) n = cap - 1;
    memcpy(dst, src, n);
    dst[n] = 0;
}

static appm_status appm__fail(appm_diag *d, appm_status s, const char *file, unsigned line,
                              const char *fmt, ...)
{
    va_list ap;
    if (d && d->status == APPM_OK) {
        d->status = s;
        d->line = line;
        appm__copy_str(d->file, sizeof d->file, file ? file : "");
        va_start(ap, fmt);
        vsnprintf(d->message, sizeof d->message, fmt, ap);
        va_end(ap);
    }
    return s;
}

typedef struct appm__mem {
    appm_allocator a;
    appm_file_reader reader; /* appm_config.reader: where appm__read_file gets its bytes */
    appm_diag *diag; /* where an allocation failure is reported (may be NULL) */
    size_t live, peak;
} appm__mem;

static void *appm__default_alloc(void *user, size_t size)
{
    (void)user;
    return malloc(size);
}

static void appm__default_free(void *user, void *p, size_t size)
{
    (void)user;
    (void)size;
    free(p);
}

static void appm__mem_init(appm__mem *m, const appm_config *cfg)
{
    memset(m, 0, sizeof *m);
    if (cfg && cfg->allocator.alloc && cfg->allocator.free) {
        m->a = cfg->allocator;
    } else {
        m->a.alloc = appm__default_alloc;
        m->a.free = appm__default_free;
        m->a.user = NULL;
    }
    if (cfg && cfg->reader.read) m->reader = cfg->reader;
}

#define APPM__ALLOC_HEADER 16

static void *appm__alloc(appm__mem *m, size_t count, size_t size)
{
    size_t bytes;
    unsigned char *p;
    if (size != 0 && count > (SIZE_MAX - APPM__ALLOC_HEADER) / size) {
        appm__fail(m->diag, APPM_ERR_NOMEM, NULL, 0, "allocation of %.0f x %.0f bytes overflows",
                   (double)count, (double)size);
        return NULL;
    }
    bytes = count * size + APPM__ALLOC_HEADER;
    p = (unsigned char *)m->a.alloc(m->a.user, bytes);
    if (!p) {
        appm__fail(m->diag, APPM_ERR_NOMEM, NULL, 0, "out of memory (%.0f bytes)", (double)bytes);
        return NULL;
    }
    memset(p, 0, bytes);
    memcpy(p, &bytes, sizeof bytes);
    m->live += bytes;
    if (m->live > m->peak) m->peak = m->live;
    return p + APPM__ALLOC_HEADER;
}

static void appm__free(appm__mem *m, void *ptr)
{
    unsigned char *p;
    size_t bytes;
    if (!ptr) return;
    p = (unsigned char *)ptr - APPM__ALLOC_HEADER;
    memcpy(&bytes, p, sizeof bytes);
    m->live -= bytes;
    m->a.free(m->a.user, p, bytes);
}

/* Growable array of fixed-size elements (doubling; allocate-copy-free). */
typedef struct appm__array {
    void *data;
    size_t count, cap, elem;
} appm__array;

static void appm__array_init(appm__array *a, size_t elem)
{
    a->data = NULL;
    a->count = a->cap = 0;
    a->elem = elem;
}

static int appm__array_reserve(appm__mem *m, appm__array *a, size_t want)
{
    void *nd;
    size_t ncap;
    if (want <= a->cap) return 1;
    ncap = a->cap ? a->cap : 16;
    while (ncap < want) {
        if (ncap > SIZE_MAX / 2) return 0;
        ncap *= 2;
    }
    nd = appm__alloc(m, ncap, a->elem);
    if (!nd) return 0;
    if (a->count) memcpy(nd, a->data, a->count * a->elem);
    appm__free(m, a->data);
    a->data = nd;
    a->cap = ncap;
    return 1;
}

/* Appends one element and returns it (zeroed), or NULL when out of memory. */
static void *appm__array_push(appm__mem *m, appm__array *a)
{
    char *slot;
    if (a->count == a->cap && !appm__array_reserve(m, a, a->count + 1)) return NULL;
    slot = (char *)a->data + a->count * a->elem;
    memset(slot, 0, a->elem);
    a->count++;
    return slot;
}

static void appm__array_free(appm__mem *m, appm__array *a)
{
    appm__free(m, a->data);
    a->data = NULL;
    a->count = a->cap = 0;
}

/* ---- 2.1 Float3 ---------------------------------------------------------- */

typedef struct appm__v3 {
    float x, y, z;
#if defined(__TINYC__) && defined(__x86_64__)
    float tcc_pad; /* tcc 0.9.27 stores a returned 12-byte float struct as 16 bytes */
#endif
} appm__v3;

static inline appm__v3 appm__v(float x, float y, float z)
{
    appm__v3 r;
    r.x = x;
    r.y = y;
    r.z = z;
    return r;
}
static inline appm__v3 appm__add(appm__v3 a, appm__v3 b) { return appm__v(a.x + b.x, a.y + b.y, a.z + b.z); }
static inline appm__v3 appm__sub(appm__v3 a, appm__v3 b) { return appm__v(a.x - b.x, a.y - b.y, a.z - b.z); }
static inline appm__v3 appm__mul(appm__v3 a, appm__v3 b) { return appm__v(a.x * b.x, a.y * b.y, a.z * b.z); }
static inline appm__v3 appm__scale(appm__v3 a, float s) { return appm__v(a.x * s, a.y * s, a.z * s); }
static inline appm__v3 appm__neg(appm__v3 a) { return appm__v(-a.x, -a.y, -a.z); }
static inline float appm__dot(appm__v3 a, appm__v3 b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
static inline appm__v3 appm__cross(appm__v3 a, appm__v3 b)
{
    return appm__v(a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x);
}
static inline float appm__length(appm__v3 a) { return sqrtf(appm__dot(a, a)); }
static inline appm__v3 appm__normalize(appm__v3 a)
{
    float l = appm__length(a);
    return l > 0.0f ? appm__scale(a, 1.0f / l) : a;
}
static inline appm__v3 appm__vmin(appm__v3 a, appm__v3 b)
{
    return appm__v(a.x < b.x ? a.x : b.x, a.y < b.y ? a.y : b.y, a.z < b.z ? a.z : b.z);
}
static inline appm__v3 appm__vmax(appm__v3 a, appm__v3 b)
{
    return appm__v(a.x > b.x ? a.x : b.x, a.y > b.y ? a.y : b.y, a.z > b.z ? a.z : b.z);
}
static inline float appm__comp(appm__v3 a, int i) { return i == 0 ? a.x : (i == 1 ? a.y : a.z); }
static inline float appm__maxc(appm__v3 a)
{
    float m = a.x > a.y ? a.x : a.y;
    return m > a.z ? m : a.z;
}
static inline int appm__finite3(appm__v3 a)
{
    return a.x - a.x == 0.0f && a.y - a.y == 0.0f && a.z - a.z == 0.0f; /* false for NaN, inf */
}
/* A static function that only the tests call (some builds would warn of it). */
#if defined(__GNUC__) || defined(__clang__)
#define APPM__UNUSED __attribute__((unused))
#else
#define APPM__UNUSED
#endif
/* Rec. 709 luminance: the scalar the adaptive statistics work with. */
static inline float appm__lum(appm__v3 c) { return 0.2126f * c.x + 0.7152f * c.y + 0.0722f * c.z; }
static inline double appm__lumd(const double *c) { return 0.2126 * c[0] + 0.7152 * c[1] + 0.0722 * c[2]; }

/* Inverts the piecewise-constant CDF c[0..n] (c[0] = 0, c[n] = 1, strictly
 * increasing) at u in [0,1): the cell *i with c[i] <= u < c[i+1], and the point
 * (i + t) / n, t the position of u within the cell.  The cell is the last lo
 * in [0, n) with c[lo] <= u; appm__cdf_search finds it in [lo, lo + len), given
 * c[lo] <= u, by halving without a branch: which half u falls in is a coin
 * toss for the branch predictor (an environment map's 6 + 7 of them were 7 %
 * of a render of the bare bunny). */
static int appm__cdf_search(const double *c, int lo, int len, double u)
{
    while (len > 1) {
        const int half = len / 2;
        lo = c[lo + half] <= u ? lo + half : lo;
        len -= half;
    }
    return lo;
}

/* The point (lo + t) / n of appm__cdf_invert, for u in cell lo. */
static float appm__cdf_point(const double *c, int n, int lo, double u, int *cell)
{
    double t = (u - c[lo]) / (c[lo + 1] - c[lo]), x;
    t = t < 0.0 ? 0.0 : (t > 1.0 ? 1.0 : t);
    x = ((double)lo + t) / (double)n;
    *cell = lo;
    return (float)x < 1.0f ? (float)x : 0.99999994f;
}

static float appm__cdf_invert(const double *c, int n, float u, int *cell)
{
    return appm__cdf_point(c, n, appm__cdf_search(c, 0, n, (double)u), (double)u, cell);
}

/* A guide table (Chen and Asau 1974) for the same search: g[k] is the cell of
 * u = k / APPM__CDF_G, k = 0 .. APPM__CDF_G.  The cell is monotone in u, so u
 * in [k, k + 1) / APPM__CDF_G lies in a cell of g[k] .. g[k + 1], and the
 * search there finds the very cell (and point) the whole search finds, in a
 * cache line or two of c instead of log2 n loads across it, each waiting on
 * the last: an environment map's 49 product densities (3 MB of CDFs) missed
 * the cache on them, 10 % of a render of the bare bunny. */
#define APPM__CDF_G 32
static void appm__cdf_guide(const double *c, int n, uint32_t *g)
{
    int k;
    for (k = 0; k <= APPM__CDF_G; ++k) g[k] = (uint32_t)appm__cdf_search(c, 0, n, (double)k / APPM__CDF_G);
}

/* appm__cdf_invert with guide g (NULL, or u outside [0, 1): the whole search). */
static float appm__cdf_invert_guided(const double *c, int n, const uint32_t *g, float u, int *cell)
{
    int k, lo;
    if (!g || !(u >= 0.0f && u < 1.0f)) return appm__cdf_invert(c, n, u, cell);
    k = (int)(u * (float)APPM__CDF_G); /* exact: a power of 2 */
    lo = (int)g[k];
    return appm__cdf_point(c, n, appm__cdf_search(c, lo, (int)g[k + 1] - lo + 1, (double)u), (double)u, cell);
}

/* Orthonormal basis (t, b) around unit n without a branch on a "pick an axis"
 * heuristic (Duff et al., "Building an Orthonormal Basis, Revisited", 2017). */
static void appm__basis(appm__v3 n, appm__v3 *t, appm__v3 *b)
{
    float sign = n.z >= 0.0f ? 1.0f : -1.0f;
    float a = -1.0f / (sign + n.z);
    float c = n.x * n.y * a;
    *t = appm__v(1.0f + sign * n.x * n.x * a, sign * c, -sign * n.x);
    *b = appm__v(c, sign + n.y * n.y * a, -n.y);
}

/* ---- 2.2 Random streams ----------------------------------------------------
 *
 * PCG32 (O'Neill 2014): 64-bit state, 32-bit output, a stream selector.  Every
 * pixel and every photon path gets its own generator seeded from
 * (seed, pass, domain, index) through the SplitMix64 finaliser, so a sample
 * never depends on which thread drew it or in which order.                   */
typedef struct appm__rng {
    uint64_t state, inc;
} appm__rng;

static uint64_t appm__mix64(uint64_t z)
{
    z += 0x9E3779B97F4A7C15ull;
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
    return z ^ (z >> 31);
}

static uint32_t appm__rng_u32(appm__rng *r)
{
    uint64_t old = r->state;
    uint32_t xorshifted, rot;
    r->state = old * 6364136223846793005ull + r->inc;
    xorshifted = (uint32_t)(((old >> 18) ^ old) >> 27);
    rot = (uint32_t)(old >> 59);
    return (xorshifted >> rot) | (xorshifted << ((32u - rot) & 31u));
}

enum { APPM__DOMAIN_EYE = 1, APPM__DOMAIN_PHOTON = 2, APPM__DOMAIN_TEST = 3, APPM__DOMAIN_PIXEL = 4 };

static void appm__rng_seed(appm__rng *r, uint64_t seed, uint64_t pass, uint64_t domain,
                           uint64_t index)
{
    uint64_t k = appm__mix64(seed ^ appm__mix64(pass * 8 + domain) ^ appm__mix64(~index));
    r->state = 0;
    r->inc = (appm__mix64(k ^ 0xDA942042E4DD58B5ull) << 1) | 1u;
    appm__rng_u32(r);
    r->state += k;
    appm__rng_u32(r);
}

/* Uniform in [0, 1): 24 random bits, so 1 - 2^-24 is the largest value and a
 * CDF lookup can never run past its end. */
static inline float appm__rng_float(appm__rng *r)
{
    return (float)(appm__rng_u32(r) >> 8) * (1.0f / 16777216.0f);
}

/* Three numbers in a fixed order.  (Several appm__rng_float() calls as the
 * arguments of one call would be drawn in an order C leaves unspecified, and
 * two compilers would render two different images from one seed.) */
static void appm__rng_float3(appm__rng *r, float *u)
{
    u[0] = appm__rng_float(r);
    u[1] = appm__rng_float(r);
    u[2] = appm__rng_float(r);
}

/* ---- 2.3 Low-discrepancy sampler ------------------------------------------
 *
 * The numbers of a path, in --sampler qmc, are the coordinates of one point of
 * a randomized low-discrepancy sequence: Sobol' (Joe & Kuo 2008), Owen-scrambled
 * and index-shuffled by hashing (Laine & Karras 2011; Burley 2020), padded.
 * The dimensions come in groups of four.  Each group is the 4-D Sobol' point
 * (dims 1-4 of Joe-Kuo's table: van der Corput and three polynomials) of a
 * shuffled index, each coordinate Owen-scrambled with its own seed; each group
 * shuffles with its own seed, so groups are mutually independent (padding), while
 * inside a group, and above all in its first two coordinates (a (0,2)-sequence),
 * the points are stratified.  Owen scrambling keeps that structure: every aligned
 * block of 2^k points of coordinates (0, 1) has exactly one point in each
 * elementary interval of area 2^-k, whatever the seed.
 *
 * The shuffle is an Owen scramble of the index itself (its most significant bit
 * first), so an aligned block of 2^k indices maps onto another aligned block:
 * a pixel's passes 0 .. 2^k - 1 always form a whole (0,k,2)-net.
 *
 * The sampler is stateless: a coordinate is a pure function of (key, index,
 * group, dimension), where key = (seed, chain, pixel) for eye paths and (seed,
 * chain) for photon paths.  Nothing carries from pass to pass but the pass
 * counter, which is all a checkpoint would need.  The layout of the dimensions
 * is in appm__smp_* below; past APPM__LD_VERTICES vertices a path draws from its
 * PCG stream (section 2.2), as does every path in --sampler random.          */

/* Direction numbers v_k = m_k 2^(32-k) of Sobol' dimensions 1-6.  Dimension 1 is
 * the identity (the radical inverse in base 2); 2-6 follow from Joe and Kuo's
 * primitive polynomials and initial m_k (new-joe-kuo-6.21201, d = 2 .. 6):
 *   d = 2: s = 1, a = 0, m = 1        d = 3: s = 2, a = 1, m = 1 3
 *   d = 4: s = 3, a = 1, m = 1 3 1    d = 5: s = 3, a = 2, m = 1 1 1
 *   d = 6: s = 4, a = 1, m = 1 1 3 3
 * by m_k = 2 a_1 m_(k-1) ^ ... ^ 2^(s-1) a_(s-1) m_(k-s+1) ^ 2^s m_(k-s) ^ m_(k-s)
 * (Bratley & Fox 1988).  t_sampler recomputes them from these parameters. */
static const uint32_t appm__sobol_v[6][32] = {
    {0x80000000u, 0x40000000u, 0x20000000u, 0x10000000u, 0x08000000u, 0x04000000u, 0x02000000u,
     0x01000000u, 0x00800000u, 0x00400000u, 0x00200000u, 0x00100000u, 0x00080000u, 0x00040000u,
     0x00020000u, 0x00010000u, 0x00008000u, 0x00004000u, 0x00002000u, 0x00001000u, 0x00000800u,
     0x00000400u, 0x00000200u, 0x00000100u, 0x00000080u, 0x00000040u, 0x00000020u, 0x00000010u,
     0x00000008u, 0x00000004u, 0x00000002u, 0x00000001u},
    {0x80000000u, 0xc0000000u, 0xa0000000u, 0xf0000000u, 0x88000000u, 0xcc000000u, 0xaa000000u,
     0xff000000u, 0x80800000u, 0xc0c00000u, 0xa0a00000u, 0xf0f00000u, 0x88880000u, 0xcccc0000u,
     0xaaaa0000u, 0xffff0000u, 0x80008000u, 0xc000c000u, 0xa000a000u, 0xf000f000u, 0x88008800u,
     0xcc00cc00u, 0xaa00aa00u, 0xff00ff00u, 0x80808080u, 0xc0c0c0c0u, 0xa0a0a0a0u, 0xf0f0f0f0u,
     0x88888888u, 0xccccccccu, 0xaaaaaaaau, 0xffffffffu},
    {0x80000000u, 0xc0000000u, 0x60000000u, 0x90000000u, 0xe8000000u, 0x5c000000u, 0x8e000000u,
     0xc5000000u, 0x68800000u, 0x9cc00000u, 0xee600000u, 0x55900000u, 0x80680000u, 0xc09c0000u,
     0x60ee0000u, 0x90550000u, 0xe8808000u, 0x5cc0c000u, 0x8e606000u, 0xc5909000u, 0x6868e800u,
     0x9c9c5c00u, 0xeeee8e00u, 0x5555c500u, 0x8000e880u, 0xc0005cc0u, 0x60008e60u, 0x9000c590u,
     0xe8006868u, 0x5c009c9cu, 0x8e00eeeeu, 0xc5005555u},
    {0x80000000u, 0xc0000000u, 0x20000000u, 0x50000000u, 0xf8000000u, 0x74000000u, 0xa2000000u,
     0x93000000u, 0xd8800000u, 0x25400000u, 0x59e00000u, 0xe6d00000u, 0x78080000u, 0xb40c0000u,
     0x82020000u, 0xc3050000u, 0x208f8000u, 0x51474000u, 0xfbea2000u, 0x75d93000u, 0xa0858800u,
     0x914e5400u, 0xdbe79e00u, 0x25db6d00u, 0x58800080u, 0xe54000c0u, 0x79e00020u, 0xb6d00050u,
     0x800800f8u, 0xc00c0074u, 0x200200a2u, 0x50050093u},
    {0x80000000u, 0x40000000u, 0x20000000u, 0xb0000000u, 0xf8000000u, 0xdc000000u, 0x7a000000u,
     0x9d000000u, 0x5a800000u, 0x2fc00000u, 0xa1600000u, 0xf0b00000u, 0xda880000u, 0x6fc40000u,
     0x81620000u, 0x40bb0000u, 0x22878000u, 0xb3c9c000u, 0xfb65a000u, 0xddb2d000u, 0x78022800u,
     0x9c0b3c00u, 0x5a0fb600u, 0x2d0ddb00u, 0xa2878080u, 0xf3c9c040u, 0xdb65a020u, 0x6db2d0b0u,
     0x800228f8u, 0x400b3cdcu, 0x200fb67au, 0xb00ddb9du},
    {0x80000000u, 0x40000000u, 0x60000000u, 0x30000000u, 0xc8000000u, 0x24000000u, 0x56000000u,
     0xfb000000u, 0xe0800000u, 0x70400000u, 0xa8600000u, 0x14300000u, 0x9ec80000u, 0xdf240000u,
     0xb6d60000u, 0x8bbb0000u, 0x48008000u, 0x64004000u, 0x36006000u, 0xcb003000u, 0x2880c800u,
     0x54402400u, 0xfe605600u, 0xef30fb00u, 0x7e48e080u, 0xaf647040u, 0x1eb6a860u, 0x9f8b1430u,
     0xd6c81ec8u, 0xbb249f24u, 0x80d6d6d6u, 0x40bbbbbbu}
};

/* Bit reversal, rev.  The Owen scramble of a 32-bit fraction x / 2^32 (most
 * significant digit first) is owen(x, seed) = rev(appm__lk_permute(rev(x), seed)). */
static inline uint32_t appm__reverse32(uint32_t x)
{
    x = ((x >> 1) & 0x55555555u) | ((x & 0x55555555u) << 1);
    x = ((x >> 2) & 0x33333333u) | ((x & 0x33333333u) << 2);
    x = ((x >> 4) & 0x0F0F0F0Fu) | ((x & 0x0F0F0F0Fu) << 4);
    x = ((x >> 8) & 0x00FF00FFu) | ((x & 0x00FF00FFu) << 8);
    return (x >> 16) | (x << 16);
}

/* A seeded permutation of 32-bit words in which output bit k depends only on
 * input bits 0..k: adding, multiplying by an odd number and x ^= x * even all
 * move information towards the high bits only, and each is a bijection of the
 * low k bits for every k (the Laine-Karras construction, with the operations
 * and constants of Vegdahl's improved hash, 2021: ten operations).  Read with
 * the bits reversed, that is a nested (Owen) scramble: digit k of the result is
 * digit k of x flipped by a function of digits 1..k-1.  A hash, not Owen's
 * fully random tree, so its randomness is tested, not assumed (t_sampler). */
static inline uint32_t appm__lk_permute(uint32_t x, uint32_t seed)
{
    x ^= x * 0x3D20ADEAu;
    x += seed;
    x *= (seed >> 16) | 1u;
    x ^= x * 0x05526C56u;
    x ^= x * 0x53A22864u;
    return x;
}

/* The fast form of owen(sobol(owen(index, s0), d), s_d), the coordinate below.
 * Sobol' is linear over the bits of its index, so a point is the XOR of the
 * points of the index's four bytes, and the reversals inside both scrambles can
 * be folded into a table: with ir = lk(rev(index), s0) (so the shuffled index is
 * rev(ir)) and y = rev(sobol(rev(ir), d)) = XOR over the bytes v_b of ir of
 *   T_d[b][v_b] = rev(sobol(rev(v_b << 8b), d)),
 * the coordinate is rev(lk(y, s_d)).  4 lookups and 2 reversals instead of a
 * loop over 32 bits (the shuffled index has all 32 set) and 4 reversals.  The
 * entries of dimensions 2p and 2p + 1 share one 64-bit word (low and high
 * half), so the 4 lookups serve a pair of dimensions: a 2-D sample (a pixel, a
 * point on a light, a direction) costs one set of lookups.  The last reversal
 * and the conversion to a float are one more set of lookups: the top 24 bits of
 * rev(z) are the low 24 bits of z reversed, so the coordinate is
 *   rev(z_0) 2^-8 + rev(z_1) 2^-16 + rev(z_2) 2^-24
 * for the low three bytes z_0, z_1, z_2 of z (byte reversal rev), a sum of
 * floats with disjoint bits, hence exact: the same float as (top 24 bits) 2^-24.
 * Pairs 0 and 1 serve every group, pair 2 only the group with six dimensions.
 * Filled once per renderer (27 KiB); the sampler keeps rev(index) of its
 * path. */
#define APPM__LD_PAIRS 3
typedef struct appm__sobol_tab {
    uint64_t pair[APPM__LD_PAIRS][4][256]; /* T_2p | T_(2p+1) << 32, by byte position */
    float rev[3][256];                     /* rev(v) 2^-8, 2^-16, 2^-24 */
} appm__sobol_tab;

static void appm__sobol_table(appm__sobol_tab *tab)
{
    unsigned p, b, v;
    for (v = 0; v < 256; ++v) {
        float r = (float)(appm__reverse32(v) >> 24);
        tab->rev[0][v] = r * (1.0f / 256.0f);
        tab->rev[1][v] = r * (1.0f / 65536.0f);
        tab->rev[2][v] = r * (1.0f / 16777216.0f);
    }
    /* Sobol' is linear over the bits of its index, and so is T: the entry of a
     * byte is the XOR of the entries of its set bits.  Bit v of byte b is bit
     * 8b + v of ir, so bit j = 31 - 8b - v of the index, whose point is the
     * direction number v_j; every other entry is the XOR of two earlier ones. */
    for (p = 0; p < APPM__LD_PAIRS; ++p)
        for (b = 0; b < 4; ++b) {
            uint64_t *t = tab->pair[p][b];
            t[0] = 0;
            for (v = 0; v < 8; ++v) {
                const unsigned j = 31 - 8 * b - v;
                t[1u << v] = appm__reverse32(appm__sobol_v[2 * p][j]) |
                             (uint64_t)appm__reverse32(appm__sobol_v[2 * p + 1][j]) << 32;
            }
            for (v = 3; v < 256; ++v)
                if (v & (v - 1)) t[v] = t[v & (v - 1)] ^ t[v & (0u - v)];
        }
}

/* The Owen scramble rev(lk(y, s)) as a float in [0, 1) with 24 bits. */
static inline float appm__ld_out(const appm__sobol_tab *tab, uint32_t y, uint32_t s)
{
    uint32_t z = appm__lk_permute(y, s);
    return tab->rev[0][z & 255] + tab->rev[1][(z >> 8) & 255] + tab->rev[2][(z >> 16) & 255];
}

/* Bytes 0-2 of the table sum of pair p (the XOR of T_2p, T_2p+1 over the low
 * three bytes of ir); with the entry of byte 3 it is the whole sum y. */
static inline uint64_t appm__ld_low(const appm__sobol_tab *tab, unsigned p, uint32_t ir)
{
    const uint64_t(*t)[256] = tab->pair[p];
    return t[0][ir & 255] ^ t[1][(ir >> 8) & 255] ^ t[2][(ir >> 16) & 255];
}

/* The table sum y of pair p for the shuffled, reversed index ir. */
static inline uint64_t appm__ld_y(const appm__sobol_tab *tab, unsigned p, uint32_t ir)
{
    return appm__ld_low(tab, p, ir) ^ tab->pair[p][3][ir >> 24];
}

/* Coordinates 2p, 2p + 1 (bits 0, 1 of mask) from the pair's table sum y,
 * scrambled with seeds s and s + 0x9E3779B9, into u[0], u[1]. */
static inline void appm__ld_pair(const appm__sobol_tab *tab, uint64_t y, uint32_t s, unsigned mask, float *u)
{
    if (mask & 1u) u[0] = appm__ld_out(tab, (uint32_t)y, s);
    if (mask & 2u) u[1] = appm__ld_out(tab, (uint32_t)(y >> 32), s + 0x9E3779B9u);
}

/* The hash g of group `group` of the sequence `key`: its low half seeds the
 * index shuffle, its high half s the scrambles of its coordinates. */
static inline uint64_t appm__ld_group(uint64_t key, unsigned group)
{
    return appm__mix64(key ^ ((uint64_t)(group + 1) * 0xD1B54A32D192ED03ull));
}

/* The coordinates in `mask` (bit d: dimension d, 0..5) of group `group` of
 * point `index` of the sequence `key`, in [0, 1) with 24 bits (as
 * appm__rng_float); the others are left as they are.  One shuffle of the index
 * per group, one scramble seed per coordinate (s_d = s + d 0x9E3779B9).  Equal
 * to owen(sobol(owen(index, s0), d), s_d) (t_sampling checks); only the
 * coordinates a path will read are computed (a mirror reads none, a point light
 * no point on it), and a pair's lookups only when one of its two is read. */
static void appm__ld(const appm__sobol_tab *tab, uint64_t key, uint32_t rindex, unsigned group,
                     unsigned mask, float *u)
{
    uint64_t g = appm__ld_group(key, group);
    uint32_t ir = appm__lk_permute(rindex, (uint32_t)g), s = (uint32_t)(g >> 32);
    if (mask & 3u) appm__ld_pair(tab, appm__ld_y(tab, 0, ir), s, mask, u);
    if (mask & 12u) appm__ld_pair(tab, appm__ld_y(tab, 1, ir), s + 2u * 0x9E3779B9u, mask >> 2, u + 2);
    if (mask & 48u) appm__ld_pair(tab, appm__ld_y(tab, 2, ir), s + 4u * 0x9E3779B9u, mask >> 4, u + 4);
}

/* Independently scrambled chains of passes (cfg.chains = K): pass j (1-based)
 * belongs to chain (j - 1) mod K and is point (j - 1) / K of that chain's
 * sequences.  The chains are independent randomizations of one integral, so the
 * spread of their means is an honest error estimate (section 10), which the
 * spread of correlated successive passes is not.  The price: each chain is K
 * times shorter, its nets K times coarser, and a scrambled net's advantage
 * grows with its size: measured at 256 passes, 4 chains lost half or more of
 * what the sequence gains on the diffuse boxes (bench/sampler.sh).  So the
 * default is one chain (the best image), and K >= 2 is asked for when an
 * honest estimate matters. */
#define APPM__MAX_CHAINS 64
#define APPM__LD_VERTICES 8 /* path vertices with low-discrepancy numbers */

enum { APPM__DOMAIN_LD_EYE = 5, APPM__DOMAIN_LD_PHOTON = 6 };

/* What the photon paths of one pass share, kept by the worker that traces a
 * run of them.  All of a pass's paths are points of one sequence (one key, as
 * long as the point number n = q M + i stays below the next multiple of 2^32),
 * so the group hashes g are the same for all and are computed once.  And the
 * shuffle is an Owen scramble: the low 24 bits of ir depend only on the low 24
 * bits of rindex, the bit-reversed high 24 bits of n, which 256 consecutive
 * points share; so for such a run the lookups of bytes 0-2 (appm__ld_low) are
 * made once a pair and group, and a point costs one lookup a pair.  Same
 * numbers as appm__ld (t_sampler checks). */
#define APPM__LD_GROUPS (2u * APPM__LD_VERTICES + 2u) /* groups 0 .. APPM__G_BSDF(LD_VERTICES - 1) */
typedef struct appm__ld_cache {
    uint64_t kin, key;                             /* key = mix64(kin), of g; valid only if `set` */
    int set;
    uint64_t g[APPM__LD_GROUPS];                   /* appm__ld_group(key, group) */
    uint32_t tag[APPM__LD_GROUPS][APPM__LD_PAIRS]; /* rindex & 0xFFFFFF of `low`; 2^32 - 1: none */
    uint64_t low[APPM__LD_GROUPS][APPM__LD_PAIRS];
} appm__ld_cache;

/* appm__ld for the sequence of the cache's key. */
static void appm__ld_cached(const appm__sobol_tab *tab, appm__ld_cache *c, uint32_t rindex, unsigned group,
                            unsigned mask, float *u)
{
    uint64_t g = c->g[group];
    uint32_t ir = appm__lk_permute(rindex, (uint32_t)g), s = (uint32_t)(g >> 32), t = rindex & 0xFFFFFFu;
    unsigned p;
    for (p = 0; p < APPM__LD_PAIRS; ++p, mask >>= 2, u += 2, s += 2u * 0x9E3779B9u) {
        if (!(mask & 3u)) continue;
        if (c->tag[group][p] != t) {
            c->tag[group][p] = t;
            c->low[group][p] = appm__ld_low(tab, p, ir);
        }
        appm__ld_pair(tab, c->low[group][p] ^ tab->pair[p][3][ir >> 24], s, mask, u);
    }
}

/* The key mix64(kin), with c made to hold its hashes (nothing to do when it
 * does). */
static uint64_t appm__ld_cache_key(appm__ld_cache *c, uint64_t kin)
{
    unsigned k, p;
    if (c->set && c->kin == kin) return c->key;
    c->kin = kin;
    c->key = appm__mix64(kin);
    c->set = 1;
    for (k = 0; k < APPM__LD_GROUPS; ++k) {
        c->g[k] = appm__ld_group(c->key, k);
        for (p = 0; p < APPM__LD_PAIRS; ++p) c->tag[k][p] = 0xFFFFFFFFu;
    }
    return c->key;
}

/* The numbers of one path: a sequence key and index (qmc), and the path's PCG
 * stream (random mode, and beyond the layout).  In qmc mode the stream is
 * seeded when first asked for (appm__smp_stream): most paths never get past the
 * layout, and seeding costs four hashes a path. */
typedef struct appm__sampler {
    appm__rng rng;
    const appm__sobol_tab *tab;
    appm__ld_cache *cache; /* NULL, or the hashes of key (photon paths) */
    uint64_t key;
    uint32_t rindex;  /* the point of the sequence, bit-reversed (appm__ld) */
    uint32_t ir0, s0; /* eye paths: group 0's shuffled index and seed (appm__ld) */
    int qmc;
    int seeded;                      /* rng is seeded from (seed, pass, domain, stream) */
    uint64_t seed, pass, stream;
    unsigned domain;
} appm__sampler;

static void appm__smp_init(appm__sampler *s, const appm__sobol_tab *tab, uint64_t seed, uint64_t pass,
                           unsigned domain, uint64_t stream)
{
    s->tab = tab;
    s->cache = NULL;
    s->qmc = tab != NULL;
    s->seed = seed;
    s->pass = pass;
    s->domain = domain;
    s->stream = stream;
    s->seeded = 0;
    if (!s->qmc) {
        appm__rng_seed(&s->rng, seed, pass, domain, stream);
        s->seeded = 1;
    }
}

static appm__rng *appm__smp_stream(appm__sampler *s)
{
    if (!s->seeded) {
        appm__rng_seed(&s->rng, s->seed, s->pass, s->domain, s->stream);
        s->seeded = 1;
    }
    return &s->rng;
}

/* Eye path of pixel `pixel` in pass `pass` (or the path tracer's path); qmc
 * when tab (appm__sobol_table) is given, with `chains` chains (>= 1).  The PCG
 * stream is the one every earlier version used, so --sampler random renders the
 * same bytes as before. */
static void appm__sampler_eye(appm__sampler *s, const appm__sobol_tab *tab, unsigned chains, uint64_t seed,
                              uint64_t pass, uint64_t pixel)
{
    uint64_t p0 = pass > 0 ? pass - 1 : 0, chain = 0;
    appm__smp_init(s, tab, seed, pass, APPM__DOMAIN_EYE, pixel);
    if (!s->qmc) return;
    if (chains > 1) { /* (a 64-bit division costs more than the rest together) */
        chain = p0 % chains;
        p0 /= chains;
    }
    /* one hash of the pixel, one of the whole (the per-group hash of appm__ld
     * follows) */
    s->key = appm__mix64(seed ^ (chain * 8 + APPM__DOMAIN_LD_EYE) * 0x9E3779B97F4A7C15ull ^
                         appm__mix64(~pixel));
    s->rindex = appm__reverse32((uint32_t)p0);
    /* group 0 serves the camera and the first vertex's choice (appm__smp_bsdf) */
    {
        uint64_t g = appm__ld_group(s->key, 0);
        s->ir0 = appm__lk_permute(s->rindex, (uint32_t)g);
        s->s0 = (uint32_t)(g >> 32);
    }
}

/* Photon path i of pass `pass`, M paths a pass: point q M + i of its chain's
 * sequence, q the pass's place in the chain, so the photons of all passes
 * together fill the light's sample space as one low-discrepancy set (Keller et
 * al. 2011).  Past 2^32 points the sequence continues with a fresh key.  cache:
 * NULL, or one that the paths a worker traces in turn share (appm__ld_cache;
 * the numbers are the same either way). */
static void appm__sampler_photon(appm__sampler *s, const appm__sobol_tab *tab, appm__ld_cache *cache,
                                 unsigned chains, uint64_t seed, uint64_t pass, uint64_t M, uint64_t i)
{
    uint64_t p0 = pass > 0 ? pass - 1 : 0, chain = 0, n, kin;
    appm__smp_init(s, tab, seed, pass, APPM__DOMAIN_PHOTON, i);
    if (!s->qmc) return;
    if (chains > 1) {
        chain = p0 % chains;
        p0 /= chains;
    }
    n = p0 * M + i;
    kin = seed ^ (chain * 8 + APPM__DOMAIN_LD_PHOTON) * 0x9E3779B97F4A7C15ull ^ (n >> 32) * 0xC2B2AE3D27D4EB4Full;
    s->cache = cache;
    s->key = cache ? appm__ld_cache_key(cache, kin) : appm__mix64(kin);
    s->rindex = appm__reverse32((uint32_t)n);
}

/* The dimension layout (groups of four or six; b = the path's vertex, 0 at its
 * first hit; vertices from APPM__LD_VERTICES on draw from the PCG stream):
 *   eye path     group 0: pixel (dims 0, 1), lens (2, 3), the component or
 *                Fresnel choice at vertex 0 (4; in place of dim 2 of group 3)
 *   photon path  group 0: emission position and direction (dims 0-3, see
 *                appm__emit), the light (dim 4)
 *   vertex b     group 2 + 2b: point on the light (dims 0, 1), light choice (2)
 *                group 3 + 2b: BSDF direction (0, 1), component or Fresnel
 *                choice (2), Russian roulette (3)
 * The six-dimensional group samples jointly what one integral couples: where a
 * photon leaves and from which light, so the photons of each light are still
 * spread over its surface and directions, a subset of one net rather than an
 * independent pairing.  Its extra dimension is Joe-Kuo's 5: 1-D stratified,
 * with 2-D projections on 1-4 of t <= 3 up to 2^12 points (t_sampler), not 0;
 * position and direction keep dims 1-4.  The same coupling of an eye path's
 * first light point with its pixel (dims 5, 6 of group 0) was measured and
 * dropped: the point loses the (0,2)-net of a group of its own, and with it
 * 12 % more RMSE on the bunny under the sky at 256 passes (6 seeds; no gain
 * on the boxes or the teapot), for one index shuffle less per eye path.
 * The choice at an eye path's first vertex is different: it is 1-D, so in
 * group 0 it stays stratified by itself (dim 4 is Joe-Kuo's 5), and it is what
 * the pixel's position decides jointly with it at the edge of a highlight in
 * glass (the light's reflection, its image through the sphere).  There it took
 * 11 % of the sphere box's RMSE and 6 % of the defocused one's (6 seeds, 256
 * passes).
 * The masks say which coordinates the caller will read (the others are 0).  In
 * random mode each call draws all its numbers from the stream, in the order of
 * the output array (the order of every earlier version), whatever the mask. */
#define APPM__G_LIGHT(b) (2u + 2u * (b))
#define APPM__G_BSDF(b) (3u + 2u * (b))

/* Group `group` of the path's point (appm__ld). */
static void appm__smp_ld(const appm__sampler *s, unsigned group, unsigned mask, float *u)
{
    if (s->cache)
        appm__ld_cached(s->tab, s->cache, s->rindex, group, mask, u);
    else
        appm__ld(s->tab, s->key, s->rindex, group, mask, u);
}

/* Next-event estimation at vertex b: u[0] picks the light, u[1], u[2] the
 * point on it.  mask: bit 0 for u[0], bit 1 for u[1] and u[2]. */
static void appm__smp_light(appm__sampler *s, unsigned b, unsigned mask, float *u)
{
    float v[4] = {0, 0, 0, 0};
    if (!s->qmc || b >= APPM__LD_VERTICES) {
        appm__rng_float3(appm__smp_stream(s), u);
        return;
    }
    appm__smp_ld(s, APPM__G_LIGHT(b), (mask & 1u ? 4u : 0u) | (mask & 2u ? 3u : 0u), v);
    u[0] = v[2];
    u[1] = v[0];
    u[2] = v[1];
}

/* BSDF sampling at vertex b: u[0], u[1] the direction, u[2] the component;
 * mask from appm__bsdf_dims (bit k: u[k]), plus bit 3 when the Russian
 * roulette of this vertex will most likely be asked for (computed with the
 * rest: one index shuffle).  u holds 4 floats. */
static void appm__smp_bsdf(appm__sampler *s, unsigned b, unsigned mask, float *u)
{
    if (!s->qmc || b >= APPM__LD_VERTICES) {
        appm__rng_float3(appm__smp_stream(s), u);
        return;
    }
    u[0] = u[1] = u[2] = u[3] = 0.0f;
    if (b == 0 && s->domain == APPM__DOMAIN_EYE && (mask & 4u)) {
        appm__ld_pair(s->tab, appm__ld_y(s->tab, 2, s->ir0), s->s0 + 4u * 0x9E3779B9u, 1u, u + 2);
        mask &= ~4u;
        if (!mask) return; /* glass: nothing more */
    }
    appm__smp_ld(s, APPM__G_BSDF(b), mask, u);
}

/* Russian roulette after vertex b; u and mask: as given to appm__smp_bsdf. */
static float appm__smp_rr(appm__sampler *s, unsigned b, unsigned mask, const float *u)
{
    float v[4];
    if (!s->qmc || b >= APPM__LD_VERTICES) return appm__rng_float(appm__smp_stream(s));
    if (mask & 8u) return u[3];
    appm__smp_ld(s, APPM__G_BSDF(b), 8u, v);
    return v[3];
}

/* Photon emission: u[0] picks the light, u[1..4] position and direction.
 * mask: bit 0 for u[0], bit 1 for u[1], u[2], bit 2 for u[3], u[4]. */
static void appm__smp_emit(appm__sampler *s, unsigned mask, float *u)
{
    float v[6] = {0, 0, 0, 0, 0, 0};
    int k;
    if (!s->qmc) {
        for (k = 0; k < 5; ++k) u[k] = appm__rng_float(&s->rng);
        return;
    }
    appm__smp_ld(s, 0, (mask & 1u ? 16u : 0u) | (mask & 2u ? 3u : 0u) | (mask & 4u ? 12u : 0u), v);
    u[0] = v[4];
    for (k = 0; k < 4; ++k) u[k + 1] = v[k];
}

/* Camera (qmc only; random mode keeps its rotated R2 sequence, section 8.1). */
static void appm__smp_camera(const appm__sampler *s, int lens, float *u)
{
    appm__ld_pair(s->tab, appm__ld_y(s->tab, 0, s->ir0), s->s0, 3u, u);
    if (lens) appm__ld_pair(s->tab, appm__ld_y(s->tab, 1, s->ir0), s->s0 + 2u * 0x9E3779B9u, 3u, u + 2);
}

/* ==== 3. IMAGE I/O =======================================================
 *
 * PFM (linear float): header "PF\n<w> <h>\n<scale>\n", then rows from the
 * BOTTOM of the picture to the top; a negative scale means little-endian floats.
 * We write the host's byte order (found with memcpy, not pointer punning) and
 * read either.  PPM (P6) and PNG are 8-bit sRGB after an exposure multiply;
 * OpenEXR is linear float or half.  PNG and ZIP-compressed EXR use the deflate
 * compressor of 3.1 (no zlib): CRC-32 per PNG chunk, Adler-32 over each zlib
 * stream.  Every writer
 * writes "<name>.tmp", flushes it to the disk and renames it, so a failed
 * write (or a crash) never leaves a half-written file under the final name (a
 * destination that exists and is not a regular file - /dev/stdout, a FIFO - is
 * written in place).  3.4 - 3.10 read what textures and environment maps come
 * in: PNG, JPEG, TGA, PPM/PGM, PFM, OpenEXR and Radiance HDR.
 */
static int appm__host_little_endian(void)
{
    const uint32_t one = 1u;
    unsigned char b;
    memcpy(&b, &one, 1);
    return b == 1;
}

/* The sRGB transfer curve of x * exposure, clamped to [0,1], as a byte.  NaN
 * goes to 0; the clamp comes before the float-to-int conversion. */
static unsigned char appm__to_srgb8(float x, float exposure)
{
    float v = x * exposure;
    if (!(v > 0.0f)) return 0;
    if (v >= 1.0f) return 255;
    v = v <= 0.0031308f ? 12.92f * v : 1.055f * powf(v, 1.0f / 2.4f) - 0.055f;
    v = v * 255.0f + 0.5f;
    return (unsigned char)(v >= 255.0f ? 255.0f : v);
}

typedef struct appm__out {
    FILE *f;
    int ok;
    uint32_t crc;
} appm__out;

static void appm__put(appm__out *o, const void *p, size_t n)
{
    if (o->ok && n && fwrite(p, 1, n, o->f) != n) o->ok = 0;
}

/* CRC-32 (IEEE, reflected 0xEDB88320), four bits at a time from a constant
 * 16-entry table: no table built at run time, so no global mutable state. */
static uint32_t appm__crc32_update(uint32_t crc, const unsigned char *p, size_t n)
{
    static const uint32_t t[16] = {
        0x00000000u, 0x1DB71064u, 0x3B6E20C8u, 0x26D930ACu, 0x76DC4190u, 0x6B6B51F4u,
        0x4DB26158u, 0x5005713Cu, 0xEDB88320u, 0xF00F9344u, 0xD6D6A3E8u, 0xCB61B38Cu,
        0x9B64C2B0u, 0x86D3D2D4u, 0xA00AE278u, 0xBDBDF21Cu};
    size_t i;
    for (i = 0; i < n; ++i) {
        crc ^= p[i];
        crc = (crc >> 4) ^ t[crc & 15u];
        crc = (crc >> 4) ^ t[crc & 15u];
    }
    return crc;
}

static void appm__put_crc(appm__out *o, const void *p, size_t n)
{
    o->crc = appm__crc32_update(o->crc, (const unsigned char *)p, n);
    appm__put(o, p, n);
}

static void appm__be32(unsigned char *b, uint32_t v)
{
    b[0] = (unsigned char)(v >> 24);
    b[1] = (unsigned char)(v >> 16);
    b[2] = (unsigned char)(v >> 8);
    b[3] = (unsigned char)v;
}

static void appm__png_chunk_begin(appm__out *o, const char *type, uint32_t len)
{
    unsigned char b[4];
    appm__be32(b, len);
    appm__put(o, b, 4);
    o->crc = 0xFFFFFFFFu;
    appm__put_crc(o, type, 4);
}

static void appm__png_chunk_end(appm__out *o)
{
    unsigned char b[4];
    appm__be32(b, o->crc ^ 0xFFFFFFFFu);
    appm__put(o, b, 4);
}

/* Converts row y to sRGB bytes piece by piece through a stack buffer (no heap
 * use at all) and hands each piece to `emit`. */
#define APPM__ROW_PIECE 256
typedef void (*appm__emit_fn)(void *ctx, const unsigned char *p, size_t n);

static void appm__emit_srgb_row(const appm_image *img, uint32_t y, float exposure,
                                appm__emit_fn emit, void *ctx)
{
    unsigned char buf[3 * APPM__ROW_PIECE];
    uint32_t x = 0;
    while (x < img->width) {
        uint32_t n = img->width - x < APPM__ROW_PIECE ? img->width - x : APPM__ROW_PIECE, i;
        for (i = 0; i < n; ++i) {
            const float *p = img->rgb + 3 * ((size_t)y * img->width + x + i);
            buf[3 * i] = appm__to_srgb8(p[0], exposure);
            buf[3 * i + 1] = appm__to_srgb8(p[1], exposure);
            buf[3 * i + 2] = appm__to_srgb8(p[2], exposure);
        }
        emit(ctx, buf, (size_t)n * 3);
        x += n;
    }
}

static void appm__emit_plain(void *ctx, const unsigned char *p, size_t n)
{
    appm__put((appm__out *)ctx, p, n);
}

/* ---- 3.1 Deflate (RFC 1951) inside a zlib stream (RFC 1950) ----------------
 *
 * A streaming compressor in bounded memory, allocated once per file: a 64 KiB
 * window (two halves of 32 KiB; when the second fills, it slides down and the
 * hash positions with it), hash chains over 3-byte prefixes, lazy matching as in
 * zlib's deflate_slow (a match at p is emitted only if p + 1 does not start a
 * longer one), and blocks of up to APPM__Z_SYMS symbols.  Each block is sent
 * with the cheaper of the fixed Huffman code and a dynamic one built from its
 * own symbol counts (lengths limited to 15 bits, code-length code to 7).  The
 * compressed bytes go to a sink in pieces of at most APPM__Z_OUT bytes (for a PNG,
 * one IDAT chunk each; for an EXR block, a memory buffer).
 */
#define APPM__Z_W 32768      /* window size: the farthest a match may reach back */
#define APPM__Z_MINM 3
#define APPM__Z_MAXM 258
#define APPM__Z_HASH 32768   /* hash buckets over the next 3 bytes */
#define APPM__Z_SYMS 16384   /* symbols per block */
#define APPM__Z_OUT 65536    /* compressed bytes per sink call */
/* Chain links followed per position (the effort): for PNG near zlib's level 9
 * (4096) in size at a fraction of its time; EXR float data gains little. */
#ifndef APPM__PNG_CHAIN
#define APPM__PNG_CHAIN 1024
#endif
#define APPM__EXR_CHAIN 64
#ifndef APPM__PNG_MINKEEP
#define APPM__PNG_MINKEEP 6
#endif
/* A match may reach back at most this far, so that a chain never follows a
 * prev[] slot already reused by a newer position (zlib's MAX_DIST). */
#define APPM__Z_MAXDIST (APPM__Z_W - APPM__Z_MAXM - APPM__Z_MINM - 1)

typedef void (*appm__sink_fn)(void *ctx, const unsigned char *p, size_t n);

typedef struct appm__zlib {
    unsigned char *win;   /* 2 W bytes: the window and the look-ahead */
    int32_t *head, *prev; /* newest position per hash; older position per slot (-1: none) */
    uint16_t *lit, *dist; /* the block's symbols: literal or length, and distance (0: literal) */
    unsigned char *out;   /* APPM__Z_OUT compressed bytes waiting for the sink */
    size_t fill, pos, nsym, nout;
    int have_prev;        /* lazy matching: the byte at pos - 1 is not yet emitted */
    unsigned prev_len, prev_dist;
    unsigned max_chain;   /* chain links followed per position: the effort */
    unsigned min_keep;    /* shorter matches are dropped (zlib's Z_FILTERED: 6) */
    uint64_t bits;        /* bit buffer, least significant bit first */
    unsigned nbits;
    uint32_t s1, s2;      /* Adler-32 halves of the uncompressed data */
    uint32_t fl[286], fd[30]; /* symbol counts of the current block */
    appm__sink_fn sink;
    void *ctx;
} appm__zlib;

static const uint16_t appm__len_base[29] = {3,  4,  5,  6,  7,  8,  9,  10, 11,  13,
                                            15, 17, 19, 23, 27, 31, 35, 43, 51,  59,
                                            67, 83, 99, 115, 131, 163, 195, 227, 258};
static const unsigned char appm__len_extra[29] = {0, 0, 0, 0, 0, 0, 0, 0, 1, 1, 1, 1, 2, 2, 2,
                                                  2, 3, 3, 3, 3, 4, 4, 4, 4, 5, 5, 5, 5, 0};
static const uint16_t appm__dist_base[30] = {1,    2,    3,    4,    5,    7,     9,     13,
                                             17,   25,   33,   49,   65,   97,    129,   193,
                                             257,  385,  513,  769,  1025, 1537,  2049,  3073,
                                             4097, 6145, 8193, 12289, 16385, 24577};
static const unsigned char appm__dist_extra[30] = {0, 0, 0, 0, 1, 1, 2, 2,  3,  3,  4,  4,  5,  5,  6,
                                                   6, 7, 7, 8, 8, 9, 9, 10, 10, 11, 11, 12, 12, 13, 13};

static unsigned appm__log2u(unsigned v)
{
    unsigned k = 0;
    while (v >>= 1) k++;
    return k;
}

/* Length 3..258 -> code index 0..28 (symbol 257 + index): four codes per
 * power of two above 10, each with log2 - 2 extra bits. */
static unsigned appm__len_code(unsigned len)
{
    unsigned l = len - 3, nb;
    if (len == 258) return 28;
    if (l < 8) return l;
    nb = appm__log2u(l);
    return 4 * (nb - 1) + ((l >> (nb - 2)) & 3u);
}

/* Distance 1..32768 -> code 0..29: two codes per power of two above 4. */
static unsigned appm__dist_code(unsigned dist)
{
    unsigned d = dist - 1, nb;
    if (d < 4) return d;
    nb = appm__log2u(d);
    return 2 * nb + ((d >> (nb - 1)) & 1u);
}

static appm_status appm__zlib_init(appm__zlib *z, appm__mem *m, unsigned max_chain, unsigned min_keep)
{
    memset(z, 0, sizeof *z);
    z->win = (unsigned char *)appm__alloc(m, 2 * APPM__Z_W, 1);
    z->head = (int32_t *)appm__alloc(m, APPM__Z_HASH, sizeof(int32_t));
    z->prev = (int32_t *)appm__alloc(m, APPM__Z_W, sizeof(int32_t));
    z->lit = (uint16_t *)appm__alloc(m, APPM__Z_SYMS, sizeof(uint16_t));
    z->dist = (uint16_t *)appm__alloc(m, APPM__Z_SYMS, sizeof(uint16_t));
    z->out = (unsigned char *)appm__alloc(m, APPM__Z_OUT, 1);
    z->max_chain = max_chain;
    z->min_keep = min_keep;
    return z->win && z->head && z->prev && z->lit && z->dist && z->out ? APPM_OK : APPM_ERR_NOMEM;
}

static void appm__zlib_release(appm__zlib *z, appm__mem *m)
{
    appm__free(m, z->win);
    appm__free(m, z->head);
    appm__free(m, z->prev);
    appm__free(m, z->lit);
    appm__free(m, z->dist);
    appm__free(m, z->out);
    memset(z, 0, sizeof *z);
}

static void appm__zlib_flush_out(appm__zlib *z)
{
    if (z->nout) z->sink(z->ctx, z->out, z->nout);
    z->nout = 0;
}

/* Appends the n low bits of v (n <= 32), first bit first. */
static void appm__zbits(appm__zlib *z, uint32_t v, unsigned n)
{
    z->bits |= (uint64_t)v << z->nbits;
    z->nbits += n;
    while (z->nbits >= 8) {
        z->out[z->nout++] = (unsigned char)z->bits;
        z->bits >>= 8;
        z->nbits -= 8;
        if (z->nout == APPM__Z_OUT) appm__zlib_flush_out(z);
    }
}

/* Starts a zlib stream: header 0x78 0xDA (deflate, 32K window, "best"
 * compression; 0x78DA is a multiple of 31), empty window, Adler-32 = 1. */
static void appm__zlib_begin(appm__zlib *z, appm__sink_fn sink, void *ctx)
{
    size_t i;
    z->sink = sink;
    z->ctx = ctx;
    z->fill = z->pos = z->nsym = z->nout = 0;
    z->have_prev = 0;
    z->bits = 0;
    z->nbits = 0;
    z->s1 = 1;
    z->s2 = 0;
    for (i = 0; i < APPM__Z_HASH; ++i) z->head[i] = -1;
    memset(z->fl, 0, sizeof z->fl);
    memset(z->fd, 0, sizeof z->fd);
    appm__zbits(z, 0x78, 8);
    appm__zbits(z, 0xDA, 8);
}

static void appm__zlib_adler(appm__zlib *z, const unsigned char *p, size_t n)
{
    while (n > 0) { /* 5552 bytes is the most before the sums could pass 2^32 (zlib's NMAX) */
        size_t k = n < 5552 ? n : 5552;
        n -= k;
        while (k--) {
            z->s1 += *p++;
            z->s2 += z->s1;
        }
        z->s1 %= 65521u;
        z->s2 %= 65521u;
    }
}

/* Huffman code lengths for the counts freq[0..n-1] (n <= 288), none longer
 * than maxbits; count 0 gets length 0.  Optimal lengths come from the
 * two-queue construction over the symbols sorted by count (leaves in one queue,
 * merged nodes, born in non-decreasing weight, in the other).  If the longest
 * exceeds maxbits, the excess is folded back as zlib and miniz do: clamp, then
 * repair the Kraft sum by moving one leaf down a level at a time, and deal the
 * lengths out again, the longest to the rarest symbols. */
static void appm__huff_lengths(const uint32_t *freq, unsigned n, unsigned maxbits, unsigned char *len)
{
    uint16_t sym[288], parent[2 * 288], depth[2 * 288];
    uint32_t w[2 * 288], kraft = 0;
    unsigned count[33], m = 0, i, k, leaf = 0, node, next;
    memset(len, 0, n);
    memset(count, 0, sizeof count);
    for (i = 0; i < n; ++i)
        if (freq[i]) sym[m++] = (uint16_t)i;
    if (m < 2) {
        if (m == 1) len[sym[0]] = 1;
        return;
    }
    for (i = 1; i < m; ++i) { /* stable insertion sort by count: ties keep symbol order */
        uint16_t s = sym[i];
        for (k = i; k > 0 && freq[sym[k - 1]] > freq[s]; --k) sym[k] = sym[k - 1];
        sym[k] = s;
    }
    for (i = 0; i < m; ++i) w[i] = freq[sym[i]];
    for (node = next = m; next < 2 * m - 1; ++next) {
        unsigned a = (leaf < m && (node >= next || w[leaf] <= w[node])) ? leaf++ : node++;
        unsigned b = (leaf < m && (node >= next || w[leaf] <= w[node])) ? leaf++ : node++;
        w[next] = w[a] + w[b];
        parent[a] = parent[b] = (uint16_t)next;
    }
    depth[2 * m - 2] = 0; /* the root; every parent has a larger index than its children */
    for (i = 2 * m - 2; i-- > 0;) depth[i] = (uint16_t)(depth[parent[i]] + 1);
    for (i = 0; i < m; ++i) count[depth[i] > 32 ? 32 : depth[i]]++;
    for (i = maxbits + 1; i <= 32; ++i) {
        count[maxbits] += count[i];
        count[i] = 0;
    }
    for (i = 1; i <= maxbits; ++i) kraft += (uint32_t)count[i] << (maxbits - i);
    while (kraft > (1u << maxbits)) { /* each step: one leaf fewer at maxbits, Kraft sum - 1 */
        count[maxbits]--;
        for (i = maxbits - 1; i > 0; --i)
            if (count[i]) {
                count[i]--;
                count[i + 1] += 2;
                break;
            }
        kraft--;
    }
    for (k = 0, i = maxbits; i >= 1; --i)
        for (leaf = count[i]; leaf > 0; --leaf) len[sym[k++]] = (unsigned char)i;
}

/* Canonical codes from lengths (RFC 1951, 3.2.2), bit-reversed because
 * deflate sends Huffman codes most significant bit first into an LSB-first
 * stream. */
static void appm__huff_codes(const unsigned char *len, unsigned n, uint16_t *code)
{
    unsigned count[16], next[16], i, c = 0;
    memset(count, 0, sizeof count);
    for (i = 0; i < n; ++i) count[len[i]]++;
    count[0] = 0;
    for (i = 1; i < 16; ++i) {
        c = (c + count[i - 1]) << 1;
        next[i] = c;
    }
    for (i = 0; i < n; ++i) {
        unsigned v, r = 0, b;
        code[i] = 0;
        if (!len[i]) continue;
        v = next[len[i]]++;
        for (b = 0; b < len[i]; ++b, v >>= 1) r = (r << 1) | (v & 1u);
        code[i] = (uint16_t)r;
    }
}

/* The code-length sequence of a dynamic block, run-length coded: 16 repeats
 * the previous length 3-6 times, 17 and 18 give 3-10 and 11-138 zeros.  Each
 * entry is symbol | extra-bits value << 5; fc counts the symbols. */
static unsigned appm__zrle(const unsigned char *lens, unsigned n, uint16_t *rle, uint32_t *fc)
{
    unsigned i = 0, m = 0, last = 99;
    while (i < n) {
        unsigned v = lens[i], run = 1, t;
        while (i + run < n && lens[i + run] == v) run++;
        if (v == 0 && run >= 3) {
            t = run > 138 ? 138 : run;
            rle[m++] = (uint16_t)(t >= 11 ? 18u | (t - 11) << 5 : 17u | (t - 3) << 5);
            fc[t >= 11 ? 18 : 17]++;
            last = 0;
        } else if (v != 0 && v == last && run >= 3) {
            t = run > 6 ? 6 : run;
            rle[m++] = (uint16_t)(16u | (t - 3) << 5);
            fc[16]++;
        } else {
            t = 1;
            rle[m++] = (uint16_t)v;
            fc[v]++;
            last = v;
        }
        i += t;
    }
    return m;
}

/* A dynamic block's code tables, and what it and the fixed code would cost. */
typedef struct appm__zplan {
    unsigned char ll[288], dl[30], cl[19]; /* 288: the fixed code's two unused symbols count too */
    uint16_t rle[316];
    unsigned hlit, hdist, hclen, nrle;
    uint64_t dyn_bits, fixed_bits;
} appm__zplan;

static const unsigned char appm__cl_order[19] = {16, 17, 18, 0, 8,  7, 9,  6, 10, 5,
                                                 11, 4,  12, 3, 13, 2, 14, 1, 15};

static unsigned appm__nonzero(const uint32_t *f, unsigned n)
{
    unsigned i, k = 0;
    for (i = 0; i < n; ++i) k += f[i] != 0;
    return k;
}

static void appm__zplan_make(appm__zlib *z, appm__zplan *pl)
{
    uint32_t fc[19];
    unsigned i;
    unsigned char lens[316];
    z->fl[256] = 1; /* end of block */
    /* Two used symbols at least per code, so that every code is complete (a
     * lone length-1 code is legal in some alphabets only); a dummy costs a few
     * header bits. */
    if (appm__nonzero(z->fl, 286) < 2) z->fl[0] += 1;
    if (appm__nonzero(z->fd, 30) == 1) z->fd[z->fd[0] ? 1 : 0] += 1;
    appm__huff_lengths(z->fl, 286, 15, pl->ll);
    appm__huff_lengths(z->fd, 30, 15, pl->dl);
    for (pl->hlit = 286; pl->hlit > 257 && pl->ll[pl->hlit - 1] == 0; --pl->hlit) {
    }
    for (pl->hdist = 30; pl->hdist > 1 && pl->dl[pl->hdist - 1] == 0; --pl->hdist) {
    }
    memcpy(lens, pl->ll, pl->hlit);
    memcpy(lens + pl->hlit, pl->dl, pl->hdist);
    memset(fc, 0, sizeof fc);
    pl->nrle = appm__zrle(lens, pl->hlit + pl->hdist, pl->rle, fc);
    if (appm__nonzero(fc, 19) < 2) fc[fc[0] ? 1 : 0] += 1;
    appm__huff_lengths(fc, 19, 7, pl->cl);
    for (pl->hclen = 19; pl->hclen > 4 && pl->cl[appm__cl_order[pl->hclen - 1]] == 0; --pl->hclen) {
    }
    pl->dyn_bits = 3 + 5 + 5 + 4 + 3 * (uint64_t)pl->hclen;
    pl->fixed_bits = 3;
    for (i = 0; i < pl->nrle; ++i) {
        unsigned s = pl->rle[i] & 31u;
        pl->dyn_bits += pl->cl[s] + (s == 16 ? 2u : s == 17 ? 3u : s == 18 ? 7u : 0u);
    }
    for (i = 0; i < 286; ++i) {
        unsigned extra = i >= 257 ? appm__len_extra[i - 257] : 0, fixed = i < 144 ? 8 : i < 256 ? 9 : i < 280 ? 7 : 8;
        pl->dyn_bits += (uint64_t)z->fl[i] * (pl->ll[i] + extra);
        pl->fixed_bits += (uint64_t)z->fl[i] * (fixed + extra);
    }
    for (i = 0; i < 30; ++i) {
        pl->dyn_bits += (uint64_t)z->fd[i] * (pl->dl[i] + appm__dist_extra[i]);
        pl->fixed_bits += (uint64_t)z->fd[i] * (5u + appm__dist_extra[i]);
    }
}

/* Sends the block's symbols and its end-of-block code. */
static void appm__zsend(appm__zlib *z, const unsigned char *ll, unsigned nll, const unsigned char *dl)
{
    uint16_t lc[288], dc[30];
    size_t i;
    appm__huff_codes(ll, nll, lc);
    appm__huff_codes(dl, 30, dc);
    for (i = 0; i < z->nsym; ++i) {
        unsigned v = z->lit[i], d = z->dist[i], c;
        if (d == 0) {
            appm__zbits(z, lc[v], ll[v]);
            continue;
        }
        c = appm__len_code(v);
        appm__zbits(z, lc[257 + c], ll[257 + c]);
        appm__zbits(z, v - appm__len_base[c], appm__len_extra[c]);
        c = appm__dist_code(d);
        appm__zbits(z, dc[c], dl[c]);
        appm__zbits(z, d - appm__dist_base[c], appm__dist_extra[c]);
    }
    appm__zbits(z, lc[256], ll[256]);
}

/* Ends the current block: dynamic or fixed code, whichever is shorter. */
static void appm__zblock(appm__zlib *z, int final)
{
    appm__zplan pl;
    unsigned i;
    appm__zplan_make(z, &pl);
    if (pl.dyn_bits < pl.fixed_bits) {
        uint16_t cc[19];
        appm__zbits(z, (uint32_t)final | 2u << 1, 3); /* BFINAL, BTYPE 2: dynamic */
        appm__zbits(z, pl.hlit - 257, 5);
        appm__zbits(z, pl.hdist - 1, 5);
        appm__zbits(z, pl.hclen - 4, 4);
        for (i = 0; i < pl.hclen; ++i) appm__zbits(z, pl.cl[appm__cl_order[i]], 3);
        appm__huff_codes(pl.cl, 19, cc);
        for (i = 0; i < pl.nrle; ++i) {
            unsigned s = pl.rle[i] & 31u;
            appm__zbits(z, cc[s], pl.cl[s]);
            if (s >= 16) appm__zbits(z, pl.rle[i] >> 5, s == 16 ? 2 : s == 17 ? 3 : 7);
        }
        appm__zsend(z, pl.ll, 286, pl.dl);
    } else { /* RFC 1951, 3.2.6: 8, 9, 7, 8 bits for literal/length ranges, 5 for distances */
        for (i = 0; i < 288; ++i) pl.ll[i] = (unsigned char)(i < 144 ? 8 : i < 256 ? 9 : i < 280 ? 7 : 8);
        for (i = 0; i < 30; ++i) pl.dl[i] = 5;
        appm__zbits(z, (uint32_t)final | 1u << 1, 3);
        appm__zsend(z, pl.ll, 288, pl.dl);
    }
    z->nsym = 0;
    memset(z->fl, 0, sizeof z->fl);
    memset(z->fd, 0, sizeof z->fd);
}

static void appm__zsym(appm__zlib *z, unsigned v, unsigned dist)
{
    z->lit[z->nsym] = (uint16_t)v;
    z->dist[z->nsym] = (uint16_t)dist;
    z->nsym++;
    if (dist == 0) {
        z->fl[v]++;
    } else {
        z->fl[257 + appm__len_code(v)]++;
        z->fd[appm__dist_code(dist)]++;
    }
    if (z->nsym == APPM__Z_SYMS) appm__zblock(z, 0);
}

static uint32_t appm__zhash(const unsigned char *p) /* Knuth's multiplicative hash of 3 bytes */
{
    uint32_t v = (uint32_t)p[0] | (uint32_t)p[1] << 8 | (uint32_t)p[2] << 16;
    return (v * 2654435761u) >> 17; /* 15 bits */
}

static void appm__zinsert(appm__zlib *z, size_t p)
{
    uint32_t h = appm__zhash(z->win + p);
    z->prev[p & (APPM__Z_W - 1)] = z->head[h];
    z->head[h] = (int32_t)p;
}

/* The longest match at p (already inserted) of more than `better` (and at
 * least min_keep) and at most maxlen bytes, following at most max_chain links
 * (a quarter of them when the match to beat is already long, as zlib's
 * good_length).  0 if none.  A candidate is first tested at the two bytes that
 * would make it longer than the best so far (zlib's scan_end), which rejects
 * most of them at once. */
static unsigned appm__zmatch(const appm__zlib *z, size_t p, unsigned maxlen, unsigned better,
                             unsigned *dist)
{
    const unsigned char *s = z->win + p;
    unsigned least = z->min_keep > APPM__Z_MINM ? z->min_keep - 1 : APPM__Z_MINM - 1; /* shorter: dropped anyway */
    unsigned best = better < least ? least : better, found = 0;
    unsigned chain = better >= 32 ? z->max_chain >> 2 : z->max_chain;
    int32_t c = z->prev[p & (APPM__Z_W - 1)];
    if (best >= maxlen) return 0;
    while (c >= 0 && p - (size_t)c <= APPM__Z_MAXDIST && chain-- > 0) {
        const unsigned char *q = z->win + c;
        if (q[best] == s[best] && q[best - 1] == s[best - 1] && q[0] == s[0] && q[1] == s[1]) {
            unsigned n = 2;
            while (n < maxlen && q[n] == s[n]) n++;
            if (n > best) {
                best = n;
                found = 1;
                *dist = (unsigned)(p - (size_t)c);
                if (n >= maxlen) break;
            }
        }
        c = z->prev[c & (APPM__Z_W - 1)];
    }
    return found ? best : 0;
}

/* LZ77 with lazy evaluation over the window: runs while more than a longest
 * match of look-ahead is there (or to the end when flushing).  Invariant
 * after a call without flush: fill - pos <= APPM__Z_MAXM. */
static void appm__zrun(appm__zlib *z, int flush)
{
    while (z->pos < z->fill && (flush || z->fill - z->pos > APPM__Z_MAXM)) {
        size_t p = z->pos, avail = z->fill - p;
        unsigned maxlen = avail < APPM__Z_MAXM ? (unsigned)avail : APPM__Z_MAXM, cur = 0, cdist = 0;
        if (avail >= APPM__Z_MINM) {
            appm__zinsert(z, p);
            cur = appm__zmatch(z, p, maxlen, z->have_prev ? z->prev_len : 0, &cdist);
            if (cur == APPM__Z_MINM && cdist > 4096) cur = 0; /* 3 bytes that far cost more than literals */
            if (cur < z->min_keep) cur = 0;
        }
        if (z->have_prev && z->prev_len >= APPM__Z_MINM && z->prev_len >= cur) {
            size_t end = p - 1 + z->prev_len, q;
            appm__zsym(z, z->prev_len, z->prev_dist);
            for (q = p + 1; q < end; ++q)
                if (z->fill - q >= APPM__Z_MINM) appm__zinsert(z, q);
            z->pos = end;
            z->have_prev = 0;
        } else {
            if (z->have_prev) appm__zsym(z, z->win[p - 1], 0);
            z->have_prev = 1;
            z->prev_len = cur;
            z->prev_dist = cdist;
            z->pos = p + 1;
        }
    }
    if (flush && z->have_prev) { /* a match there would have been emitted in the loop */
        appm__zsym(z, z->win[z->pos - 1], 0);
        z->have_prev = 0;
    }
}

/* Moves the upper half of the window down; positions move with it, and those
 * that fall out of the window become "none". */
static void appm__zslide(appm__zlib *z)
{
    size_t i;
    memcpy(z->win, z->win + APPM__Z_W, APPM__Z_W);
    z->fill -= APPM__Z_W;
    z->pos -= APPM__Z_W;
    for (i = 0; i < APPM__Z_HASH; ++i) z->head[i] = z->head[i] >= APPM__Z_W ? z->head[i] - APPM__Z_W : -1;
    for (i = 0; i < APPM__Z_W; ++i) z->prev[i] = z->prev[i] >= APPM__Z_W ? z->prev[i] - APPM__Z_W : -1;
}

static void appm__zlib_feed(appm__zlib *z, const unsigned char *p, size_t n)
{
    appm__zlib_adler(z, p, n);
    while (n > 0) {
        size_t take;
        if (z->fill == 2 * APPM__Z_W) appm__zslide(z); /* pos >= W here, by zrun's invariant */
        take = 2 * APPM__Z_W - z->fill;
        if (take > n) take = n;
        memcpy(z->win + z->fill, p, take);
        z->fill += take;
        p += take;
        n -= take;
        appm__zrun(z, 0);
    }
}

/* Ends the stream: the rest of the input, the final block, byte alignment, the
 * Adler-32 (most significant byte first). */
static void appm__zlib_end(appm__zlib *z)
{
    appm__zrun(z, 1);
    appm__zblock(z, 1);
    if (z->nbits) appm__zbits(z, 0, 8 - z->nbits);
    appm__zbits(z, z->s2 >> 8, 8);
    appm__zbits(z, z->s2 & 255u, 8);
    appm__zbits(z, z->s1 >> 8, 8);
    appm__zbits(z, z->s1 & 255u, 8);
    appm__zlib_flush_out(z);
}

/* ---- 3.2 PNG --------------------------------------------------------------- */

/* The Paeth predictor (PNG specification, 9.4): whichever of the left (a),
 * upper (b) and upper-left (c) byte is nearest to a + b - c, ties in that order. */
static int appm__paeth(int a, int b, int c)
{
    int p = a + b - c, pa = p > a ? p - a : a - p, pb = p > b ? p - b : b - p, pc = p > c ? p - c : c - p;
    return pa <= pb && pa <= pc ? a : pb <= pc ? b : c;
}

/* Filter type t (0 none, 1 sub, 2 up, 3 average, 4 Paeth) of the n bytes of
 * `cur` against the row above `up` (zeros above the first row), 3 bytes per
 * pixel, into out[0..n] with the type byte first.  Returns the sum of the
 * filtered bytes read as signed magnitudes: the "minimum sum of absolute
 * differences" guess of libpng and stb_image_write at which filter will
 * compress best. */
static uint64_t appm__png_filter(int t, const unsigned char *cur, const unsigned char *up, size_t n,
                                 unsigned char *out)
{
    uint64_t cost = 0;
    size_t i;
    out[0] = (unsigned char)t;
    for (i = 0; i < n; ++i) {
        int a = i >= 3 ? cur[i - 3] : 0, b = up[i], c = i >= 3 ? up[i - 3] : 0, pred;
        unsigned char v;
        pred = t == 0 ? 0 : t == 1 ? a : t == 2 ? b : t == 3 ? (a + b) >> 1 : appm__paeth(a, b, c);
        v = (unsigned char)(cur[i] - pred);
        out[1 + i] = v;
        cost += v < 128 ? v : 256u - v;
    }
    return cost;
}

static void appm__emit_copy(void *ctx, const unsigned char *p, size_t n)
{
    unsigned char **dst = (unsigned char **)ctx;
    memcpy(*dst, p, n);
    *dst += n;
}

/* One IDAT chunk per piece of compressed output. */
static void appm__png_idat(void *ctx, const unsigned char *p, size_t n)
{
    appm__out *o = (appm__out *)ctx;
    appm__png_chunk_begin(o, "IDAT", (uint32_t)n);
    appm__put_crc(o, p, n);
    appm__png_chunk_end(o);
}

/* Rows are converted to sRGB bytes, each row filtered five ways and the
 * cheapest (by the guess above) sent to the compressor.  All buffers are
 * allocated here, once: four rows and the compressor's window and tables. */
static appm_status appm__write_png_body(appm__out *o, appm__mem *m, const appm_image *img,
                                        float exposure)
{
    static const unsigned char sig[8] = {137, 80, 78, 71, 13, 10, 26, 10};
    const uint32_t w = img->width, h = img->height;
    const size_t n = (size_t)w * 3;
    unsigned char b[13], *rows, *cur, *up, *best, *trial;
    appm__zlib z;
    appm_status st = appm__zlib_init(&z, m, APPM__PNG_CHAIN, APPM__PNG_MINKEEP);
    uint32_t y;
    rows = (unsigned char *)appm__alloc(m, 4, n + 1); /* zeroed: the row above the first */
    if (st != APPM_OK || !rows) {
        appm__free(m, rows);
        appm__zlib_release(&z, m);
        return APPM_ERR_NOMEM;
    }
    cur = rows;
    up = cur + (n + 1);
    best = up + (n + 1);
    trial = best + (n + 1);
    appm__put(o, sig, 8);
    appm__png_chunk_begin(o, "IHDR", 13);
    appm__be32(b, w);
    appm__be32(b + 4, h);
    b[8] = 8;  /* bit depth */
    b[9] = 2;  /* colour type: RGB */
    b[10] = 0; /* compression: deflate */
    b[11] = 0; /* filter method 0: a filter type byte leads each row */
    b[12] = 0; /* no interlace */
    appm__put_crc(o, b, 13);
    appm__png_chunk_end(o);
    appm__zlib_begin(&z, appm__png_idat, o);
    for (y = 0; y < h; ++y) {
        unsigned char *dst = cur, *t;
        uint64_t cost, c;
        int f;
        appm__emit_srgb_row(img, y, exposure, appm__emit_copy, &dst);
        cost = appm__png_filter(0, cur, up, n, best);
        for (f = 1; f <= 4; ++f)
            if ((c = appm__png_filter(f, cur, up, n, trial)) < cost) {
                cost = c;
                t = best;
                best = trial;
                trial = t;
            }
        appm__zlib_feed(&z, best, n + 1);
        t = up; /* this row is the next one's "above" */
        up = cur;
        cur = t;
    }
    appm__zlib_end(&z);
    appm__png_chunk_begin(o, "IEND", 0);
    appm__png_chunk_end(o);
    appm__free(m, rows);
    appm__zlib_release(&z, m);
    return APPM_OK;
}

/* ---- 3.3 OpenEXR --------------------------------------------------------------
 *
 * Single-part scanline files (the OpenEXR file layout document): magic
 * 76 2f 31 01, version 2 with no flags, the header (attributes as name, type,
 * size, value; an empty name ends it), a table with the file offset of every
 * block, then the blocks, each "first line, byte count, data".  Everything is
 * little-endian.  Channels are B, G, R (the header lists them sorted by name);
 * a block holds, line by line, all B values, then G, then R.  Linear RGB, 32-bit
 * float or 16-bit half, uncompressed (one line per block) or ZIP (16 lines per
 * block: the bytes are split into even and odd halves, delta coded, deflated;
 * a block that would not shrink is stored raw, which readers recognise by its
 * size).  The offset table precedes the blocks, so a ZIP file is compressed
 * twice: once to learn the block sizes, once to write them - no seeking, so
 * a pipe works too, and memory stays at one block.
 */
static void appm__le32(unsigned char *b, uint32_t v)
{
    b[0] = (unsigned char)v;
    b[1] = (unsigned char)(v >> 8);
    b[2] = (unsigned char)(v >> 16);
    b[3] = (unsigned char)(v >> 24);
}

/* float -> IEEE half, round to nearest even.  Finite values beyond the half
 * range become +-65504 (the largest half) rather than infinity; inf and NaN
 * stay what they are. */
static uint16_t appm__half(float f)
{
    uint32_t x, sign, e, mant, hm, rem, halfway, shift;
    memcpy(&x, &f, 4);
    sign = (x >> 16) & 0x8000u;
    e = (x >> 23) & 255u;
    mant = x & 0x7FFFFFu;
    if (e == 255) return (uint16_t)(sign | 0x7C00u | (mant ? 0x200u : 0u));
    if (e < 113) { /* below 2^-14: a half subnormal (units of 2^-24) or zero */
        if (e < 102) return (uint16_t)sign;
        mant |= 0x800000u;
        shift = 126 - e;
        hm = mant >> shift;
        rem = mant & ((1u << shift) - 1u);
        halfway = 1u << (shift - 1);
        if (rem > halfway || (rem == halfway && (hm & 1u))) hm++; /* may carry into the exponent: right */
        return (uint16_t)(sign | hm);
    }
    hm = mant >> 13;
    rem = mant & 0x1FFFu;
    e -= 112; /* rebias 127 -> 15 */
    if (rem > 0x1000u || (rem == 0x1000u && (hm & 1u))) {
        if (++hm == 0x400u) {
            hm = 0;
            e++;
        }
    }
    if (e >= 31) return (uint16_t)(sign | 0x7BFFu);
    return (uint16_t)(sign | e << 10 | hm);
}

typedef struct appm__exrw {
    const appm_image *img;
    int half, zip;
    uint32_t lines;              /* scanlines per block: 1 or 16 */
    size_t cap;                  /* bytes of the largest block, uncompressed */
    unsigned char *raw, *tmp, *packed;
    size_t npacked;
    int overflow;                /* the deflated block grew past `cap` */
    appm__zlib z;
} appm__exrw;

static void appm__exr_sink(void *ctx, const unsigned char *p, size_t n)
{
    appm__exrw *e = (appm__exrw *)ctx;
    if (e->overflow || n > e->cap - e->npacked) {
        e->overflow = 1;
        return;
    }
    memcpy(e->packed + e->npacked, p, n);
    e->npacked += n;
}

/* The block starting at line y0, as it is stored; its size in *size. */
static const unsigned char *appm__exr_block(appm__exrw *e, uint32_t y0, size_t *size)
{
    const appm_image *img = e->img;
    uint32_t y1 = y0 + e->lines < img->height ? y0 + e->lines : img->height, y, x;
    size_t n = 0, i, half_n;
    int c;
    for (y = y0; y < y1; ++y)
        for (c = 2; c >= 0; --c) /* B, G, R */
            for (x = 0; x < img->width; ++x) {
                float v = img->rgb[3 * ((size_t)y * img->width + x) + (size_t)c];
                if (e->half) {
                    uint16_t hv = appm__half(v);
                    e->raw[n++] = (unsigned char)hv;
                    e->raw[n++] = (unsigned char)(hv >> 8);
                } else {
                    uint32_t bits;
                    memcpy(&bits, &v, 4);
                    appm__le32(e->raw + n, bits);
                    n += 4;
                }
            }
    *size = n;
    if (!e->zip) return e->raw;
    half_n = (n + 1) / 2; /* even bytes first, then odd ones; then each byte minus the one before, + 128 */
    for (i = 0; i < n; ++i) e->tmp[(i & 1u) ? half_n + i / 2 : i / 2] = e->raw[i];
    for (i = n; i-- > 1;) e->tmp[i] = (unsigned char)(e->tmp[i] - e->tmp[i - 1] + 128);
    e->npacked = 0;
    e->overflow = 0;
    appm__zlib_begin(&e->z, appm__exr_sink, e);
    appm__zlib_feed(&e->z, e->tmp, n);
    appm__zlib_end(&e->z);
    if (e->overflow || e->npacked >= n) return e->raw;
    *size = e->npacked;
    return e->packed;
}

/* Appends one attribute (name, type, size, value) to the header buffer. */
static size_t appm__exr_attr(unsigned char *h, size_t at, const char *name, const char *type,
                             const void *value, uint32_t n)
{
    size_t ln = strlen(name) + 1, lt = strlen(type) + 1;
    memcpy(h + at, name, ln);
    memcpy(h + at + ln, type, lt);
    appm__le32(h + at + ln + lt, n);
    memcpy(h + at + ln + lt + 4, value, n);
    return at + ln + lt + 4 + n;
}

static size_t appm__exr_header(unsigned char *h, const appm__exrw *e)
{
    unsigned char ch[3 * 18 + 1], box[16], one[4], zero8[8], cmp, order = 0; /* INCREASING_Y */
    float f1 = 1.0f;
    uint32_t bits;
    size_t at = 8;
    int c;
    static const unsigned char magic[8] = {0x76, 0x2f, 0x31, 0x01, 2, 0, 0, 0};
    memcpy(h, magic, 8);
    memset(ch, 0, sizeof ch);
    for (c = 0; c < 3; ++c) { /* name, pixel type (1 half, 2 float), pLinear, 3 reserved, x and y sampling */
        unsigned char *q = ch + 18 * c;
        q[0] = (unsigned char)"BGR"[c];
        appm__le32(q + 2, e->half ? 1u : 2u);
        appm__le32(q + 10, 1);
        appm__le32(q + 14, 1);
    }
    memset(box, 0, sizeof box);
    appm__le32(box + 8, e->img->width - 1);
    appm__le32(box + 12, e->img->height - 1);
    memcpy(&bits, &f1, 4);
    appm__le32(one, bits);
    memset(zero8, 0, sizeof zero8);
    cmp = (unsigned char)(e->zip ? 3 : 0); /* ZIP_COMPRESSION : NO_COMPRESSION */
    at = appm__exr_attr(h, at, "channels", "chlist", ch, sizeof ch);
    at = appm__exr_attr(h, at, "compression", "compression", &cmp, 1);
    at = appm__exr_attr(h, at, "dataWindow", "box2i", box, 16);
    at = appm__exr_attr(h, at, "displayWindow", "box2i", box, 16);
    at = appm__exr_attr(h, at, "lineOrder", "lineOrder", &order, 1);
    at = appm__exr_attr(h, at, "pixelAspectRatio", "float", one, 4);
    at = appm__exr_attr(h, at, "screenWindowCenter", "v2f", zero8, 8);
    at = appm__exr_attr(h, at, "screenWindowWidth", "float", one, 4);
    h[at++] = 0;
    return at;
}

static appm_status appm__write_exr_body(appm__out *o, appm__mem *m, const appm_image *img, int half,
                                        int zip)
{
    appm__exrw e;
    unsigned char hdr[512], b[8];
    size_t hlen, size;
    uint32_t k, nblock;
    uint64_t off;
    appm_status st = APPM_OK;
    memset(&e, 0, sizeof e);
    e.img = img;
    e.half = half;
    e.zip = zip;
    e.lines = zip ? 16 : 1;
    e.cap = (size_t)e.lines * img->width * 3 * (half ? 2 : 4);
    nblock = (img->height + e.lines - 1) / e.lines;
    e.raw = (unsigned char *)appm__alloc(m, zip ? 3 : 1, e.cap);
    if (!e.raw || (zip && (st = appm__zlib_init(&e.z, m, APPM__EXR_CHAIN, 0)) != APPM_OK)) st = APPM_ERR_NOMEM;
    if (st == APPM_OK) {
        if (zip) {
            e.tmp = e.raw + e.cap;
            e.packed = e.tmp + e.cap;
        }
        hlen = appm__exr_header(hdr, &e);
        appm__put(o, hdr, hlen);
        off = hlen + 8 * (uint64_t)nblock;
        for (k = 0; k < nblock; ++k) { /* pass 1: the offset table */
            appm__exr_block(&e, k * e.lines, &size);
            appm__le32(b, (uint32_t)off);
            appm__le32(b + 4, (uint32_t)(off >> 32));
            appm__put(o, b, 8);
            off += 8 + size;
        }
        for (k = 0; k < nblock; ++k) { /* pass 2: the blocks */
            const unsigned char *p = appm__exr_block(&e, k * e.lines, &size);
            appm__le32(b, k * e.lines);
            appm__le32(b + 4, (uint32_t)size);
            appm__put(o, b, 8);
            appm__put(o, p, size);
        }
    }
    if (zip) appm__zlib_release(&e.z, m);
    appm__free(m, e.raw);
    return st;
}

static void appm__write_ppm_body(appm__out *o, const appm_image *img, float exposure)
{
    char head[64];
    uint32_t y;
    int n = sprintf(head, "P6\n%lu %lu\n255\n", (unsigned long)img->width,
                    (unsigned long)img->height);
    appm__put(o, head, (size_t)n);
    for (y = 0; y < img->height; ++y) appm__emit_srgb_row(img, y, exposure, appm__emit_plain, o);
}

static void appm__write_pfm_body(appm__out *o, const appm_image *img)
{
    char head[80];
    uint32_t y;
    int n = sprintf(head, "PF\n%lu %lu\n%s\n", (unsigned long)img->width,
                    (unsigned long)img->height, appm__host_little_endian() ? "-1.0" : "1.0");
    appm__put(o, head, (size_t)n);
    for (y = img->height; y-- > 0;) /* bottom row first */
        appm__put(o, img->rgb + (size_t)y * img->width * 3, sizeof(float) * img->width * 3);
}

static int appm__ends_with(const char *s, const char *suffix)
{
    size_t n = strlen(s), k = strlen(suffix), i;
    if (k > n) return 0;
    for (i = 0; i < k; ++i) {
        char c = s[n - k + i];
        if (c >= 'A' && c <= 'Z') c = (char)(c - 'A' + 'a');
        if (c != suffix[i]) return 0;
    }
    return 1;
}

APPM_API appm_status appm_image_write_ex(const char *path, const appm_image *img,
                                         const appm_write_options *opt, const appm_config *cfg,
                                         appm_diag *diag)
{
    enum { PFM, PPM, PNG, EXR } kind;
    char tmp[4096];
    int special;
    double exposure = opt ? opt->exposure : 0.0;
    appm__out o;
    appm__mem m;
    appm_status st = APPM_OK;
    appm__diag_clear(diag);
    if (!path || !img || !img->rgb || img->width == 0 || img->height == 0 ||
        img->width > 32768 || img->height > 32768)
        return appm__fail(diag, APPM_ERR_INVALID_ARG, path, 0, "no image to write");
    if (!(exposure >= 0.0) || exposure > 1e30)
        return appm__fail(diag, APPM_ERR_INVALID_ARG, path, 0, "exposure must be a positive number");
    if (exposure == 0.0) exposure = 1.0;
    if (appm__ends_with(path, ".pfm")) kind = PFM;
    else if (appm__ends_with(path, ".ppm")) kind = PPM;
    else if (appm__ends_with(path, ".png")) kind = PNG;
    else if (appm__ends_with(path, ".exr")) kind = EXR;
    else
        return appm__fail(diag, APPM_ERR_INVALID_ARG, path, 0,
                          "unknown image format (use .pfm, .ppm, .png or .exr)");
    if (strlen(path) + 5 > sizeof tmp)
        return appm__fail(diag, APPM_ERR_INVALID_ARG, path, 0, "path too long");
    appm__mem_init(&m, cfg);
    m.diag = diag;
    special = appm__is_special_file(path);
    sprintf(tmp, "%s.tmp", path);
    o.f = fopen(special ? path : tmp, "wb");
    o.ok = o.f != NULL;
    o.crc = 0;
    if (o.ok) {
        if (kind == PFM) appm__write_pfm_body(&o, img);
        else if (kind == PPM) appm__write_ppm_body(&o, img, (float)exposure);
        else if (kind == PNG) st = appm__write_png_body(&o, &m, img, (float)exposure);
        else st = appm__write_exr_body(&o, &m, img, opt && opt->exr_half, !(opt && opt->exr_uncompressed));
        if (!special && o.ok && st == APPM_OK && appm__file_sync(o.f) != 0) o.ok = 0; /* the data, then the name */
        if (fclose(o.f) != 0) o.ok = 0;
        if (st != APPM_OK) o.ok = 0;
        if (!special) {
            if (o.ok && appm__rename_replace(tmp, path) != 0) o.ok = 0;
            if (!o.ok) remove(tmp);
            else appm__dir_sync(path);
        }
    }
    if (st != APPM_OK) return appm__fail(diag, st, path, 0, "out of memory writing the image");
    if (!o.ok) return appm__fail(diag, APPM_ERR_IO, path, 0, "cannot write the image");
    return APPM_OK;
}

APPM_API appm_status appm_image_write(const char *path, const appm_image *img, double exposure,
                                      appm_diag *diag)
{
    appm_write_options opt;
    memset(&opt, 0, sizeof opt);
    opt.exposure = exposure;
    return appm_image_write_ex(path, img, &opt, NULL, diag);
}

/* The file through the user's reader (appm_config.reader), copied as
 * appm__read_file copies. */
static appm_status appm__read_hooked(appm__mem *m, const char *path, char **out, size_t *len, appm_diag *diag)
{
    const void *data = NULL;
    size_t n = 0;
    char *buf;
    if (m->reader.read(m->reader.user, path, &data, &n) != 0 || (!data && n))
        return appm__fail(diag, APPM_ERR_IO, path, 0, "cannot open file");
    buf = n < (size_t)-1 ? (char *)appm__alloc(m, n + 1, 1) : NULL;
    if (buf && n) memcpy(buf, data, n);
    if (m->reader.release) m->reader.release(m->reader.user, data);
    if (!buf) return appm__fail(diag, APPM_ERR_NOMEM, path, 0, "out of memory reading the file");
    buf[n] = 0;
    *out = buf;
    *len = n;
    return APPM_OK;
}

/* Reads a whole file through the allocator; one extra zero byte is appended so
 * that callers can print from it, but no parser relies on that terminator. */
static appm_status appm__read_file(appm__mem *m, const char *path, char **out, size_t *len,
                                   appm_diag *diag)
{
    FILE *f;
    char *buf = NULL;
    size_t cap = 0, n = 0;
    *out = NULL;
    *len = 0;
    if (m->reader.read) return appm__read_hooked(m, path, out, len, diag);
    f = fopen(path, "rb");
    if (!f) return appm__fail(diag, APPM_ERR_IO, path, 0, "cannot open file");
    for (;;) {
        size_t got;
        if (cap - n < 2) { /* grow geometrically: allocate, copy, free */
            size_t ncap = cap ? cap * 2 : 65536;
            char *nb;
            if (ncap < cap) break;
            nb = (char *)appm__alloc(m, ncap, 1);
            if (!nb) {
                appm__free(m, buf);
                fclose(f);
                return appm__fail(diag, APPM_ERR_NOMEM, path, 0, "out of memory reading the file");
            }
            if (n) memcpy(nb, buf, n);
            appm__free(m, buf);
            buf = nb;
            cap = ncap;
        }
        got = fread(buf + n, 1, cap - n - 1, f);
        n += got;
        if (got == 0) break;
    }
    if (ferror(f)) {
        fclose(f);
        appm__free(m, buf);
        return appm__fail(diag, APPM_ERR_IO, path, 0, "read error");
    }
    fclose(f);
    buf[n] = 0;
    *out = buf;
    *len = n;
    return APPM_OK;
}

/* Parses a PFM held in memory.  Accepts "PF" (RGB) and "Pf" (grey, expanded to
 * RGB), any whitespace between header fields, exactly one whitespace byte after
 * the scale, and either byte order; rejects sizes above 32768 and short data. */
static appm_status appm__pfm_parse(appm__mem *m, const unsigned char *p, size_t len,
                                   const char *name, appm_image *out, appm_diag *diag)
{
    size_t pos = 2, y, x;
    unsigned long dims[2] = {0, 0};
    double scale = 0.0;
    int channels, little, k;
    char num[64];
    uint64_t need; /* 64-bit: 32768 x 32768 RGB is 12 GB, beyond a 32-bit size_t */
    out->width = out->height = 0;
    out->rgb = NULL;
    if (len < 2 || p[0] != 'P' || (p[1] != 'F' && p[1] != 'f'))
        return appm__fail(diag, APPM_ERR_PARSE, name, 1, "not a PFM file (no PF/Pf magic)");
    channels = p[1] == 'F' ? 3 : 1;
    for (k = 0; k < 3; ++k) {
        size_t n = 0;
        while (pos < len && (p[pos] == ' ' || p[pos] == '\t' || p[pos] == '\n' || p[pos] == '\r'))
            pos++;
        while (pos < len && n + 1 < sizeof num && p[pos] != ' ' && p[pos] != '\t' &&
               p[pos] != '\n' && p[pos] != '\r')
            num[n++] = (char)p[pos++];
        num[n] = 0;
        if (n == 0 || n + 1 >= sizeof num)
            return appm__fail(diag, APPM_ERR_PARSE, name, 0, "truncated or malformed PFM header");
        if (k < 2) {
            char *end;
            long v = strtol(num, &end, 10);
            if (*end || v <= 0 || v > 32768)
                return appm__fail(diag, APPM_ERR_PARSE, name, 0,
                                  "PFM size '%s' is not an integer in 1..32768", num);
            dims[k] = (unsigned long)v;
        } else {
            char *end;
            scale = strtod(num, &end);
            if (*end || !(scale == scale) || scale == 0.0)
                return appm__fail(diag, APPM_ERR_PARSE, name, 0, "PFM scale '%s' is not a non-zero number", num);
        }
    }
    if (pos >= len) return appm__fail(diag, APPM_ERR_PARSE, name, 0, "PFM has no pixel data");
    pos++; /* the single whitespace byte after the scale */
    little = scale < 0.0;
    need = (uint64_t)dims[0] * dims[1] * (uint64_t)channels * 4;
    if ((uint64_t)(len - pos) < need)
        return appm__fail(diag, APPM_ERR_PARSE, name, 0,
                          "PFM data is short: %.0f bytes for %lux%lu pixels", (double)(len - pos),
                          dims[0], dims[1]);
    out->rgb = (float *)appm__alloc(m, (size_t)dims[0] * dims[1], 3 * sizeof(float));
    if (!out->rgb) return appm__fail(diag, APPM_ERR_NOMEM, name, 0, "out of memory");
    out->width = (uint32_t)dims[0];
    out->height = (uint32_t)dims[1];
    for (y = 0; y < dims[1]; ++y) {
        float *row = out->rgb + (dims[1] - 1 - y) * dims[0] * 3; /* file row 0 = bottom */
        for (x = 0; x < dims[0] * (size_t)channels; ++x) {
            const unsigned char *q = p + pos + (y * dims[0] * (size_t)channels + x) * 4;
            uint32_t bits = little ? ((uint32_t)q[0] | (uint32_t)q[1] << 8 | (uint32_t)q[2] << 16 |
                                      (uint32_t)q[3] << 24)
                                   : ((uint32_t)q[3] | (uint32_t)q[2] << 8 | (uint32_t)q[1] << 16 |
                                      (uint32_t)q[0] << 24);
            float v;
            memcpy(&v, &bits, 4);
            if (channels == 3) row[x] = v;
            else row[3 * x] = row[3 * x + 1] = row[3 * x + 2] = v;
        }
    }
    return APPM_OK;
}

APPM_API appm_status appm_image_read_pfm(const char *path, const appm_config *cfg,
                                         appm_image *out, appm_diag *diag)
{
    appm__mem m;
    char *buf;
    size_t len;
    appm_status s;
    appm__diag_clear(diag);
    if (!out) return appm__fail(diag, APPM_ERR_INVALID_ARG, path, 0, "no output image");
    out->width = out->height = 0;
    out->rgb = NULL;
    if (!path) return appm__fail(diag, APPM_ERR_INVALID_ARG, NULL, 0, "no path");
    appm__mem_init(&m, cfg);
    m.diag = diag;
    s = appm__read_file(&m, path, &buf, &len, diag);
    if (s != APPM_OK) return s;
    s = appm__pfm_parse(&m, (const unsigned char *)buf, len, path, out, diag);
    appm__free(&m, buf);
    return s;
}

/* ---- 3.4 Reading images: textures and environment maps ---------------------
 *
 * Every decoder turns a file held in memory into appm__pixels: the samples as
 * the file stores them (8-bit colour is sRGB-encoded, alpha linear; float
 * samples are linear radiance), row 0 at the top.  appm__image_decode picks
 * the decoder by the file's first bytes (TGA, which has no magic, by its
 * name), so a texture named .png that is really a JPEG still loads.  Every
 * decoder checks each read against the end of its buffer, refuses sizes above
 * APPM__IMAGE_MAX a side and sizes its input could not hold (a 100-byte file
 * never makes it allocate gigabytes), and gives APPM_ERR_PARSE with the file's
 * name and what was wrong, or APPM_ERR_NOMEM; on failure nothing is held. */
#define APPM__IMAGE_MAX 32768u /* the largest width or height any decoder accepts */

typedef struct appm__pixels {
    uint32_t w, h;
    unsigned channels; /* 1 grey, 2 grey + alpha, 3 RGB, 4 RGBA, interleaved */
    unsigned depth;    /* 8: uint8_t; 16: uint16_t (host order); 32: float, linear */
    void *data;        /* w * h * channels samples, one block from appm__alloc */
} appm__pixels;

/* ---- 3.5 Small image decoders: TGA, PGM/PPM, Radiance HDR ------------------
 *
 * Texture and environment maps arrive as whole files in memory (p, len).  Each
 * decoder fills an appm__pixels with row 0 = the TOP of the picture and column
 * 0 = its left edge, whatever order the file stores them in.
 *
 * The three decoders share one discipline, because these bytes come from
 * anywhere:
 *   - every read is preceded by a check of how many bytes remain, so a short
 *     or lying file is a parse error, never a read past the buffer;
 *   - sizes are bounded (1..APPM__IMAGE_MAX) and multiplied in 64 bits;
 *   - before allocating, the image must be one the remaining bytes could
 *     possibly encode: for raw data, exactly enough bytes; for run-length data,
 *     a bound from the best compression the format allows.  So a 20-byte file
 *     claiming 32768 x 32768 pixels is refused without touching the allocator;
 *   - on any failure out->data is NULL and everything allocated is freed.
 * Errors are APPM_ERR_PARSE with a message naming the format and the fault,
 * or APPM_ERR_NOMEM when the allocator says no. */

static void appm__dec_reset(appm__pixels *out)
{
    out->w = out->h = 0;
    out->channels = out->depth = 0;
    out->data = NULL;
}

static void appm__dec_drop(appm__mem *m, appm__pixels *out)
{
    appm__free(m, out->data);
    appm__dec_reset(out);
}

/* One block for w*h*channels samples of depth bits (8, 16 or 32).  w and h are
 * at most 2^15 and channels*bytes at most 16, so the product fits 64 bits; it
 * may still not fit a 32-bit size_t, which is an out-of-memory condition. */
static appm_status appm__dec_alloc(appm__mem *m, appm__pixels *out, uint32_t w, uint32_t h,
                                   unsigned channels, unsigned depth, const char *fmt,
                                   const char *name, appm_diag *diag)
{
    uint64_t n = (uint64_t)w * h * channels;
    size_t bytes = depth / 8;
    if (n > (uint64_t)(SIZE_MAX / bytes))
        return appm__fail(diag, APPM_ERR_NOMEM, name, 0, "%s: a %lux%lu image does not fit in memory",
                          fmt, (unsigned long)w, (unsigned long)h);
    out->data = appm__alloc(m, (size_t)n, bytes);
    if (!out->data)
        return appm__fail(diag, APPM_ERR_NOMEM, name, 0, "%s: out of memory for a %lux%lu image",
                          fmt, (unsigned long)w, (unsigned long)h);
    out->w = w;
    out->h = h;
    out->channels = channels;
    out->depth = depth;
    return APPM_OK;
}

/* Reverses the order of the rows (vflip) and/or of the pixels within each row
 * (hflip) of 8-bit pixels in place, by swapping bytes: no scratch row needed. */
static void appm__dec_flip8(appm__pixels *img, int vflip, int hflip)
{
    unsigned char *d = (unsigned char *)img->data, t;
    size_t c = img->channels, row = (size_t)img->w * c, y, x, k;
    if (vflip)
        for (y = 0; y < img->h / 2; ++y) {
            unsigned char *a = d + y * row, *b = d + (img->h - 1 - y) * row;
            for (k = 0; k < row; ++k) { t = a[k]; a[k] = b[k]; b[k] = t; }
        }
    if (hflip)
        for (y = 0; y < img->h; ++y)
            for (x = 0; x < img->w / 2; ++x) {
                unsigned char *a = d + y * row + x * c, *b = d + y * row + (img->w - 1 - x) * c;
                for (k = 0; k < c; ++k) { t = a[k]; a[k] = b[k]; b[k] = t; }
            }
}

/* -- TGA --------------------------------------------------------------------
 *
 * Truevision TGA (1989 spec, version 2.0).  An 18-byte little-endian header:
 *   0 id length   1 colour-map type (0 none, 1 present)   2 image type
 *   3 first colour-map entry index (16)   5 colour-map length (16)
 *   7 colour-map entry size in bits   8,10 x/y origin (unused here)
 *   12 width (16)   14 height (16)   16 bits per pixel   17 descriptor:
 *      bits 0-3 attribute (alpha) bits per pixel, bit 4 set = rows run right
 *      to left, bit 5 set = first row is the TOP (clear: the bottom, the
 *      default), bits 6-7 interleaving (obsolete; refused).
 * then the image ID (skipped), the colour map, and the pixels.  Image types:
 * 1 colour-mapped, 2 true colour, 3 grey; +8 for run-length encoding, where
 * each packet starts with a byte h: h & 0x80 -> one pixel value repeated
 * (h & 0x7f) + 1 times, else (h & 0x7f) + 1 literal pixels.  Packets follow
 * the pixel stream, so a run may cross from one row into the next (the 2.0
 * spec discourages it, writers do it).  A TGA 2.0 footer or extension area
 * after the pixels is ignored.
 *
 * Stored colours: 8-bit grey; 15/16-bit little-endian words A RRRRR GGGGG
 * BBBBB, expanded to 8 bits as (v << 3) | (v >> 2) so 31 -> 255 and 0 -> 0;
 * 24-bit B,G,R; 32-bit B,G,R,A.  Alpha exists only when the descriptor's
 * attribute bits say so (many 16-bit files leave the top bit as garbage, and
 * a 32-bit file with 0 attribute bits has an unused fourth byte); then the
 * output has 4 channels.  A 24-bit or grey image with attribute bits set has
 * no room for alpha and the bits are ignored.  For colour-mapped images the
 * map entries (15/16/24/32 bits) carry the colour and the pixels are 8- or
 * 16-bit indices; pixel value v names entry v - first, and an index outside
 * the map is an error. */

static unsigned appm__le16(const unsigned char *q)
{
    return (unsigned)q[0] | (unsigned)q[1] << 8;
}

static void appm__tga_color(const unsigned char *q, unsigned bits, int alpha, unsigned char c[4])
{
    unsigned v, r, g, b;
    switch (bits) {
    case 8:
        c[0] = c[1] = c[2] = q[0];
        c[3] = 255;
        break;
    case 15:
    case 16:
        v = appm__le16(q);
        r = (v >> 10) & 31u;
        g = (v >> 5) & 31u;
        b = v & 31u;
        c[0] = (unsigned char)(r << 3 | r >> 2);
        c[1] = (unsigned char)(g << 3 | g >> 2);
        c[2] = (unsigned char)(b << 3 | b >> 2);
        c[3] = (unsigned char)(!alpha || (v & 0x8000u) ? 255 : 0);
        break;
    case 24:
        c[0] = q[2]; c[1] = q[1]; c[2] = q[0]; c[3] = 255;
        break;
    default: /* 32 */
        c[0] = q[2]; c[1] = q[1]; c[2] = q[0];
        c[3] = alpha ? q[3] : 255;
        break;
    }
}

/* The header facts of one TGA file, as appm__tga_header and appm__tga_layout
 * leave them: a supported type, bit depth and size, and every offset inside
 * the file. */
typedef struct appm__tga_info {
    unsigned idlen, cmtype, type, cmfirst, cmlen, cmbits, cmbpp; /* cmbpp: bytes per map entry */
    unsigned w, h, bits, bpp, desc;                              /* bpp: bytes per stored pixel */
    unsigned channels;                                           /* out: 1 grey, 3 RGB, 4 RGBA */
    int rle, mapped, alpha;
    size_t pos; /* where the pixel data starts */
} appm__tga_info;

/* Reads the 18-byte header into t and refuses what this reader does not
 * decode: an unknown image type, interleaving, a size outside
 * 1..APPM__IMAGE_MAX, a pixel or colour-map depth the type does not allow.
 * The checks run in header order, so a file with several faults always names
 * the same one. */
static appm_status appm__tga_header(const unsigned char *p, size_t len, const char *name, appm__tga_info *t,
                                    appm_diag *diag)
{
    if (len < 18)
        return appm__fail(diag, APPM_ERR_PARSE, name, 0, "TGA: file is shorter than the 18-byte header");
    t->idlen = p[0];
    t->cmtype = p[1];
    t->type = p[2];
    t->cmfirst = appm__le16(p + 3);
    t->cmlen = appm__le16(p + 5);
    t->cmbits = p[7];
    t->w = appm__le16(p + 12);
    t->h = appm__le16(p + 14);
    t->bits = p[16];
    t->desc = p[17];
    t->rle = t->type >= 8;
    if (t->type != 1 && t->type != 2 && t->type != 3 && t->type != 9 && t->type != 10 && t->type != 11)
        return appm__fail(diag, APPM_ERR_PARSE, name, 0,
                          "TGA: image type %u is not supported (1-3 and RLE 9-11 are; 0 has no "
                          "image, 32/33 are Huffman-coded)", t->type);
    if (t->cmtype > 1)
        return appm__fail(diag, APPM_ERR_PARSE, name, 0, "TGA: colour-map type %u is not 0 or 1", t->cmtype);
    t->mapped = (t->type & 7u) == 1;
    if (t->mapped && t->cmtype != 1)
        return appm__fail(diag, APPM_ERR_PARSE, name, 0, "TGA: colour-mapped image has no colour map");
    if (t->desc & 0xC0u)
        return appm__fail(diag, APPM_ERR_PARSE, name, 0,
                          "TGA: interleaved rows (descriptor bits 6-7) are not supported");
    if (t->w == 0 || t->h == 0 || t->w > APPM__IMAGE_MAX || t->h > APPM__IMAGE_MAX)
        return appm__fail(diag, APPM_ERR_PARSE, name, 0, "TGA: size %ux%u is outside 1..%u", t->w, t->h,
                          APPM__IMAGE_MAX);
    if (t->mapped) {
        if (t->cmbits != 15 && t->cmbits != 16 && t->cmbits != 24 && t->cmbits != 32)
            return appm__fail(diag, APPM_ERR_PARSE, name, 0,
                              "TGA: colour-map entries of %u bits are not supported (15/16/24/32)", t->cmbits);
        if (t->cmlen == 0)
            return appm__fail(diag, APPM_ERR_PARSE, name, 0, "TGA: colour map is empty");
        if (t->bits != 8 && t->bits != 16)
            return appm__fail(diag, APPM_ERR_PARSE, name, 0,
                              "TGA: colour-map indices of %u bits are not supported (8 or 16)", t->bits);
    } else if ((t->type & 7u) == 2) {
        if (t->bits != 15 && t->bits != 16 && t->bits != 24 && t->bits != 32)
            return appm__fail(diag, APPM_ERR_PARSE, name, 0,
                              "TGA: true-colour pixels of %u bits are not supported (15/16/24/32)", t->bits);
    } else if (t->bits != 8) {
        return appm__fail(diag, APPM_ERR_PARSE, name, 0,
                          "TGA: grey pixels of %u bits are not supported (only 8; 16-bit grey+alpha "
                          "is refused)", t->bits);
    }
    return APPM_OK;
}

/* Derives the output channels and the offsets from a checked header, and
 * refuses a file too short for its image before anything is allocated: raw
 * data must all be there, and an RLE packet of 1 + bpp bytes covers at most
 * 128 pixels, so fewer bytes than that bound cannot hold the image. */
static appm_status appm__tga_layout(size_t len, const char *name, appm__tga_info *t, appm_diag *diag)
{
    size_t rest, mapbytes;
    uint64_t npix;
    unsigned colbits;
    /* A colour map on a true-colour or grey image is legal and unused: skip it. */
    t->cmbpp = (t->cmbits + 7) / 8;
    mapbytes = t->cmtype ? (size_t)t->cmlen * t->cmbpp : 0;
    colbits = t->mapped ? t->cmbits : t->bits;
    t->alpha = (t->desc & 15u) != 0 && (colbits == 16 || colbits == 32);
    t->channels = (t->type & 7u) == 3 ? 1 : t->alpha ? 4 : 3;
    t->bpp = (t->bits + 7) / 8;
    if (len - 18 < t->idlen || len - 18 - t->idlen < mapbytes)
        return appm__fail(diag, APPM_ERR_PARSE, name, 0, "TGA: file ends inside the image ID or colour map");
    t->pos = 18 + t->idlen + mapbytes;
    rest = len - t->pos;
    npix = (uint64_t)t->w * t->h;
    if (!t->rle && npix * t->bpp > rest)
        return appm__fail(diag, APPM_ERR_PARSE, name, 0,
                          "TGA: pixel data is truncated (%lu bytes for %ux%u pixels of %u bytes)",
                          (unsigned long)rest, t->w, t->h, t->bpp);
    if (t->rle && npix * (1 + t->bpp) > (uint64_t)rest * 128)
        return appm__fail(diag, APPM_ERR_PARSE, name, 0, "TGA: %lu bytes of RLE data cannot hold %ux%u pixels",
                          (unsigned long)rest, t->w, t->h);
    return APPM_OK;
}

/* Decodes the pixel stream into dst (w*h pixels of t->channels bytes, rows in
 * file order: appm__tga_decode flips them after).  An RLE packet may cross
 * rows but not the end of the image; each packet's bytes are checked before
 * it is read.  pal holds the colour map as RGBA when t->mapped.  On failure
 * the message is set and dst is left for the caller to free. */
static appm_status appm__tga_pixels(const unsigned char *p, size_t len, const char *name, const appm__tga_info *t,
                                    const unsigned char *pal, unsigned char *dst, appm_diag *diag)
{
    const uint64_t npix = (uint64_t)t->w * t->h;
    size_t pos = t->pos;
    uint64_t i;
    unsigned k;
    for (i = 0; i < npix;) {
        uint64_t count = npix - i, j;
        int run = 0;
        if (t->rle) {
            unsigned hdr;
            if (pos >= len) goto truncated;
            hdr = p[pos++];
            count = (hdr & 0x7Fu) + 1;
            run = (hdr & 0x80u) != 0;
            if (count > npix - i)
                return appm__fail(diag, APPM_ERR_PARSE, name, 0, "TGA: RLE packet runs past the end of the image");
        }
        if ((uint64_t)(len - pos) < (run ? 1 : count) * t->bpp) goto truncated;
        for (j = 0; j < count; ++j, ++i) {
            unsigned char cbuf[4];
            const unsigned char *c = cbuf;
            const unsigned char *q = p + pos + (run ? 0 : j * t->bpp);
            if (t->mapped) {
                unsigned idx = t->bpp == 1 ? q[0] : appm__le16(q);
                if (idx < t->cmfirst || idx - t->cmfirst >= t->cmlen)
                    return appm__fail(diag, APPM_ERR_PARSE, name, 0,
                                      "TGA: colour index %u is outside the colour map (%u..%u)", idx, t->cmfirst,
                                      t->cmfirst + t->cmlen - 1);
                c = pal + 4 * (idx - t->cmfirst);
            } else {
                appm__tga_color(q, t->bits, t->alpha, cbuf);
            }
            for (k = 0; k < t->channels; ++k) dst[i * t->channels + k] = c[k];
        }
        pos += (size_t)((run ? 1 : count) * t->bpp);
    }
    return APPM_OK;
truncated:
    return appm__fail(diag, APPM_ERR_PARSE, name, 0, "TGA: pixel data ends after %lu of %lu pixels",
                      (unsigned long)i, (unsigned long)npix);
}

static appm_status appm__tga_decode(appm__mem *m, const unsigned char *p, size_t len,
                                    const char *name, appm__pixels *out, appm_diag *diag)
{
    appm__tga_info t;
    unsigned char *pal = NULL;
    unsigned k;
    appm_status s;

    appm__dec_reset(out);
    memset(&t, 0, sizeof t);
    if ((s = appm__tga_header(p, len, name, &t, diag)) != APPM_OK) return s;
    if ((s = appm__tga_layout(len, name, &t, diag)) != APPM_OK) return s;
    if (t.mapped) {
        const unsigned char *q = p + 18 + t.idlen;
        pal = (unsigned char *)appm__alloc(m, t.cmlen, 4);
        if (!pal) return appm__fail(diag, APPM_ERR_NOMEM, name, 0, "TGA: out of memory for the colour map");
        for (k = 0; k < t.cmlen; ++k) appm__tga_color(q + (size_t)k * t.cmbpp, t.cmbits, t.alpha, pal + 4 * k);
    }
    s = appm__dec_alloc(m, out, t.w, t.h, t.channels, 8, "TGA", name, diag);
    if (s != APPM_OK) {
        appm__free(m, pal);
        return s;
    }
    s = appm__tga_pixels(p, len, name, &t, pal, (unsigned char *)out->data, diag);
    appm__free(m, pal);
    if (s != APPM_OK) {
        appm__dec_drop(m, out);
        return s;
    }
    appm__dec_flip8(out, !(t.desc & 0x20u), (t.desc & 0x10u) != 0);
    return APPM_OK;
}

/* -- PGM / PPM --------------------------------------------------------------
 *
 * Netpbm greymaps and pixmaps: "P2" (grey) or "P3" (RGB) with decimal samples,
 * "P5"/"P6" with binary ones.  The header is the magic, width, height and
 * maxval as decimal numbers separated by whitespace (space, tab, CR, LF, VT,
 * FF), where '#' starts a comment that runs to the end of the line.  A binary
 * raster starts after exactly ONE whitespace byte following maxval (the raster
 * may itself begin with a whitespace-valued byte, so no more may be skipped);
 * netpbm's reader also lets a comment stand there, and so do we.  Binary
 * samples are 1 byte when maxval < 256, else 2 bytes big-endian.  Samples
 * above maxval are invalid.  Rows run top to bottom.  Bytes after the raster
 * (a further image of a multi-image stream) are ignored.
 *
 * Output: maxval 255 or 65535 keeps the stored values (depth 8 or 16); other
 * maxvals are rescaled to the full range of the smaller depth that holds them,
 * rounding to nearest: (v * full + maxval / 2) / maxval.  In 32 bits this is at
 * most 65535 * 65534 + 32767 < 2^32. */

static int appm__pnm_space(unsigned char c)
{
    return c == ' ' || c == '\t' || c == '\n' || c == '\r' || c == '\v' || c == '\f';
}

/* Skips whitespace and comments (netpbm's plain-format reader also accepts
 * comments between raster samples, so P2/P3 rasters use this too). */
static size_t appm__pnm_skip(const unsigned char *p, size_t len, size_t pos)
{
    while (pos < len) {
        if (p[pos] == '#') {
            while (pos < len && p[pos] != '\n') pos++;
        } else if (appm__pnm_space(p[pos])) {
            pos++;
        } else {
            break;
        }
    }
    return pos;
}

/* Reads a decimal number at *pos that must end at whitespace, '#' or the end
 * of the data.  Values saturate at 10^9 so a long digit string cannot
 * overflow; callers range-check.  Returns 0 if there is no such number. */
static int appm__pnm_uint(const unsigned char *p, size_t len, size_t *pos, uint32_t *v)
{
    size_t i = *pos;
    uint32_t x = 0;
    if (i >= len || p[i] < '0' || p[i] > '9') return 0;
    for (; i < len && p[i] >= '0' && p[i] <= '9'; ++i) {
        x = x * 10 + (uint32_t)(p[i] - '0');
        if (x > 1000000000u) x = 1000000000u;
    }
    if (i < len && !appm__pnm_space(p[i]) && p[i] != '#') return 0;
    *pos = i;
    *v = x;
    return 1;
}

/* Reads the n = w*h*channels raster samples starting at pos into out (already
 * allocated at the depth maxval needs), rescaling them to the depth's full
 * range.  The caller has checked that a binary raster is all there, so only
 * plain (ascii) samples can run out.  On failure the message is set and out
 * is left for the caller to drop. */
static appm_status appm__pnm_raster(const unsigned char *p, size_t len, size_t pos, int ascii, uint32_t maxval,
                                    appm__pixels *out, const char *name, appm_diag *diag)
{
    const unsigned depth = out->depth;
    const uint32_t full = maxval > 255 ? 65535u : 255u;
    const uint64_t n = (uint64_t)out->w * out->h * out->channels;
    uint64_t i;
    uint32_t x;
    for (i = 0; i < n; ++i) {
        if (ascii) {
            /* appm__pnm_uint() stopped the previous number at a separator. */
            pos = appm__pnm_skip(p, len, pos);
            if (!appm__pnm_uint(p, len, &pos, &x)) {
                if (pos >= len)
                    return appm__fail(diag, APPM_ERR_PARSE, name, 0, "PNM: pixel data ends after %lu of %lu samples",
                                      (unsigned long)i, (unsigned long)n);
                return appm__fail(diag, APPM_ERR_PARSE, name, 0, "PNM: sample %lu is not a decimal number",
                                  (unsigned long)i);
            }
        } else if (depth == 8) {
            x = p[pos++];
        } else {
            x = (uint32_t)p[pos] << 8 | p[pos + 1];
            pos += 2;
        }
        if (x > maxval)
            return appm__fail(diag, APPM_ERR_PARSE, name, 0, "PNM: sample %lu is %lu, above maxval %lu",
                              (unsigned long)i, (unsigned long)x, (unsigned long)maxval);
        if (maxval != full) x = (x * full + maxval / 2) / maxval;
        if (depth == 8) ((unsigned char *)out->data)[i] = (unsigned char)x;
        else ((uint16_t *)out->data)[i] = (uint16_t)x;
    }
    return APPM_OK;
}

static appm_status appm__pnm_decode(appm__mem *m, const unsigned char *p, size_t len,
                                    const char *name, appm__pixels *out, appm_diag *diag)
{
    static const char *const field[3] = {"width", "height", "maxval"};
    uint32_t v[3], maxval;
    unsigned channels, depth;
    int ascii, k;
    size_t pos = 2, rest;
    uint64_t n;
    appm_status s;

    appm__dec_reset(out);
    if (len < 2 || p[0] != 'P' || (p[1] != '2' && p[1] != '3' && p[1] != '5' && p[1] != '6'))
        return appm__fail(diag, APPM_ERR_PARSE, name, 0,
                          "PNM: not a PGM/PPM file (magic must be P2, P3, P5 or P6; PBM and PAM are "
                          "not supported)");
    ascii = p[1] == '2' || p[1] == '3';
    channels = p[1] == '3' || p[1] == '6' ? 3 : 1;
    for (k = 0; k < 3; ++k) {
        size_t start = pos;
        pos = appm__pnm_skip(p, len, pos);
        if (pos == start && pos < len)
            return appm__fail(diag, APPM_ERR_PARSE, name, 0, "PNM: no whitespace before the %s", field[k]);
        if (!appm__pnm_uint(p, len, &pos, &v[k]))
            return appm__fail(diag, APPM_ERR_PARSE, name, 0,
                              pos >= len ? "PNM: file ends before the %s" : "PNM: %s is not a decimal number",
                              field[k]);
    }
    if (v[0] < 1 || v[0] > APPM__IMAGE_MAX || v[1] < 1 || v[1] > APPM__IMAGE_MAX)
        return appm__fail(diag, APPM_ERR_PARSE, name, 0, "PNM: size %lux%lu is outside 1..%u",
                          (unsigned long)v[0], (unsigned long)v[1], APPM__IMAGE_MAX);
    maxval = v[2];
    if (maxval < 1 || maxval > 65535)
        return appm__fail(diag, APPM_ERR_PARSE, name, 0, "PNM: maxval %lu is outside 1..65535",
                          (unsigned long)maxval);
    depth = maxval > 255 ? 16 : 8;
    n = (uint64_t)v[0] * v[1] * channels;
    if (!ascii) {
        if (pos < len && p[pos] == '#')
            while (pos < len && p[pos] != '\n') pos++;
        if (pos >= len) return appm__fail(diag, APPM_ERR_PARSE, name, 0, "PNM: file ends before the pixel data");
        pos++; /* the single whitespace byte after maxval (or the comment's newline) */
    }
    rest = len - pos;
    /* Binary: exactly n samples of 1 or 2 bytes.  Plain: every sample needs a
     * separator before it and at least one digit, so at least 2n bytes. */
    if (ascii ? n > rest / 2 : n * (depth / 8) > rest)
        return appm__fail(diag, APPM_ERR_PARSE, name, 0,
                          "PNM: pixel data is truncated (%lu bytes for %lux%lu pixels)", (unsigned long)rest,
                          (unsigned long)v[0], (unsigned long)v[1]);
    s = appm__dec_alloc(m, out, v[0], v[1], channels, depth, "PNM", name, diag);
    if (s != APPM_OK) return s;
    s = appm__pnm_raster(p, len, pos, ascii, maxval, out, name, diag);
    if (s != APPM_OK) appm__dec_drop(m, out);
    return s;
}

/* -- Radiance HDR (RGBE) -------------------------------------------------------
 *
 * Greg Ward's Radiance picture format (.hdr, .pic).  A text header: the magic
 * line "#?RADIANCE" (or "#?RGBE", written by some tools), then "NAME=value"
 * lines and comments up to an empty line; then the resolution line, then
 * scanlines of 4-byte pixels R,G,B,E: a shared exponent E and three 8-bit
 * mantissas.
 *
 * Header: FORMAT=32-bit_rle_rgbe is the only FORMAT accepted (absent means
 * RGBE too); 32-bit_rle_xyze (CIE XYZ primaries) is refused rather than shown
 * with the wrong colours.  EXPOSURE= is deliberately ignored: it records a
 * multiplier some tool (pfilt, a camera pipeline) already applied, and
 * dividing by it would recover the "original" radiance, but every common
 * reader (stb_image, ImageMagick, OpenImageIO's default, Blender) uses the
 * stored values as they are, and environment maps are authored and exchanged
 * on that basis; honouring it would make appm's lighting disagree with every
 * other renderer given the same file.  Other variables (PRIMARIES, PIXASPECT,
 * COLORCORR, VIEW, SOFTWARE, ...) are likewise ignored.
 *
 * Resolution line: "-Y h +X w" is the standard orientation (first scanline
 * at the top, pixels left to right).  "+Y h +X w" stores the bottom scanline
 * first and is accepted, flipped on the way in.  The other six orientations
 * (mirrored or column-major) are refused.
 *
 * Scanlines come in three encodings, told apart by their first four bytes
 * exactly as Radiance's freadcolrs() does:
 *   - new ("adaptive") RLE: only when 8 <= w <= 32767 and the scanline starts
 *     with 2, 2, hi, lo where hi < 128 and hi:lo == w.  Then the four channel
 *     planes follow one after another (all R, all G, all B, all E), each as
 *     packets: a count c > 128 means the next byte repeated c - 128 times,
 *     else c literal bytes (c == 0 is malformed and refused, as stb_image
 *     does; Radiance would skip it);
 *   - otherwise flat 4-byte pixels, with old-style RLE mixed in: a pixel
 *     1,1,1,n repeats the previous pixel n << shift times, shift growing by 8
 *     for each consecutive repeat pixel (so 1,1,1,44 then 1,1,1,1 is 300).
 *     A real pixel 1,1,1,n can therefore never be stored: the reference reader
 *     always reads it as a repeat, and so do we.  A repeat with no pixel
 *     before it in its scanline, or one running past the scanline, is an error
 *     (Radiance's reader would read or write outside its buffer).
 *
 * Conversion (Radiance's colr_color()): E == 0 is black; otherwise each
 * channel is (m + 0.5) * 2^(E - 136), i.e. ldexp(m + 0.5, E - 136); 136 is the
 * exponent bias 128 plus 8 for the mantissa's 8 bits.  We follow Ward's
 * reference rather than stb_image and ImageMagick (which use m * 2^(E-136)
 * without the +0.5): the reference writer setcolr() truncates when it
 * quantises, so a stored m stands for the interval [m, m+1) and its midpoint
 * is the unbiased reconstruction; the alternative darkens every value by up to
 * one mantissa step (0.4% to 50% depending on magnitude).  Every result is
 * exact in float (9 significant bits, exponents within float's range down
 * into its subnormals).
 *
 * Size check: new RLE covers at most 127 bytes of one plane in a 2-byte
 * packet, so a pixel needs at least 8/127 byte; old RLE can do much better in
 * principle (12 bytes for a uniform 32767-pixel scanline), but an image that
 * claims more than 128 pixels per byte of data is refused as corrupt rather
 * than allocated; every scanline needs at least 4 bytes whatever its coding. */

/* Decodes one scanline of w RGBE pixels into sc[4*w]; returns NULL or what is
 * wrong. */
static const char *appm__hdr_scanline(const unsigned char *p, size_t len, size_t *ppos,
                                      unsigned char *sc, uint32_t w)
{
    size_t pos = *ppos;
    uint32_t x = 0, c;
    unsigned shift = 0;
    if (len - pos < 4) return "file ends inside a scanline";
    if (w >= 8 && w <= 0x7FFF && p[pos] == 2 && p[pos + 1] == 2 && !(p[pos + 2] & 0x80)) {
        if (((uint32_t)p[pos + 2] << 8 | p[pos + 3]) != w) return "RLE scanline length does not match the width";
        pos += 4;
        for (c = 0; c < 4; ++c)
            for (x = 0; x < w;) {
                uint32_t count, j;
                if (pos >= len) return "file ends inside an RLE scanline";
                count = p[pos++];
                if (count == 0) return "RLE packet of length 0";
                if (count > 128) {
                    count -= 128;
                    if (count > w - x) return "RLE run goes past the end of the scanline";
                    if (pos >= len) return "file ends inside an RLE scanline";
                    for (j = 0; j < count; ++j) sc[4 * (x + j) + c] = p[pos];
                    pos++;
                } else {
                    if (count > w - x) return "RLE literal goes past the end of the scanline";
                    if (len - pos < count) return "file ends inside an RLE scanline";
                    for (j = 0; j < count; ++j) sc[4 * (x + j) + c] = p[pos + j];
                    pos += count;
                }
                x += count;
            }
        *ppos = pos;
        return NULL;
    }
    while (x < w) {
        const unsigned char *q = p + pos;
        if (len - pos < 4) return "file ends inside a scanline";
        pos += 4;
        if (q[0] == 1 && q[1] == 1 && q[2] == 1) {
            uint64_t count = (uint64_t)q[3] << shift, j;
            if (x == 0) return "old-style RLE repeat with no pixel before it";
            if (count > w - x) return "old-style RLE repeat goes past the end of the scanline";
            for (j = 0; j < count; ++j, ++x) memcpy(sc + 4 * x, sc + 4 * (x - 1), 4);
            if (shift < 32) shift += 8; /* beyond 24 any nonzero count exceeds w */
        } else {
            memcpy(sc + 4 * x, q, 4);
            x++;
            shift = 0;
        }
    }
    *ppos = pos;
    return NULL;
}

/* Reads the line at *pos (without its '\n') into [*start, *end); advances past
 * the newline.  Returns 0 if there is no newline before the end of the data. */
static int appm__hdr_line(const unsigned char *p, size_t len, size_t *pos, size_t *start, size_t *end)
{
    const unsigned char *nl = *pos < len ? (const unsigned char *)memchr(p + *pos, '\n', len - *pos) : NULL;
    if (!nl) return 0;
    *start = *pos;
    *end = (size_t)(nl - p);
    *pos = *end + 1;
    return 1;
}

/* Does the line [a, b) equal s, ignoring trailing blanks (and a CR)? */
static int appm__hdr_is(const unsigned char *p, size_t a, size_t b, const char *s)
{
    size_t n = strlen(s);
    while (b > a && (p[b - 1] == ' ' || p[b - 1] == '\t' || p[b - 1] == '\r')) b--;
    return b - a == n && memcmp(p + a, s, n) == 0;
}

/* Parses "<sign><axis> <n>" at *i of line [.., b): one or more spaces before,
 * a sign, an axis letter, spaces, a decimal number in 1..APPM__IMAGE_MAX. */
static int appm__hdr_axis(const unsigned char *p, size_t *i, size_t b, char *sign, char *axis, uint32_t *n)
{
    size_t k = *i;
    uint32_t v = 0;
    while (k < b && p[k] == ' ') k++;
    if (b - k < 2 || (p[k] != '-' && p[k] != '+') || (p[k + 1] != 'X' && p[k + 1] != 'Y')) return 0;
    *sign = (char)p[k];
    *axis = (char)p[k + 1];
    k += 2;
    if (k >= b || p[k] != ' ') return 0;
    while (k < b && p[k] == ' ') k++;
    if (k >= b || p[k] < '0' || p[k] > '9') return 0;
    for (; k < b && p[k] >= '0' && p[k] <= '9'; ++k) {
        v = v * 10 + (uint32_t)(p[k] - '0');
        if (v > APPM__IMAGE_MAX) return 0;
    }
    if (v < 1) return 0;
    *i = k;
    *n = v;
    return 1;
}

static appm_status appm__hdr_decode(appm__mem *m, const unsigned char *p, size_t len,
                                    const char *name, appm__pixels *out, appm_diag *diag)
{
    size_t pos = 0, a, b, i;
    char s1, a1, s2, a2;
    uint32_t h, w, y, x;
    unsigned char *sc;
    float *rows;
    appm_status s;

    appm__dec_reset(out);
    if (!appm__hdr_line(p, len, &pos, &a, &b) ||
        (!appm__hdr_is(p, a, b, "#?RADIANCE") && !appm__hdr_is(p, a, b, "#?RGBE")))
        return appm__fail(diag, APPM_ERR_PARSE, name, 0,
                          "HDR: not a Radiance picture (first line must be #?RADIANCE or #?RGBE)");
    for (;;) {
        if (!appm__hdr_line(p, len, &pos, &a, &b))
            return appm__fail(diag, APPM_ERR_PARSE, name, 0, "HDR: file ends inside the header");
        if (a == b) break;
        if (b - a >= 7 && memcmp(p + a, "FORMAT=", 7) == 0) {
            if (appm__hdr_is(p, a + 7, b, "32-bit_rle_xyze"))
                return appm__fail(diag, APPM_ERR_PARSE, name, 0,
                                  "HDR: XYZE pictures (FORMAT=32-bit_rle_xyze) are not supported");
            if (!appm__hdr_is(p, a + 7, b, "32-bit_rle_rgbe"))
                return appm__fail(diag, APPM_ERR_PARSE, name, 0,
                                  "HDR: unknown FORMAT (only 32-bit_rle_rgbe is supported)");
        }
    }
    if (!appm__hdr_line(p, len, &pos, &a, &b))
        return appm__fail(diag, APPM_ERR_PARSE, name, 0, "HDR: file ends before the resolution line");
    i = a;
    while (b > a && (p[b - 1] == ' ' || p[b - 1] == '\r')) b--;
    if (!appm__hdr_axis(p, &i, b, &s1, &a1, &h) || !appm__hdr_axis(p, &i, b, &s2, &a2, &w) || i != b)
        return appm__fail(diag, APPM_ERR_PARSE, name, 0,
                          "HDR: malformed resolution line (expected \"-Y height +X width\", sizes 1..%u)",
                          APPM__IMAGE_MAX);
    if (a1 != 'Y' || a2 != 'X' || s2 != '+')
        return appm__fail(diag, APPM_ERR_PARSE, name, 0,
                          "HDR: orientation \"%c%c .. %c%c ..\" is not supported (only -Y h +X w and "
                          "+Y h +X w)", s1, a1, s2, a2);
    if ((uint64_t)h * 4 > len - pos || (uint64_t)w * h > (uint64_t)(len - pos) * 128)
        return appm__fail(diag, APPM_ERR_PARSE, name, 0, "HDR: %lu bytes of pixel data cannot hold %lux%lu pixels",
                          (unsigned long)(len - pos), (unsigned long)w, (unsigned long)h);
    sc = (unsigned char *)appm__alloc(m, w, 4);
    if (!sc) return appm__fail(diag, APPM_ERR_NOMEM, name, 0, "HDR: out of memory for a scanline");
    s = appm__dec_alloc(m, out, w, h, 3, 32, "HDR", name, diag);
    if (s != APPM_OK) {
        appm__free(m, sc);
        return s;
    }
    rows = (float *)out->data;
    for (y = 0; y < h; ++y) {
        const char *why = appm__hdr_scanline(p, len, &pos, sc, w);
        float *row = rows + (size_t)(s1 == '-' ? y : h - 1 - y) * w * 3;
        if (why) {
            appm__fail(diag, APPM_ERR_PARSE, name, 0, "HDR: scanline %lu: %s", (unsigned long)y, why);
            appm__free(m, sc);
            appm__dec_drop(m, out);
            return APPM_ERR_PARSE;
        }
        for (x = 0; x < w; ++x) {
            const unsigned char *q = sc + 4 * x;
            unsigned k;
            for (k = 0; k < 3; ++k)
                row[3 * x + k] = q[3] == 0 ? 0.0f : (float)ldexp(q[k] + 0.5, (int)q[3] - 136);
        }
    }
    appm__free(m, sc);
    return APPM_OK;
}

/* ---- 3.6 Inflate (RFC 1950 zlib, RFC 1951 deflate) ---------------------------
 *
 * One zlib stream is inflated into a caller-owned buffer that must come out
 * exactly full: PNG and EXR both know the decompressed size before they start,
 * so there is no window to manage - the output buffer IS the window, and a
 * back-reference may reach anywhere into what has been written so far.
 *
 * Bits are read least significant first (RFC 1951, 3.1.1) from a 64-bit
 * buffer refilled whole bytes at a time; a refill tops it up to at least 56
 * bits while input lasts, which covers the longest symbol pair - a 15-bit
 * length code, 5 extra bits, a 15-bit distance code and 13 extra bits - so the
 * decode loop refills once per symbol.  Near the end of the input fewer bits
 * are present, and every take checks the count: reading past src + n is an
 * error, never an access.
 *
 * Huffman codes are canonical (3.2.2): a code is fully described by its code
 * lengths.  Decoding looks up the next APPM__INF_FAST bits in a table whose
 * entry holds the symbol and its code length; codes longer than that (rare:
 * only symbols with frequency below about 1/1024) fall back to walking the
 * canonical code one bit at a time from the per-length counts, as zlib's
 * "puff" does.  All tables live on the stack of appm__zlib_inflate. */
#define APPM__INF_FAST 10
#define APPM__INF_FASTN (1u << APPM__INF_FAST)

typedef struct appm__inf_huff {
    uint16_t fast[APPM__INF_FASTN]; /* symbol << 4 | length; 0: longer code or no code */
    uint16_t count[16];             /* codes of each length */
    uint16_t symbol[288];           /* symbols ordered by code */
} appm__inf_huff;

typedef struct appm__inf_bits {
    const unsigned char *src;
    size_t n, pos; /* src[pos] is the first byte not yet in buf */
    uint64_t buf;  /* the next nb bits of the stream, low bit first */
    unsigned nb;
} appm__inf_bits;

/* Tops buf up to >= 56 bits, or to whatever the input still holds.  The
 * eight-byte step ORs in bits beyond the counted ones too; they are the very
 * bytes the next refill ORs in again at the same place, so they do no harm. */
static void appm__inf_refill(appm__inf_bits *b)
{
    if (b->nb < 56 && b->n - b->pos >= 8) {
        const unsigned char *q = b->src + b->pos;
        uint64_t v = (uint64_t)q[0] | (uint64_t)q[1] << 8 | (uint64_t)q[2] << 16 | (uint64_t)q[3] << 24 |
                     (uint64_t)q[4] << 32 | (uint64_t)q[5] << 40 | (uint64_t)q[6] << 48 |
                     (uint64_t)q[7] << 56;
        b->buf |= v << b->nb;
        b->pos += (63u - b->nb) >> 3;
        b->nb |= 56u;
        return;
    }
    while (b->nb <= 56 && b->pos < b->n) {
        b->buf |= (uint64_t)b->src[b->pos++] << b->nb;
        b->nb += 8;
    }
}

/* Builds the decoding tables for code lengths len[0..n).  Over-subscribed
 * lengths are always an error; an incomplete code is allowed only when it is
 * a single code of one bit (RFC 1951 3.2.7 permits one distance code), the
 * same rule as zlib's inflate.  An empty code (no lengths at all) builds, and
 * fails only if a symbol is ever decoded from it. */
static const char *appm__inf_build(appm__inf_huff *h, const unsigned char *len, unsigned n)
{
    uint16_t offs[16], next[16];
    unsigned s, l, used = 0;
    int left = 1;
    memset(h->count, 0, sizeof h->count);
    memset(h->fast, 0, sizeof h->fast);
    for (s = 0; s < n; ++s) h->count[len[s]]++;
    h->count[0] = 0;
    for (l = 1; l < 16; ++l) {
        left = (left << 1) - h->count[l];
        if (left < 0) return "deflate: over-subscribed Huffman code";
        used += h->count[l];
    }
    if (left > 0 && !(used == 1 && h->count[1] == 1) && used != 0) return "deflate: incomplete Huffman code";
    offs[1] = 0;
    for (l = 1; l < 15; ++l) offs[l + 1] = (uint16_t)(offs[l] + h->count[l]);
    /* next[l]: the first canonical code of length l (3.2.2, step 2) */
    next[0] = 0;
    next[1] = 0;
    for (l = 2; l < 16; ++l) next[l] = (uint16_t)((next[l - 1] + h->count[l - 1]) << 1);
    for (s = 0; s < n; ++s) {
        unsigned L = len[s], code, rev = 0, i;
        if (!L) continue;
        h->symbol[offs[L]++] = (uint16_t)s;
        code = next[L]++;
        if (L > APPM__INF_FAST) continue;
        for (i = 0; i < L; ++i) rev |= ((code >> i) & 1u) << (L - 1 - i); /* codes go out MSB first */
        for (i = rev; i < APPM__INF_FASTN; i += 1u << L) h->fast[i] = (uint16_t)(s << 4 | L);
    }
    return NULL;
}

/* The next symbol of code h, or -1 with *err set. */
static int appm__inf_decode(appm__inf_bits *b, const appm__inf_huff *h, const char **err)
{
    unsigned e = h->fast[b->buf & (APPM__INF_FASTN - 1u)], l;
    int code = 0, first = 0, index = 0;
    if (e && (e & 15u) <= b->nb) {
        b->buf >>= e & 15u;
        b->nb -= e & 15u;
        return (int)(e >> 4);
    }
    for (l = 1; l < 16; ++l) { /* canonical walk: the code's bits arrive most significant first */
        int count = h->count[l];
        if (l > b->nb) {
            *err = "deflate: data ends early";
            return -1;
        }
        code |= (int)((b->buf >> (l - 1)) & 1u);
        if (code - count < first) {
            b->buf >>= l;
            b->nb -= l;
            return h->symbol[index + (code - first)];
        }
        index += count;
        first = (first + count) << 1;
        code <<= 1;
    }
    *err = "deflate: invalid Huffman code";
    return -1;
}

/* n (<= 32) bits, or *err set. */
static unsigned appm__inf_take(appm__inf_bits *b, unsigned n, const char **err)
{
    unsigned v;
    if (n > b->nb) {
        *err = "deflate: data ends early";
        return 0;
    }
    v = (unsigned)(b->buf & (((uint64_t)1 << n) - 1u));
    b->buf >>= n;
    b->nb -= n;
    return v;
}

/* Adler-32 (RFC 1950, 8.2): two sums mod 65521, deferred for 5552 bytes, the
 * most that cannot overflow 32 bits. */
static uint32_t appm__inf_adler32(const unsigned char *p, size_t n)
{
    uint32_t a = 1, b = 0;
    while (n) {
        size_t k = n < 5552 ? n : 5552, i;
        for (i = 0; i < k; ++i) {
            a += p[i];
            b += a;
        }
        a %= 65521u;
        b %= 65521u;
        p += k;
        n -= k;
    }
    return b << 16 | a;
}

/* Reads the code lengths of a dynamic block (RFC 1951, 3.2.7) and builds both
 * tables. */
static const char *appm__inf_dynamic(appm__inf_bits *b, appm__inf_huff *lit, appm__inf_huff *dist)
{
    unsigned char lens[286 + 30];
    unsigned nlit, ndist, ncode, i, k;
    const char *err = NULL;
    appm__inf_refill(b);
    nlit = appm__inf_take(b, 5, &err) + 257;
    ndist = appm__inf_take(b, 5, &err) + 1;
    ncode = appm__inf_take(b, 4, &err) + 4;
    if (err) return err;
    if (nlit > 286 || ndist > 30) return "deflate: too many length or distance codes";
    memset(lens, 0, sizeof lens);
    for (i = 0; i < ncode; ++i) {
        appm__inf_refill(b);
        lens[appm__cl_order[i]] = (unsigned char)appm__inf_take(b, 3, &err);
    }
    if (err) return err;
    if ((err = appm__inf_build(lit, lens, 19)) != NULL) return "deflate: bad code-length code";
    memset(lens, 0, 19);
    for (i = 0; i < nlit + ndist;) {
        int sym;
        unsigned rep, val = 0;
        appm__inf_refill(b);
        sym = appm__inf_decode(b, lit, &err);
        if (sym < 0) return err;
        if (sym < 16) {
            lens[i++] = (unsigned char)sym;
            continue;
        }
        if (sym == 16) {
            if (i == 0) return "deflate: repeat with no previous code length";
            val = lens[i - 1];
            rep = 3 + appm__inf_take(b, 2, &err);
        } else if (sym == 17) {
            rep = 3 + appm__inf_take(b, 3, &err);
        } else {
            rep = 11 + appm__inf_take(b, 7, &err);
        }
        if (err) return err;
        if (i + rep > nlit + ndist) return "deflate: code lengths repeat past the end";
        for (k = 0; k < rep; ++k) lens[i++] = (unsigned char)val;
    }
    if (lens[256] == 0) return "deflate: no end-of-block code";
    if ((err = appm__inf_build(lit, lens, nlit)) != NULL) return err;
    return appm__inf_build(dist, lens + nlit, ndist);
}

/* Decodes one Huffman-coded block (3.2.5) into dst[*at ..). */
static const char *appm__inf_codes(appm__inf_bits *b, const appm__inf_huff *lit, const appm__inf_huff *dist,
                                   unsigned char *dst, size_t want, size_t *at)
{
    size_t o = *at;
    const char *err = NULL;
    for (;;) {
        int sym;
        size_t len, d;
        unsigned e = 0;
        appm__inf_refill(b);
        /* the fast path of appm__inf_decode, inlined: this loop is the hot one */
        e = lit->fast[b->buf & (APPM__INF_FASTN - 1u)];
        if (e && (e & 15u) <= b->nb) {
            b->buf >>= e & 15u;
            b->nb -= e & 15u;
            sym = (int)(e >> 4);
        } else if ((sym = appm__inf_decode(b, lit, &err)) < 0) {
            break;
        }
        if (sym < 256) {
            if (o >= want) {
                err = "deflate: more data than expected";
                break;
            }
            dst[o++] = (unsigned char)sym;
            continue;
        }
        if (sym == 256) break;
        sym -= 257;
        if (sym >= 29) {
            err = "deflate: invalid length code";
            break;
        }
        len = appm__len_base[sym] + appm__inf_take(b, appm__len_extra[sym], &err);
        sym = appm__inf_decode(b, dist, &err);
        if (err) break;
        if (sym >= 30) {
            err = "deflate: invalid distance code";
            break;
        }
        d = appm__dist_base[sym] + appm__inf_take(b, appm__dist_extra[sym], &err);
        if (err) break;
        if (d > o) {
            err = "deflate: invalid distance too far back";
            break;
        }
        if (len > want - o) {
            err = "deflate: more data than expected";
            break;
        }
        if (d >= len) {
            memcpy(dst + o, dst + o - d, len);
        } else { /* overlapping copy: a run, byte by byte as the spec defines it */
            unsigned char *q = dst + o;
            const unsigned char *r = q - d;
            size_t i;
            for (i = 0; i < len; ++i) q[i] = r[i];
        }
        o += len;
    }
    *at = o;
    return err;
}

/* Inflates the zlib stream src[0..n) into dst, which must come out exactly
 * `want` bytes long.  NULL on success, else what was wrong.  Bytes after the
 * Adler-32 trailer are ignored, as zlib's inflate does. */
static const char *appm__zlib_inflate(const unsigned char *src, size_t n, unsigned char *dst, size_t want)
{
    appm__inf_huff lit, dist;
    appm__inf_bits b;
    size_t o = 0;
    unsigned final = 0;
    const char *err = NULL;
    if (n < 2) return "zlib: data ends early";
    /* RFC 1950, 2.2: CM 8 (deflate), CINFO <= 7 (window <= 32 KiB), the
     * 16-bit header a multiple of 31, no preset dictionary */
    if ((src[0] & 15u) != 8 || (src[0] >> 4) > 7 || ((unsigned)src[0] << 8 | src[1]) % 31u != 0)
        return "zlib: bad header";
    if (src[1] & 0x20u) return "zlib: preset dictionary not supported";
    b.src = src;
    b.n = n;
    b.pos = 2;
    b.buf = 0;
    b.nb = 0;
    while (!final) {
        unsigned type;
        appm__inf_refill(&b);
        final = appm__inf_take(&b, 1, &err);
        type = appm__inf_take(&b, 2, &err);
        if (err) return err;
        if (type == 0) { /* stored (3.2.4): skip to a byte boundary, LEN, NLEN, raw bytes */
            size_t len;
            unsigned nlen;
            b.buf >>= b.nb & 7u;
            b.nb &= ~7u;
            len = appm__inf_take(&b, 16, &err);
            nlen = appm__inf_take(&b, 16, &err);
            if (err) return err;
            if ((len ^ 0xFFFFu) != nlen) return "deflate: stored block length check fails";
            b.pos -= b.nb >> 3; /* give the whole bytes still buffered back to the input */
            b.buf = 0;
            b.nb = 0;
            if (len > b.n - b.pos) return "deflate: data ends early";
            if (len > want - o) return "deflate: more data than expected";
            memcpy(dst + o, src + b.pos, len);
            b.pos += len;
            o += len;
        } else if (type == 1) { /* fixed codes (3.2.6) */
            unsigned char lens[288];
            memset(lens, 8, 144);
            memset(lens + 144, 9, 112);
            memset(lens + 256, 7, 24);
            memset(lens + 280, 8, 8);
            appm__inf_build(&lit, lens, 288);
            memset(lens, 5, 32); /* 30 and 31 complete the code but never occur (3.2.6) */
            appm__inf_build(&dist, lens, 32);
            if ((err = appm__inf_codes(&b, &lit, &dist, dst, want, &o)) != NULL) return err;
        } else if (type == 2) {
            if ((err = appm__inf_dynamic(&b, &lit, &dist)) != NULL) return err;
            if ((err = appm__inf_codes(&b, &lit, &dist, dst, want, &o)) != NULL) return err;
        } else {
            return "deflate: invalid block type";
        }
    }
    if (o != want) return "deflate: data ends early";
    b.pos -= b.nb >> 3; /* the trailer starts at the next byte boundary */
    if (b.n - b.pos < 4) return "zlib: data ends early";
    {
        const unsigned char *t = src + b.pos;
        uint32_t stored = (uint32_t)t[0] << 24 | (uint32_t)t[1] << 16 | (uint32_t)t[2] << 8 | t[3];
        if (stored != appm__inf_adler32(dst, want)) return "zlib: Adler-32 mismatch";
    }
    return NULL;
}

/* ---- 3.7 PNG reader -----------------------------------------------------------
 *
 * PNG specification (ISO/IEC 15948, W3C 2nd edition).  The file is the 8-byte
 * signature then chunks: length (big-endian, < 2^31), four letter type, data,
 * CRC-32 of type and data (5.3).  A lower-case first letter marks an ancillary
 * chunk a reader may skip; an upper-case one a critical chunk it must
 * understand.  IHDR comes first, PLTE and tRNS before the IDAT chunks, which
 * are consecutive and together hold one zlib stream, and IEND last.
 *
 * The stream inflates to the filtered rows - of each Adam7 pass in turn for
 * an interlaced image (8.2) - each led by a filter type byte (9.2).  We inflate
 * all of it into one scratch buffer, undo the filters in place, and spread the
 * samples into the output.  Two allocations: the output and the scratch
 * (which also holds the IDAT data joined together when it is split). */

/* Adam7 (8.2): each pass's first column and row, and steps. */
static const unsigned char appm__png_adam7[7][4] = {
    {0, 0, 8, 8}, {4, 0, 8, 8}, {0, 4, 4, 8}, {2, 0, 4, 4}, {0, 2, 2, 4}, {1, 0, 2, 2}, {0, 1, 1, 2}};

static uint32_t appm__png_be32(const unsigned char *p)
{
    return (uint32_t)p[0] << 24 | (uint32_t)p[1] << 16 | (uint32_t)p[2] << 8 | p[3];
}

/* Pixels of a pass along an axis of n pixels: those at start, start + step, ... */
static uint32_t appm__png_pass_count(uint32_t n, unsigned start, unsigned step)
{
    return n > start ? (n - start + step - 1) / step : 0;
}

/* Undoes filter type `f` on row cur[0..n) given the unfiltered row above
 * (NULL above the first row of a pass: all zeros, 9.2) and bpp bytes per
 * complete pixel (at least 1). */
static void appm__png_unfilter(unsigned f, unsigned char *cur, const unsigned char *up, size_t n, size_t bpp)
{
    size_t i;
    if (!up) { /* with zeros above, Up is None, Paeth is Sub, Average halves the left byte */
        if (f == 1 || f == 4)
            for (i = bpp; i < n; ++i) cur[i] = (unsigned char)(cur[i] + cur[i - bpp]);
        else if (f == 3)
            for (i = bpp; i < n; ++i) cur[i] = (unsigned char)(cur[i] + (cur[i - bpp] >> 1));
        return;
    }
    switch (f) {
    case 1:
        for (i = bpp; i < n; ++i) cur[i] = (unsigned char)(cur[i] + cur[i - bpp]);
        break;
    case 2:
        for (i = 0; i < n; ++i) cur[i] = (unsigned char)(cur[i] + up[i]);
        break;
    case 3:
        for (i = 0; i < bpp && i < n; ++i) cur[i] = (unsigned char)(cur[i] + (up[i] >> 1));
        for (; i < n; ++i) cur[i] = (unsigned char)(cur[i] + ((cur[i - bpp] + up[i]) >> 1));
        break;
    case 4:
        for (i = 0; i < bpp && i < n; ++i) cur[i] = (unsigned char)(cur[i] + up[i]);
        for (; i < n; ++i) { /* Paeth (9.4): the neighbour nearest a + b - c, ties a, b, c */
            int a = cur[i - bpp], b = up[i], c = up[i - bpp];
            int pa = b - c, pb = a - c, pc;
            pc = pa + pb;
            pa = pa < 0 ? -pa : pa;
            pb = pb < 0 ? -pb : pb;
            pc = pc < 0 ? -pc : pc;
            cur[i] = (unsigned char)(cur[i] + (pa <= pb && pa <= pc ? a : pb <= pc ? b : c));
        }
        break;
    default:
        break;
    }
}

/* What one decode needs to turn filtered rows into output samples. */
typedef struct appm__png_info {
    uint32_t w, h;
    unsigned depth, type, interlace;
    unsigned in_ch;  /* samples per pixel in the file */
    unsigned out_ch; /* channels out: palette 3 or 4, + 1 for tRNS alpha */
    unsigned char pal[256][4];
    unsigned npal;
    int trns;          /* a tRNS chunk was seen */
    uint16_t key[4];   /* tRNS colour key for grey (key[0]) or RGB; with no tRNS unused */
} appm__png_info;

/* Spreads one unfiltered row of a pass (row `py` of it, `pw` pixels wide) into
 * the output.  Returns 0, or the offending palette index + 1. */
static unsigned appm__png_spread(const appm__png_info *in, const unsigned char *row, uint32_t pw, uint32_t py,
                                 const unsigned char *pass, void *outp)
{
    const uint32_t y = pass[1] + py * pass[3];
    const unsigned oc = in->out_ch, d = in->depth;
    uint32_t i, x;
    if (d == 16) {
        uint16_t *o = (uint16_t *)outp;
        for (i = 0, x = pass[0]; i < pw; ++i, x += pass[2]) {
            uint16_t *q = o + ((size_t)y * in->w + x) * oc;
            const unsigned char *s = row + (size_t)i * in->in_ch * 2;
            unsigned c, match = 1;
            for (c = 0; c < in->in_ch; ++c) {
                q[c] = (uint16_t)(s[2 * c] << 8 | s[2 * c + 1]);
                if (q[c] != in->key[c]) match = 0;
            }
            if (in->trns) q[in->in_ch] = match ? 0 : 65535;
        }
        return 0;
    }
    {
        unsigned char *o = (unsigned char *)outp;
        const unsigned mask = (1u << d) - 1u;
        const unsigned scale = d == 1 ? 255 : d == 2 ? 85 : d == 4 ? 17 : 1; /* 255 / (2^d - 1), exact */
        for (i = 0, x = pass[0]; i < pw; ++i, x += pass[2]) {
            unsigned char *q = o + ((size_t)y * in->w + x) * oc;
            unsigned v, c;
            if (d < 8) { /* packed, leftmost pixel in the high bits (7.2) */
                size_t bit = (size_t)i * d;
                v = (unsigned)(row[bit >> 3] >> (8u - d - (unsigned)(bit & 7u))) & mask;
            } else {
                v = row[(size_t)i * in->in_ch];
            }
            if (in->type == 3) {
                if (v >= in->npal) return v + 1;
                memcpy(q, in->pal[v], oc);
                continue;
            }
            if (d < 8) { /* grey only */
                q[0] = (unsigned char)(v * scale);
                if (in->trns) q[1] = v == in->key[0] ? 0 : 255;
                continue;
            }
            {
                const unsigned char *s = row + (size_t)i * in->in_ch;
                unsigned match = 1;
                for (c = 0; c < in->in_ch; ++c) {
                    q[c] = s[c];
                    if (s[c] != in->key[c]) match = 0;
                }
                if (in->trns) q[in->in_ch] = match ? 0 : 255;
            }
        }
    }
    return 0;
}

/* Where pass 1 over the chunks has got to: which chunks it has seen, and
 * where the IDAT data lies (the chunks from idat_first up to idat_end, all
 * consecutive, idat_total data bytes in idat_count chunks). */
typedef struct appm__png_scan {
    size_t idat_first, idat_total, idat_count;
    uint64_t idat_end;
    int seen_ihdr, seen_plte, seen_idat, idat_done, seen_iend;
} appm__png_scan;

/* Checks the framing of the chunk at p[at]: a whole 12-byte frame, a type of
 * four ASCII letters (5.4), data inside the file, and the CRC.  Leaves its
 * data length in *n and its type, NUL-terminated, in ty. */
static appm_status appm__png_frame(const unsigned char *p, size_t len, size_t at, uint32_t *n, char ty[5],
                                   const char *name, appm_diag *diag)
{
    const unsigned char *t;
    uint32_t crc;
    int k;
    if (len - at < 12) return appm__fail(diag, APPM_ERR_PARSE, name, 0, "PNG: file ends early (no IEND chunk)");
    *n = appm__png_be32(p + at);
    t = p + at + 4;
    for (k = 0; k < 4; ++k) { /* 5.4: type bytes are ASCII letters */
        if (!((t[k] >= 'A' && t[k] <= 'Z') || (t[k] >= 'a' && t[k] <= 'z')))
            return appm__fail(diag, APPM_ERR_PARSE, name, 0, "PNG: bad chunk type at byte %lu", (unsigned long)at);
        ty[k] = (char)t[k];
    }
    ty[4] = 0;
    if (*n > 0x7FFFFFFFu || *n > len - at - 12)
        return appm__fail(diag, APPM_ERR_PARSE, name, 0, "PNG: chunk %s runs past the end of the file", ty);
    crc = appm__crc32_update(0xFFFFFFFFu, t, 4 + (size_t)*n) ^ 0xFFFFFFFFu;
    if (crc != appm__png_be32(t + 4 + *n))
        return appm__fail(diag, APPM_ERR_PARSE, name, 0, "PNG: CRC mismatch in chunk %s", ty);
    return APPM_OK;
}

/* IHDR (11.2.2): n bytes at d.  Exactly one, 13 bytes long, with a size in
 * 1..APPM__IMAGE_MAX, a legal colour type / bit depth pair, and the only
 * compression, filter and interlace methods there are. */
static appm_status appm__png_ihdr(appm__png_info *in, appm__png_scan *sc, const unsigned char *d, uint32_t n,
                                  const char *name, appm_diag *diag)
{
    static const unsigned char ok_depth[7] = {1 | 2 | 4 | 8 | 16, 0, 8 | 16, 1 | 2 | 4 | 8, 8 | 16, 0, 8 | 16};
    if (sc->seen_ihdr) return appm__fail(diag, APPM_ERR_PARSE, name, 0, "PNG: second IHDR chunk");
    if (n != 13) return appm__fail(diag, APPM_ERR_PARSE, name, 0, "PNG: IHDR is %lu bytes, not 13", (unsigned long)n);
    sc->seen_ihdr = 1;
    in->w = appm__png_be32(d);
    in->h = appm__png_be32(d + 4);
    in->depth = d[8];
    in->type = d[9];
    in->interlace = d[12];
    if (in->w == 0 || in->h == 0 || in->w > APPM__IMAGE_MAX || in->h > APPM__IMAGE_MAX)
        return appm__fail(diag, APPM_ERR_PARSE, name, 0, "PNG: size %lux%lu is outside 1..%u",
                          (unsigned long)in->w, (unsigned long)in->h, APPM__IMAGE_MAX);
    if (in->type > 6 || !ok_depth[in->type] || in->depth > 16 || (in->depth & (in->depth - 1)) != 0 ||
        !(ok_depth[in->type] & in->depth))
        return appm__fail(diag, APPM_ERR_PARSE, name, 0, "PNG: colour type %u with bit depth %u is not legal",
                          in->type, in->depth);
    if (d[10] != 0 || d[11] != 0)
        return appm__fail(diag, APPM_ERR_PARSE, name, 0, "PNG: unknown compression or filter method");
    if (in->interlace > 1)
        return appm__fail(diag, APPM_ERR_PARSE, name, 0, "PNG: unknown interlace method %u", in->interlace);
    return APPM_OK;
}

/* PLTE (11.2.3): n bytes at d.  It comes once, before tRNS and IDAT, never in
 * a grey image, with 1..256 entries, each opaque until tRNS says otherwise. */
static appm_status appm__png_plte(appm__png_info *in, appm__png_scan *sc, const unsigned char *d, uint32_t n,
                                  const char *name, appm_diag *diag)
{
    unsigned i;
    if (sc->seen_plte || sc->seen_idat || in->trns)
        return appm__fail(diag, APPM_ERR_PARSE, name, 0, "PNG: PLTE chunk out of place");
    if (in->type == 0 || in->type == 4)
        return appm__fail(diag, APPM_ERR_PARSE, name, 0, "PNG: PLTE chunk in a greyscale image");
    if (n == 0 || n % 3 != 0 || n > 768)
        return appm__fail(diag, APPM_ERR_PARSE, name, 0, "PNG: PLTE chunk of %lu bytes", (unsigned long)n);
    sc->seen_plte = 1;
    in->npal = n / 3;
    for (i = 0; i < in->npal; ++i) {
        memcpy(in->pal[i], d + 3 * i, 3);
        in->pal[i][3] = 255;
    }
    return APPM_OK;
}

/* tRNS (11.3.2.1): n bytes at d.  It comes once, before IDAT (and after PLTE
 * in a palette image): alphas for the first palette entries, or the 16-bit
 * colour key of a grey or RGB image; an image with an alpha channel may not
 * have one. */
static appm_status appm__png_trns(appm__png_info *in, const appm__png_scan *sc, const unsigned char *d, uint32_t n,
                                  const char *name, appm_diag *diag)
{
    unsigned i;
    if (in->trns || sc->seen_idat) return appm__fail(diag, APPM_ERR_PARSE, name, 0, "PNG: tRNS chunk out of place");
    if (in->type == 3) {
        if (!sc->seen_plte) return appm__fail(diag, APPM_ERR_PARSE, name, 0, "PNG: tRNS chunk before PLTE");
        if (n > in->npal)
            return appm__fail(diag, APPM_ERR_PARSE, name, 0, "PNG: tRNS has more entries than PLTE");
        for (i = 0; i < n; ++i) in->pal[i][3] = d[i];
    } else if (in->type == 0 || in->type == 2) {
        unsigned nc = in->type == 0 ? 1 : 3;
        if (n != 2 * nc)
            return appm__fail(diag, APPM_ERR_PARSE, name, 0, "PNG: tRNS chunk of %lu bytes", (unsigned long)n);
        for (i = 0; i < nc; ++i) in->key[i] = (uint16_t)(d[2 * i] << 8 | d[2 * i + 1]);
    } else {
        return appm__fail(diag, APPM_ERR_PARSE, name, 0, "PNG: tRNS chunk in an image with alpha");
    }
    in->trns = 1;
    return APPM_OK;
}

/* Pass 1 over the chunks, from the one after the signature to IEND: checks
 * every chunk's framing and order, fills in from IHDR, PLTE and tRNS, and
 * notes in sc where the IDAT data is.  Unknown ancillary chunks are skipped;
 * an unknown critical one is refused.  Reads nothing, allocates nothing. */
static appm_status appm__png_chunks(const unsigned char *p, size_t len, appm__png_info *in, appm__png_scan *sc,
                                    const char *name, appm_diag *diag)
{
    size_t at;
    appm_status st;
    for (at = 8; !sc->seen_iend;) {
        uint32_t n = 0;
        const unsigned char *d;
        char ty[5];
        if ((st = appm__png_frame(p, len, at, &n, ty, name, diag)) != APPM_OK) return st;
        d = p + at + 8;
        if (!sc->seen_ihdr && memcmp(ty, "IHDR", 4) != 0)
            return appm__fail(diag, APPM_ERR_PARSE, name, 0, "PNG: first chunk is %s, not IHDR", ty);
        if (sc->seen_idat && memcmp(ty, "IDAT", 4) != 0) sc->idat_done = 1;
        if (memcmp(ty, "IHDR", 4) == 0) {
            if ((st = appm__png_ihdr(in, sc, d, n, name, diag)) != APPM_OK) return st;
        } else if (memcmp(ty, "PLTE", 4) == 0) {
            if ((st = appm__png_plte(in, sc, d, n, name, diag)) != APPM_OK) return st;
        } else if (memcmp(ty, "tRNS", 4) == 0) {
            if ((st = appm__png_trns(in, sc, d, n, name, diag)) != APPM_OK) return st;
        } else if (memcmp(ty, "IDAT", 4) == 0) {
            if (sc->idat_done)
                return appm__fail(diag, APPM_ERR_PARSE, name, 0, "PNG: IDAT chunks are not consecutive");
            if (in->type == 3 && !sc->seen_plte)
                return appm__fail(diag, APPM_ERR_PARSE, name, 0, "PNG: palette image without PLTE");
            if (!sc->seen_idat) sc->idat_first = at;
            sc->seen_idat = 1;
            sc->idat_total += n;
            sc->idat_count++;
            sc->idat_end = at + 12 + (uint64_t)n;
        } else if (memcmp(ty, "IEND", 4) == 0) {
            sc->seen_iend = 1;
        } else if (!((unsigned char)ty[0] & 0x20u)) { /* 5.4: bit 5 of the first byte clear: critical */
            return appm__fail(diag, APPM_ERR_PARSE, name, 0, "PNG: unknown critical chunk %s", ty);
        }
        at += 12 + (size_t)n;
    }
    if (!sc->seen_idat) return appm__fail(diag, APPM_ERR_PARSE, name, 0, "PNG: no IDAT chunk");
    return APPM_OK;
}

/* Sets the channel counts and the sizes, all in 64 bits: *raw, the filtered
 * rows of every pass as the zlib stream must inflate to, and *outbytes, the
 * output.  Refuses sizes the IDAT data could not inflate to, and sizes that do
 * not fit this machine's size_t, before anything is allocated. */
static appm_status appm__png_sizes(appm__png_info *in, size_t idat_total, uint64_t *raw, uint64_t *outbytes,
                                   const char *name, appm_diag *diag)
{
    const unsigned npass = in->interlace ? 7 : 1;
    unsigned pass, bpp_bits;
    in->in_ch = in->type == 0 ? 1 : in->type == 2 ? 3 : in->type == 3 ? 1 : in->type == 4 ? 2 : 4;
    in->out_ch = in->type == 3 ? (in->trns ? 4 : 3) : in->in_ch + (in->trns ? 1 : 0);
    bpp_bits = in->in_ch * in->depth;
    *raw = 0;
    for (pass = 0; pass < npass; ++pass) {
        static const unsigned char whole[4] = {0, 0, 1, 1};
        const unsigned char *ps = in->interlace ? appm__png_adam7[pass] : whole;
        uint64_t pw = appm__png_pass_count(in->w, ps[0], ps[2]), ph = appm__png_pass_count(in->h, ps[1], ps[3]);
        if (pw && ph) *raw += ph * (1 + (pw * bpp_bits + 7) / 8);
    }
    *outbytes = (uint64_t)in->w * in->h * in->out_ch * (in->depth == 16 ? 2 : 1);
    /* Deflate codes a 258-byte match in as little as 2 bits: at most 1032
     * bytes out per byte in.  More than that (plus the zlib framing) cannot be
     * real, and refusing it here keeps a tiny file from claiming gigabytes. */
    if (*raw > 1032u * (uint64_t)idat_total + 64)
        return appm__fail(diag, APPM_ERR_PARSE, name, 0,
                          "PNG: %lux%lu image cannot come from %lu bytes of IDAT data (corrupt or truncated)",
                          (unsigned long)in->w, (unsigned long)in->h, (unsigned long)idat_total);
    if (*raw + idat_total > (uint64_t)SIZE_MAX || *outbytes > (uint64_t)SIZE_MAX)
        return appm__fail(diag, APPM_ERR_NOMEM, name, 0, "PNG: image too large for this machine");
    return APPM_OK;
}

/* Undoes the filters of the inflated rows in scratch, pass by pass, in place,
 * and spreads the pixels into pix.  A row's filter needs the row above it
 * unfiltered, which in-place decoding in row order guarantees.  Refuses an
 * unknown filter type and a palette index past the palette. */
static appm_status appm__png_rows(const appm__png_info *in, unsigned char *scratch, unsigned char *pix,
                                  const char *name, appm_diag *diag)
{
    const unsigned npass = in->interlace ? 7 : 1, bpp_bits = in->in_ch * in->depth;
    const size_t bpp = bpp_bits >= 8 ? bpp_bits / 8 : 1; /* 9.2: bytes per complete pixel, at least 1 */
    unsigned char *row = scratch;
    unsigned pass;
    for (pass = 0; pass < npass; ++pass) {
        static const unsigned char whole[4] = {0, 0, 1, 1};
        const unsigned char *ps = in->interlace ? appm__png_adam7[pass] : whole;
        uint32_t pw = appm__png_pass_count(in->w, ps[0], ps[2]), ph = appm__png_pass_count(in->h, ps[1], ps[3]), y;
        size_t rb = ((size_t)pw * bpp_bits + 7) / 8;
        const unsigned char *up = NULL;
        if (!pw || !ph) continue;
        for (y = 0; y < ph; ++y) {
            unsigned f = row[0], bad;
            if (f > 4)
                return appm__fail(diag, APPM_ERR_PARSE, name, 0, "PNG: bad filter type %u in row %lu%s", f,
                                  (unsigned long)y, in->interlace ? " of an Adam7 pass" : "");
            appm__png_unfilter(f, row + 1, up, rb, bpp);
            if (!in->interlace && in->depth == 8 && in->type != 3 && !in->trns) /* the common case: as stored */
                memcpy(pix + (size_t)y * rb, row + 1, rb);
            else if ((bad = appm__png_spread(in, row + 1, pw, y, ps, pix)) != 0)
                return appm__fail(diag, APPM_ERR_PARSE, name, 0, "PNG: palette index %u out of range", bad - 1);
            up = row + 1;
            row += rb + 1;
        }
    }
    return APPM_OK;
}

static appm_status appm__png_decode(appm__mem *m, const unsigned char *p, size_t len, const char *name,
                                    appm__pixels *out, appm_diag *diag)
{
    static const unsigned char sig[8] = {137, 80, 78, 71, 13, 10, 26, 10};
    appm__png_info in;
    appm__png_scan sc;
    uint64_t raw, outbytes;
    unsigned char *scratch = NULL, *pix = NULL;
    const unsigned char *zsrc;
    const char *err;
    appm_status st;
    memset(out, 0, sizeof *out);
    memset(&in, 0, sizeof in);
    memset(&sc, 0, sizeof sc);
    if (len < 8 || memcmp(p, sig, 8) != 0) return appm__fail(diag, APPM_ERR_PARSE, name, 0, "PNG: bad signature");
    if ((st = appm__png_chunks(p, len, &in, &sc, name, diag)) != APPM_OK) return st;
    if ((st = appm__png_sizes(&in, sc.idat_total, &raw, &outbytes, name, diag)) != APPM_OK) return st;

    /* The scratch: the filtered rows, then (when split over several chunks)
     * the IDAT data joined. */
    scratch = (unsigned char *)appm__alloc(m, (size_t)raw + (sc.idat_count > 1 ? sc.idat_total : 0), 1);
    if (scratch) pix = (unsigned char *)appm__alloc(m, (size_t)outbytes, 1);
    if (!scratch || !pix) {
        appm__free(m, scratch);
        return appm__fail(diag, APPM_ERR_NOMEM, name, 0, "PNG: out of memory");
    }
    if (sc.idat_count > 1) {
        unsigned char *q = scratch + raw;
        size_t at;
        for (at = sc.idat_first; at < sc.idat_end;) {
            uint32_t n = appm__png_be32(p + at);
            memcpy(q, p + at + 8, n);
            q += n;
            at += 12 + (size_t)n;
        }
        zsrc = scratch + raw;
    } else {
        zsrc = p + sc.idat_first + 8;
    }
    if ((err = appm__zlib_inflate(zsrc, sc.idat_total, scratch, (size_t)raw)) != NULL)
        st = appm__fail(diag, APPM_ERR_PARSE, name, 0, "PNG: IDAT: %s", err);
    else
        st = appm__png_rows(&in, scratch, pix, name, diag);
    appm__free(m, scratch);
    if (st != APPM_OK) {
        appm__free(m, pix);
        return st;
    }
    out->w = in.w;
    out->h = in.h;
    out->channels = in.out_ch;
    out->depth = in.depth == 16 ? 16 : 8;
    out->data = pix;
    return APPM_OK;
}

/* ---- 3.8 OpenEXR reader ---------------------------------------------------------
 *
 * Single-part scanline files, as "The OpenEXR File Layout" describes them
 * (and 3.3 writes them): magic, version 2 with no flags we do not know, the
 * header attributes, the line offset table (one 64-bit file offset per block,
 * in increasing-y order whatever the lineOrder), then the blocks, each
 * "int32 y of its first line, int32 byte count, data".  A block holds its lines
 * one after the other; a line holds every channel's samples for the dataWindow
 * width, channel after channel in the order of the channel list (sorted by
 * name).  Everything is little-endian.
 *
 * ZIP (16 lines a block) and ZIPS (1) deflate the block after two reversible
 * steps; RLE runs a byte-wise run-length code before the same two steps: the
 * bytes are split into the even ones then the odd ones, and each stored as the
 * difference from the byte before, + 128.  Any compressor stores a block raw
 * when compression would not make it smaller, which shows as a byte count
 * equal to the raw size.
 *
 * Samples become 32-bit floats: HALF exactly (every half is a float), FLOAT as
 * its bits, UINT rounded to the nearest float. */

/* The file header facts we use. */
typedef struct appm__exr_info {
    int64_t x0, y0;
    uint32_t w, h;
    unsigned compression, line_order, lines; /* lines per block */
    unsigned nch;
    size_t line_bytes;       /* one line of every channel */
    size_t off[5];           /* R G B A Y: byte offset of the channel within a line */
    unsigned type[5];        /* its pixel type */
    int has[5];
} appm__exr_info;

static uint32_t appm__exr_rd32(const unsigned char *p)
{
    return (uint32_t)p[0] | (uint32_t)p[1] << 8 | (uint32_t)p[2] << 16 | (uint32_t)p[3] << 24;
}

/* IEEE half to float, exact: normal halves re-bias the exponent (15 -> 127),
 * subnormal ones (exponent 0) are normalised, since every one is a normal
 * float; infinities and NaNs keep their payload. */
static float appm__exr_half(unsigned h)
{
    uint32_t sign = (uint32_t)(h & 0x8000u) << 16, e = (h >> 10) & 31u, mant = h & 0x3FFu, bits;
    float f;
    if (e == 31) bits = sign | 0x7F800000u | mant << 13;
    else if (e != 0) bits = sign | (e + 112u) << 23 | mant << 13;
    else if (mant == 0) bits = sign;
    else {
        e = 113; /* 2^-14, the exponent of the smallest normal half, biased for float */
        while (!(mant & 0x400u)) {
            mant <<= 1;
            --e;
        }
        bits = sign | e << 23 | (mant & 0x3FFu) << 13;
    }
    memcpy(&f, &bits, 4);
    return f;
}

/* Reads the NUL-terminated string at p[*at..end) of at most `max` characters
 * (plus the NUL); NULL when it does not end in time. */
static const char *appm__exr_str(const unsigned char *p, size_t end, size_t *at, size_t max)
{
    size_t i;
    for (i = *at; i < end && i - *at <= max; ++i)
        if (p[i] == 0) {
            const char *s = (const char *)p + *at;
            *at = i + 1;
            return s;
        }
    return NULL;
}

/* The channel list (chlist): entries of name, int32 pixel type, uint8 pLinear,
 * 3 reserved bytes, int32 x and y sampling; a NUL ends it. */
static appm_status appm__exr_channels(appm__exr_info *e, const unsigned char *v, size_t n, const char *name,
                                      appm_diag *diag)
{
    static const unsigned char bytes[3] = {4, 2, 4}; /* UINT, HALF, FLOAT */
    size_t at = 0, line = 0; /* bytes per pixel of all channels so far */
    for (;;) {
        const char *cn;
        uint32_t type, xs, ys;
        int slot;
        if (at >= n) return appm__fail(diag, APPM_ERR_PARSE, name, 0, "EXR: channel list ends early");
        if (v[at] == 0) break;
        if (!(cn = appm__exr_str(v, n, &at, 255)) || n - at < 16)
            return appm__fail(diag, APPM_ERR_PARSE, name, 0, "EXR: channel list ends early");
        type = appm__exr_rd32(v + at);
        xs = appm__exr_rd32(v + at + 8);
        ys = appm__exr_rd32(v + at + 12);
        at += 16;
        if (type > 2) return appm__fail(diag, APPM_ERR_PARSE, name, 0, "EXR: channel %s has unknown pixel type %lu", cn, (unsigned long)type);
        if (xs != 1 || ys != 1)
            return appm__fail(diag, APPM_ERR_PARSE, name, 0, "EXR: subsampled channel %s is not supported", cn);
        if (++e->nch > 1024) return appm__fail(diag, APPM_ERR_PARSE, name, 0, "EXR: too many channels");
        slot = !strcmp(cn, "R") ? 0 : !strcmp(cn, "G") ? 1 : !strcmp(cn, "B") ? 2 : !strcmp(cn, "A") ? 3 : !strcmp(cn, "Y") ? 4 : -1;
        if (slot >= 0) {
            if (e->has[slot]) return appm__fail(diag, APPM_ERR_PARSE, name, 0, "EXR: channel %s listed twice", cn);
            e->has[slot] = 1;
            e->off[slot] = line; /* scaled by the width once it is known */
            e->type[slot] = type;
        }
        line += bytes[type];
    }
    e->line_bytes = line;
    return APPM_OK;
}

/* Undoes the ZIP/RLE predictor and byte split (t -> o, n bytes). */
static void appm__exr_unpredict(unsigned char *t, unsigned char *o, size_t n)
{
    size_t i, half = (n + 1) / 2;
    for (i = 1; i < n; ++i) t[i] = (unsigned char)(t[i - 1] + t[i] - 128);
    for (i = 0; i < n; ++i) o[i] = (i & 1u) ? t[half + i / 2] : t[i / 2];
}

/* OpenEXR RLE: a signed count byte c; c < 0: -c bytes follow as they are;
 * c >= 0: the next byte, c + 1 times.  Returns 0 unless dst comes out exactly full. */
static int appm__exr_unrle(const unsigned char *s, size_t n, unsigned char *d, size_t want)
{
    size_t i = 0, o = 0;
    while (i < n) {
        int c = s[i] < 128 ? s[i] : (int)s[i] - 256;
        ++i;
        if (c < 0) {
            size_t k = (size_t)-c;
            if (k > n - i || k > want - o) return 0;
            memcpy(d + o, s + i, k);
            i += k;
            o += k;
        } else {
            size_t k = (size_t)c + 1;
            if (i >= n || k > want - o) return 0;
            memset(d + o, s[i++], k);
            o += k;
        }
    }
    return o == want;
}

/* What the block pass needs besides the header: the output channels, where
 * the line offset table is, and the raw size of the largest block. */
typedef struct appm__exr_plan {
    unsigned nout, slot[4]; /* output channels; the i-th is appm__exr_info slot slot[i] (0-4: R G B A Y) */
    size_t table, nblock;   /* the line offset table: its file offset, its entries (one per block) */
    size_t maxblock;        /* raw bytes of the largest block */
} appm__exr_plan;

/* The magic number and the version field: version 2, single-part scanline,
 * no flag this reader does not know (bit 10, long names, is harmless). */
static appm_status appm__exr_version(const unsigned char *p, size_t len, const char *name, appm_diag *diag)
{
    uint32_t version;
    if (len < 8 || appm__exr_rd32(p) != 20000630u) return appm__fail(diag, APPM_ERR_PARSE, name, 0, "EXR: bad magic number");
    version = appm__exr_rd32(p + 4);
    if ((version & 0xFFu) != 2) return appm__fail(diag, APPM_ERR_PARSE, name, 0, "EXR: unknown version %lu", (unsigned long)(version & 0xFFu));
    if (version & 0x200u) return appm__fail(diag, APPM_ERR_PARSE, name, 0, "EXR: tiled files are not supported");
    if (version & 0x800u) return appm__fail(diag, APPM_ERR_PARSE, name, 0, "EXR: deep data files are not supported");
    if (version & 0x1000u) return appm__fail(diag, APPM_ERR_PARSE, name, 0, "EXR: multi-part files are not supported");
    if (version & ~0x4FFu) return appm__fail(diag, APPM_ERR_PARSE, name, 0, "EXR: unknown version flags 0x%lx", (unsigned long)version);
    return APPM_OK;
}

/* The dataWindow box2i at v (int32 xmin, ymin, xmax, ymax, inclusive): its
 * origin and a size in 1..APPM__IMAGE_MAX, computed in 64 bits so that no
 * pair of int32 corners overflows. */
static appm_status appm__exr_window(appm__exr_info *e, const unsigned char *v, const char *name, appm_diag *diag)
{
    int32_t b[4];
    int i;
    for (i = 0; i < 4; ++i) {
        uint32_t u = appm__exr_rd32(v + 4 * i);
        b[i] = u < 0x80000000u ? (int32_t)u : -(int32_t)(0xFFFFFFFFu - u) - 1;
    }
    if ((int64_t)b[2] - b[0] + 1 < 1 || (int64_t)b[2] - b[0] + 1 > APPM__IMAGE_MAX ||
        (int64_t)b[3] - b[1] + 1 < 1 || (int64_t)b[3] - b[1] + 1 > APPM__IMAGE_MAX)
        return appm__fail(diag, APPM_ERR_PARSE, name, 0, "EXR: dataWindow size is outside 1..%u", APPM__IMAGE_MAX);
    e->x0 = b[0];
    e->y0 = b[1];
    e->w = (uint32_t)((int64_t)b[2] - b[0] + 1);
    e->h = (uint32_t)((int64_t)b[3] - b[1] + 1);
    return APPM_OK;
}

/* The header from p[*at] (just after the version): attributes of name, type,
 * int32 size and value, until an empty name, which *at is left just past.
 * channels, compression and dataWindow must each come exactly once; a
 * lineOrder or part type is checked; other attributes are skipped. */
static appm_status appm__exr_attrs(appm__exr_info *e, const unsigned char *p, size_t len, size_t *at,
                                    const char *name, appm_diag *diag)
{
    int seen_ch = 0, seen_cmp = 0, seen_dw = 0;
    appm_status st;
    for (;;) {
        const char *an, *at_type;
        const unsigned char *v;
        uint32_t n;
        if (*at >= len) return appm__fail(diag, APPM_ERR_PARSE, name, 0, "EXR: header ends early");
        if (p[*at] == 0) {
            ++*at;
            break;
        }
        if (!(an = appm__exr_str(p, len, at, 255)) || !(at_type = appm__exr_str(p, len, at, 255)) || len - *at < 4)
            return appm__fail(diag, APPM_ERR_PARSE, name, 0, "EXR: header ends early");
        n = appm__exr_rd32(p + *at);
        *at += 4;
        if (n > len - *at) return appm__fail(diag, APPM_ERR_PARSE, name, 0, "EXR: attribute %s runs past the end", an);
        v = p + *at;
        *at += n;
        if (!strcmp(an, "channels")) {
            if (strcmp(at_type, "chlist") || seen_ch)
                return appm__fail(diag, APPM_ERR_PARSE, name, 0, "EXR: bad channels attribute");
            seen_ch = 1;
            if ((st = appm__exr_channels(e, v, n, name, diag)) != APPM_OK) return st;
        } else if (!strcmp(an, "compression")) {
            if (strcmp(at_type, "compression") || n != 1 || seen_cmp)
                return appm__fail(diag, APPM_ERR_PARSE, name, 0, "EXR: bad compression attribute");
            seen_cmp = 1;
            e->compression = v[0];
        } else if (!strcmp(an, "dataWindow")) {
            if (strcmp(at_type, "box2i") || n != 16 || seen_dw)
                return appm__fail(diag, APPM_ERR_PARSE, name, 0, "EXR: bad dataWindow attribute");
            seen_dw = 1;
            if ((st = appm__exr_window(e, v, name, diag)) != APPM_OK) return st;
        } else if (!strcmp(an, "lineOrder")) {
            if (strcmp(at_type, "lineOrder") || n != 1 || v[0] > 1)
                return appm__fail(diag, APPM_ERR_PARSE, name, 0, "EXR: lineOrder must be INCREASING_Y or DECREASING_Y");
            e->line_order = v[0];
        } else if (!strcmp(an, "type")) {
            if (n < 13 || memcmp(v, "scanlineimage", 13) != 0)
                return appm__fail(diag, APPM_ERR_PARSE, name, 0, "EXR: part type %.*s is not supported (only scanlineimage)",
                                  (int)(n < 32 ? n : 32), (const char *)v);
        }
    }
    if (!seen_ch || !seen_cmp || !seen_dw)
        return appm__fail(diag, APPM_ERR_PARSE, name, 0, "EXR: header lacks %s", !seen_ch ? "channels" : !seen_cmp ? "compression" : "dataWindow");
    return APPM_OK;
}

/* From a complete header: refuses the compressions this reader lacks, picks
 * the output channels (R, G, B and maybe A, else Y) into pl, and turns e's
 * per-pixel channel offsets and line size into per-line ones, once a block
 * of lines is known to fit a quarter of size_t's range. */
static appm_status appm__exr_select(appm__exr_info *e, appm__exr_plan *pl, const char *name, appm_diag *diag)
{
    static const char *const cname[10] = {"NONE", "RLE", "ZIPS", "ZIP", "PIZ", "PXR24", "B44", "B44A", "DWAA", "DWAB"};
    static const unsigned char clines[4] = {1, 1, 1, 16};
    int c;
    if (e->compression > 3)
        return appm__fail(diag, APPM_ERR_PARSE, name, 0, "EXR: %s compression is not supported (only NONE, RLE, ZIPS, ZIP)",
                          e->compression < 10 ? cname[e->compression] : "unknown");
    if (e->has[0] || e->has[1] || e->has[2]) {
        for (c = 0; c < 3; ++c)
            if (!e->has[c])
                return appm__fail(diag, APPM_ERR_PARSE, name, 0, "EXR: channel %c is missing (R, G and B go together)", "RGB"[c]);
        pl->nout = e->has[3] ? 4 : 3;
        pl->slot[0] = 0, pl->slot[1] = 1, pl->slot[2] = 2, pl->slot[3] = 3;
    } else if (e->has[4]) {
        pl->nout = 1;
        pl->slot[0] = 4;
    } else {
        return appm__fail(diag, APPM_ERR_PARSE, name, 0, "EXR: no R, G, B or Y channel");
    }
    e->lines = clines[e->compression];
    /* one line is at most 32768 pixels x 1024 channels x 4 bytes: 2^37, fine in 64 bits */
    if ((uint64_t)e->line_bytes * e->w * e->lines > (uint64_t)SIZE_MAX / 4)
        return appm__fail(diag, APPM_ERR_NOMEM, name, 0, "EXR: image too large for this machine");
    for (c = 0; c < 5; ++c) e->off[c] *= e->w;
    e->line_bytes *= e->w;
    return APPM_OK;
}

/* The line offset table at p[at], and a look at every block before anything
 * is allocated: each must start after the table and lie wholly inside the
 * file.  Sets pl->table and pl->nblock, and *packed to the blocks' data bytes. */
static appm_status appm__exr_table(const appm__exr_info *e, appm__exr_plan *pl, const unsigned char *p, size_t len,
                                   size_t at, uint64_t *packed, const char *name, appm_diag *diag)
{
    size_t k;
    *packed = 0;
    pl->nblock = (e->h + e->lines - 1) / e->lines;
    pl->table = at;
    if ((uint64_t)pl->nblock * 8 > len - at) return appm__fail(diag, APPM_ERR_PARSE, name, 0, "EXR: line offset table runs past the end");
    at += pl->nblock * 8;
    for (k = 0; k < pl->nblock; ++k) {
        const unsigned char *q = p + pl->table + 8 * k;
        uint64_t off = appm__exr_rd32(q) | (uint64_t)appm__exr_rd32(q + 4) << 32;
        uint32_t size;
        if (off < at || off > len || len - off < 8)
            return appm__fail(diag, APPM_ERR_PARSE, name, 0, "EXR: block %lu offset is outside the file", (unsigned long)k);
        size = appm__exr_rd32(p + off + 4);
        if (size > len - off - 8)
            return appm__fail(diag, APPM_ERR_PARSE, name, 0, "EXR: block %lu runs past the end of the file", (unsigned long)k);
        *packed += size;
    }
    return APPM_OK;
}

/* Converts nl raw lines at data (each e->line_bytes, channel after channel)
 * into the float rows of pix from row `row` on, interleaving the chosen
 * channels: HALF exactly, FLOAT as its bits, UINT to the nearest float. */
static void appm__exr_lines(const appm__exr_info *e, const appm__exr_plan *pl, const unsigned char *data, size_t nl,
                            size_t row, float *pix)
{
    const unsigned nout = pl->nout;
    size_t j;
    for (j = 0; j < nl; ++j) {
        const unsigned char *line = data + j * e->line_bytes;
        float *o = pix + (row + j) * e->w * nout;
        unsigned ci;
        for (ci = 0; ci < nout; ++ci) {
            const unsigned char *s = line + e->off[pl->slot[ci]];
            unsigned type = e->type[pl->slot[ci]];
            uint32_t x;
            for (x = 0; x < e->w; ++x) {
                float f;
                if (type == 1) {
                    f = appm__exr_half((unsigned)s[2 * x] | (unsigned)s[2 * x + 1] << 8);
                } else {
                    uint32_t bits = appm__exr_rd32(s + 4 * (size_t)x);
                    if (type == 2) memcpy(&f, &bits, 4);
                    else f = (float)bits;
                }
                o[(size_t)x * nout + ci] = f;
            }
        }
    }
}

/* Decodes every block into pix.  scratch holds, when the file is compressed,
 * the unpacked block (at maxblock) and its unpredicted copy (at 0), then one
 * flag per block.  A block is placed by its own y, which must start a block
 * and come once; a block whose byte count is its raw size is stored raw. */
static appm_status appm__exr_blocks(const appm__exr_info *e, const appm__exr_plan *pl, const unsigned char *p,
                                    unsigned char *scratch, float *pix, const char *name, appm_diag *diag)
{
    const size_t maxblock = pl->maxblock;
    unsigned char *seen = scratch + (e->compression ? 2 * maxblock : 0);
    size_t k;
    for (k = 0; k < pl->nblock; ++k) {
        const unsigned char *q = p + pl->table + 8 * k, *data;
        size_t off = (size_t)(appm__exr_rd32(q) | (uint64_t)appm__exr_rd32(q + 4) << 32);
        uint32_t yu = appm__exr_rd32(p + off), size = appm__exr_rd32(p + off + 4);
        int64_t y = yu < 0x80000000u ? (int64_t)yu : (int64_t)yu - 4294967296;
        int64_t rel = y - e->y0;
        size_t nl, want;
        if (rel < 0 || rel >= (int64_t)e->h || rel % e->lines != 0 || seen[rel / e->lines])
            return appm__fail(diag, APPM_ERR_PARSE, name, 0, "EXR: block %lu has a bad or repeated line number %ld",
                              (unsigned long)k, (long)y);
        seen[rel / e->lines] = 1;
        nl = (size_t)(e->h - rel < e->lines ? e->h - rel : e->lines);
        want = nl * e->line_bytes;
        data = p + off + 8;
        if (size != want) {
            const char *err = NULL;
            if (e->compression == 0) err = "uncompressed block has the wrong size";
            else if (e->compression == 1) {
                if (!appm__exr_unrle(data, size, scratch + maxblock, want)) err = "bad RLE data";
            } else {
                err = appm__zlib_inflate(data, size, scratch + maxblock, want);
            }
            if (err) return appm__fail(diag, APPM_ERR_PARSE, name, 0, "EXR: block at line %ld: %s", (long)y, err);
            appm__exr_unpredict(scratch + maxblock, scratch, want);
            data = scratch;
        }
        appm__exr_lines(e, pl, data, nl, (size_t)rel, pix);
    }
    return APPM_OK;
}

static appm_status appm__exr_decode(appm__mem *m, const unsigned char *p, size_t len, const char *name,
                                    appm__pixels *out, appm_diag *diag)
{
    appm__exr_info e;
    appm__exr_plan pl;
    size_t at = 8, scratch_n;
    uint64_t raw_total, packed_total, outcount;
    unsigned char *scratch = NULL;
    float *pix = NULL;
    appm_status st;
    memset(out, 0, sizeof *out);
    memset(&e, 0, sizeof e);
    memset(&pl, 0, sizeof pl);
    if ((st = appm__exr_version(p, len, name, diag)) != APPM_OK) return st;
    if ((st = appm__exr_attrs(&e, p, len, &at, name, diag)) != APPM_OK) return st;
    if ((st = appm__exr_select(&e, &pl, name, diag)) != APPM_OK) return st;
    if ((st = appm__exr_table(&e, &pl, p, len, at, &packed_total, name, diag)) != APPM_OK) return st;
    raw_total = (uint64_t)e.line_bytes * e.h;
    if (raw_total > 1032u * packed_total + 64u * pl.nblock)
        return appm__fail(diag, APPM_ERR_PARSE, name, 0, "EXR: %lux%lu image cannot come from %lu bytes of data (corrupt or truncated)",
                          (unsigned long)e.w, (unsigned long)e.h, (unsigned long)packed_total);
    outcount = (uint64_t)e.w * e.h * pl.nout;
    if (outcount > (uint64_t)SIZE_MAX / 4)
        return appm__fail(diag, APPM_ERR_NOMEM, name, 0, "EXR: image too large for this machine");
    pl.maxblock = e.line_bytes * (e.h < e.lines ? e.h : e.lines);
    scratch_n = (e.compression ? 2 * pl.maxblock : 0) + pl.nblock;
    scratch = (unsigned char *)appm__alloc(m, scratch_n, 1);
    if (scratch) pix = (float *)appm__alloc(m, (size_t)outcount, sizeof(float));
    if (!scratch || !pix) {
        appm__free(m, scratch);
        return appm__fail(diag, APPM_ERR_NOMEM, name, 0, "EXR: out of memory");
    }
    st = appm__exr_blocks(&e, &pl, p, scratch, pix, name, diag);
    appm__free(m, scratch);
    if (st != APPM_OK) {
        appm__free(m, pix);
        return st;
    }
    out->w = e.w;
    out->h = e.h;
    out->channels = pl.nout;
    out->depth = 32;
    out->data = pix;
    return APPM_OK;
}

/* ---- 3.9 JPEG (ITU T.81 | ISO/IEC 10918-1) --------------------------------
 *
 * Reads the Huffman-coded DCT processes of T.81 at 8-bit precision: baseline
 * (SOF0), extended sequential (SOF1) and progressive (SOF2), with one grey or
 * three colour components.  Lossless, hierarchical and arithmetic-coded files,
 * 12-bit samples, CMYK/YCCK and DNL are refused with a message.
 *
 * The output matches libjpeg-turbo's default decode (djpeg) sample for
 * sample, because every step after entropy decoding copies its arithmetic:
 *   - the accurate integer inverse DCT ("islow": Loeffler-Ligtenberg-Moschytz
 *     with 13-bit constants and 2 extra bits between the passes);
 *   - "fancy" chroma upsampling (a triangle filter, 3/4 of the nearer sample
 *     and 1/4 of the further one, with libjpeg's alternating rounding biases);
 *   - the 16-bit fixed-point YCbCr -> RGB conversion of JFIF.
 * A different rounding anywhere shifts some samples by one level.
 *
 * Memory: a sequential file whose first scan carries every component (the
 * usual case) is decoded MCU row by MCU row straight into the output; each
 * component keeps a ring of three MCU rows of samples, because upsampling an
 * output row needs the sample rows above and below it.  A progressive file
 * (or a sequential one split into several scans) needs every coefficient
 * before any block is final, so it keeps all of them and runs the same
 * row pipeline at EOI.
 *
 * Hostile input: every count read from the file is checked before it is used,
 * all sizes are computed in 64 bits, and an image must not claim more blocks
 * than its file has bits (each block costs at least one bit of DC code), so a
 * small file cannot ask for gigabytes.  A scan that runs out of data is an
 * error, never silently padded: the bit reader feeds zero bits past the end of
 * a segment (the Huffman decoder peeks ahead) but counts them, and any MCU
 * that consumes one fails.
 */
#define APPM__JPEG_FAST 9 /* Huffman codes up to this long decode with one table look-up */

/* Zig-zag order (T.81 figure A.6): the natural (row-major) index of the k-th
 * coefficient in the coded order. */
static const unsigned char appm__jpeg_zigzag[64] = {
    0,  1,  8,  16, 9,  2,  3,  10, 17, 24, 32, 25, 18, 11, 4,  5,  12, 19, 26, 33, 40, 48,
    41, 34, 27, 20, 13, 6,  7,  14, 21, 28, 35, 42, 49, 56, 57, 50, 43, 36, 29, 22, 15, 23,
    30, 37, 44, 51, 58, 59, 52, 45, 38, 31, 39, 46, 53, 60, 61, 54, 47, 55, 62, 63};

/* A canonical Huffman code (T.81 annex C): `fast` maps the next FAST bits to
 * (length << 8 | symbol), 0 where the code is longer; longer codes are found
 * with maxcode[l], the largest code of length l (-1 if none), as in F.2.2.3. */
typedef struct appm__jpeg_huff {
    uint16_t fast[1 << APPM__JPEG_FAST];
    int32_t maxcode[17];
    int32_t valptr[17]; /* symbol index of a length-l code c: valptr[l] + c */
    unsigned char vals[256];
    int defined;
} appm__jpeg_huff;

/* How a component's samples are brought to full resolution: the choice
 * libjpeg makes from the ratio of the largest sampling factor to its own. */
enum { APPM__JPEG_UP_FULL, APPM__JPEG_UP_H2V1, APPM__JPEG_UP_H1V2, APPM__JPEG_UP_H2V2, APPM__JPEG_UP_REPL };

/* The kinds of scan: sequential, and the four progressive refinements of G.1.2. */
enum { APPM__JPEG_SEQ, APPM__JPEG_DC_FIRST, APPM__JPEG_DC_REFINE, APPM__JPEG_AC_FIRST, APPM__JPEG_AC_REFINE };

typedef struct appm__jpeg_comp {
    int id, h, v, tq;        /* from SOF; h = v = 1 forced for a grey image */
    int hr, vr, up;          /* upsampling ratios (max / own) and method */
    int td, ta;              /* Huffman tables of the current scan */
    int latched, scanned;
    uint16_t q[64];          /* quantisation table in natural order, latched at the first scan */
    uint32_t cw, ch;         /* samples actually present: ceil(W * h / hmax) x ceil(H * v / vmax) */
    uint32_t bw, bh;         /* blocks, padded to whole MCUs */
    int32_t dc;              /* DC predictor (F.2.1.3.1), kept to 16 bits as libjpeg's JCOEF */
    int16_t *coef;           /* all bw x bh blocks, or only the current MCU row's v block rows */
    unsigned char *rows;     /* ring of `nrows` sample rows of `stride` bytes */
    size_t stride;
    uint32_t nrows;
    unsigned char *upbuf;    /* one upsampled output row */
} appm__jpeg_comp;

typedef struct appm__jpeg {
    appm__mem *m;
    const char *name;
    appm_diag *diag;
    const unsigned char *p;
    size_t len, pos;
    /* frame */
    int frame;               /* 0 none yet, 1 sequential, 2 progressive */
    uint32_t w, h, mcux, mcuy;
    int nc, hmax, vmax, rgb;
    appm__jpeg_comp comp[3];
    uint64_t blocks;         /* blocks the scans must cover, without MCU padding */
    uint16_t qt[4][64];
    int qt_defined[4];
    appm__jpeg_huff dc[4], ac[4];
    unsigned restart_interval;
    int jfif, adobe, adobe_transform;
    /* decoding state */
    int streaming, full, scans, complete;
    uint64_t visits;         /* blocks visited by all scans so far */
    unsigned char *out;
    /* current scan */
    int ns, kind, ss, se, ah, al;
    appm__jpeg_comp *sc[4];
    /* entropy-coded segment reader (F.2.2.5): bits MSB first in `acc` */
    uint64_t acc;
    int nbits, pad;          /* bits in acc; of them, zero bits made up past the segment's end */
    int hit;                 /* the segment's end (a marker or the end of the file) was reached */
    size_t marker_pos;
    unsigned eobrun;
} appm__jpeg;

#define APPM__JPEG_BAD(d, ...) appm__fail((d)->diag, APPM_ERR_PARSE, (d)->name, 0, __VA_ARGS__)

static appm_status appm__jpeg_nomem(appm__jpeg *d)
{
    return appm__fail(d->diag, APPM_ERR_NOMEM, d->name, 0, "JPEG: out of memory");
}

static unsigned appm__jpeg_u16(const unsigned char *b)
{
    return (unsigned)b[0] << 8 | b[1];
}

/* Two's-complement wrap to 16 bits, as libjpeg stores coefficients (JCOEF);
 * only corrupt files reach values that need it. */
static int16_t appm__jpeg_i16(int32_t v)
{
    uint32_t u = (uint32_t)v & 0xFFFFu;
    return (int16_t)((int32_t)u - (u >= 0x8000u ? 0x10000 : 0));
}

/* -- Marker segments (T.81 B.2) */

/* Builds the decoding tables of one DHT table (T.81 C.2, F.2.2.3). */
static appm_status appm__jpeg_build_huff(appm__jpeg *d, appm__jpeg_huff *t, const unsigned char *counts,
                                         const unsigned char *vals, int nvals, int is_dc, int id)
{
    int32_t code = 0;
    int l, k = 0, i;
    memset(t, 0, sizeof *t);
    memcpy(t->vals, vals, (size_t)nvals);
    for (l = 1; l <= 16; ++l) {
        t->valptr[l] = k - code;
        for (i = 0; i < counts[l - 1]; ++i, ++k, ++code) {
            if (code >= (int32_t)1 << l) break; /* reported below */
            if (is_dc && vals[k] > 15)
                return APPM__JPEG_BAD(d, "JPEG: DC Huffman table %d has symbol %d (above 15)", id, vals[k]);
            if (l <= APPM__JPEG_FAST) {
                int shift = APPM__JPEG_FAST - l, j;
                for (j = 0; j < 1 << shift; ++j)
                    t->fast[(code << shift) + j] = (uint16_t)(l << 8 | vals[k]);
            }
        }
        t->maxcode[l] = counts[l - 1] ? code - 1 : -1;
        /* The code after the last one of length l must still fit in l bits:
         * the all-ones code is reserved (C.2), and more would overflow. */
        if (code >= (int32_t)1 << l)
            return APPM__JPEG_BAD(d, "JPEG: Huffman table %d has more codes than fit their lengths", id);
        code <<= 1;
    }
    t->defined = 1;
    return APPM_OK;
}

static appm_status appm__jpeg_dht(appm__jpeg *d, const unsigned char *s, size_t n)
{
    while (n > 0) {
        int tc, th, total = 0, i;
        appm_status st;
        if (n < 17) return APPM__JPEG_BAD(d, "JPEG: truncated Huffman table (DHT)");
        tc = s[0] >> 4;
        th = s[0] & 15;
        if (tc > 1 || th > 3) return APPM__JPEG_BAD(d, "JPEG: bad Huffman table class/id 0x%02X", s[0]);
        for (i = 1; i <= 16; ++i) total += s[i];
        if (total > 256) return APPM__JPEG_BAD(d, "JPEG: Huffman table %d has %d codes (at most 256)", th, total);
        if ((size_t)total > n - 17) return APPM__JPEG_BAD(d, "JPEG: truncated Huffman table (DHT)");
        st = appm__jpeg_build_huff(d, tc ? &d->ac[th] : &d->dc[th], s + 1, s + 17, total, tc == 0, th);
        if (st != APPM_OK) return st;
        s += 17 + total;
        n -= 17 + (size_t)total;
    }
    return APPM_OK;
}

static appm_status appm__jpeg_dqt(appm__jpeg *d, const unsigned char *s, size_t n)
{
    while (n > 0) {
        int pq = s[0] >> 4, tq = s[0] & 15, k;
        if (pq > 1 || tq > 3) return APPM__JPEG_BAD(d, "JPEG: bad quantisation table precision/id 0x%02X", s[0]);
        if (n < (size_t)(1 + 64 * (pq + 1))) return APPM__JPEG_BAD(d, "JPEG: truncated quantisation table (DQT)");
        /* Table values come in zig-zag order; 16-bit ones (Pq = 1) are big-endian. */
        for (k = 0; k < 64; ++k)
            d->qt[tq][appm__jpeg_zigzag[k]] = (uint16_t)(pq ? appm__jpeg_u16(s + 1 + 2 * k) : s[1 + k]);
        d->qt_defined[tq] = 1;
        s += 1 + 64 * (pq + 1);
        n -= (size_t)(1 + 64 * (pq + 1));
    }
    return APPM_OK;
}

static appm_status appm__jpeg_sof(appm__jpeg *d, int marker, const unsigned char *s, size_t n)
{
    int i, j;
    uint64_t blocks = 0;
    if (d->frame) return APPM__JPEG_BAD(d, "JPEG: more than one frame header (SOF)");
    if (n < 6) return APPM__JPEG_BAD(d, "JPEG: truncated frame header (SOF)");
    if (s[0] != 8) return APPM__JPEG_BAD(d, "JPEG: %d-bit samples not supported (only 8-bit)", s[0]);
    d->h = appm__jpeg_u16(s + 1);
    d->w = appm__jpeg_u16(s + 3);
    d->nc = s[5];
    if (d->h == 0) return APPM__JPEG_BAD(d, "JPEG: height 0 (defined later by a DNL marker) not supported");
    if (d->w == 0) return APPM__JPEG_BAD(d, "JPEG: image width is 0");
    if (d->w > APPM__IMAGE_MAX || d->h > APPM__IMAGE_MAX)
        return APPM__JPEG_BAD(d, "JPEG: %ux%u image is larger than %u", (unsigned)d->w, (unsigned)d->h, APPM__IMAGE_MAX);
    if (d->nc == 2 || d->nc == 4)
        return APPM__JPEG_BAD(d, "JPEG: %d components not supported (only grey or YCbCr/RGB)%s", d->nc,
                              d->nc == 4 ? ", CMYK/YCCK" : "");
    if (d->nc != 1 && d->nc != 3) return APPM__JPEG_BAD(d, "JPEG: %d components not supported", d->nc);
    if (n != 6 + 3 * (size_t)d->nc) return APPM__JPEG_BAD(d, "JPEG: frame header (SOF) has the wrong length");
    d->frame = marker == 0xC2 ? 2 : 1;
    d->hmax = d->vmax = 1;
    for (i = 0; i < d->nc; ++i) {
        appm__jpeg_comp *c = &d->comp[i];
        const unsigned char *q = s + 6 + 3 * i;
        c->id = q[0];
        c->h = q[1] >> 4;
        c->v = q[1] & 15;
        c->tq = q[2];
        if (c->h < 1 || c->h > 4 || c->v < 1 || c->v > 4)
            return APPM__JPEG_BAD(d, "JPEG: component %d has sampling factors %dx%d (1..4 allowed)", c->id, c->h, c->v);
        if (c->tq > 3) return APPM__JPEG_BAD(d, "JPEG: component %d uses quantisation table %d (0..3)", c->id, c->tq);
        for (j = 0; j < i; ++j)
            if (d->comp[j].id == c->id) return APPM__JPEG_BAD(d, "JPEG: two components with id %d", c->id);
        /* A single component's scan is never interleaved, so its sampling
         * factors do not matter (A.2.2): treat it as 1x1, as libjpeg does. */
        if (d->nc == 1) c->h = c->v = 1;
        if (c->h > d->hmax) d->hmax = c->h;
        if (c->v > d->vmax) d->vmax = c->v;
    }
    d->mcux = (d->w + 8u * (unsigned)d->hmax - 1) / (8u * (unsigned)d->hmax);
    d->mcuy = (d->h + 8u * (unsigned)d->vmax - 1) / (8u * (unsigned)d->vmax);
    for (i = 0; i < d->nc; ++i) {
        appm__jpeg_comp *c = &d->comp[i];
        /* libjpeg upsamples by integral ratios only (jdsample.c); 2:1 gets the
         * triangle filter, other ratios plain replication. */
        if (d->hmax % c->h || d->vmax % c->v)
            return APPM__JPEG_BAD(d, "JPEG: component %d: sampling %dx%d against %dx%d is a fractional ratio (not supported)",
                                  c->id, c->h, c->v, d->hmax, d->vmax);
        c->hr = d->hmax / c->h;
        c->vr = d->vmax / c->v;
        c->cw = (uint32_t)(((uint64_t)d->w * (unsigned)c->h + (unsigned)d->hmax - 1) / (unsigned)d->hmax);
        c->ch = (uint32_t)(((uint64_t)d->h * (unsigned)c->v + (unsigned)d->vmax - 1) / (unsigned)d->vmax);
        c->bw = d->mcux * (uint32_t)c->h;
        c->bh = d->mcuy * (uint32_t)c->v;
        if (c->hr == 1 && c->vr == 1) c->up = APPM__JPEG_UP_FULL;
        else if (c->hr == 2 && c->vr == 1) c->up = c->cw > 2 ? APPM__JPEG_UP_H2V1 : APPM__JPEG_UP_REPL;
        else if (c->hr == 1 && c->vr == 2) c->up = APPM__JPEG_UP_H1V2;
        else if (c->hr == 2 && c->vr == 2) c->up = c->cw > 2 ? APPM__JPEG_UP_H2V2 : APPM__JPEG_UP_REPL;
        else c->up = APPM__JPEG_UP_REPL;
        blocks += (uint64_t)((c->cw + 7) / 8) * ((c->ch + 7) / 8);
    }
    /* Every block costs at least one bit in the scan that carries its DC
     * coefficient, so more blocks than bits in the file means a corrupt
     * header (and would make us allocate for nothing). */
    if (blocks > 8 * (uint64_t)d->len + 64)
        return APPM__JPEG_BAD(d, "JPEG: %ux%u image (%.0f blocks) cannot fit in a %.0f-byte file", (unsigned)d->w,
                              (unsigned)d->h, (double)blocks, (double)d->len);
    d->blocks = blocks;
    return APPM_OK;
}

/* -- Entropy-coded segments (T.81 F.2.2, G.2) */

static void appm__jpeg_reset_bits(appm__jpeg *d)
{
    d->acc = 0;
    d->nbits = d->pad = d->hit = 0;
}

/* Tops the bit buffer up to more than 56 bits.  0xFF 0x00 is a stuffed 0xFF
 * data byte (F.1.2.3); 0xFF followed by anything else is a marker (extra 0xFF
 * are fill bytes, B.1.1.2), which ends the segment: from there on zero bits
 * are fed and counted in `pad`. */
static void appm__jpeg_refill(appm__jpeg *d)
{
    while (d->nbits <= 56) {
        unsigned b = 0;
        if (!d->hit) {
            if (d->pos >= d->len) {
                d->hit = 1;
                d->marker_pos = d->len;
            } else if ((b = d->p[d->pos]) != 0xFF) {
                d->pos++;
            } else {
                size_t q = d->pos + 1;
                while (q < d->len && d->p[q] == 0xFF) q++;
                if (q < d->len && d->p[q] == 0) {
                    d->pos = q + 1;
                } else {
                    d->hit = 1;
                    d->marker_pos = d->pos;
                    b = 0;
                }
            }
        }
        if (d->hit) d->pad += 8;
        d->acc |= (uint64_t)b << (56 - d->nbits);
        d->nbits += 8;
    }
}

static unsigned appm__jpeg_bits(appm__jpeg *d, int n)
{
    unsigned v;
    if (d->nbits < n) appm__jpeg_refill(d);
    v = (unsigned)(d->acc >> (64 - n));
    d->acc <<= n;
    d->nbits -= n;
    return v;
}

/* The value of an n-bit magnitude field (F.2.2.1, EXTEND): codes below
 * 2^(n-1) are negative. */
static int32_t appm__jpeg_extend(unsigned v, int n)
{
    return v < (1u << (n - 1)) ? (int32_t)v - ((int32_t)1 << n) + 1 : (int32_t)v;
}

/* Decodes one Huffman symbol; -1 for a bit pattern that is no code. */
static int appm__jpeg_symbol(appm__jpeg *d, const appm__jpeg_huff *t)
{
    unsigned f;
    int l;
    if (d->nbits < 16) appm__jpeg_refill(d);
    f = t->fast[d->acc >> (64 - APPM__JPEG_FAST)];
    if (f) {
        d->acc <<= f >> 8;
        d->nbits -= (int)(f >> 8);
        return (int)(f & 255u);
    }
    for (l = APPM__JPEG_FAST + 1; l <= 16; ++l) {
        int32_t c = (int32_t)(d->acc >> (64 - l));
        if (c <= t->maxcode[l]) {
            d->acc <<= l;
            d->nbits -= l;
            return t->vals[t->valptr[l] + c];
        }
    }
    return -1;
}

static appm_status appm__jpeg_bad_code(appm__jpeg *d)
{
    return APPM__JPEG_BAD(d, "JPEG: corrupt scan data (invalid Huffman code)");
}

/* A sequential block (F.2.2.1, F.2.2.2): the DC difference, then run/size
 * pairs for the AC coefficients up to EOB. */
static appm_status appm__jpeg_block_seq(appm__jpeg *d, appm__jpeg_comp *c, int16_t *blk)
{
    const appm__jpeg_huff *ac = &d->ac[c->ta];
    int t = appm__jpeg_symbol(d, &d->dc[c->td]), k;
    if (t < 0) return appm__jpeg_bad_code(d);
    c->dc = appm__jpeg_i16(c->dc + (t ? appm__jpeg_extend(appm__jpeg_bits(d, t), t) : 0));
    blk[0] = (int16_t)c->dc;
    for (k = 1; k < 64; ++k) {
        int rs = appm__jpeg_symbol(d, ac), r, s;
        if (rs < 0) return appm__jpeg_bad_code(d);
        r = rs >> 4;
        s = rs & 15;
        if (s) {
            k += r;
            if (k > 63) return APPM__JPEG_BAD(d, "JPEG: corrupt scan data (AC run past the end of a block)");
            blk[appm__jpeg_zigzag[k]] = (int16_t)appm__jpeg_extend(appm__jpeg_bits(d, s), s);
        } else if (r == 15) {
            k += 15; /* ZRL: sixteen zeros */
        } else {
            break; /* EOB */
        }
    }
    return APPM_OK;
}

/* Progressive DC scans (G.1.2.1): the first carries the difference of the
 * point-transformed DC (shifted left by Al), each refinement one more bit. */
static appm_status appm__jpeg_block_dc(appm__jpeg *d, appm__jpeg_comp *c, int16_t *blk)
{
    if (d->ah == 0) {
        int t = appm__jpeg_symbol(d, &d->dc[c->td]);
        if (t < 0) return appm__jpeg_bad_code(d);
        c->dc = appm__jpeg_i16(c->dc + (t ? appm__jpeg_extend(appm__jpeg_bits(d, t), t) : 0));
        blk[0] = appm__jpeg_i16(c->dc * ((int32_t)1 << d->al));
    } else if (appm__jpeg_bits(d, 1)) {
        blk[0] = appm__jpeg_i16(blk[0] | ((int32_t)1 << d->al));
    }
    return APPM_OK;
}

/* First AC scan of a band Ss..Se (G.1.2.2): like sequential AC coding, with
 * EOBn codes that end this block and the next EOBRUN - 1 blocks at once. */
static appm_status appm__jpeg_block_ac_first(appm__jpeg *d, appm__jpeg_comp *c, int16_t *blk)
{
    const appm__jpeg_huff *ac = &d->ac[c->ta];
    int k;
    if (d->eobrun > 0) {
        d->eobrun--;
        return APPM_OK;
    }
    for (k = d->ss; k <= d->se; ++k) {
        int rs = appm__jpeg_symbol(d, ac), r, s;
        if (rs < 0) return appm__jpeg_bad_code(d);
        r = rs >> 4;
        s = rs & 15;
        if (s) {
            k += r;
            if (k > d->se) return APPM__JPEG_BAD(d, "JPEG: corrupt scan data (AC run past the end of the band)");
            blk[appm__jpeg_zigzag[k]] = appm__jpeg_i16(appm__jpeg_extend(appm__jpeg_bits(d, s), s) * ((int32_t)1 << d->al));
        } else if (r == 15) {
            k += 15;
        } else {
            d->eobrun = 1u << r;
            if (r) d->eobrun += appm__jpeg_bits(d, r);
            d->eobrun--; /* this block is the first of the run */
            break;
        }
    }
    return APPM_OK;
}

/* Appends a correction bit to a coefficient that is already non-zero: a 1
 * moves it one step of 2^Al away from zero (G.1.2.3). */
static void appm__jpeg_correct(appm__jpeg *d, int16_t *coef)
{
    if (appm__jpeg_bits(d, 1) && (*coef & (1 << d->al)) == 0)
        *coef = appm__jpeg_i16(*coef + (*coef >= 0 ? 1 : -1) * ((int32_t)1 << d->al));
}

/* AC successive-approximation refinement (G.1.2.3).  Each symbol is a run of
 * zero-history coefficients to skip and at most one newly non-zero
 * coefficient (+-2^Al); every already non-zero coefficient passed on the way
 * takes a correction bit.  In an EOB run only the correction bits remain. */
static appm_status appm__jpeg_block_ac_refine(appm__jpeg *d, appm__jpeg_comp *c, int16_t *blk)
{
    const appm__jpeg_huff *ac = &d->ac[c->ta];
    int k = d->ss;
    if (d->eobrun == 0) {
        for (; k <= d->se; ++k) {
            int rs = appm__jpeg_symbol(d, ac), r, s;
            int16_t nz = 0;
            if (rs < 0) return appm__jpeg_bad_code(d);
            r = rs >> 4;
            s = rs & 15;
            if (s) {
                if (s != 1) return APPM__JPEG_BAD(d, "JPEG: corrupt scan data (refinement coefficient of size %d)", s);
                nz = appm__jpeg_i16(appm__jpeg_bits(d, 1) ? (int32_t)1 << d->al : -((int32_t)1 << d->al));
            } else if (r != 15) {
                d->eobrun = 1u << r;
                if (r) d->eobrun += appm__jpeg_bits(d, r);
                break;
            }
            for (; k <= d->se; ++k) {
                int16_t *coef = blk + appm__jpeg_zigzag[k];
                if (*coef) appm__jpeg_correct(d, coef);
                else if (r-- == 0) break;
            }
            if (s) {
                if (k > d->se) return APPM__JPEG_BAD(d, "JPEG: corrupt scan data (AC run past the end of the band)");
                blk[appm__jpeg_zigzag[k]] = nz;
            }
        }
    }
    if (d->eobrun > 0) {
        for (; k <= d->se; ++k)
            if (blk[appm__jpeg_zigzag[k]]) appm__jpeg_correct(d, blk + appm__jpeg_zigzag[k]);
        d->eobrun--;
    }
    return APPM_OK;
}

/* -- Inverse DCT, upsampling, colour (libjpeg-turbo's arithmetic) */

/* Fixed-point constants of jidctint.c: round(x * 2^13). */
#define APPM__JPEG_F0_298 2446
#define APPM__JPEG_F0_390 3196
#define APPM__JPEG_F0_541 4433
#define APPM__JPEG_F0_765 6270
#define APPM__JPEG_F0_899 7373
#define APPM__JPEG_F1_175 9633
#define APPM__JPEG_F1_501 12299
#define APPM__JPEG_F1_847 15137
#define APPM__JPEG_F1_961 16069
#define APPM__JPEG_F2_053 16819
#define APPM__JPEG_F2_562 20995
#define APPM__JPEG_F3_072 25172
/* Rounded division by 2^n for a value of either sign.  C99 leaves the right
 * shift of a negative number to the implementation, so a bias of 2^62 (all
 * values here stay below 2^59 in magnitude, even for corrupt coefficients)
 * makes it non-negative first: floor((x + 2^(n-1)) / 2^n) exactly. */
#define APPM__JPEG_BIAS ((int64_t)1 << 62)
#define APPM__JPEG_DESCALE(x, n) \
    ((((x) + ((int64_t)1 << ((n) - 1)) + APPM__JPEG_BIAS) >> (n)) - (APPM__JPEG_BIAS >> (n)))

static unsigned char appm__jpeg_clamp(int64_t v)
{
    return (unsigned char)(v < 0 ? 0 : v > 255 ? 255 : v);
}

/* One 1-D 8-point inverse DCT (jidctint.c): the even part is a rotation by
 * sqrt(2) c6 plus butterflies, the odd part figure 8 of Loeffler et al.
 * in[i * step] holds the dequantised inputs, o[] gets the 8 outputs still
 * scaled by 2^13 (the caller descales). */
static void appm__jpeg_idct_1d(const int64_t *in, int step, int64_t *o)
{
    int64_t z1, z2, z3, z4, z5, t0, t1, t2, t3, t10, t11, t12, t13;
    z2 = in[2 * step];
    z3 = in[6 * step];
    z1 = (z2 + z3) * APPM__JPEG_F0_541;
    t2 = z1 - z3 * APPM__JPEG_F1_847;
    t3 = z1 + z2 * APPM__JPEG_F0_765;
    t0 = (in[0] + in[4 * step]) * 8192;
    t1 = (in[0] - in[4 * step]) * 8192;
    t10 = t0 + t3;
    t13 = t0 - t3;
    t11 = t1 + t2;
    t12 = t1 - t2;
    t0 = in[7 * step];
    t1 = in[5 * step];
    t2 = in[3 * step];
    t3 = in[1 * step];
    z1 = t0 + t3;
    z2 = t1 + t2;
    z3 = t0 + t2;
    z4 = t1 + t3;
    z5 = (z3 + z4) * APPM__JPEG_F1_175;
    t0 *= APPM__JPEG_F0_298;
    t1 *= APPM__JPEG_F2_053;
    t2 *= APPM__JPEG_F3_072;
    t3 *= APPM__JPEG_F1_501;
    z1 *= -APPM__JPEG_F0_899;
    z2 *= -APPM__JPEG_F2_562;
    z3 = z3 * -APPM__JPEG_F1_961 + z5;
    z4 = z4 * -APPM__JPEG_F0_390 + z5;
    t0 += z1 + z3;
    t1 += z2 + z4;
    t2 += z2 + z3;
    t3 += z1 + z4;
    o[0] = t10 + t3;
    o[7] = t10 - t3;
    o[1] = t11 + t2;
    o[6] = t11 - t2;
    o[2] = t12 + t1;
    o[5] = t12 - t1;
    o[3] = t13 + t0;
    o[4] = t13 - t0;
}

/* Dequantises and inverse-transforms one block into 8 rows of `out`.  Pass 1
 * (columns) keeps 2 fraction bits (PASS1_BITS), pass 2 (rows) removes them
 * together with the 2^13 of the constants and the 8 of the DCT's scale; the
 * +128 level shift (A.3.1) and the clamp to 0..255 come last.  A column or
 * row whose AC terms are all zero is constant, so it is filled directly (the
 * same values the full transform would give). */
static void appm__jpeg_idct(const int16_t *blk, const uint16_t *q, unsigned char *out, size_t stride)
{
    int64_t in[64], ws[64], o[8];
    int i, j;
    for (i = 0; i < 64; ++i) in[i] = (int64_t)blk[i] * q[i];
    for (j = 0; j < 8; ++j) {
        const int64_t *c = in + j;
        if (!c[8] && !c[16] && !c[24] && !c[32] && !c[40] && !c[48] && !c[56]) {
            for (i = 0; i < 8; ++i) ws[8 * i + j] = c[0] * 4;
            continue;
        }
        appm__jpeg_idct_1d(c, 8, o);
        for (i = 0; i < 8; ++i) ws[8 * i + j] = APPM__JPEG_DESCALE(o[i], 13 - 2);
    }
    for (i = 0; i < 8; ++i) {
        const int64_t *r = ws + 8 * i;
        unsigned char *dst = out + (size_t)i * stride;
        if (!r[1] && !r[2] && !r[3] && !r[4] && !r[5] && !r[6] && !r[7]) {
            unsigned char v = appm__jpeg_clamp(APPM__JPEG_DESCALE(r[0], 2 + 3) + 128);
            memset(dst, v, 8);
            continue;
        }
        appm__jpeg_idct_1d(r, 1, o);
        for (j = 0; j < 8; ++j) dst[j] = appm__jpeg_clamp(APPM__JPEG_DESCALE(o[j], 13 + 2 + 3) + 128);
    }
}

static unsigned char *appm__jpeg_row(appm__jpeg_comp *c, uint32_t r)
{
    return c->rows + (size_t)(r % c->nrows) * c->stride;
}

/* Component c's samples for output row y, at full resolution (jdsample.c).
 * The triangle filters weigh the nearer input sample 3/4 and the further
 * 1/4; libjpeg alternates the rounding bias between the two outputs of each
 * input so that errors do not all lean one way.  At the image's edges the
 * outermost real row or column stands in for its missing neighbour. */
static const unsigned char *appm__jpeg_upsample(appm__jpeg *d, appm__jpeg_comp *c, uint32_t y)
{
    unsigned char *u = c->upbuf;
    uint32_t x, n = c->cw;
    const unsigned char *a, *b;
    if (c->up == APPM__JPEG_UP_FULL) return appm__jpeg_row(c, y);
    if (c->up == APPM__JPEG_UP_REPL) {
        a = appm__jpeg_row(c, y / (uint32_t)c->vr);
        for (x = 0; x < d->w; ++x) u[x] = a[x / (uint32_t)c->hr];
        return u;
    }
    if (c->up == APPM__JPEG_UP_H2V1) {
        a = appm__jpeg_row(c, y);
        u[0] = a[0];
        u[1] = (unsigned char)((a[0] * 3 + a[1] + 2) >> 2);
        for (x = 1; x + 1 < n; ++x) {
            int v = a[x] * 3;
            u[2 * x] = (unsigned char)((v + a[x - 1] + 1) >> 2);
            u[2 * x + 1] = (unsigned char)((v + a[x + 1] + 2) >> 2);
        }
        u[2 * x] = (unsigned char)((a[x] * 3 + a[x - 1] + 1) >> 2);
        u[2 * x + 1] = a[x];
        return u;
    }
    /* Vertical 2:1: output row y lies in input row y/2, nearer its upper
     * neighbour when y is even. */
    a = appm__jpeg_row(c, y >> 1);
    if (y & 1) b = appm__jpeg_row(c, (y >> 1) + 1 < c->ch ? (y >> 1) + 1 : c->ch - 1);
    else b = appm__jpeg_row(c, (y >> 1) > 0 ? (y >> 1) - 1 : 0);
    if (c->up == APPM__JPEG_UP_H1V2) {
        int bias = (y & 1) ? 2 : 1;
        for (x = 0; x < n; ++x) u[x] = (unsigned char)((a[x] * 3 + b[x] + bias) >> 2);
        return u;
    } else {
        /* h2v2: column sums 3 near + far first, then the same 3:1 across with
         * the 1/16 scale, biases 8 and 7. */
        int last = a[0] * 3 + b[0], cur = last, next;
        for (x = 0; x < n; ++x) {
            next = x + 1 < n ? a[x + 1] * 3 + b[x + 1] : cur;
            u[2 * x] = (unsigned char)((cur * 3 + last + 8) >> 4);
            u[2 * x + 1] = (unsigned char)((cur * 3 + next + 7) >> 4);
            last = cur;
            cur = next;
        }
        return u;
    }
}

/* YCbCr -> RGB as JFIF defines it, in libjpeg's 16-bit fixed point
 * (jdcolor.c): R = Y + 1.402 Cr, G = Y - 0.34414 Cb - 0.71414 Cr,
 * B = Y + 1.772 Cb with Cb, Cr centred on 128, each product rounded half up.
 * The +512 * 2^16 keeps the shifted value non-negative (see DESCALE). */
#define APPM__JPEG_FLOOR16(v) ((((v) + ((int32_t)512 << 16)) >> 16) - 512)

static void appm__jpeg_emit_row(appm__jpeg *d, uint32_t y)
{
    const unsigned char *s[3];
    unsigned char *o = d->out + (size_t)y * d->w * (unsigned)d->nc;
    uint32_t x;
    int i;
    for (i = 0; i < d->nc; ++i) s[i] = appm__jpeg_upsample(d, &d->comp[i], y);
    if (d->nc == 1) {
        memcpy(o, s[0], d->w);
    } else if (d->rgb) {
        for (x = 0; x < d->w; ++x, o += 3) {
            o[0] = s[0][x];
            o[1] = s[1][x];
            o[2] = s[2][x];
        }
    } else {
        for (x = 0; x < d->w; ++x, o += 3) {
            int32_t yy = s[0][x], cb = s[1][x] - 128, cr = s[2][x] - 128;
            o[0] = appm__jpeg_clamp(yy + APPM__JPEG_FLOOR16(91881 * cr + 32768));
            o[1] = appm__jpeg_clamp(yy + APPM__JPEG_FLOOR16(-22554 * cb - 46802 * cr + 32768));
            o[2] = appm__jpeg_clamp(yy + APPM__JPEG_FLOOR16(116130 * cb + 32768));
        }
    }
}

static int16_t *appm__jpeg_block(appm__jpeg *d, appm__jpeg_comp *c, uint32_t brow, uint32_t bcol)
{
    uint32_t r = d->streaming ? brow % (uint32_t)c->v : brow;
    return c->coef + ((size_t)r * c->bw + bcol) * 64;
}

/* MCU row k is in: transform its blocks into the sample rings, then write
 * the output rows of MCU row k - 1, whose upsampling may look one sample row
 * into row k (and row k itself when it is the last). */
static void appm__jpeg_mcu_row_done(appm__jpeg *d, uint32_t k)
{
    uint32_t rowh = 8u * (uint32_t)d->vmax, y, y1, first;
    int i;
    for (i = 0; i < d->nc; ++i) {
        appm__jpeg_comp *c = &d->comp[i];
        uint32_t by, bx;
        for (by = k * (uint32_t)c->v; by < (k + 1) * (uint32_t)c->v; ++by) {
            unsigned char *dst = appm__jpeg_row(c, by * 8);
            for (bx = 0; bx < c->bw; ++bx)
                appm__jpeg_idct(appm__jpeg_block(d, c, by, bx), c->q, dst + 8 * (size_t)bx, c->stride);
        }
    }
    first = k > 0 ? k - 1 : 0;
    y1 = k + 1 == d->mcuy ? d->h : k * rowh;
    for (y = first * rowh; y < y1 && y < d->h; ++y) appm__jpeg_emit_row(d, y);
}

/* Finds the marker that ends the current entropy-coded segment and leaves
 * d->pos on its first 0xFF.  Whole bytes left before it are skipped, as
 * libjpeg does; consumed made-up bits mean the data ran out. */
static appm_status appm__jpeg_segment_end(appm__jpeg *d)
{
    if (d->nbits < d->pad)
        return APPM__JPEG_BAD(d, d->marker_pos >= d->len ? "JPEG: truncated scan data"
                                                          : "JPEG: corrupt scan data (ends early at a marker)");
    if (!d->hit) {
        size_t q = d->pos;
        for (;;) {
            if (q >= d->len) break;
            if (d->p[q] == 0xFF) {
                size_t r = q + 1;
                while (r < d->len && d->p[r] == 0xFF) r++;
                if (r < d->len && d->p[r] == 0) {
                    q = r + 1;
                    continue;
                }
                break;
            }
            q++;
        }
        d->marker_pos = q;
    }
    d->pos = d->marker_pos;
    appm__jpeg_reset_bits(d);
    return APPM_OK;
}

/* A restart marker RSTm (F.1.2.3) ends each interval: the bit stream
 * restarts byte-aligned with the DC predictions and EOBRUN reset. */
static appm_status appm__jpeg_restart(appm__jpeg *d, int *next)
{
    appm_status st = appm__jpeg_segment_end(d);
    size_t q = d->pos;
    int i;
    if (st != APPM_OK) return st;
    while (q < d->len && d->p[q] == 0xFF) q++;
    if (q >= d->len) return APPM__JPEG_BAD(d, "JPEG: truncated scan data (restart marker missing)");
    if (d->p[q] != 0xD0 + *next)
        return APPM__JPEG_BAD(d, "JPEG: expected restart marker RST%d, found 0xFF%02X", *next, d->p[q]);
    d->pos = q + 1;
    *next = (*next + 1) & 7;
    for (i = 0; i < d->nc; ++i) d->comp[i].dc = 0;
    d->eobrun = 0;
    return APPM_OK;
}

static appm_status appm__jpeg_decode_block(appm__jpeg *d, appm__jpeg_comp *c, uint32_t brow, uint32_t bcol)
{
    int16_t *blk = appm__jpeg_block(d, c, brow, bcol);
    switch (d->kind) {
    case APPM__JPEG_SEQ: return appm__jpeg_block_seq(d, c, blk);
    case APPM__JPEG_AC_FIRST: return appm__jpeg_block_ac_first(d, c, blk);
    case APPM__JPEG_AC_REFINE: return appm__jpeg_block_ac_refine(d, c, blk);
    default: return appm__jpeg_block_dc(d, c, blk);
    }
}

/* Decodes the entropy-coded data of one scan.  An interleaved scan (several
 * components) walks the MCUs of the frame, each holding h x v blocks of every
 * component in turn (A.2.3); a single-component scan walks that component's
 * own blocks, ceil(cw / 8) x ceil(ch / 8), without the MCU padding (A.2.2). */
static appm_status appm__jpeg_scan(appm__jpeg *d)
{
    uint32_t nx, ny, mx, my;
    unsigned todo = d->restart_interval;
    int next_rst = 0, i;
    appm_status st;
    appm__jpeg_reset_bits(d);
    d->eobrun = 0;
    for (i = 0; i < d->nc; ++i) d->comp[i].dc = 0;
    if (d->ns == 1) {
        nx = (d->sc[0]->cw + 7) / 8;
        ny = (d->sc[0]->ch + 7) / 8;
    } else {
        nx = d->mcux;
        ny = d->mcuy;
    }
    /* Bounds the work of many scans over a big image (an attack on progressive
     * decoders): ordinary files visit each block well under 16 times. */
    if (d->ns == 1) d->visits += (uint64_t)nx * ny;
    else
        for (i = 0; i < d->ns; ++i) d->visits += (uint64_t)d->sc[i]->bw * d->sc[i]->bh;
    if (d->visits > 64 * d->blocks + 4096) return APPM__JPEG_BAD(d, "JPEG: too many scans for the image size");
    for (my = 0; my < ny; ++my) {
        if (d->streaming)
            for (i = 0; i < d->nc; ++i)
                memset(d->comp[i].coef, 0, (size_t)d->comp[i].bw * (unsigned)d->comp[i].v * 64 * sizeof(int16_t));
        for (mx = 0; mx < nx; ++mx) {
            if (d->restart_interval) {
                if (todo == 0) {
                    if ((st = appm__jpeg_restart(d, &next_rst)) != APPM_OK) return st;
                    todo = d->restart_interval;
                }
                todo--;
            }
            if (d->ns == 1) {
                if ((st = appm__jpeg_decode_block(d, d->sc[0], my, mx)) != APPM_OK) return st;
            } else {
                for (i = 0; i < d->ns; ++i) {
                    appm__jpeg_comp *c = d->sc[i];
                    int bx, by;
                    for (by = 0; by < c->v; ++by)
                        for (bx = 0; bx < c->h; ++bx) {
                            st = appm__jpeg_decode_block(d, c, my * (uint32_t)c->v + (uint32_t)by,
                                                         mx * (uint32_t)c->h + (uint32_t)bx);
                            if (st != APPM_OK) return st;
                        }
                }
            }
            if (d->nbits < d->pad) return appm__jpeg_segment_end(d); /* reports the truncation */
        }
        if (d->streaming) appm__jpeg_mcu_row_done(d, my);
    }
    return appm__jpeg_segment_end(d);
}

/* Allocates the output and the per-component buffers at the first scan. */
static appm_status appm__jpeg_setup(appm__jpeg *d)
{
    uint64_t need = (uint64_t)d->w * d->h * (unsigned)d->nc;
    int i;
    if (need > SIZE_MAX) return appm__jpeg_nomem(d);
    d->out = (unsigned char *)appm__alloc(d->m, (size_t)need, 1);
    if (!d->out) return appm__jpeg_nomem(d);
    for (i = 0; i < d->nc; ++i) {
        appm__jpeg_comp *c = &d->comp[i];
        uint64_t nblk = (uint64_t)c->bw * (d->full ? c->bh : (uint32_t)c->v);
        if (nblk > SIZE_MAX / 128) return appm__jpeg_nomem(d);
        c->coef = (int16_t *)appm__alloc(d->m, (size_t)nblk * 64, sizeof(int16_t));
        c->stride = (size_t)c->bw * 8;
        c->nrows = 3u * 8u * (uint32_t)c->v;
        c->rows = (unsigned char *)appm__alloc(d->m, c->stride, c->nrows);
        if (!c->coef || !c->rows) return appm__jpeg_nomem(d);
        if (c->up != APPM__JPEG_UP_FULL) {
            c->upbuf = (unsigned char *)appm__alloc(d->m, (size_t)d->mcux * 8 * (unsigned)d->hmax + 8, 1);
            if (!c->upbuf) return appm__jpeg_nomem(d);
        }
    }
    return APPM_OK;
}

/* Which colour space three components are in, decided as libjpeg does
 * (jdapimin.c): a JFIF marker means YCbCr; else an Adobe APP14 marker's
 * transform flag (0: no transform, RGB); else component ids 'R' 'G' 'B'
 * mean RGB; anything else is taken to be YCbCr. */
static int appm__jpeg_is_rgb(const appm__jpeg *d)
{
    if (d->nc != 3 || d->jfif) return 0;
    if (d->adobe) return d->adobe_transform == 0;
    return d->comp[0].id == 'R' && d->comp[1].id == 'G' && d->comp[2].id == 'B';
}

static appm_status appm__jpeg_sos(appm__jpeg *d, const unsigned char *s, size_t n)
{
    int i, j, blocks = 0;
    appm_status st;
    if (!d->frame) return APPM__JPEG_BAD(d, "JPEG: scan (SOS) before the frame header (SOF)");
    if (d->complete) return APPM__JPEG_BAD(d, "JPEG: extra scan after the image was complete");
    if (n < 1 || s[0] < 1 || s[0] > 4 || n != 4 + 2 * (size_t)s[0])
        return APPM__JPEG_BAD(d, "JPEG: malformed scan header (SOS)");
    d->ns = s[0];
    for (i = 0; i < d->ns; ++i) {
        int id = s[1 + 2 * i];
        appm__jpeg_comp *c = NULL;
        for (j = 0; j < d->nc; ++j)
            if (d->comp[j].id == id) c = &d->comp[j];
        if (!c) return APPM__JPEG_BAD(d, "JPEG: scan uses component %d, which the frame does not have", id);
        for (j = 0; j < i; ++j)
            if (d->sc[j] == c) return APPM__JPEG_BAD(d, "JPEG: component %d appears twice in a scan", id);
        c->td = s[2 + 2 * i] >> 4;
        c->ta = s[2 + 2 * i] & 15;
        if (c->td > 3 || c->ta > 3) return APPM__JPEG_BAD(d, "JPEG: scan selects Huffman table 0x%02X", s[2 + 2 * i]);
        d->sc[i] = c;
        blocks += c->h * c->v;
    }
    d->ss = s[1 + 2 * d->ns];
    d->se = s[2 + 2 * d->ns];
    d->ah = s[3 + 2 * d->ns] >> 4;
    d->al = s[3 + 2 * d->ns] & 15;
    if (d->ns > 1 && blocks > 10) return APPM__JPEG_BAD(d, "JPEG: %d blocks per MCU (at most 10)", blocks);
    if (d->frame == 1) {
        /* Ss, Se, Ah, Al mean nothing in a sequential scan; libjpeg ignores them too. */
        d->kind = APPM__JPEG_SEQ;
        for (i = 0; i < d->ns; ++i) {
            if (d->sc[i]->scanned)
                return APPM__JPEG_BAD(d, "JPEG: component %d in two sequential scans", d->sc[i]->id);
            d->sc[i]->scanned = 1;
        }
    } else {
        /* The progression rules of G.1.1.1.1. */
        if (d->ss == 0 ? d->se != 0 : (d->ss > d->se || d->se > 63 || d->ns != 1) ||
            (d->ah != 0 && d->al != d->ah - 1) || d->al > 13)
            return APPM__JPEG_BAD(d, "JPEG: invalid progressive scan (Ss %d, Se %d, Ah %d, Al %d, %d components)",
                                  d->ss, d->se, d->ah, d->al, d->ns);
        d->kind = d->ss == 0 ? (d->ah ? APPM__JPEG_DC_REFINE : APPM__JPEG_DC_FIRST)
                             : (d->ah ? APPM__JPEG_AC_REFINE : APPM__JPEG_AC_FIRST);
    }
    for (i = 0; i < d->ns; ++i) {
        appm__jpeg_comp *c = d->sc[i];
        if ((d->kind == APPM__JPEG_SEQ || d->kind == APPM__JPEG_DC_FIRST) && !d->dc[c->td].defined)
            return APPM__JPEG_BAD(d, "JPEG: DC Huffman table %d not defined", c->td);
        if ((d->kind == APPM__JPEG_SEQ || d->kind >= APPM__JPEG_AC_FIRST) && !d->ac[c->ta].defined)
            return APPM__JPEG_BAD(d, "JPEG: AC Huffman table %d not defined", c->ta);
        /* libjpeg takes a component's table when its first scan starts; a
         * DQT after that does not change it. */
        if (!c->latched) {
            if (!d->qt_defined[c->tq]) return APPM__JPEG_BAD(d, "JPEG: quantisation table %d not defined", c->tq);
            memcpy(c->q, d->qt[c->tq], sizeof c->q);
            c->latched = 1;
        }
    }
    if (d->scans++ == 0) {
        d->streaming = d->frame == 1 && d->ns == d->nc;
        d->full = !d->streaming;
        d->rgb = appm__jpeg_is_rgb(d);
        if ((st = appm__jpeg_setup(d)) != APPM_OK) return st;
    }
    if ((st = appm__jpeg_scan(d)) != APPM_OK) return st;
    if (d->streaming) d->complete = 1;
    return APPM_OK;
}

static appm_status appm__jpeg_eoi(appm__jpeg *d)
{
    uint32_t k;
    int i;
    if (!d->frame) return APPM__JPEG_BAD(d, "JPEG: no image (EOI before any frame header)");
    if (!d->scans) return APPM__JPEG_BAD(d, "JPEG: no scan data");
    if (d->frame == 1)
        for (i = 0; i < d->nc; ++i)
            if (!d->comp[i].scanned) return APPM__JPEG_BAD(d, "JPEG: component %d has no scan", d->comp[i].id);
    if (d->full)
        for (k = 0; k < d->mcuy; ++k) appm__jpeg_mcu_row_done(d, k);
    return APPM_OK;
}

static appm_status appm__jpeg_markers(appm__jpeg *d)
{
    if (d->len < 2 || d->p[0] != 0xFF || d->p[1] != 0xD8)
        return APPM__JPEG_BAD(d, "JPEG: not a JPEG file (no SOI marker)");
    d->pos = 2;
    for (;;) {
        int mk;
        size_t n = 0;
        const unsigned char *s = NULL;
        appm_status st = APPM_OK;
        if (d->pos >= d->len) return APPM__JPEG_BAD(d, "JPEG: truncated file (no EOI marker)");
        if (d->p[d->pos] != 0xFF)
            return APPM__JPEG_BAD(d, "JPEG: expected a marker at byte %.0f, found 0x%02X", (double)d->pos,
                                  d->p[d->pos]);
        while (d->pos < d->len && d->p[d->pos] == 0xFF) d->pos++; /* fill bytes */
        if (d->pos >= d->len) return APPM__JPEG_BAD(d, "JPEG: truncated file (no EOI marker)");
        mk = d->p[d->pos++];
        if (mk == 0xD9) return appm__jpeg_eoi(d);
        if ((mk >= 0xD0 && mk <= 0xD7) || mk == 0x01) continue; /* RSTn, TEM: no segment */
        if (mk == 0x00 || mk == 0xD8) return APPM__JPEG_BAD(d, "JPEG: unexpected marker 0xFF%02X", mk);
        if (d->len - d->pos < 2) return APPM__JPEG_BAD(d, "JPEG: truncated marker 0xFF%02X", mk);
        n = appm__jpeg_u16(d->p + d->pos);
        if (n < 2) return APPM__JPEG_BAD(d, "JPEG: marker 0xFF%02X has length %u", mk, (unsigned)n);
        if (n > d->len - d->pos) return APPM__JPEG_BAD(d, "JPEG: truncated marker 0xFF%02X segment", mk);
        s = d->p + d->pos + 2;
        n -= 2;
        d->pos += n + 2;
        switch (mk) {
        case 0xC0: case 0xC1: case 0xC2: st = appm__jpeg_sof(d, mk, s, n); break;
        case 0xC4: st = appm__jpeg_dht(d, s, n); break;
        case 0xDB: st = appm__jpeg_dqt(d, s, n); break;
        case 0xDA: st = appm__jpeg_sos(d, s, n); break;
        case 0xDD:
            if (n != 2) return APPM__JPEG_BAD(d, "JPEG: restart interval (DRI) segment has the wrong length");
            d->restart_interval = appm__jpeg_u16(s);
            break;
        case 0xE0:
            if (n >= 14 && memcmp(s, "JFIF", 5) == 0) d->jfif = 1;
            break;
        case 0xEE:
            if (n >= 12 && memcmp(s, "Adobe", 5) == 0) {
                d->adobe = 1;
                d->adobe_transform = s[11];
            }
            break;
        case 0xC3: return APPM__JPEG_BAD(d, "JPEG: lossless JPEG (SOF3) not supported");
        case 0xC5: case 0xC6: case 0xC7: case 0xDE: case 0xDF:
            return APPM__JPEG_BAD(d, "JPEG: hierarchical JPEG (marker 0xFF%02X) not supported", mk);
        case 0xC9: case 0xCA: case 0xCB: case 0xCD: case 0xCE: case 0xCF: case 0xCC:
            return APPM__JPEG_BAD(d, "JPEG: arithmetic coding (marker 0xFF%02X) not supported", mk);
        case 0xDC: return APPM__JPEG_BAD(d, "JPEG: DNL marker (height given after the scan) not supported");
        default:
            if ((mk >= 0xE1 && mk <= 0xEF) || mk == 0xFE) break; /* APPn (EXIF, ICC, ...), COM: skipped */
            return APPM__JPEG_BAD(d, "JPEG: unsupported marker 0xFF%02X", mk);
        }
        if (st != APPM_OK) return st;
    }
}

static void appm__jpeg_release(appm__jpeg *d)
{
    int i;
    for (i = 0; i < 3; ++i) {
        appm__free(d->m, d->comp[i].coef);
        appm__free(d->m, d->comp[i].rows);
        appm__free(d->m, d->comp[i].upbuf);
    }
    appm__free(d->m, d->out);
    appm__free(d->m, d);
}

/* Decodes the JPEG file p[0..len) into 8-bit grey (1 channel) or RGB (3),
 * row 0 at the top.  EXIF orientation is not applied: the pixels are as
 * stored. */
static appm_status appm__jpeg_decode(appm__mem *m, const unsigned char *p, size_t len, const char *name,
                                     appm__pixels *out, appm_diag *diag)
{
    appm__jpeg *d;
    appm_status st;
    memset(out, 0, sizeof *out);
    d = (appm__jpeg *)appm__alloc(m, 1, sizeof *d);
    if (!d) return appm__fail(diag, APPM_ERR_NOMEM, name, 0, "JPEG: out of memory");
    d->m = m;
    d->name = name;
    d->diag = diag;
    d->p = p;
    d->len = p ? len : 0;
    st = appm__jpeg_markers(d);
    if (st == APPM_OK) {
        out->w = d->w;
        out->h = d->h;
        out->channels = (unsigned)d->nc;
        out->depth = 8;
        out->data = d->out;
        d->out = NULL;
    }
    appm__jpeg_release(d);
    return st;
}
/* ---- 3.10 Any image: the decoder by the first bytes ----------------------- */

static appm_status appm__pfm_decode(appm__mem *m, const unsigned char *p, size_t len, const char *name,
                                    appm__pixels *out, appm_diag *diag)
{
    appm_image img;
    appm_status st = appm__pfm_parse(m, p, len, name, &img, diag);
    if (st != APPM_OK) return st;
    out->w = img.width;
    out->h = img.height;
    out->channels = 3;
    out->depth = 32;
    out->data = img.rgb;
    return APPM_OK;
}

typedef appm_status (*appm__decode_fn)(appm__mem *m, const unsigned char *p, size_t len, const char *name,
                                       appm__pixels *out, appm_diag *diag);

/* The decoder for a file that starts with p[0..len) and is called `name`, or
 * NULL when it is no format appm reads. */
static appm__decode_fn appm__image_format(const unsigned char *p, size_t len, const char *name,
                                          const char **format)
{
    static const unsigned char png[8] = {0x89, 'P', 'N', 'G', 13, 10, 26, 10};
    static const unsigned char exr[4] = {0x76, 0x2f, 0x31, 0x01};
    *format = "PFM";
    if (len >= 2 && p[0] == 'P' && (p[1] == 'F' || p[1] == 'f')) return appm__pfm_decode;
    *format = "PNG";
    if (len >= 8 && memcmp(p, png, 8) == 0) return appm__png_decode;
    *format = "OpenEXR";
    if (len >= 4 && memcmp(p, exr, 4) == 0) return appm__exr_decode;
    *format = "JPEG";
    if (len >= 3 && p[0] == 0xFF && p[1] == 0xD8 && p[2] == 0xFF) return appm__jpeg_decode;
    *format = "PNM";
    if (len >= 2 && p[0] == 'P' && (p[1] == '2' || p[1] == '3' || p[1] == '5' || p[1] == '6'))
        return appm__pnm_decode;
    *format = "Radiance HDR";
    if (len >= 2 && p[0] == '#' && p[1] == '?') return appm__hdr_decode;
    *format = "TGA";
    if (appm__ends_with(name, ".tga") || appm__ends_with(name, ".TGA")) return appm__tga_decode;
    *format = NULL;
    return NULL;
}

static appm_status appm__image_decode(appm__mem *m, const unsigned char *p, size_t len, const char *name,
                                      appm__pixels *out, appm_diag *diag)
{
    const char *format;
    appm__decode_fn fn = appm__image_format(p, len, name, &format);
    appm_status st;
    memset(out, 0, sizeof *out);
    if (!fn)
        return appm__fail(diag, APPM_ERR_PARSE, name, 0,
                          "not an image appm reads (PNG, JPEG, TGA, PPM/PGM, PFM, OpenEXR, Radiance HDR)");
    st = fn(m, p, len, name, out, diag);
    if (st == APPM_OK && (!out->data || out->w == 0 || out->h == 0 || out->w > APPM__IMAGE_MAX ||
                          out->h > APPM__IMAGE_MAX || out->channels < 1 || out->channels > 4 ||
                          (out->depth != 8 && out->depth != 16 && out->depth != 32))) {
        appm__free(m, out->data);
        memset(out, 0, sizeof *out);
        return appm__fail(diag, APPM_ERR_PARSE, name, 0, "%s decoder gave no image", format);
    }
    if (st != APPM_OK) memset(out, 0, sizeof *out);
    return st;
}

/* The sRGB transfer curve decoded: the linear value of 8-bit code c. */
static float appm__srgb_linear(double c)
{
    return (float)(c <= 0.04045 ? c / 12.92 : pow((c + 0.055) / 1.055, 2.4));
}

/* Sample k of pixel i of img as a linear number (colour channels of 8- and
 * 16-bit images sRGB-decoded, alpha linear). */
static float appm__pixels_linear(const appm__pixels *img, size_t i, unsigned k)
{
    size_t j = i * img->channels + k;
    int alpha = (img->channels == 2 && k == 1) || (img->channels == 4 && k == 3);
    double c;
    if (img->depth == 32) return ((const float *)img->data)[j];
    c = img->depth == 8 ? ((const unsigned char *)img->data)[j] / 255.0 : ((const uint16_t *)img->data)[j] / 65535.0;
    return alpha ? (float)c : appm__srgb_linear(c);
}

APPM_API appm_status appm_image_read(const char *path, const appm_config *cfg, appm_image *out,
                                     appm_diag *diag)
{
    appm__mem m;
    char *buf;
    size_t len, i, n;
    appm__pixels px;
    appm_status s;
    appm__diag_clear(diag);
    if (!out) return appm__fail(diag, APPM_ERR_INVALID_ARG, path, 0, "no output image");
    out->width = out->height = 0;
    out->rgb = NULL;
    if (!path) return appm__fail(diag, APPM_ERR_INVALID_ARG, NULL, 0, "no path");
    appm__mem_init(&m, cfg);
    m.diag = diag;
    s = appm__read_file(&m, path, &buf, &len, diag);
    if (s != APPM_OK) return s;
    s = appm__image_decode(&m, (const unsigned char *)buf, len, path, &px, diag);
    appm__free(&m, buf);
    if (s != APPM_OK) return s;
    if (px.depth == 32 && px.channels == 3) { /* already what appm_image holds */
        out->rgb = (float *)px.data;
    } else {
        n = (size_t)px.w * px.h;
        out->rgb = (float *)appm__alloc(&m, n, 3 * sizeof(float));
        if (!out->rgb) {
            appm__free(&m, px.data);
            return appm__fail(diag, APPM_ERR_NOMEM, path, 0, "out of memory");
        }
        for (i = 0; i < n; ++i) { /* grey to all three; alpha dropped */
            unsigned k, colour = px.channels >= 3 ? 3 : 1;
            for (k = 0; k < 3; ++k) out->rgb[3 * i + k] = appm__pixels_linear(&px, i, colour == 3 ? k : 0);
        }
        appm__free(&m, px.data);
    }
    out->width = px.w;
    out->height = px.h;
    return APPM_OK;
}

APPM_API void appm_image_free(const appm_config *cfg, appm_image *img)
{
    appm__mem m;
    if (!img) return;
    appm__mem_init(&m, cfg);
    appm__free(&m, img->rgb);
    img->rgb = NULL;
    img->width = img->height = 0;
}

APPM_API appm_status appm_image_compare(const appm_image *a, const appm_image *b,
                                        appm_compare_result *out)
{
    double se = 0, rel = 0, ae = 0, sa = 0, sb = 0, n;
    size_t i, count;
    if (!a || !b || !out || !a->rgb || !b->rgb) return APPM_ERR_INVALID_ARG;
    if (a->width != b->width || a->height != b->height) return APPM_ERR_INVALID_ARG;
    count = (size_t)a->width * a->height * 3;
    for (i = 0; i < count; ++i) {
        double x = a->rgb[i], r = b->rgb[i], d = x - r;
        se += d * d;
        rel += d * d / (r * r + 0.01);
        ae += fabs(d);
        sa += x;
        sb += r;
    }
    n = (double)(count ? count : 1);
    out->rmse = sqrt(se / n);
    out->relmse = rel / n;
    out->mae = ae / n;
    out->mean_a = sa / n;
    out->mean_b = sb / n;
    return APPM_OK;
}

/* ==== 4. OBJ/MTL AND SCENES ==============================================
 *
 * Readers for the three text formats of the scene contract: `.scene` (camera,
 * image, lights, meshes), Wavefront OBJ and MTL.  All three are read from memory
 * buffers with explicit lengths (no reliance on a terminating NUL), line by line
 * (LF, CRLF or CR), with a locale-free number parser.  Every malformed input is
 * an error naming file and line; statements that are understood but not modelled
 * (textures, Ns without Ks, ...) are warnings, sent once per kind and file.
 *
 * Materials map to exactly one of four BSDFs (interface contract, section 2):
 *   illum 4, 6, 7, 9 -> smooth dielectric, index Ni (1.5)
 *   illum 3, 5       -> perfect mirror, reflectance Ks (1 1 1)
 *   Ks > 0 otherwise -> glossy: two-sided Lambert Kd plus the normalised
 *                       modified Phong lobe Ks, exponent Ns (section 6);
 *                       where Kd + Ks > 1 in a channel both are scaled to 1
 *   anything else    -> two-sided Lambert, albedo Kd (0.8), clamped to [0,1]
 * and Ke > 0 adds one-sided Lambertian emission on the counter-clockwise side.
 *
 * Invariants after loading: no triangle has zero area or a non-finite vertex
 * (such faces are dropped and counted); material 0 is the default diffuse.
 */
enum { APPM__MAT_DIFFUSE = 0, APPM__MAT_MIRROR, APPM__MAT_DIELECTRIC, APPM__MAT_GLOSSY };

#define APPM__NS_MAX 1e5 /* largest Phong exponent accepted (interface contract) */

typedef struct appm__material {
    int kind;
    int emissive;
    appm__v3 color; /* Kd (diffuse albedo) or Ks (mirror reflectance) */
    appm__v3 ke;    /* emitted radiance, front side only */
    appm__v3 ks;    /* glossy: the lobe's albedo at normal incidence; Kd + Ks <= 1 */
    float ns;       /* glossy: Phong exponent, (0, 1e5] */
    float ior;
    uint32_t name;  /* offset of the name in the loader's string pool */
    /* map_Kd, map_Ks, map_d: 1 + the texture's index in appm_scene.tex, 0 for
     * none.  map_Kd multiplies color (Kd), map_Ks ks (a mirror's color), map_d
     * cuts the surface away where its alpha is below 1/2 (appm__cut_away). */
    uint32_t map_kd, map_ks, map_d;
    double emit_area; /* emissive: the area of the triangles that use it (appm__pt_blind) */
} appm__material;

/* A decoded texture map: 8-bit samples (colour sRGB-encoded, alpha linear)
 * or linear floats (16-bit files are converted to float when they load). */
typedef struct appm__texture {
    appm__pixels px;
    uint64_t hash;  /* of its samples, for checkpoints (section 13) */
    uint32_t name;  /* loader: offset of its path in the string pool */
    int missing;    /* loader: it could not be read (--missing-textures warn) */
} appm__texture;

typedef struct appm__tri { /* 36 bytes: just what the intersection test reads */
    appm__v3 p0, p1, p2;
} appm__tri;

typedef struct appm__tri_info { /* 36 bytes: what shading reads after a hit */
    appm__v3 ng;                /* unit geometric normal, counter-clockwise side */
    float area;
    uint32_t mat;
    int32_t light;   /* index of its area light, or -1 */
    int32_t n0;      /* first of three shading normals in scene->normals, or -1 */
    uint32_t nhash;  /* its corners' vn as written, hashed (for checkpoints, section 13); 0 if flat */
    int32_t uv0;     /* first of its three corners' (u, v) pairs in appm_scene.uv, or -1 */
} appm__tri_info;

enum { APPM__LIGHT_AREA = 0, APPM__LIGHT_POINT, APPM__LIGHT_SPOT, APPM__LIGHT_ENV };

typedef struct appm__light {
    int kind;
    uint32_t tri;    /* area: the emitting triangle */
    appm__v3 pos;    /* point, spot */
    appm__v3 axis;   /* spot: unit axis */
    appm__v3 value;  /* area, environment: radiance; point, spot: intensity (W/sr) */
    float cos_cone, cos_inner; /* spot: cos(cone), cos(cone - falloff) */
    appm__v3 target;           /* spot: as written (axis is derived from it) */
    double cone, falloff;      /* spot: degrees, as written */
    double power[3]; /* emitted power (W), RGB */
    double pick;     /* probability of choosing this light for a photon */
    double nee[2];   /* probability of choosing it for a shadow ray's one sample (6.4): [0] appm's
                      * eye pass, [1] the path tracer's; 0 when nee_all or left out */
    int nee_all;     /* a point or spot light that every shading point sends a shadow ray of its own */
    unsigned line;   /* line of the `.scene` statement (0 for area lights) */
} appm__light;

/* An environment map (`environment map FILE`): the radiance arriving from
 * each direction, an equirectangular image (docs/scene-format.md 4): row 0 the
 * zenith (+y), column 0 towards -z, columns advancing towards +x; `rotate`
 * turns it about +y by that angle (column 0 then looks along +x at 90).  The
 * loader keeps the decoded file in px; the scene (6.2) keeps linear RGB times
 * `scale` in rgb and the distribution appm__env_sample draws from. */
#define APPM__ENV_PB 7 /* bins of shading normals per side of the octahedral grid (odd: +y is a bin's centre) */
#define APPM__ENV_BINS (APPM__ENV_PB * APPM__ENV_PB)
typedef struct appm__envmap {
    appm__pixels px;   /* loader: the decoded file */
    float *rgb;        /* w * h * 3 radiances */
    uint32_t w, h;
    double *cdf;       /* rows' CDF (h + 1 entries), then each row's CDF over its columns (w + 1 each) */
    uint32_t *guide;   /* their guide tables (appm__cdf_guide), APPM__CDF_G + 1 entries each, in that order */
    /* The product densities (appm__env_prod_build): per bin of shading normals, a
     * coarse pw x ph grid over the map laid out as cdf is; pcdf NULL: none. */
    double *pcdf;
    uint32_t *pguide;  /* their guide tables, laid out as guide is, bin after bin */
    uint32_t pw, ph;
    unsigned char pok[APPM__ENV_BINS]; /* the bin's density exists (its hemisphere is not black) */
    double mix_map;    /* the map's own density's share of a shadow ray's mixture where a bin has a
                        * product density (appm__env_mix_pdf): APPM__ENV_MIX_MAP, or
                        * APPM__ENV_MIX_MAP_FULL where the product densities hold every texel
                        * and no sun holds APPM__ENV_SUN_SHARE of the power */
    double scale, rotate; /* as written; rotate in degrees */
    float rot;         /* rotate in radians */
    uint64_t hash;     /* of the file's samples, scale and rotate (checkpoints) */
} appm__envmap;

typedef struct appm__camera {
    appm__v3 eye, forward, right, up;
    float fov, tan_half; /* full vertical field of view, degrees; tan(fov/2) */
    float aperture, focus;
    /* The camera statement as written, which the basis and tan_half derive from
     * (for checkpoints, section 13); framed: no statement, the loader framed the scene. */
    appm__v3 target, sky;
    double fov_deg;
    int framed;
} appm__camera;

typedef struct appm__loader {
    appm__mem *mem;
    appm_diag *diag;
    appm_log_fn log;
    void *log_user;
    const char *file;       /* file being read, for messages */
    uint64_t warned;        /* warning kinds already sent for `file` (one bit each) */
    appm__array pos;        /* appm__v3: the current OBJ's `v` */
    appm__array vn;         /* appm__v3: the current OBJ's `vn`, as written (not normalised) */
    appm__array nrm;        /* appm__v3: shading normals, three per smooth triangle */
    appm__array vt;         /* float pairs: the current OBJ's `vt` (u, v) */
    appm__array uv;         /* float pairs: three per textured triangle (tri_info.uv0) */
    appm__array tex;        /* appm__texture: every map the MTL files name, once per path */
    int missing_warn;       /* appm_config.missing_textures: a map that cannot be read is a warning */
    appm__array tri;        /* appm__tri */
    appm__array info;       /* appm__tri_info */
    appm__array mat;        /* appm__material */
    size_t mat_base;        /* first material of the current OBJ's libraries */
    appm__array names;      /* char: NUL-terminated material names */
    appm__array face;       /* int64_t triples (position, normal, texture) of the face being read */
    appm__array lights;     /* appm__light: point, spot, environment */
    appm__envmap envmap;    /* `environment map`: the decoded file (px.data NULL: none) */
    char envmap_path[512];  /* and its path, for messages */
    uint64_t dropped;
    appm__camera cam;
    int have_camera;
    uint32_t width, height;
    int bare_obj;           /* an OBJ read as a whole scene: without light it gets a studio */
    int stand_in;           /* it got one (appm__stand_in): ground plate, sky, camera */
    int white;              /* appm_config.stand_in: a bare OBJ without light gets a white environment instead */
    const char *mem_mtl;    /* in-memory MTL text (appm_scene_load_obj_memory) */
    size_t mem_mtl_len;
    const appm_memory_file *files; /* appm_scene_load_memory: the texts meshes and mtllibs name */
    size_t nfiles;
} appm__loader;

enum {
    APPM__W_CLAMPED = 1u << 1, /* bits 8 and up: one per ignored statement kind */
    APPM__W_DEGENERATE = 1u << 2,
    APPM__W_NO_MTL = 1u << 3,
    APPM__W_UNKNOWN_MAT = 1u << 4,
    APPM__W_SHORT_FACE = 1u << 5,
    APPM__W_EXTRA = 1u << 6,
    APPM__W_BEFORE_NEWMTL = 1u << 7
};

static void appm__warn(appm__loader *L, uint64_t kind, unsigned line, const char *fmt, ...)
{
    char msg[256];
    va_list ap;
    if (!L->log || (L->warned & kind)) return;
    L->warned |= kind;
    va_start(ap, fmt);
    vsnprintf(msg, sizeof msg, fmt, ap);
    va_end(ap);
    L->log(L->log_user, L->file ? L->file : "", line, msg);
}

/* ---- 4.1 Lines, tokens, numbers ------------------------------------------- */

typedef struct appm__lines {
    const char *p, *end;
    unsigned line;
} appm__lines;

/* Next line as [*s, *e) without its terminator; comments (#...) stripped.
 * A UTF-8 byte order mark before the first line (Windows editors write one)
 * is skipped, in every format read line by line (.scene, .obj, .mtl). */
static int appm__next_line(appm__lines *it, const char **s, const char **e)
{
    const char *p = it->p, *q;
    if (it->line == 0 && it->end - p >= 3 && (unsigned char)p[0] == 0xEF && (unsigned char)p[1] == 0xBB &&
        (unsigned char)p[2] == 0xBF)
        p += 3;
    if (p >= it->end) return 0;
    q = p;
    while (q < it->end && *q != '\n' && *q != '\r') q++;
    *s = p;
    *e = q;
    if (q < it->end && *q == '\r') q++;
    if (q < it->end && *q == '\n' && (q == p || q[-1] != '\n')) q++;
    it->p = q;
    it->line++;
    {
        const char *c = *s;
        while (c < *e && *c != '#') c++;
        *e = c;
    }
    return 1;
}

static int appm__is_space(char c) { return c == ' ' || c == '\t' || c == '\v' || c == '\f'; }

/* Next whitespace-separated token of [*s, e) as [*ts, *te); 0 at the end. */
static int appm__token(const char **s, const char *e, const char **ts, const char **te)
{
    const char *p = *s;
    while (p < e && appm__is_space(*p)) p++;
    if (p >= e) {
        *s = p;
        return 0;
    }
    *ts = p;
    while (p < e && !appm__is_space(*p)) p++;
    *te = p;
    *s = p;
    return 1;
}

static int appm__token_is(const char *s, const char *e, const char *word)
{
    size_t n = strlen(word);
    return (size_t)(e - s) == n && memcmp(s, word, n) == 0;
}

static int appm__lower_eq(const char *s, size_t n, const char *word)
{
    size_t i;
    if (strlen(word) != n) return 0;
    for (i = 0; i < n; ++i) {
        char c = s[i];
        if (c >= 'A' && c <= 'Z') c = (char)(c - 'A' + 'a');
        if (c != word[i]) return 0;
    }
    return 1;
}

/* A whole token as a number, C strtod syntax without hex, independent of the
 * locale: [+-] digits [. digits] [(e|E) [+-] digits], or nan / inf / infinity.
 * Mantissa digits beyond 19 only shift the exponent; the exponent saturates, so
 * "3E4570711268" is +inf, not an integer overflow.  Returns 0 if malformed. */
static int appm__parse_number(const char *s, const char *e, double *out)
{
    int neg = 0, any = 0;
    uint64_t mant = 0;
    long exp10 = 0;
    double v;
    if (s < e && (*s == '+' || *s == '-')) neg = *s++ == '-';
    if (appm__lower_eq(s, (size_t)(e - s), "nan")) {
        *out = neg ? -(double)NAN : (double)NAN;
        return 1;
    }
    if (appm__lower_eq(s, (size_t)(e - s), "inf") ||
        appm__lower_eq(s, (size_t)(e - s), "infinity")) {
        *out = neg ? -HUGE_VAL : HUGE_VAL;
        return 1;
    }
    for (; s < e && *s >= '0' && *s <= '9'; ++s) {
        any = 1;
        if (mant < 1000000000000000000ull) mant = mant * 10 + (uint64_t)(*s - '0');
        else exp10++;
    }
    if (s < e && *s == '.') {
        for (++s; s < e && *s >= '0' && *s <= '9'; ++s) {
            any = 1;
            if (mant < 1000000000000000000ull) {
                mant = mant * 10 + (uint64_t)(*s - '0');
                exp10--;
            }
        }
    }
    if (!any) return 0;
    if (s < e && (*s == 'e' || *s == 'E')) {
        int eneg = 0, edig = 0;
        long ev = 0;
        ++s;
        if (s < e && (*s == '+' || *s == '-')) eneg = *s++ == '-';
        for (; s < e && *s >= '0' && *s <= '9'; ++s) {
            edig = 1;
            if (ev < 100000) ev = ev * 10 + (*s - '0');
        }
        if (!edig) return 0;
        exp10 += eneg ? -ev : ev;
    }
    if (s != e) return 0;
    v = (double)mant;
    if (mant == 0) v = 0.0;
    else if (exp10 > 400) v = HUGE_VAL;
    else if (exp10 < -400) v = 0.0;
    else if (exp10 < 0) v = exp10 < -300 ? v / 1e300 / pow(10.0, (double)(-exp10 - 300))
                                         : v / pow(10.0, (double)-exp10);
    else if (exp10 > 0) v = v * pow(10.0, (double)exp10);
    *out = neg ? -v : v;
    return 1;
}

/* Reads `n` numbers from the rest of a line into out[]; all must be finite. */
static appm_status appm__numbers(appm__loader *L, const char **s, const char *e, unsigned line,
                                 const char *what, double *out, int n)
{
    int i;
    for (i = 0; i < n; ++i) {
        const char *ts, *te;
        if (!appm__token(s, e, &ts, &te))
            return appm__fail(L->diag, APPM_ERR_PARSE, L->file, line, "%s: expected %d numbers, got %d",
                              what, n, i);
        if (!appm__parse_number(ts, te, &out[i]))
            return appm__fail(L->diag, APPM_ERR_PARSE, L->file, line, "%s: malformed number '%.*s'",
                              what, (int)(te - ts > 40 ? 40 : te - ts), ts);
        if (!(out[i] - out[i] == 0.0))
            return appm__fail(L->diag, APPM_ERR_PARSE, L->file, line, "%s: %s value '%.*s'", what,
                              out[i] == out[i] ? "infinite" : "NaN",
                              (int)(te - ts > 40 ? 40 : te - ts), ts);
        if (fabs(out[i]) > 1e18)
            return appm__fail(L->diag, APPM_ERR_PARSE, L->file, line,
                              "%s: value %g is too large (|x| > 1e18)", what, out[i]);
    }
    return APPM_OK;
}

/* A statement whose values are complete must end there. */
static appm_status appm__line_end(appm__loader *L, const char **s, const char *e, unsigned line,
                                  const char *what)
{
    const char *ts, *te;
    if (!appm__token(s, e, &ts, &te)) return APPM_OK;
    return appm__fail(L->diag, APPM_ERR_PARSE, L->file, line, "%s: unexpected '%.*s' after the values",
                      what, (int)(te - ts > 30 ? 30 : te - ts), ts);
}

/* The rest of the line with surrounding blanks trimmed (file names may hold spaces). */
static int appm__rest(const char *s, const char *e, const char **rs, const char **re)
{
    while (s < e && appm__is_space(*s)) s++;
    while (e > s && appm__is_space(e[-1])) e--;
    *rs = s;
    *re = e;
    return e > s;
}

/* dir of `path` + `rel` (unless rel is absolute) into out[cap]. */
static int appm__join_path(char *out, size_t cap, const char *path, const char *rel, size_t rel_len)
{
    size_t dir = 0, i;
    int absolute = rel_len > 0 && (rel[0] == '/' || rel[0] == '\\' || (rel_len > 1 && rel[1] == ':'));
    if (!absolute && path)
        for (i = 0; path[i]; ++i)
            if (path[i] == '/' || path[i] == '\\') dir = i + 1;
    if (dir + rel_len + 1 > cap) return 0;
    if (dir) memcpy(out, path, dir);
    memcpy(out + dir, rel, rel_len);
    out[dir + rel_len] = 0;
    return 1;
}

/* The text at `path` (as joined by appm__join_path): one of the loader's
 * in-memory files if it has them (*owned NULL, a name none matches is a
 * missing file), else the file read into *owned, which the caller frees. */
static appm_status appm__loader_read(appm__loader *L, const char *path, const char **text, size_t *len,
                                     char **owned, appm_diag *diag)
{
    size_t i;
    *owned = NULL;
    *text = NULL;
    *len = 0;
    if (!L->files) {
        appm_status st = appm__read_file(L->mem, path, owned, len, diag);
        *text = *owned;
        return st;
    }
    for (i = 0; i < L->nfiles; ++i)
        if (L->files[i].name && strcmp(L->files[i].name, path) == 0) {
            if (!L->files[i].text && L->files[i].len)
                return appm__fail(diag, APPM_ERR_INVALID_ARG, path, 0, "no text for %.0f bytes",
                                  (double)L->files[i].len);
            *text = L->files[i].text;
            *len = L->files[i].len;
            return APPM_OK;
        }
    return appm__fail(diag, APPM_ERR_IO, path, 0, "cannot open file (none of the files given has this name)");
}

/* ---- 4.2 MTL --------------------------------------------------------------- */

static const char *appm__mat_name(const appm__loader *L, const appm__material *m)
{
    return (const char *)L->names.data + m->name;
}

/* Clamps each channel of *v to [0, 1], with one warning per file. */
static void appm__mtl_clamp(appm__loader *L, const appm__material *m, appm__v3 *v, unsigned line)
{
    float *ch[3];
    int c;
    ch[0] = &v->x;
    ch[1] = &v->y;
    ch[2] = &v->z;
    for (c = 0; c < 3; ++c) {
        if (*ch[c] > 1.0f || *ch[c] < 0.0f) {
            appm__warn(L, APPM__W_CLAMPED, line,
                       "reflectance of material '%s' outside [0,1], clamped", appm__mat_name(L, m));
            *ch[c] = *ch[c] > 1.0f ? 1.0f : 0.0f;
        }
    }
}

/* Glossy: where Kd + Ks > 1 in a channel the surface would reflect more than it
 * receives at normal incidence (the lobe's albedo is Ks there), so both are
 * scaled by 1 / (Kd + Ks) in that channel, which keeps their ratio. */
static void appm__mtl_energy(appm__loader *L, appm__material *m, unsigned line)
{
    float *kd[3], *ks[3];
    int c;
    kd[0] = &m->color.x, kd[1] = &m->color.y, kd[2] = &m->color.z;
    ks[0] = &m->ks.x, ks[1] = &m->ks.y, ks[2] = &m->ks.z;
    for (c = 0; c < 3; ++c) {
        float sum = *kd[c] + *ks[c];
        if (sum > 1.0f) {
            appm__warn(L, (uint64_t)1 << 8, line,
                       "Kd + Ks of material '%s' exceeds 1, both scaled to sum to 1", appm__mat_name(L, m));
            *kd[c] /= sum;
            *ks[c] /= sum;
        }
    }
}

/* Decides the material kind once its block is complete. */
static void appm__mtl_finish(appm__loader *L, appm__material *m, int illum, int have_ks,
                             appm__v3 ks, appm__v3 kd, int have_ns, unsigned line)
{
    m->emissive = m->ke.x > 0 || m->ke.y > 0 || m->ke.z > 0;
    m->ks = appm__v(0, 0, 0);
    if (illum == 4 || illum == 6 || illum == 7 || illum == 9) {
        m->kind = APPM__MAT_DIELECTRIC;
        m->color = appm__v(1, 1, 1);
    } else if (illum == 3 || illum == 5) {
        m->kind = APPM__MAT_MIRROR;
        m->color = have_ks ? ks : appm__v(1, 1, 1);
    } else {
        m->kind = APPM__MAT_DIFFUSE;
        m->color = kd;
        if (have_ks && (ks.x > 0 || ks.y > 0 || ks.z > 0)) {
            m->kind = APPM__MAT_GLOSSY;
            m->ks = ks;
            appm__mtl_clamp(L, m, &m->ks, line);
        }
    }
    appm__mtl_clamp(L, m, &m->color, line);
    if (m->kind == APPM__MAT_GLOSSY) appm__mtl_energy(L, m, line);
    if (have_ns && m->kind != APPM__MAT_GLOSSY)
        appm__warn(L, (uint64_t)1 << 62, line, "MTL statement 'Ns' is not modelled without Ks > 0, ignored");
}

/* The Phong exponent: (0, 1e5] (interface contract, section 2).  A positive
 * exponent below the smallest normal float (Ns 1e-301) would round to 0 or to a
 * subnormal; it is kept as FLT_MIN, a lobe no render can tell from its own. */
static appm_status appm__mtl_ns(appm__loader *L, const char **s, const char *e, unsigned line, appm__material *m)
{
    double v;
    appm_status st = appm__numbers(L, s, e, line, "Ns", &v, 1);
    if (st != APPM_OK) return st;
    if (!(v > 0.0) || v > APPM__NS_MAX)
        return appm__fail(L->diag, APPM_ERR_PARSE, L->file, line, "Phong exponent Ns %g is not in (0, 1e5]", v);
    m->ns = v < FLT_MIN ? FLT_MIN : (float)v;
    return APPM_OK;
}

/* What the open material block has said so far; appm__mtl_finish makes the
 * material of it when the block ends. */
typedef struct appm__mtl_block {
    appm__material *cur; /* the block's material; NULL before the first newmtl */
    int illum, have_ks, have_ns;
    appm__v3 ks, kd;
    unsigned line; /* of its newmtl */
} appm__mtl_block;

/* MTL's defaults for the statements of a block: illum 2, no Ks, no Ns, Kd 0.8. */
static void appm__mtl_block_reset(appm__mtl_block *b)
{
    b->illum = 2;
    b->have_ks = 0;
    b->have_ns = 0;
    b->ks = appm__v(0, 0, 0);
    b->kd = appm__v(0.8f, 0.8f, 0.8f);
}

/* Ends the open block, if there is one (appm__mtl_finish). */
static void appm__mtl_close(appm__loader *L, const appm__mtl_block *b)
{
    if (b->cur) appm__mtl_finish(L, b->cur, b->illum, b->have_ks, b->ks, b->kd, b->have_ns, b->line);
}

/* newmtl: ends the open block and opens one for a new material named by the
 * rest of the line s..e (a NUL byte in the name becomes '?'), IOR 1.5, Ns 1. */
static appm_status appm__mtl_newmtl(appm__loader *L, appm__mtl_block *b, const char *s, const char *e,
                                    unsigned line)
{
    const char *ns, *ne;
    char *name;
    size_t off = L->names.count, k;
    appm__mtl_close(L, b);
    if (!appm__rest(s, e, &ns, &ne))
        return appm__fail(L->diag, APPM_ERR_PARSE, L->file, line, "newmtl without a name");
    if (!appm__array_reserve(L->mem, &L->names, off + (size_t)(ne - ns) + 1))
        return APPM_ERR_NOMEM;
    name = (char *)L->names.data + off;
    for (k = 0; k < (size_t)(ne - ns); ++k) name[k] = ns[k] ? ns[k] : '?';
    name[ne - ns] = 0;
    L->names.count += (size_t)(ne - ns) + 1;
    b->cur = (appm__material *)appm__array_push(L->mem, &L->mat);
    if (!b->cur) return APPM_ERR_NOMEM;
    b->cur->name = (uint32_t)off;
    b->cur->ior = 1.5f;
    b->cur->ns = 1.0f;
    appm__mtl_block_reset(b);
    b->line = line;
    return APPM_OK;
}

/* Kd, Ks or Ke (`which` is 'd', 's' or 'e'): three numbers; Ke must be >= 0
 * and finite as floats. */
static appm_status appm__mtl_color(appm__loader *L, appm__mtl_block *b, char which, const char **s, const char *e,
                                   unsigned line)
{
    double v[3];
    appm_status st;
    if ((st = appm__numbers(L, s, e, line, which == 'd' ? "Kd" : which == 's' ? "Ks" : "Ke", v, 3)) != APPM_OK)
        return st;
    if (which == 'd') b->kd = appm__v((float)v[0], (float)v[1], (float)v[2]);
    else if (which == 's') {
        b->ks = appm__v((float)v[0], (float)v[1], (float)v[2]);
        b->have_ks = 1;
    } else {
        if (v[0] < 0 || v[1] < 0 || v[2] < 0)
            return appm__fail(L->diag, APPM_ERR_PARSE, L->file, line, "negative Ke");
        b->cur->ke = appm__v((float)v[0], (float)v[1], (float)v[2]);
        if (!appm__finite3(b->cur->ke))
            return appm__fail(L->diag, APPM_ERR_PARSE, L->file, line, "Ke overflows a float");
    }
    return APPM_OK;
}

/* Ni: the index of refraction, in (0, 100]. */
static appm_status appm__mtl_ni(appm__loader *L, const char **s, const char *e, unsigned line, appm__material *m)
{
    double v;
    appm_status st = appm__numbers(L, s, e, line, "Ni", &v, 1);
    if (st != APPM_OK) return st;
    if (!(v > 0.0) || v > 100.0)
        return appm__fail(L->diag, APPM_ERR_PARSE, L->file, line, "index of refraction Ni %g is not in (0, 100]", v);
    m->ior = (float)v;
    return APPM_OK;
}

/* illum: an integer 0..10, into *illum. */
static appm_status appm__mtl_illum(appm__loader *L, const char **s, const char *e, unsigned line, int *illum)
{
    double v;
    appm_status st = appm__numbers(L, s, e, line, "illum", &v, 1);
    if (st != APPM_OK) return st;
    if (v < 0 || v > 10 || v != floor(v))
        return appm__fail(L->diag, APPM_ERR_PARSE, L->file, line, "illum must be an integer 0..10");
    *illum = (int)v;
    return APPM_OK;
}

/* A texture's samples as appm__tex_lookup reads them: 8-bit as they are,
 * 16-bit converted to linear float (colour sRGB-decoded), floats as they are;
 * and the hash of the result (checkpoints).  Frees what it replaces. */
static appm_status appm__texture_prepare(appm__mem *m, appm__texture *t)
{
    size_t n = (size_t)t->px.w * t->px.h * t->px.channels, i;
    uint64_t h = appm__mix64(((uint64_t)t->px.w << 32 | t->px.h) ^ ((uint64_t)t->px.channels << 8 | t->px.depth));
    if (t->px.depth == 16) {
        float *f = (float *)appm__alloc(m, n, sizeof(float));
        if (!f) return APPM_ERR_NOMEM;
        for (i = 0; i < n; ++i) f[i] = appm__pixels_linear(&t->px, i / t->px.channels, (unsigned)(i % t->px.channels));
        appm__free(m, t->px.data);
        t->px.data = f;
        t->px.depth = 32;
    }
    { /* FNV-1a over the bytes, folded into h */
        const unsigned char *b = (const unsigned char *)t->px.data;
        size_t bytes = n * (t->px.depth == 8 ? 1 : 4);
        uint64_t f = 0xcbf29ce484222325ull;
        for (i = 0; i < bytes; ++i) f = (f ^ b[i]) * 0x100000001b3ull;
        t->hash = appm__mix64(h ^ f);
    }
    return APPM_OK;
}

/* The texture at `path`, loaded once however many materials name it: into
 * *index (1 + its place in L->tex; 0 when it is missing and missing maps
 * are warnings). */
static appm_status appm__texture_load(appm__loader *L, const char *path, unsigned line, uint32_t *index)
{
    appm__texture *t;
    const char *buf;
    char *owned;
    size_t len, k, off = L->names.count, plen = strlen(path);
    appm_status st;
    appm_diag why;
    *index = 0;
    for (k = 0; k < L->tex.count; ++k) {
        t = (appm__texture *)L->tex.data + k;
        if (strcmp((const char *)L->names.data + t->name, path) == 0) {
            *index = t->missing ? 0 : (uint32_t)k + 1;
            return APPM_OK;
        }
    }
    if (!appm__array_reserve(L->mem, &L->names, off + plen + 1)) return APPM_ERR_NOMEM;
    memcpy((char *)L->names.data + off, path, plen + 1);
    L->names.count += plen + 1;
    if (!(t = (appm__texture *)appm__array_push(L->mem, &L->tex))) return APPM_ERR_NOMEM;
    t->name = (uint32_t)off;
    appm__diag_clear(&why);
    L->mem->diag = &why;
    st = appm__loader_read(L, path, &buf, &len, &owned, &why);
    if (st == APPM_OK) {
        st = appm__image_decode(L->mem, (const unsigned char *)buf, len, path, &t->px, &why);
        appm__free(L->mem, owned);
    }
    if (st == APPM_OK) st = appm__texture_prepare(L->mem, t);
    L->mem->diag = L->diag;
    if (st == APPM_ERR_NOMEM) return appm__fail(L->diag, st, path, 0, "out of memory loading the texture");
    if (st != APPM_OK) {
        appm__free(L->mem, t->px.data);
        t->px.data = NULL;
        t->missing = 1;
        if (!L->missing_warn)
            return appm__fail(L->diag, st, L->file, line, "texture '%s': %s", path, why.message);
        if (L->log) {
            char msg[512];
            snprintf(msg, sizeof msg, "texture '%.200s': %.250s; rendered without it", path, why.message);
            L->log(L->log_user, L->file ? L->file : "", line, msg);
        }
        return APPM_OK;
    }
    *index = (uint32_t)L->tex.count;
    return APPM_OK;
}

/* map_Kd, map_Ks or map_d (`which` 'd', 's' or 'a'): [options] FILE.  The
 * options (-o, -s, -bm, -clamp, ...) are skipped with a warning; the file
 * name is the rest of the line, relative to the MTL file. */
static appm_status appm__mtl_map(appm__loader *L, appm__mtl_block *b, char which, const char *s, const char *e,
                                 unsigned line)
{
    const char *ns, *ne, *ts, *te;
    char path[4096];
    uint32_t *slot = which == 'd' ? &b->cur->map_kd : which == 's' ? &b->cur->map_ks : &b->cur->map_d;
    for (;;) { /* an option is '-' then a letter; its arguments are the numbers and words like on/off after it */
        const char *save = s;
        if (!appm__token(&save, e, &ts, &te) || te - ts < 2 || ts[0] != '-' ||
            !((ts[1] >= 'a' && ts[1] <= 'z') || (ts[1] >= 'A' && ts[1] <= 'Z')))
            break;
        appm__warn(L, (uint64_t)1 << 61, line, "texture options ('%.*s') are not modelled, ignored",
                   (int)(te - ts > 20 ? 20 : te - ts), ts);
        s = save;
        for (;;) {
            double v;
            save = s;
            if (!appm__token(&save, e, &ts, &te)) break;
            if (!appm__parse_number(ts, te, &v) && !appm__token_is(ts, te, "on") && !appm__token_is(ts, te, "off") &&
                !(te - ts == 1 && (*ts == 'r' || *ts == 'g' || *ts == 'b' || *ts == 'm' || *ts == 'l' || *ts == 'z')))
                break;
            s = save;
        }
    }
    if (!appm__rest(s, e, &ns, &ne))
        return appm__fail(L->diag, APPM_ERR_PARSE, L->file, line, "texture map without a file name");
    if (L->mem_mtl) { /* an in-memory MTL: names are as written */
        if ((size_t)(ne - ns) >= sizeof path)
            return appm__fail(L->diag, APPM_ERR_PARSE, L->file, line, "texture path too long");
        memcpy(path, ns, (size_t)(ne - ns));
        path[ne - ns] = 0;
    } else if (!appm__join_path(path, sizeof path, L->file, ns, (size_t)(ne - ns)))
        return appm__fail(L->diag, APPM_ERR_PARSE, L->file, line, "texture path too long");
    return appm__texture_load(L, path, line, slot);
}

/* Statement ts..te, not one this renderer models: a texture map, another known
 * MTL statement, or an unknown one.  Warns (each kind once per file). */
static void appm__mtl_ignored(appm__loader *L, const char *ts, const char *te, unsigned line)
{
    static const char *const ignored[] = {"Ka", "Tf", "d", "Tr", "sharpness", "Pr", "Pm",
                                          "Ps", "Pc", "Pcr", "aniso", "anisor", "norm", "bump",
                                          "disp", "decal", "refl"};
    size_t k, n = sizeof ignored / sizeof ignored[0];
    if (te - ts > 4 && memcmp(ts, "map_", 4) == 0) {
        appm__warn(L, (uint64_t)1 << 9, line,
                   "texture map '%.*s' is not modelled (map_Kd, map_Ks and map_d are), ignored",
                   (int)(te - ts > 30 ? 30 : te - ts), ts);
        return;
    }
    for (k = 0; k < n; ++k)
        if (appm__token_is(ts, te, ignored[k])) break;
    if (k < n)
        appm__warn(L, (uint64_t)1 << (10 + k), line, "MTL statement '%s' is not modelled, ignored", ignored[k]);
    else
        appm__warn(L, (uint64_t)1 << 63, line, "unknown MTL statement '%.*s' ignored",
                   (int)(te - ts > 30 ? 30 : te - ts), ts);
}

static appm_status appm__mtl_parse(appm__loader *L, const char *buf, size_t len)
{
    appm__lines it;
    const char *s, *e;
    appm__mtl_block b;
    appm_status st = APPM_OK;
    b.cur = NULL;
    b.line = 0;
    appm__mtl_block_reset(&b);
    it.p = buf;
    it.end = buf + len;
    it.line = 0;
    while (appm__next_line(&it, &s, &e)) {
        const char *ts, *te;
        if (!appm__token(&s, e, &ts, &te)) continue;
        if (appm__token_is(ts, te, "newmtl"))
            st = appm__mtl_newmtl(L, &b, s, e, it.line);
        else if (!b.cur)
            appm__warn(L, APPM__W_BEFORE_NEWMTL, it.line, "statement before any newmtl ignored");
        else if (appm__token_is(ts, te, "Kd") || appm__token_is(ts, te, "Ks") || appm__token_is(ts, te, "Ke"))
            st = appm__mtl_color(L, &b, ts[1], &s, e, it.line);
        else if (appm__token_is(ts, te, "Ni"))
            st = appm__mtl_ni(L, &s, e, it.line, b.cur);
        else if (appm__token_is(ts, te, "Ns")) {
            if ((st = appm__mtl_ns(L, &s, e, it.line, b.cur)) == APPM_OK) b.have_ns = 1;
        } else if (appm__token_is(ts, te, "illum"))
            st = appm__mtl_illum(L, &s, e, it.line, &b.illum);
        else if (appm__token_is(ts, te, "map_Kd") || appm__token_is(ts, te, "map_Ks"))
            st = appm__mtl_map(L, &b, ts[5], s, e, it.line);
        else if (appm__token_is(ts, te, "map_d"))
            st = appm__mtl_map(L, &b, 'a', s, e, it.line);
        else
            appm__mtl_ignored(L, ts, te, it.line);
        if (st != APPM_OK) return st;
    }
    appm__mtl_close(L, &b);
    return APPM_OK;
}

static appm_status appm__mtl_load(appm__loader *L, const char *obj_path, const char *rel,
                                  size_t rel_len, unsigned line)
{
    char path[4096];
    char *owned;
    const char *buf;
    size_t len;
    appm_status st;
    const char *saved_file = L->file;
    uint64_t saved_warned = L->warned;
    appm_diag quiet;
    if (L->mem_mtl) { /* in-memory scene: every mtllib means the given MTL text */
        L->file = "(mtl)";
        L->warned = 0;
        st = appm__mtl_parse(L, L->mem_mtl, L->mem_mtl_len);
        L->file = saved_file;
        L->warned = saved_warned;
        return st;
    }
    if (!appm__join_path(path, sizeof path, obj_path, rel, rel_len))
        return appm__fail(L->diag, APPM_ERR_PARSE, L->file, line, "mtllib path too long");
    appm__diag_clear(&quiet);
    L->mem->diag = &quiet;
    st = appm__loader_read(L, path, &buf, &len, &owned, &quiet);
    L->mem->diag = L->diag;
    if (st == APPM_ERR_IO) {
        appm__warn(L, APPM__W_NO_MTL, line, "cannot open material library '%s': default material used",
                   path);
        return APPM_OK;
    }
    if (st != APPM_OK) return appm__fail(L->diag, st, path, 0, "%s", quiet.message);
    L->file = path;
    L->warned = 0;
    st = appm__mtl_parse(L, buf, len);
    L->file = saved_file;
    L->warned = saved_warned;
    appm__free(L->mem, owned);
    return st;
}

/* ---- 4.3 OBJ --------------------------------------------------------------- */

/* Resolves a 1-based (or negative, relative) OBJ index against `count` items
 * read so far; -1 if out of range.  Zero is never valid. */
static int64_t appm__obj_index(const char *s, const char *e, size_t count, int *ok)
{
    int neg = 0;
    int64_t v = 0;
    *ok = 0;
    if (s < e && (*s == '-' || *s == '+')) neg = *s++ == '-';
    if (s >= e) return -1;
    for (; s < e; ++s) {
        if (*s < '0' || *s > '9') return -1;
        if (v > (INT64_MAX - 9) / 10) v = INT64_MAX / 2; /* saturate: surely out of range */
        else v = v * 10 + (*s - '0');
    }
    *ok = 1; /* well-formed number; range is checked below */
    if (v == 0) return -1;
    if (neg) v = (int64_t)count - v;
    else v = v - 1;
    if (v < 0 || (uint64_t)v >= (uint64_t)count) return -1;
    return v;
}

/* A step of the hash of a triangle's corner normals as written (tri_info.nhash).
 * The normalised ones are not hashed: where float expressions are evaluated in
 * double (s390x), the length's dot product rounds otherwise than on x86-64,
 * and a checkpoint must recognise the same file on both. */
static uint64_t appm__vn_hash(uint64_t h, appm__v3 n)
{
    const float c[3] = {n.x, n.y, n.z};
    int k;
    for (k = 0; k < 3; ++k) {
        uint32_t u;
        memcpy(&u, &c[k], sizeof u);
        h = appm__mix64(h ^ u) + 0x9E3779B97F4A7C15ull;
    }
    return h;
}

/* One vertex reference "v", "v/vt", "v//vn" or "v/vt/vn" of a face, ts..te:
 * c[0] the position's index into L->pos, c[1] the normal's into L->vn and c[2]
 * the texture coordinate's into L->vt (-1: none). */
static appm_status appm__obj_corner(appm__loader *L, const char *ts, const char *te, unsigned line, int64_t *c)
{
    const char *slash1 = ts, *slash2;
    int64_t *vi = &c[0], *ni = &c[1];
    int ok;
    *ni = -1;
    c[2] = -1;
    while (slash1 < te && *slash1 != '/') slash1++;
    *vi = appm__obj_index(ts, slash1, L->pos.count, &ok);
    if (*vi < 0)
        return appm__fail(L->diag, APPM_ERR_PARSE, L->file, line,
                          ok ? "vertex index '%.*s' out of range (%.0f vertices so far)"
                             : "malformed vertex index '%.*s'",
                          (int)(slash1 - ts > 30 ? 30 : slash1 - ts), ts, (double)L->pos.count);
    if (slash1 < te) {
        slash2 = slash1 + 1;
        while (slash2 < te && *slash2 != '/') slash2++;
        if (slash2 > slash1 + 1 && (c[2] = appm__obj_index(slash1 + 1, slash2, L->vt.count, &ok)) < 0)
            return appm__fail(L->diag, APPM_ERR_PARSE, L->file, line,
                              ok ? "texture index out of range" : "malformed texture index");
        if (slash2 < te) {
            *ni = appm__obj_index(slash2 + 1, te, L->vn.count, &ok);
            if (*ni < 0)
                return appm__fail(L->diag, APPM_ERR_PARSE, L->file, line,
                                  ok ? "normal index '%.*s' out of range" : "malformed normal index '%.*s'",
                                  (int)(te - slash2 - 1 > 30 ? 30 : te - slash2 - 1), slash2 + 1);
        }
    }
    return APPM_OK;
}

/* The shading normals of triangle `in`, from L->vn[idx[0..2]]: normalised into
 * three new entries of L->nrm (in->n0 the first), their hash as written into
 * in->nhash. */
static appm_status appm__obj_tri_normals(appm__loader *L, appm__tri_info *in, const int64_t idx[3])
{
    size_t base = L->nrm.count, j;
    uint64_t h = 0;
    if (!appm__array_reserve(L->mem, &L->nrm, base + 3)) return APPM_ERR_NOMEM;
    for (j = 0; j < 3; ++j) {
        appm__v3 vn = ((appm__v3 *)L->vn.data)[idx[j]];
        ((appm__v3 *)L->nrm.data)[base + j] = appm__normalize(vn);
        h = appm__vn_hash(h, vn);
    }
    L->nrm.count += 3;
    in->n0 = (int32_t)base;
    in->nhash = (uint32_t)(h >> 32) | 1u;
    return APPM_OK;
}

/* One triangle of a face, its corners c0, c1, c2 (triples: index into L->pos,
 * into L->vn or -1, into L->vt or -1), of material `mat`: appended to L->tri and
 * L->info, with shading normals when all three corners have one and texture
 * coordinates when all three have them and the material has a map.  A triangle whose area is zero as a
 * float is dropped instead (L->dropped, a warning). */
static appm_status appm__obj_tri(appm__loader *L, const int64_t *c0, const int64_t *c1, const int64_t *c2,
                                 uint32_t mat, unsigned line)
{
    const appm__v3 *P = (const appm__v3 *)L->pos.data;
    appm__v3 a = P[c0[0]], b = P[c1[0]], c = P[c2[0]];
    /* The normal in double: in float, the cross product of a needle's edges
     * can point 1e-3 rad off (epsilon / angle), and a ray leaving the
     * surface within that angle of its plane would be offset to the wrong
     * side (appm__offset chooses the side by ng) and hit it again. */
    double e1[3], e2[3], cr[3], area2;
    appm__tri *t;
    appm__tri_info *in;
    e1[0] = (double)b.x - a.x;
    e1[1] = (double)b.y - a.y;
    e1[2] = (double)b.z - a.z;
    e2[0] = (double)c.x - a.x;
    e2[1] = (double)c.y - a.y;
    e2[2] = (double)c.z - a.z;
    cr[0] = e1[1] * e2[2] - e1[2] * e2[1];
    cr[1] = e1[2] * e2[0] - e1[0] * e2[2];
    cr[2] = e1[0] * e2[1] - e1[1] * e2[0];
    area2 = sqrt(cr[0] * cr[0] + cr[1] * cr[1] + cr[2] * cr[2]);
    /* degenerate as stored: the area must survive the conversion to float */
    if (!((float)(0.5 * area2) > 0.0f) || !(area2 < FLT_MAX)) {
        L->dropped++;
        appm__warn(L, APPM__W_DEGENERATE, line, "degenerate (zero-area) triangles dropped");
        return APPM_OK;
    }
    t = (appm__tri *)appm__array_push(L->mem, &L->tri);
    in = (appm__tri_info *)appm__array_push(L->mem, &L->info);
    if (!t || !in) return APPM_ERR_NOMEM;
    if (L->info.count > 0x7FFFFFF0u)
        return appm__fail(L->diag, APPM_ERR_PARSE, L->file, line, "too many triangles");
    t->p0 = a;
    t->p1 = b;
    t->p2 = c;
    in->ng = appm__v((float)(cr[0] / area2), (float)(cr[1] / area2), (float)(cr[2] / area2));
    in->area = (float)(0.5 * area2);
    in->mat = mat;
    in->light = -1;
    in->n0 = -1;
    in->uv0 = -1;
    if (c0[2] >= 0 && c1[2] >= 0 && c2[2] >= 0) {
        const appm__material *mm = (const appm__material *)L->mat.data + mat;
        if (mm->map_kd || mm->map_ks || mm->map_d) {
            const float *vt = (const float *)L->vt.data;
            float *uv;
            if (L->uv.count > 0x7FFFFFF0u) return appm__fail(L->diag, APPM_ERR_PARSE, L->file, line, "too many triangles");
            if (!appm__array_reserve(L->mem, &L->uv, L->uv.count + 3)) return APPM_ERR_NOMEM;
            uv = (float *)L->uv.data + 2 * L->uv.count;
            memcpy(uv, vt + 2 * c0[2], 2 * sizeof(float));
            memcpy(uv + 2, vt + 2 * c1[2], 2 * sizeof(float));
            memcpy(uv + 4, vt + 2 * c2[2], 2 * sizeof(float));
            in->uv0 = (int32_t)L->uv.count;
            L->uv.count += 3;
        }
    }
    if (c0[1] >= 0 && c1[1] >= 0 && c2[1] >= 0) {
        /* shading normals are stored per triangle corner, three in a row */
        const int64_t idx[3] = {c0[1], c1[1], c2[1]};
        return appm__obj_tri_normals(L, in, idx);
    }
    return APPM_OK;
}

/* f: the face's vertex references into L->face (triples: position, normal or
 * -1, texture coordinate or -1), then its triangles as a fan (0, k, k+1).  A face of fewer than three
 * vertices is skipped with a warning. */
static appm_status appm__obj_face(appm__loader *L, const char **s, const char *e, unsigned line,
                                  uint32_t mat)
{
    const char *ts, *te;
    int64_t *f;
    size_t k, n;
    appm_status st;
    L->face.count = 0;
    while (appm__token(s, e, &ts, &te)) {
        int64_t c[3];
        if ((st = appm__obj_corner(L, ts, te, line, c)) != APPM_OK) return st;
        if (!appm__array_reserve(L->mem, &L->face, L->face.count + 1)) return APPM_ERR_NOMEM;
        memcpy((int64_t *)L->face.data + 3 * L->face.count++, c, sizeof c);
    }
    n = L->face.count;
    if (n < 3) {
        appm__warn(L, APPM__W_SHORT_FACE, line, "face with fewer than 3 vertices skipped");
        return APPM_OK;
    }
    f = (int64_t *)L->face.data;
    for (k = 1; k + 1 < n; ++k) /* fan: (0, k, k+1) */
        if ((st = appm__obj_tri(L, f, f + 3 * k, f + 3 * k + 3, mat, line)) != APPM_OK) return st;
    return APPM_OK;
}

/* v: a position, three numbers into L->pos (more components are ignored with
 * a warning). */
static appm_status appm__obj_v(appm__loader *L, const char **s, const char *e, unsigned line)
{
    const char *ts, *te;
    double v[3];
    appm__v3 *p;
    appm_status st;
    if ((st = appm__numbers(L, s, e, line, "v", v, 3)) != APPM_OK) return st;
    if (appm__token(s, e, &ts, &te))
        appm__warn(L, APPM__W_EXTRA, line, "extra vertex components (w, colours) ignored");
    p = (appm__v3 *)appm__array_push(L->mem, &L->pos);
    if (!p) return APPM_ERR_NOMEM;
    *p = appm__v((float)v[0], (float)v[1], (float)v[2]);
    return APPM_OK;
}

/* vn: a normal, three numbers into L->vn as written; one of zero length (after
 * normalisation in float) is an error. */
static appm_status appm__obj_vn(appm__loader *L, const char **s, const char *e, unsigned line)
{
    double v[3];
    appm__v3 *p, n;
    appm_status st;
    if ((st = appm__numbers(L, s, e, line, "vn", v, 3)) != APPM_OK) return st;
    p = (appm__v3 *)appm__array_push(L->mem, &L->vn);
    if (!p) return APPM_ERR_NOMEM;
    *p = appm__v((float)v[0], (float)v[1], (float)v[2]);
    n = appm__normalize(*p);
    if (!(appm__dot(n, n) > 0.5f))
        return appm__fail(L->diag, APPM_ERR_PARSE, L->file, line, "zero-length normal");
    return APPM_OK;
}

/* vt: a texture coordinate u [v [w]] into L->vt (v defaults to 0, w is
 * ignored); a malformed or non-finite one is 0 with a warning.  Maps repeat,
 * so any value is a place on the map. */
static appm_status appm__obj_vt(appm__loader *L, const char **s, const char *e, unsigned line)
{
    const char *ts, *te;
    double v[2] = {0.0, 0.0};
    float *p;
    int k;
    for (k = 0; k < 2; ++k) {
        if (!appm__token(s, e, &ts, &te)) break; /* "vt u": v = 0 */
        if (!appm__parse_number(ts, te, &v[k]) || !(fabs(v[k]) <= 1e18)) {
            /* most files never read their vt: a bad one is worth a warning, not a failed load */
            appm__warn(L, (uint64_t)1 << 60, line, "vt: '%.*s' is not a number below 1e18: taken as 0",
                       (int)(te - ts > 30 ? 30 : te - ts), ts);
            v[k] = 0.0;
        }
    }
    if (!appm__array_reserve(L->mem, &L->vt, L->vt.count + 1)) return APPM_ERR_NOMEM;
    p = (float *)L->vt.data + 2 * L->vt.count++;
    p[0] = (float)v[0];
    p[1] = (float)v[1];
    return APPM_OK;
}

/* usemtl, the name the rest of the line s..e: *mat becomes the last material
 * of that name read since this OBJ began (L->mat_base), else 0, the default
 * diffuse (with a warning when a name was given). */
static void appm__obj_usemtl(appm__loader *L, const char *s, const char *e, unsigned line, uint32_t *mat)
{
    const char *ns, *ne;
    size_t k;
    *mat = 0;
    if (!appm__rest(s, e, &ns, &ne)) return;
    for (k = L->mat.count; k-- > L->mat_base;) {
        const char *name = appm__mat_name(L, (appm__material *)L->mat.data + k);
        if (strlen(name) == (size_t)(ne - ns) && memcmp(name, ns, (size_t)(ne - ns)) == 0) {
            *mat = (uint32_t)k;
            break;
        }
    }
    if (*mat == 0)
        appm__warn(L, APPM__W_UNKNOWN_MAT, line, "unknown material '%.*s': default diffuse used",
                   (int)(ne - ns > 60 ? 60 : ne - ns), ns);
}

/* Statement ts..te, not one this renderer models: a warning (each kind once
 * per file) if it is a word (a letter or '_', then also digits), else an error. */
static appm_status appm__obj_ignored(appm__loader *L, const char *ts, const char *te, unsigned line)
{
    static const char *const ignored[] = {"vp", "l", "p", "cstype", "deg", "bmat", "step",
                                          "curv", "curv2", "surf", "parm", "trim", "hole",
                                          "scrv", "sp", "end", "con", "mg", "lod", "usemap",
                                          "maplib", "shadow_obj", "trace_obj", "ctech", "stech",
                                          "bevel", "c_interp", "d_interp", "call", "csh"};
    size_t k, n = sizeof ignored / sizeof ignored[0];
    int word = 1;
    const char *c;
    for (c = ts; c < te; ++c)
        if (!((*c >= 'a' && *c <= 'z') || (*c >= 'A' && *c <= 'Z') || *c == '_' ||
              (c > ts && *c >= '0' && *c <= '9')))
            word = 0;
    if (!word)
        return appm__fail(L->diag, APPM_ERR_PARSE, L->file, line, "'%.*s' is not an OBJ statement",
                          (int)(te - ts > 30 ? 30 : te - ts), ts);
    for (k = 0; k < n; ++k)
        if (appm__token_is(ts, te, ignored[k])) break;
    appm__warn(L, k < n ? (uint64_t)1 << (8 + k) : (uint64_t)1 << 63, line,
               "OBJ statement '%.*s' is not modelled, ignored", (int)(te - ts > 30 ? 30 : te - ts), ts);
    return APPM_OK;
}

static appm_status appm__obj_parse(appm__loader *L, const char *buf, size_t len, const char *path)
{
    appm__lines it;
    const char *s, *e;
    uint32_t mat = 0;
    appm_status st = APPM_OK;
    size_t i;
    L->pos.count = 0;
    L->vt.count = 0;
    L->vn.count = 0;
    L->mat_base = L->mat.count;
    for (i = 0; i < len; ++i)
        if (buf[i] == 0)
            return appm__fail(L->diag, APPM_ERR_PARSE, path, 0,
                              "binary data (NUL byte at offset %.0f): not an OBJ text file", (double)i);
    it.p = buf;
    it.end = buf + len;
    it.line = 0;
    while (appm__next_line(&it, &s, &e)) {
        const char *ts, *te, *ns, *ne;
        if (!appm__token(&s, e, &ts, &te)) continue;
        if (appm__token_is(ts, te, "v"))
            st = appm__obj_v(L, &s, e, it.line);
        else if (appm__token_is(ts, te, "vn"))
            st = appm__obj_vn(L, &s, e, it.line);
        else if (appm__token_is(ts, te, "vt"))
            st = appm__obj_vt(L, &s, e, it.line);
        else if (appm__token_is(ts, te, "f"))
            st = appm__obj_face(L, &s, e, it.line, mat);
        else if (appm__token_is(ts, te, "usemtl"))
            appm__obj_usemtl(L, s, e, it.line, &mat);
        else if (appm__token_is(ts, te, "mtllib")) {
            if (appm__rest(s, e, &ns, &ne)) st = appm__mtl_load(L, path, ns, (size_t)(ne - ns), it.line);
        } else if (appm__token_is(ts, te, "o") || appm__token_is(ts, te, "g") || appm__token_is(ts, te, "s")) {
            /* grouping and smoothing groups: nothing to do */
        } else
            st = appm__obj_ignored(L, ts, te, it.line);
        if (st != APPM_OK) return st;
    }
    return APPM_OK;
}

static appm_status appm__obj_load(appm__loader *L, const char *path, unsigned line)
{
    char *owned;
    const char *buf;
    size_t len;
    appm_status st;
    const char *saved_file = L->file;
    uint64_t saved_warned = L->warned;
    appm_diag quiet;
    appm__diag_clear(&quiet);
    L->mem->diag = &quiet;
    st = appm__loader_read(L, path, &buf, &len, &owned, &quiet);
    L->mem->diag = L->diag;
    if (st == APPM_ERR_IO)
        return appm__fail(L->diag, APPM_ERR_IO, saved_file ? saved_file : path, saved_file ? line : 0,
                          "cannot open mesh '%s'", path);
    if (st != APPM_OK) return appm__fail(L->diag, st, path, 0, "%s", quiet.message);
    L->file = path;
    L->warned = 0;
    st = appm__obj_parse(L, buf, len, path);
    L->file = saved_file;
    L->warned = saved_warned;
    appm__free(L->mem, owned);
    return st;
}

/* ---- 4.4 `.scene` files ---------------------------------------------------- */

/* Reads "key x y z" pairs of a statement in any order into the slots of `keys`. */
typedef struct appm__kv {
    const char *key;
    int n;        /* numbers that follow the key */
    double v[3];
    int seen;
} appm__kv;

static appm_status appm__keyvals(appm__loader *L, const char **s, const char *e, unsigned line,
                                 const char *stmt, appm__kv *kv, int nkv)
{
    const char *ts, *te;
    appm_status st;
    while (appm__token(s, e, &ts, &te)) {
        int k;
        for (k = 0; k < nkv; ++k)
            if (appm__token_is(ts, te, kv[k].key)) break;
        if (k == nkv)
            return appm__fail(L->diag, APPM_ERR_PARSE, L->file, line, "%s: unknown keyword '%.*s'", stmt,
                              (int)(te - ts > 30 ? 30 : te - ts), ts);
        if ((st = appm__numbers(L, s, e, line, kv[k].key, kv[k].v, kv[k].n)) != APPM_OK) return st;
        kv[k].seen = 1;
    }
    return APPM_OK;
}

static appm_status appm__need(appm__loader *L, unsigned line, const char *stmt, const appm__kv *kv,
                              int nkv)
{
    int k;
    for (k = 0; k < nkv; ++k)
        if (!kv[k].seen && kv[k].n > 0 && kv[k].key[0] != '?')
            return appm__fail(L->diag, APPM_ERR_PARSE, L->file, line, "%s: missing '%s'", stmt, kv[k].key);
    return APPM_OK;
}

static appm__v3 appm__kv3(const appm__kv *kv)
{
    return appm__v((float)kv->v[0], (float)kv->v[1], (float)kv->v[2]);
}

static appm_status appm__camera_set(appm__loader *L, unsigned line, appm__v3 eye, appm__v3 target,
                                    appm__v3 up, double fov)
{
    appm__camera *c = &L->cam;
    appm__v3 f = appm__sub(target, eye), r;
    if (!(appm__length(f) > 0.0f))
        return appm__fail(L->diag, APPM_ERR_PARSE, L->file, line, "camera: eye and target coincide");
    f = appm__normalize(f);
    r = appm__cross(f, up);
    if (!(appm__length(r) > 1e-6f * appm__length(up)) || !(appm__length(up) > 0.0f))
        return appm__fail(L->diag, APPM_ERR_PARSE, L->file, line, "camera: up is parallel to the view direction");
    if (!(fov > 0.0 && fov < 180.0))
        return appm__fail(L->diag, APPM_ERR_PARSE, L->file, line, "camera: fov %g is not in (0, 180)", fov);
    if (!((float)tan(0.5 * fov * APPM__PI / 180.0) >= FLT_MIN)) /* tan(fov/2) would underflow */
        return appm__fail(L->diag, APPM_ERR_PARSE, L->file, line, "camera: fov %g is too small", fov);
    c->eye = eye;
    c->forward = f;
    c->right = appm__normalize(r);
    c->up = appm__cross(c->right, f);
    c->fov = (float)fov;
    c->tan_half = (float)tan(0.5 * fov * APPM__PI / 180.0);
    c->target = target;
    c->sky = up;
    c->fov_deg = fov;
    c->framed = 0;
    L->have_camera = 1;
    return APPM_OK;
}

/* mesh: loads the OBJ named by the rest of the line s..e, a path relative to
 * the scene file `path`. */
static appm_status appm__scene_mesh(appm__loader *L, const char *s, const char *e, unsigned line, const char *path)
{
    const char *ns, *ne;
    char mpath[4096];
    if (!appm__rest(s, e, &ns, &ne))
        return appm__fail(L->diag, APPM_ERR_PARSE, path, line, "mesh: missing file name");
    if (!appm__join_path(mpath, sizeof mpath, path, ns, (size_t)(ne - ns)))
        return appm__fail(L->diag, APPM_ERR_PARSE, path, line, "mesh: path too long");
    return appm__obj_load(L, mpath, line);
}

/* camera eye x y z target x y z [up x y z] [fov degrees]: L->cam. */
static appm_status appm__scene_camera(appm__loader *L, const char **s, const char *e, unsigned line,
                                      const char *path)
{
    appm__kv kv[4] = {{"eye", 3, {0, 0, 0}, 0}, {"target", 3, {0, 0, 0}, 0},
                      {"up", 3, {0, 1, 0}, 0}, {"fov", 1, {40, 0, 0}, 0}};
    appm_status st;
    if ((st = appm__keyvals(L, s, e, line, "camera", kv, 4)) != APPM_OK) return st;
    if (!kv[0].seen || !kv[1].seen)
        return appm__fail(L->diag, APPM_ERR_PARSE, path, line, "camera: needs eye and target");
    return appm__camera_set(L, line, appm__kv3(&kv[0]), appm__kv3(&kv[1]), appm__kv3(&kv[2]), kv[3].v[0]);
}

/* lens aperture a focus f, a >= 0 and f > 0: the camera's thin lens. */
static appm_status appm__scene_lens(appm__loader *L, const char **s, const char *e, unsigned line,
                                    const char *path)
{
    appm__kv kv[2] = {{"aperture", 1, {0, 0, 0}, 0}, {"focus", 1, {0, 0, 0}, 0}};
    appm_status st;
    if ((st = appm__keyvals(L, s, e, line, "lens", kv, 2)) != APPM_OK) return st;
    if ((st = appm__need(L, line, "lens", kv, 2)) != APPM_OK) return st;
    if (kv[0].v[0] < 0 || !(kv[1].v[0] > 0))
        return appm__fail(L->diag, APPM_ERR_PARSE, path, line, "lens: aperture must be >= 0 and focus > 0");
    L->cam.aperture = (float)kv[0].v[0];
    L->cam.focus = (float)kv[1].v[0];
    return APPM_OK;
}

/* image width height, integers in 1..32768: L->width, L->height. */
static appm_status appm__scene_image(appm__loader *L, const char **s, const char *e, unsigned line,
                                     const char *path)
{
    double v[2];
    appm_status st;
    if ((st = appm__numbers(L, s, e, line, "image", v, 2)) != APPM_OK ||
        (st = appm__line_end(L, s, e, line, "image")) != APPM_OK)
        return st;
    if (v[0] < 1 || v[1] < 1 || v[0] > 32768 || v[1] > 32768 || v[0] != floor(v[0]) || v[1] != floor(v[1]))
        return appm__fail(L->diag, APPM_ERR_PARSE, path, line,
                          "image: width and height must be integers in 1..32768");
    L->width = (uint32_t)v[0];
    L->height = (uint32_t)v[1];
    return APPM_OK;
}

/* environment r g b (radiance >= 0): light l becomes the environment. */
/* environment map FILE [scale S] [rotate DEG]: the file decoded into
 * L->envmap (section 6.2 makes it a light); FILE relative to the scene file. */
static appm_status appm__scene_envmap(appm__loader *L, appm__light *l, const char **s, const char *e,
                                      unsigned line, const char *path)
{
    appm__kv kv[2] = {{"scale", 1, {1, 0, 0}, 0}, {"rotate", 1, {0, 0, 0}, 0}};
    const char *ts, *te, *buf;
    char mpath[4096], *owned;
    size_t len;
    appm_status st;
    appm_diag why;
    if (L->envmap.px.data) return appm__fail(L->diag, APPM_ERR_PARSE, path, line, "more than one environment");
    if (!appm__token(s, e, &ts, &te))
        return appm__fail(L->diag, APPM_ERR_PARSE, path, line, "environment map: missing file name");
    if (!appm__join_path(mpath, sizeof mpath, path, ts, (size_t)(te - ts)))
        return appm__fail(L->diag, APPM_ERR_PARSE, path, line, "environment map: path too long");
    if ((st = appm__keyvals(L, s, e, line, "environment map", kv, 2)) != APPM_OK) return st;
    if (!(kv[0].v[0] >= 0.0) || !(kv[0].v[0] <= 1e30))
        return appm__fail(L->diag, APPM_ERR_PARSE, path, line, "environment map: scale must be in [0, 1e30]");
    if (!(fabs(kv[1].v[0]) <= 1e6))
        return appm__fail(L->diag, APPM_ERR_PARSE, path, line, "environment map: rotate must be in [-1e6, 1e6] degrees");
    appm__diag_clear(&why);
    L->mem->diag = &why;
    st = appm__loader_read(L, mpath, &buf, &len, &owned, &why);
    if (st == APPM_OK) {
        st = appm__image_decode(L->mem, (const unsigned char *)buf, len, mpath, &L->envmap.px, &why);
        appm__free(L->mem, owned);
    }
    L->mem->diag = L->diag;
    if (st != APPM_OK)
        return appm__fail(L->diag, st, path, line, "environment map '%s': %s", mpath, why.message);
    L->envmap.scale = kv[0].v[0];
    L->envmap.rotate = kv[1].v[0];
    appm__copy_str(L->envmap_path, sizeof L->envmap_path, mpath);
    l->kind = APPM__LIGHT_ENV;
    l->value = appm__v((float)kv[0].v[0], (float)kv[0].v[0], (float)kv[0].v[0]);
    return APPM_OK;
}

static appm_status appm__scene_env(appm__loader *L, appm__light *l, const char **s, const char *e, unsigned line,
                                   const char *path)
{
    double v[3];
    appm_status st;
    {
        const char *save = *s, *ts, *te;
        if (appm__token(&save, e, &ts, &te) && appm__token_is(ts, te, "map")) {
            *s = save;
            return appm__scene_envmap(L, l, s, e, line, path);
        }
    }
    if ((st = appm__numbers(L, s, e, line, "environment", v, 3)) != APPM_OK ||
        (st = appm__line_end(L, s, e, line, "environment")) != APPM_OK)
        return st;
    if (v[0] < 0 || v[1] < 0 || v[2] < 0)
        return appm__fail(L->diag, APPM_ERR_PARSE, path, line, "environment: negative radiance");
    l->kind = APPM__LIGHT_ENV;
    l->value = appm__v((float)v[0], (float)v[1], (float)v[2]);
    return APPM_OK;
}

/* light point position x y z intensity r g b: light l. */
static appm_status appm__scene_point(appm__loader *L, appm__light *l, const char **s, const char *e,
                                     unsigned line)
{
    appm__kv kv[2] = {{"position", 3, {0, 0, 0}, 0}, {"intensity", 3, {0, 0, 0}, 0}};
    appm_status st;
    if ((st = appm__keyvals(L, s, e, line, "light point", kv, 2)) != APPM_OK) return st;
    if ((st = appm__need(L, line, "light point", kv, 2)) != APPM_OK) return st;
    l->kind = APPM__LIGHT_POINT;
    l->pos = appm__kv3(&kv[0]);
    l->value = appm__kv3(&kv[1]);
    return APPM_OK;
}

/* light spot position x y z target x y z intensity r g b [cone deg] [falloff
 * deg], 0 < cone < 180 and 0 <= falloff <= cone: light l. */
static appm_status appm__scene_spot(appm__loader *L, appm__light *l, const char **s, const char *e, unsigned line,
                                    const char *path)
{
    appm__kv kv[5] = {{"position", 3, {0, 0, 0}, 0}, {"target", 3, {0, 0, 0}, 0},
                      {"intensity", 3, {0, 0, 0}, 0}, {"cone", 1, {30, 0, 0}, 0},
                      {"falloff", 1, {0, 0, 0}, 0}};
    double cone, fall;
    appm_status st;
    if ((st = appm__keyvals(L, s, e, line, "light spot", kv, 5)) != APPM_OK) return st;
    if ((st = appm__need(L, line, "light spot", kv, 3)) != APPM_OK) return st;
    cone = kv[3].v[0];
    fall = kv[4].v[0];
    if (!(cone > 0 && cone < 180) || fall < 0 || fall > cone)
        return appm__fail(L->diag, APPM_ERR_PARSE, path, line,
                          "light spot: need 0 < cone < 180 and 0 <= falloff <= cone");
    l->kind = APPM__LIGHT_SPOT;
    l->pos = appm__kv3(&kv[0]);
    l->axis = appm__sub(appm__kv3(&kv[1]), l->pos);
    if (!(appm__length(l->axis) > 0))
        return appm__fail(L->diag, APPM_ERR_PARSE, path, line, "light spot: target equals position");
    l->axis = appm__normalize(l->axis);
    l->value = appm__kv3(&kv[2]);
    l->cos_cone = (float)cos(cone * APPM__PI / 180.0);
    l->cos_inner = (float)cos((cone - fall) * APPM__PI / 180.0);
    l->target = appm__kv3(&kv[1]);
    l->cone = cone;
    l->falloff = fall;
    return APPM_OK;
}

/* light point|spot ... (env = 0) or environment r g b (env = 1): a new entry
 * of L->lights; its intensity or radiance must be >= 0. */
static appm_status appm__scene_light(appm__loader *L, int env, const char **s, const char *e, unsigned line,
                                     const char *path)
{
    appm__light *l;
    const char *ks = NULL, *ke = NULL;
    appm_status st;
    if (!env && !appm__token(s, e, &ks, &ke))
        return appm__fail(L->diag, APPM_ERR_PARSE, path, line, "light: missing kind (point or spot)");
    l = (appm__light *)appm__array_push(L->mem, &L->lights);
    if (!l) return APPM_ERR_NOMEM;
    l->line = line;
    if (env)
        st = appm__scene_env(L, l, s, e, line, path);
    else if (appm__token_is(ks, ke, "point"))
        st = appm__scene_point(L, l, s, e, line);
    else if (appm__token_is(ks, ke, "spot"))
        st = appm__scene_spot(L, l, s, e, line, path);
    else
        return appm__fail(L->diag, APPM_ERR_PARSE, path, line, "light: unknown kind '%.*s' (point or spot)",
                          (int)(ke - ks > 30 ? 30 : ke - ks), ks);
    if (st != APPM_OK) return st;
    if (l->value.x < 0 || l->value.y < 0 || l->value.z < 0)
        return appm__fail(L->diag, APPM_ERR_PARSE, path, line, "light: negative intensity");
    return APPM_OK;
}

static appm_status appm__scene_parse(appm__loader *L, const char *buf, size_t len, const char *path)
{
    appm__lines it;
    const char *s, *e;
    appm_status st;
    size_t i;
    int meshes = 0;
    for (i = 0; i < len; ++i)
        if (buf[i] == 0)
            return appm__fail(L->diag, APPM_ERR_PARSE, path, 0, "binary data: not a scene file");
    it.p = buf;
    it.end = buf + len;
    it.line = 0;
    while (appm__next_line(&it, &s, &e)) {
        const char *ts, *te;
        if (!appm__token(&s, e, &ts, &te)) continue;
        if (appm__token_is(ts, te, "mesh")) {
            st = appm__scene_mesh(L, s, e, it.line, path);
            if (st == APPM_OK) meshes++;
        } else if (appm__token_is(ts, te, "camera"))
            st = appm__scene_camera(L, &s, e, it.line, path);
        else if (appm__token_is(ts, te, "lens"))
            st = appm__scene_lens(L, &s, e, it.line, path);
        else if (appm__token_is(ts, te, "image"))
            st = appm__scene_image(L, &s, e, it.line, path);
        else if (appm__token_is(ts, te, "light") || appm__token_is(ts, te, "environment"))
            st = appm__scene_light(L, ts[0] == 'e', &s, e, it.line, path);
        else
            return appm__fail(L->diag, APPM_ERR_PARSE, path, it.line, "unknown keyword '%.*s'",
                              (int)(te - ts > 30 ? 30 : te - ts), ts);
        if (st != APPM_OK) return st;
    }
    if (meshes == 0 && L->lights.count == 0)
        return appm__fail(L->diag, APPM_ERR_PARSE, path, 0, "empty scene: no mesh and no light");
    return APPM_OK;
}

/* ---- 4.5 Texture lookups -----------------------------------------------------
 *
 * (u, v) from `vt`: u runs left to right, v bottom to top (OBJ's convention),
 * both repeat.  Bilinear between the four texel centres around the point, in
 * linear values: an 8-bit colour sample is sRGB-decoded by the table below
 * before it is blended (blending the codes would darken every edge). */
static const float appm__srgb8[256] = {
     0.0f, 0.000303526991f, 0.000607053982f, 0.000910580973f, 0.00121410796f, 0.00151763496f,
     0.00182116195f, 0.00212468882f, 0.00242821593f, 0.0027317428f, 0.00303526991f, 0.00334653584f,
     0.00367650739f, 0.00402471703f, 0.00439144205f, 0.00477695325f, 0.00518151652f, 0.00560539169f,
     0.00604883302f, 0.00651209056f, 0.00699541019f, 0.00749903219f, 0.00802319311f, 0.00856812578f,
     0.00913405884f, 0.00972121768f, 0.010329823f, 0.0109600937f, 0.0116122449f, 0.012286488f,
     0.0129830325f, 0.0137020834f, 0.0144438436f, 0.0152085144f, 0.0159962941f, 0.0168073755f,
     0.0176419541f, 0.01850022f, 0.0193823613f, 0.0202885624f, 0.0212190095f, 0.0221738853f,
     0.0231533665f, 0.0241576321f, 0.0251868591f, 0.0262412224f, 0.0273208916f, 0.02842604f,
     0.0295568351f, 0.0307134446f, 0.0318960324f, 0.0331047662f, 0.0343398079f, 0.0356013142f,
     0.0368894488f, 0.0382043719f, 0.0395462364f, 0.0409151986f, 0.0423114114f, 0.043735031f,
     0.045186203f, 0.0466650873f, 0.0481718257f, 0.0497065671f, 0.0512694567f, 0.0528606474f,
     0.054480277f, 0.0561284907f, 0.0578054301f, 0.0595112368f, 0.0612460524f, 0.0630100146f,
     0.064803265f, 0.0666259378f, 0.0684781671f, 0.0703600943f, 0.0722718537f, 0.0742135718f,
     0.0761853829f, 0.078187421f, 0.0802198201f, 0.0822827071f, 0.0843762085f, 0.0865004584f,
     0.0886555836f, 0.0908417106f, 0.0930589661f, 0.0953074694f, 0.097587347f, 0.0998987257f,
     0.102241732f, 0.104616486f, 0.107023105f, 0.10946171f, 0.111932427f, 0.114435375f, 0.116970666f,
     0.119538426f, 0.122138776f, 0.124771819f, 0.127437681f, 0.130136475f, 0.13286832f, 0.135633335f,
     0.138431609f, 0.141263291f, 0.144128472f, 0.147027269f, 0.149959788f, 0.152926147f,
     0.155926466f, 0.158960834f, 0.162029371f, 0.165132195f, 0.168269396f, 0.171441108f,
     0.174647406f, 0.177888423f, 0.18116425f, 0.18447499f, 0.187820777f, 0.191201687f, 0.194617838f,
     0.198069319f, 0.20155625f, 0.205078736f, 0.208636865f, 0.212230757f, 0.215860501f, 0.219526201f,
     0.223227963f, 0.226965874f, 0.230740055f, 0.23455058f, 0.238397568f, 0.242281124f, 0.246201321f,
     0.25015828f, 0.254152089f, 0.258182853f, 0.262250662f, 0.266355604f, 0.270497799f, 0.274677306f,
     0.278894275f, 0.283148736f, 0.287440836f, 0.291770637f, 0.296138257f, 0.300543785f,
     0.304987311f, 0.309468925f, 0.313988715f, 0.318546772f, 0.323143214f, 0.327778101f,
     0.332451522f, 0.337163627f, 0.341914415f, 0.346704066f, 0.351532608f, 0.356400132f,
     0.361306787f, 0.366252601f, 0.371237695f, 0.376262128f, 0.38132602f, 0.386429429f, 0.391572475f,
     0.396755219f, 0.401977777f, 0.407240212f, 0.412542611f, 0.417885065f, 0.423267663f,
     0.428690493f, 0.434153646f, 0.439657182f, 0.445201188f, 0.450785786f, 0.456411034f,
     0.462076992f, 0.467783809f, 0.473531485f, 0.479320168f, 0.48514995f, 0.491020858f, 0.496932983f,
     0.502886474f, 0.50888133f, 0.514917672f, 0.520995557f, 0.527115107f, 0.533276379f, 0.539479494f,
     0.545724452f, 0.55201143f, 0.558340371f, 0.564711511f, 0.571124852f, 0.577580452f, 0.584078431f,
     0.590618849f, 0.597201765f, 0.603827357f, 0.610495567f, 0.617206573f, 0.623960376f,
     0.630757153f, 0.637596846f, 0.644479692f, 0.651405632f, 0.658374846f, 0.665387273f,
     0.672443151f, 0.679542482f, 0.686685324f, 0.693871737f, 0.701101899f, 0.708375752f,
     0.715693474f, 0.723055124f, 0.730460763f, 0.73791039f, 0.745404184f, 0.752942204f, 0.760524511f,
     0.768151164f, 0.775822222f, 0.783537805f, 0.791297913f, 0.799102724f, 0.806952238f,
     0.814846575f, 0.822785735f, 0.830769897f, 0.838799f, 0.846873224f, 0.854992628f, 0.863157213f,
     0.871367097f, 0.8796224f, 0.887923121f, 0.896269381f, 0.904661179f, 0.913098633f, 0.921581864f,
     0.930110872f, 0.938685715f, 0.947306514f, 0.955973327f, 0.964686275f, 0.973445296f,
     0.982250571f, 0.991102099f, 1.0f,
};

/* Texel (x, y) of t, channel k, as a linear number; colour of an 8-bit map
 * through appm__srgb8 unless raw (alpha, and the grey of a cut-out map). */
static float appm__texel(const appm__texture *t, uint32_t x, uint32_t y, unsigned k, int raw)
{
    size_t i = ((size_t)y * t->px.w + x) * t->px.channels + k;
    if (t->px.depth == 32) return ((const float *)t->px.data)[i];
    return raw ? ((const unsigned char *)t->px.data)[i] * (1.0f / 255.0f)
               : appm__srgb8[((const unsigned char *)t->px.data)[i]];
}

/* Where (u, v) falls on t: the four texels around it and the weights. */
typedef struct appm__tex_at {
    uint32_t x0, x1, y0, y1;
    float ax, ay;
} appm__tex_at;

static void appm__tex_locate(const appm__texture *t, float u, float v, appm__tex_at *a)
{
    const uint32_t w = t->px.w, h = t->px.h;
    double fx = ((double)u - floor((double)u)) * w - 0.5, fy = (1.0 - ((double)v - floor((double)v))) * h - 0.5;
    double x0f = floor(fx), y0f = floor(fy);
    a->ax = (float)(fx - x0f);
    a->ay = (float)(fy - y0f);
    /* x0f in [-1, w - 1]: wrapped by adding w before the modulo, never on a negative */
    a->x0 = (uint32_t)((int64_t)x0f + w) % w;
    a->y0 = (uint32_t)((int64_t)y0f + h) % h;
    a->x1 = a->x0 + 1 == w ? 0 : a->x0 + 1;
    a->y1 = a->y0 + 1 == h ? 0 : a->y0 + 1;
}

static float appm__tex_sample(const appm__texture *t, const appm__tex_at *a, unsigned c, int raw)
{
    return (1.0f - a->ay) * ((1.0f - a->ax) * appm__texel(t, a->x0, a->y0, c, raw) + a->ax * appm__texel(t, a->x1, a->y0, c, raw)) +
           a->ay * ((1.0f - a->ax) * appm__texel(t, a->x0, a->y1, c, raw) + a->ax * appm__texel(t, a->x1, a->y1, c, raw));
}

/* Linear RGB of t at (u, v) (a grey map's value in all three), bilinear,
 * repeating. */
static appm__v3 appm__tex_rgb(const appm__texture *t, float u, float v)
{
    appm__tex_at a;
    appm__tex_locate(t, u, v, &a);
    if (t->px.channels < 3) {
        float g = appm__tex_sample(t, &a, 0, 0);
        return appm__v(g, g, g);
    }
    return appm__v(appm__tex_sample(t, &a, 0, 0), appm__tex_sample(t, &a, 1, 0), appm__tex_sample(t, &a, 2, 0));
}

/* The cut-out value of map t at (u, v): its alpha, or for a map without
 * alpha the raw value of its first channel (a grey mask), bilinear; the
 * surface is there where this is at least 1/2. */
static float appm__tex_coverage(const appm__texture *t, float u, float v)
{
    appm__tex_at a;
    unsigned nc = t->px.channels;
    appm__tex_locate(t, u, v, &a);
    return appm__tex_sample(t, &a, nc == 2 ? 1 : nc == 4 ? 3 : 0, 1);
}

/* ==== 5. BVH ==============================================================
 *
 * A binary BVH over triangles in one flat array of 32-byte nodes.  Build:
 * binned surface-area heuristic (16 bins on each axis), iterative with an
 * explicit stack; when the centroids of a node coincide (duplicate triangles) or
 * the tree gets deep, the node is split at its median index instead, so the
 * depth stays below APPM__BVH_MAX_DEPTH and traversal needs a fixed stack.
 *
 * Intersection is the watertight test of Woop, Benthin and Wald (JCGT 2013):
 * the ray is sheared to +z, edge functions are evaluated in 2-D and recomputed
 * in double when one is exactly zero, so a ray through a shared edge or vertex
 * of a closed mesh hits at least one of its triangles.
 *
 * Ray origins leaving a surface are pushed off along the geometric normal by a
 * bound on the rounding error of the hit point (pbrt-v3, section 3.9): the point
 * is interpolated from the vertices with barycentrics, its error is at most
 * gamma(7) sum |b_i p_i| per axis, and the offset grows with that - so a scene
 * in millimetres or kilometres, or far from the origin, behaves alike.
 */
#define APPM__BVH_BINS 16
#define APPM__BVH_MAX_DEPTH 96
#define APPM__BVH_FORCE_MEDIAN 64

typedef struct appm__node { /* 32 bytes */
    float bmin[3], bmax[3];
    uint32_t first; /* leaf: first triangle; interior: left child (right = first + 1) */
    uint32_t count; /* triangles in a leaf; 0 for an interior node */
} appm__node;

/* A node of the wide tree: the boxes of its W children as structure of arrays
 * (lo[axis][child]), so one vector load fetches one bound of all children.
 * 128 bytes for W = 4 (two cache lines), 256 for W = 8.  A slot without a
 * child holds the inverted box lo = +inf, hi = -inf, which every ray misses
 * (its near distance is +inf on every axis), so no mask of used slots is kept.
 * Quantised child boxes (Ylitie, Karras and Laine 2017: per node an origin
 * and a power-of-two step per axis, one byte per plane, rounded outward) would
 * halve the node to 128 bytes, but on this project's benchmark the byte-to-float
 * conversion cost more than the memory saved: closest hits 13 % slower with
 * SSE2, no faster with AVX2, any-hit slower with both. */
#define APPM__W_INNER UINT32_MAX /* count of an interior child */

typedef struct appm__wnode {
    float lo[3][APPM__BVH_W], hi[3][APPM__BVH_W];
    uint32_t first[APPM__BVH_W]; /* interior child: its node; leaf: its first pack (scalar build: triangle) */
    uint32_t count[APPM__BVH_W]; /* leaf: its triangles; APPM__W_INNER; 0: no child */
} appm__wnode;

/* A leaf's triangles in packs of four, structure of arrays, so that one vector
 * operation evaluates a step of the watertight test for four triangles.  A
 * leaf child of a wide node names its first pack (first) and its triangles
 * (count: up to APPM__LEAF_MAX, APPM__LEAF_FLAT in a large tree, or a binary leaf's);
 * its packs are consecutive, the last one padded with copies of its first
 * lane whose index is APPM__NO_TRI, so they are never reported.  The scalar
 * path of a SIMD build tests the leaf's triangles in appm_scene.tri, where
 * they are consecutive too, from ptri[first]: a 4-byte entry per pack, 16 to a
 * cache line, where reading the pack's index lane would cost a cache miss
 * the scalar test has no other use for. */
#ifndef APPM__LEAF_MAX
#define APPM__LEAF_MAX 4
#endif
#define APPM__NO_TRI UINT32_MAX
#if defined(APPM__SSE) || defined(APPM__NEON)
#define APPM__PACKS 1 /* a scalar build stores no packs */
#endif

typedef struct appm__tpack { /* 160 bytes */
    float v[3][3][4];        /* v[vertex][axis][lane]: p0, p1, p2 of four triangles */
    uint32_t tri[4];         /* their indices in appm_scene.tri */
} appm__tpack;

/* How appm__intersect and appm__occluded traverse (appm_scene.bvh_path). */
#define APPM__BVH_SIMD 0   /* wide tree, the vector box test where there is one */
#define APPM__BVH_SCALAR 1 /* wide tree, the scalar box test (same answers) */
#define APPM__BVH_BINARY 2 /* the binary tree, kept only when APPM_BVH_BINARY is 1 */
#ifndef APPM_BVH_BINARY
#define APPM_BVH_BINARY 0
#endif

/* At most this many point and spot lights (the most powerful) get a shadow
 * ray of their own at every shading point (6.4, appm__light_table); any
 * others join the one sample that picks among the rest. */
#define APPM__NEE_DELTA 8

struct appm_scene {
    appm__mem mem;
    appm__tri *tri;        /* BVH order */
    appm__tri_info *info;  /* same order */
    uint32_t ntri;
    appm__v3 *normals;     /* shading normals, three per smooth triangle */
    uint32_t nnormals;
    uint32_t *open_off;    /* per triangle (ntri + 1): its span of open_ref; NULL: no open edge (5.5) */
    uint32_t *open_ref;    /* the open edges near each triangle, as 3 t + k (corners k, k + 1 of t) */
    uint32_t nopen;        /* open edges */
    appm__material *mat;
    uint32_t nmat;
    appm__texture *tex;    /* the maps materials name (appm__material.map_kd, ...) */
    uint32_t ntex;
    float *uv;             /* (u, v) pairs, three per textured triangle (tri_info.uv0) */
    uint64_t tex_bytes;    /* the maps' samples */
    int cutouts;           /* a material has map_d: appm__intersect looks through its holes */
    appm__light *light;
    uint32_t nlight;
    double *light_cdf;     /* nlight + 1 entries, light_cdf[nlight] == 1 */
    double *nee_cdf[2];    /* nlight + 1 entries each after light_cdf's, in its allocation: the
                            * shadow ray's one-sample choice (appm__light.nee[t]); nee_cdf[t][nlight]
                            * 1, or 0 when there is nothing to pick */
    uint32_t nee_delta[APPM__NEE_DELTA]; /* the nee_all lights */
    uint32_t nnee_delta;
    int env;               /* index of the environment light, or -1 */
    int env_auto;          /* that environment is the stand-in of a bare OBJ without light: 1 white, 2 the studio's sky */
    appm__envmap envmap;   /* the environment's map (rgb NULL: a constant environment) */
    appm__node *node;      /* binary SAH tree: freed after the collapse unless APPM_BVH_BINARY */
    uint32_t nnode, depth; /* of the binary tree */
    appm__node root;       /* its root box (the box-test slack is measured on it) */
    appm__wnode *wnode;    /* the wide tree the renderer traverses, 64-byte aligned */
    void *wnode_mem;       /* the allocation holding it */
    uint32_t nwnode, wdepth; /* of the wide tree */
    appm__tpack *pack;     /* leaf triangles, in the same allocation after the nodes */
    uint32_t *ptri;        /* per pack, its first lane's triangle (after the packs): the
                            * scalar path finds a leaf's triangles without reading its pack */
    uint32_t npack;
    int bvh_path;          /* APPM__BVH_SIMD, _SCALAR or _BINARY */
    appm__camera cam;
    uint32_t width, height;
    appm__v3 bmin, bmax, center;
    float radius;          /* bounding-sphere radius of the geometry */
    appm__v3 focus;        /* the studio's model: the centre of its bounding sphere (6.3) */
    float focus_r;         /* and its radius; 0: no focus (every scene but the studio) */
    appm__v3 plate;        /* the studio's plate: its centre (facing +y) */
    float plate_e;         /* and half its width */
    uint64_t dropped;
    char name[256];
};

typedef struct appm__ray {
    appm__v3 o, d;
    float tmin, tmax;
    /* precomputed by appm__ray_setup */
    appm__v3 inv;
    int kx, ky, kz;
    float sx, sy, sz;
    size_t off[3];  /* byte offsets of components kx, ky, kz in an appm__v3 */
    float ok[3];    /* the origin's components kx, ky, kz */
    int valid;
} appm__ray;

typedef struct appm__hit {
    float t, b1, b2; /* barycentrics of p1 and p2 */
    uint32_t tri;
} appm__hit;

/* Branch-free: a ray's dominant axis and the sign of its component are as
 * good as random, so branches on them would mostly be mispredicted. */
static void appm__ray_setup(appm__ray *r)
{
    static const int next[3] = {1, 2, 0};
    static const size_t off[3] = {offsetof(appm__v3, x), offsetof(appm__v3, y), offsetof(appm__v3, z)};
    float ax = fabsf(r->d.x), ay = fabsf(r->d.y), az = fabsf(r->d.z), dz;
    float dv[3], ov[3];
    int xy, kx, ky, neg;
    r->valid = appm__finite3(r->o) && appm__finite3(r->d) && (ax > 0 || ay > 0 || az > 0) &&
               r->tmax == r->tmax && r->tmin == r->tmin;
    if (!r->valid) return;
    dv[0] = r->d.x, dv[1] = r->d.y, dv[2] = r->d.z;
    ov[0] = r->o.x, ov[1] = r->o.y, ov[2] = r->o.z;
    xy = ax > ay; /* kz = ax > ay ? (ax > az ? 0 : 2) : (ay > az ? 1 : 2) */
    r->kz = 2 - (xy & (ax > az)) * 2 - (!xy & (ay > az));
    kx = next[r->kz];
    ky = next[kx];
    dz = dv[r->kz];
    neg = dz < 0.0f; /* keep the winding: swap x and y */
    r->kx = neg ? ky : kx;
    r->ky = neg ? kx : ky;
    r->sx = dv[r->kx] / dz;
    r->sy = dv[r->ky] / dz;
    r->inv = appm__v(1.0f / r->d.x, 1.0f / r->d.y, 1.0f / r->d.z); /* +-inf for 0 and -0 */
    r->sz = 1.0f / dz;
    r->off[0] = off[r->kx];
    r->off[1] = off[r->ky];
    r->off[2] = off[r->kz];
    r->ok[0] = ov[r->kx];
    r->ok[1] = ov[r->ky];
    r->ok[2] = ov[r->kz];
}

/* Component kx, ky or kz of a vertex, read through the ray's offsets: no
 * branch on the ray's axes in the triangle test. */
#define APPM__VC(r, v, i) (*(const float *)((const char *)&(v) + (r)->off[i]) - (r)->ok[i])

/* Woop-Benthin-Wald watertight test; on a hit in (tmin, tmax) fills h. */
static int appm__tri_hit(const appm__ray *r, const appm__tri *tr, appm__hit *h)
{
    /* A = p0 - o etc., in the ray's axis order, then sheared to +z */
    float Akz = APPM__VC(r, tr->p0, 2), Bkz = APPM__VC(r, tr->p1, 2), Ckz = APPM__VC(r, tr->p2, 2);
    float Ax = APPM__VC(r, tr->p0, 0) - r->sx * Akz, Ay = APPM__VC(r, tr->p0, 1) - r->sy * Akz;
    float Bx = APPM__VC(r, tr->p1, 0) - r->sx * Bkz, By = APPM__VC(r, tr->p1, 1) - r->sy * Bkz;
    float Cx = APPM__VC(r, tr->p2, 0) - r->sx * Ckz, Cy = APPM__VC(r, tr->p2, 1) - r->sy * Ckz;
    float U = Cx * By - Cy * Bx, V = Ax * Cy - Ay * Cx, W = Bx * Ay - By * Ax;
    float det, T, t;
    if (U == 0.0f || V == 0.0f || W == 0.0f) { /* on an edge: decide in double */
        U = (float)((double)Cx * By - (double)Cy * Bx);
        V = (float)((double)Ax * Cy - (double)Ay * Cx);
        W = (float)((double)Bx * Ay - (double)By * Ax);
    }
    if ((U < 0.0f || V < 0.0f || W < 0.0f) && (U > 0.0f || V > 0.0f || W > 0.0f)) return 0;
    det = U + V + W;
    if (det == 0.0f || det != det) return 0;
    T = U * (r->sz * Akz) + V * (r->sz * Bkz) + W * (r->sz * Ckz);
    t = T / det;
    if (!(t > r->tmin && t < r->tmax)) return 0;
    {
        /* t must exceed the bound on its own rounding error (after pbrt-v3,
         * 3.9.6): translating vertices much larger than the hit point can
         * otherwise give a small positive t for a ray that leaves the triangle.
         * Unlike pbrt, the shear error of x and y is bounded with the world-unit
         * z extent times |S_x|, |S_y| <= 1, so the bound stays tight for rays
         * whose direction is not of unit length (shadow rays). */
        const float g = FLT_EPSILON * 0.5f;
        const float g2 = 2 * g / (1 - 2 * g), g3 = 3 * g / (1 - 3 * g), g5 = 5 * g / (1 - 5 * g);
        float mzw = fmaxf(fabsf(Akz), fmaxf(fabsf(Bkz), fabsf(Ckz))), mz = fabsf(r->sz) * mzw;
        float mx = fmaxf(fabsf(Ax), fmaxf(fabsf(Bx), fabsf(Cx)));
        float my = fmaxf(fabsf(Ay), fmaxf(fabsf(By), fabsf(Cy)));
        float dz = g3 * mz, dx = g5 * (mx + fabsf(r->sx) * mzw), dy = g5 * (my + fabsf(r->sy) * mzw);
        float de = 2 * (g2 * mx * my + dy * mx + dx * my);
        float me = fmaxf(fabsf(U), fmaxf(fabsf(V), fabsf(W)));
        float dt = 3 * (g3 * me * mz + de * mz + dz * me) / fabsf(det);
        if (!(t > dt)) return 0;
    }
    h->t = t;
    h->b1 = V / det;
    h->b2 = W / det;
    return 1;
}

/* The slack of a ray's box tests.  A triangle's t from the watertight test
 * carries a rounding error that grows with the distance to its vertices, not
 * with t (they are translated to the ray origin), so a triangle hit just below
 * tmax, or lying on a face of its box, could be culled by an exact box test.
 * Every vertex lies in the root box, so 64 epsilon times the farthest finite
 * distance to a root-box plane bounds that error for the whole traversal.  A
 * false hit costs a node visit; a false miss would be a hole. */
static inline float appm__box_slack(const appm__ray *r, const appm__node *root)
{
    float v[6], m = 0.0f;
    int k;
    v[0] = (root->bmin[0] - r->o.x) * r->inv.x;
    v[1] = (root->bmax[0] - r->o.x) * r->inv.x;
    v[2] = (root->bmin[1] - r->o.y) * r->inv.y;
    v[3] = (root->bmax[1] - r->o.y) * r->inv.y;
    v[4] = (root->bmin[2] - r->o.z) * r->inv.z;
    v[5] = (root->bmax[2] - r->o.z) * r->inv.z;
    for (k = 0; k < 6; ++k) { /* branch-free: which plane is farthest is unpredictable */
        float a = fabsf(v[k]);
        a = a <= FLT_MAX ? a : 0.0f; /* inf and NaN (0 * inf) do not count */
        m = a > m ? a : m;
    }
    return 64.0f * FLT_EPSILON * m;
}

#if APPM_BVH_BINARY
/* Slab test of a node against (tmin, tmax + slack).
 *
 * A direction component of 0 (or -0) makes inv infinite: a ray strictly inside
 * the slab gets (-inf, inf), one outside an empty interval, and one lying
 * exactly in a bounding plane gets 0 * inf = NaN, which is taken as "no
 * constraint" (the ray stays on the closed slab for all t). */
static inline int appm__box_hit(const appm__ray *r, const appm__node *n, float tmax, float slack,
                                float *tnear)
{
    float t0 = r->tmin, t1 = tmax, a, b, lo, hi;
    a = (n->bmin[0] - r->o.x) * r->inv.x;
    b = (n->bmax[0] - r->o.x) * r->inv.x;
    lo = a < b ? a : b;
    hi = a < b ? b : a;
    if (lo <= hi) { /* false only for NaN: the ray lies in a bounding plane */
        t0 = lo > t0 ? lo : t0;
        t1 = hi < t1 ? hi : t1;
    }
    a = (n->bmin[1] - r->o.y) * r->inv.y;
    b = (n->bmax[1] - r->o.y) * r->inv.y;
    lo = a < b ? a : b;
    hi = a < b ? b : a;
    if (lo <= hi) {
        t0 = lo > t0 ? lo : t0;
        t1 = hi < t1 ? hi : t1;
    }
    a = (n->bmin[2] - r->o.z) * r->inv.z;
    b = (n->bmax[2] - r->o.z) * r->inv.z;
    lo = a < b ? a : b;
    hi = a < b ? b : a;
    if (lo <= hi) {
        t0 = lo > t0 ? lo : t0;
        t1 = hi < t1 ? hi : t1;
    }
    *tnear = t0;
    return t0 <= t1 + slack;
}

/* The binary traversal the wide one replaced, kept for benchmarks and tests
 * (APPM_BVH_BINARY=1 keeps the binary tree too).  Closest hit in (tmin, tmax),
 * ignoring triangle `skip`. */
static int appm__intersect_bin(const appm_scene *s, const appm__ray *r, uint32_t skip, appm__hit *h)
{
    uint32_t stack[APPM__BVH_MAX_DEPTH + 4];
    int sp = 0, found = 0;
    uint32_t ni = 0;
    float tmax = r->tmax, slack;
    appm__ray q;
    if (!r->valid || s->nnode == 0) return 0;
    q = *r;
    slack = appm__box_slack(r, &s->root);
    for (;;) {
        const appm__node *n = &s->node[ni];
        if (n->count) {
            uint32_t i;
            for (i = n->first; i < n->first + n->count; ++i) {
                if (i == skip) continue;
                q.tmax = tmax;
                if (appm__tri_hit(&q, &s->tri[i], h)) {
                    tmax = h->t;
                    h->tri = i;
                    found = 1;
                }
            }
        } else {
            float d0, d1;
            int h0 = appm__box_hit(r, &s->node[n->first], tmax, slack, &d0);
            int h1 = appm__box_hit(r, &s->node[n->first + 1], tmax, slack, &d1);
            if (h0 && h1) {
                if (d1 < d0) {
                    stack[sp++] = n->first;
                    ni = n->first + 1;
                } else {
                    stack[sp++] = n->first + 1;
                    ni = n->first;
                }
                continue;
            }
            if (h0 || h1) {
                ni = h0 ? n->first : n->first + 1;
                continue;
            }
        }
        if (sp == 0) break;
        ni = stack[--sp];
        { /* pop nodes that now lie beyond the closest hit */
            float dn;
            while (!appm__box_hit(r, &s->node[ni], tmax, slack, &dn)) {
                if (sp == 0) return found;
                ni = stack[--sp];
            }
        }
    }
    return found;
}

/* Any hit in (tmin, tmax), ignoring triangles skip0 and skip1. */
static int appm__occluded_bin(const appm_scene *s, const appm__ray *r, uint32_t skip0, uint32_t skip1)
{
    uint32_t stack[APPM__BVH_MAX_DEPTH + 4];
    int sp = 0;
    uint32_t ni = 0;
    appm__hit h;
    float slack;
    if (!r->valid || s->nnode == 0) return 0;
    slack = appm__box_slack(r, &s->root);
    for (;;) {
        const appm__node *n = &s->node[ni];
        float d;
        if (appm__box_hit(r, n, r->tmax, slack, &d)) {
            if (n->count) {
                uint32_t i;
                for (i = n->first; i < n->first + n->count; ++i)
                    if (i != skip0 && i != skip1 && appm__tri_hit(r, &s->tri[i], &h)) return 1;
            } else {
                stack[sp++] = n->first + 1;
                ni = n->first;
                continue;
            }
        }
        if (sp == 0) return 0;
        ni = stack[--sp];
    }
}
#endif

/* ---- 5.1 Wide traversal ---------------------------------------------------
 *
 * A node's W child boxes are tested at once; the hit children are visited
 * nearest first (their entry distances sorted, at most W of them), the others
 * pushed with their entry distance, so a pop can drop a node that lies beyond
 * the closest hit found since without testing its box again.
 *
 * The slab test uses, per axis, the plane the ray enters first (lo for a
 * positive direction component, hi for a negative one, chosen once per ray):
 *   t_near = (near - o) inv,  t_far = (far - o) inv,
 *   t0 = max(t0, t_near),  t1 = min(t1, t_far),  hit iff t0 <= t1 + slack.
 * With a finite inv the planes' order makes t_near <= t_far, so this is the
 * binary tree's min/max test.  A zero component gives inv = +-inf: a ray
 * outside the slab gets t_near = +inf (a miss), one inside (-inf, +inf), and
 * one lying exactly in a bounding plane 0 * inf = NaN, which the comparisons
 * below (written as "x > t0 ? x : t0") ignore: the ray stays on the closed slab,
 * as in the binary test.  SSE's maxps/minps are exactly these comparisons, NEON
 * uses compare-and-select for the same, and the scalar loop spells them out:
 * every path computes the same floats, hence the same hits.
 */
typedef struct appm__bray { /* a ray prepared for the wide box test */
    float o[3], inv[3], tmin, slack;
    size_t near_off[3], far_off[3]; /* byte offsets of lo[k] / hi[k] in a node */
#if defined(APPM__AVX8)
    __m256 vo[3], vinv[3], vtmin, vslack;
#elif defined(APPM__SSE)
    __m128 vo[3], vinv[3], vtmin, vslack;
#elif defined(APPM__NEON)
    float32x4_t vo[3], vinv[3], vtmin, vslack;
#endif
} appm__bray;

static inline void appm__bray_init(appm__bray *b, const appm__ray *r, float slack)
{
    int k;
    for (k = 0; k < 3; ++k) {
        float inv = appm__comp(r->inv, k);
        size_t lo = offsetof(appm__wnode, lo) + (size_t)k * APPM__BVH_W * sizeof(float);
        size_t hi = offsetof(appm__wnode, hi) + (size_t)k * APPM__BVH_W * sizeof(float);
        int neg = inv < 0.0f; /* -0 gives inv = -inf: negative too */
        b->o[k] = appm__comp(r->o, k);
        b->inv[k] = inv;
        b->near_off[k] = neg ? hi : lo;
        b->far_off[k] = neg ? lo : hi;
#if defined(APPM__AVX8)
        b->vo[k] = _mm256_set1_ps(b->o[k]);
        b->vinv[k] = _mm256_set1_ps(inv);
#elif defined(APPM__SSE)
        b->vo[k] = _mm_set1_ps(b->o[k]);
        b->vinv[k] = _mm_set1_ps(inv);
#elif defined(APPM__NEON)
        b->vo[k] = vdupq_n_f32(b->o[k]);
        b->vinv[k] = vdupq_n_f32(inv);
#endif
    }
    b->tmin = r->tmin;
    b->slack = slack;
#if defined(APPM__AVX8)
    b->vtmin = _mm256_set1_ps(r->tmin);
    b->vslack = _mm256_set1_ps(slack);
#elif defined(APPM__SSE)
    b->vtmin = _mm_set1_ps(r->tmin);
    b->vslack = _mm_set1_ps(slack);
#elif defined(APPM__NEON)
    b->vtmin = vdupq_n_f32(r->tmin);
    b->vslack = vdupq_n_f32(slack);
#endif
}

#define APPM__PLANE(n, off) ((const float *)((const char *)(n) + (off)))

/* The reference path: bit j of the result says child j is hit, tnear[j] its
 * entry distance (meaningful for hit children only).  The collapse puts a
 * node's children in its first slots, so the loop stops at the first empty
 * one; an empty slot's box is missed anyway, so the SIMD tests, which take
 * all slots of a vector, give the same mask. */
/* t0 only grows and t1 only shrinks from axis to axis (neither is ever NaN),
 * so a box missed after one or two axes stays missed: where every operation
 * goes through memory (tcc) stopping there pays; elsewhere the branch costs
 * more than the arithmetic it saves. */
#if defined(__TINYC__)
#define APPM__EARLY_MISS(t0, t1, slack) (!((t0) <= (t1) + (slack)))
#else
#define APPM__EARLY_MISS(t0, t1, slack) 0
#endif
static unsigned appm__boxes_scalar(const appm__bray *b, const appm__wnode *n, float tmax, float *tnear)
{
    /* the planes and the ray in locals, the axes unrolled: compilers that do
     * not unroll or keep values in registers (tcc) get a short loop too */
    const float *nx = APPM__PLANE(n, b->near_off[0]), *fx = APPM__PLANE(n, b->far_off[0]);
    const float *ny = APPM__PLANE(n, b->near_off[1]), *fy = APPM__PLANE(n, b->far_off[1]);
    const float *nz = APPM__PLANE(n, b->near_off[2]), *fz = APPM__PLANE(n, b->far_off[2]);
    const float ox = b->o[0], oy = b->o[1], oz = b->o[2], ix = b->inv[0], iy = b->inv[1], iz = b->inv[2];
    const float tmin = b->tmin, slack = b->slack;
    unsigned m = 0;
    int j;
    for (j = 0; j < APPM__BVH_W && n->count[j]; ++j) { /* used slots come first */
        float t0 = tmin, t1 = tmax, tn, tf;
        tn = (nx[j] - ox) * ix;
        tf = (fx[j] - ox) * ix;
        t0 = tn > t0 ? tn : t0;
        t1 = tf < t1 ? tf : t1;
        if (APPM__EARLY_MISS(t0, t1, slack)) continue;
        tn = (ny[j] - oy) * iy;
        tf = (fy[j] - oy) * iy;
        t0 = tn > t0 ? tn : t0;
        t1 = tf < t1 ? tf : t1;
        if (APPM__EARLY_MISS(t0, t1, slack)) continue;
        tn = (nz[j] - oz) * iz;
        tf = (fz[j] - oz) * iz;
        t0 = tn > t0 ? tn : t0;
        t1 = tf < t1 ? tf : t1;
        tnear[j] = t0;
        if (t0 <= t1 + slack) m |= 1u << j;
    }
    return m;
}

#if defined(APPM__AVX8)
static unsigned appm__boxes_simd(const appm__bray *b, const appm__wnode *n, float tmax, float *tnear)
{
    __m256 t0 = b->vtmin, t1 = _mm256_set1_ps(tmax);
    int k;
    for (k = 0; k < 3; ++k) { /* _mm256_max_ps(x, t0) is x > t0 ? x : t0 */
        __m256 tn = _mm256_mul_ps(_mm256_sub_ps(_mm256_loadu_ps(APPM__PLANE(n, b->near_off[k])), b->vo[k]),
                                  b->vinv[k]);
        __m256 tf = _mm256_mul_ps(_mm256_sub_ps(_mm256_loadu_ps(APPM__PLANE(n, b->far_off[k])), b->vo[k]),
                                  b->vinv[k]);
        t0 = _mm256_max_ps(tn, t0);
        t1 = _mm256_min_ps(tf, t1);
    }
    _mm256_storeu_ps(tnear, t0);
    return (unsigned)_mm256_movemask_ps(_mm256_cmp_ps(t0, _mm256_add_ps(t1, b->vslack), _CMP_LE_OQ));
}
#elif defined(APPM__SSE)
/* Four children at a time (two vectors for W = 8 without AVX2). */
static unsigned appm__boxes_simd(const appm__bray *b, const appm__wnode *n, float tmax, float *tnear)
{
    unsigned m = 0;
    int j, k;
    for (j = 0; j < APPM__BVH_W && n->count[j]; j += 4) { /* an empty half is skipped */
        __m128 t0 = b->vtmin, t1 = _mm_set1_ps(tmax);
        for (k = 0; k < 3; ++k) { /* _mm_max_ps(x, t0) is x > t0 ? x : t0, NaN x included */
            __m128 tn = _mm_mul_ps(_mm_sub_ps(_mm_loadu_ps(APPM__PLANE(n, b->near_off[k]) + j), b->vo[k]),
                                   b->vinv[k]);
            __m128 tf = _mm_mul_ps(_mm_sub_ps(_mm_loadu_ps(APPM__PLANE(n, b->far_off[k]) + j), b->vo[k]),
                                   b->vinv[k]);
            t0 = _mm_max_ps(tn, t0);
            t1 = _mm_min_ps(tf, t1);
        }
        _mm_storeu_ps(tnear + j, t0);
        m |= (unsigned)_mm_movemask_ps(_mm_cmple_ps(t0, _mm_add_ps(t1, b->vslack))) << j;
    }
    return m;
}
#elif defined(APPM__NEON)
static unsigned appm__boxes_simd(const appm__bray *b, const appm__wnode *n, float tmax, float *tnear)
{
    static const uint32_t bit[4] = {1, 2, 4, 8};
    unsigned m = 0;
    int j, k;
    for (j = 0; j < APPM__BVH_W && n->count[j]; j += 4) { /* an empty half is skipped */
        float32x4_t t0 = b->vtmin, t1 = vdupq_n_f32(tmax);
        uint32x4_t hit;
        for (k = 0; k < 3; ++k) { /* fmax would differ on NaN and on -0: select instead */
            float32x4_t tn =
                vmulq_f32(vsubq_f32(vld1q_f32(APPM__PLANE(n, b->near_off[k]) + j), b->vo[k]), b->vinv[k]);
            float32x4_t tf =
                vmulq_f32(vsubq_f32(vld1q_f32(APPM__PLANE(n, b->far_off[k]) + j), b->vo[k]), b->vinv[k]);
            t0 = vbslq_f32(vcgtq_f32(tn, t0), tn, t0);
            t1 = vbslq_f32(vcltq_f32(tf, t1), tf, t1);
        }
        vst1q_f32(tnear + j, t0);
        hit = vandq_u32(vcleq_f32(t0, vaddq_f32(t1, b->vslack)), vld1q_u32(bit));
        m |= (unsigned)vaddvq_u32(hit) << j;
    }
    return m;
}
#endif

#if defined(APPM__SSE) || defined(APPM__NEON)
#define APPM__BOXES(b, n, tmax, tnear, scalar)                                                               \
    ((scalar) ? appm__boxes_scalar(b, n, tmax, tnear) : appm__boxes_simd(b, n, tmax, tnear))
#else
#define APPM__BOXES(b, n, tmax, tnear, scalar) ((void)(scalar), appm__boxes_scalar(b, n, tmax, tnear))
#endif

typedef struct appm__wentry { /* a traversal stack entry */
    uint32_t first, count;    /* as in appm__wnode: a node, or a leaf's triangles */
    float tnear;              /* entry distance of its box */
} appm__wentry;

/* Lowest set bit of a nonzero mask. */
#if (defined(__GNUC__) || defined(__clang__)) && !defined(__TINYC__)
#define APPM__CTZ(m) __builtin_ctz(m)
#else
static int appm__ctz(unsigned m) /* de Bruijn: the lowest bit times B has a unique top 5 bits */
{
    static const unsigned char pos[32] = {0,  1,  28, 2,  29, 14, 24, 3, 30, 22, 20, 15, 25, 17, 4,  8,
                                          31, 27, 13, 23, 21, 19, 16, 7, 26, 12, 18, 6,  11, 5,  10, 9};
    return pos[((m & (0u - m)) * 0x077CB531u & 0xffffffffu) >> 27];
}
#define APPM__CTZ(m) appm__ctz(m)
#endif

/* Pushes the children of n in mask m onto st (st[0] the bottom), farthest
 * deepest, so that they pop nearest first, ties by slot (as a stable sort of
 * the entry distances would order them: deterministic); returns how many. */
static int appm__push_children(const appm__wnode *n, unsigned m, const float *tnear, appm__wentry *st)
{
    int c = 0, i;
    while (m) {
        int j = APPM__CTZ(m);
        appm__wentry e;
        m &= m - 1;
        e.first = n->first[j];
        e.count = n->count[j];
        e.tnear = tnear[j];
        for (i = c; i > 0 && st[i - 1].tnear <= e.tnear; --i) st[i] = st[i - 1];
        st[i] = e;
        c++;
    }
    return c;
}

/* A hint to start loading memory needed soon; nothing where it is not known. */
#if (defined(__GNUC__) || defined(__clang__)) && !defined(__TINYC__)
/* Prefetch of what a stack entry will read: every cache line of a node, or
 * the first of a leaf's triangles. */
static void appm__prefetch_entry(const appm_scene *s, const appm__wentry *e)
{
    if (e->count == APPM__W_INNER) {
        const char *p = (const char *)&s->wnode[e->first];
        size_t k;
        for (k = 0; k < sizeof(appm__wnode); k += 64) __builtin_prefetch(p + k);
    } else {
#if defined(APPM__PACKS)
        __builtin_prefetch(&s->pack[e->first]);
        __builtin_prefetch((const char *)&s->pack[e->first] + 64);
#else
        __builtin_prefetch(&s->tri[e->first]);
#endif
    }
}
#define APPM__PREFETCH_ENTRY(s, e) appm__prefetch_entry(s, e)
/* Of a triangle that is the closest hit so far (once per leaf that gives one):
 * what appm__surface will read of it (its corners and its shading record),
 * fetched while the traversal goes on, since the ray most often ends at it. */
#define APPM__PREFETCH_HIT(s, i) (__builtin_prefetch(&(s)->tri[i]), __builtin_prefetch(&(s)->info[i]))
#else
#define APPM__PREFETCH_ENTRY(s, e) ((void)(s), (void)(e))
#define APPM__PREFETCH_HIT(s, i) ((void)(s), (void)(i))
#endif

#define APPM__WSTACK ((APPM__BVH_W - 1) * APPM__BVH_MAX_DEPTH + APPM__BVH_W)

/* ---- 5.2 Leaf packs -----------------------------------------------------------
 *
 * appm__pack_hit is appm__tri_hit for four triangles at once: the same float
 * operations on the same operands in the same order (no contraction), lane by
 * lane, so each lane's t, b1, b2 and verdict are appm__tri_hit's bit for bit.
 * Two details make that exact.  A lane with an edge function exactly 0 has
 * U, V, W recomputed in double, in scalar code, as appm__tri_hit does.  And
 * fmaxf, which ignores a NaN operand, becomes maxps, which does not: they differ
 * only when a vertex difference is NaN, and then det is NaN too, so the lane is
 * a miss either way.  A lane is a hit when appm__tri_hit would accept it with
 * tmax = the leaf's entry tmax; the caller keeps the first nearest lane, which is
 * what a plain loop with a shrinking tmax keeps.  A scalar build stores no packs:
 * its leaves name their triangles directly. */

#if defined(APPM__PACKS)
/* Recomputes U, V, W in double for the lanes of `zero` (appm__tri_hit's edge rule). */
static void appm__pack_edges_double(unsigned zero, const float *A, float *U, float *V, float *W)
{
    /* A: Ax, Ay, Bx, By, Cx, Cy, four lanes each */
    while (zero) {
        int j = APPM__CTZ(zero);
        double Ax = A[j], Ay = A[4 + j], Bx = A[8 + j], By = A[12 + j], Cx = A[16 + j], Cy = A[20 + j];
        zero &= zero - 1;
        U[j] = (float)(Cx * By - Cy * Bx);
        V[j] = (float)(Ax * Cy - Ay * Cx);
        W[j] = (float)(Bx * Ay - By * Ax);
    }
}
#endif

/* The error-bound constants of appm__tri_hit, computed the same way. */
#define APPM__TRI_G (FLT_EPSILON * 0.5f)
#define APPM__TRI_G2 (2 * APPM__TRI_G / (1 - 2 * APPM__TRI_G))
#define APPM__TRI_G3 (3 * APPM__TRI_G / (1 - 3 * APPM__TRI_G))
#define APPM__TRI_G5 (5 * APPM__TRI_G / (1 - 5 * APPM__TRI_G))

#if defined(APPM__SSE)
#define APPM__V4 __m128
#define APPM__LD(p) _mm_loadu_ps(p)
#define APPM__SET(x) _mm_set1_ps(x)
#define APPM__ADD(a, b) _mm_add_ps(a, b)
#define APPM__SUB(a, b) _mm_sub_ps(a, b)
#define APPM__MUL(a, b) _mm_mul_ps(a, b)
#define APPM__DIV(a, b) _mm_div_ps(a, b)
#define APPM__MAX(a, b) _mm_max_ps(a, b)
#define APPM__ABS(a) _mm_andnot_ps(_mm_set1_ps(-0.0f), a)
#define APPM__ST(p, a) _mm_storeu_ps(p, a)
#define APPM__M4 __m128
#define APPM__EQ(a, b) _mm_cmpeq_ps(a, b)
#define APPM__LT(a, b) _mm_cmplt_ps(a, b)
#define APPM__GT(a, b) _mm_cmpgt_ps(a, b)
#define APPM__OR(a, b) _mm_or_ps(a, b)
#define APPM__AND(a, b) _mm_and_ps(a, b)
#define APPM__ANDNOT(a, b) _mm_andnot_ps(a, b) /* ~a & b */
#define APPM__MASK(a) ((unsigned)_mm_movemask_ps(a))
#elif defined(APPM__NEON)
#define APPM__V4 float32x4_t
#define APPM__LD(p) vld1q_f32(p)
#define APPM__SET(x) vdupq_n_f32(x)
#define APPM__ADD(a, b) vaddq_f32(a, b)
#define APPM__SUB(a, b) vsubq_f32(a, b)
#define APPM__MUL(a, b) vmulq_f32(a, b)
#define APPM__DIV(a, b) vdivq_f32(a, b)
#define APPM__MAX(a, b) vmaxq_f32(a, b)
#define APPM__ABS(a) vabsq_f32(a)
#define APPM__ST(p, a) vst1q_f32(p, a)
#define APPM__M4 uint32x4_t
#define APPM__EQ(a, b) vceqq_f32(a, b)
#define APPM__LT(a, b) vcltq_f32(a, b)
#define APPM__GT(a, b) vcgtq_f32(a, b)
#define APPM__OR(a, b) vorrq_u32(a, b)
#define APPM__AND(a, b) vandq_u32(a, b)
#define APPM__ANDNOT(a, b) vbicq_u32(b, a)
static unsigned appm__neon_mask(uint32x4_t m)
{
    static const uint32_t bit[4] = {1, 2, 4, 8};
    return (unsigned)vaddvq_u32(vandq_u32(m, vld1q_u32(bit)));
}
#define APPM__MASK(a) appm__neon_mask(a)
#endif

#if defined(APPM__PACKS)
/* The lanes of pk hit by r in (tmin, tmax), with their t and V, W, det (vw[0..11]). */
static inline unsigned appm__pack_hit(const appm__ray *r, const appm__tpack *pk, float tmax, float *tt,
                                      float *vw)
{
    const APPM__V4 z = APPM__SET(0.0f), sx = APPM__SET(r->sx), sy = APPM__SET(r->sy), sz = APPM__SET(r->sz);
    const APPM__V4 ox = APPM__SET(r->ok[0]), oy = APPM__SET(r->ok[1]), oz = APPM__SET(r->ok[2]);
    APPM__V4 Az = APPM__SUB(APPM__LD(pk->v[0][r->kz]), oz), Bz = APPM__SUB(APPM__LD(pk->v[1][r->kz]), oz);
    APPM__V4 Cz = APPM__SUB(APPM__LD(pk->v[2][r->kz]), oz);
    APPM__V4 Ax = APPM__SUB(APPM__SUB(APPM__LD(pk->v[0][r->kx]), ox), APPM__MUL(sx, Az));
    APPM__V4 Ay = APPM__SUB(APPM__SUB(APPM__LD(pk->v[0][r->ky]), oy), APPM__MUL(sy, Az));
    APPM__V4 Bx = APPM__SUB(APPM__SUB(APPM__LD(pk->v[1][r->kx]), ox), APPM__MUL(sx, Bz));
    APPM__V4 By = APPM__SUB(APPM__SUB(APPM__LD(pk->v[1][r->ky]), oy), APPM__MUL(sy, Bz));
    APPM__V4 Cx = APPM__SUB(APPM__SUB(APPM__LD(pk->v[2][r->kx]), ox), APPM__MUL(sx, Cz));
    APPM__V4 Cy = APPM__SUB(APPM__SUB(APPM__LD(pk->v[2][r->ky]), oy), APPM__MUL(sy, Cz));
    APPM__V4 U = APPM__SUB(APPM__MUL(Cx, By), APPM__MUL(Cy, Bx));
    APPM__V4 V = APPM__SUB(APPM__MUL(Ax, Cy), APPM__MUL(Ay, Cx));
    APPM__V4 W = APPM__SUB(APPM__MUL(Bx, Ay), APPM__MUL(By, Ax));
    APPM__V4 det, t, mzw, mz, mx, my, dx, dy, dz, de, me, dt;
    APPM__M4 ok;
    unsigned zero = APPM__MASK(APPM__OR(APPM__OR(APPM__EQ(U, z), APPM__EQ(V, z)), APPM__EQ(W, z)));
    if (zero) { /* on an edge: decide in double, lane by lane */
        float A[24], u[4], v[4], w[4];
        APPM__ST(A, Ax), APPM__ST(A + 4, Ay), APPM__ST(A + 8, Bx), APPM__ST(A + 12, By);
        APPM__ST(A + 16, Cx), APPM__ST(A + 20, Cy), APPM__ST(u, U), APPM__ST(v, V), APPM__ST(w, W);
        appm__pack_edges_double(zero, A, u, v, w);
        U = APPM__LD(u), V = APPM__LD(v), W = APPM__LD(w);
    }
    ok = APPM__AND(APPM__OR(APPM__OR(APPM__LT(U, z), APPM__LT(V, z)), APPM__LT(W, z)),
                   APPM__OR(APPM__OR(APPM__GT(U, z), APPM__GT(V, z)), APPM__GT(W, z))); /* mixed signs */
    if (APPM__MASK(ok) == 15u) return 0; /* most tests end here: the ray passes beside all four */
    det = APPM__ADD(APPM__ADD(U, V), W);
    t = APPM__DIV(APPM__ADD(APPM__ADD(APPM__MUL(U, APPM__MUL(sz, Az)), APPM__MUL(V, APPM__MUL(sz, Bz))),
                            APPM__MUL(W, APPM__MUL(sz, Cz))),
                  det); /* NaN or +-inf where det is 0 or NaN: no hit below */
    ok = APPM__ANDNOT(ok, APPM__AND(APPM__GT(t, APPM__SET(r->tmin)), APPM__LT(t, APPM__SET(tmax))));
    if (!APPM__MASK(ok)) return 0;
    /* the bound on t's rounding error, as in appm__tri_hit */
    mzw = APPM__MAX(APPM__ABS(Az), APPM__MAX(APPM__ABS(Bz), APPM__ABS(Cz)));
    mz = APPM__MUL(APPM__SET(fabsf(r->sz)), mzw);
    mx = APPM__MAX(APPM__ABS(Ax), APPM__MAX(APPM__ABS(Bx), APPM__ABS(Cx)));
    my = APPM__MAX(APPM__ABS(Ay), APPM__MAX(APPM__ABS(By), APPM__ABS(Cy)));
    dz = APPM__MUL(APPM__SET(APPM__TRI_G3), mz);
    dx = APPM__MUL(APPM__SET(APPM__TRI_G5), APPM__ADD(mx, APPM__MUL(APPM__SET(fabsf(r->sx)), mzw)));
    dy = APPM__MUL(APPM__SET(APPM__TRI_G5), APPM__ADD(my, APPM__MUL(APPM__SET(fabsf(r->sy)), mzw)));
    de = APPM__MUL(APPM__SET(2.0f), APPM__ADD(APPM__ADD(APPM__MUL(APPM__MUL(APPM__SET(APPM__TRI_G2), mx), my),
                                                        APPM__MUL(dy, mx)),
                                              APPM__MUL(dx, my)));
    me = APPM__MAX(APPM__ABS(U), APPM__MAX(APPM__ABS(V), APPM__ABS(W)));
    dt = APPM__DIV(APPM__MUL(APPM__SET(3.0f),
                             APPM__ADD(APPM__ADD(APPM__MUL(APPM__MUL(APPM__SET(APPM__TRI_G3), me), mz),
                                                 APPM__MUL(de, mz)),
                                       APPM__MUL(dz, me))),
                   APPM__ABS(det));
    ok = APPM__AND(ok, APPM__GT(t, dt));
    APPM__ST(tt, t);
    APPM__ST(vw, V); /* b1 = V / det, b2 = W / det: divided only for the lane kept */
    APPM__ST(vw + 4, W);
    APPM__ST(vw + 8, det);
    return APPM__MASK(ok);
}
#endif

/* Closest hit among a leaf's triangles (first, count as in appm__wnode),
 * ignoring `skip`; q->tmax is set to the shrinking *tmax before each test, as in
 * a plain loop over the triangles in order (lanes keep the triangles' order). */
static int appm__leaf_hit(const appm_scene *s, appm__ray *q, uint32_t first, uint32_t count, uint32_t skip,
                          float *tmax, appm__hit *h, int scalar)
{
    int found = 0;
#if defined(APPM__PACKS)
    const appm__tpack *pk = &s->pack[first], *end = pk + (count + 3) / 4;
    if (!scalar) {
        for (; pk < end; ++pk) {
            float t[4], vw[12];
            unsigned m = appm__pack_hit(q, pk, *tmax, t, vw);
            while (m) { /* lanes in triangle order: the first nearest one is kept */
                int j = APPM__CTZ(m);
                uint32_t i = pk->tri[j];
                m &= m - 1;
                if (i == APPM__NO_TRI || i == skip || !(t[j] < *tmax)) continue;
                *tmax = h->t = t[j];
                h->b1 = vw[j] / vw[8 + j]; /* the lane's V / det, as appm__tri_hit divides */
                h->b2 = vw[4 + j] / vw[8 + j];
                h->tri = i;
                found = 1;
            }
        }
        if (found) APPM__PREFETCH_HIT(s, h->tri);
        return found;
    }
    first = s->ptri[first]; /* the scalar path: the leaf's triangles, consecutive */
#endif
    {
        uint32_t i;
        (void)scalar;
        for (i = first; i < first + count; ++i) {
            if (i == skip) continue;
            q->tmax = *tmax;
            if (appm__tri_hit(q, &s->tri[i], h)) {
                *tmax = h->t;
                h->tri = i;
                found = 1;
            }
        }
    }
    if (found) APPM__PREFETCH_HIT(s, h->tri);
    return found;
}

/* Whether a leaf's triangles other than skip0 and skip1 hold a hit in (tmin, tmax). */
static int appm__leaf_any(const appm_scene *s, const appm__ray *r, uint32_t first, uint32_t count, uint32_t skip0,
                          uint32_t skip1, int scalar)
{
    appm__hit h;
    uint32_t i;
#if defined(APPM__PACKS)
    const appm__tpack *pk = &s->pack[first], *end = pk + (count + 3) / 4;
    if (!scalar) {
        for (; pk < end; ++pk) {
            float t[4], vw[12];
            unsigned m = appm__pack_hit(r, pk, r->tmax, t, vw);
            while (m) {
                i = pk->tri[APPM__CTZ(m)];
                m &= m - 1;
                if (i != APPM__NO_TRI && i != skip0 && i != skip1) return 1;
            }
        }
        return 0;
    }
    first = s->ptri[first];
#endif
    (void)scalar;
    for (i = first; i < first + count; ++i)
        if (i != skip0 && i != skip1 && appm__tri_hit(r, &s->tri[i], &h)) return 1;
    return 0;
}

/* Closest hit in (tmin, tmax) through the wide tree, ignoring triangle `skip`.
 * Triangles are tested by the same appm__tri_hit with the same shrinking tmax
 * as in a plain loop, so the answer is the loop's up to the order of exact ties. */
static int appm__intersect_wide(const appm_scene *s, const appm__ray *r, uint32_t skip, appm__hit *h, int scalar)
{
    appm__wentry stack[APPM__WSTACK], cur;
    appm__bray b;
    float tn[APPM__BVH_W], tmax = r->tmax;
    appm__ray q = *r;
    int sp = 0, found = 0;
    appm__bray_init(&b, r, appm__box_slack(r, &s->root));
    cur.first = 0;
    cur.count = APPM__W_INNER;
    for (;;) {
        if (cur.count == APPM__W_INNER) {
            const appm__wnode *n = &s->wnode[cur.first];
            unsigned m = APPM__BOXES(&b, n, tmax, tn, scalar);
            unsigned m2 = m & (m - 1); /* m without its lowest child */
            if (m2 & (m2 - 1)) { /* three or more: the far ones are fetched while the nearest is searched */
                int c = appm__push_children(n, m, tn, stack + sp), k;
                for (k = 0; k < c - 1; ++k) APPM__PREFETCH_ENTRY(s, &stack[sp + k]);
                sp += c - 1;
                cur = stack[sp];
                continue;
            }
            if (m2) { /* two: one comparison (a tie goes to the lower slot, as in the sort) */
                int j0 = APPM__CTZ(m), j1 = APPM__CTZ(m2), nj = tn[j1] < tn[j0] ? j1 : j0, fj = j0 + j1 - nj;
                stack[sp].first = n->first[fj];
                stack[sp].count = n->count[fj];
                stack[sp].tnear = tn[fj];
                APPM__PREFETCH_ENTRY(s, &stack[sp]);
                sp++;
                cur.first = n->first[nj];
                cur.count = n->count[nj];
                continue;
            }
            if (m) { /* one: no stack */
                int j = APPM__CTZ(m);
                cur.first = n->first[j];
                cur.count = n->count[j];
                continue;
            }
        } else if (appm__leaf_hit(s, &q, cur.first, cur.count, skip, &tmax, h, scalar)) {
            found = 1;
        }
        do { /* pop, dropping boxes entered beyond the closest hit: the test
              * t0 <= min(t1, tmax) + slack at push time, redone with the new tmax */
            if (sp == 0) return found;
            cur = stack[--sp];
        } while (!(cur.tnear <= tmax + b.slack));
    }
}

/* Any hit in (tmin, tmax), ignoring triangles skip0 and skip1: shadow rays. */
static int appm__occluded_wide(const appm_scene *s, const appm__ray *r, uint32_t skip0, uint32_t skip1,
                               int scalar)
{
    appm__wentry stack[APPM__WSTACK], cur;
    appm__bray b;
    float tn[APPM__BVH_W];
    int sp = 0;
    appm__bray_init(&b, r, appm__box_slack(r, &s->root));
    cur.first = 0;
    cur.count = APPM__W_INNER;
    for (;;) {
        if (cur.count == APPM__W_INNER) {
            const appm__wnode *n = &s->wnode[cur.first];
            unsigned m = APPM__BOXES(&b, n, r->tmax, tn, scalar);
            unsigned leaves = 0, k;
            while (m) { /* interior children pushed, slot order: any hit ends the search, so no sort */
                int j = APPM__CTZ(m);
                m &= m - 1;
                if (n->count[j] != APPM__W_INNER) {
                    leaves |= 1u << j;
                    continue;
                }
                stack[sp].first = n->first[j];
                stack[sp].count = n->count[j];
                stack[sp].tnear = tn[j];
                APPM__PREFETCH_ENTRY(s, &stack[sp]);
                sp++;
            }
            for (k = leaves; k; k &= k - 1) { /* leaves first: a hit there ends it all */
                int j = APPM__CTZ(k);
                if (appm__leaf_any(s, r, n->first[j], n->count[j], skip0, skip1, scalar)) return 1;
            }
        } else if (appm__leaf_any(s, r, cur.first, cur.count, skip0, skip1, scalar)) {
            return 1;
        }
        if (sp == 0) return 0;
        cur = stack[--sp];
    }
}

static int appm__intersect_tree(const appm_scene *s, const appm__ray *r, uint32_t skip, appm__hit *h)
{
#if APPM_BVH_BINARY
    if (s->bvh_path == APPM__BVH_BINARY) return appm__intersect_bin(s, r, skip, h);
#endif
    return appm__intersect_wide(s, r, skip, h, s->bvh_path == APPM__BVH_SCALAR);
}

/* Whether hit h fell in a hole of a cut-out (map_d) surface: its coverage
 * below 1/2 (section 4.5).  A triangle without texture coordinates is solid. */
static int appm__cut_away(const appm_scene *s, const appm__hit *h)
{
    const appm__tri_info *in = &s->info[h->tri];
    const appm__material *m = &s->mat[in->mat];
    const float *uv;
    float b0;
    if (!m->map_d || in->uv0 < 0) return 0;
    uv = s->uv + 2 * (size_t)in->uv0;
    b0 = 1.0f - h->b1 - h->b2;
    return appm__tex_coverage(&s->tex[m->map_d - 1], b0 * uv[0] + h->b1 * uv[2] + h->b2 * uv[4],
                              b0 * uv[1] + h->b1 * uv[3] + h->b2 * uv[5]) < 0.5f;
}

/* Cut-outs: the closest hit is searched again beyond each hit that fell in a
 * hole (tmin moved to it, strictly past it: (tmin, tmax) is open, so the
 * search moves on every time and ends).  Scenes without map_d never get
 * here, so their rays cost what they cost before. */
static int appm__intersect_holes(const appm_scene *s, const appm__ray *r, uint32_t skip, uint32_t skip1,
                                 appm__hit *h)
{
    appm__ray q = *r;
    for (;;) {
        if (!appm__intersect_tree(s, &q, skip, h)) return 0;
        if (h->tri != skip1 && !appm__cut_away(s, h)) return 1;
        q.tmin = h->t;
        skip = h->tri;
    }
}

/* Closest hit in (tmin, tmax), ignoring triangle `skip` (the one a secondary ray
 * leaves: a flat triangle cannot be hit again by a ray leaving it). */
static int appm__intersect(const appm_scene *s, const appm__ray *r, uint32_t skip, appm__hit *h)
{
    if (!r->valid || s->nwnode == 0) return 0;
    if (s->cutouts) return appm__intersect_holes(s, r, skip, skip, h);
    return appm__intersect_tree(s, r, skip, h);
}

/* Any hit in (tmin, tmax), ignoring triangles skip0 and skip1: shadow rays. */
static int appm__occluded(const appm_scene *s, const appm__ray *r, uint32_t skip0, uint32_t skip1)
{
    if (!r->valid || s->nwnode == 0) return 0;
    if (s->cutouts) {
        appm__hit h;
        return appm__intersect_holes(s, r, skip0, skip1, &h);
    }
#if APPM_BVH_BINARY
    if (s->bvh_path == APPM__BVH_BINARY) return appm__occluded_bin(s, r, skip0, skip1);
#endif
    return appm__occluded_wide(s, r, skip0, skip1, s->bvh_path == APPM__BVH_SCALAR);
}
/* ---- 5.3 Build ------------------------------------------------------------- */

typedef struct appm__bbox {
    appm__v3 lo, hi;
} appm__bbox;

static void appm__bbox_empty(appm__bbox *b)
{
    b->lo = appm__v(FLT_MAX, FLT_MAX, FLT_MAX);
    b->hi = appm__v(-FLT_MAX, -FLT_MAX, -FLT_MAX);
}

static void appm__bbox_grow(appm__bbox *b, appm__v3 p)
{
    b->lo = appm__vmin(b->lo, p);
    b->hi = appm__vmax(b->hi, p);
}

static void appm__bbox_join(appm__bbox *b, const appm__bbox *o)
{
    b->lo = appm__vmin(b->lo, o->lo);
    b->hi = appm__vmax(b->hi, o->hi);
}

static float appm__bbox_area(const appm__bbox *b)
{
    appm__v3 d = appm__sub(b->hi, b->lo);
    if (d.x < 0 || d.y < 0 || d.z < 0) return 0.0f;
    return 2.0f * (d.x * d.y + d.y * d.z + d.z * d.x);
}

typedef struct appm__build_item {
    uint32_t node, start, count, depth;
} appm__build_item;

/* Chooses a split of idx[start, start+count) and partitions it; returns the
 * size of the left part, or 0 to make a leaf. */
static uint32_t appm__bvh_split(const appm__bbox *tb, const appm__v3 *cen, uint32_t *idx,
                                uint32_t start, uint32_t count, uint32_t depth, float node_area)
{
    appm__bbox cb;
    uint32_t i, best_axis = 3, best_bin = 0, left = 0;
    float best_cost = (float)count; /* cost of a leaf: one test per triangle */
    int axis;
    appm__bbox_empty(&cb);
    for (i = start; i < start + count; ++i) appm__bbox_grow(&cb, cen[idx[i]]);
    if (count <= 2) return 0;
    if (depth < APPM__BVH_FORCE_MEDIAN) {
        for (axis = 0; axis < 3; ++axis) {
            float lo = appm__comp(cb.lo, axis), ext = appm__comp(cb.hi, axis) - lo, scale;
            appm__bbox bin[APPM__BVH_BINS], acc;
            uint32_t cnt[APPM__BVH_BINS], b, nleft;
            float area_left[APPM__BVH_BINS];
            uint32_t count_left[APPM__BVH_BINS];
            if (!(ext > 0.0f)) continue;
            scale = (float)APPM__BVH_BINS / ext;
            for (b = 0; b < APPM__BVH_BINS; ++b) {
                appm__bbox_empty(&bin[b]);
                cnt[b] = 0;
            }
            for (i = start; i < start + count; ++i) {
                float f = (appm__comp(cen[idx[i]], axis) - lo) * scale;
                b = f >= (float)(APPM__BVH_BINS - 1) ? APPM__BVH_BINS - 1 : (f > 0.0f ? (uint32_t)f : 0);
                cnt[b]++;
                appm__bbox_join(&bin[b], &tb[idx[i]]);
            }
            appm__bbox_empty(&acc);
            nleft = 0;
            for (b = 0; b + 1 < APPM__BVH_BINS; ++b) { /* sweep from the left */
                appm__bbox_join(&acc, &bin[b]);
                nleft += cnt[b];
                area_left[b] = appm__bbox_area(&acc);
                count_left[b] = nleft;
            }
            appm__bbox_empty(&acc);
            for (b = APPM__BVH_BINS - 1; b > 0; --b) { /* and from the right */
                float cost;
                appm__bbox_join(&acc, &bin[b]);
                if (count_left[b - 1] == 0 || count_left[b - 1] == count) continue;
                cost = 1.0f + (area_left[b - 1] * (float)count_left[b - 1] +
                               appm__bbox_area(&acc) * (float)(count - count_left[b - 1])) /
                                  node_area;
                if (cost < best_cost) {
                    best_cost = cost;
                    best_axis = (uint32_t)axis;
                    best_bin = b;
                }
            }
        }
    }
    if (best_axis < 3) {
        float lo = appm__comp(cb.lo, (int)best_axis);
        float scale = (float)APPM__BVH_BINS / (appm__comp(cb.hi, (int)best_axis) - lo);
        uint32_t j = start + count;
        i = start;
        while (i < j) { /* partition: bins < best_bin to the left */
            float f = (appm__comp(cen[idx[i]], (int)best_axis) - lo) * scale;
            uint32_t b = f >= (float)(APPM__BVH_BINS - 1) ? APPM__BVH_BINS - 1 : (f > 0.0f ? (uint32_t)f : 0);
            if (b < best_bin) i++;
            else {
                uint32_t t = idx[i];
                idx[i] = idx[--j];
                idx[j] = t;
            }
        }
        left = i - start;
        if (left > 0 && left < count) return left;
    }
    /* No useful SAH split.  Small nodes become leaves; big ones (duplicates,
     * or a tree too deep) are halved by index so the depth stays bounded. */
    if (count <= 8 && (depth < APPM__BVH_FORCE_MEDIAN || count <= 4)) return 0;
    return count / 2;
}

/* Per triangle of s: idx[i] = i, its bounding box tb[i] and the box's centre
 * cen[i], the arrays holding s->ntri entries. */
static void appm__bvh_boxes(const appm_scene *s, uint32_t *idx, appm__bbox *tb, appm__v3 *cen)
{
    uint32_t i;
    for (i = 0; i < s->ntri; ++i) {
        idx[i] = i;
        appm__bbox_empty(&tb[i]);
        appm__bbox_grow(&tb[i], s->tri[i].p0);
        appm__bbox_grow(&tb[i], s->tri[i].p1);
        appm__bbox_grow(&tb[i], s->tri[i].p2);
        cen[i] = appm__scale(appm__add(tb[i].lo, tb[i].hi), 0.5f);
    }
}

/* The binary nodes, top down from the root over all s->ntri triangles, into
 * s->node (room for 2 ntri) and s->depth, reordering idx[] so that every leaf's
 * triangles are consecutive.  `stack` holds APPM__BVH_MAX_DEPTH * 2 + 8 items.
 * Returns the number of nodes. */
static uint32_t appm__bvh_nodes(appm_scene *s, const appm__bbox *tb, const appm__v3 *cen, uint32_t *idx,
                                appm__build_item *stack)
{
    uint32_t i, nnode = 1, sp = 0;
    stack[sp].node = 0;
    stack[sp].start = 0;
    stack[sp].count = s->ntri;
    stack[sp].depth = 1;
    sp++;
    while (sp > 0) {
        appm__build_item it = stack[--sp];
        appm__node *nd = &s->node[it.node];
        appm__bbox b;
        uint32_t left;
        appm__bbox_empty(&b);
        for (i = it.start; i < it.start + it.count; ++i) appm__bbox_join(&b, &tb[idx[i]]);
        nd->bmin[0] = b.lo.x;
        nd->bmin[1] = b.lo.y;
        nd->bmin[2] = b.lo.z;
        nd->bmax[0] = b.hi.x;
        nd->bmax[1] = b.hi.y;
        nd->bmax[2] = b.hi.z;
        if (it.depth > s->depth) s->depth = it.depth;
        left = it.depth >= APPM__BVH_MAX_DEPTH - 1
                   ? 0
                   : appm__bvh_split(tb, cen, idx, it.start, it.count, it.depth, appm__bbox_area(&b));
        if (left == 0) {
            nd->first = it.start;
            nd->count = it.count;
            continue;
        }
        nd->first = nnode;
        nd->count = 0;
        stack[sp].node = nnode;
        stack[sp].start = it.start;
        stack[sp].count = left;
        stack[sp].depth = it.depth + 1;
        sp++;
        stack[sp].node = nnode + 1;
        stack[sp].start = it.start + left;
        stack[sp].count = it.count - left;
        stack[sp].depth = it.depth + 1;
        sp++;
        nnode += 2;
    }
    return nnode;
}

/* Puts s's triangles in leaf order, tri2[i] and info2[i] (fresh arrays of
 * s->ntri entries) taking triangle idx[i]; s's old arrays are freed. */
static void appm__bvh_leaf_order(appm_scene *s, const uint32_t *idx, appm__tri *tri2, appm__tri_info *info2)
{
    uint32_t i;
    for (i = 0; i < s->ntri; ++i) {
        tri2[i] = s->tri[idx[i]];
        info2[i] = s->info[idx[i]];
    }
    appm__free(&s->mem, s->tri);
    appm__free(&s->mem, s->info);
    s->tri = tri2;
    s->info = info2;
}

/* The binary tree (s->node), triangles put in leaf order. */
static appm_status appm__bvh_build_binary(appm_scene *s, appm_diag *diag)
{
    appm__mem *m = &s->mem;
    uint32_t n = s->ntri;
    uint32_t *idx = NULL;
    appm__bbox *tb = NULL;
    appm__v3 *cen = NULL;
    appm__build_item *stack = NULL;
    appm__tri *tri2 = NULL;
    appm__tri_info *info2 = NULL;
    s->node = NULL;
    s->nnode = 0;
    s->depth = 0;
    if (n == 0) return APPM_OK;
    (void)diag;
    idx = (uint32_t *)appm__alloc(m, n, sizeof *idx);
    tb = (appm__bbox *)appm__alloc(m, n, sizeof *tb);
    cen = (appm__v3 *)appm__alloc(m, n, sizeof *cen);
    stack = (appm__build_item *)appm__alloc(m, APPM__BVH_MAX_DEPTH * 2 + 8, sizeof *stack);
    s->node = (appm__node *)appm__alloc(m, 2 * (size_t)n, sizeof *s->node);
    if (!idx || !tb || !cen || !stack || !s->node) goto nomem;
    appm__bvh_boxes(s, idx, tb, cen);
    s->nnode = appm__bvh_nodes(s, tb, cen, idx, stack);
    /* Put the triangles in leaf order, so a leaf reads consecutive memory. */
    tri2 = (appm__tri *)appm__alloc(m, n, sizeof *tri2);
    info2 = (appm__tri_info *)appm__alloc(m, n, sizeof *info2);
    if (!tri2 || !info2) goto nomem;
    appm__bvh_leaf_order(s, idx, tri2, info2);
    appm__free(m, idx);
    appm__free(m, tb);
    appm__free(m, cen);
    appm__free(m, stack);
    return APPM_OK;
nomem:
    appm__free(m, idx);
    appm__free(m, tb);
    appm__free(m, cen);
    appm__free(m, stack);
    appm__free(m, tri2);
    appm__free(m, info2);
    appm__free(m, s->node);
    s->node = NULL;
    return APPM_ERR_NOMEM;
}

/* Collapse of the binary tree into the wide one.  A wide node starts as the
 * two children of a binary interior node; the interior child of largest surface
 * area (the one a random ray most likely enters) is replaced by its own two
 * children until there are W children or only leaves.  A binary subtree of at
 * most APPM__LEAF_MAX triangles counts as a leaf: its triangles are consecutive
 * (the build puts them in leaf order) and one pack tests them together, for
 * about the cost of one triangle, where its binary nodes would cost box tests
 * and visits; in a large tree a bigger one may too (flat leaves, below).
 * Every wide node so consumes at least one binary interior node, so there are
 * at most (nnode - 1) / 2 + 1 of them, and the tree is no deeper than the
 * binary one.  Nodes are laid out depth first, the children of a node
 * consecutively; a leaf's packs are consecutive, in the order leaves are made. */
typedef struct appm__collapse_item {
    uint32_t bin, wide, depth;
} appm__collapse_item;

typedef struct appm__collapse { /* scratch of the collapse */
    uint32_t *cnt, *fst;        /* per binary node: its subtree's triangles, the first of them */
    float *cost;                /* per binary node: its subtree's cost over its area */
    unsigned char *leaf;        /* per binary node: it becomes one leaf */
    uint32_t npack;             /* packs written so far */
} appm__collapse;

/* Flat leaves: in a tree of at least APPM__FLAT_TRIS triangles (the bunny's
 * wide tree and packs take 5.0 MB with leaves of four, past any core's own
 * cache; 3.75 MB with flat leaves, whose packs are fuller), a subtree of up
 * to APPM__LEAF_FLAT triangles also becomes one leaf when the surface-area
 * cost of testing all its packs is no more than that of its binary subtree
 * with an interior node at APPM__FLAT_NODE packs.  The traversal of such a
 * tree waits on memory: a node's children are known only when the node has
 * arrived, while the packs of a leaf are consecutive and stream in.  A level
 * less pays for the more triangles tested per leaf there (bunny, 1e6 random
 * rays, closest hits against the binary tree: SSE2 1.96-2.05x -> 2.33-2.53x,
 * AVX2 2.04-2.15x -> 2.62-2.69x), not in a tree that fits (the 2188-triangle
 * sphere box: 5 % slower, its scalar path 27 %).  Every build makes the same
 * tree, so that SIMD and scalar builds break exact ties alike and render the
 * same bytes. */
#ifndef APPM__LEAF_FLAT
#define APPM__LEAF_FLAT 16
#endif
#define APPM__FLAT_TRIS 32768
#define APPM__FLAT_NODE 2.0f

/* The leaf of triangles [first, first + count): its packs, written at the end
 * (the last one padded with copies of its first lane, marked APPM__NO_TRI);
 * returns what appm__wnode.first holds for it (its first pack, or in a scalar
 * build its first triangle). */
static uint32_t appm__emit_leaf(appm_scene *s, appm__collapse *c, uint32_t first, uint32_t count)
{
#if defined(APPM__PACKS)
    uint32_t p0 = c->npack, k, l, a;
    for (k = 0; k < count; k += 4) {
        appm__tpack *pk = &s->pack[c->npack++];
        for (l = 0; l < 4; ++l) {
            uint32_t i = first + (k + l < count ? k + l : k);
            const appm__tri *t = &s->tri[i];
            for (a = 0; a < 3; ++a) {
                pk->v[0][a][l] = appm__comp(t->p0, (int)a);
                pk->v[1][a][l] = appm__comp(t->p1, (int)a);
                pk->v[2][a][l] = appm__comp(t->p2, (int)a);
            }
            pk->tri[l] = k + l < count ? i : APPM__NO_TRI;
        }
        s->ptri[c->npack - 1] = pk->tri[0];
    }
    return p0;
#else
    (void)s;
    (void)c;
    (void)count;
    return first;
#endif
}

/* Fills wide node w from binary interior node b; pushes its interior children. */
static void appm__collapse_node(appm_scene *s, appm__collapse *cs, appm__collapse_item it,
                                appm__collapse_item *stack, uint32_t *sp)
{
    const appm__node *bn = s->node;
    appm__wnode *wn = &s->wnode[it.wide];
    uint32_t kid[APPM__BVH_W], nk = 2, i, j;
    const float inf = (float)HUGE_VAL;
    kid[0] = bn[it.bin].first;
    kid[1] = bn[it.bin].first + 1;
    while (nk < APPM__BVH_W) {
        uint32_t best = nk;
        double area = -1.0;
        for (i = 0; i < nk; ++i) {
            const appm__node *c = &bn[kid[i]];
            double dx = c->bmax[0] - c->bmin[0], dy = c->bmax[1] - c->bmin[1], dz = c->bmax[2] - c->bmin[2];
            double a = dx * dy + dy * dz + dz * dx;
            if (!cs->leaf[kid[i]] && a > area) {
                area = a;
                best = i;
            }
        }
        if (best == nk) break; /* only leaves left */
        kid[nk++] = bn[kid[best]].first + 1;
        kid[best] = bn[kid[best]].first;
    }
    for (i = 0; i < APPM__BVH_W; ++i) {
        const appm__node *c = i < nk ? &bn[kid[i]] : NULL;
        for (j = 0; j < 3; ++j) {
            wn->lo[j][i] = c ? c->bmin[j] : inf;
            wn->hi[j][i] = c ? c->bmax[j] : -inf;
        }
        if (!c) {
            wn->first[i] = wn->count[i] = 0;
        } else if (cs->leaf[kid[i]]) {
            wn->first[i] = appm__emit_leaf(s, cs, cs->fst[kid[i]], cs->cnt[kid[i]]);
            wn->count[i] = cs->cnt[kid[i]];
        } else {
            wn->count[i] = APPM__W_INNER;
            stack[*sp].bin = kid[i];
            stack[*sp].depth = it.depth + 1;
            stack[(*sp)++].wide = i; /* slot for now: numbered below */
        }
    }
}

/* The subtree sizes, first triangles and which subtrees become leaves
 * (children follow their parent in the array, so one backward sweep), and the
 * number of packs the leaves need.  cost[i] is the flat-leaf rule's cost of
 * subtree i in pack tests times area: the sum over its nodes n of area(n)
 * times APPM__FLAT_NODE for an interior one, times its packs for a leaf. */
static uint32_t appm__collapse_count(const appm_scene *s, appm__collapse *c)
{
    uint32_t i = s->nnode, np = 0, cap = s->ntri >= APPM__FLAT_TRIS ? APPM__LEAF_FLAT : APPM__LEAF_MAX;
    while (i-- > 0) {
        const appm__node *n = &s->node[i];
        double dx = n->bmax[0] - n->bmin[0], dy = n->bmax[1] - n->bmin[1], dz = n->bmax[2] - n->bmin[2];
        float a = (float)(dx * dy + dy * dz + dz * dx), flat, inner;
        c->cnt[i] = n->count ? n->count : c->cnt[n->first] + c->cnt[n->first + 1];
        c->fst[i] = n->count ? n->first : c->fst[n->first];
        flat = a * (float)((c->cnt[i] + 3) / 4);
        if (n->count) {
            c->leaf[i] = 1;
            c->cost[i] = flat;
            continue;
        }
        inner = APPM__FLAT_NODE * a + c->cost[n->first] + c->cost[n->first + 1];
        c->leaf[i] = c->cnt[i] <= APPM__LEAF_MAX || (c->cnt[i] <= cap && flat <= inner);
        c->cost[i] = c->leaf[i] ? flat : inner;
    }
    for (i = 0; i < s->nnode; ++i) {
        const appm__node *n = &s->node[i];
        uint32_t k;
        if (c->leaf[i]) continue; /* opened: its leaf-like children become leaves */
        for (k = 0; k < 2; ++k)
            if (c->leaf[n->first + k]) np += (c->cnt[n->first + k] + 3) / 4;
    }
    if (c->leaf[0]) np = (c->cnt[0] + 3) / 4;
#if !defined(APPM__PACKS)
    np = 0;
#endif
    return np;
}

/* The root as a single leaf: one wide node with one child. */
static void appm__collapse_single(appm_scene *s, appm__collapse *c)
{
    const float inf = (float)HUGE_VAL;
    appm__wnode *wn = &s->wnode[0];
    uint32_t i, j;
    for (i = 0; i < APPM__BVH_W; ++i) {
        for (j = 0; j < 3; ++j) {
            wn->lo[j][i] = i ? inf : s->node[0].bmin[j];
            wn->hi[j][i] = i ? -inf : s->node[0].bmax[j];
        }
        wn->first[i] = wn->count[i] = 0;
    }
    wn->first[0] = appm__emit_leaf(s, c, c->fst[0], c->cnt[0]);
    wn->count[0] = c->cnt[0];
}

static void appm__collapse_tree(appm_scene *s, appm__collapse *c, appm__collapse_item *stack)
{
    uint32_t sp = 0, nw = 1;
    s->wdepth = 1;
    stack[sp].bin = 0;
    stack[sp].depth = 1;
    stack[sp++].wide = 0;
    while (sp > 0) {
        appm__collapse_item it = stack[--sp];
        uint32_t base = sp, k;
        if (it.depth > s->wdepth) s->wdepth = it.depth;
        appm__collapse_node(s, c, it, stack, &sp);
        for (k = base; k < sp; ++k) { /* number the new children, in slot order */
            s->wnode[it.wide].first[stack[k].wide] = nw;
            stack[k].wide = nw++;
        }
        for (k = 0; 2 * k + 1 < sp - base; ++k) { /* reversed: slot 0 is popped first */
            appm__collapse_item t = stack[base + k];
            stack[base + k] = stack[sp - 1 - k];
            stack[sp - 1 - k] = t;
        }
    }
    s->nwnode = nw;
}

static appm_status appm__bvh_collapse(appm_scene *s)
{
    appm__mem *m = &s->mem;
    uint32_t cap = (s->nnode - 1) / 2 + 1;
    appm__collapse c;
    appm__collapse_item *stack;
    uintptr_t addr;
    appm_status st = APPM_ERR_NOMEM;
    c.npack = 0;
    c.cnt = (uint32_t *)appm__alloc(m, s->nnode, sizeof *c.cnt);
    c.fst = (uint32_t *)appm__alloc(m, s->nnode, sizeof *c.fst);
    c.cost = (float *)appm__alloc(m, s->nnode, sizeof *c.cost);
    c.leaf = (unsigned char *)appm__alloc(m, s->nnode, 1);
    stack = (appm__collapse_item *)appm__alloc(m, (APPM__BVH_W - 1) * (size_t)APPM__BVH_MAX_DEPTH + APPM__BVH_W,
                                               sizeof *stack);
    s->wnode_mem = NULL;
    if (c.cnt && c.fst && c.cost && c.leaf && stack) {
        /* in 64 bits: the sum can exceed a 32-bit size_t (wasm32) */
        uint64_t bytes;
        s->npack = appm__collapse_count(s, &c);
        bytes = ((uint64_t)cap + 1) * sizeof *s->wnode +
                (uint64_t)s->npack * (sizeof *s->pack + sizeof *s->ptri);
        if (bytes == (uint64_t)(size_t)bytes) s->wnode_mem = appm__alloc(m, (size_t)bytes, 1);
    }
    if (s->wnode_mem) {
        addr = (uintptr_t)s->wnode_mem;
        s->wnode = (appm__wnode *)((char *)s->wnode_mem + (64 - addr % 64) % 64);
        s->pack = (appm__tpack *)(s->wnode + cap); /* 64-byte aligned too */
        s->ptri = (uint32_t *)(s->pack + s->npack);
        if (c.leaf[0]) {
            appm__collapse_single(s, &c);
            s->nwnode = s->wdepth = 1;
        } else {
            appm__collapse_tree(s, &c, stack);
        }
        st = APPM_OK;
    }
    appm__free(m, stack);
    appm__free(m, c.cnt);
    appm__free(m, c.fst);
    appm__free(m, c.cost);
    appm__free(m, c.leaf);
    return st;
}

/* The binary SAH build, then its collapse into the wide tree the renderer
 * traverses; the binary tree is kept only for comparisons (APPM_BVH_BINARY). */
static appm_status appm__bvh_build(appm_scene *s, appm_diag *diag)
{
    appm_status st = appm__bvh_build_binary(s, diag);
    s->wnode = NULL;
    s->wnode_mem = NULL;
    s->nwnode = s->wdepth = s->npack = 0;
    s->pack = NULL;
    s->ptri = NULL;
    if (st != APPM_OK || s->nnode == 0) return st;
    s->root = s->node[0];
    st = appm__bvh_collapse(s);
#if !APPM_BVH_BINARY
    appm__free(&s->mem, s->node);
    s->node = NULL;
#endif
    return st;
}

/* ---- 5.4 Surface points and ray offsets ------------------------------------ */

/* gamma_7 of Higham's bound: a sum of three products of floats is within
 * gamma_7 times the sum of their magnitudes (pbrt's error bounds). */
#define APPM__GAMMA7 (7.0f * (FLT_EPSILON * 0.5f) / (1.0f - 7.0f * (FLT_EPSILON * 0.5f)))

typedef struct appm__surf {
    appm__v3 p;    /* hit point, interpolated from the vertices */
    appm__v3 err;  /* bound on its rounding error, per axis */
    appm__v3 ng;   /* unit geometric normal (counter-clockwise side) */
    appm__v3 ns;   /* unit shading normal, on the side of ng */
    uint32_t tri, mat;
    float t;
    float u, v;    /* texture coordinates (0 without) */
} appm__surf;

static void appm__surface(const appm_scene *s, const appm__hit *h, appm__surf *out)
{
    const appm__tri *t = &s->tri[h->tri];
    const appm__tri_info *in = &s->info[h->tri];
    const float b0 = 1.0f - h->b1 - h->b2, b1 = h->b1, b2 = h->b2;
    const float g7 = APPM__GAMMA7;
    appm__v3 a0 = appm__scale(t->p0, b0), a1 = appm__scale(t->p1, b1), a2 = appm__scale(t->p2, b2);
    out->p = appm__add(appm__add(a0, a1), a2);
    out->err = appm__scale(appm__v(fabsf(a0.x) + fabsf(a1.x) + fabsf(a2.x),
                                   fabsf(a0.y) + fabsf(a1.y) + fabsf(a2.y),
                                   fabsf(a0.z) + fabsf(a1.z) + fabsf(a2.z)),
                           g7);
    out->ng = in->ng;
    out->ns = in->ng;
    if (in->n0 >= 0) {
        const appm__v3 *n = s->normals + in->n0;
        appm__v3 ns = appm__normalize(
            appm__add(appm__add(appm__scale(n[0], b0), appm__scale(n[1], b1)), appm__scale(n[2], b2)));
        if (appm__finite3(ns) && appm__dot(ns, ns) > 0.5f)
            out->ns = appm__dot(ns, in->ng) < 0.0f ? appm__neg(ns) : ns;
    }
    out->tri = h->tri;
    out->mat = in->mat;
    out->t = h->t;
    out->u = out->v = 0.0f;
    if (in->uv0 >= 0) {
        const float *uv = s->uv + 2 * (size_t)in->uv0;
        out->u = b0 * uv[0] + b1 * uv[2] + b2 * uv[4];
        out->v = b0 * uv[1] + b1 * uv[3] + b2 * uv[5];
    }
}

static appm__v3 appm__clamp01(appm__v3 v)
{
    return appm__v(v.x > 0.0f ? (v.x < 1.0f ? v.x : 1.0f) : 0.0f, v.y > 0.0f ? (v.y < 1.0f ? v.y : 1.0f) : 0.0f,
                   v.z > 0.0f ? (v.z < 1.0f ? v.z : 1.0f) : 0.0f);
}

/* The material at surface point sf: the scene's, or with texture maps its
 * copy in *tmp with Kd (map_Kd) and Ks (map_Ks; a mirror's reflectance) times
 * the texel, clamped to [0, 1] (a float map may hold more). */
static const appm__material *appm__material_at(const appm_scene *s, const appm__surf *sf, appm__material *tmp)
{
    const appm__material *m = &s->mat[sf->mat];
    if ((!m->map_kd && !m->map_ks) || s->info[sf->tri].uv0 < 0) return m; /* no maps, or no vt to read them at */
    *tmp = *m;
    if (m->map_kd && m->kind != APPM__MAT_MIRROR && m->kind != APPM__MAT_DIELECTRIC)
        tmp->color = appm__mul(tmp->color, appm__clamp01(appm__tex_rgb(&s->tex[m->map_kd - 1], sf->u, sf->v)));
    if (m->map_ks) {
        appm__v3 k = appm__clamp01(appm__tex_rgb(&s->tex[m->map_ks - 1], sf->u, sf->v));
        if (m->kind == APPM__MAT_MIRROR) tmp->color = appm__mul(tmp->color, k);
        else if (m->kind == APPM__MAT_GLOSSY) tmp->ks = appm__mul(tmp->ks, k);
    }
    return tmp;
}

/* The origin for a ray leaving `sf` towards w: outside the error box of the hit
 * point on w's side, then one more float step away (pbrt's OffsetRayOrigin). */
static appm__v3 appm__offset(const appm__surf *sf, appm__v3 w)
{
    appm__v3 n = sf->ng, o;
    float d = fabsf(n.x) * sf->err.x + fabsf(n.y) * sf->err.y + fabsf(n.z) * sf->err.z;
    appm__v3 off = appm__scale(n, d);
    if (appm__dot(w, n) < 0.0f) off = appm__neg(off);
    o = appm__add(sf->p, off);
    if (off.x > 0) o.x = nextafterf(o.x, FLT_MAX);
    else if (off.x < 0) o.x = nextafterf(o.x, -FLT_MAX);
    if (off.y > 0) o.y = nextafterf(o.y, FLT_MAX);
    else if (off.y < 0) o.y = nextafterf(o.y, -FLT_MAX);
    if (off.z > 0) o.z = nextafterf(o.z, FLT_MAX);
    else if (off.z < 0) o.z = nextafterf(o.z, -FLT_MAX);
    return o;
}

static void appm__ray_init(appm__ray *r, appm__v3 o, appm__v3 d, float tmax)
{
    r->o = o;
    r->d = d;
    r->tmin = 0.0f;
    r->tmax = tmax;
    appm__ray_setup(r);
}

/* ---- 5.5 Open edges ------------------------------------------------------------
 *
 * An edge that no other triangle shares is where a surface ends against
 * nothing: the front of an open box's floor, a table's rim, a leaf's margin.  A
 * density estimate near it loses the kernel's mass beyond the edge, a bias of
 * -(1 - m) L as at a corner (10.4, step 6, whose lines come from the pixels);
 * but no pixel shows a surface beyond it, while the mesh knows the line
 * exactly.  Two edges are the same if their corners are, in either order (by
 * position: an OBJ's separate objects rarely share vertex indices).  An edge
 * seen once counts as open only if probes just beyond it (appm__edge_continues)
 * find no surface near its triangle's plane: tiles that meet without sharing
 * corners (a T-junction, unwelded copies) and a rug on a floor go on, and their
 * photons are gathered.  Each triangle lists the open edges of itself and of every
 * triangle that shares a corner with it (at most APPM__OPEN_NEAR): the lines
 * within reach of a kernel on a surface whose triangles are no smaller than it
 * (a quad's two halves see all four of its edges).  Finer meshes keep the bias
 * of the edges beyond their one-ring (docs/algorithm.md 5.6). */
#define APPM__OPEN_NEAR 8

static appm__v3 appm__corner(const appm__tri *t, uint32_t k) { return k == 0 ? t->p0 : (k == 1 ? t->p1 : t->p2); }

static int appm__same_pos(appm__v3 a, appm__v3 b) { return a.x == b.x && a.y == b.y && a.z == b.z; }

static uint64_t appm__pos_key(appm__v3 p)
{
    float f[3];
    uint32_t u[3];
    f[0] = p.x + 0.0f; /* -0 + 0 = +0: one key for positions that compare equal */
    f[1] = p.y + 0.0f;
    f[2] = p.z + 0.0f;
    memcpy(u, f, sizeof u);
    return appm__mix64(((uint64_t)u[0] << 32 | u[1]) ^ appm__mix64(u[2]));
}

/* Edge e = 3 t + k runs from corner k of triangle t to corner k + 1 (mod 3). */
static void appm__edge_ends(const appm_scene *s, uint32_t e, appm__v3 *a, appm__v3 *b)
{
    *a = appm__corner(&s->tri[e / 3], e % 3);
    *b = appm__corner(&s->tri[e / 3], (e % 3 + 1) % 3);
}

/* The slot of edge e in an open-addressing table (mask + 1 slots) whose entries
 * are 1 + the first edge seen with the same corners (low 32 bits; 0: empty) and
 * the high half of the corners' key (high 32 bits: most other edges are told
 * apart without reading their triangle). */
static size_t appm__edge_slot(const appm_scene *s, const uint64_t *tab, size_t mask, uint32_t e)
{
    appm__v3 a, b, c, d;
    uint64_t key;
    size_t i;
    appm__edge_ends(s, e, &a, &b);
    key = appm__pos_key(a) + appm__pos_key(b);
    for (i = (size_t)key & mask;; i = (i + 1) & mask) {
        if (tab[i] == 0) return i;
        if (tab[i] >> 32 != key >> 32) continue;
        appm__edge_ends(s, (uint32_t)tab[i] - 1, &c, &d);
        if ((appm__same_pos(a, c) && appm__same_pos(b, d)) || (appm__same_pos(a, d) && appm__same_pos(b, c)))
            return i;
    }
}

/* Whether a surface goes on beyond edge e, near its triangle's plane: probes at
 * a quarter, a half and three quarters of the edge, a thousandth of its length
 * (and a few float steps) beyond it, each a segment across the plane from H
 * above to H below (H a hundredth of the scene's bounding radius: a parallel
 * surface that near, a rug on a floor, a light just under a ceiling, would be
 * gathered), any of which meets a triangle within 60 degrees of parallel.  An
 * edge that a surface goes on beyond is not cut: its kernel loses nothing, and a
 * cut there would brighten it up to 2x.  Past a crossing surface (a wall) a
 * probe goes on, up to 4 hits. */
static int appm__edge_continues(const appm_scene *s, uint32_t e)
{
    const uint32_t ti = e / 3;
    appm__v3 a, b, c = appm__corner(&s->tri[ti], (e % 3 + 2) % 3), ng = s->info[ti].ng, o;
    float len, H;
    int k, hits;
    appm__edge_ends(s, e, &a, &b);
    o = appm__cross(appm__sub(b, a), ng);
    len = appm__length(appm__sub(b, a));
    if (!(appm__length(o) > 0.0f) || !(len > 0.0f)) return 1; /* degenerate: no line to cut along */
    o = appm__normalize(o);
    if (appm__dot(o, appm__sub(c, a)) > 0.0f) o = appm__neg(o); /* away from the triangle */
    H = 0.01f * s->radius > 1e-3f * len ? 0.01f * s->radius : 1e-3f * len;
    for (k = 1; k <= 3; ++k) {
        appm__v3 q = appm__add(a, appm__scale(appm__sub(b, a), 0.25f * (float)k));
        float dq = 1e-3f * len + 1e-5f * (fabsf(q.x) + fabsf(q.y) + fabsf(q.z));
        uint32_t skip = ti;
        appm__ray ray;
        appm__hit h;
        appm__ray_init(&ray, appm__add(appm__add(q, appm__scale(o, dq)), appm__scale(ng, H)), appm__neg(ng),
                       2.0f * H);
        for (hits = 0; hits < 4 && appm__intersect(s, &ray, skip, &h); ++hits) {
            if (fabsf(appm__dot(s->info[h.tri].ng, ng)) >= 0.5f) return 1;
            ray.tmin = h.t;
            skip = h.tri;
        }
    }
    return 0;
}

/* The slot of position p in a table (mask + 1 slots) of 1 + the first of the
 * open edges' ends at each position (end j: end j % 2 of open edge j / 2). */
static size_t appm__end_slot(const appm_scene *s, const uint32_t *tab, size_t mask, const uint32_t *oe,
                             appm__v3 p)
{
    size_t i;
    for (i = (size_t)appm__pos_key(p) & mask;; i = (i + 1) & mask) {
        appm__v3 a, b;
        uint32_t j;
        if (tab[i] == 0) return i;
        j = tab[i] - 1;
        appm__edge_ends(s, oe[j / 2], &a, &b);
        if (appm__same_pos(p, j % 2 ? b : a)) return i;
    }
}

/* The open edges near triangle t (its own, then those ending at its corners,
 * each once, at most APPM__OPEN_NEAR) into out; returns how many. */
static uint32_t appm__open_near(const appm_scene *s, uint32_t t, const uint8_t *open, const uint32_t *vtab,
                                size_t vmask, const uint32_t *next, const uint32_t *oe, uint32_t *out)
{
    uint32_t n = 0, k, j, i;
    for (k = 0; k < 3 && n < APPM__OPEN_NEAR; ++k)
        if (open[3 * t + k]) out[n++] = 3 * t + k;
    for (k = 0; k < 3 && n < APPM__OPEN_NEAR; ++k) {
        uint32_t head = vtab[appm__end_slot(s, vtab, vmask, oe, appm__corner(&s->tri[t], k))];
        /* a chain's edges are distinct (but for one whose two ends meet): the walk stops once the
         * list is full, so a corner that thousands of open edges share costs no more */
        for (j = head; j != 0 && n < APPM__OPEN_NEAR; j = next[j - 1]) {
            uint32_t e = oe[(j - 1) / 2];
            for (i = 0; i < n && out[i] != e; ++i) continue;
            if (i == n && n < APPM__OPEN_NEAR) out[n++] = e;
        }
    }
    return n;
}

/* Power of two >= 2 n (n > 0), or 0 on overflow. */
static size_t appm__table_size(size_t n)
{
    size_t c = 16;
    while (c < 2 * n) {
        if (c > SIZE_MAX / 4) return 0;
        c *= 2;
    }
    return c;
}

/* Finds the open edges and each triangle's list of those near it (s->open_off,
 * s->open_ref; both NULL when no edge is open).  After the BVH: the probes
 * trace rays. */
static appm_status appm__open_edges(appm_scene *s)
{
    appm__mem *m = &s->mem;
    const size_t ne = (size_t)s->ntri * 3;
    size_t cap, vcap, i, nref = 0;
    uint64_t *tab = NULL;
    uint32_t *slot = NULL, *vtab = NULL, *oe = NULL, *next = NULL, t, nearby[APPM__OPEN_NEAR];
    uint8_t *cnt = NULL, *open = NULL;
    appm_status st = APPM_ERR_NOMEM;
    s->nopen = 0;
    if (s->ntri == 0 || s->ntri > UINT32_MAX / APPM__OPEN_NEAR || !(cap = appm__table_size(ne))) return APPM_OK;
    tab = (uint64_t *)appm__alloc(m, cap, sizeof *tab);
    slot = (uint32_t *)appm__alloc(m, ne, sizeof *slot);
    cnt = (uint8_t *)appm__alloc(m, cap, 1);
    open = (uint8_t *)appm__alloc(m, ne, 1);
    if (!tab || !slot || !cnt || !open) goto done;
    for (i = 0; i < ne; ++i) { /* how many triangles have each edge (2: two or more) */
        size_t k = appm__edge_slot(s, tab, cap - 1, (uint32_t)i);
        if (tab[k] == 0) {
            appm__v3 a, b;
            appm__edge_ends(s, (uint32_t)i, &a, &b);
            tab[k] = ((appm__pos_key(a) + appm__pos_key(b)) & ~(uint64_t)0xFFFFFFFFu) | ((uint64_t)i + 1);
        }
        if (cnt[k] < 2) cnt[k]++;
        slot[i] = (uint32_t)k; /* cap <= 2^32: 3 ntri <= 3 UINT32_MAX / 8 */
    }
    for (i = 0; i < ne; ++i)
        if (cnt[slot[i]] == 1 && !appm__edge_continues(s, (uint32_t)i)) {
            open[i] = 1;
            s->nopen++;
        }
    st = APPM_OK;
    if (s->nopen == 0 || !(vcap = appm__table_size(2 * (size_t)s->nopen))) goto done;
    st = APPM_ERR_NOMEM;
    vtab = (uint32_t *)appm__alloc(m, vcap, sizeof *vtab);
    oe = (uint32_t *)appm__alloc(m, s->nopen, sizeof *oe);
    next = (uint32_t *)appm__alloc(m, 2 * (size_t)s->nopen, sizeof *next);
    s->open_off = (uint32_t *)appm__alloc(m, (size_t)s->ntri + 1, sizeof *s->open_off);
    if (!vtab || !oe || !next || !s->open_off) goto done;
    for (i = 0, t = 0; i < ne; ++i)
        if (open[i]) oe[t++] = (uint32_t)i;
    for (i = 0; i < 2 * (size_t)s->nopen; ++i) { /* each end joins the chain of its position */
        appm__v3 a, b;
        size_t k;
        appm__edge_ends(s, oe[i / 2], &a, &b);
        k = appm__end_slot(s, vtab, vcap - 1, oe, i % 2 ? b : a);
        next[i] = vtab[k];
        vtab[k] = (uint32_t)i + 1;
    }
    for (t = 0; t < s->ntri; ++t) {
        s->open_off[t] = (uint32_t)nref;
        nref += appm__open_near(s, t, open, vtab, vcap - 1, next, oe, nearby); /* <= 8 ntri: fits */
    }
    s->open_off[s->ntri] = (uint32_t)nref; /* > 0: an open edge is listed by its own triangle */
    if (!(s->open_ref = (uint32_t *)appm__alloc(m, nref, sizeof *s->open_ref))) goto done;
    for (t = 0; t < s->ntri; ++t)
        appm__open_near(s, t, open, vtab, vcap - 1, next, oe, s->open_ref + s->open_off[t]);
    st = APPM_OK;
done:
    if (st != APPM_OK || !s->open_ref) { /* none listed: none counted */
        appm__free(m, s->open_off);
        s->open_off = NULL;
        s->nopen = 0;
    }
    appm__free(m, tab);
    appm__free(m, slot);
    appm__free(m, cnt);
    appm__free(m, open);
    appm__free(m, vtab);
    appm__free(m, oe);
    appm__free(m, next);
    return st;
}

/* ==== 6. MATERIALS AND LIGHTS ============================================
 *
 * BSDFs: Lambert (cosine-weighted directions, weight = albedo), perfect mirror
 * (weight = Ks), a smooth dielectric (reflect with probability F, the exact
 * unpolarised Fresnel term, else refract; weight 1) and glossy, Lambert plus a
 * Phong lobe (section 6.1).  Lambert and glossy are also evaluated, per shadow
 * ray and (glossy) per photon in the gather.  The weight is f |cos| / pdf.
 * Two modes:
 *   radiance   (eye paths):    refraction scales by (eta_wo / eta_wi)^2, because
 *                              radiance / n^2 is what a refraction preserves;
 *   importance (photon paths): no eta^2 factor.  Veach's adjoint correction for
 *                              shading normals, |wo.ns||wi.ng| / (|wo.ng||wi.ns|)
 *                              (1997, section 5.3), is not applied (nor is it in
 *                              pbrt-v3's SPPM): exact in expectation, it is
 *                              unbounded where a photon grazes a facet of a
 *                              smooth-shaded mesh.  Measured on the sphere box,
 *                              photons reached 5.8 times their emitted weight and
 *                              became the fireflies that decided the RMSE; without
 *                              it none exceeds 1.  The price is a small bias at
 *                              the silhouettes of smooth-shaded meshes.
 * A sample that would leave through the wrong side of the geometric normal
 * (possible with shading normals) is absorbed: light must not leak.
 *
 * A photon starts at a light chosen by power (mean of R, G, B); shadow rays
 * choose otherwise (6.4, appm__light_table).  Emission is sampled so that a photon's weight gamma is
 * constant per light (zero-variance emission): gamma = Phi_light / pick -
 * on average only where the studio aims its sky's photons (6.3).
 */
enum { APPM__RADIANCE = 0, APPM__IMPORTANCE = 1 };

/* Cosine-weighted direction around unit n (Shirley-Chiu concentric disk). */
static appm__v3 appm__cosine_dir(appm__v3 n, float u1, float u2)
{
    float a = 2.0f * u1 - 1.0f, b = 2.0f * u2 - 1.0f, r, phi, x, y, z2;
    appm__v3 t, bt;
    if (a == 0.0f && b == 0.0f) return n;
    if (a * a > b * b) {
        r = a;
        phi = (APPM__PIF / 4.0f) * (b / a);
    } else {
        r = b;
        phi = (APPM__PIF / 2.0f) - (APPM__PIF / 4.0f) * (a / b);
    }
    x = r * cosf(phi);
    y = r * sinf(phi);
    z2 = 1.0f - x * x - y * y;
    appm__basis(n, &t, &bt);
    return appm__add(appm__add(appm__scale(t, x), appm__scale(bt, y)),
                     appm__scale(n, z2 > 0.0f ? sqrtf(z2) : 0.0f));
}

static appm__v3 appm__uniform_sphere(float u1, float u2)
{
    float z = 1.0f - 2.0f * u1, r2 = 1.0f - z * z, r = r2 > 0.0f ? sqrtf(r2) : 0.0f;
    float phi = 2.0f * APPM__PIF * u2;
    return appm__v(r * cosf(phi), r * sinf(phi), z);
}

/* Unpolarised Fresnel reflectance for cos_i in [0,1] on the incident side and
 * eta = n_transmitted / n_incident; 1 under total internal reflection. */
static float appm__fresnel(float cos_i, float eta)
{
    float sin2_t, cos_t, rs, rp;
    if (cos_i > 1.0f) cos_i = 1.0f;
    if (!(cos_i > 0.0f)) return 1.0f;
    sin2_t = (1.0f - cos_i * cos_i) / (eta * eta);
    if (sin2_t >= 1.0f) return 1.0f;
    cos_t = sqrtf(1.0f - sin2_t);
    rs = (cos_i - eta * cos_t) / (cos_i + eta * cos_t);
    rp = (eta * cos_i - cos_t) / (eta * cos_i + cos_t);
    return 0.5f * (rs * rs + rp * rp);
}

/* ---- 6.1 Glossy: Lambert + normalised modified Phong ------------------------
 *
 * Lafortune and Willems (1994), as interface.md section 2 defines it:
 *   f(wi, wo) = Kd / pi + Ks (Ns + 2) / (2 pi) max(0, wi . reflect(wo, n))^Ns
 * with n the shading normal on wo's side and zero for wi below the surface.
 * wi . reflect(wo, n) = 2 (wi.n)(wo.n) - wi.wo is symmetric in wi and wo, so f
 * is reciprocal: photons (which evaluate f(wi_photon, wo_eye)) and eye paths see
 * the same BSDF.  (Ns + 2) / (2 pi) normalises the lobe so that its albedo,
 * int lobe cos dw, is exactly Ks at wo = n; elsewhere the lobe is cut by the
 * horizon and the albedo is less, so the albedo never exceeds Kd + Ks <= 1.
 *
 * Sampling (one function of three uniform numbers): u3 picks the part by the
 * albedos, P_d = mean(Kd) / (mean(Kd) + mean(Ks)); (u1, u2) then give a cosine-
 * weighted direction or one about the mirror direction r = reflect(wo, n) with
 *   cos a = u1^(1 / (Ns + 1)),  pdf_lobe = (Ns + 1) / (2 pi) cos^Ns a,
 * and the weight is f cos / pdf with the mixture pdf P_d cos / pi + (1 - P_d)
 * pdf_lobe (the one-sample MIS estimator of Veach 1997, 9.2.4), so neither part
 * is noisy where the other one is large.  Directions below the surface (the
 * lobe reaches past the horizon at grazing wo) are rejected: the absorbed
 * share is exactly the albedo the horizon cuts off. */
static float appm__glossy_pd(const appm__material *m)
{
    float d = m->color.x + m->color.y + m->color.z, g = m->ks.x + m->ks.y + m->ks.z;
    return d + g > 0.0f ? d / (d + g) : 1.0f;
}

/* cos of the angle between wi and the mirror direction of wo about n. */
static float appm__phong_cos(appm__v3 n, appm__v3 wi, appm__v3 wo)
{
    return 2.0f * appm__dot(wi, n) * appm__dot(wo, n) - appm__dot(wi, wo);
}

/* f(wi, wo) of a diffuse or glossy material; n: unit shading normal on wo's
 * side.  Zero for wi below the surface, and for the specular materials. */
static appm__v3 appm__bsdf_f(const appm__material *m, appm__v3 n, appm__v3 wi, appm__v3 wo)
{
    appm__v3 f;
    float c;
    if (!(appm__dot(wi, n) > 0.0f) || (m->kind != APPM__MAT_DIFFUSE && m->kind != APPM__MAT_GLOSSY))
        return appm__v(0, 0, 0);
    f = appm__scale(m->color, (float)APPM__INV_PI);
    if (m->kind == APPM__MAT_GLOSSY && (c = appm__phong_cos(n, wi, wo)) > 0.0f) {
        float lobe = (m->ns + 2.0f) * (float)(0.5 * APPM__INV_PI) * powf(c > 1.0f ? 1.0f : c, m->ns);
        f = appm__add(f, appm__scale(m->ks, lobe));
    }
    return f;
}

/* The solid-angle pdf with which appm__bsdf_sample_dir picks wi (same n). */
static float appm__bsdf_pdf(const appm__material *m, appm__v3 n, appm__v3 wi, appm__v3 wo)
{
    float cw = appm__dot(wi, n), pd, c, pdf;
    if (!(cw > 0.0f)) return 0.0f;
    if (m->kind == APPM__MAT_DIFFUSE) return cw * (float)APPM__INV_PI;
    if (m->kind != APPM__MAT_GLOSSY) return 0.0f;
    pd = appm__glossy_pd(m);
    pdf = pd * cw * (float)APPM__INV_PI;
    if ((c = appm__phong_cos(n, wi, wo)) > 0.0f)
        pdf += (1.0f - pd) * (m->ns + 1.0f) * (float)(0.5 * APPM__INV_PI) * powf(c > 1.0f ? 1.0f : c, m->ns);
    return pdf;
}

/* A direction with pdf (Ns + 1) / (2 pi) cos^Ns a about unit r.  cos a =
 * u1^(1/(Ns+1)) and sin^2 a = -expm1(2 ln u1 / (Ns + 1)): for Ns = 1e5 the
 * lobe is 3e-3 wide, and 1 - cos^2 in float would lose most of sin a. */
static appm__v3 appm__phong_dir(appm__v3 r, float ns, float u1, float u2)
{
    float l = logf(u1) / (ns + 1.0f), ca = expf(l), sa2 = -expm1f(2.0f * l);
    float sa = sa2 > 0.0f ? sqrtf(sa2) : 0.0f, phi = 2.0f * APPM__PIF * u2;
    appm__v3 t, b;
    appm__basis(r, &t, &b);
    return appm__add(appm__add(appm__scale(t, sa * cosf(phi)), appm__scale(b, sa * sinf(phi))),
                     appm__scale(r, ca));
}

/* Glossy sample: the part by u3, a direction by (u1, u2), weight f cos / pdf. */
static int appm__glossy_sample(const appm__material *m, appm__v3 ns, appm__v3 ng, appm__v3 wo, float u1,
                               float u2, float u3, appm__v3 *wi, appm__v3 *weight, float *pdf)
{
    float c;
    if (u3 < appm__glossy_pd(m)) {
        *wi = appm__cosine_dir(ns, u1, u2);
    } else {
        appm__v3 r = appm__sub(appm__scale(ns, 2.0f * appm__dot(wo, ns)), wo);
        *wi = appm__phong_dir(appm__normalize(r), m->ns, u1, u2);
    }
    c = appm__dot(*wi, ns);
    if (!(appm__dot(*wi, ng) > 0.0f) || !(c > 0.0f)) return 0;
    *pdf = appm__bsdf_pdf(m, ns, *wi, wo);
    if (!(*pdf > 0.0f)) return 0;
    *weight = appm__scale(appm__bsdf_f(m, ns, *wi, wo), c / *pdf);
    return 1;
}

typedef struct appm__bsdf_sample {
    appm__v3 wi;
    appm__v3 weight; /* f |cos| / pdf, with the mode's corrections */
    float pdf;       /* solid angle; 0 for specular */
    int specular;
} appm__bsdf_sample;

static int appm__bsdf_sample_dir(const appm__material *m, const appm__surf *sf, appm__v3 wo,
                                 float u1, float u2, float u3, int mode, appm__bsdf_sample *bs)
{
    float side = appm__dot(wo, sf->ng) >= 0.0f ? 1.0f : -1.0f;
    appm__v3 ng = appm__scale(sf->ng, side), ns = appm__scale(sf->ns, side);
    bs->specular = m->kind != APPM__MAT_DIFFUSE && m->kind != APPM__MAT_GLOSSY;
    bs->pdf = 0.0f;
    if (m->kind == APPM__MAT_GLOSSY) {
        if (!appm__glossy_sample(m, ns, ng, wo, u1, u2, u3, &bs->wi, &bs->weight, &bs->pdf)) return 0;
    } else if (m->kind == APPM__MAT_DIFFUSE) {
        float c;
        bs->wi = appm__cosine_dir(ns, u1, u2);
        c = appm__dot(bs->wi, ns);
        if (!(appm__dot(bs->wi, ng) > 0.0f) || !(c > 0.0f)) return 0;
        bs->pdf = c * (float)APPM__INV_PI;
        bs->weight = m->color;
    } else if (m->kind == APPM__MAT_MIRROR) {
        float c = appm__dot(wo, ns);
        bs->wi = appm__sub(appm__scale(ns, 2.0f * c), wo);
        if (!(appm__dot(bs->wi, ng) > 0.0f)) return 0;
        bs->weight = m->color;
    } else {
        /* side > 0: wo is outside (the counter-clockwise side), entering the medium */
        float eta_o = side > 0.0f ? 1.0f : m->ior, eta_t = side > 0.0f ? m->ior : 1.0f;
        float cos_i = appm__dot(wo, ns), F;
        if (cos_i > 1.0f) cos_i = 1.0f;
        F = appm__fresnel(cos_i, eta_t / eta_o);
        if (u3 < F) {
            bs->wi = appm__sub(appm__scale(ns, 2.0f * cos_i), wo);
            if (!(appm__dot(bs->wi, ng) > 0.0f)) return 0;
            bs->weight = appm__v(1, 1, 1);
        } else {
            float eta = eta_o / eta_t, k = 1.0f - eta * eta * (1.0f - cos_i * cos_i), cos_t, s;
            if (!(k > 0.0f)) return 0; /* cannot happen when F < 1; guards rounding */
            cos_t = sqrtf(k);
            bs->wi = appm__normalize(
                appm__add(appm__scale(wo, -eta), appm__scale(ns, eta * cos_i - cos_t)));
            if (!(appm__dot(bs->wi, ng) < 0.0f)) return 0;
            s = mode == APPM__RADIANCE ? eta * eta : 1.0f;
            bs->weight = appm__v(s, s, s);
        }
    }
    return appm__finite3(bs->weight) && appm__finite3(bs->wi);
}

/* Which of u1, u2, u3 appm__bsdf_sample_dir reads for material m (bit k-1:
 * u_k), so that the sampler computes no others.  Glossy reads all three: u3
 * picks the part, (u1, u2) the direction. */
static unsigned appm__bsdf_dims(const appm__material *m)
{
    if (m->kind == APPM__MAT_GLOSSY) return 7u;
    return m->kind == APPM__MAT_DIFFUSE ? 3u : (m->kind == APPM__MAT_MIRROR ? 0u : 4u);
}

/* ---- 6.2 Environment maps -------------------------------------------------------
 *
 * The map is read as the radiance L(w) arriving from direction w: texel
 * (column c, row r) at u = (c + 1/2) / w, v = (r + 1/2) / h, the direction
 *      theta = pi v (from +y),  phi = 2 pi u + rot,
 *      w = (sin theta sin phi, cos theta, -sin theta cos phi),
 * and L between texel centres bilinear (repeating in u, clamped in v).
 * Shadow rays and photons draw w from a piecewise-constant density over the
 * texels (pbrt's InfiniteAreaLight, Pharr et al. 2016, 14.2.4): texel weight
 * f = the largest mean of RGB over the texel and its 8 neighbours (the texels
 * its bilinear value can borrow from, so the density is never 0 where L is
 * not) times sin theta (a row near a pole covers little solid angle).  Rows
 * are drawn by their sums, then a column within the row, each by inverting a
 * CDF (appm__cdf_invert), so the low-discrepancy points stay stratified; the
 * density in (u, v) is p(u, v) = w h f / sum f, in solid angle
 *      p(w) = p(u, v) / (2 pi^2 sin theta).
 * A small sun holding most of the power then gets most of the samples, which
 * is what makes its shadows sharp and its caustics possible at all. */

/* The radiance of texel (x, y). */
static const float *appm__env_texel(const appm__envmap *e, uint32_t x, uint32_t y)
{
    return e->rgb + 3 * ((size_t)y * e->w + x);
}

/* (u, v) in [0,1) x [0,1] of direction d. */
static void appm__env_uv(const appm__envmap *e, appm__v3 d, double *u, double *v)
{
    double y = d.y, len = sqrt((double)d.x * d.x + y * y + (double)d.z * d.z), phi;
    y = len > 0.0 ? y / len : 1.0;
    y = y > 1.0 ? 1.0 : (y < -1.0 ? -1.0 : y);
    *v = acos(y) / APPM__PI;
    phi = atan2((double)d.x, -(double)d.z) - e->rot;
    *u = phi / (2.0 * APPM__PI);
    *u -= floor(*u);
    if (!(*u < 1.0)) *u = 0.0;
}

/* L at (u, v) of appm__env_uv: bilinear between the four texel centres around it. */
static appm__v3 appm__env_lookup_uv(const appm__envmap *e, double u, double v)
{
    double fx, fy, x0f, y0f;
    float ax, ay, o[3];
    uint32_t x0, x1, y0, y1;
    int k;
    fx = u * e->w - 0.5;
    fy = v * e->h - 0.5;
    x0f = floor(fx);
    y0f = floor(fy);
    ax = (float)(fx - x0f);
    ay = (float)(fy - y0f);
    x0 = (uint32_t)((int64_t)x0f + e->w) % e->w;
    x1 = x0 + 1 == e->w ? 0 : x0 + 1;
    y0 = y0f < 0.0 ? 0 : (uint32_t)y0f; /* clamped at the poles */
    y1 = y0f < 0.0 ? 0 : (y0 + 1 < e->h ? y0 + 1 : e->h - 1);
    if (y0 >= e->h) y0 = e->h - 1;
    for (k = 0; k < 3; ++k)
        o[k] = (1.0f - ay) * ((1.0f - ax) * appm__env_texel(e, x0, y0)[k] + ax * appm__env_texel(e, x1, y0)[k]) +
               ay * ((1.0f - ax) * appm__env_texel(e, x0, y1)[k] + ax * appm__env_texel(e, x1, y1)[k]);
    return appm__v(o[0], o[1], o[2]);
}

/* L(d). */
static appm__v3 appm__env_lookup(const appm__envmap *e, appm__v3 d)
{
    double u, v;
    appm__env_uv(e, d, &u, &v);
    return appm__env_lookup_uv(e, u, v);
}

/* A direction's place in the map, (u, v) of appm__env_uv, and st = sin(pi v):
 * what its radiance and every density of it read.  A sampler returns the place
 * it drew, so that none of them is found again from the direction (an acos,
 * an atan2 and sines). */
typedef struct appm__env_place {
    double u, v, st;
} appm__env_place;

/* The direction at (u, v), and its place in *pl. */
static appm__v3 appm__env_at(const appm__envmap *e, double u, double v, appm__env_place *pl)
{
    double theta = APPM__PI * v, phi = 2.0 * APPM__PI * u + e->rot, st = sin(theta);
    pl->u = u;
    pl->v = v;
    pl->st = st;
    return appm__v((float)(st * sin(phi)), (float)cos(theta), (float)(-st * cos(phi)));
}

static appm__v3 appm__env_dir(const appm__envmap *e, double u, double v)
{
    appm__env_place pl;
    return appm__env_at(e, u, v, &pl);
}

/* The place of direction d. */
static void appm__env_place_of(const appm__envmap *e, appm__v3 d, appm__env_place *pl)
{
    appm__env_uv(e, d, &pl->u, &pl->v);
    pl->st = sin(APPM__PI * pl->v);
}

/* The solid-angle density of (u, v) under the piecewise-constant density
 * whose CDFs c lays out over a w x h grid of the map (rows' CDF, h + 1
 * entries, then each row's over its columns, w + 1 each): the map's own
 * (appm__env_sample) and each product density (appm__env_prod_sample). */
/* Its density in cell (x, y), whose sin theta is st > 0. */
static double appm__env_cell_pdf(const double *c, uint32_t w, uint32_t h, uint32_t x, uint32_t y, double st)
{
    const double *cr = c + (h + 1) + (size_t)y * (w + 1);
    return (c[y + 1] - c[y]) * (cr[x + 1] - cr[x]) * w * h / (2.0 * APPM__PI * APPM__PI * st);
}

/* st = sin(pi v), from the place (appm__env_place) that the map's grid and the
 * product's both read in a shadow ray's mixture (appm__env_mix_pdf). */
static double appm__env_grid_pdf(const double *c, uint32_t w, uint32_t h, double u, double v, double st)
{
    uint32_t x, y;
    if (!(st > 0.0)) return 0.0;
    x = (uint32_t)(u * w);
    y = (uint32_t)(v * h);
    if (x >= w) x = w - 1;
    if (y >= h) y = h - 1;
    return appm__env_cell_pdf(c, w, h, x, y, st);
}

/* The solid-angle density with which appm__env_sample draws the direction at
 * place pl. */
static float appm__env_pdf_at(const appm__envmap *e, const appm__env_place *pl)
{
    return (float)appm__env_grid_pdf(e->cdf, e->w, e->h, pl->u, pl->v, pl->st);
}

/* The same of direction d (the tests' entry: the library finds (u, v) once for both). */
APPM__UNUSED static float appm__env_pdf(const appm__envmap *e, appm__v3 d)
{
    appm__env_place pl;
    appm__env_place_of(e, d, &pl);
    return appm__env_pdf_at(e, &pl);
}

/* (u1, u2) to the place (*u, *v) of the grid density c of appm__env_grid_pdf:
 * a row by u1, a column of it by u2, each by inverting its CDF (so the
 * low-discrepancy points stay stratified); its cell (*x, *y). */
static void appm__env_grid_invert(const double *c, const uint32_t *g, uint32_t w, uint32_t h, float u1, float u2,
                                  float *u, float *v, int *x, int *y)
{
    *v = appm__cdf_invert_guided(c, (int)h, g, u1, y);
    *u = appm__cdf_invert_guided(c + (h + 1) + (size_t)*y * (w + 1), (int)w,
                                 g ? g + (size_t)(*y + 1) * (APPM__CDF_G + 1) : NULL, u2, x);
}

/* The guide tables of grid density c (laid out as appm__env_grid_pdf's) into g. */
static void appm__env_grid_guide(const double *c, uint32_t w, uint32_t h, uint32_t *g)
{
    uint32_t y;
    appm__cdf_guide(c, (int)h, g);
    for (y = 0; y < h; ++y)
        appm__cdf_guide(c + (h + 1) + (size_t)y * (w + 1), (int)w, g + (size_t)(y + 1) * (APPM__CDF_G + 1));
}

/* A direction *d from (u1, u2) with its solid-angle density (0: none), and
 * its place *pl in the map. */
static float appm__env_sample(const appm__envmap *e, float u1, float u2, appm__v3 *d, appm__env_place *pl)
{
    int y, x;
    float u, v;
    appm__env_grid_invert(e->cdf, e->guide, e->w, e->h, u1, u2, &u, &v, &x, &y);
    *d = appm__env_at(e, u, v, pl);
    if (!(pl->st > 0.0)) return 0.0f;
    return (float)appm__env_cell_pdf(e->cdf, e->w, e->h, (uint32_t)x, (uint32_t)y, pl->st);
}

/* Product sampling.  A shading point's light from the map is the integral of
 * L(w) max(0, n.w); the map's density draws w by L alone, the cosine's by
 * max(0, n.w) alone, and where the map is smooth (a sky) neither follows the
 * product: a grey ground under a sky brighter above than below, lit by one
 * shadow ray a pass, kept the grain of that mismatch.  So the map also keeps,
 * for each of APPM__ENV_BINS bins of shading normals (an octahedral grid, y
 * up, whose centre bin is +y: a flat ground's normal exactly), a density over
 * a coarse grid of at most APPM__ENV_PW x APPM__ENV_PH cells (L_cell: the
 * mean RGB of L's bilinear reconstruction over the cell, which a bright texel
 * spills into its neighbours' cells, appm__env_texel_lerp_mean) proportional to
 *      L_cell max(0, n_b . w_cell) sin theta_cell,
 * n_b the bin's centre normal and w_cell the cell's centre direction, drawn
 * as the map's own (rows, then a column, by inverting CDFs) and uniformly
 * within the cell.  For a normal at a bin's centre, under a sky smooth at the
 * cell's scale, the sample's weight f / p is close to the irradiance itself.
 * A sun smaller than a cell is still the map's density's to find: the shadow
 * ray draws from the mixture of 6.2's two and this one (appm__env_mix_pdf). */
#define APPM__ENV_PW 128
#define APPM__ENV_PH 64
/* A shadow ray's mixture (appm__env_mix_pdf): */
#define APPM__ENV_MIX_COS 0.125      /* the cosine's share, where n's bin has a product density */
#define APPM__ENV_MIX_MAP 0.375      /* the map's; the product density's is the rest */
#define APPM__ENV_MIX_MAP_FULL 0.125 /* the map's where the product densities hold every texel, and no sun */
#define APPM__ENV_SUN_OMEGA (0.04 * APPM__PI) /* 1 % of the sphere: a sun is a light this small... */
#define APPM__ENV_SUN_SHARE 0.4              /* ...that holds this share of the map's power */

/* The bin of unit normal n: its place (a, b) on the octahedral map, the
 * lower hemisphere folded over the diagonals, on a PB x PB grid. */
static uint32_t appm__env_bin(appm__v3 n)
{
    float l = fabsf(n.x) + fabsf(n.y) + fabsf(n.z), a, b;
    int i, k;
    if (!(l > 0.0f)) return (APPM__ENV_BINS - 1) / 2;
    a = n.x / l;
    b = n.z / l;
    if (n.y < 0.0f) {
        float fa = (1.0f - fabsf(b)) * (a >= 0.0f ? 1.0f : -1.0f);
        b = (1.0f - fabsf(a)) * (b >= 0.0f ? 1.0f : -1.0f);
        a = fa;
    }
    i = (int)((a + 1.0f) * 0.5f * (float)APPM__ENV_PB);
    k = (int)((b + 1.0f) * 0.5f * (float)APPM__ENV_PB);
    i = i < 0 ? 0 : (i >= APPM__ENV_PB ? APPM__ENV_PB - 1 : i);
    k = k < 0 ? 0 : (k >= APPM__ENV_PB ? APPM__ENV_PB - 1 : k);
    return (uint32_t)(i * APPM__ENV_PB + k);
}

/* The unit normal at the centre of bin `bin` (appm__env_bin's inverse there). */
static appm__v3 appm__env_bin_normal(uint32_t bin)
{
    float a = (2.0f * (float)(bin / APPM__ENV_PB) + 1.0f) / (float)APPM__ENV_PB - 1.0f;
    float b = (2.0f * (float)(bin % APPM__ENV_PB) + 1.0f) / (float)APPM__ENV_PB - 1.0f;
    float y = 1.0f - fabsf(a) - fabsf(b);
    if (y < 0.0f) {
        float fa = (1.0f - fabsf(b)) * (a >= 0.0f ? 1.0f : -1.0f);
        b = (1.0f - fabsf(a)) * (b >= 0.0f ? 1.0f : -1.0f);
        a = fa;
    }
    return appm__normalize(appm__v(a, y, b));
}

/* The mean of texel (x, y)'s RGB radiance. */
static double appm__env_texel_mean(const appm__envmap *e, uint32_t x, uint32_t y)
{
    const float *t = appm__env_texel(e, x, y);
    return ((double)t[0] + t[1] + t[2]) / 3.0;
}

/* The mean over texel (x, y)'s own cell of the bilinear L of
 * appm__env_lookup_uv, as a mean of RGB: within the cell L leans half-way
 * towards each neighbour, so in each direction the texel weighs 3/4 and its
 * two neighbours 1/8 each (wrapping in u; at a pole, where L is held
 * constant, the missing row is the texel's own).  A product density built
 * from the texels themselves would miss the light a bright texel spills into
 * its neighbours' cells: a sun of one texel sends 1 - (3/4)^2 = 44 % of its
 * light there, which only the map's own density (dilated, 6.2) then found,
 * with 3.3x the variance of a shadow ray at the 1/8 share of a full-size
 * product (docs/algorithm.md 5.9). */
static double appm__env_texel_lerp_mean(const appm__envmap *e, uint32_t x, uint32_t y)
{
    static const double wt[3] = {0.125, 0.75, 0.125};
    const uint32_t xs[3] = {x ? x - 1 : e->w - 1, x, x + 1 < e->w ? x + 1 : 0};
    const uint32_t ys[3] = {y ? y - 1 : 0, y, y + 1 < e->h ? y + 1 : y};
    double sum = 0.0;
    int a, b;
    for (b = 0; b < 3; ++b)
        for (a = 0; a < 3; ++a) sum += wt[a] * wt[b] * appm__env_texel_mean(e, xs[a], ys[b]);
    return sum;
}

/* The solid angle of a texel of row y: 2 pi / w in phi times cos theta_y -
 * cos theta_y+1. */
static double appm__env_texel_omega(const appm__envmap *e, uint32_t y)
{
    return 2.0 * APPM__PI / e->w * (cos(APPM__PI * y / e->h) - cos(APPM__PI * (y + 1.0) / e->h));
}

/* Integral of L over the sphere (W / m^2 / sr times sr), RGB, texel by
 * texel (appm__env_texel_omega). */
static void appm__env_integral(const appm__envmap *e, double *out)
{
    uint32_t x, y;
    int k;
    out[0] = out[1] = out[2] = 0.0;
    for (y = 0; y < e->h; ++y) {
        double dw = appm__env_texel_omega(e, y);
        for (x = 0; x < e->w; ++x)
            for (k = 0; k < 3; ++k) out[k] += dw * appm__env_texel(e, x, y)[k];
    }
}

/* The share of the map's power (the mean of its RGB integral) that its
 * brightest texels hold within a solid angle of `omega` steradians: a sun's
 * share, if the sun is smaller than omega.  The texels' mean radiances are
 * binned by their logarithm (APPM__ENV_PIN_BINS bins a stop, down to 2^-40
 * of the brightest; dimmer ones cannot make a pinpoint), the bins are taken
 * from the brightest down while their solid angle fits, and the bin that
 * overflows counts in proportion.  O(texels), no allocation. */
#define APPM__ENV_PIN_STOPS 40
#define APPM__ENV_PIN_BINS 16
static double appm__env_pinpoint(const appm__envmap *e, double omega)
{
    enum { NB = APPM__ENV_PIN_STOPS * APPM__ENV_PIN_BINS };
    double bw[NB], bp[NB], lmax = 0.0, total = 0.0, got = 0.0, left = omega;
    uint32_t x, y;
    int b;
    for (y = 0; y < e->h; ++y)
        for (x = 0; x < e->w; ++x) {
            const double l = appm__env_texel_mean(e, x, y);
            lmax = l > lmax ? l : lmax;
        }
    if (!(lmax > 0.0 && lmax < HUGE_VAL)) return 0.0;
    memset(bw, 0, sizeof bw);
    memset(bp, 0, sizeof bp);
    for (y = 0; y < e->h; ++y) {
        const double dw = appm__env_texel_omega(e, y);
        for (x = 0; x < e->w; ++x) {
            const double l = appm__env_texel_mean(e, x, y), f = l > 0.0 ? -log2(l / lmax) * APPM__ENV_PIN_BINS : NB;
            total += dw * l;
            if (f < (double)NB) { /* f >= 0: lmax is the brightest */
                b = (int)f;
                bw[b] += dw;
                bp[b] += dw * l;
            }
        }
    }
    for (b = 0; b < NB && left > 0.0; ++b) {
        if (bw[b] <= left) {
            got += bp[b];
            left -= bw[b];
        } else {
            got += bp[b] * left / bw[b];
            left = 0.0;
        }
    }
    return total > 0.0 ? got / total : 0.0;
}

/* Doubles of one bin's CDFs: rows (ph + 1), then each row's columns (pw + 1). */
static size_t appm__env_prod_size(const appm__envmap *e)
{
    return (size_t)e->ph + 1 + (size_t)e->ph * ((size_t)e->pw + 1);
}

/* Bin `bin`'s CDFs in pcdf, and their guide tables in pguide (NULL: none). */
static const double *appm__env_prod_cdf(const appm__envmap *e, uint32_t bin)
{
    return e->pcdf + bin * appm__env_prod_size(e);
}
static uint32_t *appm__env_prod_guide(const appm__envmap *e, uint32_t bin)
{
    return e->pguide ? e->pguide + bin * ((size_t)e->ph + 1) * (APPM__CDF_G + 1) : NULL;
}

/* The solid-angle density with which bin `bin`'s product density draws the
 * direction at place pl (0 where the bin has none). */
static double appm__env_prod_pdf_at(const appm__envmap *e, uint32_t bin, const appm__env_place *pl)
{
    if (!e->pcdf || !e->pok[bin]) return 0.0;
    return appm__env_grid_pdf(appm__env_prod_cdf(e, bin), e->pw, e->ph, pl->u, pl->v, pl->st);
}

/* A direction *d drawn from bin `bin`'s product density (which must exist),
 * and its place *pl in the map. */
static void appm__env_prod_sample(const appm__envmap *e, uint32_t bin, float u1, float u2, appm__v3 *d,
                                  appm__env_place *pl)
{
    int y, x;
    float u, v;
    appm__env_grid_invert(appm__env_prod_cdf(e, bin), appm__env_prod_guide(e, bin), e->pw, e->ph, u1, u2, &u, &v,
                          &x, &y);
    *d = appm__env_at(e, u, v, pl);
}

/* The product densities of every bin, from e->rgb; a bin whose hemisphere
 * sees no light gets none (pok 0).  mean: each coarse cell's sum of its
 * texels' mean RGB and their count. */
static appm_status appm__env_prod_build(appm__mem *m, appm__envmap *e, const char *name, appm_diag *diag)
{
    const uint32_t w = e->w, h = e->h;
    uint32_t pw = w < APPM__ENV_PW ? w : APPM__ENV_PW, ph = h < APPM__ENV_PH ? h : APPM__ENV_PH, x, y, bin;
    double *mean;
    size_t S;
    e->pw = pw;
    e->ph = ph;
    e->mix_map = pw < w || ph < h || appm__env_pinpoint(e, APPM__ENV_SUN_OMEGA) >= APPM__ENV_SUN_SHARE
                     ? APPM__ENV_MIX_MAP
                     : APPM__ENV_MIX_MAP_FULL;
    S = appm__env_prod_size(e);
    e->pcdf = (double *)appm__alloc(m, (size_t)APPM__ENV_BINS * S, sizeof(double));
    e->pguide = (uint32_t *)appm__alloc(m, (size_t)APPM__ENV_BINS * (ph + 1), (APPM__CDF_G + 1) * sizeof(uint32_t));
    mean = (double *)appm__alloc(m, (size_t)pw * ph, 2 * sizeof(double)); /* sums, then counts */
    if (!e->pcdf || !e->pguide || !mean) {
        appm__free(m, mean);
        return appm__fail(diag, APPM_ERR_NOMEM, name, 0, "out of memory for the environment map");
    }
    memset(mean, 0, (size_t)pw * ph * 2 * sizeof(double));
    for (y = 0; y < h; ++y) /* every texel into its cell: cell (x pw / w, y ph / h) */
        for (x = 0; x < w; ++x) {
            size_t c = (size_t)((uint64_t)y * ph / h) * pw + (size_t)((uint64_t)x * pw / w);
            mean[2 * c] += appm__env_texel_lerp_mean(e, x, y);
            mean[2 * c + 1] += 1.0;
        }
    for (bin = 0; bin < APPM__ENV_BINS; ++bin) {
        const appm__v3 nb = appm__env_bin_normal(bin);
        double *rows = e->pcdf + bin * S, *cols = rows + ph + 1, total;
        rows[0] = 0.0;
        for (y = 0; y < ph; ++y) {
            double v = (y + 0.5) / ph, st = sin(APPM__PI * v), sum;
            double *cr = cols + (size_t)y * (pw + 1);
            cr[0] = 0.0;
            for (x = 0; x < pw; ++x) {
                const double *mc = mean + 2 * ((size_t)y * pw + x);
                double c = (double)appm__dot(nb, appm__env_dir(e, (x + 0.5) / pw, v));
                cr[x + 1] = cr[x] + (c > 0.0 && mc[1] > 0.0 ? mc[0] / mc[1] * c : 0.0);
            }
            sum = cr[pw];
            for (x = 1; x <= pw; ++x) cr[x] = sum > 0.0 ? cr[x] / sum : (double)x / pw;
            cr[pw] = 1.0;
            rows[y + 1] = rows[y] + sum * st;
        }
        total = rows[ph];
        e->pok[bin] = total > 0.0 && total < HUGE_VAL;
        for (y = 1; y <= ph; ++y) rows[y] = e->pok[bin] ? rows[y] / total : (double)y / ph;
        rows[ph] = 1.0;
        appm__env_grid_guide(rows, pw, ph, appm__env_prod_guide(e, bin));
    }
    appm__free(m, mean);
    return APPM_OK;
}

/* The map's radiances (linear RGB times scale) and its sampling CDFs, from
 * the decoded file in e->px.  A map that holds NaN or infinity, or that is
 * black, is refused; negative samples (a lossy encoder's ringing) become 0. */
/* out[x]: the largest mean of RGB of texels x - 1, x, x + 1 of row y
 * (wrapping); mean: w floats of scratch. */
static void appm__env_row_max(const appm__envmap *e, uint32_t y, float *mean, float *out)
{
    const uint32_t w = e->w;
    uint32_t x;
    for (x = 0; x < w; ++x) {
        const float *t = appm__env_texel(e, x, y);
        mean[x] = (t[0] + t[1] + t[2]) / 3.0f;
    }
    for (x = 0; x < w; ++x) {
        float best = mean[x], l = mean[x ? x - 1 : w - 1], r = mean[x + 1 < w ? x + 1 : 0];
        if (l > best) best = l;
        if (r > best) best = r;
        out[x] = best;
    }
}

/* f[y w + x]: the mean of RGB, the largest over the 3 x 3 texels around
 * (x, y), wrapping in x, clipped at the poles.  The maximum is separable: the
 * largest of three in each row (ring: rows y - 1, y, y + 1 by y mod 3), then
 * of those three rows.  scratch: 4 w floats. */
static void appm__env_dilate(const appm__envmap *e, float *f, float *scratch)
{
    const uint32_t w = e->w, h = e->h;
    float *mean = scratch + 3 * (size_t)w;
    uint32_t x, y, row;
    for (row = 0; row < h && row < 2; ++row) appm__env_row_max(e, row, mean, scratch + (size_t)row * w);
    for (y = 0; y < h; ++y) {
        const float *mid = scratch + (size_t)(y % 3) * w;
        const float *up = y > 0 ? scratch + (size_t)((y + 2) % 3) * w : mid;
        const float *down = y + 1 < h ? scratch + (size_t)((y + 1) % 3) * w : mid;
        float *out = f + (size_t)y * w;
        for (x = 0; x < w; ++x) {
            float best = mid[x];
            if (up[x] > best) best = up[x];
            if (down[x] > best) best = down[x];
            out[x] = best;
        }
        if (y + 2 < h) appm__env_row_max(e, y + 2, mean, scratch + (size_t)((y + 2) % 3) * w);
    }
}

static appm_status appm__env_build(appm__mem *m, appm__envmap *e, const char *name, appm_diag *diag)
{
    uint32_t w = e->px.w, h = e->px.h, x, y;
    size_t n = (size_t)w * h, i;
    unsigned c3 = e->px.channels >= 3 ? 3 : 1, k;
    double total = 0.0, *rows, *cols;
    float *f, *scratch;
    e->w = w;
    e->h = h;
    e->rot = (float)(fmod(e->rotate, 360.0) * APPM__PI / 180.0); /* |rotate| <= 1e6: no precision lost */
    e->rgb = (float *)appm__alloc(m, n, 3 * sizeof(float));
    e->cdf = (double *)appm__alloc(m, (size_t)h + 1 + (size_t)h * ((size_t)w + 1), sizeof(double));
    e->guide = (uint32_t *)appm__alloc(m, (size_t)h + 1, (APPM__CDF_G + 1) * sizeof(uint32_t));
    f = (float *)appm__alloc(m, n, sizeof(float));
    scratch = (float *)appm__alloc(m, w, 4 * sizeof(float));
    if (!e->rgb || !e->cdf || !e->guide || !f || !scratch) {
        appm__free(m, f);
        appm__free(m, scratch);
        return appm__fail(diag, APPM_ERR_NOMEM, name, 0, "out of memory for the environment map");
    }
    for (i = 0; i < n; ++i)
        for (k = 0; k < 3; ++k) {
            double v = appm__pixels_linear(&e->px, i, c3 == 3 ? k : 0) * e->scale;
            if (!(v == v) || !(fabs(v) <= FLT_MAX)) {
                appm__free(m, f);
                appm__free(m, scratch);
                return appm__fail(diag, APPM_ERR_PARSE, name, 0,
                                  "environment map: pixel (%u, %u) is not a finite number",
                                  (unsigned)(i % w), (unsigned)(i / w));
            }
            e->rgb[3 * i + k] = v > 0.0 ? (float)v : 0.0f;
        }
    appm__env_dilate(e, f, scratch);
    appm__free(m, scratch);
    rows = e->cdf;
    cols = e->cdf + h + 1;
    rows[0] = 0.0;
    for (y = 0; y < h; ++y) {
        double st = sin(APPM__PI * (y + 0.5) / h), sum = 0.0;
        double *cr = cols + (size_t)y * (w + 1);
        cr[0] = 0.0;
        for (x = 0; x < w; ++x) cr[x + 1] = cr[x] + (double)f[(size_t)y * w + x];
        sum = cr[w];
        if (sum > 0.0)
            for (x = 1; x <= w; ++x) cr[x] /= sum;
        else /* a black row: uniform, never drawn (its row weight is 0) */
            for (x = 1; x <= w; ++x) cr[x] = (double)x / w;
        cr[w] = 1.0;
        rows[y + 1] = rows[y] + sum * st;
    }
    appm__free(m, f);
    total = rows[h];
    if (!(total > 0.0) || !(total < HUGE_VAL))
        return appm__fail(diag, APPM_ERR_PARSE, name, 0, "environment map: it is black, or its scale is 0, or its light sums to infinity");
    for (y = 1; y <= h; ++y) rows[y] /= total;
    rows[h] = 1.0;
    appm__env_grid_guide(e->cdf, w, h, e->guide);
    return appm__env_prod_build(m, e, name, diag);
}

/* bench/envmap.sh builds appm with APPM_ENV_UNIFORM=1 to measure what the
 * map's density buys: shadow rays then take the cosine alone and photons
 * uniform directions, as for a constant environment. */
#ifndef APPM_ENV_UNIFORM
#define APPM_ENV_UNIFORM 0
#endif

/* Shadow rays towards a map draw their direction from a mixture: 1/8 from
 * the cosine about the shading normal n, a share mix_map from the map's
 * density (a sun gets its samples) and the rest from the product density of
 * n's bin (6.2: a smooth sky times the cosine); where the bin has none, half
 * from each of the first two, as before the product.  The mixture's density
 * is their weighted mean, so no strategy's failure case (a small sun for the
 * cosine and a coarse product, a dim sky behind a bright horizon for the map)
 * costs more than a bounded factor of the variance of another; the cosine
 * keeps every direction above the surface possible.
 *   mix_map 3/8 (product 1/2): a map finer than its product densities, where a
 *     sun can hide inside a product cell, and a map with a sun (at least 40 %
 *     of its power within 1 % of the sphere, appm__env_pinpoint): a 128 x 64
 *     sky whose one-texel sun held 60 % of the light rendered 0.84x the RMSE
 *     of the 1/8 share, suns of 3 x 3 and 7 x 7 texels 0.92x and 0.96x;
 *   mix_map 1/8 (product 3/4): a map of at most APPM__ENV_PW x APPM__ENV_PH
 *     texels, which the product densities hold texel for texel, without a sun,
 *     as the studio's sky is (0.94x the RMSE of 3/8 at 32 passes).
 * Measured at equal passes (docs/algorithm.md 5.9): a quarter each for the
 * cosine and the map took 2-4 % more error on a sun that holds three quarters
 * of the light.  bin: n's (appm__env_bin); pl: the direction's place in the
 * map; cos_n: its cosine to n. */
static double appm__env_mix_pdf(const appm__envmap *e, uint32_t bin, const appm__env_place *pl, float cos_n)
{
    double pc = (cos_n > 0.0f ? cos_n : 0.0f) * APPM__INV_PI, pm;
    if (APPM_ENV_UNIFORM) return pc;
    pm = appm__env_pdf_at(e, pl);
    if (e->pcdf && e->pok[bin])
        return APPM__ENV_MIX_COS * pc + e->mix_map * pm +
               (1.0 - APPM__ENV_MIX_COS - e->mix_map) * appm__env_prod_pdf_at(e, bin, pl);
    return 0.5 * pm + 0.5 * pc;
}

/* L(d) of the scene's environment: its map's, its constant's, or 0. */
static appm__v3 appm__env_radiance(const appm_scene *s, appm__v3 d)
{
    if (s->env < 0) return appm__v(0, 0, 0);
    if (s->envmap.rgb) return appm__env_lookup(&s->envmap, d);
    return s->light[s->env].value;
}

/* ---- 6.3 Lights -------------------------------------------------------------- */

/* The entry of n whose interval [cdf[i], cdf[i+1]) of cumulative table cdf
 * holds u (binary search; u < 1 always), stepping past empty intervals
 * (lights of probability 0). */
static uint32_t appm__cdf_find(const double *cdf, uint32_t n, float u)
{
    uint32_t lo = 0, hi = n;
    double x = (double)u;
    while (hi - lo > 1) {
        uint32_t mid = lo + (hi - lo) / 2;
        if (cdf[mid] <= x) lo = mid;
        else hi = mid;
    }
    while (lo + 1 < n && !(cdf[lo + 1] > cdf[lo])) lo++;
    return lo;
}

/* The light a photon starts at (picked by power, 6.4). */
static uint32_t appm__pick_light(const appm_scene *s, float u)
{
    return appm__cdf_find(s->light_cdf, s->nlight, u);
}

/* Spot falloff of pbrt-v3: 1 inside cone-falloff, 0 outside cone, d^4 between. */
static float appm__spot_falloff(const appm__light *l, float cos_theta)
{
    float d;
    if (cos_theta <= l->cos_cone) return 0.0f;
    if (cos_theta >= l->cos_inner) return 1.0f;
    d = (cos_theta - l->cos_cone) / (l->cos_inner - l->cos_cone);
    return (d * d) * (d * d);
}

static appm__v3 appm__tri_point(const appm__tri *t, float u1, float u2, float *b1, float *b2)
{
    float su = sqrtf(u1);
    *b1 = u2 * su;
    *b2 = 1.0f - su;
    return appm__add(appm__add(appm__scale(t->p0, 1.0f - *b1 - *b2), appm__scale(t->p1, *b1)),
                     appm__scale(t->p2, *b2));
}

/* A sampled point on an area light as a surface, so that rays can leave it with
 * the same offsets as from any other hit. */
static void appm__light_surface(const appm_scene *s, uint32_t tri, float b1, float b2, appm__surf *sf)
{
    appm__hit h;
    h.t = 0.0f;
    h.b1 = b1;
    h.b2 = b2;
    h.tri = tri;
    appm__surface(s, &h, sf);
}

/* Whether the point (b1, b2) of emitting triangle tri lies in a hole of its
 * map_d cut-out.  Light there is not emitted: a sample of the whole triangle
 * that lands in a hole carries nothing (the estimate stays unbiased, and the
 * holes' share of the samples is lost). */
static int appm__light_cut(const appm_scene *s, uint32_t tri, float b1, float b2)
{
    appm__hit h;
    if (!s->cutouts) return 0;
    h.t = 0.0f;
    h.b1 = b1;
    h.b2 = b2;
    h.tri = tri;
    return appm__cut_away(s, &h);
}

typedef struct appm__photon_start {
    appm__ray ray;
    appm__v3 gamma;     /* photon weight: flux per emitted path, before dividing by M */
    uint32_t skip;      /* the emitting triangle, or UINT32_MAX */
} appm__photon_start;

/* The solid share of emitting triangle tri under its map_d cut-out, counted on
 * a 16 x 16 stratified grid of points; at least 1/256, so that a light whose
 * solid part the grid misses is still picked now and then.  It only steers
 * the choice of lights (the estimates stay unbiased whatever it is): a
 * mostly cut-away emitter gets a matching share of the samples. */
static double appm__light_solid(const appm_scene *s, uint32_t tri)
{
    const appm__material *m = &s->mat[s->info[tri].mat];
    unsigned i, j, n = 0;
    if (!s->cutouts || !m->map_d || s->info[tri].uv0 < 0) return 1.0;
    for (j = 0; j < 16; ++j)
        for (i = 0; i < 16; ++i) {
            float b1, b2;
            appm__tri_point(&s->tri[tri], ((float)i + 0.5f) / 16.0f, ((float)j + 0.5f) / 16.0f, &b1, &b2);
            n += !appm__light_cut(s, tri, b1, b2);
        }
    return (double)(n ? n : 1) / 256.0;
}

/* The power Phi (W, RGB) light l emits: what appm__emit's photon weight gamma
 * carries on average, E[gamma] = Phi / pick, so the two must agree (lights are
 * picked by power: pick = mean(Phi) / sum of mean(Phi)).
 *   area         Phi = pi A Le               (a Lambertian emitter; with a map_d
 *                cut-out, times its solid share, appm__light_solid: E[gamma]
 *                agrees to that count's accuracy)
 *   point        Phi = 4 pi I
 *   spot         Phi = 2 pi I [(1 - cos_inner) + (cos_inner - cos_cone) / 5]
 *                (the d^4 ramp integrates to a fifth of its width in cos theta)
 *   environment  Phi = 4 pi^2 R^2 L          (L through the disk of the bounding
 *                sphere, radius R, from every direction); with a map
 *                Phi = pi R^2 times the integral of L over the sphere */
static void appm__light_power(const appm_scene *s, const appm__light *l, double *power)
{
    double f;
    if (l->kind == APPM__LIGHT_AREA) {
        double a = (double)s->info[l->tri].area * appm__light_solid(s, l->tri);
        power[0] = APPM__PI * a * l->value.x;
        power[1] = APPM__PI * a * l->value.y;
        power[2] = APPM__PI * a * l->value.z;
        return;
    }
    if (l->kind == APPM__LIGHT_POINT) f = 4.0 * APPM__PI;
    else if (l->kind == APPM__LIGHT_SPOT) f = 2.0 * APPM__PI * ((1.0 - l->cos_inner) + (l->cos_inner - l->cos_cone) / 5.0);
    else if (s->envmap.rgb) { /* pi R^2 times the integral of L over the sphere */
        appm__env_integral(&s->envmap, power);
        f = APPM__PI * (double)s->radius * s->radius;
        power[0] *= f;
        power[1] *= f;
        power[2] *= f;
        return;
    } else f = 4.0 * APPM__PI * APPM__PI * (double)s->radius * s->radius;
    power[0] = f * l->value.x;
    power[1] = f * l->value.y;
    power[2] = f * l->value.z;
}

/* The studio's focus.  A bare OBJ's studio (appm__stand_in) puts a small
 * model on a wide plate under a sky, and the photons that light the model
 * are few: the sky's photons land all over the plate (direct light there,
 * which the shadow rays count) and bounce back into the sky, and 1.5-2 % of
 * the paths are stored.  Most of the picture's photon noise is on the model
 * and on the plate around it.  So the studio's photons are aimed at the
 * model's bounding sphere (appm_scene.focus, focus_r) twice, and at the plate
 * (appm_scene.plate, plate_e) once:
 *   emission   the environment's point on the disk facing its direction is
 *              drawn from a mixture: the plate's shadow on it (a share
 *              APPM__FOCUS_DISK) and the focus sphere's (a disk of radius
 *              focus_r around the focus's projection), appm__focus_disk;
 *   bounces    a diffuse bounce outside the focus sphere draws its direction from
 *              a mixture: the cosine lobe (a share APPM__FOCUS_COS) and the
 *              cone the focus sphere fills, seen from the bounce.
 * A one-sample mixture is importance sampling with the mixture's density
 * (Veach's balance heuristic), so the photon's weight divided by that density
 * keeps every estimate unbiased, and the defensive shares keep every path
 * that can light what is seen possible, with at most 1/share the weight.  Russian
 * roulette decides on the weight the cosine lobe would have given, so that
 * aimed photons are not killed for their small weights.  Every other scene has
 * no focus and takes the lights' and materials' own distributions. */
#define APPM__FOCUS_DISK 0.5f /* emission: the plate's share of the mixture (0.25, 0.75: 1.03x, 1.01x the RMSE) */
#define APPM__FOCUS_COS 0.25f /* bounces: the cosine lobe's share of the mixture */

/* The point (*px, *py) on the emission disk (frame t, b around the scene's
 * centre, facing the photon's direction d) for (u3, u4), and 1 / its area
 * density.  A photon travelling down takes a share APPM__FOCUS_DISK of its
 * points uniform over the plate's shadow on the disk (a parallelogram, the
 * plate's area times |d.y|), the rest over the focus sphere's; one travelling
 * up can meet the plate only from below, where its bounce leaves the scene,
 * and takes the focus sphere's alone.  The studio holds the plate and the
 * model, and the model lies in the focus sphere, so no photon that could
 * light what is seen is left out.  A point counts as in the shadow it was
 * drawn from even where rounding would put it a hair outside (the plate's,
 * seen almost edge on, would otherwise lose most of its points); the other
 * shadow is tested in double. */
static float appm__focus_disk(const appm_scene *s, appm__v3 d, appm__v3 t, appm__v3 b, float u3, float u4,
                              float *px, float *py)
{
    const double e = s->plate_e, rf = s->focus_r;
    const double a = d.y < 0.0f ? APPM__FOCUS_DISK : 0.0; /* the plate's share */
    appm__v3 rel = appm__sub(s->focus, s->center), pc = appm__sub(s->plate, s->center);
    double fx = appm__dot(rel, t), fy = appm__dot(rel, b), x, y, p = 0.0;
    int plate = u3 < a, focus = !plate;
    if (plate) { /* a point of the plate, moved along d onto the disk */
        double qx = pc.x + e * (2.0 * u3 / a - 1.0), qz = pc.z + e * (2.0 * u4 - 1.0);
        x = qx * t.x + (double)pc.y * t.y + qz * t.z;
        y = qx * b.x + (double)pc.y * b.y + qz * b.z;
        focus = (x - fx) * (x - fx) + (y - fy) * (y - fy) <= rf * rf;
    } else {
        double rr = rf * sqrt((u3 - a) / (1.0 - a)), phi = 2.0 * APPM__PI * u4;
        x = fx + rr * cos(phi);
        y = fy + rr * sin(phi);
        if (a > 0.0) { /* where the line from (x, y) along d meets the plate's plane */
            double qx = x * t.x + y * b.x, qy = x * t.y + y * b.y, qz = x * t.z + y * b.z;
            double k = ((double)pc.y - qy) / d.y;
            plate = fabs(qx + k * d.x - pc.x) <= e && fabs(qz + k * d.z - pc.z) <= e;
        }
    }
    if (focus) p += (1.0 - a) / (APPM__PI * rf * rf);
    if (plate) p += a / (4.0 * e * e * -(double)d.y);
    *px = (float)x;
    *py = (float)y;
    return p < 1e30 ? (float)(1.0 / p) : 0.0f; /* 0: the plate so nearly edge on that its density overflows */
}

/* Whether a photon's bounce off material m at sf is aimed (the studio's focus,
 * a diffuse surface outside the focus sphere that has the sphere's centre
 * above it, seen from direction wo). */
static int appm__focus_aims(const appm_scene *s, const appm__material *m, const appm__surf *sf, appm__v3 wo)
{
    appm__v3 dx;
    float side;
    if (!(s->focus_r > 0.0f) || m->kind != APPM__MAT_DIFFUSE) return 0;
    dx = appm__sub(s->focus, sf->p);
    side = appm__dot(wo, sf->ng) >= 0.0f ? 1.0f : -1.0f;
    return appm__dot(dx, dx) > s->focus_r * s->focus_r && side * appm__dot(dx, sf->ns) > 0.0f;
}

/* An aimed diffuse bounce (appm__focus_aims): the direction from u1 (the
 * mixture's choice and the first coordinate) and u2, in bs with the weight
 * appm__bsdf_sample_dir gives (the albedo, the cosine lobe's) and the
 * mixture's density p, and in *steer the factor the weight takes for the
 * mixture, (cos / pi) / p.  A direction the cone drew counts as in the cone
 * even where rounding puts it a hair outside, which would give it the lobe's
 * density alone, a weight up to 90x too large. */
static int appm__focus_bounce(const appm_scene *s, const appm__material *m, const appm__surf *sf, appm__v3 wo,
                              float u1, float u2, appm__bsdf_sample *bs, float *steer)
{
    const float h = APPM__FOCUS_COS;
    float side = appm__dot(wo, sf->ng) >= 0.0f ? 1.0f : -1.0f, c;
    appm__v3 ng = appm__scale(sf->ng, side), ns = appm__scale(sf->ns, side), dx = appm__sub(s->focus, sf->p);
    double d2 = appm__dot(dx, dx), f2 = (double)s->focus_r * s->focus_r;
    double gap = f2 / d2 / (1.0 + sqrt(1.0 - f2 / d2)); /* 1 - cos(theta_max), without cancellation */
    double cmax = 1.0 - gap, pc = 1.0 / (2.0 * APPM__PI * gap), p;
    appm__v3 axis = appm__scale(dx, (float)(1.0 / sqrt(d2)));
    if (u1 < h) {
        bs->wi = appm__cosine_dir(ns, u1 / h, u2);
    } else { /* uniform in the cone */
        float ct = (float)(1.0 - (double)((u1 - h) / (1.0f - h)) * gap), st = sqrtf(fmaxf(0.0f, 1.0f - ct * ct));
        float phi = 2.0f * APPM__PIF * u2;
        appm__v3 t, b;
        appm__basis(axis, &t, &b);
        bs->wi = appm__add(appm__add(appm__scale(t, st * cosf(phi)), appm__scale(b, st * sinf(phi))),
                           appm__scale(axis, ct));
    }
    c = appm__dot(bs->wi, ns);
    if (!(appm__dot(bs->wi, ng) > 0.0f) || !(c > 0.0f)) return 0;
    p = h * c * APPM__INV_PI + (u1 >= h || appm__dot(bs->wi, axis) >= (float)cmax ? (1.0 - h) * pc : 0.0);
    bs->pdf = (float)p;
    bs->weight = m->color;
    bs->specular = 0;
    *steer = (float)(c * APPM__INV_PI / p);
    return appm__finite3(bs->wi) && *steer > 0.0f && *steer <= FLT_MAX;
}

/* Samples the start of a photon path from light li and u[1..4] (appm__smp_emit):
 * position and direction (u[1], u[2] the first 2-D sample of each light kind,
 * the one a stratified sampler serves best; u[3], u[4] the second), with the
 * weight of a light picked by power (u[0] in appm__emit). */
static int appm__emit_light(const appm_scene *s, uint32_t li, const float *u, appm__photon_start *ps)
{
    const appm__light *l = &s->light[li];
    float u1 = u[1], u2 = u[2], u3 = u[3], u4 = u[4];
    appm__v3 o, d;
    float w;
    ps->skip = UINT32_MAX;
    ps->gamma = appm__v(0, 0, 0);
    if (!(l->pick > 0.0)) return 0;
    if (l->kind == APPM__LIGHT_AREA) {
        float b1, b2;
        appm__surf sf;
        appm__tri_point(&s->tri[l->tri], u1, u2, &b1, &b2);
        if (appm__light_cut(s, l->tri, b1, b2)) return 0;
        appm__light_surface(s, l->tri, b1, b2, &sf);
        d = appm__cosine_dir(sf.ng, u3, u4);
        o = appm__offset(&sf, d);
        /* gamma = Le cos / (pick * (1/A) * (cos/pi)) = Le pi A / pick */
        w = (float)(APPM__PI * s->info[l->tri].area / l->pick);
        ps->gamma = appm__scale(l->value, w);
        ps->skip = l->tri;
    } else if (l->kind == APPM__LIGHT_POINT) {
        o = l->pos;
        d = appm__uniform_sphere(u1, u2);
        ps->gamma = appm__scale(l->value, (float)(4.0 * APPM__PI / l->pick));
    } else if (l->kind == APPM__LIGHT_SPOT) {
        float cos_t = 1.0f - u1 * (1.0f - l->cos_cone), sin_t = sqrtf(fmaxf(0.0f, 1.0f - cos_t * cos_t));
        float phi = 2.0f * APPM__PIF * u2;
        appm__v3 t, b;
        appm__basis(l->axis, &t, &b);
        o = l->pos;
        d = appm__add(appm__add(appm__scale(t, sin_t * cosf(phi)), appm__scale(b, sin_t * sinf(phi))),
                      appm__scale(l->axis, cos_t));
        w = (float)(2.0 * APPM__PI * (1.0 - (double)l->cos_cone) / l->pick) * appm__spot_falloff(l, cos_t);
        ps->gamma = appm__scale(l->value, w);
    } else { /* environment: a direction, then a point on the disk facing it */
        appm__v3 t, b;
        float r = s->radius, rr = sqrtf(u3), phi = 2.0f * APPM__PIF * u4, px, py;
        double area = APPM__PI * (double)r * r; /* 1 / the point's density on the disk */
        if (!(r > 0.0f)) return 0;
        if (s->envmap.rgb) { /* the direction light arrives from by the map's density; the photon travels against it */
            appm__v3 wl;
            appm__env_place pl; /* its place in the map */
            float pdf = APPM_ENV_UNIFORM ? (float)(0.25 * APPM__INV_PI) : appm__env_sample(&s->envmap, u1, u2, &wl, &pl);
            if (APPM_ENV_UNIFORM) {
                wl = appm__uniform_sphere(u1, u2);
                appm__env_place_of(&s->envmap, wl, &pl);
            }
            if (!(pdf > 0.0f)) return 0;
            d = appm__neg(wl);
            appm__basis(d, &t, &b);
            if (s->focus_r > 0.0f) area = appm__focus_disk(s, d, t, b, u3, u4, &px, &py);
            /* gamma = L(wl) / (pick * p(wl) * (1/area)), area = pi R^2 without a focus */
            ps->gamma = appm__scale(appm__env_lookup_uv(&s->envmap, pl.u, pl.v), (float)(area / (l->pick * pdf)));
        } else {
            d = appm__uniform_sphere(u1, u2);
            appm__basis(d, &t, &b);
            /* gamma = L / (pick * (1/4pi) * (1/area)), area = pi R^2 without a focus */
            if (s->focus_r > 0.0f) {
                area = appm__focus_disk(s, d, t, b, u3, u4, &px, &py);
                ps->gamma = appm__scale(l->value, (float)(4.0 * APPM__PI * area / l->pick));
            } else {
                ps->gamma = appm__scale(l->value, (float)(4.0 * APPM__PI * APPM__PI * (double)r * r / l->pick));
            }
        }
        if (!(s->focus_r > 0.0f)) {
            px = r * rr * cosf(phi);
            py = r * rr * sinf(phi);
        } else if (!(area > 0.0)) {
            return 0;
        }
        o = appm__add(appm__sub(s->center, appm__scale(d, 1.001f * r)),
                      appm__add(appm__scale(t, px), appm__scale(b, py)));
    }
    appm__ray_init(&ps->ray, o, d, FLT_MAX);
    return appm__finite3(ps->gamma);
}

/* The start of a photon path from u[0..4]: the light by power (u[0]), then
 * appm__emit_light. */
static int appm__emit(const appm_scene *s, const float *u, appm__photon_start *ps)
{
    return appm__emit_light(s, appm__pick_light(s, u[0]), u, ps);
}

typedef struct appm__light_sample {
    appm__v3 wi;       /* unit direction from the shading point to the light */
    appm__v3 li;       /* incident radiance (or intensity / d^2) divided by the pdf */
    float pdf;         /* solid-angle pdf including the pick; 0 for delta lights */
    appm__ray shadow;  /* from the shading point to the light sample */
    uint32_t skip;     /* the light's triangle, or UINT32_MAX */
} appm__light_sample;

/* Next-event sample of light li from shading point sf (n: the shading normal
 * on the side the light must be on), chosen with probability pick.  Returns 0
 * when the sample carries nothing. */
static int appm__sample_light_k(const appm_scene *s, uint32_t li, double pick, const appm__surf *sf, appm__v3 n,
                                float u1, float u2, appm__light_sample *ls)
{
    const appm__light *l = &s->light[li];
    appm__v3 o, target, d;
    float dist2;
    ls->skip = UINT32_MAX;
    if (!(pick > 0.0)) return 0;
    if (l->kind == APPM__LIGHT_ENV) {
        float c;
        if (s->envmap.rgb) { /* the mixture of appm__env_mix_pdf, split by u1 */
            const appm__envmap *e = &s->envmap;
            const uint32_t bin = appm__env_bin(n);
            const int prod = e->pcdf && e->pok[bin];
            const float a = prod ? (float)APPM__ENV_MIX_COS : 0.5f;                  /* [0, a): the cosine */
            const float b = prod ? (float)(APPM__ENV_MIX_COS + e->mix_map) : 1.0f;   /* [a, b): the map */
            appm__env_place pl; /* the direction's place in the map */
            if (APPM_ENV_UNIFORM || u1 < a) { /* the cosine: its place in the map from the direction */
                ls->wi = APPM_ENV_UNIFORM ? appm__cosine_dir(n, u1, u2) : appm__cosine_dir(n, u1 / a, u2);
                appm__env_place_of(e, ls->wi, &pl);
            } else if (u1 < b) {
                appm__env_sample(e, (u1 - a) / (b - a), u2, &ls->wi, &pl);
            } else {
                appm__env_prod_sample(e, bin, (u1 - b) / (1.0f - b), u2, &ls->wi, &pl);
            }
            c = appm__dot(ls->wi, n);
            if (!(c > 0.0f)) return 0;
            ls->pdf = (float)(pick * appm__env_mix_pdf(e, bin, &pl, c));
            if (!(ls->pdf > 0.0f)) return 0;
            ls->li = appm__scale(appm__env_lookup_uv(e, pl.u, pl.v), 1.0f / ls->pdf);
        } else { /* a constant: by the cosine, the product's best */
            ls->wi = appm__cosine_dir(n, u1, u2);
            c = appm__dot(ls->wi, n);
            if (!(c > 0.0f)) return 0;
            ls->pdf = (float)(pick * c * APPM__INV_PI);
            ls->li = appm__scale(l->value, 1.0f / ls->pdf);
        }
        o = appm__offset(sf, ls->wi);
        appm__ray_init(&ls->shadow, o, ls->wi, FLT_MAX);
        return 1;
    }
    if (l->kind == APPM__LIGHT_AREA) {
        float b1, b2, cos_l, dist;
        appm__surf lf;
        appm__tri_point(&s->tri[l->tri], u1, u2, &b1, &b2);
        if (appm__light_cut(s, l->tri, b1, b2)) return 0;
        appm__light_surface(s, l->tri, b1, b2, &lf);
        d = appm__sub(lf.p, sf->p);
        dist2 = appm__dot(d, d);
        if (!(dist2 > 0.0f)) return 0;
        dist = sqrtf(dist2);
        ls->wi = appm__scale(d, 1.0f / dist);
        cos_l = -appm__dot(ls->wi, lf.ng);
        if (!(cos_l > 0.0f)) return 0; /* one-sided emitter seen from behind */
        ls->pdf = (float)(pick / s->info[l->tri].area * (double)dist2 / cos_l);
        ls->li = appm__scale(l->value, 1.0f / ls->pdf);
        target = appm__offset(&lf, appm__neg(ls->wi));
        ls->skip = l->tri;
    } else {
        float f = 1.0f;
        d = appm__sub(l->pos, sf->p);
        dist2 = appm__dot(d, d);
        if (!(dist2 > 0.0f)) return 0;
        ls->wi = appm__scale(d, 1.0f / sqrtf(dist2));
        if (l->kind == APPM__LIGHT_SPOT) f = appm__spot_falloff(l, -appm__dot(ls->wi, l->axis));
        if (!(f > 0.0f)) return 0;
        ls->pdf = 0.0f;
        ls->li = appm__scale(l->value, (float)(f / ((double)dist2 * pick)));
        target = l->pos;
    }
    o = appm__offset(sf, ls->wi);
    /* parametric shadow ray o + t (target - o), t in [0, 1 - 1e-4): relative, so
     * the same in any unit */
    appm__ray_init(&ls->shadow, o, appm__sub(target, o), 1.0f - 1e-4f);
    return appm__finite3(ls->li);
}

/* The one sample of the area and environment lights from table t (6.4: 0
 * appm's eye pass, 1 the path tracer's; u0 picks the light by
 * appm__light.nee[t], u1, u2 the point or direction); the point and spot
 * lights that every shading point samples are appm__sample_light_k's with
 * pick 1 (appm_scene.nee_delta). */
static int appm__sample_light(const appm_scene *s, int t, const appm__surf *sf, appm__v3 n, float u0, float u1,
                              float u2, appm__light_sample *ls)
{
    uint32_t li;
    if (!(s->nee_cdf[t][s->nlight] > 0.0)) return 0;
    li = appm__cdf_find(s->nee_cdf[t], s->nlight, u0);
    return appm__sample_light_k(s, li, s->light[li].nee[t], sf, n, u1, u2, ls);
}

/* Which numbers the lights of scene s make the samplers read (appm__smp_light,
 * appm__smp_emit): bit 0 the light choice (more than one light to pick from);
 * for next-event estimation bit 1 a point on the light (an area or environment
 * light); for emission bit 1 u1, u2 (every kind) and bit 2 u3, u4 (area and
 * environment). */
static unsigned appm__light_dims(const appm_scene *s, int emission)
{
    unsigned mask = 0u, k, picked = 0u;
    for (k = 0; k < s->nlight; ++k) picked += emission ? s->light[k].pick > 0.0 : s->light[k].nee[0] > 0.0;
    if (emission ? s->nlight > 1 : picked > 1) mask |= 1u;
    if (emission) mask |= 2u;
    for (k = 0; k < s->nlight; ++k)
        if (s->light[k].kind == APPM__LIGHT_AREA || s->light[k].kind == APPM__LIGHT_ENV)
            mask |= emission ? 4u : 2u;
    return mask;
}

/* Solid-angle pdf with which the path tracer's light sample (table 1 of
 * appm__sample_light) would have produced direction wi reaching area light
 * `tri` at distance t (for MIS in the path tracer). */
static float appm__area_light_pdf(const appm_scene *s, uint32_t tri, appm__v3 wi, float t)
{
    const appm__tri_info *in = &s->info[tri];
    float cos_l = -appm__dot(wi, in->ng);
    if (in->light < 0 || !(cos_l > 0.0f)) return 0.0f;
    return (float)(s->light[in->light].nee[1] / in->area * ((double)t * t) / cos_l);
}

/* ---- 6.4 The light table and scene assembly -------------------------------
 *
 * Loader arrays (section 4) -> an immutable scene: exact-size copies, bounds,
 * the BVH (section 5), one light per emissive triangle plus the scene's
 * lights with the table that picks them by power (6.3), and the camera.  Here,
 * not in section 4, because it needs the BVH and the lights.
 */
static void appm__loader_free(appm__loader *L)
{
    appm__array_free(L->mem, &L->pos);
    appm__array_free(L->mem, &L->vn);
    appm__array_free(L->mem, &L->nrm);
    appm__array_free(L->mem, &L->tri);
    appm__array_free(L->mem, &L->info);
    appm__array_free(L->mem, &L->mat);
    appm__array_free(L->mem, &L->names);
    appm__array_free(L->mem, &L->face);
    appm__array_free(L->mem, &L->lights);
    appm__array_free(L->mem, &L->vt);
    appm__array_free(L->mem, &L->uv);
    if (L->tex.data) { /* textures the scene did not take */
        size_t k;
        for (k = 0; k < L->tex.count; ++k) appm__free(L->mem, ((appm__texture *)L->tex.data)[k].px.data);
    }
    appm__array_free(L->mem, &L->tex);
    appm__free(L->mem, L->envmap.px.data);
    L->envmap.px.data = NULL;
}

/* Copies a loader array into an exact-size block owned by the scene. */
static void *appm__take(appm__mem *m, appm__array *a, int *ok)
{
    void *p;
    if (a->count == 0) return NULL;
    p = appm__alloc(m, a->count, a->elem);
    if (!p) {
        *ok = 0;
        return NULL;
    }
    memcpy(p, a->data, a->count * a->elem);
    return p;
}

/* Takes the map the loader decoded (or that appm_scene_set_environment_map
 * read) into *e: radiances, CDFs and hash; the file's samples are freed. */
static appm_status appm__envmap_take(appm__mem *m, appm__envmap *e, appm__envmap *from, const char *name,
                                     appm_diag *diag)
{
    appm_status st;
    size_t i, n;
    uint64_t h = 0xcbf29ce484222325ull;
    memset(e, 0, sizeof *e);
    e->px = from->px;
    e->scale = from->scale;
    e->rotate = from->rotate;
    from->px.data = NULL;
    st = appm__env_build(m, e, name, diag);
    appm__free(m, e->px.data);
    e->px.data = NULL;
    if (st != APPM_OK) return st;
    n = (size_t)e->w * e->h * 3;
    for (i = 0; i < n; ++i) { /* FNV-1a of the radiances: the file, its scale; then the rotation */
        uint32_t u;
        memcpy(&u, &e->rgb[i], 4);
        h = (h ^ u) * 0x100000001b3ull;
    }
    {
        double rot = e->rotate;
        uint64_t r;
        memcpy(&r, &rot, sizeof r);
        e->hash = appm__mix64(h ^ ((uint64_t)e->w << 32 | e->h)) ^ appm__mix64(r);
    }
    return APPM_OK;
}

static void appm__envmap_free(appm__mem *m, appm__envmap *e)
{
    appm__free(m, e->rgb);
    appm__free(m, e->cdf);
    appm__free(m, e->guide);
    appm__free(m, e->pcdf);
    appm__free(m, e->pguide);
    appm__free(m, e->px.data);
    memset(e, 0, sizeof *e);
}

static void appm__scene_free_parts(appm__mem *m, appm_scene *s)
{
    uint32_t i;
    appm__envmap_free(m, &s->envmap);
    for (i = 0; i < s->ntex; ++i) appm__free(m, s->tex[i].px.data);
    appm__free(m, s->tex);
    appm__free(m, s->uv);
    appm__free(m, s->tri);
    appm__free(m, s->info);
    appm__free(m, s->normals);
    appm__free(m, s->open_off);
    appm__free(m, s->open_ref);
    appm__free(m, s->mat);
    appm__free(m, s->light);
    appm__free(m, s->light_cdf);
    appm__free(m, s->node);
    appm__free(m, s->wnode_mem);
}

static double appm__mean3(const double *v) { return (v[0] + v[1] + v[2]) / 3.0; }

/* Whether light l is in shadow-ray table t's one sample (t = 0 appm's eye
 * pass, 1 the path tracer's). */
static int appm__nee_picked(const appm_scene *s, const appm__light *l, int t)
{
    if (l->nee_all || !(l->pick > 0.0)) return 0;
    return !(t == 1 && l->kind == APPM__LIGHT_ENV && !s->envmap.rgb);
}

/* The light-choice tables.  A photon starts at a light picked with its share
 * of the total power (the mean of the three channels), the cumulative
 * s->light_cdf.
 *
 * A shadow ray is not a photon: it is one sample of a sum over the lights,
 * and picking the term by power makes the sum noisy wherever the lights that
 * light a point are not the powerful ones.  An environment's power is its
 * flux through the whole scene, so beside it a spot light that lights the
 * model carries little of the scene's power (the teapot's 11 %), and a
 * shading point in the spot's cone took a shadow ray towards it once in 9
 * passes, with 9 times its weight.  A point or spot light costs one
 * shadow ray and no random number, so every shading point sends one to each
 * (appm__light.nee_all: the APPM__NEE_DELTA most powerful of them), and one
 * sample picks among the other lights - area, environment and any further
 * point or spot lights - by their power (appm__light.nee[0], the cumulative
 * s->nee_cdf[0]; APPM__SKY_SAMPLES under the studio's sky, appm__direct).
 * The sum of the two is the same expectation with the delta lights' share
 * of the variance gone.
 *
 * The path tracer's table (nee[1], nee_cdf[1]) leaves out a constant
 * environment: there the light sample would draw the cosine lobe, the very
 * directions of a diffuse vertex's BSDF sample, which the path traces anyway
 * and which, where it meets the model instead of the sky, carries the
 * model's light rather than nothing; so the BSDF sample alone finds it
 * (appm__pt_env, weight 1).  Measured in docs/algorithm.md 5.11. */
static appm_status appm__light_table(appm_scene *s, appm_diag *diag, const char *name)
{
    uint32_t i, k = s->nlight;
    int t;
    double total = 0.0;
    for (i = 0; i < k; ++i) total += appm__mean3(s->light[i].power);
    if (!(total > 0.0) || !(total < HUGE_VAL))
        return appm__fail(diag, APPM_ERR_PARSE, name, 0, "the lights emit no (or infinite) power");
    /* Lights are picked by power, so every photon starts with about the total
     * power in each channel: at most 3 times it (a channel against the mean of
     * three), 15 times for a spot whose falloff spans its whole cone.  Photon
     * weights are floats: beyond FLT_MAX / 16 every photon would overflow. */
    if (total > FLT_MAX / 16.0)
        return appm__fail(diag, APPM_ERR_PARSE, name, 0,
                          "the lights emit %g W, more than a photon's single-precision weight can "
                          "carry (%g W): use larger units or a smaller Ke",
                          total, FLT_MAX / 16.0);
    s->light_cdf[0] = 0.0;
    for (i = 0; i < k; ++i) {
        s->light[i].pick = appm__mean3(s->light[i].power) / total;
        s->light_cdf[i + 1] = s->light_cdf[i] + s->light[i].pick;
    }
    s->light_cdf[k] = 1.0;
    /* the APPM__NEE_DELTA most powerful point and spot lights (the first of
     * equals), in light order */
    for (i = 0; i < k; ++i) s->light[i].nee_all = 0;
    for (t = 0; t < APPM__NEE_DELTA; ++t) {
        uint32_t best = k;
        for (i = 0; i < k; ++i) {
            const appm__light *l = &s->light[i];
            if ((l->kind == APPM__LIGHT_POINT || l->kind == APPM__LIGHT_SPOT) && l->pick > 0.0 && !l->nee_all &&
                (best == k || l->pick > s->light[best].pick))
                best = i;
        }
        if (best == k) break;
        s->light[best].nee_all = 1;
    }
    s->nnee_delta = 0;
    for (i = 0; i < k; ++i)
        if (s->light[i].nee_all) s->nee_delta[s->nnee_delta++] = i;
    for (t = 0; t < 2; ++t) {
        double *cdf = s->nee_cdf[t] = s->light_cdf + (size_t)(t + 1) * (k + 1);
        total = 0.0;
        for (i = 0; i < k; ++i) total += appm__nee_picked(s, &s->light[i], t) ? s->light[i].pick : 0.0;
        cdf[0] = 0.0;
        for (i = 0; i < k; ++i) {
            appm__light *l = &s->light[i];
            l->nee[t] = appm__nee_picked(s, l, t) && total > 0.0 ? l->pick / total : 0.0;
            cdf[i + 1] = cdf[i] + l->nee[t];
        }
        cdf[k] = total > 0.0 ? 1.0 : 0.0;
    }
    return APPM_OK;
}

/* Builds the light table: one area light per emissive triangle (after the BVH
 * has fixed triangle order), then the point, spot and environment lights.  A
 * bare OBJ in which nothing emits gets a constant white environment of
 * radiance 1 (marked, so that the first light added to the scene replaces it). */
static appm_status appm__scene_lights(appm_scene *s, appm__loader *L, const char *name)
{
    uint32_t i, n = 0, k = 0, extra = (uint32_t)L->lights.count;
    for (i = 0; i < s->ntri; ++i) n += s->mat[s->info[i].mat].emissive;
    if (L->stand_in) { /* the studio's sky (appm__stand_in, L->envmap) or the white environment */
        appm__light *l = (appm__light *)appm__array_push(L->mem, &L->lights);
        if (!l) return APPM_ERR_NOMEM;
        l->kind = APPM__LIGHT_ENV;
        l->value = appm__v(1.0f, 1.0f, 1.0f);
        extra = 1;
        s->env_auto = L->white ? 1 : 2;
    }
    if (n + extra == 0)
        return appm__fail(L->diag, APPM_ERR_PARSE, name, 0,
                          "the scene has no light (no material with Ke > 0, no light or environment)");
    s->light = (appm__light *)appm__alloc(&s->mem, (size_t)n + extra, sizeof *s->light);
    s->light_cdf = (double *)appm__alloc(&s->mem, 3 * ((size_t)n + extra + 1), sizeof *s->light_cdf);
    if (!s->light || !s->light_cdf) return APPM_ERR_NOMEM;
    s->env = -1;
    for (i = 0; i < s->ntri; ++i) {
        const appm__material *m = &s->mat[s->info[i].mat];
        appm__light *l;
        if (!m->emissive) continue;
        l = &s->light[k];
        l->kind = APPM__LIGHT_AREA;
        l->tri = i;
        l->value = m->ke;
        s->mat[s->info[i].mat].emit_area += s->info[i].area;
        appm__light_power(s, l, l->power);
        s->info[i].light = (int32_t)k++;
    }
    for (i = 0; i < extra; ++i) {
        appm__light *l = &s->light[k];
        *l = ((appm__light *)L->lights.data)[i];
        if (l->kind == APPM__LIGHT_ENV) {
            appm_status st;
            if (s->env >= 0)
                return appm__fail(L->diag, APPM_ERR_PARSE, name, l->line, "more than one environment");
            s->env = (int)k;
            if (L->envmap.px.data) {
                appm_diag why;
                appm__diag_clear(&why);
                s->mem.diag = &why;
                st = appm__envmap_take(&s->mem, &s->envmap, &L->envmap, name, &why);
                s->mem.diag = L->diag;
                if (st != APPM_OK)
                    return appm__fail(L->diag, st, name, l->line, "'%s': %s", L->envmap_path, why.message);
            }
        }
        appm__light_power(s, l, l->power);
        k++;
    }
    s->nlight = k;
    return appm__light_table(s, L->diag, name);
}

/* A bare OBJ in which nothing emits and that names no light gets a studio,
 * as a product shot would show it: a ground plate under its bounding box
 * that catches its shadow (grey, albedo 0.5, 2 radii of the model's bounding
 * sphere each way: wider puts more of the photons the sky emits on it, the
 * model's share falling as the square of the scene's radius, a hair below the model so the two never overlap), a sky
 * brighter above than below with a soft key light high on the left in front
 * (an environment map, 6.2, so shadow rays and photons find the key light),
 * and a camera 20 degrees above the model, framing it.  Without form the
 * model is a silhouette: under the constant white sky of earlier versions
 * the bunny's centre was within 17 % of the background.  Lights the user
 * adds later (appm_scene_add_point_light, _set_environment...) replace the
 * sky; the plate stays. */
#define APPM__STAND_IN_W 128 /* the sky map: 128 x 64 texels, 2.8 degrees each */

/* The sky's radiance from direction d: 0.3 at the horizon to 1 at the zenith
 * (a slightly blue white), 0.2 below, and the key light, radiance 14 (a warm
 * white) within 10 degrees of its axis, fading to the sky over 3 more: about
 * as much irradiance as the whole sky, so the model has a lit side and a
 * shadow on the plate. */
static appm__v3 appm__stand_in_sky(appm__v3 d)
{
    const appm__v3 key = appm__normalize(appm__v(-0.55f, 0.72f, 0.42f));
    float y = d.y, c = appm__dot(d, key), sky = y >= 0.0f ? 0.3f + 0.7f * y : 0.2f, k = 0.0f;
    float c0 = (float)cos(13.0 * APPM__PI / 180.0), c1 = (float)cos(10.0 * APPM__PI / 180.0);
    if (c > c0) k = c >= c1 ? 14.0f : 14.0f * (c - c0) / (c1 - c0);
    return appm__v(sky * 0.92f + k, sky * 0.96f + k * 0.96f, sky + k * 0.9f);
}

/* The plate under a model of bounds lo, hi: its centre *c and half width *e. */
static void appm__plate_of(appm__v3 lo, appm__v3 hi, appm__v3 *c, float *e)
{
    float r = 0.5f * appm__length(appm__sub(hi, lo));
    *c = appm__v(0.5f * (lo.x + hi.x), lo.y - 1e-3f * r, 0.5f * (lo.z + hi.z));
    *e = 2.0f * r;
}

static appm_status appm__stand_in(appm__loader *L, appm__v3 lo, appm__v3 hi)
{
    appm__v3 c, corner[4];
    float e, y;
    const uint32_t w = APPM__STAND_IN_W, h = APPM__STAND_IN_W / 2;
    appm__material *g = (appm__material *)appm__array_push(L->mem, &L->mat);
    int64_t idx[4][3];
    uint32_t x, k, mat;
    float *sky;
    appm_status st;
    appm__plate_of(lo, hi, &c, &e);
    y = c.y;
    if (!g) return APPM_ERR_NOMEM;
    g->kind = APPM__MAT_DIFFUSE;
    g->color = appm__v(0.5f, 0.5f, 0.5f);
    g->ior = 1.5f;
    g->ns = 1.0f;
    mat = (uint32_t)L->mat.count - 1;
    corner[0] = appm__v(c.x - e, y, c.z - e);
    corner[1] = appm__v(c.x - e, y, c.z + e);
    corner[2] = appm__v(c.x + e, y, c.z + e);
    corner[3] = appm__v(c.x + e, y, c.z - e);
    L->pos.count = 0; /* the OBJ's vertices are no longer needed */
    L->vt.count = 0;
    for (k = 0; k < 4; ++k) {
        appm__v3 *p = (appm__v3 *)appm__array_push(L->mem, &L->pos);
        if (!p) return APPM_ERR_NOMEM;
        *p = corner[k];
        idx[k][0] = k;
        idx[k][1] = idx[k][2] = -1;
    }
    /* counter-clockwise seen from above: the plate faces +y */
    if ((st = appm__obj_tri(L, idx[0], idx[1], idx[2], mat, 0)) != APPM_OK ||
        (st = appm__obj_tri(L, idx[0], idx[2], idx[3], mat, 0)) != APPM_OK)
        return st;
    sky = (float *)appm__alloc(L->mem, (size_t)w * h, 3 * sizeof(float));
    if (!sky) return APPM_ERR_NOMEM;
    L->envmap.px.w = w;
    L->envmap.px.h = h;
    L->envmap.px.channels = 3;
    L->envmap.px.depth = 32;
    L->envmap.px.data = sky;
    L->envmap.scale = 1.0;
    for (k = 0; k < h; ++k)
        for (x = 0; x < w; ++x) { /* each texel: the sky at its centre's direction (6.2) */
            double th = APPM__PI * (k + 0.5) / h, ph = 2.0 * APPM__PI * (x + 0.5) / w;
            appm__v3 v = appm__stand_in_sky(
                appm__v((float)(sin(th) * sin(ph)), (float)cos(th), (float)(-sin(th) * cos(ph))));
            float *t = sky + 3 * ((size_t)k * w + x);
            t[0] = v.x;
            t[1] = v.y;
            t[2] = v.z;
        }
    L->stand_in = 1;
    return APPM_OK;
}

/* Loader arrays -> scene: exact-size copies, bounds, BVH, lights, camera. */
static appm_status appm__scene_finish(appm_scene *s, appm__loader *L, const char *name)
{
    int ok = 1;
    uint32_t i;
    appm__bbox bb, model;
    appm_status st;
    if (L->tri.count == 0 && L->lights.count == 0)
        return appm__fail(L->diag, APPM_ERR_PARSE, name, 0, "the scene has no triangles");
    appm__bbox_empty(&model);
    for (i = 0; i < L->tri.count; ++i) {
        const appm__tri *t = (const appm__tri *)L->tri.data + i;
        appm__bbox_grow(&model, t->p0);
        appm__bbox_grow(&model, t->p1);
        appm__bbox_grow(&model, t->p2);
    }
    if (L->bare_obj && L->lights.count == 0 && L->tri.count > 0) {
        uint32_t emissive = 0;
        for (i = 0; i < L->info.count; ++i)
            emissive += ((const appm__material *)L->mat.data)[((const appm__tri_info *)L->info.data)[i].mat].emissive;
        if (!emissive && L->white) L->stand_in = 1;
        else if (!emissive && (st = appm__stand_in(L, model.lo, model.hi)) != APPM_OK) return st;
    }
    s->ntri = (uint32_t)L->tri.count;
    s->nnormals = (uint32_t)L->nrm.count;
    s->nmat = (uint32_t)L->mat.count;
    s->tri = (appm__tri *)appm__take(&s->mem, &L->tri, &ok);
    s->info = (appm__tri_info *)appm__take(&s->mem, &L->info, &ok);
    s->normals = (appm__v3 *)appm__take(&s->mem, &L->nrm, &ok);
    s->mat = (appm__material *)appm__take(&s->mem, &L->mat, &ok);
    s->uv = (float *)appm__take(&s->mem, &L->uv, &ok);
    if (!ok) return APPM_ERR_NOMEM;
    if ((s->tex = (appm__texture *)appm__take(&s->mem, &L->tex, &ok)) != NULL) {
        s->ntex = (uint32_t)L->tex.count;
        L->tex.count = 0; /* the scene owns the samples now */
    }
    if (!ok) return APPM_ERR_NOMEM;
    for (i = 0; i < s->ntex; ++i)
        if (s->tex[i].px.data)
            s->tex_bytes += (uint64_t)s->tex[i].px.w * s->tex[i].px.h * s->tex[i].px.channels * (s->tex[i].px.depth / 8);
    for (i = 0; i < s->nmat; ++i) s->cutouts |= s->mat[i].map_d != 0;
    s->dropped = L->dropped;
    appm__bbox_empty(&bb);
    for (i = 0; i < s->ntri; ++i) {
        appm__bbox_grow(&bb, s->tri[i].p0);
        appm__bbox_grow(&bb, s->tri[i].p1);
        appm__bbox_grow(&bb, s->tri[i].p2);
    }
    if (s->ntri == 0) bb.lo = bb.hi = appm__v(0, 0, 0);
    s->bmin = bb.lo;
    s->bmax = bb.hi;
    s->center = appm__scale(appm__add(bb.lo, bb.hi), 0.5f);
    s->radius = 0.5f * appm__length(appm__sub(bb.hi, bb.lo));
    if (L->stand_in && !L->white) { /* the studio's photons are aimed at its model (6.3) */
        s->focus = appm__scale(appm__add(model.lo, model.hi), 0.5f);
        s->focus_r = 0.5f * appm__length(appm__sub(model.hi, model.lo));
        appm__plate_of(model.lo, model.hi, &s->plate, &s->plate_e);
    }
    if ((st = appm__bvh_build(s, L->diag)) != APPM_OK) return st;
    if ((st = appm__open_edges(s)) != APPM_OK) return st;
    if ((st = appm__scene_lights(s, L, name)) != APPM_OK) return st;
    if (!L->have_camera) { /* frame the bounding sphere, looking along -z (the studio's: from 20 degrees above) */
        int studio = L->stand_in && !L->white;
        appm__v3 mc = studio ? appm__scale(appm__add(model.lo, model.hi), 0.5f) : s->center;
        float mr = studio ? 0.5f * appm__length(appm__sub(model.hi, model.lo)) : s->radius;
        float rad = mr > 0.0f ? mr : 1.0f;
        float dist = rad / (float)sin(0.5 * 40.0 * APPM__PI / 180.0) * 1.05f;
        appm__v3 dir = studio ? appm__v(0.0f, 0.34202014f, 0.93969262f) : appm__v(0, 0, 1);
        appm__v3 eye = appm__add(mc, appm__scale(dir, dist));
        L->file = name;
        if ((st = appm__camera_set(L, 0, eye, mc, appm__v(0, 1, 0), 40.0)) != APPM_OK) return st;
        L->cam.framed = 1;
    }
    s->cam = L->cam;
    s->width = L->width ? L->width : 512;
    s->height = L->height ? L->height : 512;
    return APPM_OK;
}

static void appm__loader_init(appm__loader *L, appm__mem *m, const appm_config *cfg, appm_diag *diag)
{
    memset(L, 0, sizeof *L);
    L->mem = m;
    L->diag = diag;
    if (cfg) {
        L->log = cfg->log;
        L->log_user = cfg->log_user;
        L->missing_warn = cfg->missing_textures == APPM_MISSING_TEXTURES_WARN;
        L->white = cfg->stand_in == APPM_STAND_IN_WHITE;
    }
    appm__array_init(&L->pos, sizeof(appm__v3));
    appm__array_init(&L->vn, sizeof(appm__v3));
    appm__array_init(&L->nrm, sizeof(appm__v3));
    appm__array_init(&L->tri, sizeof(appm__tri));
    appm__array_init(&L->info, sizeof(appm__tri_info));
    appm__array_init(&L->mat, sizeof(appm__material));
    appm__array_init(&L->names, 1);
    appm__array_init(&L->face, 3 * sizeof(int64_t));
    appm__array_init(&L->vt, 2 * sizeof(float));
    appm__array_init(&L->uv, 2 * sizeof(float));
    appm__array_init(&L->tex, sizeof(appm__texture));
    appm__array_init(&L->lights, sizeof(appm__light));
}

/* A loader ready to read `file`, with material 0, the default diffuse, in place. */
static appm_status appm__loader_begin(appm__loader *L, appm__mem *m, const appm_config *cfg,
                                      appm_diag *diag, const char *file)
{
    appm__material *def;
    appm__loader_init(L, m, cfg, diag);
    L->file = file;
    def = (appm__material *)appm__array_push(m, &L->mat);
    if (!def || !appm__array_push(m, &L->names)) return APPM_ERR_NOMEM;
    def->kind = APPM__MAT_DIFFUSE;
    def->color = appm__v(0.8f, 0.8f, 0.8f);
    def->ior = 1.5f;
    return APPM_OK;
}

enum { APPM__TEXT_NONE = 0, APPM__TEXT_OBJ, APPM__TEXT_SCENE };

/* Shadow rays a shading point of the eye pass sends to the lights that table 0
 * picks among (area and environment lights, point and spot lights past the
 * APPM__NEE_DELTA that get their own): none without any, APPM__SKY_SAMPLES while
 * the studio's sky lights the scene (env_auto 2: appm__direct), else one. */
#define APPM__SKY_SAMPLES 4u /* the studio's sky (appm__direct); 2, 3, 8: 1.05x, 1.02x, 1.05x the RMSE at 10 s */
static unsigned appm__nee_samples(const appm_scene *s)
{
    if (!s->nee_cdf[0] || !(s->nee_cdf[0][s->nlight] > 0.0)) return 0u; /* no light table: no lights */
    return s->env_auto == 2 ? APPM__SKY_SAMPLES : 1u;
}

/* Common path of the public loaders.  text_kind NONE: read `path` (a .scene or
 * a .obj); OBJ or SCENE: parse `text` (named `path` in messages) instead.
 * files (SCENE only): the texts its meshes and material libraries name, instead
 * of files on disk (NULL: read from disk). */
static appm_status appm__scene_load(const char *path, int text_kind, const char *text, size_t text_len,
                                    const char *mtl, size_t mtl_len, const appm_memory_file *files,
                                    size_t nfiles, const appm_config *cfg, appm_scene **out, appm_diag *diag)
{
    appm__mem m;
    appm__loader L;
    appm_scene *s;
    appm_status st;
    appm_diag local;
    if (!diag) diag = &local;
    appm__diag_clear(diag);
    if (!out) return appm__fail(diag, APPM_ERR_INVALID_ARG, path, 0, "no output pointer");
    *out = NULL;
    if (!path) return appm__fail(diag, APPM_ERR_INVALID_ARG, NULL, 0, "no scene path");
    appm__mem_init(&m, cfg);
    m.diag = diag;
    s = (appm_scene *)appm__alloc(&m, 1, sizeof *s);
    if (!s) return APPM_ERR_NOMEM;
    st = appm__loader_begin(&L, &m, cfg, diag, path);
    L.mem_mtl = mtl;
    L.mem_mtl_len = mtl ? mtl_len : 0;
    L.files = files;
    L.nfiles = files ? nfiles : 0;
    appm__copy_str(s->name, sizeof s->name, path);
    if (st == APPM_OK) {
        if (text_kind == APPM__TEXT_OBJ) {
            L.bare_obj = 1;
            st = appm__obj_parse(&L, text, text_len, path);
        } else if (text_kind == APPM__TEXT_SCENE) {
            st = appm__scene_parse(&L, text, text_len, path);
        } else if (appm__ends_with(path, ".obj")) {
            L.file = NULL;
            L.bare_obj = 1;
            st = appm__obj_load(&L, path, 0);
        } else {
            char *buf;
            size_t len;
            st = appm__read_file(&m, path, &buf, &len, diag);
            if (st == APPM_OK) {
                st = appm__scene_parse(&L, buf, len, path);
                appm__free(&m, buf);
            }
        }
        if (st == APPM_OK) {
            s->mem = m; /* from here on the scene's own counter tracks its blocks, the loader's too */
            L.mem = &s->mem;
            st = appm__scene_finish(s, &L, path);
            m = s->mem;
            L.mem = &m;
        }
    }
    if (st == APPM_ERR_NOMEM) appm__fail(diag, APPM_ERR_NOMEM, path, 0, "out of memory loading the scene");
    appm__loader_free(&L);
    if (st != APPM_OK) {
        appm__scene_free_parts(&m, s);
        appm__free(&m, s);
        return st;
    }
    m.diag = NULL;
    s->mem = m;
    *out = s;
    return APPM_OK;
}

APPM_API appm_status appm_scene_load(const char *path, const appm_config *cfg, appm_scene **out,
                                     appm_diag *diag)
{
    return appm__scene_load(path, APPM__TEXT_NONE, NULL, 0, NULL, 0, NULL, 0, cfg, out, diag);
}

APPM_API appm_status appm_scene_load_obj_memory(const char *obj, size_t obj_len, const char *mtl,
                                                size_t mtl_len, const char *name,
                                                const appm_config *cfg, appm_scene **out,
                                                appm_diag *diag)
{
    if (!obj) {
        appm__diag_clear(diag);
        if (out) *out = NULL;
        return appm__fail(diag, APPM_ERR_INVALID_ARG, name, 0, "no OBJ text");
    }
    return appm__scene_load(name ? name : "(memory)", APPM__TEXT_OBJ, obj, obj_len, mtl, mtl_len, NULL, 0, cfg,
                            out, diag);
}

APPM_API appm_status appm_scene_load_memory(const char *scene, size_t scene_len, const char *name,
                                            const appm_memory_file *files, size_t nfiles,
                                            const appm_config *cfg, appm_scene **out, appm_diag *diag)
{
    static const appm_memory_file none = {NULL, NULL, 0};
    if (!scene || (!files && nfiles)) {
        appm__diag_clear(diag);
        if (out) *out = NULL;
        return appm__fail(diag, APPM_ERR_INVALID_ARG, name, 0, scene ? "no files" : "no scene text");
    }
    return appm__scene_load(name ? name : "(memory)", APPM__TEXT_SCENE, scene, scene_len, NULL, 0,
                            files ? files : &none, files ? nfiles : 0, cfg, out, diag);
}

APPM_API void appm_scene_destroy(appm_scene *scene)
{
    appm__mem m;
    if (!scene) return;
    m = scene->mem;
    appm__scene_free_parts(&m, scene);
    appm__free(&m, scene);
}

APPM_API void appm_scene_get_info(const appm_scene *s, appm_scene_info *info)
{
    uint32_t i;
    if (!info) return;
    memset(info, 0, sizeof *info);
    if (!s) return;
    info->triangles = s->ntri;
    info->dropped_triangles = s->dropped;
    info->open_edges = s->nopen;
    for (i = 0; i < s->nmat; ++i) {
        const appm__material *m = &s->mat[i];
        if (i == 0) { /* the implicit default counts only if some face uses it */
            uint32_t k;
            for (k = 0; k < s->ntri && s->info[k].mat != 0; ++k) {
            }
            if (k == s->ntri) continue;
        }
        info->materials_diffuse += m->kind == APPM__MAT_DIFFUSE;
        info->materials_mirror += m->kind == APPM__MAT_MIRROR;
        info->materials_dielectric += m->kind == APPM__MAT_DIELECTRIC;
        info->materials_glossy += m->kind == APPM__MAT_GLOSSY;
        info->materials_emissive += m->emissive;
    }
    for (i = 0; i < s->nlight; ++i) {
        const appm__light *l = &s->light[i];
        double *p = l->kind == APPM__LIGHT_AREA    ? info->power_area
                    : l->kind == APPM__LIGHT_POINT ? info->power_point
                    : l->kind == APPM__LIGHT_SPOT  ? info->power_spot
                                                   : info->power_environment;
        info->lights_area += l->kind == APPM__LIGHT_AREA;
        info->lights_point += l->kind == APPM__LIGHT_POINT;
        info->lights_spot += l->kind == APPM__LIGHT_SPOT;
        info->lights_environment += l->kind == APPM__LIGHT_ENV;
        info->shadow_rays_own += (uint32_t)l->nee_all;
        info->shadow_rays_picked += l->nee[0] > 0.0;
        p[0] += l->power[0];
        p[1] += l->power[1];
        p[2] += l->power[2];
    }
    info->shadow_rays_samples = appm__nee_samples(s);
    info->bbox_min[0] = s->bmin.x;
    info->bbox_min[1] = s->bmin.y;
    info->bbox_min[2] = s->bmin.z;
    info->bbox_max[0] = s->bmax.x;
    info->bbox_max[1] = s->bmax.y;
    info->bbox_max[2] = s->bmax.z;
    info->bvh_nodes = s->nwnode; /* the wide tree the renderer traverses */
    info->bvh_depth = s->wdepth;
    info->width = s->width;
    info->height = s->height;
    info->memory_bytes = s->mem.live;
    info->peak_bytes = s->mem.peak;
    for (i = 0; i < s->ntex; ++i) info->textures += s->tex[i].px.data != NULL;
    info->texture_bytes = s->tex_bytes;
    info->materials_cutout = 0;
    for (i = 0; i < s->nmat; ++i) info->materials_cutout += s->mat[i].map_d != 0;
    info->environment_map_width = s->envmap.rgb ? s->envmap.w : 0;
    info->environment_map_height = s->envmap.rgb ? s->envmap.h : 0;
}

/* Lights added to a loaded scene.  The light arrays are rebuilt one entry
 * larger (or smaller), through the scene's own allocator, and the choice table
 * is recomputed; the arrays are untouched when the call fails.  `drop` is the
 * index of a light to leave out (-1: none), `add` the light to append (NULL:
 * none). */
static appm_status appm__scene_relight(appm_scene *s, int drop, const appm__light *add, appm_diag *diag)
{
    uint32_t n = s->nlight - (drop >= 0) + (add != NULL), i, k = 0;
    appm__mem *m = &s->mem;
    appm__light *nl;
    double *cdf;
    appm__light *old = s->light;
    double *old_cdf = s->light_cdf;
    uint32_t old_n = s->nlight;
    int old_env = s->env;
    appm_status st;
    if (n == 0) return appm__fail(diag, APPM_ERR_INVALID_ARG, s->name, 0, "the scene would have no light");
    m->diag = diag;
    nl = (appm__light *)appm__alloc(m, n, sizeof *nl);
    cdf = (double *)appm__alloc(m, 3 * ((size_t)n + 1), sizeof *cdf);
    m->diag = NULL;
    if (!nl || !cdf) {
        appm__free(m, nl);
        appm__free(m, cdf);
        return APPM_ERR_NOMEM;
    }
    s->env = -1;
    for (i = 0; i < old_n; ++i) {
        if ((int)i == drop) continue;
        if (old[i].kind == APPM__LIGHT_ENV) s->env = (int)k;
        nl[k++] = old[i]; /* area lights come first and are never dropped: triangle indices hold */
    }
    if (add) {
        nl[k] = *add;
        appm__light_power(s, &nl[k], nl[k].power);
        if (add->kind == APPM__LIGHT_ENV) s->env = (int)k;
        k++;
    }
    s->light = nl;
    s->light_cdf = cdf;
    s->nlight = k;
    if ((st = appm__light_table(s, diag, s->name)) != APPM_OK) {
        s->light = old;
        s->light_cdf = old_cdf;
        s->nlight = old_n;
        s->env = old_env;
        appm__free(m, nl);
        appm__free(m, cdf);
        return st;
    }
    appm__free(m, old);
    appm__free(m, old_cdf);
    return APPM_OK;
}

static int appm__finite_nonneg3(const double *v)
{
    int i;
    for (i = 0; i < 3; ++i)
        if (!(v[i] >= 0.0 && v[i] <= FLT_MAX)) return 0;
    return 1;
}

APPM_API appm_status appm_scene_add_point_light(appm_scene *scene, const double position[3],
                                                const double intensity[3], appm_diag *diag)
{
    appm__light l;
    appm_status st;
    int i, drop;
    appm__diag_clear(diag);
    if (!scene || !position || !intensity)
        return appm__fail(diag, APPM_ERR_INVALID_ARG, NULL, 0, "no scene or light");
    for (i = 0; i < 3; ++i)
        if (!(fabs(position[i]) <= FLT_MAX))
            return appm__fail(diag, APPM_ERR_INVALID_ARG, scene->name, 0, "point light: position is not finite");
    if (!appm__finite_nonneg3(intensity))
        return appm__fail(diag, APPM_ERR_INVALID_ARG, scene->name, 0,
                          "point light: intensity must be finite and >= 0");
    memset(&l, 0, sizeof l);
    l.kind = APPM__LIGHT_POINT;
    l.pos = appm__v((float)position[0], (float)position[1], (float)position[2]);
    l.value = appm__v((float)intensity[0], (float)intensity[1], (float)intensity[2]);
    drop = scene->env_auto ? scene->env : -1;
    st = appm__scene_relight(scene, drop, &l, diag);
    if (st == APPM_OK && drop >= 0) appm__envmap_free(&scene->mem, &scene->envmap); /* the stand-in's sky */
    if (st == APPM_OK) scene->env_auto = 0;
    return st;
}

/* The environment becomes light l, with map *map (NULL: a constant one),
 * replacing the one there, if any; on failure the scene is as it was. */
static appm_status appm__scene_set_env(appm_scene *s, const appm__light *l, const appm__envmap *map, appm_diag *diag)
{
    appm__envmap old = s->envmap;
    appm_status st;
    if (map) s->envmap = *map; /* the new light's power (appm__light_power) reads it */
    else memset(&s->envmap, 0, sizeof s->envmap);
    st = appm__scene_relight(s, s->env, l, diag);
    if (st != APPM_OK) {
        s->envmap = old;
        return st;
    }
    appm__envmap_free(&s->mem, &old);
    s->env_auto = 0;
    return APPM_OK;
}

APPM_API appm_status appm_scene_set_environment(appm_scene *scene, const double radiance[3],
                                                appm_diag *diag)
{
    appm__light l;
    appm__diag_clear(diag);
    if (!scene || !radiance) return appm__fail(diag, APPM_ERR_INVALID_ARG, NULL, 0, "no scene or radiance");
    if (!appm__finite_nonneg3(radiance))
        return appm__fail(diag, APPM_ERR_INVALID_ARG, scene->name, 0,
                          "environment: radiance must be finite and >= 0");
    memset(&l, 0, sizeof l);
    l.kind = APPM__LIGHT_ENV;
    l.value = appm__v((float)radiance[0], (float)radiance[1], (float)radiance[2]);
    return appm__scene_set_env(scene, &l, NULL, diag);
}

APPM_API appm_status appm_scene_set_environment_map(appm_scene *scene, const char *path, double scale,
                                                    double rotate_degrees, const appm_config *cfg,
                                                    appm_diag *diag)
{
    appm__light l;
    appm__envmap from, map;
    appm__mem *m;
    appm_file_reader saved;
    char *buf;
    size_t len;
    appm_status st;
    appm__diag_clear(diag);
    if (!scene || !path) return appm__fail(diag, APPM_ERR_INVALID_ARG, NULL, 0, "no scene or path");
    if (!(scale >= 0.0 && scale <= 1e30) || !(fabs(rotate_degrees) <= 1e6))
        return appm__fail(diag, APPM_ERR_INVALID_ARG, path, 0,
                          "environment map: scale must be in [0, 1e30] and rotate in [-1e6, 1e6] degrees");
    m = &scene->mem;
    m->diag = diag;
    saved = m->reader;
    m->reader.read = cfg && cfg->reader.read ? cfg->reader.read : NULL; /* this call's reader, not the load's */
    m->reader.release = cfg && cfg->reader.read ? cfg->reader.release : NULL;
    m->reader.user = cfg && cfg->reader.read ? cfg->reader.user : NULL;
    memset(&from, 0, sizeof from);
    memset(&map, 0, sizeof map);
    from.scale = scale;
    from.rotate = rotate_degrees;
    st = appm__read_file(m, path, &buf, &len, diag);
    if (st == APPM_OK) {
        st = appm__image_decode(m, (const unsigned char *)buf, len, path, &from.px, diag);
        appm__free(m, buf);
    }
    if (st == APPM_OK) st = appm__envmap_take(m, &map, &from, path, diag);
    m->diag = NULL;
    m->reader = saved;
    if (st != APPM_OK) {
        appm__envmap_free(m, &map);
        return st;
    }
    memset(&l, 0, sizeof l);
    l.kind = APPM__LIGHT_ENV;
    l.value = appm__v((float)scale, (float)scale, (float)scale);
    st = appm__scene_set_env(scene, &l, &map, diag);
    if (st != APPM_OK) appm__envmap_free(m, &map);
    return st;
}

/* ==== 7. PHOTONS AND THE HASH-GRID PHOTON MAP ==============================
 *
 * What a photon path leaves on a surface (section 9 traces the paths) and the
 * map that finds the photons near a point (section 10 gathers them).  Neither
 * needs a renderer: the tests build maps from photons of their own.  A photon
 * is 32 bytes: its position, its weight gamma, and its incident direction and
 * normal packed as octahedral coordinates (7.1); the map is a hashed uniform
 * grid rebuilt every pass (7.2).
 */

typedef struct appm__photon { /* 32 bytes */
    float x, y, z;
    float power[3];  /* gamma: flux of the path, before dividing by M */
    int16_t wi[2];   /* incident direction (towards where it came from), octahedral */
    int8_t n[2];     /* geometric normal on the side it arrived from, octahedral */
    uint8_t segs;    /* light-path segments from the light to here */
    uint8_t comp;    /* photon component (section 10): APPM__COMP_CAUSTIC if the last
                      * bounce before it was stored was specular (L S+ D), else 0 */
} appm__photon;

/* Photon components: appm keeps statistics and a radius per component. */
#define APPM__COMP_DIFFUSE 0
#define APPM__COMP_CAUSTIC 1
#define APPM__NCOMP 2

/* ---- 7.1 Octahedral unit vectors (Cigolle et al. 2014) ---------------------- */

static void appm__oct_encode(appm__v3 v, float *a, float *b)
{
    float s = fabsf(v.x) + fabsf(v.y) + fabsf(v.z), x, y;
    if (!(s > 0.0f)) {
        *a = *b = 0.0f;
        return;
    }
    x = v.x / s;
    y = v.y / s;
    if (v.z < 0.0f) {
        float ox = x, oy = y;
        x = (1.0f - fabsf(oy)) * (ox >= 0.0f ? 1.0f : -1.0f);
        y = (1.0f - fabsf(ox)) * (oy >= 0.0f ? 1.0f : -1.0f);
    }
    *a = x;
    *b = y;
}

/* Rounds a value in [-1, 1] to a signed integer of the given scale, clamping
 * before the conversion (float-to-int of an out-of-range value is undefined). */
static int appm__quant(float v, float scale)
{
    float q = v * scale;
    q = q > scale ? scale : (q < -scale ? -scale : q);
    return (int)(q >= 0.0f ? q + 0.5f : q - 0.5f);
}

/* The inverse of appm__oct_encode before normalisation: (a, b) in [-1, 1]^2 ->
 * a vector with |x| + |y| + |z| = 1 along the encoded direction. */
static appm__v3 appm__oct_unpack(float a, float b)
{
    float z = 1.0f - fabsf(a) - fabsf(b);
    if (z < 0.0f) {
        float t = a;
        a = (1.0f - fabsf(b)) * (t >= 0.0f ? 1.0f : -1.0f);
        b = (1.0f - fabsf(t)) * (b >= 0.0f ? 1.0f : -1.0f);
    }
    return appm__v(a, b, z);
}

#define APPM__NORMAL_COS 0.5f /* the gather's same-surface test: normals within 60 degrees */
/* the covered test's (10.6): normals within 1.5 degrees, cos^2 1.5 deg / c^2 of out[3] below */
#define APPM__COVER_SIDE (0.999315f / (APPM__NORMAL_COS * APPM__NORMAL_COS))

/* A photon's stored directions as unit vectors: wi (towards where it came
 * from, 16 bits per coordinate: about 3e-5 rad), which the glossy gather reads
 * (10), and the normal on its side (8 bits: about 1e-2 rad); the diffuse
 * gather tests the normal without normalising. */
/* The same-surface test's view of a photon (section 10): out[0..2] its normal
 * decoded without normalisation, out[3] = c^2 |n|^2 with c = APPM__NORMAL_COS
 * (cos 60 deg, so c^2 = 1/4 exactly). */
static void appm__photon_side(const appm__photon *p, float *out)
{
    appm__v3 pn = appm__oct_unpack((float)p->n[0] * (1.0f / 127.0f), (float)p->n[1] * (1.0f / 127.0f));
    out[0] = pn.x;
    out[1] = pn.y;
    out[2] = pn.z;
    out[3] = APPM__NORMAL_COS * APPM__NORMAL_COS * appm__dot(pn, pn);
}

static appm__v3 appm__photon_wi(const appm__photon *p)
{
    return appm__normalize(appm__oct_unpack((float)p->wi[0] * (1.0f / 32767.0f), (float)p->wi[1] * (1.0f / 32767.0f)));
}

APPM__UNUSED static appm__v3 appm__photon_normal(const appm__photon *p)
{
    return appm__normalize(appm__oct_unpack((float)p->n[0] * (1.0f / 127.0f), (float)p->n[1] * (1.0f / 127.0f)));
}

typedef struct appm__chunk_rec { /* where one chunk of photon paths left its photons */
    uint32_t start, count;
} appm__chunk_rec;

/* The photon map of one pass (7.2): the photons sorted by hash bucket
 * and the table of bucket starts.  It borrows the photons (the renderer's
 * store, or any array) and owns only its table, so it can be built and
 * queried without a renderer. */
typedef struct appm__pmap {
    appm__photon *ph;  /* borrowed; photons [cell[b], cell[b+1]) lie in bucket b */
    size_t n;          /* photons in the map */
    uint32_t *cell;    /* 2^bits + 1 bucket starts */
    float *bbox;       /* per bucket its photons' bounding box, lo xyz then hi xyz (7.2) */
    size_t cell_cap;   /* entries allocated (the largest table so far: memory stays flat) */
    uint32_t bits;     /* log2 of the number of buckets */
    float cell_size, inv_cell;
    appm__v3 lo;       /* the grid's origin: the photons' bounding-box corner */
    float *hot;        /* the positions again, in map order, as three arrays x[cap], y[cap], z[cap]:
                        * all a query's distance test reads, contiguous (7.2) */
    float *side;       /* per photon, in map order: its normal n decoded (not normalised) and
                        * c^2 |n|^2 (c = APPM__NORMAL_COS), what the same-surface test reads */
    size_t hot_cap;    /* photons hot[] and side[] have room for (only grow: memory stays flat) */
    uint32_t *tag;     /* borrowed, NULL or one per photon: permuted with them by the build */
} appm__pmap;

#define APPM__CELL_SCALE 2.0f /* grid cell = this times the median gather radius (speed only) */

/* ---- 7.2 The hash grid ---------------------------------------------------------
 *
 * A uniform grid of cubic cells of size c, hashed into 2^k buckets (k chosen
 * so there are at least as many buckets as photons).  Built every pass by a
 * counting sort: (1) hash every photon, count per bucket; (2) prefix sums give
 * each bucket's start; (3) each photon's destination, assigned in chunk order;
 * (4) the photons are permuted in place by following cycles.  After the build,
 * photons[cell[b] .. cell[b+1]) are exactly those of bucket b, in chunk order.
 *
 * A query for radius R visits every cell overlapping the box [x-R, x+R], so R
 * may be larger than c (adaptive radii vary per pixel).  Distinct cells can
 * share a bucket; a bucket is read once per query: small queries deduplicate
 * their buckets, large ones accept a photon only in the cell it belongs to.
 * The cell size is twice the median gather reach of the pass (1x and 1.5x,
 * 3x and 4x were measured: more instructions per gather); which photons a
 * query finds never depends on it, only speed does.
 *
 * The gather's cost is mostly the distance test of photons that turn out to
 * lie outside R (on the sphere box about 12 tested per photon found), so the
 * build (5) keeps, beside the 32-byte records, what that test reads: the
 * positions as three float arrays in map order (hot[], 4-wide SSE compares
 * over a bucket's contiguous photons), a bounding box per bucket (a bucket
 * wholly beyond R is passed over unread), and each photon's decoded normal
 * (side[], read by the gather's same-surface test).  None of this changes
 * which photons are visited, in what order, or the float d2 handed to the
 * visitor: images are bit-identical to a plain loop over the records.
 *
 * Cell coordinates are clamped in float before the conversion to int32 (NaN
 * and huge values would be undefined behaviour), and hashed as uint32 (signed
 * overflow in the classic "x * 73856093" would be undefined behaviour too).
 */
static uint32_t appm__grid_hash(int32_t x, int32_t y, int32_t z, uint32_t bits)
{
    uint32_t h = ((uint32_t)x * 73856093u) ^ ((uint32_t)y * 19349663u) ^ ((uint32_t)z * 83492791u);
    h ^= h >> 15; /* mix the high bits down: the mask keeps only the low ones */
    h *= 0x2C1B3C6Du;
    h ^= h >> 12;
    return h & ((1u << bits) - 1u);
}

static int32_t appm__grid_coord(float p, float lo, float inv_cell)
{
    float c = floorf((p - lo) * inv_cell);
    if (!(c > -1.0e9f)) c = -1.0e9f; /* also catches NaN */
    if (c > 1.0e9f) c = 1.0e9f;
    return (int32_t)c;
}

static uint32_t appm__pmap_bucket(const appm__pmap *m, const appm__photon *p)
{
    return appm__grid_hash(appm__grid_coord(p->x, m->lo.x, m->inv_cell), appm__grid_coord(p->y, m->lo.y, m->inv_cell),
                           appm__grid_coord(p->z, m->lo.z, m->inv_cell), m->bits);
}

/* k-th smallest of a[0..n) (quickselect, reorders a). */
static float appm__select(float *a, size_t n, size_t k)
{
    size_t lo = 0, hi = n - 1;
    while (lo < hi) {
        float pivot = a[lo + (hi - lo) / 2];
        size_t i = lo, j = hi;
        while (i <= j) {
            while (a[i] < pivot) i++;
            while (a[j] > pivot) j--;
            if (i <= j) {
                float t = a[i];
                a[i] = a[j];
                a[j] = t;
                i++;
                if (j == 0) break;
                j--;
            }
        }
        if (k <= j) hi = j;
        else if (k >= i) lo = i;
        else break;
    }
    return a[k];
}

/* Two arrays of n1 items of s1 bytes and n2 of s2 into *a and *b, and the old
 * ones (old_a, old_b) freed: both or neither (0: out of memory, the old ones
 * kept). */
static int appm__pmap_grow(appm__mem *mem, void *old_a, void *old_b, size_t n1, size_t s1, size_t n2, size_t s2,
                           void **a, void **b)
{
    void *x = appm__alloc(mem, n1, s1), *y = x ? appm__alloc(mem, n2, s2) : NULL;
    if (!y) {
        appm__free(mem, x);
        return 0;
    }
    appm__free(mem, old_a);
    appm__free(mem, old_b);
    *a = x;
    *b = y;
    return 1;
}

/* The bucket table for 2^bits = nb buckets (cell[] and bbox[]) and hot[] and
 * side[] for n photons, each grown only when too small, so that memory stays
 * flat.  APPM_ERR_NOMEM leaves the old arrays in place. */
static appm_status appm__pmap_reserve(appm__pmap *m, appm__mem *mem, size_t n, uint32_t nb)
{
    if ((size_t)nb + 1 > m->cell_cap) {
        void *cell, *bbox;
        if (!appm__pmap_grow(mem, m->cell, m->bbox, (size_t)nb + 1, sizeof *m->cell, (size_t)nb * 6, sizeof *m->bbox,
                             &cell, &bbox))
            return APPM_ERR_NOMEM;
        m->cell = (uint32_t *)cell;
        m->bbox = (float *)bbox;
        m->cell_cap = (size_t)nb + 1;
    }
    /* hot[] and side[] are sized with the table (2^bits >= n, bar the cap of
     * 2^30): a pass with a few more photons than the last needs no new ones */
    if (n > m->hot_cap || !m->hot) {
        void *hot, *side;
        size_t cap = n > nb ? n : nb;
        if (!appm__pmap_grow(mem, m->hot, m->side, 3 * cap, sizeof *m->hot, 4 * cap, sizeof *m->side, &hot, &side))
            return APPM_ERR_NOMEM;
        m->hot = (float *)hot;
        m->side = (float *)side;
        m->hot_cap = cap;
    }
    return APPM_OK;
}

/* Steps (1) - (3) of the build: m->cell[0..nb] the buckets' starts and dest[i]
 * the slot of photon i, slots given out walking `runs` in order (NULL: the
 * whole array).  m's grid (lo, inv_cell, bits) must be set. */
static void appm__pmap_slots(appm__pmap *m, const appm__photon *ph, size_t n, uint32_t *dest,
                             const appm__chunk_rec *runs, uint32_t nruns, uint32_t nb)
{
    size_t i, k;
    uint32_t c;
    memset(m->cell, 0, ((size_t)nb + 1) * sizeof *m->cell);
    /* (1) counts, with each photon's bucket kept in dest[] for step (3) */
    for (i = 0; i < n; ++i) {
        uint32_t b = appm__pmap_bucket(m, &ph[i]);
        dest[i] = b;
        m->cell[b + 1]++;
    }
    /* (2) prefix sums: cell[b] = first slot of bucket b */
    for (k = 0; k < nb; ++k) m->cell[k + 1] += m->cell[k];
    /* (3) destinations, assigned walking the runs in order, with cell[] as
     * running cursors; then cell[] is restored */
    if (!runs)
        for (i = 0; i < n; ++i) dest[i] = m->cell[dest[i]]++;
    for (c = 0; runs && c < nruns; ++c)
        for (i = runs[c].start; i < (size_t)runs[c].start + runs[c].count; ++i) dest[i] = m->cell[dest[i]]++;
    for (k = nb; k > 0; --k) m->cell[k] = m->cell[k - 1];
    m->cell[0] = 0;
}

/* Step (4): moves photon i to slot dest[i], in place; each swap puts one photon
 * in its final slot.  dest[] ends as the identity. */
static void appm__pmap_permute(appm__photon *ph, uint32_t *tag, size_t n, uint32_t *dest)
{
    size_t i;
    for (i = 0; i < n; ++i) {
        while (dest[i] != i) {
            uint32_t j = dest[i], tj;
            appm__photon tp = ph[j];
            ph[j] = ph[i];
            ph[i] = tp;
            if (tag) {
                tj = tag[j];
                tag[j] = tag[i];
                tag[i] = tj;
            }
            tj = dest[j];
            dest[j] = j;
            dest[i] = tj;
        }
    }
}

/* Step (5): the query's side arrays from the sorted photons m->ph[0..m->n): the
 * positions (hot[]) and decoded normals (side[]) in map order, then each
 * non-empty bucket's bounding box among the nb (an empty one's is never read). */
static void appm__pmap_side_arrays(appm__pmap *m, uint32_t nb)
{
    const appm__photon *ph = m->ph;
    size_t i, k;
    for (i = 0; i < m->n; ++i) {
        m->hot[i] = ph[i].x;
        m->hot[m->hot_cap + i] = ph[i].y;
        m->hot[2 * m->hot_cap + i] = ph[i].z;
        appm__photon_side(&ph[i], m->side + 4 * i);
    }
    for (k = 0; k < nb; ++k) {
        float *bx = m->bbox + 6 * k;
        size_t e = m->cell[k + 1];
        if ((i = m->cell[k]) == e) continue;
        bx[0] = bx[3] = ph[i].x;
        bx[1] = bx[4] = ph[i].y;
        bx[2] = bx[5] = ph[i].z;
        for (++i; i < e; ++i) {
            if (ph[i].x < bx[0]) bx[0] = ph[i].x;
            if (ph[i].y < bx[1]) bx[1] = ph[i].y;
            if (ph[i].z < bx[2]) bx[2] = ph[i].z;
            if (ph[i].x > bx[3]) bx[3] = ph[i].x;
            if (ph[i].y > bx[4]) bx[4] = ph[i].y;
            if (ph[i].z > bx[5]) bx[5] = ph[i].z;
        }
    }
}

/* Builds map `m` over photons ph[0..n) with cubic cells of size `cell_size` > 0,
 * reordering ph in place.  `dest` is scratch for n entries.  `runs` (NULL: the
 * whole array, in order) lists the stretches of ph in the order the photons
 * must keep within a bucket - the photon pass's chunks in global order, so
 * that sums over a bucket do not depend on the thread count.  Fails only for
 * memory (the bucket table grows when a pass has more photons than any before). */
static appm_status appm__pmap_build(appm__pmap *m, appm__mem *mem, appm__photon *ph, size_t n, uint32_t *dest,
                                    const appm__chunk_rec *runs, uint32_t nruns, float cell_size)
{
    size_t i;
    uint32_t bits = 10, nb;
    appm__bbox bb;
    while (bits < 30 && ((size_t)1 << bits) < n) bits++;
    nb = 1u << bits;
    if (appm__pmap_reserve(m, mem, n, nb) != APPM_OK) return APPM_ERR_NOMEM;
    m->bits = bits;
    m->ph = ph;
    m->n = n;
    appm__bbox_empty(&bb);
    for (i = 0; i < n; ++i) appm__bbox_grow(&bb, appm__v(ph[i].x, ph[i].y, ph[i].z));
    m->lo = n ? bb.lo : appm__v(0, 0, 0);
    m->cell_size = cell_size;
    m->inv_cell = 1.0f / cell_size;
    appm__pmap_slots(m, ph, n, dest, runs, nruns, nb);
    appm__pmap_permute(ph, m->tag, n, dest);
    appm__pmap_side_arrays(m, nb);
    return APPM_OK;
}

/* visit(ctx, p, d2): photon p lies at squared distance d2 < R^2 from the query
 * point, d2 = dx^2 + dy^2 + dz^2 in float with d = x - p, summed left to right
 * (the expression every caller would write, so a visitor needs not redo it). */
typedef void (*appm__pmap_visit)(void *ctx, const appm__photon *p, float d2);

/* Photon i of the map, at squared distance d2 < R^2: visited unless `cx` is
 * non-NULL and names a cell other than its own (several cells can share a
 * bucket). */
static inline void appm__pmap_accept(const appm__pmap *m, size_t i, float d2, const int32_t *cx,
                                     appm__pmap_visit visit, void *ctx)
{
    const float *hx = m->hot, *hy = hx + m->hot_cap, *hz = hy + m->hot_cap;
    if (cx && (appm__grid_coord(hx[i], m->lo.x, m->inv_cell) != cx[0] ||
               appm__grid_coord(hy[i], m->lo.y, m->inv_cell) != cx[1] ||
               appm__grid_coord(hz[i], m->lo.z, m->inv_cell) != cx[2]))
        return;
    visit(ctx, &m->ph[i], d2);
}

/* The photons i in [i0, i1) of the map that lie within R of x (R2 = R^2), in
 * index order.  The distance test reads only the hot position arrays, where a
 * bucket's photons are contiguous; 4 at a time with SSE (each lane computes
 * the scalar expression's exact float value: no contraction, same order), the
 * rest one by one. */
static void appm__pmap_range(const appm__pmap *m, size_t i0, size_t i1, const int32_t *cx, appm__v3 x, float R2,
                             appm__pmap_visit visit, void *ctx)
{
    const float *hx = m->hot, *hy = hx + m->hot_cap, *hz = hy + m->hot_cap;
    size_t i = i0;
#if defined(APPM__SSE)
    if (i1 - i0 >= 4) {
        const __m128 qx = _mm_set1_ps(x.x), qy = _mm_set1_ps(x.y), qz = _mm_set1_ps(x.z), r2 = _mm_set1_ps(R2);
        for (; i + 4 <= i1; i += 4) {
            __m128 dx = _mm_sub_ps(qx, _mm_loadu_ps(hx + i)), dy = _mm_sub_ps(qy, _mm_loadu_ps(hy + i));
            __m128 dz = _mm_sub_ps(qz, _mm_loadu_ps(hz + i));
            __m128 d2 = _mm_add_ps(_mm_add_ps(_mm_mul_ps(dx, dx), _mm_mul_ps(dy, dy)), _mm_mul_ps(dz, dz));
            /* lowest set bit of a 4-bit mask */
            static const unsigned char low[16] = {0, 0, 1, 0, 2, 0, 1, 0, 3, 0, 1, 0, 2, 0, 1, 0};
            unsigned mask = (unsigned)_mm_movemask_ps(_mm_cmplt_ps(d2, r2));
            float d[4];
            if (!mask) continue;
            _mm_storeu_ps(d, d2);
            for (; mask; mask &= mask - 1u) appm__pmap_accept(m, i + low[mask], d[low[mask]], cx, visit, ctx);
        }
    }
#endif
    for (; i < i1; ++i) {
        float dx = x.x - hx[i], dy = x.y - hy[i], dz = x.z - hz[i], d2 = dx * dx + dy * dy + dz * dz;
        if (d2 < R2) appm__pmap_accept(m, i, d2, cx, visit, ctx);
    }
}

/* Whether bounding box bb (lo xyz, hi xyz) holds no point within R of x
 * (R2 = R^2), tested so that it never rejects a photon the query would
 * accept: with c the point of the box nearest x and d = x - c in float, each
 * |x - y| of a photon y in the box, rounded, is at least |d| in its axis
 * (rounding is monotone), and so is the sum of squares; d^2 >= R^2 rules out
 * every photon.  A NaN x is far from every box, as it is from every photon. */
static int appm__pmap_far(const float *bb, appm__v3 x, float R2)
{
    float cx = x.x < bb[0] ? bb[0] : (x.x > bb[3] ? bb[3] : x.x);
    float cy = x.y < bb[1] ? bb[1] : (x.y > bb[4] ? bb[4] : x.y);
    float cz = x.z < bb[2] ? bb[2] : (x.z > bb[5] ? bb[5] : x.z);
    float dx = x.x - cx, dy = x.y - cy, dz = x.z - cz;
    return !(dx * dx + dy * dy + dz * dz < R2);
}

/* Calls visit(ctx, p, d2) once for every photon p with d2 = |x - p|^2 < R^2, in
 * map order (bucket by bucket, chunk order within a bucket).  Visits every cell
 * overlapping the box [x - R, x + R]; a query larger than the grid itself
 * scans the array instead. */
static void appm__pmap_query(const appm__pmap *m, appm__v3 x, float R, appm__pmap_visit visit, void *ctx)
{
    float R2 = R * R;
    int32_t lo[3], hi[3], cc[3];
    double ncells;
    uint32_t seen[27];
    uint64_t seen_bits = 0; /* bit (b mod 64) of every bucket in seen[]: most buckets need no scan of it */
    int nseen = 0, check;
    if (m->n == 0) return;
    lo[0] = appm__grid_coord(x.x - R, m->lo.x, m->inv_cell);
    lo[1] = appm__grid_coord(x.y - R, m->lo.y, m->inv_cell);
    lo[2] = appm__grid_coord(x.z - R, m->lo.z, m->inv_cell);
    hi[0] = appm__grid_coord(x.x + R, m->lo.x, m->inv_cell);
    hi[1] = appm__grid_coord(x.y + R, m->lo.y, m->inv_cell);
    hi[2] = appm__grid_coord(x.z + R, m->lo.z, m->inv_cell);
    ncells = ((double)hi[0] - lo[0] + 1) * ((double)hi[1] - lo[1] + 1) * ((double)hi[2] - lo[2] + 1);
    if (ncells > (double)m->n || ncells > (double)(1u << m->bits)) {
        appm__pmap_range(m, 0, m->n, NULL, x, R2, visit, ctx);
        return;
    }
    /* small queries read each bucket once (deduplicated); large ones accept a
     * photon only in the cell it belongs to.  Empty buckets are passed over
     * before either. */
    check = ncells > 27.0;
    for (cc[2] = lo[2]; cc[2] <= hi[2]; ++cc[2])
        for (cc[1] = lo[1]; cc[1] <= hi[1]; ++cc[1])
            for (cc[0] = lo[0]; cc[0] <= hi[0]; ++cc[0]) {
                uint32_t b = appm__grid_hash(cc[0], cc[1], cc[2], m->bits);
                size_t i0 = m->cell[b], i1 = m->cell[b + 1];
                if (i0 == i1 || appm__pmap_far(m->bbox + 6 * (size_t)b, x, R2)) continue;
                if (!check) {
                    uint64_t bit = (uint64_t)1 << (b & 63u);
                    if (seen_bits & bit) {
                        int k, dup = 0;
                        for (k = 0; k < nseen; ++k) dup |= seen[k] == b;
                        if (dup) continue;
                    }
                    seen_bits |= bit;
                    seen[nseen++] = b;
                }
                appm__pmap_range(m, i0, i1, check ? cc : NULL, x, R2, visit, ctx);
            }
}

static void appm__pmap_free(appm__pmap *m, appm__mem *mem)
{
    appm__free(mem, m->cell);
    appm__free(mem, m->bbox);
    appm__free(mem, m->hot);
    appm__free(mem, m->side);
    m->cell = NULL;
    m->bbox = m->hot = m->side = NULL;
    m->cell_cap = m->hot_cap = 0;
}

/* ==== 8. THE RENDERER AND THE EYE PASS ===================================
 *
 * The renderer's state is declared first, since every later section uses it:
 * per pixel the visible point of the pass (appm__vp), what every method keeps
 * across passes (appm__pixel) and the method's own state (section 10).
 *
 * Every pass traces one eye path per pixel: a point in the pixel (box filter)
 * and on the lens - of the pixel's own low-discrepancy sequence, so that its
 * passes stratify the pixel (section 2.3), or uniformly jittered with
 * --sampler random - then through mirrors and glass until the first diffuse
 * or glossy vertex x (section 8.2).  There the path stops and becomes the
 * pixel's visible point for this pass (stochastic PPM: a new x every pass, so
 * anti-aliasing, depth of field and caustic paths all converge).  What the path
 * meets on the way is added to the pixel's direct term:
 *   emission Le of every surface hit on its front side (the light seen
 *   directly, or in a mirror), and at x the direct light by next-event
 *   estimation (a shadow ray to each point and spot light and one to an
 *   area or environment light chosen by power, four under the studio's sky;
 *   6.4).
 * With --direct photons the shadow ray is skipped and first-bounce photons are
 * gathered instead (the analytic tests and the teaching mode use this).
 *
 * Path length bookkeeping (--max-depth D, in segments from light to camera):
 * the eye path has e segments to x; emission met after k segments counts if
 * k <= D; direct light at x counts if e + 1 <= D; a photon that travelled p
 * segments counts at x if e + p <= D.
 */
/* Everything a pass computes for a pixel stays here until the gather commits
 * it to the pixel's state, so a pass that fails (out of memory in the photon
 * pass) leaves no trace and can simply be run again. */
typedef struct appm__vp { /* visible point of one pixel in the current pass: 96 bytes */
    appm__v3 x;           /* position */
    appm__v3 n;           /* unit geometric normal on the eye's side */
    appm__v3 wf;          /* W f = W albedo / pi: multiplies each photon's gamma */
    appm__v3 ld;          /* this pass's emission + direct light */
    appm__v3 wg;          /* glossy: W Ks (Ns + 2) / (2 pi), the lobe's factor; else 0 */
    appm__v3 rd;          /* glossy: reflect(wo, n_shading), the lobe's axis */
    float ns;             /* glossy: the Phong exponent */
    float footprint;      /* width of the pixel at x, scene units */
    float R;              /* the radius of this pass (appm: of the diffuse photons) */
    float Rc;             /* appm: the caustic photons' radius of this pass; 0: none */
    uint8_t segs;         /* eye-path segments to x; 0: no visible point this pass */
    uint8_t lit;          /* 1: the eye path met a light or the environment through specular
                           * vertices only (the pixel shows a light; appm__pixel.lit), a glossy
                           * lobe it follows as a mirror (appm__eye_split) counting as one */
    uint8_t pad;
    uint32_t tri;         /* the triangle of x: its open edges (5.5) cut the kernel */
} appm__vp;

/* Per-pixel state every method keeps across passes (64 bytes).  What a method
 * keeps beyond this (PPM's I, SPPM's tau, N, R, APPM's S, dI, ...) is its own
 * struct in section 10, in a separate array sized by its estimator entry. */
typedef struct appm__pixel { /* listed field by field for checkpoints: appm__pixel_fields (section 13) */
    double ld[3];      /* sum over passes of emission + direct light (pt: of the whole path) */
    double wmean, wm2; /* Welford mean and M2 of the per-pass estimates' luminance */
    double lh[2];      /* the luminance summed over the first P/2 and the first P passes, P the
                        * last power of two passed: the halves of appm__var_scales */
    uint64_t lit;      /* passes whose eye path met a light or the environment through specular
                        * vertices only: a pixel that shows a light (appm__err_weight) */
} appm__pixel;

struct appm__estimator; /* a method's entry in the table of section 10 */

#define APPM__GUIDE_RES 32        /* cells per side of a light's learned emission density (9.1) */
#define APPM__GUIDE_CELLS (APPM__GUIDE_RES * APPM__GUIDE_RES)
#define APPM__GUIDE_LIGHTS 16     /* lights guided at most: the most powerful */
/* A worker's counts per pass (appm__guide.count): shares, pairs, paths, cost,
 * squared shares. */
#define APPM__GUIDE_STRIDE(nslot) ((size_t)(nslot) * (3u * APPM__GUIDE_CELLS + 2u))
/* The learned state's arrays of one value per slot and cell (appm__guide.cells):
 * score, score_odd, samples, paths, work, in the checkpoint's order. */
#define APPM__GUIDE_ARRAYS 5

typedef struct appm__guide { /* emission guided by visual importance (section 9.1) */
    uint32_t nslot;      /* guided lights (0: --emission light) */
    uint32_t *slot;      /* per scene light: its slot, or UINT32_MAX */
    uint32_t *light;     /* per slot: its scene light */
    double *cells;       /* the APPM__GUIDE_ARRAYS arrays below, one allocation, each nslot x RES^2 */
    double *score;       /* per slot and cell: the learned importance, summed over passes */
    double *score_odd;   /* per slot and cell: its part from the odd passes that learned (the 1st,
                          * 3rd, ...): two independent halves (appm__guide_density) */
    uint64_t *seen;      /* per slot: pixel-photon pairs counted so far */
    uint64_t *passes;    /* per slot: passes that counted */
    double *samples;     /* per slot and cell: the paths it emitted, expected, summed over those passes */
    double *paths;       /* per slot and cell: the paths it emitted, counted, summed over the passes */
    double *work;        /* per slot and cell: their cost, counted (appm__guide_tally), summed likewise */
    double ref;          /* this pass: the image's mean photon term (luminance), the unit of counts */
    float *pdf;          /* per slot and cell: the density of this pass's emission, mean 1 */
    double *cdf;         /* per slot: the CDF over rows (RES + 1), then each row's (RES x (RES + 1)) */
    unsigned char *active; /* per slot: whether pdf is learned (else 1 everywhere) */
    uint64_t *count;     /* per worker, APPM__GUIDE_STRIDE(nslot) words: per slot and cell the
                          * contributions gathered this pass, in units of ref / 2^16; per slot the
                          * pixel-photon pairs; per slot and cell the paths traced, then their cost;
                          * per slot the pairs' squared shares, in units of APPM__GUIDE_SQ_UNIT
                          * (ref / 2^16)^2 */
    float *map;          /* appm_renderer_emission_map's picture */
    double *half;        /* scratch: the two halves' importance of one slot (appm__guide_halves) */
    double *sq;          /* per slot: its pixel-photon pairs' squared shares, times its pick, summed
                          * over the passes that learned: B_l, the choice between lights' measure */
    double *pick;        /* per scene light: the probability that a photon path starts there this
                          * pass (appm__guide_picks; the light's own pick while not chosen) */
    double *pcdf;        /* pick's CDF, nlight + 1 entries */
} appm__guide;

struct appm_renderer {
    appm__mem mem;
    appm_diag diag;
    const appm_scene *scene;
    const struct appm__estimator *est; /* the method: chosen once, at creation */
    appm_direct direct;
    uint32_t w, h;
    uint64_t M;          /* photon paths per pass */
    double r1;           /* initial radius (the user's, or r_auto) */
    double r_auto;       /* the automatic radius (section 12): appm's scale for clamps and h */
    int r1_auto;
    double alpha;
    struct {
        double R2;       /* r_j^2 of the next gather */
        double R;        /* the radius of the last gather */
    } ppm;               /* Knaus-Zwicker's global radius (section 10) */
    double lap_h;        /* Laplacian bandwidth h_j of this pass (the method's bandwidth hook); 0: none */
    double shrink;       /* j^(-1/6) for j = shrink_pass, by which the adaptive radii and bounds shrink */
    uint64_t shrink_pass; /* the pass shrink was computed for (0: none yet) */
    unsigned threads, max_depth;
    uint64_t seed, pass;
    appm__sobol_tab *sobol; /* --sampler qmc: appm__sobol_table (section 2.3); NULL: random */
    unsigned nee_dims, emit_dims; /* appm__light_dims of the scene */
    unsigned chains;     /* qmc: chains of passes (section 2.3); 1 with random */
    int cut;             /* the kernel renormalised where the surface ends inside it (10.4, step 6) */
    int edges;           /* the lines of that cut found: to cut, or to measure the mass (appm__gather.mass) */
    uint8_t *edge_dist;  /* with edges, per pixel: how many pixels along the row to the nearest pixel
                          * with a neighbour on another surface (0: this one; 255: none near; 10.4,
                          * step 6); an array of its own, as the cut's window reads it for 9 rows */
    double *chain_sum;   /* chains >= 2: per pixel, the chains' sums (appm__chain_add) */
    double var_scale;    /* the spread of the passes times this is the variance (appm__var_scales) */
    double noise_scale;  /* with --chains, likewise for the noise of the bias estimate (appm__var_scales; 1
                          * with one chain) */
    double *err_w;       /* per pixel, the error estimate's parts (12, appm__estimate_error): the weight
                          * w of its relative error, then its term w (bias^2 + Var) */
    double *err_b2;      /* per pixel, the method's bias^2 less its noise (appm__bias2's input) */
    uint64_t err_pass;   /* the pass err_b2 holds (0: none) */
    int err_stale;       /* a pass or a checkpoint load has come since the error estimate was made
                          * (appm__error_update) */
    int err_blind;       /* no error estimate: the path tracer on a scene whose point or spot
                          * lights may reach a surface through a mirror or glass (appm__pt_blind) */
    float *err_lum;      /* per pixel, its luminance I after the last pass (appm__err_weight's input;
                          * a float: 4 bytes a pixel, and a weight needs no more digits) */
    float pixel_angle;   /* 2 tan(fov/2) / height */
    appm__vp *vp;
    appm__pixel *pix;
    unsigned char *state; /* the method's per-pixel state: w h est->state_size bytes */
    float *image;
    float *aux[APPM_AUX_COUNT];
    /* photon store: `tasks` regions of `cap` photons; chunk c is traced by task
     * c % tasks, so the layout does not depend on scheduling */
    appm__photon *ph;
    size_t cap;
    uint32_t tasks, nchunks;
    appm__chunk_rec *chunk;
    uint32_t *task_used;
    int *task_failed;
    uint32_t *dest;      /* scratch of the map's counting sort: one per slot of the store */
    uint32_t *tag;       /* guided emission: per slot of the store, its path's emission cell (9.1) */
    appm__guide guide;
    appm__pmap pmap;     /* this pass's photons, compacted and sorted (7.2) */
    uint64_t dropped[APPM__MAX_THREADS];
    /* the photon budget (12.2): M chosen in pass 1 when the configuration left it 0 */
    uint64_t M0;         /* width * height: the photon paths of pass 1's count */
    int budget;          /* 1: M is the budget's (config.photons 0), until pass 1 chooses it */
    uint32_t nchunks_max; /* chunks the chunk arrays hold: those of APPM__BUDGET_MAX M0 with a budget */
    uint64_t work[2][APPM__MAX_THREADS]; /* per worker, the rays of this pass's eye paths [0] and
                                          * photon paths [1] */
    /* a render split over a cluster (12.1); alone: ranks 1, all rows and chunks */
    appm_cluster cluster;
    uint32_t eye0, eye1;     /* this rank's rows of the eye pass */
    uint32_t row0, row1;     /* this rank's rows of the gather (or of path tracing) */
    uint32_t chunk0, chunk1; /* this rank's chunks of photon paths */
    size_t store_slots;      /* photons that ph, dest and tag can hold */
    size_t *cl_lens;         /* per rank: the bytes of its part of the exchange at hand */
    uint32_t *cl_eye, *cl_rows, *cl_chunks; /* ranks + 1 bounds each: rank k does rows (chunks) [b[k], b[k+1]) */
    float *eye_cost, *row_cost, *chunk_cost; /* seconds each row and chunk took in the last pass */
    uint64_t *cl_words;      /* per rank: one word (a status, a count) */
    uint64_t *cl_count;      /* guided emission: per rank, its workers' counts summed */
    uint64_t dropped_other;  /* samples the other ranks dropped, all passes */
    uint64_t dropped_seen;   /* this rank's own dropped total after the last pass */
    appm_stats stats;
    char last_error[256];
};

/* ---- 8.1 Camera rays ---------------------------------------------------------- */

/* --sampler random: where in the pixel (and on the lens) pass j samples: the R2 sequence of
 * Roberts (2018), x_j = frac(s + j g) with g = (1/phi2, 1/phi2^2), phi2 the
 * plastic number - or R4 with the lens, so that the lens and pixel coordinates
 * are not correlated.  Each pixel rotates the sequence by its own random offset
 * s (Cranley-Patterson), so pixels stay independent while the passes of one
 * pixel stratify its area: a pixel cut by the edge of a bright light converges
 * like 1/N instead of 1/sqrt(N), for every method alike. */
static void appm__pixel_sample(uint64_t pass, appm__rng *rng, int lens, float *u)
{
    static const double g2[2] = {0.75487766624669276, 0.56984029099805327};
    static const double g4[4] = {0.85667488385450558, 0.73389185662113744, 0.62870406338765426,
                                 0.53859292022813244};
    const double *g = lens ? g4 : g2;
    int k, n = lens ? 4 : 2;
    for (k = 0; k < n; ++k) {
        double x = (double)appm__rng_float(rng) + (double)(pass % 16777216u) * g[k];
        x -= floor(x);
        u[k] = (float)x < 1.0f ? (float)x : 0.99999994f;
    }
}

static void appm__camera_ray(const appm_renderer *r, const appm__sampler *smp, uint32_t px,
                             uint32_t py, appm__ray *ray)
{
    const appm__camera *c = &r->scene->cam;
    float su[4], u, v, l1 = 0.0f, l2 = 0.0f;
    float aspect = (float)r->w / (float)r->h;
    if (smp->qmc) {
        appm__smp_camera(smp, c->aperture > 0.0f, su);
    } else {
        /* the rotation of pixel (px, py) is the same in every pass: a stream of its own */
        appm__rng prng;
        appm__rng_seed(&prng, r->seed, 0, APPM__DOMAIN_PIXEL, (uint64_t)py * r->w + px);
        appm__pixel_sample(r->pass, &prng, c->aperture > 0.0f, su);
    }
    u = su[0];
    v = su[1];
    if (c->aperture > 0.0f) {
        l1 = su[2];
        l2 = su[3];
    }
    float sx = (2.0f * ((float)px + u) / (float)r->w - 1.0f) * c->tan_half * aspect;
    float sy = (1.0f - 2.0f * ((float)py + v) / (float)r->h) * c->tan_half;
    appm__v3 d = appm__normalize(
        appm__add(c->forward, appm__add(appm__scale(c->right, sx), appm__scale(c->up, sy))));
    appm__v3 o = c->eye;
    if (c->aperture > 0.0f) {
        /* thin lens: a point on the lens disk, aimed at where the pinhole ray
         * meets the plane of focus */
        appm__v3 disk = appm__cosine_dir(appm__v(0, 0, 1), l1, l2); /* x, y uniform in the disk */
        appm__v3 focus = appm__add(c->eye, appm__scale(d, c->focus / appm__dot(d, c->forward)));
        o = appm__add(c->eye, appm__add(appm__scale(c->right, disk.x * c->aperture),
                                        appm__scale(c->up, disk.y * c->aperture)));
        d = appm__normalize(appm__sub(focus, o));
    }
    appm__ray_init(ray, o, d, FLT_MAX);
}

static void appm__add3(double *acc, appm__v3 v)
{
    acc[0] += v.x;
    acc[1] += v.y;
    acc[2] += v.z;
}

/* The cosine of light sample ls at point sf (ns, ng: its normals on the side
 * the light must be on), or 0 where it arrives from below either normal or its
 * shadow ray is blocked. */
static float appm__light_reaches(const appm_scene *s, const appm__surf *sf, appm__v3 ns, appm__v3 ng,
                                 const appm__light_sample *ls)
{
    float c = appm__dot(ls->wi, ns);
    if (!(c > 0.0f) || !(appm__dot(ls->wi, ng) > 0.0f) || appm__occluded(s, &ls->shadow, sf->tri, ls->skip))
        return 0.0f;
    return c;
}

/* What light sample ls brings to diffuse or glossy point sf seen from wo (ns,
 * ng: its normals on wo's side), after its shadow ray. */
static appm__v3 appm__direct_one(const appm_scene *s, const appm__surf *sf, const appm__material *m, appm__v3 wo,
                                 appm__v3 ns, appm__v3 ng, const appm__light_sample *ls)
{
    float c = appm__light_reaches(s, sf, ns, ng, ls);
    if (!(c > 0.0f)) return appm__v(0, 0, 0);
    if (m->kind == APPM__MAT_GLOSSY) return appm__scale(appm__mul(appm__bsdf_f(m, ns, ls->wi, wo), ls->li), c);
    return appm__scale(appm__mul(m->color, ls->li), c * (float)APPM__INV_PI);
}

/* Direct light at diffuse or glossy point sf seen from wo: a shadow ray to
 * each point and spot light and n = appm__nee_samples samples of the others (6.4).
 * The studio's sky takes APPM__SKY_SAMPLES, the t-th from the same numbers
 * turned by t / n in each of their three dimensions (a rotation of the
 * sequence's point: each sample is uniform, and the n are stratified against
 * each other): a sky lights a point from its whole hemisphere, half hidden by
 * the model near it, and one ray a pass left the plate's grain for the first
 * hundreds of passes (docs/algorithm.md 5.10). */
static appm__v3 appm__direct(const appm_renderer *r, const appm__surf *sf, const appm__material *m,
                             appm__v3 wo, appm__sampler *smp, unsigned vertex, unsigned n)
{
    float side = appm__dot(wo, sf->ng) >= 0.0f ? 1.0f : -1.0f;
    appm__v3 ns = appm__scale(sf->ns, side), ng = appm__scale(sf->ng, side), sum = appm__v(0, 0, 0);
    appm__v3 picked = appm__v(0, 0, 0);
    float u[3], step = 1.0f / (float)(n > 1 ? n : 1);
    uint32_t k;
    unsigned t;
    appm__light_sample ls;
    const appm_scene *s = r->scene;
    for (k = 0; k < s->nnee_delta; ++k)
        if (appm__sample_light_k(s, s->nee_delta[k], 1.0, sf, ns, 0.0f, 0.0f, &ls))
            sum = appm__add(sum, appm__direct_one(s, sf, m, wo, ns, ng, &ls));
    appm__smp_light(smp, vertex, r->nee_dims, u);
    for (t = 0; t < n; ++t) {
        if (t >= 1)
            for (k = 0; k < 3; ++k) { /* u + t / n, modulo 1 */
                u[k] += step;
                if (u[k] >= 1.0f) u[k] -= 1.0f;
            }
        if (appm__sample_light(s, 0, sf, ns, u[0], u[1], u[2], &ls))
            picked = appm__add(picked, appm__direct_one(s, sf, m, wo, ns, ng, &ls));
    }
    return appm__add(sum, n > 1 ? appm__scale(picked, 1.0f / (float)n) : picked);
}

/* ---- 8.2 Where eye paths stop ------------------------------------------------
 *
 * At a diffuse or glossy vertex the eye path stops and gathers, evaluating the
 * lobe per photon (section 10).  A very sharp lobe, Ns > APPM__GATHER_NS, would
 * leave only the few photons that arrive within its width of the mirror
 * direction, so there the vertex is split by the albedos instead: with
 * probability P_d the path gathers with the diffuse part alone (W / P_d), else
 * it continues through the lobe like a mirror (W f_lobe cos / ((1 - P_d)
 * pdf_lobe)).  Both are unbiased; which is less noisy was measured at equal
 * time: appm on CornellBox-Glossy at 64x64, 8 s, the floor's Ns (Ks 0.3)
 * raised, RMSE against a 6000-pass path-traced reference, medians of 3 seeds,
 * gathering the lobe / splitting every glossy vertex:
 *      Ns 80: 0.0053 / 0.0081   300: 0.0056 / 0.0065   1000: 0.0063 / 0.0072
 *      3000: 0.0069 / 0.0068   10000: 0.0104 / 0.0072
 * so the split starts where the two cross, Ns = 3000 (a lobe about 1 degree
 * wide).  A point or spot light seen through a continued lobe is missed, as in
 * a mirror (area lights are found by the continuation).
 */
#ifndef APPM__GATHER_NS
#define APPM__GATHER_NS 3000.0f
#endif

/* The material the eye path gathers with at m: m itself, or its diffuse part in
 * *tmp (W divided by P_d); NULL: continue with the lobe alone, left in *tmp (W
 * divided by 1 - P_d).  At a split vertex the choice takes u3 of the vertex's
 * BSDF numbers, the one the glossy sampler would use to pick the part; the
 * continuation then samples the lobe with its u1, u2 (it ignores u3). */
static const appm__material *appm__eye_split(const appm__material *m, appm__material *tmp, appm__sampler *smp,
                                             unsigned vertex, appm__v3 *W)
{
    float pd, u[4];
    if (m->kind != APPM__MAT_GLOSSY || !(m->ns > APPM__GATHER_NS)) return m;
    pd = appm__glossy_pd(m);
    *tmp = *m;
    appm__smp_bsdf(smp, vertex, 4u, u);
    if (u[2] < pd) {
        tmp->kind = APPM__MAT_DIFFUSE;
        *W = appm__scale(*W, 1.0f / pd);
        return tmp;
    }
    tmp->color = appm__v(0, 0, 0); /* P_d = 0: the sampler takes the lobe */
    *W = appm__scale(*W, 1.0f / (1.0f - pd));
    return NULL;
}

/* Makes sf the pixel's visible point of this pass (m diffuse or glossy);
 * returns the shadow rays it cast (the photon budget's count, 12.2). */
static unsigned appm__eye_vertex(appm_renderer *r, appm__vp *vp, const appm__surf *sf, const appm__material *m,
                                 appm__v3 wo, appm__v3 W, unsigned segs, float travelled, appm__v3 *ld,
                                 appm__sampler *smp, unsigned worker)
{
    unsigned rays = 0;
    vp->x = sf->p;
    vp->n = appm__dot(wo, sf->ng) >= 0.0f ? sf->ng : appm__neg(sf->ng);
    vp->wf = appm__scale(appm__mul(W, m->color), (float)APPM__INV_PI);
    vp->wg = vp->rd = appm__v(0, 0, 0);
    vp->ns = 0.0f;
    if (m->kind == APPM__MAT_GLOSSY) {
        appm__v3 ns = appm__dot(wo, sf->ng) >= 0.0f ? sf->ns : appm__neg(sf->ns);
        vp->wg = appm__scale(appm__mul(W, m->ks), (m->ns + 2.0f) * (float)(0.5 * APPM__INV_PI));
        vp->rd = appm__normalize(appm__sub(appm__scale(ns, 2.0f * appm__dot(wo, ns)), wo));
        vp->ns = m->ns;
    }
    vp->segs = (uint8_t)(segs > 255 ? 255 : segs);
    vp->tri = sf->tri;
    vp->footprint = travelled * r->pixel_angle;
    if (r->direct == APPM_DIRECT_NEE && segs + 1 <= r->max_depth) {
        const unsigned n = appm__nee_samples(r->scene);
        *ld = appm__add(*ld, appm__mul(W, appm__direct(r, sf, m, wo, smp, segs - 1, n)));
        rays = r->scene->nnee_delta + n; /* one to each point and spot light, and the samples of the rest */
    }
    if (!appm__finite3(vp->wf) || !appm__finite3(vp->wg)) {
        vp->segs = 0;
        r->dropped[worker]++;
    }
    return rays;
}

/* Traces pixel (px, py)'s eye path of this pass to its visible point; returns
 * the rays it cast, shadow rays included (the photon budget's count, 12.2). */
static unsigned appm__eye_pixel(appm_renderer *r, uint32_t px, uint32_t py, unsigned worker)
{
    const appm_scene *s = r->scene;
    const size_t pi = (size_t)py * r->w + px;
    appm__vp *vp = &r->vp[pi];
    appm__sampler smp;
    appm__ray ray;
    appm__v3 W = appm__v(1, 1, 1), ld = appm__v(0, 0, 0);
    uint32_t skip = UINT32_MAX;
    unsigned segs = 0, rays = 0;
    float travelled = 0.0f;
    appm__sampler_eye(&smp, r->sobol, r->chains, r->seed, r->pass, pi);
    appm__camera_ray(r, &smp, px, py, &ray);
    vp->segs = 0;
    vp->lit = 0;
    for (;;) {
        appm__hit h;
        appm__surf sf;
        const appm__material *m, *mg;
        appm__material tmp, tex;
        appm__v3 wo;
        appm__bsdf_sample bs;
        float u3[4];
        unsigned dims;
        if (++segs > r->max_depth) break;
        rays++;
        if (!appm__intersect(s, &ray, skip, &h)) {
            if (s->env >= 0) {
                ld = appm__add(ld, appm__mul(W, appm__env_radiance(s, ray.d)));
                vp->lit = 1;
            }
            break;
        }
        appm__surface(s, &h, &sf);
        m = appm__material_at(s, &sf, &tex);
        wo = appm__neg(ray.d);
        travelled += h.t;
        if (m->emissive && appm__dot(wo, sf.ng) > 0.0f) {
            ld = appm__add(ld, appm__mul(W, m->ke));
            vp->lit = 1;
        }
        if (m->kind == APPM__MAT_DIFFUSE || m->kind == APPM__MAT_GLOSSY) {
            if ((mg = appm__eye_split(m, &tmp, &smp, segs - 1, &W)) != NULL) {
                rays += appm__eye_vertex(r, vp, &sf, mg, wo, W, segs, travelled, &ld, &smp, worker);
                break;
            }
            m = &tmp; /* a sharp lobe: on through it */
        }
        dims = appm__bsdf_dims(m) | (segs > 4 ? 8u : 0u);
        appm__smp_bsdf(&smp, segs - 1, dims, u3);
        if (!appm__bsdf_sample_dir(m, &sf, wo, u3[0], u3[1], u3[2], APPM__RADIANCE, &bs))
            break;
        W = appm__mul(W, bs.weight);
        if (segs > 4) { /* Russian roulette on long specular chains (glass) */
            float q = appm__maxc(W);
            if (q < 1.0f) {
                if (appm__smp_rr(&smp, segs - 1, dims, u3) >= q) break;
                W = appm__scale(W, 1.0f / q);
            }
        }
        appm__ray_init(&ray, appm__offset(&sf, bs.wi), bs.wi, FLT_MAX);
        skip = sf.tri;
    }
    if (appm__finite3(ld)) {
        vp->ld = ld;
    } else {
        r->dropped[worker]++;
        vp->ld = appm__v(0, 0, 0);
    }
    return rays;
}

/* The samples this renderer's workers dropped (in a cluster: this rank's). */
static uint64_t appm__dropped_own(const appm_renderer *r)
{
    uint64_t n = 0;
    unsigned k;
    for (k = 0; k < APPM__MAX_THREADS; ++k) n += r->dropped[k];
    return n;
}

static void appm__eye_task(void *arg, uint32_t row, unsigned worker)
{
    appm_renderer *r = (appm_renderer *)arg;
    const double t0 = r->eye_cost ? appm__seconds() : 0.0;
    uint32_t x;
    uint64_t rays = 0;
    for (x = 0; x < r->w; ++x) rays += appm__eye_pixel(r, x, row, worker);
    r->work[0][worker] += rays;
    if (r->eye_cost) r->eye_cost[row] = (float)(appm__seconds() - t0); /* a cluster's balance (12.1) */
}

/* ==== 9. PHOTON PASS ======================================================
 *
 * M photon paths per pass, in chunks of APPM__CHUNK paths.  Path i of pass j
 * draws its numbers from point i of the pass's block of a low-discrepancy
 * sequence (section 2.3) or from its own random stream (seed, j, i), so its
 * photons are the same whatever thread traces it.  Chunk c is traced by task c % T into region
 * c % T of the store; the grid build then reads the chunks in order c = 0, 1,
 * ..., which makes the photon order, and every sum over photons, independent
 * of the thread count.
 *
 * A photon is stored at every diffuse or glossy hit it reaches after p >= 2 segments
 * (p >= 1 with --direct photons: then the direct light comes from photons),
 * as long as p + 1 <= D leaves room for one eye segment.  Russian roulette
 * keeps the expected weight: continue with probability q = min(1, max(gamma')
 * / max(gamma)) and divide by q.  A region that fills up marks its task failed;
 * the store then grows (on the calling thread, outside the loop) and the pass
 * is traced again - the photons do not change, only where they are kept.
 * Each photon records its component: caustic when the bounce that sent it to
 * where it was stored was specular (the paths L S+ D of Jensen's caustic map
 * and the specular tail of longer ones), diffuse otherwise.
 */
/* ---- 9.1 Emission guided by visual importance -------------------------------------
 *
 * Most photons of a scene can land where no camera looks: on caustic-glass a
 * spot light hits the floor directly (direct light is the shadow rays' job)
 * and only the few that pass through the glass make the caustic.  So the
 * emission of each guided light learns where the photons that the visible
 * points gathered were emitted, and emits more there (docs/algorithm.md 5.8).
 *
 * A light's emission is a map from its first 2-D sample u = (u1, u2) in
 * [0,1)^2 (appm__emit: the direction of a point or spot light or of the
 * environment, the point on an area light) to a photon path; the light's own
 * distribution is u uniform.  Drawing u from a density p(u) instead, and
 * dividing the photon weight gamma by p(u), leaves every expectation as it was
 * (importance sampling in the primary sample space), so every estimator stays
 * consistent whatever p is, as long as p > 0 wherever a path can contribute.
 * p is piecewise constant on a RES x RES grid of cells (row i from u1, column k
 * from u2), a mixture
 *      p_ik = a + (1 - a) g_ik,     a = APPM__GUIDE_DEFENSIVE = 1/4,
 * of the light's own density (every path stays possible: p >= 1/4, so weights
 * grow by at most 4x) and a learned density g with mean 1.  Sampling inverts
 * p's CDF, rows by u1, then the row's columns by u2: a continuous map, so the
 * low-discrepancy sampler's points (section 2.3) stay stratified.
 *
 * What g learns: a gather adds, per pixel and photon inside its kernel, the
 * pair's share of the pixel's estimate, k_R(d) lum(Psi) / M, to the photon's
 * emission cell (appm__pmap.tag, carried from the photon pass through the
 * map's sort).  Summed over pixels, a photon's shares are about its flux times
 * the density of visible points where it landed, whatever the radius: the
 * image's need for it.  With light l picked with probability pick_l and the
 * photon's weight divided by p, the sum S_c over cell c estimates V_c / RES^2,
 * V_c the mean image contribution of the light's paths started in c (with
 * the light's own weight), whatever p drew it; the score, the sum over passes
 * of S_c RES^2, is the learned importance and g = score / mean(score).  The shares are counted as integers
 * in units of 2^-16 of the image's mean photon term, per worker, so that their
 * sums do not depend on which worker gathered which row, and the scores are
 * updated on one thread in cell order after the pass: images stay
 * bit-identical for any thread count.  A light uses its learned density once
 * APPM__GUIDE_MIN pairs have been counted, if the density passes its own test
 * (appm__guide_density) and makes the photon pass more efficient
 * (appm__guide_select).
 *
 * Which light a path starts at is learned too (appm__guide_picks).  Lights are
 * picked by power, pick_l; a path picked with probability pi_l instead carries
 * pick_l / pi_l in its weight.  A pixel's photon term is a sum over the pass's
 * paths, so its variance is about the sum of the squares of their shares, and
 * light l's part of the image's summed variance is B_l / pi_l, B_l the sum of
 * its pairs' squared shares times pi_l (which does not depend on pi).  With
 * k_l a path's cost, the pass's variance x cost, (sum B_l / pi_l)(sum pi_l k_l),
 * is least at pi_l proportional to sqrt(B_l / k_l) (Cauchy-Schwarz): a light
 * gets paths by the variance its photons leave in the pixels, not by its
 * contribution, which would starve a sky whose photons each light a few pixels
 * (docs/experiments.md).  As with densities, the choice is a mixture with the
 * power's, a = 1/4, and is used only where it pays (APPM__GUIDE_PICK_GAIN). */
#define APPM__GUIDE_DEFENSIVE 0.25 /* the light's own density's share of the mixture */
#define APPM__GUIDE_MIN 64u        /* pixel-photon pairs counted before a light is guided */
#define APPM__GUIDE_PRIOR 16.0     /* paths a cell's importance is shrunk with (appm__guide_importance) */
#define APPM__GUIDE_GAIN 0.5       /* a learned density must halve its light's second moment, and each
                                    * light guided must halve the photon pass's variance x cost */
#define APPM__GUIDE_PICK_GAIN 0.95 /* a learned choice of light must cut the photon pass's variance x
                                    * cost by 5 % (the boxes' light triangles: under 0.3 %) */
#define APPM__GUIDE_CDF ((APPM__GUIDE_RES + 1) * (APPM__GUIDE_RES + 1)) /* doubles per slot */
#define APPM__GUIDE_EVERY 4u       /* after pass 32, one pass in 4 learns (appm__guide_learns) */

/* Whether pass j learns: the first 32, then every APPM__GUIDE_EVERY-th.
 * Counting every pixel-photon pair costs the gather 7 % (the white box,
 * 64x64, one thread, where guiding never pays); the densities are means over
 * the passes that learn, so once a density has formed, learning from a
 * quarter of the passes costs a quarter of that. */
static int appm__guide_learns(uint64_t j)
{
    return j <= 32u || j % APPM__GUIDE_EVERY == 0;
}

/* The cell of u: row from u1, column from u2 (clamped: u < 1 always, but a
 * float may round up). */
static uint32_t appm__guide_cell(float u1, float u2)
{
    int i = (int)(u1 * (float)APPM__GUIDE_RES), k = (int)(u2 * (float)APPM__GUIDE_RES);
    i = i < 0 ? 0 : (i >= APPM__GUIDE_RES ? APPM__GUIDE_RES - 1 : i);
    k = k < 0 ? 0 : (k >= APPM__GUIDE_RES ? APPM__GUIDE_RES - 1 : k);
    return (uint32_t)(i * APPM__GUIDE_RES + k);
}

/* The light of a photon path (from u[0], by this pass's choice, gd->pick) and
 * its first emission sample u[1], u[2], drawn from the light's slot's density
 * if it is active.  Returns the path's tag, slot * RES^2 + cell (UINT32_MAX: an
 * unguided light), the light in *li, and in *w the factor of the photon
 * weight, pick_l / (pi_l p(u)) (appm__emit_light divides by pick_l). */
static uint32_t appm__guide_warp(const appm__guide *gd, const appm_scene *s, float *u, uint32_t *li, float *w)
{
    uint32_t slot;
    int i, k;
    *li = appm__cdf_find(gd->pcdf, s->nlight, u[0]);
    *w = (float)(s->light[*li].pick / gd->pick[*li]); /* 1 exactly while pi_l = pick_l */
    if ((slot = gd->slot[*li]) == UINT32_MAX) return UINT32_MAX;
    if (!gd->active[slot]) return slot * APPM__GUIDE_CELLS + appm__guide_cell(u[1], u[2]);
    {   /* the weight from the CDFs' own steps: exactly the probability the cell was drawn with */
        const double *c = gd->cdf + (size_t)slot * APPM__GUIDE_CDF, *cr;
        u[1] = appm__cdf_invert(c, APPM__GUIDE_RES, u[1], &i);
        cr = c + (size_t)(i + 1) * (APPM__GUIDE_RES + 1);
        u[2] = appm__cdf_invert(cr, APPM__GUIDE_RES, u[2], &k);
        *w = (float)(*w / ((c[i + 1] - c[i]) * (cr[k + 1] - cr[k]) * APPM__GUIDE_CELLS));
    }
    return slot * APPM__GUIDE_CELLS + (uint32_t)(i * APPM__GUIDE_RES + k);
}

/* The learned importance of slot `slot`'s cells, V_c (the mean per pass of its
 * scores), each shrunk towards the mean over the cells by the paths behind it:
 * (N_c V_c + n0 mean(V)) / (N_c + n0), N_c the paths the cell has emitted
 * (expected), n0 = APPM__GUIDE_PRIOR.  A cell few paths have tried says little;
 * without the shrinkage a handful of lucky photons make a density of spikes
 * whose weights are noise (a closed box, 576 paths a pass, rendered 6x noisier
 * than without guiding).  Into v[]; returns their sum. */
static double appm__guide_importance(const appm__guide *gd, uint32_t slot, double *v)
{
    const double *sc = gd->score + (size_t)slot * APPM__GUIDE_CELLS, *n = gd->samples + (size_t)slot * APPM__GUIDE_CELLS;
    double mean = 0.0, sum = 0.0, J = gd->passes[slot] ? (double)gd->passes[slot] : 1.0;
    int i;
    for (i = 0; i < APPM__GUIDE_CELLS; ++i) mean += sc[i] / J;
    mean /= APPM__GUIDE_CELLS;
    for (i = 0; i < APPM__GUIDE_CELLS; ++i) {
        v[i] = (n[i] * (sc[i] / J) + APPM__GUIDE_PRIOR * mean) / (n[i] + APPM__GUIDE_PRIOR);
        sum += v[i];
    }
    return sum;
}

/* The same importance from each half of the passes that learned, the odd
 * (1st, 3rd, ...) and the even ones, each shrunk with half the paths: into
 * vo[c] and ve[c] (0 while a half is empty).  Their product estimates v_c^2
 * without the noise that v_c's own square carries (E[vo ve] = E[vo] E[ve]:
 * different passes, independent photons), which is what the test of worth
 * needs: where a few lucky photons make v spiky (a sun's caustic through a
 * glass sphere), sum v^2 promised a 30x lower variance that the image did
 * not see (docs/algorithm.md 5.8). */
static void appm__guide_halves(const appm__guide *gd, uint32_t slot, double *vo, double *ve)
{
    const size_t at = (size_t)slot * APPM__GUIDE_CELLS;
    const double *sc = gd->score + at, *so = gd->score_odd + at, *n = gd->samples + at;
    const double Jo = (double)((gd->passes[slot] + 1u) / 2u), Je = (double)(gd->passes[slot] / 2u);
    double mo = 0.0, me = 0.0;
    int i;
    if (Je < 1.0) {
        memset(vo, 0, APPM__GUIDE_CELLS * sizeof *vo);
        memset(ve, 0, APPM__GUIDE_CELLS * sizeof *ve);
        return;
    }
    for (i = 0; i < APPM__GUIDE_CELLS; ++i) {
        mo += so[i] / Jo;
        me += (sc[i] > so[i] ? sc[i] - so[i] : 0.0) / Je; /* a difference of sums: never below 0 */
    }
    mo /= APPM__GUIDE_CELLS;
    me /= APPM__GUIDE_CELLS;
    for (i = 0; i < APPM__GUIDE_CELLS; ++i) {
        const double h = 0.5 * n[i];
        vo[i] = (h * (so[i] / Jo) + APPM__GUIDE_PRIOR * mo) / (h + APPM__GUIDE_PRIOR);
        ve[i] = (h * ((sc[i] > so[i] ? sc[i] - so[i] : 0.0) / Je) + APPM__GUIDE_PRIOR * me) / (h + APPM__GUIDE_PRIOR);
    }
}

/* Slot `slot`'s CDFs from its density pdf[]: the rows' marginal, then each
 * row's conditional. */
static void appm__guide_cdf(appm__guide *gd, uint32_t slot)
{
    const float *p = gd->pdf + (size_t)slot * APPM__GUIDE_CELLS;
    double *c = gd->cdf + (size_t)slot * APPM__GUIDE_CDF;
    int i, k;
    c[0] = 0.0;
    for (i = 0; i < APPM__GUIDE_RES; ++i) {
        double *cr = c + (size_t)(i + 1) * (APPM__GUIDE_RES + 1), row = 0.0;
        for (k = 0; k < APPM__GUIDE_RES; ++k) row += p[i * APPM__GUIDE_RES + k];
        c[i + 1] = c[i] + row / APPM__GUIDE_CELLS;
        cr[0] = 0.0;
        for (k = 0; k < APPM__GUIDE_RES; ++k) cr[k + 1] = cr[k] + p[i * APPM__GUIDE_RES + k] / row;
        cr[APPM__GUIDE_RES] = 1.0;
    }
    c[APPM__GUIDE_RES] = 1.0;
}

/* What the choice between lights (appm__guide_select) knows of a slot, per
 * path of that light, from the two halves of its passes (appm__guide_halves):
 * the mean of each half's importance over the cells (the light's share of the
 * photon term); the second moments of a path's estimate of it with the
 * light's own density, mean(vo ve), and with the learned one, mean(vo ve / p);
 * and a path's mean cost (appm__guide_tally) under each. */
typedef struct appm__guide_eff {
    double mu_o, mu_e, m_own, m_with, k_own, k_with;
} appm__guide_eff;

/* Slot `slot`'s density and CDFs for the next pass: p_c = a + (1 - a) g_c,
 * g = v / mean(v) from appm__guide_importance, if the light has counted
 * APPM__GUIDE_MIN pairs and if p pays: the second moment of the estimate of
 * sum(v) that p gives, sum(v_c^2 / p_c), at most APPM__GUIDE_GAIN times the
 * light's own, sum(v_c^2) (importance sampling's variance, against uniform; a
 * density the data cannot tell from flat is not worth its weights' noise),
 * each v_c^2 estimated as the product of the two halves' (appm__guide_halves).
 * Else p = 1 everywhere (not active).  The cost of a path from cell c is its
 * mean counted cost, shrunk like v towards the light's mean. */
static void appm__guide_density(appm__guide *gd, uint32_t slot, appm__guide_eff *e)
{
    double v[APPM__GUIDE_CELLS], sum, own = 0.0, with = 0.0, n = 0.0, work = 0.0, kbar;
    const double *np = gd->paths + (size_t)slot * APPM__GUIDE_CELLS, *wk = gd->work + (size_t)slot * APPM__GUIDE_CELLS;
    double *vo = gd->half, *ve = gd->half + APPM__GUIDE_CELLS;
    float *p = gd->pdf + (size_t)slot * APPM__GUIDE_CELLS;
    int i;
    int finite;
    sum = appm__guide_importance(gd, slot, v);
    appm__guide_halves(gd, slot, vo, ve);
    finite = sum >= 0.0 && sum < HUGE_VAL;
    for (i = 0; i < APPM__GUIDE_CELLS; ++i) { /* a checkpoint's state is checked, but never trusted */
        if (!(v[i] >= 0.0 && v[i] < HUGE_VAL) || !(np[i] >= 0.0 && wk[i] >= 0.0)) finite = 0;
        if (!(vo[i] >= 0.0 && vo[i] < HUGE_VAL && ve[i] >= 0.0 && ve[i] < HUGE_VAL)) finite = 0;
        n += np[i];
        work += wk[i];
    }
    gd->active[slot] = finite && gd->seen[slot] >= APPM__GUIDE_MIN && sum > 0.0;
    kbar = n > 0.0 && work > 0.0 && work < HUGE_VAL ? work / n : 1.0;
    memset(e, 0, sizeof *e);
    for (i = 0; i < APPM__GUIDE_CELLS; ++i) {
        double k = (wk[i] + APPM__GUIDE_PRIOR * kbar) / (np[i] + APPM__GUIDE_PRIOR);
        p[i] = gd->active[slot]
                   ? (float)(APPM__GUIDE_DEFENSIVE + (1.0 - APPM__GUIDE_DEFENSIVE) * v[i] * APPM__GUIDE_CELLS / sum)
                   : 1.0f;
        own += vo[i] * ve[i];
        with += vo[i] * ve[i] / p[i];
        e->k_own += k;
        e->k_with += p[i] * k;
    }
    if (gd->active[slot] && !(own > 0.0 && with <= APPM__GUIDE_GAIN * own)) {
        gd->active[slot] = 0;
        for (i = 0; i < APPM__GUIDE_CELLS; ++i) p[i] = 1.0f;
    }
    if (!gd->active[slot]) {
        with = own;
        e->k_with = e->k_own;
    }
    appm__guide_cdf(gd, slot);
    if (!finite || !(own < HUGE_VAL && e->k_own < HUGE_VAL && e->k_with < HUGE_VAL)) { /* counts for nothing */
        memset(e, 0, sizeof *e);
        return;
    }
    for (i = 0; i < APPM__GUIDE_CELLS; ++i) {
        e->mu_o += vo[i] / APPM__GUIDE_CELLS;
        e->mu_e += ve[i] / APPM__GUIDE_CELLS;
    }
    e->m_own = own / APPM__GUIDE_CELLS;
    e->m_with = with / APPM__GUIDE_CELLS;
    e->k_own /= APPM__GUIDE_CELLS;
    e->k_with /= APPM__GUIDE_CELLS;
}

/* Which of the lights whose learned density passed appm__guide_density are
 * guided: those that make the photon pass more efficient (efficiency = 1 /
 * (variance x cost), Hammersley and Handscomb).  A path picks light l with
 * probability pi_l, so its estimate of the image's photon term, sum_l mu_l,
 * has the variance V = sum_l m_l / pi_l - (sum_l mu_l)^2 and the cost
 * K = sum_l pi_l k_l.  Greedily, the light whose guiding lowers V K the most
 * is guided, as long as that step at least halves V K (APPM__GUIDE_GAIN).  A
 * light can pass its own test and still not pay: on the bunny the point
 * light's learned density cut its own second moment 150x, but its share of
 * the photon term is 7 %, and its aimed paths hit the model three times as
 * often as its own, which miss; guiding it cost 30 % of each pass and removed
 * no error (docs/algorithm.md 5.8).  V and K are of the photon pass alone,
 * and of the candidate lights: the paths of further lights add the same to
 * both either way.  pi_l here is the light's power's pick_l: the learned
 * choice (appm__guide_picks) follows from the densities chosen here, and the
 * choice of densities must be a function of the learned state alone, not of
 * the last pass's picks, so that a resumed render chooses as the
 * uninterrupted one did. */
static void appm__guide_select(const appm_scene *sc, appm__guide *gd, const appm__guide_eff *e)
{
    unsigned char take[APPM__GUIDE_LIGHTS];
    double V = 0.0, K = 0.0, mu_o = 0.0, mu_e = 0.0;
    uint32_t s;
    int c;
    for (s = 0; s < gd->nslot; ++s) {
        const double pi = sc->light[gd->light[s]].pick;
        take[s] = gd->active[s];
        gd->active[s] = 0;
        V += e[s].m_own / pi;
        K += pi * e[s].k_own;
        mu_o += e[s].mu_o;
        mu_e += e[s].mu_e;
    }
    V -= mu_o * mu_e;
    for (;;) {
        double best_vk = HUGE_VAL, bv = 0.0, bk = 0.0;
        uint32_t best = UINT32_MAX;
        for (s = 0; s < gd->nslot; ++s) {
            const double pi = sc->light[gd->light[s]].pick;
            double v, k;
            if (!take[s] || gd->active[s]) continue;
            v = V + (e[s].m_with - e[s].m_own) / pi;
            k = K + pi * (e[s].k_with - e[s].k_own);
            if (v > 0.0 && v * k < best_vk) { /* v <= 0: the halves disagree, a promise of noise */
                best_vk = v * k;
                best = s;
                bv = v;
                bk = k;
            }
        }
        if (best == UINT32_MAX || !(V * K > 0.0 && best_vk <= APPM__GUIDE_GAIN * V * K)) break;
        gd->active[best] = 1;
        V = bv;
        K = bk;
    }
    for (s = 0; s < gd->nslot; ++s)
        if (take[s] && !gd->active[s]) { /* passed its own test, but does not pay: back to the light's own */
            float *p = gd->pdf + (size_t)s * APPM__GUIDE_CELLS;
            for (c = 0; c < APPM__GUIDE_CELLS; ++c) p[c] = 1.0f;
            appm__guide_cdf(gd, s);
        }
}

/* Every light picked by power (pi_l = pick_l), and the CDF of that. */
static void appm__guide_picks_own(const appm_scene *sc, appm__guide *gd)
{
    uint32_t i;
    for (i = 0; i < sc->nlight; ++i) gd->pick[i] = sc->light[i].pick;
    memcpy(gd->pcdf, sc->light_cdf, ((size_t)sc->nlight + 1u) * sizeof *gd->pcdf);
}

/* The choice between lights for the next pass (9.1): the guided lights share
 * their power's total P = sum pick_l as
 *      pi_l = a pick_l + (1 - a) P sqrt(B_l / k_l) / sum_m sqrt(B_m / k_m),
 * k_l a path's mean cost under the density the pass draws from (e), if all
 * lights together have counted APPM__GUIDE_MIN pairs and if it cuts the
 * photon pass's variance x cost, (sum B_l / pi_l)(sum pi_l k_l), to at most
 * APPM__GUIDE_PICK_GAIN of what the power's choice gives; else pi = pick.
 * Lights beyond the guided 16 keep their own pick. */
static void appm__guide_picks(const appm_scene *sc, appm__guide *gd, const appm__guide_eff *e)
{
    const double a = APPM__GUIDE_DEFENSIVE;
    double o[APPM__GUIDE_LIGHTS], k[APPM__GUIDE_LIGHTS], pi[APPM__GUIDE_LIGHTS], P = 0.0, tot = 0.0, v0 = 0.0,
        k0 = 0.0, v1 = 0.0, k1 = 0.0;
    uint64_t seen = 0;
    uint32_t s, i;
    appm__guide_picks_own(sc, gd);
    for (s = 0; s < gd->nslot; ++s) {
        k[s] = gd->active[s] ? e[s].k_with : e[s].k_own;
        o[s] = gd->sq[s] > 0.0 && k[s] > 0.0 ? sqrt(gd->sq[s] / k[s]) : 0.0;
        P += sc->light[gd->light[s]].pick;
        tot += o[s];
        seen += gd->seen[s];
    }
    if (seen < APPM__GUIDE_MIN || !(tot > 0.0 && tot < HUGE_VAL)) return;
    for (s = 0; s < gd->nslot; ++s) {
        const double own = sc->light[gd->light[s]].pick;
        pi[s] = a * own + (1.0 - a) * P * o[s] / tot;
        v0 += gd->sq[s] / own;
        k0 += own * k[s];
        v1 += gd->sq[s] / pi[s];
        k1 += pi[s] * k[s];
    }
    if (!(v1 * k1 <= APPM__GUIDE_PICK_GAIN * v0 * k0)) return; /* does not pay (or NaN: a state not to trust) */
    for (s = 0; s < gd->nslot; ++s) gd->pick[gd->light[s]] = pi[s];
    gd->pcdf[0] = 0.0;
    for (i = 0; i < sc->nlight; ++i) gd->pcdf[i + 1] = gd->pcdf[i] + gd->pick[i];
    gd->pcdf[sc->nlight] = 1.0;
}

/* Every slot's density and CDFs for the next pass: a function of the learned
 * state alone (so a resumed render draws the same). */
static void appm__guide_densities(const appm_renderer *r, appm__guide *gd)
{
    appm__guide_eff e[APPM__GUIDE_LIGHTS];
    uint32_t s;
    for (s = 0; s < gd->nslot; ++s) appm__guide_density(gd, s, &e[s]);
    appm__guide_select(r->scene, gd, e);
    appm__guide_picks(r->scene, gd, e);
}

/* Before a pass: every slot's density and the share of the paths drawn from
 * learned densities (the unit of the pass's counts, guide.ref, is set with
 * the renderer's state in section 12). */
static void appm__guide_prepare(appm_renderer *r)
{
    appm__guide *gd = &r->guide;
    uint32_t s;
    double share = 0.0;
    appm__guide_densities(r, gd);
    for (s = 0; s < gd->nslot; ++s)
        if (gd->active[s]) share += (1.0 - APPM__GUIDE_DEFENSIVE) * gd->pick[gd->light[s]];
    r->stats.emission_guided = share;
    r->stats.emission_lights = gd->nslot;
}

/* A count that saturates. */
static void appm__count_add(uint64_t *c, uint64_t add)
{
    *c = *c > UINT64_MAX - add ? UINT64_MAX : *c + add;
}

/* One pixel-photon pair into a worker's counts (a gather inside the kernel of
 * radius^2 R2): the pair's share of the pixel, n = k_R(d) lum(Psi) / M, in
 * units of ref / 2^16 (unit = 2^16 / (pi M ref); the biweight's 3 / pi, the
 * uniform kernel's 1 / pi), rounded; one pair; and n^2 in units of
 * APPM__GUIDE_SQ_UNIT (so that a firefly's square, n up to 4e9, still fits:
 * shares of a few units, whose squares round to 0, weigh nothing beside it).
 * Every sum saturates, here and where the workers' and ranks' counts are
 * added (appm__guide_learn, appm__cluster_guide): min(the sum, UINT64_MAX)
 * does not depend on how the pairs were split.  `pairs` is where the pairs
 * per slot start, nslot x RES^2 words in; the squares start 2 x pairs + nslot
 * words after them. */
#define APPM__GUIDE_SQ_UNIT 256.0
static void appm__guide_count(uint64_t *count, size_t pairs, uint32_t tag, float d2, float R2, int biweight,
                              double q, double unit)
{
    double u = 1.0 - (double)d2 / R2, k = biweight ? 3.0 * u * u : 1.0, n = k * q / R2 * unit;
    const size_t slot = tag / APPM__GUIDE_CELLS;
    if (!(n > 0.0)) n = 0.0;
    appm__count_add(&count[tag], n < 1e15 ? (uint64_t)(n + 0.5) : (uint64_t)1e15);
    count[pairs + slot]++;
    appm__count_add(&count[3 * pairs + pairs / APPM__GUIDE_CELLS + slot],
                    (uint64_t)((n < 4e9 ? n * n : 4e9 * 4e9) / APPM__GUIDE_SQ_UNIT + 0.5));
}

/* After the gather: the workers' counts (integers, saturating: the same sums
 * in any order) into the scores, cell by cell - score_c += S_c RES^2, S_c the
 * pass's contributions from cell c, which estimates the mean over the cell of the
 * image contribution of the light's paths started there, whatever density
 * drew the cell (the photon's weight carries 1 / p) - and back to 0. */
static void appm__guide_learn(appm_renderer *r)
{
    appm__guide *gd = &r->guide;
    size_t cells = (size_t)gd->nslot * APPM__GUIDE_CELLS, stride = APPM__GUIDE_STRIDE(gd->nslot), c;
    unsigned w;
    if (!(gd->ref > 0.0)) return; /* a pass that does not learn: nothing was counted */
    for (c = 0; c < cells; ++c) /* M pi_l p_c / RES^2 paths from cell c this pass */
        gd->samples[c] += (double)r->M * gd->pick[gd->light[c / APPM__GUIDE_CELLS]] * (double)gd->pdf[c] /
                          APPM__GUIDE_CELLS;
    for (w = 0; w < gd->nslot; ++w) gd->passes[w]++;
    for (c = 0; c < stride; ++c) {
        uint64_t n = 0;
        for (w = 0; w < r->threads; ++w) {
            appm__count_add(&n, gd->count[w * stride + c]);
            gd->count[w * stride + c] = 0;
        }
        if (c >= 3 * cells + gd->nslot) { /* B_l += pi_l x the squared shares (appm__guide_picks) */
            const size_t l = c - 3 * cells - gd->nslot;
            const double u = gd->ref / 65536.0;
            gd->sq[l] += (double)n * APPM__GUIDE_SQ_UNIT * u * u * gd->pick[gd->light[l]];
        } else if (c >= 2 * cells + gd->nslot) gd->work[c - 2 * cells - gd->nslot] += (double)n;
        else if (c >= cells + gd->nslot) gd->paths[c - cells - gd->nslot] += (double)n;
        else if (c >= cells) gd->seen[c - cells] += n;
        else if (n) {
            const double add = (double)n * (gd->ref / 65536.0) * APPM__GUIDE_CELLS;
            gd->score[c] += add;
            if (gd->passes[c / APPM__GUIDE_CELLS] & 1u) gd->score_odd[c] += add;
        }
    }
}

/* The guided lights: the APPM__GUIDE_LIGHTS most powerful (ties: the first),
 * and their arrays; 0 when out of memory. */
static int appm__guide_alloc(appm_renderer *r)
{
    appm__guide *gd = &r->guide;
    const appm_scene *s = r->scene;
    uint32_t i, k, n = 0;
    gd->slot = (uint32_t *)appm__alloc(&r->mem, s->nlight, sizeof *gd->slot);
    gd->light = (uint32_t *)appm__alloc(&r->mem, APPM__GUIDE_LIGHTS, sizeof *gd->light);
    if (!gd->slot || !gd->light) return 0;
    for (i = 0; i < s->nlight; ++i) gd->slot[i] = UINT32_MAX;
    while (n < APPM__GUIDE_LIGHTS) { /* the next most powerful light not yet taken */
        uint32_t best = UINT32_MAX;
        for (i = 0; i < s->nlight; ++i)
            if (gd->slot[i] == UINT32_MAX && s->light[i].pick > 0.0 &&
                (best == UINT32_MAX || s->light[i].pick > s->light[best].pick))
                best = i;
        if (best == UINT32_MAX) break;
        gd->slot[best] = n;
        gd->light[n++] = best;
    }
    gd->nslot = n;
    k = n * APPM__GUIDE_CELLS;
    gd->cells = (double *)appm__alloc(&r->mem, (size_t)k * APPM__GUIDE_ARRAYS, sizeof *gd->cells);
    if (gd->cells) {
        gd->score = gd->cells;
        gd->score_odd = gd->cells + k;
        gd->samples = gd->cells + 2 * (size_t)k;
        gd->paths = gd->cells + 3 * (size_t)k;
        gd->work = gd->cells + 4 * (size_t)k;
    }
    gd->half = (double *)appm__alloc(&r->mem, 2u * APPM__GUIDE_CELLS, sizeof *gd->half);
    gd->sq = (double *)appm__alloc(&r->mem, n ? n : 1u, sizeof *gd->sq);
    gd->pick = (double *)appm__alloc(&r->mem, s->nlight ? s->nlight : 1u, sizeof *gd->pick);
    gd->pcdf = (double *)appm__alloc(&r->mem, (size_t)s->nlight + 1u, sizeof *gd->pcdf);
    if (gd->pick && gd->pcdf) appm__guide_picks_own(s, gd);
    gd->seen = (uint64_t *)appm__alloc(&r->mem, n, sizeof *gd->seen);
    gd->passes = (uint64_t *)appm__alloc(&r->mem, n, sizeof *gd->passes);
    gd->pdf = (float *)appm__alloc(&r->mem, k, sizeof *gd->pdf);
    gd->cdf = (double *)appm__alloc(&r->mem, (size_t)n * APPM__GUIDE_CDF, sizeof *gd->cdf);
    gd->active = (unsigned char *)appm__alloc(&r->mem, n, 1);
    gd->count = (uint64_t *)appm__alloc(&r->mem, APPM__GUIDE_STRIDE(n), (size_t)r->threads * sizeof *gd->count);
    return n == 0 || (gd->cells && gd->half && gd->sq && gd->pick && gd->pcdf && gd->seen && gd->passes && gd->pdf &&
                      gd->cdf && gd->active && gd->count);
}

static void appm__guide_free(appm_renderer *r)
{
    appm__guide *gd = &r->guide;
    appm__free(&r->mem, gd->slot);
    appm__free(&r->mem, gd->light);
    appm__free(&r->mem, gd->cells);
    appm__free(&r->mem, gd->half);
    appm__free(&r->mem, gd->sq);
    appm__free(&r->mem, gd->pick);
    appm__free(&r->mem, gd->pcdf);
    appm__free(&r->mem, gd->seen);
    appm__free(&r->mem, gd->passes);
    appm__free(&r->mem, gd->pdf);
    appm__free(&r->mem, gd->cdf);
    appm__free(&r->mem, gd->active);
    appm__free(&r->mem, gd->count);
    appm__free(&r->mem, gd->map);
}

/* ---- 9.2 Photon paths ---------------------------------------------------------- */

#define APPM__CHUNK 1024u /* photon paths per chunk: fixed, so results do not depend on threads */

/* Whether this pass's photons carry their emission cell (appm__pmap.tag): only
 * a pass that learns reads them (a gather counts their shares), so the others
 * neither store, move nor sort them (9.1). */
static int appm__guide_tags(const appm_renderer *r)
{
    return r->tag != NULL && r->guide.ref > 0.0;
}

static int appm__store_photon_comp(appm_renderer *r, uint32_t task, const appm__surf *sf, appm__v3 wi,
                                   appm__v3 gamma, unsigned segs, unsigned comp, uint32_t tag)
{
    appm__photon *p;
    appm__v3 n = appm__dot(wi, sf->ng) >= 0.0f ? sf->ng : appm__neg(sf->ng);
    float a, b;
    size_t slot;
    if (r->task_used[task] >= r->cap) return 0;
    slot = (size_t)task * r->cap + r->task_used[task]++;
    if (appm__guide_tags(r)) r->tag[slot] = tag;
    p = &r->ph[slot];
    p->x = sf->p.x;
    p->y = sf->p.y;
    p->z = sf->p.z;
    p->power[0] = gamma.x;
    p->power[1] = gamma.y;
    p->power[2] = gamma.z;
    appm__oct_encode(wi, &a, &b);
    p->wi[0] = (int16_t)appm__quant(a, 32767.0f);
    p->wi[1] = (int16_t)appm__quant(b, 32767.0f);
    appm__oct_encode(n, &a, &b);
    p->n[0] = (int8_t)appm__quant(a, 127.0f);
    p->n[1] = (int8_t)appm__quant(b, 127.0f);
    p->segs = (uint8_t)(segs > 255 ? 255 : segs);
    p->comp = (uint8_t)comp;
    return 1;
}

/* The same for a photon of the diffuse component. */
APPM__UNUSED static int appm__store_photon(appm_renderer *r, uint32_t task, const appm__surf *sf, appm__v3 wi,
                                           appm__v3 gamma, unsigned segs)
{
    return appm__store_photon_comp(r, task, sf, wi, gamma, segs, APPM__COMP_DIFFUSE, UINT32_MAX);
}

/* Whether an eye path can gather at m (section 8.2): diffuse, or glossy with a
 * lobe it gathers or a diffuse part. */
static int appm__stores_photons(const appm__material *m)
{
    if (m->kind == APPM__MAT_DIFFUSE) return 1;
    if (m->kind != APPM__MAT_GLOSSY) return 0;
    return m->ns <= APPM__GATHER_NS || m->color.x > 0.0f || m->color.y > 0.0f || m->color.z > 0.0f;
}

/* Bit 3 of the photon sampler's mask after a bounce off m (appm__smp_bsdf): the
 * roulette is asked for when the bounce's weight lowers the path's largest
 * channel.  The weight of a diffuse or mirror bounce is the colour itself, so
 * with every channel >= 1 (the white box) it never is, and glass has weight 1.
 * A hint only: the roulette's number is the same either way. */
static unsigned appm__photon_rr_dim(const appm__material *m)
{
    if (m->kind == APPM__MAT_DIELECTRIC) return 0u;
    if (m->kind != APPM__MAT_GLOSSY && m->color.x >= 1.0f && m->color.y >= 1.0f && m->color.z >= 1.0f)
        return 0u;
    return 8u;
}

/* Guided emission's count of one traced path from cell `tag` (9.1): a path,
 * and its cost in quarters of a ray that hits - 1 for its start and the ray
 * that leaves the scene, 4 for each ray that hits (a ray that misses
 * everything is about a quarter of one that descends the BVH to a triangle). */
static void appm__guide_tally(appm_renderer *r, unsigned worker, uint32_t tag, unsigned hits)
{
    uint64_t *c;
    if (tag == UINT32_MAX || !(r->guide.ref > 0.0)) return; /* a pass that does not learn (appm__guide_learns) */
    c = r->guide.count + (size_t)worker * APPM__GUIDE_STRIDE(r->guide.nslot) +
        (size_t)r->guide.nslot * (APPM__GUIDE_CELLS + 1u) + tag;
    c[0]++;
    c[(size_t)r->guide.nslot * APPM__GUIDE_CELLS] += 1u + 4u * (uint64_t)hits;
}

/* Traces photon path `index` (cache: shared by the paths the worker traces in
 * turn, appm__sampler_photon), adding the rays it casts to *rays (the photon
 * budget's count, 12.2); returns 0 if the task's region is full.
 *
 * After each bounce a roulette keeps the path with probability q, the largest
 * channel's loss.  A studio's photon (6.3; its aim, which the user's lights
 * keep) skips it at its first hit, which is direct light (on the plate or the
 * model) and not stored: a roulette there (the plate's albedo 1/2) ended half
 * the paths after their rays were paid for.  1.78x the photons stored for
 * 1.07x the time a pass (docs/algorithm.md 5.10, which says why the other
 * scenes keep it). */
static int appm__photon_path(appm_renderer *r, uint32_t task, uint64_t index, unsigned worker,
                             appm__ld_cache *cache, uint64_t *rays)
{
    const appm_scene *s = r->scene;
    appm__sampler smp;
    appm__photon_start ps;
    appm__ray ray;
    appm__v3 gamma;
    uint32_t skip;
    unsigned segs = 0, hits = 0, casts = 0, comp = APPM__COMP_DIFFUSE; /* comp: the component of a photon stored next */
    unsigned first = r->direct == APPM_DIRECT_PHOTONS ? 1u : 2u;
    float ue[5], w = 1.0f;
    uint32_t tag = UINT32_MAX, li;
    int ok;
    appm__sampler_photon(&smp, r->sobol, cache, r->chains, r->seed, r->pass, r->M, index);
    appm__smp_emit(&smp, r->emit_dims, ue);
    if (r->guide.nslot) { /* 9.1 */
        tag = appm__guide_warp(&r->guide, s, ue, &li, &w);
        ok = appm__emit_light(s, li, ue, &ps);
    } else {
        ok = appm__emit(s, ue, &ps);
    }
    if (!ok) {
        if (!appm__finite3(ps.gamma)) r->dropped[worker]++; /* its weight overflowed */
        appm__guide_tally(r, worker, tag, 0);
        return 1;
    }
    ray = ps.ray;
    gamma = w != 1.0f ? appm__scale(ps.gamma, w) : ps.gamma;
    skip = ps.skip;
    while (++segs + 1 <= r->max_depth) {
        appm__hit h;
        appm__surf sf;
        const appm__material *m;
        appm__material tex;
        appm__v3 wi, g2;
        appm__bsdf_sample bs;
        float u3[4], steer = 1.0f; /* an aimed bounce's factor (appm__focus_bounce) */
        unsigned dims;
        float q;
        casts++;
        if (!appm__intersect(s, &ray, skip, &h)) break;
        hits++;
        appm__surface(s, &h, &sf);
        m = appm__material_at(s, &sf, &tex);
        wi = appm__neg(ray.d);
        if (appm__stores_photons(m) && segs >= first) {
            if (!appm__finite3(gamma)) {
                r->dropped[worker]++;
                break;
            }
            if (!appm__store_photon_comp(r, task, &sf, wi, gamma, segs, comp, tag)) return 0;
        }
        if (segs + 2 > r->max_depth) break; /* no deposit could count any more */
        dims = appm__bsdf_dims(m) | appm__photon_rr_dim(m);
        appm__smp_bsdf(&smp, segs - 1, dims, u3);
        if (appm__focus_aims(s, m, &sf, wi)) { /* the studio's model (6.3) */
            if (!appm__focus_bounce(s, m, &sf, wi, u3[0], u3[1], &bs, &steer)) break;
        } else if (!appm__bsdf_sample_dir(m, &sf, wi, u3[0], u3[1], u3[2], APPM__IMPORTANCE, &bs)) {
            break;
        }
        g2 = appm__mul(gamma, bs.weight);
        q = appm__maxc(gamma) > 0.0f ? appm__maxc(g2) / appm__maxc(gamma) : 0.0f;
        if (q < 1.0f && !(s->focus_r > 0.0f && segs < first)) { /* a studio's: see above */
            if (!(appm__smp_rr(&smp, segs - 1, dims, u3) < q)) break;
            g2 = appm__scale(g2, 1.0f / q);
        }
        gamma = steer != 1.0f ? appm__scale(g2, steer) : g2;
        comp = bs.specular ? APPM__COMP_CAUSTIC : APPM__COMP_DIFFUSE;
        appm__ray_init(&ray, appm__offset(&sf, bs.wi), bs.wi, FLT_MAX);
        skip = sf.tri;
    }
    appm__guide_tally(r, worker, tag, hits);
    *rays += casts;
    return 1;
}

static void appm__photon_task(void *arg, uint32_t task, unsigned worker)
{
    appm_renderer *r = (appm_renderer *)arg;
    appm__ld_cache cache;
    uint64_t rays = 0;
    uint32_t c;
    cache.set = 0;
    r->task_used[task] = 0;
    r->task_failed[task] = 0;
    for (c = r->chunk0 + task; c < r->chunk1; c += r->tasks) {
        uint64_t i0 = (uint64_t)c * APPM__CHUNK, i1 = i0 + APPM__CHUNK, i;
        const double t0 = r->chunk_cost ? appm__seconds() : 0.0;
        if (i1 > r->M) i1 = r->M;
        r->chunk[c].start = r->task_used[task];
        for (i = i0; i < i1; ++i) {
            if (!appm__photon_path(r, task, i, worker, &cache, &rays)) {
                r->task_failed[task] = 1;
                return; /* the pass is traced again, its counts from 0 */
            }
        }
        r->chunk[c].count = r->task_used[task] - r->chunk[c].start;
        if (r->chunk_cost) r->chunk_cost[c] = (float)(appm__seconds() - t0);
    }
    r->work[1][worker] += rays;
}

/* New ph, dest and tag arrays of `slots` photons each (tag only with guided
 * emission), the first `keep` photons and tags copied over; the old ones are
 * freed, and on failure nothing changes. */
static appm_status appm__store_realloc(appm_renderer *r, size_t slots, size_t keep)
{
    appm__photon *nph = (appm__photon *)appm__alloc(&r->mem, slots, sizeof *nph);
    uint32_t *ndest = nph ? (uint32_t *)appm__alloc(&r->mem, slots, sizeof *ndest) : NULL;
    uint32_t *ntag = ndest && r->tag ? (uint32_t *)appm__alloc(&r->mem, slots, sizeof *ntag) : NULL;
    if (!ndest || (r->tag && !ntag)) {
        appm__free(&r->mem, nph);
        appm__free(&r->mem, ndest);
        return APPM_ERR_NOMEM;
    }
    if (keep) memcpy(nph, r->ph, keep * sizeof *nph);
    if (keep && r->tag) memcpy(ntag, r->tag, keep * sizeof *ntag);
    appm__free(&r->mem, r->ph);
    appm__free(&r->mem, r->dest);
    appm__free(&r->mem, r->tag);
    r->ph = nph;
    r->dest = ndest;
    r->tag = ntag;
    r->store_slots = slots;
    return APPM_OK;
}

static appm_status appm__photon_pass(appm_renderer *r)
{
    uint64_t dropped[APPM__MAX_THREADS];
    memcpy(dropped, r->dropped, sizeof dropped);
    for (;;) {
        uint32_t t;
        int failed = 0;
        size_t ncap;
        if (r->guide.nslot) /* guided emission's counts start from 0 (9.1), whatever an earlier try or a
                             * pass that failed after its photon pass (and was not committed) left */
            memset(r->guide.count, 0, APPM__GUIDE_STRIDE(r->guide.nslot) * r->threads * sizeof *r->guide.count);
        memset(r->work[1], 0, sizeof r->work[1]); /* so are the budget's (12.2) */
        appm__parallel_for(r->threads, r->tasks, appm__photon_task, r);
        for (t = 0; t < r->tasks; ++t) failed |= r->task_failed[t];
        if (!failed) return APPM_OK;
        memcpy(r->dropped, dropped, sizeof dropped); /* the pass is traced again: its drops count once */
        /* grow every region by half and trace again (rare: the first pass, or a
         * pass that stores more photons than any before it) */
        ncap = r->cap + r->cap / 2 + 4096;
        if (ncap > (size_t)0xFFFFFFF0u / r->tasks)
            return appm__fail(&r->diag, APPM_ERR_NOMEM, NULL, 0,
                              "more than 4e9 photons stored in one pass: use fewer photons per pass");
        if (appm__store_realloc(r, ncap * r->tasks, 0) != APPM_OK) return APPM_ERR_NOMEM;
        r->cap = ncap;
    }
}

/* Moves the regions' chunks (this rank's: all when alone) together, region
 * after region, leaving no gaps (the chunks of one region are in order).
 * chunk[c].start becomes the offset in the compacted array: the map's build
 * reads the photons chunk by chunk through these records, so its order is
 * that of the paths whatever the number of regions.  Returns the number of
 * photons. */
static size_t appm__store_compact(appm_renderer *r)
{
    size_t out = 0;
    uint32_t t, c;
    appm__chunk_rec *cr = r->chunk;
    for (t = 0; t < r->tasks; ++t) {
        size_t base = (size_t)t * r->cap;
        for (c = r->chunk0 + t; c < r->chunk1; c += r->tasks) {
            if (cr[c].count && base + cr[c].start != out) {
                memmove(&r->ph[out], &r->ph[base + cr[c].start], cr[c].count * sizeof *r->ph);
                if (appm__guide_tags(r))
                    memmove(&r->tag[out], &r->tag[base + cr[c].start], cr[c].count * sizeof *r->tag);
            }
            cr[c].start = (uint32_t)out;
            out += cr[c].count;
        }
    }
    return out;
}

/* ==== 10. ESTIMATORS ======================================================
 *
 * Pixel-centric gathering: each pixel reads the photons near its visible point
 * x and writes only its own state, so no atomics are needed.  A photon i at y_i
 * contributes Psi_i = W f(wi_i, wo) gamma_i (no cosine: the photon's flux
 * already holds the projected-area factor) if it lies on the same surface
 * (normals within 60 degrees, arriving on the eye's side) and if e + p_i <= D.
 * On a diffuse point f = Kd / pi is the same for every photon and multiplies
 * the sums once at the end; on a glossy one the lobe is evaluated per photon
 * from its stored direction wi_i, f = Kd / pi + Ks (Ns + 2) / (2 pi) (wi_i .
 * reflect(wo, n))^Ns, and enters S, dI and the estimates like any other Psi_i.
 *
 * Kernels (2-D, on the tangent plane; u = |x - y| / r):
 *   uniform  K = 1/pi                 mu2 = 1/4   R(K) = 1/pi      (ppm, sppm)
 *   biweight K = (3/pi) (1 - u^2)^2   mu2 = 1/8   R(K) = 9/(5 pi)  (appm, appm-paper)
 * with k_r(d) = K(|d|/r) / r^2, mu2 the per-axis second moment, R(K) = int K^2.
 * The biweight is smooth (C1), which the finite-difference Laplacian needs.
 *
 * The formulas, their derivations and their sources are in docs/algorithm.md,
 * cited here by section (the papers' own equation numbers could not be
 * checked against the papers, so they are not quoted).  The subsections:
 *
 *   10.1 the gather's sums    what every photon method sums over the photons
 *                             near x, the kernel's mass on the surface, and the
 *                             table entry (appm__estimator) a method fills in
 *   10.2 baselines            ppm (Knaus-Zwicker 2011, algorithm.md 2.3): one
 *                             global radius r_j^2 = r_1^2 prod (k + alpha)/(k + 1);
 *                             sppm (Hachisuka-Jensen 2009, 2.2): per pixel N, R, tau
 *   10.3 the paper's APPM     appm-paper (Kaplanyan-Dachsbacher 2013, 4.1 - 4.8):
 *                             per pixel and pass the radius that minimises the
 *                             estimated MSE(r) = R(K) S / (M j r^2) + (mu2 r^2 dI / 2)^2,
 *                             r^6 = c_f R(K) S / (M j mu2^2 dI^2); read it beside
 *                             the pseudocode of algorithm.md 4.8
 *   10.4 appm                 the default: the paper's selector with seven named
 *                             steps on top, each with its measured reason
 *   10.5 the estimator table  one entry per method
 *   10.6 the gather           the per-row task that queries the map and commits
 *
 * The history of what was measured on the way (the variants that lost
 * included) is one table in docs/experiments.md.
 */
#define APPM__MU2 0.125                          /* biweight, per axis */
/* appm's error bar (7.2, docs/algorithm.md 7.4): the inner radius R' = R / sqrt(INNER_S2)
 * at which the same photons are weighed a second time.  To second order
 * D = I(R) - I(R') = (1 - 1 / INNER_S2) bias(R), so the bias is INNER_F D.  8, not
 * 0.1.11's 2: the bias of a feature narrower than R' (a caustic's filament) grows
 * more slowly than R^2 and D holds less of it the closer R' is to R; at
 * R / sqrt 8 the inner estimate's bias is an eighth of the outer one's to second
 * order, and D holds most of the bias of any filament wider than R'.
 * It costs noise (a photon's share of INNER_F D has 7.7x the variance of its share
 * of I(R), 1.7x at sqrt 2), which b^2 - noise takes off (appm__var_scales: not
 * scaled by the luminance's halves with one chain).  Over 12 seeds the error bar
 * read 0.68 / 0.68 of water-caustic's true error at 64 / 256 passes with 2 (0.1.11,
 * its noise scaled by those halves) and, unscaled, 0.67 / 0.69 with 4, 0.695 / 0.708
 * with 6 and 0.709 / 0.722 with 8 (docs/algorithm.md 7.4). */
#define APPM__INNER_S2 8.0
#define APPM__INNER_F (APPM__INNER_S2 / (APPM__INNER_S2 - 1.0))
#define APPM__RK (9.0 / (5.0 * APPM__PI))        /* biweight, int K^2 */
/* The constants of the adaptive methods (algorithm.md 4.3 - 4.7 and 4.10 - );
 * fixed at compile time, no build option changes them. */
#define APPM__CF (2.0 / 3.0)                     /* c_f: optimal for 1/j weights and r ~ j^(-1/6) (4.3, 4.9) */
#define APPM__WARMUP 4                           /* passes on the Knaus-Zwicker schedule (4.7) */
#define APPM__KMIN 8.0                           /* photons seen before the radius adapts (4.7) */
#define APPM__RLO 0.1                            /* lower bound, times r1 j^(-1/6) (4.7) */
#define APPM__RHI 2.0                            /* upper bound, times r1 j^(-1/6) (4.7); appm's caustic one */
#define APPM__KAPPA 1.5                          /* Laplacian bandwidth h = kappa r j^(-1/8) (4.6) */
/* appm's steps (10.4) */
#define APPM__CF_SPLIT (APPM__CF / 2.0)          /* step 1: c_f of each of two components */
#define APPM__LAP_EVERY 8                        /* step 2: after warm-up, dI on every 8th pass */
#define APPM__KAPPA_CAUSTIC 1.25                 /* step 2: the caustic component's kappa (diffuse: KAPPA) */
#define APPM__DI_FLOOR (1.0 / 64.0)              /* step 3: keep >= 1/64 of dI^2 (r at most 2x) */
#define APPM__POOL 1                             /* step 3: dI^2 pooled over (2 POOL + 1)^2 pixels */
#define APPM__RHI_DIFFUSE 3.0                    /* step 5: the diffuse component's upper bound */
#define APPM__RSTART 2.0                         /* step 4: the automatic start radius, times r_auto */
#define APPM__KMIN_APPM 32.0                     /* step 4: photons a component sees before it adapts */
#define APPM__CUT_MMIN 0.2                       /* step 6: the least kernel mass divided by */
#define APPM__CUT_LINES 4                        /* step 6: lines kept per gather (its cut_u, cut_d) */
#define APPM__CUT_WIN 4                          /* step 6: the widest window, (2 W + 1)^2 pixels */
#define APPM__CUT_LAP 1                          /* step 6: the Laplacian's kernels renormalised too */
#define APPM__CUT_FOOT 2.5                       /* step 6: a line counts if a q's foot is this many pixel widths from x's */
#define APPM__CUT_CAND 24                        /* step 6: candidate lines per window */
#define APPM__CBIAS_T 2.0                        /* step 7: measured caustic bias over the model's, to narrow */
#define APPM__CBIAS_Z 2.0                        /* step 7: ... standing this many standard errors from 0 */
#define APPM__CBIAS_PASSES 16.0                  /* step 7: ... over at least this many passes */
#define APPM__CBIAS_SCALE 0.7                    /* step 7: the caustic radius narrowed by this factor */
#define APPM__CBIAS_S2 1.5                       /* step 7: its D_c from the inner radius Rc / sqrt 1.5 */

/* ---- 10.1 The gather's sums ---------------------------------------------------
 *
 * A gather (10.6) visits the photons within its reach of x (the map's query,
 * 7.2) and adds each one's share to the sums of its component: one set of
 * sums for a method with one radius, two (diffuse and caustic photons, each
 * with its own radius) for appm.  Here: what the sums are, how they become a
 * pass's estimates (appm__gather_finish), what a method's table entry holds,
 * and the per-pixel statistics every method shares. */
typedef struct appm__sums { /* one photon component's sums over a gather's photons */
    double e[3];         /* sum of K-weighted gamma (scaled at the end) */
    double eg[3];        /* glossy: sum of K-weighted lobe(wi) gamma */
    double s;            /* sum of K lum(Psi)^2 */
    double dl;           /* sum of D_h lum(Psi) */
    double ei;           /* biweight: sum of K(|d| / R') lum(Psi) at the inner radius R' = R / sqrt 8,
                          * the photons of the same gather: appm's bias estimate (appm__gather_inner) */
    double ecb;          /* the same at R' = R / sqrt 1.5: step 7's test (appm__gather_inner_cbias), for
                          * the caustic component (or a gather's only one) */
    uint64_t count;      /* photons inside the kernel */
} appm__sums;

typedef struct appm__gather {
    appm__v3 x, n, t, b; /* visible point, normal, tangent frame */
    appm__v3 wf;         /* W f (glossy: W Kd / pi, the diffuse part) */
    appm__v3 wg, rd;     /* glossy: W Ks (Ns + 2) / (2 pi) and the lobe's axis */
    float ns;            /* glossy: the exponent */
    int glossy;
    float R;             /* kernel radius */
    float h;             /* Laplacian bandwidth (0: none this pass) */
    float hc;            /* the caustic component's bandwidth (with Rc > 0; appm__caustic_bandwidth) */
    double ihc;          /* 1 / hc (0: none), set by the query */
    double lwc[5];       /* lw (below) for the bandwidth hc, set by the query */
    float R2, Rg2;       /* R^2 and max(R, Rc, 2h, 2hc)^2, set by the query */
    double ih;           /* 1 / h (0: no Laplacian), set by the query */
    double qw[3];        /* off glossy points: the luminance weights times W f, so lum(Psi) =
                          * qw . gamma; set by the query */
    const appm__pmap *map; /* the map being queried (its side[] array), set by the query */
    unsigned max_p;      /* longest photon path that still counts */
    int biweight;
    int inner;           /* biweight: also sum the photons at R / sqrt 8 and R / sqrt 1.5 (appm__sums.ei, ecb) */
    /* [APPM__COMP_DIFFUSE]: every photon, or with Rc > 0 the diffuse ones only;
     * [APPM__COMP_CAUSTIC]: with Rc > 0 the caustic photons, gathered with radius Rc */
    appm__sums sum[APPM__NCOMP];
    float Rc, Rc2;       /* caustic kernel radius (0: one component) and its square */
    /* the kernel cut at a corner (10.4, step 6): lines of the tangent plane beyond which
     * the surface of x does not go; u (in t, b) points from x towards line k, d its distance */
    int ncut;
    float cut_u[APPM__CUT_LINES][2], cut_d[APPM__CUT_LINES];
    double mass;  /* a method that measures and does not cut (APPM__CAP_MASS), on the passes of
                   * appm__mass_pass and where the pixel gathers: the radiance kernel's mass on the
                   * surface, appm__cut_mass of the lines found (1: none, at least APPM__CUT_MMIN);
                   * 0: not measured */
    double lw[5]; /* 1 / the mass of the Laplacian's kernels at x + h t, x - h t, x + h b, x - h b
                   * and x (step 6; 1 without lines), set by the query */
    const appm_scene *scene; /* the covered test (10.6): the scene (NULL: no test), x's triangle, */
    uint32_t tri;
    float cover_eps;         /* the least offset it reads, above x's rounding error, set by the query, */
    float cover;             /* and the distance along n to the first surface in front of x (< 0: not
                              * cast yet; infinite: none within the query's reach) */
    uint64_t *gcount; /* guided emission (9.1): this worker's counts per emission cell; NULL: none */
    double gunit;     /* guided emission: counts per unit of k lum(Psi) (2^16 / (pi M ref)) */
    size_t gpairs;    /* guided emission: where in gcount the pairs per slot start */
} appm__gather;

/* The part of the kernel K_R (biweight or uniform) beyond a line at distance
 * u R from its centre.  Biweight: the 1-D marginal is (16 / (5 pi)) (1 - x^2)^(5/2),
 * and with x = sin th its integral from 0 is (16 / (5 pi)) G(th), G = 5 th / 16 +
 * 15 sin 2th / 64 + 3 sin 4th / 64 + sin 6th / 192.  Uniform: the circular segment. */

static double appm__cut_tail(double u, int biweight)
{
    double th;
    if (!(u < 1.0)) return 0.0;
    if (u < 0.0) return 1.0 - appm__cut_tail(-u, biweight); /* the centre beyond the line */
    if (!biweight) return (acos(u) - u * sqrt(1.0 - u * u)) / APPM__PI;
    { /* sin 2th = 2uc, sin 4th = 2 sin 2th cos 2th, sin 6th = 3 sin 2th - 4 sin^3 2th (c = cos th) */
        double c = sqrt(1.0 - u * u), s2 = 2.0 * u * c, c2 = 1.0 - 2.0 * u * u;
        th = asin(u);
        return 0.5 - (16.0 / (5.0 * APPM__PI)) * (5.0 * th / 16.0 + 15.0 * s2 / 64.0 + 6.0 * s2 * c2 / 64.0 +
                                                  (3.0 * s2 - 4.0 * s2 * s2 * s2) / 192.0);
    }
}

/* The mass m on the surface of x of the kernel K_R centred at x + (sx, sy)
 * (in t, b), inside every cut line of g: the product of what each line leaves
 * (exact for one line, and by symmetry for two perpendicular lines of which
 * one passes through the centre), floored at APPM__CUT_MMIN.  1 without lines. */
static double appm__cut_mass_at(const appm__gather *g, double R, double sx, double sy)
{
    double m = 1.0;
    int k;
    if (!(R > 0.0)) return 1.0;
    for (k = 0; k < g->ncut; ++k)
        m *= 1.0 - appm__cut_tail((g->cut_d[k] - sx * g->cut_u[k][0] - sy * g->cut_u[k][1]) / R, g->biweight);
    return m > APPM__CUT_MMIN ? m : APPM__CUT_MMIN;
}

static double appm__cut_mass(const appm__gather *g, double R) { return appm__cut_mass_at(g, R, 0.0, 0.0); }

/* A method that measures the mass without cutting (APPM__CAP_MASS) measures it
 * on passes 1, 1 + APPM__MASS_EVERY, 1 + 2 APPM__MASS_EVERY, ...: finding the
 * lines costs 5 % of a pass of appm-paper, and the mass is geometry, which
 * changes only with the pixel's jittered point and the slowly shrinking r.
 * The mean of every 4th pass and of every pass gave the same error bar
 * (docs/algorithm.md 7.3). */
#define APPM__MASS_EVERY 4

static int appm__mass_pass(uint64_t j)
{
    return j % APPM__MASS_EVERY == 1 % APPM__MASS_EVERY;
}

/* Turns one component's sums (kernel radius R) into this pass's estimates:
 *   e  = (1/M) sum_i k_R(x - y_i) Psi_i          (the photon term of Ihat_j)
 *   s  = (1/M) sum_i k_R(x - y_i) lum(Psi_i)^2   (the second moment s_j)
 *   dl = (1/M) sum_i D_h(x - y_i) lum(Psi_i)     (the Laplacian estimate)
 * with k_R = K(|d|/R)/R^2 and the kernel constants 1/pi (uniform) or 3/pi
 * (biweight) applied here, once, instead of per photon; divided by the kernel's
 * mass on the surface where the gather has cut lines (10.4, step 6). */
static void appm__sums_finish(const appm__gather *g, double R, double h, const appm__sums *sum, double invM,
                              double *e, double *s, double *dl)
{
    double mass = appm__cut_mass(g, R), norm;
    norm = (g->biweight ? 3.0 : 1.0) / (APPM__PI * R * R * mass);
    e[0] = e[1] = e[2] = *s = *dl = 0.0;
    if (sum->count > 0) {
        e[0] = g->wf.x * sum->e[0] * norm * invM;
        e[1] = g->wf.y * sum->e[1] * norm * invM;
        e[2] = g->wf.z * sum->e[2] * norm * invM;
        if (g->glossy) {
            e[0] += g->wg.x * sum->eg[0] * norm * invM;
            e[1] += g->wg.y * sum->eg[1] * norm * invM;
            e[2] += g->wg.z * sum->eg[2] * norm * invM;
        }
        *s = sum->s * norm * invM / mass;
    }
    if (h > 0.0) *dl = sum->dl * (3.0 / APPM__PI) / (h * h * h * h) * invM;
}

/* The estimates of component c (APPM__COMP_DIFFUSE: of every photon with one
 * component) from a gather: the sums of appm__sums_finish with the radius and
 * the bandwidth of c. */
static void appm__gather_finish(const appm__gather *g, int c, double invM, double *e, double *s, double *dl)
{
    int caustic = c == APPM__COMP_CAUSTIC;
    appm__sums_finish(g, caustic ? g->Rc : g->R, caustic ? g->hc : g->h, &g->sum[c], invM, e, s, dl);
}

/* The luminance of component c's biweight estimate at the inner radius
 * R' = R / sqrt s2 from the same photons (their sum ei), normalised as
 * appm__sums_finish normalises the one at R: by its kernel's mass on the
 * surface at R', where the gather has cut lines.  A kernel estimate's bias is
 * (mu2 / 2) R^2 Delta L to second order, so the difference of the two,
 * D = lum(e) - this, is 1 - 1/s2 of the bias at R: at R / sqrt 8
 * (APPM__INNER_S2, appm__sums.ei) 7/8 of it, from which appm's error bar
 * measures its bias instead of modelling it from the Laplacian
 * (docs/algorithm.md 7.2). */
static double appm__gather_inner_at(const appm__gather *g, int c, double s2, double ei, double invM)
{
    double R = c == APPM__COMP_CAUSTIC ? g->Rc : g->R, Ri2 = R * R / s2;
    if (!g->inner || g->sum[c].count == 0 || !(R > 0.0)) return 0.0;
    return ei * 3.0 / (APPM__PI * Ri2 * appm__cut_mass(g, sqrt(Ri2))) * invM;
}

static double appm__gather_inner(const appm__gather *g, int c, double invM)
{
    return appm__gather_inner_at(g, c, APPM__INNER_S2, g->sum[c].ei, invM);
}

/* The same at R / sqrt 1.5 (APPM__CBIAS_S2), from appm__sums.ecb: step 7's D_c,
 * lum(e) less this, is 1/3 of the bias at R.  The error bar's inner radius is
 * chosen to see as much of a narrow filament's bias as it can (7.4); a test of
 * whether there is a bias wants the most standard errors per unit of bias
 * instead, and for the biweight that grows as R' nears R (appm__caustic_outruns). */
static double appm__gather_inner_cbias(const appm__gather *g, int c, double invM)
{
    return appm__gather_inner_at(g, c, APPM__CBIAS_S2, g->sum[c].ecb, invM);
}

/* The caustic component's Laplacian bandwidth (10.4, step 2), given the
 * diffuse one h and the caustic radius Rc (0: one component, which takes h).
 * A caustic's features are sharper than the diffuse light's (the filaments of
 * light through a glass or a wave), and a wide h flattens them (|dI| falls like
 * h^-4), so its radius stayed at the upper bound: kappa_c = 1.25 against 1.5.
 * Narrower still (1.0) sharpens the caustic more but makes the Laplacian noisy
 * wherever caustic photons are sparse, and the floors around it and smooth
 * caustics (a plane mirror's) lose more than the caustic gains; the diffuse
 * component keeps 1.5 (docs/algorithm.md 5.2, docs/experiments.md). */
static float appm__caustic_bandwidth(float h, float Rc)
{
    return Rc > 0.0f ? (float)(h * (APPM__KAPPA_CAUSTIC / APPM__KAPPA)) : h;
}


/* What a method is and does: its entry in the estimator table (10.5).  The
 * renderer picks the entry once, in appm_renderer_create, and calls only
 * through it; a new method is one entry plus its own functions.  Hooks that a
 * method does not need are NULL.  Per pass j the renderer calls:
 *   start       once, on pass 1, after r1 is known (initialise state)
 *   bandwidth   the Laplacian bandwidth h_j of the pass (0: none this pass)
 *   radius      per pixel: the gather radius of pass j (stored in appm__vp.R)
 *   radius_c    per pixel: the caustic component's radius (appm__vp.Rc; < 0:
 *               the same as the radius; without the hook Rc is 0 and every
 *               photon gathers with R)
 *   commit      per pixel, after the gather: fold it into the state (the
 *               direct term is already committed to appm__pixel)
 *   pass_end    once, after the gather (global schedules)
 * and on request:
 *   photon_term the photon part of the pixel value after j passes (0: none)
 *   bias        the estimated bias of the pixel (luminance), for the error,
 *               and the variance of that estimate's own noise (0: not known)
 *   aux_value   the RADIUS and LAPLACIAN maps (and the per-component radii) */
enum {
    APPM__CAP_PHOTONS = 1,   /* photon passes (else section 11's path tracer)       */
    APPM__CAP_BIWEIGHT = 2,  /* biweight kernel (else uniform)                       */
    APPM__CAP_CUT = 4,       /* the kernel cut at a corner (10.4, step 6)            */
    APPM__CAP_ERROR = 8,     /* keeps an error estimate (appm_stats.est_relerr)      */
    APPM__CAP_MASS = 16,     /* finds the cut's lines, to measure the mass it loses (gather.mass) */
    APPM__CAP_INNER = 32     /* sums its photons at R / sqrt 8 and R / sqrt 1.5 too, to measure its bias
                              * (7.2, gather.inner) */
};

typedef struct appm__field { /* one field of a method's per-pixel state */
    const char *name;
    size_t offset;           /* bytes from the start of the state */
    unsigned count;          /* values */
    unsigned is_u64;         /* 1: uint64_t values, 0: doubles */
} appm__field;

typedef struct appm__estimator {
    const char *name;        /* appm_method_name */
    unsigned caps;           /* APPM__CAP_* */
    unsigned aux;            /* bit (1 << k) for every map k of appm_aux it provides */
    size_t state_size;       /* bytes of per-pixel state (0: none) */
    const appm__field *fields;
    unsigned nfields;
    void (*start)(appm_renderer *r);
    double (*bandwidth)(const appm_renderer *r);
    float (*radius)(const appm_renderer *r, const void *state);
    float (*radius_c)(const appm_renderer *r, const void *state);
    void (*commit)(appm_renderer *r, appm__pixel *px, void *state, const appm__vp *vp, const appm__gather *g,
                   unsigned worker);
    void (*pass_end)(appm_renderer *r);
    int (*photon_term)(const appm_renderer *r, const void *state, double j, double *out);
    double (*bias)(const void *state, double j, double *noise);
    double (*aux_value)(const appm_renderer *r, const void *state, appm_aux which);
} appm__estimator;

/* The method's state of pixel i. */
static void *appm__state(const appm_renderer *r, size_t i)
{
    return r->state + i * r->est->state_size;
}

/* This pass's estimates from a gather (appm__gather_finish); a NaN or inf
 * among them is counted as dropped and the pass contributes 0 instead. */
static void appm__drop_nonfinite(appm_renderer *r, unsigned worker, double *e, double *s, double *dl)
{
    if (!(e[0] - e[0] == 0.0 && e[1] - e[1] == 0.0 && e[2] - e[2] == 0.0 && *s - *s == 0.0 &&
          *dl - *dl == 0.0)) {
        r->dropped[worker]++;
        e[0] = e[1] = e[2] = *s = *dl = 0.0;
    }
}

/* Component c's estimates of this pass, checked. */
static void appm__gather_estimates(appm_renderer *r, const appm__gather *g, int c, unsigned worker, double *e,
                                   double *s, double *dl)
{
    appm__gather_finish(g, c, 1.0 / (double)r->M, e, s, dl);
    appm__drop_nonfinite(r, worker, e, s, dl);
}

/* Welford update of the per-pass estimate's luminance (for the noise estimate). */
static void appm__welford(appm__pixel *p, uint64_t j, double v)
{
    double d = v - p->wmean;
    p->wmean += d / (double)j;
    p->wm2 += d * (v - p->wmean);
}

/* With K >= 2 chains (section 2.3): the sum of a pixel's per-pass luminances in
 * each chain, sums[0 .. K-1]. */
static void appm__chain_add(double *sums, unsigned K, uint64_t j, double v)
{
    if (sums) sums[(j - 1) % K] += v;
}

/* Pixel i's chain sums, or NULL with one chain. */
static double *appm__chain_sums(const appm_renderer *r, size_t i)
{
    return r->chain_sum ? r->chain_sum + i * r->chains : NULL;
}

/* The per-pass estimate v of pixel px in this pass, for the noise estimate:
 * its Welford statistics, its chain's sum and, after a power of two of
 * passes, the sums of the two halves (appm__var_scales). */
static void appm__pass_value(appm_renderer *r, appm__pixel *px, double v)
{
    appm__welford(px, r->pass, v);
    appm__chain_add(appm__chain_sums(r, (size_t)(px - r->pix)), r->chains, r->pass, v);
    if ((r->pass & (r->pass - 1)) == 0) {
        px->lh[0] = px->lh[1];
        px->lh[1] = px->wmean * (double)r->pass;
    }
}

/* The variance of a pixel's mean over j passes (luminance).
 *   independent passes (random): Var = s^2 / j with s^2 = M2 / (j - 1).
 *   one sequence (qmc, 1 chain): the same formula.  Successive passes are then
 *           negatively correlated (that is the point of the sequence), so it
 *           overstates the error where the sequence helps: an upper bound,
 *           which appm__var_scales brings down to size.
 *   K >= 2 chains (sums, section 2.3): independent randomizations.  With n_c
 *           passes and mean m_c in chain c and the overall mean m,
 *           sum_c n_c (m_c - m)^2 has expectation (K - 1) sigma^2, sigma^2 / n_c
 *           the variance of a chain mean (one-way analysis of variance), so
 *           Var(m) = sum_c n_c (m_c - m)^2 / ((K - 1) j).  K - 1 degrees of
 *           freedom per pixel, many over an image. */
static double appm__mean_var(const appm__pixel *p, const double *sums, unsigned chains, uint64_t j)
{
    double m = 0.0, ss = 0.0;
    uint64_t k, K = j < chains ? j : chains;
    if (j < 2) return 0.0;
    if (!sums || chains < 2) return p->wm2 / ((double)(j - 1) * (double)j);
    for (k = 0; k < K; ++k) m += sums[k];
    m /= (double)j;
    for (k = 0; k < K; ++k) {
        double n = (double)(j / chains + (k < j % chains)), d = sums[k] / n - m;
        ss += n * d * d;
    }
    return ss / ((double)(K - 1) * (double)j);
}

/* The recursive (Yamato) mean of ppm and the adaptive methods after pass j:
 *   I_j = I_{j-1} + (Ihat_j - I_{j-1}) / j   (algorithm.md 1). */
static void appm__mean_update(double *I, uint64_t pass, const double *e)
{
    double j = (double)pass;
    int c;
    for (c = 0; c < 3; ++c) I[c] += (e[c] - I[c]) / j;
}

/* Whether a pixel's radius R sits at a bound of [lo, hi] (appm_stats.clamped). */
static int appm__at_bound(double R, double lo, double hi)
{
    return R <= lo * (1.0 + 1e-6) || R >= hi * (1.0 - 1e-6);
}

/* ---- 10.2 Baselines: ppm and sppm ----------------------------------------------
 *
 * Per-pixel state of each method (beside appm__pixel, which all share), named
 * after its paper's symbols as pbrt-v4's SPPMPixel is.  Plain doubles and
 * 64-bit counts only: the estimator table lists them field by field, so they
 * can be written and read back one by one (section 13). */

/* -- ppm (Knaus-Zwicker 2011): one global radius, r_{j+1}^2 = r_j^2 (j + alpha) / (j + 1)
 *    (algorithm.md 2.3), the pixel the plain mean of the Ihat_j. */
typedef struct appm__ppm_state {
    double I[3];    /* running mean I_j of the per-pass estimates Ihat_j (photon term) */
} appm__ppm_state;

static const appm__field appm__ppm_fields[] = {{"I", offsetof(appm__ppm_state, I), 3, 0}};

static void appm__ppm_start(appm_renderer *r) { r->ppm.R2 = r->r1 * r->r1; }

static float appm__ppm_radius(const appm_renderer *r, const void *state)
{
    (void)state;
    return (float)sqrt(r->ppm.R2);
}

static void appm__ppm_commit(appm_renderer *r, appm__pixel *px, void *state, const appm__vp *vp,
                             const appm__gather *g, unsigned worker)
{
    appm__ppm_state *ppm = (appm__ppm_state *)state;
    double e[3], s, dl;
    appm__gather_estimates(r, g, APPM__COMP_DIFFUSE, worker, e, &s, &dl);
    appm__mean_update(ppm->I, r->pass, e);
    appm__pass_value(r, px, (double)appm__lum(vp->ld) + appm__lumd(e));
}

static void appm__ppm_pass_end(appm_renderer *r)
{
    r->ppm.R = sqrt(r->ppm.R2);
    r->ppm.R2 *= ((double)r->pass + r->alpha) / ((double)r->pass + 1.0);
}

/* The photon term of a method whose state begins with its running mean I[3]
 * (ppm and appm-paper: the pixel is the plain mean of the Ihat_j). */
static int appm__mean_term(const appm_renderer *r, const void *state, double j, double *out)
{
    const double *I = (const double *)state;
    (void)r;
    (void)j;
    out[0] = I[0];
    out[1] = I[1];
    out[2] = I[2];
    return 1;
}

static double appm__ppm_aux(const appm_renderer *r, const void *state, appm_aux which)
{
    (void)state;
    (void)which; /* RADIUS only */
    return r->ppm.R;
}

/* -- sppm (Hachisuka-Jensen 2009): after a pass that found m photons with flux
 *    Phi: N' = N + alpha m, R' = R sqrt(N' / (N + m)), tau' = (tau + Phi) R'^2 / R^2
 *    (algorithm.md 2.2); L = tau / (j M pi R^2). */
typedef struct appm__sppm_state {
    double tau[3];  /* tau: accumulated flux, rescaled to the current radius */
    double N;       /* N: accumulated photon count (alpha-weighted, so not whole) */
    double R;       /* R: radius of the next gather */
} appm__sppm_state;

static const appm__field appm__sppm_fields[] = {{"tau", offsetof(appm__sppm_state, tau), 3, 0},
                                                {"N", offsetof(appm__sppm_state, N), 1, 0},
                                                {"R", offsetof(appm__sppm_state, R), 1, 0}};

static void appm__sppm_start(appm_renderer *r)
{
    size_t i, npix = (size_t)r->w * r->h;
    for (i = 0; i < npix; ++i) ((appm__sppm_state *)appm__state(r, i))->R = r->r1;
}

static float appm__sppm_radius(const appm_renderer *r, const void *state)
{
    (void)r;
    return (float)((const appm__sppm_state *)state)->R;
}

static void appm__sppm_commit(appm_renderer *r, appm__pixel *px, void *state, const appm__vp *vp,
                              const appm__gather *g, unsigned worker)
{
    appm__sppm_state *sppm = (appm__sppm_state *)state;
    const appm__sums *sum = &g->sum[APPM__COMP_DIFFUSE];
    double R = sppm->R, N_new, R_new, ratio, phi[3];
    int c;
    (void)px;
    (void)vp;
    if (sum->count == 0) return;
    N_new = sppm->N + r->alpha * (double)sum->count;
    R_new = R * sqrt(N_new / (sppm->N + (double)sum->count));
    ratio = (R_new * R_new) / (R * R);
    phi[0] = g->wf.x * sum->e[0] + g->wg.x * sum->eg[0]; /* the lobe's part: 0 off glossy points */
    phi[1] = g->wf.y * sum->e[1] + g->wg.y * sum->eg[1];
    phi[2] = g->wf.z * sum->e[2] + g->wg.z * sum->eg[2];
    if (phi[0] - phi[0] == 0.0 && phi[1] - phi[1] == 0.0 && phi[2] - phi[2] == 0.0) {
        for (c = 0; c < 3; ++c) sppm->tau[c] = (sppm->tau[c] + phi[c]) * ratio;
        sppm->N = N_new;
        sppm->R = R_new;
    } else {
        r->dropped[worker]++;
    }
}

static int appm__sppm_term(const appm_renderer *r, const void *state, double j, double *out)
{
    const appm__sppm_state *sppm = (const appm__sppm_state *)state;
    int c;
    if (!(sppm->R > 0.0)) return 0;
    for (c = 0; c < 3; ++c) out[c] = sppm->tau[c] / (j * (double)r->M * APPM__PI * sppm->R * sppm->R);
    return 1;
}

static double appm__sppm_aux(const appm_renderer *r, const void *state, appm_aux which)
{
    (void)r;
    (void)which; /* RADIUS only: the radius of the next gather */
    return ((const appm__sppm_state *)state)->R;
}


/* ---- 10.3 The paper's APPM (--method appm-paper; algorithm.md 4.1 - 4.8) ------
 *
 * Kaplanyan and Dachsbacher's selector as algorithm.md derives it, one photon
 * component, in the order of the pseudocode of 4.8.  Per pixel and pass j:
 *   radius (4.3, 4.7)  r_j = [c_f R(K) S / (M j mu2^2 dI^2)]^(1/6), c_f = 2/3:
 *                      the minimiser of MSE(r) = R(K) S / (M j r^2) + (mu2 r^2 dI / 2)^2
 *                      (4.2), after a warm-up on the Knaus-Zwicker schedule
 *                      r1 j^(-1/6), changing at most 2x per pass, and inside
 *                      [RLO, RHI] r1 j^(-1/6) so that r shrinks at the optimal rate;
 *   gather (4.4 - 4.6) within r the kernel estimate e and the second moment s,
 *                      within 2h the 5-point finite-difference Laplacian dl with
 *                      bandwidth h_j = kappa r1 j^(-1/8), every pass;
 *   update             the running means I, S and dI (weight 1/j each).
 * The image is Ld / j + I; the bias estimate (mu2 / 2) dI mean(r^2), and for
 * the error bar alone the seam's, from the mean mass m of the kernel on the
 * surface (appm__paper_seam). */
typedef struct appm__paper_state {
    double I[3];    /* running mean I_j of the photon term */
    double S;       /* running mean of the kernel's second moment s_j (4.4) */
    double dI;      /* running mean of the per-vertex Laplacians, DeltaI (4.5) */
    double R;       /* r_j, the radius of the last gather */
    double R2sum;   /* sum of r_j^2, for the bias estimate */
    double m;       /* mean of the kernel's mass on the surface m_j over the gathers measured (1 off
                     * the seams; 0 before the first) */
    uint64_t N;     /* photons found so far */
    uint64_t Nm;    /* gathers whose mass was measured */
} appm__paper_state;

static const appm__field appm__paper_fields[] = {
    {"I", offsetof(appm__paper_state, I), 3, 0},   {"S", offsetof(appm__paper_state, S), 1, 0},
    {"dI", offsetof(appm__paper_state, dI), 1, 0}, {"R", offsetof(appm__paper_state, R), 1, 0},
    {"R2sum", offsetof(appm__paper_state, R2sum), 1, 0}, {"m", offsetof(appm__paper_state, m), 1, 0},
    {"N", offsetof(appm__paper_state, N), 1, 1}, {"Nm", offsetof(appm__paper_state, Nm), 1, 1}};

/* 4.3: the closed-form minimiser of MSE(r) = R(K) S / (M j r^2) + (mu2 r^2 dI / 2)^2
 * (set dMSE/dr = 0):  r^6 = c_f R(K) S / (M j mu2^2 dI^2), for Mj = M j.  Takes
 * dI^2; returns 0 when the formula has no finite positive answer (S or dI^2
 * zero, NaN, inf). */
static double appm__r_opt(double S, double dI2, double Mj, double cf)
{
    double den = Mj * APPM__MU2 * APPM__MU2 * dI2, r6;
    if (!(S > 0.0) || !(den > 0.0) || !(den < HUGE_VAL)) return 0.0;
    r6 = cf * APPM__RK * S / den;
    return (r6 > 0.0 && r6 < HUGE_VAL) ? pow(r6, 1.0 / 6.0) : 0.0;
}

/* j^(-1/6) of the renderer's pass, by which the radius and its bounds shrink:
 * computed once a pass (pow is most of the radius's cost), or here for a
 * caller between passes. */
static double appm__pass_shrink(const appm_renderer *r)
{
    return r->shrink_pass == r->pass && r->shrink > 0.0 ? r->shrink : pow((double)r->pass, -1.0 / 6.0);
}

/* 4.7: the bounds of pass j, [RLO, RHI] r1 j^(-1/6) (shrink = j^(-1/6)). */
static void appm__paper_bounds(double r1, double shrink, double *lo, double *hi)
{
    *lo = APPM__RLO * r1 * shrink;
    *hi = APPM__RHI * r1 * shrink;
}

/* 4.8 step 2: the radius of pass j from the statistics after j - 1 passes. */
static double appm__paper_radius_of(const appm__paper_state *p, double r1, uint64_t M, uint64_t j, double shrink)
{
    double lo, hi, rad = r1 * shrink; /* Knaus-Zwicker (alpha = 2/3): the warm-up and the fallback */
    appm__paper_bounds(r1, shrink, &lo, &hi);
    if (j > APPM__WARMUP && p->N >= APPM__KMIN && p->S > 0.0 && p->dI - p->dI == 0.0 && p->dI != 0.0) {
        rad = appm__r_opt(p->S, p->dI * p->dI, (double)M * (double)j, APPM__CF);
        if (rad == 0.0) rad = hi;                 /* dI^2 so small that r^6 overflows: flat */
        if (rad < 0.5 * p->R) rad = 0.5 * p->R; /* at most a factor 2 per pass */
        if (rad > 2.0 * p->R) rad = 2.0 * p->R;
    }
    if (!(rad >= lo)) rad = lo; /* also catches NaN */
    return rad > hi ? hi : rad;
}

static float appm__paper_radius(const appm_renderer *r, const void *state)
{
    return (float)appm__paper_radius_of((const appm__paper_state *)state, r->r1, r->M, r->pass,
                                        appm__pass_shrink(r));
}

/* 4.6: the Laplacian's bandwidth h_j = kappa r1 j^(-1/8), every pass. */
static double appm__paper_bandwidth(const appm_renderer *r)
{
    return APPM__KAPPA * r->r1 * pow((double)r->pass, -1.0 / 8.0);
}

/* 4.8 step 4: this pass's e, s and dl (divided by M) into the running means. */
static void appm__paper_commit(appm_renderer *r, appm__pixel *px, void *state, const appm__vp *vp,
                               const appm__gather *g, unsigned worker)
{
    appm__paper_state *p = (appm__paper_state *)state;
    double j = (double)r->pass, e[3], s, dl;
    appm__gather_estimates(r, g, APPM__COMP_DIFFUSE, worker, e, &s, &dl);
    appm__mean_update(p->I, r->pass, e);
    p->S += (s - p->S) / j;
    p->dI += (dl - p->dI) / j;
    p->N += g->sum[APPM__COMP_DIFFUSE].count;
    p->R = vp->R;
    p->R2sum += p->R * p->R;
    if (g->mass > 0.0) {
        p->Nm++;
        p->m += (g->mass - p->m) / (double)p->Nm;
    }
    appm__pass_value(r, px, (double)appm__lum(vp->ld) + appm__lumd(e));
}

/* appm_stats.clamped: the fraction of this pass's gathering pixels whose
 * radius sits at a bound. */
static void appm__paper_pass_end(appm_renderer *r)
{
    size_t i, npix = (size_t)r->w * r->h;
    uint64_t n = 0, at = 0;
    double lo, hi;
    appm__paper_bounds(r->r1, appm__pass_shrink(r), &lo, &hi);
    for (i = 0; i < npix; ++i) {
        if (r->vp[i].segs == 0 || r->vp[i].segs >= r->max_depth) continue;
        n++;
        at += (uint64_t)appm__at_bound(((const appm__paper_state *)appm__state(r, i))->R, lo, hi);
    }
    r->stats.clamped = n ? (double)at / (double)n : 0.0;
}

/* The bias at a seam, where the surface ends inside the kernel (10.4, step 6,
 * which appm-paper does not take): pass j's photon estimate is m_j L there,
 * so the mean I = m L, m the mean of the m_j over the passes that gather (a
 * pass whose point sees no surface adds 0 to I, rightly, and no m_j), and the
 * bias I - L = I (1 - 1/m).  A first-order term that no r^2 model holds:
 * without it the error estimate of the empty white box read 0.42 of the truth
 * at 64 passes (bench/errparts, 12 seeds; docs/algorithm.md 7.3). */
static double appm__paper_seam(const appm__paper_state *p)
{
    return p->m > 0.0 && p->m < 1.0 ? appm__lumd(p->I) * (1.0 - 1.0 / p->m) : 0.0;
}

/* 4.2: the bias (mu2 / 2) dI r^2, with r^2 the mean over the passes, and the
 * seam's.  The paper keeps no spread of dI: its noise is not known. */
static double appm__paper_bias(const void *state, double j, double *noise)
{
    const appm__paper_state *p = (const appm__paper_state *)state;
    *noise = 0.0;
    return 0.5 * APPM__MU2 * p->dI * (p->R2sum / j) + appm__paper_seam(p);
}

static double appm__paper_aux(const appm_renderer *r, const void *state, appm_aux which)
{
    const appm__paper_state *p = (const appm__paper_state *)state;
    (void)r;
    return which == APPM_AUX_LAPLACIAN ? p->dI : p->R;
}


/* ---- 10.4 appm: the paper's selector and seven steps on top (the default) ------
 *
 * appm is 10.3 with these steps, each named where the code takes it and each
 * kept for the reason measured (docs/algorithm.md 5.1 - 5.6 and 5.13, the figures
 * in docs/experiments.md):
 *   step 1  two photon components, caustic (the last bounce specular) and
 *           diffuse, each with its own statistics and radius, c_f halved:
 *           a caustic over a smooth floor no longer shares the floor's wide
 *           kernel (toy of algorithm.md 5.1: RMSE at the caustic 0.052 -> 0.024);
 *   step 2  the Laplacian on the warm-up passes and then every 8th, with
 *           h = kappa r_auto j^(-1/8) from the automatic radius, averaged with
 *           inverse-variance weights h^6: a wide bandwidth on a few passes
 *           beats a narrow one on every pass at the same cost (5.2);
 *   step 3  dI^2 corrected for its noise and pooled over the 3x3 neighbours
 *           on the same surface: a noisy dI^2 otherwise narrows the radius
 *           where photons are sparse (5.3);
 *   step 4  a pixel that has seen fewer than KMIN photons doubles its radius
 *           each pass (a k-nearest-neighbour radius) instead of waiting, and
 *           the caustic radius follows the diffuse one until it has seen KMIN
 *           caustic photons (5.4);
 *   step 5  bounds from both r1 and r_auto, the diffuse component's upper one
 *           3 (not 2): 0.94x the RMSE on CornellBox-Original at an equal
 *           instruction count, at most 2.2 % worse on three other scenes (5.5);
 *   step 6  the kernel cut at a corner: where the surface ends inside the
 *           kernel, the estimate is divided by the kernel's mass on it: the
 *           seams of a box were 8 % dark; equal-pass RMSE 0.73x on
 *           CornellBox-Original (5.6);
 *   step 7  the caustic radius 0.7x as wide where the caustic's measured
 *           bias (at Rc and Rc / sqrt 1.5) outruns the model's: a filament
 *           narrower than the Laplacian's bandwidth, not a flat mirror's
 *           smooth light (5.13).
 * The pixel's photon term is the sum of the components', and so is its bias
 * (mu2 / 2) sum_c r_c^2 dI_c (the biases add before they are squared).  The
 * error bar measures that bias rather than modelling it: D_j, the pass's photon
 * term at r less the same photons' at r / sqrt 8, is 7/8 of the bias of the pass
 * to second order (appm__gather_inner), and the pixel keeps the mean and the
 * spread of the D_j over all its passes. */
typedef struct appm__adaptive_stats { /* the statistics of one photon component */
    double I[3];    /* running mean I_j of the photon term */
    double S;       /* running mean of the kernel second moment s_j */
    double dI;      /* weighted running mean of the per-pass Laplacians (step 2) */
    double dI_w;    /* sum of their weights (h_j / r_auto)^6 */
    double dI_m2;   /* weighted Welford M2 of the per-pass Laplacians (their spread, step 3) */
    double R;       /* radius r_j of the last gather */
    uint64_t N;     /* photons found so far */
    double dI2p;    /* step 3: dI^2 pooled over neighbours after the last Laplacian pass (0: none) */
} appm__adaptive_stats;

typedef struct appm__adaptive_px { /* appm's per-pixel state: one record per photon component (step 1) */
    appm__adaptive_stats comp[APPM__NCOMP]; /* [APPM__COMP_DIFFUSE], [APPM__COMP_CAUSTIC] */
    double D, D_m2; /* Welford mean and M2 over the passes of D_j, summed over the components */
    /* step 7: over the passes since the caustic component adapts, the Welford mean
     * and M2 of its own D_j (at Rc and Rc / sqrt 1.5), their count, and the mean
     * of what the model predicts of them, (1/3) (mu2 / 2) Rc_j^2 dI_c */
    double Dc, Dc_m2, Dc_n, Pc;
} appm__adaptive_px;

#define APPM__KOFF(c, f) \
    (offsetof(appm__adaptive_px, comp) + (c) * sizeof(appm__adaptive_stats) + offsetof(appm__adaptive_stats, f))
#define APPM__KFIELDS(c, x) \
    {"I" x, APPM__KOFF(c, I), 3, 0}, {"S" x, APPM__KOFF(c, S), 1, 0}, {"dI" x, APPM__KOFF(c, dI), 1, 0}, \
        {"dI_w" x, APPM__KOFF(c, dI_w), 1, 0}, {"dI_m2" x, APPM__KOFF(c, dI_m2), 1, 0}, \
        {"R" x, APPM__KOFF(c, R), 1, 0}, {"N" x, APPM__KOFF(c, N), 1, 1}, {"dI2p" x, APPM__KOFF(c, dI2p), 1, 0}
static const appm__field appm__adaptive_fields[] = {
    APPM__KFIELDS(APPM__COMP_DIFFUSE, "_d"), APPM__KFIELDS(APPM__COMP_CAUSTIC, "_c"),
    {"D", offsetof(appm__adaptive_px, D), 1, 0}, {"D_m2", offsetof(appm__adaptive_px, D_m2), 1, 0},
    {"Dc", offsetof(appm__adaptive_px, Dc), 1, 0}, {"Dc_m2", offsetof(appm__adaptive_px, Dc_m2), 1, 0},
    {"Dc_n", offsetof(appm__adaptive_px, Dc_n), 1, 0}, {"Pc", offsetof(appm__adaptive_px, Pc), 1, 0}};

/* -- Step 1: two components.  I = I_c + I_d, the caustic and diffuse photons
 * gathered with radii r_c, r_d; independent noise, so MSE = sum_k A_k / r_k^2 +
 * (b_c r_c^2 + b_d r_d^2)^2, A_k = R(K) S_k / (M j), b_k = mu2 dI_k / 2.  The
 * bias terms add before squaring, so the radii are coupled; the joint
 * minimiser diverges where b_c b_d < 0 (the biases cancel), and that sign is
 * what a noisy Laplacian cannot tell.  (a + b)^2 <= 2a^2 + 2b^2 bounds the MSE by
 * a separable sum whose minimiser is 4.3's formula per component with c_f / 2
 * (APPM__CF_SPLIT): exact for equal biases, 5 % of MSE off when one dominates
 * (algorithm.md 5.1). */

/* -- Step 2: the Laplacian's schedule.  Whether pass j estimates the Laplacian.
 * Its gather reaches 2h, several times the area of the radiance kernel, so it
 * is the expensive part of a pass.  For a fixed cost f h^2 (f: the fraction of
 * passes that estimate it), the variance of the running mean dI goes as
 * 1 / (f h^6) = 1 / (cost h^4): a wide bandwidth on a few passes beats a narrow
 * one on every pass.  The price is smoothing bias in dI, of which r only feels
 * the cube root.  Every pass of the warm-up estimates it, then every
 * APPM__LAP_EVERY-th. */
static int appm__lap_pass(uint64_t j)
{
    return j <= APPM__WARMUP || (j - APPM__WARMUP) % APPM__LAP_EVERY == 0;
}

/* Laplacian passes among the first j. */
static uint64_t appm__lap_count(uint64_t j)
{
    return j <= APPM__WARMUP ? j : APPM__WARMUP + (j - APPM__WARMUP) / APPM__LAP_EVERY;
}

/* The bandwidth of pass j: h_j = kappa r_auto j^(-1/8), from the automatic
 * radius r_auto (section 12) rather than r1, shrinking more slowly than r
 * (docs/algorithm.md 4.6).  It deliberately does not follow the pixel's
 * adaptive radius: with h = kappa r, a sharp feature seen through a wide h
 * looks flat (|dI| falls like h^-4), which licenses a wider r, which keeps h
 * wide - a start with a large radius would never come back. */
static double appm__lap_h(double r_auto, uint64_t j)
{
    return APPM__KAPPA * r_auto * pow((double)j, -1.0 / 8.0);
}

static double appm__adaptive_bandwidth(const appm_renderer *r)
{
    return appm__lap_pass(r->pass) ? appm__lap_h(r->r_auto, r->pass) : 0.0;
}

/* The statistics after pass j: the mean I and likewise S, as in 10.3; dI the
 * weighted mean over the passes that estimate the Laplacian (weight dl_weight,
 * 0 on the others); the photon count. */
static void appm__adaptive_update(appm__adaptive_stats *p, uint64_t pass, const double *e, double s, double dl,
                                  double dl_weight, uint64_t count)
{
    double j = (double)pass;
    appm__mean_update(p->I, pass, e);
    p->S += (s - p->S) / j;
    if (dl_weight > 0.0) {
        /* inverse-variance weighted mean (West 1979): a Laplacian from bandwidth
         * h has variance ~ 1/h^6, and h shrinks with j, so equal weights would
         * let the later, noisier estimates dominate */
        double d = dl - p->dI;
        p->dI_w += dl_weight;
        p->dI += d * (dl_weight / p->dI_w);
        p->dI_m2 += dl_weight * d * (dl - p->dI);
    }
    p->N += count;
}

/* -- Step 3: dI^2 without its noise, pooled.  Var(dI), the variance of the
 * weighted mean of n Laplacian passes from their weighted Welford sum (0 before
 * two); dI^2 - Var(dI), an unbiased estimate of the square of the true
 * Laplacian (may be negative). */
static double appm__di_var(const appm__adaptive_stats *p, uint64_t n)
{
    return n >= 2 && p->dI_w > 0.0 ? p->dI_m2 / ((double)(n - 1) * p->dI_w) : 0.0;
}

static double appm__di2_unbiased(const appm__adaptive_stats *p, uint64_t n)
{
    return p->dI * p->dI - appm__di_var(p, n);
}

/* dI^2 for the radius formula.  The square of a noisy mean overestimates the
 * square of its expectation: E[dI^2] = dI_true^2 + Var(dI).  So the variance of
 * the weighted mean is taken off, keeping at least APPM__DI_FLOOR of dI^2: where
 * the Laplacian is mostly noise, the radius grows (less noise, more bias)
 * instead of collapsing.  With per-pass variances c / w_j, the weighted Welford
 * sum M2 estimates (n - 1) c, and the mean's variance is c / sum(w). */
static double appm__di2(const appm__adaptive_stats *p, uint64_t n)
{
    double d2 = p->dI * p->dI, c = appm__di2_unbiased(p, n);
    return c > APPM__DI_FLOOR * d2 ? c : APPM__DI_FLOOR * d2;
}

/* dI^2 of each component of pixel i (into out) pooled over the pixels of the
 * (2 APPM__POOL + 1)^2 window whose visible points this pass lie within h of
 * its own on the same surface (normals within 25 degrees) and that have seen
 * APPM__KMIN_APPM photons of the component: the mean of their unbiased estimates
 * dI_q^2 - Var(dI_q), floored at APPM__DI_FLOOR times the mean dI_q^2. */
static void appm__pool_di2(const appm_renderer *r, size_t i, uint64_t n, double h, double *out)
{
    const appm__vp *v = &r->vp[i];
    int64_t x0 = (int64_t)(i % r->w), y0 = (int64_t)(i / r->w), dx, dy;
    double sum[APPM__NCOMP] = {0.0, 0.0}, sq[APPM__NCOMP] = {0.0, 0.0}, m[APPM__NCOMP] = {0.0, 0.0};
    int c;
    for (dy = -APPM__POOL; dy <= APPM__POOL; ++dy)
        for (dx = -APPM__POOL; dx <= APPM__POOL; ++dx) {
            int64_t x = x0 + dx, y = y0 + dy;
            size_t q;
            const appm__adaptive_px *a;
            appm__v3 d;
            if (x < 0 || y < 0 || x >= (int64_t)r->w || y >= (int64_t)r->h) continue;
            q = (size_t)(y * (int64_t)r->w + x);
            a = (const appm__adaptive_px *)appm__state(r, q);
            d = appm__sub(r->vp[q].x, v->x);
            if (q != i && (r->vp[q].segs == 0 || !((double)appm__dot(d, d) < h * h) ||
                           !(appm__dot(r->vp[q].n, v->n) > 0.9f)))
                continue;
            for (c = 0; c < APPM__NCOMP; ++c) {
                const appm__adaptive_stats *p = &a->comp[c];
                if (q != i && p->N < APPM__KMIN_APPM) continue;
                sum[c] += appm__di2_unbiased(p, n);
                sq[c] += p->dI * p->dI;
                m[c] += 1.0;
            }
        }
    for (c = 0; c < APPM__NCOMP; ++c) {
        double s = sum[c] / m[c], f = sq[c] * APPM__DI_FLOOR / m[c];
        out[c] = s > f ? s : f;
    }
}

/* After a Laplacian pass j, each pixel's pooled dI^2 (appm__adaptive_stats.dI2p)
 * from the state after j passes and this pass's visible points; read by the
 * radii of the passes up to the next Laplacian pass.  Each pixel writes only
 * its own dI2p, which no pixel reads here. */
static void appm__pool_task(void *arg, uint32_t row, unsigned worker)
{
    appm_renderer *r = (appm_renderer *)arg;
    uint64_t n = appm__lap_count(r->pass);
    double h = r->lap_h, out[APPM__NCOMP];
    uint32_t x;
    (void)worker;
    for (x = 0; x < r->w; ++x) {
        size_t i = (size_t)row * r->w + x;
        appm__adaptive_px *a = (appm__adaptive_px *)appm__state(r, i);
        int c;
        if (!r->vp[i].segs || (a->comp[0].N < APPM__KMIN_APPM && a->comp[1].N < APPM__KMIN_APPM)) continue;
        appm__pool_di2(r, i, n, h, out);
        for (c = 0; c < APPM__NCOMP; ++c) a->comp[c].dI2p = out[c];
    }
}

/* -- Steps 4 and 5: the radius.  The bounds of pass j: [RLO min(r1, r_auto),
 * rhi max(r1, r_auto)] j^(-1/6), rhi being APPM__RHI or APPM__RHI_DIFFUSE
 * (shrink = j^(-1/6)). */
static void appm__adaptive_bounds(double r1, double r_auto, double shrink, double rhi, double *lo, double *hi)
{
    *lo = APPM__RLO * (r1 < r_auto ? r1 : r_auto) * shrink;
    *hi = rhi * (r1 > r_auto ? r1 : r_auto) * shrink;
}

/* Radius for pass j from one component's statistics after j-1 passes: 10.3's
 * radius with steps 3 - 5.  r1 is the initial radius, r_auto the automatic
 * one, r0 the radius before the formula has data (the warm-up passes, or no
 * Laplacian yet; r0 j^(-1/6)), cf the constant of the radius formula, di2 the
 * dI^2 to use (< 0 or NaN: the component's own, appm__di2), rhi the upper
 * bound's factor.  Never NaN, 0 or inf: every path ends inside the bounds of
 * appm__adaptive_bounds. */
static double appm__adaptive_radius(double r1, double r_auto, double r0, uint64_t M, uint64_t j, double shrink,
                                    double rhi, const appm__adaptive_stats *p, double cf, double di2)
{
    double lo, hi, rad = r0 * shrink;
    appm__adaptive_bounds(r1, r_auto, shrink, rhi, &lo, &hi);
    if (j > 1 && p->N < APPM__KMIN_APPM && p->R > 0.0) {
        /* step 4: too few photons seen to estimate anything: widen, as a k-nearest-
         * neighbour radius would, instead of waiting at a radius that may be
         * the reason so few photons arrive.  32, not appm-paper's 8: S and the
         * Laplacian of a handful of photons are mostly noise, and the formula
         * read from them shrank sparse pixels too early (caustic-glass after 8
         * passes 0.93-0.95x the RMSE, textured after 256 0.90-0.92x; at equal
         * time, thousands of passes, within noise; docs/algorithm.md 5.4) */
        rad = 2.0 * p->R;
        return rad > hi ? hi : (rad >= lo ? rad : lo);
    }
    if (j > APPM__WARMUP && p->N >= APPM__KMIN_APPM && p->S > 0.0 && p->dI == p->dI && p->dI != 0.0) {
        if (!(di2 >= 0.0)) di2 = appm__di2(p, appm__lap_count(j - 1));
        rad = appm__r_opt(p->S, di2, (double)M * (double)j, cf);
        if (rad == 0.0) rad = hi; /* dI^2 so small the formula overflows: flat */
        if (p->R > 0.0) {
            if (rad < 0.5 * p->R) rad = 0.5 * p->R;
            if (rad > 2.0 * p->R) rad = 2.0 * p->R;
        }
    }
    if (!(rad >= lo)) rad = lo; /* also catches NaN */
    if (rad > hi) rad = hi;
    return rad;
}

/* The same with j^(-1/6) computed here and the caustic bound (the tests' entry). */
APPM__UNUSED static double appm__adaptive_radius_at(double r1, double r_auto, uint64_t M, uint64_t j,
                                                    const appm__adaptive_stats *p, double cf, double di2)
{
    return appm__adaptive_radius(r1, r_auto, r1, M, j, pow((double)j, -1.0 / 6.0), APPM__RHI, p, cf, di2);
}

/* Step 4: the radius before the formula has data.  A radius the user told
 * (--radius) is the start, as promised; the automatic start is APPM__RSTART
 * r_auto.  The warm-up passes stay in the mean, and a few wide ones cost little
 * bias and much noise: after 8 passes caustic-glass's RMSE is 0.86x, water-
 * caustic's 0.82x and the white box's 0.88x that of a start at r_auto, the same
 * after 128 (docs/algorithm.md 5.4).  Not for a told radius: t_appm's toy, whose
 * appm must not depend on r1, doubled its error at r1 = 3 r_auto started twice
 * as wide. */
static double appm__adaptive_start(const appm_renderer *r)
{
    return r->r1_auto ? APPM__RSTART * r->r_auto : r->r1;
}

/* Step 5: each component's upper bound, APPM__RHI_DIFFUSE or APPM__RHI. */
static double appm__comp_rhi(int c) { return c == APPM__COMP_DIFFUSE ? APPM__RHI_DIFFUSE : APPM__RHI; }

static double appm__adaptive_comp_radius(const appm_renderer *r, const appm__adaptive_px *a, int c)
{
    const appm__adaptive_stats *p = &a->comp[c];
    return appm__adaptive_radius(r->r1, r->r_auto, appm__adaptive_start(r), r->M, r->pass, appm__pass_shrink(r),
                                 appm__comp_rhi(c), p, APPM__CF_SPLIT, p->dI2p > 0.0 ? p->dI2p : -1.0);
}

static float appm__adaptive_radius_diffuse(const appm_renderer *r, const void *state)
{
    return (float)appm__adaptive_comp_radius(r, (const appm__adaptive_px *)state, APPM__COMP_DIFFUSE);
}

/* Step 7: whether the caustic's measured bias outruns the model's.  The radius
 * formula weighs noise against the model's bias (mu2 / 2) r^2 dI_c, with dI_c
 * the Laplacian at bandwidth h_c.  Across a filament of focused light narrower
 * than h_c that Laplacian is the filament's, blurred: the model sees too little
 * bias, and the formula sets a radius wider than the one that minimises the
 * error (on caustic-glass, 76 % of the squared error at 30 s is bias, and a
 * caustic radius 0.7x as wide everywhere cut the RMSE to 0.86-0.89x).  But a
 * flat mirror's reflected light (the mirror box's floor) is smooth, its bias
 * small, and there the same narrowing costs 4.5-8 % in noise.  What tells them
 * apart is the bias measured as the error bar measures it (7.2): D_c, the
 * caustic term at Rc less the same photons' at an inner radius Rc / s.  Where
 * the light is smooth across the kernel its mean is 1 - 1/s^2 of the bias, as
 * the model's is, and it does not look through the bandwidth h_c as the model
 * does.  The radius is narrowed where the mean of the D_c stands APPM__CBIAS_Z
 * standard errors from 0 (a bias, not noise) and beyond APPM__CBIAS_T times
 * what the model predicts of it over the same passes, (1 - 1/s^2) (mu2 / 2)
 * Rc_j^2 dI_c (or with the other sign: the model has the bias's sign wrong),
 * after APPM__CBIAS_PASSES such passes.
 *
 * The inner radius is the test's own, s^2 = 1.5 (APPM__CBIAS_S2), not the
 * error bar's 8.  D_c's noise is what hides the bias: in caustic-glass's
 * caustic, where nine tenths of the squared error is bias, the mean of the
 * D_c at Rc / sqrt 8 stood a median of 1 standard error from 0 after 2000
 * passes.  Per unit of a bias smooth across the kernel, a biweight's D at
 * Rc / s has a standard deviation proportional to
 * sqrt(int (K_R - K_R/s)^2) / (1 - 1/s^2) (photons of one power, spread
 * evenly), which falls as s nears 1: relative to s^2 = 8 the test sees 1.45x
 * the standard errors at s^2 = 4, 1.70x at 3, 2.14x at 2, 2.56x at 1.5 and
 * 2.89x at 1.25 (at 1.5 as many as 6.6x the passes would give; 1.9x on the
 * toy's quadratic field in tests/t_appm.c, whose photons' powers vary).  On a
 * filament narrower than the inner radius the trade is smaller: D holds only
 * the part of its bias between the two radii, the less the closer they are.
 * On the toy's ridge 1/8 of R wide D_c reads 9.1 times the prediction at
 * R / sqrt 1.5 against 22 at R / sqrt 8: still well beyond T.  Measured
 * against the error bar's radius (docs/algorithm.md 5.13): caustic-glass
 * 0.91-0.95x the RMSE at 1500 passes (s^2 = 2: 0.94-0.97x, 1.25: 0.92-0.94x),
 * whose caustic's photons spread inside Rc as evenly as a flat mirror's; the
 * textured scene, which lost 0.2-1.7 % to step 7 at the error bar's radius,
 * 0.99-1.00x (1.001-1.008x of 0.1.12's by the product of the ratios); the
 * mirror box 0.996-0.998x. */
static int appm__caustic_outruns(const appm__adaptive_px *a)
{
    double n = a->Dc_n, se;
    if (n < APPM__CBIAS_PASSES) return 0;
    se = sqrt(a->Dc_m2 / ((n - 1.0) * n));
    if (!(fabs(a->Dc) > APPM__CBIAS_Z * se)) return 0;
    return a->Dc > 0.0 ? a->Dc > APPM__CBIAS_T * a->Pc : a->Dc < APPM__CBIAS_T * a->Pc;
}

/* Step 7's sums after a pass whose caustic D_j (at Rc / sqrt 1.5) is d,
 * gathered at radius Rc, with the caustic statistics already updated by the
 * pass: from the pass at which the component adapts (APPM__KMIN_APPM photons)
 * on, the Welford mean and M2 of the D_j and the running mean of the model's
 * prediction of them, whose dI_c is the Laplacian's running mean after that
 * pass. */
static void appm__caustic_bias_add(appm__adaptive_px *a, double d, double Rc)
{
    const appm__adaptive_stats *p = &a->comp[APPM__COMP_CAUSTIC];
    double dd, pred = (1.0 - 1.0 / APPM__CBIAS_S2) * 0.5 * APPM__MU2 * Rc * Rc * p->dI;
    if (p->N < APPM__KMIN_APPM) return;
    a->Dc_n += 1.0;
    dd = d - a->Dc;
    a->Dc += dd / a->Dc_n;
    a->Dc_m2 += dd * (d - a->Dc);
    a->Pc += (pred - a->Pc) / a->Dc_n;
}

/* Step 4: the caustic radius; until the pixel has seen APPM__KMIN_APPM caustic
 * photons it is the diffuse one (returned as -1: "the same"): widening in
 * search of caustic light that may not exist would widen every gather of a
 * scene without any.  Then the formula's, narrowed by step 7 where the
 * caustic's measured bias outruns the model's. */
static float appm__adaptive_radius_caustic(const appm_renderer *r, const void *state)
{
    const appm__adaptive_px *a = (const appm__adaptive_px *)state;
    double rad, lo, hi;
    if (a->comp[APPM__COMP_CAUSTIC].N < APPM__KMIN_APPM) return -1.0f;
    rad = appm__adaptive_comp_radius(r, a, APPM__COMP_CAUSTIC);
    if (appm__caustic_outruns(a)) { /* step 7 */
        appm__adaptive_bounds(r->r1, r->r_auto, appm__pass_shrink(r), APPM__RHI, &lo, &hi);
        rad *= APPM__CBIAS_SCALE;
        if (rad < lo) rad = lo;
    }
    return (float)rad;
}

/* The component with the larger photon term (ties: diffuse): the one whose
 * radius the RADIUS map shows and clamped= counts. */
static int appm__adaptive_dominant(const appm__adaptive_px *a)
{
    return appm__lumd(a->comp[APPM__COMP_CAUSTIC].I) > appm__lumd(a->comp[APPM__COMP_DIFFUSE].I)
               ? APPM__COMP_CAUSTIC
               : APPM__COMP_DIFFUSE;
}

/* A pass's D for one component: its estimate e's luminance less the same
 * photons' estimate at an inner radius; 0 where the pass's estimates were
 * dropped (e and the kernel's second moment m all 0), where it found no
 * photon of the component, or where D is not finite. */
static double appm__pass_d(const double *e, double m, double inner)
{
    double d = appm__lumd(e) - inner;
    return d - d == 0.0 && (e[0] != 0.0 || e[1] != 0.0 || e[2] != 0.0 || m != 0.0) ? d : 0.0;
}

static void appm__adaptive_commit(appm_renderer *r, appm__pixel *px, void *state, const appm__vp *vp,
                                  const appm__gather *g, unsigned worker)
{
    appm__adaptive_px *a = (appm__adaptive_px *)state;
    double e[APPM__NCOMP][3], s[APPM__NCOMP], dl[APPM__NCOMP], hr = g->h / r->r_auto;
    const double invM = 1.0 / (double)r->M;
    double w = g->h > 0.0f ? hr * hr * hr * hr * hr * hr : 0.0; /* step 2's weight (h / r_auto)^6 */
    double D = 0.0, d;
    int c;
    a->comp[APPM__COMP_DIFFUSE].R = vp->R;
    a->comp[APPM__COMP_CAUSTIC].R = vp->Rc;
    for (c = 0; c < APPM__NCOMP; ++c) {
        appm__gather_estimates(r, g, c, worker, e[c], &s[c], &dl[c]);
        appm__adaptive_update(&a->comp[c], r->pass, e[c], s[c], dl[c], w, g->sum[c].count);
        D += appm__pass_d(e[c], s[c], appm__gather_inner(g, c, invM)); /* D_j (7.2) */
        /* step 7's D_c, from its own inner radius; it counts every pass too, an empty
         * one as 0: averaged over the passes that found photons only, D_c would read
         * 1 / (their share) times its mean against a prediction made for every pass */
        if (c == APPM__COMP_CAUSTIC)
            appm__caustic_bias_add(a, appm__pass_d(e[c], s[c], appm__gather_inner_cbias(g, c, invM)), g->Rc);
    }
    d = D - a->D; /* Welford, over every pass: the image's bias is the mean of the passes' */
    a->D += d / (double)r->pass;
    a->D_m2 += d * (D - a->D);
    appm__pass_value(r, px,
                     (double)appm__lum(vp->ld) + appm__lumd(e[APPM__COMP_DIFFUSE]) +
                         appm__lumd(e[APPM__COMP_CAUSTIC]));
}

/* appm_stats.clamped: the fraction of this pass's gathering pixels whose
 * dominant component's radius sits at a bound of its own (appm__adaptive_bounds);
 * after a Laplacian pass, also the pooled dI^2 (step 3). */
static void appm__adaptive_pass_end(appm_renderer *r)
{
    size_t i, npix = (size_t)r->w * r->h;
    uint64_t n = 0, at = 0;
    double lo, hi[APPM__NCOMP], shrink = appm__pass_shrink(r);
    int c;
    if (r->lap_h > 0.0 && r->pass >= APPM__WARMUP) appm__parallel_for(r->threads, r->h, appm__pool_task, r);
    for (c = 0; c < APPM__NCOMP; ++c)
        appm__adaptive_bounds(r->r1, r->r_auto, shrink, appm__comp_rhi(c), &lo, &hi[c]);
    for (i = 0; i < npix; ++i) {
        const appm__adaptive_px *a = (const appm__adaptive_px *)appm__state(r, i);
        if (r->vp[i].segs == 0 || r->vp[i].segs >= r->max_depth) continue;
        c = appm__adaptive_dominant(a);
        n++;
        at += (uint64_t)appm__at_bound(a->comp[c].R, lo, hi[c]);
    }
    r->stats.clamped = n ? (double)at / (double)n : 0.0;
}

static int appm__adaptive_term(const appm_renderer *r, const void *state, double j, double *out)
{
    const appm__adaptive_px *a = (const appm__adaptive_px *)state;
    int c;
    (void)r;
    (void)j;
    for (c = 0; c < 3; ++c) out[c] = a->comp[APPM__COMP_DIFFUSE].I[c] + a->comp[APPM__COMP_CAUSTIC].I[c];
    return 1;
}

/* The bias of the image, measured (docs/algorithm.md 7.2): the mean of the
 * passes' biases (mu2 / 2) r_j^2 Delta L, summed over the components, is
 * APPM__INNER_F = 8/7 times the mean of the D_j, whatever r_j each pass took;
 * *noise is the variance of that estimate, from the spread of the D_j, so that
 * b^2 - noise estimates the squared bias without the noise of D in it. */
static double appm__adaptive_bias(const void *state, double j, double *noise)
{
    const appm__adaptive_px *a = (const appm__adaptive_px *)state;
    *noise = j > 1.0 ? APPM__INNER_F * APPM__INNER_F * a->D_m2 / ((j - 1.0) * j) : 0.0;
    return APPM__INNER_F * a->D;
}

static double appm__adaptive_aux(const appm_renderer *r, const void *state, appm_aux which)
{
    const appm__adaptive_px *a = (const appm__adaptive_px *)state;
    (void)r;
    switch (which) {
    case APPM_AUX_LAPLACIAN: return a->comp[APPM__COMP_DIFFUSE].dI + a->comp[APPM__COMP_CAUSTIC].dI;
    case APPM_AUX_RADIUS_CAUSTIC: return a->comp[APPM__COMP_CAUSTIC].R;
    case APPM_AUX_RADIUS_DIFFUSE: return a->comp[APPM__COMP_DIFFUSE].R;
    default: return a->comp[appm__adaptive_dominant(a)].R;
    }
}

/* -- Step 6: the kernel cut at a corner (docs/algorithm.md 5.6).
 *
 * Where x's surface ends inside the kernel - a wall meeting the floor, the edge
 * of a box's top - the same-surface test keeps the other surface's photons out,
 * and no photon of x's surface lies beyond the edge, so (1/M) sum k_R Psi
 * estimates m L(x), m < 1 the part of the kernel's mass on the surface: a
 * bias of first order, -(1 - m) L, up to half of L at the seam itself and
 * -8 % on average over the pixels next to a seam of CornellBox-Original (32x32,
 * 256 passes, against the path tracer: tests/t_appm.c), which no r^2 term of
 * the MSE model describes.  The remedy is the classic one
 * for a density estimate near the edge of its support: divide by m (and s_j by
 * m^2, the estimate's variance growing with it).
 *
 * m comes from the geometry, not the photons.  The plane of a neighbouring
 * pixel's visible point q, on a surface whose normal is APPM__NORMAL_COS or
 * more from n (so the gather keeps its photons out), meets x's tangent plane
 * in a line, at distance d = |n_q.(x - q)| / |n_q - (n_q.n) n| from x, and x's
 * surface lies on x's side of it: at a concave corner the wall's normal faces
 * x, at a convex edge x lies behind the side's plane, and both give
 * n_q.(x - q) of the sign that puts x inside.  The biweight's mass beyond a line
 * at distance u R is (16 / (5 pi)) int_u^1 (1 - t^2)^(5/2) dt (appm__cut_tail).
 * A line counts only if two neighbours give it (to 0.995 in direction and
 * 0.02 of the reach in distance: a plane, not a curved surface, whose normals turn from
 * pixel to pixel), only if q lies near it (within 2 W pixel widths, so that a
 * surface seen beside x across a depth step, whose plane only extended would
 * meet x's, does not count), only if one of them has its foot on the line
 * within APPM__CUT_FOOT pixel widths of x's (the other surface meets x's only
 * where its pixels show it: beyond the end of a box's face, its plane extended
 * would cut a floor that goes on; measured against ray-cast masses) and
 * only within reach of x (the largest radius of
 * the gather, or 2h on the passes that estimate the Laplacian).  The
 * candidates are the pixels of the (2W+1)^2 window, W = reach / (pixel width)
 * + 1 (at most APPM__CUT_WIN), that
 * have a 4-neighbour on another surface (edge_dist, set with the radii): a
 * line between two pixels separates two 4-neighbours.  Several lines (the
 * APPM__CUT_LINES nearest): the product of what each leaves (exact for one, and for two perpendicular lines
 * of which one passes through x).  m is floored at APPM__CUT_MMIN.
 *
 * The Laplacian's 5-point stencil (4.6) is cut as well, each of its kernels
 * by its own amount (centred at x +- h t, x +- h b, possibly beyond the line,
 * where more than half of it is gone), and uncorrected reads the edge as
 * curvature; each is divided by its own mass (gather.lw, APPM__CUT_LAP), with
 * the lines sought within 2h on the passes that estimate it.  Not corrected:
 * the first-order remainder R grad L . c (c the centroid of the kept part),
 * and a surface that ends where no pixel sees its neighbour (the image's
 * border, a hidden side).  Only appm cuts (APPM__CAP_CUT): ppm, sppm and
 * appm-paper keep their papers' estimators; appm-paper finds the lines only to
 * measure the mass its kernel loses, for its error bar (APPM__CAP_MASS). */
/* Whether a 4-neighbour of pixel i sees a surface whose normal is 60
 * degrees or more from i's (APPM__NORMAL_COS): a corner or an edge passes
 * between them.  Any line between two pixels also separates two 4-neighbours. */
static uint8_t appm__edge_flag(const appm_renderer *r, size_t i)
{
    const appm__vp *v = &r->vp[i];
    size_t x = i % r->w, y = i / r->w, w = r->w;
    const appm__vp *q[4];
    int k, n = 0;
    if (!v->segs) return 0;
    if (x > 0) q[n++] = v - 1;
    if (x + 1 < w) q[n++] = v + 1;
    if (y > 0) q[n++] = v - w;
    if (y + 1 < r->h) q[n++] = v + w;
    for (k = 0; k < n; ++k)
        if (q[k]->segs && appm__dot(v->n, q[k]->n) < APPM__NORMAL_COS) return 1;
    return 0;
}

/* The edge flags of a row and, in edge_dist, each pixel's distance along the row
 * to the nearest flagged one (capped at 255): a sweep each way. */
static void appm__edge_row(appm_renderer *r, uint32_t row)
{
    uint8_t *e = &r->edge_dist[(size_t)row * r->w];
    uint32_t x, d = 255;
    for (x = 0; x < r->w; ++x) e[x] = appm__edge_flag(r, (size_t)row * r->w + x) ? 0 : 255;
    for (x = 0; x < r->w; ++x) {
        d = e[x] == 0 ? 0 : (d < 255 ? d + 1 : 255);
        e[x] = (uint8_t)d;
    }
    for (x = r->w, d = 255; x-- > 0;) {
        d = e[x] == 0 ? 0 : (d < 255 ? d + 1 : 255);
        if (d < e[x]) e[x] = (uint8_t)d;
    }
}

/* Adds to g the open edges (5.5) near x's triangle that cut its kernel: an edge
 * of a triangle within 60 degrees of x's plane, lying in that plane (within
 * 0.1 Rm at both ends), x on its triangle's side, x's foot within the edge and
 * within reach Rm.  Of two parallel lines on the same side only the nearer
 * cuts (a floor that runs on under a wall ends at the wall). */
static void appm__open_lines(const appm_renderer *r, const appm__vp *v, appm__gather *g, float Rm)
{
    const appm_scene *s = r->scene;
    uint32_t j, j1;
    if (!s || !s->open_off || v->tri >= s->ntri) return;
    for (j = s->open_off[v->tri], j1 = s->open_off[v->tri + 1]; j < j1; ++j) {
        const uint32_t e = s->open_ref[j];
        appm__v3 a, b, c;
        float ex, ey, len, ux, uy, d, foot;
        int k;
        appm__v3 ab;
        double ax, ay, az, bx, by, bz, cx, cy, cz;
        appm__edge_ends(s, e, &a, &b);
        a = appm__sub(a, v->x);
        b = appm__sub(b, v->x);
        if (fabsf(appm__dot(s->info[e / 3].ng, v->n)) < 0.5f || fabsf(appm__dot(a, v->n)) > 0.1f * Rm ||
            fabsf(appm__dot(b, v->n)) > 0.1f * Rm)
            continue;
        /* Most edges that pass lie in x's plane far from x (a floor's rim seen from
         * its middle): reject them before the square root and divisions below.
         * An edge that cuts has x's foot q on it within Rm in the plane, and q is
         * within 0.1 Rm of the plane, so x's distance from the edge's line in
         * space is below sqrt(1.01) Rm; |a x (b - a)|^2 / |b - a|^2 is that
         * distance squared, and 1.05 leaves room for rounding.  In double: both
         * sides go as the fourth power of the scene's scale, which a float
         * overflows (or flushes to 0) for a scene 1e10 times larger or smaller. */
        ab = appm__sub(b, a);
        ax = a.x, ay = a.y, az = a.z, bx = ab.x, by = ab.y, bz = ab.z;
        cx = ay * bz - az * by, cy = az * bx - ax * bz, cz = ax * by - ay * bx;
        if (cx * cx + cy * cy + cz * cz >= 1.05 * (double)Rm * Rm * (bx * bx + by * by + bz * bz)) continue;
        c = appm__sub(appm__corner(&s->tri[e / 3], (e % 3 + 2) % 3), v->x); /* the triangle's third corner */
        ex = appm__dot(b, g->t) - appm__dot(a, g->t);
        ey = appm__dot(b, g->b) - appm__dot(a, g->b);
        len = sqrtf(ex * ex + ey * ey);
        if (!(len > 0.0f)) continue;
        ex /= len;
        ey /= len;
        ux = ey; /* the line's normal, then turned away from the edge's triangle */
        uy = -ex;
        d = appm__dot(a, g->t) * ux + appm__dot(a, g->b) * uy;
        if (appm__dot(c, g->t) * ux + appm__dot(c, g->b) * uy > d) {
            ux = -ux;
            uy = -uy;
            d = -d;
        }
        foot = -(appm__dot(a, g->t) * ex + appm__dot(a, g->b) * ey);
        if (!(d >= 0.0f && d < Rm && foot >= 0.0f && foot <= len)) continue;
        for (k = 0; k < g->ncut; ++k)
            if (g->cut_u[k][0] * ux + g->cut_u[k][1] * uy > 0.995f) break;
        if (k < g->ncut) {
            if (d < g->cut_d[k]) g->cut_d[k] = d;
        } else if (g->ncut < APPM__CUT_LINES) {
            g->cut_u[k][0] = ux;
            g->cut_u[k][1] = uy;
            g->cut_d[k] = d;
            g->ncut++;
        }
    }
}

static void appm__cut_lines(const appm_renderer *r, size_t i, appm__gather *g)
{
    const appm__vp *v = &r->vp[i];
    int64_t x0 = (int64_t)(i % r->w), y0 = (int64_t)(i / r->w), W, x, y, xa, xb, ya, yb;
    float Rm = v->R > v->Rc ? v->R : v->Rc, fp = v->footprint, pw; /* pw: a pixel's width at x */
    float lu[APPM__CUT_CAND][2], ld[APPM__CUT_CAND]; /* candidate lines: direction, distance */
    float lf[APPM__CUT_CAND];                       /* the nearest foot of a q along the line */
    int ls[APPM__CUT_CAND], nl = 0, k;              /* and how many neighbours give each */
    g->ncut = 0;
    if (APPM__CUT_LAP && 2.0f * g->h > Rm) Rm = 2.0f * g->h; /* the Laplacian's kernels reach 2h */
    if (APPM__CUT_LAP && 2.0f * g->hc > Rm) Rm = 2.0f * g->hc; /* and 2 hc */
    if (!(Rm > 0.0f)) return;
    W = fp > 0.0f && Rm / fp < (float)APPM__CUT_WIN ? (int64_t)(Rm / fp) + 1 : APPM__CUT_WIN;
    pw = fp > 0.0f ? fp : Rm;
    ya = y0 - W < 0 ? 0 : y0 - W;
    yb = y0 + W >= (int64_t)r->h ? (int64_t)r->h - 1 : y0 + W;
    xa = x0 - W < 0 ? 0 : x0 - W;
    xb = x0 + W >= (int64_t)r->w ? (int64_t)r->w - 1 : x0 + W;
    for (y = ya; y <= yb; ++y) {
        /* edge_dist of (x0, y): the distance to the nearest flagged pixel of row y; beyond W
         * this row's part of the window has no candidate */
        const uint8_t *e = &r->edge_dist[(size_t)(y * (int64_t)r->w)];
        if (e[x0] > W) continue;
        for (x = xa; x <= xb; ++x) {
            const appm__vp *q;
            float c, at, ab, al, g0, d, hq, ux, uy, sq;
            appm__v3 xq;
            if (e[x] != 0) { /* a plane's pixels next to the line give it; e[x] is the distance to the
                              * nearest of those, so none lies before x + e[x] */
                x += e[x] - 1;
                continue;
            }
            q = &r->vp[(size_t)(y * (int64_t)r->w + x)];
            if (q == v) continue;
            c = appm__dot(v->n, q->n);
            if (c >= APPM__NORMAL_COS) continue; /* the same surface for the gather */
            at = appm__dot(q->n, g->t);
            ab = appm__dot(q->n, g->b);
            al = sqrtf(at * at + ab * ab);
            if (!(al > 0.5f)) continue; /* planes within 30 degrees of parallel: no line near */
            xq = appm__sub(v->x, q->x);
            g0 = appm__dot(q->n, xq);
            d = fabsf(g0) / al;
            if (!(d < Rm)) continue;
            hq = fabsf(appm__dot(v->n, xq)) / al; /* q's distance from the line, in its plane */
            if (!(hq < 2.0f * (float)W * pw)) continue;
            ux = (g0 > 0.0f ? -at : at) / al;
            uy = (g0 > 0.0f ? -ab : ab) / al;
            /* where q's foot lies along the line, measured from x's foot: the other surface
             * meets x's only where its pixels show it, not along its plane extended */
            sq = fabsf(uy * appm__dot(xq, g->t) - ux * appm__dot(xq, g->b));
            for (k = 0; k < nl; ++k)
                if (lu[k][0] * ux + lu[k][1] * uy > 0.995f && fabsf(ld[k] - d) < 0.02f * Rm) break;
            if (k < nl) {
                ls[k]++;
                if (d < ld[k]) ld[k] = d;
                if (sq < lf[k]) lf[k] = sq;
            } else if (nl < APPM__CUT_CAND) {
                lu[nl][0] = ux;
                lu[nl][1] = uy;
                ld[nl] = d;
                lf[nl] = sq;
                ls[nl++] = 1;
            }
        }
    }
    while (g->ncut < APPM__CUT_LINES) { /* the nearest of the lines two neighbours give */
        int best = -1;
        for (k = 0; k < nl; ++k)
            if (ls[k] >= 2 && lf[k] < APPM__CUT_FOOT * pw && (best < 0 || ld[k] < ld[best])) best = k;
        if (best < 0) break;
        g->cut_u[g->ncut][0] = lu[best][0];
        g->cut_u[g->ncut][1] = lu[best][1];
        g->cut_d[g->ncut] = ld[best];
        g->ncut++;
        ls[best] = 0;
    }
    appm__open_lines(r, v, g, Rm);
}



/* ---- 10.5 The estimator table --------------------------------------------------
 *
 * One entry per appm_method (10.1 says what the fields and hooks are). */
#define APPM__AUX_BIT(k) (1u << (k))

static const appm__estimator appm__estimators[APPM_METHOD_COUNT] = {
    [APPM_METHOD_PPM] = {"ppm", APPM__CAP_PHOTONS, APPM__AUX_BIT(APPM_AUX_RADIUS) | APPM__AUX_BIT(APPM_AUX_VARIANCE),
                         sizeof(appm__ppm_state), appm__ppm_fields,
                         sizeof appm__ppm_fields / sizeof appm__ppm_fields[0], appm__ppm_start, NULL,
                         appm__ppm_radius, NULL, appm__ppm_commit, appm__ppm_pass_end, appm__mean_term, NULL,
                         appm__ppm_aux},
    [APPM_METHOD_SPPM] = {"sppm", APPM__CAP_PHOTONS, APPM__AUX_BIT(APPM_AUX_RADIUS), sizeof(appm__sppm_state),
                          appm__sppm_fields, sizeof appm__sppm_fields / sizeof appm__sppm_fields[0],
                          appm__sppm_start, NULL, appm__sppm_radius, NULL, appm__sppm_commit, NULL,
                          appm__sppm_term, NULL, appm__sppm_aux},
    [APPM_METHOD_APPM_PAPER] = {"appm-paper",
                                APPM__CAP_PHOTONS | APPM__CAP_BIWEIGHT | APPM__CAP_ERROR | APPM__CAP_MASS,
                                APPM__AUX_BIT(APPM_AUX_RADIUS) | APPM__AUX_BIT(APPM_AUX_VARIANCE) |
                                    APPM__AUX_BIT(APPM_AUX_LAPLACIAN) | APPM__AUX_BIT(APPM_AUX_ERROR),
                                sizeof(appm__paper_state), appm__paper_fields,
                                sizeof appm__paper_fields / sizeof appm__paper_fields[0], NULL,
                                appm__paper_bandwidth, appm__paper_radius, NULL, appm__paper_commit,
                                appm__paper_pass_end, appm__mean_term, appm__paper_bias, appm__paper_aux},
    [APPM_METHOD_APPM] = {"appm", APPM__CAP_PHOTONS | APPM__CAP_BIWEIGHT | APPM__CAP_CUT | APPM__CAP_ERROR |
                                      APPM__CAP_INNER,
                          APPM__AUX_BIT(APPM_AUX_RADIUS) | APPM__AUX_BIT(APPM_AUX_VARIANCE) |
                              APPM__AUX_BIT(APPM_AUX_LAPLACIAN) | APPM__AUX_BIT(APPM_AUX_ERROR) |
                              APPM__AUX_BIT(APPM_AUX_RADIUS_CAUSTIC) | APPM__AUX_BIT(APPM_AUX_RADIUS_DIFFUSE),
                          sizeof(appm__adaptive_px), appm__adaptive_fields,
                          sizeof appm__adaptive_fields / sizeof appm__adaptive_fields[0], NULL,
                          appm__adaptive_bandwidth, appm__adaptive_radius_diffuse, appm__adaptive_radius_caustic,
                          appm__adaptive_commit, appm__adaptive_pass_end, appm__adaptive_term,
                          appm__adaptive_bias, appm__adaptive_aux},
    /* section 11; its whole path sum is the "direct" term */
    [APPM_METHOD_PT] = {"pt", APPM__CAP_ERROR, APPM__AUX_BIT(APPM_AUX_VARIANCE) | APPM__AUX_BIT(APPM_AUX_ERROR), 0,
                        NULL, 0, NULL, NULL, NULL, NULL, NULL, NULL, NULL, NULL, NULL}};

/* ---- 10.6 The gather --------------------------------------------------------------
 *
 * Per row of pixels, after the photon map of the pass is built: commit the
 * pass's direct term, gather the photons near the visible point (with the
 * kernel cut's lines where the method cuts), and hand the sums to the
 * method's commit.  A pixel without a visible point commits an empty gather:
 * its pass contributes 0.  A photon's share of the sums comes first: the
 * biweight (or uniform) kernel and the 5-point Laplacian stencil of
 * algorithm.md 4.6, per photon. */

/* One photon's share of one component's sums (lobe: the glossy lobe's value at
 * the photon's direction; ih and lw: 1 / the component's bandwidth, 0 for none,
 * and its kernels' masses; cbias: the component step 7 reads, the caustic one,
 * whose sum at R / sqrt 1.5 is kept too; in a gather of one component, as the
 * tests' toys make, that one). */
static inline void appm__gather_sums(const appm__gather *g, const appm__photon *p, float d2, float R2, double ih,
                                     const double *lw, double q, float lobe, appm__sums *sum, int cbias)
{
    if (d2 < R2) {
        double k = 1.0;
        if (g->biweight) {
            double u = 1.0 - (double)d2 / R2;
            k = u * u;
            sum->s += k * q * q;
            /* within R' = R / sqrt 1.5, where 1 - d^2 / R'^2 = 1.5 u - 0.5, and within
             * R / sqrt 8, where it is 8 u - 7; the tests read d2 and R2, not u, so that they
             * do not wait for u's division (nor does a mispredicted branch) */
            if (g->inner && cbias && d2 < (float)(1.0 / APPM__CBIAS_S2) * R2) {
                double ucb = APPM__CBIAS_S2 * u - (APPM__CBIAS_S2 - 1.0);
                sum->ecb += ucb * ucb * q;
            }
            if (g->inner && d2 < (float)(1.0 / APPM__INNER_S2) * R2) {
                double ui = APPM__INNER_S2 * u - (APPM__INNER_S2 - 1.0);
                sum->ei += ui * ui * q;
            }
        }
        sum->e[0] += k * p->power[0];
        sum->e[1] += k * p->power[1];
        sum->e[2] += k * p->power[2];
        if (g->glossy) {
            sum->eg[0] += k * lobe * p->power[0];
            sum->eg[1] += k * lobe * p->power[1];
            sum->eg[2] += k * lobe * p->power[2];
        }
        sum->count++;
    }
    if (ih > 0.0) {
        /* algorithm.md 4.6:  D_h(d) h^4 / (3/pi): the biweight at x +- h t, x +- h b minus 4 times
         * at x.  With a = |d|^2 / h^2 and d = x - y, |d +- h t|^2 / h^2 = a + 1 +- 2 (d.t)/h.
         * Beyond 2h (a >= 4) every term is 0, since a + 1 - 2 |d.t| / h >= (sqrt(a) - 1)^2 >= 1:
         * such photons (inside a wider R or Rc) are skipped (the power is finite, checked
         * at emission, so 0 * q is 0). */
        double a = (double)d2 * ih * ih, stencil = 0.0;
        if (a < 4.0) {
            float dx = g->x.x - p->x, dy = g->x.y - p->y, dz = g->x.z - p->z;
            double dt = (dx * g->t.x + dy * g->t.y + dz * g->t.z) * ih;
            double db = (dx * g->b.x + dy * g->b.y + dz * g->b.z) * ih;
            double c[4];
            int k;
            c[0] = a + 1.0 + 2.0 * dt;
            c[1] = a + 1.0 - 2.0 * dt;
            c[2] = a + 1.0 + 2.0 * db;
            c[3] = a + 1.0 - 2.0 * db;
            for (k = 0; k < 4; ++k)
                if (c[k] < 1.0) stencil += lw[k] * (1.0 - c[k]) * (1.0 - c[k]);
            if (a < 1.0) stencil -= 4.0 * lw[4] * (1.0 - a) * (1.0 - a);
            sum->dl += stencil * q;
        }
    }
}

/* Whether photon p, on a surface facing as x's (normals within 1.5 degrees:
 * APPM__COVER_SIDE), lies on a surface that covers x: in front of x along n
 * by more than x's rounding error and by at least 1/64 of its distance, with
 * a surface in front of x at or before the photon's depth.  Why: every
 * McGuire Cornell box's lamp hangs 1 cm below its ceiling, facing down as the
 * ceiling does; the ceiling seen past the lamp's edge lies in the lamp's
 * shadow, and a kernel wider than 1 cm gathered the lamp's photons there
 * (21 % bright on that band; docs/algorithm.md 5.6).  The test asks the
 * geometry, not the photons: beside the lamp nothing covers the ceiling, and
 * its kernel keeps the lamp's photons.  One probe ray a gather, cast at the
 * first such photon, from beyond x's rounding error (a ray from x itself
 * can meet the next triangle of x's own plane far from the origin). */
static int appm__covered(appm__gather *g, const appm__photon *p, float d2)
{
    float o = (p->x - g->x.x) * g->n.x + (p->y - g->x.y) * g->n.y + (p->z - g->x.z) * g->n.z;
    if (!(o > g->cover_eps) || o * o * 4096.0f < d2) return 0;
    if (g->cover < 0.0f) {
        appm__ray ray;
        appm__hit h;
        appm__ray_init(&ray, g->x, g->n, sqrtf(g->Rg2));
        ray.tmin = g->cover_eps;
        g->cover = appm__intersect(g->scene, &ray, g->tri, &h) ? h.t : INFINITY;
    }
    return g->cover <= o * 1.001f + g->cover_eps;
}

/* Photon p at squared distance d2 (< the query's reach, max(R, Rc, 2h, 2hc)^2)
 * into g's sums; R2 = R^2, ih = 1/h.  The cheap rejections come first (path
 * length, one byte; then the normal), and lum(Psi), which only the second
 * moment and the Laplacian read, is not formed for the uniform kernel. */
static void appm__gather_near(appm__gather *g, const appm__photon *p, float d2, float R2, double ih,
                              const float *side, uint32_t tag)
{
    float lobe = 0.0f, dn;
    double q = 0.0;
    if (p->segs > g->max_p) return;
    /* same surface: angle(n_photon, n) < 60 deg.  With the octahedral decode
     * not normalised (side, from appm__photon_side): cos >= c <=> dot > 0 and
     * dot^2 >= c^2 |n|^2 */
    dn = side[0] * g->n.x + side[1] * g->n.y + side[2] * g->n.z;
    if (!(dn > 0.0f) || dn * dn < side[3]) return;
    if (g->scene && dn * dn >= APPM__COVER_SIDE * side[3] && appm__covered(g, p, d2)) return;
    if (g->glossy) { /* the lobe at the photon's own direction (section 6.1) */
        float c = appm__dot(appm__photon_wi(p), g->rd);
        appm__v3 wf;
        lobe = c > 0.0f ? powf(c > 1.0f ? 1.0f : c, g->ns) : 0.0f;
        wf = appm__add(g->wf, appm__scale(g->wg, lobe));
        q = 0.2126 * wf.x * p->power[0] + 0.7152 * wf.y * p->power[1] + 0.0722 * wf.z * p->power[2];
    } else if (g->biweight || g->h > 0.0f || g->gcount) {
        q = g->qw[0] * p->power[0] + g->qw[1] * p->power[1] + g->qw[2] * p->power[2];
    }
    { /* one call site, so that the compiler inlines it: the caustic component's
       * radius and sums, or the diffuse (or only) one's */
        int c = p->comp == APPM__COMP_CAUSTIC && g->Rc > 0.0f;
        if (g->gcount && tag != UINT32_MAX && d2 < (c ? g->Rc2 : R2)) /* 9.1: this pair's share of the image */
            appm__guide_count(g->gcount, g->gpairs, tag, d2, c ? g->Rc2 : R2, g->biweight, q, g->gunit);
        appm__gather_sums(g, p, d2, c ? g->Rc2 : R2, c ? g->ihc : ih, c ? g->lwc : g->lw, q, lobe,
                          &g->sum[c ? APPM__COMP_CAUSTIC : APPM__COMP_DIFFUSE], c || !(g->Rc > 0.0f));
    }
}

/* lw[k] = 1 / the mass on the surface of the Laplacian's five kernels of
 * bandwidth h (at x + h t, x - h t, x + h b, x - h b and x; step 6), 1 where
 * the gather has no cut lines. */
static void appm__lap_masses(const appm__gather *g, double h, double *lw)
{
    int k;
    for (k = 0; k < 5; ++k) lw[k] = 1.0;
    if (APPM__CUT_LAP && g->ncut > 0 && h > 0.0) { /* the stencil's kernels, each renormalised by its own mass */
        lw[0] = 1.0 / appm__cut_mass_at(g, h, h, 0.0);
        lw[1] = 1.0 / appm__cut_mass_at(g, h, -h, 0.0);
        lw[2] = 1.0 / appm__cut_mass_at(g, h, 0.0, h);
        lw[3] = 1.0 / appm__cut_mass_at(g, h, 0.0, -h);
        lw[4] = 1.0 / appm__cut_mass_at(g, h, 0.0, 0.0);
    }
}

/* The per-pixel constants of the visit: 1/h, 1/hc, the kernels' masses and
 * the luminance weights of lum(Psi), whose first factor is (0.2126 W f_x) gamma_x,
 * as before. */
static void appm__gather_consts(appm__gather *g)
{
    g->cover = -1.0f;
    g->cover_eps = 0.0f;
    if (g->scene && g->tri < g->scene->ntri) { /* x's rounding error along n (appm__surface), 4x */
        const appm__tri *t = &g->scene->tri[g->tri];
        float e = 0.0f;
        int k;
        for (k = 0; k < 3; ++k) {
            float m = fabsf(appm__comp(t->p0, k)), m1 = fabsf(appm__comp(t->p1, k)), m2 = fabsf(appm__comp(t->p2, k));
            m = m1 > m ? m1 : m;
            m = m2 > m ? m2 : m;
            e += fabsf(appm__comp(g->n, k)) * m;
        }
        e *= 4.0f * APPM__GAMMA7;
        g->cover_eps = 1e-4f * sqrtf(g->Rg2) > e ? 1e-4f * sqrtf(g->Rg2) : e;
    }
    g->ih = g->h > 0.0f ? 1.0 / g->h : 0.0;
    g->ihc = g->hc > 0.0f ? 1.0 / g->hc : 0.0;
    appm__lap_masses(g, g->h, g->lw);
    if (g->hc == g->h) memcpy(g->lwc, g->lw, sizeof g->lw);
    else appm__lap_masses(g, g->hc, g->lwc);
    g->qw[0] = 0.2126 * g->wf.x;
    g->qw[1] = 0.7152 * g->wf.y;
    g->qw[2] = 0.0722 * g->wf.z;
}

/* Photon p into g's sums if it lies within Rg2 = (reach)^2 of g->x (R2 = R^2):
 * the entry for callers that hold a photon but no query (the tests' toys). */
APPM__UNUSED static void appm__gather_photon(appm__gather *g, const appm__photon *p, float R2, float Rg2)
{
    float dx = g->x.x - p->x, dy = g->x.y - p->y, dz = g->x.z - p->z;
    float d2 = dx * dx + dy * dy + dz * dz, side[4];
    if (!(d2 < Rg2)) return;
    g->Rg2 = Rg2;
    appm__photon_side(p, side);
    appm__gather_consts(g);
    appm__gather_near(g, p, d2, R2, g->ih, side, UINT32_MAX);
}

static void appm__gather_visit(void *ctx, const appm__photon *p, float d2)
{
    appm__gather *g = (appm__gather *)ctx;
    size_t i = (size_t)(p - g->map->ph);
    appm__gather_near(g, p, d2, g->R2, g->ih, g->map->side + 4 * i, g->map->tag ? g->map->tag[i] : UINT32_MAX);
}

/* Visits every photon within max(R, Rc, 2h, 2hc) of g->x (7.2's query), with
 * the per-pixel constants of the visit computed once. */
static void appm__gather_query(const appm__pmap *m, appm__gather *g)
{
    float Rg = g->R > 2.0f * g->h ? g->R : 2.0f * g->h;
    if (g->Rc > Rg) Rg = g->Rc;
    if (2.0f * g->hc > Rg) Rg = 2.0f * g->hc;
    g->Rc2 = g->Rc * g->Rc;
    g->R2 = g->R * g->R;
    g->Rg2 = Rg * Rg;
    appm__gather_consts(g);
    g->map = m;
    appm__pmap_query(m, g->x, Rg, appm__gather_visit, g);
}

/* The radiance kernel's mass on the surface for a method that does not cut
 * (APPM__CAP_MASS): the cut's lines sought within R, not 2h (the Laplacian's
 * kernels are not measured), and g left without lines. */
static double appm__seam_mass(const appm_renderer *r, size_t i, appm__gather *g)
{
    const float h = g->h, hc = g->hc;
    double m;
    g->h = g->hc = 0.0f;
    appm__cut_lines(r, i, g);
    m = appm__cut_mass(g, g->R);
    g->h = h;
    g->hc = hc;
    g->ncut = 0;
    return m;
}

static void appm__gather_task(void *arg, uint32_t row, unsigned worker)
{
    appm_renderer *r = (appm_renderer *)arg;
    const appm__estimator *est = r->est;
    const double t0 = r->row_cost ? appm__seconds() : 0.0;
    uint32_t x;
    for (x = 0; x < r->w; ++x) {
        size_t pi = (size_t)row * r->w + x;
        const appm__vp *vp = &r->vp[pi];
        appm__pixel *p = &r->pix[pi];
        appm__gather g;
        memset(&g, 0, sizeof g);
        appm__add3(p->ld, vp->ld); /* the pass has succeeded: commit its direct term */
        p->lit += vp->lit;
        if (vp->segs > 0 && vp->segs < r->max_depth) {
            g.x = vp->x;
            g.n = vp->n;
            appm__basis(vp->n, &g.t, &g.b);
            g.wf = vp->wf;
            g.glossy = vp->wg.x > 0.0f || vp->wg.y > 0.0f || vp->wg.z > 0.0f;
            g.wg = vp->wg;
            g.rd = vp->rd;
            g.ns = vp->ns;
            g.max_p = r->max_depth - vp->segs;
            g.biweight = (est->caps & APPM__CAP_BIWEIGHT) != 0;
            g.inner = (est->caps & APPM__CAP_INNER) != 0;
            g.R = vp->R;
            g.Rc = vp->Rc;
            g.h = (float)r->lap_h;
            g.hc = appm__caustic_bandwidth(g.h, g.Rc);
            g.scene = r->scene;
            g.tri = vp->tri;
            if (r->cut) appm__cut_lines(r, pi, &g);
            else if (r->edges && appm__mass_pass(r->pass)) g.mass = appm__seam_mass(r, pi, &g);
            if (r->guide.nslot && r->guide.ref > 0.0) {
                g.gpairs = (size_t)r->guide.nslot * APPM__GUIDE_CELLS;
                g.gcount = r->guide.count + (size_t)worker * APPM__GUIDE_STRIDE(r->guide.nslot);
                g.gunit = 65536.0 / (APPM__PI * (double)r->M * r->guide.ref);
            }
            appm__gather_query(&r->pmap, &g);
        }
        est->commit(r, p, appm__state(r, pi), vp, &g, worker);
    }
    if (r->row_cost) r->row_cost[row] = (float)(appm__seconds() - t0);
}

/* ==== 11. PATH-TRACING REFERENCE ==========================================
 *
 * An unbiased unidirectional path tracer for reference images: at every
 * diffuse or glossy vertex a shadow ray to each point and spot light, one to
 * an area light or environment map chosen by power from the path tracer's own
 * table (6.4), and one BSDF-sampled continuation (section 6.1's mixture for
 * glossy), the two combined by multiple importance sampling (power
 * heuristic, Veach 1997) for area lights and environment maps.  A constant
 * environment is found by the continuation alone (weight 1); point and spot
 * lights are reached by shadow rays only.  After a specular bounce, emission
 * found by the continuation counts fully (no shadow ray could have found it).
 * Caustics from point lights are therefore missing by construction - that is
 * what photons are for.  Russian roulette from the fourth segment on.
 */
static float appm__mis(float a, float b)
{
    float a2 = a * a, b2 = b * b;
    return a2 + b2 > 0.0f ? a2 / (a2 + b2) : 0.0f;
}

/* What light sample ls brings to a path vertex (ns, ng: its normals on wo's
 * side) with throughput W, weighted by the power heuristic against the BSDF
 * sampling that could have found the same light (a delta light's pdf is 0:
 * weight 1). */
static appm__v3 appm__pt_direct_one(const appm_scene *s, const appm__surf *sf, const appm__material *m, appm__v3 wo,
                                    appm__v3 ns, appm__v3 ng, appm__v3 W, const appm__light_sample *ls)
{
    float c = appm__light_reaches(s, sf, ns, ng, ls), w;
    if (!(c > 0.0f)) return appm__v(0, 0, 0);
    if (m->kind == APPM__MAT_GLOSSY) { /* MIS against the mixture pdf of section 6.1 */
        w = ls->pdf > 0.0f ? appm__mis(ls->pdf, appm__bsdf_pdf(m, ns, ls->wi, wo)) : 1.0f;
        return appm__scale(appm__mul(appm__mul(W, appm__bsdf_f(m, ns, ls->wi, wo)), ls->li), c * w);
    }
    w = ls->pdf > 0.0f ? appm__mis(ls->pdf, c * (float)APPM__INV_PI) : 1.0f;
    return appm__scale(appm__mul(appm__mul(W, m->color), ls->li), c * (float)APPM__INV_PI * w);
}

/* Next-event estimate at a diffuse or glossy path vertex with throughput W
 * (side: wo's side of the geometric normal; u: the light sample's numbers): a
 * shadow ray to each point and spot light and one sample of the others (6.4),
 * as appm__direct. */
static appm__v3 appm__pt_direct(const appm_scene *s, const appm__surf *sf, const appm__material *m, appm__v3 wo,
                                float side, appm__v3 W, const float *u)
{
    appm__v3 ns = appm__scale(sf->ns, side), ng = appm__scale(sf->ng, side), sum = appm__v(0, 0, 0);
    appm__light_sample ls;
    uint32_t k;
    for (k = 0; k < s->nnee_delta; ++k)
        if (appm__sample_light_k(s, s->nee_delta[k], 1.0, sf, ns, 0.0f, 0.0f, &ls))
            sum = appm__add(sum, appm__pt_direct_one(s, sf, m, wo, ns, ng, W, &ls));
    if (appm__sample_light(s, 1, sf, ns, u[0], u[1], u[2], &ls))
        sum = appm__add(sum, appm__pt_direct_one(s, sf, m, wo, ns, ng, W, &ls));
    return sum;
}

/* Whether a path tracer cannot see some of the scene's light that reaches a
 * surface through a mirror or glass (a caustic).  It finds that light only by
 * a BSDF direction that, through the mirror or glass, meets the emitter.  A
 * point or spot light no direction meets; an area light smaller than
 * APPM__PT_TINY of the scene's bounding disk, pi R^2, a diffuse bounce meets
 * about once in 10^4 (water-caustic's 5 x 4 mm light: 2e-6 of it; the Cornell
 * boxes' 0.019).  The spread of the passes cannot see light that no pass
 * found: on caustic-glass the path tracer's estimate read 0.18-0.50 of its
 * true error, on water-caustic 0.06-0.24.  There it reports none (-1), as ppm
 * does, rather than a number that says 1 % where the truth is 25 %.  An
 * emitter is the triangles of one emissive material, counted if they carry at
 * least APPM__PT_TINY_POWER of the photons (an indicator lamp beside the room's
 * light does not count).  An environment map's sun is the same: the power of
 * its brightest texels within APPM__PT_TINY x pi steradians (the solid angle
 * of such an area light seen from the scene; a 1-degree sun is 0.76 of it) is
 * counted alike (appm__env_pinpoint).  On the textured scene, a glass sphere
 * under a sun of 1 degree, the estimate read 0.93, 2.01 and 2.46 of the true
 * error at 256 passes (seeds 1-3) and 0.41 at 16 (seed 1): the fireflies of
 * the sun's caustic decide the error, and one render's spread of them is as
 * heavy-tailed.  The scene's materials count as appm_scene_get_info counts
 * them (one that the MTL defines and no face uses too: the check cannot know
 * which surfaces the lights reach). */
#define APPM__PT_TINY 1e-4
#define APPM__PT_TINY_POWER 0.01
static int appm__pt_blind(const appm_scene *s)
{
    appm_scene_info in;
    double tiny = 0.0, disk = APPM__PI * (double)s->radius * s->radius;
    uint32_t k;
    appm_scene_get_info(s, &in);
    if (in.materials_mirror + in.materials_dielectric == 0) return 0;
    if (in.lights_point + in.lights_spot > 0) return 1;
    for (k = 0; k < s->nlight; ++k) {
        const appm__light *l = &s->light[k];
        if (l->kind == APPM__LIGHT_AREA && s->mat[s->info[l->tri].mat].emit_area < APPM__PT_TINY * disk)
            tiny += l->pick;
        else if (l->kind == APPM__LIGHT_ENV && s->envmap.rgb)
            tiny += l->pick * appm__env_pinpoint(&s->envmap, APPM__PT_TINY * APPM__PI);
    }
    return tiny >= APPM__PT_TINY_POWER;
}

/* The environment's radiance *Le that a path tracer's ray in direction d meets,
 * and its MIS weight against the light sample of the vertex before (1 after a
 * specular bounce or from the camera, where no light sample was taken). */
static float appm__pt_env(const appm_scene *s, appm__v3 d, int prev_specular, float prev_pdf, appm__v3 prev_ns,
                          appm__v3 *Le)
{
    float w = 1.0f;
    appm__env_place pl = {0.0, 0.0, 0.0}; /* the map's place of d, for its density and its radiance */
    if (s->envmap.rgb) appm__env_place_of(&s->envmap, d, &pl);
    if (!prev_specular) {
        float c = appm__dot(d, prev_ns);
        if (s->envmap.rgb)
            w = appm__mis(prev_pdf, (float)(s->light[s->env].nee[1] *
                                            appm__env_mix_pdf(&s->envmap, appm__env_bin(prev_ns), &pl, c)));
        /* else a constant environment, which the light samples leave to this ray (6.4): w = 1 */
    }
    *Le = s->envmap.rgb ? appm__env_lookup_uv(&s->envmap, pl.u, pl.v) : s->light[s->env].value;
    return w;
}

static void appm__pt_pixel(appm_renderer *r, uint32_t px, uint32_t py, unsigned worker)
{
    const appm_scene *s = r->scene;
    const size_t pi = (size_t)py * r->w + px;
    appm__sampler smp;
    appm__ray ray;
    appm__v3 W = appm__v(1, 1, 1), L = appm__v(0, 0, 0), prev_ns = appm__v(0, 0, 1);
    float prev_pdf = 0.0f;
    int prev_specular = 1, lit = 0, chain = 1; /* chain: every vertex so far specular */
    uint32_t skip = UINT32_MAX;
    unsigned segs = 0;
    appm__sampler_eye(&smp, r->sobol, r->chains, r->seed, r->pass, pi);
    appm__camera_ray(r, &smp, px, py, &ray);
    for (;;) {
        appm__hit h;
        appm__surf sf;
        const appm__material *m;
        appm__material tex;
        appm__v3 wo;
        appm__bsdf_sample bs;
        float u3[4];
        unsigned dims;
        if (++segs > r->max_depth) break;
        if (!appm__intersect(s, &ray, skip, &h)) {
            if (s->env >= 0) {
                appm__v3 Le;
                float w = appm__pt_env(s, ray.d, prev_specular, prev_pdf, prev_ns, &Le);
                L = appm__add(L, appm__scale(appm__mul(W, Le), w));
                lit |= chain;
            }
            break;
        }
        appm__surface(s, &h, &sf);
        m = appm__material_at(s, &sf, &tex);
        wo = appm__neg(ray.d);
        if (m->emissive && appm__dot(wo, sf.ng) > 0.0f) {
            float w = prev_specular ? 1.0f : appm__mis(prev_pdf, appm__area_light_pdf(s, sf.tri, ray.d, h.t));
            lit |= chain;
            L = appm__add(L, appm__scale(appm__mul(W, m->ke), w));
        }
        if ((m->kind == APPM__MAT_DIFFUSE || m->kind == APPM__MAT_GLOSSY) && segs + 1 <= r->max_depth) {
            float side = appm__dot(wo, sf.ng) >= 0.0f ? 1.0f : -1.0f;
            prev_ns = appm__scale(sf.ns, side);
            appm__smp_light(&smp, segs - 1, r->nee_dims, u3);
            L = appm__add(L, appm__pt_direct(s, &sf, m, wo, side, W, u3));
        }
        dims = appm__bsdf_dims(m) | (segs >= 3 ? 8u : 0u);
        appm__smp_bsdf(&smp, segs - 1, dims, u3);
        if (!appm__bsdf_sample_dir(m, &sf, wo, u3[0], u3[1], u3[2], APPM__RADIANCE, &bs))
            break;
        W = appm__mul(W, bs.weight);
        prev_pdf = bs.pdf;
        prev_specular = bs.specular;
        chain &= bs.specular != 0;
        if (segs >= 3) {
            float q = appm__maxc(W);
            q = q > 0.95f ? 0.95f : q;
            if (!(appm__smp_rr(&smp, segs - 1, dims, u3) < q)) break;
            W = appm__scale(W, 1.0f / q);
        }
        appm__ray_init(&ray, appm__offset(&sf, bs.wi), bs.wi, FLT_MAX);
        skip = sf.tri;
    }
    if (!appm__finite3(L)) {
        r->dropped[worker]++;
        L = appm__v(0, 0, 0);
    }
    appm__add3(r->pix[pi].ld, L);
    r->pix[pi].lit += (uint64_t)lit;
    appm__pass_value(r, &r->pix[pi], (double)appm__lum(L));
}

static void appm__pt_task(void *arg, uint32_t row, unsigned worker)
{
    appm_renderer *r = (appm_renderer *)arg;
    const double t0 = r->row_cost ? appm__seconds() : 0.0;
    uint32_t x;
    for (x = 0; x < r->w; ++x) appm__pt_pixel(r, x, row, worker);
    if (r->row_cost) r->row_cost[row] = (float)(appm__seconds() - t0);
}

/* ==== 12. RENDERER ======================================================
 *
 * The renderer's life cycle: create validates every option and allocates all
 * per-pixel state; each pass runs eye pass -> radii -> photon pass -> map ->
 * gather (appm__photon_method_pass); the image and the diagnostic maps are
 * derived from the per-pixel state on request.
 */
/* The photon budget (12.2): pass 1 may multiply the M0 = width * height photon
 * paths a pass by 2 or by 4 (APPM__BUDGET_MAX), as long as the photon paths'
 * rays stay within 1.65 times the eye paths'. */
#define APPM__BUDGET_MAX 4u
#define APPM__BUDGET_NUM 33u /* the ratio, 1.65 = 33 / 20: compared in integers, the same on */
#define APPM__BUDGET_DEN 20u /* every build (an x87 double might round the boundary otherwise) */

APPM_API void appm_config_init(appm_config *cfg)
{
    if (!cfg) return;
    memset(cfg, 0, sizeof *cfg);
    cfg->method = APPM_METHOD_APPM;
    cfg->direct = APPM_DIRECT_NEE;
    cfg->alpha = 2.0 / 3.0;
    cfg->max_depth = 32;
    cfg->sampler = APPM_SAMPLER_QMC;
    cfg->chains = 1;
    cfg->emission = APPM_EMISSION_GUIDED;
}


/* Frees the cluster's arrays (12.1): the renderer renders alone again. */
static void appm__cluster_free(appm_renderer *r)
{
    appm__free(&r->mem, r->cl_lens);
    appm__free(&r->mem, r->cl_words);
    appm__free(&r->mem, r->cl_count);
    appm__free(&r->mem, r->cl_eye);
    appm__free(&r->mem, r->cl_rows);
    appm__free(&r->mem, r->cl_chunks);
    appm__free(&r->mem, r->eye_cost);
    appm__free(&r->mem, r->row_cost);
    appm__free(&r->mem, r->chunk_cost);
    r->cl_lens = NULL;
    r->cl_words = r->cl_count = NULL;
    r->cl_eye = r->cl_rows = r->cl_chunks = NULL;
    r->eye_cost = r->row_cost = r->chunk_cost = NULL;
    memset(&r->cluster, 0, sizeof r->cluster);
    r->cluster.ranks = 1;
    r->eye0 = r->row0 = r->chunk0 = 0;
    r->eye1 = r->row1 = r->h;
    r->chunk1 = r->nchunks;
}

static void appm__renderer_free_parts(appm_renderer *r)
{
    int k;
    appm__free(&r->mem, r->vp);
    appm__free(&r->mem, r->edge_dist);
    appm__free(&r->mem, r->pix);
    appm__free(&r->mem, r->image);
    for (k = 0; k < APPM_AUX_COUNT; ++k) appm__free(&r->mem, r->aux[k]);
    appm__free(&r->mem, r->ph);
    appm__free(&r->mem, r->chunk);
    appm__free(&r->mem, r->task_used);
    appm__free(&r->mem, r->task_failed);
    appm__free(&r->mem, r->dest);
    appm__free(&r->mem, r->tag);
    appm__guide_free(r);
    appm__free(&r->mem, r->state);
    appm__pmap_free(&r->pmap, &r->mem);
    appm__free(&r->mem, r->sobol);
    appm__free(&r->mem, r->chain_sum);
    appm__free(&r->mem, r->err_w);
    appm__free(&r->mem, r->err_b2);
    appm__free(&r->mem, r->err_lum);
    appm__cluster_free(r);
}

/* The chunks of APPM__CHUNK paths that `paths` photon paths take. */
static uint64_t appm__chunks_of(uint64_t paths)
{
    return (paths + APPM__CHUNK - 1) / APPM__CHUNK;
}

/* Photons per task region of the first store, 1.5 per path plus slack, in
 * double and clamped before the conversion: 1.5 x 2^32 paths exceed a 32-bit
 * size_t (wasm32), and cap * tasks must fit the store's uint32 indices, the
 * limit appm__photon_pass grows to.  Too large a store fails to allocate.
 * The guess is for the busiest task (its whole chunks); the slack (4096, or
 * one more per path and 256 for a task of fewer paths) spares most renders
 * the retrace of a first pass that overflows, and a tiny pass (a preview, a
 * test, a fuzzed checkpoint) does not pay 160 KB a thread for it. */
static size_t appm__store_guess(uint64_t paths, unsigned tasks)
{
    /* the busiest task's paths: chunks of APPM__CHUNK go to the tasks in turn */
    const uint64_t chunks = appm__chunks_of(paths);
    const uint64_t busiest = (chunks + tasks - 1) / tasks * APPM__CHUNK;
    const double per_task = (double)(busiest < paths ? busiest : paths);
    const double guess = per_task * 1.5 + (per_task + 256.0 < 4096.0 ? per_task + 256.0 : 4096.0);
    const size_t limit = (size_t)0xFFFFFFF0u / tasks;
    return guess < (double)limit ? (size_t)guess : limit;
}

/* The options of a renderer of `scene`: cfg (NULL: all defaults) with every 0
 * replaced by its default, validated.  APPM_ERR_INVALID_ARG for an absurd one. */
static appm_status appm__config_resolve(const appm_scene *scene, const appm_config *cfg, appm_config *out,
                                        appm_diag *diag)
{
    appm_config c;
    if (cfg) c = *cfg;
    else memset(&c, 0, sizeof c);
    if (c.width == 0) c.width = scene->width;
    if (c.height == 0) c.height = scene->height;
    if (c.width > 32768 || c.height > 32768)
        return appm__fail(diag, APPM_ERR_INVALID_ARG, NULL, 0, "image size %ux%u is above 32768",
                          (unsigned)c.width, (unsigned)c.height);
    if ((int)c.method < 0 || c.method >= APPM_METHOD_COUNT)
        return appm__fail(diag, APPM_ERR_INVALID_ARG, NULL, 0, "unknown method %d", (int)c.method);
    if ((int)c.direct < 0 || c.direct > APPM_DIRECT_PHOTONS)
        return appm__fail(diag, APPM_ERR_INVALID_ARG, NULL, 0, "unknown direct-light mode");
    if ((int)c.sampler < 0 || c.sampler > APPM_SAMPLER_RANDOM)
        return appm__fail(diag, APPM_ERR_INVALID_ARG, NULL, 0, "unknown sampler %d",
                          (int)c.sampler);
    if (c.chains > APPM__MAX_CHAINS)
        return appm__fail(diag, APPM_ERR_INVALID_ARG, NULL, 0, "%u chains is above %d", c.chains,
                          APPM__MAX_CHAINS);
    if (c.chains == 0 || c.sampler == APPM_SAMPLER_RANDOM) c.chains = 1;
    if ((int)c.emission < 0 || c.emission > APPM_EMISSION_LIGHT)
        return appm__fail(diag, APPM_ERR_INVALID_ARG, NULL, 0, "unknown emission %d", (int)c.emission);
    if (c.alpha == 0.0) c.alpha = 2.0 / 3.0;
    if (!(c.alpha > 0.0 && c.alpha <= 1.0))
        return appm__fail(diag, APPM_ERR_INVALID_ARG, NULL, 0, "alpha %g is not in (0, 1]", c.alpha);
    if (!(c.radius >= 0.0) || !(c.radius < HUGE_VAL))
        return appm__fail(diag, APPM_ERR_INVALID_ARG, NULL, 0, "radius %g is not a positive number", c.radius);
    if (c.photons == 0) c.photons = (uint64_t)c.width * c.height;
    if (c.photons > ((uint64_t)1 << 32))
        return appm__fail(diag, APPM_ERR_INVALID_ARG, NULL, 0,
                          "%.0f photons per pass is above the limit of 2^32", (double)c.photons);
    if (c.max_depth == 0) c.max_depth = 32;
    if (c.max_depth > 254)
        return appm__fail(diag, APPM_ERR_INVALID_ARG, NULL, 0, "max depth %u is above 254", c.max_depth);
    if (c.threads == 0) c.threads = appm_cpu_count();
    if (c.threads > APPM__MAX_THREADS) c.threads = APPM__MAX_THREADS;
#if APPM_THREADS == 0
    if (c.threads > 1 && c.log) c.log(c.log_user, "", 0, "built without threads: rendering on 1 thread");
    c.threads = 1;
#endif
    if (c.log && scene->radius > 0.0f && c.radius > 0.1 * (2.0 * (double)scene->radius)) {
        /* a radius past a tenth of the bounding box's diagonal (2 scene->radius) is valid (the
         * estimates stay sound: tests/t_extremes.c renders r = 1e9), but each pixel visits a
         * large share of the photons: the sphere box at 512 x 512 takes 0.5 s a pass at the
         * automatic radius and 340 s at r = 5, its diagonal being 3.3 */
        const double diagonal = 2.0 * (double)scene->radius;
        char msg[256];
        if (c.radius > diagonal)
            snprintf(msg, sizeof msg,
                     "radius %g is larger than the whole scene (its bounding box's diagonal is %g): every "
                     "pixel gathers every photon, and a pass is slow",
                     c.radius, diagonal);
        else
            snprintf(msg, sizeof msg,
                     "radius %g is %.0f %% of the scene's size (its bounding box's diagonal is %g): each "
                     "pixel gathers a large share of the photons, and a pass is slow",
                     c.radius, 100.0 * c.radius / diagonal, diagonal);
        c.log(c.log_user, "", 0, msg);
    }
    if (scene->env_auto == 1 && c.log) /* once per renderer: the stand-in light is worth a word */
        c.log(c.log_user, scene->name, 0,
              "nothing in the model emits light: it is lit by a constant white environment of "
              "radiance 1 (add lights to choose others)");
    if (scene->env_auto == 2 && c.log)
        c.log(c.log_user, scene->name, 0,
              "nothing in the model emits light: it is shown in a studio - a sky brighter above "
              "than below with a soft key light high on the left, a grey ground plate under it "
              "and a camera 20 degrees above (add lights or an environment to replace the sky)");
    *out = c;
    return APPM_OK;
}

/* The photon passes' part of a renderer: the chunks' records (as many as the
 * photon budget may choose, 12.2), the tasks' counts, the store (a first guess
 * of 1.5 photons a path; it grows if needed) and guided emission's state.
 * Returns 0 when out of memory. */
static int appm__photon_alloc(appm_renderer *r, const appm_config *c)
{
    r->chunk = (appm__chunk_rec *)appm__alloc(&r->mem, r->nchunks_max, sizeof *r->chunk);
    r->task_used = (uint32_t *)appm__alloc(&r->mem, r->tasks, sizeof *r->task_used);
    r->task_failed = (int *)appm__alloc(&r->mem, r->tasks, sizeof *r->task_failed);
    r->cap = appm__store_guess(r->M, r->tasks);
    r->store_slots = r->cap * r->tasks;
    r->ph = (appm__photon *)appm__alloc(&r->mem, r->cap * r->tasks, sizeof *r->ph);
    if (r->ph) r->dest = (uint32_t *)appm__alloc(&r->mem, r->cap * r->tasks, sizeof *r->dest);
    if (!r->chunk || !r->task_used || !r->task_failed || !r->dest) return 0;
    if (c->emission != APPM_EMISSION_GUIDED) return 1;
    return appm__guide_alloc(r) &&
           (!r->guide.nslot || (r->tag = (uint32_t *)appm__alloc(&r->mem, r->cap * r->tasks, sizeof *r->tag)) != NULL);
}

/* The sampler's part of a renderer (section 2.3): which numbers the scene's
 * lights read, the Sobol' table (qmc) and the chains' sums (chains >= 2).
 * Returns 0 when out of memory. */
static int appm__sampler_alloc(appm_renderer *r, const appm_config *c)
{
    r->nee_dims = appm__light_dims(r->scene, 0);
    r->emit_dims = appm__light_dims(r->scene, 1);
    r->chains = c->chains;
    if (c->sampler == APPM_SAMPLER_QMC) {
        r->sobol = (appm__sobol_tab *)appm__alloc(&r->mem, 1, sizeof *r->sobol);
        if (!r->sobol) return 0;
        appm__sobol_table(r->sobol);
    }
    if (c->chains >= 2) {
        r->chain_sum = (double *)appm__alloc(&r->mem, (size_t)r->w * r->h * c->chains, sizeof(double));
        if (!r->chain_sum) return 0;
    }
    return 1;
}

/* The error estimate's parts per pixel (section 12), for a method that reports
 * it.  Returns 0 when out of memory. */
static int appm__error_alloc(appm_renderer *r)
{
    const size_t npix = (size_t)r->w * r->h;
    r->err_blind = !(r->est->caps & APPM__CAP_PHOTONS) && appm__pt_blind(r->scene);
    if (r->est->caps & APPM__CAP_ERROR) {
        r->err_w = (double *)appm__alloc(&r->mem, npix, sizeof(double));
        r->err_lum = (float *)appm__alloc(&r->mem, npix, sizeof(float));
    }
    if (r->est->bias) r->err_b2 = (double *)appm__alloc(&r->mem, npix, sizeof(double));
    return (!(r->est->caps & APPM__CAP_ERROR) || (r->err_w && r->err_lum)) && (!r->est->bias || r->err_b2);
}

APPM_API appm_status appm_renderer_create(const appm_scene *scene, const appm_config *cfg,
                                          appm_renderer **out, appm_diag *diag)
{
    appm__mem m;
    appm_renderer *r;
    appm_config c;
    appm_status st;
    size_t npix;
    appm_diag local;
    if (!diag) diag = &local;
    appm__diag_clear(diag);
    if (!out) return appm__fail(diag, APPM_ERR_INVALID_ARG, NULL, 0, "no output pointer");
    *out = NULL;
    if (!scene) return appm__fail(diag, APPM_ERR_INVALID_ARG, NULL, 0, "no scene");
    memset(&c, 0, sizeof c); /* filled below; gcc cannot see that on every path */
    if ((st = appm__config_resolve(scene, cfg, &c, diag)) != APPM_OK) return st;
    appm__mem_init(&m, &c);
    m.diag = diag;
    r = (appm_renderer *)appm__alloc(&m, 1, sizeof *r);
    if (!r) return APPM_ERR_NOMEM;
    r->mem = m;
    r->mem.diag = diag;
    r->scene = scene;
    r->est = &appm__estimators[c.method];
    r->cut = (r->est->caps & APPM__CAP_CUT) != 0;
    r->edges = r->cut || (r->est->caps & APPM__CAP_MASS) != 0;
    r->direct = c.direct;
    r->w = c.width;
    r->h = c.height;
    r->M = c.photons;
    r->M0 = (uint64_t)c.width * c.height;
    r->budget = (!cfg || cfg->photons == 0) && (r->est->caps & APPM__CAP_PHOTONS) != 0;
    r->r1 = c.radius;
    r->r1_auto = c.radius == 0.0;
    r->alpha = c.alpha;
    r->threads = c.threads;
    r->max_depth = c.max_depth;
    r->seed = c.seed;
    r->pixel_angle = 2.0f * scene->cam.tan_half / (float)r->h;
    r->tasks = r->threads;
    r->nchunks = (uint32_t)appm__chunks_of(r->M);
    r->nchunks_max = r->budget ? (uint32_t)appm__chunks_of(APPM__BUDGET_MAX * r->M0) : r->nchunks;
    r->cluster.ranks = 1;
    r->eye1 = r->row1 = r->h;
    r->chunk1 = r->nchunks;
    npix = (size_t)r->w * r->h;
    r->vp = (appm__vp *)appm__alloc(&r->mem, npix, sizeof *r->vp);
    r->pix = (appm__pixel *)appm__alloc(&r->mem, npix, sizeof *r->pix);
    r->image = (float *)appm__alloc(&r->mem, npix, 3 * sizeof(float));
    if (r->est->state_size) r->state = (unsigned char *)appm__alloc(&r->mem, npix, r->est->state_size);
    if (r->edges) r->edge_dist = (uint8_t *)appm__alloc(&r->mem, npix, 1);
    if (!r->vp || !r->pix || !r->image || (r->est->state_size && !r->state) || (r->edges && !r->edge_dist) ||
        !appm__sampler_alloc(r, &c) || !appm__error_alloc(r) ||
        ((r->est->caps & APPM__CAP_PHOTONS) && !appm__photon_alloc(r, &c))) {
        appm__mem fm;
        appm__renderer_free_parts(r);
        fm = r->mem;
        appm__free(&fm, r);
        return APPM_ERR_NOMEM;
    }
    r->stats.threads = r->threads;
    r->stats.est_relerr = -1.0;
    r->var_scale = r->noise_scale = 1.0;
    r->stats.clamped = -1.0;
    r->stats.memory_bytes = r->mem.live; /* what appm info reports before any pass */
    r->stats.peak_bytes = r->mem.peak;
    r->mem.diag = &r->diag;
    *out = r;
    return APPM_OK;
}

APPM_API void appm_renderer_destroy(appm_renderer *r)
{
    appm__mem m;
    if (!r) return;
    appm__renderer_free_parts(r);
    m = r->mem;
    appm__free(&m, r);
}

APPM_API const char *appm_renderer_last_error(const appm_renderer *r)
{
    return r ? r->last_error : "";
}

/* Every pixel's gather radius of this pass, from its method (10.5). */
static void appm__radius_task(void *arg, uint32_t row, unsigned worker)
{
    appm_renderer *r = (appm_renderer *)arg;
    uint32_t x;
    (void)worker;
    if (r->edges) appm__edge_row(r, row);
    for (x = 0; x < r->w; ++x) {
        size_t i = (size_t)row * r->w + x;
        r->vp[i].R = r->est->radius(r, appm__state(r, i));
        r->vp[i].Rc = r->est->radius_c ? r->est->radius_c(r, appm__state(r, i)) : 0.0f;
        if (r->vp[i].Rc < 0.0f) r->vp[i].Rc = r->vp[i].R;
    }
}

/* The default initial radius r_1 (pass 1): twice the median width of a pixel
 * at the visible points.  A radius tied to the pixel footprint keeps the
 * kernel's blur at a few pixels whatever the scene's units and however far the
 * camera is, which is what a viewer judges; photon density does not enter, so
 * the ppm/sppm user tunes --radius for a given budget, while appm adapts it.
 * Falls back to 1/1000 of the scene's diagonal when no pixel sees a surface. */
static double appm__default_radius(appm_renderer *r)
{
    size_t n = 0, i, npix = (size_t)r->w * r->h;
    float *tmp = r->image; /* scratch: the image is rebuilt on request */
    double rad = 0.0;
    for (i = 0; i < npix; ++i)
        if (r->vp[i].segs > 0 && r->vp[i].footprint > 0.0f) tmp[n++] = r->vp[i].footprint;
    if (n > 0) rad = 2.0 * appm__select(tmp, n, n / 2);
    if (!(rad > 0.0) || !(rad < HUGE_VAL)) rad = 2e-3 * (double)r->scene->radius;
    if (!(rad > 0.0) || !(rad < HUGE_VAL)) rad = 1e-3;
    return rad;
}

/* Median of the gather reaches (the radius, or the Laplacian's 2h) of the
 * pixels that have a visible point: 7.2's cell size is a multiple of it. */
static float appm__median_gather_radius(appm_renderer *r)
{
    size_t n = 0, i, npix = (size_t)r->w * r->h;
    float *tmp = r->image; /* scratch: the image is rebuilt on request */
    const double h2 = 2.0 * r->lap_h;
    for (i = 0; i < npix; ++i) {
        double g;
        if (r->vp[i].segs == 0) continue;
        g = (double)r->vp[i].R > r->vp[i].Rc ? (double)r->vp[i].R : (double)r->vp[i].Rc;
        tmp[n++] = (float)(h2 > g ? h2 : g);
    }
    if (n == 0) return (float)(r->r1 > 0 ? r->r1 : 1.0);
    return APPM__CELL_SCALE * appm__select(tmp, n, n / 2);
}

/* The photon part of pixel i's value after j passes into out[3]; 0: none. */
static int appm__photon_term(const appm_renderer *r, size_t i, double j, double *out)
{
    return r->est->photon_term && r->est->photon_term(r, appm__state(r, i), j, out);
}

/* Pixel i's luminance I after j passes. */
static double appm__pixel_lum(const appm_renderer *r, size_t i, double j)
{
    double I = appm__lumd(r->pix[i].ld) / j, t[3];
    if (appm__photon_term(r, i, j, t)) I += appm__lumd(t);
    return I;
}

/* The pixels of the (up to) 3 x 3 window around pixel i, clipped at the
 * image's border, row by row: their indices into idx; returns how many (4 at a
 * corner, 6 along an edge). */
static int appm__window3(const appm_renderer *r, size_t i, size_t idx[9])
{
    int64_t x0 = (int64_t)(i % r->w), y0 = (int64_t)(i / r->w), dx, dy;
    int n = 0;
    for (dy = -1; dy <= 1; ++dy)
        for (dx = -1; dx <= 1; ++dx) {
            int64_t x = x0 + dx, y = y0 + dy;
            if (x < 0 || y < 0 || x >= (int64_t)r->w || y >= (int64_t)r->h) continue;
            idx[n++] = (size_t)(y * (int64_t)r->w + x);
        }
    return n;
}

/* The weight of pixel i's squared error in the relative error, 1 / (I~^2 + 0.01),
 * as appm_image_compare's relmse weighs it with the reference's value there.
 * I~ is the pixel's own I (r->err_lum, filled for this pass), except where one
 * pass holds the pixel: a path tracer's firefly, a rare bright photon.  There
 * the reference is dark, I is the one sample's share, and 1 / (I^2 + 0.01)
 * shrank the weight of the very pixel whose spread is large, so that the error
 * bar missed what a render that met the rare path showed (the path tracer on
 * the sphere box read 0.30 of the true error at 64 passes, appm-paper on the
 * textured scene 0.62; docs/algorithm.md 7.3).  Such a pixel takes the median
 * of the I of its 3 x 3 neighbourhood when that is lower: one sample cannot
 * move it.  "One pass holds it": j mu^2 / (mu^2 + s^2) < 2, mu and s^2 the mean
 * and spread (M2 / j) of the per-pass luminance: the number of passes that would
 * give that spread if each pass were 0 or one value X (k passes of X: mu = q X,
 * s^2 = q (1 - q) X^2 with q = k / j, so j mu^2 / (mu^2 + s^2) = j q = k).  A pixel that shows a
 * light through specular vertices only (appm__pixel.lit) keeps its I: a light
 * smaller than the pixel is met as rarely as a firefly, and there the reference
 * is as bright as the render (a 5 x 4 mm light on water-caustic read 1744x the
 * true error without this). */
static double appm__err_weight(const appm_renderer *r, size_t i)
{
    const appm__pixel *p = &r->pix[i];
    double I = r->err_lum[i], j = (double)r->pass;
    if (p->lit == 0 && j >= 2.0) {
        double mu = p->wmean, s2 = p->wm2 / j; /* the passes' own spread, not the sample variance */
        if (j * mu * mu < 2.0 * (mu * mu + s2)) {
            size_t idx[9];
            float v[9];
            int n = appm__window3(r, i, idx), a, b;
            double m;
            for (a = 0; a < n; ++a) v[a] = r->err_lum[idx[a]];
            for (a = 1; a < n; ++a) /* insertion sort of at most 9 */
                for (b = a; b > 0 && v[b - 1] > v[b]; --b) {
                    float t = v[b];
                    v[b] = v[b - 1];
                    v[b - 1] = t;
                }
            m = (n & 1) ? (double)v[n / 2] : 0.5 * ((double)v[n / 2 - 1] + (double)v[n / 2]);
            if (m < I) I = m;
        }
    }
    return 1.0 / (I * I + 0.01);
}

/* The variance of a pixel's mean with one low-discrepancy sequence: the spread
 * of its passes (appm__mean_var) times this factor, the same for the whole
 * image.  Successive passes of one sequence are negatively correlated, so
 * their spread overstates the variance of their mean (6-8x measured on bunny
 * and teapot).  But the first and the second half of P = 2^k passes are each
 * a whole net of the sequence (section 2.3), two estimates of the pixel whose
 * errors are close to independent: their difference measures the variance of
 * the mean of P passes, (H1 - H2)^2 / 4, the way two chains would, without
 * the chains' coarser nets.  One degree of freedom a pixel is noisy, so the
 * halves only set the scale:
 *   c = sum_i w_i (H1 - H2)_i^2 / 4 * P / j  /  sum_i w_i Var_spread,i,
 * P/j carrying the variance of P passes to j >= P (the halves show the
 * sequence's gain has run out at that scale: the variance falls as 1/j there),
 * w_i the weight of pixel i in the relative error.  At most 1, the spread's
 * bound; 1 with random numbers (independent passes: the spread is right and
 * has j - 1 degrees of freedom a pixel) and before 2 passes.
 *   With K >= 2 chains a pixel's variance is the spread between its chains,
 * honest, and var_scale is 1.  The passes within each chain are still one
 * sequence's, and the bias estimate's noise is scaled by the same ratio with
 * the chains' variance in the numerator (appm__err_b2_task's noise_scale), as
 * if the spread of its passes overstated its noise as the luminance's does.
 * That was not measured for D with chains; with one chain it does not hold
 * (below), so with chains part of D's noise may stay in b^2.
 *   With one chain the bias estimate's noise is not scaled (noise_scale 1):
 * appm's D_j do not gain from the sequence as the image's luminance does.
 * Measured with D's own halves, found as c is (docs/algorithm.md 7.4): their
 * ratio was 1 (capped; 0.96 on one bunny seed) where the luminance's was
 * 0.49-0.67 (the RG box, 64 passes), 0.75-0.84 (water-caustic, 256) and
 * 0.56-0.65 (the bunny, 256); scaled by the luminance's c, D's noise was left
 * in b^2 and read as bias (the RG box's squared bias 15-19x the truth). */
static void appm__var_scales(appm_renderer *r)
{
    size_t i, npix = (size_t)r->w * r->h;
    uint64_t P = r->pass;
    double j = (double)r->pass, a = 0.0, b = 0.0, c;
    int chains = r->chains >= 2 && r->chain_sum;
    r->var_scale = r->noise_scale = 1.0;
    if ((!r->sobol && !chains) || r->pass < 2) return;
    while (P & (P - 1)) P &= P - 1; /* the largest power of two <= j */
    for (i = 0; i < npix; ++i) {
        const appm__pixel *p = &r->pix[i];
        double w = r->err_w[i], h = 0.5 * (double)P; /* appm__err_weight, filled by appm__err_w_task */
        double d = p->lh[0] / h - (p->lh[1] - p->lh[0]) / h;
        a += chains ? w * appm__mean_var(p, appm__chain_sums(r, i), r->chains, r->pass)
                    : w * 0.25 * d * d * ((double)P / j);
        b += w * appm__mean_var(p, NULL, 1, r->pass);
    }
    c = b > 0.0 ? a / b : 1.0;
    c = c < 1.0 ? c : 1.0;
    if (chains) r->noise_scale = c;
    else r->var_scale = c;
}

/* The squared bias of pixel i after j passes, as the error estimate takes it:
 * of the (up to) 3 x 3 pixels around i, the mean of the method's bias^2 with the
 * largest left out.  A kernel estimate's bias is a field as smooth as the
 * kernel, which spans several pixels, so a pixel whose model bias stands alone
 * holds a noisy Laplacian, not a bias: on the teapot one pixel of its silhouette
 * (a stencil off a surface curving away at a grazing angle) held 42 % of the
 * image's squared model bias, 6x the true squared bias in all; without it,
 * 1.05x at 256 passes.  A band two pixels wide or more, as a shadow's edge
 * leaves, keeps its bias (docs/algorithm.md 7.3).  Each pixel's bias^2 is taken
 * less the noise of its own estimate (the method's bias hook), with --chains
 * scaled by the chains' ratio (noise_scale, set before this is called); the mean
 * is floored at 0. */
static double appm__bias2(const appm_renderer *r, size_t i)
{
    size_t idx[9];
    double sum = 0.0, top = -HUGE_VAL, b2;
    int n, k;
    if (!r->err_b2) return 0.0;
    n = appm__window3(r, i, idx);
    for (k = 0; k < n; ++k) {
        double b = r->err_b2[idx[k]];
        sum += b;
        if (b > top) top = b;
    }
    b2 = n > 1 ? (sum - top) / (double)(n - 1) : sum;
    return b2 > 0.0 ? b2 : 0.0;
}

/* The error estimate's parts of pixel row `row`, one step over all rows at a
 * time (appm__parallel_for): each step reads only what the steps before it
 * wrote, so the parts are the same for any thread count, and the image's sum
 * is taken afterwards in pixel order.  Each pixel's bias^2 was computed nine
 * times in the 3 x 3 rule, and its weight twice, on one thread after every
 * pass: 8 % of a one-thread render of the bare bunny. */
static void appm__err_lum_task(void *arg, uint32_t row, unsigned worker)
{
    appm_renderer *r = (appm_renderer *)arg;
    size_t i = (size_t)row * r->w, end = i + r->w;
    (void)worker;
    for (; i < end; ++i) r->err_lum[i] = (float)appm__pixel_lum(r, i, (double)r->pass);
}

static void appm__err_w_task(void *arg, uint32_t row, unsigned worker)
{
    appm_renderer *r = (appm_renderer *)arg;
    size_t i = (size_t)row * r->w, end = i + r->w;
    (void)worker;
    for (; i < end; ++i) r->err_w[i] = appm__err_weight(r, i);
}

/* Each pixel's bias^2 less the noise of its own estimate, times noise_scale
 * (set before: 1 with one chain). */
static void appm__err_b2_task(void *arg, uint32_t row, unsigned worker)
{
    appm_renderer *r = (appm_renderer *)arg;
    size_t i = (size_t)row * r->w, end = i + r->w;
    (void)worker;
    for (; i < end; ++i) {
        double noise, b = r->est->bias(appm__state(r, i), (double)r->pass, &noise);
        r->err_b2[i] = b * b - r->noise_scale * noise;
    }
}

static void appm__err_term_task(void *arg, uint32_t row, unsigned worker)
{
    appm_renderer *r = (appm_renderer *)arg;
    size_t i = (size_t)row * r->w, end = i + r->w;
    (void)worker;
    for (; i < end; ++i) {
        const appm__pixel *p = &r->pix[i];
        double var = r->var_scale * appm__mean_var(p, appm__chain_sums(r, i), r->chains, r->pass);
        r->err_w[i] *= appm__bias2(r, i) + var;
    }
}

/* err_b2 for this pass (the ERROR map of pass 1, which has no estimate, needs it too). */
static void appm__err_b2_fill(appm_renderer *r)
{
    if (!r->err_b2 || r->err_pass == r->pass) return;
    appm__parallel_for(r->threads, r->h, appm__err_b2_task, r);
    r->err_pass = r->pass;
}

APPM_API int appm_renderer_keeps_error(const appm_renderer *r)
{
    return r && (r->est->caps & APPM__CAP_ERROR) && !r->err_blind;
}

/* The estimated relative error of the image (appm_stats.est_relerr):
 *   sqrt( mean over pixels of (bias^2 + Var) w ), w = appm__err_weight's
 *   1 / (I~^2 + 0.01); none (-1) where the renderer keeps none
 *   (appm_renderer_keeps_error),
 * bias^2 from appm__bias2, Var from the Welford spread of the per-pass
 * estimates divided by j, scaled by appm__var_scales, or from the spread between
 * the chains (appm__mean_var). */
static void appm__estimate_error(appm_renderer *r)
{
    size_t i, npix = (size_t)r->w * r->h;
    double sum = 0.0;
    r->var_scale = r->noise_scale = 1.0;
    if (r->pass < 2 || !(r->est->caps & APPM__CAP_ERROR)) {
        r->stats.est_relerr = -1.0;
        return;
    }
    appm__parallel_for(r->threads, r->h, appm__err_lum_task, r);
    appm__parallel_for(r->threads, r->h, appm__err_w_task, r);
    appm__var_scales(r);
    r->err_pass = 0;
    appm__err_b2_fill(r);
    appm__parallel_for(r->threads, r->h, appm__err_term_task, r);
    for (i = 0; i < npix; ++i) sum += r->err_w[i];
    /* the VARIANCE and ERROR maps keep the halves' scale; the image's estimate says none */
    r->stats.est_relerr = r->err_blind ? -1.0 : sqrt(sum / (double)npix);
}

/* The error estimate is made when it is read - appm_renderer_stats, the
 * VARIANCE and ERROR maps - as the image is (appm_renderer_image), not after
 * every pass: its sweeps over the pixels took 3 % of a pass (the sphere box,
 * 64 x 64, one thread) where nothing read it, the command line without --log,
 * --reference or --until-error among them.  It depends only on the state after the last
 * pass, so when it is made changes no digit of it. */
static void appm__error_update(appm_renderer *r)
{
    if (!r->err_stale) return;
    r->err_stale = 0;
    appm__estimate_error(r);
}

/* ---- 12.1 Passes split over a cluster -----------------------------------------
 *
 * appm_renderer_set_cluster (appm.h): every rank holds the whole per-pixel
 * state and does a share of each pass's work - rows [eye0, eye1) of the eye
 * pass, chunks [chunk0, chunk1) of the photon paths, rows [row0, row1) of the
 * gather - then the ranks exchange what they computed, so that after each
 * exchange every rank's arrays are those a renderer alone would hold.  Everything else (the radii,
 * the medians that size the grid, the photon map's build, the pooled dI^2,
 * the error estimate) every rank computes from identical data in the same
 * order, so no floating-point sum is ever split.  The exchanges of a pass:
 *   after the eye pass     vp of each rank's rows
 *   after the photon pass  a status word, the chunk records, the photons
 *                          (and their emission cells), a status word
 *   after the map's build  a status word
 *   after the gather       pix, the method's state and the chains' sums of
 *                          each rank's rows; guided emission's counts; the
 *                          samples each rank dropped; the seconds each row
 *                          and chunk took in each phase
 * Sums of integers (counts, drops) are exact in any order.  Which rank does
 * which rows and chunks changes nothing but the time: each phase's shares of
 * the next pass are cut where the last pass's seconds say the work is even
 * (the floor's rows cost more than the ceiling's, and not in the same
 * proportion in the eye pass as in the gather), from data every rank holds
 * alike.  docs/distributed.md has the measured exchange and its model. */

/* The hook over buf with the parts in r->cl_lens; its time and bytes into the stats. */
static appm_status appm__cluster_exchange(appm_renderer *r, void *buf)
{
    const double t0 = appm__seconds();
    unsigned k;
    int rc = r->cluster.allgather(r->cluster.user, buf, r->cl_lens);
    for (k = 0; k < r->cluster.ranks; ++k) {
        if (k == r->cluster.rank) r->stats.cluster_bytes_out += r->cl_lens[k];
        else r->stats.cluster_bytes_in += r->cl_lens[k];
    }
    r->stats.seconds_cluster += appm__seconds() - t0;
    if (rc == 0) return APPM_OK;
    return appm__fail(&r->diag, APPM_ERR_IO, NULL, 0, "the cluster's exchange failed (rank %u of %u)",
                      r->cluster.rank, r->cluster.ranks);
}

/* Items [b[k], b[k+1]) at base, `size` bytes each: rank k's into every rank's copy. */
static appm_status appm__cluster_share(appm_renderer *r, void *base, const uint32_t *b, size_t size)
{
    unsigned k;
    for (k = 0; k < r->cluster.ranks; ++k) r->cl_lens[k] = (size_t)(b[k + 1] - b[k]) * size;
    return appm__cluster_exchange(r, base);
}

/* One word per rank into r->cl_words (rank k's at [k]). */
static appm_status appm__cluster_words(appm_renderer *r, uint64_t mine)
{
    unsigned k;
    for (k = 0; k < r->cluster.ranks; ++k) r->cl_lens[k] = sizeof *r->cl_words;
    r->cl_words[r->cluster.rank] = mine;
    return appm__cluster_exchange(r, r->cl_words);
}

/* After a step that can fail on one rank (memory): every rank learns the
 * first failure and returns it, so that none waits in an exchange the failed
 * one never enters.  The failed rank keeps its own message. */
static appm_status appm__cluster_agree(appm_renderer *r, appm_status st, const char *step)
{
    unsigned k;
    appm_status x;
    if (r->cluster.ranks <= 1) return st;
    if ((x = appm__cluster_words(r, (uint64_t)st)) != APPM_OK) return x;
    for (k = 0; k < r->cluster.ranks; ++k) {
        if (r->cl_words[k] == APPM_OK) continue;
        if (k == r->cluster.rank) return st;
        x = r->cl_words[k] < APPM_STATUS_COUNT ? (appm_status)r->cl_words[k] : APPM_ERR_IO;
        return appm__fail(&r->diag, x, NULL, 0, "rank %u failed in %s: %s", k, step, appm_status_string(x));
    }
    return APPM_OK;
}

/* ph, dest and tag with room for n photons, keeping the first `keep`. */
static appm_status appm__store_reserve(appm_renderer *r, size_t n, size_t keep)
{
    if (n <= r->store_slots) return APPM_OK;
    if (n > (size_t)0xFFFFFFF0u)
        return appm__fail(&r->diag, APPM_ERR_NOMEM, NULL, 0,
                          "more than 4e9 photons stored in one pass: use fewer photons per pass");
    return appm__store_realloc(r, n + n / 8 + 4096, keep);
}

/* The photons rank k's chunks stored (their records must be every rank's). */
static size_t appm__cluster_stored(const appm_renderer *r, unsigned k)
{
    size_t n = 0;
    uint32_t c;
    for (c = r->cl_chunks[k]; c < r->cl_chunks[k + 1]; ++c) n += r->chunk[c].count;
    return n;
}

/* Each rank's photons, `size` bytes each, laid out rank after rank at base,
 * into every rank's copy. */
static appm_status appm__cluster_share_photons(appm_renderer *r, void *base, size_t size)
{
    unsigned k;
    for (k = 0; k < r->cluster.ranks; ++k) r->cl_lens[k] = appm__cluster_stored(r, k) * size;
    return appm__cluster_exchange(r, base);
}

/* The photons of every rank into ph, rank after rank, and the chunk records
 * of every chunk with its offset there; *n: this rank's photons on entry (at
 * the front of ph, as compacted), all of them on return. */
static appm_status appm__cluster_photons(appm_renderer *r, size_t *n)
{
    size_t total = 0, base = 0;
    appm_status st;
    unsigned k;
    uint32_t c;
    if ((st = appm__cluster_share(r, r->chunk, r->cl_chunks, sizeof *r->chunk)) != APPM_OK) return st;
    for (k = 0; k < r->cluster.ranks; ++k) { /* rank k's records are offsets in its own compacted store */
        if (k == r->cluster.rank) base = total;
        for (c = r->cl_chunks[k]; c < r->cl_chunks[k + 1]; ++c) r->chunk[c].start += (uint32_t)total;
        total += appm__cluster_stored(r, k);
    }
    st = appm__cluster_agree(r, appm__store_reserve(r, total, *n), "the photon store");
    if (st != APPM_OK) return st;
    memmove(r->ph + base, r->ph, *n * sizeof *r->ph);
    if (appm__guide_tags(r)) memmove(r->tag + base, r->tag, *n * sizeof *r->tag);
    *n = total;
    if ((st = appm__cluster_share_photons(r, r->ph, sizeof *r->ph)) != APPM_OK) return st;
    return appm__guide_tags(r) ? appm__cluster_share_photons(r, r->tag, sizeof *r->tag) : APPM_OK;
}

/* Guided emission's counts of this rank's workers, summed, then over the
 * ranks (in rank order: integers, exact) into worker 0's. */
static appm_status appm__cluster_guide(appm_renderer *r)
{
    appm__guide *gd = &r->guide;
    const size_t stride = APPM__GUIDE_STRIDE(gd->nslot);
    uint64_t *mine = r->cl_count + r->cluster.rank * stride;
    appm_status st;
    size_t c;
    unsigned k, w;
    for (c = 0; c < stride; ++c) {
        uint64_t sum = 0;
        for (w = 0; w < r->threads; ++w) {
            appm__count_add(&sum, gd->count[w * stride + c]);
            gd->count[w * stride + c] = 0;
        }
        mine[c] = sum;
    }
    for (k = 0; k < r->cluster.ranks; ++k) r->cl_lens[k] = stride * sizeof *r->cl_count;
    if ((st = appm__cluster_exchange(r, r->cl_count)) != APPM_OK) return st;
    for (k = 0; k < r->cluster.ranks; ++k)
        for (c = 0; c < stride; ++c) appm__count_add(&gd->count[c], r->cl_count[k * stride + c]);
    return APPM_OK;
}

/* Bounds b[0 .. ranks] that cut items 0 .. n-1 where the running sum of their
 * costs crosses k/ranks of the total (an even split of the items when
 * nothing was measured). */
static void appm__cluster_balance(const float *cost, uint32_t n, unsigned ranks, uint32_t *b)
{
    double total = 0.0, run = 0.0;
    uint32_t i;
    unsigned k;
    for (i = 0; i < n; ++i)
        if (cost[i] > 0.0f) total += cost[i]; /* NaN and negative: nothing */
    b[0] = 0;
    b[ranks] = n;
    for (k = 1, i = 0; k < ranks; ++k) {
        if (!(total > 0.0 && total < HUGE_VAL)) {
            b[k] = (uint32_t)((uint64_t)n * k / ranks);
            continue;
        }
        for (; i < n; ++i) {
            const double c = cost[i] > 0.0f ? cost[i] : 0.0;
            if (run + c > total * k / ranks) break;
            run += c;
        }
        b[k] = i;
    }
}

/* This rank's rows and chunks from the bounds. */
static void appm__cluster_mine(appm_renderer *r)
{
    const unsigned k = r->cluster.rank;
    r->eye0 = r->cl_eye[k];
    r->eye1 = r->cl_eye[k + 1];
    r->row0 = r->cl_rows[k];
    r->row1 = r->cl_rows[k + 1];
    r->chunk0 = r->cl_chunks[k];
    r->chunk1 = r->cl_chunks[k + 1];
}

/* After the gather (or a path-tracing pass): every rank's rows of the pixel
 * state, guided emission's counts, the samples the other ranks dropped, and
 * the costs that cut the next pass's shares. */
static appm_status appm__cluster_pixels(appm_renderer *r)
{
    const size_t w = r->w;
    const uint64_t own = appm__dropped_own(r);
    appm_status st;
    unsigned k;
    if ((st = appm__cluster_share(r, r->pix, r->cl_rows, w * sizeof *r->pix)) != APPM_OK) return st;
    if (r->state && (st = appm__cluster_share(r, r->state, r->cl_rows, w * r->est->state_size)) != APPM_OK)
        return st;
    if (r->chain_sum &&
        (st = appm__cluster_share(r, r->chain_sum, r->cl_rows, w * r->chains * sizeof *r->chain_sum)) != APPM_OK)
        return st;
    if (r->guide.nslot && r->guide.ref > 0.0 && (st = appm__cluster_guide(r)) != APPM_OK) return st;
    if ((st = appm__cluster_words(r, own - r->dropped_seen)) != APPM_OK) return st;
    r->dropped_seen = own;
    for (k = 0; k < r->cluster.ranks; ++k)
        if (k != r->cluster.rank) r->dropped_other += r->cl_words[k];
    if ((st = appm__cluster_share(r, r->row_cost, r->cl_rows, sizeof *r->row_cost)) != APPM_OK) return st;
    appm__cluster_balance(r->row_cost, r->h, r->cluster.ranks, r->cl_rows);
    if (r->est->caps & APPM__CAP_PHOTONS) {
        if ((st = appm__cluster_share(r, r->eye_cost, r->cl_eye, sizeof *r->eye_cost)) != APPM_OK ||
            (st = appm__cluster_share(r, r->chunk_cost, r->cl_chunks, sizeof *r->chunk_cost)) != APPM_OK)
            return st;
        appm__cluster_balance(r->eye_cost, r->h, r->cluster.ranks, r->cl_eye);
        appm__cluster_balance(r->chunk_cost, r->nchunks, r->cluster.ranks, r->cl_chunks);
    }
    appm__cluster_mine(r);
    return APPM_OK;
}

APPM_API appm_status appm_renderer_set_cluster(appm_renderer *r, const appm_cluster *c, appm_diag *diag)
{
    appm_diag local;
    const size_t counts = r && r->guide.nslot ? APPM__GUIDE_STRIDE(r->guide.nslot) : 0;
    if (!diag) diag = &local;
    appm__diag_clear(diag);
    if (!r) return appm__fail(diag, APPM_ERR_INVALID_ARG, NULL, 0, "no renderer");
    appm__cluster_free(r);
    if (!c || c->ranks <= 1) return APPM_OK;
    if (c->ranks > 65536 || c->rank >= c->ranks || !c->allgather)
        return appm__fail(diag, APPM_ERR_INVALID_ARG, NULL, 0, "cluster: rank %u of %u%s", c->rank, c->ranks,
                          c->allgather ? "" : " without an allgather");
    r->cl_lens = (size_t *)appm__alloc(&r->mem, c->ranks, sizeof *r->cl_lens);
    r->cl_words = (uint64_t *)appm__alloc(&r->mem, c->ranks, sizeof *r->cl_words);
    r->cl_eye = (uint32_t *)appm__alloc(&r->mem, (size_t)c->ranks + 1, sizeof *r->cl_eye);
    r->cl_rows = (uint32_t *)appm__alloc(&r->mem, (size_t)c->ranks + 1, sizeof *r->cl_rows);
    r->cl_chunks = (uint32_t *)appm__alloc(&r->mem, (size_t)c->ranks + 1, sizeof *r->cl_chunks);
    r->eye_cost = (float *)appm__alloc(&r->mem, r->h, sizeof *r->eye_cost);
    r->row_cost = (float *)appm__alloc(&r->mem, r->h, sizeof *r->row_cost);
    r->chunk_cost = (float *)appm__alloc(&r->mem, r->nchunks_max ? r->nchunks_max : 1, sizeof *r->chunk_cost);
    if (counts) r->cl_count = (uint64_t *)appm__alloc(&r->mem, c->ranks, counts * sizeof *r->cl_count);
    if (!r->cl_lens || !r->cl_words || !r->cl_eye || !r->cl_rows || !r->cl_chunks || !r->eye_cost ||
        !r->row_cost || !r->chunk_cost || (counts && !r->cl_count)) {
        appm__cluster_free(r);
        return appm__fail(diag, APPM_ERR_NOMEM, NULL, 0, "out of memory for the cluster's arrays");
    }
    memset(r->eye_cost, 0, r->h * sizeof *r->eye_cost);
    memset(r->row_cost, 0, r->h * sizeof *r->row_cost);
    memset(r->chunk_cost, 0, (r->nchunks_max ? r->nchunks_max : 1) * sizeof *r->chunk_cost);
    r->cluster = *c;
    r->dropped_seen = appm__dropped_own(r); /* known to all already: only new drops are sent */
    appm__cluster_balance(r->eye_cost, r->h, c->ranks, r->cl_eye); /* nothing measured: even */
    appm__cluster_balance(r->row_cost, r->h, c->ranks, r->cl_rows);
    appm__cluster_balance(r->chunk_cost, r->nchunks, c->ranks, r->cl_chunks);
    appm__cluster_mine(r);
    return APPM_OK;
}

/* ---- 12.2 The photon budget ----------------------------------------------------
 *
 * How many photon paths a pass, M, when the configuration leaves it 0.  The eye
 * pass costs what its paths cost whatever M is; the photon pass, the map and
 * the gather grow with M.  Which side's error the time should buy was measured
 * rather than modelled (docs/algorithm.md 5.12): at equal time, with guided
 * emission, more photons a pass won on the scenes whose eye paths are dear
 * against their photon paths - caustic-glass, where every eye path that sees
 * the caustic crosses the glass and the spot's photons mostly end on the floor
 * (0.78-0.87x the error with 4 M0 paths a pass, from 1 s to 30 s at 56x80),
 * the bunny (0.88-0.96x with 4 M0 at 8 s) - and lost where both sides cost
 * alike (the Cornell boxes: 1.2-1.6x with 4 M0) or where the eye paths make
 * the error (the studio: 1.10x with 2 M0; the sphere box).
 * The rule follows the cost: pass 1 counts the rays its eye paths cast (shadow
 * rays included), E, and those of its M0 = width * height photon paths, P, and
 * takes
 *      M = k M0,   k the largest of 1, 2, 4 with k P <= 1.65 E,
 * then traces pass 1's photons again with k M0 paths (pass 1's first M0 paths
 * are the same whatever M: the sampler's index is (j - 1) M + i).  The rays are
 * counted, not timed: the counts are integers, summed over the workers and the
 * ranks, so the same scene, options and seed make the same choice on any
 * machine, thread count or cluster, and the image is the one `--photons k M0`
 * renders, byte for byte.  M is then fixed: every estimator keeps one M per
 * render.  The gather's cost, which also grows with M, is not counted.  The
 * ratio 1.65 is set on the scenes measured: the studio (E / P 1.13-1.15, 1.10x
 * the error with 2 M0) and caustic-glass (2.5-2.7, 0.78-0.87x with 4 M0) bound
 * it to 1.6-1.74, and 1.65 keeps both 3-10 % from a threshold. */

/* Sets M, and the chunks it takes: alone all of them, in a cluster each rank's
 * share, even (a pass measures the next shares, 12.1). */
static void appm__set_photons(appm_renderer *r, uint64_t M)
{
    r->M = M;
    r->nchunks = (uint32_t)appm__chunks_of(M);
    if (r->cluster.ranks > 1) {
        memset(r->chunk_cost, 0, (r->nchunks_max ? r->nchunks_max : 1) * sizeof *r->chunk_cost);
        appm__cluster_balance(r->chunk_cost, r->nchunks, r->cluster.ranks, r->cl_chunks);
        appm__cluster_mine(r);
    } else {
        r->chunk1 = r->nchunks;
    }
}

/* The rays of side `side` (0: eye, 1: photon) of this pass: this rank's
 * workers', then every rank's (the same sum, so the same choice, on all). */
static appm_status appm__budget_rays(appm_renderer *r, int side, uint64_t *out)
{
    uint64_t n = 0;
    unsigned k;
    appm_status st;
    for (k = 0; k < r->threads; ++k) n += r->work[side][k];
    if (r->cluster.ranks > 1) {
        if ((st = appm__cluster_words(r, n)) != APPM_OK) return st;
        for (n = 0, k = 0; k < r->cluster.ranks; ++k) n += r->cl_words[k];
    }
    *out = n;
    return APPM_OK;
}

/* Pass 1 of a render whose M is the budget's, after its photon pass of M0
 * paths: k (the rule above), and the photon pass again with k M0 paths, whose
 * dropped samples count from `dropped` (the workers' counts before the first
 * try, whose M0 paths are traced again). */
static appm_status appm__budget(appm_renderer *r, const uint64_t *dropped)
{
    uint64_t E, P, k = 1;
    size_t need = 0;
    uint32_t t;
    appm_status st;
    if ((st = appm__budget_rays(r, 0, &E)) != APPM_OK || (st = appm__budget_rays(r, 1, &P)) != APPM_OK) return st;
    /* Under the studio's sky k stays 1 (docs/algorithm.md 5.12): its photons are
     * aimed at the model (6.3), and its error is the sky's grain on the plate,
     * which the further shadow rays of appm__direct buy down but the count
     * reads as eye cost (E / P 1.63 with four, 1.27 with two, 0.93 with one):
     * 2 w h rendered 1.06x the error of w h with two. */
    while (r->scene->env_auto != 2 && 2 * k <= APPM__BUDGET_MAX &&
           APPM__BUDGET_DEN * 2 * k * P <= APPM__BUDGET_NUM * E)
        k *= 2;
    if (r->cluster.ranks > 1) { /* the same sums give the same k; a rank of another build might not */
        if ((st = appm__cluster_words(r, k)) != APPM_OK) return st;
        for (t = 0; t < r->cluster.ranks; ++t)
            if (r->cl_words[t] != k)
                return appm__fail(&r->diag, APPM_ERR_IO, NULL, 0,
                                  "rank %u chose %llu times width * height photon paths a pass, rank %u %llu: "
                                  "are all ranks the same build?",
                                  (unsigned)t, (unsigned long long)r->cl_words[t], r->cluster.rank,
                                  (unsigned long long)k);
    }
    r->stats.budget_rays = P > 0 ? (double)E / (double)P : 0.0;
    r->budget = 2;
    if (k == 1) return APPM_OK;
    appm__set_photons(r, k * r->M0);
    memcpy(r->dropped, dropped, sizeof r->dropped);
    for (t = 0; t < r->tasks; ++t) /* room for k times the photons, not found by tracing again and again */
        if (r->task_used[t] > need) need = r->task_used[t];
    need = need * k + need * k / 4 + 4096;
    if (need > r->cap && need <= (size_t)0xFFFFFFF0u / r->tasks) {
        if (appm__store_realloc(r, need * r->tasks, 0) != APPM_OK)
            return appm__cluster_agree(r, APPM_ERR_NOMEM, "the photon store");
        r->cap = need;
    }
    return appm__cluster_agree(r, appm__photon_pass(r), "the photon pass");
}

/* The photon part of the image's mean luminance after the passes so far: the
 * unit in which guided emission counts contributions (9.1; 0: nothing
 * gathered yet, nothing to learn). */
static double appm__guide_ref(const appm_renderer *r)
{
    size_t i, npix = (size_t)r->w * r->h;
    double sum = 0.0, t[3];
    if (r->pass < 2) return 0.0;
    for (i = 0; i < npix; ++i)
        if (appm__photon_term(r, i, (double)(r->pass - 1), t)) sum += appm__lumd(t);
    sum /= (double)npix;
    return sum > 0.0 && sum < HUGE_VAL ? sum : 0.0;
}

/* One photon-mapping pass (eye pass, radii, photon pass, map, gather); times
 * t[0..2] at the ends of the radii, the photon pass and the map.  On failure
 * nothing is committed: the pixel state changes only in the gather. */
static appm_status appm__photon_method_pass(appm_renderer *r, double *t)
{
    const appm__estimator *est = r->est;
    const int alone = r->cluster.ranks <= 1;
    uint64_t dropped[APPM__MAX_THREADS];
    appm_status st;
    size_t n;
    float cell;
    memset(r->work[0], 0, sizeof r->work[0]);
    appm__parallel_range(r->threads, r->eye0, r->eye1 - r->eye0, appm__eye_task, r);
    if (!alone && (st = appm__cluster_share(r, r->vp, r->cl_eye, (size_t)r->w * sizeof *r->vp)) != APPM_OK)
        return st;
    if (r->pass == 1) {
        r->r_auto = appm__default_radius(r);
        if (r->r1_auto) r->r1 = r->r_auto;
        if (est->start) est->start(r);
    }
    r->lap_h = est->bandwidth ? est->bandwidth(r) : 0.0;
    r->shrink = pow((double)r->pass, -1.0 / 6.0);
    r->shrink_pass = r->pass;
    appm__parallel_for(r->threads, r->h, appm__radius_task, r);
    cell = appm__median_gather_radius(r);
    if (r->guide.nslot) {
        appm__guide_prepare(r);
        r->guide.ref = appm__guide_learns(r->pass) ? appm__guide_ref(r) : 0.0;
    }
    t[0] = appm__seconds();
    if (r->pass == 1 && r->budget == 1) memcpy(dropped, r->dropped, sizeof dropped); /* for appm__budget */
    st = appm__cluster_agree(r, appm__photon_pass(r), "the photon pass");
    if (st == APPM_OK && r->pass == 1 && r->budget == 1) st = appm__budget(r, dropped);
    if (st != APPM_OK) return st;
    n = appm__store_compact(r);
    if (!alone && (st = appm__cluster_photons(r, &n)) != APPM_OK) return st;
    t[1] = appm__seconds();
    r->pmap.tag = appm__guide_tags(r) ? r->tag : NULL;
    st = appm__pmap_build(&r->pmap, &r->mem, r->ph, n, r->dest, r->chunk, r->nchunks, cell > 0.0f ? cell : 1.0f);
    if ((st = appm__cluster_agree(r, st, "the photon map's build")) != APPM_OK) return st;
    t[2] = appm__seconds();
    appm__parallel_range(r->threads, r->row0, r->row1 - r->row0, appm__gather_task, r);
    if (!alone && (st = appm__cluster_pixels(r)) != APPM_OK) return st;
    if (r->guide.nslot) appm__guide_learn(r);
    if (est->pass_end) est->pass_end(r);
    r->stats.photons_emitted += r->M;
    r->stats.photons_per_pass = r->M;
    r->stats.photons_stored = r->pmap.n;
    return APPM_OK;
}

APPM_API appm_status appm_renderer_pass(appm_renderer *r)
{
    double t0, t[3], t4;
    appm_status st;
    if (!r) return APPM_ERR_INVALID_ARG;
    appm__diag_clear(&r->diag);
    t0 = appm__seconds();
    r->pass++;
    if (!(r->est->caps & APPM__CAP_PHOTONS)) {
        appm__parallel_range(r->threads, r->row0, r->row1 - r->row0, appm__pt_task, r);
        st = r->cluster.ranks > 1 ? appm__cluster_pixels(r) : APPM_OK;
        t[0] = t[1] = t[2] = appm__seconds();
    } else {
        st = appm__photon_method_pass(r, t);
    }
    if (st != APPM_OK) {
        r->pass--;
        if (st == APPM_ERR_NOMEM && r->diag.status == APPM_OK)
            appm__fail(&r->diag, st, NULL, 0, "out of memory in the photon pass");
        appm__copy_str(r->last_error, sizeof r->last_error, r->diag.message);
        return st;
    }
    t4 = appm__seconds();
    r->stats.passes = r->pass;
    r->stats.eye_paths += (uint64_t)r->w * r->h;
    r->stats.initial_radius = r->r1;
    r->stats.seconds += t4 - t0;
    r->stats.seconds_eye += t[0] - t0;
    r->stats.seconds_photons += t[1] - t[0];
    r->stats.seconds_grid += t[2] - t[1];
    r->stats.seconds_gather += t4 - t[2];
    r->stats.dropped_samples = r->dropped_other + appm__dropped_own(r);
    r->stats.memory_bytes = r->mem.live;
    r->stats.peak_bytes = r->mem.peak;
    r->err_stale = 1;
    return APPM_OK;
}

/* Pixel value after j passes: mean direct term + the method's photon term. */
APPM_API void appm_renderer_image(appm_renderer *r, appm_image *out)
{
    size_t i, npix;
    double j;
    if (!out) return;
    out->width = out->height = 0;
    out->rgb = NULL;
    if (!r) return;
    npix = (size_t)r->w * r->h;
    j = r->pass ? (double)r->pass : 1.0;
    for (i = 0; i < npix; ++i) {
        const appm__pixel *p = &r->pix[i];
        double t[3];
        int c, has = appm__photon_term(r, i, j, t);
        for (c = 0; c < 3; ++c) {
            double v = p->ld[c] / j;
            if (has) v += t[c];
            r->image[3 * i + c] = (float)v;
        }
    }
    out->width = r->w;
    out->height = r->h;
    out->rgb = r->image;
}

APPM_API void appm_renderer_stats(const appm_renderer *r, appm_stats *out)
{
    if (!out) return;
    memset(out, 0, sizeof *out);
    if (!r) return;
    /* est_relerr brought up to date: a renderer is never a const object (appm_renderer_create
     * allocates it), so its estimate may be made through this read-only view */
    appm__error_update((appm_renderer *)r);
    *out = r->stats;
}

APPM_API const float *appm_renderer_aux(appm_renderer *r, appm_aux which)
{
    size_t i, npix;
    float *a;
    if (!r || (int)which < 0 || which >= APPM_AUX_COUNT || r->pass == 0) return NULL;
    if (!(r->est->aux & APPM__AUX_BIT(which))) return NULL;
    npix = (size_t)r->w * r->h;
    if (!r->aux[which]) { /* allocated on first request: most renders never ask */
        r->aux[which] = (float *)appm__alloc(&r->mem, npix, sizeof(float));
        if (!r->aux[which]) return NULL;
    }
    a = r->aux[which];
    if (which == APPM_AUX_VARIANCE || which == APPM_AUX_ERROR) appm__error_update(r); /* var_scale */
    if (which == APPM_AUX_ERROR) appm__err_b2_fill(r);
    for (i = 0; i < npix; ++i) {
        const appm__pixel *p = &r->pix[i];
        double var = r->var_scale * appm__mean_var(p, appm__chain_sums(r, i), r->chains, r->pass), v;
        switch (which) {
        case APPM_AUX_RADIUS:
        case APPM_AUX_RADIUS_CAUSTIC:
        case APPM_AUX_RADIUS_DIFFUSE:
        case APPM_AUX_LAPLACIAN: v = r->est->aux_value(r, appm__state(r, i), which); break;
        case APPM_AUX_VARIANCE: v = var; break;
        default: /* the error bar |bias| + 1.645 sigma */
            v = 1.645 * sqrt(var) + sqrt(appm__bias2(r, i));
            break;
        }
        a[i] = (float)v;
    }
    return a;
}

APPM_API const char *appm_method_name(appm_method m)
{
    return (int)m >= 0 && m < APPM_METHOD_COUNT ? appm__estimators[m].name : NULL;
}

APPM_API const float *appm_renderer_emission_map(appm_renderer *r, unsigned k, unsigned *width,
                                                 unsigned *height)
{
    const appm__guide *gd;
    int i, v;
    if (width) *width = 0;
    if (height) *height = 0;
    if (!r || k >= r->guide.nslot) return NULL;
    gd = &r->guide;
    if (!r->guide.map && !(r->guide.map = (float *)appm__alloc(&r->mem, APPM__GUIDE_CELLS, sizeof(float))))
        return NULL;
    appm__guide_densities(r, &r->guide); /* a function of the learned state: the next pass makes the same */
    for (v = 0; v < APPM__GUIDE_RES; ++v) /* picture row v: u2; column: u1 */
        for (i = 0; i < APPM__GUIDE_RES; ++i)
            r->guide.map[v * APPM__GUIDE_RES + i] = gd->pdf[(size_t)k * APPM__GUIDE_CELLS + (size_t)i * APPM__GUIDE_RES + v];
    if (width) *width = APPM__GUIDE_RES;
    if (height) *height = APPM__GUIDE_RES;
    return r->guide.map;
}

APPM_API appm_status appm_method_parse(const char *name, appm_method *out)
{
    int k;
    for (k = 0; name && k < (int)APPM_METHOD_COUNT; ++k)
        if (strcmp(name, appm__estimators[k].name) == 0) {
            if (out) *out = (appm_method)k;
            return APPM_OK;
        }
    return APPM_ERR_INVALID_ARG;
}

/* ==== 13. CHECKPOINTS ======================================================
 *
 * A checkpoint is everything the next pass reads that a fresh renderer of the
 * same scene and options does not already have: the pass counter j, the radii
 * r1 and r_auto fixed by pass 1, ppm's global radius, the counters of
 * appm_stats, and per pixel the shared appm__pixel plus the method's state,
 * written field by field from the estimator table (10.2) - so a field added to
 * a method's table is saved without a change here.  What a pass rebuilds
 * (visible points, the photon store and map, the image, the aux maps) is not
 * saved: the random numbers of pass j are a function of (seed, j, index)
 * (sections 2.2, 2.3: the sampler is stateless; only the chains' sums of its
 * error estimate are saved), and the photon store's capacity only decides
 * whether a pass is traced twice, never what it stores.  So N passes, save,
 * load into a renderer of the same scene and options (any thread count), N
 * passes give the bytes of 2N passes.
 *
 * Layout, little-endian, each value packed byte by byte (doubles as their
 * IEEE-754 bits), so a checkpoint moves between machines:
 *   "APPMCKPT", u32 format version, u32 x 3 library version,
 *   u32 method, direct, width, height, max_depth, sampler, chains, guided lights;
 *   u64 photons, seed;
 *   f64 alpha, radius option (0: automatic); u64 x 5 scene hashes (below:
 *   geometry, materials, shading normals, lights, camera and image size);
 *   u64 pass, photons emitted, photons stored, eye paths, dropped samples;
 *   f64 r1, r_auto, ppm R^2, ppm R, seconds (total, eye, photons, grid, gather);
 *   the field lists of appm__pixel, of the method's state and of the chains'
 *   sums (one field of `chains` values with chains >= 2, else none) (u32
 *   count, then per field u32 name length, name, u32 count, u32 is_u64);
 *   per pixel, in reading order, those fields' values (8 bytes each);
 *   per guided light (9.1), u64 pairs counted, u64 passes that counted, f64
 *   its pairs' squared shares (B_l of the choice between lights), f64 x
 *   RES^2 learned scores, f64 x RES^2 their part from the odd passes, f64 x
 *   RES^2 paths per cell (expected), f64 x RES^2 paths per cell (counted) and
 *   f64 x RES^2 their cost;
 *   u32 1 if the photon budget chose M (12.2), 0 if it was given, and f64 its
 *   reading E / P (0 before pass 1 or without a budget);
 *   u64 FNV-1a hash of all bytes before it.
 * The format version changes with this layout and with what the scene hashes
 * cover, so that a checkpoint of an older build is refused as such, never
 * misread nor taken for one of another scene (version 2: the hashes in five
 * parts, with the glossy lobe, the normals and the statements as written;
 * version 3: the guided emission's lights and scores; version 4: the cost of
 * its paths and the scores' odd half; version 5: the photon budget's flag;
 * version 6: the squared shares of the choice between lights).
 * A checkpoint of another format or library version, scene, method, option set,
 * image size or field list is refused (APPM_ERR_INVALID_ARG, saying which); a
 * truncated, altered or impossible one is APPM_ERR_PARSE.  Loading reads the
 * input twice - first to check everything, then to apply it - so a refused
 * checkpoint leaves the renderer as it was. */
#define APPM__CK_FORMAT 6u
#define APPM__CK_GUIDE_WORDS (3u + APPM__GUIDE_ARRAYS * APPM__GUIDE_CELLS) /* 8-byte words a guided light */

/* Where the c-th learned value of slot k stands in appm__guide.cells, in the
 * checkpoint's order: the slot's RES^2 values of each array in turn. */
static size_t appm__guide_cell_at(const appm__guide *gd, uint32_t k, unsigned c)
{
    return (size_t)(c / APPM__GUIDE_CELLS) * gd->nslot * APPM__GUIDE_CELLS + (size_t)k * APPM__GUIDE_CELLS +
           c % APPM__GUIDE_CELLS;
}
#define APPM__CK_BLOCK 65536              /* file buffer */
#define APPM__CK_MAXFIELDS 64
#define APPM__FNV_BASIS 14695981039346656037ull
#define APPM__FNV_PRIME 1099511628211ull

/* The shared per-pixel state (section 8's appm__pixel), field by field as the
 * estimator table lists each method's: a field added to appm__pixel must be
 * listed here (t_checkpoint checks that the list tiles the struct). */
static const appm__field appm__pixel_fields[] = {{"ld", offsetof(appm__pixel, ld), 3, 0},
                                                 {"wmean", offsetof(appm__pixel, wmean), 1, 0},
                                                 {"wm2", offsetof(appm__pixel, wm2), 1, 0},
                                                 {"lh", offsetof(appm__pixel, lh), 2, 0},
                                                 {"lit", offsetof(appm__pixel, lit), 1, 1}};

/* The field lists one checkpoint is written with, per pixel: the shared
 * pixel's, the method's state's, and the chains' sums (section 2.3; a list of
 * one field, or none with one chain), each at its own base (appm__ck_base). */
#define APPM__CK_TABLES 3

typedef struct appm__ck_layout {
    const appm__field *f[APPM__CK_TABLES];
    unsigned n[APPM__CK_TABLES];
    appm__field chain; /* the one field of table 2 */
} appm__ck_layout;

static void appm__ck_layout_of(const appm_renderer *r, appm__ck_layout *L)
{
    L->f[0] = appm__pixel_fields;
    L->n[0] = sizeof appm__pixel_fields / sizeof appm__pixel_fields[0];
    L->f[1] = r->est->fields;
    L->n[1] = r->est->nfields;
    L->chain.name = "chain_sum";
    L->chain.offset = 0;
    L->chain.count = r->chains;
    L->chain.is_u64 = 0;
    L->f[2] = &L->chain;
    L->n[2] = r->chain_sum ? 1 : 0;
}

/* Where table t of pixel i's values live. */
static unsigned char *appm__ck_base(const appm_renderer *r, unsigned t, size_t i)
{
    if (t == 0) return (unsigned char *)&r->pix[i];
    if (t == 1) return r->est->state_size ? (unsigned char *)appm__state(r, i) : NULL;
    return (unsigned char *)appm__chain_sums(r, i);
}

/* The scene as its files describe it, in five parts, so that a refusal can say
 * which one differs: geometry, materials, shading normals, lights, camera and
 * image size.  Values are hashed one by one (struct padding never enters).
 * The triangles enter each of the first three as a set (a sum of per-triangle
 * hashes, each of them over the triangle's vertices as well, so that a part
 * says which triangle carries what), and area lights through their triangles'
 * Ke: the BVH's triangle order, which a build for another machine may choose
 * otherwise, does not change a hash, so a checkpoint of the same scene file is
 * recognised there.  For the same reason only values as read from the files
 * enter, or results of single IEEE operations on them (the vertices, a
 * material's Kd and Ks after clamping and energy scaling, the geometric normal
 * and area, computed in double): where float expressions are evaluated in
 * double (s390x), a dot product or a cross product rounds otherwise than on
 * x86-64, and libm's cos and tan may differ by an ulp between machines.  So the
 * corner normals enter as written (tri_info.nhash), not normalised; the camera
 * as its statement (eye, target, up, fov) or as "framed by the loader", not as
 * its basis and tan(fov/2); a spot light by position, target, cone and
 * falloff, not by its axis and cosines; and the lights' powers and picking
 * probabilities (sums in BVH order) not at all - all of these are functions of
 * what is hashed. */
enum { APPM__SH_GEOMETRY, APPM__SH_MATERIALS, APPM__SH_NORMALS, APPM__SH_LIGHTS, APPM__SH_CAMERA, APPM__SH_PARTS };

static const char *const appm__sh_part[APPM__SH_PARTS] = {
    "its geometry differs", "its materials differ", "its shading normals differ", "its lights differ",
    "its camera or image size differs"};

static uint64_t appm__hash_u(uint64_t h, uint64_t v) { return appm__mix64(h ^ v) + 0x9E3779B97F4A7C15ull; }

static uint64_t appm__hash_f(uint64_t h, float f)
{
    uint32_t u;
    memcpy(&u, &f, sizeof u);
    return appm__hash_u(h, u);
}

static uint64_t appm__hash_d(uint64_t h, double d)
{
    uint64_t u;
    memcpy(&u, &d, sizeof u);
    return appm__hash_u(h, u);
}

static uint64_t appm__hash_v3(uint64_t h, appm__v3 v)
{
    return appm__hash_f(appm__hash_f(appm__hash_f(h, v.x), v.y), v.z);
}

/* Triangle i's terms of the three per-triangle parts, added to sum[]. */
static void appm__hash_tri(const appm_scene *s, uint32_t i, uint64_t *sum)
{
    const appm__tri_info *t = &s->info[i];
    const appm__material *m = &s->mat[t->mat];
    uint64_t v = appm__hash_v3(appm__hash_v3(appm__hash_v3(1, s->tri[i].p0), s->tri[i].p1), s->tri[i].p2), h;
    sum[APPM__SH_GEOMETRY] += appm__mix64(appm__hash_f(appm__hash_v3(v, t->ng), t->area));
    h = appm__hash_u(appm__hash_u(v, (uint32_t)m->kind), (uint32_t)m->emissive);
    h = appm__hash_v3(appm__hash_v3(appm__hash_v3(h, m->color), m->ke), m->ks);
    h = appm__hash_f(appm__hash_f(h, m->ns), m->ior);
    if (m->map_kd || m->map_ks || m->map_d) { /* maps and coordinates: only where there are maps, so
                                               * the hashes of scenes without stay what they were */
        h = appm__hash_u(h, m->map_kd ? s->tex[m->map_kd - 1].hash : 0);
        h = appm__hash_u(h, m->map_ks ? s->tex[m->map_ks - 1].hash : 0);
        h = appm__hash_u(h, m->map_d ? s->tex[m->map_d - 1].hash : 0);
        if (t->uv0 >= 0) {
            const float *uv = s->uv + 2 * (size_t)t->uv0;
            int k;
            for (k = 0; k < 6; ++k) h = appm__hash_f(h, uv[k]);
        }
    }
    sum[APPM__SH_MATERIALS] += appm__mix64(h);
    sum[APPM__SH_NORMALS] += appm__mix64(appm__hash_u(v, t->nhash));
}

static uint64_t appm__hash_lights(const appm_scene *s)
{
    uint64_t h = appm__hash_u(0, s->nlight);
    uint32_t i;
    for (i = 0; i < s->nlight; ++i) {
        const appm__light *l = &s->light[i];
        if (l->kind == APPM__LIGHT_AREA) continue;
        h = appm__hash_v3(appm__hash_u(h, (uint32_t)l->kind), l->value);
        if (l->kind == APPM__LIGHT_ENV && s->envmap.rgb) h = appm__hash_u(h, s->envmap.hash);
        if (l->kind == APPM__LIGHT_ENV) continue;
        h = appm__hash_v3(h, l->pos);
        if (l->kind == APPM__LIGHT_SPOT)
            h = appm__hash_d(appm__hash_d(appm__hash_v3(h, l->target), l->cone), l->falloff);
    }
    return h;
}

static uint64_t appm__hash_camera(const appm_scene *s)
{
    const appm__camera *c = &s->cam;
    uint64_t h = appm__hash_u(0, (uint32_t)c->framed);
    if (!c->framed) h = appm__hash_d(appm__hash_v3(appm__hash_v3(appm__hash_v3(h, c->eye), c->target), c->sky), c->fov_deg);
    h = appm__hash_f(appm__hash_f(h, c->aperture), c->focus);
    return appm__hash_u(appm__hash_u(h, s->width), s->height);
}

static void appm__scene_hash(const appm_scene *s, uint64_t out[APPM__SH_PARTS])
{
    uint32_t i, k;
    for (k = 0; k < 3; ++k) out[k] = 0;
    for (i = 0; i < s->ntri; ++i) appm__hash_tri(s, i, out);
    for (k = 0; k < 3; ++k) out[k] = appm__hash_u(appm__hash_u(k, s->ntri), out[k]);
    out[APPM__SH_LIGHTS] = appm__hash_lights(s);
    out[APPM__SH_CAMERA] = appm__hash_camera(s);
}

/* -- Byte sinks and sources.  The writer fills the caller's buffer (counting
 *    on past its end, so that a NULL buffer measures) or a block flushed to a
 *    file; the reader walks a buffer or refills a block from a file.  Both keep
 *    the FNV-1a hash of every byte that passes. */
typedef struct appm__ckw {
    unsigned char *buf;
    size_t cap, len;
    FILE *f;         /* NULL: memory */
    uint64_t total;  /* bytes produced */
    uint64_t sum;
    int ok;
} appm__ckw;

static void appm__ckw_bytes(appm__ckw *w, const unsigned char *p, size_t n)
{
    size_t i;
    for (i = 0; i < n; ++i) {
        w->sum = (w->sum ^ p[i]) * APPM__FNV_PRIME;
        if (w->len == w->cap && w->f) {
            if (fwrite(w->buf, 1, w->len, w->f) != w->len) w->ok = 0;
            w->len = 0;
        }
        if (w->len < w->cap) w->buf[w->len++] = p[i];
    }
    w->total += n;
}

static void appm__ckw_u(appm__ckw *w, uint64_t v, int bytes)
{
    unsigned char b[8];
    int k;
    for (k = 0; k < bytes; ++k) b[k] = (unsigned char)(v >> (8 * k));
    appm__ckw_bytes(w, b, (size_t)bytes);
}

static void appm__ckw_d(appm__ckw *w, double d)
{
    uint64_t u;
    memcpy(&u, &d, sizeof u);
    appm__ckw_u(w, u, 8);
}

typedef struct appm__ckr {
    const unsigned char *p;
    size_t len, pos;     /* bytes at p, bytes of them read */
    FILE *f;             /* NULL: memory */
    unsigned char *blk;  /* file: the block p points to */
    uint64_t sum;
    int ok;              /* 0 once a read ran past the end (or failed) */
} appm__ckr;

static void appm__ckr_rewind(appm__ckr *r)
{
    r->pos = 0;
    r->sum = APPM__FNV_BASIS;
    r->ok = 1;
    if (r->f) {
        r->len = 0;
        if (fseek(r->f, 0L, SEEK_SET) != 0) r->ok = 0;
    }
}

/* The next byte into *b; 0 at the end.  hashed: whether it enters the sum. */
static int appm__ckr_byte(appm__ckr *r, unsigned char *b, int hashed)
{
    if (r->pos == r->len) {
        if (r->f && r->ok) {
            r->len = fread(r->blk, 1, APPM__CK_BLOCK, r->f);
            r->pos = 0;
            r->p = r->blk;
        }
        if (r->pos == r->len) {
            r->ok = 0;
            return 0;
        }
    }
    *b = r->p[r->pos++];
    if (hashed) r->sum = (r->sum ^ *b) * APPM__FNV_PRIME;
    return 1;
}

static uint64_t appm__ckr_u(appm__ckr *r, int bytes)
{
    uint64_t v = 0;
    unsigned char b = 0;
    int k;
    for (k = 0; k < bytes && appm__ckr_byte(r, &b, 1); ++k) v |= (uint64_t)b << (8 * k);
    return r->ok ? v : 0;
}

static double appm__ckr_d(appm__ckr *r)
{
    uint64_t u = appm__ckr_u(r, 8);
    double d;
    memcpy(&d, &u, sizeof d);
    return d;
}

/* -- What a checkpoint says about its render (compared on load) and the
 *    renderer-wide state (applied on load). */
typedef struct appm__ck_head {
    uint32_t format, version[3], method, direct, w, h, max_depth, sampler, chains, guided;
    uint64_t M, seed, scene[APPM__SH_PARTS];
    double alpha, radius;
} appm__ck_head;

typedef struct appm__ck_glob {
    uint64_t pass, emitted, stored, eye, dropped;
    double r1, r_auto, ppm_R2, ppm_R, sec[5];
} appm__ck_glob;

static void appm__ck_head_of(const appm_renderer *r, appm__ck_head *h)
{
    h->format = APPM__CK_FORMAT;
    h->version[0] = APPM_VERSION_MAJOR;
    h->version[1] = APPM_VERSION_MINOR;
    h->version[2] = APPM_VERSION_PATCH;
    h->method = (uint32_t)(r->est - appm__estimators);
    h->direct = (uint32_t)r->direct;
    h->w = r->w;
    h->h = r->h;
    h->max_depth = r->max_depth;
    h->sampler = (uint32_t)(r->sobol ? APPM_SAMPLER_QMC : APPM_SAMPLER_RANDOM);
    h->chains = r->chains;
    h->guided = r->guide.nslot;
    h->M = r->M;
    h->seed = r->seed;
    appm__scene_hash(r->scene, h->scene);
    h->alpha = r->alpha;
    h->radius = r->r1_auto ? 0.0 : r->r1;
}

static void appm__ck_glob_of(const appm_renderer *r, appm__ck_glob *g)
{
    g->pass = r->pass;
    g->emitted = r->stats.photons_emitted;
    g->stored = r->stats.photons_stored;
    g->eye = r->stats.eye_paths;
    g->dropped = r->dropped_other + appm__dropped_own(r);
    g->r1 = r->r1;
    g->r_auto = r->r_auto;
    g->ppm_R2 = r->ppm.R2;
    g->ppm_R = r->ppm.R;
    g->sec[0] = r->stats.seconds;
    g->sec[1] = r->stats.seconds_eye;
    g->sec[2] = r->stats.seconds_photons;
    g->sec[3] = r->stats.seconds_grid;
    g->sec[4] = r->stats.seconds_gather;
}

/* One pixel's or one state's fields, 8 bytes a value. */
static void appm__ck_put_fields(appm__ckw *w, const unsigned char *base, const appm__field *f, unsigned n)
{
    unsigned i, k;
    for (i = 0; i < n; ++i)
        for (k = 0; k < f[i].count; ++k) {
            uint64_t u;
            memcpy(&u, base + f[i].offset + 8 * (size_t)k, sizeof u); /* a double's bits or a count */
            appm__ckw_u(w, u, 8);
        }
}

/* The whole checkpoint of `r` with field lists L into w. */
static void appm__ck_write(appm__ckw *w, const appm_renderer *r, const appm__ck_layout *L)
{
    appm__ck_head h;
    appm__ck_glob g;
    size_t i, npix = (size_t)r->w * r->h;
    unsigned t, k;
    appm__ck_head_of(r, &h);
    appm__ck_glob_of(r, &g);
    appm__ckw_bytes(w, (const unsigned char *)"APPMCKPT", 8);
    appm__ckw_u(w, h.format, 4);
    for (k = 0; k < 3; ++k) appm__ckw_u(w, h.version[k], 4);
    appm__ckw_u(w, h.method, 4);
    appm__ckw_u(w, h.direct, 4);
    appm__ckw_u(w, h.w, 4);
    appm__ckw_u(w, h.h, 4);
    appm__ckw_u(w, h.max_depth, 4);
    appm__ckw_u(w, h.sampler, 4);
    appm__ckw_u(w, h.chains, 4);
    appm__ckw_u(w, h.guided, 4);
    appm__ckw_u(w, h.M, 8);
    appm__ckw_u(w, h.seed, 8);
    appm__ckw_d(w, h.alpha);
    appm__ckw_d(w, h.radius);
    for (k = 0; k < APPM__SH_PARTS; ++k) appm__ckw_u(w, h.scene[k], 8);
    appm__ckw_u(w, g.pass, 8);
    appm__ckw_u(w, g.emitted, 8);
    appm__ckw_u(w, g.stored, 8);
    appm__ckw_u(w, g.eye, 8);
    appm__ckw_u(w, g.dropped, 8);
    appm__ckw_d(w, g.r1);
    appm__ckw_d(w, g.r_auto);
    appm__ckw_d(w, g.ppm_R2);
    appm__ckw_d(w, g.ppm_R);
    for (k = 0; k < 5; ++k) appm__ckw_d(w, g.sec[k]);
    for (t = 0; t < APPM__CK_TABLES; ++t) {
        appm__ckw_u(w, L->n[t], 4);
        for (k = 0; k < L->n[t]; ++k) {
            size_t len = strlen(L->f[t][k].name);
            appm__ckw_u(w, len, 4);
            appm__ckw_bytes(w, (const unsigned char *)L->f[t][k].name, len);
            appm__ckw_u(w, L->f[t][k].count, 4);
            appm__ckw_u(w, L->f[t][k].is_u64, 4);
        }
    }
    for (i = 0; i < npix; ++i)
        for (t = 0; t < APPM__CK_TABLES; ++t)
            if (L->n[t]) appm__ck_put_fields(w, appm__ck_base(r, t, i), L->f[t], L->n[t]);
    for (k = 0; k < r->guide.nslot; ++k) { /* the learned emission (9.1) */
        unsigned c;
        appm__ckw_u(w, r->guide.seen[k], 8);
        appm__ckw_u(w, r->guide.passes[k], 8);
        appm__ckw_d(w, r->guide.sq[k]);
        for (c = 0; c < APPM__GUIDE_ARRAYS * APPM__GUIDE_CELLS; ++c)
            appm__ckw_d(w, r->guide.cells[appm__guide_cell_at(&r->guide, k, c)]);
    }
    appm__ckw_u(w, r->budget != 0, 4);
    appm__ckw_d(w, r->stats.budget_rays);
    appm__ckw_u(w, w->sum, 8);
}

/* -- Reading.  What comes before the pixels, as the file says it. */
#define APPM__CK_NAME 32

typedef struct appm__ck_file {
    appm__ck_head h;
    appm__ck_glob g;
    unsigned n[APPM__CK_TABLES];
    struct {
        char name[APPM__CK_NAME];
        uint32_t count, is_u64;
    } f[APPM__CK_TABLES][APPM__CK_MAXFIELDS];
    int magic, layout_ok;
    uint32_t budget;     /* after the pixels: the photon budget's flag and reading (12.2) */
    double budget_rays;
} appm__ck_file;

static void appm__ck_read_layout(appm__ckr *rd, appm__ck_file *F)
{
    unsigned t, k;
    F->layout_ok = 1;
    for (t = 0; t < APPM__CK_TABLES && F->layout_ok; ++t) {
        F->n[t] = (unsigned)appm__ckr_u(rd, 4);
        /* a pixel always has fields: so each pixel costs at least 8 bytes and no
         * header can make the reader loop longer than the input is long */
        if (F->n[t] > APPM__CK_MAXFIELDS || (t == 0 && F->n[t] == 0)) F->layout_ok = 0;
        for (k = 0; k < F->n[t] && F->layout_ok; ++k) {
            uint64_t len = appm__ckr_u(rd, 4), c;
            unsigned char b = 0;
            if (len >= APPM__CK_NAME) {
                F->layout_ok = 0;
                break;
            }
            for (c = 0; c < len; ++c) {
                appm__ckr_byte(rd, &b, 1);
                F->f[t][k].name[c] = (char)b;
            }
            F->f[t][k].name[len] = 0;
            F->f[t][k].count = (uint32_t)appm__ckr_u(rd, 4);
            F->f[t][k].is_u64 = (uint32_t)appm__ckr_u(rd, 4);
            if (F->f[t][k].count == 0 || F->f[t][k].count > 64 || F->f[t][k].is_u64 > 1) F->layout_ok = 0;
        }
    }
}

static void appm__ck_read_front(appm__ckr *rd, appm__ck_file *F)
{
    appm__ck_head *h = &F->h;
    appm__ck_glob *g = &F->g;
    unsigned char m[8];
    unsigned k;
    memset(F, 0, sizeof *F);
    for (k = 0; k < 8; ++k)
        if (!appm__ckr_byte(rd, &m[k], 1)) m[k] = 0;
    F->magic = memcmp(m, "APPMCKPT", 8) == 0;
    h->format = (uint32_t)appm__ckr_u(rd, 4);
    if (!F->magic || h->format != APPM__CK_FORMAT) return; /* the rest may mean something else */
    for (k = 0; k < 3; ++k) h->version[k] = (uint32_t)appm__ckr_u(rd, 4);
    h->method = (uint32_t)appm__ckr_u(rd, 4);
    h->direct = (uint32_t)appm__ckr_u(rd, 4);
    h->w = (uint32_t)appm__ckr_u(rd, 4);
    h->h = (uint32_t)appm__ckr_u(rd, 4);
    h->max_depth = (uint32_t)appm__ckr_u(rd, 4);
    h->sampler = (uint32_t)appm__ckr_u(rd, 4);
    h->chains = (uint32_t)appm__ckr_u(rd, 4);
    h->guided = (uint32_t)appm__ckr_u(rd, 4);
    h->M = appm__ckr_u(rd, 8);
    h->seed = appm__ckr_u(rd, 8);
    h->alpha = appm__ckr_d(rd);
    h->radius = appm__ckr_d(rd);
    for (k = 0; k < APPM__SH_PARTS; ++k) h->scene[k] = appm__ckr_u(rd, 8);
    g->pass = appm__ckr_u(rd, 8);
    g->emitted = appm__ckr_u(rd, 8);
    g->stored = appm__ckr_u(rd, 8);
    g->eye = appm__ckr_u(rd, 8);
    g->dropped = appm__ckr_u(rd, 8);
    g->r1 = appm__ckr_d(rd);
    g->r_auto = appm__ckr_d(rd);
    g->ppm_R2 = appm__ckr_d(rd);
    g->ppm_R = appm__ckr_d(rd);
    for (k = 0; k < 5; ++k) g->sec[k] = appm__ckr_d(rd);
    appm__ck_read_layout(rd, F);
}

/* First reading of the pixels: only their length and whether every double is
 * finite (the renderer never stores a NaN or an infinity in its statistics);
 * then the photon budget's flag and reading into F. */
static void appm__ck_scan_pixels(appm__ckr *rd, appm__ck_file *F, int *nonfinite)
{
    uint64_t i, bits, npix = (uint64_t)F->h.w * F->h.h;
    unsigned t, k, c;
    for (i = 0; i < npix && rd->ok; ++i)
        for (t = 0; t < APPM__CK_TABLES; ++t)
            for (k = 0; k < F->n[t]; ++k)
                for (c = 0; c < F->f[t][k].count; ++c) {
                    uint64_t u = appm__ckr_u(rd, 8);
                    double d;
                    memcpy(&d, &u, sizeof d);
                    if (!F->f[t][k].is_u64 && !(d - d == 0.0)) *nonfinite = 1;
                }
    for (i = 0; i < (uint64_t)F->h.guided * APPM__CK_GUIDE_WORDS && F->h.guided <= APPM__GUIDE_LIGHTS && rd->ok; ++i) {
        uint64_t u = appm__ckr_u(rd, 8);
        double d;
        memcpy(&d, &u, sizeof d);
        if (i % APPM__CK_GUIDE_WORDS >= 2 && !(d >= 0.0 && d < HUGE_VAL)) *nonfinite = 1; /* the doubles */
    }
    F->budget = (uint32_t)appm__ckr_u(rd, 4);
    bits = appm__ckr_u(rd, 8);
    memcpy(&F->budget_rays, &bits, sizeof bits);
    /* a flag of 0 or 1; the reading finite and not negative (not -0 either: every value saved as
     * read), and 0 where no budget has read (photons given, or pass 0) */
    if (F->budget > 1 || (bits >> 63) || !(F->budget_rays < HUGE_VAL) || ((F->budget == 0 || F->g.pass == 0) && bits))
        *nonfinite = 1;
}

/* Second reading: the values into the renderer, at the offsets of its own
 * field lists (which the first reading found equal to the file's). */
static void appm__ck_get_fields(appm__ckr *rd, unsigned char *base, const appm__field *f, unsigned n)
{
    unsigned i, k;
    for (i = 0; i < n; ++i)
        for (k = 0; k < f[i].count; ++k) {
            uint64_t u = appm__ckr_u(rd, 8);
            memcpy(base + f[i].offset + 8 * (size_t)k, &u, sizeof u);
        }
}

static void appm__ck_load_pixels(appm__ckr *rd, appm_renderer *r, const appm__ck_layout *L)
{
    size_t i, npix = (size_t)r->w * r->h;
    unsigned t;
    for (i = 0; i < npix; ++i)
        for (t = 0; t < APPM__CK_TABLES; ++t)
            if (L->n[t]) appm__ck_get_fields(rd, appm__ck_base(r, t, i), L->f[t], L->n[t]);
    for (t = 0; t < r->guide.nslot; ++t) {
        unsigned c;
        r->guide.seen[t] = appm__ckr_u(rd, 8);
        r->guide.passes[t] = appm__ckr_u(rd, 8);
        r->guide.sq[t] = appm__ckr_d(rd);
        for (c = 0; c < APPM__GUIDE_ARRAYS * APPM__GUIDE_CELLS; ++c)
            r->guide.cells[appm__guide_cell_at(&r->guide, t, c)] = appm__ckr_d(rd);
    }
    (void)appm__ckr_u(rd, 4); /* the budget's flag and reading: applied by appm__ck_load */
    (void)appm__ckr_d(rd);
}

/* The stored hash after the pixels: 1 it matches and the input ends there,
 * 0 it differs, -1 the input ends early, -2 bytes follow. */
static int appm__ck_trailer(appm__ckr *rd)
{
    uint64_t sum = rd->sum, stored = 0;
    unsigned char b = 0;
    int k;
    if (!rd->ok) return -1;
    for (k = 0; k < 8; ++k) {
        if (!appm__ckr_byte(rd, &b, 0)) return -1;
        stored |= (uint64_t)b << (8 * k);
    }
    if (appm__ckr_byte(rd, &b, 0)) return -2;
    return stored == sum ? 1 : 0;
}

static appm_status appm__ck_option(appm_diag *d, const char *name, const char *what, double file, double mine)
{
    return appm__fail(d, APPM_ERR_INVALID_ARG, name, 0,
                      "a checkpoint of another option set: %s is %.17g there, %.17g in this render", what, file,
                      mine);
}

/* The checkpoint's render against this renderer's: the first difference, named. */
static appm_status appm__ck_compare(const appm__ck_file *F, const appm__ck_head *want, const appm__ck_layout *L,
                                    const char *name, appm_diag *d)
{
    const appm__ck_head *h = &F->h;
    unsigned t, k;
    if (memcmp(h->version, want->version, sizeof h->version) != 0)
        return appm__fail(d, APPM_ERR_INVALID_ARG, name, 0,
                          "a checkpoint of appm %u.%u.%u; this is appm %s, whose passes may differ", h->version[0],
                          h->version[1], h->version[2], APPM_VERSION);
    if (h->method != want->method)
        return appm__fail(d, APPM_ERR_INVALID_ARG, name, 0, "a checkpoint of method %s; this render uses %s",
                          h->method < APPM_METHOD_COUNT ? appm__estimators[h->method].name : "(unknown)",
                          appm__estimators[want->method].name);
    if (h->w != want->w || h->h != want->h)
        return appm__fail(d, APPM_ERR_INVALID_ARG, name, 0, "a checkpoint of a %lux%lu image; this render is %lux%lu",
                          (unsigned long)h->w, (unsigned long)h->h, (unsigned long)want->w, (unsigned long)want->h);
    for (k = 0; k < APPM__SH_PARTS; ++k)
        if (h->scene[k] != want->scene[k])
            return appm__fail(d, APPM_ERR_INVALID_ARG, name, 0, "a checkpoint of another scene: %s",
                              appm__sh_part[k]);
    if (h->direct != want->direct) return appm__ck_option(d, name, "direct", h->direct, want->direct);
    if (h->M != want->M) return appm__ck_option(d, name, "photons", (double)h->M, (double)want->M);
    if (h->seed != want->seed) return appm__ck_option(d, name, "seed", (double)h->seed, (double)want->seed);
    if (memcmp(&h->alpha, &want->alpha, sizeof h->alpha) != 0)
        return appm__ck_option(d, name, "alpha", h->alpha, want->alpha);
    if (memcmp(&h->radius, &want->radius, sizeof h->radius) != 0)
        return appm__ck_option(d, name, "radius (0: automatic)", h->radius, want->radius);
    if (h->max_depth != want->max_depth) return appm__ck_option(d, name, "max depth", h->max_depth, want->max_depth);
    if (h->sampler != want->sampler)
        return appm__fail(d, APPM_ERR_INVALID_ARG, name, 0,
                          "a checkpoint of another option set: sampler %s there, %s in this render",
                          h->sampler == APPM_SAMPLER_QMC ? "qmc" : h->sampler == APPM_SAMPLER_RANDOM ? "random" : "?",
                          want->sampler == APPM_SAMPLER_QMC ? "qmc" : "random");
    if (h->chains != want->chains) return appm__ck_option(d, name, "chains", h->chains, want->chains);
    if (h->guided != want->guided)
        return appm__ck_option(d, name, "guided lights (--emission)", h->guided, want->guided);
    for (t = 0; t < APPM__CK_TABLES; ++t)
        for (k = 0; k < (F->n[t] > L->n[t] ? F->n[t] : L->n[t]); ++k)
            if (k >= F->n[t] || k >= L->n[t] || strcmp(F->f[t][k].name, L->f[t][k].name) != 0 ||
                F->f[t][k].count != L->f[t][k].count || F->f[t][k].is_u64 != L->f[t][k].is_u64)
                return appm__fail(d, APPM_ERR_INVALID_ARG, name, 0,
                                  "a checkpoint whose %s state differs from this build's (field %u: '%s' there, "
                                  "'%s' here): written by another version",
                                  t == 0 ? "pixel" : t == 1 ? appm__estimators[want->method].name : "chain",
                                  k + 1,
                                  k < F->n[t] ? F->f[t][k].name : "", k < L->n[t] ? L->f[t][k].name : "");
    return APPM_OK;
}

/* Values no render produces: a non-finite or negative radius or time, r1
 * unlike the radius option, a radius of 0 after pass 1, an absurd pass count. */
static int appm__ck_glob_ok(const appm__ck_glob *g, const appm__ck_head *h, int photons)
{
    const double v[4] = {g->r1, g->r_auto, g->ppm_R2, g->ppm_R};
    int k;
    if (g->pass > ((uint64_t)1 << 52)) return 0;
    for (k = 0; k < 4; ++k)
        if (!(v[k] >= 0.0 && v[k] < HUGE_VAL)) return 0;
    for (k = 0; k < 5; ++k)
        if (!(g->sec[k] >= 0.0 && g->sec[k] < HUGE_VAL)) return 0;
    if (h->radius > 0.0 && g->r1 != h->radius) return 0;
    if (photons && g->pass > 0 && !(g->r1 > 0.0 && g->r_auto > 0.0)) return 0;
    return 1;
}

static void appm__ck_apply(appm_renderer *r, const appm__ck_glob *g)
{
    r->pass = g->pass;
    r->r1 = g->r1;
    r->r_auto = g->r_auto;
    r->ppm.R2 = g->ppm_R2;
    r->ppm.R = g->ppm_R;
    memset(r->dropped, 0, sizeof r->dropped);
    r->dropped[0] = r->dropped_seen = g->dropped; /* counted as this rank's own */
    r->dropped_other = 0;
    r->stats.passes = g->pass;
    r->stats.photons_emitted = g->emitted;
    r->stats.photons_stored = g->stored;
    r->stats.eye_paths = g->eye;
    r->stats.dropped_samples = g->dropped;
    r->stats.initial_radius = g->pass ? g->r1 : 0.0;
    r->stats.seconds = g->sec[0];
    r->stats.seconds_eye = g->sec[1];
    r->stats.seconds_photons = g->sec[2];
    r->stats.seconds_grid = g->sec[3];
    r->stats.seconds_gather = g->sec[4];
    /* readings of the last pass that the checkpoint does not hold: none until the next pass,
     * whatever this renderer read before the load */
    r->stats.clamped = -1.0;
    r->stats.emission_guided = 0.0;
    r->stats.emission_lights = 0;
    r->err_stale = 1;
}

/* Back to the state after creation (a file that changed between the readings). */
static void appm__ck_reset(appm_renderer *r)
{
    appm__ck_glob g;
    size_t npix = (size_t)r->w * r->h;
    memset(&g, 0, sizeof g);
    g.r1 = r->r1_auto ? 0.0 : r->r1;
    memset(r->pix, 0, npix * sizeof *r->pix);
    if (r->est->state_size) memset(r->state, 0, npix * r->est->state_size);
    if (r->chain_sum) memset(r->chain_sum, 0, npix * r->chains * sizeof *r->chain_sum);
    if (r->guide.nslot) {
        memset(r->guide.cells, 0,
               (size_t)r->guide.nslot * APPM__GUIDE_ARRAYS * APPM__GUIDE_CELLS * sizeof *r->guide.cells);
        memset(r->guide.seen, 0, r->guide.nslot * sizeof *r->guide.seen);
        memset(r->guide.passes, 0, r->guide.nslot * sizeof *r->guide.passes);
        memset(r->guide.sq, 0, r->guide.nslot * sizeof *r->guide.sq);
        appm__guide_picks_own(r->scene, &r->guide);
    }
    appm__ck_apply(r, &g);
    if (r->budget) { /* as created: the budget chooses again in pass 1 */
        appm__set_photons(r, r->M0);
        r->budget = 1;
    }
    r->stats.budget_rays = 0.0;
    r->stats.photons_per_pass = 0;
}

/* Checks all of rd, then (a second reading) applies it to r. */
static appm_status appm__ck_load(appm_renderer *r, appm__ckr *rd, const appm__ck_layout *L, const char *name,
                                 appm_diag *d)
{
    appm__ck_file F;
    appm__ck_head want;
    appm__ck_glob g;
    appm_status st;
    int nonfinite = 0, tr, budget_differs;
    double budget_rays;
    appm__ck_head_of(r, &want);
    appm__ck_read_front(rd, &F);
    if (!F.magic) return appm__fail(d, APPM_ERR_PARSE, name, 0, "not an appm checkpoint");
    if (!rd->ok) return appm__fail(d, APPM_ERR_PARSE, name, 0, "truncated checkpoint");
    if (F.h.format != APPM__CK_FORMAT)
        return appm__fail(d, APPM_ERR_INVALID_ARG, name, 0,
                          "checkpoint format version %lu; this build reads version %u only",
                          (unsigned long)F.h.format, APPM__CK_FORMAT);
    if (rd->ok && (!F.layout_ok || F.h.w < 1 || F.h.w > 32768 || F.h.h < 1 || F.h.h > 32768))
        return appm__fail(d, APPM_ERR_PARSE, name, 0, "corrupted checkpoint (impossible image size or field list)");
    appm__ck_scan_pixels(rd, &F, &nonfinite);
    tr = appm__ck_trailer(rd);
    if (tr == -1) return appm__fail(d, APPM_ERR_PARSE, name, 0, "truncated checkpoint");
    if (tr == -2) return appm__fail(d, APPM_ERR_PARSE, name, 0, "corrupted checkpoint (bytes after its end)");
    if (tr == 0) return appm__fail(d, APPM_ERR_PARSE, name, 0, "corrupted checkpoint (checksum mismatch)");
    budget_differs = F.budget != (r->budget != 0); /* the path tracer has none: 0 */
    budget_rays = F.budget_rays; /* the second reading below reads F's head again, not this */
    if (budget_differs || (F.budget == 1 && r->budget &&
                           (F.g.pass ? F.h.M == r->M0 || F.h.M == 2 * r->M0 || F.h.M == 4 * r->M0 : F.h.M == r->M0)))
        want.M = F.h.M; /* the budget's choice (12.2; M0 before pass 1), which this render makes again; or refused below */
    if ((st = appm__ck_compare(&F, &want, L, name, d)) != APPM_OK) return st;
    if (!nonfinite && budget_differs)
        return appm__fail(d, APPM_ERR_INVALID_ARG, name, 0,
                          "a checkpoint of %s; this render %s (--photons)",
                          F.budget ? "a render whose photon budget chose its photon paths a pass"
                                   : "a render told its photon paths a pass",
                          r->budget ? "leaves them to the photon budget" : "is told them");
    if (nonfinite || !appm__ck_glob_ok(&F.g, &F.h, (r->est->caps & APPM__CAP_PHOTONS) != 0))
        return appm__fail(d, APPM_ERR_PARSE, name, 0,
                          "corrupted checkpoint (a value no render produces: non-finite statistics, radii or "
                          "times, or an absurd pass count)");
    g = F.g;
    appm__ckr_rewind(rd);
    appm__ck_read_front(rd, &F);
    appm__ck_load_pixels(rd, r, L);
    if (appm__ck_trailer(rd) != 1 || memcmp(&g, &F.g, sizeof g) != 0) {
        appm__ck_reset(r);
        return appm__fail(d, APPM_ERR_IO, name, 0, "the checkpoint changed while it was read");
    }
    appm__ck_apply(r, &F.g);
    if (r->budget) { /* after pass 1 the checkpoint's M is the budget's choice; before it, M0 */
        appm__set_photons(r, F.g.pass ? F.h.M : r->M0);
        r->budget = F.g.pass ? 2 : 1;
        r->stats.budget_rays = budget_rays;
    }
    r->stats.photons_per_pass = F.g.pass && (r->est->caps & APPM__CAP_PHOTONS) ? r->M : 0;
    return APPM_OK;
}

/* -- The public calls, over memory or files (through r's allocator). */
static appm_status appm__ck_save_mem(const appm_renderer *r, const appm__ck_layout *L, void *buf, size_t cap,
                                     size_t *size, appm_diag *d)
{
    appm__ckw w;
    memset(&w, 0, sizeof w);
    w.buf = (unsigned char *)buf;
    w.cap = buf ? cap : 0;
    w.sum = APPM__FNV_BASIS;
    w.ok = 1;
    appm__ck_write(&w, r, L);
    if (w.total > (uint64_t)SIZE_MAX)
        return appm__fail(d, APPM_ERR_NOMEM, NULL, 0, "a checkpoint of %.0f bytes does not fit in memory",
                          (double)w.total);
    if (size) *size = (size_t)w.total;
    if (buf && w.total > cap)
        return appm__fail(d, APPM_ERR_INVALID_ARG, NULL, 0, "the buffer holds %.0f bytes; the checkpoint needs %.0f",
                          (double)cap, (double)w.total);
    return APPM_OK;
}

static appm_status appm__ck_save_file(appm_renderer *r, const appm__ck_layout *L, const char *path, appm_diag *d)
{
    char tmp[4096];
    int special;
    appm__ckw w;
    appm_diag *keep = r->mem.diag;
    if (strlen(path) + 5 > sizeof tmp) return appm__fail(d, APPM_ERR_INVALID_ARG, path, 0, "path too long");
    special = appm__is_special_file(path);
    sprintf(tmp, "%s.tmp", path);
    memset(&w, 0, sizeof w);
    w.sum = APPM__FNV_BASIS;
    w.ok = 1;
    w.cap = APPM__CK_BLOCK;
    r->mem.diag = d;
    w.buf = (unsigned char *)appm__alloc(&r->mem, APPM__CK_BLOCK, 1);
    r->mem.diag = keep;
    if (!w.buf) return appm__fail(d, APPM_ERR_NOMEM, path, 0, "out of memory writing the checkpoint");
    w.f = fopen(special ? path : tmp, "wb");
    if (w.f) {
        appm__ck_write(&w, r, L);
        if (w.len && fwrite(w.buf, 1, w.len, w.f) != w.len) w.ok = 0;
        if (!special && w.ok && appm__file_sync(w.f) != 0) w.ok = 0; /* the data first, then the name */
        if (fclose(w.f) != 0) w.ok = 0;
        if (!special) {
            if (w.ok && appm__rename_replace(tmp, path) != 0) w.ok = 0;
            if (!w.ok) remove(tmp);
            else appm__dir_sync(path);
        }
    } else {
        w.ok = 0;
    }
    appm__free(&r->mem, w.buf);
    if (!w.ok) return appm__fail(d, APPM_ERR_IO, path, 0, "cannot write the checkpoint");
    return APPM_OK;
}

static appm_status appm__ck_load_mem(appm_renderer *r, const appm__ck_layout *L, const void *buf, size_t len,
                                     appm_diag *d)
{
    appm__ckr rd;
    memset(&rd, 0, sizeof rd);
    rd.p = (const unsigned char *)buf;
    rd.len = len;
    appm__ckr_rewind(&rd);
    return appm__ck_load(r, &rd, L, NULL, d);
}

static appm_status appm__ck_load_file(appm_renderer *r, const appm__ck_layout *L, const char *path, appm_diag *d)
{
    appm__ckr rd;
    appm_status st;
    appm_diag *keep = r->mem.diag;
    memset(&rd, 0, sizeof rd);
    rd.f = fopen(path, "rb");
    if (!rd.f) return appm__fail(d, APPM_ERR_IO, path, 0, "cannot open the checkpoint");
    r->mem.diag = d;
    rd.blk = (unsigned char *)appm__alloc(&r->mem, APPM__CK_BLOCK, 1);
    r->mem.diag = keep;
    if (!rd.blk) {
        fclose(rd.f);
        return appm__fail(d, APPM_ERR_NOMEM, path, 0, "out of memory reading the checkpoint");
    }
    appm__ckr_rewind(&rd);
    st = appm__ck_load(r, &rd, L, path, d);
    if (st == APPM_OK && ferror(rd.f)) st = appm__fail(d, APPM_ERR_IO, path, 0, "read error");
    fclose(rd.f);
    appm__free(&r->mem, rd.blk);
    return st;
}

APPM_API appm_status appm_renderer_save(const appm_renderer *r, void *buf, size_t cap, size_t *size,
                                        appm_diag *diag)
{
    appm__ck_layout L;
    appm__diag_clear(diag);
    if (size) *size = 0;
    if (!r) return appm__fail(diag, APPM_ERR_INVALID_ARG, NULL, 0, "no renderer");
    appm__ck_layout_of(r, &L);
    return appm__ck_save_mem(r, &L, buf, cap, size, diag);
}

APPM_API appm_status appm_renderer_save_file(appm_renderer *r, const char *path, appm_diag *diag)
{
    appm__ck_layout L;
    appm__diag_clear(diag);
    if (!r || !path) return appm__fail(diag, APPM_ERR_INVALID_ARG, path, 0, "no renderer or no path");
    appm__ck_layout_of(r, &L);
    return appm__ck_save_file(r, &L, path, diag);
}

APPM_API appm_status appm_renderer_load(appm_renderer *r, const void *buf, size_t len, appm_diag *diag)
{
    appm__ck_layout L;
    appm__diag_clear(diag);
    if (!r || (!buf && len)) return appm__fail(diag, APPM_ERR_INVALID_ARG, NULL, 0, "no renderer or no checkpoint");
    appm__ck_layout_of(r, &L);
    return appm__ck_load_mem(r, &L, buf, len, diag);
}

APPM_API appm_status appm_renderer_load_file(appm_renderer *r, const char *path, appm_diag *diag)
{
    appm__ck_layout L;
    appm__diag_clear(diag);
    if (!r || !path) return appm__fail(diag, APPM_ERR_INVALID_ARG, path, 0, "no renderer or no path");
    appm__ck_layout_of(r, &L);
    if (r->mem.reader.read) { /* appm_config.reader: its bytes, loaded as they are lent */
        const void *data = NULL;
        size_t len = 0;
        appm_status st;
        if (r->mem.reader.read(r->mem.reader.user, path, &data, &len) != 0 || (!data && len))
            return appm__fail(diag, APPM_ERR_IO, path, 0, "cannot open the checkpoint");
        st = appm__ck_load_mem(r, &L, data, len, diag);
        if (r->mem.reader.release) r->mem.reader.release(r->mem.reader.user, data);
        return st;
    }
    return appm__ck_load_file(r, &L, path, diag);
}

#endif /* APPM_C_INCLUDED */

/* ==== LICENSE =============================================================
 *
 * MIT License.  Copyright (c) 2026 the appm authors.
 *
 * Permission is hereby granted, free of charge, to any person obtaining a copy
 * of this software and associated documentation files (the "Software"), to deal
 * in the Software without restriction, including without limitation the rights
 * to use, copy, modify, merge, publish, distribute, sublicense, and/or sell
 * copies of the Software, and to permit persons to whom the Software is
 * furnished to do so, subject to the following conditions:
 *
 * The above copyright notice and this permission notice shall be included in
 * all copies or substantial portions of the Software.
 *
 * THE SOFTWARE IS PROVIDED "AS IS", WITHOUT WARRANTY OF ANY KIND, EXPRESS OR
 * IMPLIED, INCLUDING BUT NOT LIMITED TO THE WARRANTIES OF MERCHANTABILITY,
 * FITNESS FOR A PARTICULAR PURPOSE AND NONINFRINGEMENT. IN NO EVENT SHALL THE
 * AUTHORS OR COPYRIGHT HOLDERS BE LIABLE FOR ANY CLAIM, DAMAGES OR OTHER
 * LIABILITY, WHETHER IN AN ACTION OF CONTRACT, TORT OR OTHERWISE, ARISING FROM,
 * OUT OF OR IN CONNECTION WITH THE SOFTWARE OR THE USE OR OTHER DEALINGS IN THE
 * SOFTWARE.
 */
