/* tests/t_bvh.c - BVH traversal and the triangle test (appm.c section 5).
 *
 * What is checked, and against what:
 *   1. BVH == brute force (testing.md G1, G6).  appm__intersect must return
 *      exactly what a plain loop of appm__tri_hit over every triangle returns:
 *      same hit/miss, bitwise the same t and barycentrics, the same triangle
 *      (another one only for an exact tie), and appm__occluded(tmax) must equal
 *      (closest t < tmax).  Both call the same triangle routine on the same
 *      floats, so any difference is a traversal bug (a box test that rejected a
 *      box holding the answer, a stack pop that pruned too much), never rounding.
 *   2. Watertightness (G2, Embree's protocol): rays from inside a closed
 *      tessellated sphere far from the origin, and a tiny one, never escape.
 *   3. Self-intersection (G3, pbrt's Triangle.Reintersect): a ray spawned with
 *      appm__offset from a hit point never hits its own triangle again.
 *   4. Degenerate builds (G7, G8): duplicates, one triangle, a geometric chain
 *      that drives the SAH deep; NaN/inf/zero rays miss without crashing.
 *   5. pbrt's Triangle.BadCases (G4): a zero-area triangle is never hit.
 *   6. The wide tree's SIMD and scalar box tests agree exactly, ties included
 *      (every ray of part 1 goes through both), and the whole suite runs once
 *      on each path.
 *
 * The brute-force reference for the 69k-triangle bunny would cost 1e10 triangle
 * tests for 1e5 rays, so the big ray sets use the same loop with a culling step
 * that is provably conservative (a bounding sphere per chunk of 32 consecutive
 * triangles, tested in double with a margin 1e4 times the rounding error of the
 * float test); it visits the surviving triangles in the same order with the same
 * shrinking tmax, so its answers are bitwise those of the plain loop.  A subset
 * of rays is checked against the plain loop as well, which also tests the cull.
 */
#include "../appm.c"
#include "check.h"

#define GROUP "bvh"

static appm__rng g_rng;

static float uf(void) { return appm__rng_float(&g_rng); }
static float urange(float a, float b) { return a + (b - a) * uf(); }

/* Uniform direction, in double then rounded (independent of the library's own
 * sampling code). */
static appm__v3 rand_dir(void)
{
    double z = 1.0 - 2.0 * uf(), r = sqrt(fmax(0.0, 1.0 - z * z)), ph = 2.0 * APPM__PI * uf();
    return appm__v((float)(r * cos(ph)), (float)(r * sin(ph)), (float)z);
}

static appm__v3 rand_in_box(appm__v3 lo, appm__v3 hi)
{
    return appm__v(urange(lo.x, hi.x), urange(lo.y, hi.y), urange(lo.z, hi.z));
}

static appm__v3 lerp3(appm__v3 a, appm__v3 b, float t) { return appm__add(a, appm__scale(appm__sub(b, a), t)); }

/* ---- Scenes ---------------------------------------------------------------- */

/* The traversal every scene of the current round uses (main runs the suite
 * once per path: the vector box test, where the build has one, and the scalar). */
static int g_path = APPM__BVH_SIMD;

static appm_scene *on_path(appm_scene *s)
{
    if (s) s->bvh_path = g_path;
    return s;
}

static appm_scene *load_text(const char *obj, const char *mtl, const char *name)
{
    appm_scene *s = NULL;
    appm_diag d;
    appm_status st = appm_scene_load_obj_memory(obj, strlen(obj), mtl, mtl ? strlen(mtl) : 0, name, NULL, &s, &d);
    CHECK_MSG(st == APPM_OK, "%s: %s:%u: %s", name, d.file, d.line, d.message);
    return st == APPM_OK ? on_path(s) : NULL;
}

/* A growing text buffer for generated OBJ files. */
typedef struct tbuf {
    char *p;
    size_t n, cap;
} tbuf;

static void tputs(tbuf *t, const char *fmt, ...)
{
    va_list ap;
    int k;
    for (;;) {
        size_t room = t->cap - t->n;
        va_start(ap, fmt);
        k = vsnprintf(t->p ? t->p + t->n : NULL, t->p ? room : 0, fmt, ap);
        va_end(ap);
        if (k < 0) abort();
        if (t->p && (size_t)k < room) {
            t->n += (size_t)k;
            return;
        }
        t->cap = t->cap * 2 + (size_t)k + 4096;
        t->p = (char *)realloc(t->p, t->cap);
        if (!t->p) abort();
    }
}

static const char *EMIT_MTL = "newmtl glow\nKe 1 1 1\nKd 0.5 0.5 0.5\n";

/* A UV sphere with shared vertices (so it is closed: neighbouring triangles
 * use the very same floats for their common edge), nseg x nring, counter-
 * clockwise seen from outside, every triangle emissive so the scene has a light. */
static appm_scene *uv_sphere(double cx, double cy, double cz, double R, int nseg, int nring)
{
    tbuf t = {NULL, 0, 0};
    int i, j;
    appm_scene *s;
    tputs(&t, "mtllib m.mtl\nusemtl glow\n");
    tputs(&t, "v %.17g %.17g %.17g\n", cx, cy + R, cz); /* 1: north pole */
    for (i = 1; i < nring; ++i) {
        double th = APPM__PI * i / nring;
        for (j = 0; j < nseg; ++j) {
            double ph = 2.0 * APPM__PI * j / nseg;
            tputs(&t, "v %.17g %.17g %.17g\n", cx + R * sin(th) * cos(ph), cy + R * cos(th),
                  cz - R * sin(th) * sin(ph));
        }
    }
    tputs(&t, "v %.17g %.17g %.17g\n", cx, cy - R, cz); /* last: south pole */
#define RV(i, j) (2 + ((i) - 1) * nseg + ((j) % nseg))
    for (j = 0; j < nseg; ++j) tputs(&t, "f 1 %d %d\n", RV(1, j), RV(1, j + 1));
    for (i = 1; i + 1 < nring; ++i)
        for (j = 0; j < nseg; ++j) {
            tputs(&t, "f %d %d %d\n", RV(i, j), RV(i + 1, j), RV(i + 1, j + 1));
            tputs(&t, "f %d %d %d\n", RV(i, j), RV(i + 1, j + 1), RV(i, j + 1));
        }
    for (j = 0; j < nseg; ++j)
        tputs(&t, "f %d %d %d\n", RV(nring - 1, j), 2 + (nring - 1) * nseg, RV(nring - 1, j + 1));
#undef RV
    s = load_text(t.p, EMIT_MTL, "sphere.obj");
    free(t.p);
    return s;
}

/* An axis-aligned cube of edge `a` centred at c, 12 emissive triangles. */
static appm_scene *cube(double cx, double cy, double cz, double a)
{
    static const int f[12][3] = {{1, 3, 2}, {2, 3, 4}, {5, 6, 7}, {6, 8, 7}, {1, 2, 5}, {2, 6, 5},
                                 {3, 7, 4}, {4, 7, 8}, {1, 5, 3}, {3, 5, 7}, {2, 4, 6}, {4, 8, 6}};
    tbuf t = {NULL, 0, 0};
    int i;
    appm_scene *s;
    tputs(&t, "mtllib m.mtl\nusemtl glow\n");
    for (i = 0; i < 8; ++i)
        tputs(&t, "v %.17g %.17g %.17g\n", cx + (i & 1 ? a : -a) / 2, cy + (i & 2 ? a : -a) / 2,
              cz + (i & 4 ? a : -a) / 2);
    for (i = 0; i < 12; ++i) tputs(&t, "f %d %d %d\n", f[i][0], f[i][1], f[i][2]);
    s = load_text(t.p, EMIT_MTL, "cube.obj");
    free(t.p);
    return s;
}

