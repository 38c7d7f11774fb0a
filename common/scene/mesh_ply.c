/* PLY reader (see mesh_ply.h). The header is read line by line into a table of elements
 * and properties; the body is then read element by element through one value reader per
 * format (ascii tokens, or little/big-endian binary), every read bounded by the buffer's
 * end. Counts are checked against the bytes left before any allocation: each element of
 * a binary file needs at least its fixed bytes, each value of an ascii file at least two
 * bytes (a digit and a separator). */
#include "scene/mesh_ply.h"
#include "base/bytes.h"
#include "base/log.h"
#include <math.h>
#include <stdarg.h>
#include <stdbool.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define PLY_MAX_HEADER (1u << 20)
#define PLY_MAX_ELEMS 64
#define PLY_MAX_PROPS 64
#define PLY_NAME_MAX 64

enum ply_format { PLY_ASCII, PLY_BINARY_LE, PLY_BINARY_BE };
enum ply_type { T_NONE, T_I8, T_U8, T_I16, T_U16, T_I32, T_U32, T_F32, T_F64 };
enum ply_role { R_NONE, R_X, R_Y, R_Z, R_NX, R_NY, R_NZ, R_U, R_V, R_INDICES };

static const struct {
    const char *name;
    enum ply_type type;
} type_names[] = {{"char", T_I8},    {"int8", T_I8},     {"uchar", T_U8},   {"uint8", T_U8},
                  {"short", T_I16},  {"int16", T_I16},   {"ushort", T_U16}, {"uint16", T_U16},
                  {"int", T_I32},    {"int32", T_I32},   {"uint", T_U32},   {"uint32", T_U32},
                  {"float", T_F32},  {"float32", T_F32}, {"double", T_F64}, {"float64", T_F64}};

static const struct {
    const char *name;
    enum ply_role role;
} vertex_roles[] = {{"x", R_X},         {"y", R_Y},         {"z", R_Z},         {"nx", R_NX},
                    {"ny", R_NY},       {"nz", R_NZ},       {"u", R_U},         {"v", R_V},
                    {"s", R_U},         {"t", R_V},         {"texture_u", R_U}, {"texture_v", R_V},
                    {"texture_s", R_U}, {"texture_t", R_V}};

struct ply_prop {
    char name[PLY_NAME_MAX];
    enum ply_type type;       /* of the value, or of a list's items */
    enum ply_type count_type; /* T_NONE: not a list */
    enum ply_role role;
};

struct ply_elem {
    char name[PLY_NAME_MAX];
    uint64_t count;
    struct ply_prop props[PLY_MAX_PROPS];
    uint32_t num_props;
    uint32_t line;            /* of its "element" line in the header */
};

struct ply {
    const char *file;         /* as shown in messages */
    const uint8_t *p, *end;   /* the body's cursor */
    enum ply_format format;
    uint32_t line;            /* ascii: the line of the cursor */
    struct ply_elem elems[PLY_MAX_ELEMS];
    uint32_t num_elems;
    /* where the body reader is, for messages */
    const struct ply_elem *cur_elem;
    const struct ply_prop *cur_prop;
    uint64_t cur_index;
    char *err;
    size_t errlen;
};

static size_t type_size(enum ply_type t)
{
    static const size_t sizes[] = {0, 1, 1, 2, 2, 4, 4, 4, 8};
    return sizes[t];
}

static bool type_is_int(enum ply_type t) { return t >= T_I8 && t <= T_U32; }

__attribute__((format(printf, 2, 3))) static int ply_fail(struct ply *ply, const char *fmt, ...)
{
    char msg[512], where[256] = "";
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(msg, sizeof msg, fmt, ap);
    va_end(ap);
    if (ply->cur_elem)
        str_fmt(where, sizeof where, "element %s %llu%s%s: ", ply->cur_elem->name,
                (unsigned long long)ply->cur_index, ply->cur_prop ? ", property " : "",
                ply->cur_prop ? ply->cur_prop->name : "");
    if (ply->format == PLY_ASCII || !ply->cur_elem)
        str_fmt(ply->err, ply->errlen, "%s:%u: %s%s", ply->file, ply->line, where, msg);
    else
        str_fmt(ply->err, ply->errlen, "%s: %s%s", ply->file, where, msg);
    return -1;
}

