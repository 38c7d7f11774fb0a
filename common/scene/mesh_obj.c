/* Wavefront OBJ + MTL reader (see mesh_obj.h). Input is untrusted bytes: every read is
 * bounded by the buffer length (no reliance on a NUL), every count is checked against
 * MESH_OBJ_MAX_ELEMENTS before it grows an array, and numbers follow a strict grammar
 * (no "nan"/"inf", no hex) before strtod sees a NUL-terminated copy. OBJ indices keep
 * separate v/vt/vn spaces; corners are deduplicated into shared mesh vertices at the end.
 * Called by scene_json.c; fuzzed directly. */
#include "scene/mesh_obj.h"
#include "image/image_load.h"
#include "base/log.h"
#include "scene/texture.h"
#include <float.h>
#include <math.h>
#include <stdarg.h>
#include <stdbool.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define NAME_LEN_MAX 1024
#define DEFAULT_ALBEDO 0.8f
/* Non-convex polygons are ear-clipped in O(n^2); longer ones are refused. */
#define EAR_CLIP_MAX_CORNERS 512
/* Warnings about materials no MTL defines, per file, before they are only counted. */
#define UNKNOWN_MATERIAL_WARNINGS 5

/* A path as exporters write it, made what asset_path_join takes: backslashes (Windows)
 * become '/', "." components and repeated separators go. ".." stays, so a path that
 * leaves the scene folder is still refused there. In place; n is the length. */
static void path_normalise(char *p)
{
    for (char *q = p; *q; q++)
        if (*q == '\\')
            *q = '/';
    char *out = p;
    const char *in = p;
    int absolute = *in == '/';
    if (absolute)
        *out++ = *in++; /* kept: asset_path_join refuses it by name */
    while (*in) {
        const char *e = strchr(in, '/');
        size_t n = e ? (size_t)(e - in) : strlen(in);
        if (!(n == 0 || (n == 1 && in[0] == '.'))) {
            if (out > p && out[-1] != '/')
                *out++ = '/';
            memmove(out, in, n);
            out += n;
        }
        in += n + (e != NULL);
    }
    *out = '\0';
}

struct mesh_obj_mtl {
    char path[ASSET_PATH_MAX];  /* relative to the scene folder */
    char **names;               /* raw names from newmtl */
    uint32_t *ids;              /* scene material of each name */
    size_t num, cap;
};

void mesh_obj_cache_fini(struct mesh_obj_cache *cache)
{
    for (size_t i = 0; i < cache->num_mtls; i++) {
        struct mesh_obj_mtl *m = &cache->mtls[i];
        for (size_t k = 0; k < m->num; k++)
            free(m->names[k]);
        free(m->names);
        free(m->ids);
    }
    free(cache->mtls);
    memset(cache, 0, sizeof *cache);
}

struct mesh_obj_options mesh_obj_default_options(void)
{
    struct mesh_obj_options o;
    o.transform = dxform_identity();
    o.material_override = MESH_OBJ_NO_OVERRIDE;
    o.display_dir = "";
    o.mesh_name = NULL;
    return o;
}

/* ---- Line and token scanning shared by OBJ and MTL ---- */

struct reader {
    const char *text;
    size_t len;
    size_t pos;          /* start of the next line */
    size_t line_start, line_end, cur;
    uint32_t line;
    char file[ASSET_PATH_MAX + 256];  /* display name */
    char *err;
    size_t errlen;
};

struct token {
    const char *p;
    size_t n;
};

static void reader_init(struct reader *r, const char *display_dir, const char *rel_path, const char *text,
                        size_t len, char *err, size_t errlen)
{
    memset(r, 0, sizeof *r);
    r->text = text;
    r->len = len;
    str_fmt(r->file, sizeof r->file, "%s%s", display_dir ? display_dir : "", rel_path);
    r->err = err;
    r->errlen = errlen;
}

/* Advances to the next line; the line excludes its '\n' and a trailing '\r'. */
static bool reader_next_line(struct reader *r)
{
    if (r->pos >= r->len)
        return false;
    size_t s = r->pos, e = s;
    while (e < r->len && r->text[e] != '\n')
        e++;
    r->pos = e < r->len ? e + 1 : e;
    if (e > s && r->text[e - 1] == '\r')
        e--;
    r->line_start = r->cur = s;
    r->line_end = e;
    r->line++;
    return true;
}

/* Columns count UTF-8 code points, like jansson does for the scene file. */
static uint32_t reader_col(const struct reader *r, const char *p)
{
    uint32_t col = 1;
    for (const char *q = r->text + r->line_start; q < p; q++)
        if (((unsigned char)*q & 0xC0) != 0x80)
            col++;
    return col;
}

__attribute__((format(printf, 3, 4))) static int reader_fail(struct reader *r, const char *at, const char *fmt, ...)
{
    char msg[768];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(msg, sizeof msg, fmt, ap);
    va_end(ap);
    if (!at)
        at = r->text + r->cur;
    str_fmt(r->err, r->errlen, "%s:%u:%u: %s", r->file, r->line, reader_col(r, at), msg);
    return -1;
}

static bool is_space(char c) { return c == ' ' || c == '\t' || c == '\r' || c == '\v' || c == '\f'; }

/* Next whitespace-separated token of the current line; '#' at a token start begins a
 * comment. Returns 1 with a token, 0 at the end of the line, -1 on a control byte. */
static int reader_token(struct reader *r, struct token *t)
{
    size_t i = r->cur, e = r->line_end;
    while (i < e && is_space(r->text[i]))
        i++;
    if (i >= e || r->text[i] == '#') {
        r->cur = e;
        return 0;
    }
    size_t s = i;
    while (i < e && !is_space(r->text[i])) {
        unsigned char c = (unsigned char)r->text[i];
        if (c < 0x20 || c == 0x7f) {
            r->cur = i;
            return reader_fail(r, r->text + i, "unexpected control byte 0x%02x", c);
        }
        i++;
    }
    r->cur = i;
    t->p = r->text + s;
    t->n = i - s;
    return 1;
}

static bool token_is(const struct token *t, const char *word)
{
    size_t n = strlen(word);
    return t->n == n && memcmp(t->p, word, n) == 0;
}

/* The rest of the line as one name (names may contain spaces); at least one token. */
static int reader_rest(struct reader *r, struct token *name, const char *what)
{
    const char *at = r->text + r->cur;
    struct token t;
    int k = reader_token(r, &t);
    if (k < 0)
        return -1;
    if (k == 0)
        return reader_fail(r, at, "%s needs a name", what);
    name->p = t.p;
    const char *end = t.p + t.n;
    while ((k = reader_token(r, &t)) == 1)
        end = t.p + t.n;
    if (k < 0)
        return -1;
    name->n = (size_t)(end - name->p);
    if (name->n > NAME_LEN_MAX)
        return reader_fail(r, name->p, "%s name longer than %d bytes", what, NAME_LEN_MAX);
    return 0;
}

