/* tests/t_sampler.c - the low-discrepancy sampler (appm.c section 2.3) and the
 * error estimate built on its chains (section 10).
 *
 *   1. Sobol' itself: the direction numbers recomputed from Joe and Kuo's
 *      primitive polynomials and initial m_k; the first points (in Gray-code
 *      order, as published) of dimensions 1-6; dimension 1 is the radical
 *      inverse in base 2.
 *   2. The fast path (tables, folded bit reversals) equals the definition
 *      owen(sobol(owen(index, s0), d), s_d), for random indices and keys; the
 *      photon paths' shared cache of hashes and lookups changes no number.
 *   3. Stratification, which holds for every seed by construction: every
 *      aligned block of 2^k points of coordinates (0, 1) of a group puts exactly
 *      one point in each elementary interval [a/2^p, (a+1)/2^p) x [b/2^q,
 *      (b+1)/2^q), p + q = k (a (0,k,2)-net); coordinates 2 to 5 are 1-D
 *      stratified, and the pairs with the joint dimensions 4, 5 keep the t of
 *      the unscrambled sequence.  Through the path samplers: the photons of one pass (M a
 *      power of two) are such a net in their emission position, and so are the
 *      2M photons of two passes of one chain (Keller et al. 2011); a pixel's
 *      first 2^k passes of one chain are a net in the pixel - with one chain
 *      (the default) and with four - and the choice at its first vertex is
 *      stratified, jointly with the pixel at the t of unscrambled Sobol'.
 *   4. Randomization: over many keys one coordinate of one point is uniform, and
 *      coordinates of different groups (padding) are independent (chi-square
 *      tests, p > 0.001 each); chains differ.
 *   5. --sampler random is the earlier PCG stream, number for number, and so is
 *      qmc past the last low-discrepancy vertex.
 *   6. The variance of a pixel mean from the chains (one-way analysis of
 *      variance) on exact inputs, and its expectation on independent passes,
 *      with the chains and with the spread of the passes.
 *   7. Renders: both samplers, and qmc with 4 chains, give the same bytes on 1,
 *      2 and 3 threads (5000 photons a pass: not a power of two, a partial last
 *      chunk), different images from each other; an invalid sampler and too
 *      many chains are refused.
 */
#include "../appm.c"
#define CHECK_GAMMA_Q
#include "check.h"

static appm__sobol_tab g_tab;

/* ---- Chi-square (gamma_q from check.h, as t_sampling.c) --------------------- */


/* Pearson's X^2 of counts against equal expectations; returns p. */
static double chi2_uniform(const long *obs, int cells, long n)
{
    double e = (double)n / cells, x2 = 0.0;
    int k;
    for (k = 0; k < cells; ++k) x2 += (obs[k] - e) * (obs[k] - e) / e;
    return gamma_q(0.5 * (cells - 1), 0.5 * x2);
}

/* ---- 1. Sobol' ------------------------------------------------------------------ */

/* Direction numbers from (s, a, m_1..m_s) by the Bratley-Fox recurrence, for
 * dimensions 2-6 of new-joe-kuo-6.21201 (written out again here, from the
 * published file, not from appm.c). */
static void joe_kuo_dirs(unsigned s, unsigned a, const unsigned *m0, uint32_t *v)
{
    uint32_t m[32];
    unsigned k, i;
    for (k = 0; k < s; ++k) m[k] = m0[k];
    for (k = s; k < 32; ++k) {
        uint32_t x = m[k - s] ^ (m[k - s] << s);
        for (i = 1; i < s; ++i)
            if ((a >> (s - 1 - i)) & 1u) x ^= m[k - i] << i;
        m[k] = x;
    }
    for (k = 0; k < 32; ++k) v[k] = m[k] << (31 - k);
}

static uint32_t radical_inverse2(uint32_t i)
{
    uint32_t x = 0;
    int k;
    for (k = 0; k < 32; ++k) x |= ((i >> k) & 1u) << (31 - k);
    return x;
}

/* Point i of Sobol' dimension d (0..5), 32 bits, by the definition: the XOR
 * of v_k over the set bits k of i (natural order, not Gray code).  appm.c
 * keeps only its tables, built from single bits by linearity; section 2
 * checks them against this. */
static uint32_t sobol_point(uint32_t i, unsigned d)
{
    const uint32_t *v = appm__sobol_v[d];
    uint32_t x = 0;
    for (; i; i >>= 1, ++v)
        if (i & 1u) x ^= *v;
    return x;
}

