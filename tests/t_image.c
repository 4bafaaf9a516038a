/* tests/t_image.c - image files: PFM, PPM and PNG writers, the PFM reader, the
 * error metrics, and what a failed write leaves behind.
 *
 * The files are checked byte by byte against the formats' own definitions,
 * decoded here independently of the library:
 *   PFM  "PF\n<w> <h>\n<scale>\n", rows bottom to top, scale < 0 = little-endian
 *   PPM  "P6\n<w> <h>\n255\n", rows top to bottom, RGB bytes
 *   PNG  signature, chunks each with a CRC-32 over type + data, a zlib stream
 *        (header, deflate blocks, Adler-32) of rows each led by a filter byte.
 * The PNG writer promises stored (uncompressed) deflate blocks, so the small
 * inflater below only knows those.
 *
 * sRGB bytes used below, from the sRGB curve 1.055 v^(1/2.4) - 0.055 (12.92 v
 * under 0.0031308), times 255, rounded; every value is at least 0.016 away from
 * a rounding boundary, so float and double arithmetic agree:
 *   0 -> 0, 0.5 -> 188, 1 -> 255, 2 -> 255 (clamped), NaN -> 0, -1 -> 0,
 *   0.25 -> 137, 0.001 -> 3, 0.1 -> 89, 0.75 -> 225, 1e30 and +inf -> 255. */
#include "../appm.c"
#include "check.h"

#if defined(__unix__) || defined(__APPLE__)
#include <sys/stat.h>
#include <unistd.h>
#define HAVE_POSIX 1
#else
#define HAVE_POSIX 0
#endif

/* ---- helpers ------------------------------------------------------------- */

static unsigned char *read_all(const char *path, size_t *len)
{
    FILE *f = fopen(path, "rb");
    unsigned char *buf;
    long n;
    *len = 0;
    if (!f) return NULL;
    fseek(f, 0, SEEK_END);
    n = ftell(f);
    fseek(f, 0, SEEK_SET);
    buf = (unsigned char *)malloc((size_t)n + 1);
    if (buf && fread(buf, 1, (size_t)n, f) != (size_t)n) {
        free(buf);
        buf = NULL;
    }
    fclose(f);
    if (buf) *len = (size_t)n;
    return buf;
}

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

static uint32_t fbits(float v)
{
    uint32_t u;
    memcpy(&u, &v, 4);
    return u;
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
        for (i = 0; i < (size_t)W * H * 3; ++i) same &= fbits(back.rgb[i]) == fbits(px[i]);
        CHECK_MSG(same, "PFM round trip is not bit exact");
        CHECK(back.rgb[0] == -1.5f); /* top-left comes back top-left */
    }
    appm_image_free(NULL, &back);
    CHECK(back.rgb == NULL);
    /* The file itself: header, then the BOTTOM row first, in host order. */
    raw = read_all(path, &len);
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
                uint32_t u = fbits(1.0f + (float)x + 10.0f * (float)y + 0.125f * (float)c);
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
            uint32_t u = fbits(0.5f * (float)x - (float)y);
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
    int blocks;                /* stored deflate blocks */
    unsigned char *raw;        /* the inflated rows (filter byte + RGB) */
    size_t raw_len;
} png_info;

/* Walks the chunks, checks every CRC, joins the IDAT data, checks the zlib
 * header, inflates stored blocks and checks the Adler-32. */
