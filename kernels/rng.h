/* rng.h: stateless randomness (DESIGN.md section 2).
 *
 * Every random number of a path is a pure function of (seed, path, bounce,
 * dimension): Philox4x32-10 with counter (path, bounce, block, tag) and key
 * (seed low, seed high). One call yields dimensions 4*block .. 4*block+3 of
 * that bounce. A path traced again with the same seed is the same path, and
 * its suffix from any bounce can be re-traced alone.
 *
 * Dimensions, by bounce:
 *   bounce 0 (emission): block 0 = (emitter choice, position u, position v,
 *                        direction u); block 1 = (direction v, -, -, -);
 *                        an environment map also takes block 1's y and z
 *                        (its texel's jitter, light.h)
 *   bounce b >= 1 (scattering at the end of segment b-1): block 0 =
 *                        (direction u, direction v, Russian roulette, -)
 */
#ifndef OCLGI_RNG_H
#define OCLGI_RNG_H

#include <pyopencl-random123/philox.cl>

#define RNG_TAG 0x6f636c67u /* "oclg": separates this stream from other uses */

inline float4 rng_uniform4(uint seed_lo, uint seed_hi, uint path, uint bounce, uint block)
{
    philox4x32_ctr_t c = {{path, bounce, block, RNG_TAG}};
    philox4x32_key_t k = {{seed_lo, seed_hi}};
    philox4x32_ctr_t r = philox4x32(c, k);
    /* 24 bits per float: exact in float32, uniform on [0, 1). */
    return (float4)((float)(r.v[0] >> 8), (float)(r.v[1] >> 8),
                    (float)(r.v[2] >> 8), (float)(r.v[3] >> 8)) * (1.0f / 16777216.0f);
}

#endif