static void test_sobol(void)
{
    static const unsigned m2[] = {1}, m3[] = {1, 3}, m4[] = {1, 3, 1}, m5[] = {1, 1, 1}, m6[] = {1, 1, 3, 3};
    /* the first points of dimensions 1-6 in Gray-code order, as the Joe-Kuo
     * generator prints them (point 0 is the origin) */
    static const double first[16][6] = {{0, 0, 0, 0, 0, 0},
                                        {0.5, 0.5, 0.5, 0.5, 0.5, 0.5},
                                        {0.75, 0.25, 0.25, 0.25, 0.75, 0.75},
                                        {0.25, 0.75, 0.75, 0.75, 0.25, 0.25},
                                        {0.375, 0.375, 0.625, 0.875, 0.375, 0.125},
                                        {0.875, 0.875, 0.125, 0.375, 0.875, 0.625},
                                        {0.625, 0.125, 0.875, 0.625, 0.625, 0.875},
                                        {0.125, 0.625, 0.375, 0.125, 0.125, 0.375},
                                        {0.1875, 0.3125, 0.9375, 0.4375, 0.5625, 0.3125},
                                        {0.6875, 0.8125, 0.4375, 0.9375, 0.0625, 0.8125},
                                        {0.9375, 0.0625, 0.6875, 0.1875, 0.3125, 0.5625},
                                        {0.4375, 0.5625, 0.1875, 0.6875, 0.8125, 0.0625},
                                        {0.3125, 0.1875, 0.3125, 0.5625, 0.9375, 0.4375},
                                        {0.8125, 0.6875, 0.8125, 0.0625, 0.4375, 0.9375},
                                        {0.5625, 0.4375, 0.0625, 0.8125, 0.1875, 0.6875},
                                        {0.0625, 0.9375, 0.5625, 0.3125, 0.6875, 0.1875}};
    uint32_t v[32], i;
    unsigned d, k, bad = 0;
    for (k = 0; k < 32; ++k) bad += appm__sobol_v[0][k] != (1u << (31 - k));
    joe_kuo_dirs(1, 0, m2, v);
    for (k = 0; k < 32; ++k) bad += appm__sobol_v[1][k] != v[k];
    joe_kuo_dirs(2, 1, m3, v);
    for (k = 0; k < 32; ++k) bad += appm__sobol_v[2][k] != v[k];
    joe_kuo_dirs(3, 1, m4, v);
    for (k = 0; k < 32; ++k) bad += appm__sobol_v[3][k] != v[k];
    joe_kuo_dirs(3, 2, m5, v);
    for (k = 0; k < 32; ++k) bad += appm__sobol_v[4][k] != v[k];
    joe_kuo_dirs(4, 1, m6, v);
    for (k = 0; k < 32; ++k) bad += appm__sobol_v[5][k] != v[k];
    CHECK_MSG(bad == 0, "%u direction numbers differ from the Joe-Kuo recurrence", bad);
    for (i = 0; i < 16; ++i)
        for (d = 0; d < 6; ++d) {
            double x = sobol_point(i ^ (i >> 1), d) / 4294967296.0;
            CHECK_MSG(x == first[i][d], "Sobol' point %u (Gray code) dim %u: %.9g, published %.9g", i, d + 1,
                      x, first[i][d]);
        }
    for (bad = 0, i = 0; i < 100000; ++i)
        bad += sobol_point(i * 2654435761u, 0) != radical_inverse2(i * 2654435761u);
    CHECK_MSG(bad == 0, "dimension 1 differs from the radical inverse %u times", bad);
    CHECK(appm__reverse32(1u) == 0x80000000u && appm__reverse32(0x12345678u) == 0x1E6A2C48u);
}

/* ---- 2. The fast path against the definition --------------------------------- */

static uint32_t owen_ref(uint32_t x, uint32_t seed)
{
    return radical_inverse2(appm__lk_permute(radical_inverse2(x), seed));
}

static void test_fast_path(void)
{
    appm__rng rng;
    unsigned n, d, bad = 0, bad_range = 0;
    appm__rng_seed(&rng, 1, 0, APPM__DOMAIN_TEST, 21);
    for (n = 0; n < 200000; ++n) {
        uint64_t key = ((uint64_t)appm__rng_u32(&rng) << 32) | appm__rng_u32(&rng);
        uint32_t index = n < 1000 ? n : appm__rng_u32(&rng);
        unsigned group = appm__rng_u32(&rng) % 40;
        uint64_t g = appm__mix64(key ^ ((uint64_t)(group + 1) * 0xD1B54A32D192ED03ull));
        float u[6];
        appm__ld(&g_tab, key, appm__reverse32(index), group, 63u, u);
        for (d = 0; d < 6; ++d) {
            uint32_t i = owen_ref(index, (uint32_t)g);
            uint32_t x = owen_ref(sobol_point(i, d), (uint32_t)(g >> 32) + d * 0x9E3779B9u);
            bad += u[d] != (float)(x >> 8) * (1.0f / 16777216.0f);
            bad_range += !(u[d] >= 0.0f && u[d] < 1.0f);
        }
    }
    CHECK_MSG(bad == 0, "%u coordinates differ from owen(sobol(owen(i)))", bad);
    CHECK_MSG(bad_range == 0, "%u coordinates outside [0, 1)", bad_range);
    /* the mask computes exactly the coordinates asked for */
    {
        float a[6] = {-1, -1, -1, -1, -1, -1}, b[6];
        appm__ld(&g_tab, 77, appm__reverse32(5), 2, 37u, a);
        appm__ld(&g_tab, 77, appm__reverse32(5), 2, 63u, b);
        CHECK(a[0] == b[0] && a[1] == -1.0f && a[2] == b[2] && a[3] == -1.0f && a[4] == -1.0f &&
              a[5] == b[5]);
    }
}

/* ---- 3. Stratification ---------------------------------------------------------- */

/* Whether the n = 2^k points (x[i], y[i]) form a (0,k,2)-net: for every split
 * p + q = k, each of the 2^k intervals holds one point. */
