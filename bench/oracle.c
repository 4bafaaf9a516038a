/* bench/oracle.c - the error-minimising fixed radius per pixel, against the
 * radius appm picks (docs/algorithm.md 4.16).
 *
 *   oracle REF.pfm R_AUTO PASSES REGIONS.txt NF F_1..F_NF NS IMG_1_1..IMG_NF_NS APPM_1..APPM_NS
 *
 * IMG_f_s: ppm with the fixed radius F_f x R_AUTO (alpha 1) after PASSES passes,
 * seed s (f-major order).  APPM_s: the --aux prefix of appm's render of seed s
 * at the same passes (PREFIX-radius{,-caustic,-diffuse}.pfm are read, and the
 * image PREFIX.pfm of the last seed).
 *
 * Per pixel, e_f = the squared error against REF summed over the channels, the
 * 3x3 neighbours and the NS seeds (the reference's own noise adds the same to
 * every f, so it moves no minimum); the oracle radius f* is the grid minimum
 * refined by a parabola in log f through it and its two grid neighbours.
 *
 * Units: ppm's kernel is the uniform disc, appm's the biweight.  Their bias is
 * mu2 r^2 DeltaI / 2 with mu2 = 1/4 (uniform, per axis) and 1/8 (biweight), so a
 * biweight radius R smooths as a uniform one of R / sqrt 2.  appm's radius R_N
 * is that of its last pass; its image averages passes with radii shrinking
 * about as j^(-1/6) (at the bound exactly so), whose mean bias is that of a
 * fixed radius sqrt(3/2) R_N and mean variance that of one sqrt(4/3) R_N; so
 * appm's radius is compared as the fixed uniform radius
 *     u = KAPPA R_N / R_AUTO,  KAPPA = sqrt(1.5 / 2) = 0.866,
 * and its upper bound 2 r_auto PASSES^(-1/6) as KAPPA times that.
 *
 * Pixels left out: the reference's luminance >= 1 (the light seen directly)
 * and where appm's radius map is not a positive number (no gather).
 * "edges" are the pixels whose reference luminance over the 3x3 neighbours
 * varies by more than half its mean (shadow and geometric edges, the rims of
 * a caustic), reported beside the rectangles of REGIONS.txt ("name x0 y0 x1
 * y1", first match wins) and "smooth" (the other pixels); "@bound": those of
 * them at appm's upper bound on every seed. */
#include "../appm.h"
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include "pixstat.h"
#include <math.h>

#define MAXF 32
#define MAXS 8
#define MAXR 32
#define KAPPA 0.8660254


static int readimg(const char *path, appm_image *im, unsigned w, unsigned h)
{
    appm_diag d;
    if (appm_image_read_pfm(path, NULL, im, &d)) {
        fprintf(stderr, "oracle: %s: %s\n", d.file, d.message);
        return 0;
    }
    if (w && (im->width != w || im->height != h)) {
        fprintf(stderr, "oracle: %s: size differs\n", path);
        return 0;
    }
    return 1;
}

/* One set of pixels: the quartiles of f*, appm's u (dominant, caustic,
 * diffuse component), the fraction with f* above appm's bound and above
 * appm's u, the fraction of appm's pixels at its bound, and the squared error
 * (per pixel, 3 seeds summed) at the oracle's grid minimum, at the grid point
 * nearest appm's u and at the grid point nearest the bound, relative to the
 * best single f for the whole set. */
typedef struct set {
    double *fs, *u, *uc, *ud;
    size_t n;
    size_t above_bound, above_u, at_bound;
    double e_or, e_u, e_b, e_f[MAXF];
    double *dlog;                         /* |log2 f*(first seeds) / f*(last seed)| */
    size_t nd;
    double t_or, t_u, t_appm, tr_f[MAXF], te_f[MAXF]; /* the last seed's squared error, unsmoothed */
} set;

