/* NanoVDB density grids: one float grid of a .nvdb file (the OpenVDB family's sparse
 * format, uncompressed), read with NanoVDB's portable C reader (PNanoVDB.h) through
 * bounds-checked buffer accessors and copied voxel for voxel into the dense grid of
 * medium.h. Files are untrusted: every header field is validated before use and every
 * read of the tree is checked against the grid's size. Called by scene_json.c for a
 * density file that starts with the NanoVDB magic (the test files: tests/tools/make_nvdb.cpp). */
#ifndef BRUME_NVDB_H
#define BRUME_NVDB_H
#include <stddef.h>
#include <stdint.h>
#include "scene/grid.h"
#include "base/vec.h"

/* Largest dense grid nvdb_parse makes (GRID_MAX_VOXELS; the fuzz target lowers it to stay fast). */
extern uint64_t nvdb_max_voxels;

/* 1 if data starts like a NanoVDB file or grid buffer ("NanoVDB" and a version letter). */
int nvdb_is_nvdb(const uint8_t *data, size_t size);

/* Reads the float grid named grid_name (NULL: the file's first float grid) of a .nvdb file:
 * segments of a 16-byte header (magic "NanoVDB0", version 32.x, grid count, codec NONE),
 * the grids' metadata and names, then each grid's buffer. The dense grid covers the grid's
 * active index box plus one voxel of border on every side: dense voxel (i, j, k) holds the
 * value at index bbox_min - 1 + (i, j, k), so densities fall to 0 beyond the active box as
 * in NanoVDB's own trilinear sampler. Densities must be finite; negative ones become 0.
 * *to_world maps the dense grid's unit cube onto the file's world space with the grid's
 * index-to-world map (voxel centres at integer index coordinates). *negatives counts the
 * voxels clamped to 0. 0, or -1 with a message in err. */
int nvdb_parse(const uint8_t *data, size_t size, const char *grid_name, struct density_grid *out,
               struct xform *to_world, uint64_t *negatives, char *err, size_t errlen);

#endif