/* Strict decimal grammar: [+-] (d+ [. d*] | . d+) [(e|E) [+-] d+]. */
static bool number_syntax_ok(const char *p, size_t n)
{
    size_t i = 0, digits = 0;
    if (i < n && (p[i] == '+' || p[i] == '-'))
        i++;
    while (i < n && p[i] >= '0' && p[i] <= '9')
        i++, digits++;
    if (i < n && p[i] == '.') {
        i++;
        while (i < n && p[i] >= '0' && p[i] <= '9')
            i++, digits++;
    }
    if (digits == 0)
        return false;
    if (i < n && (p[i] == 'e' || p[i] == 'E')) {
        i++;
        if (i < n && (p[i] == '+' || p[i] == '-'))
            i++;
        size_t ed = 0;
        while (i < n && p[i] >= '0' && p[i] <= '9')
            i++, ed++;
        if (ed == 0)
            return false;
    }
    return i == n;
}

/* A number that fits a float, read in double: vertices keep their digits until the render
 * frame's origin is subtracted. */
static int token_number(struct reader *r, const struct token *t, double *out)
{
    char buf[80];
    if (t->n >= sizeof buf || !number_syntax_ok(t->p, t->n))
        return reader_fail(r, t->p, "malformed number \"%.*s\"", (int)(t->n > 32 ? 32 : t->n), t->p);
    memcpy(buf, t->p, t->n);
    buf[t->n] = '\0';
    double d = strtod(buf, NULL);
    if (!(d >= -FLT_MAX && d <= FLT_MAX))
        return reader_fail(r, t->p, "number \"%s\" out of range", buf);
    *out = d;
    return 0;
}

static int token_float(struct reader *r, const struct token *t, float *out)
{
    double d;
    if (token_number(r, t, &d) != 0)
        return -1;
    *out = (float)d;
    return 0;
}

/* Reads between min_n and max_n numbers to the end of the line; returns the count.
 * where (optional, max_n entries) receives each number's position for messages. */
static int reader_numbers(struct reader *r, double *out, const char **where, int min_n, int max_n, const char *what)
{
    int n = 0;
    struct token t;
    int k;
    const char *start = r->text + r->cur;
    while ((k = reader_token(r, &t)) == 1) {
        if (n == max_n)
            return reader_fail(r, t.p, "%s takes at most %d numbers", what, max_n);
        if (token_number(r, &t, &out[n]) != 0)
            return -1;
        if (where)
            where[n] = t.p;
        n++;
    }
    if (k < 0)
        return -1;
    if (n < min_n)
        return reader_fail(r, n ? r->text + r->cur : start, "%s needs %s%d numbers, got %d", what,
                           min_n == max_n ? "" : "at least ", min_n, n);
    return n;
}

/* reader_numbers rounded to float (max_n <= 6): everything but vertex positions. */
static int reader_floats(struct reader *r, float *out, const char **where, int min_n, int max_n, const char *what)
{
    double d[6];
    int n = reader_numbers(r, d, where, min_n, max_n < 6 ? max_n : 6, what);
    for (int i = 0; i < n; i++)
        out[i] = (float)d[i];
    return n;
}

/* ---- MTL ---- */

static void material_name(char *out, const char *mtl_path, const struct token *name)
{
    str_fmt(out, SCENE_NAME_MAX, "%s:%.*s", mtl_path, (int)name->n, name->p);
}

static const char *const map_keywords[] = {"map_Kd", "map_Ka", "map_Ks", "map_Ke", "map_Ns", "map_d",
                                           "map_bump", "bump", "map_Bump", "disp", "decal", "refl",
                                           "norm", "map_Pr", "map_Pm", "map_Ps", "map_Pc", "map_Pcr",
                                           "map_aniso", "map_anisor", "map_Tr"};
static const char *const mtl_ignored[] = {"Ka", "Ks", "Ns", "Ni", "d", "Tr", "Tf", "illum",
                                          "sharpness", "Pr", "Pm", "Ps", "Pc", "Pcr", "aniso", "anisor"};

/* map_Kd [-s u v [w]] [-o u v [w]] [-clamp on|off] file: an image texture for the
 * diffuse albedo, relative to the MTL's folder (the albedo Kd then multiplies it; a
 * material with map_Kd and no Kd gets Kd 1). With bump (map_Bump, map_bump, bump; also
 * -bm mult): a height map, read as linear values, scaled by mult (default 1) in scene
 * units. With norm: a tangent-space normal map (linear values). Returns 0, 1 when the
 * statement was skipped
 * (an option we do not support: warned), -1 on an error (in r->err). */
enum mtl_map { MTL_MAP_KD, MTL_MAP_BUMP, MTL_MAP_NORM };

