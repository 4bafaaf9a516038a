/* gen_appm_exr.c - writes OpenEXR fixtures with appm's own writer (appm.c 3.3,
 * appm_image_write_ex), so tests/t_decode.c checks that what appm writes reads
 * back bit for bit.  tests/images/make_png.py builds and runs it; by hand, from
 * the repository root:
 *   cc -O1 -I. tests/images/gen_appm_exr.c appm.c -o gen -lm -pthread && ./gen tests/images/png
 * Each image is 5x20: the first 16-line block is noise (incompressible, so the
 * ZIP writer stores it raw), the last 4 lines smooth (deflated), a short block. */
#include "appm.h"
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <string.h>

#define W 5
#define H 20

static uint32_t rng_state = 12345u;
static uint32_t rnd(void)
{
    rng_state = rng_state * 1664525u + 1013904223u;
    return rng_state ^ (rng_state >> 15);
}

/* Exactly the value of half h (no NaN): ldexp in double, then exact as float. */
static float half_value(uint32_t h)
{
    uint32_t e = (h >> 10) & 31u, m = h & 0x3FFu;
    double v = e == 0 ? ldexp((double)m, -24) : e == 31 ? HUGE_VAL : ldexp((double)(1024u + m), (int)e - 25);
    return (float)((h & 0x8000u) ? -v : v);
}

static int write_one(const char *dir, const char *file, int half, int uncompressed, const float *rgb)
{
    char path[1024];
    FILE *f;
    appm_image img;
    appm_write_options opt;
    appm_diag d;
    size_t i;
    img.width = W;
    img.height = H;
    img.rgb = (float *)rgb;
    memset(&opt, 0, sizeof opt);
    opt.exr_half = half;
    opt.exr_uncompressed = uncompressed;
    snprintf(path, sizeof path, "%s/%s", dir, file);
    if (appm_image_write_ex(path, &img, &opt, NULL, &d) != APPM_OK) {
        fprintf(stderr, "%s: %s\n", path, d.message);
        return 1;
    }
    snprintf(path, sizeof path, "%s/%s.expect", dir, file);
    if (!(f = fopen(path, "wb"))) return 1;
    fprintf(f, "%d %d 3 32\n", W, H);
    for (i = 0; i < (size_t)W * H * 3; ++i) { /* float32 little-endian */
        uint32_t b;
        unsigned char q[4];
        memcpy(&b, &rgb[i], 4);
        q[0] = (unsigned char)b, q[1] = (unsigned char)(b >> 8), q[2] = (unsigned char)(b >> 16),
        q[3] = (unsigned char)(b >> 24);
        fwrite(q, 1, 4, f);
    }
    return fclose(f) != 0;
}

int main(int argc, char **argv)
{
    static float fl[W * H * 3], hf[W * H * 3];
    const char *dir = argc > 1 ? argv[1] : "fixtures";
    size_t i;
    int bad = 0;
    for (i = 0; i < (size_t)W * H * 3; ++i) {
        size_t y = i / (W * 3);
        if (y < 16) {
            uint32_t b = rnd(), h = rnd() & 0xFFFFu;
            memcpy(&fl[i], &b, 4); /* any bits at all, NaNs included: float is written as is */
            if (((h >> 10) & 31u) == 31u) h &= ~0x4000u; /* no NaN or inf from the noise */
            hf[i] = half_value(h);
        } else {
            fl[i] = (float)(0.01 * (double)i + 0.5);
            hf[i] = half_value(0x3C00u + (uint32_t)(i % 64u)); /* 1 + k/1024 */
        }
    }
    hf[3 * W * 17] = half_value(0x0001u); /* smallest subnormal */
    hf[3 * W * 17 + 1] = half_value(0x83FFu);
    hf[3 * W * 17 + 2] = half_value(0x7C00u); /* +inf */
    hf[3 * W * 18] = half_value(0x7BFFu);     /* 65504 */
    bad |= write_one(dir, "appm_zip_float_5x20.exr", 0, 0, fl);
    bad |= write_one(dir, "appm_none_float_5x20.exr", 0, 1, fl);
    bad |= write_one(dir, "appm_zip_half_5x20.exr", 1, 0, hf);
    bad |= write_one(dir, "appm_none_half_5x20.exr", 1, 1, hf);
    return bad;
}
