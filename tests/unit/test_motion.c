/* Object motion: keyframe interpolation and Embree time steps (motion.c), the static BVH
 * when nothing moves (accel.c), hits rebuilt at the ray's time lying on the ray, the
 * linear coverage ramp of an edge moving at constant speed (rigid keys and deformation
 * frames, keys exactly at shutter open and close), hard cases (180-degree rotation between
 * keys, zero-length shutter), and the scene keys that describe motion and materials. */
#include <criterion/criterion.h>
#include <math.h>
#include <stdio.h>
#include <string.h>
#include "render/integrator.h"
#include "base/log.h"
#include "scene/motion.h"
#include "scene/scene_json.h"
#include "scene/texture.h"
#include "helpers.h"

static uint32_t add_mat(struct scene *s, vec3 emission)
{
    struct material m;
    memset(&m, 0, sizeof m);
    m.type = MATERIAL_DIFFUSE;
    m.emission = emission;
    return scene_add_material(s, &m);
}

/* Quad in the plane z = 0 over [x0, x1] x [y0, y1], facing +z (toward the camera). */
static struct mesh quad_mesh(float x0, float x1, float y0, float y1, uint32_t mat)
{
    return test_quad(v3(x0, y0, 0), v3(x1, y0, 0), v3(x1, y1, 0), v3(x0, y1, 0), mat, 0);
}

static struct motion_key key(float t, vec3 translate, vec3 axis, float degrees)
{
    struct motion_key k;
    memset(&k, 0, sizeof k);
    k.time = t;
    k.scale = v3(1, 1, 1);
    k.translate = translate;
    motion_quat_from_axis_angle(axis, degrees, k.quat);
    return k;
}

/* T R S of a key as a 3x4 affine transform (the renderer hands Embree the quaternion; only
 * these checks need the matrix). */
static struct xform key_xform(const struct motion_key *k)
{
    double r = k->quat[0], i = k->quat[1], j = k->quat[2], q = k->quat[3];
    double m[3][3] = {{1 - 2 * (j * j + q * q), 2 * (i * j - q * r), 2 * (i * q + j * r)},
                      {2 * (i * j + q * r), 1 - 2 * (i * i + q * q), 2 * (j * q - i * r)},
                      {2 * (i * q - j * r), 2 * (j * q + i * r), 1 - 2 * (i * i + j * j)}};
    double s[3] = {k->scale.x, k->scale.y, k->scale.z}, tr[3] = {k->translate.x, k->translate.y, k->translate.z};
    struct xform x;
    for (int a = 0; a < 3; a++) {
        for (int b = 0; b < 3; b++)
            x.m[a][b] = (float)(m[a][b] * s[b]);
        x.m[a][3] = (float)tr[a];
    }
    return x;
}

static struct motion_key *keys2(struct motion_key a, struct motion_key b)
{
    struct motion_key *k = mem_alloc(2 * sizeof *k);
    k[0] = a;
    k[1] = b;
    return k;
}

static int scene_has_motion(const struct scene *s, uint32_t frame)
{
    struct accel a;
    char err[256];
    cr_assert_eq(accel_init(&a, s, frame, 1, err, sizeof err), 0, "%s", err);
    int m = a.has_motion;
    accel_fini(&a);
    return m;
}

/* Renders s and returns each column's mean alpha (coverage) and R over the rows. */
static void render_columns(const struct scene *s, double *alpha, double *red, uint64_t *nans)
{
    struct tile_stats st;
    float *px = test_render(s, 2, &st);
    uint32_t w = s->settings.width, h = s->settings.height;
    for (uint32_t x = 0; x < w; x++) {
        alpha[x] = red[x] = 0.0;
        for (uint32_t y = 0; y < h; y++) {
            alpha[x] += px[(y * w + x) * TILE_NUM_CHANNELS + CH_A] / h;
            red[x] += px[(y * w + x) * TILE_NUM_CHANNELS + CH_R] / h;
        }
    }
    *nans = st.nan_samples;
    free(px);
}

/* Adds the moving quad q to s and renders it. The right edge sweeps x = -1 -> 1 uniformly
 * over the shutter, so a point x is covered for the fraction (1 - x) / 2 of the time; a
 * pixel's coverage is that at its centre. Frees s. */
