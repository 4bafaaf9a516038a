/*
 * report.c - turn appm benchmark logs into tables and log-log plots.
 *
 * Usage: report DIR [--target-rmse X]...
 *
 * Input, all inside DIR:
 *   runs.csv   header "scene,method,config,log", one line per run, e.g.
 *                cornell-sphere,ppm,r0=1x alpha=0.667,cornell-sphere-ppm-r1-a0.667.csv
 *              "log" is relative to DIR (or absolute); method is appm, ppm, sppm or pt.
 *   log files  written by "appm render ... --log FILE.csv": header
 *              "pass,seconds,photons,rmse,relmse", one row per pass; seconds and
 *              photons are cumulative, rmse and relmse may be empty.
 *
 * Output, written into DIR:
 *   results.csv             one row per run: totals, final error and the fitted
 *                           log-log slopes of RMSE vs photons and vs seconds.
 *   SCENE-rmse-time.svg     RMSE vs wall time, one polyline per run.
 *   SCENE-rmse-photons.svg  RMSE vs photon paths emitted (path tracing left out).
 *   report.md               per scene: the plots, an equal-time RMSE table, a
 *                           time-to-target table and the appm / best ppm ratio.
 *
 * Columns are found by their header names, so extra or reordered columns are
 * accepted.  Lines may end in CRLF; blank lines are ignored; fields may be
 * quoted as in RFC 4180.  Rows with an empty, non-finite or non-positive RMSE
 * are left out of fits, plots and tables.  A missing or malformed log is
 * reported on stderr as FILE:LINE and its run is skipped.
 *
 * Exit status: 0 if at least one run was processed; 2 on bad usage or if no
 * run could be processed; 1 if an output file could not be written.
 */
#include "../appm.h"

#include <ctype.h>
#include <errno.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* ------------------------------------------------------------------ memory */

static void die_oom(void)
{
    fprintf(stderr, "report: out of memory\n");
    exit(1);
}

/* realloc for arrays, with the size multiplication checked for overflow. */
static void *xrealloc(void *p, size_t count, size_t size)
{
    void *q;
    size_t bytes;
    if (size && count > (size_t)-1 / size) die_oom();
    bytes = count * size;
    q = realloc(p, bytes > 0 ? bytes : 1);
    if (!q) die_oom();
    return q;
}

/* Makes room for element index n of an array with capacity *cap. */
#define GROW(arr, n, cap)                                                   \
    do {                                                                    \
        if ((n) >= (cap)) {                                                 \
            (cap) = (cap) ? 2 * (cap) : 16;                                 \
            (arr) = xrealloc((arr), (cap), sizeof *(arr));                  \
        }                                                                   \
    } while (0)

static char *xstrdup(const char *s)
{
    size_t n = strlen(s) + 1;
    char *d = xrealloc(NULL, n, 1);
    memcpy(d, s, n);
    return d;
}

static char *join_path(const char *dir, const char *name)
{
    size_t a = strlen(dir), b = strlen(name);
    int sep = a > 0 && dir[a - 1] != '/';
    char *p;
    if (name[0] == '/') return xstrdup(name);
    p = xrealloc(NULL, a + b + 2, 1);
    memcpy(p, dir, a);
    if (sep) p[a] = '/';
    memcpy(p + a + sep, name, b + 1);
    return p;
}

/* --------------------------------------------------------------- CSV input */

/* Reads one line of any length into *buf (grown as needed) and strips the
 * line ending, so files written on Windows (CRLF) read the same.  Returns 0 at
 * end of file when nothing was read, 1 otherwise. */
static int read_line(FILE *f, char **buf, size_t *cap)
{
    size_t len = 0;
    int c = EOF;
    if (!*buf) {
        *cap = 256;
        *buf = xrealloc(NULL, *cap, 1);
    }
    while ((c = getc(f)) != EOF && c != '\n') {
        if (len + 1 >= *cap) {
            *cap *= 2;
            *buf = xrealloc(*buf, *cap, 1);
        }
        (*buf)[len++] = (char)c;
    }
    if (c == EOF && len == 0) return 0;
    while (len > 0 && (*buf)[len - 1] == '\r') len--;
    (*buf)[len] = '\0';
    return 1;
}

static int is_blank(const char *s)
{
    while (*s && isspace((unsigned char)*s)) s++;
    return *s == '\0';
}

static char *trim(char *s)
{
    char *e;
    while (*s && isspace((unsigned char)*s)) s++;
    e = s + strlen(s);
    while (e > s && isspace((unsigned char)e[-1])) *--e = '\0';
    return s;
}

typedef struct {
    char **f;
    size_t n, cap;
} Fields;

/* Splits line in place into comma-separated fields, undoing RFC 4180 quoting
 * ("a,b" and "say ""hi"""); fields are trimmed.  Returns -1 on a malformed
 * quote. */
static int split_csv(char *line, Fields *out)
{
    char *r = line;
    out->n = 0;
    for (;;) {
        char *start = r, *w = r, end;
        if (*r == '"') {
            r++;
            for (;;) {
                if (*r == '\0') return -1;
                if (*r == '"') {
                    if (r[1] != '"') break;
                    r++;
                }
                *w++ = *r++;
            }
            r++;
            while (*r == ' ' || *r == '\t') r++;
            if (*r != ',' && *r != '\0') return -1;
        } else {
            while (*r && *r != ',') r++;
            w = r;
        }
        /* w trails r inside quoted fields, so remember the separator first. */
        end = *r;
        *w = '\0';
        GROW(out->f, out->n, out->cap);
        out->f[out->n++] = trim(start);
        if (end == '\0') return 0;
        r++;
    }
}

/* Strict number parse: unlike bare strtod, "1.5abc" and "" are rejected. */
static int parse_num(const char *s, double *v)
{
    char *end;
    if (*s == '\0') return 0;
    errno = 0;
    *v = strtod(s, &end);
    if (end == s) return 0;
    while (*end && isspace((unsigned char)*end)) end++;
    return *end == '\0';
}

