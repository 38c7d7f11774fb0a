/* Unit tests of the OBJ/MTL reader (common/scene/mesh_obj.c): every face form, relative
 * indices, polygons, CRLF, transforms, materials, and that each error names the right
 * file:line:col. Files come from an in-memory asset source. */
#include <criterion/criterion.h>
#include <math.h>
#include <stdio.h>
#include <unistd.h>
#include <string.h>
#include "scene/mesh_obj.h"
#include "helpers.h"

/* Parses text as "m.obj" with files as the rest of the folder; returns the rc. */
static int parse(const char *text, const struct mem_file *files, const struct mesh_obj_options *opt,
                 struct scene *s, char *err)
{
    struct asset_source src = {mem_read, (void *)(uintptr_t)files};
    struct mesh_obj_cache cache = {0};
    int rc = mesh_obj_parse(s, &cache, &src, "m.obj", text, strlen(text), opt, err, 512);
    mesh_obj_cache_fini(&cache);
    return rc;
}

static void expect_error(const char *text, const struct mem_file *files, const char *want)
{
    struct scene s = {0};
    char err[512] = "";
    cr_assert_eq(parse(text, files, NULL, &s, err), -1, "expected failure for: %s", text);
    cr_expect(strstr(err, want) != NULL, "error \"%s\" lacks \"%s\"", err, want);
    scene_fini(&s);
}

static const char quad[] = "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\n";

Test(mesh_obj, plain_faces_and_default_material)
{
    struct scene s = {0};
    char err[512];
    char text[256];
    snprintf(text, sizeof text, "%sf 1 2 3\nf 1 3 4\n", quad);
    cr_assert_eq(parse(text, NULL, NULL, &s, err), 0, "%s", err);
    cr_assert_eq(s.num_meshes, 1);
    struct mesh *m = &s.meshes[0];
    cr_expect_eq(m->num_vertices, 4);
    cr_expect_eq(m->num_triangles, 2);
    cr_expect_null(m->normals);
    cr_expect_null(m->uvs);
    cr_expect_str_eq(m->name, "m.obj");
    uint32_t want[6] = {0, 1, 2, 0, 2, 3};
    for (int i = 0; i < 6; i++)
        cr_expect_eq(m->indices[i], want[i]);
    cr_assert_eq(s.num_materials, 1);
    cr_expect_eq(m->material_ids[0], 0);
    cr_expect_float_eq(s.materials[0].albedo.x, 0.8f, 1e-6);
    cr_expect(v3_is_black(s.materials[0].emission));
    scene_fini(&s);
}

Test(mesh_obj, all_face_forms)
{
    struct scene s = {0};
    char err[512];
    const char *text = "v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 0 1\nvn 0 0 1\n"
                       "f 1/1/1 2/2/1 3/3/1\n";
    cr_assert_eq(parse(text, NULL, NULL, &s, err), 0, "%s", err);
    cr_assert_not_null(s.meshes[0].normals);
    cr_assert_not_null(s.meshes[0].uvs);
    cr_expect_float_eq(s.meshes[0].uvs[2], 1.0f, 1e-6);
    cr_expect_float_eq(s.meshes[0].normals[2], 1.0f, 1e-6);
    scene_fini(&s);

    text = "v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 0 1\nf 1/1 2/2 3/3\n";
    cr_assert_eq(parse(text, NULL, NULL, &s, err), 0, "%s", err);
    cr_expect_null(s.meshes[0].normals);
    cr_expect_not_null(s.meshes[0].uvs);
    scene_fini(&s);

    text = "v 0 0 0\nv 1 0 0\nv 0 1 0\nvn 0 0 1\nf 1//1 2//1 3//1\n";
    cr_assert_eq(parse(text, NULL, NULL, &s, err), 0, "%s", err);
    cr_expect_not_null(s.meshes[0].normals);
    cr_expect_null(s.meshes[0].uvs);
    scene_fini(&s);

    /* Mixed forms: attributes missing at some corner are dropped for the whole mesh. */
    text = "v 0 0 0\nv 1 0 0\nv 0 1 0\nvn 0 0 1\nf 1//1 2 3//1\n";
    cr_assert_eq(parse(text, NULL, NULL, &s, err), 0, "%s", err);
    cr_expect_null(s.meshes[0].normals);
    scene_fini(&s);
}

