#!/bin/sh
# tests/quickstart.sh QUICKSTART - the header's QUICK START is true: the code
# shown in appm.h is, byte for byte, examples/quickstart.c; every scene file the
# header names exists; the compiled example (QUICKSTART) runs and writes a PNG.
#
#   sh tests/quickstart.sh build/quickstart     (from the repository root)
#
# Prints one line per failed check and "N passed, N failed" as its last line.
if [ $# -ne 1 ] || [ ! -f appm.h ]; then
    echo "usage (from the repository root): sh tests/quickstart.sh QUICKSTART_BINARY" >&2
    exit 2
fi
npass=0
nfail=0
check() {
    what=$1
    shift
    if "$@"; then npass=$((npass + 1)); else nfail=$((nfail + 1)); echo "FAIL: $what"; fi
}
mkdir -p tests/out
# the program in the header: from its first #include to the closing brace of
# main, less the comment's " *     " margin (" *" alone on empty lines)
awk '/^ \*     #include <stdio.h>$/ { on = 1 }
     on { line = $0; if (line == " *") print ""; else { sub(/^ \*     /, "", line); print line } }
     on && /^ \*     }$/ { exit }' appm.h >tests/out/quickstart-header.c
check "appm.h holds a QUICK START program" [ -s tests/out/quickstart-header.c ]
check "the QUICK START of appm.h is examples/quickstart.c, byte for byte" \
    cmp -s tests/out/quickstart-header.c examples/quickstart.c
for f in $(grep -o 'scenes/[A-Za-z0-9._-]*' appm.h | sort -u); do
    check "appm.h names $f, which exists" [ -f "$f" ]
done
for f in $(grep -o '\(docs\|examples\)/[A-Za-z0-9._/-]*[A-Za-z0-9]' appm.h | sort -u); do
    check "appm.h names $f, which exists" [ -f "$f" ]
done
rm -f tests/out/quickstart.png
"$1" tests/out/quickstart.png
rc=$?
check "the quick start exits 0 (got $rc)" [ "$rc" -eq 0 ]
check "the quick start wrote a PNG" [ "$(dd if=tests/out/quickstart.png bs=1 skip=1 count=3 2>/dev/null)" = PNG ]
echo "$npass passed, $nfail failed"
[ "$nfail" -eq 0 ]