static void check_ramp(struct scene *s, struct mesh *q)
{
    enum { W = 64 };
    scene_add_mesh(s, q);
    test_ramp_camera(s, W, 256);
    cr_assert_eq(scene_has_motion(s, 0), 1);
    double alpha[W], red[W];
    uint64_t nans;
    render_columns(s, alpha, red, &nans);
    cr_assert_eq(nans, 0);
    double n = (double)s->settings.spp * s->settings.height, sq = 0.0;
    int inside = 0;
    for (int x = 0; x < W; x++) {
        double xc = -2.0 + 4.0 * (x + 0.5) / W, half_px = 2.0 / W;
        double expect = xc + half_px <= -1.0 ? 1.0 : xc - half_px >= 1.0 ? 0.0 : (1.0 - xc) / 2.0;
        if (fabs(xc) < 1.0 - half_px) {
            double se = sqrt(fmax(expect * (1 - expect), 1e-3) / n);
            cr_assert(fabs(alpha[x] - expect) < 5.0 * se, "column %d: coverage %.4f expected %.4f (se %.3f)", x,
                      alpha[x], expect, se);
            sq += (alpha[x] - expect) * (alpha[x] - expect) / (se * se);
            inside++;
        } else if (fabs(xc) > 1.0 + half_px) {
            cr_assert_eq(alpha[x], expect, "column %d outside the sweep", x);
        }
        cr_assert_float_eq(red[x], alpha[x] * 2.0, 1e-5, "radiance follows coverage");
    }
    /* Chi-square of the inner columns against the ramp (mean 'inside', sd sqrt(2 inside)). */
    cr_assert(sq < inside + 5.0 * sqrt(2.0 * inside), "chi2 %.1f over %d columns", sq, inside);
    scene_fini(s);
}

Test(motion, moving_edge_rigid_keys_give_linear_ramp)
{
    struct scene s;
    memset(&s, 0, sizeof s);
    uint32_t lamp = add_mat(&s, v3(2, 2, 2));
    struct mesh q = quad_mesh(-10, 0, -10, 10, lamp);
    /* Keys exactly at shutter open and close. */
    q.keys = keys2(key(0, v3(-1, 0, 0), v3(0, 0, 1), 0), key(1, v3(1, 0, 0), v3(0, 0, 1), 0));
    q.num_keys = 2;
    check_ramp(&s, &q);
}

Test(motion, moving_edge_deformation_frames_give_linear_ramp)
{
    struct scene s;
    memset(&s, 0, sizeof s);
    uint32_t lamp = add_mat(&s, v3(2, 2, 2));
    struct mesh q = quad_mesh(-11, -1, -10, 10, lamp);
    /* Three frames, the middle one at the shutter's midpoint; frame 2 outside the shutter. */
    q.num_frames = 3;
    q.frame_times = mem_alloc(3 * sizeof(float));
    q.frame_positions = mem_alloc(3 * 12 * sizeof(float));
    for (int f = 0; f < 3; f++) {
        q.frame_times[f] = 0.5f * (float)f + (f == 2 ? 1.0f : 0.0f); /* 0, 0.5, 2 */
        float dx = f == 0 ? 0.0f : f == 1 ? 1.0f : 4.0f;
        for (int v = 0; v < 4; v++) {
            q.frame_positions[f * 12 + 3 * v] = q.positions[3 * v] + dx;
            q.frame_positions[f * 12 + 3 * v + 1] = q.positions[3 * v + 1];
            q.frame_positions[f * 12 + 3 * v + 2] = 0.0f;
        }
    }
    check_ramp(&s, &q);
}

