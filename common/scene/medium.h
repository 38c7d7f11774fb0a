/* Participating media: homogeneous media (absorption, scattering, emission, Henyey-Greenstein
 * phase), which objects they fill, the scene's fog, and the settings of the volume
 * renderer. Parsed by scene_json.c into scene.media; read-only while rendering. The
 * closed-form pieces (transmittance, free-flight sampling, HG phase) live here so that the
 * path tracer (media_integrator.c), the photon pass (photonmap.c) and the tests share them.
 * Conventions: directions are directions of travel; the phase function of light travelling
 * along d_in and leaving along d_out is hg(dot(d_in, d_out), g), so g > 0 is forward. */
#ifndef BRUME_MEDIUM_H
#define BRUME_MEDIUM_H
#include <stddef.h>
#include <stdint.h>
#include "scene/scene.h"
#include "base/vec.h"

#define MEDIUM_NONE UINT32_MAX
#define MEDIA_MAX 256
/* Path of the volume photon map among a job's blobs: absolute, so no scene file can have it. */
#define MEDIA_PHOTON_ASSET "/volume-photon-map"

struct photon_map;

/* A dense density grid (file format: grid_parse) placed by grid_to_world, which maps the
 * unit cube [0,1]^3 onto the grid's extent. Densities are sampled trilinearly between
 * voxel centres and are 0 outside the cube. */
struct density_grid {
    uint32_t nx, ny, nz;
    float *data;            /* nx * ny * nz values, x fastest, each >= 0 and finite */
    float scale;            /* multiplies every value */
    float max_density;      /* max of data, times scale: the majorant's density */
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
    MEDIA_METHOD_COUNT_
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
    float skip_bound;           /* skip the photon pass when multiple scattering is bounded below this */
    uint32_t max_photon_depth;  /* interactions per photon path */
    struct photon_map *map;     /* worker: the map from the master's blob; NULL if none */
};

struct scene_media *media_scene_new(void);
void media_scene_free(struct scene_media **m);
/* Records that mesh / sphere idx holds medium (grows the per-object arrays). */
void media_set_mesh(struct scene_media *m, uint32_t idx, uint32_t medium);
void media_set_sphere(struct scene_media *m, uint32_t idx, uint32_t medium);
uint32_t media_mesh_inside(const struct scene_media *m, uint32_t idx);
uint32_t media_sphere_inside(const struct scene_media *m, uint32_t idx);
int media_validate(const struct scene *s, char *err, size_t errlen);
const char *media_method_name(enum media_method m);
int media_method_from_name(const char *name, enum media_method *out);

/* ---- closed forms for homogeneous media ---- */

/* exp(-sigma_t d) per channel; 1 where sigma_t is 0 (also for d = inf). */
vec3 medium_transmittance(const struct medium *m, float d);
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

/* ---- heterogeneous media (density grids) ---- */

#define GRID_MAGIC "BRGRID01"
#define GRID_MAX_VOXELS (1u << 27)
/* Parses the dense grid format: 8 bytes "BRGRID01", three little-endian uint32 nx ny nz
 * (each >= 1, product <= GRID_MAX_VOXELS), then nx*ny*nz little-endian float32 densities
 * (x fastest, then y, then z), each finite and >= 0; nothing after. 0 or -1 with err. */
int grid_parse(const uint8_t *data, size_t size, struct density_grid *out, char *err, size_t errlen);
/* Sets the placement and scale and derives the occupied box and voxel size. */
void grid_finish(struct density_grid *g, const struct xform *grid_to_world, float scale);
void grid_free(struct density_grid **g);
/* Density (scale applied) at world point p. */
float grid_density(const struct density_grid *g, vec3 p);

/* Density at p: 1 for homogeneous media. */
static inline float medium_density(const struct medium *m, vec3 p)
{
    return m->grid ? grid_density(m->grid, p) : 1.0f;
}
/* The part [*t0, *t1) of o + t d, t in [0, tmax), where the medium can be non-empty
 * (homogeneous: all of it). Returns 0 if there is none. d need not be unit for grids. */
