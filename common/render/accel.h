/* Ray queries through Embree 3: one device and top-level scene per job and frame, shared
 * read-only by the render threads. Still geometry has no time steps; only what moves in
 * this frame's shutter gets them (deformation as vertex steps, rigid keys as instances).
 * Also the frame's geometry as hits need it (scene description, face normals). A scene
 * where nothing moves has has_motion == 0 and costs nothing extra. Hits are reported per
 * scene mesh / sphere. Built by render_job.c; read by everything that traces rays. */
#ifndef BRUME_ACCEL_H
#define BRUME_ACCEL_H
#include <math.h>
#include <stddef.h>
#include <stdint.h>
#if defined(__SSE__)
#include <xmmintrin.h>
#endif
#include <embree3/rtcore.h>
#include "scene/scene.h"
#include "base/vec.h"

/* How one mesh or sphere with motion data is represented this frame. */
struct accel_motion {
    RTCScene child;         /* instanced scene (rigid keyframes), or NULL */
    RTCGeometry instance;   /* retained instance geometry, or NULL */
    uint32_t num_steps;     /* deformation: vertex sets in steps (1 = frozen this frame); 0 = none */
    float *steps;           /* num_steps * 3 * num_vertices (+ padding), shared with Embree */
};

struct accel {
    RTCDevice device;
    RTCScene scene;
    uint32_t sphere_geom;   /* the accel_hit.geom of spheres: == num_meshes */
    uint32_t num_spheres;
    uint32_t still_geoms;   /* hits with geom below it are on still triangles: sphere_geom
                             * when no mesh or sphere has motion data, else 0 (still_tri
                             * tells them apart) */
    unsigned char *still_tri; /* per accel_hit.geom (sphere_geom included): 1 for a mesh
                             * without motion data (no keys, no frames), 0 for spheres */
    int has_motion;         /* something has time steps: rays must carry their time */
    int packets_exact;      /* accel_intersect_packet gives accel_intersect's hits bit for bit:
                             * only triangles, none instanced or with time steps (Embree's
                             * packet kernels for spheres and motion round t differently) */
    uint32_t num_top;       /* top-level geometries */
    uint32_t *top_mesh;     /* per top-level geometry: mesh index, or sphere_geom for the still spheres */
    uint32_t *top_sphere;   /* per top-level geometry: the sphere of a rigid sphere instance, or UINT32_MAX */
    uint32_t *still_sphere; /* primitive of the still-sphere geometry -> sphere index */
    struct accel_motion *mesh_motion;   /* per mesh, NULL when no mesh has motion data */
    struct accel_motion *sphere_motion; /* per sphere, NULL when no sphere has keys */
    const struct scene *desc;   /* the scene description built from (outlives the accel) */
    vec3 **face_normals;        /* per mesh, per triangle: unit right-handed normal of the
                                 * stored vertices (zero if degenerate); hits read it rather
                                 * than a cross product and a square root each */
};

struct accel_hit {
    float t;
    uint32_t geom, prim;    /* mesh and triangle, or sphere_geom and sphere index */
    float u, v;     /* barycentrics for triangles */
};

/* Embree's name of an instruction set ("avx2", "sse4.2", "avx512"), and the enum of a name
 * (0, or -1 for an unknown one). */
const char *embree_isa_name(enum embree_isa isa);
int embree_isa_from_name(const char *name, enum embree_isa *isa);
/* 1 when this CPU runs Embree's kernels for `isa` (the features Embree requires of it). */
int embree_isa_supported(enum embree_isa isa);
/* "threads=T,isa=NAME" for rtcNewDevice; -1 with err when this CPU lacks the instruction set. */
int embree_device_config(enum embree_isa isa, uint32_t threads, char *config, size_t size, char *err, size_t errlen);

/* Builds the scene for frame `frame` (its shutter is frame + camera.shutter_open .. close)
 * with the Embree kernels of scene->settings.embree_isa. threads: Embree's build threads
 * (0 = all cores). Returns 0 or -1 with err. */
int accel_init(struct accel *a, const struct scene *scene, uint32_t frame, uint32_t threads, char *err,
                size_t errlen);
void accel_fini(struct accel *a);

/* The hit as the renderer names it: mesh and triangle, or sphere_geom and sphere index. */
static inline void accel_hit_from_embree_(const struct accel *a, unsigned geom_id, unsigned inst_id,
                                          unsigned prim_id, float t, float u, float v, struct accel_hit *hit)
{
    unsigned top = inst_id != RTC_INVALID_GEOMETRY_ID ? inst_id : geom_id;
    hit->t = t;
    hit->geom = a->top_mesh[top];
    hit->prim = prim_id;
    if (hit->geom == a->sphere_geom)
        hit->prim = a->top_sphere[top] != UINT32_MAX ? a->top_sphere[top] : a->still_sphere[prim_id];
    hit->u = u;
    hit->v = v;
}

/* A ray's origin, tnear, direction and time, for every rtcIntersect1 / rtcOccluded1 of the
 * render layer. Embree reads the first two groups as
 * 16-byte vectors right away: written as one 16-byte store each, the load takes its bytes
 * from the store queue (four 4-byte stores cannot feed it, and it would wait for them to
 * be written through, on every ray). */
static inline void accel_ray_set(struct RTCRay *r, vec3 o, float tnear, vec3 d, float time01)
{
#if defined(__SSE__)
    _mm_store_ps(&r->org_x, _mm_setr_ps(o.x, o.y, o.z, tnear));
    _mm_store_ps(&r->dir_x, _mm_setr_ps(d.x, d.y, d.z, time01));
#else
    r->org_x = o.x, r->org_y = o.y, r->org_z = o.z, r->tnear = tnear;
    r->dir_x = d.x, r->dir_y = d.y, r->dir_z = d.z, r->time = time01;
#endif
}

