/* The environment light's map and its sampling distribution (see envmap.h). */
#include "scene/envmap.h"
#include "base/cdf.h"
#include "base/log.h"
#include <float.h>
#include <math.h>
#include <stdlib.h>

static float lum(const float *c)
{
    return 0.2126f * c[0] + 0.7152f * c[1] + 0.0722f * c[2];
}

struct environment *envmap_new(float *rgb, uint32_t width, uint32_t height, float strength, float rotation)
{
    struct environment *e = mem_calloc(1, sizeof *e);
    e->rgb = rgb;
    e->width = width;
    e->height = height;
    e->strength = strength;
    e->rotation = rotation;
    e->cond_cdf = mem_alloc(sizeof(float) * (size_t)height * (width + 1));
    e->marg_cdf = mem_alloc(sizeof(float) * (height + 1));
    double mean[3] = {0, 0, 0}, marg = 0.0;
    double *row_int = mem_alloc(sizeof(double) * height);
    for (uint32_t y = 0; y < height; y++) {
        double st = sin(M_PI * (y + 0.5) / height), acc = 0.0;
        float *cdf = &e->cond_cdf[(size_t)y * (width + 1)];
        cdf[0] = 0.0f;
        for (uint32_t x = 0; x < width; x++) {
            const float *c = &rgb[3 * ((size_t)y * width + x)];
            acc += (double)fmaxf(0.0f, lum(c)) * st / width;
            for (int k = 0; k < 3; k++)
                mean[k] += (double)c[k] * st;
            cdf[x + 1] = (float)acc;
        }
        for (uint32_t x = 1; x <= width; x++)
            cdf[x] = acc > 0.0 ? (float)(cdf[x] / acc) : (float)x / width;
        cdf[width] = 1.0f;
        row_int[y] = acc;
        marg += acc / height;
    }
    double acc = 0.0;
    e->marg_cdf[0] = 0.0f;
    for (uint32_t y = 0; y < height; y++) {
        acc += row_int[y] / height;
        e->marg_cdf[y + 1] = marg > 0.0 ? (float)(acc / marg) : (float)(y + 1) / height;
    }
    e->marg_cdf[height] = 1.0f;
    e->marg_int = (float)marg;
    free(row_int);
    e->cell_pdf = mem_alloc(sizeof(float) * (size_t)width * height);
    for (uint32_t y = 0; y < height; y++) {
        float st = sinf((float)M_PI * (y + 0.5f) / e->height);
        for (uint32_t x = 0; x < width; x++)
            e->cell_pdf[(size_t)y * width + x] =
                e->marg_int > 0.0f ? fmaxf(0.0f, lum(&rgb[3 * ((size_t)y * width + x)])) * st / e->marg_int : 0.0f;
    }
    /* Solid-angle mean: sum of L sin(theta) dtheta dphi / 4 pi, with sum of sin over rows ~ 2 h / pi. */
    double wsum = 0.0;
    for (uint32_t y = 0; y < height; y++)
        wsum += sin(M_PI * (y + 0.5) / height) * width;
    e->mean = v3((float)(mean[0] / wsum * strength), (float)(mean[1] / wsum * strength), (float)(mean[2] / wsum * strength));
    return e;
}

void envmap_free(struct environment **pe)
{
    struct environment *e = *pe;
    if (!e)
        return;
    free(e->rgb);
    free(e->cond_cdf);
    free(e->marg_cdf);
    free(e->cell_pdf);
    free(e);
    *pe = NULL;
}

static void dir_to_uv(const struct environment *e, vec3 d, float *u, float *v)
{
    float phi = atan2f(d.z, d.x) - e->rotation * (float)(M_PI / 180.0);
    float uu = phi * (float)(0.5 * M_1_PI);
    uu -= floorf(uu);
    *u = uu < 1.0f ? uu : 0.0f;
    float vv = acosf(fminf(1.0f, fmaxf(-1.0f, d.y))) * (float)M_1_PI;
    *v = fminf(vv, 0x1.fffffep-1f);
}

static vec3 uv_to_dir(const struct environment *e, float u, float v, float *sin_t)
{
    float theta = v * (float)M_PI, phi = u * 2.0f * (float)M_PI + e->rotation * (float)(M_PI / 180.0);
    float st = sinf(theta);
    *sin_t = st;
    return v3(st * cosf(phi), cosf(theta), st * sinf(phi));
}

vec3 envmap_eval(const struct environment *e, vec3 d)
{
    float u, v;
    dir_to_uv(e, d, &u, &v);
    uint32_t x = (uint32_t)(u * e->width), y = (uint32_t)(v * e->height);
    x = x < e->width ? x : e->width - 1;
    y = y < e->height ? y : e->height - 1;
    const float *c = &e->rgb[3 * ((size_t)y * e->width + x)];
    return v3(c[0] * e->strength, c[1] * e->strength, c[2] * e->strength);
}

