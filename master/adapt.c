/* Adaptive rounds (see adapt.h). The allocation minimises the cost of reaching a variance
 * budget: with a tile's pixel variance of the mean v m / n after n passes (v after m) and a
 * cost c per pass, the Lagrange optimum of sum c n subject to sum v m / n = budget is
 * n = s sqrt(v m / c), tiles held at their current passes or at the cap leaving the free
 * set. Everything is summed in tile order, so the same inputs give the same bits. */
#include "adapt.h"
#include "base/log.h"
#include <math.h>
#include <stdlib.h>
#include <string.h>

struct adapt *adapt_new(uint32_t num_tiles, uint32_t tiles_x, const uint32_t *pixels, uint32_t max_passes, uint32_t step,
                        double target, uint32_t max_rounds)
{
    struct adapt *a = mem_calloc(1, sizeof *a);
    a->num_tiles = num_tiles;
    a->tiles_x = tiles_x && tiles_x <= num_tiles ? tiles_x : (num_tiles ? num_tiles : 1);
    a->max_passes = max_passes;
    a->step = step && max_passes % step == 0 ? step : 1;
    a->target = target;
    a->max_rounds = max_rounds;
    a->prior_dof = ADAPT_PRIOR_DOF;
    a->confidence_z = ADAPT_CONFIDENCE_Z;
    a->first_passes = ADAPT_FIRST_PASSES;
    a->tiles = mem_calloc(num_tiles ? num_tiles : 1, sizeof *a->tiles);
    for (uint32_t t = 0; t < num_tiles; t++)
        a->tiles[t].pixels = pixels[t];
    return a;
}

void adapt_free(struct adapt **ap)
{
    if (!*ap)
        return;
    free((*ap)->tiles);
    free(*ap);
    *ap = NULL;
}

void adapt_set_pixel_error(struct adapt *a, double pixel_error)
{
    a->pixel_error = pixel_error > 0.0 ? pixel_error : 0.0;
}

double adapt_pixel_floor(const struct adapt *a)
{
    double mean = 0.0, pixels = 0.0;
    for (uint32_t t = 0; t < a->num_tiles; t++) {
        mean += a->tiles[t].sum_mean;
        pixels += a->tiles[t].pixels;
    }
    return pixels > 0.0 && mean > 0.0 ? ADAPT_PIXEL_FLOOR * mean / pixels : 0.0;
}

uint64_t adapt_pixel_bound(uint32_t num_tiles, const double *w, const uint32_t *m, double bound, uint32_t max_passes,
                           uint32_t growth, uint32_t step, uint32_t *n)
{
    uint64_t added = 0;
    double b2 = bound * bound;
    for (uint32_t t = 0; t < num_tiles && b2 > 0.0; t++) {
        if (!(m[t] > 0 && w[t] > b2))
            continue;
        /* the worst pixel's variance falls as 1/n: m w / n <= bound^2 */
        double need = ceil(m[t] * (w[t] / b2) / step - 1e-9) * step;
        if (need <= m[t]) /* above the bound by less than the rounding: one more step */
            need = (double)m[t] + step;
        double cap = (double)m[t] * growth < max_passes ? (double)m[t] * growth : max_passes;
        need = need > cap ? cap : need;
        if (need > n[t]) {
            added += (uint32_t)need - n[t];
            n[t] = (uint32_t)need;
        }
    }
    return added;
}

void adapt_set_pass_spp(struct adapt *a, uint32_t spp_per_pass)
{
    uint32_t k = spp_per_pass ? spp_per_pass : 1;
    a->first_passes = (ADAPT_FIRST_SPP + k - 1) / k;
}

void adapt_begin(struct adapt *a)
{
    uint32_t first = a->first_passes ? a->first_passes : 1;
    first = (first + a->step - 1) / a->step * a->step;
    first = a->max_passes < first ? a->max_passes : first;
    a->round = 0;
    a->finished = 0;
    a->est = a->est_raw = a->dof = a->aim = 0.0;
    a->uniform = 0;
    a->predicted = 0.0;
    a->pixels_over = a->pixels_over_capped = 0;
    a->worst = 0.0;
    a->num_history = 0;
    a->outstanding = 0;
    for (uint32_t t = 0; t < a->num_tiles; t++) {
        uint32_t px = a->tiles[t].pixels;
        memset(&a->tiles[t], 0, sizeof a->tiles[t]);
        a->tiles[t].pixels = px;
        a->tiles[t].passes = first;
        a->outstanding += first;
    }
}

