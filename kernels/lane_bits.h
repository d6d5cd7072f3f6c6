/* lane_bits.h: the set lanes of a comparison as a bit mask, taken one bit
 * at a time, lowest first (the disc walk's children met, box_wide.h, and
 * crossed discs, detp_disc_index.h; the sphere cache's records met). A
 * loop over the set bits costs one unpredictable branch per set lane
 * instead of one per lane. */
#ifndef OCLGI_LANE_BITS_H
#define OCLGI_LANE_BITS_H

/* bit k set when lane k of `t` (a comparison's result: 0 or -1) is set */
inline uint lane_bits8(int8 t)
{
    int8 bits = t & (int8)(1, 2, 4, 8, 16, 32, 64, 128);
    int4 b4 = bits.lo | bits.hi;
    int2 b2 = b4.lo | b4.hi;
    return (uint)(b2.x | b2.y);
}

/* the index of the lowest set bit of m (m != 0) */
inline int lowest_bit(uint m)
{
    return 31 - clz(m & (0u - m));
}

#endif