float envmap_pdf_uv(const struct environment *e, float u, float v)
{
    if (!(e->marg_int > 0.0f))
        return 0.0f;
    uint32_t x = (uint32_t)(u * e->width), y = (uint32_t)(v * e->height);
    x = x < e->width ? x : e->width - 1;
    y = y < e->height ? y : e->height - 1;
    return e->cell_pdf[(size_t)y * e->width + x];
}

void envmap_sample_uv(const struct environment *e, float u1, float u2, float *u, float *v, float *pdf)
{
    uint32_t y = cdf_cell(e->marg_cdf, e->height, u1);
    float dy = e->marg_cdf[y + 1] - e->marg_cdf[y];
    float fy = dy > 0.0f ? (u1 - e->marg_cdf[y]) / dy : 0.5f;
    const float *cdf = &e->cond_cdf[(size_t)y * (e->width + 1)];
    uint32_t x = cdf_cell(cdf, e->width, u2);
    float dx = cdf[x + 1] - cdf[x];
    float fx = dx > 0.0f ? (u2 - cdf[x]) / dx : 0.5f;
    *v = fminf((y + fminf(fmaxf(fy, 0.0f), 1.0f)) / e->height, 0x1.fffffep-1f);
    *u = fminf((x + fminf(fmaxf(fx, 0.0f), 1.0f)) / e->width, 0x1.fffffep-1f);
    /* The cell's density, from the cell indices (not the rounded point). */
    *pdf = e->cell_pdf[(size_t)y * e->width + x];
}

vec3 envmap_sample(const struct environment *e, float u1, float u2, float *pdf)
{
    if (e->uniform) {
        float z = 1.0f - 2.0f * u1, r = sqrtf(fmaxf(0.0f, 1.0f - z * z)), sp, cp;
        sincos_2pi(u2, &sp, &cp);
        *pdf = (float)(0.25 * M_1_PI);
        return v3(r * cp, z, r * sp);
    }
    float u, v, p2, st;
    envmap_sample_uv(e, u1, u2, &u, &v, &p2);
    vec3 d = uv_to_dir(e, u, v, &st);
    *pdf = st > 0.0f && p2 > 0.0f ? p2 / (2.0f * (float)(M_PI * M_PI) * st) : 0.0f;
    return d;
}

float envmap_pdf(const struct environment *e, vec3 d)
{
    if (e->uniform)
        return (float)(0.25 * M_1_PI);
    float u, v;
    dir_to_uv(e, d, &u, &v);
    float st = sinf(v * (float)M_PI);
    return st > 0.0f ? envmap_pdf_uv(e, u, v) / (2.0f * (float)(M_PI * M_PI) * st) : 0.0f;
}

vec3 envmap_emit(const struct environment *e, vec3 center, float radius, vec3 aim_center, float aim_radius,
                 float aim_share, const float u[5], vec3 *o, vec3 *d)
{
    float pdf;
    vec3 w = envmap_sample(e, u[0], u[1], &pdf);
    if (!(pdf > 0.0f) || !(radius > 0.0f))
        return v3(0, 0, 0);
    int can_aim = aim_share > 0.0f && aim_radius > 0.0f;
    int aimed = can_aim && u[4] < aim_share;
    vec3 t, b;
    v3_basis(w, &t, &b);
    /* Plane coordinates (along t, b) relative to center; the aimed disc's centre. */
    vec3 rel = v3_sub(aim_center, center);
    float ax = can_aim ? v3_dot(rel, t) : 0.0f, ay = can_aim ? v3_dot(rel, b) : 0.0f;
    float r = (aimed ? aim_radius : radius) * sqrtf(u[2]), sp, cp;
    sincos_2pi(u[3], &sp, &cp);
    float x = r * cp + (aimed ? ax : 0.0f), y = r * sp + (aimed ? ay : 0.0f);
    /* The mixture's density at x; the bounds are widened by a few ulps so that a point drawn
     * on a disc's rim always counts as inside it. */
    const float grow = 1.0f + 4.0f * FLT_EPSILON;
    double dens = 0.0;
    if (!can_aim || aim_share < 1.0f)
        if (x * x + y * y <= radius * radius * grow)
            dens += (1.0 - (can_aim ? aim_share : 0.0f)) / (M_PI * (double)radius * radius);
    if (can_aim && (x - ax) * (x - ax) + (y - ay) * (y - ay) <= aim_radius * aim_radius * grow)
        dens += aim_share / (M_PI * (double)aim_radius * aim_radius);
    if (!(dens > 0.0))
        return v3(0, 0, 0);
    /* Start beyond both spheres, so the photon crosses everything on its line. */
    float far = can_aim ? fmaxf(radius, v3_length(rel) + aim_radius) : radius;
    *o = v3_add(v3_add(center, v3_scale(w, far)), v3_add(v3_scale(t, x), v3_scale(b, y)));
    *d = v3_neg(w);
    return v3_scale(envmap_eval(e, w), (float)(1.0 / ((double)pdf * dens)));
}
