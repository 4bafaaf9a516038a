/* main.c - the `appm` command line.  Uses only the public API of appm.h.
 *
 *   appm render SCENE [options]    progressive render, writes an image
 *   appm compare A.pfm B.pfm       error of A against the reference B
 *   appm info SCENE                what the scene holds, memory it will need
 *
 * Exit codes: 0 success, 1 bad usage, 2 bad input file, 3 out of memory or
 * another runtime failure.  Errors go to stderr as "appm: FILE:LINE: message".
 */
#if !defined(_WIN32) && !defined(_POSIX_C_SOURCE)
#define _POSIX_C_SOURCE 200809L
#endif
#if !defined(_WIN32) && !defined(_FILE_OFFSET_BITS)
#define _FILE_OFFSET_BITS 64 /* logs and images over 2 GiB on 32-bit glibc, as appm.c */
#endif
#if defined(_WIN32) && !defined(_CRT_SECURE_NO_WARNINGS)
#define _CRT_SECURE_NO_WARNINGS
#endif

#include "appm.h"

#include <math.h>
#include <signal.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#if defined(_WIN32)
#include <io.h>
#define appm_isatty(fd) _isatty(fd)
#elif defined(__unix__) || defined(__APPLE__)
#include <unistd.h>
#define appm_isatty(fd) isatty(fd)
#else
#define appm_isatty(fd) 0
#endif

enum { EXIT_OK = 0, EXIT_USAGE = 1, EXIT_INPUT = 2, EXIT_RUNTIME = 3 };

static volatile sig_atomic_t g_interrupted = 0;

/* The distributed front end, mpi.c, includes this file (with APPM_CLI_NO_MAIN)
 * and runs `appm render` on every rank of a job through these hooks; a plain
 * build has none (g_cli NULL) and renders alone. */
typedef struct cli_hooks {
    unsigned rank, ranks;
    appm_file_reader reader; /* every file of a load read on rank 0 and sent to all */
    appm_cluster cluster;    /* the exchanges of a pass (appm_renderer_set_cluster) */
    appm_allocator allocator; /* the renderer's and the scene's, if set (tests) */
    /* collective: every rank's exit code in, the job's out (the first failing
     * rank's code, that rank into *who) */
    int (*agree)(int rc, unsigned *who);
    /* collective: rank 0's code to every rank (0 go on, 1 stop, else an exit code) */
    int (*decide)(int code);
    /* ends the whole job at once: for a failure on one rank in the middle of
     * reads that every rank takes part in, where no agreement can follow */
    void (*abort_job)(int rc);
} cli_hooks;

static const cli_hooks *g_cli = NULL;
static const char *g_who = "appm"; /* how messages begin: "appm", or "appm: rank K" */

/* Whether this process writes: images, maps, logs, checkpoints, the summary. */
static int cli_root(void)
{
    return !g_cli || g_cli->rank == 0;
}

/* After a step every rank takes: the job's exit code (the first failing rank's;
 * rank 0 names it when another rank failed). */
static int cli_agree(int rc)
{
    unsigned who = 0;
    int job;
    if (!g_cli) return rc;
    job = g_cli->agree(rc, &who);
    if (job != EXIT_OK && rc == EXIT_OK && g_cli->rank == 0) /* said once: rank 0 itself did not fail */
        fprintf(stderr, "%s: rank %u of %u failed (exit code %d; its message is above): the job ends\n", g_who, who,
                g_cli->ranks, job);
    return job;
}

static void on_sigint(int sig)
{
    (void)sig;
    g_interrupted = 1;
}

static double now_seconds(void)
{
#if defined(CLOCK_MONOTONIC) && !defined(_WIN32)
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
#else
    return (double)time(NULL);
#endif
}

static int usage_error(const char *fmt, ...)
{
    va_list ap;
    fprintf(stderr, "%s: ", g_who);
    va_start(ap, fmt);
    vfprintf(stderr, fmt, ap);
    va_end(ap);
    fprintf(stderr, "\n(see 'appm --help')\n");
    return EXIT_USAGE;
}

/* Reports a library failure and maps it to an exit code. */
static int lib_error(appm_status s, const appm_diag *d, const char *fallback_file)
{
    const char *file = d && d->file[0] ? d->file : fallback_file;
    const char *msg = d && d->message[0] ? d->message : appm_status_string(s);
    if (file && d && d->line) fprintf(stderr, "%s: %s:%u: %s\n", g_who, file, d->line, msg);
    else if (file) fprintf(stderr, "%s: %s: %s\n", g_who, file, msg);
    else fprintf(stderr, "%s: %s\n", g_who, msg);
    if (s == APPM_ERR_PARSE || s == APPM_ERR_IO) return EXIT_INPUT;
    if (s == APPM_ERR_INVALID_ARG) return EXIT_USAGE;
    return EXIT_RUNTIME;
}

static void on_warning(void *user, const char *file, unsigned line, const char *message)
{
    int quiet = *(const int *)user;
    if (quiet) return;
    if (file && file[0] && line) fprintf(stderr, "%s: warning: %s:%u: %s\n", g_who, file, line, message);
    else if (file && file[0]) fprintf(stderr, "%s: warning: %s: %s\n", g_who, file, message);
    else fprintf(stderr, "%s: warning: %s\n", g_who, message);
}

static const char *const HELP =
    "appm - adaptive progressive photon mapping\n"
    "\n"
    "usage:\n"
    "  appm render SCENE [options]   progressive render of a .scene or .obj, writes an image\n"
    "  appm compare A B              error of image A against the reference B (linear:\n"
    "                                .pfm .exr .hdr; 8-bit files are sRGB-decoded)\n"
    "  appm info SCENE               what the scene contains, memory it will need\n"
    "  appm --help | appm render --help | appm --version\n";

