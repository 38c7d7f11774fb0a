/* Scene file (version 1) to flat scene (see scene_json.h, docs/scene-format.md).
 * jansson checks the syntax; this file checks the meaning: every object's keys against a
 * closed list, every value's type and range. jansson keeps no positions, so values are
 * addressed by a path of ordinals (member order in the text, which jansson preserves;
 * duplicates are rejected) and, only when an error is reported, the already valid text
 * is rescanned along that path to find the line:col of the key or value. Errors are
 * reported on first occurrence. Called by the master and by workers. */
#include "scene/scene_json.h"
#include "base/jsonpos.h"
#include "base/log.h"
#include "scene/medium.h"
#include "scene/grid.h"
#include "scene/nvdb.h"
#include "scene/mesh_obj.h"
#include "scene/mesh_ply.h"
#include "scene/motion.h"
#include "scene/sampler.h"
#include "image/image_load.h"
#include "scene/texture.h"
#include "scene/envmap.h"
#include "scene/microfacet.h"
#include <float.h>
#include <jansson.h>
#include <math.h>
#include <stdarg.h>
#include <stdbool.h>
#include <stdio.h>
#include <string.h>

#define JPATH_MAX 16
#define SCENE_VERSION 1

/* Location of a value: ordinal of the member (objects) or element (arrays) per level. */
struct jpath {
    int n;
    uint32_t comp[JPATH_MAX];
};

struct ctx {
    const char *name;
    const char *text;
    size_t len;
    char *err;
    size_t errlen;
    struct scene *scene;
    const struct asset_source *src;
    struct mesh_obj_cache cache;
    uint32_t num_json_materials;  /* materials 0..n-1 are the scene file's, by name */
    char display_dir[1024];
    const double *origin;         /* scene.origin: subtracted from every position read */
    bool origin_given;            /* by the caller: the camera does not set it */
    uint32_t frame;               /* the frame whose files a "#" pattern names */
};

static struct jpath jpath_child(const struct jpath *p, uint32_t ordinal)
{
    struct jpath c = *p;
    CHECK(c.n < JPATH_MAX);
    c.comp[c.n++] = ordinal;
    return c;
}

enum at { AT_VALUE, AT_KEY };

__attribute__((format(printf, 4, 5))) static int fail(struct ctx *c, const struct jpath *p, enum at at,
                                                      const char *fmt, ...)
{
    struct json_step steps[JPATH_MAX];
    for (int i = 0; i < p->n; i++)
        steps[i] = (struct json_step){NULL, p->comp[i]};
    va_list ap;
    va_start(ap, fmt);
    json_error_at(c->err, c->errlen, c->name, c->text, c->len, steps, p->n, at == AT_KEY, fmt, ap);
    va_end(ap);
    return -1;
}

/* A key or name made safe to print inside quotes in a one-line message. */
static const char *printable(const char *in, char *buf, size_t size)
{
    size_t o = 0;
    for (const char *p = in; *p && o + 4 < size; p++)
        buf[o++] = ((unsigned char)*p < 0x20 || *p == 0x7f || *p == '"') ? '?' : *p;
    if (o + 4 >= size && strlen(in) > o) {
        buf[o++] = '.';
        buf[o++] = '.';
        buf[o++] = '.';
    }
    buf[o] = '\0';
    return buf;
}

/* ---- Typed access ---- */

struct member {
    json_t *val;
    struct jpath path;
};

/* Keys that later versions will accept; naming them says so instead of "unknown". */
static const char *const planned_keys[] = {"shutter", "keyframes", "motion"};

/* Checks obj's keys against allowed (a closed list) and fills out[i] for allowed[i]
 * (val NULL when absent). */
static int object_members(struct ctx *c, json_t *obj, const struct jpath *p, const char *what,
                          const char *const *allowed, size_t n_allowed, struct member *out)
{
    if (!json_is_object(obj))
        return fail(c, p, AT_VALUE, "%s must be an object", what);
    for (size_t i = 0; i < n_allowed; i++)
        out[i].val = NULL;
    const char *key;
    json_t *val;
    uint32_t ordinal = 0;
    json_object_foreach(obj, key, val) {
        struct jpath kp = jpath_child(p, ordinal++);
        size_t i = 0;
        while (i < n_allowed && strcmp(key, allowed[i]) != 0)
            i++;
        if (i < n_allowed) {
            out[i].val = val;
            out[i].path = kp;
            continue;
        }
        char kb[80];
        for (size_t k = 0; k < sizeof planned_keys / sizeof *planned_keys; k++)
            if (strcmp(key, planned_keys[k]) == 0)
                return fail(c, &kp, AT_KEY, "key \"%s\" in %s is planned, not yet accepted", key, what);
        char list[512] = "";
        size_t o = 0;
        for (size_t k = 0; k < n_allowed && o < sizeof list; k++)
            o += (size_t)snprintf(list + o, sizeof list - o, "%s%s", k ? ", " : "", allowed[k]);
        return fail(c, &kp, AT_KEY, "unknown key \"%s\" in %s (expected one of: %s)",
                    printable(key, kb, sizeof kb), what, list);
    }
    return 0;
}

static int require(struct ctx *c, const struct member *m, const struct jpath *obj_path, const char *what,
                   const char *key)
{
    if (!m->val)
        return fail(c, obj_path, AT_VALUE, "%s: missing key \"%s\"", what, key);
    return 0;
}

static const char *type_name(const json_t *v)
{
    switch (json_typeof(v)) {
    case JSON_OBJECT: return "an object";
    case JSON_ARRAY: return "an array";
    case JSON_STRING: return "a string";
    case JSON_INTEGER: return "an integer";
    case JSON_REAL: return "a number";
    case JSON_TRUE:
    case JSON_FALSE: return "a boolean";
    case JSON_NULL: return "null";
    }
    return "?";
}

/* A number that fits a float, kept in double (positions and transforms, until the origin
 * is subtracted). */
static int get_double(struct ctx *c, json_t *v, const struct jpath *p, const char *what, double *out)
{
    if (!json_is_number(v))
        return fail(c, p, AT_VALUE, "%s must be a number, not %s", what, type_name(v));
    double d = json_number_value(v);
    if (!(d >= -FLT_MAX && d <= FLT_MAX))
        return fail(c, p, AT_VALUE, "%s is out of range", what);
    *out = d;
    return 0;
}

static int get_float(struct ctx *c, json_t *v, const struct jpath *p, const char *what, float *out)
{
    double d;
    if (get_double(c, v, p, what, &d) != 0)
        return -1;
    *out = (float)d;
    return 0;
}

static int get_uint(struct ctx *c, const struct member *m, const char *what, json_int_t lo, json_int_t hi,
                    json_int_t *out)
{
    if (!json_is_integer(m->val))
        return fail(c, &m->path, AT_VALUE, "%s must be an integer, not %s", what, type_name(m->val));
    json_int_t v = json_integer_value(m->val);
    if (v < lo || v > hi)
        return fail(c, &m->path, AT_VALUE, "%s %lld out of range %lld..%lld", what, (long long)v, (long long)lo,
                    (long long)hi);
    *out = v;
    return 0;
}

static int get_dvec3(struct ctx *c, json_t *v, const struct jpath *p, const char *what, double out[3])
{
    if (!json_is_array(v) || json_array_size(v) != 3)
        return fail(c, p, AT_VALUE, "%s must be an array of 3 numbers", what);
    for (size_t i = 0; i < 3; i++) {
        struct jpath ep = jpath_child(p, (uint32_t)i);
        if (get_double(c, json_array_get(v, i), &ep, what, &out[i]) != 0)
            return -1;
    }
    return 0;
}

/* Directions, sizes and colours. */
static int get_vec3(struct ctx *c, json_t *v, const struct jpath *p, const char *what, vec3 *out)
{
    double d[3];
    if (get_dvec3(c, v, p, what, d) != 0)
        return -1;
    *out = v3((float)d[0], (float)d[1], (float)d[2]);
    return 0;
}

/* p - origin, rounded to float once. */
static vec3 rel_point(const struct ctx *c, const double p[3])
{
    return v3((float)(p[0] - c->origin[0]), (float)(p[1] - c->origin[1]), (float)(p[2] - c->origin[2]));
}

/* A world position: stored relative to the scene's origin (scene.h). */
static int get_point(struct ctx *c, json_t *v, const struct jpath *p, const char *what, vec3 *out)
{
    double d[3];
    if (get_dvec3(c, v, p, what, d) != 0)
        return -1;
    *out = rel_point(c, d);
    return 0;
}

/* Each component of a colour in [lo, hi]; the message points at the component. */
static int check_color(struct ctx *c, const struct member *m, const char *what, float lo, float hi, vec3 col)
{
    float f[3] = {col.x, col.y, col.z};
    for (uint32_t i = 0; i < 3; i++)
        if (!(f[i] >= lo && f[i] <= hi)) {
            struct jpath ep = jpath_child(&m->path, i);
            if (hi == FLT_MAX)
                return fail(c, &ep, AT_VALUE, "%s components must be >= %g", what, (double)lo);
            return fail(c, &ep, AT_VALUE, "%s components must be in [%g, %g]", what, (double)lo, (double)hi);
        }
    return 0;
}

static int get_string(struct ctx *c, const struct member *m, const char *what, const char **out)
{
    if (!json_is_string(m->val))
        return fail(c, &m->path, AT_VALUE, "%s must be a string, not %s", what, type_name(m->val));
    *out = json_string_value(m->val);
    return 0;
}

/* ---- Transforms ---- */

/* Transforms are composed in double (struct dxform, vec.h) and rounded to float once, after
 * the origin is subtracted. */

static int parse_rotation(struct ctx *c, json_t *v, const struct jpath *p, struct dxform *out)
{
    static const char *const keys[] = {"axis", "degrees"};
    struct member m[2];
    if (object_members(c, v, p, "rotate", keys, 2, m) != 0 || require(c, &m[0], p, "rotate", "axis") != 0 ||
        require(c, &m[1], p, "rotate", "degrees") != 0)
        return -1;
    vec3 axis;
    float deg;
    if (get_vec3(c, m[0].val, &m[0].path, "rotate axis", &axis) != 0 ||
        get_float(c, m[1].val, &m[1].path, "rotate degrees", &deg) != 0)
        return -1;
    double x = axis.x, y = axis.y, z = axis.z, l = sqrt(x * x + y * y + z * z);
    if (!(l > 0.0) || !isfinite(l))
        return fail(c, &m[0].path, AT_VALUE, "rotate axis must be a non-zero vector");
    x /= l, y /= l, z /= l;
    double a = (double)deg * (M_PI / 180.0), s = sin(a), co = cos(a), t = 1.0 - co;
    struct dxform r = {{{t * x * x + co, t * x * y - s * z, t * x * z + s * y, 0},
                     {t * x * y + s * z, t * y * y + co, t * y * z - s * x, 0},
                     {t * x * z - s * y, t * y * z + s * x, t * z * z + co, 0}}};
    *out = r;
    return 0;
}

