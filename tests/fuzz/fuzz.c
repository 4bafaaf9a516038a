/* tests/fuzz/fuzz.c - the libFuzzer program of appm's six readers.  Which reader
 * it fuzzes is its own name: tests/fuzz/run.sh builds it once and links it as
 * fuzz_obj, fuzz_mtl, fuzz_scene, fuzz_pfm, fuzz_checkpoint and fuzz_image
 * (one build instead of six: each compiles all of appm.c with the sanitizers).
 *   obj         Wavefront OBJ text (and, after the first NUL byte, MTL text)
 *               through appm_scene_load_obj_memory and appm__obj_parse
 *   mtl         MTL text through appm__mtl_parse, then a generated OBJ that uses
 *               its materials, loaded and rendered
 *   scene       .scene text through appm__scene_parse (mesh files never exist),
 *               finished into a scene and rendered
 *   pfm         PFM images through appm__pfm_parse, with a write/read round trip
 *   checkpoint  checkpoints through appm_renderer_load (as given, and with the
 *               checksum made right), a save-after-load round trip and a pass
 *   image       every image format appm reads (PNG, JPEG, OpenEXR, TGA, PGM/PPM,
 *               Radiance HDR, PFM) through appm__image_decode; the first byte
 *               picks the name (bit 0: x.tga, else x.img) and, bit 1 clear,
 *               makes a PNG's chunk CRCs right; an image of at most 65,536
 *               texels then becomes an environment map, sampled
 * The entry code and its checks are in targets.h; tests/t_fuzz_regress.c replays
 * the corpus without libFuzzer.  By hand:
 *   clang -g -O1 -fsanitize=fuzzer,address,undefined tests/fuzz/fuzz.c -o fuzz_obj -lm -pthread
 *   ./fuzz_obj tests/fuzz/corpus/obj */
#include "../../appm.c"
#include "targets.h"

int LLVMFuzzerInitialize(int *argc, char ***argv);
int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

/* The reader: the program's name after "fuzz_" (fuzz_obj -> obj). */
static char fuzz_name[32];

int LLVMFuzzerInitialize(int *argc, char ***argv)
{
    const char *self = *argc > 0 && (*argv)[0] ? (*argv)[0] : "", *b = self, *p;
    size_t k;
    for (p = self; *p; ++p)
        if (*p == '/') b = p + 1;
    if (strncmp(b, "fuzz_", 5) == 0) b += 5;
    for (k = 0; k < FUZZ_TARGET_COUNT; ++k)
        if (strcmp(fuzz_targets[k].name, b) == 0) {
            strcpy(fuzz_name, b);
            return 0;
        }
    fprintf(stderr, "fuzz: name this program fuzz_TARGET, TARGET one of obj mtl scene pfm checkpoint image "
                    "(it is '%s')\n", self);
    exit(2);
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    if (fuzz_run(fuzz_name, data, size) == FUZZ_BAD) abort();
    return 0;
}