/* ---- Header ---- */

/* The next whitespace-separated word of the line [*p, end) into out (NUL-terminated);
 * 0 when the line has no more words, -1 when one is too long. */
static int header_word(const char **p, const char *end, char *out, size_t outlen)
{
    while (*p < end && (**p == ' ' || **p == '\t'))
        (*p)++;
    size_t n = 0;
    while (*p < end && **p != ' ' && **p != '\t') {
        if (n + 1 >= outlen)
            return -1;
        out[n++] = *(*p)++;
    }
    out[n] = '\0';
    return n > 0;
}

static enum ply_type type_from_name(const char *name)
{
    for (size_t i = 0; i < sizeof type_names / sizeof *type_names; i++)
        if (!strcmp(name, type_names[i].name))
            return type_names[i].type;
    return T_NONE;
}

static int header_property(struct ply *ply, const char *p, const char *end)
{
    if (ply->num_elems == 0)
        return ply_fail(ply, "property before any element");
    struct ply_elem *e = &ply->elems[ply->num_elems - 1];
    if (e->num_props >= PLY_MAX_PROPS)
        return ply_fail(ply, "element %s has more than %d properties", e->name, PLY_MAX_PROPS);
    struct ply_prop *pr = &e->props[e->num_props];
    memset(pr, 0, sizeof *pr);
    char w[PLY_NAME_MAX];
    if (header_word(&p, end, w, sizeof w) != 1)
        return ply_fail(ply, "property needs a type and a name");
    if (!strcmp(w, "list")) {
        char ct[PLY_NAME_MAX];
        if (header_word(&p, end, ct, sizeof ct) != 1 || header_word(&p, end, w, sizeof w) != 1)
            return ply_fail(ply, "property list needs a count type, an item type and a name");
        pr->count_type = type_from_name(ct);
        if (!type_is_int(pr->count_type))
            return ply_fail(ply, "list count type \"%s\" is not an integer type", ct);
    }
    pr->type = type_from_name(w);
    if (pr->type == T_NONE)
        return ply_fail(ply, "unknown property type \"%s\"", w);
    if (header_word(&p, end, pr->name, sizeof pr->name) != 1)
        return ply_fail(ply, "property needs a name (at most %d bytes)", PLY_NAME_MAX - 1);
    if (header_word(&p, end, w, sizeof w) != 0)
        return ply_fail(ply, "property %s: unexpected \"%s\" after its name", pr->name, w);
    for (uint32_t i = 0; i < e->num_props; i++)
        if (!strcmp(e->props[i].name, pr->name))
            return ply_fail(ply, "element %s: property %s defined twice", e->name, pr->name);
    if (!strcmp(e->name, "vertex") && pr->count_type == T_NONE)
        for (size_t i = 0; i < sizeof vertex_roles / sizeof *vertex_roles; i++)
            if (!strcmp(pr->name, vertex_roles[i].name))
                pr->role = vertex_roles[i].role;
    if (!strcmp(e->name, "face") && pr->count_type != T_NONE &&
        (!strcmp(pr->name, "vertex_indices") || !strcmp(pr->name, "vertex_index"))) {
        if (!type_is_int(pr->type))
            return ply_fail(ply, "face property %s: indices must be of an integer type", pr->name);
        pr->role = R_INDICES;
    }
    e->num_props++;
    return 0;
}

