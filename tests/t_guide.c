/* tests/t_guide.c - photon emission guided by visual importance (appm.c 9.1).
 *
 * What is checked, and against what:
 *   1. The sampler reproduces its density: a learned score with a known pattern,
 *      200 000 emission samples warped by it, their cells against the mixture
 *      density a + (1 - a) g (chi^2 over the 1024 cells), each sample's weight
 *      factor the inverse of the density of its cell, each tag its cell.
 *   2. Photon weights still add up to each light's power on average: with a
 *      learned density for each light of caustic-glass (a spot and an
 *      environment), the mean over uniform numbers of gamma per emitted
 *      path, summed by light, against appm_scene_info's powers (within 4
 *      standard errors), as the unguided emission does.
 *   3. Where guiding cannot help, a closed diffuse box lit from inside, guided
 *      and unguided renders agree within their noise (the mean of the image,
 *      over 3 seeds each): the learned density would not pay, so guiding
 *      switches itself off.
 *   4. Where it helps, caustic-glass, the passes store many more photons per
 *      emitted path (deterministic counts, not times: at least 3x at 56x80
 *      after 32 and 48 passes; more with more paths a pass).
 *   5. Determinism: the same image bit for bit with 1, 2 and 3 threads;
 *      a checkpoint after N passes, loaded and run N more, gives the image of
 *      2N passes bit for bit, and a renderer that does not guide refuses it;
 *      --emission light has no guide at all; the default is guided.
 *   6. The choice between lights by the photon pass's efficiency, against
 *      sums done by hand (test_select).
 *   7. The learned choice of light (pi_l from the squared shares B_l and the
 *      costs k_l), against picks worked by hand: taken where it cuts the
 *      pass's variance x cost by 5 %, not where the lights' B are alike
 *      (test_picks); with it, weights still add up to each light's power (2);
 *      on caustic-glass it moves paths from the sky to the spot; checkpoints
 *      carry B_l.
 */
#include "../appm.c"
#include "check.h"

/* A guide of one slot for light 0 of s, its score set by `pattern`. */
static void fake_guide(appm__guide *gd, uint32_t *slot, uint32_t *light, double *score, uint64_t *seen, float *pdf,
                       double *cdf, unsigned char *active, double (*pattern)(int i, int k))
{
    static double samples[APPM__GUIDE_CELLS], paths[APPM__GUIDE_CELLS], work[APPM__GUIDE_CELLS],
        odd[APPM__GUIDE_CELLS], half[2 * APPM__GUIDE_CELLS];
    static uint64_t passes[1] = {2}; /* two passes that learned the same: halves that agree */
    appm__guide_eff e;
    int i, k;
    memset(gd, 0, sizeof *gd);
    gd->samples = samples;
    gd->paths = paths; /* nothing counted: every cell costs the same */
    gd->work = work;
    gd->score_odd = odd;
    gd->half = half;
    gd->passes = passes;
    for (i = 0; i < APPM__GUIDE_CELLS; ++i) samples[i] = 1e12; /* no shrinkage: the pattern itself */
    gd->nslot = 1;
    gd->slot = slot;
    gd->light = light;
    gd->score = score;
    gd->seen = seen;
    gd->pdf = pdf;
    gd->cdf = cdf;
    gd->active = active;
    slot[0] = 0;
    light[0] = 0;
    seen[0] = APPM__GUIDE_MIN;
    for (i = 0; i < APPM__GUIDE_RES; ++i)
        for (k = 0; k < APPM__GUIDE_RES; ++k) {
            odd[i * APPM__GUIDE_RES + k] = pattern(i, k);
            score[i * APPM__GUIDE_RES + k] = 2.0 * pattern(i, k);
        }
    appm__guide_density(gd, 0, &e);
}

static double peaks(int i, int k)
{
    if (i >= 10 && i < 14 && k >= 20 && k < 26) return 400.0; /* a bright patch */
    if (k < 8) return 0.0;                                     /* nothing: the defensive share alone */
    return 1.0 + 0.1 * i;
}

