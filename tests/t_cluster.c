/* tests/t_cluster.c - one render split over several ranks (appm.c 12.1).
 *
 * The ranks here are threads of one process, each with its own renderer, and
 * the all-gather they share is a pair of barriers around a copy: what an MPI
 * job (mpi.c, tests/mpi.sh) does between processes, without MPI.
 *
 * What is checked, and against what:
 *   1. Byte identity: for every method (appm, appm-paper, ppm, sppm, pt), and
 *      for appm with guided emission and with two chains, the image after a
 *      few passes on 1, 2, 3 and 4 ranks (1 or 2 threads each) is the image of
 *      one renderer alone, bit for bit; so are the photon counts, the dropped
 *      samples and a checkpoint (the renderer's whole state), byte for byte.
 *   2. Resume across sizes: a checkpoint saved after 2 passes by a job of 3
 *      ranks, loaded by a job of 2 that runs 2 more, gives the image of 4
 *      passes alone.  Both cases also with the photon budget (appm.c 12.2),
 *      whose choice sums the rays every rank counted.
 *   3. Bytes: each rank's parts and what it received add up over the ranks
 *      (every byte one rank gives, the others receive).
 *   4. Failure: a rank whose allocator runs dry in the first pass fails it
 *      with APPM_ERR_NOMEM, and every other rank returns the same status with
 *      a message that names that rank - none waits forever; an exchange hook
 *      that fails fails the pass with APPM_ERR_IO.
 *   5. Arguments: rank >= ranks, more than 65536 ranks, no hook are refused.
 *   6. Files through appm_config.reader (how a job's ranks get rank 0's
 *      files): a scene under a name only the reader knows loads, every lent
 *      buffer is released, and without the reader the name is a missing file;
 *      appm_renderer_load_file loads a checkpoint the reader lends, and a
 *      reader that fails gives APPM_ERR_IO.
 */
#include "../appm.c"
#include "check.h"

#define MAX_RANKS 4

#if APPM_THREADS == 1

/* ---- an in-process cluster: ranks are threads ------------------------------ */

typedef struct world {
    pthread_mutex_t lock;
    pthread_cond_t cond;
    unsigned ranks, waiting, generation;
    void *buf[MAX_RANKS];
    int fail_hook; /* every hook call fails */
} world;

typedef struct rank_ctx {
    world *w;
    unsigned rank;
} rank_ctx;

static void world_barrier(world *w)
{
    unsigned gen;
    pthread_mutex_lock(&w->lock);
    gen = w->generation;
    if (++w->waiting == w->ranks) {
        w->waiting = 0;
        w->generation++;
        pthread_cond_broadcast(&w->cond);
    } else {
        while (gen == w->generation) pthread_cond_wait(&w->cond, &w->lock);
    }
    pthread_mutex_unlock(&w->lock);
}

/* appm_cluster.allgather: publish the buffer, copy the others' parts from
 * theirs, and wait until every rank has copied before anyone goes on. */
static int world_allgather(void *user, void *buf, const size_t *lens)
{
    rank_ctx *c = (rank_ctx *)user;
    world *w = c->w;
    size_t off = 0;
    unsigned k;
    if (w->fail_hook) return 1;
    w->buf[c->rank] = buf;
    world_barrier(w);
    for (k = 0; k < w->ranks; ++k) {
        if (k != c->rank && lens[k]) memcpy((char *)buf + off, (const char *)w->buf[k] + off, lens[k]);
        off += lens[k];
    }
    world_barrier(w);
    return 0;
}

/* ---- one job ---------------------------------------------------------------- */

/* A job: `ranks` renderers of scene s with cfg, `passes` passes each, rank 0's
 * image and checkpoint kept. */
typedef struct job {
    const appm_scene *s;
    appm_config cfg;
    unsigned ranks, passes;
    const void *resume; /* a checkpoint every rank loads first (NULL: none) */
    size_t resume_len;
    size_t fail_rank_bytes; /* > 0: rank 1's allocator fails after this many bytes */
    world w;
    /* results, per rank */
    appm_status st[MAX_RANKS];
    char msg[MAX_RANKS][256];
    appm_stats stats[MAX_RANKS];
    float *image;           /* rank 0's, malloc'd */
    unsigned char *ck;      /* rank 0's checkpoint, malloc'd */
    size_t ck_len;
    int images_agree;       /* every rank's image equals rank 0's */
} job;

