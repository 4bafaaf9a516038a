/* tests/t_pmap.c - the photon map (appm.c section 7.2) and the photon record.
 *
 * What is checked, and against what:
 *   1. Query == linear scan.  appm__pmap_query must visit exactly the photons
 *      a plain loop over the array finds with |x - y|^2 < R^2 (the same float
 *      expression), each once: the visited set is sorted and compared with the
 *      scan's; the squared distance it hands each visit must be the scan's,
 *      bit for bit (the gather uses it in place of its own, and the query's
 *      four-wide test must agree with the scalar expression), and the photons
 *      must come in map order (increasing index: the order the gather sums in).  Cases: random photon clouds and random points and radii; radius
 *      0; radii larger than the whole grid (the scan path); query points and
 *      photons exactly on cell boundaries; radii that reach exactly one cell
 *      further; the empty map; all photons in one cell; duplicate positions;
 *      a tiny table where many cells share a bucket.  An off-by-one in the cell
 *      range (a `<` for `<=`, a missing cell at either end) drops the photons
 *      of the last or first cell and fails here.
 *   2. The build's invariants: the photons are a permutation of the input;
 *      every photon in [cell[b], cell[b+1]) hashes to bucket b; within a
 *      bucket the input order (or the order of the runs given) is kept, which
 *      is what makes sums over photons independent of the thread count.  The
 *      hot position arrays repeat each photon's position, side[] holds
 *      appm__photon_side of each, in map order, and every photon lies in its
 *      bucket's bounding box (a box too small would drop photons from queries,
 *      which (1) catches too).
 *   3. The photon record: the octahedral encoding round-trips (16-bit wi to
 *      within 1e-4 rad, 8-bit normals to within 2e-2 rad, the axes exactly), and
 *      appm__store_photon keeps the incident direction that glossy gathering
 *      will need.
 */
#include "../appm.c"
#include "check.h"

static appm__rng g_rng;

static float pmap_uf(void) { return appm__rng_float(&g_rng); }

typedef struct visit_log {
    const appm__photon *base;
    size_t *idx;
    size_t n, cap;
    int overflow;
    appm__v3 x;      /* the query point */
    int d2_ok;       /* every d2 handed over equals the scan's expression */
    int ordered;     /* indices came in increasing order (small queries: map order) */
} visit_log;

static void log_visit(void *ctx, const appm__photon *p, float d2)
{
    visit_log *v = (visit_log *)ctx;
    float dx = v->x.x - p->x, dy = v->x.y - p->y, dz = v->x.z - p->z, e2 = dx * dx + dy * dy + dz * dz;
    size_t i = (size_t)(p - v->base);
    v->d2_ok &= memcmp(&e2, &d2, sizeof d2) == 0;
    if (v->n > 0 && v->idx[v->n - 1] >= i) v->ordered = 0;
    if (v->n < v->cap) v->idx[v->n++] = i;
    else v->overflow = 1;
}

static void log_init(visit_log *v, const appm__pmap *m, size_t *buf, size_t cap, appm__v3 x)
{
    v->base = m->ph;
    v->idx = buf;
    v->n = 0;
    v->cap = cap;
    v->overflow = 0;
    v->x = x;
    v->d2_ok = 1;
    v->ordered = 1;
}

static int cmp_size(const void *a, const void *b)
{
    size_t x = *(const size_t *)a, y = *(const size_t *)b;
    return x < y ? -1 : x > y;
}

static appm__photon make_photon(float x, float y, float z, float tag)
{
    appm__photon p;
    memset(&p, 0, sizeof p);
    p.x = x;
    p.y = y;
    p.z = z;
    p.power[0] = tag; /* the photon's index in the input, to check orders */
    p.n[0] = (int8_t)((int)tag % 255 - 127); /* some normal, for side[] */
    p.n[1] = (int8_t)(((int)tag * 37) % 255 - 127);
    return p;
}

/* Queries (x, R) on map m and compares with the linear scan over m->ph.
 * Returns 1 when both give the same set; on a mismatch prints the case. */