static int mtl_map_kd(struct reader *r, struct scene *scene, const struct asset_source *src, const char *mtl_path,
                      const char *display_dir, uint32_t cur, const struct token *kw, bool *kd_given,
                      enum mtl_map kind)
{
    const bool bump = kind == MTL_MAP_BUMP;
    const char *what = kind == MTL_MAP_KD ? "map_Kd" : (bump ? "bump map" : "normal map");
    float bm = 1.0f;
    if (cur == UINT32_MAX)
        return reader_fail(r, kw->p, "%s before any newmtl", what);
    struct texture t;
    texture_init(&t, TEXTURE_IMAGE, NULL);
    str_fmt(t.name, sizeof t.name, "%s", scene->materials[cur].name);
    for (;;) {
        size_t save = r->cur;
        struct token o;
        int k = reader_token(r, &o);
        if (k < 0)
            return -1;
        if (k == 0)
            return reader_fail(r, r->text + r->cur, "%s needs a file name", what);
        if (o.n < 2 || o.p[0] != '-') {
            r->cur = save;
            break;
        }
        if (token_is(&o, "-s") || token_is(&o, "-o")) {
            float v[3] = {0, 0, 0};
            int n = 0;
            for (; n < 3; n++) { /* two or three numbers; stop at the first non-number */
                size_t at = r->cur;
                struct token nt;
                if (reader_token(r, &nt) != 1 || !number_syntax_ok(nt.p, nt.n)) {
                    r->cur = at;
                    break;
                }
                if (token_float(r, &nt, &v[n]) != 0)
                    return -1;
            }
            if (n < 2)
                return reader_fail(r, o.p, "%.*s needs 2 or 3 numbers", (int)o.n, o.p);
            float *dst = o.p[1] == 's' ? t.scale : t.offset;
            dst[0] = v[0];
            dst[1] = v[1];
            if (o.p[1] == 's' && !(fabsf(v[0]) >= 1e-6f && fabsf(v[1]) >= 1e-6f && fabsf(v[0]) <= 1e6f &&
                                   fabsf(v[1]) <= 1e6f))
                return reader_fail(r, o.p, "-s components must be in [1e-6, 1e6] in magnitude");
            if (o.p[1] == 'o' && !(fabsf(v[0]) <= 1e6f && fabsf(v[1]) <= 1e6f))
                return reader_fail(r, o.p, "-o components must be in [-1e6, 1e6]");
            continue;
        }
        if (bump && token_is(&o, "-bm")) {
            struct token v;
            if (reader_token(r, &v) != 1 || token_float(r, &v, &bm) != 0 || !(fabsf(bm) <= 1e6f))
                return reader_fail(r, o.p, "-bm needs a number in [-1e6, 1e6]");
            continue;
        }
        if (token_is(&o, "-clamp")) {
            struct token v;
            if (reader_token(r, &v) != 1 || !(token_is(&v, "on") || token_is(&v, "off")))
                return reader_fail(r, o.p, "-clamp needs on or off");
            t.wrap = token_is(&v, "on") ? TEXWRAP_CLAMP : TEXWRAP_REPEAT;
            continue;
        }
        log_warn("%s:%u:%u: %s option \"%.*s\" not supported: %s ignored", r->file, r->line, reader_col(r, o.p),
                 what, (int)(o.n > 16 ? 16 : o.n), o.p, what);
        r->cur = r->line_end;
        return 1;
    }
    struct token file;
    if (reader_rest(r, &file, what) != 0)
        return -1;
    char rel[ASSET_PATH_MAX], dir[ASSET_PATH_MAX], name[NAME_LEN_MAX + 1], why[1024];
    const char *slash = strrchr(mtl_path, '/');
    size_t dl = slash ? (size_t)(slash - mtl_path) : 0;
    memcpy(dir, mtl_path, dl);
    dir[dl] = '\0';
    memcpy(name, file.p, file.n);
    name[file.n] = '\0';
    path_normalise(name);
    if (asset_path_join(dir, name, rel, sizeof rel, why, sizeof why) != 0)
        return reader_fail(r, file.p, "%s: %s", what, why);
    char display[ASSET_PATH_MAX + 1024];
    str_fmt(display, sizeof display, "%s%s", display_dir ? display_dir : "", rel);
    if (!src || !src->read)
        return reader_fail(r, file.p, "%s: no asset source to read \"%s\" from", what, rel);
    /* Heights are data, not colours: a bump map's bytes are read as linear. */
    if (image_load_asset(src, rel, display, kind == MTL_MAP_KD, &t.image, why, sizeof why) != 0)
        return reader_fail(r, file.p, "%s: %s", what, why);
    if (scene->num_textures >= 65536) {
        texture_fini(&t);
        return reader_fail(r, kw->p, "too many textures (at most 65536)");
    }
    uint32_t id = scene_add_texture(scene, &t) + 1;
    if (kind == MTL_MAP_NORM) {
        scene->materials[cur].normal_tex = id;
        return 0;
    }
    if (bump) {
        scene->materials[cur].bump_tex = id;
        scene->materials[cur].bump_scale = bm;
        return 0;
    }
    scene->materials[cur].albedo_tex = id;
    if (!*kd_given)
        scene->materials[cur].albedo = v3(1, 1, 1);
    return 0;
}

static int mtl_parse(struct scene *scene, struct mesh_obj_mtl *mtl, const char *display_dir, const char *text,
                     size_t len, const struct asset_source *src, char *err, size_t errlen)
{
    struct reader r;
    reader_init(&r, display_dir, mtl->path, text, len, err, errlen);
    uint32_t warned_maps = 0;
    bool warned_unknown = false;
    uint32_t cur = UINT32_MAX;  /* scene id of the material being defined */
    bool kd_given = false;      /* of the current material */
    while (reader_next_line(&r)) {
        struct token kw;
        int k = reader_token(&r, &kw);
        if (k < 0)
            return -1;
        if (k == 0)
            continue;
        if (token_is(&kw, "newmtl")) {
            struct token name;
            if (reader_rest(&r, &name, "newmtl") != 0)
                return -1;
            for (size_t i = 0; i < mtl->num; i++)
                if (strlen(mtl->names[i]) == name.n && memcmp(mtl->names[i], name.p, name.n) == 0)
                    return reader_fail(&r, name.p, "material \"%.*s\" defined twice", (int)name.n, name.p);
            if (mtl->num >= MESH_OBJ_MAX_ELEMENTS)
                return reader_fail(&r, kw.p, "too many materials");
            struct material m;
            memset(&m, 0, sizeof m);
            material_name(m.name, mtl->path, &name);
            m.type = MATERIAL_DIFFUSE;
            m.albedo = v3(DEFAULT_ALBEDO, DEFAULT_ALBEDO, DEFAULT_ALBEDO);
            m.emission = v3(0, 0, 0);
            cur = scene_add_material(scene, &m);
            kd_given = false;
            size_t cap = mtl->cap;
            mem_grow((void **)&mtl->names, &cap, mtl->num + 1, sizeof *mtl->names);
            cap = mtl->cap;
            mem_grow((void **)&mtl->ids, &cap, mtl->num + 1, sizeof *mtl->ids);
            mtl->cap = cap;
            char *copy = mem_alloc(name.n + 1);
            memcpy(copy, name.p, name.n);
            copy[name.n] = '\0';
            mtl->names[mtl->num] = copy;
            mtl->ids[mtl->num] = cur;
            mtl->num++;
            continue;
        }
        bool is_kd = token_is(&kw, "Kd"), is_ke = token_is(&kw, "Ke");
        if (is_kd || is_ke) {
            if (cur == UINT32_MAX)
                return reader_fail(&r, kw.p, "%s before any newmtl", is_kd ? "Kd" : "Ke");
            const char *at = r.text + r.cur;
            float c[3];
            const char *where[3];
            int n = reader_floats(&r, c, where, 1, 3, is_kd ? "Kd" : "Ke");
            if (n < 0)
                return -1;
            if (n == 2)
                return reader_fail(&r, at, "%s needs 1 or 3 numbers", is_kd ? "Kd" : "Ke");
            if (n == 1)
                c[1] = c[2] = c[0];
            for (int i = 0; i < 3; i++) {
                if (is_kd && !(c[i] >= 0.0f && c[i] <= 1.0f))
                    return reader_fail(&r, where[n == 1 ? 0 : i], "Kd components must be in [0, 1]");
                if (is_ke && !(c[i] >= 0.0f))
                    return reader_fail(&r, where[n == 1 ? 0 : i], "Ke components must be >= 0");
            }
            if (is_kd)
                scene->materials[cur].albedo = v3(c[0], c[1], c[2]);
            else
                scene->materials[cur].emission = v3(c[0], c[1], c[2]);
            kd_given = kd_given || is_kd;
            continue;
        }
        bool known = false;
        for (size_t i = 0; i < sizeof mtl_ignored / sizeof *mtl_ignored; i++)
            if (token_is(&kw, mtl_ignored[i]))
                known = true;
        if (known) {
            r.cur = r.line_end;  /* parameters of ignored statements are not interpreted */
            continue;
        }
        if (token_is(&kw, "map_Kd") || token_is(&kw, "map_Bump") || token_is(&kw, "map_bump") || token_is(&kw, "bump") ||
            token_is(&kw, "norm")) {
            enum mtl_map kind = token_is(&kw, "map_Kd") ? MTL_MAP_KD : (token_is(&kw, "norm") ? MTL_MAP_NORM : MTL_MAP_BUMP);
            if (mtl_map_kd(&r, scene, src, mtl->path, display_dir, cur, &kw, &kd_given, kind) < 0)
                return -1;
            continue;
        }
        size_t map = SIZE_MAX;
        for (size_t i = 0; i < sizeof map_keywords / sizeof *map_keywords; i++)
            if (token_is(&kw, map_keywords[i]))
                map = i;
        if (map == SIZE_MAX && kw.n > 4 && memcmp(kw.p, "map_", 4) == 0)
            map = 0;  /* unlisted maps share map_Kd's warning bit but keep their name */
        if (map != SIZE_MAX) {
            if (!(warned_maps & (1u << map))) {
                warned_maps |= 1u << map;
                log_warn("%s:%u:%u: %.*s ignored for now", r.file, r.line, reader_col(&r, kw.p), (int)kw.n,
                         kw.p);
            }
            r.cur = r.line_end;
            continue;
        }
        if (!warned_unknown) {
            warned_unknown = true;
            log_warn("%s:%u:%u: unknown MTL statement \"%.*s\" ignored (further ones silently)", r.file, r.line,
                     reader_col(&r, kw.p), (int)(kw.n > 32 ? 32 : kw.n), kw.p);
        }
        r.cur = r.line_end;
    }
    return 0;
}

