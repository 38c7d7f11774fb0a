/* Pinhole camera rays: centre ray along the view direction, corners at the field of view,
 * handedness (image right = camera right), unit directions. */
#include <criterion/criterion.h>
#include <math.h>
#include "camera.h"

static struct camera make(float fov, uint32_t w, uint32_t h)
{
    struct camera_desc d = {v3(0, 0, 0), v3(0, 0, -1), v3(0, 1, 0), fov, 0, 0};
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
