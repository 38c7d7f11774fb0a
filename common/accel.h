/* Ray queries through Embree 3: one device and one static scene per job, built from the
 * flat scene (meshes as triangle geometries, all spheres in one sphere-point geometry),
 * committed once and then shared read-only by every render thread. Geometry ids: mesh i
 * is geometry i; spheres are geometry num_meshes, primitive = sphere index. */
#ifndef BRUME_ACCEL_H
#define BRUME_ACCEL_H
#include <stddef.h>
#include <stdint.h>
#include <embree3/rtcore.h>
#include "scene.h"
#include "vec.h"

struct accel {
    RTCDevice device;
    RTCScene scene;
    uint32_t sphere_geom;   /* == num_meshes; valid when the scene has spheres */
};

struct accel_hit {
    float t;
    uint32_t geom, prim;
    float u, v;     /* barycentrics for triangles */
    vec3 ng;        /* geometric normal, unnormalised, as Embree reports it */
};

/* threads: Embree's build threads (0 = all cores). Returns 0 or -1 with err. */
int accel_build(struct accel *a, const struct scene *scene, uint32_t threads, char *err, size_t errlen);
void accel_free(struct accel *a);

/* Closest hit in (0, tmax); returns 1 on a hit. */
int accel_intersect(const struct accel *a, vec3 org, vec3 dir, float tmax, struct accel_hit *hit);
/* 1 if anything blocks the segment (0, tmax). */
int accel_occluded(const struct accel *a, vec3 org, vec3 dir, float tmax);

#endif