static int parse_transform(struct ctx *c, const struct member *tm, struct dxform *out, double *uniform_scale,
                           bool *uniform)
{
    static const char *const keys[] = {"translate", "rotate", "scale", "matrix"};
    struct member m[4];
    if (object_members(c, tm->val, &tm->path, "transform", keys, 4, m) != 0)
        return -1;
    struct dxform t = dxform_identity();
    if (m[3].val) {
        if (m[0].val || m[1].val || m[2].val)
            return fail(c, &m[3].path, AT_KEY, "matrix cannot be combined with translate, rotate or scale");
        size_t n = json_is_array(m[3].val) ? json_array_size(m[3].val) : 0;
        if (n != 12 && n != 16)
            return fail(c, &m[3].path, AT_VALUE, "matrix must be an array of 12 or 16 numbers (row-major)");
        double f[16];
        for (size_t i = 0; i < n; i++) {
            struct jpath ep = jpath_child(&m[3].path, (uint32_t)i);
            if (get_double(c, json_array_get(m[3].val, i), &ep, "matrix entry", &f[i]) != 0)
                return -1;
        }
        if (n == 16 && !(f[12] == 0 && f[13] == 0 && f[14] == 0 && f[15] == 1))
            return fail(c, &m[3].path, AT_VALUE, "matrix: last row must be 0 0 0 1 (affine transforms only)");
        for (int i = 0; i < 3; i++)
            for (int j = 0; j < 4; j++)
                t.m[i][j] = f[4 * i + j];
    } else {
        if (m[2].val) {
            double sc[3];
            if (json_is_number(m[2].val)) {
                sc[0] = sc[1] = sc[2] = json_number_value(m[2].val);
            } else if (json_is_array(m[2].val) && json_array_size(m[2].val) == 3) {
                vec3 v;
                if (get_vec3(c, m[2].val, &m[2].path, "scale", &v) != 0)
                    return -1;
                sc[0] = v.x, sc[1] = v.y, sc[2] = v.z;
            } else {
                return fail(c, &m[2].path, AT_VALUE, "scale must be a number or an array of 3 numbers");
            }
            for (int i = 0; i < 3; i++) {
                if (!(fabs(sc[i]) > 0.0) || !(fabs(sc[i]) <= FLT_MAX))
                    return fail(c, &m[2].path, AT_VALUE, "scale must be non-zero and finite");
                t.m[i][i] = sc[i];
            }
        }
        if (m[1].val) {
            if (json_is_array(m[1].val)) {
                for (size_t i = 0; i < json_array_size(m[1].val); i++) {
                    struct jpath ep = jpath_child(&m[1].path, (uint32_t)i);
                    struct dxform r;
                    if (parse_rotation(c, json_array_get(m[1].val, i), &ep, &r) != 0)
                        return -1;
                    t = dxform_then(&t, &r);
                }
            } else {
                struct dxform r;
                if (parse_rotation(c, m[1].val, &m[1].path, &r) != 0)
                    return -1;
                t = dxform_then(&t, &r);
            }
        }
        if (m[0].val) {
            double v[3];
            if (get_dvec3(c, m[0].val, &m[0].path, "translate", v) != 0)
                return -1;
            for (int i = 0; i < 3; i++)
                t.m[i][3] += v[i];
        }
    }
    double (*a)[4] = t.m;
    double det = a[0][0] * (a[1][1] * a[2][2] - a[1][2] * a[2][1]) -
                 a[0][1] * (a[1][0] * a[2][2] - a[1][2] * a[2][0]) +
                 a[0][2] * (a[1][0] * a[2][1] - a[1][1] * a[2][0]);
    bool finite = isfinite(det);
    for (int i = 0; i < 3; i++)
        for (int j = 0; j < 4; j++)
            finite = finite && fabs(a[i][j]) <= FLT_MAX;
    if (!finite || det == 0.0)
        return fail(c, &tm->path, AT_VALUE, "transform is singular or not finite");
    /* Uniform scale: the columns are orthogonal and of equal length (rotation * s). */
    double len2[3], maxdot = 0.0;
    for (int j = 0; j < 3; j++)
        len2[j] = a[0][j] * a[0][j] + a[1][j] * a[1][j] + a[2][j] * a[2][j];
    for (int j = 0; j < 3; j++)
        for (int k = j + 1; k < 3; k++)
            maxdot = fmax(maxdot, fabs(a[0][j] * a[0][k] + a[1][j] * a[1][k] + a[2][j] * a[2][k]));
    double mean = (len2[0] + len2[1] + len2[2]) / 3.0, tol = 1e-5 * mean;
    *uniform = fabs(len2[0] - mean) <= tol && fabs(len2[1] - mean) <= tol && fabs(len2[2] - mean) <= tol &&
               maxdot <= tol;
    *uniform_scale = sqrt(mean);
    *out = t;
    return 0;
}

/* ---- Sections ---- */

/* "textures": name -> {type: image | checker, ...}; see docs/scene-format.md. */
static int parse_textures(struct ctx *c, const struct member *tm)
{
    if (!json_is_object(tm->val))
        return fail(c, &tm->path, AT_VALUE, "textures must be an object (name -> texture)");
    enum { K_TYPE, K_FILE, K_FILTER, K_ANISO, K_SCALE, K_OFFSET, K_WRAP, K_SRGB, K_COLOR0, K_COLOR1, K_N };
    static const char *const keys[K_N] = {"type", "file", "filter", "max_anisotropy", "scale", "offset",
                                          "wrap", "srgb", "color0", "color1"};
    const char *name = NULL;
    json_t *def;
    uint32_t ordinal = 0;
    json_object_foreach(tm->val, name, def) {
        struct jpath p = jpath_child(&tm->path, ordinal++);
        char nb[80], what[160], why[1024];
        size_t n = strlen(name);
        if (n == 0 || n >= SCENE_NAME_MAX)
            return fail(c, &p, AT_KEY, "texture name must be 1 to %d bytes long", SCENE_NAME_MAX - 1);
        if (c->scene->num_textures >= 65536)
            return fail(c, &p, AT_KEY, "too many textures (at most 65536)");
        str_fmt(what, sizeof what, "texture \"%s\"", printable(name, nb, sizeof nb));
        struct member m[K_N];
        const char *type = NULL;
        if (object_members(c, def, &p, what, keys, K_N, m) != 0 || require(c, &m[K_TYPE], &p, what, "type") != 0 ||
            get_string(c, &m[K_TYPE], "type", &type) != 0)
            return -1;
        int is_image = strcmp(type, "image") == 0;
        if (!is_image && strcmp(type, "checker") != 0) {
            char tb[80];
            return fail(c, &m[K_TYPE].path, AT_VALUE, "unknown texture type \"%s\" (known: image, checker)",
                        printable(type, tb, sizeof tb));
        }
        static const int image_only[] = {K_FILE, K_WRAP, K_SRGB}, checker_only[] = {K_COLOR0, K_COLOR1};
        for (size_t k = 0; k < 3; k++)
            if (!is_image && m[image_only[k]].val)
                return fail(c, &m[image_only[k]].path, AT_KEY, "key \"%s\" applies to image textures only",
                            keys[image_only[k]]);
        for (size_t k = 0; k < 2; k++)
            if (is_image && m[checker_only[k]].val)
                return fail(c, &m[checker_only[k]].path, AT_KEY, "key \"%s\" applies to checker textures only",
                            keys[checker_only[k]]);
        struct texture t;
        texture_init(&t, is_image ? TEXTURE_IMAGE : TEXTURE_CHECKER, name);
        if (m[K_FILTER].val) {
            const char *f = NULL;
            if (get_string(c, &m[K_FILTER], "filter", &f) != 0)
                return -1;
            if (texture_filter_from_name(f, &t.filter) != 0) {
                char fb[80];
                return fail(c, &m[K_FILTER].path, AT_VALUE,
                            "unknown filter \"%s\" (known: nearest, bilinear, trilinear, ewa)",
                            printable(f, fb, sizeof fb));
            }
        }
        if (m[K_ANISO].val) {
            if (get_float(c, m[K_ANISO].val, &m[K_ANISO].path, "max_anisotropy", &t.max_aniso) != 0)
                return -1;
            if (!(t.max_aniso >= 1.0f && t.max_aniso <= TEXTURE_MAX_ANISO))
                return fail(c, &m[K_ANISO].path, AT_VALUE, "max_anisotropy must be in [1, %g]",
                            (double)TEXTURE_MAX_ANISO);
        }
        const int pair_keys[2] = {K_SCALE, K_OFFSET};
        for (int k = 0; k < 2; k++) {
            const struct member *pm = &m[pair_keys[k]];
            if (!pm->val)
                continue;
            if (!json_is_array(pm->val) || json_array_size(pm->val) != 2)
                return fail(c, &pm->path, AT_VALUE, "%s must be an array of 2 numbers", keys[pair_keys[k]]);
            float *dst = k == 0 ? t.scale : t.offset;
            for (uint32_t i = 0; i < 2; i++) {
                struct jpath ep = jpath_child(&pm->path, i);
                if (get_float(c, json_array_get(pm->val, i), &ep, keys[pair_keys[k]], &dst[i]) != 0)
                    return -1;
                if (k == 0 && !(fabsf(dst[i]) >= 1e-6f && fabsf(dst[i]) <= 1e6f))
                    return fail(c, &ep, AT_VALUE, "scale components must be in [1e-6, 1e6] in magnitude");
                if (k == 1 && !(fabsf(dst[i]) <= 1e6f))
                    return fail(c, &ep, AT_VALUE, "offset components must be in [-1e6, 1e6]");
            }
        }
        if (m[K_COLOR0].val && (get_vec3(c, m[K_COLOR0].val, &m[K_COLOR0].path, "color0", &t.color0) != 0 ||
                                check_color(c, &m[K_COLOR0], "color0", 0.0f, 1.0f, t.color0) != 0))
            return -1;
        if (m[K_COLOR1].val && (get_vec3(c, m[K_COLOR1].val, &m[K_COLOR1].path, "color1", &t.color1) != 0 ||
                                check_color(c, &m[K_COLOR1], "color1", 0.0f, 1.0f, t.color1) != 0))
            return -1;
        if (!is_image) {
            scene_add_texture(c->scene, &t);
            continue;
        }
        if (m[K_WRAP].val) {
            const char *w = NULL;
            if (get_string(c, &m[K_WRAP], "wrap", &w) != 0)
                return -1;
            if (strcmp(w, "repeat") == 0)
                t.wrap = TEXWRAP_REPEAT;
            else if (strcmp(w, "clamp") == 0)
                t.wrap = TEXWRAP_CLAMP;
            else
                return fail(c, &m[K_WRAP].path, AT_VALUE, "wrap must be \"repeat\" or \"clamp\"");
        }
        int srgb = 1;
        if (m[K_SRGB].val) {
            if (!json_is_boolean(m[K_SRGB].val))
                return fail(c, &m[K_SRGB].path, AT_VALUE, "srgb must be true or false, not %s",
                            type_name(m[K_SRGB].val));
            srgb = json_is_true(m[K_SRGB].val);
        }
        const char *file = NULL;
        if (require(c, &m[K_FILE], &p, what, "file") != 0 || get_string(c, &m[K_FILE], "file", &file) != 0)
            return -1;
        if (asset_path_check(file, why, sizeof why) != 0)
            return fail(c, &m[K_FILE].path, AT_VALUE, "file: %s", why);
        if (!c->src || !c->src->read)
            return fail(c, &m[K_FILE].path, AT_VALUE, "cannot read image \"%s\": no asset source", file);
        char display[2048];
        str_fmt(display, sizeof display, "%s%s", c->display_dir, file);
        if (image_load_asset(c->src, file, display, srgb, &t.image, why, sizeof why) != 0)
            return fail(c, &m[K_FILE].path, AT_VALUE, "cannot load image: %s", why);
        scene_add_texture(c->scene, &t);
    }
    return 0;
}

/* The texture named by member m's string into *slot (1 + index). */
static int find_texture(struct ctx *c, const struct member *m, const char *key, uint32_t *slot)
{
    const char *tname = NULL;
    if (get_string(c, m, key, &tname) != 0)
        return -1;
    for (uint32_t t = 0; t < c->scene->num_textures && !*slot; t++)
        if (strcmp(c->scene->textures[t].name, tname) == 0)
            *slot = t + 1;
    if (!*slot) {
        char tb[80];
        return fail(c, &m->path, AT_VALUE, "unknown texture \"%s\" (not in \"textures\")", printable(tname, tb, sizeof tb));
    }
    return 0;
}

/* A roughness in [0, 1] from member m (a number). */
static int get_roughness(struct ctx *c, const struct member *m, const char *key, float *out)
{
    if (get_float(c, m->val, &m->path, key, out) != 0)
        return -1;
    if (!(*out >= 0.0f && *out <= 1.0f))
        return fail(c, &m->path, AT_VALUE, "%s must be in [0, 1]", key);
    return 0;
}

