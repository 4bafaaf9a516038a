/* tests/t_loader.c - the OBJ/MTL/.scene loader against the interface contract
 * (docs/scene-format.md sections 1 and 2) and the malformed inputs that crashed
 * other loaders (docs/testing.md section 3).
 *
 * What is checked, and why it matters:
 *   - the Cornell boxes of scenes/ load with the triangle, material and light
 *     counts and the light power that the files imply (counted here by hand
 *     from the OBJ/MTL text, not taken from the loader);
 *   - every OBJ feature of the contract (CRLF, negative indices, N-gons, every
 *     face form, normals before positions, no final newline, long lines) gives
 *     the same triangles as its plain equivalent;
 *   - every malformed input is an error naming file and line, never a crash
 *     (the sanitizer build turns out-of-bounds reads into failures);
 *   - warnings arrive through the log callback once per kind and file;
 *   - the MTL -> material table and the `.scene` statements, field by field;
 *   - a `.scene` with its OBJ and MTL from memory is the scene read from the
 *     files (same hash, same image), and takes nothing from disk;
 *   - the locale-free number parser, accepted and rejected forms.
 *
 * Fixtures live in tests/fixtures/ (each named after what it exercises); files
 * that are easier to build in code are written to tests/out/.  Run from the
 * repository root. */
#include "../appm.c"
#include "check.h"

#define FIX "tests/fixtures/"

/* ---- helpers ---------------------------------------------------------------- */

/* Every warning the loader sends, so tests can count them by kind. */
#define LOG_MAX 64
typedef struct logbuf {
    int n;
    unsigned line[LOG_MAX];
    char file[LOG_MAX][300];
    char msg[LOG_MAX][300];
} logbuf;

static void log_fn(void *user, const char *file, unsigned line, const char *msg)
{
    logbuf *lb = (logbuf *)user;
    if (lb->n >= LOG_MAX) return;
    lb->line[lb->n] = line;
    snprintf(lb->file[lb->n], sizeof lb->file[0], "%s", file ? file : "(null)");
    snprintf(lb->msg[lb->n], sizeof lb->msg[0], "%s", msg ? msg : "(null)");
    lb->n++;
}

/* Warnings whose message contains `needle`. */
static int log_count(const logbuf *lb, const char *needle)
{
    int i, n = 0;
    for (i = 0; i < lb->n; ++i) n += strstr(lb->msg[i], needle) != NULL;
    return n;
}

static int log_find(const logbuf *lb, const char *needle)
{
    int i;
    for (i = 0; i < lb->n; ++i)
        if (strstr(lb->msg[i], needle)) return i;
    return -1;
}

/* "Once per kind and file": the same message from the same file twice means a
 * warning kind was repeated. */
static int log_has_repeats(const logbuf *lb)
{
    int i, j;
    for (i = 0; i < lb->n; ++i)
        for (j = i + 1; j < lb->n; ++j)
            if (strcmp(lb->file[i], lb->file[j]) == 0 && strcmp(lb->msg[i], lb->msg[j]) == 0) return 1;
    return 0;
}

static void cfg_with_log(appm_config *cfg, logbuf *lb)
{
    memset(cfg, 0, sizeof *cfg);
    if (lb) {
        memset(lb, 0, sizeof *lb);
        cfg->log = log_fn;
        cfg->log_user = lb;
    }
}

static appm_status load(const char *path, appm_scene **s, appm_diag *d, logbuf *lb)
{
    appm_config cfg;
    cfg_with_log(&cfg, lb);
    *s = NULL;
    return appm_scene_load(path, &cfg, s, d);
}

/* Loads OBJ (and MTL) text from exact-size heap copies without a terminating
 * NUL, so that the sanitizer build catches any read past the given length. */
static appm_status load_mem_n(const char *obj, size_t obj_len, const char *mtl, size_t mtl_len,
                              appm_scene **s, appm_diag *d, logbuf *lb)
{
    appm_config cfg;
    char *o = (char *)malloc(obj_len ? obj_len : 1), *m = NULL;
    appm_status st;
    memcpy(o, obj, obj_len);
    if (mtl) {
        m = (char *)malloc(mtl_len ? mtl_len : 1);
        memcpy(m, mtl, mtl_len);
    }
    cfg_with_log(&cfg, lb);
    *s = NULL;
    st = appm_scene_load_obj_memory(o, obj_len, m, mtl_len, "mem.obj", &cfg, s, d);
    free(o);
    free(m);
    return st;
}

static appm_status load_mem(const char *obj, const char *mtl, appm_scene **s, appm_diag *d, logbuf *lb)
{
    return load_mem_n(obj, strlen(obj), mtl, mtl ? strlen(mtl) : 0, s, d, lb);
}

static const char LIGHT_MTL[] = "newmtl light\nKd 0.5 0.5 0.5\nKe 1 1 1\n";

/* OBJ text with one emissive triangle using `light`, for MTL tests. */
static const char TRI_LIGHT[] = "mtllib m.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nusemtl light\nf 1 2 3\n";

static int same_v3(appm__v3 a, appm__v3 b) { return a.x == b.x && a.y == b.y && a.z == b.z; }

/* Two scenes hold the same triangles: positions, normals, areas, materials and
 * shading normals, bit for bit (the BVH orders triangles by geometry only, so
 * equal input gives equal order). */
static int same_geometry(const appm_scene *a, const appm_scene *b)
{
    uint32_t i;
    if (!a || !b || a->ntri != b->ntri || a->nnormals != b->nnormals) return 0;
    for (i = 0; i < a->ntri; ++i) {
        const appm__tri_info *x = &a->info[i], *y = &b->info[i];
        if (!same_v3(a->tri[i].p0, b->tri[i].p0) || !same_v3(a->tri[i].p1, b->tri[i].p1) ||
            !same_v3(a->tri[i].p2, b->tri[i].p2))
            return 0;
        if (!same_v3(x->ng, y->ng) || x->area != y->area || x->mat != y->mat ||
            (x->n0 < 0) != (y->n0 < 0))
            return 0;
        if (x->n0 >= 0) {
            int k;
            for (k = 0; k < 3; ++k)
                if (!same_v3(a->normals[x->n0 + k], b->normals[y->n0 + k])) return 0;
        }
    }
    return 1;
}

static double emissive_area(const appm_scene *s)
{
    uint32_t i;
    double a = 0.0;
    for (i = 0; i < s->ntri; ++i)
        if (s->mat[s->info[i].mat].emissive) a += s->info[i].area;
    return a;
}

/* An error of kind `st` on line `line` of a file whose name contains `file`. */
#define CHECK_ERR(got, d, want_st, want_line, file_part)                                         \
    do {                                                                                         \
        appm_status got_ = (got); /* evaluated once: `got` is usually a load call */             \
        CHECK_MSG(got_ == (want_st), "status %d (%s), expected %d; %s:%u: %s", (int)got_,        \
                  appm_status_string(got_), (int)(want_st), (d).file, (d).line, (d).message);   \
        CHECK_MSG((d).status == (want_st), "diag.status %d", (int)(d).status);                   \
        CHECK_MSG((d).line == (unsigned)(want_line), "diag.line %u, expected %u (%s)", (d).line, \
                  (unsigned)(want_line), (d).message);                                           \
        CHECK_MSG(strstr((d).file, (file_part)) != NULL, "diag.file '%s' should name '%s'",      \
                  (d).file, (file_part));                                                        \
        CHECK_MSG((d).message[0] != 0, "empty message");                                         \
    } while (0)

/* ---- Cornell boxes ------------------------------------------------------------ */

typedef struct cornell_case {
    const char *path;
    uint64_t tris;            /* quads count 2, triangles 1 (awk over the `f` lines) */
    uint32_t diffuse, mirror, dielectric;
    double ke[3];             /* Ke of the `light` material */
    uint32_t glossy;          /* materials with Ks > 0 on illum 2 (glossy since interface.md 2) */
    int scene_camera;         /* loaded through a .scene with a camera statement */
} cornell_case;

/* CornellBox-Glossy's two glossy materials after the Kd + Ks <= 1 scaling. */
static void check_glossy_box(const appm_scene *s)
{
    uint32_t m, nsph = 0, nfloor = 0;
    for (m = 1; m < s->nmat; ++m) {
        const appm__material *mt = &s->mat[m];
        if (mt->kind != APPM__MAT_GLOSSY) continue;
        if (mt->ns == 32.0f) { /* sphere: Kd 0.486 0.631 0.663, Ks 0.7 */
            nsph++;
            CHECK_NEAR(mt->color.x, 0.486 / 1.186, 1e-6);
            CHECK_NEAR(mt->ks.x, 0.7 / 1.186, 1e-6);
            CHECK_NEAR(mt->color.z + mt->ks.z, 1.0, 1e-6);
        } else if (mt->ns == 80.0f) { /* floor: Kd 0.725 0.71 0.68, Ks 0.3 (sums <= 1.025) */
            nfloor++;
            CHECK_NEAR(mt->color.x, 0.725 / 1.025, 1e-6);
            CHECK_NEAR(mt->color.z, 0.68, 1e-6); /* 0.98: not scaled */
            CHECK_NEAR(mt->ks.z, 0.3, 1e-6);
        }
    }
    CHECK_MSG(nsph == 1 && nfloor == 1, "%u sphere, %u floor materials", nsph, nfloor);
}

