/* tests/t_decode.c - the image decoders of appm.c section 3.4 (PNG, OpenEXR,
 * JPEG, TGA, PGM/PPM, Radiance HDR, and inflate), appm__image_decode and
 * appm_image_read.
 *
 * The fixtures are in tests/images/ (see its README.md for what made them):
 * each X comes with X.expect, "w h channels depth\n" then the samples the file
 * encodes (uint8; uint16 and float32 little-endian, row 0 = top), written from
 * the pixels given to an independent encoder (PIL, ImageMagick, hand-written
 * Python writers) or, for JPEG, decoded by libjpeg-turbo's djpeg.  A PNG/EXR
 * fixture with X.fail instead must be refused with that text in the message.
 *
 *   - every fixture decodes to exactly its samples (floats bit for bit), by its
 *     own decoder and by appm__image_decode (which picks it by magic / .tga);
 *   - every prefix of several files of each format fails cleanly;
 *   - bit flips keep the invariants: a valid status, out->data NULL exactly on
 *     failure, the diag set, only the pixel block left allocated on success,
 *     nothing at all after a failure (the counting allocator of check.h);
 *     the small decoders never allocate beyond what the input could describe;
 *   - allocation k = 1, 2, ... failing gives APPM_ERR_NOMEM, nothing leaked,
 *     until the decode needs no more (for every fixture);
 *   - hand-made refusals with their messages; inflate on zlib streams and on
 *     hand-made deflate blocks;
 *   - appm_image_read: linear RGB from PNG, PGM, TGA (sRGB-decoded), JPEG, EXR,
 *     HDR, PFM; appm_image_write -> appm_image_read round trips.
 * APPM_TEST_QUICK=1 (the sanitizer build) thins out the bit flips, damage
 * rounds and prefixes.  Run from the repository root. */
#include "../appm.c"
#include "check.h"
#include "fuzz/targets.h" /* fuzz__png_fix_crcs */

#define IMG_DIR "tests/images"

static long g_decodes, g_nomem;

/* ---- helpers ---------------------------------------------------------------- */

static int ends_with(const char *s, const char *t)
{
    size_t n = strlen(s), k = strlen(t);
    return n >= k && strcmp(s + n - k, t) == 0;
}

/* tests/images/<set>/<file>, read whole (NUL appended); NULL when missing. */
static unsigned char *read_fixture(const char *set, const char *file, size_t *len)
{
    char path[1024];
    snprintf(path, sizeof path, "%s/%s/%s", IMG_DIR, set, file);
    return check_read_file(path, len);
}

/* An exact-size copy (ASan sees a read one byte past the end). */
static unsigned char *dup_exact(const unsigned char *p, size_t n)
{
    unsigned char *q = (unsigned char *)malloc(n ? n : 1);
    if (q && n) memcpy(q, p, n);
    return q;
}

static uint32_t lcg(uint32_t *s)
{
    *s = *s * 1664525u + 1013904223u;
    return *s;
}

/* The decoder a fixture's extension names. */
static appm__decode_fn decoder_for(const char *name)
{
    if (ends_with(name, ".png")) return appm__png_decode;
    if (ends_with(name, ".exr")) return appm__exr_decode;
    if (ends_with(name, ".jpg")) return appm__jpeg_decode;
    if (ends_with(name, ".tga")) return appm__tga_decode;
    if (ends_with(name, ".pgm") || ends_with(name, ".ppm")) return appm__pnm_decode;
    if (ends_with(name, ".hdr")) return appm__hdr_decode;
    return NULL;
}

/* The small decoders promise a peak allocation bounded by the input's size. */
static int bounded_decoder(appm__decode_fn fn)
{
    return fn == appm__tga_decode || fn == appm__pnm_decode || fn == appm__hdr_decode;
}

/* ---- one decode with the counting allocator ---------------------------------- */

typedef struct dec {
    check_alloc a;
    appm__mem m;
    appm_diag d;
    appm__pixels px;
    appm_status st;
    size_t len;
    const char *name;
} dec;

static void dec_run(dec *r, appm__decode_fn fn, const unsigned char *p, size_t len, const char *name,
                    long fail_at)
{
    appm_config cfg;
    memset(&cfg, 0, sizeof cfg);
    check_use_alloc(&cfg, &r->a, fail_at);
    appm__mem_init(&r->m, &cfg);
    appm__diag_clear(&r->d);
    r->m.diag = &r->d;
    memset(&r->px, 0x55, sizeof r->px); /* the decoder must overwrite it */
    r->len = len;
    r->name = name;
    r->st = fn(&r->m, p, len, name, &r->px, &r->d);
    g_decodes++;
}

static size_t px_bytes(const appm__pixels *px)
{
    return (size_t)px->w * px->h * px->channels * (px->depth / 8);
}

/* The invariants every call must keep; frees the pixels.  Returns 1 if all hold
 * (and prints what broke otherwise).  bounded: peak <= 2048 len + 4096. */
static int dec_settle(dec *r, int bounded)
{
    const char *why = NULL;
    size_t live = r->m.live;
    if (r->st != APPM_OK && r->st != APPM_ERR_PARSE && r->st != APPM_ERR_NOMEM) why = "unexpected status";
    else if ((r->st == APPM_OK) != (r->px.data != NULL)) why = "data not NULL exactly on failure";
    else if (r->st != APPM_OK && (r->d.status != r->st || !r->d.message[0])) why = "diag not set";
    else if (r->st == APPM_ERR_PARSE && strcmp(r->d.file, r->name) != 0) why = "diag names another file";
    else if (r->st == APPM_ERR_NOMEM && !(r->a.fail_at > 0 && r->a.count >= r->a.fail_at))
        why = "out of memory without a failed allocation";
    else if (r->st == APPM_OK) {
        if (r->px.w < 1 || r->px.h < 1 || r->px.w > APPM__IMAGE_MAX || r->px.h > APPM__IMAGE_MAX)
            why = "size out of range";
        else if (r->px.channels < 1 || r->px.channels > 4) why = "channels out of range";
        else if (r->px.depth != 8 && r->px.depth != 16 && r->px.depth != 32) why = "bad depth";
        else if (live != px_bytes(&r->px) + APPM__ALLOC_HEADER) why = "more than the pixels left allocated";
    } else if (live != 0) why = "memory left allocated after a failure";
    if (!why && (long long)live != r->a.live) why = "allocator and memory counter disagree";
    if (!why && bounded && r->m.peak > (size_t)2048 * r->len + 4096) why = "allocated beyond what the input holds";
    if (r->st == APPM_OK && r->px.data) {
        volatile unsigned char sink = 0;
        size_t n = px_bytes(&r->px), i;
        for (i = 0; i < n; i += 97) sink ^= ((const unsigned char *)r->px.data)[i];
        if (n) sink ^= ((const unsigned char *)r->px.data)[n - 1];
        (void)sink;
        appm__free(&r->m, r->px.data);
        r->px.data = NULL;
    }
    if (!why && (r->m.live != 0 || r->a.live != 0)) why = "memory left allocated after freeing the pixels";
    if (why)
        fprintf(stderr, "  %s (%lu bytes): %s: status %d, live %lu, peak %lu, message \"%s\"\n", r->name,
                (unsigned long)r->len, why, (int)r->st, (unsigned long)live, (unsigned long)r->m.peak,
                r->d.message);
    return why == NULL;
}

/* Do the pixels equal X.expect's samples?  why gets the first difference. */
static int same_pixels(const appm__pixels *px, const unsigned char *exp, size_t elen, char *why, size_t whyn)
{
    unsigned w, h, c, d;
    size_t i, n;
    const unsigned char *e = (const unsigned char *)memchr(exp, '\n', elen);
    if (!e || sscanf((const char *)exp, "%u %u %u %u", &w, &h, &c, &d) != 4 || (d != 8 && d != 16 && d != 32)) {
        snprintf(why, whyn, "bad .expect header");
        return 0;
    }
    e++;
    if (px->w != w || px->h != h || px->channels != c || px->depth != d) {
        snprintf(why, whyn, "got %lux%lu c%u d%u, expected %ux%u c%u d%u", (unsigned long)px->w,
                 (unsigned long)px->h, px->channels, px->depth, w, h, c, d);
        return 0;
    }
    n = (size_t)w * h * c;
    if ((size_t)(exp + elen - e) != n * (d / 8)) {
        snprintf(why, whyn, ".expect has the wrong length");
        return 0;
    }
    for (i = 0; i < n; ++i) {
        uint32_t got, want;
        const unsigned char *q = e + i * (d / 8);
        if (d == 8) {
            got = ((const unsigned char *)px->data)[i];
            want = q[0];
        } else if (d == 16) {
            got = ((const uint16_t *)px->data)[i];
            want = (uint32_t)q[0] | (uint32_t)q[1] << 8;
        } else {
            memcpy(&got, (const float *)px->data + i, 4);
            want = (uint32_t)q[0] | (uint32_t)q[1] << 8 | (uint32_t)q[2] << 16 | (uint32_t)q[3] << 24;
        }
        if (got != want) {
            snprintf(why, whyn, "sample %lu (x %lu y %lu c %lu) is 0x%lx, expected 0x%lx", (unsigned long)i,
                     (unsigned long)(i / c % w), (unsigned long)(i / c / w), (unsigned long)(i % c),
                     (unsigned long)got, (unsigned long)want);
            return 0;
        }
    }
    return 1;
}

