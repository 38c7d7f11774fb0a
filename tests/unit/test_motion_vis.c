/* Analytic motion blur (motion_vis.c): coverage intervals of moving triangles and spheres
 * against closed forms (a square crossing the ray, two squares at different depths, depth
 * curves that cross), the hard cases (double roots, degenerate and flipping triangles,
 * motion parallel to an edge, zero motion, 1e6 displacement, 1e-7 triangles, coincident
 * surfaces, a zero-length shutter), the stable quadratic against the naive one, strata
 * weights under the trapezoid shutter, and renders: a moving edge's ramp without time
 * noise, and the still image when nothing moves in the shutter. */
#include <criterion/criterion.h>
#include <math.h>
#include <string.h>
#include "render/motion_vis.h"
#include "base/log.h"
#include "scene/motion.h"
#include "helpers.h"

static const double DZ[3] = {0, 0, 1}; /* the ray: from the origin along +z */

/* Triangle (x, y) vertices at z, moved by (dx, dy) over the segment [0, 1]. */
static struct mv_cand tri(const double xy[3][2], double z, double dx, double dy, uint32_t obj, uint32_t prim)
{
    struct mv_cand c;
    memset(&c, 0, sizeof c);
    c.obj = obj, c.prim = prim, c.ta = 0.0, c.tb = 1.0;
    for (int i = 0; i < 3; i++) {
        c.p0[i][0] = xy[i][0], c.p0[i][1] = xy[i][1], c.p0[i][2] = z;
        c.p1[i][0] = xy[i][0] + dx, c.p1[i][1] = xy[i][1] + dy, c.p1[i][2] = z;
    }
    mv_cand_coverage(&c, DZ);
    return c;
}

/* Axis-aligned square [x0, x0 + s] x [y0, y0 + s] at z as two triangles (2 candidates). */
static void square(struct mv_cand *c, double x0, double y0, double s, double z, double dx, uint32_t obj)
{
    const double a[3][2] = {{x0, y0}, {x0 + s, y0}, {x0 + s, y0 + s}};
    const double b[3][2] = {{x0, y0}, {x0 + s, y0 + s}, {x0, y0 + s}};
    c[0] = tri(a, z, dx, 0, obj, 0);
    c[1] = tri(b, z, dx, 0, obj, 1);
}

static double covered(const struct mv_cand *c, uint32_t n)
{
    struct mv_piece p[64];
    uint32_t np = mv_resolve(c, n, DZ, INFINITY, p, 64);
    cr_assert(np > 0);
    double f = 0.0;
    for (uint32_t i = 0; i < np; i++) {
        cr_assert(isfinite(p[i].t0) && isfinite(p[i].t1) && p[i].t1 >= p[i].t0);
        if (p[i].cand != MV_STILL)
            f += p[i].t1 - p[i].t0;
    }
    return f;
}

Test(motion_vis, stable_quadratic_beats_the_naive_formula)
{
    /* Nearly linear: a = 1e-13, root at 0.5 + 2.5e-14 (series: c / -b (1 + ac / b^2)),
     * the other near 1e13. */
    double a = 1e-13, b = -1.0, c = 0.5, r[2], want = 0.5 * (1.0 + 0.5e-13);
    cr_assert_eq(mv_quadratic_roots(a, b, c, r), 2);
    cr_assert(fabs(r[0] - want) < 1e-15, "stable root %.17g", r[0]);
    double naive = (-b - sqrt(b * b - 4 * a * c)) / (2 * a);
    cr_assert(fabs(naive - want) > 1e-5, "the naive formula cancels (%.17g): the test shows nothing", naive);
    /* Double root, linear, no root, zero polynomial. */
    cr_assert_eq(mv_quadratic_roots(1, -1, 0.25, r), 1);
    cr_assert_float_eq(r[0], 0.5, 1e-15);
    cr_assert_eq(mv_quadratic_roots(0, 2, -1, r), 1);
    cr_assert_float_eq(r[0], 0.5, 1e-15);
    cr_assert_eq(mv_quadratic_roots(1, 0, 1, r), 0);
    cr_assert_eq(mv_quadratic_roots(0, 0, 0, r), 0);
    /* Huge and tiny coefficients: scaled, no overflow or underflow. */
    cr_assert_eq(mv_quadratic_roots(1e200, -1e200, 0.25e200, r), 1);
    cr_assert_eq(mv_quadratic_roots(1e-200, -3e-200, 2e-200, r), 2);
    cr_assert_float_eq(r[0], 1.0, 1e-12);
    cr_assert_float_eq(r[1], 2.0, 1e-12);
}

