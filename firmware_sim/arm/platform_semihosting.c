/* Cortex-M4F platform: I/O through semihosting (QEMU -semihosting), exit with a status code,
 * fault reporting, and the stack high-water mark from the pattern painted by startup.S. */
#include <string.h>

#include "platform.h"
#include "platform_arm.h"
#include "semihosting.h"

extern uint32_t __stack_limit[];
extern uint32_t __stack_top[];

int platform_open_input(const char *path) {
  uint32_t block[3] = {(uint32_t)(uintptr_t)path, 1u /* "rb" */, (uint32_t)strlen(path)};
  return (int)semihosting_call(SYS_OPEN, block);
}

int32_t platform_read(int handle, void *buffer, uint32_t bytes) {
  uint32_t block[3] = {(uint32_t)handle, (uint32_t)(uintptr_t)buffer, bytes};
  const int32_t not_read = semihosting_call(SYS_READ, block);
  if (not_read < 0 || (uint32_t)not_read > bytes) return -1;
  return (int32_t)(bytes - (uint32_t)not_read);
}

void platform_close(int handle) {
  uint32_t block[1] = {(uint32_t)handle};
  (void)semihosting_call(SYS_CLOSE, block);
}

/* Semihosting ":tt" opened for writing is the emulator's stdout, for appending its stderr. */
static int console_handle(int stream) {
  static int handles[2] = {-1, -1};
  const int index = stream == PLATFORM_STDERR ? 1 : 0;
  if (handles[index] < 0) {
    uint32_t block[3] = {(uint32_t)(uintptr_t)":tt", index == 1 ? 8u /* "a" */ : 4u /* "w" */,
                         3u};
    handles[index] = (int)semihosting_call(SYS_OPEN, block);
  }
  return handles[index];
}

void platform_write(int stream, const char *text, uint32_t length) {
  uint32_t block[3] = {(uint32_t)console_handle(stream), (uint32_t)(uintptr_t)text, length};
  (void)semihosting_call(SYS_WRITE, block);
}

int platform_command_line(char *buffer, uint32_t size) {
  uint32_t block[2] = {(uint32_t)(uintptr_t)buffer, size};
  return semihosting_call(SYS_GET_CMDLINE, block) == 0 ? 0 : -1;
}

uint32_t platform_stack_high_water_bytes(void) {
  const uint32_t *word = __stack_limit;
  while (word < __stack_top && *word == 0x5AA5F00Du) ++word;
  return (uint32_t)((uintptr_t)__stack_top - (uintptr_t)word);
}

void platform_exit(int status) {
  uint32_t block[2] = {ADP_STOPPED_APPLICATION_EXIT, (uint32_t)status};
  for (;;) (void)semihosting_call(SYS_EXIT_EXTENDED, block);
}

void platform_fault(uint32_t exception_number) {
  char text[] = "fatal: exception 0x00\n";
  text[19] = "0123456789abcdef"[(exception_number >> 4) & 0xFu];
  text[20] = "0123456789abcdef"[exception_number & 0xFu];
  platform_write(PLATFORM_STDERR, text, (uint32_t)(sizeof text - 1u));
  platform_exit(3);
}