/* X.expect of fixture X (for a JPEG: base.expect for base.jpg). */
static unsigned char *read_expect(const char *set, const char *file, size_t *len)
{
    char en[512];
    size_t n = strlen(file);
    if (ends_with(file, ".jpg")) snprintf(en, sizeof en, "%.*s.expect", (int)(n - 4), file);
    else snprintf(en, sizeof en, "%s.expect", file);
    return read_fixture(set, en, len);
}

/* ---- fixtures ------------------------------------------------------------------ */

/* A fixture: exact samples through its decoder and through appm__image_decode
 * (or, with X.fail, the refusal), then allocation failure k = 1, 2, ... */
static void test_fixture(const char *set, const char *file)
{
    size_t len = 0, elen = 0, flen = 0;
    unsigned char *p = read_fixture(set, file, &len), *exp = NULL, *fail_text, *buf;
    appm__decode_fn fn = decoder_for(file);
    char fn_name[512], why[256];
    dec r;
    int pass, bad;
    long k;
    CHECK_MSG(p != NULL && fn != NULL, "%s/%s: cannot read the fixture", set, file);
    if (!p || !fn) {
        free(p);
        return;
    }
    buf = dup_exact(p, len);
    snprintf(fn_name, sizeof fn_name, "%s.fail", file);
    fail_text = read_fixture(set, fn_name, &flen);
    if (!fail_text) {
        exp = read_expect(set, file, &elen);
        CHECK_MSG(exp != NULL, "%s/%s: no .expect", set, file);
    }
    for (pass = 0; pass < 2; ++pass) { /* 0: its decoder; 1: appm__image_decode */
        const char *via = pass ? "appm__image_decode" : "its decoder";
        dec_run(&r, pass ? appm__image_decode : fn, buf, len, file, 0);
        if (fail_text) {
            CHECK_MSG(r.st == APPM_ERR_PARSE && strstr(r.d.message, (const char *)fail_text),
                      "%s through %s: expected a refusal with \"%s\", got status %d \"%s\"", file, via,
                      (const char *)fail_text, (int)r.st, r.d.message);
            CHECK_MSG(strncmp(r.d.message, ends_with(file, ".png") ? "PNG: " : "EXR: ", 5) == 0, "%s: \"%s\"",
                      file, r.d.message);
        } else if (exp) {
            why[0] = 0;
            CHECK_MSG(r.st == APPM_OK && same_pixels(&r.px, exp, elen, why, sizeof why),
                      "%s through %s: status %d (%s) %s", file, via, (int)r.st, r.d.message, why);
        }
        CHECK_MSG(dec_settle(&r, bounded_decoder(fn)), "%s through %s: invariants", file, via);
    }
    /* allocation failure at each allocation in turn, until the decode succeeds */
    bad = 0;
    for (k = 1; k < 40; ++k) {
        dec_run(&r, fn, buf, len, file, k);
        if (r.a.count < k) { /* needed fewer than k allocations: the normal result */
            why[0] = 0;
            if (fail_text ? r.st != APPM_ERR_PARSE : (r.st != APPM_OK || !exp || !same_pixels(&r.px, exp, elen, why, sizeof why)))
                bad++;
            if (!dec_settle(&r, bounded_decoder(fn))) bad++;
            break;
        }
        g_nomem++;
        if (r.st != APPM_ERR_NOMEM || r.px.data != NULL) {
            fprintf(stderr, "  %s: allocation %ld failed, status %d \"%s\"\n", file, k, (int)r.st, r.d.message);
            bad++;
        }
        if (!dec_settle(&r, bounded_decoder(fn))) bad++;
    }
    CHECK_MSG(bad == 0 && k < 40 && (fail_text || k > 1), "%s: allocation failures (k %ld, %d bad)", file, k, bad);
    free(buf);
    free(p);
    free(exp);
    free(fail_text);
}

/* Prefixes of a fixture shorter than this may be refused; longer ones may
 * still hold a whole image: a TGA 2.0 footer cut off, a plain PNM whose last
 * number lost digits (indistinguishable from a valid file). */
static size_t must_fail_below(const char *name, const unsigned char *p, size_t len)
{
    static const char footer[] = "TRUEVISION-XFILE.";
    size_t k;
    if (ends_with(name, ".tga") && len >= 26 && memcmp(p + len - 18, footer, 18) == 0) return len - 26;
    if ((ends_with(name, ".pgm") || ends_with(name, ".ppm")) && len > 2 && (p[1] == '2' || p[1] == '3')) {
        k = len;
        while (k > 0 && appm__pnm_space(p[k - 1])) k--;
        while (k > 0 && p[k - 1] >= '0' && p[k - 1] <= '9') k--;
        return k + 1; /* the last number's first digit alone is a valid file */
    }
    return len;
}

/* Every prefix (every step-th in quick mode) is refused with APPM_ERR_PARSE,
 * each one copied to a buffer of exactly its size. */
static void test_prefixes(const char *set, const char *file, size_t step)
{
    size_t len = 0, n, limit;
    unsigned char *p = read_fixture(set, file, &len);
    appm__decode_fn fn = decoder_for(file);
    int bad = 0;
    CHECK_MSG(p != NULL && fn != NULL, "%s/%s: cannot read the fixture", set, file);
    if (!p || !fn) {
        free(p);
        return;
    }
    limit = must_fail_below(file, p, len);
    for (n = 0; n < len; n += step) {
        unsigned char *q = dup_exact(p, n);
        dec r;
        dec_run(&r, fn, q, n, file, 0);
        if (n < limit && r.st != APPM_ERR_PARSE) {
            if (!bad) fprintf(stderr, "  %s: prefix of %lu bytes: status %d \"%s\"\n", file, (unsigned long)n,
                              (int)r.st, r.d.message);
            bad++;
        }
        if (!dec_settle(&r, bounded_decoder(fn))) bad++;
        free(q);
    }
    CHECK_MSG(bad == 0, "%s: %d bad prefixes", file, bad);
    free(p);
}

/* Single-bit flips: every step-th bit (step 1: all).  must_refuse: each one is
 * refused (a PNG: the CRCs see it).  Returns how many decoded. */
static long test_bit_flips(const char *set, const char *file, size_t step, int must_refuse)
{
    size_t len = 0, bit;
    unsigned char *p = read_fixture(set, file, &len), *buf;
    appm__decode_fn fn = decoder_for(file);
    int bad = 0, unrefused = 0;
    long ok = 0;
    CHECK_MSG(p != NULL && fn != NULL, "%s/%s: cannot read the fixture", set, file);
    if (!p || !fn) {
        free(p);
        return 0;
    }
    buf = dup_exact(p, len);
    for (bit = 0; bit < 8 * len; bit += step) {
        dec r;
        buf[bit / 8] ^= (unsigned char)(1u << (bit % 8));
        dec_run(&r, fn, buf, len, file, 0);
        buf[bit / 8] ^= (unsigned char)(1u << (bit % 8));
        if (r.st == APPM_OK) ok++;
        if (must_refuse && r.st != APPM_ERR_PARSE) unrefused++;
        if (!dec_settle(&r, bounded_decoder(fn))) bad++;
    }
    CHECK_MSG(bad == 0, "%s: %d bit flips broke the invariants", file, bad);
    CHECK_MSG(unrefused == 0, "%s: %d bit flips not refused", file, unrefused);
    free(buf);
    free(p);
    return ok;
}

/* rounds random multi-bit damages (1..8 bits, after the first `keep` bytes);
 * a PNG gets its CRCs recomputed.  The invariants must hold; some damage must
 * be refused. */
static void test_damage_file(const char *set, const char *file, int rounds, size_t keep, uint32_t seed)
{
    size_t len = 0;
    unsigned char *p = read_fixture(set, file, &len), *q;
    appm__decode_fn fn = decoder_for(file);
    int k, bad = 0, refused = 0;
    uint32_t s = seed;
    CHECK_MSG(p != NULL && fn != NULL && len > keep, "%s/%s: cannot read the fixture", set, file);
    if (!p || !fn || len <= keep) {
        free(p);
        return;
    }
    q = dup_exact(p, len);
    for (k = 0; k < rounds; ++k) {
        dec r;
        int j, flips = 1 + (int)(lcg(&s) >> 29);
        memcpy(q, p, len);
        for (j = 0; j < flips; ++j) {
            uint32_t v = lcg(&s);
            q[keep + (v >> 8) % (len - keep)] ^= (unsigned char)(1u << (v & 7u));
        }
        if (fn == appm__png_decode) fuzz__png_fix_crcs(q, len);
        dec_run(&r, fn, q, len, file, 0);
        if (r.st != APPM_OK) refused++;
        if (!dec_settle(&r, bounded_decoder(fn))) bad++;
    }
    CHECK_MSG(bad == 0, "%s: %d damaged copies broke the invariants", file, bad);
    CHECK_MSG(refused > 0, "%s: no damage refused", file);
    free(q);
    free(p);
}

