/* Smoke settings (see settings.h). jansson checks the syntax and keeps no positions; on a
 * semantic error base/jsonpos.h finds the key path's line:col in the (already valid) text.
 * The settings are two levels deep at most (top level and "source"). */
#include "settings.h"
#include "base/asset.h"
#include "base/jsonpos.h"
#include "base/log.h"
#include <jansson.h>
#include <math.h>
#include <stdarg.h>
#include <stdbool.h>
#include <stdio.h>
#include <string.h>

void smoke_settings_default(struct smoke_settings *s)
{
    memset(s, 0, sizeof *s);
    s->res[0] = s->res[1] = s->res[2] = 32;
    s->size = 1.0f;
    s->frames = 24;
    s->steps_per_frame = 2;
    s->dt = 1.0f / 48.0f;
    s->viscosity = 0.0f;
    s->alpha = 0.05f;
    s->beta = 1.0f;
    s->epsilon = 2.0f;
    s->source_center[0] = 0.5f;
    s->source_center[1] = 0.2f;
    s->source_center[2] = 0.5f;
    s->source_radius = 0.08f;
    s->source_rate = 8.0f;
    s->source_temperature = 1.0f;
    s->source_jitter = 0.5f;
    s->sponge_width = 4;
    s->sponge_strength = 20.0f;
    s->seed = 1;
    s->threads = 1;
    snprintf(s->output, sizeof s->output, "smoke.####.grid");
    s->nvdb_threshold = 1e-4f;
}

struct ctx {
    const char *name, *text;
    size_t len;
    char *err;
    size_t errlen;
};

__attribute__((format(printf, 5, 6))) static int fail(const struct ctx *c, const char *const *keys, int n,
                                                      bool at_key, const char *fmt, ...)
{
    struct json_step steps[2];
    for (int i = 0; i < n && i < 2; i++)
        steps[i] = (struct json_step){keys[i], 0};
    va_list ap;
    va_start(ap, fmt);
    json_error_at(c->err, c->errlen, c->name, c->text, c->len, steps, n < 2 ? n : 2, at_key, fmt, ap);
    va_end(ap);
    return -1;
}

/* ---- typed reads ---- */

static int get_float(const struct ctx *c, json_t *obj, const char *const *path, int n, float lo, float hi,
                     float *out)
{
    json_t *v = json_object_get(obj, path[n - 1]);
    if (!v)
        return 0;
    if (!json_is_number(v))
        return fail(c, path, n, false, "\"%s\" must be a number", path[n - 1]);
    double x = json_number_value(v);
    if (!isfinite(x) || x < lo || x > hi)
        return fail(c, path, n, false, "\"%s\" is %g, outside [%g, %g]", path[n - 1], x, (double)lo, (double)hi);
    *out = (float)x;
    return 0;
}

static int get_uint(const struct ctx *c, json_t *obj, const char *const *path, int n, uint64_t lo, uint64_t hi,
                    uint64_t *out)
{
    json_t *v = json_object_get(obj, path[n - 1]);
    if (!v)
        return 0;
    if (!json_is_integer(v) || json_integer_value(v) < 0 || (uint64_t)json_integer_value(v) < lo ||
        (uint64_t)json_integer_value(v) > hi)
        return fail(c, path, n, false, "\"%s\" must be an integer in [%llu, %llu]", path[n - 1],
                    (unsigned long long)lo, (unsigned long long)hi);
    *out = (uint64_t)json_integer_value(v);
    return 0;
}

static int get_vec(const struct ctx *c, json_t *obj, const char *const *path, int n, float lo, float hi,
                   float out[3])
{
    json_t *v = json_object_get(obj, path[n - 1]);
    if (!v)
        return 0;
    if (!json_is_array(v) || json_array_size(v) != 3)
        return fail(c, path, n, false, "\"%s\" must be an array of 3 numbers", path[n - 1]);
    for (size_t i = 0; i < 3; i++) {
        json_t *e = json_array_get(v, i);
        double x = json_is_number(e) ? json_number_value(e) : NAN;
        if (!isfinite(x) || x < lo || x > hi)
            return fail(c, path, n, false, "\"%s\"[%zu] must be a finite number in [%g, %g]", path[n - 1], i,
                        (double)lo, (double)hi);
        out[i] = (float)x;
    }
    return 0;
}