typedef struct rank_arg {
    job *j;
    rank_ctx ctx;
    float *image;
} rank_arg;

/* Rank 1's allocator in the failure test: malloc until `budget` bytes are live. */
typedef struct budget_alloc {
    size_t live, budget;
} budget_alloc;

static void *budget_malloc(void *user, size_t size)
{
    budget_alloc *b = (budget_alloc *)user;
    void *p;
    if (b->live + size > b->budget) return NULL;
    p = malloc(size);
    if (p) b->live += size;
    return p;
}

static void budget_free(void *user, void *p, size_t size)
{
    budget_alloc *b = (budget_alloc *)user;
    if (!p) return;
    b->live -= size;
    free(p);
}

static void *rank_main(void *arg)
{
    rank_arg *a = (rank_arg *)arg;
    job *j = a->j;
    const unsigned k = a->ctx.rank;
    appm_config cfg = j->cfg;
    appm_renderer *r = NULL;
    appm_cluster cl;
    appm_diag d;
    appm_image img;
    budget_alloc ba;
    unsigned p;
    appm_status st;
    if (k == 1 && j->fail_rank_bytes) {
        ba.live = 0;
        ba.budget = (size_t)-1;
        cfg.allocator.alloc = budget_malloc;
        cfg.allocator.free = budget_free;
        cfg.allocator.user = &ba;
    }
    st = appm_renderer_create(j->s, &cfg, &r, &d);
    if (st == APPM_OK && k == 1 && j->fail_rank_bytes) ba.budget = ba.live + j->fail_rank_bytes;
    cl.rank = k;
    cl.ranks = j->ranks;
    cl.allgather = world_allgather;
    cl.user = &a->ctx;
    if (st == APPM_OK) st = appm_renderer_set_cluster(r, &cl, &d);
    if (st == APPM_OK && j->resume) st = appm_renderer_load(r, j->resume, j->resume_len, &d);
    for (p = 0; st == APPM_OK && p < j->passes; ++p) st = appm_renderer_pass(r);
    j->st[k] = st;
    snprintf(j->msg[k], sizeof j->msg[k], "%s", r ? appm_renderer_last_error(r) : d.message);
    if (r) {
        appm_renderer_stats(r, &j->stats[k]);
        appm_renderer_image(r, &img);
        a->image = (float *)malloc((size_t)img.width * img.height * 3 * sizeof(float));
        if (a->image) memcpy(a->image, img.rgb, (size_t)img.width * img.height * 3 * sizeof(float));
        if (k == 0 && appm_renderer_save(r, NULL, 0, &j->ck_len, NULL) == APPM_OK) {
            j->ck = (unsigned char *)malloc(j->ck_len);
            if (j->ck && appm_renderer_save(r, j->ck, j->ck_len, &j->ck_len, NULL) != APPM_OK) j->ck_len = 0;
        }
        appm_renderer_destroy(r);
    }
    return NULL;
}

/* Runs the job; 0 if the threads could not be had. */
static int job_run(job *j)
{
    pthread_t th[MAX_RANKS];
    rank_arg a[MAX_RANKS];
    unsigned k;
    size_t npix = (size_t)j->cfg.width * j->cfg.height;
    memset(&j->w, 0, sizeof j->w);
    pthread_mutex_init(&j->w.lock, NULL);
    pthread_cond_init(&j->w.cond, NULL);
    j->w.ranks = j->ranks;
    for (k = 0; k < j->ranks; ++k) {
        a[k].j = j;
        a[k].ctx.w = &j->w;
        a[k].ctx.rank = k;
        a[k].image = NULL;
        if (pthread_create(&th[k], NULL, rank_main, &a[k]) != 0) return 0;
    }
    for (k = 0; k < j->ranks; ++k) pthread_join(th[k], NULL);
    j->images_agree = 1;
    for (k = 0; k < j->ranks; ++k) {
        if (!a[k].image || !a[0].image || memcmp(a[k].image, a[0].image, npix * 3 * sizeof(float)) != 0)
            j->images_agree = 0;
        if (k) free(a[k].image);
    }
    j->image = a[0].image;
    pthread_mutex_destroy(&j->w.lock);
    pthread_cond_destroy(&j->w.cond);
    return 1;
}

