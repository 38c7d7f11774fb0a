/* Camera rays. Pinhole: centre ray along the view direction, corners at the field of view,
 * handedness (image right = camera right), unit directions. Thin lens: aperture 0 is the
 * pinhole bit for bit; the circle of confusion matches the thin-lens formula; polygonal
 * apertures are inside the polygon and uniform; shutter and keyframed motion; hard cases
 * (tiny/huge focus, huge aperture, zero shutter, 180-degree turns) stay finite. */
#include <criterion/criterion.h>
#include <math.h>
#include <string.h>
#include "scene/camera.h"

static struct camera make(float fov, uint32_t w, uint32_t h)
{
    struct camera_desc d;
    memset(&d, 0, sizeof d);
    d.position = v3(0, 0, 0);
    d.look_at = v3(0, 0, -1);
    d.up = v3(0, 1, 0);
    d.fov_y_deg = fov;
    struct camera c;
    camera_init(&c, &d, w, h);
    return c;
}

Test(camera, centre_ray_is_view_direction)
{
    struct camera c = make(60.0f, 640, 480);
    vec3 o, d;
    camera_ray(&c, 320.0f, 240.0f, &o, &d);
    cr_assert_float_eq(d.x, 0.0f, 1e-6f);
    cr_assert_float_eq(d.y, 0.0f, 1e-6f);
    cr_assert_float_eq(d.z, -1.0f, 1e-6f);
}

Test(camera, vertical_field_of_view)
{
    struct camera c = make(90.0f, 100, 100);
    vec3 o, d;
    camera_ray(&c, 50.0f, 0.0f, &o, &d); /* top edge, centre column: 45 degrees up */
    cr_assert_float_eq(atan2f(d.y, -d.z), (float)M_PI / 4.0f, 1e-5f);
    camera_ray(&c, 100.0f, 50.0f, &o, &d); /* right edge: +x when looking down -z */
    cr_assert_gt(d.x, 0.0f);
    cr_assert_float_eq(atan2f(d.x, -d.z), (float)M_PI / 4.0f, 1e-5f);
}

Test(camera, aspect_ratio_widens_horizontally)
{
    struct camera c = make(60.0f, 200, 100);
    vec3 o, d;
    camera_ray(&c, 200.0f, 50.0f, &o, &d);
    float tan_h = d.x / -d.z;
    cr_assert_float_eq(tan_h, 2.0f * tanf(30.0f * (float)M_PI / 180.0f), 1e-5f);
}

Test(camera, unit_directions_everywhere)
{
    struct camera c = make(120.0f, 33, 17);
    for (float y = 0; y <= 17; y += 0.5f)
        for (float x = 0; x <= 33; x += 0.5f) {
            vec3 o, d;
            camera_ray(&c, x, y, &o, &d);
            cr_assert_float_eq(v3_length(d), 1.0f, 1e-5f);
        }
}

Test(vec, sincos_2pi_accuracy)
{
    double worst = 0.0;
    for (int i = 0; i <= 1 << 20; i++) {
        float u = (float)i / (float)(1 << 20), s, c;
        sincos_2pi(u, &s, &c);
        double a = 2.0 * M_PI * (double)u;
        worst = fmax(worst, fmax(fabs(s - sin(a)), fabs(c - cos(a))));
    }
    cr_assert_lt(worst, 2e-7, "worst error %g", worst);
}

Test(vec, basis_is_orthonormal)
{
    vec3 ns[] = {v3(0, 0, 1), v3(0, 0, -1), v3(1, 0, 0), v3(0.6f, 0.0f, -0.8f), v3(0.577350f, 0.577350f, 0.577350f)};
    for (size_t i = 0; i < sizeof ns / sizeof ns[0]; i++) {
        vec3 n = v3_normalize(ns[i]), t, b;
        v3_basis(n, &t, &b);
        cr_assert_float_eq(v3_dot(t, t), 1.0f, 1e-6f);
        cr_assert_float_eq(v3_dot(b, b), 1.0f, 1e-6f);
        cr_assert_float_eq(v3_dot(t, n), 0.0f, 1e-6f);
        cr_assert_float_eq(v3_dot(b, n), 0.0f, 1e-6f);
        cr_assert_float_eq(v3_dot(t, b), 0.0f, 1e-6f);
    }
}