static void test_cornell(void)
{
    /* The light quad of every box spans x in [-0.24, 0.23] and z in [-0.22, 0.16]:
     * area 0.47 * 0.38.  A one-sided Lambertian emitter sends Phi = pi A Le. */
    const double light_area = 0.47 * 0.38;
    static const cornell_case cases[] = {
        {"scenes/CornellBox-Original.obj", 36, 8, 0, 0, {17, 12, 4}, 0, 0},
        {"scenes/CornellBox-Mirror.obj", 36, 7, 1, 0, {17, 12, 4}, 0, 0},
        {"scenes/CornellBox-Empty-RG.obj", 12, 6, 0, 0, {17, 12, 4}, 0, 0},
        {"scenes/CornellBox-Empty-White.obj", 12, 6, 0, 0, {10, 10, 10}, 0, 0},
        {"scenes/CornellBox-Glossy.obj", 1112, 6, 0, 0, {10, 10, 10}, 2, 0},
        {"scenes/CornellBox-Sphere.obj", 2188, 6, 1, 1, {10, 10, 10}, 0, 0},
        {"scenes/cornell-original.scene", 36, 8, 0, 0, {17, 12, 4}, 0, 1},
        {"scenes/cornell-mirror.scene", 36, 7, 1, 0, {17, 12, 4}, 0, 1},
        {"scenes/cornell-empty-rg.scene", 12, 6, 0, 0, {17, 12, 4}, 0, 1},
        {"scenes/cornell-empty-white.scene", 12, 6, 0, 0, {10, 10, 10}, 0, 1},
        {"scenes/cornell-glossy.scene", 1112, 6, 0, 0, {10, 10, 10}, 2, 1},
        {"scenes/cornell-sphere.scene", 2188, 6, 1, 1, {10, 10, 10}, 0, 1},
        {"scenes/cornell-sphere-dof.scene", 2188, 6, 1, 1, {10, 10, 10}, 0, 1},
    };
    size_t k;
    for (k = 0; k < sizeof cases / sizeof cases[0]; ++k) {
        const cornell_case *c = &cases[k];
        appm_scene *s;
        appm_diag d;
        logbuf lb;
        appm_scene_info in;
        appm_status st = load(c->path, &s, &d, &lb);
        int i;
        CHECK_MSG(st == APPM_OK, "%s: %s:%u: %s", c->path, d.file, d.line, d.message);
        if (st != APPM_OK) continue;
        appm_scene_get_info(s, &in);
        CHECK_MSG(in.triangles == c->tris, "%s: %llu triangles", c->path, (unsigned long long)in.triangles);
        CHECK_MSG(in.dropped_triangles == 0, "%s: dropped %llu", c->path,
                  (unsigned long long)in.dropped_triangles);
        CHECK_MSG(in.materials_diffuse == c->diffuse && in.materials_mirror == c->mirror &&
                      in.materials_dielectric == c->dielectric && in.materials_glossy == c->glossy,
                  "%s: %u diffuse, %u mirror, %u dielectric, %u glossy", c->path, in.materials_diffuse,
                  in.materials_mirror, in.materials_dielectric, in.materials_glossy);
        CHECK_MSG(in.materials_emissive == 1, "%s: %u emissive", c->path, in.materials_emissive);
        CHECK_MSG(in.lights_area == 2 && in.lights_point == 0 && in.lights_spot == 0 &&
                      in.lights_environment == 0,
                  "%s: lights %u/%u/%u/%u", c->path, in.lights_area, in.lights_point, in.lights_spot,
                  in.lights_environment);
        for (i = 0; i < 3; ++i) CHECK_NEAR(in.power_area[i], APPM__PI * light_area * c->ke[i], 1e-2);
        CHECK_NEAR(emissive_area(s), light_area, 1e-5);
        CHECK(in.width == 512 && in.height == 512);
        /* Warnings: every MTL of the archive has Ka lines (ignored), each file
         * must say so exactly once.  Only the glossy box's sphere has Kd + Ks > 1
         * (0.486 + 0.7 in red): one warning, and the two scaled to sum to 1. */
        CHECK_MSG(log_count(&lb, "'Ka'") == 1, "%s: %d Ka warnings", c->path, log_count(&lb, "'Ka'"));
        CHECK_MSG(log_count(&lb, "Kd + Ks") == (c->glossy ? 1 : 0), "%s: %d Kd + Ks warnings", c->path,
                  log_count(&lb, "Kd + Ks"));
        if (c->glossy) check_glossy_box(s);
        CHECK_MSG(!log_has_repeats(&lb), "%s: a warning kind was sent twice", c->path);
        if (log_find(&lb, "'Ka'") >= 0)
            CHECK(strstr(lb.file[log_find(&lb, "'Ka'")], ".mtl") != NULL);
        if (c->scene_camera) {
            /* camera eye (-0.011, y, z) target (-0.011, y, 0) up (0 1 0) fov 39.31 */
            CHECK_NEAR(s->cam.eye.x, -0.011, 1e-6);
            CHECK_NEAR(s->cam.forward.z, -1.0, 1e-6);
            CHECK_NEAR(s->cam.fov, 39.31, 1e-4);
        } else {
            CHECK_NEAR(s->cam.fov, 40.0, 1e-6); /* the automatic camera of a bare .obj */
        }
        if (c->dielectric) {
            /* CornellBox-Sphere: two spheres of 1088 triangles, every one with
             * vertex normals (v//vn faces); mirror Ks 0.95, glass Ni 2.5. */
            uint32_t t, nmir = 0, ndie = 0, smooth_mir = 0, smooth_die = 0, m;
            for (t = 0; t < s->ntri; ++t) {
                const appm__material *mt = &s->mat[s->info[t].mat];
                if (mt->kind == APPM__MAT_MIRROR) {
                    nmir++;
                    smooth_mir += s->info[t].n0 >= 0;
                } else if (mt->kind == APPM__MAT_DIELECTRIC) {
                    ndie++;
                    smooth_die += s->info[t].n0 >= 0;
                }
            }
            CHECK_MSG(nmir == 1088 && ndie == 1088, "%u mirror, %u glass triangles", nmir, ndie);
            CHECK(smooth_mir == 1088 && smooth_die == 1088);
            CHECK(s->nnormals == 3 * 2188); /* every face of this file has vn */
            for (m = 1; m < s->nmat; ++m) {
                if (s->mat[m].kind == APPM__MAT_MIRROR) {
                    CHECK_NEAR(s->mat[m].color.x, 0.95, 1e-6);
                    CHECK_NEAR(s->mat[m].color.z, 0.95, 1e-6);
                }
                if (s->mat[m].kind == APPM__MAT_DIELECTRIC) CHECK_NEAR(s->mat[m].ior, 2.5, 1e-6);
            }
        }
        appm_scene_destroy(s);
    }
}

/* Two meshes in one scene: the warnings are per file (one Ka warning for each
 * MTL), the triangles and lights add up. */
static void test_two_meshes(void)
{
    const char *path = check_path("loader", "two-meshes.scene");
    appm_scene *s;
    appm_diag d;
    logbuf lb;
    appm_scene_info in;
    appm_status st;
    CHECK(check_write_file(path, "mesh ../../scenes/CornellBox-Original.obj\n"
                                 "mesh ../../scenes/CornellBox-Mirror.obj\n"));
    st = load(path, &s, &d, &lb);
    CHECK_MSG(st == APPM_OK, "%s:%u: %s", d.file, d.line, d.message);
    if (st != APPM_OK) return;
    appm_scene_get_info(s, &in);
    CHECK(in.triangles == 72);
    CHECK(in.lights_area == 4);
    CHECK(in.materials_emissive == 2);
    CHECK(in.materials_mirror == 1);
    CHECK(log_count(&lb, "'Ka'") == 2);
    {
        int a = log_find(&lb, "'Ka'"), b;
        for (b = a + 1; b < lb.n; ++b)
            if (strstr(lb.msg[b], "'Ka'")) break;
        CHECK(a >= 0 && b < lb.n && strstr(lb.file[a], "Original.mtl") && strstr(lb.file[b], "Mirror.mtl"));
    }
    CHECK(!log_has_repeats(&lb));
    appm_scene_destroy(s);
    /* One OBJ with two material libraries: each library is its own file.  The
     * OBJ warns first (about `p`), and that must not silence a kind of MTL
     * warning: the two files' kinds are counted separately. */
    path = check_path("loader", "two-mtllib.obj");
    CHECK(check_write_file(path, "p 1\nl 1 2\nvp 1\n"
                                 "mtllib ../../scenes/CornellBox-Original.mtl\n"
                                 "mtllib ../../scenes/CornellBox-Mirror.mtl\n"
                                 "v 0 0 0\nv 1 0 0\nv 0 1 0\nusemtl light\nf 1 2 3\n"));
    st = load(path, &s, &d, &lb);
    CHECK_MSG(st == APPM_OK, "%s:%u: %s", d.file, d.line, d.message);
    CHECK(log_count(&lb, "'Ka'") == 2);
    CHECK(!log_has_repeats(&lb));
    if (s) CHECK(s->nmat == 1 + 8 + 8);
    appm_scene_destroy(s);
}

/* ---- OBJ features ------------------------------------------------------------- */

/* tests/fixtures/crlf.obj with LF line ends, comments and all, so that line
 * numbers agree too. */
static const char SQUARE_LF[] = "# The same unit square as in t_loader.c's LF text, with CRLF line ends.\n"
                                "# A loader that keeps the CR would look for \"light.mtl\\r\" and \"light\\r\".\n"
                                "mtllib light.mtl\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvn 0 0 1\n"
                                "usemtl light\nf 1//1 2//1 3//1\nf 1//1 3//1 4//1\n";

static void test_crlf(void)
{
    appm_scene *a, *b, *c;
    appm_diag d;
    logbuf lb;
    char cr[sizeof SQUARE_LF];
    size_t i;
    appm_status st = load(FIX "crlf.obj", &a, &d, &lb);
    CHECK_MSG(st == APPM_OK, "%s:%u: %s", d.file, d.line, d.message);
    CHECK(load_mem(SQUARE_LF, LIGHT_MTL, &b, &d, NULL) == APPM_OK);
    /* old Mac line ends (CR only) are lines too */
    memcpy(cr, SQUARE_LF, sizeof cr);
    for (i = 0; cr[i]; ++i)
        if (cr[i] == '\n') cr[i] = '\r';
    CHECK(load_mem(cr, LIGHT_MTL, &c, &d, NULL) == APPM_OK);
    if (a && b && c) {
        CHECK(a->ntri == 2);
        CHECK(a->nnormals == 6);
        CHECK(a->mat[a->info[0].mat].emissive); /* "usemtl light\r" found its material */
        CHECK(lb.n == 0);                       /* no "cannot open light.mtl\r" */
        CHECK(same_geometry(a, b));
        CHECK(same_geometry(c, b));
    }
    appm_scene_destroy(a);
    appm_scene_destroy(b);
    appm_scene_destroy(c);
}

