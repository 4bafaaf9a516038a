/* bench/eqcpu.c - one equal-CPU-time run, for comparisons on a shared machine.
 *
 *   cc -std=c99 -O2 bench/eqcpu.c appm.c -o bench/eqcpu -lm -pthread
 *   bench/eqcpu SCENE METHOD SEED BUDGET RADIUS ALPHA REF_A.pfm REF_B.pfm MASK [REF_MSE [SIZE]]
 *
 * Renders SIZE x SIZE (default 64x64) with 2 threads, pass after pass, until the process has used
 * BUDGET seconds of CPU time (both threads counted): wall time is meaningless
 * when other jobs share the cores.  A negative BUDGET renders -BUDGET passes
 * (equal passes instead of equal time: what a radius costs apart from time).  RADIUS and ALPHA 0 mean the defaults.  The
 * reference is the mean of two independent renders A and B, and its own noise
 * E[(A - B)^2] / 4 is subtracted from the measured MSE (or, with A and B the same
 * file, REF_MSE from its .mse file; REF_MSE 0: from A and B).  "rmse_masked" counts only the pixels whose
 * reference luminance is below MASK (a light seen directly excluded).
 *
 * EQCPU_CURVE=K (with a pass count) also prints a "curve" line after every K-th pass, the error so
 * far and the processor time spent in the passes (the time of these measurements left out): one
 * run gives the error at every budget, which bench/eqcurve.sh compares between methods at equal
 * time.  The passes and their images are the same as without it. */
#include "../appm.h"
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <math.h>
#include <time.h>
static double lum(const float *p) { return 0.2126 * p[0] + 0.7152 * p[1] + 0.0722 * p[2]; }

/* The RMSE of img against the mean of A and B, all pixels and masked, the reference's noise
 * (REF_MSE if > 0, else (A - B)^2 / 4) subtracted; nm: the masked pixels. */
static void errors(const appm_image *img, const appm_image *A, const appm_image *B, double mask, double ref_mse,
                   double *rmse, double *rmse_m, double *nm_out)
{
    double se = 0, sm = 0, na = 0, nm = 0, nse = 0, nsm = 0;
    size_t i, n = (size_t)img->width * img->height;
    for (i = 0; i < n; ++i) {
        float ref[3]; int c; double rl;
        for (c = 0; c < 3; ++c) ref[c] = 0.5f * (A->rgb[3 * i + c] + B->rgb[3 * i + c]);
        rl = lum(ref);
        for (c = 0; c < 3; ++c) {
            double e = img->rgb[3 * i + c] - ref[c], q = A->rgb[3 * i + c] - B->rgb[3 * i + c];
            double q2 = ref_mse > 0 ? ref_mse : q * q / 4; /* the reference's noise */
            se += e * e; nse += q2; na++;
            if (rl < mask) { sm += e * e; nsm += q2; nm++; }
        }
    }
    *rmse = (se - nse) / na > 0 ? sqrt((se - nse) / na) : 0.0;
    *rmse_m = nm > 0 && (sm - nsm) / nm > 0 ? sqrt((sm - nsm) / nm) : 0.0;
    *nm_out = nm / 3;
}

int main(int argc, char **argv)
{
    appm_scene *s; appm_diag d; appm_config cfg; appm_renderer *r; appm_image A, B, img; appm_stats st;
    double budget, mask, ref_mse, rmse, rmse_m, nm, spent = 0.0; /* spent: CPU seconds outside the curve's measurements */
    clock_t c0;
    long curve = getenv("EQCPU_CURVE") ? atol(getenv("EQCPU_CURVE")) : 0;
    if (argc < 10) { fprintf(stderr, "usage: scene method seed budget radius alpha refA refB mask\n"); return 2; }
    if (appm_scene_load(argv[1], NULL, &s, &d) != APPM_OK) { printf("%s\n", d.message); return 1; }
    appm_config_init(&cfg);
    appm_method_parse(argv[2], &cfg.method);
    cfg.seed = (uint64_t)atoll(argv[3]); budget = atof(argv[4]); cfg.radius = atof(argv[5]); cfg.alpha = atof(argv[6]);
    mask = atof(argv[9]);
    ref_mse = argc > 10 ? atof(argv[10]) : 0.0;
    cfg.width = cfg.height = argc > 11 ? (uint32_t)atoi(argv[11]) : 64; cfg.threads = 2;
    if (appm_image_read_pfm(argv[7], NULL, &A, &d) != APPM_OK || appm_image_read_pfm(argv[8], NULL, &B, &d) != APPM_OK) { printf("%s\n", d.message); return 1; }
    if (appm_renderer_create(s, &cfg, &r, &d) != APPM_OK) { printf("%s\n", d.message); return 1; }
    c0 = clock();
    if (budget < 0) /* -BUDGET passes instead: the same comparison at equal passes */
        while (appm_renderer_stats(r, &st), (double)st.passes < -budget) {
            appm_renderer_pass(r);
            if (curve > 0 && (st.passes + 1) % (uint64_t)curve == 0) {
                clock_t c1 = clock();
                spent += (double)(c1 - c0) / CLOCKS_PER_SEC;
                appm_renderer_image(r, &img);
                errors(&img, &A, &B, mask, ref_mse, &rmse, &rmse_m, &nm);
                printf("curve passes=%llu cpu=%.4f rmse=%.6f rmse_masked=%.6f\n", (unsigned long long)st.passes + 1,
                       spent, rmse, rmse_m);
                c0 = clock();
            }
        }
    else
        while ((double)(clock() - c0) / CLOCKS_PER_SEC < budget) appm_renderer_pass(r);
    spent += (double)(clock() - c0) / CLOCKS_PER_SEC;
    appm_renderer_image(r, &img); appm_renderer_stats(r, &st);
    errors(&img, &A, &B, mask, ref_mse, &rmse, &rmse_m, &nm);
    printf("passes=%llu cpu=%.2f wall=%.2f rmse=%.6f rmse_masked=%.6f clamped=%.4f masked_px=%.0f\n",
           (unsigned long long)st.passes, spent, st.seconds, rmse, rmse_m,
#ifdef NO_CLAMPED
           -1.0,
#else
           st.clamped,
#endif
           nm);
    return 0;
}