static int check_keys(const struct ctx *c, json_t *obj, const char *parent, const char *const *allowed)
{
    const char *key;
    json_t *val;
    json_object_foreach(obj, key, val) {
        size_t i = 0;
        while (allowed[i] && strcmp(allowed[i], key) != 0)
            i++;
        if (allowed[i])
            continue;
        char list[512] = "";
        size_t o = 0;
        for (size_t k = 0; allowed[k] && o < sizeof list; k++)
            o += (size_t)snprintf(list + o, sizeof list - o, "%s%s", k ? ", " : "", allowed[k]);
        const char *path[2] = {parent, key};
        char kb[64];
        snprintf(kb, sizeof kb, "%s", key);
        for (char *p = kb; *p; p++)
            if ((unsigned char)*p < 0x20 || *p == '"')
                *p = '?';
        return parent ? fail(c, path, 2, true, "unknown key \"%s\" in %s (expected one of: %s)", kb, parent, list)
                      : fail(c, path + 1, 1, true, "unknown key \"%s\" (expected one of: %s)", kb, list);
    }
    return 0;
}

static const char *const top_keys[] = {"version", "resolution", "size", "frames", "steps_per_frame", "dt",
                                       "viscosity", "buoyancy", "confinement", "source", "sponge", "seed",
                                       "threads", "output", "nvdb_threshold", NULL};
static const char *const buoy_keys[] = {"alpha", "beta", NULL};
static const char *const source_keys[] = {"center", "radius", "rate", "temperature", "velocity", "jitter", NULL};
static const char *const sponge_keys[] = {"width", "strength", NULL};

