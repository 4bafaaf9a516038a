/* bench/seammass.c - the kernel mass the seam model of appm.c 10.5 divides by,
 * against the true mass on the floor, found by casting rays (docs/algorithm.md
 * 4.19).  For scenes whose floor is the plane y = 0 with normal +y
 * (CornellBox-Original, ...).
 *
 *   cc -std=c99 -O2 bench/seammass.c -o bench/seammass -lm -pthread
 *   bench/seammass SCENE SIZE PASSES
 *
 * After PASSES passes of appm at SIZE x SIZE (seed 11, 1 thread), for every
 * pixel whose visible point lies on the floor, seen directly: the model's mass
 * m (appm__cut_lines, appm__cut_mass at the pixel's radius R) and the true one,
 * the biweight's weight over a 120 x 120 grid of the disc of radius R counting
 * the points where the floor goes on (a ray down finds it within 0.02 and a ray
 * up meets nothing for 1.5).  Prints the pixels where the estimate's factor
 * (true m) / (model m) is off by more than 15 %, then the count of pixels over
 * 1.15 and under 0.87. */
#include "../appm.c"
#include <stdio.h>

static const appm_scene *scene_;

static int cast(appm__v3 o, appm__v3 dir, float *t)
{
    appm__ray ry;
    appm__hit h;
    memset(&ry, 0, sizeof ry);
    ry.o = o;
    ry.d = dir;
    ry.tmin = 0.0f;
    ry.tmax = 1e30f;
    appm__ray_setup(&ry);
    if (!appm__intersect(scene_, &ry, UINT32_MAX, &h)) return 0;
    *t = h.t;
    return 1;
}

static int on_floor(float x, float z)
{
    float t;
    if (!cast(appm__v(x, 0.01f, z), appm__v(0, -1, 0), &t) || t > 0.02f) return 0;
    return !cast(appm__v(x, 0.001f, z), appm__v(0, 1, 0), &t) || t > 1.5f;
}

int main(int argc, char **argv)
{
    appm_scene *s = NULL;
    appm_diag d;
    appm_config cfg;
    appm_renderer *r = NULL;
    int S, P, x, y, p, over = 0, under = 0, n = 0;
    if (argc < 4 || (S = atoi(argv[2])) < 4 || (P = atoi(argv[3])) < 1) {
        fprintf(stderr, "usage: seammass SCENE SIZE PASSES\n");
        return 2;
    }
    if (appm_scene_load(argv[1], NULL, &s, &d) != APPM_OK) {
        fprintf(stderr, "%s\n", d.message);
        return 1;
    }
    scene_ = s;
    appm_config_init(&cfg);
    cfg.width = cfg.height = (uint32_t)S;
    cfg.threads = 1;
    cfg.seed = 11;
    if (appm_renderer_create(s, &cfg, &r, &d) != APPM_OK) {
        fprintf(stderr, "%s\n", d.message);
        return 1;
    }
    for (p = 0; p < P; ++p) appm_renderer_pass(r);
    for (y = 0; y < S; ++y)
        for (x = 0; x < S; ++x) {
            size_t i = (size_t)y * (size_t)S + (size_t)x;
            const appm__vp *vp = &r->vp[i];
            appm__gather g;
            double m, tm, in = 0.0, all = 0.0, f;
            int a, b, k = 120;
            if (vp->segs != 1 || !(vp->n.y > 0.99f) || !(fabsf(vp->x.y) < 1e-3f)) continue;
            memset(&g, 0, sizeof g);
            g.x = vp->x;
            g.n = vp->n;
            appm__basis(vp->n, &g.t, &g.b);
            g.biweight = 1;
            appm__cut_lines(r, i, &g);
            m = appm__cut_mass(&g, vp->R);
            for (a = 0; a < k; ++a)
                for (b = 0; b < k; ++b) {
                    double u = -1.0 + (a + 0.5) * 2.0 / k, v = -1.0 + (b + 0.5) * 2.0 / k, q = u * u + v * v, w;
                    if (q >= 1.0) continue;
                    w = (1.0 - q) * (1.0 - q);
                    all += w;
                    if (on_floor(vp->x.x + vp->R * (float)u, vp->x.z + vp->R * (float)v)) in += w;
                }
            tm = in / all;
            f = tm / m;
            n++;
            if (f > 1.15 || f < 0.87)
                printf("px(%d,%d) lines %d model m %.3f true m %.3f: estimate x%.2f\n", x, y, g.ncut, m, tm, f);
            over += f > 1.15;
            under += f < 0.87;
        }
    printf("%s %dx%d after %d passes: %d floor pixels, %d over 1.15, %d under 0.87\n", argv[1], S, S, P, n, over, under);
    appm_renderer_destroy(r);
    appm_scene_destroy(s);
    return 0;
}