/* A scene assembled by hand (for triangles the loader would not accept, and
 * for zero triangles), built with the library's own appm__bvh_build. */
static appm_scene *hand_scene(const appm__tri *tris, uint32_t n)
{
    appm_scene *s = (appm_scene *)calloc(1, sizeof *s);
    uint32_t i;
    if (!s) abort();
    appm__mem_init(&s->mem, NULL);
    s->ntri = n;
    if (n) {
        s->tri = (appm__tri *)appm__alloc(&s->mem, n, sizeof *s->tri);
        s->info = (appm__tri_info *)appm__alloc(&s->mem, n, sizeof *s->info);
        if (!s->tri || !s->info) abort();
        for (i = 0; i < n; ++i) {
            appm__v3 cr = appm__cross(appm__sub(tris[i].p1, tris[i].p0), appm__sub(tris[i].p2, tris[i].p0));
            s->tri[i] = tris[i];
            s->info[i].ng = appm__normalize(cr);
            s->info[i].area = 0.5f * appm__length(cr);
            s->info[i].light = -1;
            s->info[i].n0 = -1;
        }
    }
    CHECK(appm__bvh_build(s, NULL) == APPM_OK);
    return on_path(s);
}

static void hand_free(appm_scene *s)
{
    appm__free(&s->mem, s->tri);
    appm__free(&s->mem, s->info);
    appm__free(&s->mem, s->node);
    appm__free(&s->mem, s->wnode_mem);
    CHECK(s->mem.live == 0); /* the build freed all its scratch memory */
    free(s);
}

/* ---- Brute force ------------------------------------------------------------ */

/* The reference: every triangle, in index order, with a shrinking tmax - the
 * same rule as the leaf loop of appm__intersect, minus the tree. */
static int brute(const appm_scene *s, const appm__ray *r, appm__hit *h)
{
    appm__ray q = *r;
    uint32_t i;
    int found = 0;
    if (!r->valid) return 0;
    for (i = 0; i < s->ntri; ++i)
        if (appm__tri_hit(&q, &s->tri[i], h)) {
            q.tmax = h->t;
            h->tri = i;
            found = 1;
        }
    return found;
}

#define CHUNK 32

typedef struct cull {
    uint32_t n;
    double *c; /* centre, 3 per chunk */
    double *R; /* radius of a sphere holding every vertex of the chunk */
} cull;

static void cull_init(cull *cu, const appm_scene *s)
{
    uint32_t k, i;
    cu->n = (s->ntri + CHUNK - 1) / CHUNK;
    cu->c = (double *)malloc(3 * sizeof(double) * (cu->n + 1));
    cu->R = (double *)malloc(sizeof(double) * (cu->n + 1));
    if (!cu->c || !cu->R) abort();
    for (k = 0; k < cu->n; ++k) {
        double lo[3] = {HUGE_VAL, HUGE_VAL, HUGE_VAL}, hi[3] = {-HUGE_VAL, -HUGE_VAL, -HUGE_VAL}, R = 0;
        uint32_t end = (k + 1) * CHUNK < s->ntri ? (k + 1) * CHUNK : s->ntri;
        int a, v;
        for (i = k * CHUNK; i < end; ++i)
            for (v = 0; v < 3; ++v) {
                appm__v3 p = v == 0 ? s->tri[i].p0 : (v == 1 ? s->tri[i].p1 : s->tri[i].p2);
                for (a = 0; a < 3; ++a) {
                    double x = appm__comp(p, a);
                    lo[a] = fmin(lo[a], x);
                    hi[a] = fmax(hi[a], x);
                }
            }
        for (a = 0; a < 3; ++a) cu->c[3 * k + a] = 0.5 * (lo[a] + hi[a]);
        for (i = k * CHUNK; i < end; ++i)
            for (v = 0; v < 3; ++v) {
                appm__v3 p = v == 0 ? s->tri[i].p0 : (v == 1 ? s->tri[i].p1 : s->tri[i].p2);
                double dx = p.x - cu->c[3 * k], dy = p.y - cu->c[3 * k + 1], dz = p.z - cu->c[3 * k + 2];
                R = fmax(R, sqrt(dx * dx + dy * dy + dz * dz));
            }
        cu->R[k] = R;
    }
}

static void cull_free(cull *cu)
{
    free(cu->c);
    free(cu->R);
}

/* The brute-force loop, skipping chunks whose bounding sphere the ray's line
 * provably misses.  The float test can only report a hit within a few ulps of
 * the true geometry (relative error ~1e-7 of the distances involved), so a
 * margin of 1e-3 of those distances can never drop a triangle it would hit. */
static int brute_cull(const appm_scene *s, const cull *cu, const appm__ray *r, appm__hit *h)
{
    appm__ray q = *r;
    uint32_t k, i;
    int found = 0;
    double o[3], d[3], dd;
    if (!r->valid) return 0;
    o[0] = r->o.x, o[1] = r->o.y, o[2] = r->o.z;
    d[0] = r->d.x, d[1] = r->d.y, d[2] = r->d.z;
    dd = d[0] * d[0] + d[1] * d[1] + d[2] * d[2];
    for (k = 0; k < cu->n; ++k) {
        double v0 = cu->c[3 * k] - o[0], v1 = cu->c[3 * k + 1] - o[1], v2 = cu->c[3 * k + 2] - o[2];
        double along = (v0 * d[0] + v1 * d[1] + v2 * d[2]) / sqrt(dd);
        double x0 = v1 * d[2] - v2 * d[1], x1 = v2 * d[0] - v0 * d[2], x2 = v0 * d[1] - v1 * d[0];
        double dist2 = (x0 * x0 + x1 * x1 + x2 * x2) / dd;
        double m = cu->R[k] + 1e-3 * (sqrt(v0 * v0 + v1 * v1 + v2 * v2) + cu->R[k]) + 1e-30;
        uint32_t end;
        if (dist2 > m * m || along < -m) continue;
        end = (k + 1) * CHUNK < s->ntri ? (k + 1) * CHUNK : s->ntri;
        for (i = k * CHUNK; i < end; ++i)
            if (appm__tri_hit(&q, &s->tri[i], h)) {
                q.tmax = h->t;
                h->tri = i;
                found = 1;
            }
    }
    return found;
}

/* ---- 1. BVH against brute force ------------------------------------------- */

typedef struct ray_stats {
    const char *name;
    long rays, hits, bad_hit, bad_t, bad_tri, ties, bad_any, bad_clip, bad_cull, bad_path, pure;
    int printed;
} ray_stats;

static void stats_start(ray_stats *st, const char *name)
{
    memset(st, 0, sizeof *st);
    st->name = name;
}

static void report_ray(ray_stats *st, const char *what, appm__v3 o, appm__v3 d)
{
    if (st->printed++ >= 3) return;
    fprintf(stderr, "  %s: %s: o = (%.9g, %.9g, %.9g) d = (%.9g, %.9g, %.9g)\n", st->name, what, o.x, o.y,
            o.z, d.x, d.y, d.z);
}

/* The vector and the scalar box test must give the very same answer, exact
 * ties included (the same triangle): they compute the same floats and visit
 * the same nodes in the same order.  Without SIMD both calls are scalar. */
