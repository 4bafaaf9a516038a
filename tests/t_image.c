/* tests/t_image.c - image files: PFM, PPM, PNG and EXR writers, the PFM reader, the
 * error metrics, and what a failed write leaves behind.
 *
 * The files are checked byte by byte against the formats' own definitions,
 * decoded here independently of the library:
 *   PFM  "PF\n<w> <h>\n<scale>\n", rows bottom to top, scale < 0 = little-endian
 *   PPM  "P6\n<w> <h>\n255\n", rows top to bottom, RGB bytes
 *   PNG  signature, chunks each with a CRC-32 over type + data, a zlib stream
 *        (header, deflate blocks, Adler-32) of rows each led by a filter byte.
 * The PNG's zlib stream is inflated and its row filters undone by
 * tests/inflate.h, written from the RFCs independently of the library; the
 * pixels must be exactly the PPM writer's bytes.
 *
 * sRGB bytes used below, from the sRGB curve 1.055 v^(1/2.4) - 0.055 (12.92 v
 * under 0.0031308), times 255, rounded; every value is at least 0.016 away from
 * a rounding boundary, so float and double arithmetic agree:
 *   0 -> 0, 0.5 -> 188, 1 -> 255, 2 -> 255 (clamped), NaN -> 0, -1 -> 0,
 *   0.25 -> 137, 0.001 -> 3, 0.1 -> 89, 0.75 -> 225, 1e30 and +inf -> 255. */
#include "../appm.c"
#include "check.h"
#include "inflate.h"

#if defined(__unix__) || defined(__APPLE__)
#include <sys/stat.h>
#include <unistd.h>
#define HAVE_POSIX 1
#else
#define HAVE_POSIX 0
#endif

/* ---- helpers ------------------------------------------------------------- */

static int write_bytes(const char *path, const void *p, size_t n)
{
    FILE *f = fopen(path, "wb");
    int ok = f && fwrite(p, 1, n, f) == n;
    if (f && fclose(f) != 0) ok = 0;
    return ok;
}

static int file_exists(const char *path)
{
    FILE *f = fopen(path, "rb");
    if (f) fclose(f);
    return f != NULL;
}

static int host_little(void)
{
    uint32_t one = 1;
    unsigned char b;
    memcpy(&b, &one, 1);
    return b == 1;
}

static float bits_to_float(uint32_t u)
{
    float v;
    memcpy(&v, &u, 4);
    return v;
}

static uint32_t be32(const unsigned char *p)
{
    return (uint32_t)p[0] << 24 | (uint32_t)p[1] << 16 | (uint32_t)p[2] << 8 | p[3];
}

/* CRC-32 of PNG (ISO 3309), the byte-wise table form of the PNG specification's
 * sample code, independent of the library's 4-bit version. */
static uint32_t crc_table[256];
static void crc_init(void)
{
    uint32_t n, k, c;
    for (n = 0; n < 256; ++n) {
        c = n;
        for (k = 0; k < 8; ++k) c = c & 1 ? 0xEDB88320u ^ (c >> 1) : c >> 1;
        crc_table[n] = c;
    }
}
static uint32_t crc32_of(const unsigned char *p, size_t n)
{
    uint32_t c = 0xFFFFFFFFu;
    size_t i;
    for (i = 0; i < n; ++i) c = crc_table[(c ^ p[i]) & 255] ^ (c >> 8);
    return c ^ 0xFFFFFFFFu;
}

static uint32_t adler32_of(const unsigned char *p, size_t n)
{
    uint32_t a = 1, b = 0;
    size_t i;
    for (i = 0; i < n; ++i) {
        a = (a + p[i]) % 65521u;
        b = (b + a) % 65521u;
    }
    return b << 16 | a;
}

/* ---- PFM ----------------------------------------------------------------------- */

static void test_pfm_round_trip(void)
{
    enum { W = 5, H = 3 };
    const char *path = check_path("image", "round.pfm");
    float px[W * H * 3];
    appm_image img, back;
    appm_diag d;
    unsigned char *raw;
    size_t len, i;
    char head[64];
    int x, y, c;
    /* An asymmetric gradient (every value distinct, so a flip or a transpose
     * shows), plus the extremes a float can hold. */
    for (y = 0; y < H; ++y)
        for (x = 0; x < W; ++x)
            for (c = 0; c < 3; ++c) px[3 * (y * W + x) + c] = (float)(100 * y + 10 * x + c) + 0.25f;
    px[0] = -1.5f;                      /* negative */
    px[1] = 1e-40f;                     /* denormal */
    px[2] = 3.0e38f;                    /* huge */
    px[3] = -0.0f;                      /* the sign of zero is a bit too */
    px[4] = FLT_MIN;
    px[5] = -FLT_MAX;
    px[6] = (float)HUGE_VAL;            /* infinity */
    px[7] = bits_to_float(0x00000001u); /* the smallest denormal */
    img.width = W;
    img.height = H;
    img.rgb = px;
    remove(path);
    CHECK(appm_image_write(path, &img, 1.0, &d) == APPM_OK);
    CHECK(appm_image_read_pfm(path, NULL, &back, &d) == APPM_OK);
    CHECK(back.width == W && back.height == H);
    if (back.rgb && back.width == W && back.height == H) {
        int same = 1;
        for (i = 0; i < (size_t)W * H * 3; ++i) same &= check_fbits(back.rgb[i]) == check_fbits(px[i]);
        CHECK_MSG(same, "PFM round trip is not bit exact");
        CHECK(back.rgb[0] == -1.5f); /* top-left comes back top-left */
    }
    appm_image_free(NULL, &back);
    CHECK(back.rgb == NULL);
    /* The file itself: header, then the BOTTOM row first, in host order. */
    raw = check_read_file(path, &len);
    CHECK(raw != NULL);
    if (!raw) return;
    sprintf(head, "PF\n%d %d\n%s\n", W, H, host_little() ? "-1.0" : "1.0");
    CHECK(len == strlen(head) + (size_t)W * H * 12);
    CHECK(len >= strlen(head) && memcmp(raw, head, strlen(head)) == 0);
    if (len == strlen(head) + (size_t)W * H * 12) {
        const unsigned char *data = raw + strlen(head);
        CHECK(memcmp(data, px + 3 * W * (H - 1), W * 12) == 0); /* file row 0 = image row H-1 */
        CHECK(memcmp(data + W * 12 * (H - 1), px, W * 12) == 0); /* last file row = image row 0 */
    }
    free(raw);
    /* NaN survives as a NaN */
    px[8] = (float)NAN;
    CHECK(appm_image_write(path, &img, 1.0, &d) == APPM_OK);
    CHECK(appm_image_read_pfm(path, NULL, &back, &d) == APPM_OK);
    if (back.rgb) CHECK(back.rgb[8] != back.rgb[8]);
    appm_image_free(NULL, &back);
}

