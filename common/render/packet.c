/* Camera rays of one pixel traced as an Embree packet (see packet.h). */
#include "render/packet.h"
#include <stdlib.h>
#include <string.h>

void camera_packet_trace(const struct render_job *job, struct sampler_pixel *sp, uint32_t px, uint32_t py,
                         uint32_t s0, uint32_t n, struct camera_packet *cp)
{
    vec3 org[ACCEL_PACKET], dir[ACCEL_PACKET];
    float time01[ACCEL_PACKET];
    cp->n = n;
    for (uint32_t k = 0; k < n; k++) {
        cp->smp[k] = sampler_start_pixel(sp, s0 + k);
        camera_generate(&job->camera, &cp->smp[k], job->frame, px, py, &cp->cs[k]);
        org[k] = cp->cs[k].o;
        dir[k] = cp->cs[k].d;
        time01[k] = cp->cs[k].time01;
    }
    accel_intersect_packet(&job->accel, n, org, dir, time01, cp->hit, cp->found);
}
