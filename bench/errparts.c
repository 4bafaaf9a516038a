/* bench/errparts.c - the error bar's two parts against the truth, over seeds.
 *
 *   cc -std=c99 -O2 bench/errparts.c -o bench/errparts -lm -pthread
 *   bench/errparts SCENE REFERENCE.pfm PASSES [SEEDS [METHOD [REF_NOISE]]]
 *
 * Renders SCENE at 64x64 with METHOD (default appm) for seeds 1..SEEDS
 * (default 12) and splits est_relerr's square (docs/algorithm.md 7.2) into its
 * variance part (the halves' scale times the passes' spread) and its squared-bias
 * part (appm__bias2), each a weighted mean over the pixels with the weights of
 * the relative error.  The truth of each, in the same luminance measure: the
 * spread of the seeds' images (the variance), and the squared difference of
 * their mean from REFERENCE less that spread over SEEDS and less REF_NOISE,
 * the reference's own noise in the same measure (the squared bias), each
 * weighted as relmse weighs it, by the reference (1 / (ref^2 + 0.01)).
 * REF_NOISE (default 0) is bench/ref/NAME.mse's ref_relmse, which refmix
 * counts per channel where this counts luminance: close for a grey light.  It
 * matters where the reference is noisy: the sphere box's reference, whose
 * caustic a path tracer finds by chance, holds 3.3e-4, as much as appm's own
 * squared error at 256 passes (7e-4), and counted as bias it read a bias that
 * is not there.  The
 * references are make bench-errbar's (bench/ref/NAME-64e.pfm).  Also prints the
 * halves' and the quarters' differences of the last power of two of passes, as
 * docs/algorithm.md 7.3 uses them. */
#include "../appm.c"

#define EP_W 64
#define EP_N (EP_W * EP_W)
#define EP_MAXSEEDS 32

static double lum(const float *c) { return 0.2126 * c[0] + 0.7152 * c[1] + 0.0722 * c[2]; }

