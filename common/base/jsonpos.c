/* Positions in JSON text (see jsonpos.h). */
#include "base/jsonpos.h"
#include "base/log.h"
#include <stdbool.h>
#include <stdio.h>
#include <string.h>

struct scanner {
    const char *t;
    size_t len, i;
    uint32_t line, col;
};

static void scan_advance(struct scanner *s)
{
    unsigned char c = (unsigned char)s->t[s->i++];
    if (c == '\n') {
        s->line++;
        s->col = 1;
    } else if ((c & 0xC0) != 0x80) {
        s->col++;  /* columns count code points, as jansson's do */
    }
}

static void scan_ws(struct scanner *s)
{
    while (s->i < s->len && (s->t[s->i] == ' ' || s->t[s->i] == '\t' || s->t[s->i] == '\n' || s->t[s->i] == '\r'))
        scan_advance(s);
}

/* Skips a string (s at its opening quote); 1 if its raw content equals key. */
static bool scan_string(struct scanner *s, const char *key)
{
    size_t start = s->i + 1;
    scan_advance(s);  /* opening quote */
    while (s->i < s->len && s->t[s->i] != '"') {
        if (s->t[s->i] == '\\' && s->i + 1 < s->len)
            scan_advance(s);
        scan_advance(s);
    }
    bool same = key && s->i - start == strlen(key) && memcmp(s->t + start, key, s->i - start) == 0;
    if (s->i < s->len)
        scan_advance(s);
    return same;
}

static void scan_skip_value(struct scanner *s)
{
    if (s->i >= s->len)
        return;
    char c = s->t[s->i];
    if (c == '"') {
        scan_string(s, NULL);
    } else if (c == '{' || c == '[') {
        size_t depth = 0;
        while (s->i < s->len) {
            c = s->t[s->i];
            if (c == '"') {
                scan_string(s, NULL);
                continue;
            }
            if (c == '{' || c == '[')
                depth++;
            else if ((c == '}' || c == ']') && --depth == 0) {
                scan_advance(s);
                return;
            }
            scan_advance(s);
        }
    } else {
        while (s->i < s->len && !strchr(",]} \t\r\n", s->t[s->i]))
            scan_advance(s);
    }
}

/* s is at a value at depth `depth` of the path; finds the key or value it names. */
static bool scan_locate(struct scanner *s, const struct json_step *p, int n, int depth, bool want_key,
                        uint32_t *line, uint32_t *col)
{
    scan_ws(s);
    if (s->i >= s->len)
        return false;
    if (depth == n) {
        *line = s->line;
        *col = s->col;
        return true;
    }
    char open = s->t[s->i];
    if (open != '{' && open != '[')
        return false;
    scan_advance(s);
    for (uint32_t k = 0;; k++) {
        scan_ws(s);
        if (s->i >= s->len || s->t[s->i] == '}' || s->t[s->i] == ']')
            return false;
        uint32_t kline = s->line, kcol = s->col;
        bool named = false;
        if (open == '{') {
            named = scan_string(s, p[depth].key);
            scan_ws(s);
            if (s->i < s->len && s->t[s->i] == ':')
                scan_advance(s);
        }
        if (p[depth].key ? named : k == p[depth].index) {
            if (want_key && open == '{' && depth + 1 == n) {
                *line = kline;
                *col = kcol;
                return true;
            }
            return scan_locate(s, p, n, depth + 1, want_key, line, col);
        }
        scan_ws(s);
        scan_skip_value(s);
        scan_ws(s);
        if (s->i < s->len && s->t[s->i] == ',')
            scan_advance(s);
    }
}

int json_locate(const char *text, size_t len, const struct json_step *path, int n, int want_key, uint32_t *line,
                uint32_t *col)
{
    struct scanner s = {text, len, 0, 1, 1};
    if (!scan_locate(&s, path, n, 0, want_key != 0, line, col)) {
        *line = *col = 1;
        return 0;
    }
    return 1;
}

int json_error_at(char *err, size_t errlen, const char *name, const char *text, size_t len,
                  const struct json_step *path, int n, int want_key, const char *fmt, va_list ap)
{
    uint32_t line = 1, col = 1;
    if (n > 0)
        json_locate(text, len, path, n, want_key, &line, &col);
    char msg[1024];
    vsnprintf(msg, sizeof msg, fmt, ap);
    str_fmt(err, errlen, "%s:%u:%u: %s", name, line, col, msg);
    return -1;
}