static int parse_materials(struct ctx *c, const struct member *mm)
{
    if (!json_is_object(mm->val))
        return fail(c, &mm->path, AT_VALUE, "materials must be an object (name -> material)");
    /* One closed list for all types; which keys a type takes is checked below. */
    enum { K_TYPE, K_ALBEDO, K_EMISSION, K_REFL, K_IOR, K_TRANS, K_ALBEDO_TEX, K_BUMP_TEX, K_BUMP_SCALE, K_NORMAL_TEX,
           K_ROUGH, K_UROUGH, K_VROUGH, K_ETA, K_K, K_VISIBLE, K_N };
    static const char *const keys[K_N] = {"type", "albedo", "emission", "reflectance", "ior", "transmittance",
                                          "albedo_texture", "bump_texture", "bump_scale", "normal_texture",
                                          "roughness", "uroughness", "vroughness", "eta", "k", "sample_visible"};
    enum { T_DIFFUSE, T_MIRROR, T_DIELECTRIC, T_CONDUCTOR, T_PLASTIC, T_COATED, T_N };
    static const char *const type_names[T_N] = {"diffuse", "mirror", "dielectric", "conductor", "plastic",
                                                "coateddiffuse"};
    static const enum material_type type_of[T_N] = {MATERIAL_DIFFUSE, MATERIAL_MIRROR, MATERIAL_DIELECTRIC,
                                                    MATERIAL_CONDUCTOR, MATERIAL_PLASTIC, MATERIAL_PLASTIC};
    static const char *const type_keys[T_N] = {
        "albedo, albedo_texture",
        "reflectance, roughness, uroughness, vroughness, sample_visible",
        "ior, transmittance, roughness, uroughness, vroughness, sample_visible",
        "eta, k, reflectance, roughness, uroughness, vroughness, sample_visible",
        "albedo, albedo_texture, ior, roughness, uroughness, vroughness, sample_visible",
        "albedo, albedo_texture, ior, roughness, uroughness, vroughness, sample_visible"};
    /* Per key, the material types (bits of enum material_type) it applies to; 0 = any. */
    const unsigned D = 1u << MATERIAL_DIFFUSE, M = 1u << MATERIAL_MIRROR, G = 1u << MATERIAL_DIELECTRIC,
                   C = 1u << MATERIAL_CONDUCTOR, P = 1u << MATERIAL_PLASTIC;
    const unsigned key_types[K_N] = {0, D | P, 0, M | C, G | P, G, D | P, 0, 0, 0,
                                     M | G | C | P, M | G | C | P, M | G | C | P, C, C, M | G | C | P};
    const char *name = NULL;
    json_t *def;
    uint32_t ordinal = 0;
    json_object_foreach(mm->val, name, def) {
        struct jpath p = jpath_child(&mm->path, ordinal++);
        char nb[80];
        size_t n = strlen(name);
        if (n == 0 || n >= SCENE_NAME_MAX)
            return fail(c, &p, AT_KEY, "material name must be 1 to %d bytes long", SCENE_NAME_MAX - 1);
        char what[160];
        str_fmt(what, sizeof what, "material \"%s\"", printable(name, nb, sizeof nb));
        struct member m[K_N];
        const char *type = NULL;
        if (object_members(c, def, &p, what, keys, K_N, m) != 0 || require(c, &m[K_TYPE], &p, what, "type") != 0 ||
            get_string(c, &m[K_TYPE], "type", &type) != 0)
            return -1;
        int ti = 0;
        while (ti < T_N && strcmp(type, type_names[ti]) != 0)
            ti++;
        if (ti == T_N) {
            char tb[80];
            return fail(c, &m[K_TYPE].path, AT_VALUE,
                        "unknown material type \"%s\" (known: diffuse, mirror, dielectric, conductor, plastic, "
                        "coateddiffuse)",
                        printable(type, tb, sizeof tb));
        }
        enum material_type mt = type_of[ti];
        for (int k = 1; k < K_N; k++)
            if (m[k].val && key_types[k] && !(key_types[k] & (1u << mt)))
                return fail(c, &m[k].path, AT_KEY, "key \"%s\" does not apply to a %s material (its keys: %s, emission, "
                            "bump_texture, bump_scale, normal_texture)",
                            keys[k], type_names[ti], type_keys[ti]);
        struct material mat;
        memset(&mat, 0, sizeof mat);
        memcpy(mat.name, name, n + 1);
        mat.type = mt;
        mat.albedo = v3(0.8f, 0.8f, 0.8f);
        mat.emission = v3(0, 0, 0);
        mat.reflectance = v3(1, 1, 1);
        mat.transmittance = v3(1, 1, 1);
        mat.ior = 1.5f;
        /* Copper (pbrt-v4's default conductor, its spectra at 650, 550 and 450 nm). */
        mat.eta = v3(0.200f, 0.924f, 1.102f);
        mat.k = v3(3.912f, 2.452f, 2.142f);
        if (m[K_REFL].val && (get_vec3(c, m[K_REFL].val, &m[K_REFL].path, "reflectance", &mat.reflectance) != 0 ||
                              check_color(c, &m[K_REFL], "reflectance", 0.0f, 1.0f, mat.reflectance) != 0))
            return -1;
        if (mt == MATERIAL_CONDUCTOR) {
            if (m[K_REFL].val && (m[K_ETA].val || m[K_K].val))
                return fail(c, &m[K_REFL].path, AT_KEY, "%s: give \"reflectance\" or \"eta\" and \"k\", not both", what);
            mat.schlick = m[K_REFL].val != NULL;
            if (m[K_ETA].val && (get_vec3(c, m[K_ETA].val, &m[K_ETA].path, "eta", &mat.eta) != 0 ||
                                 check_color(c, &m[K_ETA], "eta", 1e-3f, 100.0f, mat.eta) != 0))
                return -1;
            if (m[K_K].val && (get_vec3(c, m[K_K].val, &m[K_K].path, "k", &mat.k) != 0 ||
                               check_color(c, &m[K_K], "k", 0.0f, 100.0f, mat.k) != 0))
                return -1;
        }
        if (m[K_TRANS].val && (get_vec3(c, m[K_TRANS].val, &m[K_TRANS].path, "transmittance", &mat.transmittance) != 0 ||
                               check_color(c, &m[K_TRANS], "transmittance", 0.0f, 1.0f, mat.transmittance) != 0))
            return -1;
        if (m[K_IOR].val) {
            if (get_float(c, m[K_IOR].val, &m[K_IOR].path, "ior", &mat.ior) != 0)
                return -1;
            if (!(mat.ior >= 1.0f / 16.0f && mat.ior <= 16.0f))
                return fail(c, &m[K_IOR].path, AT_VALUE, "ior must be in [0.0625, 16] (inside / outside)");
        }
        float rough = 0.0f, ur, vr;
        if (m[K_ROUGH].val && json_is_string(m[K_ROUGH].val)) {
            if (m[K_UROUGH].val || m[K_VROUGH].val)
                return fail(c, &m[K_ROUGH].path, AT_VALUE, "%s: a roughness texture excludes uroughness and vroughness", what);
            if (find_texture(c, &m[K_ROUGH], "roughness", &mat.roughness_tex) != 0)
                return -1;
            rough = 1.0f;
        } else if (m[K_ROUGH].val && get_roughness(c, &m[K_ROUGH], "roughness", &rough) != 0) {
            return -1;
        }
        ur = vr = rough;
        if (m[K_UROUGH].val && get_roughness(c, &m[K_UROUGH], "uroughness", &ur) != 0)
            return -1;
        if (m[K_VROUGH].val && get_roughness(c, &m[K_VROUGH], "vroughness", &vr) != 0)
            return -1;
        mat.alpha_x = microfacet_alpha(ur);
        mat.alpha_y = microfacet_alpha(vr);
        if (m[K_VISIBLE].val) {
            if (!json_is_boolean(m[K_VISIBLE].val))
                return fail(c, &m[K_VISIBLE].path, AT_VALUE, "sample_visible must be true or false");
            mat.sample_all = !json_is_true(m[K_VISIBLE].val);
        }
        if (m[K_ALBEDO_TEX].val) { /* a texture's albedo is multiplied by "albedo" (default white) */
            if (find_texture(c, &m[K_ALBEDO_TEX], "albedo_texture", &mat.albedo_tex) != 0)
                return -1;
            mat.albedo = v3(1, 1, 1);
        }
        mat.bump_scale = 1.0f;
        if (m[K_BUMP_TEX].val && find_texture(c, &m[K_BUMP_TEX], "bump_texture", &mat.bump_tex) != 0)
            return -1;
        if (m[K_NORMAL_TEX].val && find_texture(c, &m[K_NORMAL_TEX], "normal_texture", &mat.normal_tex) != 0)
            return -1;
        if (m[K_BUMP_SCALE].val) {
            if (!m[K_BUMP_TEX].val)
                return fail(c, &m[K_BUMP_SCALE].path, AT_KEY, "bump_scale needs \"bump_texture\"");
            if (get_float(c, m[K_BUMP_SCALE].val, &m[K_BUMP_SCALE].path, "bump_scale", &mat.bump_scale) != 0)
                return -1;
            if (!(fabsf(mat.bump_scale) <= 1e6f))
                return fail(c, &m[K_BUMP_SCALE].path, AT_VALUE, "bump_scale must be in [-1e6, 1e6]");
        }
        if (m[K_ALBEDO].val && (get_vec3(c, m[K_ALBEDO].val, &m[K_ALBEDO].path, "albedo", &mat.albedo) != 0 ||
                                check_color(c, &m[K_ALBEDO], "albedo", 0.0f, 1.0f, mat.albedo) != 0))
            return -1;
        if (m[K_EMISSION].val && (get_vec3(c, m[K_EMISSION].val, &m[K_EMISSION].path, "emission", &mat.emission) != 0 ||
                                  check_color(c, &m[K_EMISSION], "emission", 0.0f, FLT_MAX, mat.emission) != 0))
            return -1;
        scene_add_material(c->scene, &mat);
        c->num_json_materials++;
    }
    return 0;
}

static int find_material(struct ctx *c, const struct member *m, uint32_t *id)
{
    const char *name = NULL;
    if (get_string(c, m, "material", &name) != 0)
        return -1;
    for (uint32_t i = 0; i < c->num_json_materials; i++)
        if (strcmp(c->scene->materials[i].name, name) == 0) {
            *id = i;
            return 0;
        }
    char nb[80];
    return fail(c, &m->path, AT_VALUE, "unknown material \"%s\" (not in \"materials\")",
                printable(name, nb, sizeof nb));
}

/* ---- Media ---- */

/* "density": {"file", "scale"?, "transform"?, "grid"?}: a dense grid filling the unit cube,
 * which the transform places in the world, or a NanoVDB file (chosen by its magic, not its
 * name), whose own index-to-world map comes first and the transform after it. */
