/* The surface's u axis (surface_dpdu, render/surface.c) and the anisotropic lobes' frame
 * built on it (material_with_axis, material_frame, scene/material.c): the roughness axes follow
 * the mesh's uv map (swapping u and v turns them 90 degrees), the sphere's longitude, the
 * rigid motion at the ray's time; the arbitrary frame where there are no uvs. And a
 * render: an anisotropic highlight on a quad stretches along the uv map's u axis. */
#include <criterion/criterion.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include "helpers.h"
#include "base/log.h"
#include "render/render_job.h"
#include "render/surface.h"
#include "base/rng.h"
#include "scene/material.h"

#define QUAD_V "v -2 -2 0\nv 2 -2 0\nv 2 2 0\nv -2 2 0\n"

/* u along +x (v along +y), u along +y (swapped), no uvs, and smooth normals tilted to +x. */
static const struct mem_file files[] = {
    {"uv.obj", QUAD_V "vt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nf 1/1 2/2 3/3 4/4\n", 0},
    {"swap.obj", QUAD_V "vt 0 0\nvt 0 1\nvt 1 1\nvt 1 0\nf 1/1 2/2 3/3 4/4\n", 0},
    {"nouv.obj", QUAD_V "f 1 2 3 4\n", 0},
    {"smooth.obj", QUAD_V "vt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nvn 0.5 0 1\nf 1/1/1 2/2/1 3/3/1 4/4/1\n", 0},
    {NULL, NULL, 0}};

/* A scene with objects (JSON array items) over the conductor "brushed" (uroughness 0.5,
 * vroughness 0.1) and an isotropic one, "round"; camera at z = 4 looking down -z. */
static void load(const char *objects, uint32_t size, uint32_t spp, struct scene *s)
{
    char text[4096], err[512];
    snprintf(text, sizeof text,
             "{\"version\": 1, \"camera\": {\"position\": [0, 0, 4], \"look_at\": [0, 0, 0], \"fov_y\": 40,"
             " \"shutter_open\": 0, \"shutter_close\": 1},\n"
             "\"render\": {\"width\": %u, \"height\": %u, \"spp\": %u, \"max_depth\": 1, \"seed\": 5, \"tile_size\": 16},\n"
             "\"materials\": {\"brushed\": {\"type\": \"conductor\", \"reflectance\": [0.9, 0.9, 0.9],"
             " \"uroughness\": 0.5, \"vroughness\": 0.1},\n"
             " \"round\": {\"type\": \"conductor\", \"reflectance\": [0.9, 0.9, 0.9], \"roughness\": 0.3}},\n"
             "\"objects\": [%s],\n"
             "\"lights\": [{\"type\": \"point\", \"position\": [0, 0, 4], \"intensity\": [20, 20, 20]}]}",
             size, size, spp, objects);
    cr_assert_eq(test_scene_load(text, files, s, err), 0, "%s", err);
}

struct hit {
    struct surface s;
    vec3 dpdu;
};

/* The surface where the ray from (x, y, 4) down -z meets the scene at time01, and its dP/du
 * where the material is anisotropic (as the integrators ask for it). */
static struct hit hit_at(const char *objects, float x, float y, float time01)
{
    log_set_level(LOG_ERROR);
    struct scene s;
    load(objects, 8, 1, &s);
    struct render_job job;
    char err[512];
    cr_assert_eq(render_job_init(&job, &s, 0, 1, err, sizeof err), 0, "%s", err);
    struct accel_hit h;
    vec3 o = v3(x, y, 4), d = v3(0, 0, -1);
    cr_assert(accel_intersect(&job.accel, o, d, INFINITY, time01, &h));
    struct hit r;
    surface_from_hit(&job.accel, &job.lights, o, d, &h, time01, &r.s);
    r.dpdu = material_is_anisotropic(&s.materials[r.s.material]) ? surface_dpdu(&job.accel, o, d, &h, time01)
                                                                  : v3(0, 0, 0);
    render_job_fini(&job);
    scene_fini(&s);
    return r;
}

