/* bench/studio.c - the form measure of bench/studio.sh: the mean luminance
 * (Rec. 709) of the image's central tenth (a square of a tenth of the width)
 * against the mean of its four corner squares of the same size.
 *   studio IMAGE   prints "centre=C corners=K diff=|C-K|/K" */
#include <math.h>
#include <stdio.h>
#include "../appm.h"

static double square(const appm_image *im, unsigned x0, unsigned y0, unsigned s)
{
    double sum = 0.0;
    unsigned x, y;
    for (y = y0; y < y0 + s; ++y)
        for (x = x0; x < x0 + s; ++x) {
            const float *p = im->rgb + 3 * ((size_t)y * im->width + x);
            sum += 0.2126 * p[0] + 0.7152 * p[1] + 0.0722 * p[2];
        }
    return sum / ((double)s * s);
}

int main(int argc, char **argv)
{
    appm_image im;
    appm_diag d;
    unsigned s, w, h;
    double c, k;
    if (argc != 2 || appm_image_read(argv[1], NULL, &im, &d) != APPM_OK) {
        fprintf(stderr, "usage: studio IMAGE (%s)\n", argc == 2 ? d.message : "");
        return 2;
    }
    w = im.width;
    h = im.height;
    s = w / 10 ? w / 10 : 1;
    c = square(&im, w / 2 - s / 2, h / 2 - s / 2, s);
    k = (square(&im, 0, 0, s) + square(&im, w - s, 0, s) + square(&im, 0, h - s, s) + square(&im, w - s, h - s, s)) / 4;
    printf("centre=%.4f corners=%.4f diff=%.3f\n", c, k, fabs(c - k) / k);
    appm_image_free(NULL, &im);
    return 0;
}
