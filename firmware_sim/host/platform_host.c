#include <stdio.h>

#include "platform.h"

/* One input file at a time is all the firmware needs. */
static FILE *g_input;

int platform_open_input(const char *path) {
  if (g_input != NULL) return -1;
  g_input = fopen(path, "rb");
  return g_input != NULL ? 0 : -1;
}

int32_t platform_read(int handle, void *buffer, uint32_t bytes) {
  if (handle != 0 || g_input == NULL) return -1;
  const size_t got = fread(buffer, 1, bytes, g_input);
  return ferror(g_input) ? -1 : (int32_t)got;
}

void platform_close(int handle) {
  if (handle == 0 && g_input != NULL) {
    fclose(g_input);
    g_input = NULL;
  }
}

void platform_write(int stream, const char *text, uint32_t length) {
  FILE *out = stream == PLATFORM_STDERR ? stderr : stdout;
  fwrite(text, 1, length, out);
}
