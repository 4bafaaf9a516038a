/* tests/fuzz/gen_checkpoint.c - writes the seed corpus of the checkpoint fuzz
 * target (tests/fuzz/corpus/checkpoint/): checkpoints of the renderer that
 * targets.h loads them into, for every method after 0 and 2 passes (ok-*),
 * and damaged ones (err-*); with a second folder, also the checkpoint of
 * tests/fuzz/regressions/.  Run again when the checkpoint format, the library
 * version or a method's state changes, from the repository root:
 *   cc -std=c99 -O1 tests/fuzz/gen_checkpoint.c -lm -pthread -o build/gen_checkpoint &&
 *   build/gen_checkpoint tests/fuzz/corpus/checkpoint tests/fuzz/regressions */
#include "../../appm.c"
#include "targets.h"

/* v at offset off (little-endian), then the trailing checksum made right. */
static void forge(unsigned char *p, size_t n, size_t off, uint64_t v, int bytes)
{
    uint64_t h = 14695981039346656037ull;
    size_t i;
    int k;
    for (k = 0; k < bytes; ++k) p[off + (size_t)k] = (unsigned char)(v >> (8 * k));
    for (i = 0; i + 8 < n; ++i) h = (h ^ p[i]) * 1099511628211ull;
    for (k = 0; k < 8; ++k) p[n - 8 + (size_t)k] = (unsigned char)(h >> (8 * k));
}

static int put(const char *dir, const char *name, const unsigned char *p, size_t n)
{
    char path[1024];
    FILE *f;
    snprintf(path, sizeof path, "%s/%s", dir, name);
    f = fopen(path, "wb");
    if (!f || fwrite(p, 1, n, f) != n || fclose(f) != 0) {
        fprintf(stderr, "cannot write %s\n", path);
        return 1;
    }
    return 0;
}

int main(int argc, char **argv)
{
    int m, passes, bad = 0;
    (void)fuzz_run; /* the replayer's entry, not needed here */
    if (argc != 2 && argc != 3) {
        fprintf(stderr, "usage: gen_checkpoint FOLDER [REGRESSIONS]\n");
        return 2;
    }
    for (m = 0; m < 2 * (int)APPM_METHOD_COUNT; ++m) /* m >= the method count: guided emission */
        for (passes = 0; passes <= 2; passes += 2) {
            unsigned char probe[FUZZ_CK_GUIDED_AT + 1], *buf;
            fuzz_env e;
            appm_scene *scene = NULL;
            appm_renderer *r = NULL;
            size_t n = 0;
            int k;
            char name[64];
            memset(probe, 0, sizeof probe);
            probe[FUZZ_CK_METHOD_AT] = (unsigned char)(m % APPM_METHOD_COUNT);
            probe[FUZZ_CK_GUIDED_AT] = (unsigned char)(m >= (int)APPM_METHOD_COUNT);
            fuzz__env_init(&e, 0);
            if (fuzz__ck_setup(&e, probe, sizeof probe, &scene, &r) != APPM_OK) return 1;
            for (k = 0; k < passes; ++k) appm_renderer_pass(r);
            appm_renderer_save(r, NULL, 0, &n, NULL);
            buf = (unsigned char *)malloc(n);
            if (!buf || appm_renderer_save(r, buf, n, &n, NULL) != APPM_OK) return 1;
            snprintf(name, sizeof name, "ok-%s%s-%d.ckpt", appm_method_name((appm_method)(m % APPM_METHOD_COUNT)),
                     m >= (int)APPM_METHOD_COUNT ? "-guided" : "", passes);
            bad |= put(argv[1], name, buf, n);
            if (m == APPM_METHOD_APPM && passes == 0 && argc == 3) {
                /* the budget's reading (the 8 bytes before the checksum) -0: the
                 * fuzzer's find, kept in regressions/ (t_fuzz_regress checks that
                 * it still reaches that check) */
                forge(buf, n, n - 16, 0x8000000000000000ull, 8);
                bad |= put(argv[2], "checkpoint-budget-reading-negative-zero.ckpt", buf, n);
                forge(buf, n, n - 16, 0, 8);
            }
            if (m == APPM_METHOD_APPM && passes == 2) {
                snprintf(name, sizeof name, "err-%s-truncated.ckpt", appm_method_name((appm_method)m));
                bad |= put(argv[1], name, buf, n / 2);
                buf[n / 2] ^= 4;
                bad |= put(argv[1], "err-appm-bitflip.ckpt", buf, n);
                buf[n / 2] ^= 4;
                forge(buf, n, 32, 0xFFFFFFFFu, 4); /* width */
                bad |= put(argv[1], "err-appm-width-2e32.ckpt", buf, n);
                forge(buf, n, 32, 4, 4);
                forge(buf, n, 168, 0x7FF8000000000000ull, 8); /* r1 = NaN */
                bad |= put(argv[1], "err-appm-nan-radius.ckpt", buf, n);
                forge(buf, n, 168, 0, 8);
                forge(buf, n, 240, 0xFFFFFFFFu, 4); /* pixel field count */
                bad |= put(argv[1], "err-appm-field-count.ckpt", buf, n);
            }
            free(buf);
            appm_renderer_destroy(r);
            appm_scene_destroy(scene);
        }
    return bad;
}