Test(motion_vis, square_crossing_the_ray_covers_a_known_fraction)
{
    /* Unit square from x in [-1.5, -0.5] moving +3: covers x = 0 for t in [1/6, 1/2]. */
    struct mv_cand c[2];
    square(c, -1.5, -0.3, 1.0, 5.0, 3.0, 7);
    cr_assert(fabs(covered(c, 2) - 1.0 / 3.0) < 1e-6, "fraction %.9f", covered(c, 2));
    struct mv_piece p[8];
    uint32_t np = mv_resolve(c, 2, DZ, INFINITY, p, 8);
    /* Still, square (its two triangles, one after the other), still. */
    cr_assert(np >= 3 && np <= 4);
    cr_assert_eq(p[0].cand, MV_STILL);
    cr_assert(fabs(p[0].t1 - 1.0 / 6.0) < 1e-9);
    cr_assert_eq(p[np - 1].cand, MV_STILL);
    cr_assert(fabs(p[np - 1].t0 - 0.5) < 1e-9);
    /* Strata: the square and the rest, each once, weights as the box shutter's lengths. */
    struct camera cam;
    memset(&cam, 0, sizeof cam);
    struct mv_strata st;
    mv_strata_from_pieces(&cam, p, np, c, 0.5f, &st);
    cr_assert_eq(st.n, 2);
    double ws = 0;
    for (uint32_t k = 0; k < st.n; k++) {
        ws += st.weight[k];
        cr_assert(fabs(st.weight[k] - 1.0 / 3.0) < 1e-6 || fabs(st.weight[k] - 2.0 / 3.0) < 1e-6);
        int in_square = st.time01[k] >= 1.0 / 6.0 && st.time01[k] <= 0.5;
        cr_assert_eq(in_square, fabs(st.weight[k] - 1.0 / 3.0) < 1e-6, "stratum %u's time %g", k, st.time01[k]);
    }
    cr_assert_float_eq(ws, 1.0, 1e-12);
    /* A still surface in front hides it: one still piece. */
    cr_assert_eq(mv_resolve(c, 2, DZ, 4.0, p, 8), 1);
    cr_assert_eq(p[0].cand, MV_STILL);
}

Test(motion_vis, two_squares_at_different_depths_split_the_time)
{
    /* Far square (z 5) covers t in [1/6, 1/2]; near square (z 3) moving -3 from x in
     * [1, 2] covers t in [1/3, 2/3]; near wins where both do. */
    struct mv_cand c[4];
    square(c, -1.5, -0.3, 1.0, 5.0, 3.0, 1);
    square(c + 2, 1.0, -0.4, 1.0, 3.0, -3.0, 2);
    struct mv_piece p[16];
    uint32_t np = mv_resolve(c, 4, DZ, INFINITY, p, 16);
    double far = 0, near = 0, still = 0, near_start = 2, near_end = -1;
    for (uint32_t i = 0; i < np; i++) {
        double len = p[i].t1 - p[i].t0;
        if (p[i].cand == MV_STILL)
            still += len;
        else if (c[p[i].cand].obj == 1)
            far += len;
        else {
            near += len;
            near_start = fmin(near_start, p[i].t0);
            near_end = fmax(near_end, p[i].t1);
        }
    }
    cr_assert(fabs(far - 1.0 / 6.0) < 1e-6, "far %.9f", far);
    cr_assert(fabs(near - 1.0 / 3.0) < 1e-6, "near %.9f", near);
    cr_assert(fabs(still - 0.5) < 1e-6, "still %.9f", still);
    cr_assert(fabs(near_start - 1.0 / 3.0) < 1e-9 && fabs(near_end - 2.0 / 3.0) < 1e-9);
}