/* Per candidate up[i]: the variance its step up removes per cost, indexed by i. */
static double *step_gain(uint32_t num_up, const uint32_t *up, const double *v, const double *c, const uint32_t *m,
                              const uint32_t *n, const double *hi)
{
    double *gain = mem_alloc(sizeof *gain * (num_up ? num_up : 1));
    for (uint32_t i = 0; i < num_up; i++) {
        uint32_t t = up[i];
        gain[i] = (v[t] * m[t] / n[t] - v[t] * m[t] / hi[t]) / (c[t] * (hi[t] - n[t]));
    }
    return gain;
}

/* up (tile indices) sorted by gain (parallel to up) descending, then by tile index: a
 * merge sort on the pairs, a total order, so the same inputs give the same order. */
static void sort_by_gain(uint32_t *up, double *gain, uint32_t n)
{
    uint32_t *tu = mem_alloc(sizeof *tu * (n ? n : 1));
    double *tg = mem_alloc(sizeof *tg * (n ? n : 1));
    for (uint32_t width = 1; width < n; width *= 2) {
        for (uint32_t lo = 0; lo < n; lo += 2 * width) {
            uint32_t mid = lo + width < n ? lo + width : n, hi = lo + 2 * width < n ? lo + 2 * width : n;
            uint32_t i = lo, j = mid, k = lo;
            while (i < mid || j < hi) {
                int take_i = j >= hi || (i < mid && (gain[i] > gain[j] || (gain[i] == gain[j] && up[i] < up[j])));
                tu[k] = take_i ? up[i] : up[j];
                tg[k++] = take_i ? gain[i++] : gain[j++];
            }
        }
        memcpy(up, tu, sizeof *up * n);
        memcpy(gain, tg, sizeof *gain * n);
    }
    free(tu);
    free(tg);
}

/* The continuous optimum of adapt_allocate (before the growth limit and the step): want[t]
 * >= m[t], at most max_passes, by Lagrange with clamping. */
static void lagrange(uint32_t num_tiles, const double *v, const double *c, const uint32_t *m, double budget,
                     uint32_t max_passes, double *want)
{
    uint8_t *fixed = mem_calloc(num_tiles ? num_tiles : 1, 1);
    double fixed_var = 0.0;
    for (uint32_t t = 0; t < num_tiles; t++) {
        want[t] = m[t];
        if (!(v[t] > 0.0) || m[t] >= max_passes) {
            fixed[t] = 1;
            fixed_var += v[t] > 0.0 ? v[t] : 0.0;
        }
    }
    /* Each pass moves at least one tile out of the free set, or ends. */
    for (uint32_t iter = 0; iter <= num_tiles; iter++) {
        double sum = 0.0;
        for (uint32_t t = 0; t < num_tiles; t++)
            if (!fixed[t])
                sum += sqrt(v[t] * m[t] * c[t]);
        double free_budget = budget - fixed_var;
        int changed = 0;
        for (uint32_t t = 0; t < num_tiles; t++) {
            if (fixed[t])
                continue;
            if (!(free_budget > 0.0)) { /* the budget cannot be met: everything free to the cap */
                want[t] = max_passes;
                continue;
            }
            want[t] = sum / free_budget * sqrt(v[t] * m[t] / c[t]);
            if (want[t] <= m[t]) {
                want[t] = m[t];
                fixed[t] = 1;
                fixed_var += v[t];
                changed = 1;
            } else if (want[t] >= max_passes) {
                want[t] = max_passes;
                fixed[t] = 1;
                fixed_var += v[t] * m[t] / max_passes;
                changed = 1;
            }
        }
        if (!changed || !(free_budget > 0.0))
            break;
    }
    free(fixed);
}

