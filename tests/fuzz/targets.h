/* tests/fuzz/targets.h - the six fuzz entry points of appm's readers, shared by
 * the libFuzzer program (tests/fuzz/fuzz.c) and the regression replayer
 * (tests/t_fuzz_regress.c).  Include it after appm.c.
 *
 *   fuzz_obj_one    input split at the first NUL into OBJ and MTL text, loaded by
 *                   appm_scene_load_obj_memory; the raw bytes also go through a
 *                   loader to appm__obj_parse, whose arrays are then checked
 *   fuzz_mtl_one    appm__mtl_parse through a loader (materials checked), then a
 *                   generated OBJ that uses every material, loaded and rendered
 *   fuzz_scene_one  appm__scene_parse through a loader, finished into a scene
 *                   (as appm__scene_load does) and rendered when it loads
 *   fuzz_pfm_one    appm__pfm_parse; a parsed image must survive a write/read
 *                   round trip bit for bit
 *   fuzz_checkpoint_one  appm_renderer_load into a fresh renderer of a fixed
 *                   scene, as given and with its checksum made right; a
 *                   refused checkpoint leaves the renderer fresh, an accepted
 *                   one saves back to the same bytes and renders a pass
 *   fuzz_image_one  appm__image_decode (every image format appm reads); the
 *                   first byte picks the name (x.tga or x.img) and whether a
 *                   PNG's chunk CRCs are made right; pixels and memory checked;
 *                   a small image also built and sampled as an environment map
 *
 * Each returns the status of its main call (>= 0) when everything the library
 * promises held, or FUZZ_BAD (-1) after printing what did not:
 *   - the status is a valid appm_status and the appm_diag agrees with it (same
 *     status, a NUL-terminated message, no output object after a failure);
 *   - every byte taken from cfg.allocator is given back, with the size that was
 *     asked for (so leaks show up even without LeakSanitizer);
 *   - reader-specific invariants (see the fuzz__check_* functions).
 * The libFuzzer programs abort() on FUZZ_BAD, so it is reported as a crash.
 *
 * Every input runs a second time with one allocation made to fail (which one
 * is derived from the input's bytes): the result must then be APPM_ERR_NOMEM,
 * with nothing leaked.  A bare OBJ without light is lit by the studio for one
 * input in eight (by the hash; corpus/obj/no-light-studio.obj is one), by the
 * white stand-in otherwise.  Whatever loads is rendered: 4x4 pixels, 32
 * photons, two passes, one thread, the method chosen by the input's hash.
 *
 * Hermetic: every file name points into a folder that does not exist, the MTL
 * text of in-memory loads is always given (so `mtllib` never opens a file), and
 * absolute `mesh` paths of .scene input are made relative before parsing.  So
 * no input can make a reader open a real file; `mesh` always fails with
 * APPM_ERR_IO, harmlessly.  Buffers are exact-size copies, so ASan sees a read
 * one byte past the end of any of them.
 *
 * fuzz__scene_from_buffer goes through appm__scene_load (section 12). */
#ifndef APPM_FUZZ_TARGETS_H
#define APPM_FUZZ_TARGETS_H

#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define FUZZ_BAD (-1)
#define FUZZ_DIR "/nonexistent-appm-fuzz/"

/* ---- Counting allocator ---------------------------------------------------- */

typedef struct fuzz_alloc {
    long count, fail_at; /* fail allocation number fail_at (1-based; 0: never) */
    int failed;          /* an allocation was refused */
    int bad_free;        /* a free hook got a size other than the one allocated */
    long long live;
} fuzz_alloc;

#define FUZZ__HEADER 16

static void *fuzz__alloc_fn(void *user, size_t n)
{
    fuzz_alloc *a = (fuzz_alloc *)user;
    unsigned char *p;
    a->count++;
    if (a->fail_at > 0 && a->count == a->fail_at) {
        a->failed = 1;
        return NULL;
    }
    if (((uint64_t)n >> 40) != 0) return NULL; /* absurd (1 TiB): never reached by a sane reader */
    p = (unsigned char *)malloc(n + FUZZ__HEADER);
    if (!p) return NULL;
    memcpy(p, &n, sizeof n);
    a->live += (long long)n;
    return p + FUZZ__HEADER;
}

static void fuzz__free_fn(void *user, void *ptr, size_t n)
{
    fuzz_alloc *a = (fuzz_alloc *)user;
    unsigned char *p;
    size_t asked;
    if (!ptr) return;
    p = (unsigned char *)ptr - FUZZ__HEADER;
    memcpy(&asked, p, sizeof asked);
    if (asked != n) a->bad_free = 1;
    a->live -= (long long)asked;
    free(p);
}

static void fuzz__log_fn(void *user, const char *file, unsigned line, const char *message)
{
    int *bad = (int *)user;
    (void)line;
    if (!file || !message || !memchr(message, 0, 4096) || !memchr(file, 0, 4096)) *bad = 1;
}

typedef struct fuzz_env {
    fuzz_alloc a;
    appm_config cfg;
    appm_diag diag;
    int log_bad;
} fuzz_env;

static void fuzz__env_init(fuzz_env *e, long fail_at)
{
    memset(e, 0, sizeof *e);
    e->a.fail_at = fail_at;
    e->cfg.allocator.alloc = fuzz__alloc_fn;
    e->cfg.allocator.free = fuzz__free_fn;
    e->cfg.allocator.user = &e->a;
    e->cfg.log = fuzz__log_fn;
    e->cfg.log_user = &e->log_bad;
    memset(&e->diag, 0x5A, sizeof e->diag); /* the library must overwrite it */
}

static int fuzz__bad(const char *target, const char *what)
{
    fprintf(stderr, "fuzz %s: invariant broken: %s\n", target, what);
    return FUZZ_BAD;
}

/* FNV-1a of the input: picks the render method and the allocation to fail. */
static uint32_t fuzz__hash(const unsigned char *p, size_t n)
{
    uint32_t h = 2166136261u;
    size_t i;
    for (i = 0; i < n; ++i) h = (h ^ p[i]) * 16777619u;
    return h;
}

