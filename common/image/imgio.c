/* Image I/O through OpenEXRCore and libpng (see imgio.h). Invariants: every OpenEXRCore
 * context gets a struct imgio_stream as user data, so its I/O goes through our functions
 * (memory or our own fd, never a library-opened file) and its error messages are captured
 * for the caller's err buffer instead of being printed. Callers: the worker encodes tiles,
 * the master decode-checks them and assembles the file, tests and tools read files back. */
#include "image/imgio.h"
#include "base/bytes.h"
#include "base/log.h"

#include <errno.h>
#include <fcntl.h>
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stdbool.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#ifdef __SSE2__
#include <emmintrin.h>
#endif
#include <sys/stat.h>
#include <unistd.h>

#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wpedantic"
#pragma GCC diagnostic ignored "-Wstrict-prototypes"
#include <OpenEXR/openexr.h>
#include <png.h>
#pragma GCC diagnostic pop
#include <libdeflate.h>

/* Chunk leader of a single-part tiled file: tile x, y, level x, level y, data size. */
#define TILE_LEADER_BYTES 20

/* ---------------------------------------------------------------------------------------
 * Error strings */

static void set_err(char *err, size_t errlen, const char *fmt, ...) __attribute__((format(printf, 3, 4)));
static void set_err(char *err, size_t errlen, const char *fmt, ...)
{
    if (!err || errlen == 0)
        return;
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(err, errlen, fmt, ap);
    va_end(ap);
}

/* ---------------------------------------------------------------------------------------
 * Streams: the user data of every context. Memory-backed reading serves the decode check,
 * memory capture serves header bytes, fd-backed I/O lets us fsync and report errno. */

struct imgio_stream {
    int fd; /* >= 0: file-backed */
    int io_errno;
    const uint8_t *src; /* memory-backed reading */
    size_t src_len;
    bool capture; /* memory-backed writing: keep bytes (else discard) */
    uint8_t *dst;
    size_t dst_len, dst_cap;
    char lib_msg[256]; /* first OpenEXRCore message since the last reset */
};

static void stream_init(struct imgio_stream *s)
{
    memset(s, 0, sizeof *s);
    s->fd = -1;
}

/* A stream reading path; -1 with the reason in err when it cannot be opened. */
static int stream_open_read(struct imgio_stream *s, const char *path, char *err, size_t errlen)
{
    stream_init(s);
    /* O_NONBLOCK: a FIFO in the file's place would otherwise block open() until a writer
     * comes, signals included; fstat then refuses anything but a regular file. */
    s->fd = open(path, O_RDONLY | O_CLOEXEC | O_NONBLOCK);
    if (s->fd < 0) {
        set_err(err, errlen, "%s: cannot open: %s", path, strerror(errno));
        return -1;
    }
    struct stat st;
    int fst = fstat(s->fd, &st);
    if (fst != 0 || !S_ISREG(st.st_mode)) {
        set_err(err, errlen, "%s: cannot open: %s", path, fst != 0 ? strerror(errno) : "not a regular file");
        close(s->fd);
        s->fd = -1;
        return -1;
    }
    return 0;
}

static void on_exr_error(exr_const_context_t ctxt, exr_result_t code, const char *msg)
{
    void *ud = NULL;
    struct imgio_stream *s = NULL;
    if (ctxt && exr_get_user_data(ctxt, &ud) == EXR_ERR_SUCCESS)
        s = ud;
    if (!msg)
        msg = exr_get_default_error_message(code);
    /* Errors are expected while decode-checking untrusted chunks, so the caller decides
     * whether to log; only keep a trace at debug level. */
    log_debug("openexr: %s (%s)", msg, exr_get_error_code_as_string(code));
    if (s && s->lib_msg[0] == '\0')
        snprintf(s->lib_msg, sizeof s->lib_msg, "%s", msg);
    else if (!s)
        log_error("openexr: %s", msg);
}

static int64_t stream_read(exr_const_context_t ctxt, void *userdata, void *buffer, uint64_t sz,
                           uint64_t offset, exr_stream_error_func_ptr_t error_cb)
{
    (void)ctxt;
    (void)error_cb;
    struct imgio_stream *s = userdata;
    if (s->fd < 0) {
        if (offset >= s->src_len)
            return 0;
        uint64_t n = s->src_len - offset;
        if (n > sz)
            n = sz;
        memcpy(buffer, s->src + offset, (size_t)n);
        return (int64_t)n;
    }
    uint64_t done = 0;
    while (done < sz) {
        ssize_t r = pread(s->fd, (uint8_t *)buffer + done, (size_t)(sz - done), (off_t)(offset + done));
        if (r < 0 && errno == EINTR)
            continue;
        if (r < 0) {
            s->io_errno = errno;
            return -1;
        }
        if (r == 0)
            break;
        done += (uint64_t)r;
    }
    return (int64_t)done;
}

static int64_t stream_size(exr_const_context_t ctxt, void *userdata)
{
    (void)ctxt;
    struct imgio_stream *s = userdata;
    if (s->fd < 0)
        return (int64_t)s->src_len;
    struct stat st;
    if (fstat(s->fd, &st) != 0)
        return -1;
    return (int64_t)st.st_size;
}

static int64_t stream_write(exr_const_context_t ctxt, void *userdata, const void *buffer, uint64_t sz,
                            uint64_t offset, exr_stream_error_func_ptr_t error_cb)
{
    (void)ctxt;
    (void)error_cb;
    struct imgio_stream *s = userdata;
    if (s->fd < 0) {
        if (!s->capture)
            return (int64_t)sz;
        size_t end = (size_t)(offset + sz);
        mem_grow((void **)&s->dst, &s->dst_cap, end, 1);
        if (offset > s->dst_len)
            memset(s->dst + s->dst_len, 0, (size_t)offset - s->dst_len);
        memcpy(s->dst + offset, buffer, (size_t)sz);
        if (end > s->dst_len)
            s->dst_len = end;
        return (int64_t)sz;
    }
    uint64_t done = 0;
    while (done < sz) {
        ssize_t r = pwrite(s->fd, (const uint8_t *)buffer + done, (size_t)(sz - done), (off_t)(offset + done));
        if (r < 0 && errno == EINTR)
            continue;
        if (r <= 0) {
            s->io_errno = r < 0 ? errno : ENOSPC;
            return -1;
        }
        done += (uint64_t)r;
    }
    return (int64_t)done;
}

static exr_context_initializer_t stream_initializer(struct imgio_stream *s)
{
    exr_context_initializer_t init = EXR_DEFAULT_CONTEXT_INITIALIZER;
    init.error_handler_fn = on_exr_error;
    init.user_data = s;
    init.read_fn = stream_read;
    init.size_fn = stream_size;
    init.write_fn = stream_write;
    /* A missing or damaged chunk must be an error, never a silent scan of the file. */
    init.flags = EXR_CONTEXT_FLAG_DISABLE_CHUNK_RECONSTRUCTION;
    return init;
}

/* "what: library message" (or errno / the generic message when the library said nothing). */
static void lib_err(char *err, size_t errlen, const struct imgio_stream *s, exr_result_t rv, const char *what)
{
    if (s && s->io_errno)
        set_err(err, errlen, "%s: %s", what, strerror(s->io_errno));
    else if (s && s->lib_msg[0])
        set_err(err, errlen, "%s: %s", what, s->lib_msg);
    else
        set_err(err, errlen, "%s: %s", what, exr_get_default_error_message(rv));
}

/* ---------------------------------------------------------------------------------------
 * Tile grid */

uint32_t imgio_tiles_x(const struct image_desc *d)
{
    return d->tile_size ? (uint32_t)(((uint64_t)d->width + d->tile_size - 1) / d->tile_size) : 0;
}

uint32_t imgio_tiles_y(const struct image_desc *d)
{
    return d->tile_size ? (uint32_t)(((uint64_t)d->height + d->tile_size - 1) / d->tile_size) : 0;
}

void imgio_tile_rect(const struct image_desc *d, uint32_t tx, uint32_t ty, uint32_t *x0, uint32_t *y0,
                     uint32_t *w, uint32_t *h)
{
    uint64_t x = (uint64_t)tx * d->tile_size, y = (uint64_t)ty * d->tile_size;
    /* Out-of-grid tiles get an empty rectangle rather than wrapped arithmetic. */
    uint64_t xe = x + d->tile_size < d->width ? x + d->tile_size : d->width;
    uint64_t ye = y + d->tile_size < d->height ? y + d->tile_size : d->height;
    *x0 = x < d->width ? (uint32_t)x : d->width;
    *y0 = y < d->height ? (uint32_t)y : d->height;
    *w = xe > x ? (uint32_t)(xe - x) : 0;
    *h = ye > y ? (uint32_t)(ye - y) : 0;
}

/* ---------------------------------------------------------------------------------------
 * Header definition shared by encoder, decode check and writer */

