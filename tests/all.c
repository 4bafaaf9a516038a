/* tests/all.c - every tests/t_*.c compiled into one program.
 *
 * Each test is a program of its own (it includes "../appm.c" and builds alone:
 * `cc tests/t_image.c -lm -pthread`), but then every test compiles all of appm.c
 * again, and make test builds each test twice (plain and with the sanitizers).  Here appm.c is compiled once: the first test includes it and
 * the others' inclusions are empty (its APPM_C_INCLUDED guard).  So the tests
 * share one file scope, and two of them must not define the same name.
 *
 * Which test runs: the first argument (`build/tests t_image`, `node
 * tests/wasi-run.mjs tests.wasm t_image`), or without one the program's own name
 * (make test links build/t_image to build/tests).
 * A name that is not listed here fails: a new tests/t_*.c must be added below. */
#include "../appm.c"
#define CHECK_GAMMA_Q /* t_sampler and t_sampling use it */
#include "check.h"

#define main t_alloc_main
#include "t_alloc.c"
#undef main
#undef GROUP
#define main t_appm_main
#include "t_appm.c"
#undef main
#undef GROUP
#define main t_budget_main
#include "t_budget.c"
#undef main
#undef GROUP
#define main t_bvh_main
#include "t_bvh.c"
#undef main
#undef GROUP
#define main t_checkpoint_main
#include "t_checkpoint.c"
#undef main
#undef GROUP
#define main t_cluster_main
#include "t_cluster.c"
#undef main
#undef GROUP
#define main t_decode_main
#include "t_decode.c"
#undef main
#undef GROUP
#define main t_estimator_main
#include "t_estimator.c"
#undef main
#undef GROUP
#define main t_extremes_main
#include "t_extremes.c"
#undef main
#undef GROUP
#define main t_fuzz_regress_main
#include "t_fuzz_regress.c"
#undef main
#undef GROUP
#define main t_guide_main
#include "t_guide.c"
#undef main
#undef GROUP
#define main t_image_main
#include "t_image.c"
#undef main
#undef GROUP
#define main t_lights_main
#include "t_lights.c"
#undef main
#undef GROUP
#define main t_loader_main
#include "t_loader.c"
#undef main
#undef GROUP
#define main t_pmap_main
#include "t_pmap.c"
#undef main
#undef GROUP
#define main t_portable_main
#include "t_portable.c"
#undef main
#undef GROUP
#define main t_render_main
#include "t_render.c"
#undef main
#undef GROUP
#define main t_sampler_main
#include "t_sampler.c"
#undef main
#undef GROUP
#define main t_sampling_main
#include "t_sampling.c"
#undef main
#undef GROUP
#define main t_texture_main
#include "t_texture.c"
#undef main
#undef GROUP

static const struct {
    const char *name;
    int (*run)(void);
} all_tests[] = {
    {"t_alloc", t_alloc_main},       {"t_appm", t_appm_main},
    {"t_budget", t_budget_main},     {"t_bvh", t_bvh_main},
    {"t_checkpoint", t_checkpoint_main},
    {"t_cluster", t_cluster_main},   {"t_decode", t_decode_main},
    {"t_estimator", t_estimator_main}, {"t_extremes", t_extremes_main},
    {"t_fuzz_regress", t_fuzz_regress_main}, {"t_guide", t_guide_main},
    {"t_image", t_image_main},       {"t_lights", t_lights_main},
    {"t_loader", t_loader_main},     {"t_pmap", t_pmap_main},
    {"t_portable", t_portable_main}, {"t_render", t_render_main},
    {"t_sampler", t_sampler_main},   {"t_sampling", t_sampling_main},
    {"t_texture", t_texture_main},
};

/* The last path component of s, without its extension (t_image.exe, tests.wasm). */
static void all_base(const char *s, char *out, size_t cap)
{
    const char *b = s, *p, *dot = NULL;
    size_t n;
    for (p = s; *p; ++p) {
        if (*p == '/' || *p == '\\') {
            b = p + 1;
            dot = NULL;
        } else if (*p == '.') {
            dot = p;
        }
    }
    n = dot && dot > b ? (size_t)(dot - b) : strlen(b);
    if (n >= cap) n = cap - 1;
    memcpy(out, b, n);
    out[n] = '\0';
}

int main(int argc, char **argv)
{
    char name[64];
    size_t i, n = sizeof all_tests / sizeof all_tests[0];
    all_base(argc > 1 ? argv[1] : argc > 0 && argv[0] ? argv[0] : "", name, sizeof name);
    for (i = 0; i < n; ++i)
        if (strcmp(name, all_tests[i].name) == 0) return all_tests[i].run();
    fprintf(stderr, "tests: no test named '%s'; the tests are:", name);
    for (i = 0; i < n; ++i) fprintf(stderr, " %s", all_tests[i].name);
    fprintf(stderr, "\n(a new tests/t_*.c must be listed in tests/all.c)\n");
    return 2;
}