static void test_negative_index(void)
{
    /* negative-index.obj with every relative index resolved by hand against the
     * vertices (and normals) read so far. */
    static const char positive[] = "mtllib light.mtl\nusemtl light\n"
                                   "v 0 0 0\nv 1 0 0\nv 1 1 0\nvn 0 0 1\nf 1//1 2//1 3//1\n"
                                   "v 0 1 0\nf 1 3 4\n"
                                   "v 2 0 0\nv 2 1 0\nvn 0 0.6 0.8\nf 2//1 5//2 6//1\n";
    appm_scene *a, *b, *c;
    appm_diag d;
    CHECK(load(FIX "negative-index.obj", &a, &d, NULL) == APPM_OK);
    CHECK(load_mem(positive, LIGHT_MTL, &b, &d, NULL) == APPM_OK);
    if (a && b) {
        CHECK(a->ntri == 3);
        CHECK(a->nnormals == 6);
        CHECK(same_geometry(a, b));
    }
    appm_scene_destroy(a);
    appm_scene_destroy(b);
    /* relative indices that reach before the first vertex, normal or vt */
    CHECK_ERR(load_mem("v 0 0 0\nv 1 0 0\nv 0 1 0\nf -4 -2 -1\n", NULL, &c, &d, NULL), d, APPM_ERR_PARSE, 4,
              "mem.obj");
    CHECK_ERR(load_mem("v 0 0 0\nv 1 0 0\nv 0 1 0\nvn 0 0 1\nf 1//-2 2//-1 3//-1\n", NULL, &c, &d, NULL), d,
              APPM_ERR_PARSE, 5, "mem.obj");
    CHECK_ERR(load_mem("v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nf 1/-1 2/-1 3/-2\n", NULL, &c, &d, NULL), d,
              APPM_ERR_PARSE, 5, "mem.obj");
    CHECK(c == NULL);
}

static void test_polygon(void)
{
    appm_scene *s;
    appm_diag d;
    uint32_t i, n5 = 0, n20 = 0;
    double a5 = 0, a20 = 0;
    CHECK(load(FIX "polygon.obj", &s, &d, NULL) == APPM_OK);
    if (!s) return;
    CHECK(s->ntri == (5 - 2) + (20 - 2));
    CHECK(s->dropped == 0);
    for (i = 0; i < s->ntri; ++i) {
        if (fabs(s->info[i].ng.z) > 0.999f) { /* the pentagon lies in z = 0 */
            n5++;
            a5 += s->info[i].area;
        } else { /* the 20-gon in y = 3 */
            n20++;
            a20 += s->info[i].area;
            CHECK(fabs(s->tri[i].p0.y - 3.0f) < 1e-6f);
        }
    }
    CHECK(n5 == 3 && n20 == 18);
    /* a regular n-gon of radius r has area (n/2) r^2 sin(2 pi / n) */
    CHECK_NEAR(a5, 2.5 * sin(2.0 * APPM__PI / 5.0), 1e-5);
    CHECK_NEAR(a20, 10.0 * 4.0 * sin(2.0 * APPM__PI / 20.0), 1e-4);
    appm_scene_destroy(s);
}

/* A 40-gon whose face line carries 100 KB of blanks between its indices: no
 * fixed line or token buffer, and every index still counts. */
static void test_big_polygon_long_line(void)
{
    enum { N = 40, PAD = 2500 };
    size_t cap = 200000, n = 0;
    char *buf = (char *)malloc(cap);
    int k, j;
    appm_scene *s;
    appm_diag d;
    appm_status st;
    n += (size_t)sprintf(buf + n, "mtllib x\nusemtl light\n");
    for (k = 0; k < N; ++k)
        n += (size_t)sprintf(buf + n, "v %.9f %.9f 0\n", cos(2 * APPM__PI * k / N), sin(2 * APPM__PI * k / N));
    buf[n++] = 'f';
    for (k = 0; k < N; ++k) {
        for (j = 0; j < PAD; ++j) buf[n++] = (char)(j % 2 ? '\t' : ' ');
        n += (size_t)sprintf(buf + n, "%d", k + 1);
    }
    CHECK(n > 100000);
    st = load_mem_n(buf, n, LIGHT_MTL, strlen(LIGHT_MTL), &s, &d, NULL); /* no final newline either */
    CHECK_MSG(st == APPM_OK, "%s:%u: %s", d.file, d.line, d.message);
    if (s) {
        uint32_t i;
        double area = 0;
        CHECK(s->ntri == N - 2 && s->dropped == 0);
        for (i = 0; i < s->ntri; ++i) area += s->info[i].area;
        CHECK_NEAR(area, 0.5 * N * sin(2 * APPM__PI / N), 1e-4);
    }
    appm_scene_destroy(s);
    free(buf);
}

static void test_missing_mtl(void)
{
    appm_scene *s;
    appm_diag d;
    logbuf lb;
    appm_status st;
    int w;
    /* Bare: the warning, and no light at all (the face fell back to the
     * default material), so the white environment stands in. */
    st = load(FIX "missing-mtl.obj", &s, &d, &lb);
    CHECK(st == APPM_OK);
    if (s) {
        appm_scene_info in;
        appm_scene_get_info(s, &in);
        CHECK(in.lights_environment == 1 && in.lights_point == 0 && in.lights_area == 0);
        appm_scene_destroy(s);
    }
    w = log_find(&lb, "does-not-exist.mtl");
    CHECK_MSG(w >= 0, "no warning about the missing .mtl (%d warnings)", lb.n);
    if (w >= 0) {
        CHECK(lb.line[w] == 2);
        CHECK(strstr(lb.file[w], "missing-mtl.obj") != NULL);
    }
    CHECK(log_count(&lb, "unknown material") == 1);
    /* With a point light from a .scene the same mesh loads. */
    st = load(FIX "missing-mtl.scene", &s, &d, &lb);
    CHECK_MSG(st == APPM_OK, "%s:%u: %s", d.file, d.line, d.message);
    if (s) {
        appm_scene_info in;
        appm_scene_get_info(s, &in);
        CHECK(in.triangles == 1);
        CHECK(in.lights_point == 1 && in.lights_area == 0);
        CHECK(s->info[0].mat == 0);
        CHECK(s->mat[0].kind == APPM__MAT_DIFFUSE);
        CHECK_NEAR(s->mat[0].color.y, 0.8, 1e-6); /* the default albedo */
        CHECK(log_find(&lb, "does-not-exist.mtl") >= 0);
    }
    appm_scene_destroy(s);
}

static void test_vn_before_v(void)
{
    appm_scene *s;
    appm_diag d;
    CHECK(load(FIX "vn-before-v.obj", &s, &d, NULL) == APPM_OK);
    if (!s) return;
    CHECK(s->ntri == 1 && s->nnormals == 3);
    if (s->ntri == 1 && s->info[0].n0 >= 0) {
        const appm__v3 *n = s->normals + s->info[0].n0;
        /* f 1//2 2//1 3//2: the corners' normals in face order */
        CHECK(same_v3(n[0], appm__v(0, 0, -1)));
        CHECK(same_v3(n[1], appm__v(0, 0, 1)));
        CHECK(same_v3(n[2], appm__v(0, 0, -1)));
    }
    appm_scene_destroy(s);
}

static void test_face_forms(void)
{
    appm_scene *s;
    appm_diag d;
    uint32_t i, smooth = 0;
    CHECK(load(FIX "face-forms.obj", &s, &d, NULL) == APPM_OK);
    if (!s) return;
    CHECK(s->ntri == 6);
    /* v//vn, v/vt/vn and the mixed v/vt/vn + v//vn faces carry normals; a face
     * where one corner has none (the last) gets the geometric normal. */
    for (i = 0; i < s->ntri; ++i) smooth += s->info[i].n0 >= 0;
    CHECK(smooth == 3);
    CHECK(s->nnormals == 9);
    appm_scene_destroy(s);
    /* texture and normal indices are range-checked too */
    CHECK_ERR(load_mem("v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nf 1/1 2/2 3/1\n", NULL, &s, &d, NULL), d,
              APPM_ERR_PARSE, 5, "mem.obj");
    CHECK_ERR(load_mem("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1//1 2//1 3//1\n", NULL, &s, &d, NULL), d,
              APPM_ERR_PARSE, 4, "mem.obj");
    CHECK_ERR(load_mem("v 0 0 0\nv 1 0 0\nv 0 1 0\n\nf 1/x 2 3\n", NULL, &s, &d, NULL), d, APPM_ERR_PARSE,
              5, "mem.obj");
    CHECK_ERR(load_mem("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3a\n", NULL, &s, &d, NULL), d, APPM_ERR_PARSE, 4,
              "mem.obj");
}

/* Malformed OBJ files: each names the file and the line. */
static void test_obj_errors(void)
{
    static const struct {
        const char *file;
        unsigned line;
        const char *word; /* expected in the message */
    } cases[] = {
        {"index-out-of-range.obj", 7, "4"},
        {"zero-index.obj", 7, "0"},
        {"nan-vertex.obj", 5, "NaN"},
        {"inf-vertex.obj", 6, "inf"},
        {"huge-exponent.obj", 5, "inf"},
    };
    size_t k;
    for (k = 0; k < sizeof cases / sizeof cases[0]; ++k) {
        char path[256];
        appm_scene *s;
        appm_diag d;
        appm_status st;
        snprintf(path, sizeof path, FIX "%s", cases[k].file);
        st = load(path, &s, &d, NULL);
        CHECK_ERR(st, d, APPM_ERR_PARSE, cases[k].line, cases[k].file);
        CHECK_MSG(strstr(d.message, cases[k].word) != NULL, "%s: message '%s'", cases[k].file, d.message);
        CHECK(s == NULL);
    }
    /* The same classes in memory, with variants. */
    {
        static const struct {
            const char *obj;
            unsigned line;
        } mem[] = {
            {"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 55555555555555555555555555\n", 4}, /* beyond int64 */
            {"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 -9223372036854775808\n", 4},
            {"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\nf 2 3 4\nv 1 1 0\n", 5}, /* 4 comes later */
            {"v 0 0 0\nv -nan 0 0\nv 0 1 0\nf 1 2 3\n", 2},
            {"v 0 0 0\nv 0 0 INFINITY\nv 0 1 0\nf 1 2 3\n", 2},
            {"v 0 0 0\nv 1e39 0 0\nv 0 1 0\nf 1 2 3\n", 2},  /* beyond float */
            {"v 0 0 0\nv 1e19 0 0\nv 0 1 0\nf 1 2 3\n", 2},  /* squares overflow float */
            {"v 0 0 0\nv 0.0 1,0 0\nv 0 1 0\nf 1 2 3\n", 2}, /* decimal comma */
            {"v 0 0 0\nv 1 0\nv 0 1 0\nf 1 2 3\n", 2},       /* too few numbers */
            {"v 0 0 0\nv 1.#IND 0 0\nv 0 1 0\nf 1 2 3\n", 2},
            {"v 0 0 0\nvn 0 0 0\n", 2},                      /* a zero normal cannot be normalised */
            {"v 0 0 0\n\n\n#\n@@@ 1 2 3\n", 5},              /* not an OBJ statement */
        };
        for (k = 0; k < sizeof mem / sizeof mem[0]; ++k) {
            appm_scene *s;
            appm_diag d;
            appm_status st = load_mem(mem[k].obj, LIGHT_MTL, &s, &d, NULL);
            CHECK_MSG(st == APPM_ERR_PARSE && d.line == mem[k].line,
                      "case %d: status %d line %u (%s), expected line %u", (int)k, (int)st, d.line,
                      d.message, mem[k].line);
            CHECK(strcmp(d.file, "mem.obj") == 0);
        }
    }
}