static const char *const RENDER_HELP =
    "usage: appm render SCENE [options]\n"
    "\n"
    "  -o, --output FILE     image to write: .pfm or .exr (linear float), .ppm or .png\n"
    "                        (8-bit sRGB) [SCENENAME.png in the current folder]\n"
    "  --exr float|half      sample type of an .exr output [float]\n"
    "  --exr-compression zip|none   compression of an .exr output [zip]\n"
    "  --method M            appm (adaptive radius, default) | appm-paper (the adaptive radius\n"
    "                        as Kaplanyan-Dachsbacher derive it: one photon component) | ppm\n"
    "                        (global radius schedule, Knaus-Zwicker) | sppm (per-pixel\n"
    "                        statistics, Hachisuka-Jensen) | pt (unbiased path tracer, for\n"
    "                        references)\n"
    "  --time SECONDS        stop after this wall time (the pass in flight finishes)\n"
    "  --passes N            stop after N passes (with neither: 60 s)\n"
    "  --until-error E       stop when the estimated relative error falls below E (appm,\n"
    "                        appm-paper, pt; not pt with a mirror or glass and a point,\n"
    "                        spot or tiny light)\n"
    "  --photons N           photon paths emitted per pass [chosen in pass 1: 1, 2 or 4\n"
    "                        times width * height, as the eye and photon paths' rays\n"
    "                        compare]\n"
    "  --radius R            initial radius in scene units [2 pixel widths at the visible points]\n"
    "  --alpha A             radius shrinkage for ppm/sppm, 0 < A <= 1 (1: fixed radius) [2/3]\n"
    "  --threads N           worker threads [all cores]\n"
    "  --seed N              random seed; same seed + passes = same image for any thread count [0]\n"
    "  --size WxH            override the scene's image size\n"
    "  --max-depth N         longest light path counted, in segments from light to camera [32]\n"
    "  --direct MODE         nee (shadow rays, default) | photons (first-bounce photons)\n"
    "  --sampler S           qmc (scrambled Sobol' in every path dimension, default) |\n"
    "                        random (independent PCG streams, the earlier sampler)\n"
    "  --emission E          guided (default: photons emitted where the camera's visible\n"
    "                        points gathered them, learned pass by pass, for each light\n"
    "                        where that pays) | light (each light's own distribution)\n"
    "  --chains K            qmc: K independently scrambled chains of passes, est_relerr\n"
    "                        from their spread (K >= 2), at a price in accuracy; with one,\n"
    "                        from the passes' spread scaled by the sequence's halves [1]\n"
    "  --exposure X          multiply before the sRGB conversion of .png/.ppm [1]\n"
    "  --reference REF       compare with this image after every pass (.pfm .exr .hdr ...)\n"
    "  --log FILE.csv        one row per pass: pass,seconds,photons,rmse,relmse,est_relerr\n"
    "  --aux PREFIX          also write PREFIX-{radius,variance,laplacian,error}.pfm and .png\n"
    "                        (appm also PREFIX-radius-{caustic,diffuse}: each component's radius;\n"
    "                        guided emission PREFIX-emission-K: light K's learned density)\n"
    "  --checkpoint FILE     save the whole render state to FILE (atomically) every 10 s of\n"
    "                        wall time, or every --checkpoint-every N passes, and at the end\n"
    "  --checkpoint-every N  with --checkpoint: every N passes instead of every 10 s\n"
    "  --resume FILE         continue from a checkpoint of the same scene and options (any\n"
    "                        --threads); --passes counts the whole render, --time this run\n"
    "  -q, --quiet           no progress output and no warnings\n"
    "\n"
    "lights and maps:\n";

/* The second half of `appm render --help` (C99 compilers need only take
 * string literals of up to 4095 characters). */
static const char *const RENDER_HELP_LIGHTS =
    "  --environment R G B   add (or replace) a constant environment light of this radiance\n"
    "  --environment-map FILE   light the scene by this equirectangular map (.exr .hdr .pfm\n"
    "                        .png .jpg ...; row 0 the zenith, +y; column 0 looking along -z),\n"
    "                        replacing its environment\n"
    "  --environment-scale S    multiply the map's radiance by S [1]\n"
    "  --environment-rotate DEG turn the map about the up axis (90: column 0 looks along +x) [0]\n"
    "  --missing-textures error|warn   a texture map that cannot be read fails the load\n"
    "                        (error) or renders without it, with a warning [error]\n"
    "  --light point X Y Z R G B    add a point light (intensity W/sr per channel); repeatable\n"
    "                        (a bare .obj that emits nothing and gets none of these is\n"
    "                        shown in a studio, with a warning: see --stand-in)\n"
    "  --stand-in studio|white   what lights a bare .obj without light: a sky with a key\n"
    "                        light, a ground plate and a camera from above (studio), or a\n"
    "                        constant white environment of radiance 1 (white) [studio]\n";


/* "appm, ppm, sppm, pt or appm-paper": the library's method names, for messages. */
static const char *method_list(char *buf, size_t size)
{
    size_t len = 0;
    int m, n = (int)APPM_METHOD_COUNT;
    buf[0] = 0;
    for (m = 0; m < n; ++m) {
        int k = snprintf(buf + len, size - len, "%s%s", m == 0 ? "" : (m + 1 < n ? ", " : " or "),
                         appm_method_name((appm_method)m));
        if (k < 0 || (size_t)k >= size - len) break;
        len += (size_t)k;
    }
    return buf;
}

/* ---- Strict number parsing ---------------------------------------------- */

static int parse_double(const char *s, double *out)
{
    char *end;
    double v;
    if (!s || !*s) return 0;
    v = strtod(s, &end);
    if (*end || v != v || v == HUGE_VAL || v == -HUGE_VAL) return 0;
    *out = v;
    return 1;
}

static int parse_u64(const char *s, unsigned long long *out)
{
    unsigned long long v = 0;
    const char *p = s;
    if (!s || !*s) return 0;
    /* also accept 1e6-style counts, which are common for photon numbers */
    for (; *p; ++p) {
        if (*p < '0' || *p > '9') {
            double d;
            if (!parse_double(s, &d) || d < 0 || d > 1.8e19 || d != floor(d)) return 0;
            *out = (unsigned long long)d;
            return 1;
        }
        if (v > (18446744073709551615ull - (unsigned long long)(*p - '0')) / 10) return 0; /* past 2^64 - 1 */
        v = v * 10 + (unsigned long long)(*p - '0');
    }
    *out = v;
    return 1;
}

/* ---- False colour for the diagnostic maps ---------------------------------
 * Viridis (van der Walt & Smith 2015) for magnitudes: perceptually uniform and
 * monotonic in lightness, so it reads in greyscale print too.  A blue-white-red
 * diverging map (Moreland's "cool to warm") for the signed Laplacian.  Control
 * points are sRGB; the PNG writer applies the sRGB curve to linear values, so
 * each colour is linearised first. */
static const float VIRIDIS[9][3] = {
    {0.267f, 0.005f, 0.329f}, {0.283f, 0.141f, 0.458f}, {0.254f, 0.265f, 0.530f},
    {0.207f, 0.372f, 0.553f}, {0.164f, 0.471f, 0.558f}, {0.128f, 0.567f, 0.551f},
    {0.135f, 0.659f, 0.518f}, {0.267f, 0.749f, 0.441f}, {0.993f, 0.906f, 0.144f}};
static const float COOLWARM[5][3] = {{0.230f, 0.299f, 0.754f}, {0.552f, 0.690f, 0.996f},
                                     {0.865f, 0.865f, 0.865f}, {0.958f, 0.604f, 0.482f},
                                     {0.706f, 0.016f, 0.150f}};

static float srgb_to_linear(float c)
{
    return c <= 0.04045f ? c / 12.92f : powf((c + 0.055f) / 1.055f, 2.4f);
}

static void colour_map(const float (*map)[3], int n, float t, float *rgb)
{
    float x;
    int i, k;
    if (!(t > 0.0f)) t = 0.0f;
    if (t > 1.0f) t = 1.0f;
    x = t * (float)(n - 1);
    i = (int)x;
    if (i >= n - 1) i = n - 2;
    x -= (float)i;
    for (k = 0; k < 3; ++k) rgb[k] = srgb_to_linear(map[i][k] * (1.0f - x) + map[i + 1][k] * x);
}

/* Writes one diagnostic map as grey PFM and false-colour PNG.  `mode`: 0 linear
 * from 0 to the 99th percentile, 1 logarithmic over 4 decades below it, 2
 * signed (symmetric around 0, to the 99th percentile of |v|). */
