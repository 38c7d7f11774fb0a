/* NanoVDB output: a dense float grid encoded as a .nvdb file by NanoVDB's own C++ writer
 * (nanovdb/util/GridBuilder.h and IO.h from Debian's libnanovdb-dev), behind a C function.
 * Callers: smoke/store.c (the simulator's frames) and tests/tools/make_nvdb.cpp
 * (`--from-grid`, the renderer's test files). */
#ifndef BRUME_SMOKE_NVDB_OUT_H
#define BRUME_SMOKE_NVDB_OUT_H
#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

/* Encodes values (n[0] x n[1] x n[2] floats, x fastest) as a .nvdb file: one float grid of
 * class fog volume named `name`, background 0, codec NONE, with statistics. Only the
 * voxels whose finite value is > threshold are stored (active); the others (NaN and
 * infinities too) are the background. Index (i, j, k) has its voxel centre at world voxel_size * (i, j, k) + origin
 * (per axis). *out gets a malloc'd buffer of *len bytes (the caller frees it); *active, when
 * not NULL, the number of stored voxels. 0, or -1 with a message in err. */
int nvdb_encode_fog(const float *values, const uint32_t n[3], float threshold, const double voxel_size[3],
                    const double origin[3], const char *name, uint8_t **out, size_t *len, uint64_t *active,
                    char *err, size_t errlen);

#ifdef __cplusplus
}
#endif
#endif