Test(mesh_obj, negative_indices_and_polygons)
{
    struct scene s = {0};
    char err[512];
    const char *text = "v 0 0 0\nv 1 0 0\nv 2 1 0\nv 1 2 0\nv 0 1 0\nf -5 -4 -3 -2 -1\n";
    cr_assert_eq(parse(text, NULL, NULL, &s, err), 0, "%s", err);
    struct mesh *m = &s.meshes[0];
    cr_assert_eq(m->num_triangles, 3);
    uint32_t want[9] = {0, 1, 2, 0, 2, 3, 0, 3, 4};
    for (int i = 0; i < 9; i++)
        cr_expect_eq(m->indices[i], want[i]);
    cr_expect_float_eq(m->positions[3 * 2], 2.0f, 1e-6);
    scene_fini(&s);

    /* Relative indices count from the vertices read so far. */
    text = "v 0 0 0\nv 1 0 0\nv 0 1 0\nf -3 -2 -1\nv 5 5 5\nf -4 -3 -1\n";
    cr_assert_eq(parse(text, NULL, NULL, &s, err), 0, "%s", err);
    cr_expect_eq(s.meshes[0].num_vertices, 4);
    cr_expect_float_eq(s.meshes[0].positions[3 * s.meshes[0].indices[5]], 5.0f, 1e-6);
    scene_fini(&s);
}

Test(mesh_obj, crlf_comments_and_ignored_statements)
{
    struct scene s = {0};
    char err[512];
    const char *text = "# comment\r\no thing\r\ng group a\r\ns off\r\nv 0 0 0 1\r\nv 1 0 0  # trailing\r\n"
                       "v 0 1 0\r\nl 1 2\r\n\r\n   \r\nf 1 2 3\r\n";
    cr_assert_eq(parse(text, NULL, NULL, &s, err), 0, "%s", err);
    cr_expect_eq(s.meshes[0].num_triangles, 1);
    scene_fini(&s);
}

Test(mesh_obj, empty_file_gives_no_mesh)
{
    struct scene s = {0};
    char err[512];
    cr_assert_eq(parse("", NULL, NULL, &s, err), 0);
    cr_expect_eq(s.num_meshes, 0);
    cr_expect_eq(s.num_materials, 0);
    scene_fini(&s);
}

Test(mesh_obj, vertex_sharing)
{
    struct scene s = {0};
    char err[512];
    /* The same (v, vt) pair is one vertex; the same v with another vt is a second one. */
    const char *text = "v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nvt 1 1\nf 1/1 2/1 3/1\nf 1/1 3/1 2/2\n";
    cr_assert_eq(parse(text, NULL, NULL, &s, err), 0, "%s", err);
    cr_expect_eq(s.meshes[0].num_vertices, 4);
    scene_fini(&s);
}