static void job_free(job *j)
{
    free(j->image);
    free(j->ck);
    j->image = NULL;
    j->ck = NULL;
}

/* The render alone: image and checkpoint (malloc'd). */
static void alone(const appm_scene *s, const appm_config *cfg, unsigned passes, float **image, unsigned char **ck,
                  size_t *ck_len, appm_stats *stats)
{
    appm_renderer *r;
    appm_image img;
    unsigned p;
    *image = NULL;
    *ck = NULL;
    *ck_len = 0;
    if (appm_renderer_create(s, cfg, &r, NULL) != APPM_OK) return;
    for (p = 0; p < passes; ++p) appm_renderer_pass(r);
    appm_renderer_stats(r, stats);
    appm_renderer_image(r, &img);
    *image = (float *)malloc((size_t)img.width * img.height * 3 * sizeof(float));
    if (*image) memcpy(*image, img.rgb, (size_t)img.width * img.height * 3 * sizeof(float));
    if (appm_renderer_save(r, NULL, 0, ck_len, NULL) == APPM_OK && (*ck = (unsigned char *)malloc(*ck_len)) != NULL)
        appm_renderer_save(r, *ck, *ck_len, ck_len, NULL);
    appm_renderer_destroy(r);
}

/* The stats of `passes` passes alone (zeros if the render fails). */
static appm_stats alone_stats(const appm_scene *s, const appm_config *cfg, unsigned passes)
{
    float *img = NULL;
    unsigned char *ck = NULL;
    size_t ck_len = 0;
    appm_stats st;
    memset(&st, 0, sizeof st);
    alone(s, cfg, passes, &img, &ck, &ck_len, &st);
    free(img);
    free(ck);
    return st;
}

/* Two checkpoints of the same state: every byte but the five seconds of
 * appm_stats (layout, section 13: after 200 bytes of identification,
 * options, scene hashes, counters and radii) and the hash at the end that
 * covers them. */
static int same_bytes(const unsigned char *a, size_t na, const unsigned char *b, size_t nb)
{
    return a && b && na == nb && na > 248 && memcmp(a, b, 200) == 0 && memcmp(a + 240, b + 240, na - 248) == 0;
}

/* Case 1 for one configuration: ranks 1..4, threads 1 and 2 alternating. */
static void check_identity(const char *what, const appm_scene *s, const appm_config *cfg, unsigned passes)
{
    float *ref;
    unsigned char *ck;
    size_t ck_len, npix = (size_t)cfg->width * cfg->height;
    appm_stats st;
    unsigned n;
    alone(s, cfg, passes, &ref, &ck, &ck_len, &st);
    CHECK_MSG(ref && ck, "%s: the render alone", what);
    if (!ref || !ck) return;
    for (n = 1; n <= MAX_RANKS; ++n) {
        job j;
        unsigned k;
        uint64_t out = 0, in = 0;
        memset(&j, 0, sizeof j);
        j.s = s;
        j.cfg = *cfg;
        j.cfg.threads = 1 + n % 2;
        j.ranks = n;
        j.passes = passes;
        CHECK(job_run(&j));
        for (k = 0; k < n; ++k) CHECK_MSG(j.st[k] == APPM_OK, "%s, %u ranks: rank %u: %s", what, n, k, j.msg[k]);
        CHECK_MSG(j.images_agree, "%s, %u ranks: the ranks' images differ", what, n);
        CHECK_MSG(j.image && memcmp(j.image, ref, npix * 3 * sizeof(float)) == 0,
                  "%s, %u ranks: the image is not that of the render alone", what, n);
        CHECK_MSG(same_bytes(j.ck, j.ck_len, ck, ck_len), "%s, %u ranks: the checkpoint differs", what, n);
        CHECK(j.stats[0].photons_stored == st.photons_stored && j.stats[0].dropped_samples == st.dropped_samples &&
              j.stats[0].photons_emitted == st.photons_emitted);
        for (k = 0; k < n; ++k) {
            out += j.stats[k].cluster_bytes_out * (n - 1); /* each part goes to every other rank */
            in += j.stats[k].cluster_bytes_in;
        }
        CHECK_MSG(out == in && (n == 1 || in > 0), "%s, %u ranks: %llu bytes given, %llu received", what, n,
                  (unsigned long long)out, (unsigned long long)in);
        job_free(&j);
    }
    free(ref);
    free(ck);
}