static struct camera_desc desc_basic(void)
{
    struct camera_desc d;
    memset(&d, 0, sizeof d);
    d.position = v3(0, 0, 0);
    d.look_at = v3(0, 0, -1);
    d.up = v3(0, 1, 0);
    d.fov_y_deg = 40.0f;
    return d;
}

static int same_bits(vec3 a, vec3 b)
{
    return memcmp(&a, &b, sizeof a) == 0;
}

Test(thin_lens, aperture_zero_is_pinhole_bit_for_bit)
{
    struct camera_desc d = desc_basic();
    d.focus_distance = 3.0f;
    struct camera c;
    camera_init(&c, &d, 64, 48);
    cr_assert_eq(c.uses_lens, 0);
    cr_assert_eq(c.uses_time, 0);
    for (int t = 0; t < SAMPLER_COUNT_; t++)
        for (uint32_t i = 0; i < 64; i++) {
            uint32_t px = i % 64, py = (i * 7) % 48;
            struct sampler s = sampler_start_type((enum sampler_type)t, 4, 0, py * 64u + px, i, 16);
            struct camera_sample cs;
            camera_generate(&c, &s, 0, px, py, &cs);
            /* The pre-thin-lens ray generation, verbatim. */
            vec3 o, dir;
            camera_ray(&c, (float)px + sampler_get(&s, DIM_PIXEL_X), (float)py + sampler_get(&s, DIM_PIXEL_Y), &o, &dir);
            cr_assert(same_bits(cs.o, o) && same_bits(cs.d, dir));
            cr_assert_eq(cs.time01, 0.0f);
            /* The inline pinhole is the general path's. */
            struct camera_sample cg;
            camera_generate_general_(&c, &s, 0, px, py, &cg);
            cr_assert(same_bits(cs.o, cg.o) && same_bits(cs.d, cg.d) && cs.jx == cg.jx && cs.jy == cg.jy &&
                      cs.time01 == cg.time01);
        }
}

/* The film position (pixels) at which point q is seen through lens sample (lu, lv): the
 * camera is linear in film position for a fixed lens point, so two rays locate it. */
static void film_of_point(const struct camera *c, vec3 q, float lu, float lv, double *fx, double *fy)
{
    double f[2] = {0, 0};
    for (int axis = 0; axis < 2; axis++) {
        double val[2];
        for (int k = 0; k < 2; k++) {
            float x = axis == 0 ? 10.0f + 30.0f * k : 32.0f, y = axis == 1 ? 10.0f + 30.0f * k : 32.0f;
            vec3 o, d;
            camera_ray_lens(c, &c->still, x, y, lu, lv, &o, &d);
            double t = ((double)q.z - o.z) / d.z; /* plane z = q.z (camera looks down -z) */
            val[k] = axis == 0 ? o.x + t * d.x - q.x : o.y + t * d.y - q.y;
        }
        /* val is linear in the film coordinate: zero crossing. */
        f[axis] = 10.0 + 30.0 * val[0] / (val[0] - val[1]);
    }
    *fx = f[0];
    *fy = f[1];
}