/* Every name in a list file (one a line); the fixture loop of a set. */
static int for_each_listed(const char *set, const char *list, const char *ext, int with_flips, int quick)
{
    size_t len = 0;
    char *text = (char *)read_fixture(set, list, &len), *line, *next;
    int count = 0;
    CHECK_MSG(text != NULL, "%s/%s/%s missing (run from the repository root)", IMG_DIR, set, list);
    if (!text) return 0;
    for (line = text; *line; line = next) {
        char file[256];
        next = strchr(line, '\n');
        if (next) *next++ = 0;
        else next = line + strlen(line);
        if (line[0] == 0 || line[0] == '\r') continue;
        snprintf(file, sizeof file, "%s%s", line, ext);
        if (ends_with(file, ".zz")) continue; /* zlib streams: test_inflate_fixture */
        test_fixture(set, file);
        if (with_flips == 1) { /* JPEG: random multi-bit damage, whole file after SOI */
            test_damage_file(set, file, quick ? 100 : 300, 2, (uint32_t)count * 2654435761u + 1u);
        } else if (with_flips == 2) { /* small: every prefix and every bit */
            test_prefixes(set, file, quick ? 3 : 1);
            test_bit_flips(set, file, quick ? 4 : 1, 0);
        }
        count++;
    }
    free(text);
    return count;
}

/* ---- inflate ---------------------------------------------------------------------- */

/* The same data as make_png.py's zdata(). */
static unsigned char *zdata(size_t n)
{
    static const char *const words[8] = {"red ", "green ", "blue ", "photon ", "map\n", "kd-tree ", "splat ", "x"};
    unsigned char *out = (unsigned char *)malloc(n + 40000);
    size_t len = 0;
    uint32_t x = 1;
    while (out && len < n) {
        x = (x * 1103515245u + 12345u) & 0x7FFFFFFFu;
        if (len % 40000 < 8 && len >= 8) {
            unsigned char noise[256];
            uint32_t y = (uint32_t)(len / 40000 + 7);
            int i;
            for (i = 0; i < 256; ++i) {
                y = (y * 1103515245u + 12345u) & 0x7FFFFFFFu;
                noise[i] = (unsigned char)(y >> 16);
            }
            memcpy(out + len, noise, 256);
            memset(out + len + 256, '.', 32000 - 256);
            memcpy(out + len + 32000, noise, 256);
            len += 32256;
            continue;
        }
        {
            const char *w = words[((x >> 24) & 15u) == 0 ? (x >> 16) & 7u : (x >> 16) & 1u];
            memcpy(out + len, w, strlen(w));
            len += strlen(w);
        }
    }
    return out;
}

/* A python zlib stream z_<how>_<size>.zz: inflates to zdata(size); one byte
 * short or long fails; every truncation (every step-th) fails. */
static void test_inflate_fixture(const char *file, size_t step)
{
    size_t n = 0, want, k;
    unsigned char *z = read_fixture("png", file, &n), *dst, *ref, *cut;
    const char *us = strrchr(file, '_'), *err;
    int ok = 1;
    want = us ? (size_t)strtoul(us + 1, NULL, 10) : 0;
    CHECK_MSG(z != NULL, "%s missing", file);
    if (!z) return;
    ref = zdata(want);
    dst = (unsigned char *)malloc(want + 1);
    err = appm__zlib_inflate(z, n, dst, want);
    CHECK_MSG(err == NULL, "%s: %s", file, err);
    CHECK_MSG(err || memcmp(dst, ref, want) == 0, "%s: wrong bytes", file);
    if (want > 0) CHECK(appm__zlib_inflate(z, n, dst, want - 1) != NULL);
    err = appm__zlib_inflate(z, n, dst, want + 1);
    CHECK_MSG(err && strstr(err, "ends early"), "%s want+1: %s", file, err ? err : "(ok)");
    for (k = 0; k < n; k += step) {
        cut = dup_exact(z, k);
        if (appm__zlib_inflate(cut, k, dst, want) == NULL) ok = 0;
        free(cut);
    }
    CHECK_MSG(ok, "%s: a truncated stream inflated", file);
    free(z);
    free(ref);
    free(dst);
}

/* A bit writer for hand-made streams: deflate packs fields LSB first and
 * Huffman codes MSB first (RFC 1951, 3.1.1). */
typedef struct bw {
    unsigned char b[70000 + 64];
    size_t n;
    unsigned bit;
} bw;

static void bw_put(bw *w, unsigned v, unsigned n)
{
    unsigned i;
    for (i = 0; i < n; ++i) {
        if (w->bit == 0) w->b[w->n++] = 0;
        w->b[w->n - 1] |= (unsigned char)(((v >> i) & 1u) << w->bit);
        w->bit = (w->bit + 1) & 7u;
    }
}

static void bw_code(bw *w, unsigned code, unsigned n)
{
    while (n--) bw_put(w, (code >> n) & 1u, 1);
}

static void bw_adler(bw *w, const unsigned char *p, size_t n)
{
    uint32_t a = 1, b = 0, s;
    size_t i;
    for (i = 0; i < n; ++i) {
        a = (a + p[i]) % 65521u;
        b = (b + a) % 65521u;
    }
    s = b << 16 | a;
    w->bit = 0;
    w->b[w->n++] = (unsigned char)(s >> 24);
    w->b[w->n++] = (unsigned char)(s >> 16);
    w->b[w->n++] = (unsigned char)(s >> 8);
    w->b[w->n++] = (unsigned char)s;
}

static void bw_start(bw *w)
{
    memset(w, 0, sizeof *w);
    w->b[0] = 0x78;
    w->b[1] = 0x01;
    w->n = 2;
}

static void test_inflate_handmade(void)
{
    static bw w;
    static unsigned char out[70000];
    unsigned char *ref = zdata(70000);
    const char *err;
    size_t at;
    /* stored blocks: a > 64 KiB stream needs two of them (LEN is 16 bits) */
    bw_start(&w);
    for (at = 0; at < 70000;) {
        size_t k = 70000 - at < 65535 ? 70000 - at : 65535;
        bw_put(&w, at + k == 70000, 1);
        bw_put(&w, 0, 2);
        w.bit = 0;
        bw_put(&w, (unsigned)k, 16);
        bw_put(&w, (unsigned)k ^ 0xFFFFu, 16);
        memcpy(w.b + w.n, ref + at, k);
        w.n += k;
        at += k;
    }
    bw_adler(&w, ref, 70000);
    err = appm__zlib_inflate(w.b, w.n, out, 70000);
    CHECK_MSG(err == NULL && memcmp(out, ref, 70000) == 0, "stored 70000: %s", err ? err : "wrong bytes");
    w.b[w.n - 1] ^= 1;
    err = appm__zlib_inflate(w.b, w.n, out, 70000);
    CHECK_MSG(err && strstr(err, "Adler"), "Adler: %s", err ? err : "(ok)");
    w.b[2 + 3] ^= 1; /* NLEN no longer the complement of LEN */
    err = appm__zlib_inflate(w.b, w.n, out, 70000);
    CHECK_MSG(err && strstr(err, "stored"), "NLEN: %s", err ? err : "(ok)");

    /* fixed block: literal 'A', then length 3 distance 2 - one too far back */
    bw_start(&w);
    bw_put(&w, 1, 1);
    bw_put(&w, 1, 2);
    bw_code(&w, 0x30 + 'A', 8); /* literals 0..143: 8-bit codes from 00110000 */
    bw_code(&w, 1, 7);           /* 257 (length 3): 7-bit code 0000001 */
    bw_code(&w, 1, 5);           /* distance code 1: distance 2 */
    bw_code(&w, 0, 7);           /* end of block */
    bw_adler(&w, (const unsigned char *)"AAAA", 4);
    err = appm__zlib_inflate(w.b, w.n, out, 4);
    CHECK_MSG(err && strstr(err, "too far back"), "far: %s", err ? err : "(ok)");
    /* the same with distance 1 is a run: "AAAA" */
    bw_start(&w);
    bw_put(&w, 1, 1);
    bw_put(&w, 1, 2);
    bw_code(&w, 0x30 + 'A', 8);
    bw_code(&w, 1, 7);
    bw_code(&w, 0, 5);
    bw_code(&w, 0, 7);
    bw_adler(&w, (const unsigned char *)"AAAA", 4);
    err = appm__zlib_inflate(w.b, w.n, out, 4);
    CHECK_MSG(err == NULL && memcmp(out, "AAAA", 4) == 0, "run: %s", err ? err : "wrong bytes");
    err = appm__zlib_inflate(w.b, w.n, out, 3);
    CHECK_MSG(err && strstr(err, "more data than expected"), "short dst: %s", err ? err : "(ok)");
    err = appm__zlib_inflate(w.b, w.n, out, 5);
    CHECK_MSG(err && strstr(err, "ends early"), "long dst: %s", err ? err : "(ok)");

    /* block type 3 is reserved */
    bw_start(&w);
    bw_put(&w, 1, 1);
    bw_put(&w, 3, 2);
    bw_put(&w, 0, 16);
    err = appm__zlib_inflate(w.b, w.n, out, 1);
    CHECK_MSG(err && strstr(err, "block type"), "type 3: %s", err ? err : "(ok)");
    /* headers */
    {
        static const unsigned char dict[] = {0x78, 0xBB, 0, 0, 0, 1}, cm[] = {0x79, 0x9C, 3, 0, 0, 0, 0, 1},
                                   chk[] = {0x78, 0x9D, 3, 0, 0, 0, 0, 1}, ok[] = {0x78, 0x9C, 3, 0, 0, 0, 0, 1};
        CHECK(appm__zlib_inflate(ok, sizeof ok, out, 0) == NULL); /* zlib.compress(b"") */
        err = appm__zlib_inflate(dict, sizeof dict, out, 0);
        CHECK_MSG(err && strstr(err, "dictionary"), "dict: %s", err ? err : "(ok)");
        err = appm__zlib_inflate(cm, sizeof cm, out, 0);
        CHECK_MSG(err && strstr(err, "bad header"), "CM: %s", err ? err : "(ok)");
        err = appm__zlib_inflate(chk, sizeof chk, out, 0);
        CHECK_MSG(err && strstr(err, "bad header"), "FCHECK: %s", err ? err : "(ok)");
    }
    free(ref);
}