/* An exact-size heap copy (at least one byte, so that the pointer is never NULL). */
static char *fuzz__dup(const void *p, size_t n)
{
    char *c = (char *)malloc(n ? n : 1);
    if (!c) abort();
    if (n) memcpy(c, p, n);
    return c;
}

static int fuzz__status_ok(int st) { return st >= 0 && st < (int)APPM_STATUS_COUNT; }

/* The diag after a call that returned `st`. */
static int fuzz__check_diag(const char *target, const appm_diag *d, appm_status st)
{
    if (!fuzz__status_ok((int)st)) return fuzz__bad(target, "status out of range");
    if (d->status != st) return fuzz__bad(target, "diag.status differs from the returned status");
    if (!memchr(d->message, 0, sizeof d->message) || !memchr(d->file, 0, sizeof d->file))
        return fuzz__bad(target, "diag strings not NUL-terminated");
    if (st != APPM_OK && d->message[0] == 0) return fuzz__bad(target, "error without a message");
    return 0;
}

/* What is left after every object was destroyed. */
static int fuzz__check_env(const char *target, const fuzz_env *e)
{
    if (e->a.live != 0) {
        fprintf(stderr, "fuzz %s: %lld bytes leaked through the allocator\n", target, e->a.live);
        return FUZZ_BAD;
    }
    if (e->a.bad_free) return fuzz__bad(target, "free hook got a wrong size");
    if (e->log_bad) return fuzz__bad(target, "log callback got a bad file or message");
    return 0;
}

/* Two passes of a tiny render; returns the first failing status. */
static appm_status fuzz__render(const char *target, fuzz_env *e, const appm_scene *scene,
                                uint32_t h, int *bad)
{
    appm_config c = e->cfg;
    appm_renderer *r = (appm_renderer *)&r; /* must be overwritten */
    appm_diag d;
    appm_status st;
    appm_image img;
    int pass;
    c.width = c.height = 4;
    c.photons = 32;
    c.threads = 1;
    c.max_depth = 6;
    c.method = (appm_method)(h % 4u);
    c.direct = (appm_direct)((h >> 2) & 1u);
    c.seed = h >> 3;
    st = appm_renderer_create(scene, &c, &r, &d);
    if (fuzz__check_diag(target, &d, st)) *bad = 1;
    if (st != APPM_OK) {
        if (r) *bad = fuzz__bad(target, "renderer returned after a failure");
        return st;
    }
    if (!r) {
        *bad = fuzz__bad(target, "no renderer after success");
        return st;
    }
    for (pass = 0; pass < 2 && st == APPM_OK; ++pass) st = appm_renderer_pass(r);
    if (!fuzz__status_ok((int)st)) *bad = fuzz__bad(target, "pass status out of range");
    if (st == APPM_OK) {
        appm_renderer_image(r, &img);
        if (img.width != 4 || img.height != 4 || !img.rgb)
            *bad = fuzz__bad(target, "rendered image has the wrong size");
    }
    appm_renderer_destroy(r);
    return st;
}

/* Invariants of a loaded scene (section 4 and 12: no zero-area or non-finite
 * triangle, valid material and light indices, a light CDF ending at 1). */
static int fuzz__check_scene(const char *target, const appm_scene *s)
{
    uint32_t i, area_lights = 0;
    appm_scene_info info;
    if (s->width < 1 || s->width > 32768 || s->height < 1 || s->height > 32768)
        return fuzz__bad(target, "scene image size out of range");
    if (s->nlight == 0 || !s->light || !s->light_cdf)
        return fuzz__bad(target, "scene without lights");
    for (i = 0; i < s->ntri; ++i) {
        const appm__tri *t = &s->tri[i];
        const appm__tri_info *in = &s->info[i];
        if (!appm__finite3(t->p0) || !appm__finite3(t->p1) || !appm__finite3(t->p2))
            return fuzz__bad(target, "non-finite vertex in the scene");
        if (!(in->area > 0.0f) || !(in->area < FLT_MAX))
            return fuzz__bad(target, "bad triangle area");
        if (in->mat >= s->nmat) return fuzz__bad(target, "material index out of range");
        if (in->light >= 0 && (uint32_t)in->light >= s->nlight)
            return fuzz__bad(target, "light index out of range");
        if (in->n0 >= 0 && (uint32_t)in->n0 + 3 > s->nnormals)
            return fuzz__bad(target, "shading normal index out of range");
        area_lights += s->mat[in->mat].emissive;
    }
    for (i = 0; i < s->nlight; ++i)
        if (!(s->light_cdf[i + 1] >= s->light_cdf[i] - 1e-12))
            return fuzz__bad(target, "light CDF not monotone");
    if (s->light_cdf[s->nlight] != 1.0) return fuzz__bad(target, "light CDF does not end at 1");
    if (!(s->cam.tan_half > 0.0f) || !(s->cam.tan_half < FLT_MAX))
        return fuzz__bad(target, "bad camera");
    appm_scene_get_info(s, &info);
    if (info.triangles != s->ntri || info.lights_area != area_lights)
        return fuzz__bad(target, "scene info disagrees with the scene");
    return 0;
}

/* Load result -> checks -> tiny render -> destroy.  Returns the first failing
 * status of the chain (load, renderer, passes) or FUZZ_BAD. */
static int fuzz__after_load(const char *target, fuzz_env *e, appm_status st, appm_scene *scene,
                            uint32_t h)
{
    int bad = 0;
    if (fuzz__check_diag(target, &e->diag, st)) bad = 1;
    if (st != APPM_OK && scene) {
        bad = fuzz__bad(target, "scene returned after a failure");
        scene = NULL; /* not ours to destroy */
    }
    if (st == APPM_OK && !scene) bad = fuzz__bad(target, "no scene after success");
    if (st == APPM_OK && scene) {
        if (fuzz__check_scene(target, scene)) bad = 1;
        st = fuzz__render(target, e, scene, h, &bad);
    }
    appm_scene_destroy(scene);
    if (fuzz__check_env(target, e)) bad = 1;
    return bad ? FUZZ_BAD : (int)st;
}

