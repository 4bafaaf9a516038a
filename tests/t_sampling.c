/* tests/t_sampling.c - sampling, BSDFs, Fresnel and light choice (appm.c section 6).
 *
 *   1. Pearson chi-square goodness of fit (testing.md S1, S8): cosine-weighted
 *      hemisphere, uniform sphere, uniform triangle, light choice by power.
 *      Expected cell counts come from the exact integral of the pdf over each
 *      cell; cells expecting fewer than 5 samples are pooled; the p-value is the
 *      regularised upper incomplete gamma function Q(dof/2, X^2/2), implemented
 *      here; every test must reach p > 1 - (1 - 0.01)^(1/K) (Sidak correction
 *      for K tests, so the whole file fails by chance with probability 1%).  A
 *      sample in a cell of zero probability fails at once.
 *   2. Smooth dielectric (S3, S4): Fresnel values; the reflect/refract choice
 *      is a Bernoulli(F) trial, so the reflected count k of n samples must
 *      satisfy |k - nF| < 4 sqrt(nF(1-F)); Snell's law; the eta^2 factor of
 *      radiance transport and its absence for importance (photons).
 *   3. Sampled weights f cos / pdf: diffuse and mirror give exactly their
 *      albedo, glass exactly 1 for photons (S5).
 *   4. Photon emission (A8, S8, S9): the light pick frequencies, the CDF's ends,
 *      zero-variance emission weights, and power conservation.
 *   5. Glossy (Lambert + normalised modified Phong): chi-square of the lobe
 *      sampler at several Ns and of the whole BSDF sampler at several angles,
 *      the albedo against numerical integration, reciprocity, energy <= 1 for
 *      every wo, the lobe's pdf and f against closed forms, and large Ns
 *      approaching the mirror.
 *   The chi-square tests of section 1 run twice: with the PCG stream, and with
 *   the numbers of the low-discrepancy sampler (appm.c section 2.3; its own
 *   tests are in t_sampler.c), which must map to the same distributions.  A
 *   stratified sequence fits a distribution better than chance, so its X^2 is
 *   small and p close to 1: a wrong mapping still shows as p = 0.
 */
#include "../appm.c"
#define CHECK_GAMMA_Q
#include "check.h"

#define GROUP "sampling"
#define NTESTS_CHI2 19 /* chi-square tests in this file, for the Sidak correction */
#define DEG (APPM__PI / 180.0)

static appm__rng g_rng;

/* The source of sample_uf(): the PCG stream, or (g_qmc) coordinates 0, 1 of successive
 * points of one sequence of the sampler (group 3: a vertex's BSDF numbers), two
 * calls a point - every sampler tested with it takes two numbers. */
static int g_qmc;
static uint64_t g_qmc_calls;
static appm__sobol_tab g_tab;

static float sample_uf(void)
{
    float u[4];
    uint64_t c = g_qmc_calls++;
    if (!g_qmc) return appm__rng_float(&g_rng);
    appm__ld(&g_tab, 0x5EED5EEDull, appm__reverse32((uint32_t)(c / 2)), 3, 3u, u);
    return u[c % 2];
}

/* ---- Chi-square machinery --------------------------------------------------- */

static double chi2_sf(double x, double dof) { return gamma_q(0.5 * dof, 0.5 * x); }

static double sidak_alpha(void) { return 1.0 - pow(1.0 - 0.01, 1.0 / NTESTS_CHI2); }

static int cmp_by_expected(const void *a, const void *b)
{
    const double *x = (const double *)a, *y = (const double *)b;
    return (x[1] > y[1]) - (x[1] < y[1]);
}

/* Pearson's test of observed against expected counts over n cells.  Cells are
 * sorted by expected count and the smallest merged until each pool expects at
 * least 5 (the chi-square approximation needs that).  Prints and checks. */
static void chi2_check(const char *name, const double *obs, const double *expct, int n)
{
    double *c = (double *)malloc(2 * sizeof(double) * (size_t)n), stat = 0.0, po = 0.0, pe = 0.0, p, total_o = 0,
           total_e = 0;
    int i, cells = 0, zero_bad = 0;
    if (!c) abort();
    for (i = 0; i < n; ++i) {
        c[2 * i] = obs[i];
        c[2 * i + 1] = expct[i];
        total_o += obs[i];
        total_e += expct[i];
        if (expct[i] <= 0.0 && obs[i] > 0.0) zero_bad++;
    }
    qsort(c, (size_t)n, 2 * sizeof(double), cmp_by_expected);
    for (i = 0; i < n; ++i) {
        if (c[2 * i + 1] <= 0.0) continue; /* cells that cannot be hit (checked above) */
        po += c[2 * i];
        pe += c[2 * i + 1];
        if (pe >= 5.0 || i == n - 1) {
            stat += (po - pe) * (po - pe) / pe;
            cells++;
            po = pe = 0.0;
        }
    }
    if (pe > 0.0) { /* a last small pool: fold it into the statistic as one cell */
        stat += (po - pe) * (po - pe) / pe;
        cells++;
    }
    p = cells > 1 ? chi2_sf(stat, cells - 1) : 0.0;
    printf("  %-28s X^2 = %9.2f  dof = %4d  p = %.4f\n", name, stat, cells - 1, p);
    CHECK_MSG(zero_bad == 0, "%s: %d cells of probability 0 got samples", name, zero_bad);
    CHECK_MSG(fabs(total_e - total_o) <= 1e-6 * total_o, "%s: expected counts sum to %.9g, not %.9g", name, total_e,
              total_o);
    CHECK_MSG(cells > 10, "%s: only %d cells", name, cells);
    CHECK_MSG(p > sidak_alpha(), "%s: p = %.3g below the Sidak level %.3g", name, p, sidak_alpha());
    free(c);
}

static void test_gamma_q(void)
{
    /* closed forms: dof 2: exp(-x/2); dof 4: exp(-y)(1 + y); dof 1: erfc(sqrt(y));
     * dof 3: erfc(sqrt(y)) + 2 sqrt(y/pi) exp(-y), with y = x/2; and the
     * tabulated 95% point of 100 degrees of freedom, 124.342 */
    double x;
    for (x = 0.1; x < 60.0; x *= 1.7) {
        double y = 0.5 * x;
        CHECK_NEAR(chi2_sf(x, 2), exp(-y), 1e-12);
        CHECK_NEAR(chi2_sf(x, 4), exp(-y) * (1 + y), 1e-12);
        CHECK_NEAR(chi2_sf(x, 1), erfc(sqrt(y)), 1e-12);
        CHECK_NEAR(chi2_sf(x, 3), erfc(sqrt(y)) + 2 * sqrt(y / APPM__PI) * exp(-y), 1e-12);
    }
    CHECK_NEAR(chi2_sf(124.342, 100), 0.05, 1e-4);
    CHECK_NEAR(chi2_sf(3.841458820694124, 1), 0.05, 1e-9);
}

/* ---- 1. Sample distributions ---------------------------------------------------- */

#define NT 11 /* cos(theta) or z bins: odd, so no bin edge sits at a symmetric value */
#define NP 21 /* phi bins */

/* Any orthonormal frame around n, in double (the tests must not reuse the
 * library's appm__basis to read back the library's samples). */