static int write_aux(const char *prefix, const char *name, const float *v, uint32_t w, uint32_t h,
                     int mode)
{
    size_t n = (size_t)w * h, i, m = 0;
    float *rgb = (float *)malloc(n * 3 * sizeof(float)), *tmp = (float *)malloc(n * sizeof(float));
    char path[4096];
    appm_image img;
    appm_diag d;
    float hi = 0.0f;
    int ok = 1;
    if (!rgb || !tmp) {
        free(rgb);
        free(tmp);
        fprintf(stderr, "%s: out of memory writing %s map\n", g_who, name);
        return 0;
    }
    for (i = 0; i < n; ++i) {
        rgb[3 * i] = rgb[3 * i + 1] = rgb[3 * i + 2] = v[i];
        if (v[i] == v[i]) tmp[m++] = mode == 2 ? fabsf(v[i]) : v[i];
    }
    img.width = w;
    img.height = h;
    img.rgb = rgb;
    snprintf(path, sizeof path, "%s-%s.pfm", prefix, name);
    if (appm_image_write(path, &img, 1.0, &d) != APPM_OK) {
        fprintf(stderr, "%s: %s: %s\n", g_who, path, d.message);
        ok = 0;
    }
    if (m > 0) { /* 99th percentile by a partial sort would be nicer; a histogram pass is enough */
        size_t k;
        float mx = 0.0f;
        for (k = 0; k < m; ++k) mx = tmp[k] > mx ? tmp[k] : mx;
        if (mx > 0.0f) {
            size_t bins[1024] = {0}, acc = 0;
            for (k = 0; k < m; ++k) {
                size_t b = (size_t)(tmp[k] / mx * 1023.0f);
                bins[b > 1023 ? 1023 : b]++;
            }
            for (k = 0; k < 1024; ++k) {
                acc += bins[k];
                if (acc >= m - m / 100) break;
            }
            hi = mx * (float)(k + 1) / 1024.0f;
        }
    }
    for (i = 0; i < n; ++i) {
        float t, x = v[i];
        if (!(hi > 0.0f) || x != x) t = 0.0f;
        else if (mode == 0) t = x / hi;
        else if (mode == 1) t = x > 0.0f ? 1.0f + log10f(x / hi) / 4.0f : 0.0f;
        else t = 0.5f + 0.5f * x / hi;
        if (mode == 2) colour_map(COOLWARM, 5, t, rgb + 3 * i);
        else colour_map(VIRIDIS, 9, t, rgb + 3 * i);
    }
    snprintf(path, sizeof path, "%s-%s.png", prefix, name);
    if (appm_image_write(path, &img, 1.0, &d) != APPM_OK) {
        fprintf(stderr, "%s: %s: %s\n", g_who, path, d.message);
        ok = 0;
    }
    free(rgb);
    free(tmp);
    return ok;
}

/* ---- appm render ----------------------------------------------------------- */

#define MAX_CLI_LIGHTS 256

typedef struct render_opts {
    const char *scene, *output, *reference, *log, *aux, *checkpoint, *resume;
    appm_config cfg;
    appm_write_options write;
    double lights[MAX_CLI_LIGHTS][6]; /* --light point: position, intensity */
    int nlights, have_env;
    double env[3];                    /* --environment */
    const char *env_map;              /* --environment-map */
    double env_scale, env_rotate;     /* --environment-scale, --environment-rotate */
    int have_env_scale, have_env_rotate;
    int have_stand_in;                /* --stand-in given */
    double time_limit, until_error, exposure;
    unsigned long long passes, checkpoint_every; /* 0: every CHECKPOINT_SECONDS */
    int quiet, have_time, have_passes, have_until;
} render_opts;

/* --light point X Y Z R G B  or  --environment R G B, at argv[*i]; moves *i to
 * the last value.  Returns -1 when fine, else the usage error's exit code. */
static int parse_light(int argc, char **argv, int *i, render_opts *o)
{
    const char *a = argv[*i];
    int env = a[2] == 'e', k, first = *i + (env ? 1 : 2), n = env ? 3 : 6;
    double *dst = env ? o->env : o->lights[o->nlights];
    if (!env && o->nlights == MAX_CLI_LIGHTS) return usage_error("more than %d --light options", MAX_CLI_LIGHTS);
    if (!env && (*i + 1 >= argc || strcmp(argv[*i + 1], "point") != 0))
        return usage_error("--light needs: point X Y Z R G B");
    for (k = 0; k < n; ++k) {
        if (first + k >= argc || !parse_double(argv[first + k], &dst[k]))
            return usage_error(env ? "--environment needs three numbers R G B" : "--light needs: point X Y Z R G B");
        if ((env || k >= 3) && dst[k] < 0)
            return usage_error("%s: negative %s '%s'", a, env ? "radiance" : "intensity", argv[first + k]);
    }
    *i = first + n - 1;
    if (env) o->have_env = 1;
    else o->nlights++;
    return -1;
}

/* The options about files and their formats: whether `a` (with value v) is
 * one, and then *rc = -1 when fine, else the usage error's exit code. */
static int parse_output_option(const char *a, const char *v, render_opts *o, int *rc)
{
    unsigned long long u;
    double d;
    *rc = -1;
    if (strcmp(a, "-o") == 0 || strcmp(a, "--output") == 0) o->output = v;
    else if (strcmp(a, "--reference") == 0) o->reference = v;
    else if (strcmp(a, "--log") == 0) o->log = v;
    else if (strcmp(a, "--aux") == 0) o->aux = v;
    else if (strcmp(a, "--checkpoint") == 0) o->checkpoint = v;
    else if (strcmp(a, "--resume") == 0) o->resume = v;
    else if (strcmp(a, "--checkpoint-every") == 0) {
        if (!parse_u64(v, &u) || u == 0) *rc = usage_error("--checkpoint-every needs passes >= 1, not '%s'", v);
        else o->checkpoint_every = u;
    } else if (strcmp(a, "--exr") == 0) {
        if (strcmp(v, "float") == 0) o->write.exr_half = 0;
        else if (strcmp(v, "half") == 0) o->write.exr_half = 1;
        else *rc = usage_error("--exr must be float or half, not '%s'", v);
    } else if (strcmp(a, "--exr-compression") == 0) {
        if (strcmp(v, "zip") == 0) o->write.exr_uncompressed = 0;
        else if (strcmp(v, "none") == 0) o->write.exr_uncompressed = 1;
        else *rc = usage_error("--exr-compression must be zip or none, not '%s'", v);
    } else if (strcmp(a, "--environment-map") == 0) {
        o->env_map = v;
    } else if (strcmp(a, "--environment-scale") == 0) {
        if (!parse_double(v, &d) || !(d >= 0 && d <= 1e30))
            *rc = usage_error("--environment-scale needs a number in [0, 1e30], not '%s'", v);
        else o->env_scale = d, o->have_env_scale = 1;
    } else if (strcmp(a, "--environment-rotate") == 0) {
        if (!parse_double(v, &d) || !(fabs(d) <= 1e6))
            *rc = usage_error("--environment-rotate needs degrees in [-1e6, 1e6], not '%s'", v);
        else o->env_rotate = d, o->have_env_rotate = 1;
    } else if (strcmp(a, "--stand-in") == 0) {
        if (strcmp(v, "studio") == 0) o->cfg.stand_in = APPM_STAND_IN_STUDIO;
        else if (strcmp(v, "white") == 0) o->cfg.stand_in = APPM_STAND_IN_WHITE;
        else *rc = usage_error("--stand-in must be studio or white, not '%s'", v);
        o->have_stand_in = 1;
    } else if (strcmp(a, "--missing-textures") == 0) {
        if (strcmp(v, "error") == 0) o->cfg.missing_textures = APPM_MISSING_TEXTURES_ERROR;
        else if (strcmp(v, "warn") == 0) o->cfg.missing_textures = APPM_MISSING_TEXTURES_WARN;
        else *rc = usage_error("--missing-textures must be error or warn, not '%s'", v);
    } else if (strcmp(a, "--exposure") == 0) {
        if (!parse_double(v, &d) || !(d > 0)) *rc = usage_error("--exposure needs a number > 0, not '%s'", v);
        else o->exposure = d;
    } else {
        return 0;
    }
    return 1;
}