/* ---- hand-made refusals ----------------------------------------------------------- */

/* Decodes (s, n) with fn, expecting status want and, for a failure, msg within
 * the message; a refusal whose message says "cannot" allocated nothing. */
static void expect_line(appm__decode_fn fn, const char *name, const void *s, size_t n, appm_status want,
                        const char *msg, int line)
{
    dec r;
    unsigned char *q = dup_exact((const unsigned char *)s, n);
    dec_run(&r, fn, q, n, name, 0);
    if (r.st == want && (want == APPM_OK || strstr(r.d.message, msg))) g_pass++;
    else {
        g_fail++;
        fprintf(stderr, "%s:%d: %s: status %d \"%s\", expected %d \"%s\"\n", __FILE__, line, name, (int)r.st,
                r.d.message, (int)want, msg);
    }
    CHECK_MSG(want == APPM_OK || r.m.peak == 0 || !strstr(msg, "cannot"), "line %d allocated %lu", line,
              (unsigned long)r.m.peak);
    CHECK_MSG(dec_settle(&r, bounded_decoder(fn)), "line %d: invariants", line);
    free(q);
}
#define EXPECT(fn, lit, want, msg) expect_line(fn, "test", lit, sizeof(lit) - 1, want, msg, __LINE__)
#define BAD(fn, lit, msg) EXPECT(fn, lit, APPM_ERR_PARSE, msg)

/* Decodes a literal that must succeed; the caller checks r->px, then settles. */
#define DECODE_OK(fn, lit, r) decode_ok(fn, lit, sizeof(lit) - 1, r, __LINE__)
static int decode_ok(appm__decode_fn fn, const char *s, size_t n, dec *r, int line)
{
    dec_run(r, fn, (const unsigned char *)s, n, "test", 0);
    CHECK_MSG(r->st == APPM_OK, "line %d: %s", line, r->d.message);
    return r->st == APPM_OK;
}

static void test_tga_refusals(void)
{
    appm__decode_fn T = appm__tga_decode;
    dec r;
    /* 18-byte header: id, cmtype, type, cmfirst(2), cmlen(2), cmbits, x(2), y(2), w(2), h(2), bits, desc */
    BAD(T, "", "shorter than the 18-byte header");
    BAD(T, "\0\0\2\0\0\0\0\0\0\0\0\0\1\0\1\0\30", "shorter than");
    BAD(T, "\0\0\0\0\0\0\0\0\0\0\0\0\1\0\1\0\30\0", "image type 0");
    BAD(T, "\0\0\40\0\0\0\0\0\0\0\0\0\1\0\1\0\30\0", "image type 32");
    BAD(T, "\0\2\2\0\0\0\0\0\0\0\0\0\1\0\1\0\30\0", "colour-map type 2");
    BAD(T, "\0\0\1\0\0\0\0\0\0\0\0\0\1\0\1\0\10\0", "has no colour map");
    BAD(T, "\0\0\2\0\0\0\0\0\0\0\0\0\0\0\1\0\30\0", "outside 1..32768");
    BAD(T, "\0\0\2\0\0\0\0\0\0\0\0\0\1\200\1\0\30\0", "outside 1..32768");
    BAD(T, "\0\0\2\0\0\0\0\0\0\0\0\0\1\0\1\0\21\0", "true-colour pixels of 17 bits");
    BAD(T, "\0\0\3\0\0\0\0\0\0\0\0\0\1\0\1\0\20\0", "grey pixels of 16 bits");
    BAD(T, "\0\0\2\0\0\0\0\0\0\0\0\0\1\0\1\0\30\100", "interleaved");
    BAD(T, "\0\1\1\0\0\0\0\30\0\0\0\0\1\0\1\0\10\0", "colour map is empty");
    BAD(T, "\0\1\1\0\0\1\0\14\0\0\0\0\1\0\1\0\10\0", "entries of 12 bits");
    BAD(T, "\0\1\1\0\0\1\0\30\0\0\0\0\1\0\1\0\4\0\1\2\3\0", "indices of 4 bits");
    BAD(T, "\0\1\1\0\0\2\0\30\0\0\0\0\1\0\1\0\10\0\1\2\3", "inside the image ID or colour map");
    BAD(T, "\5\0\2\0\0\0\0\0\0\0\0\0\1\0\1\0\30\0abcd", "inside the image ID");
    BAD(T, "\0\0\2\0\0\0\0\0\0\0\0\0\2\0\1\0\30\0\1\2\3\4\5", "truncated");
    /* index 3 with first entry 1 and two entries: 1..2 */
    BAD(T, "\0\1\1\1\0\2\0\30\0\0\0\0\1\0\1\0\10\0\1\2\3\4\5\6\3", "colour index 3 is outside");
    BAD(T, "\0\1\1\1\0\2\0\30\0\0\0\0\1\0\1\0\10\0\1\2\3\4\5\6\0", "colour index 0 is outside");
    BAD(T, "\0\0\12\0\0\0\0\0\0\0\0\0\2\0\1\0\30\0\202\1\2\3", "runs past the end");
    BAD(T, "\0\0\12\0\0\0\0\0\0\0\0\0\2\0\1\0\30\0\1\1\2\3", "ends after 0 of 2");
    BAD(T, "\0\0\12\0\0\0\0\0\0\0\0\0\2\0\1\0\30\0\200\1\2\3", "ends after 1 of 2");
    /* 32768 x 32768 from a few bytes: refused before allocating */
    BAD(T, "\0\0\13\0\0\0\0\0\0\0\0\0\0\200\0\200\10\0\377\0", "cannot hold");
    BAD(T, "\0\0\3\0\0\0\0\0\0\0\0\0\0\200\0\200\10\0\377\0", "truncated");
    /* a run may cross a row: a 2x2 grey bottom-up image, a run of 3 then a literal */
    if (DECODE_OK(T, "\0\0\13\0\0\0\0\0\0\0\0\0\2\0\2\0\10\0\202\7\0\11", &r)) {
        const unsigned char *d = (const unsigned char *)r.px.data;
        CHECK(r.px.channels == 1 && d[0] == 7 && d[1] == 9 && d[2] == 7 && d[3] == 7);
    }
    CHECK(dec_settle(&r, 1));
    /* 16-bit pixel 0x7FFF with no attribute bits: white, 3 channels; with 1: alpha 0 */
    if (DECODE_OK(T, "\0\0\2\0\0\0\0\0\0\0\0\0\1\0\1\0\20\0\377\177", &r)) {
        const unsigned char *d = (const unsigned char *)r.px.data;
        CHECK(r.px.channels == 3 && d[0] == 255 && d[1] == 255 && d[2] == 255);
    }
    CHECK(dec_settle(&r, 1));
    if (DECODE_OK(T, "\0\0\2\0\0\0\0\0\0\0\0\0\1\0\1\0\20\1\020\102", &r)) {
        const unsigned char *d = (const unsigned char *)r.px.data;
        /* 0x4210: r 16 g 16 b 16 -> 132, alpha bit clear -> 0 */
        CHECK(r.px.channels == 4 && d[0] == 132 && d[1] == 132 && d[2] == 132 && d[3] == 0);
    }
    CHECK(dec_settle(&r, 1));
}

