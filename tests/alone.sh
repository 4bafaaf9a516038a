#!/bin/sh
# tests/alone.sh BINARY... - each test program run on its own, as a developer
# runs one: from a copy of the repository root that has no tests/out yet.
# The program must create its scratch folder itself (tests/check.h) and pass.
#
#   sh tests/alone.sh build/t_image build/t_loader    (from the repository root)
#
# Prints one line per failed check and "N passed, N failed" as its last line.
if [ ! -d tests/fixtures ]; then
    echo "tests/alone.sh: run it from the repository root" >&2
    exit 2
fi
root=$(pwd)
npass=0
nfail=0
for t in "$@"; do
    tmp=$(mktemp -d "${TMPDIR:-/tmp}/appm-alone.XXXXXX") || exit 2
    mkdir "$tmp/tests"
    ln -s "$root/tests/fixtures" "$tmp/tests/fixtures"
    ln -s "$root/scenes" "$tmp/scenes"
    case $t in /*) bin=$t ;; *) bin=$root/$t ;; esac
    last=$(cd "$tmp" && "$bin" 2>/dev/null | tail -n 1)
    case $last in
    *" passed, 0 failed") npass=$((npass + 1)) ;;
    *) nfail=$((nfail + 1)); echo "FAIL: $t run alone without tests/out: ${last:-no summary}" ;;
    esac
    rm -rf "$tmp"
done
echo "$npass passed, $nfail failed"
[ "$nfail" -eq 0 ]