static int is_net(const float *x, const float *y, unsigned k)
{
    static unsigned char seen[1u << 14];
    unsigned p, n = 1u << k, i;
    for (p = 0; p <= k; ++p) {
        memset(seen, 0, n);
        for (i = 0; i < n; ++i) {
            unsigned a = (unsigned)(x[i] * (float)(1u << p)), b = (unsigned)(y[i] * (float)(1u << (k - p)));
            unsigned cell = (a << (k - p)) | b;
            if (seen[cell]++) return 0;
        }
    }
    return 1;
}

static int is_strat1(const float *x, unsigned k)
{
    static unsigned char seen[1u << 14];
    unsigned n = 1u << k, i;
    memset(seen, 0, n);
    for (i = 0; i < n; ++i)
        if (seen[(unsigned)(x[i] * (float)n)]++) return 0;
    return 1;
}

/* The quality parameter t of the n = 2^k points (x[i], y[i]): the least t for
 * which every elementary interval of area 2^(t-k) holds exactly 2^t points
 * (t = 0: a (0,k,2)-net).  x, y as 32-bit fractions (unscrambled Sobol') when
 * xi, yi are given, else from the floats. */
static unsigned net_t(const float *x, const float *y, const uint32_t *xi, const uint32_t *yi, unsigned k)
{
    static unsigned short seen[1u << 13];
    unsigned t, p, i, n = 1u << k;
    for (t = 0; t < k; ++t) {
        unsigned m = k - t, ok = 1;
        for (p = 0; p <= m && ok; ++p) {
            memset(seen, 0, sizeof seen[0] << m);
            for (i = 0; i < n && ok; ++i) {
                unsigned a = xi ? (p ? xi[i] >> (32 - p) : 0) : (unsigned)(x[i] * (float)(1u << p));
                unsigned b = yi ? (m - p ? yi[i] >> (32 - (m - p)) : 0)
                                : (unsigned)(y[i] * (float)(1u << (m - p)));
                ok = ++seen[(a << (m - p)) | b] <= (1u << t);
            }
        }
        if (ok) return t;
    }
    return k;
}

static float g_x[6][1u << 13];
static uint32_t g_xi[2][1u << 13];


static void test_stratification(void)
{
    static const uint32_t starts[] = {0u, 1u << 13, 5u << 13, 0xFFFFE000u};
    unsigned k, s, key, i, d, nets = 0, bad = 0;
    for (key = 0; key < 6; ++key)
        for (k = 0; k <= 13; ++k)
            for (s = 0; s < 4; ++s) {
                unsigned group = key * 3 + 1, n = 1u << k;
                for (i = 0; i < n; ++i) {
                    float u[6];
                    appm__ld(&g_tab, appm__mix64(key), appm__reverse32(starts[s] + i), group, 63u, u);
                    for (d = 0; d < 6; ++d) g_x[d][i] = u[d];
                }
                nets++;
                if (!is_net(g_x[0], g_x[1], k) || !is_strat1(g_x[2], k) || !is_strat1(g_x[3], k) ||
                    !is_strat1(g_x[4], k) || !is_strat1(g_x[5], k)) {
                    if (bad++ < 5)
                        fprintf(stderr, "  key %u, block of 2^%u at %u: not stratified\n", key, k, starts[s]);
                }
            }
    CHECK_MSG(bad == 0, "%u of %u aligned blocks not stratified", bad, nets);
    printf("  %u aligned blocks of 2^0 .. 2^13 points: (0,k,2)-nets in (0, 1), stratified in 2 .. 5\n",
           nets);
}

/* The joint dimensions of the six-dimensional groups (the photon's light choice
 * with its emission): the 2-D projections that pair
 * dimension 4 or 5 with another are no (0,k,2)-nets, but an aligned block of
 * 2^k points of a shuffled, scrambled group is a digital shift of Sobol's first
 * 2^k, scrambled, and neither changes t: every projection of every block has
 * the t of the unscrambled sequence, computed here by brute force.  (With
 * padded groups these pairs would be independent, and t would be random.) */
static void test_joint_dims(void)
{
    static const unsigned pairs[][2] = {{0, 4}, {1, 4}, {2, 4}, {3, 4}, {0, 5}, {1, 5}, {4, 5}};
    unsigned k, pr, i, key, tmax = 0, bad = 0, blocks = 0;
    for (k = 1; k <= 12; ++k)
        for (pr = 0; pr < sizeof pairs / sizeof pairs[0]; ++pr) {
            unsigned a = pairs[pr][0], b = pairs[pr][1], n = 1u << k, t0;
            for (i = 0; i < n; ++i) {
                g_xi[0][i] = sobol_point(i, a);
                g_xi[1][i] = sobol_point(i, b);
            }
            t0 = net_t(NULL, NULL, g_xi[0], g_xi[1], k);
            if (t0 > tmax) tmax = t0;
            for (key = 0; key < 3; ++key) {
                uint32_t start = (key * 0x9E3779B9u) & ~(n - 1u);
                for (i = 0; i < n; ++i) {
                    float u[6];
                    appm__ld(&g_tab, appm__mix64(key + 100), appm__reverse32(start + i), key, 63u, u);
                    g_x[0][i] = u[a];
                    g_x[1][i] = u[b];
                }
                blocks++;
                if (net_t(g_x[0], g_x[1], NULL, NULL, k) != t0 && bad++ < 5)
                    fprintf(stderr, "  dims %u, %u, 2^%u points: t = %u, unscrambled %u\n", a + 1, b + 1, k,
                            net_t(g_x[0], g_x[1], NULL, NULL, k), t0);
            }
        }
    CHECK_MSG(bad == 0, "%u of %u blocks changed their t under scrambling", bad, blocks);
    /* the pairs are not independent: some t stays well below that of random points */
    CHECK_MSG(tmax <= 3, "Joe-Kuo dims 5, 6 with 1-4: t up to %u (at most 3 expected up to 2^12)", tmax);
    printf("  joint dimensions: %u blocks keep the unscrambled t (at most %u)\n", blocks, tmax);
}

