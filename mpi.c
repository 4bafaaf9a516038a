/* mpi.c - `appm-mpi`, the `appm` command line on many machines (MPI).
 *
 *   mpirun -np N appm-mpi render SCENE [the options of appm render]
 *
 * renders the image `appm render` makes with the same options, byte for byte,
 * for any N and any --threads per rank.  Build: make mpi (mpicc; Open MPI or
 * MPICH).  The library knows nothing of MPI: this file gives it three hooks.
 *
 *   files     every file a load reads (scene, meshes, materials, the --resume
 *             checkpoint) is read by rank 0 and broadcast (appm_file_reader),
 *             so the other ranks need not see the files at all;
 *   exchange  the pass's all-gathers (appm_cluster): MPI_Allgatherv in place;
 *   control   during the setup the ranks agree on an exit code (a rank that
 *             failed names itself; rank 0 says which rank ended the job; a
 *             rank short of memory while the others still read the scene's
 *             files ends the job at once), and after every pass rank 0 - its
 *             clock, its SIGUSR1 or Ctrl-C, its checkpoint - decides for all
 *             whether to go on.  Open MPI's mpirun kills the ranks on Ctrl-C;
 *             `kill -USR1 <mpirun's pid>` stops after the pass in flight and
 *             writes the image and the checkpoint.
 * Only rank 0 writes images, maps, the log, checkpoints and the summary line;
 * a message from another rank begins "appm: rank K:".  `info`, `compare`,
 * --help and --version run on rank 0 alone.  MPI's default error handler
 * ends the whole job when a rank dies, so no rank waits forever for one that
 * is gone.  docs/distributed.md: the design, the measured exchange and the
 * model of its scaling.
 *
 * For the tests, APPM_MPI_FAIL=K:WHEN makes every allocation of rank K fail
 * from WHEN on: `load` (the scene's load runs out of memory while rank 0 still
 * sends files: the job is ended), `create` (the renderer's creation: the
 * ranks agree to stop), `pass` (the first pass: the library's agreement).
 */
#define APPM_CLI_NO_MAIN
#include "main.c"

#include <limits.h>
#include <mpi.h>

typedef struct mpi_state {
    MPI_Comm comm;
    int rank, ranks;
    int *counts, *displs; /* MPI_Allgatherv's, per rank */
    int *codes;           /* every rank's exit code (mpi_agree) */
    int fail;             /* APPM_MPI_FAIL: this rank's allocations fail after `fail - 1` agreements */
    int agreed;           /* agreements so far */
    int armed;            /* allocations fail */
} mpi_state;

/* Pieces of at most 1 GiB: MPI counts are ints. */
#define MPI_PIECE ((size_t)1 << 30)

static int bcast_bytes(mpi_state *m, void *buf, size_t len, int root)
{
    size_t off = 0;
    while (off < len) {
        size_t n = len - off < MPI_PIECE ? len - off : MPI_PIECE;
        if (MPI_Bcast((char *)buf + off, (int)n, MPI_BYTE, root, m->comm) != MPI_SUCCESS) return 1;
        off += n;
    }
    return 0;
}

