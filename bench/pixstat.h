/* bench/pixstat.h - the per-pixel statistics that bench/oracle.c and
 * bench/lapdiag.c share, so that both programs split an image into the same
 * regions (docs/algorithm.md 4.16, 4.18) and report the same quantiles. */
#ifndef BENCH_PIXSTAT_H
#define BENCH_PIXSTAT_H
#include <stdlib.h>

/* Rec. 709 luminance of an RGB triple. */
static double pix_lum(const float *p) { return 0.2126 * p[0] + 0.7152 * p[1] + 0.0722 * p[2]; }

static int pix_dcmp(const void *a, const void *b)
{
    double x = *(const double *)a, y = *(const double *)b;
    return x < y ? -1 : x > y;
}

/* The q-quantile of v[0 .. n-1] (nearest rank; sorts v); NaN when n is 0. */
static double pix_quant(double *v, size_t n, double q)
{
    if (!n) return 0.0 / 0.0;
    qsort(v, n, sizeof *v, pix_dcmp);
    return v[(size_t)(q * (double)(n - 1) + 0.5)];
}

/* An "edge" pixel of the w x h image rgb: its luminance over the 3x3
 * neighbours (clipped at the border) varies by more than half its mean. */
static int pix_edge(const float *rgb, unsigned w, unsigned h, unsigned x, unsigned y)
{
    double lo = 1e30, hi = 0.0, mean = 0.0;
    int dx, dy, nn = 0;
    for (dy = -1; dy <= 1; ++dy)
        for (dx = -1; dx <= 1; ++dx) {
            int xx = (int)x + dx, yy = (int)y + dy;
            double l;
            if (xx < 0 || yy < 0 || xx >= (int)w || yy >= (int)h) continue;
            l = pix_lum(rgb + 3 * ((size_t)yy * w + (size_t)xx));
            lo = l < lo ? l : lo;
            hi = l > hi ? l : hi;
            mean += l;
            nn++;
        }
    mean /= nn;
    return (hi - lo) > 0.5 * mean;
}
#endif