/* The options of the render itself (method, sampler, stopping rules, the
 * appm_config numbers): as parse_output_option. */
static int parse_render_option(const char *a, const char *v, render_opts *o, int *rc)
{
    unsigned long long u;
    double d;
    *rc = -1;
    if (strcmp(a, "--method") == 0) {
        char names[256];
        if (appm_method_parse(v, &o->cfg.method) != APPM_OK)
            *rc = usage_error("unknown method '%s' (%s)", v, method_list(names, sizeof names));
    } else if (strcmp(a, "--sampler") == 0) {
        if (strcmp(v, "qmc") == 0) o->cfg.sampler = APPM_SAMPLER_QMC;
        else if (strcmp(v, "random") == 0) o->cfg.sampler = APPM_SAMPLER_RANDOM;
        else *rc = usage_error("--sampler must be qmc or random, not '%s'", v);
    } else if (strcmp(a, "--direct") == 0) {
        if (strcmp(v, "nee") == 0) o->cfg.direct = APPM_DIRECT_NEE;
        else if (strcmp(v, "photons") == 0) o->cfg.direct = APPM_DIRECT_PHOTONS;
        else *rc = usage_error("--direct must be nee or photons, not '%s'", v);
    } else if (strcmp(a, "--time") == 0) {
        if (!parse_double(v, &d) || !(d > 0)) {
            *rc = usage_error("--time needs seconds > 0, not '%s'", v);
        } else {
            o->time_limit = d;
            o->have_time = 1;
        }
    } else if (strcmp(a, "--until-error") == 0) {
        if (!parse_double(v, &d) || !(d > 0)) {
            *rc = usage_error("--until-error needs a number > 0, not '%s'", v);
        } else {
            o->until_error = d;
            o->have_until = 1;
        }
    } else if (strcmp(a, "--passes") == 0) {
        if (!parse_u64(v, &u) || u == 0) {
            *rc = usage_error("--passes needs an integer >= 1, not '%s'", v);
        } else {
            o->passes = u;
            o->have_passes = 1;
        }
    } else if (strcmp(a, "--photons") == 0) {
        if (!parse_u64(v, &u) || u == 0 || u > 4294967296ull)
            *rc = usage_error("--photons needs an integer in 1..2^32, not '%s'", v);
        else o->cfg.photons = u;
    } else if (strcmp(a, "--radius") == 0) {
        if (!parse_double(v, &d) || !(d > 0)) *rc = usage_error("--radius needs a length > 0, not '%s'", v);
        else o->cfg.radius = d;
    } else if (strcmp(a, "--alpha") == 0) {
        if (!parse_double(v, &d) || !(d > 0 && d <= 1)) *rc = usage_error("--alpha must be in (0, 1], not '%s'", v);
        else o->cfg.alpha = d;
    } else if (strcmp(a, "--threads") == 0) {
        if (!parse_u64(v, &u) || u == 0 || u > 256) *rc = usage_error("--threads needs 1..256, not '%s'", v);
        else o->cfg.threads = (unsigned)u;
    } else if (strcmp(a, "--seed") == 0) {
        if (!parse_u64(v, &u)) *rc = usage_error("--seed needs an integer from 0 to 18446744073709551615, not '%s'", v);
        else o->cfg.seed = u;
    } else if (strcmp(a, "--emission") == 0) {
        if (strcmp(v, "guided") == 0) o->cfg.emission = APPM_EMISSION_GUIDED;
        else if (strcmp(v, "light") == 0) o->cfg.emission = APPM_EMISSION_LIGHT;
        else *rc = usage_error("--emission needs guided or light, not '%s'", v);
    } else if (strcmp(a, "--chains") == 0) {
        if (!parse_u64(v, &u) || u == 0 || u > 64) *rc = usage_error("--chains needs 1..64, not '%s'", v);
        else o->cfg.chains = (unsigned)u;
    } else if (strcmp(a, "--max-depth") == 0) {
        if (!parse_u64(v, &u) || u == 0 || u > 254) *rc = usage_error("--max-depth needs 1..254, not '%s'", v);
        else o->cfg.max_depth = (unsigned)u;
    } else if (strcmp(a, "--size") == 0) {
        unsigned long w, h;
        char x, extra;
        if (sscanf(v, "%lu%c%lu%c", &w, &x, &h, &extra) != 3 || (x != 'x' && x != 'X') || w < 1 || h < 1 ||
            w > 32768 || h > 32768) {
            *rc = usage_error("--size needs WxH with 1 <= W, H <= 32768, not '%s'", v);
        } else {
            o->cfg.width = (uint32_t)w;
            o->cfg.height = (uint32_t)h;
        }
    } else {
        return 0;
    }
    return 1;
}

static int parse_render(int argc, char **argv, render_opts *o)
{
    int i;
    memset(o, 0, sizeof *o);
    appm_config_init(&o->cfg);
    o->exposure = 1.0;
    for (i = 2; i < argc; ++i) {
        const char *a = argv[i], *v = i + 1 < argc ? argv[i + 1] : NULL;
        int rc;
        if (strcmp(a, "-h") == 0 || strcmp(a, "--help") == 0) {
            fputs(RENDER_HELP, stdout);
            fputs(RENDER_HELP_LIGHTS, stdout);
            exit(EXIT_OK);
        }
        if (strcmp(a, "-q") == 0 || strcmp(a, "--quiet") == 0) {
            o->quiet = 1;
            continue;
        }
        if (strcmp(a, "--light") == 0 || strcmp(a, "--environment") == 0) {
            if ((rc = parse_light(argc, argv, &i, o)) >= 0) return rc;
            continue;
        }
        if (a[0] != '-' || a[1] == 0) {
            if (o->scene) return usage_error("more than one scene given ('%s')", a);
            o->scene = a;
            continue;
        }
        if (!v) return usage_error("option %s needs a value", a);
        i++;
        if (!parse_output_option(a, v, o, &rc) && !parse_render_option(a, v, o, &rc))
            return usage_error("unknown option '%s'", a);
        if (rc >= 0) return rc;
    }
    if (!o->scene) return usage_error("render needs a scene file");
    if (o->checkpoint_every && !o->checkpoint) return usage_error("--checkpoint-every needs --checkpoint FILE");
    if ((o->have_env_scale || o->have_env_rotate) && !o->env_map)
        return usage_error("--environment-scale and --environment-rotate need --environment-map FILE");
    if (o->env_map && o->have_env) return usage_error("--environment and --environment-map: give one of them");
    /* the user's own lights replace all of the studio (its plate and camera too), as
     * they replaced the white environment before: the bare OBJ loads without one */
    if (!o->have_stand_in && (o->nlights || o->have_env || o->env_map)) o->cfg.stand_in = APPM_STAND_IN_WHITE;
    return -1;
}