/* Runs `run(ctx, env)` normally, then again with one allocation failing. */
typedef int (*fuzz__run_fn)(const void *ctx, fuzz_env *e);

static int fuzz__twice(const char *target, fuzz__run_fn run, const void *ctx, uint32_t h)
{
    /* A bare OBJ gets the studio (its sky map costs more than the rest of a
     * small input's load under the fuzzer's instrumentation) for one input in
     * eight, the white furnace for the others: both stay covered. */
    const appm_stand_in stand_in = (h >> 28) % 8u == 0 ? APPM_STAND_IN_STUDIO : APPM_STAND_IN_WHITE;
    fuzz_env e;
    int st, st2;
    long n;
    fuzz__env_init(&e, 0);
    e.cfg.stand_in = stand_in;
    st = run(ctx, &e);
    n = e.a.count;
    if (st == FUZZ_BAD || n == 0) return st;
    fuzz__env_init(&e, 1 + (long)(h % (uint32_t)n));
    e.cfg.stand_in = stand_in;
    st2 = run(ctx, &e);
    if (st2 == FUZZ_BAD) return FUZZ_BAD;
    if (e.a.failed && st2 != APPM_ERR_NOMEM) {
        fprintf(stderr, "fuzz %s: allocation %ld of %ld failed, yet the status is %d, not NOMEM\n",
                target, e.a.fail_at, n, st2);
        return FUZZ_BAD;
    }
    return st;
}

/* ---- Loader set-up (as appm__scene_load does it) ---------------------------- */

static void fuzz__mem_begin(appm__mem *m, fuzz_env *e)
{
    appm__mem_init(m, &e->cfg);
    m->diag = &e->diag;
    appm__diag_clear(&e->diag);
}

/* `m` comes from fuzz__mem_begin. */
static appm_status fuzz__loader_begin(appm__loader *L, appm__mem *m, fuzz_env *e, const char *file)
{
    return appm__loader_begin(L, m, &e->cfg, &e->diag, file);
}

/* Materials after appm__mtl_parse: names inside the pool, kinds known, colours
 * clamped to [0,1], Ke finite and >= 0, Ni in (0,100]; glossy: Kd + Ks <= 1,
 * Ns in (0, 1e5]. */
static int fuzz__check_materials(const char *target, const appm__loader *L)
{
    size_t i;
    for (i = 0; i < L->mat.count; ++i) {
        const appm__material *m = (const appm__material *)L->mat.data + i;
        const float c[3] = {m->color.x, m->color.y, m->color.z};
        int k;
        if (m->name >= L->names.count ||
            !memchr((const char *)L->names.data + m->name, 0, L->names.count - m->name))
            return fuzz__bad(target, "material name outside the name pool");
        if (m->kind < APPM__MAT_DIFFUSE || m->kind > APPM__MAT_GLOSSY)
            return fuzz__bad(target, "unknown material kind");
        if (m->kind == APPM__MAT_GLOSSY) { /* Ks in [0,1], Kd + Ks <= 1 per channel, Ns in (0, 1e5] */
            const float s[3] = {m->ks.x, m->ks.y, m->ks.z};
            for (k = 0; k < 3; ++k)
                if (!(s[k] >= 0.0f && s[k] <= 1.0f && c[k] + s[k] <= 1.0f + 1e-6f))
                    return fuzz__bad(target, "glossy Ks outside [0,1] or Kd + Ks > 1");
            if (!(m->ns > 0.0f && m->ns <= 1e5f)) return fuzz__bad(target, "Ns out of range");
        }
        for (k = 0; k < 3; ++k)
            if (!(c[k] >= 0.0f && c[k] <= 1.0f))
                return fuzz__bad(target, "reflectance outside [0,1]");
        if (!appm__finite3(m->ke) || m->ke.x < 0 || m->ke.y < 0 || m->ke.z < 0)
            return fuzz__bad(target, "bad Ke");
        if (m->emissive != (m->ke.x > 0 || m->ke.y > 0 || m->ke.z > 0))
            return fuzz__bad(target, "emissive flag disagrees with Ke");
        if (!(m->ior > 0.0f && m->ior <= 100.0f)) return fuzz__bad(target, "Ni out of range");
    }
    return 0;
}

/* Triangles after appm__obj_parse: one info per triangle, valid indices, finite
 * vertices, positive area, unit geometric and shading normals. */
static int fuzz__check_triangles(const char *target, const appm__loader *L)
{
    size_t i;
    if (L->tri.count != L->info.count) return fuzz__bad(target, "triangle and info counts differ");
    if (L->nrm.count % 3 != 0) return fuzz__bad(target, "shading normals not in threes");
    for (i = 0; i < L->tri.count; ++i) {
        const appm__tri *t = (const appm__tri *)L->tri.data + i;
        const appm__tri_info *in = (const appm__tri_info *)L->info.data + i;
        float len = appm__length(in->ng);
        if (!appm__finite3(t->p0) || !appm__finite3(t->p1) || !appm__finite3(t->p2))
            return fuzz__bad(target, "non-finite vertex kept");
        if (!(in->area > 0.0f) || !(in->area < FLT_MAX))
            return fuzz__bad(target, "bad triangle area");
        if (!(fabsf(len - 1.0f) < 1e-3f)) return fuzz__bad(target, "geometric normal not unit");
        if (in->mat >= L->mat.count) return fuzz__bad(target, "material index out of range");
        if (in->light != -1) return fuzz__bad(target, "light index set while loading");
        if (in->n0 != -1) {
            int k;
            if (in->n0 < 0 || (size_t)in->n0 + 3 > L->nrm.count)
                return fuzz__bad(target, "shading normal index out of range");
            for (k = 0; k < 3; ++k) {
                float nl = appm__length(((const appm__v3 *)L->nrm.data)[in->n0 + k]);
                if (!(fabsf(nl - 1.0f) < 1e-3f))
                    return fuzz__bad(target, "shading normal not unit");
            }
        }
    }
    return 0;
}

/* ---- OBJ --------------------------------------------------------------------- */

