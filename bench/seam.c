/* bench/seam.c - where an image pair differs, the mean relative difference of
 * other images from a reference (docs/algorithm.md 4.19: the seams of
 * water-caustic).
 *
 *   cc -std=c99 -O2 bench/seam.c appm.c -o bench/seam -lm -pthread
 *   bench/seam A.pfm B.pfm REF.pfm X.pfm [X.pfm ...]
 *
 * The pixels counted are those where A and B differ (A and B: the same render
 * without and with a change that touches only some pixels) and where REF and
 * every X have a luminance in (0.02, 10) (black pixels and the light left out).
 * Prints their number and, for each X, the mean of lum(X) / lum(REF) - 1. */
#include "../appm.h"
#include <stdio.h>
#include <string.h>

static double lum(const float *p) { return 0.2126 * p[0] + 0.7152 * p[1] + 0.0722 * p[2]; }

int main(int argc, char **argv)
{
    appm_image im[16];
    appm_diag d;
    size_t i, n, k, used = 0;
    int a, nx = argc - 4;
    double sum[16] = {0};
    if (argc < 5 || nx > 12) {
        fprintf(stderr, "usage: seam A.pfm B.pfm REF.pfm X.pfm [X.pfm ...] (at most 12)\n");
        return 2;
    }
    for (a = 1; a < argc; ++a) {
        if (appm_image_read_pfm(argv[a], NULL, &im[a - 1], &d) != APPM_OK) {
            fprintf(stderr, "%s\n", d.message);
            return 1;
        }
        if (im[a - 1].width != im[0].width || im[a - 1].height != im[0].height) {
            fprintf(stderr, "%s: not the size of %s\n", argv[a], argv[1]);
            return 1;
        }
    }
    n = (size_t)im[0].width * im[0].height;
    for (i = 0; i < n; ++i) {
        double r = lum(im[2].rgb + 3 * i);
        int ok = memcmp(im[0].rgb + 3 * i, im[1].rgb + 3 * i, 3 * sizeof(float)) != 0 && r > 0.02 && r < 10.0;
        for (k = 0; ok && k < (size_t)nx; ++k) {
            double x = lum(im[3 + k].rgb + 3 * i);
            ok = x > 0.02 && x < 10.0;
        }
        if (!ok) continue;
        for (k = 0; k < (size_t)nx; ++k) sum[k] += lum(im[3 + k].rgb + 3 * i) / r - 1.0;
        used++;
    }
    printf("pixels=%lu", (unsigned long)used);
    for (k = 0; k < (size_t)nx; ++k) printf(" %s=%+.4f", argv[4 + k], used ? sum[k] / (double)used : 0.0);
    printf("\n");
    for (a = 0; a < argc - 1; ++a) appm_image_free(NULL, &im[a]);
    return 0;
}
