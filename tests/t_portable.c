/* tests/t_portable.c - the byte-order and platform-sensitive parts of appm, small
 * and self-contained, so that it can run on every target of make portability
 * (tcc, mingw-w64 under wine, aarch64 and big-endian s390x under qemu) as well
 * as in make test.
 *
 *   - PFM: header and raw bytes of a written file (the scale's sign must match
 *     the host's byte order), bottom-to-top rows, a bit-exact round trip, and
 *     hand-made files of both byte orders decoded to exact values;
 *   - PNG: the CRC-32 check value, every chunk's CRC recomputed here bit by
 *     bit, the pixel bytes of a tiny image (inflated by tests/inflate.h), and
 *     the CRC-32 of whole PNG and EXR files of a fixed pattern against the
 *     values from x86-64: the compressor is integer code, so every machine
 *     must write the same bytes;
 *   - random streams: the PCG32 step against the reference pcg32 demo, the
 *     SplitMix64 finaliser, and the seeded streams' first values (integers, so
 *     they must be identical everywhere; computed on x86-64);
 *   - the locale-free number parser on a few exact values;
 *   - the checkpoint's scene hash of two small scenes read from files against
 *     the values from x86-64 (only values as read enter it, so a checkpoint
 *     resumes on every machine);
 *   - a tiny render of a closed emissive box read from files (a furnace: every
 *     wall has Ke = Kd = 0.5, so the radiance is 1 everywhere): the image mean
 *     within a tolerance of 1, and of the reference machine's mean when
 *     APPM_PORTABLE_REF holds that machine's "furnace means:" line - never
 *     bit-exact across machines (docs/CONTRIBUTING.md, Determinism) - the
 *     deterministic integer statistics, and 1 vs 2 threads byte-identical.
 * Run from the repository root; scratch files go to tests/out/. */
#include "../appm.c"
#include "check.h"
#include "inflate.h"

/* ---- helpers ------------------------------------------------------------- */

static uint32_t bits_of(float v)
{
    uint32_t b;
    memcpy(&b, &v, 4);
    return b;
}

static uint32_t be32_at(const unsigned char *p)
{
    return (uint32_t)p[0] << 24 | (uint32_t)p[1] << 16 | (uint32_t)p[2] << 8 | (uint32_t)p[3];
}

static uint32_t le32_at(const unsigned char *p)
{
    return (uint32_t)p[3] << 24 | (uint32_t)p[2] << 16 | (uint32_t)p[1] << 8 | (uint32_t)p[0];
}

/* ---- PFM ----------------------------------------------------------------- */

static void test_pfm_write(void)
{
    float px[3 * 3 * 2];
    appm_image img, back;
    appm_diag d;
    const char *path = check_path("portable", "rt.pfm");
    unsigned char *raw;
    size_t len, i;
    int little = appm__host_little_endian();
    const char *head = little ? "PF\n3 2\n-1.0\n" : "PF\n3 2\n1.0\n";
    uint32_t one = 1u;
    unsigned char first;
    memcpy(&first, &one, 1);
    CHECK(little == (first == 1)); /* the library's probe agrees with this one */
    for (i = 0; i < 18; ++i) px[i] = (float)i * 0.25f - 1.0f + (i == 5 ? 1e-30f : 0.0f);
    px[0] = 1.0f; /* top-left red */
    img.width = 3;
    img.height = 2;
    img.rgb = px;
    CHECK(appm_image_write(path, &img, 1.0, &d) == APPM_OK);
    raw = check_read_file(path, &len);
    CHECK(raw != NULL);
    if (!raw) return;
    CHECK(len == strlen(head) + 18 * 4);
    CHECK(len >= strlen(head) && memcmp(raw, head, strlen(head)) == 0);
    if (len == strlen(head) + 18 * 4) {
        /* file row 0 is the bottom image row (y = 1); the top-left pixel is in the last row */
        const unsigned char *data = raw + strlen(head);
        for (i = 0; i < 18; ++i) {
            size_t y = 1 - i / 9, x = i % 9;
            uint32_t got = little ? le32_at(data + 4 * i) : be32_at(data + 4 * i);
            CHECK_MSG(got == bits_of(px[y * 9 + x]), "PFM float %u", (unsigned)i);
        }
    }
    free(raw);
    CHECK(appm_image_read_pfm(path, NULL, &back, &d) == APPM_OK);
    CHECK(back.width == 3 && back.height == 2);
    CHECK(back.rgb && memcmp(back.rgb, px, sizeof px) == 0);
    appm_image_free(NULL, &back);
}