/* v is a positive multiple of the unit vector want (to float rounding). */
static void assert_along(vec3 v, vec3 want, const char *what)
{
    float l = v3_length(v);
    cr_assert(l > 0.0f, "%s: zero", what);
    vec3 u = v3_scale(v, 1.0f / l);
    cr_assert(v3_dot(u, want) > 1.0f - 1e-5f, "%s: (%g, %g, %g), want (%g, %g, %g)", what, u.x, u.y, u.z, want.x,
              want.y, want.z);
}

Test(surface, dpdu_follows_the_uv_map)
{
    struct hit a = hit_at("{\"type\": \"obj\", \"file\": \"uv.obj\", \"material\": \"brushed\"}", 0.3f, 0.2f, 0.0f);
    assert_along(a.dpdu, v3(1, 0, 0), "u along x");
    cr_assert_float_eq(v3_length(a.dpdu), 4.0f, 1e-5f); /* the quad is 4 wide over u in [0, 1] */
    struct hit b = hit_at("{\"type\": \"obj\", \"file\": \"swap.obj\", \"material\": \"brushed\"}", 0.3f, 0.2f, 0.0f);
    assert_along(b.dpdu, v3(0, 1, 0), "u and v swapped: u along y");
    /* Other side of the quad's diagonal (the other triangle): the same axis. */
    struct hit c = hit_at("{\"type\": \"obj\", \"file\": \"uv.obj\", \"material\": \"brushed\"}", -0.5f, 0.7f, 0.0f);
    assert_along(c.dpdu, v3(1, 0, 0), "second triangle");
}

Test(surface, dpdu_zero_without_uvs)
{
    struct hit a = hit_at("{\"type\": \"obj\", \"file\": \"nouv.obj\", \"material\": \"brushed\"}", 0.3f, 0.2f, 0.0f);
    cr_assert(a.dpdu.x == 0.0f && a.dpdu.y == 0.0f && a.dpdu.z == 0.0f, "no uvs: the arbitrary frame");
}

Test(surface, dpdu_of_a_sphere_is_its_longitude)
{
    const char *sp = "{\"type\": \"sphere\", \"center\": [0, 0, 0], \"radius\": 1, \"material\": \"brushed\"}";
    struct hit a = hit_at(sp, 0.0f, 0.0f, 0.0f);
    assert_along(a.dpdu, v3(1, 0, 0), "sphere at +z");
    struct hit b = hit_at(sp, 0.6f, 0.0f, 0.0f); /* n = (0.6, 0, 0.8) */
    assert_along(b.dpdu, v3(0.8f, 0, -0.6f), "sphere at (0.6, 0, 0.8)");
    cr_assert(fabsf(v3_dot(b.dpdu, b.s.ns)) < 1e-5f * v3_length(b.dpdu), "tangent to the sphere");
}

Test(surface, dpdu_turns_with_rigid_motion)
{
    /* A quarter turn about z over the shutter: u along x at time 0, along y at time 1, the
     * diagonal halfway. */
    const char *obj = "{\"type\": \"obj\", \"file\": \"uv.obj\", \"material\": \"brushed\", \"keyframes\": ["
                      "{\"time\": 0}, {\"time\": 1, \"rotate\": {\"axis\": [0, 0, 1], \"degrees\": 90}}]}";
    assert_along(hit_at(obj, 0.3f, 0.2f, 0.0f).dpdu, v3(1, 0, 0), "time 0");
    assert_along(hit_at(obj, 0.3f, 0.2f, 1.0f).dpdu, v3(0, 1, 0), "time 1");
    assert_along(hit_at(obj, 0.3f, 0.2f, 0.5f).dpdu, v3_normalize(v3(1, 1, 0)), "time 0.5");
    const char *sp = "{\"type\": \"sphere\", \"center\": [0, 0, 0], \"radius\": 1, \"material\": \"brushed\", \"keyframes\": ["
                     "{\"time\": 0}, {\"time\": 1, \"rotate\": {\"axis\": [0, 0, 1], \"degrees\": 90}}]}";
    assert_along(hit_at(sp, 0.0f, 0.0f, 1.0f).dpdu, v3(0, 1, 0), "rotated sphere at +z, time 1");
}