static int parse_object(const struct ctx *c, json_t *root, struct smoke_settings *s)
{
    if (check_keys(c, root, NULL, top_keys))
        return -1;
    uint64_t u;
    const char *p[2];
#define P1(k) (p[0] = (k), p)
#define P2(a, b) (p[0] = (a), p[1] = (b), p)
    json_t *ver = json_object_get(root, "version");
    if (ver && !(json_is_integer(ver) && json_integer_value(ver) == 1))
        return fail(c, P1("version"), 1, false, "\"version\" must be 1");
    json_t *res = json_object_get(root, "resolution");
    if (res) {
        if (!json_is_array(res) || json_array_size(res) != 3)
            return fail(c, P1("resolution"), 1, false, "\"resolution\" must be an array of 3 integers");
        for (size_t i = 0; i < 3; i++) {
            json_t *e = json_array_get(res, i);
            if (!json_is_integer(e) || json_integer_value(e) < SMOKE_MIN_RES ||
                json_integer_value(e) > SMOKE_MAX_RES)
                return fail(c, P1("resolution"), 1, false,
                            "\"resolution\"[%zu] must be an integer in [%d, %d] (the sponge and the FFT need room)",
                            i, SMOKE_MIN_RES, SMOKE_MAX_RES);
            s->res[i] = (uint32_t)json_integer_value(e);
        }
    }
    if (get_float(c, root, P1("size"), 1, 1e-6f, 1e6f, &s->size))
        return -1;
    if (json_object_get(root, "frames")) {
        if (get_uint(c, root, P1("frames"), 1, 1, 100000, &u))
            return -1;
        s->frames = (uint32_t)u;
    }
    if (json_object_get(root, "steps_per_frame")) {
        if (get_uint(c, root, P1("steps_per_frame"), 1, 1, 10000, &u))
            return -1;
        s->steps_per_frame = (uint32_t)u;
    }
    if (get_float(c, root, P1("dt"), 1, 1e-6f, 10.0f, &s->dt) ||
        get_float(c, root, P1("viscosity"), 1, 0.0f, 1e3f, &s->viscosity) ||
        get_float(c, root, P1("confinement"), 1, 0.0f, 1e3f, &s->epsilon))
        return -1;
    json_t *b = json_object_get(root, "buoyancy");
    if (b) {
        if (!json_is_object(b))
            return fail(c, P1("buoyancy"), 1, false, "\"buoyancy\" must be an object");
        if (check_keys(c, b, "buoyancy", buoy_keys) ||
            get_float(c, b, P2("buoyancy", "alpha"), 2, -1e6f, 1e6f, &s->alpha) ||
            get_float(c, b, P2("buoyancy", "beta"), 2, -1e6f, 1e6f, &s->beta))
            return -1;
    }
    json_t *src = json_object_get(root, "source");
    if (src) {
        if (!json_is_object(src))
            return fail(c, P1("source"), 1, false, "\"source\" must be an object");
        if (check_keys(c, src, "source", source_keys) ||
            get_vec(c, src, P2("source", "center"), 2, -1e6f, 1e6f, s->source_center) ||
            get_float(c, src, P2("source", "radius"), 2, 1e-6f, 1e6f, &s->source_radius) ||
            get_float(c, src, P2("source", "rate"), 2, 0.0f, 1e6f, &s->source_rate) ||
            get_float(c, src, P2("source", "temperature"), 2, -1e6f, 1e6f, &s->source_temperature) ||
            get_vec(c, src, P2("source", "velocity"), 2, -1e6f, 1e6f, s->source_velocity) ||
            get_float(c, src, P2("source", "jitter"), 2, 0.0f, 1.0f, &s->source_jitter))
            return -1;
    }
    json_t *sp = json_object_get(root, "sponge");
    if (sp) {
        if (!json_is_object(sp))
            return fail(c, P1("sponge"), 1, false, "\"sponge\" must be an object");
        if (check_keys(c, sp, "sponge", sponge_keys))
            return -1;
        if (json_object_get(sp, "width")) {
            if (get_uint(c, sp, P2("sponge", "width"), 2, 0, SMOKE_MAX_RES / 2, &u))
                return -1;
            s->sponge_width = (uint32_t)u;
        }
        if (get_float(c, sp, P2("sponge", "strength"), 2, 0.0f, 1e6f, &s->sponge_strength))
            return -1;
    }
    if (json_object_get(root, "seed")) {
        if (get_uint(c, root, P1("seed"), 1, 0, (uint64_t)INT64_MAX, &u))
            return -1;
        s->seed = u;
    }
    if (json_object_get(root, "threads")) {
        if (get_uint(c, root, P1("threads"), 1, 1, 256, &u))
            return -1;
        s->threads = (uint32_t)u;
    }
    json_t *out = json_object_get(root, "output");
    if (out) {
        const char *o = json_string_value(out);
        if (!o || strlen(o) >= sizeof s->output || !strchr(o, '#') || strstr(o, "..") || strchr(o, '/') ||
            smoke_output_nvdb(o) < 0)
            return fail(c, P1("output"), 1, false,
                        "\"output\" must be a file name (no folder) with a run of '#', ending in .nvdb or .grid, "
                        "e.g. \"smoke.####.nvdb\"");
        snprintf(s->output, sizeof s->output, "%s", o);
    }
    if (get_float(c, root, P1("nvdb_threshold"), 1, 0.0f, 1e6f, &s->nvdb_threshold))
        return -1;
#undef P1
#undef P2
    char msg[400];
    if (smoke_settings_check(s, msg, sizeof msg))
        return fail(c, NULL, 0, false, "%s", msg);
    return 0;
}