/* appm_file_reader.read: rank 0 reads, everyone gets {ok, length} and the bytes. */
static int mpi_read(void *user, const char *path, const void **data, size_t *len)
{
    mpi_state *m = (mpi_state *)user;
    unsigned long long head[2] = {0, 0}; /* ok, length */
    char *buf = NULL;
    if (m->rank == 0) {
        FILE *f = fopen(path, "rb");
        size_t cap = 0, n = 0;
        int ok = f != NULL;
        while (ok) {
            size_t got;
            if (n == cap) {
                char *nb = cap > ((size_t)-1) / 2 ? NULL : (char *)realloc(buf, cap ? cap * 2 : 65536);
                if (!nb) {
                    ok = 0;
                    break;
                }
                buf = nb;
                cap = cap ? cap * 2 : 65536;
            }
            got = fread(buf + n, 1, cap - n, f);
            n += got;
            if (got == 0) {
                ok = !ferror(f);
                break;
            }
        }
        if (f) fclose(f);
        head[0] = (unsigned long long)ok;
        head[1] = (unsigned long long)n;
    }
    if (MPI_Bcast(head, 2, MPI_UNSIGNED_LONG_LONG, 0, m->comm) != MPI_SUCCESS || !head[0]) {
        free(buf);
        return 1;
    }
    if (m->rank != 0 && (buf = (char *)malloc(head[1] ? (size_t)head[1] : 1)) == NULL) {
        /* no memory for a file the others hold: end the job rather than diverge */
        fprintf(stderr, "%s: %s: out of memory receiving the file\n", g_who, path);
        MPI_Abort(m->comm, EXIT_RUNTIME);
    }
    if (bcast_bytes(m, buf, (size_t)head[1], 0) != 0) {
        free(buf);
        return 1;
    }
    *data = buf;
    *len = (size_t)head[1];
    return 0;
}

static void mpi_release(void *user, const void *data)
{
    (void)user;
    free((void *)data);
}

/* appm_cluster.allgather: the parts, rank after rank, in place. */
static int mpi_allgather(void *user, void *buf, const size_t *lens)
{
    mpi_state *m = (mpi_state *)user;
    size_t off = 0;
    int k, fits = 1;
    for (k = 0; k < m->ranks; ++k) {
        if (lens[k] > (size_t)INT_MAX || off > (size_t)INT_MAX) fits = 0;
        else {
            m->counts[k] = (int)lens[k];
            m->displs[k] = (int)off;
        }
        off += lens[k];
    }
    if (fits)
        return MPI_Allgatherv(MPI_IN_PLACE, 0, MPI_DATATYPE_NULL, buf, m->counts, m->displs, MPI_BYTE, m->comm) !=
               MPI_SUCCESS;
    for (off = 0, k = 0; k < m->ranks; ++k) { /* beyond 2 GiB: each rank's part broadcast in pieces */
        if (bcast_bytes(m, (char *)buf + off, lens[k], k) != 0) return 1;
        off += lens[k];
    }
    return 0;
}

/* cli_hooks.agree: every rank's exit code; the first failing rank's wins. */
static mpi_state *g_mpi;

static int mpi_agree(int rc, unsigned *who)
{
    mpi_state *m = g_mpi;
    int k, job = EXIT_OK;
    if (MPI_Allgather(&rc, 1, MPI_INT, m->codes, 1, MPI_INT, m->comm) != MPI_SUCCESS) return EXIT_RUNTIME;
    for (k = 0; k < m->ranks; ++k)
        if (m->codes[k] != EXIT_OK) {
            job = m->codes[k];
            *who = (unsigned)k;
            break;
        }
    if (m->fail && ++m->agreed >= m->fail - 1) m->armed = 1;
    return job;
}

static void mpi_abort_job(int rc)
{
    fprintf(stderr, "%s: ending the job\n", g_who);
    MPI_Abort(g_mpi->comm, rc);
}

static int mpi_decide(int code)
{
    if (MPI_Bcast(&code, 1, MPI_INT, 0, g_mpi->comm) != MPI_SUCCESS) return EXIT_RUNTIME;
    return code;
}

/* The test allocator of APPM_MPI_FAIL: malloc until armed, then nothing. */
static void *mpi_alloc(void *user, size_t size)
{
    return ((mpi_state *)user)->armed ? NULL : malloc(size);
}

static void mpi_free(void *user, void *p, size_t size)
{
    (void)user;
    (void)size;
    free(p);
}

/* `render --help` (or -h) anywhere: parse_render would print and exit on every rank. */
static int wants_help(int argc, char **argv)
{
    int i;
    for (i = 2; i < argc; ++i)
        if (strcmp(argv[i], "--help") == 0 || strcmp(argv[i], "-h") == 0) return 1;
    return 0;
}

