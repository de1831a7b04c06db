/*
 * hybrid.h: what the seed-004 controllers (explicit_mpc.c, hybrid_mpc.c) share: the move
 * blocks of controllers/hybrid/miqp.py parse_blocks and the checks of HybridMpcParams (the
 * parameters both declare) with the speed-time reference profile they load.
 */
#ifndef ATO_HYBRID_H
#define ATO_HYBRID_H

#include <stddef.h>

#include "law.h"
#include "profile.h"

/* the block lengths of `text` ("3:4:3"; blank: one stage per block) into blocks[] (room for
 * `horizon`), their count into *count; 0 after the core's message (positive lengths summing
 * to N) */
int hybrid_blocks(const char* text, int horizon, int* blocks, int* count, char* err,
                      size_t n);

/* HybridMpcParams.check and the profile of HybridMpc.__init__, in their order, for the
 * parameter values v (value references vr_*) and strings s; loads the time profile into
 * *profile; 0 after a message that names the parameter */
typedef struct {
    int N, q_speed, q_position, R, dR, move_blocks, sample_time, coupler_force_max,
        position_reference, delta_mode, reference;
} hybrid_vrs;

/* the value references of a law whose generated header declares HybridMpcParams */
#define HYBRID_VRS                                                                      \
    {ATO_VR_N, ATO_VR_q_speed, ATO_VR_q_position, ATO_VR_R, ATO_VR_dR, ATO_VR_move_blocks,  \
     ATO_VR_sample_time, ATO_VR_coupler_force_max, ATO_VR_position_reference,              \
     ATO_VR_delta_mode, ATO_VR_reference}

int hybrid_check(const ato_values* p, const hybrid_vrs* vr, ato_profile* profile,
                     char* err, size_t n);

#endif
