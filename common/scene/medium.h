/* Participating media: homogeneous media (absorption, scattering, emission, HG phase; g > 0
 * forward, directions are of travel), which objects they fill, the fog, and the volume
 * renderer's settings. Parsed by scene_json.c into scene.media, read-only while rendering;
 * holds nothing built at render time (the photon map is the render job's). The closed
 * forms (transmittance, free flight, phase) are shared by render/ and tests; grids: grid.h. */
#ifndef BRUME_MEDIUM_H
#define BRUME_MEDIUM_H
#include <math.h>
#include <stddef.h>
#include <stdint.h>
#include "scene/scene_limits.h"
#include "base/vec.h"

#define MEDIUM_NONE UINT32_MAX
#define MEDIA_MAX 256
/* Path of the volume photon map among a job's blobs: absolute, so no scene file can have it. */
#define MEDIA_PHOTON_ASSET "/volume-photon-map"

/* A dense density grid (file format: grid_parse, grid.h) placed by grid_to_world, which maps the
 * unit cube [0,1]^3 onto the grid's extent. Densities are sampled trilinearly between
 * voxel centres and are 0 outside the cube. */
struct density_grid {
    uint32_t nx, ny, nz;
    float *data;            /* nx * ny * nz values, x fastest, each >= 0 and finite */
    float scale;            /* multiplies every value */
    float max_density;      /* max of data, times scale (the photon pass's skip bound) */
    uint32_t maj_n[3];      /* majorant cells per axis, GRID_MAJ_BLOCK voxels each (grid.h) */
    float *majorant;        /* per cell, x fastest: an upper bound of the density (scale applied)
                             * anywhere in it; lives in data's allocation, after the voxels */
    struct xform grid_to_world, world_to_grid;
    vec3 occ_lo, occ_hi;    /* grid-space box holding every non-zero voxel's support */
    float voxel_world;      /* smallest voxel edge in world units: the marching step scale */
};

struct medium {
    char name[SCENE_NAME_MAX];
    vec3 sigma_a, sigma_s;  /* per scene unit, each >= 0 */
    vec3 sigma_t;           /* sigma_a + sigma_s */
    vec3 emission;          /* emitted radiance per unit length (W / sr / m^3), >= 0 */
    float g;                /* Henyey-Greenstein asymmetry in (-1, 1) */
    struct density_grid *grid; /* heterogeneous: coefficients times the grid's density; NULL = homogeneous */
};

/* How camera paths treat media. */
enum media_method {
    MEDIA_VPT,          /* volumetric path tracing: free-flight sampling, NEE with transmittance */
    MEDIA_MARCH_STEPS,  /* Jensen ray marching, a photon-map lookup per step */
    MEDIA_MARCH_BEAM,   /* Jensen ray marching for single scattering, beam radiance estimate */
    MEDIA_MARCH_BEAMS,  /* the same single scattering, photon beams (beam x beam) for multiple scattering */
    MEDIA_METHOD_COUNT_
};

/* March and beam: how the indirect light of the first diffuse camera-path vertex is
 * estimated (docs/media.md, "Indirect light at diffuse surfaces"). */
enum media_indirect {
    MEDIA_INDIRECT_GATHER, /* one diffuse bounce, marched, then the surface photon map */
    MEDIA_INDIRECT_PATH,   /* the path goes on as VPT; the photon maps serve the camera segments only */
    MEDIA_INDIRECT_COUNT_
};

struct scene_media {
    struct medium *media;
    uint32_t num_media;
    uint32_t fog;               /* medium outside every medium object, or MEDIUM_NONE */
    uint32_t *mesh_medium;      /* per mesh (first num_mesh_medium): medium inside, or MEDIUM_NONE */
    uint32_t num_mesh_medium;
    uint32_t *sphere_medium;
    uint32_t num_sphere_medium;
    uint32_t interface_material;/* invisible boundary material, or UINT32_MAX */
    enum media_method method;
    float step;                 /* ray-marching step in scene units; 0 = 1/200 of the scene's size */
    uint64_t photons;           /* photons emitted by the photon pass */
    float radius;               /* gather radius; 0 = 1/100 of the scene's size */
    uint32_t knn;               /* per-step estimate: photons of Jensen's k-nearest query (default 50) */
    int shadow_cache;           /* march / beam in grids: cached shadow transmittance (default 1) */
    int surface_photons;        /* march / beam: a surface photon map for diffuse surfaces' indirect light (default 1) */
    enum media_indirect indirect; /* march / beam: final gather or path-traced indirect light */
    float skip_bound;           /* skip the photon pass when multiple scattering is bounded below this */
    uint32_t max_photon_depth;  /* interactions per photon path; 0 = the render's max_depth (media_max_photon_depth) */
    float alpha;                /* progressive radius reduction per pass, in (0, 1]; 0 = MEDIA_DEFAULT_ALPHA */
    uint32_t photon_split;      /* most walkers a heavy photon splits into where it meets a bounded
                                 * medium (1 = none); 0 = MEDIA_DEFAULT_PHOTON_SPLIT */
    uint32_t direct_samples;    /* camera rays per sample for the lights seen straight from the camera
                                 * (1..MEDIA_MAX_DIRECT_SAMPLES; 1 = the sample's own ray only); 0 = the
                                 * method's default (media_direct_samples) */
};
/* volume.direct_samples: the photon methods' default (vpt's is 1) and the largest. */
#define MEDIA_DEFAULT_DIRECT_SAMPLES 8u
#define MEDIA_MAX_DIRECT_SAMPLES 64u
/* The camera rays per sample for directly seen lights: volume.direct_samples, or by
 * default 8 for march, beam and beams and 1 for vpt (docs/media.md). */
