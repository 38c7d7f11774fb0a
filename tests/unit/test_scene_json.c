/* Unit tests of the scene file reader (common/scene/scene_json.c): defaults, transforms, every
 * class of error with the line:col it must name, and the scenes shipped in scenes/
 * loaded from disk. Most tests read OBJ files from an in-memory asset source. */
#include <criterion/criterion.h>
#include <math.h>
#include <stdio.h>
#include <string.h>
#include "scene/light.h"
#include "scene/scene_json.h"
#include "helpers.h"

static const struct mem_file g_files[] = {
    {"tri.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n", 0},
    {"a/x.obj", "mtllib m.mtl\nusemtl paint\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n", 0},
    {"a/m.mtl", "newmtl paint\nKd 1 0 0\n", 0},
    {"b/x.obj", "mtllib m.mtl\nusemtl paint\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n", 0},
    {"b/m.mtl", "newmtl paint\nKd 0 1 0\n", 0},
    {"bad.obj", "v 0 0 0\nv 1 0 zz\n", 0},
    {"big.obj", "v 1e30 0 0\nv 0 1 0\nv 0 0 1\nf 1 2 3\n", 0},
    {"q.ply", "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\n"
              "element face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n"
              "4 0 1 2 3\n", 0},
    {"bad.ply", "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nend_header\n0\n", 0},
    {NULL, NULL, 0}};

/* A valid scene is HEAD + the text given + "}". */
#define HEAD                                                                        \
    "{\"version\": 1,\n"                                                            \
    "\"camera\": {\"position\": [0, 0, -5], \"look_at\": [0, 0, 0], \"fov_y\": 40},\n" \
    "\"render\": {\"width\": 64, \"height\": 48}"

/* Built with -DSHOW_POS, prints the text at each reported position: the quickest way to
 * check a new expectation points at the intended token. */
static void show_position(const char *text, const char *err)
{
#ifdef SHOW_POS
    unsigned line, col;
    if (sscanf(err, "scenes/t.json:%u:%u", &line, &col) != 2)
        return;
    const char *q = text;
    for (unsigned i = 1; i < line && strchr(q, '\n'); i++)
        q = strchr(q, '\n') + 1;
    for (unsigned c = 1; c < col && *q; c += ((*++q & 0xC0) != 0x80))
        ;
    fprintf(stderr, "POS %-70.70s | %.20s\n", err, q);
#else
    (void)text;
    (void)err;
#endif
}

static void expect_error(const char *text, const char *want)
{
    show_position(text, test_scene_expect_error(text, g_files, want));
}

Test(scene_json, defaults)
{
    struct scene s;
    char err[512];
    cr_assert_eq(test_scene_load(HEAD "}", g_files, &s, err), 0, "%s", err);
    cr_expect_eq(s.settings.width, 64);
    cr_expect_eq(s.settings.height, 48);
    cr_expect_eq(s.settings.spp, 16);
    cr_expect_eq(s.settings.max_depth, 8);
    cr_expect_eq(s.settings.seed, 0);
    cr_expect_eq(s.settings.tile_size, 32);
    cr_expect_float_eq(s.camera.up.y, 1.0f, 0);
    cr_expect_float_eq(s.camera.up.x, 0.0f, 0);
    cr_expect_float_eq(s.camera.aperture_radius, 0.0f, 0);
    cr_expect_float_eq(s.camera.focus_distance, 0.0f, 0);
    cr_expect_float_eq(s.camera.fov_y_deg, 40.0f, 0);
    cr_expect_float_eq(s.camera.position.z, -5.0f, 0);
    cr_expect_eq(s.num_meshes + s.num_spheres + s.num_lights + s.num_materials, 0);
    scene_fini(&s);

    const char *full = "{\"version\": 1, \"camera\": {\"position\": [0, 0, -5], \"look_at\": [0, 0, 0],"
                       " \"up\": [0, 1, 1], \"fov_y\": 40, \"aperture\": 0, \"focus_distance\": 3},"
                       " \"render\": {\"width\": 5, \"height\": 7, \"spp\": 3, \"max_depth\": 2,"
                       " \"seed\": 12345678901, \"tile_size\": 8}}";
    cr_assert_eq(test_scene_load(full, g_files, &s, err), 0, "%s", err);
    cr_expect_eq(s.settings.spp, 3);
    cr_expect_eq(s.settings.max_depth, 2);
    cr_expect_eq(s.settings.seed, 12345678901ull);
    cr_expect_eq(s.settings.tile_size, 8);
    cr_expect_float_eq(s.camera.up.z, 1.0f, 0);
    cr_expect_float_eq(s.camera.focus_distance, 3.0f, 0);
    scene_fini(&s);
}

