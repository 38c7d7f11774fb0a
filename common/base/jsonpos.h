/* Where a value or key lies in JSON text, for error messages as file:line:column: jansson
 * checks the syntax but keeps no positions, so after a semantic error the (already valid)
 * text is rescanned along the path to the offending value. Callers: scene/scene_json.c,
 * smoke/settings.c. */
#ifndef BRUME_JSONPOS_H
#define BRUME_JSONPOS_H
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>

/* One level of a path: the object member named key (its raw bytes between the quotes), or,
 * when key is NULL, the index-th member or array element (from 0, in text order). */
struct json_step {
    const char *key;
    uint32_t index;
};

/* Line and column (from 1; columns count code points, as jansson's do) of the value the n
 * steps of path name in text, or of its key (want_key, when the last step is a member).
 * 1 if found; 0 if not (then 1:1). */
int json_locate(const char *text, size_t len, const struct json_step *path, int n, int want_key, uint32_t *line,
                uint32_t *col);

/* "name:line:col: message" into err, the position that of json_locate (1:1 when n is 0 or
 * the path is not found), the message from fmt and ap. Returns -1, for `return` in parsers. */
int json_error_at(char *err, size_t errlen, const char *name, const char *text, size_t len,
                  const struct json_step *path, int n, int want_key, const char *fmt, va_list ap)
    __attribute__((format(printf, 9, 0)));

#endif
