/* Adaptive rendering to a target error (docs/adaptive.md): which tiles get which passes.
 * A frame renders in rounds; in each round some tiles get more passes (units (tile, pass)
 * of a fixed pass size), and every decision is taken when the round's units are all
 * folded, from per-tile sums that depend only on the folded passes, never on timing, so
 * the passes each tile gets (and the image) are the same for any worker count or arrival
 * order, and after a journal replay. Pure: no I/O, no clock. Called by master/master.c;
 * tested by tests/unit/test_adapt.c. */
#ifndef BRUME_ADAPT_H
#define BRUME_ADAPT_H
#include <stdint.h>

#define ADAPT_FIRST_PASSES 4u   /* passes every tile gets before its batch-means estimate counts... */
#define ADAPT_FIRST_SPP 32u     /* ...or as many as make these samples per pixel (adapt_set_pass_spp) */
#define ADAPT_GROWTH 2u         /* a tile's passes at most double per round: early estimates are rough */
#define ADAPT_MAX_HISTORY 256u
/* The pooled estimate (adapt_pool): a tile's variance is shrunk toward its neighbours' as
 * if they were ADAPT_PRIOR_DOF degrees of freedom of evidence; and the rounds aim below the
 * target by ADAPT_CONFIDENCE_Z standard deviations of the image estimate's own error. */
#define ADAPT_PRIOR_DOF 4.0
#define ADAPT_CONFIDENCE_Z 1.0
/* The uniform fallback: when the pilot (round 0) predicts that the allocation would need
 * more than this fraction of the work of uniform passes to the same aim
 * (adapt_predicted_ratio), the frame renders uniform passes instead (adapt_uniform): a
 * saving that small does not pay for what the work leaves out (an adaptive render's units,
 * and its noisy blocks' dearer rays, docs/adaptive.md). */
#define ADAPT_UNIFORM_GAIN 0.8
/* The per-pixel bound (--pixel-error, adapt_set_pixel_error): a pixel's relative error is
 * its standard error over max(its mean, ADAPT_PIXEL_FLOOR x the image's mean), so a
 * near-black pixel is held to an absolute error, not to a share of its own tiny value
 * (docs/adaptive.md, "A per-pixel bound"). */
#define ADAPT_PIXEL_FLOOR 0.1

/* A tile's state as the rounds see it. The master's "tiles" here are the pixel blocks of
 * the render's tiles (render/tile.h: a unit renders some blocks of a tile), in a grid of
 * tiles_x blocks a row; a block past the image's edge has no pixels and gets nothing. */
struct adapt_tile {
    uint32_t pixels;
    uint32_t passes;        /* passes released so far (its units 0..passes-1) */
    double sum_var;         /* over its pixels: variance of the pixel mean (mean of R, G, B), after `passes` */
    double sum_var_sq;      /* over its pixels: v^2 / (q + 1), v a pixel's variance from q stream means (an
                             * unbiased estimate of sigma^4 / (q - 1)), so
                             * that sum_var has sum_var^2 / sum_var_sq degrees of freedom (Welch-Satterthwaite) */
    double sum_mean;        /* over its pixels: the pixel mean (mean of R, G, B) */
    double worst;           /* per-pixel bound: the largest squared relative error of its pixels
                             * (variance of the mean over max(mean, adapt_pixel_floor)^2) */
    uint32_t over;          /* per-pixel bound: its pixels whose squared relative error is above the bound's square */
    uint64_t samples, rays; /* traced so far (deterministic: the cost measure, never time) */
};

