/* Photon beams (Jarosz, Nowrouzezahrai, Sadeghi and Zwicker 2011, "A comprehensive theory
 * of volumetric radiance estimation using photon points and beams"; progressive as in
 * Jarosz, Nowrouzezahrai, Thomas, Sloan and Zwicker 2011, "Progressive photon beams"):
 * the `beams` method stores each photon flight through a medium after its first
 * interaction as a short beam (from where the flight starts to where it ends: the next
 * scattering, a surface, or the medium's end), with the power the photon had at its start.
 * A flight's length is drawn with P(length > v) = Tr(v) (grey sigma_t), so a short beam
 * holding the power unattenuated along its length is an unbiased stand-in for the long
 * beam weighted by Tr(v). The camera side is the beam x beam estimate with a 1D kernel:
 * for every photon beam that passes within r of the camera segment,
 *     power x sigma_s(x_w) x phase(theta) x Tr_camera(w) / (2 r sin theta),
 * w the camera ray's parameter at the lines' closest approach, theta the angle between
 * the two. Beams are cut into chunks (at most PB_CHUNK_RADII radii long) whose boxes,
 * grown by r, go into an Embree user-geometry BVH; a query collects the chunks the
 * segment passes within r of and sums them in chunk order, so the result never depends
 * on Embree's traversal order or thread count.
 *
 * Wire: a section after the photon map(s) of a pass, "BVPB0001", u32 count, u32 0, u64
 * emitted, f32 radius, u32 0 (32 bytes), then count 32-byte beams (below). */
#ifndef BRUME_PHOTON_BEAMS_H
#define BRUME_PHOTON_BEAMS_H
#include <stddef.h>
#include <stdint.h>
#include "base/vec.h"
#include "scene/medium.h"
#include "scene/scene.h"

struct photon_tau;

struct photon_beam {
    float a[3], b[3];   /* start and end of the flight (b != a) */
    uint8_t rgbe[4];    /* power at the start (W), shared exponent */
    uint32_t depth;     /* events of the light path before the flight, 1..PHOTON_DEPTH_MAX */
};

#define PB_MAGIC "BVPB0001"
#define PB_HEADER 32
#define PB_CHUNK_RADII 8.0f     /* a chunk's length, in gather radii (at most PB_MAX_CHUNKS per beam) */
#define PB_MAX_CHUNKS 64u
#define PB_MIN_SIN 1e-3f        /* beams closer than this to parallel to the camera ray are left out */

/* Beams one block of photon indices stored, in index order. */
struct photon_beam_list {
    struct photon_beam *a;
    uint32_t n;
    size_t cap;
};

/* Appends a beam from a to b with power (nothing for black or non-finite power). */
void photon_beam_store(struct photon_beam_list *l, vec3 a, vec3 b, vec3 power, uint32_t depth);
/* Joins the blocks in index order (freeing them) and writes the section to *out. 0, or -1
 * with err (too many beams). */
int photon_beams_serialise(struct photon_beam_list *blocks, uint32_t num_blocks, float radius, uint64_t emitted,
                           uint8_t **out, size_t *bytes, uint32_t *count, char *err, size_t errlen);

/* The decoded beams of one pass and their BVH (read-only while rendering). */
struct photon_beams;
/* 1 when data starts with the beams' magic. */
int photon_beams_is_section(const uint8_t *data, size_t size);
/* Decodes the section at data (it must span all of size), checking every field, and builds
 * the BVH. 0, or -1 with err. */
int photon_beams_decode(const uint8_t *data, size_t size, struct photon_beams **out, char *err, size_t errlen);
void photon_beams_free(struct photon_beams **pb);
uint32_t photon_beams_count(const struct photon_beams *pb);
/* Bytes of the decoded beams (not the chunks and BVH the first query builds). */
size_t photon_beams_bytes(const struct photon_beams *pb);
float photon_beams_radius(const struct photon_beams *pb);
/* Sets the radius of a decoded set (tests), rebuilding its BVH. */
void photon_beams_set_radius(struct photon_beams *pb, float radius);
/* The Embree kernels its BVH is built and traversed with: the job's (scene.h, enum
 * embree_isa; default EMBREE_ISA_AVX2). Before the first query. */
void photon_beams_set_isa(struct photon_beams *pb, enum embree_isa isa);
/* Builds a set from beams in memory (tests). */
struct photon_beams *photon_beams_from(const struct photon_beam *beams, uint32_t n, float radius);

/* The beam x beam estimate (the first call builds the BVH, thread-safely) of the light in-scattered toward o along o + t d, t in [0, t1)
 * (d unit) in medium md: the sum above over beams of depth <= depth_max. tau: the camera
 * ray's transmittance from a marched table (grids), or NULL for the closed form; sigma_s
 * times the grid's density at the closest point for grids. */
vec3 photon_beams_estimate(struct photon_beams *pb, vec3 o, vec3 d, float t1, const struct medium *md,
                           const struct photon_tau *tau, uint32_t depth_max);
/* The same by a loop over every beam (tests). */
vec3 photon_beams_estimate_brute(struct photon_beams *pb, vec3 o, vec3 d, float t1, const struct medium *md,
                                 const struct photon_tau *tau, uint32_t depth_max);
#endif
