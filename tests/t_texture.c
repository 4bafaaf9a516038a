/* tests/t_texture.c - texture maps (vt, map_Kd, map_Ks, map_d) and environment
 * maps (section 4.5, 6.2): lookups against hand-computed bilinear values, a
 * textured plane whose rendered value is its texel times the light, cut-outs
 * that let light and rays through, an emitter whose cut-out holes emit nothing, the environment sampler against its own
 * density (chi-square) and against a quadrature of the sphere, its product densities and the shadow rays'
 * irradiance against a quadrature, a white-map
 * furnace, rotation, missing maps, and the checkpoint hash. */
#include "../appm.c"
#include "check.h"

/* The base-2 radical inverse of i (van der Corput). */
static double vdc(uint32_t i)
{
    double r = 0.0, f = 0.5;
    for (; i; i >>= 1, f *= 0.5)
        if (i & 1u) r += f;
    return r;
}

/* tests/out/texture-NAME into buf (check_path's buffer lasts two calls). */
static void tpath(char *buf, const char *name)
{
    snprintf(buf, 256, "%s", check_path("texture", name));
}

/* tests/out/texture-NAMESUFFIX into buf. */
static void tpath2(char *buf, const char *name, const char *suffix)
{
    char text[256];
    snprintf(text, sizeof text, "%s%s", name, suffix);
    tpath(buf, text);
}

/* A w x h PFM of linear RGB from rgb[] (row 0 at the top) at path. */
static int write_pfm(const char *path, uint32_t w, uint32_t h, const float *rgb)
{
    appm_image img;
    img.width = w;
    img.height = h;
    img.rgb = (float *)rgb;
    return appm_image_write(path, &img, 1.0, NULL) == APPM_OK;
}

/* A unit square in the z = 0 plane facing +z, (u, v) = (x, y) over [0,1]^2,
 * in material m of MTL file mtl. */
static void write_plane(const char *obj, const char *mtl_name)
{
    char text[512];
    snprintf(text, sizeof text,
             "mtllib %.200s\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\n"
             "usemtl m\nf 1/1 2/2 3/3\nf 1/1 3/3 4/4\n",
             mtl_name);
    CHECK(check_write_file(obj, text));
}

/* A camera looking at the unit square from +z, the square filling the image. */
static const char *const PLANE_CAMERA = "camera eye 0.5 0.5 2 target 0.5 0.5 0 fov 28.0724869\nimage 32 32\n";

/* The unit square in material m of MTL text mtl_text (whose maps name files
 * in tests/out), seen by PLANE_CAMERA under a constant white sky, written as
 * tests/out/texture-NAME.{mtl,obj,scene} and loaded (NULL on failure). */
static appm_scene *load_plane(const char *name, const char *mtl_text)
{
    char mtl[256], obj[256], scn[256], text[512];
    appm_scene *s = NULL;
    appm_diag d;
    tpath2(mtl, name, ".mtl");
    tpath2(obj, name, ".obj");
    tpath2(scn, name, ".scene");
    CHECK(check_write_file(mtl, mtl_text));
    snprintf(text, sizeof text, "texture-%s.mtl", name);
    write_plane(obj, text);
    snprintf(text, sizeof text, "%smesh texture-%s.obj\nenvironment 1 1 1\n", PLANE_CAMERA, name);
    CHECK(check_write_file(scn, text));
    CHECK_MSG(appm_scene_load(scn, NULL, &s, &d) == APPM_OK, "%s", d.message);
    return s;
}

static void render_texture(const appm_scene *s, appm_method method, unsigned passes, appm_image *out)
{
    appm_config cfg;
    appm_renderer *r = NULL;
    appm_diag d;
    unsigned k;
    appm_config_init(&cfg);
    cfg.method = method;
    cfg.threads = 2;
    out->rgb = NULL;
    CHECK(appm_renderer_create(s, &cfg, &r, &d) == APPM_OK);
    if (!r) return;
    for (k = 0; k < passes; ++k) CHECK(appm_renderer_pass(r) == APPM_OK);
    appm_renderer_image(r, out);
    {
        size_t n = (size_t)out->width * out->height * 3;
        float *copy = (float *)malloc(n * sizeof(float));
        if (copy) memcpy(copy, out->rgb, n * sizeof(float));
        out->rgb = copy;
    }
    appm_renderer_destroy(r);
}

static const float *px(const appm_image *img, uint32_t x, uint32_t y)
{
    return img->rgb + 3 * ((size_t)y * img->width + x);
}

/* Bilinear lookups, wrap-around and sRGB decoding against values worked out
 * by hand. */
static void test_lookup(void)
{
    static const unsigned char g8[4] = {0, 255, 128, 64}; /* 2 x 2 grey */
    float f[2 * 2 * 3] = {1, 0, 0, 0, 1, 0, 0, 0, 1, 1, 1, 1};
    appm__texture t;
    appm__v3 c;
    memset(&t, 0, sizeof t);
    t.px.w = 2;
    t.px.h = 2;
    t.px.channels = 3;
    t.px.depth = 32;
    t.px.data = f;
    /* texel centres: (u, v) = ((x + 1/2) / 2, 1 - (y + 1/2) / 2) */
    c = appm__tex_rgb(&t, 0.25f, 0.75f);
    CHECK(c.x == 1 && c.y == 0 && c.z == 0);
    c = appm__tex_rgb(&t, 0.75f, 0.25f);
    CHECK(c.x == 1 && c.y == 1 && c.z == 1);
    c = appm__tex_rgb(&t, 0.5f, 0.75f); /* halfway between the top two */
    CHECK_NEAR(c.x, 0.5, 1e-6);
    CHECK_NEAR(c.y, 0.5, 1e-6);
    CHECK_NEAR(c.z, 0.0, 1e-6);
    c = appm__tex_rgb(&t, 0.0f, 0.75f); /* the left edge wraps: halfway between right and left */
    CHECK_NEAR(c.x, 0.5, 1e-6);
    CHECK_NEAR(c.y, 0.5, 1e-6);
    c = appm__tex_rgb(&t, 3.25f, -1.25f); /* repeat: the same as (0.25, 0.75) */
    CHECK(c.x == 1 && c.y == 0 && c.z == 0);
    c = appm__tex_rgb(&t, 0.5f, 0.5f); /* the centre: the mean of all four */
    CHECK_NEAR(c.x, 0.5, 1e-6);
    CHECK_NEAR(c.y, 0.5, 1e-6);
    CHECK_NEAR(c.z, 0.5, 1e-6);
    /* 8-bit grey: sRGB-decoded before blending; as a mask: raw */
    t.px.channels = 1;
    t.px.depth = 8;
    t.px.data = (void *)g8;
    c = appm__tex_rgb(&t, 0.75f, 0.75f);
    CHECK_NEAR(c.x, 1.0, 1e-6);
    c = appm__tex_rgb(&t, 0.25f, 0.25f); /* code 128 */
    CHECK_NEAR(c.x, pow((128 / 255.0 + 0.055) / 1.055, 2.4), 1e-6);
    c = appm__tex_rgb(&t, 0.5f, 0.75f); /* between codes 0 and 255: linear mean 0.5, not code 128 */
    CHECK_NEAR(c.x, 0.5, 1e-6);
    CHECK_NEAR(appm__tex_coverage(&t, 0.5f, 0.25f), (128 + 64) / 510.0, 1e-6);
    {   /* the table agrees with the formula at every code */
        int k, bad = 0;
        for (k = 0; k < 256; ++k)
            if (fabs(appm__srgb8[k] - appm__srgb_linear(k / 255.0)) > 1e-7) bad++;
        CHECK(bad == 0);
    }
}

/* A plane under a constant white environment reflects albedo x 1: each pixel
 * of the rendered square is Kd times the texel under it.  The path tracer's
 * cosine-sampled shadow rays make each sample exactly the albedo. */
