/* tests/inflate.h - an independent inflater (RFC 1950 zlib, RFC 1951 deflate)
 * and PNG row un-filter for the image tests, written from the RFCs and the PNG
 * specification, sharing no code with appm.c.  Slow and simple on purpose, in
 * the manner of zlib's "puff": bit-at-a-time Huffman decoding from canonical
 * code counts.  Every malformed input returns an error instead of reading out of
 * bounds, so a wrong encoder is reported, not crashed on. */
#ifndef TESTS_INFLATE_H
#define TESTS_INFLATE_H

#include <stdint.h>
#include <stdlib.h>
#include <string.h>

typedef struct tinf {
    const unsigned char *in;
    size_t inlen, pos;
    unsigned bit, bitcnt;
    unsigned char *out;
    size_t outcap, outlen;
    int err;
    int blocks[3]; /* blocks seen per type: stored, fixed, dynamic */
} tinf;

typedef struct tinf_huff {
    short count[16];
    short symbol[288];
} tinf_huff;

static unsigned tinf_bits(tinf *s, unsigned n)
{
    unsigned v = s->bit;
    while (s->bitcnt < n) {
        if (s->pos >= s->inlen) {
            s->err = 1;
            return 0;
        }
        v |= (unsigned)s->in[s->pos++] << s->bitcnt;
        s->bitcnt += 8;
    }
    s->bit = (unsigned)(((unsigned long)v) >> n);
    s->bitcnt -= n;
    return v & ((1u << n) - 1u);
}

/* Builds counts and symbols; returns 0 for a complete code, > 0 incomplete, < 0 over-subscribed. */
static int tinf_build(tinf_huff *h, const unsigned char *len, int n)
{
    short offs[16];
    int i, left = 1;
    memset(h->count, 0, sizeof h->count);
    for (i = 0; i < n; ++i) h->count[len[i]]++;
    if (h->count[0] == n) return 0;
    for (i = 1; i < 16; ++i) {
        left <<= 1;
        left -= h->count[i];
        if (left < 0) return left;
    }
    offs[1] = 0;
    for (i = 1; i < 15; ++i) offs[i + 1] = (short)(offs[i] + h->count[i]);
    for (i = 0; i < n; ++i)
        if (len[i]) h->symbol[offs[len[i]]++] = (short)i;
    return left;
}

static int tinf_decode(tinf *s, const tinf_huff *h)
{
    int code = 0, first = 0, index = 0, l;
    for (l = 1; l < 16; ++l) {
        int count;
        code |= (int)tinf_bits(s, 1);
        if (s->err) return -1;
        count = h->count[l];
        if (code - count < first) return h->symbol[index + (code - first)];
        index += count;
        first += count;
        first <<= 1;
        code <<= 1;
    }
    s->err = 2;
    return -1;
}

static void tinf_put(tinf *s, unsigned char c)
{
    if (s->outlen >= s->outcap) {
        s->err = 3;
        return;
    }
    s->out[s->outlen++] = c;
}

static void tinf_codes(tinf *s, const tinf_huff *lh, const tinf_huff *dh)
{
    static const short lbase[29] = {3, 4, 5, 6, 7, 8, 9, 10, 11, 13, 15, 17, 19, 23, 27,
                                    31, 35, 43, 51, 59, 67, 83, 99, 115, 131, 163, 195, 227, 258};
    static const short lext[29] = {0, 0, 0, 0, 0, 0, 0, 0, 1, 1, 1, 1, 2, 2, 2, 2, 3, 3, 3, 3, 4, 4, 4, 4, 5, 5, 5, 5, 0};
    static const short dbase[30] = {1, 2, 3, 4, 5, 7, 9, 13, 17, 25, 33, 49, 65, 97, 129, 193, 257, 385, 513, 769,
                                    1025, 1537, 2049, 3073, 4097, 6145, 8193, 12289, 16385, 24577};
    static const short dext[30] = {0, 0, 0, 0, 1, 1, 2, 2, 3, 3, 4, 4, 5, 5, 6, 6, 7, 7, 8, 8, 9, 9, 10, 10, 11, 11, 12, 12, 13, 13};
    for (;;) {
        int sym = tinf_decode(s, lh);
        if (s->err || sym < 0) return;
        if (sym < 256) {
            tinf_put(s, (unsigned char)sym);
        } else if (sym == 256) {
            return;
        } else {
            unsigned len, dist, k;
            sym -= 257;
            if (sym >= 29) {
                s->err = 4;
                return;
            }
            len = (unsigned)lbase[sym] + tinf_bits(s, (unsigned)lext[sym]);
            sym = tinf_decode(s, dh);
            if (s->err || sym < 0 || sym >= 30) {
                s->err = 5;
                return;
            }
            dist = (unsigned)dbase[sym] + tinf_bits(s, (unsigned)dext[sym]);
            if (dist > s->outlen || dist > 32768) {
                s->err = 6;
                return;
            }
            for (k = 0; k < len && !s->err; ++k) tinf_put(s, s->out[s->outlen - dist]);
        }
        if (s->err) return;
    }
}

