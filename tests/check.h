/* tests/check.h - the whole test framework: CHECK macros, a closing summary
 * line, temporary files, and an allocator that fails on request.
 *
 * Every tests/t_*.c is its own program: it includes "../appm.c" (to reach the
 * static internals) and this file, runs its checks and ends with
 * `return check_finish();`, which prints "N passed, N failed".  tests/run.sh
 * runs them all and adds the counts up.  make test builds them as one program
 * (tests/all.c), so the helpers they share live here; they need appm.h first.
 *
 * APPM_TEST_QUICK=1 in the environment (set for the sanitizer builds) asks
 * slow tests to use fewer samples; tolerances must stay honest for both.
 * APPM_TEST_QUICK=2 (emulated targets) is quick, with check_count's loops
 * shorter still. */
#ifndef APPM_TEST_CHECK_H
#define APPM_TEST_CHECK_H

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#if defined(_WIN32)
#include <direct.h>
#define check_mkdir_(path) _mkdir(path)
#else
#include <sys/stat.h>
#define check_mkdir_(path) mkdir(path, 0777)
#endif

static int g_pass, g_fail;

#define CHECK(cond)                                                                      \
    do {                                                                                 \
        if (cond) g_pass++;                                                              \
        else {                                                                           \
            g_fail++;                                                                    \
            fprintf(stderr, "%s:%d: CHECK(%s) failed\n", __FILE__, __LINE__, #cond);     \
        }                                                                                \
    } while (0)

/* CHECK with a printf-style explanation printed on failure. */
#define CHECK_MSG(cond, ...)                                                             \
    do {                                                                                 \
        if (cond) g_pass++;                                                              \
        else {                                                                           \
            g_fail++;                                                                    \
            fprintf(stderr, "%s:%d: CHECK(%s) failed: ", __FILE__, __LINE__, #cond);     \
            fprintf(stderr, __VA_ARGS__);                                                \
            fprintf(stderr, "\n");                                                       \
        }                                                                                \
    } while (0)

/* |a - b| <= tol, printing both values on failure. */
#define CHECK_NEAR(a, b, tol)                                                            \
    do {                                                                                 \
        double check_a_ = (double)(a), check_b_ = (double)(b), check_t_ = (double)(tol); \
        if (fabs(check_a_ - check_b_) <= check_t_) g_pass++;                             \
        else {                                                                           \
            g_fail++;                                                                    \
            fprintf(stderr, "%s:%d: %s = %.9g, expected %s = %.9g within %.3g\n",        \
                    __FILE__, __LINE__, #a, check_a_, #b, check_b_, check_t_);           \
        }                                                                                \
    } while (0)

static inline int check_finish(void)
{
    printf("%d passed, %d failed\n", g_pass, g_fail);
    return g_fail != 0;
}

static inline int check_quick(void)
{
    const char *q = getenv("APPM_TEST_QUICK");
    return q && (q[0] == '1' || q[0] == '2');
}

/* A loop's length: FULL, QUICK with APPM_TEST_QUICK=1, and QUICK / 5 with
 * APPM_TEST_QUICK=2 (an emulator, some 50 times slower: tests/portability.sh's
 * qemu runs), never below 1.  Only loops whose tolerance does not depend on
 * their length may use it. */
static inline long check_count(long full, long quick)
{
    const char *q = getenv("APPM_TEST_QUICK");
    if (q && q[0] == '2') return quick / 5 > 0 ? quick / 5 : 1;
    return check_quick() ? quick : full;
}

/* A scratch file for the test: tests/out/<group>-<file>, or with APPM_TEST_OUT
 * set (tests/run.sh gives each command its own, so that two builds of one test
 * may run side by side) tests/out-<APPM_TEST_OUT>/<group>-<file>: one folder
 * beside tests/out, so that files naming each other (a scene and its mesh, or
 * ../fixtures/) still find each other.  The first call creates the folder (an
 * existing one is fine), so a test binary also runs on its own from the
 * repository root.  Returns a static buffer: copy if needed. */
static inline const char *check_path(const char *group, const char *file)
{
    static char buf[2][1024], dir[64];
    static int k, made;
    if (!made) {
        const char *tag = getenv("APPM_TEST_OUT");
        (void)check_mkdir_("tests/out");
        snprintf(dir, sizeof dir, "tests/out");
        if (tag && tag[0] && strlen(tag) < 32 && !strpbrk(tag, "/\\.")) {
            snprintf(dir, sizeof dir, "tests/out-%s", tag);
            (void)check_mkdir_(dir);
        }
        made = 1;
    }
    k ^= 1;
    snprintf(buf[k], sizeof buf[k], "%s/%s-%s", dir, group, file);
    return buf[k];
}

static inline int check_write_file(const char *path, const char *text)
{
    FILE *f = fopen(path, "wb");
    size_t n = strlen(text);
    int ok = f && fwrite(text, 1, n, f) == n;
    if (f && fclose(f) != 0) ok = 0;
    return ok;
}

/* The whole of a file in a malloc'd buffer with a NUL after its *len bytes (so
 * a text file is also a C string); NULL, *len = 0 when it cannot be read. */
static inline unsigned char *check_read_file(const char *path, size_t *len)
{
    FILE *f = fopen(path, "rb");
    unsigned char *buf = NULL;
    long n;
    *len = 0;
    if (!f) return NULL;
    if (fseek(f, 0, SEEK_END) == 0 && (n = ftell(f)) >= 0 && fseek(f, 0, SEEK_SET) == 0) {
        buf = (unsigned char *)malloc((size_t)n + 1);
        if (buf && fread(buf, 1, (size_t)n, f) == (size_t)n) {
            buf[n] = 0;
            *len = (size_t)n;
        } else {
            free(buf);
            buf = NULL;
        }
    }
    fclose(f);
    return buf;
}

#define CHECK_PI 3.14159265358979323846

/* A float's bits, for comparisons that must be exact (and see -0 and NaNs). */
static inline uint32_t check_fbits(float f)
{
    uint32_t u;
    memcpy(&u, &f, sizeof u);
    return u;
}

/* The mean of every channel of every pixel. */
static inline double check_image_mean(const appm_image *img)
{
    size_t i, n = (size_t)img->width * img->height * 3;
    double s = 0.0;
    for (i = 0; i < n; ++i) s += img->rgb[i];
    return s / (double)n;
}

static inline const char *check_method_name(appm_method m)
{
    static const char *const names[APPM_METHOD_COUNT] = {"appm", "ppm", "sppm", "pt", "appm-paper"};
    return names[m];
}

/* The glossy lobe's albedo A(theta) of appm.c section 6.1,
 * int (Ns+2)/(2 pi) cos^Ns(a) max(0, n.wi) dw at incidence theta (st = sin
 * theta, ct = cos theta), integrated in the lobe's own frame: with
 * t = cos^(Ns+1) a the lobe measure is uniform, (Ns+1)/(2 pi) cos^Ns a dw =
 * dt dphi / (2 pi), so the albedo is (Ns+2)/(Ns+1) times the mean of
 * max(0, n.wi) over (t, phi).  At fixed t, n.wi = A - B cos phi
 * (A = cos a cos theta, B = sin a sin theta), whose positive part has the mean
 * (A (pi - p0) + B sin p0) / pi, p0 = acos(A / B), with p0 / pi of the circle
 * below the horizon; the t integral is a midpoint rule of n points on each side
 * of t* = sin^(Ns+1) theta, where the horizon starts to cut.  *below (unless
 * NULL): the share of lobe samples below the horizon. */
static inline double check_lobe_quad(double ns, double st, double ct, int n, double *below)
{
    double ts = pow(st, ns + 1.0), sum = 0.0, out = 0.0;
    int i, part;
    for (part = 0; part < 2; ++part) {
        double lo = part ? ts : 0.0, hi = part ? 1.0 : ts, h = (hi - lo) / n;
        for (i = 0; i < n && h > 0.0; ++i) {
            double t = lo + (i + 0.5) * h, ca = pow(t, 1.0 / (ns + 1.0)), sa = sqrt(fmax(0.0, 1.0 - ca * ca));
            double A = ca * ct, B = sa * st, p0;
            if (B <= fabs(A)) {
                sum += (A > 0.0 ? A : 0.0) * h;
                out += (A > 0.0 ? 0.0 : 1.0) * h;
                continue;
            }
            p0 = acos(A / B);
            sum += (A * (CHECK_PI - p0) + B * sin(p0)) / CHECK_PI * h;
            out += p0 / CHECK_PI * h;
        }
    }
    if (below) *below = out;
    return (ns + 2.0) / (ns + 1.0) * sum;
}

/* An allocator that counts live bytes and fails allocation number `fail_at`
 * (1-based; 0 = never), the SQLite memdebug_fail idea. */
typedef struct check_alloc {
    long count, fail_at;
    long long live, peak;
} check_alloc;

static inline void *check_alloc_fn(void *user, size_t n)
{
    check_alloc *a = (check_alloc *)user;
    void *p;
    a->count++;
    if (a->fail_at > 0 && a->count == a->fail_at) return NULL;
    p = malloc(n);
    if (p) {
        a->live += (long long)n;
        if (a->live > a->peak) a->peak = a->live;
    }
    return p;
}

static inline void check_free_fn(void *user, void *p, size_t n)
{
    check_alloc *a = (check_alloc *)user;
    if (!p) return;
    a->live -= (long long)n;
    free(p);
}

static inline void check_use_alloc(appm_config *cfg, check_alloc *a, long fail_at)
{
    memset(a, 0, sizeof *a);
    a->fail_at = fail_at;
    cfg->allocator.alloc = check_alloc_fn;
    cfg->allocator.free = check_free_fn;
    cfg->allocator.user = a;
}

/* The warnings a library call passes to cfg.log (set cfg.log = check_on_log,
 * cfg.log_user = a check_log): how many, and the last one with its line. */
typedef struct check_log {
    int n;
    unsigned line;
    char last[512];
} check_log;

static inline void check_on_log(void *user, const char *file, unsigned line, const char *msg)
{
    check_log *l = (check_log *)user;
    (void)file;
    l->n++;
    l->line = line;
    snprintf(l->last, sizeof l->last, "%s", msg);
}

/* Loads a scene, recording a failed CHECK (with file:line: message) on error. */
static inline appm_scene *check_load_scene(const char *path)
{
    appm_scene *s = NULL;
    appm_diag d;
    appm_status st = appm_scene_load(path, NULL, &s, &d);
    CHECK_MSG(st == APPM_OK, "loading %s: %s:%u: %s", path, d.file, d.line, d.message);
    return st == APPM_OK ? s : NULL;
}

static inline appm_renderer *check_renderer(const appm_scene *s, const appm_config *cfg)
{
    appm_renderer *r = NULL;
    appm_diag d;
    appm_status st = appm_renderer_create(s, cfg, &r, &d);
    CHECK_MSG(st == APPM_OK, "appm_renderer_create: %s", d.message);
    return st == APPM_OK ? r : NULL;
}

/* Runs n passes; 0 (and a failed CHECK) at the first failure. */
static inline int check_passes(appm_renderer *r, int n)
{
    int i;
    for (i = 0; i < n; ++i) {
        appm_status st = appm_renderer_pass(r);
        if (st != APPM_OK) {
            CHECK_MSG(st == APPM_OK, "appm_renderer_pass: %s", appm_renderer_last_error(r));
            return 0;
        }
    }
    return 1;
}

#ifdef CHECK_GAMMA_Q
/* For the chi-square tests (t_sampling, t_sampler); define CHECK_GAMMA_Q
 * before including this header. */
/* Regularised upper incomplete gamma function Q(a, x) = Gamma(a, x) / Gamma(a):
 * the power series of P = 1 - Q for x < a + 1, where it converges fast, and
 * Lentz's continued fraction for Q otherwise (Numerical Recipes, 6.2). */
static double gamma_q(double a, double x)
{
    double lpre;
    int i;
    if (!(x > 0.0)) return 1.0;
    lpre = -x + a * log(x) - lgamma(a);
    if (x < a + 1.0) {
        double ap = a, del = 1.0 / a, sum = del;
        for (i = 0; i < 10000; ++i) {
            ap += 1.0;
            del *= x / ap;
            sum += del;
            if (fabs(del) < fabs(sum) * 1e-16) break;
        }
        return 1.0 - sum * exp(lpre);
    } else {
        const double tiny = 1e-300;
        double b = x + 1.0 - a, c = 1.0 / tiny, d = 1.0 / b, h = d;
        for (i = 1; i < 10000; ++i) {
            double an = -i * (i - a), del;
            b += 2.0;
            d = an * d + b;
            if (fabs(d) < tiny) d = tiny;
            c = b + an / c;
            if (fabs(c) < tiny) c = tiny;
            d = 1.0 / d;
            del = d * c;
            h *= del;
            if (fabs(del - 1.0) < 1e-16) break;
        }
        return exp(lpre) * h;
    }
}

/* Survival function of the chi-square distribution with `dof` degrees. */
#endif

#endif
