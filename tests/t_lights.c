/* tests/t_lights.c - lights for any scene: the white environment a bare OBJ
 * without light gets with appm_config.stand_in = APPM_STAND_IN_WHITE (the
 * studio, the default, is tested at the end, with the photons it aims at its
 * model: appm.c 6.3), and the lights added to a loaded scene
 * (appm_scene_add_point_light, appm_scene_set_environment).
 *
 * The scene is one two-sided Lambertian square, albedo rho = 0.5, side 2, in
 * the plane z = 0, framed by the automatic camera (looking along -z).  Analytic
 * answers, rendered with the unbiased path tracer:
 *   - constant environment L, nothing else in the way: every point of the
 *     square sees the whole upper hemisphere, E = pi L, so Lo = rho L = 0.5 L;
 *     a pixel that misses the square sees L itself;
 *   - point light of intensity I at distance d on the square's axis: at the
 *     centre E = I / d^2, Lo = rho / pi * I / d^2 (= 0.5 for I = 4 pi, d = 2),
 *     and off-centre by s: E = I d / (d^2 + s^2)^(3/2).
 * Powers (appm_scene_info): point 4 pi I, environment 4 pi^2 R^2 L with R the
 * bounding-sphere radius (here sqrt 2). */
#include "../appm.c"
#include "check.h"

static const char QUAD_OBJ[] = "mtllib q.mtl\nusemtl grey\n"
                               "v -1 -1 0\nv 1 -1 0\nv 1 1 0\nv -1 1 0\nf 1 2 3 4\n";
static const char QUAD_MTL[] = "newmtl grey\nKd 0.5 0.5 0.5\n";

/* The quad under the white stand-in (appm_config.stand_in), cfg's other
 * fields as given (cfg may be NULL). */
static appm_scene *load_quad(const appm_config *cfg)
{
    appm_scene *s = NULL;
    appm_diag d;
    appm_config white;
    appm_status st;
    if (cfg) white = *cfg;
    else appm_config_init(&white);
    white.stand_in = APPM_STAND_IN_WHITE;
    st = appm_scene_load_obj_memory(QUAD_OBJ, strlen(QUAD_OBJ), QUAD_MTL, strlen(QUAD_MTL), "quad.obj", &white, &s,
                                    &d);
    CHECK_MSG(st == APPM_OK, "%s:%u: %s", d.file, d.line, d.message);
    return s;
}

/* Mean of channel 1 over the pixels of the square [x0, x1) x [y0, y1). */
static double rect_mean(const appm_image *img, uint32_t x0, uint32_t x1, uint32_t y0, uint32_t y1)
{
    double sum = 0.0;
    uint32_t x, y;
    for (y = y0; y < y1; ++y)
        for (x = x0; x < x1; ++x) sum += img->rgb[3 * ((size_t)y * img->width + x) + 1];
    return sum / ((double)(x1 - x0) * (y1 - y0));
}

/* Renders `passes` passes of `method` at 32x32 into *img (a copy, to free). */
static int render_method(const appm_scene *s, appm_method method, int passes, check_log *w, appm_image *img)
{
    appm_config cfg;
    appm_renderer *r = NULL;
    appm_diag d;
    appm_image view;
    int k;
    appm_config_init(&cfg);
    cfg.method = method;
    cfg.width = cfg.height = 32;
    cfg.threads = 1; /* a build without threads would warn about 2 */
    cfg.log = check_on_log;
    cfg.log_user = w;
    img->rgb = NULL;
    if (appm_renderer_create(s, &cfg, &r, &d) != APPM_OK) {
        CHECK_MSG(0, "renderer: %s", d.message);
        return 0;
    }
    for (k = 0; k < passes; ++k) CHECK(appm_renderer_pass(r) == APPM_OK);
    appm_renderer_image(r, &view);
    *img = view;
    img->rgb = (float *)malloc(sizeof(float) * 3 * 32 * 32);
    if (img->rgb) memcpy(img->rgb, view.rgb, sizeof(float) * 3 * 32 * 32);
    appm_renderer_destroy(r);
    return img->rgb != NULL;
}

/* The same with the path tracer. */
static int render_lights(const appm_scene *s, int passes, check_log *w, appm_image *img)
{
    return render_method(s, APPM_METHOD_PT, passes, w, img);
}

static void test_white_environment(void)
{
    appm_scene *s = load_quad(NULL);
    appm_scene_info in;
    appm_image img;
    check_log w = {0, 0, ""};
    const double R = sqrt(2.0), want = 4.0 * APPM__PI * APPM__PI * R * R;
    if (!s) return;
    appm_scene_get_info(s, &in);
    CHECK(in.lights_environment == 1 && in.lights_point == 0 && in.lights_area == 0);
    CHECK(s->focus_r == 0.0f); /* only the studio aims its photons (6.3) */
    CHECK_NEAR(in.power_environment[0], want, want * 1e-6);
    CHECK_NEAR(in.power_environment[2], want, want * 1e-6);
    if (render_lights(s, check_quick() ? 16 : 64, &w, &img)) {
        double centre = rect_mean(&img, 12, 20, 12, 20), corner = rect_mean(&img, 0, 2, 0, 2);
        CHECK_NEAR(centre, 0.5, check_quick() ? 0.04 : 0.02); /* rho L */
        CHECK_NEAR(corner, 1.0, 1e-6);                        /* the environment itself */
        free(img.rgb);
    }
    CHECK_MSG(w.n == 1 && strstr(w.last, "white environment") != NULL, "%d warnings, last '%s'", w.n, w.last);
    appm_scene_destroy(s);
}

