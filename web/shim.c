/* web/shim.c - the few entry points the browser page needs, over appm's public API.
 *
 * Built with appm.c for wasm32-wasi by `make web` (no threads, no file I/O: the
 * scene arrives as text from JavaScript - OBJ and MTL through
 * appm_scene_load_obj_memory, which frames the camera as for a bare .obj, or a
 * .scene with the OBJ and MTL it names through appm_scene_load_memory, which
 * takes the .scene's camera and lights).
 * `make test-web` checks its pixels against `appm render` of the same .obj.
 *
 * One instance holds one scene and one renderer: the page runs one Web Worker,
 * and so one WebAssembly instance, per side of the side-by-side view.  All
 * numbers cross the boundary as int or double (doubles hold the 64-bit counts
 * exactly up to 2^53), so no BigInt is needed in JavaScript.  Buffers handed
 * out are owned here and stay valid until the next call that rebuilds them.
 *
 * The false-colour maps are those of `appm render --aux` (main.c): viridis for
 * the radius and, on a log scale over 4 decades, the variance; a blue-white-red
 * map for the signed Laplacian; each scaled to its 99th percentile.
 */
#include "../appm.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#if defined(__wasm__)
#define WEB_EXPORT(name) __attribute__((export_name(#name)))
#else
#define WEB_EXPORT(name)
#endif

static struct {
    appm_scene *scene;
    appm_renderer *r;
    appm_diag diag;
    unsigned char *rgba;    /* width * height * 4 bytes, rebuilt on each request */
    float *tmp;             /* width * height floats: the percentile's scratch   */
    size_t npix;
    int method;             /* the renderer's appm_method                         */
    char error[600];
} W;

static void web_set_error(appm_status s, const appm_diag *d)
{
    const char *m = d && d->message[0] ? d->message : appm_status_string(s);
    if (d && d->file[0] && d->line)
        snprintf(W.error, sizeof W.error, "%s:%u: %s", d->file, d->line, m);
    else if (d && d->file[0])
        snprintf(W.error, sizeof W.error, "%s: %s", d->file, m);
    else
        snprintf(W.error, sizeof W.error, "%s", m);
}

/* ---- Memory for JavaScript's strings ------------------------------------- */

WEB_EXPORT(web_alloc) void *web_alloc(unsigned n) { return malloc(n ? n : 1); }
WEB_EXPORT(web_free) void web_free(void *p) { free(p); }
WEB_EXPORT(web_error) const char *web_error(void) { return W.error; }

static void web_drop_renderer(void)
{
    appm_renderer_destroy(W.r);
    W.r = NULL;
    free(W.rgba);
    free(W.tmp);
    W.rgba = NULL;
    W.tmp = NULL;
    W.npix = 0;
}

static void web_drop_scene(void)
{
    web_drop_renderer();
    appm_scene_destroy(W.scene);
    W.scene = NULL;
    W.error[0] = '\0';
}

/* Replaces the scene (and drops the renderer) by the OBJ/MTL texts given;
 * returns the appm_status (0: ok; otherwise web_error() says why). */
WEB_EXPORT(web_load)
int web_load(const char *obj, unsigned obj_len, const char *mtl, unsigned mtl_len, const char *name)
{
    appm_status s;
    web_drop_scene();
    s = appm_scene_load_obj_memory(obj, obj_len, mtl_len ? mtl : NULL, mtl_len, name, NULL,
                                   &W.scene, &W.diag);
    if (s != APPM_OK) web_set_error(s, &W.diag);
    return (int)s;
}

/* The same from a .scene text (named `name`) and the OBJ and MTL texts that
 * its `mesh` line and the OBJ's `mtllib` line name (obj_name, mtl_name, as
 * written there): the scene gets the .scene's camera and lights. */
