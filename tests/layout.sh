#!/bin/sh
# tests/layout.sh - the layout rules of docs/CONTRIBUTING.md that a script can check:
#   1. no function of appm.c or main.c is longer than 80 lines, counted from the
#      first line of its signature to its closing brace (a body opens with "{"
#      alone on a line and closes with "}" alone on a line);
#   2. appm.c's sections are numbered 1, 2, ... in order, each number once, and
#      every subsection "N.M" lies in section N, numbered 1, 2, ... in order;
#   3. every tests/t_*.c is in tests/all.c (included and in its table), so that
#      make test runs it.
# Prints one line per broken rule and "N passed, N failed" as its last line.
cd "$(dirname "$0")/.." || exit 2
pass=0
fail=0
for f in appm.c main.c; do
    long=$(awk -v file="$f" '
        /^[A-Za-z_]/ && !sig { sig = NR }
        /^[ \t]*$/ || /^\/?\*/ || /^#/ { if (!body) sig = 0 }
        /;[ \t]*$/ && !body { sig = 0 }
        /^\{$/ { body = 1; if (!sig) sig = NR }
        /^\}/ && body { n = NR - sig + 1; if (n > 80) printf "%s:%d: a function of %d lines\n", file, sig, n; body = 0; sig = 0 }
    ' "$f")
    if [ -z "$long" ]; then
        pass=$((pass + 1))
    else
        printf '%s\n' "$long"
        fail=$((fail + 1))
    fi
done
bad=$(awk '
    /^\/\* ==== [0-9]+\. / { n = $3 + 0; if (n != sec + 1) printf "appm.c:%d: section %d after section %d\n", NR, n, sec; sec = n; sub_ = 0 }
    /^\/\* ---- [0-9]+\.[0-9]+ / {
        split($3, p, "."); if (p[1] + 0 != sec || p[2] + 0 != sub_ + 1)
            printf "appm.c:%d: subsection %s in section %d after %d.%d\n", NR, $3, sec, sec, sub_
        sub_ = p[2] + 0 }
    /^\/\* ---- [^0-9]/ { printf "appm.c:%d: a subsection without a number\n", NR }
    END { if (sec < 10) printf "appm.c: only %d numbered sections\n", sec }
' appm.c)
if [ -z "$bad" ]; then pass=$((pass + 1)); else printf '%s\n' "$bad"; fail=$((fail + 1)); fi
missing=""
for t in tests/t_*.c; do
    n=$(basename "$t" .c)
    grep -q "^#include \"$n.c\"" tests/all.c && grep -q "{\"$n\", ${n}_main}" tests/all.c ||
        missing="$missing $n"
done
if [ -z "$missing" ]; then pass=$((pass + 1)); else echo "tests/all.c lacks:$missing"; fail=$((fail + 1)); fi
echo "$pass passed, $fail failed"
[ "$fail" -eq 0 ]
