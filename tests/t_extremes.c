/* tests/t_extremes.c - numerical extremes (docs/testing.md section 2).
 *
 * Each group pushes one quantity to its limit and states, in its comment, what
 * good behaviour is there; the checks assert exactly that:
 *
 *   r  radius 1e-9 and 1e9 scene units         finite; 1e9 gives the blurred value;
 *                                              past a tenth of the scene, one warning
 *   a  alpha 1e-6 and 1 - 1e-6; invalid alphas finite, r > 0, r never grows; refused
 *   o  one photon per pass; photons 2^32        finite; clean APPM_ERR_NOMEM, no leak
 *   n  accumulators at 1e7 passes, n = 2^40     exact means, updates never stall
 *   s  scene scaled 1e-6 .. 1e6, and moved      same mean, radius follows the scale
 *   d  degenerate and duplicate triangles       dropped at load: the same bytes
 *   l  zero-area and tiny area lights           "no light" error; power in the info
 *   b  albedo 1 everywhere in a closed box      terminates; a depth cap lowers it
 *   c  camera inside a closed unlit cube        exactly black
 *   x  a light whose photons overflow float     what happens is stated and checked
 *   t  64 threads on an 8x8 image               the same bytes as 1 thread
 *
 * Every scene is written as text under tests/out/ and loaded through the
 * public API; internals (the per-pixel update, the pass counter) are reached
 * only where a public path would take hours.  Every group is small enough
 * to run unchanged under the sanitizers (APPM_TEST_QUICK changes nothing
 * here).  APPM_TEST_ONLY=ra (letters above) runs only those groups;
 * APPM_TEST_VERBOSE=1 prints the measured numbers.
 */
#include "../appm.c"
#include "check.h"

#define GROUP "extremes"

static int g_verbose;

/* ---- Helpers ---------------------------------------------------------------- */

/* A scene written under tests/out/ by this group. */
static appm_scene *load_scene(const char *file)
{
    return check_load_scene(check_path(GROUP, file));
}

static int write_scratch(const char *file, const char *text)
{
    int ok = check_write_file(check_path(GROUP, file), text);
    CHECK_MSG(ok, "cannot write %s", check_path(GROUP, file));
    return ok;
}




/* Summary of an image: how many values are NaN or infinite, the smallest
 * value, and the mean luminance (Rec. 709 weights, as the library's). */
typedef struct img_sum {
    size_t nonfinite;
    double min, lum;
} img_sum;

static img_sum summarize(const appm_image *img)
{
    img_sum s;
    size_t i, n = (size_t)img->width * img->height;
    s.nonfinite = 0;
    s.min = HUGE_VAL;
    s.lum = 0.0;
    for (i = 0; i < n; ++i) {
        const float *p = img->rgb + 3 * i;
        int c;
        for (c = 0; c < 3; ++c) {
            if (!(p[c] - p[c] == 0.0f)) s.nonfinite++;
            else if (p[c] < s.min) s.min = p[c];
        }
        s.lum += 0.2126 * p[0] + 0.7152 * p[1] + 0.0722 * p[2];
    }
    s.lum /= (double)(n ? n : 1);
    return s;
}

/* Renders `passes` passes and returns the summary of the image (and, when
 * `copy` is not NULL, a copy of its floats, w*h*3 of them; when `stats` is
 * not NULL, the statistics).  On failure: -1 in lum, zeros in copy and stats. */
static img_sum render_sum(const appm_scene *s, const appm_config *cfg, int passes, float *copy,
                      appm_stats *stats)
{
    img_sum sum;
    appm_renderer *r = check_renderer(s, cfg);
    appm_image img;
    sum.nonfinite = 0;
    sum.min = 0.0;
    sum.lum = -1.0;
    if (stats) memset(stats, 0, sizeof *stats);
    if (!r) return sum;
    if (copy) memset(copy, 0, (size_t)r->w * r->h * 3 * sizeof(float));
    if (check_passes(r, passes)) {
        appm_renderer_image(r, &img);
        sum = summarize(&img);
        if (copy) memcpy(copy, img.rgb, (size_t)img.width * img.height * 3 * sizeof(float));
        if (stats) appm_renderer_stats(r, stats);
    }
    appm_renderer_destroy(r);
    return sum;
}

/* ---- Scenes ------------------------------------------------------------------
 *
 * PLANE: a diffuse square (albedo 1/2, 100 x 100) with a point light of
 * intensity I = 2 at height h = 1 above its centre; the camera looks straight
 * down through the light (a point light is not geometry, so it hides nothing).
 *
 * BOX: a Cornell-like box [-1,1]^3 open at the front (z = +1) with a red and a
 * green wall and a small square light under the ceiling facing down. */
#define PL_I 2.0
#define PL_H 1.0
#define PL_HALF 50.0
#define PL_RHO 0.5

static const char PLANE_OBJ[] = "mtllib extremes-plane.mtl\n"
                                "usemtl half\n"
                                "v -50 0 -50\nv -50 0 50\nv 50 0 50\nv 50 0 -50\n"
                                "f 1 2 3 4\n";
static const char PLANE_MTL[] = "newmtl half\nKd 0.5 0.5 0.5\n";
static const char PLANE_SCENE[] = "mesh extremes-plane.obj\n"
                                  "light point position 0 1 0 intensity 2 2 2\n"
                                  "camera eye 0 2 0 target 0 0 0 up 0 0 -1 fov 20\n"
                                  "image 8 8\n";

static const char BOX_MTL[] = "newmtl white\nKd 0.7 0.7 0.7\n"
                              "newmtl red\nKd 0.6 0.1 0.1\n"
                              "newmtl green\nKd 0.1 0.6 0.1\n"
                              "newmtl light\nKd 0.7 0.7 0.7\nKe 8 8 8\n";

/* The box's vertices in unit coordinates and its faces (1-based, each with its
 * material).  Windings give inward normals; the light's faces downwards. */
static const double BOX_V[16][3] = {
    {-1, -1, -1}, {1, -1, -1}, {1, -1, 1}, {-1, -1, 1},       /* floor   1-4   */
    {-1, 1, -1},  {1, 1, -1},  {1, 1, 1},  {-1, 1, 1},        /* ceiling 5-8   */
    {-0.25, 0.98, -0.25}, {0.25, 0.98, -0.25}, {0.25, 0.98, 0.25}, {-0.25, 0.98, 0.25}, /* 9-12 */
    {-1, -1, -1}, {-1, 1, -1}, {1, 1, -1}, {1, -1, -1}};     /* back wall 13-16 */
static const char *const BOX_F[] = {"usemtl white\nf 1 4 3 2\n",   "f 5 6 7 8\n",
                                    "f 13 14 15 16\n",             "usemtl red\nf 1 5 8 4\n",
                                    "usemtl green\nf 2 3 7 6\n",   "usemtl light\nf 9 10 11 12\n"};

/* WHITE: a closed box [-1,1]^3 of albedo 1 inside and out, with a small light
 * (albedo 1 as well) under its ceiling. */
static const char WHITE_BOX_OBJ[] = "mtllib extremes-white.mtl\n"
                                    "v -1 -1 -1\nv 1 -1 -1\nv 1 1 -1\nv -1 1 -1\n"
                                    "v -1 -1 1\nv 1 -1 1\nv 1 1 1\nv -1 1 1\n"
                                    "v -0.2 0.99 -0.2\nv 0.2 0.99 -0.2\nv 0.2 0.99 0.2\nv -0.2 0.99 0.2\n"
                                    "usemtl white\n"
                                    "f 1 2 3 4\nf 5 8 7 6\nf 1 4 8 5\nf 2 6 7 3\nf 1 5 6 2\nf 4 3 7 8\n"
                                    "usemtl light\nf 9 10 11 12\n";
static const char WHITE_BOX_MTL[] = "newmtl white\nKd 1 1 1\nnewmtl light\nKd 1 1 1\nKe 1 1 1\n";
static const char WHITE_BOX_SCENE[] = "mesh extremes-white.obj\n"
                                      "camera eye 0 -0.2 0.9 target 0 0 -1 up 0 1 0 fov 70\nimage 8 8\n";

/* Writes the box scaled by `s` and moved by (tx, 0, 0) as <name>.obj (sharing
 * extremes-box.mtl) and <name>.scene with the camera moved alike. */
static int write_box(const char *name, double s, double tx, unsigned size)
{
    char obj[4096], scene[1024], file[128];
    size_t n = 0;
    int i, ok;
    n += (size_t)snprintf(obj + n, sizeof obj - n, "mtllib extremes-box.mtl\n");
    for (i = 0; i < 16; ++i)
        n += (size_t)snprintf(obj + n, sizeof obj - n, "v %.17g %.17g %.17g\n", BOX_V[i][0] * s + tx,
                              BOX_V[i][1] * s, BOX_V[i][2] * s);
    for (i = 0; i < 6; ++i) n += (size_t)snprintf(obj + n, sizeof obj - n, "%s", BOX_F[i]);
    snprintf(scene, sizeof scene,
             "mesh extremes-%s.obj\n"
             "camera eye %.17g %.17g %.17g target %.17g %.17g 0 up 0 1 0 fov 40\n"
             "image %u %u\n",
             name, tx, -0.4 * s, 3.6 * s, tx, -0.4 * s, size, size);
    snprintf(file, sizeof file, "%s.obj", name);
    ok = write_scratch(file, obj);
    snprintf(file, sizeof file, "%s.scene", name);
    return ok && write_scratch(file, scene) && write_scratch("box.mtl", BOX_MTL);
}