/* Hand-made files in both byte orders decode to exact values on every host. */
static void test_pfm_parse(void)
{
    static const unsigned char big[] = {
        'P',  'F',  '\n', '1',  ' ',  '2',  '\n', '1',  '.',  '0',
        '\n', 0x3F, 0x80, 0x00, 0x00, 0x40, 0x00, 0x00, 0x00, /* 1, 2 */
        0xC0, 0x40, 0x00, 0x00,                               /* -3 (bottom row) */
        0x3E, 0x80, 0x00, 0x00, 0x7F, 0x80, 0x00, 0x00,       /* .25, inf */
        0x00, 0x00, 0x00, 0x01};                              /* denormal */
    static const unsigned char little[] = {'P',  'f',  ' ',  '2',  '\t', '1',  '\r', '\n',
                                           '-',  '4',  '\n', 0x00, 0x00, 0xC0, 0x3F, /* 1.5 */
                                           0x01, 0x00, 0x80, 0xBF}; /* -1 - 2^-23 */
    appm__mem m;
    appm_image img;
    appm_diag d;
    appm__mem_init(&m, NULL);
    CHECK(appm__pfm_parse(&m, big, sizeof big, "big", &img, &d) == APPM_OK);
    if (img.rgb) {
        CHECK(img.width == 1 && img.height == 2);
        /* the file's first row is the bottom one: image row 1 */
        CHECK(img.rgb[3] == 1.0f && img.rgb[4] == 2.0f && img.rgb[5] == -3.0f);
        CHECK(img.rgb[0] == 0.25f && img.rgb[1] == HUGE_VALF && bits_of(img.rgb[2]) == 1u);
        appm__free(&m, img.rgb);
    }
    CHECK(appm__pfm_parse(&m, little, sizeof little, "little", &img, &d) == APPM_OK);
    if (img.rgb) {
        CHECK(img.width == 2 && img.height == 1);
        CHECK(img.rgb[0] == 1.5f && img.rgb[1] == 1.5f && img.rgb[2] == 1.5f);
        CHECK(bits_of(img.rgb[3]) == 0xBF800001u && img.rgb[5] == img.rgb[3]);
        appm__free(&m, img.rgb);
    }
    CHECK(appm__pfm_parse(&m, big, sizeof big - 1, "short", &img, &d) == APPM_ERR_PARSE);
    CHECK(img.rgb == NULL);
    CHECK(m.live == 0);
}

/* ---- PNG ----------------------------------------------------------------- */

static uint32_t ref_crc(const unsigned char *p, size_t n) /* bitwise CRC-32 (IEEE) */
{
    uint32_t c = 0xFFFFFFFFu;
    size_t i;
    int k;
    for (i = 0; i < n; ++i) {
        c ^= p[i];
        for (k = 0; k < 8; ++k) c = (c >> 1) ^ (0xEDB88320u & (0u - (c & 1u)));
    }
    return c ^ 0xFFFFFFFFu;
}