/* Photon emission through the path sampler: pass j's M = 2^k photons, and the
 * 2M of passes j and j + K (one chain of K; places 2q and 2q + 1 in it, an
 * aligned block), are nets in (u1, u2). */
static void photon_nets(unsigned K)
{
    static const unsigned js[] = {1, 2, 3, 4, 9, 12, 17};
    const unsigned k = 10, M = 1u << k;
    unsigned jj, i, pass2, other = 0;
    for (jj = 0; jj < sizeof js / sizeof js[0]; ++jj) {
        unsigned j = js[jj];
        if ((j - 1) / K % 2) continue; /* place 2q + 1: its pair is the pass before */
        for (pass2 = 0; pass2 < 2; ++pass2)
            for (i = 0; i < M; ++i) {
                appm__sampler smp;
                float u[5];
                appm__sampler_photon(&smp, &g_tab, NULL, K, 42, j + pass2 * K, M, i);
                appm__smp_emit(&smp, 7u, u);
                g_x[0][pass2 * M + i] = u[1];
                g_x[1][pass2 * M + i] = u[2];
                g_x[2][pass2 * M + i] = u[3];
                g_x[3][pass2 * M + i] = u[0];
            }
        /* the light choice is stratified: a light of power share P gets
         * floor(M P) or ceil(M P) of a pass's photons, whatever the scramble */
        {
            unsigned below = 0;
            for (i = 0; i < M; ++i) below += g_x[3][i] < 0.3f;
            CHECK_MSG(below == (unsigned)(0.3 * M) || below == (unsigned)(0.3 * M) + 1,
                      "K = %u, pass %u: %u of %u photons picked the light of share 0.3", K, j, below, M);
        }
        CHECK_MSG(is_net(g_x[0], g_x[1], k), "K = %u, pass %u: its %u photons are not a net", K, j, M);
        CHECK_MSG(is_net(g_x[0], g_x[1], k + 1), "K = %u, passes %u and %u: their photons are not a net", K,
                  j, j + K);
        CHECK_MSG(is_strat1(g_x[2], k + 1), "K = %u, passes %u and %u: u3 is not stratified", K, j, j + K);
    }
    /* and a pixel's passes 1, 1 + K, 1 + 2K, ... (chain 0) in the pixel, and the
     * choice at its first vertex (group 0, dim 4) jointly with the pixel */
    for (i = 0; i < 256; ++i) {
        appm__sampler smp;
        float u[4];
        float v[3], w[4], x[6];
        appm__sampler_eye(&smp, &g_tab, K, 3, 1 + (uint64_t)i * K, 1234);
        appm__smp_camera(&smp, 1, u);
        g_x[0][i] = u[0];
        g_x[1][i] = u[1];
        g_x[2][i] = u[2];
        appm__smp_light(&smp, 0, 2u, v);
        g_x[3][i] = v[1];
        g_x[4][i] = v[2];
        appm__smp_bsdf(&smp, 0, 4u, w);
        g_x[5][i] = w[2];
        appm__ld(&g_tab, smp.key, smp.rindex, 0, 16u, x);
        other += w[2] != x[4];
    }
    CHECK_MSG(other == 0, "K = %u: %u first choices are not dim 4 of group 0", K, other);
    CHECK_MSG(is_net(g_x[3], g_x[4], 8),
              "K = %u: a pixel's 256 passes of one chain are not a net on the light at vertex 0", K);
    CHECK_MSG(is_net(g_x[0], g_x[1], 8),
              "K = %u: a pixel's 256 passes of one chain are not a net in the pixel", K);
    CHECK_MSG(is_strat1(g_x[2], 8),
              "K = %u: a pixel's 256 passes of one chain are not stratified on the lens", K);
    CHECK_MSG(is_strat1(g_x[5], 8),
              "K = %u: a pixel's 256 passes of one chain are not stratified in the first choice", K);
    {
        unsigned d, t, t0;
        for (d = 0; d < 2; ++d) {
            for (i = 0; i < 256; ++i) {
                g_xi[0][i] = sobol_point(i, d);
                g_xi[1][i] = sobol_point(i, 4);
            }
            t0 = net_t(NULL, NULL, g_xi[0], g_xi[1], 8);
            t = net_t(g_x[d], g_x[5], NULL, NULL, 8);
            CHECK_MSG(t == t0 && t <= 3, "K = %u: pixel %c and the first choice: t = %u, unscrambled %u", K,
                      d ? 'y' : 'x', t, t0);
        }
    }
}

