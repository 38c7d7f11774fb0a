/* Where a scene's files come from. The master reads them from the scene's folder on disk
 * (and records their bytes to publish as blobs); a worker reads them from its blob cache.
 * Paths are relative to the scene's folder, as written in the scene; asset_path_check()
 * rejects absolute paths, ".." components, empty components and backslashes, so a
 * scene cannot name a file outside its folder. */
#ifndef BRUME_ASSET_H
#define BRUME_ASSET_H
#include <stdatomic.h>
#include <stddef.h>
#include <stdint.h>

#define ASSET_PATH_MAX 1024

struct asset_source {
    /* Reads rel_path into a mem_alloc'd buffer (*data, NUL-terminated beyond *size).
     * Returns 0, or -1 with one line in err (naming the path). */
    int (*read)(void *ctx, const char *rel_path, char **data, size_t *size, char *err, size_t errlen);
    void *ctx;
};

/* The process's stop flag for scene loading (the master's SIGINT / SIGTERM flag, the
 * worker's cancel of a load on its loader thread; NULL, the default, for none). Atomic:
 * set by a signal handler or by another thread than the one loading, and a lock-free
 * atomic is safe for both. Once it is set, asset_dir_read and the parsers that can run
 * long (OBJ, every few thousand lines) fail with "interrupted", so a signal ends a load
 * within moments whatever the scene's size. */
void asset_set_stop_flag(const atomic_int *flag);
int asset_stop_requested(void);

/* 0 if rel_path is a safe relative path (see above), else -1 with the reason in err. */
int asset_path_check(const char *rel_path, char *err, size_t errlen);

/* Joins a directory (relative to the scene folder, "" for the folder itself) and a path
 * written in a file in that directory (e.g. an MTL named by an OBJ); result checked with
 * asset_path_check. Returns 0 or -1. */
int asset_path_join(const char *dir, const char *rel, char *out, size_t outlen, char *err, size_t errlen);

/* A name for one frame of a sequence: the last run of '#' in pat replaced by frame,
 * zero-padded to the run's width ("smoke.####.nvdb", 7 -> "smoke.0007.nvdb"; a frame
 * wider than the run is written in full). 1 when pat has a run, 0 when it has none (out
 * is pat), -1 when out is too small. The master's --frames output names and a scene's
 * per-frame files (a grid "smoke.####.nvdb") both use it. */
int asset_frame_name(const char *pat, uint32_t frame, char *out, size_t outlen);

/* fsync of the folder holding path, so that a rename into it lasts a crash; 0 or -1. */
int asset_fsync_parent(const char *path);

/* A source reading from a folder on disk; it also records every file read (path and
 * bytes), which the master publishes as blobs. Symlinks that resolve outside the folder
 * are refused; so is anything but a regular file, and opening never blocks (a FIFO named
 * as a texture would otherwise hang the master in open()). */
struct asset_dir {
    char root[4096];          /* realpath of the scene folder */
    struct asset_file {
        char path[ASSET_PATH_MAX];
        char *data;
        size_t size;
        /* The file's resolved path and identity when read (real NULL for entries that are
         * not files, such as the master's photon map): asset_dir_find compares output
         * names against them. */
        char *real;
        uint64_t dev, ino;
    } *files;
    size_t num_files, cap_files;
};
int asset_dir_init(struct asset_dir *dir, const char *folder, char *err, size_t errlen);
struct asset_source asset_dir_source(struct asset_dir *dir);
/* Reads a file through the source and records it (used for the scene file itself). */
int asset_dir_read(void *ctx, const char *rel_path, char **data, size_t *size, char *err, size_t errlen);
void asset_dir_fini(struct asset_dir *dir);
/* The recorded file that path (any path on this machine, e.g. an output name) names: the
 * same device and inode, or the same resolved path (a name that does not exist yet is
 * resolved through its folder). Its index, or -1 when path names none of them. */
long asset_dir_find(const struct asset_dir *dir, const char *path);
/* realpath of path, or of its folder joined with its last component when path does not
 * exist yet (an output about to be written), mem_alloc'd. NULL when neither resolves. */
char *asset_resolve_maybe_new(const char *path);

#endif