uint64_t adapt_allocate(uint32_t num_tiles, const double *v, const double *c, const uint32_t *m, double budget,
                        uint32_t max_passes, uint32_t growth, uint32_t step, uint32_t *n)
{
    double *want = mem_alloc(sizeof *want * (num_tiles ? num_tiles : 1));
    lagrange(num_tiles, v, c, m, budget, max_passes, want);
    /* Rounding to the step: every tile down (an optimum on a step stays), then one step up
     * for the tiles whose step buys the most variance per cost, until the budget is met:
     * the projected variance lands on the budget instead of past it by a step a tile. */
    uint32_t *up = mem_alloc(sizeof *up * (num_tiles ? num_tiles : 1)), num_up = 0;
    double proj = 0.0;
    for (uint32_t t = 0; t < num_tiles; t++) {
        double cap = (double)m[t] * growth < max_passes ? (double)m[t] * growth : max_passes;
        double lo = floor((want[t] + 1e-9) / step) * step, hi = ceil((want[t] - 1e-9) / step) * step;
        lo = lo > cap ? cap : lo;
        hi = hi > cap ? cap : hi;
        n[t] = lo > m[t] ? (uint32_t)lo : m[t];
        uint32_t nh = hi > m[t] ? (uint32_t)hi : m[t];
        want[t] = nh; /* from here: the step up */
        if (v[t] > 0.0) {
            proj += v[t] * m[t] / n[t];
            if (nh > n[t])
                up[num_up++] = t;
        }
    }
    if (proj > budget && num_up) {
        /* by gain per cost, then tile index: the same order for the same inputs */
        double *gain = step_gain(num_up, up, v, c, m, n, want);
        sort_by_gain(up, gain, num_up);
        for (uint32_t i = 0; i < num_up && proj > budget; i++) {
            uint32_t t = up[i];
            proj -= v[t] * m[t] / n[t] - v[t] * m[t] / want[t];
            n[t] = (uint32_t)want[t];
        }
        free(gain);
    }
    uint64_t added = 0;
    for (uint32_t t = 0; t < num_tiles; t++)
        added += n[t] - m[t];
    free(up);
    free(want);
    return added;
}

/* sum over the rendered tiles of v m / max(level, m): their projected variance at one level. */
static double projected_at(uint32_t num_tiles, const double *v, const uint32_t *m, double level)
{
    double proj = 0.0;
    for (uint32_t t = 0; t < num_tiles; t++)
        if (m[t] > 0 && v[t] > 0.0)
            proj += v[t] * m[t] / (level > m[t] ? level : m[t]);
    return proj;
}

uint64_t adapt_uniform(uint32_t num_tiles, const double *v, const uint32_t *m, double budget, uint32_t max_passes,
                       uint32_t growth, uint32_t step, uint32_t *n)
{
    uint32_t lo = 0, least = 0;
    for (uint32_t t = 0; t < num_tiles; t++)
        if (m[t] > 0) {
            lo = m[t] > lo ? m[t] : lo;
            least = least == 0 || m[t] < least ? m[t] : least;
        }
    uint64_t added = 0;
    if (lo > 0) {
        uint64_t g = (uint64_t)least * growth;
        uint32_t hi = g < max_passes ? (uint32_t)g : max_passes;
        uint32_t klo = (lo + step - 1) / step, khi = hi / step;
        khi = khi < klo ? klo : khi;
        /* the fewest steps whose level meets the budget (the projection falls with the level), or the most */
        while (klo < khi) {
            uint32_t k = klo + (khi - klo) / 2;
            if (projected_at(num_tiles, v, m, (double)k * step) <= budget)
                khi = k;
            else
                klo = k + 1;
        }
        lo = klo * step;
    }
    for (uint32_t t = 0; t < num_tiles; t++) {
        n[t] = m[t] > 0 && lo > m[t] ? lo : m[t];
        added += n[t] - m[t];
    }
    return added;
}

double adapt_predicted_ratio(uint32_t num_tiles, const double *v, const double *c, const uint32_t *m, double budget,
                             uint32_t max_passes)
{
    double *want = mem_alloc(sizeof *want * (num_tiles ? num_tiles : 1));
    lagrange(num_tiles, v, c, m, budget, max_passes, want);
    double top = 0.0;
    for (uint32_t t = 0; t < num_tiles; t++)
        top = m[t] > top ? m[t] : top;
    /* the one level for every tile: sum v m / level = budget, at least every tile's passes, at most the cap */
    double level = budget > 0.0 ? projected_at(num_tiles, v, m, top) * top / budget : (double)max_passes;
    level = level < top ? top : level > max_passes ? max_passes : level;
    double alloc = 0.0, uniform = 0.0;
    for (uint32_t t = 0; t < num_tiles; t++)
        if (m[t] > 0) {
            alloc += c[t] * want[t];
            uniform += c[t] * level;
        }
    free(want);
    return uniform > 0.0 ? alloc / uniform : 1.0;
}

double adapt_image_estimate(const struct adapt *a)
{
    double var = 0.0, mean = 0.0, pixels = 0.0;
    for (uint32_t t = 0; t < a->num_tiles; t++) {
        var += a->tiles[t].sum_var;
        mean += a->tiles[t].sum_mean;
        pixels += a->tiles[t].pixels;
    }
    return pixels > 0.0 && mean > 0.0 ? sqrt(var / pixels) / (mean / pixels) : 0.0;
}

/* Per pixel, the sum of the mean^2 (the scale of a tile's relative variance). */
static double mean_sq(const struct adapt_tile *at)
{
    return at->pixels ? at->sum_mean * at->sum_mean / at->pixels : 0.0;
}