Test(motion, still_scenes_get_no_time_steps)
{
    struct scene s;
    memset(&s, 0, sizeof s);
    uint32_t lamp = add_mat(&s, v3(1, 1, 1));
    scene_add_mesh(&s, &(struct mesh){0});
    s.num_meshes = 0; /* (grow the array once) */
    struct mesh q = quad_mesh(-1, 1, -1, 1, lamp);
    scene_add_mesh(&s, &q);
    struct sphere sp = {"ball", v3(0, 0, -2), 0.5f, lamp, NULL, 0};
    scene_add_sphere(&s, &sp);
    test_ramp_camera(&s, 16, 1);
    cr_assert_eq(scene_has_motion(&s, 0), 0, "nothing moves");
    /* Identical keys count as still, also when they rotate and move the object. */
    s.spheres[0].keys = keys2(key(0, v3(1, 2, 3), v3(0, 1, 0), 30), key(1, v3(1, 2, 3), v3(0, 1, 0), 30));
    s.spheres[0].num_keys = 2;
    cr_assert_eq(scene_has_motion(&s, 0), 0, "identical keys");
    /* Keys that differ only outside this frame's shutter: still within it. */
    s.spheres[0].keys[1].time = 5.0f;
    s.spheres[0].keys[1].translate = v3(4, 0, 0);
    s.camera.shutter_close = 0.0f;
    cr_assert_eq(scene_has_motion(&s, 0), 0, "zero-length shutter");
    s.camera.shutter_close = 0.5f;
    cr_assert_eq(scene_has_motion(&s, 0), 1, "moving during the shutter");
    cr_assert_eq(scene_has_motion(&s, 7), 0, "after the last key (frame 7)");
    scene_fini(&s);
}

Test(motion, zero_length_shutter_freezes_at_open)
{
    struct scene s;
    memset(&s, 0, sizeof s);
    uint32_t lamp = add_mat(&s, v3(2, 2, 2));
    struct mesh q = quad_mesh(-10, 0, -10, 10, lamp);
    q.keys = keys2(key(0, v3(-1, 0, 0), v3(0, 0, 1), 0), key(1, v3(1, 0, 0), v3(0, 0, 1), 0));
    q.num_keys = 2;
    scene_add_mesh(&s, &q);
    test_ramp_camera(&s, 64, 16);
    s.camera.shutter_open = s.camera.shutter_close = 0.75f; /* edge at x = 0.5 */
    cr_assert_eq(scene_has_motion(&s, 0), 0);
    double alpha[64], red[64];
    uint64_t nans;
    render_columns(&s, alpha, red, &nans);
    cr_assert_eq(nans, 0);
    for (int x = 0; x < 64; x++) {
        double xc = -2.0 + 4.0 * (x + 0.5) / 64;
        if (fabs(xc - 0.5) > 0.1)
            cr_assert_eq(alpha[x], xc < 0.5 ? 1.0 : 0.0, "column %d", x);
    }
    scene_fini(&s);
}

Test(motion, step_counts_follow_the_keys)
{
    const float a[] = {0.0f, 1.0f}, b[] = {0.0f, 0.5f, 1.0f}, c[] = {-3.0f, 0.25f, 9.0f}, d[] = {0.0f, 0.123457f, 1.0f};
    cr_assert_eq(motion_step_count(a, sizeof(float), 2, 0.0, 1.0), 2);
    cr_assert_eq(motion_step_count(b, sizeof(float), 3, 0.0, 1.0), 3);
    cr_assert_eq(motion_step_count(c, sizeof(float), 3, 0.0, 1.0), 5);
    cr_assert_eq(motion_step_count(d, sizeof(float), 3, 0.0, 1.0), MOTION_MAX_SEGMENTS + 1);
    cr_assert_eq(motion_step_count(b, sizeof(float), 3, 2.0, 3.0), 2);
}

Test(motion, half_turn_between_keys_is_finite)
{
    struct motion_key k[2] = {key(0, v3(0, 0, 0), v3(0, 1, 0), 0), key(1, v3(0, 0, 0), v3(0, 1, 0), 180)};
    for (int i = 0; i <= 16; i++) {
        struct motion_key m;
        motion_key_at(k, 2, i / 16.0, &m);
        double l = 0;
        for (int j = 0; j < 4; j++) {
            cr_assert(isfinite(m.quat[j]));
            l += m.quat[j] * m.quat[j];
        }
        cr_assert_float_eq(l, 1.0, 1e-5);
    }
    struct motion_key mid;
    motion_key_at(k, 2, 0.5, &mid);
    struct xform x = key_xform(&mid);
    vec3 p = xform_point(&x, v3(1, 0, 0)); /* a quarter turn about y: (1,0,0) -> (0,0,-1) */
    cr_assert_float_eq(p.x, 0.0f, 1e-5f);
    cr_assert_float_eq(p.z, -1.0f, 1e-5f);
}