Test(thin_lens, circle_of_confusion_matches_formula)
{
    /* Film in tangent units t = s / focus: a point at depth z is seen through lens offset a at
     * t = a (1/zf - 1/z), so the blur diameter is 2 R |z - zf| / (z zf) tangent units, i.e.
     * times height / (2 tan(fov/2)) pixels. (The brief's A f |z - zf| / (z (zf - f)) with
     * film distance f zf / (zf - f) in place of f is the same expression.) */
    const float R = 0.05f, zf = 4.0f, zs[] = {1.5f, 2.5f, 8.0f, 40.0f};
    struct camera_desc d = desc_basic();
    d.aperture_radius = R;
    d.focus_distance = zf;
    struct camera c;
    camera_init(&c, &d, 64, 64);
    for (size_t k = 0; k < sizeof zs / sizeof *zs; k++) {
        vec3 q = v3(0, 0, -zs[k]);
        double lo_x = 1e30, hi_x = -1e30, lo_y = 1e30, hi_y = -1e30;
        for (uint32_t i = 0; i < 4096; i++) {
            struct sampler s = sampler_start_type(SAMPLER_SOBOL, 1, 0, 0, i, 4096);
            float lu, lv;
            sampler_get_2d(&s, DIM_LENS_U, &lu, &lv);
            double fx, fy;
            film_of_point(&c, q, lu, lv, &fx, &fy);
            lo_x = fmin(lo_x, fx), hi_x = fmax(hi_x, fx), lo_y = fmin(lo_y, fy), hi_y = fmax(hi_y, fy);
        }
        double expect = 2.0 * R * fabs(zs[k] - zf) / (zs[k] * zf) * 64.0 / (2.0 * tan(20.0 * M_PI / 180.0));
        cr_assert(fabs((hi_x - lo_x) - expect) < 0.03 * expect, "z=%g x-diameter %g, expected %g", zs[k], hi_x - lo_x,
                  expect);
        cr_assert(fabs((hi_y - lo_y) - expect) < 0.03 * expect, "z=%g y-diameter %g, expected %g", zs[k], hi_y - lo_y,
                  expect);
    }
    /* In focus: every lens point sees it at the same film position. */
    double fx0, fy0, fx1, fy1;
    film_of_point(&c, v3(0.3f, -0.2f, -zf), 0.1f, 0.2f, &fx0, &fy0);
    film_of_point(&c, v3(0.3f, -0.2f, -zf), 0.9f, 0.7f, &fx1, &fy1);
    cr_assert(fabs(fx0 - fx1) < 1e-3 && fabs(fy0 - fy1) < 1e-3);
}

static int inside_polygon(const struct camera *c, float x, float y, float eps)
{
    for (uint32_t k = 0; k < c->blades; k++) {
        float ax = c->blade_x[k] * c->lens_radius, ay = c->blade_y[k] * c->lens_radius;
        float bx = c->blade_x[k + 1] * c->lens_radius, by = c->blade_y[k + 1] * c->lens_radius;
        if ((bx - ax) * (y - ay) - (by - ay) * (x - ax) < -eps)
            return 0;
    }
    return 1;
}

/* Chi-square of lens samples over an 8x8 grid on the bounding square, expected counts from
 * each cell's area inside the aperture (fine sub-grid), cells with < 5 expected merged out. */
static void check_aperture_uniform(const struct camera *c)
{
    enum { G = 8, SUB = 64, N = 200000 };
    static double area[G * G];
    static unsigned hist[G * G];
    memset(hist, 0, sizeof hist);
    double total = 0.0;
    for (int cy = 0; cy < G; cy++)
        for (int cx = 0; cx < G; cx++) {
            int in = 0;
            for (int j = 0; j < SUB; j++)
                for (int i = 0; i < SUB; i++) {
                    float x = (float)(-1.0 + 2.0 * (cx + (i + 0.5) / SUB) / G) * c->lens_radius;
                    float y = (float)(-1.0 + 2.0 * (cy + (j + 0.5) / SUB) / G) * c->lens_radius;
                    in += c->blades ? inside_polygon(c, x, y, 0.0f) : (x * x + y * y <= c->lens_radius * c->lens_radius);
                }
            area[cy * G + cx] = in;
            total += in;
        }
    for (uint32_t i = 0; i < N; i++) {
        float x, y;
        camera_lens_point(c, rng_uniform(rng_key(3, 0, i, 0), 0), rng_uniform(rng_key(3, 0, i, 0), 1), &x, &y);
        if (c->blades)
            cr_assert(inside_polygon(c, x, y, 1e-5f * c->lens_radius), "(%g, %g) outside", x, y);
        else
            cr_assert_leq(x * x + y * y, c->lens_radius * c->lens_radius * (1.0f + 1e-5f));
        int cx = (int)floorf((x / c->lens_radius + 1.0f) * 0.5f * G), cy = (int)floorf((y / c->lens_radius + 1.0f) * 0.5f * G);
        cx = cx < 0 ? 0 : (cx >= G ? G - 1 : cx);
        cy = cy < 0 ? 0 : (cy >= G ? G - 1 : cy);
        hist[cy * G + cx]++;
    }
    double chi2 = 0.0;
    int dof = -1;
    for (int k = 0; k < G * G; k++) {
        double e = N * area[k] / total;
        if (e < 50.0)
            continue; /* edge slivers: the sub-grid area estimate is too coarse there */
        chi2 += (hist[k] - e) * (hist[k] - e) / e;
        dof++;
    }
    /* Generous bound (about p = 1e-4 for these dof). */
    cr_assert_lt(chi2, dof + 5.0 * sqrt(2.0 * dof), "chi2 %g with %d dof", chi2, dof);
}