static void test_png_bytes(void)
{
    static const unsigned char sig[8] = {137, 80, 78, 71, 13, 10, 26, 10};
    /* 2x2: black, white (clamped), 0.5 grey (sRGB 188), a colour */
    float px[12] = {0, 0, 0, 1, 5, 1, 0.5f, 0.5f, 0.5f, 1, 0, 0.5f};
    /* filter byte + RGB per row */
    static const unsigned char pixels[14] = {0, 0,   0,   0,   255, 255, 255,
                                             0, 188, 188, 188, 255, 0,   188};
    appm_image img;
    appm_diag d;
    const char *path = check_path("portable", "tiny.png");
    unsigned char *raw;
    size_t len, pos = 8;
    int chunks = 0, crc_ok = 1;
    CHECK(appm__crc32_update(0xFFFFFFFFu, (const unsigned char *)"123456789", 9) ==
          (0xCBF43926u ^ 0xFFFFFFFFu));
    img.width = img.height = 2;
    img.rgb = px;
    CHECK(appm_image_write(path, &img, 1.0, &d) == APPM_OK);
    raw = check_read_file(path, &len);
    CHECK(raw && len > 8 && memcmp(raw, sig, 8) == 0);
    if (!raw) return;
    while (pos + 12 <= len) {
        uint32_t n = be32_at(raw + pos);
        if (pos + 12 + n > len) break;
        if (ref_crc(raw + pos + 4, 4 + (size_t)n) != be32_at(raw + pos + 8 + n)) crc_ok = 0;
        if (memcmp(raw + pos + 4, "IHDR", 4) == 0) {
            CHECK(n == 13 && be32_at(raw + pos + 8) == 2 && be32_at(raw + pos + 12) == 2);
            CHECK(raw[pos + 16] == 8 && raw[pos + 17] == 2);
        }
        if (memcmp(raw + pos + 4, "IDAT", 4) == 0) {
            /* the zlib stream inflates (header and Adler-32 checked) to the rows */
            unsigned char rows[15], pix[12];
            size_t got = tinf_zlib(raw + pos + 8, n, rows, sizeof rows, NULL);
            CHECK(got == 14);
            CHECK(got == 14 && png_unfilter(rows, 6, 2, 3, pix, NULL));
            CHECK(got == 14 && memcmp(pix, pixels + 1, 6) == 0 && memcmp(pix + 6, pixels + 8, 6) == 0);
        }
        chunks++;
        pos += 12 + n;
    }
    CHECK(chunks == 3 && pos == len);
    CHECK(crc_ok);
    free(raw);
}

/* Whole files of a fixed 61x37 pattern (smooth ramps, a repeated tile and
 * pseudo-random values, so that literals, matches, both block codes and all row
 * filters occur): their CRC-32 must be the x86-64 value on every machine.  The
 * PNG's pattern uses only values whose sRGB bytes are far from a rounding
 * boundary (t_image.c's list), so that no libm's powf can change a byte.  When
 * the writers change on purpose, print the new values here and paste them. */
static void test_file_bytes(void)
{
    static const char *const names[4] = {"pattern.png", "pattern.exr", "pattern-h.exr", "pattern-n.exr"};
    static const uint32_t want[4] = {0xD8C5044Du, 0x2D618011u, 0x213C5662u, 0xAE8A02E3u};
    static const float safe[7] = {0.0f, 0.5f, 1.0f, 0.25f, 0.001f, 0.1f, 0.75f};
    enum { W = 61, H = 37 };
    float *px = (float *)malloc(sizeof(float) * W * H * 3), *ps = (float *)malloc(sizeof(float) * W * H * 3);
    uint32_t state = 7u;
    int i, k;
    appm_image img;
    if (!px || !ps) {
        free(px);
        free(ps);
        return;
    }
    for (i = 0; i < W * H * 3; ++i) {
        int x = i / 3 % W, y = i / 3 / W;
        state = state * 1664525u + 1013904223u;
        px[i] = y < 12 ? (float)x / (float)W : y < 24 ? (float)((x % 5) * (i % 3)) * 0.2f
                                                     : (float)(state >> 8) / 16777216.0f;
        ps[i] = safe[y < 12 ? x * 7 / W : y < 24 ? (x % 5 + i % 3) % 7 : (int)(state >> 29) % 7];
    }
    img.width = W;
    img.height = H;
    for (k = 0; k < 4; ++k) {
        appm_write_options opt;
        appm_diag d;
        const char *path = check_path("portable", names[k]);
        unsigned char *raw;
        size_t len;
        memset(&opt, 0, sizeof opt);
        opt.exr_half = k == 2;
        opt.exr_uncompressed = k == 3;
        img.rgb = k == 0 ? ps : px;
        CHECK(appm_image_write_ex(path, &img, &opt, NULL, &d) == APPM_OK);
        raw = check_read_file(path, &len);
        CHECK(raw != NULL);
        if (!raw) continue;
        if (want[k] == 0) printf("%s: %lu bytes, crc32 0x%08lXu\n", names[k], (unsigned long)len,
                                 (unsigned long)ref_crc(raw, len));
        else CHECK_MSG(ref_crc(raw, len) == want[k], "%s: crc32 0x%08lX, %lu bytes", names[k],
                       (unsigned long)ref_crc(raw, len), (unsigned long)len);
        free(raw);
    }
    free(px);
    free(ps);
}

/* ---- Random streams and numbers ------------------------------------------- */