/* Hits on a quad spinning half a turn (and moving) lie on the ray when rebuilt from object
 * space with the instance transform at the ray's time, as the integrator does. */
Test(motion, rebuilt_hits_lie_on_the_ray)
{
    struct scene s;
    memset(&s, 0, sizeof s);
    uint32_t lamp = add_mat(&s, v3(1, 1, 1));
    struct mesh q = quad_mesh(-1, 1, -1, 1, lamp);
    q.keys = keys2(key(0, v3(0, 0, 0), v3(0, 1, 0.2f), -80), key(1, v3(0.5f, 0, 0), v3(0, 1, 0.2f), 100));
    q.num_keys = 2;
    scene_add_mesh(&s, &q);
    test_ramp_camera(&s, 16, 1);
    struct accel a;
    char err[256];
    cr_assert_eq(accel_init(&a, &s, 0, 1, err, sizeof err), 0, "%s", err);
    cr_assert_eq(a.has_motion, 1);
    int hits = 0;
    for (int i = 0; i < 400; i++) {
        float t01 = (i % 20) / 19.0f, ox = ((i / 20) - 10) * 0.05f;
        vec3 o = v3(ox, 0.1f, 10), d = v3(0, 0, -1);
        struct accel_hit h;
        if (!accel_intersect(&a, o, d, INFINITY, t01, &h))
            continue;
        hits++;
        struct xform x;
        cr_assert_eq(accel_object_xform(&a, h.geom, h.prim, t01, &x), 1);
        const uint32_t *idx = &s.meshes[0].indices[3 * h.prim];
        const float *p = s.meshes[0].positions;
        vec3 va = v3(p[3 * idx[0]], p[3 * idx[0] + 1], p[3 * idx[0] + 2]);
        vec3 vb = v3(p[3 * idx[1]], p[3 * idx[1] + 1], p[3 * idx[1] + 2]);
        vec3 vc = v3(p[3 * idx[2]], p[3 * idx[2] + 1], p[3 * idx[2] + 2]);
        vec3 po = v3_add(v3_add(v3_scale(va, 1 - h.u - h.v), v3_scale(vb, h.u)), v3_scale(vc, h.v));
        vec3 pw = xform_point(&x, po), pr = v3_add(o, v3_scale(d, h.t));
        cr_assert(v3_length(v3_sub(pw, pr)) < 1e-4f, "time %g: rebuilt (%g %g %g) ray (%g %g %g)", (double)t01,
                  (double)pw.x, (double)pw.y, (double)pw.z, (double)pr.x, (double)pr.y, (double)pr.z);
    }
    cr_assert(hits > 100, "%d hits", hits);
    accel_fini(&a);
    /* The half turn also renders without NaN (the quad is seen edge-on mid-shutter). */
    s.camera.shutter_close = 1.0f;
    s.settings.max_depth = 4;
    double alpha[16], red[16];
    uint64_t nans;
    render_columns(&s, alpha, red, &nans);
    cr_assert_eq(nans, 0);
    scene_fini(&s);
}

/* ---- Scene keys ---- */

static const struct mem_file g_files[] = {
    {"a.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n", 0},
    {"b.obj", "v 0 0 1\nv 1 0 1\nv 0 1 1\nf 1 2 3\n", 0},
    {"quad.obj", "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3 4\n", 0},
    {NULL, NULL, 0}};

#define HEAD                                                                        \
    "{\"version\": 1,\n"                                                            \
    "\"camera\": {\"position\": [0, 0, -5], \"look_at\": [0, 0, 0], \"fov_y\": 40},\n" \
    "\"render\": {\"width\": 8, \"height\": 8},\n"                                  \
    "\"materials\": {\"m\": {\"type\": \"diffuse\"}, \"glass\": {\"type\": \"dielectric\", \"ior\": 1.33}},\n"

static void expect_error(const char *text, const char *want)
{
    test_scene_expect_error(text, g_files, want);
}