static int same_as_scan(const appm__pmap *m, appm__v3 x, float R, size_t *buf_a, size_t *buf_b, const char *what)
{
    visit_log v;
    size_t i, ns = 0;
    float R2 = R * R;
    log_init(&v, m, buf_a, m->n + 1, x);
    appm__pmap_query(m, x, R, log_visit, &v);
    if (!v.d2_ok) {
        fprintf(stderr, "%s: query (%.9g %.9g %.9g) R %.9g: a visit got a d2 other than the scan's\n", what, x.x,
                x.y, x.z, R);
        return 0;
    }
    for (i = 0; i < m->n; ++i) {
        const appm__photon *p = &m->ph[i];
        float dx = x.x - p->x, dy = x.y - p->y, dz = x.z - p->z;
        if (dx * dx + dy * dy + dz * dz < R2) buf_b[ns++] = i;
    }
    qsort(buf_a, v.n, sizeof *buf_a, cmp_size);
    if (!v.overflow && v.n == ns && (ns == 0 || memcmp(buf_a, buf_b, ns * sizeof *buf_a) == 0)) return 1;
    fprintf(stderr, "%s: query (%.9g %.9g %.9g) R %.9g: map visited %lu photons, scan finds %lu\n", what, x.x, x.y,
            x.z, R, (unsigned long)v.n, (unsigned long)ns);
    return 0;
}

/* Builds a map over ph[0..n) (copied, so the caller's order is kept). */
static appm__photon *build(appm__pmap *m, appm__mem *mem, const appm__photon *src, size_t n, float cell,
                           const appm__chunk_rec *runs, uint32_t nruns)
{
    appm__photon *ph = (appm__photon *)malloc((n ? n : 1) * sizeof *ph);
    uint32_t *dest = (uint32_t *)malloc((n ? n : 1) * sizeof *dest);
    appm_status st;
    if (!ph || !dest) {
        free(ph);
        free(dest);
        return NULL;
    }
    if (n) memcpy(ph, src, n * sizeof *ph);
    st = appm__pmap_build(m, mem, ph, n, dest, runs, nruns, cell);
    free(dest);
    CHECK(st == APPM_OK);
    return ph;
}

/* The build's invariants (2) on map m built from src[0..n) in input order. */
static void check_build(const appm__pmap *m, size_t n, const char *what)
{
    size_t i, nb = (size_t)1 << m->bits;
    int bucket_ok = 1, order_ok = 1, perm_ok = 1, hot_ok = 1, box_ok = 1;
    unsigned char *seen = (unsigned char *)calloc(n ? n : 1, 1);
    CHECK(m->n == n && m->cell[0] == 0 && m->cell[nb] == n);
    for (i = 0; i < n; ++i) {
        float side[4];
        appm__photon_side(&m->ph[i], side);
        hot_ok &= m->hot[i] == m->ph[i].x && m->hot[m->hot_cap + i] == m->ph[i].y &&
                  m->hot[2 * m->hot_cap + i] == m->ph[i].z && memcmp(side, m->side + 4 * i, sizeof side) == 0;
    }
    CHECK_MSG(hot_ok, "%s: the hot positions or side[] do not repeat the photons in map order", what);
    for (i = 0; i < nb; ++i) {
        size_t k;
        for (k = m->cell[i]; k < m->cell[i + 1]; ++k) {
            const float *bb = m->bbox + 6 * i;
            bucket_ok &= appm__pmap_bucket(m, &m->ph[k]) == i;
            box_ok &= bb[0] <= m->ph[k].x && m->ph[k].x <= bb[3] && bb[1] <= m->ph[k].y && m->ph[k].y <= bb[4] &&
                      bb[2] <= m->ph[k].z && m->ph[k].z <= bb[5];
            if (k > m->cell[i]) order_ok &= m->ph[k - 1].power[0] < m->ph[k].power[0];
        }
    }
    for (i = 0; seen && i < n; ++i) {
        size_t t = (size_t)m->ph[i].power[0];
        if (t < n && !seen[t]) seen[t] = 1;
        else perm_ok = 0;
    }
    CHECK_MSG(bucket_ok, "%s: a photon lies outside its bucket's range", what);
    CHECK_MSG(box_ok, "%s: a photon lies outside its bucket's bounding box", what);
    CHECK_MSG(order_ok, "%s: the input order is not kept within a bucket", what);
    CHECK_MSG(perm_ok && seen, "%s: the map's photons are not a permutation of the input", what);
    free(seen);
}

