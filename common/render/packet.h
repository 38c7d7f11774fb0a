/* Camera rays traced together: the camera samples of up to ACCEL_PACKET consecutive
 * samples of one pixel, made from their own samplers exactly as a single sample makes
 * them, and their first hits from one Embree packet (rays of one pixel share nearly all of
 * their BVH traversal). The path tracer takes a slot's camera sample and first hit in place
 * of making and tracing its own; the paths' first shadow rays then go as one packet too
 * (integrator.c, render_block), so pixels are bit-identical with and without packets
 * (tests/integration/packets.sh). Used by integrator.c for scenes without media whose
 * accel is packets_exact (triangles only, nothing moving or instanced): Embree's packet
 * kernels round t by an ulp differently for spheres and for motion, which would move a
 * pixel. */
#ifndef BRUME_PACKET_H
#define BRUME_PACKET_H
#include <stdint.h>
#include "render/render_job.h"
#include "scene/sampler.h"

struct camera_packet {
    uint32_t n;
    struct sampler smp[ACCEL_PACKET];
    struct camera_sample cs[ACCEL_PACKET];
    struct accel_hit hit[ACCEL_PACKET];
    int found[ACCEL_PACKET];
};

/* Samples [s0, s0 + n) of pixel (px, py), n <= ACCEL_PACKET, sp set up for the pixel. */
void camera_packet_trace(const struct render_job *job, struct sampler_pixel *sp, uint32_t px, uint32_t py,
                         uint32_t s0, uint32_t n, struct camera_packet *cp);

#endif
