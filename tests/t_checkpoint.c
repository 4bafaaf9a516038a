/* tests/t_checkpoint.c - checkpoint and resume (appm.c section 13).
 *
 * What is checked, and against what:
 *   1. Resume is exact: for every method and thread counts 1 and 2 (and with
 *      3 chains of the sampler for appm and pt), N passes,
 *      save, load into a new renderer (with the other thread count), N more
 *      passes give the render of 2N uninterrupted passes bit for bit: the
 *      image, every aux map the method has, est_relerr and the counters of
 *      appm_stats.  A loaded renderer saves the bytes it was loaded from; the
 *      bytes do not depend on the thread count; the file calls round trip too.
 *   2. Nothing is left out: a checkpoint written and read with any one field
 *      of the per-pixel lists left out resumes to another render, so every
 *      listed field is state the next passes depend on (the round trip of 1
 *      would fail if the estimator table missed a field; the halves of the
 *      error estimate on a render long enough to read them).  And the pixel
 *      list tiles appm__pixel as the estimator entries tile their states.
 *   3. Refusals: a checkpoint of another method, seed, photon count, alpha,
 *      radius, depth, direct mode, image size, sampler, chain count, scene,
 *      format version, library version or field list is refused with
 *      APPM_ERR_INVALID_ARG and a message that names it; the renderer is left
 *      as it was.
 *   4. Damage: every truncation and every single-bit flip of a checkpoint is
 *      an error (never APPM_OK), and the renderer is left as it was.
 *   5. Hostile input with a valid checksum (absurd sizes, field counts, name
 *      lengths, pass counts, NaN statistics, negative radii) is APPM_ERR_PARSE.
 *   6. Byte order: the file is little-endian whatever the host: values read
 *      back byte by byte at their documented offsets.
 *   7. The scene hash ignores the triangles' order (a BVH built elsewhere may
 *      order them otherwise) and sees, each in its own part, a moved vertex,
 *      another albedo, Ks or Ns, another camera, another point light.  And a
 *      checkpoint of scene files resumed after an edit of one Ns, one Ks, one
 *      vn, a spot's cone or the fov is refused, the message naming the part
 *      (materials, shading normals, lights, camera); the same files read
 *      again are accepted.
 *   8. A tripwire: appm_config has exactly the fields the checkpoint header
 *      was written for, so a new option cannot slip past the comparison. */
#include "../appm.c"
#include "check.h"

#define NPASS 6 /* appm: past the warm-up of 4, and 2N = 12 estimates the Laplacian */
/* The omission test saves at the end of appm's warm-up, where its radius
 * limits bind, with so few photons that some pixels still widen their radius
 * (fewer than APPM__KMIN_APPM, 32, photons seen; appm-paper: 8): then its last radius R is state too. */
#define NSAVE 4
#define SPARSE 300
#define DENSE 20000 /* enough caustic photons for appm's caustic component */
/* appm's step 7 reads its sums only after 16 passes of them: saved at 20, resumed
 * to 28 (at DENSE photons some of the 12 x 10 pixels pass its test from pass 16
 * on, and their next pass narrows; were none to, its four fields would read as
 * unused and test_fields_matter would fail) */
#define LATE_SAVE 20
#define LATE_TOTAL 28

/* Offsets of the layout comment of section 13. */
#define OFF_FORMAT 8
#define OFF_VERSION 12
#define OFF_W 32
#define OFF_PASS 128
#define OFF_R1 168
#define OFF_SECONDS 200
#define OFF_LAYOUT 240

static appm_config config(appm_method m, unsigned threads)
{
    appm_config c;
    appm_config_init(&c);
    c.method = m;
    c.width = 12;
    c.height = 10;
    c.photons = 3000;
    c.threads = threads;
    c.seed = 7;
    c.emission = APPM_EMISSION_LIGHT; /* the guided state's 40 K bytes a light: test_damage's own case */
    return c;
}

static appm_renderer *make(const appm_scene *s, const appm_config *c, int passes)
{
    appm_renderer *r = check_renderer(s, c);
    if (r && !check_passes(r, passes)) {
        appm_renderer_destroy(r);
        r = NULL;
    }
    return r;
}

/* Whether a and b show the same render: image, aux maps, error estimate, counters. */
static int same_render(appm_renderer *a, appm_renderer *b)
{
    appm_image ia, ib;
    appm_stats sa, sb;
    int k, same;
    size_t n;
    appm_renderer_image(a, &ia);
    appm_renderer_image(b, &ib);
    n = (size_t)ia.width * ia.height;
    same = ia.width == ib.width && ia.height == ib.height && memcmp(ia.rgb, ib.rgb, n * 3 * sizeof(float)) == 0;
    for (k = 0; k < APPM_AUX_COUNT && same; ++k) {
        const float *xa = appm_renderer_aux(a, (appm_aux)k), *xb = appm_renderer_aux(b, (appm_aux)k);
        same = (xa == NULL) == (xb == NULL) && (!xa || memcmp(xa, xb, n * sizeof(float)) == 0);
    }
    appm_renderer_stats(a, &sa);
    appm_renderer_stats(b, &sb);
    return same && sa.passes == sb.passes && sa.photons_emitted == sb.photons_emitted &&
           sa.eye_paths == sb.eye_paths && sa.dropped_samples == sb.dropped_samples &&
           memcmp(&sa.est_relerr, &sb.est_relerr, sizeof(double)) == 0 &&
           memcmp(&sa.initial_radius, &sb.initial_radius, sizeof(double)) == 0;
}

/* A checkpoint of r in a malloc'd buffer (NULL on failure). */
static unsigned char *save(appm_renderer *r, size_t *n)
{
    unsigned char *buf;
    appm_diag d;
    size_t need = 0, got = 0;
    *n = 0;
    if (appm_renderer_save(r, NULL, 0, &need, &d) != APPM_OK || need == 0) return NULL;
    buf = (unsigned char *)malloc(need);
    if (buf && appm_renderer_save(r, buf, need, &got, &d) == APPM_OK && got == need) {
        *n = need;
        return buf;
    }
    free(buf);
    return NULL;
}

static void put_le(unsigned char *p, uint64_t v, int bytes)
{
    int k;
    for (k = 0; k < bytes; ++k) p[k] = (unsigned char)(v >> (8 * k));
}

