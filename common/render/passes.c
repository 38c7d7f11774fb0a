/* Progressive photon-map passes: the plan of a frame's passes and the kernel dimensions
 * of the radius rule (see passes.h). */
#include "render/passes.h"
#include "scene/scene.h"
#include "scene/scene_limits.h"

int passes_volume_kernel_dim(enum media_method method)
{
    /* The beam estimate gathers the photons within r of the camera ray: its kernel blurs
     * only across the ray, so its variance grows as 1 / r^2 against an r^2 bias, and the
     * radius rule that balances the two is the 2D one (Jarosz et al. 2011). */
    /* Photon beams' 1D kernel blurs along one axis only (1 / r variance against an r bias). */
    return method == MEDIA_MARCH_BEAMS ? 1 : method == MEDIA_MARCH_BEAM ? 2 : 3;
}

int passes_plan(uint32_t spp, uint32_t asked, uint64_t photons, int photons_given, double stored_per_photon,
                uint64_t pixels, struct pass_plan *out)
{
    if (spp == 0)
        spp = 1;
    uint32_t p = asked, k;
    if (p == 0) {
        /* A pass's cost grows with its photons twice: tracing them, which goes with the
         * photons emitted, and the map (its bytes, its rows) and every beam query, which
         * walks the M r^2 photons near its ray: they go with the photons stored. Past a few
         * photons per pixel, more passes buy more (each also shrinks the radius, and brings
         * its own camera samples) than denser maps. */
        uint64_t px = pixels ? pixels : 1, cap = (uint64_t)PASS_PHOTONS_PER_PIXEL * px;
        if (!photons_given && photons > cap)
            photons = cap;
        /* The count of passes comes from the emitted cap alone: the stored cap below
         * depends on the pilot, hence on the frame's grid, and the frames of a range must
         * plan the same passes. It only lowers the photons, so the total stays in bounds. */
        uint64_t most = photons ? PASS_MAX_PHOTONS / photons : SCENE_MAX_PASSES;
        if (most < 1)
            most = 1;
        if (most > SCENE_MAX_PASSES)
            most = SCENE_MAX_PASSES;
        k = PASS_DEFAULT_SPP;
        if ((spp + k - 1) / k > most)
            k = (uint32_t)((spp + most - 1) / most);
        p = (spp + k - 1) / k;
        if (stored_per_photon > 0.0) {
            double stored_cap = (double)PASS_STORED_PER_PIXEL * (double)px / stored_per_photon;
            if (!photons_given && stored_cap < (double)photons)
                photons = stored_cap < 1.0 ? 1 : (uint64_t)stored_cap;
        }
    }
    if (p > SCENE_MAX_PASSES)
        p = SCENE_MAX_PASSES;
    k = (spp + p - 1) / p;
    out->passes = p;
    out->spp_per_pass = k;
    out->spp = (uint64_t)k * p > SCENE_MAX_SPP ? 0 : k * p;
    out->photons = photons;
    return out->spp ? 0 : -1;
}
