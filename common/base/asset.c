/* Scene asset access (see asset.h): the path rules that keep a scene inside its folder,
 * and the on-disk source the master uses. Paths are checked twice: lexically
 * (asset_path_check), then after realpath(), so a symlink cannot lead out of the folder.
 * Every file read is recorded once, by path, so the master can publish it as a blob.
 * Callers: scene_json.c and mesh_obj.c (through struct asset_source), the master. */
#include "base/asset.h"
#include "base/log.h"
#include <errno.h>
#include <fcntl.h>
#include <libgen.h>
#include <limits.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

/* Same cap as a blob (blob.h): a larger file could never reach a worker anyway. */
#define ASSET_MAX_FILE_SIZE (1ull << 32)

_Static_assert(ATOMIC_INT_LOCK_FREE == 2, "the stop flag is written by signal handlers");
static const atomic_int *stop_flag;

void asset_set_stop_flag(const atomic_int *flag) { stop_flag = flag; }

int asset_stop_requested(void) { return stop_flag && atomic_load(stop_flag); }

int asset_path_check(const char *rel_path, char *err, size_t errlen)
{
    size_t len = strlen(rel_path);
    if (len == 0) {
        str_fmt(err, errlen, "empty path");
        return -1;
    }
    if (len >= ASSET_PATH_MAX) {
        str_fmt(err, errlen, "path longer than %d bytes", ASSET_PATH_MAX - 1);
        return -1;
    }
    if (rel_path[0] == '/') {
        str_fmt(err, errlen, "absolute path \"%s\" not allowed (paths are relative to the scene folder)",
                rel_path);
        return -1;
    }
    if (strchr(rel_path, '\\')) {
        str_fmt(err, errlen, "backslash in path \"%s\" (use '/')", rel_path);
        return -1;
    }
    for (const char *p = rel_path; *p; p++)
        if ((unsigned char)*p < 0x20 || *p == 0x7f) {
            str_fmt(err, errlen, "control character in path");
            return -1;
        }
    /* "." is refused too: one file must have exactly one name, since workers look
     * assets up by the path written in the scene. */
    const char *c = rel_path;
    for (;;) {
        const char *slash = strchr(c, '/');
        size_t n = slash ? (size_t)(slash - c) : strlen(c);
        if (n == 0) {
            str_fmt(err, errlen, "empty component in path \"%s\"", rel_path);
            return -1;
        }
        if ((n == 1 && c[0] == '.') || (n == 2 && c[0] == '.' && c[1] == '.')) {
            str_fmt(err, errlen, "\"%.*s\" component in path \"%s\" not allowed (paths stay inside the scene folder)",
                    (int)n, c, rel_path);
            return -1;
        }
        if (!slash)
            break;
        c = slash + 1;
    }
    return 0;
}

int asset_path_join(const char *dir, const char *rel, char *out, size_t outlen, char *err, size_t errlen)
{
    if (asset_path_check(rel, err, errlen) != 0)
        return -1;
    size_t dn = strlen(dir), rn = strlen(rel);
    size_t need = dn + (dn ? 1 : 0) + rn + 1;
    if (need > outlen || need > ASSET_PATH_MAX) {
        str_fmt(err, errlen, "path \"%s\" too long", rel);
        return -1;
    }
    if (dn) {
        memcpy(out, dir, dn);
        out[dn] = '/';
        memcpy(out + dn + 1, rel, rn + 1);
    } else {
        memcpy(out, rel, rn + 1);
    }
    return asset_path_check(out, err, errlen);
}

int asset_dir_init(struct asset_dir *dir, const char *folder, char *err, size_t errlen)
{
    memset(dir, 0, sizeof *dir);
    char *real = realpath(folder, NULL);
    if (!real) {
        str_fmt(err, errlen, "%s: %s", folder, strerror(errno));
        return -1;
    }
    struct stat st;
    if (stat(real, &st) != 0 || !S_ISDIR(st.st_mode)) {
        str_fmt(err, errlen, "%s: not a directory", folder);
        free(real);
        return -1;
    }
    if (strlen(real) >= sizeof dir->root) {
        str_fmt(err, errlen, "%s: path too long", folder);
        free(real);
        return -1;
    }
    strcpy(dir->root, real);
    free(real);
    return 0;
}