/* ---- r. Radius extremes -------------------------------------------------------
 *
 * Good behaviour (testing.md section 2): a radius of 1e-9 scene units (far
 * below the pixel footprint, so hardly a photon falls inside) and one of 1e9
 * (every photon falls inside every gather) both render to completion with
 * every pixel finite and non-negative, for ppm, sppm and appm.
 *
 * With r = 1e9 and alpha = 1 the estimate is the fully blurred one.  With
 * first-bounce photons and max depth 2 (light -> plane -> camera) every pixel
 * sees every photon that reached the plane, so
 *      L = (rho/pi) (sum of photon power on the plane) / (pi r^2)
 * whose expectation is (rho/pi) I Omega / (pi r^2), Omega the solid angle of
 * the square from the light: Omega = 4 asin(a^2 / (a^2 + h^2)) for half side a.
 * (testing.md's E_r = (2I/r^2)(1 - h/sqrt(h^2 + r^2)) is the same for an
 * infinite plane, where Omega -> 2 pi; the finite square catches 1.8% less.)
 * The count of photons on the plane is Binomial(M, Omega / 4 pi) per pass, all
 * of the same power, so the relative standard error of the mean over P passes
 * is sqrt((1 - p) / (P M p)); 4 of them are allowed (ppm and sppm see the same
 * photons, so this is one draw, not two).  sppm with alpha = 1 keeps R fixed
 * (R' = R sqrt(N'/(N+m)) with N' = N + m), so it gives the same value.
 *
 * appm weights the photons with the biweight kernel, and shrinks its radius as
 * j^(-1/6) from r1, so its value is not this one: it is checked for finite,
 * non-negative pixels and a finite positive radius map only. */
static void test_radius(void)
{
    static const appm_method methods[3] = {APPM_METHOD_PPM, APPM_METHOD_SPPM, APPM_METHOD_APPM};
    static const double radii[2] = {1e-9, 1e9};
    const uint64_t M = 8192;
    const int passes = 4;
    const double omega = 4.0 * asin(PL_HALF * PL_HALF / (PL_HALF * PL_HALF + PL_H * PL_H));
    const double p = omega / (4.0 * APPM__PI);
    appm_scene *s;
    int mi, ri;
    s = load_scene("plane.scene");
    if (!s) return;
    for (ri = 0; ri < 2; ++ri) {
        for (mi = 0; mi < 3; ++mi) {
            appm_config cfg;
            appm_renderer *r;
            appm_image img;
            appm_stats st;
            img_sum sum;
            const float *rad;
            size_t i, bad_r = 0;
            appm_config_init(&cfg);
            cfg.method = methods[mi];
            cfg.direct = APPM_DIRECT_PHOTONS;
            cfg.max_depth = 2;
            cfg.radius = radii[ri];
            cfg.alpha = 1.0;
            cfg.photons = M;
            cfg.seed = 11;
            cfg.threads = 2;
            r = check_renderer(s, &cfg);
            if (!r) continue;
            if (!check_passes(r, passes)) {
                appm_renderer_destroy(r);
                continue;
            }
            appm_renderer_image(r, &img);
            appm_renderer_stats(r, &st);
            sum = summarize(&img);
            rad = appm_renderer_aux(r, APPM_AUX_RADIUS);
            for (i = 0; rad && i < (size_t)img.width * img.height; ++i)
                bad_r += !(rad[i] > 0.0f && rad[i] < HUGE_VAL);
            CHECK_MSG(sum.nonfinite == 0, "r=%g %s: %lu non-finite values", radii[ri],
                      check_method_name(methods[mi]), (unsigned long)sum.nonfinite);
            CHECK_MSG(sum.min >= 0.0, "r=%g %s: negative pixel %g", radii[ri], check_method_name(methods[mi]),
                      sum.min);
            CHECK_MSG(rad != NULL && bad_r == 0, "r=%g %s: %lu radii not finite and > 0", radii[ri],
                      check_method_name(methods[mi]), (unsigned long)bad_r);
            CHECK_MSG(st.initial_radius == radii[ri], "r=%g %s: initial radius %g", radii[ri],
                      check_method_name(methods[mi]), st.initial_radius);
            if (ri == 1 && methods[mi] != APPM_METHOD_APPM) {
                const double R = radii[ri];
                const double expect = PL_RHO / APPM__PI * PL_I * omega / (APPM__PI * R * R);
                const double rel_se = sqrt((1.0 - p) / ((double)passes * (double)M * p));
                /* 1e-6: float rounding of photon powers and of the pixel value */
                CHECK_MSG(fabs(sum.lum - expect) <= (4.0 * rel_se + 1e-6) * expect,
                          "r=1e9 %s: L = %.6g, blurred value %.6g within 4 SE (%.2g relative)",
                          check_method_name(methods[mi]), sum.lum, expect, rel_se);
                if (g_verbose)
                    printf("r=1e9 %-4s L %.6g expected %.6g (%+.2f SE)\n", check_method_name(methods[mi]),
                           sum.lum, expect, (sum.lum / expect - 1.0) / rel_se);
            }
            appm_renderer_destroy(r);
        }
    }
    appm_scene_destroy(s);
}

/* A radius past a tenth of the scene's bounding-box diagonal is valid (test_radius), but each pixel
 * then visits a large share of the photons (the sphere box at 512 x 512: 0.5 s a pass at the
 * automatic radius, 340 s at r = 5): appm_renderer_create says so through cfg.log, once, and
 * not for a radius below that, nor for a renderer it refuses for another option. */
static void test_radius_warning(void)
{
    static const double share[4] = {0.09, 0.5, 1.5, 1.5}; /* of the diagonal */
    static const char *const want[4] = {NULL, "% of the scene's size", "larger than the whole scene", NULL};
    appm_scene_info info;
    appm_scene *s = load_scene("plane.scene");
    double diagonal = 0.0;
    int k;
    if (!s) return;
    appm_scene_get_info(s, &info);
    for (k = 0; k < 3; ++k)
        diagonal += (info.bbox_max[k] - info.bbox_min[k]) * (info.bbox_max[k] - info.bbox_min[k]);
    diagonal = sqrt(diagonal);
    for (k = 0; k < 4; ++k) {
        appm_config cfg;
        appm_renderer *r = NULL;
        appm_diag d;
        check_log l;
        memset(&l, 0, sizeof l);
        appm_config_init(&cfg);
        cfg.width = cfg.height = 8;
        cfg.threads = 1; /* a build without threads would warn about 2 */
        cfg.radius = share[k] * diagonal;
        cfg.max_depth = k == 3 ? 300 : 0; /* 300: refused after the radius's check */
        cfg.log = check_on_log;
        cfg.log_user = &l;
        CHECK_MSG(appm_renderer_create(s, &cfg, &r, &d) == (k == 3 ? APPM_ERR_INVALID_ARG : APPM_OK),
                  "radius %g, case %d: %s", cfg.radius, k, d.message);
        if (want[k])
            CHECK_MSG(l.n == 1 && strstr(l.last, want[k]) != NULL, "radius %.2f diagonals: %d warnings, '%s'",
                      share[k], l.n, l.last);
        else
            CHECK_MSG(l.n == 0, "radius %.2f diagonals, case %d: %d warnings, '%s'", share[k], k, l.n, l.last);
        appm_renderer_destroy(r);
    }
    appm_scene_destroy(s);
}

/* ---- a. Alpha extremes -------------------------------------------------------
 *
 * Good behaviour: alpha is the fraction of new photons kept, valid in (0, 1].
 * Near either end the radius stays finite and positive and never grows:
 *   ppm   r_{j+1}^2 = r_j^2 (j + alpha) / (j + 1): with alpha = 1e-6 it falls
 *         about as r1 / sqrt(j), never to 0;
 *   sppm  N' = N + alpha m, R' = R sqrt(N' / (N + m)): the first pass that
 *         finds photons multiplies R by sqrt(alpha) = 1e-3, later ones less.
 * (With alpha = 0 the first such pass gives R = 0, then 0/0: pbrt-v3 does.)
 * Out of range values are refused by appm_renderer_create with
 * APPM_ERR_INVALID_ARG: negative, above 1, NaN, infinite.  alpha = 0 is not
 * among them: in appm_config every 0 means "the default", here 2/3 - the
 * command line is where "--alpha 0" is refused. */