Test(thin_lens, polygon_aperture_inside_and_uniform)
{
    const uint32_t blades[] = {3, 5, 6, 9};
    for (size_t k = 0; k < 4; k++) {
        struct camera_desc d = desc_basic();
        d.aperture_radius = 0.5f;
        d.blades = blades[k];
        d.blade_rotation_deg = 17.0f;
        struct camera c;
        camera_init(&c, &d, 16, 16);
        check_aperture_uniform(&c);
    }
    struct camera_desc d = desc_basic();
    d.aperture_radius = 2.0f;
    struct camera c;
    camera_init(&c, &d, 16, 16);
    check_aperture_uniform(&c); /* circle */
}

static void all_rays_finite(const struct camera *c, uint32_t frame)
{
    for (int t = 0; t < SAMPLER_COUNT_; t++)
        for (uint32_t i = 0; i < 256; i++) {
            struct sampler s = sampler_start_type((enum sampler_type)t, 2, frame, i, i, 64);
            struct camera_sample cs;
            camera_generate(c, &s, frame, i % 16, (i / 16) % 16, &cs);
            cr_assert(v3_is_finite(cs.o) && v3_is_finite(cs.d), "non-finite ray");
            cr_assert(fabsf(v3_length(cs.d) - 1.0f) < 1e-4f, "|d| = %g", v3_length(cs.d));
            cr_assert(cs.time01 >= 0.0f && cs.time01 <= 1.0f && isfinite(camera_shutter_time(c, frame, cs.time01)));
        }
}

Test(thin_lens, hard_cases_stay_finite)
{
    const float focus[] = {1e-4f, 1e8f, 1.0f};
    const float aperture[] = {1e-6f, 1.0f, 1e6f};
    for (int f = 0; f < 3; f++)
        for (int a = 0; a < 3; a++)
            for (uint32_t blades = 0; blades < 7; blades += 6) {
                struct camera_desc d = desc_basic();
                d.focus_distance = focus[f];
                d.aperture_radius = aperture[a];
                d.blades = blades;
                struct camera c;
                camera_init(&c, &d, 16, 16);
                all_rays_finite(&c, 0);
            }
    /* A focus point behind the camera falls back to the nearest plane, still finite. */
    struct camera_desc d = desc_basic();
    d.aperture_radius = 0.1f;
    d.has_focus_point = 1;
    d.focus_point = v3(0, 0, 5);
    struct camera c;
    camera_init(&c, &d, 16, 16);
    all_rays_finite(&c, 0);
}