static void test_warp_chi2(void)
{
    static double score[APPM__GUIDE_CELLS], cdf[APPM__GUIDE_CDF];
    static float pdf[APPM__GUIDE_CELLS];
    static uint64_t hist[APPM__GUIDE_CELLS];
    uint32_t slot[1], light[1];
    uint64_t seen[1];
    unsigned char active[1];
    appm__guide gd;
    appm_scene s;
    appm__light l;
    double lcdf[2] = {0.0, 1.0}, chi2 = 0.0, dof = APPM__GUIDE_CELLS - 1, pmin = 1e9;
    appm__rng rng;
    int n = 200000, j, badw = 0, badtag = 0;
    memset(&s, 0, sizeof s);
    memset(&l, 0, sizeof l);
    l.pick = 1.0;
    s.light = &l;
    s.nlight = 1;
    s.light_cdf = lcdf;
    fake_guide(&gd, slot, light, score, seen, pdf, cdf, active, peaks);
    gd.pick = &l.pick; /* the light's own pick: weights carry only 1 / p */
    gd.pcdf = lcdf;
    CHECK(active[0] == 1);
    for (j = 0; j < APPM__GUIDE_CELLS; ++j) pmin = pdf[j] < pmin ? pdf[j] : pmin;
    CHECK_NEAR(pmin, APPM__GUIDE_DEFENSIVE, 1e-6); /* the defensive share where nothing was learned */
    appm__rng_seed(&rng, 5, 0, APPM__DOMAIN_TEST, 3);
    for (j = 0; j < n; ++j) {
        float u[5], w;
        uint32_t li, tag, cell;
        u[0] = appm__rng_float(&rng);
        u[1] = appm__rng_float(&rng);
        u[2] = appm__rng_float(&rng);
        tag = appm__guide_warp(&gd, &s, u, &li, &w);
        cell = appm__guide_cell(u[1], u[2]);
        hist[cell]++;
        badtag += tag != cell;
        badw += fabsf(w * pdf[tag] - 1.0f) > 2e-5f;
    }
    for (j = 0; j < APPM__GUIDE_CELLS; ++j) {
        double e = (double)n * pdf[j] / APPM__GUIDE_CELLS, d = (double)hist[j] - e;
        chi2 += d * d / e;
    }
    printf("guided warp: chi^2 %.0f over %.0f degrees of freedom\n", chi2, dof);
    CHECK_MSG(chi2 < dof + 5.0 * sqrt(2.0 * dof), "chi^2 %.0f, %.0f degrees of freedom", chi2, dof);
    /* a float may round a point onto its cell's far edge: a handful, never more */
    CHECK_MSG(badtag < n / 10000, "%d of %d samples tagged with another cell than theirs", badtag, n);
    CHECK_MSG(badw == 0, "%d weights are not 1 / p of the cell (to float rounding)", badw);
}

/* 2: E[gamma] per light over the emission, guided as a render would guide it. */
static void test_weights_power(void)
{
    appm_scene *s = check_load_scene("scenes/caustic-glass.scene");
    appm_config cfg;
    appm_renderer *r;
    appm_scene_info info;
    double sum[2][3], sq[2][3], want[2][3];
    int n = check_quick() ? 100000 : 400000, j, l, c;
    appm__rng rng;
    if (!s) return;
    appm_config_init(&cfg);
    cfg.emission = APPM_EMISSION_GUIDED;
    cfg.width = 16;
    cfg.height = 16;
    cfg.threads = 1;
    r = check_renderer(s, &cfg);
    if (!r) {
        appm_scene_destroy(s);
        return;
    }
    CHECK(r->guide.nslot == 2 && s->nlight == 2);
    for (l = 0; l < 2; ++l) { /* a learned density, different per light */
        r->guide.seen[l] = APPM__GUIDE_MIN;
        r->guide.passes[l] = 2;
        for (j = 0; j < APPM__GUIDE_CELLS; ++j)
            r->guide.score_odd[(size_t)l * APPM__GUIDE_CELLS + j] = (j * 7 + l * 13) % 97 < 20 ? 5.0 + l : 0.1,
            r->guide.score[(size_t)l * APPM__GUIDE_CELLS + j] = 2.0 * r->guide.score_odd[(size_t)l * APPM__GUIDE_CELLS + j],
            r->guide.samples[(size_t)l * APPM__GUIDE_CELLS + j] = 1e6;
    }
    {   /* each light's own density (appm__guide_select may guide only one), and a choice of
         * light that moves paths: B = 1 and 50 (7) */
        appm__guide_eff e[2];
        for (l = 0; l < 2; ++l) appm__guide_density(&r->guide, (uint32_t)l, &e[l]);
        r->guide.sq[0] = 1.0;
        r->guide.sq[1] = 50.0;
        appm__guide_picks(s, &r->guide, e);
    }
    CHECK(r->guide.active[0] && r->guide.active[1]);
    CHECK_MSG(fabs(r->guide.pick[0] - s->light[0].pick) > 0.05, "the choice of light did not move: %g, power's %g",
              r->guide.pick[0], s->light[0].pick);
    appm_scene_get_info(s, &info);
    for (l = 0; l < 2; ++l) {
        const double *p = s->light[l].kind == APPM__LIGHT_SPOT ? info.power_spot : info.power_environment;
        for (c = 0; c < 3; ++c) want[l][c] = p[c], sum[l][c] = sq[l][c] = 0.0;
    }
    appm__rng_seed(&rng, 9, 0, APPM__DOMAIN_TEST, 4);
    for (j = 0; j < n; ++j) {
        float u[5], w;
        uint32_t li;
        appm__photon_start ps;
        for (c = 0; c < 5; ++c) u[c] = appm__rng_float(&rng);
        appm__guide_warp(&r->guide, s, u, &li, &w);
        if (!appm__emit_light(s, li, u, &ps)) continue;
        for (c = 0; c < 3; ++c) {
            double g = (double)((&ps.gamma.x)[c] * w);
            sum[li][c] += g;
            sq[li][c] += g * g;
        }
    }
    for (l = 0; l < 2; ++l)
        for (c = 0; c < 3; ++c) {
            double m = sum[l][c] / n, se = sqrt((sq[l][c] / n - m * m) / n);
            CHECK_MSG(fabs(m - want[l][c]) < 4.0 * se + 1e-9 * want[l][c],
                      "light %d channel %d: mean weight %.6g, power %.6g (standard error %.3g)", l, c, m,
                      want[l][c], se);
        }
    appm_renderer_destroy(r);
    appm_scene_destroy(s);
}