static void test_point_light_falloff(void)
{
    appm_scene *s = load_quad(NULL);
    appm_scene_info in;
    appm_image img;
    appm_diag d;
    check_log w = {0, 0, ""};
    const double pos[3] = {0, 0, 2}, I[3] = {4 * APPM__PI, 4 * APPM__PI, 4 * APPM__PI};
    const double bad[3] = {1, -1, 1}, nan3[3] = {0, (double)NAN, 0};
    if (!s) return;
    CHECK(appm_scene_add_point_light(s, pos, bad, &d) == APPM_ERR_INVALID_ARG);
    CHECK(appm_scene_add_point_light(s, nan3, I, &d) == APPM_ERR_INVALID_ARG);
    CHECK(appm_scene_add_point_light(NULL, pos, I, &d) == APPM_ERR_INVALID_ARG);
    appm_scene_get_info(s, &in);
    CHECK(in.lights_environment == 1 && in.lights_point == 0); /* unchanged by the refusals */
    CHECK(appm_scene_add_point_light(s, pos, I, &d) == APPM_OK);
    appm_scene_get_info(s, &in);
    CHECK(in.lights_environment == 0 && in.lights_point == 1); /* the stand-in is gone */
    CHECK_NEAR(in.power_point[1], 16.0 * APPM__PI * APPM__PI, 1e-3);
    if (render_lights(s, 4, &w, &img)) {
        /* the central 2x2 pixels reach s = 0.1 off the axis: E falls by < 0.4 % there */
        double centre = rect_mean(&img, 15, 17, 15, 17), corner = rect_mean(&img, 0, 2, 0, 2);
        CHECK_NEAR(centre, 0.5, 0.006);
        CHECK(corner == 0.0); /* no environment any more */
        free(img.rgb);
    }
    CHECK_MSG(w.n == 0, "%d warnings, last '%s'", w.n, w.last);
    /* a second point light behind the square: it lights the back face only, so
     * the camera's side keeps its mean.  Every shading point sends a shadow ray
     * to each point light (appm.c 6.4), so 4 passes give it as closely as one
     * light did; picking one light by power, half the time each, would give 1
     * or 0 a sample (the mean of 16 samples off by 0.125 per sample off half). */
    {
        const double back[3] = {0, 0, -2};
        CHECK(appm_scene_add_point_light(s, back, I, &d) == APPM_OK);
        appm_scene_get_info(s, &in);
        CHECK(in.lights_point == 2);
        CHECK(s->nnee_delta == 2 && s->nee_cdf[0][s->nlight] == 0.0); /* nothing left to pick */
        CHECK_NEAR(in.power_point[0], 32.0 * APPM__PI * APPM__PI, 1e-3);
        if (render_lights(s, 4, &w, &img)) {
            CHECK_NEAR(rect_mean(&img, 15, 17, 15, 17), 0.5, 0.006);
            free(img.rgb);
        }
    }
    appm_scene_destroy(s);
}

/* Shadow rays (appm.c 6.4): a point light of intensity 4 pi at height 2 over
 * the square (0.5 at its centre) and a constant environment L = 1/4 (rho L =
 * 0.125), so 0.625.  The point light gets a shadow ray at every shading point
 * and the environment one cosine-distributed sample, exact for a constant sky
 * seen whole: 4 passes of appm and of the path tracer give 0.625 within the
 * pixels' own spread.  Picked by power (the point light 0.89 of it) one
 * sample in nine would see only the sky, at 9x its weight.  Beyond
 * APPM__NEE_DELTA point lights the weakest join the one sample: nine lights at
 * one place with intensities 1 : 2 : ... : 9 (4 pi in all) give the eight
 * strongest a ray each and leave the weakest alone in the one sample (no
 * choice, weight 1), so every sample is 0.5. */
static void test_delta_lights_every_point(void)
{
    appm_scene *s = load_quad(NULL);
    appm_image img;
    appm_diag d;
    check_log w = {0, 0, ""};
    const double pos[3] = {0, 0, 2}, I[3] = {4 * APPM__PI, 4 * APPM__PI, 4 * APPM__PI};
    const double L[3] = {0.25, 0.25, 0.25};
    const appm_method methods[2] = {APPM_METHOD_APPM, APPM_METHOD_PT};
    int k, m;
    if (!s) return;
    CHECK(appm_scene_set_environment(s, L, &d) == APPM_OK);
    CHECK(appm_scene_add_point_light(s, pos, I, &d) == APPM_OK);
    CHECK(s->nnee_delta == 1 && s->nee_cdf[0][s->nlight] == 1.0);
    CHECK_NEAR(s->light[s->env].nee[0], 1.0, 1e-12);    /* the sky alone is picked */
    CHECK(s->light[s->env].pick < 0.2);             /* while photons start mostly at the point light */
    CHECK(appm__light_dims(s, 0) == 2u);            /* no choice left to draw */
    CHECK(s->nee_cdf[1][s->nlight] == 0.0);         /* the path tracer's BSDF sample finds the sky */
    {
        appm_scene_info in;
        appm_scene_get_info(s, &in);
        CHECK(in.shadow_rays_own == 1 && in.shadow_rays_picked == 1 && in.shadow_rays_samples == 1);
    }
    for (m = 0; m < 2; ++m)
        if (render_method(s, methods[m], 4, &w, &img)) {
            CHECK_NEAR(rect_mean(&img, 15, 17, 15, 17), 0.625, 0.006);
            free(img.rgb);
        }
    appm_scene_destroy(s);
    s = load_quad(NULL);
    if (!s) return;
    for (k = 0; k < 9; ++k) {
        const double f = 4 * APPM__PI * (k + 1) / 45.0, Ik[3] = {f, f, f};
        CHECK(appm_scene_add_point_light(s, pos, Ik, &d) == APPM_OK);
    }
    CHECK(s->nlight == 9 && s->nnee_delta == 8 && s->nee_cdf[0][s->nlight] == 1.0);
    CHECK(!s->light[0].nee_all && s->light[0].nee[0] == 1.0); /* the weakest, picked */
    for (k = 1; k < 9; ++k) CHECK(s->light[k].nee_all && s->light[k].nee[0] == 0.0);
    {
        appm_scene_info in;
        appm_scene_get_info(s, &in);
        CHECK(in.shadow_rays_own == 8 && in.shadow_rays_picked == 1);
    }
    CHECK(appm__light_dims(s, 0) == 0u);
    for (m = 0; m < 2; ++m)
        if (render_method(s, methods[m], 4, &w, &img)) {
            CHECK_NEAR(rect_mean(&img, 15, 17, 15, 17), 0.5, 0.006);
            free(img.rgb);
        }
    CHECK_MSG(w.n == 0, "%d warnings, last '%s'", w.n, w.last);
    appm_scene_destroy(s);
}