static uint64_t get_le(const unsigned char *p, int bytes)
{
    uint64_t v = 0;
    int k;
    for (k = 0; k < bytes; ++k) v |= (uint64_t)p[k] << (8 * k);
    return v;
}

/* Rewrites the trailing FNV-1a hash, so that an edit reaches the checks behind it. */
static void fix_sum(unsigned char *p, size_t n)
{
    uint64_t h = 14695981039346656037ull;
    size_t i;
    for (i = 0; i + 8 < n; ++i) h = (h ^ p[i]) * 1099511628211ull;
    put_le(p + n - 8, h, 8);
}

/* 1. N + save + load + N == 2N, for every method and thread count. */
static void test_resume(const appm_scene *s)
{
    int m;
    unsigned t;
    for (m = 0; m < (int)APPM_METHOD_COUNT; ++m) {
        unsigned char *bytes[2] = {NULL, NULL};
        size_t len[2] = {0, 0};
        for (t = 1; t <= 2; ++t) {
            appm_config ca = config((appm_method)m, t), cb = config((appm_method)m, 3 - t);
            appm_renderer *whole = make(s, &ca, 2 * NPASS), *a = make(s, &ca, NPASS), *b = make(s, &cb, 0);
            appm_diag d;
            appm_status st;
            unsigned char *again;
            size_t n2;
            if (!whole || !a || !b) goto next;
            bytes[t - 1] = save(a, &len[t - 1]);
            CHECK(bytes[t - 1] != NULL);
            if (!bytes[t - 1]) goto next;
            st = appm_renderer_load(b, bytes[t - 1], len[t - 1], &d);
            CHECK_MSG(st == APPM_OK, "%s: load: %s", appm_method_name((appm_method)m), d.message);
            again = save(b, &n2);
            CHECK_MSG(again && n2 == len[t - 1] && memcmp(again, bytes[t - 1], n2) == 0,
                      "%s: a loaded renderer saves other bytes", appm_method_name((appm_method)m));
            free(again);
            {   /* every counter comes back as saved: the thread count and memory are b's own,
                 * and clamped, emission_guided and emission_lights, readings of the last pass
                 * that the checkpoint does not hold, read none until the next pass (appm.h),
                 * also in a renderer that had read them before the load (a, loaded with its
                 * own bytes) */
                appm_stats sa, sb;
                appm_renderer_stats(a, &sa);
                appm_renderer_stats(b, &sb);
                CHECK_MSG(sa.passes == sb.passes && sa.photons_emitted == sb.photons_emitted &&
                              sa.photons_stored == sb.photons_stored && sa.eye_paths == sb.eye_paths &&
                              sa.initial_radius == sb.initial_radius && sa.seconds == sb.seconds &&
                              sa.seconds_eye == sb.seconds_eye && sa.seconds_photons == sb.seconds_photons &&
                              sa.seconds_grid == sb.seconds_grid && sa.seconds_gather == sb.seconds_gather &&
                              sa.dropped_samples == sb.dropped_samples &&
                              memcmp(&sa.est_relerr, &sb.est_relerr, sizeof(double)) == 0 &&
                              sa.photons_per_pass == sb.photons_per_pass && sa.budget_rays == sb.budget_rays,
                          "%s, %u then %u threads: the loaded renderer's counters differ from the saved one's",
                          appm_method_name((appm_method)m), t, 3 - t);
                CHECK_MSG(appm_renderer_load(a, bytes[t - 1], len[t - 1], &d) == APPM_OK,
                          "%s: a renderer loads its own checkpoint: %s", appm_method_name((appm_method)m), d.message);
                appm_renderer_stats(a, &sa);
                CHECK_MSG(sa.clamped < 0.0 && sa.emission_guided == 0.0 && sa.emission_lights == 0 &&
                              sb.clamped < 0.0 && sb.emission_guided == 0.0 && sb.emission_lights == 0,
                          "%s: after a load clamped %g / %g, emission_guided %g / %g, emission_lights %u / %u",
                          appm_method_name((appm_method)m), sa.clamped, sb.clamped, sa.emission_guided,
                          sb.emission_guided, sa.emission_lights, sb.emission_lights);
            }
            CHECK(b->pass == NPASS);
            if (st == APPM_OK && check_passes(b, NPASS))
                CHECK_MSG(same_render(whole, b), "%s, %u then %u threads: %d + save + load + %d passes differ "
                          "from %d passes", appm_method_name((appm_method)m), t, 3 - t, NPASS, NPASS, 2 * NPASS);
        next:
            appm_renderer_destroy(whole);
            appm_renderer_destroy(a);
            appm_renderer_destroy(b);
        }
        /* all but the wall times (and the checksum over them) */
        CHECK_MSG(bytes[0] && bytes[1] && len[0] == len[1] && memcmp(bytes[0], bytes[1], OFF_SECONDS) == 0 &&
                      memcmp(bytes[0] + OFF_LAYOUT, bytes[1] + OFF_LAYOUT, len[0] - OFF_LAYOUT - 8) == 0,
                  "%s: the checkpoint depends on the thread count", appm_method_name((appm_method)m));
        free(bytes[0]);
        free(bytes[1]);
    }
}

/* With chains (section 2.3) the chains' sums are state too (est_relerr reads
 * them): the resume is exact with them and differs without them. */
static void test_chains(const appm_scene *s)
{
    int k;
    static const appm_method ms[2] = {APPM_METHOD_APPM, APPM_METHOD_PT};
    for (k = 0; k < 2; ++k) {
        appm_config ca = config(ms[k], 1), cb;
        appm_renderer *whole, *a, *b, *c;
        appm__ck_layout L;
        unsigned char *buf;
        size_t n = 0;
        ca.chains = 3;
        cb = ca;
        cb.threads = 2;
        whole = make(s, &ca, 2 * NPASS);
        a = make(s, &ca, NPASS);
        b = make(s, &cb, 0);
        c = make(s, &cb, 0);
        if (whole && a && b && c && (buf = save(a, &n)) != NULL) {
            CHECK(appm_renderer_load(b, buf, n, NULL) == APPM_OK);
            if (check_passes(b, NPASS))
                CHECK_MSG(same_render(whole, b), "%s, 3 chains: the resume differs", appm_method_name(ms[k]));
            free(buf);
            appm__ck_layout_of(a, &L);
            CHECK(L.n[2] == 1 && L.chain.count == 3);
            L.n[2] = 0; /* leave the chains' sums out */
            buf = (unsigned char *)malloc(n);
            if (buf && appm__ck_save_mem(a, &L, buf, n, &n, NULL) == APPM_OK &&
                appm__ck_load_mem(c, &L, buf, n, NULL) == APPM_OK && check_passes(c, NPASS))
                CHECK_MSG(!same_render(whole, c), "%s: without the chains' sums the resume is the same",
                          appm_method_name(ms[k]));
            free(buf);
        }
        appm_renderer_destroy(whole);
        appm_renderer_destroy(a);
        appm_renderer_destroy(b);
        appm_renderer_destroy(c);
    }
}