static void test_rng(void)
{
    /* pcg32_srandom_r(&rng, 42u, 54u) of the reference pcg32-demo */
    static const uint32_t demo[6] = {0xa15c02b7u, 0x7b47f409u, 0xba1d3330u,
                                     0x83d2f293u, 0xbfa4784bu, 0xcbed606eu};
    /* appm__rng_seed(42, pass 3, APPM__DOMAIN_TEST, index 7), computed on x86-64.  When
     * appm__rng_seed changes on purpose, print the new values there and paste them. */
    static const uint32_t seeded[8] = {0xC20BEB30u, 0xC82AB7A2u, 0xACB96598u, 0x4523354Du,
                                       0xCC283C03u, 0xE85565FAu, 0x3419CDCCu, 0xA876D21Bu};
    static const uint32_t zero[4] = {0x3F75A020u, 0x540B8CBDu, 0x5460AAB2u, 0xBCE5DE45u};
    appm__rng r;
    int i, ok = 1;
    r.state = 0;
    r.inc = (54u << 1) | 1u;
    appm__rng_u32(&r);
    r.state += 42u;
    appm__rng_u32(&r);
    for (i = 0; i < 6; ++i) ok &= appm__rng_u32(&r) == demo[i];
    CHECK_MSG(ok, "PCG32 step differs from the reference generator");
    CHECK(appm__mix64(0) == 0xE220A8397B1DCDAFull); /* SplitMix64's first output for seed 0 */
    appm__rng_seed(&r, 42, 3, APPM__DOMAIN_TEST, 7);
    for (ok = 1, i = 0; i < 8; ++i) ok &= appm__rng_u32(&r) == seeded[i];
    CHECK_MSG(ok, "seeded stream differs from the x86-64 values");
    appm__rng_seed(&r, 0, 0, 0, 0);
    for (ok = 1, i = 0; i < 4; ++i) ok &= appm__rng_u32(&r) == zero[i];
    CHECK(ok);
    appm__rng_seed(&r, 42, 3, APPM__DOMAIN_TEST, 7);
    CHECK(appm__rng_float(&r) == (float)(seeded[0] >> 8) / 16777216.0f);
}

static void test_numbers(void)
{
    static const struct {
        const char *s;
        double v;
    } cases[] = {{"0.1", 0.1},      {"-2.5e3", -2500.0},
                 {".8e-001", 0.08}, {"+17", 17.0},
                 {"1E-5", 1e-5},    {"123456789012", 123456789012.0},
                 {"-0", -0.0},      {"0.000244140625", 0.000244140625}};
    size_t i;
    double v;
    for (i = 0; i < sizeof cases / sizeof cases[0]; ++i) {
        const char *s = cases[i].s;
        CHECK_MSG(appm__parse_number(s, s + strlen(s), &v) && v == cases[i].v &&
                      (v != 0.0 || (1.0 / v < 0) == (1.0 / cases[i].v < 0)),
                  "'%s' parsed as %.17g", s, v);
    }
    {
        static const char huge[] = "3E4570711268", comma[] = "1,5";
        CHECK(appm__parse_number(huge, huge + strlen(huge), &v) && v == HUGE_VAL);
        CHECK(!appm__parse_number(comma, comma + strlen(comma), &v));
    }
}

/* ---- The checkpoint's scene hash ------------------------------------------- */

/* The five parts of appm.c 12.2's scene hash of two small scenes read from
 * files - smooth triangles (vn), a glossy material whose Kd + Ks is scaled,
 * a spot light, a lens, an explicit camera; and a mesh with a point light and
 * the camera the loader frames - must be the values of x86-64 on every
 * machine: otherwise a checkpoint would not resume there.  (Values computed on
 * x86-64; they change only with what the hash covers, and then the checkpoint
 * format version changes too.) */