Test(mesh_obj, errors_name_line_and_column)
{
    expect_error("v 0 0 0\nv 1 0 x\n", NULL, "m.obj:2:7: malformed number \"x\"");
    expect_error("v 0 0 0\nv 1 0 1e\n", NULL, "m.obj:2:7: malformed number");
    expect_error("v 0 0 nan\n", NULL, "m.obj:1:7: malformed number");
    expect_error("v 0 0 1e999\n", NULL, "m.obj:1:7: number \"1e999\" out of range");
    expect_error("v 0 0\n", NULL, "m.obj:1:6: v needs at least 3 numbers, got 2");
    expect_error("v 0 0 0 1 2\n", NULL, "m.obj:1:1: v takes 3, 4 or 6 numbers");
    expect_error("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 4\n", NULL, "m.obj:4:7: vertex index 4 out of range (3");
    expect_error("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 -4\n", NULL, "m.obj:4:7: vertex index -4 out of range");
    expect_error("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 0 1 2\n", NULL, "m.obj:4:3: vertex index 0 is invalid");
    expect_error("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1/2 2 3\n", NULL, "m.obj:4:5: texture coordinate index 2 out of range");
    expect_error("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1//1 2 3\n", NULL, "m.obj:4:6: normal index 1 out of range");
    expect_error("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1/ 2 3\n", NULL, "m.obj:4:3: face corner \"1/\" ends with '/'");
    expect_error("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1/1/1/1 2 3\n", NULL, "m.obj:4:3: face corner");
    expect_error("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1a 2 3\n", NULL, "m.obj:4:3: malformed vertex index \"1a\"");
    expect_error("v 0 0 0\nv 1 0 0\nf 1 2\n", NULL, "m.obj:3:6: face needs at least 3 corners, got 2");
    expect_error("v 0 0 0\nfoo 1 2\n", NULL, "m.obj:2:1: unknown statement \"foo\"");
    expect_error("v 0 0 0\r\nv 0 \x01 0\r\n", NULL, "m.obj:2:5: unexpected control byte 0x01");
    /* Columns count characters, not bytes. */
    expect_error("usemtl \xc3\xa9\x01\n", NULL, "m.obj:1:9: unexpected control byte 0x01");
}

Test(mesh_obj, materials_from_mtl)
{
    static const struct mem_file files[] = {
        {"m.mtl", "# lib\nnewmtl red\nKa 0 0 0\nKd 1 0 0\nKs 0 0 0\nNs 10\nNi 1.5\nd 1\nillum 2\n"
                  "map_Ks red.png\nnewmtl glow\nKd 0.5\nKe 4 5 6\nmap_Ks x.png\n", 0},
        {NULL, NULL, 0}};
    struct scene s = {0};
    char err[512];
    const char *text = "mtllib m.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\nusemtl glow\nf 1 2 3\n"
                       "usemtl red\nf 1 2 3\n";
    cr_assert_eq(parse(text, files, NULL, &s, err), 0, "%s", err);
    cr_assert_eq(s.num_materials, 3);  /* red, glow, then the default for the first face */
    cr_expect_str_eq(s.materials[0].name, "m.mtl:red");
    cr_expect_str_eq(s.materials[1].name, "m.mtl:glow");
    cr_expect_float_eq(s.materials[0].albedo.x, 1.0f, 1e-6);
    cr_expect_float_eq(s.materials[0].albedo.y, 0.0f, 1e-6);
    cr_expect_float_eq(s.materials[1].albedo.z, 0.5f, 1e-6);
    cr_expect_float_eq(s.materials[1].emission.y, 5.0f, 1e-6);
    const struct mesh *m = &s.meshes[0];
    cr_expect_eq(m->material_ids[0], 2);
    cr_expect_eq(m->material_ids[1], 1);
    cr_expect_eq(m->material_ids[2], 0);
    scene_fini(&s);
}