int medium_clip(const struct medium *m, vec3 o, vec3 d, float tmax, float *t0, float *t1);
/* Transmittance over [0, len) of o + t d (d unit): closed form for homogeneous media;
 * for grids ratio tracking (unbiased, ratio != 0) or a jittered march (Jensen) using the
 * random numbers of key. */
vec3 medium_tr_segment(const struct medium *m, vec3 o, vec3 d, float len, uint64_t key, int ratio);
/* Homogeneous media: the density of a scattering event at t under medium_sample_distance
 * with the same chan (for MIS). */
float medium_flight_pdf(const struct medium *m, vec3 chan, float t);
/* Emission reaching o from [0, len) of o + t d (d unit): the integral of Tr(t) e rho(t),
 * closed form for homogeneous media (rho = 1); for grids an unbiased one-sample estimate,
 * a uniform point of the occupied span with its transmittance by ratio tracking (random
 * numbers from key). */
vec3 medium_emission_segment(const struct medium *m, vec3 o, vec3 d, float len, uint64_t key);
/* Free flight over [0, tmax) of o + t d: closed form (medium_sample_distance) for
 * homogeneous media, weighted delta tracking against the majorant for grids. Same
 * contract as medium_sample_distance; random numbers from key. */
int medium_sample_flight(const struct medium *m, vec3 o, vec3 d, float tmax, vec3 chan, uint64_t key, float *t,
                         vec3 *weight);
/* Ray-marching step for this medium: the settings' step, or half a voxel for grids if smaller. */
float medium_march_step(const struct medium *m, float step);

/* ---- shadow transmittance cache (Jensen's methods in grids, never VPT) ---- */

/* World-space bounding box of the grid's occupied box (empty: lo > hi). */
void grid_world_box(const struct density_grid *g, vec3 *lo, vec3 *hi);
/* Optical depth per unit sigma_t of m's grid along the segment a -> b: the midpoint rule
 * at steps of at most half a voxel over the part inside the occupied box. Deterministic. */
float grid_optical_depth(const struct medium *m, vec3 a, vec3 b);

/* Optical depth from the vertices of a lattice over the world box of a grid's occupied box
 * to one point light, by grid_optical_depth (one vertex per TR_CACHE_SPACING voxels, at
 * most TR_CACHE_MAX_N per axis); trilinear lookups. The march's shadow rays read it
 * instead of marching: filled once per job (values do not depend on threads). Its error
 * against the exact march is what trilinear interpolation of a smooth function over one
 * voxel leaves (test_medium.c states the bound it checks). */
#define TR_CACHE_SPACING 1.0f
#define TR_CACHE_MAX_N 129u
struct tr_cache {
    vec3 light, lo, hi, cell, inv_cell;
    uint32_t n[3];
    float *tau;     /* n[0] n[1] n[2] values, x fastest; NULL = empty */
};
/* Returns 1 if a cache was filled (m has a grid with a non-empty occupied box), else 0. */
int tr_cache_build(struct tr_cache *c, const struct medium *m, vec3 light, uint32_t threads);
void tr_cache_free(struct tr_cache *c);
/* Interpolated optical depth from p to the light; 0 when p is outside the lattice. */
int tr_cache_tau(const struct tr_cache *c, vec3 p, float *tau);
/* The same from any point p: outside the lattice (where the density is zero) the segment
 * to the light is clipped to the lattice's box; *tau is the value at the entry point, or 0
 * when the segment misses the box. Returns 0 only when there is no cache or p is not
 * finite. */
int tr_cache_tau_from(const struct tr_cache *c, vec3 p, float *tau);

/* Henyey-Greenstein phase function for cos(d_in, d_out) = cos_theta. */
float phase_hg(float cos_theta, float g);
/* Samples d_out for light travelling along d_in (unit); returns the pdf (= the phase value). */
float phase_hg_sample(vec3 d_in, float g, float u1, float u2, vec3 *d_out);
/* cos(theta) of the HG sample for (g, u): exposed for the chi-square test. */
float phase_hg_sample_cos(float g, float u);

#endif
