/* bench/refmix.c - combine two independent reference renders A and B.
 *
 *   refmix A.pfm B.pfm OUT.pfm [K]  writes (A + B) / 2 and prints ref_mse=X and
 *                                   ref_relmse=Y
 *
 * A and B have independent errors of equal variance v per pixel and channel,
 * so E[(A - B)^2] = 2v and the average has variance v/2 = E[(A - B)^2] / 4.
 * That is ref_mse: the part of any method's measured MSE against OUT that is
 * the reference's own noise.  Since a method's error is independent of the
 * reference's, MSE(method, OUT) = MSE(method, truth) + ref_mse, and the
 * benchmark subtracts it.  ref_relmse is the same for the relative error
 * (appm_image_compare's relmse: each squared difference over OUT^2 + 0.01).
 *
 * With K > 1, A and B were rendered at K times the size and are first reduced
 * to it by the mean of each K x K block.  The eye pass jitters over the pixel
 * with equal weight (a box filter), so the block's mean has the expectation of
 * the pixel it covers, and a photon method's automatic radius, two pixel widths,
 * is K times narrower: a kernel leans K times less towards its own bias, which
 * in water-caustic's corners, where ppm's kernel loses the wall beyond them,
 * read 8-15 % dark at K = 1 (docs/testing.md).  `refmix A A A K` reduces one
 * half in place (refs.sh keeps its halves so with REF_HALVES=1). */
#include "../appm.h"
#include <stdio.h>
#include <stdlib.h>

/* The image reduced K times in place: each pixel the mean of a K x K block
 * (in double); non-zero if its sides are not multiples of K. */
static int shrink(appm_image *im, int K)
{
    uint32_t w = im->width / (uint32_t)K, h = im->height / (uint32_t)K, x, y, c;
    int i, j;
    if (w * (uint32_t)K != im->width || h * (uint32_t)K != im->height || w == 0 || h == 0) return 1;
    for (y = 0; y < h; ++y)
        for (x = 0; x < w; ++x)
            for (c = 0; c < 3; ++c) {
                double s = 0.0;
                for (j = 0; j < K; ++j)
                    for (i = 0; i < K; ++i)
                        s += im->rgb[(((size_t)y * K + j) * im->width + (size_t)x * K + i) * 3 + c];
                im->rgb[((size_t)y * w + x) * 3 + c] = (float)(s / ((double)K * K));
            }
    im->width = w;
    im->height = h;
    return 0;
}

int main(int argc, char **argv)
{
    appm_image a, b;
    appm_diag d;
    appm_compare_result c;
    size_t i, n;
    double rel = 0.0;
    int K = argc == 5 ? atoi(argv[4]) : 1;
    if ((argc != 4 && argc != 5) || K < 1 || K > 64) {
        fprintf(stderr, "usage: refmix A.pfm B.pfm OUT.pfm [K]\n");
        return 1;
    }
    if (appm_image_read_pfm(argv[1], NULL, &a, &d) || appm_image_read_pfm(argv[2], NULL, &b, &d)) {
        fprintf(stderr, "refmix: %s: %s\n", d.file, d.message);
        return 2;
    }
    if (K > 1 && (shrink(&a, K) || shrink(&b, K))) {
        fprintf(stderr, "refmix: %s or %s is not a multiple of %d pixels wide and high\n", argv[1], argv[2], K);
        return 2;
    }
    if (appm_image_compare(&a, &b, &c) != APPM_OK) {
        fprintf(stderr, "refmix: the images differ in size\n");
        return 2;
    }
    n = (size_t)a.width * a.height * 3;
    for (i = 0; i < n; ++i) {
        double df = (double)a.rgb[i] - b.rgb[i];
        a.rgb[i] = 0.5f * (a.rgb[i] + b.rgb[i]);
        rel += df * df / 4.0 / ((double)a.rgb[i] * a.rgb[i] + 0.01);
    }
    if (appm_image_write(argv[3], &a, 1.0, &d) != APPM_OK) {
        fprintf(stderr, "refmix: %s: %s\n", argv[3], d.message);
        return 2;
    }
    printf("ref_mse=%.9g\nref_relmse=%.9g\n", c.rmse * c.rmse / 4.0, n ? rel / (double)n : 0.0);
    appm_image_free(NULL, &a);
    appm_image_free(NULL, &b);
    return 0;
}