static void test_textured_plane(void)
{
    char tex[256];
    float rgb[4 * 4 * 3]; /* 4 x 4 texels of distinct colours */
    appm_scene *s;
    appm_image img;
    int k, worst_k = -1;
    double worst = 0.0;
    tpath(tex, "kd.pfm");
    for (k = 0; k < 16; ++k) {
        rgb[3 * k] = 0.1f + 0.05f * (float)k;
        rgb[3 * k + 1] = 0.9f - 0.05f * (float)k;
        rgb[3 * k + 2] = (k & 1) ? 0.7f : 0.2f;
    }
    CHECK(write_pfm(tex, 4, 4, rgb));
    if (!(s = load_plane("plane", "newmtl m\nKd 0.5 1 1\nmap_Kd texture-kd.pfm\n"))) return;
    CHECK(s->ntex == 1 && s->uv != NULL);
    render_texture(s, APPM_METHOD_PT, 16, &img);
    if (img.rgb) {
        for (k = 0; k < 16; ++k) { /* a pixel near the centre of texel k: 8 x 8 pixels a texel */
            uint32_t x = (uint32_t)(k % 4) * 8 + 4, y = (uint32_t)(k / 4) * 8 + 4, c;
            double want[3] = {0, 0, 0};
            int i, j;
            for (j = 0; j < 8; ++j) /* the pixel's mean of the bilinear texture: its samples' expectation */
                for (i = 0; i < 8; ++i) {
                    appm__v3 t = appm__tex_rgb(&s->tex[0], ((float)x + (i + 0.5f) / 8.0f) / 32.0f,
                                               1.0f - ((float)y + (j + 0.5f) / 8.0f) / 32.0f);
                    want[0] += 0.5 * t.x / 64.0;
                    want[1] += t.y / 64.0;
                    want[2] += t.z / 64.0;
                }
            for (c = 0; c < 3; ++c) {
                double e = fabs(px(&img, x, y)[c] - want[c]);
                if (e > worst) worst = e, worst_k = k;
            }
        }
        CHECK_MSG(worst < 2e-3, "textured plane: worst |pixel - Kd texel| %g at texel %d", worst, worst_k);
        free(img.rgb);
    }
    appm_scene_destroy(s);
}

/* map_d: where the mask is 0 the plane is not there.  A camera ray through the
 * hole sees the environment (1), one on the solid half sees albedo 0.5; the
 * closest-hit and the any-hit (shadow) searches both pass the hole and stop
 * on the solid half. */
static void test_cutout(void)
{
    char mask[256];
    float rgb[2 * 1 * 3] = {0, 0, 0, 1, 1, 1}; /* left half a hole, right half solid */
    appm_scene *s;
    appm_image img;
    tpath(mask, "mask.pfm");
    CHECK(write_pfm(mask, 2, 1, rgb));
    if (!(s = load_plane("cut", "newmtl m\nKd 0.5 0.5 0.5\nmap_d texture-mask.pfm\n"))) return;
    CHECK(s->cutouts);
    render_texture(s, APPM_METHOD_PT, 2, &img);
    if (img.rgb) {
        /* the mask is bilinear between texel centres u = 1/4 (0) and 3/4 (1): the edge at u = 1/2 */
        CHECK_NEAR(px(&img, 4, 16)[0], 1.0, 1e-6);  /* u = 0.14: hole, the environment behind */
        CHECK_NEAR(px(&img, 27, 16)[1], 0.5, 2e-3); /* u = 0.86: solid */
        CHECK_NEAR(px(&img, 14, 16)[0], 1.0, 1e-6); /* u = 0.45: hole */
        CHECK_NEAR(px(&img, 17, 16)[0], 0.5, 2e-3); /* u = 0.55: solid */
        free(img.rgb);
    }
    {   /* rays: through the hole nothing is hit; the solid half occludes */
        appm__ray r;
        appm__hit h;
        appm__ray_init(&r, appm__v(0.2f, 0.5f, 1.0f), appm__v(0, 0, -1), FLT_MAX);
        CHECK(!appm__intersect(s, &r, UINT32_MAX, &h));
        CHECK(!appm__occluded(s, &r, UINT32_MAX, UINT32_MAX));
        appm__ray_init(&r, appm__v(0.8f, 0.5f, 1.0f), appm__v(0, 0, -1), FLT_MAX);
        CHECK(appm__intersect(s, &r, UINT32_MAX, &h) && fabsf(h.t - 1.0f) < 1e-5f);
        CHECK(appm__occluded(s, &r, UINT32_MAX, UINT32_MAX));
    }
    appm_scene_destroy(s);
}

/* Howell's view factor from a point to a parallel rectangle a x b at distance
 * 1 whose corner lies above it (catalogue B-3). */
static double corner_view_factor(double a, double b)
{
    const double pa = sqrt(1.0 + a * a), pb = sqrt(1.0 + b * b);
    return (a / pa * atan(b / pa) + b / pb * atan(a / pb)) / (2.0 * APPM__PI);
}

/* An emitting unit square at z = 1, facing down (Le = 1), whose map_d cuts
 * away its half u < 1/2, over a floor at z = 0.  Light samples and photon
 * starts that land in the hole carry nothing; what they carry on average is
 * what the solid half [1/2, 1] x [0, 1] emits:
 *   - next-event estimates of the irradiance at (3/4, 1/2, 0): pi Le times the
 *     view factor of the solid half, four rectangles 1/4 x 1/2 with a corner
 *     above the point (the uncut square would give 1.7 times as much);
 *   - the photon weight over light picks and emission samples: the power of
 *     the solid half, pi A Le = pi / 2 (the uncut square: pi);
 *   - the power by which lights are picked is that of the solid half: the
 *     diagonal splits the square into triangles whose solid shares are 3/4
 *     and 1/4, so they are picked 3/4 and 1/4 of the time, and 3/8 of the
 *     samples land in a hole (1/2 if lights were picked by their whole area).
 * Stratified samples: 64 light picks x 64 x 64 points. */
static void test_cut_emitter(void)
{
    char mask[256], mtl[256], obj[256], scn[256];
    float rgb[2 * 1 * 3] = {0, 0, 0, 1, 1, 1};
    appm_scene *s = NULL;
    appm_diag d;
    appm__ray ray;
    appm__hit h;
    appm__surf sf;
    double e_sum = 0.0, g_sum = 0.0, want_e = APPM__PI * 4.0 * corner_view_factor(0.25, 0.5);
    long n = 0, e_zero = 0, g_zero = 0;
    unsigned pick, i, j;
    const unsigned K = 64;
    tpath(mask, "emask.pfm");
    tpath(mtl, "lamp.mtl");
    tpath(obj, "lamp.obj");
    tpath(scn, "lamp.scene");
    CHECK(write_pfm(mask, 2, 1, rgb));
    CHECK(check_write_file(mtl, "newmtl lamp\nKd 0 0 0\nKe 1 1 1\nmap_d texture-emask.pfm\n"
                                "newmtl floor\nKd 0.5 0.5 0.5\n"));
    CHECK(check_write_file(obj, "mtllib texture-lamp.mtl\nv 0 0 1\nv 1 0 1\nv 1 1 1\nv 0 1 1\n"
                                "vt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nusemtl lamp\n"
                                "f 1/1 3/3 2/2\nf 1/1 4/4 3/3\nusemtl floor\n"
                                "v -2 -2 0\nv 3 -2 0\nv 3 3 0\nv -2 3 0\nf 5 6 7\nf 5 7 8\n"));
    CHECK(check_write_file(scn, "camera eye 0.5 0.5 0.5 target 0.5 0.5 0 fov 60\nimage 8 8\n"
                                "mesh texture-lamp.obj\n"));
    CHECK_MSG(appm_scene_load(scn, NULL, &s, &d) == APPM_OK, "%s", d.message);
    if (!s) return;
    CHECK(s->cutouts && s->nlight == 2);
    /* the lights are picked by the power of their solid parts (a 16 x 16 count: 1/16 of a triangle
     * at most in error); uncut, pi */
    CHECK_MSG(fabs(s->light[0].power[1] + s->light[1].power[1] - 0.5 * APPM__PI) < 0.05,
              "cut emitter: power %.4f + %.4f, the solid half's %.4f", s->light[0].power[1],
              s->light[1].power[1], 0.5 * APPM__PI);
    appm__ray_init(&ray, appm__v(0.75f, 0.5f, 0.5f), appm__v(0, 0, -1), FLT_MAX);
    CHECK(appm__intersect(s, &ray, UINT32_MAX, &h));
    appm__surface(s, &h, &sf);
    for (pick = 0; pick < K; ++pick)
        for (j = 0; j < K; ++j)
            for (i = 0; i < K; ++i) {
                const float u0 = ((float)pick + 0.5f) / (float)K, u1 = ((float)i + 0.5f) / (float)K,
                            u2 = ((float)j + 0.5f) / (float)K;
                const float ue[5] = {u0, u1, u2, 0.3f, 0.6f};
                appm__light_sample ls;
                appm__photon_start ps;
                if (appm__sample_light(s, 0, &sf, appm__v(0, 0, 1), u0, u1, u2, &ls))
                    e_sum += (double)ls.li.x * ls.wi.z;
                else
                    e_zero++;
                if (appm__emit(s, ue, &ps)) g_sum += ps.gamma.y;
                else g_zero++;
                n++;
            }
    CHECK_MSG(fabs(e_sum / (double)n / want_e - 1.0) < 5e-3, "cut emitter: irradiance %.6f, the solid half's %.6f",
              e_sum / (double)n, want_e);
    CHECK_MSG(fabs(g_sum / (double)n / (0.5 * APPM__PI) - 1.0) < 5e-3,
              "cut emitter: mean photon weight %.6f, the solid half's power %.6f", g_sum / (double)n,
              0.5 * APPM__PI);
    CHECK_MSG(labs(8 * e_zero - 3 * n) < n / 25 && labs(8 * g_zero - 3 * n) < n / 25,
              "cut emitter: %ld and %ld of %ld samples in the hole, not 3/8", e_zero, g_zero, n);
    appm_scene_destroy(s);
}