/* A PFM in the other byte order, written byte by byte: big-endian, scale 1.0. */
static void test_pfm_big_endian_and_grey(void)
{
    const char *path = check_path("image", "be.pfm");
    unsigned char buf[256];
    size_t n;
    int x, y, c;
    appm_image img;
    appm_diag d;
    /* image value at (x, y, c) = 1 + x + 10 y + 0.125 c, 2 wide, 3 high */
    n = (size_t)sprintf((char *)buf, "PF\n2 3\n1.0\n");
    for (y = 2; y >= 0; --y) /* bottom row first */
        for (x = 0; x < 2; ++x)
            for (c = 0; c < 3; ++c) {
                uint32_t u = check_fbits(1.0f + (float)x + 10.0f * (float)y + 0.125f * (float)c);
                buf[n++] = (unsigned char)(u >> 24);
                buf[n++] = (unsigned char)(u >> 16);
                buf[n++] = (unsigned char)(u >> 8);
                buf[n++] = (unsigned char)u;
            }
    CHECK(write_bytes(path, buf, n));
    CHECK(appm_image_read_pfm(path, NULL, &img, &d) == APPM_OK);
    CHECK(img.width == 2 && img.height == 3);
    if (img.rgb && img.width == 2 && img.height == 3) {
        int ok = 1;
        for (y = 0; y < 3; ++y)
            for (x = 0; x < 2; ++x)
                for (c = 0; c < 3; ++c)
                    ok &= img.rgb[3 * (y * 2 + x) + c] == 1.0f + (float)x + 10.0f * (float)y + 0.125f * (float)c;
        CHECK_MSG(ok, "big-endian PFM read wrong");
    }
    appm_image_free(NULL, &img);
    /* Grey "Pf", little-endian, 3 wide, 2 high, header fields on one line */
    path = check_path("image", "grey.pfm");
    n = (size_t)sprintf((char *)buf, "Pf 3 2 -1\n");
    for (y = 1; y >= 0; --y)
        for (x = 0; x < 3; ++x) {
            uint32_t u = check_fbits(0.5f * (float)x - (float)y);
            buf[n++] = (unsigned char)u;
            buf[n++] = (unsigned char)(u >> 8);
            buf[n++] = (unsigned char)(u >> 16);
            buf[n++] = (unsigned char)(u >> 24);
        }
    CHECK(write_bytes(path, buf, n));
    CHECK(appm_image_read_pfm(path, NULL, &img, &d) == APPM_OK);
    CHECK(img.width == 3 && img.height == 2);
    if (img.rgb && img.width == 3 && img.height == 2) {
        int ok = 1;
        for (y = 0; y < 2; ++y)
            for (x = 0; x < 3; ++x)
                for (c = 0; c < 3; ++c) ok &= img.rgb[3 * (y * 3 + x) + c] == 0.5f * (float)x - (float)y;
        CHECK_MSG(ok, "grey PFM read wrong");
    }
    appm_image_free(NULL, &img);
}

static void test_pfm_malformed(void)
{
    static const char *const heads[] = {
        "",                  /* empty file */
        "P",                 /* magic cut short */
        "P6\n2 2\n255\n",    /* a PPM */
        "PG\n2 2\n-1.0\n",   /* no such PFM kind */
        "pf\n2 2\n-1.0\n",   /* magic is case sensitive */
        "PF\n0 2\n-1.0\n",   /* zero size */
        "PF\n2 0\n-1.0\n",
        "PF\n-1 2\n-1.0\n",  /* negative */
        "PF\n99999 2\n-1.0\n", /* above 32768 */
        "PF\n2 99999\n-1.0\n",
        "PF\nabc 2\n-1.0\n", /* not numbers */
        "PF\n2 x\n-1.0\n",
        "PF\n2.5 2\n-1.0\n",
        "PF\n0x2 2\n-1.0\n",
        "PF\n2\n",           /* header cut short */
        "PF\n2 2\n",
        "PF\n2 2\nzero\n",   /* bad scale */
        "PF\n2 2\n0\n",
        "PF\n2 2\nnan\n",
        "PF\n2 2\n-1.0",     /* no byte after the scale, no data */
        "PF\n2 2\n-1.0\n",   /* no data */
        "PF\n32768 32768\n-1.0\n", /* legal size, 12 GB short: rejected before allocating */
        "PF\n1234567890123456789012345678901234567890123456789012345678901234567890 2\n-1.0\n",
    };
    const char *path = check_path("image", "bad.pfm");
    size_t k;
    for (k = 0; k < sizeof heads / sizeof heads[0]; ++k) {
        appm_image img;
        appm_diag d;
        appm_status st;
        CHECK(write_bytes(path, heads[k], strlen(heads[k])));
        img.rgb = (float *)&img; /* must come back NULL */
        st = appm_image_read_pfm(path, NULL, &img, &d);
        CHECK_MSG(st == APPM_ERR_PARSE, "header %d ('%.20s'): status %d", (int)k, heads[k], (int)st);
        CHECK(img.rgb == NULL && img.width == 0 && img.height == 0);
        CHECK(d.status == st && strstr(d.file, "bad.pfm") != NULL);
    }
    /* Data one byte short of 2 x 2 x 3 floats */
    {
        unsigned char buf[64];
        size_t n = (size_t)sprintf((char *)buf, "PF\n2 2\n-1.0\n");
        appm_image img;
        appm_diag d;
        memset(buf + n, 0x3f, 48);
        CHECK(write_bytes(path, buf, n + 47));
        CHECK(appm_image_read_pfm(path, NULL, &img, &d) == APPM_ERR_PARSE);
        CHECK(img.rgb == NULL);
        CHECK(write_bytes(path, buf, n + 48)); /* and complete, it reads */
        CHECK(appm_image_read_pfm(path, NULL, &img, &d) == APPM_OK);
        appm_image_free(NULL, &img);
        /* grey data is a third of that */
        buf[1] = 'f';
        CHECK(write_bytes(path, buf, n + 15));
        CHECK(appm_image_read_pfm(path, NULL, &img, &d) == APPM_ERR_PARSE);
        CHECK(write_bytes(path, buf, n + 16));
        CHECK(appm_image_read_pfm(path, NULL, &img, &d) == APPM_OK);
        appm_image_free(NULL, &img);
    }
    /* A missing file is an I/O error, not a parse error */
    {
        appm_image img;
        appm_diag d;
        CHECK(appm_image_read_pfm("tests/out/no-such-dir/none.pfm", NULL, &img, &d) == APPM_ERR_IO);
    }
}