static void complain(const char *file, unsigned long line, const char *fmt, ...)
{
    va_list ap;
    if (line) fprintf(stderr, "report: %s:%lu: ", file, line);
    else fprintf(stderr, "report: %s: ", file);
    va_start(ap, fmt);
    vfprintf(stderr, fmt, ap);
    va_end(ap);
    fputc('\n', stderr);
}

/* ------------------------------------------------------------------- model */

typedef struct {
    double pass, seconds, photons, rmse, relmse;
} Row;

typedef struct {
    char *scene, *method, *config, *log;
    Row *pt;                      /* rows with a usable RMSE, in file order   */
    size_t npt, cappt;
    double passes, seconds, photons; /* from the last row, usable or not      */
    double final_rmse, final_relmse;
    int x_is_pass;                /* no photons (pt): "photons" slope is vs pass */
    double slope_x, slope_t;
    double eq_rmse;               /* RMSE at the scene's equal time T         */
    int style, thick;             /* palette index, drawn heavier             */
} Run;

typedef struct {
    char *name, *stem;            /* stem: name made safe as a file name      */
    size_t *run, nrun, caprun;    /* indices into the run array               */
    double T;                     /* equal time: every run got this far       */
    double own_target[3];         /* defaults, when none were given            */
    const double *target;
    size_t ntarget;
} Scene;

enum { X_TIME, X_PHOTONS, X_PASS };

static double xval(const Row *p, int axis)
{
    return axis == X_TIME ? p->seconds : axis == X_PHOTONS ? p->photons : p->pass;
}

static int is_method(const Run *r, const char *m) { return strcmp(r->method, m) == 0; }

enum { C_PASS, C_SECONDS, C_PHOTONS, C_RMSE, C_RELMSE, NCOL };
static const char *const col_name[NCOL] = { "pass", "seconds", "photons", "rmse", "relmse" };

/* Reads one log into r.  Any structural problem rejects the whole run rather
 * than plotting half a curve that would look like a real result. */
static int load_log(Run *r, const char *path)
{
    FILE *f = fopen(path, "r");
    char *line = NULL;
    size_t cap = 0, need = 0, nrows = 0, i;
    unsigned long lineno = 0;
    Fields fl = { NULL, 0, 0 };
    int col[NCOL], have_header = 0, ok = 1, c;

    if (!f) {
        complain(path, 0, "cannot open: %s", strerror(errno));
        return -1;
    }
    for (c = 0; c < NCOL; c++) col[c] = -1;
    while (ok && read_line(f, &line, &cap)) {
        double v[NCOL];
        lineno++;
        if (is_blank(line)) continue;
        if (split_csv(line, &fl) < 0) {
            complain(path, lineno, "unbalanced quotes");
            ok = 0;
            break;
        }
        if (!have_header) {
            for (i = 0; i < fl.n; i++)
                for (c = 0; c < NCOL; c++)
                    if (col[c] < 0 && strcmp(fl.f[i], col_name[c]) == 0) col[c] = (int)i;
            for (c = 0; c < C_RELMSE; c++) /* relmse is optional */
                if (col[c] < 0) {
                    complain(path, lineno, "header lacks column '%s'", col_name[c]);
                    ok = 0;
                }
            for (c = 0; c < NCOL; c++)
                if (col[c] >= 0 && (size_t)col[c] + 1 > need) need = (size_t)col[c] + 1;
            have_header = 1;
            continue;
        }
        if (fl.n < need) {
            complain(path, lineno, "expected %lu fields, found %lu", (unsigned long)need,
                     (unsigned long)fl.n);
            ok = 0;
            break;
        }
        for (c = 0; c < NCOL && ok; c++) {
            const char *s = col[c] >= 0 ? fl.f[col[c]] : "";
            if (c >= C_RMSE) {
                /* Error columns are blank when no reference was given, and a
                 * NaN there only means "not measured". */
                if (*s == '\0') v[c] = NAN;
                else if (!parse_num(s, &v[c])) ok = 0;
                else if (!isfinite(v[c])) v[c] = NAN;
            } else if (!parse_num(s, &v[c]) || !isfinite(v[c])) {
                ok = 0;
            }
            if (!ok) complain(path, lineno, "bad %s value '%s'", col_name[c], s);
        }
        if (!ok) break;
        nrows++;
        r->passes = v[C_PASS];
        r->seconds = v[C_SECONDS];
        r->photons = v[C_PHOTONS];
        if (v[C_RMSE] > 0) {
            Row *p;
            GROW(r->pt, r->npt, r->cappt);
            p = &r->pt[r->npt++];
            p->pass = v[C_PASS];
            p->seconds = v[C_SECONDS];
            p->photons = v[C_PHOTONS];
            p->rmse = v[C_RMSE];
            p->relmse = v[C_RELMSE];
        }
    }
    if (ok && ferror(f)) {
        complain(path, lineno, "read error");
        ok = 0;
    }
    if (ok && !have_header) {
        complain(path, 0, "empty file, no header");
        ok = 0;
    } else if (ok && nrows == 0) {
        complain(path, lineno, "no data rows");
        ok = 0;
    } else if (ok && r->npt == 0) {
        complain(path, lineno, "no row has an RMSE > 0");
        ok = 0;
    }
    fclose(f);
    free(line);
    free(fl.f);
    return ok ? 0 : -1;
}

/* ------------------------------------------------------------------ maths */

/* Interpolates y(x) linearly in log-log space; power laws come out exact. */
static double log_interp(double x0, double y0, double x1, double y1, double x)
{
    double t;
    if (x1 == x0) return y1;
    t = (log(x) - log(x0)) / (log(x1) - log(x0));
    return exp(log(y0) + t * (log(y1) - log(y0)));
}