static void test_garbage(void)
{
    appm_scene *s;
    appm_diag d;
    unsigned char bytes[4096];
    char *text;
    size_t n = 0, i;
    FILE *f;
    appm_status st;
    /* as a .scene (by its extension) */
    CHECK_ERR(load(FIX "garbage.bin", &s, &d, NULL), d, APPM_ERR_PARSE, 0, "garbage.bin");
    /* as an OBJ file and as OBJ text */
    f = fopen(FIX "garbage.bin", "rb");
    CHECK(f != NULL);
    if (!f) return;
    n = fread(bytes, 1, sizeof bytes, f);
    fclose(f);
    CHECK(n == 512);
    {
        const char *path = check_path("loader", "garbage.obj");
        FILE *g = fopen(path, "wb");
        CHECK(g && fwrite(bytes, 1, n, g) == n);
        if (g) fclose(g);
        st = load(path, &s, &d, NULL);
        CHECK(st == APPM_ERR_PARSE && s == NULL);
        CHECK(strstr(d.file, "garbage.obj") != NULL);
    }
    st = load_mem_n((const char *)bytes, n, NULL, 0, &s, &d, NULL);
    CHECK(st == APPM_ERR_PARSE && s == NULL);
    /* without NUL bytes the text parser itself must reject it */
    text = (char *)malloc(n);
    for (i = 0; i < n; ++i) text[i] = (char)(bytes[i] ? bytes[i] : 'x');
    st = load_mem_n(text, n, NULL, 0, &s, &d, NULL);
    CHECK(st == APPM_ERR_PARSE && s == NULL);
    CHECK(d.line >= 1);
    /* garbage as MTL text: warnings or an error, never a crash or a read
     * outside the buffer */
    st = load_mem_n(TRI_LIGHT, strlen(TRI_LIGHT), text, n, &s, &d, NULL);
    CHECK(st == APPM_OK || st == APPM_ERR_PARSE);
    appm_scene_destroy(s);
    st = load_mem_n(TRI_LIGHT, strlen(TRI_LIGHT), (const char *)bytes, n, &s, &d, NULL);
    CHECK(st == APPM_OK || st == APPM_ERR_PARSE);
    appm_scene_destroy(s);
    free(text);
}

static void test_empty(void)
{
    appm_scene *s;
    appm_diag d;
    const char *comments = check_path("loader", "comments-only.scene");
    CHECK_ERR(load(FIX "empty.obj", &s, &d, NULL), d, APPM_ERR_PARSE, 0, "empty.obj");
    CHECK(s == NULL);
    CHECK_ERR(load(FIX "empty.scene", &s, &d, NULL), d, APPM_ERR_PARSE, 0, "empty.scene");
    CHECK(s == NULL);
    CHECK(check_write_file(comments, "# nothing but a comment\n\n   \t\n"));
    CHECK_ERR(load(comments, &s, &d, NULL), d, APPM_ERR_PARSE, 0, "comments-only.scene");
    CHECK_ERR(load_mem_n("", 0, NULL, 0, &s, &d, NULL), d, APPM_ERR_PARSE, 0, "mem.obj");
    /* a file that does not exist at all */
    CHECK_ERR(load(FIX "no-such-file.obj", &s, &d, NULL), d, APPM_ERR_IO, 0, "no-such-file.obj");
    CHECK_ERR(load(FIX "no-such-file.scene", &s, &d, NULL), d, APPM_ERR_IO, 0, "no-such-file.scene");
}

/* Writes a .scene into tests/out/ (its mesh paths are relative to that folder). */
static appm_status load_scene_text(const char *text, appm_scene **s, appm_diag *d)
{
    const char *path = check_path("loader", "stmt.scene");
    if (!check_write_file(path, text)) return APPM_ERR_IO;
    return load(path, s, d, NULL);
}

static void test_scene_file_errors(void)
{
    appm_scene *s;
    appm_diag d;
    /* on failure the output pointer is cleared, not left dangling */
    s = (appm_scene *)&d;
    CHECK(appm_scene_load(FIX "no-such-file.obj", NULL, &s, NULL) == APPM_ERR_IO);
    CHECK(s == NULL);
    CHECK_ERR(load(FIX "unknown-keyword.scene", &s, &d, NULL), d, APPM_ERR_PARSE, 3, "unknown-keyword.scene");
    CHECK(strstr(d.message, "sphere") != NULL);
    CHECK_ERR(load(FIX "missing-mesh.scene", &s, &d, NULL), d, APPM_ERR_IO, 3, "missing-mesh.scene");
    CHECK(strstr(d.message, "no-such-mesh.obj") != NULL);
    /* a bare OBJ without light gets the white environment; a .scene without
     * light is still an error */
    CHECK(load(FIX "no-light.obj", &s, &d, NULL) == APPM_OK);
    appm_scene_destroy(s);
    CHECK(load_scene_text("mesh ../fixtures/no-light.obj\n", &s, &d) == APPM_ERR_PARSE);
    CHECK(strstr(d.message, "no light") != NULL);
    CHECK(s == NULL);
    /* an error inside a mesh of a scene names the OBJ and its line, not the scene */
    CHECK(load_scene_text("camera eye 0 0 5 target 0 0 0\nmesh ../fixtures/nan-vertex.obj\n", &s, &d) ==
          APPM_ERR_PARSE);
    CHECK(d.line == 5 && strstr(d.file, "nan-vertex.obj") != NULL);
    /* CRLF line ends in a .scene */
    CHECK(load_scene_text("# crlf\r\nmesh ../fixtures/crlf.obj\r\nimage 64 48\r\n", &s, &d) == APPM_OK);
    if (s) CHECK(s->width == 64 && s->height == 48);
    appm_scene_destroy(s);
    CHECK(load_scene_text("# crlf\r\nmesh ../fixtures/crlf.obj\r\nimage 64 48\r\nbogus\r\n", &s, &d) ==
          APPM_ERR_PARSE);
    CHECK(d.line == 4);
}

static void test_degenerate_duplicate(void)
{
    appm_scene *s;
    appm_diag d;
    logbuf lb;
    appm_scene_info in;
    CHECK(load(FIX "degenerate.obj", &s, &d, &lb) == APPM_OK);
    if (s) {
        uint32_t i;
        appm_scene_get_info(s, &in);
        CHECK(in.triangles == 3);
        CHECK(in.dropped_triangles == 3);
        CHECK(in.lights_area == 3); /* no zero-area emitter reached the light table */
        for (i = 0; i < s->ntri; ++i) CHECK(s->info[i].area > 0.0f);
        /* one warning for the kind, at the first offender */
        CHECK(log_count(&lb, "degenerate") == 1);
        if (log_find(&lb, "degenerate") >= 0) CHECK(lb.line[log_find(&lb, "degenerate")] == 11);
    }
    appm_scene_destroy(s);
    CHECK(load(FIX "duplicate.obj", &s, &d, NULL) == APPM_OK);
    if (s) {
        uint32_t i, up = 0, down = 0;
        appm_scene_get_info(s, &in);
        CHECK(in.triangles == 3 && in.dropped_triangles == 0);
        for (i = 0; i < s->ntri; ++i) {
            up += s->info[i].ng.z > 0.99f;
            down += s->info[i].ng.z < -0.99f;
        }
        CHECK(up == 2 && down == 1); /* counter-clockwise winding decides the side */
    }
    appm_scene_destroy(s);
    /* an OBJ of nothing but degenerate triangles has no triangles left */
    CHECK(load_mem("mtllib m\nusemtl light\nv 0 0 0\nv 1 0 0\nv 2 0 0\nf 1 2 3\nf 1 1 1\n", LIGHT_MTL, &s, &d,
                   NULL) == APPM_ERR_PARSE);
}

static void test_short_face(void)
{
    appm_scene *s;
    appm_diag d;
    logbuf lb;
    CHECK(load(FIX "short-face.obj", &s, &d, &lb) == APPM_OK);
    if (s) CHECK(s->ntri == 2);
    CHECK(log_count(&lb, "fewer than 3") == 1);
    if (log_find(&lb, "fewer than 3") >= 0) CHECK(lb.line[log_find(&lb, "fewer than 3")] == 8);
    appm_scene_destroy(s);
    /* `f` alone and `f 1` are short too */
    CHECK(load_mem("mtllib m\nusemtl light\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf\nf 1\nf 1 2 3\n", LIGHT_MTL, &s, &d,
                   &lb) == APPM_OK);
    if (s) CHECK(s->ntri == 1);
    CHECK(log_count(&lb, "fewer than 3") == 1);
    appm_scene_destroy(s);
}

static void test_long_line(void)
{
    appm_scene *s;
    appm_diag d;
    appm_status st = load(FIX "long-line.obj", &s, &d, NULL);
    CHECK_MSG(st == APPM_OK, "%s:%u: %s", d.file, d.line, d.message);
    if (s) {
        appm_scene_info in;
        appm_scene_get_info(s, &in);
        CHECK(in.triangles == 1);
        CHECK(in.bbox_max[0] == 1.0); /* 1 followed by 102400 zeros, times 1e-102400 */
    }
    appm_scene_destroy(s);
}