static void test_alpha(void)
{
    static const appm_method methods[3] = {APPM_METHOD_PPM, APPM_METHOD_SPPM, APPM_METHOD_APPM};
    static const double alphas[2] = {1e-6, 1.0 - 1e-6};
    const double bad[7] = {-0.5, -1e-300, 1.0 + 1e-12, 2.0, NAN, HUGE_VAL, -HUGE_VAL};
    appm_scene *s = load_scene("plane.scene");
    appm_config cfg;
    appm_renderer *r;
    appm_diag d;
    int mi, ai, k;
    if (!s) return;
    for (ai = 0; ai < 2; ++ai) {
        for (mi = 0; mi < 3; ++mi) {
            float prev[64];
            int j, finite = 1, positive = 1, grows = 0;
            appm_config_init(&cfg);
            cfg.method = methods[mi];
            cfg.direct = APPM_DIRECT_PHOTONS;
            cfg.alpha = alphas[ai];
            cfg.photons = 4096;
            cfg.threads = 2;
            r = check_renderer(s, &cfg);
            if (!r) continue;
            for (j = 1; j <= 8; ++j) {
                appm_image img;
                const float *rad;
                size_t i;
                if (!check_passes(r, 1)) break;
                appm_renderer_image(r, &img);
                finite &= summarize(&img).nonfinite == 0;
                rad = appm_renderer_aux(r, APPM_AUX_RADIUS);
                if (!rad) {
                    positive = 0;
                    break;
                }
                for (i = 0; i < 64; ++i) {
                    positive &= rad[i] > 0.0f && rad[i] < HUGE_VAL;
                    /* appm may widen a pixel's radius (by design, within its clamps) */
                    if (j > 1 && methods[mi] != APPM_METHOD_APPM && rad[i] > prev[i]) grows++;
                    prev[i] = rad[i];
                }
            }
            CHECK_MSG(finite, "alpha=%g %s: non-finite image", alphas[ai], check_method_name(methods[mi]));
            CHECK_MSG(positive, "alpha=%g %s: a radius is 0, negative or not finite", alphas[ai],
                      check_method_name(methods[mi]));
            CHECK_MSG(grows == 0, "alpha=%g %s: the radius grew %d times", alphas[ai],
                      check_method_name(methods[mi]), grows);
            if (g_verbose)
                printf("alpha=%-9g %-4s last radius %.4g (r1 %.4g)\n", alphas[ai], check_method_name(methods[mi]),
                       (double)prev[0], r->r1);
            appm_renderer_destroy(r);
        }
    }
    for (k = 0; k < 7; ++k) {
        appm_status st;
        appm_config_init(&cfg);
        cfg.alpha = bad[k];
        r = (appm_renderer *)&cfg; /* must be overwritten with NULL */
        st = appm_renderer_create(s, &cfg, &r, &d);
        CHECK_MSG(st == APPM_ERR_INVALID_ARG && r == NULL && strstr(d.message, "alpha") != NULL,
                  "alpha %g: status %d, message '%s'", bad[k], (int)st, d.message);
        if (st == APPM_OK) appm_renderer_destroy(r);
    }
    /* the two ends of the valid range, and 0 meaning the default */
    appm_config_init(&cfg);
    cfg.alpha = 1.0;
    r = check_renderer(s, &cfg);
    CHECK(r && r->alpha == 1.0);
    appm_renderer_destroy(r);
    cfg.alpha = 0.0;
    r = check_renderer(s, &cfg);
    CHECK(r && r->alpha == 2.0 / 3.0);
    appm_renderer_destroy(r);
    appm_scene_destroy(s);
}

/* ---- o. Photon counts: one, and more than memory ----------------------------
 *
 * Good behaviour: one photon path per pass is a valid (very noisy) budget: 50
 * passes of every method give finite pixels and count 50 photons emitted.
 *
 * At the other end, photons = 2^32 (the largest count accepted; 2^32 + 1 is
 * refused as an invalid argument) needs a photon store of 1.5 x 2^32 x 32
 * bytes.  With an allocator that refuses to hold more than 64 MB, the
 * renderer must fail cleanly: APPM_ERR_NOMEM from appm_renderer_create (or
 * from the first pass, where the store may be sized), no renderer returned,
 * and every byte given back.
 *
 * A pass allocates too: the first one the photon map's hash table, any pass
 * a larger photon store when its photons do not fit (the store starts at 1.5
 * photons per path; the albedo-1 box stores 30).  When that allocation is
 * refused, the pass fails with APPM_ERR_NOMEM and is not counted, and the
 * renderer stays usable.  Since the image depends only on scene, config, seed
 * and the number of passes, a retry once memory is available must give the
 * same bytes as a renderer that never failed. */
typedef struct budget {
    long long live, limit;
    long refused, calls;
} budget;

static void *limited_alloc(void *user, size_t n)
{
    budget *b = (budget *)user;
    void *p;
    b->calls++;
    if ((long long)n > b->limit - b->live) {
        b->refused++;
        return NULL;
    }
    p = malloc(n);
    if (p) b->live += (long long)n;
    return p;
}

static void limited_free(void *user, void *p, size_t n)
{
    budget *b = (budget *)user;
    if (!p) return;
    b->live -= (long long)n;
    free(p);
}

static void use_budget(appm_config *cfg, budget *b, long long limit)
{
    memset(b, 0, sizeof *b);
    b->limit = limit;
    cfg->allocator.alloc = limited_alloc;
    cfg->allocator.free = limited_free;
    cfg->allocator.user = b;
}

/* Runs the first pass of a ppm render of `s` with `margin` bytes allowed
 * beyond what appm_renderer_create took; that pass must fail with
 * APPM_ERR_NOMEM.  Then, with memory to spare, two passes must give the bytes
 * of a clean two-pass render.  `what` says which allocation is expected to
 * fail (for the messages). */
static void failed_pass(const appm_scene *s, long long margin, const char *what)
{
    float *ref = (float *)malloc(8 * 8 * 3 * sizeof(float));
    appm_config cfg;
    appm_renderer *r;
    appm_image img;
    appm_stats stats;
    appm_status st;
    appm_image ref_img;
    budget b;
    long long after_create;
    ref_img.width = ref_img.height = 8;
    ref_img.rgb = ref;
    appm_config_init(&cfg);
    cfg.method = APPM_METHOD_PPM;
    cfg.photons = 4096;
    cfg.threads = 1;
    cfg.seed = 5;
    if (!ref) return;
    render_sum(s, &cfg, 2, ref, NULL); /* a renderer that never ran out of memory */
    use_budget(&cfg, &b, 1ll << 40);
    r = check_renderer(s, &cfg);
    if (r) {
        after_create = b.live;
        b.limit = after_create + margin;
        st = appm_renderer_pass(r);
        appm_renderer_stats(r, &stats);
        CHECK_MSG(st == APPM_ERR_NOMEM && b.refused > 0, "%s under a budget: status %d", what, (int)st);
        CHECK_MSG(appm_renderer_last_error(r)[0] != 0 && stats.passes == 0,
                  "%s: no message, or the pass was counted", what);
        /* a failed pass may keep a store it did manage to grow, within budget */
        CHECK_MSG(b.live >= after_create && b.live <= b.limit, "%s: %lld bytes held, budget %lld", what,
                  b.live, b.limit);
        b.limit = 1ll << 40;
        if (check_passes(r, 2)) {
            appm_renderer_image(r, &img);
            CHECK(summarize(&img).nonfinite == 0);
            CHECK_MSG(memcmp(img.rgb, ref, sizeof(float) * 8 * 8 * 3) == 0,
                      "%s: after the failed pass, the retry differs from a clean render "
                      "(mean %.6g vs %.6g: the failed pass left state behind)",
                      what, summarize(&img).lum, summarize(&ref_img).lum);
        }
    }
    appm_renderer_destroy(r);
    CHECK_MSG(b.live == 0, "%s: %lld bytes leaked", what, b.live);
    free(ref);
}