/* The cache the photon paths of one worker share (appm__ld_cache) changes no
 * number: photon paths traced in turn through one cache, as a worker traces
 * them, against the same paths without it, every coordinate of the emission and
 * of every vertex's groups, across runs of 256 points (the cached lookups),
 * across passes and chains (a new key), and across n = 2^32 (a new key in the
 * middle of a pass: M = 2^31 - 1000 photons, point 2000 of pass 3 is n = 2^32). */
static void test_photon_cache(void)
{
    static const struct {
        unsigned chains;
        uint64_t pass, M, i0;
        unsigned n;
    } runs[] = {{1, 1, 4096, 0, 1500}, {1, 2, 5000, 4000, 700}, {3, 7, 1000, 100, 900},
                {1, 3, (1ull << 31) - 1000, 0, 5200}, {2, 5, 1024, 1000, 10}};
    appm__ld_cache cache;
    uint64_t key0 = 0, key1 = 0;
    unsigned r, k, b, bad = 0, total = 0, masks[] = {63u, 3u, 12u, 15u, 7u, 16u, 8u, 48u};
    cache.set = 0;
    for (r = 0; r < sizeof runs / sizeof runs[0]; ++r)
        for (k = 0; k < runs[r].n; ++k) {
            appm__sampler a, c;
            uint64_t i = runs[r].i0 + k;
            float ua[6], uc[6];
            int d;
            appm__sampler_photon(&a, &g_tab, NULL, runs[r].chains, 9, runs[r].pass, runs[r].M, i);
            appm__sampler_photon(&c, &g_tab, &cache, runs[r].chains, 9, runs[r].pass, runs[r].M, i);
            bad += a.key != c.key || a.rindex != c.rindex;
            if (r == 3 && k == 0) key0 = c.key;
            if (r == 3 && k == runs[r].n - 1) key1 = c.key;
            appm__smp_emit(&a, 7u, ua);
            appm__smp_emit(&c, 7u, uc);
            for (d = 0; d < 5; ++d) bad += ua[d] != uc[d];
            total += 5;
            for (b = 0; b < APPM__LD_VERTICES; ++b) {
                /* a mask that varies from path to path, as the materials do */
                unsigned m = masks[(k + b) % 8];
                for (d = 0; d < 6; ++d) ua[d] = uc[d] = -1.0f;
                appm__ld(&g_tab, a.key, a.rindex, APPM__G_BSDF(b), m, ua);
                appm__smp_ld(&c, APPM__G_BSDF(b), m, uc);
                for (d = 0; d < 6; ++d) bad += ua[d] != uc[d];
                appm__ld(&g_tab, a.key, a.rindex, APPM__G_LIGHT(b), m, ua);
                appm__smp_ld(&c, APPM__G_LIGHT(b), m, uc);
                for (d = 0; d < 6; ++d) bad += ua[d] != uc[d];
                total += 12;
            }
        }
    CHECK_MSG(bad == 0, "%u of %u numbers differ with the photon cache", bad, total);
    CHECK_MSG(key0 != key1, "the key did not change at n = 2^32");
}

static void test_photon_nets(void)
{
    photon_nets(1);
    photon_nets(4);
}

/* ---- 4. Randomization -------------------------------------------------------------- */

static void test_randomization(void)
{
    enum { NB = 32, NK = 32768 };
    static long h1[NB], h2[NB * NB], h3[NB * NB];
    unsigned key, i;
    double p1, p2, p3;
    long same = 0;
    memset(h1, 0, sizeof h1);
    memset(h2, 0, sizeof h2);
    memset(h3, 0, sizeof h3);
    for (key = 0; key < NK; ++key) {
        float a[4], b[4];
        uint64_t kk = appm__mix64(key * 7919u + 1);
        /* point 0 of each sequence (the least random index) */
        appm__ld(&g_tab, kk, appm__reverse32(0), 0, 1u, a);
        h1[(int)(a[0] * NB)]++;
        /* groups 2 and 3 of one point: light and BSDF numbers of one vertex */
        for (i = 0; i < 4; ++i) {
            appm__ld(&g_tab, kk, appm__reverse32(i), 2, 3u, a);
            appm__ld(&g_tab, kk, appm__reverse32(i), 3, 3u, b);
            h2[(int)(a[0] * NB) * NB + (int)(b[0] * NB)]++;
            h3[(int)(a[1] * NB) * NB + (int)(b[1] * NB)]++;
        }
    }
    p1 = chi2_uniform(h1, NB, NK);
    p2 = chi2_uniform(h2, NB * NB, 4L * NK);
    p3 = chi2_uniform(h3, NB * NB, 4L * NK);
    printf("  chi-square p: first coordinate over keys %.4f; groups 2 x 3, dim 0 %.4f, dim 1 %.4f\n", p1, p2,
           p3);
    CHECK_MSG(p1 > 0.001, "point 0 over %d keys is not uniform: p = %.3g", NK, p1);
    CHECK_MSG(p2 > 0.001, "groups 2 and 3 are dependent in dim 0: p = %.3g", p2);
    CHECK_MSG(p3 > 0.001, "groups 2 and 3 are dependent in dim 1: p = %.3g", p3);
    /* 4 chains: passes 1 and 2 of a pixel are points 0 of two independent
     * sequences, never the same numbers */
    for (i = 0; i < 1000; ++i) {
        appm__sampler s1, s2;
        float u1[2], u2[2];
        appm__sampler_eye(&s1, &g_tab, 4, 9, 1, i);
        appm__sampler_eye(&s2, &g_tab, 4, 9, 2, i);
        appm__smp_camera(&s1, 0, u1);
        appm__smp_camera(&s2, 0, u2);
        same += u1[0] == u2[0] && u1[1] == u2[1];
    }
    CHECK_MSG(same == 0, "%ld pixels got the same numbers in passes 1 and 2", same);
}