/* The file calls: atomic (no temporary left), and the same resume. */
static void test_file(const appm_scene *s)
{
    appm_config c = config(APPM_METHOD_APPM, 2);
    appm_renderer *whole = make(s, &c, 2 * NPASS), *a = make(s, &c, NPASS), *b = make(s, &c, 0);
    const char *path = check_path("checkpoint", "resume.ckpt");
    char tmp[1100];
    appm_diag d;
    FILE *f;
    if (!whole || !a || !b) goto done;
    CHECK_MSG(appm_renderer_save_file(a, path, &d) == APPM_OK, "save_file: %s", d.message);
    snprintf(tmp, sizeof tmp, "%s.tmp", path);
    f = fopen(tmp, "rb");
    CHECK_MSG(f == NULL, "the temporary %s is left behind", tmp);
    if (f) fclose(f);
    CHECK_MSG(appm_renderer_load_file(b, path, &d) == APPM_OK, "load_file: %s", d.message);
    if (check_passes(b, NPASS)) CHECK_MSG(same_render(whole, b), "a resume through a file differs");
    CHECK(appm_renderer_load_file(b, check_path("checkpoint", "missing.ckpt"), &d) == APPM_ERR_IO);
    CHECK(appm_renderer_save_file(a, "tests/out/no-such-folder/x.ckpt", &d) == APPM_ERR_IO);
done:
    appm_renderer_destroy(whole);
    appm_renderer_destroy(a);
    appm_renderer_destroy(b);
}

/* 2. Every listed field matters: leave it out of both writing and reading. */
static int resumes_same_without(const appm_scene *s, appm_method m, unsigned table, unsigned field,
                                appm_renderer *whole, uint64_t photons, int nsave, int ntotal)
{
    appm_config c = config(m, 1);
    appm_renderer *a, *b;
    c.photons = photons;
    a = make(s, &c, nsave);
    b = make(s, &c, 0);
    appm__ck_layout L;
    appm__field less[APPM__CK_MAXFIELDS];
    unsigned char *buf = NULL;
    size_t n = 0, k, j = 0;
    int same = -1;
    if (!a || !b) goto done;
    appm__ck_layout_of(a, &L);
    for (k = 0; k < L.n[table]; ++k)
        if (k != field) less[j++] = L.f[table][k];
    L.f[table] = less;
    L.n[table] = (unsigned)j;
    if (appm__ck_save_mem(a, &L, NULL, 0, &n, NULL) != APPM_OK || !(buf = (unsigned char *)malloc(n))) goto done;
    if (appm__ck_save_mem(a, &L, buf, n, &n, NULL) != APPM_OK) goto done;
    if (appm__ck_load_mem(b, &L, buf, n, NULL) != APPM_OK || !check_passes(b, ntotal - nsave)) goto done;
    same = same_render(whole, b);
done:
    free(buf);
    appm_renderer_destroy(a);
    appm_renderer_destroy(b);
    return same;
}

static void test_fields_matter(const appm_scene *s)
{
    int m;
    size_t covered = 0;
    unsigned f, t;
    for (f = 0; f < sizeof appm__pixel_fields / sizeof appm__pixel_fields[0]; ++f) {
        CHECK(appm__pixel_fields[f].offset == covered);
        covered += appm__pixel_fields[f].count * (appm__pixel_fields[f].is_u64 ? sizeof(uint64_t) : sizeof(double));
    }
    CHECK_MSG(covered == sizeof(appm__pixel), "appm__pixel_fields cover %lu of %lu bytes", (unsigned long)covered,
              (unsigned long)sizeof(appm__pixel));
    for (m = 0; m < (int)APPM_METHOD_COUNT; ++m) {
        appm_config c = config((appm_method)m, 1);
        appm_renderer *whole;
        appm__ck_layout L;
        appm_renderer *dense = NULL, *late = NULL;
        c.photons = SPARSE;
        whole = make(s, &c, 2 * NPASS);
        if (!whole) continue;
        if (m == APPM_METHOD_APPM) {
            c.photons = DENSE;
            dense = make(s, &c, 2 * NPASS);
            late = make(s, &c, LATE_TOTAL);
        }
        appm__ck_layout_of(whole, &L);
        for (t = 0; t < 2; ++t)
            for (f = 0; f < L.n[t]; ++f) {
                /* sppm keeps no spread of its per-pass estimates (no VARIANCE map); the
                 * halves (lh) serve only the error estimate, which ppm has not, and on
                 * these 120 pixels its scale sits at its bound 1: test_halves_matter */
                int halves = t == 0 && strcmp(L.f[t][f].name, "lh") == 0, same;
                int unused = (m == APPM_METHOD_SPPM && t == 0 && f > 0) || halves;
                if (halves && m != APPM_METHOD_PPM && m != APPM_METHOD_SPPM) continue;
                /* lit only weighs a pixel in the error estimate, where one pass holds it:
                 * test_lit_carried and tests/t_estimator.c */
                if (t == 0 && strcmp(L.f[t][f].name, "lit") == 0) continue;
                same = resumes_same_without(s, (appm_method)m, t, f, whole, SPARSE, NSAVE, 2 * NPASS);
                /* appm's caustic radius is read only once a pixel has seen enough
                 * caustic photons, which the sparse render never reaches, and its
                 * step 7 only 16 passes later */
                if (same == 1 && dense)
                    same = resumes_same_without(s, (appm_method)m, t, f, dense, DENSE, NSAVE, 2 * NPASS);
                if (same == 1 && late)
                    same = resumes_same_without(s, (appm_method)m, t, f, late, DENSE, LATE_SAVE, LATE_TOTAL);
                CHECK_MSG(same == unused, "%s: a checkpoint without field '%s' resumes to %s render",
                          appm_method_name((appm_method)m), L.f[t][f].name, same ? "the same" : "another");
            }
        appm_renderer_destroy(whole);
        appm_renderer_destroy(dense);
        appm_renderer_destroy(late);
    }
}

