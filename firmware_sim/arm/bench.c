/* Instruction-count bench for the Cortex-M4F (run under QEMU with a single-step execution
 * trace, see README "Instruction counting"). It loads the same input stream as the firmware,
 * then runs one phase per measured function; tools/count_instructions.py splits the trace at
 * each call of bench_phase() and counts, for every call of the phase's function, the
 * instructions from its entry to its return (callees included).
 *
 * Phase order is the contract with count_instructions.py (PHASES there). To add a function:
 * append a phase here and a row there. */
#include <string.h>

#include "adc.h"
#include "bench_kalman.h"
#include "dualprobe/dualprobe.h"
#include "firmware.h"
#include "platform.h"
#include "platform_arm.h"
#include "pt100.h"

#define BENCH_SAMPLES 512u

enum bench_phase_id {
  PHASE_UPDATE = 1,       /* dp_diff_update_f32, per sample */
  PHASE_SOLVE = 2,        /* dp_diff_solve_f32, every solve_every ticks of the stream */
  PHASE_RECONSTRUCT = 3,  /* dp_recon_update_f32, per sample */
  PHASE_TICK = 4,         /* firmware_tick: ADC + CVD + update + reconstruct (+ solve) */
  PHASE_PT100 = 5,        /* pt100_temperature, per channel reading */
  PHASE_KALMAN = 6,       /* bench_kalman_update (causal Kalman reconstruction), per sample */
  PHASE_KALMAN_CONFIGURE = 7, /* bench_kalman_init: validation + discretisation (double), once */
  PHASE_END = 8
};

/* The Kalman phase measures samples KALMAN_WARMUP.. of the bench input: the first ones fill
 * the GLR window (64 candidates), so the measured samples cost what a running ECU pays. */
#define KALMAN_WARMUP 128u
/* Gas intensity (K^2/s) of the Kalman's random walk: levels that hold still between steps (an
 * ECU calibration constant; the cost per sample does not depend on it). */
#define KALMAN_INTENSITY 1e-4f

/* The trace splits at the entry of this function; noinline and a side effect keep it. */
volatile uint32_t g_bench_phase;
__attribute__((noinline)) void bench_phase(uint32_t phase) { g_bench_phase = phase; }

static uint32_t g_counts1[BENCH_SAMPLES];
static uint32_t g_counts2[BENCH_SAMPLES];
static float g_t1[BENCH_SAMPLES];
static float g_t2[BENCH_SAMPLES];
static firmware_state g_state;
static char g_command_line[256];
volatile float g_sink;

