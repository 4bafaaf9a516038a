/* bench/lapdiag.c - is appm's Laplacian too small at the edges, or S too large?
 * (docs/algorithm.md 4.18, step 1.)
 *
 *   lapdiag SCENE REF.pfm PASSES SEED
 *
 * Renders appm (64x64, 1 thread; the build of bench/lapdiag.sh) for PASSES passes and, per pixel, compares
 * three Laplacians of the photon term (luminance, scene units, both components
 * summed):
 *   dI_h    appm's own: the weighted running mean of the 5-point differences at
 *           h (what --aux writes as PREFIX-laplacian.pfm), and sqrt of the
 *           pooled, noise-corrected dI^2 the radius uses (dI2p, summed);
 *   dI_ref  the least-squares quadratic of 10.5 fitted to the REFERENCE's photon
 *           term, REF minus appm's own mean direct term, over the same 5x5
 *           neighbours (same surface, their mean visible points): the pixel-scale
 *           Laplacian of the converged image;
 *   dI_img  the same fit to appm's running photon term (10.5, before its noise
 *           correction).
 * and S against the pixel's measured variance: the model's photon variance
 * R(K) S / (M j R^2) per component (R^2 the mean over passes), summed, over the
 * variance of the pixel's mean (appm__mean_var: direct light included, so >= the
 * photon part).  Regions as bench/oracle.c: "edges" where the reference
 * luminance over 3x3 varies by more than half its mean, "smooth" the rest,
 * the light seen directly (luminance >= 1) left out.  Printed: medians (and
 * quartiles) of |dI_ref| / |dI_h|, |dI_img| / |dI_h|, |dI_ref| / sqrt(dI2p),
 * and of the variance ratio. */
#include "appm.c" /* appm.c with bench/imglap.patch applied: built by bench/lapdiag.sh */
#include <stdio.h>
#include "pixstat.h"


#define NSTAT 4
static const char *const stat_name[NSTAT] = {"|dI_ref|/|dI_h|", "|dI_img|/|dI_h|", "|dI_ref|/sqrt(dI2p)",
                                             "Var_model(S)/Var_meas"};

int main(int argc, char **argv)
{
    appm_scene *s = NULL;
    appm_config cfg;
    appm_renderer *r = NULL;
    appm_diag d;
    appm_image ref;
    unsigned long passes, j;
    size_t i, n, npix, cnt[2] = {0, 0};
    double *st[2][NSTAT], *dref;
    int reg, k;
    if (argc < 5) {
        fprintf(stderr, "usage: lapdiag SCENE REF.pfm PASSES SEED\n");
        return 1;
    }
    if (appm_scene_load(argv[1], NULL, &s, &d) != APPM_OK || appm_image_read_pfm(argv[2], NULL, &ref, &d)) {
        fprintf(stderr, "lapdiag: %s\n", d.message);
        return 2;
    }
    passes = strtoul(argv[3], NULL, 10);
    appm_config_init(&cfg);
    cfg.width = ref.width;
    cfg.height = ref.height;
    cfg.threads = 1;
    cfg.seed = strtoull(argv[4], NULL, 10);
    if (appm_renderer_create(s, &cfg, &r, &d) != APPM_OK) return 2;
    for (j = 0; j < passes; ++j) appm_renderer_pass(r);
    npix = (size_t)r->w * r->h;
    dref = (double *)calloc(npix, sizeof *dref);
    for (reg = 0; reg < 2; ++reg)
        for (k = 0; k < NSTAT; ++k) st[reg][k] = (double *)malloc(npix * sizeof(double));
    /* the reference's photon term into the state's I (component 0; component 1
     * zero), so that appm__img_lap fits it; the running terms kept aside */
    {
        double *keep = (double *)malloc(npix * 6 * sizeof(double)), *dimg = (double *)malloc(npix * sizeof(double));
        int *ok = (int *)malloc(npix * sizeof(int)), *okr = (int *)malloc(npix * sizeof(int));
        for (i = 0; i < npix; ++i) {
            double t[2], v;
            ok[i] = r->vp[i].segs > 0 && appm__img_lap(r, i, t, &v);
            dimg[i] = ok[i] ? t[0] + t[1] : 0.0;
        }
        for (i = 0; i < npix; ++i) {
            appm__appm_px *a = (appm__appm_px *)appm__state(r, i);
            int c;
            for (c = 0; c < 3; ++c) {
                keep[6 * i + c] = a->k[0].I[c];
                keep[6 * i + 3 + c] = a->k[1].I[c];
                a->k[0].I[c] = ref.rgb[3 * i + c] - r->pix[i].ld[c] / (double)passes;
                a->k[1].I[c] = 0.0;
            }
        }
        for (i = 0; i < npix; ++i) {
            double t[2], v;
            okr[i] = r->vp[i].segs > 0 && appm__img_lap(r, i, t, &v);
            dref[i] = okr[i] ? t[0] : 0.0;
        }
        for (i = 0; i < npix; ++i) {
            appm__appm_px *a = (appm__appm_px *)appm__state(r, i);
            int c;
            for (c = 0; c < 3; ++c) {
                a->k[0].I[c] = keep[6 * i + c];
                a->k[1].I[c] = keep[6 * i + 3 + c];
            }
        }
        for (i = 0; i < npix; ++i) {
            const appm__appm_px *a = (const appm__appm_px *)appm__state(r, i);
            double dh, dp, vm = 0.0, vmeas;
            int c;
            if (!ok[i] || !okr[i] || pix_lum(ref.rgb + 3 * i) >= 1.0) continue;
            reg = pix_edge(ref.rgb, r->w, r->h, (unsigned)(i % r->w), (unsigned)(i / r->w)) ? 0 : 1;
            dh = fabs(a->k[0].dI + a->k[1].dI);
            dp = sqrt((a->k[0].dI2p > 0 ? a->k[0].dI2p : 0.0) + (a->k[1].dI2p > 0 ? a->k[1].dI2p : 0.0));
            for (c = 0; c < APPM__NCOMP; ++c) {
                double R2 = a->k[c].R2sum / (double)passes;
                if (R2 > 0.0) vm += APPM__RK * a->k[c].S / ((double)r->M * (double)passes * R2);
            }
            vmeas = appm__mean_var(&r->pix[i], appm__chain_sums(r, i), r->chains, r->pass);
            if (!(dh > 0.0) || !(dp > 0.0) || !(vmeas > 0.0)) continue;
            n = cnt[reg]++;
            st[reg][0][n] = fabs(dref[i]) / dh;
            st[reg][1][n] = fabs(dimg[i]) / dh;
            st[reg][2][n] = fabs(dref[i]) / dp;
            st[reg][3][n] = vm / vmeas;
        }
        free(keep), free(dimg), free(ok), free(okr);
    }
    printf("%s passes=%lu seed=%s r_auto=%.4g\n", argv[1], passes, argv[4], r->r_auto);
    for (reg = 0; reg < 2; ++reg) {
        printf("  %-6s n=%4lu", reg ? "smooth" : "edges", (unsigned long)cnt[reg]);
        for (k = 0; k < NSTAT; ++k)
            printf("  %s %.3g [%.3g %.3g]", stat_name[k], pix_quant(st[reg][k], cnt[reg], 0.5), pix_quant(st[reg][k], cnt[reg], 0.25),
                   pix_quant(st[reg][k], cnt[reg], 0.75));
        printf("\n");
    }
    appm_renderer_destroy(r);
    appm_scene_destroy(s);
    return 0;
}
