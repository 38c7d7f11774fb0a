/* Ray differentials (see raydiff.h). Derivatives are of the unit direction, so reflection
 * and refraction use Igehy's formulas for normalized rays; position derivatives come from
 * the transfer to the tangent plane, and texture coordinate derivatives from a least-
 * squares solve of dP = dP/da da + dP/db db (normal equations: any triangle shape, and a
 * zero determinant gives zero derivatives, i.e. a point lookup, never NaN). */
#include "render/raydiff.h"
#include <math.h>
#include <string.h>

static float clamp_to(float x, float bound)
{
    if (!isfinite(x))
        return 0.0f;
    return x > bound ? bound : (x < -bound ? -bound : x);
}

static float clampf(float x)
{
    return clamp_to(x, RAYDIFF_MAX);
}

/* Direction derivatives (scale-free). */
static vec3 sane(vec3 v)
{
    if (!v3_is_finite(v))
        return v3(0, 0, 0);
    return v3(clampf(v.x), clampf(v.y), clampf(v.z));
}

/* Position and normal derivatives: they scale with the scene (a floor scaled by 1e10 has
 * footprints of 1e9), so only a bound far from any scene's. */
static vec3 sane_space(vec3 v)
{
    if (!v3_is_finite(v))
        return v3(0, 0, 0);
    return v3(clamp_to(v.x, RAYDIFF_MAX_SPACE), clamp_to(v.y, RAYDIFF_MAX_SPACE), clamp_to(v.z, RAYDIFF_MAX_SPACE));
}

float raydiff_spp_scale(uint32_t spp)
{
    float s = spp > 0 ? 1.0f / sqrtf((float)spp) : 1.0f;
    return s > 0.125f ? s : 0.125f;
}

float raydiff_cell_scale(uint32_t n)
{
    float s = n > 0 ? 1.0f / (float)n : 1.0f;
    return s > 0.125f ? s : 0.125f;
}

void raydiff_camera(const struct camera *cam, const struct camera_pose *pose, vec3 d, float scale,
                    struct raydiff *rd)
{
    /* Film direction D = forward + right sx + up sy has |D| = 1 / (d . forward); the thin
     * lens aims from a fixed lens point at D * focus, which gives the same derivative. */
    float kx = 2.0f * cam->aspect * cam->tan_half_fov_y / cam->width;
    float ky = -2.0f * cam->tan_half_fov_y / cam->height;
    vec3 dDx = v3_scale(pose->right, kx), dDy = v3_scale(pose->up, ky);
    float c = v3_dot(d, pose->forward) * scale;
    rd->dodx = rd->dody = v3(0, 0, 0);
    rd->cx = rd->cy = 0.0f;
    rd->dddx = sane(v3_scale(v3_sub(dDx, v3_scale(d, v3_dot(d, dDx))), c));
    rd->dddy = sane(v3_scale(v3_sub(dDy, v3_scale(d, v3_dot(d, dDy))), c));
}

void raydiff_set_center(struct raydiff *rd, float jx, float jy, uint32_t nx, uint32_t ny, float sx, float sy)
{
    rd->cx = rd->cy = 0.0f;
    if (nx == 0 || ny == 0 || !(sx > 0.0f) || !(sy > 0.0f) || !(jx >= 0.0f && jx < 1.0f) ||
        !(jy >= 0.0f && jy < 1.0f))
        return;
    float fx = (float)nx, fy = (float)ny;
    rd->cx = ((floorf(jx * fx) + 0.5f) / fx - jx) / sx;
    rd->cy = ((floorf(jy * fy) + 0.5f) / fy - jy) / sy;
}

void raydiff_transfer(const struct raydiff *rd, vec3 d, float t, vec3 n, vec3 *dpdx, vec3 *dpdy)
{
    /* n may be a triangle's raw cross product: beyond float's squared range (edges of
     * 4e9 or 1e-19) its length and its dot products would overflow or underflow. */
    float n2 = v3_dot(n, n);
    if (!(n2 >= 0x1p-126f && n2 <= 0x1.fffffep127f))
        n = v3_normalize(n);
    float dn = v3_dot(d, n), nl = v3_length(n), lim = RAYDIFF_MIN_COS * nl;
    /* Grazing: the footprint stretches without bound; cap it (the filter's anisotropy
     * clamp then bounds the lookup's cost). */
    if (fabsf(dn) < lim)
        dn = dn < 0.0f ? -lim : lim;
    if (!(fabsf(dn) > 0.0f) || !isfinite(t)) {
        *dpdx = *dpdy = v3(0, 0, 0);
        return;
    }
    vec3 vx = v3_add(rd->dodx, v3_scale(rd->dddx, t)), vy = v3_add(rd->dody, v3_scale(rd->dddy, t));
    *dpdx = sane_space(v3_sub(vx, v3_scale(d, v3_dot(vx, n) / dn)));
    *dpdy = sane_space(v3_sub(vy, v3_scale(d, v3_dot(vy, n) / dn)));
}