/* Case 2: 2 passes on 3 ranks, checkpoint, 2 more on 2 ranks = 4 alone. */
static void check_resume(const appm_scene *s, const appm_config *cfg)
{
    float *ref;
    unsigned char *ck;
    size_t ck_len, npix = (size_t)cfg->width * cfg->height;
    appm_stats st;
    job a, b;
    alone(s, cfg, 4, &ref, &ck, &ck_len, &st);
    memset(&a, 0, sizeof a);
    a.s = s;
    a.cfg = *cfg;
    a.ranks = 3;
    a.passes = 2;
    CHECK(job_run(&a) && a.ck);
    memset(&b, 0, sizeof b);
    b.s = s;
    b.cfg = *cfg;
    b.cfg.threads = 2;
    b.ranks = 2;
    b.passes = 2;
    b.resume = a.ck;
    b.resume_len = a.ck_len;
    CHECK(job_run(&b));
    CHECK_MSG(b.st[0] == APPM_OK && b.st[1] == APPM_OK, "resume: %s / %s", b.msg[0], b.msg[1]);
    CHECK(b.images_agree && ref && b.image && memcmp(b.image, ref, npix * 3 * sizeof(float)) == 0);
    CHECK(same_bytes(b.ck, b.ck_len, ck, ck_len));
    job_free(&a);
    job_free(&b);
    free(ref);
    free(ck);
}

/* Case 4: rank 1 runs out of memory in its first pass; every rank returns. */
static void check_failure(const appm_scene *s, const appm_config *cfg)
{
    job j;
    unsigned k;
    memset(&j, 0, sizeof j);
    j.s = s;
    j.cfg = *cfg;
    j.ranks = 3;
    j.passes = 2;
    j.fail_rank_bytes = 4096; /* the photon map's first arrays are larger */
    CHECK(job_run(&j));
    CHECK_MSG(j.st[1] == APPM_ERR_NOMEM, "rank 1: %d %s", (int)j.st[1], j.msg[1]);
    for (k = 0; k < 3; ++k) {
        if (k == 1) continue;
        CHECK_MSG(j.st[k] == APPM_ERR_NOMEM && strstr(j.msg[k], "rank 1 failed") != NULL, "rank %u: %d %s", k,
                  (int)j.st[k], j.msg[k]);
        CHECK(j.stats[k].passes == 0);
    }
    job_free(&j);
}

static void check_failing_hook(const appm_scene *s, const appm_config *cfg)
{
    appm_renderer *r;
    appm_cluster cl;
    world w;
    rank_ctx ctx;
    memset(&w, 0, sizeof w);
    w.ranks = 2;
    w.fail_hook = 1;
    ctx.w = &w;
    ctx.rank = 0;
    cl.rank = 0;
    cl.ranks = 2;
    cl.allgather = world_allgather;
    cl.user = &ctx;
    if (appm_renderer_create(s, cfg, &r, NULL) != APPM_OK) {
        CHECK(0);
        return;
    }
    CHECK(appm_renderer_set_cluster(r, &cl, NULL) == APPM_OK);
    CHECK(appm_renderer_pass(r) == APPM_ERR_IO);
    CHECK(strstr(appm_renderer_last_error(r), "exchange failed") != NULL);
    CHECK(appm_renderer_set_cluster(r, NULL, NULL) == APPM_OK);
    CHECK(appm_renderer_pass(r) == APPM_OK); /* alone again */
    appm_renderer_destroy(r);
}