/* An appm__envmap built from w x h linear RGB floats px (taken: freed by the
 * build), as the loader hands a decoded map over; 1 on success. */
static int take_env(appm__mem *m, appm__envmap *e, float *px, uint32_t w, uint32_t h, double rotate)
{
    appm__envmap from;
    appm_diag d;
    memset(&from, 0, sizeof from);
    from.px.w = w;
    from.px.h = h;
    from.px.channels = 3;
    from.px.depth = 32;
    from.px.data = px;
    from.scale = 1.0;
    from.rotate = rotate;
    appm__diag_clear(&d);
    return appm__envmap_take(m, e, &from, "env", &d) == APPM_OK;
}

/* An environment map of w x h texels with a bright texel at (sx, sy) on a
 * dim background, decoded straight into a scene-less appm__envmap. */
static int make_env(appm__mem *m, appm__envmap *e, uint32_t w, uint32_t h, uint32_t sx, uint32_t sy,
                    double rotate)
{
    float *f = (float *)appm__alloc(m, (size_t)w * h, 3 * sizeof(float));
    uint32_t x, y;
    if (!f) return 0;
    for (y = 0; y < h; ++y)
        for (x = 0; x < w; ++x) {
            float v = (x == sx && y == sy) ? 500.0f : 0.2f + 0.6f * (float)y / (float)h + 0.1f * (float)(x % 3);
            f[3 * ((size_t)y * w + x)] = v;
            f[3 * ((size_t)y * w + x) + 1] = 0.5f * v;
            f[3 * ((size_t)y * w + x) + 2] = 0.25f * v;
        }
    return take_env(m, e, f, w, h, rotate);
}

/* The environment's sampling density on small maps (1..5 x 1..5 texels, where
 * the wrap in x and the clipped poles meet): the CDFs appm__env_build makes
 * (from the separable 3 x 3 maximum in a ring of rows) equal, bit for bit,
 * those of the 9-texel definition computed here, on maps with ties, zeros
 * and one bright texel. */
static void test_env_small_maps(void)
{
    appm__mem m;
    uint32_t w, h, x, y, seed = 12345u;
    int trial, bad = 0, built = 0;
    appm__mem_init(&m, NULL);
    for (h = 1; h <= 5; ++h)
        for (w = 1; w <= 5; ++w)
            for (trial = 0; trial < 8; ++trial) {
                size_t n = (size_t)w * h, i;
                float *px = (float *)appm__alloc(&m, n, 3 * sizeof(float)), f[25];
                double want[6 + 5 * 6], total;
                appm__envmap e;
                if (!px) return;
                for (i = 0; i < 3 * n; ++i) { /* levels 0, 0.25, 0.5, 0.75: ties and zeros */
                    seed = seed * 1664525u + 1013904223u;
                    px[i] = 0.25f * (float)(seed >> 30);
                }
                px[3 * (size_t)(seed % n) + 1] = 40.0f;
                if (!take_env(&m, &e, px, w, h, 0.0)) {
                    bad++;
                    continue;
                }
                built++;
                for (y = 0; y < h; ++y) /* the definition: the largest mean over the 3 x 3 texels */
                    for (x = 0; x < w; ++x) {
                        float best = 0.0f;
                        int dy, dx;
                        for (dy = -1; dy <= 1; ++dy)
                            for (dx = -1; dx <= 1; ++dx) {
                                int yy = (int)y + dy, xx = ((int)x + dx + (int)w) % (int)w;
                                const float *t;
                                if (yy < 0 || yy >= (int)h) continue;
                                t = e.rgb + 3 * ((size_t)yy * w + (size_t)xx);
                                if ((t[0] + t[1] + t[2]) / 3.0f > best) best = (t[0] + t[1] + t[2]) / 3.0f;
                            }
                        f[y * w + x] = best;
                    }
                want[0] = 0.0; /* rows, then a column CDF a row, as appm__env_build lays them out */
                for (y = 0; y < h; ++y) {
                    double st = sin(APPM__PI * (y + 0.5) / h), *cr = want + h + 1 + (size_t)y * (w + 1), sum;
                    cr[0] = 0.0;
                    for (x = 0; x < w; ++x) cr[x + 1] = cr[x] + (double)f[y * w + x];
                    sum = cr[w];
                    for (x = 1; x <= w; ++x) cr[x] = sum > 0.0 ? cr[x] / sum : (double)x / w;
                    cr[w] = 1.0;
                    want[y + 1] = want[y] + sum * st;
                }
                total = want[h];
                for (y = 1; y <= h; ++y) want[y] /= total;
                want[h] = 1.0;
                bad += memcmp(want, e.cdf, (h + 1 + (size_t)h * (w + 1)) * sizeof(double)) != 0;
                appm__envmap_free(&m, &e);
            }
    CHECK_MSG(bad == 0 && built == 200, "small environment maps: %d of %d sampling tables differ from the "
              "9-texel definition", bad, built);
    CHECK(m.live == 0);
}

/* appm__cdf_invert (which the map's rows and columns are drawn by) against a
 * scan: the cell is the last i < n with c[i] <= u, also where cells have zero
 * probability (equal neighbours, which a scan skips to the last of) and where
 * u is exactly a cell's start; the point is (i + t) / n within it.  The guided
 * inversion gives the same cell and the same bits of the point, also at the
 * guide's own steps k / APPM__CDF_G and just below them. */