/* ---- PNG ------------------------------------------------------------------------ */

typedef struct png_info {
    int ok;
    uint32_t w, h;
    int idat;                  /* IDAT chunks */
    int blocks[3];             /* deflate blocks: stored, fixed, dynamic */
    int filters[5];            /* rows per filter type */
    unsigned char *raw;        /* the pixels, RGB, row 0 first (filters undone) */
    size_t raw_len;
    size_t zlen;               /* bytes of the zlib stream */
} png_info;

/* Walks the chunks, checks every CRC, joins the IDAT data, inflates it
 * (header, blocks and Adler-32 checked by tests/inflate.h) and undoes the row
 * filters. */
static png_info png_decode(const unsigned char *p, size_t len)
{
    static const unsigned char sig[8] = {137, 80, 78, 71, 13, 10, 26, 10};
    png_info r;
    unsigned char *z = NULL, *rows;
    size_t zlen = 0, pos = 8, got, want;
    int seen_ihdr = 0, seen_iend = 0, first = 1;
    memset(&r, 0, sizeof r);
    CHECK(len >= 8 && memcmp(p, sig, 8) == 0);
    if (len < 8 || memcmp(p, sig, 8) != 0) return r;
    z = (unsigned char *)malloc(len);
    while (pos + 12 <= len) {
        uint32_t n = be32(p + pos);
        const unsigned char *type = p + pos + 4, *data = p + pos + 8;
        if (pos + 12 + (size_t)n > len) break;
        CHECK_MSG(crc32_of(type, 4 + (size_t)n) == be32(data + n), "CRC of chunk %.4s is wrong", (const char *)type);
        if (first) CHECK(memcmp(type, "IHDR", 4) == 0); /* IHDR comes first */
        first = 0;
        if (memcmp(type, "IHDR", 4) == 0 && n == 13) {
            seen_ihdr = 1;
            r.w = be32(data);
            r.h = be32(data + 4);
            CHECK(data[8] == 8 && data[9] == 2); /* 8-bit RGB */
            CHECK(data[10] == 0 && data[11] == 0 && data[12] == 0);
        } else if (memcmp(type, "IDAT", 4) == 0) {
            memcpy(z + zlen, data, n);
            zlen += n;
            r.idat++;
        } else if (memcmp(type, "IEND", 4) == 0) {
            seen_iend = 1;
            CHECK(n == 0);
            CHECK(pos + 12 == len); /* nothing after IEND */
        }
        pos += 12 + (size_t)n;
    }
    CHECK(seen_ihdr && seen_iend);
    r.zlen = zlen;
    want = (size_t)r.h * (1 + 3 * (size_t)r.w);
    rows = (unsigned char *)malloc(want + 1);
    got = seen_ihdr ? tinf_zlib(z, zlen, rows, want + 1, r.blocks) : (size_t)-1;
    CHECK_MSG(got == want, "the zlib stream inflates to %.0f bytes, not %.0f", (double)got, (double)want);
    if (got == want) {
        r.raw_len = (size_t)r.h * 3 * r.w;
        r.raw = (unsigned char *)malloc(r.raw_len + 1);
        r.ok = png_unfilter(rows, 3 * (size_t)r.w, r.h, 3, r.raw, r.filters);
        CHECK(r.ok);
    }
    free(rows);
    free(z);
    return r;
}

/* The sRGB bytes of the values named in the header comment. */
static const float VALS[10] = {0.0f, 0.5f, 1.0f, 2.0f, 0.0f /* NaN, set below */, -1.0f,
                               0.25f, 0.001f, 0.1f, 0.75f};
static const unsigned char BYTES[10] = {0, 188, 255, 255, 0, 0, 137, 3, 89, 225};

static void test_png(void)
{
    const char *path = check_path("image", "small.png");
    float px[2 * 2 * 3] = {0.0f, 0.5f, 1.0f, 2.0f, 0.0f, -1.0f, /* row 0 */
                           0.25f, 0.001f, 1e30f, 0.1f, 0.75f, 0.0f};
    static const unsigned char want[2 * 6] = {0, 188, 255, 255, 0, 0, /* row 0 */
                                              137, 3, 255, 89, 225, 0};
    appm_image img;
    appm_diag d;
    unsigned char *raw;
    size_t len;
    px[4] = (float)NAN;
    px[11] = (float)HUGE_VAL;
    img.width = 2;
    img.height = 2;
    img.rgb = px;
    CHECK(appm_image_write(path, &img, 1.0, &d) == APPM_OK);
    raw = check_read_file(path, &len);
    CHECK(raw != NULL);
    if (raw) {
        png_info r = png_decode(raw, len);
        unsigned char want2[sizeof want];
        memcpy(want2, want, sizeof want);
        want2[11] = 255; /* +inf */
        CHECK(r.ok && r.w == 2 && r.h == 2);
        CHECK(r.raw_len == sizeof want);
        CHECK(r.raw_len == sizeof want && memcmp(r.raw, want2, sizeof want) == 0);
        free(r.raw);
        free(raw);
    }
    /* 300 rows of 1 + 3 * 200 bytes = 180300 bytes: more than the 64 KiB
     * window of the compressor, so it slides. */
    {
        enum { W = 200, H = 300 };
        float *big = (float *)malloc(sizeof(float) * W * H * 3);
        unsigned char *expect = (unsigned char *)malloc((size_t)H * 3 * W);
        float vals[10];
        int x, y, c;
        memcpy(vals, VALS, sizeof vals);
        vals[4] = (float)NAN;
        for (y = 0; y < H; ++y) {
            for (x = 0; x < W; ++x)
                for (c = 0; c < 3; ++c) {
                    int k = (3 * x + c + 7 * y) % 10;
                    big[3 * ((size_t)y * W + x) + c] = vals[k];
                    expect[(size_t)y * 3 * W + 3 * x + c] = BYTES[k];
                }
        }
        img.width = W;
        img.height = H;
        img.rgb = big;
        path = check_path("image", "wide.png");
        CHECK(appm_image_write(path, &img, 1.0, &d) == APPM_OK);
        raw = check_read_file(path, &len);
        CHECK(raw != NULL);
        if (raw) {
            png_info r = png_decode(raw, len);
            CHECK(r.ok && r.w == W && r.h == H);
            CHECK(r.raw_len == (size_t)H * 3 * W);
            CHECK(r.raw_len == (size_t)H * 3 * W && memcmp(r.raw, expect, r.raw_len) == 0);
            /* a pattern repeating every 10 bytes and 7 rows compresses to a few percent */
            CHECK_MSG(r.zlen < (size_t)H * (1 + 3 * W) / 20, "zlib stream %.0f bytes", (double)r.zlen);
            free(r.raw);
            free(raw);
        }
        free(big);
        free(expect);
    }
}