/* A closed box, 2 units wide, every wall Lambertian (albedo 0.6), lit by an
 * emissive square under the ceiling facing down; the camera inside. */
static const char BOX_OBJ[] =
    "mtllib box.mtl\nusemtl wall\n"
    "v -1 -1 -1\nv 1 -1 -1\nv 1 1 -1\nv -1 1 -1\nv -1 -1 1\nv 1 -1 1\nv 1 1 1\nv -1 1 1\n"
    "f 1 2 3 4\nf 5 8 7 6\nf 1 5 6 2\nf 4 3 7 8\nf 1 4 8 5\nf 2 6 7 3\n"
    "usemtl lamp\nv -0.3 0.99 -0.3\nv 0.3 0.99 -0.3\nv 0.3 0.99 0.3\nv -0.3 0.99 0.3\nf 9 10 11 12\n";
static const char GUIDE_BOX_MTL[] = "newmtl wall\nKd 0.6 0.6 0.6\nnewmtl lamp\nKd 0 0 0\nKe 5 5 5\n";
static const char GUIDE_BOX_SCENE[] = "mesh box.obj\ncamera eye 0 0 0.9 target 0 -0.2 -1 up 0 1 0 fov 70\nimage 24 24\n";

static double box_mean(appm_scene *s, appm_emission e, uint64_t seed, double *guided)
{
    appm_config cfg;
    appm_renderer *r;
    appm_image img;
    appm_stats st;
    double m = 0.0;
    size_t i;
    appm_config_init(&cfg);
    cfg.emission = e;
    cfg.seed = seed;
    cfg.threads = 2;
    r = check_renderer(s, &cfg);
    if (!r) return -1.0;
    check_passes(r, 48);
    appm_renderer_image(r, &img);
    appm_renderer_stats(r, &st);
    *guided = st.emission_guided;
    for (i = 0; i < (size_t)img.width * img.height; ++i)
        m += appm__lum(appm__v(img.rgb[3 * i], img.rgb[3 * i + 1], img.rgb[3 * i + 2]));
    appm_renderer_destroy(r);
    return m / ((double)img.width * img.height);
}

static void test_closed_box(void)
{
    appm_memory_file files[2] = {{"box.obj", BOX_OBJ, sizeof BOX_OBJ - 1}, {"box.mtl", GUIDE_BOX_MTL, sizeof GUIDE_BOX_MTL - 1}};
    appm_scene *s = NULL;
    appm_diag d;
    double g[3], l[3], mg = 0.0, ml = 0.0, vg = 0.0, vl = 0.0, share = 0.0, tmp;
    int k;
    CHECK_MSG(appm_scene_load_memory(GUIDE_BOX_SCENE, sizeof GUIDE_BOX_SCENE - 1, "box.scene", files, 2, NULL, &s, &d) == APPM_OK,
              "box: %s", d.message);
    if (!s) return;
    for (k = 0; k < 3; ++k) {
        g[k] = box_mean(s, APPM_EMISSION_GUIDED, (uint64_t)k + 1, &tmp);
        share = tmp;
        l[k] = box_mean(s, APPM_EMISSION_LIGHT, (uint64_t)k + 1, &tmp);
        mg += g[k] / 3.0;
        ml += l[k] / 3.0;
    }
    for (k = 0; k < 3; ++k) {
        vg += (g[k] - mg) * (g[k] - mg) / 2.0;
        vl += (l[k] - ml) * (l[k] - ml) / 2.0;
    }
    printf("closed box: mean %.5f guided (guided share %.2f), %.5f from the light (sd of a render %.2g, %.2g)\n", mg,
           share, ml, sqrt(vg), sqrt(vl));
    /* every path of the box is useful: the learned density cannot halve the second
     * moment, so guiding stays off (appm__guide_density's test) */
    CHECK_MSG(share == 0.0, "guiding in use in the closed box (share %.2f)", share);
    /* the means of 3 renders each, against 4 standard errors of their difference
     * (and 0.3 % of the value, for seeds that happen to agree) */
    CHECK_MSG(fabs(mg - ml) < 4.0 * sqrt((vg + vl) / 3.0) + 3e-3 * ml, "guided %.5f, unguided %.5f", mg, ml);
    appm_scene_destroy(s);
}

/* The options of the caustic-glass renders: w x h, seed 3. */
static appm_config glass_config(appm_emission e, unsigned threads, uint32_t w, uint32_t h)
{
    appm_config cfg;
    appm_config_init(&cfg);
    cfg.emission = e;
    cfg.threads = threads;
    cfg.width = w;
    cfg.height = h;
    cfg.seed = 3;
    return cfg;
}

/* A renderer of caustic-glass after `passes` passes, or NULL. */
static appm_renderer *glass_render(appm_scene *s, appm_emission e, unsigned threads, uint32_t w, uint32_t h,
                                   int passes)
{
    appm_config cfg = glass_config(e, threads, w, h);
    appm_renderer *r = check_renderer(s, &cfg);
    if (r && !check_passes(r, passes)) {
        appm_renderer_destroy(r);
        r = NULL;
    }
    return r;
}