/* Least-squares slope of log RMSE vs log x.  Only the upper two thirds of the
 * log-x range take part: the first passes are dominated by the initial radius
 * and would bend the asymptotic rate we are after. */
static double fit_slope(const Run *r, int axis)
{
    double lmin = HUGE_VAL, lmax = -HUGE_VAL, thr, mx = 0, my = 0, sxx = 0, sxy = 0;
    size_t i, n = 0;
    for (i = 0; i < r->npt; i++) {
        double x = xval(&r->pt[i], axis);
        if (x > 0) {
            double l = log(x);
            if (l < lmin) lmin = l;
            if (l > lmax) lmax = l;
        }
    }
    if (!(lmax > lmin)) return NAN;
    thr = lmin + (lmax - lmin) / 3 - 1e-12 * (1 + fabs(lmin));
    for (i = 0; i < r->npt; i++) {
        double x = xval(&r->pt[i], axis);
        if (x > 0 && log(x) >= thr) {
            mx += log(x);
            my += log(r->pt[i].rmse);
            n++;
        }
    }
    if (n < 2) return NAN;
    mx /= (double)n;
    my /= (double)n;
    for (i = 0; i < r->npt; i++) {
        double x = xval(&r->pt[i], axis);
        if (x > 0 && log(x) >= thr) {
            double dx = log(x) - mx;
            sxx += dx * dx;
            sxy += dx * (log(r->pt[i].rmse) - my);
        }
    }
    return sxx > 0 ? sxy / sxx : NAN;
}

static double max_time(const Run *r)
{
    double m = NAN;
    size_t i;
    for (i = 0; i < r->npt; i++)
        if (r->pt[i].seconds > 0 && !(r->pt[i].seconds <= m)) m = r->pt[i].seconds;
    return m;
}

/* RMSE at time T; NaN when the run's first measurement came after T. */
static double rmse_at_time(const Run *r, double T)
{
    const Row *prev = NULL;
    size_t i;
    if (!(T > 0)) return NAN;
    for (i = 0; i < r->npt; i++) {
        const Row *p = &r->pt[i];
        if (!(p->seconds > 0)) continue;
        if (p->seconds == T) return p->rmse;
        if (p->seconds > T)
            return prev ? log_interp(prev->seconds, prev->rmse, p->seconds, p->rmse, T) : NAN;
        prev = p;
    }
    return NAN;
}

/* First time the RMSE drops to target; NaN if it never does. */
static double time_to_reach(const Run *r, double target)
{
    const Row *prev = NULL;
    size_t i;
    for (i = 0; i < r->npt; i++) {
        const Row *p = &r->pt[i];
        if (!(p->seconds > 0)) continue;
        if (p->rmse <= target)
            return prev ? log_interp(prev->rmse, prev->seconds, p->rmse, p->seconds, target)
                        : p->seconds;
        prev = p;
    }
    return NAN;
}

static int cmp_double(const void *a, const void *b)
{
    double x = *(const double *)a, y = *(const double *)b;
    return (x > y) - (x < y);
}

