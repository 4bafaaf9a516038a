/* examples/embed.c - the smallest useful program on appm: load a scene, render
 * a few passes, write a PNG.   cc -std=c99 -O2 examples/embed.c appm.c -lm -pthread */
#include <stdio.h>
#include "../appm.h"

int main(int argc, char **argv)
{
    const char *scene_path = argc > 1 ? argv[1] : "scenes/cornell-original.scene";
    const char *out_path = argc > 2 ? argv[2] : "embed.png";
    appm_config cfg = {0}; /* zero means default: APPM, all cores, seed 0 */
    appm_scene *scene;
    appm_renderer *r;
    appm_diag diag;
    appm_image img;
    int pass, rc = 0;

    if (appm_scene_load(scene_path, &cfg, &scene, &diag) != APPM_OK) {
        fprintf(stderr, "%s:%u: %s\n", diag.file, diag.line, diag.message);
        return 1;
    }
    cfg.width = cfg.height = 128;
    if (appm_renderer_create(scene, &cfg, &r, &diag) != APPM_OK) {
        fprintf(stderr, "%s\n", diag.message);
        appm_scene_destroy(scene);
        return 1;
    }
    for (pass = 0; pass < 8 && rc == 0; ++pass) rc = appm_renderer_pass(r) != APPM_OK;
    appm_renderer_image(r, &img); /* borrowed: valid until the next pass */
    if (rc == 0 && appm_image_write(out_path, &img, 1.0, &diag) != APPM_OK) {
        fprintf(stderr, "%s: %s\n", out_path, diag.message);
        rc = 1;
    }
    appm_renderer_destroy(r);
    appm_scene_destroy(scene);
    if (rc == 0) printf("wrote %s\n", out_path);
    return rc;
}
