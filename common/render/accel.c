/* Embree 3 scene building and ray queries (see accel.h). Embree errors go into the
 * project log through the device error callback. Scenes are built with high quality: the
 * BVH is built once per frame and traced by millions of rays. Motion is resampled into
 * uniform Embree time steps over the shutter (motion.c); still geometry never gets any,
 * because time steps cost Embree throughput on every ray. */
#include "render/accel.h"
#include "base/log.h"
#include "scene/motion.h"
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static void accel_on_error(void *user, enum RTCError code, const char *str)
{
    (void)user;
    log_error("embree: error %d: %s", (int)code, str ? str : "(no message)");
}

static const char *const isa_names[EMBREE_ISA_COUNT_] = {"avx2", "sse4.2", "avx512"};

const char *embree_isa_name(enum embree_isa isa)
{
    return (unsigned)isa < EMBREE_ISA_COUNT_ ? isa_names[isa] : "?";
}

int embree_isa_from_name(const char *name, enum embree_isa *isa)
{
    for (unsigned i = 0; i < EMBREE_ISA_COUNT_; i++)
        if (strcmp(name, isa_names[i]) == 0) {
            *isa = (enum embree_isa)i;
            return 0;
        }
    return -1;
}

/* The features Embree 3 asks of each of its instruction sets, as far as the compiler's
 * __builtin_cpu_supports names them (Embree checks the rest itself: rtcNewDevice then
 * fails with RTC_ERROR_UNSUPPORTED_CPU). */
int embree_isa_supported(enum embree_isa isa)
{
#if defined(__x86_64__) || defined(__i386__)
    __builtin_cpu_init();
    int sse42 = __builtin_cpu_supports("sse4.2") && __builtin_cpu_supports("popcnt");
    int avx2 = sse42 && __builtin_cpu_supports("avx") && __builtin_cpu_supports("avx2") &&
               __builtin_cpu_supports("fma") && __builtin_cpu_supports("bmi") && __builtin_cpu_supports("bmi2");
    int avx512 = avx2 && __builtin_cpu_supports("avx512f") && __builtin_cpu_supports("avx512cd") &&
                 __builtin_cpu_supports("avx512dq") && __builtin_cpu_supports("avx512bw") &&
                 __builtin_cpu_supports("avx512vl");
    switch (isa) {
    case EMBREE_ISA_SSE42: return sse42;
    case EMBREE_ISA_AVX2: return avx2;
    case EMBREE_ISA_AVX512: return avx512;
    default: return 0;
    }
#else
    (void)isa;
    return 0;
#endif
}

int embree_device_config(enum embree_isa isa, uint32_t threads, char *config, size_t size, char *err, size_t errlen)
{
    if (!embree_isa_supported(isa)) {
        str_fmt(err, errlen,
                "this CPU cannot run Embree's %s kernels, which the job's rays use on every node (--embree-isa %s; "
                "a cluster with older CPUs renders with an instruction set they all have, e.g. --embree-isa sse4.2)",
                embree_isa_name(isa), embree_isa_name(isa));
        return -1;
    }
    snprintf(config, size, "threads=%u,isa=%s", threads, embree_isa_name(isa));
    return 0;
}

/* A triangle geometry for mesh m: its own positions, or num_steps vertex sets in steps. */
static RTCGeometry new_triangles(struct accel *a, const struct mesh *m, const float *steps, uint32_t num_steps)
{
    RTCGeometry g = rtcNewGeometry(a->device, RTC_GEOMETRY_TYPE_TRIANGLE);
    unsigned *ib = rtcSetNewGeometryBuffer(g, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3, 3 * sizeof(unsigned),
                                           m->num_triangles);
    if (!ib) {
        rtcReleaseGeometry(g);
        return NULL;
    }
    memcpy(ib, m->indices, 3 * sizeof(unsigned) * m->num_triangles);
    if (!steps) {
        /* Embree allocates padded buffers itself (it may read 16 bytes past the last vertex). */
        float *vb = rtcSetNewGeometryBuffer(g, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, 3 * sizeof(float),
                                            m->num_vertices);
        if (!vb) {
            rtcReleaseGeometry(g);
            return NULL;
        }
        memcpy(vb, m->positions, 3 * sizeof(float) * m->num_vertices);
    } else {
        size_t nf = 3 * (size_t)m->num_vertices;
        if (num_steps > 1)
            rtcSetGeometryTimeStepCount(g, num_steps);
        for (uint32_t k = 0; k < num_steps; k++)
            rtcSetSharedGeometryBuffer(g, RTC_BUFFER_TYPE_VERTEX, k, RTC_FORMAT_FLOAT3, steps,
                                       k * nf * sizeof(float), 3 * sizeof(float), m->num_vertices);
    }
    rtcCommitGeometry(g);
    return g;
}

