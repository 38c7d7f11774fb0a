/* Embree 3 scene building and ray queries (see accel.h). Embree errors go into the
 * project log through the device error callback. The scene is static and built with
 * high quality: the BVH is built once per job and traced by millions of rays. */
#include "accel.h"
#include "log.h"
#include <string.h>
#include <stdio.h>

static void accel_on_error(void *user, enum RTCError code, const char *str)
{
    (void)user;
    log_error("embree: error %d: %s", (int)code, str ? str : "(no message)");
}

int accel_build(struct accel *a, const struct scene *s, uint32_t threads, char *err, size_t errlen)
{
    memset(a, 0, sizeof *a);
    char config[64];
    snprintf(config, sizeof config, "threads=%u", threads);
    a->device = rtcNewDevice(config);
    if (!a->device) {
        str_fmt(err, errlen, "embree: cannot create device (error %d)", (int)rtcGetDeviceError(NULL));
        return -1;
    }
    rtcSetDeviceErrorFunction(a->device, accel_on_error, NULL);
    a->scene = rtcNewScene(a->device);
    rtcSetSceneBuildQuality(a->scene, RTC_BUILD_QUALITY_HIGH);
    rtcSetSceneFlags(a->scene, RTC_SCENE_FLAG_NONE);

    for (uint32_t i = 0; i < s->num_meshes; i++) {
        const struct mesh *m = &s->meshes[i];
        RTCGeometry g = rtcNewGeometry(a->device, RTC_GEOMETRY_TYPE_TRIANGLE);
        /* Embree allocates padded buffers itself (it may read 16 bytes past the last vertex). */
        float *vb = rtcSetNewGeometryBuffer(g, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3,
                                            3 * sizeof(float), m->num_vertices);
        unsigned *ib = rtcSetNewGeometryBuffer(g, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3,
                                               3 * sizeof(unsigned), m->num_triangles);
        if (!vb || !ib) {
            rtcReleaseGeometry(g);
            str_fmt(err, errlen, "embree: cannot allocate buffers for mesh \"%s\"", m->name);
            accel_free(a);
            return -1;
        }
        memcpy(vb, m->positions, 3 * sizeof(float) * m->num_vertices);
        memcpy(ib, m->indices, 3 * sizeof(unsigned) * m->num_triangles);
        rtcCommitGeometry(g);
        unsigned id = rtcAttachGeometry(a->scene, g);
        rtcReleaseGeometry(g);
        CHECK(id == i);
    }
    a->sphere_geom = s->num_meshes;
    if (s->num_spheres > 0) {
        RTCGeometry g = rtcNewGeometry(a->device, RTC_GEOMETRY_TYPE_SPHERE_POINT);
        float *vb = rtcSetNewGeometryBuffer(g, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT4,
                                            4 * sizeof(float), s->num_spheres);
        if (!vb) {
            rtcReleaseGeometry(g);
            str_fmt(err, errlen, "embree: cannot allocate the sphere buffer");
            accel_free(a);
            return -1;
        }
        for (uint32_t i = 0; i < s->num_spheres; i++) {
            vb[4 * i + 0] = s->spheres[i].center.x;
            vb[4 * i + 1] = s->spheres[i].center.y;
            vb[4 * i + 2] = s->spheres[i].center.z;
            vb[4 * i + 3] = s->spheres[i].radius;
        }
        rtcCommitGeometry(g);
        unsigned id = rtcAttachGeometry(a->scene, g);
        rtcReleaseGeometry(g);
        CHECK(id == a->sphere_geom);
    }
    rtcCommitScene(a->scene);
    enum RTCError e = rtcGetDeviceError(a->device);
    if (e != RTC_ERROR_NONE) {
        str_fmt(err, errlen, "embree: scene build failed (error %d)", (int)e);
        accel_free(a);
        return -1;
    }
    return 0;
}

void accel_free(struct accel *a)
{
    if (a->scene)
        rtcReleaseScene(a->scene);
    if (a->device)
        rtcReleaseDevice(a->device);
    memset(a, 0, sizeof *a);
}

int accel_intersect(const struct accel *a, vec3 o, vec3 d, float tmax, struct accel_hit *hit)
{
    struct RTCIntersectContext ctx;
    rtcInitIntersectContext(&ctx);
    struct RTCRayHit rh;
    rh.ray.org_x = o.x, rh.ray.org_y = o.y, rh.ray.org_z = o.z;
    rh.ray.dir_x = d.x, rh.ray.dir_y = d.y, rh.ray.dir_z = d.z;
    rh.ray.tnear = 0.0f;
    rh.ray.tfar = tmax;
    rh.ray.time = 0.0f;
    rh.ray.mask = 0xffffffffu;
    rh.ray.id = 0;
    rh.ray.flags = 0;
    rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
    rh.hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
    rtcIntersect1(a->scene, &ctx, &rh);
    if (rh.hit.geomID == RTC_INVALID_GEOMETRY_ID)
        return 0;
    hit->t = rh.ray.tfar;
    hit->geom = rh.hit.geomID;
    hit->prim = rh.hit.primID;
    hit->u = rh.hit.u;
    hit->v = rh.hit.v;
    hit->ng = v3(rh.hit.Ng_x, rh.hit.Ng_y, rh.hit.Ng_z);
    return 1;
}

int accel_occluded(const struct accel *a, vec3 o, vec3 d, float tmax)
{
    struct RTCIntersectContext ctx;
    rtcInitIntersectContext(&ctx);
    struct RTCRay r;
    r.org_x = o.x, r.org_y = o.y, r.org_z = o.z;
    r.dir_x = d.x, r.dir_y = d.y, r.dir_z = d.z;
    r.tnear = 0.0f;
    r.tfar = tmax;
    r.time = 0.0f;
    r.mask = 0xffffffffu;
    r.id = 0;
    r.flags = 0;
    rtcOccluded1(a->scene, &ctx, &r);
    return r.tfar < 0.0f;
}
