/* tests/t_alloc.c - out-of-memory behaviour, the SQLite "fail the Nth
 * allocation" method.
 *
 * For each API call that allocates, the call is repeated with allocation
 * number 1, 2, 3, ... failing, until a run gets through.  Every failing run
 * must return APPM_ERR_NOMEM and give back every byte it took (the counting
 * allocator's live byte count returns to 0): a single leak on any of the error
 * paths shows up as a non-zero count at exactly that N.  The run that succeeds
 * must then release everything on destroy.
 *
 * Checkpoints: the file calls fail cleanly at each of their allocations; the
 * buffer calls allocate nothing.
 *
 * The allocation wrapper itself is tested for the overflow of count * size
 * (a classic way to turn a huge request into a tiny block) and for zeroing. */
#include "../appm.c"
#include "check.h"

/* ---- the wrapper ------------------------------------------------------------ */

/* An allocator that hands out memory full of 0xA5 (so zeroing is visible),
 * refuses absurd sizes and records the sizes it saw. */
typedef struct dirty_alloc {
    long calls, frees;
    size_t last_alloc, last_free;
    long fail_at; /* 1-based; 0 = never */
} dirty_alloc;

static void *dirty_alloc_fn(void *user, size_t n)
{
    dirty_alloc *a = (dirty_alloc *)user;
    void *p;
    a->calls++;
    a->last_alloc = n;
    if (a->fail_at > 0 && a->calls == a->fail_at) return NULL;
    if (n > ((size_t)1 << 30)) return NULL;
    p = malloc(n);
    if (p) memset(p, 0xA5, n);
    return p;
}

static void dirty_free_fn(void *user, void *p, size_t n)
{
    dirty_alloc *a = (dirty_alloc *)user;
    a->frees++;
    a->last_free = n;
    free(p);
}

static void test_wrapper(void)
{
    appm_config cfg;
    dirty_alloc da;
    appm__mem m;
    appm_diag d;
    unsigned char *p;
    size_t i;
    int zero = 1;
    memset(&cfg, 0, sizeof cfg);
    memset(&da, 0, sizeof da);
    cfg.allocator.alloc = dirty_alloc_fn;
    cfg.allocator.free = dirty_free_fn;
    cfg.allocator.user = &da;
    appm__mem_init(&m, &cfg);
    appm__diag_clear(&d);
    m.diag = &d;

    /* count * size beyond SIZE_MAX: refused before the hook is asked */
    CHECK(appm__alloc(&m, SIZE_MAX / 2, 4) == NULL);
    CHECK(d.status == APPM_ERR_NOMEM);
    CHECK(da.calls == 0);
    CHECK(m.live == 0);
    /* the product that wraps around to a tiny number is the dangerous one:
     * (SIZE_MAX / 3 + 2) * 3 == 3 (mod 2^N) */
    appm__diag_clear(&d);
    CHECK(appm__alloc(&m, SIZE_MAX / 3 + 2, 3) == NULL);
    CHECK(d.status == APPM_ERR_NOMEM && da.calls == 0);
    /* the header is counted as well: just below SIZE_MAX overflows with it */
    appm__diag_clear(&d);
    CHECK(appm__alloc(&m, SIZE_MAX - 8, 1) == NULL);
    CHECK(d.status == APPM_ERR_NOMEM && da.calls == 0);
    CHECK(appm__alloc(&m, SIZE_MAX / 8, 8) == NULL && da.calls == 0);
    /* a request that fits size_t but the allocator refuses: NOMEM too */
    appm__diag_clear(&d);
    CHECK(appm__alloc(&m, (size_t)1 << 31, 1) == NULL);
    CHECK(d.status == APPM_ERR_NOMEM && da.calls == 1);
    CHECK(m.live == 0);

    /* zeroed memory, and the free hook receives the size the alloc hook got */
    p = (unsigned char *)appm__alloc(&m, 100, 8);
    CHECK(p != NULL);
    if (p) {
        for (i = 0; i < 800; ++i) zero &= p[i] == 0;
        CHECK_MSG(zero, "appm__alloc returned memory that is not zeroed");
        CHECK(da.last_alloc >= 800);
        CHECK(m.live == da.last_alloc);
        appm__free(&m, p);
        CHECK(da.last_free == da.last_alloc);
        CHECK(m.live == 0);
    }
    appm__free(&m, NULL); /* freeing NULL is a no-op, as free(NULL) */
    CHECK(da.frees == 1);

    /* growable arrays: pushed slots are zeroed; a failed growth keeps the
     * array as it was */
    {
        appm__array arr;
        int k, ok = 1;
        uint64_t *slot;
        appm__array_init(&arr, sizeof(uint64_t));
        for (k = 0; k < 16; ++k) {
            slot = (uint64_t *)appm__array_push(&m, &arr);
            CHECK(slot != NULL);
            if (!slot) break;
            ok &= *slot == 0;
            *slot = (uint64_t)k * 3u;
        }
        CHECK(ok);
        CHECK(arr.count == 16 && arr.cap == 16);
        da.fail_at = da.calls + 1; /* the growth to 32 fails */
        CHECK(appm__array_push(&m, &arr) == NULL);
        CHECK(arr.count == 16 && arr.cap == 16);
        ok = 1;
        for (k = 0; k < 16; ++k) ok &= ((uint64_t *)arr.data)[k] == (uint64_t)k * 3u;
        CHECK(ok);
        da.fail_at = 0;
        slot = (uint64_t *)appm__array_push(&m, &arr); /* and it can grow later */
        CHECK(slot != NULL && *slot == 0 && arr.count == 17 && arr.cap == 32);
        appm__array_free(&m, &arr);
        CHECK(m.live == 0);
    }
}