Test(mesh_obj, mtl_errors)
{
    static const struct mem_file bad_kd[] = {{"m.mtl", "newmtl a\nKd 1.5 0 0\n", 0}, {NULL, NULL, 0}};
    static const struct mem_file early[] = {{"m.mtl", "\n  Kd 1 1 1\n", 0}, {NULL, NULL, 0}};
    static const struct mem_file twice[] = {{"m.mtl", "newmtl a\nnewmtl a\n", 0}, {NULL, NULL, 0}};
    static const struct mem_file bad_num[] = {{"m.mtl", "newmtl a\nKe 1 2 q\n", 0}, {NULL, NULL, 0}};
    expect_error("mtllib m.mtl\n", bad_kd, "m.mtl:2:4: Kd components must be in [0, 1]");
    expect_error("mtllib m.mtl\n", early, "m.mtl:2:3: Kd before any newmtl");
    expect_error("mtllib m.mtl\n", twice, "m.mtl:2:8: material \"a\" defined twice");
    expect_error("mtllib m.mtl\n", bad_num, "m.mtl:2:8: malformed number \"q\"");
    expect_error("mtllib missing.mtl\n", NULL, "m.obj:1:8: cannot read MTL file: missing.mtl: No such file");
    expect_error("mtllib ../up.mtl\n", NULL, "m.obj:1:8: mtllib \"../up.mtl\"");
    expect_error("mtllib /etc/passwd\n", NULL, "m.obj:1:8: mtllib \"/etc/passwd\": absolute path");
    expect_error("mtllib\n", NULL, "m.obj:1:7: mtllib needs a file name");
    /* Escapes stay refused after "." components and backslashes are normalised. */
    expect_error("mtllib .\\..\\up.mtl\n", NULL, "m.obj:1:8: mtllib \"../up.mtl\"");
    expect_error("mtllib sub/./../../x.mtl\n", NULL, "m.obj:1:8: mtllib \"sub/../../x.mtl\"");
    expect_error("mtllib \\etc\\passwd\n", NULL, "absolute path");
}

/* Runs parse with stderr (the log) captured into out (outlen bytes). */
static int parse_capture(const char *text, const struct mem_file *files, struct scene *s, char *err, char *out,
                         size_t outlen)
{
    fflush(stderr);
    FILE *tmp = tmpfile();
    cr_assert_not_null(tmp);
    int saved = dup(2);
    dup2(fileno(tmp), 2);
    int rc = parse(text, files, NULL, s, err);
    fflush(stderr);
    dup2(saved, 2);
    close(saved);
    rewind(tmp);
    size_t n = fread(out, 1, outlen - 1, tmp);
    out[n] = '\0';
    fclose(tmp);
    return rc;
}

Test(mesh_obj, unknown_material_is_default_grey_with_a_warning)
{
    static const struct mem_file ok[] = {{"m.mtl", "newmtl a\nKd 1 0 0\n", 0}, {NULL, NULL, 0}};
    struct scene s = {0};
    char err[512], log[4096];
    const char *text = "mtllib m.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nusemtl Default\nf 1 2 3\nusemtl a\nf 1 2 3\n";
    cr_assert_eq(parse_capture(text, ok, &s, err, log, sizeof log), 0, "%s", err);
    cr_expect(strstr(log, "m.obj:5:8: unknown material \"Default\"") != NULL, "log: %s", log);
    const struct mesh *m = &s.meshes[0];
    const struct material *grey = &s.materials[m->material_ids[0]];
    cr_expect_str_eq(grey->name, "default");
    cr_expect_float_eq(grey->albedo.x, 0.8f, 1e-6);
    cr_expect_float_eq(grey->albedo.z, 0.8f, 1e-6);
    cr_expect_str_eq(s.materials[m->material_ids[1]].name, "m.mtl:a");
    scene_fini(&s);
}

Test(mesh_obj, dot_components_and_backslashes_in_paths)
{
    static const struct mem_file files[] = {{"sub/m.mtl", "newmtl a\nKd 0 1 0\n", 0}, {NULL, NULL, 0}};
    const char *forms[] = {"./sub/m.mtl", ".\\sub\\m.mtl", "sub/./m.mtl", "sub//m.mtl", "./././sub\\.\\m.mtl"};
    for (size_t i = 0; i < sizeof forms / sizeof *forms; i++) {
        struct scene s = {0};
        char err[512], text[256];
        snprintf(text, sizeof text, "mtllib %s\nusemtl a\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n", forms[i]);
        cr_assert_eq(parse(text, files, NULL, &s, err), 0, "%s: %s", forms[i], err);
        cr_expect_str_eq(s.materials[s.meshes[0].material_ids[0]].name, "sub/m.mtl:a", "%s", forms[i]);
        scene_fini(&s);
    }
}