/* Finds the cache index of the MTL at mtl_path, reading it on first use. Returns 0, -1
 * when it cannot be read, -2 when it is malformed (err then has its file:line:col). */
static int mtl_get(struct scene *scene, struct mesh_obj_cache *cache, const struct asset_source *src,
                   const char *display_dir, const char *mtl_path, size_t *index, char *err, size_t errlen)
{
    for (size_t i = 0; i < cache->num_mtls; i++)
        if (strcmp(cache->mtls[i].path, mtl_path) == 0) {
            *index = i;
            return 0;
        }
    char *data = NULL;
    size_t size = 0;
    if (!src || !src->read) {
        str_fmt(err, errlen, "%s: no asset source to read it from", mtl_path);
        return -1;
    }
    if (src->read(src->ctx, mtl_path, &data, &size, err, errlen) != 0)
        return -1;
    mem_grow((void **)&cache->mtls, &cache->cap_mtls, cache->num_mtls + 1, sizeof *cache->mtls);
    struct mesh_obj_mtl *m = &cache->mtls[cache->num_mtls++];
    memset(m, 0, sizeof *m);
    memcpy(m->path, mtl_path, strlen(mtl_path) + 1);
    int rc = mtl_parse(scene, m, display_dir, data, size, src, err, errlen);
    free(data);
    *index = cache->num_mtls - 1;
    return rc == 0 ? 0 : -2;
}

/* ---- OBJ ---- */

struct corner { int32_t v, vt, vn; };

struct obj_state {
    double *pos;             /* as written: the transform and origin apply in double */
    float *nrm, *uv;
    size_t num_pos, num_nrm, num_uv, cap_pos, cap_nrm, cap_uv;
    struct corner *corners;  /* 3 per triangle */
    uint32_t *tri_mat;
    size_t num_tris, cap_corners, cap_tri;
    struct corner *poly;     /* corners of the face being read */
    size_t cap_poly;
    size_t *mtls;            /* cache indices named by mtllib */
    size_t num_mtls, cap_mtls;
    uint32_t unknown_materials; /* usemtl names no MTL defines */
    double *proj;            /* 2 per corner of the face being read: its projection (ear clipping) */
    uint32_t *ring;          /* the corners left to clip */
    size_t cap_proj, cap_ring;
};

static void obj_state_free(struct obj_state *s)
{
    free(s->pos);
    free(s->nrm);
    free(s->uv);
    free(s->corners);
    free(s->tri_mat);
    free(s->poly);
    free(s->mtls);
    free(s->proj);
    free(s->ring);
}

static int parse_index(struct reader *r, const char *p, size_t n, size_t count, const char *what, int32_t *out)
{
    size_t i = 0;
    bool neg = false;
    if (i < n && (p[i] == '-' || p[i] == '+'))
        neg = p[i++] == '-';
    if (i == n)
        return reader_fail(r, p, "malformed %s index \"%.*s\"", what, (int)(n > 32 ? 32 : n), p);
    uint64_t v = 0;
    for (; i < n; i++) {
        if (p[i] < '0' || p[i] > '9')
            return reader_fail(r, p, "malformed %s index \"%.*s\"", what, (int)(n > 32 ? 32 : n), p);
        v = v * 10 + (uint64_t)(p[i] - '0');
        if (v > (uint64_t)MESH_OBJ_MAX_ELEMENTS * 4)
            v = (uint64_t)MESH_OBJ_MAX_ELEMENTS * 4;  /* saturate: reported as out of range */
    }
    if (v == 0)
        return reader_fail(r, p, "%s index 0 is invalid (OBJ indices start at 1)", what);
    if (v > count)
        return reader_fail(r, p, "%s index %s%llu out of range (%zu defined so far)", what, neg ? "-" : "",
                           (unsigned long long)v, count);
    *out = (int32_t)(neg ? count - v : v - 1);
    return 0;
}