static uint32_t read_le32(const uint8_t *p) {
  return (uint32_t)p[0] | ((uint32_t)p[1] << 8) | ((uint32_t)p[2] << 16) | ((uint32_t)p[3] << 24);
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

static int fail(const char *message) {
  platform_write(PLATFORM_STDERR, message, (uint32_t)strlen(message));
  return 2;
}

/* Phase PHASE_SOLVE: re-reads the input stream in chunks; healthy ticks update the estimator,
 * every solve_every-th tick solves. Keeps the last good time constants. */
static int stream_solves(const char *path, const firmware_config *config,
                         dp_diff_instance_f32 *estimator, dp_diff_result_f32 *result,
                         float *tau1, float *tau2) {
  const int handle = platform_open_input(path);
  uint8_t header[FIRMWARE_HEADER_BYTES];
  if (handle < 0 ||
      platform_read(handle, header, FIRMWARE_HEADER_BYTES) != (int32_t)FIRMWARE_HEADER_BYTES) {
    return -1;
  }
  static uint8_t chunk[64 * 8];
  bench_phase(PHASE_SOLVE);
  for (uint32_t done = 0; done < config->ticks;) {
    uint32_t want = config->ticks - done;
    if (want > 64u) want = 64u;
    if (platform_read(handle, chunk, want * 8u) != (int32_t)(want * 8u)) return -1;
    for (uint32_t i = 0; i < want; ++i) {
      float t1;
      float t2;
      if (adc_read_channel(read_le32(chunk + 8u * i), &t1) == CHANNEL_OK &&
          adc_read_channel(read_le32(chunk + 8u * i + 4u), &t2) == CHANNEL_OK) {
        (void)dp_diff_update_f32(estimator, t1, t2);
      }
      if ((done + i + 1u) % config->solve_every == 0u &&
          dp_diff_solve_f32(estimator, result) == DP_STATUS_OK) {
        *tau1 = result->tau1;
        *tau2 = result->tau2;
      }
    }
    done += want;
  }
  platform_close(handle);
  return 0;
}

int main(void) {
  if (platform_command_line(g_command_line, sizeof g_command_line) != 0) {
    return fail("bench: no command line\n");
  }
  /* Second word of the command line: the input stream. */
  char *path = g_command_line;
  while (*path != ' ' && *path != '\0') ++path;
  while (*path == ' ') ++path;
  char *end = path;
  while (*end != ' ' && *end != '\0') ++end;
  *end = '\0';
  const int handle = platform_open_input(path);
  if (handle < 0) return fail("bench: cannot open input\n");
  uint8_t header[FIRMWARE_HEADER_BYTES];
  firmware_config config;
  if (platform_read(handle, header, FIRMWARE_HEADER_BYTES) != (int32_t)FIRMWARE_HEADER_BYTES ||
      firmware_parse_header(header, &config) != 0 || config.ticks < BENCH_SAMPLES) {
    return fail("bench: bad input header or fewer ticks than BENCH_SAMPLES\n");
  }
  uint8_t pair[8];
  for (uint32_t k = 0; k < BENCH_SAMPLES; ++k) {
    if (platform_read(handle, pair, 8u) != 8) return fail("bench: short input\n");
    g_counts1[k] = read_le32(pair);
    g_counts2[k] = read_le32(pair + 4);
    if (adc_read_channel(g_counts1[k], &g_t1[k]) != CHANNEL_OK ||
        adc_read_channel(g_counts2[k], &g_t2[k]) != CHANNEL_OK) {
      return fail("bench: the first BENCH_SAMPLES ticks must be fault-free\n");
    }
  }
  platform_close(handle);

  const dp_diff_config_f32 diff = {config.sample_interval, config.method, config.sigma1,
                                   config.sigma2, config.forgetting};
  dp_diff_instance_f32 estimator;
  if (dp_diff_init_f32(&estimator, &diff) != DP_STATUS_OK) return fail("bench: bad config\n");

  bench_phase(PHASE_UPDATE);
  for (uint32_t k = 0; k < BENCH_SAMPLES; ++k) (void)dp_diff_update_f32(&estimator, g_t1[k], g_t2[k]);

  /* Solves on the scatters a running ECU sees: the whole input stream, updated every tick
   * (not measured here) and solved every solve_every ticks (measured). */
  dp_diff_result_f32 result;
  dp_diff_reset_f32(&estimator);
  float tau1 = 1.0f;
  float tau2 = 1.0f;
  if (stream_solves(path, &config, &estimator, &result, &tau1, &tau2) != 0) {
    return fail("bench: cannot stream the input for the solve phase\n");
  }

  const dp_recon_config_f32 recon_config = {config.sample_interval, tau1, tau2, config.source,
                                            config.lowpass_tau};
  dp_recon_instance_f32 recon;
  if (dp_recon_init_f32(&recon, &recon_config) != DP_STATUS_OK) return fail("bench: recon\n");
  bench_phase(PHASE_RECONSTRUCT);
  float gas = 0.0f;
  for (uint32_t k = 0; k < BENCH_SAMPLES; ++k) {
    (void)dp_recon_update_f32(&recon, g_t1[k], g_t2[k], &gas);
  }
  g_sink = gas;

  if (firmware_init(&g_state, &config) != DP_STATUS_OK) return fail("bench: firmware init\n");
  bench_phase(PHASE_TICK);
  tick_output out;
  for (uint32_t k = 0; k < BENCH_SAMPLES; ++k) firmware_tick(&g_state, g_counts1[k], g_counts2[k], &out);
  g_sink = out.gas;

  bench_phase(PHASE_PT100);
  float sum = 0.0f;
  for (uint32_t k = 0; k < BENCH_SAMPLES; ++k) {
    sum += pt100_temperature(adc_counts_to_ohm(g_counts1[k]));
  }
  g_sink = sum;

  /* Noise levels of the calibration (GTLS ones), else a typical 0.02 K. */
  const float sigma1 = config.sigma1 > 0.0f ? config.sigma1 : 0.02f;
  const float sigma2 = config.sigma2 > 0.0f ? config.sigma2 : 0.02f;
  if (bench_kalman_init(config.sample_interval, tau1, tau2, sigma1, sigma2, KALMAN_INTENSITY) !=
      0) {
    return fail("bench: kalman config\n");
  }
  for (uint32_t k = 0; k < KALMAN_WARMUP; ++k) (void)bench_kalman_update(g_t1[k], g_t2[k], &gas);
  bench_phase(PHASE_KALMAN);
  for (uint32_t k = KALMAN_WARMUP; k < BENCH_SAMPLES; ++k) {
    (void)bench_kalman_update(g_t1[k], g_t2[k], &gas);
  }
  g_sink = gas;

  /* What a retune costs (the ECU re-solves the time constants every second). */
  bench_phase(PHASE_KALMAN_CONFIGURE);
  if (bench_kalman_init(config.sample_interval, tau1, tau2, sigma1, sigma2, KALMAN_INTENSITY) !=
      0) {
    return fail("bench: kalman config\n");
  }

  bench_phase(PHASE_END);
  put_dec_line("kalman_bytes=", bench_kalman_bytes());
  put_dec_line("kalman_jumps=", bench_kalman_jumps());
  return 0;
}