static int desc_check(const struct image_desc *d, char *err, size_t errlen)
{
    if (!d) {
        set_err(err, errlen, "imgio: no image description");
        return -1;
    }
    /* OpenEXR boxes are int32; keep headroom so w*h*channels*4 never overflows size_t. */
    if (d->width == 0 || d->height == 0 || d->width > (1u << 20) || d->height > (1u << 20)) {
        set_err(err, errlen, "imgio: bad image size %ux%u", d->width, d->height);
        return -1;
    }
    if (d->tile_size == 0 || d->tile_size > 4096) {
        set_err(err, errlen, "imgio: bad tile size %u", d->tile_size);
        return -1;
    }
    if (d->num_channels == 0 || d->num_channels > IMGIO_MAX_CHANNELS) {
        set_err(err, errlen, "imgio: bad channel count %u", d->num_channels);
        return -1;
    }
    if (d->half_mask >> (d->num_channels - 1) >> 1) {
        set_err(err, errlen, "imgio: half_mask 0x%x names channels beyond %u", d->half_mask, d->num_channels);
        return -1;
    }
    if (d->compression != IMGIO_NONE && d->compression != IMGIO_ZIP && d->compression != IMGIO_PIZ &&
        d->compression != IMGIO_RLE && d->compression != IMGIO_ZIPS) {
        set_err(err, errlen, "imgio: bad compression %d", (int)d->compression);
        return -1;
    }
    for (uint32_t c = 0; c < d->num_channels; c++) {
        size_t n = strnlen(d->channel_names[c], sizeof d->channel_names[c]);
        if (n == 0 || n == sizeof d->channel_names[c]) {
            set_err(err, errlen, "imgio: channel %u has an empty or unterminated name", c);
            return -1;
        }
        for (uint32_t k = 0; k < c; k++)
            if (strcmp(d->channel_names[c], d->channel_names[k]) == 0) {
                set_err(err, errlen, "imgio: duplicate channel name \"%s\"", d->channel_names[c]);
                return -1;
            }
    }
    return 0;
}

static exr_compression_t to_exr_compression(enum imgio_compression c)
{
    switch (c) {
    case IMGIO_ZIP:
        return EXR_COMPRESSION_ZIP;
    case IMGIO_PIZ:
        return EXR_COMPRESSION_PIZ;
    case IMGIO_RLE:
        return EXR_COMPRESSION_RLE;
    case IMGIO_ZIPS:
        return EXR_COMPRESSION_ZIPS;
    case IMGIO_NONE:
    default:
        return EXR_COMPRESSION_NONE;
    }
}

static int channel_is_half(const struct image_desc *d, uint32_t c)
{
    return c < 32 && (d->half_mask >> c & 1u);
}

/* Defines the one tiled part. width/height are passed separately so the decode check can
 * describe a one-tile image with the same tile size and channels. */
static exr_result_t define_part(exr_context_t ctx, const struct image_desc *d, uint32_t width, uint32_t height)
{
    int part = -1;
    exr_result_t rv = exr_add_part(ctx, NULL, EXR_STORAGE_TILED, &part);
    if (rv == EXR_ERR_SUCCESS)
        rv = exr_initialize_required_attr_simple(ctx, part, (int32_t)width, (int32_t)height,
                                                 to_exr_compression(d->compression));
    if (rv == EXR_ERR_SUCCESS)
        rv = exr_set_lineorder(ctx, part, EXR_LINEORDER_RANDOM_Y);
    if (rv == EXR_ERR_SUCCESS)
        rv = exr_set_tile_descriptor(ctx, part, d->tile_size, d->tile_size, EXR_TILE_ONE_LEVEL,
                                     EXR_TILE_ROUND_DOWN);
    for (uint32_t c = 0; rv == EXR_ERR_SUCCESS && c < d->num_channels; c++)
        rv = exr_add_channel(ctx, part, d->channel_names[c], channel_is_half(d, c) ? EXR_PIXEL_HALF : EXR_PIXEL_FLOAT,
                             EXR_PERCEPTUALLY_LOGARITHMIC, 1, 1);
    return rv;
}

/* Bytes of one pixel in a chunk (before compression): 2 per HALF channel, 4 per FLOAT. */
static size_t desc_pixel_bytes(const struct image_desc *d)
{
    size_t b = 0;
    for (uint32_t c = 0; c < d->num_channels; c++)
        b += channel_is_half(d, c) ? 2 : 4;
    return b;
}

/* Renderer channel index of a channel named by the library (channel lists are sorted). */
static int desc_channel_index(const struct image_desc *d, const char *name)
{
    for (uint32_t c = 0; c < d->num_channels; c++)
        if (name && d->channel_names[c][0] == name[0] && strcmp(d->channel_names[c], name) == 0)
            return (int)c;
    return -1;
}

/* ---------------------------------------------------------------------------------------
 * Encoder */

struct imgio_encoder {
    struct image_desc desc;
    struct imgio_stream stream; /* discards everything: the context never writes a chunk */
    exr_context_t ctx;
    /* ZIP and ZIPS chunks: compressed here with libdeflate (zip_compress_chunk), reusing
     * the compressor and the two buffers from tile to tile. */
    struct libdeflate_compressor *deflater;
    uint8_t *zip_tmp, *zip_out;
    size_t zip_cap, zip_out_cap;
};

/* The ZIP codec of OpenEXR (the same bytes for ZIP's 16 and ZIPS's 1 scanline per block:
 * a tile chunk is one block) is a zlib stream of the packed chunk after two reversible
 * steps that make float and half data compressible: the bytes are split into those at
 * even and those at odd offsets, one half after the other, and each byte but the first
 * is replaced by its difference from the previous one plus 128 (mod 256). OpenEXRCore
 * 3.1 compresses with zlib's compress2 (level 6 by default, about 75 instructions a
 * byte on render tiles even at level 1); libdeflate at level 1 writes a valid zlib stream
 * of about the same size (docs/benchmarks.md, "AOVs") in a third of the instructions and
 * is deterministic, so every worker still sends the same bytes for a tile. Readers,
 * OpenEXRCore's decode check included, inflate it like any ZIP chunk. */
#define IMGIO_DEFLATE_LEVEL 1

/* The pipeline's user data while a tile is encoded: where the chunk goes, and the encoder. */
struct chunk_capture {
    uint8_t *bytes;
    size_t size;
    struct imgio_encoder *enc;
};

/* ---------------------------------------------------------------------------------------
 * Packing and unpacking of chunks whose channels are all HALF or FLOAT, unsampled, read
 * from and written to interleaved FLOAT tiles (all Brume writes; what decode_chunk asks
 * for). The packed bytes are, line after line, each channel's w little-endian values in
 * the file's channel order. OpenEXRCore's generic routines convert a value at a time
 * through a type dispatch once the channel types are mixed; these do the same conversions
 * (HALF: round to nearest even, as OpenEXRCore does; back: exact), a plain copy for FLOAT. */

static float bits_float(uint32_t b)
{
    float f;
    memcpy(&f, &b, sizeof f);
    return f;
}

static uint32_t float_bits(float f)
{
    uint32_t b;
    memcpy(&b, &f, sizeof b);
    return b;
}

/* float -> HALF bits, round to nearest even; overflow to infinity; NaN stays NaN with the
 * top of its payload (at least one bit set), as OpenEXRCore's conversion keeps it. */
static uint16_t float_to_half_bits(float f)
{
    uint32_t x = float_bits(f), a = x & 0x7fffffffu;
    uint16_t sign = (uint16_t)(x >> 16 & 0x8000u);
    if (a >= 0x38800000u && a < 0x477ff000u) { /* a normal half: rebias 127 -> 15, RNE */
        uint32_t r = a - 0x38000000u;
        r += 0x0fffu + (r >> 13 & 1u);
        return (uint16_t)(sign | r >> 13);
    }
    if (a < 0x38800000u) /* below 2^-14: adding 0.5 rounds to a multiple of 2^-24 (RNE), exactly the subnormal */
        return (uint16_t)(sign | (float_bits(bits_float(a) + 0.5f) - 0x3f000000u));
    if (a <= 0x7f800000u) /* 65520 and up, infinity */
        return (uint16_t)(sign | 0x7c00u);
    uint32_t m = (a & 0x7fffffu) >> 13; /* NaN */
    return (uint16_t)(sign | 0x7c00u | m | (m == 0));
}

/* HALF bits -> float (exact): the bits moved into place and scaled by 2^112 (normals and
 * subnormals alike); infinity and NaN (payload kept) set apart. */
static float half_bits_to_float(uint16_t h)
{
    uint32_t o = (uint32_t)(h & 0x7fffu) << 13, sign = (uint32_t)(h & 0x8000u) << 16;
    if (o >= 0x0f800000u)
        return bits_float(sign | 0x7f800000u | o);
    return bits_float(sign | float_bits(bits_float(o) * 0x1p112f));
}

#ifdef __SSE2__
/* Four at a time, the same bits: float_to_half_bits on four floats into dst (8 bytes), or 0
 * (nothing written) when one is a NaN, left to the scalar conversion. */