static int parse_corner(struct reader *r, const struct token *t, const struct obj_state *s, struct corner *c)
{
    const char *p = t->p, *end = t->p + t->n;
    const char *s1 = memchr(p, '/', t->n);
    const char *s2 = s1 ? memchr(s1 + 1, '/', (size_t)(end - s1 - 1)) : NULL;
    if (s2 && memchr(s2 + 1, '/', (size_t)(end - s2 - 1)))
        return reader_fail(r, p, "face corner \"%.*s\" has more than three parts", (int)(t->n > 32 ? 32 : t->n), p);
    c->vt = c->vn = -1;
    if (parse_index(r, p, (size_t)((s1 ? s1 : end) - p), s->num_pos, "vertex", &c->v) != 0)
        return -1;
    if (s1) {
        const char *b = s1 + 1, *e = s2 ? s2 : end;
        if (b < e) {
            if (parse_index(r, b, (size_t)(e - b), s->num_uv, "texture coordinate", &c->vt) != 0)
                return -1;
        } else if (!s2) {
            return reader_fail(r, p, "face corner \"%.*s\" ends with '/'", (int)(t->n > 32 ? 32 : t->n), p);
        }
    }
    if (s2) {
        if (s2 + 1 >= end)
            return reader_fail(r, p, "face corner \"%.*s\" ends with '/'", (int)(t->n > 32 ? 32 : t->n), p);
        if (parse_index(r, s2 + 1, (size_t)(end - s2 - 1), s->num_nrm, "normal", &c->vn) != 0)
            return -1;
    }
    return 0;
}

/* Appends one element of elem_size bytes to *arr (*cap counts elements). */
static int push_element(struct reader *r, void **arr, size_t *count, size_t *cap, const void *v, size_t elem_size,
                        const char *what)
{
    if (*count >= MESH_OBJ_MAX_ELEMENTS)
        return reader_fail(r, r->text + r->line_start, "more than %u %s", MESH_OBJ_MAX_ELEMENTS, what);
    mem_grow(arr, cap, *count + 1, elem_size);
    memcpy((char *)*arr + *count * elem_size, v, elem_size);
    (*count)++;
    return 0;
}

static uint32_t default_material(struct scene *scene, struct mesh_obj_cache *cache)
{
    if (!cache->has_default) {
        struct material m;
        memset(&m, 0, sizeof m);
        str_fmt(m.name, sizeof m.name, "default");
        m.type = MATERIAL_DIFFUSE;
        m.albedo = v3(DEFAULT_ALBEDO, DEFAULT_ALBEDO, DEFAULT_ALBEDO);
        cache->default_material = scene_add_material(scene, &m);
        cache->has_default = 1;
    }
    return cache->default_material;
}

static const char *const obj_unsupported[] = {"l", "p", "vp", "cstype", "deg", "bmat", "step", "curv",
                                              "curv2", "surf", "parm", "trim", "hole", "scrv", "sp", "end",
                                              "con", "mg", "bevel", "c_interp", "d_interp", "lod", "maplib",
                                              "usemap", "shadow_obj", "trace_obj", "ctech", "stech", "call",
                                              "csh"};

static void add_triangle(struct obj_state *s, uint32_t a, uint32_t b, uint32_t c, uint32_t material)
{
    struct corner *t = &s->corners[3 * s->num_tris];
    t[0] = s->poly[a];
    t[1] = s->poly[b];
    t[2] = s->poly[c];
    s->tri_mat[s->num_tris++] = material;
}

/* Twice the signed area of the projected triangle (a, b, c); > 0 turning left. */
static double proj_cross(const double *q, uint32_t a, uint32_t b, uint32_t c)
{
    return (q[2 * b] - q[2 * a]) * (q[2 * c + 1] - q[2 * a + 1]) - (q[2 * b + 1] - q[2 * a + 1]) * (q[2 * c] - q[2 * a]);
}

/* Projects the face's n corners onto the plane of its Newell normal (the best-fit plane's
 * orientation, which also fits non-planar polygons), turned so the polygon winds
 * counter-clockwise. 1 when it is convex (every turn left or straight, one turn around
 * in all), so that a fan splits it exactly; 0 when it is not; -1 when it crosses itself
 * (its turns add up to other than one turn around). A degenerate face (zero normal)
 * counts as convex: its fan is the zero-area triangles it always gave. */
static int polygon_project_convex(struct obj_state *s, size_t n)
{
    double nrm[3] = {0, 0, 0};
    for (size_t i = 0; i < n; i++) {
        const double *a = &s->pos[3 * (size_t)s->poly[i].v], *b = &s->pos[3 * (size_t)s->poly[(i + 1) % n].v];
        nrm[0] += (a[1] - b[1]) * (a[2] + b[2]);
        nrm[1] += (a[2] - b[2]) * (a[0] + b[0]);
        nrm[2] += (a[0] - b[0]) * (a[1] + b[1]);
    }
    int k = fabs(nrm[0]) > fabs(nrm[1]) ? (fabs(nrm[0]) > fabs(nrm[2]) ? 0 : 2) : (fabs(nrm[1]) > fabs(nrm[2]) ? 1 : 2);
    if (!(fabs(nrm[k]) > 0.0) || !isfinite(nrm[k]))
        return 1;
    int u = (k + 1) % 3, v = (k + 2) % 3;
    double flip = nrm[k] < 0.0 ? -1.0 : 1.0;
    mem_grow((void **)&s->proj, &s->cap_proj, 2 * n, sizeof *s->proj);
    for (size_t i = 0; i < n; i++) {
        const double *p = &s->pos[3 * (size_t)s->poly[i].v];
        s->proj[2 * i] = flip * p[u];
        s->proj[2 * i + 1] = p[v];
    }
    double turning = 0.0;
    int convex = 1;
    for (size_t i = 0; i < n; i++) {
        uint32_t a = (uint32_t)((i + n - 1) % n), b = (uint32_t)i, c = (uint32_t)((i + 1) % n);
        convex &= proj_cross(s->proj, a, b, c) >= 0.0;
        double ex = s->proj[2 * b] - s->proj[2 * a], ey = s->proj[2 * b + 1] - s->proj[2 * a + 1];
        double fx = s->proj[2 * c] - s->proj[2 * b], fy = s->proj[2 * c + 1] - s->proj[2 * b + 1];
        turning += atan2(ex * fy - ey * fx, ex * fx + ey * fy);
    }
    if (fabs(turning - 2.0 * M_PI) > 0.5)
        return -1; /* a star turns around more than once, a figure eight not at all */
    return convex;
}

/* 1 when projected point p lies inside or on the triangle (a, b, c) (counter-clockwise). */
static int proj_in_triangle(const double *q, uint32_t a, uint32_t b, uint32_t c, uint32_t p)
{
    return proj_cross(q, a, b, p) >= 0.0 && proj_cross(q, b, c, p) >= 0.0 && proj_cross(q, c, a, p) >= 0.0;
}

/* Ear clipping of the projected, counter-clockwise polygon: an ear is a corner turning
 * left whose triangle holds no other corner; clipping keeps the polygon's winding, so
 * every triangle faces the way the polygon does. Corners on a straight line are clipped
 * last, as zero-area ears. -1 when no ear is left (a polygon that crosses itself). */