/* Newell normal of triangle or polygon corners p[0..n-1] (xyz each). */
static void newell(const float *p, int n, double out[3])
{
    out[0] = out[1] = out[2] = 0.0;
    for (int i = 0; i < n; i++) {
        const float *a = &p[3 * i], *b = &p[3 * ((i + 1) % n)];
        out[0] += ((double)a[1] - b[1]) * ((double)a[2] + b[2]);
        out[1] += ((double)a[2] - b[2]) * ((double)a[0] + b[0]);
        out[2] += ((double)a[0] - b[0]) * ((double)a[1] + b[1]);
    }
}

/* Triangulates the polygon pts (n corners, xyz) as one OBJ face; checks n - 2 triangles,
 * each facing the polygon's way, whose areas add up to the polygon's. */
static void check_polygon(const float *pts, int n)
{
    char text[8192];
    size_t len = 0;
    for (int i = 0; i < n; i++)
        len += (size_t)snprintf(text + len, sizeof text - len, "v %.9g %.9g %.9g\n", pts[3 * i], pts[3 * i + 1],
                                pts[3 * i + 2]);
    len += (size_t)snprintf(text + len, sizeof text - len, "f");
    for (int i = 0; i < n; i++)
        len += (size_t)snprintf(text + len, sizeof text - len, " %d", i + 1);
    snprintf(text + len, sizeof text - len, "\n");
    struct scene s = {0};
    char err[512];
    cr_assert_eq(parse(text, NULL, NULL, &s, err), 0, "%s", err);
    const struct mesh *m = &s.meshes[0];
    cr_assert_eq(m->num_triangles, (uint32_t)n - 2);
    double pn[3];
    newell(pts, n, pn);
    double plen = sqrt(pn[0] * pn[0] + pn[1] * pn[1] + pn[2] * pn[2]), area = 0.0;
    for (uint32_t t = 0; t < m->num_triangles; t++) {
        float tri[9];
        for (int k = 0; k < 3; k++)
            memcpy(&tri[3 * k], &m->positions[3 * m->indices[3 * t + k]], 3 * sizeof(float));
        double tn[3];
        newell(tri, 3, tn);
        double along = (tn[0] * pn[0] + tn[1] * pn[1] + tn[2] * pn[2]) / plen;
        cr_expect_gt(along, 0.0, "triangle %u faces away from the polygon", t);
        area += along;
    }
    cr_expect(fabs(area - plen) < 1e-4 * plen, "triangles cover %g of the polygon's %g", area / 2, plen / 2);
    scene_fini(&s);
}

Test(mesh_obj, concave_polygons_ear_clipped_facing_the_polygon)
{
    /* An L, an arrow whose notch is at the first corner (a fan from there folds over),
     * and a comb of 16 teeth (64 corners) as a CAD exporter writes a cut-out; all in a
     * tilted plane. */
    const float el[] = {0, 0, 0, 2, 0, 0, 2, 1, 0, 1, 1, 0, 1, 2, 0, 0, 2, 0};
    const float arrow[] = {0, 0.5f, 0, -1, -1, 0, 2, 0, 0, -1, 1, 0};
    float comb[64 * 3];
    int n = 0;
    for (int t = 0; t < 16; t++) { /* teeth along x, up to y = 2, base at y = 0 */
        float x = (float)t;
        const float c[4][2] = {{x, 1}, {x + 0.25f, 2}, {x + 0.5f, 2}, {x + 0.75f, 1}};
        for (int k = 0; k < 4; k++) {
            comb[3 * n] = c[k][0];
            comb[3 * n + 1] = c[k][1];
            comb[3 * n + 2] = 0.3f * c[k][0] - 0.2f * c[k][1]; /* tilted plane */
            n++;
        }
    }
    /* close the comb through the base: replace the first and last corners' y by 0 */
    comb[1] = 0.0f;
    comb[2] = 0.0f;
    comb[3 * 63 + 1] = 0.0f;
    comb[3 * 63 + 2] = 0.3f * comb[3 * 63];
    check_polygon(el, 6);
    check_polygon(arrow, 4);
    check_polygon(comb, 64);
    /* Reversed winding: the triangles follow it. */
    float rev[64 * 3];
    for (int i = 0; i < 64; i++)
        memcpy(&rev[3 * i], &comb[3 * (63 - i)], 3 * sizeof(float));
    check_polygon(rev, 64);
}

