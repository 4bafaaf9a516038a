#!/bin/sh
# bench/mpi_model.sh [SVG] - the scaling model of appm-mpi (docs/distributed.md):
# a table of projected speed-ups and, if SVG is given, a plot of them.
#
# Per pass, one rank with one thread renders in T1 = W + R seconds: W is the
# work the ranks split (eye paths, photon paths, the gather), R the work every
# rank repeats (the photon map's build over all photons, the radii's medians,
# the pooled Laplacian).  A job of N ranks takes
#     T(N) = W / N + R + C(N),   C(N) = (N - 1) / N * D / B + X * ceil(log2 N) * a
# where D is the bytes all-gathered per pass (every rank receives all but its
# own part), B the link's bandwidth, a its latency and X the exchanges per
# pass.  Speed-up S(N) = T1 / T(N).  Measured inputs (environment overrides):
#   W_PER_PX, R_PER_PX  seconds per pixel of W and R on one core
#   D_PER_PX            bytes all-gathered per pixel and pass (appm: visible
#                       point 96, pixel 64, state 208, photons ~32 a path)
#   PIXELS              the frame (1920 x 1080 by default)
#   D2_PER_PX, R2_PER_PX  the same for the design not built (docs/distributed.md
#                       section 4: pixels owned, photons all-gathered: only the
#                       photons and one radius a pixel cross, and the repeated
#                       work is the map's build alone)
# The defaults are the figures measured on CornellBox-Sphere at 800x640 with
# one thread (docs/distributed.md, section 3).
set -u
W_PER_PX=${W_PER_PX:-1.9e-6}
R_PER_PX=${R_PER_PX:-1.4e-7}
D_PER_PX=${D_PER_PX:-400}
D2_PER_PX=${D2_PER_PX:-36}
R2_PER_PX=${R2_PER_PX:-6.5e-8}
PIXELS=${PIXELS:-2073600}
X=${X:-13}
svg=${1:-}
awk -v wp="$W_PER_PX" -v rp="$R_PER_PX" -v dp="$D_PER_PX" -v rp2="$R2_PER_PX" -v dp2="$D2_PER_PX" -v P="$PIXELS" \
    -v X="$X" -v svg="$svg" '
function lg2(n,  k) { k = 0; while ((2 ^ k) < n) k++; return k }
function T(n, B, a) { return W / n + R + (n - 1) / n * D / B + X * lg2(n) * a }
function use(d) { R = Rd[d]; D = Dd[d]; T1 = W + rp * P }
BEGIN {
    W = wp * P; Rd[1] = rp * P; Dd[1] = dp * P; Rd[2] = rp2 * P; Dd[2] = dp2 * P
    dname[1] = "built: state replicated"; dname[2] = "not built: pixels owned"
    nl = split("10 Gbit/s (TCP):1.25e9:2e-5|100 Gbit/s (RDMA):1.25e10:2e-6", links, "|")
    printf "frame %d pixels, one core: T1 = W + R = %.2f + %.3f s a pass\n\n", P, W, Rd[1]
    printf "| design | D a pass | link | N = 2 | 8 | 64 | 512 | limit T1 / (R + D/B) |\n"
    printf "|---|---|---|---|---|---|---|---|\n"
    for (d = 1; d <= 2; ++d)
        for (l = 1; l <= nl; ++l) {
            split(links[l], f, ":"); name[l] = f[1]; bw[l] = f[2]; lat[l] = f[3]
            use(d)
            printf "| %s | %.0f MB | %s | %.2f | %.2f | %.2f | %.2f | %.1f |\n", dname[d], D / 1e6, f[1],
                T1 / T(2, f[2], f[3]), T1 / T(8, f[2], f[3]), T1 / T(64, f[2], f[3]), T1 / T(512, f[2], f[3]),
                T1 / (R + D / f[2])
        }
    if (svg == "") exit
    # the plot: speed-up against N (log2 axis 1..512, log2 axis 1..512), ideal dashed
    w = 560; h = 360; x0 = 60; y0 = 310; sx = (w - 90) / 9; sy = 270 / 9
    printf "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"%d\" height=\"%d\" font-family=\"sans-serif\" font-size=\"12\">\n", w, h > svg
    printf "<rect width=\"%d\" height=\"%d\" fill=\"white\"/>\n", w, h > svg
    for (k = 0; k <= 9; ++k) {
        printf "<line x1=\"%g\" y1=\"%g\" x2=\"%g\" y2=\"%g\" stroke=\"#ddd\"/>\n", x0 + k * sx, y0, x0 + k * sx, y0 - 9 * sy > svg
        printf "<text x=\"%g\" y=\"%g\" text-anchor=\"middle\">%d</text>\n", x0 + k * sx, y0 + 16, 2 ^ k > svg
        printf "<line x1=\"%g\" y1=\"%g\" x2=\"%g\" y2=\"%g\" stroke=\"#ddd\"/>\n", x0, y0 - k * sy, x0 + 9 * sx, y0 - k * sy > svg
        printf "<text x=\"%g\" y=\"%g\" text-anchor=\"end\">%d</text>\n", x0 - 6, y0 - k * sy + 4, 2 ^ k > svg
    }
    printf "<text x=\"%g\" y=\"%g\" text-anchor=\"middle\">ranks N (one core each)</text>\n", x0 + 4.5 * sx, y0 + 34 > svg
    printf "<text x=\"14\" y=\"%g\" transform=\"rotate(-90 14 %g)\" text-anchor=\"middle\">speed-up</text>\n", y0 - 4.5 * sy, y0 - 4.5 * sy > svg
    printf "<line x1=\"%g\" y1=\"%g\" x2=\"%g\" y2=\"%g\" stroke=\"#999\" stroke-dasharray=\"4 4\"/>\n", x0, y0, x0 + 9 * sx, y0 - 9 * sy > svg
    split("#1f77b4 #d62728", col, " ")
    for (d = 1; d <= 2; ++d)
        for (l = 1; l <= nl; ++l) {
            use(d)
            pts = ""
            for (k = 0; k <= 90; ++k) {
                n = 2 ^ (k / 10); s = T1 / T(n, bw[l], lat[l])
                pts = pts sprintf("%.1f,%.1f ", x0 + k / 10 * sx, y0 - log(s) / log(2) * sy)
            }
            printf "<polyline fill=\"none\" stroke=\"%s\" stroke-width=\"2\"%s points=\"%s\"/>\n", col[l],
                d == 2 ? " stroke-dasharray=\"6 3\"" : "", pts > svg
            printf "<text x=\"%g\" y=\"%g\" fill=\"%s\">%s, %s%s</text>\n", x0 + 10, 26 + 16 * (2 * d + l - 2),
                col[l], name[l], dname[d], d == 2 ? " (dashed)" : "" > svg
        }
    printf "<text x=\"%g\" y=\"%g\">model, appm, a %d-pixel frame; grey: ideal</text>\n", x0 + 10, y0 - 10, P > svg
    print "</svg>" > svg
}'