/* A checkpoint of r without the pixel field `name`, in *n bytes (NULL on
 * failure), and in *L (its field list in `less`) the layout to load it with. */
static unsigned char *save_without(appm_renderer *r, const char *name, appm__ck_layout *L, appm__field *less,
                                   size_t *n)
{
    unsigned char *buf = NULL;
    size_t k, j = 0;
    appm__ck_layout_of(r, L);
    for (k = 0; k < L->n[0]; ++k)
        if (strcmp(L->f[0][k].name, name) != 0) less[j++] = L->f[0][k];
    CHECK(j + 1 == L->n[0]);
    L->f[0] = less;
    L->n[0] = (unsigned)j;
    *n = 0;
    if (appm__ck_save_mem(r, L, NULL, 0, n, NULL) != APPM_OK || !(buf = (unsigned char *)malloc(*n))) return NULL;
    if (appm__ck_save_mem(r, L, buf, *n, n, NULL) != APPM_OK) {
        free(buf);
        return NULL;
    }
    return buf;
}

/* appm__pixel.lit is state: the path tracer on the teapot under its sky,
 * 12 x 10, 6 passes (the sky's pixels count 6), loaded into a renderer that
 * has made 3 passes of its own (its sky's counts are 3): with the field, every
 * pixel holds the saved count; without it, no pixel that shows the sky on
 * every pass holds 6. */
static void test_lit_carried(void)
{
    appm_scene *s = check_load_scene("scenes/teapot.scene");
    appm_config c;
    appm_renderer *a = NULL, *b = NULL, *b2 = NULL;
    appm__ck_layout L;
    appm__field less[APPM__CK_MAXFIELDS];
    unsigned char *buf = NULL, *full = NULL;
    size_t n = 0, k, npix, lit = 0, kept = 0, same = 0;
    if (!s) return;
    c = config(APPM_METHOD_PT, 1);
    a = make(s, &c, 6);
    b = make(s, &c, 3);
    b2 = make(s, &c, 0);
    if (!a || !b || !b2) goto done;
    npix = (size_t)a->w * a->h;
    CHECK(b->pix[0].lit == 3);
    if (!(buf = save_without(a, "lit", &L, less, &n)) || appm__ck_load_mem(b, &L, buf, n, NULL) != APPM_OK) goto done;
    if (!(full = save(a, &n)) || appm_renderer_load(b2, full, n, NULL) != APPM_OK) goto done;
    for (k = 0; k < npix; ++k) {
        lit += a->pix[k].lit == 6;
        kept += a->pix[k].lit == 6 && b->pix[k].lit == 6;
        same += b2->pix[k].lit == a->pix[k].lit;
    }
    CHECK_MSG(lit > 0 && lit < npix && kept == 0 && same == npix,
              "%lu of %lu pixels show the sky; without the field %lu hold the saved count, with it %lu",
              (unsigned long)lit, (unsigned long)npix, (unsigned long)kept, (unsigned long)same);
done:
    free(buf);
    free(full);
    appm_renderer_destroy(a);
    appm_renderer_destroy(b);
    appm_renderer_destroy(b2);
    appm_scene_destroy(s);
}

/* The halves of appm__var_scales are state: the path tracer on the bunny, 24 x 24,
 * saved after 20 passes without them, resumes to 40 passes with another error
 * estimate (the scale of pass 40 reads the halves of pass 32: S(16) was saved),
 * and with them to the same one. */
static void test_halves_matter(void)
{
    appm_scene *s = check_load_scene("scenes/bunny.scene");
    appm_config c;
    appm_renderer *whole = NULL, *a = NULL, *b = NULL, *b2 = NULL;
    appm_stats sw, sb;
    appm__ck_layout L;
    appm__field less[APPM__CK_MAXFIELDS];
    unsigned char *buf = NULL, *full = NULL;
    size_t n = 0;
    if (!s) return;
    c = config(APPM_METHOD_PT, 1);
    c.width = c.height = 24;
    whole = make(s, &c, 40);
    a = make(s, &c, 20);
    b = make(s, &c, 0);
    b2 = make(s, &c, 0);
    if (!whole || !a || !b || !b2) goto done;
    appm_renderer_stats(whole, &sw); /* makes the estimate and var_scale */
    CHECK_MSG(whole->var_scale < 1.0, "var_scale %.4f: the halves' scale should be below its bound here",
              whole->var_scale);
    if (!(buf = save_without(a, "lh", &L, less, &n))) goto done;
    if (appm__ck_load_mem(b, &L, buf, n, NULL) != APPM_OK || !check_passes(b, 20)) goto done;
    appm_renderer_stats(b, &sb);
    CHECK_MSG(sb.est_relerr != sw.est_relerr, "without the halves: est_relerr %.6g, whole %.6g", sb.est_relerr,
              sw.est_relerr);
    if (!(full = save(a, &n))) goto done;
    CHECK(appm_renderer_load(b2, full, n, NULL) == APPM_OK && check_passes(b2, 20) && same_render(whole, b2));
done:
    free(buf);
    free(full);
    appm_renderer_destroy(whole);
    appm_renderer_destroy(a);
    appm_renderer_destroy(b);
    appm_renderer_destroy(b2);
    appm_scene_destroy(s);
}

/* 3. Refusals.  `fresh` (0 passes) must stay untouched by a refused load. */
static void expect_refused(appm_renderer *r, const unsigned char *buf, size_t n, appm_status want, const char *word,
                           const char *what)
{
    appm_diag d;
    appm_status st = appm_renderer_load(r, buf, n, &d);
    CHECK_MSG(st == want, "%s: status %d (%s), expected %d", what, (int)st, d.message, (int)want);
    CHECK_MSG(st == APPM_OK || (d.status == st && strstr(d.message, word) != NULL),
              "%s: the message '%s' does not say '%s'", what, d.message, word);
    CHECK_MSG(r->pass == 0 && r->stats.passes == 0, "%s: a refused load changed the renderer", what);
}