static void compare_paths(const appm_scene *s, const appm__ray *r, ray_stats *st, appm__v3 o, appm__v3 d)
{
    appm__hit a, b;
    int fa = appm__intersect_wide(s, r, UINT32_MAX, &a, 0), fb = appm__intersect_wide(s, r, UINT32_MAX, &b, 1);
    if (fa != fb || (fa && (check_fbits(a.t) != check_fbits(b.t) || check_fbits(a.b1) != check_fbits(b.b1) ||
                            check_fbits(a.b2) != check_fbits(b.b2) || a.tri != b.tri)) ||
        appm__occluded_wide(s, r, UINT32_MAX, UINT32_MAX, 0) != appm__occluded_wide(s, r, UINT32_MAX, UINT32_MAX, 1)) {
        st->bad_path++;
        report_ray(st, "the SIMD and the scalar box test disagree", o, d);
    }
}

/* One ray through the BVH and through the reference.  `pure` also runs the
 * plain loop and requires the culled loop to agree with it bitwise. */
static void compare_ray(const appm_scene *s, const cull *cu, appm__v3 o, appm__v3 d, ray_stats *st, int pure)
{
    appm__ray r;
    appm__hit hb, hf, hp, hc;
    int fb, ff, fc, expect;
    float T;
    appm__ray_init(&r, o, d, FLT_MAX);
    if (!r.valid) return;
    st->rays++;
    fb = appm__intersect(s, &r, UINT32_MAX, &hb);
    ff = cu ? brute_cull(s, cu, &r, &hf) : brute(s, &r, &hf);
    compare_paths(s, &r, st, o, d);
    if (pure && cu) {
        int fp = brute(s, &r, &hp);
        st->pure++;
        if (fp != ff || (fp && (check_fbits(hp.t) != check_fbits(hf.t) || hp.tri != hf.tri))) {
            st->bad_cull++;
            report_ray(st, "culled reference differs from the plain loop", o, d);
        }
    }
    st->hits += ff;
    if (fb != ff) {
        st->bad_hit++;
        report_ray(st, fb ? "BVH hit, brute force missed" : "BVH missed, brute force hit", o, d);
        return;
    }
    if (ff) {
        if (check_fbits(hb.t) != check_fbits(hf.t)) {
            st->bad_t++;
            report_ray(st, "different t", o, d);
        } else if (hb.tri != hf.tri) {
            /* An exact tie: accept the BVH's triangle only if it is really hit
             * at exactly that t (rays through shared edges and vertices). */
            appm__hit ht;
            appm__ray q = r;
            if (hb.tri < s->ntri && appm__tri_hit(&q, &s->tri[hb.tri], &ht) && check_fbits(ht.t) == check_fbits(hf.t)) {
                st->ties++;
            } else {
                st->bad_tri++;
                report_ray(st, "different triangle, not a tie", o, d);
            }
        } else if (check_fbits(hb.b1) != check_fbits(hf.b1) || check_fbits(hb.b2) != check_fbits(hf.b2)) {
            st->bad_t++;
            report_ray(st, "different barycentrics", o, d);
        }
    }
    /* Any-hit and clipped closest-hit with a tmax at, just above, or randomly
     * around the closest t. */
    if (ff) {
        switch (st->rays % 4) {
        case 0: T = hf.t; break;                       /* hit exactly at tmax: not in (0, tmax) */
        case 1: T = nextafterf(hf.t, FLT_MAX); break;  /* one ulp later: in */
        default: T = hf.t * urange(0.25f, 2.0f); break;
        }
    } else {
        T = st->rays % 2 ? FLT_MAX : urange(0.01f, 10.0f);
    }
    r.tmax = T;
    expect = ff && hf.t < T;
    if (appm__occluded(s, &r, UINT32_MAX, UINT32_MAX) != expect) {
        st->bad_any++;
        report_ray(st, "occluded() disagrees with closest t < tmax", o, d);
    }
    fc = appm__intersect(s, &r, UINT32_MAX, &hc);
    if (fc != expect || (fc && check_fbits(hc.t) != check_fbits(hf.t))) {
        st->bad_clip++;
        report_ray(st, "intersect() with a finite tmax disagrees", o, d);
    }
    compare_paths(s, &r, st, o, d);
}

static void stats_check(const ray_stats *st, long min_rays)
{
    printf("  %-22s rays %7ld  hits %7ld  ties %5ld  plain-loop checked %5ld\n", st->name, st->rays, st->hits,
           st->ties, st->pure);
    CHECK_MSG(st->rays >= min_rays, "%s: only %ld valid rays", st->name, st->rays);
    CHECK_MSG(st->bad_hit == 0, "%s: %ld hit/miss disagreements", st->name, st->bad_hit);
    CHECK_MSG(st->bad_t == 0, "%s: %ld t or barycentric disagreements", st->name, st->bad_t);
    CHECK_MSG(st->bad_tri == 0, "%s: %ld triangle disagreements that are not ties", st->name, st->bad_tri);
    CHECK_MSG(st->bad_any == 0, "%s: %ld any-hit disagreements", st->name, st->bad_any);
    CHECK_MSG(st->bad_clip == 0, "%s: %ld clipped closest-hit disagreements", st->name, st->bad_clip);
    CHECK_MSG(st->bad_cull == 0, "%s: %ld culled-reference disagreements (test bug)", st->name, st->bad_cull);
    CHECK_MSG(st->bad_path == 0, "%s: %ld SIMD/scalar disagreements", st->name, st->bad_path);
}

static appm__v3 tri_vertex(const appm__tri *t, int k)
{
    return k == 0 ? t->p0 : (k == 1 ? t->p1 : t->p2);
}

/* Vertices, edge midpoints, or random interior points of random triangles. */
static appm__v3 tri_target(const appm_scene *s, int kind)
{
    const appm__tri *t = &s->tri[appm__rng_u32(&g_rng) % s->ntri];
    int k = (int)(appm__rng_u32(&g_rng) % 3);
    if (kind == 0) return tri_vertex(t, k);
    if (kind == 1) return appm__scale(appm__add(tri_vertex(t, k), tri_vertex(t, (k + 1) % 3)), 0.5f);
    {
        float b1 = uf(), b2 = uf();
        if (b1 + b2 > 1) b1 = 1 - b1, b2 = 1 - b2;
        return appm__add(t->p0, appm__add(appm__scale(appm__sub(t->p1, t->p0), b1),
                                          appm__scale(appm__sub(t->p2, t->p0), b2)));
    }
}

static float signed_zero(void) { return uf() < 0.5f ? 0.0f : -0.0f; }

/* The wide tree's structure: every triangle in exactly one leaf, used slots
 * first, a leaf's packs holding its triangles in order with the padding lanes
 * marked, every leaf box holding its triangles, and nwnode / wdepth (also the
 * scene info's bvh_nodes / bvh_depth) those of the tree reached from the root. */