static int float4_to_half_bits(__m128 f, uint8_t *dst)
{
    __m128i x = _mm_castps_si128(f), a = _mm_and_si128(x, _mm_set1_epi32(0x7fffffff));
    if (_mm_movemask_epi8(_mm_cmpgt_epi32(a, _mm_set1_epi32(0x7f800000))))
        return 0;
    __m128i r = _mm_sub_epi32(a, _mm_set1_epi32(0x38000000));
    r = _mm_add_epi32(r, _mm_add_epi32(_mm_set1_epi32(0x0fff), _mm_and_si128(_mm_srli_epi32(r, 13), _mm_set1_epi32(1))));
    r = _mm_srli_epi32(r, 13);
    __m128i sub = _mm_sub_epi32(_mm_castps_si128(_mm_add_ps(_mm_castsi128_ps(a), _mm_set1_ps(0.5f))),
                                _mm_set1_epi32(0x3f000000));
    __m128i is_sub = _mm_cmplt_epi32(a, _mm_set1_epi32(0x38800000)), is_inf = _mm_cmpgt_epi32(a, _mm_set1_epi32(0x477fefff));
    r = _mm_or_si128(_mm_and_si128(is_sub, sub), _mm_andnot_si128(is_sub, r));
    r = _mm_or_si128(_mm_and_si128(is_inf, _mm_set1_epi32(0x7c00)), _mm_andnot_si128(is_inf, r));
    __m128i hi = _mm_srai_epi32(x, 16); /* the sign in bit 15 once packed to 16 bits */
    __m128i h = _mm_or_si128(_mm_packs_epi32(r, r), _mm_and_si128(_mm_packs_epi32(hi, hi), _mm_set1_epi16(-0x8000)));
    _mm_storel_epi64((__m128i *)dst, h);
    return 1;
}

/* half_bits_to_float on four HALFs at src (8 bytes) into dst, dst + ps, dst + 2 ps, dst + 3 ps. */
static void half4_bits_to_float(const uint8_t *src, float *dst, size_t ps)
{
    __m128i h = _mm_unpacklo_epi16(_mm_loadl_epi64((const __m128i *)src), _mm_setzero_si128());
    __m128i o = _mm_slli_epi32(_mm_and_si128(h, _mm_set1_epi32(0x7fff)), 13);
    __m128i fin = _mm_castps_si128(_mm_mul_ps(_mm_castsi128_ps(o), _mm_set1_ps(0x1p112f)));
    __m128i special = _mm_cmpgt_epi32(o, _mm_set1_epi32(0x0f7fffff));
    __m128i r = _mm_or_si128(_mm_and_si128(special, _mm_or_si128(o, _mm_set1_epi32(0x7f800000))),
                             _mm_andnot_si128(special, fin));
    __m128 f = _mm_castsi128_ps(_mm_or_si128(r, _mm_slli_epi32(_mm_and_si128(h, _mm_set1_epi32(0x8000)), 16)));
    _mm_store_ss(dst, f);
    _mm_store_ss(dst + ps, _mm_shuffle_ps(f, f, 1));
    _mm_store_ss(dst + 2 * ps, _mm_shuffle_ps(f, f, 2));
    _mm_store_ss(dst + 3 * ps, _mm_shuffle_ps(f, f, 3));
}
#endif

/* 1 when the channels (n of them, a chunk of w x h) take the routines below. */
static int float_channels_fit(const exr_coding_channel_info_t *chans, int16_t n, int32_t w, int32_t h, int decode)
{
#if defined(__BYTE_ORDER__) && __BYTE_ORDER__ == __ORDER_LITTLE_ENDIAN__
    for (int16_t c = 0; c < n; c++) {
        const exr_coding_channel_info_t *ch = &chans[c];
        const uint8_t *ptr = decode ? ch->decode_to_ptr : ch->encode_from_ptr;
        if ((ch->data_type != EXR_PIXEL_HALF && ch->data_type != EXR_PIXEL_FLOAT) || ch->x_samples != 1 ||
            ch->y_samples != 1 || ch->height != h || ch->width != w ||
            ch->bytes_per_element != (ch->data_type == EXR_PIXEL_HALF ? 2 : 4) ||
            (ptr && (ch->user_data_type != EXR_PIXEL_FLOAT || ch->user_bytes_per_element != 4 ||
                     ch->user_pixel_stride % 4 != 0 || ch->user_line_stride % 4 != 0 || (uintptr_t)ptr % 4 != 0)))
            return 0;
    }
    return 1;
#else
    (void)chans, (void)n, (void)w, (void)h, (void)decode;
    return 0;
#endif
}

/* n floats (4 bytes each) from src to dst, ss and ds bytes apart. */
static void copy_floats(uint8_t *dst, size_t ds, const uint8_t *src, size_t ss, size_t n)
{
    size_t x = 0;
    for (; x + 4 <= n; x += 4, dst += 4 * ds, src += 4 * ss) {
        memcpy(dst, src, 4);
        memcpy(dst + ds, src + ss, 4);
        memcpy(dst + 2 * ds, src + 2 * ss, 4);
        memcpy(dst + 3 * ds, src + 3 * ss, 4);
    }
    for (; x < n; x++, dst += ds, src += ss)
        memcpy(dst, src, 4);
}

static exr_result_t pack_float_chunk(exr_encode_pipeline_t *p)
{
    uint8_t *dst = p->packed_buffer;
    size_t w = (size_t)p->chunk.width, need = 0;
    for (int16_t c = 0; c < p->channel_count; c++)
        need += w * (size_t)p->chunk.height * (size_t)p->channels[c].bytes_per_element;
    if (!dst || need > p->packed_alloc_size)
        return EXR_ERR_INVALID_ARGUMENT;
    for (int32_t y = 0; y < p->chunk.height; y++)
        for (int16_t c = 0; c < p->channel_count; c++) {
            const exr_coding_channel_info_t *ch = &p->channels[c];
            const float *src = (const float *)(ch->encode_from_ptr + (size_t)y * (size_t)ch->user_line_stride);
            size_t ps = (size_t)ch->user_pixel_stride / 4;
            if (ch->data_type == EXR_PIXEL_HALF) {
                size_t x = 0;
#ifdef __SSE2__
                for (; x + 4 <= w; x += 4) {
                    const float *q = src + x * ps;
                    if (!float4_to_half_bits(_mm_set_ps(q[3 * ps], q[2 * ps], q[ps], q[0]), dst + 2 * x))
                        break; /* a NaN: the rest one by one */
                }
#endif
                for (; x < w; x++) {
                    uint16_t hb = float_to_half_bits(src[x * ps]);
                    memcpy(dst + 2 * x, &hb, 2);
                }
                dst += 2 * w;
            } else {
                copy_floats(dst, 4, (const uint8_t *)src, 4 * ps, w);
                dst += 4 * w;
            }
        }
    p->packed_bytes = need;
    return EXR_ERR_SUCCESS;
}

static exr_result_t unpack_float_chunk(exr_decode_pipeline_t *p)
{
    const uint8_t *src = p->unpacked_buffer;
    size_t w = (size_t)p->chunk.width, need = 0;
    for (int16_t c = 0; c < p->channel_count; c++)
        need += w * (size_t)p->chunk.height * (size_t)p->channels[c].bytes_per_element;
    if (!src || need > (size_t)p->chunk.unpacked_size)
        return EXR_ERR_CORRUPT_CHUNK;
    for (int32_t y = 0; y < p->chunk.height; y++)
        for (int16_t c = 0; c < p->channel_count; c++) {
            const exr_coding_channel_info_t *ch = &p->channels[c];
            size_t bytes = (size_t)ch->bytes_per_element;
            if (ch->decode_to_ptr) {
                float *dst = (float *)(ch->decode_to_ptr + (size_t)y * (size_t)ch->user_line_stride);
                size_t ps = (size_t)ch->user_pixel_stride / 4;
                if (bytes == 2) {
                    size_t x = 0;
#ifdef __SSE2__
                    for (; x + 4 <= w; x += 4)
                        half4_bits_to_float(src + 2 * x, dst + x * ps, ps);
#endif
                    for (; x < w; x++) {
                        uint16_t hb;
                        memcpy(&hb, src + 2 * x, 2);
                        dst[x * ps] = half_bits_to_float(hb);
                    }
                } else
                    copy_floats((uint8_t *)dst, 4 * ps, src, 4, w);
            }
            src += w * bytes;
        }
    return EXR_ERR_SUCCESS;
}