/* Embree's bound on every component of a ray's origin and direction (FLT_LARGE in its
 * ray.h): a ray past it, or with a NaN, fails Embree's ray.valid(), which Debian's build
 * asserts (an abort). Scene coordinates may lie anywhere a float reaches (a point light at
 * 1e30 from the camera), so such a ray is not traced: it misses everything; a shadow
 * segment toward such a point is traced scaled (accel_occluded). */
#define ACCEL_RAY_MAX 1.844e18f
static inline int accel_ray_ok_(vec3 o, vec3 d)
{
    return fabsf(o.x) <= ACCEL_RAY_MAX && fabsf(o.y) <= ACCEL_RAY_MAX && fabsf(o.z) <= ACCEL_RAY_MAX &&
           fabsf(d.x) <= ACCEL_RAY_MAX && fabsf(d.y) <= ACCEL_RAY_MAX && fabsf(d.z) <= ACCEL_RAY_MAX;
}

/* Closest hit in (0, tmax) at time01 in [0, 1] across the shutter; returns 1 on a hit.
 * Inline: the path tracer calls it for every bounce. */
static inline int accel_intersect(const struct accel *a, vec3 o, vec3 d, float tmax, float time01,
                                  struct accel_hit *hit)
{
    if (!accel_ray_ok_(o, d))
        return 0;
    struct RTCIntersectContext ctx;
    rtcInitIntersectContext(&ctx);
    struct RTCRayHit rh;
    accel_ray_set(&rh.ray, o, 0.0f, d, time01);
    rh.ray.tfar = tmax;
    rh.ray.mask = 0xffffffffu;
    rh.ray.id = 0;
    rh.ray.flags = 0;
    rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
    rh.hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
    rtcIntersect1(a->scene, &ctx, &rh);
    if (rh.hit.geomID == RTC_INVALID_GEOMETRY_ID)
        return 0;
    /* u and v one float at a time, as Embree stored them: an 8-byte load of the pair would
     * wait for both stores to leave the store buffer. */
    float u = rh.hit.u, v = rh.hit.v;
#if defined(__SSE__)
    __asm__("" : "+x"(u)); /* keeps GCC from joining the two loads into one */
#endif
    accel_hit_from_embree_(a, rh.hit.geomID, rh.hit.instID[0], rh.hit.primID, rh.ray.tfar, u, v, hit);
    return 1;
}
/* Closest hits of n <= ACCEL_PACKET camera-like rays in (0, inf), traced together as one
 * Embree packet (coherent rays share the BVH traversal; fewer than 3 go one by one, which
 * costs less): found[k] and hits[k] as accel_intersect gives them for ray k, bit for bit
 * where packets_exact (tests/unit/test_accel.c, tests/integration/packets.sh). */
#define ACCEL_PACKET 16
void accel_intersect_packet(const struct accel *a, uint32_t n, const vec3 *org, const vec3 *dir,
                            const float *time01, struct accel_hit *hits, int *found);
/* 1 if anything blocks the segment (0, tmax) at time01. Inline, as accel_intersect: every
 * vertex of a path casts one. */
static inline int accel_occluded(const struct accel *a, vec3 o, vec3 d, float tmax, float time01)
{
    if (!accel_ray_ok_(o, d)) {
        /* A shadow ray toward a point beyond the bound (a light 1e19 away): the same segment
         * with d scaled by 2^-68 and tmax by 2^68, both exact, which brings any finite d in. */
        d = v3_scale(d, 0x1p-68f);
        tmax *= 0x1p68f;
        if (!accel_ray_ok_(o, d))
            return 0;
    }
    struct RTCIntersectContext ctx;
    rtcInitIntersectContext(&ctx);
    struct RTCRay r;
    accel_ray_set(&r, o, 0.0f, d, time01);
    r.tfar = tmax;
    r.mask = 0xffffffffu;
    r.id = 0;
    r.flags = 0;
    rtcOccluded1(a->scene, &ctx, &r);
    return r.tfar < 0.0f;
}
/* accel_occluded of n <= ACCEL_PACKET segments (org[k], dir[k]) in (0, tmax), traced as one
 * Embree packet (fewer than 4 one by one): occluded[k] as accel_occluded gives it for
 * segment k, where packets_exact (the first shadow rays of a pixel's paths, integrator.c). */
void accel_occluded_packet(const struct accel *a, uint32_t n, const vec3 *org, const vec3 *dir, float tmax,
                           const float *time01, int *occluded);

/* Object to world transform of a rigidly moving mesh or sphere (geom, prim as in a hit) at
 * time01; returns 0 (and leaves out alone) for geometry without an instance. */
/* Attaches to scene s a user geometry of n primitives sharing user data `user`, with
 * Embree's bounds and intersect callbacks: the way a query collects every primitive whose
 * box a ray meets (motion_vis.c, photon_beams.c). */
void accel_attach_user_geometry(RTCDevice dev, RTCScene s, uint32_t n, void *user, RTCBoundsFunction bounds,
                                RTCIntersectFunctionN intersect);
int accel_object_xform_slow_(const struct accel *a, uint32_t geom, uint32_t prim, float time01, struct xform *out);
static inline int accel_object_xform(const struct accel *a, uint32_t geom, uint32_t prim, float time01,
                                     struct xform *out)
{
    if (!a->mesh_motion && !a->sphere_motion)
        return 0; /* nothing instanced: no lookup per hit (objects with keys are instanced
                   * even when still during this frame's shutter) */
    return accel_object_xform_slow_(a, geom, prim, time01, out);
}

#endif