static png_info png_decode(const unsigned char *p, size_t len)
{
    static const unsigned char sig[8] = {137, 80, 78, 71, 13, 10, 26, 10};
    png_info r;
    unsigned char *z = NULL;
    size_t zlen = 0, pos = 8, zp;
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
        } else if (memcmp(type, "IEND", 4) == 0) {
            seen_iend = 1;
            CHECK(n == 0);
            CHECK(pos + 12 == len); /* nothing after IEND */
        }
        pos += 12 + (size_t)n;
    }
    CHECK(seen_ihdr && seen_iend);
    /* zlib: CM = 8 (deflate), window <= 32K, no preset dictionary, check bits */
    CHECK(zlen >= 6);
    if (zlen < 6) {
        free(z);
        return r;
    }
    CHECK((z[0] & 15) == 8 && (z[0] >> 4) <= 7);
    CHECK((z[1] & 0x20) == 0);
    CHECK(((unsigned)z[0] * 256u + z[1]) % 31u == 0);
    r.raw = (unsigned char *)malloc(zlen);
    zp = 2;
    for (;;) {
        unsigned hdr, ln, nln;
        if (zp + 5 > zlen) {
            CHECK_MSG(0, "deflate stream runs past the IDAT data");
            break;
        }
        hdr = z[zp];
        CHECK_MSG(((hdr >> 1) & 3) == 0, "block type %u is not 'stored'", (hdr >> 1) & 3);
        if (((hdr >> 1) & 3) != 0) break;
        ln = z[zp + 1] | (unsigned)z[zp + 2] << 8;
        nln = z[zp + 3] | (unsigned)z[zp + 4] << 8;
        CHECK(nln == (~ln & 0xFFFFu));
        zp += 5;
        if (zp + ln > zlen) {
            CHECK_MSG(0, "stored block runs past the IDAT data");
            break;
        }
        memcpy(r.raw + r.raw_len, z + zp, ln);
        r.raw_len += ln;
        zp += ln;
        r.blocks++;
        if (hdr & 1) break; /* BFINAL */
    }
    CHECK(zp + 4 == zlen); /* the Adler-32 closes the stream */
    if (zp + 4 == zlen) {
        CHECK_MSG(be32(z + zp) == adler32_of(r.raw, r.raw_len), "Adler-32 is wrong");
        r.ok = 1;
    }
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
    static const unsigned char want[2 * 7] = {0, 0, 188, 255, 255, 0, 0, /* filter 0, row 0 */
                                              0, 137, 3, 255, 89, 225, 0};
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
    raw = read_all(path, &len);
    CHECK(raw != NULL);
    if (raw) {
        png_info r = png_decode(raw, len);
        unsigned char want2[sizeof want];
        memcpy(want2, want, sizeof want);
        want2[13] = 255; /* +inf */
        CHECK(r.ok && r.w == 2 && r.h == 2);
        CHECK(r.raw_len == sizeof want);
        CHECK(r.raw_len == sizeof want && memcmp(r.raw, want2, sizeof want) == 0);
        free(r.raw);
        free(raw);
    }
    /* Wide enough that the rows span several 65535-byte stored blocks:
     * 300 rows of 1 + 3 * 200 bytes = 180300 bytes = 3 blocks. */
    {
        enum { W = 200, H = 300 };
        float *big = (float *)malloc(sizeof(float) * W * H * 3);
        unsigned char *expect = (unsigned char *)malloc((size_t)H * (1 + 3 * W));
        float vals[10];
        int x, y, c;
        memcpy(vals, VALS, sizeof vals);
        vals[4] = (float)NAN;
        for (y = 0; y < H; ++y) {
            expect[(size_t)y * (1 + 3 * W)] = 0;
            for (x = 0; x < W; ++x)
                for (c = 0; c < 3; ++c) {
                    int k = (3 * x + c + 7 * y) % 10;
                    big[3 * ((size_t)y * W + x) + c] = vals[k];
                    expect[(size_t)y * (1 + 3 * W) + 1 + 3 * x + c] = BYTES[k];
                }
        }
        img.width = W;
        img.height = H;
        img.rgb = big;
        path = check_path("image", "wide.png");
        CHECK(appm_image_write(path, &img, 1.0, &d) == APPM_OK);
        raw = read_all(path, &len);
        CHECK(raw != NULL);
        if (raw) {
            png_info r = png_decode(raw, len);
            CHECK(r.ok && r.w == W && r.h == H);
            CHECK_MSG(r.blocks == 3, "%d stored blocks", r.blocks);
            CHECK(r.raw_len == (size_t)H * (1 + 3 * W));
            CHECK(r.raw_len == (size_t)H * (1 + 3 * W) && memcmp(r.raw, expect, r.raw_len) == 0);
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
    raw = read_all(path, &len);
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
        raw = read_all(path, &len);
        CHECK(raw && len == strlen(hd) + 12 && memcmp(raw + strlen(hd), want2, 12) == 0);
        free(raw);
        CHECK(appm_image_write(path, &img, 4.0, &d) == APPM_OK);
        raw = read_all(path, &len);
        CHECK(raw && len == strlen(hd) + 12 && memcmp(raw + strlen(hd), want4, 12) == 0);
        free(raw);
        CHECK(appm_image_write(path, &img, 0.0, &d) == APPM_OK);
        raw = read_all(path, &len);
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
    before = read_all(keep, &n1);
    {
        struct stat st;
        if (stat("/dev/full", &st) == 0 && S_ISCHR(st.st_mode) && symlink("/dev/full", tmp) == 0) {
            appm_status s = appm_image_write(keep, &other, 1.0, &d);
            CHECK_MSG(s == APPM_ERR_IO, "write to a full disk returned %d", (int)s);
            CHECK(lstat(tmp, &st) != 0); /* no "<name>.tmp" left behind */
            after = read_all(keep, &n2);
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
    after = read_all(keep, &n2);
    CHECK(before && after && n1 == n2 && memcmp(before, after, n1) == 0);
    free(after);
    rmdir(tmp);
    /* and with the way clear, a write replaces the file */
    CHECK(appm_image_write(keep, &other, 1.0, &d) == APPM_OK);
    after = read_all(keep, &n2);
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

int main(void)
{
    crc_init();
    test_pfm_round_trip();
    test_pfm_big_endian_and_grey();
    test_pfm_malformed();
    test_png();
    test_ppm();
    test_write_failures();
    test_compare();
    return check_finish();
}