/* A still mesh beside a moving sphere: its hits take the inline path (accel.still_tri, per
 * geometry, not only when nothing in the scene moves) and give the general path's surface
 * bit for bit; the sphere's keep the general path. */
Test(surface, still_mesh_beside_a_moving_sphere)
{
    log_set_level(LOG_ERROR);
    struct scene s;
    load("{\"type\": \"obj\", \"file\": \"uv.obj\", \"material\": \"round\"},"
         "{\"type\": \"sphere\", \"center\": [5, 0, 0], \"radius\": 1, \"material\": \"round\", \"keyframes\": ["
         "{\"time\": 0}, {\"time\": 1, \"translate\": [0, 1, 0]}]}",
         8, 1, &s);
    struct render_job job;
    char err[512];
    cr_assert_eq(render_job_init(&job, &s, 0, 1, err, sizeof err), 0, "%s", err);
    const struct accel *a = &job.accel;
    cr_assert(a->has_motion && a->still_geoms == 0, "the sphere moves");
    cr_assert(a->still_tri[0] == 1, "the quad is still");
    cr_assert(a->still_tri[a->sphere_geom] == 0, "spheres take the general path");
    struct accel_hit h;
    vec3 o = v3(0.3f, 0.2f, 4), d = v3(0, 0, -1);
    cr_assert(accel_intersect(a, o, d, INFINITY, 0.5f, &h) && h.geom == 0);
    struct surface fast, slow;
    memset(&fast, 0, sizeof fast);
    memset(&slow, 0, sizeof slow);
    surface_from_hit(a, &job.lights, o, d, &h, 0.5f, &fast);
    surface_from_hit_slow_(a, &job.lights, o, d, &h, 0.5f, &slow);
    cr_assert(memcmp(&fast, &slow, sizeof fast) == 0, "the inline surface is the general one");
    render_job_fini(&job);
    scene_fini(&s);
}

/* light_sample: a point light's sample reads neither the pick (one light) nor the point's
 * uniforms (NaN there changes nothing), and a table without lights gives no sample. */
Test(surface, light_sample_point_and_empty_table)
{
    log_set_level(LOG_ERROR);
    struct scene s;
    load("{\"type\": \"obj\", \"file\": \"uv.obj\", \"material\": \"round\"}", 8, 1, &s);
    struct light_table t;
    light_table_init(&t, &s);
    cr_assert(t.num_entries == 1 && t.points_only && !light_sample_reads_pick(&t) && !light_sample_reads_point(&t));
    struct light_sample ls;
    light_sample(&t, &s, v3(0, 0, 2), NAN, NAN, NAN, &ls);
    cr_assert(ls.pdf == 1.0f && ls.is_delta && ls.entry == 0);
    cr_assert(ls.p.x == 0.0f && ls.p.y == 0.0f && ls.p.z == 4.0f);
    cr_assert(ls.radiance.x == 5.0f && ls.radiance.y == 5.0f && ls.radiance.z == 5.0f, "I / d^2 = 20 / 4");
    light_table_fini(&t);
    s.num_lights = 0; /* the quad alone: nothing emits */
    light_table_init(&t, &s);
    cr_assert(t.num_entries == 0);
    ls.pdf = 1.0f;
    light_sample(&t, &s, v3(0, 0, 2), 0.5f, 0.5f, 0.5f, &ls);
    cr_assert(ls.pdf == 0.0f, "no lights, no sample");
    light_table_fini(&t);
    s.num_lights = 1;
    scene_fini(&s);
}