/* ---- PPM ---------------------------------------------------------------------- */

static void test_ppm(void)
{
    const char *path = check_path("image", "enc.ppm");
    /* one pixel per value, all three channels equal */
    float v[7];
    float px[7 * 3];
    static const unsigned char want[7] = {0, 0, 0, 188, 255, 255, 255};
    appm_image img;
    appm_diag d;
    unsigned char *raw;
    size_t len;
    int i;
    v[0] = (float)NAN;
    v[1] = -1.0f;
    v[2] = 0.0f;
    v[3] = 0.5f;
    v[4] = 1.0f;
    v[5] = 1e30f;
    v[6] = (float)HUGE_VAL;
    for (i = 0; i < 21; ++i) px[i] = v[i / 3];
    img.width = 7;
    img.height = 1;
    img.rgb = px;
    CHECK(appm_image_write(path, &img, 1.0, &d) == APPM_OK);
    raw = check_read_file(path, &len);
    CHECK(raw && len == strlen("P6\n7 1\n255\n") + 21);
    if (raw && len == strlen("P6\n7 1\n255\n") + 21) {
        const unsigned char *p = raw + strlen("P6\n7 1\n255\n");
        int ok = 1;
        CHECK(memcmp(raw, "P6\n7 1\n255\n", strlen("P6\n7 1\n255\n")) == 0);
        for (i = 0; i < 21; ++i) ok &= p[i] == want[i / 3];
        CHECK_MSG(ok, "PPM bytes %d %d %d %d %d %d %d", p[0], p[3], p[6], p[9], p[12], p[15], p[18]);
    }
    free(raw);
    /* Exposure multiplies before the encoding: 0.25 x 2 = 0.5 -> 188, x 4 = 1
     * -> 255, 0.125 x 2 = 0.25 -> 137; exposure 0 means 1. Rows stay in order
     * (2 x 2 image, row 0 first). */
    {
        float q[12] = {0.25f, 0.25f, 0.25f, 0.125f, 0.125f, 0.125f, 0.5f, 0.5f, 0.5f, 0, 0, 0};
        static const unsigned char want2[12] = {188, 188, 188, 137, 137, 137, 255, 255, 255, 0, 0, 0};
        static const unsigned char want4[12] = {255, 255, 255, 188, 188, 188, 255, 255, 255, 0, 0, 0};
        /* 0.125: 1.055 * 0.125^(1/2.4) - 0.055 = 0.3886, x 255 + 0.5 = 99.59 -> 99 */
        static const unsigned char want1[12] = {137, 137, 137, 99, 99, 99, 188, 188, 188, 0, 0, 0};
        const char *hd = "P6\n2 2\n255\n";
        img.width = 2;
        img.height = 2;
        img.rgb = q;
        CHECK(appm_image_write(path, &img, 2.0, &d) == APPM_OK);
        raw = check_read_file(path, &len);
        CHECK(raw && len == strlen(hd) + 12 && memcmp(raw + strlen(hd), want2, 12) == 0);
        free(raw);
        CHECK(appm_image_write(path, &img, 4.0, &d) == APPM_OK);
        raw = check_read_file(path, &len);
        CHECK(raw && len == strlen(hd) + 12 && memcmp(raw + strlen(hd), want4, 12) == 0);
        free(raw);
        CHECK(appm_image_write(path, &img, 0.0, &d) == APPM_OK);
        raw = check_read_file(path, &len);
        CHECK(raw && len == strlen(hd) + 12 && memcmp(raw + strlen(hd), want1, 12) == 0);
        free(raw);
        /* exposure must be a non-negative number */
        CHECK(appm_image_write(path, &img, -1.0, &d) == APPM_ERR_INVALID_ARG);
        CHECK(appm_image_write(path, &img, (double)NAN, &d) == APPM_ERR_INVALID_ARG);
    }
}

/* ---- failed writes ------------------------------------------------------------ */

