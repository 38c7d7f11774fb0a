/* Unit tests of the PLY reader (common/scene/mesh_ply.c): the same quad in ascii, binary
 * little- and big-endian gives the same mesh; every index and count type; uv names (u v,
 * s t, texture_u texture_v); polygons triangulated; elements and properties the renderer
 * does not use are skipped; and each malformed file is refused with a message naming
 * the file, the element and property (and the line, for ascii). */
#include <criterion/criterion.h>
#include <math.h>
#include <stdio.h>
#include <string.h>
#include "scene/mesh_ply.h"

static int parse(const void *data, size_t len, struct scene *s, char *err)
{
    struct mesh_obj_cache cache = {0};
    int rc = mesh_ply_parse(s, &cache, "m.ply", data, len, NULL, err, 512);
    mesh_obj_cache_fini(&cache);
    return rc;
}

static void expect_error(const void *data, size_t len, const char *want)
{
    struct scene s = {0};
    char err[512] = "";
    cr_assert_eq(parse(data, len, &s, err), -1, "expected failure for: %.*s", (int)(len > 300 ? 300 : len),
                 (const char *)data);
    cr_expect(strstr(err, want) != NULL, "error \"%s\" lacks \"%s\"", err, want);
    cr_expect_eq(s.num_meshes, 0);
    scene_fini(&s);
}

static void expect_text_error(const char *text, const char *want) { expect_error(text, strlen(text), want); }

/* A little binary writer. */
struct buf { uint8_t b[4096]; size_t n; int be; };
static void put(struct buf *w, const void *v, size_t n)
{
    for (size_t i = 0; i < n; i++)
        w->b[w->n + i] = ((const uint8_t *)v)[w->be ? n - 1 - i : i];
    w->n += n;
}
static void put_text(struct buf *w, const char *t) { memcpy(w->b + w->n, t, strlen(t)); w->n += strlen(t); }
static void put_f(struct buf *w, float f) { put(w, &f, 4); }
static void put_d(struct buf *w, double d) { put(w, &d, 8); }
static void put_u8(struct buf *w, uint8_t v) { put(w, &v, 1); }
static void put_i32(struct buf *w, int32_t v) { put(w, &v, 4); }
static void put_u16(struct buf *w, uint16_t v) { put(w, &v, 2); }

static const float quad_p[4][3] = {{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0}};

/* The quad with normals and uvs, vertex x y z as float, nx ny nz as double, uvs as s t
 * floats, an extra "confidence" uchar, the face list uchar/int, one extra element. */
static size_t binary_quad(struct buf *w, int be)
{
    memset(w, 0, sizeof *w);
    w->be = be;
    put_text(w, be ? "ply\nformat binary_big_endian 1.0\n" : "ply\r\nformat binary_little_endian 1.0\r\n");
    put_text(w, "comment made by a test\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\n"
                "property double nx\nproperty double ny\nproperty double nz\nproperty float s\nproperty float t\n"
                "property uchar confidence\nelement face 1\nproperty list uchar int vertex_indices\n"
                "element edge 1\nproperty int vertex1\nproperty int vertex2\nend_header\n");
    for (int i = 0; i < 4; i++) {
        for (int k = 0; k < 3; k++)
            put_f(w, quad_p[i][k]);
        put_d(w, 0.0);
        put_d(w, 0.0);
        put_d(w, 1.0);
        put_f(w, quad_p[i][0]);
        put_f(w, quad_p[i][1]);
        put_u8(w, 200);
    }
    put_u8(w, 4);
    for (int i = 0; i < 4; i++)
        put_i32(w, i);
    put_i32(w, 0);
    put_i32(w, 1);
    return w->n;
}

static const char ascii_quad[] =
    "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\n"
    "property float nx\nproperty float ny\nproperty float nz\nproperty float s\nproperty float t\n"
    "property uchar confidence\nelement face 1\nproperty list uchar int vertex_indices\n"
    "element edge 1\nproperty int vertex1\nproperty int vertex2\nend_header\n"
    "0 0 0 0 0 1 0 0 200\n1 0 0 0 0 1 1 0 200\n1 1 0 0 0 1 1 1 200\n0 1 0 0 0 1 0 1 200\n4 0 1 2 3\n0 1\n";