/* APPM_MPI_FAIL=K:WHEN for rank `rank`: 0 (not this rank, or not well
 * formed), else 1 + the agreements of the setup after which its allocations
 * fail (load: none; create: after the scene's; pass: after the last). */
static int fail_after(const char *s, int rank)
{
    int k = 0, digits = 0;
    if (!s) return 0;
    for (; *s >= '0' && *s <= '9' && k < 1000000; ++s, ++digits) k = 10 * k + (*s - '0');
    if (!digits || k != rank || *s != ':') return 0;
    if (strcmp(s + 1, "load") == 0) return 1;
    if (strcmp(s + 1, "create") == 0) return 2;
    if (strcmp(s + 1, "pass") == 0) return 4; /* render_setup agrees twice, cmd_render once */
    return 0;
}

int main(int argc, char **argv)
{
    static char who[64];
    mpi_state m;
    cli_hooks h;
    const char *fail = getenv("APPM_MPI_FAIL");
    int rc;
    if (MPI_Init(&argc, &argv) != MPI_SUCCESS) {
        fprintf(stderr, "appm: MPI_Init failed\n");
        return EXIT_RUNTIME;
    }
    memset(&m, 0, sizeof m);
    m.comm = MPI_COMM_WORLD;
    MPI_Comm_rank(m.comm, &m.rank);
    MPI_Comm_size(m.comm, &m.ranks);
    g_mpi = &m;
    if (m.rank > 0) {
        snprintf(who, sizeof who, "appm: rank %d", m.rank);
        g_who = who;
    }
    if (argc >= 2 && strcmp(argv[1], "render") == 0 && wants_help(argc, argv)) {
        if (m.rank == 0) fputs(RENDER_HELP, stdout), fputs(RENDER_HELP_LIGHTS, stdout); /* parse_render would exit before MPI_Finalize */
        MPI_Finalize();
        return EXIT_OK;
    }
    if (argc < 2 || strcmp(argv[1], "render") != 0) { /* help, version, info, compare: rank 0 alone */
        rc = m.rank == 0 ? appm_cli(argc, argv) : EXIT_OK;
        MPI_Finalize();
        return rc;
    }
    m.counts = (int *)malloc((size_t)m.ranks * sizeof *m.counts);
    m.displs = (int *)malloc((size_t)m.ranks * sizeof *m.displs);
    m.codes = (int *)malloc((size_t)m.ranks * sizeof *m.codes);
    if (!m.counts || !m.displs || !m.codes) {
        fprintf(stderr, "%s: out of memory\n", g_who);
        MPI_Abort(m.comm, EXIT_RUNTIME);
    }
    m.fail = fail_after(fail, m.rank);
    m.armed = m.fail == 1;
    memset(&h, 0, sizeof h);
    h.rank = (unsigned)m.rank;
    h.ranks = (unsigned)m.ranks;
    h.reader.read = mpi_read;
    h.reader.release = mpi_release;
    h.reader.user = &m;
    h.cluster.rank = (unsigned)m.rank;
    h.cluster.ranks = (unsigned)m.ranks;
    h.cluster.allgather = mpi_allgather;
    h.cluster.user = &m;
    h.agree = mpi_agree;
    h.decide = mpi_decide;
    h.abort_job = mpi_abort_job;
    if (m.fail) {
        h.allocator.alloc = mpi_alloc;
        h.allocator.free = mpi_free;
        h.allocator.user = &m;
    }
    g_cli = &h;
    /* Open MPI's mpirun answers Ctrl-C by killing the ranks, but passes
     * SIGUSR1 on: `kill -USR1 <mpirun's pid>` stops the job after the pass in
     * flight, with the image and the checkpoint written, as Ctrl-C does appm. */
    signal(SIGUSR1, on_sigint);
    rc = appm_cli(argc, argv);
    free(m.counts);
    free(m.displs);
    free(m.codes);
    MPI_Finalize();
    return rc;
}