WEB_EXPORT(web_load_scene)
int web_load_scene(const char *scene, unsigned scene_len, const char *name, const char *obj, unsigned obj_len,
                   const char *obj_name, const char *mtl, unsigned mtl_len, const char *mtl_name)
{
    appm_memory_file files[2];
    appm_status s;
    web_drop_scene();
    files[0].name = obj_name;
    files[0].text = obj;
    files[0].len = obj_len;
    files[1].name = mtl_name;
    files[1].text = mtl;
    files[1].len = mtl_len;
    s = appm_scene_load_memory(scene, scene_len, name, files, 2, NULL, &W.scene, &W.diag);
    if (s != APPM_OK) web_set_error(s, &W.diag);
    return (int)s;
}

/* The library's method names, so that the page asks for methods by name:
 * web_method_name(m) for m = 0 .. web_method_count() - 1 (appm_method values). */
WEB_EXPORT(web_method_count) int web_method_count(void) { return (int)APPM_METHOD_COUNT; }
WEB_EXPORT(web_method_name) const char *web_method_name(int m)
{
    return appm_method_name((appm_method)m);
}

/* A renderer for the loaded scene.  method: an appm_method value; sampler: an
 * appm_sampler value (0 qmc, 1 random); photons, radius, alpha: 0 means the
 * library's default. */
WEB_EXPORT(web_create)
int web_create(int method, int sampler, int width, int height, double photons, double radius,
               double alpha, double seed)
{
    appm_config cfg;
    appm_status s;
    web_drop_renderer();
    W.error[0] = '\0';
    if (!W.scene) {
        snprintf(W.error, sizeof W.error, "no scene loaded");
        return (int)APPM_ERR_INVALID_ARG;
    }
    if (!(photons >= 0 && photons < 9.0e15) || !(seed >= 0 && seed < 9.0e15) || width < 1 ||
        height < 1 || width > 32768 || height > 32768 || method < 0 ||
        method >= (int)APPM_METHOD_COUNT || sampler < 0 || sampler > (int)APPM_SAMPLER_RANDOM) {
        snprintf(W.error, sizeof W.error, "an option is out of range");
        return (int)APPM_ERR_INVALID_ARG;
    }
    appm_config_init(&cfg);
    cfg.method = (appm_method)method;
    cfg.sampler = (appm_sampler)sampler;
    cfg.width = (uint32_t)width;
    cfg.height = (uint32_t)height;
    cfg.photons = (uint64_t)photons;
    cfg.radius = radius;
    cfg.alpha = alpha;
    cfg.seed = (uint64_t)seed;
    cfg.threads = 1;
    s = appm_renderer_create(W.scene, &cfg, &W.r, &W.diag);
    if (s != APPM_OK) {
        web_set_error(s, &W.diag);
        W.r = NULL;
        return (int)s;
    }
    W.method = method;
    W.npix = (size_t)width * (size_t)height;
    if (W.npix <= (size_t)-1 / 4) { /* 32768^2 x 4 bytes overflows wasm32's size_t */
        W.rgba = (unsigned char *)malloc(W.npix * 4);
        W.tmp = (float *)malloc(W.npix * sizeof(float));
    }
    if (!W.rgba || !W.tmp) {
        web_drop_renderer();
        snprintf(W.error, sizeof W.error, "%s", appm_status_string(APPM_ERR_NOMEM));
        return (int)APPM_ERR_NOMEM;
    }
    return 0;
}

WEB_EXPORT(web_pass) int web_pass(void)
{
    appm_status s;
    if (!W.r) return (int)APPM_ERR_INVALID_ARG;
    s = appm_renderer_pass(W.r);
    if (s != APPM_OK) snprintf(W.error, sizeof W.error, "%s", appm_renderer_last_error(W.r));
    return (int)s;
}

/* ---- Numbers ----------------------------------------------------------------- */

/* The estimated relative error of the image: the library's own estimate for
 * appm and pt; for ppm, whose estimator keeps a variance but no bias
 * estimate, the noise part alone, sqrt(mean(Var / (I^2 + 0.01))), the same
 * weight as the library gives a pixel that several passes hold; -1 where
 * there is none (sppm, first pass). */
