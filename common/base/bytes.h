/* Little-endian byte order for everything Brume writes to disk or the wire (protocol,
 * journal, photon map blobs, EXR chunk headers, grid files). Bytes in, bytes out, no
 * alignment assumed: a caller checks bounds before it reads; these never do. */
#ifndef BRUME_BYTES_H
#define BRUME_BYTES_H
#include <stdint.h>
#include <string.h>

static inline void bytes_put_u16(uint8_t *p, uint16_t v) { p[0] = (uint8_t)v; p[1] = (uint8_t)(v >> 8); }

static inline void bytes_put_u32(uint8_t *p, uint32_t v)
{
    for (int i = 0; i < 4; i++)
        p[i] = (uint8_t)(v >> (8 * i));
}

static inline void bytes_put_u64(uint8_t *p, uint64_t v)
{
    for (int i = 0; i < 8; i++)
        p[i] = (uint8_t)(v >> (8 * i));
}

static inline uint16_t bytes_get_u16(const uint8_t *p) { return (uint16_t)(p[0] | (uint16_t)p[1] << 8); }

static inline uint32_t bytes_get_u32(const uint8_t *p)
{
    return (uint32_t)p[0] | (uint32_t)p[1] << 8 | (uint32_t)p[2] << 16 | (uint32_t)p[3] << 24;
}

static inline uint64_t bytes_get_u64(const uint8_t *p)
{
    return (uint64_t)bytes_get_u32(p) | (uint64_t)bytes_get_u32(p + 4) << 32;
}

/* IEEE-754 values by their bit patterns (memcpy, so no aliasing or alignment issue). */
static inline void bytes_put_f32(uint8_t *p, float f)
{
    uint32_t u;
    memcpy(&u, &f, 4);
    bytes_put_u32(p, u);
}

static inline float bytes_get_f32(const uint8_t *p)
{
    uint32_t u = bytes_get_u32(p);
    float f;
    memcpy(&f, &u, 4);
    return f;
}

static inline void bytes_put_f64(uint8_t *p, double d)
{
    uint64_t u;
    memcpy(&u, &d, 8);
    bytes_put_u64(p, u);
}

static inline double bytes_get_f64(const uint8_t *p)
{
    uint64_t u = bytes_get_u64(p);
    double d;
    memcpy(&d, &u, 8);
    return d;
}

#endif
