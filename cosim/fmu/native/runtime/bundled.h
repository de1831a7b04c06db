/*
 * bundled.h: a data file bundled in the FMU's resources, opened by name:
 * <resources>/<folder>/<name>.<ext> (written at build time by cosim/build/native.py). The
 * native FMU reads bundled data only: a name holding '/', '\\' or '.' is a file path, which
 * only the Python FMU reads.
 */
#ifndef ATO_BUNDLED_H
#define ATO_BUNDLED_H

#include <stddef.h>
#include <stdio.h>

/* open <resources>/<folder>/<name>.<ext> for reading; NULL with a message in err naming the
 * parameter `key` and its value (a file path; no such bundled file) */
FILE* ato_open_bundled(const char* resources, const char* folder, const char* name,
                       const char* ext, const char* key, char* err, size_t n);

#endif
