/*
 * vars.h: the variable table of a native model, as the generated <model>_decl.h fills it
 * (cosim/build/native.py writes that header from the core's Python declarations, so
 * names, value references, starts and ranges are declared once).
 */
#ifndef ATO_VARS_H
#define ATO_VARS_H

enum ato_causality { ATO_PARAMETER, ATO_INPUT, ATO_OUTPUT };
enum ato_type { ATO_REAL, ATO_INTEGER, ATO_BOOLEAN, ATO_STRING };

typedef struct ato_var {
    const char* name;
    int causality;      /* enum ato_causality */
    int type;           /* enum ato_type */
    double start;       /* Real/Integer/Boolean start */
    const char* start_string; /* String start */
    int has_min, has_max;
    double min, max;
} ato_var;

#endif