Test(motion_vis, crossing_depth_curves_split_where_they_cross)
{
    /* Two large triangles over the ray, one receding (z 4 -> 6), one approaching (5 -> 3):
     * depths cross at t = 1/4. */
    const double big[3][2] = {{-10, -10}, {10, -10}, {0, 10}};
    struct mv_cand c[2];
    c[0] = tri(big, 4.0, 0, 0, 1, 0);
    c[1] = tri(big, 5.0, 0, 0, 2, 0);
    for (int i = 0; i < 3; i++)
        c[0].p1[i][2] = 6.0, c[1].p1[i][2] = 3.0;
    mv_cand_coverage(&c[0], DZ);
    mv_cand_coverage(&c[1], DZ);
    struct mv_piece p[8];
    uint32_t np = mv_resolve(c, 2, DZ, INFINITY, p, 8);
    cr_assert_eq(np, 2);
    cr_assert_eq(p[0].cand, 0);
    cr_assert_eq(p[1].cand, 1);
    cr_assert(fabs(p[0].t1 - 0.25) < 1e-9, "crossing at %.12f", p[0].t1);
    cr_assert_float_eq(mv_cand_depth(&c[0], DZ, 0.5), 5.0, 1e-12);
}

Test(motion_vis, double_root_grazing_sphere_is_finite)
{
    /* A sphere of radius 0.5 whose centre passes at exactly 0.5 from the ray: the coverage
     * quadratic touches zero at t = 1/2 and turns back. Then one a hair closer. */
    for (int k = 0; k < 2; k++) {
        struct mv_cand c;
        memset(&c, 0, sizeof c);
        c.sphere = 1, c.ta = 0, c.tb = 1;
        double y = k == 0 ? 0.5 : 0.5 - 1e-9;
        c.p0[0][0] = -1, c.p0[0][1] = y, c.p0[0][2] = 5, c.p0[1][0] = 0.5;
        c.p1[0][0] = 1, c.p1[0][1] = y, c.p1[0][2] = 5, c.p1[1][0] = 0.5;
        mv_cand_coverage(&c, DZ);
        double f = covered(&c, 1);
        /* Half-chord sqrt(0.5^2 - y^2) over the speed 2, both sides. */
        double want = k == 0 ? 0.0 : sqrt(0.25 - y * y);
        cr_assert(fabs(f - want) < 1e-6, "grazing %d: coverage %.3g, want %.3g", k, f, want);
    }
    /* And a sphere crossing squarely: |x| <= 0.5 for t in [3/8, 5/8]. */
    struct mv_cand c;
    memset(&c, 0, sizeof c);
    c.sphere = 1, c.ta = 0, c.tb = 1;
    c.p0[0][0] = -2, c.p0[0][2] = 5, c.p0[1][0] = 0.5;
    c.p1[0][0] = 2, c.p1[0][2] = 5, c.p1[1][0] = 0.5;
    mv_cand_coverage(&c, DZ);
    cr_assert_eq(c.niv, 1);
    cr_assert(fabs(c.iv[0][0] - 0.375) < 1e-12 && fabs(c.iv[0][1] - 0.625) < 1e-12);
    cr_assert_float_eq(mv_cand_depth(&c, DZ, 0.5), 4.5, 1e-12);
}

Test(motion_vis, degenerate_and_flipping_triangles)
{
    /* Apex moving from (0, -4) to (0, 2) over a base at y = -1: a line at t = 1/2, then
     * flipped; it covers the origin only after the flip, for t > 2/3. */
    const double flip[3][2] = {{-1, -1}, {1, -1}, {0, -4}};
    struct mv_cand c = tri(flip, 5.0, 0, 0, 1, 0);
    c.p1[2][1] = 2.0;
    mv_cand_coverage(&c, DZ);
    cr_assert_eq(c.niv, 1);
    cr_assert(fabs(c.iv[0][0] - 2.0 / 3.0) < 1e-12 && c.iv[0][1] == 1.0, "[%g, %g]", c.iv[0][0], c.iv[0][1]);
    /* The reverse: it covers until the apex passes y = 0 (t = 1/3), before collapsing. */
    const double flip2[3][2] = {{-1, -1}, {1, -1}, {0, 2}};
    c = tri(flip2, 5.0, 0, 0, 1, 0);
    c.p1[2][1] = -4.0;
    mv_cand_coverage(&c, DZ);
    cr_assert_eq(c.niv, 1);
    cr_assert(c.iv[0][0] == 0.0 && fabs(c.iv[0][1] - 1.0 / 3.0) < 1e-12);
    /* A triangle that is a line all the time (seen edge-on) covers nothing. */
    const double line[3][2] = {{-1, 0}, {1, 0}, {0, 0}};
    c = tri(line, 5.0, 0.1, 0, 1, 0);
    cr_assert_eq(c.niv, 0);
    /* Seen edge-on in 3D: the ray lies in its plane; depth is infinite, no coverage. */
    memset(&c, 0, sizeof c);
    c.ta = 0, c.tb = 1;
    double v[3][3] = {{0, 0, 1}, {0, 1, 3}, {0, -1, 3}};
    memcpy(c.p0, v, sizeof v);
    memcpy(c.p1, v, sizeof v);
    mv_cand_coverage(&c, DZ);
    cr_assert_eq(c.niv, 0);
}

