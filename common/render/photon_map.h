/* The photon map (Jensen and Christensen 1998): 20-byte photons (position, RGBE power,
 * octahedral direction) sorted by the cell of a hash grid with cells of twice the gather
 * radius, plus each bucket's start: two flat arrays, serialised behind a 48-byte header;
 * a surface map of the same format may follow the volume map. Written by the master
 * (photon_trace.c), decoded with bounds checks by workers and owned by the render job;
 * read-only while rendering. A reader adds what it alone uses (decoded photons, the beam
 * query's rows; never serialised). Also the job's volume blob (media settings + map). */
#ifndef BRUME_PHOTON_MAP_H
#define BRUME_PHOTON_MAP_H
#include <stddef.h>
#include <stdint.h>
#include "scene/medium.h"
#include "scene/scene.h"
#include "base/vec.h"
#include "render/photon_codec.h"

struct photon_beam_grid;
struct photon_beams;

struct photon {
    float p[3];
    uint8_t rgbe[4];    /* power (W), shared exponent */
    uint16_t dir;       /* direction of travel, octahedral 8+8 bits */
    uint16_t depth;     /* PHOTON_EVENTS: scattering + surface events of the light path before it
                         * arrived here, 1..PHOTON_DEPTH_MAX (lookups leave out photons that would
                         * make the camera path plus the light path longer than max_depth); and
                         * in a grid its density code (photon_codec.h) */
};
/* A lookup's depth_max that keeps every photon. */
#define PHOTON_DEPTH_ANY UINT32_MAX

struct photon_decoded {
    float dir[3], power[3];
    float density_floor; /* photon_density_floor of its depth word */
};

struct photon_map {
    uint32_t num_photons;
    uint32_t table_size;        /* buckets, a power of two */
    uint64_t num_emitted;
    float radius, cell_size;
    struct photon *photons;     /* sorted by bucket */
    uint32_t *bucket_start;     /* table_size + 1 */
    struct photon_decoded *decoded; /* per photon, filled by photon_map_decode; NULL: decode on the fly */
    struct photon_beam_grid *beam; /* the beam query's rows of photons (photon_map.c), built by
                                    * photon_map_decode for a volume map; NULL: the query reads
                                    * every photon (maps built by hand in tests) */
    struct photon_beams *beams; /* the `beams` method's photon beams (photon_beams.h), or NULL */
    struct photon_map *surface; /* the volume map's companion: photons on diffuse surfaces, or NULL */
    struct photon_map *next_pass; /* the next pass's map (progressive passes, volume blob), or NULL; owned */
};

/* Photons one block of photon indices stored, in index order (photon_trace.c fills them). */
struct photon_list {
    struct photon *a;
    uint32_t n;
    size_t cap;
};

/* Joins the blocks' photons in index order (freeing them), sorts them stably by hash-grid
 * bucket (cells of 2 radius) and writes one map (header, photons, bucket starts) to
 * *map (caller frees). 0, or -1 with err (too many photons, big-endian host). */
int photon_map_serialise(struct photon_list *blocks, uint32_t num_blocks, float radius, uint64_t emitted,
                         uint8_t **map, size_t *bytes, uint32_t *count, char *err, size_t errlen);
/* The byte size of the map photon_map_serialise wrote at map (this process's own bytes,
 * not checked: a blob from the network goes through photon_map_decode). */
size_t photon_map_serialised_bytes(const uint8_t *map);
/* Sorts the map photon_map_serialise wrote at map (bytes long, this process's own) again
 * for a new gather radius, in place: its photons, in the order the map holds them, go
 * through photon_map_serialise (the size stays: the bucket table follows the photon
 * count). 0, or -1 with err. */
int photon_map_set_radius(uint8_t *map, size_t bytes, float radius, char *err, size_t errlen);
/* Checks and decodes a blob (every size and index is checked before use). */
int photon_map_decode(const uint8_t *data, size_t size, struct photon_map **out, char *err, size_t errlen);
/* The same, with the beam query's rows along world axis row_axis (0, 1 or 2; the plain
 * decode: 0): a query walks fewer rows when its ray runs along them, so a worker lays them
 * along the camera's view (photon_map_row_axis). The estimate is the same sum in another
 * order (so its last bits may differ). */
int photon_map_decode_rows(const uint8_t *data, size_t size, int row_axis, struct photon_map **out, char *err,
                           size_t errlen);
/* The world axis a direction runs most along (the first of equals): the rows' axis for
 * queries along it. */
int photon_map_row_axis(vec3 d);
/* Bytes the decoded map holds (its surface map and later passes' too): photons, buckets,
 * decoded photons, the beam query's rows and the photon beams' decoded beams; the beams'
 * chunks and BVH, built by the first query, are not counted. */
size_t photon_map_bytes(const struct photon_map *m);
/* Frees the map, its surface map and the maps of the passes after it. */
void photon_map_free(struct photon_map **pm);