static int parse_density(struct ctx *c, const struct member *dm, struct density_grid **out)
{
    static const char *const keys[] = {"file", "scale", "transform", "grid"};
    struct member m[4];
    if (object_members(c, dm->val, &dm->path, "density", keys, 4, m) != 0 ||
        require(c, &m[0], &dm->path, "density", "file") != 0)
        return -1;
    const char *file = NULL, *grid_name = NULL;
    char why[1024];
    if (get_string(c, &m[0], "file", &file) != 0)
        return -1;
    if (asset_path_check(file, why, sizeof why) != 0)
        return fail(c, &m[0].path, AT_VALUE, "file: %s", why);
    /* A run of '#' names one grid per frame: this frame's (asset_frame_name). */
    char frame_file[ASSET_PATH_MAX];
    int per_frame = asset_frame_name(file, c->frame, frame_file, sizeof frame_file);
    if (per_frame < 0)
        return fail(c, &m[0].path, AT_VALUE, "file: the name of frame %u's grid is too long", c->frame);
    if (per_frame) {
        struct scene *sc = c->scene;
        sc->frame_patterns = mem_realloc(sc->frame_patterns, (sc->frame_files + 1) * sizeof *sc->frame_patterns);
        sc->frame_patterns[sc->frame_files++] = mem_strdup(file);
        file = frame_file;
    }
    float scale = 1.0f;
    if (m[1].val) {
        if (get_float(c, m[1].val, &m[1].path, "scale", &scale) != 0)
            return -1;
        if (!(scale >= 0.0f && scale <= 1e30f))
            return fail(c, &m[1].path, AT_VALUE, "scale must be in [0, 1e30]");
    }
    struct dxform t = dxform_identity();
    if (m[2].val) {
        double us;
        bool uniform;
        if (parse_transform(c, &m[2], &t, &us, &uniform) != 0)
            return -1;
    }
    if (m[3].val) {
        if (get_string(c, &m[3], "grid", &grid_name) != 0)
            return -1;
        if (grid_name[0] == '\0')
            return fail(c, &m[3].path, AT_VALUE, "grid must name a grid of the NanoVDB file");
    }
    char *data = NULL;
    size_t size = 0;
    if (!c->src || !c->src->read)
        return fail(c, &m[0].path, AT_VALUE, "cannot read grid \"%s\": no asset source", file);
    if (c->src->read(c->src->ctx, file, &data, &size, why, sizeof why) != 0) {
        if (per_frame)
            return fail(c, &m[0].path, AT_VALUE, "cannot read frame %u's grid \"%s\": %s", c->frame, file, why);
        return fail(c, &m[0].path, AT_VALUE, "cannot read grid: %s", why);
    }
    struct density_grid *g = mem_calloc(1, sizeof *g);
    const uint8_t *bytes = (const uint8_t *)data;
    int rc;
    struct xform tw; /* grid to the render frame */
    if (nvdb_is_nvdb(bytes, size)) {
        struct xform file_to_world;
        uint64_t negatives;
        rc = nvdb_parse(bytes, size, grid_name, g, &file_to_world, &negatives, why, sizeof why);
        if (rc == 0) {
            struct dxform fw = dxform_from_float(&file_to_world);
            t = dxform_then(&fw, &t);
            struct dxform tr = dxform_minus_origin(&t, c->origin);
            tw = dxform_to_float(&tr);
            double det = (double)tw.m[0][0] * ((double)tw.m[1][1] * tw.m[2][2] - (double)tw.m[1][2] * tw.m[2][1]) -
                         (double)tw.m[0][1] * ((double)tw.m[1][0] * tw.m[2][2] - (double)tw.m[1][2] * tw.m[2][0]) +
                         (double)tw.m[0][2] * ((double)tw.m[1][0] * tw.m[2][1] - (double)tw.m[1][1] * tw.m[2][0]);
            bool finite = isfinite(det) && det != 0.0;
            for (int i = 0; i < 3; i++)
                for (int j = 0; j < 4; j++)
                    finite = finite && isfinite(tw.m[i][j]);
            if (!finite) {
                str_fmt(why, sizeof why, "the grid's map and the transform together are singular or not finite");
                rc = -1;
            }
        }
    } else {
        if (grid_name) {
            free(data);
            free(g);
            return fail(c, &m[3].path, AT_KEY, "grid: \"%s\" is not a NanoVDB file (only those hold named grids)", file);
        }
        rc = grid_parse(bytes, size, g, why, sizeof why);
        struct dxform tr = dxform_minus_origin(&t, c->origin);
        tw = dxform_to_float(&tr);
    }
    free(data);
    if (rc != 0) {
        grid_free(&g);
        return fail(c, &m[0].path, AT_VALUE, "grid \"%s\": %s", file, why);
    }
    grid_finish(g, &tw, scale);
    *out = g;
    return 0;
}

static int parse_media(struct ctx *c, const struct member *mm)
{
    if (!json_is_object(mm->val))
        return fail(c, &mm->path, AT_VALUE, "media must be an object (name -> medium)");
    if (json_object_size(mm->val) > MEDIA_MAX)
        return fail(c, &mm->path, AT_VALUE, "at most %d media", MEDIA_MAX);
    c->scene->media = media_scene_new();
    struct scene_media *sm = c->scene->media;
    sm->media = mem_calloc(json_object_size(mm->val) + 1, sizeof *sm->media);
    static const char *const keys[] = {"sigma_a", "sigma_s", "emission", "g", "density"};
    const char *name;
    json_t *def;
    uint32_t ordinal = 0;
    json_object_foreach(mm->val, name, def) {
        struct jpath p = jpath_child(&mm->path, ordinal++);
        size_t n = strlen(name);
        if (n == 0 || n >= SCENE_NAME_MAX)
            return fail(c, &p, AT_KEY, "medium name must be 1 to %d bytes long", SCENE_NAME_MAX - 1);
        char nb[80], what[160];
        str_fmt(what, sizeof what, "medium \"%s\"", printable(name, nb, sizeof nb));
        struct member m[5];
        if (object_members(c, def, &p, what, keys, 5, m) != 0)
            return -1;
        struct medium md;
        memset(&md, 0, sizeof md);
        memcpy(md.name, name, n + 1);
        vec3 *dst[3] = {&md.sigma_a, &md.sigma_s, &md.emission};
        for (int k = 0; k < 3; k++)
            if (m[k].val && (get_vec3(c, m[k].val, &m[k].path, keys[k], dst[k]) != 0 ||
                             check_color(c, &m[k], keys[k], 0.0f, 1e30f, *dst[k]) != 0))
                return -1;
        if (m[3].val) {
            if (get_float(c, m[3].val, &m[3].path, "g", &md.g) != 0)
                return -1;
            if (!(md.g > -1.0f && md.g < 1.0f))
                return fail(c, &m[3].path, AT_VALUE, "g must be in (-1, 1)");
        }
        md.sigma_t = v3_add(md.sigma_a, md.sigma_s);
        if (m[4].val && parse_density(c, &m[4], &md.grid) != 0)
            return -1;
        sm->media[sm->num_media++] = md;
    }
    return 0;
}

static int find_medium(struct ctx *c, const struct member *m, uint32_t *id)
{
    const char *name = NULL;
    if (get_string(c, m, "medium", &name) != 0)
        return -1;
    const struct scene_media *sm = c->scene->media;
    for (uint32_t i = 0; sm && i < sm->num_media; i++)
        if (strcmp(sm->media[i].name, name) == 0) {
            *id = i;
            return 0;
        }
    char nb[80];
    return fail(c, &m->path, AT_VALUE, "unknown medium \"%s\" (not in \"media\")", printable(name, nb, sizeof nb));
}

/* The invisible boundary of a medium object: an index-matched dielectric (ior 1, no tint),
 * which the media integrator crosses without counting a bounce. Made once per scene. */
static uint32_t interface_material(struct ctx *c)
{
    struct scene_media *sm = c->scene->media;
    if (sm->interface_material == UINT32_MAX) {
        struct material mat;
        memset(&mat, 0, sizeof mat);
        str_fmt(mat.name, sizeof mat.name, "@medium boundary");
        mat.type = MATERIAL_DIELECTRIC;
        mat.ior = 1.0f;
        mat.transmittance = v3(1, 1, 1);
        mat.reflectance = v3(1, 1, 1);
        sm->interface_material = scene_add_material(c->scene, &mat);
    }
    return sm->interface_material;
}

static int parse_volume(struct ctx *c, const struct member *vm)
{
    static const char *const keys[] = {"method", "fog", "step", "photons", "radius", "skip_bound", "max_photon_depth",
                                       "knn", "shadow_cache", "surface_photons", "alpha", "indirect",
                                       "direct_samples", "photon_split"};
    struct member m[14];
    if (object_members(c, vm->val, &vm->path, "volume", keys, 14, m) != 0)
        return -1;
    struct scene_media *sm = c->scene->media;
    if (m[0].val) {
        const char *name = NULL;
        if (get_string(c, &m[0], "method", &name) != 0)
            return -1;
        if (media_method_from_name(name, &sm->method) != 0)
            return fail(c, &m[0].path, AT_VALUE, "method must be \"vpt\", \"march\", \"beam\" or \"beams\"");
    }
    if (m[1].val && find_medium(c, &m[1], &sm->fog) != 0)
        return -1;
    float f;
    if (m[2].val) {
        if (get_float(c, m[2].val, &m[2].path, "step", &f) != 0)
            return -1;
        if (!(f > 0.0f))
            return fail(c, &m[2].path, AT_VALUE, "step must be > 0 (scene units)");
        sm->step = f;
    }
    if (m[3].val) {
        json_int_t n;
        if (get_uint(c, &m[3], "photons", 0, (json_int_t)1 << 32, &n) != 0)
            return -1;
        sm->photons = (uint64_t)n;
    }
    if (m[4].val) {
        if (get_float(c, m[4].val, &m[4].path, "radius", &f) != 0)
            return -1;
        if (!(f > 0.0f))
            return fail(c, &m[4].path, AT_VALUE, "radius must be > 0 (scene units)");
        sm->radius = f;
    }
    if (m[5].val) {
        if (get_float(c, m[5].val, &m[5].path, "skip_bound", &f) != 0)
            return -1;
        if (!(f >= 0.0f && f <= 1.0f))
            return fail(c, &m[5].path, AT_VALUE, "skip_bound must be in [0, 1]");
        sm->skip_bound = f;
    }
    if (m[6].val) {
        json_int_t n;
        if (get_uint(c, &m[6], "max_photon_depth", 1, 1024, &n) != 0)
            return -1;
        sm->max_photon_depth = (uint32_t)n;
    }
    if (m[7].val) {
        json_int_t n;
        if (get_uint(c, &m[7], "knn", 1, 1024, &n) != 0)
            return -1;
        sm->knn = (uint32_t)n;
    }
    if (m[8].val) {
        if (!json_is_boolean(m[8].val))
            return fail(c, &m[8].path, AT_VALUE, "shadow_cache must be true or false");
        sm->shadow_cache = json_is_true(m[8].val);
    }
    if (m[9].val) {
        if (!json_is_boolean(m[9].val))
            return fail(c, &m[9].path, AT_VALUE, "surface_photons must be true or false");
        sm->surface_photons = json_is_true(m[9].val);
    }
    if (m[10].val) {
        if (get_float(c, m[10].val, &m[10].path, "alpha", &f) != 0)
            return -1;
        if (!(f > 0.0f && f <= 1.0f))
            return fail(c, &m[10].path, AT_VALUE, "alpha must be in (0, 1]");
        sm->alpha = f;
    }
    if (m[11].val) {
        const char *name = NULL;
        if (get_string(c, &m[11], "indirect", &name) != 0)
            return -1;
        if (media_indirect_from_name(name, &sm->indirect) != 0)
            return fail(c, &m[11].path, AT_VALUE, "indirect must be \"gather\" or \"path\"");
    }
    if (m[12].val) {
        json_int_t n;
        if (get_uint(c, &m[12], "direct_samples", 1, MEDIA_MAX_DIRECT_SAMPLES, &n) != 0)
            return -1;
        sm->direct_samples = (uint32_t)n;
    }
    if (m[13].val) {
        json_int_t n;
        if (get_uint(c, &m[13], "photon_split", 1, MEDIA_MAX_PHOTON_SPLIT, &n) != 0)
            return -1;
        sm->photon_split = (uint32_t)n;
    }
    return 0;
}

/* A direction given as the difference of two points: non-zero and of finite length, at
 * any scale (v3_length_rescaled: points 1e20 apart are fine). */
static int direction_ok(vec3 d)
{
    float l = v3_length_rescaled(d);
    return l > 0.0f && isfinite(l);
}

/* One camera keyframe: {time, position, look_at, up?}. */
static int parse_camera_key(struct ctx *c, json_t *obj, const struct jpath *p, struct camera_keyframe *k)
{
    static const char *const keys[] = {"time", "position", "look_at", "up"};
    struct member m[4];
    if (object_members(c, obj, p, "camera keyframe", keys, 4, m) != 0)
        return -1;
    for (int i = 0; i < 3; i++)
        if (require(c, &m[i], p, "camera keyframe", keys[i]) != 0)
            return -1;
    k->up = v3(0, 1, 0);
    if (get_float(c, m[0].val, &m[0].path, "time", &k->time) != 0 ||
        get_point(c, m[1].val, &m[1].path, "position", &k->position) != 0 ||
        get_point(c, m[2].val, &m[2].path, "look_at", &k->look_at) != 0 ||
        (m[3].val && get_vec3(c, m[3].val, &m[3].path, "up", &k->up) != 0))
        return -1;
    if (!(fabsf(k->time) <= 1e7f))
        return fail(c, &m[0].path, AT_VALUE, "time must be within +-1e7 frames");
    vec3 fwd = v3_sub(k->look_at, k->position);
    if (!direction_ok(fwd))
        return fail(c, &m[2].path, AT_VALUE, "look_at must differ from position");
    if (!(v3_length(v3_cross(v3_normalize(fwd), v3_normalize(k->up))) > 1e-6f))
        return fail(c, m[3].val ? &m[3].path : p, AT_VALUE, "up must not be zero or parallel to the view direction");
    return 0;
}

