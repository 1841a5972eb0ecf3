/* Instruction-count bench of the noise-robust loop (issue 13) on the Cortex-M4F, run under
 * QEMU with a single-step trace like arm/bench.c (README "Instruction counting"); phases are
 * PHASES_ROBUST in tools/count_instructions.py. Input: a version-2 stream (the drive cycle).
 *
 *   1 dp_svf_update_f32 on ticks 0..FEED-1 and dp_svf_solve_f32 every SOLVE_EVERY ticks (both
 *     counted in this phase, each per call)
 *   2 dp_kalman_update_f32 (scheduled with the flow), after a warm-up that fills the window
 *   3 firmware_robust_tick: ADC, CVD x2, fault checks, SVF update, schedule, Kalman (no solve)
 * Only FEED ticks after the first SKIP of the stream are used (the trace of every executed
 * instruction is written to disk, ~500 bytes per instruction, and longer runs only repeat the
 * same paths). The float solves within the start-up transient window (66 tf/Ts rows) are
 * refused (insufficient excitation: the C API does not trust the float projection of the
 * start-up transients there, see dp_svf_solve_f32), so FEED
 * spans that window and the solves measured include ok ones (the full path: eigen-solve,
 * exponent fit, roots); the trace is then ~2.5 GB, deleted after counting. */
#include <string.h>

#include "adc.h"
#include "dualprobe/dualprobe.h"
#include "firmware.h"
#include "platform.h"
#include "platform_arm.h"

#define SKIP 6000u /* ticks of the stream skipped (read, not processed): mid-cycle data */
#define FEED 5000u
#define SOLVE_EVERY 500u
#define KALMAN_WARMUP 64u
#define MEASURED 256u

enum { PHASE_SVF = 1, PHASE_KALMAN = 2, PHASE_TICK = 3, PHASE_END = 4 };

volatile uint32_t g_bench_phase;
__attribute__((noinline)) void bench_phase(uint32_t phase) { g_bench_phase = phase; }

static uint32_t g_counts1[FEED];
static uint32_t g_counts2[FEED];
static float g_flow[FEED];
static float g_t1[FEED];
static float g_t2[FEED];
static firmware_state g_state;
static dp_svf_instance_f32 g_svf;
static dp_kalman_instance_f32 g_kalman;
static char g_command_line[256];
volatile float g_sink;
static uint32_t g_ok_solves;

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

static uint32_t read_le32(const uint8_t *p) {
  return (uint32_t)p[0] | ((uint32_t)p[1] << 8) | ((uint32_t)p[2] << 16) | ((uint32_t)p[3] << 24);
}

static int fail(const char *message) {
  platform_write(PLATFORM_STDERR, message, (uint32_t)strlen(message));
  return 2;
}

