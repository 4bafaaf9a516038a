/* bench/budget.c - appm at k photon paths a pixel a pass: the error curve of one render.
 *
 *   cc -std=c99 -O2 bench/budget.c appm.c -o bench/budget -lm -pthread
 *   bench/budget SCENE REF.pfm K MASK SEED PASSES [METHOD]
 *
 * Renders at the reference's size with one thread, K * width * height photon paths a pass,
 * and prints "passes seconds rmse" after every power of two of passes and every 16th: the
 * RMSE over the pixels whose reference luminance is below MASK (a light seen directly left
 * out), the seconds those passes took.  bench/budget.sh reads the curves of K = 1/4 .. 4 at
 * equal passes and at equal time (docs/experiments.md, the photon budget). */
#include "../appm.h"
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <math.h>

static double lum(const float *p) { return 0.2126 * p[0] + 0.7152 * p[1] + 0.0722 * p[2]; }

int main(int argc, char **argv)
{
    appm_scene *sc;
    appm_renderer *r;
    appm_config c;
    appm_diag d;
    appm_image ref, img;
    double k, mask;
    int N, j;
    if (argc < 7) {
        fprintf(stderr, "usage: budget SCENE REF.pfm K MASK SEED PASSES [METHOD]\n");
        return 2;
    }
    k = atof(argv[3]);
    mask = atof(argv[4]);
    N = atoi(argv[6]);
    memset(&c, 0, sizeof c);
    if (appm_scene_load(argv[1], NULL, &sc, &d) != APPM_OK || appm_image_read_pfm(argv[2], NULL, &ref, &d) != APPM_OK) {
        fprintf(stderr, "budget: %s\n", d.message);
        return 1;
    }
    c.width = ref.width;
    c.height = ref.height;
    c.threads = 1;
    c.seed = (uint64_t)atoi(argv[5]);
    if (argc > 7 && appm_method_parse(argv[7], &c.method) != APPM_OK) return 2;
    c.photons = (uint64_t)(k * c.width * c.height + 0.5);
    if (appm_renderer_create(sc, &c, &r, &d) != APPM_OK) {
        fprintf(stderr, "budget: %s\n", d.message);
        return 1;
    }
    for (j = 1; j <= N; ++j) {
        if (appm_renderer_pass(r) != APPM_OK) return 1;
        if ((j & (j - 1)) == 0 || j % 16 == 0) {
            size_t i, n = (size_t)c.width * c.height;
            double se = 0.0;
            long nm = 0;
            appm_stats st;
            appm_renderer_image(r, &img);
            for (i = 0; i < n; ++i) {
                int ch;
                if (lum(ref.rgb + 3 * i) >= mask) continue;
                nm++;
                for (ch = 0; ch < 3; ++ch) {
                    double e = (double)img.rgb[3 * i + ch] - ref.rgb[3 * i + ch];
                    se += e * e;
                }
            }
            appm_renderer_stats(r, &st);
            printf("%d %.5f %.6g\n", j, st.seconds, nm ? sqrt(se / (3.0 * (double)nm)) : 0.0);
        }
    }
    appm_renderer_destroy(r);
    appm_image_free(NULL, &ref);
    appm_scene_destroy(sc);
    return 0;
}