/* Progressive photon mapping (Knaus and Zwicker 2011; volumes as in Jarosz et al. 2011):
 * the gather radius of pass p (0-based) for a kernel of dimension dim (3: volume, 2:
 * surface), r_p^dim = r_{p-1}^dim (p + alpha) / (p + 1), r_0 = r0 (their rule with their
 * 1-based pass number i = p: r_{i+1}^dim = r_i^dim (i + alpha) / (i + 1)). Monotone, and
 * r_p -> 0 for alpha < 1 (r_p^dim ~ p^(alpha - 1)); alpha = 1 keeps r0. */
double photon_pass_radius(double r0, double alpha, uint32_t pass, int dim);

/* Every lookup counts only photons of depth <= depth_max (PHOTON_DEPTH_ANY: all). */

/* Flux density of indirect light at x on a surface with unit normal n (on the side light
 * arrives from): sum of the power of the surface photons within the map's radius of x,
 * near the tangent plane (|(p - x) . n| <= r / 4) and arriving from n's side, over pi r^2.
 * A diffuse surface of albedo a reflects a / pi times it. 0 without a surface map. */
vec3 photon_map_surface(const struct photon_map *m, vec3 x, vec3 n, uint32_t depth_max);
/* Jensen's k-nearest query: the (at most) k photons nearest to x within rmax (capped at 8
 * hash-grid cells, 16 gather radii), searched in rings of cells around x's cell until the
 * k-th distance is below the next ring's; indices into m->photons in idx (room for
 * min(k, PM_KNN_MAX)); *r2 gets the squared radius of the estimate's sphere: the k-th
 * distance when k were found, else rmax^2. Ties broken by index: deterministic. */
#define PM_KNN_MAX 1024u
uint32_t photon_map_knn(const struct photon_map *m, vec3 x, uint32_t k, float rmax, uint32_t *idx, float *r2);
/* Jensen's per-step estimate with the k nearest photons (adaptive radius, at most rmax):
 * sum of phase x power / (4/3 pi r_k^3). In a grid (grid_max, its maximum density, > 0)
 * each photon is weighed by photon_density_weight(rho, ...), rho the density at x. */
vec3 photon_map_gather_knn(const struct photon_map *m, vec3 x, vec3 d_out, float g, uint32_t k, float rmax,
                           uint32_t depth_max, float rho, float grid_max);
/* Beam radiance estimate (Jarosz et al. 2008) along o + t d, t in [0, t1), in medium md:
 * sum over photons within r of the ray of K(r) Tr(t_i) phase power, K = 1 / (pi r^2), in
 * a grid times photon_density_weight of the density at t_i (photon_codec.h). One query
 * for the whole segment. tau: transmittance and density from a marched table (grids), or
 * NULL for the closed form (and grid lookups). */
vec3 photon_map_beam(const struct photon_map *m, vec3 o, vec3 d, float t1, const struct medium *md,
                     const struct photon_tau *tau, uint32_t depth_max);

/* Encodings, exposed for tests. */
uint16_t photon_dir_encode(vec3 d);
vec3 photon_dir_decode(uint16_t e);
/* The beam query's rows (photon_map.c), for tests: its cell size, the rows holding photons
 * and the most photons in one; 1 when the rows are found in a flat (y, z) table, 0 in a
 * hash table, -1 when the map has no rows. */
int photon_map_beam_layout(const struct photon_map *m, float *cell, uint32_t *rows, uint32_t *longest);

/* The volume blob of a job (path MEDIA_PHOTON_ASSET): the media settings the master
 * settled on (command-line overrides included) and the photon maps, one per pass, if any
 * were built. Every worker renders with exactly these; the blob is content-addressed like
 * any asset. Format "BVOL0002": a 48-byte header (magic, method, step, radius r0, number
 * of maps P <= VOLUME_BLOB_MAX_MAPS, photons per pass, alpha, indirect mode, zero
 * padding), then per map
 * its byte size (u64) and the map (photon_map_serialise's bytes: volume map, then
 * surface map). */
#define VOLUME_BLOB_MAX_MAPS 1024u
int volume_blob_make_passes(const struct scene_media *sm, const uint8_t *const *maps, const size_t *map_sizes,
                            uint32_t num_maps, uint8_t **out, size_t *out_size);
/* One map (or none when map is NULL): a single pass. */
int volume_blob_make(const struct scene_media *sm, const uint8_t *map, size_t map_size, uint8_t **out,
                     size_t *out_size);
/* Checks a volume blob and decodes its maps into a chain (*maps, then ->next_pass; NULL
 * when it holds none) and its count; settings into *settings when not NULL (method, step,
 * radius, photons, alpha, indirect). Needs no scene (the fuzz target calls it). 0 or -1
 * with err. */
int volume_blob_decode(const uint8_t *data, size_t size, struct scene_media *settings, struct photon_map **maps,
                       uint32_t *num_maps, char *err, size_t errlen);
/* Applies a volume blob to a freshly parsed scene (its settings) and decodes its maps into
 * *map, a chain of one map per pass linked by next_pass (NULL when the blob has none; the
 * caller hands it to its render job). 0 or -1 with err. */
int volume_blob_apply(struct scene *s, const uint8_t *data, size_t size, struct photon_map **map, char *err,
                      size_t errlen);
#endif