/* A child scene holding g (released here), instanced with the keys over [t0, t1]. */
static void add_instance(struct accel *a, struct accel_motion *mo, RTCGeometry g, const struct motion_key *keys,
                         uint32_t num_keys, double t0, double t1)
{
    mo->child = rtcNewScene(a->device);
    rtcSetSceneBuildQuality(mo->child, RTC_BUILD_QUALITY_HIGH);
    rtcAttachGeometry(mo->child, g);
    rtcReleaseGeometry(g);
    rtcCommitScene(mo->child);
    RTCGeometry inst = rtcNewGeometry(a->device, RTC_GEOMETRY_TYPE_INSTANCE);
    rtcSetGeometryInstancedScene(inst, mo->child);
    int still = motion_keys_still(keys, num_keys, t0, t1);
    uint32_t steps = still ? 1 : motion_step_count(&keys[0].time, sizeof *keys, num_keys, t0, t1);
    if (steps > 1) {
        rtcSetGeometryTimeStepCount(inst, steps);
        a->has_motion = 1;
    }
    for (uint32_t k = 0; k < steps; k++) {
        struct motion_key key;
        motion_key_at(keys, num_keys, steps > 1 ? t0 + (t1 - t0) * k / (steps - 1) : t0, &key);
        struct RTCQuaternionDecomposition qd;
        rtcInitQuaternionDecomposition(&qd);
        rtcQuaternionDecompositionSetScale(&qd, key.scale.x, key.scale.y, key.scale.z);
        rtcQuaternionDecompositionSetQuaternion(&qd, key.quat[0], key.quat[1], key.quat[2], key.quat[3]);
        rtcQuaternionDecompositionSetTranslation(&qd, key.translate.x, key.translate.y, key.translate.z);
        rtcSetGeometryTransformQuaternion(inst, k, &qd);
    }
    rtcCommitGeometry(inst);
    mo->instance = inst; /* our reference, for transforms at hit time */
}

static unsigned attach_top(struct accel *a, RTCGeometry g, uint32_t mesh, uint32_t sphere)
{
    unsigned id = rtcAttachGeometry(a->scene, g);
    CHECK(id == a->num_top);
    a->top_mesh[id] = mesh;
    a->top_sphere[id] = sphere;
    a->num_top++;
    return id;
}

static int build_meshes(struct accel *a, const struct scene *s, double t0, double t1, char *err, size_t errlen)
{
    for (uint32_t i = 0; i < s->num_meshes; i++) {
        const struct mesh *m = &s->meshes[i];
        struct accel_motion *mo = a->mesh_motion ? &a->mesh_motion[i] : NULL;
        const float *steps = NULL;
        uint32_t num_steps = 0;
        if (m->num_frames >= 2) {
            size_t nf = 3 * (size_t)m->num_vertices;
            num_steps = motion_frames_still(m->frame_positions, m->frame_times, m->num_frames, m->num_vertices, t0, t1)
                            ? 1
                            : motion_step_count(m->frame_times, sizeof(float), m->num_frames, t0, t1);
            mo->steps = mem_alloc(sizeof(float) * (nf * num_steps + 4)); /* Embree reads 16 bytes past */
            memset(mo->steps + nf * num_steps, 0, 4 * sizeof(float));
            for (uint32_t k = 0; k < num_steps; k++)
                motion_frames_at(m->positions, m->frame_positions, m->frame_times, m->num_frames, m->num_vertices,
                                 num_steps > 1 ? t0 + (t1 - t0) * k / (num_steps - 1) : t0, mo->steps + k * nf);
            mo->num_steps = num_steps;
            steps = mo->steps;
            a->has_motion |= num_steps > 1;
        }
        RTCGeometry g = new_triangles(a, m, steps, num_steps);
        if (!g) {
            str_fmt(err, errlen, "embree: cannot allocate buffers for mesh \"%s\"", m->name);
            return -1;
        }
        if (m->num_keys > 0) {
            add_instance(a, mo, g, m->keys, m->num_keys, t0, t1);
            attach_top(a, mo->instance, i, UINT32_MAX);
        } else {
            attach_top(a, g, i, UINT32_MAX);
            rtcReleaseGeometry(g);
        }
    }
    return 0;
}