Test(shutter, zero_length_consumes_no_time)
{
    struct camera_desc d = desc_basic();
    d.shutter_open = d.shutter_close = 0.25f;
    d.num_keyframes = 2;
    d.keyframes[0] = (struct camera_keyframe){0.0f, v3(0, 0, 0), v3(0, 0, -1), v3(0, 1, 0)};
    d.keyframes[1] = (struct camera_keyframe){1.0f, v3(1, 0, 0), v3(1, 0, -1), v3(0, 1, 0)};
    struct camera c;
    camera_init(&c, &d, 16, 16);
    cr_assert_eq(c.uses_time, 0);
    camera_set_scene_motion(&c, 1);
    cr_assert_eq(c.uses_time, 0); /* still no time: the shutter has no length */
    struct sampler s = sampler_start_type(SAMPLER_SOBOL, 1, 0, 0, 0, 1);
    struct camera_sample cs;
    camera_generate(&c, &s, 0, 8, 8, &cs);
    cr_assert_eq(cs.time01, 0.0f);
    cr_assert_float_eq(cs.o.x, 0.25f, 1e-6f); /* the pose at frame + shutter_open */
    all_rays_finite(&c, 0);
}

Test(shutter, still_scene_consumes_no_time_unless_objects_move)
{
    struct camera_desc d = desc_basic();
    d.shutter_open = 0.0f;
    d.shutter_close = 0.5f;
    struct camera c;
    camera_init(&c, &d, 16, 16);
    cr_assert_eq(c.uses_time, 0);
    camera_set_scene_motion(&c, 1);
    cr_assert_eq(c.uses_time, 1);
    struct sampler s = sampler_start_type(SAMPLER_STRATIFIED, 1, 3, 0, 1, 4);
    struct camera_sample cs;
    camera_generate(&c, &s, 3, 8, 8, &cs);
    cr_assert_eq(cs.time01, sampler_get(&s, DIM_TIME));
    cr_assert_float_eq(camera_shutter_time(&c, 3, cs.time01), 3.0 + 0.5 * cs.time01, 1e-9);
}

Test(shutter, trapezoid_warp)
{
    struct camera_desc d = desc_basic();
    d.shutter_close = 1.0f;
    d.shutter_ramp = 0.25f;
    struct camera c;
    camera_init(&c, &d, 16, 16);
    float prev = 0.0f;
    for (int i = 0; i <= 1000; i++) {
        float u = (float)i / 1000.0f, t = camera_shutter_warp(&c, u);
        cr_assert(t >= prev && t >= 0.0f && t <= 1.0f);
        prev = t;
    }
    cr_assert_float_eq(camera_shutter_warp(&c, 0.5f), 0.5f, 1e-6f);
    cr_assert_eq(camera_shutter_warp(&c, 0.0f), 0.0f);
    /* Density: the ramps carry a / 2 each of h = 1 / (1 - r): CDF at r is h r / 2. */
    double h = 1.0 / 0.75, cdf_r = 0.5 * h * 0.25;
    cr_assert_float_eq(camera_shutter_warp(&c, (float)cdf_r), 0.25f, 1e-5f);
    d.shutter_ramp = 0.5f; /* triangle */
    camera_init(&c, &d, 16, 16);
    cr_assert_float_eq(camera_shutter_warp(&c, 0.125f), 0.25f, 1e-5f);
}