static void test_refusals(const appm_scene *s, const appm_scene *other)
{
    static const struct {
        const char *word;
        int field;
    } opts[] = {{"method", 0}, {"seed", 1}, {"photons", 2}, {"alpha", 3}, {"radius", 4},
                {"max depth", 5}, {"direct", 6}, {"image", 7}, {"sampler", 8}, {"chains", 9}};
    appm_config base = config(APPM_METHOD_APPM, 1);
    appm_renderer *a = make(s, &base, 2), *r;
    unsigned char *buf, *copy;
    size_t n, k;
    if (!a) return;
    buf = save(a, &n);
    copy = (unsigned char *)malloc(n + 1);
    if (!buf || !copy) goto done;
    for (k = 0; k < sizeof opts / sizeof opts[0]; ++k) {
        appm_config c = base;
        switch (opts[k].field) {
        case 0: c.method = APPM_METHOD_PPM; break;
        case 1: c.seed = 8; break;
        case 2: c.photons = 3001; break;
        case 3: c.alpha = 0.5; break;
        case 4: c.radius = 0.05; break;
        case 5: c.max_depth = 5; break;
        case 6: c.direct = APPM_DIRECT_PHOTONS; break;
        case 7: c.height = 11; break;
        case 8: c.sampler = APPM_SAMPLER_RANDOM; break;
        default: c.chains = 2; break;
        }
        if ((r = make(s, &c, 0)) != NULL) expect_refused(r, buf, n, APPM_ERR_INVALID_ARG, opts[k].word, opts[k].word);
        appm_renderer_destroy(r);
    }
    if ((r = make(other, &base, 0)) != NULL) expect_refused(r, buf, n, APPM_ERR_INVALID_ARG, "scene", "scene");
    appm_renderer_destroy(r);
    if ((r = make(s, &base, 0)) == NULL) goto done;
    memcpy(copy, buf, n);
    put_le(copy + OFF_FORMAT, APPM__CK_FORMAT + 1, 4);
    fix_sum(copy, n);
    expect_refused(r, copy, n, APPM_ERR_INVALID_ARG, "format version", "format version");
    memcpy(copy, buf, n);
    put_le(copy + OFF_VERSION + 4, APPM_VERSION_MINOR + 1, 4);
    fix_sum(copy, n);
    expect_refused(r, copy, n, APPM_ERR_INVALID_ARG, "this is appm", "library version");
    memcpy(copy, buf, n);
    copy[OFF_LAYOUT + 4 + 4 + 1] = 'x'; /* "ld" -> "lx": a build with other pixel fields */
    fix_sum(copy, n);
    expect_refused(r, copy, n, APPM_ERR_INVALID_ARG, "pixel state", "field list");
    memcpy(copy, buf, n);
    copy[n] = 0;
    expect_refused(r, copy, n + 1, APPM_ERR_PARSE, "after its end", "trailing byte");
    expect_refused(r, (const unsigned char *)"P6\n1 1\n255\n", 11, APPM_ERR_PARSE, "not an appm checkpoint",
                   "another file");
    CHECK_MSG(appm_renderer_load(r, buf, n, NULL) == APPM_OK, "the unaltered checkpoint is refused");
    appm_renderer_destroy(r);
done:
    free(buf);
    free(copy);
    appm_renderer_destroy(a);
}

/* 4. Every truncation and every bit flip of a small checkpoint is an error;
 * with guided emission, whose learned state makes the checkpoint 30 times
 * larger, every `stride`-th truncation and one bit of every `stride`-th byte. */
static void test_damage(const appm_scene *s, appm_emission e, size_t stride)
{
    appm_config c = config(APPM_METHOD_APPM, 1);
    appm_renderer *a, *r;
    unsigned char *buf, *copy, *after;
    size_t n, i, n2;
    long wrong_trunc = 0, wrong_flip = 0, changed = 0;
    int b;
    c.width = 3;
    c.height = 2;
    c.photons = 500;
    c.emission = e;
    a = make(s, &c, 3);
    r = make(s, &c, 0);
    if (!a || !r) goto out;
    buf = save(a, &n);
    copy = (unsigned char *)malloc(n);
    if (!buf || !copy) goto done;
    CHECK(e == APPM_EMISSION_LIGHT || r->guide.nslot > 0);
    for (i = 0; i < n; i += stride) {
        memcpy(copy, buf, i);
        if (appm_renderer_load(r, copy, i, NULL) != APPM_ERR_PARSE) wrong_trunc++;
        changed += r->pass != 0;
    }
    CHECK_MSG(wrong_trunc == 0, "%ld of %lu truncations were not a parse error", wrong_trunc, (unsigned long)n);
    memcpy(copy, buf, n);
    for (i = 0; i < n; i += stride)
        for (b = stride > 1 ? (int)(i % 8) : 0; b < (stride > 1 ? (int)(i % 8) + 1 : 8); ++b) {
            appm_status st;
            copy[i] ^= (unsigned char)(1u << b);
            st = appm_renderer_load(r, copy, n, NULL);
            /* the format version is read before the checksum (another format may hash otherwise) */
            if (!(st == APPM_ERR_PARSE || (st == APPM_ERR_INVALID_ARG && i >= OFF_FORMAT && i < OFF_FORMAT + 4)))
                wrong_flip++;
            changed += r->pass != 0;
            copy[i] ^= (unsigned char)(1u << b);
        }
    CHECK_MSG(wrong_flip == 0, "%ld of %lu bit flips were not refused", wrong_flip, (unsigned long)(8 * n));
    CHECK_MSG(changed == 0, "%ld damaged checkpoints changed the renderer", changed);
    after = save(r, &n2);
    CHECK(after != NULL && r->pass == 0);
    free(after);
done:
    free(buf);
    free(copy);
out:
    appm_renderer_destroy(a);
    appm_renderer_destroy(r);
}

/* 5. Hostile: well-formed bytes, valid checksum, impossible content. */
static void hostile(appm_renderer *r, const unsigned char *buf, size_t n, size_t off, uint64_t v, int bytes,
                    const char *what)
{
    unsigned char *copy = (unsigned char *)malloc(n);
    appm_diag d;
    appm_status st;
    if (!copy) return;
    memcpy(copy, buf, n);
    put_le(copy + off, v, bytes);
    fix_sum(copy, n);
    st = appm_renderer_load(r, copy, n, &d);
    CHECK_MSG(st == APPM_ERR_PARSE, "%s: status %d (%s), expected a parse error", what, (int)st, d.message);
    CHECK(r->pass == 0);
    free(copy);
}