/* Least squares dp = a * ea + b * eb. */
static void solve2(vec3 ea, vec3 eb, vec3 dp, float *a, float *b)
{
    double a11 = v3_dot(ea, ea), a12 = v3_dot(ea, eb), a22 = v3_dot(eb, eb);
    double det = a11 * a22 - a12 * a12;
    /* Relative threshold: a sliver or zero-area parametrization has no inverse. */
    if (!(det > 1e-12 * a11 * a22) || !isfinite(det)) {
        *a = *b = 0.0f;
        return;
    }
    double r1 = v3_dot(ea, dp), r2 = v3_dot(eb, dp), inv = 1.0 / det;
    *a = clampf((float)((a22 * r1 - a12 * r2) * inv));
    *b = clampf((float)((a11 * r2 - a12 * r1) * inv));
}

void raydiff_triangle(const vec3 p[3], const float (*uv)[2], const vec3 *nrm, float b1, float b2, vec3 ng,
                      const struct raydiff *rd, vec3 d, float t, struct raydiff_hit *out)
{
    raydiff_transfer(rd, d, t, ng, &out->dpdx, &out->dpdy);
    vec3 e1 = v3_sub(p[1], p[0]), e2 = v3_sub(p[2], p[0]);
    float b1x, b2x, b1y, b2y;
    solve2(e1, e2, out->dpdx, &b1x, &b2x);
    solve2(e1, e2, out->dpdy, &b1y, &b2y);
    float b0 = 1.0f - b1 - b2;
    struct tex_coord *tc = &out->tc;
    tc->cx = rd->cx, tc->cy = rd->cy;
    out->dpdu = e1, out->dpdv = e2, out->has_dpduv = 1;
    if (uv) {
        float du1 = uv[1][0] - uv[0][0], dv1 = uv[1][1] - uv[0][1];
        float du2 = uv[2][0] - uv[0][0], dv2 = uv[2][1] - uv[0][1];
        /* dp/d(u, v) = [e1 e2] [[du1 du2] [dv1 dv2]]^-1, when the uv triangle has area. */
        float det = du1 * dv2 - du2 * dv1, scale = fmaxf(fabsf(du1 * dv2), fabsf(du2 * dv1));
        if (fabsf(det) > 1e-6f * scale && isfinite(det)) {
            out->dpdu = sane_space(v3_scale(v3_sub(v3_scale(e1, dv2), v3_scale(e2, dv1)), 1.0f / det));
            out->dpdv = sane_space(v3_scale(v3_sub(v3_scale(e2, du1), v3_scale(e1, du2)), 1.0f / det));
        } else {
            out->has_dpduv = 0;
        }
        tc->u = b0 * uv[0][0] + b1 * uv[1][0] + b2 * uv[2][0];
        tc->v = b0 * uv[0][1] + b1 * uv[1][1] + b2 * uv[2][1];
        tc->dudx = clampf(du1 * b1x + du2 * b2x);
        tc->dvdx = clampf(dv1 * b1x + dv2 * b2x);
        tc->dudy = clampf(du1 * b1y + du2 * b2y);
        tc->dvdy = clampf(dv1 * b1y + dv2 * b2y);
    } else {
        tc->u = b1, tc->v = b2;
        tc->dudx = b1x, tc->dvdx = b2x, tc->dudy = b1y, tc->dvdy = b2y;
    }
    out->n = v3_normalize(ng);
    out->dndx = out->dndy = v3(0, 0, 0);
    if (nrm) {
        vec3 N = v3_add(v3_add(v3_scale(nrm[0], b0), v3_scale(nrm[1], b1)), v3_scale(nrm[2], b2));
        float len = v3_length(N);
        if (len > 1e-6f && isfinite(len)) {
            vec3 n = v3_scale(N, 1.0f / len);
            vec3 n10 = v3_sub(nrm[1], nrm[0]), n20 = v3_sub(nrm[2], nrm[0]);
            vec3 dNx = v3_add(v3_scale(n10, b1x), v3_scale(n20, b2x));
            vec3 dNy = v3_add(v3_scale(n10, b1y), v3_scale(n20, b2y));
            out->n = n;
            out->dndx = sane_space(v3_scale(v3_sub(dNx, v3_scale(n, v3_dot(n, dNx))), 1.0f / len));
            out->dndy = sane_space(v3_scale(v3_sub(dNy, v3_scale(n, v3_dot(n, dNy))), 1.0f / len));
        }
    }
}