static void check_quad(const struct scene *s)
{
    cr_assert_eq(s->num_meshes, 1);
    const struct mesh *m = &s->meshes[0];
    cr_assert_eq(m->num_vertices, 4);
    cr_assert_eq(m->num_triangles, 2);
    cr_assert_not_null(m->normals);
    cr_assert_not_null(m->uvs);
    const uint32_t want[6] = {0, 1, 2, 0, 2, 3};
    for (int i = 0; i < 6; i++)
        cr_expect_eq(m->indices[i], want[i]);
    for (uint32_t v = 0; v < 4; v++) {
        for (int k = 0; k < 3; k++)
            cr_expect_eq(m->positions[3 * v + k], quad_p[v][k]);
        cr_expect_eq(m->normals[3 * v + 2], 1.0f);
        cr_expect_eq(m->uvs[2 * v], quad_p[v][0]);
        cr_expect_eq(m->uvs[2 * v + 1], quad_p[v][1]);
    }
    cr_expect_str_eq(s->materials[m->material_ids[0]].name, "default");
}

Test(mesh_ply, ascii_and_both_binary_orders_give_the_same_quad)
{
    char err[512];
    struct scene s = {0};
    cr_assert_eq(parse(ascii_quad, strlen(ascii_quad), &s, err), 0, "%s", err);
    check_quad(&s);
    scene_fini(&s);
    struct buf w;
    for (int be = 0; be < 2; be++) {
        size_t n = binary_quad(&w, be);
        cr_assert_eq(parse(w.b, n, &s, err), 0, "%s", err);
        check_quad(&s);
        scene_fini(&s);
    }
}

Test(mesh_ply, uv_names_count_types_and_polygons)
{
    static const char *const uv[][2] = {{"u", "v"}, {"s", "t"}, {"texture_u", "texture_v"}, {"texture_s", "texture_t"}};
    static const char *const lists[] = {"uchar int", "uint8 uint32", "ushort int", "int uint", "char short"};
    for (int i = 0; i < 4; i++) {
        char text[1024];
        snprintf(text, sizeof text,
                 "ply\nformat ascii 1.0\nelement vertex 5\nproperty double x\nproperty double y\nproperty double z\n"
                 "property float %s\nproperty float %s\nelement face 1\nproperty list %s vertex_index\nend_header\n"
                 "0 0 0 0 0\n2 0 0 1 0\n3 1 0 1 0.5\n2 2 0 1 1\n0 2 0 0 1\n5 0 1 2 3 4\n",
                 uv[i][0], uv[i][1], lists[i]);
        struct scene s = {0};
        char err[512];
        cr_assert_eq(parse(text, strlen(text), &s, err), 0, "%s: %s", uv[i][0], err);
        const struct mesh *m = &s.meshes[0];
        cr_expect_eq(m->num_triangles, 3, "a pentagon is 3 triangles");
        cr_assert_not_null(m->uvs, "%s %s read as uvs", uv[i][0], uv[i][1]);
        cr_expect_eq(m->uvs[2 * 2 + 1], 0.5f);
        cr_expect_null(m->normals);
        scene_fini(&s);
    }
    /* A concave face is ear-clipped: every triangle faces +z like the polygon. */
    const char *concave = "ply\nformat ascii 1.0\nelement vertex 6\nproperty float x\nproperty float y\nproperty float z\n"
                          "element face 1\nproperty list uchar int vertex_indices\nend_header\n"
                          "1 1 0\n1 2 0\n0 2 0\n0 0 0\n2 0 0\n2 1 0\n6 0 1 2 3 4 5\n";
    struct scene s = {0};
    char err[512];
    cr_assert_eq(parse(concave, strlen(concave), &s, err), 0, "%s", err);
    const struct mesh *m = &s.meshes[0];
    cr_assert_eq(m->num_triangles, 4);
    for (uint32_t t = 0; t < 4; t++) {
        const float *a = &m->positions[3 * m->indices[3 * t]], *b = &m->positions[3 * m->indices[3 * t + 1]],
                    *c = &m->positions[3 * m->indices[3 * t + 2]];
        float z = (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]);
        cr_expect_gt(z, 0.0f, "triangle %u faces -z", t);
    }
    scene_fini(&s);
}