static RTCGeometry new_spheres(struct accel *a, const struct scene *s, const uint32_t *which, uint32_t n)
{
    RTCGeometry g = rtcNewGeometry(a->device, RTC_GEOMETRY_TYPE_SPHERE_POINT);
    float *vb = rtcSetNewGeometryBuffer(g, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT4, 4 * sizeof(float), n);
    if (!vb) {
        rtcReleaseGeometry(g);
        return NULL;
    }
    for (uint32_t k = 0; k < n; k++) {
        const struct sphere *sp = &s->spheres[which[k]];
        vb[4 * k + 0] = sp->center.x;
        vb[4 * k + 1] = sp->center.y;
        vb[4 * k + 2] = sp->center.z;
        vb[4 * k + 3] = sp->radius;
    }
    rtcCommitGeometry(g);
    return g;
}

static int build_spheres(struct accel *a, const struct scene *s, double t0, double t1, char *err, size_t errlen)
{
    uint32_t n_still = 0;
    a->still_sphere = mem_alloc(sizeof(uint32_t) * (s->num_spheres ? s->num_spheres : 1));
    for (uint32_t i = 0; i < s->num_spheres; i++)
        if (s->spheres[i].num_keys == 0)
            a->still_sphere[n_still++] = i;
    if (n_still > 0) {
        RTCGeometry g = new_spheres(a, s, a->still_sphere, n_still);
        if (!g) {
            str_fmt(err, errlen, "embree: cannot allocate the sphere buffer");
            return -1;
        }
        attach_top(a, g, a->sphere_geom, UINT32_MAX);
        rtcReleaseGeometry(g);
    }
    for (uint32_t i = 0; i < s->num_spheres; i++) {
        if (s->spheres[i].num_keys == 0)
            continue;
        RTCGeometry g = new_spheres(a, s, &i, 1);
        if (!g) {
            str_fmt(err, errlen, "embree: cannot allocate the buffer of sphere \"%s\"", s->spheres[i].name);
            return -1;
        }
        struct accel_motion *mo = &a->sphere_motion[i];
        add_instance(a, mo, g, s->spheres[i].keys, s->spheres[i].num_keys, t0, t1);
        attach_top(a, mo->instance, a->sphere_geom, i);
    }
    return 0;
}

int accel_init(struct accel *a, const struct scene *s, uint32_t frame, uint32_t threads, char *err,
                size_t errlen)
{
    memset(a, 0, sizeof *a);
    char config[64];
    if (embree_device_config(s->settings.embree_isa, threads, config, sizeof config, err, errlen) != 0)
        return -1;
    a->device = rtcNewDevice(config);
    if (!a->device) {
        str_fmt(err, errlen, "embree: cannot create device (error %d)", (int)rtcGetDeviceError(NULL));
        return -1;
    }
    rtcSetDeviceErrorFunction(a->device, accel_on_error, NULL);
    a->scene = rtcNewScene(a->device);
    rtcSetSceneBuildQuality(a->scene, RTC_BUILD_QUALITY_HIGH);
    rtcSetSceneFlags(a->scene, RTC_SCENE_FLAG_NONE);
    a->sphere_geom = s->num_meshes;
    a->num_spheres = s->num_spheres;
    size_t max_top = (size_t)s->num_meshes + s->num_spheres + 1;
    a->top_mesh = mem_alloc(sizeof(uint32_t) * max_top);
    a->top_sphere = mem_alloc(sizeof(uint32_t) * max_top);
    for (uint32_t i = 0; i < s->num_meshes; i++)
        if (s->meshes[i].num_keys > 0 || s->meshes[i].num_frames >= 2) {
            a->mesh_motion = mem_calloc(s->num_meshes, sizeof *a->mesh_motion);
            break;
        }
    for (uint32_t i = 0; i < s->num_spheres; i++)
        if (s->spheres[i].num_keys > 0) {
            a->sphere_motion = mem_calloc(s->num_spheres, sizeof *a->sphere_motion);
            break;
        }
    a->still_tri = mem_calloc((size_t)s->num_meshes + 1, 1);
    for (uint32_t i = 0; i < s->num_meshes; i++)
        a->still_tri[i] = s->meshes[i].num_keys == 0 && s->meshes[i].num_frames < 2;
    a->still_geoms = a->mesh_motion || a->sphere_motion ? 0 : a->sphere_geom;
    /* The shutter of this frame; an empty or inverted one freezes everything at its open. */
    double t0 = (double)frame + s->camera.shutter_open, t1 = (double)frame + s->camera.shutter_close;
    if (!(t1 > t0))
        t1 = t0;
    if (build_meshes(a, s, t0, t1, err, errlen) != 0 || build_spheres(a, s, t0, t1, err, errlen) != 0) {
        accel_fini(a);
        return -1;
    }
    rtcCommitScene(a->scene);
    enum RTCError e = rtcGetDeviceError(a->device);
    if (e != RTC_ERROR_NONE) {
        str_fmt(err, errlen, "embree: scene build failed (error %d)", (int)e);
        accel_fini(a);
        return -1;
    }
    a->desc = s;
    a->packets_exact = s->num_spheres == 0 && !a->mesh_motion && !a->has_motion;
    a->face_normals = mem_calloc(s->num_meshes ? s->num_meshes : 1, sizeof *a->face_normals);
    for (uint32_t i = 0; i < s->num_meshes; i++) {
        const struct mesh *m = &s->meshes[i];
        a->face_normals[i] = mem_alloc(sizeof(vec3) * (m->num_triangles ? m->num_triangles : 1));
        for (uint32_t t = 0; t < m->num_triangles; t++) {
            const float *pa = &m->positions[3 * m->indices[3 * t]], *pb = &m->positions[3 * m->indices[3 * t + 1]],
                        *pc = &m->positions[3 * m->indices[3 * t + 2]];
            vec3 va = v3(pa[0], pa[1], pa[2]);
            a->face_normals[i][t] =
                v3_normalize(v3_cross(v3_sub(v3(pb[0], pb[1], pb[2]), va), v3_sub(v3(pc[0], pc[1], pc[2]), va)));
        }
    }
    return 0;
}