static void test_photon_counts(void)
{
    static const appm_method methods[4] = {APPM_METHOD_APPM, APPM_METHOD_PPM, APPM_METHOD_SPPM,
                                           APPM_METHOD_PT};
    appm_scene *s, *white;
    appm_config cfg;
    appm_renderer *r = NULL;
    appm_diag d;
    appm_status st;
    budget b;
    int mi;
    s = load_scene("box.scene");
    if (!s) return;
    for (mi = 0; mi < 4; ++mi) {
        appm_stats stats;
        img_sum sum;
        appm_config_init(&cfg);
        cfg.method = methods[mi];
        cfg.photons = 1;
        cfg.threads = 2;
        memset(&stats, 0, sizeof stats);
        sum = render_sum(s, &cfg, 50, NULL, &stats);
        CHECK_MSG(sum.lum >= 0.0 && sum.nonfinite == 0 && sum.min >= 0.0,
                  "1 photon/pass %s: mean %g, %lu non-finite, min %g", check_method_name(methods[mi]), sum.lum,
                  (unsigned long)sum.nonfinite, sum.min);
        CHECK(stats.passes == 50);
        CHECK(stats.photons_emitted == (methods[mi] == APPM_METHOD_PT ? 0u : 50u));
    }

    /* 2^32 + 1: above the documented limit */
    appm_config_init(&cfg);
    cfg.photons = ((uint64_t)1 << 32) + 1;
    st = appm_renderer_create(s, &cfg, &r, &d);
    CHECK(st == APPM_ERR_INVALID_ARG && r == NULL);

    /* 2^32 under a 64 MB budget */
    for (mi = 0; mi < 3; ++mi) {
        appm_config_init(&cfg);
        cfg.method = methods[mi];
        cfg.photons = (uint64_t)1 << 32;
        cfg.threads = 2;
        use_budget(&cfg, &b, 64ll << 20);
        r = (appm_renderer *)&cfg;
        st = appm_renderer_create(s, &cfg, &r, &d);
        if (st == APPM_OK) {
            /* allowed by the contract: then the first pass must fail */
            st = appm_renderer_pass(r);
            CHECK_MSG(st == APPM_ERR_NOMEM, "2^32 photons, %s: first pass gave %d",
                      check_method_name(methods[mi]), (int)st);
            appm_renderer_destroy(r);
        } else {
            CHECK_MSG(st == APPM_ERR_NOMEM && r == NULL && d.status == APPM_ERR_NOMEM && d.message[0],
                      "2^32 photons, %s: create gave %d (%s)", check_method_name(methods[mi]), (int)st, d.message);
        }
        /* with a 32-bit size_t the store's size overflows and is refused before
         * the allocator is asked */
        CHECK_MSG((b.refused > 0 || sizeof(size_t) < 8) && b.live == 0,
                  "2^32 photons, %s: %ld refused, %lld bytes leaked",
                  check_method_name(methods[mi]), b.refused, b.live);
    }

    /* a pass that runs out of memory, then a retry */
    failed_pass(s, 0, "its first allocation (the photon map's table)");
    white = load_scene("white.scene");
    if (white) failed_pass(white, 1 << 20, "growing the photon store (30 photons per path)");
    appm_scene_destroy(white);
    appm_scene_destroy(s);
}

/* ---- n. Accumulators that must not stall ---------------------------------------
 *
 * Good behaviour: every quantity that grows with the number of passes or
 * photons is kept where adding one more still changes it, and a running mean
 * of a constant stays that constant.
 *
 * (1) appm__adaptive_update and appm__welford, 1e7 passes of the same per-pass values: the
 *     recursive mean I += (x - I) / j reproduces x exactly after the first
 *     pass (x - I is then exactly 0), so acc, S, dI and the Welford mean are
 *     bitwise x, and the Welford M2 and the Laplacian's spread stay 0; the
 *     photon count, 1000 per pass, reaches 1e10 exactly (integers below 2^53
 *     are exact in double; in float, whose spacing at 1e10 is 1024, each
 *     addition of 1000 would round, and the count would end 2% off).
 *     A different value at pass 1e7 + 1 still moves the mean by
 *     (x' - x) / (1e7 + 1): checked to 1e-15 relative.
 * (2) n = 2^40 (1e12 photons) plus 1 photon is 2^40 + 1.
 * (3) sppm's N in the gather: with every pixel's N set to 2^40 after a pass,
 *     the next pass must still add alpha m to N and shrink R by
 *     sqrt(N' / (N + m)) - with a float N both would be lost.
 * (4) photons_emitted and eye_paths are 64-bit: with the pass counter set to
 *     just below 3 x 2^31 / M passes, one more pass lands the count exactly on
 *     3 x 2^31 = M x passes (a 32-bit product or sum would wrap). */
static void test_accumulators(void)
{
    const double e[3] = {0.1, 0.3, 0.7}, e2[3] = {0.2, 0.6, 1.4};
    const double s_in = 0.0123, dl_in = -2.5, ld_lum = 0.2;
    const uint64_t passes = 10000000u;
    appm__adaptive_stats px;
    appm__pixel pw;
    uint64_t j;
    int c, exact = 1;
    double v;
    memset(&px, 0, sizeof px);
    memset(&pw, 0, sizeof pw);
    for (j = 1; j <= passes; ++j) {
        appm__adaptive_update(&px, j, e, s_in, dl_in, 1.0, 1000);
        appm__welford(&pw, j, ld_lum + appm__lumd(e));
    }
    for (c = 0; c < 3; ++c) exact &= px.I[c] == e[c];
    v = ld_lum + appm__lumd(e);
    CHECK_MSG(exact, "the running mean of a constant drifted: %.17g %.17g %.17g", px.I[0], px.I[1],
              px.I[2]);
    CHECK(px.S == s_in);
    CHECK(px.dI == dl_in && px.dI_m2 == 0.0 && px.dI_w == (double)passes);
    CHECK(pw.wmean == v && pw.wm2 == 0.0);
    CHECK_MSG(px.N == 10000000000u, "photon count %.17g, expected 1e10", (double)px.N);
    appm__adaptive_update(&px, passes + 1, e2, s_in, dl_in, 1.0, 1);
    for (c = 0; c < 3; ++c)
        CHECK_NEAR(px.I[c], e[c] + (e2[c] - e[c]) / (double)(passes + 1), 1e-15 * e[c]);
    CHECK(px.I[0] != e[0] && px.N == 10000000001u);

    /* (2) */
    memset(&px, 0, sizeof px);
    px.N = (uint64_t)1 << 40;
    appm__adaptive_update(&px, 2, e, s_in, dl_in, 0.0, 1);
    CHECK(px.N == ((uint64_t)1 << 40) + 1);

    /* (3) sppm at N = 2^40 */
    {
        appm_scene *s = load_scene("plane.scene");
        appm_config cfg;
        appm_renderer *r;
        appm_config_init(&cfg);
        cfg.method = APPM_METHOD_SPPM;
        cfg.direct = APPM_DIRECT_PHOTONS;
        cfg.photons = 65536;
        cfg.threads = 2;
        r = s ? check_renderer(s, &cfg) : NULL;
        if (r && check_passes(r, 1)) {
            const double N0 = 1099511627776.0;
            double r_before[64];
            int i, moved = 0, consistent = 1;
            for (i = 0; i < 64; ++i) {
                appm__sppm_state *k = (appm__sppm_state *)appm__state(r, (size_t)i);
                k->N = N0;
                r_before[i] = k->R;
            }
            if (check_passes(r, 1)) {
                for (i = 0; i < 64; ++i) {
                    const appm__sppm_state *p = (const appm__sppm_state *)appm__state(r, (size_t)i);
                    double m = (p->N - N0) / r->alpha, expect_r;
                    if (p->N == N0) continue; /* no photon found: nothing to change */
                    moved++;
                    /* m is a whole number of photons; N has 2^-12 resolution at 2^40 */
                    consistent &= m >= 0.5 && fabs(m - floor(m + 0.5)) < 1e-2;
                    m = floor(m + 0.5);
                    expect_r = r_before[i] * sqrt(p->N / (N0 + m));
                    consistent &= p->R < r_before[i] && fabs(p->R - expect_r) <= 1e-12 * expect_r;
                }
                CHECK_MSG(moved >= 32, "sppm at N = 2^40: only %d of 64 pixels changed N", moved);
                CHECK_MSG(consistent, "sppm at N = 2^40: N, R not updated as N' = N + alpha m, "
                                      "R' = R sqrt(N'/(N+m))");
            }
        }
        appm_renderer_destroy(r);
        appm_scene_destroy(s);
    }

    /* (4) 64-bit counts */
    CHECK(sizeof(((appm_stats *)0)->photons_emitted) == 8 && sizeof(((appm_stats *)0)->eye_paths) == 8);
    {
        appm_scene *s = load_scene("plane.scene");
        appm_config cfg;
        appm_renderer *r;
        const uint64_t M = 1024, target = (uint64_t)3 << 31, before = target / M - 1;
        appm_config_init(&cfg);
        cfg.method = APPM_METHOD_PPM;
        cfg.radius = 0.05;
        cfg.photons = M;
        cfg.threads = 1;
        r = s ? check_renderer(s, &cfg) : NULL;
        if (r && check_passes(r, 1)) {
            appm_stats st;
            appm_image img;
            /* the state 6291455 passes in: counters consistent with it */
            r->pass = before;
            r->stats.photons_emitted = before * M;
            r->stats.eye_paths = before * 64;
            if (check_passes(r, 1)) {
                appm_renderer_stats(r, &st);
                appm_renderer_image(r, &img);
                CHECK_MSG(st.passes == before + 1 && st.photons_emitted == target &&
                              st.eye_paths == (before + 1) * 64,
                          "after %.0f passes of %.0f photons: passes %.0f, photons %.0f, eye paths %.0f",
                          (double)(before + 1), (double)M, (double)st.passes, (double)st.photons_emitted,
                          (double)st.eye_paths);
                CHECK(summarize(&img).nonfinite == 0);
            }
        }
        appm_renderer_destroy(r);
        appm_scene_destroy(s);
    }
}