static exr_result_t zip_compress_chunk(exr_encode_pipeline_t *p)
{
    struct chunk_capture *cap = p->encoding_user_data;
    struct imgio_encoder *e = cap ? cap->enc : NULL;
    size_t n = (size_t)p->packed_bytes;
    const uint8_t *src = p->packed_buffer;
    if (!e || !src || n == 0)
        return EXR_ERR_INVALID_ARGUMENT;
    size_t bound = libdeflate_zlib_compress_bound(e->deflater, n);
    if (n > e->zip_cap) {
        free(e->zip_tmp);
        e->zip_tmp = mem_alloc(n);
        e->zip_cap = n;
    }
    if (bound > e->zip_out_cap) {
        free(e->zip_out);
        e->zip_out = mem_alloc(bound);
        e->zip_out_cap = bound;
    }
    /* Both steps in one pass: t = src's bytes at even offsets then those at odd ones, t[0]
     * kept and t[i] replaced by t[i] - t[i - 1] + 128 (h: the number of even offsets). */
    uint8_t *t = e->zip_tmp;
    size_t h = (n + 1) / 2;
    t[0] = src[0];
    for (size_t k = 1; k < h; k++)
        t[k] = (uint8_t)(src[2 * k] - src[2 * k - 2] + 128u);
    if (n > 1)
        t[h] = (uint8_t)(src[1] - src[2 * h - 2] + 128u);
    for (size_t k = 1; h + k < n; k++)
        t[h + k] = (uint8_t)(src[2 * k + 1] - src[2 * k - 1] + 128u);
    size_t z = libdeflate_zlib_compress(e->deflater, t, n, e->zip_out, e->zip_out_cap);
    if (z > 0 && z < n) {
        p->compressed_buffer = e->zip_out;
        p->compressed_bytes = z;
    } else { /* incompressible: OpenEXR stores the packed bytes as they are */
        p->compressed_buffer = p->packed_buffer;
        p->compressed_bytes = n;
    }
    p->compressed_alloc_size = 0; /* ours (or the packed buffer): the pipeline frees neither */
    return EXR_ERR_SUCCESS;
}

/* Replaces the pipeline's default write: takes the same buffer and byte count that the
 * default would pass to exr_write_tile_chunk (compressed_buffer, which the pipeline points
 * at the packed bytes when nothing was compressed), so the master can write it unchanged. */
static exr_result_t capture_chunk(exr_encode_pipeline_t *p)
{
    struct chunk_capture *cap = p->encoding_user_data;
    if (!cap || !p->compressed_buffer || p->compressed_bytes == 0)
        return EXR_ERR_INVALID_ARGUMENT;
    cap->bytes = mem_alloc(p->compressed_bytes);
    memcpy(cap->bytes, p->compressed_buffer, p->compressed_bytes);
    cap->size = p->compressed_bytes;
    return EXR_ERR_SUCCESS;
}

struct imgio_encoder *imgio_encoder_new(const struct image_desc *d, char *err, size_t errlen)
{
    if (desc_check(d, err, errlen) != 0)
        return NULL;
    struct imgio_encoder *e = mem_calloc(1, sizeof *e);
    e->desc = *d;
    stream_init(&e->stream);
    exr_context_initializer_t init = stream_initializer(&e->stream);
    exr_result_t rv = exr_start_write(&e->ctx, "<tile encoder>", EXR_WRITE_FILE_DIRECTLY, &init);
    if (rv == EXR_ERR_SUCCESS)
        rv = define_part(e->ctx, d, d->width, d->height);
    if (rv == EXR_ERR_SUCCESS)
        rv = exr_write_header(e->ctx);
    if (rv == EXR_ERR_SUCCESS && (d->compression == IMGIO_ZIP || d->compression == IMGIO_ZIPS) &&
        !(e->deflater = libdeflate_alloc_compressor(IMGIO_DEFLATE_LEVEL)))
        rv = EXR_ERR_OUT_OF_MEMORY;
    if (rv != EXR_ERR_SUCCESS) {
        lib_err(err, errlen, &e->stream, rv, "imgio: cannot set up tile encoder");
        imgio_encoder_free(&e);
        return NULL;
    }
    return e;
}

int imgio_encode_tile(struct imgio_encoder *e, uint32_t tx, uint32_t ty, const float *pixels,
                      uint8_t **chunk, size_t *chunk_size, char *err, size_t errlen)
{
    *chunk = NULL;
    *chunk_size = 0;
    if (!e) {
        set_err(err, errlen, "imgio: encode: no encoder");
        return -1;
    }
    const struct image_desc *d = &e->desc;
    if (tx >= imgio_tiles_x(d) || ty >= imgio_tiles_y(d) || !pixels) {
        set_err(err, errlen, "imgio: encode: tile (%u,%u) outside %ux%u grid or no pixels", tx, ty,
                imgio_tiles_x(d), imgio_tiles_y(d));
        return -1;
    }
    uint32_t x0, y0, w, h;
    imgio_tile_rect(d, tx, ty, &x0, &y0, &w, &h);
    e->stream.lib_msg[0] = '\0';

    exr_chunk_info_t cinfo;
    exr_encode_pipeline_t enc = EXR_ENCODE_PIPELINE_INITIALIZER;
    struct chunk_capture cap = {NULL, 0, e};
    bool pipe_ok = false;
    exr_result_t rv = exr_write_tile_chunk_info(e->ctx, 0, (int)tx, (int)ty, 0, 0, &cinfo);
    if (rv == EXR_ERR_SUCCESS)
        rv = exr_encoding_initialize(e->ctx, 0, &cinfo, &enc);
    if (rv == EXR_ERR_SUCCESS) {
        pipe_ok = true;
        if (cinfo.width != (int32_t)w || cinfo.height != (int32_t)h)
            rv = EXR_ERR_INCORRECT_CHUNK;
    }
    for (int16_t i = 0; rv == EXR_ERR_SUCCESS && i < enc.channel_count; i++) {
        exr_coding_channel_info_t *ch = &enc.channels[i];
        int c = desc_channel_index(d, ch->channel_name);
        if (c < 0) {
            rv = EXR_ERR_INVALID_ARGUMENT;
            break;
        }
        /* Read straight from the interleaved tile: no deinterleaving copy. */
        ch->user_bytes_per_element = 4;
        ch->user_data_type = EXR_PIXEL_FLOAT;
        ch->user_pixel_stride = (int32_t)(d->num_channels * sizeof(float));
        ch->user_line_stride = (int32_t)((size_t)w * d->num_channels * sizeof(float));
        ch->encode_from_ptr = (const uint8_t *)(pixels + c);
    }
    if (rv == EXR_ERR_SUCCESS)
        rv = exr_encoding_choose_default_routines(e->ctx, 0, &enc);
    if (rv == EXR_ERR_SUCCESS) {
        enc.encoding_user_data = &cap;
        if (e->deflater)
            enc.compress_fn = zip_compress_chunk;
        if (float_channels_fit(enc.channels, enc.channel_count, enc.chunk.width, enc.chunk.height, 0))
            enc.convert_and_pack_fn = pack_float_chunk;
        enc.write_fn = capture_chunk;
        /* The default yield checks write ordering of a real file; nothing is written here. */
        enc.yield_until_ready_fn = NULL;
        rv = exr_encoding_run(e->ctx, 0, &enc);
    }
    if (pipe_ok)
        exr_encoding_destroy(e->ctx, &enc);
    if (rv != EXR_ERR_SUCCESS || !cap.bytes) {
        free(cap.bytes);
        char what[96];
        snprintf(what, sizeof what, "imgio: encode tile (%u,%u)", tx, ty);
        lib_err(err, errlen, &e->stream, rv != EXR_ERR_SUCCESS ? rv : EXR_ERR_UNKNOWN, what);
        return -1;
    }
    *chunk = cap.bytes;
    *chunk_size = cap.size;
    return 0;
}

void imgio_encoder_free(struct imgio_encoder **e)
{
    if (!e || !*e)
        return;
    if ((*e)->ctx)
        exr_finish(&(*e)->ctx); /* its offset table goes to the discarding stream */
    if ((*e)->deflater)
        libdeflate_free_compressor((*e)->deflater);
    free((*e)->zip_tmp);
    free((*e)->zip_out);
    free(*e);
    *e = NULL;
}

/* ---------------------------------------------------------------------------------------
 * Decode check. The chunk's bytes depend only on the tile's clipped size, the channels and
 * the compression, not on where the tile sits. So the check builds, in memory, a complete
 * one-tile file (w x h image, same tile size and channels): header bytes captured from a
 * write context, a one-entry offset table, the chunk leader for tile (0,0) and the chunk.
 * That is O(1) per call whatever the image size, and it runs the library's own reader with
 * its bounds checks over bytes we fully control. */

/* Captures the header of a one-tile image; returns 0 or -1. *hdr is mem_alloc'd. */
static int capture_tile_header(const struct image_desc *d, uint32_t w, uint32_t h, uint8_t **hdr, size_t *hdr_len,
                               char *err, size_t errlen)
{
    struct imgio_stream s;
    stream_init(&s);
    s.capture = true;
    exr_context_initializer_t init = stream_initializer(&s);
    exr_context_t ctx = NULL;
    exr_result_t rv = exr_start_write(&ctx, "<decode check>", EXR_WRITE_FILE_DIRECTLY, &init);
    if (rv == EXR_ERR_SUCCESS)
        rv = define_part(ctx, d, w, h);
    if (rv == EXR_ERR_SUCCESS)
        rv = exr_write_header(ctx);
    s.capture = false; /* the offset table written at finish is ours to build */
    if (rv != EXR_ERR_SUCCESS)
        lib_err(err, errlen, &s, rv, "imgio: decode check: cannot build header");
    if (ctx)
        exr_finish(&ctx);
    if (rv != EXR_ERR_SUCCESS) {
        free(s.dst);
        return -1;
    }
    *hdr = s.dst;
    *hdr_len = s.dst_len;
    return 0;
}

