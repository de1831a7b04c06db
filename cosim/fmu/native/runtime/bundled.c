/* bundled.c: bundled data files opened by name (bundled.h) */
#include "bundled.h"

#include <stdlib.h>
#include <string.h>

FILE* ato_open_bundled(const char* resources, const char* folder, const char* name,
                       const char* ext, const char* key, char* err, size_t n) {
    if (strpbrk(name, "/\\.")) {
        snprintf(err, n, "%s = '%s': the native build reads bundled %s only "
                 "(resources/%s/*.%s); a file path needs the Python FMU", key, name, folder,
                 folder, ext);
        return NULL;
    }
    size_t len = strlen(resources) + strlen(folder) + strlen(name) + strlen(ext) + 4;
    char* path = malloc(len);
    snprintf(path, len, "%s/%s/%s.%s", resources, folder, name, ext);
    FILE* f = fopen(path, "r");
    if (!f) snprintf(err, n, "%s = '%s': no bundled file of that name (%s)", key, name, path);
    free(path);
    return f;
}