static void test_hostile(const appm_scene *s)
{
    appm_config c = config(APPM_METHOD_SPPM, 1);
    appm_renderer *a = make(s, &c, 2), *r = make(s, &c, 0);
    unsigned char *buf;
    size_t n, pix0;
    double nan = 0.0, neg = -1.0, inf = HUGE_VAL;
    uint64_t u;
    if (!a || !r || !(buf = save(a, &n))) goto out;
    nan = nan / nan;
    hostile(r, buf, n, OFF_W, 0xFFFFFFFFu, 4, "width 2^32-1");
    hostile(r, buf, n, OFF_W, 0, 4, "width 0");
    hostile(r, buf, n, OFF_LAYOUT, 0xFFFFFFFFu, 4, "2^32-1 pixel fields");
    hostile(r, buf, n, OFF_LAYOUT, 0, 4, "no pixel fields");
    hostile(r, buf, n, OFF_LAYOUT + 4, 0x7FFFFFFFu, 4, "a field name of 2 GB");
    hostile(r, buf, n, OFF_LAYOUT + 4 + 4 + 2, 0xFFFFFFFFu, 4, "a field of 2^32-1 values");
    hostile(r, buf, n, OFF_LAYOUT + 4 + 4 + 2 + 4, 7, 4, "a field of type 7");
    hostile(r, buf, n, OFF_PASS, (uint64_t)1 << 63, 8, "pass 2^63");
    memcpy(&u, &neg, sizeof u);
    hostile(r, buf, n, OFF_R1, u, 8, "negative r1");
    memcpy(&u, &inf, sizeof u);
    hostile(r, buf, n, OFF_SECONDS, u, 8, "infinite seconds");
    hostile(r, buf, n, OFF_R1, 0, 8, "r1 = 0 after two passes");
    /* the first value of pixel 0 (ld[0]) follows the field lists; then the last (sppm's R), the
     * photon budget's flag (u32) and reading (f64), the hash */
    pix0 = n - 8 - 12 - (size_t)r->w * r->h * 8 * (5 + 5);
    memcpy(&u, &nan, sizeof u);
    hostile(r, buf, n, pix0, u, 8, "NaN in a pixel");
    hostile(r, buf, n, n - 28, u, 8, "NaN radius in the last pixel");
    hostile(r, buf, n, n - 16, u, 8, "a NaN reading of the photon budget");
    hostile(r, buf, n, n - 20, 2, 4, "a photon budget's flag of 2");
    hostile(r, buf, n, n - 16, (uint64_t)1 << 63, 8, "a reading of -0 (saved again, it would be +0)");
    hostile(r, buf, n, n - 16, 0x3FF0000000000000ull, 8, "a reading of 1 where photons were given");
    free(buf);
out:
    appm_renderer_destroy(a);
    appm_renderer_destroy(r);
}

/* 6. Little-endian at the documented offsets, whatever the host. */
static void test_byte_order(const appm_scene *s)
{
    appm_config c = config(APPM_METHOD_PPM, 1);
    appm_renderer *a = make(s, &c, 3);
    unsigned char *buf;
    size_t n, pix0;
    uint64_t u;
    double r1, ld0;
    if (!a || !(buf = save(a, &n))) {
        appm_renderer_destroy(a);
        return;
    }
    CHECK(memcmp(buf, "APPMCKPT", 8) == 0);
    CHECK(buf[OFF_FORMAT] == APPM__CK_FORMAT && buf[OFF_FORMAT + 1] == 0 && buf[OFF_FORMAT + 3] == 0);
    CHECK(get_le(buf + OFF_W, 4) == 12 && get_le(buf + OFF_W + 4, 4) == 10);
    CHECK(get_le(buf + 44, 4) == APPM_SAMPLER_QMC && get_le(buf + 48, 4) == 1); /* sampler, chains */
    CHECK(get_le(buf + 52, 4) == 0 && a->guide.nslot == 0);                      /* guided lights */
    CHECK(get_le(buf + 56, 8) == 3000 && get_le(buf + 64, 8) == 7);              /* photons, seed */
    CHECK(get_le(buf + OFF_PASS, 8) == 3);
    u = get_le(buf + OFF_R1, 8);
    memcpy(&r1, &u, sizeof r1);
    CHECK(r1 == a->r1 && r1 > 0.0);
    /* ppm: 7 pixel values and lit + I[3]; then per guided light APPM__CK_GUIDE_WORDS words (none
     * here); the photon budget's flag and reading (12 bytes) */
    pix0 = n - 8 - 12 - (size_t)a->guide.nslot * 8 * APPM__CK_GUIDE_WORDS - (size_t)a->w * a->h * 8 * (8 + 3);
    CHECK(get_le(buf + n - 20, 4) == 0); /* photons given: no budget */
    u = get_le(buf + pix0, 8);
    memcpy(&ld0, &u, sizeof ld0);
    CHECK(ld0 == a->pix[0].ld[0]);
    /* the state's last field, "I": u32 length 1, "I", count 3, is_u64 0; then no chain field */
    CHECK(get_le(buf + pix0 - 17, 4) == 1 && buf[pix0 - 13] == 'I');
    CHECK(get_le(buf + pix0 - 12, 4) == 3 && get_le(buf + pix0 - 8, 4) == 0 && get_le(buf + pix0 - 4, 4) == 0);
    free(buf);
    appm_renderer_destroy(a);
}

/* 7. The first of the scene hash's parts in which a and b differ, or -1. */
static int part_differs(const uint64_t *a, const uint64_t *b)
{
    int k;
    for (k = 0; k < APPM__SH_PARTS; ++k)
        if (a[k] != b[k]) return k;
    return -1;
}

