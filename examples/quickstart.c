#include <stdio.h>
#include "appm.h"

int main(int argc, char **argv)
{
    const char *out = argc > 1 ? argv[1] : "out.png";
    appm_config cfg = {0};             // zero means default, everywhere
    appm_scene *scene;
    appm_renderer *r;
    appm_diag diag;
    appm_image img;
    int pass, rc = 1;
    if (appm_scene_load("scenes/cornell-original.scene", &cfg, &scene, &diag)) {
        fprintf(stderr, "%s:%u: %s\n", diag.file, diag.line, diag.message);
        return 1;
    }
    cfg.width = cfg.height = 64;       // override the scene's image size
    if (appm_renderer_create(scene, &cfg, &r, &diag) == APPM_OK) {
        for (pass = 0; pass < 4; ++pass) appm_renderer_pass(r);
        appm_renderer_image(r, &img);  // borrowed view, linear RGB
        rc = appm_image_write(out, &img, 1.0, &diag) != APPM_OK;
        appm_renderer_destroy(r);
    }
    appm_scene_destroy(scene);
    return rc;
}