/* The path tracer's shadow-ray table (appm.c 6.4) leaves a constant sky to
 * its BSDF sample, and its MIS weights must use that table's probabilities,
 * not appm's.  Two strips emitting L_e = 4 downwards (Kd 0: they only emit
 * and block) at height c = 1/2 over the square, |x| in [0.3, 0.8], |y| < 1/2,
 * under a sky of L = 1/4.  At the centre the strips fill a cosine-weighted
 * share F of the hemisphere (the form factor of a point to a parallel
 * rectangle over one of its corners, F(a, b) = (X/sqrt(1+X^2) atan(Y/sqrt(1+X^2))
 * + Y/sqrt(1+Y^2) atan(X/sqrt(1+Y^2))) / 2pi, X = a/c, Y = b/c, summed over
 * corners with signs), and the sky the rest: Lo = rho (L_e F + L (1 - F)) =
 * 0.5592; symmetric in x, so within 0.1 of the centre F moves by < 1 %.
 * Nothing the camera sees gathers photons (the square's bounces leave or end
 * on the strips), so appm's image is its direct light too. */
static double corner_ff(double a, double b, double c)
{
    double X = fabs(a) / c, Y = fabs(b) / c, sx = sqrt(1 + X * X), sy = sqrt(1 + Y * Y);
    double f = (X / sx * atan(Y / sx) + Y / sy * atan(X / sy)) / (2 * APPM__PI);
    return (a < 0) != (b < 0) ? -f : f;
}

static void test_pt_sky_by_bsdf(void)
{
    static const char obj[] = "mtllib s.mtl\nusemtl grey\nv -1 -1 0\nv 1 -1 0\nv 1 1 0\nv -1 1 0\nf 1 2 3 4\n"
                              "usemtl lamp\nv 0.3 -0.5 0.5\nv 0.3 0.5 0.5\nv 0.8 0.5 0.5\nv 0.8 -0.5 0.5\nf 5 6 7 8\n"
                              "v -0.8 -0.5 0.5\nv -0.8 0.5 0.5\nv -0.3 0.5 0.5\nv -0.3 -0.5 0.5\nf 9 10 11 12\n";
    static const char mtl[] = "newmtl grey\nKd 0.5 0.5 0.5\nnewmtl lamp\nKd 0 0 0\nKe 4 4 4\n";
    const double L[3] = {0.25, 0.25, 0.25}, c = 0.5;
    const appm_method methods[2] = {APPM_METHOD_APPM, APPM_METHOD_PT};
    double F = 0.0, want, area[2] = {0, 0};
    appm_scene *s = NULL;
    appm_diag d;
    appm_image img;
    check_log w = {0, 0, ""};
    uint32_t k;
    int m, side;
    for (side = -1; side <= 1; side += 2) { /* x in side * [0.3, 0.8], y in [-0.5, 0.5] */
        double x0 = side < 0 ? -0.8 : 0.3, x1 = side < 0 ? -0.3 : 0.8;
        F += corner_ff(x1, 0.5, c) - corner_ff(x0, 0.5, c) - corner_ff(x1, -0.5, c) + corner_ff(x0, -0.5, c);
    }
    want = 0.5 * (4.0 * F + 0.25 * (1.0 - F));
    CHECK_NEAR(want, 0.5592, 1e-4);
    CHECK(appm_scene_load_obj_memory(obj, strlen(obj), mtl, strlen(mtl), "strips.obj", NULL, &s, &d) == APPM_OK);
    if (!s) return;
    CHECK(appm_scene_set_environment(s, L, &d) == APPM_OK);
    for (k = 0; k < s->nlight; ++k)
        if (s->light[k].kind == APPM__LIGHT_AREA) {
            area[0] += s->light[k].nee[0];
            area[1] += s->light[k].nee[1];
        }
    CHECK_NEAR(area[1], 1.0, 1e-12); /* the path tracer's table: the strips alone */
    CHECK(area[0] > 0.2 && area[0] < 0.8); /* appm's: the strips and the sky by power */
    CHECK(s->light[s->env].nee[1] == 0.0 && s->light[s->env].nee[0] > 0.2);
    for (m = 0; m < 2; ++m)
        if (render_method(s, methods[m], 256, &w, &img)) {
            double got = rect_mean(&img, 15, 17, 15, 17);
            CHECK_MSG(fabs(got - want) < 0.012, "%s: %.4f, want %.4f", m ? "pt" : "appm", got, want);
            free(img.rgb);
        }
    CHECK_MSG(w.n == 0, "%d warnings, last '%s'", w.n, w.last);
    appm_scene_destroy(s);
}