static void test_no_trailing_newline(void)
{
    appm_scene *s;
    appm_diag d;
    appm_scene_info in;
    static const char obj[] = "mtllib m\nusemtl light\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3";
    static const char mtl[] = "newmtl light\nKe 1 1 1\nKe 9 9 9";
    CHECK(load(FIX "no-trailing-newline.obj", &s, &d, NULL) == APPM_OK);
    if (s) {
        appm_scene_get_info(s, &in);
        CHECK(in.triangles == 2); /* the last face, with no newline, counts */
        /* the last MTL line, with no newline, set Ke = (2, 3, 4) on area 1 */
        CHECK_NEAR(in.power_area[0], APPM__PI * 2.0, 1e-5);
        CHECK_NEAR(in.power_area[1], APPM__PI * 3.0, 1e-5);
        CHECK_NEAR(in.power_area[2], APPM__PI * 4.0, 1e-5);
    }
    appm_scene_destroy(s);
    /* Buffers are bounded by their lengths, not by a NUL: cut the MTL before
     * its last statement and the first Ke stays. */
    CHECK(load_mem_n(obj, sizeof obj - 1, mtl, sizeof mtl - 1 - 9, &s, &d, NULL) == APPM_OK);
    if (s) {
        appm_scene_get_info(s, &in);
        CHECK(in.triangles == 1);
        CHECK_NEAR(in.power_area[0], APPM__PI * 0.5 * 1.0, 1e-5);
    }
    appm_scene_destroy(s);
    /* and an OBJ cut in the middle of its last face has no face there */
    CHECK(load_mem_n(obj, sizeof obj - 1 - 2, mtl, sizeof mtl - 1, &s, &d, NULL) != APPM_OK);
}

/* ---- MTL ------------------------------------------------------------------------ */

static void test_mtl_before_newmtl(void)
{
    appm_scene *s;
    appm_diag d;
    logbuf lb;
    int w;
    CHECK(load(FIX "mtl-before-newmtl.obj", &s, &d, &lb) == APPM_OK);
    w = log_find(&lb, "newmtl");
    CHECK_MSG(w >= 0, "no warning about statements before newmtl");
    if (w >= 0) {
        CHECK(lb.line[w] == 1);
        CHECK(strstr(lb.file[w], "mtl-before-newmtl.mtl") != NULL);
    }
    CHECK(log_count(&lb, "newmtl") == 1); /* two such lines, one warning */
    if (s) {
        const appm__material *m = &s->mat[s->info[0].mat];
        CHECK(s->nmat == 2);
        CHECK(m->emissive);
        CHECK_NEAR(m->ke.x, 1.0, 0); /* not the 5 of the orphan line */
        CHECK_NEAR(m->color.x, 0.8, 1e-6);
        CHECK_NEAR(m->color.y, 0.8, 1e-6); /* the orphan Kd 1 0 0 did not leak in */
    }
    appm_scene_destroy(s);
}

static void test_mtl_mapping(void)
{
    /* Materials m0..m10 with illum 0..10, all with Kd, Ks and Ni, then the
     * defaults when the parameters are absent, then Ke on each kind. */
    char mtl[4096];
    size_t n = 0;
    int k;
    appm_scene *s;
    appm_diag d;
    logbuf lb;
    for (k = 0; k <= 10; ++k)
        n += (size_t)sprintf(mtl + n, "newmtl m%d\nKd 0.1 0.2 0.3\nKs 0.4 0.5 0.6\nNi 1.33\nillum %d\n\n", k, k);
    n += (size_t)sprintf(mtl + n, "newmtl glass_default\nillum 7\n"     /* mat 12 */
                                  "newmtl mirror_default\nillum 3\n"    /* mat 13 */
                                  "newmtl diffuse_default\n"            /* mat 14 */
                                  "newmtl emissive_mirror\nillum 5\nKe 1 2 3\n" /* mat 15 */
                                  "newmtl emissive_glass\nKe 0 0 0.5\nillum 4\n" /* mat 16 */
                                  "newmtl zero_ke\nKe 0 0 0\n"          /* mat 17 */
                                  "newmtl light\nKe 4 4 4\nKd 0.2 0.2 0.2\n"); /* mat 18 */
    CHECK(load_mem(TRI_LIGHT, mtl, &s, &d, &lb) == APPM_OK);
    if (!s) return;
    CHECK(s->nmat == 19);
    if (s->nmat == 19) {
        for (k = 0; k <= 10; ++k) {
            const appm__material *m = &s->mat[1 + k];
            if (k == 4 || k == 6 || k == 7 || k == 9) {
                CHECK_MSG(m->kind == APPM__MAT_DIELECTRIC, "illum %d: kind %d", k, m->kind);
                CHECK_NEAR(m->ior, 1.33, 1e-6);
                CHECK(same_v3(m->color, appm__v(1, 1, 1))); /* clear: Kd and Ks ignored */
            } else if (k == 3 || k == 5) {
                CHECK_MSG(m->kind == APPM__MAT_MIRROR, "illum %d: kind %d", k, m->kind);
                CHECK(same_v3(m->color, appm__v(0.4f, 0.5f, 0.6f))); /* Ks */
            } else { /* Ks 0.4 0.5 0.6 > 0 on the others: glossy, Ns 1 by default */
                CHECK_MSG(m->kind == APPM__MAT_GLOSSY, "illum %d: kind %d", k, m->kind);
                CHECK(same_v3(m->color, appm__v(0.1f, 0.2f, 0.3f))); /* Kd */
                CHECK(same_v3(m->ks, appm__v(0.4f, 0.5f, 0.6f)));
                CHECK(m->ns == 1.0f);
            }
            CHECK(!m->emissive);
        }
        CHECK(s->mat[12].kind == APPM__MAT_DIELECTRIC);
        CHECK_NEAR(s->mat[12].ior, 1.5, 0);
        CHECK(s->mat[13].kind == APPM__MAT_MIRROR && same_v3(s->mat[13].color, appm__v(1, 1, 1)));
        CHECK(s->mat[14].kind == APPM__MAT_DIFFUSE && same_v3(s->mat[14].color, appm__v(0.8f, 0.8f, 0.8f)));
        CHECK(s->mat[15].kind == APPM__MAT_MIRROR && s->mat[15].emissive);
        CHECK(same_v3(s->mat[15].ke, appm__v(1, 2, 3)));
        CHECK(s->mat[16].kind == APPM__MAT_DIELECTRIC && s->mat[16].emissive);
        CHECK(!s->mat[17].emissive);
        CHECK(s->mat[18].kind == APPM__MAT_DIFFUSE && s->mat[18].emissive);
        CHECK(same_v3(s->mat[18].color, appm__v(0.2f, 0.2f, 0.2f)));
        CHECK(s->info[0].mat == 18); /* usemtl found the right one */
    }
    {
        appm_scene_info in;
        appm_scene_get_info(s, &in);
        /* dielectric: illum 4 6 7 9, glass_default, emissive_glass; mirror: illum
         * 3 5, mirror_default, emissive_mirror; glossy: illum 0 1 2 8 10; the
         * other 3 are diffuse */
        CHECK(in.materials_dielectric == 6 && in.materials_mirror == 4 && in.materials_diffuse == 3);
        CHECK(in.materials_glossy == 5);
        CHECK(in.materials_emissive == 3);
        CHECK(in.lights_area == 1); /* only used emissive materials make lights */
    }
    CHECK(log_count(&lb, "Kd + Ks") == 0); /* 0.1 + 0.4 .. 0.3 + 0.6: all below 1 */
    CHECK(!log_has_repeats(&lb));
    appm_scene_destroy(s);
}

/* Glossy materials: Ns at its limits, Kd + Ks scaling, defaults, warnings. */
static void test_mtl_glossy(void)
{
    appm_scene *s;
    appm_diag d;
    logbuf lb;
    /* Glossy: Ns at the limits, Kd + Ks > 1 scaled per channel keeping the
     * ratio (one warning for the file), Ns reset to 1 at each newmtl, and Ns
     * without Ks > 0 a warning (the material stays diffuse). */
    CHECK(load_mem(TRI_LIGHT,
                   "newmtl light\nKe 1 1 1\nKd 0.5 0.5 0.5\nKs 0.25 0.75 1.5\nNs 100000\n"
                   "newmtl g2\nKd 0.9 0.1 0\nKs 0.3 0.3 0.3\nNs 0.001\n"
                   "newmtl g3\nKs 0.1 0 0\n"
                   "newmtl d\nKs 0 0 0\nNs 50\n",
                   &s, &d, &lb) == APPM_OK);
    if (s) {
        const appm__material *m = &s->mat[1];
        CHECK(m->kind == APPM__MAT_GLOSSY && m->ns == 1e5f);
        CHECK_NEAR(m->color.x, 0.5, 1e-7);          /* 0.75: unchanged */
        CHECK_NEAR(m->ks.x, 0.25, 1e-7);
        CHECK_NEAR(m->color.y, 0.5 / 1.25, 1e-7);   /* 1.25: scaled */
        CHECK_NEAR(m->ks.y, 0.75 / 1.25, 1e-7);
        CHECK_NEAR(m->color.z, 0.5 / 1.5, 1e-7);    /* Ks 1.5 clamped to 1 first */
        CHECK_NEAR(m->ks.z, 1.0 / 1.5, 1e-7);
        m = &s->mat[2];
        CHECK(m->kind == APPM__MAT_GLOSSY && m->ns == 0.001f);
        CHECK_NEAR(m->color.x, 0.9 / 1.2, 1e-7);
        CHECK_NEAR(m->ks.x, 0.3 / 1.2, 1e-7);
        CHECK_NEAR(m->color.y, 0.1, 1e-7);
        m = &s->mat[3];
        CHECK(m->kind == APPM__MAT_GLOSSY && m->ns == 1.0f);
        CHECK(same_v3(m->color, appm__v(0.8f, 0.8f, 0.8f)) && same_v3(m->ks, appm__v(0.1f, 0, 0)));
        CHECK(s->mat[4].kind == APPM__MAT_DIFFUSE);
    }
    CHECK(log_count(&lb, "Kd + Ks") == 1);
    CHECK(log_count(&lb, "'Ns'") == 1);
    if (log_find(&lb, "'Ns'") >= 0) CHECK(strstr(lb.msg[log_find(&lb, "'Ns'")], "Ks > 0") != NULL);
    CHECK(log_count(&lb, "clamped") == 1);
    CHECK(!log_has_repeats(&lb));
    appm_scene_destroy(s);
}