/* ---- s. Scene scale ------------------------------------------------------------
 *
 * Good behaviour: nothing in the renderer has an absolute length scale.  The
 * box scaled by 1e-6 .. 1e6 (camera scaled with it), or moved by 1e6 along x
 * (camera moved with it), is the same picture: the same radiance (Ke is a
 * radiance, independent of scale), an automatic radius proportional to the
 * scale (it is twice the median pixel footprint: ratio within 1e-3), no NaN.
 *
 * How close the image means must be:
 *   noise   SCALE_SEEDS renders of the unit box with independent seeds give
 *           sigma, the standard deviation of an image mean (measured, so it
 *           includes the correlation of neighbouring pixels that share
 *           photons, which a per-pixel standard error would miss for ppm).
 *           Two independent renders would differ by sqrt(2) sigma; allowed:
 *           5 sqrt(2) sigma (sigma from 8 seeds: |t_7| > 5 has probability
 *           1.6e-3), and never more than 3%, "a few percent".  Here sigma is
 *           4% of the mean, so the 3% is the binding one of these two.
 *   coupling  every render below uses the seed of the unit render it is
 *           compared with, so both are the same random experiment on
 *           geometry that differs only by float rounding: 2^-24 relative
 *           for a pure scale, 2^-4 / 1e3 = 6e-5 of the box for the box of
 *           size 1e3 moved to x = 1e6.  Their means may differ by rounding
 *           effects only (1e-7 and 3e-5 relative are seen); allowed 1e-3.
 *           An absolute epsilon anywhere (ray offsets, radii, grid cells)
 *           breaks this at 1e-6 or 1e6 by far more.
 * The unit box moved to x = 1e6 gets the 3% only: a float there has a spacing
 * of 2^-4 = 0.0625, so hit points are rounded by up to 3% of the box and ray
 * offsets (a bound on that rounding) are 0.4 units long.  The picture
 * survives (the box's corners are exact floats) with a mean that moves by
 * about 1% - a statement about the float limit, not a noise test. */
#define SCALE_SEEDS 8
#define SCALE_PASSES 8

typedef struct scale_case {
    const char *name;
    double s, tx;
} scale_case;

static void scale_render(const appm_scene *s, appm_method m, uint64_t seed, double *mean, double *r1,
                         size_t *nonfinite)
{
    appm_config cfg;
    appm_renderer *r;
    appm_image img;
    appm_stats st;
    appm_config_init(&cfg);
    cfg.method = m;
    cfg.photons = 16384;
    cfg.seed = seed;
    cfg.threads = 2;
    *mean = *r1 = -1.0;
    *nonfinite = 1;
    r = check_renderer(s, &cfg);
    if (!r) return;
    if (check_passes(r, SCALE_PASSES)) {
        img_sum sum;
        appm_renderer_image(r, &img);
        appm_renderer_stats(r, &st);
        sum = summarize(&img);
        *nonfinite = sum.nonfinite;
        *mean = sum.lum;
        *r1 = st.initial_radius;
    }
    appm_renderer_destroy(r);
}

static void test_scale(void)
{
    static const scale_case cases[7] = {{"box-1", 1.0, 0.0},     {"box-1e-6", 1e-6, 0.0},
                                        {"box-1e-3", 1e-3, 0.0}, {"box-1e3", 1e3, 0.0},
                                        {"box-1e6", 1e6, 0.0},   {"box-1e3-moved", 1e3, 1e6},
                                        {"box-1-moved", 1.0, 1e6}};
    static const appm_method methods[2] = {APPM_METHOD_PPM, APPM_METHOD_PT};
    double mean[2][7], r1[2][7], sigma[2];
    int k, mi;
    for (k = 0; k < 7; ++k) {
        appm_scene *s;
        char file[64];
        size_t nf;
        if (!write_box(cases[k].name, cases[k].s, cases[k].tx, 16)) return;
        snprintf(file, sizeof file, "%s.scene", cases[k].name);
        s = load_scene(file);
        if (!s) return;
        for (mi = 0; mi < 2; ++mi) {
            scale_render(s, methods[mi], 3, &mean[mi][k], &r1[mi][k], &nf);
            CHECK_MSG(nf == 0 && mean[mi][k] > 0.0, "%s %s: %lu non-finite values, mean %g", cases[k].name,
                      check_method_name(methods[mi]), (unsigned long)nf, mean[mi][k]);
            if (k == 0) { /* the spread of the image mean over independent seeds */
                double m[SCALE_SEEDS], sum = 0.0, ss = 0.0, rr;
                int i;
                for (i = 0; i < SCALE_SEEDS; ++i) {
                    scale_render(s, methods[mi], 100u + (uint64_t)i, &m[i], &rr, &nf);
                    sum += m[i];
                }
                for (i = 0; i < SCALE_SEEDS; ++i)
                    ss += (m[i] - sum / SCALE_SEEDS) * (m[i] - sum / SCALE_SEEDS);
                sigma[mi] = sqrt(ss / (SCALE_SEEDS - 1));
            }
        }
        appm_scene_destroy(s);
    }
    for (mi = 0; mi < 2; ++mi) {
        for (k = 1; k < 7; ++k) {
            double d = mean[mi][k] - mean[mi][0], tol = 5.0 * sqrt(2.0) * sigma[mi];
            if (tol > 0.03 * mean[mi][0]) tol = 0.03 * mean[mi][0];
            if (k < 6 && tol > 1e-3 * mean[mi][0]) tol = 1e-3 * mean[mi][0];
            CHECK_MSG(fabs(d) <= tol, "%s %s: mean %.6g vs %.6g at scale 1 (difference %.3g, allowed %.3g)",
                      cases[k].name, check_method_name(methods[mi]), mean[mi][k], mean[mi][0], d, tol);
            if (methods[mi] == APPM_METHOD_PPM) {
                double ratio = r1[mi][k] / r1[mi][0] / cases[k].s;
                CHECK_MSG(fabs(ratio - 1.0) <= 1e-3, "%s: automatic radius %.6g, %.6g times that at scale 1",
                          cases[k].name, r1[mi][k], r1[mi][k] / r1[mi][0]);
            }
            if (g_verbose)
                printf("%-14s %-4s mean %.6f (scale 1: %.6f, sigma %.2g) relative difference %.2g, r1/s %.6g\n",
                       cases[k].name, check_method_name(methods[mi]), mean[mi][k], mean[mi][0], sigma[mi],
                       d / mean[mi][0], r1[mi][k] / cases[k].s);
        }
    }
}

/* ---- d. Degenerate and duplicate triangles -------------------------------------
 *
 * Good behaviour: a zero-area triangle has no normal (the cross product is 0,
 * normalising it gives NaN) and can be neither hit nor sampled, so the loader
 * drops it and counts it.  Then a mesh of 1000 degenerate triangles plus one
 * valid quad is, after loading, the quad alone: the same triangles in the
 * same order, the same BVH, the same light table - so the same seed renders
 * the same bytes, for every method.  The degenerate kinds: three equal
 * vertices, two equal vertices, three distinct collinear vertices (in the
 * floor's plane and far outside the scene, where they would otherwise have
 * moved the bounding box).
 *
 * Duplicated triangles (the floor three times over, once with reversed
 * winding) are legal: they load, and render without NaN or dropped samples.
 * With the same seed the render is the same random experiment as the single
 * floor's: whichever copy a ray hits, it finds the same plane, the same
 * two-sided material and the same point up to float rounding (the copies
 * interpolate it from their vertices in another order).  So the means may
 * differ by rounding effects only (3e-8 relative is seen); allowed 1e-3,
 * far below what a copy that shaded differently would change. */