Test(mesh_obj, non_planar_polygon_and_bad_ones)
{
    /* A concave hexagon bent out of its plane (z up to 0.2 over a span of 2). */
    const float bent[] = {0, 0, 0, 2, 0, 0.2f, 2, 1, 0.1f, 1, 1, -0.1f, 1, 2, 0.15f, 0, 2, 0};
    check_polygon(bent, 6);
    /* A pentagram crosses itself: no ear to clip. */
    char text[512];
    size_t len = 0;
    for (int i = 0; i < 5; i++) {
        double a = 2.0 * M_PI * (2 * i) / 5.0;
        len += (size_t)snprintf(text + len, sizeof text - len, "v %.6f %.6f 0\n", cos(a), sin(a));
    }
    snprintf(text + len, sizeof text - len, "f 1 2 3 4 5\n");
    expect_error(text, NULL, "m.obj:6:2: face with 5 corners crosses itself");
    /* So does an uneven bow tie. */
    expect_error("v 0 0 0\nv 2 2 0\nv 2 0 0\nv 0 1 0\nf 1 2 3 4\n", NULL, "m.obj:5:2: face with 4 corners crosses itself");
}

/* Reads rel_path through src and parses it, as the scene reader does. */
static int load_obj(struct scene *s, struct mesh_obj_cache *cache, const struct asset_source *src, const char *rel_path,
                    const struct mesh_obj_options *opt, char *err)
{
    char *data;
    size_t size;
    if (src->read(src->ctx, rel_path, &data, &size, err, 512) != 0)
        return -1;
    int rc = mesh_obj_parse(s, cache, src, rel_path, data, size, opt, err, 512);
    free(data);
    return rc;
}

Test(mesh_obj, mtllib_relative_to_obj_folder)
{
    static const struct mem_file files[] = {
        {"models/car.obj", "mtllib car.mtl\nusemtl paint\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n", 0},
        {"models/car.mtl", "newmtl paint\nKd 0 0 1\n", 0},
        {NULL, NULL, 0}};
    struct asset_source src = {mem_read, (void *)(uintptr_t)files};
    struct mesh_obj_cache cache = {0};
    struct scene s = {0};
    char err[512];
    struct mesh_obj_options opt = mesh_obj_default_options();
    opt.display_dir = "scenes/x/";
    cr_assert_eq(load_obj(&s, &cache, &src, "models/car.obj", &opt, err), 0, "%s", err);
    /* The same MTL named by a second OBJ is not read twice: its materials are shared. */
    cr_assert_eq(load_obj(&s, &cache, &src, "models/car.obj", &opt, err), 0, "%s", err);
    cr_expect_eq(s.num_materials, 1);
    cr_expect_str_eq(s.materials[0].name, "models/car.mtl:paint");
    cr_expect_eq(s.num_meshes, 2);
    cr_expect_eq(s.meshes[1].material_ids[0], 0);
    cr_expect_eq(load_obj(&s, &cache, &src, "models/none.obj", &opt, err), -1);
    cr_expect(strstr(err, "models/none.obj") != NULL, "%s", err);
    mesh_obj_cache_fini(&cache);
    scene_fini(&s);
}

Test(mesh_obj, override_skips_mtl)
{
    struct scene s = {0};
    char err[512];
    struct material white = {.name = "w", .albedo = {1, 1, 1}};
    scene_add_material(&s, &white);
    struct mesh_obj_options opt = mesh_obj_default_options();
    opt.material_override = 0;
    const char *text = "mtllib nowhere.mtl\nusemtl nothing\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n";
    cr_assert_eq(parse(text, NULL, &opt, &s, err), 0, "%s", err);
    cr_expect_eq(s.num_materials, 1);
    cr_expect_eq(s.meshes[0].material_ids[0], 0);
    scene_fini(&s);
}