double adapt_pool(const struct adapt *a, double *v, double *dof)
{
    uint32_t tx = a->tiles_x, ty = (a->num_tiles + tx - 1) / tx;
    double all_v = 0.0, all_m2 = 0.0;
    for (uint32_t t = 0; t < a->num_tiles; t++) {
        all_v += a->tiles[t].sum_var;
        all_m2 += mean_sq(&a->tiles[t]);
    }
    double sum = 0.0, sum_sq = 0.0;
    for (uint32_t t = 0; t < a->num_tiles; t++) {
        const struct adapt_tile *at = &a->tiles[t];
        uint32_t x = t % tx, y = t / tx;
        double nv = 0.0, nm2 = 0.0;
        for (uint32_t j = y ? y - 1 : 0; j <= y + 1 && j < ty; j++)
            for (uint32_t i = x ? x - 1 : 0; i <= x + 1 && i < tx; i++) {
                uint32_t u = j * tx + i;
                if (u == t || u >= a->num_tiles)
                    continue;
                nv += a->tiles[u].sum_var;
                nm2 += mean_sq(&a->tiles[u]);
            }
        if (!(nv > 0.0 && nm2 > 0.0)) { /* neighbours without variance: the image's */
            nv = all_v - at->sum_var;
            nm2 = all_m2 - mean_sq(at);
        }
        double prior = nv > 0.0 && nm2 > 0.0 ? nv / nm2 * mean_sq(at) : 0.0;
        double d = at->sum_var > 0.0 && at->sum_var_sq > 0.0 ? at->sum_var * at->sum_var / at->sum_var_sq : 0.0;
        double k = a->prior_dof > 0.0 ? a->prior_dof : 0.0;
        double own = at->sum_var > 0.0 ? at->sum_var : 0.0, pooled = d + k > 0.0 ? (d * own + k * prior) / (d + k) : own;
        /* Only ever raised: a tile's own figure is unbiased, and lowering the few tiles
         * whose bright pixels carry the image's error would hide it. */
        v[t] = pooled > own ? pooled : own;
        dof[t] = d + k > 0.0 ? d + k : 1.0;
        sum += v[t];
        sum_sq += v[t] * v[t] / dof[t];
    }
    return sum_sq > 0.0 ? sum * sum / sum_sq : 0.0;
}

