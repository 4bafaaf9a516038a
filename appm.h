/* appm.h - Adaptive Progressive Photon Mapping.  Public API and manual.
 *
 * ABOUT
 *     appm renders physically based images of triangle scenes (Wavefront OBJ/MTL)
 *     by progressive photon mapping.  Each pass traces one eye path per pixel and a
 *     batch of photon paths, and joins them with a kernel of radius r.  A large r
 *     blurs (bias), a small r is noisy (variance), and the best r differs from
 *     pixel to pixel.  The default method, APPM (Kaplanyan & Dachsbacher 2013),
 *     estimates each pixel's variance and Laplacian from the photons themselves and
 *     picks, per pixel and pass, the radius that minimises the estimated error.
 *     The classic baselines (PPM with the Knaus-Zwicker global radius schedule,
 *     stochastic PPM) and an unbiased path tracer (for references) are included.
 *
 *     Two files, C99, no dependencies beyond libc and libm (threads optional).
 *
 * QUICK START
 *     examples/quickstart.c, which make test compiles and runs (and checks
 *     that it is, byte for byte, the program below).  Run it from the
 *     repository root:  cc -std=c99 -I. examples/quickstart.c appm.c -lm -pthread
 *
 *     #include <stdio.h>
 *     #include "appm.h"
 *
 *     int main(int argc, char **argv)
 *     {
 *         const char *out = argc > 1 ? argv[1] : "out.png";
 *         appm_config cfg = {0};             // zero means default, everywhere
 *         appm_scene *scene;
 *         appm_renderer *r;
 *         appm_diag diag;
 *         appm_image img;
 *         int pass, rc = 1;
 *         if (appm_scene_load("scenes/cornell-original.scene", &cfg, &scene, &diag)) {
 *             fprintf(stderr, "%s:%u: %s\n", diag.file, diag.line, diag.message);
 *             return 1;
 *         }
 *         cfg.width = cfg.height = 64;       // override the scene's image size
 *         if (appm_renderer_create(scene, &cfg, &r, &diag) == APPM_OK) {
 *             for (pass = 0; pass < 4; ++pass) appm_renderer_pass(r);
 *             appm_renderer_image(r, &img);  // borrowed view, linear RGB
 *             rc = appm_image_write(out, &img, 1.0, &diag) != APPM_OK;
 *             appm_renderer_destroy(r);
 *         }
 *         appm_scene_destroy(scene);
 *         return rc;
 *     }
 *
 *     examples/embed.c adds error handling for every call; the scene format is
 *     in docs/scene-format.md, the algorithm in docs/algorithm.md.
 *
 * BUILDING
 *     cc -std=c99 -O2 -c appm.c -pthread          (POSIX threads, the default on Unix)
 *     cc -std=c99 -O2 -DAPPM_THREADS=0 -c appm.c  (no threads: embedded, WASM)
 *     x86_64-w64-mingw32-gcc -std=c99 -O2 -c appm.c   (Win32 threads, the default on Windows)
 *     Link with -lm.  APPM_THREADS: 0 none, 1 pthreads, 2 Win32.
 *     Never build with -ffast-math: the renderer relies on NaN checks and on the
 *     order of floating-point sums (an #error says so).
 *     Unity build: #define APPM_API static, then #include "appm.c".
 *     SIMD: the BVH (8 children per node) tests a node's child boxes with SSE2
 *     on every x86-64 build, with AVX2 given -mavx2 or -march=native, and with
 *     NEON on aarch64, as the compiler's own macros say; tcc, other targets and
 *     -DAPPM_SIMD=0 use a portable scalar test.  Its leaves (up to 4
 *     triangles; up to 16 in a mesh of 32768 or more, where the surface-area
 *     cost says so) are tested four triangles at once in SSE2/NEON lanes, with the
 *     scalar watertight test's float operations per lane.  The scalar tests compute the
 *     same floats, so a SIMD build and its -DAPPM_SIMD=0 twin (same compiler,
 *     same other flags) render the same bytes, and so do gcc's default and
 *     -mavx2 builds (make portability checks both).
 *
 * CONVENTIONS
 *     Units are scene units; right-handed coordinates; angles in degrees at the
 *     interface (scene files, config), radians inside.  Colours are linear RGB
 *     radiance.  Image row 0 is the top row; pixel (x, y) of an appm_image is at
 *     rgb[3 * (y * width + x)].  PFM files store rows bottom to top, as the format
 *     demands; the readers and writers here flip for you.
 *
 *     Ownership: whatever appm creates, an appm_*_destroy() (or appm_image_free)
 *     frees; whatever you pass in stays yours; a pointer appm returns is borrowed
 *     until the next call that changes the same object.
 *
 *     Threads: a scene is immutable after loading and may be shared by any number
 *     of renderers in any threads.  A renderer is used by one thread at a time; it
 *     starts and joins its own worker threads inside each call.  The library has
 *     no global or thread-local state.
 *
 *     Errors: every fallible call returns an appm_status; APPM_OK is 0.  Calls that
 *     take an appm_diag * (may be NULL) fill it with the file, line and message of
 *     the first error.  The library never prints, exits or aborts; warnings go to
 *     the optional log callback, once per kind and file.
 *
 *     Memory: every allocation goes through cfg.allocator (malloc/free when both
 *     hooks are NULL).  Rendering allocates at renderer creation and, rarely, when
 *     a pass stores more photons than any pass before it; memory does not grow
 *     from pass to pass after that.
 *
 *     Determinism: the image depends only on the scene, the config, the seed and
 *     the number of passes - never on the thread count or on scheduling.
 *
 * ALGORITHM IN ONE SCREEN (method APPM, one pass j = 1, 2, ...)
 *     1. eye pass: per pixel, one jittered camera path through mirrors and glass to
 *        its first diffuse vertex x with weight W; direct light at x by next-event
 *        estimation (a shadow ray to each point and spot light, and one to an
 *        area or environment light picked by power; two under the studio's sky).
 *     2. radius: r = [c R(K) S / (M j mu2^2 dI^2)]^(1/6) from the pixel's running
 *        second moment S and Laplacian dI, per photon component (caustic:
 *        photons whose last bounce was specular; diffuse: the rest), clamped
 *        to [0.1 min(r1, r_auto), c max(r1, r_auto)] j^(-1/6) with c = 2 for the
 *        caustic component and 3 for the diffuse one (r_auto: 2 pixel widths,
 *        as cfg.radius).
 *     3. photon pass: M photon paths from the lights (chosen by power), stored at
 *        diffuse hits, binned into a hash grid.
 *     4. gather: per pixel, I += (1/j) ((1/M) sum_i k_r(x - y_i) W f gamma_i - I);
 *        S and dI are updated from the same photons (dI by a 5-point finite
 *        difference of kernel estimates with bandwidth h ~ j^(-1/8)).
 *     The pixel value is mean(direct) + I_caustic + I_diffuse.
 *
 * REFERENCES
 *     A. Kaplanyan, C. Dachsbacher. Adaptive Progressive Photon Mapping. ACM TOG
 *         32(2), 2013.
 *     C. Knaus, M. Zwicker. Progressive Photon Mapping: A Probabilistic Approach.
 *         ACM TOG 30(3), 2011.
 *     T. Hachisuka, S. Ogaki, H. W. Jensen. Progressive Photon Mapping. SIGGRAPH
 *         Asia 2008.   T. Hachisuka, H. W. Jensen. Stochastic Progressive Photon
 *         Mapping. SIGGRAPH Asia 2009.
 *
 * LICENSE
 *     MIT; the full text is at the end of appm.c.
 */
