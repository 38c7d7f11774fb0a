/* A frame's files: the output name of each frame of a range, whether a frame is already
 * rendered, the tiled EXR assembled from the workers' chunks, the PNG preview and the run's
 * stats JSON. Invariant: every file appears whole or not at all (temporary name, fsync,
 * rename, fsync of the folder). Called by master/master.c; no sockets, no scheduling. */
#ifndef BRUME_OUTPUT_H
#define BRUME_OUTPUT_H
#include <jansson.h>
#include <stddef.h>
#include <stdint.h>
#include "image/imgio.h"
#include "scene/scene.h"

/* A finished tile's EXR chunk as the worker encoded it (the master never re-encodes). */
struct net_payload;
struct output_chunk {
    uint8_t *data;
    size_t size;
    struct net_payload *payload; /* data lies in this received frame, or NULL: data is mem_alloc'd */
};
/* Frees what c holds and clears it. */
void output_chunk_free(struct output_chunk *c);

/* The output file of one frame: the last run of '#' in pattern becomes the zero-padded
 * frame number (as many digits as '#'s, more if needed); without one, ".NNNN" goes in
 * front of the extension. Without a range (have_frames 0) the name is pattern. 0, or -1
 * when it does not fit. */
int output_frame_path(const char *pattern, int have_frames, uint32_t frame, char *out, size_t outlen);
/* 1 when path exists and its header says it was rendered from scene_hash with this spp,
 * seed and layout (files appear only by rename after fsync, so one that reads back is
 * complete); 0 otherwise, with an info or warning line saying why it is rendered again. */
int output_is_done(const char *path, const char *scene_hash, uint32_t spp, uint64_t seed,
                   const struct image_desc *desc);
/* Writes the tiled EXR of desc from one chunk per tile (row-major) atomically. 0 or -1. */
int output_write_exr(const char *path, const struct image_desc *desc, const struct image_attrs *attrs,
                     const struct output_chunk *chunks, char *err, size_t errlen);
/* A tone-mapped sRGB PNG of the decoded chunks (a tile that does not decode stays black). */
int output_write_preview(const char *path, const struct image_desc *desc, const struct output_chunk *chunks,
                         char *err, size_t errlen);
/* Whether path's folder takes a new file: creates and removes the temporary name the
 * writers use (path.tmp.PID); an empty path or a folder at path (which the final rename
 * cannot replace) is refused. Checked before the first tile, so that a render whose output
 * cannot be written fails at once, not after the night's work. 0, or -1 with the cause. */
int output_check_writable(const char *path, char *err, size_t errlen);
/* Removes the temporary files of path (path.tmp.PID) that a writer killed before its
 * rename left behind: those whose PID is no live process (a live one may be another
 * master's write under way, and stays). Returns how many were removed. */
unsigned output_remove_stale_tmp(const char *path);
/* Writes root as indented JSON to path atomically. 0 or -1. */
int output_write_json(const char *path, const json_t *root, char *err, size_t errlen);

/* The id AOVs' name tables as string attributes of a (id.object/N: the N-th mesh, then
 * sphere, by name; id.material/N), for the AOVs the scene's settings ask for; free with
 * output_id_names_free. */
void output_id_names(const struct scene *sc, struct image_attrs *a);
void output_id_names_free(struct image_attrs *a);

#endif