/* Renders caustic-glass at 56x80: the image into img (56 x 80 x 3 floats) and its stats. */
static int glass(appm_scene *s, appm_emission e, unsigned threads, int passes, float *img, appm_stats *st)
{
    appm_renderer *r = glass_render(s, e, threads, 56, 80, passes);
    appm_image im;
    if (!r) return 0;
    appm_renderer_image(r, &im);
    memcpy(img, im.rgb, (size_t)56 * 80 * 3 * sizeof(float));
    appm_renderer_stats(r, st);
    if (e == APPM_EMISSION_LIGHT) CHECK(r->guide.nslot == 0 && r->tag == NULL && !r->pmap.tag);
    appm_renderer_destroy(r);
    return 1;
}

/* The photons stored by pass `passes` of caustic-glass at 56x80. */
static uint64_t glass_stored(appm_scene *s, appm_emission e, int passes)
{
    appm_renderer *r = glass_render(s, e, 2, 56, 80, passes);
    appm_stats st;
    if (!r) return 0;
    appm_renderer_stats(r, &st);
    appm_renderer_destroy(r);
    return st.photons_stored;
}

static void test_glass(void)
{
    static float a[56 * 80 * 3], b[56 * 80 * 3];
    appm_scene *s = check_load_scene("scenes/caustic-glass.scene");
    appm_stats sa, sb;
    uint64_t stored_g = 0, stored_l = 0;
    int p;
    if (!s) return;
    /* 4: photons stored per emitted path in the 16th and the 32nd pass (56x80) */
    for (p = 32; p <= 48; p += 16) {
        stored_g += glass_stored(s, APPM_EMISSION_GUIDED, p);
        stored_l += glass_stored(s, APPM_EMISSION_LIGHT, p);
    }
    printf("caustic-glass 56x80: photons stored in passes 32 and 48: %llu guided, %llu from the lights\n",
           (unsigned long long)stored_g, (unsigned long long)stored_l);
    CHECK_MSG(stored_g >= 3 * stored_l, "guided emission stores %llu photons, the lights' own %llu",
              (unsigned long long)stored_g, (unsigned long long)stored_l);
    {   /* 7: after 48 passes the sky's photons, each lighting a few pixels of the floor, and the
         * spot's, aimed through the glass, leave B_sky / B_spot about 3 at k_spot / k_sky about
         * 4.5: the choice gives the spot about 0.195 of the paths, its power 0.123 */
        appm_renderer *r = glass_render(s, APPM_EMISSION_GUIDED, 2, 56, 80, 48);
        if (r) {
            const uint32_t spot = s->light[0].kind == APPM__LIGHT_SPOT ? 0u : 1u;
            printf("caustic-glass 56x80, pass 49: the spot's paths %.3f (its power's %.3f)\n", r->guide.pick[spot],
                   s->light[spot].pick);
            /* a render's value (the same for any thread count): B_l counted with the power's pick
             * instead of pi_l reads 0.170 */
            CHECK_MSG(r->guide.pick[spot] > 0.18, "the spot's pick %.3f, its power's %.3f", r->guide.pick[spot],
                      s->light[spot].pick);
            appm_renderer_destroy(r);
        }
    }
    /* 5: threads */
    if (glass(s, APPM_EMISSION_GUIDED, 1, 40, a, &sa)) {
        unsigned t;
        CHECK(sa.emission_guided > 0.0 && sa.emission_lights == 2);
        for (t = 2; t <= 3; ++t)
            if (glass(s, APPM_EMISSION_GUIDED, t, 40, b, &sb))
                CHECK_MSG(memcmp(a, b, sizeof a) == 0, "guided emission: %u threads render another image", t);
    }
    appm_scene_destroy(s);
}

static void test_guide_checkpoint(void)
{
    static float a[56 * 80 * 3];
    appm_scene *s = check_load_scene("scenes/caustic-glass.scene");
    appm_config cfg;
    appm_renderer *r, *q;
    appm_stats st;
    appm_image im;
    appm_diag d;
    size_t size = 0;
    void *buf;
    if (!s || !glass(s, APPM_EMISSION_GUIDED, 2, 48, a, &st)) {
        appm_scene_destroy(s);
        return;
    }
    CHECK(st.emission_guided > 0.0); /* the second half draws from learned densities */
    cfg = glass_config(APPM_EMISSION_GUIDED, 1, 56, 80);
    r = check_renderer(s, &cfg);
    q = check_renderer(s, &cfg);
    if (r && q && check_passes(r, 24) && appm_renderer_save(r, NULL, 0, &size, &d) == APPM_OK &&
        (buf = malloc(size)) != NULL) {
        CHECK(appm_renderer_save(r, buf, size, &size, &d) == APPM_OK);
        {   /* into a renderer that does not guide: refused, saying why */
            appm_renderer *u;
            cfg.emission = APPM_EMISSION_LIGHT;
            u = check_renderer(s, &cfg);
            CHECK(u && appm_renderer_load(u, buf, size, &d) == APPM_ERR_INVALID_ARG &&
                  strstr(d.message, "--emission") != NULL);
            appm_renderer_destroy(u);
        }
        CHECK_MSG(appm_renderer_load(q, buf, size, &d) == APPM_OK, "load: %s", d.message);
        CHECK(memcmp(q->guide.score, r->guide.score, (size_t)2 * APPM__GUIDE_CELLS * sizeof(double)) == 0);
        CHECK(memcmp(q->guide.score_odd, r->guide.score_odd, (size_t)2 * APPM__GUIDE_CELLS * sizeof(double)) == 0);
        CHECK(memcmp(q->guide.samples, r->guide.samples, (size_t)2 * APPM__GUIDE_CELLS * sizeof(double)) == 0);
        CHECK(memcmp(q->guide.paths, r->guide.paths, (size_t)2 * APPM__GUIDE_CELLS * sizeof(double)) == 0);
        CHECK(memcmp(q->guide.work, r->guide.work, (size_t)2 * APPM__GUIDE_CELLS * sizeof(double)) == 0);
        CHECK(r->guide.sq[0] > 0.0 && r->guide.sq[1] > 0.0 && memcmp(q->guide.sq, r->guide.sq, 2 * sizeof(double)) == 0);
        if (check_passes(q, 24)) {
            appm_renderer_image(q, &im);
            CHECK_MSG(memcmp(im.rgb, a, sizeof a) == 0, "24 + 24 passes across a checkpoint differ from 48");
        }
        free(buf);
    }
    appm_renderer_destroy(r);
    appm_renderer_destroy(q);
    appm_scene_destroy(s);
}

