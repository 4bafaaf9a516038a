/* tests/fuzz/fuzz_checkpoint.c - libFuzzer target: checkpoints through
 * appm_renderer_load (as given, and with the checksum made right), with a
 * save-after-load round trip and a pass of what loads.
 * The entry code and its checks are in targets.h; tests/fuzz/run.sh builds and
 * runs this, tests/t_fuzz_regress.c replays the corpus without libFuzzer.
 *   clang -g -O1 -fsanitize=fuzzer,address,undefined tests/fuzz/fuzz_checkpoint.c -lm -pthread */
#include "../../appm.c"
#include "targets.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    if (fuzz_run("checkpoint", data, size) == FUZZ_BAD) abort();
    return 0;
}