static int ear_clip(struct obj_state *s, size_t n, uint32_t material)
{
    mem_grow((void **)&s->ring, &s->cap_ring, n, sizeof *s->ring);
    uint32_t *ring = s->ring;
    for (size_t i = 0; i < n; i++)
        ring[i] = (uint32_t)i;
    size_t m = n;
    const double *q = s->proj;
    while (m > 3) {
        size_t found = SIZE_MAX;
        for (int pass = 0; pass < 2 && found == SIZE_MAX; pass++)
            for (size_t i = 0; i < m && found == SIZE_MAX; i++) {
                uint32_t a = ring[(i + m - 1) % m], b = ring[i], c = ring[(i + 1) % m];
                double cr = proj_cross(q, a, b, c);
                if (pass == 0 ? !(cr > 0.0) : !(cr >= 0.0))
                    continue;
                int empty = 1;
                for (size_t j = 0; j < m && empty; j++) {
                    uint32_t p = ring[j];
                    if (p == a || p == b || p == c)
                        continue;
                    const double *pp = &q[2 * p];
                    if ((pp[0] == q[2 * a] && pp[1] == q[2 * a + 1]) || (pp[0] == q[2 * c] && pp[1] == q[2 * c + 1]))
                        continue; /* a corner repeated where the polygon touches itself */
                    empty = !(cr > 0.0 && proj_in_triangle(q, a, b, c, p));
                }
                if (empty)
                    found = i;
            }
        if (found == SIZE_MAX)
            return -1;
        add_triangle(s, ring[(found + m - 1) % m], ring[found], ring[(found + 1) % m], material);
        memmove(&ring[found], &ring[found + 1], (m - found - 1) * sizeof *ring);
        m--;
    }
    add_triangle(s, ring[0], ring[1], ring[2], material);
    return 0;
}

/* Triangles of the polygon in s->poly (n >= 3 corners) into s: a fan when it is convex,
 * else ear clipping. -1 with the reason in why. */
static int polygon_add(struct obj_state *s, size_t n, uint32_t material, char *why, size_t whylen)
{
    if (s->num_tris + (n - 2) > MESH_OBJ_MAX_ELEMENTS) {
        str_fmt(why, whylen, "more than %u triangles", MESH_OBJ_MAX_ELEMENTS);
        return -1;
    }
    mem_grow((void **)&s->corners, &s->cap_corners, 3 * (s->num_tris + n - 2), sizeof *s->corners);
    mem_grow((void **)&s->tri_mat, &s->cap_tri, s->num_tris + n - 2, sizeof *s->tri_mat);
    int shape = n == 3 ? 1 : polygon_project_convex(s, n);
    if (shape < 0) {
        str_fmt(why, whylen, "face with %zu corners crosses itself: it cannot be triangulated", n);
        return -1;
    }
    if (shape == 1) {
        /* Fan around the first corner: exact for convex polygons (most of what exporters write). */
        for (size_t i = 1; i + 1 < n; i++)
            add_triangle(s, 0, (uint32_t)i, (uint32_t)(i + 1), material);
        return 0;
    }
    if (n > EAR_CLIP_MAX_CORNERS) {
        str_fmt(why, whylen, "non-convex face with %zu corners (at most %d can be triangulated)", n,
                EAR_CLIP_MAX_CORNERS);
        return -1;
    }
    if (ear_clip(s, n, material) != 0) {
        str_fmt(why, whylen, "face with %zu corners cannot be triangulated: it folds back on its plane", n);
        return -1;
    }
    return 0;
}

static int obj_face(struct reader *r, struct obj_state *s, uint32_t material)
{
    size_t n = 0;
    struct token t;
    int k;
    const char *start = r->text + r->cur;
    while ((k = reader_token(r, &t)) == 1) {
        if (n >= MESH_OBJ_MAX_ELEMENTS)
            return reader_fail(r, t.p, "face with too many corners");
        mem_grow((void **)&s->poly, &s->cap_poly, n + 1, sizeof *s->poly);
        if (parse_corner(r, &t, s, &s->poly[n]) != 0)
            return -1;
        n++;
    }
    if (k < 0)
        return -1;
    if (n < 3)
        return reader_fail(r, n ? r->text + r->cur : start, "face needs at least 3 corners, got %zu", n);
    char why[160];
    if (polygon_add(s, n, material, why, sizeof why) != 0)
        return reader_fail(r, start, "%s", why);
    return 0;
}

/* Cofactor matrix of the 3x3 part: det * inverse transpose, so it maps normals
 * correctly up to scale (and sign, fixed by the caller). */
static void xform_cofactor(const struct xform *t, float c[3][3], float *det)
{
    const float (*m)[4] = t->m;
    c[0][0] = m[1][1] * m[2][2] - m[1][2] * m[2][1];
    c[0][1] = m[1][2] * m[2][0] - m[1][0] * m[2][2];
    c[0][2] = m[1][0] * m[2][1] - m[1][1] * m[2][0];
    c[1][0] = m[0][2] * m[2][1] - m[0][1] * m[2][2];
    c[1][1] = m[0][0] * m[2][2] - m[0][2] * m[2][0];
    c[1][2] = m[0][1] * m[2][0] - m[0][0] * m[2][1];
    c[2][0] = m[0][1] * m[1][2] - m[0][2] * m[1][1];
    c[2][1] = m[0][2] * m[1][0] - m[0][0] * m[1][2];
    c[2][2] = m[0][0] * m[1][1] - m[0][1] * m[1][0];
    *det = m[0][0] * c[0][0] + m[0][1] * c[0][1] + m[0][2] * c[0][2];
}

static uint64_t corner_hash(int32_t v, int32_t vt, int32_t vn)
{
    uint64_t h = (uint64_t)(uint32_t)v * 0x9E3779B97F4A7C15ull;
    h ^= (uint64_t)(uint32_t)vt * 0xC2B2AE3D27D4EB4Full + (h >> 29);
    h ^= (uint64_t)(uint32_t)vn * 0x165667B19E3779F9ull + (h >> 32);
    return h ^ (h >> 31);
}