/* Random clouds, points and radii: (1) and (2). */
static void test_random(appm__mem *mem)
{
    const int sets = check_quick() ? 6 : 20, queries = check_quick() ? 300 : 1000;
    int s, bad = 0, total = 0;
    for (s = 0; s < sets; ++s) {
        size_t n = (size_t)(1 + appm__rng_u32(&g_rng) % 3000), i;
        float spread = s % 3 == 0 ? 1.0f : (s % 3 == 1 ? 100.0f : 1e-3f);
        float cell = spread * (0.01f + 0.3f * pmap_uf());
        appm__photon *src = (appm__photon *)malloc(n * sizeof *src), *ph;
        size_t *a = (size_t *)malloc((n + 1) * sizeof *a), *b = (size_t *)malloc((n + 1) * sizeof *b);
        appm__pmap m;
        int q;
        memset(&m, 0, sizeof m);
        if (!src || !a || !b) {
            CHECK(!"out of memory");
            free(src), free(a), free(b);
            return;
        }
        for (i = 0; i < n; ++i) /* a flat cluster (a wall) mixed with a volume */
            src[i] = make_photon(spread * pmap_uf(), i % 2 ? spread * pmap_uf() : 0.25f * spread, spread * pmap_uf(), (float)i);
        ph = build(&m, mem, src, n, cell, NULL, 0);
        if (!ph) break;
        check_build(&m, n, "random cloud");
        for (q = 0; q < queries; ++q) {
            appm__v3 x;
            float R;
            int kind = q % 5;
            if (kind == 0) { /* at a photon */
                const appm__photon *p = &m.ph[appm__rng_u32(&g_rng) % n];
                x = appm__v(p->x, p->y, p->z);
            } else {
                x = appm__v(spread * (1.2f * pmap_uf() - 0.1f), spread * (1.2f * pmap_uf() - 0.1f),
                            spread * (1.2f * pmap_uf() - 0.1f));
            }
            if (kind == 3) { /* on a cell boundary, in every coordinate */
                x.x = m.lo.x + cell * (float)(appm__rng_u32(&g_rng) % 8);
                x.y = m.lo.y + cell * (float)(appm__rng_u32(&g_rng) % 8);
                x.z = m.lo.z + cell * (float)(appm__rng_u32(&g_rng) % 8);
            }
            R = kind == 1 ? 0.0f
                          : (kind == 2 ? spread * 3.0f * pmap_uf() /* often larger than the whole grid */
                                       : cell * (0.05f + 3.0f * pmap_uf()));
            if (kind == 4) R = cell * (float)(1 + appm__rng_u32(&g_rng) % 3); /* to exactly a cell boundary */
            total++;
            bad += !same_as_scan(&m, x, R, a, b, "random cloud");
        }
        free(ph);
        free(src), free(a), free(b);
        appm__pmap_free(&m, mem);
    }
    CHECK_MSG(bad == 0, "%d of %d queries differ from the linear scan", bad, total);
}

/* Lattices of photons exactly on cell corners, queried at lattice points with
 * radii of whole cells: every photon sits on the boundary of eight cells. */
static void test_lattice(appm__mem *mem)
{
    enum { K = 9 };
    appm__photon src[K * K * K], *ph;
    size_t a[K * K * K + 1], b[K * K * K + 1];
    appm__pmap m;
    int i, j, k, bad = 0, total = 0;
    const float cell = 0.25f;
    memset(&m, 0, sizeof m);
    for (i = 0; i < K; ++i)
        for (j = 0; j < K; ++j)
            for (k = 0; k < K; ++k) src[(i * K + j) * K + k] = make_photon(cell * i, cell * j, cell * k, (float)((i * K + j) * K + k));
    ph = build(&m, mem, src, K * K * K, cell, NULL, 0);
    if (!ph) return;
    check_build(&m, K * K * K, "lattice");
    for (i = 0; i < K; ++i)
        for (j = 0; j < K; j += 2) {
            float R;
            for (R = 0.0f; R <= 4.0f * cell; R += 0.5f * cell) {
                appm__v3 x = appm__v(cell * i, cell * j, cell * ((i + j) % K));
                total++;
                bad += !same_as_scan(&m, x, R, a, b, "lattice");
                x.x += 0.5f * cell; /* halfway: the box ends on a boundary */
                total++;
                bad += !same_as_scan(&m, x, R + 1e-3f, a, b, "lattice");
            }
        }
    CHECK_MSG(bad == 0, "%d of %d lattice queries differ from the linear scan", bad, total);
    free(ph);
    appm__pmap_free(&m, mem);
}