/* "dir/name.scene" -> "name.png" */
static void default_output(const char *scene, char *out, size_t cap)
{
    const char *base = scene, *p, *dot = NULL;
    size_t n;
    for (p = scene; *p; ++p)
        if (*p == '/' || *p == '\\') base = p + 1;
    for (p = base; *p; ++p)
        if (*p == '.') dot = p;
    n = dot ? (size_t)(dot - base) : strlen(base);
    if (n == 0) {
        base = "render";
        n = 6;
    }
    if (n + 5 > cap) n = cap - 5;
    memcpy(out, base, n);
    memcpy(out + n, ".png", 5);
}

/* Seconds of wall time between checkpoints without --checkpoint-every. */
#define CHECKPOINT_SECONDS 10.0

/* Whether a checkpoint is due after this pass (last: time and pass of the last one). */
static int checkpoint_due(const render_opts *o, const appm_stats *st, double now, const double *last)
{
    if (!o->checkpoint) return 0;
    if (o->checkpoint_every) return st->passes % o->checkpoint_every == 0;
    return now - last[0] >= CHECKPOINT_SECONDS;
}

/* Saves the checkpoint; 0 (with a message) if it could not be written. */
static int save_checkpoint(appm_renderer *r, const render_opts *o, double now, double *last)
{
    appm_diag d;
    appm_stats st;
    appm_status s = appm_renderer_save_file(r, o->checkpoint, &d);
    appm_renderer_stats(r, &st);
    last[0] = now;
    last[1] = (double)st.passes;
    if (s == APPM_OK) return 1;
    lib_error(s, &d, o->checkpoint);
    return 0;
}

/* --environment or --environment-map, then the --light point lights, in
 * command-line order. */
static int add_cli_lights(const render_opts *o, appm_scene *scene)
{
    appm_diag d;
    appm_status s;
    int k;
    if (o->have_env && (s = appm_scene_set_environment(scene, o->env, &d)) != APPM_OK)
        return lib_error(s, &d, "--environment");
    if (o->env_map && (s = appm_scene_set_environment_map(scene, o->env_map, o->have_env_scale ? o->env_scale : 1.0,
                                                          o->env_rotate, &o->cfg, &d)) != APPM_OK)
        return lib_error(s, &d, o->env_map);
    for (k = 0; k < o->nlights; ++k)
        if ((s = appm_scene_add_point_light(scene, o->lights[k], o->lights[k] + 3, &d)) != APPM_OK)
            return lib_error(s, &d, "--light");
    return EXIT_OK;
}

/* --resume: the checkpoint into r, its pass count into *resumed; EXIT_OK or the exit code. */
static int resume_render(appm_renderer *r, const render_opts *o, unsigned long long *resumed)
{
    appm_diag d;
    appm_stats st;
    appm_status s = appm_renderer_load_file(r, o->resume, &d); /* in a job, through cfg.reader */
    if (s != APPM_OK) return lib_error(s, &d, o->resume);
    appm_renderer_stats(r, &st);
    *resumed = (unsigned long long)st.passes;
    if (!o->quiet) fprintf(stderr, "%s: resuming %s after pass %llu\n", g_who, o->resume, *resumed);
    return EXIT_OK;
}

/* The state of one `appm render`, shared by its steps. */
typedef struct render_run {
    render_opts o;
    char outbuf[1024];          /* the default output name */
    appm_scene *scene;
    appm_renderer *r;
    appm_image ref, img;        /* --reference; the render's image */
    appm_stats st;
    appm_compare_result cmp;    /* of the image against ref, if have_cmp */
    int have_cmp, progress;
    FILE *logf;                 /* --log */
    double t0, last_ck[2];      /* start of the passes; time and pass of the last checkpoint */
    double drawn;               /* when the progress line was last drawn (seconds after t0) */
    unsigned long long resumed; /* passes the --resume checkpoint held */
    clock_t c0;                 /* processor time of the passes: the cost on a shared machine */
} render_run;

/* What the options leave open: the output name, the stopping rule (60 s), where warnings go. */
static void render_defaults(render_run *R)
{
    render_opts *o = &R->o;
    o->cfg.log = on_warning;
    o->cfg.log_user = &o->quiet;
    if (g_cli) {
        o->cfg.reader = g_cli->reader;
        if (g_cli->allocator.alloc) o->cfg.allocator = g_cli->allocator;
        if (!cli_root()) o->quiet = 1; /* rank 0 speaks for the job; errors still print */
    }
    if (!o->output) {
        default_output(o->scene, R->outbuf, sizeof R->outbuf);
        o->output = R->outbuf;
    }
    if (!o->have_time && !o->have_passes && !o->have_until) {
        o->time_limit = 60.0;
        o->have_time = 1;
    }
}

/* The path tracer reaches a point or spot light only by a shadow ray, which no
 * mirror or glass lets through: light from such a light that reaches a surface
 * through one (a caustic) is missing from its image, and the renderer keeps no
 * error estimate there (appm_renderer_keeps_error). */
static void warn_pt_caustics(const render_opts *o, const appm_renderer *r)
{
    if (o->cfg.method != APPM_METHOD_PT || !o->cfg.log || appm_renderer_keeps_error(r)) return;
    o->cfg.log(o->cfg.log_user, o->scene, 0,
               "pt does not render the light that reaches a surface through a mirror or glass from a point or "
               "spot light, or from an area light or a sun in the environment map too small to be met by "
               "chance (caustics): its image leaves it out or shows it as rare bright speckles, and it reports "
               "no error estimate (--method appm renders it)");
}

/* --until-error needs an error estimate: ppm and sppm keep none, nor does the
 * path tracer where it cannot see some of the light.  Alone it would never stop
 * the render, so it is refused; beside --time or --passes it is only said to
 * have no effect. */
static int check_until_error(const render_opts *o, const appm_renderer *r)
{
    const char *why = o->cfg.method == APPM_METHOD_PT ? "reports no error estimate on a scene whose caustics it "
                                                        "cannot find (a point, spot or tiny light and a mirror or glass)"
                                                      : "keeps no error estimate";
    if (!o->have_until || appm_renderer_keeps_error(r)) return EXIT_OK;
    if (!o->have_time && !o->have_passes)
        return usage_error("--until-error: %s %s, so the render would never stop (--method appm keeps one; "
                           "or add --time or --passes)",
                           appm_method_name(o->cfg.method), why);
    if (o->cfg.log) {
        char msg[256];
        snprintf(msg, sizeof msg, "--until-error has no effect: %s %s", appm_method_name(o->cfg.method), why);
        o->cfg.log(o->cfg.log_user, o->scene, 0, msg);
    }
    return EXIT_OK;
}

