/* Cortex-M4F-only platform services (the portable ones are in src/platform.h). */
#ifndef FIRMWARE_PLATFORM_ARM_H
#define FIRMWARE_PLATFORM_ARM_H

#include <stdint.h>

/* The emulator's command line (QEMU -semihosting-config arg=...); 0 on success. */
int platform_command_line(char *buffer, uint32_t size);
/* Bytes of the stack reservation ever written (painted pattern overwritten). */
uint32_t platform_stack_high_water_bytes(void);
void platform_exit(int status) __attribute__((noreturn));
void platform_fault(uint32_t exception_number) __attribute__((noreturn));

#endif