static int parse_camera(struct ctx *c, const struct member *cm)
{
    enum { POS, LOOK, UP, FOV, APERTURE, FOCUS_DIST, F_NUMBER, FOCAL_MM, FOCUS_POINT, BLADES, BLADE_ROT, S_OPEN,
           S_CLOSE, S_CURVE, S_RAMP, KEYS, MBLUR, NKEYS };
    static const char *const keys[NKEYS] = {"position", "look_at", "up", "fov_y", "aperture", "focus_distance",
                                            "f_number", "focal_length_mm", "focus_point", "blades",
                                            "blade_rotation", "shutter_open", "shutter_close", "shutter_curve",
                                            "shutter_ramp", "keyframes", "motion_blur"};
    struct member m[NKEYS];
    if (object_members(c, cm->val, &cm->path, "camera", keys, NKEYS, m) != 0)
        return -1;
    struct camera_desc *cd = &c->scene->camera;
    /* Keyframes define the camera's path: position / look_at / up then come from them. */
    if (m[KEYS].val) {
        for (int i = POS; i <= UP; i++)
            if (m[i].val)
                return fail(c, &m[i].path, AT_KEY, "camera: \"%s\" conflicts with \"keyframes\" (give it per key)",
                            keys[i]);
        if (!json_is_array(m[KEYS].val) || json_array_size(m[KEYS].val) < 1 ||
            json_array_size(m[KEYS].val) > CAMERA_MAX_KEYFRAMES)
            return fail(c, &m[KEYS].path, AT_VALUE, "keyframes must be an array of 1..%d objects",
                        CAMERA_MAX_KEYFRAMES);
        cd->num_keyframes = (uint32_t)json_array_size(m[KEYS].val);
        for (uint32_t i = 0; i < cd->num_keyframes; i++) {
            struct jpath kp = jpath_child(&m[KEYS].path, i);
            if (parse_camera_key(c, json_array_get(m[KEYS].val, i), &kp, &cd->keyframes[i]) != 0)
                return -1;
            if (i > 0 && !(cd->keyframes[i].time > cd->keyframes[i - 1].time))
                return fail(c, &kp, AT_VALUE, "keyframe times must increase");
        }
        cd->position = cd->keyframes[0].position;
        cd->look_at = cd->keyframes[0].look_at;
        cd->up = cd->keyframes[0].up;
        if (require(c, &m[FOV], &cm->path, "camera", keys[FOV]) != 0 ||
            get_float(c, m[FOV].val, &m[FOV].path, "fov_y", &cd->fov_y_deg) != 0)
            return -1;
    } else {
        for (int i = 0; i < 4; i++)
            if (i != UP && require(c, &m[i], &cm->path, "camera", keys[i]) != 0)
                return -1;
        cd->up = v3(0, 1, 0);
        if (get_point(c, m[POS].val, &m[POS].path, "position", &cd->position) != 0 ||
            get_point(c, m[LOOK].val, &m[LOOK].path, "look_at", &cd->look_at) != 0 ||
            (m[UP].val && get_vec3(c, m[UP].val, &m[UP].path, "up", &cd->up) != 0) ||
            get_float(c, m[FOV].val, &m[FOV].path, "fov_y", &cd->fov_y_deg) != 0)
            return -1;
    }
    if (!(cd->fov_y_deg > 0.0f && cd->fov_y_deg < 180.0f))
        return fail(c, &m[FOV].path, AT_VALUE, "fov_y must be in (0, 180) degrees");
    vec3 fwd = v3_sub(cd->look_at, cd->position);
    if (!direction_ok(fwd))
        return fail(c, &m[LOOK].path, AT_VALUE, "look_at must differ from position");
    float cross = v3_length(v3_cross(v3_normalize(fwd), v3_normalize(cd->up)));
    if (!(cross > 1e-6f))
        return fail(c, m[UP].val ? &m[UP].path : &cm->path, AT_VALUE,
                    "up must not be zero or parallel to the view direction");
    /* Lens: a radius, or an f-number with a focal length (scene units taken as metres). */
    if (m[APERTURE].val && m[F_NUMBER].val)
        return fail(c, &m[F_NUMBER].path, AT_KEY, "give either \"aperture\" or \"f_number\", not both");
    if (m[APERTURE].val) {
        if (get_float(c, m[APERTURE].val, &m[APERTURE].path, "aperture", &cd->aperture_radius) != 0)
            return -1;
        if (!(cd->aperture_radius >= 0.0f && cd->aperture_radius <= 1e6f))
            return fail(c, &m[APERTURE].path, AT_VALUE, "aperture must be in [0, 1e6] (lens radius, scene units)");
    }
    if (m[FOCAL_MM].val && !m[F_NUMBER].val)
        return fail(c, &m[FOCAL_MM].path, AT_KEY, "focal_length_mm is only used with f_number");
    if (m[F_NUMBER].val) {
        float fn, fl;
        if (require(c, &m[FOCAL_MM], &cm->path, "camera (with f_number)", "focal_length_mm") != 0 ||
            get_float(c, m[F_NUMBER].val, &m[F_NUMBER].path, "f_number", &fn) != 0 ||
            get_float(c, m[FOCAL_MM].val, &m[FOCAL_MM].path, "focal_length_mm", &fl) != 0)
            return -1;
        if (!(fn >= 0.1f && fn <= 1e6f))
            return fail(c, &m[F_NUMBER].path, AT_VALUE, "f_number must be in [0.1, 1e6]");
        if (!(fl > 0.0f && fl <= 1e6f))
            return fail(c, &m[FOCAL_MM].path, AT_VALUE, "focal_length_mm must be in (0, 1e6]");
        cd->aperture_radius = (float)((double)fl * 1e-3 / (2.0 * fn));
    }
    if (m[FOCUS_DIST].val && m[FOCUS_POINT].val)
        return fail(c, &m[FOCUS_POINT].path, AT_KEY, "give either \"focus_distance\" or \"focus_point\", not both");
    if (m[FOCUS_DIST].val) {
        if (get_float(c, m[FOCUS_DIST].val, &m[FOCUS_DIST].path, "focus_distance", &cd->focus_distance) != 0)
            return -1;
        if (!(cd->focus_distance >= 0.0f && cd->focus_distance <= 1e12f))
            return fail(c, &m[FOCUS_DIST].path, AT_VALUE,
                        "focus_distance must be in [0, 1e12] (0 = distance to look_at)");
    }
    if (m[FOCUS_POINT].val) {
        if (get_point(c, m[FOCUS_POINT].val, &m[FOCUS_POINT].path, "focus_point", &cd->focus_point) != 0)
            return -1;
        cd->has_focus_point = 1;
    }
    if (m[BLADES].val) {
        json_int_t b;
        if (get_uint(c, &m[BLADES], "blades", 3, CAMERA_MAX_BLADES, &b) != 0)
            return -1;
        cd->blades = (uint32_t)b;
    }
    if (m[BLADE_ROT].val) {
        if (!m[BLADES].val)
            return fail(c, &m[BLADE_ROT].path, AT_KEY, "blade_rotation needs \"blades\"");
        if (get_float(c, m[BLADE_ROT].val, &m[BLADE_ROT].path, "blade_rotation", &cd->blade_rotation_deg) != 0)
            return -1;
        if (!(fabsf(cd->blade_rotation_deg) <= 360.0f))
            return fail(c, &m[BLADE_ROT].path, AT_VALUE, "blade_rotation must be in [-360, 360] degrees");
    }
    /* Shutter, in frames relative to the frame's time. */
    if ((m[S_OPEN].val && get_float(c, m[S_OPEN].val, &m[S_OPEN].path, "shutter_open", &cd->shutter_open) != 0) ||
        (m[S_CLOSE].val && get_float(c, m[S_CLOSE].val, &m[S_CLOSE].path, "shutter_close", &cd->shutter_close) != 0))
        return -1;
    if (m[S_OPEN].val && !m[S_CLOSE].val)
        cd->shutter_close = cd->shutter_open;
    if (!(fabsf(cd->shutter_open) <= 1e6f && fabsf(cd->shutter_close) <= 1e6f))
        return fail(c, m[S_OPEN].val ? &m[S_OPEN].path : &m[S_CLOSE].path, AT_VALUE,
                    "shutter_open / shutter_close must be within +-1e6 frames");
    if (!(cd->shutter_close >= cd->shutter_open))
        return fail(c, m[S_CLOSE].val ? &m[S_CLOSE].path : &m[S_OPEN].path, AT_VALUE,
                    "shutter_close must be >= shutter_open");
    int trapezoid = 0;
    if (m[S_CURVE].val) {
        const char *curve = NULL;
        if (get_string(c, &m[S_CURVE], "shutter_curve", &curve) != 0)
            return -1;
        if (strcmp(curve, "trapezoid") == 0)
            trapezoid = 1;
        else if (strcmp(curve, "box") != 0)
            return fail(c, &m[S_CURVE].path, AT_VALUE, "shutter_curve must be \"box\" or \"trapezoid\"");
    }
    cd->shutter_ramp = trapezoid ? 0.25f : 0.0f;
    if (m[S_RAMP].val) {
        if (!trapezoid)
            return fail(c, &m[S_RAMP].path, AT_KEY, "shutter_ramp needs \"shutter_curve\": \"trapezoid\"");
        if (get_float(c, m[S_RAMP].val, &m[S_RAMP].path, "shutter_ramp", &cd->shutter_ramp) != 0)
            return -1;
        if (!(cd->shutter_ramp >= 0.0f && cd->shutter_ramp <= 0.5f))
            return fail(c, &m[S_RAMP].path, AT_VALUE, "shutter_ramp must be in [0, 0.5]");
    }
    cd->motion_blur = MOTION_BLUR_SAMPLED;
    if (m[MBLUR].val) {
        const char *mb = NULL;
        if (get_string(c, &m[MBLUR], "motion_blur", &mb) != 0)
            return -1;
        if (strcmp(mb, "analytic") == 0)
            cd->motion_blur = MOTION_BLUR_ANALYTIC;
        else if (strcmp(mb, "sampled") != 0)
            return fail(c, &m[MBLUR].path, AT_VALUE, "motion_blur must be \"analytic\" or \"sampled\"");
    }
    return 0;
}

const char *const scene_aov_names[AOV_COUNT_] = {"Z", "N", "albedo", "P", "id.object", "id.material"};
static const char *const filter_names[FILTER_COUNT_] = {"box", "gaussian", "blackman-harris"};

/* Index of name in names[0..n-1], or -1. */
static int name_index(const char *const *names, int n, const char *name)
{
    for (int i = 0; i < n; i++)
        if (!strcmp(name, names[i]))
            return i;
    return -1;
}

/* The first n bytes of s as a name of at most outlen - 1 bytes; -1 when empty or longer. */
static int name_copy(const char *s, size_t n, char *out, size_t outlen)
{
    if (n == 0 || n >= outlen)
        return -1;
    memcpy(out, s, n);
    out[n] = '\0';
    return 0;
}

int scene_aov_from_name(const char *name) { return name_index(scene_aov_names, AOV_COUNT_, name); }

int scene_aovs_from_list(const char *list, uint32_t *aovs)
{
    *aovs = 0;
    if (!strcmp(list, "all")) {
        *aovs = AOV_ALL;
        return 0;
    }
    while (*list) {
        size_t n = strcspn(list, ",");
        char name[32];
        if (name_copy(list, n, name, sizeof name) != 0)
            return -1;
        int a = scene_aov_from_name(name);
        if (a < 0)
            return -1;
        *aovs |= 1u << a;
        list += n + (list[n] == ',');
    }
    return 0;
}

int scene_filter_from_name(const char *name) { return name_index(filter_names, FILTER_COUNT_, name); }

int scene_filter_from_spec(const char *spec, uint32_t *filter, float *width)
{
    char name[32];
    size_t n = strcspn(spec, ":");
    if (name_copy(spec, n, name, sizeof name) != 0)
        return -1;
    int f = scene_filter_from_name(name);
    if (f < 0)
        return -1;
    *filter = (uint32_t)f;
    *width = f == FILTER_BOX ? 1.0f : SCENE_FILTER_DEFAULT_WIDTH;
    if (spec[n] == ':') {
        char *end;
        double w = strtod(spec + n + 1, &end);
        if (f == FILTER_BOX || end == spec + n + 1 || *end || !(w >= SCENE_FILTER_MIN_WIDTH) ||
            !(w <= SCENE_FILTER_MAX_WIDTH))
            return -1;
        *width = (float)w;
    }
    return 0;
}