static void test_pnm_refusals(void)
{
    appm__decode_fn P = appm__pnm_decode;
    dec r;
    BAD(P, "", "not a PGM/PPM");
    BAD(P, "P1\n1 1\n1\n", "not a PGM/PPM");
    BAD(P, "P4\n1 1\n\0", "not a PGM/PPM");
    BAD(P, "P7\nWIDTH 1\n", "not a PGM/PPM");
    BAD(P, "P6", "file ends before the width");
    BAD(P, "P61 1 255\n\0\0\0", "no whitespace before the width");
    BAD(P, "P5 1", "file ends before the height");
    BAD(P, "P5 1x1 255\n\0", "width is not a decimal number");
    BAD(P, "P5 1 1x 255\n\0", "height is not a decimal number");
    BAD(P, "P5 -1 1 255\n\0", "width is not a decimal number");
    BAD(P, "P5 0 1 255\n\0", "outside 1..32768");
    BAD(P, "P5 32769 1 255\n\0", "outside 1..32768");
    BAD(P, "P5 99999999999999999999 1 255\n\0", "outside 1..32768");
    BAD(P, "P5 1 1 0\n\0", "maxval 0 is outside");
    BAD(P, "P5 1 1 65536\n\0\0", "maxval 65536 is outside");
    BAD(P, "P5 1 1 255", "ends before the pixel data");
    BAD(P, "P5 1 1 255\n", "truncated");
    BAD(P, "P5 2 1 65535\n\0\0\0", "truncated");
    BAD(P, "P5 1 1 15\n\20", "sample 0 is 16, above maxval 15");
    BAD(P, "P5 1 1 1000\n\3\351", "above maxval 1000");
    BAD(P, "P2 2 1 15\n3 16\n", "sample 1 is 16, above maxval 15");
    BAD(P, "P2 2 1 15\n3 1x\n", "sample 1 is not a decimal number");
    BAD(P, "P2 2 1 15\n3 -1\n", "sample 1 is not a decimal number");
    BAD(P, "P2 3 1 15\n3 1  ", "ends after 2 of 3 samples");
    BAD(P, "P2 3 1 15\n3 1", "truncated");
    BAD(P, "P3 1 1 15\n3 1         ", "ends after 2 of 3 samples");
    BAD(P, "P5 32768 32768 255\n\0\0\0\0", "truncated");
    BAD(P, "P2 32768 32768 255\n0 0 0 0 0", "truncated");
    /* exactly one whitespace byte after maxval: the raster here is "\n\5" */
    if (DECODE_OK(P, "P5 2 1 255\n\n\5", &r))
        CHECK(((unsigned char *)r.px.data)[0] == 10 && ((unsigned char *)r.px.data)[1] == 5);
    CHECK(dec_settle(&r, 1));
    /* maxval 1 -> 0, 255; comments in the raster */
    if (DECODE_OK(P, "P2 2 1 1\n1 #x\n 0", &r))
        CHECK(((unsigned char *)r.px.data)[0] == 255 && ((unsigned char *)r.px.data)[1] == 0);
    CHECK(dec_settle(&r, 1));
    /* maxval 256 (depth 16): 128 -> 32768, 256 -> 65535 */
    if (DECODE_OK(P, "P5 2 1 256\n\0\200\1\0", &r))
        CHECK(r.px.depth == 16 && ((uint16_t *)r.px.data)[0] == 32768 && ((uint16_t *)r.px.data)[1] == 65535);
    CHECK(dec_settle(&r, 1));
    /* 65534: the largest product the scaling forms */
    if (DECODE_OK(P, "P5 1 1 65534\n\377\376", &r)) CHECK(((uint16_t *)r.px.data)[0] == 65535);
    CHECK(dec_settle(&r, 1));
    /* a second image after the first is ignored */
    EXPECT(P, "P5 1 1 255\n\7P5 1 1 255\n\7", APPM_OK, "");
}

static void test_hdr_refusals(void)
{
    appm__decode_fn H = appm__hdr_decode;
    dec r;
    BAD(H, "", "not a Radiance picture");
    BAD(H, "#?RADIANCEX\n\n-Y 1 +X 1\n\1\2\3\4", "not a Radiance picture");
    BAD(H, "P6\n", "not a Radiance picture");
    BAD(H, "#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n", "ends inside the header");
    BAD(H, "#?RADIANCE\nFORMAT=32-bit_rle_xyze\n\n-Y 1 +X 1\n\1\2\3\4", "XYZE");
    BAD(H, "#?RADIANCE\nFORMAT=24-bit\n\n-Y 1 +X 1\n\1\2\3\4", "unknown FORMAT");
    BAD(H, "#?RADIANCE\n\n-Y 1 +X 1", "before the resolution line");
    BAD(H, "#?RADIANCE\n\n-Y 1 -X 1\n\1\2\3\4", "orientation \"-Y .. -X ..\"");
    BAD(H, "#?RADIANCE\n\n+X 1 +Y 1\n\1\2\3\4", "orientation \"+X .. +Y ..\"");
    BAD(H, "#?RADIANCE\n\n-Y 0 +X 1\n\1\2\3\4", "malformed resolution");
    BAD(H, "#?RADIANCE\n\n-Y 32769 +X 1\n\1\2\3\4", "malformed resolution");
    BAD(H, "#?RADIANCE\n\n-Y 1 +X 1 2\n\1\2\3\4", "malformed resolution");
    BAD(H, "#?RADIANCE\n\n-Y1 +X 1\n\1\2\3\4", "malformed resolution");
    BAD(H, "#?RADIANCE\n\n-Y 2 +X 1\n\1\2\3\4", "cannot hold");
    BAD(H, "#?RADIANCE\n\n-Y 32768 +X 32768\n\2\2\200\0\0\0\0\0\0\0\0\0", "cannot hold");
    BAD(H, "#?RADIANCE\n\n-Y 1 +X 2\n\1\2\3\4\5\6\7", "ends inside a scanline");
    BAD(H, "#?RADIANCE\n\n-Y 1 +X 8\n\2\2\0\11", "length does not match");
    BAD(H, "#?RADIANCE\n\n-Y 1 +X 8\n\2\2\0\10\0", "length 0");
    BAD(H, "#?RADIANCE\n\n-Y 1 +X 8\n\2\2\0\10\211\1", "run goes past");
    BAD(H, "#?RADIANCE\n\n-Y 1 +X 8\n\2\2\0\10\11\1", "literal goes past");
    BAD(H, "#?RADIANCE\n\n-Y 1 +X 8\n\2\2\0\10\210", "ends inside an RLE scanline");
    BAD(H, "#?RADIANCE\n\n-Y 1 +X 8\n\2\2\0\10\210\1\210\1\210\1\210", "ends inside an RLE scanline");
    BAD(H, "#?RADIANCE\n\n-Y 1 +X 2\n\1\1\1\1\5\5\5\5", "no pixel before it");
    BAD(H, "#?RADIANCE\n\n-Y 1 +X 2\n\5\5\5\5\1\1\1\2", "goes past the end");
    BAD(H, "#?RADIANCE\n\n-Y 1 +X 300\n\5\5\5\5\1\1\1\0\1\1\1\0\1\1\1\0\1\1\1\0\1\1\1\1", "goes past the end");
    /* RGBE convention: (m + 0.5) * 2^(e - 136); e == 0 is black whatever m is */
    if (DECODE_OK(H, "#?RADIANCE\n\n-Y 1 +X 2\n\200\100\0\201\377\377\377\0", &r)) {
        const float *f = (const float *)r.px.data;
        CHECK(f[0] == 128.5f / 128.0f && f[1] == 64.5f / 128.0f && f[2] == 0.5f / 128.0f);
        CHECK(f[3] == 0.0f && f[4] == 0.0f && f[5] == 0.0f);
    }
    CHECK(dec_settle(&r, 1));
    /* extremes: e = 1 (a subnormal float) and e = 255 */
    if (DECODE_OK(H, "#?RADIANCE\n\n-Y 1 +X 1\n\377\0\0\1", &r))
        CHECK(((float *)r.px.data)[0] == (float)ldexp(255.5, -135) && ((float *)r.px.data)[0] > 0);
    CHECK(dec_settle(&r, 1));
    if (DECODE_OK(H, "#?RADIANCE\n\n-Y 1 +X 1\n\377\0\0\377", &r))
        CHECK(((float *)r.px.data)[0] == (float)ldexp(255.5, 119));
    CHECK(dec_settle(&r, 1));
    /* old RLE: zero-length repeats and a repeat straight after a repeat (shift 8) */
    EXPECT(H, "#?RADIANCE\n\n-Y 1 +X 257\n\5\5\5\5\1\1\1\0\1\1\1\1", APPM_OK, "");
    /* new RLE only for 8 <= w <= 32767: at w = 7 these bytes are flat pixels */
    EXPECT(H, "#?RADIANCE\n\n-Y 1 +X 7\n\2\2\0\7\2\2\0\7\2\2\0\7\2\2\0\7\2\2\0\7\2\2\0\7\2\2\0\7", APPM_OK, "");
    /* trailing blanks in the magic and resolution lines are fine; EXPOSURE ignored */
    EXPECT(H, "#?RGBE  \nEXPOSURE=0.5\n\n-Y 1  +X 1 \n\1\2\3\4", APPM_OK, "");
}

