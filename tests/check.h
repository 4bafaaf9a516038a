/* tests/check.h - the whole test framework: CHECK macros, a closing summary
 * line, temporary files, and an allocator that fails on request.
 *
 * Every tests/t_*.c is its own program: it includes "../appm.c" (to reach the
 * static internals) and this file, runs its checks and ends with
 * `return check_finish();`, which prints "N passed, N failed".  tests/run.sh
 * runs them all and adds the counts up.
 *
 * APPM_TEST_QUICK=1 in the environment (set for the sanitizer builds) asks
 * slow tests to use fewer samples; tolerances must stay honest for both. */
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
    return q && q[0] == '1';
}

/* A scratch folder for the test's files: tests/out/<group>-<file>.  The first
 * call creates tests/out (an existing one is fine), so a test binary also runs
 * on its own from the repository root.  Returns a static buffer: copy if needed. */
static inline const char *check_path(const char *group, const char *file)
{
    static char buf[2][1024];
    static int k, made;
    if (!made) {
        (void)check_mkdir_("tests/out");
        made = 1;
    }
    k ^= 1;
    snprintf(buf[k], sizeof buf[k], "tests/out/%s-%s", group, file);
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