static void test_degenerate_scene(void)
{
    static const appm_method methods[4] = {APPM_METHOD_APPM, APPM_METHOD_PPM, APPM_METHOD_SPPM,
                                           APPM_METHOD_PT};
    static const char quad[] = "v -1 0 -1\nv -1 0 1\nv 1 0 1\nv 1 0 -1\n";
    char *obj = (char *)malloc(200000);
    size_t n = 0;
    int i, mi;
    appm_scene *a = NULL, *b = NULL, *dup = NULL;
    appm_scene_info info;
    float *ia = (float *)malloc(8 * 8 * 3 * sizeof(float)), *ib = (float *)malloc(8 * 8 * 3 * sizeof(float));
    if (!obj || !ia || !ib) {
        CHECK(0);
        free(obj);
        free(ia);
        free(ib);
        return;
    }
    CHECK(write_scratch("quad.obj", "v -1 0 -1\nv -1 0 1\nv 1 0 1\nv 1 0 -1\nf 1 2 3 4\n"));
    /* the same quad, its face between 250 degenerate faces before and 750 after */
    n += (size_t)snprintf(obj + n, 200000 - n, "%s", quad);
    n += (size_t)snprintf(obj + n, 200000 - n, "v 0.3 0 0.3\nv 0.5 0 0.5\nv 0.7 0 0.7\n"); /* 5-7 collinear */
    n += (size_t)snprintf(obj + n, 200000 - n, "v 1e3 0 0\nv 2e3 0 0\nv 3e3 0 0\n");       /* 8-10 far, collinear */
    for (i = 0; i < 1000; ++i) {
        static const char *const kinds[4] = {"f 5 5 5\n", "f 1 1 3\n", "f 5 6 7\n", "f 8 9 10\n"};
        if (i == 250) n += (size_t)snprintf(obj + n, 200000 - n, "f 1 2 3 4\n");
        n += (size_t)snprintf(obj + n, 200000 - n, "%s", kinds[i % 4]);
    }
    CHECK(write_scratch("quad-degenerate.obj", obj));
    n = 0;
    n += (size_t)snprintf(obj + n, 200000 - n, "%sf 1 2 3 4\nf 1 2 3 4\nf 4 3 2 1\n", quad);
    CHECK(write_scratch("quad-duplicate.obj", obj));
    CHECK(write_scratch("quad.scene", "mesh extremes-quad.obj\n"
                                      "light point position 0.2 1 0.1 intensity 1 1 1\n"
                                      "camera eye 0 2 2 target 0 0 0 up 0 1 0 fov 60\nimage 8 8\n"));
    CHECK(write_scratch("quad-degenerate.scene", "mesh extremes-quad-degenerate.obj\n"
                                                 "light point position 0.2 1 0.1 intensity 1 1 1\n"
                                                 "camera eye 0 2 2 target 0 0 0 up 0 1 0 fov 60\nimage 8 8\n"));
    CHECK(write_scratch("quad-duplicate.scene", "mesh extremes-quad-duplicate.obj\n"
                                                "light point position 0.2 1 0.1 intensity 1 1 1\n"
                                                "camera eye 0 2 2 target 0 0 0 up 0 1 0 fov 60\nimage 8 8\n"));
    a = load_scene("quad.scene");
    b = load_scene("quad-degenerate.scene");
    dup = load_scene("quad-duplicate.scene");
    if (a && b && dup) {
        appm_scene_get_info(b, &info);
        CHECK_MSG(info.triangles == 2 && info.dropped_triangles == 1000, "triangles %.0f, dropped %.0f",
                  (double)info.triangles, (double)info.dropped_triangles);
        CHECK(info.bbox_max[0] == 1.0 && info.bbox_min[0] == -1.0);
        appm_scene_get_info(dup, &info);
        CHECK(info.triangles == 6 && info.dropped_triangles == 0);
        for (mi = 0; mi < 4; ++mi) {
            appm_config cfg;
            img_sum sa, sb, sd;
            appm_stats st;
            appm_config_init(&cfg);
            cfg.method = methods[mi];
            cfg.photons = 4096;
            cfg.seed = 9;
            cfg.threads = 2;
            sa = render_sum(a, &cfg, 3, ia, NULL);
            sb = render_sum(b, &cfg, 3, ib, NULL);
            CHECK_MSG(sa.lum > 0.0 && memcmp(ia, ib, 8 * 8 * 3 * sizeof(float)) == 0,
                      "%s: 1000 degenerate triangles changed the image (mean %.6g vs %.6g)",
                      check_method_name(methods[mi]), sb.lum, sa.lum);
            sd = render_sum(dup, &cfg, 3, ib, &st);
            CHECK_MSG(sd.nonfinite == 0 && sd.min >= 0.0 && st.dropped_samples == 0,
                      "%s: duplicated triangles give %lu non-finite values, %.0f dropped",
                      check_method_name(methods[mi]), (unsigned long)sd.nonfinite, (double)st.dropped_samples);
            CHECK_MSG(fabs(sd.lum - sa.lum) <= 1e-3 * sa.lum, "%s: duplicated floor, mean %.9g vs %.9g",
                      check_method_name(methods[mi]), sd.lum, sa.lum);
            if (g_verbose)
                printf("duplicates %-4s mean %.9f single %.9f identical %d\n", check_method_name(methods[mi]),
                       sd.lum, sa.lum, memcmp(ia, ib, 8 * 8 * 3 * sizeof(float)) == 0);
        }
    }
    appm_scene_destroy(a);
    appm_scene_destroy(b);
    appm_scene_destroy(dup);
    free(obj);
    free(ia);
    free(ib);
}

/* ---- l. Lights of zero and of tiny area ----------------------------------------
 *
 * Good behaviour: an emissive material only on degenerate faces emits nothing
 * (power = pi A Ke = 0, and a zero-area emitter would have pdf 1/A = inf); the
 * faces are dropped, so a scene with no other light has no light, which is a
 * clear load error (APPM_ERR_PARSE, "no light"); with a point light as well,
 * it loads with no area light.
 *
 * A light of radiance Ke = 1e6 on a triangle of area 1e-12 is legal: its
 * power pi A Ke = pi 1e-6 shows in appm_scene_get_info (float area: 1e-6
 * relative), and next to a point light of power 4 pi the image stays finite,
 * nothing is dropped, and the mean moves by no more than its share of the
 * power (1.25e-7) plus the effect of choosing lights with pick probabilities
 * that moved by that much: 1e-3 relative is far above both. */
static void test_area_lights(void)
{
    static const appm_method methods[4] = {APPM_METHOD_APPM, APPM_METHOD_PPM, APPM_METHOD_SPPM,
                                           APPM_METHOD_PT};
    /* the tiny triangle lies in the plane y = 0.9 with legs of sqrt(2e-12),
     * exactly representable differences: area = 1e-12 */
    const double leg = sqrt(2e-12);
    char obj[1024];
    appm_scene *s, *tiny, *plain;
    appm_status st;
    appm_diag d;
    appm_scene_info info;
    int mi;
    CHECK(write_scratch("deg-light.mtl", "newmtl floor\nKd 0.5 0.5 0.5\nnewmtl glow\nKe 5 5 5\n"));
    CHECK(write_scratch("deg-light.obj", "mtllib extremes-deg-light.mtl\n"
                                         "v -1 0 -1\nv -1 0 1\nv 1 0 1\nv 1 0 -1\n"
                                         "v 0 1 0\nv 0.5 1 0\nv 1 1 0\n"
                                         "usemtl floor\nf 1 2 3 4\n"
                                         "usemtl glow\nf 5 6 7\nf 5 5 6\nf 7 7 7\n"));
    CHECK(write_scratch("deg-light.scene", "mesh extremes-deg-light.obj\n"
                                           "camera eye 0 2 2 target 0 0 0 up 0 1 0 fov 60\nimage 8 8\n"));
    CHECK(write_scratch("deg-light-point.scene", "mesh extremes-deg-light.obj\n"
                                                 "light point position 0 1 0 intensity 1 1 1\n"
                                                 "camera eye 0 2 2 target 0 0 0 up 0 1 0 fov 60\nimage 8 8\n"));
    s = NULL;
    st = appm_scene_load(check_path(GROUP, "deg-light.scene"), NULL, &s, &d);
    CHECK_MSG(st == APPM_ERR_PARSE && s == NULL && strstr(d.message, "no light") != NULL,
              "emission on degenerate faces only: status %d, '%s'", (int)st, d.message);
    s = load_scene("deg-light-point.scene");
    if (s) {
        appm_scene_get_info(s, &info);
        CHECK(info.lights_area == 0 && info.lights_point == 1 && info.dropped_triangles == 3);
        CHECK(info.power_area[0] == 0.0 && info.materials_emissive == 1);
    }
    appm_scene_destroy(s);

    snprintf(obj, sizeof obj,
             "mtllib extremes-tiny.mtl\n"
             "v -1 0 -1\nv -1 0 1\nv 1 0 1\nv 1 0 -1\n"
             "v 0 0.9 0\nv %.17g 0.9 0\nv 0 0.9 %.17g\n"
             "usemtl floor\nf 1 2 3 4\n"
             "usemtl glow\nf 5 6 7\n",
             leg, leg);
    CHECK(write_scratch("tiny.obj", obj));
    CHECK(write_scratch("tiny.mtl", "newmtl floor\nKd 0.5 0.5 0.5\nnewmtl glow\nKd 0 0 0\nKe 1e6 1e6 1e6\n"));
    CHECK(write_scratch("tiny.scene", "mesh extremes-tiny.obj\n"
                                      "light point position 0 1 0 intensity 2 2 2\n"
                                      "camera eye 0 2 2 target 0 0 0 up 0 1 0 fov 60\nimage 8 8\n"));
    CHECK(write_scratch("tiny-plain.scene", "mesh extremes-deg-light.obj\n"
                                            "light point position 0 1 0 intensity 2 2 2\n"
                                            "camera eye 0 2 2 target 0 0 0 up 0 1 0 fov 60\nimage 8 8\n"));
    tiny = load_scene("tiny.scene");
    plain = load_scene("tiny-plain.scene");
    if (tiny && plain) {
        uint32_t i;
        appm_scene_get_info(tiny, &info);
        CHECK(info.lights_area == 1 && info.lights_point == 1 && info.dropped_triangles == 0);
        for (i = 0; i < 3; ++i)
            CHECK_NEAR(info.power_area[i], APPM__PI * 1e-12 * 1e6, 1e-6 * APPM__PI * 1e-6);
        /* it faces down, towards the floor: (0,0.9,0) -> (leg,0.9,0) -> (0,0.9,leg)
         * is counter-clockwise seen from below */
        for (i = 0; i < tiny->ntri; ++i)
            if (tiny->info[i].light >= 0) CHECK(tiny->info[i].ng.y < -0.999f);
        for (mi = 0; mi < 4; ++mi) {
            appm_config cfg;
            appm_stats st1;
            img_sum a, b;
            appm_config_init(&cfg);
            cfg.method = methods[mi];
            cfg.photons = 4096;
            cfg.seed = 4;
            cfg.threads = 2;
            a = render_sum(tiny, &cfg, 4, NULL, &st1);
            b = render_sum(plain, &cfg, 4, NULL, NULL);
            CHECK_MSG(a.nonfinite == 0 && a.min >= 0.0 && st1.dropped_samples == 0,
                      "tiny bright light, %s: %lu non-finite, min %g, %.0f dropped", check_method_name(methods[mi]),
                      (unsigned long)a.nonfinite, a.min, (double)st1.dropped_samples);
            CHECK_MSG(fabs(a.lum - b.lum) <= 1e-3 * b.lum, "tiny bright light, %s: mean %.7g vs %.7g without",
                      check_method_name(methods[mi]), a.lum, b.lum);
        }
    }
    appm_scene_destroy(tiny);
    appm_scene_destroy(plain);
}