static void free_motion(struct accel_motion *mo, uint32_t n)
{
    for (uint32_t i = 0; mo && i < n; i++) {
        if (mo[i].instance)
            rtcReleaseGeometry(mo[i].instance);
        if (mo[i].child)
            rtcReleaseScene(mo[i].child);
        free(mo[i].steps);
    }
    free(mo);
}

void accel_fini(struct accel *a)
{
    /* The top-level scene first: it references the instances and their scenes. */
    if (a->scene)
        rtcReleaseScene(a->scene);
    free_motion(a->mesh_motion, a->sphere_geom);
    free_motion(a->sphere_motion, a->num_spheres);
    if (a->device)
        rtcReleaseDevice(a->device);
    free(a->top_mesh);
    free(a->top_sphere);
    free(a->still_sphere);
    free(a->still_tri);
    for (uint32_t i = 0; a->face_normals && i < a->sphere_geom; i++)
        free(a->face_normals[i]);
    free(a->face_normals);
    memset(a, 0, sizeof *a);
}

/* A packet as Embree's RTCRayN / RTCRayHitN of width w (4, 8 or 16): arrays of w floats or
 * ints in the order of RTCRayHit16's fields, so one layout serves every width.
 * RTCRayNt: org xyz, tnear, dir xyz, time, tfar, mask, id, flags; then RTCHitNt: Ng xyz,
 * u, v, primID, geomID, instID[1]. Floats and ints share it (a union: C11 type punning). */
#define PK_ALIGN 64
union packet {
    _Alignas(PK_ALIGN) float f[20 * 16];
    unsigned u[20 * 16];
};

/* Fewer rays than these go one by one: a 4-wide packet costs Embree about as much as 2.5
 * closest-hit rays or 3 occlusion rays (callgrind, docs/benchmarks.md). */
#define PACKET_MIN_HITS 3
#define PACKET_MIN_OCCLUDED 4

/* The narrowest packet width holding n rays. */
static inline uint32_t packet_width(uint32_t n)
{
    return n <= 4 ? 4 : n <= 8 ? 8 : 16;
}

/* Sets up a coherent query of n rays in (0, tmax): the context, the rays of the narrowest
 * packet that holds them and its valid mask (lanes past n repeat ray 0, masked off).
 * Returns the packet's width. */
static inline __attribute__((always_inline)) uint32_t packet_fill(struct RTCIntersectContext *ctx, union packet *pk,
                                                                  int *valid, uint32_t n, const vec3 *org,
                                                                  const vec3 *dir, const float *time01, float tmax)
{
    rtcInitIntersectContext(ctx);
    ctx->flags = RTC_INTERSECT_CONTEXT_FLAG_COHERENT;
    const uint32_t w = packet_width(n);
    float *f = pk->f;
    unsigned *ui = pk->u;
    for (uint32_t k = 0; k < w; k++) {
        uint32_t i = k < n ? k : 0;
        valid[k] = k < n && accel_ray_ok_(org[i], dir[i]) ? -1 : 0; /* an untraceable ray misses */
        f[0 * w + k] = org[i].x, f[1 * w + k] = org[i].y, f[2 * w + k] = org[i].z;
        f[3 * w + k] = 0.0f;
        f[4 * w + k] = dir[i].x, f[5 * w + k] = dir[i].y, f[6 * w + k] = dir[i].z;
        f[7 * w + k] = time01[i];
        f[8 * w + k] = tmax;
        ui[9 * w + k] = 0xffffffffu;
        ui[10 * w + k] = k;
        ui[11 * w + k] = 0;
    }
    return w;
}