/* ---- 5. The random mode and the fallback ---------------------------------------- */

static void test_streams(void)
{
    appm__sampler smp;
    appm__rng ref;
    float u[4], w[5], e;
    unsigned bad = 0, k;
    /* random: every call draws from the earlier stream (seed, pass, domain, index) in order */
    appm__sampler_eye(&smp, NULL, 1, 17, 5, 99);
    appm__rng_seed(&ref, 17, 5, APPM__DOMAIN_EYE, 99);
    appm__smp_light(&smp, 0, 3u, u);
    for (k = 0; k < 3; ++k) bad += u[k] != appm__rng_float(&ref);
    appm__smp_bsdf(&smp, 1, 15u, u);
    for (k = 0; k < 3; ++k) bad += u[k] != appm__rng_float(&ref);
    bad += appm__smp_rr(&smp, 1, 15u, u) != appm__rng_float(&ref);
    appm__sampler_photon(&smp, NULL, NULL, 1, 17, 5, 1000, 321);
    appm__rng_seed(&ref, 17, 5, APPM__DOMAIN_PHOTON, 321);
    appm__smp_emit(&smp, 0u, w);
    for (k = 0; k < 5; ++k) bad += w[k] != appm__rng_float(&ref);
    CHECK_MSG(bad == 0, "random mode: %u numbers differ from the PCG stream", bad);
    /* qmc past the layout: the same stream */
    bad = 0;
    appm__sampler_eye(&smp, &g_tab, 1, 17, 5, 99);
    appm__rng_seed(&ref, 17, 5, APPM__DOMAIN_EYE, 99);
    appm__smp_bsdf(&smp, APPM__LD_VERTICES, 15u, u);
    for (k = 0; k < 3; ++k) bad += u[k] != appm__rng_float(&ref);
    e = appm__smp_rr(&smp, APPM__LD_VERTICES, 15u, u);
    bad += e != appm__rng_float(&ref);
    CHECK_MSG(bad == 0, "qmc past vertex %d: %u numbers differ from the PCG stream", APPM__LD_VERTICES, bad);
    /* and before it, not the stream */
    appm__smp_bsdf(&smp, 0, 15u, u);
    appm__rng_seed(&ref, 17, 5, APPM__DOMAIN_EYE, 99);
    CHECK(u[0] != appm__rng_float(&ref));
}

/* ---- 6. The variance of a pixel mean ----------------------------------------------- */

static double g_sums[4];

static void feed(appm__pixel *p, const double *v, uint64_t n)
{
    uint64_t j;
    memset(p, 0, sizeof *p);
    memset(g_sums, 0, sizeof g_sums);
    for (j = 1; j <= n; ++j) {
        appm__welford(p, j, v[j - 1]);
        appm__chain_add(g_sums, 4, j, v[j - 1]);
    }
}

static void test_mean_var(void)
{
    static const double v[10] = {1, 2, 4, 8, 3, 5, 7, 9, 0.5, 1.5};
    appm__pixel p;
    double m = 0, ss = 0, cm[4], want;
    int j, c;
    /* random: s^2 / j, s^2 the sample variance */
    feed(&p, v, 10);
    for (j = 0; j < 10; ++j) m += v[j] / 10;
    for (j = 0; j < 10; ++j) ss += (v[j] - m) * (v[j] - m);
    CHECK_NEAR(appm__mean_var(&p, NULL, 1, 10), ss / 9 / 10, 1e-12);
    CHECK_NEAR(appm__mean_var(&p, g_sums, 1, 10), ss / 9 / 10, 1e-12); /* one chain: the same */
    /* qmc, 8 passes: chains {1,3}, {2,5}, {4,7}, {8,9} (pass j in chain (j-1) mod 4) */
    feed(&p, v, 8);
    for (c = 0; c < 4; ++c) cm[c] = (v[c] + v[c + 4]) / 2;
    m = (cm[0] + cm[1] + cm[2] + cm[3]) / 4;
    for (ss = 0, c = 0; c < 4; ++c) ss += (cm[c] - m) * (cm[c] - m);
    want = ss / (4 * 3);
    CHECK_NEAR(appm__mean_var(&p, g_sums, 4, 8), want, 1e-12);
    /* qmc, 10 passes: chains of 3, 3, 2, 2; sum n_c (m_c - m)^2 / ((K - 1) j) */
    feed(&p, v, 10);
    {
        double s[4] = {v[0] + v[4] + v[8], v[1] + v[5] + v[9], v[2] + v[6], v[3] + v[7]};
        double n[4] = {3, 3, 2, 2}, mm = 0, q = 0;
        for (c = 0; c < 4; ++c) mm += s[c] / 10;
        for (c = 0; c < 4; ++c) q += n[c] * (s[c] / n[c] - mm) * (s[c] / n[c] - mm);
        CHECK_NEAR(appm__mean_var(&p, g_sums, 4, 10), q / (3 * 10), 1e-12);
    }
    /* 2 and 3 passes: as many chains as passes */
    feed(&p, v, 2);
    CHECK_NEAR(appm__mean_var(&p, g_sums, 4, 2), (v[0] - v[1]) * (v[0] - v[1]) / 4, 1e-12);
    CHECK(appm__mean_var(&p, g_sums, 4, 1) == 0.0);
    /* independent passes (uniform, variance 1/12): both estimates average to
     * 1 / (12 j) over many pixels; 20000 pixels of 3 degrees of freedom give a
     * relative standard error of 0.6 %, so 3 % is 5 sigma */
    {
        appm__rng rng;
        double sum[2] = {0, 0};
        int px, mode;
        static double w[13];
        appm__rng_seed(&rng, 5, 0, APPM__DOMAIN_TEST, 5);
        for (px = 0; px < 20000; ++px) {
            for (j = 0; j < 13; ++j) w[j] = appm__rng_float(&rng);
            feed(&p, w, 13);
            for (mode = 0; mode < 2; ++mode)
                sum[mode] += appm__mean_var(&p, mode ? g_sums : NULL, mode ? 4 : 1, 13) / 20000;
        }
        CHECK_MSG(fabs(sum[0] * 12 * 13 - 1) < 0.03, "random: mean estimate %.4f of the truth",
                  sum[0] * 12 * 13);
        CHECK_MSG(fabs(sum[1] * 12 * 13 - 1) < 0.03, "chains: mean estimate %.4f of the truth",
                  sum[1] * 12 * 13);
    }
}

