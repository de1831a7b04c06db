/*
 * minmax.h: Python's max(a, b) and min(a, b) for the native models (plants and controller
 * laws): the first argument unless the second is larger / smaller, so that NaN and signed
 * zeros come out as the Python cores' do.
 */
#ifndef ATO_MINMAX_H
#define ATO_MINMAX_H

static inline double ato_max(double a, double b) { return b > a ? b : a; }
static inline double ato_min(double a, double b) { return b < a ? b : a; }

#endif