/* ---- b. Albedo 1 in a closed box -------------------------------------------------
 *
 * Good behaviour: with nothing absorbing, photon paths never lose weight, so
 * Russian roulette (continue with probability max(gamma') / max(gamma) = 1)
 * never ends them: only the depth cap does.  The render must still end - each
 * photon path is cut at max_depth (32) segments, the path tracer's roulette
 * is capped at 0.95 - and every pixel is finite.  Photons are stored at
 * segments 2 .. 31 (two segments at least with shadow rays for the direct
 * light; one eye segment must remain), so at most 30 per path: nearly all of
 * them, since the box is closed and watertight.
 *
 * With no absorption each bounce carries the full emitted power around again,
 * so the radiance grows about linearly in the number of bounces counted: a cap
 * of 3 segments (two bounces) gives far less than a cap of 32.  The check asks
 * for a factor of 3 (the expected factor is about 10). */
static void test_albedo_one(void)
{
    static const appm_method methods[4] = {APPM_METHOD_APPM, APPM_METHOD_PPM, APPM_METHOD_SPPM,
                                           APPM_METHOD_PT};
    const uint64_t M = 2048;
    appm_scene *s;
    int mi;
    s = load_scene("white.scene");
    if (!s) return;
    for (mi = 0; mi < 4; ++mi) {
        appm_config cfg;
        appm_stats st32, st3;
        img_sum deep, shallow;
        appm_config_init(&cfg);
        cfg.method = methods[mi];
        cfg.photons = M;
        cfg.seed = 2;
        cfg.threads = 2;
        deep = render_sum(s, &cfg, 2, NULL, &st32);
        cfg.max_depth = 3;
        shallow = render_sum(s, &cfg, 2, NULL, &st3);
        CHECK_MSG(deep.nonfinite == 0 && shallow.nonfinite == 0 && deep.min >= 0.0 && shallow.min >= 0.0,
                  "albedo 1, %s: non-finite or negative pixels", check_method_name(methods[mi]));
        CHECK_MSG(deep.lum > 3.0 * shallow.lum && shallow.lum > 0.0,
                  "albedo 1, %s: mean %.5g at depth 32 vs %.5g at depth 3", check_method_name(methods[mi]), deep.lum,
                  shallow.lum);
        if (methods[mi] != APPM_METHOD_PT)
            CHECK_MSG(st32.photons_stored <= 30 * M && st32.photons_stored >= 29 * M,
                      "albedo 1, %s: %.0f photons stored from %.0f paths (30 per path expected)",
                      check_method_name(methods[mi]), (double)st32.photons_stored, (double)M);
        if (g_verbose)
            printf("albedo 1 %-4s mean %.5f (depth 32) %.5f (depth 3) photons/path %.3f\n",
                   check_method_name(methods[mi]), deep.lum, shallow.lum, (double)st32.photons_stored / (double)M);
    }
    appm_scene_destroy(s);
}

/* ---- c. Camera inside a closed, unlit cube -----------------------------------------
 *
 * Good behaviour: from inside a closed cube whose lights are all outside, no
 * light path reaches the camera: shadow rays hit the walls, the path tracer
 * never escapes, photons land on the outside faces only.  The image is
 * exactly 0 in every pixel - not small, not NaN.
 *
 * For the photons this needs the kernel to stay on its own side of the
 * walls.  The gather is a sphere that takes photons whose normal is within
 * 60 degrees of the visible point's: that rejects the outside of the same
 * wall (opposite normal) and of the adjacent walls (perpendicular), but the
 * outside of the opposite wall faces the same way - the roof's outside is lit
 * from above and faces up, like the floor's inside - and lies 2 units away.
 * A gather wider than that would take those photons: light leaking through a
 * wall, the bias of every photon-mapping kernel wider than the room.  So the
 * view is narrow enough (16 x 16 pixels, 60 degrees) that the automatic
 * radius is small, r1 = 0.2 is given, and the largest radius any method
 * may use (appm: the larger of its upper bounds APPM__RHI and
 * APPM__RHI_DIFFUSE times max(r1, automatic)) is checked to stay below 2. */
static void test_camera_inside(void)
{
    static const appm_method methods[4] = {APPM_METHOD_APPM, APPM_METHOD_PPM, APPM_METHOD_SPPM,
                                           APPM_METHOD_PT};
    appm_scene *s;
    int mi;
    CHECK(write_scratch("closed.obj", "mtllib extremes-closed.mtl\n"
                                      "v -1 -1 -1\nv 1 -1 -1\nv 1 1 -1\nv -1 1 -1\n"
                                      "v -1 -1 1\nv 1 -1 1\nv 1 1 1\nv -1 1 1\n"
                                      "v -1 3 -1\nv 1 3 -1\nv 1 3 1\nv -1 3 1\n"
                                      "usemtl grey\n"
                                      "f 1 2 3 4\nf 5 8 7 6\nf 1 4 8 5\nf 2 6 7 3\nf 1 5 6 2\nf 4 3 7 8\n"
                                      "usemtl light\nf 9 10 11 12\n"));
    CHECK(write_scratch("closed.mtl", "newmtl grey\nKd 0.8 0.8 0.8\nnewmtl light\nKe 10 10 10\n"));
    CHECK(write_scratch("closed.scene", "mesh extremes-closed.obj\n"
                                        "light point position 0.5 4 0.3 intensity 10 10 10\n"
                                        "camera eye 0.1 -0.2 0.3 target 0 0.5 -1 up 0 1 0 fov 60\n"
                                        "image 16 16\n"));
    s = load_scene("closed.scene");
    if (!s) return;
    for (mi = 0; mi < 4; ++mi) {
        appm_config cfg;
        appm_renderer *r;
        appm_image img;
        appm_stats st;
        const float *rad;
        float rmax = 0.0f;
        size_t i, nonzero = 0;
        appm_config_init(&cfg);
        cfg.method = methods[mi];
        cfg.photons = 4096;
        cfg.radius = 0.2;
        cfg.threads = 2;
        r = check_renderer(s, &cfg);
        if (!r) continue;
        if (check_passes(r, 3)) {
            appm_renderer_image(r, &img);
            appm_renderer_stats(r, &st);
            for (i = 0; i < (size_t)16 * 16 * 3; ++i) nonzero += !(img.rgb[i] == 0.0f);
            rad = appm_renderer_aux(r, APPM_AUX_RADIUS);
            for (i = 0; rad && i < (size_t)16 * 16; ++i) rmax = rad[i] > rmax ? rad[i] : rmax;
            if (methods[mi] == APPM_METHOD_APPM) {
                double rb = r->r_auto > r->r1 ? r->r_auto : r->r1;
                double rhi = APPM__RHI > APPM__RHI_DIFFUSE ? APPM__RHI : APPM__RHI_DIFFUSE;
                CHECK_MSG(rhi * rb < 2.0, "the appm radius may reach %g", rhi * rb);
            }
            CHECK_MSG(rmax < 2.0, "inside a closed cube, %s: radius %g", check_method_name(methods[mi]), rmax);
            CHECK_MSG(nonzero == 0 && st.dropped_samples == 0, "inside a closed cube, %s: %lu values not 0",
                      check_method_name(methods[mi]), (unsigned long)nonzero);
            if (methods[mi] != APPM_METHOD_PT)
                CHECK_MSG(st.photons_stored > 0, "inside a closed cube, %s: the outside got no photons",
                          check_method_name(methods[mi]));
        }
        appm_renderer_destroy(r);
    }
    appm_scene_destroy(s);
}