/* Decodes chunk k of an open read context into interleaved floats for the requested
 * channels (want[i] names output channel i; NULL-terminated list of nc names). The
 * rectangle (ox, oy, w, h) in the output image of stride out_w receives the chunk. */
struct decode_target {
    float *pixels;
    size_t out_w;        /* pixels per output row */
    uint32_t nc;         /* output channels, interleaved */
    const char *const *names;
};

/* ZIP and ZIPS chunks are inflated with libdeflate (in about half of zlib's instructions),
 * then the two steps of zip_compress_chunk are undone. The pipeline's user data while a
 * chunk is decoded: the decompressor and a buffer for the inflated bytes. */
struct zip_inflate {
    struct libdeflate_decompressor *inflater;
    uint8_t *tmp, *out;
};

/* t[i] = t[0] + sum over 0 < j <= i of (t[j] - 128), mod 256, in place: the running sums
 * that undo zip_compress_chunk's differences. With SSE2, 16 bytes at a time (a prefix sum
 * in four shifted adds, plus the carry of the bytes before): the same bytes. */
static void zip_running_sums(uint8_t *t, size_t n)
{
    if (n == 0)
        return;
    uint8_t v = t[0];
    size_t i = 1;
#ifdef __SSE2__
    const __m128i bias = _mm_set1_epi8((char)0x80);
    for (; i + 16 <= n; i += 16) {
        __m128i x = _mm_sub_epi8(_mm_loadu_si128((const __m128i *)(t + i)), bias);
        x = _mm_add_epi8(x, _mm_slli_si128(x, 1));
        x = _mm_add_epi8(x, _mm_slli_si128(x, 2));
        x = _mm_add_epi8(x, _mm_slli_si128(x, 4));
        x = _mm_add_epi8(x, _mm_slli_si128(x, 8));
        x = _mm_add_epi8(x, _mm_set1_epi8((char)v));
        _mm_storeu_si128((__m128i *)(t + i), x);
        v = t[i + 15];
    }
#endif
    for (; i < n; i++)
        t[i] = v = (uint8_t)(v + t[i] - 128u);
}

static exr_result_t zip_decompress_chunk(exr_decode_pipeline_t *p)
{
    struct zip_inflate *z = p->decoding_user_data;
    size_t n = (size_t)p->chunk.unpacked_size, packed = (size_t)p->chunk.packed_size, got = 0;
    if (!z || !p->packed_buffer)
        return EXR_ERR_INVALID_ARGUMENT;
    if (n == 0)
        return EXR_ERR_SUCCESS;
    if (packed == 0)
        return EXR_ERR_CORRUPT_CHUNK;
    if (!p->unpacked_buffer) { /* ours; the pipeline frees only what it allocated */
        free(z->out);
        z->out = mem_alloc(n);
        p->unpacked_buffer = z->out;
        p->unpacked_alloc_size = 0;
    }
    uint8_t *dst = p->unpacked_buffer;
    if (packed == n) { /* stored as it was: not compressed */
        if ((void *)dst != p->packed_buffer)
            memcpy(dst, p->packed_buffer, n);
        return EXR_ERR_SUCCESS;
    }
    free(z->tmp);
    z->tmp = mem_alloc(n);
    /* The stream must fill the chunk exactly and inflate to exactly its unpacked size (no
     * trailing bytes: the master writes a chunk's bytes into the file as they are). */
    size_t used = 0;
    if (libdeflate_zlib_decompress_ex(z->inflater, p->packed_buffer, packed, z->tmp, n, &used, &got) !=
            LIBDEFLATE_SUCCESS ||
        got != n || used != packed)
        return EXR_ERR_CORRUPT_CHUNK;
    /* Both steps undone: the running sums of the differences (mod 256), in place, then the
     * first half to the even offsets and the second to the odd ones. */
    uint8_t *t = z->tmp;
    size_t h = (n + 1) / 2;
    zip_running_sums(t, n);
    size_t k = 0;
#ifdef __SSE2__
    for (; k + 16 <= n - h; k += 16) { /* 16 even and 16 odd bytes into 32 of dst */
        __m128i e = _mm_loadu_si128((const __m128i *)(t + k)), o = _mm_loadu_si128((const __m128i *)(t + h + k));
        _mm_storeu_si128((__m128i *)(dst + 2 * k), _mm_unpacklo_epi8(e, o));
        _mm_storeu_si128((__m128i *)(dst + 2 * k + 16), _mm_unpackhi_epi8(e, o));
    }
#endif
    for (; k < h; k++) {
        dst[2 * k] = t[k];
        if (h + k < n)
            dst[2 * k + 1] = t[h + k];
    }
    return EXR_ERR_SUCCESS;
}

static exr_result_t decode_chunk(exr_context_t ctx, const exr_chunk_info_t *cinfo, const struct decode_target *t,
                                 size_t ox, size_t oy)
{
    exr_decode_pipeline_t dec = EXR_DECODE_PIPELINE_INITIALIZER;
    exr_result_t rv = exr_decoding_initialize(ctx, 0, cinfo, &dec);
    if (rv != EXR_ERR_SUCCESS)
        return rv;
    int used = 0;
    for (int16_t i = 0; i < dec.channel_count; i++) {
        exr_coding_channel_info_t *ch = &dec.channels[i];
        ch->decode_to_ptr = NULL; /* channels nobody asked for are skipped */
        for (uint32_t c = 0; c < t->nc; c++) {
            if (!ch->channel_name || ch->channel_name[0] != t->names[c][0] ||
                strcmp(ch->channel_name, t->names[c]) != 0)
                continue;
            ch->user_bytes_per_element = 4;
            ch->user_data_type = EXR_PIXEL_FLOAT;
            ch->user_pixel_stride = (int32_t)(t->nc * sizeof(float));
            ch->user_line_stride = (int32_t)(t->out_w * t->nc * sizeof(float));
            ch->decode_to_ptr = (uint8_t *)(t->pixels + (oy * t->out_w + ox) * t->nc + c);
            used++;
        }
    }
    if (used == 0) {
        exr_decoding_destroy(ctx, &dec);
        return EXR_ERR_INVALID_ARGUMENT;
    }
    rv = exr_decoding_choose_default_routines(ctx, 0, &dec);
    exr_compression_t comp = EXR_COMPRESSION_NONE;
    struct zip_inflate zi = {NULL, NULL, NULL};
    if (rv == EXR_ERR_SUCCESS && dec.decompress_fn && exr_get_compression(ctx, 0, &comp) == EXR_ERR_SUCCESS &&
        (comp == EXR_COMPRESSION_ZIP || comp == EXR_COMPRESSION_ZIPS) &&
        (zi.inflater = libdeflate_alloc_decompressor())) {
        dec.decoding_user_data = &zi;
        dec.decompress_fn = zip_decompress_chunk;
        /* (our decompress_fn always leaves the unpacked bytes in unpacked_buffer) */
        if (float_channels_fit(dec.channels, dec.channel_count, dec.chunk.width, dec.chunk.height, 1))
            dec.unpack_and_convert_fn = unpack_float_chunk;
    }
    if (rv == EXR_ERR_SUCCESS)
        rv = exr_decoding_run(ctx, 0, &dec);
    exr_decoding_destroy(ctx, &dec);
    if (zi.inflater)
        libdeflate_free_decompressor(zi.inflater);
    free(zi.tmp);
    free(zi.out);
    return rv;
}