/* The halves of one sequence (appm__var_scales): the ratio of the halves' variance
 * to the passes' spread recomputed from r's pixels' fields, independently of the
 * library's loop, with the library's weights (appm__err_weight, tested in
 * tests/t_estimator.c); var_scale is that ratio capped at 1 (halves_scale). */
static double halves_ratio(const appm_renderer *r)
{
    size_t i, n = (size_t)r->w * r->h;
    uint64_t P = 1;
    double j = (double)r->pass, a = 0, b = 0;
    while (2 * P <= r->pass) P *= 2;
    for (i = 0; i < n; ++i) {
        const appm__pixel *p = &r->pix[i];
        double w = appm__err_weight(r, i);
        double h1 = p->lh[0] / (P / 2.0), h2 = (p->lh[1] - p->lh[0]) / (P / 2.0);
        a += w * (h1 - h2) * (h1 - h2) / 4 * (double)P / j;
        b += w * p->wm2 / ((j - 1) * j);
    }
    return a / b;
}

static double halves_scale(const appm_renderer *r)
{
    double c = halves_ratio(r);
    return c < 1 ? c : 1;
}

/* 6b. The variance of a pixel's mean with one sequence, from its halves: the
 * scale the library takes recomputed by hand (after 37 passes: the halves of
 * the first 32); the halves' sums are those of the passes; and the estimate
 * against the truth, the spread of the means of independent renders
 * (different seeds, so different scrambles) of the path tracer, which has no
 * bias: on the bunny (a point light and a sky, where the sequence helps
 * most) the spread of the passes overstates the variance (1.38x here; 2.1x
 * while the point light was picked by power rather than sent a shadow ray
 * at every point, a choice the sequence stratified; appm.c 6.4); the
 * halves must be within 0.7 - 1.4 of the truth (16 seeds: the truth's own
 * relative standard error over 1024 pixels is a few per cent; the halves'
 * one degree of freedom a pixel, 16 renders, about 10 %). */