/* ---- scene loading ---------------------------------------------------------- */

/* Loads either a file (obj == NULL) or OBJ/MTL text, or (files != NULL) a
 * .scene text in obj with its two files, failing allocation 1, 2, ... until a
 * load succeeds. */
static void fail_each_load(const char *what, const char *path, const char *obj, size_t obj_len,
                           const char *mtl, size_t mtl_len, const appm_memory_file *files)
{
    long n;
    int leaks = 0, wrong = 0;
    appm_config cfg;
    check_alloc a;
    appm_scene *s = NULL;
    appm_diag d;
    appm_status st = APPM_ERR_NOMEM;
    for (n = 1; n < 100000; ++n) {
        memset(&cfg, 0, sizeof cfg);
        check_use_alloc(&cfg, &a, n);
        s = (appm_scene *)&cfg; /* must be cleared on failure */
        st = files ? appm_scene_load_memory(obj, obj_len, path, files, 2, &cfg, &s, &d)
             : obj ? appm_scene_load_obj_memory(obj, obj_len, mtl, mtl_len, path, &cfg, &s, &d)
                   : appm_scene_load(path, &cfg, &s, &d);
        if (st == APPM_OK) break;
        if (st != APPM_ERR_NOMEM || d.status != APPM_ERR_NOMEM || s != NULL || a.count < n) {
            if (!wrong++)
                fprintf(stderr, "%s: failing allocation %ld: status %d, diag %d '%s', %ld allocations\n", what,
                        n, (int)st, (int)d.status, d.message, a.count);
        }
        if (a.live != 0) {
            if (!leaks++) fprintf(stderr, "%s: failing allocation %ld leaks %lld bytes\n", what, n, a.live);
        }
    }
    CHECK_MSG(wrong == 0, "%s: %d runs returned something else than a clean APPM_ERR_NOMEM", what, wrong);
    CHECK_MSG(leaks == 0, "%s: %d failing runs leaked", what, leaks);
    CHECK_MSG(st == APPM_OK, "%s: never loaded: %s", what, d.message);
    CHECK_MSG(n > 10, "%s: only %ld allocations: the loop tested little", what, n - 1);
    /* the successful run made n - 1 allocations (the n-th never came) */
    CHECK(a.count == n - 1);
    if (st == APPM_OK) {
        appm_scene_info in;
        appm_scene_get_info(s, &in);
        CHECK(in.triangles > 0);
        /* the scene's own accounting agrees with the allocator's */
        CHECK_MSG(in.memory_bytes == (uint64_t)a.live, "%s: scene says %llu bytes, allocator %lld", what,
                  (unsigned long long)in.memory_bytes, a.live);
        CHECK(in.peak_bytes == (uint64_t)a.peak);
        appm_scene_destroy(s);
        CHECK_MSG(a.live == 0, "%s: destroy left %lld bytes", what, a.live);
    }
}