/* The scene with the command line's lights, the reference image, the renderer
 * (resumed from --resume), the log; EXIT_OK or the exit code. */
static int render_setup(render_run *R)
{
    const render_opts *o = &R->o;
    appm_diag d;
    appm_status s;
    int rc;
    if ((s = appm_scene_load(o->scene, &o->cfg, &R->scene, &d)) != APPM_OK) {
        rc = lib_error(s, &d, o->scene);
        /* a job's ranks parse the same bytes, so they fail alike - except for
         * memory, where this rank may have left the others reading files */
        if (g_cli && s == APPM_ERR_NOMEM) g_cli->abort_job(rc);
        return cli_agree(rc);
    }
    if ((rc = cli_agree(add_cli_lights(o, R->scene))) != EXIT_OK) return rc;
    if ((s = appm_renderer_create(R->scene, &o->cfg, &R->r, &d)) != APPM_OK) rc = lib_error(s, &d, NULL);
    else if (g_cli && (s = appm_renderer_set_cluster(R->r, &g_cli->cluster, &d)) != APPM_OK)
        rc = lib_error(s, &d, NULL);
    if ((rc = cli_agree(rc)) != EXIT_OK) return rc; /* before the --resume read every rank takes part in */
    warn_pt_caustics(o, R->r);
    if ((rc = cli_agree(check_until_error(o, R->r))) != EXIT_OK) return rc;
    if (o->resume && (rc = resume_render(R->r, o, &R->resumed)) != EXIT_OK) return rc;
    /* what rank 0 alone reads comes after the reads every rank of a job takes part in */
    if (o->reference && cli_root() && (s = appm_image_read(o->reference, NULL, &R->ref, &d)) != APPM_OK)
        return lib_error(s, &d, o->reference);
    if (R->ref.rgb) {
        appm_renderer_image(R->r, &R->img);
        if (R->ref.width != R->img.width || R->ref.height != R->img.height) {
            fprintf(stderr, "%s: %s: reference is %lux%lu, the render %lux%lu\n", g_who, o->reference,
                    (unsigned long)R->ref.width, (unsigned long)R->ref.height, (unsigned long)R->img.width,
                    (unsigned long)R->img.height);
            return EXIT_INPUT;
        }
    }
    if (o->log && cli_root()) {
        R->logf = fopen(o->log, o->resume ? "a" : "w"); /* a resumed render continues its log */
        if (!R->logf) {
            fprintf(stderr, "%s: %s: cannot open the log for writing\n", g_who, o->log);
            return EXIT_INPUT;
        }
        if (!o->resume || ftell(R->logf) == 0) fprintf(R->logf, "pass,seconds,photons,rmse,relmse,est_relerr\n");
    }
    return EXIT_OK;
}

/* After a pass at el seconds: the comparison with --reference and the --log row. */
static void render_log_pass(render_run *R, double el)
{
    const appm_stats *st = &R->st;
    if (!R->ref.rgb && !R->logf) return;
    R->have_cmp = 0;
    if (R->ref.rgb) {
        appm_renderer_image(R->r, &R->img);
        R->have_cmp = appm_image_compare(&R->img, &R->ref, &R->cmp) == APPM_OK;
    }
    if (R->logf) {
        fprintf(R->logf, "%llu,%.6f,%llu,", (unsigned long long)st->passes, el,
                (unsigned long long)st->photons_emitted);
        if (R->have_cmp) fprintf(R->logf, "%.9g,%.9g,", R->cmp.rmse, R->cmp.relmse);
        else fprintf(R->logf, ",,");
        if (st->est_relerr >= 0) fprintf(R->logf, "%.9g", st->est_relerr);
        fprintf(R->logf, "\n");
    }
}

/* The progress line on a terminal: the time left by --time or by the passes' pace. */
static void render_progress(const render_run *R, double el)
{
    const render_opts *o = &R->o;
    const appm_stats *st = &R->st;
    double remaining = o->have_time ? o->time_limit - el : -1.0;
    if (o->have_passes) {
        double by_pass = el / (double)(st->passes - R->resumed) * (double)(o->passes - st->passes);
        if (remaining < 0 || by_pass < remaining) remaining = by_pass;
    }
    fprintf(stderr, "\rpass %llu  photons %.3g  elapsed %.1fs  remaining %.1fs   ", (unsigned long long)st->passes,
            (double)st->photons_emitted, el, remaining > 0 ? remaining : 0.0);
    fflush(stderr);
}

/* After a pass at el seconds: a checkpoint if one is due, then whether to
 * stop - 0 go on, 1 stop, else the exit code of a failed checkpoint.  Rank 0
 * of a job decides (its clock, its Ctrl-C) and saves for all. */
static int render_next(render_run *R, double el)
{
    const render_opts *o = &R->o;
    int code = 0;
    if (cli_root()) {
        if (checkpoint_due(o, &R->st, now_seconds(), R->last_ck) &&
            !save_checkpoint(R->r, o, now_seconds(), R->last_ck))
            code = EXIT_RUNTIME;
        else if (g_interrupted || (o->have_time && el >= o->time_limit) ||
                 (o->have_until && R->st.est_relerr >= 0 && R->st.est_relerr < o->until_error))
            code = 1;
    }
    return g_cli ? g_cli->decide(code) : code;
}

/* After a pass at el seconds: R->st as this render reads it.  Reading the
 * stats makes the error estimate (appm_renderer_stats: a sweep over the
 * pixels, 3 % of a small pass), so they are read after every pass only for
 * --log, --reference and --until-error; else only to redraw the progress line
 * (at most five times a second: R->drawn = el), and the pass count, all the
 * stopping rules and the checkpoints read besides, moves on by itself. */
static void render_read_stats(render_run *R, double el)
{
    const render_opts *o = &R->o;
    if (R->logf || R->ref.rgb || o->have_until || (R->progress && el - R->drawn >= 0.2)) {
        appm_renderer_stats(R->r, &R->st);
        R->drawn = R->progress && el - R->drawn >= 0.2 ? el : R->drawn;
    } else {
        R->st.passes++;
    }
}

/* Passes until a stopping rule holds (--passes, --time, --until-error, Ctrl-C)
 * or a pass or a checkpoint fails; EXIT_OK or the exit code. */
static int render_passes(render_run *R)
{
    const render_opts *o = &R->o;
    appm_status s;
    int next;
    R->progress = !o->quiet && appm_isatty(2);
    signal(SIGINT, on_sigint);
    signal(SIGTERM, on_sigint); /* a shutdown, a batch system's time limit: finish the pass, save, write */
    R->t0 = R->last_ck[0] = now_seconds();
    R->drawn = -1.0;
    R->c0 = clock();
    appm_renderer_stats(R->r, &R->st);
    for (;;) {
        double el;
        if (o->have_passes && R->st.passes >= o->passes) break; /* also a checkpoint already past N */
        if ((s = appm_renderer_pass(R->r)) != APPM_OK) { /* on every rank of a job alike */
            fprintf(stderr, "%s: pass failed: %s\n", g_who,
                    appm_renderer_last_error(R->r)[0] ? appm_renderer_last_error(R->r) : appm_status_string(s));
            return EXIT_RUNTIME;
        }
        el = now_seconds() - R->t0;
        render_read_stats(R, el);
        render_log_pass(R, el);
        if (R->progress && R->drawn == el) render_progress(R, el);
        if ((next = render_next(R, el)) != 0) return next == 1 ? EXIT_OK : next;
    }
    return EXIT_OK;
}