/* Builds the mesh from the triangles read: shared vertices per distinct (v, vt, vn). */
static void obj_build_mesh(struct obj_state *s, const struct mesh_obj_options *opt, const char *name,
                           const char *file, struct mesh *out)
{
    size_t nc = 3 * s->num_tris;
    bool has_uv = s->num_uv > 0, has_n = s->num_nrm > 0;
    for (size_t i = 0; i < nc && (has_uv || has_n); i++) {
        if (s->corners[i].vt < 0)
            has_uv = false;
        if (s->corners[i].vn < 0)
            has_n = false;
    }
    size_t tsize = 16;
    while (tsize < 2 * nc)
        tsize *= 2;
    uint32_t *table = mem_alloc(tsize * sizeof *table);
    memset(table, 0xff, tsize * sizeof *table);
    struct corner *keys = mem_alloc(nc * sizeof *keys);
    uint32_t *indices = mem_alloc(nc * sizeof *indices);
    uint32_t nv = 0;
    for (size_t i = 0; i < nc; i++) {
        struct corner c = s->corners[i];
        if (!has_uv)
            c.vt = -1;
        if (!has_n)
            c.vn = -1;
        size_t h = (size_t)corner_hash(c.v, c.vt, c.vn) & (tsize - 1);
        for (;;) {
            uint32_t e = table[h];
            if (e == UINT32_MAX) {
                table[h] = nv;
                keys[nv] = c;
                indices[i] = nv++;
                break;
            }
            if (keys[e].v == c.v && keys[e].vt == c.vt && keys[e].vn == c.vn) {
                indices[i] = e;
                break;
            }
            h = (h + 1) & (tsize - 1);
        }
    }
    free(table);
    /* Normals from the transform rounded to float, positions in double. */
    struct xform tf = dxform_to_float(&opt->transform);
    float cof[3][3], det;
    xform_cofactor(&tf, cof, &det);
    float nsign = det < 0.0f ? -1.0f : 1.0f;
    float *positions = mem_alloc(3 * (size_t)nv * sizeof *positions);
    float *normals = has_n ? mem_alloc(3 * (size_t)nv * sizeof *normals) : NULL;
    float *uvs = has_uv ? mem_alloc(2 * (size_t)nv * sizeof *uvs) : NULL;
    for (uint32_t i = 0; i < nv; i++) {
        double w[3];
        dxform_point(&opt->transform, &s->pos[3 * (size_t)keys[i].v], w);
        positions[3 * i + 0] = (float)w[0];
        positions[3 * i + 1] = (float)w[1];
        positions[3 * i + 2] = (float)w[2];
        if (normals) {
            const float *q = &s->nrm[3 * (size_t)keys[i].vn];
            vec3 nn = v3(nsign * (cof[0][0] * q[0] + cof[0][1] * q[1] + cof[0][2] * q[2]),
                         nsign * (cof[1][0] * q[0] + cof[1][1] * q[1] + cof[1][2] * q[2]),
                         nsign * (cof[2][0] * q[0] + cof[2][1] * q[1] + cof[2][2] * q[2]));
            float l = v3_length_rescaled(nn);
            if (!(l > 0.0f) || !isfinite(l)) {
                /* A zero normal cannot shade; geometric normals are the honest fallback. */
                log_warn("%s: degenerate vertex normal, normals dropped for this mesh", file);
                free(normals);
                normals = NULL;
            } else {
                nn = v3_scale(nn, 1.0f / l);
                normals[3 * i + 0] = nn.x;
                normals[3 * i + 1] = nn.y;
                normals[3 * i + 2] = nn.z;
            }
        }
        if (uvs) {
            const float *q = &s->uv[2 * (size_t)keys[i].vt];
            uvs[2 * i + 0] = q[0];
            uvs[2 * i + 1] = q[1];
        }
    }
    free(keys);
    if (det < 0.0f)
        for (size_t t = 0; t < s->num_tris; t++) {
            uint32_t tmp = indices[3 * t + 1];
            indices[3 * t + 1] = indices[3 * t + 2];
            indices[3 * t + 2] = tmp;
        }
    memset(out, 0, sizeof *out);
    str_fmt(out->name, sizeof out->name, "%s", name);
    out->num_vertices = nv;
    out->num_triangles = (uint32_t)s->num_tris;
    out->positions = positions;
    out->normals = normals;
    out->uvs = uvs;
    out->indices = indices;
    out->material_ids = s->tri_mat;
    s->tri_mat = NULL;
    s->cap_tri = 0;
}

static uint32_t default_material(struct scene *scene, struct mesh_obj_cache *cache);

/* usemtl: a name no MTL read so far defines gets the default grey material and a
 * warning naming file:line (as Blender and Cycles load such files). */
static int obj_usemtl(struct reader *r, struct obj_state *s, struct scene *scene, struct mesh_obj_cache *cache,
                      uint32_t *material)
{
    struct token name;
    if (reader_rest(r, &name, "usemtl") != 0)
        return -1;
    for (size_t i = 0; i < s->num_mtls; i++) {
        const struct mesh_obj_mtl *m = &cache->mtls[s->mtls[i]];
        for (size_t k = 0; k < m->num; k++)
            if (strlen(m->names[k]) == name.n && memcmp(m->names[k], name.p, name.n) == 0) {
                *material = m->ids[k];
                return 0;
            }
    }
    if (s->unknown_materials++ < UNKNOWN_MATERIAL_WARNINGS)
        log_warn("%s:%u:%u: unknown material \"%.*s\" (not defined in any mtllib read so far): the default grey "
                 "material is used", r->file, r->line, reader_col(r, name.p), (int)(name.n > 64 ? 64 : name.n), name.p);
    *material = default_material(scene, cache);
    return 0;
}

static int obj_mtllib(struct reader *r, struct obj_state *s, struct scene *scene, struct mesh_obj_cache *cache,
                      const struct asset_source *src, const char *obj_dir, const char *display_dir)
{
    struct token t;
    int k, count = 0;
    while ((k = reader_token(r, &t)) == 1) {
        count++;
        char rel[ASSET_PATH_MAX], path[ASSET_PATH_MAX], why[2048];
        if (t.n >= sizeof rel)
            return reader_fail(r, t.p, "mtllib path too long");
        memcpy(rel, t.p, t.n);
        rel[t.n] = '\0';
        path_normalise(rel);
        if (asset_path_join(obj_dir, rel, path, sizeof path, why, sizeof why) != 0)
            return reader_fail(r, t.p, "mtllib \"%s\": %s", rel, why);
        size_t index = 0;
        int got = mtl_get(scene, cache, src, display_dir, path, &index, why, sizeof why);
        if (got == -2) {
            str_fmt(r->err, r->errlen, "%s", why);  /* already has the MTL's file:line:col */
            return -1;
        }
        if (got != 0)
            return reader_fail(r, t.p, "cannot read MTL file: %s", why);
        mem_grow((void **)&s->mtls, &s->cap_mtls, s->num_mtls + 1, sizeof *s->mtls);
        s->mtls[s->num_mtls++] = index;
    }
    if (k < 0)
        return -1;
    if (count == 0)
        return reader_fail(r, NULL, "mtllib needs a file name");
    return 0;
}