Test(motion_vis, motion_parallel_to_an_edge)
{
    /* Triangle (-1,-1) (1,-1) (0,1) sliding along its base by 4 from x offset -2: at
     * offset o it covers the origin when -o in [-0.5, 0.5], so t in [3/8, 5/8]. */
    const double t3[3][2] = {{-3, -1}, {-1, -1}, {-2, 1}};
    struct mv_cand c = tri(t3, 5.0, 4.0, 0, 1, 0);
    cr_assert_eq(c.niv, 1);
    cr_assert(fabs(c.iv[0][0] - 0.375) < 1e-12 && fabs(c.iv[0][1] - 0.625) < 1e-12, "[%.15g, %.15g]", c.iv[0][0],
              c.iv[0][1]);
    /* Sliding along the base line through the origin's height: the base edge's function is
     * zero throughout (a = b = c = 0); finite, and covered where the interior passes. */
    const double on[3][2] = {{-3, 0}, {-1, 0}, {-2, 1}};
    c = tri(on, 5.0, 4.0, 0, 1, 0);
    cr_assert(c.niv <= 1);
    if (c.niv == 1)
        cr_assert(isfinite(c.iv[0][0]) && isfinite(c.iv[0][1]));
}

Test(motion_vis, zero_motion_is_exactly_still)
{
    const double t3[3][2] = {{-1, -1}, {1, -1}, {0, 1}};
    struct mv_cand c = tri(t3, 5.0, 0, 0, 1, 0);
    cr_assert_eq(c.niv, 1);
    cr_assert(c.iv[0][0] == 0.0 && c.iv[0][1] == 1.0);
    struct mv_piece p[4];
    cr_assert_eq(mv_resolve(&c, 1, DZ, INFINITY, p, 4), 1);
    cr_assert(p[0].cand == 0 && p[0].t0 == 0.0 && p[0].t1 == 1.0);
    cr_assert_eq(mv_cand_depth(&c, DZ, 0.3), 5.0);
    const double away[3][2] = {{2, 2}, {3, 2}, {2, 3}};
    c = tri(away, 5.0, 0, 0, 1, 0);
    cr_assert_eq(c.niv, 0);
}

Test(motion_vis, huge_displacement_and_tiny_triangles)
{
    /* A unit square moving 2e6 across the ray: covered for 1 / 2e6 of the shutter. */
    struct mv_cand c[2];
    square(c, -1e6 - 0.5, -0.5, 1.0, 5.0, 2e6, 1);
    double f = covered(c, 2);
    cr_assert(fabs(f - 5e-7) < 5e-7 * 1e-6, "huge: %.12g", f);
    /* A 1e-7 square moving 4e-7 across: covered a quarter of the time. */
    square(c, -1.5e-7, -0.5e-7, 1e-7, 5.0, 4e-7, 1);
    f = covered(c, 2);
    cr_assert(fabs(f - 0.25) < 0.25 * 1e-6, "tiny: %.12g", f);
    /* Both far from the origin of the render frame (1e6 along the ray). */
    square(c, -1.5, -0.5, 1.0, 1e6, 3.0, 1);
    f = covered(c, 2);
    cr_assert(fabs(f - 1.0 / 3.0) < 1e-6, "far: %.12g", f);
}

