/* Ray differentials (Igehy, SIGGRAPH 1999): how a ray's origin and direction change per
 * pixel step, carried along a path to give every texture lookup its footprint. Camera
 * rays start them (scaled by max(1/8, 1/sqrt(spp))); hits transfer them to the tangent
 * plane; perfect reflection and refraction carry them exactly, a diffuse bounce as a
 * conservative cone. Every result is finite (clamped; non-finite parts give a point
 * lookup). Callers: texshade.c, tests. */
#ifndef BRUME_RAYDIFF_H
#define BRUME_RAYDIFF_H
#include <stdint.h>
#include "scene/camera.h"
#include "scene/texture.h"
#include "base/vec.h"

#define RAYDIFF_MAX 1e8f          /* bound on scale-free derivatives: directions, (u, v) */
#define RAYDIFF_MAX_SPACE 1e30f   /* on position and normal ones, which scale with the scene */
#define RAYDIFF_MIN_COS 1e-4f     /* |cos| between ray and plane used in the transfer */
#define RAYDIFF_DIFFUSE_SPREAD 0.125f /* radians per pixel step after a diffuse bounce, at least */

struct raydiff {
    vec3 dodx, dody;    /* origin derivatives */
    vec3 dddx, dddy;    /* unit-direction derivatives */
    /* Offset from the sample's film position to the centre of its pixel cell, in
     * differential steps (0: none). Lookups are centred there, so a footprint covers the
     * cell the sample stands for, not one shifted by the sample's jitter. Kept through
     * specular bounces, zeroed by a diffuse one. */
    float cx, cy;
};

/* What a hit gives the footprint: position, texture coordinate and shading normal
 * derivatives, and the normal they belong to (unit; the caller flips dn with it). */
struct raydiff_hit {
    vec3 dpdx, dpdy;
    struct tex_coord tc;
    vec3 n;             /* the interpolated (unflipped) shading normal */
    vec3 dndx, dndy;
    vec3 dpdu, dpdv;    /* position derivatives along u and v (bump mapping) */
    int has_dpduv;      /* 0 when the uv mapping is degenerate there */
};

/* Scale of camera differentials for spp samples per pixel: 1/sqrt(spp), at least 1/8. */
float raydiff_spp_scale(uint32_t spp);
/* The same for n cells along one axis of a sample's pixel grid: 1/n, at least 1/8. */
float raydiff_cell_scale(uint32_t n);
/* Camera ray with unit direction d at pose: origin derivatives 0 (same lens point),
 * direction derivatives of the normalized film direction, times scale; no centring offset. */
void raydiff_camera(const struct camera *cam, const struct camera_pose *pose, vec3 d, float scale,
                    struct raydiff *rd);
/* The centring offset of a sample at (jx, jy) in its pixel ([0, 1)^2) whose pixel holds one
 * sample per cell of an nx x ny grid (sampler_pixel_cells; nx or ny 0: none), for camera
 * differentials of scale (sx, sy) pixels along x and y. */
void raydiff_set_center(struct raydiff *rd, float jx, float jy, uint32_t nx, uint32_t ny, float sx, float sy);

/* Transfer to the plane through the hit with normal n (any length, the geometric one):
 * dP = dO + t dD + dt D with dt from dP . n = 0. */
void raydiff_transfer(const struct raydiff *rd, vec3 d, float t, vec3 n, vec3 *dpdx, vec3 *dpdy);

/* A triangle hit: world vertices p[3], optional per-vertex uv[3][2] (NULL: the
 * barycentrics are the uvs) and unit world normals nrm[3] (NULL: flat), barycentrics
 * (b1, b2), geometric normal ng, the ray (d, t) and its differentials. The hit's texture
 * coordinate carries rd's centring offset (as does a sphere hit's). */
void raydiff_triangle(const vec3 p[3], const float (*uv)[2], const vec3 *nrm, float b1, float b2, vec3 ng,
                      const struct raydiff *rd, vec3 d, float t, struct raydiff_hit *out);
/* A sphere hit at p (on the surface): uv from the pole along +y (u = longitude from +z
 * toward +x, v = 1 at the north pole), its derivatives, and dn = dp / r. */
void raydiff_sphere(vec3 center, float radius, vec3 p, const struct raydiff *rd, vec3 d, float t,
                    struct raydiff_hit *out);
/* The (u, v) of a sphere point, as raydiff_sphere defines it. */
void raydiff_sphere_uv(vec3 center, vec3 p, float *u, float *v);

/* Propagation at a hit with position derivatives dpdx/dpdy and shading normal n (unit,
 * on the side the ray came from) with derivatives dndx/dndy. d_in: the incoming unit
 * direction; d_out: the outgoing one. eta_i_over_t: index on the incident side over the
 * transmitted side. */
void raydiff_reflect(struct raydiff *rd, vec3 d_in, vec3 d_out, vec3 n, vec3 dndx, vec3 dndy, vec3 dpdx,
                     vec3 dpdy);
void raydiff_refract(struct raydiff *rd, vec3 d_in, vec3 d_out, vec3 n, vec3 dndx, vec3 dndy, vec3 dpdx,
                     vec3 dpdy, float eta_i_over_t);
void raydiff_diffuse(struct raydiff *rd, vec3 d_out, vec3 dpdx, vec3 dpdy);

#endif