static void frame(const double n[3], double t[3], double b[3])
{
    double a[3] = {1, 0, 0}, l;
    if (fabs(n[0]) > 0.9) a[0] = 0, a[1] = 1;
    t[0] = a[1] * n[2] - a[2] * n[1];
    t[1] = a[2] * n[0] - a[0] * n[2];
    t[2] = a[0] * n[1] - a[1] * n[0];
    l = sqrt(t[0] * t[0] + t[1] * t[1] + t[2] * t[2]);
    t[0] /= l, t[1] /= l, t[2] /= l;
    b[0] = n[1] * t[2] - n[2] * t[1];
    b[1] = n[2] * t[0] - n[0] * t[2];
    b[2] = n[0] * t[1] - n[1] * t[0];
}

static int bin_of(double v, double lo, double hi, int n)
{
    int k = (int)floor((v - lo) / (hi - lo) * n);
    return k < 0 ? 0 : (k >= n ? n - 1 : k);
}

/* Cosine-weighted directions around n: pdf cos(theta)/pi per steradian, so a
 * cell [c0,c1] x [phi0,phi1] has probability (c1^2 - c0^2)(phi1 - phi0)/(2 pi). */
static void test_cosine(appm__v3 n, long N, const char *name)
{
    double obs[NT * NP], ex[NT * NP], nd[3] = {n.x, n.y, n.z}, t[3], b[3];
    long i, below = 0, badlen = 0;
    int a, c;
    frame(nd, t, b);
    memset(obs, 0, sizeof obs);
    for (i = 0; i < N; ++i) {
        appm__v3 w = appm__cosine_dir(n, sample_uf(), sample_uf());
        double x = w.x * t[0] + w.y * t[1] + w.z * t[2], y = w.x * b[0] + w.y * b[1] + w.z * b[2];
        double z = w.x * nd[0] + w.y * nd[1] + w.z * nd[2], phi = atan2(y, x);
        if (fabs(x * x + y * y + z * z - 1.0) > 1e-5) badlen++;
        if (z < 0) { /* the lower hemisphere has probability 0 */
            below++;
            continue;
        }
        obs[bin_of(z, 0, 1, NT) * NP + bin_of(phi, -APPM__PI, APPM__PI, NP)] += 1;
    }
    for (c = 0; c < NT; ++c)
        for (a = 0; a < NP; ++a) {
            double c0 = (double)c / NT, c1 = (double)(c + 1) / NT;
            ex[c * NP + a] = (double)N * (c1 * c1 - c0 * c0) / NP;
        }
    CHECK_MSG(below == 0, "%s: %ld samples below the surface", name, below);
    CHECK_MSG(badlen == 0, "%s: %ld samples not of unit length", name, badlen);
    chi2_check(name, obs, ex, NT * NP);
}

/* Uniform on the sphere: every (z, phi) cell of the grid has equal area. */
static void test_sphere(long N)
{
    double obs[NT * NP], ex[NT * NP];
    long i, badlen = 0;
    int k;
    memset(obs, 0, sizeof obs);
    for (i = 0; i < N; ++i) {
        appm__v3 w = appm__uniform_sphere(sample_uf(), sample_uf());
        double phi = atan2((double)w.y, (double)w.x);
        if (fabs((double)w.x * w.x + (double)w.y * w.y + (double)w.z * w.z - 1.0) > 1e-5) badlen++;
        obs[bin_of(w.z, -1, 1, NT) * NP + bin_of(phi, -APPM__PI, APPM__PI, NP)] += 1;
    }
    for (k = 0; k < NT * NP; ++k) ex[k] = (double)N / (NT * NP);
    CHECK_MSG(badlen == 0, "uniform sphere: %ld samples not of unit length", badlen);
    chi2_check("uniform sphere (z, phi)", obs, ex, NT * NP);
}

/* Uniform in area on a triangle: the barycentrics (b1, b2) are then uniform on
 * the simplex b1, b2 >= 0, b1 + b2 <= 1, for any triangle (area is affine).  On
 * a 20 x 20 grid the diagonal runs through grid corners: cells below it have
 * area h^2, the cells it cuts h^2 / 2, those above 0. */
#define NB 20
static void test_triangle(long N)
{
    double obs[NB * NB], ex[NB * NB];
    appm__tri t;
    long i, outside = 0, badpoint = 0;
    int a, c;
    t.p0 = appm__v(0.3f, -1.2f, 2.0f);
    t.p1 = appm__v(4.1f, 0.7f, -0.5f);
    t.p2 = appm__v(-1.0f, 2.5f, 1.5f);
    memset(obs, 0, sizeof obs);
    for (i = 0; i < N; ++i) {
        float b1, b2;
        appm__v3 p = appm__tri_point(&t, sample_uf(), sample_uf(), &b1, &b2);
        /* the point is the one the barycentrics name: p0 + b1 e1 + b2 e2 */
        double q[3], e = 0;
        int k;
        for (k = 0; k < 3; ++k) {
            double p0 = appm__comp(t.p0, k), p1 = appm__comp(t.p1, k), p2 = appm__comp(t.p2, k);
            q[k] = p0 + b1 * (p1 - p0) + b2 * (p2 - p0);
            e = fmax(e, fabs(q[k] - appm__comp(p, k)));
        }
        if (e > 1e-5) badpoint++;
        if (b1 < 0 || b2 < 0 || (double)b1 + b2 > 1.0 + 1e-7) {
            outside++;
            continue;
        }
        obs[bin_of(b1, 0, 1, NB) * NB + bin_of(b2, 0, 1, NB)] += 1;
    }
    for (a = 0; a < NB; ++a)
        for (c = 0; c < NB; ++c)
            ex[a * NB + c] = (double)N * 2.0 / (NB * NB) * (a + c < NB - 1 ? 1.0 : (a + c == NB - 1 ? 0.5 : 0.0));
    CHECK_MSG(outside == 0, "triangle: %ld barycentrics outside the simplex", outside);
    CHECK_MSG(badpoint == 0, "triangle: %ld points do not match their barycentrics", badpoint);
    chi2_check("triangle (b1, b2)", obs, ex, NB * NB);
}

/* ---- 2. Dielectric -------------------------------------------------------------- */

/* Unpolarised Fresnel reflectance in double: cos_i on the incident side,
 * eta = n_t / n_i. */
static double fresnel_ref(double ci, double eta)
{
    double s2 = (1.0 - ci * ci) / (eta * eta), ct, rs, rp;
    if (s2 >= 1.0) return 1.0;
    ct = sqrt(1.0 - s2);
    rs = (ci - eta * ct) / (ci + eta * ct);
    rp = (eta * ci - ct) / (eta * ci + ct);
    return 0.5 * (rs * rs + rp * rp);
}

static float fresnel_deg(double deg, double eta) { return appm__fresnel((float)cos(deg * DEG), (float)eta); }