Test(scene_json, materials_spheres_lights)
{
    struct scene s;
    char err[512];
    const char *text = HEAD ",\n\"materials\": {\"m\": {\"type\": \"diffuse\", \"albedo\": [0.1, 0.2, 0.3]},"
                            " \"glow\": {\"type\": \"diffuse\", \"emission\": [1, 2, 3]}},\n"
                            "\"objects\": [{\"type\": \"sphere\", \"center\": [1, 2, 3], \"radius\": 0.5,"
                            " \"material\": \"glow\", \"name\": \"ball\"}],\n"
                            "\"lights\": [{\"type\": \"point\", \"position\": [0, 5, 0], \"intensity\": [4, 4, 4]}]}";
    cr_assert_eq(test_scene_load(text, g_files, &s, err), 0, "%s", err);
    cr_assert_eq(s.num_materials, 2);
    cr_expect_str_eq(s.materials[0].name, "m");
    cr_expect_float_eq(s.materials[0].albedo.z, 0.3f, 0);
    cr_expect_float_eq(s.materials[1].albedo.x, 0.8f, 0);  /* default albedo */
    cr_expect_float_eq(s.materials[1].emission.z, 3.0f, 0);
    cr_assert_eq(s.num_spheres, 1);
    cr_expect_eq(s.spheres[0].material_id, 1);
    cr_expect_str_eq(s.spheres[0].name, "ball");
    cr_expect_float_eq(s.spheres[0].radius, 0.5f, 0);
    cr_assert_eq(s.num_lights, 1);
    cr_expect_eq(s.lights[0].type, LIGHT_POINT);
    cr_expect_float_eq(s.lights[0].position.y, 5.0f, 0);
    scene_fini(&s);
}

Test(scene_json, obj_and_transforms)
{
    struct scene s;
    char err[512];
    /* scale 2, rotate 90 degrees about y, translate (10, 0, 0): (1,0,0) -> (2,0,0) ->
     * (0,0,-2) -> (10,0,-2). */
    const char *text = HEAD ",\n\"objects\": [{\"type\": \"obj\", \"file\": \"tri.obj\", \"transform\":"
                            " {\"scale\": 2, \"rotate\": {\"axis\": [0, 1, 0], \"degrees\": 90},"
                            " \"translate\": [10, 0, 0]}},\n"
                            "{\"type\": \"obj\", \"file\": \"tri.obj\", \"transform\": {\"matrix\":"
                            " [1, 0, 0, 1, 0, 1, 0, 2, 0, 0, 1, 3, 0, 0, 0, 1]}},\n"
                            "{\"type\": \"obj\", \"file\": \"tri.obj\", \"transform\": {\"scale\": [1, 2, 3],"
                            " \"rotate\": [{\"axis\": [0, 0, 1], \"degrees\": 90}, {\"axis\": [1, 0, 0],"
                            " \"degrees\": 90}]}},\n"
                            "{\"type\": \"sphere\", \"center\": [1, 0, 0], \"radius\": 1, \"material\": \"w\","
                            " \"transform\": {\"scale\": 3, \"rotate\": {\"axis\": [1, 1, 1], \"degrees\": 30},"
                            " \"translate\": [0, 1, 0]}}],\n"
                            "\"materials\": {\"w\": {\"type\": \"diffuse\"}}}";
    cr_assert_eq(test_scene_load(text, g_files, &s, err), 0, "%s", err);
    cr_assert_eq(s.num_meshes, 3);
    const float *p = s.meshes[0].positions;
    cr_expect_float_eq(p[3], 10.0f, 1e-5);
    cr_expect_float_eq(p[4], 0.0f, 1e-5);
    cr_expect_float_eq(p[5], -2.0f, 1e-5);
    cr_expect_str_eq(s.meshes[0].name, "tri.obj");
    p = s.meshes[1].positions;
    cr_expect_float_eq(p[3], 2.0f, 1e-6);
    cr_expect_float_eq(p[4], 2.0f, 1e-6);
    cr_expect_float_eq(p[5], 3.0f, 1e-6);
    /* (0,1,0) scaled to (0,2,0), about z to (-2,0,0), about x stays (-2,0,0). */
    p = s.meshes[2].positions;
    cr_expect_float_eq(p[6], -2.0f, 1e-5);
    cr_expect_float_eq(p[7], 0.0f, 1e-5);
    cr_expect_float_eq(p[8], 0.0f, 1e-5);
    /* The default material of faces without usemtl follows the scene's own. */
    cr_expect_eq(s.num_materials, 2);
    cr_expect_eq(s.meshes[0].material_ids[0], 1);
    cr_expect_float_eq(s.spheres[0].radius, 3.0f, 1e-5);
    cr_expect_float_eq(v3_length(v3_sub(s.spheres[0].center, v3(0, 1, 0))), 3.0f, 1e-5);
    scene_fini(&s);
}

Test(scene_json, mtl_names_are_namespaced_and_override_wins)
{
    struct scene s;
    char err[512];
    const char *text = HEAD ",\n\"materials\": {\"gold\": {\"type\": \"diffuse\", \"albedo\": [1, 0.8, 0]}},\n"
                            "\"objects\": [{\"type\": \"obj\", \"file\": \"a/x.obj\"}, {\"type\": \"obj\","
                            " \"file\": \"b/x.obj\"}, {\"type\": \"obj\", \"file\": \"a/x.obj\"},"
                            " {\"type\": \"obj\", \"file\": \"b/x.obj\", \"material\": \"gold\"}]}";
    cr_assert_eq(test_scene_load(text, g_files, &s, err), 0, "%s", err);
    cr_assert_eq(s.num_materials, 3);
    cr_expect_str_eq(s.materials[1].name, "a/m.mtl:paint");
    cr_expect_str_eq(s.materials[2].name, "b/m.mtl:paint");
    cr_expect_eq(s.meshes[0].material_ids[0], 1);
    cr_expect_eq(s.meshes[1].material_ids[0], 2);
    cr_expect_eq(s.meshes[2].material_ids[0], 1);
    cr_expect_eq(s.meshes[3].material_ids[0], 0);
    scene_fini(&s);
}