static void test_halves(void)
{
    enum { SEEDS = 16, W = 32, PASSES = 64 };
    static double mean[W * W], sq[W * W], est[2][W * W];
    appm_scene *sc = check_load_scene("scenes/bunny.scene");
    appm_config cfg;
    appm_renderer *r;
    int s, i;
    double truth = 0, ratio[2] = {0, 0};
    if (!sc) return;
    appm_config_init(&cfg);
    cfg.method = APPM_METHOD_PT;
    cfg.width = cfg.height = W;
    cfg.threads = 2;
    r = check_renderer(sc, &cfg);
    if (r && check_passes(r, 37)) {
        appm_stats st;
        double sum32 = 0, c;
        appm_renderer_stats(r, &st); /* makes the estimate: var_scale, and the weights halves_scale reads */
        c = halves_scale(r);
        CHECK_MSG(r->var_scale > 0.0 && r->var_scale < 1.0 && fabs(r->var_scale - c) <= 1e-12 * c,
                  "var_scale %.17g, by hand %.17g", r->var_scale, c);
        for (i = 0; i < W * W; ++i) sum32 += r->pix[i].lh[1];
        CHECK(sum32 > 0.0);
        {   /* the spread's bound: with the first half's sums moved into the second the halves
             * differ far more than the passes spread, and the scale is 1, not their ratio */
            for (i = 0; i < W * W; ++i) {
                r->pix[i].lh[1] += r->pix[i].lh[0];
                r->pix[i].lh[0] = 0.0;
                r->err_w[i] = appm__err_weight(r, i); /* the weights var_scales reads (the estimate
                                                       * left each weight times its pixel's error there) */
            }
            c = halves_ratio(r);
            appm__var_scales(r);
            CHECK_MSG(c > 1.5 && r->var_scale == 1.0, "halves / spread %.3f: var_scale %.17g, not 1", c,
                      r->var_scale);
        }
    }
    appm_renderer_destroy(r);
    for (s = 0; s < SEEDS && !check_quick(); ++s) {
        appm_image img;
        cfg.seed = 100 + (uint64_t)s;
        r = check_renderer(sc, &cfg);
        if (!r || !check_passes(r, PASSES)) {
            appm_renderer_destroy(r);
            break;
        }
        appm_renderer_image(r, &img);
        appm__error_update(r); /* var_scale */
        for (i = 0; i < W * W; ++i) {
            double L = appm__lum(appm__v(img.rgb[3 * i], img.rgb[3 * i + 1], img.rgb[3 * i + 2]));
            double spread = appm__mean_var(&r->pix[i], NULL, 1, PASSES);
            mean[i] += L / SEEDS;
            sq[i] += L * L / SEEDS;
            est[0][i] += spread / SEEDS;
            est[1][i] += r->var_scale * spread / SEEDS;
        }
        appm_renderer_destroy(r);
    }
    if (s == SEEDS) {
        for (i = 0; i < W * W; ++i) {
            double w = 1.0 / (mean[i] * mean[i] + 0.01);
            truth += w * (sq[i] - mean[i] * mean[i]) * SEEDS / (SEEDS - 1);
            ratio[0] += w * est[0][i];
            ratio[1] += w * est[1][i];
        }
        ratio[0] /= truth;
        ratio[1] /= truth;
        CHECK_MSG(ratio[0] > 1.2, "the spread of the passes: %.3f of the variance (the sequence should gain)",
                  ratio[0]);
        CHECK_MSG(ratio[1] > 0.7 * 0.7 && ratio[1] < 1.4 * 1.4, "the halves: %.3f of the variance", ratio[1]);
        printf("# halves: variance estimate / truth %.3f (the spread of the passes: %.3f)\n", ratio[1], ratio[0]);
    }
    appm_scene_destroy(sc);
}

/* ---- 7. Renders -------------------------------------------------------------------- */

static int render32(const appm_scene *sc, appm_sampler smp, unsigned chains, appm_method m, unsigned threads,
                    float *out)
{
    appm_config cfg;
    appm_renderer *r;
    appm_image img;
    int ok = 0;
    appm_config_init(&cfg);
    cfg.method = m;
    cfg.sampler = smp;
    cfg.chains = chains;
    cfg.width = cfg.height = 32;
    cfg.photons = 5000;
    cfg.threads = threads;
    cfg.seed = 5;
    r = check_renderer(sc, &cfg);
    if (r && check_passes(r, 6)) {
        appm_renderer_image(r, &img);
        memcpy(out, img.rgb, sizeof(float) * 3 * 32 * 32);
        ok = 1;
    }
    appm_renderer_destroy(r);
    return ok;
}

static void test_renders(void)
{
    static float img[3][3][3 * 32 * 32];
    static const char *const label[3] = {"qmc", "random", "qmc, 4 chains"};
    static const appm_method methods[2] = {APPM_METHOD_APPM, APPM_METHOD_PT};
    appm_scene *sc = check_load_scene("scenes/cornell-sphere-dof.scene");
    appm_config cfg;
    appm_renderer *r = NULL;
    appm_diag d;
    int smp, t, mi;
    if (!sc) return;
    for (mi = 0; mi < 2; ++mi) {
        for (smp = 0; smp < 3; ++smp)
            for (t = 0; t < 3; ++t)
                CHECK(render32(sc, smp == 1 ? APPM_SAMPLER_RANDOM : APPM_SAMPLER_QMC, smp == 2 ? 4 : 1,
                               methods[mi], (unsigned)t + 1, img[smp][t]));
        for (smp = 0; smp < 3; ++smp) {
            CHECK_MSG(memcmp(img[smp][0], img[smp][1], sizeof img[0][0]) == 0,
                      "%s, method %d: 1 and 2 threads differ", label[smp], mi);
            CHECK_MSG(memcmp(img[smp][0], img[smp][2], sizeof img[0][0]) == 0,
                      "%s, method %d: 1 and 3 threads differ", label[smp], mi);
        }
        CHECK_MSG(memcmp(img[0][0], img[1][0], sizeof img[0][0]) != 0, "method %d: qmc and random agree", mi);
        CHECK_MSG(memcmp(img[0][0], img[2][0], sizeof img[0][0]) != 0, "method %d: 1 and 4 chains agree", mi);
    }
    appm_config_init(&cfg);
    cfg.sampler = (appm_sampler)7;
    CHECK(appm_renderer_create(sc, &cfg, &r, &d) == APPM_ERR_INVALID_ARG && r == NULL &&
          strstr(d.message, "sampler"));
    appm_config_init(&cfg);
    cfg.chains = 65;
    CHECK(appm_renderer_create(sc, &cfg, &r, &d) == APPM_ERR_INVALID_ARG && r == NULL &&
          strstr(d.message, "chains"));
    appm_scene_destroy(sc);
}

int main(void)
{
    appm__sobol_table(&g_tab);
    test_sobol();
    test_fast_path();
    test_joint_dims();
    test_stratification();
    test_photon_nets();
    test_photon_cache();
    test_randomization();
    test_streams();
    test_mean_var();
    test_halves();
    test_renders();
    return check_finish();
}