Test(surface, frame_gram_schmidt_against_the_shading_normal)
{
    vec3 x, y;
    /* Smooth normals: the uv axis stays the surface's dP/du; the frame makes it orthogonal
     * to whatever shading normal the lobe uses, keeping it in the plane of (tu, n). */
    struct hit s = hit_at("{\"type\": \"obj\", \"file\": \"smooth.obj\", \"material\": \"brushed\"}", 0.3f, 0.2f, 0.0f);
    assert_along(s.dpdu, v3(1, 0, 0), "smooth quad: dP/du");
    cr_assert(s.s.ns.x > 0.4f, "tilted shading normal");
    material_frame(s.s.ns, s.dpdu, &x, &y);
    cr_assert(fabsf(v3_dot(x, s.s.ns)) < 1e-6f && fabsf(v3_dot(y, s.s.ns)) < 1e-6f && fabsf(v3_dot(x, y)) < 1e-6f);
    cr_assert(fabsf(v3_length(x) - 1.0f) < 1e-6f && fabsf(v3_length(y) - 1.0f) < 1e-6f);
    cr_assert(fabsf(x.y) < 1e-6f && x.x > 0.0f, "x in the plane of dP/du and n");
    assert_along(y, v3(0, 1, 0), "y = n x x");
    /* No usable axis: the arbitrary frame, exactly. */
    vec3 n = v3_normalize(v3(0.3f, -0.2f, 0.9f)), bt, bb;
    v3_basis(n, &bt, &bb);
    material_frame(n, v3(0, 0, 0), &x, &y);
    cr_assert(x.x == bt.x && x.y == bt.y && x.z == bt.z && y.x == bb.x && y.y == bb.y && y.z == bb.z);
    material_frame(n, v3_scale(n, 3.0f), &x, &y);
    cr_assert(x.x == bt.x && x.y == bt.y && x.z == bt.z, "tu along n");
}

Test(surface, anisotropic_lobe_turns_with_the_axis)
{
    struct material m, mx, my;
    memset(&m, 0, sizeof m);
    m.type = MATERIAL_CONDUCTOR;
    m.schlick = 1;
    m.reflectance = v3(0.9f, 0.9f, 0.9f);
    m.alpha_x = 0.25f;
    m.alpha_y = 0.01f;
    vec3 n = v3(0, 0, 1);
    uint64_t key = 0x5eedull;
    for (uint32_t i = 0; i < 64; i++) {
        /* wo, wi above the surface; R: a quarter turn about n. */
        float a = 6.2831853f * rng_uniform(key, 4 * i), b = 6.2831853f * rng_uniform(key, 4 * i + 1);
        float ca = 0.2f + 0.8f * rng_uniform(key, 4 * i + 2), cb = 0.2f + 0.8f * rng_uniform(key, 4 * i + 3);
        float sa = sqrtf(1.0f - ca * ca), sb = sqrtf(1.0f - cb * cb);
        vec3 wo = v3(sa * cosf(a), sa * sinf(a), ca), wi = v3(sb * cosf(b), sb * sinf(b), cb);
        vec3 rwo = v3(-wo.y, wo.x, wo.z), rwi = v3(-wi.y, wi.x, wi.z);
        float p1, p2;
        vec3 f1 = material_eval(material_with_axis(&m, v3(1, 0, 0), &mx), n, wo, wi, 1, &p1);
        vec3 f2 = material_eval(material_with_axis(&m, v3(0, 2, 0), &my), n, rwo, rwi, 1, &p2);
        cr_assert(fabsf(f1.x - f2.x) <= 1e-5f * fmaxf(1.0f, f1.x) && fabsf(p1 - p2) <= 1e-5f * fmaxf(1.0f, p1),
                  "pair %u: %g %g, pdf %g %g", i, f1.x, f2.x, p1, p2);
        struct bsdf_sample s1, s2;
        material_sample(&mx, n, wo, 1, rng_uniform(key, 1000 + i), rng_uniform(key, 2000 + i), &s1);
        material_sample(&my, n, rwo, 1, rng_uniform(key, 1000 + i), rng_uniform(key, 2000 + i), &s2);
        cr_assert((s1.pdf > 0.0f) == (s2.pdf > 0.0f), "sample %u: one failed, not the other", i);
        cr_assert(!(s1.pdf > 0.0f) || (fabsf(s2.wi.x + s1.wi.y) < 1e-5f && fabsf(s2.wi.y - s1.wi.x) < 1e-5f && fabsf(s2.wi.z - s1.wi.z) < 1e-5f),
                  "sample %u turns with the axis", i);
    }
    /* The lobe is wider along the axis: light reflected off the mirror direction along x
     * is brighter with u along x than with u along y. */
    vec3 wo = v3(0, 0, 1), wi = v3_normalize(v3(0.4f, 0, 1));
    float p;
    float along = material_eval(material_with_axis(&m, v3(1, 0, 0), &mx), n, wo, wi, 1, &p).x;
    float across = material_eval(material_with_axis(&m, v3(0, 1, 0), &my), n, wo, wi, 1, &p).x;
    cr_assert(along > 10.0f * across, "along u %g, across %g", along, across);
    /* An isotropic lobe ignores the axis, bit for bit. */
    m.alpha_x = m.alpha_y = 0.09f;
    vec3 tn = v3_normalize(v3(0.2f, 0.1f, 1.0f));
    struct bsdf_sample s1, s2;
    material_sample(&m, tn, wo, 1, 0.3f, 0.6f, &s1);
    material_sample(material_with_axis(&m, v3(0.3f, 0.7f, 0.1f), &mx), tn, wo, 1, 0.3f, 0.6f, &s2);
    cr_assert(s1.wi.x == s2.wi.x && s1.wi.y == s2.wi.y && s1.wi.z == s2.wi.z && s1.pdf == s2.pdf);
}