void accel_intersect_packet(const struct accel *a, uint32_t n, const vec3 *org, const vec3 *dir,
                            const float *time01, struct accel_hit *hits, int *found)
{
    CHECK(n >= 1 && n <= ACCEL_PACKET);
    if (n < PACKET_MIN_HITS) {
        for (uint32_t k = 0; k < n; k++)
            found[k] = accel_intersect(a, org[k], dir[k], INFINITY, time01[k], &hits[k]);
        return;
    }
    struct RTCIntersectContext ctx;
    union packet pk;
    _Alignas(PK_ALIGN) int valid[16];
    const uint32_t w = packet_fill(&ctx, &pk, valid, n, org, dir, time01, INFINITY);
    float *f = pk.f;
    unsigned *ui = pk.u;
    for (uint32_t k = 0; k < w; k++)
        ui[18 * w + k] = ui[19 * w + k] = RTC_INVALID_GEOMETRY_ID;
    if (w == 4)
        rtcIntersect4(valid, a->scene, &ctx, (struct RTCRayHit4 *)&pk);
    else if (w == 8)
        rtcIntersect8(valid, a->scene, &ctx, (struct RTCRayHit8 *)&pk);
    else
        rtcIntersect16(valid, a->scene, &ctx, (struct RTCRayHit16 *)&pk);
    for (uint32_t k = 0; k < n; k++) {
        found[k] = ui[18 * w + k] != RTC_INVALID_GEOMETRY_ID;
        if (found[k])
            accel_hit_from_embree_(a, ui[18 * w + k], ui[19 * w + k], ui[17 * w + k], f[8 * w + k], f[15 * w + k],
                                   f[16 * w + k], &hits[k]);
    }
}

void accel_occluded_packet(const struct accel *a, uint32_t n, const vec3 *org, const vec3 *dir, float tmax,
                           const float *time01, int *occluded)
{
    CHECK(n >= 1 && n <= ACCEL_PACKET);
    if (n < PACKET_MIN_OCCLUDED) {
        for (uint32_t k = 0; k < n; k++)
            occluded[k] = accel_occluded(a, org[k], dir[k], tmax, time01[k]);
        return;
    }
    struct RTCIntersectContext ctx;
    union packet pk;
    _Alignas(PK_ALIGN) int valid[16];
    const uint32_t w = packet_fill(&ctx, &pk, valid, n, org, dir, time01, tmax);
    if (w == 4)
        rtcOccluded4(valid, a->scene, &ctx, (struct RTCRay4 *)&pk);
    else if (w == 8)
        rtcOccluded8(valid, a->scene, &ctx, (struct RTCRay8 *)&pk);
    else
        rtcOccluded16(valid, a->scene, &ctx, (struct RTCRay16 *)&pk);
    for (uint32_t k = 0; k < n; k++) /* a lane the packet could not take goes alone, as accel_occluded takes it */
        occluded[k] = valid[k] ? pk.f[8 * w + k] < 0.0f : accel_occluded(a, org[k], dir[k], tmax, time01[k]);
}

int accel_object_xform_slow_(const struct accel *a, uint32_t geom, uint32_t prim, float time01, struct xform *out)
{
    const struct accel_motion *mo = NULL;
    if (geom == a->sphere_geom)
        mo = a->sphere_motion ? &a->sphere_motion[prim] : NULL;
    else
        mo = a->mesh_motion ? &a->mesh_motion[geom] : NULL;
    if (!mo || !mo->instance)
        return 0;
    float m[12];
    rtcGetGeometryTransform(mo->instance, time01, RTC_FORMAT_FLOAT3X4_ROW_MAJOR, m);
    memcpy(out->m, m, sizeof m);
    return 1;
}

void accel_attach_user_geometry(RTCDevice dev, RTCScene s, uint32_t n, void *user, RTCBoundsFunction bounds,
                                RTCIntersectFunctionN intersect)
{
    RTCGeometry g = rtcNewGeometry(dev, RTC_GEOMETRY_TYPE_USER);
    rtcSetGeometryUserPrimitiveCount(g, n);
    rtcSetGeometryUserData(g, user);
    rtcSetGeometryBoundsFunction(g, bounds, NULL);
    rtcSetGeometryIntersectFunction(g, intersect);
    rtcCommitGeometry(g);
    rtcAttachGeometry(s, g);
    rtcReleaseGeometry(g);
}