static void test_fresnel(void)
{
    static const float cs[] = {1.0f, 1e-3f, 1e-7f, 0.0f, -0.0f, 0.5f};
    static const float etas[] = {1.5f, 1.0f / 1.5f, 1.0f, 2.4f, 1.0f / 2.4f};
    double a;
    size_t i, j;
    /* testing.md S4 (Mitsuba's test_fresnel and test_dielectric) */
    CHECK_NEAR(fresnel_deg(0, 1.5), 0.04, 1e-5);
    CHECK_NEAR(fresnel_deg(30, 1.5), 0.041523, 1e-5);
    CHECK_NEAR(fresnel_deg(45, 1.5), 0.050240, 1e-5);
    CHECK_NEAR(fresnel_deg(45, 1.5), 0.5 * (0.0920134 * 0.0920134 + 0.3033370 * 0.3033370), 1e-5);
    CHECK_NEAR(fresnel_deg(60, 1.5), 0.089187, 1e-5);
    CHECK_NEAR(fresnel_deg(80, 1.5), 0.387704355, 1e-5);
    CHECK_NEAR(fresnel_deg(89.9, 1.5), 0.989912, 1e-5);
    CHECK_NEAR(fresnel_deg(10, 1 / 1.5), 0.040083, 1e-5);
    /* total internal reflection beyond asin(1/1.5) = 41.8103 degrees */
    CHECK(fresnel_deg(41.80, 1 / 1.5) < 1.0f);
    CHECK(fresnel_deg(41.82, 1 / 1.5) == 1.0f);
    CHECK(fresnel_deg(60, 1 / 1.5) == 1.0f);
    CHECK(fresnel_deg(89.9, 1 / 1.5) == 1.0f);
    /* the whole curve, both directions, against the double formula */
    for (a = 0.0; a <= 90.0; a += 0.25) {
        CHECK_NEAR(fresnel_deg(a, 1.5), fresnel_ref(cos(a * DEG), 1.5), 1e-5);
        if (fabs(a - 41.8103) > 0.01) CHECK_NEAR(fresnel_deg(a, 1 / 1.5), fresnel_ref(cos(a * DEG), 1 / 1.5), 1e-5);
    }
    /* extremes: F in [0, 1] and finite; eta = 1 reflects nothing */
    for (i = 0; i < sizeof cs / sizeof cs[0]; ++i)
        for (j = 0; j < sizeof etas / sizeof etas[0]; ++j) {
            float F = appm__fresnel(cs[i], etas[j]);
            CHECK_MSG(F >= 0.0f && F <= 1.0f, "F(cos %g, eta %g) = %g", cs[i], etas[j], F);
        }
    CHECK(appm__fresnel(1.0f, 1.0f) == 0.0f);
    CHECK_NEAR(appm__fresnel(0.5f, 1.0f), 0.0, 1e-7);
}

static appm__surf flat_surf(void)
{
    appm__surf sf;
    memset(&sf, 0, sizeof sf);
    sf.ng = sf.ns = appm__v(0, 0, 1);
    return sf;
}

/* Samples the dielectric at incidence theta from outside (side > 0: wo in the
 * air, above the counter-clockwise face) or inside (in the glass). */
static void dielectric_case(double theta, int outside, long n)
{
    appm__material m;
    appm__surf sf = flat_surf();
    double st = sin(theta * DEG), ct = cos(theta * DEG);
    appm__v3 wo = appm__v((float)st, 0.0f, (float)(outside ? ct : -ct));
    double eta_o = outside ? 1.0 : 1.5, eta_t = outside ? 1.5 : 1.0; /* wo's side, the other side */
    double F = fresnel_ref(fabs((double)wo.z), eta_t / eta_o), z, rw = (eta_o / eta_t) * (eta_o / eta_t);
    double snell = 0, plane = 0, refl_dir = 0, theta_t = -1;
    long i, k = 0, rejected = 0, bad_w_rad = 0, bad_w_imp = 0, not_delta = 0;
    memset(&m, 0, sizeof m);
    m.kind = APPM__MAT_DIELECTRIC;
    m.ior = 1.5f;
    for (i = 0; i < n; ++i) {
        float u1 = sample_uf(), u2 = sample_uf(), u3 = sample_uf();
        appm__bsdf_sample bs, bi;
        int ok = appm__bsdf_sample_dir(&m, &sf, wo, u1, u2, u3, APPM__RADIANCE, &bs);
        int ok2 = appm__bsdf_sample_dir(&m, &sf, wo, u1, u2, u3, APPM__IMPORTANCE, &bi);
        if (!ok || !ok2) {
            rejected++;
            continue;
        }
        if (!bs.specular || bs.pdf != 0.0f) not_delta++;
        if ((bs.wi.z > 0) == (wo.z > 0)) { /* reflected: the mirror image of wo */
            k++;
            refl_dir = fmax(refl_dir, fabs(bs.wi.x + wo.x) + fabs(bs.wi.y + wo.y) + fabs(bs.wi.z - wo.z));
            if (bs.weight.x != 1.0f || bs.weight.y != 1.0f || bs.weight.z != 1.0f) bad_w_rad++;
            if (bi.weight.x != 1.0f || bi.weight.y != 1.0f || bi.weight.z != 1.0f) bad_w_imp++;
        } else { /* refracted: Snell n_o sin(theta_o) = n_t sin(theta_t), in the plane of incidence */
            double sin_t = sqrt((double)bs.wi.x * bs.wi.x + (double)bs.wi.y * bs.wi.y);
            snell = fmax(snell, fabs(eta_o * st - eta_t * sin_t));
            plane = fmax(plane, fabs(bs.wi.y) + (bs.wi.x * wo.x > 0 ? 1.0 : 0.0));
            theta_t = asin(sin_t) / DEG;
            /* radiance: (eta_o / eta_t)^2, what radiance / n^2 invariance gives;
             * importance (photons): no factor */
            if (fabs(bs.weight.x - rw) > 1e-6 * rw || bs.weight.y != bs.weight.x || bs.weight.z != bs.weight.x)
                bad_w_rad++;
            if (bi.weight.x != 1.0f || bi.weight.y != 1.0f || bi.weight.z != 1.0f) bad_w_imp++;
        }
    }
    n -= rejected;
    z = F > 0 && F < 1 ? (k - n * F) / sqrt(n * F * (1 - F)) : (double)(k - (F >= 1 ? n : 0));
    printf("  dielectric %s %4.1f deg: F = %.6f, reflected %.6f, z = %+.2f\n", outside ? "outside" : "inside ",
           theta, F, (double)k / n, z);
    CHECK_MSG(rejected == 0, "theta %g %s: %ld samples rejected", theta, outside ? "out" : "in", rejected);
    if (F >= 1.0) CHECK_MSG(k == n, "theta %g inside: total internal reflection, but %ld of %ld reflected", theta, k, n);
    else CHECK_MSG(fabs(z) < 4.0, "theta %g %s: reflect fraction %.6f, F = %.6f, z = %.2f", theta,
                   outside ? "out" : "in", (double)k / n, F, z);
    CHECK_MSG(not_delta == 0, "theta %g: %ld samples not marked specular with pdf 0", theta, not_delta);
    CHECK_MSG(snell < 1e-5, "theta %g: Snell's law off by %.3g", theta, snell);
    CHECK_MSG(plane < 1e-6, "theta %g: refraction leaves the plane of incidence (%.3g)", theta, plane);
    CHECK_MSG(refl_dir < 1e-6, "theta %g: reflection off the mirror direction by %.3g", theta, refl_dir);
    CHECK_MSG(bad_w_rad == 0, "theta %g: %ld radiance weights wrong", theta, bad_w_rad);
    CHECK_MSG(bad_w_imp == 0, "theta %g: %ld importance weights not 1", theta, bad_w_imp);
    if (outside && theta == 80.0) /* Mitsuba's test_dielectric: theta_t = 41.03641052520335 deg */
        CHECK_NEAR(theta_t, 41.03641052520335, 1e-4);
}