static void test_cdf_invert(void)
{
    static double c[130];
    uint32_t g[APPM__CDF_G + 1];
    unsigned seed = 7, bad = 0, cases = 0, differ = 0;
    int n, trial, k;
    for (n = 1; n <= 129; n += (n < 9 ? 1 : 15))
        for (trial = 0; trial < 20; ++trial) {
            c[0] = 0.0;
            for (k = 1; k <= n; ++k) {
                seed = seed * 1103515245u + 12345u;
                c[k] = c[k - 1] + ((seed >> 16) % 4 == 0 ? 0.0 : (double)((seed >> 8) % 1000 + 1)); /* some empty */
            }
            if (!(c[n] > 0.0)) c[n] = 1.0;
            for (k = 1; k <= n; ++k) c[k] /= c[n];
            appm__cdf_guide(c, n, g);
            for (k = 0; k < 64 + 2 * APPM__CDF_G; ++k) {
                float u, x, xg;
                int cell, cg, want = 0, i;
                seed = seed * 1103515245u + 12345u;
                if (k >= 64) /* the guide's steps, and the float just below each */
                    u = (k - 64) % 2 ? nextafterf((float)((k - 64) / 2 + 1) / APPM__CDF_G, 0.0f)
                                     : (float)((k - 64) / 2) / APPM__CDF_G;
                else
                    u = k < n ? (float)c[k] : (float)((seed >> 8) & 0xFFFF) / 65536.0f; /* starts, then anywhere */
                if (!(u < 1.0f)) continue;
                for (i = 0; i < n; ++i)
                    if (c[i] <= (double)u) want = i;
                x = appm__cdf_invert(c, n, u, &cell);
                xg = appm__cdf_invert_guided(c, n, g, u, &cg);
                cases++;
                if (cell != want || !(x >= (double)want / n - 1e-6 && x <= (double)(want + 1) / n + 1e-6)) bad++;
                if (cg != cell || memcmp(&xg, &x, sizeof x) != 0) differ++;
            }
        }
    CHECK_MSG(bad == 0 && cases > 5000, "%u of %u inversions off the scan's cell", bad, cases);
    CHECK_MSG(differ == 0, "%u of %u guided inversions differ from the whole search", differ, cases);
}

/* The guide tables where the map keeps them (appm__env_grid_guide's layout:
 * the rows' table, then each row's): the map's own grid and every product
 * bin's give the same place and cell with their guides as without, over a
 * 256 x 256 grid of (u1, u2) and the guides' steps, on a map with a small sun
 * (the rows' and a row's CDF a step) and rotated. */
static void test_env_guides(void)
{
    appm__mem m;
    appm__envmap e;
    unsigned differ = 0, cases = 0, b;
    int i, k;
    appm__mem_init(&m, NULL);
    if (!make_env(&m, &e, 96, 48, 70, 9, 33.0)) {
        CHECK(0);
        return;
    }
    CHECK(e.guide && e.pguide);
    for (b = 0; b <= APPM__ENV_BINS; ++b) { /* bin APPM__ENV_BINS: the map's own grid */
        const int own = b == APPM__ENV_BINS;
        const uint32_t w = own ? e.w : e.pw, h = own ? e.h : e.ph;
        const double *c = own ? e.cdf : appm__env_prod_cdf(&e, b);
        const uint32_t *g = own ? e.guide : appm__env_prod_guide(&e, b);
        if (!own && !e.pok[b]) continue;
        for (i = 0; i < 256 + APPM__CDF_G; ++i)
            for (k = 0; k < 256 + APPM__CDF_G; ++k) {
                float u1 = i < 256 ? (i + 0.5f) / 256.0f : (float)(i - 256) / APPM__CDF_G;
                float u2 = k < 256 ? (k * 0.618034f) - (float)floor(k * 0.618034f) : (float)(k - 256) / APPM__CDF_G;
                float u[2], v[2];
                int x[2], y[2];
                appm__env_grid_invert(c, g, w, h, u1, u2, &u[0], &v[0], &x[0], &y[0]);
                appm__env_grid_invert(c, NULL, w, h, u1, u2, &u[1], &v[1], &x[1], &y[1]);
                cases++;
                differ += x[0] != x[1] || y[0] != y[1] || memcmp(&u[0], &u[1], sizeof u[0]) != 0 ||
                          memcmp(&v[0], &v[1], sizeof v[0]) != 0;
            }
    }
    CHECK_MSG(differ == 0 && cases > 1000000, "%u of %u draws differ with the guides", differ, cases);
    appm__envmap_free(&m, &e);
    CHECK(m.live == 0);
}

/* Whether pl, the place a sampler returns, is (u, v) = appm__env_uv of the
 * direction it returns, to float rounding (u wraps around at 1; at the poles u
 * is any), with st = sin(pi v) to the bit. */
static int same_place(double u, double v, const appm__env_place *pl)
{
    double w = fabs(u - pl->u);
    w = w > 0.5 ? 1.0 - w : w;
    return fabs(v - pl->v) < 1e-5 && (w < 1e-5 || pl->v < 1e-4 || pl->v > 1.0 - 1e-4) &&
           pl->st == sin(CHECK_PI * pl->v);
}

/* On a map turned by 33 degrees the place each draw returns (the map's own,
 * unturned (u, v)) is still its direction's, and the radiance read there is
 * the direction's: the map's draws and those of three product bins. */
static void test_env_place_rotated(void)
{
    appm__mem m;
    appm__envmap e;
    const uint32_t N = 100000;
    uint32_t i, b, misplaced = 0, off = 0, drawn = 0;
    appm__mem_init(&m, NULL);
    if (!make_env(&m, &e, 32, 16, 23, 5, 33.0)) {
        CHECK(0);
        return;
    }
    for (b = 0; b < 4; ++b) /* b 0: the map; then bins 0, the middle one and the last */
        for (i = 0; i < N; ++i) {
            appm__v3 d, L, Ld;
            double u, v;
            appm__env_place pl;
            uint32_t bin = b == 1 ? 0 : (b == 2 ? (APPM__ENV_BINS - 1) / 2 : APPM__ENV_BINS - 1);
            float u1 = (float)((i + 0.5) / N), u2 = (float)vdc(i);
            if (b == 0) {
                if (!(appm__env_sample(&e, u1, u2, &d, &pl) > 0.0f)) continue;
            } else {
                if (!e.pok[bin]) continue;
                appm__env_prod_sample(&e, bin, u1, u2, &d, &pl);
            }
            appm__env_uv(&e, d, &u, &v);
            drawn++;
            misplaced += !same_place(u, v, &pl);
            L = appm__env_lookup_uv(&e, pl.u, pl.v);
            Ld = appm__env_lookup(&e, d);
            off += fabsf(L.x - Ld.x) > 1e-3f * (Ld.x + 1e-3f);
        }
    CHECK_MSG(drawn > 3 * N && misplaced == 0 && off == 0,
              "turned map: of %u draws %u places not their direction's, %u radiances off", drawn, misplaced, off);
    appm__envmap_free(&m, &e);
    CHECK(m.live == 0);
}

/* The sampler draws directions with the density appm__env_pdf says (chi-square
 * over the texels), the density it returns is that density and the place in
 * the map it returns is the direction's, and the density integrates to 1 over
 * the sphere. */
static void test_env_sampler(void)
{
    appm__mem m;
    appm__envmap e;
    const uint32_t W = 16, H = 8, N = check_quick() ? 200000 : 1000000;
    double *count, chi2 = 0.0, integral = 0.0, expect_sum = 0.0;
    uint32_t i, x, y, mismatch = 0, misplaced = 0;
    int dof = 0;
    appm__mem_init(&m, NULL);
    CHECK(make_env(&m, &e, W, H, 11, 2, 0.0));
    count = (double *)calloc((size_t)W * H, sizeof(double));
    if (!count) return;
    for (i = 0; i < N; ++i) {
        appm__v3 d;
        float u1 = (float)((i + 0.5) / N), u2 = (float)vdc(i), p;
        double u, v;
        appm__env_place pl;
        p = appm__env_sample(&e, u1, u2, &d, &pl);
        if (!(p > 0.0f)) continue;
        if (fabsf(appm__env_pdf(&e, d) - p) > 1e-3f * p) mismatch++;
        appm__env_uv(&e, d, &u, &v);
        if (!same_place(u, v, &pl)) misplaced++;
        x = (uint32_t)(u * W);
        y = (uint32_t)(v * H);
        if (x >= W) x = W - 1;
        if (y >= H) y = H - 1;
        count[(size_t)y * W + x] += 1.0;
    }
    CHECK_MSG(mismatch == 0, "%u samples whose returned density is not appm__env_pdf's", mismatch);
    CHECK_MSG(misplaced == 0, "%u samples whose returned place is not their direction's", misplaced);
    for (y = 0; y < H; ++y)
        for (x = 0; x < W; ++x) { /* expected count: the texel's probability, N (cdf steps) */
            const double *cr = e.cdf + (H + 1) + (size_t)y * (W + 1);
            double pr = (e.cdf[y + 1] - e.cdf[y]) * (cr[x + 1] - cr[x]) * N, o = count[(size_t)y * W + x];
            expect_sum += pr;
            if (pr < 5.0) continue;
            chi2 += (o - pr) * (o - pr) / pr;
            dof++;
        }
    /* a stratified u1 makes the counts closer than random ones: chi2 well below dof is fine */
    CHECK_MSG(chi2 < dof + 4.0 * sqrt(2.0 * dof), "chi2 %g with %d degrees of freedom", chi2, dof);
    CHECK_NEAR(expect_sum, N, 1e-6 * N);
    /* quadrature: the density integrates to 1 over the sphere */
    for (y = 0; y < 400; ++y)
        for (x = 0; x < 800; ++x) {
            double th = CHECK_PI * (y + 0.5) / 400, ph = 2 * CHECK_PI * (x + 0.5) / 800;
            appm__v3 d = appm__v((float)(sin(th) * sin(ph)), (float)cos(th), (float)(-sin(th) * cos(ph)));
            integral += appm__env_pdf(&e, d) * sin(th) * (CHECK_PI / 400) * (2 * CHECK_PI / 800);
        }
    CHECK_NEAR(integral, 1.0, 2e-3);
    free(count);
    appm__envmap_free(&m, &e);
    CHECK(m.live == 0);
}