int mesh_obj_parse(struct scene *scene, struct mesh_obj_cache *cache, const struct asset_source *src,
                   const char *rel_path, const char *text, size_t len, const struct mesh_obj_options *opt_in,
                   char *err, size_t errlen)
{
    struct mesh_obj_options opt = opt_in ? *opt_in : mesh_obj_default_options();
    if (!opt.display_dir)
        opt.display_dir = "";
    struct reader r;
    reader_init(&r, opt.display_dir, rel_path, text, len, err, errlen);
    char obj_dir[ASSET_PATH_MAX];
    const char *slash = strrchr(rel_path, '/');
    size_t dn = slash ? (size_t)(slash - rel_path) : 0;
    if (dn >= sizeof obj_dir)
        dn = 0;
    memcpy(obj_dir, rel_path, dn);
    obj_dir[dn] = '\0';

    struct obj_state s;
    memset(&s, 0, sizeof s);
    bool have_material = opt.material_override != MESH_OBJ_NO_OVERRIDE;
    uint32_t material = opt.material_override;
    bool warned_unsupported = false;
    int rc = -1;
    while (reader_next_line(&r)) {
        /* A huge OBJ parses for seconds: a SIGINT / SIGTERM must not wait for its end. */
        if ((r.line & 4095) == 0 && asset_stop_requested()) {
            reader_fail(&r, NULL, "interrupted");
            goto done;
        }
        struct token kw;
        int k = reader_token(&r, &kw);
        if (k < 0)
            goto done;
        if (k == 0)
            continue;
        if (token_is(&kw, "v")) {
            double v[6];
            int n = reader_numbers(&r, v, NULL, 3, 6, "v");
            if (n < 0)
                goto done;
            if (n == 5) {  /* x y z [w], or x y z r g b (the common vertex colour extension) */
                reader_fail(&r, kw.p, "v takes 3, 4 or 6 numbers");
                goto done;
            }
            if (push_element(&r, (void **)&s.pos, &s.num_pos, &s.cap_pos, v, 3 * sizeof *v, "vertices") != 0)
                goto done;
        } else if (token_is(&kw, "vn")) {
            float v[3];
            if (reader_floats(&r, v, NULL, 3, 3, "vn") < 0 ||
                push_element(&r, (void **)&s.nrm, &s.num_nrm, &s.cap_nrm, v, 3 * sizeof *v, "normals") != 0)
                goto done;
        } else if (token_is(&kw, "vt")) {
            float v[3] = {0, 0, 0};
            if (reader_floats(&r, v, NULL, 1, 3, "vt") < 0 ||
                push_element(&r, (void **)&s.uv, &s.num_uv, &s.cap_uv, v, 2 * sizeof *v, "texture coordinates") != 0)
                goto done;
        } else if (token_is(&kw, "f")) {
            if (!have_material) {
                material = default_material(scene, cache);
                have_material = true;
            }
            if (obj_face(&r, &s, material) != 0)
                goto done;
        } else if (token_is(&kw, "o") || token_is(&kw, "g") || token_is(&kw, "s")) {
            r.cur = r.line_end;  /* grouping and smoothing do not change what is rendered */
        } else if (token_is(&kw, "usemtl")) {
            if (opt.material_override != MESH_OBJ_NO_OVERRIDE) {
                r.cur = r.line_end;
                continue;
            }
            if (obj_usemtl(&r, &s, scene, cache, &material) != 0)
                goto done;
            have_material = true;
        } else if (token_is(&kw, "mtllib")) {
            if (opt.material_override != MESH_OBJ_NO_OVERRIDE) {
                r.cur = r.line_end;
                continue;
            }
            if (obj_mtllib(&r, &s, scene, cache, src, obj_dir, opt.display_dir) != 0)
                goto done;
        } else {
            bool known = false;
            for (size_t i = 0; i < sizeof obj_unsupported / sizeof *obj_unsupported; i++)
                if (token_is(&kw, obj_unsupported[i]))
                    known = true;
            if (!known) {
                reader_fail(&r, kw.p, "unknown statement \"%.*s\"", (int)(kw.n > 32 ? 32 : kw.n), kw.p);
                goto done;
            }
            if (!warned_unsupported) {
                warned_unsupported = true;
                log_warn("%s:%u:%u: \"%.*s\" statements ignored (only faces are rendered)", r.file, r.line,
                         reader_col(&r, kw.p), (int)kw.n, kw.p);
            }
            r.cur = r.line_end;
        }
    }
    if (s.num_tris == 0) {
        log_warn("%s: no faces, nothing to render", r.file);
    } else {
        struct mesh m;
        obj_build_mesh(&s, &opt, opt.mesh_name ? opt.mesh_name : rel_path, r.file, &m);
        scene_add_mesh(scene, &m);
    }
    rc = 0;
done:
    obj_state_free(&s);
    return rc;
}

int mesh_obj_from_arrays(struct scene *scene, struct mesh_obj_cache *cache, const struct mesh_arrays *a,
                         const struct mesh_obj_options *opt_in, const char *file, char *err, size_t errlen)
{
    struct mesh_obj_options opt = opt_in ? *opt_in : mesh_obj_default_options();
    uint32_t material = opt.material_override != MESH_OBJ_NO_OVERRIDE ? opt.material_override
                                                                       : default_material(scene, cache);
    struct obj_state s;
    memset(&s, 0, sizeof s);
    /* Borrowed: the OBJ state's attribute arrays are the caller's (not freed below). */
    s.pos = a->positions;
    s.nrm = a->normals;
    s.uv = a->uvs;
    s.num_pos = a->num_vertices;
    s.num_nrm = a->normals ? a->num_vertices : 0;
    s.num_uv = a->uvs ? a->num_vertices : 0;
    int rc = 0;
    size_t at = 0;
    for (size_t f = 0; f < a->num_faces && rc == 0; f++) {
        size_t n = a->face_sizes[f];
        mem_grow((void **)&s.poly, &s.cap_poly, n, sizeof *s.poly);
        for (size_t k = 0; k < n; k++) {
            int32_t v = (int32_t)a->face_corners[at + k];
            s.poly[k] = (struct corner){v, a->uvs ? v : -1, a->normals ? v : -1};
        }
        at += n;
        char why[160];
        if (polygon_add(&s, n, material, why, sizeof why) != 0) {
            str_fmt(err, errlen, "%s%s: face %zu: %s", opt.display_dir ? opt.display_dir : "", file, f, why);
            rc = -1;
        }
    }
    if (rc == 0 && s.num_tris > 0) {
        struct mesh m;
        char display[ASSET_PATH_MAX + 1024];
        str_fmt(display, sizeof display, "%s%s", opt.display_dir ? opt.display_dir : "", file);
        obj_build_mesh(&s, &opt, opt.mesh_name ? opt.mesh_name : file, display, &m);
        scene_add_mesh(scene, &m);
    } else if (rc == 0) {
        log_warn("%s%s: no faces, nothing to render", opt.display_dir ? opt.display_dir : "", file);
    }
    s.pos = NULL;
    s.nrm = s.uv = NULL;
    obj_state_free(&s);
    return rc;
}