/* True if real (a realpath result) is root itself or lies below it. */
static int path_is_inside(const char *root, const char *real)
{
    size_t n = strlen(root);
    if (n == 1 && root[0] == '/')
        return real[0] == '/';
    return strncmp(root, real, n) == 0 && (real[n] == '/' || real[n] == '\0');
}

/* fd is a regular file of file_size bytes (fstat). */
static int read_whole_fd(int fd, const char *rel_path, off_t file_size, char **data, size_t *size, char *err,
                         size_t errlen)
{
    if ((unsigned long long)file_size >= ASSET_MAX_FILE_SIZE) {
        str_fmt(err, errlen, "%s: file larger than %llu bytes", rel_path, ASSET_MAX_FILE_SIZE);
        return -1;
    }
    /* The size may change while we read; we read what is there up to EOF. */
    size_t cap = (size_t)file_size + 1, len = 0;
    char *buf = mem_alloc(cap);
    for (;;) {
        if (len + 1 >= cap) {
            if (cap >= ASSET_MAX_FILE_SIZE) {
                free(buf);
                str_fmt(err, errlen, "%s: file larger than %llu bytes", rel_path, ASSET_MAX_FILE_SIZE);
                return -1;
            }
            cap *= 2;
            buf = mem_realloc(buf, cap);
        }
        ssize_t r = read(fd, buf + len, cap - 1 - len);
        if (r < 0) {
            if (errno == EINTR)
                continue;
            str_fmt(err, errlen, "%s: %s", rel_path, strerror(errno));
            free(buf);
            return -1;
        }
        if (r == 0)
            break;
        len += (size_t)r;
    }
    buf[len] = '\0';
    *data = buf;
    *size = len;
    return 0;
}

int asset_dir_read(void *ctx, const char *rel_path, char **data, size_t *size, char *err, size_t errlen)
{
    struct asset_dir *dir = ctx;
    *data = NULL;
    *size = 0;
    char why[256];
    if (asset_path_check(rel_path, why, sizeof why) != 0) {
        str_fmt(err, errlen, "%s", why);
        return -1;
    }
    if (asset_stop_requested()) {
        str_fmt(err, errlen, "%s: interrupted", rel_path);
        return -1;
    }
    /* Served from the record when read before: the bytes a scene saw stay the bytes
     * that are published, even if the file changes on disk meanwhile. */
    for (size_t i = 0; i < dir->num_files; i++)
        if (strcmp(dir->files[i].path, rel_path) == 0) {
            *size = dir->files[i].size;
            *data = mem_alloc(*size + 1);
            memcpy(*data, dir->files[i].data, *size);
            (*data)[*size] = '\0';
            return 0;
        }
    size_t need = strlen(dir->root) + 1 + strlen(rel_path) + 1;
    char *full = mem_alloc(need);
    str_fmt(full, need, "%s/%s", dir->root, rel_path);
    char *real = realpath(full, NULL);
    free(full);
    if (!real) {
        str_fmt(err, errlen, "%s: %s", rel_path, strerror(errno));
        return -1;
    }
    if (!path_is_inside(dir->root, real)) {
        str_fmt(err, errlen, "%s: resolves outside the scene folder (symlink?)", rel_path);
        free(real);
        return -1;
    }
    /* O_NONBLOCK: opening a FIFO for reading would otherwise wait for a writer forever
     * (signals included), before fstat could tell it is no file. It changes nothing for
     * the regular files that are read. */
    int fd = open(real, O_RDONLY | O_CLOEXEC | O_NOFOLLOW | O_NONBLOCK);
    if (fd < 0) {
        str_fmt(err, errlen, "%s: %s", rel_path, strerror(errno));
        free(real);
        return -1;
    }
    struct stat st;
    if (fstat(fd, &st) != 0) {
        str_fmt(err, errlen, "%s: %s", rel_path, strerror(errno));
        st.st_mode = 0;
    } else if (!S_ISREG(st.st_mode)) {
        str_fmt(err, errlen, "%s: not a regular file (%s)", rel_path,
                S_ISFIFO(st.st_mode)                            ? "a FIFO"
                : S_ISDIR(st.st_mode)                           ? "a folder"
                : S_ISCHR(st.st_mode) || S_ISBLK(st.st_mode)    ? "a device"
                : S_ISSOCK(st.st_mode)                          ? "a socket"
                                                                : "not a file");
    }
    int rc = S_ISREG(st.st_mode) ? read_whole_fd(fd, rel_path, st.st_size, data, size, err, errlen) : -1;
    close(fd);
    if (rc != 0) {
        free(real);
        return -1;
    }
    mem_grow((void **)&dir->files, &dir->cap_files, dir->num_files + 1, sizeof *dir->files);
    struct asset_file *f = &dir->files[dir->num_files++];
    memset(f, 0, sizeof *f);
    memcpy(f->path, rel_path, strlen(rel_path) + 1);
    f->size = *size;
    f->real = real;
    f->dev = (uint64_t)st.st_dev;
    f->ino = (uint64_t)st.st_ino;
    f->data = mem_alloc(*size + 1);
    memcpy(f->data, *data, *size + 1);
    return 0;
}