Test(motion_vis, coincident_surfaces_moving_together)
{
    struct mv_cand c[4];
    square(c, -1.5, -0.3, 1.0, 5.0, 3.0, 1);
    square(c + 2, -1.5, -0.3, 1.0, 5.0, 3.0, 2);
    struct mv_piece p[16];
    uint32_t np = mv_resolve(c, 4, DZ, INFINITY, p, 16);
    double f = 0;
    for (uint32_t i = 0; i < np; i++)
        if (p[i].cand != MV_STILL) {
            cr_assert_eq(c[p[i].cand].obj, 1, "ties go to the first candidate");
            f += p[i].t1 - p[i].t0;
        }
    cr_assert(fabs(f - 1.0 / 3.0) < 1e-6);
}

Test(motion_vis, zero_length_shutter_segment)
{
    /* A segment of no length: coverage is a point or nothing, and the pieces are still. */
    const double t3[3][2] = {{-1, -1}, {1, -1}, {0, 1}};
    struct mv_cand c = tri(t3, 5.0, 3.0, 0, 1, 0);
    c.ta = c.tb = 0.5;
    mv_cand_coverage(&c, DZ);
    cr_assert(c.niv <= 1);
    for (uint32_t k = 0; k < c.niv; k++)
        cr_assert(c.iv[k][0] == 0.5 && c.iv[k][1] == 0.5);
    cr_assert(isfinite(mv_cand_depth(&c, DZ, 0.5)));
    struct mv_piece p[4];
    cr_assert_eq(mv_resolve(&c, 1, DZ, INFINITY, p, 4), 1);
    cr_assert(p[0].cand == MV_STILL && p[0].t0 == 0.0 && p[0].t1 == 1.0);
}

Test(motion_vis, trapezoid_weights_are_the_curve_integral)
{
    struct camera cam;
    memset(&cam, 0, sizeof cam);
    cam.shutter_ramp = 0.2f;
    struct mv_cand c[2];
    square(c, -1.5, -0.3, 1.0, 5.0, 3.0, 1); /* covers [1/6, 1/2] */
    struct mv_piece p[8];
    uint32_t np = mv_resolve(c, 2, DZ, INFINITY, p, 8);
    /* The curve's integral over [1/6, 1/2] by the midpoint rule. */
    double r = 0.2, h = 1.0 / (1.0 - r), want = 0;
    enum { N = 200000 };
    for (int i = 0; i < N; i++) {
        double t = 1.0 / 6.0 + (0.5 - 1.0 / 6.0) * (i + 0.5) / N;
        want += (t < r ? h * t / r : t > 1 - r ? h * (1 - t) / r : h) * (0.5 - 1.0 / 6.0) / N;
    }
    for (float u = 0.0f; u < 1.0f; u += 0.125f) {
        struct mv_strata st;
        mv_strata_from_pieces(&cam, p, np, c, u, &st);
        cr_assert_eq(st.n, 2);
        double wsq = -1;
        for (uint32_t k = 0; k < 2; k++)
            if (st.time01[k] > 1.0 / 6.0 - 1e-6 && st.time01[k] < 0.5 + 1e-6)
                wsq = st.weight[k];
        cr_assert(fabs(wsq - want) < 1e-6, "u %g: weight %.9f want %.9f", u, wsq, want);
        cr_assert_float_eq(st.weight[0] + st.weight[1], 1.0, 1e-12);
    }
    cr_assert_float_eq(mv_shutter_cdf(0.2, 1.0), 1.0, 1e-15);
    cr_assert_float_eq(mv_shutter_cdf(0.2, 0.5), 0.5, 1e-15);
}

/* Camera at z = 10 looking down -z over x in [-2, 2] (W x 4 pixels); an emitting half
 * plane whose right edge sweeps x = -1 -> 1 over the shutter. */
static void edge_scene(struct scene *s, uint32_t w, uint32_t spp, int analytic, float close)
{
    memset(s, 0, sizeof *s);
    struct material m;
    memset(&m, 0, sizeof m);
    m.type = MATERIAL_DIFFUSE;
    m.emission = v3(2, 2, 2);
    uint32_t lamp = scene_add_material(s, &m);
    struct mesh q = test_quad(v3(-10, -10, 0), v3(0, -10, 0), v3(0, 10, 0), v3(-10, 10, 0), lamp, 0);
    q.keys = mem_alloc(2 * sizeof *q.keys);
    for (int k = 0; k < 2; k++) {
        memset(&q.keys[k], 0, sizeof q.keys[k]);
        q.keys[k].time = (float)k;
        q.keys[k].scale = v3(1, 1, 1);
        q.keys[k].quat[0] = 1.0f;
        q.keys[k].translate = v3(k ? 1.0f : -1.0f, 0, 0);
    }
    q.num_keys = 2;
    scene_add_mesh(s, &q);
    test_ramp_camera(s, w, spp);
    s->camera.shutter_close = close;
    s->camera.motion_blur = analytic ? MOTION_BLUR_ANALYTIC : MOTION_BLUR_SAMPLED;
}

