/* Texture evaluation (see texture.h). The checker's box filter integrates the square wave
 * in closed form per axis (the integral of the odd-square indicator over [0, x] is
 * floor(x/2) + 2 max(x/2 - floor(x/2) - 1/2, 0)), as in pbrt-v3's Checkerboard2DTexture;
 * both axes combine as the probability that exactly one of them is odd. */
#include "scene/texture.h"
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <string.h>

static const char *const filter_names[TEXFILTER_COUNT_] = {"nearest", "bilinear", "trilinear", "ewa"};

void texture_init(struct texture *t, enum texture_type type, const char *name)
{
    memset(t, 0, sizeof *t);
    if (name)
        snprintf(t->name, sizeof t->name, "%s", name);
    t->type = type;
    t->filter = TEXTURE_DEFAULT_FILTER;
    t->wrap = TEXWRAP_REPEAT;
    t->max_aniso = TEXTURE_DEFAULT_MAX_ANISO;
    t->scale[0] = t->scale[1] = 1.0f;
    t->color0 = v3(1, 1, 1);
    t->color1 = v3(0, 0, 0);
}

void texture_fini(struct texture *t)
{
    tex_image_fini(&t->image);
}

int texture_filter_from_name(const char *name, enum texture_filter *out)
{
    for (int i = 0; i < TEXFILTER_COUNT_; i++)
        if (strcmp(name, filter_names[i]) == 0) {
            *out = (enum texture_filter)i;
            return 0;
        }
    return -1;
}

const char *texture_filter_name(enum texture_filter f)
{
    return (unsigned)f < TEXFILTER_COUNT_ ? filter_names[f] : "?";
}

static double bump_int(double x)
{
    double h = floor(x / 2.0);
    return h + 2.0 * fmax(x / 2.0 - h - 0.5, 0.0);
}

/* Whether floor(x) is odd, in floating point: exact for any finite x (no integer
 * conversion, which is undefined beyond int64's range). */
static int odd_floor(double x)
{
    return fmod(floor(x), 2.0) != 0.0;
}

static int odd_square(double s, double t)
{
    return odd_floor(s) != odd_floor(t);
}

vec3 texture_checker_box(float s, float t, float ds, float dt, vec3 c0, vec3 c1)
{
    if (!isfinite(s) || !isfinite(t))
        return v3(0, 0, 0);
    double S = s, T = t, dS = isfinite(ds) ? fabs(ds) : 0.0, dT = isfinite(dt) ? fabs(dt) : 0.0;
    double s0 = S - dS, s1 = S + dS, t0 = T - dT, t1 = T + dT;
    if (floor(s0) == floor(s1) && floor(t0) == floor(t1))
        return odd_square(S, T) ? c1 : c0;
    double fs, ft; /* fraction of the box's extent on odd columns / odd rows */
    if (dS > 0.0)
        fs = (bump_int(s1) - bump_int(s0)) / (2.0 * dS);
    else
        fs = odd_floor(S) ? 1.0 : 0.0;
    if (dT > 0.0)
        ft = (bump_int(t1) - bump_int(t0)) / (2.0 * dT);
    else
        ft = odd_floor(T) ? 1.0 : 0.0;
    fs = fmin(fmax(fs, 0.0), 1.0);
    ft = fmin(fmax(ft, 0.0), 1.0);
    float odd = (float)(fs + ft - 2.0 * fs * ft);
    return v3_add(v3_scale(c0, 1.0f - odd), v3_scale(c1, odd));
}

void tex_coord_centre(const struct tex_coord *tc, float *u, float *v)
{
    float cu = tc->u + tc->dudx * tc->cx + tc->dudy * tc->cy;
    float cv = tc->v + tc->dvdx * tc->cx + tc->dvdy * tc->cy;
    int ok = isfinite(cu) && isfinite(cv);
    *u = ok ? cu : tc->u;
    *v = ok ? cv : tc->v;
}

vec3 texture_eval(const struct texture *t, const struct mip *m, const struct tex_coord *tc)
{
    float u = tc->u, v = tc->v;
    if (t->filter != TEXFILTER_NEAREST && t->filter != TEXFILTER_BILINEAR)
        tex_coord_centre(tc, &u, &v);
    float s = u * t->scale[0] + t->offset[0], tt = v * t->scale[1] + t->offset[1];
    float dsdx = tc->dudx * t->scale[0], dsdy = tc->dudy * t->scale[0];
    float dtdx = tc->dvdx * t->scale[1], dtdy = tc->dvdy * t->scale[1];
    if (t->type == TEXTURE_CHECKER) {
        if (t->filter == TEXFILTER_NEAREST)
            return texture_checker_box(s, tt, 0.0f, 0.0f, t->color0, t->color1);
        /* The box bounding the footprint's parallelogram. */
        float ds = fmaxf(fabsf(dsdx), fabsf(dsdy)), dt = fmaxf(fabsf(dtdx), fabsf(dtdy));
        return texture_checker_box(s, tt, ds, dt, t->color0, t->color1);
    }
    /* Images: v points up, rows go down. */
    return mip_lookup(m, t->filter, t->max_aniso, s, 1.0f - tt, dsdx, -dtdx, dsdy, -dtdy);
}