static double web_ppm_noise(void)
{
    const float *var = appm_renderer_aux(W.r, APPM_AUX_VARIANCE);
    appm_image img;
    double sum = 0.0;
    size_t i;
    if (!var) return -1.0;
    appm_renderer_image(W.r, &img);
    for (i = 0; i < W.npix; ++i) {
        const float *c = img.rgb + 3 * i;
        double I = 0.2126 * c[0] + 0.7152 * c[1] + 0.0722 * c[2];
        sum += (double)var[i] / (I * I + 0.01);
    }
    return sqrt(sum / (double)W.npix);
}

/* which: 0 passes, 1 photon paths emitted, 2 seconds inside the passes, 3 the
 * estimated relative error (see above), 4 the initial radius, 5 bytes held,
 * 6 photons stored in the last pass, 7 eye paths, 8 whether 3 is noise only. */
WEB_EXPORT(web_stat) double web_stat(int which)
{
    appm_stats st;
    if (!W.r) return -1.0;
    appm_renderer_stats(W.r, &st);
    switch (which) {
    case 0: return (double)st.passes;
    case 1: return (double)st.photons_emitted;
    case 2: return st.seconds;
    case 3: return W.method == APPM_METHOD_PPM && st.passes >= 2 ? web_ppm_noise() : st.est_relerr;
    case 4: return st.initial_radius;
    case 5: return (double)st.memory_bytes;
    case 6: return (double)st.photons_stored;
    case 7: return (double)st.eye_paths;
    case 8: return W.method == APPM_METHOD_PPM && st.passes >= 2 ? 1.0 : 0.0;
    default: return -1.0;
    }
}

/* The image as linear float RGB, width * height * 3, row 0 at the top. */
WEB_EXPORT(web_image) const float *web_image(void)
{
    appm_image img;
    if (!W.r) return NULL;
    appm_renderer_image(W.r, &img);
    return img.rgb;
}

/* ---- Pictures ------------------------------------------------------------------ */

/* The sRGB curve of the PNG writer (appm.c, section 3), so the page shows what
 * `appm render -o x.png` writes. */
static unsigned char web_srgb8(float v)
{
    if (!(v > 0.0f)) return 0;
    if (v >= 1.0f) return 255;
    v = v <= 0.0031308f ? 12.92f * v : 1.055f * powf(v, 1.0f / 2.4f) - 0.055f;
    v = v * 255.0f + 0.5f;
    return (unsigned char)(v >= 255.0f ? 255.0f : v);
}

/* The image as 8-bit sRGB RGBA for a canvas, after multiplying by `exposure`. */
WEB_EXPORT(web_image_rgba) const unsigned char *web_image_rgba(double exposure)
{
    appm_image img;
    size_t i;
    float e = exposure > 0 ? (float)exposure : 1.0f;
    if (!W.r) return NULL;
    appm_renderer_image(W.r, &img);
    for (i = 0; i < W.npix; ++i) {
        W.rgba[4 * i] = web_srgb8(img.rgb[3 * i] * e);
        W.rgba[4 * i + 1] = web_srgb8(img.rgb[3 * i + 1] * e);
        W.rgba[4 * i + 2] = web_srgb8(img.rgb[3 * i + 2] * e);
        W.rgba[4 * i + 3] = 255;
    }
    return W.rgba;
}

/* Viridis (van der Walt & Smith 2015) and Moreland's cool-to-warm, sRGB control
 * points: main.c's tables.  The canvas takes sRGB bytes directly, so unlike the
 * CLI (which linearises, then lets the PNG writer re-apply the curve) the
 * interpolated control points are written as they are; the two round trips
 * differ by at most a step of the 8-bit rounding. */
static const float WEB_VIRIDIS[9][3] = {
    {0.267f, 0.005f, 0.329f}, {0.283f, 0.141f, 0.458f}, {0.254f, 0.265f, 0.530f},
    {0.207f, 0.372f, 0.553f}, {0.164f, 0.471f, 0.558f}, {0.128f, 0.567f, 0.551f},
    {0.135f, 0.659f, 0.518f}, {0.267f, 0.749f, 0.441f}, {0.993f, 0.906f, 0.144f}};