static void test_set_environment(void)
{
    appm_scene *s = load_quad(NULL);
    appm_scene_info in;
    appm_image img;
    appm_diag d;
    check_log w = {0, 0, ""};
    const double L[3] = {2, 2, 2}, zero[3] = {0, 0, 0}, inf3[3] = {1, (double)HUGE_VAL, 1};
    const double want = 4.0 * APPM__PI * APPM__PI * 2.0 * 2.0;
    if (!s) return;
    /* the stand-in may not be replaced by nothing */
    CHECK(appm_scene_set_environment(s, zero, &d) != APPM_OK);
    CHECK(appm_scene_set_environment(s, inf3, &d) == APPM_ERR_INVALID_ARG);
    appm_scene_get_info(s, &in);
    CHECK(in.lights_environment == 1);
    CHECK_NEAR(in.power_environment[0], want / 2.0, want * 1e-6);
    CHECK(appm_scene_set_environment(s, L, &d) == APPM_OK);
    CHECK(appm_scene_set_environment(s, L, &d) == APPM_OK); /* replaces, never adds */
    appm_scene_get_info(s, &in);
    CHECK(in.lights_environment == 1);
    CHECK_NEAR(in.power_environment[0], want, want * 1e-6);
    if (render_lights(s, check_quick() ? 16 : 64, &w, &img)) {
        CHECK_NEAR(rect_mean(&img, 12, 20, 12, 20), 1.0, check_quick() ? 0.08 : 0.04);
        CHECK_NEAR(rect_mean(&img, 0, 2, 0, 2), 2.0, 1e-6);
        free(img.rgb);
    }
    CHECK(w.n == 0); /* a chosen environment is no stand-in */
    appm_scene_destroy(s);
}

/* A failed allocation leaves the scene as it was and leaks nothing. */
static void test_allocation_failure(void)
{
    const double pos[3] = {0, 0, 2}, I[3] = {1, 1, 1};
    long n;
    int ok = 0, bad = 0;
    for (n = 1; n < 20 && !ok; ++n) {
        appm_config cfg;
        check_alloc a;
        appm_scene *s;
        appm_scene_info in;
        appm_diag d;
        long long before;
        memset(&cfg, 0, sizeof cfg);
        check_use_alloc(&cfg, &a, 0);
        s = load_quad(&cfg);
        if (!s) return;
        before = a.live;
        a.fail_at = a.count + n;
        if (appm_scene_add_point_light(s, pos, I, &d) == APPM_OK) {
            ok = 1;
        } else {
            appm_scene_get_info(s, &in);
            if (a.live != before || in.lights_point != 0 || in.lights_environment != 1 || d.status != APPM_ERR_NOMEM)
                bad++;
        }
        appm_scene_destroy(s);
        if (a.live != 0) bad++;
    }
    CHECK(ok && n > 2);
    CHECK(bad == 0);
}

/* The studio (appm_config.stand_in's default): a ground plate under the
 * model, facing up; a sky map brighter above than below with a key light;
 * the camera 20 degrees above.  A sphere rendered in it differs from the
 * image's corners by more than 30 % in luminance (the measure of
 * "form"), and a light the user adds replaces the sky, not the plate. */
/* A unit sphere (12 x 24 quads, no material: the default, Kd 0.8, as the
 * bunny's) loaded as a bare OBJ, so in the studio; NULL on failure. */
static appm_scene *studio_sphere(void)
{
    char obj[64 * 1024];
    size_t at = 0;
    int i, j, n = 12;
    appm_scene *s = NULL;
    appm_diag d;
    for (i = 0; i <= n; ++i)
        for (j = 0; j < 2 * n; ++j) {
            double th = APPM__PI * i / n, ph = APPM__PI * j / n;
            at += (size_t)snprintf(obj + at, sizeof obj - at, "v %.6f %.6f %.6f\n", sin(th) * cos(ph), cos(th),
                                   sin(th) * sin(ph));
        }
    for (i = 0; i < n; ++i)
        for (j = 0; j < 2 * n; ++j) {
            int a = i * 2 * n + j + 1, b = i * 2 * n + (j + 1) % (2 * n) + 1;
            at += (size_t)snprintf(obj + at, sizeof obj - at, "f %d %d %d %d\n", a, a + 2 * n, b + 2 * n, b);
        }
    CHECK(appm_scene_load_obj_memory(obj, at, NULL, 0, "sphere.obj", NULL, &s, &d) == APPM_OK);
    return s;
}

static void test_studio(void)
{
    appm_scene *s = studio_sphere();
    appm_diag d;
    appm_scene_info in;
    appm_image img;
    check_log w = {0, 0, ""};
    uint32_t t, plate = 0;
    if (!s) return;
    /* the photons' focus (6.3): the model's bounding sphere, not the plate's */
    CHECK(fabsf(s->focus.x) < 1e-5f && fabsf(s->focus.y) < 1e-5f && fabsf(s->focus.z) < 1e-5f);
    CHECK(fabsf(s->focus_r - sqrtf(3.0f)) < 1e-4f);
    appm_scene_get_info(s, &in);
    CHECK(in.lights_environment == 1 && in.environment_map_width == 128 && in.environment_map_height == 64);
    CHECK(in.shadow_rays_samples == APPM__SKY_SAMPLES); /* the sky's four a shading point (appm__direct) */
    for (t = 0; t < s->ntri; ++t)
        if (s->info[t].ng.y > 0.999f && s->tri[t].p0.y < -1.0f && s->tri[t].p0.y > -1.01f) {
            const appm__v3 p[3] = {s->tri[t].p0, s->tri[t].p1, s->tri[t].p2};
            int k;
            plate++;
            CHECK(s->mat[s->info[t].mat].color.x == 0.5f && s->info[t].area > 3.9f);
            for (k = 0; k < 3; ++k) /* the plate the emission aims at (appm__focus_disk) is this one */
                CHECK(p[k].y == s->plate.y && fabsf(fabsf(p[k].x - s->plate.x) - s->plate_e) < 1e-5f &&
                      fabsf(fabsf(p[k].z - s->plate.z) - s->plate_e) < 1e-5f);
        }
    CHECK(plate == 2 && s->plate_e > 2.0f * s->focus_r - 1e-5f);
    CHECK(s->cam.forward.y < -0.33f && s->cam.forward.y > -0.35f); /* 20 degrees down */
    {
        appm__v3 up = appm__env_radiance(s, appm__v(0, 1, 0)), down = appm__env_radiance(s, appm__v(0, -1, 0));
        appm__v3 key = appm__env_radiance(s, appm__normalize(appm__v(-0.55f, 0.72f, 0.42f)));
        CHECK(up.y > 3.0f * down.y && key.y > 10.0f * up.y);
    }
    if (render_lights(s, check_quick() ? 8 : 32, &w, &img)) {
        double centre = rect_mean(&img, 12, 20, 12, 20);
        double corners = (rect_mean(&img, 0, 3, 0, 3) + rect_mean(&img, 29, 32, 0, 3) + rect_mean(&img, 0, 3, 29, 32) +
                          rect_mean(&img, 29, 32, 29, 32)) / 4.0;
        CHECK_MSG(fabs(centre - corners) > 0.3 * corners, "centre %g, corners %g", centre, corners);
        free(img.rgb);
    }
    CHECK_MSG(w.n == 1 && strstr(w.last, "studio") != NULL, "%d warnings, last '%s'", w.n, w.last);
    {
        const double pos[3] = {0, 3, 2}, I[3] = {1, 1, 1};
        CHECK(appm_scene_add_point_light(s, pos, I, &d) == APPM_OK);
        appm_scene_get_info(s, &in);
        CHECK(in.lights_environment == 0 && in.environment_map_width == 0 && s->envmap.rgb == NULL);
        for (t = 0, plate = 0; t < s->ntri; ++t) /* the plate is geometry: it stays */
            plate += s->info[t].ng.y > 0.999f && s->tri[t].p0.y < -1.0f && s->tri[t].p0.y > -1.01f;
        CHECK(plate == 2);
    }
    appm_scene_destroy(s);
}

