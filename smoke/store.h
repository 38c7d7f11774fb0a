/* Files the simulator writes: density grids, as NanoVDB fog volumes (smoke/nvdb_out.h) or
 * dense (the BRGRID01 format common/scene/grid.c reads), and checkpoints of the full state, each written atomically (temporary file in
 * the same folder, fsync, rename, fsync of the folder). Callers: smoke/main.c, tests. */
#ifndef BRUME_SMOKE_STORE_H
#define BRUME_SMOKE_STORE_H
#include <stddef.h>
#include <stdint.h>
#include "fluid.h"

/* Writes len bytes to path atomically. 0 or -1 with err. */
int store_write_atomic(const char *path, const void *data, size_t len, char *err, size_t errlen);
/* The density as a BRGRID01 grid (negative values clamped to 0). 0 or -1. */
int store_write_grid(const char *path, const struct fluid *f, char *err, size_t errlen);
/* The density as the bytes of a NanoVDB file (store_write_nvdb's), malloc'd into *buf. */
int store_encode_nvdb(const struct fluid *f, uint8_t **buf, size_t *len, uint64_t *active, char *err,
                      size_t errlen);
/* The density as a NanoVDB fog volume in the simulation's world units (voxel edge f->h,
 * voxel (i, j, k)'s centre at ((i, j, k) + 0.5) h, as the source's position is given),
 * storing the densities above s.nvdb_threshold. *bytes and *active (either may be NULL):
 * the file's size and the voxels stored. 0 or -1. */
int store_write_nvdb(const char *path, const struct fluid *f, size_t *bytes, uint64_t *active, char *err,
                     size_t errlen);
/* One frame, in the format the name's extension chooses (.nvdb, else dense); *bytes (may be
 * NULL) gets the file's size. 0 or -1. */
int store_write_frame(const char *path, const struct fluid *f, size_t *bytes, char *err, size_t errlen);
/* Bytes of a BRGRID01 file of f's size. */
size_t store_grid_bytes(const struct fluid *f);
/* Hash of the settings that shape the state (everything but frames, threads and output). */
uint64_t store_settings_hash(const struct smoke_settings *s);
/* Checkpoint: magic "BRSMCK01", settings hash, nx ny nz, frames done, steps done, then
 * u v w density temperature as float32. */
int store_write_checkpoint(const char *path, const struct fluid *f, uint32_t frame, char *err, size_t errlen);
/* Loads a checkpoint into f (made by fluid_init with the same settings). 1 loaded (with
 * *frame), 0 no file, -1 a file that does not match or is damaged (err says why). */
int store_read_checkpoint(const char *path, struct fluid *f, uint32_t *frame, char *err, size_t errlen);

#endif