static void test_scene_hash_values(void)
{
    static const uint64_t want[2][APPM__SH_PARTS] = {
        {0xf5af553141b6f6ebull, 0x93b0885205f9a440ull, 0xe7f8a0594b5ba4e1ull, 0x3bdccbfde664aebcull,
         0xebd6a7b3ae61853dull},
        {0xf5af553141b6f6ebull, 0x93b0885205f9a440ull, 0xe7f8a0594b5ba4e1ull, 0x1932ef62bd6b0895ull,
         0xa61d1a3c8796c2c1ull}};
    static const char *const names[2] = {"smooth.scene", "framed.scene"};
    int k, j;
    CHECK(check_write_file(check_path("portable", "smooth.mtl"),
                           "newmtl gloss\nKd 0.7 0.5 0.3\nKs 0.6 0.3 0.1\nNs 37.5\nnewmtl floor\nKd 0.3 0.6 0.9\n"));
    CHECK(check_write_file(check_path("portable", "smooth.obj"),
                           "mtllib portable-smooth.mtl\nv -1 0 -1\nv 1 0 -1\nv 1 0.3 1\nv -1 0.1 1\nv 0 1.7 0.2\n"
                           "vn 0.3 1 -0.1\nvn -0.2 0.9 0.35\nvn 0.11 0.7 0.71\nusemtl floor\nf 1//1 2//2 3//3 4//1\n"
                           "usemtl gloss\nf 1//3 3//2 5//1\nf 2 5 4\n"));
    CHECK(check_write_file(check_path("portable", "smooth.scene"),
                           "mesh portable-smooth.obj\ncamera eye 0.3 2.1 3.7 target 0.1 0.4 -0.2 up 0.1 1 0 fov 37.3\n"
                           "lens aperture 0.05 focus 3.3\nimage 40 30\n"
                           "light spot position 0.7 3 1.1 target 0 0 0.2 intensity 9 8 7 cone 33.3 falloff 7.7\n"));
    CHECK(check_write_file(check_path("portable", "framed.scene"),
                           "mesh portable-smooth.obj\nlight point position 0.3 2.9 0.7 intensity 3 4 5\n"));
    for (k = 0; k < 2; ++k) {
        appm_scene *s = NULL;
        appm_diag d;
        uint64_t h[APPM__SH_PARTS];
        CHECK_MSG(appm_scene_load(check_path("portable", names[k]), NULL, &s, &d) == APPM_OK, "%s:%u: %s", d.file,
                  d.line, d.message);
        if (!s) continue;
        appm__scene_hash(s, h);
        for (j = 0; j < APPM__SH_PARTS; ++j)
            CHECK_MSG(h[j] == want[k][j], "%s: the scene hash's part %d is 0x%016llx, x86-64's 0x%016llxull",
                      names[k], j, (unsigned long long)h[j], (unsigned long long)want[k][j]);
        appm_scene_destroy(s);
    }
}

/* ---- A tiny render ---------------------------------------------------------- */

/* The cube [-1,1]^3, every face counter-clockwise seen from inside. */
static int write_cube(void)
{
    static const int axes[6][4] = {{0, 1, 2, 1},  {0, 1, 2, -1}, {1, 2, 0, 1},
                                   {1, 2, 0, -1}, {2, 0, 1, 1},  {2, 0, 1, -1}};
    char obj[2048], *p = obj;
    int f, k;
    p += sprintf(p, "# closed box, inward faces\nmtllib portable-box.mtl\nusemtl wall\n");
    for (f = 0; f < 6; ++f) { /* face at coordinate a = s, spanned by axes u, v */
        int a = axes[f][2], u = axes[f][0], v = axes[f][1], s = axes[f][3];
        static const int corner[4][2] = {{-1, -1}, {1, -1}, {1, 1}, {-1, 1}};
        for (k = 0; k < 4; ++k) {
            int c[3];
            c[a] = s;
            c[u] = corner[k][0];
            c[v] = corner[k][1];
            p += sprintf(p, "v %d %d %d\n", c[0], c[1], c[2]);
        }
        /* (u x v) points along +a, so -a (inward) at s = +1 needs the reverse order */
        p += sprintf(p, s > 0 ? "f -1 -2 -3 -4\n" : "f -4 -3 -2 -1\n");
    }
    return check_write_file(check_path("portable", "box.obj"), obj) &&
           check_write_file(check_path("portable", "box.mtl"),
                            "newmtl wall\nKd 0.5 0.5 0.5\nKe 0.5 0.5 0.5\n") &&
           check_write_file(check_path("portable", "box.scene"),
                            "mesh portable-box.obj\n"
                            "camera eye 0.1 0.2 0.5 target 0 0 -1 up 0 1 0 fov 70\nimage 16 12\n");
}

