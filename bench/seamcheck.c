/* bench/seamcheck.c - the kernel cut at a seam (appm.c 10.5, docs/algorithm.md
 * 4.19) against the path tracer, on any scene whose light a path tracer reaches.
 *
 *   cc -std=c99 -O2 bench/seamcheck.c -o bench/seamcheck -lm -pthread
 *   bench/seamcheck SCENE SIZE PASSES PT_PASSES
 *
 * Renders SIZE x SIZE with appm for PASSES passes with the cut and without it
 * (the renderer's own switch, which the public API does not offer), and with
 * the path tracer for PT_PASSES passes, seed 11, 2 threads.  Over the pixels
 * next to a seam (a 4-neighbour on another surface in appm's last pass) and
 * whose reference luminance lies in (0.02, 1): the mean relative error of each
 * appm image and its RMSE; then the RMSE over all such pixels, seam or not.
 * The same measurement as t_appm's test_corner_bias, for other scenes. */
#include "../appm.c"
#include <stdio.h>

#define MAXS 256

static double lumf(const float *p) { return 0.2126 * p[0] + 0.7152 * p[1] + 0.0722 * p[2]; }

int main(int argc, char **argv)
{
    static float ref[MAXS * MAXS * 3], img[2][MAXS * MAXS * 3];
    static uint8_t edge[MAXS * MAXS];
    appm_scene *s = NULL;
    appm_diag d;
    int S, P, PT, t, i;
    double err[2] = {0, 0}, se[2] = {0, 0}, sa[2] = {0, 0}, n = 0, na = 0;
    if (argc < 5 || (S = atoi(argv[2])) < 4 || S > MAXS || (P = atoi(argv[3])) < 1 || (PT = atoi(argv[4])) < 1) {
        fprintf(stderr, "usage: seamcheck SCENE SIZE(4..%d) PASSES PT_PASSES\n", MAXS);
        return 2;
    }
    if (appm_scene_load(argv[1], NULL, &s, &d) != APPM_OK) {
        fprintf(stderr, "%s\n", d.message);
        return 1;
    }
    for (t = 0; t < 3; ++t) { /* 0, 1: appm with and without the cut; 2: the path tracer */
        appm_config cfg;
        appm_renderer *r = NULL;
        appm_image im;
        appm_config_init(&cfg);
        cfg.width = cfg.height = (uint32_t)S;
        cfg.threads = 2;
        cfg.seed = 11;
        cfg.method = t == 2 ? APPM_METHOD_PT : APPM_METHOD_APPM;
        if (appm_renderer_create(s, &cfg, &r, &d) != APPM_OK) {
            fprintf(stderr, "%s\n", d.message);
            return 1;
        }
        if (t == 1) r->cut = 0;
        for (i = 0; i < (t == 2 ? PT : P); ++i)
            if (appm_renderer_pass(r) != APPM_OK) {
                fprintf(stderr, "pass %d failed\n", i + 1);
                return 1;
            }
        appm_renderer_image(r, &im);
        memcpy(t == 2 ? ref : img[t], im.rgb, sizeof(float) * 3 * (size_t)S * (size_t)S);
        if (t == 0)
            for (i = 0; i < S * S; ++i) edge[i] = r->vp[i].segs && r->vp[i].edge == 0;
        appm_renderer_destroy(r);
    }
    for (i = 0; i < S * S; ++i) {
        double L = lumf(ref + 3 * i);
        if (!(L > 0.02) || L >= 1.0) continue;
        for (t = 0; t < 2; ++t) {
            double v = lumf(img[t] + 3 * i);
            if (edge[i]) {
                err[t] += v / L - 1.0;
                se[t] += (v - L) * (v - L);
            }
            sa[t] += (v - L) * (v - L);
        }
        n += edge[i];
        na += 1.0;
    }
    if (n < 1.0 || na < 1.0) {
        printf("%s: no pixel next to a seam\n", argv[1]);
        return 0;
    }
    printf("%s %dx%d, %d passes, pt %d: %.0f pixels at a seam: mean relative error cut %+.4f, without %+.4f; "
           "their RMSE %.5f, %.5f; all pixels' RMSE %.5f, %.5f\n",
           argv[1], S, S, P, PT, n, err[0] / n, err[1] / n, sqrt(se[0] / n), sqrt(se[1] / n), sqrt(sa[0] / na),
           sqrt(sa[1] / na));
    appm_scene_destroy(s);
    return 0;
}