/* 5: the workers' counts are summed saturating, so a sum past 2^64 - 1 is
 * the same however it was split: on caustic-glass (two lights, two workers)
 * a pass's squared shares of 2^64 - 6 and 10 in either order, or all on one
 * worker, give one B_l, that of 2^64 - 1 (plain sums wrap to 4: 1024x1024,
 * --photons 300 rendered other bytes on 2 threads than on 1).  */
static void test_count_split(void)
{
    appm_scene *s = check_load_scene("scenes/caustic-glass.scene");
    appm_config cfg;
    appm_renderer *r;
    double got[3];
    int k;
    if (!s) return;
    appm_config_init(&cfg);
    cfg.width = cfg.height = 8;
    cfg.threads = 2;
    r = check_renderer(s, &cfg);
    /* two workers' counts (a build without threads has one: nothing to split) */
    CHECK(!r || r->threads == (APPM_THREADS ? 2u : 1u));
    if (r && r->guide.nslot == 2 && r->threads == 2) {
        const size_t stride = APPM__GUIDE_STRIDE(2), at = 3 * 2 * APPM__GUIDE_CELLS + 2; /* slot 0's squares */
        const uint64_t split[3][2] = {{UINT64_MAX - 5u, 10u}, {10u, UINT64_MAX - 5u}, {UINT64_MAX, 0u}};
        for (k = 0; k < 3; ++k) {
            memset(r->guide.count, 0, 2 * stride * sizeof *r->guide.count);
            r->guide.count[at] = split[k][0];
            r->guide.count[stride + at] = split[k][1];
            r->guide.sq[0] = 0.0;
            r->guide.ref = 1.0;
            appm__guide_learn(r);
            got[k] = r->guide.sq[0];
        }
        { /* B = n x the squares' unit x (ref / 2^16)^2 x pi_l, n = 2^64 - 1 */
            const double want =
                (double)UINT64_MAX * APPM__GUIDE_SQ_UNIT / 65536.0 / 65536.0 * r->guide.pick[r->guide.light[0]];
            CHECK_MSG(got[0] == got[1] && got[0] == got[2] && fabs(got[0] - want) < 1e-9 * want,
                      "B from split sums %.17g, %.17g, one worker's %.17g, want %.17g", got[0], got[1], got[2], want);
        }
    }
    appm_renderer_destroy(r);
    appm_scene_destroy(s);
}

/* 5 and 7: a checkpoint where the learned choice of light has moved (the
 * bunny under its sky, 32x32: the sky takes more than its power's share by
 * pass 24): 24 passes, saved, loaded into a new renderer, 24 more, give the
 * bytes of 48.  The picks are not saved: the next pass makes them from the
 * saved B_l (a checkpoint without B_l fails here, as in the caustic-glass
 * case); that they never read the last pass's picks is test_select's. */
static void test_picks_checkpoint(void)
{
    appm_scene *s = check_load_scene("scenes/bunny.scene");
    appm_config cfg;
    appm_renderer *a, *b, *c;
    appm_image im;
    appm_diag d;
    size_t size = 0, n = (size_t)32 * 32 * 3;
    float *want = (float *)malloc(n * sizeof(float));
    void *buf = NULL;
    uint32_t k, moved = 0;
    if (!s || !want) {
        appm_scene_destroy(s);
        free(want);
        return;
    }
    appm_config_init(&cfg);
    cfg.width = cfg.height = 32;
    cfg.threads = 2;
    cfg.seed = 5;
    a = check_renderer(s, &cfg);
    b = check_renderer(s, &cfg);
    c = check_renderer(s, &cfg);
    if (a && b && c && check_passes(a, 48) && check_passes(b, 24)) {
        appm_renderer_image(a, &im);
        memcpy(want, im.rgb, n * sizeof(float));
        for (k = 0; k < s->nlight; ++k) moved += fabs(b->guide.pick[k] - s->light[k].pick) > 0.05;
        CHECK_MSG(moved == 2, "the bunny's learned choice of light did not move by pass 24 (%u lights)", moved);
        if (appm_renderer_save(b, NULL, 0, &size, &d) == APPM_OK && (buf = malloc(size)) != NULL &&
            appm_renderer_save(b, buf, size, &size, &d) == APPM_OK) {
            CHECK_MSG(appm_renderer_load(c, buf, size, &d) == APPM_OK, "load: %s", d.message);
            CHECK(memcmp(c->guide.sq, b->guide.sq, c->guide.nslot * sizeof(double)) == 0);
            if (check_passes(c, 24)) {
                appm_renderer_image(c, &im);
                CHECK_MSG(memcmp(im.rgb, want, n * sizeof(float)) == 0,
                          "the bunny: 24 + 24 passes across a checkpoint differ from 48");
            }
        }
    }
    free(buf);
    free(want);
    appm_renderer_destroy(a);
    appm_renderer_destroy(b);
    appm_renderer_destroy(c);
    appm_scene_destroy(s);
}