int main(void) {
  if (platform_command_line(g_command_line, sizeof g_command_line) != 0) {
    return fail("bench: no command line\n");
  }
  char *path = g_command_line;
  while (*path != ' ' && *path != '\0') ++path;
  while (*path == ' ') ++path;
  char *end = path;
  while (*end != ' ' && *end != '\0') ++end;
  *end = '\0';
  const int handle = platform_open_input(path);
  if (handle < 0) return fail("bench: cannot open input\n");
  uint8_t header[FIRMWARE_HEADER_BYTES];
  uint8_t extra[FIRMWARE_HEADER2_EXTRA_BYTES];
  firmware_config config;
  if (platform_read(handle, header, FIRMWARE_HEADER_BYTES) != (int32_t)FIRMWARE_HEADER_BYTES ||
      firmware_parse_header(header, &config) != 0 || config.version != FIRMWARE_VERSION_ROBUST ||
      platform_read(handle, extra, FIRMWARE_HEADER2_EXTRA_BYTES) !=
          (int32_t)FIRMWARE_HEADER2_EXTRA_BYTES ||
      firmware_parse_header2(extra, &config) != 0 || config.ticks < SKIP + FEED ||
      config.estimator != ESTIMATOR_SVF) {
    return fail("bench: need a version-2 SVF stream of at least FEED ticks\n");
  }
  uint8_t row[12];
  for (uint32_t k = 0; k < SKIP; ++k) {
    if (platform_read(handle, row, 12u) != 12) return fail("bench: short input\n");
  }
  for (uint32_t k = 0; k < FEED; ++k) {
    if (platform_read(handle, row, 12u) != 12) return fail("bench: short input\n");
    g_counts1[k] = read_le32(row);
    g_counts2[k] = read_le32(row + 4);
    const uint32_t bits = read_le32(row + 8);
    memcpy(&g_flow[k], &bits, sizeof bits);
    if (adc_read_channel(g_counts1[k], &g_t1[k]) != CHANNEL_OK ||
        adc_read_channel(g_counts2[k], &g_t2[k]) != CHANNEL_OK) {
      return fail("bench: the first FEED ticks must be fault-free\n");
    }
  }
  platform_close(handle);

  /* The loop's own initialisation (SVF and Kalman configured from the calibration). */
  if (firmware_init(&g_state, &config) != DP_STATUS_OK) return fail("bench: firmware init\n");
  memcpy(&g_svf, &g_state.svf, sizeof g_svf);
  memcpy(&g_kalman, &g_state.kalman, sizeof g_kalman);

  dp_svf_result_f32 result;
  dp_svf_result_f32 good;
  memset(&good, 0, sizeof good);
  good.status = DP_STATUS_NOT_READY;
  bench_phase(PHASE_SVF);
  for (uint32_t k = 0; k < FEED; ++k) {
    (void)dp_svf_update_f32(&g_svf, g_t1[k], g_t2[k], g_flow[k]);
    if ((k + 1u) % SOLVE_EVERY == 0u) {
      const dp_status status = dp_svf_solve_f32(&g_svf, &result);
      if (status == DP_STATUS_OK) {
        good = result;
        ++g_ok_solves;
      }
    }
  }
  if (good.status != DP_STATUS_OK) return fail("bench: no ok solve in the bench feed\n");
  put_dec_line("bench_ok_solves=", g_ok_solves);

  if (dp_kalman_retune_f32(&g_kalman, good.tau1, good.tau2) != DP_STATUS_OK) {
    return fail("bench: kalman retune\n");
  }
  float gas = 0.0f;
  for (uint32_t k = 0; k < KALMAN_WARMUP; ++k) {
    const float psi = dp_svf_schedule_f32(&g_svf, &good, g_flow[k]);
    (void)dp_kalman_update_f32(&g_kalman, g_t1[k], g_t2[k], psi, &gas);
  }
  bench_phase(PHASE_KALMAN);
  for (uint32_t k = KALMAN_WARMUP; k < KALMAN_WARMUP + MEASURED; ++k) {
    const float psi = dp_svf_schedule_f32(&g_svf, &good, g_flow[k]);
    (void)dp_kalman_update_f32(&g_kalman, g_t1[k], g_t2[k], psi, &gas);
  }
  g_sink = gas;

  /* The whole tick as the loop runs it, with published time constants and no solve. */
  config.solve_every = 0xFFFFFFFFu;
  config.initial_tau1 = good.tau1[0];
  config.initial_tau2 = good.tau2[0];
  if (firmware_init(&g_state, &config) != DP_STATUS_OK) return fail("bench: firmware init\n");
  (void)dp_kalman_retune_f32(&g_state.kalman, good.tau1, good.tau2);
  g_state.good = good;
  tick_output out;
  for (uint32_t k = 0; k < KALMAN_WARMUP; ++k) {
    firmware_robust_tick(&g_state, g_counts1[k], g_counts2[k], g_flow[k], &out);
  }
  bench_phase(PHASE_TICK);
  for (uint32_t k = KALMAN_WARMUP; k < KALMAN_WARMUP + MEASURED; ++k) {
    firmware_robust_tick(&g_state, g_counts1[k], g_counts2[k], g_flow[k], &out);
  }
  g_sink = out.gas;
  bench_phase(PHASE_END);
  return 0;
}
