/* tests/t_fuzz_regress.c - replays the fuzz corpus and the kept crash inputs
 * without libFuzzer, so that `make test` runs them under ASan+UBSan too.
 *
 * Every file of tests/fuzz/corpus/<target>/ and of tests/fuzz/regressions/ goes
 * through all the entry points of tests/fuzz/targets.h (obj, mtl, scene, pfm,
 * checkpoint, image),
 * which check their own invariants (valid status, diag, no leak through the
 * allocator hooks, reader-specific promises) and run an out-of-memory variant.
 * A file in corpus/<target>/ named ok-* must load with APPM_OK through its own
 * target, one named err-* must fail; other names only have to be handled.
 * Run from the repository root (as make test does). */
#include "../appm.c"
#include "check.h"
#include "fuzz/targets.h"

#include <dirent.h>

#define REGRESS_MAX_FILES 4096
#define REGRESS_MAX_BYTES (1u << 20)

static int name_cmp(const void *a, const void *b)
{
    return strcmp(*(const char *const *)a, *(const char *const *)b);
}

static unsigned char *read_all(const char *path, size_t *len)
{
    FILE *f = fopen(path, "rb");
    unsigned char *buf;
    size_t n;
    *len = 0;
    if (!f) return NULL;
    buf = (unsigned char *)malloc(REGRESS_MAX_BYTES);
    if (!buf) {
        fclose(f);
        return NULL;
    }
    n = fread(buf, 1, REGRESS_MAX_BYTES, f);
    fclose(f);
    *len = n;
    return buf;
}

/* Replays every regular file of `dir` (sorted by name); `own` is the target the
 * folder belongs to (NULL for regressions/).  Returns the number of files. */
static int replay_dir(const char *dir, const char *own)
{
    DIR *d = opendir(dir);
    struct dirent *ent;
    char *names[REGRESS_MAX_FILES];
    int n = 0, i;
    if (!d) return 0;
    while ((ent = readdir(d)) != NULL && n < REGRESS_MAX_FILES) {
        size_t len = strlen(ent->d_name);
        if (ent->d_name[0] == '.') continue;
        names[n] = (char *)malloc(len + 1);
        if (!names[n]) break;
        memcpy(names[n], ent->d_name, len + 1);
        n++;
    }
    closedir(d);
    qsort(names, (size_t)n, sizeof names[0], name_cmp);
    for (i = 0; i < n; ++i) {
        char path[1024];
        unsigned char *data;
        size_t len, k;
        snprintf(path, sizeof path, "%s/%s", dir, names[i]);
        data = read_all(path, &len);
        if (!data) { /* a folder or an unreadable entry: not a test input */
            free(names[i]);
            continue;
        }
        CHECK_MSG(len < REGRESS_MAX_BYTES, "%s: input larger than 1 MiB", path);
        for (k = 0; k < FUZZ_TARGET_COUNT; ++k) {
            const char *t = fuzz_targets[k].name;
            int st = fuzz_run(t, data, len);
            CHECK_MSG(st >= 0 && st < (int)APPM_STATUS_COUNT, "%s through %s: %s", path, t,
                      st == FUZZ_BAD ? "invariant broken (see above)" : "status out of range");
            if (own && strcmp(own, t) == 0 && strncmp(names[i], "ok-", 3) == 0)
                CHECK_MSG(st == APPM_OK, "%s through %s: status %d (%s), expected ok", path, t, st,
                          appm_status_string((appm_status)st));
            if (own && strcmp(own, t) == 0 && strncmp(names[i], "err-", 4) == 0)
                CHECK_MSG(st > 0, "%s through %s: status %d, expected an error", path, t, st);
        }
        free(data);
        free(names[i]);
    }
    return n;
}

/* The checkpoint kept in regressions/ must still reach the check it was kept
 * for, the budget's reading of -0, and not stop at the version or the field
 * list in front of it: written again with each change of appm's state (from
 * ok-appm-0 of the corpus with the reading made -0 and its checksum right).
 * From 0.1.11 to 0.1.12 it was refused on its field list and tested nothing. */
static void test_checkpoint_regression_reaches_its_check(void)
{
    static const char path[] = "tests/fuzz/regressions/checkpoint-budget-reading-negative-zero.ckpt";
    size_t len;
    unsigned char *data = read_all(path, &len);
    fuzz_env e;
    appm_scene *s = NULL;
    appm_renderer *r = NULL;
    appm_status st;
    CHECK_MSG(data && len > 16, "%s: missing", path);
    if (!data || len <= 16) {
        free(data);
        return;
    }
    fuzz__env_init(&e, 0); /* as the checkpoint target and gen_checkpoint set it up */
    st = fuzz__ck_setup(&e, data, len, &s, &r);
    CHECK(st == APPM_OK);
    if (st == APPM_OK) {
        st = appm_renderer_load(r, data, len, &e.diag);
        CHECK_MSG(st == APPM_ERR_PARSE && strstr(e.diag.message, "a value no render produces"),
                  "%s: status %d, '%s' (want the budget reading's refusal)", path, (int)st, e.diag.message);
    }
    appm_renderer_destroy(r);
    appm_scene_destroy(s);
    free(data);
}

int main(void)
{
    size_t k;
    int total = 0, n;
    char dir[256];
    for (k = 0; k < FUZZ_TARGET_COUNT; ++k) {
        snprintf(dir, sizeof dir, "tests/fuzz/corpus/%s", fuzz_targets[k].name);
        n = replay_dir(dir, fuzz_targets[k].name);
        CHECK_MSG(n > 0, "%s: no corpus files (run from the repository root)", dir);
        total += n;
    }
    total += replay_dir("tests/fuzz/regressions", NULL);
    test_checkpoint_regression_reaches_its_check();
    printf("replayed %d files through %d targets\n", total, (int)FUZZ_TARGET_COUNT);
    return check_finish();
}