/* 6. The choice between lights (appm__guide_select), against sums done by
 * hand.  Two lights, each picked with probability 1/2.  Light 0's importance
 * lies in 8 of the 1024 cells (v = 128 there: mean 1, its own second moment
 * 128, its learned density 96.25 there and 1/4 elsewhere: 1.33); light 1's is
 * flat (v = T: nothing to learn, its own test fails).  With T = 14 guiding
 * light 0 takes V = 2 (128 + T^2) - (1 + T)^2 = 423 to 169.7 (0.40x):
 *   a. every path costs the same: guided;
 *   b. its 8 cells' paths cost 12 (they hit the model; the others leave the
 *      scene): K = 1.043 -> 5.13, V K 1.97x: not guided, although its own test
 *      passes - the bunny's point light;
 *   c. as b, but light 0 holds the photon term (T = 0.5): V 254.25 -> 0.91,
 *      V K 0.018x: guided;
 *   d. every path costing the same, light 1 dimmer (T = 4): guiding light 0
 *      takes V = 263 to 9.7, guided; but if the even pass put its 8 spikes in
 *      8 other cells, v spikes over 16 cells and its own squares would still
 *      promise V 135 -> 9.7 (0.07x), while the halves' products are 0 there:
 *      the density promises nothing, not guided;
 *   e. every path costing the same, T = 3, and the odd pass alone with 8
 *      spikes of 1280 in 8 more cells: light 0's own test passes (its
 *      halves agree where both have light: 128 -> 7.9, 0.06x), V = 2 (128 +
 *      9) - (11 + 3)(1 + 3) = 218, but guided V = 2 (7.9 + 9) - 56 = -22:
 *      the halves' means disagree too much for a variance, not guided. */
static void select_case(double hot_cost, double T, int disagree, double odd_spike, int want)
{
    static double score[2 * APPM__GUIDE_CELLS], odd[2 * APPM__GUIDE_CELLS], samples[2 * APPM__GUIDE_CELLS],
        paths[2 * APPM__GUIDE_CELLS], work[2 * APPM__GUIDE_CELLS], cdf[2 * APPM__GUIDE_CDF], half[2 * APPM__GUIDE_CELLS];
    static float pdf[2 * APPM__GUIDE_CELLS];
    static appm_renderer r;
    static appm_scene sc;
    static appm__light L[2];
    uint32_t slot[2] = {0, 1}, light[2] = {0, 1};
    uint64_t seen[2] = {APPM__GUIDE_MIN, APPM__GUIDE_MIN}, passes[2] = {2, 2};
    /* no B: lights picked by power.  The picks a pass left are not part of the learned state: stale
     * ones (0.05 and 0.95, as if the last pass had learned another choice) must not change what is
     * guided, or a resumed render, which starts from the power's, would choose otherwise */
    double lcdf[3] = {0.0, 0.5, 1.0}, pick[2] = {0.05, 0.95}, pcdf[3], sq[2] = {0.0, 0.0};
    unsigned char active[2];
    int c;
    memset(&r, 0, sizeof r);
    memset(&sc, 0, sizeof sc);
    memset(L, 0, sizeof L);
    L[0].pick = L[1].pick = 0.5;
    sc.light = L;
    sc.nlight = 2;
    sc.light_cdf = lcdf;
    r.scene = &sc;
    r.guide.pick = pick;
    r.guide.pcdf = pcdf;
    r.guide.sq = sq;
    r.guide.nslot = 2;
    r.guide.slot = slot;
    r.guide.light = light;
    r.guide.score = score;
    r.guide.score_odd = odd;
    r.guide.half = half;
    r.guide.samples = samples;
    r.guide.paths = paths;
    r.guide.work = work;
    r.guide.seen = seen;
    r.guide.passes = passes;
    r.guide.pdf = pdf;
    r.guide.cdf = cdf;
    r.guide.active = active;
    for (c = 0; c < APPM__GUIDE_CELLS; ++c) {
        int hot = c % 128 == 5; /* 8 cells */
        odd[c] = hot ? 128.0 : 0.0; /* two passes that agree */
        odd[APPM__GUIDE_CELLS + c] = T;
        score[c] = 2.0 * odd[c];
        if (c % 128 == 37) score[c] = odd[c] = odd_spike; /* in the odd pass alone */
        if (disagree) /* the even pass's 8 spikes in 8 other cells: noise */
            score[c] = odd[c] + (c % 128 == 69 ? 128.0 : 0.0);
        score[APPM__GUIDE_CELLS + c] = 2.0 * T;
        samples[c] = samples[APPM__GUIDE_CELLS + c] = 1e12; /* no shrinkage */
        paths[c] = paths[APPM__GUIDE_CELLS + c] = 1e9;
        work[c] = 1e9 * (hot ? hot_cost : 1.0);
        work[APPM__GUIDE_CELLS + c] = 1e9;
    }
    if (odd_spike > 0.0) { /* light 0 passes its own test: the choice between lights decides */
        appm__guide_eff e;
        appm__guide_density(&r.guide, 0, &e);
        CHECK_MSG(active[0] && e.m_with <= 0.5 * e.m_own, "own test: active %d, %g against %g", active[0], e.m_with,
                  e.m_own);
    }
    appm__guide_prepare(&r);
    CHECK_MSG(active[0] == want && !active[1],
              "hot cells cost %g, T %g, halves %s, odd spikes %g: light 0 guided %d, light 1 %d", hot_cost, T,
              disagree ? "disagree" : "agree", odd_spike, active[0], active[1]);
    CHECK_NEAR(r.stats.emission_guided, want ? 0.375 : 0.0, 1e-12);
    CHECK(pick[0] == 0.5 && pick[1] == 0.5 && pcdf[1] == 0.5);
    for (c = 0; c < APPM__GUIDE_CELLS; ++c) /* a light not guided draws from its own density */
        if (!want && pdf[c] != 1.0f) break;
    CHECK(want || c == APPM__GUIDE_CELLS);
}