static void test_write_failures(void)
{
    enum { W = 64, H = 64 };
    float *px = (float *)calloc((size_t)W * H * 3, sizeof(float));
    appm_image img, other;
    appm_diag d;
    const char *bad = "tests/out/image-no-such-dir/x.pfm";
    char keep[256], tmp[300];
    unsigned char *before, *after;
    size_t n1, n2;
    int i;
    for (i = 0; i < W * H * 3; ++i) px[i] = (float)i;
    img.width = W;
    img.height = H;
    img.rgb = px;
    other = img;
    other.width = W / 2; /* a different, smaller image */

    /* a folder that does not exist: an I/O error and no file at all */
    CHECK(appm_image_write(bad, &img, 1.0, &d) == APPM_ERR_IO);
    CHECK(d.status == APPM_ERR_IO && strstr(d.file, "x.pfm") != NULL);
    CHECK(!file_exists(bad));
    CHECK(!file_exists("tests/out/image-no-such-dir/x.pfm.tmp"));
    /* bad arguments write nothing */
    CHECK(appm_image_write(check_path("image", "x.jpg"), &img, 1.0, &d) == APPM_ERR_INVALID_ARG);
    CHECK(!file_exists(check_path("image", "x.jpg")) && !file_exists(check_path("image", "x.jpg.tmp")));
    other.height = 0;
    CHECK(appm_image_write(check_path("image", "x.pfm"), &other, 1.0, &d) == APPM_ERR_INVALID_ARG);
    other.height = H;

#if HAVE_POSIX
    /* A full disk, honestly: "<name>.tmp" is made a symbolic link to /dev/full,
     * so the writer's own fopen/fwrite/fclose on its temporary meet ENOSPC.
     * The good file under the final name must survive untouched and the
     * temporary must be gone. */
    snprintf(keep, sizeof keep, "%s", check_path("image", "keep.pfm"));
    snprintf(tmp, sizeof tmp, "%s.tmp", keep);
    remove(tmp);
    CHECK(appm_image_write(keep, &img, 1.0, &d) == APPM_OK);
    before = check_read_file(keep, &n1);
    {
        struct stat st;
        if (stat("/dev/full", &st) == 0 && S_ISCHR(st.st_mode) && symlink("/dev/full", tmp) == 0) {
            appm_status s = appm_image_write(keep, &other, 1.0, &d);
            CHECK_MSG(s == APPM_ERR_IO, "write to a full disk returned %d", (int)s);
            CHECK(lstat(tmp, &st) != 0); /* no "<name>.tmp" left behind */
            after = check_read_file(keep, &n2);
            CHECK(before && after && n1 == n2 && memcmp(before, after, n1) == 0);
            free(after);
            remove(tmp);
        } else {
            printf("note: /dev/full unavailable, the full-disk case is skipped\n");
        }
    }
    /* The destination is a directory (with a file in it): the rename fails,
     * the directory and its content stay, the temporary is removed. */
    {
        char dir[256], inner[300];
        snprintf(dir, sizeof dir, "%s", check_path("image", "dest-dir.png"));
        snprintf(inner, sizeof inner, "%s/inside", dir);
        mkdir(dir, 0755);
        CHECK(write_bytes(inner, "x", 1));
        CHECK(appm_image_write(dir, &img, 1.0, &d) == APPM_ERR_IO);
        CHECK(file_exists(inner));
        snprintf(tmp, sizeof tmp, "%s.tmp", dir);
        CHECK(!file_exists(tmp));
    }
    /* The temporary's name is taken by a directory: fopen fails, and the
     * existing good file is kept. */
    snprintf(tmp, sizeof tmp, "%s.tmp", keep);
    mkdir(tmp, 0755);
    CHECK(appm_image_write(keep, &other, 1.0, &d) == APPM_ERR_IO);
    after = check_read_file(keep, &n2);
    CHECK(before && after && n1 == n2 && memcmp(before, after, n1) == 0);
    free(after);
    rmdir(tmp);
    /* and with the way clear, a write replaces the file */
    CHECK(appm_image_write(keep, &other, 1.0, &d) == APPM_OK);
    after = check_read_file(keep, &n2);
    CHECK(after && n2 < n1);
    free(after);
    free(before);
#else
    (void)keep;
    (void)tmp;
    (void)before;
    (void)after;
    (void)n1;
    (void)n2;
    printf("note: no POSIX file system calls, the failed-write cases are skipped\n");
#endif
    free(px);
}

/* ---- compare ------------------------------------------------------------------ */

static void test_compare(void)
{
    /* 2 pixels x 3 channels.  d = a - b = {0, 1, -0.5, 0, -1, 1} */
    float a[6] = {1, 2, 0.5f, 0, -1, 3};
    float b[6] = {1, 1, 1, 0, 0, 2};
    appm_image A, B;
    appm_compare_result r;
    A.width = 2;
    A.height = 1;
    A.rgb = a;
    B = A;
    B.rgb = b;
    CHECK(appm_image_compare(&A, &B, &r) == APPM_OK);
    /* sum d^2 = 0 + 1 + 0.25 + 0 + 1 + 1 = 3.25 over 6 values */
    CHECK_NEAR(r.rmse, sqrt(3.25 / 6.0), 1e-12);
    /* sum d^2 / (b^2 + 0.01) = 1/1.01 + 0.25/1.01 + 1/0.01 + 1/4.01 */
    CHECK_NEAR(r.relmse, (1.0 / 1.01 + 0.25 / 1.01 + 1.0 / 0.01 + 1.0 / 4.01) / 6.0, 1e-12);
    CHECK_NEAR(r.mae, 3.5 / 6.0, 1e-12);
    CHECK_NEAR(r.mean_a, 5.5 / 6.0, 1e-12);
    CHECK_NEAR(r.mean_b, 5.0 / 6.0, 1e-12);
    /* an image against itself */
    CHECK(appm_image_compare(&A, &A, &r) == APPM_OK);
    CHECK(r.rmse == 0.0 && r.relmse == 0.0 && r.mae == 0.0);
    /* the reference is the second argument: relmse is not symmetric */
    CHECK(appm_image_compare(&B, &A, &r) == APPM_OK);
    CHECK_NEAR(r.relmse, (1.0 / 4.01 + 0.25 / 0.26 + 1.0 / 1.01 + 1.0 / 9.01) / 6.0, 1e-12);
    /* sizes must match, also when the pixel counts agree (2x1 vs 1x2) */
    B.width = 1;
    B.height = 2;
    CHECK(appm_image_compare(&A, &B, &r) != APPM_OK);
    B.width = 1;
    B.height = 1;
    CHECK(appm_image_compare(&A, &B, &r) != APPM_OK);
    CHECK(appm_image_compare(NULL, &B, &r) != APPM_OK);
    CHECK(appm_image_compare(&A, &A, NULL) != APPM_OK);
}

/* ---- PNG against PPM, compression, deflate parts --------------------------------- */

/* Writes img as .png and .ppm and checks that the PNG's pixels are exactly the
 * PPM's bytes; returns the size of the PNG's zlib stream. */
