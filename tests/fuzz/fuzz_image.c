/* tests/fuzz/fuzz_image.c - libFuzzer target: every image format appm reads (PNG,
 * JPEG, OpenEXR, TGA, PGM/PPM, Radiance HDR, PFM) through appm__image_decode.
 * The first input byte picks the name (bit 0: x.tga, else x.img) and, bit 1
 * clear, makes a PNG's chunk CRCs right; the rest is the file.
 * The entry code and its checks are in targets.h; tests/fuzz/run.sh builds and
 * runs this, tests/t_fuzz_regress.c replays the corpus without libFuzzer.
 *   clang -g -O1 -fsanitize=fuzzer,address,undefined tests/fuzz/fuzz_image.c -lm -pthread */
#include "../../appm.c"
#include "targets.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    if (fuzz_run("image", data, size) == FUZZ_BAD) abort();
    return 0;
}
