/* A frame's files (see output.h). Everything is written under a temporary name in the
 * destination folder, fsync'ed, renamed into place and the folder fsync'ed, so a reader
 * (or a restarted master deciding to skip a frame) never sees half a file. Called by
 * master/master.c. */
#include "output.h"
#include "base/asset.h"
#include "base/log.h"
#include "wire/net.h"
#include <dirent.h>
#include <errno.h>
#include <signal.h>
#include <fcntl.h>
#include <libgen.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

int output_frame_path(const char *pat, int have_frames, uint32_t frame, char *out, size_t outlen)
{
    if (!have_frames)
        return snprintf(out, outlen, "%s", pat) < (int)outlen ? 0 : -1;
    if (strchr(pat, '#'))
        return asset_frame_name(pat, frame, out, outlen) == 1 ? 0 : -1;
    const char *slash = strrchr(pat, '/'), *dot = strrchr(pat, '.');
    const char *base = slash ? slash + 1 : pat;
    int n;
    if (dot && dot > base)
        n = snprintf(out, outlen, "%.*s.%04u%s", (int)(dot - pat), pat, frame, dot);
    else
        n = snprintf(out, outlen, "%s.%04u", pat, frame);
    return n > 0 && (size_t)n < outlen ? 0 : -1;
}

int output_is_done(const char *path, const char *scene_hash, uint32_t spp, uint64_t seed,
                   const struct image_desc *desc)
{
    struct image_attrs a;
    struct image_desc d;
    char err[512];
    if (access(path, F_OK) != 0)
        return 0;
    if (imgio_read_attrs(path, &d, &a, err, sizeof err) != 0) {
        log_warn("%s exists but cannot be read (%s); rendering it again", path, err);
        return 0;
    }
    if (strcmp(a.scene_hash, scene_hash) != 0 || a.spp != spp || a.seed != seed || d.width != desc->width ||
        d.height != desc->height || d.tile_size != desc->tile_size) {
        log_info("%s exists but was rendered from another scene or other settings; rendering it again", path);
        return 0;
    }
    return 1;
}

unsigned output_remove_stale_tmp(const char *path)
{
    char dbuf[4200], bbuf[4200];
    snprintf(dbuf, sizeof dbuf, "%s", path);
    snprintf(bbuf, sizeof bbuf, "%s", path);
    const char *dir = dirname(dbuf), *base = basename(bbuf);
    size_t blen = strlen(base);
    DIR *d = opendir(dir);
    if (!d)
        return 0;
    unsigned removed = 0;
    struct dirent *e;
    while ((e = readdir(d))) {
        const char *n = e->d_name;
        if (blen == 0 || strncmp(n, base, blen) != 0 || strncmp(n + blen, ".tmp.", 5) != 0)
            continue;
        const char *digits = n + blen + 5;
        char *end;
        errno = 0;
        long pid = strtol(digits, &end, 10);
        if (*digits < '1' || *digits > '9' || *end || errno || pid <= 0 || pid > INT32_MAX || pid == (long)getpid())
            continue;
        if (kill((pid_t)pid, 0) == 0 || errno != ESRCH) /* alive (or not ours to signal): may be writing */
            continue;
        char full[4500];
        snprintf(full, sizeof full, "%s/%s", dir, n);
        if (unlink(full) == 0)
            removed++;
    }
    closedir(d);
    return removed;
}

/* The temporary file is renamed into place; the folder is synced so the rename lasts. */
int output_check_writable(const char *path, char *err, size_t errlen)
{
    /* The rename at the end cannot replace a folder, nor name nothing. */
    struct stat st;
    if (path[0] == '\0') {
        str_fmt(err, errlen, "the output name is empty");
        return -1;
    }
    if (stat(path, &st) == 0 && S_ISDIR(st.st_mode)) {
        str_fmt(err, errlen, "%s: is a folder; the output must be a file name", path);
        return -1;
    }
    char tmp[4200];
    snprintf(tmp, sizeof tmp, "%s.tmp.%d", path, (int)getpid());
    int fd = open(tmp, O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0644);
    if (fd < 0) {
        str_fmt(err, errlen, "%s: cannot create the output there: %s", tmp, strerror(errno));
        return -1;
    }
    close(fd);
    unlink(tmp);
    return 0;
}

static int publish(const char *tmp, const char *path, char *err, size_t errlen)
{
    if (rename(tmp, path) != 0) {
        str_fmt(err, errlen, "%s: cannot rename into place: %s", path, strerror(errno));
        unlink(tmp);
        return -1;
    }
    asset_fsync_parent(path);
    return 0;
}