typedef struct fuzz__buf2 {
    const char *a, *b;
    size_t alen, blen;
    uint32_t h;
} fuzz__buf2;

/* The common case of a target with one input: a NUL-terminated copy of the
 * data (edited in place by `prep` when given), run twice by fuzz__twice. */
static int fuzz__twice_one(const char *target, fuzz__run_fn run, void (*prep)(char *, size_t),
                           const unsigned char *data, size_t size)
{
    char *buf = fuzz__dup(data, size);
    fuzz__buf2 in;
    int st;
    if (prep) prep(buf, size);
    in.a = buf;
    in.alen = size;
    in.b = NULL;
    in.blen = 0;
    in.h = fuzz__hash(data, size);
    st = fuzz__twice(target, run, &in, in.h);
    free(buf);
    return st;
}

static int fuzz__obj_public(const void *ctx, fuzz_env *e)
{
    const fuzz__buf2 *in = (const fuzz__buf2 *)ctx;
    appm_scene *scene = (appm_scene *)&scene; /* must be overwritten */
    appm_status st = appm_scene_load_obj_memory(in->a, in->alen, in->b, in->blen,
                                                FUZZ_DIR "fuzz.obj", &e->cfg, &scene, &e->diag);
    return fuzz__after_load("obj", e, st, scene, in->h);
}

/* appm__obj_parse through a loader (MTL text in memory), then the loader's arrays. */
static int fuzz__obj_loader(const void *ctx, fuzz_env *e)
{
    const fuzz__buf2 *in = (const fuzz__buf2 *)ctx;
    appm__mem m;
    appm__loader L;
    appm_status st;
    int bad = 0;
    fuzz__mem_begin(&m, e);
    st = fuzz__loader_begin(&L, &m, e, FUZZ_DIR "fuzz.obj");
    L.mem_mtl = in->b;
    L.mem_mtl_len = in->blen;
    if (st == APPM_OK) st = appm__obj_parse(&L, in->a, in->alen, FUZZ_DIR "fuzz.obj");
    if (st == APPM_OK && (fuzz__check_materials("obj", &L) || fuzz__check_triangles("obj", &L)))
        bad = 1;
    if (st != APPM_OK && st != APPM_ERR_NOMEM && fuzz__check_diag("obj", &e->diag, st)) bad = 1;
    if (!fuzz__status_ok((int)st)) bad = 1;
    appm__loader_free(&L);
    if (m.live != 0) bad = fuzz__bad("obj", "loader memory counter not back at 0");
    if (fuzz__check_env("obj", e)) bad = 1;
    return bad ? FUZZ_BAD : (int)st;
}

static int fuzz_obj_one(const unsigned char *data, size_t size)
{
    const unsigned char *nul = (const unsigned char *)memchr(data, 0, size);
    size_t olen = nul ? (size_t)(nul - data) : size;
    size_t mlen = nul ? size - olen - 1 : 0;
    char *obj = fuzz__dup(data, olen), *mtl = fuzz__dup(nul ? nul + 1 : data, mlen);
    char *raw = fuzz__dup(data, size);
    fuzz__buf2 split, whole;
    int st, st2 = APPM_OK;
    split.a = obj;
    split.alen = olen;
    split.b = mtl;
    split.blen = mlen;
    split.h = fuzz__hash(data, size);
    whole = split;
    whole.a = raw;
    whole.alen = size;
    whole.blen = 0; /* no MTL text: every mtllib reads an empty library */
    st = fuzz__twice("obj", fuzz__obj_public, &split, split.h);
    if (st != FUZZ_BAD) st2 = fuzz__twice("obj", fuzz__obj_loader, &whole, split.h);
    if (st != FUZZ_BAD && st2 != FUZZ_BAD && nul && st2 != APPM_ERR_PARSE)
        st2 = fuzz__bad("obj", "a NUL byte in OBJ text was not a parse error");
    if (st != FUZZ_BAD && st2 != FUZZ_BAD && nul)
        st2 = fuzz__twice("obj", fuzz__obj_loader, &split, split.h);
    free(obj);
    free(mtl);
    free(raw);
    return st2 == FUZZ_BAD ? FUZZ_BAD : st;
}

/* ---- MTL --------------------------------------------------------------------- */

static int fuzz__mtl_loader(const void *ctx, fuzz_env *e)
{
    const fuzz__buf2 *in = (const fuzz__buf2 *)ctx;
    appm__mem m;
    appm__loader L;
    appm_status st;
    int bad = 0;
    fuzz__mem_begin(&m, e);
    st = fuzz__loader_begin(&L, &m, e, FUZZ_DIR "fuzz.mtl");
    if (st == APPM_OK) st = appm__mtl_parse(&L, in->a, in->alen);
    if (st == APPM_OK && fuzz__check_materials("mtl", &L)) bad = 1;
    if (st != APPM_OK && st != APPM_ERR_NOMEM && fuzz__check_diag("mtl", &e->diag, st)) bad = 1;
    if (!fuzz__status_ok((int)st)) bad = 1;
    appm__loader_free(&L);
    if (m.live != 0) bad = fuzz__bad("mtl", "loader memory counter not back at 0");
    if (fuzz__check_env("mtl", e)) bad = 1;
    return bad ? FUZZ_BAD : (int)st;
}

static int fuzz__mtl_public(const void *ctx, fuzz_env *e)
{
    const fuzz__buf2 *in = (const fuzz__buf2 *)ctx;
    appm_scene *scene = (appm_scene *)&scene;
    appm_status st = appm_scene_load_obj_memory(in->b, in->blen, in->a, in->alen,
                                                FUZZ_DIR "fuzz.obj", &e->cfg, &scene, &e->diag);
    return fuzz__after_load("mtl", e, st, scene, in->h);
}

/* An OBJ with one quad per material name (first 8), plus a lamp.  The names are
 * read back from a parse of the MTL text. */
