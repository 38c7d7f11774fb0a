/* Analytic motion blur (camera.motion_blur "analytic"): for one camera ray, with its
 * pixel and lens point fixed, the times across the shutter at which each moving triangle
 * or sphere covers the ray, resolved by depth into pieces that tile the shutter, grouped
 * by visible object into strata that the integrator shades once each, weighted by the
 * shutter curve's integral over the stratum. The mv_* functions are pure geometry (no
 * Embree; tests call them); motion_vis_* finds the candidates with Embree. Callers:
 * render_job.c (build), integrator.c (strata per camera sample), tests. docs/motion.md. */
#ifndef BRUME_MOTION_VIS_H
#define BRUME_MOTION_VIS_H
#include <stdint.h>
#include "render/accel.h"
#include "scene/camera.h"

#define MV_MAX_IV 4          /* coverage intervals of one candidate segment at most */
#define MV_MAX_STRATA 8      /* shaded strata per camera sample at most (the rest merge) */
#define MV_STILL UINT32_MAX  /* a piece where no moving surface is in front */
#define MV_MAX_ANGLE_DEG 4.0 /* rotation per linear segment at most (docs/motion.md: the bound) */

/* One moving triangle (or sphere) over one linear segment [ta, tb] of the shutter (time01):
 * positions relative to the ray origin at ta (p0) and tb (p1), linear in between. A
 * sphere has its centre in p0[0] / p1[0] and its radius in p0[1][0] / p1[1][0]. */
struct mv_cand {
    uint32_t obj;        /* stratum key: mesh index, or num_meshes + sphere index */
    uint32_t prim, seg;  /* triangle and segment (the order of candidates) */
    int sphere;
    double ta, tb;
    double p0[3][3], p1[3][3];
    uint32_t niv;        /* coverage intervals (time01, disjoint, increasing) */
    double iv[MV_MAX_IV][2];
};

/* A time interval (time01) of the shutter and the candidate visible in it (or MV_STILL). */
struct mv_piece {
    double t0, t1;
    uint32_t cand;
};

/* What the integrator shades: n strata, each at time01[k] with weight[k] (the shutter
 * curve's integral over the stratum; the weights sum to 1). n == 1: shade the camera
 * sample as it is. */
struct mv_strata {
    uint32_t n;
    float time01[MV_MAX_STRATA];
    double weight[MV_MAX_STRATA];
};

/* Real roots of a s^2 + b s + c (sorted; a double root once), without cancellation:
 * q = -(b + sign(b) sqrt(b^2 - 4ac)) / 2, roots q / a and c / q; a == 0 is linear. */
int mv_quadratic_roots(double a, double b, double c, double r[2]);
/* Coverage of the ray from the origin along unit d by c over its segment: fills c->iv,
 * c->niv (intervals where the ray meets the surface in front of its origin; an interval
 * of zero length when ta == tb and it covers). */
void mv_cand_coverage(struct mv_cand *c, const double d[3]);
/* Distance along d to c's surface at time01 t in [ta, tb] (INFINITY when it is behind the
 * origin or parallel to the ray). */
double mv_cand_depth(const struct mv_cand *c, const double d[3], double t);
/* Nearest surface over the shutter: the pieces (at most max, merged where the same
 * candidate continues) that tile [0, 1] from the candidates' coverage; still_depth is the
 * nearest still surface (INFINITY: none), which hides what lies behind it. Returns the
 * count, or 0 when max is too small. */
uint32_t mv_resolve(const struct mv_cand *c, uint32_t nc, const double d[3], double still_depth,
                    struct mv_piece *out, uint32_t max);
/* The shutter curve's CDF at time01 t (camera.c's trapezoid; the box when ramp is 0). */
double mv_shutter_cdf(double ramp, double t);
/* Strata from pieces: pieces of the same object (or MV_STILL) form one stratum; its time
 * is drawn with u in [0, 1) inside its pieces with the shutter curve's density. */
void mv_strata_from_pieces(const struct camera *cam, const struct mv_piece *p, uint32_t np, const struct mv_cand *c,
                           float u, struct mv_strata *st);

struct motion_vis;
/* The candidate structure for frame `frame`, or NULL when analytic visibility does not
 * apply (setting "sampled", nothing moves, the shutter is closed, the camera moves: then
 * the ray itself depends on time, and the log says so). */
struct motion_vis *motion_vis_new(const struct accel *a, const struct scene *s, const struct camera *cam,
                                  uint32_t frame);
void motion_vis_free(struct motion_vis **mv);
/* The strata of camera sample cs (u: its uniform time sample, before the shutter curve).
 * Pure function of the ray and u. Returns st->n. */
uint32_t motion_vis_strata(const struct motion_vis *mv, const struct camera *cam, const struct camera_sample *cs,
                           float u, struct mv_strata *st);

#endif
