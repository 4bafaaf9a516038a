/* bench/regions.c - RMSE of an image against a reference, per region.
 *
 *   regions IMG.pfm REF.pfm REGIONS.txt [MASK]
 *
 * REGIONS.txt has one region a line, "name x0 y0 x1 y1": the pixels x0 <= x <
 * x1, y0 <= y < y1 (row 0 at the top, as the images); /dev/null for none.
 * Prints one line "name=RMSE" per region and "all=RMSE" for the whole image,
 * RMSE over the pixels and channels of the region (no subtraction of the
 * reference's noise: the regions are small, and that noise would need the
 * reference's two halves; it makes two renders' errors look more alike, never
 * less).  With MASK, also "masked=RMSE" over the pixels whose reference
 * luminance is under MASK: the light seen directly, whose few bright pixels
 * would otherwise hold most of a render's error (water-caustic's lamp, and its
 * image in the water that an eye ray meets once in thousands of passes). */
#include "../appm.h"
#include <stdio.h>
#include <stdlib.h>
#include <math.h>

/* The RMSE over the pixels x0 <= x < x1, y0 <= y < y1 whose reference (b)
 * luminance is under `mask` (HUGE_VAL: every pixel). */
static void rmse(const appm_image *a, const appm_image *b, unsigned x0, unsigned y0, unsigned x1, unsigned y1,
                 double mask, const char *name)
{
    double s = 0.0;
    unsigned long n = 0;
    unsigned x, y;
    int c;
    for (y = y0; y < y1 && y < a->height; ++y)
        for (x = x0; x < x1 && x < a->width; ++x) {
            const float *q = b->rgb + 3 * ((size_t)y * b->width + x);
            if (mask < HUGE_VAL && !(0.2126 * q[0] + 0.7152 * q[1] + 0.0722 * q[2] < mask)) continue;
            for (c = 0; c < 3; ++c) {
                double d = (double)a->rgb[3 * ((size_t)y * a->width + x) + c] - q[c];
                s += d * d;
                n++;
            }
        }
    printf("%s=%.6g\n", name, n ? sqrt(s / n) : 0.0);
}

int main(int argc, char **argv)
{
    appm_image a, b;
    appm_diag d;
    FILE *f;
    char name[64];
    unsigned x0, y0, x1, y1;
    double mask = 0.0;
    if (argc != 4 && argc != 5) {
        fprintf(stderr, "usage: regions IMG.pfm REF.pfm REGIONS.txt [MASK]\n");
        return 1;
    }
    if (argc == 5) {
        char *end;
        mask = strtod(argv[4], &end);
        if (end == argv[4] || *end || !(mask > 0.0)) {
            fprintf(stderr, "regions: MASK must be a positive luminance, not '%s'\n", argv[4]);
            return 1;
        }
    }
    if (appm_image_read_pfm(argv[1], NULL, &a, &d) || appm_image_read_pfm(argv[2], NULL, &b, &d)) {
        fprintf(stderr, "regions: %s: %s\n", d.file, d.message);
        return 2;
    }
    if (a.width != b.width || a.height != b.height) {
        fprintf(stderr, "regions: the images differ in size\n");
        return 2;
    }
    f = fopen(argv[3], "r");
    if (!f) {
        fprintf(stderr, "regions: cannot open %s\n", argv[3]);
        return 2;
    }
    while (fscanf(f, "%63s %u %u %u %u", name, &x0, &y0, &x1, &y1) == 5)
        rmse(&a, &b, x0, y0, x1, y1, HUGE_VAL, name);
    fclose(f);
    rmse(&a, &b, 0, 0, a.width, a.height, HUGE_VAL, "all");
    if (argc == 5) rmse(&a, &b, 0, 0, a.width, a.height, mask, "masked");
    appm_image_free(NULL, &a);
    appm_image_free(NULL, &b);
    return 0;
}