static void test_scene_loads(void)
{
    size_t olen, mlen;
    char *obj = (char *)check_read_file("scenes/CornellBox-Original.obj", &olen);
    char *mtl = (char *)check_read_file("scenes/CornellBox-Original.mtl", &mlen);
    size_t slen;
    char *scene = (char *)check_read_file("scenes/cornell-original.scene", &slen);
    fail_each_load("cornell-sphere.scene", "scenes/cornell-sphere.scene", NULL, 0, NULL, 0, NULL);
    fail_each_load("CornellBox-Glossy.obj", "scenes/CornellBox-Glossy.obj", NULL, 0, NULL, 0, NULL);
    CHECK(obj && mtl && scene);
    if (obj && mtl) fail_each_load("obj in memory", "CornellBox-Original.obj", obj, olen, mtl, mlen, NULL);
    if (obj && mtl && scene) {
        appm_memory_file files[2];
        files[0].name = "CornellBox-Original.obj";
        files[0].text = obj;
        files[0].len = olen;
        files[1].name = "CornellBox-Original.mtl";
        files[1].text = mtl;
        files[1].len = mlen;
        fail_each_load(".scene in memory", "cornell-original.scene", scene, slen, NULL, 0, files);
    }
    free(obj);
    free(mtl);
    free(scene);
    /* a scene with point, spot and environment lights and no area light */
    {
        const char *path = check_path("alloc", "lights.scene");
        CHECK(check_write_file(path, "mesh ../fixtures/no-light.obj\n"
                                     "light point position 0 1 0 intensity 1 1 1\n"
                                     "light spot position 0 5 0 target 0 0 0 intensity 1 1 1 cone 20 falloff 5\n"
                                     "environment 0.1 0.1 0.1\n"));
        fail_each_load("lights.scene", path, NULL, 0, NULL, 0, NULL);
    }
}

/* ---- rendering ---------------------------------------------------------------- */

static void render_cfg(appm_config *cfg, appm_method method)
{
    memset(cfg, 0, sizeof *cfg);
    cfg->width = 32;
    cfg->height = 32;
    cfg->photons = (uint64_t)check_count(20000, 4000); /* every allocation path, fewer photons quick */
    cfg->threads = 2;
    cfg->method = method;
}