static void wide_walk(const appm_scene *s, uint32_t ni, uint32_t depth, unsigned char *seen, uint32_t *nodes,
                      uint32_t *maxd, long *bad)
{
    const appm__wnode *n = &s->wnode[ni];
    int j, used = 1;
    (*nodes)++;
    if (depth > *maxd) *maxd = depth;
    for (j = 0; j < APPM__BVH_W; ++j) {
        uint32_t c = n->count[j], first = n->first[j], k, a;
        if (!c) {
            used = 0;
            continue;
        }
        if (!used) ++*bad; /* a used slot after an empty one */
        if (c == APPM__W_INNER) {
            wide_walk(s, first, depth + 1, seen, nodes, maxd, bad);
            continue;
        }
#if defined(APPM__PACKS)
        for (k = 0; k < (c + 3) / 4 * 4; ++k) {
            uint32_t t = s->pack[first + k / 4].tri[k % 4];
            if (k >= c ? t != APPM__NO_TRI : t != s->pack[first].tri[0] + k) ++*bad;
            if (k % 4 == 0 && s->ptri[first + k / 4] != s->pack[first + k / 4].tri[0]) ++*bad;
        }
        first = s->pack[first].tri[0];
#endif
        for (k = first; k < first + c; ++k) {
            const appm__v3 *p;
            if (k >= s->ntri || seen[k]++) {
                ++*bad;
                continue;
            }
            p = &s->tri[k].p0;
            for (a = 0; a < 9; ++a) {
                float x = appm__comp(p[a / 3], (int)(a % 3));
                if (x < n->lo[a % 3][j] || x > n->hi[a % 3][j]) ++*bad;
            }
        }
    }
}

/* The largest leaf of the wide tree: at most 8 triangles (the binary build's
 * largest leaf) in a small tree, at most APPM__LEAF_FLAT in a large one. */
static uint32_t check_leaf_sizes(const appm_scene *s, const char *name)
{
    uint32_t i, j, big = 0, cap = s->ntri >= APPM__FLAT_TRIS ? APPM__LEAF_FLAT : 8;
    for (i = 0; i < s->nwnode; ++i)
        for (j = 0; j < APPM__BVH_W; ++j) {
            uint32_t c = s->wnode[i].count[j];
            if (c != APPM__W_INNER && c > big) big = c;
        }
    CHECK_MSG(big <= cap, "%s: a leaf of %u triangles (at most %u)", name, big, cap);
    return big;
}

/* Returns the largest leaf's triangle count. */
static uint32_t check_wide_tree(const appm_scene *s, const char *name)
{
    unsigned char *seen = (unsigned char *)calloc(s->ntri ? s->ntri : 1, 1);
    uint32_t nodes = 0, maxd = 0, i, missing = 0;
    long bad = 0;
    appm_scene_info in;
    CHECK(seen != NULL);
    if (!seen) return 0;
    wide_walk(s, 0, 1, seen, &nodes, &maxd, &bad);
    for (i = 0; i < s->ntri; ++i) missing += seen[i] != 1;
    printf("%s: wide tree %u nodes, depth %u, %u packs\n", name, s->nwnode, s->wdepth, s->npack);
    CHECK(bad == 0 && missing == 0);
    CHECK(nodes == s->nwnode && maxd == s->wdepth && maxd <= s->depth);
    appm_scene_get_info(s, &in);
    CHECK(in.bvh_nodes == s->nwnode && in.bvh_depth == s->wdepth);
    free(seen);
    return check_leaf_sizes(s, name);
}

/* All ray families against one scene.  n: number of uniform random rays; the
 * other families get n/10 each; `npure` rays are also run through the plain loop. */
static void bvh_vs_brute(const appm_scene *s, const char *name, long n, long npure, int use_cull)
{
    ray_stats st;
    cull cu;
    const cull *cp = NULL;
    appm__v3 lo = s->bmin, hi = s->bmax, ext = appm__sub(hi, lo), elo, ehi, ilo, ihi;
    float diag = appm__length(ext);
    long i, m = n / 10;
    char label[64];
    if (use_cull) {
        cull_init(&cu, s);
        cp = &cu;
    }
    elo = appm__sub(lo, appm__scale(ext, 0.5f));
    ehi = appm__add(hi, appm__scale(ext, 0.5f));
    ilo = lerp3(lo, hi, 0.35f);
    ihi = lerp3(lo, hi, 0.65f);
    printf("%s: %u triangles, %u nodes, depth %u\n", name, s->ntri, s->nnode, s->depth);
    CHECK(s->depth < APPM__BVH_MAX_DEPTH);
    check_wide_tree(s, name);

    snprintf(label, sizeof label, "%s random", name);
    stats_start(&st, label);
    for (i = 0; i < n; ++i) compare_ray(s, cp, rand_in_box(elo, ehi), rand_dir(), &st, i < npure);
    stats_check(&st, n * 9 / 10);

    snprintf(label, sizeof label, "%s inside", name);
    stats_start(&st, label);
    for (i = 0; i < m; ++i) compare_ray(s, cp, rand_in_box(ilo, ihi), rand_dir(), &st, 0);
    stats_check(&st, m * 9 / 10);

    /* Grazing: through a point of a triangle at 1e-7..1e-1 radians from its
     * plane, or exactly along one of its edges (shared with a neighbour). */
    snprintf(label, sizeof label, "%s grazing", name);
    stats_start(&st, label);
    for (i = 0; i < m; ++i) {
        uint32_t k = appm__rng_u32(&g_rng) % s->ntri;
        const appm__tri *t = &s->tri[k];
        appm__v3 d, p;
        if (i % 2) {
            appm__v3 ng = s->info[k].ng, tt, bt;
            float a = urange(0.0f, 2.0f * APPM__PIF), e = powf(10.0f, urange(-7.0f, -1.0f));
            appm__basis(ng, &tt, &bt);
            p = appm__add(t->p0, appm__scale(appm__sub(t->p1, t->p0), 0.3f));
            p = appm__add(p, appm__scale(appm__sub(t->p2, t->p0), 0.3f));
            d = appm__add(appm__add(appm__scale(tt, cosf(a)), appm__scale(bt, sinf(a))),
                          appm__scale(ng, uf() < 0.5f ? e : -e));
            d = appm__normalize(d);
        } else {
            int v = (int)(appm__rng_u32(&g_rng) % 3);
            appm__v3 a = tri_vertex(t, v), b = tri_vertex(t, (v + 1) % 3);
            d = appm__sub(b, a);
            p = a;
        }
        compare_ray(s, cp, appm__sub(p, appm__scale(d, urange(0.01f, 1.0f) * diag / appm__length(d))), d, &st, 0);
    }
    stats_check(&st, m * 9 / 10);

    /* Axis-aligned: direction components exactly +0 or -0; some origins
     * exactly on a face of the root box, moving along that face. */
    snprintf(label, sizeof label, "%s axis-aligned", name);
    stats_start(&st, label);
    for (i = 0; i < m; ++i) {
        appm__v3 o = rand_in_box(elo, ehi), d;
        float c[3];
        int a = (int)(appm__rng_u32(&g_rng) % 3), pattern = (int)(i % 4);
        c[0] = signed_zero(), c[1] = signed_zero(), c[2] = signed_zero();
        c[a] = uf() < 0.5f ? 1.0f : -1.0f;
        if (pattern == 1) c[(a + 1) % 3] = urange(-1.0f, 1.0f);
        if (pattern >= 2) { /* on the box face x_b = lo or hi, with d_b = +-0 */
            int b = (a + 1 + (int)(appm__rng_u32(&g_rng) % 2)) % 3;
            float face = uf() < 0.5f ? appm__comp(lo, b) : appm__comp(hi, b);
            if (b == 0) o.x = face;
            else if (b == 1) o.y = face;
            else o.z = face;
            c[3 - a - b] = pattern == 3 ? urange(-1.0f, 1.0f) : c[3 - a - b];
            /* aim into the box along the other axes */
            o = appm__v(b == 0 ? o.x : urange(lo.x, hi.x), b == 1 ? o.y : urange(lo.y, hi.y),
                        b == 2 ? o.z : urange(lo.z, hi.z));
            if (a == 0) o.x = c[0] > 0 ? elo.x : ehi.x;
            if (a == 1) o.y = c[1] > 0 ? elo.y : ehi.y;
            if (a == 2) o.z = c[2] > 0 ? elo.z : ehi.z;
        }
        d = appm__v(c[0], c[1], c[2]);
        compare_ray(s, cp, o, d, &st, 0);
    }
    stats_check(&st, m * 9 / 10);

    /* Aimed exactly at vertices and edge midpoints (unnormalised directions,
     * which the test must handle too). */
    snprintf(label, sizeof label, "%s vertices/edges", name);
    stats_start(&st, label);
    for (i = 0; i < m; ++i) {
        appm__v3 o = rand_in_box(elo, ehi), target = tri_target(s, (int)(i % 2));
        compare_ray(s, cp, o, appm__sub(target, o), &st, i < npure / 10);
    }
    stats_check(&st, m * 9 / 10);
    if (use_cull) cull_free(&cu);
}

