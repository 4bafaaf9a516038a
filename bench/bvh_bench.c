/* bench/bvh_bench.c - BVH build time, ray throughput and photon-pass speed:
 * the wide tree (with the box test this build has, and with the scalar one)
 * against the binary tree it is collapsed from, side by side in one run.
 *
 *   cc -std=c99 -O2 bench/bvh_bench.c -o build/bvh_bench -lm -pthread
 *   ./build/bvh_bench [MESH.obj [RAYS [PHOTON-SCENE [SIZE]]]]
 *       defaults: scenes/stanford-bunny.obj, 1e6 rays, scenes/cornell-sphere.scene, 512
 *   (add -mavx2 or -march=native for the 8-wide AVX2 tree, -DAPPM_SIMD=0 for
 *   the scalar build)
 *
 * Every figure is the median of 3 rounds (BVH_ROUNDS=N in the environment:
 * N rounds, 1 to 15; the wall-clock photon figures want 5 or more); within a round the three traversals
 * take turns every 10000 rays (photon passes: pass by pass), so a change in
 * the machine's load hits all of them alike, each on rays no other one has
 * just traced and after an untimed warm-up of its own (see trace()).
 * One line per traversal (path=binary|scalar|simd):
 *   closest_per_s   closest hits (appm__ray_init + appm__intersect) per second
 *                   for RAYS rays, origins uniform in the mesh's bounding box,
 *                   directions uniform; the rays are drawn before the clock starts
 *   anyhit_per_s    appm__occluded on the same rays (tmax = FLT_MAX)
 *   photon_per_s_1t, photon_per_s_2t   photon paths per second of the photon
 *                   pass alone (appm_stats.seconds_photons) rendering
 *                   PHOTON-SCENE at SIZE^2 with ppm, 3 passes, 1 and 2 threads
 *                   (SIZE^2 photon paths a pass)
 *   checksum        sum of the closest hits' t (equal for all paths up to ties)
 * Then one summary line:
 *   bvh_build_ms    median of 5 builds (binary SAH build + collapse) of the
 *                   loaded triangles, each on a fresh copy in the loader's order
 *   binary_build_ms the binary build alone (what the build was before the collapse)
 *   ratios new/old of each figure, triangles, node counts, depth, hit_fraction,
 *   sah_cost (of the binary tree: node visits plus triangle tests expected for a
 *   random line through the root box, a machine-independent quality figure).
 * Rays and builds are timed in processor time (clock(); one thread, so the
 * time other jobs take from it does not count), photon passes in wall-clock
 * time (the renderer's, with up to two threads); run on an idle machine.
 */
#define APPM_BVH_BINARY 1 /* keep the binary tree and its traversal for the comparison */
#include "../appm.c"

#include <stdio.h>

#define BUILDS 5
#define ROUNDS_MAX 15
#define NPATH 3

static const int path_id[NPATH] = {APPM__BVH_BINARY, APPM__BVH_SCALAR, APPM__BVH_SIMD};
static const char *path_name[NPATH] = {"binary", "scalar", "simd"};

static int cmp_double(const void *a, const void *b)
{
    double x = *(const double *)a, y = *(const double *)b;
    return (x > y) - (x < y);
}

static double median(double *v, int n)
{
    qsort(v, (size_t)n, sizeof v[0], cmp_double);
    return v[n / 2];
}

static double node_area(const appm__node *n)
{
    double dx = n->bmax[0] - n->bmin[0], dy = n->bmax[1] - n->bmin[1], dz = n->bmax[2] - n->bmin[2];
    return 2.0 * (dx * dy + dy * dz + dz * dx);
}

/* Expected cost of a random ray through the root box under the surface-area
 * heuristic: sum over interior nodes of P(visit) * 1 (box tests of its two
 * children counted as one visit) plus sum over leaves of P(visit) * count. */
static double sah_cost(const appm_scene *s)
{
    double root = node_area(&s->node[0]), c = 0.0;
    uint32_t i;
    if (!(root > 0.0)) return 0.0;
    for (i = 0; i < s->nnode; ++i) {
        const appm__node *n = &s->node[i];
        c += node_area(n) / root * (n->count ? (double)n->count : 1.0);
    }
    return c;
}