int adapt_decide(struct adapt *a, int stop, uint64_t samples_total)
{
    uint32_t n_tiles = a->num_tiles;
    double *v = mem_alloc(sizeof *v * (n_tiles ? n_tiles : 1)), *c = mem_alloc(sizeof *c * (n_tiles ? n_tiles : 1));
    double *dof = mem_alloc(sizeof *dof * (n_tiles ? n_tiles : 1));
    uint32_t *m = mem_alloc(sizeof *m * (n_tiles ? n_tiles : 1)), *n = mem_alloc(sizeof *n * (n_tiles ? n_tiles : 1));
    a->est_raw = adapt_image_estimate(a);
    a->dof = adapt_pool(a, v, dof);
    double var = 0.0, mean = 0.0, pixels = 0.0;
    for (uint32_t t = 0; t < n_tiles; t++) {
        var += v[t];
        mean += a->tiles[t].sum_mean;
        pixels += a->tiles[t].pixels;
    }
    a->est = pixels > 0.0 && mean > 0.0 ? sqrt(var / pixels) / (mean / pixels) : 0.0;
    a->aim = a->target > 0.0 ? a->target / (1.0 + a->confidence_z / sqrt(2.0 * (a->dof > 0.5 ? a->dof : 0.5)))
                             : 0.5 * a->est; /* a time limit alone: each round aims at half the error */
    if (a->num_history < ADAPT_MAX_HISTORY) {
        a->hist_samples[a->num_history] = (double)samples_total;
        a->hist_est[a->num_history++] = a->est;
    }
    double *w = mem_alloc(sizeof *w * (n_tiles ? n_tiles : 1));
    double worst = 0.0;
    a->pixels_over = a->pixels_over_capped = 0;
    for (uint32_t t = 0; t < n_tiles; t++) {
        const struct adapt_tile *at = &a->tiles[t];
        w[t] = a->pixel_error > 0.0 ? at->worst : 0.0;
        worst = w[t] > worst ? w[t] : worst;
        a->pixels_over += a->pixel_error > 0.0 ? at->over : 0;
        a->pixels_over_capped += a->pixel_error > 0.0 && at->passes >= a->max_passes ? at->over : 0;
    }
    a->worst = sqrt(worst);
    /* A target alone, once met, is met; with no target the bound alone counts (a time limit
     * or round cap alone: neither, each round aims at half the error). */
    int target_met = a->target > 0.0 ? a->est <= a->aim : a->pixel_error > 0.0;
    int pixels_met = !(a->pixel_error > 0.0) || a->pixels_over == 0;
    a->met = (a->target > 0.0 || a->pixel_error > 0.0) && target_met && pixels_met;
    uint64_t added = 0;
    if (!(stop || a->est <= 0.0 || (target_met && pixels_met) || (a->max_rounds && a->round + 1 >= a->max_rounds))) {
        for (uint32_t t = 0; t < n_tiles; t++) {
            const struct adapt_tile *at = &a->tiles[t];
            m[t] = at->passes;
            /* Rays (every bounce and shadow ray) plus one per camera sample: what a pass of
             * this tile costs, counted, not timed. */
            c[t] = at->passes ? (double)(at->rays + at->samples) / at->passes : 1.0;
            if (!(c[t] > 0.0))
                c[t] = 1.0;
        }
        /* relRMSE^2 = (sum var / pixels) / (sum mean / pixels)^2 <= aim^2 */
        double budget = a->aim * a->aim * mean * mean / pixels;
        if (target_met) { /* the bound's passes only */
            memcpy(n, m, sizeof *n * n_tiles);
        } else {
            if (a->round == 0) { /* the pilot's decision, for the whole frame: adapt or uniform passes */
                a->predicted = adapt_predicted_ratio(n_tiles, v, c, m, budget, a->max_passes);
                a->uniform = a->predicted > ADAPT_UNIFORM_GAIN;
            }
            added = a->uniform ? adapt_uniform(n_tiles, v, m, budget, a->max_passes, ADAPT_GROWTH, a->step, n)
                               : adapt_allocate(n_tiles, v, c, m, budget, a->max_passes, ADAPT_GROWTH, a->step, n);
        }
        if (a->pixel_error > 0.0)
            added += adapt_pixel_bound(n_tiles, w, m, a->pixel_error, a->max_passes, ADAPT_GROWTH, a->step, n);
        a->outstanding = 0;
        for (uint32_t t = 0; t < n_tiles; t++) {
            a->outstanding += n[t] - a->tiles[t].passes;
            a->tiles[t].passes = n[t];
        }
    }
    free(v);
    free(w);
    free(c);
    free(dof);
    free(m);
    free(n);
    if (added == 0) {
        a->finished = 1;
        return 0;
    }
    a->round++;
    return 1;
}

double adapt_eta_samples(const struct adapt *a)
{
    if (!(a->target > 0.0) || a->num_history == 0 || !(a->est > 0.0) || !(a->aim > 0.0))
        return 0.0;
    double sx = 0, sy = 0, sxx = 0, sxy = 0;
    uint32_t k = 0;
    for (uint32_t i = 0; i < a->num_history; i++) {
        if (!(a->hist_est[i] > 0.0) || !(a->hist_samples[i] > 0.0))
            continue;
        double x = log(a->hist_samples[i]), y = log(a->hist_est[i]);
        sx += x, sy += y, sxx += x * x, sxy += x * y;
        k++;
    }
    double b = 0.5; /* Monte Carlo's rate until two rounds say otherwise */
    if (k >= 2 && sxx * k - sx * sx > 0.0)
        b = -(sxy * k - sx * sy) / (sxx * k - sx * sx);
    b = b < 0.25 ? 0.25 : b > 1.0 ? 1.0 : b;
    double last = a->hist_samples[a->num_history - 1];
    return a->est <= a->aim ? last : last * pow(a->est / a->aim, 1.0 / b);
}

uint32_t adapt_tile_units(const uint32_t *old, const uint32_t *now, uint32_t nb)
{
    uint32_t lo = UINT32_MAX, hi = 0, units = 0;
    for (uint32_t b = 0; b < nb; b++)
        if (now[b] > old[b]) {
            lo = old[b] < lo ? old[b] : lo;
            hi = now[b] > hi ? now[b] : hi;
        }
    for (uint32_t p = lo; p < hi; p++)
        for (uint32_t b = 0; b < nb; b++)
            if (old[b] <= p && p < now[b]) {
                units++;
                break;
            }
    return units;
}

uint32_t adapt_fit_units(const uint32_t *old, uint32_t *now, uint32_t nb, uint32_t room)
{
    uint32_t units;
    while ((units = adapt_tile_units(old, now, nb)) > room) {
        uint32_t lowest = nb;
        for (uint32_t b = 0; b < nb; b++)
            if (now[b] > old[b] && (lowest == nb || old[b] < old[lowest]))
                lowest = b;
        now[lowest] = old[lowest];
    }
    return units;
}