Test(scene_json, syntax_errors_from_jansson)
{
    expect_error("{\"version\": 1,\n  \"camera\" {}}", "scenes/t.json:2:12: ");
    expect_error("{\"version\": 1,\n\"camera\": {\"fov_y\": 1,\n  \"fov_y\": 2}}",
                 "scenes/t.json:3:9: duplicate object key");
    expect_error("", "scenes/t.json:1:1: ");
    expect_error("[1, 2]", "scenes/t.json:1:1: the scene must be an object");
    expect_error("{\"version\": 1} x", "scenes/t.json:1:16: end of file expected");
}

Test(scene_json, unknown_keys_and_wrong_types)
{
    expect_error(HEAD ",\n  \"fov\": 3}", "scenes/t.json:4:3: unknown key \"fov\" in the scene");
    expect_error("{\"version\": 1, \"render\": {\"width\": 1, \"height\": 1},\n\"camera\": {\"position\": [0, 0, -5],\n  \"fovy\": 40}}",
                 "scenes/t.json:3:3: unknown key \"fovy\" in camera (expected one of: position, look_at");
    expect_error("{\"version\": 1,\n\"render\": {\"width\": \"64\", \"height\": 1}, \"camera\": {\"position\": [0, 0, -5],"
                 " \"look_at\": [0, 0, 0], \"fov_y\": 40}}",
                 "scenes/t.json:2:21: width must be an integer, not a string");
    expect_error(HEAD ",\n\"objects\": [{\"type\": \"sphere\", \"center\": [0, 0, true], \"radius\": 1,"
                      " \"material\": \"x\"}]}",
                 "scenes/t.json:4:49: center must be a number, not a boolean");
    expect_error(HEAD ",\n\"objects\": {}}", "scenes/t.json:4:12: objects must be an array");
    expect_error(HEAD ",\n\"objects\": [{\"type\": \"cube\"}]}",
                 "scenes/t.json:4:22: unknown object type \"cube\"");
    expect_error(HEAD ",\n\"objects\": [{\"file\": \"tri.obj\"}]}",
                 "scenes/t.json:4:13: objects[0]: missing key \"type\"");
    expect_error(HEAD ",\n\"lights\": [{\"type\": \"area\"}]}", "scenes/t.json:4:21: unknown light type \"area\"");
    expect_error(HEAD ",\n\"lights\": [{\"type\": \"point\", \"position\": [0, 0, 0], \"intensity\": [1, 1]}]}",
                 "scenes/t.json:4:66: intensity must be an array of 3 numbers");
    expect_error(HEAD ",\n\"materials\": {\"m\": {\"type\": \"diffuse\", \"albedo\": [0.5, 1.5, 0]}}}",
                 "scenes/t.json:4:56: albedo components must be in [0, 1]");
    expect_error(HEAD ",\n\"materials\": {\"m\": {\"type\": \"glass\"}}}",
                 "scenes/t.json:4:29: unknown material type \"glass\"");
    expect_error(HEAD ",\n\"materials\": {\"m\": {\"kind\": \"diffuse\"}}}",
                 "scenes/t.json:4:21: unknown key \"kind\" in material \"m\"");
    /* Keys before the offending one may hold escapes and multi-byte characters: columns
     * count characters. */
    expect_error("{\"version\": 1, \"render\": {\"width\": 1, \"height\": 1}, \"camera\": {\"position\": [0, 0, -5],"
                 " \"look_at\": [0, 0, 0], \"fov_y\": 40}, \"materials\": {\"\xc3\xa9\\u00e9\\\"]{\": {\"type\": \"diffuse\"},"
                 " \"\xc3\xa9\": {\"type\": \"diffuse\", \"x\": 1}}}",
                 "scenes/t.json:1:199: unknown key \"x\" in material \"\xc3\xa9\"");
}