static appm_scene *load_mesh(const char *mesh)
{
    const char *tmp = "appm-bvh-bench.scene.tmp";
    appm_scene *s = NULL;
    appm_diag d;
    FILE *f = fopen(tmp, "wb");
    /* A bare OBJ without emitters is not a valid scene (it has no light), so
     * wrap it in a scene file with a point light; mesh paths in a scene file
     * are relative to its folder, here the current one. */
    if (!f) {
        fprintf(stderr, "bvh_bench: cannot write %s\n", tmp);
        return NULL;
    }
    fprintf(f, "mesh %s\nlight point position 0 1 0 intensity 1 1 1\n", mesh);
    fclose(f);
    if (appm_scene_load(tmp, NULL, &s, &d) != APPM_OK) fprintf(stderr, "bvh_bench: %s:%u: %s\n", d.file, d.line, d.message);
    remove(tmp);
    if (s && s->ntri == 0) {
        fprintf(stderr, "bvh_bench: no triangles\n");
        appm_scene_destroy(s);
        s = NULL;
    }
    return s;
}

/* Median build times (ms) of the full build and of the binary build alone.
 * The loaded arrays are set aside; each build gets copies, which the build
 * frees after writing its reordered ones; the last full build is kept. */
static int time_builds(appm_scene *s, double *full_ms, double *binary_ms)
{
    appm__tri *tri0 = s->tri;
    appm__tri_info *info0 = s->info;
    double full[BUILDS], bin[BUILDS];
    uint32_t n = s->ntri;
    int b, k;
    appm__free(&s->mem, s->node);
    appm__free(&s->mem, s->wnode_mem);
    for (b = 0; b < 2 * BUILDS; ++b) {
        appm__tri *tc = (appm__tri *)appm__alloc(&s->mem, n, sizeof *tc);
        appm__tri_info *ic = (appm__tri_info *)appm__alloc(&s->mem, n, sizeof *ic);
        clock_t t0, t1;
        if (!tc || !ic) return 0;
        memcpy(tc, tri0, n * sizeof *tc);
        memcpy(ic, info0, n * sizeof *ic);
        s->tri = tc;
        s->info = ic;
        k = b / 2;
        t0 = clock();
        if ((b % 2 ? appm__bvh_build(s, NULL) : appm__bvh_build_binary(s, NULL)) != APPM_OK) return 0;
        t1 = clock();
        (b % 2 ? full : bin)[k] = 1e3 * (double)(t1 - t0) / CLOCKS_PER_SEC;
        if (b + 1 < 2 * BUILDS) {
            appm__free(&s->mem, s->tri);
            appm__free(&s->mem, s->info);
            appm__free(&s->mem, s->node);
            if (b % 2) appm__free(&s->mem, s->wnode_mem);
        }
    }
    appm__free(&s->mem, tri0);
    appm__free(&s->mem, info0);
    *full_ms = median(full, BUILDS);
    *binary_ms = median(bin, BUILDS);
    return 1;
}

#define CHUNK 10000
#define WARM 5000

/* Traces rays [b, e) on the scene's current path; returns the hits and adds
 * the closest hits' t to *tsum. */
static long trace_range(const appm_scene *s, const appm__v3 *orig, const appm__v3 *dir, long b, long e, int anyhit,
                        double *tsum)
{
    long i, hits = 0;
    for (i = b; i < e; ++i) {
        appm__ray r;
        appm__hit h;
        appm__ray_init(&r, orig[i], dir[i], FLT_MAX);
        if (anyhit) {
            hits += appm__occluded(s, &r, UINT32_MAX, UINT32_MAX);
        } else if (appm__intersect(s, &r, UINT32_MAX, &h)) {
            hits++;
            *tsum += h.t;
        }
    }
    return hits;
}

/* Processor seconds per path for closest hits (anyhit = 0) or any hits of all
 * rays.  The paths take turns chunk by chunk (CHUNK rays), so that a change of
 * load during the run is shared by all of them, and in one turn each traces a
 * different chunk (path k at step c the chunk c + k nch / NPATH), so that no
 * path traces rays whose nodes and triangles another path has just brought
 * into the cache: tracing the very rays the path before traced made a path up
 * to 20 % faster.  Before its timed chunk each path traces, untimed, WARM rays
 * of a chunk no path has traced lately, so its own tree is in the cache as it
 * is when a renderer uses only that path (two runs of the same code in a row,
 * otherwise, differed by 5-10 %).  checksum sums t chunk by chunk in chunk
 * order, so it is the same sum for every path. */
