/* What the photon map and the photon beams share (see photon_codec.h). */
#include "render/photon_codec.h"
#include <math.h>
#include <string.h>

void photon_rgbe_encode(vec3 c, uint8_t out[4])
{
    float m = v3_max_component(c);
    if (!(m > 1e-32f) || !isfinite(m)) {
        memset(out, 0, 4);
        return;
    }
    int e;
    float f = frexpf(m, &e) * 256.0f / m; /* m = f' 2^e, f' in [0.5, 1) */
    out[0] = (uint8_t)fminf(c.x * f, 255.0f);
    out[1] = (uint8_t)fminf(c.y * f, 255.0f);
    out[2] = (uint8_t)fminf(c.z * f, 255.0f);
    out[3] = (uint8_t)(e + 128);
}

vec3 photon_rgbe_decode(const uint8_t in[4])
{
    if (in[3] == 0)
        return v3(0, 0, 0);
    float f = ldexpf(1.0f, (int)in[3] - (128 + 8));
    /* +0.5: the centre of the quantisation bin, so the code is unbiased on average. */
    return v3(((float)in[0] + 0.5f) * f, ((float)in[1] + 0.5f) * f, ((float)in[2] + 0.5f) * f);
}

_Static_assert(PHOTON_DEPTH_MAX <= 0x7ffu, "a photon's events fit the depth word's 11 bits");

uint16_t photon_depth_word(uint32_t events, float density_rel)
{
    uint32_t k = 0;
    if (density_rel > 0.0f && density_rel < 1.0f) {
        int e;
        frexpf(density_rel, &e); /* density_rel in [2^(e-1), 2^e) */
        k = -e > 31 ? 31u : (uint32_t)-e;
    }
    return (uint16_t)(events | k << 11);
}

float photon_density_floor(uint16_t word)
{
    return ldexpf(1.0f, -(int)(word >> 11) - 1);
}

