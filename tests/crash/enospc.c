/* tests/crash/enospc.c - an LD_PRELOAD shim for tests/crash.sh: a disk that
 * fills up.  Every file opened for writing whose name ends in ".tmp" (how appm
 * writes a checkpoint or an image before renaming it into place) may take at
 * most APPM_ENOSPC_BYTES bytes in all, counted over the whole process; past
 * that, fwrite writes what still fits and fails with ENOSPC, as write(2) does
 * on a full disk.  Other files are untouched.
 *   cc -shared -fPIC -O1 tests/crash/enospc.c -o build/enospc.so -ldl
 *   APPM_ENOSPC_BYTES=100000 LD_PRELOAD=build/enospc.so ./appm render ... */
#define _GNU_SOURCE
#include <dlfcn.h>
#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define MAX_TRACKED 16

static FILE *tracked[MAX_TRACKED];
static long long budget = -1; /* bytes left; -1: not read yet */

static long long left(void)
{
    if (budget < 0) {
        const char *e = getenv("APPM_ENOSPC_BYTES");
        budget = e ? atoll(e) : (long long)1 << 62;
    }
    return budget;
}

/* Opens through the C library's NAME ("fopen", or "fopen64", which a program
 * built with _FILE_OFFSET_BITS 64 calls, as appm is) and tracks a .tmp file
 * opened for writing. */
static FILE *open_tracked(const char *name, const char *path, const char *mode)
{
    FILE *(*real)(const char *, const char *) = (FILE * (*)(const char *, const char *)) dlsym(RTLD_NEXT, name);
    FILE *f = real ? real(path, mode) : NULL;
    size_t n = strlen(path);
    int k;
    if (f && strchr(mode, 'w') && n > 4 && strcmp(path + n - 4, ".tmp") == 0)
        for (k = 0; k < MAX_TRACKED; ++k)
            if (!tracked[k]) {
                tracked[k] = f;
                break;
            }
    return f;
}

FILE *fopen(const char *path, const char *mode) { return open_tracked("fopen", path, mode); }
FILE *fopen64(const char *path, const char *mode);
FILE *fopen64(const char *path, const char *mode) { return open_tracked("fopen64", path, mode); }

int fclose(FILE *f)
{
    int (*real)(FILE *) = (int (*)(FILE *))dlsym(RTLD_NEXT, "fclose");
    int k;
    for (k = 0; k < MAX_TRACKED; ++k)
        if (tracked[k] == f) tracked[k] = NULL;
    return real(f);
}

size_t fwrite(const void *p, size_t size, size_t count, FILE *f)
{
    size_t (*real)(const void *, size_t, size_t, FILE *) =
        (size_t(*)(const void *, size_t, size_t, FILE *))dlsym(RTLD_NEXT, "fwrite");
    int k, mine = 0;
    long long want = (long long)size * (long long)count;
    for (k = 0; k < MAX_TRACKED; ++k) mine |= tracked[k] == f;
    if (!mine || size == 0) return real(p, size, count, f);
    if (want <= left()) {
        budget -= want;
        return real(p, size, count, f);
    }
    {
        size_t fit = (size_t)(left() / (long long)size), got = fit ? real(p, size, fit, f) : 0;
        budget -= (long long)(got * size);
        errno = ENOSPC;
        return got;
    }
}