static void test_renderer(const appm_scene *scene, appm_method method, const char *what)
{
    long n, k;
    int bad = 0;
    appm_config cfg;
    check_alloc a;
    appm_renderer *r = NULL;
    appm_diag d;
    appm_status st = APPM_ERR_NOMEM;
    long create_allocs;

    /* appm_renderer_create */
    for (n = 1; n < 1000; ++n) {
        render_cfg(&cfg, method);
        check_use_alloc(&cfg, &a, n);
        r = (appm_renderer *)&cfg;
        st = appm_renderer_create(scene, &cfg, &r, &d);
        if (st == APPM_OK) break;
        if (st != APPM_ERR_NOMEM || r != NULL || a.live != 0 || d.status != APPM_ERR_NOMEM) {
            if (!bad++)
                fprintf(stderr, "%s: create, failing allocation %ld: status %d, %lld bytes left\n", what, n,
                        (int)st, a.live);
        }
    }
    CHECK_MSG(bad == 0, "%s: %d failing creates were not clean", what, bad);
    CHECK(st == APPM_OK && n > 3);
    create_allocs = a.count;
    if (st == APPM_OK) {
        appm_renderer_destroy(r);
        CHECK(a.live == 0);
    }

    /* appm_renderer_pass: allocation create_allocs + k fails, k = 1, 2, ... */
    bad = 0;
    for (k = 1; k < 1000; ++k) {
        render_cfg(&cfg, method);
        check_use_alloc(&cfg, &a, 0);
        st = appm_renderer_create(scene, &cfg, &r, &d);
        CHECK(st == APPM_OK);
        if (st != APPM_OK) return;
        CHECK(a.count == create_allocs);
        a.fail_at = a.count + k;
        st = appm_renderer_pass(r);
        if (st == APPM_OK) {
            appm_stats stats;
            appm_image img;
            appm_renderer_stats(r, &stats);
            CHECK(stats.passes == 1);
            /* the pass allocated k - 1 blocks; the renderer accounts for all */
            CHECK(a.count == create_allocs + k - 1);
            CHECK(stats.memory_bytes == (uint64_t)a.live);
            appm_renderer_image(r, &img);
            CHECK(img.rgb != NULL && img.width == 32);
            appm_renderer_destroy(r);
            CHECK(a.live == 0);
            break;
        }
        if (st != APPM_ERR_NOMEM || appm_renderer_last_error(r)[0] == 0) {
            if (!bad++)
                fprintf(stderr, "%s: pass, failing allocation %ld of the pass: status %d, '%s'\n", what, k,
                        (int)st, appm_renderer_last_error(r));
        }
        {
            appm_stats stats;
            appm_renderer_stats(r, &stats);
            if (stats.passes != 0 && !bad++) fprintf(stderr, "%s: a failed pass was counted\n", what);
        }
        appm_renderer_destroy(r);
        if (a.live != 0 && !bad++) fprintf(stderr, "%s: pass failure %ld: %lld bytes left\n", what, k, a.live);
    }
    CHECK_MSG(bad == 0, "%s: %d failing passes were not clean", what, bad);
    CHECK_MSG(st == APPM_OK, "%s: the pass never succeeded", what);
    if (method == APPM_METHOD_PT)
        CHECK_MSG(k == 1, "%s: a path-tracing pass allocated %ld blocks (it needs none)", what, k - 1);
    else /* the first photon pass builds its grid */
        CHECK_MSG(k > 1, "%s: the pass allocated nothing: the loop tested nothing", what);
}

/* A pass that stores more photons than the first guess (1.5 per path) grows
 * the store, allocate-copy-free, and traces again: make each of those
 * allocations fail too.  White walls (albedo 1) with first-bounce photons
 * stored store about 4 photons per path, so the first pass grows twice. */
static void test_pass_growth(void)
{
    appm_config cfg;
    check_alloc a;
    appm_scene *scene = NULL;
    appm_renderer *r;
    appm_diag d;
    long base, used, k;
    int bad = 0;
    CHECK(appm_scene_load("scenes/cornell-empty-white.scene", NULL, &scene, &d) == APPM_OK);
    if (!scene) return;
    /* how many allocations does a clean first pass make? */
    render_cfg(&cfg, APPM_METHOD_APPM);
    cfg.width = cfg.height = 8;
    cfg.photons = (uint64_t)check_count(16000, 16000); /* emulated: 3200, and the store still grows */
    cfg.direct = APPM_DIRECT_PHOTONS;
    check_use_alloc(&cfg, &a, 0);
    CHECK(appm_renderer_create(scene, &cfg, &r, &d) == APPM_OK);
    base = a.count;
    CHECK(appm_renderer_pass(r) == APPM_OK);
    used = a.count - base;
    appm_renderer_destroy(r);
    CHECK(a.live == 0);
    CHECK_MSG(used >= 3, "the first pass made %ld allocations: the store did not grow", used);
    for (k = 1; k <= used; ++k) {
        appm_status st;
        check_use_alloc(&cfg, &a, 0);
        CHECK(appm_renderer_create(scene, &cfg, &r, &d) == APPM_OK);
        a.fail_at = a.count + k;
        st = appm_renderer_pass(r);
        if (st != APPM_ERR_NOMEM && !bad++) fprintf(stderr, "growth: allocation %ld: status %d\n", k, (int)st);
        /* the renderer is still whole: with memory back, a pass succeeds */
        a.fail_at = 0;
        st = appm_renderer_pass(r);
        if (st != APPM_OK && !bad++) fprintf(stderr, "growth: pass after a failure: status %d\n", (int)st);
        appm_renderer_destroy(r);
        if (a.live != 0 && !bad++) fprintf(stderr, "growth: allocation %ld: %lld bytes left\n", k, a.live);
    }
    CHECK(bad == 0);
    appm_scene_destroy(scene);
}

/* ---- checkpoints ------------------------------------------------------------------ */