/* Reads the header up to end_header; on success ply->p is at the body. */
static int header_parse(struct ply *ply, const uint8_t *data, size_t len)
{
    const char *text = (const char *)data, *end = text + (len < PLY_MAX_HEADER ? len : PLY_MAX_HEADER);
    const char *p = text;
    bool have_format = false;
    ply->line = 0;
    for (;;) {
        const char *nl = memchr(p, '\n', (size_t)(end - p));
        ply->line++;
        if (!nl)
            return ply_fail(ply, "%s", len > PLY_MAX_HEADER ? "header longer than 1 MiB" : "no end_header line");
        const char *le = nl > p && nl[-1] == '\r' ? nl - 1 : nl;
        for (const char *q = p; q < le; q++)
            if ((unsigned char)*q < 0x20 && *q != '\t')
                return ply_fail(ply, "unexpected control byte 0x%02x in the header", (unsigned char)*q);
        char kw[PLY_NAME_MAX];
        const char *q = p;
        int k = header_word(&q, le, kw, sizeof kw);
        p = nl + 1;
        if (ply->line == 1) {
            if (k != 1 || strcmp(kw, "ply") != 0 || header_word(&q, le, kw, sizeof kw) != 0)
                return ply_fail(ply, "not a PLY file (it must start with a line \"ply\")");
            continue;
        }
        if (k == 0)
            continue;
        if (k < 0)
            return ply_fail(ply, "header word too long");
        if (!strcmp(kw, "comment") || !strcmp(kw, "obj_info"))
            continue;
        if (!strcmp(kw, "end_header")) {
            if (!have_format)
                return ply_fail(ply, "no format line before end_header");
            ply->p = (const uint8_t *)p;
            ply->line++; /* the body's first line */
            return 0;
        }
        if (!strcmp(kw, "format")) {
            char f[PLY_NAME_MAX], v[PLY_NAME_MAX];
            if (have_format || header_word(&q, le, f, sizeof f) != 1 || header_word(&q, le, v, sizeof v) != 1 ||
                strcmp(v, "1.0") != 0)
                return ply_fail(ply, "format must be given once, as ascii, binary_little_endian or "
                                     "binary_big_endian, version 1.0");
            if (!strcmp(f, "ascii"))
                ply->format = PLY_ASCII;
            else if (!strcmp(f, "binary_little_endian"))
                ply->format = PLY_BINARY_LE;
            else if (!strcmp(f, "binary_big_endian"))
                ply->format = PLY_BINARY_BE;
            else
                return ply_fail(ply, "unknown format \"%s\"", f);
            have_format = true;
        } else if (!strcmp(kw, "element")) {
            if (ply->num_elems >= PLY_MAX_ELEMS)
                return ply_fail(ply, "more than %d elements", PLY_MAX_ELEMS);
            struct ply_elem *e = &ply->elems[ply->num_elems];
            memset(e, 0, sizeof *e);
            char c[32];
            if (header_word(&q, le, e->name, sizeof e->name) != 1 || header_word(&q, le, c, sizeof c) != 1)
                return ply_fail(ply, "element needs a name and a count");
            char *ce;
            unsigned long long n = strtoull(c, &ce, 10);
            if (*ce || c[0] == '-' || c[0] == '+' || n > PLY_MAX_ELEMENTS)
                return ply_fail(ply, "element %s: count \"%s\" is not a number up to %u", e->name, c,
                                PLY_MAX_ELEMENTS);
            for (uint32_t i = 0; i < ply->num_elems; i++)
                if (!strcmp(ply->elems[i].name, e->name))
                    return ply_fail(ply, "element %s defined twice", e->name);
            e->count = n;
            e->line = ply->line;
            ply->num_elems++;
        } else if (!strcmp(kw, "property")) {
            if (header_property(ply, q, le) != 0)
                return -1;
        } else {
            return ply_fail(ply, "unknown header line \"%s\"", kw);
        }
    }
}

/* ---- Body values ---- */