struct adapt {
    uint32_t num_tiles, tiles_x, max_passes, max_rounds;
    uint32_t step;          /* a tile's passes are a multiple of step (the sampler's streams) */
    double target;          /* relRMSE to reach; 0: none (time limit or max_rounds only) */
    double pixel_error;     /* every pixel's relative standard error to reach (adapt_set_pixel_error); 0: none */
    uint64_t pixels_over;   /* per-pixel bound, at the last decision: pixels above it... */
    uint64_t pixels_over_capped; /* ...of them in blocks at max_passes... */
    double worst;           /* ...and the largest relative error of a pixel (not squared) */
    int met;                /* at the last decision: the target (if any) and the bound (if any) held */
    uint32_t round;         /* rounds released so far (round 0 = the first passes) */
    uint32_t outstanding;   /* units of the current round not yet folded */
    int finished;           /* no more passes: the frame ends once outstanding is 0 */
    double est;             /* the image's estimated relRMSE at the last decision (pooled tiles, adapt_pool) */
    double est_raw;         /* the same from the tiles' own variances (what the EXR's channels say) */
    double dof;             /* the effective degrees of freedom of est's variance */
    double aim;             /* what est must reach: the target less est's own uncertainty */
    double prior_dof, confidence_z; /* ADAPT_PRIOR_DOF, ADAPT_CONFIDENCE_Z (0, 0: the tiles' own figures) */
    int uniform;            /* the pilot chose uniform passes: every tile at one level from round 1 on */
    double predicted;       /* at the pilot: adapt_predicted_ratio (0 before, or when round 0 was the last) */
    uint32_t first_passes;  /* round 0's passes (before rounding up to step) */
    uint32_t num_history;   /* (samples, estimate) at each decision: the ETA's fit */
    double hist_samples[ADAPT_MAX_HISTORY], hist_est[ADAPT_MAX_HISTORY];
    struct adapt_tile *tiles;
};

/* Tiles in rows of tiles_x (neighbours for adapt_pool); max_passes (>= 2) passes at most per
 * tile; pixels[t] the pixel count of tile t; step:
 * passes go in multiples of it (SAMPLER_STREAMS, so that every stream of a tile holds as
 * many passes and the batch means weigh them equally), 1 when max_passes is not a
 * multiple of it. */
struct adapt *adapt_new(uint32_t num_tiles, uint32_t tiles_x, const uint32_t *pixels, uint32_t max_passes, uint32_t step,
                        double target, uint32_t max_rounds);
void adapt_free(struct adapt **a);
/* A per-pixel bound P (0: none): the frame goes on until every pixel's relative standard
 * error (adapt_tile.worst, .over: the caller fills them before each decision) is at most
 * P, or its block is at max_passes; with a target too, both must hold. */
void adapt_set_pixel_error(struct adapt *a, double pixel_error);
/* The floor of the per-pixel bound's scale: ADAPT_PIXEL_FLOOR x the image's mean pixel (the
 * tiles' sum_mean over their pixels); 0 for a black image. */
double adapt_pixel_floor(const struct adapt *a);
/* The per-pixel bound's rule: a tile whose worst pixel's squared relative error w[t] after
 * m[t] passes is above bound^2 gets, under the 1/n model, the passes that bring it to the
 * bound, m w / bound^2, rounded up to a multiple of step, at most growth x m[t] and
 * max_passes; n[t] (what another rule gave, >= m[t]) is raised to that, never lowered.
 * Returns the passes added to n. */
uint64_t adapt_pixel_bound(uint32_t num_tiles, const double *w, const uint32_t *m, double bound, uint32_t max_passes,
                           uint32_t growth, uint32_t step, uint32_t *n);
/* Passes of spp_per_pass samples: round 0 gives ceil(ADAPT_FIRST_SPP / spp_per_pass) passes
 * (at least 1) instead of ADAPT_FIRST_PASSES, so that a high --spp cap (which makes the
 * passes larger, at most PROTO_MAX_PASSES of them) does not make round 0 overshoot. */
void adapt_set_pass_spp(struct adapt *a, uint32_t spp_per_pass);
/* A new frame: round 0, every tile first_passes passes (rounded up to a multiple of step,
 * at most max_passes). The caller releases units (t, p) for p < tiles[t].passes. */
void adapt_begin(struct adapt *a);
/* The allocation rule. Tiles of sum variance v[t] (pixel variances of the mean summed,
 * after m[t] passes), cost per pass c[t] > 0: the fewest-cost passes n[t] >= m[t] (at most
 * max_passes) with sum_t v[t] m[t] / n[t] <= budget, by Lagrange: n[t] proportional to
 * sqrt(v[t] m[t] / c[t]) (the error per unit cost equalised), each at most growth x m[t],
 * rounded to a multiple of step: down, then up for the tiles whose step removes the most
 * variance per cost until the budget is met (so the projection lands on the budget, not a
 * step past it in every tile). m[t] and max_passes are multiples of step. Writes
 * n; returns the passes added. */