#endif /* APPM_THREADS == 1 */

static int dummy_allgather(void *user, void *buf, const size_t *lens)
{
    (void)user;
    (void)buf;
    (void)lens;
    return 0;
}

/* Case 5. */
static void check_arguments(const appm_scene *s, const appm_config *cfg)
{
    appm_renderer *r;
    appm_cluster cl;
    appm_diag d;
    if (appm_renderer_create(s, cfg, &r, NULL) != APPM_OK) {
        CHECK(0);
        return;
    }
    memset(&cl, 0, sizeof cl);
    cl.allgather = dummy_allgather;
    cl.ranks = 2;
    cl.rank = 2;
    CHECK(appm_renderer_set_cluster(r, &cl, &d) == APPM_ERR_INVALID_ARG && strstr(d.message, "rank 2 of 2"));
    cl.rank = 0;
    cl.ranks = 65537;
    CHECK(appm_renderer_set_cluster(r, &cl, &d) == APPM_ERR_INVALID_ARG);
    cl.ranks = 2;
    cl.allgather = NULL;
    CHECK(appm_renderer_set_cluster(r, &cl, &d) == APPM_ERR_INVALID_ARG);
    CHECK(appm_renderer_set_cluster(NULL, &cl, &d) == APPM_ERR_INVALID_ARG);
    cl.ranks = 1; /* one rank: alone, the hook is never called */
    CHECK(appm_renderer_set_cluster(r, &cl, &d) == APPM_OK && appm_renderer_pass(r) == APPM_OK);
    appm_renderer_destroy(r);
}

/* ---- case 6: a reader that serves "virtual/NAME" from scenes/NAME, or one buffer */

typedef struct test_reader {
    int reads, releases;
    const void *buf; /* non-NULL: every read lends this */
    size_t len;
} test_reader;

static int test_read(void *user, const char *path, const void **data, size_t *len)
{
    test_reader *t = (test_reader *)user;
    char real[512];
    FILE *f;
    char *b;
    long n;
    t->reads++;
    if (t->buf) {
        *data = t->buf;
        *len = t->len;
        return 0;
    }
    if (strncmp(path, "virtual/", 8) != 0) return 1;
    snprintf(real, sizeof real, "scenes/%s", path + 8);
    if (!(f = fopen(real, "rb"))) return 1;
    fseek(f, 0, SEEK_END);
    n = ftell(f);
    fseek(f, 0, SEEK_SET);
    b = (char *)malloc(n > 0 ? (size_t)n : 1);
    if (!b || fread(b, 1, (size_t)n, f) != (size_t)n) {
        free(b);
        fclose(f);
        return 1;
    }
    fclose(f);
    *data = b;
    *len = (size_t)n;
    return 0;
}

static void test_release(void *user, const void *data)
{
    test_reader *t = (test_reader *)user;
    t->releases++;
    if (!t->buf) free((void *)data);
}

