/*
 * numpy_random.h: numpy's seeded normal draws in C, so that a native plant's seeded
 * disturbance is the Python core's: np.random.default_rng([w0, w1, ...]).standard_normal().
 *
 *  - SeedSequence (numpy.random.bit_generator): the entropy words (each non-negative integer
 *    as its little-endian 32-bit words, 0 as one word) hashed into a pool of 4 words and
 *    expanded to the 4 64-bit words that seed PCG64;
 *  - PCG64 (XSL-RR 128/64): state = state * M + inc (mod 2^128), output
 *    rotr64(hi ^ lo, hi >> 58) of the new state; seeded as pcg_setseq_128_srandom_r;
 *    128-bit arithmetic in two 64-bit words (plain C99, no compiler extension);
 *  - standard_normal: numpy's 256-strip ziggurat, its tables measured from numpy at build
 *    time (ato_numpy_normal.h, cosim/build/native.py numpy_normal_header), the tail by
 *    Marsaglia's method with log1p.
 */
#ifndef ATO_NUMPY_RANDOM_H
#define ATO_NUMPY_RANDOM_H

#include <stdint.h>

typedef struct { uint64_t hi, lo; } ato_u128;
typedef struct { ato_u128 state, inc; } ato_pcg64;

/* PCG64(SeedSequence(ints)) for non-negative integers ints[0..n-1] */
void ato_pcg64_seed(ato_pcg64* g, const uint64_t* ints, int n);
uint64_t ato_pcg64_next(ato_pcg64* g);
/* (next >> 11) 2^-53, in [0, 1) */
double ato_pcg64_double(ato_pcg64* g);
/* Generator.standard_normal() */
double ato_standard_normal(ato_pcg64* g);

#endif
