/*
 * instance_registry.h: the instances an FMU binary has handed out and not yet freed, so that
 * freeing an instance twice is detected and refused with a log message (as the FMI Reference
 * FMUs' state machine does) instead of freeing its memory twice (abort or segfault). FMI leaves
 * a second fmi2FreeInstance / fmi3FreeInstance undefined; the host's logger for the message is
 * kept, with the instance name, for the last REGISTRY_FREED freed instances (a "memo" the
 * caller fills). An address malloc hands out again is a new instance: only a second free
 * before that is detected. Header-only (static functions), included by the FMI fronts and the
 * Python FMUs' shim; a spin lock (GCC builtins) guards it, so it needs no pthreads.
 */
#ifndef INSTANCE_REGISTRY_H
#define INSTANCE_REGISTRY_H

#include <stdlib.h>
#include <string.h>

#define REGISTRY_FREED 64
#define REGISTRY_MEMO 384 /* bytes of the caller's memo: logger, environment, name */

static volatile int registry_lock_flag = 0;
static const void** registry_live = NULL;
static size_t registry_n = 0, registry_cap = 0;
static struct {
    const void* instance;
    unsigned char memo[REGISTRY_MEMO];
} registry_freed[REGISTRY_FREED];
static size_t registry_next = 0;

static void registry_lock(void)
{
    while (__sync_lock_test_and_set(&registry_lock_flag, 1)) {
    }
}

static void registry_unlock(void) { __sync_lock_release(&registry_lock_flag); }

/* a new live instance (an address freed before is forgotten); 0 when out of memory */
static int registry_add(const void* instance)
{
    int ok = 1;
    registry_lock();
    for (size_t k = 0; k < REGISTRY_FREED; k++)
        if (registry_freed[k].instance == instance)
            registry_freed[k].instance = NULL;
    if (registry_n == registry_cap) {
        size_t cap = registry_cap ? 2 * registry_cap : 16;
        const void** grown = (const void**)realloc((void*)registry_live, cap * sizeof *grown);
        if (grown) {
            registry_live = grown;
            registry_cap = cap;
        } else {
            ok = 0;
        }
    }
    if (ok)
        registry_live[registry_n++] = instance;
    registry_unlock();
    return ok;
}

/* 1 when ``instance`` is live (handed out and not freed) */
static int registry_is_live(const void* instance)
{
    int live = 0;
    registry_lock();
    for (size_t k = 0; k < registry_n && !live; k++)
        live = registry_live[k] == instance;
    registry_unlock();
    return live;
}

/* 1: ``instance`` was live and is now released (``memo``, REGISTRY_MEMO bytes, is kept for a
 * later message); -1: it was freed already (its memo is copied into ``memo``); 0: unknown */
static int registry_release(const void* instance, void* memo)
{
    int found = 0;
    registry_lock();
    for (size_t k = 0; k < registry_n; k++)
        if (registry_live[k] == instance) {
            registry_live[k] = registry_live[--registry_n];
            registry_freed[registry_next].instance = instance;
            memcpy(registry_freed[registry_next].memo, memo, REGISTRY_MEMO);
            registry_next = (registry_next + 1) % REGISTRY_FREED;
            found = 1;
            break;
        }
    if (!found)
        for (size_t k = 0; k < REGISTRY_FREED; k++)
            if (registry_freed[k].instance == instance) {
                memcpy(memo, registry_freed[k].memo, REGISTRY_MEMO);
                found = -1;
                break;
            }
    registry_unlock();
    return found;
}

#endif