static size_t png_matches_ppm(const appm_image *img, const char *name)
{
    char png[512], ppm[512];
    unsigned char *a, *b;
    size_t la, lb, zlen = 0;
    appm_diag d;
    snprintf(png, sizeof png, "%s.png", check_path("image", name));
    snprintf(ppm, sizeof ppm, "%s.ppm", check_path("image", name));
    CHECK_MSG(appm_image_write(png, img, 1.0, &d) == APPM_OK, "%s: %s", png, d.message);
    CHECK(appm_image_write(ppm, img, 1.0, &d) == APPM_OK);
    a = check_read_file(png, &la);
    b = check_read_file(ppm, &lb);
    CHECK(a && b);
    if (a && b) {
        png_info r = png_decode(a, la);
        char head[64];
        size_t hl = (size_t)sprintf(head, "P6\n%lu %lu\n255\n", (unsigned long)img->width,
                                    (unsigned long)img->height);
        CHECK(r.ok && r.w == img->width && r.h == img->height);
        CHECK_MSG(r.ok && lb == hl + r.raw_len && memcmp(b + hl, r.raw, r.raw_len) == 0,
                  "%s: the PNG's pixels differ from the PPM's", name);
        zlen = r.zlen;
        free(r.raw);
    }
    free(a);
    free(b);
    return zlen;
}

static float *image_alloc(appm_image *img, uint32_t w, uint32_t h)
{
    img->width = w;
    img->height = h;
    img->rgb = (float *)malloc(sizeof(float) * 3 * (size_t)w * h);
    return img->rgb;
}

static void test_png_matches_ppm(void)
{
    appm_image img;
    size_t i, n, z;
    uint32_t x, y, state = 12345u;
    /* all black and all white compress to almost nothing: 512 rows of 1537 bytes */
    n = (size_t)512 * 512 * 3;
    if (!image_alloc(&img, 512, 512)) return;
    for (i = 0; i < n; ++i) img.rgb[i] = 0.0f;
    z = png_matches_ppm(&img, "black");
    CHECK_MSG(z > 0 && z < 2000, "all-black 512x512: %.0f bytes", (double)z);
    for (i = 0; i < n; ++i) img.rgb[i] = 3.0f; /* clamps to 255 */
    z = png_matches_ppm(&img, "white");
    CHECK_MSG(z > 0 && z < 2000, "all-white 512x512: %.0f bytes", (double)z);
    /* noise: incompressible bytes may not grow much beyond the raw size */
    for (i = 0; i < n; ++i) {
        state = state * 1664525u + 1013904223u;
        img.rgb[i] = (float)(state >> 8) / 16777216.0f;
    }
    z = png_matches_ppm(&img, "noise");
    CHECK_MSG(z > 0 && z < (size_t)512 * 1537 * 102 / 100, "noise 512x512: %.0f bytes", (double)z);
    /* a smooth gradient: the filters should make it small */
    for (y = 0; y < 512; ++y)
        for (x = 0; x < 512; ++x) {
            float *p = img.rgb + 3 * ((size_t)y * 512 + x);
            p[0] = (float)x / 511.0f;
            p[1] = (float)y / 511.0f;
            p[2] = 0.25f;
        }
    z = png_matches_ppm(&img, "gradient");
    CHECK_MSG(z > 0 && z < (size_t)512 * 1537 / 10, "gradient 512x512: %.0f bytes", (double)z);
    free(img.rgb);
    /* 1x1 */
    if (!image_alloc(&img, 1, 1)) return;
    img.rgb[0] = 0.5f;
    img.rgb[1] = 0.25f;
    img.rgb[2] = 0.1f;
    CHECK(png_matches_ppm(&img, "one") > 0);
    free(img.rgb);
    /* 32768 wide, 3 rows: a row of 98305 bytes is larger than the window */
    if (!image_alloc(&img, 32768, 3)) return;
    for (i = 0; i < (size_t)32768 * 3 * 3; ++i) {
        state = state * 1664525u + 1013904223u;
        img.rgb[i] = (i / 3) % 97 < 50 ? (float)(i % 256) / 255.0f : (float)(state >> 8) / 16777216.0f;
    }
    CHECK(png_matches_ppm(&img, "wide32768") > 0);
    free(img.rgb);
}

static void test_checksums_and_codes(void)
{
    appm__zlib z;
    uint32_t freq[30];
    unsigned char len[30];
    unsigned i, maxlen = 0;
    double kraft = 0.0;
    /* Adler-32 of "Wikipedia" is 0x11E60398 (RFC 1950's definition, the
     * textbook example); also over more than 5552 bytes, where the sums are
     * reduced in pieces. */
    memset(&z, 0, sizeof z);
    z.s1 = 1;
    appm__zlib_adler(&z, (const unsigned char *)"Wikipedia", 9);
    CHECK((z.s2 << 16 | z.s1) == 0x11E60398u);
    {
        unsigned char *big = (unsigned char *)malloc(100000);
        for (i = 0; i < 100000; ++i) big[i] = (unsigned char)(255 - i % 7);
        z.s1 = 1;
        z.s2 = 0;
        appm__zlib_adler(&z, big, 100000);
        CHECK((z.s2 << 16 | z.s1) == adler32_of(big, 100000));
        free(big);
    }
    CHECK(appm__crc32_update(0xFFFFFFFFu, (const unsigned char *)"123456789", 9) == (0xCBF43926u ^ 0xFFFFFFFFu));
    /* Fibonacci counts make the optimal code 29 levels deep: the limit to 15
     * must hold and leave a complete code (Kraft sum exactly 1). */
    freq[0] = freq[1] = 1;
    for (i = 2; i < 30; ++i) freq[i] = freq[i - 1] + freq[i - 2];
    appm__huff_lengths(freq, 30, 15, len);
    for (i = 0; i < 30; ++i) {
        maxlen = len[i] > maxlen ? len[i] : maxlen;
        kraft += ldexp(1.0, -(int)len[i]);
        CHECK(len[i] >= 1);
    }
    CHECK(maxlen == 15);
    CHECK(kraft == 1.0);
    for (i = 1; i < 30; ++i) CHECK(len[i] <= len[i - 1]); /* rarer symbols never get shorter codes */
    /* deflate's length and distance codes at their boundaries (RFC 1951, 3.2.5) */
    CHECK(appm__len_code(3) == 0 && appm__len_code(10) == 7 && appm__len_code(11) == 8);
    CHECK(appm__len_code(12) == 8 && appm__len_code(13) == 9 && appm__len_code(257) == 27);
    CHECK(appm__len_code(227) == 27 && appm__len_code(226) == 26 && appm__len_code(258) == 28);
    CHECK(appm__dist_code(1) == 0 && appm__dist_code(4) == 3 && appm__dist_code(5) == 4);
    CHECK(appm__dist_code(7) == 5 && appm__dist_code(24577) == 29 && appm__dist_code(32768) == 29);
    CHECK(appm__dist_code(24576) == 28);
    for (i = 3; i <= 258; ++i) { /* every length lies inside its code's range */
        unsigned c = appm__len_code(i);
        CHECK(i >= appm__len_base[c] && i - appm__len_base[c] < (1u << appm__len_extra[c]) && (c < 28 || i == 258));
    }
}

