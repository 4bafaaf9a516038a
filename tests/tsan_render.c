/* tests/tsan_render.c - a threaded render for ThreadSanitizer (testing.md R4).
 *
 * Not one of the tests/t_*.c programs: tests/dynamic.sh builds it with
 * -fsanitize=thread and runs it with TSAN_OPTIONS=halt_on_error=1, so any
 * data race in the worker loop (eye pass, photon pass, gather, radius update,
 * path tracer, the error estimate) ends the program with a report.  A race that TSan does not
 * happen to see can still show as a difference in the image: each method
 * renders 4 passes (appm with guided emission 8) with 4 threads and with 1
 * thread, and the two images must
 * be the same bytes (the image depends only on scene, config, seed and the
 * number of passes - never on the thread count).
 *
 * The scene is held in memory (no files): a box open at the front with a
 * coloured wall, a mirror block and a glass block, lit by an area light, so
 * that every kind of path and every phase of a pass runs on the workers.
 * The last line is "N passed, N failed", like every test program. */
#include "../appm.c"
#include "check.h"

static const char OBJ[] = "mtllib box.mtl\n"
                          "v -1 -1 -1\nv 1 -1 -1\nv 1 1 -1\nv -1 1 -1\n"
                          "v -1 -1 1\nv 1 -1 1\nv 1 1 1\nv -1 1 1\n"
                          "v -0.25 0.98 -0.25\nv 0.25 0.98 -0.25\nv 0.25 0.98 0.25\nv -0.25 0.98 0.25\n"
                          /* a mirror and a glass slab standing on the floor */
                          "v -0.7 -1 -0.6\nv -0.2 -1 -0.6\nv -0.2 0 -0.6\nv -0.7 0 -0.6\n"
                          "v 0.2 -1 0.1\nv 0.7 -1 0.1\nv 0.7 -0.3 0.1\nv 0.2 -0.3 0.1\n"
                          "v 0.2 -1 0.3\nv 0.7 -1 0.3\nv 0.7 -0.3 0.3\nv 0.2 -0.3 0.3\n"
                          "usemtl white\nf 1 2 6 5\nf 4 8 7 3\nf 1 4 3 2\n"
                          "usemtl red\nf 1 5 8 4\n"
                          "usemtl green\nf 2 3 7 6\n"
                          "usemtl light\nf 9 10 11 12\n"
                          "usemtl mirror\nf 13 14 15 16\n"
                          "usemtl glass\nf 17 18 19 20\nf 24 23 22 21\nf 17 20 24 21\nf 18 22 23 19\n"
                          "f 20 19 23 24\n";
static const char MTL[] = "newmtl white\nKd 0.7 0.7 0.7\n"
                          "newmtl red\nKd 0.6 0.1 0.1\n"
                          "newmtl green\nKd 0.1 0.6 0.1\n"
                          "newmtl light\nKd 0.7 0.7 0.7\nKe 8 8 8\n"
                          "newmtl mirror\nillum 3\nKs 0.9 0.9 0.9\n"
                          "newmtl glass\nillum 7\nNi 1.5\n";

#define SIZE 16

static int render(const appm_scene *s, appm_method m, appm_emission e, unsigned threads, float *out)
{
    appm_config cfg;
    appm_renderer *r = NULL;
    appm_diag d;
    appm_image img;
    int pass;
    appm_config_init(&cfg);
    cfg.method = m;
    cfg.width = cfg.height = SIZE;
    cfg.photons = 4096;
    cfg.threads = threads;
    cfg.seed = 17;
    cfg.emission = e;
    if (appm_renderer_create(s, &cfg, &r, &d) != APPM_OK) {
        fprintf(stderr, "appm_renderer_create: %s\n", d.message);
        return 0;
    }
    for (pass = 0; pass < (e == APPM_EMISSION_GUIDED ? 8 : 4); ++pass) {
        appm_stats st;
        if (appm_renderer_pass(r) != APPM_OK) {
            fprintf(stderr, "appm_renderer_pass: %s\n", appm_renderer_last_error(r));
            appm_renderer_destroy(r);
            return 0;
        }
        appm_renderer_stats(r, &st); /* the error estimate's sweeps run on the workers when it is read */
    }
    appm_renderer_image(r, &img);
    memcpy(out, img.rgb, sizeof(float) * SIZE * SIZE * 3);
    appm_renderer_destroy(r);
    return 1;
}

int main(void)
{
    float one[SIZE * SIZE * 3], four[SIZE * SIZE * 3];
    appm_scene *s = NULL;
    appm_diag d;
    int m;
    if (appm_scene_load_obj_memory(OBJ, sizeof OBJ - 1, MTL, sizeof MTL - 1, "tsan-box", NULL, &s, &d) !=
        APPM_OK) {
        fprintf(stderr, "%s:%u: %s\n", d.file, d.line, d.message);
        CHECK(0);
        return check_finish();
    }
    for (m = 0; m < (int)APPM_METHOD_COUNT; ++m) {
        int ok = render(s, (appm_method)m, APPM_EMISSION_LIGHT, 1, one) &&
                 render(s, (appm_method)m, APPM_EMISSION_LIGHT, 4, four);
        CHECK_MSG(ok && memcmp(one, four, sizeof one) == 0, "%s: 4 threads differ from 1 thread",
                  appm_method_name((appm_method)m));
    }
    { /* guided emission: each worker counts into its own array (appm.c 9.1) */
        int ok = render(s, APPM_METHOD_APPM, APPM_EMISSION_GUIDED, 1, one) &&
                 render(s, APPM_METHOD_APPM, APPM_EMISSION_GUIDED, 4, four);
        CHECK_MSG(ok && memcmp(one, four, sizeof one) == 0, "guided emission: 4 threads differ from 1 thread");
    }
    appm_scene_destroy(s);
    return check_finish();
}
