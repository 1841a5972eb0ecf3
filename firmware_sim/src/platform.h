/* What the firmware needs from its platform: the host build maps it to stdio
 * (host/platform_host.c), the Cortex-M4F build to ARM semihosting (arm/platform_semihosting.c). */
#ifndef FIRMWARE_PLATFORM_H
#define FIRMWARE_PLATFORM_H

#include <stdint.h>

#define PLATFORM_STDOUT 1
#define PLATFORM_STDERR 2

/* Opens a binary file for reading; returns a handle >= 0, or -1. */
int platform_open_input(const char *path);
/* Reads up to `bytes`; returns the number of bytes read (0 at end of file), -1 on error. */
int32_t platform_read(int handle, void *buffer, uint32_t bytes);
void platform_close(int handle);
/* Writes `length` bytes of text to PLATFORM_STDOUT or PLATFORM_STDERR. */
void platform_write(int stream, const char *text, uint32_t length);

#endif