static void trace(appm_scene *s, const appm__v3 *orig, const appm__v3 *dir, long nrays, int anyhit,
                  double *sec, long *hits, double *checksum)
{
    long nch = (nrays + CHUNK - 1) / CHUNK, c;
    double *part = (double *)calloc((size_t)(nch * NPATH), sizeof *part), dummy = 0.0;
    int k;
    for (k = 0; k < NPATH; ++k) {
        sec[k] = checksum[k] = 0.0;
        hits[k] = 0;
    }
    if (!part) return;
    for (c = 0; c < nch; ++c) {
        for (k = 0; k < NPATH; ++k) {
            long ch = (c + k * nch / NPATH) % nch, wc = (ch + nch / (2 * NPATH) + 1) % nch;
            long b = ch * CHUNK, e = b + CHUNK < nrays ? b + CHUNK : nrays;
            long wb = wc * CHUNK, we = wb + WARM < nrays ? wb + WARM : nrays;
            clock_t t0;
            s->bvh_path = path_id[k];
            (void)trace_range(s, orig, dir, wb, we, anyhit, &dummy);
            t0 = clock();
            hits[k] += trace_range(s, orig, dir, b, e, anyhit, &part[k * nch + ch]);
            sec[k] += (double)(clock() - t0) / CLOCKS_PER_SEC;
        }
    }
    for (k = 0; k < NPATH; ++k)
        for (c = 0; c < nch; ++c) checksum[k] += part[k * nch + c];
    free(part);
}

/* Photon paths per second of the photon pass alone, per path: one renderer
 * per path (each on its own copy of the scene), 3 ppm passes each, the
 * renderers taking turns pass by pass. */
static void photon_rates(appm_scene **ps, unsigned threads, uint32_t size, double *rate)
{
    appm_renderer *r[NPATH];
    appm_config cfg;
    int k, p;
    appm_config_init(&cfg);
    cfg.method = APPM_METHOD_PPM;
    cfg.width = cfg.height = size;
    cfg.threads = threads;
    for (k = 0; k < NPATH; ++k) {
        ps[k]->bvh_path = path_id[k];
        r[k] = NULL;
        if (appm_renderer_create(ps[k], &cfg, &r[k], NULL) != APPM_OK) r[k] = NULL;
    }
    for (p = 0; p < 3; ++p)
        for (k = 0; k < NPATH; ++k)
            if (r[k]) appm_renderer_pass(r[k]);
    for (k = 0; k < NPATH; ++k) {
        appm_stats st;
        appm_renderer_stats(r[k], &st);
        rate[k] = st.seconds_photons > 0.0 ? (double)st.photons_emitted / st.seconds_photons : 0.0;
        appm_renderer_destroy(r[k]);
    }
}

