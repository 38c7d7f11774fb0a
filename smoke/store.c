/* Grid and checkpoint files (see store.h). */
#include "store.h"
#include "base/asset.h"
#include "base/bytes.h"
#include "base/log.h"
#include "scene/grid.h"
#include "nvdb_out.h"
#include <errno.h>
#include <fcntl.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#define CKPT_MAGIC "BRSMCK01"
#define CKPT_HEADER 40

int store_write_atomic(const char *path, const void *data, size_t len, char *err, size_t errlen)
{
    char tmp[1100];
    if ((size_t)snprintf(tmp, sizeof tmp, "%s.tmp.%ld", path, (long)getpid()) >= sizeof tmp) {
        str_fmt(err, errlen, "%s: path too long", path);
        return -1;
    }
    int fd = open(tmp, O_WRONLY | O_CREAT | O_TRUNC, 0644);
    if (fd < 0) {
        str_fmt(err, errlen, "%s: %s", tmp, strerror(errno));
        return -1;
    }
    const uint8_t *p = data;
    size_t off = 0;
    while (off < len) {
        ssize_t w = write(fd, p + off, len - off);
        if (w < 0 && errno == EINTR)
            continue;
        if (w <= 0) {
            str_fmt(err, errlen, "%s: %s", tmp, w < 0 ? strerror(errno) : "short write");
            close(fd);
            unlink(tmp);
            return -1;
        }
        off += (size_t)w;
    }
    if (fsync(fd) != 0 || close(fd) != 0) {
        str_fmt(err, errlen, "%s: %s", tmp, strerror(errno));
        unlink(tmp);
        return -1;
    }
    if (rename(tmp, path) != 0) {
        str_fmt(err, errlen, "rename %s -> %s: %s", tmp, path, strerror(errno));
        unlink(tmp);
        return -1;
    }
    asset_fsync_parent(path);
    return 0;
}

size_t store_grid_bytes(const struct fluid *f) { return 20 + f->n * sizeof(float); }

int store_write_grid(const char *path, const struct fluid *f, char *err, size_t errlen)
{
    size_t len = store_grid_bytes(f);
    uint8_t *buf = mem_alloc(len);
    memcpy(buf, GRID_MAGIC, 8);
    bytes_put_u32(buf + 8, f->nx);
    bytes_put_u32(buf + 12, f->ny);
    bytes_put_u32(buf + 16, f->nz);
    for (size_t i = 0; i < f->n; i++) {
        float d = f->d[i];
        d = d > 0.0f && isfinite(d) ? d : 0.0f;
        uint32_t bits;
        memcpy(&bits, &d, 4);
        bytes_put_u32(buf + 20 + 4 * i, bits);
    }
    int rc = store_write_atomic(path, buf, len, err, errlen);
    free(buf);
    return rc;
}

int store_encode_nvdb(const struct fluid *f, uint8_t **buf, size_t *len, uint64_t *active, char *err, size_t errlen)
{
    const uint32_t n[3] = {f->nx, f->ny, f->nz};
    const double h = f->h;
    const double size[3] = {h, h, h}, origin[3] = {0.5 * h, 0.5 * h, 0.5 * h};
    return nvdb_encode_fog(f->d, n, f->s.nvdb_threshold, size, origin, "density", buf, len, active, err, errlen);
}

int store_write_nvdb(const char *path, const struct fluid *f, size_t *bytes, uint64_t *active, char *err,
                     size_t errlen)
{
    uint8_t *buf = NULL;
    size_t len = 0;
    if (store_encode_nvdb(f, &buf, &len, active, err, errlen) != 0)
        return -1;
    int rc = store_write_atomic(path, buf, len, err, errlen);
    free(buf);
    if (bytes)
        *bytes = len;
    return rc;
}

int store_write_frame(const char *path, const struct fluid *f, size_t *bytes, char *err, size_t errlen)
{
    if (smoke_output_nvdb(path) == 1)
        return store_write_nvdb(path, f, bytes, NULL, err, errlen);
    if (bytes)
        *bytes = store_grid_bytes(f);
    return store_write_grid(path, f, err, errlen);
}