static char *fuzz__mtl_scene_obj(const char *mtl, size_t len, size_t *olen)
{
    fuzz_env e;
    appm__mem m;
    appm__loader L;
    size_t cap = 256, n = 0, i, count = 0;
    char *out;
    fuzz__env_init(&e, 0);
    fuzz__mem_begin(&m, &e);
    if (fuzz__loader_begin(&L, &m, &e, "fuzz.mtl") == APPM_OK &&
        appm__mtl_parse(&L, mtl, len) == APPM_OK)
        count = L.mat.count;
    for (i = 1; i < count && i <= 8; ++i)
        cap += strlen(appm__mat_name(&L, (const appm__material *)L.mat.data + i)) + 160;
    out = (char *)malloc(cap);
    if (!out) abort();
    n += (size_t)sprintf(out + n, "mtllib fuzz.mtl\nv -1 -1 -1\nv 1 -1 -1\nv 1 -1 1\nv -1 -1 1\n"
                                  "f 1 2 3 4\nusemtl __fuzz_lamp\nv -1 1 1\nv 1 1 1\nv 0 1 -1\n"
                                  "f -1 -2 -3\n");
    for (i = 1; i < count && i <= 8; ++i) {
        float z = -0.9f + 0.2f * (float)i;
        n += (size_t)sprintf(out + n,
                             "usemtl %s\nv -0.5 -0.5 %.2f\nv 0.5 -0.5 %.2f\nv 0.5 0.5 %.2f\n"
                             "vn 0 0 1\nf -3//1 -2//1 -1//1\n",
                             appm__mat_name(&L, (const appm__material *)L.mat.data + i), z, z, z);
    }
    appm__loader_free(&L);
    *olen = n;
    return out;
}

static int fuzz_mtl_one(const unsigned char *data, size_t size)
{
    static const char lamp[] = "\nnewmtl __fuzz_lamp\nKd 0 0 0\nKe 4 4 4\n";
    char *mtl = fuzz__dup(data, size), *mtl_lamp, *obj;
    fuzz__buf2 in;
    size_t olen;
    int st, st2 = APPM_OK;
    in.a = mtl;
    in.alen = size;
    in.b = NULL;
    in.blen = 0;
    in.h = fuzz__hash(data, size);
    st = fuzz__twice("mtl", fuzz__mtl_loader, &in, in.h);
    if (st == APPM_OK) {
        obj = fuzz__mtl_scene_obj(mtl, size, &olen);
        mtl_lamp = (char *)malloc(size + sizeof lamp - 1);
        if (!mtl_lamp) abort();
        if (size) memcpy(mtl_lamp, data, size);
        memcpy(mtl_lamp + size, lamp, sizeof lamp - 1);
        in.a = mtl_lamp;
        in.alen = size + sizeof lamp - 1;
        in.b = obj;
        in.blen = olen;
        st2 = fuzz__twice("mtl", fuzz__mtl_public, &in, in.h);
        free(mtl_lamp);
        free(obj);
    }
    free(mtl);
    return st2 == FUZZ_BAD ? FUZZ_BAD : st;
}

/* ---- .scene -------------------------------------------------------------------- */

/* A .scene held in memory, through the loaders' common path. */
static appm_status fuzz__scene_from_buffer(const char *buf, size_t len, const char *path,
                                           fuzz_env *e, appm_scene **out)
{
    appm__diag_clear(&e->diag);
    return appm__scene_load(path, APPM__TEXT_SCENE, buf, len, NULL, 0, NULL, 0, &e->cfg, out, &e->diag);
}

/* Absolute `mesh` paths become relative (to a folder that does not exist). */
static void fuzz__scene_confine(char *buf, size_t len)
{
    appm__lines it;
    const char *s, *e;
    it.p = buf;
    it.end = buf + len;
    it.line = 0;
    while (appm__next_line(&it, &s, &e)) {
        const char *ts, *te, *rs, *re;
        if (!appm__token(&s, e, &ts, &te) || !appm__token_is(ts, te, "mesh")) continue;
        if (!appm__rest(s, e, &rs, &re)) continue;
        if (rs[0] == '/' || rs[0] == '\\') buf[rs - buf] = '_';
        if (re - rs > 1 && rs[1] == ':') buf[rs - buf + 1] = '_';
    }
}

static int fuzz__scene_run(const void *ctx, fuzz_env *e)
{
    const fuzz__buf2 *in = (const fuzz__buf2 *)ctx;
    appm_scene *scene = NULL;
    appm_status st = fuzz__scene_from_buffer(in->a, in->alen, FUZZ_DIR "fuzz.scene", e, &scene);
    return fuzz__after_load("scene", e, st, scene, in->h);
}

static int fuzz_scene_one(const unsigned char *data, size_t size)
{
    return fuzz__twice_one("scene", fuzz__scene_run, fuzz__scene_confine, data, size);
}

/* ---- PFM ------------------------------------------------------------------------- */

/* Writes `img` as PFM to a temporary file and parses it again: must be identical. */
static int fuzz__pfm_roundtrip(fuzz_env *e, const appm_image *img)
{
    appm__out o;
    appm__mem m;
    appm_image back;
    appm_diag d;
    long n;
    unsigned char *bytes;
    int bad = 0;
    size_t count = (size_t)img->width * img->height * 3;
#if defined(__wasi__)
    o.f = NULL; /* WASI has no tmpfile() */
#else
    o.f = tmpfile();
#endif
    if (!o.f) return 0; /* no temporary files here: nothing to check */
    o.ok = 1;
    o.crc = 0;
    appm__write_pfm_body(&o, img);
    n = ftell(o.f);
    if (!o.ok || n <= 0) {
        fclose(o.f);
        return fuzz__bad("pfm", "cannot write the parsed image back");
    }
    rewind(o.f);
    bytes = (unsigned char *)malloc((size_t)n);
    if (!bytes) abort();
    if (fread(bytes, 1, (size_t)n, o.f) != (size_t)n) bad = fuzz__bad("pfm", "short read");
    fclose(o.f);
    appm__mem_init(&m, &e->cfg);
    if (!bad && appm__pfm_parse(&m, bytes, (size_t)n, "back.pfm", &back, &d) != APPM_OK) {
        bad = fuzz__bad("pfm", "the written image does not parse");
    } else if (!bad) {
        if (back.width != img->width || back.height != img->height ||
            memcmp(back.rgb, img->rgb, count * sizeof(float)) != 0)
            bad = fuzz__bad("pfm", "write/read round trip changed the image");
        appm__free(&m, back.rgb);
    }
    free(bytes);
    return bad ? FUZZ_BAD : 0;
}