static void test_dielectric(void)
{
    static const double angles[] = {0, 30, 60, 80, 89};
    long n = check_quick() ? 200000 : 1000000;
    size_t i;
    for (i = 0; i < sizeof angles / sizeof angles[0]; ++i) {
        dielectric_case(angles[i], 1, n);
        dielectric_case(angles[i], 0, n);
    }
    { /* Mitsuba's spot values at normal incidence: transmission weight 1/1.5^2
       * for radiance and 1 for importance, chosen with probability 0.96 */
        appm__material m;
        appm__surf sf = flat_surf();
        appm__bsdf_sample bs;
        memset(&m, 0, sizeof m);
        m.kind = APPM__MAT_DIELECTRIC;
        m.ior = 1.5f;
        CHECK(appm__bsdf_sample_dir(&m, &sf, appm__v(0, 0, 1), 0.5f, 0.5f, 0.5f, APPM__RADIANCE, &bs));
        CHECK_NEAR(bs.wi.z, -1.0, 1e-6);
        CHECK_NEAR(bs.weight.y, 1.0 / 2.25, 1e-6);
        CHECK(appm__bsdf_sample_dir(&m, &sf, appm__v(0, 0, 1), 0.5f, 0.5f, 0.5f, APPM__IMPORTANCE, &bs));
        CHECK_NEAR(bs.weight.y, 1.0, 1e-7);
        CHECK(appm__bsdf_sample_dir(&m, &sf, appm__v(0, 0, 1), 0.5f, 0.5f, 0.039f, APPM__RADIANCE, &bs));
        CHECK_NEAR(bs.wi.z, 1.0, 1e-6); /* u3 < F = 0.04: reflected */
        CHECK(appm__bsdf_sample_dir(&m, &sf, appm__v(0, 0, 1), 0.5f, 0.5f, 0.041f, APPM__RADIANCE, &bs));
        CHECK_NEAR(bs.wi.z, -1.0, 1e-6);
    }
}

/* ---- 3. Sampled weights ------------------------------------------------------ */

static void test_weights(void)
{
    long N = check_quick() ? 100000 : 400000, i;
    appm__material dif, mir, gla;
    appm__surf sf = flat_surf();
    double sum_d[3] = {0, 0, 0}, sum_m[3] = {0, 0, 0}, sum_g = 0, sum_gr = 0, exp_gr = 0, var_gr = 0;
    long exact_d = 0, exact_m = 0, exact_g = 0, pdf_bad = 0, dir_bad = 0;
    memset(&dif, 0, sizeof dif);
    memset(&mir, 0, sizeof mir);
    memset(&gla, 0, sizeof gla);
    dif.kind = APPM__MAT_DIFFUSE;
    dif.color = appm__v(0.3f, 0.5f, 0.7f);
    mir.kind = APPM__MAT_MIRROR;
    mir.color = appm__v(0.9f, 0.6f, 0.25f);
    gla.kind = APPM__MAT_DIELECTRIC;
    gla.ior = 1.5f;
    for (i = 0; i < N; ++i) {
        /* wo uniform over the sphere: both sides of the two-sided materials */
        appm__v3 wo = appm__uniform_sphere(sample_uf(), sample_uf());
        appm__bsdf_sample bs;
        float u1 = sample_uf(), u2 = sample_uf(), u3 = sample_uf();
        int mode = (int)(i & 1);
        if (appm__bsdf_sample_dir(&dif, &sf, wo, u1, u2, u3, mode, &bs)) {
            float c = fabsf(bs.wi.z);
            sum_d[0] += bs.weight.x, sum_d[1] += bs.weight.y, sum_d[2] += bs.weight.z;
            exact_d += bs.weight.x == dif.color.x && bs.weight.y == dif.color.y && bs.weight.z == dif.color.z;
            /* pdf = cos / pi on wo's side */
            if (fabs(bs.pdf - c / APPM__PI) > 1e-6 || (bs.wi.z > 0) != (wo.z > 0)) pdf_bad++;
        }
        if (appm__bsdf_sample_dir(&mir, &sf, wo, u1, u2, u3, mode, &bs)) {
            sum_m[0] += bs.weight.x, sum_m[1] += bs.weight.y, sum_m[2] += bs.weight.z;
            exact_m += bs.weight.x == mir.color.x && bs.weight.y == mir.color.y && bs.weight.z == mir.color.z;
            if (fabs(bs.wi.x + wo.x) + fabs(bs.wi.y + wo.y) + fabs(bs.wi.z - wo.z) > 1e-6) dir_bad++;
        }
        if (appm__bsdf_sample_dir(&gla, &sf, wo, u1, u2, u3, APPM__IMPORTANCE, &bs)) {
            sum_g += bs.weight.y;
            exact_g += bs.weight.x == 1.0f && bs.weight.y == 1.0f && bs.weight.z == 1.0f;
        }
        if (appm__bsdf_sample_dir(&gla, &sf, wo, u1, u2, u3, APPM__RADIANCE, &bs)) {
            /* radiance: E[w] = F + (1 - F) s, s = (eta_o / eta_t)^2, a two-point
             * variable with variance F (1 - F) (1 - s)^2 */
            double eo = wo.z > 0 ? 1.0 : 1.5, et = wo.z > 0 ? 1.5 : 1.0, s = (eo / et) * (eo / et);
            double F = fresnel_ref(fabs((double)wo.z), et / eo);
            sum_gr += bs.weight.y;
            exp_gr += F + (1 - F) * s;
            var_gr += F * (1 - F) * (1 - s) * (1 - s);
        }
    }
    /* Each weight is the albedo exactly, so the means are too (rejected
     * samples, rays exactly in the tangent plane, would lower them). */
    CHECK_NEAR(sum_d[0] / N, 0.3, 1e-3);
    CHECK_NEAR(sum_d[1] / N, 0.5, 1e-3);
    CHECK_NEAR(sum_d[2] / N, 0.7, 1e-3);
    CHECK_MSG(exact_d >= N - N / 1000, "diffuse: only %ld of %ld weights equal the albedo", exact_d, N);
    CHECK_MSG(pdf_bad == 0, "diffuse: %ld samples with pdf != cos/pi or on the wrong side", pdf_bad);
    CHECK_NEAR(sum_m[0] / N, 0.9, 1e-3);
    CHECK_NEAR(sum_m[1] / N, 0.6, 1e-3);
    CHECK_NEAR(sum_m[2] / N, 0.25, 1e-3);
    CHECK_MSG(exact_m >= N - N / 1000, "mirror: only %ld of %ld weights equal Ks", exact_m, N);
    CHECK_MSG(dir_bad == 0, "mirror: %ld samples off the mirror direction", dir_bad);
    /* glass for photons: F * 1 + (1 - F) * 1 = 1 */
    CHECK_NEAR(sum_g / N, 1.0, 1e-3);
    CHECK_MSG(exact_g >= N - N / 1000, "glass: only %ld of %ld importance weights are 1", exact_g, N);
    CHECK_MSG(fabs(sum_gr - exp_gr) < 4.0 * sqrt(var_gr), "glass radiance: sum %.6g, expected %.6g +- %.3g", sum_gr,
              exp_gr, sqrt(var_gr));
}

/* ---- 4. Lights -------------------------------------------------------------- */

/* pbrt-v3 spot falloff as docs/scene-format.md defines it, integrated over the cone
 * numerically (Simpson, 2e5 intervals in cos theta), times 2 pi. */
static double spot_solid_angle(double cone_deg, double falloff_deg)
{
    double cc = cos(cone_deg * DEG), ci = cos((cone_deg - falloff_deg) * DEG), sum = 0, h;
    int i, n = 200000;
    h = (1.0 - cc) / n;
    for (i = 0; i <= n; ++i) {
        double c = cc + i * h, d = ci > cc ? (c - cc) / (ci - cc) : 1.0, f;
        d = d < 0 ? 0 : (d > 1 ? 1 : d);
        f = d * d * d * d;
        sum += f * (i == 0 || i == n ? 1 : (i % 2 ? 4 : 2));
    }
    return 2.0 * APPM__PI * sum * h / 3.0;
}