uint64_t store_settings_hash(const struct smoke_settings *s)
{
    struct smoke_settings c = *s;
    c.frames = 0;
    c.threads = 0;
    c.nvdb_threshold = 0.0f;
    memset(c.output, 0, sizeof c.output);
    const uint8_t *p = (const uint8_t *)&c;
    uint64_t h = 0xcbf29ce484222325ull;  /* FNV-1a */
    for (size_t i = 0; i < sizeof c; i++)
        h = (h ^ p[i]) * 0x100000001b3ull;
    return h;
}

static float *const *state_fields(const struct fluid *f, float *out[5])
{
    out[0] = f->u;
    out[1] = f->v;
    out[2] = f->w;
    out[3] = f->d;
    out[4] = f->t;
    return out;
}

int store_write_checkpoint(const char *path, const struct fluid *f, uint32_t frame, char *err, size_t errlen)
{
    size_t len = CKPT_HEADER + 5 * f->n * sizeof(float);
    uint8_t *buf = mem_alloc(len);
    memcpy(buf, CKPT_MAGIC, 8);
    bytes_put_u64(buf + 8, store_settings_hash(&f->s));
    bytes_put_u32(buf + 16, f->nx);
    bytes_put_u32(buf + 20, f->ny);
    bytes_put_u32(buf + 24, f->nz);
    bytes_put_u32(buf + 28, frame);
    bytes_put_u64(buf + 32, f->step);
    float *fields[5];
    state_fields(f, fields);
    uint8_t *p = buf + CKPT_HEADER;
    for (int c = 0; c < 5; c++)
        for (size_t i = 0; i < f->n; i++, p += 4) {
            uint32_t bits;
            memcpy(&bits, &fields[c][i], 4);
            bytes_put_u32(p, bits);
        }
    int rc = store_write_atomic(path, buf, len, err, errlen);
    free(buf);
    return rc;
}

int store_read_checkpoint(const char *path, struct fluid *f, uint32_t *frame, char *err, size_t errlen)
{
    FILE *fp = fopen(path, "rb");
    if (!fp) {
        if (errno == ENOENT)
            return 0;
        str_fmt(err, errlen, "%s: %s", path, strerror(errno));
        return -1;
    }
    size_t len = CKPT_HEADER + 5 * f->n * sizeof(float);
    uint8_t *buf = mem_alloc(len + 1);
    size_t got = fread(buf, 1, len + 1, fp);
    fclose(fp);
    int rc = -1;
    if (got != len || memcmp(buf, CKPT_MAGIC, 8) != 0) {
        str_fmt(err, errlen, "%s: not a checkpoint of this size (%zu bytes, expected %zu)", path, got, len);
    } else if (bytes_get_u64(buf + 8) != store_settings_hash(&f->s) || bytes_get_u32(buf + 16) != f->nx ||
               bytes_get_u32(buf + 20) != f->ny || bytes_get_u32(buf + 24) != f->nz) {
        str_fmt(err, errlen, "%s: written with other settings (remove it, or pass --restart)", path);
    } else if ((uint64_t)bytes_get_u32(buf + 28) * f->s.steps_per_frame != bytes_get_u64(buf + 32)) {
        str_fmt(err, errlen, "%s: frame and step counts disagree", path);
    } else {
        float *fields[5];
        state_fields(f, fields);
        const uint8_t *p = buf + CKPT_HEADER;
        rc = 1;
        for (int c = 0; c < 5 && rc == 1; c++)
            for (size_t i = 0; i < f->n; i++, p += 4) {
                uint32_t bits = bytes_get_u32(p);
                memcpy(&fields[c][i], &bits, 4);
                if (!isfinite(fields[c][i])) {
                    str_fmt(err, errlen, "%s: a value that is not finite", path);
                    rc = -1;
                    break;
                }
            }
        *frame = bytes_get_u32(buf + 28);
        f->step = bytes_get_u64(buf + 32);
    }
    free(buf);
    return rc;
}