/* A diffuse material of grey albedo `albedo` and a surface point at the
 * origin facing +y, for the aimed bounce's tests. */
static void focus_surface(appm__material *m, appm__surf *sf, float albedo)
{
    memset(m, 0, sizeof *m);
    memset(sf, 0, sizeof *sf);
    m->kind = APPM__MAT_DIFFUSE;
    m->color = appm__v(albedo, albedo, albedo);
    sf->ng = sf->ns = appm__v(0, 1, 0);
}

/* The studio's aimed diffuse bounce (appm__focus_bounce): a surface facing
 * +y at the origin, the focus sphere (radius rf) at height D above it.  Over
 * a 1024 x 1024 grid of (u1, u2), the mean of the weight factor `steer`
 * estimates the cosine lobe's integral, 1, and its mean where the direction
 * falls in the sphere's cone the lobe's share of the cone, sin^2 theta_max =
 * (rf / D)^2 (the cone's axis along the normal): one-sample importance
 * sampling with the mixture's density is unbiased, though more than three
 * quarters of the directions go into the cone. */
static void test_focus_bounce(void)
{
    static appm_scene sc; /* zero: only focus and focus_r are read */
    appm__material m;
    appm__surf sf;
    const int n = 1024; /* the rim's discontinuity: 512 leaves 2e-3 */
    const float D = 3.0f, rf = 1.0f;
    double all = 0.0, cone = 0.0, inside = 0.0;
    int i, k, fails = 0;
    focus_surface(&m, &sf, 0.5f);
    sc.focus = appm__v(0, D, 0);
    sc.focus_r = rf;
    CHECK(appm__focus_aims(&sc, &m, &sf, appm__v(0, 1, 0)));
    CHECK(!appm__focus_aims(&sc, &m, &sf, appm__v(0, -1, 0))); /* seen from below: the sphere is behind */
    sf.p = appm__v(0, D - 0.5f, 0);
    CHECK(!appm__focus_aims(&sc, &m, &sf, appm__v(0, 1, 0))); /* inside the sphere: the lobe alone */
    sf.p = appm__v(0, 0, 0);
    for (i = 0; i < n; ++i)
        for (k = 0; k < n; ++k) {
            appm__bsdf_sample bs;
            float steer = 0.0f;
            if (!appm__focus_bounce(&sc, &m, &sf, appm__v(0, 1, 0), (i + 0.5f) / n, (k + 0.5f) / n, &bs, &steer)) {
                fails++;
                continue;
            }
            all += steer;
            if (bs.wi.y >= sqrtf(1.0f - rf * rf / (D * D))) {
                cone += steer;
                inside += 1.0;
            }
            if (!(bs.weight.x == 0.5f && bs.pdf > 0.0f && fabsf(appm__length(bs.wi) - 1.0f) < 1e-5f)) fails++;
        }
    all /= (double)n * n;
    cone /= (double)n * n;
    CHECK(fails == 0);
    CHECK_NEAR(all, 1.0, 2e-3);
    CHECK_NEAR(cone, (double)(rf * rf) / (D * D), 2e-3);
    CHECK(inside > 0.7 * n * n); /* the cone's 3/4, and the lobe's own share of it */
}

/* The same with a cone partly below the horizon and seen from the surface's
 * back (the side flip): a surface facing +y seen from below (wo = -y), the
 * sphere below it and to the side, its axis 11 degrees from the surface and
 * its half-angle 19 degrees.  The mean of `steer` is still the lobe's integral, 1 (the
 * cone's directions below the surface are lost, the lobe's weight makes up
 * for them), and its mean within the cone the cosine lobe's probability of
 * the cone, counted independently from 1024 x 1024 cosine-lobe directions. */