/* appm_renderer_save_file and appm_renderer_load_file with allocation k of the
 * call failing, k = 1, 2, ...: NOMEM, nothing leaked, no file (or no change to
 * the renderer) left behind; the buffer calls allocate nothing at all. */
static void test_checkpoint(const appm_scene *scene)
{
    appm_config cfg;
    check_alloc a;
    appm_renderer *r = NULL, *fresh = NULL;
    appm_diag d;
    appm_status st = APPM_ERR_NOMEM;
    const char *path = check_path("alloc", "oom.ckpt");
    unsigned char *buf = NULL;
    size_t n = 0;
    long k, before, bad = 0, live;
    render_cfg(&cfg, APPM_METHOD_APPM);
    check_use_alloc(&cfg, &a, 0);
    if (appm_renderer_create(scene, &cfg, &r, &d) != APPM_OK || appm_renderer_pass(r) != APPM_OK ||
        appm_renderer_create(scene, &cfg, &fresh, &d) != APPM_OK) {
        CHECK_MSG(0, "checkpoint: no renderer");
        goto done;
    }
    before = a.count;
    CHECK(appm_renderer_save(r, NULL, 0, &n, &d) == APPM_OK && n > 0);
    buf = (unsigned char *)malloc(n);
    CHECK(buf && appm_renderer_save(r, buf, n, &n, &d) == APPM_OK);
    CHECK(buf && appm_renderer_load(fresh, buf, n, &d) == APPM_OK && fresh->pass == 1);
    CHECK_MSG(a.count == before, "the buffer calls made %ld allocations", a.count - before);
    appm_renderer_destroy(fresh);
    fresh = NULL;
    CHECK(appm_renderer_create(scene, &cfg, &fresh, &d) == APPM_OK);
    remove(path);
    for (k = 1, st = APPM_ERR_NOMEM; k < 100 && st != APPM_OK; ++k) {
        FILE *f;
        live = (long)a.live;
        a.fail_at = a.count + k;
        st = appm_renderer_save_file(r, path, &d);
        a.fail_at = 0;
        if (st == APPM_OK) break;
        f = fopen(path, "rb");
        if ((st != APPM_ERR_NOMEM || d.status != st || (long)a.live != live || f) && !bad++)
            fprintf(stderr, "checkpoint: save_file, failing allocation %ld: status %d\n", k, (int)st);
        if (f) fclose(f);
    }
    CHECK_MSG(st == APPM_OK && k > 1, "save_file: status %d after %ld tries", (int)st, k);
    for (k = 1, st = APPM_ERR_NOMEM; k < 100 && st != APPM_OK && fresh; ++k) {
        live = (long)a.live;
        a.fail_at = a.count + k;
        st = appm_renderer_load_file(fresh, path, &d);
        a.fail_at = 0;
        if (st == APPM_OK) break;
        if ((st != APPM_ERR_NOMEM || d.status != st || (long)a.live != live || fresh->pass != 0) && !bad++)
            fprintf(stderr, "checkpoint: load_file, failing allocation %ld: status %d\n", k, (int)st);
    }
    CHECK_MSG(st == APPM_OK && k > 1 && fresh && fresh->pass == 1, "load_file: status %d after %ld tries",
              (int)st, k);
    CHECK(bad == 0);
done:
    free(buf);
    appm_renderer_destroy(r);
    appm_renderer_destroy(fresh);
    CHECK(a.live == 0);
}

/* appm_renderer_set_cluster: each of its allocations failing gives
 * APPM_ERR_NOMEM, leaks nothing and leaves the renderer rendering alone; one
 * more allocation than it needs succeeds.  (Its exchanges: tests/t_cluster.c.) */
static int never_called(void *user, void *buf, const size_t *lens)
{
    (void)buf;
    (void)lens;
    ++*(int *)user;
    return 1;
}

