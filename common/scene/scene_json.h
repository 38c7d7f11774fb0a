/* Scene file (version 1, JSON) to flat scene. Syntax errors come from jansson with line
 * and column; semantic errors (unknown key, wrong type, value out of range, missing OBJ)
 * name the line and column of the offending key or value: "scenes/x.json:12:7: ...".
 * Format documented in docs/scene-format.md. Called by the master and by workers (which
 * read the same bytes from blobs, so both build the same scene). */
#ifndef BRUME_SCENE_JSON_H
#define BRUME_SCENE_JSON_H
#include <stddef.h>
#include "base/asset.h"
#include "scene/scene.h"

/* Parses text (len bytes) named `name` in messages; OBJ/MTL files are read through src,
 * relative to the scene's folder. On success fills *out (which must be zeroed) and
 * returns 0; on failure returns -1, leaves *out freed and writes one line into err. */
int scene_json_parse(const char *name, const char *text, size_t len, const struct asset_source *src,
                     struct scene *out, char *err, size_t errlen);
/* The same with the render frame's origin (scene.h) given in world coordinates instead of
 * taken from the camera; {0, 0, 0} keeps world space (unit tests that check positions
 * written in the file). origin NULL: scene_json_parse. */
int scene_json_parse_origin(const char *name, const char *text, size_t len, const struct asset_source *src,
                            const double origin[3], struct scene *out, char *err, size_t errlen);
/* The same for one frame of a sequence: a file name with a run of '#' (a density grid
 * "smoke.####.nvdb") names that frame's file (asset_frame_name), and the scene counts
 * such names in frame_files. The other two parse frame 0, the frame of a render without
 * --frames. */
int scene_json_parse_frame(const char *name, const char *text, size_t len, const struct asset_source *src,
                           const double origin[3], uint32_t frame, struct scene *out, char *err, size_t errlen);

/* AOV and filter names as render.aovs, render.filter, --aovs and --filter take them:
 * an enum aov / enum pixel_filter, or -1. */
extern const char *const scene_aov_names[AOV_COUNT_];
int scene_aov_from_name(const char *name);
int scene_filter_from_name(const char *name);
/* "Z,N,albedo" or "all" into a bit set; 0 or -1. */
int scene_aovs_from_list(const char *list, uint32_t *aovs);
/* "gaussian", "gaussian:2.0" (width in pixels), "blackman-harris:1.5" or "box"; 0 or -1. */
int scene_filter_from_spec(const char *spec, uint32_t *filter, float *width);

#endif
