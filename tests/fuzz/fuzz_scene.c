/* tests/fuzz/fuzz_scene.c - libFuzzer target: .scene text through appm__scene_parse
 * (mesh files never exist), finished into a scene and rendered.
 * The entry code and its checks are in targets.h; tests/fuzz/run.sh builds and
 * runs this, tests/t_fuzz_regress.c replays the corpus without libFuzzer.
 *   clang -g -O1 -fsanitize=fuzzer,address,undefined tests/fuzz/fuzz_scene.c -lm -pthread */
#include "../../appm.c"
#include "targets.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    if (fuzz_run("scene", data, size) == FUZZ_BAD) abort();
    return 0;
}