static double median(double *v, size_t n)
{
    if (n == 0) return NAN;
    qsort(v, n, sizeof *v, cmp_double);
    return n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

/* Index of the run of the given method with the lowest equal-time RMSE (or
 * lowest final RMSE when by_final), or -1. */
static long best_run(const Scene *s, const Run *runs, const char *method, int by_final)
{
    long best = -1;
    double bv = HUGE_VAL;
    size_t k;
    for (k = 0; k < s->nrun; k++) {
        const Run *r = &runs[s->run[k]];
        double v = by_final ? r->final_rmse : r->eq_rmse;
        if (is_method(r, method) && v < bv) {
            bv = v;
            best = (long)s->run[k];
        }
    }
    return best;
}

/* -------------------------------------------------------------------- SVG */

/* Okabe-Ito, ordered so that the low-contrast yellow comes last. */
static const char *const palette[] = { "#0072B2", "#D55E00", "#009E73", "#CC79A7",
                                       "#E69F00", "#56B4E9", "#000000", "#F0E442" };
#define NPALETTE (sizeof palette / sizeof palette[0])
/* Once the colours run out, later runs repeat them with a dash pattern. */
static const char *const dashes[] = { NULL, "8 3", "2 2", "8 3 2 3" };
#define NDASHES (sizeof dashes / sizeof dashes[0])

typedef struct {
    FILE *f;
    double left, right, top, bottom;       /* plot area in pixels           */
    double xlo, xhi, ylo, yhi;             /* axis range in log10 units     */
} Plot;

/* Keeps every coordinate finite and sane, so no NaN or inf can reach the
 * file whatever the data did. */
static double safe(double v)
{
    if (!isfinite(v)) return 0;
    return v < -1e6 ? -1e6 : v > 1e6 ? 1e6 : v;
}

static double px(const Plot *p, double lx)
{
    return safe(p->left + (lx - p->xlo) / (p->xhi - p->xlo) * (p->right - p->left));
}

static double py(const Plot *p, double ly)
{
    return safe(p->bottom - (ly - p->ylo) / (p->yhi - p->ylo) * (p->bottom - p->top));
}

static void xml_text(FILE *f, const char *s)
{
    for (; *s; s++) switch (*s) {
        case '&': fputs("&amp;", f); break;
        case '<': fputs("&lt;", f); break;
        case '>': fputs("&gt;", f); break;
        case '"': fputs("&quot;", f); break;
        default:
            /* Control characters are not allowed in XML 1.0. */
            if ((unsigned char)*s >= 0x20 || *s == '\t') fputc(*s, f);
    }
}

static void svg_text(FILE *f, double x, double y, const char *anchor, int size,
                     const char *extra, const char *text)
{
    fprintf(f, "<text x=\"%.2f\" y=\"%.2f\" text-anchor=\"%s\" font-size=\"%d\"%s%s>", safe(x),
            safe(y), anchor, size, extra ? " " : "", extra ? extra : "");
    xml_text(f, text);
    fputs("</text>\n", f);
}

static void run_label(const Run *r, char **buf, size_t *cap)
{
    size_t n = strlen(r->method) + strlen(r->config) + 2;
    if (n > *cap) {
        *cap = n;
        *buf = xrealloc(*buf, n, 1);
    }
    strcpy(*buf, r->method);
    if (r->config[0]) {
        strcat(*buf, " ");
        strcat(*buf, r->config);
    }
}

static int usable(double x, double y) { return x > 0 && y > 0 && isfinite(x) && isfinite(y); }

/* Lower and upper decade around [lmin, lmax]; always at least one decade. */
static void decades(double lmin, double lmax, double *lo, double *hi)
{
    *lo = floor(lmin + 1e-9);
    *hi = ceil(lmax - 1e-9);
    if (*hi <= *lo) {
        *lo -= 1;
        *hi += 1;
    }
}

static void axes(const Plot *p, const char *xlabel)
{
    FILE *f = p->f;
    char lab[32];
    double d;
    /* Label every decade unless that would crowd the axis. */
    int xstep = (int)ceil((p->xhi - p->xlo) / 10), ystep = (int)ceil((p->yhi - p->ylo) / 10);
    if (xstep < 1) xstep = 1;
    if (ystep < 1) ystep = 1;

    fputs("<g stroke=\"#000\" stroke-width=\"1\">\n", f);
    for (d = p->xlo; d <= p->xhi + 0.5; d += 1) {
        int m;
        double x = px(p, d);
        fprintf(f, "<line x1=\"%.2f\" y1=\"%.2f\" x2=\"%.2f\" y2=\"%.2f\" stroke=\"#e0e0e0\"/>\n",
                x, p->top, x, p->bottom);
        fprintf(f, "<line x1=\"%.2f\" y1=\"%.2f\" x2=\"%.2f\" y2=\"%.2f\"/>\n", x, p->bottom, x,
                p->bottom - 8);
        for (m = 2; m <= 9 && d < p->xhi - 0.5; m++) {
            double xm = px(p, d + log10((double)m));
            fprintf(f, "<line x1=\"%.2f\" y1=\"%.2f\" x2=\"%.2f\" y2=\"%.2f\"/>\n", xm, p->bottom,
                    xm, p->bottom - 4);
        }
    }
    for (d = p->ylo; d <= p->yhi + 0.5; d += 1) {
        int m;
        double y = py(p, d);
        fprintf(f, "<line x1=\"%.2f\" y1=\"%.2f\" x2=\"%.2f\" y2=\"%.2f\" stroke=\"#e0e0e0\"/>\n",
                p->left, y, p->right, y);
        fprintf(f, "<line x1=\"%.2f\" y1=\"%.2f\" x2=\"%.2f\" y2=\"%.2f\"/>\n", p->left, y,
                p->left + 8, y);
        for (m = 2; m <= 9 && d < p->yhi - 0.5; m++) {
            double ym = py(p, d + log10((double)m));
            fprintf(f, "<line x1=\"%.2f\" y1=\"%.2f\" x2=\"%.2f\" y2=\"%.2f\"/>\n", p->left, ym,
                    p->left + 4, ym);
        }
    }
    fprintf(f, "<rect x=\"%.2f\" y=\"%.2f\" width=\"%.2f\" height=\"%.2f\" fill=\"none\"/>\n",
            p->left, p->top, p->right - p->left, p->bottom - p->top);
    fputs("</g>\n", f);

    for (d = p->xlo; d <= p->xhi + 0.5; d += 1)
        if ((long)(d - p->xlo) % xstep == 0) {
            sprintf(lab, "1e%ld", (long)d);
            svg_text(f, px(p, d), p->bottom + 18, "middle", 12, NULL, lab);
        }
    for (d = p->ylo; d <= p->yhi + 0.5; d += 1)
        if ((long)(d - p->ylo) % ystep == 0) {
            sprintf(lab, "1e%ld", (long)d);
            svg_text(f, p->left - 8, py(p, d) + 4, "end", 12, NULL, lab);
        }
    svg_text(f, 0.5 * (p->left + p->right), p->bottom + 42, "middle", 14, NULL, xlabel);
    fprintf(f, "<text x=\"0\" y=\"0\" text-anchor=\"middle\" font-size=\"14\" "
               "transform=\"translate(%.2f %.2f) rotate(-90)\">RMSE</text>\n",
            p->left - 58, 0.5 * (p->top + p->bottom));
}

/* Dashed reference line of the given slope from the anchor to where it leaves
 * the plot on the right or the bottom, labelled at its far end. */
static void guide(const Plot *p, double lx0, double ly0, double slope, const char *label)
{
    double lx1 = p->xhi, ly1 = ly0 + slope * (p->xhi - lx0);
    if (ly1 < p->ylo) {
        lx1 = lx0 + (p->ylo - ly0) / slope;
        ly1 = p->ylo;
    }
    if (!(lx1 - lx0 > 1e-9)) return;
    fprintf(p->f,
            "<line x1=\"%.2f\" y1=\"%.2f\" x2=\"%.2f\" y2=\"%.2f\" stroke=\"#666\" "
            "stroke-width=\"1.2\" stroke-dasharray=\"6 4\"/>\n",
            px(p, lx0), py(p, ly0), px(p, lx1), py(p, ly1));
    /* A white halo keeps the label readable where its own line crosses it. */
    svg_text(p->f, px(p, lx1) - 4, py(p, ly1) - 6, "end", 12,
             "fill=\"#444\" stroke=\"#fff\" stroke-width=\"3\" paint-order=\"stroke\"", label);
}

/* Writes one log-log plot of RMSE against axis (X_TIME or X_PHOTONS) for the
 * runs of scene s.  Returns -1 if the file could not be written. */
static int write_plot(const char *path, const Scene *s, const Run *runs, int axis,
                      const char *title, const char *xlabel)
{
    Plot p;
    FILE *f;
    size_t k, i, nplot = 0, maxlab = 0;
    double lxmin = HUGE_VAL, lxmax = -HUGE_VAL, lymin = HUGE_VAL, lymax = -HUGE_VAL;
    double width, height;
    long anchor = -1;
    char *lab = NULL;
    size_t labcap = 0;
    int rc;

    for (k = 0; k < s->nrun; k++) {
        const Run *r = &runs[s->run[k]];
        int any = 0;
        if (axis == X_PHOTONS && r->x_is_pass) continue;
        for (i = 0; i < r->npt; i++) {
            double x = xval(&r->pt[i], axis), y = r->pt[i].rmse;
            if (!usable(x, y)) continue;
            any = 1;
            if (log10(x) < lxmin) lxmin = log10(x);
            if (log10(x) > lxmax) lxmax = log10(x);
            if (log10(y) < lymin) lymin = log10(y);
            if (log10(y) > lymax) lymax = log10(y);
        }
        if (!any) continue;
        nplot++;
        run_label(r, &lab, &labcap);
        if (strlen(lab) > maxlab) maxlab = strlen(lab);
        /* Guides start at the best appm run, else at the first run drawn. */
        if (anchor < 0 ||
            (is_method(r, "appm") && (!is_method(&runs[anchor], "appm") ||
                                      r->final_rmse < runs[anchor].final_rmse)))
            anchor = (long)s->run[k];
    }

    f = fopen(path, "w");
    if (!f) {
        complain(path, 0, "cannot write: %s", strerror(errno));
        free(lab);
        return -1;
    }
    p.f = f;
    p.left = 90;
    p.top = 50;
    p.right = 640;
    p.bottom = 460;
    width = p.right + 60 + 7.0 * (double)maxlab + 20;
    if (width < 900) width = 900;
    height = p.bottom + 60;
    if (p.top + 22.0 * (double)nplot + 20 > height) height = p.top + 22.0 * (double)nplot + 20;

    fprintf(f, "<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n"
               "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"%.0f\" height=\"%.0f\" "
               "viewBox=\"0 0 %.0f %.0f\" font-family=\"Helvetica, Arial, sans-serif\">\n"
               "<rect width=\"100%%\" height=\"100%%\" fill=\"#fff\"/>\n",
            width, height, width, height);
    svg_text(f, 0.5 * (p.left + p.right), 28, "middle", 16, "font-weight=\"bold\"", title);

    if (nplot == 0) {
        p.xlo = p.ylo = 0;
        p.xhi = p.yhi = 1;
        fprintf(f, "<rect x=\"%.2f\" y=\"%.2f\" width=\"%.2f\" height=\"%.2f\" fill=\"none\" "
                   "stroke=\"#000\"/>\n",
                p.left, p.top, p.right - p.left, p.bottom - p.top);
        svg_text(f, 0.5 * (p.left + p.right), 0.5 * (p.top + p.bottom), "middle", 14, NULL,
                 "no data");
    } else {
        decades(lxmin, lxmax, &p.xlo, &p.xhi);
        decades(lymin, lymax, &p.ylo, &p.yhi);
        axes(&p, xlabel);
        fprintf(f, "<clipPath id=\"plotarea\"><rect x=\"%.2f\" y=\"%.2f\" width=\"%.2f\" "
                   "height=\"%.2f\"/></clipPath>\n<g clip-path=\"url(#plotarea)\">\n",
                p.left, p.top, p.right - p.left, p.bottom - p.top);

        /* Guides first, so the data is drawn over them. */
        if (anchor >= 0) {
            const Run *r = &runs[anchor];
            for (i = 0; i < r->npt; i++)
                if (usable(xval(&r->pt[i], axis), r->pt[i].rmse)) break;
            if (i < r->npt) {
                double lx0 = log10(xval(&r->pt[i], axis)), ly0 = log10(r->pt[i].rmse);
                guide(&p, lx0, ly0, -1.0 / 3.0, "slope -1/3");
                guide(&p, lx0, ly0, -1.0 / 2.0, "slope -1/2");
            }
        }
        for (k = 0; k < s->nrun; k++) {
            const Run *r = &runs[s->run[k]];
            const char *colour = palette[(size_t)r->style % NPALETTE];
            const char *dash = dashes[((size_t)r->style / NPALETTE) % NDASHES];
            double lastx = -1e9, lasty = -1e9, fx = 0, fy = 0;
            size_t n = 0;
            if (axis == X_PHOTONS && r->x_is_pass) continue;
            fprintf(f, "<polyline fill=\"none\" stroke=\"%s\" stroke-width=\"%s\" "
                       "stroke-linejoin=\"round\"",
                    colour, r->thick ? "3" : "1.5");
            if (dash) fprintf(f, " stroke-dasharray=\"%s\"", dash);
            fputs(" points=\"", f);
            for (i = 0; i < r->npt; i++) {
                double x = xval(&r->pt[i], axis), y = r->pt[i].rmse;
                int last;
                if (!usable(x, y)) continue;
                fx = px(&p, log10(x));
                fy = py(&p, log10(y));
                /* Long logs have thousands of passes; points closer than
                 * half a pixel to the previous one add bytes, not detail. */
                last = i + 1 == r->npt;
                if (n > 0 && !last && fabs(fx - lastx) < 0.5 && fabs(fy - lasty) < 0.5) continue;
                fprintf(f, "%s%.2f,%.2f", n ? " " : "", fx, fy);
                lastx = fx;
                lasty = fy;
                n++;
            }
            fputs("\"/>\n", f);
            /* A marker on the final point keeps one-point runs visible. */
            if (n > 0)
                fprintf(f, "<circle cx=\"%.2f\" cy=\"%.2f\" r=\"%s\" fill=\"%s\"/>\n", fx, fy,
                        r->thick ? "4" : "3", colour);
        }

        fputs("</g>\n", f);

        /* Legend to the right of the plot, in run order. */
        i = 0;
        for (k = 0; k < s->nrun; k++) {
            const Run *r = &runs[s->run[k]];
            const char *dash = dashes[((size_t)r->style / NPALETTE) % NDASHES];
            double y = p.top + 10 + 22.0 * (double)i;
            int any = 0;
            size_t j;
            if (axis == X_PHOTONS && r->x_is_pass) continue;
            for (j = 0; j < r->npt && !any; j++) any = usable(xval(&r->pt[j], axis), r->pt[j].rmse);
            if (!any) continue;
            fprintf(f, "<line x1=\"%.2f\" y1=\"%.2f\" x2=\"%.2f\" y2=\"%.2f\" stroke=\"%s\" "
                       "stroke-width=\"%s\"",
                    p.right + 20, y, p.right + 50, y, palette[(size_t)r->style % NPALETTE],
                    r->thick ? "3" : "1.5");
            if (dash) fprintf(f, " stroke-dasharray=\"%s\"", dash);
            fputs("/>\n", f);
            run_label(r, &lab, &labcap);
            svg_text(f, p.right + 58, y + 4, "start", 12, NULL, lab);
            i++;
        }
    }
    fputs("</svg>\n", f);
    free(lab);
    rc = ferror(f) ? -1 : 0;
    if (fclose(f) != 0) rc = -1;
    if (rc) complain(path, 0, "write error");
    return rc;
}

/* ---------------------------------------------------------------- writers */

static void csv_field(FILE *f, const char *s)
{
    if (strpbrk(s, ",\"\r\n")) {
        fputc('"', f);
        for (; *s; s++) {
            if (*s == '"') fputc('"', f);
            fputc(*s, f);
        }
        fputc('"', f);
    } else {
        fputs(s, f);
    }
}

static void csv_num(FILE *f, double v)
{
    fputc(',', f);
    if (isfinite(v)) fprintf(f, "%.10g", v);
}

/* Markdown table cell: pipes would end the cell early. */
static void md_text(FILE *f, const char *s)
{
    for (; *s; s++) {
        if (*s == '|') fputc('\\', f);
        fputc(*s == '\n' ? ' ' : *s, f);
    }
}

static void md_num(FILE *f, double v, const char *suffix)
{
    if (isfinite(v)) fprintf(f, " %.4g%s |", v, suffix);
    else fputs(" \xE2\x80\x94 |", f); /* em dash */
}

static int close_checked(FILE *f, const char *path)
{
    int bad = ferror(f);
    if (fclose(f) != 0) bad = 1;
    if (bad) complain(path, 0, "write error");
    return bad ? -1 : 0;
}

static int write_results(const char *path, const Run *runs, size_t nrun)
{
    FILE *f = fopen(path, "w");
    size_t i;
    if (!f) {
        complain(path, 0, "cannot write: %s", strerror(errno));
        return -1;
    }
    fputs("scene,method,config,passes,seconds,photons,final_rmse,final_relmse,"
          "slope_rmse_photons,slope_rmse_time,x_for_slope\n",
          f);
    for (i = 0; i < nrun; i++) {
        const Run *r = &runs[i];
        if (r->npt == 0) continue;
        csv_field(f, r->scene);
        fputc(',', f);
        csv_field(f, r->method);
        fputc(',', f);
        csv_field(f, r->config);
        csv_num(f, r->passes);
        csv_num(f, r->seconds);
        csv_num(f, r->photons);
        csv_num(f, r->final_rmse);
        csv_num(f, r->final_relmse);
        csv_num(f, r->slope_x);
        csv_num(f, r->slope_t);
        fputs(r->x_is_pass ? ",passes\n" : ",photons\n", f);
    }
    return close_checked(f, path);
}

static int write_report(const char *path, const Scene *scenes, size_t nscene, const Run *runs)
{
    FILE *f = fopen(path, "w");
    size_t si, k, t;
    if (!f) {
        complain(path, 0, "cannot write: %s", strerror(errno));
        return -1;
    }
    fputs("# appm benchmark report\n\n"
          "Equal-time RMSE is taken at T, the longest wall time that every run of the scene\n"
          "reached.  Values between logged passes are interpolated linearly in log-log space.\n"
          "Slopes are least-squares fits of log RMSE against log photon paths (log passes for\n"
          "path tracing, which emits no photons) and against log seconds, over the upper two\n"
          "thirds of each run's logged range.  A run already below a target at its first\n"
          "logged pass is credited with that pass's time.  \xE2\x80\x94 means not reached.\n",
          f);
    for (si = 0; si < nscene; si++) {
        const Scene *s = &scenes[si];
        long ba = best_run(s, runs, "appm", 0), bp = best_run(s, runs, "ppm", 0);

        fputs("\n## ", f);
        md_text(f, s->name);
        fputs("\n\n", f);
        fprintf(f, "![%s: RMSE vs time](%s-rmse-time.svg)\n\n", s->stem, s->stem);
        fprintf(f, "![%s: RMSE vs photons](%s-rmse-photons.svg)\n\n", s->stem, s->stem);

        if (isfinite(s->T)) fprintf(f, "### Equal-time RMSE at T = %.4g s\n\n", s->T);
        else fputs("### Equal-time RMSE (no common time)\n\n", f);
        fputs("| method | config | RMSE at T | final RMSE | slope vs photons | slope vs time |\n"
              "|---|---|---:|---:|---:|---:|\n",
              f);
        for (k = 0; k < s->nrun; k++) {
            const Run *r = &runs[s->run[k]];
            fputs("| ", f);
            md_text(f, r->method);
            fputs(" | ", f);
            md_text(f, r->config);
            fputs(" |", f);
            md_num(f, r->eq_rmse, "");
            md_num(f, r->final_rmse, "");
            md_num(f, r->slope_x, r->x_is_pass ? " (vs passes)" : "");
            md_num(f, r->slope_t, "");
            fputc('\n', f);
        }

        fputs("\n### Time to reach RMSE (seconds)\n\n| method | config |", f);
        for (t = 0; t < s->ntarget; t++) fprintf(f, " RMSE %.4g |", s->target[t]);
        fputs("\n|---|---|", f);
        for (t = 0; t < s->ntarget; t++) fputs("---:|", f);
        fputc('\n', f);
        for (k = 0; k < s->nrun; k++) {
            const Run *r = &runs[s->run[k]];
            fputs("| ", f);
            md_text(f, r->method);
            fputs(" | ", f);
            md_text(f, r->config);
            fputs(" |", f);
            for (t = 0; t < s->ntarget; t++) md_num(f, time_to_reach(r, s->target[t]), "");
            fputc('\n', f);
        }

        fputs("\nappm / best ppm equal-time RMSE ratio: ", f);
        if (ba >= 0 && bp >= 0) {
            fprintf(f, "%.4g (appm ", runs[ba].eq_rmse / runs[bp].eq_rmse);
            md_text(f, runs[ba].config);
            fputs(", ppm ", f);
            md_text(f, runs[bp].config);
            fputs(")\n", f);
        } else {
            fprintf(f, "\xE2\x80\x94 (%s)\n",
                    best_run(s, runs, "appm", 1) < 0 ? "no appm run"
                    : best_run(s, runs, "ppm", 1) < 0 ? "no ppm run"
                                                      : "no equal-time RMSE");
        }
    }
    return close_checked(f, path);
}

/* ------------------------------------------------------------------- main */

static void usage(FILE *f)
{
    fputs("usage: report DIR [--target-rmse X]...\n"
          "Reads DIR/runs.csv and the logs it lists; writes results.csv, report.md and\n"
          "SCENE-rmse-time.svg / SCENE-rmse-photons.svg into DIR.\n",
          f);
}

/* Scene names become file names: keep them inside DIR and shell-friendly. */
static char *make_stem(const char *name, const Scene *scenes, size_t nscene)
{
    size_t n = strlen(name), i, suffix = 1;
    char *stem = xrealloc(NULL, n + 24, 1);
    for (i = 0; i < n; i++) {
        unsigned char c = (unsigned char)name[i];
        stem[i] = (char)(isalnum(c) || c == '-' || c == '_' || (c == '.' && i > 0) ? c : '_');
    }
    stem[n] = '\0';
    if (n == 0) strcpy(stem, "scene");
    for (;;) {
        int clash = 0;
        for (i = 0; i < nscene && !clash; i++) clash = strcmp(scenes[i].stem, stem) == 0;
        if (!clash) return stem;
        sprintf(stem + (n ? n : 5), "-%lu", (unsigned long)++suffix);
    }
}

int main(int argc, char **argv)
{
    const char *dir = NULL;
    double *targets = NULL;
    size_t ntargets = 0, captargets = 0;
    Run *runs = NULL;
    size_t nrun = 0, caprun = 0, nscene = 0, capscene = 0, i, k;
    Scene *scenes = NULL;
    char *path, *line = NULL;
    size_t linecap = 0;
    Fields fl = { NULL, 0, 0 };
    FILE *f;
    unsigned long lineno = 0;
    int col[4] = { -1, -1, -1, -1 }, have_header = 0, failed = 0;
    static const char *const runs_cols[4] = { "scene", "method", "config", "log" };

    for (i = 1; i < (size_t)argc; i++) {
        const char *a = argv[i], *val = NULL;
        if (strcmp(a, "-h") == 0 || strcmp(a, "--help") == 0) {
            usage(stdout);
            return 0;
        }
        if (strcmp(a, "--target-rmse") == 0) {
            if (i + 1 >= (size_t)argc) {
                fprintf(stderr, "report: --target-rmse needs a value\n");
                return 2;
            }
            val = argv[++i];
        } else if (strncmp(a, "--target-rmse=", 14) == 0) {
            val = a + 14;
        }
        if (val) {
            double v;
            if (!parse_num(val, &v) || !isfinite(v) || v <= 0) {
                fprintf(stderr, "report: --target-rmse: '%s' is not a positive number\n", val);
                return 2;
            }
            GROW(targets, ntargets, captargets);
            targets[ntargets++] = v;
        } else if (a[0] == '-' && a[1] != '\0') {
            fprintf(stderr, "report: unknown option '%s'\n", a);
            usage(stderr);
            return 2;
        } else if (!dir) {
            dir = a;
        } else {
            fprintf(stderr, "report: more than one DIR given\n");
            usage(stderr);
            return 2;
        }
    }
    if (!dir) {
        usage(stderr);
        return 2;
    }

    /* runs.csv: one run per line; bad lines are skipped, not fatal. */
    path = join_path(dir, "runs.csv");
    f = fopen(path, "r");
    if (!f) {
        complain(path, 0, "cannot open: %s", strerror(errno));
        free(path);
        free(targets);
        return 2;
    }
    while (read_line(f, &line, &linecap)) {
        Run r;
        char *logpath;
        lineno++;
        if (is_blank(line)) continue;
        if (split_csv(line, &fl) < 0) {
            complain(path, lineno, "unbalanced quotes; line skipped");
            continue;
        }
        if (!have_header) {
            int c, bad = 0;
            for (k = 0; k < fl.n; k++)
                for (c = 0; c < 4; c++)
                    if (col[c] < 0 && strcmp(fl.f[k], runs_cols[c]) == 0) col[c] = (int)k;
            for (c = 0; c < 4; c++)
                if (col[c] < 0) {
                    complain(path, lineno, "header lacks column '%s'", runs_cols[c]);
                    bad = 1;
                }
            if (bad) break;
            have_header = 1;
            continue;
        }
        if (fl.n < 4 || (size_t)col[0] >= fl.n || (size_t)col[1] >= fl.n ||
            (size_t)col[2] >= fl.n || (size_t)col[3] >= fl.n || fl.f[col[3]][0] == '\0') {
            complain(path, lineno, "expected scene,method,config,log; line skipped");
            continue;
        }
        memset(&r, 0, sizeof r);
        r.scene = xstrdup(fl.f[col[0]]);
        r.method = xstrdup(fl.f[col[1]]);
        r.config = xstrdup(fl.f[col[2]]);
        r.log = xstrdup(fl.f[col[3]]);
        if (appm_method_parse(r.method, NULL) != APPM_OK)
            complain(path, lineno, "unknown method '%s' (kept)", r.method);
        logpath = join_path(dir, r.log);
        if (load_log(&r, logpath) < 0) {
            fprintf(stderr, "report: skipping run %s / %s / %s\n", r.scene, r.method, r.config);
            free(r.scene);
            free(r.method);
            free(r.config);
            free(r.log);
            free(r.pt);
        } else {
            GROW(runs, nrun, caprun);
            runs[nrun++] = r;
        }
        free(logpath);
    }
    if (ferror(f)) complain(path, lineno, "read error");
    fclose(f);
    free(path);
    free(line);
    free(fl.f);

    if (nrun == 0) {
        fprintf(stderr, "report: no run could be processed\n");
        free(targets);
        free(runs);
        return 2;
    }

    /* Per-run numbers. */
    for (i = 0; i < nrun; i++) {
        Run *r = &runs[i];
        int photons = 0;
        for (k = 0; k < r->npt; k++) photons |= r->pt[k].photons > 0;
        r->x_is_pass = is_method(r, "pt") || !photons;
        r->final_rmse = r->pt[r->npt - 1].rmse;
        r->final_relmse = r->pt[r->npt - 1].relmse;
        r->slope_x = fit_slope(r, r->x_is_pass ? X_PASS : X_PHOTONS);
        r->slope_t = fit_slope(r, X_TIME);
        r->eq_rmse = NAN;
    }

    /* Group by scene, in order of first appearance. */
    for (i = 0; i < nrun; i++) {
        Scene *s = NULL;
        for (k = 0; k < nscene && !s; k++)
            if (strcmp(scenes[k].name, runs[i].scene) == 0) s = &scenes[k];
        if (!s) {
            GROW(scenes, nscene, capscene);
            s = &scenes[nscene];
            memset(s, 0, sizeof *s);
            s->name = runs[i].scene;
            s->stem = make_stem(s->name, scenes, nscene);
            nscene++;
        }
        GROW(s->run, s->nrun, s->caprun);
        runs[i].style = (int)s->nrun;
        s->run[s->nrun++] = i;
    }

    for (i = 0; i < nscene; i++) {
        Scene *s = &scenes[i];
        double *v = xrealloc(NULL, s->nrun, sizeof *v), m0, mf;
        long bp;
        s->T = NAN;
        for (k = 0; k < s->nrun; k++) {
            double t = max_time(&runs[s->run[k]]);
            if (isfinite(t) && !(t >= s->T)) s->T = t;
        }
        for (k = 0; k < s->nrun; k++) runs[s->run[k]].eq_rmse = rmse_at_time(&runs[s->run[k]], s->T);

        if (ntargets) {
            s->target = targets;
            s->ntarget = ntargets;
        } else {
            /* Targets strictly between the typical first and final error, so
             * that most runs reach the easy one and few reach the hard one. */
            for (k = 0; k < s->nrun; k++) v[k] = runs[s->run[k]].pt[0].rmse;
            m0 = median(v, s->nrun);
            for (k = 0; k < s->nrun; k++) v[k] = runs[s->run[k]].final_rmse;
            mf = median(v, s->nrun);
            for (k = 0; k < 3; k++) s->own_target[k] = m0 * pow(mf / m0, (double)(k + 1) / 4.0);
            s->target = s->own_target;
            s->ntarget = 3;
        }
        free(v);

        for (k = 0; k < s->nrun; k++) runs[s->run[k]].thick = is_method(&runs[s->run[k]], "appm");
        bp = best_run(s, runs, "ppm", 0);
        if (bp < 0) bp = best_run(s, runs, "ppm", 1);
        if (bp >= 0) runs[bp].thick = 1;
    }

    path = join_path(dir, "results.csv");
    failed |= write_results(path, runs, nrun) < 0;
    free(path);

    for (i = 0; i < nscene; i++) {
        Scene *s = &scenes[i];
        size_t n = strlen(s->stem) + 32;
        char *name = xrealloc(NULL, n, 1), *title = xrealloc(NULL, strlen(s->name) + 40, 1);
        sprintf(name, "%s-rmse-time.svg", s->stem);
        sprintf(title, "%s: RMSE vs wall time", s->name);
        path = join_path(dir, name);
        failed |= write_plot(path, s, runs, X_TIME, title, "wall time [s]") < 0;
        free(path);
        sprintf(name, "%s-rmse-photons.svg", s->stem);
        sprintf(title, "%s: RMSE vs photon paths", s->name);
        path = join_path(dir, name);
        failed |= write_plot(path, s, runs, X_PHOTONS, title, "photon paths emitted") < 0;
        free(path);
        free(name);
        free(title);
    }

    path = join_path(dir, "report.md");
    failed |= write_report(path, scenes, nscene, runs) < 0;
    free(path);

    for (i = 0; i < nscene; i++) {
        free(scenes[i].stem);
        free(scenes[i].run);
    }
    free(scenes);
    for (i = 0; i < nrun; i++) {
        free(runs[i].scene);
        free(runs[i].method);
        free(runs[i].config);
        free(runs[i].log);
        free(runs[i].pt);
    }
    free(runs);
    free(targets);
    return failed ? 1 : 0;
}