uint64_t adapt_allocate(uint32_t num_tiles, const double *v, const double *c, const uint32_t *m, double budget,
                        uint32_t max_passes, uint32_t growth, uint32_t step, uint32_t *n);
/* Uniform passes to the budget: every tile that has passes (m[t] > 0: one not rendered
 * keeps 0) gets one level n, the fewest multiple of step, at least every m[t], with sum_t
 * v[t] m[t] / max(n, m[t]) <= budget, at most max_passes and growth x the fewest m[t] (the
 * most of those when none meets it). Writes n; returns the passes added. */
uint64_t adapt_uniform(uint32_t num_tiles, const double *v, const uint32_t *m, double budget, uint32_t max_passes,
                       uint32_t growth, uint32_t step, uint32_t *n);
/* From the pilot's tiles (v, c, m as adapt_allocate's: the pooled variances the rounds
 * allocate by): the work (sum c n) of the allocation's continuous optimum (no growth limit,
 * no step) over that of one level for every tile meeting the same budget (sum v m / level
 * = budget, at least every m, at most max_passes), over the tiles with m > 0; 1 when
 * nothing is rendered. At most 1 when the budget can be met. Chosen and judged on the same
 * noisy figures, it is below what the rounds reach (docs/adaptive.md). */
double adapt_predicted_ratio(uint32_t num_tiles, const double *v, const double *c, const uint32_t *m, double budget,
                             uint32_t max_passes);
/* The image's estimated relRMSE from the tiles' sums: sqrt(sum var / pixels) / (sum mean /
 * pixels); 0 for a black image. */
double adapt_image_estimate(const struct adapt *a);
/* Tile variances that resist selection: a tile whose own estimate rests on few degrees of
 * freedom (d = sum_var^2 / sum_var_sq: a few bright pixels, or no variance seen at all) is
 * raised toward a prior from its neighbours (the 3x3 tiles around it, or the whole image
 * when they show none): their pooled relative variance (sum var / sum of mean^2 per pixel)
 * times its own mean^2 per pixel. v[t] = max(v_t, (d v_t + K prior) / (d + K)), K =
 * a->prior_dof; dof[t] = d + K. Returns the effective degrees of freedom of sum v
 * (Welch-Satterthwaite). A tile that missed a rare bright path its neighbours found so
 * still gets passes; one whose own pixels show it keeps its figure. */
double adapt_pool(const struct adapt *a, double *v, double *dof);
/* The decision at a round's end (every tile's sums up to date): 1 when a new round is
 * released (tiles' passes raised: the caller releases units [old, new) of each, pass by
 * pass), 0 when the frame is finished (target met, every tile at max_passes, max_rounds
 * reached, or stop set: the time limit). The target is met when the pooled estimate est
 * is at most aim = target / (1 + Z / sqrt(2 dof)): a relRMSE estimated from dof degrees
 * of freedom is off by about 1 / sqrt(2 dof) of itself, Z = a->confidence_z. The
 * allocation aims at the same figure. With a per-pixel bound the frame also waits for every
 * tile's worst pixel (adapt_pixel_bound raises its passes), and a target alone, once met, is
 * met. Round 0's decision (the pilot's) also chooses, for
 * the frame, between the allocation and uniform passes (ADAPT_UNIFORM_GAIN): a->uniform,
 * a->predicted. */
int adapt_decide(struct adapt *a, int stop, uint64_t samples_total);
/* Units that take one tile's blocks from old[b] to now[b] passes (b < nb): one unit per
 * pass p some block gets (old[b] <= p < now[b]), rendering the blocks that get it. */
uint32_t adapt_tile_units(const uint32_t *old, const uint32_t *now, uint32_t nb);
/* A tile holds at most as many units as the frame's passes (its slots); a round that would
 * need more than `room` units for a tile (blocks far apart in passes each need their own)
 * keeps the growing block with the fewest passes (the lowest index first) where it is,
 * again until it fits. Returns the units the round now needs. */
uint32_t adapt_fit_units(const uint32_t *old, uint32_t *now, uint32_t nb, uint32_t room);
/* Samples in all at which the fitted decay of the estimate (est ~ samples^-b over the
 * decisions so far) reaches the aim; 0 when it cannot be told (no target, one point). */
double adapt_eta_samples(const struct adapt *a);

#endif