static int fuzz__pfm_run(const void *ctx, fuzz_env *e)
{
    const fuzz__buf2 *in = (const fuzz__buf2 *)ctx;
    appm__mem m;
    appm_image img;
    appm_status st;
    int bad = 0;
    appm__mem_init(&m, &e->cfg);
    m.diag = &e->diag;
    appm__diag_clear(&e->diag);
    memset(&img, 0x5A, sizeof img);
    st = appm__pfm_parse(&m, (const unsigned char *)in->a, in->alen, FUZZ_DIR "fuzz.pfm", &img,
                         &e->diag);
    if (fuzz__check_diag("pfm", &e->diag, st)) bad = 1;
    if (st != APPM_OK) {
        if (img.rgb || img.width || img.height)
            bad = fuzz__bad("pfm", "image left set after a failure");
    } else {
        int grey = in->alen > 1 && in->a[1] == 'f';
        size_t need = (size_t)img.width * img.height * (grey ? 1 : 3) * 4;
        if (!img.rgb || img.width < 1 || img.width > 32768 || img.height < 1 || img.height > 32768)
            bad = fuzz__bad("pfm", "bad image after success");
        else if (need > in->alen)
            bad = fuzz__bad("pfm", "more pixels than the input holds");
        else if (e->a.fail_at == 0 && (size_t)img.width * img.height <= 4096 &&
                 fuzz__pfm_roundtrip(e, &img))
            bad = 1;
        appm__free(&m, img.rgb);
    }
    if (m.live != 0) bad = fuzz__bad("pfm", "memory counter not back at 0");
    if (fuzz__check_env("pfm", e)) bad = 1;
    return bad ? FUZZ_BAD : (int)st;
}

static int fuzz_pfm_one(const unsigned char *data, size_t size)
{
    return fuzz__twice_one("pfm", fuzz__pfm_run, NULL, data, size);
}

/* ---- Images (PNG, JPEG, OpenEXR, TGA, PGM/PPM, Radiance HDR, PFM) ---------------- */

/* The first byte of the input picks the file's name: bit 0 set "x.tga" (TGA
 * has no magic; appm__image_decode knows it by its name), clear "x.img"; with
 * bit 1 clear, a PNG gets every chunk CRC made right first, so that mutations
 * reach the decoder behind the CRC check.  The rest is the file. */
typedef struct fuzz__img {
    const unsigned char *p;
    size_t n;
    const char *name;
} fuzz__img;

static void fuzz__png_fix_crcs(unsigned char *p, size_t n)
{
    size_t at = 8;
    while (n >= 12 && at <= n - 12) {
        uint32_t len = appm__png_be32(p + at), c;
        if (len > n - at - 12) break;
        c = appm__crc32_update(0xFFFFFFFFu, p + at + 4, 4 + (size_t)len) ^ 0xFFFFFFFFu;
        p[at + 8 + len] = (unsigned char)(c >> 24);
        p[at + 9 + len] = (unsigned char)(c >> 16);
        p[at + 10 + len] = (unsigned char)(c >> 8);
        p[at + 11 + len] = (unsigned char)c;
        at += 12 + (size_t)len;
    }
}

/* A decoded image of at most 65,536 texels as an environment map
 * (appm__envmap_take: radiances, the map's CDFs, the product densities and
 * their mixture share): refused only as not finite or black (PARSE, naming the
 * file) or out of memory; built, its share is one of the two, and a direction
 * drawn from the map's density or from a bin's product density is finite, of
 * unit length and has a density > 0 and finite there under the density that
 * drew it, with a finite radiance >= 0.  Every block is freed. */
static int fuzz__envmap_check(appm__mem *m, appm__pixels *px, const char *name, appm_diag *diag, appm_status *out)
{
    appm__envmap from, e;
    appm_status st;
    int bad = 0, k;
    uint32_t bin;
    memset(&from, 0, sizeof from);
    from.px = *px;
    from.scale = 1.0;
    px->data = NULL; /* taken */
    st = appm__envmap_take(m, &e, &from, name, diag);
    *out = st;
    if (st != APPM_OK) {
        if (st != APPM_ERR_PARSE && st != APPM_ERR_NOMEM) bad = fuzz__bad("image", "environment map: status neither PARSE nor NOMEM");
        if (st == APPM_ERR_PARSE && strcmp(diag->file, name) != 0)
            bad = fuzz__bad("image", "environment map: the refusal names another file");
        appm__envmap_free(m, &e);
        return bad;
    }
    if (e.mix_map != APPM__ENV_MIX_MAP && e.mix_map != APPM__ENV_MIX_MAP_FULL)
        bad = fuzz__bad("image", "environment map: a mixture share of neither kind");
    for (k = 0; k < 16 && !bad; ++k) {
        const float u1 = ((float)(k % 4) + 0.37f) / 4.0f, u2 = ((float)(k / 4) + 0.61f) / 4.0f;
        appm__env_place pl;
        appm__v3 d, L;
        float pdf = appm__env_sample(&e, u1, u2, &d, &pl), len = appm__dot(d, d);
        L = appm__env_lookup_uv(&e, pl.u, pl.v);
        if (!(pdf > 0.0f && pdf <= FLT_MAX) || !(fabsf(len - 1.0f) < 1e-3f))
            bad = fuzz__bad("image", "environment map: a drawn direction without a finite density > 0");
        if (!(L.x >= 0.0f && L.x <= FLT_MAX && L.y >= 0.0f && L.y <= FLT_MAX && L.z >= 0.0f && L.z <= FLT_MAX))
            bad = fuzz__bad("image", "environment map: a radiance not finite and >= 0");
        for (bin = (uint32_t)k; bin < APPM__ENV_BINS && !bad; bin += 16) {
            double p;
            if (!e.pcdf || !e.pok[bin]) continue;
            appm__env_prod_sample(&e, bin, u1, u2, &d, &pl);
            p = appm__env_prod_pdf_at(&e, bin, &pl);
            len = appm__dot(d, d);
            if (!(p > 0.0 && p < HUGE_VAL) || !(fabsf(len - 1.0f) < 1e-3f))
                bad = fuzz__bad("image", "environment map: a product draw without a finite density > 0");
        }
    }
    appm__envmap_free(m, &e);
    return bad;
}