/* render.aovs: a list of AOV names. */
static int parse_aovs(struct ctx *c, const struct member *am, uint32_t *aovs)
{
    *aovs = 0;
    if (!json_is_array(am->val))
        return fail(c, &am->path, AT_VALUE, "aovs must be an array of AOV names");
    for (size_t i = 0; i < json_array_size(am->val); i++) {
        struct member e = {json_array_get(am->val, i), jpath_child(&am->path, (uint32_t)i)};
        const char *name = NULL;
        if (get_string(c, &e, "an AOV", &name) != 0)
            return -1;
        int a = scene_aov_from_name(name);
        if (a < 0)
            return fail(c, &e.path, AT_VALUE,
                        "unknown AOV \"%s\" (Z, N, albedo, P, id.object or id.material)", name);
        *aovs |= 1u << a;
    }
    return 0;
}

/* render.filter: {"type": "box" | "gaussian" | "blackman-harris", "width": pixels}. */
static int parse_filter(struct ctx *c, const struct member *fm, struct camera_desc *cd)
{
    static const char *const keys[] = {"type", "width"};
    struct member m[2];
    const char *name = NULL;
    if (object_members(c, fm->val, &fm->path, "filter", keys, 2, m) != 0 ||
        require(c, &m[0], &fm->path, "filter", "type") != 0 || get_string(c, &m[0], "filter type", &name) != 0)
        return -1;
    int f = scene_filter_from_name(name);
    if (f < 0)
        return fail(c, &m[0].path, AT_VALUE, "unknown filter \"%s\" (box, gaussian or blackman-harris)", name);
    cd->filter = (uint32_t)f;
    cd->filter_width = f == FILTER_BOX ? 1.0f : SCENE_FILTER_DEFAULT_WIDTH;
    if (m[1].val) {
        if (f == FILTER_BOX)
            return fail(c, &m[1].path, AT_VALUE, "the box filter is one pixel wide: it takes no width");
        if (get_float(c, m[1].val, &m[1].path, "filter width", &cd->filter_width) != 0)
            return -1;
        if (!(cd->filter_width >= SCENE_FILTER_MIN_WIDTH && cd->filter_width <= SCENE_FILTER_MAX_WIDTH))
            return fail(c, &m[1].path, AT_VALUE, "filter width must be in [%g, %g] pixels",
                        (double)SCENE_FILTER_MIN_WIDTH, (double)SCENE_FILTER_MAX_WIDTH);
    }
    return 0;
}

static int parse_render(struct ctx *c, const struct member *rm)
{
    static const char *const keys[] = {"width", "height", "spp", "max_depth", "seed", "tile_size", "sampler",
                                       "passes", "target_error", "time_limit", "aovs", "filter", "pixel_error"};
    struct member m[13];
    if (object_members(c, rm->val, &rm->path, "render", keys, 13, m) != 0 ||
        require(c, &m[0], &rm->path, "render", "width") != 0 ||
        require(c, &m[1], &rm->path, "render", "height") != 0)
        return -1;
    struct render_settings *r = &c->scene->settings;
    json_int_t v[6] = {0, 0, 16, 8, 0, 32};  /* defaults of the optional ones */
    const json_int_t lo[6] = {1, 1, 1, 1, 0, 8};
    const json_int_t hi[6] = {SCENE_MAX_DIM, SCENE_MAX_DIM, SCENE_MAX_SPP, SCENE_MAX_DEPTH, INT64_MAX, 1024};
    for (int i = 0; i < 6; i++)
        if (m[i].val && get_uint(c, &m[i], keys[i], lo[i], hi[i], &v[i]) != 0)
            return -1;
    r->width = (uint32_t)v[0];
    r->height = (uint32_t)v[1];
    r->spp = (uint32_t)v[2];
    r->max_depth = (uint32_t)v[3];
    r->seed = (uint64_t)v[4];
    r->tile_size = (uint32_t)v[5];
    r->sampler = SCENE_DEFAULT_SAMPLER;
    if (m[6].val) {
        const char *name = NULL;
        if (get_string(c, &m[6], "sampler", &name) != 0)
            return -1;
        if (sampler_type_from_name(name, &r->sampler) != 0)
            return fail(c, &m[6].path, AT_VALUE, "sampler must be \"independent\", \"stratified\" or \"sobol\"");
    }
    r->passes = 0;
    if (m[7].val) {
        json_int_t n;
        if (get_uint(c, &m[7], "passes", 1, SCENE_MAX_PASSES, &n) != 0)
            return -1;
        r->passes = (uint32_t)n;
    }
    /* Adaptive rendering (docs/adaptive.md): a target relRMSE and a per-pixel bound in (0, 1),
     * a time limit in s. */
    r->target_error = 0.0f;
    r->time_limit = 0.0f;
    if (m[8].val && get_float(c, m[8].val, &m[8].path, "target_error", &r->target_error) != 0)
        return -1;
    if (m[8].val && !(r->target_error > 0.0f && r->target_error < 1.0f))
        return fail(c, &m[8].path, AT_VALUE, "target_error must be in (0, 1)");
    r->pixel_error = 0.0f;
    if (m[12].val && get_float(c, m[12].val, &m[12].path, "pixel_error", &r->pixel_error) != 0)
        return -1;
    if (m[12].val && !(r->pixel_error > 0.0f && r->pixel_error < 1.0f))
        return fail(c, &m[12].path, AT_VALUE, "pixel_error must be in (0, 1)");
    if (m[9].val && get_float(c, m[9].val, &m[9].path, "time_limit", &r->time_limit) != 0)
        return -1;
    if (m[9].val && !(r->time_limit > 0.0f && r->time_limit < 1e9f))
        return fail(c, &m[9].path, AT_VALUE, "time_limit must be seconds > 0");
    r->aovs = 0;
    if (m[10].val && parse_aovs(c, &m[10], &r->aovs) != 0)
        return -1;
    c->scene->camera.filter = FILTER_BOX;
    c->scene->camera.filter_width = 1.0f;
    if (m[11].val && parse_filter(c, &m[11], &c->scene->camera) != 0)
        return -1;
    return 0;
}

/* Finds "type" among an object's members (its ordinal is needed for messages). */
static int object_type(struct ctx *c, json_t *obj, const struct jpath *p, const char *what, struct member *out,
                       const char **type)
{
    if (!json_is_object(obj))
        return fail(c, p, AT_VALUE, "%s must be an object", what);
    const char *key;
    json_t *val;
    uint32_t ordinal = 0;
    json_object_foreach(obj, key, val) {
        if (strcmp(key, "type") == 0) {
            out->val = val;
            out->path = jpath_child(p, ordinal);
            return get_string(c, out, "type", type);
        }
        ordinal++;
    }
    return fail(c, p, AT_VALUE, "%s: missing key \"type\"", what);
}

/* ---- Motion ---- */

#define MAX_KEYFRAMES 4096

/* Hamilton product a * b: the rotation b, then a. */
static void quat_mul(const double a[4], const double b[4], double out[4])
{
    out[0] = a[0] * b[0] - a[1] * b[1] - a[2] * b[2] - a[3] * b[3];
    out[1] = a[0] * b[1] + a[1] * b[0] + a[2] * b[3] - a[3] * b[2];
    out[2] = a[0] * b[2] - a[1] * b[3] + a[2] * b[0] + a[3] * b[1];
    out[3] = a[0] * b[3] + a[1] * b[2] - a[2] * b[1] + a[3] * b[0];
}

static int parse_key_rotation(struct ctx *c, json_t *v, const struct jpath *p, double q[4])
{
    static const char *const keys[] = {"axis", "degrees"};
    struct member m[2];
    vec3 axis;
    float deg;
    if (object_members(c, v, p, "rotate", keys, 2, m) != 0 || require(c, &m[0], p, "rotate", "axis") != 0 ||
        require(c, &m[1], p, "rotate", "degrees") != 0 ||
        get_vec3(c, m[0].val, &m[0].path, "rotate axis", &axis) != 0 ||
        get_float(c, m[1].val, &m[1].path, "rotate degrees", &deg) != 0)
        return -1;
    double l = sqrt((double)axis.x * axis.x + (double)axis.y * axis.y + (double)axis.z * axis.z);
    if (!(l > 0.0) || !isfinite(l))
        return fail(c, &m[0].path, AT_VALUE, "rotate axis must be a non-zero vector");
    float qf[4];
    motion_quat_from_axis_angle(v3((float)(axis.x / l), (float)(axis.y / l), (float)(axis.z / l)), deg, qf);
    for (int k = 0; k < 4; k++)
        q[k] = qf[k];
    return 0;
}

/* "keyframes": [{"time", "translate", "rotate", "scale"}, ...] into *out (caller frees). */
static int parse_keyframes(struct ctx *c, const struct member *km, struct motion_key **out, uint32_t *num)
{
    size_t n = json_is_array(km->val) ? json_array_size(km->val) : 0;
    if (n == 0 || n > MAX_KEYFRAMES)
        return fail(c, &km->path, AT_VALUE, "keyframes must be an array of 1 to %d objects", MAX_KEYFRAMES);
    static const char *const keys[] = {"time", "translate", "rotate", "scale"};
    static const double zero[3] = {0, 0, 0};
    struct motion_key *k = mem_calloc(n, sizeof *k);
    for (size_t i = 0; i < n; i++) {
        struct jpath p = jpath_child(&km->path, (uint32_t)i);
        struct member m[4];
        char what[48];
        str_fmt(what, sizeof what, "keyframes[%zu]", i);
        if (object_members(c, json_array_get(km->val, i), &p, what, keys, 4, m) != 0 ||
            require(c, &m[0], &p, what, "time") != 0 || get_float(c, m[0].val, &m[0].path, "time", &k[i].time) != 0)
            goto fail;
        if (i > 0 && !(k[i].time > k[i - 1].time)) {
            fail(c, &m[0].path, AT_VALUE, "keyframe times must increase (%g after %g)", (double)k[i].time,
                 (double)k[i - 1].time);
            goto fail;
        }
        k[i].scale = v3(1, 1, 1);
        if (m[3].val) {
            if (json_is_number(m[3].val)) {
                float f;
                if (get_float(c, m[3].val, &m[3].path, "scale", &f) != 0)
                    goto fail;
                k[i].scale = v3(f, f, f);
            } else if (get_vec3(c, m[3].val, &m[3].path, "scale", &k[i].scale) != 0) {
                goto fail;
            }
            if (!(k[i].scale.x > 0.0f && k[i].scale.y > 0.0f && k[i].scale.z > 0.0f)) {
                fail(c, &m[3].path, AT_VALUE, "keyframe scale must be > 0 (mirrors belong in \"transform\")");
                goto fail;
            }
        }
        double q[4] = {1, 0, 0, 0};
        if (m[2].val) {
            size_t nr = json_is_array(m[2].val) ? json_array_size(m[2].val) : 1;
            for (size_t r = 0; r < nr; r++) {
                struct jpath rp = json_is_array(m[2].val) ? jpath_child(&m[2].path, (uint32_t)r) : m[2].path;
                json_t *rv = json_is_array(m[2].val) ? json_array_get(m[2].val, r) : m[2].val;
                double qr[4] = {1, 0, 0, 0}, t[4];
                if (parse_key_rotation(c, rv, &rp, qr) != 0)
                    goto fail;
                quat_mul(qr, q, t); /* later rotations apply after earlier ones */
                memcpy(q, t, sizeof q);
            }
        }
        double l = sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]);
        for (int j = 0; j < 4; j++)
            k[i].quat[j] = (float)(q[j] / l);
        /* Keys move the object in the render frame: their translation holds the origin. */
        if (m[1].val ? get_point(c, m[1].val, &m[1].path, "translate", &k[i].translate) != 0
                     : (k[i].translate = rel_point(c, zero), 0))
            goto fail;
    }
    *out = k;
    *num = (uint32_t)n;
    return 0;
fail:
    free(k);
    return -1;
}