/* One ascii token as a number of type t. */
static int ascii_value(struct ply *ply, enum ply_type t, double *out)
{
    for (;;) {
        if (ply->p >= ply->end) {
            if (ply->line > 1 && ply->p[-1] == '\n')
                ply->line--; /* name the last line, not the empty one after it */
            return ply_fail(ply, "the file ends early");
        }
        uint8_t c = *ply->p;
        if (c == '\n')
            ply->line++;
        else if (c != ' ' && c != '\t' && c != '\r')
            break;
        ply->p++;
    }
    char tok[72];
    size_t n = 0;
    while (ply->p < ply->end && *ply->p != ' ' && *ply->p != '\t' && *ply->p != '\r' && *ply->p != '\n') {
        uint8_t c = *ply->p;
        if (!((c >= '0' && c <= '9') || c == '-' || c == '+' || c == '.' || c == 'e' || c == 'E'))
            return ply_fail(ply, "malformed number (byte 0x%02x)", c);
        if (n + 1 >= sizeof tok)
            return ply_fail(ply, "number longer than %zu characters", sizeof tok - 1);
        tok[n++] = (char)c;
        ply->p++;
    }
    tok[n] = '\0';
    char *e;
    if (type_is_int(t)) {
        long long v = strtoll(tok, &e, 10);
        if (*e || e == tok)
            return ply_fail(ply, "malformed integer \"%s\"", tok);
        static const long long lo[] = {0, -128, 0, -32768, 0, -2147483648LL, 0};
        static const long long hi[] = {0, 127, 255, 32767, 65535, 2147483647LL, 4294967295LL};
        if (v < lo[t] || v > hi[t])
            return ply_fail(ply, "integer %s out of its type's range", tok);
        *out = (double)v;
        return 0;
    }
    double v = strtod(tok, &e);
    if (*e || e == tok || !isfinite(v))
        return ply_fail(ply, "malformed number \"%s\"", tok);
    if (t == T_F32 && !isfinite((float)v))
        return ply_fail(ply, "number %s out of float's range", tok);
    *out = t == T_F32 ? (double)(float)v : v;
    return 0;
}

static int binary_value(struct ply *ply, enum ply_type t, double *out)
{
    size_t n = type_size(t);
    if ((size_t)(ply->end - ply->p) < n)
        return ply_fail(ply, "the file ends early");
    uint8_t b[8];
    if (ply->format == PLY_BINARY_LE)
        memcpy(b, ply->p, n);
    else
        for (size_t i = 0; i < n; i++)
            b[i] = ply->p[n - 1 - i];
    ply->p += n;
    switch (t) {
    case T_I8: *out = (int8_t)b[0]; break;
    case T_U8: *out = b[0]; break;
    case T_I16: *out = (int16_t)bytes_get_u16(b); break;
    case T_U16: *out = bytes_get_u16(b); break;
    case T_I32: *out = (int32_t)bytes_get_u32(b); break;
    case T_U32: *out = bytes_get_u32(b); break;
    case T_F32: {
        uint32_t u = bytes_get_u32(b);
        float f;
        memcpy(&f, &u, 4);
        *out = f;
        break;
    }
    case T_F64: {
        uint64_t u = bytes_get_u64(b);
        memcpy(out, &u, 8);
        break;
    }
    default: return ply_fail(ply, "bad type");
    }
    return 0;
}

static inline int read_value(struct ply *ply, enum ply_type t, double *out)
{
    return ply->format == PLY_ASCII ? ascii_value(ply, t, out) : binary_value(ply, t, out);
}

/* ---- Body ---- */

/* The least bytes one instance of e takes: its scalars' and list counts' sizes (binary),
 * two bytes a value (ascii: a digit and a separator). */
static uint64_t elem_min_bytes(const struct ply *ply, const struct ply_elem *e)
{
    uint64_t n = 0;
    for (uint32_t i = 0; i < e->num_props; i++) {
        const struct ply_prop *pr = &e->props[i];
        n += ply->format == PLY_ASCII ? 2 : type_size(pr->count_type != T_NONE ? pr->count_type : pr->type);
    }
    return n;
}

struct ply_out {
    struct mesh_arrays a;
    size_t num_corners, cap_corners, cap_faces;
    uint64_t num_vertices;    /* the vertex element's count (indices are checked against it) */
};

/* A list whose items are read and dropped. */
static int skip_list(struct ply *ply, const struct ply_prop *pr)
{
    double n, v;
    if (read_value(ply, pr->count_type, &n) != 0)
        return -1;
    if (n < 0)
        return ply_fail(ply, "negative list count %.0f", n);
    for (uint64_t j = 0; j < (uint64_t)n; j++)
        if (read_value(ply, pr->type, &v) != 0)
            return -1;
    return 0;
}