/* The product densities of shadow rays (appm.c 6.2).  Each bin's centre
 * normal falls in its own bin; on a 300 x 150 map (coarse cells of 2-3 texels)
 * every bin's density integrates to 1 over the sphere (quadrature) and the
 * centre bin's draws what it says (chi-square over its cells). */
static void test_env_product(void)
{
    appm__mem m;
    appm__envmap e;
    const uint32_t N = check_quick() ? 200000 : 1000000;
    uint32_t b, i, x, y, bad_bin = 0, stray = 0, misplaced = 0;
    double *count, chi2 = 0.0;
    int dof = 0;
    appm__mem_init(&m, NULL);
    for (b = 0; b < APPM__ENV_BINS; ++b) bad_bin += appm__env_bin(appm__env_bin_normal(b)) != b;
    CHECK_MSG(bad_bin == 0, "%u bins whose centre normal lies in another bin", bad_bin);
    CHECK(appm__env_bin_normal((APPM__ENV_BINS - 1) / 2).y == 1.0f); /* a flat ground's normal: a centre */
    if (!make_env(&m, &e, 300, 150, 40, 30, 0.0)) return;
    CHECK(e.pw == APPM__ENV_PW && e.ph == APPM__ENV_PH);
    for (b = 0; b < APPM__ENV_BINS; b += 6) {
        double integral = 0.0;
        CHECK(e.pok[b]);
        for (y = 0; y < 5 * APPM__ENV_PH; ++y) /* 5 x 5 points a cell: the sum is exact to rounding */
            for (x = 0; x < 5 * APPM__ENV_PW; ++x) {
                double th = CHECK_PI * (y + 0.5) / (5 * APPM__ENV_PH), ph = 2 * CHECK_PI * (x + 0.5) / (5 * APPM__ENV_PW);
                appm__env_place pl;
                appm__v3 d = appm__v((float)(sin(th) * sin(ph)), (float)cos(th), (float)(-sin(th) * cos(ph)));
                appm__env_place_of(&e, d, &pl);
                integral += appm__env_prod_pdf_at(&e, b, &pl) * sin(th) *
                            (CHECK_PI / (5 * APPM__ENV_PH)) * (2 * CHECK_PI / (5 * APPM__ENV_PW));
            }
        CHECK_MSG(fabs(integral - 1.0) < 1e-3, "bin %u: its density integrates to %.5f", b, integral);
    }
    count = (double *)calloc((size_t)e.pw * e.ph, sizeof(double));
    if (!count) return;
    b = (APPM__ENV_BINS - 1) / 2;
    for (i = 0; i < N; ++i) {
        appm__v3 d;
        double u, v;
        appm__env_place pl;
        appm__env_prod_sample(&e, b, (float)((i + 0.5) / N), (float)vdc(i), &d, &pl);
        appm__env_uv(&e, d, &u, &v);
        if (!same_place(u, v, &pl)) misplaced++;
        x = (uint32_t)(u * e.pw);
        y = (uint32_t)(v * e.ph);
        count[(size_t)(y < e.ph ? y : e.ph - 1) * e.pw + (x < e.pw ? x : e.pw - 1)] += 1.0;
    }
    for (y = 0; y < e.ph; ++y)
        for (x = 0; x < e.pw; ++x) {
            const double *c = appm__env_prod_cdf(&e, b), *cr = c + (e.ph + 1) + (size_t)y * (e.pw + 1);
            double pr = (c[y + 1] - c[y]) * (cr[x + 1] - cr[x]) * N, o = count[(size_t)y * e.pw + x];
            if (pr == 0.0 && o > 0.0) stray++; /* below the centre normal's horizon: never drawn */
            if (pr < 5.0) continue;
            chi2 += (o - pr) * (o - pr) / pr;
            dof++;
        }
    CHECK_MSG(dof > 1000 && chi2 < dof + 4.0 * sqrt(2.0 * dof), "chi2 %g with %d degrees of freedom", chi2, dof);
    CHECK_MSG(stray == 0, "%u cells of density 0 drawn", stray);
    CHECK_MSG(misplaced == 0, "%u draws whose returned place is not their direction's", misplaced);
    free(count);
    appm__envmap_free(&m, &e);
    CHECK(m.live == 0);
}

/* A W x H sky map of grey values grey[] (row 0 at the top) over a floor, as
 * tests/out/texture-NAME.{pfm,scene} and texture-NAME-floor.obj, loaded, and
 * the floor's surface at (0.1, 0, 0.2) in *sf (NULL on failure). */
static appm_scene *load_sky(const char *name, uint32_t W, uint32_t H, const float *grey, appm__surf *sf)
{
    char map[256], scn[256], obj[256], text[256];
    float *px = (float *)malloc((size_t)W * H * 3 * sizeof(float));
    appm_scene *s = NULL;
    appm_diag d;
    appm__ray ray;
    appm__hit h;
    size_t i;
    if (!px) return NULL;
    for (i = 0; i < (size_t)W * H; ++i) px[3 * i] = px[3 * i + 1] = px[3 * i + 2] = grey[i];
    tpath2(map, name, ".pfm");
    tpath2(obj, name, "-floor.obj");
    tpath2(scn, name, ".scene");
    CHECK(write_pfm(map, W, H, px));
    free(px);
    CHECK(check_write_file(obj, "v -1 0 -1\nv 1 0 -1\nv 1 0 1\nv -1 0 1\nf 1 3 2\nf 1 4 3\n"));
    snprintf(text, sizeof text, "mesh texture-%s-floor.obj\nenvironment map texture-%s.pfm\n", name, name);
    CHECK(check_write_file(scn, text));
    CHECK_MSG(appm_scene_load(scn, NULL, &s, &d) == APPM_OK, "%s", d.message);
    if (!s) return NULL;
    appm__ray_init(&ray, appm__v(0.1f, 1.0f, 0.2f), appm__v(0, -1, 0), FLT_MAX);
    CHECK(appm__intersect(s, &ray, UINT32_MAX, &h));
    appm__surface(s, &h, sf);
    return s;
}

/* The irradiance of the scene's map at normal n by the midpoint rule on a
 * grid of `rows` x 2 `rows` points over the sphere. */
static double sky_quadrature(const appm_scene *s, appm__v3 n, uint32_t rows)
{
    double sum = 0.0;
    uint32_t x, y;
    for (y = 0; y < rows; ++y)
        for (x = 0; x < 2 * rows; ++x) {
            double th = CHECK_PI * (y + 0.5) / rows, ph = CHECK_PI * (x + 0.5) / rows, c;
            appm__v3 w = appm__v((float)(sin(th) * sin(ph)), (float)cos(th), (float)(-sin(th) * cos(ph)));
            c = appm__dot(n, w);
            if (c > 0.0) sum += appm__env_lookup(&s->envmap, w).x * c * sin(th) * (CHECK_PI / rows) * (CHECK_PI / rows);
        }
    return sum;
}