static void test_focus_oblique(void)
{
    static appm_scene sc;
    appm__material m;
    appm__surf sf;
    const int n = 1024;
    const appm__v3 down = appm__v(0, -1, 0);
    appm__v3 axis;
    double all = 0.0, cone = 0.0, lobe = 0.0, cmax;
    int i, k, above = 0;
    focus_surface(&m, &sf, 0.8f);
    sc.focus = appm__v(3.0f, -0.6f, 0.0f); /* 11 degrees under the surface, half-angle 19 */
    sc.focus_r = 1.0f;
    axis = appm__normalize(sc.focus);
    cmax = sqrt(1.0 - 1.0 / (double)appm__dot(sc.focus, sc.focus));
    CHECK(appm__focus_aims(&sc, &m, &sf, appm__neg(down)) == 0); /* seen from above: the sphere is behind */
    CHECK(appm__focus_aims(&sc, &m, &sf, down));
    for (i = 0; i < n; ++i)
        for (k = 0; k < n; ++k) {
            appm__bsdf_sample bs;
            float steer = 0.0f, u1 = (i + 0.5f) / n, u2 = (k + 0.5f) / n;
            appm__v3 w = appm__cosine_dir(down, u1, u2);
            if (appm__dot(w, axis) >= cmax) lobe += 1.0;
            if (!appm__focus_bounce(&sc, &m, &sf, down, u1, u2, &bs, &steer)) continue;
            above += !(bs.wi.y < 0.0f); /* on the side wo is on */
            all += steer;
            if (appm__dot(bs.wi, axis) >= cmax) cone += steer;
        }
    all /= (double)n * n;
    cone /= (double)n * n;
    lobe /= (double)n * n;
    CHECK(above == 0);
    CHECK_MSG(lobe > 0.01 && lobe < 0.1, "lobe %g", lobe); /* a cone partly under the surface */
    CHECK_NEAR(all, 1.0, 2e-3);
    CHECK_NEAR(cone, lobe, 2e-3);
}

/* The studio's emission disk (appm__focus_disk).  A point (x, y) of the disk
 * (frame t, b facing d, around the origin) is on the plate's shadow when the
 * line through it along d meets the plate, and on the focus's when it is
 * within focus_r of the focus's projection; sc holds the plate and focus. */
static int on_plate(const appm_scene *sc, appm__v3 d, appm__v3 t, appm__v3 b, double x, double y)
{
    double q[3], k;
    q[0] = x * t.x + y * b.x;
    q[1] = x * t.y + y * b.y;
    q[2] = x * t.z + y * b.z;
    k = (sc->plate.y - q[1]) / d.y;
    return fabs(q[0] + k * d.x - sc->plate.x) <= sc->plate_e && fabs(q[2] + k * d.z - sc->plate.z) <= sc->plate_e;
}

static int on_focus(const appm_scene *sc, appm__v3 t, appm__v3 b, double x, double y)
{
    double fx = x - appm__dot(sc->focus, t), fy = y - appm__dot(sc->focus, b);
    return fx * fx + fy * fy <= (double)sc->focus_r * sc->focus_r;
}

/* Over a 512 x 512 grid of (u3, u4) the mean of 1 / density times the
 * indicator of a region estimates the area of the region's part that the
 * photons can come from: for a photon travelling down, the plate's shadow (the
 * plate's area times |d.y|), the focus's (pi focus_r^2) and their union (counted
 * on a fine grid of the disk), for one travelling up the focus's alone (the
 * plate's shadow outside it gets nothing: it can meet the plate only from below). */
static void test_focus_disk(void)
{
    static appm_scene sc;
    const int n = 512, g = 1500;
    int dir;
    sc.center = appm__v(0, 0, 0);
    sc.focus = appm__v(0.2f, 0.5f, -0.1f);
    sc.focus_r = 0.5f;
    sc.plate = appm__v(0.1f, -0.4f, 0.0f);
    sc.plate_e = 1.0f;
    for (dir = 0; dir < 2; ++dir) {
        appm__v3 d = appm__normalize(dir ? appm__v(-0.3f, 0.7f, 0.2f) : appm__v(0.5f, -0.8f, 0.3f)), t, b;
        double plate = 0.0, focus = 0.0, uni = 0.0, only = 0.0, grid = 0.0, cell = 6.0 / g;
        double want_plate = 4.0 * sc.plate_e * sc.plate_e * fabs(d.y), want_focus = APPM__PI * 0.25;
        int i, k, zero = 0;
        appm__basis(d, &t, &b);
        for (i = 0; i < n; ++i)
            for (k = 0; k < n; ++k) {
                float x, y, area = appm__focus_disk(&sc, d, t, b, (i + 0.5f) / n, (k + 0.5f) / n, &x, &y);
                int p = on_plate(&sc, d, t, b, x, y), f = on_focus(&sc, t, b, x, y);
                if (!(area > 0.0f)) {
                    zero++;
                    continue;
                }
                plate += p ? area : 0.0;
                focus += f ? area : 0.0;
                uni += p || f ? area : 0.0;
                only += p && !f ? area : 0.0;
            }
        for (i = 0; i < g; ++i) /* the union's area, on the disk's square [-3, 3)^2 */
            for (k = 0; k < g; ++k) {
                double x = -3.0 + (i + 0.5) * cell, y = -3.0 + (k + 0.5) * cell;
                grid += on_plate(&sc, d, t, b, x, y) || on_focus(&sc, t, b, x, y) ? cell * cell : 0.0;
            }
        plate /= (double)n * n;
        focus /= (double)n * n;
        uni /= (double)n * n;
        only /= (double)n * n;
        CHECK(zero == 0);
        CHECK_NEAR(focus, want_focus, 3e-3 * want_focus);
        if (dir == 0) {
            CHECK_NEAR(plate, want_plate, 3e-3 * want_plate);
            CHECK_NEAR(uni, grid, 3e-3 * grid);
            /* the two shadows overlap in part */
            CHECK_MSG(grid > want_plate + 0.1 && grid < want_plate + want_focus - 0.1, "union %g", grid);
        } else {
            CHECK(only == 0.0 && uni == focus);
        }
    }
    { /* a sun on the horizon: the plate's shadow a sliver 4e-6 wide, whose points
       * must keep their density (the whole: the sphere's shadow and the sliver) */
        appm__v3 d = appm__normalize(appm__v(0.6f, -1e-6f, 0.8f)), t, b;
        double all = 0.0, want = APPM__PI * 0.25;
        int i, k, zero = 0;
        appm__basis(d, &t, &b);
        for (i = 0; i < n; ++i)
            for (k = 0; k < n; ++k) {
                float x, y, area = appm__focus_disk(&sc, d, t, b, (i + 0.5f) / n, (k + 0.5f) / n, &x, &y);
                zero += !(area > 0.0f);
                all += area;
            }
        all /= (double)n * n;
        CHECK(zero == 0);
        CHECK_MSG(all > 0.997 * want && all < 1.003 * want + 4e-6, "edge on: %g against %g", all, want);
    }
}

