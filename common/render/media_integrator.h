/* Camera paths through participating media: the volumetric path tracer (reference) and
 * Jensen's ray marching with per-step photon lookups or the beam radiance estimate. They
 * read the job's media state (media_track.h) and photon map (photon_map.h) and track the
 * medium across boundaries with media_track.c. Called by integrator.c, which hands over
 * every camera sample of a scene with media. */
#ifndef BRUME_MEDIA_INTEGRATOR_H
#define BRUME_MEDIA_INTEGRATOR_H
#include "render/raydiff.h"
#include "render/render_job.h"
#include "scene/medium.h"  /* media settings, for callers that pick the method */
#include "scene/sampler.h"

/* One camera sample of a media scene, from the camera ray (org, dir) at time01, with the
 * photon map of the first pass. */
vec3 media_sample_path(const struct render_job *job, const struct sampler *smp, uint32_t px, uint32_t py, vec3 org,
                       vec3 dir, float time01, uint64_t *rays, int *hit_any);
/* The same with the photon map of pass `pass` (< job->num_passes; render_job_pass_media).
 * first: NULL, or the camera ray's closest hit already traced (for AOVs), valid when
 * first_found; the path then starts from it instead of tracing the ray again. rd: the
 * camera ray's differentials (texshade_camera) when the job has textures, or NULL (point
 * lookups). direct: NULL, or where the light seen straight along the camera ray
 * (media_direct_light's) goes instead of into the result, for the caller to average it
 * with other camera rays' (render_job.direct_samples). */
vec3 media_sample_path_pass(const struct render_job *job, uint32_t pass, const struct sampler *smp, uint32_t px,
                            uint32_t py, vec3 org, vec3 dir, float time01, const struct accel_hit *first,
                            int first_found, const struct raydiff *camera_rd, vec3 *direct, uint64_t *rays,
                            int *hit_any);
/* The light seen straight along camera ray (org, dir) at time01: an emitter's light at the
 * first hit times the camera medium's transmittance to it (as the pass's method weighs
 * it), or, from a camera in no medium, the environment's where the ray escapes; zero
 * behind a medium boundary. One ray. Only for jobs with direct_samples > 1 (the camera's
 * medium is not a grid). */
vec3 media_direct_light(const struct render_job *job, uint32_t pass, vec3 org, vec3 dir, float time01, uint64_t *rays);

/* Glow sampling. A point light inside a scattering medium glows: the light a ray gathers
 * from it by single scattering falls off as 1 / (the ray's distance to the light), ~
 * 1 / sin(theta) for rays leaving a point at the angle theta from the direction c to the
 * light, whose square cosine sampling cannot integrate (fireflies on surfaces next to a
 * light in fog). This density is 1 / (pi^2 sin(theta)) in the cone theta < pi/2 around
 * the unit direction c (theta uniform in [0, pi/2), the azimuth uniform), 0 outside:
 * the glow over it is bounded. The final gather's bounce of march and beam samples the
 * mixture of cosine sampling and this density toward each glowing light (docs/media.md). */
vec3 media_glow_sample(vec3 c, float u1, float u2);
/* Its density at the unit direction w (solid angle; large but finite along c). */
float media_glow_pdf(vec3 c, vec3 w);

#endif
