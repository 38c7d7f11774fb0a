/* Image I/O: OpenEXR through OpenEXRCore (tile chunks, tiled files, reading back) and
 * tone-mapped PNG previews through libpng. Workers encode each rendered tile into one
 * compressed EXR tile chunk; the master decode-checks it and writes the chunk's bytes
 * unchanged into a tiled EXR whose tiles are the render tiles (line order RANDOM_Y).
 * No function here is named exr_*; OpenEXRCore errors are routed into the project log. */
#ifndef BRUME_IMGIO_H
#define BRUME_IMGIO_H
#include <stddef.h>
#include <stdint.h>

#define IMGIO_MAX_CHANNELS 24

/* Tile codecs (OpenEXRCore's lossless ones; render tiles use ZIP, docs/benchmarks.md
 * compares them). */
enum imgio_compression { IMGIO_NONE, IMGIO_ZIP, IMGIO_PIZ, IMGIO_RLE, IMGIO_ZIPS };

/* Everything that fixes the bytes of a tile chunk and the file header. Channels are
 * given in the renderer's order; pixel buffers are interleaved in that order:
 * pixels[((y * tile_w) + x) * num_channels + c]. Pixel buffers are always 32-bit float;
 * in the file and its chunks a channel is FLOAT, or HALF where its bit in half_mask is
 * set (encoding rounds to the nearest half, as OpenEXR does; decoding widens exactly). */
struct image_desc {
    uint32_t width, height;
    uint32_t tile_size;
    uint32_t num_channels;
    char channel_names[IMGIO_MAX_CHANNELS][32];
    enum imgio_compression compression;
    uint32_t half_mask;     /* bit c: channel c is stored as HALF */
};

/* Metadata written into the header of the final file. */
struct image_attrs {
    uint32_t spp;
    uint64_t seed;
    double render_seconds;
    char scene_hash[65];    /* hex */
    char software[64];      /* e.g. "brume 0.1" */
    /* The error estimate and, with passes, how far the render went (docs/adaptive.md);
     * written when > 0 (est_rel_rmse: always). */
    double est_rel_rmse;    /* brume_est_rel_rmse: the image's estimated relRMSE */
    uint32_t passes;        /* brume_passes: passes of the frame (adaptive: at most, per tile) */
    double target_error;    /* brume_target_error */
    double pixel_error;     /* brume_pixel_error: the per-pixel bound */
    uint32_t rounds;        /* brume_rounds: adaptive rounds rendered (--max-rounds reproduces a time-limited run) */
    uint32_t time_limited;  /* brume_time_limited: 1 when --time-limit ended the render */
    /* Further string attributes (the AOVs' id name tables), written as given. */
    uint32_t num_strings;
    char **string_names, **string_values;
};

/* Tile grid helpers: number of tiles across and down, and a tile's pixel rectangle. */
uint32_t imgio_tiles_x(const struct image_desc *d);
uint32_t imgio_tiles_y(const struct image_desc *d);
void imgio_tile_rect(const struct image_desc *d, uint32_t tx, uint32_t ty,
                     uint32_t *x0, uint32_t *y0, uint32_t *w, uint32_t *h);

/* Encoder (worker side): one per thread; reusable for any number of tiles. */
struct imgio_encoder;
struct imgio_encoder *imgio_encoder_new(const struct image_desc *d, char *err, size_t errlen);
/* Encodes tile (tx, ty) from interleaved pixels (w*h*num_channels floats, tile-local)
 * into *chunk (mem_alloc'd; caller frees) of *chunk_size bytes. Returns 0 or -1. */
int imgio_encode_tile(struct imgio_encoder *e, uint32_t tx, uint32_t ty, const float *pixels,
                      uint8_t **chunk, size_t *chunk_size, char *err, size_t errlen);
void imgio_encoder_free(struct imgio_encoder **e);

/* Decodes a chunk produced by imgio_encode_tile back into interleaved pixels (w*h*nc).
 * Used by the master to check a chunk before accepting it, and by tests. Any malformed
 * input returns -1 with a message; never crashes. */
int imgio_decode_tile(const struct image_desc *d, uint32_t tx, uint32_t ty, const uint8_t *chunk,
                      size_t chunk_size, float *pixels, char *err, size_t errlen);

/* Writer (master side): a tiled EXR at path (the caller passes a temporary name and
 * renames it after imgio_writer_close succeeds). */
struct imgio_writer;
struct imgio_writer *imgio_writer_open(const char *path, const struct image_desc *d,
                                       const struct image_attrs *a, char *err, size_t errlen);
/* Writes an encoded chunk for tile (tx, ty) as is; tiles may arrive in any order. A tile
 * already written is skipped and returns 0 (re-issued tiles are bit-identical). */
int imgio_writer_put_tile(struct imgio_writer *w, uint32_t tx, uint32_t ty, const uint8_t *chunk,
                          size_t chunk_size, char *err, size_t errlen);
/* Finishes the file (offset table) and fsyncs it. Returns 0 or -1; frees w either way.
 * Fails if any tile is missing. On failure the (regular) file at path is removed.
 * The master opens the writer once every tile has arrived, so the attributes (render
 * time included) are final when the header is written. */
int imgio_writer_close(struct imgio_writer **w, char *err, size_t errlen);

/* Reads any EXR (scanline or tiled) into interleaved float pixels for the named
 * channels (missing channels are an error). *pixels is mem_alloc'd. */
int imgio_read(const char *path, const char *const *channels, uint32_t num_channels, float **pixels,
               uint32_t *width, uint32_t *height, char *err, size_t errlen);

/* The same on an EXR file in memory (size bytes); name is used in messages. An image
 * wider or taller than max_side (0: IMGIO_READ_MAX_SIDE, which imgio_read allows) is
 * refused from its header, before its pixels are allocated. */
#define IMGIO_READ_MAX_SIDE (1u << 20)
int imgio_read_memory(const char *name, const uint8_t *data, size_t size, const char *const *channels,
                      uint32_t num_channels, uint32_t max_side, float **pixels, uint32_t *width, uint32_t *height,
                      char *err, size_t errlen);

/* Reads back what imgio_writer_open wrote into a header: size and tile size into d (0
 * when not square-tiled; channels are not filled in) and spp, seed and scene hash into a.
 * The master uses it to skip frames already rendered. 0, or -1 when the file cannot be
 * read or lacks those attributes. */
int imgio_read_attrs(const char *path, struct image_desc *d, struct image_attrs *a, char *err, size_t errlen);

/* Writes an 8-bit sRGB PNG of interleaved RGB(A) floats with the given stride, exposure
 * scaled and clamped (a plain preview, not a grade). Written to a temporary file and
 * renamed. Returns 0 or -1. */
int imgio_write_png(const char *path, const float *pixels, uint32_t width, uint32_t height,
                    uint32_t stride, float exposure, char *err, size_t errlen);

#endif
