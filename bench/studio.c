/* bench/studio.c - the measures of bench/studio.sh.
 *   studio IMAGE        form: the mean luminance (Rec. 709) of the image's
 *                       central tenth (a square of a tenth of the width)
 *                       against the mean of its four corner squares of the
 *                       same size; prints "centre=C corners=K diff=|C-K|/K"
 *   studio IMAGE REF    grain as a viewer sees it: the 8-bit sRGB code of
 *                       each pixel's luminance (as a grey PNG would hold it:
 *                       clamped to [0, 1], rounded), against REF's; over the
 *                       middle 60 % of the image in each direction (the model
 *                       and the plate around it) prints "codes=RMS over4=F", F
 *                       the fraction of those pixels more than 4 codes off.
 *                       Two roundings leave about 0.41 codes RMS even between
 *                       equal images, and REF's own noise counts too. */
#include <math.h>
#include <stdio.h>
#include "../appm.h"

static double luminance(const appm_image *im, size_t i)
{
    const float *p = im->rgb + 3 * i;
    return 0.2126 * p[0] + 0.7152 * p[1] + 0.0722 * p[2];
}

static double square(const appm_image *im, unsigned x0, unsigned y0, unsigned s)
{
    double sum = 0.0;
    unsigned x, y;
    for (y = y0; y < y0 + s; ++y)
        for (x = x0; x < x0 + s; ++x) sum += luminance(im, (size_t)y * im->width + x);
    return sum / ((double)s * s);
}

/* The 8-bit sRGB code of linear value y (the transfer curve of IEC 61966-2-1). */
static int code8(double y)
{
    y = y > 0.0 ? (y < 1.0 ? y : 1.0) : 0.0;
    y = y <= 0.0031308 ? 12.92 * y : 1.055 * pow(y, 1.0 / 2.4) - 0.055;
    return (int)floor(255.0 * y + 0.5);
}

static int grain(const char *a, const char *b)
{
    appm_image im, ref;
    appm_diag d;
    unsigned x, y, x0, x1, y0, y1;
    double sum = 0.0, n = 0.0, over = 0.0;
    if (appm_image_read(a, NULL, &im, &d) != APPM_OK) {
        fprintf(stderr, "studio: %s\n", d.message);
        return 2;
    }
    if (appm_image_read(b, NULL, &ref, &d) != APPM_OK || ref.width != im.width || ref.height != im.height) {
        fprintf(stderr, "studio: %s: %s\n", b, d.message[0] ? d.message : "not the image's size");
        appm_image_free(NULL, &im);
        return 2;
    }
    x0 = im.width / 5;
    x1 = im.width - x0;
    y0 = im.height / 5;
    y1 = im.height - y0;
    for (y = y0; y < y1; ++y)
        for (x = x0; x < x1; ++x) {
            const size_t i = (size_t)y * im.width + x;
            const int e = code8(luminance(&im, i)) - code8(luminance(&ref, i));
            sum += (double)e * e;
            over += e > 4 || e < -4;
            n += 1.0;
        }
    printf("codes=%.3f over4=%.4f\n", sqrt(sum / n), over / n);
    appm_image_free(NULL, &im);
    appm_image_free(NULL, &ref);
    return 0;
}

int main(int argc, char **argv)
{
    appm_image im;
    appm_diag d;
    unsigned s, w, h;
    double c, k;
    if (argc == 3) return grain(argv[1], argv[2]);
    if (argc != 2 || appm_image_read(argv[1], NULL, &im, &d) != APPM_OK) {
        fprintf(stderr, "usage: studio IMAGE [REF] (%s)\n", argc == 2 ? d.message : "");
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