Test(scene_json, missing_and_range_errors)
{
    expect_error("{\"camera\": {}}", "scenes/t.json:1:1: scene: missing key \"version\"");
    expect_error("{\"version\": 2}", "scenes/t.json:1:13: unsupported scene version 2");
    expect_error("{\"version\": 1, \"render\": {\"width\": 1, \"height\": 1},\n \"camera\": {\"position\": [0, 0, -5], \"look_at\": [0, 0, 0]}}",
                 "scenes/t.json:2:12: camera: missing key \"fov_y\"");
    expect_error("{\"version\": 1,\n\"render\": {\"width\": 0, \"height\": 1}, \"camera\": {\"position\": [0, 0, -5],"
                 " \"look_at\": [0, 0, 0], \"fov_y\": 40}}",
                 "scenes/t.json:2:21: width 0 out of range 1..16384");
    expect_error("{\"version\": 1,\n\"render\": {\"width\": 1, \"height\": 16385}, \"camera\": {\"position\": [0, 0,"
                 " -5], \"look_at\": [0, 0, 0], \"fov_y\": 40}}",
                 "scenes/t.json:2:34: height 16385 out of range 1..16384");
    expect_error("{\"version\": 1,\n\"render\": {\"width\": 1, \"height\": 1, \"spp\": 0}, \"camera\": {\"position\":"
                 " [0, 0, -5], \"look_at\": [0, 0, 0], \"fov_y\": 40}}",
                 "scenes/t.json:2:44: spp 0 out of range");
    expect_error("{\"version\": 1, \"render\": {\"width\": 1, \"height\": 1},\n\"camera\": {\"position\": [0, 0, -5],"
                 " \"look_at\": [0, 0, 0], \"fov_y\": 180}}",
                 "scenes/t.json:2:67: fov_y must be in (0, 180)");
    expect_error("{\"version\": 1, \"render\": {\"width\": 1, \"height\": 1},\n\"camera\": {\"position\": [0, 0, -5],"
                 " \"look_at\": [0, 0, 0], \"fov_y\": 1e300}}",
                 "scenes/t.json:2:67: fov_y is out of range");
    expect_error("{\"version\": 1, \"render\": {\"width\": 1, \"height\": 1},\n\"camera\": {\"position\": [0, 0, 0],"
                 " \"look_at\": [0, 0, 0], \"fov_y\": 40}}",
                 "scenes/t.json:2:46: look_at must differ from position");
    expect_error("{\"version\": 1, \"render\": {\"width\": 1, \"height\": 1},\n\"camera\": {\"position\": [0, 0, -5],"
                 " \"look_at\": [0, 0, 0], \"up\": [0, 0, 2], \"fov_y\": 40}}",
                 "scenes/t.json:2:64: up must not be zero or parallel");
    expect_error(HEAD ",\n\"objects\": [{\"type\": \"sphere\", \"center\": [0, 0, 0], \"radius\": 0,"
                      " \"material\": \"x\"}]}",
                 "scenes/t.json:4:63: radius must be > 0");
}

Test(scene_json, thin_lens_and_planned_keys)
{
    expect_error("{\"version\": 1, \"render\": {\"width\": 1, \"height\": 1},\n\"camera\": {\"position\": [0, 0, -5],"
                 " \"look_at\": [0, 0, 0], \"fov_y\": 40, \"aperture\": -1}}",
                 "scenes/t.json:2:83: aperture must be in [0, 1e6]");
    expect_error(HEAD ",\n\"shutter\": [0, 1]}", "scenes/t.json:4:1: key \"shutter\" in the scene is planned, not yet accepted");
    expect_error(HEAD ",\n\"objects\": [{\"type\": \"obj\", \"file\": \"tri.obj\", \"keyframes\": []}]}",
                 "scenes/t.json:4:61: keyframes must be an array of 1 to 4096 objects");
}

Test(scene_json, files_and_materials_by_name)
{
    expect_error(HEAD ",\n\"objects\": [{\"type\": \"obj\", \"file\": \"nope.obj\"}]}",
                 "scenes/t.json:4:37: cannot read OBJ file: nope.obj: No such file");
    expect_error(HEAD ",\n\"objects\": [{\"type\": \"obj\", \"file\": \"../secret.obj\"}]}",
                 "scenes/t.json:4:37: file: \"..\" component in path \"../secret.obj\"");
    expect_error(HEAD ",\n\"objects\": [{\"type\": \"obj\", \"file\": \"/etc/passwd\"}]}",
                 "scenes/t.json:4:37: file: absolute path \"/etc/passwd\" not allowed");
    expect_error(HEAD ",\n\"objects\": [{\"type\": \"obj\", \"file\": \"tri.obj\", \"material\": \"nope\"}]}",
                 "scenes/t.json:4:60: unknown material \"nope\"");
    expect_error(HEAD ",\n\"objects\": [{\"type\": \"sphere\", \"center\": [0, 0, 0], \"radius\": 1,"
                      " \"material\": \"nope\"}]}",
                 "scenes/t.json:4:78: unknown material \"nope\"");
    /* Errors inside an OBJ name the OBJ, in the scene's folder, with its own line:col. */
    expect_error(HEAD ",\n\"objects\": [{\"type\": \"obj\", \"file\": \"bad.obj\"}]}",
                 "scenes/bad.obj:2:7: malformed number \"zz\"");
}