int imgio_decode_tile(const struct image_desc *d, uint32_t tx, uint32_t ty, const uint8_t *chunk,
                      size_t chunk_size, float *pixels, char *err, size_t errlen)
{
    if (desc_check(d, err, errlen) != 0)
        return -1;
    if (tx >= imgio_tiles_x(d) || ty >= imgio_tiles_y(d)) {
        set_err(err, errlen, "imgio: decode: tile (%u,%u) outside %ux%u grid", tx, ty, imgio_tiles_x(d),
                imgio_tiles_y(d));
        return -1;
    }
    if (!pixels) {
        set_err(err, errlen, "imgio: decode: no output buffer");
        return -1;
    }
    uint32_t x0, y0, w, h;
    imgio_tile_rect(d, tx, ty, &x0, &y0, &w, &h);
    size_t raw = (size_t)w * h * desc_pixel_bytes(d);
    /* A chunk never exceeds its raw size (OpenEXR stores raw bytes when compression would
     * grow them), and uncompressed chunks are exactly that size. */
    if (!chunk || chunk_size == 0 || chunk_size > raw || (d->compression == IMGIO_NONE && chunk_size != raw)) {
        set_err(err, errlen, "imgio: decode tile (%u,%u): chunk of %zu bytes, expected %s%zu", tx, ty,
                chunk ? chunk_size : 0, d->compression == IMGIO_NONE ? "" : "1 to ", raw);
        return -1;
    }

    uint8_t *file = NULL;
    size_t hdr_len = 0;
    if (capture_tile_header(d, w, h, &file, &hdr_len, err, errlen) != 0)
        return -1;
    size_t file_len = hdr_len + 8 + TILE_LEADER_BYTES + chunk_size;
    file = mem_realloc(file, file_len);
    uint8_t *p = file + hdr_len;
    bytes_put_u64(p, hdr_len + 8);
    p += 8;
    bytes_put_u32(p, 0);  /* tile x */
    bytes_put_u32(p + 4, 0);  /* tile y */
    bytes_put_u32(p + 8, 0);  /* level x */
    bytes_put_u32(p + 12, 0); /* level y */
    bytes_put_u32(p + 16, (uint32_t)chunk_size);
    memcpy(p + TILE_LEADER_BYTES, chunk, chunk_size);

    struct imgio_stream s;
    stream_init(&s);
    s.src = file;
    s.src_len = file_len;
    exr_context_initializer_t init = stream_initializer(&s);
    exr_context_t ctx = NULL;
    exr_chunk_info_t cinfo;
    exr_result_t rv = exr_start_read(&ctx, "<decode check>", &init);
    if (rv == EXR_ERR_SUCCESS)
        rv = exr_read_tile_chunk_info(ctx, 0, 0, 0, 0, 0, &cinfo);
    if (rv == EXR_ERR_SUCCESS && (cinfo.width != (int32_t)w || cinfo.height != (int32_t)h ||
                                  cinfo.packed_size != chunk_size || cinfo.unpacked_size != raw))
        rv = EXR_ERR_CORRUPT_CHUNK;
    if (rv == EXR_ERR_SUCCESS) {
        const char *names[IMGIO_MAX_CHANNELS];
        for (uint32_t c = 0; c < d->num_channels; c++)
            names[c] = d->channel_names[c];
        struct decode_target t = {pixels, w, d->num_channels, names};
        rv = decode_chunk(ctx, &cinfo, &t, 0, 0);
    }
    if (rv != EXR_ERR_SUCCESS) {
        char what[96];
        snprintf(what, sizeof what, "imgio: decode tile (%u,%u) of %zu bytes", tx, ty, chunk_size);
        lib_err(err, errlen, &s, rv, what);
    }
    if (ctx)
        exr_finish(&ctx);
    free(file);
    return rv == EXR_ERR_SUCCESS ? 0 : -1;
}

/* ---------------------------------------------------------------------------------------
 * Writer */

struct imgio_writer {
    struct image_desc desc;
    struct imgio_stream stream; /* our fd, so close can fsync it */
    exr_context_t ctx;
    char *path;
    bool unlink_on_failure; /* only a regular file we opened, never e.g. a device node */
    /* OpenEXRCore counts chunk writes and stops accepting any once it has seen as many
     * as the file has tiles, so a duplicate would lock out a missing tile: track them. */
    uint8_t *written;
    uint32_t num_written, num_tiles;
    /* The first failed tile write (e.g. "No space left on device"): close reports it, not
     * the missing tiles it left, whatever error buffer the caller gives close. */
    char first_err[512];
};

static void writer_discard(struct imgio_writer *w)
{
    if (w->ctx)
        exr_finish(&w->ctx);
    if (w->stream.fd >= 0) {
        close(w->stream.fd);
        /* A half-written file is useless; the caller renames only on success. */
        if (w->unlink_on_failure)
            unlink(w->path);
    }
    free(w->written);
    free(w->path);
    free(w);
}