/* (the scene is changed in place and restored; no renderer uses it meanwhile) */
static void test_scene_hash(appm_scene *s)
{
    uint64_t h0[APPM__SH_PARTS], h[APPM__SH_PARTS];
    appm__tri t;
    appm__tri_info in;
    appm__material *m = &s->mat[s->info[1].mat];
    float keep;
    appm__scene_hash(s, h0);
    CHECK(s->ntri > 2);
    t = s->tri[0];
    in = s->info[0];
    s->tri[0] = s->tri[s->ntri - 1];
    s->info[0] = s->info[s->ntri - 1];
    s->tri[s->ntri - 1] = t;
    s->info[s->ntri - 1] = in;
    appm__scene_hash(s, h);
    CHECK_MSG(part_differs(h, h0) == -1, "the scene hash depends on the triangle order");
    s->tri[s->ntri - 1] = s->tri[0];
    s->info[s->ntri - 1] = s->info[0];
    s->tri[0] = t;
    s->info[0] = in;
    keep = s->tri[1].p2.y;
    s->tri[1].p2.y = nextafterf(keep, 1e30f);
    appm__scene_hash(s, h);
    CHECK_MSG(part_differs(h, h0) == APPM__SH_GEOMETRY, "a vertex moved by one ulp: part %d", part_differs(h, h0));
    s->tri[1].p2.y = keep;
    keep = m->color.x;
    m->color.x = keep * 0.5f;
    appm__scene_hash(s, h);
    CHECK_MSG(part_differs(h, h0) == APPM__SH_MATERIALS, "another albedo: part %d", part_differs(h, h0));
    m->color.x = keep;
    keep = m->ks.y;
    m->ks.y = keep + 0.125f;
    appm__scene_hash(s, h);
    CHECK_MSG(part_differs(h, h0) == APPM__SH_MATERIALS, "another Ks: part %d", part_differs(h, h0));
    m->ks.y = keep;
    keep = m->ns;
    m->ns = keep + 1.0f;
    appm__scene_hash(s, h);
    CHECK_MSG(part_differs(h, h0) == APPM__SH_MATERIALS, "another Ns: part %d", part_differs(h, h0));
    m->ns = keep;
    keep = s->cam.eye.z;
    s->cam.eye.z = keep + 1.0f;
    appm__scene_hash(s, h);
    CHECK_MSG(part_differs(h, h0) == APPM__SH_CAMERA, "another camera: part %d", part_differs(h, h0));
    s->cam.eye.z = keep;
    appm__scene_hash(s, h);
    CHECK(part_differs(h, h0) == -1);
}

/* A scene of a glossy box on a smooth floor under a spot light, written with
 * the given MTL Ks and Ns, the floor's second vn, the spot's cone and the fov,
 * into files of its own (tag), and loaded. */
static appm_scene *edit_scene(const char *tag, const char *ks, const char *ns, const char *vn, const char *cone,
                              const char *fov)
{
    char obj[1024], mtl[256], scene[512], name[64];
    appm_scene *s = NULL;
    appm_diag d;
    sprintf(mtl, "newmtl floor\nKd 0.6 0.6 0.6\nnewmtl gloss\nKd 0.3 0.3 0.3\nKs %s\nNs %s\n", ks, ns);
    sprintf(obj,
            "mtllib checkpoint-edit-%s.mtl\n"
            "v -2 0 -2\nv 2 0 -2\nv 2 0 2\nv -2 0 2\nvn 0 1 0\nvn %s\n"
            "usemtl floor\nf 4//1 3//2 2//1 1//1\n"
            "v -0.5 0 0.5\nv 0.5 0 0.5\nv 0.5 1 0.5\nv -0.5 1 0.5\nv 0.5 0 -0.5\nv 0.5 1 -0.5\n"
            "usemtl gloss\nf 5 6 7 8\nf 6 9 10 7\nf 8 7 10\n",
            tag, vn);
    sprintf(scene,
            "mesh checkpoint-edit-%s.obj\ncamera eye 1 2.5 3.5 target 0 0.4 0 up 0 1 0 fov %s\n"
            "light spot position 0.5 3 1.5 target 0 0 0 intensity 20 20 20 cone %s falloff 5\n"
            "environment 0.05 0.05 0.05\n",
            tag, fov, cone);
    sprintf(name, "edit-%s.mtl", tag);
    if (!check_write_file(check_path("checkpoint", name), mtl)) return NULL;
    sprintf(name, "edit-%s.obj", tag);
    if (!check_write_file(check_path("checkpoint", name), obj)) return NULL;
    sprintf(name, "edit-%s.scene", tag);
    if (!check_write_file(check_path("checkpoint", name), scene)) return NULL;
    CHECK_MSG(appm_scene_load(check_path("checkpoint", name), NULL, &s, &d) == APPM_OK, "%s:%u: %s", d.file, d.line,
              d.message);
    return s;
}

/* A checkpoint of the scene files, resumed after an edit of one value in them:
 * refused, naming the part that differs; after no edit (the files written and
 * read again), accepted. */
static void test_edits(void)
{
    static const struct {
        const char *tag, *ks, *ns, *vn, *cone, *fov, *word;
    } v[] = {{"same", "0.4 0.4 0.4", "20", "0.1 1 0", "40", "40", NULL},
             {"ns", "0.4 0.4 0.4", "21", "0.1 1 0", "40", "40", "its materials differ"},
             {"ks", "0.4 0.41 0.4", "20", "0.1 1 0", "40", "40", "its materials differ"},
             {"vn", "0.4 0.4 0.4", "20", "0.1 1 0.001", "40", "40", "its shading normals differ"},
             {"cone", "0.4 0.4 0.4", "20", "0.1 1 0", "40.5", "40", "its lights differ"},
             {"fov", "0.4 0.4 0.4", "20", "0.1 1 0", "40", "40.001", "its camera or image size differs"}};
    appm_scene *base = edit_scene("base", v[0].ks, v[0].ns, v[0].vn, v[0].cone, v[0].fov);
    appm_config c = config(APPM_METHOD_APPM, 1);
    appm_renderer *a = base ? make(base, &c, 2) : NULL;
    size_t k, n_edit = 0;
    unsigned char *buf = a ? save(a, &n_edit) : NULL;
    CHECK(buf != NULL);
    for (k = 0; buf && k < sizeof v / sizeof v[0]; ++k) {
        appm_scene *s = edit_scene(v[k].tag, v[k].ks, v[k].ns, v[k].vn, v[k].cone, v[k].fov);
        appm_renderer *r = s ? make(s, &c, 0) : NULL;
        if (r && v[k].word)
            expect_refused(r, buf, n_edit, APPM_ERR_INVALID_ARG, v[k].word, v[k].tag);
        else if (r)
            CHECK_MSG(appm_renderer_load(r, buf, n_edit, NULL) == APPM_OK, "the same files read again: refused");
        CHECK(r != NULL);
        appm_renderer_destroy(r);
        appm_scene_destroy(s);
    }
    free(buf);
    appm_renderer_destroy(a);
    appm_scene_destroy(base);
}