/* ---- OpenEXR, read back by a reader written here from the file layout ------------ */

static uint32_t le32(const unsigned char *p)
{
    return (uint32_t)p[0] | (uint32_t)p[1] << 8 | (uint32_t)p[2] << 16 | (uint32_t)p[3] << 24;
}

static float half_to_float(unsigned h)
{
    unsigned e = (h >> 10) & 31, m = h & 1023;
    float v = e == 0 ? ldexpf((float)m, -24) : e == 31 ? (m ? (float)NAN : (float)HUGE_VAL)
                                                         : ldexpf((float)(m | 1024), (int)e - 25);
    return (h & 0x8000) ? -v : v;
}

/* Reads a file written by appm (attributes in its order are not assumed: each
 * is looked up by name) into rgb (w*h*3).  Returns 0 on any inconsistency. */
static int exr_read(const unsigned char *p, size_t len, uint32_t w, uint32_t h, float *rgb, int *half, int *zip)
{
    size_t pos = 8, k, nblock, lines;
    int type[3] = {-1, -1, -1}, have_dw = 0;
    if (len < 8 || le32(p) != 20000630u || le32(p + 4) != 2) return 0;
    *zip = -1;
    while (pos < len && p[pos]) { /* name, type, size, value */
        const char *name = (const char *)p + pos, *ty;
        uint32_t sz;
        pos += strlen(name) + 1;
        ty = (const char *)p + pos;
        pos += strlen(ty) + 1;
        sz = le32(p + pos);
        pos += 4;
        if (pos + sz > len) return 0;
        if (!strcmp(name, "channels") && !strcmp(ty, "chlist")) {
            size_t q = pos;
            int c;
            for (c = 0; c < 3; ++c) { /* sorted: B, G, R */
                if (p[q] != "BGR"[c] || p[q + 1] != 0) return 0;
                type[c] = (int)le32(p + q + 2);
                if (le32(p + q + 10) != 1 || le32(p + q + 14) != 1) return 0;
                q += 18;
            }
            if (p[q] != 0 || q + 1 != pos + sz) return 0;
        } else if (!strcmp(name, "compression")) {
            *zip = p[pos] == 3 ? 1 : p[pos] == 0 ? 0 : -1;
        } else if (!strcmp(name, "dataWindow")) {
            have_dw = le32(p + pos) == 0 && le32(p + pos + 4) == 0 && le32(p + pos + 8) == w - 1 &&
                      le32(p + pos + 12) == h - 1;
        }
        pos += sz;
    }
    if (pos >= len || *zip < 0 || !have_dw || type[0] != type[1] || type[1] != type[2]) return 0;
    if (type[0] != 1 && type[0] != 2) return 0;
    *half = type[0] == 1;
    pos++;
    lines = *zip ? 16 : 1;
    nblock = (h + lines - 1) / lines;
    for (k = 0; k < nblock; ++k) {
        size_t off = le32(p + pos + 8 * k), bs = (size_t)(*half ? 2 : 4), y0, ny, raw_n, sz, i, y, c, x;
        unsigned char *raw, *tmp;
        if (le32(p + pos + 8 * k + 4) != 0 || off + 8 > len) return 0;
        y0 = le32(p + off);
        sz = le32(p + off + 4);
        if (y0 != k * lines || off + 8 + sz > len) return 0;
        ny = y0 + lines <= h ? lines : h - y0;
        raw_n = ny * w * 3 * bs;
        raw = (unsigned char *)malloc(raw_n + 1);
        tmp = (unsigned char *)malloc(raw_n + 1);
        if (sz == raw_n) {
            memcpy(raw, p + off + 8, raw_n);
        } else { /* inflate, undo the delta, then the even/odd split */
            size_t got = tinf_zlib(p + off + 8, sz, tmp, raw_n + 1, NULL), hn = (raw_n + 1) / 2;
            if (got != raw_n) {
                free(raw);
                free(tmp);
                return 0;
            }
            for (i = 1; i < raw_n; ++i) tmp[i] = (unsigned char)(tmp[i - 1] + tmp[i] - 128);
            for (i = 0; i < raw_n; ++i) raw[i] = tmp[(i & 1) ? hn + i / 2 : i / 2];
        }
        for (y = 0, i = 0; y < ny; ++y)
            for (c = 0; c < 3; ++c)
                for (x = 0; x < w; ++x, i += bs) {
                    float v;
                    if (*half) v = half_to_float((unsigned)raw[i] | (unsigned)raw[i + 1] << 8);
                    else v = bits_to_float(le32(raw + i));
                    rgb[3 * ((y0 + y) * w + x) + 2 - c] = v;
                }
        free(raw);
        free(tmp);
    }
    return 1;
}