int main(int argc, char **argv)
{
    static double L[EP_MAXSEEDS][EP_N], W[EP_MAXSEEDS][EP_N], B2[EP_MAXSEEDS][EP_N], V[EP_MAXSEEDS][EP_N];
    static double Q[EP_MAXSEEDS][4][EP_N]; /* luminance summed to the end of each quarter of P */
    appm_config cfg;
    appm_scene *s = NULL;
    appm_image ref;
    appm_diag d;
    int passes, seeds, k, q;
    uint64_t P = 1;
    size_t i;
    double est_b = 0, est_v = 0, true_v = 0, true_b = 0, halves = 0, quarters = 0;
    if (argc < 4) {
        fprintf(stderr, "usage: %s SCENE REFERENCE.pfm PASSES [SEEDS [METHOD [REF_NOISE]]]\n", argv[0]);
        return 2;
    }
    passes = atoi(argv[3]);
    seeds = argc > 4 ? atoi(argv[4]) : 12;
    if (passes < 4 || seeds < 2 || seeds > EP_MAXSEEDS) {
        fprintf(stderr, "errparts: PASSES >= 4, SEEDS in 2..%d\n", EP_MAXSEEDS);
        return 2;
    }
    while (P * 2 <= (uint64_t)passes) P *= 2;
    appm_config_init(&cfg);
    if (appm_scene_load(argv[1], &cfg, &s, &d) != APPM_OK || appm_image_read(argv[2], &cfg, &ref, &d) != APPM_OK) {
        fprintf(stderr, "errparts: %s\n", d.message);
        return 1;
    }
    if (ref.width != EP_W || ref.height != EP_W) {
        fprintf(stderr, "errparts: the reference must be %dx%d\n", EP_W, EP_W);
        return 1;
    }
    for (k = 0; k < seeds; ++k) {
        appm_renderer *r;
        appm_image img;
        int p;
        cfg.width = cfg.height = EP_W;
        cfg.seed = (uint64_t)k + 1;
        cfg.method = APPM_METHOD_APPM;
        if (argc > 5 && appm_method_parse(argv[5], &cfg.method) != APPM_OK) {
            fprintf(stderr, "errparts: unknown method %s\n", argv[5]);
            return 2;
        }
        if (appm_renderer_create(s, &cfg, &r, &d) != APPM_OK) {
            fprintf(stderr, "errparts: %s\n", d.message);
            return 1;
        }
        for (p = 1; p <= passes; ++p) {
            appm_renderer_pass(r);
            if ((uint64_t)p <= P && p % (int)(P / 4) == 0)
                for (i = 0; i < EP_N; ++i) Q[k][p / (P / 4) - 1][i] = r->pix[i].wmean * p;
        }
        appm_renderer_image(r, &img);
        appm__error_update(r); /* the estimate's parts: err_lum, err_b2, var_scale */
        for (i = 0; i < EP_N; ++i) {
            L[k][i] = lum(img.rgb + 3 * i);
            W[k][i] = appm__err_weight(r, i);
            B2[k][i] = appm__bias2(r, i);
            V[k][i] = r->var_scale * appm__mean_var(&r->pix[i], NULL, 1, r->pass);
        }
        printf("seed %d: est_relerr %.5f, halves' scale %.3f, of the bias's noise %.3f\n", k + 1, r->stats.est_relerr, r->var_scale, r->noise_scale);
        appm_renderer_destroy(r);
    }
    for (i = 0; i < EP_N; ++i) {
        double m = 0, v = 0, w, Lr = lum(ref.rgb + 3 * i);
        for (k = 0; k < seeds; ++k) {
            double qv[4], h1, h2;
            m += L[k][i];
            est_b += W[k][i] * B2[k][i];
            est_v += W[k][i] * V[k][i];
            for (q = 0; q < 4; ++q) qv[q] = (Q[k][q][i] - (q ? Q[k][q - 1][i] : 0.0)) / (double)(P / 4);
            h1 = 0.5 * (qv[0] + qv[1]);
            h2 = 0.5 * (qv[2] + qv[3]);
            halves += W[k][i] * 0.25 * (h1 - h2) * (h1 - h2) * (double)P / passes;
            quarters += W[k][i] * 0.125 * ((qv[0] - qv[1]) * (qv[0] - qv[1]) + (qv[2] - qv[3]) * (qv[2] - qv[3]));
        }
        m /= seeds;
        /* the truth's weight is relmse's, from the reference: the renders' own
         * (appm__err_weight) differ most where a rare path decides a pixel (the
         * light seen in the water of water-caustic), where they gave the seeds'
         * spread of a pixel that one seed met the weight 1 / 0.01 */
        w = 1.0 / (Lr * Lr + 0.01);
        for (k = 0; k < seeds; ++k) v += (L[k][i] - m) * (L[k][i] - m);
        v /= seeds - 1;
        true_v += w * v;
        true_b += w * ((m - Lr) * (m - Lr) - v / seeds);
    }
    est_b /= (double)seeds * EP_N;
    est_v /= (double)seeds * EP_N;
    halves /= (double)seeds * EP_N;
    quarters /= (double)seeds * EP_N;
    true_v /= EP_N;
    true_b /= EP_N;
    if (argc > 6) true_b -= atof(argv[6]);
    printf("%s, %d passes, %d seeds; the reference's own noise %s\n", argv[1], passes, seeds,
           argc > 6 ? argv[6] : "0 (not given)");
    printf("variance:     estimated %.4g, true %.4g, ratio %.3f\n", est_v, true_v, est_v / true_v);
    printf("squared bias: estimated %.4g, true %.4g, ratio %.3f\n", est_b, true_b, est_b / true_b);
    printf("error:        estimated %.4f, true %.4f, ratio %.3f\n", sqrt(est_b + est_v), sqrt(true_b + true_v),
           sqrt((est_b + est_v) / (true_b + true_v)));
    printf("P = %u: halves (H1 - H2)^2 / 4 %.4g; 2 halves / quarters %.3f (1: independent)\n", (unsigned)P, halves,
           2.0 * halves * passes / (double)P / quarters);
    appm_image_free(&cfg, &ref);
    appm_scene_destroy(s);
    return 0;
}