/* appm__image_decode: a refusal leaves no pixels and names the file; out of
 * memory only when an allocation was refused (every decoder bounds what a
 * file of n bytes can make it allocate); a decoded image has a valid size,
 * depth and channel count, only its pixel block stays allocated, every byte
 * of it is readable, 8- and 16-bit samples give linear values in [0,1], and a
 * Radiance HDR's are finite and >= 0; a small one then makes an environment
 * map (fuzz__envmap_check). */
static int fuzz__image_run(const void *ctx, fuzz_env *e)
{
    const fuzz__img *in = (const fuzz__img *)ctx;
    appm__mem m;
    appm__pixels px;
    appm_status st, ret;
    int bad = 0;
    appm__mem_init(&m, &e->cfg);
    m.diag = &e->diag;
    appm__diag_clear(&e->diag);
    memset(&px, 0x5A, sizeof px);
    st = appm__image_decode(&m, in->p, in->n, in->name, &px, &e->diag);
    ret = st;
    if (fuzz__check_diag("image", &e->diag, st)) bad = 1;
    if (st != APPM_OK) {
        if (px.data) bad = fuzz__bad("image", "pixels left after a failure");
        if (st != APPM_ERR_PARSE && st != APPM_ERR_NOMEM) bad = fuzz__bad("image", "status neither PARSE nor NOMEM");
        if (st == APPM_ERR_NOMEM && !e->a.failed)
            bad = fuzz__bad("image", "out of memory though no allocation was refused (a missing size check)");
        if (st == APPM_ERR_PARSE && strcmp(e->diag.file, in->name) != 0)
            bad = fuzz__bad("image", "the refusal names another file");
    } else if (!px.data || px.w < 1 || px.h < 1 || px.w > APPM__IMAGE_MAX || px.h > APPM__IMAGE_MAX ||
               px.channels < 1 || px.channels > 4 || (px.depth != 8 && px.depth != 16 && px.depth != 32)) {
        bad = fuzz__bad("image", "bad image after success");
    } else {
        size_t bytes = (size_t)px.w * px.h * px.channels * (px.depth / 8), i, n = (size_t)px.w * px.h;
        int hdr = in->n >= 2 && in->p[0] == '#' && in->p[1] == '?';
        volatile unsigned char sink = 0;
        unsigned k;
        if (m.live != bytes + APPM__ALLOC_HEADER) bad = fuzz__bad("image", "more than the pixels left allocated");
        for (i = 0; i < bytes; i += 61) sink ^= ((const unsigned char *)px.data)[i];
        sink ^= ((const unsigned char *)px.data)[bytes - 1]; /* ASan checks the block's size */
        (void)sink;
        for (i = 0; i < n && i < 4096 && !bad; ++i)
            for (k = 0; k < px.channels; ++k) {
                float v = appm__pixels_linear(&px, i, k);
                if (px.depth != 32 && !(v >= 0.0f && v <= 1.0f))
                    bad = fuzz__bad("image", "an 8- or 16-bit sample outside [0,1]");
                if (hdr && !(v >= 0.0f && v <= FLT_MAX)) bad = fuzz__bad("image", "a Radiance HDR value not finite and >= 0");
            }
    }
    if (st == APPM_OK && !bad && (size_t)px.w * px.h <= 65536) {
        appm_status est = APPM_OK;
        if (fuzz__envmap_check(&m, &px, in->name, &e->diag, &est)) bad = 1;
        if (est == APPM_ERR_NOMEM) { /* the map's allocations count as the decoder's */
            if (!e->a.failed) bad = fuzz__bad("image", "environment map: out of memory though no allocation was refused");
            ret = APPM_ERR_NOMEM;
        }
    }
    if (st == APPM_OK) appm__free(&m, px.data); /* NULL once the map took it */
    if (m.live != 0) bad = fuzz__bad("image", "memory counter not back at 0");
    if (fuzz__check_env("image", e)) bad = 1;
    return bad ? FUZZ_BAD : (int)ret;
}

static int fuzz_image_one(const unsigned char *data, size_t size)
{
    static const unsigned char png_sig[8] = {0x89, 'P', 'N', 'G', 13, 10, 26, 10};
    unsigned sel = size ? data[0] : 0u;
    size_t n = size ? size - 1 : 0;
    unsigned char *buf = (unsigned char *)fuzz__dup(size ? data + 1 : data, n); /* exact size */
    fuzz__img in;
    int st;
    if (!(sel & 2u) && n >= 8 && memcmp(buf, png_sig, 8) == 0) fuzz__png_fix_crcs(buf, n);
    in.p = buf;
    in.n = n;
    in.name = (sel & 1u) ? FUZZ_DIR "x.tga" : FUZZ_DIR "x.img";
    st = fuzz__twice("image", fuzz__image_run, &in, fuzz__hash(data, size));
    free(buf);
    return st;
}

/* ---- Checkpoints --------------------------------------------------------------- */

/* The renderer checkpoints are loaded into: a lamp over a floor, 4x3 pixels, 64
 * photons, one thread; the method is the one named at the checkpoint's method
 * offset (24), so that a mutated checkpoint of any method meets its own kind
 * of renderer, with guided emission if its count of guided lights (offset 52)
 * is not 0.  tests/fuzz/gen_checkpoint.c writes the seed corpus with it. */
#define FUZZ_CK_METHOD_AT 24
#define FUZZ_CK_GUIDED_AT 52