Test(scene_json, transform_errors)
{
#define OBJ_T(t) HEAD ",\n\"objects\": [{\"type\": \"obj\", \"file\": \"tri.obj\", \"transform\": " t "}]}"
    expect_error(OBJ_T("{\"scale\": 0}"), "scenes/t.json:4:71: scale must be non-zero");
    expect_error(OBJ_T("{\"scale\": \"big\"}"), "scenes/t.json:4:71: scale must be a number or an array of 3");
    expect_error(OBJ_T("{\"rotate\": {\"axis\": [0, 0, 0], \"degrees\": 5}}"),
                 "scenes/t.json:4:81: rotate axis must be a non-zero vector");
    expect_error(OBJ_T("{\"rotate\": [{\"axis\": [0, 0, 1]}]}"),
                 "scenes/t.json:4:73: rotate: missing key \"degrees\"");
    expect_error(OBJ_T("{\"matrix\": [1, 2, 3]}"), "scenes/t.json:4:72: matrix must be an array of 12 or 16");
    expect_error(OBJ_T("{\"matrix\": [1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 1, 1]}"),
                 "scenes/t.json:4:72: matrix: last row must be 0 0 0 1");
    expect_error(OBJ_T("{\"translate\": [1, 1, 1], \"matrix\": [1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0]}"),
                 "scenes/t.json:4:86: matrix cannot be combined");
    expect_error(OBJ_T("{\"matrix\": [1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 0, 0]}"),
                 "scenes/t.json:4:61: transform is singular");
    expect_error(OBJ_T("{\"skew\": 1}"), "scenes/t.json:4:62: unknown key \"skew\" in transform");
    expect_error(HEAD ",\n\"materials\": {\"w\": {\"type\": \"diffuse\"}},\n\"objects\": [{\"type\": \"sphere\","
                      " \"center\": [0, 0, 0], \"radius\": 1, \"material\": \"w\", \"transform\": {\"scale\": [1, 2, 1]}}]}",
                 "scenes/t.json:5:96: a sphere's transform must scale uniformly");
#undef OBJ_T
}

Test(scene_json, validate_runs_last)
{
    /* Each number is in range, but the transformed vertex overflows: only scene_validate
     * sees it, and its message carries the scene name. */
    expect_error(HEAD ",\n\"objects\": [{\"type\": \"obj\", \"file\": \"big.obj\", \"transform\": {\"scale\": 1e20}}]}",
                 "scenes/t.json: mesh \"big.obj\": non-finite vertex position");
}

Test(scene_json, textures_with_media_accepted)
{
    /* The media integrator applies textures (media_integrator.c, texshade.h): a scene with
     * media and every texture kind loads. */
    struct scene s;
    char err[512];
    cr_assert_eq(test_scene_load(HEAD ",\n\"textures\": {\"c\": {\"type\": \"checker\"}},\n"
                                      "\"materials\": {\"m\": {\"type\": \"plastic\", \"albedo_texture\": \"c\", "
                                      "\"roughness\": \"c\", \"bump_texture\": \"c\"},"
                                      " \"n\": {\"type\": \"diffuse\", \"normal_texture\": \"c\"}},\n"
                                      "\"media\": {\"fog\": {\"sigma_a\": [0.1, 0.1, 0.1], \"sigma_s\": [0.1, 0.1, 0.1]}},\n"
                                      "\"volume\": {\"fog\": \"fog\"},\n"
                                      "\"objects\": [{\"type\": \"sphere\", \"center\": [0, 0, 0], \"radius\": 1, \"material\": \"m\"},"
                                      " {\"type\": \"sphere\", \"center\": [3, 0, 0], \"radius\": 1, \"material\": \"n\"}]}",
                                 g_files, &s, err),
                 0, "%s", err);
    int albedo = 0, normal = 0;
    for (uint32_t i = 0; i < s.num_materials; i++) {
        albedo |= s.materials[i].albedo_tex != 0 && s.materials[i].roughness_tex != 0 && s.materials[i].bump_tex != 0;
        normal |= s.materials[i].normal_tex != 0;
    }
    cr_expect(albedo && normal && s.media != NULL);
    scene_fini(&s);
}

static int load_file(const char *path, struct scene *s, char *err, size_t errlen)
{
    char folder[512];
    snprintf(folder, sizeof folder, "%s", path);
    char *slash = strrchr(folder, '/');
    cr_assert_not_null(slash);
    *slash = '\0';
    struct asset_dir dir;
    cr_assert_eq(asset_dir_init(&dir, folder, err, errlen), 0, "%s", err);
    struct asset_source src = asset_dir_source(&dir);
    char *text;
    size_t size;
    cr_assert_eq(asset_dir_read(&dir, slash + 1, &text, &size, err, errlen), 0, "%s", err);
    memset(s, 0, sizeof *s);
    int rc = scene_json_parse(path, text, size, &src, s, err, errlen);
    free(text);
    asset_dir_fini(&dir);
    return rc;
}