static const char *LIGHT_OBJ = "mtllib sampling-lamp.mtl\n"
                               "v -0.25 1.9 -0.2\nv 0.25 1.9 -0.2\nv 0.25 1.9 0.2\nv -0.25 1.9 0.2\n"
                               "v -2 0 -2\nv 2 0 -2\nv 2 0 2\nv -2 0 2\n"
                               "usemtl lamp\nf 1 2 3\nf 1 3 4\n"
                               "usemtl floor\nf 5 8 7 6\n";
static const char *LAMP_MTL = "newmtl lamp\nKe 4 3 2\nKd 0 0 0\nnewmtl floor\nKd 0.5 0.5 0.5\n";
static const char *LAMP_SCENE = "mesh sampling-lamp.obj\n"
                                 "light point position 0 1 0 intensity 1 2 3\n"
                                 "light point position 1 1 0 intensity 0 0 0\n"
                                 "light spot position 0 1.5 0 target 0 0 0 intensity 10 10 10 cone 30 falloff 10\n"
                                 "light spot position 1 1.5 0 target 1 0 0 intensity 5 4 3 cone 45 falloff 0\n"
                                 "light point position -1 1 0 intensity 0.5 0.5 0.5\n"
                                 "light point position -1 1 1 intensity 0 0 0\n";

#define NL 8 /* 2 area (the lamp quad), then the 6 lights of the scene file, in order */

static void test_lights(void)
{
    appm_scene *s = NULL;
    appm_diag d;
    appm_scene_info info;
    double phi[NL][3], tot[3] = {0, 0, 0}, totm = 0, sr_soft, sr_hard;
    double obs[NL], ex[NL];
    long N = check_quick() ? 200000 : 1000000, i, count[NL], emit_fail = 0, dir_bad = 0;
    double gsum[NL][3], gsum2[NL][3], gmin[NL][3], gmax[NL][3], all[3] = {0, 0, 0}, all2[3] = {0, 0, 0};
    uint32_t k;
    int c;
    CHECK(check_write_file(check_path(GROUP, "lamp.obj"), LIGHT_OBJ));
    CHECK(check_write_file(check_path(GROUP, "lamp.mtl"), LAMP_MTL));
    CHECK(check_write_file(check_path(GROUP, "lights.scene"), LAMP_SCENE));
    CHECK_MSG(appm_scene_load(check_path(GROUP, "lights.scene"), NULL, &s, &d) == APPM_OK, "%s:%u: %s", d.file,
              d.line, d.message);
    if (!s) return;
    CHECK(s->nlight == NL);
    if (s->nlight != NL) {
        appm_scene_destroy(s);
        return;
    }
    /* Closed-form powers: a Lambertian emitter pi Le A (the quad's two halves
     * are 0.1 each); a point light 4 pi I; a spot I times the solid angle its
     * falloff integrates to. */
    sr_soft = spot_solid_angle(30, 10);
    sr_hard = spot_solid_angle(45, 0);
    {
        static const double I[NL][3] = {{4, 3, 2}, {4, 3, 2}, {1, 2, 3}, {0, 0, 0},
                                        {10, 10, 10}, {5, 4, 3}, {0.5, 0.5, 0.5}, {0, 0, 0}};
        const double geo[NL] = {APPM__PI * 0.1, APPM__PI * 0.1, 4 * APPM__PI, 4 * APPM__PI,
                                sr_soft,        sr_hard,        4 * APPM__PI, 4 * APPM__PI};
        for (k = 0; k < NL; ++k)
            for (c = 0; c < 3; ++c) {
                phi[k][c] = I[k][c] * geo[k];
                tot[c] += phi[k][c];
            }
        totm = (tot[0] + tot[1] + tot[2]) / 3.0;
    }
    appm_scene_get_info(s, &info);
    for (c = 0; c < 3; ++c) {
        CHECK_NEAR(info.power_area[c], phi[0][c] + phi[1][c], 1e-5 * tot[c]);
        CHECK_NEAR(info.power_point[c], phi[2][c] + phi[6][c], 1e-5 * tot[c]);
        CHECK_NEAR(info.power_spot[c], phi[4][c] + phi[5][c], 1e-5 * tot[c]);
    }
    /* pick_i = mean power_i / total, and the CDF runs from 0 to 1 */
    for (k = 0; k < NL; ++k) {
        double want = (phi[k][0] + phi[k][1] + phi[k][2]) / 3.0 / totm;
        CHECK_MSG(fabs(s->light[k].pick - want) < 1e-6, "light %u: pick %.9g, power says %.9g", k, s->light[k].pick,
                  want);
        CHECK(s->light_cdf[k + 1] >= s->light_cdf[k]);
    }
    CHECK(s->light_cdf[0] == 0.0 && s->light_cdf[NL] == 1.0);

    /* Frequencies of appm__pick_light against pick (chi-square; the two
     * zero-power lights must never come up). */
    memset(obs, 0, sizeof obs);
    for (i = 0; i < N; ++i) obs[appm__pick_light(s, sample_uf())] += 1;
    for (k = 0; k < NL; ++k) ex[k] = (double)N * s->light[k].pick;
    CHECK(obs[3] == 0 && obs[7] == 0);
    {
        /* too few cells for chi2_check's "more than 10": a plain Pearson test */
        double stat = 0;
        int cells = 0;
        for (k = 0; k < NL; ++k)
            if (ex[k] > 0) {
                stat += (obs[k] - ex[k]) * (obs[k] - ex[k]) / ex[k];
                cells++;
            }
        printf("  %-28s X^2 = %9.2f  dof = %4d  p = %.4f\n", "light pick", stat, cells - 1, chi2_sf(stat, cells - 1));
        CHECK_MSG(chi2_sf(stat, cells - 1) > sidak_alpha(), "light pick: p = %.3g", chi2_sf(stat, cells - 1));
    }
    /* The ends and every boundary of the CDF: u = 0, u = 1 - 2^-24 (the largest
     * appm__rng_float returns) and the floats at and around each cdf[i] all
     * land on a light of non-zero power whose interval holds u. */
    {
        float us[3 * NL + 2];
        int nu = 0, j;
        us[nu++] = 0.0f;
        us[nu++] = 1.0f - 1.0f / 16777216.0f;
        for (k = 0; k < NL; ++k) {
            float f = (float)s->light_cdf[k];
            us[nu++] = f;
            us[nu++] = nextafterf(f, 0.0f);
            us[nu++] = nextafterf(f, 1.0f);
        }
        for (j = 0; j < nu; ++j) {
            uint32_t li;
            if (!(us[j] >= 0.0f && us[j] < 1.0f)) continue;
            li = appm__pick_light(s, us[j]);
            CHECK_MSG(li < NL && s->light[li].pick > 0.0, "u = %.9g picks light %u of power 0", us[j], li);
            if (li < NL)
                CHECK_MSG(s->light_cdf[li] <= us[j] && us[j] < s->light_cdf[li + 1],
                          "u = %.9g picks light %u, interval [%.9g, %.9g)", us[j], li, s->light_cdf[li],
                          s->light_cdf[li + 1]);
        }
    }

    /* Emission.  Every photon of a light carries gamma = Phi / pick, except
     * in a spot's soft rim where gamma follows the falloff; the mean of gamma
     * over all photons is the total power. */
    memset(count, 0, sizeof count);
    memset(gsum, 0, sizeof gsum);
    memset(gsum2, 0, sizeof gsum2);
    for (k = 0; k < NL; ++k)
        for (c = 0; c < 3; ++c) gmin[k][c] = HUGE_VAL, gmax[k][c] = -HUGE_VAL;
    for (i = 0; i < N; ++i) {
        appm__photon_start ps;
        float ue[5];
        uint32_t li;
        double g[3];
        for (c = 0; c < 5; ++c) ue[c] = sample_uf();
        li = appm__pick_light(s, ue[0]); /* the light appm__emit will choose */
        if (!appm__emit(s, ue, &ps)) {
            emit_fail++;
            continue;
        }
        g[0] = ps.gamma.x, g[1] = ps.gamma.y, g[2] = ps.gamma.z;
        count[li]++;
        for (c = 0; c < 3; ++c) {
            gsum[li][c] += g[c];
            gsum2[li][c] += g[c] * g[c];
            gmin[li][c] = fmin(gmin[li][c], g[c]);
            gmax[li][c] = fmax(gmax[li][c], g[c]);
            all[c] += g[c];
            all2[c] += g[c] * g[c];
        }
        /* directions: area lights into the front hemisphere, spots inside the cone */
        if (s->light[li].kind == APPM__LIGHT_AREA) {
            if (!(appm__dot(ps.ray.d, s->info[s->light[li].tri].ng) > 0.0f) || ps.skip != s->light[li].tri) dir_bad++;
        } else if (s->light[li].kind == APPM__LIGHT_SPOT) {
            if (appm__dot(ps.ray.d, s->light[li].axis) < s->light[li].cos_cone - 1e-6f) dir_bad++;
        }
    }
    CHECK_MSG(emit_fail == 0, "%ld emissions failed", emit_fail);
    CHECK_MSG(dir_bad == 0, "%ld photons left in a direction the light does not emit", dir_bad);
    CHECK(count[3] == 0 && count[7] == 0);
    for (k = 0; k < NL; ++k) {
        if (k == 3 || k == 7 || k == 4 || count[k] == 0) continue;
        for (c = 0; c < 3; ++c) {
            double want = phi[k][c] / s->light[k].pick;
            CHECK_MSG(gmax[k][c] - gmin[k][c] <= 1e-6 * gmax[k][c], "light %u: gamma spread [%.9g, %.9g]", k,
                      gmin[k][c], gmax[k][c]);
            CHECK_MSG(fabs(gmax[k][c] - want) <= 1e-5 * want, "light %u: gamma %.9g, Phi / pick = %.9g", k, gmax[k][c],
                      want);
        }
    }
    /* Power: mean gamma against the total, within 3 standard errors, channel by
     * channel; and the soft spot's share alone against its closed form. */
    for (c = 0; c < 3; ++c) {
        double mean = all[c] / N, se = sqrt((all2[c] / N - mean * mean) / N);
        printf("  emitted power channel %d: %.6f +- %.6f, closed form %.6f\n", c, mean, se, tot[c]);
        CHECK_MSG(fabs(mean - tot[c]) < 3.0 * se, "channel %d: power %.6g +- %.3g, want %.6g", c, mean, se, tot[c]);
    }
    {
        double mean = gsum[4][0] / N, se = sqrt((gsum2[4][0] / N - mean * mean) / N);
        printf("  soft spot power: %.6f +- %.6f, closed form %.6f\n", mean, se, phi[4][0]);
        CHECK_MSG(fabs(mean - phi[4][0]) < 3.0 * se, "soft spot: power %.6g +- %.3g, want %.6g", mean, se, phi[4][0]);
        CHECK(gmin[4][0] >= 0.0 && gmax[4][0] <= phi[4][0] / s->light[4].pick * (2 * APPM__PI * (1 - cos(30 * DEG))) /
                                                     sr_soft * (1 + 1e-5));
    }
    appm_scene_destroy(s);
}

