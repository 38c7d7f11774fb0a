/* Output names against input files (see outnames.h). A frame range may hold billions of
 * frames, so its names are enumerated only up to OUTNAMES_ENUM_MAX frames; beyond that
 * the only frames checked are those whose number appears in an input's resolved path
 * (an output name that resolves to an input carries its frame number in the input's
 * name, unless it reaches it through a symlink) and the range's ends. */
#include "outnames.h"
#include "output.h"
#include "base/log.h"
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

#define OUTNAMES_ENUM_MAX 10000u

/* -1 with err set when path names an input. */
static int check_name(const struct asset_dir *inputs, const char *path, const char *what, char *err, size_t errlen)
{
    long i = asset_dir_find(inputs, path);
    if (i < 0)
        return 0;
    str_fmt(err, errlen, "%s %s is %s, a file the scene reads; refusing to overwrite it (choose another -o)", what,
            path, inputs->files[i].path);
    return -1;
}

/* True when a and b name the same file: the same name, device and inode, or resolved path. */
static int same_file(const char *a, const char *b)
{
    if (strcmp(a, b) == 0)
        return 1;
    struct stat sa, sb;
    if (stat(a, &sa) == 0 && stat(b, &sb) == 0 && sa.st_dev == sb.st_dev && sa.st_ino == sb.st_ino)
        return 1;
    char *ra = asset_resolve_maybe_new(a), *rb = asset_resolve_maybe_new(b);
    int same = ra && rb && strcmp(ra, rb) == 0;
    free(ra);
    free(rb);
    return same;
}

/* The EXR and journal names of one frame. */
static int check_frame(const struct master_opts *o, const struct asset_dir *inputs, uint32_t frame, char *err,
                       size_t errlen)
{
    char out[4200], journal[4300];
    if (output_frame_path(o->output_path, o->have_frames, frame, out, sizeof out) != 0)
        return 0; /* a name that does not fit is the render loop's error */
    snprintf(journal, sizeof journal, "%s.journal", out);
    if (check_name(inputs, out, "output", err, errlen) != 0 || check_name(inputs, journal, "journal", err, errlen) != 0)
        return -1;
    char preview[4200], stats[4300];
    if (!o->preview_path || output_frame_path(o->preview_path, o->have_frames, frame, preview, sizeof preview) != 0)
        return 0;
    if (check_name(inputs, preview, "preview", err, errlen) != 0)
        return -1;
    /* The PNG would replace the EXR (or its journal or stats) once the frame is done. */
    snprintf(stats, sizeof stats, "%s.stats.json", o->output_path);
    const char *const ours[3] = {out, journal, stats};
    for (int i = 0; i < 3; i++)
        if (same_file(preview, ours[i])) {
            str_fmt(err, errlen, "preview %s is also the %s %s; refusing to write over it (choose another --preview)",
                    preview, i == 0 ? "output" : i == 1 ? "journal" : "stats file", ours[i]);
            return -1;
        }
    return 0;
}

static int in_range(const struct master_opts *o, uint64_t f)
{
    return f >= o->frame_first && f <= o->frame_last && (f - o->frame_first) % o->frame_step == 0;
}

/* Every frame number written in path (each run of up to 10 digits inside a run of digits). */
static int check_frames_named_in(const struct master_opts *o, const struct asset_dir *inputs, const char *path,
                                 char *err, size_t errlen)
{
    for (const char *p = path; *p; p++) {
        if (*p < '0' || *p > '9')
            continue;
        uint64_t v = 0;
        for (const char *q = p; *q >= '0' && *q <= '9' && q - p < 10; q++) {
            v = v * 10 + (uint64_t)(*q - '0');
            if (in_range(o, v) && check_frame(o, inputs, (uint32_t)v, err, errlen) != 0)
                return -1;
        }
    }
    return 0;
}

int outnames_stats_path(const struct master_opts *o, char *out, size_t outlen)
{
    char base[4200];
    if (o->have_frames && o->frame_first == o->frame_last) {
        if (output_frame_path(o->output_path, 1, o->frame_first, base, sizeof base) != 0)
            return -1;
    } else {
        snprintf(base, sizeof base, "%s", o->output_path);
    }
    int n = snprintf(out, outlen, "%s.stats.json", base);
    return n < 0 || (size_t)n >= outlen ? -1 : 0;
}

int outnames_check(const struct master_opts *o, const struct asset_dir *inputs, char *err, size_t errlen)
{
    char stats[4300];
    if (outnames_stats_path(o, stats, sizeof stats) != 0) {
        snprintf(err, errlen, "-o %s: the stats file's name is too long", o->output_path);
        return -1;
    }
    if (check_name(inputs, stats, "stats file", err, errlen) != 0)
        return -1;
    if (!o->have_frames)
        return check_frame(o, inputs, 0, err, errlen);
    uint64_t count = ((uint64_t)o->frame_last - o->frame_first) / o->frame_step + 1;
    if (count <= OUTNAMES_ENUM_MAX) {
        for (uint64_t f = o->frame_first; f <= o->frame_last; f += o->frame_step)
            if (check_frame(o, inputs, (uint32_t)f, err, errlen) != 0)
                return -1;
        return 0;
    }
    uint32_t last = o->frame_first + (uint32_t)((count - 1) * o->frame_step);
    if (check_frame(o, inputs, o->frame_first, err, errlen) != 0 || check_frame(o, inputs, last, err, errlen) != 0)
        return -1;
    for (size_t i = 0; i < inputs->num_files; i++)
        if (inputs->files[i].real && check_frames_named_in(o, inputs, inputs->files[i].real, err, errlen) != 0)
            return -1;
    return 0;
}
