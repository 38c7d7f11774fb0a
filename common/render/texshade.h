/* Textures in the path tracer: the glue between a render_job and the ray differential
 * maths (raydiff.c) and texture lookups (texture.c) in the job's MIP pyramids (built by
 * render_job.c). Only scenes whose materials use a texture pay for it (render_job.textured);
 * others never call in here, so their images are unchanged bit for bit. Callers: integrator.c,
 * media_integrator.c (camera paths through media) and photon_trace.c (photon hits, without
 * a footprint). */
#ifndef BRUME_TEXSHADE_H
#define BRUME_TEXSHADE_H
#include "render/raydiff.h"
#include "render/render_job.h"
#include "render/surface.h"
#include "scene/material.h"
#include "scene/sampler.h"

/* Differentials of the camera ray cs (pose at its time, lens point fixed) of sample smp:
 * where the sampler puts one sample per cell of a grid over the pixel
 * (sampler_pixel_cells), the footprint is the sample's cell, centred on it; otherwise an
 * isotropic footprint of 1/spp of the pixel's area at the sample. */
void texshade_camera(const struct render_job *job, const struct camera_sample *cs, const struct sampler *smp,
                     struct raydiff *rd);
/* Differential geometry of hit h of the ray (org, dir) at time01, with rd's centring
 * offset for the footprint filters. */
void texshade_hit(const struct render_job *job, vec3 org, vec3 dir, const struct accel_hit *h, float time01,
                  const struct raydiff *rd, struct raydiff_hit *out);
/* The material with its albedo texture looked up (a copy in *buf), or mat itself. */
const struct material *texshade_material(const struct render_job *job, const struct material *mat,
                                         const struct raydiff_hit *dh, struct material *buf);
/* The shading normal ns (unit, on the side of ng) perturbed by the material's normal map
 * (tangent space) or else its bump map (height differences over the footprint's uv
 * extent, as pbrt's BumpMap); ns itself when the material has neither, the mapping is
 * degenerate, or the result would face away from ng. mips: the job's pyramids. */
vec3 texshade_bump(const struct scene *scene, const struct mip *mips, const struct material *mat,
                   const struct raydiff_hit *dh, vec3 ng, vec3 ns);
/* Carries rd over a scattering at the hit: exact for delta bounces, a cone otherwise.
 * ns: the shading normal used (on the side of the incoming ray); front as for
 * material_sample. */
void texshade_scatter(struct raydiff *rd, const struct material *mat, const struct bsdf_sample *bs, int front,
                      vec3 dir, vec3 ns, const struct raydiff_hit *dh);

/* A hit's textures in one call, for paths through media and photon paths: the material
 * with its albedo and roughness textures looked up (a copy in *buf, or mat itself), and
 * s->ns (on s->ng's side) perturbed by its bump or normal map. rd: the ray's differentials,
 * or NULL for point lookups (photons carry no footprint). dh (NULL: not wanted) gets the
 * hit's differential geometry for texshade_scatter. mat itself, s untouched, when the job
 * has no textures. */
const struct material *texshade_surface(const struct render_job *job, vec3 org, vec3 dir, const struct accel_hit *h,
                                        float time01, const struct raydiff *rd, struct surface *s,
                                        const struct material *mat, struct material *buf, struct raydiff_hit *dh);
/* rd carried t along its ray (unit direction dir) to where the ray crosses a surface of
 * normal n without bending (a medium's boundary): the origin derivatives there. */
void texshade_cross(struct raydiff *rd, vec3 dir, float t, vec3 n);
/* rd carried t along its ray (unit direction dir) to a scattering in a medium, then out
 * along d_out as the conservative cone of a diffuse bounce (whatever the phase function). */
void texshade_scatter_volume(struct raydiff *rd, vec3 dir, float t, vec3 d_out);

#endif
