/* The environment light: a lat-long (equirectangular) radiance map at infinity, times
 * strength, turned by rotation degrees about +y. Direction d maps to
 * phi = atan2(d.z, d.x) - rotation (u = phi / 2 pi, wrapped to [0, 1)) and
 * theta = acos(d.y) (v = theta / pi, row 0 at +y); each texel is constant over its cell
 * (nearest lookup), so the sampling distribution below is exactly proportional to the
 * texels' luminance. Sampled by a piecewise-constant 2D distribution (pbrt's
 * PiecewiseConstant2D): a marginal over rows and a conditional per row, of luminance times
 * sin(theta) at the row centre; its solid-angle pdf is p(u, v) / (2 pi^2 sin(theta)).
 * `uniform` samples the sphere uniformly instead (for the benchmark). Built by
 * scene_json.c; read-only while rendering (light.c, integrators, photon_trace.c). */
#ifndef BRUME_ENVMAP_H
#define BRUME_ENVMAP_H
#include <stdint.h>
#include "base/vec.h"

struct environment {
    float *rgb;             /* width * height * 3 linear radiance, rows from +y down */
    uint32_t width, height;
    float strength;         /* multiplies the map */
    float rotation;         /* degrees about +y */
    int uniform;            /* sample the sphere uniformly, not by the map */
    /* the distribution: */
    float *cond_cdf;        /* height rows of width + 1 */
    float *marg_cdf;        /* height + 1 */
    float marg_int;         /* integral over [0, 1]^2; 0 = a black map */
    float *cell_pdf;        /* width * height: each cell's density over [0, 1]^2, kept so that a
                             * pdf query (every escaped ray, every light sample) is a lookup */
    vec3 mean;              /* solid-angle mean radiance (strength included) */
};

/* Takes ownership of rgb (mem_alloc'd) and builds the distribution. */
struct environment *envmap_new(float *rgb, uint32_t width, uint32_t height, float strength, float rotation);
void envmap_free(struct environment **env);

/* Radiance arriving from direction d (unit, pointing away from the scene). */
vec3 envmap_eval(const struct environment *e, vec3 d);
/* A direction from two uniforms; *pdf its solid-angle density (0 = none). */
vec3 envmap_sample(const struct environment *e, float u1, float u2, float *pdf);
float envmap_pdf(const struct environment *e, vec3 d);

/* A photon from the environment (photon_trace.c), from five uniforms u: a direction w by
 * envmap_sample (u[0], u[1]), and the line of direction -w through a point x of the plane
 * through `center` perpendicular to w, uniform on the disc of radius `radius` (the scene's
 * bounding sphere seen along w) or, when u[4] < aim_share, uniform on the disc of the
 * sphere (aim_center, aim_radius) seen along w (where media are; aim_share 0: none).
 * *o lies on the line outside both spheres, *d = -w. Returns the power of the photon for
 * a budget of one: L(w) / (pdf(w) p(x)), p the mixture's density over the plane (each
 * disc's uniform density times its share, summed over the discs holding x), so that the
 * expected power of the lines crossing any region inside the union of the two spheres is
 * the sky's power through it (pi r^2 times the integral of L over the sphere, for a ball
 * of radius r): unbiased for any share. 0 when nothing is emitted. */
vec3 envmap_emit(const struct environment *e, vec3 center, float radius, vec3 aim_center, float aim_radius,
                 float aim_share, const float u[5], vec3 *o, vec3 *d);

/* The continuous 2D distribution alone, on [0, 1)^2 (tests): a point and its density. */
void envmap_sample_uv(const struct environment *e, float u1, float u2, float *u, float *v, float *pdf);
float envmap_pdf_uv(const struct environment *e, float u, float v);

#endif