/* K x K stratified shadow-ray draws at surface sf with normal n: the mean of
 * their irradiance estimates, and in *spread (if not NULL) the relative spread
 * of one draw about it. */
static double sky_draws(const appm_scene *s, const appm__surf *sf, appm__v3 n, uint32_t K, double *spread)
{
    double sum = 0.0, sum2 = 0.0, mean;
    uint32_t i, j;
    for (j = 0; j < K; ++j)
        for (i = 0; i < K; ++i) {
            appm__light_sample ls;
            double v = 0.0;
            if (appm__sample_light(s, 0, sf, n, 0.5f, ((float)i + 0.5f) / (float)K, ((float)j + 0.5f) / (float)K, &ls))
                v = (double)ls.li.x * appm__dot(ls.wi, n);
            sum += v;
            sum2 += v * v;
        }
    mean = sum / ((double)K * K);
    if (spread) *spread = sqrt(fmax(sum2 / ((double)K * K) - mean * mean, 0.0)) / mean;
    return mean;
}

/* A shadow ray's estimate of the irradiance from a map, E(n) = integral of
 * L(w) max(0, n.w), through appm__sample_light's mixture (map, cosine and the
 * product density of n's bin), matches a quadrature within 1 % for normals at
 * a bin's centre and off it, up and down, under a sky brighter above with a
 * small bright patch (visibility aside: the samples are not traced).  Twice:
 * a W x H = 96 x 48 map, which the product densities hold texel for texel
 * (the map's share of the mixture 1/8), and a 288 x 144 one, finer than they
 * are (3/8); the patch covers the same solid angle in both. */
static void test_env_irradiance_at(uint32_t W, uint32_t H, double mix_map)
{
    static const float nrm[5][3] = {{0, 1, 0}, {0.3f, 0.9f, 0.2f}, {1, 0, 0}, {-0.2f, -0.7f, 0.5f}, {0, -1, 0}};
    const uint32_t K = check_quick() ? 160 : 400, f = W / 96;
    float *grey = (float *)malloc((size_t)W * H * sizeof(float));
    appm_scene *s;
    appm__surf sf;
    uint32_t x, y, k;
    if (!grey) return;
    for (y = 0; y < H; ++y)
        for (x = 0; x < W; ++x) {
            float v = y < H / 2 ? 1.0f - 0.8f * (float)y / (float)H : 0.15f;
            if (x >= 60 * f && x < 63 * f && y >= 10 * f && y < 13 * f) v = 60.0f; /* 3 x 3 texels at 96 x 48 */
            grey[(size_t)y * W + x] = v;
        }
    s = load_sky("sky", W, H, grey, &sf);
    free(grey);
    if (!s) return;
    CHECK_MSG(s->envmap.mix_map == mix_map, "%ux%u: the map's share %g, want %g", W, H, s->envmap.mix_map, mix_map);
    for (k = 0; k < 5; ++k) {
        const appm__v3 n = appm__normalize(appm__v(nrm[k][0], nrm[k][1], nrm[k][2]));
        double want = sky_quadrature(s, n, 240 * f), est = sky_draws(s, &sf, n, K, NULL); /* 5 x 5 points a texel */
        CHECK_MSG(fabs(est / want - 1.0) < 0.01, "%ux%u, normal %u: irradiance %.5f, the quadrature's %.5f", W, H, k,
                  est, want);
    }
    appm_scene_destroy(s);
}

static void test_env_irradiance(void)
{
    test_env_irradiance_at(96, 48, 0.125);
    test_env_irradiance_at(288, 144, 0.375);
}

/* A sun of one texel in a sky of at most APPM__ENV_PW x APPM__ENV_PH texels,
 * whose product densities hold every texel (the map's share 1/8): the
 * bilinear L of a bright texel spills 44 % of its light into its neighbours'
 * cells, which the product density must hold too (appm__env_texel_lerp_mean).
 * Built from the texels alone it left that light to the map's 1/8 share, and
 * one shadow ray's relative spread read 1.9-2.3 (docs/algorithm.md 5.9).  The
 * irradiance of K x K stratified draws against the quadrature, and the spread
 * of one draw about it. */
static void test_env_sun_spread_at(float sun, double mix_map, double bound)
{
    static const float nrm[3][3] = {{0, 1, 0}, {0.3f, 0.9f, 0.2f}, {-0.5f, 0.8f, 0.1f}};
    const uint32_t W = 128, H = 64, K = 256;
    float *grey = (float *)malloc((size_t)W * H * sizeof(float));
    appm_scene *s;
    appm__surf sf;
    uint32_t x, y, k;
    if (!grey) return;
    for (y = 0; y < H; ++y)
        for (x = 0; x < W; ++x) grey[(size_t)y * W + x] = x == 40 && y == 12 ? sun : (y < H / 2 ? 0.2f : 0.05f);
    s = load_sky("sun", W, H, grey, &sf);
    free(grey);
    if (!s) return;
    CHECK_MSG(s->envmap.mix_map == mix_map, "sun %g: the map's share %g, want %g", sun, s->envmap.mix_map, mix_map);
    for (k = 0; k < 3; ++k) {
        const appm__v3 n = appm__normalize(appm__v(nrm[k][0], nrm[k][1], nrm[k][2]));
        double spread, want = sky_quadrature(s, n, 4 * H), mean = sky_draws(s, &sf, n, K, &spread); /* 4 x 4 a texel */
        CHECK_MSG(fabs(mean / want - 1.0) < 0.01, "sun %g, normal %u: irradiance %.5f, the quadrature's %.5f", sun, k,
                  mean, want);
        CHECK_MSG(spread < bound, "sun %g, normal %u: one shadow ray's relative spread %.3f", sun, k, spread);
        printf("sun of one texel %g, normal %u: irradiance %.4f (quadrature %.4f), one ray's spread %.3f\n", sun, k,
               mean, want, spread);
    }
    appm_scene_destroy(s);
}

static void test_env_sun_spread(void)
{
    test_env_sun_spread_at(400.0f, APPM__ENV_MIX_MAP_FULL, 0.85);
    test_env_sun_spread_at(2000.0f, APPM__ENV_MIX_MAP, 1.0);
}

/* The contract's orientation: row 0 is +y, column 0 looks along -z, columns
 * advance towards +x; rotate 90 turns column 0 to +x. */
static void test_env_orientation(void)
{
    appm__mem m;
    appm__envmap e;
    appm__v3 L;
    appm__mem_init(&m, NULL);
    /* bright texel in the middle row (the horizon), column 0 */
    CHECK(make_env(&m, &e, 16, 9, 0, 4, 0.0));
    L = appm__env_lookup(&e, appm__env_dir(&e, 0.5 / 16, 4.5 / 9));
    CHECK_NEAR(L.x, 500.0, 1e-3);
    {
        appm__v3 d = appm__env_dir(&e, 0.5 / 16, 4.5 / 9);
        CHECK(d.z < -0.95f && fabsf(d.y) < 1e-6f);
    }
    CHECK(appm__env_dir(&e, 0.25, 0.5).x > 0.999f); /* a quarter of the way: +x */
    CHECK(appm__env_dir(&e, 0.3, 0.0).y > 0.999f);  /* row 0: the zenith */
    appm__envmap_free(&m, &e);
    CHECK(make_env(&m, &e, 16, 9, 0, 4, 90.0));
    L = appm__env_lookup(&e, appm__normalize(appm__v(1.0f, 0.0f, 0.19891237f))); /* 1/32 turn past +x */
    CHECK_NEAR(L.x, 500.0, 1e-2);
    L = appm__env_lookup(&e, appm__v(0, 0, -1));
    CHECK(L.x < 1.0f);
    appm__envmap_free(&m, &e);
}