/* Deformation: frames 1.. of an OBJ sequence, each with mesh's topology, into mesh. */
static int parse_frames(struct ctx *c, const struct member *fm, const struct member *tm,
                        const struct mesh_obj_options *opt, struct mesh *mesh)
{
    size_t n = json_array_size(fm->val);
    if (!tm->val || !json_is_array(tm->val) || json_array_size(tm->val) != n)
        return fail(c, tm->val ? &tm->path : &fm->path, AT_VALUE,
                    "frame_times must be an array of %zu numbers, one per frame", n);
    mesh->frame_times = mem_alloc(sizeof(float) * n);
    for (size_t i = 0; i < n; i++) {
        struct jpath ep = jpath_child(&tm->path, (uint32_t)i);
        if (get_float(c, json_array_get(tm->val, i), &ep, "frame time", &mesh->frame_times[i]) != 0)
            return -1;
        if (i > 0 && !(mesh->frame_times[i] > mesh->frame_times[i - 1]))
            return fail(c, &ep, AT_VALUE, "frame_times must increase");
    }
    size_t nf = 3 * (size_t)mesh->num_vertices;
    mesh->frame_positions = mem_alloc(sizeof(float) * nf * n);
    memcpy(mesh->frame_positions, mesh->positions, sizeof(float) * nf);
    mesh->num_frames = (uint32_t)n;
    for (size_t i = 1; i < n; i++) {
        struct member em = {json_array_get(fm->val, i), jpath_child(&fm->path, (uint32_t)i)};
        const char *file = NULL;
        char why[1024];
        if (get_string(c, &em, "frame", &file) != 0)
            return -1;
        if (asset_path_check(file, why, sizeof why) != 0)
            return fail(c, &em.path, AT_VALUE, "frames: %s", why);
        char *data = NULL;
        size_t size = 0;
        if (c->src->read(c->src->ctx, file, &data, &size, why, sizeof why) != 0)
            return fail(c, &em.path, AT_VALUE, "cannot read OBJ file: %s", why);
        /* Only positions are kept: parse into a scratch scene with one stand-in material
         * (no MTL files are read for later frames). */
        struct scene tmp;
        memset(&tmp, 0, sizeof tmp);
        struct material dummy;
        memset(&dummy, 0, sizeof dummy);
        scene_add_material(&tmp, &dummy);
        struct mesh_obj_cache cache;
        memset(&cache, 0, sizeof cache);
        struct mesh_obj_options o = *opt;
        o.material_override = 0;
        int rc = mesh_obj_parse(&tmp, &cache, c->src, file, data, size, &o, c->err, c->errlen);
        free(data);
        mesh_obj_cache_fini(&cache);
        if (rc == 0) {
            const struct mesh *fmsh = tmp.num_meshes == 1 ? &tmp.meshes[0] : NULL;
            if (!fmsh || fmsh->num_vertices != mesh->num_vertices || fmsh->num_triangles != mesh->num_triangles ||
                memcmp(fmsh->indices, mesh->indices, 3 * sizeof(uint32_t) * mesh->num_triangles) != 0) {
                char fb[80], f0[80];
                rc = fail(c, &em.path, AT_VALUE,
                          "frame \"%s\" does not have the topology of the first frame \"%s\" "
                          "(%u vertices, %u triangles; the first has %u, %u)",
                          printable(file, fb, sizeof fb), printable(mesh->name, f0, sizeof f0),
                          fmsh ? fmsh->num_vertices : 0, fmsh ? fmsh->num_triangles : 0, mesh->num_vertices,
                          mesh->num_triangles);
            } else {
                memcpy(mesh->frame_positions + i * nf, fmsh->positions, sizeof(float) * nf);
            }
        }
        scene_fini(&tmp);
        if (rc != 0)
            return -1;
    }
    return 0;
}

/* An "obj" or (ply set) "ply" object: a mesh file, its material, transform and motion. */
static int parse_obj_object(struct ctx *c, json_t *obj, const struct jpath *p, const char *what, int ply)
{
    static const char *const keys[] = {"type", "file", "material", "transform", "name", "keyframes", "frames",
                                       "frame_times", "medium"};
    struct member m[9];
    if (object_members(c, obj, p, what, keys, 9, m) != 0)
        return -1;
    uint32_t inside = MEDIUM_NONE;
    if (m[8].val && find_medium(c, &m[8], &inside) != 0)
        return -1;
    if (ply && (m[6].val || m[7].val))
        return fail(c, m[6].val ? &m[6].path : &m[7].path, AT_KEY,
                    "%s: a deforming sequence (\"frames\") is read from OBJ files only", what);
    /* A deforming object names its OBJ sequence in "frames" instead of "file". */
    if (m[6].val) {
        if (m[1].val)
            return fail(c, &m[1].path, AT_KEY, "%s: \"file\" and \"frames\" exclude each other", what);
        if (!json_is_array(m[6].val) || json_array_size(m[6].val) < 2 || json_array_size(m[6].val) > 1024)
            return fail(c, &m[6].path, AT_VALUE, "frames must be an array of 2 to 1024 OBJ paths");
        m[1].val = json_array_get(m[6].val, 0);
        m[1].path = jpath_child(&m[6].path, 0);
    } else if (m[7].val) {
        return fail(c, &m[7].path, AT_KEY, "frame_times needs \"frames\"");
    }
    if (require(c, &m[1], p, what, "file") != 0)
        return -1;
    struct mesh_obj_options opt = mesh_obj_default_options();
    opt.display_dir = c->display_dir;
    const char *file = NULL, *name = NULL;
    char why[1024];
    if (get_string(c, &m[1], "file", &file) != 0)
        return -1;
    if (asset_path_check(file, why, sizeof why) != 0)
        return fail(c, &m[1].path, AT_VALUE, "file: %s", why);
    if (m[2].val && find_material(c, &m[2], &opt.material_override) != 0)
        return -1;
    if (m[8].val && !m[2].val)
        opt.material_override = interface_material(c);
    if (m[3].val) {
        double s;
        bool uniform;
        if (parse_transform(c, &m[3], &opt.transform, &s, &uniform) != 0)
            return -1;
    }
    /* A moving object's vertices are in the space its keys move (their translations hold
     * the origin); any other object's are in the render frame. */
    if (!m[5].val)
        opt.transform = dxform_minus_origin(&opt.transform, c->origin);
    if (m[4].val && get_string(c, &m[4], "name", &name) != 0)
        return -1;
    opt.mesh_name = name;
    char *data = NULL;
    size_t size = 0;
    if (!c->src || !c->src->read)
        return fail(c, &m[1].path, AT_VALUE, "cannot read OBJ file \"%s\": no asset source", file);
    if (c->src->read(c->src->ctx, file, &data, &size, why, sizeof why) != 0)
        return fail(c, &m[1].path, AT_VALUE, "cannot read %s file: %s", ply ? "PLY" : "OBJ", why);
    uint32_t before = c->scene->num_meshes;
    int rc = ply ? mesh_ply_parse(c->scene, &c->cache, file, (const uint8_t *)data, size, &opt, c->err, c->errlen)
                 : mesh_obj_parse(c->scene, &c->cache, c->src, file, data, size, &opt, c->err, c->errlen);
    free(data);
    for (uint32_t i = before; rc == 0 && m[8].val && i < c->scene->num_meshes; i++)
        media_set_mesh(c->scene->media, i, inside);
    if (rc != 0 || (!m[5].val && !m[6].val))
        return rc;
    if (c->scene->num_meshes != before + 1)
        return fail(c, &m[1].path, AT_VALUE, "a moving object needs a mesh file with faces");
    struct mesh *mesh = &c->scene->meshes[before];
    if (m[5].val && parse_keyframes(c, &m[5], &mesh->keys, &mesh->num_keys) != 0)
        return -1;
    if (m[6].val && parse_frames(c, &m[6], &m[7], &opt, mesh) != 0)
        return -1;
    return 0;
}

static int parse_sphere(struct ctx *c, json_t *obj, const struct jpath *p, const char *what)
{
    static const char *const keys[] = {"type", "center", "radius", "material", "transform", "name", "keyframes",
                                       "medium"};
    struct member m[8];
    if (object_members(c, obj, p, what, keys, 8, m) != 0 || require(c, &m[1], p, what, "center") != 0 ||
        require(c, &m[2], p, what, "radius") != 0 || (!m[7].val && require(c, &m[3], p, what, "material") != 0))
        return -1;
    uint32_t inside = MEDIUM_NONE;
    if (m[7].val && find_medium(c, &m[7], &inside) != 0)
        return -1;
    struct sphere sp;
    memset(&sp, 0, sizeof sp);
    double center[3];
    if (get_dvec3(c, m[1].val, &m[1].path, "center", center) != 0 ||
        get_float(c, m[2].val, &m[2].path, "radius", &sp.radius) != 0)
        return -1;
    if (!(sp.radius > 0.0f))
        return fail(c, &m[2].path, AT_VALUE, "radius must be > 0");
    if (m[3].val ? find_material(c, &m[3], &sp.material_id) != 0 : (sp.material_id = interface_material(c), 0))
        return -1;
    /* As for meshes: a moving sphere's centre is in the space its keys move, any other's
     * in the render frame. */
    struct dxform t = dxform_identity();
    if (m[4].val) {
        double s;
        bool uniform;
        if (parse_transform(c, &m[4], &t, &s, &uniform) != 0)
            return -1;
        if (!uniform)
            return fail(c, &m[4].path, AT_VALUE, "a sphere's transform must scale uniformly");
        double r = (double)sp.radius * s;
        if (!(r > 0.0 && r <= FLT_MAX))
            return fail(c, &m[4].path, AT_VALUE, "transformed sphere is out of range");
        sp.radius = (float)r;
    }
    if (!m[6].val)
        t = dxform_minus_origin(&t, c->origin);
    double w[3];
    dxform_point(&t, center, w);
    sp.center = v3((float)w[0], (float)w[1], (float)w[2]);
    if (!v3_is_finite(sp.center))
        return fail(c, m[4].val ? &m[4].path : &m[1].path, AT_VALUE, "%s is out of range",
                    m[4].val ? "transformed sphere" : "sphere center (from the camera)");
    const char *name = NULL;
    if (m[5].val && get_string(c, &m[5], "name", &name) != 0)
        return -1;
    if (name)
        str_fmt(sp.name, sizeof sp.name, "%s", name);
    else
        str_fmt(sp.name, sizeof sp.name, "sphere %u", c->scene->num_spheres);
    if (m[6].val && parse_keyframes(c, &m[6], &sp.keys, &sp.num_keys) != 0)
        return -1;
    if (m[7].val && sp.num_keys > 0) {
        free(sp.keys);
        return fail(c, &m[7].path, AT_KEY, "a medium cannot fill a moving sphere");
    }
    uint32_t si = scene_add_sphere(c->scene, &sp);
    if (m[7].val)
        media_set_sphere(c->scene->media, si, inside);
    return 0;
}

static int parse_objects(struct ctx *c, const struct member *om)
{
    if (!json_is_array(om->val))
        return fail(c, &om->path, AT_VALUE, "objects must be an array");
    for (size_t i = 0; i < json_array_size(om->val); i++) {
        struct jpath p = jpath_child(&om->path, (uint32_t)i);
        json_t *obj = json_array_get(om->val, i);
        char what[64];
        str_fmt(what, sizeof what, "objects[%zu]", i);
        struct member tm;
        const char *type = NULL;
        if (object_type(c, obj, &p, what, &tm, &type) != 0)
            return -1;
        int rc;
        if (strcmp(type, "obj") == 0 || strcmp(type, "ply") == 0) {
            rc = parse_obj_object(c, obj, &p, what, strcmp(type, "ply") == 0);
        } else if (strcmp(type, "sphere") == 0) {
            rc = parse_sphere(c, obj, &p, what);
        } else {
            char tb[80];
            rc = fail(c, &tm.path, AT_VALUE, "unknown object type \"%s\" (known: obj, ply, sphere)",
                      printable(type, tb, sizeof tb));
        }
        if (rc != 0)
            return -1;
    }
    return 0;
}