static inline uint32_t media_direct_samples(const struct scene_media *sm)
{
    return sm->direct_samples ? sm->direct_samples : sm->method == MEDIA_VPT ? 1u : MEDIA_DEFAULT_DIRECT_SAMPLES;
}
/* Interactions a photon path may take: volume.max_photon_depth, or by default the render's
 * max_depth. A lookup counts a photon of k prior events only when the camera path plus k
 * stays within max_depth (k <= max_depth - 1), and the tracer stores photons with k up to
 * the bound - 1: the default keeps every photon a lookup can count, and no more. */
static inline uint32_t media_max_photon_depth(const struct scene_media *sm, uint32_t max_depth)
{
    return sm->max_photon_depth ? sm->max_photon_depth : max_depth; /* validated: 1..SCENE_MAX_DEPTH */
}
/* volume.photon_split's default and largest value (photon_trace.c, docs/media.md). */
#define MEDIA_DEFAULT_PHOTON_SPLIT 8u
#define MEDIA_MAX_PHOTON_SPLIT 64u
/* Knaus and Zwicker's alpha: the share of each pass's photons a pass keeps in the radius rule. */
#define MEDIA_DEFAULT_ALPHA (2.0f / 3.0f)

struct scene_media *media_scene_new(void);
void media_scene_free(struct scene_media **m);
/* The media own their grids (grid.c parses and fills them); also for a grid not yet attached. */
void grid_free(struct density_grid **g);
/* Records that mesh / sphere idx holds medium (grows the per-object arrays). */
void media_set_mesh(struct scene_media *m, uint32_t idx, uint32_t medium);
void media_set_sphere(struct scene_media *m, uint32_t idx, uint32_t medium);
uint32_t media_mesh_inside(const struct scene_media *m, uint32_t idx);
uint32_t media_sphere_inside(const struct scene_media *m, uint32_t idx);
const char *media_method_name(enum media_method m);
int media_method_from_name(const char *name, enum media_method *out);
const char *media_indirect_name(enum media_indirect m);
int media_indirect_from_name(const char *name, enum media_indirect *out);
/* Whether the photon pass keeps a surface map: only the final gather reads one. */
int media_wants_surface_photons(const struct scene_media *m);

/* ---- closed forms for homogeneous media ---- */

/* exp(-sigma_t d) per channel; 1 where sigma_t is 0 (also for d = inf). */
vec3 medium_transmittance(const struct medium *m, float d);
/* exp(-sigma_t tau) per channel for a finite optical depth tau in density units (a grid's
 * integrated density): one exponential for a grey medium, whose three are the same bits.
 * Inline: the beam query takes one for each photon it accepts. */
static inline vec3 medium_tr_tau(const struct medium *m, float tau)
{
    float tx = expf(-m->sigma_t.x * tau);
    if (m->sigma_t.y == m->sigma_t.x && m->sigma_t.z == m->sigma_t.x)
        return v3(tx, tx, tx);
    return v3(tx, expf(-m->sigma_t.y * tau), expf(-m->sigma_t.z * tau));
}
/* Integral over [0, d] of exp(-sigma_t t) * emission dt per channel (finite for d = inf
 * when sigma_t > 0; 0 for channels with sigma_t = 0 and d = inf, which cannot be seen). */
vec3 medium_emission_integral(const struct medium *m, float d);

/* Free flight in [0, tmax) (tmax may be inf), sampled on one channel chosen by u_channel
 * with probabilities in proportion to chan (the path throughput; uniform if black) and
 * weighted by the one-sample MIS over the three channels. Returns 1 for a scattering
 * event at *t with *weight = sigma_s Tr(t) / pdf(t), or 0 for passing through to tmax with
 * *weight = Tr(tmax) / P(pass). Weights are finite for any sigma_t in [0, 1e30]. */
int medium_sample_distance(const struct medium *m, float tmax, vec3 chan, float u_channel, float u, float *t,
                           vec3 *weight);
/* Homogeneous media: the density of a scattering event at t under medium_sample_distance
 * with the same chan (for MIS). */
float medium_flight_pdf(const struct medium *m, vec3 chan, float t);

/* Henyey-Greenstein phase function for cos(d_in, d_out) = cos_theta. */
float phase_hg(float cos_theta, float g);
/* Samples d_out for light travelling along d_in (unit); returns the pdf (= the phase value). */
float phase_hg_sample(vec3 d_in, float g, float u1, float u2, vec3 *d_out);
/* cos(theta) of the HG sample for (g, u): exposed for the chi-square test. */
float phase_hg_sample_cos(float g, float u);

/* Strongly forward-scattering media in march and beam (docs/media.md, "The forward
 * cone"): Henyey-Greenstein scattering by less than acos(MEDIUM_FORWARD_COS) (2.6 degrees) is
 * taken as no scattering along camera rays, whose transmittance then uses sigma_t - f
 * sigma_s, f = phase_forward_mass(g), while in-scattering (single scattering and the
 * photon estimates) uses phase_hg_cut, the phase function without that cone. Photons are
 * traced with the whole phase function. At g = 0.999 the cone holds 98 % of the
 * scattering, a spike no photon estimate can resolve. */
#define MEDIUM_FORWARD_COS 0.999f
double phase_forward_mass(float g);
/* HG for cos_theta <= MEDIUM_FORWARD_COS, else 0 (not renormalised). */
float phase_hg_cut(float cos_theta, float g);
/* md with sigma_t reduced by the forward cone's share of sigma_s (a copy; the render job
 * keeps one per medium, media_track.h). */
struct medium medium_forward_cut(const struct medium *md);

#endif
