/* tests/t_budget.c - the photon budget (appm.c 12.2).
 *
 * With appm_config.photons = 0, pass 1 counts the rays of its eye paths (E)
 * and of its first width * height photon paths (P) and takes M = k w h
 * photon paths a pass, k the largest of 1, 2, 4 with k P <= 1.65 E.
 *
 * What is checked, and against what:
 *   1. The counts, on a scene where every ray is known: a camera looking
 *      straight down at a floor 200 m wide from 1 m, two point lights 0.5 m
 *      above it.  Each eye path casts one ray to the floor and, with shadow
 *      rays, one to each point light (there is no other light to sample):
 *      E = 3 w h.
 *      On a black floor each photon path casts one ray (up into nothing, or
 *      down to the floor, where the black surface ends it): P = w h.  So
 *      E / P = 3 exactly and k = 4.  With --direct photons (no shadow rays)
 *      E / P = 1 exactly and k = 1.  On a white floor a path that goes down
 *      bounces up and leaves: P is about 1.5 w h, so E / P is about 2 with
 *      shadow rays (k = 2) and about 2/3 without (k = 1).
 *   2. The choice changes M and nothing else: the image is the image of a
 *      render told photons = k w h, byte for byte, each with 1 and 3 threads,
 *      for appm and ppm; the path tracer has no budget; a configuration that
 *      gives photons keeps them.
 *   3. Checkpoints: 2 passes saved, loaded into a fresh renderer of the same
 *      options and run 2 more, give the image of 4 passes; a checkpoint of
 *      pass 0 chooses again in the pass after the load; a renderer told
 *      photons refuses it, and a budget's renderer refuses the checkpoint of
 *      a render told the same M, each naming the photons.
 *   4. The committed scenes the rule was set on (docs/algorithm.md 5.12):
 *      caustic-glass takes 4 w h, the bunny 2 w h, CornellBox-Original w h,
 *      and the studio (a bare OBJ) w h, which it keeps whatever its count
 *      (E / P 1.63 with its four sky samples a shading point: 2 w h without
 *      the studio's exception).
 */
#include "../appm.c"
#include "check.h"

static const char BUDGET_FLOOR_OBJ[] = "mtllib floor.mtl\n"
                                       "v -100 0 -100\nv 100 0 -100\nv 100 0 100\nv -100 0 100\n"
                                       "usemtl floor\nf 1 4 3\nf 1 3 2\n";
static const char BUDGET_BLACK_MTL[] = "newmtl floor\nKd 0 0 0\n";
static const char BUDGET_WHITE_MTL[] = "newmtl floor\nKd 1 1 1\n";
static const char BUDGET_FLOOR_SCENE[] = "mesh floor.obj\n"
                                         "camera eye 0 1 0  target 0 0 0  up 0 0 -1  fov 60\n"
                                         "image 16 12\n"
                                         "light point position 0 0.5 0 intensity 1 1 1\n"
                                         "light point position 0.3 0.5 0.2 intensity 1 1 1\n";

static appm_scene *budget_floor(const char *mtl, size_t mtl_len)
{
    appm_memory_file files[2];
    appm_scene *s = NULL;
    appm_diag d;
    files[0].name = "floor.obj";
    files[0].text = BUDGET_FLOOR_OBJ;
    files[0].len = sizeof BUDGET_FLOOR_OBJ - 1;
    files[1].name = "floor.mtl";
    files[1].text = mtl;
    files[1].len = mtl_len;
    CHECK_MSG(appm_scene_load_memory(BUDGET_FLOOR_SCENE, sizeof BUDGET_FLOOR_SCENE - 1, "floor.scene", files, 2, NULL,
                                     &s, &d) == APPM_OK,
              "floor: %s", d.message);
    return s;
}

static appm_config budget_config(appm_method m, appm_direct direct, unsigned threads, uint64_t photons)
{
    appm_config c;
    appm_config_init(&c);
    c.method = m;
    c.direct = direct;
    c.threads = threads;
    c.photons = photons;
    c.seed = 5;
    return c;
}

/* `passes` passes of s with c: the image into img (w h 3 floats, w h at most
 * 64 x 64) and the stats; 0 on failure. */