static const float WEB_COOLWARM[5][3] = {{0.230f, 0.299f, 0.754f}, {0.552f, 0.690f, 0.996f},
                                         {0.865f, 0.865f, 0.865f}, {0.958f, 0.604f, 0.482f},
                                         {0.706f, 0.016f, 0.150f}};

static void web_colour(const float (*map)[3], int n, float t, unsigned char *rgba)
{
    float x;
    int i, k;
    if (!(t > 0.0f)) t = 0.0f;
    if (t > 1.0f) t = 1.0f;
    x = t * (float)(n - 1);
    i = (int)x;
    if (i >= n - 1) i = n - 2;
    x -= (float)i;
    for (k = 0; k < 3; ++k) {
        float c = map[i][k] * (1.0f - x) + map[i + 1][k] * x;
        rgba[k] = (unsigned char)(c * 255.0f + 0.5f);
    }
    rgba[3] = 255;
}

/* The 99th percentile of the finite values of v (|v| if `absolute`), by a
 * 1024-bin histogram up to the maximum, as main.c's write_aux. */
static float web_percentile99(const float *v, int absolute)
{
    size_t i, m = 0, acc = 0, bins[1024] = {0};
    float mx = 0.0f;
    int k;
    for (i = 0; i < W.npix; ++i)
        if (v[i] == v[i]) W.tmp[m++] = absolute ? fabsf(v[i]) : v[i];
    for (i = 0; i < m; ++i) mx = W.tmp[i] > mx ? W.tmp[i] : mx;
    if (m == 0 || !(mx > 0.0f)) return 0.0f;
    for (i = 0; i < m; ++i) {
        size_t b = (size_t)(W.tmp[i] / mx * 1023.0f);
        bins[b > 1023 ? 1023 : b]++;
    }
    for (k = 0; k < 1024; ++k) {
        acc += bins[k];
        if (acc >= m - m / 100) break;
    }
    return mx * (float)(k + 1) / 1024.0f;
}

/* One diagnostic map (an appm_aux value: 0 radius, 1 variance, 2 Laplacian,
 * 3 error bar) in false colour as RGBA, or NULL when the method keeps none.
 * Scales as `--aux`: radius linear from 0, variance and error log over 4
 * decades, the Laplacian symmetric around 0.  *hi_out gets the top of the scale. */
static const unsigned char *web_aux_map(int which, double *hi_out)
{
    const float *v;
    float hi;
    int mode = which == 0 ? 0 : which == 2 ? 2 : 1;
    size_t i;
    if (!W.r || which < 0 || which >= APPM_AUX_COUNT) return NULL;
    v = appm_renderer_aux(W.r, (appm_aux)which);
    if (!v) return NULL;
    hi = web_percentile99(v, mode == 2);
    *hi_out = hi;
    for (i = 0; i < W.npix; ++i) {
        float t, x = v[i];
        if (!(hi > 0.0f) || x != x) t = 0.0f;
        else if (mode == 0) t = x / hi;
        else if (mode == 1) t = x > 0.0f ? 1.0f + log10f(x / hi) / 4.0f : 0.0f;
        else t = 0.5f + 0.5f * x / hi;
        if (mode == 2) web_colour(WEB_COOLWARM, 5, t, W.rgba + 4 * i);
        else web_colour(WEB_VIRIDIS, 9, t, W.rgba + 4 * i);
    }
    return W.rgba;
}

static double web_aux_hi_value;

WEB_EXPORT(web_aux_rgba) const unsigned char *web_aux_rgba(int which)
{
    web_aux_hi_value = 0.0;
    return web_aux_map(which, &web_aux_hi_value);
}

/* The top of the scale of the last web_aux_rgba map (its 99th percentile). */
WEB_EXPORT(web_aux_hi) double web_aux_hi(void) { return web_aux_hi_value; }
