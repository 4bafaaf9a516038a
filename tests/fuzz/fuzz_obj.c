/* tests/fuzz/fuzz_obj.c - libFuzzer target: Wavefront OBJ text (and, after the first NUL
 * byte, MTL text) through appm_scene_load_obj_memory and appm__obj_parse.
 * The entry code and its checks are in targets.h; tests/fuzz/run.sh builds and
 * runs this, tests/t_fuzz_regress.c replays the corpus without libFuzzer.
 *   clang -g -O1 -fsanitize=fuzzer,address,undefined tests/fuzz/fuzz_obj.c -lm -pthread */
#include "../../appm.c"
#include "targets.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    if (fuzz_run("obj", data, size) == FUZZ_BAD) abort();
    return 0;
}
