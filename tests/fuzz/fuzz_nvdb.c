/* libFuzzer target for NanoVDB density grids (common/scene/nvdb.c): any bytes, with the grid
 * chosen by size (the first float grid, "density" or "temperature"), must load as a sane
 * dense grid (finite densities >= 0, within the voxel limit) or fail with a message; a
 * loaded grid is then placed and looked up. The voxel limit is lowered so that a changed
 * bounding box cannot make one input slow. Seeds: the files of build/make_nvdb (run.sh).
 * Built and run by tests/fuzz/run.sh. */
#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>
#include "base/log.h"
#include "scene/medium.h"
#include "scene/nvdb.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    static const char *const names[] = {NULL, "density", "temperature"};
    nvdb_max_voxels = 1u << 18;
    struct density_grid g;
    struct xform x;
    uint64_t neg;
    char err[512] = "";
    if (nvdb_parse(data, size, names[size % 3], &g, &x, &neg, err, sizeof err) != 0) {
        if (err[0] == '\0' || g.data)
            abort();
        return 0;
    }
    size_t n = (size_t)g.nx * g.ny * g.nz;
    if (n == 0 || n > nvdb_max_voxels)
        abort();
    for (size_t i = 0; i < n; i++)
        if (!(g.data[i] >= 0.0f) || !isfinite(g.data[i]))
            abort();
    for (int i = 0; i < 3; i++)
        for (int j = 0; j < 4; j++)
            if (!isfinite(x.m[i][j]))
                abort();
    struct density_grid *pg = mem_alloc(sizeof *pg);
    *pg = g;
    grid_finish(pg, &x, 1.0f);
    for (int k = 0; k < 8; k++) {
        vec3 p = xform_point(&pg->grid_to_world, v3(0.125f * (float)k, 0.5f, 1.0f - 0.125f * (float)k));
        (void)grid_density(pg, p);
    }
    grid_free(&pg);
    return 0;
}