/* A JPEG refusal: APPM_ERR_PARSE, "JPEG: " and `want` in the message. */
static void jpeg_refused(const unsigned char *p, size_t len, const char *want, const char *what)
{
    dec r;
    unsigned char *q = dup_exact(p, len);
    dec_run(&r, appm__jpeg_decode, q, len, "t.jpg", 0);
    CHECK_MSG(r.st == APPM_ERR_PARSE && strstr(r.d.message, want) && strncmp(r.d.message, "JPEG: ", 6) == 0,
              "%s: status %d, message '%s', wanted '%s'", what, (int)r.st, r.d.message, want);
    CHECK_MSG(dec_settle(&r, 0), "%s: invariants", what);
    free(q);
}

/* Offset of marker 0xFF mk in a JPEG header (before the first SOS), or -1. */
static size_t find_marker(const unsigned char *p, size_t len, int mk)
{
    size_t i = 2;
    while (i + 4 <= len && p[i] == 0xFF) {
        if (p[i + 1] == mk) return i;
        if (p[i + 1] == 0xDA) break;
        i += 2 + appm__jpeg_u16(p + i + 2);
    }
    return (size_t)-1;
}

/* A copy of p without the segment at offset `at`. */
static unsigned char *cut_segment(const unsigned char *p, size_t len, size_t at, size_t *outlen)
{
    size_t n = 2 + appm__jpeg_u16(p + at + 2);
    unsigned char *q = (unsigned char *)malloc(len);
    memcpy(q, p, at);
    memcpy(q + at, p + at + n, len - at - n);
    *outlen = len - n;
    return q;
}

static void test_jpeg_refusals(void)
{
    size_t len = 0, len2, at;
    unsigned char *base = read_fixture("jpeg", "c33_420_q75.jpg", &len), *q;
    static const unsigned char four[] = {0xFF, 0xD8, 0xFF, 0xC0, 0, 20, 8, 0, 8, 0, 8, 4, 1, 0x11, 0, 2, 0x11, 0,
                                         3, 0x11, 0, 4, 0x11, 0, 0xFF, 0xD9};
    static const unsigned char two[] = {0xFF, 0xD8, 0xFF, 0xC0, 0, 14, 8, 0, 8, 0, 8, 2, 1, 0x11, 0, 2, 0x11, 0,
                                        0xFF, 0xD9};
    static const unsigned char dnl[] = {0xFF, 0xD8, 0xFF, 0xC0, 0, 11, 8, 0, 0, 0, 8, 1, 1, 0x11, 0, 0xFF, 0xD9};
    static const unsigned char huge[] = {0xFF, 0xD8, 0xFF, 0xC0, 0, 11, 8, 0x7F, 0xFF, 0x7F, 0xFF, 1, 1, 0x11, 0,
                                         0xFF, 0xD9};
    static const unsigned char wide[] = {0xFF, 0xD8, 0xFF, 0xC0, 0, 11, 8, 0, 8, 0x80, 0x01, 1, 1, 0x11, 0,
                                         0xFF, 0xD9};
    static const unsigned char dhp[] = {0xFF, 0xD8, 0xFF, 0xDE, 0, 2, 0xFF, 0xD9};
    static const unsigned char noscan[] = {0xFF, 0xD8, 0xFF, 0xC0, 0, 11, 8, 0, 8, 0, 8, 1, 1, 0x11, 0, 0xFF, 0xD9};
    static const unsigned char frac[] = {0xFF, 0xD8, 0xFF, 0xC0, 0, 17, 8, 0, 8, 0, 8, 3, 1, 0x31, 0, 2, 0x21, 0,
                                         3, 0x11, 0, 0xFF, 0xD9};
    static const unsigned char png[] = {0x89, 'P', 'N', 'G', 13, 10, 26, 10};
    dec r;
    CHECK(base != NULL);
    if (!base) return;
    jpeg_refused(four, sizeof four, "CMYK", "4 components");
    jpeg_refused(two, sizeof two, "2 components", "2 components");
    jpeg_refused(dnl, sizeof dnl, "DNL", "height 0");
    jpeg_refused(huge, sizeof huge, "cannot fit", "32767x32767 in 17 bytes");
    jpeg_refused(wide, sizeof wide, "larger than", "width 32769");
    jpeg_refused(dhp, sizeof dhp, "hierarchical", "DHP");
    jpeg_refused(noscan, sizeof noscan, "no scan", "SOF then EOI");
    jpeg_refused(frac, sizeof frac, "fractional", "3:2 sampling");
    jpeg_refused(png, sizeof png, "no SOI", "PNG signature");
    jpeg_refused(NULL, 0, "no SOI", "empty");
    q = (unsigned char *)malloc(len + 16);
    at = find_marker(base, len, 0xC0);
    CHECK(at != (size_t)-1);
    if (at != (size_t)-1) {
        memcpy(q, base, len);
        q[at + 1] = 0xC3;
        jpeg_refused(q, len, "lossless", "SOF3");
        q[at + 1] = 0xC9;
        jpeg_refused(q, len, "arithmetic", "SOF9");
        q[at + 1] = 0xC5;
        jpeg_refused(q, len, "hierarchical", "SOF5");
        q[at + 1] = 0xC0;
        q[at + 4] = 12;
        jpeg_refused(q, len, "12-bit", "12-bit precision");
        memcpy(q, base, len);
        q[at + 11] = 0x31; /* luma 3x1 */
        q[at + 14] = 0x21; /* Cb 2x1: 3/2, no integral ratio */
        jpeg_refused(q, len, "fractional", "3:2 sampling via SOF edit");
        /* trailing bytes after EOI are ignored */
        memcpy(q, base, len);
        memcpy(q + len, "garbage after EOI", 16);
        dec_run(&r, appm__jpeg_decode, q, len + 16, "t.jpg", 0);
        CHECK_MSG(r.st == APPM_OK, "trailing garbage: %s", r.d.message);
        CHECK(dec_settle(&r, 0));
    }
    at = find_marker(base, len, 0xC4);
    CHECK(at != (size_t)-1);
    if (at != (size_t)-1) {
        unsigned char *c = cut_segment(base, len, at, &len2);
        jpeg_refused(c, len2, "Huffman table 0 not defined", "no DHT");
        free(c);
    }
    at = find_marker(base, len, 0xDB);
    CHECK(at != (size_t)-1);
    if (at != (size_t)-1) {
        unsigned char *c = cut_segment(base, len, at, &len2);
        jpeg_refused(c, len2, "quantisation table 0 not defined", "no DQT");
        free(c);
    }
    free(q);
    free(base);
    base = read_fixture("jpeg", "c33_arith.jpg", &len);
    CHECK(base != NULL);
    if (base) jpeg_refused(base, len, "arithmetic", "cjpeg -arithmetic");
    free(base);
    base = read_fixture("jpeg", "c33_420_rst1.jpg", &len);
    CHECK(base != NULL);
    if (base) { /* RST0 renumbered RST5: the sequence check catches it */
        size_t i;
        for (i = len - 2; i > 2; --i)
            if (base[i] == 0xFF && base[i + 1] == 0xD0) {
                base[i + 1] = 0xD5;
                break;
            }
        jpeg_refused(base, len, "expected restart marker RST0", "wrong RST");
    }
    free(base);
}