static void test_half(void)
{
    CHECK(appm__half(1.0f) == 0x3C00 && appm__half(-2.0f) == 0xC000 && appm__half(0.0f) == 0);
    CHECK(appm__half(-0.0f) == 0x8000 && appm__half(0.5f) == 0x3800);
    CHECK(appm__half(0.1f) == 0x2E66);                   /* 0.0999755859375, the nearest half */
    CHECK(appm__half(65504.0f) == 0x7BFF && appm__half(65519.0f) == 0x7BFF);
    CHECK(appm__half(65520.0f) == 0x7BFF && appm__half(1e30f) == 0x7BFF); /* clamped, not inf */
    CHECK(appm__half(-1e30f) == 0xFBFF);
    CHECK(appm__half((float)HUGE_VAL) == 0x7C00 && (appm__half((float)NAN) & 0x7FFF) > 0x7C00);
    CHECK(appm__half(ldexpf(1.0f, -24)) == 0x0001);          /* the smallest subnormal */
    CHECK(appm__half(ldexpf(1.0f, -25)) == 0x0000);          /* halfway: to even, 0 */
    CHECK(appm__half(ldexpf(3.0f, -25)) == 0x0002);          /* halfway: to even, 2 */
    CHECK(appm__half(ldexpf(1.0f, -14)) == 0x0400);          /* the smallest normal */
    CHECK(appm__half(ldexpf(1023.5f, -24)) == 0x0400);       /* rounds up into the normals */
    CHECK(appm__half(1.0f + ldexpf(1.0f, -11)) == 0x3C00);   /* halfway: to even */
    CHECK(appm__half(1.0f + ldexpf(3.0f, -11)) == 0x3C02);
    CHECK(appm__half(2047.5f) == 0x6800);                    /* 2048 after rounding: exponent carries */
}

static void test_exr(void)
{
    enum { W = 37, H = 41 }; /* 41 lines: two full ZIP blocks and a short one */
    static const int halfs[2] = {0, 1}, comps[2] = {0, 1};
    appm_image img;
    float *back;
    uint32_t state = 99u;
    size_t i, n = (size_t)W * H * 3;
    int a, b;
    if (!image_alloc(&img, W, H)) return;
    back = (float *)malloc(sizeof(float) * n);
    for (i = 0; i < n; ++i) { /* smooth, noisy, tiny, huge and special values */
        state = state * 1664525u + 1013904223u;
        img.rgb[i] = i % 5 == 0 ? (float)(i % 97) * 0.01f : (float)(state >> 8) / 65536.0f - 64.0f;
    }
    img.rgb[3] = 1e-9f;
    img.rgb[4] = 7e4f;
    img.rgb[5] = (float)HUGE_VAL;
    for (a = 0; a < 2; ++a)
        for (b = 0; b < 2; ++b) {
            appm_write_options opt;
            appm_diag d;
            const char *path = check_path("image", halfs[a] ? (comps[b] ? "h-none.exr" : "h-zip.exr")
                                                            : (comps[b] ? "f-none.exr" : "f-zip.exr"));
            unsigned char *p;
            size_t len;
            int half = -1, zip = -1, bad = 0;
            memset(&opt, 0, sizeof opt);
            opt.exr_half = halfs[a];
            opt.exr_uncompressed = comps[b];
            CHECK(appm_image_write_ex(path, &img, &opt, NULL, &d) == APPM_OK);
            p = check_read_file(path, &len);
            CHECK(p != NULL);
            if (!p) continue;
            memset(back, 0, sizeof(float) * n);
            CHECK_MSG(exr_read(p, len, W, H, back, &half, &zip), "%s does not read back", path);
            CHECK(half == halfs[a] && zip == !comps[b]);
            for (i = 0; i < n; ++i) {
                float want = halfs[a] ? half_to_float(appm__half(img.rgb[i])) : img.rgb[i];
                if (check_fbits(back[i]) != check_fbits(want)) bad++;
            }
            CHECK_MSG(bad == 0, "%s: %d values differ", path, bad);
            /* mostly noise: a ZIP block that would grow is stored raw, so the
             * file is never larger than header + table + block heads + data */
            CHECK_MSG(len <= (size_t)W * H * 3 * (halfs[a] ? 2 : 4) + 400 + 16 * H, "%s: %.0f bytes", path,
                      (double)len);
            free(p);
        }
    /* a smooth image: ZIP must gain, and still read back exactly */
    for (i = 0; i < n; ++i) img.rgb[i] = (float)(i / 3 % W) * 0.125f + (float)(i % 3);
    {
        const char *path = check_path("image", "smooth.exr");
        appm_diag d;
        unsigned char *p;
        size_t len;
        int half, zip, bad = 0;
        CHECK(appm_image_write(path, &img, 1.0, &d) == APPM_OK);
        p = check_read_file(path, &len);
        CHECK(p && exr_read(p, len, W, H, back, &half, &zip) && !half && zip);
        for (i = 0; p && i < n; ++i) bad += check_fbits(back[i]) != check_fbits(img.rgb[i]);
        CHECK(bad == 0);
        CHECK_MSG(len < (size_t)W * H * 12 / 4, "smooth.exr: %.0f bytes", (double)len);
        free(p);
    }
    free(back);
    free(img.rgb);
}

static void test_write_allocation_failures(void)
{
    enum { W = 64, H = 20 };
    static const char *const names[3] = {"oom.png", "oom.exr", "oom-h.exr"};
    appm_image img;
    size_t i;
    int k;
    if (!image_alloc(&img, W, H)) return;
    for (i = 0; i < (size_t)W * H * 3; ++i) img.rgb[i] = (float)(i % 13) / 13.0f;
    for (k = 0; k < 3; ++k) {
        const char *path = check_path("image", names[k]);
        appm_write_options opt;
        appm_status st = APPM_ERR_NOMEM;
        long nfail;
        int bad = 0;
        memset(&opt, 0, sizeof opt);
        opt.exr_half = k == 2;
        for (nfail = 1; nfail < 40 && st != APPM_OK; ++nfail) {
            appm_config cfg;
            check_alloc al;
            appm_diag d;
            memset(&cfg, 0, sizeof cfg);
            check_use_alloc(&cfg, &al, nfail);
            remove(path);
            st = appm_image_write_ex(path, &img, &opt, &cfg, &d);
            if (al.live != 0) bad++;
            if (st != APPM_OK && (st != APPM_ERR_NOMEM || file_exists(path))) bad++;
        }
        CHECK_MSG(bad == 0, "%s: a failed allocation leaked or left a file", names[k]);
        CHECK_MSG(st == APPM_OK && nfail > 2, "%s: status %d after %ld tries", names[k], (int)st, nfail);
    }
    free(img.rgb);
}

int main(void)
{
    crc_init();
    test_pfm_round_trip();
    test_pfm_big_endian_and_grey();
    test_pfm_malformed();
    test_png();
    test_png_matches_ppm();
    test_checksums_and_codes();
    test_half();
    test_exr();
    test_write_allocation_failures();
    test_ppm();
    test_write_failures();
    test_compare();
    return check_finish();
}