/* A white sphere (Kd 1) under a white map (radiance 1 everywhere) is 1 in
 * every pixel, on average within 0.5 %: the map's density, the mixture with
 * the cosine and the photon weights all cancel. */
static void test_env_furnace(void)
{
    static const appm_method methods[3] = {APPM_METHOD_PT, APPM_METHOD_APPM, APPM_METHOD_PPM};
    char map[256], mtl[256], obj[256], scn[256];
    float *white = (float *)malloc(32 * 16 * 3 * sizeof(float));
    FILE *f;
    int i, j, n = 16, mi;
    appm_scene *s = NULL;
    appm_diag d;
    tpath(map, "white.pfm");
    tpath(mtl, "white.mtl");
    tpath(obj, "sphere.obj");
    tpath(scn, "furnace.scene");
    if (!white) return;
    for (i = 0; i < 32 * 16 * 3; ++i) white[i] = 1.0f;
    CHECK(write_pfm(map, 32, 16, white));
    free(white);
    CHECK(check_write_file(mtl, "newmtl w\nKd 1 1 1\n"));
    f = fopen(obj, "w");
    if (!f) return;
    fprintf(f, "mtllib texture-white.mtl\nusemtl w\n");
    for (i = 0; i <= n; ++i)
        for (j = 0; j < 2 * n; ++j) {
            double th = CHECK_PI * i / n, ph = CHECK_PI * j / n;
            fprintf(f, "v %.9f %.9f %.9f\n", sin(th) * cos(ph), cos(th), sin(th) * sin(ph));
        }
    for (i = 0; i < n; ++i)
        for (j = 0; j < 2 * n; ++j) {
            int a = i * 2 * n + j + 1, b = i * 2 * n + (j + 1) % (2 * n) + 1;
            if (i > 0) fprintf(f, "f %d %d %d\n", a, a + 2 * n, b);
            if (i < n - 1) fprintf(f, "f %d %d %d\n", b, a + 2 * n, b + 2 * n);
        }
    fclose(f);
    CHECK(check_write_file(scn, "camera eye 0 0 4 target 0 0 0 fov 40\nimage 48 48\nmesh texture-sphere.obj\n"
                                "environment map texture-white.pfm\n"));
    CHECK(appm_scene_load(scn, NULL, &s, &d) == APPM_OK);
    if (!s) return;
    CHECK(s->envmap.rgb != NULL && s->envmap.w == 32 && s->envmap.h == 16);
    {   /* rotate beyond a million degrees is refused, naming the line */
        char bad[256];
        appm_scene *t = NULL;
        tpath(bad, "rot.scene");
        CHECK(check_write_file(bad, "mesh texture-sphere.obj\nenvironment map texture-white.pfm rotate 1e17\n"));
        CHECK(appm_scene_load(bad, NULL, &t, &d) == APPM_ERR_PARSE && d.line == 2 && strstr(d.message, "rotate"));
        appm_scene_destroy(t);
    }
    for (mi = 0; mi < 3; ++mi) {
        appm_image img;
        render_texture(s, methods[mi], check_quick() ? 16 : 64, &img);
        if (img.rgb) {
            double sum = 0.0;
            size_t k, cnt = (size_t)img.width * img.height * 3;
            for (k = 0; k < cnt; ++k) sum += img.rgb[k];
            CHECK_MSG(fabs(sum / (double)cnt - 1.0) < 5e-3, "furnace, method %s: mean %.5f", appm_method_name(methods[mi]),
                      sum / (double)cnt);
            free(img.rgb);
        }
    }
    appm_scene_destroy(s);
}

/* Loading: vt forms, a texture named twice is loaded once, a missing map is
 * an error naming it and the MTL line, or with warn one warning per file; a
 * face without vt on a textured material is untextured. */
static void test_loading(void)
{
    char tex[256], mtl[256], obj[256];
    float g[3] = {0.25f, 0.25f, 0.25f};
    appm_scene *s = NULL;
    appm_diag d;
    appm_config cfg;
    check_log lb;
    tpath(tex, "grey.pfm");
    tpath(mtl, "two.mtl");
    tpath(obj, "two.obj");
    CHECK(write_pfm(tex, 1, 1, g));
    CHECK(check_write_file(mtl, "newmtl a\nmap_Kd texture-grey.pfm\nnewmtl b\nmap_Kd texture-grey.pfm\n"
                                "map_Ks texture-grey.pfm\nnewmtl c\nKd 1 1 1\nmap_Kd texture-none.png\n"
                                "map_d texture-none.png\n"));
    CHECK(check_write_file(obj, "mtllib texture-two.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0.5\nvt 1 0 0\nvt 0 1\n"
                                "usemtl a\nf 1/1 2/2 3/3\nusemtl b\nf 1/1 3/3 2/2\nusemtl a\nf 1 2 3\n"));
    CHECK(appm_scene_load(obj, NULL, &s, &d) == APPM_ERR_IO);
    CHECK_MSG(strstr(d.message, "texture-none.png") != NULL && d.line == 8 && strstr(d.file, "two.mtl") != NULL,
              "%s:%u: %s", d.file, d.line, d.message);
    appm_config_init(&cfg);
    memset(&lb, 0, sizeof lb);
    cfg.missing_textures = APPM_MISSING_TEXTURES_WARN;
    cfg.log = check_on_log;
    cfg.log_user = &lb;
    CHECK(appm_scene_load(obj, &cfg, &s, &d) == APPM_OK);
    CHECK_MSG(lb.n == 1 && strstr(lb.last, "texture-none.png") != NULL && lb.line == 8, "%d warnings, last '%s'",
              lb.n, lb.last);
    if (s) {
        appm_scene_info in;
        uint32_t i, textured = 0;
        appm_scene_get_info(s, &in);
        CHECK(in.textures == 1 && in.texture_bytes == 12);
        CHECK(s->mat[1].map_kd == 1 && s->mat[2].map_kd == 1 && s->mat[2].map_ks == 1);
        CHECK(s->mat[3].map_kd == 0 && s->mat[3].map_d == 0 && !s->cutouts);
        for (i = 0; i < s->ntri; ++i) {
            appm__surf sf;
            appm__material tmp;
            memset(&sf, 0, sizeof sf);
            sf.tri = i;
            sf.mat = s->info[i].mat;
            /* a face without vt takes its material without the maps */
            if (s->info[i].uv0 < 0) CHECK(appm__material_at(s, &sf, &tmp) == &s->mat[sf.mat]);
            else CHECK(appm__material_at(s, &sf, &tmp) == &tmp && tmp.color.x == s->mat[sf.mat].color.x * 0.25f);
        }
        for (i = 0; i < s->ntri; ++i)
            if (s->info[i].uv0 >= 0) {
                const float *uv = s->uv + 2 * (size_t)s->info[i].uv0;
                textured++;
                CHECK(uv[0] == 0.5f && uv[1] == 0.0f); /* "vt 0.5": v = 0 */
            }
        CHECK(textured == 2);
    }
    appm_scene_destroy(s);
    /* a malformed vt is 0 with one warning (most files never read theirs); a bad texture index is an error */
    memset(&lb, 0, sizeof lb);
    {
        static const char bad_vt[] = "v 0 0 0\nv 1 0 0\nv 0 1 0\nvt x nan\nvt 1e300 2\nf 1/1 2/2 3/1\n";
        CHECK(appm_scene_load_obj_memory(bad_vt, strlen(bad_vt), NULL, 0, "m.obj", &cfg, &s, &d) == APPM_OK);
    }
    CHECK_MSG(lb.n == 1 && strstr(lb.last, "vt") != NULL && lb.line == 4, "%d warnings, last '%s' at %u", lb.n, lb.last,
              lb.line); /* one per kind and file */
    appm_scene_destroy(s);
    CHECK(appm_scene_load_obj_memory("v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nf 1/2 2/1 3/1\n", 43, NULL, 0, "m.obj", NULL,
                                     &s, &d) == APPM_ERR_PARSE &&
          d.line == 5 && strstr(d.message, "texture index") != NULL);
}