/* The dispatcher: unknown bytes are refused by name; TGA only by its name. */
static void test_dispatch(void)
{
    static const char tga[] = "\0\0\2\0\0\0\0\0\0\0\0\0\1\0\1\0\30\0\1\2\3";
    dec r;
    expect_line(appm__image_decode, "x.img", "hello", 5, APPM_ERR_PARSE, "not an image appm reads", __LINE__);
    expect_line(appm__image_decode, "x.img", "", 0, APPM_ERR_PARSE, "not an image appm reads", __LINE__);
    expect_line(appm__image_decode, "x.img", tga, sizeof tga - 1, APPM_ERR_PARSE, "not an image", __LINE__);
    dec_run(&r, appm__image_decode, (const unsigned char *)tga, sizeof tga - 1, "x.TGA", 0);
    CHECK_MSG(r.st == APPM_OK && r.px.w == 1 && r.px.h == 1 && r.px.channels == 3 &&
                  ((unsigned char *)r.px.data)[0] == 3 && ((unsigned char *)r.px.data)[2] == 1,
              "TGA by name: %s", r.d.message);
    CHECK(dec_settle(&r, 1));
    /* PFM through the dispatcher: 1x1 grey, big-endian */
    {
        static const unsigned char pfm[] = {'P', 'f', '\n', '1', ' ', '1', '\n', '1', '\n', 0x3F, 0x00, 0, 0};
        dec_run(&r, appm__image_decode, pfm, sizeof pfm, "x.img", 0);
        CHECK_MSG(r.st == APPM_OK && r.px.depth == 32 && r.px.channels == 3 && ((float *)r.px.data)[0] == 0.5f &&
                      ((float *)r.px.data)[2] == 0.5f,
                  "PFM: %s", r.d.message);
        CHECK(dec_settle(&r, 0));
    }
}

/* ---- appm_image_read ------------------------------------------------------------ */

/* The sRGB curve decoded, in double: the linear value of code c of `full`. */
static double srgb_to_linear(double v)
{
    return v <= 0.04045 ? v / 12.92 : pow((v + 0.055) / 1.055, 2.4);
}

static double linear_to_srgb(double v)
{
    if (!(v > 0.0)) return 0.0;
    if (v >= 1.0) return 1.0;
    return v <= 0.0031308 ? 12.92 * v : 1.055 * pow(v, 1.0 / 2.4) - 0.055;
}

/* Reads set/file with appm_image_read (a counting allocator, then allocation
 * failure k = 1, 2, ...) and compares with the linear RGB its .expect samples
 * give: 8/16-bit colour through the sRGB curve, grey to all three, alpha
 * dropped, floats bit for bit. */
static void test_read_linear(const char *set, const char *file)
{
    char path[1024];
    size_t elen = 0, i, n, bad = 0;
    unsigned char *exp = read_expect(set, file, &elen);
    const unsigned char *e;
    unsigned w = 0, h = 0, c = 0, d = 0;
    appm_config cfg;
    check_alloc a;
    appm_image img;
    appm_diag diag;
    appm_status st;
    long k;
    snprintf(path, sizeof path, "%s/%s/%s", IMG_DIR, set, file);
    CHECK_MSG(exp != NULL, "%s: no .expect", path);
    if (!exp) return;
    e = (const unsigned char *)memchr(exp, '\n', elen);
    if (!e || sscanf((const char *)exp, "%u %u %u %u", &w, &h, &c, &d) != 4) {
        CHECK_MSG(0, "%s: bad .expect", path);
        free(exp);
        return;
    }
    e++;
    memset(&cfg, 0, sizeof cfg);
    check_use_alloc(&cfg, &a, 0);
    memset(&img, 0x5A, sizeof img);
    st = appm_image_read(path, &cfg, &img, &diag);
    CHECK_MSG(st == APPM_OK && img.width == w && img.height == h && img.rgb, "%s: %s", path, diag.message);
    if (st == APPM_OK && img.width == w && img.height == h) {
        n = (size_t)w * h;
        for (i = 0; i < n * 3; ++i) {
            unsigned ch = c >= 3 ? (unsigned)(i % 3) : 0u;
            size_t j = i / 3 * c + ch;
            double want;
            float got = img.rgb[i];
            if (d == 32) {
                uint32_t wb, gb;
                wb = (uint32_t)e[4 * j] | (uint32_t)e[4 * j + 1] << 8 | (uint32_t)e[4 * j + 2] << 16 |
                     (uint32_t)e[4 * j + 3] << 24;
                memcpy(&gb, &got, 4);
                if (gb != wb && !(got != got && (wb & 0x7F800000u) == 0x7F800000u && (wb & 0x7FFFFFu))) bad++;
                continue;
            }
            want = d == 8 ? srgb_to_linear(e[j] / 255.0) : srgb_to_linear((e[2 * j] | e[2 * j + 1] << 8) / 65535.0);
            if (!(fabs(got - want) <= 1e-6 * want + 1e-9)) {
                if (!bad) fprintf(stderr, "  %s: sample %lu is %.9g, expected %.9g\n", path, (unsigned long)i, got, want);
                bad++;
            }
        }
        CHECK_MSG(bad == 0, "%s: %lu samples differ from the linear expectation", path, (unsigned long)bad);
    }
    if (st == APPM_OK) appm_image_free(&cfg, &img);
    CHECK_MSG(a.live == 0, "%s: %lld bytes leaked", path, a.live);
    /* allocation failures through appm_image_read (file buffer, pixels, conversion) */
    bad = 0;
    for (k = 1; k < 40; ++k) {
        check_use_alloc(&cfg, &a, k);
        st = appm_image_read(path, &cfg, &img, &diag);
        if (a.count < k) {
            if (st != APPM_OK) bad++;
            else appm_image_free(&cfg, &img);
            break;
        }
        if (st != APPM_ERR_NOMEM || img.rgb != NULL || diag.status != APPM_ERR_NOMEM) bad++;
        if (a.live != 0) bad++;
    }
    CHECK_MSG(bad == 0 && k > 1 && k < 40 && a.live == 0, "%s: appm_image_read allocation failures (k %ld, %lu bad)",
              path, k, (unsigned long)bad);
    free(exp);
}

static void test_image_read(void)
{
    char path[1024];
    appm_image img;
    appm_diag diag;
    appm_status st;
    /* the sRGB curve on known codes */
    CHECK_NEAR(srgb_to_linear(128 / 255.0), 0.2158605, 1e-6);
    CHECK_NEAR(srgb_to_linear(10 / 255.0), 10 / 255.0 / 12.92, 1e-12);
    test_read_linear("png", "pil_RGB_17x9.png");   /* 8-bit sRGB RGB */
    test_read_linear("png", "pil_RGBA_17x9.png");  /* alpha dropped */
    test_read_linear("png", "t0_d16_13x7.png");    /* 16-bit grey to all three */
    test_read_linear("jpeg", "c33_420_q75.jpg");   /* djpeg's samples, sRGB-decoded */
    test_read_linear("jpeg", "grey33.jpg");
    test_read_linear("png", "rgb_float_zip_7x5.exr");
    test_read_linear("png", "appm_zip_half_5x20.exr");
    test_read_linear("png", "rgba_half_zip_9x18.exr");
    test_read_linear("small", "tga_rgba_33x17.tga");
    test_read_linear("small", "pgm_p5_65535_13x7.pgm");
    test_read_linear("small", "hdr_rle_33x17.hdr");
    /* one PNG value against the sRGB formula written out */
    snprintf(path, sizeof path, "%s/png/t2_d8_1x1.png", IMG_DIR);
    {
        size_t elen = 0;
        unsigned char *exp = read_expect("png", "t2_d8_1x1.png", &elen);
        const unsigned char *e = exp ? (const unsigned char *)memchr(exp, '\n', elen) : NULL;
        st = appm_image_read(path, NULL, &img, &diag);
        CHECK_MSG(st == APPM_OK && e && img.width == 1 && img.height == 1, "%s: %s", path, diag.message);
        if (st == APPM_OK && e) {
            int k;
            for (k = 0; k < 3; ++k) {
                double v = e[1 + k] / 255.0;
                double lin = v <= 0.04045 ? v / 12.92 : pow((v + 0.055) / 1.055, 2.4);
                CHECK_NEAR(img.rgb[k], lin, 1e-6);
            }
        }
        appm_image_free(NULL, &img);
        free(exp);
    }
    /* a PFM written here: grey, big-endian, 2x2, bottom row first */
    {
        static const unsigned char pfm[] = {'P', 'f', '\n', '2', ' ', '2', '\n', '1', '.', '0', '\n',
                                            0x3F, 0x80, 0, 0,  0xC0, 0x00, 0,    0, /* bottom: 1, -2 */
                                            0x3E, 0x80, 0, 0,  0x47, 0x00, 0,    0}; /* top: 0.25, 32768 */
        const char *p = check_path("decode", "grey-be.pfm");
        FILE *f = fopen(p, "wb");
        int ok = f && fwrite(pfm, 1, sizeof pfm, f) == sizeof pfm;
        if (f && fclose(f) != 0) ok = 0;
        CHECK(ok);
        st = appm_image_read(p, NULL, &img, &diag);
        CHECK_MSG(st == APPM_OK && img.width == 2 && img.height == 2, "%s: %s", p, diag.message);
        if (st == APPM_OK && img.width == 2 && img.height == 2) {
            static const float want[4] = {0.25f, 32768.0f, 1.0f, -2.0f};
            int i, k, same = 1;
            for (i = 0; i < 4; ++i)
                for (k = 0; k < 3; ++k) same &= img.rgb[3 * i + k] == want[i];
            CHECK_MSG(same, "%s: %g %g %g %g", p, img.rgb[0], img.rgb[3], img.rgb[6], img.rgb[9]);
        }
        appm_image_free(NULL, &img);
    }
    /* failures: a missing file, an unknown format */
    st = appm_image_read("tests/images/no-such-file.png", NULL, &img, &diag);
    CHECK_MSG(st == APPM_ERR_IO && img.rgb == NULL, "missing file: %d %s", (int)st, diag.message);
    snprintf(path, sizeof path, "%s/README.md", IMG_DIR);
    st = appm_image_read(path, NULL, &img, &diag);
    CHECK_MSG(st == APPM_ERR_PARSE && img.rgb == NULL && strstr(diag.message, "not an image"), "README.md: %d %s",
              (int)st, diag.message);
}