#ifndef APPM_H_INCLUDED
#define APPM_H_INCLUDED

#include <stddef.h> /* size_t */
#include <stdint.h> /* uint32_t, uint64_t */

#define APPM_VERSION_MAJOR 0
#define APPM_VERSION_MINOR 1
#define APPM_VERSION_PATCH 14
#define APPM_VERSION "0.1.14"

#ifndef APPM_API
#if defined(_WIN32) && defined(APPM_BUILD_DLL)
#define APPM_API __declspec(dllexport)
#elif defined(_WIN32) && defined(APPM_USE_DLL)
#define APPM_API __declspec(dllimport)
#else
#define APPM_API extern
#endif
#endif

#ifdef __cplusplus
extern "C" {
#endif

/* ---- Status and diagnostics ------------------------------------------------ */

typedef enum appm_status {
    APPM_OK = 0,
    APPM_ERR_NOMEM,       /* an allocation failed; nothing was leaked            */
    APPM_ERR_IO,          /* a file could not be opened, read or written         */
    APPM_ERR_PARSE,       /* malformed scene, OBJ, MTL or image: see appm_diag    */
    APPM_ERR_INVALID_ARG, /* NULL pointer, absurd option, NaN in input           */
    APPM_STATUS_COUNT
} appm_status;

/* Static English text for `s`; never NULL, never to be freed. */
APPM_API const char *appm_status_string(appm_status s);

/* "0.1.14": the version of the implementation that was compiled (APPM_VERSION is
 * the version of the header).  The patch number changes with every change to
 * what a pass computes (an estimator's constant, the sampler, the emission),
 * so a checkpoint never resumes under passes other than those that wrote it. */
APPM_API const char *appm_version(void);

/* Detail of the first error of a call.  `file` is the input file at fault (empty
 * when none), `line` its 1-based line (0 when not about a line). */
typedef struct appm_diag {
    appm_status status;
    unsigned line;
    char file[256];
    char message[256];
} appm_diag;

/* ---- Hooks ----------------------------------------------------------------- */

/* Both NULL: malloc/free.  Both set: every byte appm uses comes from `alloc`;
 * `free` gets the size that was asked for (for arena and pool allocators).
 * The renderer calls the hooks only from the thread that called appm. */
typedef struct appm_allocator {
    void *(*alloc)(void *user, size_t size);
    void (*free)(void *user, void *ptr, size_t size);
    void *user;
} appm_allocator;

/* Warnings (ignored MTL statements, clamped albedos, dropped triangles, ...).
 * `file` may be "" and `line` 0.  Each kind of warning is sent once per file. */
typedef void (*appm_log_fn)(void *user, const char *file, unsigned line, const char *message);

/* Where the loaders get the bytes of a file (appm_config.reader): read(user,
 * path, &data, &len) returns 0 and a buffer of len bytes that stays valid until
 * release(user, data), or non-zero when the file cannot be read (a missing
 * file: what fopen failing would mean).  appm copies the bytes and releases
 * them before it returns.  The distributed front end (mpi.c) reads every file
 * on rank 0 and sends it to the others with these hooks, so a scene only rank
 * 0 can see renders on every rank. */
typedef struct appm_file_reader {
    int (*read)(void *user, const char *path, const void **data, size_t *len);
    void (*release)(void *user, const void *data);
    void *user;
} appm_file_reader;

/* ---- Configuration --------------------------------------------------------- */

/* The methods.  appm-paper is Kaplanyan and Dachsbacher's adaptive radius as
 * its derivation gives it (docs/algorithm.md 4.1 - 4.8: one photon component,
 * the recursive finite-difference Laplacian on every pass, the closed-form
 * radius and its safeguards), for teaching and comparison.  appm, the default,
 * is that selector with seven measured steps on top (docs/algorithm.md 5): two
 * photon components (caustic and diffuse) with their own radii and Laplacian
 * bandwidths, a Laplacian on fewer passes with a wider bandwidth, its square
 * corrected for noise and pooled over neighbouring pixels, a start at twice the
 * automatic radius (a told radius is the start) and a k-nearest-neighbour
 * widening where photons are sparse, per-component bounds, and the kernel renormalised where the
 * surface ends inside it (a wall meeting the floor, a box's edge, a mesh's
 * open edge where the surface ends against nothing: without it every seam and
 * rim is dark by the kernel's missing part), and a caustic radius 0.7x as wide
 * where the caustic's bias, measured at two radii (r and r / sqrt 1.5), outruns
 * the model's twice over (a focused filament, since 0.1.13; the inner radius
 * since 0.1.14).  ppm and sppm keep their
 * papers' estimators but for one test that every photon method shares: a
 * photon on a surface that covers the gathering point (a lamp hung just under
 * a ceiling, facing as it does) is not gathered there (docs/algorithm.md 5.6,
 * since 0.1.4). */
typedef enum appm_method {
    APPM_METHOD_APPM = 0,   /* adaptive bandwidth, per pixel and pass (default)       */
    APPM_METHOD_PPM,        /* global radius r_j^2 = r_1^2 prod (k+alpha)/(k+1)       */
    APPM_METHOD_SPPM,       /* per-pixel N, tau, R statistics (Hachisuka-Jensen)       */
    APPM_METHOD_PT,         /* unbiased path tracer with NEE + MIS, for references    */
    APPM_METHOD_APPM_PAPER, /* the paper's adaptive bandwidth, one photon component   */
    APPM_METHOD_COUNT
} appm_method;

/* "appm", "ppm", "sppm", "pt", "appm-paper"; NULL for a value that is not a method. */
APPM_API const char *appm_method_name(appm_method m);

/* The method called `name` (as appm_method_name spells it) into *out;
 * APPM_ERR_INVALID_ARG (and *out untouched) for any other name or NULL. */
APPM_API appm_status appm_method_parse(const char *name, appm_method *out);

typedef enum appm_direct {
    APPM_DIRECT_NEE = 0,  /* direct light at the visible point by shadow rays      */
    APPM_DIRECT_PHOTONS   /* first-bounce photons are stored and gathered instead   */
} appm_direct;

/* Where the numbers of every path come from (appm.c, section 2.3).
 *   QMC: a randomized low-discrepancy sequence (Owen-scrambled Sobol' in
 *     padded groups of 4 dimensions, 6 for the photon's emission with its
 *     light choice, 5 for the camera with the eye path's component or Fresnel
 *     choice at its first vertex) in every dimension: pixel, lens, light choice, point on
 *     the light, BSDF direction, Fresnel choice, Russian roulette, photon
 *     emission and every photon bounce (the first 8 vertices of a path; PCG
 *     beyond).  The photons of all passes form one low-discrepancy set.  Stateless: a sample is a
 *     function of (seed, pass, pixel or photon index, dimension) only, so the
 *     state of a render is its pixel statistics and the pass counter - nothing
 *     else would need saving.  See `chains` for the error estimate.
 *   RANDOM: independent PCG streams (and the rotated R2 sequence for the pixel
 *     and lens), the sampler of earlier versions, bit for bit; kept to compare
 *     and to teach what the sequence buys. */
typedef enum appm_sampler {
    APPM_SAMPLER_QMC = 0,  /* default */
    APPM_SAMPLER_RANDOM
} appm_sampler;

/* Where photon paths start (appm.c section 9.1).
 *   LIGHT: the lights' own distributions (the images of versions before
 *     guiding was the default, bit for bit).
 *   GUIDED (default): each light's first emission sample - the direction of a point or
 *     spot light or of the environment, the point on an area light - is drawn
 *     from a mixture of the light's own distribution (a defensive quarter) and
 *     a 32x32 piecewise-constant density learned from where the photons that
 *     the visible points gathered in the finished passes were emitted.  Photon
 *     weights carry the ratio of the densities, so every estimator stays
 *     consistent; where nothing is gathered yet (the first pass, or a light
 *     whose photons no pixel sees), emission is the light's own.  The learned
 *     densities are part of a checkpoint.  At most 16 lights (the most
 *     powerful) are candidates, and a light is guided only where its learned
 *     density makes the photon pass more efficient (variance x cost, counted,
 *     not timed); elsewhere - a closed box, a light whose photons no pixel
 *     sees - it emits as LIGHT, and the image is LIGHT's bit for bit when no
 *     light ever pays.  Which light a path starts at is learned as well: the
 *     guided lights share their power's paths by the variance their photons
 *     leave in the pixels over their cost (a quarter still by power), where
 *     that cuts the photon pass's variance x cost by 5 % (since 0.1.3).  Measured at equal time (docs/algorithm.md 5.8): 0.73x
 *     the RMSE of LIGHT on a caustic seen only through glass, 0.97x on the
 *     teapot, 1.00x on the bunny under a sky (where guiding stays off). */
typedef enum appm_emission {
    APPM_EMISSION_GUIDED = 0, /* default; LIGHT was the default (and 0) in earlier
                               * versions: code that wants it names it */
    APPM_EMISSION_LIGHT
} appm_emission;

/* What a texture map (map_Kd, map_Ks, map_d) that cannot be read or decoded
 * does to a scene's load. */
typedef enum appm_missing_textures {
    APPM_MISSING_TEXTURES_ERROR = 0, /* default: the load fails, naming the map and the MTL line */
    APPM_MISSING_TEXTURES_WARN       /* one warning per map (cfg.log); the material renders without it */
} appm_missing_textures;

/* What lights a bare OBJ in which nothing emits and that names no light
 * (appm_scene_load of a .obj, appm_scene_load_obj_memory). */
typedef enum appm_stand_in {
    APPM_STAND_IN_STUDIO = 0, /* default: a product shot - a sky brighter above than below
                               * with a soft key light high on the left in front (an
                               * environment map), a grey ground plate (albedo 0.5) under
                               * the model's bounding box, 2 of its bounding radii each
                               * way, and the camera 20 degrees above, framing the model;
                               * its photons are aimed at the model and the plate (of the
                               * sky's photons travelling down half at the model, half at
                               * the plate, none elsewhere; those travelling up at the
                               * model; three quarters of the bounces off the plate at the
                               * model), with weights that keep every estimate unbiased
                               * (appm.c 6.3)                                              */
    APPM_STAND_IN_WHITE       /* a constant white environment of radiance 1 and the camera
                               * looking along -z: a furnace, as earlier versions lit it   */
} appm_stand_in;
/* Lights added to the loaded scene (appm_scene_add_point_light, ..._set_environment,
 * ..._set_environment_map) replace the stand-in's sky or white environment, and
 * with the sky its four shadow rays a shading point and its photon count of width *
 * height; the studio's plate, camera and aim stay, and its photons still skip
 * the roulette at their first hit.  The command line loads with WHITE when it is
 * given lights, so that they replace all of it. */

/* Every field: 0 (or NULL) means "default".  `appm_config cfg = {0};` works. */
typedef struct appm_config {
    appm_allocator allocator;
    appm_log_fn log;          /* NULL: warnings are dropped                          */
    void *log_user;

    appm_method method;       /* APPM_METHOD_APPM                                    */
    appm_direct direct;       /* APPM_DIRECT_NEE                                     */
    uint32_t width, height;   /* the scene's `image` size (512 x 512)                */
    uint64_t photons;         /* photon paths emitted per pass.  0: the photon budget
                               * (appm.c 12.2) - pass 1 counts the rays of its eye
                               * paths, E, and of width * height photon paths, P,
                               * and takes k * width * height, k the largest of 1,
                               * 2, 4 with k P <= 1.65 E (a caustic seen through
                               * glass: 4, 0.78-0.87x the error at equal time; the
                               * Cornell boxes: 1; the studio's sky keeps 1 whatever
                               * it counts).  Counted, not timed: the same
                               * choice on every machine and thread count, and the
                               * image of that count given.  stats.photons_per_pass
                               * says what was chosen                               */
    double radius;            /* initial radius r1, scene units: 2 pixel widths at the
                               * visible points of the first pass (median)          */
    double alpha;             /* ppm/sppm shrinkage in (0,1]: 2/3 (1 = fixed radius)  */
    unsigned threads;         /* worker threads: all cores                           */
    uint64_t seed;            /* 0 is a valid seed and the default                   */
    unsigned max_depth;       /* longest counted path, in segments: 32               */
    appm_sampler sampler;     /* APPM_SAMPLER_QMC                                    */
    /* qmc: passes dealt to this many independently scrambled, interleaved chains
     * (at most 64).  1 (default): one sequence, the best image; est_relerr then
     * takes the spread of the per-pass estimates, scaled by the difference of
     * the two halves of the last power of two of passes (each a whole net of the
     * sequence): successive passes are correlated, and their spread alone
     * overstates the error where the sequence helps.  K >= 2: est_relerr from
     * the spread between the chains, at a price in accuracy (each chain's nets
     * are K times coarser; 4 chains lost half or more of the gain on diffuse
     * boxes at 256 passes), 8 K bytes a pixel. */
    unsigned chains;
    appm_emission emission;   /* APPM_EMISSION_GUIDED                                */
    appm_file_reader reader;  /* every file a load reads (scenes, meshes, materials, maps,
                               * images, a renderer's checkpoints): NULL read
                               * hook: the file system                              */
    appm_missing_textures missing_textures; /* APPM_MISSING_TEXTURES_ERROR            */
    appm_stand_in stand_in;   /* APPM_STAND_IN_STUDIO                                */
} appm_config;

/* The defaults spelled out (every field set to the value 0 stands for, where that
 * value does not depend on the scene). */
APPM_API void appm_config_init(appm_config *cfg);

/* ---- Scenes ---------------------------------------------------------------- */

typedef struct appm_scene appm_scene;       /* opaque, immutable once loaded */
typedef struct appm_renderer appm_renderer; /* opaque */

/* Loads a `.scene` file or a bare `.obj` (the format: docs/scene-format.md).
 * Paths inside are relative to the file's folder.  Only cfg->allocator, cfg->log
 * and cfg->log_user are used; cfg may be NULL. */
APPM_API appm_status appm_scene_load(const char *path, const appm_config *cfg, appm_scene **out,
                                     appm_diag *diag);

/* Loads an OBJ held in memory, with an optional MTL text (mtl may be NULL; any
 * `mtllib` line then refers to it).  Neither buffer needs a terminating NUL.  The
 * camera frames the model as for a bare `.obj`.  `name` is used in messages. */
APPM_API appm_status appm_scene_load_obj_memory(const char *obj, size_t obj_len, const char *mtl,
                                                size_t mtl_len, const char *name,
                                                const appm_config *cfg, appm_scene **out,
                                                appm_diag *diag);

/* A file held in memory, for appm_scene_load_memory: `name` is the path that
 * appm_scene_load would open for it (a `mesh` or `mtllib` name joined to the
 * folder of the file naming it; so with a scene named "box.scene", the names
 * as written), `text` its len bytes (no terminating NUL needed). */
typedef struct appm_memory_file {
    const char *name;
    const char *text;
    size_t len;
} appm_memory_file;

/* Loads a `.scene` text held in memory, as appm_scene_load loads the file
 * `name` - its camera, lens, image size, lights and meshes - except that every
 * mesh and material library it names is one of files[0 .. nfiles-1], matched
 * by name, and nothing is read from disk: a name that none matches is a
 * missing file (an error for a mesh, a warning and the default material for a
 * material library).  Neither the scene text nor the files need a NUL. */
APPM_API appm_status appm_scene_load_memory(const char *scene, size_t scene_len, const char *name,
                                            const appm_memory_file *files, size_t nfiles,
                                            const appm_config *cfg, appm_scene **out, appm_diag *diag);

APPM_API void appm_scene_destroy(appm_scene *scene);

/* Lights for any scene, added after loading (a model downloaded from the web
 * rarely has an emissive material).  Call them before creating a renderer from
 * the scene, never while one exists: they are the only calls that change a
 * loaded scene.  A bare OBJ in which nothing emits and that has no light loads
 * with a constant white environment of radiance 1 as a stand-in (each renderer
 * made from it logs one warning saying so); the first light added through
 * these calls replaces that stand-in.
 *
 * appm_scene_add_point_light: a point light at `position` (scene units) with
 * radiant intensity `intensity` (W/sr per channel, finite, >= 0); any number.
 * appm_scene_set_environment: a constant environment of `radiance` arriving
 * from every unoccluded direction; replaces the scene's environment, if any.
 * Both return APPM_ERR_INVALID_ARG for non-finite or negative values and leave
 * the scene as it was on any error. */
APPM_API appm_status appm_scene_add_point_light(appm_scene *scene, const double position[3],
                                                const double intensity[3], appm_diag *diag);
APPM_API appm_status appm_scene_set_environment(appm_scene *scene, const double radiance[3],
                                                appm_diag *diag);
/* The environment becomes the equirectangular map at `path` (any format
 * appm_image_read reads; row 0 the zenith, +y; column 0 looking along -z,
 * columns advancing towards +x), its radiance times `scale` (>= 0), turned
 * by `rotate_degrees` about +y (90: column 0 looks along +x); replaces a
 * constant or mapped environment, or a bare OBJ's stand-in sky.  Shadow rays
 * and photons are drawn by the map's brightness times sin(theta).  The file
 * is read through cfg->reader when one is set; its memory comes from the
 * scene's allocator.  APPM_ERR_IO, _PARSE (an unreadable, non-finite or black
 * map) or _INVALID_ARG leave the scene as it was. */
APPM_API appm_status appm_scene_set_environment_map(appm_scene *scene, const char *path, double scale,
                                                    double rotate_degrees, const appm_config *cfg,
                                                    appm_diag *diag);

typedef struct appm_scene_info {
    uint64_t triangles;       /* after fan triangulation, degenerate ones dropped */
    uint64_t dropped_triangles;
    uint32_t materials_diffuse, materials_mirror, materials_dielectric;
    uint32_t materials_emissive;    /* materials with Ke > 0 (counted among the above too) */
    uint32_t lights_area;           /* emissive triangles                                */
    uint32_t lights_point, lights_spot, lights_environment;
    double power_area[3];           /* emitted power (W) per kind, RGB                   */
    double power_point[3], power_spot[3], power_environment[3];
    double bbox_min[3], bbox_max[3];
    uint64_t bvh_nodes;             /* nodes of the wide BVH the renderer traverses      */
    uint32_t bvh_depth;             /* and its depth (root = 1)                          */
    uint32_t width, height;         /* the scene's image size                            */
    uint64_t memory_bytes;          /* bytes the scene holds                            */
    uint64_t peak_bytes;            /* the most that loading held at once               */
    uint32_t materials_glossy;      /* Lambert + Phong lobe (Ks > 0 on illum 2)          */
    uint32_t textures;              /* texture maps loaded (each file once)              */
    uint64_t texture_bytes;         /* their samples (part of memory_bytes)              */
    uint32_t materials_cutout;      /* materials with a map_d cut-out                    */
    uint32_t environment_map_width, environment_map_height; /* 0: no map                */
    uint64_t open_edges;            /* edges where a surface ends against nothing: no
                                     * other triangle shares them and no surface goes on
                                     * beyond; appm's kernel is cut along them           */
    uint32_t shadow_rays_own;       /* point and spot lights that every shading point sends
                                     * a shadow ray of its own (the 8 most powerful)     */
    uint32_t shadow_rays_picked;    /* the other lights, among which one more shadow ray
                                     * a shading point picks by power (appm's eye pass;
                                     * the path tracer leaves a constant sky out)        */
    uint32_t shadow_rays_samples;   /* how many it picks a shading point in the eye pass
                                     * (each picks its own): 0 without such lights, 4
                                     * while the studio's sky lights the scene, else 1  */
} appm_scene_info;

APPM_API void appm_scene_get_info(const appm_scene *scene, appm_scene_info *info);

/* ---- Images ---------------------------------------------------------------- */

typedef struct appm_image {
    uint32_t width, height;
    float *rgb;               /* width * height * 3 floats, row 0 at the top */
} appm_image;

/* Writes by extension: `.pfm` (linear float RGB, bit exact), `.exr` (OpenEXR,
 * linear RGB, 32-bit float, ZIP compressed, bit exact), `.ppm` (P6) or `.png`
 * (8-bit sRGB after multiplying by `exposure`; 0 means 1; deflate compressed
 * with a per-row filter choice).  The file appears under its name only once it
 * is complete (written to a temporary, then renamed).  Writing a PNG or EXR
 * allocates about 0.5 MiB plus a few rows (malloc; appm_image_write_ex takes an
 * allocator). */
APPM_API appm_status appm_image_write(const char *path, const appm_image *img, double exposure,
                                      appm_diag *diag);

/* The choices of appm_image_write_ex; all zero = appm_image_write's defaults. */
typedef struct appm_write_options {
    double exposure;      /* .png, .ppm: multiply before the sRGB curve (0 means 1)        */
    int exr_half;         /* .exr: 16-bit half floats (finite values beyond +-65504 clamp  */
                          /*       to it); 0: 32-bit float                                 */
    int exr_uncompressed; /* .exr: no compression; 0: ZIP (lossless, 16 lines a block)     */
} appm_write_options;

/* appm_image_write with options (opt may be NULL) and the allocator of cfg
 * (cfg may be NULL: malloc/free). */
APPM_API appm_status appm_image_write_ex(const char *path, const appm_image *img,
                                         const appm_write_options *opt, const appm_config *cfg,
                                         appm_diag *diag);

/* Reads a PFM (either byte order, colour or grey).  The pixels come from
 * cfg->allocator (cfg may be NULL); free them with appm_image_free(). */
APPM_API appm_status appm_image_read_pfm(const char *path, const appm_config *cfg,
                                         appm_image *out, appm_diag *diag);
/* Reads any image appm reads as a texture or an environment map (by its first
 * bytes; TGA by the name's .tga): PNG (every colour type and depth, palette,
 * Adam7), JPEG (baseline and progressive, 4:4:4 / 4:2:2 / 4:2:0), TGA, PPM/PGM,
 * PFM, OpenEXR (scanline: none, RLE, ZIPS, ZIP; half, float, uint) and Radiance
 * HDR, as linear RGB: 8- and 16-bit colour sRGB-decoded, grey copied to all
 * three channels, alpha dropped.  Free with appm_image_free(). */
APPM_API appm_status appm_image_read(const char *path, const appm_config *cfg, appm_image *out,
                                     appm_diag *diag);
APPM_API void appm_image_free(const appm_config *cfg, appm_image *img);

/* Error metrics of `a` against the reference `b` (same size): the `compare` line
 * of the command line.  relmse divides each squared error by b^2 + 0.01. */
typedef struct appm_compare_result {
    double rmse, relmse, mae, mean_a, mean_b;
} appm_compare_result;
APPM_API appm_status appm_image_compare(const appm_image *a, const appm_image *b,
                                        appm_compare_result *out);

/* ---- Rendering ------------------------------------------------------------- */

/* Prepares a progressive render of `scene` (which must outlive the renderer).
 * Allocates everything a pass needs except the photon store, which is sized by
 * the first pass.  Options are validated here: alpha outside (0,1], a size
 * of 0 or above 32768, a negative or non-finite radius give APPM_ERR_INVALID_ARG.
 * A radius above a tenth of the scene's bounding-box diagonal is valid, but each
 * pixel then gathers a large share of the photons and a pass is slow: cfg.log
 * (if set) is told so once. */
APPM_API appm_status appm_renderer_create(const appm_scene *scene, const appm_config *cfg,
                                          appm_renderer **out, appm_diag *diag);

/* Runs one pass: eye pass, photon pass, photon map, gather, radius update. */
APPM_API appm_status appm_renderer_pass(appm_renderer *r);

/* The current estimate (linear RGB), as a view borrowed until the next pass. */
APPM_API void appm_renderer_image(appm_renderer *r, appm_image *out);

typedef struct appm_stats {
    uint64_t passes;
    uint64_t photons_emitted;       /* photon paths, all passes                        */
    uint64_t photons_stored;        /* photons stored in the last pass                  */
    uint64_t eye_paths;             /* all passes                                       */
    double initial_radius;          /* r1, scene units                                  */
    double seconds;                 /* wall time inside appm_renderer_pass              */
    double seconds_eye, seconds_photons, seconds_grid, seconds_gather; /* per phase     */
    uint64_t memory_bytes;          /* held by the renderer now                         */
    uint64_t peak_bytes;            /* the most the renderer held at once               */
    uint64_t dropped_samples;       /* NaN/inf contributions discarded (never in image)  */
    double est_relerr;              /* appm, pt: estimated image relative error, the     */
                                    /* root mean over pixels of (bias^2 + var) /         */
                                    /* (I^2 + 0.01) (appm's bias measured from its       */
                                    /* photons at radii r and r / sqrt 8, appm-paper's   */
                                    /* the model (mu2/2) r^2 dI; where one pass holds a  */
                                    /* pixel that shows no light, I is its 3x3 median if */
                                    /* lower);                                           */
                                    /* var from the spread between the                   */
                                    /* chains (chains >= 2) or the passes (one chain:    */
                                    /* scaled by the sequence's halves); < 0: none (ppm, */
                                    /* sppm; pt where a point or spot light, a tiny area */
                                    /* light or a sun may shine through a mirror or      */
                                    /* glass: appm_renderer_keeps_error)                 */
    double clamped;                 /* appm: fraction of gathering pixels at a radius bound
                                       after the last pass (< 0: none; so after a
                                       checkpoint's load until the next pass)              */
    unsigned threads;
    double emission_guided;         /* the share of the last pass's photon paths drawn
                                       from learned densities (0: none; at most 3/4; 0
                                       after a checkpoint's load until the next pass)      */
    unsigned emission_lights;       /* lights guided emission may guide (set by a pass;
                                       0 after a checkpoint's load until the next)         */
    uint64_t photons_per_pass;      /* M: photon paths a pass, config.photons or the
                                       budget's choice (0: the path tracer)               */
    double budget_rays;             /* the photon budget's reading in pass 1: the rays of
                                       the eye paths over those of width * height photon
                                       paths (0: photons given, or no budget)             */
    /* A render split over a cluster (appm_renderer_set_cluster), all passes of
     * this renderer: the bytes of this rank's parts of the exchanges, the bytes
     * of the other ranks' parts it received, and the wall time spent in the
     * exchange hook (waiting for slower ranks included).  0 when alone. */
    uint64_t cluster_bytes_out, cluster_bytes_in;
    double seconds_cluster;
} appm_stats;

/* The counters after the last pass.  est_relerr is made here (with the
 * renderer's worker threads, like appm_renderer_image's image) when a pass or
 * a checkpoint load has come since it was last read: a pass does not pay for an
 * estimate nobody reads.  Its value does not depend on when it is read;
 * seconds counts the passes only. */
APPM_API void appm_renderer_stats(const appm_renderer *r, appm_stats *out);

/* 1 when the renderer keeps an error estimate (appm_stats.est_relerr >= 0 from
 * its second pass on, what --until-error stops on): appm, appm-paper and pt,
 * but not pt on a scene with a mirror or glass and a point or spot light, or
 * an area light too small to be met by chance (an emissive material whose
 * triangles cover less than 1e-4 of pi R^2, R half the diagonal of the scene's
 * bounding box, and that carries at least 1 % of the power), or an
 * environment map whose brightest texels within 1e-4 pi steradians (a sun
 * 1.15 degrees across) carry 1 % of the power.  A point or spot light reaches a
 * surface only by shadow rays, which no mirror or glass lets through, and a
 * diffuse bounce meets such a small light or sun about once in 10^4, so the
 * light they send through a mirror or glass (a caustic) is missing from the
 * path tracer's image or shows as rare fireflies, and the spread of its
 * passes cannot measure light they never or seldom found.  Its VARIANCE and ERROR maps still show the noise of what
 * it renders. */
APPM_API int appm_renderer_keeps_error(const appm_renderer *r);

/* Diagnostic images of the adaptive method (a teacher's pictures), width*height
 * floats each, borrowed until the next pass.  Returns NULL when the method keeps
 * no such map (e.g. laplacian for ppm), before the first pass, or when the map's
 * memory (allocated on the first request) cannot be had.
 *   RADIUS     the radius each pixel gathered with in the last pass (scene units;
 *              sppm: the radius R of its next gather; appm: the radius of the
 *              pixel's dominant photon component, the one with the larger term)
 *   VARIANCE   the estimated variance of the pixel (luminance)
 *   LAPLACIAN  the estimated pixel Laplacian dI (luminance per area^2)
 *   ERROR      the estimated error bar |bias| + 1.645 sigma (luminance)
 *   RADIUS_CAUSTIC, RADIUS_DIFFUSE  appm: the radius of each photon component
 *              (caustic: photons whose last bounce was specular; diffuse: the
 *              rest) in the last pass                                          */
typedef enum appm_aux {
    APPM_AUX_RADIUS = 0,
    APPM_AUX_VARIANCE,
    APPM_AUX_LAPLACIAN,
    APPM_AUX_ERROR,
    APPM_AUX_RADIUS_CAUSTIC,
    APPM_AUX_RADIUS_DIFFUSE,
    APPM_AUX_COUNT
} appm_aux;
APPM_API const float *appm_renderer_aux(appm_renderer *r, appm_aux which);

/* The emission density of guided light k (k = 0 .. stats.emission_lights - 1,
 * the lights in order of power) that the next pass samples, over the light's
 * first emission sample (u1, u2) in [0,1)^2: *width x *height floats, row v
 * for u2 in [v/height, (v+1)/height), mean 1 (1 everywhere: the light's own
 * distribution), borrowed until the next pass or the next call (one buffer
 * serves every k).  NULL for k beyond the guided lights or with
 * APPM_EMISSION_LIGHT. */
APPM_API const float *appm_renderer_emission_map(appm_renderer *r, unsigned k, unsigned *width,
                                                 unsigned *height);

/* ---- Checkpoints -------------------------------------------------------------
 *
 * A checkpoint holds everything the next pass depends on (per-pixel statistics,
 * pass counter, radius schedule, counters of appm_stats, seed, method, options,
 * image size, a hash of the scene, the format and library version) in a fixed
 * little-endian layout, so it moves between machines.  Load it into a renderer
 * created from the same scene and options - the thread count may differ - and
 * the passes that follow give, bit for bit, the image of a render that was
 * never interrupted.  A checkpoint of another scene, method, option set, image
 * size or version is refused with APPM_ERR_INVALID_ARG and a message naming
 * the difference; a truncated or altered one gives APPM_ERR_PARSE (a checksum
 * covers every byte).  A refused load leaves the renderer as it was.  "Another
 * scene" is one whose files state other values: geometry, materials (Kd, Ks,
 * Ns, Ke, Ni, illum), shading normals (vn), lights or camera, each named when
 * it differs; another machine reading the same files has the same scene.  The
 * format version changes with the layout and with what the scene hash covers;
 * a checkpoint of another format version is refused as such (compatibility is
 * exact: same format and library version, or nothing; the library version
 * changes whenever a pass would compute something else).  The layout is
 * described in appm.c, section 13.
 *
 * appm_renderer_save writes into buf (cap bytes) and sets *size to the bytes
 * the checkpoint takes; buf NULL only measures.  APPM_ERR_INVALID_ARG when cap
 * is too small (*size still says how much is needed).  It allocates nothing.
 * appm_renderer_save_file writes `path` atomically (a temporary, then renamed,
 * as appm_image_write does) through a 64 KiB buffer from cfg.allocator.
 * appm_renderer_load reads a checkpoint from memory (it allocates nothing);
 * appm_renderer_load_file from `path`, through a 64 KiB buffer from
 * cfg.allocator; if the file changes between its two readings, the load fails
 * with APPM_ERR_IO and the renderer is back at its state after creation.
 * With cfg.reader set, load_file loads the bytes the reader lends instead. */
APPM_API appm_status appm_renderer_save(const appm_renderer *r, void *buf, size_t cap, size_t *size,
                                        appm_diag *diag);
APPM_API appm_status appm_renderer_save_file(appm_renderer *r, const char *path, appm_diag *diag);
APPM_API appm_status appm_renderer_load(appm_renderer *r, const void *buf, size_t len, appm_diag *diag);
APPM_API appm_status appm_renderer_load_file(appm_renderer *r, const char *path, appm_diag *diag);

/* ---- Distributed rendering ----------------------------------------------------
 *
 * One render split over `ranks` processes (an MPI job, say: mpi.c is such a
 * front end), each holding a renderer of the same scene and options.  Every
 * rank keeps the whole per-pixel state; a pass splits its work - each rank
 * traces the eye paths of a band of rows, the photon paths of a band of the
 * pass's 1024-path chunks and gathers for a band of rows, the bands cut where
 * the last pass's measured times say the work is even (the first pass: even
 * counts) - and then exchanges what it computed, so that after each pass every
 * rank holds, bit for bit, the state of a renderer that ran alone.  Hence
 * the image, the diagnostic maps and a checkpoint on any rank are those of a
 * render on one machine with the same options, for any number of ranks and
 * threads per rank, and a checkpoint saved by a job of N ranks resumes in a
 * job of any other size (and alone).  The per-phase times of appm_stats
 * include each phase's exchange.
 * What is exchanged per pass (docs/distributed.md has the cost model):
 *   the visible points of each rank's rows (92 bytes a pixel), its photons
 *   (32 bytes each, 4 more with guided emission) with their chunk records
 *   (8 bytes per 1024 paths), and after the gather its rows' pixel state (40
 *   bytes a pixel plus the method's: 24 ppm, 40 sppm, 80 appm-paper, 208
 *   appm, 0 pt; 8 a chain with chains >= 2), plus a few words (statuses,
 *   dropped samples, guided emission's counts: 8 KiB a guided light, and 4
 *   bytes a row and a chunk of measured times).
 *
 * allgather(user, buf, lens) is the one collective the library needs: every
 * rank calls it at the same point of the same pass with the same lens[0 ..
 * ranks-1]; buf holds the parts of all ranks one after another (rank k's at
 * offset lens[0] + ... + lens[k-1]), of which this rank's is filled on entry;
 * on return every part must be (MPI_Allgatherv with MPI_IN_PLACE).  A non-zero
 * return fails the pass with APPM_ERR_IO and leaves the renderer's pixel
 * state undefined (destroy it; resume from a checkpoint); the hook must then
 * fail on every rank alike, or end the job (as MPI's default error handler
 * does), since the other ranks would wait in the next exchange.  Every rank must call
 * appm_renderer_pass the same number of times; a pass that fails on one rank
 * for lack of memory fails on all of them (the ranks agree on a status word
 * after each step that can fail), the failing rank's message naming the
 * cause and the others' naming the rank.
 *
 * appm_renderer_set_cluster: c NULL or c->ranks <= 1 renders alone again.
 * APPM_ERR_INVALID_ARG for rank >= ranks, ranks > 65536 or no allgather;
 * APPM_ERR_NOMEM if its few arrays cannot be had.  Call it between passes. */
typedef struct appm_cluster {
    unsigned rank, ranks;
    int (*allgather)(void *user, void *buf, const size_t *lens);
    void *user;
} appm_cluster;
APPM_API appm_status appm_renderer_set_cluster(appm_renderer *r, const appm_cluster *c, appm_diag *diag);

/* The message of the last failed call on `r` ("" if none). */
APPM_API const char *appm_renderer_last_error(const appm_renderer *r);

APPM_API void appm_renderer_destroy(appm_renderer *r);

/* Number of processors the built-in thread backend would use (1 without threads). */
APPM_API unsigned appm_cpu_count(void);

#ifdef __cplusplus
}
#endif

#endif /* APPM_H_INCLUDED */