Test(scene_json, cornell_from_disk)
{
    struct scene s;
    char err[1024];
    cr_assert_eq(load_file("../../scenes/cornell/cornell.json", &s, err, sizeof err), 0, "%s", err);
    cr_expect_eq(s.settings.width, 512);
    cr_expect_eq(s.settings.height, 512);
    cr_expect_eq(s.settings.spp, 64);
    cr_expect_eq(s.settings.max_depth, 8);
    cr_expect_float_eq(s.camera.fov_y_deg, 39.3f, 1e-6);
    /* Read from disk, positions are relative to the camera at (278, 273, -800). */
    cr_expect(s.origin[0] == 278.0 && s.origin[1] == 273.0 && s.origin[2] == -800.0);
    cr_expect(s.camera.position.x == 0.0f && s.camera.position.y == 0.0f && s.camera.position.z == 0.0f);
    cr_expect_float_eq(s.camera.look_at.z, 800.0f, 0);
    cr_assert_eq(s.num_meshes, 1);
    cr_expect_eq(s.meshes[0].num_triangles, 36);  /* 18 quads */
    cr_expect_eq(s.num_materials, 4);
    /* Exactly the two light triangles emit, at y = 548.7, facing down. */
    const struct mesh *m = &s.meshes[0];
    int emitting = 0;
    for (uint32_t t = 0; t < m->num_triangles; t++) {
        if (v3_is_black(s.materials[m->material_ids[t]].emission))
            continue;
        emitting++;
        vec3 p[3];
        for (int k = 0; k < 3; k++) {
            const float *q = &m->positions[3 * m->indices[3 * t + k]];
            p[k] = v3(q[0], q[1], q[2]);
            cr_expect_float_eq(p[k].y, 548.7f - 273.0f, 1e-3);
        }
        vec3 n = v3_cross(v3_sub(p[1], p[0]), v3_sub(p[2], p[0]));
        cr_expect_lt(n.y, 0.0f);
    }
    cr_expect_eq(emitting, 2);
    scene_fini(&s);
}

Test(scene_json, tiny_from_disk)
{
    struct scene s;
    char err[1024];
    cr_assert_eq(load_file("../../scenes/tiny/tiny.json", &s, err, sizeof err), 0, "%s", err);
    cr_expect_eq(s.settings.width, 32);
    cr_expect_eq(s.settings.height, 24);
    cr_expect_eq(s.settings.spp, 4);
    cr_expect_eq(s.num_meshes, 2);
    cr_expect_eq(s.num_spheres, 1);
    cr_expect_eq(s.num_lights, 1);
    cr_expect_eq(s.meshes[0].num_triangles, 14);
    cr_expect_eq(s.meshes[1].num_triangles, 2);
    cr_expect_float_eq(s.meshes[1].positions[1], 3.0f - 2.0f, 0); /* the camera is at y = 2 */
    cr_expect_gt(s.materials[s.meshes[1].material_ids[0]].emission.x, 0.0f);
    scene_fini(&s);
}

/* The same scene written near the world origin and 1e7 away (along x), read in the camera's frame:
 * every position comes out the same (the far one is subtracted in double before rounding),
 * and origin says where the frame lies. */
Test(scene_json, positions_relative_to_the_camera)
{
    char json[2][2048], obj[2][256];
    const double off[2] = {0.0, 1e7};
    for (int i = 0; i < 2; i++) {
        double o = off[i];
        snprintf(obj[i], sizeof obj[i], "v %.17g 0.25 0.3\nv %.17g 0 0.5\nv %.17g 1 0.1\nf 1 2 3\n", o + 0.5,
                 o + 1.0, o + 0.125);
        snprintf(json[i], sizeof json[i],
                 "{\"version\": 1,\n\"camera\": {\"keyframes\": [{\"time\": 0, \"position\": [%.17g, 1.5, -5],"
                 " \"look_at\": [%.17g, 0.5, 0]}, {\"time\": 1, \"position\": [%.17g, 1.5, -5],"
                 " \"look_at\": [%.17g, 0.5, 0]}], \"fov_y\": 40, \"focus_point\": [%.17g, 0, 0.7]},\n"
                 "\"render\": {\"width\": 8, \"height\": 8},\n"
                 "\"materials\": {\"w\": {\"type\": \"diffuse\"}},\n"
                 "\"objects\": [{\"type\": \"obj\", \"file\": \"far.obj\", \"material\": \"w\"},\n"
                 " {\"type\": \"obj\", \"file\": \"tri.obj\", \"material\": \"w\", \"transform\": {\"rotate\":"
                 " {\"axis\": [0, 1, 0], \"degrees\": 30}, \"translate\": [%.17g, 2, 0.3]}},\n"
                 " {\"type\": \"obj\", \"file\": \"tri.obj\", \"material\": \"w\", \"keyframes\": [{\"time\": 0,"
                 " \"translate\": [%.17g, 0, 0]}, {\"time\": 1}]},\n"
                 " {\"type\": \"sphere\", \"center\": [%.17g, 0.5, 0.25], \"radius\": 0.5, \"material\": \"w\"}],\n"
                 "\"lights\": [{\"type\": \"point\", \"position\": [%.17g, 3, -2], \"intensity\": [1, 1, 1]},\n"
                 " {\"type\": \"spot\", \"position\": [%.17g, 3, 0], \"look_at\": [%.17g, 0, 0.5],"
                 " \"intensity\": [1, 1, 1], \"angle\": 30}]}",
                 o - 0.5, o, o + 0.5, o + 0.25, o + 0.2, o + 0.1, o - 0.75, o + 1.2, o - 2.0,
                 o, o + 0.5);
    }
    struct scene s[2];
    for (int i = 0; i < 2; i++) {
        const struct mem_file files[] = {{"far.obj", obj[i], 0}, g_files[0], {NULL, NULL, 0}};
        struct asset_source src = {mem_read, (void *)(uintptr_t)files};
        char err[512] = "";
        cr_assert_eq(scene_json_parse("scenes/t.json", json[i], strlen(json[i]), &src, &s[i], err, sizeof err), 0,
                     "%s", err);
        cr_expect(s[i].origin[0] == off[i] - 0.5 && s[i].origin[1] == 1.5 && s[i].origin[2] == -5.0);
        cr_expect(s[i].camera.position.x == 0.0f && s[i].camera.position.z == 0.0f);
    }
    cr_assert_eq(s[0].num_meshes, 3);
    cr_assert_eq(s[1].num_meshes, 3);
    for (uint32_t m = 0; m < 3; m++)
        for (uint32_t k = 0; k < 3 * s[0].meshes[m].num_vertices; k++)
            cr_expect_float_eq(s[1].meshes[m].positions[k], s[0].meshes[m].positions[k], 1e-6, "mesh %u [%u]", m, k);
    const vec3 a[] = {s[0].camera.keyframes[1].position, s[0].camera.keyframes[1].look_at, s[0].camera.look_at,
                      s[0].camera.focus_point, s[0].meshes[2].keys[0].translate,
                      s[0].spheres[0].center, s[0].lights[0].position, s[0].lights[1].position,
                      s[0].lights[1].direction};
    const vec3 b[] = {s[1].camera.keyframes[1].position, s[1].camera.keyframes[1].look_at, s[1].camera.look_at,
                      s[1].camera.focus_point, s[1].meshes[2].keys[0].translate,
                      s[1].spheres[0].center, s[1].lights[0].position, s[1].lights[1].position,
                      s[1].lights[1].direction};
    for (size_t i = 0; i < sizeof a / sizeof *a; i++)
        cr_expect(v3_length(v3_sub(a[i], b[i])) <= 1e-6f, "position %zu: (%g %g %g) vs (%g %g %g)", i, (double)a[i].x,
                  (double)a[i].y, (double)a[i].z, (double)b[i].x, (double)b[i].y, (double)b[i].z);
    /* A key without a translation leaves the object where the world origin is. */
    cr_expect_float_eq(s[1].meshes[2].keys[1].translate.x, (float)(-s[1].origin[0]), 0);
    scene_fini(&s[0]);
    scene_fini(&s[1]);
}