/* The empty map, one cell holding everything, duplicates, a tiny table. */
static void test_degenerate_maps(appm__mem *mem)
{
    enum { N = 2000 };
    static appm__photon src[N];
    static size_t a[N + 1], b[N + 1];
    appm__photon *ph;
    appm__pmap m;
    int i, bad = 0;
    memset(&m, 0, sizeof m);
    /* empty */
    ph = build(&m, mem, src, 0, 1.0f, NULL, 0);
    if (ph) {
        CHECK(m.n == 0);
        CHECK(same_as_scan(&m, appm__v(0, 0, 0), 10.0f, a, b, "empty"));
        free(ph);
    }
    /* all in one cell of size 1, a query from a neighbouring cell */
    for (i = 0; i < N; ++i) src[i] = make_photon(0.5f + 0.4f * pmap_uf(), 0.5f + 0.4f * pmap_uf(), 0.5f + 0.4f * pmap_uf(), (float)i);
    ph = build(&m, mem, src, N, 1.0f, NULL, 0);
    if (ph) {
        check_build(&m, N, "one cell");
        for (i = 0; i < 200; ++i)
            bad += !same_as_scan(&m, appm__v(2.0f * pmap_uf() - 0.5f, 2.0f * pmap_uf() - 0.5f, 1.5f * pmap_uf()), 0.6f * pmap_uf(), a, b,
                                 "one cell");
        free(ph);
    }
    /* duplicates: 500 photons at each of 4 points, queried at the points
     * (d = 0 < R) and at R exactly the distance to a neighbour (excluded) */
    for (i = 0; i < N; ++i) src[i] = make_photon((float)(i % 4) * 0.5f, 0.0f, 0.0f, (float)i);
    ph = build(&m, mem, src, N, 0.3f, NULL, 0);
    if (ph) {
        visit_log v;
        check_build(&m, N, "duplicates");
        for (i = 0; i < 4; ++i) {
            bad += !same_as_scan(&m, appm__v(0.5f * (float)i, 0, 0), 0.5f, a, b, "duplicates");
            bad += !same_as_scan(&m, appm__v(0.5f * (float)i, 0, 0), 0.0f, a, b, "duplicates");
        }
        log_init(&v, &m, a, N + 1, appm__v(0.5f, 0, 0));
        appm__pmap_query(&m, appm__v(0.5f, 0, 0), 0.5f, log_visit, &v);
        CHECK_MSG(v.ordered, "duplicates: one bucket's photons not visited in map order");
        CHECK_MSG(v.n == 500, "duplicates: %lu photons within 0.5 of a point holding 500, expected 500",
                  (unsigned long)v.n);
        free(ph);
    }
    /* a map of 3 photons has 2^10 buckets; with cells of 1e-3 a query of radius
     * 0.05 spans 1e6 cells, more than the table: the scan path */
    for (i = 0; i < 3; ++i) src[i] = make_photon(0.01f * (float)i, 0.0f, 0.0f, (float)i);
    ph = build(&m, mem, src, 3, 1e-3f, NULL, 0);
    if (ph) {
        bad += !same_as_scan(&m, appm__v(0, 0, 0), 0.05f, a, b, "tiny table");
        bad += !same_as_scan(&m, appm__v(0, 0, 0), 0.015f, a, b, "tiny table");
        free(ph);
    }
    CHECK_MSG(bad == 0, "%d degenerate queries differ from the linear scan", bad);
    appm__pmap_free(&m, mem);
}

/* Runs: the second half is listed first, so within a bucket its photons must
 * come before those of the first half. */
static void test_runs(appm__mem *mem)
{
    enum { N = 3000 };
    static appm__photon src[N];
    appm__chunk_rec runs[2];
    appm__photon *ph;
    appm__pmap m;
    size_t i, nb;
    int ok = 1, mixed = 0;
    memset(&m, 0, sizeof m);
    for (i = 0; i < N; ++i) src[i] = make_photon(pmap_uf(), pmap_uf(), 0.0f, (float)i);
    runs[0].start = N / 2;
    runs[0].count = N - N / 2;
    runs[1].start = 0;
    runs[1].count = N / 2;
    ph = build(&m, mem, src, N, 0.2f, runs, 2);
    if (!ph) return;
    nb = (size_t)1 << m.bits;
    for (i = 0; i < nb; ++i) {
        size_t k;
        for (k = m.cell[i] + 1; k < m.cell[i + 1]; ++k) {
            float p = m.ph[k - 1].power[0], q = m.ph[k].power[0];
            int hp = p >= N / 2, hq = q >= N / 2;
            mixed |= hp != hq;
            ok &= hp == hq ? p < q : hp && !hq;
        }
    }
    CHECK_MSG(ok, "runs: the order of the runs is not kept within a bucket");
    CHECK(mixed); /* the check above saw buckets holding both halves */
    free(ph);
    appm__pmap_free(&m, mem);
}