/* --aux: each map the method has, as PFM and false-colour PNG; 0 if one failed. */
static int render_write_aux(render_run *R)
{
    static const char *const names[APPM_AUX_COUNT] = {"radius", "variance",       "laplacian",
                                                      "error",  "radius-caustic", "radius-diffuse"};
    static const int modes[APPM_AUX_COUNT] = {0, 1, 2, 1, 0, 0};
    int k, ok = 1;
    const float *e;
    unsigned w, h;
    for (k = 0; k < APPM_AUX_COUNT; ++k) {
        const float *a = appm_renderer_aux(R->r, (appm_aux)k);
        if (a && !write_aux(R->o.aux, names[k], a, R->img.width, R->img.height, modes[k])) ok = 0;
    }
    for (k = 0; (e = appm_renderer_emission_map(R->r, (unsigned)k, &w, &h)) != NULL; ++k) {
        char name[32];
        snprintf(name, sizeof name, "emission-%d", k);
        if (!write_aux(R->o.aux, name, e, w, h, 0)) ok = 0;
    }
    return ok;
}

/* After the passes (rc: how they ended): the last checkpoint, then the image
 * and the aux maps - also after Ctrl-C or a failed pass (which commits
 * nothing), if any pass is done; rc, or the exit code of a failed write. */
static int render_write(render_run *R, int rc)
{
    render_opts *o = &R->o;
    appm_diag d;
    appm_status s;
    appm_renderer_stats(R->r, &R->st); /* also after a failed pass, even the first */
    if (R->progress) {
        if (rc == EXIT_OK && R->st.passes > R->resumed) render_progress(R, now_seconds() - R->t0); /* the last pass's */
        fprintf(stderr, "\n");
    }
    if (!cli_root()) return rc;
    if (o->checkpoint && (double)R->st.passes != R->last_ck[1] && !save_checkpoint(R->r, o, now_seconds(), R->last_ck))
        rc = EXIT_RUNTIME;
    if (rc != EXIT_OK && R->st.passes == 0) return rc;
    appm_renderer_image(R->r, &R->img);
    o->write.exposure = o->exposure;
    if ((s = appm_image_write_ex(o->output, &R->img, &o->write, NULL, &d)) != APPM_OK) {
        rc = lib_error(s, &d, o->output);
        return rc == EXIT_INPUT ? EXIT_RUNTIME : rc;
    }
    if (o->aux && !render_write_aux(R)) rc = EXIT_RUNTIME;
    return rc;
}

/* The summary line of the interface contract (section 3), on stdout. */
static void render_summary(render_run *R)
{
    const render_opts *o = &R->o;
    appm_stats *st = &R->st;
    appm_renderer_stats(R->r, st);
    printf("passes=%llu photons=%llu seconds=%.2f radius=%.6g output=%s method=%s threads=%u "
           "peak_bytes=%llu dropped=%llu",
           (unsigned long long)st->passes, (unsigned long long)st->photons_emitted, st->seconds, st->initial_radius,
           o->output, appm_method_name(o->cfg.method), st->threads, (unsigned long long)st->peak_bytes,
           (unsigned long long)st->dropped_samples);
    printf(" eye_s=%.3f photon_s=%.3f grid_s=%.3f gather_s=%.3f photons_stored=%llu", st->seconds_eye,
           st->seconds_photons, st->seconds_grid, st->seconds_gather, (unsigned long long)st->photons_stored);
    if (st->photons_per_pass) {
        printf(" photons_per_pass=%llu budget=%s", (unsigned long long)st->photons_per_pass,
               o->cfg.photons ? "fixed" : "auto");
        if (st->budget_rays > 0.0) printf(" budget_rays=%.3f", st->budget_rays);
    }
    if (st->est_relerr >= 0) printf(" est_relerr=%.4g", st->est_relerr);
    if (st->clamped >= 0) printf(" clamped=%.4f", st->clamped);
    if (o->cfg.emission == APPM_EMISSION_GUIDED) printf(" emission=guided guided=%.3f", st->emission_guided);
    else printf(" emission=light");
    printf(" sampler=%s", o->cfg.sampler == APPM_SAMPLER_RANDOM ? "random" : "qmc");
    if (o->cfg.sampler == APPM_SAMPLER_QMC) printf(" chains=%u", o->cfg.chains ? o->cfg.chains : 1u);
    printf(" cpu_s=%.3f", (double)(clock() - R->c0) / CLOCKS_PER_SEC);
    if (R->have_cmp) printf(" rmse=%.6g relmse=%.6g", R->cmp.rmse, R->cmp.relmse);
    if (o->resume) printf(" resumed=%llu", R->resumed);
    if (o->checkpoint) printf(" checkpoint=%s", o->checkpoint);
    if (g_interrupted) printf(" interrupted=1");
    if (g_cli)
        printf(" ranks=%u exchange_s=%.3f exchange_bytes_in=%llu exchange_bytes_out=%llu", g_cli->ranks,
               st->seconds_cluster, (unsigned long long)st->cluster_bytes_in,
               (unsigned long long)st->cluster_bytes_out);
    printf("\n");
}

/* Closes the log (a failed close is a write error) and frees everything. */
static int render_cleanup(render_run *R, int rc)
{
    if (R->logf && fclose(R->logf) != 0 && rc == EXIT_OK) {
        fprintf(stderr, "%s: %s: write error\n", g_who, R->o.log);
        rc = EXIT_RUNTIME;
    }
    appm_renderer_destroy(R->r);
    appm_image_free(NULL, &R->ref);
    appm_scene_destroy(R->scene);
    return rc;
}

static int cmd_render(int argc, char **argv)
{
    render_run R;
    int rc;
    memset(&R, 0, sizeof R);
    R.last_ck[1] = -1.0; /* no checkpoint yet */
    if ((rc = parse_render(argc, argv, &R.o)) >= 0) return rc;
    render_defaults(&R);
    rc = cli_agree(render_setup(&R));
    if (rc == EXIT_OK) rc = render_write(&R, render_passes(&R));
    if (rc == EXIT_OK && cli_root()) render_summary(&R);
    return render_cleanup(&R, rc);
}

/* ---- appm compare / info --------------------------------------------------- */

/* Pixels of `img` with a NaN or infinite channel; the first (in reading order,
 * row 0 at the top) into *fx, *fy.  Says so on stderr and returns their count. */
static unsigned long report_nonfinite(const char *path, const appm_image *img)
{
    unsigned long n = 0, fx = 0, fy = 0, i, npix = (unsigned long)img->width * img->height;
    for (i = 0; i < npix; ++i) {
        const float *p = &img->rgb[3 * i];
        int c, bad = 0;
        for (c = 0; c < 3; ++c) bad |= !(p[c] - p[c] == 0.0f); /* NaN or inf */
        if (bad && n++ == 0) {
            fx = i % img->width;
            fy = i / img->width;
        }
    }
    if (n)
        fprintf(stderr, "%s: %s: %lu pixel%s hold NaN or infinite values; the first is x=%lu y=%lu (row 0 at the top)\n", g_who,
                path, n, n == 1 ? "" : "s", fx, fy);
    return n;
}