struct asset_source asset_dir_source(struct asset_dir *dir)
{
    struct asset_source s = {asset_dir_read, dir};
    return s;
}

void asset_dir_fini(struct asset_dir *dir)
{
    for (size_t i = 0; i < dir->num_files; i++) {
        free(dir->files[i].data);
        free(dir->files[i].real);
    }
    free(dir->files);
    dir->files = NULL;
    dir->num_files = dir->cap_files = 0;
}

char *asset_resolve_maybe_new(const char *path)
{
    char *real = realpath(path, NULL);
    if (real || errno != ENOENT)
        return real;
    size_t n = strlen(path);
    char *folder = mem_alloc(n + 2);
    memcpy(folder, path, n + 1);
    char *slash = strrchr(folder, '/');
    const char *name = slash ? path + (slash - folder) + 1 : path;
    if (!slash)
        strcpy(folder, ".");
    else if (slash == folder)
        folder[1] = '\0'; /* "/name" */
    else
        *slash = '\0';
    char *rf = realpath(folder, NULL);
    free(folder);
    if (!rf)
        return NULL;
    size_t need = strlen(rf) + 1 + strlen(name) + 1;
    char *out = mem_alloc(need);
    str_fmt(out, need, "%s/%s", strcmp(rf, "/") == 0 ? "" : rf, name);
    free(rf);
    return out;
}

long asset_dir_find(const struct asset_dir *dir, const char *path)
{
    struct stat st;
    int exists = stat(path, &st) == 0;
    char *real = asset_resolve_maybe_new(path);
    long found = -1;
    for (size_t i = 0; i < dir->num_files && found < 0; i++) {
        const struct asset_file *f = &dir->files[i];
        if (!f->real)
            continue;
        /* By name too: a file replaced since it was read has another inode, but writing
         * over its name still destroys what the scene refers to. */
        if ((exists && (uint64_t)st.st_dev == f->dev && (uint64_t)st.st_ino == f->ino) ||
            (real && strcmp(real, f->real) == 0))
            found = (long)i;
    }
    free(real);
    return found;
}

int asset_frame_name(const char *pat, uint32_t frame, char *out, size_t outlen)
{
    const char *hash_end = strrchr(pat, '#');
    int n;
    if (!hash_end) {
        n = snprintf(out, outlen, "%s", pat);
        return n >= 0 && (size_t)n < outlen ? 0 : -1;
    }
    const char *hash_start = hash_end;
    while (hash_start > pat && hash_start[-1] == '#')
        hash_start--;
    int digits = (int)(hash_end - hash_start) + 1;
    n = snprintf(out, outlen, "%.*s%0*u%s", (int)(hash_start - pat), pat, digits, frame, hash_end + 1);
    return n > 0 && (size_t)n < outlen ? 1 : -1;
}

int asset_fsync_parent(const char *path)
{
    char buf[4096];
    snprintf(buf, sizeof buf, "%s", path);
    int fd = open(dirname(buf), O_RDONLY | O_DIRECTORY);
    if (fd < 0)
        return -1;
    int rc = fsync(fd);
    close(fd);
    return rc;
}