Test(mesh_ply, header_errors)
{
    expect_text_error("plx\nformat ascii 1.0\nend_header\n", "m.ply:1: not a PLY file");
    expect_text_error("ply\nformat ascii 2.0\nend_header\n", "m.ply:2: format must be given once");
    expect_text_error("ply\nformat binary_middle_endian 1.0\nend_header\n", "m.ply:2: unknown format \"binary_middle_endian\"");
    expect_text_error("ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\n", "m.ply:5: no end_header");
    expect_text_error("ply\nformat ascii 1.0\nelement vertex -3\nend_header\n", "m.ply:3: element vertex: count \"-3\"");
    expect_text_error("ply\nformat ascii 1.0\nelement vertex 99999999999\nend_header\n", "count \"99999999999\"");
    expect_text_error("ply\nformat ascii 1.0\nelement vertex 1\nproperty quad x\nend_header\n",
                      "m.ply:4: unknown property type \"quad\"");
    expect_text_error("ply\nformat ascii 1.0\nelement face 1\nproperty list float int vertex_indices\nend_header\n",
                      "m.ply:4: list count type \"float\" is not an integer type");
    expect_text_error("ply\nformat ascii 1.0\nelement face 1\nproperty list uchar float vertex_indices\nend_header\n",
                      "indices must be of an integer type");
    expect_text_error("ply\nformat ascii 1.0\nproperty float x\nend_header\n", "m.ply:3: property before any element");
    expect_text_error("ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nend_header\n0 0\n",
                      "properties x, y and z are required");
    expect_text_error("ply\nformat ascii 1.0\nelement face 0\nproperty list uchar int vertex_indices\nend_header\n",
                      "no vertex element");
    expect_text_error("ply\nformat ascii 1.0\nbogus\nend_header\n", "m.ply:3: unknown header line \"bogus\"");
    /* UTF-16 (a byte-order mark, then NULs). */
    expect_error("\xff\xfep\0l\0y\0\n\0", 10, "m.ply:1: unexpected control byte 0x00 in the header");
}

static const char ascii_head[] = "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
                                 "property float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n";

Test(mesh_ply, body_errors_name_element_property_and_line)
{
    static const char *const cases[][2] = {
        {"0 0 0\n1 0 0\n0 1 0\n3 0 1 3\n", "m.ply:13: element face 0, property vertex_indices: vertex index 3 out of range (3 vertices)"},
        {"0 0 0\n1 0 x\n0 1 0\n3 0 1 2\n", "m.ply:11: element vertex 1, property z: malformed number"},
        {"0 0 0\n1 0 nan\n0 1 0\n3 0 1 2\n", "element vertex 1, property z: malformed number"},
        {"0 0 0\n1 0 0\n0 1 0\n2 0 1\n", "element face 0, property vertex_indices: 2 corners (a face has 3 to 65535)"},
        {"0 0 0\n1 0 0\n0 1 0\n300 0 1 2\n", "property vertex_indices: integer 300 out of its type's range"},
        {"0 0 0\n1 0 0\n0 1 0\n3 0 1\n", "m.ply:13: element face 0, property vertex_indices: the file ends early"},
        {"0 0 0\n1 0 0\n0 1 0\n3 0 -1 2\n", "vertex index -1 out of range"},
    };
    for (size_t i = 0; i < sizeof cases / sizeof *cases; i++) {
        char t[1024];
        snprintf(t, sizeof t, "%s%s", ascii_head, cases[i][0]);
        expect_text_error(t, cases[i][1]);
    }
    /* Counts are checked against the bytes left before anything is allocated. */
    expect_text_error("ply\nformat binary_little_endian 1.0\nelement vertex 100000000\nproperty float x\n"
                      "property float y\nproperty float z\nend_header\n\1\2\3",
                      "element vertex: 100000000 of them cannot fit in the 3 bytes left");
    /* Truncated binary data names the element and property. */
    struct buf w;
    size_t n = binary_quad(&w, 0);
    expect_error(w.b, n - 10, "m.ply: element face 0, property vertex_indices: the file ends early");
    /* A binary float index list and a huge list count. */
    n = binary_quad(&w, 1);
    w.b[n - 8 - 17] = 0xff; /* the face's corner count: 255, more than the bytes left */
    expect_error(w.b, n, "element face 0, property vertex_indices");
}

Test(mesh_ply, binary_types_and_ushort_counts)
{
    struct buf w;
    memset(&w, 0, sizeof w);
    put_text(&w, "ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty short x\nproperty ushort y\n"
                 "property char z\nelement face 1\nproperty list ushort uint vertex_indices\nend_header\n");
    int16_t xs[3] = {-2, 4, -2};
    uint16_t ys[3] = {0, 0, 60000};
    int8_t zs[3] = {-1, -1, 127};
    for (int i = 0; i < 3; i++) {
        put(&w, &xs[i], 2);
        put_u16(&w, ys[i]);
        put(&w, &zs[i], 1);
    }
    put_u16(&w, 3);
    for (uint32_t i = 0; i < 3; i++)
        put(&w, &i, 4);
    struct scene s = {0};
    char err[512];
    cr_assert_eq(parse(w.b, w.n, &s, err), 0, "%s", err);
    const struct mesh *m = &s.meshes[0];
    cr_expect_eq(m->positions[0], -2.0f);
    cr_expect_eq(m->positions[3 * 2 + 1], 60000.0f);
    cr_expect_eq(m->positions[3 * 2 + 2], 127.0f);
    scene_fini(&s);
}