static void test_mtl_values(void)
{
    appm_scene *s;
    appm_diag d;
    logbuf lb;
    /* Kd above 1 (energy gain) and below 0 are clamped, with one warning */
    CHECK(load_mem(TRI_LIGHT, "newmtl light\nKd 2 0.5 -1\nKe 1 1 1\nnewmtl b\nKd 3 3 3\n", &s, &d, &lb) == APPM_OK);
    if (s) {
        CHECK(same_v3(s->mat[1].color, appm__v(1.0f, 0.5f, 0.0f)));
        CHECK(same_v3(s->mat[2].color, appm__v(1, 1, 1)));
    }
    CHECK(log_count(&lb, "clamped") == 1);
    appm_scene_destroy(s);
    /* mirror reflectance Ks is clamped the same way */
    CHECK(load_mem(TRI_LIGHT, "newmtl light\nKe 1 1 1\nnewmtl mir\nillum 3\nKs 1.5 0.5 0.5\n", &s, &d, &lb) ==
          APPM_OK);
    if (s) CHECK(same_v3(s->mat[2].color, appm__v(1.0f, 0.5f, 0.5f)));
    appm_scene_destroy(s);
    /* Ni 0 or negative is an error naming the MTL line; so are bad numbers */
    {
        static const struct {
            const char *mtl;
            unsigned line;
        } bad[] = {
            {"newmtl light\nKe 1 1 1\nNi 0\n", 3},
            {"newmtl light\nKe 1 1 1\nillum 7\nNi -1.5\n", 4},
            {"newmtl light\nKe 1 1 1\nNi nan\n", 3},
            {"newmtl light\nKd 0.5 0.5\nKe 1 1 1\n", 2},
            {"newmtl light\nKd 0.5 0.5 nan\n", 2},
            {"newmtl light\nKe 1 1 1e39\n", 2},
            {"newmtl light\nKe -1 1 1\n", 2},
            {"newmtl light\nillum 4.5\n", 2},
            /* the Phong exponent: (0, 1e5] (interface.md section 2) */
            {"newmtl light\nKe 1 1 1\nKs 0.5 0.5 0.5\nNs 0\n", 4},
            {"newmtl light\nKe 1 1 1\nNs -3\n", 3},
            {"newmtl light\nKe 1 1 1\nNs nan\n", 3},
            {"newmtl light\nKe 1 1 1\nNs 100001\n", 3},
            {"newmtl light\nKe 1 1 1\nNs 1e6\nKs 0.2 0.2 0.2\n", 3},
            {"newmtl light\nKe 1 1 1\nNs\n", 3},
            {"newmtl light\nillum -1\n", 2},
            {"newmtl\n", 1},
        };
        size_t k;
        for (k = 0; k < sizeof bad / sizeof bad[0]; ++k) {
            appm_status st = load_mem(TRI_LIGHT, bad[k].mtl, &s, &d, NULL);
            CHECK_MSG(st == APPM_ERR_PARSE && d.line == bad[k].line && strcmp(d.file, "(mtl)") == 0,
                      "MTL case %d: status %d, %s:%u: %s", (int)k, (int)st, d.file, d.line, d.message);
            CHECK(s == NULL);
        }
    }
    /* In a file, the error names the .mtl file itself. */
    {
        const char *mtlp = check_path("loader", "bad-ni.mtl");
        const char *objp = check_path("loader", "bad-ni.obj");
        char objpath[256];
        snprintf(objpath, sizeof objpath, "%s", objp);
        CHECK(check_write_file(mtlp, "newmtl light\nKe 1 1 1\nNi -2\n"));
        CHECK(check_write_file(objpath, "mtllib loader-bad-ni.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nusemtl light\nf 1 2 3\n"));
        CHECK_ERR(load(objpath, &s, &d, NULL), d, APPM_ERR_PARSE, 3, "loader-bad-ni.mtl");
    }
    /* Material state is reset at each newmtl (tinyobjloader #391). */
    CHECK(load_mem(TRI_LIGHT, "newmtl a\nillum 5\nKs 0.3 0.3 0.3\nKd 0.1 0.1 0.1\nNi 2\nKe 1 1 1\n"
                              "newmtl light\nKe 1 0 0\nnewmtl c\nillum 7\n",
                   &s, &d, NULL) == APPM_OK);
    if (s) {
        CHECK(s->mat[2].kind == APPM__MAT_DIFFUSE);
        CHECK(same_v3(s->mat[2].color, appm__v(0.8f, 0.8f, 0.8f)));
        CHECK(same_v3(s->mat[2].ke, appm__v(1, 0, 0)));
        CHECK_NEAR(s->mat[3].ior, 1.5, 0);
        CHECK(!s->mat[3].emissive);
    }
    appm_scene_destroy(s);
    /* An unknown usemtl name: a warning and the default material. */
    CHECK(load_mem("mtllib m\nv 0 0 0\nv 1 0 0\nv 0 1 0\nusemtl light\nf 1 2 3\nusemtl nope\nf 3 2 1\n",
                   LIGHT_MTL, &s, &d, &lb) == APPM_OK);
    if (s) {
        uint32_t i, def = 0;
        for (i = 0; i < s->ntri; ++i) def += s->info[i].mat == 0;
        CHECK(def == 1);
    }
    CHECK(log_count(&lb, "nope") == 1);
    if (log_find(&lb, "nope") >= 0) CHECK(lb.line[log_find(&lb, "nope")] == 7);
    appm_scene_destroy(s);
    /* Ignored statements: one warning per kind, e.g. many Ka, Ns and map_Ka */
    CHECK(load_mem(TRI_LIGHT,
                   "newmtl light\nKa 1 1 1\nNs 10\nmap_Ka a.png\nKe 1 1 1\n"
                   "newmtl b\nKa 0 0 0\nNs 20\nmap_Ka -o 0 -7 0 -s 1 10 1 -clamp on tex.png\nmap_Bump x\n",
                   &s, &d, &lb) == APPM_OK);
    CHECK(log_count(&lb, "'Ka'") == 1);
    CHECK(log_count(&lb, "'Ns'") == 1);
    CHECK(log_count(&lb, "map_") == 1);
    CHECK(!log_has_repeats(&lb));
    appm_scene_destroy(s);
}

/* OBJ statements that are understood but not modelled (l, p, curves, ...):
 * one warning per statement kind and file (docs/scene-format.md section 2). */
static void test_obj_ignored_warnings(void)
{
    appm_scene *s;
    appm_diag d;
    logbuf lb;
    CHECK(load_mem("mtllib m\nusemtl light\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n"
                   "l 1 2\nl 2 3\nshadow_obj s.obj\np 1\nvp 0.5\nmaplib x\no a\ng b\ns 1\n",
                   LIGHT_MTL, &s, &d, &lb) == APPM_OK);
    CHECK(log_count(&lb, "'l'") == 1);
    CHECK_MSG(log_count(&lb, "'shadow_obj'") == 1, "'shadow_obj' was not reported (its warning kind is shared)");
    CHECK(log_count(&lb, "'p'") == 1);
    CHECK(log_count(&lb, "'vp'") == 1);
    CHECK_MSG(log_count(&lb, "'maplib'") == 1, "'maplib' was not reported (its warning kind is shared)");
    CHECK(log_count(&lb, "'o'") == 0 && log_count(&lb, "'g'") == 0 && log_count(&lb, "'s'") == 0);
    appm_scene_destroy(s);
}

/* ---- .scene statements --------------------------------------------------------- */

static void test_scene_statements(void)
{
    appm_scene *s;
    appm_diag d;
    appm_status st;
    appm_scene_info in;
    st = load_scene_text("# every statement of the format\n"
                         "mesh ../fixtures/no-light.obj\n"
                         "camera eye 1 2 3  target 1 2 0  up 1 1 0  fov 30\n"
                         "lens aperture 0.05 focus 3.9\n"
                         "image 64 48\n"
                         "light point position 0 1.5 0 intensity 1 2 0.5\n"
                         "light\tspot position 0 5 9 target -5 2.75 0 intensity 3 2 1 cone 30 falloff 5\n"
                         "environment 0.1 0.2 0.3\n",
                         &s, &d);
    CHECK_MSG(st == APPM_OK, "%s:%u: %s", d.file, d.line, d.message);
    if (!s) return;
    appm_scene_get_info(s, &in);
    /* camera: forward = (0,0,-1); right = forward x up = (1,-1,0)/sqrt2;
     * true up = right x forward = (1,1,0)/sqrt2 */
    CHECK(same_v3(s->cam.eye, appm__v(1, 2, 3)));
    CHECK_NEAR(s->cam.forward.z, -1.0, 1e-6);
    CHECK_NEAR(s->cam.right.x, sqrt(0.5), 1e-6);
    CHECK_NEAR(s->cam.right.y, -sqrt(0.5), 1e-6);
    CHECK_NEAR(s->cam.right.z, 0.0, 1e-6);
    CHECK_NEAR(s->cam.up.x, sqrt(0.5), 1e-6);
    CHECK_NEAR(s->cam.up.y, sqrt(0.5), 1e-6);
    CHECK_NEAR(s->cam.fov, 30.0, 1e-6);
    CHECK_NEAR(s->cam.tan_half, tan(15.0 * APPM__PI / 180.0), 1e-6);
    CHECK_NEAR(s->cam.aperture, 0.05, 1e-7);
    CHECK_NEAR(s->cam.focus, 3.9, 1e-6);
    CHECK(in.width == 64 && in.height == 48);
    CHECK(in.lights_point == 1 && in.lights_spot == 1 && in.lights_environment == 1 && in.lights_area == 0);
    /* point: Phi = 4 pi I */
    CHECK_NEAR(in.power_point[0], 4 * APPM__PI * 1.0, 1e-5);
    CHECK_NEAR(in.power_point[1], 4 * APPM__PI * 2.0, 1e-5);
    CHECK_NEAR(in.power_point[2], 4 * APPM__PI * 0.5, 1e-5);
    {
        /* spot: I inside cone - falloff, the d^4 ramp to 0 at the cone:
         * Phi = 2 pi I [(1 - cos 25deg) + (cos 25deg - cos 30deg) / 5] */
        double ci = cos(25.0 * APPM__PI / 180.0), cc = cos(30.0 * APPM__PI / 180.0);
        double f = 2 * APPM__PI * ((1 - ci) + (ci - cc) / 5);
        uint32_t k;
        CHECK_NEAR(in.power_spot[0], 3 * f, 3e-5 * f);
        CHECK_NEAR(in.power_spot[1], 2 * f, 2e-5 * f);
        CHECK_NEAR(in.power_spot[2], 1 * f, 1e-5 * f);
        for (k = 0; k < s->nlight; ++k) {
            const appm__light *l = &s->light[k];
            if (l->kind == APPM__LIGHT_SPOT) {
                /* axis = normalize(target - position) = (-5, -2.25, -9) / |.| */
                double len = sqrt(25 + 2.25 * 2.25 + 81);
                CHECK_NEAR(l->axis.x, -5 / len, 1e-6);
                CHECK_NEAR(l->axis.y, -2.25 / len, 1e-6);
                CHECK_NEAR(l->axis.z, -9 / len, 1e-6);
                CHECK_NEAR(l->cos_cone, cc, 1e-6);
                CHECK_NEAR(l->cos_inner, ci, 1e-6);
            }
            if (l->kind == APPM__LIGHT_ENV) CHECK(same_v3(l->value, appm__v(0.1f, 0.2f, 0.3f)));
            if (l->kind == APPM__LIGHT_POINT) CHECK(same_v3(l->pos, appm__v(0, 1.5f, 0)));
        }
    }
    appm_scene_destroy(s);
    /* keys in any order, fov and up optional (40 degrees, +y) */
    st = load_scene_text("mesh ../fixtures/crlf.obj\ncamera target 0 0 0 eye 0 0 2\n", &s, &d);
    CHECK(st == APPM_OK);
    if (s) {
        CHECK_NEAR(s->cam.fov, 40.0, 1e-6);
        CHECK_NEAR(s->cam.up.y, 1.0, 1e-6);
        CHECK(s->cam.aperture == 0.0f); /* no lens: a pinhole */
    }
    appm_scene_destroy(s);
    /* a spot without falloff has a hard edge: Phi = 2 pi I (1 - cos cone) */
    st = load_scene_text("mesh ../fixtures/no-light.obj\nlight spot position 0 0 1 target 0 0 0 intensity 1 1 1 cone 60\n",
                         &s, &d);
    CHECK(st == APPM_OK);
    if (s) {
        appm_scene_get_info(s, &in);
        CHECK_NEAR(in.power_spot[1], 2 * APPM__PI * (1 - 0.5), 1e-5);
    }
    appm_scene_destroy(s);
}