static void test_cluster(const appm_scene *scene)
{
    appm_config cfg;
    check_alloc a;
    appm_renderer *r = NULL;
    appm_cluster cl;
    appm_diag d;
    appm_status st = APPM_ERR_NOMEM;
    long k, live, bad = 0;
    int calls = 0;
    render_cfg(&cfg, APPM_METHOD_APPM);
    cfg.emission = APPM_EMISSION_GUIDED; /* the guided counts' array too */
    check_use_alloc(&cfg, &a, 0);
    if (appm_renderer_create(scene, &cfg, &r, &d) != APPM_OK) {
        CHECK_MSG(0, "cluster: no renderer");
        return;
    }
    cl.rank = 1;
    cl.ranks = 3;
    cl.allgather = never_called;
    cl.user = &calls;
    for (k = 1; k < 100; ++k) {
        live = (long)a.live;
        a.fail_at = a.count + k;
        st = appm_renderer_set_cluster(r, &cl, &d);
        a.fail_at = 0;
        if (st == APPM_OK) break;
        if ((st != APPM_ERR_NOMEM || (long)a.live != live || r->cluster.ranks != 1 || r->row1 != r->h) && !bad++)
            fprintf(stderr, "cluster: failing allocation %ld: status %d\n", k, (int)st);
    }
    CHECK_MSG(st == APPM_OK && k > 5, "set_cluster: status %d after %ld tries", (int)st, k);
    CHECK(bad == 0 && r->cluster.ranks == 3 && r->row0 > 0 && r->row1 < r->h);
    CHECK(appm_renderer_set_cluster(r, NULL, &d) == APPM_OK && r->row0 == 0 && r->row1 == r->h);
    CHECK(appm_renderer_pass(r) == APPM_OK && calls == 0); /* alone again: the hook is not called */
    appm_renderer_destroy(r);
    CHECK(a.live == 0);
}

/* ---- PFM reading ---------------------------------------------------------------- */

static void test_read_pfm(void)
{
    enum { W = 100, H = 100 }; /* 120 KB: the file buffer has to grow once */
    const char *path = check_path("alloc", "read.pfm");
    float *px = (float *)malloc(sizeof(float) * W * H * 3);
    appm_image img;
    appm_config cfg;
    check_alloc a;
    appm_diag d;
    appm_status st = APPM_ERR_NOMEM;
    long n;
    int i, bad = 0;
    for (i = 0; i < W * H * 3; ++i) px[i] = (float)i * 0.5f;
    img.width = W;
    img.height = H;
    img.rgb = px;
    CHECK(appm_image_write(path, &img, 1.0, &d) == APPM_OK);
    for (n = 1; n < 100; ++n) {
        memset(&cfg, 0, sizeof cfg);
        check_use_alloc(&cfg, &a, n);
        st = appm_image_read_pfm(path, &cfg, &img, &d);
        if (st == APPM_OK) break;
        if ((st != APPM_ERR_NOMEM || img.rgb != NULL || a.live != 0 || d.status != APPM_ERR_NOMEM) && !bad++)
            fprintf(stderr, "read_pfm: failing allocation %ld: status %d, %lld bytes left\n", n, (int)st, a.live);
    }
    CHECK(bad == 0);
    CHECK(st == APPM_OK);
    CHECK(n >= 3); /* the buffer, its growth, the pixels */
    if (st == APPM_OK) {
        CHECK(img.width == W && img.height == H && memcmp(img.rgb, px, sizeof(float) * W * H * 3) == 0);
        CHECK(a.live > 0);
        appm_image_free(&cfg, &img);
        CHECK(a.live == 0);
    }
    free(px);
}

int main(void)
{
    appm_scene *scene = NULL;
    appm_diag d;
    test_wrapper();
    test_scene_loads();
    test_read_pfm();
    /* renderers over a scene loaded with the ordinary allocator */
    CHECK(appm_scene_load("scenes/cornell-sphere.scene", NULL, &scene, &d) == APPM_OK);
    if (scene) {
        test_renderer(scene, APPM_METHOD_APPM, "appm");
        test_renderer(scene, APPM_METHOD_SPPM, "sppm");
        test_renderer(scene, APPM_METHOD_PPM, "ppm");
        test_renderer(scene, APPM_METHOD_PT, "pt");
        test_renderer(scene, APPM_METHOD_APPM_PAPER, "appm-paper");
        test_checkpoint(scene);
        test_cluster(scene);
    }
    appm_scene_destroy(scene);
    test_pass_growth();
    return check_finish();
}