Test(camera_motion, keys_at_shutter_open_and_close)
{
    struct camera_desc d = desc_basic();
    d.shutter_open = 0.0f;
    d.shutter_close = 1.0f;
    d.num_keyframes = 2;
    d.keyframes[0] = (struct camera_keyframe){5.0f, v3(0, 0, 0), v3(0, 0, -1), v3(0, 1, 0)};
    d.keyframes[1] = (struct camera_keyframe){6.0f, v3(2, 0, 0), v3(2, 0, -1), v3(0, 1, 0)};
    struct camera c;
    camera_init(&c, &d, 16, 16);
    cr_assert(c.moving && c.uses_time);
    struct camera_pose p;
    camera_pose_at(&c, 5.0, &p);
    cr_assert_float_eq(p.origin.x, 0.0f, 1e-6f);
    cr_assert_float_eq(p.forward.z, -1.0f, 1e-6f);
    camera_pose_at(&c, 6.0, &p);
    cr_assert_float_eq(p.origin.x, 2.0f, 1e-6f);
    camera_pose_at(&c, 5.5, &p);
    cr_assert_float_eq(p.origin.x, 1.0f, 1e-6f);
    camera_pose_at(&c, 100.0, &p); /* held after the last key */
    cr_assert_float_eq(p.origin.x, 2.0f, 1e-6f);
    all_rays_finite(&c, 5);
    all_rays_finite(&c, 6);
    /* Frame 5: rays span the shutter, so origins spread over [0, 2]. */
    float lo = 1e9f, hi = -1e9f;
    for (uint32_t i = 0; i < 64; i++) {
        struct sampler s = sampler_start_type(SAMPLER_SOBOL, 1, 5, 0, i, 64);
        struct camera_sample cs;
        camera_generate(&c, &s, 5, 8, 8, &cs);
        lo = fminf(lo, cs.o.x), hi = fmaxf(hi, cs.o.x);
        cr_assert_float_eq(cs.o.x, 2.0f * cs.time01, 1e-5f);
    }
    cr_assert(lo < 0.1f && hi > 1.9f);
}

Test(camera_motion, half_turn_between_keys)
{
    struct camera_desc d = desc_basic();
    d.shutter_close = 1.0f;
    d.aperture_radius = 0.01f;
    d.num_keyframes = 3;
    d.keyframes[0] = (struct camera_keyframe){0.0f, v3(0, 0, 0), v3(0, 0, -1), v3(0, 1, 0)};
    d.keyframes[1] = (struct camera_keyframe){0.5f, v3(0, 0, 0), v3(0, 0, 1), v3(0, 1, 0)};  /* 180 about y */
    d.keyframes[2] = (struct camera_keyframe){1.0f, v3(0, 0, 0), v3(0, 0, 1), v3(0, -1, 0)}; /* 180 roll */
    struct camera c;
    camera_init(&c, &d, 16, 16);
    for (int i = 0; i <= 100; i++) {
        struct camera_pose p;
        camera_pose_at(&c, i / 100.0, &p);
        cr_assert(v3_is_finite(p.forward) && v3_is_finite(p.up) && v3_is_finite(p.right));
        cr_assert_float_eq(v3_length(p.forward), 1.0f, 1e-5f);
        cr_assert_float_eq(v3_dot(p.forward, p.up), 0.0f, 1e-5f);
        cr_assert_float_eq(v3_dot(v3_cross(p.right, p.up), v3_neg(p.forward)), 1.0f, 1e-5f);
    }
    struct camera_pose p;
    camera_pose_at(&c, 0.5, &p);
    cr_assert_float_eq(p.forward.z, 1.0f, 1e-5f);
    camera_pose_at(&c, 1.0, &p);
    cr_assert_float_eq(p.up.y, -1.0f, 1e-5f);
    all_rays_finite(&c, 0);
}

/* ---- Pixel filters (filter importance sampling) ---- */

static struct camera make_filtered(uint32_t filter, float width)
{
    struct camera_desc d;
    memset(&d, 0, sizeof d);
    d.look_at = v3(0, 0, -1);
    d.up = v3(0, 1, 0);
    d.fov_y_deg = 40.0f;
    d.filter = filter;
    d.filter_width = width;
    struct camera c;
    camera_init(&c, &d, 64, 64);
    return c;
}

static double splitmix01(uint64_t *s)
{
    uint64_t z = (*s += 0x9e3779b97f4a7c15ull);
    z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ull;
    z = (z ^ (z >> 27)) * 0x94d049bb133111ebull;
    return (double)((z ^ (z >> 31)) >> 11) * 0x1p-53;
}

/* Chi-square of N offsets in B bins over the filter's support against the filter's own
 * density (Simpson's rule per bin), bins expecting fewer than 5 samples pooled with their
 * neighbours; 1 when the statistic is below the p = 0.001 critical value
 * (Wilson-Hilferty). */