Test(mesh_obj, transform_positions_normals_and_winding)
{
    struct scene s = {0};
    char err[512];
    struct mesh_obj_options opt = mesh_obj_default_options();
    /* Scale x by 2, then translate by (10, 20, 30). */
    struct dxform t = {{{2, 0, 0, 10}, {0, 1, 0, 20}, {0, 0, 1, 30}}};
    opt.transform = t;
    const char *text = "v 1 0 0\nv 0 1 0\nv 0 0 1\nvn 1 1 0\nf 1//1 2//1 3//1\n";
    cr_assert_eq(parse(text, NULL, &opt, &s, err), 0, "%s", err);
    const struct mesh *m = &s.meshes[0];
    cr_expect_float_eq(m->positions[0], 12.0f, 1e-5);
    cr_expect_float_eq(m->positions[1], 20.0f, 1e-5);
    cr_expect_float_eq(m->positions[5], 30.0f, 1e-5);
    cr_expect_float_eq(m->positions[8], 31.0f, 1e-5);
    /* Inverse transpose: (1, 1, 0) becomes (0.5, 1, 0), normalised. */
    float l = sqrtf(1.25f);
    cr_expect_float_eq(m->normals[0], 0.5f / l, 1e-5);
    cr_expect_float_eq(m->normals[1], 1.0f / l, 1e-5);
    cr_expect_eq(m->indices[1], 1);
    scene_fini(&s);

    /* A mirror keeps the geometric normal on the same side by flipping the winding. */
    struct dxform mirror = {{{-1, 0, 0, 0}, {0, 1, 0, 0}, {0, 0, 1, 0}}};
    opt.transform = mirror;
    cr_assert_eq(parse(text, NULL, &opt, &s, err), 0, "%s", err);
    cr_expect_eq(s.meshes[0].indices[1], 2);
    cr_expect_eq(s.meshes[0].indices[2], 1);
    cr_expect_float_eq(s.meshes[0].normals[0], -1.0f / sqrtf(2.0f), 1e-5);
    scene_fini(&s);
}

/* Vertex normals survive a scale of 1e10 or 1e-10: the cofactor matrix (scale^2) makes the
 * transformed normal's squared length overflow or underflow float, which once dropped
 * every normal of the mesh as "degenerate". */
Test(mesh_obj, normals_kept_at_huge_and_tiny_scales)
{
    const double scales[] = {1e10, 1e-10, -1e10};
    for (int i = 0; i < 3; i++) {
        struct scene s = {0};
        char err[512];
        struct mesh_obj_options opt = mesh_obj_default_options();
        double k = scales[i];
        struct dxform t = {{{k, 0, 0, 0}, {0, k, 0, 0}, {0, 0, k, 0}}};
        opt.transform = t;
        const char *text = "v 1 0 0\nv 0 1 0\nv 0 0 1\nvn 1 2 2\nf 1//1 2//1 3//1\n";
        cr_assert_eq(parse(text, NULL, &opt, &s, err), 0, "%s", err);
        const struct mesh *m = &s.meshes[0];
        cr_assert_not_null(m->normals, "scale %g: normals dropped", k);
        float sg = k < 0 ? -1.0f : 1.0f; /* a mirror by -1 in every axis: the normal flips with the winding */
        cr_expect_float_eq(m->normals[0], sg * 1.0f / 3.0f, 1e-6, "scale %g", k);
        cr_expect_float_eq(m->normals[1], sg * 2.0f / 3.0f, 1e-6, "scale %g", k);
        cr_expect_float_eq(m->normals[2], sg * 2.0f / 3.0f, 1e-6, "scale %g", k);
        scene_fini(&s);
    }
}