static void test_scene_malformed(void)
{
    /* Each statement on line 3, after a comment and a valid mesh. */
    static const char *const bad[] = {
        "camera eye 0 0 x target 0 0 0",
        "camera eye 0 0 5 target 0 0 0 fov 4O",
        "camera eye 0 0 5 target 0 0 0 up 0 1,0 0",
        "camera eye 0 0 5 target 0 0",
        "camera eye 0 0 5",
        "camera eye 0 0 5 target 0 0 5",
        "camera eye 0 0 5 target 0 0 0 fov 180",
        "camera eye 0 0 5 target 0 0 0 up 0 0 1",
        "camera eye 0 0 5 target 0 0 0 zoom 2",
        "lens aperture 0,05 focus 3.9",
        "lens aperture 0.05 focus 3.9e",
        "lens aperture 0.05",
        "lens aperture -1 focus 1",
        "image 512 51x",
        "image 512",
        "image 0 512",
        "image 51.5 512",
        "image 40000 512",
        "light point position 0 1..5 0 intensity 1 1 1",
        "light point position 0 1 0 intensity 1 1 nan",
        "light point position 0 1 0",
        "light point position 0 1 0 intensity -1 1 1",
        "light spot position 0 5 0 target 0 0 0 intensity 1 1 1 cone 3O",
        "light spot position 0 5 0 target 0 0 0 intensity 1 1 1 falloff --1",
        "light spot position 0 5 0 target 0 5 0 intensity 1 1 1",
        "light spot position 0 5 0 target 0 0 0 intensity 1 1 1 cone 30 falloff 40",
        "light area position 0 0 0 intensity 1 1 1",
        "light",
        "environment 0.1 0.1 inf",
        "environment 0.1 0.1",
        "environment 0.1 0.1 0x1",
        "environment -1 0 0",
        "mesh",
        "Mesh ../fixtures/crlf.obj",
    };
    size_t k;
    for (k = 0; k < sizeof bad / sizeof bad[0]; ++k) {
        char text[512];
        appm_scene *s;
        appm_diag d;
        appm_status st;
        snprintf(text, sizeof text, "# malformed statement below\nmesh ../fixtures/crlf.obj\n%s\n", bad[k]);
        st = load_scene_text(text, &s, &d);
        CHECK_MSG(st == APPM_ERR_PARSE && d.line == 3 && strstr(d.file, "loader-stmt.scene"),
                  "'%s': status %d, %s:%u: %s", bad[k], (int)st, d.file, d.line, d.message);
        CHECK(s == NULL);
    }
    /* Two environments are one too many: the second one's line is named. */
    {
        appm_scene *s;
        appm_diag d;
        appm_status st = load_scene_text("mesh ../fixtures/crlf.obj\nenvironment 1 1 1\nenvironment 2 2 2\n", &s, &d);
        CHECK_MSG(st == APPM_ERR_PARSE && d.line == 3, "status %d line %u: %s", (int)st, d.line, d.message);
    }
}

/* Numbers after a complete statement are not silently skipped either
 * ("no silent skipping", docs/scene-format.md section 1). */
static void test_scene_trailing_tokens(void)
{
    static const char *const bad[] = {"image 64 48 junk", "environment 1 1 1 7"};
    size_t k;
    for (k = 0; k < sizeof bad / sizeof bad[0]; ++k) {
        char text[256];
        appm_scene *s;
        appm_diag d;
        appm_status st;
        snprintf(text, sizeof text, "# trailing tokens below\nmesh ../fixtures/crlf.obj\n%s\n", bad[k]);
        st = load_scene_text(text, &s, &d);
        CHECK_MSG(st == APPM_ERR_PARSE && d.line == 3, "'%s' was accepted (status %d)", bad[k], (int)st);
        appm_scene_destroy(s);
    }
}

/* A bare .obj gets a camera that frames its bounding box looking along -z,
 * 512x512 and fov 40 (docs/scene-format.md section 1). */
static void test_bare_obj_camera(void)
{
    appm_scene *s;
    appm_diag d;
    appm_scene_info in;
    int c;
    CHECK(load("scenes/CornellBox-Original.obj", &s, &d, NULL) == APPM_OK);
    if (!s) return;
    appm_scene_get_info(s, &in);
    CHECK(in.width == 512 && in.height == 512);
    CHECK_NEAR(s->cam.fov, 40.0, 1e-6);
    CHECK_NEAR(s->cam.forward.x, 0.0, 1e-6);
    CHECK_NEAR(s->cam.forward.y, 0.0, 1e-6);
    CHECK_NEAR(s->cam.forward.z, -1.0, 1e-6);
    CHECK_NEAR(s->cam.up.y, 1.0, 1e-6);
    CHECK(s->cam.eye.z > (float)in.bbox_max[2]); /* in front of the model */
    /* every corner of the bounding box lies inside the view frustum */
    for (c = 0; c < 8; ++c) {
        appm__v3 p = appm__v((float)(c & 1 ? in.bbox_max[0] : in.bbox_min[0]),
                             (float)(c & 2 ? in.bbox_max[1] : in.bbox_min[1]),
                             (float)(c & 4 ? in.bbox_max[2] : in.bbox_min[2]));
        appm__v3 v = appm__sub(p, s->cam.eye);
        double z = appm__dot(v, s->cam.forward);
        CHECK(z > 0);
        CHECK(fabs(appm__dot(v, s->cam.up)) <= z * s->cam.tan_half);
        CHECK(fabs(appm__dot(v, s->cam.right)) <= z * s->cam.tan_half);
    }
    appm_scene_destroy(s);
    /* the in-memory loader frames the model the same way */
    CHECK(load_mem(SQUARE_LF, LIGHT_MTL, &s, &d, NULL) == APPM_OK);
    if (s) {
        CHECK_NEAR(s->cam.eye.x, 0.5, 1e-6); /* centred on the unit square */
        CHECK_NEAR(s->cam.eye.y, 0.5, 1e-6);
        CHECK(s->width == 512 && s->height == 512);
    }
    appm_scene_destroy(s);
}

/* ---- .scene + OBJ + MTL from memory ---------------------------------------------- */

/* The whole file at path (malloc'ed, *len bytes), or NULL. */
static char *read_whole(const char *path, size_t *len)
{
    FILE *f = fopen(path, "rb");
    char *buf = NULL;
    long n;
    *len = 0;
    if (!f) return NULL;
    if (fseek(f, 0, SEEK_END) == 0 && (n = ftell(f)) >= 0 && fseek(f, 0, SEEK_SET) == 0 &&
        (buf = (char *)malloc((size_t)n + 1)) != NULL && fread(buf, 1, (size_t)n, f) == (size_t)n)
        *len = (size_t)n;
    fclose(f);
    return buf;
}

/* The image of 2 appm passes at 16 x 12 (malloc'ed), or NULL. */
static float *render_small(const appm_scene *s)
{
    appm_config c;
    appm_renderer *r;
    appm_image img;
    float *out = NULL;
    appm_config_init(&c);
    c.width = 16;
    c.height = 12;
    c.photons = 2000;
    c.threads = 1;
    r = check_renderer(s, &c);
    if (r && check_passes(r, 2)) {
        appm_renderer_image(r, &img);
        out = (float *)malloc(sizeof(float) * 3 * 16 * 12);
        if (out) memcpy(out, img.rgb, sizeof(float) * 3 * 16 * 12);
    }
    appm_renderer_destroy(r);
    return out;
}

/* appm_scene_load_memory with the texts of scenes/cornell-sphere.scene, its
 * OBJ and its MTL is the scene appm_scene_load reads from the files: the same
 * counts, the same scene hash in all five parts (geometry, materials, normals,
 * lights, and the .scene's camera, not a framed one), the same image.  Names
 * are matched as appm_scene_load would open them, and nothing comes from disk:
 * a mesh missing from the files is an error even where the file exists, a
 * missing MTL the default material with a warning. */
