/* An FMU that misbehaves on purpose, for the tests of how hosts contain it: the preprocessor
 * switch ON_INSTANTIATE or ON_STEP names what fmi2Instantiate or every fmi2DoStep does first
 * (spin(): a loop at 100 % of a core; block(): waits forever using no CPU; segfault(); abort();
 * exit(3); slow_once(): uses 0.3 s of CPU in the first call of the process, then returns: a
 * healthy FMU with one long call; the process's environment remembers it, since a host that
 * unloads and loads the binary again resets its static data), and NAN_OUTPUT makes y NaN
 * from t = 0.25 on. Otherwise y = 2 u. */
#define NR 2 /* u (in), y (out) */
#define NI 0
#define NB 0
#define NS 0
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

__attribute__((unused)) static void spin(void) {
    volatile int forever = 1;
    while (forever) {
    }
}
__attribute__((unused)) static void block(void) {
    for (;;) pause();
}
__attribute__((unused)) static void segfault(void) {
    volatile int *volatile nowhere = NULL;
    *nowhere = 1;
}
__attribute__((unused)) static void slow_once(void) {
    char pid[24];
    snprintf(pid, sizeof pid, "%ld", (long)getpid());
    const char *done = getenv("HOSTILE_SLOW_ONCE_PID"); /* a forked child has its own call */
    if (done && strcmp(done, pid) == 0) return;
    setenv("HOSTILE_SLOW_ONCE_PID", pid, 1);
    clock_t end = clock() + (clock_t)(0.3 * CLOCKS_PER_SEC); /* clock(): CPU time */
    while (clock() < end) {
    }
}

#include "fmi2_common.c"

static void model_defaults(Inst *m) { m->r[0] = 0.5; m->r[1] = 1.0; }

static void model_outputs(Inst *m) {
    m->r[1] = 2.0 * m->r[0];
#ifdef NAN_OUTPUT
    if (m->time >= 0.25) m->r[1] = NAN;
#endif
}

static fmi2Status model_step(Inst *m, fmi2Real t, fmi2Real h) {
    (void)m; (void)t; (void)h;
#ifdef ON_STEP
    ON_STEP;
#endif
    return fmi2OK;
}