static int budget_render(const appm_scene *s, const appm_config *c, int passes, float *img, appm_stats *st)
{
    appm_renderer *r = check_renderer(s, c);
    appm_image im;
    int ok = r && check_passes(r, passes);
    if (ok) {
        appm_renderer_image(r, &im);
        memcpy(img, im.rgb, (size_t)im.width * im.height * 3 * sizeof(float));
        appm_renderer_stats(r, st);
    }
    appm_renderer_destroy(r);
    return ok;
}

/* Cases 1 and 2 on one floor: the reading, the choice, and the image of the
 * same M given. */
static void budget_case(const appm_scene *s, appm_method m, appm_direct direct, double lo, double hi, unsigned k)
{
    static float a[64 * 64 * 3], b[64 * 64 * 3];
    const uint64_t M0 = 16u * 12u;
    appm_config c = budget_config(m, direct, 1, 0);
    appm_stats sa, sb;
    unsigned t;
    if (!budget_render(s, &c, 3, a, &sa)) return;
    CHECK_MSG(sa.budget_rays >= lo && sa.budget_rays <= hi && sa.photons_per_pass == k * M0,
              "%s, direct %d: E / P = %.6f (want %g..%g), M = %llu (want %u w h)", appm_method_name(m), (int)direct,
              sa.budget_rays, lo, hi, (unsigned long long)sa.photons_per_pass, k);
    CHECK(sa.photons_emitted == 3 * k * M0);
    for (t = 1; t <= 3; t += 2) { /* the budget with 3 threads, the same M given with 1 and 3: the same bytes */
        c = budget_config(m, direct, t, 0);
        if (t > 1 && budget_render(s, &c, 3, b, &sb))
            CHECK_MSG(memcmp(a, b, (size_t)M0 * 3 * sizeof(float)) == 0 && sb.budget_rays == sa.budget_rays &&
                          sb.photons_per_pass == sa.photons_per_pass,
                      "%s: the budget's choice or image with %u threads differs from 1 thread's",
                      appm_method_name(m), t);
        c.photons = k * M0;
        if (budget_render(s, &c, 3, b, &sb)) {
            CHECK_MSG(memcmp(a, b, (size_t)M0 * 3 * sizeof(float)) == 0,
                      "%s: the budget's image is not that of photons = %u w h given (%u threads)",
                      appm_method_name(m), k, t);
            CHECK(sb.budget_rays == 0.0 && sb.photons_per_pass == k * M0 &&
                  sb.dropped_samples == sa.dropped_samples);
        }
    }
}

/* Case 3. */
static void budget_checkpoint(const appm_scene *s)
{
    static float a[16 * 12 * 3];
    appm_config c = budget_config(APPM_METHOD_APPM, APPM_DIRECT_NEE, 2, 0);
    appm_renderer *r = check_renderer(s, &c), *q = NULL, *z = NULL;
    appm_stats st;
    appm_image im;
    appm_diag d;
    void *buf = NULL, *buf0 = NULL;
    size_t size = 0, size0 = 0;
    if (!r || !budget_render(s, &c, 4, a, &st)) goto done;
    if (appm_renderer_save(r, NULL, 0, &size0, &d) != APPM_OK || !(buf0 = malloc(size0)) ||
        appm_renderer_save(r, buf0, size0, &size0, &d) != APPM_OK || !check_passes(r, 2) ||
        appm_renderer_save(r, NULL, 0, &size, &d) != APPM_OK || !(buf = malloc(size)) ||
        appm_renderer_save(r, buf, size, &size, &d) != APPM_OK) {
        CHECK(0);
        goto done;
    }
    c.threads = 1;
    q = check_renderer(s, &c);
    CHECK_MSG(q && appm_renderer_load(q, buf, size, &d) == APPM_OK, "load: %s", d.message);
    if (q && check_passes(q, 2)) {
        appm_renderer_image(q, &im);
        CHECK_MSG(memcmp(im.rgb, a, sizeof a) == 0, "2 + 2 passes across a checkpoint differ from 4");
        appm_renderer_stats(q, &st);
        CHECK_MSG(st.photons_per_pass == 4u * 16u * 12u && st.budget_rays == 3.0,
                  "after the load: %llu photon paths a pass, the reading %g", (unsigned long long)st.photons_per_pass,
                  st.budget_rays);
    }
    z = check_renderer(s, &c); /* pass 0 saved: the budget chooses in the pass after the load */
    CHECK_MSG(z && appm_renderer_load(z, buf0, size0, &d) == APPM_OK, "load of pass 0: %s", d.message);
    if (z && check_passes(z, 4)) {
        appm_renderer_image(z, &im);
        CHECK(memcmp(im.rgb, a, sizeof a) == 0);
    }
    appm_renderer_destroy(z);
    c.photons = 4u * 16u * 12u; /* told photons, even the M chosen: refused, saying which option */
    z = check_renderer(s, &c);
    CHECK(z && appm_renderer_load(z, buf, size, &d) == APPM_ERR_INVALID_ARG && strstr(d.message, "photons") != NULL);
    if (z && check_passes(z, 2)) { /* and its checkpoint by a budget's renderer */
        free(buf);
        buf = NULL;
        if (appm_renderer_save(z, NULL, 0, &size, &d) == APPM_OK && (buf = malloc(size)) != NULL &&
            appm_renderer_save(z, buf, size, &size, &d) == APPM_OK) {
            appm_renderer_destroy(q);
            c.photons = 0;
            q = check_renderer(s, &c);
            CHECK_MSG(q && appm_renderer_load(q, buf, size, &d) == APPM_ERR_INVALID_ARG &&
                          strstr(d.message, "photon budget") != NULL,
                      "load: %s", d.message);
        }
    }
done:
    free(buf);
    free(buf0);
    appm_renderer_destroy(r);
    appm_renderer_destroy(q);
    appm_renderer_destroy(z);
}