static void test_point_light(void)
{
    static const char obj[] = "v -1 0 -1\nv 1 0 -1\nv 1 0 1\nv -1 0 1\nf 4 3 2 1\n";
    static const char sc1[] = "mesh checkpoint-floor.obj\ncamera eye 0 3 3 target 0 0 0 up 0 1 0 fov 40\n"
                              "light point position 0 1 0 intensity 5 5 5\n";
    static const char sc2[] = "mesh checkpoint-floor.obj\ncamera eye 0 3 3 target 0 0 0 up 0 1 0 fov 40\n"
                              "light point position 0 1.5 0 intensity 5 5 5\n";
    appm_scene *a = NULL, *b = NULL;
    appm_diag d;
    uint64_t ha[APPM__SH_PARTS], hb[APPM__SH_PARTS];
    if (!check_write_file(check_path("checkpoint", "floor.obj"), obj) ||
        !check_write_file(check_path("checkpoint", "l1.scene"), sc1) ||
        !check_write_file(check_path("checkpoint", "l2.scene"), sc2)) {
        CHECK_MSG(0, "cannot write the light scenes");
        return;
    }
    CHECK(appm_scene_load(check_path("checkpoint", "l1.scene"), NULL, &a, &d) == APPM_OK);
    CHECK(appm_scene_load(check_path("checkpoint", "l2.scene"), NULL, &b, &d) == APPM_OK);
    if (a && b) {
        appm__scene_hash(a, ha);
        appm__scene_hash(b, hb);
        CHECK_MSG(part_differs(ha, hb) == APPM__SH_LIGHTS, "a moved point light: part %d", part_differs(ha, hb));
    }
    appm_scene_destroy(a);
    appm_scene_destroy(b);
}

/* 8. The options as appm__ck_head_of knew them.  If this fails, appm_config has
 * changed: an option that changes the image (a sampler, chains, ...) must go
 * into appm__ck_head (written, read, compared with a message) and the layout
 * comment of appm.c 12.2; one that does not (like threads) needs nothing.
 * Then add it here. */
typedef struct known_config {
    appm_allocator allocator;
    appm_log_fn log;
    void *log_user;
    appm_method method;  /* compared */
    appm_direct direct;  /* compared */
    uint32_t width, height; /* compared */
    uint64_t photons;    /* compared */
    double radius;       /* compared */
    double alpha;        /* compared */
    unsigned threads;    /* free: the image does not depend on it */
    uint64_t seed;       /* compared */
    unsigned max_depth;  /* compared */
    appm_sampler sampler; /* compared */
    unsigned chains;     /* compared */
    appm_emission emission; /* compared (as the count of guided lights) */
    appm_file_reader reader; /* free: where a load's bytes come from */
    appm_missing_textures missing_textures; /* free: what it changes is in the scene's hash */
    appm_stand_in stand_in; /* free: the plate and the sky are in the scene's hash */
} known_config;

static void test_config_tripwire(void)
{
    CHECK_MSG(sizeof(appm_config) == sizeof(known_config) &&
                  offsetof(appm_config, chains) == offsetof(known_config, chains) &&
                  offsetof(appm_config, reader) == offsetof(known_config, reader) &&
                  offsetof(appm_config, missing_textures) == offsetof(known_config, missing_textures) &&
                  offsetof(appm_config, stand_in) == offsetof(known_config, stand_in),
              "appm_config has fields the checkpoint does not know: see the comment above test_config_tripwire");
}

static void test_arguments(const appm_scene *s)
{
    appm_config c = config(APPM_METHOD_PT, 1);
    appm_renderer *a = make(s, &c, 1);
    unsigned char small[16];
    size_t need = 0;
    appm_diag d;
    if (!a) return;
    CHECK(appm_renderer_save(a, small, sizeof small, &need, &d) == APPM_ERR_INVALID_ARG && need > sizeof small);
    CHECK(strstr(d.message, "buffer") != NULL);
    CHECK(appm_renderer_save(NULL, NULL, 0, &need, &d) == APPM_ERR_INVALID_ARG && need == 0);
    CHECK(appm_renderer_load(a, NULL, 5, &d) == APPM_ERR_INVALID_ARG);
    CHECK(appm_renderer_load(NULL, small, 5, &d) == APPM_ERR_INVALID_ARG);
    CHECK(appm_renderer_load(a, small, 0, &d) == APPM_ERR_PARSE);
    CHECK(appm_renderer_save_file(a, NULL, &d) == APPM_ERR_INVALID_ARG);
    CHECK(appm_renderer_load_file(a, NULL, &d) == APPM_ERR_INVALID_ARG);
    appm_renderer_destroy(a);
}

int main(void)
{
    appm_scene *s = check_load_scene("scenes/cornell-sphere.scene");
    appm_scene *other = check_load_scene("scenes/cornell-original.scene");
    {   /* checkpoints record the version numbers; --version and appm_version() say the string */
        char v[32];
        snprintf(v, sizeof v, "%d.%d.%d", APPM_VERSION_MAJOR, APPM_VERSION_MINOR, APPM_VERSION_PATCH);
        CHECK_MSG(strcmp(v, APPM_VERSION) == 0 && strcmp(v, appm_version()) == 0, "version %s, string %s", v,
                  APPM_VERSION);
    }
    if (s && other) {
        test_resume(s);
        test_file(s);
        test_chains(s);
        test_fields_matter(s);
        test_refusals(s, other);
        test_damage(s, APPM_EMISSION_LIGHT, 1);
        test_damage(s, APPM_EMISSION_GUIDED, 53);
        test_hostile(s);
        test_byte_order(s);
        test_arguments(s);
        test_scene_hash(s);
    }
    test_point_light();
    test_halves_matter();
    test_lit_carried();
    test_edits();
    test_config_tripwire();
    appm_scene_destroy(s);
    appm_scene_destroy(other);
    return check_finish();
}