/* Second moments of the red channel about its centroid over a w x w render. */
static void moments(const float *px, uint32_t w, double *mxx, double *myy)
{
    double s = 0, sx = 0, sy = 0, sxx = 0, syy = 0;
    for (uint32_t y = 0; y < w; y++)
        for (uint32_t x = 0; x < w; x++) {
            double v = px[((size_t)y * w + x) * TILE_NUM_CHANNELS + CH_R];
            s += v, sx += v * x, sy += v * y, sxx += v * x * x, syy += v * y * y;
        }
    cr_assert(s > 0.0);
    *mxx = sxx / s - (sx / s) * (sx / s);
    *myy = syy / s - (sy / s) * (sy / s);
}

/* The render check: a brushed quad seen from the point light. With u along x the
 * highlight stretches along x; with u and v swapped in the mesh, along y. */
Test(surface, anisotropic_highlight_turns_with_the_uv_map)
{
    log_set_level(LOG_ERROR);
    const uint32_t w = 48;
    double r[2];
    const char *obj[2] = {"{\"type\": \"obj\", \"file\": \"uv.obj\", \"material\": \"brushed\"}",
                          "{\"type\": \"obj\", \"file\": \"swap.obj\", \"material\": \"brushed\"}"};
    for (int k = 0; k < 2; k++) {
        struct scene s;
        load(obj[k], w, 16, &s);
        struct tile_stats st;
        float *px = test_render(&s, 2, &st);
        double mxx, myy;
        moments(px, w, &mxx, &myy);
        r[k] = mxx / myy;
        free(px);
        scene_fini(&s);
    }
    cr_assert(r[0] > 2.0 && r[1] < 0.5, "x/y spread of the highlight: u along x %g, swapped %g", r[0], r[1]);
    cr_assert(fabs(log(r[0]) + log(r[1])) < 0.2, "a quarter turn: the ratios are inverse (%g, %g)", r[0], r[1]);
}

/* MIS weights whose squares overflow float (a lamp's area pdf of 1e24 seen from inside a
 * sphere of radius 1e12) stay finite: inf / inf was a NaN sample. */
Test(surface, power_heuristic_finite_when_squares_overflow)
{
    cr_expect(power_heuristic(2.0f, 1.0f) == 0.8f);
    float w = power_heuristic(1.14e24f, 0.318f);
    cr_expect(w == 1.0f, "%g", w);
    w = power_heuristic(0.318f, 1.14e24f);
    cr_expect(w >= 0.0f && w < 1e-40f, "%g", w);
    w = power_heuristic(3e19f, 3e19f);
    cr_expect(w == 0.5f, "%g", w);
    cr_expect(power_heuristic(INFINITY, 1.0f) == 1.0f);
    cr_expect(power_heuristic(INFINITY, INFINITY) == 0.5f);
    cr_expect(power_heuristic(NAN, 1.0f) == 0.0f);
}