/* Case 4: the rule on committed scenes, at a small size (the counts are per
 * pixel and per path: the size hardly moves them). */
static void budget_scene(const char *path, uint32_t w, uint32_t h, unsigned k)
{
    appm_scene *s = check_load_scene(path);
    appm_config c = budget_config(APPM_METHOD_APPM, APPM_DIRECT_NEE, 2, 0);
    appm_renderer *r;
    appm_stats st;
    if (!s) return;
    c.width = w;
    c.height = h;
    r = check_renderer(s, &c);
    if (r && check_passes(r, 1)) {
        appm_renderer_stats(r, &st);
        printf("%s %ux%u: eye rays / photon rays %.3f, %llu photon paths a pass\n", path, w, h, st.budget_rays,
               (unsigned long long)st.photons_per_pass);
        CHECK_MSG(st.photons_per_pass == (uint64_t)k * w * h, "%s: %llu photon paths a pass, want %u w h", path,
                  (unsigned long long)st.photons_per_pass, k);
    }
    appm_renderer_destroy(r);
    appm_scene_destroy(s);
}

int main(void)
{
    appm_scene *black = budget_floor(BUDGET_BLACK_MTL, sizeof BUDGET_BLACK_MTL - 1);
    appm_scene *white = budget_floor(BUDGET_WHITE_MTL, sizeof BUDGET_WHITE_MTL - 1);
    if (black) {
        budget_case(black, APPM_METHOD_APPM, APPM_DIRECT_NEE, 3.0, 3.0, 4);
        budget_case(black, APPM_METHOD_PPM, APPM_DIRECT_NEE, 3.0, 3.0, 4);
        budget_case(black, APPM_METHOD_APPM, APPM_DIRECT_PHOTONS, 1.0, 1.0, 1);
        budget_checkpoint(black);
        {   /* the path tracer has no photons and no budget */
            static float img[16 * 12 * 3];
            appm_config c = budget_config(APPM_METHOD_PT, APPM_DIRECT_NEE, 1, 0);
            appm_stats st;
            if (budget_render(black, &c, 2, img, &st))
                CHECK(st.photons_per_pass == 0 && st.budget_rays == 0.0 && st.photons_emitted == 0);
        }
    }
    if (white) {
        budget_case(white, APPM_METHOD_APPM, APPM_DIRECT_NEE, 1.8, 2.2, 2);
        budget_case(white, APPM_METHOD_APPM, APPM_DIRECT_PHOTONS, 0.6, 0.7, 1);
    }
    appm_scene_destroy(black);
    appm_scene_destroy(white);
    budget_scene("scenes/caustic-glass.scene", 28, 40, 4);
    budget_scene("scenes/bunny.scene", 32, 32, 2);
    budget_scene("scenes/cornell-original.scene", 32, 32, 1);
    budget_scene("scenes/stanford-bunny.obj", 32, 32, 1);
    return check_finish();
}