static void report(const char *name, set *s, int nf, const double *F, double tot_u)
{
    int k, kb = 0, kt = 0;
    for (k = 1; k < nf; ++k)
        if (s->tr_f[k] < s->tr_f[kt]) kt = k;
    for (k = 1; k < nf; ++k)
        if (s->e_f[k] < s->e_f[kb]) kb = k;
    if (!s->n) return;
    printf("%-13s n=%4lu f*=%.3g [%.3g %.3g] appm_u=%.3g (c %.3g d %.3g) f*>bound=%.2f f*>u=%.2f at_bound=%.2f "
           "best_global_f=%.3g mse/best: oracle %.3f appm_u %.3f bound %.3f\n",
           name, (unsigned long)s->n, pix_quant(s->fs, s->n, 0.5), pix_quant(s->fs, s->n, 0.25), pix_quant(s->fs, s->n, 0.75),
           pix_quant(s->u, s->n, 0.5), pix_quant(s->uc, s->n, 0.5), pix_quant(s->ud, s->n, 0.5),
           (double)s->above_bound / s->n, (double)s->above_u / s->n, (double)s->at_bound / s->n, F[kb],
           s->e_or / s->e_f[kb], s->e_u / s->e_f[kb], s->e_b / s->e_f[kb]);
    if (s->nd)
        printf("%-13s   held-out seed: share of appm_u's error %.3f; |log2 f*(first)/f*(last)| median %.2f; "
               "mse/(best global f %.3g of the first seeds): oracle %.3f appm_u %.3f appm's image %.3f\n",
               name, s->t_u / tot_u, pix_quant(s->dlog, s->nd, 0.5), F[kt], s->t_or / s->te_f[kt], s->t_u / s->te_f[kt],
               s->t_appm / s->te_f[kt]);
}

/* The grid point of least error and its refinement (a parabola in log f). */
static double argmin(const double *ep, const double *F, int nf, int *kbo)
{
    int k, kb = 0;
    double fs;
    for (k = 1; k < nf; ++k)
        if (ep[k] < ep[kb]) kb = k;
    fs = F[kb];
    if (kb > 0 && kb < nf - 1) {
        double t0 = log(F[kb - 1]), t1 = log(F[kb]), t2 = log(F[kb + 1]);
        double d1 = (ep[kb] - ep[kb - 1]) / (t1 - t0), d2 = (ep[kb + 1] - ep[kb]) / (t2 - t1);
        double cc = (d2 - d1) / (t2 - t0);
        if (cc > 0.0) {
            double t = 0.5 * (t0 + t1) - d1 / (2.0 * cc);
            fs = exp(t < t0 ? t0 : t > t2 ? t2 : t);
        }
    }
    *kbo = kb;
    return fs;
}

static int nearest(const double *F, int nf, double v)
{
    int k, b = 0;
    for (k = 1; k < nf; ++k)
        if (fabs(log(F[k] / v)) < fabs(log(F[b] / v))) b = k;
    return b;
}