int smoke_settings_check(const struct smoke_settings *s, char *err, size_t errlen)
{
    uint64_t n = 1;
    for (int i = 0; i < 3; i++) {
        if (s->res[i] < SMOKE_MIN_RES || s->res[i] > SMOKE_MAX_RES) {
            str_fmt(err, errlen, "resolution %u along axis %d: each side must be in [%d, %d] voxels", s->res[i], i,
                    SMOKE_MIN_RES, SMOKE_MAX_RES);
            return -1;
        }
        n *= s->res[i];
    }
    if (n > SMOKE_MAX_VOXELS) {
        str_fmt(err, errlen, "%llu voxels: at most %u", (unsigned long long)n, SMOKE_MAX_VOXELS);
        return -1;
    }
    const float vals[] = {s->size, s->dt, s->viscosity, s->alpha, s->beta, s->epsilon, s->source_radius,
                          s->source_rate, s->source_temperature, s->source_jitter, s->sponge_strength,
                          s->source_center[0], s->source_center[1], s->source_center[2],
                          s->source_velocity[0], s->source_velocity[1], s->source_velocity[2]};
    for (size_t i = 0; i < sizeof vals / sizeof *vals; i++)
        if (!isfinite(vals[i])) {
            str_fmt(err, errlen, "a setting is not finite (NaN or infinity)");
            return -1;
        }
    if (!(s->size > 0.0f) || !(s->dt > 0.0f) || s->viscosity < 0.0f || s->epsilon < 0.0f ||
        !(s->source_radius > 0.0f) || s->source_rate < 0.0f || s->sponge_strength < 0.0f ||
        s->source_jitter < 0.0f || s->source_jitter > 1.0f) {
        str_fmt(err, errlen, "size, dt and source radius must be > 0; viscosity, confinement, rate and sponge "
                             "strength >= 0; jitter in [0, 1]");
        return -1;
    }
    if (s->frames < 1 || s->steps_per_frame < 1 || s->threads < 1) {
        str_fmt(err, errlen, "frames, steps_per_frame and threads must be >= 1");
        return -1;
    }
    for (int a = 0; a < 3; a++) {
        float len = s->size * (float)s->res[a] / (float)s->res[0];
        if (s->source_center[a] < 0.0f || s->source_center[a] > len) {
            str_fmt(err, errlen, "source centre %g along axis %d is outside the domain [0, %g]",
                    (double)s->source_center[a], a, (double)len);
            return -1;
        }
    }
    char name[300];
    if (smoke_output_nvdb(s->output) < 0) {
        str_fmt(err, errlen, "output pattern \"%s\" must end in .nvdb or .grid", s->output);
        return -1;
    }
    if (!(s->nvdb_threshold >= 0.0f) || !isfinite(s->nvdb_threshold)) {
        str_fmt(err, errlen, "nvdb_threshold must be finite and >= 0");
        return -1;
    }
    if (smoke_frame_name(s->output, 1, name, sizeof name)) {
        str_fmt(err, errlen, "output pattern \"%s\" needs exactly one run of '#'", s->output);
        return -1;
    }
    uint32_t minres = s->res[0] < s->res[1] ? s->res[0] : s->res[1];
    minres = minres < s->res[2] ? minres : s->res[2];
    if (2 * s->sponge_width >= minres) {
        str_fmt(err, errlen, "sponge width %u leaves no interior in %u voxels", s->sponge_width, minres);
        return -1;
    }
    return 0;
}

int smoke_settings_parse(const char *name, const char *text, size_t len, struct smoke_settings *s, char *err,
                         size_t errlen)
{
    smoke_settings_default(s);
    if (errlen)
        err[0] = '\0';
    json_error_t jerr;
    json_t *root = json_loadb(text, len, JSON_REJECT_DUPLICATES, &jerr);
    if (!root) {
        str_fmt(err, errlen, "%s:%d:%d: %s", name, jerr.line > 0 ? jerr.line : 1, jerr.column > 0 ? jerr.column : 1,
                jerr.text);
        return -1;
    }
    struct ctx c = {name, text, len, err, errlen};
    int rc;
    if (!json_is_object(root)) {
        str_fmt(err, errlen, "%s:1:1: the settings must be a JSON object", name);
        rc = -1;
    } else {
        rc = parse_object(&c, root, s);
    }
    json_decref(root);
    return rc;
}

int smoke_output_nvdb(const char *pattern)
{
    size_t n = strlen(pattern);
    if (n >= 5 && strcmp(pattern + n - 5, ".nvdb") == 0)
        return 1;
    if (n >= 5 && strcmp(pattern + n - 5, ".grid") == 0)
        return 0;
    return -1;
}

int smoke_frame_name(const char *pattern, uint32_t frame, char *out, size_t size)
{
    const char *h = strchr(pattern, '#');
    if (!h)
        return -1;
    if (strchr(h + strspn(h, "#"), '#'))
        return -1;  /* one run only */
    return asset_frame_name(pattern, frame, out, size) == 1 ? 0 : -1;
}