Test(motion_vis, analytic_moving_edge_has_no_time_noise)
{
    /* Each sample sees the exact share of the shutter at its film point: at 4 spp the
     * column means follow the ramp (1 - x) / 2 to the pixel jitter's spread only, where
     * sampled time at 4 spp is off by about 0.1. */
    enum { W = 32 };
    struct scene s;
    edge_scene(&s, W, 4, 1, 1.0f);
    struct tile_stats st;
    float *px = test_render(&s, 2, &st);
    cr_assert_eq(st.nan_samples, 0);
    double worst = 0, worst_alpha = 0;
    for (int x = 0; x < W; x++) {
        double xc = -2.0 + 4.0 * (x + 0.5) / W, half_px = 2.0 / W;
        if (fabs(xc) > 1.0 - half_px)
            continue;
        double red = 0, alpha = 0;
        for (int y = 0; y < 4; y++) {
            red += px[(y * W + x) * TILE_NUM_CHANNELS + CH_R] / 4.0;
            alpha += px[(y * W + x) * TILE_NUM_CHANNELS + CH_A] / 4.0;
        }
        worst = fmax(worst, fabs(red / 2.0 - (1.0 - xc) / 2.0));
        /* Coverage is the covered share of the shutter too (over the empty background),
         * not the hit of one stratum. */
        worst_alpha = fmax(worst_alpha, fabs(alpha - (1.0 - xc) / 2.0));
    }
    cr_assert(worst < 0.01, "worst column error %.4f", worst);
    cr_assert(worst_alpha < 0.01, "worst column alpha error %.4f", worst_alpha);
    free(px);
    scene_fini(&s);
}

Test(motion_vis, closed_shutter_gives_the_still_image)
{
    /* Shutter of zero length: nothing uses time, analytic and sampled are the same bits. */
    struct scene a, b;
    edge_scene(&a, 16, 4, 1, 0.0f);
    edge_scene(&b, 16, 4, 0, 0.0f);
    struct tile_stats st;
    float *pa = test_render(&a, 1, &st), *pb = test_render(&b, 2, &st);
    cr_assert_eq(memcmp(pa, pb, sizeof(float) * 16 * 4 * TILE_NUM_CHANNELS), 0);
    free(pa);
    free(pb);
    scene_fini(&a);
    scene_fini(&b);
}

Test(motion_vis, scene_key_motion_blur)
{
    const char *ok = "{\"version\": 1, \"camera\": {\"position\": [0, 0, -5], \"look_at\": [0, 0, 0], \"fov_y\": 40,"
                     " \"motion_blur\": \"analytic\"}, \"render\": {\"width\": 8, \"height\": 8},"
                     " \"materials\": {\"m\": {\"type\": \"diffuse\"}},"
                     " \"objects\": [{\"type\": \"sphere\", \"center\": [0, 0, 0], \"radius\": 1, \"material\": \"m\"}]}";
    struct scene s;
    char err[512];
    cr_assert_eq(test_scene_load(ok, NULL, &s, err), 0, "%s", err);
    cr_assert_eq(s.camera.motion_blur, MOTION_BLUR_ANALYTIC);
    scene_fini(&s);
    const char *bad = "{\"version\": 1, \"camera\": {\"position\": [0, 0, -5], \"look_at\": [0, 0, 0], \"fov_y\": 40,"
                      " \"motion_blur\": \"fast\"}, \"render\": {\"width\": 8, \"height\": 8},"
                      " \"materials\": {\"m\": {\"type\": \"diffuse\"}},"
                      " \"objects\": [{\"type\": \"sphere\", \"center\": [0, 0, 0], \"radius\": 1, \"material\": \"m\"}]}";
    test_scene_expect_error(bad, NULL, "motion_blur must be \"analytic\" or \"sampled\"");
}