/* Light powers in the ratio 0 : 1 : 0 : 1 : 2 : 0 make every CDF boundary
 * exactly representable (0, 1/4, 1/2, 1), so u can sit exactly on one: u = 1/4
 * must choose the light whose interval [1/4, 1/2) starts there, never the
 * zero-power light whose empty interval is [1/4, 1/4), nor the one before. */
static void test_pick_boundaries(void)
{
    static const float u[] = {0.0f, 0.25f, 0.5f, 0.2499999851f, 0.4999999702f, 0.9999999404f};
    static const uint32_t want[] = {1, 3, 4, 1, 3, 4};
    appm_scene *s = NULL;
    appm_diag d;
    size_t i;
    CHECK(check_write_file(check_path(GROUP, "exact.scene"),
                           "light point position 0 0 0 intensity 0 0 0\n"
                           "light point position 1 0 0 intensity 1 1 1\n"
                           "light point position 2 0 0 intensity 0 0 0\n"
                           "light point position 3 0 0 intensity 1 1 1\n"
                           "light point position 4 0 0 intensity 2 2 2\n"
                           "light point position 5 0 0 intensity 0 0 0\n"));
    CHECK_MSG(appm_scene_load(check_path(GROUP, "exact.scene"), NULL, &s, &d) == APPM_OK, "%s:%u: %s", d.file,
              d.line, d.message);
    if (!s) return;
    CHECK(s->nlight == 6);
    CHECK(s->light_cdf[2] == 0.25 && s->light_cdf[3] == 0.25 && s->light_cdf[4] == 0.5);
    for (i = 0; i < sizeof u / sizeof u[0]; ++i) {
        uint32_t li = appm__pick_light(s, u[i]);
        CHECK_MSG(li == want[i], "u = %.10g picks light %u, not %u", u[i], li, want[i]);
    }
    appm_scene_destroy(s);
}

/* ---- 5. Glossy --------------------------------------------------------------
 *
 * The test's own double-precision model of interface.md section 2, written
 * from the formula and not from the library:
 *   f = Kd / pi + Ks (Ns + 2) / (2 pi) max(0, wi . r)^Ns,  r = 2 (wo.n) n - wo,
 *   pdf = P_d cos / pi + (1 - P_d) (Ns + 1) / (2 pi) max(0, wi . r)^Ns (wi above),
 *   P_d = sum Kd / (sum Kd + sum Ks). */

static appm__material glossy_mat(double kd, double ks, double ns)
{
    appm__material m;
    memset(&m, 0, sizeof m);
    m.kind = APPM__MAT_GLOSSY;
    m.color = appm__v((float)kd, (float)kd, (float)kd);
    m.ks = appm__v((float)ks, (float)ks, (float)ks);
    m.ns = (float)ns;
    return m;
}

/* wo at polar angle theta (degrees) from +z, azimuth 0. */
static appm__v3 wo_at(double theta) { return appm__v((float)sin(theta * DEG), 0.0f, (float)cos(theta * DEG)); }

static double ref_pdf(double kd, double ks, double ns, const double wo[3], const double wi[3])
{
    double r[3] = {-wo[0], -wo[1], wo[2]}, c = wi[0] * r[0] + wi[1] * r[1] + wi[2] * r[2], pd = kd / (kd + ks);
    if (wi[2] <= 0.0) return 0.0;
    return pd * wi[2] / APPM__PI + (c > 0 ? (1.0 - pd) * (ns + 1.0) / (2.0 * APPM__PI) * pow(c, ns) : 0.0);
}