static int filter_chi2_ok(uint32_t filter, float width, double support, int bins, int n)
{
    struct camera c = make_filtered(filter, width);
    double *obs = calloc((size_t)bins, sizeof *obs), *expect = calloc((size_t)bins, sizeof *expect), total = 0.0;
    uint64_t s = 12345;
    for (int i = 0; i < n; i++) {
        float off = camera_filter_offset(&c, (float)splitmix01(&s));
        cr_assert(fabs(off) <= support * 0.5 + 1e-5, "offset %g outside the support", (double)off);
        int b = (int)floor((off + support * 0.5) / support * bins);
        obs[b < 0 ? 0 : b >= bins ? bins - 1 : b]++;
    }
    for (int b = 0; b < bins; b++) {
        double a = -support * 0.5 + support * b / bins, h = support / bins / 64.0, sum = 0.0;
        for (int k = 0; k < 64; k++) {
            double x = a + k * h;
            sum += h / 6.0 *
                   (camera_filter_eval(filter, width, x) + 4.0 * camera_filter_eval(filter, width, x + h / 2) +
                    camera_filter_eval(filter, width, x + h));
        }
        expect[b] = sum;
        total += sum;
    }
    double chi2 = 0.0, po = 0.0, pe = 0.0;
    int df = -1;
    for (int b = 0; b < bins; b++) {
        po += obs[b];
        pe += expect[b] / total * n;
        if (pe >= 5.0 || b == bins - 1) {
            chi2 += (po - pe) * (po - pe) / pe;
            df++;
            po = pe = 0.0;
        }
    }
    free(obs);
    free(expect);
    double k = 2.0 / (9.0 * df), crit = df * pow(1.0 - k + 3.09 * sqrt(k), 3.0);
    cr_log_info("chi-square %g over %d df (critical %g)", chi2, df, crit);
    cr_assert_gt(df, 10);
    return chi2 < crit;
}

Test(filter, gaussian_offsets_follow_the_filter)
{
    /* Cycles' Gaussian of width w: support 3 w, sigma w / 4. */
    cr_assert(filter_chi2_ok(FILTER_GAUSSIAN, 1.5f, 4.5, 60, 200000));
    cr_assert(filter_chi2_ok(FILTER_GAUSSIAN, 4.0f, 12.0, 60, 200000));
}

Test(filter, blackman_harris_offsets_follow_the_filter)
{
    /* Support 2 w. */
    cr_assert(filter_chi2_ok(FILTER_BLACKMAN_HARRIS, 1.5f, 3.0, 40, 200000));
    cr_assert(filter_chi2_ok(FILTER_BLACKMAN_HARRIS, 0.5f, 1.0, 40, 200000));
}

Test(filter, gaussian_moments)
{
    struct camera c = make_filtered(FILTER_GAUSSIAN, 2.0f);
    double m1 = 0.0, m2 = 0.0;
    const int n = 100000;
    for (int i = 0; i < n; i++) {
        double o = camera_filter_offset(&c, ((float)i + 0.5f) / n);
        m1 += o;
        m2 += o * o;
    }
    m1 /= n;
    m2 /= n;
    cr_assert_lt(fabs(m1), 1e-4, "mean offset %g", m1);
    cr_assert_lt(fabs(sqrt(m2) - 0.5), 0.005, "standard deviation %g, want width / 4 = 0.5", sqrt(m2));
    cr_assert_float_eq(c.filter_footprint, (float)(0.5 / sqrt(1.0 / 12.0)), 0.02f);
}

Test(filter, box_is_the_pixel_bit_for_bit)
{
    struct camera b = make_filtered(FILTER_BOX, 0.0f);
    cr_assert_eq(b.filter_footprint, 1.0f);
    for (int i = 0; i < 16; i++)
        cr_assert_eq(camera_filter_offset(&b, i / 16.0f), i / 16.0f - 0.5f);
}

/* focus_distance 0 focuses on look_at at any distance: 1e20 away (its squared length
 * overflows float) the plane in focus is 1e20 away, not the 1e-6 fallback of an invalid
 * distance; the same for a moving camera's keys. */