/* ---- x. A light so bright its photons overflow float --------------------------------
 *
 * Good behaviour (testing.md I3): no NaN or inf ever reaches the image, and
 * whatever is discarded for being non-finite is counted in
 * stats.dropped_samples - or the scene is refused at load with a clear
 * message.
 *
 * What appm does with Ke = 1e38 (a finite float, but a photon of a 2 x 2
 * light would carry pi A Ke = 1.26e39 > FLT_MAX): it refuses it at load.
 * Every number in a scene, OBJ or MTL file must satisfy |x| <= 1e18 (so that
 * squares and products of coordinates stay far from float overflow), and the
 * error names the MTL file and line.  Ke = 1e39, which a float cannot hold at
 * all, is refused the same way.
 *
 * Under that limit the photons can still overflow: Ke = 1e18 on a light of
 * 2e12 x 2e12 (a scene in such units) emits pi A Ke = 1.3e43 W, so every
 * photon's float weight is infinite, while its shadow rays are fine (Le A cos
 * / (pick d^2) is about 4e18 at d = 1e12).  Then either the load refuses the
 * scene, or each method renders finite pixels and counts the photons it
 * discarded (dropped_samples > 0).  The path tracer uses no photons: finite
 * and lit is all it must be. */
static void test_overflow_light(void)
{
    static const appm_method methods[4] = {APPM_METHOD_APPM, APPM_METHOD_PPM, APPM_METHOD_SPPM,
                                           APPM_METHOD_PT};
    static const char obj[] = "mtllib extremes-%s.mtl\n"
                              "v -2 0 -2\nv -2 0 2\nv 2 0 2\nv 2 0 -2\n"
                              "v -1 1 -1\nv 1 1 -1\nv 1 1 1\nv -1 1 1\n"
                              "usemtl floor\nf 1 2 3 4\nusemtl light\nf 5 6 7 8\n";
    static const char big_obj[] = "mtllib extremes-huge.mtl\n"
                                  "v -2e12 0 -2e12\nv -2e12 0 2e12\nv 2e12 0 2e12\nv 2e12 0 -2e12\n"
                                  "v -1e12 1e12 -1e12\nv 1e12 1e12 -1e12\nv 1e12 1e12 1e12\nv -1e12 1e12 1e12\n"
                                  "usemtl floor\nf 1 2 3 4\nusemtl light\nf 5 6 7 8\n";
    static const char *const names[2] = {"hot", "inf"};
    char text[512], file[64];
    appm_scene *s = NULL;
    appm_status st;
    appm_diag d;
    int mi, k;
    for (k = 0; k < 2; ++k) {
        snprintf(text, sizeof text, obj, names[k]);
        snprintf(file, sizeof file, "%s.obj", names[k]);
        CHECK(write_scratch(file, text));
        snprintf(text, sizeof text, "newmtl floor\nKd 0.5 0.5 0.5\nnewmtl light\nKe %s %s %s\n",
                 k ? "1e39" : "1e38", k ? "1e39" : "1e38", k ? "1e39" : "1e38");
        snprintf(file, sizeof file, "%s.mtl", names[k]);
        CHECK(write_scratch(file, text));
        snprintf(text, sizeof text,
                 "mesh extremes-%s.obj\ncamera eye 0 0.5 3 target 0 0.5 0 up 0 1 0 fov 70\nimage 8 8\n", names[k]);
        snprintf(file, sizeof file, "%s.scene", names[k]);
        CHECK(write_scratch(file, text));
        st = appm_scene_load(check_path(GROUP, file), NULL, &s, &d);
        snprintf(file, sizeof file, "%s.mtl", names[k]);
        CHECK_MSG(st == APPM_ERR_PARSE && s == NULL && d.line == 4 && strstr(d.file, file) != NULL &&
                      strstr(d.message, "Ke") != NULL,
                  "Ke %s: status %d at %s:%u: %s", k ? "1e39" : "1e38", (int)st, d.file, d.line, d.message);
        appm_scene_destroy(s);
        s = NULL;
    }

    CHECK(write_scratch("huge.obj", big_obj));
    CHECK(write_scratch("huge.mtl", "newmtl floor\nKd 0.5 0.5 0.5\nnewmtl light\nKe 1e18 1e18 1e18\n"));
    CHECK(write_scratch("huge.scene", "mesh extremes-huge.obj\n"
                                      "camera eye 0 0.5e12 3e12 target 0 0.5e12 0 up 0 1 0 fov 70\n"
                                      "image 8 8\n"));
    st = appm_scene_load(check_path(GROUP, "huge.scene"), NULL, &s, &d);
    if (st != APPM_OK) {
        CHECK_MSG(st == APPM_ERR_PARSE && d.message[0] != 0, "huge light: status %d (%s)", (int)st, d.message);
        return;
    }
    for (mi = 0; mi < 4; ++mi) {
        appm_config cfg;
        appm_stats stats;
        img_sum sum;
        appm_config_init(&cfg);
        cfg.method = methods[mi];
        cfg.photons = 2048;
        cfg.threads = 2;
        sum = render_sum(s, &cfg, 2, NULL, &stats);
        CHECK_MSG(sum.lum > 0.0 && sum.nonfinite == 0, "huge light, %s: mean %g, %lu non-finite values",
                  check_method_name(methods[mi]), sum.lum, (unsigned long)sum.nonfinite);
        if (methods[mi] != APPM_METHOD_PT)
            CHECK_MSG(stats.dropped_samples > 0,
                      "huge light, %s: %.0f photons stored, %.0f samples dropped - photons whose power "
                      "overflows float were discarded without being counted",
                      check_method_name(methods[mi]), (double)stats.photons_stored, (double)stats.dropped_samples);
        if (g_verbose)
            printf("huge light %-4s mean %.4g dropped %.0f stored %.0f\n", check_method_name(methods[mi]), sum.lum,
                   (double)stats.dropped_samples, (double)stats.photons_stored);
    }
    appm_scene_destroy(s);
}

/* ---- t. More threads than rows -----------------------------------------------------
 *
 * Good behaviour (testing.md R3): the image depends only on scene, config,
 * seed and passes.  64 threads on an 8-row image (more workers than row tasks;
 * 64 photon-store regions for 2 chunks of photon paths) give the same bytes as
 * one thread, for every method. */
static void test_threads(void)
{
    static const appm_method methods[4] = {APPM_METHOD_APPM, APPM_METHOD_PPM, APPM_METHOD_SPPM,
                                           APPM_METHOD_PT};
    appm_scene *s = load_scene("box.scene");
    int mi;
    if (!s) return;
    for (mi = 0; mi < 4; ++mi) {
        appm_config cfg;
        appm_stats st;
        float one[8 * 8 * 3], many[8 * 8 * 3];
        img_sum a;
        appm_config_init(&cfg);
        cfg.method = methods[mi];
        cfg.photons = 2000;
        cfg.seed = 8;
        cfg.threads = 1;
        a = render_sum(s, &cfg, 3, one, NULL);
        cfg.threads = 64;
        render_sum(s, &cfg, 3, many, &st);
        /* a build without threads runs on 1, whatever it is asked */
        CHECK_MSG(a.lum > 0.0 && memcmp(one, many, sizeof one) == 0 && st.threads == (APPM_THREADS ? 64u : 1u),
                  "%s: 64 threads differ from 1 (threads used %u)", check_method_name(methods[mi]), st.threads);
    }
    appm_scene_destroy(s);
}

/* ---- main ---------------------------------------------------------------------------- */

static int wanted(char group)
{
    const char *only = getenv("APPM_TEST_ONLY");
    return !only || !only[0] || strchr(only, group) != NULL;
}

int main(void)
{
    g_verbose = getenv("APPM_TEST_VERBOSE") != NULL;
    /* the scenes that several groups share */
    CHECK(write_scratch("plane.obj", PLANE_OBJ) && write_scratch("plane.mtl", PLANE_MTL) &&
          write_scratch("plane.scene", PLANE_SCENE) && write_box("box", 1.0, 0.0, 8) &&
          write_scratch("white.obj", WHITE_BOX_OBJ) && write_scratch("white.mtl", WHITE_BOX_MTL) &&
          write_scratch("white.scene", WHITE_BOX_SCENE));
    if (wanted('r')) {
        test_radius();
        test_radius_warning();
    }
    if (wanted('a')) test_alpha();
    if (wanted('o')) test_photon_counts();
    if (wanted('n')) test_accumulators();
    if (wanted('s')) test_scale();
    if (wanted('d')) test_degenerate_scene();
    if (wanted('l')) test_area_lights();
    if (wanted('b')) test_albedo_one();
    if (wanted('c')) test_camera_inside();
    if (wanted('x')) test_overflow_light();
    if (wanted('t')) test_threads();
    return check_finish();
}