/* set_environment_map: replaces a constant environment; a black or missing
 * map leaves the scene as it was; the checkpoint hash sees the map and the
 * texture's samples. */
static void test_api(void)
{
    char map[256], black[256];
    float sky[8 * 4 * 3], zero[3] = {0, 0, 0};
    appm_scene *s = NULL;
    appm_diag d;
    uint64_t h0[APPM__SH_PARTS], h1[APPM__SH_PARTS], h2[APPM__SH_PARTS];
    int i;
    tpath(map, "sky.pfm");
    tpath(black, "black.pfm");
    for (i = 0; i < 8 * 4 * 3; ++i) sky[i] = 0.5f + 0.01f * (float)i;
    CHECK(write_pfm(map, 8, 4, sky));
    CHECK(write_pfm(black, 1, 1, zero));
    CHECK(appm_scene_load("scenes/cornell-sphere.scene", NULL, &s, &d) == APPM_OK);
    if (!s) return;
    appm__scene_hash(s, h0);
    /* a missing file first: nothing of the call's own may be freed that it did not make */
    CHECK(appm_scene_set_environment_map(s, "tests/out/none.pfm", 1.0, 0.0, NULL, &d) == APPM_ERR_IO);
    CHECK(appm_scene_set_environment_map(s, black, 1.0, 0.0, NULL, &d) == APPM_ERR_PARSE);
    CHECK(appm_scene_set_environment_map(s, "tests/out/none.pfm", 1.0, 0.0, NULL, &d) == APPM_ERR_IO);
    CHECK(appm_scene_set_environment_map(s, map, -1.0, 0.0, NULL, &d) == APPM_ERR_INVALID_ARG);
    CHECK(s->env < 0 && s->envmap.rgb == NULL);
    CHECK(appm_scene_set_environment_map(s, map, 2.0, 30.0, NULL, &d) == APPM_OK);
    CHECK(s->env >= 0 && s->envmap.rgb != NULL && s->envmap.rgb[0] == 1.0f);
    appm__scene_hash(s, h1);
    CHECK(h1[APPM__SH_LIGHTS] != h0[APPM__SH_LIGHTS] && h1[APPM__SH_GEOMETRY] == h0[APPM__SH_GEOMETRY]);
    CHECK(appm_scene_set_environment_map(s, map, 2.0, 31.0, NULL, &d) == APPM_OK);
    appm__scene_hash(s, h2);
    CHECK(h2[APPM__SH_LIGHTS] != h1[APPM__SH_LIGHTS]);
    {
        double one[3] = {1, 1, 1};
        CHECK(appm_scene_set_environment(s, one, &d) == APPM_OK);
        CHECK(s->envmap.rgb == NULL && s->env >= 0);
    }
    appm_scene_destroy(s);
}

/* appm__env_pinpoint, the share of a map's power in its brightest texels
 * within a solid angle (pt's blindness to a sun's caustics, appm__pt_blind),
 * against sums over the texels done here: a flat map holds omega / 4 pi in
 * any omega; make_env's bright texel holds its own power over the total in
 * its own solid angle, half of it in half that angle, and the same plus the
 * next brightest texels' share of the rest in a wider one.  Then the
 * committed scenes: the textured scene's sun (1 degree, behind a glass
 * sphere) makes the path tracer report no error; the studio's key light (10
 * degrees) holds little within 1e-4 pi sr. */
static void test_env_pinpoint(void)
{
    appm__mem m;
    appm__envmap e;
    const uint32_t w = 64, h = 32, sx = 10, sy = 9;
    double dw, total = 0.0, sun, next = 0.0, dnext = 0.0;
    float *f;
    uint32_t x, y;
    appm__mem_init(&m, NULL);
    f = (float *)appm__alloc(&m, (size_t)w * h, 3 * sizeof(float));
    for (x = 0; f && x < w * h * 3; ++x) f[x] = 2.0f;
    if (f && take_env(&m, &e, f, w, h, 0.0)) {
        CHECK_NEAR(appm__env_pinpoint(&e, 0.1), 0.1 / (4.0 * APPM__PI), 1e-12);
        CHECK_NEAR(appm__env_pinpoint(&e, 4.0 * APPM__PI), 1.0, 1e-12);
        appm__envmap_free(&m, &e);
    }
    if (make_env(&m, &e, w, h, sx, sy, 0.0)) {
        for (y = 0; y < h; ++y) { /* the texels' power, brute force; the next brightest: row h-1, x % 3 == 2 */
            const double d = 2.0 * APPM__PI / w * (cos(APPM__PI * y / h) - cos(APPM__PI * (y + 1.0) / h));
            for (x = 0; x < w; ++x) {
                const float *t = appm__env_texel(&e, x, y);
                total += d * ((double)t[0] + t[1] + t[2]) / 3.0;
                if (y == h - 1 && x % 3 == 2) next += d * ((double)t[0] + t[1] + t[2]) / 3.0, dnext += d;
            }
        }
        dw = 2.0 * APPM__PI / w * (cos(APPM__PI * sy / h) - cos(APPM__PI * (sy + 1.0) / h));
        sun = dw * (500.0 + 250.0 + 125.0) / 3.0;
        CHECK_NEAR(appm__env_pinpoint(&e, dw), sun / total, 1e-9);
        CHECK_NEAR(appm__env_pinpoint(&e, 0.5 * dw), 0.5 * sun / total, 1e-9);
        CHECK_NEAR(appm__env_pinpoint(&e, dw + dnext), (sun + next) / total, 1e-9);
        appm__envmap_free(&m, &e);
    }
    f = (float *)appm__alloc(&m, (size_t)w * h, 3 * sizeof(float));
    for (x = 0; f && x < w * h * 3; ++x) f[x] = 1.0f;
    if (f) { /* two bright texels a third of a stop apart, 5 bins: the brighter alone in its solid angle */
        for (x = 0; x < 3; ++x) f[3 * ((size_t)sy * w + sx) + x] = 500.0f, f[3 * ((size_t)sy * w + sx + 1) + x] = 400.0f;
        if (take_env(&m, &e, f, w, h, 0.0)) {
            dw = 2.0 * APPM__PI / w * (cos(APPM__PI * sy / h) - cos(APPM__PI * (sy + 1.0) / h));
            total = 4.0 * APPM__PI + dw * (499.0 + 399.0);
            CHECK_NEAR(appm__env_pinpoint(&e, dw), 500.0 * dw / total, 1e-9);
            appm__envmap_free(&m, &e);
        }
    }
    {
        appm_scene *s = check_load_scene("scenes/textured.scene");
        uint32_t k;
        if (s) {
            for (k = 0; k < s->nlight; ++k)
                if (s->light[k].kind == APPM__LIGHT_ENV) {
                    double share = appm__env_pinpoint(&s->envmap, APPM__PT_TINY * APPM__PI);
                    printf("textured scene: the sun's share within 1e-4 pi sr %.3f\n", share);
                    CHECK_MSG(share > 0.1, "the 1-degree sun holds %.3f", share);
                }
            CHECK(appm__pt_blind(s) == 1);
            appm_scene_destroy(s);
        }
        s = check_load_scene("scenes/stanford-bunny.obj"); /* the studio: no glass, and a wide key light */
        if (s) {
            double share = appm__env_pinpoint(&s->envmap, APPM__PT_TINY * APPM__PI);
            printf("studio: the key light's share within 1e-4 pi sr %.4f\n", share);
            CHECK_MSG(s->envmap.rgb && share < 0.01, "the studio's sky holds %.4f", share);
            appm_scene_destroy(s);
        }
    }
}

int main(void)
{
    test_lookup();
    test_textured_plane();
    test_cutout();
    test_cut_emitter();
    test_env_small_maps();
    test_cdf_invert();
    test_env_guides();
    test_env_sampler();
    test_env_place_rotated();
    test_env_product();
    test_env_irradiance();
    test_env_sun_spread();
    test_env_orientation();
    test_env_furnace();
    test_env_pinpoint();
    test_loading();
    test_api();
    return check_finish();
}