static int parse_spot(struct ctx *c, json_t *obj, const struct jpath *p, const char *what,
                      const char *const *keys)
{
    struct member m[7];
    struct light l;
    memset(&l, 0, sizeof l);
    l.type = LIGHT_SPOT;
    if (object_members(c, obj, p, what, keys, 7, m) != 0 || require(c, &m[1], p, what, "position") != 0 ||
        require(c, &m[2], p, what, "intensity") != 0 || require(c, &m[5], p, what, "angle") != 0 ||
        get_point(c, m[1].val, &m[1].path, "position", &l.position) != 0 ||
        get_vec3(c, m[2].val, &m[2].path, "intensity", &l.intensity) != 0 ||
        check_color(c, &m[2], "intensity", 0.0f, FLT_MAX, l.intensity) != 0)
        return -1;
    if (!!m[3].val == !!m[4].val)
        return fail(c, m[4].val ? &m[4].path : p, m[4].val ? AT_KEY : AT_VALUE,
                    "%s: give exactly one of \"direction\" and \"look_at\"", what);
    vec3 d;
    if (m[3].val && get_vec3(c, m[3].val, &m[3].path, "direction", &d) != 0)
        return -1;
    if (m[4].val) {
        vec3 at;
        if (get_point(c, m[4].val, &m[4].path, "look_at", &at) != 0)
            return -1;
        d = v3_sub(at, l.position);
    }
    const struct member *dm = m[3].val ? &m[3] : &m[4];
    if (!direction_ok(d))
        return fail(c, &dm->path, AT_VALUE, "spot direction must be a non-zero vector");
    l.direction = v3_normalize(d);
    float angle, falloff = 0.0f;
    if (get_float(c, m[5].val, &m[5].path, "angle", &angle) != 0)
        return -1;
    if (!(angle > 0.0f && angle <= 180.0f))
        return fail(c, &m[5].path, AT_VALUE, "angle (half-angle of the cone, degrees) must be in (0, 180]");
    if (m[6].val) {
        if (get_float(c, m[6].val, &m[6].path, "falloff", &falloff) != 0)
            return -1;
        if (!(falloff >= 0.0f && falloff <= angle))
            return fail(c, &m[6].path, AT_VALUE, "falloff must be in [0, angle] degrees");
    }
    double outer = (double)angle * M_PI / 180.0, inner = (double)(angle - falloff) * M_PI / 180.0;
    l.cos_outer = (float)cos(outer);
    l.cos_inner = (float)cos(inner);
    if (!(l.cos_outer < 1.0f)) /* a cone below ~0.02 degrees: the narrowest float can tell */
        l.cos_outer = nextafterf(1.0f, 0.0f);
    if (!(l.cos_inner > l.cos_outer))
        l.cos_inner = nextafterf(l.cos_outer, 2.0f);
    scene_add_light(c->scene, &l);
    return 0;
}

/* The environment light: a lat-long image (any texture format image_load reads, linear
 * RGB; 8-bit files as sRGB) with strength and rotation (envmap.h). */
static int parse_environment(struct ctx *c, json_t *obj, const struct jpath *p, const char *what)
{
    enum { E_TYPE, E_FILE, E_STRENGTH, E_ROTATION, E_SAMPLING, E_N };
    static const char *const keys[E_N] = {"type", "file", "strength", "rotation", "sampling"};
    struct member m[E_N];
    if (object_members(c, obj, p, what, keys, E_N, m) != 0 || require(c, &m[E_FILE], p, what, "file") != 0)
        return -1;
    if (c->scene->env)
        return fail(c, &m[E_TYPE].path, AT_VALUE, "%s: only one environment light is allowed", what);
    float strength = 1.0f, rotation = 0.0f;
    if (m[E_STRENGTH].val) {
        if (get_float(c, m[E_STRENGTH].val, &m[E_STRENGTH].path, "strength", &strength) != 0)
            return -1;
        if (!(strength >= 0.0f && strength <= 1e12f))
            return fail(c, &m[E_STRENGTH].path, AT_VALUE, "strength must be in [0, 1e12]");
    }
    if (m[E_ROTATION].val) {
        if (get_float(c, m[E_ROTATION].val, &m[E_ROTATION].path, "rotation", &rotation) != 0)
            return -1;
        if (!(fabsf(rotation) <= 3600.0f))
            return fail(c, &m[E_ROTATION].path, AT_VALUE, "rotation (degrees about +y) must be in [-3600, 3600]");
    }
    int uniform = 0;
    if (m[E_SAMPLING].val) {
        const char *smp = NULL;
        if (get_string(c, &m[E_SAMPLING], "sampling", &smp) != 0)
            return -1;
        if (strcmp(smp, "uniform") == 0)
            uniform = 1;
        else if (strcmp(smp, "importance") != 0)
            return fail(c, &m[E_SAMPLING].path, AT_VALUE, "sampling must be \"importance\" or \"uniform\"");
    }
    const char *file = NULL;
    if (get_string(c, &m[E_FILE], "file", &file) != 0)
        return -1;
    if (!c->src)
        return fail(c, &m[E_FILE].path, AT_VALUE, "cannot read image \"%s\": no asset source", file);
    char display[2048], why[512];
    str_fmt(display, sizeof display, "%s%s", c->display_dir, file);
    struct tex_image img;
    if (image_load_asset(c->src, file, display, 1, &img, why, sizeof why) != 0)
        return fail(c, &m[E_FILE].path, AT_VALUE, "cannot load image: %s", why);
    size_t np = (size_t)img.width * img.height;
    float *rgb = mem_alloc(sizeof(float) * 3 * np);
    for (size_t i = 0; i < np; i++)
        for (int k = 0; k < 3; k++) {
            size_t j = i * img.channels + (img.channels == 3 ? (size_t)k : 0);
            float v = img.format == TEXEL_F32 ? ((const float *)img.data)[j]
                      : img.format == TEXEL_U8_SRGB ? mip_srgb_to_linear(((const uint8_t *)img.data)[j] / 255.0f)
                                                    : ((const uint8_t *)img.data)[j] / 255.0f;
            rgb[3 * i + k] = isfinite(v) && v > 0.0f ? fminf(v, 1e30f) : 0.0f;
        }
    uint32_t w = img.width, h = img.height;
    tex_image_fini(&img);
    c->scene->env = envmap_new(rgb, w, h, strength, rotation);
    c->scene->env->uniform = uniform;
    return 0;
}

static int parse_lights(struct ctx *c, const struct member *lm)
{
    if (!json_is_array(lm->val))
        return fail(c, &lm->path, AT_VALUE, "lights must be an array");
    static const char *const keys[] = {"type", "position", "intensity"};
    static const char *const spot_keys[] = {"type", "position", "intensity", "direction", "look_at", "angle",
                                            "falloff"};
    for (size_t i = 0; i < json_array_size(lm->val); i++) {
        struct jpath p = jpath_child(&lm->path, (uint32_t)i);
        json_t *obj = json_array_get(lm->val, i);
        char what[64];
        str_fmt(what, sizeof what, "lights[%zu]", i);
        struct member tm;
        const char *type = NULL;
        if (object_type(c, obj, &p, what, &tm, &type) != 0)
            return -1;
        if (strcmp(type, "spot") == 0) {
            if (parse_spot(c, obj, &p, what, spot_keys) != 0)
                return -1;
            continue;
        }
        if (strcmp(type, "environment") == 0) {
            if (parse_environment(c, obj, &p, what) != 0)
                return -1;
            continue;
        }
        if (strcmp(type, "point") != 0) {
            char tb[80];
            return fail(c, &tm.path, AT_VALUE,
                        "unknown light type \"%s\" (known: point, spot, environment; area lights are emissive materials)",
                        printable(type, tb, sizeof tb));
        }
        struct member m[3];
        struct light l;
        memset(&l, 0, sizeof l);
        l.type = LIGHT_POINT;
        if (object_members(c, obj, &p, what, keys, 3, m) != 0 || require(c, &m[1], &p, what, "position") != 0 ||
            require(c, &m[2], &p, what, "intensity") != 0 ||
            get_point(c, m[1].val, &m[1].path, "position", &l.position) != 0 ||
            get_vec3(c, m[2].val, &m[2].path, "intensity", &l.intensity) != 0 ||
            check_color(c, &m[2], "intensity", 0.0f, FLT_MAX, l.intensity) != 0)
            return -1;
        scene_add_light(c->scene, &l);
    }
    return 0;
}

/* The scene's origin (scene.h): the camera's position, its first key's if it moves, read
 * before anything positional. A camera without a usable position keeps 0: parse_camera
 * reports it. */
static void read_origin(struct ctx *c, json_t *camera)
{
    json_t *pos = json_object_get(camera, "position"), *keys = json_object_get(camera, "keyframes");
    if (!pos && json_is_array(keys))
        pos = json_object_get(json_array_get(keys, 0), "position");
    if (!json_is_array(pos) || json_array_size(pos) != 3)
        return;
    double o[3];
    for (size_t i = 0; i < 3; i++) {
        json_t *v = json_array_get(pos, i);
        o[i] = json_is_number(v) ? json_number_value(v) : NAN;
        if (!(o[i] >= -FLT_MAX && o[i] <= FLT_MAX))
            return;
    }
    memcpy(c->scene->origin, o, sizeof o);
}

static int parse_root(struct ctx *c, json_t *root)
{
    static const char *const keys[] = {"version", "camera", "render", "materials", "objects", "lights", "media",
                                       "volume", "textures"};
    struct jpath rp = {0, {0}};
    struct member m[9];
    if (object_members(c, root, &rp, "the scene", keys, 9, m) != 0 ||
        require(c, &m[0], &rp, "scene", "version") != 0)
        return -1;
    if (!json_is_integer(m[0].val))
        return fail(c, &m[0].path, AT_VALUE, "version must be an integer, not %s", type_name(m[0].val));
    if (json_integer_value(m[0].val) != SCENE_VERSION)
        return fail(c, &m[0].path, AT_VALUE, "unsupported scene version %lld (this build reads version %d)",
                    (long long)json_integer_value(m[0].val), SCENE_VERSION);
    if (require(c, &m[1], &rp, "scene", "camera") != 0 || require(c, &m[2], &rp, "scene", "render") != 0)
        return -1;
    if (!c->origin_given)
        read_origin(c, m[1].val);
    /* Textures, then materials: objects refer to materials (and materials to textures) by
     * name wherever they appear in the file. */
    if (m[8].val && parse_textures(c, &m[8]) != 0)
        return -1;
    if (m[3].val && parse_materials(c, &m[3]) != 0)
        return -1;
    /* Media before objects (which name them); the volume settings name the fog. */
    if (m[6].val && parse_media(c, &m[6]) != 0)
        return -1;
    if (m[7].val && !m[6].val)
        return fail(c, &m[7].path, AT_KEY, "\"volume\" needs \"media\"");
    if (m[7].val && parse_volume(c, &m[7]) != 0)
        return -1;
    if (parse_camera(c, &m[1]) != 0 || parse_render(c, &m[2]) != 0)
        return -1;
    if (m[4].val && parse_objects(c, &m[4]) != 0)
        return -1;
    if (m[5].val && parse_lights(c, &m[5]) != 0)
        return -1;
    return 0;
}

int scene_json_parse(const char *name, const char *text, size_t len, const struct asset_source *src,
                     struct scene *out, char *err, size_t errlen)
{
    return scene_json_parse_origin(name, text, len, src, NULL, out, err, errlen);
}

int scene_json_parse_origin(const char *name, const char *text, size_t len, const struct asset_source *src,
                            const double origin[3], struct scene *out, char *err, size_t errlen)
{
    return scene_json_parse_frame(name, text, len, src, origin, 0, out, err, errlen);
}

int scene_json_parse_frame(const char *name, const char *text, size_t len, const struct asset_source *src,
                           const double origin[3], uint32_t frame, struct scene *out, char *err, size_t errlen)
{
    memset(out, 0, sizeof *out);
    json_error_t jerr;
    json_t *root = json_loadb(text, len, JSON_REJECT_DUPLICATES, &jerr);
    if (!root) {
        str_fmt(err, errlen, "%s:%d:%d: %s", name, jerr.line > 0 ? jerr.line : 1, jerr.column > 0 ? jerr.column : 1,
                jerr.text);
        return -1;
    }
    struct ctx c;
    memset(&c, 0, sizeof c);
    c.name = name;
    c.text = text;
    c.len = len;
    c.err = err;
    c.errlen = errlen;
    c.scene = out;
    c.src = src;
    c.frame = frame;
    c.origin = out->origin;
    if (origin) {
        memcpy(out->origin, origin, sizeof out->origin);
        c.origin_given = true;
    }
    const char *slash = strrchr(name, '/');
    if (slash && (size_t)(slash - name) + 2 <= sizeof c.display_dir)
        memcpy(c.display_dir, name, (size_t)(slash - name) + 1);
    int rc = parse_root(&c, root);
    json_decref(root);
    mesh_obj_cache_fini(&c.cache);
    if (rc == 0) {
        char why[512];
        if (scene_validate(out, why, sizeof why) != 0) {
            str_fmt(err, errlen, "%s: %s", name, why);
            rc = -1;
        }
    }
    if (rc != 0)
        scene_fini(out);
    return rc;
}