/* Renders `passes` passes of ppm at a fixed radius (one thread, seed `seed`)
 * at 32x32 and returns the image's mean luminance and in *centre the mean over
 * the model's middle, or -1 on failure. */
static double render_photons(const appm_scene *s, int passes, uint64_t seed, double *centre)
{
    appm_config cfg;
    appm_renderer *r = NULL;
    appm_diag d;
    appm_image view;
    double sum = 0.0;
    size_t i;
    int k;
    appm_config_init(&cfg);
    cfg.method = APPM_METHOD_PPM; /* a fixed radius: both estimate the same blurred image */
    cfg.alpha = 1.0;
    cfg.radius = 0.15;
    cfg.photons = 4096;
    cfg.width = cfg.height = 32;
    cfg.threads = 1;
    cfg.seed = seed;
    if (appm_renderer_create(s, &cfg, &r, &d) != APPM_OK) {
        CHECK_MSG(0, "renderer: %s", d.message);
        return -1.0;
    }
    for (k = 0; k < passes; ++k) CHECK(appm_renderer_pass(r) == APPM_OK);
    appm_renderer_image(r, &view);
    for (i = 0; i < 32 * 32; ++i) sum += appm__lum(appm__v(view.rgb[3 * i], view.rgb[3 * i + 1], view.rgb[3 * i + 2]));
    *centre = rect_mean(&view, 10, 22, 10, 22);
    appm_renderer_destroy(r);
    return sum / (32.0 * 32.0);
}

/* The mean over seeds 1-3 of the ratios aimed / not aimed (focus_r = 0: the
 * sky's own emission, cosine bounces; env_auto = 0: one shadow ray to the sky)
 * of the image's mean and of its centre,
 * less 1, into image[0] and image[1]. */
static void focus_ratios(appm_scene *s, int passes, double *image)
{
    uint64_t seed;
    image[0] = image[1] = 0.0;
    for (seed = 1; seed <= 3; ++seed) {
        double c1, c0, m1 = render_photons(s, passes, seed, &c1), m0;
        float keep = s->focus_r;
        int sky = s->env_auto;
        s->focus_r = 0.0f;
        s->env_auto = 0; /* and one shadow ray to the sky (appm__nee_samples) */
        m0 = render_photons(s, passes, seed, &c0);
        s->focus_r = keep;
        s->env_auto = sky;
        image[0] += (m1 / m0 - 1.0) / 3.0;
        image[1] += (c1 / c0 - 1.0) / 3.0;
    }
}

/* The studio's aimed photons change the noise, not the picture: the sphere in
 * the studio rendered by ppm at a fixed radius with its focus and without (the
 * photons aimed and spared the roulette at their first hit, or not); under the
 * studio's sky and under a constant environment set on the scene (the aim
 * stays), which takes the other branch of the sky's emission.  Under the sky
 * the direct term differs too: its four samples a shading point are weighed
 * by 1/4 each, and weighed by 1 the image's mean reads +2.24. */
static void test_focus_unbiased(void)
{
    appm_scene *s = studio_sphere();
    const double white[3] = {1.0, 1.0, 1.0};
    int passes = check_quick() ? 16 : 48, k;
    appm_diag d;
    if (!s) return;
    for (k = 0; k < 2; ++k) {
        double r[2];
        if (k == 1) CHECK(appm_scene_set_environment(s, white, &d) == APPM_OK && s->focus_r > 0.0f);
        focus_ratios(s, passes, r);
        /* 16 seeds at 48 passes under the sky: the image's ratio 1.0005, the
         * centre's 1.0020 (standard error 0.0028); a photon weight without the
         * mixture's factor makes the aimed photons 2-4x too heavy */
        CHECK_MSG(fabs(r[0]) < 0.015, "%s: image mean %+.4f with the focus", k ? "constant" : "sky", r[0]);
        CHECK_MSG(fabs(r[1]) < 0.04, "%s: centre %+.4f with the focus", k ? "constant" : "sky", r[1]);
    }
    appm_scene_destroy(s);
}

/* A studio's photon skips the roulette at its first hit (appm.c 9.2,
 * docs/algorithm.md 5.10): the sky's photons land on the plate (albedo 1/2) or
 * the sphere (0.8) first, direct light, and the roulette there ended 20-50 %
 * of them; and the sky's photons start over the plate or the sphere, not the
 * scene's whole disk (appm__focus_disk).  Photons stored a path over 4 passes
 * of the sphere in the studio: 0.305, 0.165 with the roulette, 0.205 from the
 * whole disk (appm 0.1.6). */
static void test_focus_roulette(void)
{
    appm_scene *s = studio_sphere();
    appm_config cfg;
    appm_renderer *r;
    appm_stats st;
    double stored = 0.0;
    int k;
    if (!s) return;
    appm_config_init(&cfg);
    cfg.width = cfg.height = 32;
    cfg.photons = 16384;
    cfg.threads = 1;
    cfg.seed = 5;
    if ((r = check_renderer(s, &cfg)) != NULL) {
        for (k = 0; k < 4; ++k) {
            CHECK(appm_renderer_pass(r) == APPM_OK);
            appm_renderer_stats(r, &st);
            stored += (double)st.photons_stored / (4.0 * 16384.0);
        }
        printf("the studio's sphere: %.4f photons stored a path\n", stored);
        CHECK_MSG(stored > 0.26, "%.4f photons stored a path, not above 0.26", stored);
        appm_renderer_destroy(r);
    }
    appm_scene_destroy(s);
}