/* HEAD with more keys in the render block. */
#define HEAD_RENDER(extra)                                                          \
    "{\"version\": 1,\n"                                                            \
    "\"camera\": {\"position\": [0, 0, -5], \"look_at\": [0, 0, 0], \"fov_y\": 40},\n" \
    "\"render\": {\"width\": 64, \"height\": 48,\n" extra "}"

Test(scene_json, aovs_filter_and_ply)
{
    struct scene s;
    char err[512];
    cr_assert_eq(test_scene_load(HEAD_RENDER("\"aovs\": [\"Z\", \"albedo\", \"id.object\"], "
                                             "\"filter\": {\"type\": \"gaussian\", \"width\": 2}") ",\n"
                                 "\"objects\": [{\"type\": \"ply\", \"file\": \"q.ply\", \"name\": \"quad\"}]}",
                                 g_files, &s, err),
                 0, "%s", err);
    cr_expect_eq(s.settings.aovs, (1u << AOV_Z) | (1u << AOV_ALBEDO) | (1u << AOV_ID_OBJECT));
    cr_expect_eq(s.camera.filter, FILTER_GAUSSIAN);
    cr_expect_eq(s.camera.filter_width, 2.0f);
    cr_assert_eq(s.num_meshes, 1);
    cr_expect_eq(s.meshes[0].num_triangles, 2);
    cr_expect_str_eq(s.meshes[0].name, "quad");
    scene_fini(&s);
    cr_assert_eq(test_scene_load(HEAD "}", g_files, &s, err), 0, "%s", err);
    cr_expect_eq(s.settings.aovs, 0, "no AOVs by default");
    cr_expect_eq(s.camera.filter, FILTER_BOX);
    scene_fini(&s);

    expect_error(HEAD_RENDER("\"aovs\": \"Z\"") "}", "scenes/t.json:4:9: aovs must be an array of AOV names");
    expect_error(HEAD_RENDER("\"aovs\": [\"Z\", \"depth\"]") "}",
                 "scenes/t.json:4:15: unknown AOV \"depth\" (Z, N, albedo, P, id.object or id.material)");
    expect_error(HEAD_RENDER("\"filter\": {\"type\": \"mitchell\"}") "}",
                 "scenes/t.json:4:20: unknown filter \"mitchell\" (box, gaussian or blackman-harris)");
    expect_error(HEAD_RENDER("\"filter\": {\"type\": \"gaussian\", \"width\": 40}") "}",
                 "scenes/t.json:4:41: filter width must be in [0.25, 16] pixels");
    expect_error(HEAD_RENDER("\"filter\": {\"type\": \"box\", \"width\": 2}") "}",
                 "the box filter is one pixel wide: it takes no width");
    expect_error(HEAD_RENDER("\"filter\": {\"width\": 2}") "}", "filter: missing key \"type\"");
    expect_error(HEAD ",\n\"objects\": [{\"type\": \"ply\", \"frames\": [\"q.ply\", \"q.ply\"]}]}",
                 "objects[0]: a deforming sequence (\"frames\") is read from OBJ files only");
    expect_error(HEAD ",\n\"objects\": [{\"type\": \"ply\", \"file\": \"bad.ply\"}]}",
                 "scenes/bad.ply:3: element vertex: properties x, y and z are required");
    expect_error(HEAD ",\n\"objects\": [{\"type\": \"ply\", \"file\": \"none.ply\"}]}", "cannot read PLY file");
}