Test(motion, scene_keys_for_motion_and_materials)
{
    struct scene s;
    char err[512] = "";
    const char *ok = HEAD "\"objects\": [\n"
                          "{\"type\": \"obj\", \"file\": \"a.obj\", \"material\": \"glass\", \"keyframes\": [\n"
                          "  {\"time\": 0}, {\"time\": 1, \"translate\": [1, 0, 0], \"scale\": 2,\n"
                          "   \"rotate\": [{\"axis\": [0, 1, 0], \"degrees\": 90}, {\"axis\": [1, 0, 0], \"degrees\": 90}]}]},\n"
                          "{\"type\": \"obj\", \"frames\": [\"a.obj\", \"b.obj\"], \"frame_times\": [0, 0.5]},\n"
                          "{\"type\": \"sphere\", \"center\": [0, 0, 0], \"radius\": 1, \"material\": \"m\",\n"
                          "  \"keyframes\": [{\"time\": 0}, {\"time\": 2, \"translate\": [0, 1, 0]}]}]}";
    cr_assert_eq(test_scene_load(ok, g_files, &s, err), 0, "%s", err);
    cr_assert_eq(s.materials[1].type, MATERIAL_DIELECTRIC);
    cr_assert_float_eq(s.materials[1].ior, 1.33f, 1e-6f);
    cr_assert_eq(s.meshes[0].num_keys, 2);
    cr_assert_float_eq(s.meshes[0].keys[1].scale.y, 2.0f, 0.0f);
    /* y by 90, then x by 90: (1, 0, 0) -> (0, 0, -1) -> (0, 1, 0). */
    struct xform x = key_xform(&s.meshes[0].keys[1]);
    vec3 p = xform_point(&x, v3(0.5f, 0, 0));
    cr_assert(fabsf(p.x - 1.0f) < 1e-5f && fabsf(p.y - 1.0f) < 1e-5f && fabsf(p.z) < 1e-5f, "%g %g %g",
              (double)p.x, (double)p.y, (double)p.z);
    cr_assert_eq(s.meshes[1].num_frames, 2);
    cr_assert_float_eq(s.meshes[1].frame_positions[9 + 2], 1.0f, 0.0f);
    cr_assert_eq(s.spheres[0].num_keys, 2);
    scene_fini(&s);

    expect_error(HEAD "\"objects\": [{\"type\": \"obj\", \"frames\": [\"a.obj\", \"quad.obj\"], \"frame_times\": [0, 1]}]}",
                 "scenes/t.json:5:49: frame \"quad.obj\" does not have the topology of the first frame");
    expect_error(HEAD "\"objects\": [{\"type\": \"obj\", \"frames\": [\"a.obj\", \"b.obj\"], \"frame_times\": [1, 1]}]}",
                 "scenes/t.json:5:78: frame_times must increase");
    expect_error(HEAD "\"objects\": [{\"type\": \"obj\", \"frames\": [\"a.obj\", \"b.obj\"]}]}",
                 "frame_times must be an array of 2 numbers");
    expect_error(HEAD "\"objects\": [{\"type\": \"obj\", \"file\": \"a.obj\", \"keyframes\": [{\"time\": 1}, {\"time\": 0}]}]}",
                 "scenes/t.json:5:82: keyframe times must increase");
    expect_error(HEAD "\"objects\": [{\"type\": \"obj\", \"file\": \"a.obj\", \"keyframes\": [{\"time\": 0, \"scale\": -1}]}]}",
                 "scenes/t.json:5:81: keyframe scale must be > 0");
    expect_error(HEAD "\"objects\": [{\"type\": \"obj\", \"file\": \"a.obj\", \"keyframes\": [{\"time\": 0, \"spin\": 1}]}]}",
                 "scenes/t.json:5:72: unknown key \"spin\" in keyframes[0]");
    expect_error("{\"version\": 1,\n\"camera\": {\"position\": [0, 0, -5], \"look_at\": [0, 0, 0], \"fov_y\": 40},\n"
                 "\"render\": {\"width\": 8, \"height\": 8},\n\"materials\": {\"x\": {\"type\": \"mirror\", \"ior\": 1.5}}}",
                 "scenes/t.json:4:39: key \"ior\" does not apply to a mirror material");
    expect_error("{\"version\": 1,\n\"camera\": {\"position\": [0, 0, -5], \"look_at\": [0, 0, 0], \"fov_y\": 40},\n"
                 "\"render\": {\"width\": 8, \"height\": 8},\n\"materials\": {\"x\": {\"type\": \"dielectric\", \"ior\": \"1.5\"}}}",
                 "scenes/t.json:4:50: ior must be a number, not a string");
    expect_error("{\"version\": 1,\n\"camera\": {\"position\": [0, 0, -5], \"look_at\": [0, 0, 0], \"fov_y\": 40},\n"
                 "\"render\": {\"width\": 8, \"height\": 8},\n\"materials\": {\"x\": {\"type\": \"mirror\", \"reflectance\": [1, 2, 0]}}}",
                 "scenes/t.json:4:58: reflectance components must be in [0, 1]");
}