int output_write_exr(const char *path, const struct image_desc *desc, const struct image_attrs *attrs,
                     const struct output_chunk *chunks, char *err, size_t errlen)
{
    char tmp[4200];
    snprintf(tmp, sizeof tmp, "%s.tmp.%d", path, (int)getpid());
    struct imgio_writer *w = imgio_writer_open(tmp, desc, attrs, err, errlen);
    if (!w)
        return -1;
    uint32_t tiles_x = imgio_tiles_x(desc), num_tiles = tiles_x * imgio_tiles_y(desc);
    for (uint32_t t = 0; t < num_tiles; t++)
        if (imgio_writer_put_tile(w, t % tiles_x, t / tiles_x, chunks[t].data, chunks[t].size, err, errlen) != 0) {
            char ignored[64];
            imgio_writer_close(&w, ignored, sizeof ignored);
            unlink(tmp);
            return -1;
        }
    if (imgio_writer_close(&w, err, errlen) != 0) {
        unlink(tmp);
        return -1;
    }
    return publish(tmp, path, err, errlen);
}

int output_write_preview(const char *path, const struct image_desc *desc, const struct output_chunk *chunks,
                         char *err, size_t errlen)
{
    uint32_t nc = desc->num_channels, tiles_x = imgio_tiles_x(desc), num_tiles = tiles_x * imgio_tiles_y(desc);
    float *img = mem_alloc(sizeof(float) * desc->width * desc->height * nc);
    float *tile = mem_alloc(sizeof(float) * desc->tile_size * desc->tile_size * nc);
    char terr[256];
    for (uint32_t t = 0; t < num_tiles; t++) {
        uint32_t tx = t % tiles_x, ty = t / tiles_x, x0, y0, tw, th;
        imgio_tile_rect(desc, tx, ty, &x0, &y0, &tw, &th);
        if (imgio_decode_tile(desc, tx, ty, chunks[t].data, chunks[t].size, tile, terr, sizeof terr) != 0)
            continue;
        for (uint32_t y = 0; y < th; y++)
            memcpy(&img[((size_t)(y0 + y) * desc->width + x0) * nc], &tile[(size_t)y * tw * nc],
                   sizeof(float) * tw * nc);
    }
    int rc = imgio_write_png(path, img, desc->width, desc->height, nc, 1.0f, err, errlen);
    free(tile);
    free(img);
    return rc;
}

int output_write_json(const char *path, const json_t *root, char *err, size_t errlen)
{
    char tmp[4200];
    snprintf(tmp, sizeof tmp, "%s.tmp.%d", path, (int)getpid());
    FILE *f = fopen(tmp, "w");
    if (!f) {
        str_fmt(err, errlen, "%s: %s", tmp, strerror(errno));
        return -1;
    }
    int bad = json_dumpf(root, f, JSON_INDENT(2) | JSON_PRESERVE_ORDER) != 0 || fputc('\n', f) == EOF ||
              fflush(f) != 0 || fsync(fileno(f)) != 0;
    int saved = errno;
    if (fclose(f) != 0 && !bad) {
        bad = 1;
        saved = errno;
    }
    if (bad) {
        str_fmt(err, errlen, "%s: cannot write: %s", tmp, strerror(saved));
        unlink(tmp);
        return -1;
    }
    return publish(tmp, path, err, errlen);
}

static void add_string(struct image_attrs *a, const char *name, const char *value)
{
    a->string_names = mem_realloc(a->string_names, sizeof *a->string_names * (a->num_strings + 1));
    a->string_values = mem_realloc(a->string_values, sizeof *a->string_values * (a->num_strings + 1));
    a->string_names[a->num_strings] = mem_strdup(name);
    a->string_values[a->num_strings] = mem_strdup(value);
    a->num_strings++;
}

void output_id_names(const struct scene *sc, struct image_attrs *a)
{
    char name[64];
    uint32_t aovs = sc->settings.aovs;
    for (uint32_t i = 0; (aovs & (1u << AOV_ID_OBJECT)) && i < sc->num_meshes + sc->num_spheres; i++) {
        snprintf(name, sizeof name, "id.object/%u", i);
        add_string(a, name, i < sc->num_meshes ? sc->meshes[i].name : sc->spheres[i - sc->num_meshes].name);
    }
    for (uint32_t i = 0; (aovs & (1u << AOV_ID_MATERIAL)) && i < sc->num_materials; i++) {
        snprintf(name, sizeof name, "id.material/%u", i);
        add_string(a, name, sc->materials[i].name);
    }
}

void output_id_names_free(struct image_attrs *a)
{
    for (uint32_t i = 0; i < a->num_strings; i++) {
        free(a->string_names[i]);
        free(a->string_values[i]);
    }
    free(a->string_names);
    free(a->string_values);
    a->string_names = a->string_values = NULL;
    a->num_strings = 0;
}

void output_chunk_free(struct output_chunk *c)
{
    if (c->payload)
        net_payload_free(&c->payload);
    else
        free(c->data);
    c->data = NULL;
    c->size = 0;
}