static double lobe_albedo(double ns, double theta, int n)
{
    return check_lobe_quad(ns, sin(theta * DEG), cos(theta * DEG), n, NULL);
}

/* The lobe alone: cos(a) to the axis must follow (Ns+1) cos^Ns a on [0, 1], so
 * v = cos^(Ns+1) a is uniform; binned in v and in the azimuth about the axis. */
static void test_lobe_chi2(double ns, long N)
{
    double obs[NT * NP], ex[NT * NP], axis[3] = {0.48, -0.6, 0.64}, t[3], b[3];
    appm__v3 ax = appm__v(0.48f, -0.6f, 0.64f);
    long i, badlen = 0;
    int c;
    char name[64];
    frame(axis, t, b);
    memset(obs, 0, sizeof obs);
    for (i = 0; i < N; ++i) {
        appm__v3 w = appm__phong_dir(ax, (float)ns, sample_uf(), sample_uf());
        double x = w.x * t[0] + w.y * t[1] + w.z * t[2], y = w.x * b[0] + w.y * b[1] + w.z * b[2];
        double z = w.x * axis[0] + w.y * axis[1] + w.z * axis[2];
        double a = atan2(sqrt(x * x + y * y), z), v = exp((ns + 1.0) * log(cos(a)));
        if (fabs(x * x + y * y + z * z - 1.0) > 1e-5) badlen++;
        obs[bin_of(z > 0 ? v : 0.0, 0, 1, NT) * NP + bin_of(atan2(y, x), -APPM__PI, APPM__PI, NP)] += 1;
    }
    for (c = 0; c < NT * NP; ++c) ex[c] = (double)N / (NT * NP);
    snprintf(name, sizeof name, "Phong lobe, Ns = %g", ns);
    CHECK_MSG(badlen == 0, "%s: %ld samples not of unit length", name, badlen);
    chi2_check(name, obs, ex, NT * NP);
}

/* The whole glossy sampler at incidence theta: cells in (cos theta_i, phi_i)
 * about the normal, expected counts from the reference pdf integrated over
 * each cell (midpoint, S x S points), plus one cell for the rejected samples
 * (the lobe below the horizon), whose probability (1 - P_d) P_below comes from
 * the lobe-frame quadrature above; the cells are scaled to hold the rest
 * (this removes the midpoint rule's global error, of order 1e-4, which at
 * normal incidence would otherwise expect rejections where none can occur). */
static void test_glossy_chi2(double kd, double ks, double ns, double theta, long N)
{
    enum { S = 24 };
    static double obs[NT * NP + 1], ex[NT * NP + 1];
    appm__material m = glossy_mat(kd, ks, ns);
    appm__surf sf = flat_surf();
    appm__v3 wo = wo_at(theta);
    double wod[3] = {wo.x, wo.y, wo.z}, up = 0.0, below, pd = kd / (kd + ks);
    long i;
    int c, a, k, l;
    char name[64];
    memset(obs, 0, sizeof obs);
    for (i = 0; i < N; ++i) {
        appm__bsdf_sample bs;
        if (!appm__bsdf_sample_dir(&m, &sf, wo, sample_uf(), sample_uf(), sample_uf(), APPM__RADIANCE, &bs)) {
            obs[NT * NP] += 1;
            continue;
        }
        obs[bin_of(bs.wi.z, 0, 1, NT) * NP + bin_of(atan2(bs.wi.y, bs.wi.x), -APPM__PI, APPM__PI, NP)] += 1;
    }
    for (c = 0; c < NT; ++c)
        for (a = 0; a < NP; ++a) {
            double sum = 0.0, dz = 1.0 / NT / S, dp = 2.0 * APPM__PI / NP / S;
            for (k = 0; k < S; ++k)
                for (l = 0; l < S; ++l) {
                    double z = (c + (k + 0.5) / S) / NT, phi = -APPM__PI + 2.0 * APPM__PI * (a + (l + 0.5) / S) / NP;
                    double sz = sqrt(1.0 - z * z), wi[3];
                    wi[0] = sz * cos(phi), wi[1] = sz * sin(phi), wi[2] = z;
                    sum += ref_pdf(kd, ks, ns, wod, wi) * dz * dp; /* dw = dz dphi */
                }
            ex[c * NP + a] = (double)N * sum;
            up += sum;
        }
    check_lobe_quad(ns, sin(theta * DEG), cos(theta * DEG), 20000, &below);
    ex[NT * NP] = (double)N * (1.0 - pd) * below;
    for (c = 0; c < NT * NP; ++c) ex[c] *= (1.0 - (1.0 - pd) * below) / up;
    snprintf(name, sizeof name, "glossy Ns %g at %g deg", ns, theta);
    chi2_check(name, obs, ex, NT * NP + 1);
}

/* E[f cos / pdf] of the sampler against Kd + Ks A(theta) from the quadrature. */
static void test_glossy_albedo(void)
{
    static const double nss[4] = {1, 10, 100, 1000}, thetas[4] = {0, 30, 60, 85};
    long N = check_quick() ? 100000 : 400000, i;
    int a, b;
    CHECK_NEAR(lobe_albedo(1, 0, 20000), 1.0, 1e-6); /* the normalisation: A(0) = 1 */
    CHECK_NEAR(lobe_albedo(100, 0, 20000), 1.0, 1e-6);
    for (a = 0; a < 4; ++a)
        for (b = 0; b < 4; ++b) {
            appm__material m = glossy_mat(0.3, 0.6, nss[a]);
            appm__surf sf = flat_surf();
            appm__v3 wo = wo_at(thetas[b]);
            double sum = 0.0, sum2 = 0.0, mean, se, expect = 0.3 + 0.6 * lobe_albedo(nss[a], thetas[b], 20000);
            long bad = 0;
            for (i = 0; i < N; ++i) {
                appm__bsdf_sample bs;
                double w;
                if (!appm__bsdf_sample_dir(&m, &sf, wo, sample_uf(), sample_uf(), sample_uf(), (int)(i & 1), &bs)) continue;
                w = bs.weight.y;
                sum += w, sum2 += w * w;
                /* the sample's pdf and weight agree with the library's pdf and f */
                if (fabs(bs.pdf - appm__bsdf_pdf(&m, sf.ns, bs.wi, wo)) > 1e-5 * bs.pdf ||
                    bs.specular || !(w >= 0.0))
                    bad++;
            }
            mean = sum / N;
            se = sqrt((sum2 / N - mean * mean) / N);
            CHECK_MSG(fabs(mean - expect) <= 4.0 * se + 1e-4, "glossy Ns %g at %g deg: albedo %.5f, quadrature %.5f (SE %.2g)",
                      nss[a], thetas[b], mean, expect, se);
            CHECK_MSG(bad == 0, "glossy Ns %g at %g deg: %ld samples with a bad pdf or weight", nss[a], thetas[b], bad);
            if (getenv("APPM_TEST_VERBOSE"))
                printf("  glossy albedo Ns %6g theta %2g: MC %.5f quadrature %.5f SE %.2g\n", nss[a], thetas[b],
                       mean, expect, se);
        }
}

/* Energy: with Kd + Ks = 1 the albedo is at most 1 at every incidence, and 1
 * exactly at normal incidence; it falls towards grazing as the horizon cuts the
 * lobe.  f and pdf against the closed forms, and reciprocity f(a,b) = f(b,a). */