static void test_select(void)
{
    select_case(1.0, 14.0, 0, 0.0, 1);
    select_case(12.0, 14.0, 0, 0.0, 0);
    select_case(12.0, 0.5, 0, 0.0, 1);
    select_case(1.0, 4.0, 0, 0.0, 1);
    select_case(1.0, 4.0, 1, 0.0, 0);
    select_case(1.0, 3.0, 0, 1280.0, 0);
}

/* 7. The learned choice of light (appm__guide_picks) against picks worked by
 * hand.  Three lights picked by power 0.6, 0.15 and 0.25; the first two are
 * guided (P = 0.75), their densities not active, so k_l is k_own.
 *   a. B = 1 and 16, every path costing 1: sqrt(B / k) = 1 and 4, so
 *      pi = 0.25 x 0.6 + 0.75 x 0.75 x 1/5 = 0.2625 and 0.25 x 0.15 + 0.75 x
 *      0.75 x 4/5 = 0.4875, the third light's 0.25 kept; V 108.33 -> 36.63
 *      at the same K: taken.  A path of light 1 weighs 0.15 / 0.4875.
 *   b. light 1's paths costing 16: sqrt(B / k) = 1 and 1, pi = 0.43125 and
 *      0.31875; V K 325 -> 290.5 (0.894x): taken.
 *   c. the two guided lights of equal power (0.375 each), B = 1 and 1.1,
 *      costs equal: the choice would cut V K to 0.9995x, not the 0.95x that
 *      pays: not taken, every light keeps its power's pick.
 *   d. fewer than APPM__GUIDE_MIN pairs: not taken.
 *   e. as a, but light 0 guided by its density, whose paths cost 16 (its own
 *      1): sqrt(B / k) = 1/4 and 4, pi = 0.15 + 0.5625 / 17 = 0.183088 and
 *      0.0375 + 0.5625 x 16 / 17 = 0.566912; V K 1056.25 -> 117.8: taken. */
static void picks_case(const double *own, const double *B, const double *k, double k0_with, uint64_t pairs,
                       const double *want)
{
    static appm__light L[3];
    appm_scene sc;
    appm__guide gd;
    appm__guide_eff e[2];
    uint32_t slot[3] = {0, 1, UINT32_MAX}, light[2] = {0, 1}, li;
    uint64_t seen[2];
    double lcdf[4], pick[3], pcdf[4], sq[2];
    unsigned char active[2] = {0, 0};
    float u[5] = {0.0f, 0.5f, 0.5f, 0.5f, 0.5f}, w;
    float pdf[2 * APPM__GUIDE_CELLS];
    double cdf[2 * APPM__GUIDE_CDF];
    int i;
    memset(&sc, 0, sizeof sc);
    memset(&gd, 0, sizeof gd);
    memset(e, 0, sizeof e);
    lcdf[0] = 0.0;
    for (i = 0; i < 3; ++i) {
        L[i].pick = own[i];
        lcdf[i + 1] = lcdf[i] + own[i];
    }
    lcdf[3] = 1.0;
    sc.light = L;
    sc.nlight = 3;
    sc.light_cdf = lcdf;
    gd.nslot = 2;
    gd.slot = slot;
    gd.light = light;
    gd.seen = seen;
    gd.active = active;
    gd.sq = sq;
    gd.pick = pick;
    gd.pcdf = pcdf;
    for (i = 0; i < 2; ++i) {
        sq[i] = B[i];
        seen[i] = pairs / 2;
        e[i].k_own = e[i].k_with = k[i];
    }
    if (k0_with > 0.0) { /* light 0 draws from its density (flat here: the warp's weight is pick / pi) */
        active[0] = 1;
        e[0].k_with = k0_with;
        gd.pdf = pdf;
        gd.cdf = cdf;
        for (i = 0; i < 2 * APPM__GUIDE_CELLS; ++i) pdf[i] = 1.0f;
        appm__guide_cdf(&gd, 0);
        appm__guide_cdf(&gd, 1);
    }
    appm__guide_picks(&sc, &gd, e);
    for (i = 0; i < 3; ++i)
        CHECK_MSG(fabs(pick[i] - want[i]) < 1e-12, "light %d: picked with %.6g, want %.6g", i, pick[i], want[i]);
    CHECK_NEAR(pcdf[1], want[0], 1e-12);
    CHECK_NEAR(pcdf[2], want[0] + want[1], 1e-12);
    CHECK(pcdf[3] == 1.0);
    u[0] = (float)(want[0] + 0.5 * want[1]); /* inside light 1's interval: its weight carries pick / pi */
    (void)appm__guide_warp(&gd, &sc, u, &li, &w);
    CHECK_MSG(li == 1 && fabs(w - own[1] / want[1]) < 1e-6, "light %u, weight factor %g (want light 1, %g)", li, w,
              own[1] / want[1]);
}