/* The next frame of a kept scene (render_job_reframe, as a worker does between frames)
 * gives the pixels of a fresh job for that frame, and keeps the texture pyramids. */
Test(motion, reframed_job_equals_a_fresh_one)
{
    struct scene s;
    memset(&s, 0, sizeof s);
    uint32_t lamp = add_mat(&s, v3(2, 2, 2));
    struct mesh q = quad_mesh(-10, 0, -10, 10, lamp);
    q.keys = keys2(key(0, v3(-1, 0, 0), v3(0, 0, 1), 0), key(3, v3(1, 0, 0), v3(0, 0, 1), 30));
    q.num_keys = 2;
    scene_add_mesh(&s, &q);
    /* A still image-textured wall behind, lit by the moving lamp: the job has pyramids. */
    s.textures = mem_calloc(1, sizeof *s.textures);
    s.num_textures = 1;
    texture_init(&s.textures[0], TEXTURE_IMAGE, "ramp");
    cr_assert_eq(tex_image_alloc(&s.textures[0].image, 8, 8, 1, TEXEL_F32), 0);
    for (int i = 0; i < 64; i++)
        ((float *)s.textures[0].image.data)[i] = (float)(i % 7) / 7.0f;
    struct material wm;
    memset(&wm, 0, sizeof wm);
    wm.type = MATERIAL_DIFFUSE;
    wm.albedo = v3(1, 1, 1);
    wm.albedo_tex = 1;
    struct mesh wall = quad_mesh(-20, 20, -20, 20, scene_add_material(&s, &wm));
    for (int k = 0; k < 4; k++)
        wall.positions[3 * k + 2] = -1.0f;
    scene_add_mesh(&s, &wall);
    test_ramp_camera(&s, 32, 4);
    s.settings.max_depth = 2;
    struct render_job a, b;
    char err[256];
    cr_assert_eq(render_job_init(&a, &s, 0, 2, err, sizeof err), 0, "%s", err);
    const struct mip *mips = a.mips;
    cr_assert_eq(render_job_reframe(&a, 2, 2, err, sizeof err), 0, "%s", err);
    cr_assert(mips && a.mips == mips && a.textured, "pyramids kept");
    cr_assert_eq(a.frame, 2u);
    cr_assert_eq(render_job_init(&b, &s, 2, 2, err, sizeof err), 0, "%s", err);
    uint32_t w = s.settings.width, h = s.settings.height;
    float *pa = mem_alloc(sizeof(float) * w * h * TILE_NUM_CHANNELS), *pb = mem_alloc(sizeof(float) * w * h * TILE_NUM_CHANNELS);
    struct tile_stats sa, sb;
    integrator_render_tile(&a, 0, 0, w, h, pa, &sa);
    integrator_render_tile(&b, 0, 0, w, h, pb, &sb);
    cr_assert(memcmp(pa, pb, sizeof(float) * w * h * TILE_NUM_CHANNELS) == 0, "reframed pixels differ from a fresh job's");
    /* And the frame matters: frame 0 differs. */
    render_job_fini(&b);
    cr_assert_eq(render_job_init(&b, &s, 0, 2, err, sizeof err), 0, "%s", err);
    integrator_render_tile(&b, 0, 0, w, h, pb, &sb);
    cr_assert(memcmp(pa, pb, sizeof(float) * w * h * TILE_NUM_CHANNELS) != 0, "frames 0 and 2 render the same");
    free(pa);
    free(pb);
    render_job_fini(&a);
    render_job_fini(&b);
    scene_fini(&s);
}