static void test_glossy_energy(void)
{
    static const double nss[5] = {0.5, 1, 10, 100, 1000};
    int a, k;
    long i, nonrecip = 0, badf = 0, badpdf = 0;
    for (a = 0; a < 5; ++a) {
        /* the quadrature's own error, known at normal incidence where A = 1 */
        double worst = 0.0, prev = 2.0, qerr = fabs(lobe_albedo(nss[a], 0, 5000) - 1.0);
        int mono = 1;
        for (k = 0; k <= 89; ++k) {
            double alb = 0.25 + 0.75 * lobe_albedo(nss[a], k, 5000);
            worst = alb > worst ? alb : worst;
            mono &= alb <= prev + 1e-9;
            prev = alb;
        }
        CHECK_MSG(worst <= 1.0 + 0.75 * qerr + 1e-9, "Ns %g: albedo %.7f > 1 (quadrature error %.2g)", nss[a],
                  worst, qerr);
        CHECK_MSG(mono, "Ns %g: the albedo does not fall monotonically towards grazing", nss[a]);
    }
    for (i = 0; i < 200000; ++i) {
        appm__material m = glossy_mat(0.2 + 0.3 * sample_uf(), 0.4 * sample_uf() + 0.01, nss[i % 5] * (1.0 + sample_uf()));
        appm__v3 x = appm__uniform_sphere(sample_uf(), sample_uf()), y = appm__uniform_sphere(sample_uf(), sample_uf()), n = appm__v(0, 0, 1);
        appm__v3 f1, f2;
        double xd[3], yd[3], r[3], c, fr, pr;
        x.z = fabsf(x.z), y.z = fabsf(y.z);
        f1 = appm__bsdf_f(&m, n, x, y);
        f2 = appm__bsdf_f(&m, n, y, x);
        if (fabs(f1.y - f2.y) > 1e-5 * (f1.y + f2.y) + 1e-30) nonrecip++;
        xd[0] = x.x, xd[1] = x.y, xd[2] = x.z, yd[0] = y.x, yd[1] = y.y, yd[2] = y.z;
        r[0] = -yd[0], r[1] = -yd[1], r[2] = yd[2];
        c = xd[0] * r[0] + xd[1] * r[1] + xd[2] * r[2];
        fr = m.color.y / APPM__PI + (c > 0 ? m.ks.y * (m.ns + 2.0) / (2.0 * APPM__PI) * pow(c, m.ns) : 0.0);
        pr = ref_pdf(m.color.y, m.ks.y, m.ns, yd, xd);
        /* float rounding of c (1e-7) grows by Ns in c^Ns */
        if (fabs(f1.y - fr) > (1e-5 + 1e-6 * m.ns) * fr) badf++;
        if (fabs(appm__bsdf_pdf(&m, n, x, y) - pr) > (1e-5 + 1e-6 * m.ns) * pr) badpdf++;
    }
    CHECK_MSG(nonrecip == 0, "%ld pairs with f(a,b) != f(b,a)", nonrecip);
    CHECK_MSG(badf == 0, "%ld values of f off the closed form", badf);
    CHECK_MSG(badpdf == 0, "%ld values of the pdf off the closed form", badpdf);
    { /* below the surface: nothing */
        appm__material m = glossy_mat(0.5, 0.5, 10);
        appm__v3 f = appm__bsdf_f(&m, appm__v(0, 0, 1), appm__v(0.6f, 0, -0.8f), appm__v(0, 0, 1));
        CHECK(f.x == 0.0f && appm__bsdf_pdf(&m, appm__v(0, 0, 1), appm__v(0.6f, 0, -0.8f), appm__v(0, 0, 1)) == 0.0f);
    }
}

/* Large Ns approaches the mirror: at Ns = 1e5 every sample lies within 0.02
 * rad of the mirror direction (P(a > 0.02) = cos(0.02)^100001 = 2e-9); Kd = 0
 * so the lobe is always chosen.  The weight tends to Ks cos(theta), not Ks:
 * the normalisation (Ns + 2) / (2 pi) is exact at normal incidence only, and a
 * narrow lobe's albedo is Ks times the cosine at its axis (Lafortune and
 * Willems' model; the quadrature checks this limit too). */
static void test_glossy_mirror_limit(void)
{
    appm__material m = glossy_mat(0.0, 0.9, 1e5);
    appm__surf sf = flat_surf();
    appm__v3 wo = wo_at(45.0), r = appm__v(-wo.x, -wo.y, wo.z);
    long i, N = 100000, far = 0, rejected = 0;
    double sum = 0.0, amax = 0.0;
    for (i = 0; i < N; ++i) {
        appm__bsdf_sample bs;
        double a;
        if (!appm__bsdf_sample_dir(&m, &sf, wo, sample_uf(), sample_uf(), sample_uf(), APPM__RADIANCE, &bs)) {
            rejected++;
            continue;
        }
        a = acos(fmin(1.0, (double)appm__dot(bs.wi, r)));
        amax = a > amax ? a : amax;
        far += a > 0.02;
        sum += bs.weight.x;
    }
    CHECK_MSG(far == 0 && rejected == 0, "Ns 1e5: %ld samples beyond 0.02 rad (max %.4f), %ld rejected", far, amax,
              rejected);
    /* E[w] = Ks A(45 deg), A -> cos 45 deg (the lobe is 3e-3 wide) */
    CHECK_NEAR(sum / N, 0.9 * cos(45.0 * DEG), 2e-3);
    CHECK_NEAR(lobe_albedo(1e5, 45, 2000), cos(45.0 * DEG), 1e-4);
    CHECK_NEAR(lobe_albedo(1e5, 0, 2000), 1.0, 1e-6);
}

int main(void)
{
    int quick = check_quick();
    long N = quick ? 200000 : 1000000;
    appm__rng_seed(&g_rng, 2, 0, APPM__DOMAIN_TEST, 2);
    test_gamma_q();
    printf("chi-square tests (Sidak level %.5f):\n", sidak_alpha());
    test_cosine(appm__v(0, 0, 1), N, "cosine around +z");
    test_cosine(appm__normalize(appm__v(0.3f, -0.8f, -0.52f)), N, "cosine around a tilted n");
    test_sphere(N);
    test_triangle(N);
    g_qmc = 1;
    appm__sobol_table(&g_tab);
    printf("the same, fed with the low-discrepancy sampler:\n");
    test_cosine(appm__v(0, 0, 1), N, "qmc: cosine around +z");
    test_cosine(appm__normalize(appm__v(0.3f, -0.8f, -0.52f)), N, "qmc: cosine around a tilted n");
    test_sphere(N);
    test_triangle(N);
    g_qmc = 0;
    test_fresnel();
    test_dielectric();
    test_weights();
    test_lights();
    test_pick_boundaries();
    printf("glossy:\n");
    test_lobe_chi2(1, N);
    test_lobe_chi2(10, N);
    test_lobe_chi2(100, N);
    test_lobe_chi2(1e4, N);
    test_glossy_chi2(0.4, 0.5, 1, 0, N);
    test_glossy_chi2(0.4, 0.5, 10, 30, N);
    test_glossy_chi2(0.4, 0.5, 10, 75, N);
    test_glossy_chi2(0.2, 0.7, 40, 0, N);
    test_glossy_chi2(0.2, 0.7, 40, 50, N);
    test_glossy_chi2(0.2, 0.7, 40, 85, N);
    test_glossy_albedo();
    test_glossy_energy();
    test_glossy_mirror_limit();
    return check_finish();
}