void raydiff_sphere_uv(vec3 center, vec3 p, float *u, float *v)
{
    vec3 q = v3_sub(p, center);
    float r = v3_length(q);
    float phi = atan2f(q.x, q.z);
    float cy = r > 0.0f ? q.y / r : 1.0f;
    cy = cy > 1.0f ? 1.0f : (cy < -1.0f ? -1.0f : cy);
    *u = 0.5f + phi * (float)(0.5 / M_PI);
    *v = 1.0f - acosf(cy) * (float)(1.0 / M_PI);
}

void raydiff_sphere(vec3 center, float radius, vec3 p, const struct raydiff *rd, vec3 d, float t,
                    struct raydiff_hit *out)
{
    vec3 q = v3_sub(p, center);
    out->n = v3_normalize(q);
    raydiff_transfer(rd, d, t, out->n, &out->dpdx, &out->dpdy);
    raydiff_sphere_uv(center, p, &out->tc.u, &out->tc.v);
    out->tc.cx = rd->cx, out->tc.cy = rd->cy;
    float rho = sqrtf(q.x * q.x + q.z * q.z);
    float sp = rho > 0.0f ? q.x / rho : 0.0f, cp = rho > 0.0f ? q.z / rho : 1.0f;
    vec3 dpdu = v3_scale(v3(q.z, 0.0f, -q.x), (float)(2.0 * M_PI));
    vec3 dpdv = v3_scale(v3(q.y * sp, -rho, q.y * cp), (float)-M_PI);
    out->dpdu = dpdu, out->dpdv = dpdv, out->has_dpduv = rho > 1e-6f * radius;
    solve2(dpdu, dpdv, out->dpdx, &out->tc.dudx, &out->tc.dvdx);
    solve2(dpdu, dpdv, out->dpdy, &out->tc.dudy, &out->tc.dvdy);
    float inv_r = radius > 0.0f ? 1.0f / radius : 0.0f;
    out->dndx = sane_space(v3_scale(out->dpdx, inv_r));
    out->dndy = sane_space(v3_scale(out->dpdy, inv_r));
}

static vec3 reflect_dd(vec3 d, vec3 dd, vec3 n, vec3 dn)
{
    float dn_ = v3_dot(d, n);
    float ddn = v3_dot(dd, n) + v3_dot(d, dn);
    return sane(v3_sub(dd, v3_scale(v3_add(v3_scale(dn, dn_), v3_scale(n, ddn)), 2.0f)));
}

void raydiff_reflect(struct raydiff *rd, vec3 d_in, vec3 d_out, vec3 n, vec3 dndx, vec3 dndy, vec3 dpdx,
                     vec3 dpdy)
{
    (void)d_out;
    rd->dodx = dpdx;
    rd->dody = dpdy;
    rd->dddx = reflect_dd(d_in, rd->dddx, n, dndx);
    rd->dddy = reflect_dd(d_in, rd->dddy, n, dndy);
}

static vec3 refract_dd(vec3 d, vec3 dd, vec3 n, vec3 dn, float eta, float cos_i, float cos_t)
{
    float mu = eta * cos_i - cos_t;
    float dcos_i = -(v3_dot(dd, n) + v3_dot(d, dn));
    float dcos_t = eta * eta * cos_i * dcos_i / cos_t;
    float dmu = eta * dcos_i - dcos_t;
    return sane(v3_add(v3_add(v3_scale(dd, eta), v3_scale(dn, mu)), v3_scale(n, dmu)));
}

void raydiff_refract(struct raydiff *rd, vec3 d_in, vec3 d_out, vec3 n, vec3 dndx, vec3 dndy, vec3 dpdx,
                     vec3 dpdy, float eta_i_over_t)
{
    float cos_i = -v3_dot(d_in, n), cos_t = -v3_dot(d_out, n);
    /* Near the critical angle dcos_t / dcos_i grows without bound: cap it. */
    cos_t = cos_t > RAYDIFF_MIN_COS ? cos_t : RAYDIFF_MIN_COS;
    rd->dodx = dpdx;
    rd->dody = dpdy;
    rd->dddx = refract_dd(d_in, rd->dddx, n, dndx, eta_i_over_t, cos_i, cos_t);
    rd->dddy = refract_dd(d_in, rd->dddy, n, dndy, eta_i_over_t, cos_i, cos_t);
}

void raydiff_diffuse(struct raydiff *rd, vec3 d_out, vec3 dpdx, vec3 dpdy)
{
    float spread = fmaxf(fmaxf(v3_length(rd->dddx), v3_length(rd->dddy)), RAYDIFF_DIFFUSE_SPREAD);
    vec3 t, b;
    v3_basis(d_out, &t, &b);
    rd->dodx = dpdx;
    rd->dody = dpdy;
    rd->dddx = sane(v3_scale(t, spread));
    rd->dddy = sane(v3_scale(b, spread));
    rd->cx = rd->cy = 0.0f; /* the cone no longer maps film offsets */
}