Test(camera, focus_on_a_far_look_at)
{
    struct camera_desc d = desc_basic();
    d.look_at = v3(0, 0, -1e20f);
    d.aperture_radius = 0.1f;
    struct camera c;
    camera_init(&c, &d, 8, 8);
    cr_expect(fabsf(c.still.focus / 1e20f - 1.0f) < 1e-6f, "focus %g", (double)c.still.focus);
    d.keyframes[0] = (struct camera_keyframe){0.0f, v3(0, 0, 0), v3(0, 0, -1e20f), v3(0, 1, 0)};
    d.keyframes[1] = (struct camera_keyframe){1.0f, v3(1, 0, 0), v3(1, 0, -1e20f), v3(0, 1, 0)};
    d.num_keyframes = 2;
    d.shutter_close = 1.0f;
    camera_init(&c, &d, 8, 8);
    struct camera_pose p;
    camera_pose_at(&c, 0.5, &p);
    cr_expect(fabsf(p.focus / 1e20f - 1.0f) < 1e-6f, "moving: focus %g", (double)p.focus);
}

/* camera_generate_shifted: a zero shift gives camera_generate's ray bit for bit (pinhole,
 * gaussian filter, thin lens, moving camera with an open shutter); a shift moves the pixel
 * jitter modulo 1 and keeps the lens sample and the time; the jitter stays in [0, 1). */
Test(camera, shifted_rays)
{
    for (int variant = 0; variant < 4; variant++) {
        struct camera_desc d = desc_basic();
        if (variant == 1) {
            d.filter = FILTER_GAUSSIAN;
            d.filter_width = 1.5f;
        }
        if (variant == 2) {
            d.aperture_radius = 0.2f;
            d.focus_distance = 3.0f;
        }
        if (variant == 3) {
            d.shutter_close = 1.0f;
            d.num_keyframes = 2;
            d.keyframes[0] = (struct camera_keyframe){0.0f, v3(0, 0, 0), v3(0, 0, -1), v3(0, 1, 0)};
            d.keyframes[1] = (struct camera_keyframe){1.0f, v3(1, 0, 0), v3(1, 0, -1), v3(0, 1, 0)};
        }
        struct camera c;
        camera_init(&c, &d, 16, 16);
        for (uint32_t i = 0; i < 64; i++) {
            struct sampler s = sampler_start_type(SAMPLER_SOBOL, 7, 0, i % 16, i / 16, i);
            struct camera_sample cs, z, sh;
            camera_generate(&c, &s, 0, i % 16, i / 16, &cs);
            camera_generate_shifted(&c, &s, 0, i % 16, i / 16, &cs, 0.0f, 0.0f, &z);
            cr_assert(same_bits(cs.o, z.o) && same_bits(cs.d, z.d) && cs.time01 == z.time01 && cs.jx == z.jx &&
                          cs.jy == z.jy, "variant %d, sample %u: zero shift differs", variant, i);
            float su = 0.75f, sv = 0.999999f;
            camera_generate_shifted(&c, &s, 0, i % 16, i / 16, &cs, su, sv, &sh);
            cr_assert(sh.jx >= 0.0f && sh.jx < 1.0f && sh.jy >= 0.0f && sh.jy < 1.0f);
            float wx = cs.jx + su >= 1.0f ? cs.jx + su - 1.0f : cs.jx + su;
            cr_assert_eq(sh.jx, wx);
            cr_assert_eq(sh.time01, cs.time01);
            /* the same lens point and time: only the film point moved */
            struct camera_sample back;
            camera_generate_shifted(&c, &s, 0, i % 16, i / 16, &sh, 0.0f, 0.0f, &back);
            cr_assert(same_bits(back.o, sh.o) && same_bits(back.d, sh.d));
            if (variant == 0)
                cr_assert(same_bits(sh.o, cs.o), "a pinhole's rays share the origin");
        }
    }
}