int main(int argc, char **argv)
{
    appm_image ref, img[MAXF][MAXS], ar[MAXS][3], ai;
    double F[MAXF], rauto, r_hi, bound_u, *e, *es, *er;
    unsigned long passes;
    int nf, ns, a = 1, k, s, c, r, nreg = 0, kbnd;
    unsigned w, h, x, y, i, rx0[MAXR], ry0[MAXR], rx1[MAXR], ry1[MAXR];
    char rname[MAXR][64];
    static const char *const comp[3] = {"radius", "radius-caustic", "radius-diffuse"};
    set sets[MAXR + 5];
    FILE *fr;
    if (argc < 8) {
        fprintf(stderr, "usage: oracle REF.pfm R_AUTO PASSES REGIONS.txt NF F.. NS IMG.. APPM..\n");
        return 1;
    }
    if (!readimg(argv[a++], &ref, 0, 0)) return 2;
    w = ref.width;
    h = ref.height;
    rauto = atof(argv[a++]);
    passes = strtoul(argv[a++], NULL, 10);
    fr = fopen(argv[a++], "r");
    if (!fr) return 2;
    while (nreg < MAXR && fscanf(fr, "%63s %u %u %u %u", rname[nreg], &rx0[nreg], &ry0[nreg], &rx1[nreg],
                                 &ry1[nreg]) == 5)
        nreg++;
    fclose(fr);
    nf = atoi(argv[a++]);
    if (nf < 3 || nf > MAXF || a + nf >= argc) return 1;
    for (k = 0; k < nf; ++k) F[k] = atof(argv[a++]);
    ns = atoi(argv[a++]);
    if (ns < 1 || ns > MAXS || argc != a + nf * ns + ns) {
        fprintf(stderr, "oracle: expected %d images and %d prefixes\n", nf * ns, ns);
        return 1;
    }
    for (k = 0; k < nf; ++k)
        for (s = 0; s < ns; ++s)
            if (!readimg(argv[a++], &img[k][s], w, h)) return 2;
    for (s = 0; s < ns; ++s, ++a)
        for (c = 0; c < 3; ++c) {
            char p[4096];
            snprintf(p, sizeof p, "%s-%s.pfm", argv[a], comp[c]);
            if (!readimg(p, &ar[s][c], w, h)) return 2;
        }
    { /* appm's own image of the last seed, PREFIX.pfm */
        char p[4096];
        snprintf(p, sizeof p, "%s.pfm", argv[a - 1]);
        if (!readimg(p, &ai, w, h)) return 2;
    }
    r_hi = 2.0 * rauto * pow((double)passes, -1.0 / 6.0); /* appm's upper bound of the last pass */
    bound_u = KAPPA * r_hi / rauto;
    kbnd = nearest(F, nf, bound_u);
    e = (double *)calloc((size_t)w * h * nf, sizeof *e);
    es = (double *)calloc((size_t)w * h * nf * ns, sizeof *es);
    er = (double *)calloc((size_t)w * h * nf * ns, sizeof *er);
    memset(sets, 0, sizeof sets);
    for (i = 0; i < (unsigned)(nreg + 5); ++i) {
        sets[i].fs = (double *)malloc(sizeof(double) * w * h);
        sets[i].u = (double *)malloc(sizeof(double) * w * h);
        sets[i].uc = (double *)malloc(sizeof(double) * w * h);
        sets[i].ud = (double *)malloc(sizeof(double) * w * h);
        sets[i].dlog = (double *)malloc(sizeof(double) * w * h);
    }
    for (y = 0; y < h; ++y)
        for (x = 0; x < w; ++x)
            for (k = 0; k < nf; ++k) {
                double sum = 0.0;
                int dx, dy;
                for (dy = -1; dy <= 1; ++dy)
                    for (dx = -1; dx <= 1; ++dx) {
                        int xx = (int)x + dx, yy = (int)y + dy;
                        if (xx < 0 || yy < 0 || xx >= (int)w || yy >= (int)h) continue;
                        for (s = 0; s < ns; ++s)
                            for (c = 0; c < 3; ++c) {
                                size_t o = 3 * ((size_t)yy * w + xx) + c;
                                double d = (double)img[k][s].rgb[o] - ref.rgb[o];
                                sum += d * d;
                                es[(((size_t)y * w + x) * nf + k) * ns + s] += d * d;
                                if (!dx && !dy) er[(((size_t)y * w + x) * nf + k) * ns + s] += d * d;
                            }
                    }
                e[((size_t)y * w + x) * nf + k] = sum;
            }
    for (y = 0; y < h; ++y)
        for (x = 0; x < w; ++x) {
            size_t p = (size_t)y * w + x;
            const double *ep = e + p * nf;
            double u[3], fs, ra, ftr = 0.0, fte = 0.0;
            int kb = 0, ktr = 0, inset[4], m;
            if (pix_lum(ref.rgb + 3 * p) >= 1.0) continue;
            for (c = 0; c < 3; ++c) {
                double v[MAXS];
                for (s = 0; s < ns; ++s) v[s] = ar[s][c].rgb[3 * p];
                qsort(v, ns, sizeof *v, pix_dcmp);
                u[c] = KAPPA * v[ns / 2] / rauto;
            }
            if (!(u[0] > 0.0) || u[0] != u[0]) continue;
            fs = argmin(ep, F, nf, &kb);
            if (ns > 1) { /* f* from the first ns-1 seeds, judged on the last */
                double tr[MAXF], te[MAXF];
                int kt, ke;
                for (k = 0; k < nf; ++k) {
                    tr[k] = 0.0;
                    for (s = 0; s < ns - 1; ++s) tr[k] += es[(p * nf + k) * ns + s];
                    te[k] = es[(p * nf + k) * ns + ns - 1];
                }
                ftr = argmin(tr, F, nf, &kt);
                fte = argmin(te, F, nf, &ke);
                ktr = kt;
            }
            inset[0] = -1;
            for (r = 0; r < nreg; ++r)
                if (x >= rx0[r] && x < rx1[r] && y >= ry0[r] && y < ry1[r]) {
                    inset[0] = r;
                    break;
                }
            inset[1] = pix_edge(ref.rgb, w, h, x, y) ? nreg : nreg + 1;
            inset[2] = nreg + 2;
            ra = 0.0;
            for (s = 0; s < ns; ++s) ra += ar[s][0].rgb[3 * p];
            /* at the bound on every seed: the edges and smooth pixels appm holds there */
            inset[3] = ra / ns >= 0.999 * r_hi ? inset[1] + 3 : -1;
            for (m = 0; m < 4; ++m) {
                set *st;
                if (inset[m] < 0) continue;
                st = &sets[inset[m]];
                st->fs[st->n] = fs;
                st->u[st->n] = u[0];
                st->uc[st->n] = u[1];
                st->ud[st->n] = u[2];
                st->n++;
                if (fs > bound_u) st->above_bound++;
                if (fs > u[0]) st->above_u++;
                if (inset[3] >= 0) st->at_bound++;
                st->e_or += ep[kb];
                st->e_u += ep[nearest(F, nf, u[0])];
                st->e_b += ep[kbnd];
                for (k = 0; k < nf; ++k) st->e_f[k] += ep[k];
                if (ns > 1) {
                    const double *tp = er + p * nf * ns + ns - 1;
                    st->dlog[st->nd++] = fabs(log(ftr / fte) / log(2.0));
                    st->t_or += tp[ktr * ns];
                    st->t_u += tp[nearest(F, nf, u[0]) * ns];
                    for (c = 0; c < 3; ++c) {
                        double d = (double)ai.rgb[3 * p + c] - ref.rgb[3 * p + c];
                        st->t_appm += d * d;
                    }
                    for (k = 0; k < nf; ++k) {
                        double tr = 0.0;
                        for (s = 0; s < ns - 1; ++s) tr += er[(p * nf + k) * ns + s];
                        st->tr_f[k] += tr;
                        st->te_f[k] += tp[k * ns];
                    }
                }
            }
        }
    printf("passes=%lu r_auto=%.6g bound_u=%.3g (fixed uniform radius / r_auto; grid point %.3g)\n", passes, rauto,
           bound_u, F[kbnd]);
    for (r = 0; r < nreg; ++r) report(rname[r], &sets[r], nf, F, sets[nreg + 2].t_u);
    report("edges", &sets[nreg], nf, F, sets[nreg + 2].t_u);
    report("smooth", &sets[nreg + 1], nf, F, sets[nreg + 2].t_u);
    report("all", &sets[nreg + 2], nf, F, sets[nreg + 2].t_u);
    report("edges@bound", &sets[nreg + 3], nf, F, sets[nreg + 2].t_u);
    report("smooth@bound", &sets[nreg + 4], nf, F, sets[nreg + 2].t_u);
    return 0;
}