static void check_reader(const appm_scene *box, const appm_config *base)
{
    appm_config cfg = *base;
    test_reader t;
    appm_scene *s = NULL;
    appm_renderer *r = NULL, *fresh = NULL;
    appm_diag d;
    unsigned char *ck = NULL;
    size_t n = 0;
    memset(&t, 0, sizeof t);
    cfg.reader.read = test_read;
    cfg.reader.release = test_release;
    cfg.reader.user = &t;
    CHECK_MSG(appm_scene_load("virtual/cornell-sphere.scene", &cfg, &s, &d) == APPM_OK, "%s", d.message);
    CHECK_MSG(t.reads >= 3 && t.releases == t.reads, "%d reads, %d releases", t.reads, t.releases);
    appm_scene_destroy(s);
    CHECK(appm_scene_load("virtual/cornell-sphere.scene", base, &s, &d) == APPM_ERR_IO);
    if (appm_renderer_create(box, base, &r, NULL) != APPM_OK) {
        CHECK(0);
        return;
    }
    appm_renderer_pass(r);
    appm_renderer_pass(r);
    if (appm_renderer_save(r, NULL, 0, &n, NULL) == APPM_OK && (ck = (unsigned char *)malloc(n)) != NULL &&
        appm_renderer_save(r, ck, n, &n, NULL) == APPM_OK) {
        memset(&t, 0, sizeof t);
        t.buf = ck;
        t.len = n;
        CHECK(appm_renderer_create(box, &cfg, &fresh, NULL) == APPM_OK);
        CHECK(fresh && appm_renderer_load_file(fresh, "nowhere/lent.ck", &d) == APPM_OK && fresh->pass == 2);
        CHECK(t.reads == 1 && t.releases == 1);
        t.buf = NULL; /* "nowhere/..." is not virtual: the read fails */
        CHECK(fresh && appm_renderer_load_file(fresh, "nowhere/lent.ck", &d) == APPM_ERR_IO);
    } else {
        CHECK(0);
    }
    free(ck);
    appm_renderer_destroy(r);
    appm_renderer_destroy(fresh);
}

int main(void)
{
    appm_scene *box = NULL, *glass = NULL;
    appm_config cfg;
    appm_diag d;
    const int quick = getenv("APPM_TEST_QUICK") != NULL;
    CHECK(appm_scene_load("scenes/cornell-sphere.scene", NULL, &box, &d) == APPM_OK);
    CHECK(appm_scene_load("scenes/caustic-glass.scene", NULL, &glass, &d) == APPM_OK);
    if (!box || !glass) return check_finish();
    memset(&cfg, 0, sizeof cfg);
    cfg.width = 24;
    cfg.height = 19; /* rows do not split evenly over 2, 3 or 4 ranks */
    cfg.photons = 3000; /* 3 chunks: a rank may trace none */
    check_arguments(box, &cfg);
    check_reader(box, &cfg);
#if APPM_THREADS == 1
    {
        static const appm_method methods[] = {APPM_METHOD_APPM, APPM_METHOD_APPM_PAPER, APPM_METHOD_PPM,
                                              APPM_METHOD_SPPM, APPM_METHOD_PT};
        unsigned m, passes = quick ? 3 : 5;
        for (m = 0; m < sizeof methods / sizeof methods[0]; ++m) {
            cfg.method = methods[m];
            check_identity(appm_method_name(methods[m]), box, &cfg, passes);
        }
        cfg.method = APPM_METHOD_APPM;
        cfg.photons = 9000;
        cfg.emission = APPM_EMISSION_GUIDED; /* learned densities: counts summed over ranks */
        {   /* by pass 20 the spot draws from its learned density (the warp, on every rank) */
            appm_stats st = alone_stats(glass, &cfg, 20);
            CHECK_MSG(st.emission_guided > 0.0, "caustic-glass 24x19, 20 passes: guided share %g", st.emission_guided);
        }
        check_identity("appm guided", glass, &cfg, 20);
        cfg.photons = 0; /* the photon budget (12.2): each rank counts the rays of its own rows and chunks,
                          * all sum every rank's, and all choose the same M */
        {
            appm_stats st = alone_stats(glass, &cfg, 2);
            CHECK_MSG(st.photons_per_pass == 4u * 24u * 19u, "caustic-glass 24x19: %llu photon paths a pass",
                      (unsigned long long)st.photons_per_pass);
        }
        check_identity("appm, the photon budget", glass, &cfg, passes);
        check_resume(glass, &cfg); /* the budget's M from a checkpoint of 3 ranks, on 2 */
        cfg.photons = 9000;
        cfg.emission = APPM_EMISSION_LIGHT;
        cfg.chains = 2;
        check_identity("appm 2 chains", glass, &cfg, passes);
        cfg.chains = 0;
        cfg.photons = 3000;
        check_resume(box, &cfg);
        check_failure(box, &cfg);
        check_failing_hook(box, &cfg);
    }
#else
    (void)quick;
#endif
    appm_scene_destroy(box);
    appm_scene_destroy(glass);
    return check_finish();
}