/* The adaptive keys of the render block: target_error, pixel_error (both in (0, 1)) and
 * time_limit; none by default. */
Test(scene_json, adaptive_keys)
{
    struct scene s;
    char err[512];
    cr_assert_eq(test_scene_load(HEAD_RENDER("\"target_error\": 0.02, \"pixel_error\": 0.05, \"time_limit\": 60") "}",
                                 g_files, &s, err),
                 0, "%s", err);
    cr_expect_float_eq(s.settings.target_error, 0.02f, 1e-9f);
    cr_expect_float_eq(s.settings.pixel_error, 0.05f, 1e-9f);
    cr_expect_float_eq(s.settings.time_limit, 60.0f, 1e-9f);
    scene_fini(&s);
    cr_assert_eq(test_scene_load(HEAD "}", g_files, &s, err), 0, "%s", err);
    cr_expect(s.settings.pixel_error == 0.0f && s.settings.target_error == 0.0f, "none by default");
    scene_fini(&s);
    expect_error(HEAD_RENDER("\"pixel_error\": 1.5") "}", "scenes/t.json:4:16: pixel_error must be in (0, 1)");
    expect_error(HEAD_RENDER("\"pixel_error\": \"low\"") "}", "pixel_error");
}

/* Every spot angle in (0, 180] loads: a cone narrower than float's cosine can tell from 0
 * (below about 0.02 degrees) keeps cos_outer < cos_inner <= 1 (scene_validate's rule) and
 * lights its axis fully, and no direction outside it. */
Test(scene_json, spot_of_tiny_angle_loads)
{
    const char *angles[] = {"1e-30", "0.001", "0.0198", "0.02", "180"};
    for (int i = 0; i < 5; i++)
        for (int f = 0; f < 2; f++) {
            char json[1024], err[512] = "";
            snprintf(json, sizeof json,
                     HEAD ",\n\"lights\": [{\"type\": \"spot\", \"position\": [0, 3, 0], \"direction\": [0, -1, 0],"
                          " \"intensity\": [1, 1, 1], \"angle\": %s%s%s}]}",
                     angles[i], f ? ", \"falloff\": " : "", f ? angles[i] : "");
            struct scene s;
            cr_assert_eq(test_scene_load(json, g_files, &s, err), 0, "angle %s falloff %d: %s", angles[i], f, err);
            const struct light *l = &s.lights[0];
            cr_expect(l->cos_outer >= -1.0f && l->cos_outer < l->cos_inner && l->cos_inner <= 1.0f, "angle %s", angles[i]);
            cr_expect(light_spot_falloff(l, v3(0, -1, 0)) == 1.0f, "angle %s falloff %d: axis not lit", angles[i], f);
            if (i < 4)
                cr_expect(light_spot_falloff(l, v3(0.01f, -1, 0)) == 0.0f, "angle %s: lit outside the cone", angles[i]);
            scene_fini(&s);
        }
}

/* A view or spot direction of any non-zero length loads: look_at 1e20 away (its squared
 * length overflows float) or 1e-25 away (underflows) is not "equal to position". */
Test(scene_json, directions_of_any_length_load)
{
    const char *offs[] = {"1e20", "1e-25"};
    for (int i = 0; i < 2; i++) {
        char json[1024], err[512] = "";
        snprintf(json, sizeof json,
                 "{\"version\": 1,\n\"camera\": {\"position\": [0, 0, 0], \"look_at\": [0, 0, %s], \"fov_y\": 40},\n"
                 "\"render\": {\"width\": 8, \"height\": 8},\n"
                 "\"lights\": [{\"type\": \"spot\", \"position\": [0, 0, 0], \"look_at\": [0, -%s, 0],"
                 " \"intensity\": [1, 1, 1], \"angle\": 30},\n"
                 " {\"type\": \"spot\", \"position\": [0, 0, 0], \"direction\": [0, -%s, 0],"
                 " \"intensity\": [1, 1, 1], \"angle\": 30}]}",
                 offs[i], offs[i], offs[i]);
        struct scene s;
        cr_assert_eq(test_scene_load(json, g_files, &s, err), 0, "offset %s: %s", offs[i], err);
        for (int k = 0; k < 2; k++)
            cr_expect(fabsf(s.lights[k].direction.y + 1.0f) < 1e-6f, "offset %s: spot %d direction", offs[i], k);
        scene_fini(&s);
    }
}