static void test_bvh_vs_brute(void)
{
    const char *path = check_path(GROUP, "bunny.scene");
    appm_scene *s = NULL;
    appm_diag d;
    /* The bunny has no light of its own; a point light makes it a valid scene. */
    CHECK(check_write_file(path, "mesh ../../scenes/stanford-bunny.obj\n"
                                 "light point position 0 1 0 intensity 1 1 1\n"));
    CHECK_MSG(appm_scene_load(path, NULL, &s, &d) == APPM_OK, "%s:%u: %s", d.file, d.line, d.message);
    if (on_path(s)) {
        CHECK(s->ntri > 60000);
        CHECK(check_leaf_sizes(s, "bunny") > 8); /* it has flat leaves, traced below */
        bvh_vs_brute(s, "bunny", check_count(100000, 10000), check_count(1000, 100), 1);
        appm_scene_destroy(s);
    }
    /* A scene of axis-aligned walls with shared edges and exactly coplanar
     * neighbours, where ties and box-face rays are common. */
    s = NULL;
    CHECK_MSG(appm_scene_load("scenes/CornellBox-Original.obj", NULL, &s, &d) == APPM_OK, "%s:%u: %s", d.file,
              d.line, d.message);
    if (on_path(s)) {
        bvh_vs_brute(s, "cornell", check_count(50000, 5000), 0, 0);
        appm_scene_destroy(s);
    }
}

/* ---- 2. Watertightness ----------------------------------------------------- */

static void watertight(double cx, double cy, double cz, double R, long n, const char *name)
{
    appm_scene *s = uv_sphere(cx, cy, cz, R, 64, 32);
    long i, miss = 0, occl_miss = 0, bad_dist = 0, rays = 0;
    uint32_t k;
    appm__v3 c = appm__v((float)cx, (float)cy, (float)cz);
    if (!s) return;
    CHECK_MSG(s->dropped == 0 && s->ntri == 2 * 64 * 31, "%s: %u triangles, %u dropped: not closed", name,
              s->ntri, (unsigned)s->dropped);
    for (i = 0; i < n; ++i) {
        /* origin uniform in the ball of radius R/2 around the centre */
        appm__v3 w = rand_dir(), d = rand_dir(), o;
        double rr = 0.5 * R * cbrt((double)uf()), dx, dy, dz, t;
        appm__ray r;
        appm__hit h;
        o = appm__v((float)(cx + rr * w.x), (float)(cy + rr * w.y), (float)(cz + rr * w.z));
        appm__ray_init(&r, o, d, FLT_MAX);
        rays++;
        if (!appm__intersect(s, &r, UINT32_MAX, &h)) {
            if (miss++ < 3)
                fprintf(stderr, "  %s: escaped: o = (%.9g, %.9g, %.9g) d = (%.9g, %.9g, %.9g)\n", name, o.x, o.y,
                        o.z, d.x, d.y, d.z);
            continue;
        }
        occl_miss += !appm__occluded(s, &r, UINT32_MAX, UINT32_MAX);
        /* the hit lies on the tessellated sphere: between the inscribed
         * distance R cos(pi/64) cos(pi/32) >= 0.9976 R and R (plus the float
         * rounding of the vertices, ulp(2e5)/2 = 0.008 = 0.4% of R = 2) */
        t = h.t;
        dx = (double)o.x + t * d.x - cx;
        dy = (double)o.y + t * d.y - cy;
        dz = (double)o.z + t * d.z - cz;
        t = sqrt(dx * dx + dy * dy + dz * dz);
        if (!(t > 0.99 * R && t < 1.01 * R)) bad_dist++;
    }
    /* Straight at every vertex and every edge midpoint from the centre. */
    for (k = 0; k < s->ntri; ++k) {
        int v;
        for (v = 0; v < 6; ++v) {
            const appm__tri *t = &s->tri[k];
            appm__v3 target = v < 3 ? tri_vertex(t, v)
                                    : appm__scale(appm__add(tri_vertex(t, v - 3), tri_vertex(t, (v - 2) % 3)), 0.5f);
            appm__ray r;
            appm__hit h;
            appm__ray_init(&r, c, appm__sub(target, c), FLT_MAX);
            rays++;
            if (!appm__intersect(s, &r, UINT32_MAX, &h)) {
                if (miss++ < 3)
                    fprintf(stderr, "  %s: escaped through a %s of triangle %u\n", name, v < 3 ? "vertex" : "edge", k);
            }
            occl_miss += !appm__occluded(s, &r, UINT32_MAX, UINT32_MAX);
        }
    }
    printf("%s: %ld rays, %ld escaped\n", name, rays, miss);
    CHECK_MSG(miss == 0, "%s: %ld of %ld rays from inside escaped", name, miss, rays);
    CHECK_MSG(occl_miss == 0, "%s: %ld rays from inside not occluded", name, occl_miss);
    CHECK_MSG(bad_dist == 0, "%s: %ld hits off the sphere", name, bad_dist);
    appm_scene_destroy(s);
}

static void test_watertight(void)
{
    long n = check_count(100000, 20000);
    watertight(1e5, 1e3, -2e5, 2.0, n, "sphere R=2 at (1e5,1e3,-2e5)");
    watertight(148376, 1234, -223423, 2.0, n / 4, "sphere R=2 at Embree's point");
    watertight(1e-3, -2e-3, 5e-4, 1e-4, n, "sphere R=1e-4");
}

/* ---- 3. Self-intersection ----------------------------------------------------- */

/* +-10^U(lo,hi) */
static float rexp(float lo, float hi)
{
    float m = powf(10.0f, urange(lo, hi));
    return uf() < 0.5f ? -m : m;
}

/* One triangle through the real loader, so that its geometric normal is the
 * one the library computes; emissive, so that the scene has a light.  NULL
 * when the loader drops it (zero area in float). */
static appm_scene *one_tri_scene(const appm__v3 *p)
{
    char obj[512];
    appm_scene *s = NULL;
    snprintf(obj, sizeof obj, "mtllib m.mtl\nusemtl glow\nv %.9g %.9g %.9g\nv %.9g %.9g %.9g\nv %.9g %.9g %.9g\nf 1 2 3\n",
             p[0].x, p[0].y, p[0].z, p[1].x, p[1].y, p[1].z, p[2].x, p[2].y, p[2].z);
    if (appm_scene_load_obj_memory(obj, strlen(obj), EMIT_MTL, strlen(EMIT_MTL), "tri.obj", NULL, &s, NULL) != APPM_OK)
        return NULL;
    if (s->ntri != 1) {
        appm_scene_destroy(s);
        return NULL;
    }
    return on_path(s);
}