static void test_picks(void)
{
    const double own[3] = {0.6, 0.15, 0.25}, even[3] = {0.375, 0.375, 0.25};
    const double Ba[2] = {1.0, 16.0}, Bc[2] = {1.0, 1.1}, k1[2] = {1.0, 1.0}, kb[2] = {1.0, 16.0};
    const double wa[3] = {0.2625, 0.4875, 0.25}, wb[3] = {0.43125, 0.31875, 0.25};
    const double we[3] = {0.15 + 0.5625 / 17.0, 0.0375 + 0.5625 * 16.0 / 17.0, 0.25};
    picks_case(own, Ba, k1, 0.0, APPM__GUIDE_MIN, wa);
    picks_case(own, Ba, kb, 0.0, APPM__GUIDE_MIN, wb);
    picks_case(even, Bc, k1, 0.0, APPM__GUIDE_MIN, even);
    picks_case(own, Ba, k1, 0.0, APPM__GUIDE_MIN - 2, own);
    picks_case(own, Ba, k1, 16.0, APPM__GUIDE_MIN, we);
}

/* A cell's importance shrunk towards the mean by the paths behind it
 * (appm__guide_importance): (N_c V_c + n0 mean) / (N_c + n0), n0 = 16, V_c the
 * cell's scores a pass.  Over 4 passes: cell 0 scored 2 a pass from 16 paths,
 * cell 1 nothing from none, the rest 1 a pass from 16 paths each, so mean(V) =
 * 1 and v = 1.5, 1 (the mean: no paths, no say), 1.  The halves
 * (appm__guide_halves), odd and even passes 2 each, are shrunk with half the
 * paths each (32 a cell here, so 16 a half): the same figures from either half.
 * Without the shrinkage cell 1 reads 0 and cell 0 2; with all the paths in
 * each half, 1.667. */
static void test_importance(void)
{
    static double score[APPM__GUIDE_CELLS], odd[APPM__GUIDE_CELLS], samples[APPM__GUIDE_CELLS];
    static double v[APPM__GUIDE_CELLS], vo[APPM__GUIDE_CELLS], ve[APPM__GUIDE_CELLS];
    appm__guide gd;
    uint64_t passes = 4;
    int i, bad = 0;
    memset(&gd, 0, sizeof gd);
    gd.nslot = 1;
    gd.score = score;
    gd.score_odd = odd;
    gd.samples = samples;
    gd.passes = &passes;
    for (i = 0; i < APPM__GUIDE_CELLS; ++i) {
        score[i] = i == 0 ? 8.0 : (i == 1 ? 0.0 : 4.0);
        samples[i] = i == 1 ? 0.0 : 16.0;
    }
    CHECK_NEAR(appm__guide_importance(&gd, 0, v), 1024.5, 1e-9);
    CHECK_NEAR(v[0], 1.5, 1e-12);
    CHECK_NEAR(v[1], 1.0, 1e-12);
    for (i = 2; i < APPM__GUIDE_CELLS; ++i) bad += fabs(v[i] - 1.0) > 1e-12;
    CHECK_MSG(bad == 0, "%d cells of the rest not at 1", bad);
    for (i = 0; i < APPM__GUIDE_CELLS; ++i) {
        odd[i] = 0.5 * score[i];
        samples[i] *= 2.0;
    }
    appm__guide_halves(&gd, 0, vo, ve);
    CHECK_NEAR(vo[0], 1.5, 1e-12);
    CHECK_NEAR(ve[0], 1.5, 1e-12);
    CHECK_NEAR(vo[1], 1.0, 1e-12);
    CHECK_NEAR(ve[1], 1.0, 1e-12);
    for (bad = 0, i = 2; i < APPM__GUIDE_CELLS; ++i) bad += fabs(vo[i] - 1.0) > 1e-12 || fabs(ve[i] - 1.0) > 1e-12;
    CHECK_MSG(bad == 0, "%d cells of the rest not at 1 in the halves", bad);
}

int main(void)
{
    {   /* guided is the default, and a zeroed configuration is the default */
        static const appm_config zero;
        appm_config c;
        appm_config_init(&c);
        CHECK(c.emission == APPM_EMISSION_GUIDED && zero.emission == APPM_EMISSION_GUIDED);
    }
    test_select();
    test_importance();
    test_picks();
    test_warp_chi2();
    test_weights_power();
    test_closed_box();
    test_glass();
    test_guide_checkpoint();
    test_picks_checkpoint();
    test_count_split();
    return check_finish();
}