static void render_box(const appm_scene *scene, appm_method method, unsigned threads, float **out,
                       appm_stats *st)
{
    appm_config cfg;
    appm_renderer *r;
    appm_diag d;
    appm_image img;
    int pass;
    appm_config_init(&cfg);
    cfg.method = method;
    cfg.photons = 2000;
    cfg.threads = threads;
    cfg.seed = 7;
    *out = NULL;
    CHECK(appm_renderer_create(scene, &cfg, &r, &d) == APPM_OK);
    if (!r) return;
    for (pass = 0; pass < 3; ++pass) CHECK(appm_renderer_pass(r) == APPM_OK);
    appm_renderer_image(r, &img);
    appm_renderer_stats(r, st);
    *out = (float *)malloc(sizeof(float) * 3 * img.width * img.height);
    if (*out) memcpy(*out, img.rgb, sizeof(float) * 3 * img.width * img.height);
    appm_renderer_destroy(r);
}

static void test_render(void)
{
    static const appm_method methods[2] = {APPM_METHOD_APPM, APPM_METHOD_PT};
    appm_scene *scene = NULL;
    appm_scene_info info;
    appm_diag d;
    int k;
    double mean[2] = {0, 0}, ref_mean[2];
    const char *ref;
    CHECK(write_cube());
    CHECK_MSG(appm_scene_load(check_path("portable", "box.scene"), NULL, &scene, &d) == APPM_OK,
              "%s:%u: %s", d.file, d.line, d.message);
    if (!scene) return;
    appm_scene_get_info(scene, &info);
    CHECK(info.triangles == 12 && info.dropped_triangles == 0 && info.lights_area == 12);
    CHECK(info.width == 16 && info.height == 12);
    CHECK(info.bbox_min[0] == -1.0 && info.bbox_max[2] == 1.0);
    CHECK_NEAR(info.power_area[0], 24.0 * APPM__PI * 0.5, 1e-4); /* pi A Le, A = 24 */
    for (k = 0; k < 2; ++k) {
        float *one, *two;
        appm_stats s1, s2;
        appm_image img;
        render_box(scene, methods[k], 1, &one, &s1);
        render_box(scene, methods[k], 2, &two, &s2);
        if (!one || !two) {
            free(one);
            free(two);
            CHECK(0);
            continue;
        }
        CHECK_MSG(memcmp(one, two, sizeof(float) * 3 * 16 * 12) == 0,
                  "method %d: 1 and 2 threads give different images", (int)methods[k]);
        CHECK(s1.passes == 3 && s1.eye_paths == 3 * 16 * 12);
        if (methods[k] != APPM_METHOD_PT) {
            CHECK(s1.photons_emitted == 3 * 2000);
            CHECK(s1.photons_stored == s2.photons_stored && s1.photons_stored > 0);
        }
        img.width = 16;
        img.height = 12;
        img.rgb = one;
        /* furnace: L = Le / (1 - rho) = 1 everywhere.  The path tracer is unbiased
         * (about 0.99 after three passes); a photon kernel may lose photons past the
         * box's edges, so the photon methods are allowed to read somewhat low. */
        mean[k] = check_image_mean(&img);
        if (methods[k] == APPM_METHOD_PT)
            CHECK_NEAR(mean[k], 1.0, 0.05);
        else
            CHECK_MSG(mean[k] > 0.85 && mean[k] < 1.05, "appm furnace mean %.4f", mean[k]);
        free(one);
        free(two);
    }
    appm_scene_destroy(scene);
    /* Another machine may round differently and so take other paths: the means
     * must agree with the reference machine's within a tolerance, never exactly.
     * tests/portability.sh passes the native build's line in APPM_PORTABLE_REF. */
    printf("furnace means: %.6f %.6f\n", mean[0], mean[1]);
    ref = getenv("APPM_PORTABLE_REF");
    if (ref && sscanf(ref, "furnace means: %lf %lf", &ref_mean[0], &ref_mean[1]) == 2) {
        CHECK_NEAR(mean[0], ref_mean[0], 0.03);
        CHECK_NEAR(mean[1], ref_mean[1], 0.03);
    }
}

int main(void)
{
    printf("host: %s-endian, %u-bit size_t, APPM_THREADS=%d\n",
           appm__host_little_endian() ? "little" : "big", (unsigned)(sizeof(size_t) * 8),
           APPM_THREADS);
    test_pfm_write();
    test_pfm_parse();
    test_png_bytes();
    test_file_bytes();
    test_rng();
    test_numbers();
    test_scene_hash_values();
    test_render();
    return check_finish();
}
