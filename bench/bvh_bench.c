/* bench/bvh_bench.c - BVH build time and closest-hit throughput on one thread.
 *
 *   cc -std=c99 -O2 bench/bvh_bench.c -o build/bvh_bench -lm -pthread
 *   ./build/bvh_bench [MESH.obj [RAYS]]      (default scenes/stanford-bunny.obj, 1e6)
 *
 * Prints one line of key=value pairs:
 *   bvh_build_ms  median of 5 builds of the loaded triangles (appm__bvh_build on
 *                 a fresh copy each time; the input is in the order the loader
 *                 left it, i.e. the previous build's leaf order)
 *   rays_per_s    closest hits (appm__ray_init + appm__intersect) per second for
 *                 RAYS rays with origins uniform in the bounding box and uniform
 *                 directions; the rays are drawn before the clock starts
 *   triangles, nodes, depth, hit_fraction (of those rays), sah_cost (the tree's
 *   surface-area cost: node visits plus triangle tests expected for a random
 *   line through the root box, a quality figure independent of the machine).
 * Timing is wall-clock (CLOCK_MONOTONIC); run on an idle machine.
 */
#include "../appm.c"

#include <stdio.h>

#define BUILDS 5

static int cmp_double(const void *a, const void *b)
{
    double x = *(const double *)a, y = *(const double *)b;
    return (x > y) - (x < y);
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

int main(int argc, char **argv)
{
    const char *mesh = argc > 1 ? argv[1] : "scenes/stanford-bunny.obj";
    long nrays = argc > 2 ? atol(argv[2]) : 1000000L, i, hits = 0;
    const char *tmp = "appm-bvh-bench.scene.tmp";
    appm_scene *s = NULL;
    appm_diag d;
    FILE *f;
    double ms[BUILDS], t0, t1, checksum = 0.0;
    appm__tri *tri0;
    appm__tri_info *info0;
    appm__node *node0;
    uint32_t n;
    appm__v3 *orig, *dir;
    appm__rng rng;
    int b;

    /* A bare OBJ without emitters is not a valid scene (it has no light), so
     * wrap it in a scene file with a point light; mesh paths in a scene file
     * are relative to its folder, here the current one. */
    f = fopen(tmp, "wb");
    if (!f) {
        fprintf(stderr, "bvh_bench: cannot write %s\n", tmp);
        return 1;
    }
    fprintf(f, "mesh %s\nlight point position 0 1 0 intensity 1 1 1\n", mesh);
    fclose(f);
    if (appm_scene_load(tmp, NULL, &s, &d) != APPM_OK) {
        fprintf(stderr, "bvh_bench: %s:%u: %s\n", d.file, d.line, d.message);
        remove(tmp);
        return 1;
    }
    remove(tmp);
    n = s->ntri;
    if (n == 0) {
        fprintf(stderr, "bvh_bench: no triangles\n");
        appm_scene_destroy(s);
        return 1;
    }

    /* Builds: the loaded arrays are set aside; each build gets copies, which
     * appm__bvh_build frees after writing its reordered ones. */
    tri0 = s->tri;
    info0 = s->info;
    node0 = s->node;
    for (b = 0; b < BUILDS; ++b) {
        appm__tri *tc = (appm__tri *)appm__alloc(&s->mem, n, sizeof *tc);
        appm__tri_info *ic = (appm__tri_info *)appm__alloc(&s->mem, n, sizeof *ic);
        if (!tc || !ic) {
            fprintf(stderr, "bvh_bench: out of memory\n");
            return 1;
        }
        memcpy(tc, tri0, n * sizeof *tc);
        memcpy(ic, info0, n * sizeof *ic);
        s->tri = tc;
        s->info = ic;
        t0 = appm__seconds();
        if (appm__bvh_build(s, NULL) != APPM_OK) {
            fprintf(stderr, "bvh_bench: build failed\n");
            return 1;
        }
        t1 = appm__seconds();
        ms[b] = 1e3 * (t1 - t0);
        if (b + 1 < BUILDS) {
            appm__free(&s->mem, s->tri);
            appm__free(&s->mem, s->info);
            appm__free(&s->mem, s->node);
        }
    }
    /* keep the last build (equal to the first: the build is deterministic) */
    appm__free(&s->mem, tri0);
    appm__free(&s->mem, info0);
    appm__free(&s->mem, node0);
    qsort(ms, BUILDS, sizeof ms[0], cmp_double);

    /* Rays, drawn up front. */
    orig = (appm__v3 *)malloc((size_t)nrays * sizeof *orig);
    dir = (appm__v3 *)malloc((size_t)nrays * sizeof *dir);
    if (!orig || !dir) {
        fprintf(stderr, "bvh_bench: out of memory\n");
        return 1;
    }
    appm__rng_seed(&rng, 1, 0, APPM__DOMAIN_TEST, 0);
    for (i = 0; i < nrays; ++i) {
        float u1 = appm__rng_float(&rng), u2 = appm__rng_float(&rng), u3 = appm__rng_float(&rng);
        orig[i] = appm__v(s->bmin.x + u1 * (s->bmax.x - s->bmin.x), s->bmin.y + u2 * (s->bmax.y - s->bmin.y),
                          s->bmin.z + u3 * (s->bmax.z - s->bmin.z));
        dir[i] = appm__uniform_sphere(appm__rng_float(&rng), appm__rng_float(&rng));
    }
    t0 = appm__seconds();
    for (i = 0; i < nrays; ++i) {
        appm__ray r;
        appm__hit h;
        appm__ray_init(&r, orig[i], dir[i], FLT_MAX);
        if (appm__intersect(s, &r, UINT32_MAX, &h)) {
            hits++;
            checksum += h.t;
        }
    }
    t1 = appm__seconds();

    printf("bvh_build_ms=%.2f rays_per_s=%.0f triangles=%u nodes=%u depth=%u hit_fraction=%.4f sah_cost=%.2f "
           "build_ms_min=%.2f build_ms_max=%.2f checksum=%.6g\n",
           ms[BUILDS / 2], (double)nrays / (t1 - t0), s->ntri, s->nnode, s->depth, (double)hits / (double)nrays,
           sah_cost(s), ms[0], ms[BUILDS - 1], checksum);
    free(orig);
    free(dir);
    appm_scene_destroy(s);
    return 0;
}
