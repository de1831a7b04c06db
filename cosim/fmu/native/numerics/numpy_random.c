/* numpy_random.c: see numpy_random.h. */
#include <math.h>

#include "numpy_random.h"
#include "ato_numpy_normal.h"

/* SeedSequence constants (numpy.random.bit_generator) */
#define INIT_A 0x43b0d7e5u
#define MULT_A 0x931e8875u
#define INIT_B 0x8b51f9ddu
#define MULT_B 0x58f38dedu
#define MIX_MULT_L 0xca01f9ddu
#define MIX_MULT_R 0x4973f715u
#define POOL 4
/* PCG64 multiplier */
static const ato_u128 MULT = {0x2360ED051FC65DA4ULL, 0x4385DF649FCCF645ULL};
/* the ziggurat's tail start r and 1 / r */
#define ZIG_R 3.6541528853610088
#define ZIG_INV_R 0.27366123732975828

static uint32_t hashmix(uint32_t value, uint32_t* hash_const) {
    value ^= *hash_const;
    *hash_const *= MULT_A;
    value *= *hash_const;
    value ^= value >> 16;
    return value;
}
static uint32_t mix(uint32_t x, uint32_t y) {
    uint32_t result = MIX_MULT_L * x - MIX_MULT_R * y;
    result ^= result >> 16;
    return result;
}

static ato_u128 add128(ato_u128 a, ato_u128 b) {
    ato_u128 r;
    r.lo = a.lo + b.lo;
    r.hi = a.hi + b.hi + (r.lo < a.lo);
    return r;
}
/* a * b mod 2^128 */
static ato_u128 mul128(ato_u128 a, ato_u128 b) {
    uint64_t a0 = a.lo & 0xffffffffu, a1 = a.lo >> 32, b0 = b.lo & 0xffffffffu, b1 = b.lo >> 32;
    uint64_t p00 = a0 * b0, p01 = a0 * b1, p10 = a1 * b0, p11 = a1 * b1;
    uint64_t mid = (p00 >> 32) + (p01 & 0xffffffffu) + (p10 & 0xffffffffu);
    ato_u128 r;
    r.lo = (p00 & 0xffffffffu) | (mid << 32);
    r.hi = p11 + (p01 >> 32) + (p10 >> 32) + (mid >> 32) + a.hi * b.lo + a.lo * b.hi;
    return r;
}
static void step(ato_pcg64* g) { g->state = add128(mul128(g->state, MULT), g->inc); }

void ato_pcg64_seed(ato_pcg64* g, const uint64_t* ints, int n) {
    uint32_t entropy[64];
    int k = 0;
    for (int i = 0; i < n && k < 62; i++) {
        uint64_t x = ints[i];
        if (x == 0) { entropy[k++] = 0; continue; }
        while (x && k < 64) { entropy[k++] = (uint32_t)(x & 0xffffffffu); x >>= 32; }
    }
    uint32_t pool[POOL], hash_const = INIT_A;
    for (int i = 0; i < POOL; i++) pool[i] = hashmix(i < k ? entropy[i] : 0, &hash_const);
    for (int src = 0; src < POOL; src++)
        for (int dst = 0; dst < POOL; dst++)
            if (src != dst) pool[dst] = mix(pool[dst], hashmix(pool[src], &hash_const));
    for (int src = POOL; src < k; src++)
        for (int dst = 0; dst < POOL; dst++)
            pool[dst] = mix(pool[dst], hashmix(entropy[src], &hash_const));
    /* generate_state(4, uint64): 8 words from the pool, pairs little-endian */
    uint32_t words[8], hb = INIT_B;
    for (int i = 0; i < 8; i++) {
        uint32_t v = pool[i % POOL];
        v ^= hb;
        hb *= MULT_B;
        v *= hb;
        v ^= v >> 16;
        words[i] = v;
    }
    uint64_t seed[4];
    for (int i = 0; i < 4; i++)
        seed[i] = (uint64_t)words[2 * i] | ((uint64_t)words[2 * i + 1] << 32);
    ato_u128 initstate = {seed[0], seed[1]}, initseq = {seed[2], seed[3]};
    g->state.hi = g->state.lo = 0;
    g->inc.hi = (initseq.hi << 1) | (initseq.lo >> 63);
    g->inc.lo = (initseq.lo << 1) | 1u;
    step(g);
    g->state = add128(g->state, initstate);
    step(g);
}

uint64_t ato_pcg64_next(ato_pcg64* g) {
    step(g);
    uint64_t x = g->state.hi ^ g->state.lo;
    unsigned rot = (unsigned)(g->state.hi >> 58);
    return (x >> rot) | (x << ((64u - rot) & 63u));
}

double ato_pcg64_double(ato_pcg64* g) {
    return (double)(ato_pcg64_next(g) >> 11) * (1.0 / 9007199254740992.0);
}

double ato_standard_normal(ato_pcg64* g) {
    for (;;) {
        uint64_t r = ato_pcg64_next(g);
        int idx = (int)(r & 0xff);
        r >>= 8;
        int sign = (int)(r & 0x1);
        uint64_t rabs = (r >> 1) & 0x000fffffffffffffULL;
        double x = (double)rabs * ATO_ZIG_WI[idx];
        if (sign) x = -x;
        if (rabs < ATO_ZIG_KI[idx]) return x;
        if (idx == 0) {
            for (;;) {
                double xx = -ZIG_INV_R * log1p(-ato_pcg64_double(g));
                double yy = -log1p(-ato_pcg64_double(g));
                if (yy + yy > xx * xx)
                    return ((rabs >> 8) & 0x1) ? -(ZIG_R + xx) : ZIG_R + xx;
            }
        } else {
            if ((ATO_ZIG_FI[idx - 1] - ATO_ZIG_FI[idx]) * ato_pcg64_double(g) + ATO_ZIG_FI[idx]
                < exp(-0.5 * x * x))
                return x;
        }
    }
}