/* pbrt's Triangle.Reintersect: triangles whose coordinates are +-10^U(-6,6)
 * (independent per coordinate: slivers of every shape), needles (an angle of
 * 1e-5..1e-2 rad, where a float cross product loses the normal's direction) and
 * compact triangles anywhere; a hit point found by a ray at an interior point;
 * from it, rays in uniform directions, grazing directions (1e-6..1e-1 rad off
 * the plane) and towards random far points, each leaving from
 * appm__offset(surface, w).  None may hit the triangle it leaves: the offset
 * must clear the hit point's rounding error, on the side w points to, and the
 * triangle test must not report a t that is rounding noise. */
static void test_reintersect(void)
{
    int quick = check_quick();
    int ntri = quick ? 1000 : 2000, nray = quick ? 200 : 500, i, j;
    long tris_used = 0, tris_tried = 0, rehits = 0, rays = 0, grazing = 0, wrong_side = 0;
    for (i = 0; i < ntri; ++i) {
        appm_scene *ts;
        const appm__tri *tri;
        appm__v3 p[3], ng, target, o, dir;
        float size, b1, b2;
        appm__ray r;
        appm__hit h;
        appm__surf sf;
        double nt[3];
        int k;
        if (i % 3 == 0) { /* every coordinate independent: slivers of every shape */
            for (k = 0; k < 3; ++k) p[k] = appm__v(rexp(-6, 6), rexp(-6, 6), rexp(-6, 6));
        } else if (i % 3 == 1) { /* a needle: an angle of 1e-5..1e-2 rad at p0 */
            appm__v3 u = rand_dir(), v = appm__normalize(appm__cross(u, rand_dir()));
            float len = powf(10.0f, urange(-6.0f, 6.0f)), alpha = powf(10.0f, urange(-5.0f, -2.0f));
            p[0] = appm__v(rexp(-6, 6), rexp(-6, 6), rexp(-6, 6));
            p[1] = appm__add(p[0], appm__scale(u, len));
            p[2] = appm__add(p[0], appm__scale(appm__add(appm__scale(u, cosf(alpha)), appm__scale(v, sinf(alpha))),
                                               len * urange(0.5f, 1.0f)));
        } else { /* a compact triangle far from (or near) the origin */
            appm__v3 base = appm__v(rexp(-6, 6), rexp(-6, 6), rexp(-6, 6));
            float mag = fmaxf(fabsf(base.x), fmaxf(fabsf(base.y), fabsf(base.z)));
            size = mag * powf(10.0f, urange(-5.0f, 0.0f));
            for (k = 0; k < 3; ++k)
                p[k] = appm__add(base, appm__v(size * urange(-1, 1), size * urange(-1, 1), size * urange(-1, 1)));
        }
        tris_tried++;
        if (!(ts = one_tri_scene(p))) continue;
        tri = &ts->tri[0];
        p[0] = tri->p0, p[1] = tri->p1, p[2] = tri->p2; /* as parsed */
        ng = ts->info[0].ng;
        /* a point well inside, computed in double, and a ray at it from a
         * random side at a distance comparable to the triangle */
        b1 = urange(0.1f, 0.8f);
        b2 = urange(0.1f, 0.9f - b1);
        target = appm__v((float)((1.0 - b1 - b2) * p[0].x + (double)b1 * p[1].x + (double)b2 * p[2].x),
                         (float)((1.0 - b1 - b2) * p[0].y + (double)b1 * p[1].y + (double)b2 * p[2].y),
                         (float)((1.0 - b1 - b2) * p[0].z + (double)b1 * p[1].z + (double)b2 * p[2].z));
        size = fmaxf(appm__length(appm__sub(p[1], p[0])), appm__length(appm__sub(p[2], p[0])));
        do dir = rand_dir();
        while (fabsf(appm__dot(dir, ng)) < 0.2f);
        o = appm__add(target, appm__scale(dir, size * urange(0.5f, 2.0f)));
        appm__ray_init(&r, o, appm__sub(target, o), FLT_MAX);
        if (!appm__tri_hit(&r, tri, &h)) {
            appm_scene_destroy(ts);
            continue;
        }
        h.tri = 0;
        appm__surface(ts, &h, &sf);
        tris_used++;
        { /* the true unit normal, in double from the float vertices */
            double e1[3], e2[3], l;
            for (k = 0; k < 3; ++k) {
                e1[k] = (double)appm__comp(p[1], k) - appm__comp(p[0], k);
                e2[k] = (double)appm__comp(p[2], k) - appm__comp(p[0], k);
            }
            nt[0] = e1[1] * e2[2] - e1[2] * e2[1];
            nt[1] = e1[2] * e2[0] - e1[0] * e2[2];
            nt[2] = e1[0] * e2[1] - e1[1] * e2[0];
            l = sqrt(nt[0] * nt[0] + nt[1] * nt[1] + nt[2] * nt[2]);
            nt[0] /= l, nt[1] /= l, nt[2] /= l;
        }
        for (j = 0; j < nray; ++j) {
            appm__v3 w, tt, bt;
            appm__ray q;
            appm__hit hh;
            int kind = j % 4;
            if (kind <= 1) { /* uniform on the sphere: both sides */
                w = rand_dir();
            } else if (kind == 2) { /* grazing: 1e-6..1e-1 rad off the plane, either side */
                float a = urange(0.0f, 2.0f * APPM__PIF), e = powf(10.0f, urange(-6.0f, -1.0f));
                appm__basis(ng, &tt, &bt);
                w = appm__normalize(appm__add(appm__add(appm__scale(tt, cosf(a)), appm__scale(bt, sinf(a))),
                                              appm__scale(ng, uf() < 0.5f ? e : -e)));
                grazing++;
            } else { /* towards a random point anywhere (pbrt's SpawnRayTo) */
                appm__v3 to = appm__v(rexp(-6, 6), rexp(-6, 6), rexp(-6, 6));
                w = appm__normalize(appm__sub(to, sf.p));
                if (!(appm__length(w) > 0.5f)) continue;
            }
            o = appm__offset(&sf, w);
            /* The offset origin lies strictly on w's side of the true plane
             * (evaluated in double), unless w is so close to the plane that
             * the float normal cannot tell the sides apart. */
            {
                double od = ((double)o.x - p[0].x) * nt[0] + ((double)o.y - p[0].y) * nt[1] +
                            ((double)o.z - p[0].z) * nt[2];
                double wn = w.x * nt[0] + w.y * nt[1] + w.z * nt[2];
                if (fabs(wn) > 1e-2 && !(od * wn > 0.0)) wrong_side++;
            }
            appm__ray_init(&q, o, w, FLT_MAX);
            rays++;
            /* skip = UINT32_MAX is what this models: the triangle is not excluded */
            if (appm__tri_hit(&q, tri, &hh)) {
                if (rehits++ < 3)
                    fprintf(stderr,
                            "  re-hit: tri (%.9g %.9g %.9g) (%.9g %.9g %.9g) (%.9g %.9g %.9g)\n"
                            "          p = (%.9g %.9g %.9g) w = (%.9g %.9g %.9g) t = %.9g\n",
                            p[0].x, p[0].y, p[0].z, p[1].x, p[1].y, p[1].z, p[2].x, p[2].y, p[2].z, sf.p.x, sf.p.y,
                            sf.p.z, w.x, w.y, w.z, hh.t);
            }
        }
        appm_scene_destroy(ts);
    }
    printf("reintersect: %ld of %ld triangles hit, %ld spawned rays (%ld grazing), %ld re-hits\n", tris_used,
           tris_tried, rays, grazing, rehits);
    /* most can be hit; the thinnest needles only from close by (a ray must
     * resolve their width: the test rejects hits within its rounding error) */
    CHECK_MSG(tris_used >= tris_tried * 3 / 4, "only %ld of %ld triangles could be hit", tris_used, tris_tried);
    CHECK_MSG(wrong_side == 0, "%ld of %ld offset origins on the wrong side of the plane", wrong_side, rays);
    CHECK_MSG(rehits == 0, "%ld of %ld spawned rays hit their own triangle", rehits, rays);
}