static int read_vertex(struct ply *ply, const struct ply_elem *e, uint64_t i, struct ply_out *o)
{
    for (uint32_t k = 0; k < e->num_props; k++) {
        const struct ply_prop *pr = &e->props[k];
        ply->cur_prop = pr;
        double v;
        if (pr->count_type != T_NONE) {
            if (skip_list(ply, pr) != 0)
                return -1;
            continue;
        }
        if (read_value(ply, pr->type, &v) != 0)
            return -1;
        if (pr->role == R_NONE)
            continue;
        if (!isfinite(v) || fabs(v) > 1e30)
            return ply_fail(ply, "not a finite number of sane size");
        switch (pr->role) {
        case R_X: case R_Y: case R_Z: o->a.positions[3 * i + (size_t)(pr->role - R_X)] = v; break;
        case R_NX: case R_NY: case R_NZ:
            if (o->a.normals)
                o->a.normals[3 * i + (size_t)(pr->role - R_NX)] = (float)v;
            break;
        case R_U: case R_V:
            if (o->a.uvs)
                o->a.uvs[2 * i + (size_t)(pr->role - R_U)] = (float)v;
            break;
        default: break;
        }
    }
    ply->cur_prop = NULL;
    return 0;
}

static int read_face(struct ply *ply, const struct ply_elem *e, struct ply_out *o)
{
    bool have_indices = false;
    for (uint32_t k = 0; k < e->num_props; k++) {
        const struct ply_prop *pr = &e->props[k];
        ply->cur_prop = pr;
        double v;
        if (pr->role != R_INDICES) {
            if (pr->count_type != T_NONE ? skip_list(ply, pr) != 0 : read_value(ply, pr->type, &v) != 0)
                return -1;
            continue;
        }
        if (have_indices)
            return ply_fail(ply, "the face has a second vertex index list");
        have_indices = true;
        double nd;
        if (read_value(ply, pr->count_type, &nd) != 0)
            return -1;
        if (!(nd >= 3 && nd <= PLY_MAX_FACE_CORNERS))
            return ply_fail(ply, "%.0f corners (a face has 3 to %u)", nd, PLY_MAX_FACE_CORNERS);
        size_t n = (size_t)nd;
        if (o->num_corners + n > PLY_MAX_ELEMENTS)
            return ply_fail(ply, "more than %u face corners in all", PLY_MAX_ELEMENTS);
        mem_grow((void **)&o->a.face_corners, &o->cap_corners, o->num_corners + n, sizeof *o->a.face_corners);
        for (size_t j = 0; j < n; j++) {
            if (read_value(ply, pr->type, &v) != 0)
                return -1;
            if (!(v >= 0 && v < (double)o->num_vertices))
                return ply_fail(ply, "vertex index %.0f out of range (%llu vertices)", v,
                                (unsigned long long)o->num_vertices);
            o->a.face_corners[o->num_corners + j] = (uint32_t)v;
        }
        o->a.face_sizes[o->a.num_faces++] = (uint32_t)n;
        o->num_corners += n;
    }
    ply->cur_prop = NULL;
    if (!have_indices)
        return ply_fail(ply, "no vertex_indices list");
    return 0;
}