static int cmd_compare(int argc, char **argv)
{
    appm_image a, b;
    appm_diag d;
    appm_compare_result c;
    appm_status s;
    if (argc != 4) return usage_error("compare needs two image files");
    if ((s = appm_image_read(argv[2], NULL, &a, &d)) != APPM_OK) {
        lib_error(s, &d, argv[2]);
        return EXIT_INPUT;
    }
    if ((s = appm_image_read(argv[3], NULL, &b, &d)) != APPM_OK) {
        lib_error(s, &d, argv[3]);
        appm_image_free(NULL, &a);
        return EXIT_INPUT;
    }
    if (appm_image_compare(&a, &b, &c) != APPM_OK) {
        fprintf(stderr, "%s: %s is %lux%lu but %s is %lux%lu\n", g_who, argv[2], (unsigned long)a.width,
                (unsigned long)a.height, argv[3], (unsigned long)b.width, (unsigned long)b.height);
        appm_image_free(NULL, &a);
        appm_image_free(NULL, &b);
        return EXIT_INPUT;
    }
    if (report_nonfinite(argv[2], &a) + report_nonfinite(argv[3], &b) > 0) {
        appm_image_free(NULL, &a);
        appm_image_free(NULL, &b);
        return EXIT_INPUT;
    }
    printf("rmse=%.6g relmse=%.6g mae=%.6g mean_a=%.6g mean_b=%.6g\n", c.rmse, c.relmse, c.mae,
           c.mean_a, c.mean_b);
    appm_image_free(NULL, &a);
    appm_image_free(NULL, &b);
    return EXIT_OK;
}

static int cmd_info(int argc, char **argv)
{
    appm_scene *scene;
    appm_renderer *r;
    appm_scene_info in;
    appm_stats st;
    appm_diag d;
    appm_config cfg;
    appm_status s;
    int quiet = 0;
    if (argc != 3) return usage_error("info needs one scene file");
    appm_config_init(&cfg);
    cfg.log = on_warning;
    cfg.log_user = &quiet;
    if ((s = appm_scene_load(argv[2], &cfg, &scene, &d)) != APPM_OK) return lib_error(s, &d, argv[2]);
    appm_scene_get_info(scene, &in);
    printf("scene       %s\n", argv[2]);
    printf("triangles   %llu (%llu degenerate dropped)\n", (unsigned long long)in.triangles,
           (unsigned long long)in.dropped_triangles);
    printf("materials   %u diffuse, %u mirror, %u dielectric, %u glossy (%u emissive)\n",
           in.materials_diffuse, in.materials_mirror, in.materials_dielectric, in.materials_glossy,
           in.materials_emissive);
    printf("lights      %u area, %u point, %u spot, %u environment\n", in.lights_area, in.lights_point,
           in.lights_spot, in.lights_environment);
    if (in.lights_area)
        printf("  power area         %.4g %.4g %.4g W\n", in.power_area[0], in.power_area[1], in.power_area[2]);
    if (in.lights_point)
        printf("  power point        %.4g %.4g %.4g W\n", in.power_point[0], in.power_point[1], in.power_point[2]);
    if (in.lights_spot)
        printf("  power spot         %.4g %.4g %.4g W\n", in.power_spot[0], in.power_spot[1], in.power_spot[2]);
    if (in.lights_environment)
        printf("  power environment  %.4g %.4g %.4g W\n", in.power_environment[0],
               in.power_environment[1], in.power_environment[2]);
    {
        static const char *const word[] = {"none", "one", "two", "three", "four"};
        unsigned n = in.shadow_rays_samples;
        char many[16];
        const char *samples = n < 5 ? word[n] : many;
        if (n >= 5) snprintf(many, sizeof many, "%u", n);
        printf("shadow rays %u a shading point", in.shadow_rays_own + n);
        if (in.shadow_rays_own)
            printf(": one to each of %u point or spot light%s", in.shadow_rays_own, in.shadow_rays_own > 1 ? "s" : "");
        if (in.shadow_rays_picked > 1)
            printf("%s %s%s picked by power among %u%s", in.shadow_rays_own ? "," : ":", samples,
                   n > 1 ? ", each to a light" : " to a light", in.shadow_rays_picked,
                   in.shadow_rays_own ? " others" : " lights");
        else if (in.shadow_rays_picked == 1)
            printf("%s %s to the %slight", in.shadow_rays_own ? "," : ":", samples, in.shadow_rays_own ? "other " : "");
    }
    printf("\n");
    printf("bounds      (%.5g, %.5g, %.5g) .. (%.5g, %.5g, %.5g)\n", in.bbox_min[0], in.bbox_min[1],
           in.bbox_min[2], in.bbox_max[0], in.bbox_max[1], in.bbox_max[2]);
    printf("bvh         %llu nodes, depth %u\n", (unsigned long long)in.bvh_nodes, in.bvh_depth);
    printf("open edges  %llu (appm cuts its kernel along them)\n", (unsigned long long)in.open_edges);
    printf("image       %ux%u\n", in.width, in.height);
    if (in.textures)
        printf("textures    %u maps, %.1f KiB (%u materials with cut-outs)\n", in.textures,
               (double)in.texture_bytes / 1024.0, in.materials_cutout);
    if (in.environment_map_width)
        printf("environment map %ux%u\n", in.environment_map_width, in.environment_map_height);
    printf("memory      scene %.1f KiB (peak while loading %.1f KiB)\n", (double)in.memory_bytes / 1024.0,
           (double)in.peak_bytes / 1024.0);
    cfg.threads = 1;
    if (appm_renderer_create(scene, &cfg, &r, &d) == APPM_OK) {
        appm_renderer_stats(r, &st);
        printf("            renderer %.1f MiB at %ux%u with %llu, %llu or %llu photon paths per pass (the "
               "photon budget chooses, and the photon store grows to fit, in the first pass)\n",
               (double)st.memory_bytes / (1024.0 * 1024.0), in.width, in.height,
               (unsigned long long)in.width * in.height, 2ull * in.width * in.height, 4ull * in.width * in.height);
        appm_renderer_destroy(r);
    }
    appm_scene_destroy(scene);
    return EXIT_OK;
}

static int appm_cli(int argc, char **argv)
{
    if (argc < 2 || strcmp(argv[1], "--help") == 0 || strcmp(argv[1], "-h") == 0) {
        fputs(HELP, argc < 2 ? stderr : stdout);
        return argc < 2 ? EXIT_USAGE : EXIT_OK;
    }
    if (strcmp(argv[1], "--version") == 0) {
        printf("appm %s\n", appm_version());
        return EXIT_OK;
    }
    if (strcmp(argv[1], "render") == 0) return cmd_render(argc, argv);
    if (strcmp(argv[1], "compare") == 0) return cmd_compare(argc, argv);
    if (strcmp(argv[1], "info") == 0) return cmd_info(argc, argv);
    return usage_error("unknown command '%s'", argv[1]);
}
#ifndef APPM_CLI_NO_MAIN
int main(int argc, char **argv)
{
    return appm_cli(argc, argv);
}
#endif