static double angle(appm__v3 a, appm__v3 b)
{
    double d = (double)a.x * b.x + (double)a.y * b.y + (double)a.z * b.z;
    double la = sqrt((double)a.x * a.x + (double)a.y * a.y + (double)a.z * a.z);
    double lb = sqrt((double)b.x * b.x + (double)b.y * b.y + (double)b.z * b.z);
    d /= la * lb;
    return acos(d > 1.0 ? 1.0 : (d < -1.0 ? -1.0 : d));
}

/* (3) the photon record's directions */
static void test_octahedral(void)
{
    static const float axes[6][3] = {{1, 0, 0}, {-1, 0, 0}, {0, 1, 0}, {0, -1, 0}, {0, 0, 1}, {0, 0, -1}};
    double worst_wi = 0.0, worst_n = 0.0;
    int i, axes_ok = 1;
    appm_renderer r;
    appm__photon store[4];
    uint32_t used = 0;
    for (i = 0; i < 20000; ++i) {
        double z = 1.0 - 2.0 * pmap_uf(), s = sqrt(fmax(0.0, 1.0 - z * z)), ph = 2.0 * APPM__PI * pmap_uf(), e;
        appm__v3 v = appm__v((float)(s * cos(ph)), (float)(s * sin(ph)), (float)z);
        appm__photon p;
        float a, b;
        memset(&p, 0, sizeof p);
        appm__oct_encode(v, &a, &b);
        p.wi[0] = (int16_t)appm__quant(a, 32767.0f);
        p.wi[1] = (int16_t)appm__quant(b, 32767.0f);
        p.n[0] = (int8_t)appm__quant(a, 127.0f);
        p.n[1] = (int8_t)appm__quant(b, 127.0f);
        e = angle(appm__photon_wi(&p), v);
        if (e > worst_wi) worst_wi = e;
        e = angle(appm__photon_normal(&p), v);
        if (e > worst_n) worst_n = e;
    }
    CHECK_MSG(worst_wi < 1e-4, "16-bit octahedral wi: worst error %.3g rad", worst_wi);
    CHECK_MSG(worst_n < 2e-2, "8-bit octahedral normal: worst error %.3g rad", worst_n);
    CHECK(worst_wi > 0.0); /* quantised: not exact everywhere */
    for (i = 0; i < 6; ++i) {
        appm__v3 v = appm__v(axes[i][0], axes[i][1], axes[i][2]), w;
        appm__photon p;
        float a, b;
        memset(&p, 0, sizeof p);
        appm__oct_encode(v, &a, &b);
        p.wi[0] = (int16_t)appm__quant(a, 32767.0f);
        p.wi[1] = (int16_t)appm__quant(b, 32767.0f);
        w = appm__photon_wi(&p);
        axes_ok &= w.x == v.x && w.y == v.y && w.z == v.z;
    }
    CHECK_MSG(axes_ok, "an axis does not round-trip exactly");
    /* appm__store_photon keeps wi and the normal on wi's side */
    memset(&r, 0, sizeof r);
    r.ph = store;
    r.cap = 4;
    r.task_used = &used;
    {
        appm__surf sf;
        appm__v3 wi = appm__normalize(appm__v(0.3f, -0.5f, -0.8f));
        memset(&sf, 0, sizeof sf);
        sf.p = appm__v(1, 2, 3);
        sf.ng = appm__v(0, 0, 1); /* wi arrives from below: the stored normal is -z */
        CHECK(appm__store_photon(&r, 0, &sf, wi, appm__v(1, 2, 3), 5) == 1);
        CHECK(used == 1 && store[0].x == 1.0f && store[0].z == 3.0f && store[0].segs == 5);
        CHECK(angle(appm__photon_wi(&store[0]), wi) < 1e-4);
        CHECK(angle(appm__photon_normal(&store[0]), appm__v(0, 0, -1)) < 2e-2);
        used = 4;
        CHECK(appm__store_photon(&r, 0, &sf, wi, appm__v(1, 2, 3), 5) == 0); /* full region */
    }
}

int main(void)
{
    appm__mem mem;
    appm__mem_init(&mem, NULL);
    appm__rng_seed(&g_rng, 12345, 0, APPM__DOMAIN_TEST, 0);
    test_random(&mem);
    test_lattice(&mem);
    test_degenerate_maps(&mem);
    test_runs(&mem);
    test_octahedral();
    CHECK_MSG(mem.live == 0, "%lld bytes of map tables not freed", (long long)mem.live);
    return check_finish();
}
