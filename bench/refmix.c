/* bench/refmix.c - combine two independent reference renders A and B.
 *
 *   refmix A.pfm B.pfm OUT.pfm     writes (A + B) / 2 and prints ref_mse=X and
 *                                  ref_relmse=Y
 *
 * A and B have independent errors of equal variance v per pixel and channel,
 * so E[(A - B)^2] = 2v and the average has variance v/2 = E[(A - B)^2] / 4.
 * That is ref_mse: the part of any method's measured MSE against OUT that is
 * the reference's own noise.  Since a method's error is independent of the
 * reference's, MSE(method, OUT) = MSE(method, truth) + ref_mse, and the
 * benchmark subtracts it.  ref_relmse is the same for the relative error
 * (appm_image_compare's relmse: each squared difference over OUT^2 + 0.01). */
#include "../appm.h"
#include <stdio.h>

int main(int argc, char **argv)
{
    appm_image a, b;
    appm_diag d;
    appm_compare_result c;
    size_t i, n;
    double rel = 0.0;
    if (argc != 4) {
        fprintf(stderr, "usage: refmix A.pfm B.pfm OUT.pfm\n");
        return 1;
    }
    if (appm_image_read_pfm(argv[1], NULL, &a, &d) || appm_image_read_pfm(argv[2], NULL, &b, &d)) {
        fprintf(stderr, "refmix: %s: %s\n", d.file, d.message);
        return 2;
    }
    if (appm_image_compare(&a, &b, &c) != APPM_OK) {
        fprintf(stderr, "refmix: the images differ in size\n");
        return 2;
    }
    n = (size_t)a.width * a.height * 3;
    for (i = 0; i < n; ++i) {
        double d = (double)a.rgb[i] - b.rgb[i];
        a.rgb[i] = 0.5f * (a.rgb[i] + b.rgb[i]);
        rel += d * d / 4.0 / ((double)a.rgb[i] * a.rgb[i] + 0.01);
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