/* The studio's four sky samples a shading point (appm__direct, docs/algorithm.md
 * 5.10): the t-th is the first's numbers turned by t/4, so the four are
 * stratified against each other.  At a point of the plate beside the sphere,
 * over 256 passes of one pixel's numbers: the four samples' mean has the same
 * mean as one sample and 0.130 of its spread across passes (0.174 in 0.1.8;
 * four equal samples give the same spread, ratio 1; four independent ones 1/4;
 * two turned by 1/2, as until 0.1.7, 0.465).  And each sample is a shadow ray the photon budget
 * counts (12.2): a pass of the studio casts three eye rays more for each
 * shading point than the same pass with one sample. */
static void test_sky_samples(void)
{
    appm_scene *s = studio_sphere();
    appm_config cfg;
    appm_renderer *r;
    if (!s) return;
    appm_config_init(&cfg);
    cfg.width = cfg.height = 16;
    cfg.threads = 1;
    cfg.photons = 256;
    if ((r = check_renderer(s, &cfg)) != NULL) {
        appm__ray ray;
        appm__hit h;
        appm__surf sf;
        appm__material tex;
        const appm__material *m;
        double sum[2] = {0, 0}, sq[2] = {0, 0}, var[2];
        uint64_t rays[2], points = 0;
        const int N = 256;
        const unsigned n = APPM__SKY_SAMPLES;
        int j, k;
        size_t i;
        CHECK(appm__nee_samples(s) == n && n == 4);
        appm__ray_init(&ray, appm__v(1.3f, 5.0f, 0.4f), appm__v(0.0f, -1.0f, 0.0f), FLT_MAX);
        CHECK(appm__intersect(s, &ray, UINT32_MAX, &h));
        appm__surface(s, &h, &sf);
        m = appm__material_at(s, &sf, &tex);
        for (j = 1; j <= N; ++j)
            for (k = 0; k < 2; ++k) {
                appm__sampler smp;
                double v;
                appm__sampler_eye(&smp, r->sobol, r->chains, r->seed, (uint64_t)j, 7);
                v = appm__lum(appm__direct(r, &sf, m, appm__v(0.0f, 1.0f, 0.0f), &smp, 0, k ? 1u : n));
                sum[k] += v;
                sq[k] += v * v;
            }
        for (k = 0; k < 2; ++k) var[k] = (sq[k] - sum[k] * sum[k] / N) / (N - 1);
        printf("the studio's plate: %.4f with %u sky samples, %.4f with one; spread %.3g against %.3g (%.3f)\n",
               sum[0] / N, n, sum[1] / N, var[0], var[1], var[0] / var[1]);
        CHECK_NEAR(sum[0] / N, sum[1] / N, 0.03 * sum[1] / N);
        CHECK_MSG(var[1] > 0.0 && var[0] < 0.38 * var[1], "four samples' spread %.3f of one's, not below 0.38",
                  var[1] > 0.0 ? var[0] / var[1] : 0.0);
        for (k = 0; k < 2; ++k) { /* one pass with four samples, one with one: the eye rays it counts */
            int sky = s->env_auto;
            if (k) s->env_auto = 0;
            r->pass = 0;
            CHECK(appm_renderer_pass(r) == APPM_OK);
            for (rays[k] = 0, i = 0; i < APPM__MAX_THREADS; ++i) rays[k] += r->work[0][i];
            s->env_auto = sky;
        }
        for (i = 0; i < (size_t)r->w * r->h; ++i) points += r->vp[i].segs > 0;
        CHECK_MSG(points > 100 && rays[0] - rays[1] == (n - 1) * points,
                  "eye rays %llu with four sky samples, %llu with one: %llu more, for %llu shading points",
                  (unsigned long long)rays[0], (unsigned long long)rays[1],
                  (unsigned long long)(rays[0] - rays[1]), (unsigned long long)points);
        appm_renderer_destroy(r);
    }
    appm_scene_destroy(s);
}

/* The studio's aimed photons with 1 and 3 threads: the same bytes (appm,
 * 6 passes at 24x24; the aim is a function of each path's own numbers). */
static void test_focus_threads(void)
{
    static float img[2][3 * 24 * 24];
    appm_scene *s = studio_sphere();
    unsigned k;
    int ok = 1;
    if (!s) return;
    for (k = 0; k < 2 && ok; ++k) {
        appm_config cfg;
        appm_renderer *r;
        appm_image view;
        appm_config_init(&cfg);
        cfg.width = cfg.height = 24;
        cfg.photons = 8192; /* 8 chunks: the threads share the photon pass */
        cfg.threads = k ? 3u : 1u;
        cfg.seed = 7;
        r = check_renderer(s, &cfg);
        ok = r && check_passes(r, 6);
        if (ok) {
            appm_renderer_image(r, &view);
            memcpy(img[k], view.rgb, sizeof img[k]);
        }
        appm_renderer_destroy(r);
    }
    CHECK(ok && memcmp(img[0], img[1], sizeof img[0]) == 0);
    appm_scene_destroy(s);
}

int main(void)
{
    test_focus_threads();
    test_focus_unbiased();
    test_focus_roulette();
    test_sky_samples();
    test_studio();
    test_focus_bounce();
    test_focus_oblique();
    test_focus_disk();
    test_white_environment();
    test_point_light_falloff();
    test_delta_lights_every_point();
    test_pt_sky_by_bsdf();
    test_set_environment();
    test_allocation_failure();
    return check_finish();
}
