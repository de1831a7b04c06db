/*
 * grade.h: a controller's view of a bundled route's grades (plants.route.Route.grade and
 * grade_accel), read from resources/routes/<route>.grade (written at build time by
 * cosim/build/native.py route_tables): the step profile of the grade (permille, uphill
 * positive) over position (m).
 */
#ifndef ATO_GRADE_H
#define ATO_GRADE_H

#include <stddef.h>

#define ATO_GRADE_GRAVITY 9.81 /* plants.route.GRAVITY */

typedef struct { int n; double* starts; double* values; } ato_grade;

/* load the grades of the bundled route `route` from `resources`; 0 with a message in err
 * (a file path, not a bundled route; no such route) */
int ato_grade_load(const char* resources, const char* route, ato_grade* out, char* err,
                   size_t n);
void ato_grade_free(ato_grade* g);
/* grade.at(s) (permille): values[bisect_right(starts, s) - 1] */
double ato_grade_at(const ato_grade* g, double s);
/* Route.grade_accel(s) (m/s2): GRAVITY * grade.at(s) / 1000 */
double ato_grade_accel(const ato_grade* g, double s);

#endif
