/* Cortex-M4F firmware image: `firmware.elf INPUT` through the semihosting command line. */
#include <string.h>

#include "firmware.h"
#include "platform.h"
#include "platform_arm.h"

/* Returns the second whitespace-separated word of the command line (the first is the
 * program name), NUL-terminated in place, or NULL. */
static const char *input_argument(char *line) {
  char *word = line;
  for (int index = 0; index < 2; ++index) {
    while (*word == ' ') ++word;
    if (*word == '\0') return 0;
    char *end = word;
    while (*end != '\0' && *end != ' ') ++end;
    if (index == 1) {
      *end = '\0';
      return word;
    }
    word = end;
  }
  return 0;
}

static void put_dec_line(const char *label, uint32_t value) {
  char text[64];
  uint32_t n = (uint32_t)strlen(label);
  memcpy(text, label, n);
  char digits[10];
  int count = 0;
  do {
    digits[count++] = (char)('0' + value % 10u);
    value /= 10u;
  } while (value != 0u);
  while (count > 0) text[n++] = digits[--count];
  text[n++] = '\n';
  platform_write(PLATFORM_STDERR, text, n);
}

static char g_command_line[256];

int main(void) {
  const char *path = 0;
  if (platform_command_line(g_command_line, sizeof g_command_line) == 0) {
    path = input_argument(g_command_line);
  }
  const int status = firmware_run(path);
  /* Measured on the target itself, for the budget report. */
  put_dec_line("estimator_bytes=", (uint32_t)sizeof(dp_diff_instance_f32));
  put_dec_line("reconstruction_bytes=", (uint32_t)sizeof(dp_recon_instance_f32));
  put_dec_line("firmware_state_bytes=", (uint32_t)sizeof(firmware_state));
  put_dec_line("svf_bytes=", (uint32_t)sizeof(dp_svf_instance_f32));
  put_dec_line("kalman_instance_bytes=", (uint32_t)sizeof(dp_kalman_instance_f32));
  put_dec_line("stack_high_water_bytes=", platform_stack_high_water_bytes());
  return status;
}