/* Scene level: rays from inside closed cubes (tiny, unit, far away) hit a face;
 * from that hit, rays spawned with appm__offset go into the cube and must hit a
 * different face, or out of it and must hit nothing. */
static void reintersect_cube(double cx, double cy, double cz, double a, const char *name)
{
    appm_scene *s = cube(cx, cy, cz, a);
    long i, j, n = check_quick() ? 500 : 3000, rehit = 0, escaped = 0, leaked = 0, spawned = 0, primary_miss = 0;
    long near_edge = 0;
    appm__v3 c = appm__v((float)cx, (float)cy, (float)cz);
    if (!s) return;
    CHECK(s->ntri == 12);
    for (i = 0; i < n; ++i) {
        appm__v3 o = appm__add(c, appm__scale(rand_dir(), (float)(0.4 * a * uf())));
        appm__ray r;
        appm__hit h;
        appm__surf sf;
        appm__ray_init(&r, o, rand_dir(), FLT_MAX);
        if (!appm__intersect(s, &r, UINT32_MAX, &h)) {
            primary_miss++;
            continue;
        }
        appm__surface(s, &h, &sf);
        for (j = 0; j < 20; ++j) {
            appm__v3 w = rand_dir(), out_n = sf.ng;
            appm__ray q;
            appm__hit hh;
            int hit;
            if (appm__dot(out_n, appm__sub(sf.p, c)) < 0) out_n = appm__neg(out_n);
            if (j % 4 == 3) { /* grazing, inwards or outwards */
                appm__v3 tt, bt;
                appm__basis(out_n, &tt, &bt);
                w = appm__normalize(appm__add(tt, appm__scale(out_n, rexp(-6, -2))));
            }
            appm__ray_init(&q, appm__offset(&sf, w), w, FLT_MAX);
            spawned++;
            hit = appm__intersect(s, &q, UINT32_MAX, &hh);
            if (appm__dot(w, out_n) > 0) {
                leaked += hit; /* leaving a convex closed box: nothing to hit */
            } else if (!hit) {
                /* Going in, the ray must hit the box again - unless its origin
                 * is so close to an adjacent face (within the hit point's error
                 * box, or 1e-4 of the edge) that it may lie outside that face. */
                appm__v3 so = appm__offset(&sf, w);
                double m = fmax(1e-4 * a, 4.0 * appm__maxc(sf.err)), inside = HUGE_VAL;
                int ax;
                for (ax = 0; ax < 3; ++ax)
                    inside = fmin(inside, 0.5 * a - fabs((double)appm__comp(so, ax) - appm__comp(c, ax)) +
                                              (fabs(appm__comp(out_n, ax)) > 0.5f ? HUGE_VAL : 0.0));
                if (inside > m) {
                    if (escaped++ < 3)
                        fprintf(stderr, "  %s: escaped: o = (%.9g, %.9g, %.9g) w = (%.9g, %.9g, %.9g)\n", name,
                                so.x, so.y, so.z, w.x, w.y, w.z);
                } else {
                    near_edge++;
                }
            } else if (appm__dot(s->info[hh.tri].ng, sf.ng) > 0.999f &&
                       fabsf(appm__dot(appm__sub(s->tri[hh.tri].p0, sf.p), sf.ng)) < 1e-3f * (float)a) {
                rehit++; /* its own face (the triangle or its coplanar partner) */
            }
        }
    }
    printf("%s: %ld spawned rays, %ld re-hits, %ld escaped (+%ld from next to an edge), %ld leaked\n", name,
           spawned, rehit, escaped, near_edge, leaked);
    CHECK_MSG(primary_miss == 0, "%s: %ld rays from inside missed the cube", name, primary_miss);
    CHECK_MSG(rehit == 0, "%s: %ld spawned rays hit their own face", name, rehit);
    CHECK_MSG(escaped == 0, "%s: %ld inward rays escaped", name, escaped);
    CHECK_MSG(leaked == 0, "%s: %ld outward rays hit the cube", name, leaked);
    appm_scene_destroy(s);
}

static void test_reintersect_scenes(void)
{
    reintersect_cube(0, 0, 0, 1, "cube a=1");
    reintersect_cube(1e5, 1e3, -2e5, 1, "cube a=1 at (1e5,1e3,-2e5)");
    reintersect_cube(1e-3, 2e-3, -1e-3, 1e-4, "cube a=1e-4");
    reintersect_cube(-3e6, 5e5, 1e6, 1e3, "cube a=1e3 at (-3e6,5e5,1e6)");
}

/* ---- 4. Degenerate builds and bad rays ------------------------------------- */

static void aimed_rays(const appm_scene *s, const char *name, long n, int expect_all_hit)
{
    ray_stats st;
    long i, before, aimed = 0, aimed_hits = 0;
    appm__v3 lo = s->bmin, hi = s->bmax, ext = appm__sub(hi, lo), elo, ehi;
    float e = fmaxf(appm__maxc(ext), 1e-3f);
    elo = appm__sub(lo, appm__v(e, e, e));
    ehi = appm__add(hi, appm__v(e, e, e));
    stats_start(&st, name);
    for (i = 0; i < n; ++i) {
        appm__v3 o, d;
        if (i % 2) {
            o = rand_in_box(elo, ehi);
            d = rand_dir();
        } else { /* at an interior point, from 1..10 triangle sizes away */
            const appm__tri *t = &s->tri[appm__rng_u32(&g_rng) % s->ntri];
            float b1 = urange(0.05f, 0.9f), b2 = urange(0.05f, 0.95f - b1), size;
            appm__v3 target = appm__add(t->p0, appm__add(appm__scale(appm__sub(t->p1, t->p0), b1),
                                                         appm__scale(appm__sub(t->p2, t->p0), b2)));
            size = fmaxf(appm__length(appm__sub(t->p1, t->p0)), appm__length(appm__sub(t->p2, t->p0)));
            o = appm__add(target, appm__scale(rand_dir(), size * urange(1.0f, 10.0f)));
            d = appm__sub(target, o);
        }
        before = st.hits;
        compare_ray(s, NULL, o, d, &st, 0);
        if (i % 2 == 0) aimed++, aimed_hits += st.hits - before;
    }
    stats_check(&st, n * 9 / 10);
    /* every aimed ray hits (its target is well inside a triangle) */
    if (expect_all_hit) CHECK_MSG(aimed_hits == aimed, "%s: %ld aimed rays, %ld hits", name, aimed, aimed_hits);
}