static const char fuzz__ck_obj[] = "mtllib lamp.mtl\nv -2 0 -2\nv 2 0 -2\nv 2 0 2\nv -2 0 2\nf 4 3 2 1\n"
                                   "usemtl lamp\nv -0.5 2 -0.5\nv 0.5 2 -0.5\nv 0 2 0.5\nf 7 6 5\n";
static const char fuzz__ck_mtl[] = "newmtl lamp\nKd 0 0 0\nKe 5 5 5\n";

static appm_status fuzz__ck_setup(fuzz_env *e, const unsigned char *data, size_t size, appm_scene **scene,
                                  appm_renderer **r)
{
    appm_config c = e->cfg;
    appm_status st;
    *r = NULL;
    st = appm_scene_load_obj_memory(fuzz__ck_obj, sizeof fuzz__ck_obj - 1, fuzz__ck_mtl, sizeof fuzz__ck_mtl - 1,
                                    FUZZ_DIR "lamp.obj", &e->cfg, scene, &e->diag);
    if (st != APPM_OK) return st;
    c.width = 4;
    c.height = 3;
    c.photons = 64;
    c.threads = 1;
    c.max_depth = 6;
    c.method = (appm_method)(size > FUZZ_CK_METHOD_AT ? data[FUZZ_CK_METHOD_AT] % (unsigned)APPM_METHOD_COUNT : 0u);
    /* guided emission if the checkpoint says it guides lights: it carries their densities */
    c.emission = size > FUZZ_CK_GUIDED_AT && data[FUZZ_CK_GUIDED_AT] ? APPM_EMISSION_GUIDED : APPM_EMISSION_LIGHT;
    return appm_renderer_create(*scene, &c, r, &e->diag);
}

/* One load of `data` into a fresh renderer.  Refused: the renderer is still
 * fresh.  Accepted: saving gives back exactly `data`, and a pass runs. */
static int fuzz__ck_load_one(appm_renderer *r, const unsigned char *data, size_t size)
{
    appm_diag d;
    appm_status st;
    memset(&d, 0x5A, sizeof d);
    st = appm_renderer_load(r, data, size, &d);
    if (fuzz__check_diag("checkpoint", &d, st)) return FUZZ_BAD;
    if (st != APPM_OK) {
        if (r->pass != 0 || r->stats.passes != 0) return fuzz__bad("checkpoint", "a refused load changed the renderer");
        return (int)st;
    }
    {
        unsigned char *back = (unsigned char *)malloc(size ? size : 1);
        size_t n = 0;
        int same;
        if (!back) abort();
        same = appm_renderer_save(r, back, size, &n, &d) == APPM_OK && n == size && memcmp(back, data, size) == 0;
        free(back);
        if (!same) return fuzz__bad("checkpoint", "saving a loaded checkpoint gives other bytes");
    }
    st = appm_renderer_pass(r);
    if (st != APPM_OK && st != APPM_ERR_NOMEM) return fuzz__bad("checkpoint", "a pass after a load failed");
    return (int)st;
}

/* One variant: a fresh scene and renderer, the load, the checks. */
static int fuzz__ck_variant(fuzz_env *e, const unsigned char *data, size_t size)
{
    appm_scene *scene = NULL;
    appm_renderer *r = NULL;
    appm_status st = fuzz__ck_setup(e, data, size, &scene, &r);
    int res = (int)st;
    if (st == APPM_OK) res = fuzz__ck_load_one(r, data, size);
    appm_renderer_destroy(r);
    appm_scene_destroy(scene);
    return res;
}

/* The input as it is (mostly stopped by the checksum), then with its checksum
 * made right, so that mutations reach the checks behind it.  Returns the
 * status of the first, or APPM_ERR_NOMEM if either ran out of memory. */
static int fuzz__ck_run(const void *ctx, fuzz_env *e)
{
    const fuzz__buf2 *in = (const fuzz__buf2 *)ctx;
    const unsigned char *data = (const unsigned char *)in->a;
    int raw = fuzz__ck_variant(e, data, in->alen), fixed = APPM_OK;
    if (raw != FUZZ_BAD && in->alen >= 8) {
        unsigned char *copy = (unsigned char *)fuzz__dup(data, in->alen);
        uint64_t h = 14695981039346656037ull; /* FNV-1a of all bytes before the last 8 */
        size_t i;
        int k;
        for (i = 0; i + 8 < in->alen; ++i) h = (h ^ copy[i]) * 1099511628211ull;
        for (k = 0; k < 8; ++k) copy[in->alen - 8 + (size_t)k] = (unsigned char)(h >> (8 * k));
        fixed = fuzz__ck_variant(e, copy, in->alen);
        free(copy);
    }
    if (fuzz__check_env("checkpoint", e)) return FUZZ_BAD;
    if (raw == FUZZ_BAD || fixed == FUZZ_BAD) return FUZZ_BAD;
    return raw == APPM_ERR_NOMEM || fixed == APPM_ERR_NOMEM ? APPM_ERR_NOMEM : raw;
}

static int fuzz_checkpoint_one(const unsigned char *data, size_t size)
{
    return fuzz__twice_one("checkpoint", fuzz__ck_run, NULL, data, size);
}

/* ---- Table ------------------------------------------------------------------- */

typedef int (*fuzz_fn)(const unsigned char *data, size_t size);

static const struct fuzz_target {
    const char *name;
    fuzz_fn one;
} fuzz_targets[] = {
    {"obj", fuzz_obj_one}, {"mtl", fuzz_mtl_one}, {"scene", fuzz_scene_one}, {"pfm", fuzz_pfm_one},
    {"checkpoint", fuzz_checkpoint_one}, {"image", fuzz_image_one}};

#define FUZZ_TARGET_COUNT (sizeof fuzz_targets / sizeof fuzz_targets[0])

/* The entry point called `name`, on the bytes; FUZZ_BAD for an unknown name. */
static int fuzz_run(const char *name, const unsigned char *data, size_t size)
{
    size_t k;
    for (k = 0; k < FUZZ_TARGET_COUNT; ++k)
        if (strcmp(fuzz_targets[k].name, name) == 0) return fuzz_targets[k].one(data, size);
    return fuzz__bad(name, "no such target");
}

#endif