int main(int argc, char **argv)
{
    const char *mesh = argc > 1 ? argv[1] : "scenes/stanford-bunny.obj";
    long nrays = argc > 2 ? atol(argv[2]) : 1000000L, i;
    const char *pscene = argc > 3 ? argv[3] : "scenes/cornell-sphere.scene";
    uint32_t size = argc > 4 ? (uint32_t)atol(argv[4]) : 512;
    double closest[NPATH][ROUNDS_MAX], anyhit[NPATH][ROUNDS_MAX], ph1[NPATH][ROUNDS_MAX], ph2[NPATH][ROUNDS_MAX];
    double med[4][NPATH], checksum[NPATH], cs[NPATH], sec[NPATH], rate[NPATH], full_ms, bin_ms;
    long hits[NPATH], ahits[NPATH];
    appm_scene *s = load_mesh(mesh), *ps[NPATH];
    appm__v3 *orig, *dir;
    appm_diag d;
    appm__rng rng;
    const char *env = getenv("BVH_ROUNDS");
    int k, round, rounds = env ? atoi(env) : 3;
    if (rounds < 1 || rounds > ROUNDS_MAX) {
        fprintf(stderr, "bvh_bench: BVH_ROUNDS must be 1 to %d\n", ROUNDS_MAX);
        return 1;
    }
    if (!s) return 1;
    if (!time_builds(s, &full_ms, &bin_ms)) {
        fprintf(stderr, "bvh_bench: build failed\n");
        return 1;
    }
    for (k = 0; k < NPATH; ++k)
        if (appm_scene_load(pscene, NULL, &ps[k], &d) != APPM_OK) {
            fprintf(stderr, "bvh_bench: %s:%u: %s\n", d.file, d.line, d.message);
            return 1;
        }

    /* Rays, drawn up front, each draw in its own statement so that the ray
     * set does not depend on the compiler's order of evaluating arguments. */
    orig = (appm__v3 *)malloc((size_t)nrays * sizeof *orig);
    dir = (appm__v3 *)malloc((size_t)nrays * sizeof *dir);
    if (!orig || !dir || nrays < 1) {
        fprintf(stderr, "bvh_bench: out of memory\n");
        return 1;
    }
    appm__rng_seed(&rng, 1, 0, APPM__DOMAIN_TEST, 0);
    for (i = 0; i < nrays; ++i) {
        float u1 = appm__rng_float(&rng), u2 = appm__rng_float(&rng), u3 = appm__rng_float(&rng);
        float u4 = appm__rng_float(&rng), u5 = appm__rng_float(&rng);
        orig[i] = appm__v(s->bmin.x + u1 * (s->bmax.x - s->bmin.x), s->bmin.y + u2 * (s->bmax.y - s->bmin.y),
                          s->bmin.z + u3 * (s->bmax.z - s->bmin.z));
        dir[i] = appm__uniform_sphere(u4, u5);
    }
    for (round = 0; round < rounds; ++round) {
        trace(s, orig, dir, nrays, 0, sec, hits, checksum);
        for (k = 0; k < NPATH; ++k) closest[k][round] = (double)nrays / sec[k];
        trace(s, orig, dir, nrays, 1, sec, ahits, cs);
        for (k = 0; k < NPATH; ++k) anyhit[k][round] = (double)nrays / sec[k];
        photon_rates(ps, 1, size, rate);
        for (k = 0; k < NPATH; ++k) ph1[k][round] = rate[k];
        photon_rates(ps, 2, size, rate);
        for (k = 0; k < NPATH; ++k) ph2[k][round] = rate[k];
    }
    for (k = 0; k < NPATH; ++k) {
        med[0][k] = median(closest[k], rounds);
        med[1][k] = median(anyhit[k], rounds);
        med[2][k] = median(ph1[k], rounds);
        med[3][k] = median(ph2[k], rounds);
        printf("path=%s closest_per_s=%.0f anyhit_per_s=%.0f photon_per_s_1t=%.0f photon_per_s_2t=%.0f "
               "checksum=%.9g\n",
               path_name[k], med[0][k], med[1][k], med[2][k], med[3][k], checksum[k]);
    }
    printf("rounds=%d simd=%s width=%d bvh_build_ms=%.2f binary_build_ms=%.2f build_ratio=%.3f closest_ratio=%.3f "
           "anyhit_ratio=%.3f photon_ratio_1t=%.3f photon_ratio_2t=%.3f scalar_closest_ratio=%.3f "
           "scalar_anyhit_ratio=%.3f triangles=%u nodes=%u wide_nodes=%u depth=%u hit_fraction=%.4f "
           "anyhit_fraction=%.4f sah_cost=%.2f\n",
           rounds, APPM__SIMD_NAME, APPM__BVH_W, full_ms, bin_ms, full_ms / bin_ms, med[0][2] / med[0][0],
           med[1][2] / med[1][0], med[2][2] / med[2][0], med[3][2] / med[3][0], med[0][1] / med[0][0],
           med[1][1] / med[1][0], s->ntri, s->nnode, s->nwnode, s->depth, (double)hits[0] / (double)nrays,
           (double)ahits[0] / (double)nrays, sah_cost(s));
    free(orig);
    free(dir);
    for (k = 0; k < NPATH; ++k) appm_scene_destroy(ps[k]);
    appm_scene_destroy(s);
    return 0;
}
