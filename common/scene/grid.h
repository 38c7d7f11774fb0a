/* Heterogeneous media: dense density grids (parse, placement, trilinear lookup) and what
 * a grid adds to a medium: clipping rays to the occupied box, delta / ratio tracking, the
 * marched transmittance and the per-light shadow transmittance cache. Grids are built by
 * scene_json.c and nvdb.c and read-only while rendering; the medium_* entry points below
 * take any medium and fall back to medium.c's closed forms when it has no grid. Callers:
 * media tracking and estimators, the photon pass, tests. */
#ifndef BRUME_GRID_H
#define BRUME_GRID_H
#include <stddef.h>
#include <stdint.h>
#include "scene/medium.h"

#define GRID_MAGIC "BRGRID01"
#define GRID_MAX_VOXELS (1u << 27)
/* Parses the dense grid format: 8 bytes "BRGRID01", three little-endian uint32 nx ny nz
 * (each >= 1, product <= GRID_MAX_VOXELS), then nx*ny*nz little-endian float32 densities
 * (x fastest, then y, then z), each finite and >= 0; nothing after. 0 or -1 with err. */
int grid_parse(const uint8_t *data, size_t size, struct density_grid *out, char *err, size_t errlen);
/* Sets the placement and scale and derives the occupied box, the voxel size and the
 * majorant cells (below). */
void grid_finish(struct density_grid *g, const struct xform *grid_to_world, float scale);
/* Density (scale applied) at world point p. */
float grid_density(const struct density_grid *g, vec3 p);

/* Local majorants: the grid is cut into cells of GRID_MAJ_BLOCK^3 voxels, each holding the
 * largest voxel value (times scale, inflated by 2^-16 against rounding) within one voxel
 * beyond what its trilinear support touches, so no lookup in the cell (even one rounded
 * across its face) exceeds it. Delta tracking, ratio tracking and free flight walk these
 * cells along the ray (a 3D DDA) with each cell's majorant, skip cells whose majorant is 0,
 * and take at most GRID_TRACK_MAX tentative collisions per call: a ray that reaches the
 * bound counts as absorbed (transmittance 0, no scattering), is counted
 * (grid_track_bound_hits) and logged (the first, then at each power of 10). */
#define GRID_MAJ_BLOCK 4u
#define GRID_TRACK_MAX 65536u
/* The majorant of the cell holding world point p; 0 outside the grid. For tests. */
float grid_majorant(const struct density_grid *g, vec3 p);
/* Rays of this process whose tracking reached GRID_TRACK_MAX so far. */
uint64_t grid_track_bound_hits(void);

/* The part [*t0, *t1) of o + t d, t in [0, tmax), where the medium can be non-empty
 * (homogeneous: all of it). Returns 0 if there is none. d need not be unit for grids. */
int medium_clip(const struct medium *m, vec3 o, vec3 d, float tmax, float *t0, float *t1);
/* Transmittance over [0, len) of o + t d (d unit): closed form for homogeneous media;
 * for grids ratio tracking against the local majorants (unbiased, ratio != 0) or a
 * jittered march (Jensen) using the
 * random numbers of key. */
vec3 medium_tr_segment(const struct medium *m, vec3 o, vec3 d, float len, uint64_t key, int ratio);
/* Emission reaching o from [0, len) of o + t d (d unit): the integral of Tr(t) e rho(t),
 * closed form for homogeneous media (rho = 1); for grids an unbiased one-sample estimate,
 * a uniform point of the occupied span with its transmittance by ratio tracking (random
 * numbers from key). */
vec3 medium_emission_segment(const struct medium *m, vec3 o, vec3 d, float len, uint64_t key);
/* Free flight over [0, tmax) of o + t d: closed form (medium_sample_distance) for
 * homogeneous media, weighted delta tracking against the local majorants for grids. Same
 * contract as medium_sample_distance; random numbers from key. */
int medium_sample_flight(const struct medium *m, vec3 o, vec3 d, float tmax, vec3 chan, uint64_t key, float *t,
                         vec3 *weight);
/* medium_clip's answer for one ray, kept by a caller that clipped it already. */
struct medium_clip_memo {
    int hit;        /* medium_clip's return (-1 to a caller: not taken) */
    float t0, t1;
};
/* The same flight with clip = medium_clip's answer for (o, d, tmax) (NULL: clipped here). */
int medium_sample_flight_clip(const struct medium *m, vec3 o, vec3 d, float tmax, const struct medium_clip_memo *clip,
                              vec3 chan, uint64_t key, float *t, vec3 *weight);
/* Ray-marching step for this medium: the settings' step, or half a voxel for grids if smaller. */
float medium_march_step(const struct medium *m, float step);

/* ---- directions toward a grid's density (the final gather's bounce) ---- */
/* A lattice of cells over the grid's occupied box (about GRID_MAJ_BLOCK voxels an edge, at
 * most GRID_AIM_MAX_N an axis), each weighted by the densities of the voxel centres inside
 * it. A sample picks a cell in proportion to its weight and a point uniform in it, and
 * returns the direction from p to that point; grid_aim_pdf is that direction's density
 * (solid angle): the sum over the cells the ray from p crosses of the cell's probability
 * over its world volume times the integral of t^2 across it. Exact, so that a mixture
 * with other strategies stays unbiased. */
#define GRID_AIM_MAX_N 32u
struct grid_aim {
    const struct density_grid *g;
    uint32_t n[3];
    vec3 lo, hi;            /* grid-space box of the lattice (the occupied box) */
    float *cdf;             /* 1 + n[0] n[1] n[2] cumulative probabilities (cdf.h), x fastest: 0 .. 1 */
    double cell_volume;     /* world volume of a cell */
};
/* Returns 1 if the grid has density to aim at, else 0 (a is then empty: cdf NULL). */
int grid_aim_init(struct grid_aim *a, const struct density_grid *g);
void grid_aim_fini(struct grid_aim *a);
/* The unit direction from p toward a sampled point (u0 picks the cell, u1..u3 the point);
 * the zero vector if the point is p. */
vec3 grid_aim_sample(const struct grid_aim *a, vec3 p, float u0, float u1, float u2, float u3);
float grid_aim_pdf(const struct grid_aim *a, vec3 p, vec3 w);

/* ---- shadow transmittance cache (Jensen's methods in grids, never VPT) ---- */

/* 1 when no voxel holds density (the occupied box is marked empty, lo > hi). */
static inline int grid_is_empty(const struct density_grid *g)
{
    return !(g->occ_lo.x <= g->occ_hi.x && g->occ_lo.y <= g->occ_hi.y && g->occ_lo.z <= g->occ_hi.z);
}
/* World-space bounding box of the grid's occupied box (empty: lo > hi). */
void grid_world_box(const struct density_grid *g, vec3 *lo, vec3 *hi);
/* Grows [lo, hi] to hold the world box of every grid among the media (those with data). */
struct scene_media;
void media_grids_grow_box(const struct scene_media *sm, vec3 *lo, vec3 *hi);
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
int tr_cache_init(struct tr_cache *c, const struct medium *m, vec3 light, uint32_t threads);
void tr_cache_fini(struct tr_cache *c);
/* Interpolated optical depth from p to the light; 0 when p is outside the lattice. */
int tr_cache_tau(const struct tr_cache *c, vec3 p, float *tau);
/* The same from any point p: outside the lattice (where the density is zero) the segment
 * to the light is clipped to the lattice's box; *tau is the value at the entry point, or 0
 * when the segment misses the box. Returns 0 only when there is no cache or p is not
 * finite. */
int tr_cache_tau_from(const struct tr_cache *c, vec3 p, float *tau);

#endif