static void test_degenerate(void)
{
    int quick = check_quick();
    long n = quick ? 400 : 4000;
    tbuf t = {NULL, 0, 0};
    appm_scene *s;
    int i;
    appm__tri *tris;
    uint32_t k, nchain = 961;

    /* 1e4 copies of one triangle: every centroid equal, SAH has nothing to
     * bin; the build must fall back to median splits, not recurse forever. */
    tputs(&t, "mtllib m.mtl\nusemtl glow\nv 0 0 0\nv 1 0 0\nv 0 1 0.5\n");
    for (i = 0; i < 10000; ++i) tputs(&t, "f 1 2 3\n");
    s = load_text(t.p, EMIT_MTL, "copies.obj");
    free(t.p);
    if (s) {
        printf("10000 copies: %u nodes, depth %u\n", s->nnode, s->depth);
        CHECK(s->ntri == 10000);
        CHECK(s->depth < APPM__BVH_MAX_DEPTH);
        check_wide_tree(s, "copies");
        aimed_rays(s, "copies", n, 1);
        appm_scene_destroy(s);
    }

    s = load_text("mtllib m.mtl\nusemtl glow\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n", EMIT_MTL, "one.obj");
    if (s) {
        CHECK(s->ntri == 1 && s->nnode == 1 && s->depth == 1);
        aimed_rays(s, "single triangle", n, 1);
        appm_scene_destroy(s);
    }

    /* A geometric chain: 8 triangles per octave from x = 2^-60 to 2^60, each
     * of a size proportional to its x.  The SAH bins are uniform, so every
     * split can only peel off the top few octaves: the deepest tree a sane
     * coordinate range allows (about 50 levels), which must stay below the
     * traversal stack's depth. */
    tris = (appm__tri *)malloc(nchain * sizeof *tris);
    if (!tris) abort();
    for (k = 0; k < nchain; ++k) {
        float x = (float)pow(2.0, ((double)k - 480.0) / 8.0);
        tris[k].p0 = appm__v(x, 0, 0);
        tris[k].p1 = appm__v(1.3f * x, 0, 0.3f * x);
        tris[k].p2 = appm__v(x, 0.3f * x, 0.15f * x);
    }
    s = hand_scene(tris, nchain);
    printf("geometric chain: %u triangles, %u nodes, depth %u\n", s->ntri, s->nnode, s->depth);
    CHECK(s->depth < APPM__BVH_MAX_DEPTH);
    check_wide_tree(s, "geometric chain");
    aimed_rays(s, "geometric chain", n, 1);
    hand_free(s);

    /* Zero triangles: an empty tree that every query misses. */
    s = hand_scene(tris, 0);
    {
        appm__ray r;
        appm__hit h;
        appm__ray_init(&r, appm__v(0, 0, 0), appm__v(0, 0, 1), FLT_MAX);
        CHECK(s->nnode == 0);
        CHECK(!appm__intersect(s, &r, UINT32_MAX, &h));
        CHECK(!appm__occluded(s, &r, UINT32_MAX, UINT32_MAX));
    }
    hand_free(s);
    free(tris);
}

static void test_bad_rays(void)
{
    appm_scene *s = uv_sphere(0, 0, 0, 1, 16, 8);
    const float nan = (float)NAN, inf = (float)HUGE_VAL;
    const appm__v3 O[] = {
        {nan, 0, 0},  {0, nan, 0}, {0, 0, nan}, {inf, 0, 0}, {0, -inf, 0}, {0, 0, inf}, {0, 0, 0}, {0, 0, 0},
        {0, 0, 0},    {0, 0, 0},   {0, 0, 0},   {0, 0, 0},   {nan, nan, nan}, {0, 0, 0}, {0, 0, 0}};
    const appm__v3 D[] = {
        {0, 0, 1},    {0, 0, 1},   {1, 0, 0},   {-1, 0, 0},  {0, 1, 0},   {0, 0, -1},  {nan, 0, 0}, {0, nan, 1},
        {inf, 0, 0},  {0, -inf, 1}, {0, 0, 0},  {-0.0f, 0, -0.0f}, {nan, nan, nan}, {inf, inf, inf}, {nan, 1, 0}};
    size_t i, nrays = sizeof O / sizeof O[0];
    if (!s) return;
    for (i = 0; i < nrays; ++i) {
        appm__ray r;
        appm__hit h;
        appm__ray_init(&r, O[i], D[i], FLT_MAX);
        CHECK_MSG(!appm__intersect(s, &r, UINT32_MAX, &h), "bad ray %u reported a hit", (unsigned)i);
        CHECK_MSG(!appm__occluded(s, &r, UINT32_MAX, UINT32_MAX), "bad ray %u reported occlusion", (unsigned)i);
    }
    { /* a good ray with a NaN tmax, and the same ray with tmax = +inf */
        appm__ray r;
        appm__hit h;
        appm__ray_init(&r, appm__v(0, 0, 0), appm__v(0, 0, 1), nan);
        CHECK(!appm__intersect(s, &r, UINT32_MAX, &h));
        CHECK(!appm__occluded(s, &r, UINT32_MAX, UINT32_MAX));
        appm__ray_init(&r, appm__v(0, 0, 0), appm__v(0, 0, 1), inf);
        CHECK(appm__intersect(s, &r, UINT32_MAX, &h));
        CHECK(appm__occluded(s, &r, UINT32_MAX, UINT32_MAX));
    }
    appm_scene_destroy(s);
}

/* ---- 5. pbrt Triangle.BadCases ------------------------------------------------- */

static void test_bad_cases(void)
{
    /* Collinear (same x and z): zero area.  A naive test computes a tiny,
     * rounding-made determinant and reports a hit. */
    appm__tri t;
    appm__ray r;
    appm__hit h;
    t.p0 = appm__v(-1113.45459f, -79.049614f, -56.2431908f);
    t.p1 = appm__v(-1113.45459f, -87.0922699f, -56.2431908f);
    t.p2 = appm__v(-1113.45459f, -79.2090149f, -56.2431908f);
    appm__ray_init(&r, appm__v(-1081.47925f, 99.9999542f, 87.7701111f),
                   appm__v(-32.1072998f, -183.355865f, -144.607635f), (float)HUGE_VAL);
    CHECK(r.valid);
    CHECK_MSG(!appm__tri_hit(&r, &t, &h), "zero-area triangle hit at t = %.9g", h.t);
    /* the same, with the vertices in every order */
    {
        appm__tri u;
        u.p0 = t.p1, u.p1 = t.p2, u.p2 = t.p0;
        CHECK(!appm__tri_hit(&r, &u, &h));
        u.p0 = t.p2, u.p1 = t.p1, u.p2 = t.p0;
        CHECK(!appm__tri_hit(&r, &u, &h));
    }
}

int main(void)
{
    int round;
    printf("box test: %s, %d-wide tree\n", APPM__SIMD_NAME, APPM__BVH_W);
    for (round = 0; round < 2; ++round) {
        g_path = round ? APPM__BVH_SCALAR : APPM__BVH_SIMD;
        printf("-- %s box test --\n", round ? "scalar" : "SIMD");
        appm__rng_seed(&g_rng, 1, 0, APPM__DOMAIN_TEST, 1);
        test_bad_cases();
        test_bad_rays();
        test_degenerate();
        test_reintersect();
        test_reintersect_scenes();
        test_watertight();
        test_bvh_vs_brute();
    }
    return check_finish();
}