/* Sets up the arrays the vertex and face elements fill. */
static int out_init(struct ply *ply, struct ply_out *o, const struct ply_elem **vertex, const struct ply_elem **face)
{
    *vertex = *face = NULL;
    for (uint32_t i = 0; i < ply->num_elems; i++) {
        const struct ply_elem *e = &ply->elems[i];
        uint64_t min = elem_min_bytes(ply, e), left = (uint64_t)(ply->end - ply->p);
        ply->line = e->line; /* errors here point at the element's header line */
        if (min > 0 && e->count > left / min)
            return ply_fail(ply, "element %s: %llu of them cannot fit in the %llu bytes left", e->name,
                            (unsigned long long)e->count, (unsigned long long)left);
        if (!strcmp(e->name, "vertex"))
            *vertex = e;
        else if (!strcmp(e->name, "face"))
            *face = e;
    }
    if (!*vertex)
        return ply_fail(ply, "no vertex element");
    ply->line = (*vertex)->line;
    uint32_t roles = 0;
    for (uint32_t k = 0; k < (*vertex)->num_props; k++)
        roles |= 1u << (*vertex)->props[k].role;
    const uint32_t xyz = (1u << R_X) | (1u << R_Y) | (1u << R_Z), nrm = (1u << R_NX) | (1u << R_NY) | (1u << R_NZ),
                   uv = (1u << R_U) | (1u << R_V);
    if ((roles & xyz) != xyz)
        return ply_fail(ply, "element vertex: properties x, y and z are required");
    size_t nv = (size_t)(*vertex)->count;
    o->num_vertices = nv;
    o->a.num_vertices = nv;
    o->a.positions = mem_calloc(nv ? 3 * nv : 1, sizeof *o->a.positions);
    if ((roles & nrm) == nrm)
        o->a.normals = mem_calloc(nv ? 3 * nv : 1, sizeof *o->a.normals);
    if ((roles & uv) == uv)
        o->a.uvs = mem_calloc(nv ? 2 * nv : 1, sizeof *o->a.uvs);
    if (*face) {
        ply->line = (*face)->line;
        bool indices = false;
        for (uint32_t k = 0; k < (*face)->num_props; k++)
            indices |= (*face)->props[k].role == R_INDICES;
        if (!indices)
            return ply_fail(ply, "element face: no list property vertex_indices (or vertex_index)");
        o->a.face_sizes = mem_alloc((*face)->count ? (size_t)(*face)->count * sizeof *o->a.face_sizes : 1);
        /* A triangle mesh's corners, allocated once (more grow as needed). */
        o->cap_corners = (size_t)(*face)->count * 3;
        o->a.face_corners = mem_alloc(o->cap_corners ? o->cap_corners * sizeof *o->a.face_corners : 1);
    }
    return 0;
}

static void out_fini(struct ply_out *o)
{
    free(o->a.positions);
    free(o->a.normals);
    free(o->a.uvs);
    free(o->a.face_sizes);
    free(o->a.face_corners);
}

int mesh_ply_parse(struct scene *scene, struct mesh_obj_cache *cache, const char *rel_path, const uint8_t *data,
                   size_t len, const struct mesh_obj_options *opt_in, char *err, size_t errlen)
{
    struct mesh_obj_options opt = opt_in ? *opt_in : mesh_obj_default_options();
    char file[ASSET_PATH_MAX + 1024];
    str_fmt(file, sizeof file, "%s%s", opt.display_dir ? opt.display_dir : "", rel_path);
    struct ply *ply = mem_calloc(1, sizeof *ply);
    ply->file = file;
    ply->err = err;
    ply->errlen = errlen;
    ply->end = data + len;
    struct ply_out o;
    memset(&o, 0, sizeof o);
    const struct ply_elem *vertex, *face;
    int rc = -1;
    if (header_parse(ply, data, len) != 0)
        goto done;
    uint32_t body_line = ply->line;
    if (out_init(ply, &o, &vertex, &face) != 0)
        goto done;
    ply->line = body_line;
    /* A vertex element after the face element: indices are still checked against its
     * declared count. */
    for (uint32_t k = 0; k < ply->num_elems; k++) {
        const struct ply_elem *e = &ply->elems[k];
        ply->cur_elem = e;
        for (uint64_t i = 0; i < e->count && e->num_props > 0; i++) {
            ply->cur_index = i;
            if ((i & 0xfffff) == 0 && i && asset_stop_requested()) {
                ply_fail(ply, "interrupted");
                goto done;
            }
            int r;
            if (e == vertex) {
                r = read_vertex(ply, e, i, &o);
            } else if (e == face) {
                r = read_face(ply, e, &o);
            } else {
                r = 0;
                for (uint32_t p = 0; p < e->num_props && r == 0; p++) {
                    double v;
                    ply->cur_prop = &e->props[p];
                    r = e->props[p].count_type != T_NONE ? skip_list(ply, &e->props[p])
                                                         : read_value(ply, e->props[p].type, &v);
                }
                ply->cur_prop = NULL;
            }
            if (r != 0)
                goto done;
        }
    }
    ply->cur_elem = NULL;
    if (!face || o.a.num_faces == 0) {
        log_warn("%s: no faces, nothing to render", file);
        rc = 0;
        goto done;
    }
    rc = mesh_obj_from_arrays(scene, cache, &o.a, &opt, rel_path, err, errlen);
done:
    out_fini(&o);
    free(ply);
    return rc;
}