struct imgio_writer *imgio_writer_open(const char *path, const struct image_desc *d,
                                       const struct image_attrs *a, char *err, size_t errlen)
{
    if (desc_check(d, err, errlen) != 0)
        return NULL;
    if (!path || !a) {
        set_err(err, errlen, "imgio: writer needs a path and attributes");
        return NULL;
    }
    if (a->spp > INT32_MAX) {
        set_err(err, errlen, "%s: spp %u does not fit the int attribute", path, a->spp);
        return NULL;
    }
    struct imgio_writer *w = mem_calloc(1, sizeof *w);
    w->desc = *d;
    w->path = mem_strdup(path);
    w->num_tiles = imgio_tiles_x(d) * imgio_tiles_y(d);
    w->written = mem_calloc(w->num_tiles, 1);
    stream_init(&w->stream);
    w->stream.fd = open(path, O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
    if (w->stream.fd < 0) {
        set_err(err, errlen, "%s: cannot create: %s", path, strerror(errno));
        writer_discard(w);
        return NULL;
    }
    struct stat st;
    w->unlink_on_failure = fstat(w->stream.fd, &st) == 0 && S_ISREG(st.st_mode);
    exr_context_initializer_t init = stream_initializer(&w->stream);
    exr_result_t rv = exr_start_write(&w->ctx, path, EXR_WRITE_FILE_DIRECTLY, &init);
    if (rv == EXR_ERR_SUCCESS)
        rv = define_part(w->ctx, d, d->width, d->height);
    char seed[24], hash[sizeof a->scene_hash], sw[sizeof a->software];
    snprintf(seed, sizeof seed, "%llu", (unsigned long long)a->seed);
    snprintf(hash, sizeof hash, "%s", a->scene_hash); /* terminate even if the caller did not */
    snprintf(sw, sizeof sw, "%s", a->software);
    if (rv == EXR_ERR_SUCCESS)
        rv = exr_attr_set_int(w->ctx, 0, "brume_spp", (int32_t)a->spp);
    if (rv == EXR_ERR_SUCCESS)
        rv = exr_attr_set_string(w->ctx, 0, "brume_seed", seed);
    if (rv == EXR_ERR_SUCCESS)
        rv = exr_attr_set_double(w->ctx, 0, "brume_render_seconds", a->render_seconds);
    if (rv == EXR_ERR_SUCCESS)
        rv = exr_attr_set_string(w->ctx, 0, "brume_scene_hash", hash);
    if (rv == EXR_ERR_SUCCESS && sw[0])
        rv = exr_attr_set_string(w->ctx, 0, "software", sw);
    if (rv == EXR_ERR_SUCCESS)
        rv = exr_attr_set_double(w->ctx, 0, "brume_est_rel_rmse", a->est_rel_rmse);
    if (rv == EXR_ERR_SUCCESS && a->passes > 1)
        rv = exr_attr_set_int(w->ctx, 0, "brume_passes", (int32_t)(a->passes & INT32_MAX));
    if (rv == EXR_ERR_SUCCESS && a->target_error > 0.0)
        rv = exr_attr_set_double(w->ctx, 0, "brume_target_error", a->target_error);
    if (rv == EXR_ERR_SUCCESS && a->pixel_error > 0.0)
        rv = exr_attr_set_double(w->ctx, 0, "brume_pixel_error", a->pixel_error);
    if (rv == EXR_ERR_SUCCESS && a->rounds > 0)
        rv = exr_attr_set_int(w->ctx, 0, "brume_rounds", (int32_t)(a->rounds & INT32_MAX));
    if (rv == EXR_ERR_SUCCESS && a->time_limited)
        rv = exr_attr_set_int(w->ctx, 0, "brume_time_limited", 1);
    for (uint32_t i = 0; rv == EXR_ERR_SUCCESS && i < a->num_strings; i++)
        rv = exr_attr_set_string(w->ctx, 0, a->string_names[i], a->string_values[i]);
    if (rv == EXR_ERR_SUCCESS)
        rv = exr_write_header(w->ctx);
    if (rv != EXR_ERR_SUCCESS) {
        char what[300];
        snprintf(what, sizeof what, "%s: cannot write EXR header", path);
        lib_err(err, errlen, &w->stream, rv, what);
        writer_discard(w);
        return NULL;
    }
    return w;
}

int imgio_writer_put_tile(struct imgio_writer *w, uint32_t tx, uint32_t ty, const uint8_t *chunk,
                          size_t chunk_size, char *err, size_t errlen)
{
    if (!w) {
        set_err(err, errlen, "imgio: put tile: no writer");
        return -1;
    }
    const struct image_desc *d = &w->desc;
    if (tx >= imgio_tiles_x(d) || ty >= imgio_tiles_y(d)) {
        set_err(err, errlen, "%s: tile (%u,%u) outside %ux%u grid", w->path, tx, ty, imgio_tiles_x(d),
                imgio_tiles_y(d));
        return -1;
    }
    uint32_t x0, y0, tw, th;
    imgio_tile_rect(d, tx, ty, &x0, &y0, &tw, &th);
    size_t raw = (size_t)tw * th * d->num_channels * sizeof(float);
    if (!chunk || chunk_size == 0 || chunk_size > raw) {
        set_err(err, errlen, "%s: tile (%u,%u): chunk of %zu bytes, at most %zu allowed", w->path, tx, ty,
                chunk ? chunk_size : 0, raw);
        return -1;
    }
    /* Re-issued tiles are bit-identical (deterministic rendering), so the first one wins. */
    size_t k = (size_t)ty * imgio_tiles_x(d) + tx;
    if (w->written[k]) {
        log_debug("%s: tile (%u,%u) already written; duplicate skipped", w->path, tx, ty);
        return 0;
    }
    w->stream.lib_msg[0] = '\0';
    exr_result_t rv = exr_write_tile_chunk(w->ctx, 0, (int)tx, (int)ty, 0, 0, chunk, chunk_size);
    if (rv != EXR_ERR_SUCCESS) {
        char what[300];
        snprintf(what, sizeof what, "%s: cannot write tile (%u,%u)", w->path, tx, ty);
        lib_err(err, errlen, &w->stream, rv, what);
        if (!w->first_err[0])
            lib_err(w->first_err, sizeof w->first_err, &w->stream, rv, what);
        return -1;
    }
    w->written[k] = 1;
    w->num_written++;
    return 0;
}

int imgio_writer_close(struct imgio_writer **wp, char *err, size_t errlen)
{
    if (!wp || !*wp)
        return 0;
    struct imgio_writer *w = *wp;
    *wp = NULL;
    if (w->num_written != w->num_tiles) {
        /* The offset table would point at nothing: never leave such a file behind. */
        if (w->first_err[0])
            set_err(err, errlen, "%s", w->first_err);
        else
            set_err(err, errlen, "%s: %u of %u tiles missing", w->path, w->num_tiles - w->num_written, w->num_tiles);
        writer_discard(w);
        return -1;
    }
    w->stream.lib_msg[0] = '\0';
    exr_result_t rv = exr_finish(&w->ctx); /* writes the offset table through our stream */
    w->ctx = NULL;
    if (rv != EXR_ERR_SUCCESS || w->stream.io_errno) {
        char what[300];
        snprintf(what, sizeof what, "%s: cannot finish EXR", w->path);
        lib_err(err, errlen, &w->stream, rv != EXR_ERR_SUCCESS ? rv : EXR_ERR_WRITE_IO, what);
        writer_discard(w);
        return -1;
    }
    /* Durable before the caller renames it into place. */
    if (fsync(w->stream.fd) != 0) {
        set_err(err, errlen, "%s: fsync: %s", w->path, strerror(errno));
        writer_discard(w);
        return -1;
    }
    int fd = w->stream.fd;
    w->stream.fd = -1;
    if (close(fd) != 0) {
        set_err(err, errlen, "%s: close: %s", w->path, strerror(errno));
        if (w->unlink_on_failure)
            unlink(w->path);
        writer_discard(w);
        return -1;
    }
    writer_discard(w);
    return 0;
}

/* ---------------------------------------------------------------------------------------
 * Reading any EXR */

static int read_stream(struct imgio_stream *sp, const char *path, const char *const *channels,
                       uint32_t num_channels, uint32_t max_side, float **pixels, uint32_t *width, uint32_t *height,
                       char *err, size_t errlen);

int imgio_read(const char *path, const char *const *channels, uint32_t num_channels, float **pixels,
               uint32_t *width, uint32_t *height, char *err, size_t errlen)
{
    *pixels = NULL;
    *width = *height = 0;
    if (!path || !channels || num_channels == 0) {
        set_err(err, errlen, "imgio: read: no path or no channels requested");
        return -1;
    }
    struct imgio_stream s;
    if (stream_open_read(&s, path, err, errlen) != 0)
        return -1;
    int rc = read_stream(&s, path, channels, num_channels, IMGIO_READ_MAX_SIDE, pixels, width, height, err, errlen);
    close(s.fd);
    return rc;
}

int imgio_read_memory(const char *name, const uint8_t *data, size_t size, const char *const *channels,
                      uint32_t num_channels, uint32_t max_side, float **pixels, uint32_t *width, uint32_t *height,
                      char *err, size_t errlen)
{
    *pixels = NULL;
    *width = *height = 0;
    if (!name || !channels || num_channels == 0) {
        set_err(err, errlen, "imgio: read: no name or no channels requested");
        return -1;
    }
    struct imgio_stream s;
    stream_init(&s);
    s.src = data;
    s.src_len = size;
    if (max_side == 0 || max_side > IMGIO_READ_MAX_SIDE)
        max_side = IMGIO_READ_MAX_SIDE;
    return read_stream(&s, name, channels, num_channels, max_side, pixels, width, height, err, errlen);
}

static int read_stream(struct imgio_stream *sp, const char *path, const char *const *channels,
                       uint32_t num_channels, uint32_t max_side, float **pixels, uint32_t *width, uint32_t *height,
                       char *err, size_t errlen)
{
    exr_context_initializer_t init = stream_initializer(sp);
    exr_context_t ctx = NULL;
    float *out = NULL;
    char what[300];
    snprintf(what, sizeof what, "%s: cannot read EXR", path);
    int ok = 0;

    exr_result_t rv = exr_start_read(&ctx, path, &init);
    exr_storage_t storage = EXR_STORAGE_LAST_TYPE;
    exr_attr_box2i_t dw;
    memset(&dw, 0, sizeof dw);
    const exr_attr_chlist_t *chl = NULL;
    if (rv == EXR_ERR_SUCCESS)
        rv = exr_get_storage(ctx, 0, &storage);
    if (rv == EXR_ERR_SUCCESS)
        rv = exr_get_data_window(ctx, 0, &dw);
    if (rv == EXR_ERR_SUCCESS)
        rv = exr_get_channels(ctx, 0, &chl);
    if (rv != EXR_ERR_SUCCESS) {
        lib_err(err, errlen, sp, rv, what);
        goto done;
    }
    if (storage != EXR_STORAGE_SCANLINE && storage != EXR_STORAGE_TILED) {
        set_err(err, errlen, "%s: deep images are not supported", path);
        goto done;
    }
    int64_t iw = (int64_t)dw.max.x - dw.min.x + 1, ih = (int64_t)dw.max.y - dw.min.y + 1;
    if (iw <= 0 || ih <= 0 || (uint64_t)iw * (uint64_t)ih * num_channels > ((uint64_t)1 << 32)) {
        set_err(err, errlen, "%s: unsupported data window %lldx%lld", path, (long long)iw, (long long)ih);
        goto done;
    }
    /* Before the pixels are allocated: a header of a few bytes may claim any size. */
    if (iw > max_side || ih > max_side) {
        set_err(err, errlen, "%s: image size %lldx%lld not supported (each side 1..%u)", path, (long long)iw,
                (long long)ih, max_side);
        goto done;
    }
    for (uint32_t c = 0; c < num_channels; c++) {
        /* One library channel decodes into one place, so a repeat would stay zero. */
        for (uint32_t k = 0; k < c; k++)
            if (channels[c] && channels[k] && strcmp(channels[c], channels[k]) == 0) {
                set_err(err, errlen, "%s: channel \"%s\" requested twice", path, channels[c]);
                goto done;
            }
        const exr_attr_chlist_entry_t *found = NULL;
        for (int i = 0; i < chl->num_channels; i++)
            if (channels[c] && chl->entries[i].name.str && strcmp(chl->entries[i].name.str, channels[c]) == 0)
                found = &chl->entries[i];
        if (!found) {
            set_err(err, errlen, "%s: no channel \"%s\"", path, channels[c] ? channels[c] : "(null)");
            goto done;
        }
        if (found->pixel_type != EXR_PIXEL_HALF && found->pixel_type != EXR_PIXEL_FLOAT) {
            set_err(err, errlen, "%s: channel \"%s\" is not HALF or FLOAT", path, channels[c]);
            goto done;
        }
        if (found->x_sampling != 1 || found->y_sampling != 1) {
            set_err(err, errlen, "%s: channel \"%s\" is subsampled", path, channels[c]);
            goto done;
        }
    }
    out = mem_calloc((size_t)iw * (size_t)ih * num_channels, sizeof(float));
    struct decode_target t = {out, (size_t)iw, num_channels, channels};
    exr_chunk_info_t cinfo;
    if (storage == EXR_STORAGE_SCANLINE) {
        int32_t lines = 0;
        rv = exr_get_scanlines_per_chunk(ctx, 0, &lines);
        if (rv == EXR_ERR_SUCCESS && lines <= 0)
            rv = EXR_ERR_FILE_BAD_HEADER;
        for (int64_t y = dw.min.y; rv == EXR_ERR_SUCCESS && y <= dw.max.y; y += lines) {
            rv = exr_read_scanline_chunk_info(ctx, 0, (int)y, &cinfo);
            if (rv != EXR_ERR_SUCCESS)
                break;
            int64_t cy = (int64_t)cinfo.start_y - dw.min.y;
            if (cy < 0 || cinfo.height <= 0 || cy + cinfo.height > ih || cinfo.width != iw) {
                rv = EXR_ERR_CORRUPT_CHUNK;
                break;
            }
            rv = decode_chunk(ctx, &cinfo, &t, 0, (size_t)cy);
        }
    } else {
        int32_t tw = 0, th = 0, lw = 0, lh = 0, cx = 0, cy = 0;
        rv = exr_get_tile_sizes(ctx, 0, 0, 0, &tw, &th);
        if (rv == EXR_ERR_SUCCESS)
            rv = exr_get_level_sizes(ctx, 0, 0, 0, &lw, &lh);
        if (rv == EXR_ERR_SUCCESS && (tw <= 0 || th <= 0 || lw != iw || lh != ih))
            rv = EXR_ERR_FILE_BAD_HEADER;
        if (rv == EXR_ERR_SUCCESS) {
            cx = (int32_t)((lw + (int64_t)tw - 1) / tw);
            cy = (int32_t)((lh + (int64_t)th - 1) / th);
        }
        for (int32_t ty = 0; rv == EXR_ERR_SUCCESS && ty < cy; ty++)
            for (int32_t tx = 0; rv == EXR_ERR_SUCCESS && tx < cx; tx++) {
                rv = exr_read_tile_chunk_info(ctx, 0, tx, ty, 0, 0, &cinfo);
                if (rv != EXR_ERR_SUCCESS)
                    break;
                int64_t px = (int64_t)tx * tw, py = (int64_t)ty * th;
                if (cinfo.width <= 0 || cinfo.height <= 0 || px + cinfo.width > iw || py + cinfo.height > ih) {
                    rv = EXR_ERR_CORRUPT_CHUNK;
                    break;
                }
                rv = decode_chunk(ctx, &cinfo, &t, (size_t)px, (size_t)py);
            }
    }
    if (rv != EXR_ERR_SUCCESS) {
        lib_err(err, errlen, sp, rv, what);
        goto done;
    }
    *pixels = out;
    out = NULL;
    *width = (uint32_t)iw;
    *height = (uint32_t)ih;
    ok = 1;
done:
    free(out);
    if (ctx)
        exr_finish(&ctx);
    return ok ? 0 : -1;
}

int imgio_read_attrs(const char *path, struct image_desc *d, struct image_attrs *a, char *err, size_t errlen)
{
    memset(d, 0, sizeof *d);
    memset(a, 0, sizeof *a);
    struct imgio_stream s;
    if (stream_open_read(&s, path, err, errlen) != 0)
        return -1;
    exr_context_initializer_t init = stream_initializer(&s);
    exr_context_t ctx = NULL;
    char what[300];
    snprintf(what, sizeof what, "%s: cannot read the EXR header", path);
    exr_attr_box2i_t dw;
    memset(&dw, 0, sizeof dw);
    exr_storage_t storage = EXR_STORAGE_LAST_TYPE;
    uint32_t tx = 0, ty = 0;
    int32_t spp = 0, seed_len = 0, hash_len = 0;
    const char *seed = NULL, *hash = NULL;
    exr_result_t rv = exr_start_read(&ctx, path, &init);
    if (rv == EXR_ERR_SUCCESS)
        rv = exr_get_data_window(ctx, 0, &dw);
    if (rv == EXR_ERR_SUCCESS)
        rv = exr_get_storage(ctx, 0, &storage);
    if (rv == EXR_ERR_SUCCESS && storage == EXR_STORAGE_TILED)
        rv = exr_get_tile_descriptor(ctx, 0, &tx, &ty, NULL, NULL);
    if (rv == EXR_ERR_SUCCESS)
        rv = exr_attr_get_int(ctx, 0, "brume_spp", &spp);
    if (rv == EXR_ERR_SUCCESS)
        rv = exr_attr_get_string(ctx, 0, "brume_seed", &seed_len, &seed);
    if (rv == EXR_ERR_SUCCESS)
        rv = exr_attr_get_string(ctx, 0, "brume_scene_hash", &hash_len, &hash);
    int ok = 0;
    if (rv != EXR_ERR_SUCCESS) {
        lib_err(err, errlen, &s, rv, what);
    } else if (dw.max.x < dw.min.x || dw.max.y < dw.min.y || spp < 0 || seed_len <= 0 || seed_len > 20 ||
               hash_len <= 0 || (size_t)hash_len >= sizeof a->scene_hash) {
        set_err(err, errlen, "%s: not a header this renderer wrote", path);
    } else {
        char seed_s[24];
        memcpy(seed_s, seed, (size_t)seed_len);
        seed_s[seed_len] = '\0';
        char *end;
        errno = 0;
        a->seed = strtoull(seed_s, &end, 10);
        if (errno != 0 || *end != '\0') {
            set_err(err, errlen, "%s: brume_seed \"%s\" is not a number", path, seed_s);
        } else {
            memcpy(a->scene_hash, hash, (size_t)hash_len);
            a->scene_hash[hash_len] = '\0';
            a->spp = (uint32_t)spp;
            d->width = (uint32_t)((int64_t)dw.max.x - dw.min.x + 1);
            d->height = (uint32_t)((int64_t)dw.max.y - dw.min.y + 1);
            d->tile_size = tx == ty ? tx : 0;
            ok = 1;
        }
    }
    if (ctx)
        exr_finish(&ctx);
    close(s.fd);
    return ok ? 0 : -1;
}

/* ---------------------------------------------------------------------------------------
 * PNG preview */

struct png_failure {
    char msg[200];
};

static void on_png_error(png_structp png, png_const_charp msg)
{
    struct png_failure *f = png_get_error_ptr(png);
    if (f)
        snprintf(f->msg, sizeof f->msg, "%s", msg ? msg : "libpng error");
    png_longjmp(png, 1);
}

static void on_png_warning(png_structp png, png_const_charp msg)
{
    (void)png;
    log_debug("libpng: %s", msg ? msg : "");
}

static uint8_t srgb_byte(float v, float exposure)
{
    float x = v * exposure;
    if (!(x > 0.0f)) /* also catches NaN */
        return 0;
    if (x >= 1.0f)
        return 255;
    double s = x <= 0.0031308f ? 12.92 * x : 1.055 * pow(x, 1.0 / 2.4) - 0.055;
    long b = lround(s * 255.0);
    return (uint8_t)(b < 0 ? 0 : b > 255 ? 255 : b);
}

int imgio_write_png(const char *path, const float *pixels, uint32_t width, uint32_t height,
                    uint32_t stride, float exposure, char *err, size_t errlen)
{
    if (!path || !pixels || width == 0 || height == 0 || stride < 3 || width > (1u << 20) ||
        height > (1u << 20)) {
        set_err(err, errlen, "%s: bad PNG request (%ux%u, stride %u)", path ? path : "(null)", width, height,
                stride);
        return -1;
    }
    size_t plen = strlen(path);
    char *tmp = mem_alloc(plen + 5);
    memcpy(tmp, path, plen);
    memcpy(tmp + plen, ".tmp", 5);
    FILE *fp = fopen(tmp, "wb");
    if (!fp) {
        set_err(err, errlen, "%s: cannot create: %s", tmp, strerror(errno));
        free(tmp);
        return -1;
    }
    struct stat st;
    bool tmp_is_file = fstat(fileno(fp), &st) == 0 && S_ISREG(st.st_mode);
    /* Everything setjmp's error path touches is set before setjmp and never changed after,
     * so none of it needs to be volatile. */
    uint8_t *row = mem_alloc((size_t)width * 3);
    struct png_failure fail = {""};
    png_structp png = png_create_write_struct(PNG_LIBPNG_VER_STRING, &fail, on_png_error, on_png_warning);
    png_infop info = png ? png_create_info_struct(png) : NULL;
    if (!png || !info) {
        set_err(err, errlen, "%s: cannot initialise libpng", path);
        png_destroy_write_struct(png ? &png : NULL, NULL);
        goto fail_file;
    }
    if (setjmp(png_jmpbuf(png))) {
        set_err(err, errlen, "%s: PNG write failed: %s", path, fail.msg);
        png_destroy_write_struct(&png, &info);
        goto fail_file;
    }
    png_init_io(png, fp);
    png_set_IHDR(png, info, width, height, 8, PNG_COLOR_TYPE_RGB, PNG_INTERLACE_NONE, PNG_COMPRESSION_TYPE_DEFAULT,
                 PNG_FILTER_TYPE_DEFAULT);
    png_set_sRGB_gAMA_and_cHRM(png, info, PNG_sRGB_INTENT_PERCEPTUAL);
    png_write_info(png, info);
    for (uint32_t y = 0; y < height; y++) {
        const float *src = pixels + (size_t)y * width * stride;
        for (uint32_t x = 0; x < width; x++)
            for (int c = 0; c < 3; c++)
                row[(size_t)x * 3 + (size_t)c] = srgb_byte(src[(size_t)x * stride + (size_t)c], exposure);
        png_write_row(png, row);
    }
    png_write_end(png, info);
    png_destroy_write_struct(&png, &info);
    if (fflush(fp) != 0 || fsync(fileno(fp)) != 0) {
        set_err(err, errlen, "%s: cannot write: %s", tmp, strerror(errno));
        goto fail_file;
    }
    if (fclose(fp) != 0) {
        fp = NULL;
        set_err(err, errlen, "%s: cannot close: %s", tmp, strerror(errno));
        goto fail_file;
    }
    fp = NULL;
    if (rename(tmp, path) != 0) {
        set_err(err, errlen, "%s: cannot rename from %s: %s", path, tmp, strerror(errno));
        goto fail_file;
    }
    free(row);
    free(tmp);
    return 0;

fail_file:
    if (fp)
        fclose(fp);
    if (tmp_is_file)
        unlink(tmp);
    free(row);
    free(tmp);
    return -1;
}