static void tinf_dynamic(tinf *s)
{
    static const unsigned char order[19] = {16, 17, 18, 0, 8, 7, 9, 6, 10, 5, 11, 4, 12, 3, 13, 2, 14, 1, 15};
    unsigned char lens[320];
    tinf_huff lh, dh, ch;
    int nlen = (int)tinf_bits(s, 5) + 257, ndist = (int)tinf_bits(s, 5) + 1, ncode = (int)tinf_bits(s, 4) + 4, i = 0;
    if (s->err || nlen > 286 || ndist > 30) {
        s->err = 7;
        return;
    }
    memset(lens, 0, sizeof lens);
    for (i = 0; i < ncode; ++i) lens[order[i]] = (unsigned char)tinf_bits(s, 3);
    if (tinf_build(&ch, lens, 19) != 0) { /* the code-length code must be complete */
        s->err = 8;
        return;
    }
    i = 0;
    while (i < nlen + ndist && !s->err) {
        int sym = tinf_decode(s, &ch), rep = 0, val = 0;
        if (sym < 0) return;
        if (sym < 16) {
            lens[i++] = (unsigned char)sym;
            continue;
        }
        if (sym == 16) {
            if (i == 0) {
                s->err = 9;
                return;
            }
            val = lens[i - 1];
            rep = 3 + (int)tinf_bits(s, 2);
        } else if (sym == 17) {
            rep = 3 + (int)tinf_bits(s, 3);
        } else {
            rep = 11 + (int)tinf_bits(s, 7);
        }
        if (i + rep > nlen + ndist) {
            s->err = 10;
            return;
        }
        while (rep--) lens[i++] = (unsigned char)val;
    }
    if (s->err) return;
    if (lens[256] == 0 || tinf_build(&lh, lens, nlen) != 0 || tinf_build(&dh, lens + nlen, ndist) < 0) {
        s->err = 11; /* appm's codes are complete; an empty distance code is allowed */
        return;
    }
    tinf_codes(s, &lh, &dh);
}

/* Inflates the zlib stream z[0..zlen) into out (capacity cap); checks the header
 * and the Adler-32.  Returns the number of bytes, or (size_t)-1 on any error. */
static size_t tinf_zlib(const unsigned char *z, size_t zlen, unsigned char *out, size_t cap, int blocks[3])
{
    tinf s;
    int last = 0;
    uint32_t a1 = 1, a2 = 0, want;
    size_t i;
    memset(&s, 0, sizeof s);
    if (zlen < 6 || (z[0] & 15) != 8 || (z[0] >> 4) > 7 || (z[1] & 0x20) || ((unsigned)z[0] * 256u + z[1]) % 31u)
        return (size_t)-1;
    s.in = z;
    s.inlen = zlen - 4;
    s.pos = 2;
    s.out = out;
    s.outcap = cap;
    while (!last && !s.err) {
        unsigned type;
        last = (int)tinf_bits(&s, 1);
        type = tinf_bits(&s, 2);
        if (s.err) break;
        if (type == 0) {
            unsigned len, nlen;
            s.bit = s.bitcnt = 0; /* to the byte boundary */
            if (s.pos + 4 > s.inlen) {
                s.err = 12;
                break;
            }
            len = s.in[s.pos] | (unsigned)s.in[s.pos + 1] << 8;
            nlen = s.in[s.pos + 2] | (unsigned)s.in[s.pos + 3] << 8;
            s.pos += 4;
            if (nlen != (~len & 0xFFFFu) || s.pos + len > s.inlen) {
                s.err = 13;
                break;
            }
            while (len-- && !s.err) tinf_put(&s, s.in[s.pos++]);
        } else if (type == 1) {
            unsigned char lens[318];
            tinf_huff lh, dh;
            for (i = 0; i < 288; ++i) lens[i] = (unsigned char)(i < 144 ? 8 : i < 256 ? 9 : i < 280 ? 7 : 8);
            for (i = 0; i < 30; ++i) lens[288 + i] = 5;
            tinf_build(&lh, lens, 288);
            tinf_build(&dh, lens + 288, 30);
            tinf_codes(&s, &lh, &dh);
        } else if (type == 2) {
            tinf_dynamic(&s);
        } else {
            s.err = 14;
        }
        if (type < 3) s.blocks[type]++;
    }
    if (s.err || s.pos != s.inlen) return (size_t)-1; /* the Adler-32 follows the last block exactly */
    for (i = 0; i < s.outlen; ++i) {
        a1 = (a1 + out[i]) % 65521u;
        a2 = (a2 + a1) % 65521u;
    }
    want = (uint32_t)z[zlen - 4] << 24 | (uint32_t)z[zlen - 3] << 16 | (uint32_t)z[zlen - 2] << 8 | z[zlen - 1];
    if (want != (a2 << 16 | a1)) return (size_t)-1;
    if (blocks) memcpy(blocks, s.blocks, sizeof s.blocks);
    return s.outlen;
}

/* Undoes the PNG row filters in place: raw holds h rows of 1 + stride bytes;
 * the pixels (h * stride bytes) go to px.  bpp = bytes per pixel.  Returns 0 on
 * an unknown filter type. */
static int png_unfilter(const unsigned char *raw, size_t stride, size_t h, size_t bpp, unsigned char *px,
                        int counts[5])
{
    size_t y, i;
    for (y = 0; y < h; ++y) {
        const unsigned char *f = raw + y * (stride + 1) + 1;
        unsigned char *cur = px + y * stride;
        const unsigned char *up = y ? cur - stride : NULL;
        int t = raw[y * (stride + 1)];
        if (t > 4) return 0;
        if (counts) counts[t]++;
        for (i = 0; i < stride; ++i) {
            int a = i >= bpp ? cur[i - bpp] : 0, b = up ? up[i] : 0, c = (up && i >= bpp) ? up[i - bpp] : 0, pr;
            if (t == 0) pr = 0;
            else if (t == 1) pr = a;
            else if (t == 2) pr = b;
            else if (t == 3) pr = (a + b) / 2;
            else {
                int p = a + b - c, pa = abs(p - a), pb = abs(p - b), pc = abs(p - c);
                pr = (pa <= pb && pa <= pc) ? a : (pb <= pc ? b : c);
            }
            cur[i] = (unsigned char)(f[i] + pr);
        }
    }
    return 1;
}

#endif