static void test_scene_memory(void)
{
    const char *paths[3] = {"scenes/cornell-sphere.scene", "scenes/CornellBox-Sphere.obj",
                            "scenes/CornellBox-Sphere.mtl"};
    char *text[3];
    size_t len[3], k;
    appm_memory_file files[2];
    appm_scene *disk = NULL, *mem = NULL;
    appm_scene_info a, b;
    appm_diag d;
    logbuf lb;
    float *ia = NULL, *ib = NULL;
    for (k = 0; k < 3; ++k) text[k] = read_whole(paths[k], &len[k]);
    if (!text[0] || !text[1] || !text[2]) {
        CHECK_MSG(0, "cannot read the Cornell box files");
        goto done;
    }
    files[0].name = "scenes/CornellBox-Sphere.obj";
    files[0].text = text[1];
    files[0].len = len[1];
    files[1].name = "scenes/CornellBox-Sphere.mtl";
    files[1].text = text[2];
    files[1].len = len[2];
    CHECK(appm_scene_load(paths[0], NULL, &disk, &d) == APPM_OK);
    CHECK_MSG(appm_scene_load_memory(text[0], len[0], paths[0], files, 2, NULL, &mem, &d) == APPM_OK, "%s: %s",
              d.file, d.message);
    if (disk && mem) {
        uint64_t ha[APPM__SH_PARTS], hb[APPM__SH_PARTS];
        appm_scene_get_info(disk, &a);
        appm_scene_get_info(mem, &b);
        CHECK(a.triangles == b.triangles && disk->nmat == mem->nmat && a.lights_area == b.lights_area);
        CHECK(b.width == 512 && b.height == 512 && !mem->cam.framed);
        CHECK_NEAR(mem->cam.fov_deg, 39.31, 0.0);
        appm__scene_hash(disk, ha);
        appm__scene_hash(mem, hb);
        for (k = 0; k < APPM__SH_PARTS; ++k) CHECK_MSG(ha[k] == hb[k], "scene hash part %d differs", (int)k);
        ia = render_small(disk);
        ib = render_small(mem);
        CHECK(ia && ib && memcmp(ia, ib, sizeof(float) * 3 * 16 * 12) == 0);
    }
    appm_scene_destroy(mem);
    mem = NULL;
    /* without a folder in the name, the names as written in the files */
    files[0].name = "CornellBox-Sphere.obj";
    files[1].name = "CornellBox-Sphere.mtl";
    CHECK(appm_scene_load_memory(text[0], len[0], "cornell-sphere.scene", files, 2, NULL, &mem, &d) == APPM_OK);
    appm_scene_destroy(mem);
    mem = NULL;
    /* the mesh is on disk at scenes/CornellBox-Sphere.obj, but not among the files */
    CHECK(appm_scene_load_memory(text[0], len[0], paths[0], files, 2, NULL, &mem, &d) == APPM_ERR_IO && !mem);
    CHECK(d.line == 3 && strstr(d.message, "cannot open mesh 'scenes/CornellBox-Sphere.obj'") != NULL);
    /* the MTL missing: the default material, with a warning (and a light, since nothing emits then) */
    files[0].name = "scenes/CornellBox-Sphere.obj";
    memset(&lb, 0, sizeof lb);
    {
        static const char lit[] = "mesh CornellBox-Sphere.obj\nenvironment 1 1 1\n";
        appm_config c;
        appm_config_init(&c);
        c.log = log_fn;
        c.log_user = &lb;
        CHECK(appm_scene_load_memory(lit, strlen(lit), "scenes/lit.scene", files, 1, &c, &mem, &d) == APPM_OK);
    }
    CHECK(log_count(&lb, "cannot open material library 'scenes/CornellBox-Sphere.mtl'") == 1);
    if (mem) {
        appm_scene_get_info(mem, &b);
        CHECK(mem->nmat == 1 && b.lights_area == 0);
    }
    appm_scene_destroy(mem);
    mem = NULL;
    CHECK(appm_scene_load_memory(NULL, 0, "x.scene", files, 1, NULL, &mem, &d) == APPM_ERR_INVALID_ARG && !mem);
    CHECK(appm_scene_load_memory(text[0], len[0], "x.scene", NULL, 2, NULL, &mem, &d) == APPM_ERR_INVALID_ARG);
    CHECK(appm_scene_load_memory(text[0], len[0], "x.scene", NULL, 0, NULL, &mem, &d) == APPM_ERR_IO);
done:
    for (k = 0; k < 3; ++k) free(text[k]);
    free(ia);
    free(ib);
    appm_scene_destroy(disk);
}

/* ---- the number parser ----------------------------------------------------------- */

static int num(const char *text, double *v) { return appm__parse_number(text, text + strlen(text), v); }

static void test_parse_number(void)
{
    static const struct {
        const char *text;
        double want;
    } good[] = {
        {"1", 1.0},        {"-0", -0.0},     {".5", 0.5},          {"5.", 5.0},
        {"1e-3", 1e-3},    {"1E+3", 1000.0}, {".8e-001", 0.08},    {"+2.5", 2.5},
        {"-7.25e2", -725}, {"0.1", 0.1},     {"123.456", 123.456}, {"00012", 12.0},
        {"1e-400", 0.0},   {"-1e-400", -0.0},
        {"12345678901234567890123", 12345678901234567890123.0}, /* more than 19 digits */
        {"3.14159265358979323846264338327950288", 3.14159265358979323846}, /* and after the point */
        {"0.000000000000000000000000000000000000001234567890123456789012", 1.234567890123456789e-39},
    };
    static const char *const bad[] = {"1,0", "e5",  "1e",   "--1", "0x10", "",     ".",   "+",
                                      "-",   "1e+", "1.2.3", "1e5.", "1 ",  " 1",   "nan1", "infinit",
                                      "1.#IND", "1d5", "0b1"};
    size_t k;
    double v;
    for (k = 0; k < sizeof good / sizeof good[0]; ++k) {
        int ok = num(good[k].text, &v);
        CHECK_MSG(ok, "'%s' rejected", good[k].text);
        if (!ok) continue;
        /* these have correctly rounded answers a single division or product gives */
        CHECK_MSG(v == good[k].want || fabs(v - good[k].want) <= 1e-15 * fabs(good[k].want),
                  "'%s' -> %.17g, expected %.17g", good[k].text, v, good[k].want);
        CHECK_MSG(signbit(v) == signbit(good[k].want), "'%s': sign of zero", good[k].text);
    }
    CHECK(num("1e400", &v) && v == HUGE_VAL);
    CHECK(num("-1e400", &v) && v == -HUGE_VAL);
    CHECK(num("3E4570711268", &v) && v == HUGE_VAL); /* saturating exponent: no overflow */
    CHECK(num("1e-4570711268", &v) && v == 0.0);
    CHECK(num("nan", &v) && v != v);
    CHECK(num("NaN", &v) && v != v);
    CHECK(num("-nan", &v) && v != v);
    CHECK(num("inf", &v) && v == HUGE_VAL);
    CHECK(num("-Infinity", &v) && v == -HUGE_VAL);
    CHECK(num("+INF", &v) && v == HUGE_VAL);
    CHECK(num("1.7976931348623157e308", &v) && v < HUGE_VAL && fabs(v - DBL_MAX) <= 1e-15 * DBL_MAX);
    CHECK(num("2.2250738585072014e-308", &v) && fabs(v - DBL_MIN) <= 1e-15 * DBL_MIN);
    for (k = 0; k < sizeof bad / sizeof bad[0]; ++k) CHECK_MSG(!num(bad[k], &v), "'%s' accepted", bad[k]);
    /* bounded by `e`, not by a NUL: "12" out of "12345" */
    {
        const char digits[] = "12345e9";
        CHECK(appm__parse_number(digits, digits + 2, &v) && v == 12.0);
        CHECK(appm__parse_number(digits, digits + 5, &v) && v == 12345.0);
        CHECK(!appm__parse_number(digits, digits + 6, &v)); /* "12345e": no exponent digits */
    }
}

/* A UTF-8 byte order mark at the start of a .scene, .obj or .mtl (Windows
 * editors write one) is skipped, not an unknown keyword (docs/scene-format.md 1);
 * a BOM anywhere else is still an error, and line numbers stay right. */
static void test_bom(void)
{
    appm_scene *s = NULL;
    appm_diag d;
    logbuf lb;
    CHECK(load_mem("\xEF\xBB\xBFmtllib m.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nusemtl light\nf 1 2 3\n",
                   "\xEF\xBB\xBFnewmtl light\nKd 0.5 0.5 0.5\nKe 1 1 1\n", &s, &d, &lb) == APPM_OK);
    CHECK_MSG(lb.n == 0, "%d warnings for a BOM (first: %s)", lb.n, lb.n ? lb.msg[0] : "");
    if (s) CHECK(s->ntri == 1 && s->nlight == 1 && s->mat[s->info[0].mat].emissive);
    appm_scene_destroy(s);
    /* a BOM alone, and a BOM in front of an empty MTL */
    s = NULL;
    CHECK(load_mem("\xEF\xBB\xBF", NULL, &s, &d, &lb) == APPM_ERR_PARSE && strstr(d.message, "no triangles"));
    appm_scene_destroy(s);
    s = NULL;
    CHECK(load_scene_text("\xEF\xBB\xBFmesh ../fixtures/no-light.obj\nimage 64 48\nlight point position 0 1 0 "
                          "intensity 1 1 1\n",
                          &s, &d) == APPM_OK);
    if (s) CHECK(s->width == 64 && s->height == 48);
    appm_scene_destroy(s);
    s = NULL;
    CHECK(load_scene_text("image 64 48\n\xEF\xBB\xBFmesh ../fixtures/no-light.obj\n", &s, &d) == APPM_ERR_PARSE);
    CHECK_MSG(d.line == 2, "a BOM on line 2: error on line %u", d.line);
    appm_scene_destroy(s);
}

int main(void)
{
    test_parse_number();
    test_cornell();
    test_two_meshes();
    test_crlf();
    test_negative_index();
    test_polygon();
    test_big_polygon_long_line();
    test_missing_mtl();
    test_vn_before_v();
    test_face_forms();
    test_obj_errors();
    test_garbage();
    test_empty();
    test_scene_file_errors();
    test_degenerate_duplicate();
    test_short_face();
    test_long_line();
    test_no_trailing_newline();
    test_mtl_before_newmtl();
    test_mtl_mapping();
    test_mtl_values();
    test_mtl_glossy();
    test_obj_ignored_warnings();
    test_scene_statements();
    test_scene_malformed();
    test_scene_trailing_tokens();
    test_bare_obj_camera();
    test_scene_memory();
    test_bom();
    return check_finish();
}