/* ---- write / read round trips ------------------------------------------------------- */

#define RT_W 37
#define RT_H 21 /* two ZIP blocks of 16 lines, the second short */

/* Writes img to tests/out/decode-<file> (opt as given), reads it back with
 * appm_image_read; kind 0: 8-bit sRGB (PNG, PPM); 1: bit exact; 2: half. */
static void roundtrip(const appm_image *img, const char *file, const appm_write_options *opt, int kind)
{
    const char *path = check_path("decode", file);
    appm_image back;
    appm_diag d;
    appm_status st = appm_image_write_ex(path, img, opt, NULL, &d);
    size_t i, n = (size_t)img->width * img->height * 3, bad = 0;
    CHECK_MSG(st == APPM_OK, "writing %s: %s", path, d.message);
    if (st != APPM_OK) return;
    st = appm_image_read(path, NULL, &back, &d);
    CHECK_MSG(st == APPM_OK && back.width == img->width && back.height == img->height, "reading %s: %s", path,
              d.message);
    if (st != APPM_OK) return;
    for (i = 0; i < n && back.width == img->width && back.height == img->height; ++i) {
        float v = img->rgb[i], got = back.rgb[i];
        int ok;
        if (kind == 1) ok = check_fbits(got) == check_fbits(v);
        else if (kind == 2) {
            double av = fabs(v);
            if (av > 65504.0) ok = got == (v > 0 ? 65504.0f : -65504.0f);
            else ok = fabs(got - v) <= (av < 6.103515625e-05 ? ldexp(1.0, -25) : av * ldexp(1.0, -11));
        } else {
            /* the code the writer chose must be the nearest to v's sRGB value */
            double code = linear_to_srgb(v) * 255.0, gcode = linear_to_srgb(got) * 255.0;
            ok = fabs(gcode - floor(gcode + 0.5)) < 1e-3 && fabs(gcode - code) <= 0.5 + 1e-3;
        }
        if (!ok) {
            if (!bad) fprintf(stderr, "  %s: sample %lu: wrote %.9g, read %.9g\n", file, (unsigned long)i, v, got);
            bad++;
        }
    }
    CHECK_MSG(bad == 0, "%s: %lu samples off", file, (unsigned long)bad);
    appm_image_free(NULL, &back);
}

static void test_roundtrip(void)
{
    static float rgb[RT_W * RT_H * 3];
    appm_image img;
    appm_write_options opt;
    uint32_t s = 4242;
    size_t i;
    for (i = 0; i < sizeof rgb / sizeof rgb[0]; ++i) {
        uint32_t r = lcg(&s);
        float u = (float)(r >> 8) / 16777216.0f;
        switch (r % 8u) {
        case 0: rgb[i] = u * 1e-3f; break;           /* dark: the linear part of sRGB */
        case 1: rgb[i] = 1.0f + u * 1e4f; break;     /* bright: clipped to 255 */
        case 2: rgb[i] = -u; break;                  /* negative: 0 */
        case 3: rgb[i] = u * 1e5f; break;            /* beyond half's 65504 */
        case 4: rgb[i] = u * 1e-6f; break;           /* half subnormals */
        default: rgb[i] = u; break;
        }
    }
    rgb[0] = 0.0f;
    rgb[1] = 0.5f;
    rgb[2] = 1.0f;
    img.width = RT_W;
    img.height = RT_H;
    img.rgb = rgb;
    memset(&opt, 0, sizeof opt);
    roundtrip(&img, "rt.png", &opt, 0);
    roundtrip(&img, "rt.ppm", &opt, 0);
    roundtrip(&img, "rt.pfm", &opt, 1);
    roundtrip(&img, "rt-float-zip.exr", &opt, 1);
    opt.exr_uncompressed = 1;
    roundtrip(&img, "rt-float-none.exr", &opt, 1);
    opt.exr_half = 1;
    roundtrip(&img, "rt-half-none.exr", &opt, 2);
    opt.exr_uncompressed = 0;
    roundtrip(&img, "rt-half-zip.exr", &opt, 2);
}

/* ---- main ---------------------------------------------------------------------------- */

int main(void)
{
    CHECK(fuzz_run("image", (const unsigned char *)"\0", 1) != FUZZ_BAD); /* the fuzz target's own checks, once */
    static const char *const png_prefixes[] = {"t2_d8_adam7_33x17.png", "t6_d8_split1_7x5.png",
                                               "t3_d4_trns_13x7.png",   "pil_RGBA_17x9.png",
                                               "rgba_half_zip_9x18.exr", "rgb_float_rle_7x5.exr",
                                               "appm_zip_half_5x20.exr", "rgba_float_zip_offset_decreasing_7x20.exr"};
    static const char *const jpeg_prefixes[] = {"c33_420_rst1.jpg", "photo_420_prog.jpg", "grey33.jpg",
                                                "c1x1_prog.jpg",    "c33_successive.jpg", "c33_multiscan.jpg",
                                                "c33_fill.jpg",     "c17x9_422_prog.jpg"};
    static const char *const zz[] = {"z_level0_3000.zz", "z_level6_70000.zz", "z_level9_70000.zz",
                                     "z_empty_0.zz",     "z_fixed_70000.zz",  "z_huffonly_3000.zz"};
    const int quick = check_quick();
    int n, i;
    size_t step = quick ? 3 : 1;

    /* PNG and OpenEXR */
    n = for_each_listed("png", "index.txt", "", 0, quick);
    CHECK_MSG(n > 130, "png: %d fixtures", n);
    for (i = 0; i < (int)(sizeof png_prefixes / sizeof png_prefixes[0]); ++i)
        test_prefixes("png", png_prefixes[i], step);
    test_bit_flips("png", "t0_d16_trns_adam7_7x13.png", step, 1);
    test_bit_flips("png", "t3_d2_13x7.png", step, 1);
    CHECK(test_bit_flips("png", "rgb_half_zips_7x5.exr", step, 0) > 0);
    CHECK(test_bit_flips("png", "appm_zip_float_5x20.exr", step, 0) > 0);
    CHECK(test_bit_flips("png", "rgba_half_rle_9x5.exr", step, 0) > 0);
    test_damage_file("png", "t2_d8_adam7_33x17.png", quick ? 1000 : 3000, 8, 99);
    test_damage_file("png", "t0_d1_trns_13x7.png", quick ? 1000 : 3000, 8, 98);
    test_damage_file("png", "t6_d16_33x17.png", quick ? 1000 : 3000, 8, 97);
    test_damage_file("png", "rgb_mixed_zip_9x20.exr", quick ? 1000 : 3000, 4, 96);
    for (i = 0; i < (int)(sizeof zz / sizeof zz[0]); ++i) test_inflate_fixture(zz[i], quick ? 5 : 1);
    test_inflate_handmade();

    /* JPEG */
    n = for_each_listed("jpeg", "LIST", ".jpg", 1, quick);
    CHECK_MSG(n >= 45, "jpeg: %d fixtures", n);
    for (i = 0; i < (int)(sizeof jpeg_prefixes / sizeof jpeg_prefixes[0]); ++i)
        test_prefixes("jpeg", jpeg_prefixes[i], step);
    test_bit_flips("jpeg", "c33_420_q75.jpg", step, 0); /* every single bit of a few */
    test_bit_flips("jpeg", "c33_successive.jpg", step, 0);
    test_bit_flips("jpeg", "grey33_rst_q10.jpg", step, 0);
    test_bit_flips("jpeg", "c17x9_422_prog.jpg", step, 0);
    test_jpeg_refusals();

    /* TGA, PGM/PPM, Radiance HDR */
    n = for_each_listed("small", "MANIFEST", "", 2, quick);
    CHECK_MSG(n >= 36, "small: %d fixtures", n);
    test_tga_refusals();
    test_pnm_refusals();
    test_hdr_refusals();

    test_dispatch();
    test_image_read();
    test_roundtrip();
    fprintf(stderr, "t_decode: %ld decodes, %ld injected allocation failures%s\n", g_decodes, g_nomem,
            quick ? " (quick)" : "");
    return check_finish();
}
